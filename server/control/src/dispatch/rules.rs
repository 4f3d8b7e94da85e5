//! Rules outside the LP: the fallback dispatch and diesel commitment.
//!
//! **Owns:** the rule-based dispatch used when the optimiser cannot be trusted
//! (renewables first, then storage, then diesel), and the diesel on/off rule
//! with hysteresis on net load and state of charge plus minimum run and stop
//! times (settings: `CommitmentConfig`). Both are pure functions.
//!
//! **Must not touch:** I/O, clocks (time comes in as an argument), the solver.

use gridscada_config::CommitmentConfig;
use gridscada_tagdb::Timestamp;

use super::single::DispatchProblem;
use super::Setpoints;

/// The setpoints of the fallback rule.
#[derive(Debug, Clone, PartialEq)]
pub struct FallbackDispatch {
    /// Per unit id, kW (storage: + discharge), in problem order.
    pub setpoints_kw: Setpoints,
    pub shed_kw: f64,
    /// Supply that could not be placed anywhere (running diesels' minimum
    /// load beyond demand and storage charging), kW; 0 normally.
    pub unabsorbed_kw: f64,
}

fn finite_nonneg(x: f64) -> f64 {
    if x.is_finite() {
        x.max(0.0)
    } else {
        0.0
    }
}

/// Load following by rule: renewables first, then storage, then diesel above
/// its minimum, then shedding. A surplus charges storage and the rest of it
/// is curtailed from the renewables. Never panics, whatever the numbers: a
/// non-finite or negative value counts as zero.
pub fn fallback_dispatch(p: &DispatchProblem) -> FallbackDispatch {
    let dt = if p.dt_h.is_finite() && p.dt_h > 0.0 {
        p.dt_h
    } else {
        1.0 / 720.0
    };
    let demand = finite_nonneg(p.demand_kw);
    let mut ren: Vec<f64> =
        p.pv.iter()
            .chain(&p.wind)
            .map(|u| finite_nonneg(u.available_kw))
            .collect();
    let mut oil: Vec<f64> = p
        .oil
        .iter()
        .map(|u| {
            if u.running {
                finite_nonneg(u.min_kw)
            } else {
                0.0
            }
        })
        .collect();
    let mut sto: Vec<f64> = vec![0.0; p.storage.len()];
    let supply: f64 = ren.iter().sum::<f64>() + oil.iter().sum::<f64>();
    let mut surplus = supply - demand;
    let mut shed = 0.0;
    if surplus > 0.0 {
        for (k, s) in p.storage.iter().enumerate() {
            let ch = finite_nonneg(s.charge_limit_kw(dt)).min(surplus);
            sto[k] = -ch;
            surplus -= ch;
        }
        // Curtail the most expensive renewables first.
        let costs: Vec<f64> = p.pv.iter().chain(&p.wind).map(|u| u.cost_per_kwh).collect();
        let mut order: Vec<usize> = (0..ren.len()).collect();
        order.sort_by(|&a, &b| costs[b].total_cmp(&costs[a]));
        for i in order {
            let cut = ren[i].min(surplus);
            ren[i] -= cut;
            surplus -= cut;
        }
    } else {
        let mut deficit = -surplus;
        for (k, s) in p.storage.iter().enumerate() {
            let dis = finite_nonneg(s.discharge_limit_kw(dt)).min(deficit);
            sto[k] = dis;
            deficit -= dis;
        }
        let mut order: Vec<usize> = (0..p.oil.len()).filter(|&k| p.oil[k].running).collect();
        order.sort_by(|&a, &b| p.oil[a].cost_per_kwh.total_cmp(&p.oil[b].cost_per_kwh));
        for k in order {
            let room = (finite_nonneg(p.oil[k].max_kw) - oil[k]).max(0.0);
            let more = room.min(deficit);
            oil[k] += more;
            deficit -= more;
        }
        shed = deficit.max(0.0);
        surplus = 0.0;
    }
    let ids = p.pv.iter().chain(&p.wind).map(|u| u.id.clone());
    let mut sp: Vec<(String, f64)> = ids.zip(ren).collect();
    sp.extend(p.oil.iter().map(|u| u.id.clone()).zip(oil));
    sp.extend(p.storage.iter().map(|u| u.id.clone()).zip(sto));
    FallbackDispatch {
        setpoints_kw: Setpoints(sp),
        shed_kw: shed,
        unabsorbed_kw: surplus.max(0.0),
    }
}

/// Commitment state of one diesel, kept by the driver between periods.
#[derive(Debug, Clone, PartialEq)]
pub struct DieselState {
    pub id: String,
    pub max_kw: f64,
    pub cost_per_kwh: f64,
    /// What the commitment rule last commanded.
    pub run: bool,
    /// When that command last changed (start of the min run/stop timer).
    pub since: Timestamp,
}

/// One start or stop.
#[derive(Debug, Clone, PartialEq)]
pub struct CommitmentDecision {
    pub id: String,
    pub run: bool,
    pub reason: String,
}

/// A diesel is stopped only if the remaining units cover the net load with
/// this share of their power to spare: the net-load half of the hysteresis
/// (the start threshold is the full cover). `CommitmentConfig` has no field
/// for it yet.
pub const STOP_MARGIN: f64 = 0.1;

/// The diesel on/off rule. At most one change per call.
///
/// - `net_load_kw`: demand minus available renewables.
/// - `storage_cover_kw`: what storage can deliver, sustained for `min_run_s`.
/// - `soc_frac`: stored energy over capacity; `None` when unknown (treated as
///   low: a diesel is started rather than trusting a battery we cannot see).
///
/// Start the cheapest stopped diesel past its minimum stop time when the net
/// load exceeds what storage and the running diesels can cover, or when the
/// state of charge is below `start_soc_frac` and no diesel runs. Stop the most
/// expensive running diesel past its minimum run time when the state of charge
/// is above `stop_soc_frac` and the others cover the net load with
/// [`STOP_MARGIN`] to spare.
pub fn commit_diesels(
    cfg: &CommitmentConfig,
    now: Timestamp,
    net_load_kw: f64,
    storage_cover_kw: f64,
    soc_frac: Option<f64>,
    diesels: &[DieselState],
) -> Option<CommitmentDecision> {
    let net = if net_load_kw.is_finite() {
        net_load_kw
    } else {
        f64::INFINITY
    };
    let store = finite_nonneg(storage_cover_kw);
    let running_cover: f64 = diesels
        .iter()
        .filter(|d| d.run)
        .map(|d| finite_nonneg(d.max_kw))
        .sum();
    let cover = store + running_cover;
    let none_running = !diesels.iter().any(|d| d.run);
    // NaN counts as unknown, hence low.
    let soc_low = soc_frac.is_none_or(|s| s.is_nan() || s < cfg.start_soc_frac);
    let soc_high = soc_frac.is_some_and(|s| s > cfg.stop_soc_frac);
    let held = |d: &DieselState, min_s: f64| now.since(d.since).as_secs_f64() >= min_s;

    let start_reason = if net > cover {
        Some(format!(
            "net load {net:.1} kW exceeds what storage and running diesels cover ({cover:.1} kW)"
        ))
    } else if soc_low && none_running {
        Some(match soc_frac {
            Some(s) => format!(
                "state of charge {:.0} % is below {:.0} %",
                s * 100.0,
                cfg.start_soc_frac * 100.0
            ),
            None => "state of charge is unknown".to_string(),
        })
    } else {
        None
    };
    if let Some(reason) = start_reason {
        return diesels
            .iter()
            .filter(|d| !d.run && held(d, cfg.min_stop_s))
            .min_by(|a, b| a.cost_per_kwh.total_cmp(&b.cost_per_kwh))
            .map(|d| CommitmentDecision {
                id: d.id.clone(),
                run: true,
                reason,
            });
    }
    if soc_high {
        let cand = diesels
            .iter()
            .filter(|d| d.run && held(d, cfg.min_run_s))
            .max_by(|a, b| a.cost_per_kwh.total_cmp(&b.cost_per_kwh))?;
        let without = cover - finite_nonneg(cand.max_kw);
        if net <= (1.0 - STOP_MARGIN) * without {
            return Some(CommitmentDecision {
                id: cand.id.clone(),
                run: false,
                reason: format!(
                    "state of charge above {:.0} % and net load {net:.1} kW is covered without it ({without:.1} kW)",
                    cfg.stop_soc_frac * 100.0
                ),
            });
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dispatch::single::{OilUnit, RenewableUnit, StorageUnit};

    fn problem(demand: f64, pv: f64, soc: f64, running: bool) -> DispatchProblem {
        DispatchProblem {
            dt_h: 0.25,
            demand_kw: demand,
            voll_per_kwh: 5.0,
            pv: vec![RenewableUnit {
                id: "pv1".into(),
                available_kw: pv,
                cost_per_kwh: 0.0,
            }],
            wind: vec![],
            oil: vec![OilUnit {
                id: "dg1".into(),
                running,
                min_kw: 30.0,
                max_kw: 150.0,
                cost_per_kwh: 0.35,
            }],
            storage: vec![StorageUnit {
                id: "bess1".into(),
                soc_kwh: soc,
                soc_min_kwh: 20.0,
                soc_max_kwh: 200.0,
                max_charge_kw: 50.0,
                max_discharge_kw: 60.0,
                eff_charge: 0.95,
                eff_discharge: 0.95,
                cycle_cost_per_kwh: 0.02,
                stored_value_per_kwh: 0.0,
            }],
        }
    }

    #[test]
    fn fallback_follows_renewables_storage_diesel_order() {
        let f = fallback_dispatch(&problem(180.0, 60.0, 80.0, true));
        assert_eq!(f.setpoints_kw.get("pv1"), Some(60.0));
        assert_eq!(f.setpoints_kw.get("bess1"), Some(60.0));
        assert_eq!(f.setpoints_kw.get("dg1"), Some(60.0)); // 30 min + 30 more
        assert_eq!(f.shed_kw, 0.0);
        // Surplus: storage charges, the rest is curtailed.
        let f = fallback_dispatch(&problem(20.0, 100.0, 80.0, false));
        assert_eq!(f.setpoints_kw.get("bess1"), Some(-50.0));
        assert_eq!(f.setpoints_kw.get("pv1"), Some(70.0));
        // Nothing left: shed.
        let f = fallback_dispatch(&problem(300.0, 0.0, 20.0, false));
        assert_eq!(f.shed_kw, 300.0);
    }

    #[test]
    fn fallback_survives_garbage() {
        let mut p = problem(f64::NAN, f64::INFINITY, -5.0, true);
        p.dt_h = 0.0;
        let f = fallback_dispatch(&p);
        assert!(f.setpoints_kw.0.iter().all(|(_, v)| v.is_finite()));
    }

    fn dg(run: bool, since_s: i64) -> DieselState {
        DieselState {
            id: "dg1".into(),
            max_kw: 150.0,
            cost_per_kwh: 0.35,
            run,
            since: Timestamp::from_millis(since_s * 1000),
        }
    }

    #[test]
    fn commitment_has_hysteresis_and_minimum_times() {
        let cfg = CommitmentConfig::default(); // start < 25 %, stop > 60 %, run 900 s, stop 300 s
        let now = Timestamp::from_millis(10_000_000);
        let t = |s: i64| 10_000 - s; // "s seconds ago"
                                     // Net load beyond storage: start.
        let d = commit_diesels(&cfg, now, 100.0, 60.0, Some(0.5), &[dg(false, t(1000))]).unwrap();
        assert!(d.run);
        // ... but not within the minimum stop time.
        assert!(commit_diesels(&cfg, now, 100.0, 60.0, Some(0.5), &[dg(false, t(100))]).is_none());
        // Low SoC alone starts it; unknown SoC too.
        assert!(commit_diesels(&cfg, now, 10.0, 60.0, Some(0.2), &[dg(false, t(1000))]).is_some());
        assert!(commit_diesels(&cfg, now, 10.0, 60.0, None, &[dg(false, t(1000))]).is_some());
        // Between the thresholds a running diesel keeps running (hysteresis).
        assert!(commit_diesels(&cfg, now, 10.0, 60.0, Some(0.4), &[dg(true, t(2000))]).is_none());
        // Above stop SoC and covered: stop, but only after the minimum run time.
        let d = commit_diesels(&cfg, now, 10.0, 60.0, Some(0.7), &[dg(true, t(2000))]).unwrap();
        assert!(!d.run);
        assert!(commit_diesels(&cfg, now, 10.0, 60.0, Some(0.7), &[dg(true, t(100))]).is_none());
        // Net load within the stop margin of the cover: keep running.
        assert!(commit_diesels(&cfg, now, 58.0, 60.0, Some(0.7), &[dg(true, t(2000))]).is_none());
    }
}
