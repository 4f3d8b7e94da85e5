//! The Sparkplug B edge node: publishes the tag database to a broker.
//!
//! NBIRTH (with `bdSeq` and `Node Control/Rebirth`), one DBIRTH per device
//! (see [`model`] for which tags a device carries), then DDATA on change
//! (deadband, batched over `batch_ms`), each metric with its own timestamp
//! and quality. NDEATH is the MQTT will of every session; DDEATH when a
//! device's communication fails, and DBIRTH again when it recovers. NCMD
//! `Node Control/Rebirth` births everything again. DCMD writes go through
//! the shared audited write ([`gridscada_store::command::audited_write`]),
//! with the node's rights: its area (the tags `[mqtt.edge] commands` names)
//! and its role (`command_role`). While the broker is
//! unreachable, samples go to the on-disk [`buffer`] and are sent as
//! historical data after the next birth.
//!
//! With `primary_host_id`, the edge follows that host's `STATE`
//! ([`primary`]): it births only once the host is online, buffers while it
//! is not, and on the host's offline STATE sends its NDEATH, disconnects and
//! buffers until the host is back (Sparkplug 3.0).
//!
//! It is one more subscriber of the tag database: it never blocks the
//! poller (a subscriber that falls behind gets a snapshot).

pub mod buffer;
pub mod model;
pub mod primary;
mod session;

use std::collections::VecDeque;
use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use gridscada_config::{MqttConfig, MqttEdgeConfig, Plant};
use gridscada_store::command::{
    audit_refused, audited_write, CommandAudit, CommandError, Commander,
};
use gridscada_store::NewEvent;
use gridscada_tagdb::{Clock, Sample, TagDb, TagId, TagWriter, Update};
use prost::Message;
use rumqttc::{AsyncClient, QoS};
use tokio::sync::{mpsc, watch, Semaphore};
use tokio::task::JoinHandle;

use crate::proto::{Metric, MetricValue, Payload};
use crate::topic::{MessageType, Topic};
use buffer::SampleBuffer;
use model::{EdgeModel, Seq};
use primary::{PrimaryHost, Verdict};

/// At most this many metrics go in one DDATA (a large device's changes
/// are split), so that no message grows past what brokers take by default.
pub const MAX_METRICS_PER_MESSAGE: usize = 5000;
/// Refusals of one DCMD audited one by one; the rest in one record.
const MAX_AUDITED_REFUSALS: usize = 20;
/// DCMD writes in flight at once; more are refused as busy.
const MAX_WRITES_IN_FLIGHT: usize = 16;
/// The folder of the edge's files in the data folder.
pub const DATA_SUBDIR: &str = "mqtt-buffer";

/// The edge's figures for `/metrics`. Counters only grow; `connected` and
/// `buffered` are gauges.
#[derive(Debug, Default)]
pub struct EdgeMetrics {
    pub messages_sent: AtomicU64,
    pub bytes_sent: AtomicU64,
    pub messages_received: AtomicU64,
    pub bytes_received: AtomicU64,
    /// Sessions after the first one.
    pub reconnects: AtomicU64,
    pub connected: AtomicU64,
    /// Samples in the store-and-forward buffer now.
    pub buffered: AtomicU64,
    /// Samples sent as historical data after an outage.
    pub replayed: AtomicU64,
    /// Samples lost: the buffer was full, or their device had no birth.
    pub dropped: AtomicU64,
    pub commands_written: AtomicU64,
    pub commands_failed: AtomicU64,
    pub commands_refused: AtomicU64,
    /// Messages that could not be read: not Sparkplug, oversized, unknown.
    pub malformed: AtomicU64,
    /// With `primary_host_id`: 1 while that host's STATE says online and
    /// the edge has a session (it births and publishes), else 0.
    pub primary_host_online: AtomicU64,
}

impl EdgeMetrics {
    fn add(counter: &AtomicU64, n: u64) {
        counter.fetch_add(n, Ordering::Relaxed);
    }
    pub fn get(counter: &AtomicU64) -> u64 {
        counter.load(Ordering::Relaxed)
    }
}

/// The running parts the edge works with.
pub struct EdgeContext {
    pub plant: Arc<Plant>,
    pub db: Arc<TagDb>,
    pub writer: Arc<dyn TagWriter>,
    pub audit: Arc<dyn CommandAudit>,
    /// The event log (outages, dropped samples).
    pub events: mpsc::Sender<NewEvent>,
    pub clock: Arc<dyn Clock>,
}

/// Why the edge cannot start.
#[derive(Debug, thiserror::Error)]
pub enum StartError {
    #[error(transparent)]
    Connection(#[from] crate::connection::ConnectionError),
    #[error("the MQTT buffer in {}: {error}", dir.display())]
    Buffer { dir: PathBuf, error: std::io::Error },
    #[error("the configuration has no [mqtt.edge]")]
    NotConfigured,
}

/// The running edge node.
pub struct EdgeNode {
    metrics: Arc<EdgeMetrics>,
    stop: watch::Sender<bool>,
    task: JoinHandle<()>,
}

impl EdgeNode {
    /// Starts publishing. `config_dir` resolves a relative `ca_file`;
    /// `data_dir` holds the buffer.
    pub fn start(
        ctx: EdgeContext,
        mqtt: &MqttConfig,
        config_dir: &std::path::Path,
        data_dir: &std::path::Path,
    ) -> Result<EdgeNode, StartError> {
        let edge = mqtt.edge.clone().ok_or(StartError::NotConfigured)?;
        let group = mqtt.group.get_ref().clone();
        let node = edge.node.get_ref().clone();
        let client_id = mqtt
            .client_id
            .as_ref()
            .map(|c| c.get_ref().clone())
            .unwrap_or_else(|| format!("gridscada-{node}"));
        let options = crate::connection::options(mqtt, &client_id, config_dir)?;
        let dir = data_dir.join(DATA_SUBDIR);
        let buffer = SampleBuffer::open(&dir, *edge.buffer_samples.get_ref()).map_err(|error| {
            StartError::Buffer {
                dir: dir.clone(),
                error,
            }
        })?;
        let metrics = Arc::new(EdgeMetrics::default());
        EdgeMetrics::add(&metrics.buffered, buffer.len() as u64);
        let (stop, stop_rx) = watch::channel(false);
        // The session task stops after the edge loop, which says goodbye
        // (NDEATH, DISCONNECT) through it first.
        let (session_stop, session_stop_rx) = watch::channel(false);
        let (session_tx, session_rx) = mpsc::channel(1024);
        let death_topic = Topic::node(&group, MessageType::NDeath, &node).to_string();
        tokio::spawn(session::run(
            options,
            death_topic,
            session::BdSeqFile(dir.join("bdseq")),
            session_tx,
            session_stop_rx,
        ));
        let model = EdgeModel::new(&ctx.plant, &ctx.db, &edge);
        let keep_alive = Duration::from_secs(*mqtt.keep_alive_s.get_ref());
        let primary = edge
            .primary_host_id
            .as_ref()
            .map(|id| PrimaryHost::new(id.get_ref()));
        let state = Edge {
            deadband: model::Deadband::new(ctx.db.len(), *edge.deadband.get_ref()),
            born: vec![false; model.devices.len()],
            model,
            ctx,
            group,
            node,
            edge,
            max_message: *mqtt.max_message_bytes.get_ref(),
            session: None,
            seq: Seq::default(),
            pending: Vec::new(),
            buffer,
            dropped_in_outage: 0,
            recent: VecDeque::new(),
            recent_span: keep_alive.mul_f64(1.5) + Duration::from_secs(1),
            writes: Arc::new(Semaphore::new(MAX_WRITES_IN_FLIGHT)),
            metrics: metrics.clone(),
            sessions: 0,
            session_stop,
            refused_in_message: 0,
            primary,
        };
        let task = tokio::spawn(state.run(session_rx, stop_rx));
        Ok(EdgeNode {
            metrics,
            stop,
            task,
        })
    }

    pub fn metrics(&self) -> Arc<EdgeMetrics> {
        self.metrics.clone()
    }

    /// Stops: buffers what was not sent, publishes NDEATH and disconnects.
    pub async fn shutdown(self) {
        self.stop.send_replace(true);
        if let Err(e) = self.task.await {
            tracing::error!(error = %e, "the MQTT edge node failed");
        }
    }
}

/// The live session: its client and `bdSeq`.
struct Session {
    client: AsyncClient,
    bd_seq: u64,
    /// Its NBIRTH went out (with a primary host, only once it is online):
    /// until then, samples go to the buffer.
    born: bool,
}

impl Session {
    /// An orderly end (the will is not sent on DISCONNECT): NDEATH, then
    /// DISCONNECT, as Sparkplug asks of an edge that leaves on purpose.
    async fn end(&self, group: &str, node: &str) {
        let topic = Topic::node(group, MessageType::NDeath, node).to_string();
        let death = model::ndeath(self.bd_seq).encode_to_vec();
        let _ = self
            .client
            .publish(topic, QoS::AtLeastOnce, false, death)
            .await;
        let _ = self.client.disconnect().await;
    }
}

struct Edge {
    ctx: EdgeContext,
    model: EdgeModel,
    group: String,
    node: String,
    edge: MqttEdgeConfig,
    max_message: usize,
    session: Option<Session>,
    seq: Seq,
    /// Per device: its DBIRTH went out in this session (and no DDEATH since).
    born: Vec<bool>,
    deadband: model::Deadband,
    /// Changes gathered for the next DDATA.
    pending: Vec<(TagId, Sample)>,
    buffer: SampleBuffer,
    dropped_in_outage: u64,
    /// What went out lately: on a lost session it goes to the buffer too,
    /// since a broker that dies takes what it had not delivered with it
    /// (a host may see some twice, as historical data; none is lost).
    recent: VecDeque<(Instant, Vec<Metric>)>,
    recent_span: Duration,
    writes: Arc<Semaphore>,
    metrics: Arc<EdgeMetrics>,
    sessions: u64,
    session_stop: watch::Sender<bool>,
    /// Refusals of the DCMD being handled.
    refused_in_message: usize,
    /// The primary host whose STATE gates births, if configured.
    primary: Option<PrimaryHost>,
}

/// What a recent window of sent data may hold at most (metrics).
const RECENT_MAX_METRICS: usize = 200_000;

impl Edge {
    async fn run(
        mut self,
        mut sessions: mpsc::Receiver<session::SessionEvent>,
        mut stop: watch::Receiver<bool>,
    ) {
        let mut changes = self.ctx.db.subscribe_all();
        let period = Duration::from_millis(*self.edge.batch_ms.get_ref());
        let mut tick = tokio::time::interval(period);
        tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        loop {
            tokio::select! {
                _ = stop.changed() => break,
                event = sessions.recv() => match event {
                    Some(session::SessionEvent::Up { client, bd_seq }) => self.session_up(client, bd_seq).await,
                    Some(session::SessionEvent::Down { reason }) => self.session_down(&reason),
                    Some(session::SessionEvent::Message { topic, payload }) => self.on_message(&topic, &payload).await,
                    None => break,
                },
                update = changes.recv() => match update {
                    Some(update) => self.take_changes(&update),
                    None => break,
                },
                _ = tick.tick() => self.flush().await,
            }
        }
        self.flush().await;
        if let Some(s) = self.session.take() {
            s.end(&self.group, &self.node).await;
            // Let the session task send them before it stops.
            tokio::time::sleep(Duration::from_millis(200)).await;
        }
        self.session_stop.send_replace(true);
        if let Err(e) = self.buffer.flush() {
            tracing::error!(error = %e, "could not write the MQTT buffer");
        }
    }

    fn now_ms(&self) -> u64 {
        self.ctx.clock.now().as_millis().max(0) as u64
    }

    fn take_changes(&mut self, update: &Update) {
        for (id, sample) in &update.batch().changes {
            if self.deadband.offer(*id, sample) {
                self.pending.push((*id, sample.clone()));
            }
        }
    }

    async fn session_up(&mut self, client: AsyncClient, bd_seq: u64) {
        self.sessions += 1;
        if self.sessions > 1 {
            EdgeMetrics::add(&self.metrics.reconnects, 1);
        }
        self.metrics.connected.store(1, Ordering::Relaxed);
        tracing::info!(group = %self.group, node = %self.node, bd_seq, "MQTT session up");
        // Commands first, so that none sent right after the birth is missed.
        let ncmd = Topic::node(&self.group, MessageType::NCmd, &self.node).to_string();
        let dcmd = format!(
            "{}/+",
            Topic::node(&self.group, MessageType::DCmd, &self.node)
        );
        // With a primary host, its STATE too (retained: it comes at once).
        let state = self.primary.as_mut().map(|p| {
            p.new_session();
            p.topic().to_owned()
        });
        for t in [ncmd, dcmd].into_iter().chain(state) {
            if let Err(e) = client.subscribe(t, QoS::AtLeastOnce).await {
                tracing::warn!(error = %e, "could not subscribe to commands and STATE");
            }
        }
        self.session = Some(Session {
            client,
            bd_seq,
            born: false,
        });
        // Changes gathered while away go to the buffer before the births.
        self.spill_pending();
        match &self.primary {
            Some(p) => {
                tracing::info!(primary_host = %p.host_id, "waiting for the primary host's STATE online before the births")
            }
            None => self.go_live().await,
        }
    }

    /// Births, then the buffer as historical data.
    async fn go_live(&mut self) {
        self.birth_all().await;
        self.replay().await;
    }

    fn session_down(&mut self, reason: &str) {
        if self.lose_session().is_none() {
            return;
        }
        let n = self.keep_recent();
        self.event(format!(
            "MQTT broker connection lost ({reason}); buffering samples ({n} recent ones kept again as historical)"
        ));
    }

    /// Forgets the session (gone, or being ended): every device unborn.
    fn lose_session(&mut self) -> Option<Session> {
        let s = self.session.take()?;
        self.metrics.connected.store(0, Ordering::Relaxed);
        self.metrics.primary_host_online.store(0, Ordering::Relaxed);
        self.born.iter_mut().for_each(|b| *b = false);
        Some(s)
    }

    /// What went out lately may not have reached anyone: into the buffer
    /// again, to be sent as historical data. Returns how many.
    fn keep_recent(&mut self) -> usize {
        let recent: Vec<Metric> = self.recent.drain(..).flat_map(|(_, m)| m).collect();
        let n = recent.len();
        for m in recent {
            self.buffer_metric(m);
        }
        self.flush_buffer();
        n
    }

    /// Whether samples are published now (else they go to the buffer).
    fn publishing(&self) -> bool {
        self.session.as_ref().is_some_and(|s| s.born)
    }

    /// A STATE of the primary host.
    async fn on_state(&mut self, topic: &str, body: &[u8]) {
        let Some(primary) = self.primary.as_mut().filter(|p| p.topic() == topic) else {
            return self.malformed(topic, "not the STATE of this node's primary host");
        };
        let host = primary.host_id.clone();
        match primary.observe(body) {
            Verdict::Malformed(why) => self.malformed(topic, &why),
            Verdict::Stale { timestamp, last } => {
                tracing::info!(primary_host = %host, timestamp, last, "a STATE older than the last one ignored");
            }
            Verdict::Online => {
                if self.session.as_ref().is_some_and(|s| !s.born) {
                    tracing::info!(primary_host = %host, "primary host online: births");
                    self.metrics.primary_host_online.store(1, Ordering::Relaxed);
                    // What changed since the last tick is history too.
                    self.spill_pending();
                    self.go_live().await;
                }
            }
            Verdict::Offline => {
                if self.publishing() {
                    self.primary_host_lost(&host).await;
                }
            }
        }
    }

    /// The primary host went offline while the edge published: what was
    /// not sent and what went out lately go to the buffer; NDEATH and
    /// DISCONNECT (Sparkplug 3.0); the session task connects again and the
    /// edge waits there for the host's STATE online.
    async fn primary_host_lost(&mut self, host: &str) {
        self.spill_pending();
        let Some(s) = self.lose_session() else {
            return;
        };
        let n = self.keep_recent();
        s.end(&self.group, &self.node).await;
        tracing::warn!(primary_host = %host, "primary host offline: NDEATH sent, buffering samples");
        self.event(format!(
            "MQTT primary host '{host}' offline: NDEATH sent, buffering samples until it is online ({n} recent ones kept again as historical)"
        ));
    }

    fn event(&self, message: String) {
        let event = NewEvent {
            ts: self.ctx.clock.now(),
            user: None,
            source: "mqtt".into(),
            kind: "mqtt".into(),
            message,
        };
        if self.ctx.events.try_send(event).is_err() {
            tracing::warn!("event log queue full: an MQTT event was not recorded");
        }
    }

    /// NBIRTH, then DBIRTH for every device that communicates.
    async fn birth_all(&mut self) {
        let Some(bd_seq) = self.session.as_mut().map(|s| {
            s.born = true;
            s.bd_seq
        }) else {
            return;
        };
        self.born.iter_mut().for_each(|b| *b = false);
        let now = self.now_ms();
        self.seq.reset();
        let topic = Topic::node(&self.group, MessageType::NBirth, &self.node).to_string();
        self.publish(topic, model::nbirth(bd_seq, now)).await;
        for d in 0..self.model.devices.len() {
            if self.model.device_up(d, &self.ctx.db) {
                self.dbirth(d).await;
            }
        }
    }

    async fn dbirth(&mut self, d: usize) {
        let now = self.now_ms();
        let seq = self.seq.advance();
        let birth = model::dbirth(&self.model, d, &self.ctx.db, seq, now);
        // The deadband starts from what the birth carries (the same read);
        // changes of this device gathered before it are in it.
        for (id, sample) in &birth.carried {
            self.deadband.reset_to(*id, sample);
        }
        let payload = birth.payload;
        let model = &self.model;
        self.pending
            .retain(|(id, _)| model.device_of(*id) != Some(d));
        let topic = self.device_topic(MessageType::DBirth, d);
        if self.publish(topic, payload).await {
            self.born[d] = true;
        }
    }

    fn device_topic(&self, kind: MessageType, d: usize) -> String {
        Topic::device(&self.group, kind, &self.node, &self.model.devices[d].name).to_string()
    }

    /// Publishes; false if the session is gone (the caller keeps the data).
    async fn publish(&mut self, topic: String, payload: Payload) -> bool {
        let Some(s) = &self.session else {
            return false;
        };
        let bytes = payload.encode_to_vec();
        let len = bytes.len() as u64;
        match s.client.publish(topic, QoS::AtMostOnce, false, bytes).await {
            Ok(()) => {
                EdgeMetrics::add(&self.metrics.messages_sent, 1);
                EdgeMetrics::add(&self.metrics.bytes_sent, len);
                true
            }
            Err(e) => {
                tracing::warn!(error = %e, "MQTT publish failed: session lost");
                self.session_down("publish failed");
                false
            }
        }
    }

    /// Sends the gathered changes: per device one DDATA (split when large);
    /// deaths and births of devices whose communication changed.
    async fn flush(&mut self) {
        if !self.publishing() {
            self.spill_pending();
            return;
        }
        // Devices that stopped or started communicating.
        for d in 0..self.model.devices.len() {
            let up = self.model.device_up(d, &self.ctx.db);
            if self.born[d] && !up {
                let model = &self.model;
                self.pending
                    .retain(|(id, _)| model.device_of(*id) != Some(d));
                let now = self.now_ms();
                let seq = self.seq.advance();
                let topic = self.device_topic(MessageType::DDeath, d);
                self.born[d] = false;
                self.publish(topic, model::ddeath(seq, now)).await;
            } else if !self.born[d] && up {
                self.dbirth(d).await;
            }
        }
        if self.pending.is_empty() {
            return;
        }
        let pending = std::mem::take(&mut self.pending);
        let mut by_device: Vec<Vec<Metric>> = vec![Vec::new(); self.model.devices.len()];
        for (id, sample) in &pending {
            let Some(d) = self.model.device_of(*id) else {
                continue;
            };
            // A dead device's tags are Bad; its next birth carries them.
            if !self.born[d] {
                continue;
            }
            by_device[d].push(model::data_metric(
                *id,
                None,
                sample,
                self.model.datatype(*id),
            ));
        }
        let now = Instant::now();
        for (d, metrics) in by_device.into_iter().enumerate() {
            for chunk in metrics.chunks(MAX_METRICS_PER_MESSAGE) {
                let payload = Payload {
                    timestamp: Some(self.now_ms()),
                    seq: Some(self.seq.advance()),
                    metrics: chunk.to_vec(),
                    ..Default::default()
                };
                let topic = self.device_topic(MessageType::DData, d);
                if self.publish(topic, payload).await {
                    self.remember(now, d, chunk);
                } else {
                    // The session ended under us: this and the rest go to
                    // the buffer (session_down has kept what went before).
                    for m in chunk {
                        self.buffer_metric(self.named(m.clone()));
                    }
                }
            }
        }
        self.flush_buffer();
    }

    /// Keeps what went out, with names, for the recent window.
    fn remember(&mut self, at: Instant, _device: usize, chunk: &[Metric]) {
        let named: Vec<Metric> = chunk.iter().map(|m| self.named(m.clone())).collect();
        self.recent.push_back((at, named));
        let mut total: usize = self.recent.iter().map(|(_, m)| m.len()).sum();
        while let Some((t, m)) = self.recent.front() {
            if at.duration_since(*t) > self.recent_span || total > RECENT_MAX_METRICS {
                total -= m.len();
                self.recent.pop_front();
            } else {
                break;
            }
        }
    }

    /// A metric with its tag's name (buffered samples must survive a
    /// restart, after which aliases may differ).
    fn named(&self, mut m: Metric) -> Metric {
        if m.name.is_none() {
            m.name = m
                .alias
                .and_then(|a| model::tag_of_alias(a, &self.ctx.db))
                .and_then(|id| self.ctx.db.meta(id))
                .map(|meta| meta.name.to_string());
        }
        m
    }

    /// The gathered changes, into the buffer (no session).
    fn spill_pending(&mut self) {
        let pending = std::mem::take(&mut self.pending);
        for (id, sample) in &pending {
            let name = self.ctx.db.meta(*id).map(|m| m.name.to_string());
            let m = model::data_metric(*id, name.as_deref(), sample, self.model.datatype(*id));
            self.buffer_metric(m);
        }
        self.flush_buffer();
    }

    fn buffer_metric(&mut self, m: Metric) {
        match self.buffer.push(&m) {
            Ok(true) => EdgeMetrics::add(&self.metrics.buffered, 1),
            Ok(false) => {
                self.dropped_in_outage += 1;
                EdgeMetrics::add(&self.metrics.dropped, 1);
            }
            Err(e) => {
                self.dropped_in_outage += 1;
                EdgeMetrics::add(&self.metrics.dropped, 1);
                tracing::error!(error = %e, "could not write the MQTT buffer: sample dropped");
            }
        }
    }

    fn flush_buffer(&mut self) {
        if let Err(e) = self.buffer.flush() {
            tracing::error!(error = %e, "could not write the MQTT buffer");
        }
    }

    /// Sends the buffer as historical data, oldest first.
    async fn replay(&mut self) {
        if self.dropped_in_outage > 0 {
            let n = std::mem::take(&mut self.dropped_in_outage);
            self.event(format!(
                "MQTT: {n} samples dropped while the broker was unreachable (the buffer holds at most {})",
                self.edge.buffer_samples.get_ref()
            ));
        }
        if self.buffer.is_empty() {
            return;
        }
        let replay = match self.buffer.take() {
            Ok(r) => r,
            Err(e) => {
                tracing::error!(error = %e, "could not read the MQTT buffer");
                return;
            }
        };
        self.metrics.buffered.store(0, Ordering::Relaxed);
        let total = replay.metrics.len();
        // Per device, in order; a sample whose tag is gone (another
        // configuration) or whose device has no birth now is dropped.
        let mut by_device: Vec<Vec<Metric>> = vec![Vec::new(); self.model.devices.len()];
        let mut lost = 0u64;
        for mut m in replay.metrics {
            let id = m.name.as_deref().and_then(|n| self.ctx.db.id(n));
            let d = id.and_then(|id| self.model.device_of(id));
            match (id, d) {
                (Some(id), Some(d)) if self.born[d] => {
                    m.name = None;
                    m.alias = Some(model::alias(id));
                    m.is_historical = Some(true);
                    by_device[d].push(m);
                }
                _ => lost += 1,
            }
        }
        let mut unsent: Vec<Metric> = Vec::new();
        let mut sent = 0u64;
        for (d, metrics) in by_device.into_iter().enumerate() {
            for chunk in metrics.chunks(MAX_METRICS_PER_MESSAGE) {
                if !unsent.is_empty() || self.session.is_none() {
                    unsent.extend(chunk.iter().cloned().map(|m| self.named(m)));
                    continue;
                }
                let payload = Payload {
                    timestamp: Some(self.now_ms()),
                    seq: Some(self.seq.advance()),
                    metrics: chunk.to_vec(),
                    ..Default::default()
                };
                let topic = self.device_topic(MessageType::DData, d);
                if self.publish(topic, payload).await {
                    sent += chunk.len() as u64;
                } else {
                    unsent.extend(chunk.iter().cloned().map(|m| self.named(m)));
                }
            }
        }
        EdgeMetrics::add(&self.metrics.replayed, sent);
        EdgeMetrics::add(&self.metrics.dropped, lost);
        if !unsent.is_empty() {
            if let Err(e) = self.buffer.put_back(&unsent) {
                tracing::error!(error = %e, "could not keep unsent samples in the MQTT buffer");
            }
            self.metrics
                .buffered
                .store(self.buffer.len() as u64, Ordering::Relaxed);
        }
        tracing::info!(
            total,
            sent,
            lost,
            unsent = unsent.len(),
            "MQTT buffer replayed as historical data"
        );
        self.event(format!(
            "MQTT: {sent} buffered samples sent as historical data{}",
            if lost > 0 {
                format!("; {lost} dropped (their tag or device is not published now)")
            } else {
                String::new()
            }
        ));
    }

    /// A message on a command topic.
    async fn on_message(&mut self, topic: &str, payload: &[u8]) {
        EdgeMetrics::add(&self.metrics.messages_received, 1);
        EdgeMetrics::add(&self.metrics.bytes_received, payload.len() as u64);
        if payload.len() > self.max_message {
            self.malformed(
                topic,
                &format!(
                    "{} bytes, more than max_message_bytes {}",
                    payload.len(),
                    self.max_message
                ),
            );
            return;
        }
        let kind = match Topic::parse(topic) {
            Some(Topic::Message { kind, device, .. }) => (kind, device),
            Some(Topic::State { .. }) => return self.on_state(topic, payload).await,
            _ => {
                self.malformed(topic, "not a Sparkplug B command topic");
                return;
            }
        };
        let decoded = match Payload::decode(payload) {
            Ok(p) => p,
            Err(e) => {
                self.malformed(topic, &format!("not a Sparkplug B payload ({e})"));
                return;
            }
        };
        match kind {
            (MessageType::NCmd, None) => self.on_ncmd(topic, decoded).await,
            (MessageType::DCmd, Some(device)) => self.on_dcmd(&device, decoded).await,
            _ => self.malformed(topic, "not a command for this node"),
        }
    }

    fn malformed(&self, topic: &str, why: &str) {
        EdgeMetrics::add(&self.metrics.malformed, 1);
        tracing::warn!(%topic, %why, "MQTT message refused");
    }

    async fn on_ncmd(&mut self, topic: &str, payload: Payload) {
        let mut rebirth = false;
        for m in &payload.metrics {
            if m.name.as_deref() == Some(model::REBIRTH) {
                rebirth |= matches!(m.value, Some(MetricValue::Boolean(true)));
            } else {
                self.malformed(topic, &format!("unknown node command {:?}", m.name));
            }
        }
        if rebirth && !self.publishing() {
            // Not born yet (waiting for the primary host): the births come
            // when it is online.
            tracing::info!("rebirth requested before the births: ignored");
        } else if rebirth {
            tracing::info!("rebirth requested");
            self.flush().await;
            self.birth_all().await;
        }
    }

    async fn on_dcmd(&mut self, device: &str, payload: Payload) {
        self.refused_in_message = 0;
        let who = Commander {
            user: None,
            label: format!(
                "Sparkplug DCMD (as {})",
                self.edge.command_role.get_ref().label()
            ),
        };
        let Some(d) = self.model.device_named(device) else {
            for m in &payload.metrics {
                let name = m
                    .name
                    .clone()
                    .unwrap_or_else(|| format!("alias {:?}", m.alias));
                self.refuse(&who, &name, &format!("no device '{device}' on this node"));
            }
            if payload.metrics.is_empty() {
                self.malformed(device, "a DCMD to an unknown device");
            }
            self.summarize_refusals(&who, device);
            return;
        };
        for m in payload.metrics {
            let (id, value) = match model::resolve_command(&self.model, &self.ctx.db, d, &m) {
                Ok(ok) => ok,
                Err(refusal) => {
                    self.refuse(&who, &refusal.tag, &refusal.why);
                    continue;
                }
            };
            let name = self
                .ctx
                .db
                .meta(id)
                .map(|m| m.name.to_string())
                .unwrap_or_default();
            let Ok(permit) = self.writes.clone().try_acquire_owned() else {
                self.refuse(&who, &name, "too many commands in progress");
                continue;
            };
            let old = self
                .ctx
                .db
                .get(id)
                .map(|s| s.value.to_string())
                .unwrap_or_default();
            let (audit, writer, clock, metrics, who) = (
                self.ctx.audit.clone(),
                self.ctx.writer.clone(),
                self.ctx.clock.clone(),
                self.metrics.clone(),
                who.clone(),
            );
            tokio::spawn(async move {
                let _permit = permit;
                let r = audited_write(&*audit, &*writer, || clock.now(), &who, &name, &old, value)
                    .await;
                match r {
                    Ok(_) => EdgeMetrics::add(&metrics.commands_written, 1),
                    // Refused before the device (its engineering limits, a
                    // standby server): counted and recorded as refused.
                    Err(CommandError::Write(e)) if e.is_refusal() => {
                        EdgeMetrics::add(&metrics.commands_refused, 1);
                        tracing::warn!(tag = %name, error = %e, "Sparkplug DCMD refused");
                    }
                    Err(e) => {
                        EdgeMetrics::add(&metrics.commands_failed, 1);
                        tracing::warn!(tag = %name, error = %e, "Sparkplug DCMD write failed");
                    }
                }
            });
        }
        self.summarize_refusals(&who, device);
    }

    /// One audit record for the refusals of a message beyond the ones
    /// audited one by one.
    fn summarize_refusals(&self, who: &Commander, device: &str) {
        let more = self.refused_in_message.saturating_sub(MAX_AUDITED_REFUSALS);
        if more == 0 {
            return;
        }
        tracing::warn!(%device, refused = more, "Sparkplug DCMD: more metrics refused");
        let (audit, who, device, ts) = (
            self.ctx.audit.clone(),
            who.clone(),
            device.to_string(),
            self.ctx.clock.now(),
        );
        let why =
            format!("{more} more metrics of one DCMD to device '{device}' refused (see the log)");
        tokio::spawn(async move { audit_refused(&*audit, ts, &who, &device, &why).await });
    }

    /// Refuses one command: logged, counted and audited (in the background,
    /// so that a slow store does not hold up publishing). Of one message,
    /// the first [`MAX_AUDITED_REFUSALS`] are audited one by one and the
    /// rest in one record, so that a flood of bad metrics cannot flood the
    /// event log.
    fn refuse(&mut self, who: &Commander, name: &str, why: &str) {
        EdgeMetrics::add(&self.metrics.commands_refused, 1);
        self.refused_in_message += 1;
        if self.refused_in_message > MAX_AUDITED_REFUSALS {
            tracing::debug!(tag = %name, %why, "Sparkplug DCMD refused");
            return;
        }
        tracing::warn!(tag = %name, %why, "Sparkplug DCMD refused");
        let (audit, who, name, why, ts) = (
            self.ctx.audit.clone(),
            who.clone(),
            name.to_string(),
            why.to_string(),
            self.ctx.clock.now(),
        );
        tokio::spawn(async move { audit_refused(&*audit, ts, &who, &name, &why).await });
    }
}
