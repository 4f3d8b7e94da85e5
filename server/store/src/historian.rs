//! Historian tables: sample ingest, downsampled trends, raw export, retention.
//!
//! **Owns:** the `tags` and `samples` tables. **Must not touch:** the logging
//! policy (that is [`crate::Recorder`]) or buffering (that is
//! [`crate::Historian`]); these calls write what they are given, now.

use std::collections::HashMap;
use std::sync::Arc;
use std::time::Duration;

use gridscada_tagdb::{QualityCode, Timestamp};
use serde::Serialize;
use sqlx::QueryBuilder;
use tokio::io::{AsyncWrite, AsyncWriteExt};

use crate::error::db;
use crate::open_minutes;
use crate::rollup::{self, Level};
use crate::{Result, Store, StoreError};

/// The most buckets one trend query may ask for (a screen is a few thousand
/// pixels wide; more would only load the database).
pub const MAX_TREND_BUCKETS: u32 = 20_000;

/// Rows per multi-row INSERT statement on SQLite (4 or 5 parameters each, well
/// under SQLite's 32,766 parameter limit).
const SQLITE_ROWS_PER_STATEMENT: usize = 1_000;

/// Rows per page of a raw export.
const EXPORT_PAGE: i64 = 5_000;

/// One logged sample, as the historian stores it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct HistorySample {
    pub tag: Arc<str>,
    pub ts: Timestamp,
    /// The numeric value (booleans as 0/1); `None` when the reading had no
    /// finite number. Non-finite numbers are stored as `None`.
    pub value: Option<f64>,
    /// The exact integer, for an integer outside ±2^53 (which `value` rounds).
    pub exact: Option<i128>,
    pub quality: QualityCode,
}

impl HistorySample {
    /// The row of one sample as it is, without a logging policy (samples
    /// that arrive already chosen: a Sparkplug edge's store and forward).
    /// None for a string value (not logged); a Bad sample is a gap.
    pub fn of(tag: Arc<str>, sample: &gridscada_tagdb::Sample) -> Option<HistorySample> {
        if matches!(sample.value, gridscada_tagdb::Value::Str(_)) || sample.is_never_read() {
            return None;
        }
        let bad = sample.quality.code == QualityCode::Bad;
        Some(HistorySample {
            tag,
            ts: sample.timestamp,
            value: sample.value.as_f64().filter(|v| v.is_finite() && !bad),
            exact: sample
                .value
                .as_i128()
                .filter(|_| sample.value.is_wide_integer() && !bad),
            quality: sample.quality.code,
        })
    }
}

/// A sample read back from the historian.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RawSample {
    pub tag: String,
    pub ts: Timestamp,
    pub value: Option<f64>,
    /// The exact integer where `value` is an integer outside ±2^53 (as a
    /// string in JSON, like a live value of that size).
    #[serde(skip_serializing_if = "Option::is_none", serialize_with = "as_digits")]
    pub exact: Option<i128>,
    pub quality: QualityCode,
}

fn as_digits<S: serde::Serializer>(v: &Option<i128>, s: S) -> std::result::Result<S::Ok, S::Error> {
    match v {
        Some(i) => s.collect_str(i),
        None => s.serialize_none(),
    }
}

/// One bucket of a downsampled trend. Only buckets holding samples are returned.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TrendBucket {
    /// Bucket index, 0..buckets.
    pub index: u32,
    /// The bucket covers `start..end`.
    pub start: Timestamp,
    pub end: Timestamp,
    /// Samples in the bucket (including those without a value).
    pub count: u64,
    /// Over the samples that have a value; `None` if none has.
    pub min: Option<f64>,
    pub max: Option<f64>,
    pub avg: Option<f64>,
    /// The newest sample of the bucket.
    pub last: Option<f64>,
    pub last_ts: Timestamp,
    pub last_quality: QualityCode,
    /// Time the tag was Bad in the bucket, in ms: each Bad sample held until
    /// the next sample, or the end of its roll-up period (of the bucket, for
    /// a trend read from raw samples).
    pub bad_ms: u64,
}

/// The downsampled trend of one tag.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TagTrend {
    pub tag: String,
    pub buckets: Vec<TrendBucket>,
}

/// How long samples are kept.
#[derive(Debug, Clone, Default)]
pub struct RetentionPolicy {
    /// Days of raw samples for tags without their own setting; `None` keeps
    /// them forever.
    pub default_days: Option<u32>,
    /// A tag's own retention of raw samples (its `history.retention_days`).
    pub per_tag_days: HashMap<String, u32>,
    /// Days of the per-minute roll-ups, every tag; `None` keeps them forever.
    pub minute_days: Option<u32>,
    /// Days of the per-hour roll-ups, every tag; `None` keeps them forever.
    pub hour_days: Option<u32>,
}

/// Stored quality code: 0 good, 1 uncertain, 2 bad.
pub fn quality_to_code(q: QualityCode) -> i32 {
    match q {
        QualityCode::Good => 0,
        QualityCode::Uncertain => 1,
        QualityCode::Bad => 2,
    }
}

/// Reads a stored quality code; unknown codes read as bad (never as good).
pub fn quality_from_code(c: i32) -> QualityCode {
    match c {
        0 => QualityCode::Good,
        1 => QualityCode::Uncertain,
        _ => QualityCode::Bad,
    }
}

fn check_range(from: Timestamp, to: Timestamp) -> Result<()> {
    if to <= from {
        return Err(StoreError::Invalid(format!(
            "time range {}..{} is empty or reversed",
            from.as_millis(),
            to.as_millis()
        )));
    }
    Ok(())
}

/// bucket, count, min, max, avg, last_ts, last value, last quality, Bad ms.
type BucketRow = (
    i64,
    i64,
    Option<f64>,
    Option<f64>,
    Option<f64>,
    i64,
    Option<f64>,
    i32,
    i64,
);

/// From a roll-up: tag id, bucket, count, min, max, sum, values, last_ts,
/// last value, last quality, Bad ms.
pub(crate) type MultiLevelRow = (
    i64,
    i64,
    i64,
    Option<f64>,
    Option<f64>,
    Option<f64>,
    i64,
    i64,
    Option<f64>,
    i32,
    i64,
);

/// A raw sample as selected: tag id, ts, value, exact digits, quality.
type RawRow = (i64, i64, Option<f64>, Option<String>, i32);

struct Row {
    tag_id: i64,
    ts: i64,
    value: Option<f64>,
    exact: Option<String>,
    quality: i32,
}

/// A batch of samples made ready for the database without touching it: its
/// rows with their tag ids, sorted by key and one per key, its COPY text
/// (PostgreSQL) and its roll-up buckets at both levels. The historian's
/// writer prepares the next batch while this one is in the database.
pub(crate) struct PreparedSamples {
    rows: Vec<Row>,
    copy: Option<Vec<u8>>,
    /// PostgreSQL: both levels; SQLite: the minutes, which join the open
    /// minutes (`open_minutes.rs`) and make the hours.
    buckets: Vec<(Level, Vec<rollup::Agg>)>,
    /// SQLite: the median timestamp, the open minutes' clock.
    median_ts: Option<i64>,
}

impl Row {
    fn of(tag_id: i64, s: &HistorySample) -> Row {
        Row {
            tag_id,
            ts: s.ts.as_millis(),
            value: s.value.filter(|v| v.is_finite()),
            exact: s.exact.map(|i| i.to_string()),
            quality: quality_to_code(s.quality),
        }
    }
}

impl Store {
    /// Writes samples in one transaction, as multi-row inserts (SQLite) or a
    /// COPY (PostgreSQL), and brings the roll-ups up to date. A second sample
    /// for the same tag and millisecond replaces the first. Returns the number
    /// of rows written.
    pub async fn insert_samples(&self, samples: &[HistorySample]) -> Result<u64> {
        if samples.is_empty() {
            return Ok(0);
        }
        let mut names: Vec<&str> = samples.iter().map(|s| &*s.tag).collect();
        names.sort_unstable();
        names.dedup();
        let ids = self.tag_ids(&names, true).await?;
        let mut rows = Vec::with_capacity(samples.len());
        for s in samples {
            let tag_id = *ids.get(&*s.tag).ok_or_else(|| {
                StoreError::Invalid(format!("historian tag '{}' could not be registered", s.tag))
            })?;
            rows.push(Row::of(tag_id, s));
        }
        self.write_prepared(&self.prepared(rows)).await
    }

    /// [`Store::insert_samples`]'s work that needs no database: `None` when
    /// a tag of the batch is not registered yet (or this store is another
    /// site's view), and then `insert_samples` does it all.
    pub(crate) fn prepare_samples(&self, samples: &[HistorySample]) -> Option<PreparedSamples> {
        if self.view || self.inner.tag_ids_loaded.get().is_none() || samples.is_empty() {
            return None;
        }
        let rows = {
            let ids = self.inner.tag_ids.lock();
            samples
                .iter()
                .map(|s| ids.get(&*s.tag).map(|&id| Row::of(id, s)))
                .collect::<Option<Vec<Row>>>()?
        };
        Some(self.prepared(rows))
    }

    fn prepared(&self, mut rows: Vec<Row>) -> PreparedSamples {
        // Sorted by key for B-tree locality; of duplicates keep the last given
        // (a stable sort keeps arrival order within equal keys).
        rows.sort_by_key(|r| (r.tag_id, r.ts));
        let mut deduped: Vec<Row> = Vec::with_capacity(rows.len());
        for r in rows {
            match deduped.last_mut() {
                Some(l) if l.tag_id == r.tag_id && l.ts == r.ts => *l = r,
                _ => deduped.push(r),
            }
        }
        let postgres = matches!(self.inner.backend, crate::store::Backend::Postgres(_));
        let copy = postgres.then(|| copy_text(&deduped));
        let levels: &[Level] = if postgres {
            &Level::ALL
        } else {
            &[Level::Minute]
        };
        let buckets = levels
            .iter()
            .map(|&level| {
                let keys = deduped.iter().map(|r| (r.tag_id, r.ts, r.value, r.quality));
                (level, rollup::roll_up(keys, level.width()))
            })
            .collect();
        let median_ts = (!postgres)
            .then(|| open_minutes::median(deduped.iter().map(|r| r.ts).collect()))
            .flatten();
        PreparedSamples {
            rows: deduped,
            copy,
            buckets,
            median_ts,
        }
    }

    /// Writes a prepared batch in one transaction, roll-ups included.
    pub(crate) async fn write_prepared(&self, batch: &PreparedSamples) -> Result<u64> {
        self.writable("inserting historian samples")?;
        let n = batch.rows.len() as u64;
        if n == 0 {
            return Ok(0);
        }
        match &self.inner.backend {
            crate::store::Backend::Sqlite(s) => {
                // One change of the open minutes at a time, from plan to apply.
                let _gate = self.inner.open_gate.lock().await;
                self.recover_locked(s).await?;
                let mut tx = s
                    .writer()
                    .begin()
                    .await
                    .map_err(db("inserting historian samples"))?;
                for chunk in rollup::statement_chunks(&batch.rows, SQLITE_ROWS_PER_STATEMENT) {
                    // Exact integers are rare: without any, one parameter
                    // less per row.
                    let exact = chunk.iter().any(|r| r.exact.is_some());
                    let mut qb = QueryBuilder::new(if exact {
                        "INSERT INTO samples (tag_id, ts, value, exact, quality) "
                    } else {
                        "INSERT INTO samples (tag_id, ts, value, quality) "
                    });
                    qb.push_values(chunk, |mut b, r| {
                        b.push_bind(r.tag_id).push_bind(r.ts).push_bind(r.value);
                        if exact {
                            b.push_bind(r.exact.as_deref());
                        }
                        b.push_bind(r.quality);
                    });
                    qb.push(if exact {
                        " ON CONFLICT (tag_id, ts) DO UPDATE SET value = excluded.value, \
                         exact = excluded.exact, quality = excluded.quality"
                    } else {
                        " ON CONFLICT (tag_id, ts) DO UPDATE SET value = excluded.value, \
                         exact = NULL, quality = excluded.quality"
                    });
                    qb.build()
                        .execute(&mut *tx)
                        .await
                        .map_err(db("inserting historian samples"))?;
                }
                let minutes = batch
                    .buckets
                    .iter()
                    .find(|(l, _)| *l == Level::Minute)
                    .map_or(&[][..], |(_, b)| b.as_slice());
                let (plan, first) = {
                    let open = self.inner.open_minutes.lock();
                    (open.plan(minutes, batch.median_ts), !open.marked_open)
                };
                self.write_open_minutes(tx, plan, first.then_some(false))
                    .await?;
            }
            crate::store::Backend::Postgres(p) => {
                let text = match &batch.copy {
                    Some(t) => std::borrow::Cow::Borrowed(t),
                    None => std::borrow::Cow::Owned(copy_text(&batch.rows)),
                };
                // One historian writer at a time per schema (several servers
                // may share a database): roll-ups are read, merged and
                // written. The lock is taken in BEGIN's round trip.
                let begin = || {
                    p.begin_with(
                        "BEGIN; SELECT pg_advisory_xact_lock(hashtext(current_schema() || '.historian'))",
                    )
                };
                let mut tx = begin().await.map_err(db("locking the historian"))?;
                // A plain COPY into the table: as fast as PostgreSQL ingests.
                // A repeated sample makes it fail on the primary key; then the
                // batch goes again, through a staging table, merged (no
                // savepoint: the common batch opens no subtransaction, and
                // the rare one that needs the merge is redone whole).
                match copy_in(
                    &mut tx,
                    "COPY samples (tag_id, ts, value, exact, quality) FROM STDIN",
                    &text,
                )
                .await
                {
                    Ok(()) => {}
                    Err(e)
                        if e.as_database_error()
                            .is_some_and(|d| d.is_unique_violation()) =>
                    {
                        tx.rollback()
                            .await
                            .map_err(db("inserting historian samples"))?;
                        tx = begin().await.map_err(db("locking the historian"))?;
                        sqlx::query(
                            "CREATE TEMP TABLE IF NOT EXISTS samples_in \
                             (tag_id BIGINT, ts BIGINT, value DOUBLE PRECISION, exact TEXT, quality INTEGER) \
                             ON COMMIT DELETE ROWS",
                        )
                        .execute(&mut *tx)
                        .await
                        .map_err(db("inserting historian samples"))?;
                        copy_in(&mut tx, "COPY samples_in FROM STDIN", &text)
                            .await
                            .map_err(db("inserting historian samples"))?;
                        sqlx::query(
                            "INSERT INTO samples (tag_id, ts, value, exact, quality) \
                             SELECT tag_id, ts, value, exact, quality FROM samples_in \
                             ON CONFLICT (tag_id, ts) DO UPDATE SET \
                             value = EXCLUDED.value, exact = EXCLUDED.exact, quality = EXCLUDED.quality",
                        )
                        .execute(&mut *tx)
                        .await
                        .map_err(db("inserting historian samples"))?;
                    }
                    Err(e) => return Err(db("inserting historian samples")(e)),
                }
                rollup::maintain_pg(&mut tx, &batch.buckets).await?;
                tx.commit()
                    .await
                    .map_err(db("inserting historian samples"))?;
            }
        }
        Ok(n)
    }

    /// Writes a plan of the open minutes in `tx` (the batch's samples are
    /// in it already), commits, then applies the plan: the caller holds the
    /// open minutes' gate. `clean`: the state's flag to write with it.
    async fn write_open_minutes(
        &self,
        mut tx: sqlx::Transaction<'_, sqlx::Sqlite>,
        plan: open_minutes::Plan,
        clean: Option<bool>,
    ) -> Result<()> {
        rollup::maintain_sqlite(
            &mut tx,
            &[(Level::Minute, &plan.minutes), (Level::Hour, &plan.hours)],
        )
        .await?;
        open_minutes::write_state(&mut tx, &self.site, plan.watermark, clean).await?;
        // From the commit until the plan is applied, the database and the
        // open minutes disagree: a trend reading then tries again.
        let committing = open_minutes::Committing::start(&self.inner.open_minutes);
        tx.commit()
            .await
            .map_err(db("writing historian roll-ups"))?;
        {
            let mut open = self.inner.open_minutes.lock();
            if let Some(clean) = clean {
                open.marked_open = !clean;
            }
            open.apply(plan);
        }
        drop(committing);
        Ok(())
    }

    /// SQLite keeps each tag's open minute roll-up in memory until the
    /// minute is over: this writes them all (in transactions of 20,000), so
    /// a restart has nothing to rebuild. Nothing to do on PostgreSQL.
    /// Returns the minutes written.
    pub async fn close_open_minutes(&self) -> Result<u64> {
        self.close_open_minutes_within(None).await
    }

    /// [`Self::close_open_minutes`] for at most about `budget` (a stop: at a
    /// million tags the open minutes take a minute or more to write, and a
    /// service manager kills a stop that lasts). What is left stays open in
    /// the database's state, and the next start rebuilds it from the raw
    /// rows, which is faster than writing it now.
    pub async fn close_open_minutes_within(&self, budget: Option<Duration>) -> Result<u64> {
        let Some(s) = self.open_minutes_backend() else {
            return Ok(0);
        };
        let started = std::time::Instant::now();
        let _gate = self.inner.open_gate.lock().await;
        {
            let open = self.inner.open_minutes.lock();
            if !open.marked_open && open.count() == 0 {
                return Ok(0);
            }
        }
        let mut written = 0;
        loop {
            if budget.is_some_and(|b| started.elapsed() >= b) {
                let left = self.inner.open_minutes.lock().count();
                tracing::info!(
                    written,
                    left,
                    "historian: open minute roll-ups left for the next start to rebuild"
                );
                return Ok(written);
            }
            let tx = s
                .writer()
                .begin()
                .await
                .map_err(db("writing historian roll-ups"))?;
            let plan = self.inner.open_minutes.lock().plan_close(20_000);
            written += plan.minutes.len() as u64;
            let last = plan.all;
            self.write_open_minutes(tx, plan, last.then_some(true))
                .await?;
            if last {
                return Ok(written);
            }
        }
    }

    /// SQLite: rebuilds the minute roll-ups an unclean stop left open (from
    /// the raw rows at or after the site's watermark). The historian's writer
    /// calls it when it starts; the first write does it otherwise. Returns
    /// the minutes rebuilt.
    pub async fn recover_open_minutes(&self) -> Result<u64> {
        let Some(s) = self.open_minutes_backend() else {
            return Ok(0);
        };
        let _gate = self.inner.open_gate.lock().await;
        self.recover_locked(s).await
    }

    /// The SQLite backend whose open minutes this store keeps: none on
    /// PostgreSQL, nor for another site's view.
    fn open_minutes_backend(&self) -> Option<&crate::store::SqliteBackend> {
        match &self.inner.backend {
            crate::store::Backend::Sqlite(s) if !self.view => Some(s),
            _ => None,
        }
    }

    /// [`Self::recover_open_minutes`] with the open minutes' gate held.
    async fn recover_locked(&self, s: &crate::store::SqliteBackend) -> Result<u64> {
        if self.inner.open_minutes.lock().recovered {
            return Ok(0);
        }
        let mut tx = s
            .writer()
            .begin()
            .await
            .map_err(db("rebuilding the historian's open minutes"))?;
        let (closed_through, rebuilt) = open_minutes::recover(&mut tx, &self.site).await?;
        tx.commit()
            .await
            .map_err(db("rebuilding the historian's open minutes"))?;
        self.inner.open_minutes.lock().start_at(closed_through);
        if rebuilt > 0 {
            tracing::warn!(
                minutes = rebuilt,
                "historian: rebuilt the minute roll-ups an unclean stop left open"
            );
        }
        Ok(rebuilt)
    }

    /// How many minute roll-ups are open in memory (SQLite).
    pub fn open_minutes(&self) -> usize {
        self.inner.open_minutes.lock().count()
    }

    /// Downsamples `from..to` into `buckets` buckets, for each tag, computed
    /// by the database: per bucket count, min, max, avg, the last sample and
    /// the Bad time. Tags never logged come back with no buckets.
    ///
    /// Reads the coarsest roll-up (hour, then minute) that still gives at
    /// least `buckets` points; then the bucket edges are whole minutes or
    /// hours, the first may start before `from` and the last end after `to`
    /// by less than one roll-up period, and each bucket says its edges.
    /// Shorter ranges read raw samples into equal buckets over exactly
    /// `from..to`.
    pub async fn trend(
        &self,
        tags: &[&str],
        from: Timestamp,
        to: Timestamp,
        buckets: u32,
    ) -> Result<Vec<TagTrend>> {
        check_range(from, to)?;
        if buckets == 0 || buckets > MAX_TREND_BUCKETS {
            return Err(StoreError::Invalid(format!(
                "trend of {buckets} buckets: ask for 1..={MAX_TREND_BUCKETS}"
            )));
        }
        let ids = self.tag_ids(tags, false).await?;
        let (f, t, n) = (from.as_millis(), to.as_millis(), buckets as i64);
        // i128: (to - from) * buckets may not fit i64 for absurd ranges. The
        // SQL does the same product in i64, so refuse what would overflow there.
        if (t as i128 - f as i128 + 1) * n as i128 > i64::MAX as i128 {
            return Err(StoreError::Invalid("trend time range too long".into()));
        }
        let level = Level::for_trend(t - f, n);
        // Roll-ups: every tag at once (on PostgreSQL one query: a year of
        // 10 tags is 87,600 hour rows, one plan instead of one per tag).
        let from_rollup = match level {
            Some(level) => {
                let mut logged: Vec<i64> = ids.values().copied().collect();
                logged.sort_unstable();
                self.trend_from_rollup(level, &logged, f, t, n).await?
            }
            None => HashMap::new(),
        };
        let mut out = Vec::with_capacity(tags.len());
        for &tag in tags {
            let Some(&id) = ids.get(tag) else {
                out.push(TagTrend {
                    tag: tag.to_string(),
                    buckets: Vec::new(),
                });
                continue;
            };
            let buckets = match level {
                // A tag asked twice gets its buckets twice.
                Some(_) => from_rollup.get(&id).cloned().unwrap_or_default(),
                None => self.trend_from_raw(id, f, t, n).await?,
            };
            out.push(TagTrend {
                tag: tag.to_string(),
                buckets,
            });
        }
        Ok(out)
    }

    /// A trend of one tag from raw samples (short ranges).
    async fn trend_from_raw(&self, id: i64, f: i64, t: i64, n: i64) -> Result<Vec<TrendBucket>> {
        // Bucket of a sample = (ts - from) * n / (to - from), integer division
        // on both engines. The newest sample per bucket is found by joining
        // back on the primary key (tag_id, ts), which makes it unique. A Bad
        // sample is held until the next sample in its bucket, or the bucket's
        // end (the first ts of the next bucket).
        const SQL: &str = "WITH s AS ( \
               SELECT ts, value, quality, (ts - $2) * $4 / ($3 - $2) AS bucket \
               FROM samples WHERE tag_id = $1 AND ts >= $2 AND ts < $3), \
             h AS (SELECT bucket, ts, value, quality, \
                      lead(ts) OVER (PARTITION BY bucket ORDER BY ts) AS nts FROM s), \
             b AS ( \
               SELECT bucket, count(*) AS n, min(value) AS mn, max(value) AS mx, \
                      avg(value) AS av, max(ts) AS last_ts, \
                      CAST(sum(CASE WHEN quality NOT IN (0, 1) THEN \
                          coalesce(nts, $2 + (($3 - $2) * (bucket + 1) + $4 - 1) / $4) - ts \
                          ELSE 0 END) AS BIGINT) AS bad \
               FROM h GROUP BY bucket) \
             SELECT b.bucket, b.n, b.mn, b.mx, b.av, b.last_ts, s.value, s.quality, b.bad \
             FROM b JOIN samples s ON s.tag_id = $1 AND s.ts = b.last_ts \
             ORDER BY b.bucket";
        let raw: Vec<BucketRow> = on_backend!(self, reader, |p| {
            sqlx::query_as(SQL)
                .bind(id)
                .bind(f)
                .bind(t)
                .bind(n)
                .fetch_all(p)
                .await
                .map_err(db("querying a historian trend"))?
        });
        let span = (t - f) as i128;
        let edge =
            |i: i64| Timestamp::from_millis((f as i128 + span * i as i128 / n as i128) as i64);
        Ok(raw
            .into_iter()
            .map(|(b, cnt, mn, mx, av, last_ts, last, q, bad)| TrendBucket {
                index: b as u32,
                start: edge(b),
                end: edge(b + 1),
                count: cnt.max(0) as u64,
                min: mn,
                max: mx,
                avg: av,
                last,
                last_ts: Timestamp::from_millis(last_ts),
                last_quality: quality_from_code(q),
                bad_ms: bad.max(0) as u64,
            })
            .collect())
    }

    /// Trends of several tags from a roll-up level, by tag id: each trend
    /// bucket gathers whole level buckets, so its edges are whole minutes or
    /// hours (see [`rollup::edges`]) and its min, max, count and last are
    /// exactly those of the raw samples between those edges.
    async fn trend_from_rollup(
        &self,
        level: Level,
        ids: &[i64],
        f: i64,
        t: i64,
        n: i64,
    ) -> Result<HashMap<i64, Vec<TrendBucket>>> {
        let table = level.table();
        // The counts of one level bucket fit 32 bits (an hour holds 3.6 M
        // ms), and PostgreSQL sums 32-bit integers into 64 bits far faster
        // than 64-bit ones into numeric.
        // A level bucket starting before `from` (at most one) divides to 0:
        // SQL integer division truncates towards zero, and it starts less
        // than one trend bucket before `from`.
        let grouped = |tag_filter: &str| {
            format!(
                "WITH g AS ( \
                   SELECT tag_id, (bucket - $2) * $4 / ($3 - $2) AS idx, \
                          CAST(sum(CAST(n AS INTEGER)) AS BIGINT) AS n, \
                          min(min_value) AS mn, max(max_value) AS mx, sum(sum_value) AS sm, \
                          CAST(sum(CAST(n_value AS INTEGER)) AS BIGINT) AS nv, \
                          max(bucket) AS lastb, \
                          CAST(sum(CAST(bad_ms AS INTEGER)) AS BIGINT) AS bad \
                   FROM {table} WHERE tag_id {tag_filter} AND bucket >= $5 AND bucket < $3 \
                   GROUP BY tag_id, (bucket - $2) * $4 / ($3 - $2)) "
            )
        };
        let first = rollup::bucket_of(f, level.width());
        let rows: Vec<MultiLevelRow> = match &self.inner.backend {
            crate::store::Backend::Sqlite(s) => {
                // One query per tag: SQLite walks each tag's primary-key
                // range in order and looks the last sample up by key (a
                // list of tags through json_each measured 4x slower).
                let sql = format!(
                    "{} SELECT g.tag_id, g.idx, g.n, g.mn, g.mx, g.sm, g.nv, r.last_ts, \
                            r.last_value, r.last_quality, g.bad \
                     FROM g JOIN {table} r ON r.tag_id = g.tag_id AND r.bucket = g.lastb \
                     ORDER BY g.idx",
                    grouped("= $1")
                );
                let mut rows = Vec::new();
                for &id in ids {
                    rows.append(
                        &mut self
                            .trend_of_tag_sqlite(s, &sql, level, id, (f, t, n), first)
                            .await?,
                    );
                }
                rows
            }
            crate::store::Backend::Postgres(p) => {
                // A plain join makes PostgreSQL hash every roll-up row of the
                // tags (it expects ten times the groups it gets); the lateral
                // lookup with LIMIT stays one primary-key probe per bucket.
                let sql = format!(
                    "{} SELECT g.tag_id, g.idx, g.n, g.mn, g.mx, g.sm, g.nv, r.last_ts, \
                            r.last_value, r.last_quality, g.bad \
                     FROM g CROSS JOIN LATERAL (SELECT last_ts, last_value, last_quality \
                         FROM {table} r WHERE r.tag_id = g.tag_id AND r.bucket = g.lastb \
                         LIMIT 1) r \
                     ORDER BY g.tag_id, g.idx",
                    grouped("= ANY($1)")
                );
                sqlx::query_as(&sql)
                    .bind(ids)
                    .bind(f)
                    .bind(t)
                    .bind(n)
                    .bind(first)
                    .fetch_all(p)
                    .await
                    .map_err(db("querying a historian trend"))?
            }
        };
        let edge = rollup::edges(level, f, t, n);
        let mut out: HashMap<i64, Vec<TrendBucket>> = HashMap::new();
        for (id, b, cnt, mn, mx, sm, nv, last_ts, last, q, bad) in rows {
            out.entry(id).or_default().push(TrendBucket {
                index: b as u32,
                start: Timestamp::from_millis(edge(b)),
                end: Timestamp::from_millis(edge(b + 1)),
                count: cnt.max(0) as u64,
                min: mn,
                max: mx,
                avg: sm.filter(|_| nv > 0).map(|s| s / nv as f64),
                last,
                last_ts: Timestamp::from_millis(last_ts),
                last_quality: quality_from_code(q),
                bad_ms: bad.max(0) as u64,
            });
        }
        Ok(out)
    }

    /// One tag's trend rows from a roll-up level on SQLite, with its open
    /// minute folded in. The stored rows and the open minute must be of the
    /// same moment: if the open minute changed while the rows were read (a
    /// batch closed it, or one is committing), it reads again.
    async fn trend_of_tag_sqlite(
        &self,
        s: &crate::store::SqliteBackend,
        sql: &str,
        level: Level,
        id: i64,
        (f, t, n): (i64, i64, i64),
        first: i64,
    ) -> Result<Vec<MultiLevelRow>> {
        let snapshot = || {
            let open = self.inner.open_minutes.lock();
            (open.committing, open.open_of(id))
        };
        let mut tries = 0;
        // After a few reads out of step with the writer, the last one holds
        // the open minutes' gate: no batch can change them meanwhile.
        let mut gate = None;
        loop {
            if tries == 20 {
                gate = Some(self.inner.open_gate.lock().await);
            }
            let before = snapshot();
            // One read transaction: the grouped rows and the stored bucket
            // of the open minute come from one snapshot.
            let mut tx = s
                .reader()
                .begin()
                .await
                .map_err(db("querying a historian trend"))?;
            let mut rows: Vec<MultiLevelRow> = sqlx::query_as(sql)
                .bind(id)
                .bind(f)
                .bind(t)
                .bind(n)
                .bind(first)
                .fetch_all(&mut *tx)
                .await
                .map_err(db("querying a historian trend"))?;
            if let Some(open) = &before.1 {
                let w = level.width();
                let stored =
                    rollup::stored_sqlite(&mut tx, level, id, rollup::bucket_of(open.bucket, w))
                        .await?;
                // A stored bucket recomputed from raw rows may hold the first
                // samples of the open minute: fold in only those after it.
                let part = match &stored {
                    Some(r) if r.last_ts >= open.first_ts => {
                        let raw: Vec<(i64, i64, Option<f64>, i32)> =
                            sqlx::query_as(rollup::BUCKET_RAW)
                                .bind(id)
                                .bind(r.last_ts + 1)
                                .bind(open.bucket + Level::Minute.width())
                                .fetch_all(&mut *tx)
                                .await
                                .map_err(db("querying a historian trend"))?;
                        rollup::roll_up(raw, Level::Minute.width()).pop()
                    }
                    _ => Some(open.clone()),
                };
                if let Some(part) = part {
                    open_minutes::fold_open(&mut rows, level, (f, t, n), stored.as_ref(), &part);
                }
            }
            drop(tx);
            let after = snapshot();
            if (!before.0 && !after.0 && before.1 == after.1) || gate.is_some() {
                return Ok(rows);
            }
            tries += 1;
            tokio::time::sleep(std::time::Duration::from_millis(1)).await;
        }
    }

    /// Raw samples of `tags` in `from..to`, oldest first, at most `limit` rows.
    pub async fn raw_samples(
        &self,
        tags: &[&str],
        from: Timestamp,
        to: Timestamp,
        limit: u32,
    ) -> Result<Vec<RawSample>> {
        check_range(from, to)?;
        let ids = self.tag_ids(tags, false).await?;
        let by_id: HashMap<i64, &str> = ids.iter().map(|(k, &v)| (v, &**k)).collect();
        let mut out = Vec::new();
        let mut cursor = (f_start(from), i64::MIN);
        while out.len() < limit as usize {
            let want = (limit as usize - out.len()).min(EXPORT_PAGE as usize) as i64;
            let page = self.page(&by_id, cursor, to, want).await?;
            let done = (page.len() as i64) < want;
            if let Some(l) = page.last() {
                cursor = (l.1.ts.as_millis(), l.0);
            }
            out.extend(page.into_iter().map(|(_, s)| s));
            if done {
                break;
            }
        }
        Ok(out)
    }

    /// Writes the raw samples of `tags` in `from..to` as CSV to `out`, oldest
    /// first, in pages (constant memory, any length). Columns:
    /// `time_utc,ts_ms,tag,value,quality`. Returns the number of data rows.
    pub async fn export_csv<W: AsyncWrite + Unpin>(
        &self,
        tags: &[&str],
        from: Timestamp,
        to: Timestamp,
        out: &mut W,
    ) -> Result<u64> {
        check_range(from, to)?;
        let io = |source| StoreError::Io {
            what: "a historian CSV export",
            source,
        };
        out.write_all(b"time_utc,ts_ms,tag,value,quality\n")
            .await
            .map_err(io)?;
        let ids = self.tag_ids(tags, false).await?;
        let by_id: HashMap<i64, &str> = ids.iter().map(|(k, &v)| (v, &**k)).collect();
        let mut cursor = (f_start(from), i64::MIN);
        let mut rows = 0u64;
        loop {
            let page = self.page(&by_id, cursor, to, EXPORT_PAGE).await?;
            let mut text = String::with_capacity(page.len() * 64);
            for (_, s) in &page {
                crate::csv::row(&mut text, s);
            }
            out.write_all(text.as_bytes()).await.map_err(io)?;
            rows += page.len() as u64;
            if (page.len() as i64) < EXPORT_PAGE {
                break;
            }
            if let Some(l) = page.last() {
                cursor = (l.1.ts.as_millis(), l.0);
            }
        }
        out.flush().await.map_err(io)?;
        Ok(rows)
    }

    /// One page of raw samples after `(ts, tag_id)` (keyset pagination: no
    /// OFFSET, so a long export stays linear).
    async fn page(
        &self,
        by_id: &HashMap<i64, &str>,
        after: (i64, i64),
        to: Timestamp,
        limit: i64,
    ) -> Result<Vec<(i64, RawSample)>> {
        if by_id.is_empty() {
            return Ok(Vec::new());
        }
        let rows: Vec<RawRow> = on_backend!(self, reader, |p| {
            let mut qb = QueryBuilder::new(
                "SELECT tag_id, ts, value, exact, quality FROM samples WHERE tag_id IN (",
            );
            let mut sep = qb.separated(", ");
            for id in by_id.keys() {
                sep.push_bind(*id);
            }
            qb.push(") AND ts < ")
                .push_bind(to.as_millis())
                .push(" AND (ts > ")
                .push_bind(after.0)
                .push(" OR (ts = ")
                .push_bind(after.0)
                .push(" AND tag_id > ")
                .push_bind(after.1)
                .push(")) ORDER BY ts, tag_id LIMIT ")
                .push_bind(limit);
            qb.build_query_as()
                .fetch_all(p)
                .await
                .map_err(db("reading raw historian samples"))?
        });
        Ok(rows
            .into_iter()
            .map(|(id, ts, value, exact, q)| {
                (
                    id,
                    RawSample {
                        tag: by_id.get(&id).copied().unwrap_or_default().to_string(),
                        ts: Timestamp::from_millis(ts),
                        value,
                        exact: exact.and_then(|x| x.parse().ok()),
                        quality: quality_from_code(q),
                    },
                )
            })
            .collect())
    }

    /// Deletes samples older than `before`: of one tag, or of all tags.
    /// Returns the number of rows deleted.
    pub async fn delete_samples_before(&self, tag: Option<&str>, before: Timestamp) -> Result<u64> {
        self.writable("deleting historian samples")?;
        let ids: Vec<i64> = match tag {
            Some(t) => self.tag_ids(&[t], false).await?.into_values().collect(),
            None => self.all_tag_ids().await?,
        };
        let mut deleted = 0;
        // Per tag, so each delete is a range scan of the primary key (no extra
        // index on ts to slow ingest down), and each transaction stays short
        // so the writer is not held for minutes.
        for id in ids {
            deleted += on_backend!(self, writer, |p| {
                sqlx::query("DELETE FROM samples WHERE tag_id = $1 AND ts < $2")
                    .bind(id)
                    .bind(before.as_millis())
                    .execute(p)
                    .await
                    .map_err(db("deleting old historian samples"))?
                    .rows_affected()
            });
        }
        Ok(deleted)
    }

    /// Applies a retention policy at `now`: raw samples per tag, roll-ups per
    /// level. Returns the number of rows deleted (raw and roll-up).
    pub async fn apply_retention(&self, policy: &RetentionPolicy, now: Timestamp) -> Result<u64> {
        self.writable("applying historian retention")?;
        const DAY_MS: i64 = 86_400_000;
        let all: Vec<(i64, String)> = on_backend!(self, reader, |p| {
            sqlx::query_as("SELECT id, name FROM tags WHERE site = $1")
                .bind(&*self.site)
                .fetch_all(p)
                .await
                .map_err(db("listing historian tags"))?
        });
        let mut deleted = 0;
        for (id, name) in &all {
            let days = policy
                .per_tag_days
                .get(name)
                .copied()
                .or(policy.default_days);
            let Some(days) = days else { continue };
            let cutoff = now.as_millis().saturating_sub(days as i64 * DAY_MS);
            deleted += on_backend!(self, writer, |p| {
                sqlx::query("DELETE FROM samples WHERE tag_id = $1 AND ts < $2")
                    .bind(*id)
                    .bind(cutoff)
                    .execute(p)
                    .await
                    .map_err(db("applying historian retention"))?
                    .rows_affected()
            });
        }
        for (level, days) in [
            (Level::Minute, policy.minute_days),
            (Level::Hour, policy.hour_days),
        ] {
            let Some(days) = days else { continue };
            // Only buckets wholly older than the cutoff go.
            let cutoff = rollup::bucket_of(
                now.as_millis().saturating_sub(days as i64 * DAY_MS),
                level.width(),
            );
            let sql = rollup::delete_sql(level);
            for (id, _) in &all {
                deleted += on_backend!(self, writer, |p| {
                    sqlx::query(&sql)
                        .bind(*id)
                        .bind(cutoff)
                        .execute(p)
                        .await
                        .map_err(db("applying historian roll-up retention"))?
                        .rows_affected()
                });
            }
        }
        if deleted > 0 {
            tracing::info!(deleted, "historian retention applied");
        }
        Ok(deleted)
    }

    async fn all_tag_ids(&self) -> Result<Vec<i64>> {
        Ok(on_backend!(self, reader, |p| {
            sqlx::query_scalar("SELECT id FROM tags WHERE site = $1")
                .bind(&*self.site)
                .fetch_all(p)
                .await
                .map_err(db("listing historian tags"))?
        }))
    }

    /// Names of every tag the historian has logged.
    pub async fn historian_tags(&self) -> Result<Vec<String>> {
        Ok(on_backend!(self, reader, |p| {
            sqlx::query_scalar("SELECT name FROM tags WHERE site = $1 ORDER BY name")
                .bind(&*self.site)
                .fetch_all(p)
                .await
                .map_err(db("listing historian tags"))?
        }))
    }
}

/// Rows in PostgreSQL's COPY text format (tab-separated, `\\N` for NULL).
/// Values print as Rust's shortest round-trip decimal, which PostgreSQL
/// reads back to the same float; exact integers are plain digits.
fn copy_text(rows: &[Row]) -> Vec<u8> {
    use std::fmt::Write;
    let mut out = String::with_capacity(rows.len() * 40);
    for r in rows {
        let _ = write!(out, "{}\t{}\t", r.tag_id, r.ts);
        match r.value {
            Some(v) => {
                let _ = write!(out, "{v}");
            }
            None => out.push_str("\\N"),
        }
        out.push('\t');
        out.push_str(r.exact.as_deref().unwrap_or("\\N"));
        let _ = writeln!(out, "\t{}", r.quality);
    }
    out.into_bytes()
}

/// Runs one `COPY ... FROM STDIN` with `data` on the transaction's connection.
async fn copy_in(
    tx: &mut sqlx::Transaction<'_, sqlx::Postgres>,
    statement: &str,
    data: &[u8],
) -> std::result::Result<(), sqlx::Error> {
    let mut copy = (**tx).copy_in_raw(statement).await?;
    copy.send(data).await?;
    copy.finish().await?;
    Ok(())
}

/// The keyset cursor that starts at `from` inclusive.
fn f_start(from: Timestamp) -> i64 {
    from.as_millis().saturating_sub(1)
}

#[cfg(test)]
mod sample_rows {
    use super::*;
    use gridscada_tagdb::{Quality, Sample};

    #[test]
    fn a_sample_becomes_its_row_and_a_bad_one_a_gap() {
        let at = Timestamp::from_millis(1_600_000_000_000);
        let row = HistorySample::of("T".into(), &Sample::good(12.5, at)).unwrap();
        assert_eq!(
            (row.ts, row.value, row.quality),
            (at, Some(12.5), QualityCode::Good)
        );
        let mut bad = Sample::good(12.5, at);
        bad.quality = Quality::bad("site offline");
        let row = HistorySample::of("T".into(), &bad).unwrap();
        assert_eq!((row.value, row.quality), (None, QualityCode::Bad));
        assert!(HistorySample::of("T".into(), &Sample::good("text", at)).is_none());
        assert!(
            HistorySample::of(
                "T".into(),
                &Sample::never_read(gridscada_tagdb::Value::Float(0.0))
            )
            .is_none(),
            "never read"
        );
    }
}
