//! Poller benchmarks: prints a table.
//!
//! `cargo run --release -p gridscada-modbus --example bench`
//!
//! 1. One connection: requests/s and registers/s through the full poller
//!    (planning, framing, decoding, TagDb batches) against an in-process
//!    tokio-modbus server on loopback, with the link saturated.
//! 2. Scale: 100,000 tags on 50 devices (one TCP server each, in a child
//!    process so its CPU is not counted) scanned every second: the poller's
//!    CPU share, resident memory and late scans.
//!
//! Loopback only; every loop is bounded in time.

#[path = "../tests/common/mod.rs"]
mod common;

use std::io::{BufRead, BufReader, Write};
use std::process::{Command, Stdio};
use std::sync::Arc;
use std::time::{Duration, Instant};

use common::*;
use gridscada_modbus::FieldIo;
use gridscada_tagdb::SystemClock;

const SCALE_DEVICES: usize = 50;
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
    let (req_s, reg_s, rtt) = rt.block_on(single_connection(Duration::from_secs(secs)));
    let scale = rt.block_on(scale(Duration::from_secs(secs * 2)));
    println!();
    println!("| benchmark | figure |");
    println!("|---|---|");
    println!("| one connection, requests/s (125-register reads) | {req_s:.0} |");
    println!("| one connection, registers/s | {reg_s:.0} |");
    println!("| one connection, mean round trip | {rtt:.3} ms |");
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

async fn single_connection(run: Duration) -> (f64, f64, f64) {
    let bank = Bank::with_units(&[1]);
    let (addr, _server) = serve(Arc::clone(&bank), "127.0.0.1:0").await;
    // 40 blocks of 125 registers (gaps beyond max_gap), scanned every 10 ms:
    // the link never catches up, so it runs flat out.
    let mut text =
        device("D", addr, 1, 10, 1000).replace("retries = 1", "retries = 1\nmax_gap = 0");
    for b in 0..40u32 {
        for r in 0..125u32 {
            let a = b * 200 + r;
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
    (
        reqs / secs,
        reqs * 125.0 / secs,
        secs * 1000.0 / reqs.max(1.0),
    )
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
