//! The live outer loop of the microgrid cascade.
//!
//! **Owns:** every `dispatch_period_s` of plant time: reading demand,
//! availability, state of charge and running state from the tag database;
//! the diesel commitment rule; building and solving the single-period LP (the
//! same [`DispatchProblem::solve`] as `gridscada dispatch solve`); switching
//! to the rule-based fallback on stale or Bad measurements, a failed solve or
//! a failed write; writing each unit's setpoint and the diesels' run commands
//! through the `TagWriter`; publishing a [`DispatchStatus`] and emitting
//! [`DispatchNotice`]s (events, the "dispatch fallback" alarm).
//!
//! **Must not touch:** Modbus or any device directly (only `TagWriter`), the
//! alarm engine and the event store (it only sends notices), wall time (plant
//! time comes from the `Clock`). [`Dispatcher::step`] is one period without
//! sleeping, so tests drive it with a fake writer and tag database.

use std::collections::{BTreeMap, HashMap, VecDeque};
use std::sync::Arc;
use std::time::Duration;

use serde::Serialize;
use tokio::sync::{mpsc, watch};

use gridscada_config::{MicrogridConfig, UnitConfig, UnitIo, UnitKind};
use gridscada_tagdb::{Clock, TagDb, TagWriter, Timestamp, Value};

use super::lookahead::{horizon_problem, plan, HorizonPlan};
use super::rules::{commit_diesels, fallback_dispatch, DieselState};
use super::single::{DispatchProblem, OilUnit, RenewableUnit, StorageUnit};
use super::{DispatchError, Setpoints};

/// Name of the alarm raised while the loop runs on the fallback rule.
pub const FALLBACK_ALARM: &str = "dispatch fallback";

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum DispatchMode {
    /// Setpoints come from the LP.
    Optimal,
    /// Setpoints come from the rule (see `reason`).
    Fallback,
}

/// What the outer loop did in its last period; published on a watch channel
/// for the HMI.
#[derive(Debug, Clone, Serialize)]
pub struct DispatchStatus {
    /// Plant time of the period (0 before the first one).
    pub at: Timestamp,
    pub mode: DispatchMode,
    /// The solver's verdict: "optimal", "infeasible", "error", or "not solved"
    /// (inputs unusable) / "not run" (before the first period).
    pub status: String,
    /// Why the loop is in fallback (or why the solve failed).
    pub reason: Option<String>,
    /// The problem built from the measurements (in fallback: with substitutes).
    pub inputs: Option<DispatchProblem>,
    /// Setpoints written (or attempted), kW per unit id.
    pub setpoints_kw: Setpoints,
    /// Run command per diesel id.
    pub run_cmd: BTreeMap<String, bool>,
    pub shed_kw: f64,
    pub objective: Option<f64>,
    pub solve_ms: Option<f64>,
    /// Writes the field did not confirm in this period.
    pub write_failures: Vec<String>,
    /// The look-ahead plan in force (with `[microgrid.horizon]` only).
    pub horizon: Option<HorizonPlan>,
}

impl Default for DispatchStatus {
    fn default() -> Self {
        DispatchStatus {
            at: Timestamp::from_millis(0),
            mode: DispatchMode::Fallback,
            status: "not run".into(),
            reason: None,
            inputs: None,
            setpoints_kw: Setpoints::default(),
            run_cmd: BTreeMap::new(),
            shed_kw: 0.0,
            objective: None,
            solve_ms: None,
            write_failures: Vec::new(),
            horizon: None,
        }
    }
}

/// For the event log and the alarm engine.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "type", rename_all = "lowercase")]
pub enum DispatchNotice {
    /// A system event ("dispatch back to optimal", "dg1 start: ...").
    Event { at: Timestamp, message: String },
    /// Raise (`active`) or clear an alarm, e.g. [`FALLBACK_ALARM`].
    Alarm {
        at: Timestamp,
        name: String,
        active: bool,
        reason: String,
    },
}

/// Runs the outer loop until the task is dropped: one [`Dispatcher::step`]
/// every `dispatch_period_s` of plant time.
pub async fn run_dispatch(
    cfg: MicrogridConfig,
    db: Arc<TagDb>,
    writer: Arc<dyn TagWriter>,
    clock: Arc<dyn Clock>,
    status: watch::Sender<DispatchStatus>,
    notices: mpsc::Sender<DispatchNotice>,
) {
    run_dispatch_with(
        cfg,
        db,
        writer,
        clock,
        status,
        notices,
        DispatchPolicy::Optimal,
    )
    .await
}

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

/// [`run_dispatch`] with an explicit [`DispatchPolicy`].
pub async fn run_dispatch_with(
    cfg: MicrogridConfig,
    db: Arc<TagDb>,
    writer: Arc<dyn TagWriter>,
    clock: Arc<dyn Clock>,
    status: watch::Sender<DispatchStatus>,
    notices: mpsc::Sender<DispatchNotice>,
    policy: DispatchPolicy,
) {
    let period = Duration::from_secs_f64(period_s(&cfg));
    wait_for_first_reading(&cfg, &db, &*clock).await;
    let mut d = Dispatcher::new(cfg, clock.now()).with_policy(policy);
    // Notices the channel had no room for; sent first next period, never dropped.
    let mut backlog: VecDeque<DispatchNotice> = VecDeque::new();
    loop {
        let (st, out) = d.step(&db, &*writer, clock.now()).await;
        status.send_replace(st);
        backlog.extend(out);
        while let Some(n) = backlog.pop_front() {
            match notices.try_send(n) {
                Ok(()) => {}
                Err(mpsc::error::TrySendError::Full(n)) => {
                    tracing::warn!(
                        "dispatch notice channel full; {} notices wait",
                        backlog.len() + 1
                    );
                    backlog.push_front(n);
                    break;
                }
                Err(mpsc::error::TrySendError::Closed(_)) => {
                    backlog.clear();
                    break;
                }
            }
        }
        clock.sleep(period).await;
    }
}

/// What a kWh left in `unit` is worth to the single-period LP: the cheapest
/// diesel energy it will displace later, discounted by the round trip and a
/// margin. That makes storing a renewable surplus (or a running diesel's
/// minimum-load excess) worth more than curtailing it, while charging from a
/// diesel that could be turned down never pays (value·eff_c < diesel cost),
/// and discharging stays cheaper than starting the diesel. Without a diesel,
/// stored energy displaces shedding later: a small share of the value of
/// lost load.
fn stored_energy_value(mg: &MicrogridConfig, unit: &UnitConfig) -> f64 {
    const MARGIN: f64 = 0.9;
    let round_trip = *unit.eff_charge.get_ref() * *unit.eff_discharge.get_ref();
    let displaced = mg
        .units
        .iter()
        .filter(|u| u.kind == UnitKind::Diesel)
        .map(|u| u.cost_per_kwh)
        .fold(f64::INFINITY, f64::min);
    let displaced = if displaced.is_finite() {
        displaced
    } else {
        0.05 * mg.voll_per_kwh
    };
    (MARGIN * displaced * round_trip).max(0.0)
}

/// Lets the field I/O read the plant once before the first decision: acting
/// on "no value yet" would run the fallback (and start the diesel) on every
/// server start. Waits at most `stale_after_s`; after that, the loop runs
/// and the fallback handles whatever is still missing.
async fn wait_for_first_reading(cfg: &MicrogridConfig, db: &TagDb, clock: &dyn Clock) {
    let mut names = vec![cfg.demand_tag.get_ref().clone()];
    for u in &cfg.units {
        let io = u.io();
        names.extend(
            u.required_tags()
                .into_iter()
                .filter(|t| *t != io.setpoint_kw && *t != io.run_cmd),
        );
    }
    let ids: Vec<_> = names.iter().filter_map(|n| db.id(n)).collect();
    let give_up = clock
        .now()
        .add(Duration::from_secs_f64(cfg.stale_after_s.max(0.0)));
    while clock.now() < give_up {
        let read_once = ids
            .iter()
            .all(|id| db.get(*id).is_some_and(|s| s.timestamp.as_millis() > 0));
        if read_once {
            return;
        }
        clock.sleep(Duration::from_millis(100)).await;
    }
}

fn period_s(cfg: &MicrogridConfig) -> f64 {
    let p = *cfg.dispatch_period_s.get_ref();
    if p.is_finite() && p >= 0.1 {
        p
    } else {
        5.0
    }
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
    /// The last look-ahead plan (made every `resolve_s`), and which diesels
    /// ran when it was made.
    plan: Option<HorizonPlan>,
    plan_running: Vec<bool>,
    /// Setpoints the field accepted last period: where the plan's ramps start.
    last_setpoints: Setpoints,
}

/// One measurement: the value, or why it cannot be used.
type Meas = Result<f64, String>;

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
                cost_per_kwh: u.cfg.cost_per_kwh,
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
                        cost_per_kwh: cfg.cost_per_kwh,
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
        let soc_frac = (soc_known && cap_sum > 0.0).then(|| soc_sum / cap_sum);
        let mut commitment_changed = false;
        if let Some(dec) = commit_diesels(
            &self.cfg.commitment,
            now,
            problem.demand_kw - renewables,
            storage_cover,
            soc_frac,
            &self.diesels,
        ) {
            if let Some(d) = self.diesels.iter_mut().find(|d| d.id == dec.id) {
                d.run = dec.run;
                d.since = now;
            }
            commitment_changed = true;
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

        // Look ahead when a plan is due, and price stored energy with it.
        if self.policy == DispatchPolicy::Optimal && problems.is_empty() {
            self.look_ahead(&problem, now, commitment_changed, &mut notices);
        }
        // A running diesel stops only once the battery is charged (the
        // commitment rule, which the plan relaxes away), so while one runs a
        // stored kWh is worth at least the fixed estimate: storing surplus
        // then shortens the diesel's run.
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
            match problem.solve() {
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
            DispatchPolicy::Optimal => st.mode,
        };
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

    /// Makes a new plan when none exists, the last is `resolve_s` old, or the
    /// diesel commitment just changed; events when planning starts failing
    /// and when it recovers.
    fn look_ahead(
        &mut self,
        measured: &DispatchProblem,
        now: Timestamp,
        commitment_changed: bool,
        notices: &mut Vec<DispatchNotice>,
    ) {
        let Some(h) = self.cfg.horizon.clone() else {
            return;
        };
        let running: Vec<bool> = measured.oil.iter().map(|o| o.running).collect();
        let due = match &self.plan {
            None => true,
            Some(p) => {
                commitment_changed
                    || running != self.plan_running
                    || now < p.at
                    || now.since(p.at).as_secs_f64() >= *h.resolve_s.get_ref()
            }
        };
        if !due {
            return;
        }
        let cfg = &self.cfg;
        let terminal = |id: &str| {
            cfg.units
                .iter()
                .find(|u| u.id.get_ref() == id)
                .map_or(0.0, |u| stored_energy_value(cfg, u))
        };
        let problem = horizon_problem(cfg, &h, now, measured, &self.last_setpoints, &terminal);
        let new = plan(&problem, now);
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
        self.plan_running = running;
    }

    /// What the plan says a stored kWh in `id` is worth, while the plan is
    /// optimal and no older than three re-plan intervals. Capped below the
    /// price of shedding: a shortfall the forecast only expects later never
    /// makes the dispatch shed now to save energy for it.
    fn planned_value(&self, id: &str, now: Timestamp) -> Option<f64> {
        let h = self.cfg.horizon.as_ref()?;
        let p = self.plan.as_ref().filter(|p| p.is_optimal())?;
        let fresh = now >= p.at && now.since(p.at).as_secs_f64() <= 3.0 * *h.resolve_s.get_ref();
        let eff_d = self
            .cfg
            .units
            .iter()
            .find(|u| u.id.get_ref() == id)
            .map_or(1.0, |u| *u.eff_discharge.get_ref());
        let cap = 0.9 * self.cfg.voll_per_kwh * eff_d;
        fresh
            .then(|| p.stored_energy_value_per_kwh.get(id))
            .flatten()
            .map(|v| v.min(cap))
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

#[cfg(test)]
mod tests {
    use super::*;
    use gridscada_tagdb::{Quality, Sample, TagMeta, ValueKind, WriteError, WriteFuture};
    use std::sync::Mutex;

    const CFG: &str = r#"
dispatch_period_s = 5.0
voll_per_kwh = 5.0
demand_tag = "MG.Load.P_kW"
stale_after_s = 15.0

[commitment]
start_soc_frac = 0.25
stop_soc_frac = 0.6
min_run_s = 900.0
min_stop_s = 300.0

[[unit]]
id = "pv1"
kind = "pv"
name = "PV array"
prefix = "MG.PV1"
rated_kw = 100.0

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
cost_per_kwh = 0.35
"#;

    fn config() -> MicrogridConfig {
        toml::from_str(CFG).unwrap()
    }

    fn db(cfg: &MicrogridConfig) -> Arc<TagDb> {
        let mut metas = vec![TagMeta::new(
            cfg.demand_tag.get_ref().as_str(),
            ValueKind::Float,
        )];
        for u in &cfg.units {
            for t in u.required_tags() {
                let kind = if t.ends_with("Running") || t.ends_with("RunCmd") {
                    ValueKind::Bool
                } else {
                    ValueKind::Float
                };
                metas.push(TagMeta::new(t.as_str(), kind).writable(true));
            }
        }
        Arc::new(TagDb::new(metas).unwrap())
    }

    /// Confirms writes by storing them in the tag database; can fail one tag.
    struct FakeWriter {
        db: Arc<TagDb>,
        now: Mutex<Timestamp>,
        fail: Mutex<Option<String>>,
        log: Mutex<Vec<(String, Value)>>,
    }

    impl TagWriter for FakeWriter {
        fn write<'a>(&'a self, name: &'a str, value: Value) -> WriteFuture<'a> {
            Box::pin(async move {
                if self.fail.lock().unwrap().as_deref() == Some(name) {
                    return Err(WriteError::Timeout(name.to_string()));
                }
                let id = self
                    .db
                    .id(name)
                    .ok_or_else(|| WriteError::UnknownTag(name.into()))?;
                let s = Sample {
                    value: value.clone(),
                    quality: Quality::GOOD,
                    timestamp: *self.now.lock().unwrap(),
                };
                self.db.apply([(id, s.clone())]);
                self.log.lock().unwrap().push((name.to_string(), value));
                Ok(s)
            })
        }
    }

    fn set(db: &TagDb, name: &str, v: impl Into<Value>, at: Timestamp) {
        db.set(db.id(name).unwrap(), v, Quality::GOOD, at);
    }

    fn plant(db: &TagDb, at: Timestamp, demand: f64, pv: f64, soc: f64, running: bool) {
        set(db, "MG.Load.P_kW", demand, at);
        set(db, "MG.PV1.Available_kW", pv, at);
        set(db, "MG.BESS1.SoC_kWh", soc, at);
        set(db, "MG.DG1.Running", running, at);
    }

    fn written(w: &FakeWriter, tag: &str) -> Option<Value> {
        w.log
            .lock()
            .unwrap()
            .iter()
            .rev()
            .find(|(n, _)| n == tag)
            .map(|(_, v)| v.clone())
    }

    fn fake_writer(db: &Arc<TagDb>, now: Timestamp) -> FakeWriter {
        FakeWriter {
            db: db.clone(),
            now: Mutex::new(now),
            fail: Mutex::new(None),
            log: Mutex::new(Vec::new()),
        }
    }

    fn fixture() -> (MicrogridConfig, Arc<TagDb>, FakeWriter) {
        let cfg = config();
        let db = db(&cfg);
        let w = fake_writer(&db, Timestamp::from_millis(0));
        (cfg, db, w)
    }

    #[tokio::test]
    async fn optimal_period_writes_balanced_setpoints() {
        let (cfg, db, w) = fixture();
        let now = Timestamp::from_millis(1_000_000);
        plant(&db, now, 150.0, 60.0, 100.0, true);
        let mut d = Dispatcher::new(cfg, now);
        let (st, notices) = d.step(&db, &w, now).await;
        assert_eq!(st.mode, DispatchMode::Optimal, "{:?}", st.reason);
        assert_eq!(st.status, "optimal");
        // PV 60, battery 60, diesel 30.
        assert_eq!(
            written(&w, "MG.PV1.Setpoint_kW")
                .and_then(|v| v.as_f64())
                .map(|v| v.round()),
            Some(60.0)
        );
        assert_eq!(
            written(&w, "MG.BESS1.Setpoint_kW")
                .and_then(|v| v.as_f64())
                .map(|v| v.round()),
            Some(60.0)
        );
        assert_eq!(
            written(&w, "MG.DG1.Setpoint_kW")
                .and_then(|v| v.as_f64())
                .map(|v| v.round()),
            Some(30.0)
        );
        assert_eq!(written(&w, "MG.DG1.RunCmd"), Some(Value::Bool(true)));
        let total: f64 = st.setpoints_kw.0.iter().map(|(_, v)| v).sum::<f64>() + st.shed_kw;
        assert!((total - 150.0).abs() < 1e-6);
        assert!(notices
            .iter()
            .all(|n| !matches!(n, DispatchNotice::Alarm { .. })));
        serde_json::to_string(&st).unwrap();
    }

    #[tokio::test]
    async fn stale_or_bad_measurements_fall_back_and_raise_then_clear_the_alarm() {
        let (cfg, db, w) = fixture();
        let t0 = Timestamp::from_millis(1_000_000);
        plant(&db, t0, 150.0, 60.0, 100.0, true);
        let mut d = Dispatcher::new(cfg, t0);
        d.step(&db, &w, t0).await;
        // 20 s later nothing was refreshed: stale.
        let t1 = t0.add(Duration::from_secs(20));
        let (st, notices) = d.step(&db, &w, t1).await;
        assert_eq!(st.mode, DispatchMode::Fallback);
        assert!(
            st.reason.as_deref().unwrap().contains("stale"),
            "{:?}",
            st.reason
        );
        assert!(notices.iter().any(|n| matches!(n, DispatchNotice::Alarm { active: true, name, .. } if name == FALLBACK_ALARM)));
        // Fallback still writes sane, balanced setpoints from the held values.
        let total: f64 = st.setpoints_kw.0.iter().map(|(_, v)| v).sum::<f64>() + st.shed_kw;
        assert!((total - 150.0).abs() < 1e-6);
        // A Bad quality demand also falls back (alarm already active: no new raise).
        plant(&db, t1, 150.0, 60.0, 100.0, true);
        db.set(
            db.id("MG.Load.P_kW").unwrap(),
            150.0,
            Quality::bad("comm failure"),
            t1,
        );
        let (st, notices) = d.step(&db, &w, t1).await;
        assert_eq!(st.mode, DispatchMode::Fallback);
        assert!(st.reason.as_deref().unwrap().contains("Bad"));
        assert!(notices.is_empty());
        // Fresh and good again: optimal, alarm cleared.
        plant(&db, t1, 150.0, 60.0, 100.0, true);
        let (st, notices) = d.step(&db, &w, t1).await;
        assert_eq!(st.mode, DispatchMode::Optimal);
        assert!(notices
            .iter()
            .any(|n| matches!(n, DispatchNotice::Alarm { active: false, .. })));
    }

    /// The fixture's plant with a look-ahead whose demand curve is `demand`.
    fn with_horizon(demand: &str) -> MicrogridConfig {
        toml::from_str(&format!(
            "{CFG}\n[horizon]\nperiods = 16\nperiod_s = 900.0\nresolve_s = 60.0\n\
             blend_h = 2.0\ndemand_forecast_kw = {demand}\n"
        ))
        .unwrap()
    }

    const FIVE_PM: i64 = 17 * 3_600_000;

    #[tokio::test]
    async fn look_ahead_charges_from_the_running_diesel_before_an_evening_peak() {
        // 17:00, diesel running, 60 kW demand, no sun, battery at 40 kWh.
        // The forecast peak of 200 kW at 19:00-20:00 exceeds the diesel's
        // 150 kW plus what 40 kWh can give: energy stored now averts shedding.
        let peak = "[[0, 60], [17, 60], [18.5, 200], [20.5, 200], [21, 60]]";
        let now = Timestamp::from_millis(FIVE_PM);
        let run = |cfg: MicrogridConfig| async move {
            let db = db(&cfg);
            let w = fake_writer(&db, now);
            plant(&db, now, 60.0, 0.0, 40.0, true);
            let mut d = Dispatcher::new(cfg, now);
            d.step(&db, &w, now).await
        };
        let (ahead, notices) = run(with_horizon(peak)).await;
        assert_eq!(ahead.mode, DispatchMode::Optimal, "{:?}", ahead.reason);
        let plan = ahead.horizon.as_ref().expect("a plan");
        assert_eq!(plan.status, "optimal", "{:?}", plan.reason);
        assert_eq!(plan.periods, 16);
        assert_eq!(plan.demand_kw[0], 60.0);
        assert!(
            plan.demand_kw.iter().any(|d| *d > 190.0),
            "{:?}",
            plan.demand_kw
        );
        let value = plan.stored_energy_value_per_kwh.get("bess1").unwrap();
        assert!(value > 1.0, "stored energy averts shedding: {value}");
        // The dispatch priced stored energy at the plan's value (capped) and
        // charges the battery from the diesel at full rate.
        let priced = ahead.inputs.as_ref().unwrap().storage[0].stored_value_per_kwh;
        assert!((priced - value.min(0.9 * 5.0 * 0.95)).abs() < 1e-9);
        let bess = ahead.setpoints_kw.get("bess1").unwrap();
        let dg = ahead.setpoints_kw.get("dg1").unwrap();
        assert!(
            (bess + 50.0).abs() < 1e-3,
            "battery charges at 50 kW: {bess}"
        );
        assert!((dg - 110.0).abs() < 1e-3, "diesel 60 + 50 kW: {dg}");
        assert!(notices
            .iter()
            .all(|n| !matches!(n, DispatchNotice::Alarm { .. })));
        // Without the look-ahead the same moment discharges the battery to
        // the diesel's minimum load instead.
        let (alone, _) = run(config()).await;
        assert!(alone.horizon.is_none());
        assert!(alone.setpoints_kw.get("bess1").unwrap() > 0.0, "{alone:?}");
    }

    #[tokio::test]
    async fn the_plan_is_renewed_every_resolve_interval_and_a_failed_one_is_reported() {
        // The diesel just restarted (held on by its minimum run time) meets
        // 10 kW of demand, and the battery is all but full. This 5 s period
        // can store the excess; a 15-minute look-ahead period cannot, so no
        // plan exists.
        let cfg = with_horizon("[[0, 60]]");
        let db = db(&cfg);
        let t0 = Timestamp::from_millis(FIVE_PM);
        let w = fake_writer(&db, t0);
        plant(&db, t0, 10.0, 0.0, 189.9, true);
        let mut d = Dispatcher::new(cfg, t0);
        let (st, notices) = d.step(&db, &w, t0).await;
        let plan = st.horizon.as_ref().unwrap();
        assert_eq!(plan.status, "infeasible", "{plan:?}");
        assert!(notices.iter().any(|n| matches!(n,
            DispatchNotice::Event { message, .. } if message.contains("look-ahead failed"))));
        // The dispatch itself goes on, optimal, with the fixed estimate.
        assert_eq!(st.mode, DispatchMode::Optimal, "{:?}", st.reason);
        let fixed = stored_energy_value(&d.cfg, &d.cfg.units[1]);
        assert_eq!(
            st.inputs.as_ref().unwrap().storage[0].stored_value_per_kwh,
            fixed
        );
        // 5 s later: no new plan yet, no repeated event.
        let t1 = t0.add(Duration::from_secs(5));
        plant(&db, t1, 10.0, 0.0, 189.9, true);
        let (st, notices) = d.step(&db, &w, t1).await;
        assert_eq!(st.horizon.as_ref().unwrap().at, t0);
        assert!(notices.is_empty(), "{notices:?}");
        // A minute on, demand is back: planned again, and said so.
        let t2 = t0.add(Duration::from_secs(60));
        plant(&db, t2, 60.0, 0.0, 20.0, true);
        let (st, notices) = d.step(&db, &w, t2).await;
        let plan = st.horizon.as_ref().unwrap();
        assert_eq!((plan.at, plan.status.as_str()), (t2, "optimal"), "{plan:?}");
        assert!(notices.iter().any(|n| matches!(n,
            DispatchNotice::Event { message, .. } if message.contains("planning again"))));
    }

    #[tokio::test]
    async fn failed_write_switches_to_the_rule() {
        let (cfg, db, w) = fixture();
        let now = Timestamp::from_millis(1_000_000);
        plant(&db, now, 150.0, 60.0, 100.0, true);
        *w.fail.lock().unwrap() = Some("MG.BESS1.Setpoint_kW".into());
        let mut d = Dispatcher::new(cfg, now);
        let (st, notices) = d.step(&db, &w, now).await;
        assert_eq!(st.mode, DispatchMode::Fallback);
        assert!(st
            .reason
            .as_deref()
            .unwrap()
            .contains("MG.BESS1.Setpoint_kW"));
        assert!(!st.write_failures.is_empty());
        assert!(notices
            .iter()
            .any(|n| matches!(n, DispatchNotice::Alarm { active: true, .. })));
        // The other units still got setpoints.
        assert!(written(&w, "MG.PV1.Setpoint_kW").is_some());
        assert!(written(&w, "MG.DG1.Setpoint_kW").is_some());
    }

    #[tokio::test]
    async fn diesel_is_started_by_the_rule_and_only_loaded_once_running() {
        let (cfg, db, w) = fixture();
        let now = Timestamp::from_millis(1_000_000);
        // Net load 200 - 20 = 180 kW, far beyond the battery: start dg1.
        plant(&db, now, 200.0, 20.0, 100.0, false);
        let mut d = Dispatcher::new(cfg, now);
        let (st, notices) = d.step(&db, &w, now).await;
        assert_eq!(written(&w, "MG.DG1.RunCmd"), Some(Value::Bool(true)));
        assert!(notices.iter().any(
            |n| matches!(n, DispatchNotice::Event { message, .. } if message.contains("dg1 start"))
        ));
        // Not yet running: zero setpoint and the deficit is shed.
        assert_eq!(st.setpoints_kw.get("dg1"), Some(0.0));
        assert!(st.shed_kw > 100.0);
        // Next period it reports running: loaded.
        let t1 = now.add(Duration::from_secs(5));
        plant(&db, t1, 200.0, 20.0, 100.0, true);
        let (st, _) = d.step(&db, &w, t1).await;
        assert!(st.setpoints_kw.get("dg1").unwrap() > 100.0);
        assert!(st.shed_kw < 1e-6);
    }

    #[tokio::test]
    async fn rule_policy_never_solves_and_raises_no_alarm() {
        let (cfg, db, w) = fixture();
        let now = Timestamp::from_millis(1_000_000);
        plant(&db, now, 150.0, 60.0, 100.0, true);
        let mut d = Dispatcher::new(cfg, now).with_policy(DispatchPolicy::Rule);
        let (st, notices) = d.step(&db, &w, now).await;
        assert_eq!(st.status, "rule");
        assert_eq!(st.mode, DispatchMode::Fallback);
        assert!(st.objective.is_none());
        assert!(st.reason.is_none(), "{:?}", st.reason);
        assert!(notices
            .iter()
            .all(|n| !matches!(n, DispatchNotice::Alarm { .. })));
        let total: f64 = st.setpoints_kw.0.iter().map(|(_, v)| v).sum::<f64>() + st.shed_kw;
        assert!((total - 150.0).abs() < 1e-6);
    }

    /// A plant clock for the loop: sleeping advances plant time at once.
    struct StepClock(Mutex<Timestamp>);
    impl Clock for StepClock {
        fn now(&self) -> Timestamp {
            *self.0.lock().unwrap()
        }
        fn sleep(
            &self,
            d: Duration,
        ) -> std::pin::Pin<Box<dyn std::future::Future<Output = ()> + Send>> {
            let mut t = self.0.lock().unwrap();
            *t = t.add(d);
            Box::pin(tokio::task::yield_now())
        }
    }

    #[tokio::test]
    async fn run_dispatch_publishes_status_and_notices() {
        let (cfg, db, w) = fixture();
        // Stale measurements at start: a fallback alarm must arrive.
        plant(&db, Timestamp::from_millis(0), 150.0, 60.0, 100.0, true);
        let clock = Arc::new(StepClock(Mutex::new(Timestamp::from_millis(1_000_000))));
        let (stx, mut srx) = watch::channel(DispatchStatus::default());
        let (ntx, mut nrx) = mpsc::channel(16);
        let task = tokio::spawn(run_dispatch(cfg, db.clone(), Arc::new(w), clock, stx, ntx));
        loop {
            let n = nrx.recv().await.unwrap();
            if let DispatchNotice::Alarm {
                active,
                name,
                reason,
                ..
            } = n
            {
                assert!(
                    active && name == FALLBACK_ALARM && reason.contains("stale"),
                    "{reason}"
                );
                break;
            }
        }
        srx.changed().await.unwrap();
        assert_eq!(srx.borrow().mode, DispatchMode::Fallback);
        task.abort();
    }
}
