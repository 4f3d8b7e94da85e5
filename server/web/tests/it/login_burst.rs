//! A burst of 200 simultaneous wrong-password logins, each from its own
//! address and name (so throttling does not stop them): the password work is
//! capped (auth::PasswordPool), so the process's peak memory grows by a few
//! hashes' worth, not by one 19 MiB Argon2 buffer per request. Alone in its
//! test binary so the peak RSS is this burst's own. The figures, against the
//! uncapped way, are in docs/BENCHMARKS.md (`cargo run --release -p
//! gridscada-web --example login_burst`).

use crate::common;

use std::sync::Arc;

use axum::http::{Method, StatusCode};
use common::*;
use serde_json::json;

/// Peak resident set size of this process so far, in MiB (Linux).
fn peak_rss_mib() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib / 1024.0)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_login_burst_stays_within_bounded_memory() {
    let h = Arc::new(Harness::new(Options::default()).await);
    let Some(before) = peak_rss_mib() else {
        eprintln!("no /proc/self/status: peak RSS not measured");
        return;
    };
    let tries: Vec<_> = (0..200u32)
        .map(|i| {
            let h = h.clone();
            tokio::spawn(async move {
                let req = request(
                    Method::POST,
                    "/api/session",
                    None,
                    Some(json!({"username": format!("user-{i}"), "password": "wrong password!"})),
                );
                let peer =
                    std::net::SocketAddr::from(([10, 7, (i / 250) as u8, (i % 250) as u8], 5000));
                h.send_from(req, peer).await.status
            })
        })
        .collect();
    let mut refused = 0;
    let mut busy = 0;
    for t in tries {
        match t.await.unwrap() {
            StatusCode::UNAUTHORIZED => refused += 1,
            StatusCode::TOO_MANY_REQUESTS => busy += 1,
            other => panic!("unexpected {other}"),
        }
    }
    let after = peak_rss_mib().unwrap();
    let grown = after - before;
    eprintln!(
        "login burst: {refused} judged, {busy} told busy; peak RSS {before:.0} -> {after:.0} MiB (+{grown:.0})"
    );
    assert_eq!(refused + busy, 200);
    assert!(refused >= 32, "the queue takes a burst: {refused} judged");
    // Four threads at most, 19 MiB of reused Argon2 memory each, plus slack
    // (uncapped, the same burst took the server past 3 GB).
    assert!(grown < 100.0, "peak RSS grew by {grown:.0} MiB");
    // And the server still answers a real login afterwards.
    let r = h
        .call(
            Method::POST,
            "/api/session",
            None,
            Some(json!({"username": "operator", "password": PASSWORD})),
        )
        .await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text());
}
