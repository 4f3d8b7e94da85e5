//! The multi-period (look-ahead) dispatch: a receding-horizon LP, or a QP when
//! setpoint smoothing is on. `gridscada dispatch solve` takes it for a JSON
//! object with a `"periods"` key.
//!
//! **Owns:** the horizon problem and solution types, their validation, and the
//! model: state-of-charge dynamics across periods, ramp limits, spinning
//! reserve, an optional cap on the instantaneous renewable share, a terminal
//! value for stored energy and an optional quadratic penalty on setpoint
//! changes; plus the post-solve repair and check.
//!
//! **Must not touch:** I/O and commitment (which oil units run in which period
//! is an input).
//!
//! # Input JSON
//!
//! ```json
//! {"dt_h": 0.25, "voll_per_kwh": 5.0,
//!  "periods": [
//!    {"demand_kw": 180.0, "available_kw": {"pv1": 60.0, "wt1": 25.0}},
//!    {"demand_kw": 170.0, "available_kw": {"pv1": 55.0, "wt1": 30.0}, "running": {"dg1": false}}
//!  ],
//!  "pv":   [{"id": "pv1", "cost_per_kwh": 0.0, "ramp_kw_per_s": 10.0, "initial_kw": 58.0}],
//!  "wind": [{"id": "wt1", "cost_per_kwh": 0.01}],
//!  "oil":  [{"id": "dg1", "running": true, "min_kw": 30.0, "max_kw": 150.0,
//!            "cost_per_kwh": 0.35, "ramp_kw_per_s": 5.0, "initial_kw": 40.0}],
//!  "storage": [{"id": "bess1", "soc_kwh": 80.0, "soc_min_kwh": 20.0, "soc_max_kwh": 200.0,
//!               "max_charge_kw": 50.0, "max_discharge_kw": 60.0, "eff_charge": 0.95,
//!               "eff_discharge": 0.95, "cycle_cost_per_kwh": 0.02,
//!               "ramp_kw_per_s": 50.0, "initial_kw": 0.0, "terminal_value_per_kwh": 0.3}],
//!  "reserve": {"load_frac": 0.1, "pv_frac": 0.2, "wind_frac": 0.3, "shortfall_cost_per_kwh": 1.0},
//!  "max_renewable_share": 0.3,
//!  "smoothing_cost_per_kw2": 0.001}
//! ```
//!
//! - `relaxed_commitment` (optional, oil, default false): after the first
//!   period the unit may produce anywhere in `[0, max_kw]`, whatever
//!   `running` says: the LP relaxation of starts and stops decided outside
//!   the problem (the live loop's look-ahead uses it).
//! - `periods[t].available_kw` must give every PV and wind unit's forecast;
//!   `periods[t].running` optionally overrides an oil unit's `running` in
//!   period t (the commitment schedule).
//! - `soc_kwh` is the state of charge at the start of the horizon.
//! - Optional per unit: `ramp_kw_per_s` (0 or absent = unlimited; the limit per
//!   period is `ramp_kw_per_s · 3600 · dt_h`) and `initial_kw` (the setpoint in
//!   force now, the start of the first ramp and smoothing step). PV and wind
//!   are limited when ramping up only (nature ramps them down); oil units in
//!   both directions between periods in which they run; storage on its net
//!   setpoint in both directions.
//! - `reserve` (optional): in every period the headroom of running oil units
//!   (`max_kw − p`) plus each storage unit's discharge headroom (power and
//!   stored energy at the start of the period) must cover `load_frac·demand +
//!   pv_frac·Σp_pv + wind_frac·Σp_wind`; a shortfall is allowed at
//!   `shortfall_cost_per_kwh` so the problem stays feasible.
//! - `max_renewable_share` (optional): `Σp_pv + Σp_wind ≤ share·demand`.
//! - `terminal_value_per_kwh` (optional, storage): worth of energy left at the
//!   end of the horizon, subtracted from the cost.
//! - `final_soc_min_kwh` (optional, storage): the horizon ends with at least
//!   this state of charge.
//! - `optimize_commitment` (optional, oil, default false): the problem decides
//!   in which periods the unit runs (branch and bound over on/off variables,
//!   each relaxation solved by clarabel), with `no_load_cost_per_h` (paid per
//!   hour running), `start_cost`, `min_up_h`, `min_down_h` and
//!   `hours_in_state` (how long it has been in its present state `running`;
//!   absent: long enough). The answer then has `commitment`: per unit its
//!   on/off per period, its starts, the relaxations solved (`nodes`), and
//!   whether the schedule is `proven` within 0.1 % of the optimum, with the
//!   `lower_bound` no schedule beats. `max_commitment_nodes` (optional,
//!   default 4000, at most 200,000) caps the relaxations.
//! - `smoothing_cost_per_kw2` (optional, > 0 makes it a QP): adds
//!   `w·Σ (setpoint_t − setpoint_{t−1})²` over units and periods.
//!
//! Objective: `Σ_t dt_h·(Σ c·p + Σ cycle·(ch+dis) + voll·shed +
//! shortfall_cost·shortfall) − Σ terminal_value·soc_end + smoothing`.
//! SoC dynamics: `soc_t = soc_{t−1} + eff_c·dt·ch_t − dt·dis_t/eff_d`,
//! `soc_min ≤ soc_t ≤ soc_max`.
//!
//! This file holds the types, the precheck and the solve; reading and
//! validating the JSON is in `horizon/validate.rs`, the model in
//! `horizon/model.rs`.

use std::collections::BTreeMap;
use std::time::Instant;

use serde::{Deserialize, Serialize};

use super::lp::FEAS_TOL;
use super::single::{rebalance, StorageUnit};
use super::{DispatchError, Setpoints};

mod commitment;
mod model;
#[cfg(test)]
mod tests;
mod validate;
pub(crate) use validate::periods_within_limit;

/// Longest horizon accepted (keeps untrusted input from exhausting memory).
pub const MAX_PERIODS: usize = 10_000;

/// Demand and availability forecast of one period.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PeriodForecast {
    pub demand_kw: f64,
    /// Forecast available power per PV/wind unit id, kW.
    pub available_kw: BTreeMap<String, f64>,
    /// Commitment per oil unit id in this period (default: the unit's `running`).
    #[serde(default)]
    pub running: BTreeMap<String, bool>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HorizonRenewable {
    pub id: String,
    pub cost_per_kwh: f64,
    #[serde(default)]
    pub ramp_kw_per_s: f64,
    #[serde(default)]
    pub initial_kw: Option<f64>,
}

#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct HorizonOil {
    pub id: String,
    pub running: bool,
    pub min_kw: f64,
    pub max_kw: f64,
    pub cost_per_kwh: f64,
    #[serde(default)]
    pub ramp_kw_per_s: f64,
    #[serde(default)]
    pub initial_kw: Option<f64>,
    /// After the first period the unit may produce anywhere in
    /// `[0, max_kw]`: the LP relaxation of starts and stops that a rule
    /// outside the problem decides later.
    #[serde(default)]
    pub relaxed_commitment: bool,
    /// The problem decides when the unit runs, in every period (optimal
    /// commitment, by branch and bound): `running` is its state now.
    #[serde(default)]
    pub optimize_commitment: bool,
    /// Cost of each hour running, whatever the load (no-load fuel).
    #[serde(default)]
    pub no_load_cost_per_h: f64,
    /// Cost of each start.
    #[serde(default)]
    pub start_cost: f64,
    /// Minimum up and down times, h.
    #[serde(default)]
    pub min_up_h: f64,
    #[serde(default)]
    pub min_down_h: f64,
    /// How long the unit has been in its present state (`running`), h;
    /// absent: long enough for any minimum up or down time.
    #[serde(default)]
    pub hours_in_state: Option<f64>,
}

impl HorizonOil {
    /// The first periods whose state is forced by the minimum up or down
    /// time still running now: how many, and the state.
    pub(crate) fn forced_periods(&self, dt_h: f64) -> usize {
        let Some(in_state) = self.hours_in_state else {
            return 0;
        };
        let min = if self.running {
            self.min_up_h
        } else {
            self.min_down_h
        };
        let left = (min - in_state).max(0.0);
        // A remainder within a millisecond of a period boundary ends there.
        ((left / dt_h) - 1e-9 / dt_h.max(1e-9)).ceil().max(0.0) as usize
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HorizonStorage {
    #[serde(flatten)]
    pub unit: StorageUnit,
    #[serde(default)]
    pub ramp_kw_per_s: f64,
    #[serde(default)]
    pub initial_kw: Option<f64>,
    #[serde(default)]
    pub terminal_value_per_kwh: f64,
    /// State of charge the horizon must end with at least, kWh (a perfect
    /// foresight run ends where the realized run ended, for a fair cost).
    #[serde(default)]
    pub final_soc_min_kwh: Option<f64>,
}

/// Spinning reserve requirement: the same rule as `[microgrid.horizon]
/// reserve` in the plant configuration.
pub use gridscada_config::ReserveConfig as ReserveRule;

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HorizonProblem {
    pub dt_h: f64,
    pub voll_per_kwh: f64,
    pub periods: Vec<PeriodForecast>,
    #[serde(default)]
    pub pv: Vec<HorizonRenewable>,
    #[serde(default)]
    pub wind: Vec<HorizonRenewable>,
    #[serde(default)]
    pub oil: Vec<HorizonOil>,
    #[serde(default)]
    pub storage: Vec<HorizonStorage>,
    #[serde(default)]
    pub reserve: Option<ReserveRule>,
    #[serde(default)]
    pub max_renewable_share: Option<f64>,
    #[serde(default)]
    pub smoothing_cost_per_kw2: f64,
    /// Relaxations the commitment search may solve (default 4000).
    #[serde(default)]
    pub max_commitment_nodes: Option<usize>,
}

/// One period of a horizon solution.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PeriodResult {
    /// Per unit id, kW; storage is discharge − charge.
    pub setpoints_kw: Setpoints,
    pub shed_kw: f64,
    /// Per storage id.
    pub charge_kw: Setpoints,
    pub discharge_kw: Setpoints,
    /// State of charge at the end of the period, per storage id.
    pub soc_kwh: Setpoints,
    /// Spinning reserve not covered (0 without a reserve rule), kW.
    pub reserve_shortfall_kw: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct HorizonSolution {
    pub status: &'static str,
    pub objective: f64,
    /// Per storage id: how much the horizon's cost falls per kWh more stored
    /// at the start (the marginal value of stored energy), per kWh. The live
    /// loop prices stored energy with it in the single-period LP.
    pub stored_energy_value_per_kwh: Setpoints,
    pub periods: Vec<PeriodResult>,
    /// Per oil unit whose commitment the problem decided: whether it runs in
    /// each period, and the search's figures.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub commitment: Option<CommitmentResult>,
    pub solve_ms: f64,
}

/// The on/off schedule a horizon chose, and how sure it is.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CommitmentResult {
    /// Per oil unit id: runs in period t.
    pub running: BTreeMap<String, Vec<bool>>,
    /// Starts in the schedule (including one in period 0).
    pub starts: BTreeMap<String, u32>,
    /// Relaxations solved by the branch and bound.
    pub nodes: usize,
    /// The schedule is proven within the gap of the optimum.
    pub proven: bool,
    /// No schedule costs less than this.
    pub lower_bound: f64,
}

impl HorizonProblem {
    fn running(&self, t: usize, k: usize) -> bool {
        let u = &self.oil[k];
        self.periods[t]
            .running
            .get(&u.id)
            .copied()
            .unwrap_or(u.running)
    }

    /// Output bounds of oil unit `k` in period `t`, and whether it counts as
    /// online (reserve headroom, ramps).
    fn oil_band(&self, t: usize, k: usize) -> (f64, f64, bool) {
        let u = &self.oil[k];
        if u.optimize_commitment || (u.relaxed_commitment && t > 0) {
            (0.0, u.max_kw, true)
        } else if self.running(t, k) {
            (u.min_kw, u.max_kw, true)
        } else {
            (0.0, 0.0, false)
        }
    }

    /// A clear reason for the obvious infeasibility: in some period the
    /// running oil units' minimum load exceeds demand plus storage charging power.
    pub fn precheck(&self) -> Option<String> {
        let absorb: f64 = self.storage.iter().map(|s| s.unit.max_charge_kw).sum();
        for (t, p) in self.periods.iter().enumerate() {
            let forced: f64 = (0..self.oil.len())
                .map(|k| {
                    let u = &self.oil[k];
                    if u.optimize_commitment {
                        let on = u.running && t < u.forced_periods(self.dt_h);
                        if on {
                            u.min_kw
                        } else {
                            0.0
                        }
                    } else {
                        self.oil_band(t, k).0
                    }
                })
                .sum();
            if forced > p.demand_kw + absorb + FEAS_TOL {
                return Some(format!(
                    "period {t}: running oil units must produce at least {forced} kW (minimum \
                     stable load), but demand is {} kW and storage can absorb at most {absorb} kW",
                    p.demand_kw
                ));
            }
        }
        None
    }

    pub fn solve(&self) -> Result<HorizonSolution, DispatchError> {
        let started = Instant::now();
        self.validate("").map_err(DispatchError::Invalid)?;
        if let Some(reason) = self.precheck() {
            return Err(DispatchError::Infeasible(reason));
        }
        if !self.oil.iter().any(|o| o.optimize_commitment) {
            return self.solve_fixed(started);
        }
        // Decide the schedule, then solve the dispatch of that schedule at
        // full precision (its prices give the worth of stored energy) and
        // add what running and starting cost.
        let commit = commitment::decide(self)?;
        let fixed = commitment::with_schedule(self, &commit.running);
        let mut sol = fixed.solve_fixed(started)?;
        sol.objective += commitment::fixed_costs(self, &commit.running);
        sol.commitment = Some(commit);
        sol.solve_ms = started.elapsed().as_secs_f64() * 1e3;
        Ok(sol)
    }

    /// The worth of a stored kWh at the start of each period, per storage
    /// unit, from the problem's LP relaxation: commitment decided in
    /// fractions of a period (a unit may run part of a period), which is the
    /// convex envelope of the on/off schedules and cheap to solve over a
    /// long horizon. The live look-ahead takes its terminal value from it,
    /// so a short plan values what it leaves in storage as the day ahead
    /// does.
    pub fn relaxed_stored_energy_values(&self) -> Result<Vec<Setpoints>, DispatchError> {
        self.validate("").map_err(DispatchError::Invalid)?;
        let (model, v) = self.build();
        let (_, prices) = model.solve_with_prices()?;
        Ok(v.soc_rows
            .iter()
            .map(|rows| {
                Setpoints(
                    self.storage
                        .iter()
                        .zip(rows)
                        .map(|(s, &row)| (s.unit.id.clone(), prices[row]))
                        .collect(),
                )
            })
            .collect())
    }

    /// The dispatch with every oil unit's commitment given.
    fn solve_fixed(&self, started: Instant) -> Result<HorizonSolution, DispatchError> {
        let (model, v) = self.build();
        let (mut x, prices) = model.solve_with_prices()?;
        // Repair: state of charge exactly from the (clipped) flows, then the
        // power balance of each period by moving non-storage variables.
        for (k, s) in self.storage.iter().enumerate() {
            let mut soc = s.unit.soc_kwh;
            for t in 0..self.periods.len() {
                let (ch, dis, sv) = v.storage[t][k];
                soc += s.unit.eff_charge * self.dt_h * x[ch]
                    - self.dt_h * x[dis] / s.unit.eff_discharge;
                x[sv] = soc;
            }
        }
        for t in 0..self.periods.len() {
            rebalance(&model, v.balance_row[t], &mut x, &v.balance_adjust[t]);
        }
        model.check(&x, FEAS_TOL).map_err(|e| {
            DispatchError::Solver(format!("solver answer failed the constraint check: {e}"))
        })?;
        let periods = (0..self.periods.len())
            .map(|t| {
                let mut sp: Vec<(String, f64)> = v.units[t]
                    .iter()
                    .map(|(id, j)| (id.clone(), x[*j]))
                    .collect();
                let mut ch = Vec::new();
                let mut dis = Vec::new();
                let mut soc = Vec::new();
                for (k, s) in self.storage.iter().enumerate() {
                    let (c, d, sv) = v.storage[t][k];
                    sp.push((s.unit.id.clone(), x[d] - x[c]));
                    ch.push((s.unit.id.clone(), x[c]));
                    dis.push((s.unit.id.clone(), x[d]));
                    soc.push((s.unit.id.clone(), x[sv]));
                }
                PeriodResult {
                    setpoints_kw: Setpoints(sp),
                    shed_kw: x[v.shed[t]],
                    charge_kw: Setpoints(ch),
                    discharge_kw: Setpoints(dis),
                    soc_kwh: Setpoints(soc),
                    reserve_shortfall_kw: v.shortfall[t].map_or(0.0, |j| x[j]),
                }
            })
            .collect();
        // The worth of one more kWh stored now: the price of the starting
        // state of charge in the first period's dynamics.
        let stored_energy_value_per_kwh = Setpoints(
            self.storage
                .iter()
                .zip(&v.first_soc_row)
                .map(|(s, &row)| (s.unit.id.clone(), prices[row]))
                .collect(),
        );
        Ok(HorizonSolution {
            status: "optimal",
            objective: model.objective(&x),
            stored_energy_value_per_kwh,
            periods,
            commitment: None,
            solve_ms: started.elapsed().as_secs_f64() * 1e3,
        })
    }
}
