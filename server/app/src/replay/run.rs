//! One run of a scenario: starting the stack on its clock, driving the
//! timeline (initial state, steps, events, expectations) in plant time, and
//! collecting what happened at the end.

use std::path::Path;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use anyhow::{anyhow, Context};
use gridscada_config::Plant;
use gridscada_control::dispatch::{DispatchMode, DispatchPolicy};
use gridscada_control::fault_isolation::PanelStatus;
use gridscada_sim::scenario::expect::ExpectationResult;
use gridscada_sim::scenario::report::{AlarmSummary, FaultRecord, Plot, TimelineEntry};
use gridscada_sim::scenario::{self, Scenario};
use gridscada_sim::SimSnapshot;
use gridscada_tagdb::{Clock, ScaledClock, Timestamp};

use crate::data::open_store;
use crate::runtime::{Stack, StackOptions};
use crate::sinks;

use super::clock::{FlooredClock, Pace, VirtualClock};
use super::foresight::ForesightRecorder;
use super::operator::{Inputs, Operator};
use super::progress::Progress;
use super::report::Sampler;

/// What one run measured.
pub(super) struct RunOutcome {
    pub(super) wall: Duration,
    pub(super) baseline: SimSnapshot,
    pub(super) end: SimSnapshot,
    pub(super) soc_min_pct: f64,
    pub(super) faults: Vec<FaultRecord>,
    pub(super) results: Vec<ExpectationResult>,
    pub(super) timeline: Vec<TimelineEntry>,
    pub(super) plots: Vec<Plot>,
    pub(super) shed_kwh: f64,
    pub(super) fallback_periods: u64,
    pub(super) alarms: AlarmSummary,
    pub(super) panel_end: Vec<PanelStatus>,
    pub(super) poll_timeouts: u64,
    pub(super) historian_dropped: u64,
    /// What the day was, period by period, for the perfect-foresight optimum.
    pub(super) foresight: ForesightRecorder,
}

/// Runs the scenario once; `progress` is the progress line's label and
/// whether it stays quiet (a run beside another).
pub(super) fn run_once(
    scn: &Scenario,
    plant: &Plant,
    pace: Pace,
    policy: DispatchPolicy,
    data: Option<&Path>,
    progress: (&str, bool),
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
            let (hook, wake) = (clock.clone(), clock.clone());
            let rt = tokio::runtime::Builder::new_current_thread()
                .enable_all()
                .on_thread_park(move || hook.on_idle())
                .on_thread_unpark(move || wake.on_wake())
                .build()
                .context("starting the replay runtime")?;
            rt.block_on(run_stack(
                scn,
                plant,
                clock.clone(),
                Some(clock),
                policy,
                &data,
                progress,
            ))
        }
        Pace::Scaled(speed) => {
            let rt = tokio::runtime::Builder::new_multi_thread()
                .enable_all()
                .build()
                .context("starting the replay runtime")?;
            let clock: Arc<dyn Clock> =
                Arc::new(FlooredClock(ScaledClock::new(clock_start(scn), speed)));
            rt.block_on(run_stack(scn, plant, clock, None, policy, &data, progress))
        }
    }
}

/// Plant time when the stack starts: the warm-up before the scenario's start.
pub(super) fn clock_start(scn: &Scenario) -> Timestamp {
    Timestamp::from_millis(scn.start.as_millis() - scn.warmup.as_millis() as i64)
}

async fn run_stack(
    scn: &Scenario,
    plant: &Plant,
    clock: Arc<dyn Clock>,
    virt: Option<Arc<VirtualClock>>,
    policy: DispatchPolicy,
    data: &Path,
    (label, quiet): (&str, bool),
) -> anyhow::Result<RunOutcome> {
    let store = open_store(plant, data).await?;
    let stack = Stack::start(
        plant.clone(),
        store,
        StackOptions {
            clock: clock.clone(),
            simulate: true,
            real_devices: Vec::new(),
            simulator_pipes: true,
            dispatch_policy: policy,
            restore_panels: false,
            data_dir: data.to_path_buf(),
            notify: false,
        },
    )
    .await?;
    if let Some(v) = &virt {
        let stats = stack.poll_stats();
        v.start(move || stats.in_flight());
    }
    let wall = Instant::now();
    let driven = drive(&stack, scn, Progress::new(label, scn, quiet)).await;
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
    foresight: ForesightRecorder,
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
    let mut foresight = ForesightRecorder::new(&stack.plant);
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
        foresight.push(now, &snap);
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
        foresight,
    })
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
                "{}: sequence ended {} — {}, {} switching operations, {} re-energisations",
                f.panel,
                f.outcome,
                match f.restore_s {
                    Some(s) => format!("restoration {s:.1} s"),
                    None => "not restored".into(),
                },
                f.switching_ops,
                f.reenergisations
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
        foresight: d.foresight,
    })
}
