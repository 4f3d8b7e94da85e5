//! Historian roll-ups: per tag, per minute and per hour, the count, min, max,
//! sum, first and last sample and the Bad time, kept as samples are written,
//! so a trend over a month or a year reads thousands of rows, not millions.
//!
//! **Owns:** the `samples_minute` and `samples_hour` tables, and how a trend
//! picks its level. **Must not touch:** the raw `samples` table (only reads
//! it back to redo a bucket that a late or repeated sample changed).
//!
//! Maintenance is incremental: a batch is rolled up in memory, and each of
//! its buckets is either new, appended to the stored bucket (all its samples
//! after the stored last one: merged by the database in the upsert itself,
//! without reading the stored bucket first; one statement for both levels
//! on PostgreSQL, one per level on SQLite), or,
//! for a late or repeated sample, recomputed from the raw rows of that one
//! bucket.

use std::collections::HashSet;

use sqlx::{PgConnection, QueryBuilder, SqliteConnection};

use crate::error::db;
use crate::Result;

/// A roll-up level: the width of its buckets and its table.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Level {
    Minute,
    Hour,
}

impl Level {
    pub(crate) const ALL: [Level; 2] = [Level::Minute, Level::Hour];

    /// Bucket width in ms.
    pub(crate) fn width(self) -> i64 {
        match self {
            Level::Minute => 60_000,
            Level::Hour => 3_600_000,
        }
    }

    pub(crate) fn table(self) -> &'static str {
        match self {
            Level::Minute => "samples_minute",
            Level::Hour => "samples_hour",
        }
    }

    /// The coarsest level whose buckets still give at least `buckets`
    /// points over `span_ms`; `None`: the range is short, read raw samples.
    pub(crate) fn for_trend(span_ms: i64, buckets: i64) -> Option<Level> {
        // Level bucket width <= span / buckets, in integers.
        [Level::Hour, Level::Minute]
            .into_iter()
            .find(|l| l.width() as i128 * buckets as i128 <= span_ms as i128)
    }
}

/// Start of the bucket of width `w` holding `ts` (floor, also before 1970).
pub(crate) fn bucket_of(ts: i64, w: i64) -> i64 {
    ts - ts.rem_euclid(w)
}

/// Quality codes other than good (0) and uncertain (1) read as Bad.
fn is_bad(code: i32) -> bool {
    !matches!(code, 0 | 1)
}

/// The columns of a roll-up row, in table order.
pub(crate) const COLUMNS: &str = "tag_id, bucket, n, n_value, min_value, max_value, sum_value, \
                       first_ts, first_value, last_ts, last_value, last_quality, bad_ms";

/// One roll-up bucket of one tag.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Agg {
    pub tag_id: i64,
    pub bucket: i64,
    /// Samples, and those of them with a value (min, max, sum are over these).
    pub n: i64,
    pub n_value: i64,
    pub min: Option<f64>,
    pub max: Option<f64>,
    pub sum: Option<f64>,
    pub first_ts: i64,
    pub first_value: Option<f64>,
    pub last_ts: i64,
    pub last_value: Option<f64>,
    pub last_quality: i32,
    /// Time Bad within the bucket: each sample held until the next sample in
    /// the bucket, the last one until the bucket's end.
    pub bad_ms: i64,
}

impl Agg {
    fn start(tag_id: i64, bucket: i64, w: i64, ts: i64, v: Option<f64>, q: i32) -> Agg {
        Agg {
            tag_id,
            bucket,
            n: 1,
            n_value: v.is_some() as i64,
            min: v,
            max: v,
            sum: v,
            first_ts: ts,
            first_value: v,
            last_ts: ts,
            last_value: v,
            last_quality: q,
            bad_ms: if is_bad(q) { bucket + w - ts } else { 0 },
        }
    }

    /// Adds a sample newer than every sample already in.
    fn push(&mut self, w: i64, ts: i64, v: Option<f64>, q: i32) {
        let end = self.bucket + w;
        // The previous last sample was held to the bucket's end; it ends here.
        if is_bad(self.last_quality) {
            self.bad_ms -= end - ts;
        }
        if is_bad(q) {
            self.bad_ms += end - ts;
        }
        self.n += 1;
        if let Some(v) = v {
            self.n_value += 1;
            self.min = Some(self.min.map_or(v, |m| m.min(v)));
            self.max = Some(self.max.map_or(v, |m| m.max(v)));
            self.sum = Some(self.sum.map_or(v, |s| s + v));
        }
        self.last_ts = ts;
        self.last_value = v;
        self.last_quality = q;
    }

    /// `self` followed by `later` (same bucket of width `w`), whose samples
    /// all come after `self`'s: what the database's merge does
    /// (`merge_sql`), and how open minutes join their hour.
    pub(crate) fn append(&mut self, w: i64, later: &Agg) {
        let end = self.bucket + w;
        if is_bad(self.last_quality) {
            self.bad_ms -= end - later.first_ts;
        }
        self.bad_ms += later.bad_ms;
        self.n += later.n;
        self.n_value += later.n_value;
        self.min = opt(self.min, later.min, f64::min);
        self.max = opt(self.max, later.max, f64::max);
        self.sum = opt(self.sum, later.sum, |a, b| a + b);
        self.last_ts = later.last_ts;
        self.last_value = later.last_value;
        self.last_quality = later.last_quality;
    }

    /// This bucket of width `from` as a part of the wider bucket of width
    /// `to` holding it: its last sample is then held to the wider end.
    pub(crate) fn widened(&self, from: i64, to: i64) -> Agg {
        let bucket = bucket_of(self.bucket, to);
        let mut a = self.clone();
        if is_bad(a.last_quality) {
            a.bad_ms += (bucket + to) - (self.bucket + from);
        }
        a.bucket = bucket;
        a
    }
}

/// `f` of two optional values, or the one that is there.
pub(crate) fn opt(a: Option<f64>, b: Option<f64>, f: impl Fn(f64, f64) -> f64) -> Option<f64> {
    match (a, b) {
        (Some(a), Some(b)) => Some(f(a, b)),
        (a, b) => a.or(b),
    }
}

/// Rolls up samples `(tag_id, ts, value, quality)` sorted by tag then time,
/// one per key, into buckets of width `w`.
pub(crate) fn roll_up(
    rows: impl IntoIterator<Item = (i64, i64, Option<f64>, i32)>,
    w: i64,
) -> Vec<Agg> {
    let mut out: Vec<Agg> = Vec::new();
    for (tag_id, ts, v, q) in rows {
        let bucket = bucket_of(ts, w);
        match out.last_mut() {
            Some(a) if a.tag_id == tag_id && a.bucket == bucket => a.push(w, ts, v, q),
            _ => out.push(Agg::start(tag_id, bucket, w, ts, v, q)),
        }
    }
    out
}

/// Raw rows of SQLite per roll-up statement: 13 parameters each.
pub(crate) const SQLITE_ROWS: usize = 500;

/// `items` in multi-row statements of `max` rows, the rest in chunks of
/// descending powers of two: a statement's text depends on its row count,
/// and this way a few shapes recur (and stay prepared in the connection's
/// cache) instead of a new one to parse for every batch's remainder.
pub(crate) fn statement_chunks<T>(items: &[T], max: usize) -> impl Iterator<Item = &[T]> {
    let max = max.max(1);
    let mut rest = items;
    std::iter::from_fn(move || {
        if rest.is_empty() {
            return None;
        }
        let n = if rest.len() >= max {
            max
        } else {
            1 << rest.len().ilog2()
        };
        let (chunk, tail) = rest.split_at(n);
        rest = tail;
        Some(chunk)
    })
}

/// Inserts a batch's buckets, or appends each to the stored bucket in the
/// same statement where all its samples come after the stored last one
/// (the merge of [`Agg::append`], in SQL: no read of the stored buckets
/// first). A bucket it does not write (a late or repeated sample: the
/// `WHERE` fails) is recomputed from raw rows; PostgreSQL returns the keys
/// written, SQLite's count of changed rows says whether any was left.
fn merge_sql(level: Level) -> String {
    let end = format!("(r.bucket + {})", level.width());
    let pick = |f: &str, op: &str| {
        format!(
            "{f} = CASE WHEN r.{f} IS NULL THEN excluded.{f} \
             WHEN excluded.{f} IS NULL THEN r.{f} \
             WHEN excluded.{f} {op} r.{f} THEN excluded.{f} ELSE r.{f} END"
        )
    };
    format!(
        " ON CONFLICT (tag_id, bucket) DO UPDATE SET \
         n = r.n + excluded.n, n_value = r.n_value + excluded.n_value, {}, {}, \
         sum_value = COALESCE(r.sum_value + excluded.sum_value, r.sum_value, excluded.sum_value), \
         last_ts = excluded.last_ts, last_value = excluded.last_value, \
         last_quality = excluded.last_quality, \
         bad_ms = r.bad_ms + excluded.bad_ms - CASE WHEN r.last_quality IN (0, 1) THEN 0 \
         ELSE {end} - excluded.first_ts END \
         WHERE excluded.first_ts > r.last_ts",
        pick("min_value", "<"),
        pick("max_value", ">"),
    )
}

/// The buckets of `batch` the merge did not write (not in `written`),
/// recomputed from their raw rows on `conn` (either backend's connection).
macro_rules! recompute {
    ($conn:expr, $batch:expr, $written:expr, $w:expr) => {{
        let mut redo = Vec::new();
        for a in $batch
            .iter()
            .filter(|a| !$written.contains(&(a.tag_id, a.bucket)))
        {
            let raw: Vec<(i64, i64, Option<f64>, i32)> = sqlx::query_as(BUCKET_RAW)
                .bind(a.tag_id)
                .bind(a.bucket)
                .bind(a.bucket + $w)
                .fetch_all(&mut *$conn)
                .await
                .map_err(db("re-reading a historian bucket"))?;
            redo.extend(roll_up(raw, $w));
        }
        redo
    }};
}

/// The stored bucket of `level` of one tag, if any (SQLite).
pub(crate) async fn stored_sqlite(
    conn: &mut SqliteConnection,
    level: Level,
    tag_id: i64,
    bucket: i64,
) -> Result<Option<Agg>> {
    type Stored = (
        i64,
        i64,
        i64,
        i64,
        Option<f64>,
        Option<f64>,
        Option<f64>,
        i64,
        Option<f64>,
        i64,
        Option<f64>,
        i32,
        i64,
    );
    let row: Option<Stored> = sqlx::query_as(&format!(
        "SELECT {COLUMNS} FROM {} WHERE tag_id = $1 AND bucket = $2",
        level.table()
    ))
    .bind(tag_id)
    .bind(bucket)
    .fetch_optional(conn)
    .await
    .map_err(db("querying a historian trend"))?;
    Ok(row.map(|r| Agg {
        tag_id: r.0,
        bucket: r.1,
        n: r.2,
        n_value: r.3,
        min: r.4,
        max: r.5,
        sum: r.6,
        first_ts: r.7,
        first_value: r.8,
        last_ts: r.9,
        last_value: r.10,
        last_quality: r.11,
        bad_ms: r.12,
    }))
}

/// The statement re-reading one bucket's raw rows (`$1` tag, `$2..$3`).
pub(crate) const BUCKET_RAW: &str = "SELECT tag_id, ts, value, quality FROM samples \
     WHERE tag_id = $1 AND ts >= $2 AND ts < $3 ORDER BY ts";

/// Brings both levels up to date with a batch already inserted in the raw
/// table in the same transaction: `levels`, the batch rolled up per level
/// ([`roll_up`] of its rows, sorted by tag then time, one per key).
pub(crate) async fn maintain_sqlite(
    conn: &mut SqliteConnection,
    levels: &[(Level, &[Agg])],
) -> Result<()> {
    for &(level, batch) in levels {
        let w = level.width();
        let mut written = HashSet::with_capacity(batch.len());
        for chunk in statement_chunks(batch, SQLITE_ROWS) {
            let mut qb =
                QueryBuilder::new(format!("INSERT INTO {} AS r ({COLUMNS}) ", level.table()));
            push_sqlite_values(&mut qb, chunk);
            qb.push(merge_sql(level));
            // Each row is inserted or merged, or (a late or repeated sample)
            // left for a recompute. The count says whether any was left;
            // then the whole chunk is recomputed, which is rare and cheaper
            // than returning every key of every batch.
            let changed = qb
                .build()
                .execute(&mut *conn)
                .await
                .map_err(db("writing historian roll-ups"))?
                .rows_affected();
            if changed == chunk.len() as u64 {
                written.extend(chunk.iter().map(|a| (a.tag_id, a.bucket)));
            }
        }
        let redo = recompute!(conn, batch, &written, w);
        for chunk in statement_chunks(&redo, SQLITE_ROWS) {
            let mut qb = QueryBuilder::new(format!("INSERT INTO {} ({COLUMNS}) ", level.table()));
            push_sqlite_values(&mut qb, chunk);
            qb.push(UPSERT);
            qb.build()
                .execute(&mut *conn)
                .await
                .map_err(db("writing historian roll-ups"))?;
        }
    }
    Ok(())
}

pub(crate) fn push_sqlite_values(qb: &mut QueryBuilder<'_, sqlx::Sqlite>, chunk: &[Agg]) {
    qb.push_values(chunk, |mut b, a| {
        b.push_bind(a.tag_id)
            .push_bind(a.bucket)
            .push_bind(a.n)
            .push_bind(a.n_value)
            .push_bind(a.min)
            .push_bind(a.max)
            .push_bind(a.sum)
            .push_bind(a.first_ts)
            .push_bind(a.first_value)
            .push_bind(a.last_ts)
            .push_bind(a.last_value)
            .push_bind(a.last_quality)
            .push_bind(a.bad_ms);
    });
}

/// A recomputed bucket replaces the stored one.
const UPSERT: &str = " ON CONFLICT (tag_id, bucket) DO UPDATE SET \
    n = excluded.n, n_value = excluded.n_value, min_value = excluded.min_value, \
    max_value = excluded.max_value, sum_value = excluded.sum_value, \
    first_ts = excluded.first_ts, first_value = excluded.first_value, \
    last_ts = excluded.last_ts, last_value = excluded.last_value, \
    last_quality = excluded.last_quality, bad_ms = excluded.bad_ms";

/// [`maintain_sqlite`] for PostgreSQL: one statement merges both levels
/// (an upsert per level, as arrays, each in a `WITH`). The caller holds the
/// historian's advisory lock, so two writers never merge into the same
/// bucket at once.
pub(crate) async fn maintain_pg(
    conn: &mut PgConnection,
    levels: &[(Level, Vec<Agg>)],
) -> Result<()> {
    let merges: Vec<String> = levels.iter().map(|(l, _)| merge_sql(*l)).collect();
    let parts: Vec<(Level, &[Agg], &str)> = levels
        .iter()
        .zip(&merges)
        .map(|((l, b), m)| (*l, b.as_slice(), m.as_str()))
        .collect();
    let written: HashSet<(i64, i64, i64)> =
        pg_upsert(&mut *conn, &parts).await?.into_iter().collect();
    let mut redone: Vec<(Level, Vec<Agg>)> = Vec::new();
    for (i, (level, batch)) in levels.iter().enumerate() {
        let written: HashSet<(i64, i64)> = written
            .iter()
            .filter(|k| k.0 == i as i64)
            .map(|k| (k.1, k.2))
            .collect();
        let redo = recompute!(conn, batch, &written, level.width());
        if !redo.is_empty() {
            redone.push((*level, redo));
        }
    }
    if !redone.is_empty() {
        let parts: Vec<(Level, &[Agg], &str)> = redone
            .iter()
            .map(|(l, b)| (*l, b.as_slice(), UPSERT))
            .collect();
        pg_upsert(&mut *conn, &parts).await?;
    }
    Ok(())
}

/// Each part's buckets as an `INSERT ... SELECT FROM UNNEST` of arrays with
/// its `ON CONFLICT` clause (the merge or a replace), all in one statement;
/// returns the keys written as (part's index, tag id, bucket).
async fn pg_upsert(
    conn: &mut PgConnection,
    parts: &[(Level, &[Agg], &str)],
) -> Result<Vec<(i64, i64, i64)>> {
    use std::fmt::Write;
    // The array type of each column of COLUMNS, in order.
    const ARRAYS: [&str; 13] = [
        "bigint", "bigint", "bigint", "bigint", "float8", "float8", "float8", "bigint", "float8",
        "bigint", "float8", "int4", "bigint",
    ];
    let mut sql = String::from("WITH ");
    for (i, (level, _, conflict)) in parts.iter().enumerate() {
        let arrays: Vec<String> = ARRAYS
            .iter()
            .enumerate()
            .map(|(k, ty)| format!("${}::{ty}[]", i * ARRAYS.len() + k + 1))
            .collect();
        let _ = write!(
            sql,
            "{}u{i} AS (INSERT INTO {} AS r ({COLUMNS}) SELECT * FROM UNNEST({}){conflict} \
             RETURNING {i}::bigint, tag_id, bucket)",
            if i == 0 { "" } else { ", " },
            level.table(),
            arrays.join(", "),
        );
    }
    let selects: Vec<String> = (0..parts.len())
        .map(|i| format!("SELECT * FROM u{i}"))
        .collect();
    let _ = write!(sql, " {}", selects.join(" UNION ALL "));
    let mut query = sqlx::query_as(&sql);
    for (_, batch, _) in parts {
        macro_rules! col {
            ($f:ident) => {
                batch.iter().map(|a| a.$f).collect::<Vec<_>>()
            };
        }
        query = query
            .bind(col!(tag_id))
            .bind(col!(bucket))
            .bind(col!(n))
            .bind(col!(n_value))
            .bind(col!(min))
            .bind(col!(max))
            .bind(col!(sum))
            .bind(col!(first_ts))
            .bind(col!(first_value))
            .bind(col!(last_ts))
            .bind(col!(last_value))
            .bind(col!(last_quality))
            .bind(col!(bad_ms));
    }
    query
        .fetch_all(conn)
        .await
        .map_err(db("writing historian roll-ups"))
}

/// The edges of a trend of `n` buckets over `f..t` read from `level`: bucket
/// `i` holds the level's buckets whose start `b` has
/// `(b - f) * n / (t - f) == i` (the raw trend's rule applied to `b`), so its
/// edges are whole minutes or hours: the first starts at the level bucket
/// holding `f`, the last ends at the first level edge at or after `t`. A
/// trend read from roll-ups therefore has exactly the min, max and count a
/// raw query over the same edges gives.
pub(crate) fn edges(level: Level, f: i64, t: i64, n: i64) -> impl Fn(i64) -> i64 {
    let w = level.width();
    let span = (t - f) as i128;
    move |i: i64| {
        if i <= 0 {
            return bucket_of(f, w);
        }
        if i >= n {
            return bucket_of(t - 1, w) + w;
        }
        // The first ts with (ts - f) * n >= span * i, rounded up to the level.
        let x = f as i128 + (span * i as i128 + n as i128 - 1) / n as i128;
        let x = x as i64;
        let b = bucket_of(x, w);
        if b == x {
            b
        } else {
            b + w
        }
    }
}

/// The statement deleting one tag's (`$1`) roll-up rows of `level` whose
/// bucket starts before `$2` (a range scan of the primary key).
pub(crate) fn delete_sql(level: Level) -> String {
    format!(
        "DELETE FROM {} WHERE tag_id = $1 AND bucket < $2",
        level.table()
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn appending_equals_rolling_up_at_once() {
        let w = 60_000;
        let rows: Vec<(i64, i64, Option<f64>, i32)> = vec![
            (1, 0, Some(1.0), 0),
            (1, 10_000, Some(5.0), 2),
            (1, 20_000, None, 2),
            (1, 30_000, Some(-1.0), 0),
            (1, 50_000, Some(2.0), 2),
        ];
        let whole = roll_up(rows.clone(), w);
        assert_eq!(whole.len(), 1);
        assert_eq!(whole[0].bad_ms, 20_000 + 10_000);
        for cut in 1..rows.len() {
            let mut a = roll_up(rows[..cut].to_vec(), w).remove(0);
            let b = roll_up(rows[cut..].to_vec(), w).remove(0);
            a.append(w, &b);
            assert_eq!(a, whole[0], "cut at {cut}");
        }
    }

    #[test]
    fn statements_take_whole_chunks_then_powers_of_two() {
        let items: Vec<u32> = (0..1_300).collect();
        let sizes: Vec<usize> = statement_chunks(&items, 500).map(<[u32]>::len).collect();
        assert_eq!(sizes, [500, 500, 256, 32, 8, 4]);
        let again: Vec<u32> = statement_chunks(&items, 500).flatten().copied().collect();
        assert_eq!(again, items, "every item once, in order");
        assert_eq!(statement_chunks(&items[..0], 500).count(), 0);
        assert_eq!(
            statement_chunks(&items[..3], 0)
                .map(<[u32]>::len)
                .collect::<Vec<_>>(),
            [1, 1, 1]
        );
    }

    #[test]
    fn buckets_floor_before_1970_too() {
        assert_eq!(bucket_of(-1, 60_000), -60_000);
        assert_eq!(bucket_of(59_999, 60_000), 0);
        assert_eq!(bucket_of(60_000, 60_000), 60_000);
    }

    #[test]
    fn levels_give_at_least_the_points_asked() {
        const DAY: i64 = 86_400_000;
        assert_eq!(Level::for_trend(DAY, 500), Some(Level::Minute));
        assert_eq!(Level::for_trend(365 * DAY, 500), Some(Level::Hour));
        assert_eq!(Level::for_trend(8 * 3_600_000, 500), None);
        assert_eq!(Level::for_trend(500 * 60_000, 500), Some(Level::Minute));
    }

    #[test]
    fn edges_are_on_the_grid_and_match_the_rule() {
        let (f, t, n) = (1_700_000_012_345i64, 1_700_000_012_345 + 86_400_000, 500);
        let e = edges(Level::Minute, f, t, n);
        assert_eq!(e(0) % 60_000, 0);
        assert!(e(0) <= f && e(n) >= t);
        for i in 0..n {
            assert!(e(i) < e(i + 1));
            // Every level bucket in [e(i), e(i+1)) maps to i by the raw rule.
            let mut b = e(i);
            while b < e(i + 1) {
                let idx = ((b - f).max(0) as i128 * n as i128 / (t - f) as i128) as i64;
                assert_eq!(idx, i, "bucket {b}");
                b += 60_000;
            }
        }
    }
}
