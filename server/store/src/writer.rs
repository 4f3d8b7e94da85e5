//! The historian writer task: a bounded buffer in front of the database.
//!
//! Producers [`HistorianHandle::push`] without waiting. One task drains the
//! buffer in batches and prepares each (tag ids, order, roll-ups: the work
//! of [`Store::insert_samples`] that needs no database); a second writes
//! them in order, so the next batch is prepared while one is in the
//! database. When the database is slow
//! the buffer absorbs it; when the buffer is full, new samples are dropped,
//! counted, and the overflow flag goes up (for a system alarm) until the buffer
//! is back under half full. A batch that fails to write is retried with
//! backoff, never discarded, except at shutdown, where it is counted as dropped.
//! A sample offered after shutdown is counted as dropped too, but is no
//! overflow: whoever stops the writer stops its producers first.
//!
//! **Owns:** buffering, batching, retry and the historian metrics. **Must not
//! touch:** which samples to log (that is [`crate::Recorder`]).
//!
//! Waiting here (linger, retry backoff) is wall time on purpose: it paces I/O
//! with the database, not plant behaviour, so a compressed replay clock must
//! not speed it up.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use serde::Serialize;
use tokio::sync::{mpsc, watch, Semaphore};
use tokio::task::JoinHandle;

use crate::historian::PreparedSamples;
use crate::{HistorySample, Store};

/// How long a stop spends writing the open minute roll-ups (SQLite); the
/// next start rebuilds the rest. The packaged service gives a stop 30 s.
pub(crate) const STOP_BUDGET: Duration = Duration::from_secs(10);

/// Sizes and pacing of the writer.
#[derive(Debug, Clone)]
pub struct HistorianConfig {
    /// Samples the buffer holds before dropping.
    pub capacity: usize,
    /// Most samples per database transaction.
    pub batch_max: usize,
    /// After the first sample of a batch arrives, wait this long for more
    /// (fewer, bigger transactions at low rates).
    pub linger: Duration,
    /// Longest wait between retries of a failed batch.
    pub max_backoff: Duration,
}

impl Default for HistorianConfig {
    fn default() -> Self {
        HistorianConfig {
            capacity: 100_000,
            batch_max: 5_000,
            linger: Duration::from_millis(200),
            max_backoff: Duration::from_secs(5),
        }
    }
}

/// A snapshot of the writer's health.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct HistorianMetrics {
    /// Samples waiting in the buffer (not counting the batch being written;
    /// a batch taken while another is in the database counts until its
    /// turn).
    pub buffered: usize,
    pub capacity: usize,
    /// Samples lost: dropped because the buffer was full, offered after the
    /// writer stopped, or not written at shutdown.
    pub dropped: u64,
    pub samples_written: u64,
    pub batches_written: u64,
    /// Failed write attempts (each retried).
    pub write_errors: u64,
    pub last_write_ms: f64,
    pub max_write_ms: f64,
    /// Whether the buffer overflowed and has not drained below half since.
    pub overflow: bool,
}

#[derive(Default)]
struct Counters {
    dropped: AtomicU64,
    written: AtomicU64,
    batches: AtomicU64,
    errors: AtomicU64,
    last_us: AtomicU64,
    max_us: AtomicU64,
}

struct Shared {
    counters: Counters,
    overflow: watch::Sender<bool>,
    capacity: usize,
    /// Room left: `capacity` minus the samples held in the buffer, where a
    /// batch taken from it while another is in the database still counts
    /// (so a stuck database gets no more room than before the two stages).
    room: Semaphore,
    /// A batch is in the database (from its hand-over to its last attempt).
    writing: AtomicBool,
    /// A sample was offered after the writer stopped (logged once).
    stopped_drop: AtomicBool,
}

/// Pushes samples into the historian buffer. Cheap to clone.
#[derive(Clone)]
pub struct HistorianHandle {
    tx: mpsc::UnboundedSender<HistorySample>,
    shared: Arc<Shared>,
}

/// The writer task. Dropping it stops the writer like [`Historian::shutdown`]
/// (final flush of the buffer) but without waiting for it; prefer shutdown.
pub struct Historian {
    handle: HistorianHandle,
    stop: watch::Sender<bool>,
    pause: watch::Sender<bool>,
    task: JoinHandle<()>,
}

impl HistorianHandle {
    /// Queues a sample without waiting. Returns false if it was dropped
    /// (buffer full or writer stopped); the drop is counted either way.
    ///
    /// A full buffer is an overflow (the flag goes up, for a system alarm).
    /// A sample offered after the writer stopped is not: nothing will drain
    /// the buffer again, so it is a loss at shutdown, counted in `dropped`
    /// like any other and logged once, but no overflow. (The application
    /// stops every producer before the writer, so an orderly shutdown offers
    /// none.)
    pub fn push(&self, sample: HistorySample) -> bool {
        let sent = if self.tx.is_closed() {
            Err(Refused::Stopped)
        } else {
            match self.shared.room.try_acquire() {
                Ok(permit) => {
                    permit.forget();
                    self.tx.send(sample).map_err(|_| {
                        self.shared.room.add_permits(1);
                        Refused::Stopped
                    })
                }
                Err(_) => Err(Refused::Full),
            }
        };
        match sent {
            Ok(()) => true,
            Err(Refused::Full) => {
                let dropped = self.shared.counters.dropped.fetch_add(1, Ordering::Relaxed) + 1;
                let raised = self
                    .shared
                    .overflow
                    .send_if_modified(|o| !std::mem::replace(o, true));
                if raised {
                    tracing::error!(
                        dropped,
                        "historian overflow: buffer full, samples are being dropped"
                    );
                }
                false
            }
            Err(Refused::Stopped) => {
                let dropped = self.shared.counters.dropped.fetch_add(1, Ordering::Relaxed) + 1;
                if !self.shared.stopped_drop.swap(true, Ordering::Relaxed) {
                    tracing::error!(
                        dropped,
                        "historian stopped: a sample offered after its writer stopped was \
                         dropped (a producer outlived the writer; counted in dropped)"
                    );
                }
                false
            }
        }
    }

    /// Queues many samples; returns how many were accepted.
    pub fn push_all(&self, samples: impl IntoIterator<Item = HistorySample>) -> usize {
        samples
            .into_iter()
            .map(|s| self.push(s))
            .filter(|&ok| ok)
            .count()
    }

    pub fn metrics(&self) -> HistorianMetrics {
        let c = &self.shared.counters;
        HistorianMetrics {
            buffered: self.shared.held(),
            capacity: self.shared.capacity,
            dropped: c.dropped.load(Ordering::Relaxed),
            samples_written: c.written.load(Ordering::Relaxed),
            batches_written: c.batches.load(Ordering::Relaxed),
            write_errors: c.errors.load(Ordering::Relaxed),
            last_write_ms: c.last_us.load(Ordering::Relaxed) as f64 / 1000.0,
            max_write_ms: c.max_us.load(Ordering::Relaxed) as f64 / 1000.0,
            overflow: *self.shared.overflow.borrow(),
        }
    }

    /// Follows the overflow flag: true while samples are being (or were
    /// recently) dropped. Raise a system alarm on it.
    pub fn overflow(&self) -> watch::Receiver<bool> {
        self.shared.overflow.subscribe()
    }
}

impl Historian {
    /// Starts the writer task on the current tokio runtime.
    pub fn spawn(store: Store, config: HistorianConfig) -> Historian {
        let capacity = config.capacity.clamp(1, Semaphore::MAX_PERMITS);
        let (tx, rx) = mpsc::unbounded_channel();
        let shared = Arc::new(Shared {
            counters: Counters::default(),
            overflow: watch::channel(false).0,
            capacity,
            room: Semaphore::new(capacity),
            writing: AtomicBool::new(false),
            stopped_drop: AtomicBool::new(false),
        });
        let (stop, stop_rx) = watch::channel(false);
        let (pause, pause_rx) = watch::channel(false);
        let task = tokio::spawn(run(store, config, rx, shared.clone(), stop_rx, pause_rx));
        Historian {
            handle: HistorianHandle { tx, shared },
            stop,
            pause,
            task,
        }
    }

    pub fn handle(&self) -> HistorianHandle {
        self.handle.clone()
    }

    pub fn metrics(&self) -> HistorianMetrics {
        self.handle.metrics()
    }

    /// Holds writes (e.g. during a backup or maintenance): samples collect in
    /// the buffer, and overflow as usual if it fills.
    pub fn pause(&self, paused: bool) {
        self.pause.send_replace(paused);
    }

    /// Writes everything buffered (one attempt per remaining batch), then
    /// stops. Returns the final metrics.
    pub async fn shutdown(self) -> HistorianMetrics {
        self.stop.send_replace(true);
        if let Err(e) = self.task.await {
            tracing::error!(error = %e, "historian writer task failed");
        }
        self.handle.metrics()
    }
}

/// A batch on its way from the buffer to the database.
enum Batch {
    /// Made ready (tag ids, order, COPY text, roll-ups) before its turn.
    Prepared {
        samples: usize,
        rows: PreparedSamples,
    },
    /// Holding a tag not registered yet: [`Store::insert_samples`] does it all.
    Raw(Vec<HistorySample>),
}

impl Batch {
    fn of(store: &Store, samples: Vec<HistorySample>) -> Batch {
        match store.prepare_samples(&samples) {
            Some(rows) => Batch::Prepared {
                samples: samples.len(),
                rows,
            },
            None => Batch::Raw(samples),
        }
    }

    fn len(&self) -> usize {
        match self {
            Batch::Prepared { samples, .. } => *samples,
            Batch::Raw(s) => s.len(),
        }
    }
}

/// The buffer's side of the writer: takes batches and prepares them, while
/// [`write_batches`] writes the one before. One prepared batch waits while
/// one is written, so a batch's CPU work overlaps the database's time on
/// the previous one.
async fn run(
    store: Store,
    config: HistorianConfig,
    mut rx: mpsc::UnboundedReceiver<HistorySample>,
    shared: Arc<Shared>,
    mut stop: watch::Receiver<bool>,
    mut pause: watch::Receiver<bool>,
) {
    // What an unclean stop left open is rebuilt before the first batch (a
    // failure here is retried by the first write).
    if let Err(e) = store.recover_open_minutes().await {
        tracing::warn!(error = %e, "historian: the open minute roll-ups could not be rebuilt yet");
    }
    let batch_max = config.batch_max.max(1);
    let (ready_tx, ready_rx) = mpsc::channel::<(Batch, usize)>(1);
    let writer = tokio::spawn(write_batches(
        store.clone(),
        config.clone(),
        ready_rx,
        shared.clone(),
        stop.clone(),
        pause.clone(),
    ));
    let mut batch: Vec<HistorySample> = Vec::with_capacity(batch_max);
    // Of the batch being collected, the samples that still hold room.
    let mut held = 0;
    let take = |n: usize, held: &mut usize| {
        if shared.writing.load(Ordering::SeqCst) {
            *held += n;
        } else {
            shared.release(n);
        }
    };
    loop {
        // Paused: leave samples in the buffer until resumed or stopped.
        while *pause.borrow() && !stopping(&stop) {
            tokio::select! {
                r = pause.changed() => if r.is_err() { break },
                _ = stop.changed() => {}
            }
        }
        if stopping(&stop) || pause.has_changed().is_err() {
            break;
        }
        // Biased: a pause or stop that is already signalled wins over
        // samples waiting, so a pause takes effect before the next batch.
        tokio::select! {
            biased;
            _ = stop.changed() => continue,
            _ = pause.changed() => continue,
            n = rx.recv_many(&mut batch, batch_max) => {
                if n == 0 { break; } // every handle dropped
                take(n, &mut held);
            }
        }
        // Linger for a fuller batch, but only until it is full: under a
        // burst the batch fills in microseconds, and sleeping out the
        // whole linger there cost a third of a 200,000-sample burst's
        // time (docs/BENCHMARKS.md).
        if batch.len() < batch_max && !config.linger.is_zero() {
            let until = tokio::time::Instant::now() + config.linger;
            while batch.len() < batch_max {
                let room = batch_max - batch.len();
                tokio::select! {
                    _ = tokio::time::sleep_until(until) => break,
                    _ = stop.changed() => break,
                    n = rx.recv_many(&mut batch, room) => {
                        if n == 0 { break }
                        take(n, &mut held);
                    }
                }
            }
        }
        let full = std::mem::replace(&mut batch, Vec::with_capacity(batch_max));
        // Waits while the writer is busy with the batch before; the buffer
        // takes what comes meanwhile.
        let ready = (Batch::of(&store, full), std::mem::take(&mut held));
        if let Err(lost) = ready_tx.send(ready).await {
            shared.release(lost.0 .1);
            count_lost(&shared, lost.0 .0.len());
            break;
        }
    }
    // Shutdown: everything still here goes to the writer, which makes one
    // attempt at each batch.
    rx.close();
    while let Ok(s) = rx.try_recv() {
        batch.push(s);
        held += 1;
    }
    shared.release(std::mem::take(&mut held));
    while !batch.is_empty() {
        let rest = batch.split_off(batch.len().min(batch_max));
        if let Err(lost) = ready_tx.send((Batch::of(&store, batch), 0)).await {
            count_lost(&shared, lost.0 .0.len() + rest.len());
            break;
        }
        batch = rest;
    }
    drop(ready_tx);
    if let Err(e) = writer.await {
        tracing::error!(error = %e, "historian writer task failed");
    }
    // The open minute roll-ups (SQLite) are written, so the next start has
    // nothing to rebuild.
    match store.close_open_minutes_within(Some(STOP_BUDGET)).await {
        Ok(minutes) => tracing::debug!(minutes, "historian: open minute roll-ups written"),
        Err(e) => tracing::warn!(error = %e,
            "historian: could not write the open minute roll-ups; the next start rebuilds them"),
    }
}

/// The database's side of the writer: each batch in order, retried until
/// written; once stopping, one attempt each.
async fn write_batches(
    store: Store,
    config: HistorianConfig,
    mut ready: mpsc::Receiver<(Batch, usize)>,
    shared: Arc<Shared>,
    mut stop: watch::Receiver<bool>,
    mut pause: watch::Receiver<bool>,
) {
    while let Some((batch, held)) = ready.recv().await {
        // Handed to the database: its room in the buffer is free again (as
        // before the stages, the batch being written is not counted).
        shared.writing.store(true, Ordering::SeqCst);
        shared.release(held);
        // A pause holds the batch already prepared too.
        while *pause.borrow() && !stopping(&stop) {
            tokio::select! {
                r = pause.changed() => if r.is_err() { break },
                _ = stop.changed() => {}
            }
        }
        let written =
            !stopping(&stop) && write_with_retry(&store, &config, &batch, &shared, &mut stop).await;
        if !written {
            if let Err(e) = write_once(&store, &batch, &shared).await {
                count_lost(&shared, batch.len());
                tracing::error!(error = %e, lost = batch.len(), "historian could not write at shutdown");
            }
        }
        shared.writing.store(false, Ordering::SeqCst);
    }
}

fn count_lost(shared: &Shared, n: usize) {
    shared
        .counters
        .dropped
        .fetch_add(n as u64, Ordering::Relaxed);
}

/// Why [`HistorianHandle::push`] refused a sample.
enum Refused {
    Full,
    Stopped,
}

impl Shared {
    /// Samples held in the buffer (see `room`).
    fn held(&self) -> usize {
        self.capacity.saturating_sub(self.room.available_permits())
    }

    /// Frees the room of `n` samples; clears the overflow flag once the
    /// buffer is back under half full.
    fn release(&self, n: usize) {
        if n == 0 {
            return;
        }
        self.room.add_permits(n);
        if self.held() <= self.capacity / 2 {
            self.overflow
                .send_if_modified(|o| std::mem::replace(o, false));
        }
    }
}

/// Told to stop, or the [`Historian`] owning the stop signal was dropped.
fn stopping(stop: &watch::Receiver<bool>) -> bool {
    *stop.borrow() || stop.has_changed().is_err()
}

async fn write_once(store: &Store, batch: &Batch, shared: &Shared) -> crate::Result<()> {
    let started = Instant::now();
    let res = match batch {
        Batch::Prepared { rows, .. } => store.write_prepared(rows).await,
        Batch::Raw(samples) => store.insert_samples(samples).await,
    };
    let us = started.elapsed().as_micros().min(u64::MAX as u128) as u64;
    let c = &shared.counters;
    match res {
        Ok(_) => {
            c.written.fetch_add(batch.len() as u64, Ordering::Relaxed);
            c.batches.fetch_add(1, Ordering::Relaxed);
            c.last_us.store(us, Ordering::Relaxed);
            c.max_us.fetch_max(us, Ordering::Relaxed);
            Ok(())
        }
        Err(e) => {
            c.errors.fetch_add(1, Ordering::Relaxed);
            Err(e)
        }
    }
}

/// Writes a batch, retrying with backoff until it is written (true) or the
/// writer is told to stop (false, batch not written).
async fn write_with_retry(
    store: &Store,
    config: &HistorianConfig,
    batch: &Batch,
    shared: &Shared,
    stop: &mut watch::Receiver<bool>,
) -> bool {
    let mut backoff = Duration::from_millis(100);
    loop {
        match write_once(store, batch, shared).await {
            Ok(()) => return true,
            Err(e) => {
                tracing::warn!(error = %e, samples = batch.len(), retry_in = ?backoff,
                    "historian write failed; keeping the batch and retrying");
            }
        }
        if stopping(stop) {
            return false;
        }
        tokio::select! {
            _ = tokio::time::sleep(backoff) => {}
            _ = stop.changed() => return false,
        }
        backoff = (backoff * 2).min(config.max_backoff.max(Duration::from_millis(100)));
    }
}
