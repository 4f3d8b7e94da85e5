//! The single-period dispatch LP: one dispatch period, the problem the live
//! outer loop solves every `dispatch_period_s` and `gridscada dispatch solve`
//! answers for a JSON object without a `"periods"` key.
//!
//! **Owns:** the problem and solution types, their validation, the LP (seed
//! eqs. 1-7 with power balance, state-of-charge energy limits, diesel minimum
//! load and priced load shedding), the infeasibility pre-check, and the
//! post-solve repair that turns the interior-point answer into setpoints that
//! satisfy every constraint.
//!
//! **Must not touch:** I/O and commitment (the diesel on/off decision comes in
//! as `running`).
//!
//! Input JSON (every list may be empty or missing):
//!
//! ```json
//! {"dt_h": 0.25, "demand_kw": 180.0, "voll_per_kwh": 5.0,
//!  "pv":   [{"id": "pv1", "available_kw": 60.0, "cost_per_kwh": 0.0}],
//!  "wind": [{"id": "wt1", "available_kw": 25.0, "cost_per_kwh": 0.01}],
//!  "oil":  [{"id": "dg1", "running": true, "min_kw": 30.0, "max_kw": 150.0, "cost_per_kwh": 0.35}],
//!  "storage": [{"id": "bess1", "soc_kwh": 80.0, "soc_min_kwh": 20.0, "soc_max_kwh": 200.0,
//!               "max_charge_kw": 50.0, "max_discharge_kw": 60.0, "eff_charge": 0.95,
//!               "eff_discharge": 0.95, "cycle_cost_per_kwh": 0.02}]}
//! ```
//!
//! LP: minimise `dt_h·(Σ c·p + Σ cycle·(ch+dis) + voll·shed)` subject to
//! `Σp + Σ(dis−ch) + shed = demand`, `0 ≤ p_pv,wind ≤ available`,
//! `min ≤ p_oil ≤ max` if running else `p_oil = 0`, `0 ≤ ch ≤ max_charge`,
//! `eff_c·ch·dt ≤ soc_max − soc`, `0 ≤ dis ≤ max_discharge`,
//! `dis·dt/eff_d ≤ soc − soc_min`, `0 ≤ shed ≤ demand`.

use std::time::Instant;

use serde::{Deserialize, Serialize};
use serde_json::Value;

use super::input::{index, InputError, Obj, Problems};
use super::lp::{Model, Sense, FEAS_TOL};
use super::{DispatchError, Setpoints};

/// A PV array or wind turbine.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RenewableUnit {
    pub id: String,
    /// What the unit could produce now, kW.
    pub available_kw: f64,
    pub cost_per_kwh: f64,
}

/// An oil-fired (diesel) generator; `running` comes from the commitment rule.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OilUnit {
    pub id: String,
    pub running: bool,
    /// Minimum stable load while running, kW.
    pub min_kw: f64,
    pub max_kw: f64,
    pub cost_per_kwh: f64,
}

/// A storage unit (battery, pumped hydro) at its present state of charge.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StorageUnit {
    pub id: String,
    pub soc_kwh: f64,
    pub soc_min_kwh: f64,
    pub soc_max_kwh: f64,
    pub max_charge_kw: f64,
    pub max_discharge_kw: f64,
    pub eff_charge: f64,
    pub eff_discharge: f64,
    /// Wear cost per kWh charged or discharged.
    pub cycle_cost_per_kwh: f64,
    /// Optional (JSON `stored_value_per_kwh`, default 0): what a kWh left in
    /// store is worth at the end of the period, e.g. the diesel energy it
    /// will displace later. It adds `−value·ΔSoC` to the objective, so a
    /// single-period dispatch stores a renewable surplus instead of
    /// curtailing it. Zero gives exactly the contract's objective.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub stored_value_per_kwh: f64,
}

fn is_zero(v: &f64) -> bool {
    *v == 0.0
}

/// One dispatch period.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DispatchProblem {
    /// Period length, hours.
    pub dt_h: f64,
    pub demand_kw: f64,
    /// Value of lost load: the price of shedding, per kWh.
    pub voll_per_kwh: f64,
    #[serde(default)]
    pub pv: Vec<RenewableUnit>,
    #[serde(default)]
    pub wind: Vec<RenewableUnit>,
    #[serde(default)]
    pub oil: Vec<OilUnit>,
    #[serde(default)]
    pub storage: Vec<StorageUnit>,
}

/// The optimal setpoints of one period.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DispatchSolution {
    /// Always `"optimal"`; infeasibility is a [`DispatchError`].
    pub status: &'static str,
    /// Cost of the period, as in the LP objective.
    pub objective: f64,
    /// Per unit id, kW; storage is discharge − charge (positive = discharge).
    pub setpoints_kw: Setpoints,
    /// Load that cannot be served, kW.
    pub shed_kw: f64,
    /// Wall time of build + solve + repair, ms.
    pub solve_ms: f64,
}

/// Values beyond this (kW, kWh, per kWh) are refused as implausible; keeps the
/// solver's numbers well scaled whatever the input.
pub(crate) const MAX_MAGNITUDE: f64 = 1e9;

pub(crate) fn bad(path: String, msg: impl Into<String>) -> InputError {
    InputError::new(path, msg)
}

/// `v >= 0` (and plausible).
pub(crate) fn nonneg(path: String, v: f64) -> Result<(), InputError> {
    if !v.is_finite() {
        Err(bad(path, format!("{v} is not a finite number")))
    } else if v < 0.0 {
        Err(bad(path, format!("{v} is negative")))
    } else if v > MAX_MAGNITUDE {
        Err(bad(path, format!("{v} is implausibly large")))
    } else {
        Ok(())
    }
}

pub(crate) fn efficiency(path: String, v: f64) -> Result<(), InputError> {
    if !(v.is_finite() && v > 0.0 && v <= 1.0) {
        Err(bad(path, format!("{v} is outside (0, 1]")))
    } else {
        Ok(())
    }
}

pub(crate) fn unique_ids<'a>(
    ids: impl Iterator<Item = (String, &'a str)>,
) -> Result<(), InputError> {
    let mut seen: Vec<&str> = Vec::new();
    for (path, id) in ids {
        if id.trim().is_empty() {
            return Err(bad(path, "id is empty"));
        }
        if seen.contains(&id) {
            return Err(bad(path, format!("duplicate id '{id}'")));
        }
        seen.push(id);
    }
    Ok(())
}

impl RenewableUnit {
    pub(crate) fn from_value(v: &Value, path: &str) -> Result<Self, InputError> {
        let mut o = Obj::new(v, path)?;
        let u = RenewableUnit {
            id: o.string("id")?,
            available_kw: o.num("available_kw")?,
            cost_per_kwh: o.num("cost_per_kwh")?,
        };
        o.finish()?;
        Ok(u)
    }
}

impl OilUnit {
    pub(crate) fn from_value(v: &Value, path: &str) -> Result<Self, InputError> {
        let mut o = Obj::new(v, path)?;
        let u = OilUnit {
            id: o.string("id")?,
            running: o.bool("running")?,
            min_kw: o.num("min_kw")?,
            max_kw: o.num("max_kw")?,
            cost_per_kwh: o.num("cost_per_kwh")?,
        };
        o.finish()?;
        Ok(u)
    }

    pub(crate) fn validate(&self, path: &str) -> Result<(), InputError> {
        let mut pr = Problems::default();
        pr.check(nonneg(format!("{path}.min_kw"), self.min_kw));
        pr.check(nonneg(format!("{path}.max_kw"), self.max_kw));
        pr.check(nonneg(format!("{path}.cost_per_kwh"), self.cost_per_kwh));
        if self.max_kw < self.min_kw {
            pr.check(Err(bad(
                format!("{path}.max_kw"),
                format!("{} is below min_kw {}", self.max_kw, self.min_kw),
            )));
        }
        pr.finish()
    }
}

impl StorageUnit {
    pub(crate) fn from_value(v: &Value, path: &str) -> Result<Self, InputError> {
        let mut o = Obj::new(v, path)?;
        let mut u = StorageUnit::read_fields(&mut o)?;
        u.stored_value_per_kwh = o.opt_num("stored_value_per_kwh")?.unwrap_or(0.0);
        o.finish()?;
        Ok(u)
    }

    /// The fields every storage unit has, single-period or horizon; the
    /// caller reads its own extra keys and finishes the object.
    pub(crate) fn read_fields(o: &mut Obj<'_>) -> Result<Self, InputError> {
        Ok(StorageUnit {
            id: o.string("id")?,
            soc_kwh: o.num("soc_kwh")?,
            soc_min_kwh: o.num("soc_min_kwh")?,
            soc_max_kwh: o.num("soc_max_kwh")?,
            max_charge_kw: o.num("max_charge_kw")?,
            max_discharge_kw: o.num("max_discharge_kw")?,
            eff_charge: o.num("eff_charge")?,
            eff_discharge: o.num("eff_discharge")?,
            cycle_cost_per_kwh: o.num("cycle_cost_per_kwh")?,
            stored_value_per_kwh: 0.0,
        })
    }

    pub(crate) fn validate(&self, path: &str) -> Result<(), InputError> {
        let mut pr = Problems::default();
        pr.check(nonneg(format!("{path}.soc_kwh"), self.soc_kwh));
        pr.check(nonneg(format!("{path}.soc_min_kwh"), self.soc_min_kwh));
        pr.check(nonneg(format!("{path}.soc_max_kwh"), self.soc_max_kwh));
        pr.check(nonneg(format!("{path}.max_charge_kw"), self.max_charge_kw));
        pr.check(nonneg(
            format!("{path}.max_discharge_kw"),
            self.max_discharge_kw,
        ));
        pr.check(efficiency(format!("{path}.eff_charge"), self.eff_charge));
        pr.check(efficiency(
            format!("{path}.eff_discharge"),
            self.eff_discharge,
        ));
        pr.check(nonneg(
            format!("{path}.cycle_cost_per_kwh"),
            self.cycle_cost_per_kwh,
        ));
        pr.check(nonneg(
            format!("{path}.stored_value_per_kwh"),
            self.stored_value_per_kwh,
        ));
        if self.soc_max_kwh < self.soc_min_kwh {
            pr.check(Err(bad(
                format!("{path}.soc_max_kwh"),
                format!(
                    "{} is below soc_min_kwh {}",
                    self.soc_max_kwh, self.soc_min_kwh
                ),
            )));
        }
        if self.soc_kwh < self.soc_min_kwh || self.soc_kwh > self.soc_max_kwh {
            pr.check(Err(bad(
                format!("{path}.soc_kwh"),
                format!(
                    "{} is outside [soc_min_kwh, soc_max_kwh] = [{}, {}]",
                    self.soc_kwh, self.soc_min_kwh, self.soc_max_kwh
                ),
            )));
        }
        pr.finish()
    }

    /// Charge limit this period: power, and room left below `soc_max`.
    pub fn charge_limit_kw(&self, dt_h: f64) -> f64 {
        let room = (self.soc_max_kwh - self.soc_kwh).max(0.0) / (self.eff_charge * dt_h);
        self.max_charge_kw.min(room)
    }

    /// Discharge limit this period: power, and energy left above `soc_min`.
    pub fn discharge_limit_kw(&self, dt_h: f64) -> f64 {
        let left = (self.soc_kwh - self.soc_min_kwh).max(0.0) * self.eff_discharge / dt_h;
        self.max_discharge_kw.min(left)
    }
}

pub(crate) fn renewable_validate(u: &RenewableUnit, path: &str) -> Result<(), InputError> {
    let mut pr = Problems::default();
    pr.check(nonneg(format!("{path}.available_kw"), u.available_kw));
    pr.check(nonneg(format!("{path}.cost_per_kwh"), u.cost_per_kwh));
    pr.finish()
}

pub(crate) fn parse_list<T>(
    o: &mut Obj<'_>,
    key: &'static str,
    f: impl Fn(&Value, &str) -> Result<T, InputError>,
) -> Result<Vec<T>, InputError> {
    let (path, items) = o.list(key, true)?;
    items
        .iter()
        .enumerate()
        .map(|(i, v)| f(v, &index(&path, i)))
        .collect()
}

/// Longest period accepted, h: a leap year.
pub const MAX_DT_H: f64 = 24.0 * 366.0;

/// Most units (PV, wind, oil and storage together) a problem may have: far
/// beyond any microgrid, and solved in well under a second (200,000 units
/// took 31-52 s before this limit).
pub const MAX_UNITS: usize = 1_000;

pub(crate) fn dt_h_valid(path: String, dt_h: f64) -> Result<(), InputError> {
    if !(dt_h.is_finite() && dt_h > 0.0 && dt_h <= MAX_DT_H) {
        return Err(bad(
            path,
            format!("{dt_h} is not a number of hours in (0, {MAX_DT_H}] (a period of at most a leap year)"),
        ));
    }
    Ok(())
}

/// At most [`MAX_UNITS`] units in all.
pub(crate) fn units_within_limit(path: String, units: usize) -> Result<(), InputError> {
    if units > MAX_UNITS {
        return Err(bad(
            path,
            format!("{units} units; at most {MAX_UNITS} (PV, wind, oil and storage together) are accepted"),
        ));
    }
    Ok(())
}

impl DispatchProblem {
    /// Reads the problem from parsed JSON at `path` ("" for the document).
    /// Checks shape and types only; [`DispatchProblem::validate`] checks values.
    pub fn from_value(v: &Value, path: &str) -> Result<Self, InputError> {
        let mut o = Obj::new(v, path)?;
        let p = DispatchProblem {
            dt_h: o.num("dt_h")?,
            demand_kw: o.num("demand_kw")?,
            voll_per_kwh: o.num("voll_per_kwh")?,
            pv: parse_list(&mut o, "pv", RenewableUnit::from_value)?,
            wind: parse_list(&mut o, "wind", RenewableUnit::from_value)?,
            oil: parse_list(&mut o, "oil", OilUnit::from_value)?,
            storage: parse_list(&mut o, "storage", StorageUnit::from_value)?,
        };
        o.finish()?;
        Ok(p)
    }

    /// Checks every value; errors name the field (`prefix` + path).
    pub fn validate(&self, prefix: &str) -> Result<(), InputError> {
        let mut pr = Problems::default();
        let at = |k: &str| super::input::join(prefix, k);
        pr.check(dt_h_valid(at("dt_h"), self.dt_h));
        pr.check(nonneg(at("demand_kw"), self.demand_kw));
        pr.check(nonneg(at("voll_per_kwh"), self.voll_per_kwh));
        pr.check(units_within_limit(
            prefix.to_string(),
            self.pv.len() + self.wind.len() + self.oil.len() + self.storage.len(),
        ));
        for (i, u) in self.pv.iter().enumerate() {
            pr.check(renewable_validate(u, &index(&at("pv"), i)));
        }
        for (i, u) in self.wind.iter().enumerate() {
            pr.check(renewable_validate(u, &index(&at("wind"), i)));
        }
        for (i, u) in self.oil.iter().enumerate() {
            pr.check(u.validate(&index(&at("oil"), i)));
        }
        for (i, u) in self.storage.iter().enumerate() {
            pr.check(u.validate(&index(&at("storage"), i)));
        }
        pr.check(unique_ids(self.ids_with_paths(prefix)));
        pr.finish()
    }

    fn ids_with_paths<'a>(&'a self, prefix: &str) -> impl Iterator<Item = (String, &'a str)> {
        let at = |k: &str, i: usize| format!("{}.id", index(&super::input::join(prefix, k), i));
        let mut v: Vec<(String, &str)> = Vec::new();
        v.extend(
            self.pv
                .iter()
                .enumerate()
                .map(|(i, u)| (at("pv", i), u.id.as_str())),
        );
        v.extend(
            self.wind
                .iter()
                .enumerate()
                .map(|(i, u)| (at("wind", i), u.id.as_str())),
        );
        v.extend(
            self.oil
                .iter()
                .enumerate()
                .map(|(i, u)| (at("oil", i), u.id.as_str())),
        );
        v.extend(
            self.storage
                .iter()
                .enumerate()
                .map(|(i, u)| (at("storage", i), u.id.as_str())),
        );
        v.into_iter()
    }

    /// A clear reason when the problem is infeasible for an obvious cause:
    /// running diesels' minimum load that demand plus storage charging cannot
    /// absorb (PV and wind can always be curtailed, shedding covers deficits).
    pub fn precheck(&self) -> Option<String> {
        let forced: f64 = self
            .oil
            .iter()
            .filter(|o| o.running)
            .map(|o| o.min_kw)
            .sum();
        let absorb: f64 = self
            .storage
            .iter()
            .map(|s| s.charge_limit_kw(self.dt_h))
            .sum();
        if forced > self.demand_kw + absorb + FEAS_TOL {
            let ids: Vec<&str> = self
                .oil
                .iter()
                .filter(|o| o.running && o.min_kw > 0.0)
                .map(|o| o.id.as_str())
                .collect();
            return Some(format!(
                "running oil units ({}) must produce at least {forced} kW (minimum stable load), \
                 but demand is {} kW and storage can absorb only {absorb:.3} kW",
                ids.join(", "),
                self.demand_kw
            ));
        }
        None
    }

    /// Validates, solves and checks: the one solve used by the CLI and the
    /// live outer loop.
    pub fn solve(&self) -> Result<DispatchSolution, DispatchError> {
        let started = Instant::now();
        self.validate("").map_err(DispatchError::Invalid)?;
        if let Some(reason) = self.precheck() {
            return Err(DispatchError::Infeasible(reason));
        }
        let (model, vars) = self.build();
        let mut x = model.solve()?;
        model.snap(&mut x);
        // Charging and discharging at once only burns cycle cost here: keep the net.
        for &(ch, dis) in &vars.storage {
            let net = x[dis] - x[ch];
            x[dis] = net.max(0.0).min(model.ub[dis]);
            x[ch] = (-net).max(0.0).min(model.ub[ch]);
        }
        rebalance(&model, 0, &mut x, &vars.balance_adjust);
        model.check(&x, FEAS_TOL).map_err(|e| {
            DispatchError::Solver(format!("solver answer failed the constraint check: {e}"))
        })?;
        let mut setpoints = Vec::with_capacity(vars.units.len());
        for (id, j) in &vars.units {
            setpoints.push((id.clone(), x[*j]));
        }
        for (k, &(ch, dis)) in vars.storage.iter().enumerate() {
            setpoints.push((self.storage[k].id.clone(), x[dis] - x[ch]));
        }
        Ok(DispatchSolution {
            status: "optimal",
            objective: model.objective(&x),
            setpoints_kw: Setpoints(setpoints),
            shed_kw: x[vars.shed],
            solve_ms: started.elapsed().as_secs_f64() * 1e3,
        })
    }

    fn build(&self) -> (Model, Vars) {
        let dt = self.dt_h;
        let mut m = Model::default();
        let mut units = Vec::new();
        let mut bal: Vec<(usize, f64)> = Vec::new();
        for u in self.pv.iter().chain(&self.wind) {
            let j = m.var(
                format!("{} output", u.id),
                0.0,
                u.available_kw,
                dt * u.cost_per_kwh,
            );
            units.push((u.id.clone(), j));
            bal.push((j, 1.0));
        }
        for u in &self.oil {
            let (lo, hi) = if u.running {
                (u.min_kw, u.max_kw)
            } else {
                (0.0, 0.0)
            };
            let j = m.var(format!("{} output", u.id), lo, hi, dt * u.cost_per_kwh);
            units.push((u.id.clone(), j));
            bal.push((j, 1.0));
        }
        let mut storage = Vec::new();
        for s in &self.storage {
            // ΔSoC = dt·(eff_c·ch − dis/eff_d), valued at stored_value.
            let c = dt * s.cycle_cost_per_kwh;
            let v = dt * s.stored_value_per_kwh;
            let ch = m.var(
                format!("{} charge", s.id),
                0.0,
                s.charge_limit_kw(dt),
                c - v * s.eff_charge,
            );
            let dis = m.var(
                format!("{} discharge", s.id),
                0.0,
                s.discharge_limit_kw(dt),
                c + v / s.eff_discharge,
            );
            storage.push((ch, dis));
            bal.push((ch, -1.0));
            bal.push((dis, 1.0));
        }
        let shed = m.var(
            "load shed".into(),
            0.0,
            self.demand_kw,
            dt * self.voll_per_kwh,
        );
        bal.push((shed, 1.0));
        let balance_adjust = bal.clone();
        m.row("power balance".into(), bal, Sense::Eq, self.demand_kw);
        (
            m,
            Vars {
                units,
                storage,
                shed,
                balance_adjust,
            },
        )
    }
}

struct Vars {
    units: Vec<(String, usize)>,
    storage: Vec<(usize, usize)>,
    shed: usize,
    balance_adjust: Vec<(usize, f64)>,
}

/// Removes the small residual an interior-point answer leaves in equality row
/// `row`, by moving the listed variables (with their coefficient in the row)
/// within their bounds, cheapest move first.
pub(crate) fn rebalance(model: &Model, row: usize, x: &mut [f64], adjust: &[(usize, f64)]) {
    let r = &model.rows[row];
    let resid = r.rhs - r.value(x);
    if resid.abs() < 1e-15 {
        return;
    }
    // Moving variable j by d changes the row by coef·d; we need coef·d = resid.
    let mut moves: Vec<(f64, usize, f64)> = adjust
        .iter()
        .map(|&(j, coef)| {
            let dir = (resid / coef).signum();
            (dir * model.cost[j], j, coef)
        })
        .collect();
    moves.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut left = resid;
    for (_, j, coef) in moves {
        if left.abs() < 1e-15 {
            break;
        }
        let want = left / coef;
        let new = (x[j] + want).clamp(model.lb[j], model.ub[j]);
        left -= coef * (new - x[j]);
        x[j] = new;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    pub(crate) fn example() -> DispatchProblem {
        DispatchProblem {
            dt_h: 0.25,
            demand_kw: 180.0,
            voll_per_kwh: 5.0,
            pv: vec![RenewableUnit {
                id: "pv1".into(),
                available_kw: 60.0,
                cost_per_kwh: 0.0,
            }],
            wind: vec![RenewableUnit {
                id: "wt1".into(),
                available_kw: 25.0,
                cost_per_kwh: 0.01,
            }],
            oil: vec![OilUnit {
                id: "dg1".into(),
                running: true,
                min_kw: 30.0,
                max_kw: 150.0,
                cost_per_kwh: 0.35,
            }],
            storage: vec![StorageUnit {
                id: "bess1".into(),
                soc_kwh: 80.0,
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

    fn sp(s: &DispatchSolution, id: &str) -> f64 {
        s.setpoints_kw.get(id).unwrap()
    }

    fn balance(p: &DispatchProblem, s: &DispatchSolution) -> f64 {
        s.setpoints_kw.0.iter().map(|(_, v)| v).sum::<f64>() + s.shed_kw - p.demand_kw
    }

    #[test]
    fn merit_order_on_the_contract_example() {
        let p = example();
        let s = p.solve().unwrap();
        // PV 60 + wind 25 + storage 60 (cheaper than diesel) + diesel 35.
        assert!((sp(&s, "pv1") - 60.0).abs() < 1e-6);
        assert!((sp(&s, "wt1") - 25.0).abs() < 1e-6);
        assert!((sp(&s, "bess1") - 60.0).abs() < 1e-6);
        assert!((sp(&s, "dg1") - 35.0).abs() < 1e-6);
        assert!(s.shed_kw.abs() < 1e-6);
        let expect = 0.25 * (25.0 * 0.01 + 60.0 * 0.02 + 35.0 * 0.35);
        assert!((s.objective - expect).abs() < 1e-9 * expect.max(1.0));
        assert!(balance(&p, &s).abs() < 1e-9);
    }

    #[test]
    fn diesel_minimum_that_nothing_can_absorb_is_infeasible() {
        let mut p = example();
        p.demand_kw = 10.0;
        p.pv[0].available_kw = 0.0;
        p.storage[0].soc_kwh = 200.0; // full: cannot charge
        match p.solve() {
            Err(DispatchError::Infeasible(r)) => assert!(r.contains("dg1"), "{r}"),
            other => panic!("expected infeasible, got {other:?}"),
        }
    }

    #[test]
    fn surplus_is_curtailed_and_diesel_minimum_charges_storage() {
        let mut p = example();
        p.demand_kw = 20.0;
        p.oil[0].running = false;
        let s = p.solve().unwrap();
        // Charging costs cycle cost and a single period gives stored energy no
        // value: cheapest PV covers the load, the rest is curtailed.
        assert!((sp(&s, "pv1") - 20.0).abs() < 1e-6);
        assert!(sp(&s, "wt1").abs() < 1e-6);
        assert!(sp(&s, "bess1").abs() < 1e-6);
        // A running diesel's minimum load beyond demand goes into storage.
        p.demand_kw = 10.0;
        p.oil[0].running = true;
        let s = p.solve().unwrap();
        assert!((sp(&s, "dg1") - 30.0).abs() < 1e-6);
        assert!((sp(&s, "bess1") + 20.0).abs() < 1e-6);
        assert!(sp(&s, "pv1").abs() < 1e-6);
        assert!(balance(&p, &s).abs() < 1e-9);
    }

    #[test]
    fn empty_lists_shed_everything_and_zero_demand_costs_nothing() {
        let p = DispatchProblem {
            dt_h: 1.0,
            demand_kw: 42.0,
            voll_per_kwh: 3.0,
            pv: vec![],
            wind: vec![],
            oil: vec![],
            storage: vec![],
        };
        let s = p.solve().unwrap();
        assert!((s.shed_kw - 42.0).abs() < 1e-9);
        assert!((s.objective - 126.0).abs() < 1e-6);
        let mut z = example();
        z.demand_kw = 0.0;
        z.oil[0].running = false;
        let s = z.solve().unwrap();
        assert!(s.objective.abs() < 1e-8, "{}", s.objective);
        assert!(balance(&z, &s).abs() < 1e-9);
    }

    #[test]
    fn degenerate_equal_costs_still_balance() {
        let mut p = example();
        p.wind[0].cost_per_kwh = 0.0; // PV and wind tie
        p.demand_kw = 50.0;
        p.oil[0].running = false;
        p.storage[0].soc_kwh = 200.0; // full, cannot absorb
        let s = p.solve().unwrap();
        assert!((sp(&s, "pv1") + sp(&s, "wt1") + sp(&s, "bess1") - 50.0).abs() < 1e-6);
        assert!(s.objective.abs() < 1e-6);
    }

    #[test]
    fn empty_storage_cannot_discharge_and_full_cannot_charge() {
        let mut p = example();
        p.storage[0].soc_kwh = 20.0; // at minimum
        let s = p.solve().unwrap();
        assert!(sp(&s, "bess1") <= 1e-9);
        assert!((sp(&s, "dg1") - 95.0).abs() < 1e-6);
        p.storage[0].soc_kwh = 200.0;
        p.demand_kw = 60.0;
        p.oil[0].running = false;
        let s = p.solve().unwrap();
        assert!(sp(&s, "bess1") >= -1e-9);
    }

    #[test]
    fn energy_limit_binds_over_a_long_period() {
        let mut p = example();
        p.dt_h = 2.0; // 60 kWh above the minimum / 2 h * 0.95 = 28.5 kW
        let s = p.solve().unwrap();
        assert!((sp(&s, "bess1") - 28.5).abs() < 1e-6);
    }

    #[test]
    fn invalid_values_name_their_field() {
        let mut p = example();
        p.storage[0].eff_charge = 1.2;
        let e = p.validate("").unwrap_err();
        assert_eq!(
            e.to_string(),
            "storage[0].eff_charge: 1.2 is outside (0, 1]"
        );
        let mut p = example();
        p.wind[0].id = "pv1".into();
        assert_eq!(p.validate("").unwrap_err().path, "wind[0].id");
        let mut p = example();
        p.storage[0].soc_kwh = 5.0;
        assert_eq!(p.validate("").unwrap_err().path, "storage[0].soc_kwh");
        let mut p = example();
        p.pv[0].available_kw = -1.0;
        assert_eq!(p.validate("").unwrap_err().path, "pv[0].available_kw");
        let mut p = example();
        p.demand_kw = f64::NAN;
        assert_eq!(p.validate("").unwrap_err().path, "demand_kw");
    }

    #[test]
    fn a_value_for_stored_energy_stores_a_surplus_instead_of_curtailing() {
        let mut p = DispatchProblem::from_value(
            &serde_json::json!({
                "dt_h": 0.25, "demand_kw": 20.0, "voll_per_kwh": 5.0,
                "pv": [{"id": "pv1", "available_kw": 60.0, "cost_per_kwh": 0.0}],
                "storage": [{"id": "bess1", "soc_kwh": 80.0, "soc_min_kwh": 20.0, "soc_max_kwh": 200.0,
                             "max_charge_kw": 30.0, "max_discharge_kw": 60.0,
                             "eff_charge": 0.95, "eff_discharge": 0.95, "cycle_cost_per_kwh": 0.02}]
            }),
            "",
        )
        .unwrap();
        // Without a value, charging only costs wear: the PV is curtailed.
        let s = p.solve().unwrap();
        assert!(s.setpoints_kw.get("bess1").unwrap().abs() < 1e-6);
        // Valued at 0.3/kWh, the surplus goes into the battery, up to its limit.
        p.storage[0].stored_value_per_kwh = 0.3;
        let s = p.solve().unwrap();
        assert!((s.setpoints_kw.get("bess1").unwrap() + 30.0).abs() < 1e-6);
        assert!((s.setpoints_kw.get("pv1").unwrap() - 50.0).abs() < 1e-6);
        // The objective carries the value of the energy stored.
        let stored = 0.95 * 30.0 * 0.25;
        let expect = 0.25 * 0.02 * 30.0 - 0.3 * stored;
        assert!(
            (s.objective - expect).abs() < 1e-6,
            "{} vs {expect}",
            s.objective
        );
    }
}
