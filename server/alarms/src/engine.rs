//! The alarm engine: the thin async shell around [`AlarmSet`].
//!
//! **Owns:** feeding tag database changes into the alarm set, running its
//! timers on the plant [`Clock`], serialising operator operations with
//! evaluation, and handing transitions, events and state records to the
//! channels the application gives it (in the order they happened). It also
//! publishes a version counter that changes whenever the alarm list changes,
//! for the HMI push.
//!
//! **Must not touch:** the store, the web layer. Persistence is whoever reads
//! the channels; restore is a list of [`AlarmStateRecord`]s passed in.
//!
//! Outputs go first to an internal unbounded queue, under the same lock as
//! the state change, so their order is the order of the changes; a forwarder
//! task then sends them to the (bounded) application channels. A slow store
//! therefore never stalls alarm evaluation or an operator's acknowledgement;
//! the queue length is reported in [`EngineStats`].

use std::collections::{BTreeSet, VecDeque};
use std::sync::atomic::{AtomicI64, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Duration;

use gridscada_config::Plant;
use gridscada_tagdb::{Clock, TagDb, TagId, Update};
use parking_lot::Mutex;
use serde::Serialize;
use tokio::sync::{mpsc, watch, Notify};

use crate::events::Event;
use crate::machine::AlarmDef;
use crate::model::{
    AlarmError, AlarmFilter, AlarmId, AlarmStateRecord, AlarmTransition, AlarmView,
};
use crate::set::{AlarmSet, InputId, Outputs, RestoreReport};
use crate::suppression::{plant_rules, SuppressionRule};

/// Where the engine sends what it produces.
#[derive(Debug, Clone)]
pub struct AlarmChannels {
    /// Every state transition: alarm history.
    pub transitions: mpsc::Sender<AlarmTransition>,
    /// Operator actions on alarms (ack, shelve, unshelve, out of service) and
    /// shelving expiry: the event log.
    pub events: mpsc::Sender<Event>,
    /// The new persistent state of every alarm that changed, for an upsert
    /// keyed by `key`. Optional: [`AlarmEngine::persisted_states`] gives all.
    pub states: Option<mpsc::Sender<AlarmStateRecord>>,
}

/// Engine settings.
#[derive(Debug, Clone)]
pub struct EngineOptions {
    /// Suppression rules; `None`: the plant's ([`plant_rules`]: the panels'
    /// defaults and the configured `[[suppression]]` rules).
    pub rules: Option<Vec<SuppressionRule>>,
    /// Longest the engine sleeps between timer checks (plant time).
    pub max_tick: Duration,
}

impl Default for EngineOptions {
    fn default() -> Self {
        EngineOptions {
            rules: None,
            max_tick: Duration::from_secs(1),
        }
    }
}

/// Counters for `/metrics` and the diagnostics page.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize)]
pub struct EngineStats {
    pub alarms: usize,
    pub active: usize,
    pub unacked: usize,
    pub shelved: usize,
    pub suppressed: usize,
    pub out_of_service: usize,
    /// Alarm condition evaluations since start (a counter: rate() gives
    /// evaluations per second).
    pub evaluations_total: u64,
    /// Time spent evaluating changes and running the timers since start, in
    /// nanoseconds (a counter: its rate is the share of a core the alarm
    /// evaluation takes).
    pub evaluation_nanos_total: u64,
    pub transitions_total: u64,
    /// Outputs waiting to be taken by the application channels.
    pub queued_outputs: u64,
}

/// Versions remembered with what they changed: a client further behind
/// than this is sent the whole list.
const CHANGE_LOG: usize = 512;

/// What one version of the alarm list changed.
#[derive(Debug)]
enum VersionChange {
    /// These alarms, and nothing else.
    Alarms(Vec<AlarmId>),
    /// Anything may have changed.
    Any,
}

/// The alarm list for a client, whole or as the changes since its version.
#[derive(Debug, Clone, PartialEq)]
pub enum AlarmListUpdate {
    Whole {
        version: u64,
        alarms: Vec<AlarmView>,
    },
    Changes {
        version: u64,
        since: u64,
        /// The alarms changed since, as the list shows them now (not sorted).
        changed: Vec<AlarmView>,
        /// Alarms changed since that the list no longer shows.
        removed: Vec<AlarmId>,
    },
}

#[derive(Debug)]
enum Output {
    Transition(AlarmTransition),
    Event(Event),
    State(AlarmStateRecord),
}

/// The alarm engine. Build with [`AlarmEngine::new`], then spawn
/// [`AlarmEngine::run`]; operations may be called from any task.
pub struct AlarmEngine {
    set: Mutex<AlarmSet>,
    db: Arc<TagDb>,
    clock: Arc<dyn Clock>,
    /// Input of each tag id, by tag index. Grows when alarms are defined
    /// at run time ([`AlarmEngine::define`]).
    bind: Mutex<Vec<Option<InputId>>>,
    watched: Mutex<Vec<TagId>>,
    /// The watched tags changed: the run loop subscribes to the new set.
    rewatch: Notify,
    outbox: mpsc::UnboundedSender<Output>,
    outbox_rx: Mutex<Option<mpsc::UnboundedReceiver<Output>>>,
    channels: Mutex<Option<AlarmChannels>>,
    queued: AtomicI64,
    transitions_total: AtomicU64,
    evaluation_nanos: AtomicU64,
    version: watch::Sender<u64>,
    /// Which alarms each recent version changed, newest last, so a live list
    /// can be kept up to date with the changes instead of the whole list.
    changes: Mutex<VecDeque<(u64, VersionChange)>>,
    wake: Notify,
    max_tick: Duration,
}

impl AlarmEngine {
    /// Builds the engine from the plant's alarm configuration, devices and
    /// panels, restoring `restore` (the persisted states; empty on first start).
    pub fn new(
        plant: &Plant,
        db: Arc<TagDb>,
        clock: Arc<dyn Clock>,
        channels: AlarmChannels,
        restore: &[AlarmStateRecord],
        options: EngineOptions,
    ) -> Result<Arc<AlarmEngine>, AlarmError> {
        let rules = options.rules.unwrap_or_else(|| plant_rules(plant));
        let set = AlarmSet::from_plant(plant, rules)?;
        Ok(Self::with_set(
            set,
            db,
            clock,
            channels,
            restore,
            options.max_tick,
        ))
    }

    /// Builds the engine around an already built alarm set (tests, tools).
    pub fn with_set(
        mut set: AlarmSet,
        db: Arc<TagDb>,
        clock: Arc<dyn Clock>,
        channels: AlarmChannels,
        restore: &[AlarmStateRecord],
        max_tick: Duration,
    ) -> Arc<AlarmEngine> {
        if !restore.is_empty() {
            let RestoreReport {
                restored,
                recreated,
                skipped,
            } = set.restore(restore);
            tracing::info!(
                restored,
                recreated,
                skipped = skipped.len(),
                "alarm states restored"
            );
            if !skipped.is_empty() {
                tracing::warn!(keys = ?skipped, "persisted alarm states without a configured alarm were dropped");
            }
        }
        let mut bind = vec![None; db.len()];
        let mut watched = Vec::new();
        let mut missing = Vec::new();
        for (input, tag) in set.inputs() {
            match db.id(tag) {
                Some(id) => {
                    bind[id.index()] = Some(input);
                    watched.push(id);
                }
                // Error-text tags are optional; condition tags are not.
                None if tag.ends_with(".Comm.LastError") => {}
                None => missing.push(tag.to_owned()),
            }
        }
        if !missing.is_empty() {
            tracing::warn!(
                count = missing.len(),
                first = ?missing.iter().take(10).collect::<Vec<_>>(),
                "alarm input tags missing from the tag database; their alarms will never activate"
            );
        }
        let (outbox, outbox_rx) = mpsc::unbounded_channel();
        Arc::new(AlarmEngine {
            set: Mutex::new(set),
            db,
            clock,
            bind: Mutex::new(bind),
            watched: Mutex::new(watched),
            rewatch: Notify::new(),
            outbox,
            outbox_rx: Mutex::new(Some(outbox_rx)),
            channels: Mutex::new(Some(channels)),
            queued: AtomicI64::new(0),
            transitions_total: AtomicU64::new(0),
            evaluation_nanos: AtomicU64::new(0),
            version: watch::Sender::new(0),
            changes: Mutex::new(VecDeque::new()),
            wake: Notify::new(),
            max_tick: max_tick.max(Duration::from_millis(10)),
        })
    }

    /// Runs the engine until the tag database is dropped: evaluates the
    /// current values, then every change, and runs the timers. Spawns the
    /// forwarder to the application channels. Call once.
    pub async fn run(self: Arc<Self>) {
        let rx = self.outbox_rx.lock().take();
        let channels = self.channels.lock().take();
        let (Some(rx), Some(channels)) = (rx, channels) else {
            tracing::error!("AlarmEngine::run called twice; the second call does nothing");
            return;
        };
        let forwarder = Arc::clone(&self);
        tokio::spawn(async move { forwarder.forward(rx, channels).await });

        let watched = self.watched.lock().clone();
        let mut sub = self.db.subscribe(&watched);
        // Start from the current values: the subscription only brings changes.
        let snap = self.db.snapshot(&watched);
        self.apply_changes(&snap.changes);
        loop {
            let now = self.clock.now();
            let due = self.set.lock().next_deadline();
            if due.is_some_and(|d| d <= now) {
                self.tick_at(now);
                continue;
            }
            let wait = due
                .map(|d| d.since(now))
                .unwrap_or(self.max_tick)
                .clamp(Duration::from_millis(1), self.max_tick);
            tokio::select! {
                update = sub.recv() => match update {
                    // A snapshot after lag carries every watched tag's current
                    // sample; evaluation is idempotent, so both apply alike.
                    Some(Update::Changes(b)) | Some(Update::Snapshot(b)) => self.apply_changes(&b.changes),
                    None => break,
                },
                _ = self.clock.sleep(wait) => {}
                _ = self.wake.notified() => {}
                // Alarms defined at run time: watch their tags too, from
                // their current values.
                _ = self.rewatch.notified() => {
                    let watched = self.watched.lock().clone();
                    let snap = sub.watch(Some(&watched));
                    self.apply_changes(&snap.batch().changes);
                }
            }
        }
        tracing::info!("tag database closed; alarm engine stopped");
    }

    fn apply_changes(&self, changes: &[(TagId, gridscada_tagdb::Sample)]) {
        let bind = self.bind.lock();
        let batch: Vec<(InputId, &gridscada_tagdb::Sample)> = changes
            .iter()
            .filter_map(|(id, s)| bind.get(id.index()).copied().flatten().map(|i| (i, s)))
            .collect();
        drop(bind);
        if batch.is_empty() {
            return;
        }
        let now = self.clock.now();
        self.timed(|| self.with_set_mut(|set, out| set.apply(&batch, now, out)));
    }

    fn tick_at(&self, now: gridscada_tagdb::Timestamp) {
        self.timed(|| self.with_set_mut(|set, out| set.tick(now, out)));
    }

    /// Runs `f`, adding its wall time to the evaluation counter.
    fn timed<R>(&self, f: impl FnOnce() -> R) -> R {
        let started = std::time::Instant::now();
        let r = f();
        self.evaluation_nanos.fetch_add(
            u64::try_from(started.elapsed().as_nanos()).unwrap_or(u64::MAX),
            Ordering::Relaxed,
        );
        r
    }

    /// Runs `f` on the set under the lock and queues what it produced.
    fn with_set_mut<R>(&self, f: impl FnOnce(&mut AlarmSet, &mut Outputs) -> R) -> R {
        let mut out = Outputs::default();
        let mut set = self.set.lock();
        let r = f(&mut set, &mut out);
        if !out.is_empty() {
            self.publish(&set, out);
        }
        r
    }

    fn publish(&self, set: &AlarmSet, out: Outputs) {
        let changed: BTreeSet<AlarmId> = out.transitions.iter().map(|t| t.id).collect();
        let mut n = 0i64;
        self.transitions_total
            .fetch_add(out.transitions.len() as u64, Ordering::Relaxed);
        for t in out.transitions {
            n += 1;
            let _ = self.outbox.send(Output::Transition(t));
        }
        for &id in &changed {
            if let Some(r) = set.record(id) {
                n += 1;
                let _ = self.outbox.send(Output::State(r));
            }
        }
        for e in out.events {
            n += 1;
            let _ = self.outbox.send(Output::Event(e));
        }
        self.queued.fetch_add(n, Ordering::Relaxed);
        // Shown without a transition (a comm alarm's error text, a message):
        // no list of ids says what changed.
        self.bump_version(if out.view_changed || changed.is_empty() {
            VersionChange::Any
        } else {
            VersionChange::Alarms(changed.into_iter().collect())
        });
        // A new timer (delay, shelving) may be earlier than the run loop's sleep.
        self.wake.notify_one();
    }

    async fn forward(&self, mut rx: mpsc::UnboundedReceiver<Output>, ch: AlarmChannels) {
        let mut warned = false;
        while let Some(o) = rx.recv().await {
            self.queued.fetch_sub(1, Ordering::Relaxed);
            let ok = match o {
                Output::Transition(t) => ch.transitions.send(t).await.is_ok(),
                Output::Event(e) => ch.events.send(e).await.is_ok(),
                Output::State(r) => match &ch.states {
                    Some(s) => s.send(r).await.is_ok(),
                    None => true,
                },
            };
            if !ok && !warned {
                warned = true;
                tracing::warn!("an alarm output channel is closed; alarm history or events are no longer stored");
            }
        }
    }

    fn op<R>(
        &self,
        f: impl FnOnce(&mut AlarmSet, gridscada_tagdb::Timestamp, &mut Outputs) -> Result<R, AlarmError>,
    ) -> Result<R, AlarmError> {
        let now = self.clock.now();
        self.with_set_mut(|set, out| f(set, now, out))
    }

    /// The alarms the filter shows, newest change first.
    pub fn summary(&self, filter: &AlarmFilter) -> Vec<AlarmView> {
        self.set.lock().summary(filter)
    }

    pub fn view(&self, id: AlarmId) -> Option<AlarmView> {
        self.set.lock().view(id)
    }

    pub fn id_of(&self, key: &str) -> Option<AlarmId> {
        self.set.lock().id_of(key)
    }

    /// "Ack Top": the newest unacknowledged alarm within the filter.
    pub fn ack_top(&self, user: &str, filter: &AlarmFilter) -> Result<Option<AlarmId>, AlarmError> {
        self.op(|s, now, out| s.ack_top(filter, user, now, out))
    }

    /// Acknowledges the listed alarms; returns those that were waiting for it.
    pub fn ack_ids(&self, user: &str, ids: &[AlarmId]) -> Result<Vec<AlarmId>, AlarmError> {
        self.op(|s, now, out| s.ack_ids(ids, user, now, out))
    }

    /// "Ack All" within the filter.
    pub fn ack_all(&self, user: &str, filter: &AlarmFilter) -> Result<Vec<AlarmId>, AlarmError> {
        self.op(|s, now, out| s.ack_all(filter, user, now, out))
    }

    /// Shelves alarm `id` for `minutes` (1 to 10080). Returns when it expires.
    pub fn shelve(
        &self,
        id: AlarmId,
        user: &str,
        minutes: u32,
        reason: &str,
    ) -> Result<gridscada_tagdb::Timestamp, AlarmError> {
        let d = Duration::from_secs(u64::from(minutes) * 60);
        self.op(|s, now, out| s.shelve(id, user, d, reason, now, out))
    }

    pub fn unshelve(&self, id: AlarmId, user: &str) -> Result<(), AlarmError> {
        self.op(|s, now, out| s.unshelve(id, user, now, out))
    }

    /// Takes alarm `id` out of service (`true`, reason required) or returns it.
    pub fn set_out_of_service(
        &self,
        id: AlarmId,
        user: &str,
        out_of_service: bool,
        reason: &str,
    ) -> Result<bool, AlarmError> {
        self.op(|s, now, out| {
            s.set_out_of_service(id, user, out_of_service, reason, None, now, out)
        })
    }

    /// Takes alarm `id` out of service until `until` (then it returns by
    /// itself, recorded as the cause `in_service` with no user).
    pub fn out_of_service_until(
        &self,
        id: AlarmId,
        user: &str,
        reason: &str,
        until: gridscada_tagdb::Timestamp,
    ) -> Result<bool, AlarmError> {
        self.op(|s, now, out| s.set_out_of_service(id, user, true, reason, Some(until), now, out))
    }

    /// Adds alarm definitions while the engine runs: the alarms of tags
    /// that appear at run time (a central Sparkplug host's remote tags,
    /// whose edge declares them in its births). A key already defined is
    /// kept as it is (a rebirth declares the same alarms again). A
    /// definition that cannot be taken (its tag is not in the database, a
    /// bad limit) is an error; the others are defined all the same. Returns
    /// the keys added.
    pub fn define(&self, defs: Vec<AlarmDef>) -> Result<Vec<String>, AlarmError> {
        let mut added = Vec::new();
        let mut refused = None;
        let mut new_tags = Vec::new();
        {
            let mut set = self.set.lock();
            for def in defs {
                if set.id_of(&def.key).is_some() {
                    continue;
                }
                if let Some(tag) = def.tag.as_deref().filter(|t| self.db.id(t).is_none()) {
                    refused.get_or_insert(AlarmError::invalid(
                        format!("alarm '{}'", def.key),
                        format!("tag '{tag}' is not in the tag database"),
                    ));
                    continue;
                }
                let key = def.key.clone();
                match set.define(def) {
                    Ok(_) => added.push(key),
                    Err(e) => {
                        refused.get_or_insert(e);
                    }
                }
            }
            if !added.is_empty() {
                let mut bind = self.bind.lock();
                for (input, tag) in set.inputs() {
                    let Some(id) = self.db.id(tag) else { continue };
                    if bind.len() <= id.index() {
                        bind.resize(id.index() + 1, None);
                    }
                    if bind[id.index()].is_none() {
                        bind[id.index()] = Some(input);
                        new_tags.push(id);
                    }
                }
            }
        }
        if !added.is_empty() {
            self.watched.lock().extend(new_tags);
            self.rewatch.notify_one();
            self.bump_version(VersionChange::Any);
        }
        match refused {
            Some(e) => Err(e),
            None => Ok(added),
        }
    }

    /// Raises system alarm `key` (sequence lockout, dispatch fallback,
    /// historian overflow...). Raising again updates the message.
    pub fn raise(
        &self,
        key: &str,
        priority: u32,
        selection: &str,
        message: &str,
    ) -> Result<AlarmId, AlarmError> {
        self.op(|s, now, out| s.raise(key, priority, selection, message, now, out))
    }

    /// Clears system alarm `key`; Ok(false) if it was not raised.
    pub fn clear(&self, key: &str) -> Result<bool, AlarmError> {
        self.op(|s, now, out| s.clear(key, now, out))
    }

    /// Every alarm's persistent state (for a full save, e.g. at shutdown).
    /// Takes over the states another server of a redundant pair persisted
    /// (acknowledgements, shelving, what stands), as at a start: the server
    /// becoming active continues from the record the active one left, and
    /// the next evaluation moves on from there.
    pub fn adopt(&self, records: &[AlarmStateRecord]) {
        let report = self.set.lock().restore(records);
        tracing::info!(
            restored = report.restored,
            skipped = report.skipped.len(),
            "alarm states taken over"
        );
        self.bump_version(VersionChange::Any);
        self.wake.notify_one();
    }

    pub fn persisted_states(&self) -> Vec<AlarmStateRecord> {
        self.set.lock().records()
    }

    /// A counter that changes whenever the alarm list may have changed.
    pub fn subscribe_version(&self) -> watch::Receiver<u64> {
        self.version.subscribe()
    }

    /// Moves the version on, noting what changed.
    fn bump_version(&self, change: VersionChange) {
        let mut log = self.changes.lock();
        let mut version = 0;
        self.version.send_modify(|v| {
            *v += 1;
            version = *v;
        });
        log.push_back((version, change));
        while log.len() > CHANGE_LOG {
            log.pop_front();
        }
    }

    /// The default alarm list (as [`AlarmEngine::summary`] with the default
    /// filter) for a client that has the list of version `since`: nothing
    /// if it is current; the changed alarms and the ids that left the list
    /// if the versions since are still known and name their alarms; else
    /// the whole list.
    pub fn summary_since(&self, since: Option<u64>) -> Option<AlarmListUpdate> {
        // Under the set's lock, the version and the set agree: a change
        // publishes its version before the lock is released.
        let set = self.set.lock();
        let version = *self.version.borrow();
        let filter = AlarmFilter::default();
        let since = match since {
            Some(s) if s == version => return None,
            Some(s) if s < version => s,
            _ => {
                return Some(AlarmListUpdate::Whole {
                    version,
                    alarms: set.summary(&filter),
                })
            }
        };
        let log = self.changes.lock();
        let mut ids = BTreeSet::new();
        let complete = log.front().is_some_and(|(v, _)| *v <= since + 1)
            && log
                .iter()
                .filter(|(v, _)| *v > since)
                .all(|(_, c)| match c {
                    VersionChange::Alarms(a) => {
                        ids.extend(a.iter().copied());
                        true
                    }
                    VersionChange::Any => false,
                });
        drop(log);
        if !complete {
            return Some(AlarmListUpdate::Whole {
                version,
                alarms: set.summary(&filter),
            });
        }
        let (changed, removed) = set.summary_of(ids, &filter);
        Some(AlarmListUpdate::Changes {
            version,
            since,
            changed,
            removed,
        })
    }

    pub fn evaluations_total(&self) -> u64 {
        self.set.lock().evaluations()
    }

    pub fn stats(&self) -> EngineStats {
        let set = self.set.lock();
        let mut s = EngineStats {
            alarms: set.len(),
            evaluations_total: set.evaluations(),
            transitions_total: self.transitions_total.load(Ordering::Relaxed),
            evaluation_nanos_total: self.evaluation_nanos.load(Ordering::Relaxed),
            queued_outputs: self.queued.load(Ordering::Relaxed).max(0) as u64,
            ..EngineStats::default()
        };
        for i in 0..set.len() {
            let Some(a) = set.alarm(AlarmId(i as u32)) else {
                continue;
            };
            s.active += a.is_active() as usize;
            s.unacked += (!a.is_acked()) as usize;
            s.shelved += a.shelved().is_some() as usize;
            s.suppressed += a.is_suppressed() as usize;
            s.out_of_service += a.out_of_service().is_some() as usize;
        }
        s
    }
}
