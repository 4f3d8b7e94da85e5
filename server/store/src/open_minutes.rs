//! The SQLite historian's open minutes: each tag's current minute roll-up,
//! folded in memory as batches come and written once, when the minute is
//! over, with its hour merged in then.
//!
//! At a million tags every logged sample lands on its own page of each
//! roll-up table; writing a minute once instead of at every batch that
//! touches it halves the pages written per sample (docs/BENCHMARKS.md,
//! "open minutes"). PostgreSQL keeps writing its roll-ups with their samples:
//! a redundant pair shares the database and may take over at any moment.
//!
//! The rules, per tag:
//! - a minute at or after the tag's floor (the watermark, and the end of its
//!   last written minute) joins the open minute, or closes it and opens the
//!   next;
//! - a sample before that floor is written to the roll-ups at once, the
//!   way PostgreSQL does;
//! - a sample before the open minute's last one (late or repeated) writes
//!   the open minute, and the floor moves past it: the sample is then
//!   written at once;
//! - the roll-up clock is the newest batch's median timestamp (a device
//!   with a wrong clock does not move it); once a minute ends before the
//!   clock less [`GRACE_MS`], every tag's open minute before it is written
//!   and the durable watermark (`historian_rollup_state`) moves past it.
//!
//! A trend folds the open minutes of its tags into what it reads
//! ([`fold_open`]). After a crash, the minutes at or after the watermark
//! are rebuilt from the raw rows before the historian's first write
//! ([`recover`]: the historian's writer does it when it starts; a process
//! that only reads, such as a command, leaves it to the server); a clean
//! stop writes every open minute first ([`crate::Store::close_open_minutes`]).
//! The state is per site: one server writes a site's history.
//!
//! **Owns:** the open minutes, the roll-up clock and the watermark row.
//! **Must not touch:** the raw samples (read only, to rebuild) and the
//! roll-up tables (written through [`rollup::maintain_sqlite`]).

use sqlx::{QueryBuilder, SqliteConnection};

use crate::error::db;
use crate::rollup::{self, bucket_of, Agg, Level};
use crate::Result;

const MINUTE: i64 = 60_000;
const HOUR: i64 = 3_600_000;

/// How long after a minute's end (by the roll-up clock) its stragglers may
/// still join it; later ones are written to the roll-ups at once.
pub(crate) const GRACE_MS: i64 = 60_000;

/// A minute starting this far after the roll-up clock is written at once
/// and moves no floor: a device stamping samples in the future (a wrong
/// clock) must not close every tag's minutes for good.
const HORIZON_MS: i64 = 3_600_000;

/// The roll-up clock stays within this many ms of 1970 (±285,000 years),
/// so no bucket arithmetic on it can overflow.
const CLOCK_BOUND: i64 = 1 << 53;

/// Tag ids from here on keep no open minute (their roll-ups are written with
/// their samples): bounds the table, which is indexed by tag id.
const MAX_SLOTS: i64 = 1 << 22;

/// Open minutes the clock's sweep writes with one batch, at most: a
/// million quiet tags are written over a few batches, not in one.
const SWEEP_PER_BATCH: usize = 25_000;

/// Tags per statement when rebuilding after a crash (bounds its memory).
const RECOVER_TAGS: i64 = 20_000;

/// One tag's open minute, in 88 bytes (`Agg` takes 168): `n == 0` when
/// none is open; NaN stands for no value (the historian stores finite
/// values only).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Slot {
    bucket: i64,
    n: u32,
    n_value: u32,
    min: f64,
    max: f64,
    sum: f64,
    first_ts: i64,
    first_value: f64,
    last_ts: i64,
    last_value: f64,
    last_quality: i32,
    /// At most a minute: fits.
    bad_ms: i32,
    /// Minutes of this tag before this are written.
    closed_next: i64,
}

fn nan(v: Option<f64>) -> f64 {
    v.unwrap_or(f64::NAN)
}

fn some(v: f64) -> Option<f64> {
    (!v.is_nan()).then_some(v)
}

impl Slot {
    const EMPTY: Slot = Slot {
        bucket: 0,
        n: 0,
        n_value: 0,
        min: f64::NAN,
        max: f64::NAN,
        sum: f64::NAN,
        first_ts: 0,
        first_value: f64::NAN,
        last_ts: 0,
        last_value: f64::NAN,
        last_quality: 0,
        bad_ms: 0,
        closed_next: i64::MIN,
    };

    fn open(&self, tag_id: i64) -> Option<Agg> {
        (self.n > 0).then(|| Agg {
            tag_id,
            bucket: self.bucket,
            n: self.n as i64,
            n_value: self.n_value as i64,
            min: some(self.min),
            max: some(self.max),
            sum: some(self.sum),
            first_ts: self.first_ts,
            first_value: some(self.first_value),
            last_ts: self.last_ts,
            last_value: some(self.last_value),
            last_quality: self.last_quality,
            bad_ms: self.bad_ms as i64,
        })
    }

    /// Holds `a` as the open minute (a minute holds at most 60,000 samples
    /// of one tag, one per millisecond, so the counts fit).
    fn hold(&mut self, a: &Agg) {
        *self = Slot {
            bucket: a.bucket,
            n: a.n as u32,
            n_value: a.n_value as u32,
            min: nan(a.min),
            max: nan(a.max),
            sum: nan(a.sum),
            first_ts: a.first_ts,
            first_value: nan(a.first_value),
            last_ts: a.last_ts,
            last_value: nan(a.last_value),
            last_quality: a.last_quality,
            bad_ms: a.bad_ms as i32,
            closed_next: self.closed_next,
        };
    }

    /// The open minute is written: none is open, and the tag's later
    /// samples before its end are written at once.
    fn close(&mut self) {
        if self.n > 0 {
            self.closed_next = self.closed_next.max(self.bucket.saturating_add(MINUTE));
            self.n = 0;
        }
    }
}

/// Tags' slots in a chunk of the table.
const CHUNK: usize = 4096;

/// The slots by tag id, in chunks: growing never copies the table (88 MiB
/// at a million tags, which the first rows of a new plant register a few
/// thousand at a time).
#[derive(Default)]
struct Slots(Vec<Box<[Slot]>>);

impl Slots {
    fn get(&self, i: usize) -> Option<&Slot> {
        self.0.get(i / CHUNK).map(|c| &c[i % CHUNK])
    }

    fn get_mut(&mut self, i: usize) -> &mut Slot {
        while self.0.len() <= i / CHUNK {
            self.0.push(vec![Slot::EMPTY; CHUNK].into_boxed_slice());
        }
        &mut self.0[i / CHUNK][i % CHUNK]
    }

    /// The slots from tag id `from` on, with their ids.
    fn from(&self, from: usize) -> impl Iterator<Item = (usize, &Slot)> {
        self.0
            .iter()
            .enumerate()
            .skip(from / CHUNK)
            .flat_map(|(c, chunk)| {
                chunk
                    .iter()
                    .enumerate()
                    .map(move |(k, s)| (c * CHUNK + k, s))
            })
            .skip(from % CHUNK)
    }

    fn len(&self) -> usize {
        self.0.len() * CHUNK
    }
}

/// The open minutes of one database, with the roll-up clock.
pub(crate) struct OpenMinutes {
    /// By tag id.
    slots: Slots,
    /// Minutes before this are written, or written at the latest by the
    /// sweep under way, for every tag: samples before it are written at once.
    cutoff: i64,
    /// Minutes before this are written for every tag (the durable watermark).
    closed_through: i64,
    /// Writing every open minute before `.0`, `SWEEP_PER_BATCH` a batch;
    /// the slots from `.1` on are still to see.
    sweep: Option<(i64, usize)>,
    /// The newest batch median timestamp.
    clock: i64,
    /// What a crash left open is rebuilt, and the watermark read
    /// ([`recover`], before the first write).
    pub(crate) recovered: bool,
    /// The watermark row says a minute may be open (set once per start).
    pub(crate) marked_open: bool,
    /// A transaction that changes the open minutes is committing: what the
    /// database holds and what this holds may not match until it is
    /// applied. A trend reading then tries again.
    pub(crate) committing: bool,
}

/// Marks a commit of the open minutes under way until dropped, however the
/// commit ends (an error, or its future dropped).
pub(crate) struct Committing<'a>(&'a parking_lot::Mutex<OpenMinutes>);

impl<'a> Committing<'a> {
    pub(crate) fn start(open: &'a parking_lot::Mutex<OpenMinutes>) -> Self {
        open.lock().committing = true;
        Committing(open)
    }
}

impl Drop for Committing<'_> {
    fn drop(&mut self) {
        self.0.lock().committing = false;
    }
}

/// What a batch does to the roll-ups: the minutes to write now and their
/// hours, and the open minutes once it is committed.
pub(crate) struct Plan {
    /// Written now: closed minutes and those written at once, by tag then
    /// minute (a tag's open minute before its late samples).
    pub(crate) minutes: Vec<Agg>,
    /// The hours of `minutes`, merged per tag and hour where they follow
    /// each other.
    pub(crate) hours: Vec<Agg>,
    /// The watermark to write in the same transaction, when it moved.
    pub(crate) watermark: Option<i64>,
    slots: Vec<(usize, Slot)>,
    /// Slots whose open minute the sweep writes.
    swept: Vec<usize>,
    sweep: Option<(i64, usize)>,
    cutoff: i64,
    clock: i64,
    /// The last part of a clean stop: no minute is open after it.
    pub(crate) all: bool,
}

impl Default for OpenMinutes {
    fn default() -> Self {
        OpenMinutes {
            slots: Slots::default(),
            cutoff: i64::MIN,
            closed_through: i64::MIN,
            sweep: None,
            clock: i64::MIN,
            recovered: false,
            marked_open: false,
            committing: false,
        }
    }
}

impl OpenMinutes {
    /// The open minute of a tag, if any.
    pub(crate) fn open_of(&self, tag_id: i64) -> Option<Agg> {
        usize::try_from(tag_id)
            .ok()
            .and_then(|i| self.slots.get(i))
            .and_then(|s| s.open(tag_id))
    }

    /// How many minutes are open.
    pub(crate) fn count(&self) -> usize {
        self.slots.from(0).filter(|(_, s)| s.n > 0).count()
    }

    /// What a batch does: `batch`, its samples rolled up by minute (sorted
    /// by tag then time, see [`rollup::roll_up`]); `median_ts`, the median
    /// timestamp of its samples. Changes nothing until [`Self::apply`].
    pub(crate) fn plan(&self, batch: &[Agg], median_ts: Option<i64>) -> Plan {
        let clock = match median_ts {
            Some(m) => self.clock.max(m.clamp(-CLOCK_BOUND, CLOCK_BOUND)),
            None => self.clock,
        };
        let cutoff = match clock {
            i64::MIN => self.cutoff,
            c => self.cutoff.max(bucket_of(c - GRACE_MS, MINUTE)),
        };
        let horizon = clock.saturating_add(HORIZON_MS);
        let mut minutes: Vec<Agg> = Vec::new();
        let mut slots: Vec<(usize, Slot)> = Vec::new();
        for group in batch.chunk_by(|a, b| a.tag_id == b.tag_id) {
            let id = group[0].tag_id;
            if !(0..MAX_SLOTS).contains(&id) {
                minutes.extend_from_slice(group);
                continue;
            }
            // Minutes past the horizon are written at once (see HORIZON_MS).
            let (group, future) = group.split_at(group.partition_point(|a| a.bucket < horizon));
            minutes.extend_from_slice(future);
            if group.is_empty() {
                continue;
            }
            let mut slot = self.slots.get(id as usize).copied().unwrap_or(Slot::EMPTY);
            let mut open = slot.open(id);
            if let Some(o) = open.take_if(|o| o.bucket < cutoff) {
                minutes.push(o);
                slot.close();
            }
            // A sample before the open minute's last one: the open minute is
            // written now, and the tag's samples up to its end with it.
            let conflict = open.as_ref().is_some_and(|o| {
                group.iter().any(|a| {
                    a.bucket < o.bucket || (a.bucket == o.bucket && a.first_ts <= o.last_ts)
                })
            });
            if conflict {
                minutes.extend(open.take());
                slot.close();
            }
            let floor = cutoff.max(slot.closed_next);
            let at_once = group.partition_point(|a| a.bucket < floor);
            minutes.extend_from_slice(&group[..at_once]);
            for a in &group[at_once..] {
                match &mut open {
                    Some(o) if o.bucket == a.bucket => o.append(MINUTE, a),
                    Some(o) => {
                        let closed = std::mem::replace(o, a.clone());
                        slot.closed_next =
                            slot.closed_next.max(closed.bucket.saturating_add(MINUTE));
                        minutes.push(closed);
                    }
                    None => open = Some(a.clone()),
                }
            }
            match &open {
                Some(o) => slot.hold(o),
                None => slot.n = 0,
            }
            slots.push((id as usize, slot));
        }
        // The clock passed a minute: every other tag's open minute before
        // the new cutoff is written too (the batch's tags are done above),
        // a part with each batch; the watermark moves once all are.
        let mut sweep = match self.sweep {
            _ if cutoff > self.cutoff => Some((cutoff, 0)),
            s => s,
        };
        let mut swept = Vec::new();
        let mut watermark = None;
        if let Some((target, from)) = sweep {
            let mut done: Vec<usize> = slots.iter().map(|(i, _)| *i).collect();
            done.sort_unstable();
            let mut next = self.slots.len();
            for (i, s) in self.slots.from(from) {
                if swept.len() == SWEEP_PER_BATCH {
                    next = i;
                    break;
                }
                if s.n > 0 && s.bucket < target && done.binary_search(&i).is_err() {
                    minutes.extend(s.open(i as i64));
                    swept.push(i);
                }
            }
            if next == self.slots.len() {
                sweep = None;
                watermark = Some(target);
            } else {
                sweep = Some((target, next));
            }
        }
        minutes.sort_by_key(|a| (a.tag_id, a.bucket));
        let hours = hours_of(&minutes);
        Plan {
            minutes,
            hours,
            watermark: watermark.filter(|&w| w > self.closed_through),
            slots,
            swept,
            sweep,
            cutoff,
            clock,
            all: false,
        }
    }

    /// Up to `limit` open minutes written (a clean stop, in parts); with the
    /// last part, the watermark moves past the last minute written, so no
    /// minute reopens after a restart.
    pub(crate) fn plan_close(&self, limit: usize) -> Plan {
        let mut minutes = Vec::new();
        let mut swept = Vec::new();
        let mut cutoff = self.cutoff;
        let mut all = true;
        for (i, s) in self.slots.from(0) {
            if s.n > 0 {
                if swept.len() == limit {
                    all = false;
                    break;
                }
                minutes.extend(s.open(i as i64));
                swept.push(i);
            }
        }
        if all {
            for (_, s) in self.slots.from(0) {
                let mut s = *s;
                s.close();
                cutoff = cutoff.max(s.closed_next);
            }
        }
        minutes.sort_by_key(|a| (a.tag_id, a.bucket));
        let hours = hours_of(&minutes);
        Plan {
            minutes,
            hours,
            watermark: all.then_some(cutoff),
            slots: Vec::new(),
            swept,
            sweep: None,
            cutoff,
            clock: self.clock,
            all,
        }
    }

    /// The plan's transaction is committed.
    pub(crate) fn apply(&mut self, plan: Plan) {
        for (i, s) in plan.slots {
            *self.slots.get_mut(i) = s;
        }
        for i in plan.swept {
            self.slots.get_mut(i).close();
        }
        if plan.all {
            self.slots = Slots::default();
        }
        if let Some(w) = plan.watermark {
            self.closed_through = w;
        }
        self.sweep = plan.sweep;
        self.cutoff = plan.cutoff;
        self.clock = plan.clock;
    }

    /// The watermark read before the first write (after [`recover`]).
    pub(crate) fn start_at(&mut self, closed_through: i64) {
        self.cutoff = closed_through;
        self.closed_through = closed_through;
        self.recovered = true;
    }
}

/// The hours of minute buckets sorted by tag then minute: each widened to
/// its hour, then merged with the one before where it follows it (a late
/// sample's minute does not; it goes as its own row, and the database's
/// merge recomputes that hour from the raw rows).
fn hours_of(minutes: &[Agg]) -> Vec<Agg> {
    let mut hours: Vec<Agg> = Vec::with_capacity(minutes.len());
    for m in minutes {
        let h = m.widened(MINUTE, HOUR);
        match hours.last_mut() {
            Some(p) if p.tag_id == h.tag_id && p.bucket == h.bucket && h.first_ts > p.last_ts => {
                p.append(HOUR, &h)
            }
            _ => hours.push(h),
        }
    }
    hours
}

/// The median of the timestamps of a batch's samples.
pub(crate) fn median(mut ts: Vec<i64>) -> Option<i64> {
    if ts.is_empty() {
        return None;
    }
    let mid = ts.len() / 2;
    Some(*ts.select_nth_unstable(mid).1)
}

/// Writes the site's watermark, and whether a minute may be open, in the
/// transaction on `conn`.
pub(crate) async fn write_state(
    conn: &mut SqliteConnection,
    site: &str,
    closed_through: Option<i64>,
    clean: Option<bool>,
) -> Result<()> {
    if closed_through.is_none() && clean.is_none() {
        return Ok(());
    }
    sqlx::query(
        "INSERT INTO historian_rollup_state (site, closed_through, clean)          VALUES ($1, COALESCE($2, -9223372036854775807), COALESCE($3, 1))          ON CONFLICT (site) DO UPDATE SET          closed_through = COALESCE($2, historian_rollup_state.closed_through),          clean = COALESCE($3, historian_rollup_state.clean)",
    )
    .bind(site)
    .bind(closed_through)
    .bind(clean.map(i32::from))
    .execute(conn)
    .await
    .map_err(db("writing the historian's roll-up watermark"))?;
    Ok(())
}

/// Before the historian's first write, on the writer connection in a
/// transaction: after a crash (the site's state says a minute may have
/// been open), the minute roll-ups of the site's raw samples at or after
/// the watermark that have no row are written and merged into their hours,
/// and the watermark moves past the minutes seen (those not beyond the
/// horizon of their median). Returns the watermark, and the minutes
/// rebuilt.
pub(crate) async fn recover(conn: &mut SqliteConnection, site: &str) -> Result<(i64, u64)> {
    let (closed_through, clean): (i64, i32) =
        sqlx::query_as("SELECT closed_through, clean FROM historian_rollup_state WHERE site = $1")
            .bind(site)
            .fetch_optional(&mut *conn)
            .await
            .map_err(db("reading the historian's roll-up watermark"))?
            .unwrap_or((i64::MIN + 1, 1));
    if clean != 0 {
        return Ok((closed_through, 0));
    }
    let top: Option<i64> = sqlx::query_scalar("SELECT max(id) FROM tags WHERE site = $1")
        .bind(site)
        .fetch_one(&mut *conn)
        .await
        .map_err(db("rebuilding the historian's open minutes"))?;
    let mut seen: Vec<i64> = Vec::new();
    let mut rebuilt = 0u64;
    let mut from = 0i64;
    while from <= top.unwrap_or(-1) {
        // One seek of the primary key per tag: the raw table is keyed by tag.
        let raw: Vec<(i64, i64, Option<f64>, i32)> = sqlx::query_as(
            "SELECT s.tag_id, s.ts, s.value, s.quality FROM tags t \
             JOIN samples s ON s.tag_id = t.id AND s.ts >= $1 \
             WHERE t.site = $2 AND t.id >= $3 AND t.id < $4 ORDER BY s.tag_id, s.ts",
        )
        .bind(closed_through)
        .bind(site)
        .bind(from)
        .bind(from.saturating_add(RECOVER_TAGS))
        .fetch_all(&mut *conn)
        .await
        .map_err(db("rebuilding the historian's open minutes"))?;
        from = from.saturating_add(RECOVER_TAGS);
        let minutes = rollup::roll_up(raw, MINUTE);
        seen.extend(minutes.iter().map(|a| a.bucket));
        // A minute with a row was written when it closed, whole; one
        // without was open when the process stopped.
        let mut missing: Vec<Agg> = Vec::new();
        for chunk in rollup::statement_chunks(&minutes, rollup::SQLITE_ROWS) {
            let mut qb = QueryBuilder::new(format!(
                "INSERT INTO {} ({}) ",
                Level::Minute.table(),
                rollup::COLUMNS
            ));
            rollup::push_sqlite_values(&mut qb, chunk);
            qb.push(" ON CONFLICT (tag_id, bucket) DO NOTHING RETURNING tag_id, bucket");
            let keys: Vec<(i64, i64)> = qb
                .build_query_as()
                .fetch_all(&mut *conn)
                .await
                .map_err(db("rebuilding the historian's open minutes"))?;
            let keys: std::collections::HashSet<(i64, i64)> = keys.into_iter().collect();
            missing.extend(
                chunk
                    .iter()
                    .filter(|a| keys.contains(&(a.tag_id, a.bucket)))
                    .cloned(),
            );
        }
        rebuilt += missing.len() as u64;
        rollup::maintain_sqlite(conn, &[(Level::Hour, &hours_of(&missing))]).await?;
    }
    // Past every minute seen, but not past a device's wrong clock: a minute
    // beyond the horizon of the minutes' median is written at once anyway.
    let mut watermark = closed_through;
    if let Some(mid) = median(seen.clone()) {
        let horizon = mid.saturating_add(HORIZON_MS);
        if let Some(newest) = seen.into_iter().filter(|&m| m < horizon).max() {
            watermark = watermark.max(newest.saturating_add(MINUTE));
        }
    }
    write_state(conn, site, Some(watermark), Some(true)).await?;
    Ok((watermark, rebuilt))
}

/// Folds a tag's open minute into the trend rows read from `level` for it
/// (`rows`: `(tag, index, n, min, max, sum, n_value, last_ts, last value,
/// last quality, bad ms)`, by index): `stored`, the level's row holding
/// the open minute, if any; `tail`, the open minute's samples after the
/// stored row's last one when the stored row already holds some of them
/// (a bucket recomputed from raw rows), else the open minute itself.
pub(crate) fn fold_open(
    rows: &mut Vec<crate::historian::MultiLevelRow>,
    level: Level,
    (f, t, n): (i64, i64, i64),
    stored: Option<&Agg>,
    open: &Agg,
) {
    let w = level.width();
    let part = open.widened(MINUTE, w);
    let b = part.bucket;
    if b < bucket_of(f, w) || b >= t {
        return;
    }
    let bad_added = match stored {
        Some(r) => {
            let mut merged = r.clone();
            merged.append(w, &part);
            merged.bad_ms - r.bad_ms
        }
        None => part.bad_ms,
    };
    // As the SQL does: truncating division (a bucket before `f` gives 0).
    let idx = (b - f) * n / (t - f);
    match rows.iter_mut().find(|r| r.1 == idx) {
        Some(r) => {
            r.2 += part.n;
            r.3 = rollup::opt(r.3, part.min, f64::min);
            r.4 = rollup::opt(r.4, part.max, f64::max);
            r.5 = rollup::opt(r.5, part.sum, |a, b| a + b);
            r.6 += part.n_value;
            if part.last_ts > r.7 {
                (r.7, r.8, r.9) = (part.last_ts, part.last_value, part.last_quality);
            }
            r.10 += bad_added;
        }
        None => {
            rows.push((
                part.tag_id,
                idx,
                part.n,
                part.min,
                part.max,
                part.sum,
                part.n_value,
                part.last_ts,
                part.last_value,
                part.last_quality,
                bad_added,
            ));
            rows.sort_by_key(|r| r.1);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn samples(tag: i64, from: i64, n: i64, step: i64) -> Vec<(i64, i64, Option<f64>, i32)> {
        (0..n)
            .map(|i| {
                let q = if i % 7 == 3 { 2 } else { 0 };
                (tag, from + i * step, Some(i as f64), q)
            })
            .collect()
    }

    /// Minutes closed by the plans plus those still open equal the samples
    /// rolled up at once; so do their hours.
    #[test]
    fn batches_fold_into_the_same_minutes_and_hours() {
        let t0 = 1_700_000_000_000 - 1_700_000_000_000 % HOUR;
        let all: Vec<_> = [1, 2, 5]
            .iter()
            .flat_map(|&tag| samples(tag, t0 + tag * 777, 500, 7_919))
            .collect();
        let mut sorted = all.clone();
        sorted.sort_by_key(|s| s.1);
        let mut open = OpenMinutes::default();
        let mut written: Vec<Agg> = Vec::new();
        let mut hours: Vec<Agg> = Vec::new();
        for batch in sorted.chunks(37) {
            let mut b = batch.to_vec();
            b.sort_by_key(|s| (s.0, s.1));
            let median_ts = median(b.iter().map(|s| s.1).collect());
            let plan = open.plan(&rollup::roll_up(b, MINUTE), median_ts);
            written.extend(plan.minutes.iter().cloned());
            hours.extend(plan.hours.iter().cloned());
            open.apply(plan);
        }
        assert!(open.count() > 0, "the last minutes are still open");
        let plan = open.plan_close(usize::MAX);
        written.extend(plan.minutes.iter().cloned());
        hours.extend(plan.hours.iter().cloned());
        open.apply(plan);
        assert_eq!(open.count(), 0);
        let mut by_key = all.clone();
        by_key.sort_by_key(|s| (s.0, s.1));
        written.sort_by_key(|a| (a.tag_id, a.bucket));
        assert_eq!(written, rollup::roll_up(by_key.clone(), MINUTE));
        // Each hour arrives in parts that follow each other.
        hours.sort_by_key(|a| (a.tag_id, a.bucket, a.first_ts));
        let merged = {
            let mut out: Vec<Agg> = Vec::new();
            for h in hours {
                match out.last_mut() {
                    Some(p) if p.tag_id == h.tag_id && p.bucket == h.bucket => {
                        assert!(h.first_ts > p.last_ts);
                        p.append(HOUR, &h)
                    }
                    _ => out.push(h),
                }
            }
            out
        };
        assert_eq!(merged, rollup::roll_up(by_key, HOUR));
    }

    /// A sample before the open minute's last one is written at once, with
    /// the open minute, and the tag's minute stays closed after.
    #[test]
    fn a_late_sample_writes_the_open_minute_with_it() {
        let t0 = 1_700_000_040_000;
        let mut open = OpenMinutes::default();
        let first = rollup::roll_up(samples(9, t0, 3, 1_000), MINUTE);
        let plan = open.plan(&first, Some(t0));
        assert!(plan.minutes.is_empty() && plan.watermark.is_some());
        open.apply(plan);
        assert_eq!(open.open_of(9).unwrap().n, 3);
        let late = rollup::roll_up(samples(9, t0 + 500, 1, 1), MINUTE);
        let plan = open.plan(&late, Some(t0 + 500));
        assert_eq!(
            plan.minutes.len(),
            2,
            "the open minute, then the late sample"
        );
        assert_eq!(plan.minutes[0].n, 3);
        assert_eq!(plan.hours.len(), 2, "the late one does not follow");
        open.apply(plan);
        assert!(open.open_of(9).is_none());
        // More samples of that minute: written at once too.
        let more = rollup::roll_up(samples(9, t0 + 5_000, 1, 1), MINUTE);
        let plan = open.plan(&more, Some(t0 + 5_000));
        assert_eq!(plan.minutes.len(), 1);
        open.apply(plan);
        assert!(open.open_of(9).is_none());
    }

    /// The clock passing a minute's end plus the grace writes every tag's
    /// open minute before it, and moves the watermark.
    #[test]
    fn the_clock_closes_quiet_tags() {
        let t0 = 1_700_000_040_000;
        let mut open = OpenMinutes::default();
        let plan = open.plan(&rollup::roll_up(samples(3, t0, 2, 1_000), MINUTE), Some(t0));
        open.apply(plan);
        let later = t0 + MINUTE + GRACE_MS + MINUTE;
        let plan = open.plan(
            &rollup::roll_up(samples(4, later, 1, 1), MINUTE),
            Some(later),
        );
        assert_eq!(plan.minutes.len(), 1);
        assert_eq!(plan.minutes[0].tag_id, 3);
        assert!(plan.watermark.unwrap() > t0);
        open.apply(plan);
        assert!(open.open_of(3).is_none());
        assert!(open.open_of(4).is_some());
    }

    /// A device stamping a sample a day ahead: written at once, and the
    /// tag's later minutes still open (no floor, no cutoff moved by it).
    #[test]
    fn a_sample_from_the_future_moves_nothing() {
        let t0 = 1_700_000_040_000;
        let mut open = OpenMinutes::default();
        let plan = open.plan(&rollup::roll_up(samples(5, t0, 3, 1_000), MINUTE), Some(t0));
        open.apply(plan);
        let ahead = rollup::roll_up(samples(5, t0 + 86_400_000, 1, 1), MINUTE);
        let plan = open.plan(&ahead, Some(t0 + 5_000));
        assert_eq!(plan.minutes.len(), 1, "written at once");
        assert_eq!(plan.minutes[0].bucket, t0 + 86_400_000);
        open.apply(plan);
        assert_eq!(open.open_of(5).unwrap().n, 3, "the open minute stays");
        let next = rollup::roll_up(samples(5, t0 + MINUTE, 1, 1), MINUTE);
        let plan = open.plan(&next, Some(t0 + MINUTE));
        assert_eq!(plan.minutes.len(), 1, "the minute before closes");
        open.apply(plan);
        assert_eq!(open.open_of(5).unwrap().bucket, t0 + MINUTE);
        let close = open.plan_close(usize::MAX);
        assert!(close.watermark.unwrap() <= t0 + 2 * MINUTE);
    }

    /// Timestamps far apart and far from now (a device's clock gone wrong
    /// by ±285,000 years): no overflow, nothing lost.
    #[test]
    fn extreme_timestamps_do_not_overflow() {
        let mut open = OpenMinutes::default();
        for ts in [-CLOCK_BOUND * 2, -1, 0, CLOCK_BOUND * 2, 5] {
            let batch = rollup::roll_up(vec![(1, ts, Some(1.0), 2)], MINUTE);
            let plan = open.plan(&batch, Some(ts));
            let n: i64 = plan.minutes.iter().map(|a| a.n).sum();
            open.apply(plan);
            assert!(n + open.open_of(1).map_or(0, |o| o.n) >= 1);
        }
        open.apply(open.plan_close(usize::MAX));
        assert_eq!(open.count(), 0);
    }

    #[test]
    fn a_slot_holds_an_open_minute_exactly() {
        let a = rollup::roll_up(
            vec![(7, 60_000, None, 2), (7, 61_000, Some(-0.0), 0)],
            MINUTE,
        )
        .remove(0);
        let mut s = Slot::EMPTY;
        s.hold(&a);
        assert_eq!(s.open(7), Some(a));
        assert_eq!(std::mem::size_of::<Slot>(), 88);
    }
}
