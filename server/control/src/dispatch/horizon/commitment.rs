//! Optimal commitment: which oil units run in which period, decided by
//! branch and bound over the horizon's on/off variables ([`crate::dispatch::mip`]),
//! so that no-load fuel, starts and minimum up/down times are priced
//! exactly instead of by a state-of-charge rule.

use std::collections::BTreeMap;

use crate::dispatch::mip::{relax_and_fix, solve_binary_from, MipLimits};

/// Searches with more on/off decisions than this start from relax and fix.
const RELAX_AND_FIX_FROM: usize = 16;
use crate::dispatch::DispatchError;

use super::{CommitmentResult, HorizonProblem};

/// The schedule of every oil unit with `optimize_commitment`.
pub(super) fn decide(p: &HorizonProblem) -> Result<CommitmentResult, DispatchError> {
    let (model, v) = p.build();
    let binaries: Vec<usize> = v
        .commit
        .iter()
        .flatten()
        .map(|c| c.on)
        .filter(|&j| model.lb[j] != model.ub[j])
        .collect();
    let limits = MipLimits {
        max_nodes: p.max_nodes(),
        ..MipLimits::default()
    };
    // Many on/off decisions (a day of 15-minute periods, or several
    // diesels) start from a relax-and-fix schedule: rounding the relaxation
    // rarely finds a good one there.
    let start = if binaries.len() > RELAX_AND_FIX_FROM {
        let groups: Vec<Vec<usize>> = (0..p.periods.len())
            .map(|t| {
                v.commit
                    .iter()
                    .filter_map(|c| c.get(t))
                    .map(|c| c.on)
                    .filter(|&j| model.lb[j] != model.ub[j])
                    .collect()
            })
            .collect();
        let window = if p.periods.len() > 24 { 16 } else { 8 };
        relax_and_fix(&model, &groups, window, window / 2, 40)
    } else {
        None
    };
    let sol = solve_binary_from(&model, &binaries, limits, start)?;
    let mut running = BTreeMap::new();
    let mut starts = BTreeMap::new();
    for (k, u) in p.oil.iter().enumerate() {
        let Some(vars) = v.commit.get(k).filter(|c| !c.is_empty()) else {
            continue;
        };
        let sched: Vec<bool> = vars.iter().map(|c| sol.x[c.on] > 0.5).collect();
        starts.insert(u.id.clone(), count_starts(u.running, &sched));
        running.insert(u.id.clone(), sched);
    }
    Ok(CommitmentResult {
        running,
        starts,
        nodes: sol.nodes,
        proven: sol.proven,
        lower_bound: sol.bound,
    })
}

fn count_starts(running_now: bool, sched: &[bool]) -> u32 {
    let mut prev = running_now;
    let mut n = 0;
    for &on in sched {
        if on && !prev {
            n += 1;
        }
        prev = on;
    }
    n
}

/// `p` with the schedule given: every decided unit runs (at its minimum
/// stable load or more) exactly in its scheduled periods.
pub(super) fn with_schedule(
    p: &HorizonProblem,
    schedule: &BTreeMap<String, Vec<bool>>,
) -> HorizonProblem {
    let mut fixed = p.clone();
    for u in &mut fixed.oil {
        let Some(sched) = schedule.get(&u.id) else {
            continue;
        };
        u.optimize_commitment = false;
        u.relaxed_commitment = false;
        for (t, per) in fixed.periods.iter_mut().enumerate() {
            per.running.insert(u.id.clone(), sched[t]);
        }
        // A unit started in the first period ramps from standstill.
        if !u.running && sched.first() == Some(&true) {
            u.initial_kw = None;
        }
    }
    fixed
}

/// What the schedule costs beyond the energy: no-load hours and starts.
pub(super) fn fixed_costs(p: &HorizonProblem, schedule: &BTreeMap<String, Vec<bool>>) -> f64 {
    p.oil
        .iter()
        .filter_map(|u| {
            let sched = schedule.get(&u.id)?;
            let hours = sched.iter().filter(|&&on| on).count() as f64 * p.dt_h;
            Some(
                u.no_load_cost_per_h * hours
                    + u.start_cost * f64::from(count_starts(u.running, sched)),
            )
        })
        .sum()
}

impl HorizonProblem {
    /// Relaxations the branch and bound may solve: enough for a day of
    /// 15-minute periods; `max_commitment_nodes` overrides.
    fn max_nodes(&self) -> usize {
        self.max_commitment_nodes.unwrap_or(4000)
    }
}
