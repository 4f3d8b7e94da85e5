//! The topology processor: from each switching device's position and each
//! source's service state, which sections are energised (and from which
//! sources), dead, earthed or unknown; which sources run in parallel; how
//! many loops the closed network has.
//!
//! One full recompute per change, over four disjoint-set forests of
//! sections: what certainly conducts (closed devices and transformers), what
//! may conduct (those and devices of unknown position), and the same two
//! for earth, which does not pass a transformer. A recompute is linear in
//! the size of the network; no state is kept between changes, so opening a
//! switch needs no undo.

use crate::dsu::Dsu;
use crate::model::{Model, ParallelPermission, SecIdx};

/// A switching device's position, or a source's service state (`Closed`: in
/// service).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Pos {
    Open,
    Closed,
    /// Bad or uncertain quality, an intermediate or indeterminate double
    /// point, no value yet.
    Unknown,
}

impl Pos {
    pub fn as_str(self) -> &'static str {
        match self {
            Pos::Open => "OPEN",
            Pos::Closed => "CLOSED",
            Pos::Unknown => "UNKNOWN",
        }
    }
}

/// What the processor reads: one position per switching device and one
/// service state per source, in the model's order.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Inputs {
    pub switches: Vec<Pos>,
    pub sources: Vec<Pos>,
}

impl Inputs {
    /// Every device in its normal position, every source in service.
    pub fn normal(model: &Model) -> Inputs {
        Inputs {
            switches: model
                .switches
                .iter()
                .map(|s| {
                    if s.normally_closed {
                        Pos::Closed
                    } else {
                        Pos::Open
                    }
                })
                .collect(),
            sources: vec![Pos::Closed; model.sources.len()],
        }
    }

    /// The same with one device moved.
    pub fn with(&self, switch: usize, pos: Pos) -> Inputs {
        let mut next = self.clone();
        next.switches[switch] = pos;
        next
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SectionState {
    Energised,
    Dead,
    Earthed,
    /// Energised or earthed depends on a device or source whose state is not
    /// known.
    Unknown,
    /// Energised and earthed at once: an earth fault made by switching.
    EnergisedEarthed,
}

impl SectionState {
    pub fn as_str(self) -> &'static str {
        match self {
            SectionState::Energised => "ENERGISED",
            SectionState::Dead => "DEAD",
            SectionState::Earthed => "EARTHED",
            SectionState::Unknown => "UNKNOWN",
            SectionState::EnergisedEarthed => "ENERGISED+EARTHED",
        }
    }
    pub fn energised(self) -> bool {
        matches!(
            self,
            SectionState::Energised | SectionState::EnergisedEarthed
        )
    }
    pub fn earthed(self) -> bool {
        matches!(self, SectionState::Earthed | SectionState::EnergisedEarthed)
    }
}

/// Why a section is unknown: a device or a source whose state is not known
/// and which could change the section's state.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Unknown {
    Switch(usize),
    Source(usize),
}

/// Sources feeding one connected part of the network.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Parallel {
    /// Sorted source indices, two or more.
    pub sources: Vec<usize>,
    /// Their groups, sorted, each once.
    pub groups: Vec<usize>,
    /// The strictest permission between any two of the groups.
    pub permission: ParallelPermission,
    /// False: only through a device or source whose state is unknown.
    pub certain: bool,
    /// A section of the connected part.
    pub section: SecIdx,
}

/// What closes a loop in the closed network.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Edge {
    Switch(usize),
    Transformer(usize),
}

const MAYBE_ENERGISED: u8 = 1;
const MAYBE_EARTHED: u8 = 2;
const MAYBE_MORE_SOURCES: u8 = 4;

#[derive(Debug, Clone, PartialEq)]
pub struct Topology {
    pub state: Vec<SectionState>,
    /// Each section's connected part through closed devices and
    /// transformers, numbered densely from 0.
    pub component: Vec<u32>,
    /// Per connected part, the sources in service feeding it, sorted.
    pub fed_by: Vec<Vec<usize>>,
    /// For an unknown section, what makes it so.
    pub unknown_because: Vec<Option<Unknown>>,
    flags: Vec<u8>,
    /// The edges that close each independent loop (their count is the
    /// number of loops).
    pub loop_closers: Vec<Edge>,
    pub parallels: Vec<Parallel>,
    /// Customers on dead or earthed sections.
    pub customers_off: u64,
    /// Customers on unknown sections.
    pub customers_unknown: u64,
}

impl Topology {
    pub fn sources_of(&self, section: SecIdx) -> &[usize] {
        &self.fed_by[self.component[section as usize] as usize]
    }
    /// Not certainly energised, but may be through a device or source of
    /// unknown state.
    pub fn maybe_energised(&self, section: SecIdx) -> bool {
        self.flags[section as usize] & MAYBE_ENERGISED != 0
    }
    /// Not certainly earthed, but may be through a device of unknown state.
    pub fn maybe_earthed(&self, section: SecIdx) -> bool {
        self.flags[section as usize] & MAYBE_EARTHED != 0
    }
    /// Energised, and may be fed by more sources than those known.
    pub fn maybe_more_sources(&self, section: SecIdx) -> bool {
        self.flags[section as usize] & MAYBE_MORE_SOURCES != 0
    }
    pub fn loops(&self) -> usize {
        self.loop_closers.len()
    }
    pub fn same_component(&self, a: SecIdx, b: SecIdx) -> bool {
        self.component[a as usize] == self.component[b as usize]
    }
}

fn strictest(model: &Model, groups: &[usize]) -> ParallelPermission {
    let mut worst = ParallelPermission::Allowed;
    for (i, &a) in groups.iter().enumerate() {
        for &b in &groups[i + 1..] {
            match model.parallel(a, b) {
                ParallelPermission::Forbidden => return ParallelPermission::Forbidden,
                ParallelPermission::Overridable => worst = ParallelPermission::Overridable,
                ParallelPermission::Allowed => {}
            }
        }
    }
    worst
}

/// The source groups of these sources, sorted, each once.
pub fn groups_of(model: &Model, sources: &[usize]) -> Vec<usize> {
    let mut groups: Vec<usize> = sources.iter().map(|&s| model.sources[s].group).collect();
    groups.sort_unstable();
    groups.dedup();
    groups
}

fn parallel_of(model: &Model, mut sources: Vec<usize>, certain: bool, section: SecIdx) -> Parallel {
    sources.sort_unstable();
    let groups = groups_of(model, &sources);
    Parallel {
        permission: strictest(model, &groups),
        sources,
        groups,
        certain,
        section,
    }
}

/// The network's state from these inputs. `inputs` must have one entry per
/// device and per source of `model`; a shorter list reads as unknown.
pub fn compute(model: &Model, inputs: &Inputs) -> Topology {
    let ns = model.sections.len();
    let pos = |i: usize| inputs.switches.get(i).copied().unwrap_or(Pos::Unknown);
    let service = |i: usize| inputs.sources.get(i).copied().unwrap_or(Pos::Unknown);
    // Definite and possible conduction; definite and possible earth paths.
    let mut definite = Dsu::new(ns);
    let mut possible = Dsu::new(ns);
    let mut earth = Dsu::new(ns);
    let mut maybe_earth = Dsu::new(ns);
    let mut loop_closers = Vec::new();
    for (i, w) in model.switches.iter().enumerate() {
        let Some(b) = w.b else { continue };
        if pos(i) == Pos::Closed {
            if !definite.union(w.a, b) {
                loop_closers.push(Edge::Switch(i));
            }
            earth.union(w.a, b);
        }
    }
    for (i, t) in model.transformers.iter().enumerate() {
        if !definite.union(t.a, t.b) {
            loop_closers.push(Edge::Transformer(i));
        }
        possible.union(t.a, t.b);
    }
    // Unknown devices that join two definite parts are what make a section
    // unknown; one inside a part changes nothing.
    let mut because_possible: Vec<Option<Unknown>> = vec![None; ns];
    let mut because_earth: Vec<Option<Unknown>> = vec![None; ns];
    // (Earth has its own: a device across a transformer's two sides joins
    // nothing for energy and two parts for earth.)
    let (mut unknown_joins, mut unknown_earth_joins) = (Vec::new(), Vec::new());
    for (i, w) in model.switches.iter().enumerate() {
        let p = pos(i);
        if p == Pos::Open {
            continue;
        }
        match w.b {
            Some(b) => {
                possible.union(w.a, b);
                maybe_earth.union(w.a, b);
                if p == Pos::Unknown && definite.find(w.a) != definite.find(b) {
                    unknown_joins.push(i);
                }
                if p == Pos::Unknown && earth.find(w.a) != earth.find(b) {
                    unknown_earth_joins.push(i);
                }
            }
            None if p == Pos::Unknown => unknown_earth_joins.push(i),
            None => {}
        }
    }
    // Component numbering and the sources of each part.
    let mut dense = vec![u32::MAX; ns];
    let mut component = Vec::with_capacity(ns);
    let mut parts = 0u32;
    for s in 0..ns as u32 {
        let root = definite.find(s) as usize;
        if dense[root] == u32::MAX {
            dense[root] = parts;
            parts += 1;
        }
        component.push(dense[root]);
    }
    let mut fed_by: Vec<Vec<usize>> = vec![Vec::new(); parts as usize];
    let mut possible_sources = vec![0u32; ns];
    for (i, src) in model.sources.iter().enumerate() {
        match service(i) {
            Pos::Closed => {
                fed_by[component[src.section as usize] as usize].push(i);
                possible_sources[possible.find(src.section) as usize] += 1;
            }
            Pos::Unknown => {
                let root = possible.find(src.section) as usize;
                possible_sources[root] += 1;
                because_possible[root].get_or_insert(Unknown::Source(i));
            }
            Pos::Open => {}
        }
    }
    let mut earthed = vec![false; ns];
    let mut maybe_earthed = vec![false; ns];
    for (i, w) in model.switches.iter().enumerate() {
        if w.b.is_some() {
            continue;
        }
        match pos(i) {
            Pos::Closed => {
                earthed[earth.find(w.a) as usize] = true;
                maybe_earthed[maybe_earth.find(w.a) as usize] = true;
            }
            Pos::Unknown => maybe_earthed[maybe_earth.find(w.a) as usize] = true,
            Pos::Open => {}
        }
    }
    for &i in &unknown_joins {
        let root = possible.find(model.switches[i].a) as usize;
        because_possible[root].get_or_insert(Unknown::Switch(i));
    }
    for &i in &unknown_earth_joins {
        let root = maybe_earth.find(model.switches[i].a) as usize;
        because_earth[root].get_or_insert(Unknown::Switch(i));
    }
    let mut state = Vec::with_capacity(ns);
    let mut unknown_because = vec![None; ns];
    let mut flags = vec![0u8; ns];
    let (mut customers_off, mut customers_unknown) = (0u64, 0u64);
    for s in 0..ns as u32 {
        let fed = fed_by[component[s as usize] as usize].len() as u32;
        let proot = possible.find(s) as usize;
        let is_earthed = earthed[earth.find(s) as usize];
        let eroot = maybe_earth.find(s) as usize;
        let may_earth = maybe_earthed[eroot] && !is_earthed;
        if may_earth {
            flags[s as usize] |= MAYBE_EARTHED;
        }
        let st = if fed > 0 {
            if possible_sources[proot] > fed {
                flags[s as usize] |= MAYBE_MORE_SOURCES;
            }
            if is_earthed {
                SectionState::EnergisedEarthed
            } else {
                SectionState::Energised
            }
        } else if possible_sources[proot] > 0 {
            flags[s as usize] |= MAYBE_ENERGISED;
            unknown_because[s as usize] = because_possible[proot];
            SectionState::Unknown
        } else if may_earth {
            unknown_because[s as usize] = because_earth[eroot];
            SectionState::Unknown
        } else if is_earthed {
            SectionState::Earthed
        } else {
            SectionState::Dead
        };
        let customers = model.sections[s as usize].customers;
        match st {
            SectionState::Dead | SectionState::Earthed => customers_off += customers,
            SectionState::Unknown => customers_unknown += customers,
            _ => {}
        }
        state.push(st);
    }
    // Parallels: certain ones per definite part, uncertain ones per possible
    // part whose sources are not all in one definite part.
    let mut parallels = Vec::new();
    for (part, sources) in fed_by.iter().enumerate() {
        if sources.len() >= 2 {
            let section = model.sources[sources[0]].section;
            debug_assert_eq!(component[section as usize] as usize, part);
            parallels.push(parallel_of(model, sources.clone(), true, section));
        }
    }
    let mut by_possible: Vec<Vec<usize>> = vec![Vec::new(); ns];
    for (i, src) in model.sources.iter().enumerate() {
        if service(i) != Pos::Open {
            by_possible[possible.find(src.section) as usize].push(i);
        }
    }
    for sources in by_possible.into_iter().filter(|s| s.len() >= 2) {
        let first = component[model.sources[sources[0]].section as usize];
        let one_part = sources.iter().all(|&i| {
            service(i) == Pos::Closed && component[model.sources[i].section as usize] == first
        });
        if !one_part {
            let section = model.sources[sources[0]].section;
            parallels.push(parallel_of(model, sources, false, section));
        }
    }
    Topology {
        state,
        component,
        fed_by,
        unknown_because,
        flags,
        loop_closers,
        parallels,
        customers_off,
        customers_unknown,
    }
}
