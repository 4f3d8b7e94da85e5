//! kill -9 durability: a child process writes events (one committed call each)
//! and historian samples (through the writer task) in a loop and reports what
//! it committed; the parent kills it with SIGKILL mid-stream, reopens the
//! database and checks every reported row is there.
//!
//! The child is this same test binary, re-run with `--exact durability::crash_child` and the
//! target in environment variables, so no extra binary needs building.

use crate::common;

use std::io::{BufRead, BufReader, Write};
use std::process::{Command, Stdio};
use std::sync::Arc;
use std::time::{Duration, Instant};

use common::{Engine, TestDb};
use gridscada_store::*;
use gridscada_tagdb::{QualityCode, Timestamp};

const ENV_URL: &str = "GRIDSCADA_CRASH_CHILD_URL";
const ENV_DIR: &str = "GRIDSCADA_CRASH_CHILD_DIR";
const ENV_SCHEMA: &str = "GRIDSCADA_CRASH_CHILD_SCHEMA";

/// The child: does nothing unless started by `kill9` below.
#[test]
fn crash_child() {
    let Ok(url) = std::env::var(ENV_URL) else {
        return;
    };
    let mut options = OpenOptions::new(std::env::var(ENV_DIR).unwrap());
    options.pg_schema = std::env::var(ENV_SCHEMA).ok();
    let rt = tokio::runtime::Runtime::new().unwrap();
    rt.block_on(async move {
        let store = Store::open(&url, &options).await.unwrap();
        let hist = Historian::spawn(
            store.clone(),
            HistorianConfig {
                linger: Duration::from_millis(2),
                ..Default::default()
            },
        );
        let h = hist.handle();
        let mut out = std::io::stdout();
        for i in 0i64.. {
            let id = store
                .insert_event(&NewEvent {
                    ts: Timestamp::from_millis(i),
                    user: None,
                    source: "crash".into(),
                    kind: "test".into(),
                    message: format!("event {i}"),
                })
                .await
                .unwrap();
            // Written straight to the fd (not the test harness's capture), one
            // write per line.
            out.write_all(format!("E {id} {i}\n").as_bytes()).unwrap();
            for k in 0..10 {
                h.push(HistorySample {
                    tag: Arc::from("crash.P"),
                    ts: Timestamp::from_millis(i * 10 + k),
                    value: Some((i * 10 + k) as f64),
                    exact: None,
                    quality: QualityCode::Good,
                });
            }
            // Samples go in order through one writer, so "n written" means
            // samples 0..n are committed.
            let written = h.metrics().samples_written;
            out.write_all(format!("S {written}\n").as_bytes()).unwrap();
        }
    });
}

fn kill9(engine: Engine) {
    let rt = tokio::runtime::Runtime::new().unwrap();
    let Some(db) = rt.block_on(TestDb::new(engine, "kill9")) else {
        return;
    };
    rt.block_on(db.store.close());
    let mut cmd = Command::new(std::env::current_exe().unwrap());
    // The test's name in the harness: its module path without the binary's.
    let child_test = concat!(module_path!(), "::crash_child")
        .split_once("::")
        .map_or("crash_child", |(_, path)| path);
    cmd.args(["--exact", child_test, "--nocapture", "--test-threads=1"])
        .env(ENV_URL, &db.url)
        .env(ENV_DIR, db.dir.path())
        .stdout(Stdio::piped())
        .stderr(Stdio::null());
    if let Some(s) = &db.options.pg_schema {
        cmd.env(ENV_SCHEMA, s);
    }
    let mut child = cmd.spawn().expect("spawning the crash child");
    let mut lines = BufReader::new(child.stdout.take().unwrap()).lines();
    let mut events: Vec<(i64, i64)> = Vec::new();
    let mut samples = 0u64;
    let started = Instant::now();
    let record = |line: &str, events: &mut Vec<(i64, i64)>, samples: &mut u64| {
        let f: Vec<&str> = line.split(' ').collect();
        match f.as_slice() {
            ["E", id, i] => events.push((id.parse().unwrap(), i.parse().unwrap())),
            ["S", n] => *samples = (*samples).max(n.parse().unwrap()),
            _ => {}
        }
    };
    // Let it run until it has committed a fair amount of both, then SIGKILL.
    while events.len() < 200 || samples < 500 {
        assert!(
            started.elapsed() < Duration::from_secs(60),
            "child too slow or stuck"
        );
        match lines.next() {
            Some(Ok(l)) => record(&l, &mut events, &mut samples),
            _ => panic!("crash child ended early"),
        }
    }
    child.kill().expect("SIGKILL"); // Child::kill is SIGKILL on Unix
    child.wait().unwrap();
    // Lines already in the pipe were written before the kill: all committed.
    for l in lines.map_while(Result::ok) {
        record(&l, &mut events, &mut samples);
    }

    rt.block_on(async {
        let mut db = db;
        db.reopen().await;
        let stored = db
            .store
            .events(&EventFilter {
                source: Some("crash".into()),
                limit: 10_000,
                ..Default::default()
            })
            .await
            .unwrap();
        for (id, i) in &events {
            let e = stored
                .iter()
                .find(|e| e.id == *id)
                .unwrap_or_else(|| panic!("committed event {id} lost after kill -9"));
            assert_eq!(e.message, format!("event {i}"));
        }
        let rows = db
            .store
            .raw_samples(
                &["crash.P"],
                Timestamp::from_millis(0),
                Timestamp::from_millis(i64::MAX / 2),
                1_000_000,
            )
            .await
            .unwrap();
        assert!(
            rows.len() as u64 >= samples,
            "{} rows < {samples} reported written",
            rows.len()
        );
        for (k, r) in rows.iter().take(samples as usize).enumerate() {
            assert_eq!(r.ts.as_millis(), k as i64, "committed sample {k} lost");
        }
        eprintln!(
            "kill9 {engine:?}: {} events and {samples} samples reported committed, all found",
            events.len()
        );
        db.cleanup().await;
    });
}

#[test]
fn kill9_sqlite() {
    kill9(Engine::Sqlite);
}

#[test]
fn kill9_postgres() {
    kill9(Engine::Postgres);
}
