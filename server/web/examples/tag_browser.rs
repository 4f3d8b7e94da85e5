//! Bench: the tag browser's requests on a plant of 100,000 tags, through the
//! whole router (authorization, read access, JSON), against the peer: the
//! one request the HMI made before (every tag in one answer, as
//! `GET /api/tags` without paging still gives).
//!
//! Run: `cargo run --release -p gridscada-web --example tag_browser -- [TAGS] [ROUNDS]`
//! (defaults 100000 30).

mod bench_state;

use std::time::Instant;

use axum::body::Body;
use axum::http::{header, Request};
use gridscada_tagdb::{Sample, TagDb, TagMeta, Timestamp, ValueKind};
use http_body_util::BodyExt;
use tower::ServiceExt;

#[tokio::main(flavor = "multi_thread", worker_threads = 2)]
async fn main() {
    let mut args = std::env::args()
        .skip(1)
        .map(|a| a.parse::<usize>().expect("arguments: TAGS ROUNDS"));
    let n = args.next().unwrap_or(100_000);
    let rounds = args.next().unwrap_or(30);
    // 10 sites x 100 devices x N/1000 tags: SITE3.DEV042.T0017.
    let per_dev = (n / 1000).max(1);
    let metas: Vec<TagMeta> = (0..n)
        .map(|i| {
            let (site, dev, t) = (i / (100 * per_dev), (i / per_dev) % 100, i % per_dev);
            TagMeta::new(format!("SITE{site}.DEV{dev:03}.T{t:04}"), ValueKind::Float)
                .units("kW")
                .describe(format!("Feeder {dev} measurement {t}"))
        })
        .collect();
    let db = std::sync::Arc::new(TagDb::new(metas).expect("tag db"));
    let now = Timestamp::now_utc();
    let ids: Vec<_> = db.all_meta().map(|(id, _)| id).collect();
    db.apply(ids.iter().map(|id| (*id, Sample::good(1.5, now))));
    let dir = tempfile::tempdir().unwrap();
    let (state, cookie) = bench_state::web_state(db, dir.path()).await;
    let app = gridscada_web::router(state);

    let call =
        |path: String| {
            let app = app.clone();
            let cookie = cookie.clone();
            async move {
                let mut req = Request::get(&path)
                    .header(header::HOST, "127.0.0.1")
                    .header(header::COOKIE, cookie)
                    .body(Body::empty())
                    .unwrap();
                req.extensions_mut().insert(axum::extract::ConnectInfo(
                    std::net::SocketAddr::from(([127, 0, 0, 1], 4000)),
                ));
                let started = Instant::now();
                let resp = app.oneshot(req).await.unwrap();
                assert!(resp.status().is_success(), "{path}: {}", resp.status());
                let bytes = resp.into_body().collect().await.unwrap().to_bytes().len();
                (started.elapsed().as_secs_f64() * 1000.0, bytes)
            }
        };
    let cases: Vec<(&str, String)> = vec![
        (
            "search, first page of 200",
            "/api/tags?search=measurement%2017&limit=200".into(),
        ),
        (
            "search with no match",
            "/api/tags?search=nothing-like-this&limit=200".into(),
        ),
        (
            "a branch, page 26 of 200",
            "/api/tags?prefix=SITE3.&offset=5000&limit=200".into(),
        ),
        ("tree: the roots", "/api/tags/tree?prefix=".into()),
        (
            "tree: one site's devices",
            "/api/tags/tree?prefix=SITE3.".into(),
        ),
        (
            "one tag",
            format!("/api/tags/SITE3.DEV042.T{:04}", per_dev / 2),
        ),
        ("peer: every tag in one answer", "/api/tags".into()),
    ];
    println!("{n} tags, {rounds} rounds each, release build, in-process router (2 worker threads)");
    println!("| request | p50 ms | p99 ms | bytes |");
    println!("|---|---|---|---|");
    for (what, path) in cases {
        let mut times = vec![];
        let mut size = 0;
        for _ in 0..rounds {
            let (ms, bytes) = call(path.clone()).await;
            times.push(ms);
            size = bytes;
        }
        times.sort_by(f64::total_cmp);
        let q =
            |p: f64| times[((times.len() as f64 * p).ceil() as usize).clamp(1, times.len()) - 1];
        println!("| {what} | {:.2} | {:.2} | {size} |", q(0.5), q(0.99));
    }
}
