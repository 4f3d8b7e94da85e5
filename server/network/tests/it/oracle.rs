//! The topology processor against a plain breadth-first search from the
//! sources over closed devices, on random networks: energised sets, the
//! sources feeding each section, earthed and unknown sections, loops and
//! parallels must agree exactly.

use std::collections::{BTreeSet, VecDeque};

use gridscada_network::model::Model;
use gridscada_network::*;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

fn random_model(rng: &mut StdRng) -> Model {
    let nodes = rng.random_range(1..=200usize);
    let mut spec = Spec {
        nodes: (0..nodes)
            .map(|i| NodeSpec {
                id: format!("n{i}"),
                busbar: rng.random_bool(0.3),
                ..NodeSpec::default()
            })
            .collect(),
        groups: (0..rng.random_range(1..=3usize))
            .map(|g| format!("g{g}"))
            .collect(),
        ..Spec::default()
    };
    for i in 0..rng.random_range(0..=nodes / 4) {
        spec.branches.push(BranchSpec {
            id: format!("c{i}"),
            kind: BranchKind::Cable,
            from: rng.random_range(0..nodes),
            to: rng.random_range(0..nodes),
        });
    }
    for i in 0..rng.random_range(0..=20usize) {
        spec.branches.push(BranchSpec {
            id: format!("t{i}"),
            kind: BranchKind::Transformer,
            from: rng.random_range(0..nodes),
            to: rng.random_range(0..nodes),
        });
    }
    for i in 0..rng.random_range(0..=300usize) {
        let earth = rng.random_bool(0.15);
        spec.switches.push(SwitchSpec {
            id: format!("s{i}"),
            name: format!("S{i}"),
            kind: if earth {
                SwitchKind::EarthSwitch
            } else {
                SwitchKind::LoadBreakSwitch
            },
            from: rng.random_range(0..nodes),
            to: (!earth).then(|| rng.random_range(0..nodes)),
            normally_closed: rng.random_bool(0.5),
        });
    }
    let groups = spec.groups.len();
    for i in 0..rng.random_range(0..=6usize) {
        spec.sources.push(SourceSpec {
            id: format!("src{i}"),
            name: format!("Source {i}"),
            node: rng.random_range(0..nodes),
            group: rng.random_range(0..groups),
        });
    }
    for i in 0..rng.random_range(0..=nodes) {
        spec.loads.push(LoadSpec {
            id: format!("l{i}"),
            node: rng.random_range(0..nodes),
            customers: rng.random_range(0..50),
        });
    }
    for a in 0..groups {
        for b in a + 1..groups {
            if rng.random_bool(0.5) {
                spec.parallel.push(ParallelRule {
                    groups: (a, b),
                    overridable: rng.random_bool(0.5),
                });
            }
        }
    }
    Model::build(spec).expect("a generated spec is well formed")
}

fn random_inputs(rng: &mut StdRng, model: &Model) -> Inputs {
    let mut pick = |closed: f64, open: f64| {
        let x: f64 = rng.random();
        if x < closed {
            Pos::Closed
        } else if x < closed + open {
            Pos::Open
        } else {
            Pos::Unknown
        }
    };
    Inputs {
        switches: model.switches.iter().map(|_| pick(0.45, 0.45)).collect(),
        sources: model.sources.iter().map(|_| pick(0.7, 0.15)).collect(),
    }
}

/// Who is joined to whom across devices whose position is in `conducting`,
/// and across transformers when `transformers`.
fn adjacency(
    model: &Model,
    inputs: &Inputs,
    conducting: &[Pos],
    transformers: bool,
) -> Vec<Vec<u32>> {
    let mut adj: Vec<Vec<u32>> = vec![vec![]; model.sections.len()];
    for (i, w) in model.switches.iter().enumerate() {
        if let Some(b) = w.b {
            if conducting.contains(&inputs.switches[i]) {
                adj[w.a as usize].push(b);
                adj[b as usize].push(w.a);
            }
        }
    }
    if transformers {
        for t in &model.transformers {
            adj[t.a as usize].push(t.b);
            adj[t.b as usize].push(t.a);
        }
    }
    adj
}

/// Sections reached from `starts`, breadth first.
fn reach(adj: &[Vec<u32>], starts: impl IntoIterator<Item = u32>) -> Vec<bool> {
    let mut seen = vec![false; adj.len()];
    let mut queue: VecDeque<u32> = VecDeque::new();
    for s in starts {
        if !seen[s as usize] {
            seen[s as usize] = true;
            queue.push_back(s);
        }
    }
    while let Some(s) = queue.pop_front() {
        for &t in &adj[s as usize] {
            if !seen[t as usize] {
                seen[t as usize] = true;
                queue.push_back(t);
            }
        }
    }
    seen
}

/// Each section's connected part, numbered by labelling; and the count.
fn label(adj: &[Vec<u32>]) -> (Vec<usize>, usize) {
    let mut label = vec![usize::MAX; adj.len()];
    let mut parts = 0;
    for s in 0..adj.len() {
        if label[s] == usize::MAX {
            let mut queue = VecDeque::from([s as u32]);
            label[s] = parts;
            while let Some(x) = queue.pop_front() {
                for &t in &adj[x as usize] {
                    if label[t as usize] == usize::MAX {
                        label[t as usize] = parts;
                        queue.push_back(t);
                    }
                }
            }
            parts += 1;
        }
    }
    (label, parts)
}

struct Expected {
    state: Vec<SectionState>,
    fed_by: Vec<Vec<usize>>,
    loops: usize,
    certain: BTreeSet<Vec<usize>>,
    uncertain: BTreeSet<Vec<usize>>,
    customers_off: u64,
    customers_unknown: u64,
}

fn oracle(model: &Model, inputs: &Inputs) -> Expected {
    let n = model.sections.len();
    let closed = [Pos::Closed];
    let maybe = [Pos::Closed, Pos::Unknown];
    let energy = adjacency(model, inputs, &closed, true);
    let maybe_energy = adjacency(model, inputs, &maybe, true);
    let mut fed_by = vec![vec![]; n];
    for (i, src) in model.sources.iter().enumerate() {
        if inputs.sources[i] == Pos::Closed {
            for (s, r) in reach(&energy, [src.section]).iter().enumerate() {
                if *r {
                    fed_by[s].push(i);
                }
            }
        }
    }
    let possible = reach(
        &maybe_energy,
        model
            .sources
            .iter()
            .enumerate()
            .filter(|(i, _)| inputs.sources[*i] != Pos::Open)
            .map(|(_, s)| s.section),
    );
    let earth_starts = |states: &[Pos]| -> Vec<u32> {
        model
            .switches
            .iter()
            .enumerate()
            .filter(|(i, w)| w.b.is_none() && states.contains(&inputs.switches[*i]))
            .map(|(_, w)| w.a)
            .collect()
    };
    let earthed = reach(
        &adjacency(model, inputs, &closed, false),
        earth_starts(&closed),
    );
    let maybe_earthed = reach(
        &adjacency(model, inputs, &maybe, false),
        earth_starts(&maybe),
    );
    let mut state = Vec::with_capacity(n);
    let (mut off, mut unknown) = (0, 0);
    for s in 0..n {
        let st = if !fed_by[s].is_empty() {
            if earthed[s] {
                SectionState::EnergisedEarthed
            } else {
                SectionState::Energised
            }
        } else if possible[s] || (maybe_earthed[s] && !earthed[s]) {
            SectionState::Unknown
        } else if earthed[s] {
            SectionState::Earthed
        } else {
            SectionState::Dead
        };
        match st {
            SectionState::Dead | SectionState::Earthed => off += model.sections[s].customers,
            SectionState::Unknown => unknown += model.sections[s].customers,
            _ => {}
        }
        state.push(st);
    }
    let (label, parts) = label(&energy);
    let closed_edges = model
        .switches
        .iter()
        .enumerate()
        .filter(|(i, w)| w.b.is_some() && inputs.switches[*i] == Pos::Closed)
        .count()
        + model.transformers.len();
    let mut certain = BTreeSet::new();
    for part in 0..parts {
        let sources: Vec<usize> = (0..model.sources.len())
            .filter(|&i| {
                inputs.sources[i] == Pos::Closed && label[model.sources[i].section as usize] == part
            })
            .collect();
        if sources.len() >= 2 {
            certain.insert(sources);
        }
    }
    let mut uncertain = BTreeSet::new();
    let (plabel, pparts) = super::oracle::label(&maybe_energy);
    for part in 0..pparts {
        let sources: Vec<usize> = (0..model.sources.len())
            .filter(|&i| {
                inputs.sources[i] != Pos::Open && plabel[model.sources[i].section as usize] == part
            })
            .collect();
        if sources.len() >= 2 {
            let first = label[model.sources[sources[0]].section as usize];
            let one = sources.iter().all(|&i| {
                inputs.sources[i] == Pos::Closed
                    && label[model.sources[i].section as usize] == first
            });
            if !one {
                uncertain.insert(sources);
            }
        }
    }
    Expected {
        state,
        fed_by,
        loops: closed_edges + parts - n,
        certain,
        uncertain,
        customers_off: off,
        customers_unknown: unknown,
    }
}

fn dump(model: &Model, inputs: &Inputs) -> String {
    let mut out = String::new();
    for (i, w) in model.switches.iter().enumerate() {
        out += &format!("{} {:?}-{:?} {:?}; ", w.id, w.a, w.b, inputs.switches[i]);
    }
    for t in &model.transformers {
        out += &format!("{} {}={}; ", t.id, t.a, t.b);
    }
    for (i, s) in model.sources.iter().enumerate() {
        out += &format!(
            "{} @{} g{} {:?}; ",
            s.id, s.section, s.group, inputs.sources[i]
        );
    }
    out
}

#[test]
fn the_processor_agrees_with_a_breadth_first_search_on_random_networks() {
    let cases: u64 = std::env::var("TOPOLOGY_CASES")
        .ok()
        .and_then(|c| c.parse().ok())
        .unwrap_or(5_000);
    for seed in 0..cases {
        let mut rng = StdRng::seed_from_u64(seed);
        let model = random_model(&mut rng);
        let inputs = random_inputs(&mut rng, &model);
        let got = compute(&model, &inputs);
        let want = oracle(&model, &inputs);
        let ctx = || format!("seed {seed}: {}", dump(&model, &inputs));
        assert_eq!(got.state, want.state, "states, {}", ctx());
        for s in 0..model.sections.len() as u32 {
            assert_eq!(
                got.sources_of(s),
                want.fed_by[s as usize],
                "sources of {s}, {}",
                ctx()
            );
            if got.state[s as usize] == SectionState::Unknown {
                let why = got.unknown_because[s as usize];
                let unknown = match why {
                    Some(Unknown::Switch(i)) => inputs.switches[i] == Pos::Unknown,
                    Some(Unknown::Source(i)) => inputs.sources[i] == Pos::Unknown,
                    None => false,
                };
                assert!(unknown, "section {s} unknown because {why:?}, {}", ctx());
            }
        }
        assert_eq!(got.loops(), want.loops, "loops, {}", ctx());
        let certain: BTreeSet<Vec<usize>> = got
            .parallels
            .iter()
            .filter(|p| p.certain)
            .map(|p| p.sources.clone())
            .collect();
        let uncertain: BTreeSet<Vec<usize>> = got
            .parallels
            .iter()
            .filter(|p| !p.certain)
            .map(|p| p.sources.clone())
            .collect();
        assert_eq!(certain, want.certain, "parallels, {}", ctx());
        assert_eq!(uncertain, want.uncertain, "uncertain parallels, {}", ctx());
        assert_eq!(got.customers_off, want.customers_off, "{}", ctx());
        assert_eq!(got.customers_unknown, want.customers_unknown, "{}", ctx());
    }
}
