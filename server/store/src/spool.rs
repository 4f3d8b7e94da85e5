//! The audit trail task: events and alarm transitions on their way to the
//! store, durable even while the database is away.
//!
//! Every record passes through one task, which numbers it (its audit id) in
//! the order it arrived and writes batches to the store. A batch the store
//! cannot take is appended to the spool, a JSON-lines file in the data
//! folder (`audit-spool/spool.jsonl`), fsync'd before it counts as durable.
//! While the spool holds anything, new records go behind it, never past it,
//! and the same task replays it in order into the store (retrying with
//! back-off), then removes it. A spool left by an earlier run is replayed
//! first. The store skips a record whose audit id it already holds, so a
//! crash between the store's commit and the spool's trim stores nothing
//! twice. A torn last line (a crash in the middle of an append) is reported
//! and cut off: that record had not been acknowledged as durable.
//!
//! A caller that must not go ahead without its record (an operator command)
//! awaits [`AuditHandle::record_durable`]: it returns once the record is in
//! the store or the spool, or fails when it can be in neither.
//!
//! **Owns:** the spool file, numbering, ordering, replay and the trail's
//! metrics. **Must not touch:** what is worth recording (callers decide).
//!
//! Waiting here (write timeout, back-off) is wall time on purpose: it paces
//! I/O with the database, not plant behaviour.

use std::collections::VecDeque;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Duration;

use serde::Serialize;
use tokio::sync::{mpsc, oneshot, watch};
use tokio::task::JoinHandle;
use tokio::time::Instant;

use crate::audit::{AuditBody, AuditRecord};
use crate::Store;

/// The spool file's name inside the spool folder.
pub const SPOOL_FILE: &str = "spool.jsonl";

/// Where and how fast the trail works.
#[derive(Debug, Clone)]
pub struct AuditConfig {
    /// The spool folder, e.g. `DATA/audit-spool`.
    pub spool_dir: PathBuf,
    /// Most records per database transaction.
    pub batch_max: usize,
    /// A store write taking longer than this counts as failed (the record
    /// goes to the spool): a command never waits on a hung database.
    pub write_timeout: Duration,
    /// Longest wait between replay attempts.
    pub max_backoff: Duration,
}

impl AuditConfig {
    pub fn new(data_dir: &Path) -> AuditConfig {
        AuditConfig {
            spool_dir: data_dir.join("audit-spool"),
            batch_max: 512,
            write_timeout: Duration::from_secs(2),
            max_backoff: Duration::from_secs(5),
        }
    }
}

/// Why a record could not be made durable.
#[derive(Debug, Clone, thiserror::Error)]
pub enum AuditError {
    /// Neither the store nor the spool could take it.
    #[error("the audit record could be neither stored ({store}) nor spooled ({spool})")]
    Unavailable { store: String, spool: String },
    /// The record can never be stored (e.g. a field too long).
    #[error("the audit record was refused: {0}")]
    Rejected(String),
    /// The trail has stopped.
    #[error("the audit trail is not running")]
    Stopped,
}

/// A snapshot of the trail's health.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct AuditMetrics {
    /// Records stored straight away.
    pub stored: u64,
    /// Records appended to the spool.
    pub spooled: u64,
    /// Records replayed from the spool into the store.
    pub replayed: u64,
    /// Records in the spool, waiting for the store.
    pub pending: u64,
    /// Records neither stored nor spooled (or never storable).
    pub lost: u64,
    /// Torn or unreadable spool lines found (each reported).
    pub torn_lines: u64,
    /// Whether the spool is in use (the store is, or was lately, away).
    pub spooling: bool,
}

#[derive(Default)]
struct Counters {
    stored: AtomicU64,
    spooled: AtomicU64,
    replayed: AtomicU64,
    pending: AtomicU64,
    lost: AtomicU64,
    torn: AtomicU64,
}

struct Shared {
    counters: Counters,
    spooling: watch::Sender<bool>,
}

type Ack = oneshot::Sender<Result<(), AuditError>>;

// Nearly every message is a record; boxing it would only add an allocation.
#[allow(clippy::large_enum_variant)]
enum Msg {
    Record(AuditBody, Option<Ack>),
    /// Can a record be made durable now?
    Probe(Ack),
}

/// Hands records to the trail. Cheap to clone.
#[derive(Clone)]
pub struct AuditHandle {
    tx: mpsc::Sender<Msg>,
    shared: Arc<Shared>,
}

/// The trail task. Stop it with [`AuditTrail::shutdown`] after its producers.
pub struct AuditTrail {
    handle: AuditHandle,
    stop: watch::Sender<bool>,
    task: JoinHandle<()>,
}

impl AuditHandle {
    /// Queues a record (waiting only while the queue is full). Its fate is
    /// counted in the metrics and logged if it is lost.
    pub async fn record(&self, body: AuditBody) {
        if self.tx.send(Msg::Record(body, None)).await.is_err() {
            self.shared.counters.lost.fetch_add(1, Ordering::Relaxed);
            tracing::error!("audit trail stopped: a record offered after it stopped was lost");
        }
    }

    /// Records and waits until the record is durable: in the store or fsync'd
    /// in the spool. A command must not go ahead when this fails.
    pub async fn record_durable(&self, body: AuditBody) -> Result<(), AuditError> {
        let (ack, answer) = oneshot::channel();
        self.tx
            .send(Msg::Record(body, Some(ack)))
            .await
            .map_err(|_| AuditError::Stopped)?;
        answer.await.map_err(|_| AuditError::Stopped)?
    }

    /// Whether a record handed over now would be made durable: the store
    /// answers, or the spool can be written. For commands whose record the
    /// component makes itself (a panel sequence, the alarm engine), through
    /// this same trail.
    pub async fn probe(&self) -> Result<(), AuditError> {
        let (ack, answer) = oneshot::channel();
        self.tx
            .send(Msg::Probe(ack))
            .await
            .map_err(|_| AuditError::Stopped)?;
        answer.await.map_err(|_| AuditError::Stopped)?
    }

    pub fn metrics(&self) -> AuditMetrics {
        let c = &self.shared.counters;
        AuditMetrics {
            stored: c.stored.load(Ordering::Relaxed),
            spooled: c.spooled.load(Ordering::Relaxed),
            replayed: c.replayed.load(Ordering::Relaxed),
            pending: c.pending.load(Ordering::Relaxed),
            lost: c.lost.load(Ordering::Relaxed),
            torn_lines: c.torn.load(Ordering::Relaxed),
            spooling: *self.shared.spooling.borrow(),
        }
    }

    /// Follows whether the spool is in use. Raise a system alarm on it.
    pub fn spooling(&self) -> watch::Receiver<bool> {
        self.shared.spooling.subscribe()
    }
}

impl AuditTrail {
    /// Reads a spool left by an earlier run (cutting off a torn last line),
    /// numbers on from above every stored and spooled id, and starts the
    /// task, which replays the leftover spool before anything new.
    pub async fn start(store: Store, config: AuditConfig) -> std::io::Result<AuditTrail> {
        let path = config.spool_dir.join(SPOOL_FILE);
        let read = {
            let path = path.clone();
            tokio::task::spawn_blocking(move || read_spool(&path))
                .await
                .map_err(std::io::Error::other)??
        };
        let shared = Arc::new(Shared {
            counters: Counters::default(),
            spooling: watch::channel(!read.records.is_empty()).0,
        });
        shared
            .counters
            .torn
            .store(read.bad_lines as u64, Ordering::Relaxed);
        shared
            .counters
            .pending
            .store(read.records.len() as u64, Ordering::Relaxed);
        if !read.records.is_empty() {
            tracing::warn!(
                records = read.records.len(),
                spool = %path.display(),
                "audit spool left by an earlier run: replaying it before anything new"
            );
        }
        let stored_max = match store.max_audit_id().await {
            Ok(m) => m,
            Err(e) => {
                tracing::warn!(error = %e, "could not read the last audit id; numbering from the clock");
                0
            }
        };
        let spooled_max = read.records.iter().map(|r| r.seq).max().unwrap_or(0);
        // The clock (in microseconds) as a floor keeps ids rising across a
        // restart even if the store was replaced.
        let now_us = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.as_micros() as i64)
            .unwrap_or(0);
        let next_seq = stored_max.max(spooled_max).max(now_us) + 1;
        let (tx, rx) = mpsc::channel(4096);
        let (stop, stop_rx) = watch::channel(false);
        let task_state = Task {
            store,
            path,
            backoff: Duration::from_millis(100),
            next_drain: Instant::now(),
            pending: read.records.into(),
            next_seq,
            shared: shared.clone(),
            config,
        };
        let task = tokio::spawn(task_state.run(rx, stop_rx));
        Ok(AuditTrail {
            handle: AuditHandle { tx, shared },
            stop,
            task,
        })
    }

    pub fn handle(&self) -> AuditHandle {
        self.handle.clone()
    }

    /// Takes what is queued (stored or spooled), one last replay attempt,
    /// then stops. What is still in the spool is replayed at the next start.
    pub async fn shutdown(self) -> AuditMetrics {
        self.stop.send_replace(true);
        if let Err(e) = self.task.await {
            tracing::error!(error = %e, "audit trail task failed");
        }
        self.handle.metrics()
    }
}

struct Task {
    store: Store,
    path: PathBuf,
    config: AuditConfig,
    /// What the spool holds, oldest first (the file's contents).
    pending: VecDeque<AuditRecord>,
    next_seq: i64,
    backoff: Duration,
    next_drain: Instant,
    shared: Arc<Shared>,
}

impl Task {
    async fn run(mut self, mut rx: mpsc::Receiver<Msg>, mut stop: watch::Receiver<bool>) {
        let batch_max = self.config.batch_max.max(1);
        let mut msgs = Vec::with_capacity(batch_max);
        loop {
            let drain_due = !self.pending.is_empty();
            let next_drain = self.next_drain;
            tokio::select! {
                // A stop wins; a due replay goes before more records, so a
                // flood of new records cannot starve it.
                biased;
                r = stop.changed() => {
                    if r.is_err() || *stop.borrow() {
                        break;
                    }
                }
                _ = tokio::time::sleep_until(next_drain), if drain_due => self.replay_some().await,
                n = rx.recv_many(&mut msgs, batch_max) => {
                    if n == 0 {
                        break;
                    }
                    self.take(msgs.drain(..)).await;
                }
            }
        }
        rx.close();
        while let Ok(m) = rx.try_recv() {
            msgs.push(m);
        }
        if !msgs.is_empty() {
            self.take(msgs.drain(..)).await;
        }
        if !self.pending.is_empty() {
            self.replay_some().await;
        }
        if !self.pending.is_empty() {
            tracing::warn!(
                records = self.pending.len(),
                spool = %self.path.display(),
                "audit spool kept for the next start"
            );
        }
    }

    /// Numbers the records in arrival order, then stores them, or spools
    /// them when the spool is in use or the store fails.
    async fn take(&mut self, msgs: impl Iterator<Item = Msg>) {
        let mut records = Vec::new();
        let mut acks = Vec::new();
        let mut probes = Vec::new();
        for m in msgs {
            match m {
                Msg::Record(body, ack) => {
                    let seq = self.next_seq;
                    self.next_seq += 1;
                    records.push(AuditRecord { seq, body });
                    if let Some(ack) = ack {
                        acks.push((seq, ack));
                    }
                }
                Msg::Probe(ack) => probes.push(ack),
            }
        }
        if !records.is_empty() {
            let outcome = self.durable(records).await;
            for (seq, ack) in acks {
                let r = match &outcome {
                    Ok(rejected) => match rejected.iter().find(|(s, _)| *s == seq) {
                        Some((_, why)) => Err(AuditError::Rejected(why.clone())),
                        None => Ok(()),
                    },
                    Err(e) => Err(e.clone()),
                };
                let _ = ack.send(r);
            }
        }
        for ack in probes {
            let _ = ack.send(self.probe().await);
        }
    }

    /// Makes records durable; returns the ids the store refused for good.
    async fn durable(
        &mut self,
        records: Vec<AuditRecord>,
    ) -> Result<Vec<(i64, String)>, AuditError> {
        let n = records.len() as u64;
        let store_error = if self.pending.is_empty() {
            match self.write(&records).await {
                Ok(rejected) => {
                    let c = &self.shared.counters;
                    c.stored
                        .fetch_add(n - rejected.len() as u64, Ordering::Relaxed);
                    return Ok(rejected);
                }
                Err(e) => {
                    tracing::warn!(error = %e, records = n,
                        "the store cannot take audit records; spooling them");
                    e
                }
            }
        } else {
            "the spool is in use (records keep their order behind it)".to_string()
        };
        match append(&self.config.spool_dir, &self.path, &records).await {
            Ok(()) => {
                let c = &self.shared.counters;
                c.spooled.fetch_add(n, Ordering::Relaxed);
                if self.pending.is_empty() {
                    self.backoff = Duration::from_millis(100);
                    self.next_drain = Instant::now() + self.backoff;
                }
                self.pending.extend(records);
                c.pending
                    .store(self.pending.len() as u64, Ordering::Relaxed);
                self.shared
                    .spooling
                    .send_if_modified(|s| !std::mem::replace(s, true));
                Ok(Vec::new())
            }
            Err(e) => {
                self.shared.counters.lost.fetch_add(n, Ordering::Relaxed);
                tracing::error!(error = %e, spool = %self.path.display(), lost = n,
                    "audit records could be neither stored nor spooled: LOST");
                Err(AuditError::Unavailable {
                    store: store_error,
                    spool: e.to_string(),
                })
            }
        }
    }

    /// One store write, bounded by the write timeout. Returns the records
    /// refused for good, by id.
    async fn write(&self, records: &[AuditRecord]) -> Result<Vec<(i64, String)>, String> {
        match tokio::time::timeout(self.config.write_timeout, self.store.insert_audit(records))
            .await
        {
            Ok(Ok(rejected)) => {
                for (seq, e) in &rejected {
                    self.shared.counters.lost.fetch_add(1, Ordering::Relaxed);
                    tracing::error!(seq, error = %e, "audit record can never be stored: dropped");
                }
                Ok(rejected
                    .into_iter()
                    .map(|(s, e)| (s, e.to_string()))
                    .collect())
            }
            Ok(Err(e)) => Err(e.to_string()),
            Err(_) => Err(format!(
                "no answer within {} ms",
                self.config.write_timeout.as_millis()
            )),
        }
    }

    /// Replays the oldest spooled records; removes the spool once empty.
    async fn replay_some(&mut self) {
        let n = self.pending.len().min(self.config.batch_max.max(1));
        let chunk: Vec<AuditRecord> = self.pending.iter().take(n).cloned().collect();
        match self.write(&chunk).await {
            Ok(rejected) => {
                self.pending.drain(..n);
                let c = &self.shared.counters;
                c.replayed
                    .fetch_add((n - rejected.len()) as u64, Ordering::Relaxed);
                c.pending
                    .store(self.pending.len() as u64, Ordering::Relaxed);
                self.backoff = Duration::from_millis(100);
                self.next_drain = Instant::now();
                if self.pending.is_empty() {
                    if let Err(e) = remove(&self.path).await {
                        // Harmless: a later replay of it stores nothing twice.
                        tracing::error!(error = %e, spool = %self.path.display(),
                            "could not remove the replayed audit spool");
                    }
                    tracing::info!(
                        replayed = c.replayed.load(Ordering::Relaxed),
                        "audit spool replayed into the store"
                    );
                    self.shared
                        .spooling
                        .send_if_modified(|s| std::mem::replace(s, false));
                }
            }
            Err(e) => {
                tracing::warn!(error = %e, pending = self.pending.len(), retry_in = ?self.backoff,
                    "audit spool replay failed; retrying");
                self.next_drain = Instant::now() + self.backoff;
                self.backoff = (self.backoff * 2).min(self.config.max_backoff);
            }
        }
    }

    async fn probe(&self) -> Result<(), AuditError> {
        let store = if self.pending.is_empty() {
            match tokio::time::timeout(self.config.write_timeout, self.store.ping()).await {
                Ok(Ok(())) => return Ok(()),
                Ok(Err(e)) => e.to_string(),
                Err(_) => "no answer".to_string(),
            }
        } else {
            "the spool is in use".to_string()
        };
        match append(&self.config.spool_dir, &self.path, &[]).await {
            Ok(()) => Ok(()),
            Err(e) => Err(AuditError::Unavailable {
                store,
                spool: e.to_string(),
            }),
        }
    }
}

/// Appends records to the spool and fsyncs it (and, when it creates the
/// file, its folder). With no records it only checks the spool can be
/// opened for appending.
async fn append(dir: &Path, path: &Path, records: &[AuditRecord]) -> std::io::Result<()> {
    let mut buf = Vec::new();
    for r in records {
        serde_json::to_writer(&mut buf, r)?;
        buf.push(b'\n');
    }
    let (dir, path) = (dir.to_path_buf(), path.to_path_buf());
    tokio::task::spawn_blocking(move || {
        std::fs::create_dir_all(&dir)?;
        let created = !path.exists();
        let mut f = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(&path)?;
        if !buf.is_empty() {
            f.write_all(&buf)?;
            f.sync_data()?;
        }
        if created {
            sync_dir(&dir)?;
        }
        Ok(())
    })
    .await
    .map_err(std::io::Error::other)?
}

async fn remove(path: &Path) -> std::io::Result<()> {
    let path = path.to_path_buf();
    tokio::task::spawn_blocking(move || {
        match std::fs::remove_file(&path) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(()),
            Err(e) => return Err(e),
        }
        match path.parent() {
            Some(dir) => sync_dir(dir),
            None => Ok(()),
        }
    })
    .await
    .map_err(std::io::Error::other)?
}

fn sync_dir(dir: &Path) -> std::io::Result<()> {
    #[cfg(unix)]
    std::fs::File::open(dir)?.sync_all()?;
    #[cfg(not(unix))]
    let _ = dir;
    Ok(())
}

/// What a spool file held.
#[derive(Debug, Default)]
pub struct SpoolContents {
    pub records: Vec<AuditRecord>,
    /// Lines that were torn (the last, unterminated) or unreadable.
    pub bad_lines: usize,
}

/// Reads a spool. An unterminated last line is a torn append (the process
/// died in the middle of it, before it was acknowledged): it is reported and
/// cut off the file, so the next append starts on a line of its own. An
/// unreadable complete line is reported and skipped.
pub fn read_spool(path: &Path) -> std::io::Result<SpoolContents> {
    let bytes = match std::fs::read(path) {
        Ok(b) => b,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(SpoolContents::default()),
        Err(e) => return Err(e),
    };
    let mut out = SpoolContents::default();
    let complete = bytes.iter().rposition(|b| *b == b'\n').map_or(0, |i| i + 1);
    for (i, line) in bytes[..complete].split(|b| *b == b'\n').enumerate() {
        if line.is_empty() {
            continue;
        }
        match serde_json::from_slice::<AuditRecord>(line) {
            Ok(r) => out.records.push(r),
            Err(e) => {
                out.bad_lines += 1;
                tracing::error!(spool = %path.display(), line = i + 1, error = %e,
                    "unreadable audit spool line skipped");
            }
        }
    }
    if complete < bytes.len() {
        out.bad_lines += 1;
        tracing::error!(
            spool = %path.display(),
            bytes = bytes.len() - complete,
            "torn last line in the audit spool (a crash during an append; that record \
             was never acknowledged): cut off"
        );
        let f = std::fs::OpenOptions::new().write(true).open(path)?;
        f.set_len(complete as u64)?;
        f.sync_all()?;
    }
    Ok(out)
}
