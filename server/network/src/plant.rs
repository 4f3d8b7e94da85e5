//! The network of a configured plant: the model built from `[network]`
//! (shorthands expanded, voltages spread), and what binds each element to
//! the tag database: a device's status and command tags, a source's
//! in-service tag, a load's measured voltage.

use std::collections::HashMap;
use std::time::Duration;

use gridscada_config::{
    node_voltages, CommandBinding, InService, NetworkElements, Normally, Plant, StatusBinding,
};
use gridscada_tagdb::{QualityCode, Sample, Value};

use crate::model::{
    BranchSpec, BuildError, LoadSpec, Model, NodeSpec, ParallelRule, SourceSpec, Spec, SwitchSpec,
};
use crate::topology::Pos;

/// A plant's network and its bindings.
#[derive(Debug, Clone)]
pub struct Network {
    pub model: Model,
    /// Prefix of the tags the network publishes.
    pub prefix: String,
    pub select_timeout: Duration,
    /// Per device, in the model's order.
    pub status: Vec<Option<StatusBinding>>,
    pub command: Vec<Option<CommandBinding>>,
    /// Per source.
    pub in_service: Vec<Option<InService>>,
    /// Per load.
    pub energised: Vec<Option<String>>,
}

impl Network {
    /// The plant's network, if it has a `[network]`. The configuration's
    /// checks have passed, so an error here is a plant assembled in code.
    pub fn from_plant(plant: &Plant) -> Option<Result<Network, BuildError>> {
        let net = plant.network.as_ref()?;
        let elements = net.elements(&plant.panels, plant.microgrid.as_ref(), &|t| {
            plant.tag(t).is_some()
        });
        let timeout = Duration::from_secs_f64(net.select_timeout_s.get_ref().clamp(0.1, 86_400.0));
        Some(Network::from_elements(
            &elements,
            net.prefix.get_ref(),
            timeout,
        ))
    }

    /// The network of these elements (see [`gridscada_config::NetworkConfig::elements`]).
    pub fn from_elements(
        e: &NetworkElements,
        prefix: &str,
        select_timeout: Duration,
    ) -> Result<Network, BuildError> {
        let (kv, _) = node_voltages(e);
        let index: HashMap<&str, usize> = e
            .nodes
            .iter()
            .enumerate()
            .map(|(i, n)| (n.item.id.as_str(), i))
            .collect();
        let node = |id: &str, owner: &str| {
            index
                .get(id)
                .copied()
                .ok_or_else(|| BuildError(format!("{owner} names unknown node '{id}'")))
        };
        let mut spec = Spec {
            nodes: e
                .nodes
                .iter()
                .map(|n| NodeSpec {
                    id: n.item.id.clone(),
                    station: n.item.station.clone(),
                    busbar: n.item.busbar,
                    kv: kv.get(&n.item.id).copied(),
                })
                .collect(),
            ..Spec::default()
        };
        for b in &e.branches {
            let owner = format!("branch '{}'", b.item.id);
            spec.branches.push(BranchSpec {
                id: b.item.id.clone(),
                kind: b.item.kind,
                from: node(&b.item.from, &owner)?,
                to: node(&b.item.to, &owner)?,
            });
        }
        for s in &e.switches {
            let owner = format!("switch '{}'", s.item.id);
            spec.switches.push(SwitchSpec {
                id: s.item.id.clone(),
                name: s.item.name.clone(),
                kind: s.item.kind,
                from: node(&s.item.from, &owner)?,
                to: match &s.item.to {
                    Some(t) => Some(node(t, &owner)?),
                    None => None,
                },
                normally_closed: s.item.normally == Normally::Closed,
            });
        }
        let group = |g: &str, groups: &mut Vec<String>| {
            groups.iter().position(|x| x == g).unwrap_or_else(|| {
                groups.push(g.to_string());
                groups.len() - 1
            })
        };
        for s in &e.sources {
            let g = group(&s.item.group, &mut spec.groups);
            spec.sources.push(SourceSpec {
                id: s.item.id.clone(),
                name: s.item.name.clone(),
                node: node(&s.item.node, &format!("source '{}'", s.item.id))?,
                group: g,
            });
        }
        for l in &e.loads {
            spec.loads.push(LoadSpec {
                id: l.item.id.clone(),
                node: node(&l.item.node, &format!("load '{}'", l.item.id))?,
                customers: l.item.customers,
            });
        }
        for p in &e.parallel {
            let (a, b, overridable) = &p.item;
            let (Some(a), Some(b)) = (
                spec.groups.iter().position(|g| g == a),
                spec.groups.iter().position(|g| g == b),
            ) else {
                return Err(BuildError(format!(
                    "parallel names unknown group '{a}' or '{b}'"
                )));
            };
            spec.parallel.push(ParallelRule {
                groups: (a, b),
                overridable: *overridable,
            });
        }
        Ok(Network {
            model: Model::build(spec)?,
            prefix: prefix.to_string(),
            select_timeout,
            status: e.switches.iter().map(|s| s.item.status.clone()).collect(),
            command: e.switches.iter().map(|s| s.item.command.clone()).collect(),
            in_service: e
                .sources
                .iter()
                .map(|s| s.item.in_service.clone())
                .collect(),
            energised: e.loads.iter().map(|l| l.item.energised.clone()).collect(),
        })
    }

    /// Every tag the topology reads: devices' status and sources'
    /// in-service tags.
    pub fn input_tags(&self) -> impl Iterator<Item = &str> {
        self.status
            .iter()
            .flatten()
            .flat_map(|s| match s {
                StatusBinding::Tag(t) => vec![t.as_str()],
                StatusBinding::Pair { open, closed } => vec![open.as_str(), closed.as_str()],
            })
            .chain(self.in_service.iter().flatten().map(InService::tag))
    }
}

/// A good sample's value, or nothing.
fn good(sample: Option<&Sample>) -> Option<&Value> {
    sample
        .filter(|s| s.quality.code == QualityCode::Good)
        .map(|s| &s.value)
}

/// A device's position from its status tag(s): a bool (true closed), an
/// integer double point (1 open, 2 closed; 0 intermediate and 3
/// indeterminate are unknown), or two single points that must disagree.
/// Anything not Good is unknown; a device without status (a fuse) is
/// assumed in its normal position.
pub fn position<'a>(
    binding: Option<&StatusBinding>,
    normally_closed: bool,
    read: impl Fn(&str) -> Option<&'a Sample>,
) -> Pos {
    let closed = |b: bool| if b { Pos::Closed } else { Pos::Open };
    match binding {
        None => closed(normally_closed),
        Some(StatusBinding::Tag(t)) => match good(read(t)) {
            Some(Value::Bool(b)) => closed(*b),
            Some(v) => match v.as_i128() {
                Some(2) => Pos::Closed,
                Some(1) => Pos::Open,
                _ => Pos::Unknown,
            },
            None => Pos::Unknown,
        },
        Some(StatusBinding::Pair { open, closed: c }) => {
            match (
                good(read(open)).and_then(Value::as_bool),
                good(read(c)).and_then(Value::as_bool),
            ) {
                (Some(false), Some(true)) => Pos::Closed,
                (Some(true), Some(false)) => Pos::Open,
                _ => Pos::Unknown,
            }
        }
    }
}

/// A source's service state from its in-service binding (none: always in
/// service).
pub fn in_service<'a>(
    binding: Option<&InService>,
    read: impl Fn(&str) -> Option<&'a Sample>,
) -> Pos {
    match binding {
        None => Pos::Closed,
        Some(InService::Tag(t)) => match good(read(t)).and_then(Value::as_bool) {
            Some(true) => Pos::Closed,
            Some(false) => Pos::Open,
            None => Pos::Unknown,
        },
        Some(InService::Equals { tag, equals }) => match good(read(tag)).and_then(Value::as_i128) {
            Some(v) if v == i128::from(*equals) => Pos::Closed,
            Some(_) => Pos::Open,
            None => Pos::Unknown,
        },
    }
}
