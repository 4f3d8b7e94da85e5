//! Peak memory under a burst of simultaneous wrong-password checks: the
//! server's capped pool (`auth::PasswordPool`, one thread per core, reused
//! Argon2 memory, a bounded queue) against the peer, the uncapped way the
//! server used to do it (`spawn_blocking` per login, Argon2 allocating its
//! 19 MiB per check). Each runs in a fresh child process, so each peak is
//! its own.
//!
//! `cargo run --release -p gridscada-web --example login_burst` (BURST sets
//! the number of simultaneous checks, default 200).

use std::process::Command;
use std::sync::Arc;
use std::time::Instant;

use argon2::password_hash::{PasswordHash, PasswordVerifier};
use argon2::Argon2;
use gridscada_web::auth::{hash_password, PasswordPool};

fn peak_rss_mib() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmHWM:"))
                .and_then(|l| l.split_whitespace().nth(1)?.parse::<f64>().ok())
        })
        .map_or(f64::NAN, |kib| kib / 1024.0)
}

fn burst() -> usize {
    std::env::var("BURST")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(200)
}

async fn child(mode: &str) {
    let hash = hash_password("the right password".into()).await.unwrap();
    let before = peak_rss_mib();
    let started = Instant::now();
    let n = burst();
    let (mut judged, mut busy) = (0, 0);
    if mode == "capped" {
        let pool = Arc::new(PasswordPool::per_core());
        let tasks: Vec<_> = (0..n)
            .map(|_| {
                let (p, h) = (pool.clone(), hash.clone());
                tokio::spawn(async move { p.verify("wrong".into(), h).await })
            })
            .collect();
        for t in tasks {
            match t.await.unwrap() {
                Ok(_) => judged += 1,
                Err(_) => busy += 1,
            }
        }
    } else {
        let tasks: Vec<_> = (0..n)
            .map(|_| {
                let h = hash.clone();
                tokio::task::spawn_blocking(move || {
                    let parsed = PasswordHash::new(&h).unwrap();
                    Argon2::default().verify_password(b"wrong", &parsed).is_ok()
                })
            })
            .collect();
        for t in tasks {
            t.await.unwrap();
            judged += 1;
        }
    }
    println!(
        "{mode}\t{judged}\t{busy}\t{:.0}\t{:.0}\t{:.2}",
        before,
        peak_rss_mib(),
        started.elapsed().as_secs_f64()
    );
}

#[tokio::main(flavor = "multi_thread", worker_threads = 2)]
async fn main() {
    if let Some(mode) = std::env::args().nth(1) {
        child(&mode).await;
        return;
    }
    let me = std::env::current_exe().unwrap();
    println!(
        "{} simultaneous wrong-password checks, Argon2id m=19 MiB, {} cores",
        burst(),
        std::thread::available_parallelism().map_or(1, |n| n.get())
    );
    println!("| way | checked | told busy | peak RSS before | peak RSS after | growth | time |");
    println!("|---|---|---|---|---|---|---|");
    for mode in ["capped", "uncapped"] {
        let out = Command::new(&me).arg(mode).output().unwrap();
        let line = String::from_utf8_lossy(&out.stdout);
        let f: Vec<&str> = line.trim().split('\t').collect();
        if f.len() < 6 {
            println!(
                "| {mode} | failed: {} |",
                String::from_utf8_lossy(&out.stderr)
            );
            continue;
        }
        let (b, a): (f64, f64) = (f[3].parse().unwrap(), f[4].parse().unwrap());
        let name = if mode == "capped" {
            "gridscada (pool per core, reused memory)"
        } else {
            "peer: spawn_blocking per login"
        };
        println!(
            "| {name} | {} | {} | {b:.0} MiB | {a:.0} MiB | +{:.0} MiB | {} s |",
            f[1],
            f[2],
            a - b,
            f[5]
        );
    }
}
