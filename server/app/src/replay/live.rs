//! `gridscada demo --scenario`: a scenario driven live in the background of
//! a running demo, with the HMI attached.

use std::path::Path;
use std::sync::Arc;
use std::time::Duration;

use anyhow::anyhow;
use gridscada_config::Plant;
use gridscada_sim::scenario::expect::ExpectationResult;
use gridscada_sim::scenario::{self, Scenario};
use gridscada_sim::SimHandle;
use gridscada_tagdb::{Clock, ScaledClock};

use crate::runtime::{LiveDriver, Stack};

use super::clock::FlooredClock;
use super::load;
use super::operator::{Inputs, Operator};
use super::run::clock_start;

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
