//! Historian roll-ups on both backends: random data with gaps, bursts, Bad
//! stretches, samples without value, late and repeated samples, written in
//! random batches; every trend read from a roll-up must give exactly the
//! min, max, count and last sample of the raw samples between its bucket
//! edges, and the Bad time each sample held to the next one or to the end of
//! its roll-up period. The upgrade's one-time roll-up (migration 0009) must
//! give the same trends as the roll-ups kept while writing.

use crate::common;

use std::sync::Arc;

use common::{Engine, TestDb};
use gridscada_store::*;
use gridscada_tagdb::{QualityCode, Timestamp};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

const MINUTE: i64 = 60_000;
const HOUR: i64 = 3_600_000;
const T0: i64 = 1_700_000_000_000 + 12_345;

fn ts(ms: i64) -> Timestamp {
    Timestamp::from_millis(ms)
}

/// Weeks of one tag: mostly 1-20 s apart, bursts of 100-500 ms,
/// gaps of minutes and hours, Bad and Uncertain stretches, 2 % without value.
fn series(rng: &mut StdRng, tag: &Arc<str>, start: i64, n: usize) -> Vec<HistorySample> {
    let mut out = Vec::with_capacity(n);
    let (mut t, mut v) = (start, 100.0f64);
    let mut quality = QualityCode::Good;
    let mut stretch = 0;
    for _ in 0..n {
        t += match rng.random_range(0..100) {
            0..=69 => rng.random_range(1_000..20_000),
            70..=89 => rng.random_range(100..500),
            90..=97 => rng.random_range(MINUTE..30 * MINUTE),
            _ => rng.random_range(HOUR..6 * HOUR),
        };
        if stretch == 0 {
            quality = match rng.random_range(0..100) {
                0..=2 => QualityCode::Bad,
                3 => QualityCode::Uncertain,
                _ => QualityCode::Good,
            };
            stretch = rng.random_range(1..200);
        }
        stretch -= 1;
        v += rng.random_range(-5.0..5.0);
        out.push(HistorySample {
            tag: tag.clone(),
            ts: ts(t),
            value: (rng.random_range(0..50) != 0).then_some(v),
            exact: None,
            quality,
        });
    }
    out
}

/// Writes the samples in random batches; 1 % of them are held back and sent
/// late, 1 % are sent again later with another value (which replaces the
/// first, as a repeated sample does). The newest 10 of each tag come last,
/// after the late ones, so the last minutes are left open (SQLite keeps them
/// open in memory).
async fn write(store: &Store, rng: &mut StdRng, mut all: Vec<HistorySample>) {
    all.sort_by_key(|s| (s.tag.clone(), s.ts.as_millis()));
    let mut newest = Vec::new();
    for tag in all.chunk_by(|a, b| a.tag == b.tag) {
        newest.extend_from_slice(&tag[tag.len().saturating_sub(10)..]);
    }
    all.retain(|s| !newest.iter().any(|n| n.tag == s.tag && n.ts == s.ts));
    all.sort_by_key(|s| s.ts.as_millis());
    let mut late: Vec<HistorySample> = Vec::new();
    let mut i = 0;
    while i < all.len() {
        let len = rng.random_range(1..2_000).min(all.len() - i);
        let mut batch = Vec::with_capacity(len + late.len());
        for s in &all[i..i + len] {
            match rng.random_range(0..100) {
                0 => late.push(s.clone()),
                1 => {
                    batch.push(s.clone());
                    let mut again = s.clone();
                    again.value = again.value.map(|v| v + 1000.0);
                    late.push(again);
                }
                _ => batch.push(s.clone()),
            }
        }
        if rng.random_range(0..4) == 0 {
            batch.append(&mut late);
        }
        store.insert_samples(&batch).await.unwrap();
        i += len;
    }
    store.insert_samples(&late).await.unwrap();
    store.insert_samples(&newest).await.unwrap();
}

/// What the trend bucket must hold, from the raw samples in `start..end`.
fn check(engine: Engine, what: &str, b: &TrendBucket, raw: &[RawSample], width: i64) {
    let (s, e) = (b.start.as_millis(), b.end.as_millis());
    let inside: Vec<&RawSample> = raw
        .iter()
        .filter(|r| (s..e).contains(&r.ts.as_millis()))
        .collect();
    let ctx = format!("{engine:?} {what} bucket {} ({s}..{e})", b.index);
    assert_eq!(b.count, inside.len() as u64, "{ctx}: count");
    let values: Vec<f64> = inside.iter().filter_map(|r| r.value).collect();
    let min = values.iter().copied().reduce(f64::min);
    let max = values.iter().copied().reduce(f64::max);
    assert_eq!((b.min, b.max), (min, max), "{ctx}: envelope");
    match b.avg {
        Some(avg) => {
            let exact = values.iter().sum::<f64>() / values.len() as f64;
            assert!(
                (avg - exact).abs() <= 1e-9 * exact.abs().max(1.0),
                "{ctx}: avg {avg} vs {exact}"
            );
        }
        None => assert!(values.is_empty(), "{ctx}: avg"),
    }
    let last = inside.last().expect("a returned bucket holds samples");
    assert_eq!(
        (b.last, b.last_ts, b.last_quality),
        (last.value, last.ts, last.quality),
        "{ctx}: last sample"
    );
    // Bad time: each Bad sample held to the next one in its roll-up period,
    // or to the period's end.
    let mut bad = 0i64;
    for (k, r) in inside.iter().enumerate() {
        if r.quality != QualityCode::Bad {
            continue;
        }
        let t = r.ts.as_millis();
        let end = t - t.rem_euclid(width) + width;
        let next = inside
            .get(k + 1)
            .map(|n| n.ts.as_millis())
            .filter(|&n| n < end)
            .unwrap_or(end);
        bad += next - t;
    }
    assert_eq!(b.bad_ms, bad as u64, "{ctx}: Bad time");
}

/// Checks every trend of `queries` read from a roll-up level against the raw
/// samples of its tags; returns how many queries read raw, minute and hour.
async fn check_trends(
    engine: Engine,
    store: &Store,
    tags: &[&str],
    raw: &[Vec<RawSample>],
    queries: &[(i64, i64, u32)],
    what: &str,
) -> [usize; 3] {
    let mut levels = [0; 3];
    for &(f, t, n) in queries {
        let width = if HOUR * n as i64 <= t - f {
            HOUR
        } else if MINUTE * n as i64 <= t - f {
            MINUTE
        } else {
            levels[0] += 1;
            continue; // raw: covered by the store tests
        };
        levels[if width == HOUR { 2 } else { 1 }] += 1;
        let trends = store.trend(tags, ts(f), ts(t), n).await.unwrap();
        for (trend, raw) in trends.iter().zip(raw) {
            let what = format!("{what}, {} {f}..{t}/{n}", trend.tag);
            let mut prev_end = None;
            let mut total = 0;
            for b in &trend.buckets {
                assert!(b.index < n, "{what}: index");
                assert_eq!(b.start.as_millis().rem_euclid(width), 0, "{what}: on grid");
                assert_eq!(b.end.as_millis().rem_euclid(width), 0, "{what}: on grid");
                assert!(b.start.as_millis() > f - width && b.end.as_millis() < t + width);
                if let Some(p) = prev_end {
                    assert!(b.start >= p, "{what}: buckets in order, not overlapping");
                }
                prev_end = Some(b.end);
                check(engine, &what, b, raw, width);
                total += b.count;
            }
            // No sample between the first and the last edge is left out.
            let (lo, hi) = (
                f - f.rem_euclid(width),
                (t - 1) - (t - 1).rem_euclid(width) + width,
            );
            let expected = raw
                .iter()
                .filter(|r| (lo..hi).contains(&r.ts.as_millis()))
                .count() as u64;
            assert_eq!(total, expected, "{what}: every sample in some bucket");
        }
    }
    levels
}

async fn trends_from_rollups_equal_raw(db: TestDb) {
    let engine = db.engine;
    let store = &db.store;
    // ROLLUP_SEED=N tries other data.
    let seed = std::env::var("ROLLUP_SEED")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(0x5eed_0019);
    let mut rng = StdRng::seed_from_u64(seed);
    let names: Vec<Arc<str>> = ["A", "B", "C"].into_iter().map(Arc::from).collect();
    let mut all = Vec::new();
    for (k, name) in names.iter().enumerate() {
        all.extend(series(&mut rng, name, T0 + k as i64 * 777, 12_000));
    }
    write(store, &mut rng, all).await;
    let end = T0 + 400 * 86_400_000;
    let tags: Vec<&str> = names.iter().map(|n| &**n).collect();
    let raw: Vec<Vec<RawSample>> = {
        let mut out = Vec::new();
        for t in &tags {
            out.push(
                store
                    .raw_samples(&[t], ts(0), ts(end), u32::MAX)
                    .await
                    .unwrap(),
            );
        }
        out
    };
    let last = raw
        .iter()
        .map(|r| r.last().unwrap().ts.as_millis())
        .max()
        .unwrap();
    assert!(last - T0 > 3 * 86_400_000, "the data spans days");

    let mut queries: Vec<(i64, i64, u32)> = vec![
        (T0, last + 1, 50),
        (T0 - 5 * HOUR, last + HOUR, 30),
        (T0 + 3 * HOUR, T0 + 27 * HOUR, 500),
    ];
    for _ in 0..25 {
        let f = rng.random_range(T0 - HOUR..last);
        let t = rng.random_range(f + 1..last + 2 * HOUR);
        let n = rng.random_range(1..300);
        queries.push((f, t, n));
    }
    let levels = check_trends(
        engine,
        store,
        &tags,
        &raw,
        &queries,
        &format!("seed {seed}"),
    )
    .await;
    assert!(
        levels[1] > 3 && levels[2] > 3,
        "both levels were queried: {levels:?}"
    );

    // The upgrade's one-time roll-up gives the same trends (with the open
    // minutes written first: it rebuilds every roll-up from raw rows).
    if engine == Engine::Sqlite {
        assert!(store.open_minutes() > 0, "the last minutes were open");
    }
    store.close_open_minutes().await.unwrap();
    assert_eq!(store.open_minutes(), 0);
    let queries = [(T0, last + 1, 50u32), (T0 + HOUR, T0 + 30 * HOUR, 400)];
    let before = trends(store, &tags, &queries).await;
    rebuild_from_migration(&db).await;
    let after = trends(store, &tags, &queries).await;
    same_trends(
        &format!("{engine:?} rebuilt by the migration"),
        &after,
        &before,
    );
    db.cleanup().await;
}
both_backends!(trends_from_rollups, trends_from_rollups_equal_raw);

async fn trends(store: &Store, tags: &[&str], queries: &[(i64, i64, u32)]) -> Vec<Vec<TagTrend>> {
    let mut out = Vec::new();
    for &(f, t, n) in queries {
        out.push(store.trend(tags, ts(f), ts(t), n).await.unwrap());
    }
    out
}

/// The same buckets (the average to rounding: sums are added in another order).
fn same_trends(what: &str, after: &[Vec<TagTrend>], before: &[Vec<TagTrend>]) {
    assert_eq!(after.len(), before.len());
    for (after, before) in after.iter().zip(before) {
        assert_eq!(after.len(), before.len());
        for (a, b) in after.iter().zip(before) {
            assert_eq!(a.buckets.len(), b.buckets.len(), "{what}: {}", a.tag);
            for (x, y) in a.buckets.iter().zip(&b.buckets) {
                let (xa, ya) = (x.avg, y.avg);
                let mut x = x.clone();
                x.avg = y.avg;
                assert_eq!(&x, y, "{what}: {}", a.tag);
                let (xa, ya) = (xa.unwrap_or(0.0), ya.unwrap_or(0.0));
                assert!(
                    (xa - ya).abs() <= 1e-9 * ya.abs().max(1.0),
                    "{what}: {}",
                    a.tag
                );
            }
        }
    }
}

/// SQLite keeps each tag's open minute roll-up in memory until the minute is
/// over. A process that dies with minutes open loses none: the next open
/// rebuilds them from the raw rows, and the roll-ups then equal the
/// upgrade's rebuild of every roll-up from raw rows, before and after more
/// samples (late ones among them) are written.
async fn open_minutes_survive_a_crash(mut db: TestDb) {
    let engine = db.engine;
    let mut rng = StdRng::seed_from_u64(0x0c4a_5401);
    let names: Vec<Arc<str>> = ["A", "B", "C", "D"].into_iter().map(Arc::from).collect();
    let tags: Vec<&str> = names.iter().map(|n| &**n).collect();
    let mut all = Vec::new();
    for (k, name) in names.iter().enumerate() {
        all.extend(series(&mut rng, name, T0 + k as i64 * 777, 3_000));
    }
    let last = all.iter().map(|s| s.ts.as_millis()).max().unwrap();
    write(&db.store, &mut rng, all).await;
    if engine == Engine::Sqlite {
        assert!(db.store.open_minutes() > 0, "minutes are open at the crash");
    }
    let queries = [
        (T0, last + 1, 40u32),
        (T0 + HOUR, T0 + 30 * HOUR, 400),
        (last - 3 * HOUR, last + HOUR, 200),
    ];
    let before = trends(&db.store, &tags, &queries).await;
    // The crash: a new process opens the database; the old one never
    // writes again (its open minutes die with it).
    let reopened = Store::open(&db.url, &db.options).await.unwrap();
    let crashed = std::mem::replace(&mut db.store, reopened);
    drop(crashed);
    assert_eq!(db.store.open_minutes(), 0);
    // The historian's writer rebuilds them when it starts (else the first
    // write does).
    let rebuilt = db.store.recover_open_minutes().await.unwrap();
    assert_eq!(rebuilt > 0, engine == Engine::Sqlite, "{rebuilt} rebuilt");
    let after = trends(&db.store, &tags, &queries).await;
    same_trends(&format!("{engine:?} after the crash"), &after, &before);

    // Writing goes on, some samples in the minutes rebuilt.
    let mut more = Vec::new();
    for (k, name) in names.iter().enumerate() {
        more.extend(series(&mut rng, name, last - MINUTE + k as i64 * 333, 500));
    }
    let newest = more.iter().map(|s| s.ts.as_millis()).max().unwrap();
    write(&db.store, &mut rng, more).await;
    let queries = [
        (T0, newest + 1, 60u32),
        (last - 3 * HOUR, newest + HOUR, 300),
    ];
    let open = trends(&db.store, &tags, &queries).await;
    db.store.close_open_minutes().await.unwrap();
    rebuild_from_migration(&db).await;
    let rebuilt = trends(&db.store, &tags, &queries).await;
    same_trends(
        &format!("{engine:?} rebuilt by the migration"),
        &open,
        &rebuilt,
    );
    db.cleanup().await;
}
both_backends!(open_minutes_crash, open_minutes_survive_a_crash);

/// Fifty tags logging side by side, as a plant does: their last minutes are
/// open when the trends are read (SQLite keeps them in memory), late samples
/// among them make the database recompute hours holding open minutes, and
/// every trend at both levels still equals the raw samples; after the open
/// minutes are written, the tables equal the upgrade's rebuild from raw rows.
async fn trends_fold_in_open_minutes(db: TestDb) {
    let engine = db.engine;
    let store = &db.store;
    let mut rng = StdRng::seed_from_u64(0x0be7_0050);
    let names: Vec<Arc<str>> = (0..50).map(|k| Arc::from(format!("T{k:02}"))).collect();
    let tags: Vec<&str> = names.iter().map(|n| &**n).collect();
    let start = T0 - T0.rem_euclid(HOUR) + 17 * MINUTE;
    let mut all = Vec::new();
    for name in &names {
        let (mut t, mut v) = (start + rng.random_range(0..5_000), 0.0f64);
        while t < start + 3 * HOUR {
            t += rng.random_range(2_000..15_000);
            v += rng.random_range(-1.0..1.0);
            let quality = match rng.random_range(0..40) {
                0 => QualityCode::Bad,
                1 => QualityCode::Uncertain,
                _ => QualityCode::Good,
            };
            all.push(HistorySample {
                tag: name.clone(),
                ts: ts(t),
                value: Some(v),
                exact: None,
                quality,
            });
        }
    }
    let last = all.iter().map(|s| s.ts.as_millis()).max().unwrap();
    write(store, &mut rng, all).await;
    if engine == Engine::Sqlite {
        assert!(store.open_minutes() >= 25, "{} open", store.open_minutes());
    }
    let mut raw = Vec::new();
    for t in &tags {
        raw.push(
            store
                .raw_samples(&[t], ts(0), ts(last + 1), u32::MAX)
                .await
                .unwrap(),
        );
    }
    let queries = [
        (start, last + 1, 3u32),
        (start - HOUR, last + HOUR, 4),
        (last - 2 * HOUR, last + 1, 100),
        (last - 40 * MINUTE, last + 30 * MINUTE, 35),
        (last - 7 * MINUTE, last + 1, 7),
    ];
    let levels = check_trends(engine, store, &tags, &raw, &queries, "open minutes").await;
    assert!(levels[1] >= 3 && levels[2] >= 2, "{levels:?}");
    let open = trends(store, &tags, &queries).await;
    store.close_open_minutes().await.unwrap();
    rebuild_from_migration(&db).await;
    let rebuilt = trends(store, &tags, &queries).await;
    same_trends(
        &format!("{engine:?} rebuilt by the migration"),
        &open,
        &rebuilt,
    );
    db.cleanup().await;
}
both_backends!(open_minute_trends, trends_fold_in_open_minutes);

/// Empties the roll-up tables and runs migration 0009 again, as on a
/// database upgraded with samples already in it.
async fn rebuild_from_migration(db: &TestDb) {
    use sqlx::Connection;
    const WIPE: &str = "DELETE FROM samples_minute; DELETE FROM samples_hour;";
    match db.engine {
        Engine::Sqlite => {
            let path = db.dir.path().join("store.db");
            let mut c = sqlx::SqliteConnection::connect(&format!("sqlite://{}", path.display()))
                .await
                .unwrap();
            sqlx::raw_sql(WIPE).execute(&mut c).await.unwrap();
            sqlx::raw_sql(include_str!("../../migrations/sqlite/0009_rollups.sql"))
                .execute(&mut c)
                .await
                .unwrap();
        }
        Engine::Postgres => {
            let mut c = sqlx::PgConnection::connect(&db.url).await.unwrap();
            let schema = db.options.pg_schema.as_deref().unwrap();
            sqlx::query(&format!("SET search_path TO {schema}"))
                .execute(&mut c)
                .await
                .unwrap();
            sqlx::raw_sql(WIPE).execute(&mut c).await.unwrap();
            sqlx::raw_sql(include_str!("../../migrations/postgres/0009_rollups.sql"))
                .execute(&mut c)
                .await
                .unwrap();
        }
    }
}

async fn rollup_retention_is_per_level(db: TestDb) {
    let store = &db.store;
    const DAY: i64 = 86_400_000;
    let now = 1_000 * DAY;
    let tag: Arc<str> = Arc::from("R");
    let samples: Vec<HistorySample> = [900, 500, 100, 10]
        .into_iter()
        .map(|d| HistorySample {
            tag: tag.clone(),
            ts: ts(now - d * DAY),
            value: Some(d as f64),
            exact: None,
            quality: QualityCode::Good,
        })
        .collect();
    store.insert_samples(&samples).await.unwrap();
    let policy = RetentionPolicy {
        default_days: Some(30),
        minute_days: Some(365),
        hour_days: Some(800),
        ..Default::default()
    };
    // Raw: 900, 500, 100 go; minute: 900, 500; hour: 900.
    assert_eq!(
        store.apply_retention(&policy, ts(now)).await.unwrap(),
        3 + 2 + 1
    );
    let raw = store.raw_samples(&["R"], ts(0), ts(now), 10).await.unwrap();
    assert_eq!(raw.len(), 1);
    // A trend over three years reads hours: 500 and 100 days ago are still there.
    let year = store
        .trend(&["R"], ts(now - 1_000 * DAY), ts(now), 100)
        .await
        .unwrap();
    let values: Vec<Option<f64>> = year[0].buckets.iter().map(|b| b.last).collect();
    assert_eq!(values, vec![Some(500.0), Some(100.0), Some(10.0)]);
    // Over 20 days in 1,000 points it reads minutes: the sample 10 days ago is kept there too.
    let month = store
        .trend(&["R"], ts(now - 20 * DAY), ts(now), 1000)
        .await
        .unwrap();
    assert_eq!(month[0].buckets.len(), 1);
    db.cleanup().await;
}
both_backends!(rollup_retention, rollup_retention_is_per_level);
