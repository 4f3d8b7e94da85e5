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
//! - `smoothing_cost_per_kw2` (optional, > 0 makes it a QP): adds
//!   `w·Σ (setpoint_t − setpoint_{t−1})²` over units and periods.
//!
//! Objective: `Σ_t dt_h·(Σ c·p + Σ cycle·(ch+dis) + voll·shed +
//! shortfall_cost·shortfall) − Σ terminal_value·soc_end + smoothing`.
//! SoC dynamics: `soc_t = soc_{t−1} + eff_c·dt·ch_t − dt·dis_t/eff_d`,
//! `soc_min ≤ soc_t ≤ soc_max`.

use std::collections::BTreeMap;
use std::time::Instant;

use serde::{Deserialize, Serialize};
use serde_json::Value;

use super::input::{index, join, kind, InputError, Obj};
use super::lp::{Model, Sense, FEAS_TOL};
use super::single::{bad, dt_h_valid, nonneg, parse_list, rebalance, unique_ids, StorageUnit};
use super::{DispatchError, Setpoints};

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

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
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
    pub solve_ms: f64,
}

fn opt_nonneg(o: &mut Obj<'_>, key: &'static str) -> Result<f64, InputError> {
    Ok(o.opt_num(key)?.unwrap_or(0.0))
}

impl HorizonRenewable {
    fn from_value(v: &Value, path: &str) -> Result<Self, InputError> {
        let mut o = Obj::new(v, path)?;
        let u = HorizonRenewable {
            id: o.string("id")?,
            cost_per_kwh: o.num("cost_per_kwh")?,
            ramp_kw_per_s: opt_nonneg(&mut o, "ramp_kw_per_s")?,
            initial_kw: o.opt_num("initial_kw")?,
        };
        o.finish()?;
        Ok(u)
    }
    fn validate(&self, path: &str) -> Result<(), InputError> {
        nonneg(format!("{path}.cost_per_kwh"), self.cost_per_kwh)?;
        nonneg(format!("{path}.ramp_kw_per_s"), self.ramp_kw_per_s)?;
        if let Some(i) = self.initial_kw {
            nonneg(format!("{path}.initial_kw"), i)?;
        }
        Ok(())
    }
}

impl HorizonOil {
    fn from_value(v: &Value, path: &str) -> Result<Self, InputError> {
        let mut o = Obj::new(v, path)?;
        let u = HorizonOil {
            id: o.string("id")?,
            running: o.bool("running")?,
            min_kw: o.num("min_kw")?,
            max_kw: o.num("max_kw")?,
            cost_per_kwh: o.num("cost_per_kwh")?,
            ramp_kw_per_s: opt_nonneg(&mut o, "ramp_kw_per_s")?,
            initial_kw: o.opt_num("initial_kw")?,
            relaxed_commitment: o.opt_bool("relaxed_commitment")?.unwrap_or(false),
        };
        o.finish()?;
        Ok(u)
    }
    fn validate(&self, path: &str) -> Result<(), InputError> {
        nonneg(format!("{path}.min_kw"), self.min_kw)?;
        nonneg(format!("{path}.max_kw"), self.max_kw)?;
        nonneg(format!("{path}.cost_per_kwh"), self.cost_per_kwh)?;
        nonneg(format!("{path}.ramp_kw_per_s"), self.ramp_kw_per_s)?;
        if self.max_kw < self.min_kw {
            return Err(bad(
                format!("{path}.max_kw"),
                format!("{} is below min_kw {}", self.max_kw, self.min_kw),
            ));
        }
        if let Some(i) = self.initial_kw {
            nonneg(format!("{path}.initial_kw"), i)?;
        }
        Ok(())
    }
}

impl HorizonStorage {
    fn from_value(v: &Value, path: &str) -> Result<Self, InputError> {
        let mut o = Obj::new(v, path)?;
        let unit = StorageUnit::read_fields(&mut o)?;
        let u = HorizonStorage {
            unit,
            ramp_kw_per_s: opt_nonneg(&mut o, "ramp_kw_per_s")?,
            initial_kw: o.opt_num("initial_kw")?,
            terminal_value_per_kwh: opt_nonneg(&mut o, "terminal_value_per_kwh")?,
        };
        o.finish()?;
        Ok(u)
    }
    fn validate(&self, path: &str) -> Result<(), InputError> {
        self.unit.validate(path)?;
        nonneg(format!("{path}.ramp_kw_per_s"), self.ramp_kw_per_s)?;
        nonneg(
            format!("{path}.terminal_value_per_kwh"),
            self.terminal_value_per_kwh,
        )?;
        if let Some(i) = self.initial_kw {
            if !(i.is_finite() && i >= -self.unit.max_charge_kw && i <= self.unit.max_discharge_kw)
            {
                return Err(bad(
                    format!("{path}.initial_kw"),
                    format!(
                        "{i} is outside [-max_charge_kw, max_discharge_kw] = [{}, {}]",
                        -self.unit.max_charge_kw, self.unit.max_discharge_kw
                    ),
                ));
            }
        }
        Ok(())
    }
}

fn period_from_value(v: &Value, path: &str) -> Result<PeriodForecast, InputError> {
    let mut o = Obj::new(v, path)?;
    let demand_kw = o.num("demand_kw")?;
    let mut available_kw = BTreeMap::new();
    if let Some(a) = o.opt_obj("available_kw")? {
        for (k, v) in a.entries() {
            let p = join(&a.path, k);
            match v.as_f64() {
                Some(x) if v.is_number() => {
                    available_kw.insert(k.clone(), x);
                }
                _ => {
                    return Err(bad(p, format!("expected a number, found {}", kind(v))));
                }
            }
        }
    }
    let mut running = BTreeMap::new();
    if let Some(r) = o.opt_obj("running")? {
        for (k, v) in r.entries() {
            match v {
                Value::Bool(b) => {
                    running.insert(k.clone(), *b);
                }
                other => {
                    return Err(bad(
                        join(&r.path, k),
                        format!("expected true or false, found {}", kind(other)),
                    ))
                }
            }
        }
    }
    o.finish()?;
    Ok(PeriodForecast {
        demand_kw,
        available_kw,
        running,
    })
}

impl HorizonProblem {
    pub fn from_value(v: &Value, path: &str) -> Result<Self, InputError> {
        let mut o = Obj::new(v, path)?;
        let dt_h = o.num("dt_h")?;
        let voll_per_kwh = o.num("voll_per_kwh")?;
        let (ppath, items) = o.list("periods", false)?;
        if items.len() > MAX_PERIODS {
            return Err(bad(
                ppath,
                format!(
                    "{} periods; at most {MAX_PERIODS} are accepted",
                    items.len()
                ),
            ));
        }
        let periods = items
            .iter()
            .enumerate()
            .map(|(i, v)| period_from_value(v, &index(&ppath, i)))
            .collect::<Result<Vec<_>, _>>()?;
        let pv = parse_list(&mut o, "pv", HorizonRenewable::from_value)?;
        let wind = parse_list(&mut o, "wind", HorizonRenewable::from_value)?;
        let oil = parse_list(&mut o, "oil", HorizonOil::from_value)?;
        let storage = parse_list(&mut o, "storage", HorizonStorage::from_value)?;
        let reserve = match o.opt_obj("reserve")? {
            None => None,
            Some(mut r) => {
                let rule = ReserveRule {
                    load_frac: opt_nonneg(&mut r, "load_frac")?,
                    pv_frac: opt_nonneg(&mut r, "pv_frac")?,
                    wind_frac: opt_nonneg(&mut r, "wind_frac")?,
                    shortfall_cost_per_kwh: r.num("shortfall_cost_per_kwh")?,
                };
                r.finish()?;
                Some(rule)
            }
        };
        let max_renewable_share = o.opt_num("max_renewable_share")?;
        let smoothing_cost_per_kw2 = opt_nonneg(&mut o, "smoothing_cost_per_kw2")?;
        o.finish()?;
        Ok(HorizonProblem {
            dt_h,
            voll_per_kwh,
            periods,
            pv,
            wind,
            oil,
            storage,
            reserve,
            max_renewable_share,
            smoothing_cost_per_kw2,
        })
    }

    pub fn validate(&self, prefix: &str) -> Result<(), InputError> {
        let at = |k: &str| join(prefix, k);
        dt_h_valid(at("dt_h"), self.dt_h)?;
        nonneg(at("voll_per_kwh"), self.voll_per_kwh)?;
        if self.periods.is_empty() {
            return Err(bad(at("periods"), "needs at least one period"));
        }
        if self.periods.len() > MAX_PERIODS {
            return Err(bad(
                at("periods"),
                format!("more than {MAX_PERIODS} periods"),
            ));
        }
        for (i, u) in self.pv.iter().enumerate() {
            u.validate(&index(&at("pv"), i))?;
        }
        for (i, u) in self.wind.iter().enumerate() {
            u.validate(&index(&at("wind"), i))?;
        }
        for (i, u) in self.oil.iter().enumerate() {
            u.validate(&index(&at("oil"), i))?;
        }
        for (i, u) in self.storage.iter().enumerate() {
            u.validate(&index(&at("storage"), i))?;
        }
        let mut ids: Vec<(String, &str)> = Vec::new();
        for (k, list) in [("pv", &self.pv), ("wind", &self.wind)] {
            ids.extend(
                list.iter()
                    .enumerate()
                    .map(|(i, u)| (format!("{}.id", index(&at(k), i)), u.id.as_str())),
            );
        }
        ids.extend(
            self.oil
                .iter()
                .enumerate()
                .map(|(i, u)| (format!("{}.id", index(&at("oil"), i)), u.id.as_str())),
        );
        ids.extend(self.storage.iter().enumerate().map(|(i, u)| {
            (
                format!("{}.id", index(&at("storage"), i)),
                u.unit.id.as_str(),
            )
        }));
        unique_ids(ids.clone().into_iter())?;
        if let Some(r) = &self.reserve {
            let rp = at("reserve");
            nonneg(join(&rp, "load_frac"), r.load_frac)?;
            nonneg(join(&rp, "pv_frac"), r.pv_frac)?;
            nonneg(join(&rp, "wind_frac"), r.wind_frac)?;
            nonneg(
                join(&rp, "shortfall_cost_per_kwh"),
                r.shortfall_cost_per_kwh,
            )?;
        }
        if let Some(s) = self.max_renewable_share {
            if !(s.is_finite() && (0.0..=1.0).contains(&s)) {
                return Err(bad(
                    at("max_renewable_share"),
                    format!("{s} is outside [0, 1]"),
                ));
            }
        }
        nonneg(at("smoothing_cost_per_kw2"), self.smoothing_cost_per_kw2)?;
        let renewables: Vec<&str> = self
            .pv
            .iter()
            .chain(&self.wind)
            .map(|u| u.id.as_str())
            .collect();
        let oils: Vec<&str> = self.oil.iter().map(|u| u.id.as_str()).collect();
        for (t, p) in self.periods.iter().enumerate() {
            let pp = index(&at("periods"), t);
            nonneg(join(&pp, "demand_kw"), p.demand_kw)?;
            for (id, v) in &p.available_kw {
                let path = join(&join(&pp, "available_kw"), id);
                if !renewables.contains(&id.as_str()) {
                    return Err(bad(path, "is not a PV or wind unit"));
                }
                nonneg(path, *v)?;
            }
            for id in &renewables {
                if !p.available_kw.contains_key(*id) {
                    return Err(bad(
                        join(&pp, "available_kw"),
                        format!("no forecast for '{id}'"),
                    ));
                }
            }
            for id in p.running.keys() {
                if !oils.contains(&id.as_str()) {
                    return Err(bad(join(&join(&pp, "running"), id), "is not an oil unit"));
                }
            }
        }
        Ok(())
    }

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
        if u.relaxed_commitment && t > 0 {
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
            let forced: f64 = (0..self.oil.len()).map(|k| self.oil_band(t, k).0).sum();
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
            solve_ms: started.elapsed().as_secs_f64() * 1e3,
        })
    }

    fn build(&self) -> (Model, HVars) {
        let dt = self.dt_h;
        let nt = self.periods.len();
        let w = self.smoothing_cost_per_kw2;
        let ramp = |r: f64| if r > 0.0 { Some(r * 3600.0 * dt) } else { None };
        let mut m = Model::default();
        let mut v = HVars::default();
        // Per unit: variable of the previous period, for ramps and smoothing.
        let mut prev_ren: Vec<Option<usize>> = vec![None; self.pv.len() + self.wind.len()];
        let mut prev_oil: Vec<Option<usize>> = vec![None; self.oil.len()];
        let mut prev_sto: Vec<Option<(usize, usize, usize)>> = vec![None; self.storage.len()];
        let renewables: Vec<(&HorizonRenewable, bool)> = self
            .pv
            .iter()
            .map(|u| (u, true))
            .chain(self.wind.iter().map(|u| (u, false)))
            .collect();
        for (t, per) in self.periods.iter().enumerate() {
            let mut units = Vec::new();
            let mut bal: Vec<(usize, f64)> = Vec::new();
            let mut adjust: Vec<(usize, f64)> = Vec::new();
            let mut ren_vars: Vec<(usize, bool)> = Vec::new();
            for (i, (u, is_pv)) in renewables.iter().enumerate() {
                let avail = per.available_kw.get(&u.id).copied().unwrap_or(0.0);
                let j = m.var(
                    format!("{} output in period {t}", u.id),
                    0.0,
                    avail,
                    dt * u.cost_per_kwh,
                );
                units.push((u.id.clone(), j));
                bal.push((j, 1.0));
                adjust.push((j, 1.0));
                ren_vars.push((j, *is_pv));
                if let Some(r) = ramp(u.ramp_kw_per_s) {
                    match (prev_ren[i], u.initial_kw) {
                        (Some(p), _) => m.row(
                            format!("{} ramp-up limit in period {t}", u.id),
                            vec![(j, 1.0), (p, -1.0)],
                            Sense::Le,
                            r,
                        ),
                        (None, Some(init)) => m.row(
                            format!("{} ramp-up limit in period {t}", u.id),
                            vec![(j, 1.0)],
                            Sense::Le,
                            init + r,
                        ),
                        (None, None) => {}
                    }
                }
                if w > 0.0 {
                    match (prev_ren[i], u.initial_kw) {
                        (Some(p), _) => m.add_square(w, &[(j, 1.0), (p, -1.0)], 0.0),
                        (None, Some(init)) => m.add_square(w, &[(j, 1.0)], init),
                        (None, None) => {}
                    }
                }
                prev_ren[i] = Some(j);
            }
            let mut oil_running: Vec<(usize, f64)> = Vec::new();
            for (k, u) in self.oil.iter().enumerate() {
                let (lo, hi, run) = self.oil_band(t, k);
                let j = m.var(
                    format!("{} output in period {t}", u.id),
                    lo,
                    hi,
                    dt * u.cost_per_kwh,
                );
                units.push((u.id.clone(), j));
                bal.push((j, 1.0));
                if run {
                    adjust.push((j, 1.0));
                    oil_running.push((j, u.max_kw));
                }
                let was_running = if t == 0 {
                    u.initial_kw.is_some()
                } else {
                    self.oil_band(t - 1, k).2
                };
                if let (Some(r), true, true) = (ramp(u.ramp_kw_per_s), run, was_running) {
                    let (coefs, rhs0): (Vec<(usize, f64)>, f64) = match prev_oil[k] {
                        Some(p) => (vec![(j, 1.0), (p, -1.0)], 0.0),
                        None => (vec![(j, 1.0)], u.initial_kw.unwrap_or(0.0)),
                    };
                    let neg: Vec<(usize, f64)> = coefs.iter().map(|&(a, c)| (a, -c)).collect();
                    m.row(
                        format!("{} ramp-up limit in period {t}", u.id),
                        coefs,
                        Sense::Le,
                        rhs0 + r,
                    );
                    m.row(
                        format!("{} ramp-down limit in period {t}", u.id),
                        neg,
                        Sense::Le,
                        r - rhs0,
                    );
                }
                if w > 0.0 {
                    match (prev_oil[k], u.initial_kw) {
                        (Some(p), _) => m.add_square(w, &[(j, 1.0), (p, -1.0)], 0.0),
                        (None, Some(init)) => m.add_square(w, &[(j, 1.0)], init),
                        (None, None) => {}
                    }
                }
                prev_oil[k] = Some(j);
            }
            let mut sto_vars = Vec::new();
            let mut headroom: Vec<usize> = Vec::new();
            for (k, s) in self.storage.iter().enumerate() {
                let u = &s.unit;
                let c = dt * u.cycle_cost_per_kwh;
                let ch = m.var(
                    format!("{} charge in period {t}", u.id),
                    0.0,
                    u.max_charge_kw,
                    c,
                );
                let dis = m.var(
                    format!("{} discharge in period {t}", u.id),
                    0.0,
                    u.max_discharge_kw,
                    c,
                );
                let end_value = if t + 1 == nt {
                    -s.terminal_value_per_kwh
                } else {
                    0.0
                };
                let soc = m.var(
                    format!("{} state of charge at the end of period {t}", u.id),
                    u.soc_min_kwh,
                    u.soc_max_kwh,
                    end_value,
                );
                bal.push((ch, -1.0));
                bal.push((dis, 1.0));
                // soc_t − soc_{t−1} − eff_c·dt·ch + dt/eff_d·dis = 0
                let mut dyn_row = vec![
                    (soc, 1.0),
                    (ch, -u.eff_charge * dt),
                    (dis, dt / u.eff_discharge),
                ];
                let mut rhs = 0.0;
                match prev_sto[k] {
                    Some((_, _, ps)) => dyn_row.push((ps, -1.0)),
                    None => {
                        rhs = u.soc_kwh;
                        v.first_soc_row.push(m.rows.len());
                    }
                }
                m.row(
                    format!("{} state-of-charge dynamics in period {t}", u.id),
                    dyn_row,
                    Sense::Eq,
                    rhs,
                );
                let net = [(dis, 1.0), (ch, -1.0)];
                if let Some(r) = ramp(s.ramp_kw_per_s) {
                    let (coefs, rhs0): (Vec<(usize, f64)>, f64) = match (prev_sto[k], s.initial_kw)
                    {
                        (Some((pc, pd, _)), _) => {
                            (vec![net[0], net[1], (pd, -1.0), (pc, 1.0)], 0.0)
                        }
                        (None, Some(init)) => (net.to_vec(), init),
                        (None, None) => (Vec::new(), 0.0),
                    };
                    if !coefs.is_empty() {
                        let neg: Vec<(usize, f64)> = coefs.iter().map(|&(a, c)| (a, -c)).collect();
                        m.row(
                            format!("{} ramp-up limit in period {t}", u.id),
                            coefs,
                            Sense::Le,
                            rhs0 + r,
                        );
                        m.row(
                            format!("{} ramp-down limit in period {t}", u.id),
                            neg,
                            Sense::Le,
                            r - rhs0,
                        );
                    }
                }
                if w > 0.0 {
                    match (prev_sto[k], s.initial_kw) {
                        (Some((pc, pd, _)), _) => {
                            m.add_square(w, &[net[0], net[1], (pd, -1.0), (pc, 1.0)], 0.0)
                        }
                        (None, Some(init)) => m.add_square(w, &net, init),
                        (None, None) => {}
                    }
                }
                if self.reserve.is_some() {
                    let h = m.var(
                        format!("{} reserve headroom in period {t}", u.id),
                        0.0,
                        u.max_discharge_kw + u.max_charge_kw,
                        0.0,
                    );
                    // h ≤ max_dis − dis + ch
                    m.row(
                        format!("{} reserve power limit in period {t}", u.id),
                        vec![(h, 1.0), (dis, 1.0), (ch, -1.0)],
                        Sense::Le,
                        u.max_discharge_kw,
                    );
                    // h ≤ (soc_{t−1} − soc_min)·eff_d/dt − dis + ch
                    let g = u.eff_discharge / dt;
                    let mut row = vec![(h, 1.0), (dis, 1.0), (ch, -1.0)];
                    let rhs = match prev_sto[k] {
                        Some((_, _, ps)) => {
                            row.push((ps, -g));
                            -u.soc_min_kwh * g
                        }
                        None => (u.soc_kwh - u.soc_min_kwh) * g,
                    };
                    m.row(
                        format!("{} reserve energy limit in period {t}", u.id),
                        row,
                        Sense::Le,
                        rhs,
                    );
                    headroom.push(h);
                }
                sto_vars.push((ch, dis, soc));
                prev_sto[k] = Some((ch, dis, soc));
            }
            let shed = m.var(
                format!("load shed in period {t}"),
                0.0,
                per.demand_kw,
                dt * self.voll_per_kwh,
            );
            bal.push((shed, 1.0));
            adjust.insert(0, (shed, 1.0));
            v.balance_row.push(m.rows.len());
            m.row(
                format!("power balance in period {t}"),
                bal,
                Sense::Eq,
                per.demand_kw,
            );
            let mut shortfall = None;
            if let Some(r) = &self.reserve {
                let need_max = r.load_frac * per.demand_kw
                    + ren_vars
                        .iter()
                        .map(|&(j, is_pv)| m.ub[j] * if is_pv { r.pv_frac } else { r.wind_frac })
                        .sum::<f64>();
                let sf = m.var(
                    format!("reserve shortfall in period {t}"),
                    0.0,
                    need_max,
                    dt * r.shortfall_cost_per_kwh,
                );
                // Σ(max − p_oil) + Σh + sf ≥ load_frac·D + pv_frac·Σp_pv + wind_frac·Σp_wind
                let mut row: Vec<(usize, f64)> =
                    oil_running.iter().map(|&(j, _)| (j, 1.0)).collect();
                row.extend(headroom.iter().map(|&h| (h, -1.0)));
                row.push((sf, -1.0));
                row.extend(
                    ren_vars
                        .iter()
                        .map(|&(j, is_pv)| (j, if is_pv { r.pv_frac } else { r.wind_frac })),
                );
                let rhs = oil_running.iter().map(|&(_, mx)| mx).sum::<f64>()
                    - r.load_frac * per.demand_kw;
                m.row(
                    format!("spinning reserve in period {t}"),
                    row,
                    Sense::Le,
                    rhs,
                );
                shortfall = Some(sf);
            }
            if let Some(share) = self.max_renewable_share {
                m.row(
                    format!("renewable share cap in period {t}"),
                    ren_vars.iter().map(|&(j, _)| (j, 1.0)).collect(),
                    Sense::Le,
                    share * per.demand_kw,
                );
            }
            v.units.push(units);
            v.storage.push(sto_vars);
            v.shed.push(shed);
            v.shortfall.push(shortfall);
            v.balance_adjust.push(adjust);
        }
        (m, v)
    }
}

#[derive(Default)]
struct HVars {
    units: Vec<Vec<(String, usize)>>,
    /// Per period, per storage: (charge, discharge, soc at end).
    storage: Vec<Vec<(usize, usize, usize)>>,
    shed: Vec<usize>,
    shortfall: Vec<Option<usize>>,
    balance_row: Vec<usize>,
    balance_adjust: Vec<Vec<(usize, f64)>>,
    /// Per storage: the model row of its first-period state-of-charge
    /// dynamics, whose right-hand side is the starting state of charge.
    first_soc_row: Vec<usize>,
}

#[cfg(test)]
mod tests {
    use super::*;

    pub(crate) fn day(nt: usize) -> HorizonProblem {
        let periods = (0..nt)
            .map(|t| {
                let h = t as f64 * 24.0 / nt as f64;
                let sun = (((h - 6.0) / 12.0 * std::f64::consts::PI).sin()).max(0.0);
                PeriodForecast {
                    demand_kw: 120.0
                        + 60.0 * ((h - 18.0) / 24.0 * 2.0 * std::f64::consts::PI).cos(),
                    available_kw: [
                        ("pv1".to_string(), 100.0 * sun),
                        ("wt1".to_string(), 20.0 + 10.0 * (h / 5.0).sin()),
                    ]
                    .into_iter()
                    .collect(),
                    running: BTreeMap::new(),
                }
            })
            .collect();
        HorizonProblem {
            dt_h: 24.0 / nt as f64,
            voll_per_kwh: 5.0,
            periods,
            pv: vec![HorizonRenewable {
                id: "pv1".into(),
                cost_per_kwh: 0.0,
                ramp_kw_per_s: 0.0,
                initial_kw: None,
            }],
            wind: vec![HorizonRenewable {
                id: "wt1".into(),
                cost_per_kwh: 0.01,
                ramp_kw_per_s: 0.0,
                initial_kw: None,
            }],
            oil: vec![HorizonOil {
                id: "dg1".into(),
                running: true,
                min_kw: 30.0,
                max_kw: 150.0,
                cost_per_kwh: 0.35,
                ramp_kw_per_s: 0.01,
                initial_kw: Some(60.0),
                relaxed_commitment: false,
            }],
            storage: vec![HorizonStorage {
                unit: StorageUnit {
                    id: "bess1".into(),
                    soc_kwh: 100.0,
                    soc_min_kwh: 20.0,
                    soc_max_kwh: 190.0,
                    max_charge_kw: 50.0,
                    max_discharge_kw: 60.0,
                    eff_charge: 0.95,
                    eff_discharge: 0.95,
                    cycle_cost_per_kwh: 0.02,
                    stored_value_per_kwh: 0.0,
                },
                ramp_kw_per_s: 0.0,
                initial_kw: Some(0.0),
                terminal_value_per_kwh: 0.2,
            }],
            reserve: Some(ReserveRule {
                load_frac: 0.1,
                pv_frac: 0.2,
                wind_frac: 0.3,
                shortfall_cost_per_kwh: 1.0,
            }),
            max_renewable_share: None,
            smoothing_cost_per_kw2: 0.0,
        }
    }

    fn check_dynamics(p: &HorizonProblem, s: &HorizonSolution) {
        let u = &p.storage[0].unit;
        let mut soc = u.soc_kwh;
        for (t, r) in s.periods.iter().enumerate() {
            let ch = r.charge_kw.get("bess1").unwrap();
            let dis = r.discharge_kw.get("bess1").unwrap();
            soc += u.eff_charge * p.dt_h * ch - p.dt_h * dis / u.eff_discharge;
            assert!((soc - r.soc_kwh.get("bess1").unwrap()).abs() < 1e-9);
            assert!(soc >= u.soc_min_kwh - 1e-6 && soc <= u.soc_max_kwh + 1e-6);
            let supply: f64 = r.setpoints_kw.0.iter().map(|(_, v)| v).sum::<f64>() + r.shed_kw;
            assert!(
                (supply - p.periods[t].demand_kw).abs() < 1e-6,
                "balance in period {t}"
            );
        }
    }

    #[test]
    fn a_day_ahead_lp_respects_dynamics_ramps_and_balance() {
        let p = day(24);
        let s = p.solve().unwrap();
        check_dynamics(&p, &s);
        let ramp = 0.01 * 3600.0 * p.dt_h;
        let mut prev = 60.0;
        for r in &s.periods {
            let d = r.setpoints_kw.get("dg1").unwrap();
            assert!((d - prev).abs() <= ramp + 1e-6);
            prev = d;
        }
    }

    #[test]
    fn stored_energy_value_is_the_cost_saved_per_kwh_stored() {
        // Three cases: energy that displaces diesel later, energy that only
        // meets the terminal value, and energy that averts shedding.
        let cases = {
            let mut worth_diesel = day(24);
            worth_diesel.reserve = None;
            let mut surplus = worth_diesel.clone();
            surplus.oil.clear();
            for p in &mut surplus.periods {
                p.demand_kw = 10.0;
            }
            let mut short = surplus.clone();
            for p in &mut short.periods {
                p.demand_kw = 250.0;
            }
            [worth_diesel, surplus, short]
        };
        for p in cases {
            let s = p.solve().unwrap();
            let value = s.stored_energy_value_per_kwh.get("bess1").unwrap();
            let mut more = p.clone();
            more.storage[0].unit.soc_kwh += 0.01;
            let saved = (s.objective - more.solve().unwrap().objective) / 0.01;
            assert!(
                (value - saved).abs() <= 1e-3 * saved.abs().max(1.0),
                "value {value} vs saved {saved} per kWh"
            );
            assert!(value >= -1e-9, "{value}");
        }
    }

    #[test]
    fn relaxed_commitment_frees_the_oil_unit_after_the_first_period() {
        let mut p = day(24);
        p.reserve = None;
        p.oil[0].running = false;
        p.oil[0].initial_kw = None;
        let fixed = p.solve().unwrap();
        p.oil[0].relaxed_commitment = true;
        let relaxed = p.solve().unwrap();
        check_dynamics(&p, &relaxed);
        let dg = |s: &HorizonSolution, t: usize| s.periods[t].setpoints_kw.get("dg1").unwrap();
        assert_eq!(dg(&relaxed, 0), 0.0, "period 0 keeps the commitment");
        assert!((1..24).all(|t| dg(&fixed, t) == 0.0));
        assert!((1..24).any(|t| dg(&relaxed, t) > 1.0 && dg(&relaxed, t) < 30.0));
        assert!(relaxed.objective < fixed.objective);
    }

    #[test]
    fn smoothing_makes_it_a_qp_with_smaller_steps() {
        let mut p = day(24);
        p.oil[0].ramp_kw_per_s = 0.0;
        let lp = p.solve().unwrap();
        p.smoothing_cost_per_kw2 = 0.01;
        let qp = p.solve().unwrap();
        check_dynamics(&p, &qp);
        let steps = |s: &HorizonSolution| -> f64 {
            s.periods
                .windows(2)
                .map(|w| {
                    (w[1].setpoints_kw.get("dg1").unwrap() - w[0].setpoints_kw.get("dg1").unwrap())
                        .powi(2)
                })
                .sum()
        };
        assert!(steps(&qp) < steps(&lp));
    }

    #[test]
    fn renewable_share_cap_curtails() {
        let mut p = day(8);
        p.max_renewable_share = Some(0.3);
        let s = p.solve().unwrap();
        for (t, r) in s.periods.iter().enumerate() {
            let ren = r.setpoints_kw.get("pv1").unwrap() + r.setpoints_kw.get("wt1").unwrap();
            assert!(ren <= 0.3 * p.periods[t].demand_kw + 1e-6);
        }
    }

    #[test]
    fn missing_forecast_is_located() {
        let mut p = day(3);
        p.periods[1].available_kw.remove("wt1");
        let e = p.validate("").unwrap_err();
        assert_eq!(e.path, "periods[1].available_kw");
        assert!(e.message.contains("wt1"));
    }

    #[test]
    fn diesel_ramp_down_that_nothing_absorbs_is_infeasible() {
        let mut p = day(2);
        p.storage.clear();
        p.reserve = None;
        p.oil[0].initial_kw = Some(150.0);
        p.oil[0].ramp_kw_per_s = 0.001; // 3.6 kW per hour
        for per in &mut p.periods {
            per.demand_kw = 40.0;
        }
        assert!(matches!(p.solve(), Err(DispatchError::Infeasible(_))));
    }
}
