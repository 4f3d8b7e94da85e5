//! `gridscada replay` and `gridscada demo --scenario`: runs a scenario
//! (`gridscada_sim::scenario`) through the whole stack — simulators, the
//! poller over real Modbus on loopback, alarms, historian, fault isolation
//! and dispatch — on a compressed clock, and reports what happened.
//!
//! **Owns:** the replay clocks ([`VirtualClock`](clock::VirtualClock) for
//! `--max`, a floored scaled clock for `--speed`; `clock.rs`), driving the
//! scenario's profiles, events and expectations against a running
//! [`Stack`](crate::runtime::Stack) (`run.rs`, acting through `operator.rs`),
//! measuring the report's figures (`report.rs`), the rule-based baseline run,
//! the progress line (`progress.rs`) and the live scenario of `demo
//! --scenario` (`live.rs`). This file holds the command itself.
//!
//! **Must not touch:** control decisions or plant physics: it only acts as
//! the operator and the weather would (simulator inputs, panel commands,
//! acknowledgements) and reads what the SCADA and the simulator show.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{anyhow, Context};
use gridscada_config::Plant;
use gridscada_control::dispatch::DispatchPolicy;
use gridscada_sim::scenario::report::Report;
use gridscada_sim::scenario::{self, Scenario};

use crate::demo_plant;

mod clock;
mod foresight;
mod live;
mod operator;
mod progress;
mod report;
mod run;

pub use clock::Pace;
pub use live::LiveScenario;

use report::build_report;
use run::run_once;

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
    let mut plant = match &scn.plant {
        Some(p) => gridscada_config::load_path(p).map_err(diags)?,
        None => demo_plant::load().map_err(diags)?,
    };
    // The scenario's cost model: its fuel price is the dispatch's too.
    if let (Some(price), Some(mg)) = (scn.fuel_price_per_l, plant.microgrid.as_mut()) {
        mg.set_fuel_price(price);
    }
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
    let compare = scn.compare_rule && !args.no_compare && plant.microgrid.is_some();
    let main = |quiet_progress: bool| {
        run_once(
            scn,
            plant,
            args.pace,
            DispatchPolicy::Optimal,
            args.data.as_deref(),
            ("replay", quiet_progress),
        )
    };
    let (main, rule) = if compare {
        // The baseline is a second, independent stack on its own runtime,
        // clock and database: run it on the other core, beside the main run.
        // Neither shares state with the other, so each stays deterministic.
        std::thread::scope(|s| {
            let rule = std::thread::Builder::new()
                .name("replay-baseline".into())
                .spawn_scoped(s, || {
                    run_once(
                        scn,
                        plant,
                        args.pace,
                        DispatchPolicy::Rule,
                        None,
                        ("rule baseline", true),
                    )
                })
                .context("starting the baseline run's thread")?;
            let main = main(false);
            let rule = rule
                .join()
                .map_err(|_| anyhow!("the baseline run panicked"))?;
            anyhow::Ok((main?, Some(rule?)))
        })?
    } else {
        (main(false)?, None)
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
        match (r.figures.get("optimum_ratio"), r.cost.ratio) {
            (Some(o), Some(x)) => format!(
                " (×{o:.3} of the perfect-foresight optimum, ×{x:.3} of the rule-based dispatch)"
            ),
            (Some(o), None) => format!(" (×{o:.3} of the perfect-foresight optimum)"),
            (None, Some(x)) => format!(" (×{x:.3} of the rule-based dispatch)"),
            (None, None) => String::new(),
        }
    );
}
