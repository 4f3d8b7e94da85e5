//! Poller benchmarks: prints a table.
//!
//! `cargo run --release -p gridscada-modbus --example bench`
//!
//! 1. One connection: requests/s and registers/s through the full poller
//!    (planning, framing, decoding, TagDb batches) against an in-process
//!    tokio-modbus server on loopback, with the link saturated. Then, in the
//!    same run and against the same server, the peers in `bench/`: pymodbus's
//!    async client (`bench/pymodbus_client.py`, Python from `BENCH_PYTHON`,
//!    else `target/test-venv/bin/python`, else `python3`) and a C client on
//!    libmodbus (`bench/libmodbus_client.c`, compiled here with `cc` and
//!    `pkg-config libmodbus`). A missing peer is skipped with a note.
//! 2. Scale: 100,000 tags on 50 devices (one TCP server each, in a child
//!    process so its CPU is not counted) scanned every second: the poller's
//!    CPU share, resident memory and late scans.
//!
//! Loopback only; every loop is bounded in time.

#[path = "../tests/it/common/mod.rs"]
mod common;

use std::io::{BufRead, BufReader, Read, Write};
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::Arc;
use std::time::{Duration, Instant};

use common::*;
use gridscada_modbus::FieldIo;
use gridscada_tagdb::SystemClock;

const SCALE_DEVICES: usize = 50;
/// Blocks of the one-connection device (130 registers apart, so 500 fit in 65,536).
const SINGLE_BLOCKS: u32 = 500;
const TAGS_PER_DEVICE: usize = 2000;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .expect("runtime");
    if args.get(1).map(String::as_str) == Some("serve") {
        let n: usize = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(1);
        rt.block_on(serve_devices(n));
        return;
    }
    let secs: u64 = std::env::var("BENCH_SECS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(5);
    let one = rt.block_on(single_connection(Duration::from_secs(secs)));
    let scale = rt.block_on(scale(Duration::from_secs(secs * 2)));
    println!();
    println!("One connection, sequential 125-register reads (function 03), loopback, same server:");
    println!();
    println!("| client | requests/s | registers/s | mean round trip | requests/s vs gridscada |");
    println!("|---|---|---|---|---|");
    let ours = one.ours.req_s;
    for r in std::iter::once(&one.ours).chain(&one.peers) {
        println!(
            "| {} | {:.0} | {:.0} | {:.3} ms | {:.2}× |",
            r.client,
            r.req_s,
            r.req_s * 125.0,
            1000.0 / r.req_s.max(f64::MIN_POSITIVE),
            r.req_s / ours.max(f64::MIN_POSITIVE),
        );
    }
    for note in &one.notes {
        println!("note: {note}");
    }
    println!();
    println!("| benchmark | figure |");
    println!("|---|---|");
    println!(
        "| scale: tags / devices / scan | {} / {SCALE_DEVICES} / 1 s |",
        SCALE_DEVICES * TAGS_PER_DEVICE
    );
    println!(
        "| scale: poller CPU share (of one core) | {:.1} % |",
        scale.cpu_share * 100.0
    );
    println!("| scale: resident memory | {:.1} MiB |", scale.rss_mib);
    println!(
        "| scale: scans / late scans / overruns | {} / {} / {} |",
        scale.scans, scale.late, scale.overruns
    );
    println!(
        "| scale: requests / errors | {} / {} |",
        scale.requests, scale.errors
    );
}

/// Child process: one server per device, addresses printed one a line.
async fn serve_devices(n: usize) {
    let mut handles = Vec::new();
    let mut out = std::io::stdout();
    for _ in 0..n {
        let bank = Bank::with_units(&[1]);
        bank.unit(1, |u| {
            for (i, r) in u.input.iter_mut().enumerate().take(4096) {
                *r = i as u16;
            }
        });
        let (addr, h) = serve(bank, "127.0.0.1:0").await;
        writeln!(out, "{addr}").unwrap();
        handles.push(h);
    }
    out.flush().unwrap();
    // Until the parent closes our stdin.
    let _ = tokio::task::spawn_blocking(|| {
        let mut s = String::new();
        let _ = std::io::stdin().read_line(&mut s);
    })
    .await;
}

/// One client's figures on the shared server.
struct ClientRate {
    client: String,
    req_s: f64,
}

struct OneConnection {
    ours: ClientRate,
    peers: Vec<ClientRate>,
    /// Peers skipped or failed, and why.
    notes: Vec<String>,
}

async fn single_connection(run: Duration) -> OneConnection {
    let bank = Bank::with_units(&[1]);
    let (addr, _server) = serve(Arc::clone(&bank), "127.0.0.1:0").await;
    // 500 blocks of 125 registers (gaps beyond max_gap) scanned every 10 ms:
    // 50,000 requests/s asked for, more than the link can carry, so it runs
    // flat out (a scan that runs over starts the next at once; the overrun
    // count below shows it did). Fewer blocks would measure the scan period.
    let mut text =
        device("D", addr, 1, 10, 1000).replace("retries = 1", "retries = 1\nmax_gap = 0");
    for b in 0..SINGLE_BLOCKS {
        for r in 0..125u32 {
            let a = b * 130 + r;
            text += &format!(
                "[[tag]]\nname = \"D.R{a}\"\ndevice = \"D\"\nkind = \"holding_register\"\naddress = {a}\n"
            );
        }
    }
    let plant = plant(&text);
    let db = tagdb(&plant);
    let io = FieldIo::start(&plant, db, Arc::new(SystemClock)).expect("start");
    tokio::time::sleep(Duration::from_millis(500)).await;
    let before = io.stats().total();
    let t0 = Instant::now();
    tokio::time::sleep(run).await;
    let after = io.stats().total();
    let secs = t0.elapsed().as_secs_f64();
    io.shutdown().await;
    let reqs = (after.requests - before.requests) as f64;
    let ours = ClientRate {
        client: "gridscada poller (Rust, full scan path)".into(),
        req_s: reqs / secs,
    };
    // The peers run as child processes against the same server, which keeps
    // serving on this runtime; waiting for them happens off the runtime.
    let (peers, mut notes) = tokio::task::spawn_blocking(move || run_peers(addr, run))
        .await
        .expect("peer runner");
    let (scans, overruns) = (after.scans - before.scans, after.overruns - before.overruns);
    if overruns == 0 {
        notes.push(format!(
            "gridscada poller: no scan overran ({scans} scans), so its figure is the scan rate, not the link's limit"
        ));
    }
    if after.errors > before.errors {
        notes.push(format!(
            "gridscada poller: {} requests failed during the run",
            after.errors - before.errors
        ));
    }
    OneConnection { ours, peers, notes }
}

fn bench_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("bench")
}

/// Runs every peer client in turn; a peer that cannot run is a note, not a
/// failure of the benchmark.
fn run_peers(addr: SocketAddr, run: Duration) -> (Vec<ClientRate>, Vec<String>) {
    let mut rates = Vec::new();
    let mut notes = Vec::new();
    let host = addr.ip().to_string();
    let port = addr.port().to_string();
    let secs = format!("{}", run.as_secs_f64());
    let args = [host.as_str(), port.as_str(), "1", secs.as_str()];

    // pymodbus's async client.
    let python = python_with_pymodbus();
    match python {
        Ok(py) => {
            let script = bench_dir().join("pymodbus_client.py");
            let mut cmd = Command::new(&py);
            cmd.arg(&script).args(args);
            match run_peer(cmd, run) {
                Ok(r) => rates.push(r),
                Err(e) => notes.push(format!("pymodbus peer failed: {e}")),
            }
        }
        Err(e) => notes.push(format!("pymodbus peer skipped: {e}")),
    }

    // libmodbus, compiled here.
    match build_libmodbus_client() {
        Ok(exe) => {
            let mut cmd = Command::new(&exe);
            cmd.args(args);
            match run_peer(cmd, run) {
                Ok(r) => rates.push(r),
                Err(e) => notes.push(format!("libmodbus peer failed: {e}")),
            }
            let _ = std::fs::remove_file(&exe);
        }
        Err(e) => notes.push(format!("libmodbus peer skipped: {e}")),
    }
    (rates, notes)
}

/// The first Python that can import pymodbus: BENCH_PYTHON, the test venv
/// of scripts/test-all.sh, then python3 on PATH.
fn python_with_pymodbus() -> Result<PathBuf, String> {
    let mut candidates: Vec<PathBuf> = Vec::new();
    if let Some(p) = std::env::var_os("BENCH_PYTHON") {
        candidates.push(p.into());
    }
    let workspace = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    candidates.push(workspace.join("target/test-venv/bin/python"));
    candidates.push("python3".into());
    let mut tried = Vec::new();
    for py in candidates {
        let ok = Command::new(&py)
            .args(["-c", "import pymodbus"])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .status()
            .is_ok_and(|s| s.success());
        if ok {
            return Ok(py);
        }
        tried.push(py.display().to_string());
    }
    Err(format!(
        "no Python with pymodbus (tried {}); pip install -r tests/requirements.txt, or set BENCH_PYTHON",
        tried.join(", ")
    ))
}

/// Compiles bench/libmodbus_client.c into the temp folder.
fn build_libmodbus_client() -> Result<PathBuf, String> {
    let flags = Command::new("pkg-config")
        .args(["--cflags", "--libs", "libmodbus"])
        .output()
        .map_err(|e| {
            format!("pkg-config not runnable ({e}); apt-get install pkg-config libmodbus-dev")
        })?;
    if !flags.status.success() {
        return Err("pkg-config knows no libmodbus; apt-get install libmodbus-dev".into());
    }
    let flags = String::from_utf8_lossy(&flags.stdout).to_string();
    let exe =
        std::env::temp_dir().join(format!("gridscada-bench-libmodbus-{}", std::process::id()));
    let out = Command::new("cc")
        .arg("-O2")
        .arg("-o")
        .arg(&exe)
        .arg(bench_dir().join("libmodbus_client.c"))
        .args(flags.split_whitespace())
        .output()
        .map_err(|e| format!("cc not runnable ({e})"))?;
    if !out.status.success() {
        return Err(format!(
            "cc failed: {}",
            String::from_utf8_lossy(&out.stderr).trim()
        ));
    }
    Ok(exe)
}

/// Runs one peer (bounded: killed if it overruns its time by 30 s) and reads
/// its JSON line.
fn run_peer(mut cmd: Command, run: Duration) -> Result<ClientRate, String> {
    let mut child = cmd
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| format!("cannot start {cmd:?}: {e}"))?;
    let limit = Instant::now() + run + Duration::from_secs(30);
    let status = loop {
        match child.try_wait() {
            Ok(Some(s)) => break s,
            Ok(None) if Instant::now() > limit => {
                let _ = child.kill();
                let _ = child.wait();
                return Err("no result within its time + 30 s; killed".into());
            }
            Ok(None) => std::thread::sleep(Duration::from_millis(50)),
            Err(e) => return Err(format!("waiting: {e}")),
        }
    };
    let mut stdout = String::new();
    let mut stderr = String::new();
    if let Some(mut o) = child.stdout.take() {
        let _ = o.read_to_string(&mut stdout);
    }
    if let Some(mut e) = child.stderr.take() {
        let _ = e.read_to_string(&mut stderr);
    }
    if !status.success() {
        return Err(format!("exit {status}: {}", stderr.trim()));
    }
    let line = stdout.lines().last().unwrap_or("");
    let client = json_field(line, "client")
        .map(|c| c.trim_matches('"').to_string())
        .ok_or_else(|| format!("no \"client\" in its output {line:?}"))?;
    let req_s = json_field(line, "requests_per_s")
        .and_then(|v| v.parse::<f64>().ok())
        .filter(|v| v.is_finite() && *v > 0.0)
        .ok_or_else(|| format!("no requests_per_s in its output {line:?}"))?;
    Ok(ClientRate { client, req_s })
}

/// The raw text of a top-level field of a flat one-line JSON object whose
/// string values hold no commas (all the peers print).
fn json_field<'a>(line: &'a str, key: &str) -> Option<&'a str> {
    let body = line.trim().strip_prefix('{')?.strip_suffix('}')?;
    body.split(',').find_map(|kv| {
        let (k, v) = kv.split_once(':')?;
        (k.trim().trim_matches('"') == key).then_some(v.trim())
    })
}

struct Scale {
    cpu_share: f64,
    rss_mib: f64,
    scans: u64,
    late: u64,
    overruns: u64,
    requests: u64,
    errors: u64,
}

async fn scale(run: Duration) -> Scale {
    let exe = std::env::current_exe().expect("exe");
    let mut child = Command::new(exe)
        .args(["serve", &SCALE_DEVICES.to_string()])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .expect("server process");
    let mut lines = BufReader::new(child.stdout.take().unwrap()).lines();
    let addrs: Vec<String> = (0..SCALE_DEVICES)
        .map(|_| lines.next().expect("address").expect("address"))
        .collect();
    // Each device: 1000 u16 and 500 f32 input registers = 2000 registers, 1500
    // tags... topped up with 500 bits of packed status words = 2000 tags.
    let mut text = String::new();
    for (d, addr) in addrs.iter().enumerate() {
        text += &device(&format!("P{d}"), addr.parse().unwrap(), 1, 1000, 1000);
        for i in 0..1000 {
            text += &format!("[[tag]]\nname = \"P{d}.U{i}\"\ndevice = \"P{d}\"\nkind = \"input_register\"\naddress = {i}\n");
        }
        for i in 0..500 {
            let a = 1000 + 2 * i;
            text += &format!("[[tag]]\nname = \"P{d}.F{i}\"\ndevice = \"P{d}\"\nkind = \"input_register\"\naddress = {a}\ntype = \"f32\"\n");
        }
        for i in 0..500 {
            let a = 2000 + i / 16;
            let bit = i % 16;
            text += &format!("[[tag]]\nname = \"P{d}.S{i}\"\ndevice = \"P{d}\"\nkind = \"input_register\"\naddress = {a}\nbit = {bit}\n");
        }
    }
    let plant = plant(&text);
    assert_eq!(plant.tags.len(), SCALE_DEVICES * TAGS_PER_DEVICE);
    let db = tagdb(&plant);
    let io = FieldIo::start(&plant, db, Arc::new(SystemClock)).expect("start");
    tokio::time::sleep(Duration::from_secs(2)).await;
    let before = io.stats().total();
    let cpu0 = cpu_seconds();
    let t0 = Instant::now();
    tokio::time::sleep(run).await;
    let cpu = cpu_seconds() - cpu0;
    let wall = t0.elapsed().as_secs_f64();
    let after = io.stats().total();
    let rss = rss_mib();
    io.shutdown().await;
    drop(child.stdin.take());
    let _ = child.kill();
    let _ = child.wait();
    Scale {
        cpu_share: cpu / wall,
        rss_mib: rss,
        scans: after.scans - before.scans,
        late: after.late_scans - before.late_scans,
        overruns: after.overruns - before.overruns,
        requests: after.requests - before.requests,
        errors: after.errors - before.errors,
    }
}

/// User + system CPU of this process, from /proc/self/stat (Linux).
fn cpu_seconds() -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    // Fields after the command name, which is in parentheses.
    let rest = stat.rsplit_once(')').map(|(_, r)| r).unwrap_or("");
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks = |i: usize| f.get(i).and_then(|s| s.parse::<f64>().ok()).unwrap_or(0.0);
    // utime and stime are fields 14 and 15 (1-based), i.e. 11 and 12 here.
    (ticks(11) + ticks(12)) / 100.0
}

fn rss_mib() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .unwrap_or_default()
        .lines()
        .find(|l| l.starts_with("VmRSS:"))
        .and_then(|l| l.split_whitespace().nth(1)?.parse::<f64>().ok())
        .map(|kb| kb / 1024.0)
        .unwrap_or(0.0)
}
