//! The switching network (`[network]`): voltage levels, connectivity nodes,
//! lines, cables and transformers, switching devices bound to their status
//! and command tags, sources, loads, which source groups may run in
//! parallel, and two shorthands that bring a `[[panel]]` and the
//! `[microgrid]` into the network. [`NetworkConfig::elements`] expands the
//! shorthands, so checks and the topology processor read one flat list.

use std::ops::Range;

use serde::{Deserialize, Serialize};
use serde_spanned::Spanned;

use super::{MicrogridConfig, PanelConfig};

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NetworkConfig {
    /// Prefix of the tags the network publishes (`NET.Sec.<section>.State`).
    #[serde(default = "default_prefix")]
    pub prefix: Spanned<String>,
    /// How long a select-before-operate reservation holds.
    #[serde(default = "default_select_timeout")]
    pub select_timeout_s: Spanned<f64>,
    #[serde(default, rename = "level")]
    pub levels: Vec<LevelConfig>,
    #[serde(default, rename = "node")]
    pub nodes: Vec<NodeConfig>,
    #[serde(default, rename = "branch")]
    pub branches: Vec<BranchConfig>,
    #[serde(default, rename = "switch")]
    pub switches: Vec<SwitchConfig>,
    #[serde(default, rename = "source")]
    pub sources: Vec<SourceConfig>,
    #[serde(default, rename = "load")]
    pub loads: Vec<LoadConfig>,
    #[serde(default, rename = "parallel")]
    pub parallel: Vec<ParallelConfig>,
    /// `[[network.panel]]`: a panel's ELCB, MCCB and zones as devices.
    #[serde(default, rename = "panel")]
    pub panels: Vec<NetworkPanelConfig>,
    /// `[network.microgrid]`: every microgrid unit as a source.
    pub microgrid: Option<NetworkMicrogridConfig>,
}

fn default_prefix() -> Spanned<String> {
    Spanned::new(0..0, "NET".into())
}
fn default_select_timeout() -> Spanned<f64> {
    Spanned::new(0..0, 30.0)
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LevelConfig {
    pub id: Spanned<String>,
    pub kv: Spanned<f64>,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NodeConfig {
    pub id: Spanned<String>,
    /// Groups nodes into one station on the generated screen.
    pub station: Option<String>,
    #[serde(default)]
    pub busbar: bool,
    /// A `[[network.level]]` id; levels spread over lines, cables and
    /// switches, and across transformers by their ratio.
    pub level: Option<Spanned<String>>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum BranchKind {
    Line,
    Cable,
    Transformer,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BranchConfig {
    pub id: Spanned<String>,
    pub name: Option<String>,
    pub kind: BranchKind,
    pub from: Spanned<String>,
    pub to: Spanned<String>,
    /// A transformer's rated voltages, `from` side first.
    pub kv: Option<Spanned<[f64; 2]>>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum SwitchKind {
    CircuitBreaker,
    LoadBreakSwitch,
    Disconnector,
    EarthSwitch,
    Fuse,
}

impl SwitchKind {
    pub fn as_str(self) -> &'static str {
        match self {
            SwitchKind::CircuitBreaker => "circuit_breaker",
            SwitchKind::LoadBreakSwitch => "load_break_switch",
            SwitchKind::Disconnector => "disconnector",
            SwitchKind::EarthSwitch => "earth_switch",
            SwitchKind::Fuse => "fuse",
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Normally {
    Open,
    Closed,
}

fn normally_closed() -> Normally {
    Normally::Closed
}

/// Where a device's position is read.
#[derive(Debug, Clone, PartialEq, Eq, Deserialize, Serialize)]
#[serde(untagged)]
pub enum StatusBinding {
    /// A bool (true: closed) or an integer double point (1 open, 2 closed;
    /// 0 and 3 intermediate and indeterminate).
    Tag(String),
    /// Two single points, as many RTUs report a breaker.
    Pair { open: String, closed: String },
}

/// How a device is commanded.
#[derive(Debug, Clone, PartialEq, Eq, Deserialize, Serialize)]
#[serde(untagged)]
pub enum CommandBinding {
    /// Write true to close, false to open.
    Tag(String),
    /// One operation only: writing true to `tag` performs it (an ELCB's
    /// reset closes it; a trip coil opens a breaker).
    Pulse { tag: String, pulse: Normally },
}

impl CommandBinding {
    pub fn tag(&self) -> &str {
        match self {
            CommandBinding::Tag(t) | CommandBinding::Pulse { tag: t, .. } => t,
        }
    }
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SwitchConfig {
    pub id: Spanned<String>,
    pub name: Option<String>,
    pub kind: SwitchKind,
    pub from: Spanned<String>,
    /// None for an earth switch: it connects `from` to earth.
    pub to: Option<Spanned<String>>,
    pub status: Option<Spanned<StatusBinding>>,
    pub command: Option<Spanned<CommandBinding>>,
    #[serde(default = "normally_closed")]
    pub normally: Normally,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum SourceKind {
    Grid,
    Generator,
    Storage,
    Pv,
    Wind,
}

/// When a source is in service.
#[derive(Debug, Clone, PartialEq, Eq, Deserialize, Serialize)]
#[serde(untagged)]
pub enum InService {
    /// A bool tag, true in service.
    Tag(String),
    /// An integer tag in service at one value (a unit controller's state).
    Equals { tag: String, equals: i64 },
}

impl InService {
    pub fn tag(&self) -> &str {
        match self {
            InService::Tag(t) | InService::Equals { tag: t, .. } => t,
        }
    }
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SourceConfig {
    pub id: Spanned<String>,
    pub name: Option<String>,
    pub kind: SourceKind,
    pub node: Spanned<String>,
    /// Sources of one group may always run in parallel; default: its id.
    pub group: Option<String>,
    /// None: always in service.
    pub in_service: Option<Spanned<InService>>,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LoadConfig {
    pub id: Spanned<String>,
    pub name: Option<String>,
    pub node: Spanned<String>,
    #[serde(default)]
    pub customers: u32,
    /// A bool tag measuring that the load has voltage, checked against the
    /// topology.
    pub energised: Option<Spanned<String>>,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ParallelConfig {
    pub groups: Spanned<Vec<String>>,
    /// Refused, but a supervisor may override (a make-before-break
    /// transfer); false: allowed.
    #[serde(default)]
    pub overridable: bool,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NetworkPanelConfig {
    /// A `[[panel]]` id.
    pub panel: Spanned<String>,
    /// The node the ELCB's line side sits on.
    pub supply: Spanned<String>,
    /// Customers per zone, zone 1 first.
    #[serde(default = "no_customers")]
    pub customers: Spanned<Vec<u32>>,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NetworkMicrogridConfig {
    /// The node the units feed.
    pub node: Spanned<String>,
    #[serde(default = "default_microgrid_group")]
    pub group: String,
}

fn no_customers() -> Spanned<Vec<u32>> {
    Spanned::new(0..0, Vec::new())
}

fn default_microgrid_group() -> String {
    "microgrid".into()
}

/// One network element with the span (in the main file) of what declared
/// it: its own entry, or the shorthand that made it.
#[derive(Debug, Clone, PartialEq)]
pub struct Declared<T> {
    pub at: Range<usize>,
    pub item: T,
}

#[derive(Debug, Clone, PartialEq)]
pub struct NetNode {
    pub id: String,
    pub station: Option<String>,
    pub busbar: bool,
    pub kv: Option<f64>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct NetBranch {
    pub id: String,
    pub name: String,
    pub kind: BranchKind,
    pub from: String,
    pub to: String,
    pub kv: Option<[f64; 2]>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct NetSwitch {
    pub id: String,
    pub name: String,
    pub kind: SwitchKind,
    pub from: String,
    pub to: Option<String>,
    pub status: Option<StatusBinding>,
    pub command: Option<CommandBinding>,
    pub normally: Normally,
}

#[derive(Debug, Clone, PartialEq)]
pub struct NetSource {
    pub id: String,
    pub name: String,
    pub kind: SourceKind,
    pub node: String,
    pub group: String,
    pub in_service: Option<InService>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct NetLoad {
    pub id: String,
    pub name: String,
    pub node: String,
    pub customers: u32,
    pub energised: Option<String>,
}

/// The network as one flat list, shorthands expanded.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct NetworkElements {
    pub nodes: Vec<Declared<NetNode>>,
    pub branches: Vec<Declared<NetBranch>>,
    pub switches: Vec<Declared<NetSwitch>>,
    pub sources: Vec<Declared<NetSource>>,
    pub loads: Vec<Declared<NetLoad>>,
    /// (group, group, overridable)
    pub parallel: Vec<Declared<(String, String, bool)>>,
}

impl NetworkConfig {
    /// Every element, the shorthands expanded with the panels' and the
    /// microgrid's tag names. A shorthand naming a panel that does not exist
    /// expands to nothing (the checks say so); a zone's load is checked
    /// against the zone's `Energised` tag where the plant has one.
    pub fn elements(
        &self,
        panels: &[PanelConfig],
        microgrid: Option<&MicrogridConfig>,
        has_tag: &dyn Fn(&str) -> bool,
    ) -> NetworkElements {
        let kv_of = |level: &Option<Spanned<String>>| {
            let level = level.as_ref()?;
            self.levels
                .iter()
                .find(|l| l.id.get_ref() == level.get_ref())
                .map(|l| *l.kv.get_ref())
        };
        let mut out = NetworkElements::default();
        for n in &self.nodes {
            out.nodes.push(Declared {
                at: n.id.span(),
                item: NetNode {
                    id: n.id.get_ref().clone(),
                    station: n.station.clone(),
                    busbar: n.busbar,
                    kv: kv_of(&n.level),
                },
            });
        }
        for b in &self.branches {
            out.branches.push(Declared {
                at: b.id.span(),
                item: NetBranch {
                    id: b.id.get_ref().clone(),
                    name: b.name.clone().unwrap_or_else(|| b.id.get_ref().clone()),
                    kind: b.kind,
                    from: b.from.get_ref().clone(),
                    to: b.to.get_ref().clone(),
                    kv: b.kv.as_ref().map(|k| *k.get_ref()),
                },
            });
        }
        for s in &self.switches {
            out.switches.push(Declared {
                at: s.id.span(),
                item: NetSwitch {
                    id: s.id.get_ref().clone(),
                    name: s.name.clone().unwrap_or_else(|| s.id.get_ref().clone()),
                    kind: s.kind,
                    from: s.from.get_ref().clone(),
                    to: s.to.as_ref().map(|t| t.get_ref().clone()),
                    status: s.status.as_ref().map(|t| t.get_ref().clone()),
                    command: s.command.as_ref().map(|t| t.get_ref().clone()),
                    normally: s.normally,
                },
            });
        }
        for s in &self.sources {
            out.sources.push(Declared {
                at: s.id.span(),
                item: NetSource {
                    id: s.id.get_ref().clone(),
                    name: s.name.clone().unwrap_or_else(|| s.id.get_ref().clone()),
                    kind: s.kind,
                    node: s.node.get_ref().clone(),
                    group: s.group.clone().unwrap_or_else(|| s.id.get_ref().clone()),
                    in_service: s.in_service.as_ref().map(|t| t.get_ref().clone()),
                },
            });
        }
        for l in &self.loads {
            out.loads.push(Declared {
                at: l.id.span(),
                item: NetLoad {
                    id: l.id.get_ref().clone(),
                    name: l.name.clone().unwrap_or_else(|| l.id.get_ref().clone()),
                    node: l.node.get_ref().clone(),
                    customers: l.customers,
                    energised: l.energised.as_ref().map(|t| t.get_ref().clone()),
                },
            });
        }
        for p in &self.parallel {
            if let [a, b] = p.groups.get_ref().as_slice() {
                out.parallel.push(Declared {
                    at: p.groups.span(),
                    item: (a.clone(), b.clone(), p.overridable),
                });
            }
        }
        for np in &self.panels {
            let Some(panel) = panels.iter().find(|p| p.id.get_ref() == np.panel.get_ref()) else {
                continue;
            };
            expand_panel(&mut out, np, panel, has_tag);
        }
        if let (Some(mg), Some(units)) = (&self.microgrid, microgrid) {
            for u in &units.units {
                out.sources.push(Declared {
                    at: mg.node.span(),
                    item: NetSource {
                        id: u.id.get_ref().clone(),
                        name: u.name.clone(),
                        kind: match u.kind {
                            super::UnitKind::Pv => SourceKind::Pv,
                            super::UnitKind::Wind => SourceKind::Wind,
                            super::UnitKind::Storage => SourceKind::Storage,
                            super::UnitKind::Diesel => SourceKind::Generator,
                        },
                        node: mg.node.get_ref().clone(),
                        group: mg.group.clone(),
                        // The unit controller's state: 1 running.
                        in_service: Some(InService::Equals {
                            tag: format!("{}.State", u.prefix.get_ref()),
                            equals: 1,
                        }),
                    },
                });
            }
        }
        out
    }
}

fn expand_panel(
    out: &mut NetworkElements,
    np: &NetworkPanelConfig,
    panel: &PanelConfig,
    has_tag: &dyn Fn(&str) -> bool,
) {
    let at = np.panel.span();
    let id = panel.id.get_ref().to_lowercase();
    let io = panel.io();
    let station = Some(panel.name.clone());
    let node = |out: &mut NetworkElements, id: String, busbar: bool| {
        out.nodes.push(Declared {
            at: at.clone(),
            item: NetNode {
                id,
                station: station.clone(),
                busbar,
                kv: None,
            },
        })
    };
    let switch = |out: &mut NetworkElements,
                  id: String,
                  name: String,
                  from: String,
                  to: String,
                  status: &str,
                  command: CommandBinding| {
        out.switches.push(Declared {
            at: at.clone(),
            item: NetSwitch {
                id,
                name,
                kind: SwitchKind::CircuitBreaker,
                from,
                to: Some(to),
                status: Some(StatusBinding::Tag(status.to_string())),
                command: Some(command),
                normally: Normally::Closed,
            },
        })
    };
    let mid = format!("{id}_m");
    let busbar = format!("{id}_bb");
    node(out, mid.clone(), false);
    node(out, busbar.clone(), true);
    switch(
        out,
        format!("{id}_elcb"),
        format!("{} ELCB", panel.name),
        np.supply.get_ref().clone(),
        mid.clone(),
        &io.elcb_closed,
        CommandBinding::Pulse {
            tag: io.elcb_reset.clone(),
            pulse: Normally::Closed,
        },
    );
    switch(
        out,
        format!("{id}_mccb"),
        format!("{} MCCB", panel.name),
        mid,
        busbar.clone(),
        &io.mccb_closed,
        CommandBinding::Tag(io.mccb_cmd.clone()),
    );
    let prefix = panel.prefix.get_ref();
    for (z, (closed, cmd)) in io.zone_closed.iter().zip(&io.zone_cmd).enumerate() {
        let zone = z + 1;
        let zone_node = format!("{id}_z{zone}");
        node(out, zone_node.clone(), false);
        switch(
            out,
            format!("{id}_z{zone}"),
            format!("{} zone {zone}", panel.name),
            busbar.clone(),
            zone_node.clone(),
            closed,
            CommandBinding::Tag(cmd.clone()),
        );
        out.loads.push(Declared {
            at: at.clone(),
            item: NetLoad {
                id: format!("{id}_zone{zone}"),
                name: format!("{} zone {zone}", panel.name),
                node: zone_node,
                customers: np.customers.get_ref().get(z).copied().unwrap_or(0),
                energised: Some(format!("{prefix}.Zone{zone}.Energised")).filter(|t| has_tag(t)),
            },
        });
    }
}

/// Two voltages met on one connected part of the same voltage level.
#[derive(Debug, Clone, PartialEq)]
pub struct VoltageConflict {
    /// Where the second voltage was declared.
    pub at: Range<usize>,
    pub message: String,
}

/// The nominal voltage of each node, spread from the nodes' levels and the
/// transformers' ratings over lines, cables and switching devices; and every
/// place where two voltages meet on one part (e.g. a ring of transformers
/// whose ratings do not agree). Nodes the spreading does not reach have none.
pub fn node_voltages(
    elements: &NetworkElements,
) -> (std::collections::HashMap<String, f64>, Vec<VoltageConflict>) {
    use std::collections::HashMap;
    let index: HashMap<&str, usize> = elements
        .nodes
        .iter()
        .enumerate()
        .map(|(i, n)| (n.item.id.as_str(), i))
        .collect();
    // Parts of one voltage: nodes joined by anything but a transformer.
    let mut parent: Vec<usize> = (0..elements.nodes.len()).collect();
    fn find(parent: &mut [usize], mut x: usize) -> usize {
        while parent[x] != x {
            parent[x] = parent[parent[x]];
            x = parent[x];
        }
        x
    }
    let mut join = |a: &str, b: &str| {
        if let (Some(&a), Some(&b)) = (index.get(a), index.get(b)) {
            let (ra, rb) = (find(&mut parent, a), find(&mut parent, b));
            parent[ra] = rb;
        }
    };
    for b in &elements.branches {
        if b.item.kind != BranchKind::Transformer {
            join(&b.item.from, &b.item.to);
        }
    }
    for s in &elements.switches {
        if let Some(to) = &s.item.to {
            join(&s.item.from, to);
        }
    }
    // What each part is declared to be, and by whom.
    let mut declared: Vec<(&str, f64, Range<usize>, String)> = Vec::new();
    for n in &elements.nodes {
        if let Some(kv) = n.item.kv {
            declared.push((
                &n.item.id,
                kv,
                n.at.clone(),
                format!("node '{}'", n.item.id),
            ));
        }
    }
    for b in &elements.branches {
        if let (BranchKind::Transformer, Some([hv, lv])) = (b.item.kind, b.item.kv) {
            let who = format!("transformer '{}'", b.item.id);
            declared.push((&b.item.from, hv, b.at.clone(), who.clone()));
            declared.push((&b.item.to, lv, b.at.clone(), who));
        }
    }
    let mut part_kv: HashMap<usize, (f64, String)> = HashMap::new();
    let mut conflicts = Vec::new();
    for (node, kv, at, who) in declared {
        let Some(&i) = index.get(node) else { continue };
        let root = find(&mut parent, i);
        match part_kv.get(&root) {
            None => {
                part_kv.insert(root, (kv, who));
            }
            Some((first, by)) if (first - kv).abs() > 1e-6 * first.abs().max(1.0) => {
                conflicts.push(VoltageConflict {
                    at,
                    message: format!(
                        "{who} puts node '{node}' at {kv} kV, but {by} puts the part it is connected to at {first} kV"
                    ),
                })
            }
            Some(_) => {}
        }
    }
    let mut out = HashMap::new();
    for (i, n) in elements.nodes.iter().enumerate() {
        let root = find(&mut parent, i);
        if let Some((kv, _)) = part_kv.get(&root) {
            out.insert(n.item.id.clone(), *kv);
        }
    }
    (out, conflicts)
}
