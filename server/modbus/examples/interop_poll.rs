//! Interoperability probe: polls a plant configuration once with the real
//! field I/O and prints every tag as a JSON line, for the end-to-end tests
//! against third-party Modbus servers (`tests/e2e/interop_*`).
//!
//! ```sh
//! cargo run -p gridscada-modbus --example interop_poll -- \
//!     --config PATH [--wait-s 10] [--watch-ms 0] [--write TAG=VALUE]...
//! ```
//!
//! 1. Loads the configuration (`gridscada_config::load_path`), builds the tag
//!    database the app would (plant tags + device status tags) and starts
//!    [`FieldIo`] with the system clock.
//! 2. Waits until every plant tag has a Good reading (or `--wait-s` passes).
//! 3. Performs each `--write` in order through the field writer (which
//!    confirms by read-back) and prints one line per write:
//!    `{"write":TAG,"ok":true,"value":V,"quality":"good"}` or
//!    `{"write":TAG,"ok":false,"error":"..."}`. With `--watch-ms N`, each
//!    confirmed write is then watched for N ms: the line adds
//!    `"rollbacks":K`, the number of times the tag database showed another
//!    value, or an older timestamp, than the confirmed read-back (a scan
//!    that read the register before the write must never overwrite it).
//! 4. Prints every tag: `{"tag":NAME,"value":V,"quality":"good"|"uncertain"|"bad","reason":R}`.
//!    Non-finite floats print as `null` with `"nonfinite":"NaN"` (or `inf`, `-inf`).
//!
//! VALUE is `true`/`false`, an integer, a number, or else a string.
//! Exit status: 0 when every plant tag read Good and every write was
//! confirmed, 1 otherwise, 2 on bad arguments or configuration.
//!
//! Owns nothing but this probe's command line and output; it must not
//! change how the poller works.

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::time::{Duration, Instant};

use gridscada_modbus::FieldIo;
use gridscada_tagdb::{QualityCode, Sample, SystemClock, TagDb, Value};

struct Args {
    config: PathBuf,
    wait: Duration,
    watch: Duration,
    writes: Vec<(String, Value)>,
}

fn usage() -> String {
    "usage: interop_poll --config PATH [--wait-s SECONDS] [--watch-ms MS] [--write TAG=VALUE]..."
        .into()
}

fn parse_args(mut it: impl Iterator<Item = String>) -> Result<Args, String> {
    let mut config = None;
    let mut wait = Duration::from_secs(10);
    let mut writes = Vec::new();
    let mut watch = Duration::ZERO;
    while let Some(a) = it.next() {
        let mut next = |what: &str| it.next().ok_or_else(|| format!("{a} needs {what}"));
        match a.as_str() {
            "--config" => config = Some(PathBuf::from(next("a path")?)),
            "--wait-s" => {
                let s = next("a number of seconds")?;
                let secs: f64 = s
                    .parse()
                    .ok()
                    .filter(|v: &f64| v.is_finite() && *v >= 0.0 && *v < 3600.0)
                    .ok_or_else(|| format!("--wait-s {s}: not a number of seconds (0-3600)"))?;
                wait = Duration::from_secs_f64(secs);
            }
            "--watch-ms" => {
                let s = next("milliseconds")?;
                let ms: u64 = s.parse().ok().filter(|v| *v <= 600_000).ok_or_else(|| {
                    format!("--watch-ms {s}: not a number of milliseconds (0-600000)")
                })?;
                watch = Duration::from_millis(ms);
            }
            "--write" => {
                let w = next("TAG=VALUE")?;
                let (tag, value) = w
                    .split_once('=')
                    .ok_or_else(|| format!("--write {w}: expected TAG=VALUE"))?;
                writes.push((tag.to_string(), parse_value(value)));
            }
            "-h" | "--help" => return Err(usage()),
            other => return Err(format!("unknown argument '{other}'\n{}", usage())),
        }
    }
    Ok(Args {
        config: config.ok_or_else(usage)?,
        wait,
        watch,
        writes,
    })
}

fn parse_value(s: &str) -> Value {
    match s {
        "true" => Value::Bool(true),
        "false" => Value::Bool(false),
        _ => {
            if let Ok(i) = s.parse::<i64>() {
                Value::Int(i)
            } else if let Ok(u) = s.parse::<u64>() {
                Value::from_u64(u)
            } else if let Ok(f) = s.parse::<f64>() {
                Value::Float(f)
            } else {
                Value::Str(s.into())
            }
        }
    }
}

/// A JSON string literal.
fn json_str(s: &str) -> String {
    let mut out = String::with_capacity(s.len() + 2);
    out.push('"');
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            '\n' => out.push_str("\\n"),
            '\r' => out.push_str("\\r"),
            '\t' => out.push_str("\\t"),
            c if (c as u32) < 0x20 => out.push_str(&format!("\\u{:04x}", c as u32)),
            c => out.push(c),
        }
    }
    out.push('"');
    out
}

/// `"value":...` (and `"nonfinite"` for NaN and infinities, which JSON lacks).
fn json_value(v: &Value) -> String {
    match v {
        Value::Bool(b) => format!("\"value\":{b}"),
        Value::Int(i) => format!("\"value\":{i}"),
        Value::UInt(u) => format!("\"value\":{u}"),
        // Debug prints the shortest text that reads back to the same f64.
        Value::Float(f) if f.is_finite() => format!("\"value\":{f:?}"),
        Value::Float(f) => format!("\"value\":null,\"nonfinite\":{}", json_str(&f.to_string())),
        Value::Str(s) => format!("\"value\":{}", json_str(s)),
    }
}

fn json_quality(s: &Sample) -> String {
    let code = match s.quality.code {
        QualityCode::Good => "good",
        QualityCode::Uncertain => "uncertain",
        QualityCode::Bad => "bad",
    };
    let reason = s
        .quality
        .reason
        .as_deref()
        .map(json_str)
        .unwrap_or_else(|| "null".into());
    format!("\"quality\":\"{code}\",\"reason\":{reason}")
}

/// Watches `tag` for `window` after a confirmed write: how many times it
/// showed another value, or an older timestamp, than the confirmed sample.
async fn watch_for_rollbacks(db: &TagDb, tag: &str, confirmed: &Sample, window: Duration) -> u64 {
    let start = Instant::now();
    let mut rollbacks = 0;
    let mut last_bad = false;
    while start.elapsed() < window {
        if let Some(now) = db.get_by_name(tag) {
            // A newer sample of the same value (the next scans) is fine.
            let bad = now.value != confirmed.value || now.timestamp < confirmed.timestamp;
            if bad && !last_bad {
                rollbacks += 1;
            }
            last_bad = bad;
        }
        tokio::time::sleep(Duration::from_millis(2)).await;
    }
    rollbacks
}

fn main() -> ExitCode {
    let args = match parse_args(std::env::args().skip(1)) {
        Ok(a) => a,
        Err(e) => {
            eprintln!("{e}");
            return ExitCode::from(2);
        }
    };
    let plant = match gridscada_config::load_path(&args.config) {
        Ok(p) => p,
        Err(diags) => {
            eprintln!("{}: configuration has errors:", args.config.display());
            for d in diags {
                eprintln!("  {d:?}");
            }
            return ExitCode::from(2);
        }
    };
    let metas: Vec<_> = plant
        .tag_metas()
        .chain(gridscada_field::device_status_tags(&plant))
        .collect();
    let db = match TagDb::new(metas) {
        Ok(db) => Arc::new(db),
        Err(e) => {
            eprintln!("tag database: {e}");
            return ExitCode::from(2);
        }
    };
    let rt = match tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
    {
        Ok(rt) => rt,
        Err(e) => {
            eprintln!("tokio runtime: {e}");
            return ExitCode::from(2);
        }
    };
    let plant_tags: Vec<String> = plant
        .tags
        .iter()
        .map(|t| t.name.get_ref().clone())
        .collect();
    let ok = rt.block_on(async move {
        let io = match FieldIo::start(&plant, Arc::clone(&db), Arc::new(SystemClock)) {
            Ok(io) => io,
            Err(e) => {
                eprintln!("field I/O: {e}");
                return None;
            }
        };
        let good = |name: &str| db.get_by_name(name).is_some_and(|s| s.quality.is_good());
        let t0 = Instant::now();
        while !plant_tags.iter().all(|n| good(n)) && t0.elapsed() < args.wait {
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
        let mut all_ok = plant_tags.iter().all(|n| good(n));
        let writer = io.writer();
        for (tag, value) in &args.writes {
            // The writer has its own timeouts; this only bounds the probe.
            let r = tokio::time::timeout(Duration::from_secs(15), writer.write(tag, value.clone()))
                .await;
            let line = match r {
                Ok(Ok(s)) => {
                    let rollbacks = watch_for_rollbacks(&db, tag, &s, args.watch).await;
                    format!(
                        "{{\"write\":{},\"ok\":true,{},{},\"rollbacks\":{rollbacks}}}",
                        json_str(tag),
                        json_value(&s.value),
                        json_quality(&s)
                    )
                }
                Ok(Err(e)) => {
                    all_ok = false;
                    format!(
                        "{{\"write\":{},\"ok\":false,\"error\":{}}}",
                        json_str(tag),
                        json_str(&e.to_string())
                    )
                }
                Err(_) => {
                    all_ok = false;
                    format!(
                        "{{\"write\":{},\"ok\":false,\"error\":\"no answer within 15 s\"}}",
                        json_str(tag)
                    )
                }
            };
            println!("{line}");
        }
        for (id, meta) in db.all_meta() {
            let line = match db.get(id) {
                Some(s) => format!(
                    "{{\"tag\":{},{},{}}}",
                    json_str(&meta.name),
                    json_value(&s.value),
                    json_quality(&s)
                ),
                None => format!(
                    "{{\"tag\":{},\"value\":null,\"quality\":\"bad\",\"reason\":\"no sample\"}}",
                    json_str(&meta.name)
                ),
            };
            println!("{line}");
        }
        io.shutdown().await;
        Some(all_ok)
    });
    match ok {
        Some(true) => ExitCode::SUCCESS,
        Some(false) => ExitCode::from(1),
        None => ExitCode::from(2),
    }
}
