//! Topology update time at distribution scale:
//! `cargo bench -p gridscada-network --bench topology`.
//!
//! A generated network of 100 rings, each of 20 ring main units between two
//! ends on its own primary busbar: per RMU two ring switches, two tee
//! breakers, an earth switch and three transformers behind each tee; 10,000
//! switching devices and 20,000 sections. Each iteration toggles one random
//! ring switch and times the recompute, and the recompute plus the preview
//! against the previous result (what a select shows). The peer in the same
//! run: a plain breadth-first search from every source over the closed
//! devices and transformers, which finds only the energised set (no earth,
//! no unknown, no loops or parallels). Prints p50/p99 and the memory of the
//! model and of one result. Figures only.

use std::time::Instant;

use gridscada_network::*;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

const RINGS: usize = 100;
const RMUS: usize = 20;
const TX_PER_TEE: usize = 3;

fn rss_kib() -> u64 {
    std::fs::read_to_string("/proc/self/statm")
        .ok()
        .and_then(|s| s.split_whitespace().nth(1)?.parse::<u64>().ok())
        .map_or(0, |pages| pages * 4)
}

fn network() -> Model {
    let mut spec = Spec {
        groups: vec!["grid".into()],
        ..Spec::default()
    };
    let node = |spec: &mut Spec, id: String, busbar: bool| {
        spec.nodes.push(NodeSpec {
            id,
            busbar,
            ..NodeSpec::default()
        });
        spec.nodes.len() - 1
    };
    let switch = |spec: &mut Spec, id: String, kind, from, to, closed| {
        spec.switches.push(SwitchSpec {
            name: id.to_uppercase(),
            id,
            kind,
            from,
            to,
            normally_closed: closed,
        })
    };
    for r in 0..RINGS {
        let primary = node(&mut spec, format!("p{r}_bb"), true);
        spec.sources.push(SourceSpec {
            id: format!("grid{r}"),
            name: format!("Primary {r}"),
            node: primary,
            group: 0,
        });
        let mut previous_end = primary;
        for u in 0..RMUS {
            let id = format!("r{r}u{u}");
            let bb = node(&mut spec, format!("{id}_bb"), true);
            let ring_in = if u == 0 {
                primary
            } else {
                let far = node(&mut spec, format!("{id}_in"), false);
                spec.branches.push(BranchSpec {
                    id: format!("{id}_c"),
                    kind: BranchKind::Cable,
                    from: previous_end,
                    to: far,
                });
                switch(
                    &mut spec,
                    format!("{id}_e"),
                    SwitchKind::EarthSwitch,
                    far,
                    None,
                    false,
                );
                far
            };
            switch(
                &mut spec,
                format!("{id}_s1"),
                SwitchKind::LoadBreakSwitch,
                ring_in,
                Some(bb),
                true,
            );
            let out = if u == RMUS - 1 {
                primary
            } else {
                node(&mut spec, format!("{id}_out"), false)
            };
            // The ring's normally-open point in the middle.
            switch(
                &mut spec,
                format!("{id}_s2"),
                SwitchKind::LoadBreakSwitch,
                bb,
                Some(out),
                u != RMUS / 2,
            );
            if u == 0 {
                switch(
                    &mut spec,
                    format!("{id}_e"),
                    SwitchKind::EarthSwitch,
                    bb,
                    None,
                    false,
                );
            }
            previous_end = out;
            for t in 0..2 {
                let tee = node(&mut spec, format!("{id}_tee{t}"), false);
                switch(
                    &mut spec,
                    format!("{id}_t{t}"),
                    SwitchKind::CircuitBreaker,
                    bb,
                    Some(tee),
                    true,
                );
                for x in 0..TX_PER_TEE {
                    let lv = node(&mut spec, format!("{id}_lv{t}{x}"), true);
                    spec.branches.push(BranchSpec {
                        id: format!("{id}_tx{t}{x}"),
                        kind: BranchKind::Transformer,
                        from: tee,
                        to: lv,
                    });
                    spec.loads.push(LoadSpec {
                        id: format!("{id}_load{t}{x}"),
                        node: lv,
                        customers: 40,
                    });
                }
            }
        }
    }
    Model::build(spec).expect("the generated network is well formed")
}

/// The peer: which sections a source in service reaches, by BFS.
fn bfs_energised(model: &Model, inputs: &Inputs) -> Vec<bool> {
    let n = model.sections.len();
    let mut adj: Vec<Vec<u32>> = vec![Vec::new(); n];
    for (i, w) in model.switches.iter().enumerate() {
        if let (Some(b), Pos::Closed) = (w.b, inputs.switches[i]) {
            adj[w.a as usize].push(b);
            adj[b as usize].push(w.a);
        }
    }
    for t in &model.transformers {
        adj[t.a as usize].push(t.b);
        adj[t.b as usize].push(t.a);
    }
    let mut seen = vec![false; n];
    let mut queue = std::collections::VecDeque::new();
    for (i, s) in model.sources.iter().enumerate() {
        if inputs.sources[i] == Pos::Closed && !seen[s.section as usize] {
            seen[s.section as usize] = true;
            queue.push_back(s.section);
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

fn percentile(sorted: &[f64], p: f64) -> f64 {
    sorted[((sorted.len() - 1) as f64 * p).round() as usize]
}

fn main() {
    let rss0 = rss_kib();
    let model = network();
    let rss_model = rss_kib().saturating_sub(rss0);
    println!(
        "network: {} switching devices, {} sections, {} transformers, {} sources; model ~{} KiB (RSS delta)",
        model.switches.len(),
        model.sections.len(),
        model.transformers.len(),
        model.sources.len(),
        rss_model
    );
    assert_eq!(model.switches.len(), 10_000);
    assert_eq!(model.sections.len(), 20_000);
    let mut inputs = Inputs::normal(&model);
    let rss1 = rss_kib();
    let mut topology = compute(&model, &inputs);
    println!(
        "one result: ~{} KiB (RSS delta); {} sections energised, {} loops",
        rss_kib().saturating_sub(rss1),
        topology.state.iter().filter(|s| s.energised()).count(),
        topology.loops()
    );
    let ring_switches: Vec<usize> = model
        .switches
        .iter()
        .enumerate()
        .filter(|(_, s)| s.kind == SwitchKind::LoadBreakSwitch)
        .map(|(i, _)| i)
        .collect();
    let mut rng = StdRng::seed_from_u64(32);
    let (mut compute_us, mut with_preview_us, mut bfs_us) = (Vec::new(), Vec::new(), Vec::new());
    for _ in 0..2_000 {
        let i = ring_switches[rng.random_range(0..ring_switches.len())];
        let next = if inputs.switches[i] == Pos::Closed {
            Pos::Open
        } else {
            Pos::Closed
        };
        inputs.switches[i] = next;
        let t0 = Instant::now();
        let after = compute(&model, &inputs);
        let t1 = Instant::now();
        let p = preview(&model, &topology, &after);
        let t2 = Instant::now();
        std::hint::black_box(&p);
        let energised = bfs_energised(&model, &inputs);
        let t3 = Instant::now();
        assert!(
            energised
                .iter()
                .zip(&after.state)
                .all(|(e, s)| *e == s.energised()),
            "the processor and the BFS disagree"
        );
        compute_us.push((t1 - t0).as_secs_f64() * 1e6);
        with_preview_us.push((t2 - t0).as_secs_f64() * 1e6);
        bfs_us.push((t3 - t2).as_secs_f64() * 1e6);
        topology = after;
    }
    for (name, v) in [
        ("recompute", &mut compute_us),
        ("recompute + preview", &mut with_preview_us),
        ("peer: BFS, energised only", &mut bfs_us),
    ] {
        v.sort_by(f64::total_cmp);
        println!(
            "{name:<26} p50 {:>8.0} us   p99 {:>8.0} us   max {:>8.0} us   ({} changes)",
            percentile(v, 0.5),
            percentile(v, 0.99),
            v[v.len() - 1],
            v.len()
        );
    }
}
