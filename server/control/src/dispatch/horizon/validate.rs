//! Reading a horizon problem from its JSON (every error located by its
//! path) and validating it.

use std::collections::BTreeMap;

use serde_json::Value;

use crate::dispatch::input::{index, join, kind, InputError, Obj, Problems};
use crate::dispatch::single::{
    bad, dt_h_valid, nonneg, parse_list, unique_ids, units_within_limit, StorageUnit,
};

use super::{
    HorizonOil, HorizonProblem, HorizonRenewable, HorizonStorage, PeriodForecast, ReserveRule,
    MAX_PERIODS,
};

/// Most on/off decisions (units with `optimize_commitment` × periods) a
/// problem may ask for: a week of 15-minute periods for three diesels.
pub const MAX_COMMITMENT_BINARIES: usize = 2_016;

/// Most relaxations a problem may ask the commitment search for.
pub const MAX_COMMITMENT_NODES: usize = 200_000;

/// At most [`MAX_PERIODS`] periods.
pub(crate) fn periods_within_limit(path: String, periods: usize) -> Result<(), InputError> {
    if periods > MAX_PERIODS {
        return Err(bad(
            path,
            format!("{periods} periods; at most {MAX_PERIODS} are accepted"),
        ));
    }
    Ok(())
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
        let mut pr = Problems::default();
        pr.check(nonneg(format!("{path}.cost_per_kwh"), self.cost_per_kwh));
        pr.check(nonneg(format!("{path}.ramp_kw_per_s"), self.ramp_kw_per_s));
        if let Some(i) = self.initial_kw {
            pr.check(nonneg(format!("{path}.initial_kw"), i));
        }
        pr.finish()
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
            optimize_commitment: o.opt_bool("optimize_commitment")?.unwrap_or(false),
            no_load_cost_per_h: opt_nonneg(&mut o, "no_load_cost_per_h")?,
            start_cost: opt_nonneg(&mut o, "start_cost")?,
            min_up_h: opt_nonneg(&mut o, "min_up_h")?,
            min_down_h: opt_nonneg(&mut o, "min_down_h")?,
            hours_in_state: o.opt_num("hours_in_state")?,
        };
        o.finish()?;
        Ok(u)
    }
    fn validate(&self, path: &str) -> Result<(), InputError> {
        let mut pr = Problems::default();
        pr.check(nonneg(format!("{path}.min_kw"), self.min_kw));
        pr.check(nonneg(format!("{path}.max_kw"), self.max_kw));
        pr.check(nonneg(format!("{path}.cost_per_kwh"), self.cost_per_kwh));
        pr.check(nonneg(format!("{path}.ramp_kw_per_s"), self.ramp_kw_per_s));
        pr.check(nonneg(
            format!("{path}.no_load_cost_per_h"),
            self.no_load_cost_per_h,
        ));
        pr.check(nonneg(format!("{path}.start_cost"), self.start_cost));
        pr.check(nonneg(format!("{path}.min_up_h"), self.min_up_h));
        pr.check(nonneg(format!("{path}.min_down_h"), self.min_down_h));
        if let Some(h) = self.hours_in_state {
            pr.check(nonneg(format!("{path}.hours_in_state"), h));
        }
        if self.optimize_commitment && self.relaxed_commitment {
            pr.check(Err(bad(
                format!("{path}.optimize_commitment"),
                "cannot be combined with relaxed_commitment",
            )));
        }
        if self.max_kw < self.min_kw {
            pr.check(Err(bad(
                format!("{path}.max_kw"),
                format!("{} is below min_kw {}", self.max_kw, self.min_kw),
            )));
        }
        if let Some(i) = self.initial_kw {
            pr.check(nonneg(format!("{path}.initial_kw"), i));
        }
        pr.finish()
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
            final_soc_min_kwh: o.opt_num("final_soc_min_kwh")?,
        };
        o.finish()?;
        Ok(u)
    }
    fn validate(&self, path: &str) -> Result<(), InputError> {
        let mut pr = Problems::default();
        pr.check(self.unit.validate(path));
        pr.check(nonneg(format!("{path}.ramp_kw_per_s"), self.ramp_kw_per_s));
        pr.check(nonneg(
            format!("{path}.terminal_value_per_kwh"),
            self.terminal_value_per_kwh,
        ));
        if let Some(f) = self.final_soc_min_kwh {
            if !(f.is_finite() && f <= self.unit.soc_max_kwh) {
                pr.check(Err(bad(
                    format!("{path}.final_soc_min_kwh"),
                    format!("{f} is above soc_max_kwh {}", self.unit.soc_max_kwh),
                )));
            }
        }
        if let Some(i) = self.initial_kw {
            if !(i.is_finite() && i >= -self.unit.max_charge_kw && i <= self.unit.max_discharge_kw)
            {
                pr.check(Err(bad(
                    format!("{path}.initial_kw"),
                    format!(
                        "{i} is outside [-max_charge_kw, max_discharge_kw] = [{}, {}]",
                        -self.unit.max_charge_kw, self.unit.max_discharge_kw
                    ),
                )));
            }
        }
        pr.finish()
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
        periods_within_limit(ppath.clone(), items.len())?;
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
        let max_commitment_nodes = match o.opt_num("max_commitment_nodes")? {
            None => None,
            Some(n) if n.fract() == 0.0 && (1.0..=MAX_COMMITMENT_NODES as f64).contains(&n) => {
                Some(n as usize)
            }
            Some(n) => {
                return Err(bad(
                    join(path, "max_commitment_nodes"),
                    format!("{n} is not a whole number from 1 to {MAX_COMMITMENT_NODES}"),
                ))
            }
        };
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
            max_commitment_nodes,
        })
    }

    pub fn validate(&self, prefix: &str) -> Result<(), InputError> {
        let mut pr = Problems::default();
        let at = |k: &str| join(prefix, k);
        pr.check(dt_h_valid(at("dt_h"), self.dt_h));
        pr.check(nonneg(at("voll_per_kwh"), self.voll_per_kwh));
        if self.periods.is_empty() {
            pr.check(Err(bad(at("periods"), "needs at least one period")));
        }
        pr.check(periods_within_limit(at("periods"), self.periods.len()));
        let units = self.pv.len() + self.wind.len() + self.oil.len() + self.storage.len();
        pr.check(units_within_limit(prefix.to_string(), units));
        let decided = self.oil.iter().filter(|o| o.optimize_commitment).count();
        if decided * self.periods.len() > MAX_COMMITMENT_BINARIES {
            pr.check(Err(bad(
                at("oil"),
                format!(
                    "{decided} units with optimize_commitment over {} periods make {} on/off \
                     decisions; at most {MAX_COMMITMENT_BINARIES} are accepted",
                    self.periods.len(),
                    decided * self.periods.len()
                ),
            )));
        }
        for (i, u) in self.pv.iter().enumerate() {
            pr.check(u.validate(&index(&at("pv"), i)));
        }
        for (i, u) in self.wind.iter().enumerate() {
            pr.check(u.validate(&index(&at("wind"), i)));
        }
        for (i, u) in self.oil.iter().enumerate() {
            pr.check(u.validate(&index(&at("oil"), i)));
        }
        for (i, u) in self.storage.iter().enumerate() {
            pr.check(u.validate(&index(&at("storage"), i)));
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
        pr.check(unique_ids(ids.clone().into_iter()));
        if let Some(r) = &self.reserve {
            let rp = at("reserve");
            pr.check(nonneg(join(&rp, "load_frac"), r.load_frac));
            pr.check(nonneg(join(&rp, "pv_frac"), r.pv_frac));
            pr.check(nonneg(join(&rp, "wind_frac"), r.wind_frac));
            pr.check(nonneg(
                join(&rp, "shortfall_cost_per_kwh"),
                r.shortfall_cost_per_kwh,
            ));
        }
        if let Some(s) = self.max_renewable_share {
            if !(s.is_finite() && (0.0..=1.0).contains(&s)) {
                pr.check(Err(bad(
                    at("max_renewable_share"),
                    format!("{s} is outside [0, 1]"),
                )));
            }
        }
        pr.check(nonneg(
            at("smoothing_cost_per_kw2"),
            self.smoothing_cost_per_kw2,
        ));
        let renewables: Vec<&str> = self
            .pv
            .iter()
            .chain(&self.wind)
            .map(|u| u.id.as_str())
            .collect();
        let oils: Vec<&str> = self.oil.iter().map(|u| u.id.as_str()).collect();
        for (t, p) in self.periods.iter().enumerate() {
            let pp = index(&at("periods"), t);
            pr.check(nonneg(join(&pp, "demand_kw"), p.demand_kw));
            for (id, v) in &p.available_kw {
                let path = join(&join(&pp, "available_kw"), id);
                if !renewables.contains(&id.as_str()) {
                    pr.check(Err(bad(path.clone(), "is not a PV or wind unit")));
                }
                pr.check(nonneg(path, *v));
            }
            for id in &renewables {
                if !p.available_kw.contains_key(*id) {
                    pr.check(Err(bad(
                        join(&pp, "available_kw"),
                        format!("no forecast for '{id}'"),
                    )));
                }
            }
            for id in p.running.keys() {
                if !oils.contains(&id.as_str()) {
                    pr.check(Err(bad(
                        join(&join(&pp, "running"), id),
                        "is not an oil unit",
                    )));
                }
            }
        }
        pr.finish()
    }
}
