//! The in-memory tag database and change subscription.
//!
//! The set of tags is fixed when the database is built (the plant configuration
//! plus the derived status tags), except for a bounded room reserved up front
//! ([`TagDb::with_room`]) that a central Sparkplug host fills at run time from
//! the births of remote sites ([`TagDb::add`]). Tags are only ever appended,
//! never removed or changed, so ids stay dense and stable: lookups by id stay
//! a plain index and by name one hash probe, and every slot is allocated when
//! the database is built, so a `&TagMeta` handed out stays valid.
//!
//! Updates arrive in batches (one poll cycle is one batch). Each batch that
//! changes anything gets the next sequence number and goes out on a bounded
//! broadcast ring. A subscriber that falls behind the ring is never waited for:
//! its next receive returns a fresh snapshot instead, and batches older than the
//! snapshot are skipped, so it never rolls a value back.

use std::collections::HashMap;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, OnceLock};

use parking_lot::RwLock;
use serde::Serialize;
use tokio::sync::broadcast;

use crate::{Quality, Sample, Timestamp, Value, ValueKind};

/// Dense index of a tag in its [`TagDb`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize)]
#[serde(transparent)]
pub struct TagId(pub u32);

impl TagId {
    pub fn index(self) -> usize {
        self.0 as usize
    }
}

/// What the database knows about a tag besides its sample.
#[derive(Debug, Clone, Serialize)]
pub struct TagMeta {
    pub name: Arc<str>,
    pub description: String,
    pub kind: ValueKind,
    pub units: String,
    /// Whether commands may write it (the role check is the web layer's).
    pub writable: bool,
}

impl TagMeta {
    pub fn new(name: impl Into<Arc<str>>, kind: ValueKind) -> Self {
        TagMeta {
            name: name.into(),
            description: String::new(),
            kind,
            units: String::new(),
            writable: false,
        }
    }
    pub fn describe(mut self, description: impl Into<String>) -> Self {
        self.description = description.into();
        self
    }
    pub fn units(mut self, units: impl Into<String>) -> Self {
        self.units = units.into();
        self
    }
    pub fn writable(mut self, writable: bool) -> Self {
        self.writable = writable;
        self
    }
}

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TagDbError {
    #[error("duplicate tag name '{0}'")]
    Duplicate(String),
    #[error("tag name must not be empty")]
    EmptyName,
    #[error("too many tags (at most {} are supported)", u32::MAX)]
    TooMany,
    #[error(
        "no room for tag '{name}': all {room} slots reserved for tags added at run time are taken"
    )]
    Full { name: String, room: usize },
}

/// A batch of changes (or a snapshot), in increasing sequence order.
#[derive(Debug, Clone)]
pub struct ChangeBatch {
    /// The database sequence number after this batch.
    pub seq: u64,
    pub changes: Vec<(TagId, Sample)>,
}

/// What a subscriber receives.
#[derive(Debug, Clone)]
pub enum Update {
    /// The tags that changed since the subscriber's last update.
    Changes(Arc<ChangeBatch>),
    /// The subscriber fell behind: here is the current sample of every tag it
    /// watches. Apply it in place of everything missed.
    Snapshot(Arc<ChangeBatch>),
}

impl Update {
    pub fn batch(&self) -> &ChangeBatch {
        match self {
            Update::Changes(b) | Update::Snapshot(b) => b,
        }
    }
    pub fn is_snapshot(&self) -> bool {
        matches!(self, Update::Snapshot(_))
    }
}

struct Live {
    samples: Vec<Sample>,
    /// Per tag, the observation ticket of its current sample (see
    /// [`TagDb::ticket`]): a sample observed earlier never replaces it.
    tickets: Vec<u64>,
    seq: u64,
    /// The next observation ticket.
    next_ticket: u64,
}

/// The tag database. Cheap to share behind an `Arc`.
pub struct TagDb {
    /// One slot per tag the database can hold; the first `len` are set.
    meta: Vec<OnceLock<TagMeta>>,
    /// How many slots are set (tags added at run time raise it).
    len: AtomicUsize,
    /// How many slots were reserved for tags added at run time.
    room: usize,
    by_name: RwLock<HashMap<Arc<str>, TagId>>,
    live: RwLock<Live>,
    tx: broadcast::Sender<Arc<ChangeBatch>>,
}

/// How many change batches a subscriber may fall behind before it is snapshotted.
const RING_BATCHES: usize = 256;

impl TagDb {
    /// Builds a database holding `tags`; every tag starts Bad ("no value yet").
    pub fn new(tags: impl IntoIterator<Item = TagMeta>) -> Result<TagDb, TagDbError> {
        TagDb::with_room(tags, 0)
    }

    /// Builds a database holding `tags`, with room for `room` more tags added
    /// at run time by [`TagDb::add`]. The room is allocated now.
    pub fn with_room(
        tags: impl IntoIterator<Item = TagMeta>,
        room: usize,
    ) -> Result<TagDb, TagDbError> {
        let mut meta = Vec::new();
        let mut by_name = HashMap::new();
        for tag in tags {
            if tag.name.is_empty() {
                return Err(TagDbError::EmptyName);
            }
            let id = TagId(u32::try_from(meta.len()).map_err(|_| TagDbError::TooMany)?);
            if by_name.insert(tag.name.clone(), id).is_some() {
                return Err(TagDbError::Duplicate(tag.name.to_string()));
            }
            meta.push(OnceLock::from(tag));
        }
        let len = meta.len();
        u32::try_from(len + room).map_err(|_| TagDbError::TooMany)?;
        let mut samples: Vec<Sample> = meta
            .iter()
            .filter_map(|m| m.get())
            .map(|m| Sample::never_read(default_value(m.kind)))
            .collect();
        meta.resize_with(len + room, OnceLock::new);
        samples.resize_with(len + room, || Sample::never_read(Value::Bool(false)));
        let (tx, _) = broadcast::channel(RING_BATCHES);
        Ok(TagDb {
            meta,
            len: AtomicUsize::new(len),
            room,
            by_name: RwLock::new(by_name),
            live: RwLock::new(Live {
                tickets: vec![0; samples.len()],
                samples,
                seq: 0,
                next_ticket: 1,
            }),
            tx,
        })
    }

    /// Adds a tag at run time, in the room reserved by [`TagDb::with_room`];
    /// it starts Bad ("no value yet") like every tag. Subscribers that watch
    /// every tag see its samples from then on.
    pub fn add(&self, tag: TagMeta) -> Result<TagId, TagDbError> {
        if tag.name.is_empty() {
            return Err(TagDbError::EmptyName);
        }
        // Under the samples' lock, so an applier never sees the new id
        // before its slot is ready.
        let mut live = self.live.write();
        let mut by_name = self.by_name.write();
        if by_name.contains_key(&tag.name) {
            return Err(TagDbError::Duplicate(tag.name.to_string()));
        }
        let len = self.len.load(Ordering::Acquire);
        let Some(slot) = self.meta.get(len) else {
            return Err(TagDbError::Full {
                name: tag.name.to_string(),
                room: self.room,
            });
        };
        let id = TagId(len as u32);
        live.samples[len] = Sample::never_read(default_value(tag.kind));
        live.tickets[len] = 0;
        by_name.insert(tag.name.clone(), id);
        // Only this function sets slots, under the lock: the slot is empty.
        let _ = slot.set(tag);
        self.len.store(len + 1, Ordering::Release);
        Ok(id)
    }

    /// How many more tags [`TagDb::add`] can take.
    pub fn room_left(&self) -> usize {
        self.meta.len() - self.len()
    }

    pub fn len(&self) -> usize {
        self.len.load(Ordering::Acquire)
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    pub fn id(&self, name: &str) -> Option<TagId> {
        self.by_name.read().get(name).copied()
    }

    pub fn meta(&self, id: TagId) -> Option<&TagMeta> {
        self.meta.get(id.index()).and_then(OnceLock::get)
    }

    /// Every tag, in id order.
    pub fn all_meta(&self) -> impl Iterator<Item = (TagId, &TagMeta)> {
        self.meta[..self.len()]
            .iter()
            .enumerate()
            .filter_map(|(i, m)| Some((TagId(i as u32), m.get()?)))
    }

    /// Ids of the tags whose names start with `prefix` (all for "").
    pub fn ids_with_prefix(&self, prefix: &str) -> Vec<TagId> {
        self.all_meta()
            .filter(|(_, m)| m.name.starts_with(prefix))
            .map(|(id, _)| id)
            .collect()
    }

    pub fn get(&self, id: TagId) -> Option<Sample> {
        if id.index() >= self.len() {
            return None;
        }
        self.live.read().samples.get(id.index()).cloned()
    }

    pub fn get_by_name(&self, name: &str) -> Option<Sample> {
        self.id(name).and_then(|id| self.get(id))
    }

    /// The current sequence number: how many changing batches have been applied.
    pub fn seq(&self) -> u64 {
        self.live.read().seq
    }

    /// The current samples of `ids` (unknown ids are skipped), with the sequence
    /// number they are consistent with.
    pub fn snapshot(&self, ids: &[TagId]) -> ChangeBatch {
        let live = self.live.read();
        let len = self.len();
        let changes = ids
            .iter()
            .filter(|id| id.index() < len)
            .filter_map(|id| live.samples.get(id.index()).map(|s| (*id, s.clone())))
            .collect();
        ChangeBatch {
            seq: live.seq,
            changes,
        }
    }

    /// The current samples of every tag.
    pub fn snapshot_all(&self) -> ChangeBatch {
        let live = self.live.read();
        ChangeBatch {
            seq: live.seq,
            changes: live.samples[..self.len()]
                .iter()
                .enumerate()
                .map(|(i, s)| (TagId(i as u32), s.clone()))
                .collect(),
        }
    }

    /// Applies one batch of new samples (one poll cycle). Samples for unknown
    /// ids are ignored. Returns how many tags changed; only those are published.
    /// Never blocks on subscribers.
    pub fn apply(&self, batch: impl IntoIterator<Item = (TagId, Sample)>) -> usize {
        let mut live = self.live.write();
        // Observed now: newer than anything observed before.
        let ticket = live.next_ticket;
        live.next_ticket += 1;
        self.apply_locked(
            &mut live,
            batch.into_iter().map(|(id, s)| (id, s, ticket)),
            false,
        )
    }

    /// Applies a batch of events a device reported (a buffered report's
    /// entries, with the device's own times): unlike [`TagDb::apply`], a
    /// sample whose value and quality equal the current one's but whose
    /// time differs is published too, so an event replayed after an outage
    /// (a breaker that opened, closed and opened again while the link was
    /// down) reaches the historian even when it ends where it began.
    pub fn apply_events(&self, batch: impl IntoIterator<Item = (TagId, Sample)>) -> usize {
        let mut live = self.live.write();
        let ticket = live.next_ticket;
        live.next_ticket += 1;
        self.apply_locked(
            &mut live,
            batch.into_iter().map(|(id, s)| (id, s, ticket)),
            true,
        )
    }

    /// A ticket that orders observations: take it when a value is read from
    /// the field (before the batch it goes into is applied). Later tickets
    /// are larger. See [`TagDb::apply_observed`].
    pub fn ticket(&self) -> u64 {
        let mut live = self.live.write();
        let t = live.next_ticket;
        live.next_ticket += 1;
        t
    }

    /// Applies samples each with the ticket taken when it was observed. A
    /// sample observed before the tag's current one is dropped, whoever
    /// applies it: so a scan that read a block before a confirmed write,
    /// and applies its batch after it, cannot roll the written value back.
    /// This is the one place every writer of field values goes through
    /// ([`TagDb::apply`] observes "now").
    pub fn apply_observed(&self, batch: impl IntoIterator<Item = (TagId, Sample, u64)>) -> usize {
        let mut live = self.live.write();
        self.apply_locked(&mut live, batch, false)
    }

    /// Applies samples under the lock; `events` publishes a sample that
    /// differs from the current one only in its time.
    fn apply_locked(
        &self,
        live: &mut Live,
        batch: impl IntoIterator<Item = (TagId, Sample, u64)>,
        events: bool,
    ) -> usize {
        let mut changes = Vec::new();
        // Slots beyond it are room not yet taken (set under this same lock).
        let len = self.len();
        for (id, sample, ticket) in batch {
            let i = id.index();
            if i >= len {
                continue;
            }
            let (Some(slot), Some(seen)) = (live.samples.get_mut(i), live.tickets.get_mut(i))
            else {
                continue;
            };
            if ticket < *seen {
                continue;
            }
            *seen = ticket;
            if slot.differs_from(&sample) || (events && slot.timestamp != sample.timestamp) {
                changes.push((id, sample.clone()));
            }
            *slot = sample;
        }
        let n = changes.len();
        if n > 0 {
            live.seq += 1;
            let batch = Arc::new(ChangeBatch {
                seq: live.seq,
                changes,
            });
            // Sent under the lock so the ring holds batches in sequence order.
            // An error only means nobody is subscribed.
            let _ = self.tx.send(batch);
        }
        n
    }

    /// Sets one tag, as a batch of one. Convenience for derived tags.
    pub fn set(&self, id: TagId, value: impl Into<Value>, quality: Quality, timestamp: Timestamp) {
        self.apply([(
            id,
            Sample {
                value: value.into(),
                quality,
                timestamp,
            },
        )]);
    }

    /// Marks `ids` with `quality`, keeping their last values, as one batch.
    pub fn set_quality(&self, ids: &[TagId], quality: &Quality, timestamp: Timestamp) -> usize {
        let batch: Vec<(TagId, Sample)> = {
            let live = self.live.read();
            let len = self.len();
            ids.iter()
                .filter(|id| id.index() < len)
                .filter_map(|id| {
                    live.samples.get(id.index()).map(|s| {
                        (
                            *id,
                            Sample {
                                value: s.value.clone(),
                                quality: quality.clone(),
                                timestamp,
                            },
                        )
                    })
                })
                .collect()
        };
        self.apply(batch)
    }

    /// Subscribes to changes of every tag.
    pub fn subscribe_all(self: &Arc<Self>) -> Subscription {
        self.subscribe_filtered(None)
    }

    /// Subscribes to changes of `ids` only.
    pub fn subscribe(self: &Arc<Self>, ids: &[TagId]) -> Subscription {
        let mut filter = vec![false; self.len()];
        for id in ids {
            if let Some(f) = filter.get_mut(id.index()) {
                *f = true;
            }
        }
        self.subscribe_filtered(Some(filter))
    }

    fn subscribe_filtered(self: &Arc<Self>, filter: Option<Vec<bool>>) -> Subscription {
        // Subscribe under the read lock so `seen` and the ring position agree.
        let live = self.live.read();
        let rx = self.tx.subscribe();
        Subscription {
            db: Arc::clone(self),
            rx,
            filter,
            seen: live.seq,
        }
    }
}

fn default_value(kind: ValueKind) -> Value {
    match kind {
        ValueKind::Bool => Value::Bool(false),
        ValueKind::Int => Value::Int(0),
        ValueKind::Float => Value::Float(0.0),
        ValueKind::Str => Value::Str("".into()),
    }
}

/// A subscriber's view of the change stream. Dropping it unsubscribes.
pub struct Subscription {
    db: Arc<TagDb>,
    rx: broadcast::Receiver<Arc<ChangeBatch>>,
    /// `None` watches every tag; otherwise one flag per tag id.
    filter: Option<Vec<bool>>,
    /// The last sequence number this subscriber has been brought up to.
    seen: u64,
}

impl Subscription {
    /// Waits for the next update. Returns `None` once the database is gone.
    pub async fn recv(&mut self) -> Option<Update> {
        loop {
            match self.rx.recv().await {
                Ok(batch) => {
                    if let Some(update) = self.filter_batch(batch) {
                        return Some(update);
                    }
                }
                Err(broadcast::error::RecvError::Lagged(_)) => return Some(self.resync()),
                Err(broadcast::error::RecvError::Closed) => return None,
            }
        }
    }

    /// Returns the next update if one is ready, without waiting.
    pub fn try_recv(&mut self) -> Option<Update> {
        loop {
            match self.rx.try_recv() {
                Ok(batch) => {
                    if let Some(update) = self.filter_batch(batch) {
                        return Some(update);
                    }
                }
                Err(broadcast::error::TryRecvError::Lagged(_)) => return Some(self.resync()),
                Err(_) => return None,
            }
        }
    }

    /// Changes what this subscription watches (e.g. a WebSocket client
    /// subscribing to more tags) and returns a snapshot of the new set.
    pub fn watch(&mut self, ids: Option<&[TagId]>) -> Update {
        self.filter = ids.map(|ids| {
            let mut f = vec![false; self.db.len()];
            for id in ids {
                if let Some(slot) = f.get_mut(id.index()) {
                    *slot = true;
                }
            }
            f
        });
        self.resync()
    }

    fn filter_batch(&mut self, batch: Arc<ChangeBatch>) -> Option<Update> {
        if batch.seq <= self.seen {
            return None; // already covered by a snapshot
        }
        self.seen = batch.seq;
        match &self.filter {
            None => Some(Update::Changes(batch)),
            Some(filter) => {
                let changes: Vec<_> = batch
                    .changes
                    .iter()
                    .filter(|(id, _)| filter.get(id.index()).copied().unwrap_or(false))
                    .cloned()
                    .collect();
                (!changes.is_empty()).then(|| {
                    Update::Changes(Arc::new(ChangeBatch {
                        seq: batch.seq,
                        changes,
                    }))
                })
            }
        }
    }

    fn resync(&mut self) -> Update {
        // Drop everything queued: the snapshot supersedes it.
        self.rx = self.rx.resubscribe();
        let snap = match &self.filter {
            None => self.db.snapshot_all(),
            Some(filter) => {
                let ids: Vec<TagId> = filter
                    .iter()
                    .enumerate()
                    .filter(|(_, on)| **on)
                    .map(|(i, _)| TagId(i as u32))
                    .collect();
                self.db.snapshot(&ids)
            }
        };
        self.seen = snap.seq;
        Update::Snapshot(Arc::new(snap))
    }
}
