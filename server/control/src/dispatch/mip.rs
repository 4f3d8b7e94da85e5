//! Branch and bound over binary variables of an LP [`Model`], with clarabel
//! solving every relaxation: how the look-ahead decides when each diesel
//! runs (optimal commitment) without a second solver.
//!
//! **Owns:** the search (best bound first, a rounding heuristic for early
//! incumbents, branching on the most fractional binary, earliest first on
//! ties), its stopping rules (a relative and an absolute gap, a node limit),
//! and the answer's proof: the incumbent and the best bound, so a caller
//! always knows how far from optimal an answer can be.
//!
//! **Must not touch:** anything dispatch-specific. The model names its
//! binaries; the caller turns the answer into a schedule.
//!
//! Why it is exact: every node's relaxation is a lower bound of every
//! integer point below it, a node is dropped only when that bound cannot
//! beat the incumbent by more than the gap, and the search ends with the
//! incumbent proven within the gap of the best remaining bound. The node
//! limit is the only way to stop short, and then [`MipSolution::proven`] is
//! false and the gap is reported. No wall-clock limit: the same problem gives
//! the same answer every run (replay is deterministic).

use std::cmp::Ordering;
use std::collections::BinaryHeap;
use std::sync::mpsc;

use super::lp::{Model, SolveFailure};

/// A binary whose relaxed value is this close to 0 or 1 counts as integral.
const INT_TOL: f64 = 1e-6;

#[derive(Debug, Clone, Copy)]
pub(crate) struct MipLimits {
    /// Stop once the incumbent is within this share of the best bound.
    pub rel_gap: f64,
    /// ... or within this absolute amount (currency).
    pub abs_gap: f64,
    /// Relaxations solved at the most.
    pub max_nodes: usize,
}

impl Default for MipLimits {
    fn default() -> Self {
        MipLimits {
            rel_gap: 1e-3,
            abs_gap: 1e-2,
            max_nodes: 4000,
        }
    }
}

#[derive(Debug, Clone)]
pub(crate) struct MipSolution {
    /// The best integer point found (binaries exactly 0 or 1).
    pub x: Vec<f64>,
    #[allow(dead_code)] // read by the tests; kept beside the bound it is proven against
    pub objective: f64,
    /// No integer point costs less than this.
    pub bound: f64,
    /// Relaxations solved.
    pub nodes: usize,
    /// The incumbent is proven within the gap (the node limit was not hit).
    pub proven: bool,
}

struct Node {
    /// The parent's relaxation value: a lower bound of this node.
    bound: f64,
    fixes: Vec<(usize, f64)>,
    /// Tie-breaker that keeps the order deterministic (deeper first).
    seq: usize,
}

impl PartialEq for Node {
    fn eq(&self, o: &Self) -> bool {
        self.cmp(o) == Ordering::Equal
    }
}
impl Eq for Node {}
impl PartialOrd for Node {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}
impl Ord for Node {
    /// The max-heap pops the lowest bound first, then the newest node.
    fn cmp(&self, o: &Self) -> Ordering {
        o.bound.total_cmp(&self.bound).then(self.seq.cmp(&o.seq))
    }
}

/// Minimises `model` with the variables `binaries` restricted to {0, 1}
/// (their bounds in the model must lie within [0, 1]).
pub(crate) fn solve_binary(
    model: &Model,
    binaries: &[usize],
    limits: MipLimits,
) -> Result<MipSolution, SolveFailure> {
    solve_binary_from(model, binaries, limits, None)
}

/// [`solve_binary`] starting from a known integer point `start` (its
/// objective prunes from the first node on).
///
/// Both cores work: the two best open nodes are taken together and their
/// relaxations solved at once ([`relax_pair`]), then handled one after the
/// other in the order they were taken. That order never depends on which
/// solve finishes first, so the same problem still gives the same answer
/// on any machine (a replay stays byte for byte the same).
pub(crate) fn solve_binary_from(
    model: &Model,
    binaries: &[usize],
    limits: MipLimits,
    start: Option<Vec<f64>>,
) -> Result<MipSolution, SolveFailure> {
    with_workers(model, |works| search(model, works, binaries, limits, start))
}

/// The branch and bound of [`solve_binary_from`] on `works`.
fn search(
    model: &Model,
    works: &mut Workers<'_>,
    binaries: &[usize],
    limits: MipLimits,
    start: Option<Vec<f64>>,
) -> Result<MipSolution, SolveFailure> {
    let mut nodes = 0usize;
    let mut seq = 0usize;
    let mut best: Option<(f64, Vec<f64>)> = start.map(|x| (model.objective(&x), x));
    let mut heap = BinaryHeap::new();
    heap.push(Node {
        bound: f64::NEG_INFINITY,
        fixes: Vec::new(),
        seq,
    });
    let mut root_failure: Option<SolveFailure> = None;
    let close_enough =
        |bound: f64, inc: f64| inc - bound <= limits.abs_gap.max(limits.rel_gap * inc.abs());
    let mut proven = true;
    while proven && !heap.is_empty() {
        // The (at most) two best nodes the incumbent does not settle.
        let mut batch: Vec<Node> = Vec::with_capacity(2);
        while batch.len() < 2 {
            let Some(node) = heap.pop() else { break };
            if let Some((inc, _)) = &best {
                if close_enough(node.bound, *inc) {
                    // Every node left has a bound at least this one's.
                    heap.clear();
                    break;
                }
            }
            if nodes + batch.len() >= limits.max_nodes {
                heap.push(node);
                proven = false;
                break;
            }
            batch.push(node);
        }
        let solved = match batch.as_slice() {
            [] => break,
            [a] => vec![works.relax(&a.fixes)],
            [a, b, ..] => {
                let (ra, rb) = works.relax_pair(&a.fixes, &b.fixes);
                vec![ra, rb]
            }
        };
        for (node, relaxed) in batch.into_iter().zip(solved) {
            nodes += 1;
            let x = match relaxed {
                Ok(x) => x,
                Err(e) => {
                    if node.fixes.is_empty() {
                        root_failure = Some(e);
                    }
                    continue; // an infeasible branch holds no integer point
                }
            };
            let value = model.objective(&x);
            if let Some((inc, _)) = &best {
                if close_enough(value, *inc) {
                    continue;
                }
            }
            let fractional = binaries
                .iter()
                .copied()
                .filter(|&j| x[j] > INT_TOL && x[j] < 1.0 - INT_TOL)
                .max_by(|&a, &b| {
                    let fa = 0.5 - (x[a] - 0.5).abs();
                    let fb = 0.5 - (x[b] - 0.5).abs();
                    fa.total_cmp(&fb).then(b.cmp(&a))
                });
            let Some(j) = fractional else {
                let mut xi = x;
                for &b in binaries {
                    xi[b] = xi[b].round();
                }
                if best.as_ref().is_none_or(|(inc, _)| value < *inc) {
                    best = Some((value, xi));
                }
                continue;
            };
            // Rounding dives: at the root and now and then, fix every binary
            // to a rounded value (two thresholds, solved together) and solve
            // the rest, for an incumbent to prune with.
            if nodes == 1 || nodes.is_multiple_of(16) {
                let rounded = |threshold: f64| -> Vec<(usize, f64)> {
                    binaries
                        .iter()
                        .map(|&b| (b, if x[b] > threshold { 1.0 } else { 0.0 }))
                        .collect()
                };
                let (low, half) = (rounded(INT_TOL), rounded(0.5));
                nodes += 2;
                let (rl, rh) = works.relax_pair(&low, &half);
                for xr in [rl, rh].into_iter().flatten() {
                    let v = model.objective(&xr);
                    if best.as_ref().is_none_or(|(inc, _)| v < *inc) {
                        best = Some((v, xr));
                    }
                }
            }
            for value_of_j in [1.0, 0.0] {
                let mut fixes = node.fixes.clone();
                fixes.push((j, value_of_j));
                seq += 1;
                heap.push(Node {
                    bound: value,
                    fixes,
                    seq,
                });
            }
        }
    }
    // Stopped short: polish the incumbent by single flips (each binary
    // turned over, the rest held, the continuous part solved again), while
    // one improves it.
    if !proven {
        if let Some((v, x)) = best.take() {
            let (v, x, tried) = improve_by_flips(model, works, binaries, v, x);
            nodes += tried;
            best = Some((v, x));
        }
    }
    let lowest_open = heap.iter().map(|n| n.bound).fold(f64::INFINITY, f64::min);
    match best {
        Some((objective, x)) => Ok(MipSolution {
            bound: lowest_open.min(objective),
            x,
            objective,
            nodes,
            proven,
        }),
        None => Err(root_failure.unwrap_or_else(|| {
            if proven {
                SolveFailure::Infeasible(
                    "no on/off schedule of the diesels satisfies every constraint \
                     (minimum load, minimum up and down times, balance)"
                        .into(),
                )
            } else {
                SolveFailure::Solver(format!(
                    "no on/off schedule found within {} relaxations",
                    limits.max_nodes
                ))
            }
        })),
    }
}

/// First-improvement local search over single flips of the binaries, at
/// most three passes; returns the point, its objective and the
/// relaxations solved. Flips are tried two at a time: when the first of a
/// pair improves, the second (solved against the old point) is discarded
/// and tried again from the new one, so the walk is that of one at a time.
fn improve_by_flips(
    model: &Model,
    works: &mut Workers<'_>,
    binaries: &[usize],
    mut value: f64,
    mut x: Vec<f64>,
) -> (f64, Vec<f64>, usize) {
    let mut tried = 0;
    let flipped = |x: &[f64], flip: usize| -> Vec<(usize, f64)> {
        binaries
            .iter()
            .map(|&b| {
                let v = x[b].round();
                (b, if b == flip { 1.0 - v } else { v })
            })
            .collect()
    };
    let better = |v: f64, value: f64| v < value - 1e-9 * value.abs().max(1.0);
    for _pass in 0..3 {
        let mut improved = false;
        let mut i = 0;
        while i < binaries.len() {
            let first = flipped(&x, binaries[i]);
            let (r1, r2) = match binaries.get(i + 1) {
                Some(&next) => {
                    let second = flipped(&x, next);
                    let (r1, r2) = works.relax_pair(&first, &second);
                    tried += 2;
                    (r1, Some(r2))
                }
                None => {
                    tried += 1;
                    (works.relax(&first), None)
                }
            };
            i += 1;
            let mut take = |r: Result<Vec<f64>, SolveFailure>| -> bool {
                let Ok(xr) = r else { return false };
                let v = model.objective(&xr);
                if !better(v, value) {
                    return false;
                }
                value = v;
                x = xr;
                for &b in binaries {
                    x[b] = x[b].round();
                }
                improved = true;
                true
            };
            if take(r1) {
                continue; // the second flip is tried again from the new point
            }
            if let Some(r2) = r2 {
                i += 1;
                take(r2);
            }
        }
        if !improved {
            break;
        }
    }
    (value, x, tried)
}

/// Relax and fix: a good integer point for a long horizon, fast. The
/// binaries come in `groups` in time order (one group per period); a window
/// of `window` groups is searched as binaries with everything before it
/// fixed and everything after it relaxed, then its first `step` groups are
/// fixed, and the window moves on. Not a proof of anything: it gives the
/// exact search an incumbent to prune with from the start.
pub(crate) fn relax_and_fix(
    model: &Model,
    groups: &[Vec<usize>],
    window: usize,
    step: usize,
    nodes_per_window: usize,
) -> Option<Vec<f64>> {
    let mut fixed = model.clone();
    let step = step.max(1);
    let mut at = 0;
    while at < groups.len() {
        let end = (at + window.max(step)).min(groups.len());
        let ints: Vec<usize> = groups[at..end].iter().flatten().copied().collect();
        let limits = MipLimits {
            max_nodes: nodes_per_window,
            ..MipLimits::default()
        };
        let sol = solve_binary(&fixed, &ints, limits).ok()?;
        let keep = if end == groups.len() {
            end
        } else {
            (at + step).min(end)
        };
        for &j in groups[at..keep].iter().flatten() {
            let v = sol.x[j].round();
            fixed.lb[j] = v;
            fixed.ub[j] = v;
        }
        at = keep;
    }
    let mut x = fixed.solve_relaxation().ok()?;
    for &j in groups.iter().flatten() {
        x[j] = x[j].round();
    }
    Some(x)
}

type Fixes = Vec<(usize, f64)>;
type Relaxed = Result<Vec<f64>, SolveFailure>;

/// A search's two working copies of the model: the first solved on the
/// searching thread, the second on one helper thread that lives as long as
/// the search (a thread started for every pair cost as much as a small
/// relaxation).
struct Workers<'m> {
    model: &'m Model,
    first: Model,
    jobs: Option<mpsc::Sender<Fixes>>,
    done: mpsc::Receiver<Relaxed>,
}

impl Workers<'_> {
    /// The relaxation under `fixes`, on this thread.
    fn relax(&mut self, fixes: &[(usize, f64)]) -> Relaxed {
        relax(self.model, &mut self.first, fixes)
    }

    /// The relaxations under `a` and under `b`, solved at once on the two
    /// threads.
    fn relax_pair(&mut self, a: &[(usize, f64)], b: &[(usize, f64)]) -> (Relaxed, Relaxed) {
        let sent = self
            .jobs
            .as_ref()
            .is_some_and(|j| j.send(b.to_vec()).is_ok());
        let ra = self.relax(a);
        let rb = if sent {
            self.done.recv().unwrap_or_else(|_| Err(helper_failed()))
        } else {
            Err(helper_failed())
        };
        (ra, rb)
    }
}

fn helper_failed() -> SolveFailure {
    SolveFailure::Solver("the relaxation's worker thread failed".into())
}

/// Runs `f` with a search's [`Workers`]; the helper thread ends with it.
fn with_workers<R>(model: &Model, f: impl FnOnce(&mut Workers<'_>) -> R) -> R {
    std::thread::scope(|s| {
        let (jobs, inbox) = mpsc::channel::<Fixes>();
        let (outbox, done) = mpsc::channel::<Relaxed>();
        let helper = s.spawn(move || {
            let mut second = model.clone();
            for fixes in inbox {
                if outbox.send(relax(model, &mut second, &fixes)).is_err() {
                    break;
                }
            }
        });
        let mut works = Workers {
            model,
            first: model.clone(),
            jobs: Some(jobs),
            done,
        };
        let r = f(&mut works);
        works.jobs = None; // the helper's inbox closes: it returns
                           // Joined here, so a helper that panicked (its pairs already failed
                           // as "worker thread failed") does not take the search down.
        let _ = helper.join();
        r
    })
}

/// Solves the relaxation of `model` with `fixes` applied to a working copy
/// (its bounds restored afterwards).
fn relax(
    model: &Model,
    work: &mut Model,
    fixes: &[(usize, f64)],
) -> Result<Vec<f64>, SolveFailure> {
    for &(j, v) in fixes {
        work.lb[j] = v;
        work.ub[j] = v;
    }
    let r = work.solve_relaxation();
    for &(j, _) in fixes {
        work.lb[j] = model.lb[j];
        work.ub[j] = model.ub[j];
    }
    r
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dispatch::lp::Sense;

    /// Every 0/1 assignment, the best by exhaustive search.
    fn brute_force(model: &Model, binaries: &[usize]) -> Option<f64> {
        let mut best: Option<f64> = None;
        let mut work = model.clone();
        for mask in 0..(1u32 << binaries.len()) {
            let fixes: Vec<(usize, f64)> = binaries
                .iter()
                .enumerate()
                .map(|(i, &b)| (b, f64::from((mask >> i) & 1)))
                .collect();
            if let Ok(x) = relax(model, &mut work, &fixes) {
                let v = model.objective(&x);
                best = Some(best.map_or(v, |b: f64| b.min(v)));
            }
        }
        best
    }

    /// A knapsack-like unit commitment: three generators with a fixed cost
    /// when on, a minimum output, and a demand to meet.
    fn commitment(demand: f64) -> (Model, Vec<usize>) {
        let mut m = Model::default();
        let gens = [
            (50.0, 20.0, 1.0, 30.0),
            (80.0, 40.0, 0.8, 55.0),
            (30.0, 5.0, 1.5, 5.0),
        ];
        let mut bal = Vec::new();
        let mut bins = Vec::new();
        for (i, &(max, min, marginal, fixed)) in gens.iter().enumerate() {
            let u = m.var(format!("u{i}"), 0.0, 1.0, fixed);
            let p = m.var(format!("p{i}"), 0.0, max, marginal);
            m.row(format!("max{i}"), vec![(p, 1.0), (u, -max)], Sense::Le, 0.0);
            m.row(format!("min{i}"), vec![(p, -1.0), (u, min)], Sense::Le, 0.0);
            bal.push((p, 1.0));
            bins.push(u);
        }
        let shed = m.var("shed".into(), 0.0, demand, 10.0);
        bal.push((shed, 1.0));
        m.row("balance".into(), bal, Sense::Eq, demand);
        (m, bins)
    }

    #[test]
    fn matches_exhaustive_search() {
        for demand in [0.0, 4.0, 18.0, 33.0, 47.0, 61.0, 90.0, 125.0, 160.0, 200.0] {
            let (m, bins) = commitment(demand);
            let sol = solve_binary(&m, &bins, MipLimits::default()).unwrap();
            let exact = brute_force(&m, &bins).unwrap();
            assert!(sol.proven);
            assert!(
                (sol.objective - exact).abs() <= 1e-3 + 1e-4 * exact.abs(),
                "demand {demand}: {} vs {exact}",
                sol.objective
            );
            assert!(sol.bound <= sol.objective + 1e-9);
            for &b in &bins {
                assert!(sol.x[b] == 0.0 || sol.x[b] == 1.0);
            }
            m.check(&sol.x, 1e-5).unwrap();
        }
    }

    #[test]
    fn the_search_on_two_threads_gives_the_same_answer_every_time() {
        // Two plants' worth of generators and a demand that leaves
        // several near-ties: the paired relaxations, the dives and the
        // flips must come out in the same order on every run.
        let (m1, b1) = commitment(125.0);
        let (m2, b2) = commitment(61.0);
        let mut m = m1;
        let offset = m.lb.len();
        for j in 0..m2.lb.len() {
            m.var(format!("b{j}"), m2.lb[j], m2.ub[j], m2.cost[j]);
        }
        for r in &m2.rows {
            let coefs = r.coefs.iter().map(|&(j, a)| (j + offset, a)).collect();
            m.row(format!("b {}", r.name), coefs, r.sense, r.rhs);
        }
        let bins: Vec<usize> = b1
            .into_iter()
            .chain(b2.iter().map(|b| b + offset))
            .collect();
        for max_nodes in [3, 7, 4000] {
            let limits = MipLimits {
                max_nodes,
                ..MipLimits::default()
            };
            let first = solve_binary(&m, &bins, limits).unwrap();
            for _ in 0..10 {
                let again = solve_binary(&m, &bins, limits).unwrap();
                assert_eq!(again.x, first.x, "max_nodes {max_nodes}");
                assert_eq!(again.nodes, first.nodes);
                assert_eq!(again.bound.to_bits(), first.bound.to_bits());
            }
            if max_nodes == 4000 {
                let exact = brute_force(&m, &bins).unwrap();
                assert!(first.proven);
                assert!((first.objective - exact).abs() <= 1e-3 + 1e-4 * exact.abs());
            }
        }
    }

    #[test]
    fn an_infeasible_problem_says_so() {
        let mut m = Model::default();
        let u = m.var("u".into(), 0.0, 1.0, 1.0);
        let p = m.var("p".into(), 0.0, 10.0, 0.0);
        m.row("p = 5".into(), vec![(p, 1.0)], Sense::Eq, 5.0);
        m.row(
            "p <= 10 u".into(),
            vec![(p, 1.0), (u, -10.0)],
            Sense::Le,
            0.0,
        );
        m.row("p >= 7 u".into(), vec![(p, -1.0), (u, 7.0)], Sense::Le, 0.0);
        assert!(matches!(
            solve_binary(&m, &[u], MipLimits::default()),
            Err(SolveFailure::Infeasible(_))
        ));
    }

    #[test]
    fn the_node_limit_reports_an_unproven_answer() {
        let (m, bins) = commitment(125.0);
        let limits = MipLimits {
            max_nodes: 1,
            ..MipLimits::default()
        };
        match solve_binary(&m, &bins, limits) {
            Ok(sol) => assert!(!sol.proven || sol.nodes <= 3),
            Err(e) => assert!(matches!(e, SolveFailure::Solver(_))),
        }
    }
}
