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
    /// The worth of a stored kWh now, per storage id: what the dispatch
    /// prices stored energy at until the next plan.
    pub stored_energy_value_per_kwh: Setpoints,
}

impl HorizonPlan {
    /// Whether the plan was solved (its values may be used).
    pub fn is_optimal(&self) -> bool {
        self.status == "optimal"
    }
}

/// The horizon problem from the single-period problem measured now.
///
/// - Period 0 is the measurement; later periods are [`forecast`]s at their
///   midpoints.
/// - Diesels keep their present commitment in period 0; later they may run
///   anywhere from 0 to full output (`relaxed_commitment`): the commitment
///   rule decides starts and stops outside the LP, and will start a diesel
///   before load goes unserved, so the plan must not price stored energy as
///   if shedding were the only alternative.
/// - Stored energy left at the end is worth `terminal_value` per kWh.
/// - `initial_kw` are the setpoints in force, the start of every ramp.
pub fn horizon_problem(
    mg: &MicrogridConfig,
    h: &HorizonConfig,
    now: Timestamp,
    measured: &DispatchProblem,
    initial_kw: &Setpoints,
    terminal_value: &dyn Fn(&str) -> f64,
) -> HorizonProblem {
    let n = (*h.periods.get_ref()).max(1.0) as usize;
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
            .map(|o| HorizonOil {
                id: o.id.clone(),
                running: o.running,
                min_kw: o.min_kw,
                max_kw: o.max_kw,
                cost_per_kwh: o.cost_per_kwh,
                ramp_kw_per_s: ramp_of(&o.id),
                // A diesel just started or stopped may sit outside its band.
                initial_kw: initial(&o.id, 0.0, o.max_kw).filter(|v| !o.running || *v >= o.min_kw),
                // The commitment rule, not the plan, starts and stops it later.
                relaxed_commitment: true,
            })
            .collect(),
        storage: measured
            .storage
            .iter()
            .map(|s| HorizonStorage {
                unit: StorageUnit {
                    stored_value_per_kwh: 0.0,
                    ..s.clone()
                },
                ramp_kw_per_s: ramp_of(&s.id),
                initial_kw: initial(&s.id, -s.max_charge_kw, s.max_discharge_kw),
                terminal_value_per_kwh: terminal_value(&s.id).max(0.0),
            })
            .collect(),
        reserve: h.reserve.clone(),
        max_renewable_share: None,
        smoothing_cost_per_kw2: 0.0,
    }
}

/// Solves `p` and summarises it as a plan made at `now`.
pub fn plan(p: &HorizonProblem, now: Timestamp) -> HorizonPlan {
    let mut plan = HorizonPlan {
        at: now,
        periods: p.periods.len(),
        period_s: p.dt_h * 3600.0,
        status: "optimal".into(),
        reason: None,
        objective: None,
        solve_ms: None,
        demand_kw: p.periods.iter().map(|f| f.demand_kw).collect(),
        renewable_kw: p
            .periods
            .iter()
            .map(|f| f.available_kw.values().sum())
            .collect(),
        soc_kwh: BTreeMap::new(),
        diesel_kw: BTreeMap::new(),
        stored_energy_value_per_kwh: Setpoints::default(),
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
