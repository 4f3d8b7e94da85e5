//! The compiled network model.
//!
//! A [`Spec`] names connectivity nodes, always-conducting branches (lines,
//! cables, transformers), switching devices, sources and loads by index.
//! [`Model::build`] merges the nodes that lines and cables join into
//! **sections** (what is energised or dead as one), so the topology
//! processor only ever looks at sections, switching devices and transformers.

use std::collections::HashMap;
use std::fmt;

/// Index of a section in [`Model::sections`].
pub type SecIdx = u32;

pub use gridscada_config::{BranchKind, SwitchKind};

#[derive(Debug, Clone, Default)]
pub struct NodeSpec {
    pub id: String,
    /// Groups nodes into one station on the generated screen.
    pub station: Option<String>,
    pub busbar: bool,
    /// Nominal voltage, resolved by the configuration's checks.
    pub kv: Option<f64>,
}

#[derive(Debug, Clone)]
pub struct BranchSpec {
    pub id: String,
    pub kind: BranchKind,
    pub from: usize,
    pub to: usize,
}

#[derive(Debug, Clone)]
pub struct SwitchSpec {
    pub id: String,
    pub name: String,
    pub kind: SwitchKind,
    pub from: usize,
    /// `None` for an earth switch: it connects `from` to earth.
    pub to: Option<usize>,
    pub normally_closed: bool,
}

#[derive(Debug, Clone)]
pub struct SourceSpec {
    pub id: String,
    pub name: String,
    pub node: usize,
    /// Index in [`Spec::groups`].
    pub group: usize,
}

#[derive(Debug, Clone)]
pub struct LoadSpec {
    pub id: String,
    pub node: usize,
    pub customers: u32,
}

/// Two source groups that may run in parallel; `overridable`: they may not,
/// but a supervisor may override the refusal (a make-before-break transfer).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ParallelRule {
    pub groups: (usize, usize),
    pub overridable: bool,
}

/// The network as configured, by index.
#[derive(Debug, Clone, Default)]
pub struct Spec {
    pub nodes: Vec<NodeSpec>,
    pub branches: Vec<BranchSpec>,
    pub switches: Vec<SwitchSpec>,
    pub sources: Vec<SourceSpec>,
    pub loads: Vec<LoadSpec>,
    pub groups: Vec<String>,
    pub parallel: Vec<ParallelRule>,
}

/// A spec that names something that is not there. The configuration's checks
/// catch these with file and line first; this is the backstop, so a plant
/// assembled in code cannot make the processor index out of bounds.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BuildError(pub String);

impl fmt::Display for BuildError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for BuildError {}

#[derive(Debug, Clone)]
pub struct Section {
    /// The busbar node's id if the section has one, else the line or cable's
    /// id, else its first node's id.
    pub id: String,
    pub kv: Option<f64>,
    pub nodes: Vec<usize>,
    pub busbar: bool,
    pub loads: Vec<usize>,
    pub sources: Vec<usize>,
    pub customers: u64,
    /// Earth switches on this section.
    pub earth_switches: Vec<usize>,
}

#[derive(Debug, Clone)]
pub struct Switch {
    pub id: String,
    pub name: String,
    pub kind: SwitchKind,
    pub a: SecIdx,
    /// `None`: an earth switch.
    pub b: Option<SecIdx>,
    pub normally_closed: bool,
}

#[derive(Debug, Clone)]
pub struct Transformer {
    pub id: String,
    pub a: SecIdx,
    pub b: SecIdx,
}

#[derive(Debug, Clone)]
pub struct Source {
    pub id: String,
    pub name: String,
    pub section: SecIdx,
    pub group: usize,
}

#[derive(Debug, Clone)]
pub struct Load {
    pub id: String,
    pub section: SecIdx,
    pub customers: u32,
}

#[derive(Debug, Clone)]
pub struct Model {
    pub nodes: Vec<NodeSpec>,
    /// Each node's section.
    pub node_section: Vec<SecIdx>,
    pub sections: Vec<Section>,
    pub switches: Vec<Switch>,
    pub transformers: Vec<Transformer>,
    pub sources: Vec<Source>,
    pub loads: Vec<Load>,
    pub groups: Vec<String>,
    /// group x group: `None` forbidden, `Some(overridable)` a listed pair
    /// (`Some(false)`: allowed; `Some(true)`: refused, a supervisor may
    /// override). A group may always parallel itself.
    parallel: Vec<Vec<Option<bool>>>,
    switch_index: HashMap<String, usize>,
    section_index: HashMap<String, SecIdx>,
}

/// Whether two source groups may run in parallel.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ParallelPermission {
    Allowed,
    /// Refused, but a supervisor may override.
    Overridable,
    Forbidden,
}

impl Model {
    pub fn build(spec: Spec) -> Result<Model, BuildError> {
        let n = spec.nodes.len();
        let node = |i: usize, what: &str, id: &str| -> Result<u32, BuildError> {
            if i < n {
                Ok(i as u32)
            } else {
                Err(BuildError(format!(
                    "{what} '{id}' names node #{i}, and there are {n}"
                )))
            }
        };
        // Lines and cables join nodes into sections.
        let mut join = crate::dsu::Dsu::new(n);
        for b in &spec.branches {
            let (f, t) = (node(b.from, "branch", &b.id)?, node(b.to, "branch", &b.id)?);
            if b.kind != BranchKind::Transformer {
                join.union(f, t);
            }
        }
        let mut root_section: HashMap<u32, SecIdx> = HashMap::new();
        let mut node_section = Vec::with_capacity(n);
        let mut sections: Vec<Section> = Vec::new();
        for i in 0..n as u32 {
            let root = join.find(i);
            let next = sections.len() as SecIdx;
            let s = *root_section.entry(root).or_insert(next);
            if s == next {
                sections.push(Section {
                    id: String::new(),
                    kv: None,
                    nodes: vec![],
                    busbar: false,
                    loads: vec![],
                    sources: vec![],
                    customers: 0,
                    earth_switches: vec![],
                });
            }
            let sec = &mut sections[s as usize];
            sec.nodes.push(i as usize);
            let nd = &spec.nodes[i as usize];
            sec.busbar |= nd.busbar;
            if sec.kv.is_none() {
                sec.kv = nd.kv;
            }
            node_section.push(s);
        }
        let mut cable_of: HashMap<SecIdx, &str> = HashMap::new();
        for b in &spec.branches {
            if b.kind != BranchKind::Transformer {
                cable_of.entry(node_section[b.from]).or_insert(&b.id);
            }
        }
        for (s, sec) in sections.iter_mut().enumerate() {
            let busbar = sec.nodes.iter().find(|&&i| spec.nodes[i].busbar);
            sec.id = match (busbar, cable_of.get(&(s as SecIdx))) {
                (Some(&i), _) => spec.nodes[i].id.clone(),
                (None, Some(cable)) => cable.to_string(),
                (None, None) => spec.nodes[sec.nodes[0]].id.clone(),
            };
        }
        let mut transformers = Vec::new();
        for b in &spec.branches {
            if b.kind == BranchKind::Transformer {
                transformers.push(Transformer {
                    id: b.id.clone(),
                    a: node_section[b.from],
                    b: node_section[b.to],
                });
            }
        }
        let mut switches = Vec::with_capacity(spec.switches.len());
        for (i, w) in spec.switches.iter().enumerate() {
            let a = node_section[node(w.from, "switch", &w.id)? as usize];
            let b = match w.to {
                Some(t) => Some(node_section[node(t, "switch", &w.id)? as usize]),
                None => None,
            };
            if (w.kind == SwitchKind::EarthSwitch) != b.is_none() {
                return Err(BuildError(format!(
                    "switch '{}': an earth switch has one side, every other device two",
                    w.id
                )));
            }
            if b.is_none() {
                sections[a as usize].earth_switches.push(i);
            }
            switches.push(Switch {
                id: w.id.clone(),
                name: w.name.clone(),
                kind: w.kind,
                a,
                b,
                normally_closed: w.normally_closed,
            });
        }
        let groups = spec.groups;
        let mut sources = Vec::with_capacity(spec.sources.len());
        for (i, s) in spec.sources.iter().enumerate() {
            let sec = node_section[node(s.node, "source", &s.id)? as usize];
            if s.group >= groups.len() {
                return Err(BuildError(format!(
                    "source '{}' names an unknown group",
                    s.id
                )));
            }
            sections[sec as usize].sources.push(i);
            sources.push(Source {
                id: s.id.clone(),
                name: s.name.clone(),
                section: sec,
                group: s.group,
            });
        }
        let mut loads = Vec::with_capacity(spec.loads.len());
        for (i, l) in spec.loads.iter().enumerate() {
            let sec = node_section[node(l.node, "load", &l.id)? as usize];
            sections[sec as usize].loads.push(i);
            sections[sec as usize].customers += u64::from(l.customers);
            loads.push(Load {
                id: l.id.clone(),
                section: sec,
                customers: l.customers,
            });
        }
        let g = groups.len();
        let mut parallel = vec![vec![None; g]; g];
        for rule in &spec.parallel {
            let (a, b) = rule.groups;
            if a >= g || b >= g {
                return Err(BuildError("a parallel rule names an unknown group".into()));
            }
            parallel[a][b] = Some(rule.overridable);
            parallel[b][a] = Some(rule.overridable);
        }
        let switch_index = switches
            .iter()
            .enumerate()
            .map(|(i, s)| (s.id.clone(), i))
            .collect();
        let section_index = sections
            .iter()
            .enumerate()
            .map(|(i, s)| (s.id.clone(), i as SecIdx))
            .collect();
        Ok(Model {
            nodes: spec.nodes,
            node_section,
            sections,
            switches,
            transformers,
            sources,
            loads,
            groups,
            parallel,
            switch_index,
            section_index,
        })
    }

    pub fn switch(&self, id: &str) -> Option<usize> {
        self.switch_index.get(id).copied()
    }

    pub fn section(&self, id: &str) -> Option<SecIdx> {
        self.section_index.get(id).copied()
    }

    pub fn parallel(&self, a: usize, b: usize) -> ParallelPermission {
        if a == b {
            return ParallelPermission::Allowed;
        }
        match self.parallel[a][b] {
            None => ParallelPermission::Forbidden,
            Some(false) => ParallelPermission::Allowed,
            Some(true) => ParallelPermission::Overridable,
        }
    }

    /// The ids of these sections.
    pub fn section_ids(&self, sections: &[SecIdx]) -> Vec<String> {
        sections
            .iter()
            .map(|&s| self.sections[s as usize].id.clone())
            .collect()
    }

    /// Customers on these sections.
    pub fn customers(&self, sections: &[SecIdx]) -> u64 {
        sections
            .iter()
            .map(|&s| self.sections[s as usize].customers)
            .sum()
    }
}
