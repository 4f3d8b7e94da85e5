//! `gridscada replay` and `gridscada demo --scenario`: runs a scenario
//! (`gridscada_sim::scenario`) through the whole stack — simulators, the
//! poller over real Modbus on loopback, alarms, historian, fault isolation
//! and dispatch — on a compressed clock, and reports what happened.
//!
//! **Owns:** the replay clocks ([`VirtualClock`] for `--max`, a floored
//! scaled clock for `--speed`), driving the scenario's profiles, events and
//! expectations against a running [`Stack`], measuring the report's figures,
//! the rule-based baseline run, and the progress line.
//!
//! **Must not touch:** control decisions or plant physics: it only acts as
//! the operator and the weather would (simulator inputs, panel commands,
//! acknowledgements) and reads what the SCADA and the simulator show.

use std::collections::BTreeMap;
use std::io::{IsTerminal, Write};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, AtomicI64, Ordering};
use std::sync::{Arc, Mutex, OnceLock};
use std::task::{Poll, Waker};
use std::time::{Duration, Instant};

use anyhow::{anyhow, Context};
use gridscada_config::{Plant, UnitKind};
use gridscada_control::dispatch::{DispatchMode, DispatchPolicy, DispatchStatus};
use gridscada_control::fault_isolation::{PanelCommand, PanelCommandKind, PanelStatus};
use gridscada_sim::scenario::expect::ExpectationResult;
use gridscada_sim::scenario::report::{
    AlarmSummary, CostBreakdown, CostComparison, FaultRecord, Line, Plot, Report, TimelineEntry,
};
use gridscada_sim::scenario::{self, Action, Scenario};
use gridscada_sim::{Profile, SimHandle, SimSnapshot, ZoneLoad};
use gridscada_tagdb::{Clock, ScaledClock, SleepFuture, Timestamp};
use tokio::sync::oneshot;

use crate::data::open_store;
use crate::runtime::{LiveDriver, Stack, StackOptions};
use crate::{demo_plant, sinks};

// ----- Clocks ------------------------------------------------------------------

/// A plant clock that moves only when the whole stack is idle: `--max`.
///
/// Runs on a current-thread runtime whose park hook calls
/// [`VirtualClock::on_idle`]. The runtime parks only when no task can run;
/// if then no Modbus transaction is in flight (the poller's gauge), nothing
/// can happen until plant time moves, so the clock jumps to the earliest
/// sleeper's deadline and wakes it. Every scan, timer, dispatch period and
/// simulator step therefore happens at its exact plant time, in the same
/// order on every run, and the replay goes as fast as the CPU allows.
///
/// A request to a device that does not answer waits a short wall-time
/// timeout ([`VirtualClock::to_wall`]) and costs no plant time.
pub struct VirtualClock {
    now_ms: AtomicI64,
    timers: Mutex<Timers>,
    /// Set once the stack is up: how many transport operations are in flight.
    busy: OnceLock<Box<dyn Fn() -> u64 + Send + Sync>>,
    frozen: AtomicBool,
}

#[derive(Default)]
struct Timers {
    next_seq: u64,
    /// (deadline ms, registration order) -> waker slot.
    pending: BTreeMap<(i64, u64), Arc<Mutex<SleepSlot>>>,
}

#[derive(Default)]
struct SleepSlot {
    done: bool,
    waker: Option<Waker>,
}

/// Wall-time ceiling of a Modbus timeout under the virtual clock: loopback
/// answers come in microseconds, so this only bounds what a silent device
/// costs; it stays well above scheduling hiccups of a loaded machine, where
/// a spurious timeout would make the run differ from the last.
const VIRTUAL_TIMEOUT_CAP: Duration = Duration::from_millis(250);

impl VirtualClock {
    pub fn new(start: Timestamp) -> Arc<Self> {
        Arc::new(VirtualClock {
            now_ms: AtomicI64::new(start.as_millis()),
            timers: Mutex::new(Timers::default()),
            busy: OnceLock::new(),
            frozen: AtomicBool::new(false),
        })
    }

    /// Lets plant time move, given the poller's in-flight gauge.
    pub fn start(&self, busy: impl Fn() -> u64 + Send + Sync + 'static) {
        let _ = self.busy.set(Box::new(busy));
    }

    /// Stops plant time (while the run's records are collected).
    pub fn freeze(&self) {
        self.frozen.store(true, Ordering::SeqCst);
    }

    /// The runtime has nothing to run: advance to the next deadline.
    pub fn on_idle(&self) {
        if self.frozen.load(Ordering::SeqCst) {
            return;
        }
        let Some(busy) = self.busy.get() else { return };
        if busy() > 0 {
            return;
        }
        let mut wake = Vec::new();
        {
            let mut t = self.timers.lock().unwrap_or_else(|e| e.into_inner());
            // Forget sleeps whose futures were dropped.
            t.pending.retain(|_, s| Arc::strong_count(s) > 1);
            let Some((&(deadline, _), _)) = t.pending.iter().next() else {
                return;
            };
            let now = self.now_ms.load(Ordering::SeqCst).max(deadline);
            self.now_ms.store(now, Ordering::SeqCst);
            while let Some(entry) = t.pending.first_entry() {
                if entry.key().0 > now {
                    break;
                }
                wake.push(entry.remove());
            }
        }
        for slot in wake {
            let mut s = slot.lock().unwrap_or_else(|e| e.into_inner());
            s.done = true;
            if let Some(w) = s.waker.take() {
                w.wake();
            }
        }
    }
}

impl Clock for VirtualClock {
    fn now(&self) -> Timestamp {
        Timestamp::from_millis(self.now_ms.load(Ordering::SeqCst))
    }

    fn sleep(&self, d: Duration) -> SleepFuture {
        let slot = Arc::new(Mutex::new(SleepSlot::default()));
        if d.is_zero() {
            slot.lock().unwrap_or_else(|e| e.into_inner()).done = true;
        } else {
            let deadline = self
                .now_ms
                .load(Ordering::SeqCst)
                .saturating_add(d.as_millis().max(1) as i64);
            let mut t = self.timers.lock().unwrap_or_else(|e| e.into_inner());
            let seq = t.next_seq;
            t.next_seq += 1;
            t.pending.insert((deadline, seq), slot.clone());
        }
        Box::pin(std::future::poll_fn(move |cx| {
            let mut s = slot.lock().unwrap_or_else(|e| e.into_inner());
            if s.done {
                Poll::Ready(())
            } else {
                s.waker = Some(cx.waker().clone());
                Poll::Pending
            }
        }))
    }

    /// Plant time does not move while a request is in flight, so timeouts
    /// only need to bound how long a silent device holds the replay.
    fn to_wall(&self, d: Duration) -> Duration {
        d.min(VIRTUAL_TIMEOUT_CAP)
    }
}

/// A scaled clock whose Modbus timeouts never shrink below what loopback
/// needs under load (at ×700 a 300 ms timeout would be 0.4 ms of wall time).
struct FlooredClock(ScaledClock);

/// Least wall time a request timeout is given under `--speed`.
const SCALED_TIMEOUT_FLOOR: Duration = Duration::from_millis(25);

impl Clock for FlooredClock {
    fn now(&self) -> Timestamp {
        self.0.now()
    }
    fn sleep(&self, d: Duration) -> SleepFuture {
        self.0.sleep(d)
    }
    fn speed(&self) -> f64 {
        self.0.speed()
    }
    fn to_wall(&self, d: Duration) -> Duration {
        self.0.to_wall(d).max(SCALED_TIMEOUT_FLOOR.min(d))
    }
}

/// How plant time runs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Pace {
    /// As fast as the stack can go, on the [`VirtualClock`].
    Max,
    /// `speed` plant seconds per wall second.
    Scaled(f64),
}

impl Pace {
    fn label(self) -> String {
        match self {
            Pace::Max => "virtual (--max): plant time advances when the stack is idle".into(),
            Pace::Scaled(s) => format!("scaled ×{s}"),
        }
    }
}

// ----- The command ---------------------------------------------------------------

/// Options of `gridscada replay`.
pub struct ReplayArgs {
    pub file: PathBuf,
    pub pace: Pace,
    pub report: Option<PathBuf>,
    pub html: Option<PathBuf>,
    /// Keep the main run's database here instead of a temporary folder.
    pub data: Option<PathBuf>,
    /// Skip the rule-based baseline run.
    pub no_compare: bool,
}

/// Loads a scenario and its plant and checks one against the other.
pub fn load(file: &Path) -> anyhow::Result<(Scenario, Plant)> {
    let diags = |d: Vec<gridscada_config::Diagnostic>| {
        let lines: Vec<String> = d.iter().map(|d| d.to_string()).collect();
        anyhow!("{}\n{} problem(s) found", lines.join("\n"), d.len())
    };
    let scn = scenario::load_path(file).map_err(diags)?;
    let plant = match &scn.plant {
        Some(p) => gridscada_config::load_path(p).map_err(diags)?,
        None => demo_plant::load().map_err(diags)?,
    };
    let names: std::collections::HashSet<String> = crate::runtime::all_tags(&plant)
        .into_iter()
        .map(|t| t.name.to_string())
        .collect();
    let problems = scn.check_against(&plant, &|n| names.contains(n));
    if !problems.is_empty() {
        return Err(diags(problems));
    }
    Ok((scn, plant))
}

/// `gridscada replay FILE ...`. Exit 0 when every expectation holds, 1 when
/// one fails, 2 when the scenario cannot be read or run.
pub fn replay(args: ReplayArgs) -> ExitCode {
    let (scn, plant) = match load(&args.file) {
        Ok(x) => x,
        Err(e) => {
            eprintln!("{e:#}");
            return ExitCode::from(2);
        }
    };
    match replay_checked(&scn, &plant, &args) {
        Ok(report) => {
            print_summary(&report);
            if report.passed {
                ExitCode::SUCCESS
            } else {
                ExitCode::from(1)
            }
        }
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
    }
}

fn replay_checked(scn: &Scenario, plant: &Plant, args: &ReplayArgs) -> anyhow::Result<Report> {
    let main = run_once(
        scn,
        plant,
        args.pace,
        DispatchPolicy::Optimal,
        args.data.as_deref(),
        "replay",
    )?;
    let rule = if scn.compare_rule && !args.no_compare && plant.microgrid.is_some() {
        Some(run_once(
            scn,
            plant,
            args.pace,
            DispatchPolicy::Rule,
            None,
            "rule baseline",
        )?)
    } else {
        None
    };
    let report = build_report(scn, plant, args.pace, main, rule);
    if let Some(path) = &args.report {
        let json = serde_json::to_string_pretty(&report).context("encoding the report")?;
        std::fs::write(path, json).with_context(|| format!("writing {}", path.display()))?;
    }
    if let Some(path) = &args.html {
        std::fs::write(path, scenario::html::render(&report))
            .with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(report)
}

fn print_summary(r: &Report) {
    for e in &r.expectations {
        println!(
            "  {} line {:>3}: {} (expected {}, got {}){}",
            match (e.passed, &e.known_failure) {
                (true, _) => "pass",
                (false, Some(_)) => "KNOWN",
                (false, None) => "FAIL",
            },
            e.line,
            e.description,
            e.expected,
            e.actual,
            match (&e.known_failure, e.passed) {
                (Some(why), false) => format!(" — known failure: {why}"),
                (Some(_), true) => " — listed as a known failure but passes now".to_string(),
                _ => String::new(),
            }
        );
    }
    let f = |k: &str| r.figures.get(k).copied().unwrap_or(f64::NAN);
    println!(
        "{}: {} — {}/{} expectations met; {:.0} s of plant time in {:.1} s (×{:.0}); unserved {:.2} kWh, total cost {:.2}{}",
        r.file,
        if r.passed { "PASSED" } else { "FAILED" },
        r.expectations.iter().filter(|e| e.passed).count(),
        r.expectations.len(),
        r.duration_s,
        r.wall_s,
        r.speedup,
        f("unserved_kwh"),
        f("total_cost"),
        match r.cost.ratio {
            Some(x) => format!(" (×{x:.3} of the rule-based dispatch)"),
            None => String::new(),
        }
    );
}

// ----- One run -------------------------------------------------------------------

/// What one run measured.
struct RunOutcome {
    wall: Duration,
    baseline: SimSnapshot,
    end: SimSnapshot,
    soc_min_pct: f64,
    faults: Vec<FaultRecord>,
    results: Vec<ExpectationResult>,
    timeline: Vec<TimelineEntry>,
    plots: Vec<Plot>,
    shed_kwh: f64,
    fallback_periods: u64,
    alarms: AlarmSummary,
    panel_end: Vec<PanelStatus>,
    poll_timeouts: u64,
    historian_dropped: u64,
}

fn run_once(
    scn: &Scenario,
    plant: &Plant,
    pace: Pace,
    policy: DispatchPolicy,
    data: Option<&Path>,
    label: &str,
) -> anyhow::Result<RunOutcome> {
    let tmp;
    let data = match data {
        Some(d) => d.to_path_buf(),
        None => {
            tmp = tempfile::tempdir().context("creating a temporary data folder")?;
            tmp.path().to_path_buf()
        }
    };
    match pace {
        Pace::Max => {
            let clock = VirtualClock::new(clock_start(scn));
            let hook = clock.clone();
            let rt = tokio::runtime::Builder::new_current_thread()
                .enable_all()
                .on_thread_park(move || hook.on_idle())
                .build()
                .context("starting the replay runtime")?;
            rt.block_on(run_stack(
                scn,
                plant,
                clock.clone(),
                Some(clock),
                policy,
                &data,
                label,
            ))
        }
        Pace::Scaled(speed) => {
            let rt = tokio::runtime::Builder::new_multi_thread()
                .enable_all()
                .build()
                .context("starting the replay runtime")?;
            let clock: Arc<dyn Clock> =
                Arc::new(FlooredClock(ScaledClock::new(clock_start(scn), speed)));
            rt.block_on(run_stack(scn, plant, clock, None, policy, &data, label))
        }
    }
}

/// Plant time when the stack starts: the warm-up before the scenario's start.
fn clock_start(scn: &Scenario) -> Timestamp {
    Timestamp::from_millis(scn.start.as_millis() - scn.warmup.as_millis() as i64)
}

async fn run_stack(
    scn: &Scenario,
    plant: &Plant,
    clock: Arc<dyn Clock>,
    virt: Option<Arc<VirtualClock>>,
    policy: DispatchPolicy,
    data: &Path,
    label: &str,
) -> anyhow::Result<RunOutcome> {
    let store = open_store(plant, data).await?;
    let stack = Stack::start(
        plant.clone(),
        store,
        StackOptions {
            clock: clock.clone(),
            simulate: true,
            dispatch_policy: policy,
            restore_panels: false,
        },
    )
    .await?;
    if let Some(v) = &virt {
        let stats = stack.poll_stats();
        v.start(move || stats.in_flight());
    }
    let wall = Instant::now();
    let driven = drive(&stack, scn, Progress::new(label, scn)).await;
    let wall = wall.elapsed();
    if let Some(v) = &virt {
        v.freeze();
    }
    let result = match driven {
        Ok(d) => finish(&stack, scn, d, wall).await,
        Err(e) => Err(e),
    };
    stack.shutdown().await;
    result
}

/// What [`drive`] collected while the scenario ran.
struct Driven {
    baseline: SimSnapshot,
    soc_min_pct: f64,
    results: Vec<ExpectationResult>,
    actions: Vec<TimelineEntry>,
    plots: Vec<Plot>,
    faults: Arc<Mutex<Vec<FaultRecord>>>,
    dispatch: Arc<Mutex<DispatchTally>>,
}

#[derive(Default)]
struct DispatchTally {
    shed_kwh: f64,
    fallback_periods: u64,
    last_at: Option<Timestamp>,
}

/// Runs the scenario's timeline against a running stack: the initial state,
/// then every step (or event, or expectation) in plant time.
async fn drive(stack: &Stack, scn: &Scenario, mut progress: Progress) -> anyhow::Result<Driven> {
    let sim = stack
        .simulator
        .as_ref()
        .map(|s| s.handle())
        .ok_or_else(|| anyhow!("replay needs the simulated plant"))?;
    let clock = stack.clock.clone();
    let start = scn.start;
    let offset = |c: &dyn Clock| c.now().since(start);

    // Sequence records, from every change of each panel's status.
    let faults = Arc::new(Mutex::new(Vec::new()));
    for p in &stack.panels {
        let mut rx = p.status.clone();
        let faults = faults.clone();
        let clock = clock.clone();
        tokio::spawn(async move {
            let mut last = rx.borrow_and_update().last_sequence.clone();
            while rx.changed().await.is_ok() {
                let st = rx.borrow_and_update().clone();
                let m = &st.last_sequence;
                let finished = !matches!(
                    m.outcome,
                    gridscada_control::fault_isolation::Outcome::None
                        | gridscada_control::fault_isolation::Outcome::Running
                );
                if *m != last && finished {
                    faults
                        .lock()
                        .unwrap_or_else(|e| e.into_inner())
                        .push(FaultRecord {
                            panel: st.id.clone(),
                            at_s: clock.now().since(start).as_secs_f64(),
                            outcome: serde_json::to_value(m.outcome)
                                .ok()
                                .and_then(|v| v.as_str().map(str::to_owned))
                                .unwrap_or_default(),
                            restore_s: m.restore_s,
                            bound_s: m.bound_s,
                            switching_ops: m.switching_ops,
                            reenergisations: m.reenergisations,
                            trips: m.trips,
                            elcb_resets: m.elcb_resets,
                        });
                }
                last = m.clone();
            }
        });
    }
    // Shed energy and fallback periods, from every dispatch period.
    let dispatch = Arc::new(Mutex::new(DispatchTally::default()));
    if let Some(rx) = &stack.dispatch {
        let mut rx = rx.clone();
        let tally = dispatch.clone();
        let period = stack
            .plant
            .microgrid
            .as_ref()
            .map(|m| *m.dispatch_period_s.get_ref())
            .unwrap_or(5.0);
        tokio::spawn(async move {
            while rx.changed().await.is_ok() {
                let st = rx.borrow_and_update().clone();
                let mut t = tally.lock().unwrap_or_else(|e| e.into_inner());
                if t.last_at == Some(st.at) || st.status == "not run" {
                    continue;
                }
                t.last_at = Some(st.at);
                t.shed_kwh += st.shed_kw * period / 3600.0;
                if st.mode == DispatchMode::Fallback && st.status != "rule" {
                    t.fallback_periods += 1;
                }
            }
        });
    }

    let operator = Operator::of(stack, &sim);
    operator.initial(scn).await?;
    Inputs::at(scn, Duration::ZERO).apply(&sim, &stack.plant)?;
    let settle = start.since(clock.now());
    if !settle.is_zero() {
        clock.sleep(settle).await;
    }
    let baseline = sim.snapshot();

    let mut actions = Vec::new();
    let mut results = Vec::new();
    let mut sampler = Sampler::new(&baseline, stack.dispatch.is_some());
    let mut soc_min = f64::INFINITY;
    let mut next_event = 0usize;
    let mut expects: Vec<usize> = (0..scn.expectations.len())
        .filter(|&i| scn.expectations[i].due().is_some())
        .collect();
    expects.sort_by_key(|&i| scn.expectations[i].due());
    let mut next_expect = 0usize;
    let mut next_step = Duration::ZERO;
    let mut next_sample = Duration::ZERO;
    let mut last_inputs: Option<Inputs> = None;

    loop {
        let now = offset(&*clock);
        // Expectations due now look at the state before this instant's events.
        while let Some(&i) = expects.get(next_expect) {
            let x = &scn.expectations[i];
            if x.due().is_some_and(|at| at > now) {
                break;
            }
            let sample = match &x.kind {
                scenario::ExpectKind::Tag { tag, .. } => stack.db.get_by_name(tag),
                _ => None,
            };
            results.push(x.judge_tag(sample.as_ref()));
            next_expect += 1;
        }
        while let Some(e) = scn.events.get(next_event) {
            if e.at > now {
                break;
            }
            let text = match operator.apply(&e.action).await {
                Ok(()) => e.action.to_string(),
                Err(why) => format!("{} — refused: {why}", e.action),
            };
            actions.push(TimelineEntry {
                at_s: now.as_secs_f64(),
                source: "scenario".into(),
                text,
                priority: None,
            });
            next_event += 1;
        }
        if now >= next_step {
            let inputs = Inputs::at(scn, now);
            if last_inputs.as_ref() != Some(&inputs) {
                inputs.apply(&sim, &stack.plant)?;
                last_inputs = Some(inputs);
            }
            while next_step <= now {
                next_step += scn.step;
            }
        }
        let snap = sim.snapshot();
        if let Some(mg) = &snap.microgrid {
            for u in &mg.units {
                if let Some(p) = u.soc_pct {
                    soc_min = soc_min.min(p);
                }
            }
        }
        if now >= next_sample {
            let dispatch = stack.dispatch.as_ref().map(|d| d.borrow().clone());
            sampler.push(now, &snap, dispatch.as_ref());
            while next_sample <= now {
                next_sample += scn.sample;
            }
        }
        progress.update(now, scn.duration);
        if now >= scn.duration {
            break;
        }
        // Next instant: a step, an event, an expectation or the end.
        let mut next = next_step.min(scn.duration);
        if let Some(e) = scn.events.get(next_event) {
            next = next.min(e.at);
        }
        if let Some(at) = expects
            .get(next_expect)
            .and_then(|&i| scn.expectations[i].due())
        {
            next = next.min(at);
        }
        let wait = next.saturating_sub(offset(&*clock));
        if !wait.is_zero() {
            clock.sleep(wait).await;
        }
    }
    progress.done(scn.duration);
    Ok(Driven {
        baseline,
        soc_min_pct: soc_min,
        results,
        actions,
        plots: sampler.plots(),
        faults,
        dispatch,
    })
}

fn set_soc_pct(sim: &SimHandle, plant: &Plant, unit: &str, pct: f64) -> anyhow::Result<()> {
    let cap = plant
        .microgrid
        .as_ref()
        .and_then(|m| {
            m.units
                .iter()
                .find(|u| u.id.get_ref() == unit || u.prefix.get_ref() == unit)
        })
        .map(|u| u.capacity_kwh)
        .ok_or_else(|| anyhow!("no storage unit '{unit}'"))?;
    sim.set_soc(unit, cap * pct / 100.0)?;
    Ok(())
}

/// What the scenario does as the operator and the weather: simulator
/// inputs, panel commands and acknowledgements, nothing else.
struct Operator<'a> {
    plant: &'a Plant,
    alarms: &'a gridscada_alarms::AlarmEngine,
    panels: &'a [gridscada_web::api::panels::PanelHandle],
    sim: &'a SimHandle,
}

impl Operator<'_> {
    fn of<'a>(stack: &'a Stack, sim: &'a SimHandle) -> Operator<'a> {
        Operator {
            plant: &stack.plant,
            alarms: &stack.alarms,
            panels: &stack.panels,
            sim,
        }
    }

    async fn command(&self, panel: &str, kind: PanelCommandKind) -> Result<(), String> {
        let handle = self
            .panels
            .iter()
            .find(|p| {
                p.id == panel
                    || self
                        .plant
                        .panels
                        .iter()
                        .any(|c| c.id.get_ref() == &p.id && c.prefix.get_ref() == panel)
            })
            .ok_or_else(|| format!("no panel '{panel}'"))?;
        let (reply, rx) = oneshot::channel();
        handle
            .commands
            .send(PanelCommand {
                user: "scenario".into(),
                kind,
                reply,
            })
            .await
            .map_err(|_| "the panel's sequence is not running".to_string())?;
        match rx.await {
            Ok(Ok(())) => Ok(()),
            Ok(Err(e)) => Err(e.to_string()),
            Err(_) => Err("the panel's sequence did not answer".into()),
        }
    }

    /// Performs one scenario event; `Err` is a refusal worth recording, not
    /// a reason to stop (an operator's command can be refused in the field too).
    async fn apply(&self, action: &Action) -> Result<(), String> {
        let sim = self.sim;
        let s = |r: Result<(), gridscada_sim::Error>| r.map_err(|e| e.to_string());
        match action {
            Action::Fault { panel, zone, kind } => s(sim.inject_zone_fault(panel, *zone, *kind)),
            Action::Repair { panel, zone } => s(sim.repair_zone(panel, *zone)),
            Action::Mode { panel, mode } => {
                self.command(panel, PanelCommandKind::SetMode(*mode)).await
            }
            Action::Reset { panel } => self.command(panel, PanelCommandKind::Reset).await,
            Action::Breaker {
                panel,
                breaker,
                close,
            } => {
                self.command(
                    panel,
                    PanelCommandKind::Breaker {
                        breaker: breaker.clone(),
                        close: *close,
                    },
                )
                .await
            }
            Action::Acknowledge { user } => self
                .alarms
                .ack_all(user, &Default::default())
                .map(|_| ())
                .map_err(|e| e.to_string()),
            Action::CommLoss { device } => s(sim.set_device_offline(device, true)),
            Action::CommReturn { device } => s(sim.set_device_offline(device, false)),
            Action::Trip { unit } => s(sim.trip_unit(unit)),
            Action::UnitReset { unit } => s(sim.reset_unit(unit)),
            Action::SetSoc { unit, soc_pct } => {
                set_soc_pct(sim, self.plant, unit, *soc_pct).map_err(|e| e.to_string())
            }
        }
    }

    /// The initial state, before plant time starts running for the scenario.
    async fn initial(&self, scn: &Scenario) -> anyhow::Result<()> {
        for u in &scn.initial.units {
            if let Some(pct) = u.soc_pct {
                set_soc_pct(self.sim, self.plant, &u.id, pct)?;
            }
            if u.tripped {
                self.sim.trip_unit(&u.id)?;
            }
        }
        for p in &scn.initial.panels {
            if p.door_open {
                self.sim.set_door_open(&p.id, true)?;
            }
            for (i, kw) in p.zone_kw.iter().enumerate() {
                let pf = ZoneLoad::default_for(i + 1).pf;
                self.sim
                    .set_zone_load(&p.id, (i + 1) as u8, ZoneLoad { kw: *kw, pf })?;
            }
            if let Some(mode) = p.mode {
                self.command(&p.id, PanelCommandKind::SetMode(mode))
                    .await
                    .map_err(|e| anyhow!("initial mode of panel {}: {e}", p.id))?;
            }
        }
        Ok(())
    }
}

/// The plant inputs at one step, compared to skip unchanged updates.
#[derive(Debug, Clone, PartialEq)]
struct Inputs {
    irradiance: Option<f64>,
    wind: Option<f64>,
    demand: Option<f64>,
    zones: Vec<(String, u8, f64, f64)>,
}

impl Inputs {
    fn at(scn: &Scenario, t: Duration) -> Inputs {
        let p = &scn.profiles;
        let v = |s: &Option<scenario::Series>| s.as_ref().map(|s| s.value_at(t, scn.seed));
        // PV availability (fraction of rated) as the irradiance that gives it.
        let derate = gridscada_sim::MicrogridParams::default().pv_derate;
        let irradiance = v(&p.irradiance)
            .or_else(|| v(&p.pv_available).map(|f| f.clamp(0.0, 1.0) * 1000.0 / derate.max(1e-6)));
        Inputs {
            irradiance: irradiance.map(|x| x.max(0.0)),
            wind: v(&p.wind_speed).map(|x| x.max(0.0)),
            demand: v(&p.demand).map(|x| x.max(0.0)),
            zones: p
                .zones
                .iter()
                .map(|z| {
                    (
                        z.panel.clone(),
                        z.zone,
                        z.kw.value_at(t, scn.seed).max(0.0),
                        z.pf,
                    )
                })
                .collect(),
        }
    }

    fn apply(&self, sim: &SimHandle, plant: &Plant) -> anyhow::Result<()> {
        if plant.microgrid.is_some() {
            if let Some(x) = self.irradiance {
                sim.set_irradiance(Profile::Constant(x))?;
            }
            if let Some(x) = self.wind {
                sim.set_wind_speed(Profile::Constant(x))?;
            }
            if let Some(x) = self.demand {
                sim.set_demand(Profile::Constant(x))?;
            }
        }
        for (panel, zone, kw, pf) in &self.zones {
            sim.set_zone_load(panel, *zone, ZoneLoad { kw: *kw, pf: *pf })?;
        }
        Ok(())
    }
}

/// The report's plots, sampled every `scenario.sample`.
struct Sampler {
    t: Vec<f64>,
    lines: BTreeMap<(usize, String), Vec<f64>>,
    titles: Vec<(&'static str, &'static str)>,
    with_dispatch: bool,
}

impl Sampler {
    fn new(_first: &SimSnapshot, with_dispatch: bool) -> Self {
        Sampler {
            t: Vec::new(),
            lines: BTreeMap::new(),
            titles: vec![
                ("Power by source and demand", "kW"),
                ("State of charge", "%"),
                ("Dispatch setpoints", "kW"),
                ("Panel load (power analyzers)", "kW"),
            ],
            with_dispatch,
        }
    }

    fn put(&mut self, plot: usize, name: &str, v: f64) {
        let n = self.t.len();
        let line = self.lines.entry((plot, name.to_string())).or_default();
        line.resize(n - 1, f64::NAN);
        line.push(v);
    }

    fn push(&mut self, t: Duration, snap: &SimSnapshot, dispatch: Option<&DispatchStatus>) {
        self.t.push(t.as_secs_f64());
        if let Some(mg) = &snap.microgrid {
            for u in &mg.units {
                self.put(0, &u.id, u.p_kw);
                if let Some(p) = u.soc_pct {
                    self.put(1, &u.id, p);
                }
            }
            self.put(0, "demand", mg.demand_kw);
        }
        if self.with_dispatch {
            if let Some(d) = dispatch {
                for (id, v) in &d.setpoints_kw.0 {
                    self.put(2, id, *v);
                }
                self.put(2, "shed", d.shed_kw);
            }
        }
        for p in &snap.panels {
            self.put(3, &p.id, p.analyzer.p_kw);
        }
    }

    fn plots(self) -> Vec<Plot> {
        let n = self.t.len();
        let mut out = Vec::new();
        for (i, (title, unit)) in self.titles.iter().enumerate() {
            let lines: Vec<Line> = self
                .lines
                .iter()
                .filter(|((p, _), _)| *p == i)
                .map(|((_, name), v)| {
                    let mut values = v.clone();
                    values.resize(n, f64::NAN);
                    Line {
                        name: name.clone(),
                        values,
                    }
                })
                .collect();
            if !lines.is_empty() {
                out.push(Plot {
                    title: title.to_string(),
                    unit: unit.to_string(),
                    t_s: self.t.clone(),
                    lines,
                });
            }
        }
        out
    }
}

/// After the last step: the end state, the alarm figures and the timeline
/// from the store.
async fn finish(
    stack: &Stack,
    scn: &Scenario,
    d: Driven,
    wall: Duration,
) -> anyhow::Result<RunOutcome> {
    let sim = stack
        .simulator
        .as_ref()
        .map(|s| s.handle())
        .ok_or_else(|| anyhow!("replay needs the simulated plant"))?;
    let end = sim.snapshot();
    let from = scn.start;
    let to = scn.start.add(scn.duration).add(Duration::from_millis(1));
    // Let the sinks hand their last records to the store (plant time is
    // frozen under --max, so this is wall time only).
    let _ = stack
        .events
        .send(sinks::system_event(
            stack.clock.as_ref(),
            "replay",
            "replay",
            format!("scenario '{}' ended", scn.name),
        ))
        .await;
    tokio::time::sleep(Duration::from_millis(300)).await;

    let mut timeline = d.actions;
    let activations = stack
        .store
        .alarm_activations(from, to)
        .await
        .context("reading alarm activations")?;
    let mut acts = Vec::new();
    for a in &activations {
        let t = &a.transition;
        acts.push(gridscada_alarms::Activation {
            time: t.ts,
            key: t.alarm_key.clone(),
            priority: t.priority.max(0) as u32,
        });
        timeline.push(TimelineEntry {
            at_s: t.ts.since(from).as_secs_f64(),
            source: "alarm".into(),
            text: format!("{}: {}", t.alarm_key, t.message),
            priority: Some(t.priority.max(0) as u32),
        });
    }
    let events = stack
        .store
        .events(&gridscada_store::EventFilter {
            from: Some(from),
            to: Some(to),
            limit: 5000,
            ..Default::default()
        })
        .await
        .context("reading the event log")?;
    for e in events.iter().rev() {
        timeline.push(TimelineEntry {
            at_s: e.ts.since(from).as_secs_f64(),
            source: "event".into(),
            text: format!("{} ({}): {}", e.source, e.kind, e.message),
            priority: None,
        });
    }
    let faults = d.faults.lock().unwrap_or_else(|e| e.into_inner()).clone();
    for f in &faults {
        timeline.push(TimelineEntry {
            at_s: f.at_s,
            source: "sequence".into(),
            text: format!(
                "{}: sequence ended {} — restoration {:.1} s, {} switching operations, {} re-energisations",
                f.panel, f.outcome, f.restore_s, f.switching_ops, f.reenergisations
            ),
            priority: None,
        });
    }
    timeline.sort_by(|a, b| a.at_s.total_cmp(&b.at_s));

    let metrics = gridscada_alarms::compute_metrics(
        &acts,
        &stack.alarms.persisted_states(),
        from,
        to,
        &Default::default(),
    );
    let stats = stack.alarms.stats();
    let alarms = AlarmSummary {
        activations: metrics.total_activations,
        by_priority: metrics
            .priority_distribution
            .iter()
            .map(|p| (p.priority, p.count))
            .collect(),
        average_per_10min: metrics.average_per_interval_per_operator,
        max_per_10min: metrics.max_per_interval_per_operator,
        floods: metrics.floods.len() as u32,
        percent_time_in_flood: metrics.percent_time_in_flood,
        chattering: metrics.chattering.iter().map(|c| c.key.clone()).collect(),
        top: metrics
            .top
            .iter()
            .map(|t| (t.key.clone(), t.count))
            .collect(),
        active_end: stats.active,
        unacked_end: stats.unacked,
    };
    let tally = d.dispatch.lock().unwrap_or_else(|e| e.into_inner());
    let poll = stack.poll_stats().stats().total();
    Ok(RunOutcome {
        wall,
        baseline: d.baseline,
        end,
        soc_min_pct: d.soc_min_pct,
        faults,
        results: d.results,
        timeline,
        plots: d.plots,
        shed_kwh: tally.shed_kwh,
        fallback_periods: tally.fallback_periods,
        alarms,
        panel_end: stack
            .panels
            .iter()
            .map(|p| p.status.borrow().clone())
            .collect(),
        poll_timeouts: poll.timeouts,
        historian_dropped: stack.historian_metrics().dropped,
    })
}

// ----- Figures and the report --------------------------------------------------------

/// Energy and cost figures of one run (end minus the start of the scenario).
fn energy_figures(
    plant: &Plant,
    scn: &Scenario,
    r: &RunOutcome,
) -> (BTreeMap<String, f64>, CostBreakdown) {
    let mut f = BTreeMap::new();
    let mut cost = CostBreakdown::default();
    let (Some(mg0), Some(mg1), Some(cfg)) =
        (&r.baseline.microgrid, &r.end.microgrid, &plant.microgrid)
    else {
        return (f, cost);
    };
    let e0 = &mg0.energy;
    let e1 = &mg1.energy;
    f.insert("demand_kwh".into(), e1.demand_kwh - e0.demand_kwh);
    f.insert("served_kwh".into(), e1.served_kwh - e0.served_kwh);
    let unserved = e1.unserved_kwh - e0.unserved_kwh;
    f.insert("unserved_kwh".into(), unserved);
    f.insert("curtailed_kwh".into(), e1.curtailed_kwh - e0.curtailed_kwh);
    f.insert("surplus_kwh".into(), e1.surplus_kwh - e0.surplus_kwh);
    let (mut pv, mut wind, mut dkwh, mut fuel, mut starts, mut run_s) =
        (0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
    let (mut charged, mut discharged, mut energy_cost, mut cycling) = (0.0, 0.0, 0.0, 0.0);
    let mut soc_end = f64::NAN;
    for u1 in &mg1.units {
        let Some(u0) = mg0.units.iter().find(|u| u.id == u1.id) else {
            continue;
        };
        let Some(c) = cfg.units.iter().find(|c| c.id.get_ref() == &u1.id) else {
            continue;
        };
        let (a, b) = (&u0.counters, &u1.counters);
        let e = b.energy_kwh - a.energy_kwh;
        match u1.kind {
            UnitKind::Pv => {
                pv += e;
                energy_cost += e * c.cost_per_kwh;
            }
            UnitKind::Wind => {
                wind += e;
                energy_cost += e * c.cost_per_kwh;
            }
            UnitKind::Diesel => {
                dkwh += e;
                fuel += b.fuel_l - a.fuel_l;
                starts += (b.starts - a.starts) as f64;
                run_s += b.runtime_s - a.runtime_s;
            }
            UnitKind::Storage => {
                let ch = b.charged_kwh - a.charged_kwh;
                discharged += e;
                charged += ch;
                cycling += (ch + e) * c.cycle_cost_per_kwh / 2.0;
                soc_end = u1.soc_pct.unwrap_or(f64::NAN);
            }
        }
    }
    f.insert("pv_kwh".into(), pv);
    f.insert("wind_kwh".into(), wind);
    f.insert("diesel_kwh".into(), dkwh);
    f.insert("diesel_fuel_l".into(), fuel);
    f.insert("diesel_starts".into(), starts);
    f.insert("diesel_runtime_h".into(), run_s / 3600.0);
    f.insert("storage_charged_kwh".into(), charged);
    f.insert("storage_discharged_kwh".into(), discharged);
    f.insert("storage_throughput_kwh".into(), charged + discharged);
    if r.soc_min_pct.is_finite() {
        f.insert("soc_min_pct".into(), r.soc_min_pct);
    }
    if soc_end.is_finite() {
        f.insert("soc_end_pct".into(), soc_end);
    }
    cost = CostBreakdown::new(
        fuel * scn.fuel_price_per_l,
        energy_cost,
        cycling,
        unserved * cfg.voll_per_kwh,
    );
    f.insert("fuel_cost".into(), cost.fuel);
    f.insert("total_cost".into(), cost.total);
    f.insert("dispatch_shed_kwh".into(), r.shed_kwh);
    f.insert(
        "dispatch_fallback_periods".into(),
        r.fallback_periods as f64,
    );
    (f, cost)
}

fn build_report(
    scn: &Scenario,
    plant: &Plant,
    pace: Pace,
    main: RunOutcome,
    rule: Option<RunOutcome>,
) -> Report {
    let (mut figures, optimal) = energy_figures(plant, scn, &main);
    let rule_cost = rule.as_ref().map(|r| energy_figures(plant, scn, r).1);
    let ratio = rule_cost
        .as_ref()
        .filter(|r| r.total > 0.0)
        .map(|r| optimal.total / r.total);
    if let Some(r) = &rule_cost {
        figures.insert("rule_total_cost".into(), r.total);
    }
    if let Some(x) = ratio {
        figures.insert("cost_ratio".into(), x);
    }
    let a = &main.alarms;
    figures.insert("alarm_activations".into(), f64::from(a.activations));
    figures.insert("alarm_active_end".into(), a.active_end as f64);
    figures.insert("alarm_unacked_end".into(), a.unacked_end as f64);
    figures.insert("alarm_floods".into(), f64::from(a.floods));
    figures.insert("alarm_max_per_10min".into(), a.max_per_10min);
    figures.insert("alarm_avg_per_10min".into(), a.average_per_10min);
    figures.insert("alarm_percent_in_flood".into(), a.percent_time_in_flood);
    figures.insert("alarm_chattering".into(), a.chattering.len() as f64);
    figures.insert("fault_sequences".into(), main.faults.len() as f64);
    figures.insert("poll_timeouts".into(), main.poll_timeouts as f64);
    figures.insert("historian_dropped".into(), main.historian_dropped as f64);
    for (i, p) in plant.panels.iter().enumerate() {
        let id = p.id.get_ref();
        let seqs: Vec<&FaultRecord> = main.faults.iter().filter(|f| &f.panel == id).collect();
        let put = |f: &mut BTreeMap<String, f64>, k: &str, v: f64| {
            f.insert(format!("{id}.{k}"), v);
        };
        put(&mut figures, "sequences", seqs.len() as f64);
        put(
            &mut figures,
            "restore_s_max",
            seqs.iter().map(|f| f.restore_s).fold(0.0, f64::max),
        );
        put(
            &mut figures,
            "restore_s_last",
            seqs.last().map(|f| f.restore_s).unwrap_or(0.0),
        );
        put(
            &mut figures,
            "switching_ops",
            seqs.iter().map(|f| f64::from(f.switching_ops)).sum::<f64>() + 0.0,
        );
        put(
            &mut figures,
            "reenergisations",
            seqs.iter()
                .map(|f| f64::from(f.reenergisations))
                .sum::<f64>()
                + 0.0,
        );
        let trips = |s: &SimSnapshot| s.panels.get(i).map(|p| p.elcb_trips).unwrap_or(0);
        put(
            &mut figures,
            "elcb_trips",
            trips(&main.end).saturating_sub(trips(&main.baseline)) as f64,
        );
        put(
            &mut figures,
            "lockout",
            f64::from(u8::from(main.panel_end.get(i).is_some_and(|s| s.lockout))),
        );
        put(
            &mut figures,
            "zones_closed_end",
            main.end
                .panels
                .get(i)
                .map(|p| p.zones.iter().filter(|z| z.breaker.closed).count())
                .unwrap_or(0) as f64,
        );
    }
    let wall_s = main.wall.as_secs_f64().max(1e-6);
    let speedup = scn.duration.as_secs_f64() / wall_s;
    figures.insert("wall_s".into(), wall_s);
    figures.insert("speedup".into(), speedup);

    let mut expectations = main.results.clone();
    for x in &scn.expectations {
        if x.due().is_none() {
            expectations.push(x.judge_figure(&figures));
        }
    }
    expectations.sort_by_key(|e| e.line);
    let passed = expectations.iter().all(|e| e.acceptable());
    let mut notes = Vec::new();
    if main.historian_dropped > 0 {
        notes.push(format!(
            "the historian dropped {} samples (its writer fell behind the compressed clock)",
            main.historian_dropped
        ));
    }
    if let Some(r) = &rule {
        notes.push(format!(
            "rule-based baseline replayed in {:.1} s of wall time",
            r.wall.as_secs_f64()
        ));
    }
    Report {
        scenario: scn.name.clone(),
        description: scn.description.clone(),
        file: scn.path.display().to_string(),
        plant: scn
            .plant
            .as_ref()
            .map(|p| p.display().to_string())
            .unwrap_or_else(|| "embedded demo plant".into()),
        seed: scn.seed,
        start_ms: scn.start.as_millis(),
        duration_s: scn.duration.as_secs_f64(),
        step_s: scn.step.as_secs_f64(),
        clock: pace.label(),
        wall_s,
        speedup,
        passed,
        figures,
        cost: CostComparison {
            fuel_price_per_l: scn.fuel_price_per_l,
            voll_per_kwh: plant
                .microgrid
                .as_ref()
                .map(|m| m.voll_per_kwh)
                .unwrap_or(0.0),
            optimal,
            rule: rule_cost,
            ratio,
        },
        alarms: main.alarms,
        faults: main.faults,
        expectations,
        timeline: main.timeline,
        plots: main.plots,
        notes,
    }
}

// ----- Progress -------------------------------------------------------------------------

/// The progress line on stderr: a bar when it is a terminal, a plain line
/// every 10 % otherwise.
struct Progress {
    label: String,
    tty: bool,
    started: Instant,
    last_draw: Instant,
    last_tenth: u64,
}

impl Progress {
    fn new(label: &str, scn: &Scenario) -> Self {
        let p = Progress {
            label: format!("{} [{}]", scn.name, label),
            tty: std::io::stderr().is_terminal(),
            started: Instant::now(),
            last_draw: Instant::now(),
            last_tenth: 0,
        };
        if !p.tty {
            eprintln!("{}: starting", p.label);
        }
        p
    }

    fn update(&mut self, now: Duration, total: Duration) {
        let frac = (now.as_secs_f64() / total.as_secs_f64().max(1e-9)).clamp(0.0, 1.0);
        let wall = self.started.elapsed().as_secs_f64().max(1e-6);
        let speed = now.as_secs_f64() / wall;
        if self.tty {
            if self.last_draw.elapsed() < Duration::from_millis(200) {
                return;
            }
            self.last_draw = Instant::now();
            let filled = (frac * 30.0) as usize;
            eprint!(
                "\r{} [{}{}] {} / {}  ×{:.0} ",
                self.label,
                "#".repeat(filled),
                ".".repeat(30 - filled),
                scenario::time::format_offset(Duration::from_secs(now.as_secs())),
                scenario::time::format_offset(total),
                speed
            );
            let _ = std::io::stderr().flush();
        } else {
            let tenth = (frac * 10.0) as u64;
            if tenth > self.last_tenth && tenth < 10 {
                self.last_tenth = tenth;
                eprintln!(
                    "{}: {} of {} plant time, ×{:.0}",
                    self.label,
                    scenario::time::format_offset(Duration::from_secs(now.as_secs())),
                    scenario::time::format_offset(total),
                    speed
                );
            }
        }
    }

    fn done(&mut self, total: Duration) {
        let wall = self.started.elapsed().as_secs_f64().max(1e-6);
        if self.tty {
            eprint!("\r\x1b[2K");
        }
        eprintln!(
            "{}: {} of plant time in {:.1} s of wall time (×{:.0})",
            self.label,
            scenario::time::format_offset(total),
            wall,
            total.as_secs_f64() / wall
        );
    }
}

// ----- Live: demo --scenario --------------------------------------------------------------

/// A scenario to run live under `gridscada demo`, with the HMI attached.
pub struct LiveScenario {
    pub scenario: Scenario,
    pub plant: Plant,
    pub speed: f64,
}

impl LiveScenario {
    pub fn load(file: &Path, speed: f64) -> anyhow::Result<LiveScenario> {
        if !(speed.is_finite() && speed > 0.0 && speed <= 10_000.0) {
            return Err(anyhow!("--speed {speed}: need 0 < speed <= 10000"));
        }
        let (scenario, plant) = load(file)?;
        Ok(LiveScenario {
            scenario,
            plant,
            speed,
        })
    }

    /// The demo's clock: the scenario's start, at its speed.
    pub fn clock(&self) -> Arc<dyn Clock> {
        Arc::new(FlooredClock(ScaledClock::new(
            clock_start(&self.scenario),
            self.speed,
        )))
    }
}

impl LiveDriver for LiveScenario {
    fn plant(&self) -> &Plant {
        &self.plant
    }
    fn clock(&self) -> Arc<dyn Clock> {
        LiveScenario::clock(self)
    }
    fn start(self: Box<Self>, stack: &Stack) {
        spawn_live(stack, *self);
    }
}

/// Drives the scenario in the background of a running demo and prints each
/// expectation's verdict when it finishes; the demo keeps running after.
pub fn spawn_live(stack: &Stack, live: LiveScenario) {
    let ctx = LiveStack {
        plant: stack.plant.clone(),
        clock: stack.clock.clone(),
        db: stack.db.clone(),
        alarms: stack.alarms.clone(),
        panels: stack.panels.clone(),
        sim: stack.simulator.as_ref().map(|s| s.handle()),
    };
    println!(
        "Scenario '{}' runs at ×{} ({} of plant time).",
        live.scenario.name,
        live.speed,
        scenario::time::format_offset(live.scenario.duration)
    );
    tokio::spawn(async move {
        match ctx.run(&live.scenario).await {
            Ok(results) => {
                let failed = results.iter().filter(|r| !r.passed).count();
                for r in &results {
                    println!(
                        "  {} line {}: {} (got {})",
                        if r.passed { "pass" } else { "FAIL" },
                        r.line,
                        r.description,
                        r.actual
                    );
                }
                println!(
                    "Scenario '{}' finished: {} of {} timed expectations met; the plant keeps running.",
                    live.scenario.name,
                    results.len() - failed,
                    results.len()
                );
            }
            Err(e) => eprintln!("scenario stopped: {e:#}"),
        }
    });
}

/// The parts of a [`Stack`] a live scenario needs, owned by its task.
struct LiveStack {
    plant: Arc<Plant>,
    clock: Arc<dyn Clock>,
    db: Arc<gridscada_tagdb::TagDb>,
    alarms: Arc<gridscada_alarms::AlarmEngine>,
    panels: Vec<gridscada_web::api::panels::PanelHandle>,
    sim: Option<SimHandle>,
}

impl LiveStack {
    /// Events, profiles and timed expectations in plant time (figures need
    /// a whole replay, so they are not judged live).
    async fn run(&self, scn: &Scenario) -> anyhow::Result<Vec<ExpectationResult>> {
        let sim = self
            .sim
            .clone()
            .ok_or_else(|| anyhow!("the demo has no simulator"))?;
        let start = self.clock.now().add(scn.warmup);
        let operator = Operator {
            plant: &self.plant,
            alarms: &self.alarms,
            panels: &self.panels,
            sim: &sim,
        };
        operator.initial(scn).await?;
        Inputs::at(scn, Duration::ZERO).apply(&sim, &self.plant)?;
        self.clock.sleep(scn.warmup).await;
        let mut timed: Vec<(Duration, Option<usize>, Option<usize>)> = Vec::new();
        for (i, e) in scn.events.iter().enumerate() {
            timed.push((e.at, Some(i), None));
        }
        for (i, x) in scn.expectations.iter().enumerate() {
            if let Some(at) = x.due() {
                timed.push((at, None, Some(i)));
            }
        }
        // Expectations before events at the same instant, as in replay.
        timed.sort_by_key(|(at, ev, _)| (*at, ev.is_some()));
        let mut results = Vec::new();
        let mut t = Duration::ZERO;
        let mut ti = 0;
        while t <= scn.duration {
            Inputs::at(scn, t).apply(&sim, &self.plant)?;
            while let Some((at, ev, ex)) = timed.get(ti) {
                if *at > t {
                    break;
                }
                let wait = at.saturating_sub(self.clock.now().since(start));
                if !wait.is_zero() {
                    self.clock.sleep(wait).await;
                }
                if let Some(i) = ev {
                    let e = &scn.events[*i];
                    let outcome = operator.apply(&e.action).await;
                    println!(
                        "[scenario {}] {}{}",
                        scenario::time::format_offset(e.at),
                        e.action,
                        outcome
                            .err()
                            .map(|w| format!(" — refused: {w}"))
                            .unwrap_or_default()
                    );
                }
                if let Some(i) = ex {
                    let x = &scn.expectations[*i];
                    if let scenario::ExpectKind::Tag { tag, .. } = &x.kind {
                        results.push(x.judge_tag(self.db.get_by_name(tag).as_ref()));
                    }
                }
                ti += 1;
            }
            t += scn.step;
            let wait = t.saturating_sub(self.clock.now().since(start));
            if !wait.is_zero() {
                self.clock.sleep(wait).await;
            }
        }
        Ok(results)
    }
}
