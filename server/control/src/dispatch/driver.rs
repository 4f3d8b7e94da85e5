//! The live outer loop of the microgrid cascade.
//!
//! **Owns:** every `dispatch_period_s` of plant time: reading demand,
//! availability, state of charge and running state from the tag database;
//! the diesel commitment rule; building and solving the single-period LP (the
//! same [`DispatchProblem::solve`] as `gridscada dispatch solve`); switching
//! to the rule-based fallback on stale or Bad measurements, a failed solve or
//! a failed write; writing each unit's setpoint and the diesels' run commands
//! through the `TagWriter`; publishing a [`DispatchStatus`] and emitting
//! [`DispatchNotice`]s (events, the "dispatch fallback" alarm); the
//! look-ahead plan's thread, started when a plan is due and joined at the
//! plant time the plan is adopted (`adopt_after_s` after its measurements).
//!
//! **Must not touch:** Modbus or any device directly (only `TagWriter`), the
//! alarm engine and the event store (it only sends notices), wall time (plant
//! time comes from the `Clock`; a plan is adopted at its plant time, never
//! when its solve happens to end). [`Dispatcher::step`] is one period
//! without sleeping, so tests drive it with a fake writer and tag database.
//!
//! This file holds the [`Dispatcher`] (one period); its task is in
//! `driver/run.rs`, what it reports in `driver/status.rs`.

use std::collections::HashMap;

use serde::Serialize;

use gridscada_config::{MicrogridConfig, UnitConfig, UnitIo, UnitKind};
use gridscada_tagdb::{TagDb, TagWriter, Timestamp, Value};

use super::lookahead::{horizon_problem, horizon_problem_over, plan, value_periods, HorizonPlan};
use super::rules::{commit_diesels, fallback_dispatch, CommitmentDecision, DieselState};
use super::single::{DispatchProblem, OilUnit, RenewableUnit, StorageUnit};
use super::{DispatchError, Setpoints};

mod run;
mod status;
#[cfg(test)]
mod tests;

pub use run::{run_dispatch, run_dispatch_with};
pub use status::{DispatchMode, DispatchNotice, DispatchStatus, FALLBACK_ALARM};

use run::period_s;

/// How the outer loop chooses setpoints.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum DispatchPolicy {
    /// The LP, with the rule as fallback (the live plant).
    #[default]
    Optimal,
    /// The rule-based dispatch only, never the LP: the baseline that scenario
    /// replay compares the optimal dispatch's cost against. Running on the
    /// rule by choice raises no fallback alarm.
    Rule,
}

/// What a kWh left in `unit` is worth when no plan says better: the
/// cheapest diesel energy it will displace later (a kWh at full load, no-load
/// fuel included), discounted by the round trip and a margin. That makes
/// storing a renewable surplus (or a running diesel's minimum-load excess)
/// worth more than curtailing it. It prices stored energy in the
/// single-period LP without a fresh plan and ends the day-long relaxation
/// that values what a plan leaves stored. Without a diesel, stored energy
/// displaces shedding later: a small share of the value of lost load.
fn stored_energy_value(mg: &MicrogridConfig, unit: &UnitConfig) -> f64 {
    const MARGIN: f64 = 0.9;
    let round_trip = *unit.eff_charge.get_ref() * *unit.eff_discharge.get_ref();
    let displaced = mg
        .units
        .iter()
        .filter(|u| u.kind == UnitKind::Diesel)
        .map(|u| {
            mg.diesel_cost(u, mg.fuel_price(None))
                .average_per_kwh(u.max_kw)
        })
        .fold(f64::INFINITY, f64::min);
    let displaced = if displaced.is_finite() {
        displaced
    } else {
        0.05 * mg.voll_per_kwh
    };
    (MARGIN * displaced * round_trip).max(0.0)
}

struct LiveUnit {
    cfg: UnitConfig,
    io: UnitIo,
}

/// The outer loop's state between periods.
pub struct Dispatcher {
    cfg: MicrogridConfig,
    units: Vec<LiveUnit>,
    diesels: Vec<DieselState>,
    /// Last good value of each measurement, held for the fallback.
    held: HashMap<String, f64>,
    alarm_active: bool,
    first: bool,
    /// Run commands the field confirmed.
    run_written: HashMap<String, bool>,
    policy: DispatchPolicy,
    /// The last look-ahead plan adopted (made every `resolve_s`), and which
    /// diesels ran when it was made.
    plan: Option<HorizonPlan>,
    plan_running: Vec<bool>,
    /// The next plan, being solved on its own thread until its adoption.
    pending: Option<PendingPlan>,
    /// Setpoints the field accepted last period: where the plan's ramps start.
    last_setpoints: Setpoints,
}

/// One measurement: the value, or why it cannot be used.
type Meas = Result<f64, String>;

/// A look-ahead plan on its way: solved from the measurements of one
/// period, adopted at a fixed plant time after them.
struct PendingPlan {
    adopt_at: Timestamp,
    /// Which diesels the plan saw running.
    running: Vec<bool>,
    solve: PlanSolve,
}

/// What a plan is made from, owned, so that another thread can make it.
struct PlanInputs {
    cfg: MicrogridConfig,
    now: Timestamp,
    measured: DispatchProblem,
    /// Where the plan's ramps start: the setpoints last accepted.
    initial_kw: Setpoints,
    /// Hours each diesel has been in its present state.
    hours_in_state: HashMap<String, f64>,
}

impl PlanInputs {
    /// The plan: the day-long relaxation first, which prices what the plan
    /// leaves in storage (the fixed estimate where it fails), then the
    /// horizon with its commitment search.
    fn solve(&self) -> HorizonPlan {
        let cfg = &self.cfg;
        let Some(h) = cfg.horizon.as_ref() else {
            return HorizonPlan::failed(self.now, "no look-ahead is configured".into());
        };
        let fixed = |id: &str| {
            cfg.units
                .iter()
                .find(|u| u.id.get_ref() == id)
                .map_or(0.0, |u| stored_energy_value(cfg, u))
        };
        let in_state = |id: &str| self.hours_in_state.get(id).copied();
        let n = (*h.periods.get_ref()).max(1.0) as usize;
        let day = horizon_problem_over(
            cfg,
            h,
            value_periods(h),
            self.now,
            &self.measured,
            &self.initial_kw,
            &fixed,
            &in_state,
        );
        let values = day.relaxed_stored_energy_values().ok();
        let terminal = |id: &str| {
            values
                .as_ref()
                .and_then(|v| v.get(n))
                .and_then(|s| s.get(id))
                .filter(|v| v.is_finite())
                .map_or_else(|| fixed(id), |v| v.max(0.0))
        };
        let problem = horizon_problem(
            cfg,
            h,
            self.now,
            &self.measured,
            &self.initial_kw,
            &terminal,
            &in_state,
        );
        plan(&problem, self.now)
    }
}

/// A plan being solved on its own thread, so the control loop's thread
/// (a replay's only runtime thread) goes on meanwhile.
struct PlanSolve {
    thread: Option<std::thread::JoinHandle<HorizonPlan>>,
    now: Timestamp,
}

impl PlanSolve {
    fn start(inputs: PlanInputs) -> PlanSolve {
        let now = inputs.now;
        let thread = std::thread::Builder::new()
            .name("look-ahead".into())
            .spawn(move || inputs.solve())
            .map_err(|e| tracing::warn!("cannot start the look-ahead's thread: {e}"))
            .ok();
        PlanSolve { thread, now }
    }

    /// The plan, waiting for it if need be; a failed plan (with its reason)
    /// if the thread could not run or did not end well.
    ///
    /// The wait blocks the calling thread on purpose: a replay's plant time
    /// must not move while the plan is made. On a server's multi-thread
    /// runtime the wait hands this worker's other tasks (the pair's lease
    /// renewal among them) to another worker first: a slow plan in a debug
    /// build once starved the lease and flapped the pair.
    fn finish(self) -> HorizonPlan {
        let join = |t: std::thread::JoinHandle<HorizonPlan>| {
            if t.is_finished() || !on_multi_thread_runtime() {
                t.join()
            } else {
                tokio::task::block_in_place(|| t.join())
            }
        };
        match self.thread.map(join) {
            Some(Ok(plan)) => plan,
            Some(Err(_)) => HorizonPlan::failed(self.now, "the look-ahead's solve panicked".into()),
            None => HorizonPlan::failed(self.now, "the look-ahead's thread did not start".into()),
        }
    }
}

fn on_multi_thread_runtime() -> bool {
    tokio::runtime::Handle::try_current()
        .is_ok_and(|h| h.runtime_flavor() == tokio::runtime::RuntimeFlavor::MultiThread)
}

impl Dispatcher {
    pub fn new(cfg: MicrogridConfig, now: Timestamp) -> Self {
        let units: Vec<LiveUnit> = cfg
            .units
            .iter()
            .map(|u| LiveUnit {
                io: u.io(),
                cfg: u.clone(),
            })
            .collect();
        let eligible = Timestamp::from_millis(
            now.as_millis()
                - ((cfg.commitment.min_stop_s.max(0.0) + cfg.commitment.min_run_s.max(0.0))
                    * 1000.0)
                    .min(1e12) as i64,
        );
        let diesels = units
            .iter()
            .filter(|u| u.cfg.kind == UnitKind::Diesel)
            .map(|u| DieselState {
                id: u.cfg.id.get_ref().clone(),
                max_kw: u.cfg.max_kw,
                cost_per_kwh: cfg
                    .diesel_cost(&u.cfg, cfg.fuel_price(None))
                    .marginal_per_kwh,
                // Set from the measured running state in the first period.
                run: false,
                since: eligible,
            })
            .collect();
        Dispatcher {
            cfg,
            units,
            diesels,
            held: HashMap::new(),
            alarm_active: false,
            first: true,
            run_written: HashMap::new(),
            policy: DispatchPolicy::Optimal,
            plan: None,
            plan_running: Vec::new(),
            pending: None,
            last_setpoints: Setpoints::default(),
        }
    }

    /// Chooses how setpoints are made (the LP by default).
    pub fn with_policy(mut self, policy: DispatchPolicy) -> Self {
        self.policy = policy;
        self
    }

    fn read(&self, db: &TagDb, name: &str, now: Timestamp) -> Meas {
        let s = db
            .get_by_name(name)
            .ok_or_else(|| format!("tag {name} is not in the tag database"))?;
        if !s.quality.is_good() {
            return Err(format!("{name} is {}", s.quality));
        }
        let age = now.since(s.timestamp).as_secs_f64();
        if age > self.cfg.stale_after_s {
            return Err(format!("{name} is stale ({age:.0} s old)"));
        }
        match s.value.as_f64() {
            Some(x) if x.is_finite() => Ok(x),
            _ => Err(format!("{name} has no numeric value ({})", s.value)),
        }
    }

    /// A measurement, remembered when good; else the held value (or
    /// `default`) and the reason is added to `problems`.
    fn meas_or_held(
        &mut self,
        m: Meas,
        key: &str,
        default: f64,
        problems: &mut Vec<String>,
    ) -> f64 {
        match m {
            Ok(v) => {
                self.held.insert(key.to_string(), v);
                v
            }
            Err(e) => {
                problems.push(e);
                self.held.get(key).copied().unwrap_or(default)
            }
        }
    }

    /// One dispatch period at plant time `now`: read, commit, solve or fall
    /// back, write. Returns the status and the notices to send.
    pub async fn step(
        &mut self,
        db: &TagDb,
        writer: &dyn TagWriter,
        now: Timestamp,
    ) -> (DispatchStatus, Vec<DispatchNotice>) {
        let mut notices = Vec::new();
        let mut problems: Vec<String> = Vec::new();
        let dt_h = period_s(&self.cfg) / 3600.0;

        // Read the plant.
        let demand_tag = self.cfg.demand_tag.get_ref().clone();
        let m = self.read(db, &demand_tag, now);
        let demand = self
            .meas_or_held(m, &demand_tag, 0.0, &mut problems)
            .max(0.0);
        let mut problem = DispatchProblem {
            dt_h,
            demand_kw: demand,
            voll_per_kwh: self.cfg.voll_per_kwh,
            pv: vec![],
            wind: vec![],
            oil: vec![],
            storage: vec![],
        };
        let mut measured_running: HashMap<String, bool> = HashMap::new();
        let mut soc_sum = 0.0;
        let mut cap_sum = 0.0;
        let mut soc_known = true;
        let mut storage_cover = 0.0;
        let cover_h = (self.cfg.commitment.min_run_s / 3600.0).max(dt_h);
        for i in 0..self.units.len() {
            let (cfg, io) = (self.units[i].cfg.clone(), self.units[i].io.clone());
            let id = cfg.id.get_ref().clone();
            match cfg.kind {
                UnitKind::Pv | UnitKind::Wind => {
                    let m = self.read(db, &io.available_kw, now);
                    let mut a = self
                        .meas_or_held(m, &io.available_kw, 0.0, &mut problems)
                        .max(0.0);
                    if cfg.rated_kw > 0.0 {
                        a = a.min(cfg.rated_kw);
                    }
                    let u = RenewableUnit {
                        id,
                        available_kw: a,
                        cost_per_kwh: cfg.cost_per_kwh,
                    };
                    if cfg.kind == UnitKind::Pv {
                        problem.pv.push(u);
                    } else {
                        problem.wind.push(u);
                    }
                }
                UnitKind::Storage => {
                    let m = self.read(db, &io.soc_kwh, now);
                    let good = m.is_ok();
                    let soc = self.meas_or_held(m, &io.soc_kwh, cfg.soc_min_kwh, &mut problems);
                    // A reading just outside the band is physics, not bad input: clamp.
                    let soc = soc.clamp(cfg.soc_min_kwh, cfg.soc_max_kwh.max(cfg.soc_min_kwh));
                    let mut s = StorageUnit {
                        id,
                        soc_kwh: soc,
                        soc_min_kwh: cfg.soc_min_kwh,
                        soc_max_kwh: cfg.soc_max_kwh.max(cfg.soc_min_kwh),
                        max_charge_kw: cfg.max_charge_kw,
                        max_discharge_kw: cfg.max_discharge_kw,
                        eff_charge: *cfg.eff_charge.get_ref(),
                        eff_discharge: *cfg.eff_discharge.get_ref(),
                        cycle_cost_per_kwh: cfg.cycle_cost_per_kwh,
                        stored_value_per_kwh: stored_energy_value(&self.cfg, &cfg),
                    };
                    if !good {
                        soc_known = false;
                        // Never move a battery whose state of charge we cannot see.
                        s.max_charge_kw = 0.0;
                        s.max_discharge_kw = 0.0;
                    }
                    let cap = if cfg.capacity_kwh > 0.0 {
                        cfg.capacity_kwh
                    } else {
                        cfg.soc_max_kwh
                    };
                    soc_sum += soc;
                    cap_sum += cap;
                    storage_cover += s
                        .max_discharge_kw
                        .min((soc - s.soc_min_kwh).max(0.0) * s.eff_discharge / cover_h);
                    problem.storage.push(s);
                }
                UnitKind::Diesel => {
                    let running = match self.read(db, &io.running, now) {
                        Ok(v) => Some(v != 0.0),
                        Err(e) => {
                            problems.push(e);
                            None
                        }
                    };
                    if let Some(r) = running {
                        measured_running.insert(id.clone(), r);
                    }
                    problem.oil.push(OilUnit {
                        id,
                        running: running.unwrap_or(false),
                        min_kw: cfg.min_kw,
                        max_kw: cfg.max_kw,
                        // The fuel curve's slope: the no-load part is paid
                        // whatever the setpoint, so it is the look-ahead's
                        // commitment that weighs it.
                        cost_per_kwh: self
                            .cfg
                            .diesel_cost(&cfg, self.cfg.fuel_price(None))
                            .marginal_per_kwh,
                    });
                }
            }
        }

        // Commitment: adopt the measured state the first time, then the rule.
        if self.first {
            for d in &mut self.diesels {
                d.run = measured_running.get(&d.id).copied().unwrap_or(false);
                if d.run {
                    d.since = now; // do not stop a running diesel right after a restart
                }
            }
        }
        let renewables: f64 = problem
            .pv
            .iter()
            .chain(&problem.wind)
            .map(|u| u.available_kw)
            .sum();
        // The plan sees each diesel as commanded now (one starting counts as
        // running: it will be within seconds).
        for o in &mut problem.oil {
            o.running = self.diesels.iter().any(|d| d.id == o.id && d.run);
        }
        // Look ahead when a plan is due (from usable measurements only), and
        // adopt the plan whose time has come; stored energy is priced with it.
        if self.policy == DispatchPolicy::Optimal {
            if problems.is_empty() {
                self.look_ahead(&problem, now);
            }
            self.adopt_plan(now, &mut notices);
        }
        // Commitment: the plan's first period while the plan is fresh, else
        // the rule (an alarm says so where a look-ahead is configured).
        let mut commitment_fallback: Option<String> = None;
        let planned: Vec<Option<bool>> = self
            .diesels
            .iter()
            .map(|d| self.planned_run(&d.id, now))
            .collect();
        let soc_frac = (soc_known && cap_sum > 0.0).then(|| soc_sum / cap_sum);
        let mut decision = None;
        if planned.iter().any(Option::is_some) {
            for (d, want) in self.diesels.iter().zip(&planned) {
                if let Some(want) = *want {
                    if want != d.run {
                        decision = Some(CommitmentDecision {
                            id: d.id.clone(),
                            run: want,
                            reason: "the look-ahead plan's optimal commitment".into(),
                        });
                        break;
                    }
                }
            }
        } else {
            if self.cfg.horizon.is_some()
                && self.policy == DispatchPolicy::Optimal
                && !self.diesels.is_empty()
            {
                commitment_fallback = Some(match self.plan.as_ref() {
                    Some(p) if !p.is_optimal() => format!(
                        "diesel commitment by rule: the look-ahead plan failed ({})",
                        p.reason.clone().unwrap_or_default()
                    ),
                    Some(_) => "diesel commitment by rule: the look-ahead plan is stale".into(),
                    None => "diesel commitment by rule: no look-ahead plan".into(),
                });
            }
            decision = commit_diesels(
                &self.cfg.commitment,
                now,
                problem.demand_kw - renewables,
                storage_cover,
                soc_frac,
                &self.diesels,
            );
        }
        if let Some(dec) = decision {
            if let Some(d) = self.diesels.iter_mut().find(|d| d.id == dec.id) {
                d.run = dec.run;
                d.since = now;
            }
            notices.push(DispatchNotice::Event {
                at: now,
                message: format!(
                    "{} {}: {}",
                    dec.id,
                    if dec.run { "start" } else { "stop" },
                    dec.reason
                ),
            });
        }
        // The LP sees a diesel only when it is commanded on and reports running.
        for o in &mut problem.oil {
            let cmd = self
                .diesels
                .iter()
                .find(|d| d.id == o.id)
                .is_some_and(|d| d.run);
            let meas = measured_running.get(&o.id).copied();
            o.running = cmd && meas.unwrap_or(cmd);
        }

        // While a diesel runs, a stored kWh is worth at least the fixed
        // estimate, so surplus beside it is stored rather than curtailed
        // (kept from the rule's days: a plan expecting the battery to fill
        // anyway curtailed wind beside a diesel at minimum load).
        let diesel_committed = self.diesels.iter().any(|d| d.run);
        for s in &mut problem.storage {
            if let Some(v) = self.planned_value(&s.id, now) {
                s.stored_value_per_kwh = if diesel_committed {
                    v.max(s.stored_value_per_kwh)
                } else {
                    v
                };
            }
        }

        // Solve, or fall back.
        let mut st = DispatchStatus {
            at: now,
            ..DispatchStatus::default()
        };
        let mut reason: Option<String> = None;
        if self.policy == DispatchPolicy::Rule {
            st.status = "rule".into();
        } else if problems.is_empty() {
            match self.solve_following_plan(&problem, now) {
                Ok(sol) => {
                    st.mode = DispatchMode::Optimal;
                    st.status = "optimal".into();
                    st.objective = Some(sol.objective);
                    st.solve_ms = Some(sol.solve_ms);
                    st.shed_kw = sol.shed_kw;
                    st.setpoints_kw = sol.setpoints_kw;
                }
                Err(e) => {
                    st.status = match &e {
                        DispatchError::Infeasible(_) => "infeasible",
                        _ => "error",
                    }
                    .into();
                    reason = Some(format!("dispatch solve failed: {e}"));
                }
            }
        } else {
            st.status = "not solved".into();
            reason = Some(format!("measurements unusable: {}", problems.join("; ")));
        }
        if st.mode == DispatchMode::Fallback {
            self.apply_fallback(&problem, &mut st);
        }

        // Write setpoints, then run commands.
        let mut failures = self.write_setpoints(writer, &st.setpoints_kw).await;
        if !failures.is_empty() && st.mode == DispatchMode::Optimal {
            // The optimal set no longer balances: replace it by the rule.
            reason = Some(format!("setpoint write failed: {}", failures.join("; ")));
            st.mode = DispatchMode::Fallback;
            self.apply_fallback(&problem, &mut st);
            failures.extend(self.write_setpoints(writer, &st.setpoints_kw).await);
        }
        for d in &self.diesels {
            st.run_cmd.insert(d.id.clone(), d.run);
        }
        let diesel_io: Vec<(String, String)> = self
            .units
            .iter()
            .filter(|u| u.cfg.kind == UnitKind::Diesel)
            .map(|u| (u.cfg.id.get_ref().clone(), u.io.run_cmd.clone()))
            .collect();
        for (id, tag) in diesel_io {
            let run = st.run_cmd.get(&id).copied().unwrap_or(false);
            if self.run_written.get(&id) == Some(&run) {
                continue;
            }
            match writer.write(&tag, Value::Bool(run)).await {
                Ok(_) => {
                    self.run_written.insert(id, run);
                }
                Err(e) => failures.push(format!("{tag}: {e}")),
            }
        }
        if !failures.is_empty() && reason.is_none() {
            reason = Some(format!("write failed: {}", failures.join("; ")));
            st.mode = DispatchMode::Fallback;
        }
        if failures.is_empty() {
            self.last_setpoints = st.setpoints_kw.clone();
        }
        st.write_failures = failures;
        st.reason = reason.clone();
        st.inputs = Some(problem);
        st.horizon = self.plan.clone();

        // Alarm and events on transitions (none when the rule is the policy).
        let mode = match self.policy {
            DispatchPolicy::Rule => DispatchMode::Optimal,
            DispatchPolicy::Optimal if commitment_fallback.is_some() => DispatchMode::Fallback,
            DispatchPolicy::Optimal => st.mode,
        };
        let reason = reason.or(commitment_fallback);
        match (mode, self.alarm_active) {
            (DispatchMode::Fallback, false) => {
                let r = reason.unwrap_or_default();
                tracing::warn!("dispatch fallback: {r}");
                notices.push(DispatchNotice::Alarm {
                    at: now,
                    name: FALLBACK_ALARM.into(),
                    active: true,
                    reason: r.clone(),
                });
                notices.push(DispatchNotice::Event {
                    at: now,
                    message: format!("dispatch switched to the fallback rule: {r}"),
                });
                self.alarm_active = true;
            }
            (DispatchMode::Optimal, true) => {
                notices.push(DispatchNotice::Alarm {
                    at: now,
                    name: FALLBACK_ALARM.into(),
                    active: false,
                    reason: "optimal dispatch restored".into(),
                });
                notices.push(DispatchNotice::Event {
                    at: now,
                    message: "dispatch back to optimal".into(),
                });
                self.alarm_active = false;
            }
            _ => {}
        }
        self.first = false;
        (st, notices)
    }

    /// Starts a new plan when none exists, the last is `resolve_s` old, or
    /// the diesel commitment changed since it was made; unless one is being
    /// solved already. It is solved on its own thread from what is measured
    /// now and adopted `adopt_after_s` later (the first plan at once).
    fn look_ahead(&mut self, measured: &DispatchProblem, now: Timestamp) {
        let Some(h) = self.cfg.horizon.as_ref() else {
            return;
        };
        if self.pending.is_some() {
            return;
        }
        let running: Vec<bool> = measured.oil.iter().map(|o| o.running).collect();
        let due = match &self.plan {
            None => true,
            Some(p) => {
                running != self.plan_running
                    || now < p.at
                    || now.since(p.at).as_secs_f64() >= *h.resolve_s.get_ref()
            }
        };
        if !due {
            return;
        }
        let adopt_at = match self.plan {
            None => now,
            Some(_) => now.add(std::time::Duration::from_secs_f64(h.adopt_after_s())),
        };
        let inputs = PlanInputs {
            cfg: self.cfg.clone(),
            now,
            measured: measured.clone(),
            initial_kw: self.last_setpoints.clone(),
            hours_in_state: self
                .diesels
                .iter()
                .map(|d| {
                    (
                        d.id.clone(),
                        now.since(d.since).as_secs_f64().max(0.0) / 3600.0,
                    )
                })
                .collect(),
        };
        self.pending = Some(PendingPlan {
            adopt_at,
            running,
            solve: PlanSolve::start(inputs),
        });
    }

    /// Adopts the plan being solved once its time has come, waiting for the
    /// solve to end if it has not: the thread blocks rather than lets plant
    /// time move, so the plan is used at the same plant time on every run.
    /// Events when planning starts failing and when it recovers.
    fn adopt_plan(&mut self, now: Timestamp, notices: &mut Vec<DispatchNotice>) {
        let Some(pending) = self.pending.take_if(|p| now >= p.adopt_at) else {
            return;
        };
        let new = pending.solve.finish();
        let was_ok = self.plan.as_ref().is_none_or(HorizonPlan::is_optimal);
        match (was_ok, new.is_optimal()) {
            (true, false) => {
                let r = new.reason.clone().unwrap_or_default();
                tracing::warn!("dispatch look-ahead failed: {r}");
                notices.push(DispatchNotice::Event {
                    at: now,
                    message: format!(
                        "dispatch look-ahead failed ({r}); stored energy priced at the fixed estimate"
                    ),
                });
            }
            (false, true) => notices.push(DispatchNotice::Event {
                at: now,
                message: "dispatch look-ahead planning again".into(),
            }),
            _ => {}
        }
        self.plan = Some(new);
        self.plan_running = pending.running;
    }

    /// What the plan says a stored kWh in `id` is worth, while the plan is
    /// optimal and no older than three re-plan intervals. Capped below the
    /// price of shedding: a shortfall the forecast only expects later never
    /// makes the dispatch shed now to save energy for it.
    fn planned_value(&self, id: &str, now: Timestamp) -> Option<f64> {
        let p = self.fresh_plan(now)?;
        let eff_d = self
            .cfg
            .units
            .iter()
            .find(|u| u.id.get_ref() == id)
            .map_or(1.0, |u| *u.eff_discharge.get_ref());
        let cap = 0.9 * self.cfg.voll_per_kwh * eff_d;
        p.stored_energy_value_per_kwh.get(id).map(|v| v.min(cap))
    }

    /// The last plan, while it is optimal and no older than three re-plan
    /// intervals: the one freshness rule for its prices and its commitment.
    fn fresh_plan(&self, now: Timestamp) -> Option<&HorizonPlan> {
        let h = self.cfg.horizon.as_ref()?;
        let p = self.plan.as_ref().filter(|p| p.is_optimal())?;
        let fresh = now >= p.at && now.since(p.at).as_secs_f64() <= 3.0 * *h.resolve_s.get_ref();
        fresh.then_some(p)
    }

    /// The single-period LP with each running diesel held at the plan's
    /// output for this period, so storage follows the plan's schedule
    /// (charging from a diesel run hard, then covering while it is off)
    /// rather than only its price, which leaves the battery idle wherever
    /// the price sits between charging and discharging. Storage and
    /// renewables take up what the forecast got wrong; where they cannot
    /// (the held output would shed load or has no feasible answer), the
    /// diesel is freed within its band again.
    fn solve_following_plan(
        &self,
        problem: &DispatchProblem,
        now: Timestamp,
    ) -> Result<super::single::DispatchSolution, DispatchError> {
        let fresh_plan = self.plan.as_ref().filter(|_| {
            self.diesels
                .iter()
                .any(|d| self.planned_run(&d.id, now).is_some())
        });
        if let Some(plan) = fresh_plan {
            let mut held = problem.clone();
            let mut any = false;
            for o in held.oil.iter_mut().filter(|o| o.running) {
                if let Some(kw) = plan.diesel_kw.get(&o.id).and_then(|v| v.first()) {
                    let kw = kw.clamp(o.min_kw, o.max_kw);
                    o.min_kw = kw;
                    o.max_kw = kw;
                    any = true;
                }
            }
            if any {
                if let Ok(sol) = held.solve() {
                    if sol.shed_kw <= 1e-6 {
                        return Ok(sol);
                    }
                }
            }
        }
        problem.solve()
    }

    /// Whether the plan runs diesel `id` now, while the plan is optimal and
    /// no older than three re-plan intervals.
    fn planned_run(&self, id: &str, now: Timestamp) -> Option<bool> {
        self.fresh_plan(now)?.runs_now(id)
    }

    fn apply_fallback(&self, problem: &DispatchProblem, st: &mut DispatchStatus) {
        let f = fallback_dispatch(problem);
        st.mode = DispatchMode::Fallback;
        st.setpoints_kw = f.setpoints_kw;
        st.shed_kw = f.shed_kw;
        st.objective = None;
    }

    async fn write_setpoints(&self, writer: &dyn TagWriter, sp: &Setpoints) -> Vec<String> {
        let mut failures = Vec::new();
        for u in &self.units {
            let Some(v) = sp.get(u.cfg.id.get_ref()) else {
                continue;
            };
            if let Err(e) = writer.write(&u.io.setpoint_kw, Value::Float(v)).await {
                failures.push(format!("{}: {e}", u.io.setpoint_kw));
            }
        }
        failures
    }
}
