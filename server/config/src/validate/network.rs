//! The switching network (`[network]`): ids, what each element names (nodes,
//! tags, panels, groups), the tags' kinds, nodes nothing connects to, and
//! voltages that disagree.

use std::collections::{HashMap, HashSet};
use std::ops::Range;

use gridscada_tagdb::ValueKind;

use crate::model::*;

use super::{need_tag, positive, Ctx};

/// `^[a-z][a-z0-9_]{0,63}$`: ids become parts of tag names and URLs.
pub fn is_network_id(id: &str) -> bool {
    let mut chars = id.chars();
    matches!(chars.next(), Some('a'..='z'))
        && id.len() <= 64
        && chars.all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_')
}

struct Ids<'a> {
    what: &'static str,
    seen: HashMap<&'a str, Range<usize>>,
}

impl<'a> Ids<'a> {
    fn new(what: &'static str) -> Self {
        Ids {
            what,
            seen: HashMap::new(),
        }
    }
    fn add(&mut self, cx: &mut Ctx<'_>, id: &'a str, at: &Range<usize>) {
        if !is_network_id(id) {
            cx.err(
                0,
                at.clone(),
                format!(
                    "[network] {} id '{id}' must start with a lowercase letter and hold only lowercase letters, digits and '_' (at most 64)",
                    self.what
                ),
            );
        }
        if let Some(first) = self.seen.get(id) {
            let first = cx.place(0, first.clone());
            cx.err(
                0,
                at.clone(),
                format!(
                    "[network] duplicate {} id '{id}' (first defined at {first})",
                    self.what
                ),
            );
        } else {
            self.seen.insert(id, at.clone());
        }
    }
}

pub(super) fn check_network<'t>(
    cx: &mut Ctx<'_>,
    net: &NetworkConfig,
    main: &MainFile,
    lookup: &dyn Fn(&str) -> Option<&'t TagConfig>,
) {
    let prefix = net.prefix.get_ref();
    let prefix_ok = prefix
        .chars()
        .next()
        .is_some_and(|c| c.is_ascii_alphabetic())
        && prefix
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_');
    if !prefix_ok {
        cx.err(
            0,
            net.prefix.span(),
            format!("[network] prefix '{prefix}' must be letters, digits and '_', starting with a letter"),
        );
    }
    positive(cx, "[network]", "select_timeout_s", &net.select_timeout_s);

    let mut levels = Ids::new("level");
    for l in &net.levels {
        levels.add(cx, l.id.get_ref(), &l.id.span());
        let kv = *l.kv.get_ref();
        if !(kv.is_finite() && kv > 0.0) {
            cx.err(
                0,
                l.kv.span(),
                format!(
                    "[network] level '{}': kv must be a positive number",
                    l.id.get_ref()
                ),
            );
        }
    }
    for n in &net.nodes {
        if let Some(level) = &n.level {
            if !levels.seen.contains_key(level.get_ref().as_str()) {
                cx.err(
                    0,
                    level.span(),
                    format!(
                        "[network] node '{}': unknown level '{}'",
                        n.id.get_ref(),
                        level.get_ref()
                    ),
                );
            }
        }
    }
    for b in &net.branches {
        match (b.kind, &b.kv) {
            (BranchKind::Transformer, None) => cx.err(
                0,
                b.id.span(),
                format!(
                    "[network] transformer '{}' needs kv = [from side, to side], its rated voltages",
                    b.id.get_ref()
                ),
            ),
            (BranchKind::Transformer, Some(kv)) => {
                if !kv.get_ref().iter().all(|v| v.is_finite() && *v > 0.0) {
                    cx.err(0, kv.span(), format!("[network] transformer '{}': kv must be two positive numbers", b.id.get_ref()));
                }
            }
            (_, Some(kv)) => cx.err(
                0,
                kv.span(),
                format!("[network] branch '{}': only a transformer has kv", b.id.get_ref()),
            ),
            (_, None) => {}
        }
    }
    for p in &net.parallel {
        if p.groups.get_ref().len() != 2 {
            cx.err(
                0,
                p.groups.span(),
                "[network] parallel: groups must name two source groups",
            );
        }
    }
    for np in &net.panels {
        match main
            .panels
            .iter()
            .find(|p| p.id.get_ref() == np.panel.get_ref())
        {
            None => cx.err(
                0,
                np.panel.span(),
                format!(
                    "[network] panel '{}': no [[panel]] has this id",
                    np.panel.get_ref()
                ),
            ),
            Some(p) => {
                let given = np.customers.get_ref().len();
                if given != 0 && given != usize::from(*p.zones.get_ref()) {
                    cx.err(
                        0,
                        np.customers.span(),
                        format!(
                            "[network] panel '{}': customers lists {given} zones, the panel has {}",
                            np.panel.get_ref(),
                            p.zones.get_ref()
                        ),
                    );
                }
            }
        }
    }
    if let (Some(mg), None) = (&net.microgrid, &main.microgrid) {
        cx.err(
            0,
            mg.node.span(),
            "[network] microgrid: there is no [microgrid] to bring in",
        );
    }

    let elements = net.elements(&main.panels, main.microgrid.as_ref(), &|t| {
        lookup(t).is_some()
    });
    check_elements(cx, &elements, lookup);
}

fn check_elements<'t>(
    cx: &mut Ctx<'_>,
    e: &NetworkElements,
    lookup: &dyn Fn(&str) -> Option<&'t TagConfig>,
) {
    // Nodes and branches name sections, so they share one set of ids.
    let mut places = Ids::new("node or branch");
    for n in &e.nodes {
        places.add(cx, &n.item.id, &n.at);
    }
    let nodes: HashSet<&str> = e.nodes.iter().map(|n| n.item.id.as_str()).collect();
    for b in &e.branches {
        places.add(cx, &b.item.id, &b.at);
    }
    let mut used: HashSet<&str> = HashSet::new();
    let node_ref =
        |cx: &mut Ctx<'_>, owner: &str, field: &str, node: &'_ str, at: &Range<usize>| {
            if !nodes.contains(node) {
                cx.err(
                    0,
                    at.clone(),
                    format!("[network] {owner}: {field} names unknown node '{node}'"),
                );
            }
        };
    for b in &e.branches {
        let owner = format!("branch '{}'", b.item.id);
        node_ref(cx, &owner, "from", &b.item.from, &b.at);
        node_ref(cx, &owner, "to", &b.item.to, &b.at);
        if b.item.from == b.item.to {
            cx.err(
                0,
                b.at.clone(),
                format!(
                    "[network] {owner} connects node '{}' to itself",
                    b.item.from
                ),
            );
        }
        used.extend([b.item.from.as_str(), b.item.to.as_str()]);
    }
    let mut switches = Ids::new("switch");
    let mut commands: HashMap<&str, &str> = HashMap::new();
    let bool_ = [ValueKind::Bool];
    for s in &e.switches {
        let w = &s.item;
        switches.add(cx, &w.id, &s.at);
        let label = format!("switch '{}'", w.id);
        let owner = format!("[network] {label}");
        node_ref(cx, &label, "from", &w.from, &s.at);
        used.insert(&w.from);
        match (&w.to, w.kind) {
            (Some(_), SwitchKind::EarthSwitch) => cx.err(
                0,
                s.at.clone(),
                format!("{owner}: an earth switch connects `from` to earth and has no `to`"),
            ),
            (None, kind) if kind != SwitchKind::EarthSwitch => cx.err(
                0,
                s.at.clone(),
                format!(
                    "{owner}: a {} needs `to`, the node on its other side",
                    kind.as_str()
                ),
            ),
            (Some(to), _) => {
                node_ref(cx, &label, "to", to, &s.at);
                used.insert(to);
                if *to == w.from {
                    cx.err(
                        0,
                        s.at.clone(),
                        format!("{owner} connects node '{to}' to itself"),
                    );
                }
            }
            (None, _) => {}
        }
        match &w.status {
            None if w.kind != SwitchKind::Fuse => cx.err(
                0,
                s.at.clone(),
                format!("{owner}: needs `status`, the tag its position is read from (only a fuse may go without)"),
            ),
            None => {}
            Some(StatusBinding::Tag(t)) => {
                need_tag(cx, s.at.clone(), &owner, t, lookup, &[ValueKind::Bool, ValueKind::Int], false)
            }
            Some(StatusBinding::Pair { open, closed }) => {
                need_tag(cx, s.at.clone(), &owner, open, lookup, &bool_, false);
                need_tag(cx, s.at.clone(), &owner, closed, lookup, &bool_, false);
            }
        }
        if let Some(c) = &w.command {
            need_tag(cx, s.at.clone(), &owner, c.tag(), lookup, &bool_, true);
            if let Some(first) = commands.insert(c.tag(), &w.id) {
                cx.err(
                    0,
                    s.at.clone(),
                    format!(
                        "{owner}: command tag '{}' already commands switch '{first}'",
                        c.tag()
                    ),
                );
            }
        }
    }
    let mut sources = Ids::new("source");
    let mut groups: HashSet<&str> = HashSet::new();
    for s in &e.sources {
        sources.add(cx, &s.item.id, &s.at);
        let label = format!("source '{}'", s.item.id);
        let owner = format!("[network] {label}");
        node_ref(cx, &label, "node", &s.item.node, &s.at);
        used.insert(&s.item.node);
        groups.insert(&s.item.group);
        match &s.item.in_service {
            Some(InService::Tag(t)) => need_tag(cx, s.at.clone(), &owner, t, lookup, &bool_, false),
            Some(InService::Equals { tag, .. }) => need_tag(
                cx,
                s.at.clone(),
                &owner,
                tag,
                lookup,
                &[ValueKind::Int],
                false,
            ),
            None => {}
        }
    }
    let mut loads = Ids::new("load");
    for l in &e.loads {
        loads.add(cx, &l.item.id, &l.at);
        let label = format!("load '{}'", l.item.id);
        let owner = format!("[network] {label}");
        node_ref(cx, &label, "node", &l.item.node, &l.at);
        used.insert(&l.item.node);
        if let Some(t) = &l.item.energised {
            need_tag(cx, l.at.clone(), &owner, t, lookup, &bool_, false);
        }
    }
    for p in &e.parallel {
        for g in [&p.item.0, &p.item.1] {
            if !groups.contains(g.as_str()) {
                cx.err(
                    0,
                    p.at.clone(),
                    format!("[network] parallel: no source is in group '{g}'"),
                );
            }
        }
    }
    for n in &e.nodes {
        if !used.contains(n.item.id.as_str()) {
            cx.err(
                0,
                n.at.clone(),
                format!("[network] node '{}' is dangling: no branch, switch, source or load connects to it", n.item.id),
            );
        }
    }
    for c in node_voltages(e).1 {
        cx.err(
            0,
            c.at,
            format!("[network] voltage conflict: {}", c.message),
        );
    }
}
