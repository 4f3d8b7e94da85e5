//! `gridscada replay` end to end, through the binary: a short scenario runs
//! the whole stack and passes; the same scenario gives the same report twice,
//! byte for byte but for the wall time (virtual clock, the rule-based
//! baseline running beside the main run); a failing expectation exits 1; a broken scenario exits 2
//! with a located error.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use serde_json::Value;

const BIN: &str = env!("CARGO_BIN_EXE_gridscada");

fn scenarios() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenarios")
}

fn replay(file: &Path, extra: &[&str]) -> Output {
    Command::new(BIN)
        .arg("replay")
        .arg(file)
        .args(extra)
        .env("RUST_LOG", "warn")
        .output()
        .expect("running gridscada replay")
}

fn report(path: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).expect("report written"))
        .expect("JSON report")
}

#[test]
fn transient_fault_replays_through_the_stack_deterministically() {
    let dir = tempfile::tempdir().unwrap();
    let file = scenarios().join("transient-fault.toml");
    let mut runs = Vec::new();
    for i in 0..2 {
        let json = dir.path().join(format!("r{i}.json"));
        let html = dir.path().join(format!("r{i}.html"));
        let out = replay(
            &file,
            &[
                "--max",
                "--report",
                json.to_str().unwrap(),
                "--html",
                html.to_str().unwrap(),
            ],
        );
        assert!(
            out.status.success(),
            "stdout:\n{}\nstderr:\n{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
        let r = report(&json);
        assert_eq!(r["passed"], true);
        // The sequence really ran: one trip, everything reclosed, recorded from the panel status.
        let faults = r["faults"].as_array().unwrap();
        assert_eq!(faults.len(), 1, "{faults:?}");
        assert_eq!(faults[0]["panel"], "ss1");
        assert_eq!(faults[0]["outcome"], "restored");
        assert_eq!(r["figures"]["ss1.elcb_trips"], 1.0);
        assert!(r["timeline"]
            .as_array()
            .unwrap()
            .iter()
            .any(|t| t["source"] == "alarm"));
        let page = std::fs::read_to_string(&html).unwrap();
        assert!(page.contains("<svg") && page.contains("Timeline"));
        assert!(!page.contains("src=\"http") && !page.contains("href=\"http"));
        runs.push(r);
    }
    // Same scenario, same outcome: the baseline ran beside the main run.
    assert!(runs[0]["cost"]["rule"].is_object(), "{}", runs[0]["cost"]);
    for (k, v) in runs[0]["figures"].as_object().unwrap() {
        if k == "wall_s" || k == "speedup" {
            continue;
        }
        assert_eq!(
            Some(v),
            runs[1]["figures"].get(k),
            "figure {k} differs between runs"
        );
    }
    assert_eq!(runs[0]["faults"], runs[1]["faults"]);
    // And the whole report, byte for byte, once the wall times are out.
    let texts: Vec<String> = runs
        .into_iter()
        .map(|r| serde_json::to_string_pretty(&without_wall_time(r)).unwrap())
        .collect();
    assert!(
        texts[0] == texts[1],
        "reports differ:\n{}\n---\n{}",
        texts[0],
        texts[1]
    );
}

/// A report without what depends on the machine: the wall time and speed-up
/// of the main run, the note with the baseline's wall time and the
/// perfect-foresight optimum's solve time.
fn without_wall_time(mut r: Value) -> Value {
    let o = r.as_object_mut().unwrap();
    o.remove("wall_s");
    o.remove("speedup");
    let figures = o["figures"].as_object_mut().unwrap();
    figures.remove("wall_s");
    figures.remove("speedup");
    if let Some(optimum) = o
        .get_mut("cost")
        .and_then(|c| c.get_mut("optimum"))
        .and_then(Value::as_object_mut)
    {
        optimum.remove("solve_ms");
    }
    if let Some(notes) = o.get_mut("notes").and_then(Value::as_array_mut) {
        notes.retain(|n| !n.as_str().is_some_and(|t| t.contains("of wall time")));
    }
    r
}

#[test]
fn a_failing_expectation_exits_1_and_a_broken_scenario_exits_2() {
    let dir = tempfile::tempdir().unwrap();
    let failing = dir.path().join("failing.toml");
    std::fs::write(
        &failing,
        "name = \"fails\"\nduration = 20\nwarmup = 5\ncompare_rule = false\n\n[[expect]]\nat = 10\ntag = \"SS1.ELCB.Closed\"\nvalue = false\n",
    )
    .unwrap();
    let out = replay(&failing, &[]);
    assert_eq!(
        out.status.code(),
        Some(1),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(String::from_utf8_lossy(&out.stdout).contains("FAIL line   6"));

    let broken = dir.path().join("broken.toml");
    std::fs::write(
        &broken,
        "name = \"broken\"\nduration = 20\n\n[[event]]\nat = 5\naction = \"fault\"\npanel = \"ss1\"\nzone = 9\n",
    )
    .unwrap();
    let out = replay(&broken, &[]);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("broken.toml:8:8") && err.contains("no zone 9"),
        "{err}"
    );
}
