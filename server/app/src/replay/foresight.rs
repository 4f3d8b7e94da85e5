//! The perfect-foresight optimum of a replayed day: the yardstick of the
//! dispatch's realized cost.
//!
//! **Owns:** recording, while the main run goes, what the day really was
//! (demand and PV/wind availability, period by period, from the simulator's
//! energy counters), and solving the whole day at once with everything known:
//! the same horizon model and commitment search as the live look-ahead
//! (`HorizonProblem` with `optimize_commitment`), the plant's cost model, the
//! diesels' state and the battery's state of charge at the start, and at least
//! the realized state of charge at the end (so stored energy left over is not
//! counted as a saving).
//!
//! **Must not touch:** the run itself: it reads snapshots and solves after.
//!
//! Its period is the plant's look-ahead period (15 minutes without one): the
//! realized run is judged against a plan made at that resolution with the
//! period's average demand and availability.

use std::collections::BTreeMap;
use std::time::Duration;

use gridscada_config::{MicrogridConfig, Plant, UnitKind};
use gridscada_control::dispatch::{
    HorizonOil, HorizonProblem, HorizonRenewable, HorizonStorage, PeriodForecast, StorageUnit,
};
use gridscada_sim::scenario::report::Foresight;
use gridscada_sim::SimSnapshot;

/// Relaxations the day's commitment search may solve: a day of 15-minute
/// periods proves or comes within the reported bound in about a minute.
const FORESIGHT_NODES: usize = 1500;

/// Cumulative counters at a period boundary.
#[derive(Debug, Clone)]
struct Mark {
    at_s: f64,
    demand_kwh: f64,
    /// PV and wind: produced + curtailed, kWh (what was available).
    available_kwh: BTreeMap<String, f64>,
}

fn mark(at: Duration, snap: &SimSnapshot) -> Option<Mark> {
    let mg = snap.microgrid.as_ref()?;
    Some(Mark {
        at_s: at.as_secs_f64(),
        demand_kwh: mg.energy.demand_kwh,
        available_kwh: mg
            .units
            .iter()
            .filter(|u| matches!(u.kind, UnitKind::Pv | UnitKind::Wind))
            .map(|u| {
                (
                    u.id.clone(),
                    u.counters.energy_kwh + u.counters.curtailed_kwh,
                )
            })
            .collect(),
    })
}

/// What the day was, period by period, as the run saw it.
pub(super) struct ForesightRecorder {
    period: Duration,
    next: Duration,
    last: Option<Mark>,
    periods: Vec<PeriodForecast>,
}

impl ForesightRecorder {
    pub(super) fn new(plant: &Plant) -> Self {
        let period_s = plant
            .microgrid
            .as_ref()
            .and_then(|m| m.horizon.as_ref())
            .map_or(900.0, |h| *h.period_s.get_ref());
        let period = Duration::from_secs_f64(period_s.max(1.0));
        ForesightRecorder {
            period,
            next: Duration::ZERO,
            last: None,
            periods: Vec::new(),
        }
    }

    /// Called with every snapshot of the run, at plant offset `at`.
    pub(super) fn push(&mut self, at: Duration, snap: &SimSnapshot) {
        if at < self.next {
            return;
        }
        let Some(now) = mark(at, snap) else {
            return;
        };
        if let Some(last) = &self.last {
            let h = (now.at_s - last.at_s) / 3600.0;
            if h > 0.0 {
                let avg = |a: f64, b: f64| ((b - a) / h).max(0.0);
                self.periods.push(PeriodForecast {
                    demand_kw: avg(last.demand_kwh, now.demand_kwh),
                    available_kw: now
                        .available_kwh
                        .iter()
                        .map(|(id, e)| {
                            let e0 = last.available_kwh.get(id).copied().unwrap_or(*e);
                            (id.clone(), avg(e0, *e))
                        })
                        .collect(),
                    running: BTreeMap::new(),
                });
            }
        }
        self.last = Some(now);
        while self.next <= at {
            self.next += self.period;
        }
    }

    /// The whole periods recorded (a partial last period is left out).
    fn periods(&self) -> &[PeriodForecast] {
        &self.periods
    }

    fn period_h(&self) -> f64 {
        self.period.as_secs_f64() / 3600.0
    }
}

/// The day's optimum with everything known, or why there is none.
pub(super) fn perfect_foresight(
    plant: &Plant,
    fuel_price: Option<f64>,
    rec: &ForesightRecorder,
    baseline: &SimSnapshot,
    end: &SimSnapshot,
) -> Option<Foresight> {
    let mg = plant.microgrid.as_ref()?;
    let periods = rec.periods();
    if periods.is_empty() {
        return None;
    }
    let problem = day_problem(mg, fuel_price, rec.period_h(), periods, baseline, end)?;
    // The day's problem as `gridscada dispatch solve` reads it, for solving it
    // with another solver (docs/BENCHMARKS.md, "Dispatch against the optimum").
    if let Some(path) = std::env::var_os("GRIDSCADA_FORESIGHT_OUT") {
        let written = serde_json::to_string(&problem)
            .map_err(|e| e.to_string())
            .and_then(|text| std::fs::write(&path, text).map_err(|e| e.to_string()));
        if let Err(e) = written {
            tracing::warn!("cannot write the perfect-foresight problem to {path:?}: {e}");
        }
    }
    let covered_h = periods.len() as f64 * rec.period_h();
    Some(match problem.solve() {
        Ok(sol) => {
            let c = sol.commitment.as_ref();
            Foresight {
                status: "optimal".into(),
                reason: None,
                cost: Some(sol.objective),
                lower_bound: Some(c.map_or(sol.objective, |c| c.lower_bound)),
                proven: c.is_none_or(|c| c.proven),
                nodes: c.map_or(0, |c| c.nodes),
                periods: periods.len(),
                period_s: rec.period_h() * 3600.0,
                covered_h,
                diesel_runtime_h: c.map_or(0.0, |c| {
                    c.running.values().flatten().filter(|&&on| on).count() as f64 * rec.period_h()
                }),
                diesel_starts: c.map_or(0, |c| c.starts.values().sum()),
                solve_ms: sol.solve_ms,
            }
        }
        Err(e) => Foresight {
            status: "failed".into(),
            reason: Some(e.to_string()),
            periods: periods.len(),
            period_s: rec.period_h() * 3600.0,
            covered_h,
            ..Foresight::default()
        },
    })
}

/// The day as one horizon problem: every period known, diesels committed
/// optimally from their state at the start, storage from its state of charge
/// at the start to at least the realized one at the end.
fn day_problem(
    mg: &MicrogridConfig,
    fuel_price: Option<f64>,
    period_h: f64,
    periods: &[PeriodForecast],
    baseline: &SimSnapshot,
    end: &SimSnapshot,
) -> Option<HorizonProblem> {
    let (mg0, mg1) = (baseline.microgrid.as_ref()?, end.microgrid.as_ref()?);
    let unit0 = |id: &str| mg0.units.iter().find(|u| u.id == id);
    let unit1 = |id: &str| mg1.units.iter().find(|u| u.id == id);
    let renewable = |kind: UnitKind| {
        mg.units
            .iter()
            .filter(|u| u.kind == kind)
            .map(|u| HorizonRenewable {
                id: u.id.get_ref().clone(),
                cost_per_kwh: u.cost_per_kwh,
                ramp_kw_per_s: 0.0,
                initial_kw: None,
            })
            .collect::<Vec<_>>()
    };
    let oil = mg
        .units
        .iter()
        .filter(|u| u.kind == UnitKind::Diesel)
        .map(|u| {
            let cost = mg.diesel_cost(u, fuel_price);
            let id = u.id.get_ref().clone();
            HorizonOil {
                running: unit0(&id).is_some_and(|s| s.run_cmd),
                min_kw: u.min_kw,
                max_kw: u.max_kw,
                cost_per_kwh: cost.marginal_per_kwh,
                optimize_commitment: true,
                no_load_cost_per_h: cost.no_load_per_h,
                start_cost: cost.start_cost,
                min_up_h: cost.min_up_h,
                min_down_h: cost.min_down_h,
                id,
                ..HorizonOil::default()
            }
        })
        .collect();
    let storage = mg
        .units
        .iter()
        .filter(|u| u.kind == UnitKind::Storage)
        .map(|u| {
            let id = u.id.get_ref().clone();
            let soc_max = u.soc_max_kwh.max(u.soc_min_kwh);
            let clamp = |v: f64| v.clamp(u.soc_min_kwh, soc_max);
            let soc0 = unit0(&id)
                .and_then(|s| s.soc_kwh)
                .map_or(u.soc_min_kwh, clamp);
            let soc1 = unit1(&id).and_then(|s| s.soc_kwh).map(clamp);
            HorizonStorage {
                unit: StorageUnit {
                    id,
                    soc_kwh: soc0,
                    soc_min_kwh: u.soc_min_kwh,
                    soc_max_kwh: soc_max,
                    max_charge_kw: u.max_charge_kw,
                    max_discharge_kw: u.max_discharge_kw,
                    eff_charge: *u.eff_charge.get_ref(),
                    eff_discharge: *u.eff_discharge.get_ref(),
                    cycle_cost_per_kwh: u.cycle_cost_per_kwh,
                    stored_value_per_kwh: 0.0,
                },
                ramp_kw_per_s: 0.0,
                initial_kw: None,
                terminal_value_per_kwh: 0.0,
                final_soc_min_kwh: soc1,
            }
        })
        .collect();
    Some(HorizonProblem {
        dt_h: period_h,
        voll_per_kwh: mg.voll_per_kwh,
        periods: periods.to_vec(),
        pv: renewable(UnitKind::Pv),
        wind: renewable(UnitKind::Wind),
        oil,
        storage,
        reserve: None,
        max_renewable_share: None,
        smoothing_cost_per_kw2: 0.0,
        max_commitment_nodes: Some(FORESIGHT_NODES),
    })
}
