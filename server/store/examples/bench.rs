//! Historian benchmark: ingest rate through the writer task vs. a plain
//! batched INSERT and (PostgreSQL) a plain COPY into the same table, and the
//! time of a 500-point trend of 10 tags over a day of 1 s data (864,000
//! rows) and over a year of 5 min data (1,051,200 rows).
//!
//! cargo run --release -p gridscada-store --example bench [-- INGEST_SAMPLES [ROUNDS]]
//! PostgreSQL runs too when GRIDSCADA_TEST_PG_URL is set (in a throwaway schema).
//!
//! The writer and its peers are timed ROUNDS times (default 5), alternating
//! which goes first, each round into fresh tags; the table gives the median
//! of the rounds and the median of the per-round ratios, so one hiccup of a
//! shared machine does not decide the comparison.

use std::sync::Arc;
use std::time::{Duration, Instant};

use gridscada_store::{Historian, HistorianConfig, HistorySample, OpenOptions, Store};
use gridscada_tagdb::{QualityCode, Timestamp};
use sqlx::{Connection, QueryBuilder};

const DAY_S: i64 = 86_400;

fn samples(prefix: &str, n: usize, tags: usize, t0: i64, step_ms: i64) -> Vec<HistorySample> {
    let names: Vec<Arc<str>> = (0..tags)
        .map(|k| Arc::from(format!("{prefix}.{k}")))
        .collect();
    (0..n)
        .map(|i| HistorySample {
            tag: names[i % tags].clone(),
            ts: Timestamp::from_millis(t0 + (i / tags) as i64 * step_ms),
            value: Some((i as f64 * 0.001).sin() * 230.0),
            exact: None,
            quality: QualityCode::Good,
        })
        .collect()
}

enum Raw {
    Sqlite(sqlx::SqliteConnection),
    Pg(sqlx::PgConnection),
}

/// The baseline: multi-row INSERTs of 1,000 rows, 5,000 rows per transaction,
/// straight into the samples table with known tag ids; no buffering or tag
/// lookup.
async fn plain_insert(raw: &mut Raw, n: usize, round: usize) -> Duration {
    let rows: Vec<(i64, i64, f64)> = (0..n)
        .map(|i| {
            (
                1_000_000 + (round * 10 + i % 10) as i64,
                (i / 10) as i64 * 1000,
                i as f64,
            )
        })
        .collect();
    let started = Instant::now();
    macro_rules! go {
        ($c:expr) => {
            for tx_rows in rows.chunks(5_000) {
                let mut tx = $c.begin().await.unwrap();
                for chunk in tx_rows.chunks(1_000) {
                    let mut qb =
                        QueryBuilder::new("INSERT INTO samples (tag_id, ts, value, quality) ");
                    qb.push_values(chunk, |mut b, r| {
                        b.push_bind(r.0)
                            .push_bind(r.1)
                            .push_bind(r.2)
                            .push_bind(0i32);
                    });
                    qb.build().execute(&mut *tx).await.unwrap();
                }
                tx.commit().await.unwrap();
            }
        };
    }
    match raw {
        Raw::Sqlite(c) => go!(c),
        Raw::Pg(c) => go!(c),
    }
    started.elapsed()
}

/// The peer on PostgreSQL: COPY in text format straight into the samples
/// table with known tag ids, 5,000 rows per transaction (the writer's batch),
/// nothing else.
async fn plain_copy(c: &mut sqlx::PgConnection, n: usize, round: usize) -> Duration {
    use std::fmt::Write;
    let started = Instant::now();
    for chunk in (0..n).collect::<Vec<_>>().chunks(5_000) {
        let mut text = String::with_capacity(chunk.len() * 40);
        for &i in chunk {
            let v = (i as f64 * 0.001).sin() * 230.0;
            let _ = writeln!(
                text,
                "{}\t{}\t{v}\t\\N\t0",
                2_000_000 + (round * 10 + i % 10) as i64,
                (i / 10) as i64 * 1000
            );
        }
        let mut tx = c.begin().await.unwrap();
        let mut copy = tx
            .copy_in_raw("COPY samples (tag_id, ts, value, exact, quality) FROM STDIN")
            .await
            .unwrap();
        copy.send(text.as_bytes()).await.unwrap();
        copy.finish().await.unwrap();
        tx.commit().await.unwrap();
    }
    started.elapsed()
}

async fn through_writer(store: &Store, n: usize, round: usize) -> Duration {
    let data = samples(&format!("bench.w{round}"), n, 10, 0, 1000);
    let hist = Historian::spawn(
        store.clone(),
        HistorianConfig {
            capacity: 100_000,
            ..Default::default()
        },
    );
    let h = hist.handle();
    let started = Instant::now();
    for s in data {
        // Producer faster than any disk: back off instead of overflowing, so
        // the figure is the writer's throughput, not the drop rate.
        while h.metrics().buffered >= 99_000 {
            tokio::time::sleep(Duration::from_millis(1)).await;
        }
        h.push(s);
    }
    let m = hist.shutdown().await;
    assert_eq!(m.dropped, 0);
    assert_eq!(m.samples_written, n as u64);
    started.elapsed()
}

struct Row {
    backend: &'static str,
    /// Medians over the rounds, samples/s.
    writer: f64,
    plain: f64,
    copy: Option<f64>,
    /// Median of the rounds' writer / COPY.
    ratio: Option<f64>,
    /// Every round's writer / COPY, as run.
    ratios: Vec<f64>,
    load: f64,
    trend_ms: Vec<f64>,
    year_load: f64,
    year_ms: Vec<f64>,
}

/// Five timed 500-point trends of `tags` over `from..from + span_ms`, sorted;
/// checks every sample is counted.
async fn trends(store: &Store, tags: &[&str], from: i64, span_ms: i64, rows: u64) -> Vec<f64> {
    let mut ms = Vec::new();
    for _ in 0..5 {
        let started = Instant::now();
        let t = store
            .trend(
                tags,
                Timestamp::from_millis(from),
                Timestamp::from_millis(from + span_ms),
                500,
            )
            .await
            .unwrap();
        ms.push(started.elapsed().as_secs_f64() * 1000.0);
        assert_eq!(
            t.iter()
                .map(|t| t.buckets.iter().map(|b| b.count).sum::<u64>())
                .sum::<u64>(),
            rows
        );
    }
    ms.sort_by(f64::total_cmp);
    ms
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

async fn run(
    backend: &'static str,
    url: &str,
    options: OpenOptions,
    raw: Raw,
    n: usize,
    rounds: usize,
) -> Row {
    let store = Store::open(url, &options).await.expect("open");
    let mut raw = raw;
    let rate = |d: Duration| n as f64 / d.as_secs_f64();
    let (mut writer, mut plain, mut copy, mut ratios) = (vec![], vec![], vec![], vec![]);
    for round in 0..rounds {
        // Alternate the order, so a table growing round by round (or load
        // drifting) favours neither side.
        let peers_first = round % 2 == 0;
        if !peers_first {
            writer.push(rate(through_writer(&store, n, round).await));
        }
        plain.push(rate(plain_insert(&mut raw, n, round).await));
        if let Raw::Pg(c) = &mut raw {
            copy.push(rate(plain_copy(c, n, round).await));
        }
        if peers_first {
            writer.push(rate(through_writer(&store, n, round).await));
        }
        if let Some(&c) = copy.last() {
            ratios.push(writer[round] / c);
        }
        eprintln!(
            "{backend} round {round}: writer {:.0}/s, plain INSERT {:.0}/s{}",
            writer[round],
            plain[round],
            copy.last()
                .map(|c| format!(", COPY {c:.0}/s"))
                .unwrap_or_default()
        );
    }
    // A day of 1 s data for 10 tags; the day starts on a minute, so a
    // minute-aligned trend holds exactly the day.
    let t0 = 1_700_000_040_000;
    let day = samples("bench.day", 10 * DAY_S as usize, 10, t0, 1000);
    let started = Instant::now();
    for chunk in day.chunks(20_000) {
        store.insert_samples(chunk).await.unwrap();
    }
    let load = started.elapsed();
    drop(day);
    let tags: Vec<String> = (0..10).map(|k| format!("bench.day.{k}")).collect();
    let tag_refs: Vec<&str> = tags.iter().map(String::as_str).collect();
    let trend_ms = trends(&store, &tag_refs, t0, DAY_S * 1000, 864_000).await;
    // A year of 5 min data for 10 tags, starting on an hour.
    let y0 = 1_699_999_200_000;
    let per_tag = 365 * 288;
    let year = samples("bench.year", 10 * per_tag, 10, y0, 300_000);
    let started = Instant::now();
    for chunk in year.chunks(20_000) {
        store.insert_samples(chunk).await.unwrap();
    }
    let year_load = started.elapsed();
    drop(year);
    let tags: Vec<String> = (0..10).map(|k| format!("bench.year.{k}")).collect();
    let tag_refs: Vec<&str> = tags.iter().map(String::as_str).collect();
    let year_ms = trends(
        &store,
        &tag_refs,
        y0,
        365 * DAY_S * 1000,
        10 * per_tag as u64,
    )
    .await;
    store.close().await;
    Row {
        backend,
        writer: median(writer),
        plain: median(plain),
        copy: (!copy.is_empty()).then(|| median(copy)),
        ratio: (!ratios.is_empty()).then(|| median(ratios.clone())),
        ratios,
        load: 864_000.0 / load.as_secs_f64(),
        trend_ms,
        year_load: (10 * per_tag) as f64 / year_load.as_secs_f64(),
        year_ms,
    }
}

#[tokio::main]
async fn main() {
    let n: usize = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(200_000);
    let rounds: usize = std::env::args()
        .nth(2)
        .and_then(|a| a.parse().ok())
        .unwrap_or(5)
        .max(1);
    let mut rows = Vec::new();

    let dir = tempfile::tempdir().unwrap();
    let options = OpenOptions::new(dir.path());
    // Open once so the schema exists before the raw connection is made.
    Store::open("sqlite://bench.db", &options)
        .await
        .unwrap()
        .close()
        .await;
    let mut raw = sqlx::SqliteConnection::connect_with(
        &sqlx::sqlite::SqliteConnectOptions::new()
            .filename(dir.path().join("bench.db"))
            .journal_mode(sqlx::sqlite::SqliteJournalMode::Wal)
            .synchronous(sqlx::sqlite::SqliteSynchronous::Normal),
    )
    .await
    .unwrap();
    sqlx::query("SELECT 1").execute(&mut raw).await.unwrap();
    rows.push(
        run(
            "SQLite (WAL, sync=NORMAL)",
            "sqlite://bench.db",
            options,
            Raw::Sqlite(raw),
            n,
            rounds,
        )
        .await,
    );

    match std::env::var("GRIDSCADA_TEST_PG_URL") {
        Ok(url) => {
            let schema = format!("gs_bench_{}", std::process::id());
            let mut options = OpenOptions::new(dir.path());
            options.pg_schema = Some(schema.clone());
            Store::open(&url, &options).await.unwrap().close().await;
            let mut raw = sqlx::PgConnection::connect(&url).await.unwrap();
            sqlx::query(&format!("SET search_path TO {schema}"))
                .execute(&mut raw)
                .await
                .unwrap();
            rows.push(run("PostgreSQL", &url, options, Raw::Pg(raw), n, rounds).await);
            let mut c = sqlx::PgConnection::connect(&url).await.unwrap();
            sqlx::query(&format!("DROP SCHEMA {schema} CASCADE"))
                .execute(&mut c)
                .await
                .unwrap();
        }
        Err(_) => eprintln!("GRIDSCADA_TEST_PG_URL not set: PostgreSQL skipped"),
    }

    let load = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
    println!("\nload average at the end: {}", load.trim());
    println!("\nhistorian ingest of {n} samples (10 tags), median of {rounds} alternating rounds; 500-point trends of 10 tags over a day of 1 s data (864,000 rows) and a year of 5 min data (1,051,200 rows)\n");
    println!(
        "| backend | writer task samples/s | plain batched INSERT samples/s | plain COPY samples/s | writer / COPY (median; each round) | day load samples/s | year load samples/s | trend, day: min / median ms | trend, year: min / median ms |"
    );
    println!("|---|---:|---:|---:|---:|---:|---:|---:|---:|");
    for r in rows {
        let (copy, ratio) = match (r.copy, r.ratio) {
            (Some(c), Some(x)) => (
                format!("{c:.0}"),
                format!(
                    "{x:.2} ({})",
                    r.ratios
                        .iter()
                        .map(|x| format!("{x:.2}"))
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            ),
            _ => ("—".into(), "—".into()),
        };
        println!(
            "| {} | {:.0} | {:.0} | {copy} | {ratio} | {:.0} | {:.0} | {:.1} / {:.1} | {:.1} / {:.1} |",
            r.backend,
            r.writer,
            r.plain,
            r.load,
            r.year_load,
            r.trend_ms[0],
            r.trend_ms[r.trend_ms.len() / 2],
            r.year_ms[0],
            r.year_ms[r.year_ms.len() / 2]
        );
    }
}
