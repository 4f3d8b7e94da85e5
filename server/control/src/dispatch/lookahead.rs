//! The live loop's receding horizon: forecasts, the plan, and the worth of
//! stored energy that links the plan to each period's dispatch.
//!
//! **Owns:** forecasting demand and PV/wind availability over the horizon
//! from the measurements now and the configured daily curves ("smart
//! persistence": today's ratio to the curve, fading towards the curve with
//! `blend_h`); building the [`HorizonProblem`] from the single-period problem
//! the driver measured; and the [`HorizonPlan`] the driver publishes.
//!
//! **Must not touch:** I/O, the tag database, the clock. The driver decides
//! when to plan and passes everything in, so tests drive it directly.
//!
//! Why a price and not the plan's first setpoints: the horizon is solved every
//! `resolve_s` (a minute), while the dispatch runs every few seconds on fresh
//! measurements. The single-period LP with stored energy priced at the
//! horizon's marginal value (the multiplier of the starting state of charge)
//! is the first stage of the horizon problem, so between re-plans each
//! dispatch stays balanced on what is measured now and still follows the
//! plan's economics: charge from the diesel when the evening needs it, hold
//! energy back when shedding looms, spend it when the sun will refill it.

use std::collections::BTreeMap;

use serde::Serialize;

use gridscada_config::daily::{hour_of_day, interpolate_daily};
use gridscada_config::{HorizonConfig, MicrogridConfig};
use gridscada_tagdb::Timestamp;

use super::horizon::{
    HorizonOil, HorizonProblem, HorizonRenewable, HorizonStorage, PeriodForecast,
};
use super::single::{DispatchProblem, StorageUnit};
use super::{DispatchError, Setpoints};

/// What today's measurement says about the hours ahead, given a daily curve.
///
/// With no curve the value now persists. With one, the forecast is the curve
/// at that hour times today's ratio to the curve, the ratio fading towards 1
/// with e-folding time `blend_h` (clouds and unusual load pass). When the
/// curve is near zero now (a PV curve at night) the ratio is unknown and the
/// curve is taken as it is.
pub fn forecast(
    measured: f64,
    curve: Option<&[(f64, f64)]>,
    now_h: f64,
    ahead_h: f64,
    blend_h: f64,
) -> f64 {
    let measured = measured.max(0.0);
    let Some(curve) = curve.filter(|c| !c.is_empty()) else {
        return measured;
    };
    let peak = curve.iter().map(|p| p.1).fold(0.0, f64::max);
    let expected_now = interpolate_daily(curve, now_h);
    let expected = interpolate_daily(curve, (now_h + ahead_h).rem_euclid(24.0));
    let ratio = if peak > 0.0 && expected_now > 0.05 * peak {
        (measured / expected_now).clamp(0.0, 3.0)
    } else {
        1.0
    };
    let fade = (-ahead_h.max(0.0) / blend_h.max(1e-6)).exp();
    (expected * (1.0 + (ratio - 1.0) * fade)).max(0.0)
}

/// Seconds of full discharge the plan keeps stored above the minimum: a
/// diesel's start (10 s in the simulator) and a few dispatch periods.
pub const START_RESERVE_S: f64 = 60.0;

/// Relaxations the live plan's commitment search may solve.
pub const LIVE_COMMITMENT_NODES: usize = 300;

/// The plan the driver last made, for the HMI and the dispatch record.
#[derive(Debug, Clone, Serialize)]
pub struct HorizonPlan {
    /// Plant time the plan was made.
    pub at: Timestamp,
    pub periods: usize,
    pub period_s: f64,
    /// "optimal", or why there is no plan ("infeasible", "error").
    pub status: String,
    pub reason: Option<String>,
    pub objective: Option<f64>,
    pub solve_ms: Option<f64>,
    /// Forecast demand per period, kW (period 0 is the measurement).
    pub demand_kw: Vec<f64>,
    /// Forecast PV + wind availability per period, kW.
    pub renewable_kw: Vec<f64>,
    /// Planned state of charge at the end of each period, per storage id.
    pub soc_kwh: BTreeMap<String, Vec<f64>>,
    /// Planned diesel output per period, per diesel id.
    pub diesel_kw: BTreeMap<String, Vec<f64>>,
    /// Whether each diesel runs, per period: the plan's commitment, which the
    /// driver follows while the plan is fresh.
    pub diesel_run: BTreeMap<String, Vec<bool>>,
    /// Relaxations the commitment search solved, and whether its schedule
    /// is proven optimal (within 0.1 %).
    pub commitment_nodes: Option<usize>,
    pub commitment_proven: Option<bool>,
    /// The worth of a stored kWh now, per storage id: what the dispatch
    /// prices stored energy at until the next plan.
    pub stored_energy_value_per_kwh: Setpoints,
}

impl HorizonPlan {
    /// No plan at `at`, for `reason` (status "error").
    pub fn failed(at: Timestamp, reason: String) -> HorizonPlan {
        HorizonPlan {
            at,
            periods: 0,
            period_s: 0.0,
            status: "error".into(),
            reason: Some(reason),
            objective: None,
            solve_ms: None,
            demand_kw: Vec::new(),
            renewable_kw: Vec::new(),
            soc_kwh: BTreeMap::new(),
            diesel_kw: BTreeMap::new(),
            diesel_run: BTreeMap::new(),
            commitment_nodes: None,
            commitment_proven: None,
            stored_energy_value_per_kwh: Setpoints::default(),
        }
    }

    /// Whether the plan was solved (its values may be used).
    pub fn is_optimal(&self) -> bool {
        self.status == "optimal"
    }

    /// Whether the plan runs diesel `id` now (its first period).
    pub fn runs_now(&self, id: &str) -> Option<bool> {
        self.diesel_run.get(id).and_then(|r| r.first().copied())
    }
}

/// The horizon problem from the single-period problem measured now.
///
/// - Period 0 is the measurement; later periods are [`forecast`]s at their
///   midpoints.
/// - The plan decides when each diesel runs, from period 0 on
///   (`optimize_commitment`), priced by its fuel curve, start cost and
///   minimum up and down times ([`MicrogridConfig::diesel_cost`]);
///   `hours_in_state` says how long each has been in its present state.
/// - Stored energy left at the end is worth `terminal_value` per kWh.
/// - `initial_kw` are the setpoints in force, the start of every ramp.
pub fn horizon_problem(
    mg: &MicrogridConfig,
    h: &HorizonConfig,
    now: Timestamp,
    measured: &DispatchProblem,
    initial_kw: &Setpoints,
    terminal_value: &dyn Fn(&str) -> f64,
    hours_in_state: &dyn Fn(&str) -> Option<f64>,
) -> HorizonProblem {
    let n = (*h.periods.get_ref()).max(1.0) as usize;
    horizon_problem_over(
        mg,
        h,
        n,
        now,
        measured,
        initial_kw,
        terminal_value,
        hours_in_state,
    )
}

/// Periods of the day-long relaxation that values what a plan leaves in
/// storage: a day ahead, and always past the plan's own end.
pub fn value_periods(h: &HorizonConfig) -> usize {
    let n = (*h.periods.get_ref()).max(1.0) as usize;
    let per_day = (86_400.0 / h.period_s.get_ref().max(1.0)).ceil() as usize;
    per_day.max(n + 1)
}

/// [`horizon_problem`] over `n` periods.
#[allow(clippy::too_many_arguments)]
pub fn horizon_problem_over(
    mg: &MicrogridConfig,
    h: &HorizonConfig,
    n: usize,
    now: Timestamp,
    measured: &DispatchProblem,
    initial_kw: &Setpoints,
    terminal_value: &dyn Fn(&str) -> f64,
    hours_in_state: &dyn Fn(&str) -> Option<f64>,
) -> HorizonProblem {
    let period_h = *h.period_s.get_ref() / 3600.0;
    let blend_h = *h.blend_h.get_ref();
    let now_h = hour_of_day(now);
    let unit = |id: &str| mg.units.iter().find(|u| u.id.get_ref() == id);
    let curve_of = |id: &str| {
        unit(id)
            .and_then(|u| u.forecast_kw.as_ref())
            .map(|c| c.get_ref().as_slice())
    };
    let ramp_of = |id: &str| unit(id).map_or(0.0, |u| u.ramp_kw_per_s.max(0.0));
    let demand_curve = h
        .demand_forecast_kw
        .as_ref()
        .map(|c| c.get_ref().as_slice());
    let periods = (0..n)
        .map(|t| {
            let ahead_h = if t == 0 {
                0.0
            } else {
                (t as f64 + 0.5) * period_h
            };
            let at = |value: f64, curve: Option<&[(f64, f64)]>| {
                if t == 0 {
                    value
                } else {
                    forecast(value, curve, now_h, ahead_h, blend_h)
                }
            };
            let available_kw = measured
                .pv
                .iter()
                .chain(&measured.wind)
                .map(|u| {
                    let rated = unit(&u.id)
                        .map(|c| c.rated_kw)
                        .filter(|r| *r > 0.0)
                        .unwrap_or(f64::INFINITY);
                    (u.id.clone(), at(u.available_kw, curve_of(&u.id)).min(rated))
                })
                .collect();
            PeriodForecast {
                demand_kw: at(measured.demand_kw, demand_curve),
                available_kw,
                running: BTreeMap::new(),
            }
        })
        .collect();
    let initial = |id: &str, lo: f64, hi: f64| initial_kw.get(id).map(|v| v.clamp(lo, hi));
    let renewable = |u: &super::single::RenewableUnit| HorizonRenewable {
        id: u.id.clone(),
        cost_per_kwh: u.cost_per_kwh,
        ramp_kw_per_s: ramp_of(&u.id),
        initial_kw: initial(&u.id, 0.0, f64::INFINITY),
    };
    HorizonProblem {
        dt_h: period_h,
        voll_per_kwh: measured.voll_per_kwh,
        periods,
        pv: measured.pv.iter().map(renewable).collect(),
        wind: measured.wind.iter().map(renewable).collect(),
        oil: measured
            .oil
            .iter()
            .map(|o| {
                let cost = unit(&o.id)
                    .map(|u| mg.diesel_cost(u, mg.fuel_price(None)))
                    .unwrap_or_default();
                HorizonOil {
                    id: o.id.clone(),
                    running: o.running,
                    min_kw: o.min_kw,
                    max_kw: o.max_kw,
                    cost_per_kwh: o.cost_per_kwh,
                    ramp_kw_per_s: ramp_of(&o.id),
                    // A diesel just started or stopped may sit outside its band.
                    initial_kw: initial(&o.id, 0.0, o.max_kw)
                        .filter(|v| !o.running || *v >= o.min_kw),
                    relaxed_commitment: false,
                    optimize_commitment: true,
                    no_load_cost_per_h: cost.no_load_per_h,
                    start_cost: cost.start_cost,
                    min_up_h: cost.min_up_h,
                    min_down_h: cost.min_down_h,
                    hours_in_state: hours_in_state(&o.id),
                }
            })
            .collect(),
        storage: measured
            .storage
            .iter()
            .map(|s| HorizonStorage {
                unit: StorageUnit {
                    stored_value_per_kwh: 0.0,
                    // The plan keeps enough stored to carry full discharge
                    // while a diesel starts ([`START_RESERVE_S`]): a plan
                    // that empties the battery the moment it starts the
                    // diesel sheds load for the start's seconds. Never above
                    // what is stored now, so the plan stays feasible.
                    soc_min_kwh: (s.soc_min_kwh + s.max_discharge_kw * START_RESERVE_S / 3600.0)
                        .min(s.soc_kwh.max(s.soc_min_kwh))
                        .min(s.soc_max_kwh),
                    ..s.clone()
                },
                ramp_kw_per_s: ramp_of(&s.id),
                initial_kw: initial(&s.id, -s.max_charge_kw, s.max_discharge_kw),
                terminal_value_per_kwh: terminal_value(&s.id).max(0.0),
                final_soc_min_kwh: None,
            })
            .collect(),
        reserve: h.reserve.clone(),
        max_renewable_share: None,
        smoothing_cost_per_kw2: 0.0,
        // A budget that keeps a plan well under a second on a loaded
        // 2-core machine (docs/BENCHMARKS.md); the best schedule found by
        // then is used, and the plan says whether it is proven.
        max_commitment_nodes: Some(LIVE_COMMITMENT_NODES),
    }
}

/// Solves `p` and summarises it as a plan made at `now`.
pub fn plan(p: &HorizonProblem, now: Timestamp) -> HorizonPlan {
    let mut plan = HorizonPlan {
        periods: p.periods.len(),
        period_s: p.dt_h * 3600.0,
        status: "optimal".into(),
        reason: None,
        demand_kw: p.periods.iter().map(|f| f.demand_kw).collect(),
        renewable_kw: p
            .periods
            .iter()
            .map(|f| f.available_kw.values().sum())
            .collect(),
        ..HorizonPlan::failed(now, String::new())
    };
    match p.solve() {
        Ok(sol) => {
            plan.objective = Some(sol.objective);
            plan.solve_ms = Some(sol.solve_ms);
            for s in &p.storage {
                let id = &s.unit.id;
                let soc = sol
                    .periods
                    .iter()
                    .filter_map(|r| r.soc_kwh.get(id))
                    .collect();
                plan.soc_kwh.insert(id.clone(), soc);
            }
            for o in &p.oil {
                let kw = sol
                    .periods
                    .iter()
                    .map(|r| r.setpoints_kw.get(&o.id).unwrap_or(0.0))
                    .collect();
                plan.diesel_kw.insert(o.id.clone(), kw);
            }
            if let Some(c) = &sol.commitment {
                plan.diesel_run = c.running.clone();
                plan.commitment_nodes = Some(c.nodes);
                plan.commitment_proven = Some(c.proven);
            }
            // Never negative: a kWh stored can always be left unused.
            plan.stored_energy_value_per_kwh = Setpoints(
                sol.stored_energy_value_per_kwh
                    .0
                    .into_iter()
                    .map(|(id, v)| (id, v.max(0.0)))
                    .collect(),
            );
        }
        Err(e) => {
            plan.status = match e {
                DispatchError::Infeasible(_) => "infeasible",
                _ => "error",
            }
            .into();
            plan.reason = Some(e.to_string());
        }
    }
    plan
}

#[cfg(test)]
mod tests {
    use super::*;

    const PV: &[(f64, f64)] = &[(6.0, 0.0), (12.0, 100.0), (18.0, 0.0)];

    /// A plant with the demo's fuel curve and a look-ahead.
    const PLANT: &str = r#"
dispatch_period_s = 5.0
voll_per_kwh = 5.0
demand_tag = "MG.Load.P_kW"
fuel_price_per_l = 1.5

[horizon]
periods = 12
period_s = 900.0
demand_forecast_kw = [[0, 60], [6, 80], [12, 70], [18, 100]]

[[unit]]
id = "pv1"
kind = "pv"
name = "PV"
prefix = "MG.PV1"
rated_kw = 100.0
cost_per_kwh = 0.01
forecast_kw = [[6, 0], [12, 95], [18, 0]]

[[unit]]
id = "bess1"
kind = "storage"
name = "Battery"
prefix = "MG.BESS1"
capacity_kwh = 200.0
soc_min_kwh = 20.0
soc_max_kwh = 190.0
max_charge_kw = 50.0
max_discharge_kw = 60.0
cycle_cost_per_kwh = 0.02

[[unit]]
id = "dg1"
kind = "diesel"
name = "Diesel"
prefix = "MG.DG1"
min_kw = 30.0
max_kw = 150.0
fuel_no_load_l_per_h = 12.2175
fuel_l_per_kwh = 0.246
start_cost = 3.0
min_up_s = 1800.0
min_down_s = 900.0
"#;

    /// The plan's objective is the plant's cost function (`unit_cost`, the
    /// replay report's) summed over what the plan does, plus shedding.
    #[test]
    fn the_plans_objective_is_the_reports_cost_function() {
        use gridscada_config::{UnitKind, UnitUsage};
        let mg: MicrogridConfig = toml::from_str(PLANT).unwrap();
        let h = mg.horizon.clone().unwrap();
        for (hour, soc) in [(5.0, 30.0), (9.0, 120.0), (17.0, 60.0)] {
            let now = Timestamp::from_millis((hour * 3600.0 * 1000.0) as i64);
            let measured = DispatchProblem {
                dt_h: 5.0 / 3600.0,
                demand_kw: 70.0,
                voll_per_kwh: 5.0,
                pv: vec![super::super::single::RenewableUnit {
                    id: "pv1".into(),
                    available_kw: if hour > 6.0 && hour < 18.0 { 60.0 } else { 0.0 },
                    cost_per_kwh: 0.01,
                }],
                wind: vec![],
                oil: vec![super::super::single::OilUnit {
                    id: "dg1".into(),
                    running: false,
                    min_kw: 30.0,
                    max_kw: 150.0,
                    cost_per_kwh: 1.5 * 0.246,
                }],
                storage: vec![StorageUnit {
                    id: "bess1".into(),
                    soc_kwh: soc,
                    soc_min_kwh: 20.0,
                    soc_max_kwh: 190.0,
                    max_charge_kw: 50.0,
                    max_discharge_kw: 60.0,
                    eff_charge: 0.95,
                    eff_discharge: 0.95,
                    cycle_cost_per_kwh: 0.02,
                    stored_value_per_kwh: 0.0,
                }],
            };
            let p = horizon_problem(
                &mg,
                &h,
                now,
                &measured,
                &Setpoints::default(),
                &|_| 0.0,
                &|_| None,
            );
            let sol = p.solve().unwrap();
            let dt = p.dt_h;
            let sched = &sol.commitment.as_ref().unwrap().running["dg1"];
            let mut cost = 0.0;
            for u in &mg.units {
                let id = u.id.get_ref();
                let kw = |m: &Setpoints| m.get(id).unwrap_or(0.0);
                let mut usage = UnitUsage::default();
                for r in &sol.periods {
                    match u.kind {
                        UnitKind::Storage => {
                            usage.kwh += kw(&r.discharge_kw) * dt;
                            usage.charged_kwh += kw(&r.charge_kw) * dt;
                        }
                        _ => usage.kwh += kw(&r.setpoints_kw) * dt,
                    }
                }
                if u.kind == UnitKind::Diesel {
                    usage.run_h = sched.iter().filter(|&&on| on).count() as f64 * dt;
                    let mut prev = false;
                    for &on in sched {
                        usage.starts += f64::from(u8::from(on && !prev));
                        prev = on;
                    }
                }
                cost += mg.unit_cost(u, mg.fuel_price(None), &usage);
            }
            cost += sol.periods.iter().map(|r| r.shed_kw * dt).sum::<f64>() * 5.0;
            assert!(
                (cost - sol.objective).abs() < 1e-4 * sol.objective.abs().max(1.0),
                "at {hour} h: cost function {cost} vs objective {}",
                sol.objective
            );
        }
    }

    #[test]
    fn forecast_persists_without_a_curve_and_fades_to_the_curve_with_one() {
        assert_eq!(forecast(42.0, None, 10.0, 3.0, 2.0), 42.0);
        assert_eq!(forecast(-1.0, None, 10.0, 3.0, 2.0), 0.0);
        // Half the clear-sky output at 09:00: clouds. Right now: half.
        let now = forecast(25.0, Some(PV), 9.0, 0.0, 2.0);
        assert!((now - 25.0).abs() < 1e-9, "{now}");
        // At noon (3 h ahead): between half and the full curve.
        let noon = forecast(25.0, Some(PV), 9.0, 3.0, 2.0);
        let expected = 100.0 * (1.0 - 0.5 * (-1.5f64).exp());
        assert!((noon - expected).abs() < 1e-9, "{noon} vs {expected}");
        // Far ahead: the curve itself.
        let late = forecast(25.0, Some(PV), 9.0, 27.0, 2.0);
        assert!((late - 100.0).abs() < 1e-3, "{late}");
        // At night the ratio is unknown: tomorrow's curve as it is.
        let dawn = forecast(0.0, Some(PV), 2.0, 7.0, 2.0);
        assert!((dawn - 50.0).abs() < 1e-9, "{dawn}");
        // Past midnight the curve wraps.
        let demand = &[(0.0, 60.0), (19.0, 105.0)];
        let f = forecast(60.0, Some(demand), 23.0, 2.0, 2.0);
        assert!(f > 0.0 && f.is_finite());
    }
}
