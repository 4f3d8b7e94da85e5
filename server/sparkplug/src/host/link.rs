//! The host's MQTT session: connect, subscribe, publish `STATE`, and feed
//! every message of the group through [`Sites`] into the tag database.
//!
//! The connection (broker, client id, credentials, keep-alive, TLS) is the
//! crate's shared one (`connection.rs`, from `[mqtt]`); the host adds its
//! `STATE` will.

use std::collections::HashMap;
use std::sync::Arc;
use std::time::{Duration, Instant};

use gridscada_tagdb::{Clock, TagDb, TagWriter};
use parking_lot::Mutex;
use prost::Message;
use rumqttc::{AsyncClient, Event, EventLoop, LastWill, MqttOptions, Packet, QoS};
use tokio::sync::{mpsc, watch};
use tokio::task::JoinHandle;

use super::sites::{RemoteAlarms, Sites, SitesPolicy, HOST_OFFLINE};
use super::stats::{Counters, HostStats};
use super::writer::{Pending, RoutedWriter};
use crate::proto::Payload;
use crate::topic::{MessageType, Topic, NAMESPACE};

/// How to run the central host (from `[mqtt]` and `[mqtt.host]`).
#[derive(Debug, Clone)]
pub struct HostOptions {
    /// `[mqtt]`: the broker connection, shared with the edge node.
    pub mqtt: gridscada_config::MqttConfig,
    /// Where a relative `[mqtt] ca_file` is taken from (the main file's folder).
    pub config_dir: std::path::PathBuf,
    pub host_id: String,
    pub sites: SitesPolicy,
    /// A larger message is counted and dropped, not decoded.
    pub max_message_bytes: usize,
    /// How long a write waits for the edge to report the value.
    pub write_timeout: Duration,
}

impl HostOptions {
    /// The options of the first session, with its STATE will.
    fn mqtt_options(&self, session: i64) -> Result<MqttOptions, String> {
        let client_id = self
            .mqtt
            .client_id
            .as_ref()
            .map(|c| c.get_ref().clone())
            .unwrap_or_else(|| format!("gridscada-host-{}", self.host_id));
        let mut o = crate::connection::options(&self.mqtt, &client_id, &self.config_dir)
            .map_err(|e| e.to_string())?;
        // The protocol's own limit: refusing larger messages is ours to do
        // (counted, the session kept), not the client's (which would drop
        // the connection).
        o.set_max_packet_size(
            crate::connection::MQTT_MAX_PACKET,
            crate::connection::MQTT_MAX_PACKET,
        )
        .set_last_will(self.state_will(session));
        Ok(o)
    }

    /// The death certificate of the host session stamped `session`: STATE
    /// offline with that session's timestamp, retained, QoS 1.
    fn state_will(&self, session: i64) -> LastWill {
        LastWill::new(
            self.state_topic(),
            state_body(false, session),
            QoS::AtLeastOnce,
            true,
        )
    }

    fn state_topic(&self) -> String {
        Topic::State {
            host_id: self.host_id.clone(),
        }
        .to_string()
    }
}

/// A site going online or offline, or the host losing the broker: for the
/// event log.
#[derive(Debug, Clone)]
pub struct SiteNotice {
    /// The edge node, or "broker".
    pub source: String,
    /// Whether `source` is now online (born, connected).
    pub online: bool,
    pub message: String,
}

/// Where the host hands on what is not a live value. Each is optional.
#[derive(Default)]
pub struct HostOutputs {
    /// Sites going online and offline, the broker lost.
    pub notices: Option<mpsc::Sender<SiteNotice>>,
    /// The alarm configurations gridscada edges declare in their births
    /// (those of one birth message together).
    pub alarms: Option<mpsc::Sender<Vec<RemoteAlarms>>>,
    /// The historian, for historical samples (an edge's store and forward).
    pub history: Option<gridscada_store::HistorianHandle>,
}

/// State shared by the session task and the writer.
pub(crate) struct Shared {
    pub db: Arc<TagDb>,
    pub clock: Arc<dyn Clock>,
    pub sites: Mutex<Sites>,
    pub pending: Mutex<Pending>,
    pub counters: Counters,
    pub client: AsyncClient,
    pub write_timeout: Duration,
    /// Never waited for: a full channel drops the notice (logged anyway).
    pub notices: Option<mpsc::Sender<SiteNotice>>,
    /// Never waited for: a full channel drops the definitions (logged);
    /// the node's next birth declares them again.
    pub alarms: Option<mpsc::Sender<Vec<RemoteAlarms>>>,
    pub history: Option<gridscada_store::HistorianHandle>,
}

impl Shared {
    fn notice(&self, source: &str, online: bool, message: String) {
        if let Some(tx) = &self.notices {
            let _ = tx.try_send(SiteNotice {
                source: source.to_owned(),
                online,
                message,
            });
        }
    }
}

/// The running central host.
pub struct Host {
    shared: Arc<Shared>,
    stop: watch::Sender<bool>,
    task: JoinHandle<()>,
}

/// The timestamp of a new host session: now, and always after the last
/// one, so that edge nodes take the new birth and ignore a late will of the
/// session before (Sparkplug 3.0 compares STATE timestamps).
fn session_timestamp(last: Option<i64>) -> i64 {
    let now = gridscada_tagdb::Timestamp::now_utc().as_millis();
    last.map_or(now, |last| now.max(last + 1))
}

/// The Sparkplug 3.0 STATE body.
fn state_body(online: bool, timestamp: i64) -> Vec<u8> {
    serde_json::json!({ "online": online, "timestamp": timestamp })
        .to_string()
        .into_bytes()
}

impl Host {
    /// Starts the session task. Remote tags go into `db`'s reserved room;
    /// sites going online and offline are told on `notices`.
    pub fn start(
        opts: HostOptions,
        db: Arc<TagDb>,
        clock: Arc<dyn Clock>,
        outputs: HostOutputs,
    ) -> Result<Host, String> {
        // One timestamp per MQTT session, in its will and its online STATE,
        // as Sparkplug 3.0 asks: a session's birth and death certificates
        // match. `run` stamps every later session anew.
        let born = session_timestamp(None);
        let mqtt = opts.mqtt_options(born)?;
        let (client, events) = AsyncClient::new(mqtt, 256);
        let shared = Arc::new(Shared {
            db,
            clock,
            sites: Mutex::new(Sites::new(opts.sites.clone())),
            pending: Mutex::new(Pending::default()),
            counters: Counters::default(),
            client,
            write_timeout: opts.write_timeout,
            notices: outputs.notices,
            alarms: outputs.alarms,
            history: outputs.history,
        });
        let (stop, stop_rx) = watch::channel(false);
        let task = tokio::spawn(run(opts, shared.clone(), events, born, stop_rx));
        Ok(Host { shared, stop, task })
    }

    /// The writer for the whole server: remote tags as commands to their
    /// edge, the rest to `local` (the field writer).
    pub fn writer(&self, local: Option<Arc<dyn TagWriter>>) -> Arc<dyn TagWriter> {
        Arc::new(RoutedWriter {
            shared: self.shared.clone(),
            local,
        })
    }

    pub fn stats(&self) -> HostStats {
        self.shared.counters.snapshot()
    }

    /// A handle that reads the figures (for `/metrics`) after `self` moves.
    pub fn stats_source(&self) -> impl Fn() -> HostStats + Send + Sync + 'static {
        let shared = self.shared.clone();
        move || shared.counters.snapshot()
    }

    /// Publishes STATE offline and disconnects.
    pub async fn shutdown(self) {
        self.stop.send_replace(true);
        if tokio::time::timeout(Duration::from_secs(3), self.task)
            .await
            .is_err()
        {
            tracing::warn!("the Sparkplug host did not stop within 3 s");
        }
    }
}

async fn run(
    opts: HostOptions,
    shared: Arc<Shared>,
    mut events: EventLoop,
    mut born: i64,
    mut stop: watch::Receiver<bool>,
) {
    let state_topic = opts.state_topic();
    let group_topic = format!("{NAMESPACE}/{}/#", opts.sites.group);
    let mut connected = false;
    let mut ever_connected = false;
    let mut gate = LogGate::default();
    loop {
        let event = tokio::select! {
            biased;
            _ = stop.changed() => break,
            e = events.poll() => e,
        };
        match event {
            Ok(Event::Incoming(Packet::ConnAck(_))) => {
                if ever_connected {
                    shared.counters.reconnect();
                    shared.notice(
                        "broker",
                        true,
                        format!(
                            "central host connected to the broker {} again",
                            opts.mqtt.broker.get_ref()
                        ),
                    );
                }
                tracing::info!(broker = %opts.mqtt.broker.get_ref(), group = %opts.sites.group, "Sparkplug host connected");
                connected = true;
                ever_connected = true;
                shared.counters.set_connected(true);
                let c = &shared.client;
                // Its own STATE first (to answer a stale offline), then the
                // group, then online: edge nodes rebirth on it.
                let ok = c.try_subscribe(&state_topic, QoS::AtLeastOnce).is_ok()
                    && c.try_subscribe(&group_topic, QoS::AtLeastOnce).is_ok()
                    && c.try_publish(&state_topic, QoS::AtLeastOnce, true, state_body(true, born))
                        .is_ok();
                if !ok {
                    tracing::error!("the Sparkplug host could not queue its subscriptions");
                }
                // After a lost session every node must be born again.
                let now = shared.clock.now();
                let nodes = shared.sites.lock().known_nodes();
                for node in nodes {
                    request_rebirth(&shared, &node, now);
                }
            }
            Ok(Event::Incoming(Packet::Publish(p))) => {
                on_publish(
                    &mut gate,
                    &opts,
                    &shared,
                    &state_topic,
                    born,
                    &p.topic,
                    &p.payload,
                );
            }
            Ok(_) => {}
            Err(e) => {
                if connected {
                    connected = false;
                    shared.counters.set_connected(false);
                    tracing::warn!(broker = %opts.mqtt.broker.get_ref(), error = %e, "Sparkplug host lost the broker; remote tags are Bad until their sites are born again");
                    let now = shared.clock.now();
                    let bad = shared.sites.lock().host_offline(&shared.db, now);
                    shared.db.apply(bad);
                    let failed = shared.pending.lock().fail_all(HOST_OFFLINE);
                    for _ in 0..failed {
                        shared.counters.write(false);
                    }
                    shared
                        .counters
                        .set_sites(0, shared.counters.snapshot().tags as usize);
                } else {
                    tracing::debug!(broker = %opts.mqtt.broker.get_ref(), error = %e, "Sparkplug host cannot reach the broker");
                }
                // The next connection is a new session: its own timestamp,
                // in the will it connects with and the STATE it publishes.
                born = session_timestamp(Some(born));
                events.mqtt_options.set_last_will(opts.state_will(born));
                // rumqttc reconnects on the next poll; do not spin.
                tokio::select! {
                    _ = stop.changed() => break,
                    _ = tokio::time::sleep(Duration::from_secs(1)) => {}
                }
            }
        }
    }
    // An orderly stop: say so, rather than leave it to the will.
    if connected {
        let c = &shared.client;
        let _ = c.try_publish(
            &state_topic,
            QoS::AtLeastOnce,
            true,
            state_body(false, born),
        );
        let _ = c.try_disconnect();
        let _ = tokio::time::timeout(Duration::from_secs(2), async {
            loop {
                match events.poll().await {
                    Ok(Event::Outgoing(rumqttc::Outgoing::Disconnect)) | Err(_) => break,
                    Ok(_) => {}
                }
            }
        })
        .await;
    }
    shared.counters.set_connected(false);
}

fn request_rebirth(shared: &Shared, node: &str, now: gridscada_tagdb::Timestamp) {
    let (topic, payload) = shared.sites.lock().rebirth_command(node, now);
    match shared.client.try_publish(
        topic.to_string(),
        QoS::AtLeastOnce,
        false,
        payload.encode_to_vec(),
    ) {
        Ok(()) => {
            shared.counters.rebirth();
            tracing::info!(node, "asked the edge node for a rebirth");
        }
        Err(e) => tracing::warn!(node, error = %e, "rebirth request not sent"),
    }
}

/// At most one warning per kind of problem every 10 s: a peer that floods
/// bad messages is counted in full and logged in sample.
#[derive(Default)]
struct LogGate(HashMap<&'static str, (Instant, u64)>);

impl LogGate {
    /// How many warnings of `kind` were held back since the last one, if
    /// one may be logged now.
    fn pass(&mut self, kind: &'static str) -> Option<u64> {
        let now = Instant::now();
        match self.0.get_mut(kind) {
            Some((last, held)) if now.duration_since(*last) < Duration::from_secs(10) => {
                *held += 1;
                None
            }
            Some((last, held)) => {
                *last = now;
                Some(std::mem::take(held))
            }
            None => {
                self.0.insert(kind, (now, 0));
                Some(0)
            }
        }
    }
}

fn on_publish(
    gate: &mut LogGate,
    opts: &HostOptions,
    shared: &Shared,
    state_topic: &str,
    born: i64,
    topic_text: &str,
    body: &[u8],
) {
    let counters = &shared.counters;
    if body.len() > opts.max_message_bytes {
        counters.bytes(body.len());
        counters.problem("oversized");
        if let Some(held_back) = gate.pass("oversized") {
            tracing::warn!(
                topic = topic_text,
                bytes = body.len(),
                max = opts.max_message_bytes,
                held_back,
                "Sparkplug message larger than max_message_bytes, dropped"
            );
        }
        return;
    }
    let Some(topic) = Topic::parse(topic_text) else {
        counters.bytes(body.len());
        counters.problem("bad_topic");
        if let Some(held_back) = gate.pass("bad_topic") {
            tracing::warn!(
                topic = topic_text,
                held_back,
                "not a Sparkplug B topic, dropped"
            );
        }
        return;
    };
    let kind = match &topic {
        Topic::State { .. } => "STATE",
        Topic::Message { kind, .. } => kind.as_str(),
    };
    counters.message(kind, body.len());
    if let Topic::State { .. } = topic {
        // Another session (or the broker's will) says this host is offline
        // while it runs: say online again.
        if topic_text == state_topic {
            let online = serde_json::from_slice::<serde_json::Value>(body)
                .ok()
                .and_then(|v| v.get("online")?.as_bool());
            if online == Some(false) {
                let _ = shared.client.try_publish(
                    state_topic,
                    QoS::AtLeastOnce,
                    true,
                    state_body(true, born),
                );
            }
        }
        return;
    }
    let payload = match Payload::decode(body) {
        Ok(p) => p,
        Err(e) => {
            counters.problem("malformed");
            if let Some(held_back) = gate.pass("malformed") {
                tracing::warn!(topic = topic_text, error = %e, held_back, "malformed Sparkplug payload, dropped");
            }
            return;
        }
    };
    let now = shared.clock.now();
    let (fx, online, tags) = {
        let mut sites = shared.sites.lock();
        let fx = sites.handle(&shared.db, &topic, &payload, now);
        (fx, sites.online(), sites.remote_tags())
    };
    for p in &fx.problems {
        counters.problem(p.label());
        if let Some(held_back) = gate.pass(p.label()) {
            tracing::warn!(topic = topic_text, held_back, "{p}");
        }
    }
    if let (
        true,
        Topic::Message {
            kind, edge_node, ..
        },
    ) = (fx.online_changed, &topic)
    {
        let online = *kind == MessageType::NBirth;
        let message = if online {
            format!("{edge_node} born (NBIRTH): online, its tags Good")
        } else {
            format!("{edge_node} died (NDEATH): offline, its tags Bad")
        };
        tracing::info!("{message}");
        shared.notice(edge_node, online, message);
    }
    if fx.added > 0 {
        tracing::info!(
            topic = topic_text,
            added = fx.added,
            "remote tags added from a birth"
        );
    }
    if !fx.samples.is_empty() {
        shared.db.apply(fx.samples.iter().cloned());
        // After the apply: a confirmed write's answer shows the new value.
        let sites = shared.sites.lock();
        shared.pending.lock().offer(&fx.samples, |id| {
            sites.remote(id).map(|r| r.node.clone()).unwrap_or_default()
        });
    }
    if let (Some(tx), false) = (&shared.alarms, fx.alarms.is_empty()) {
        if tx.try_send(fx.alarms).is_err() {
            tracing::warn!(
                topic = topic_text,
                "alarm definitions of a birth not taken (queue full); the node's next birth brings them again"
            );
        }
    }
    if !fx.historical.is_empty() {
        if let Some(history) = &shared.history {
            let rows = fx.historical.iter().filter_map(|(id, sample)| {
                let name = shared.db.meta(*id)?.name.clone();
                gridscada_store::HistorySample::of(name, sample)
            });
            let taken = history.push_all(rows);
            counters.historical(taken);
        }
    }
    counters.set_sites(online, tags);
    if let Some(node) = fx.rebirth {
        request_rebirth(shared, &node, now);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_flood_of_one_problem_is_logged_once_per_window() {
        let mut gate = LogGate::default();
        assert_eq!(gate.pass("malformed"), Some(0));
        assert_eq!(gate.pass("malformed"), None);
        assert_eq!(gate.pass("malformed"), None);
        // Another kind has its own window.
        assert_eq!(gate.pass("oversized"), Some(0));
        // The window over, the next warning says how many were held back.
        gate.0.get_mut("malformed").unwrap().0 -= Duration::from_secs(11);
        assert_eq!(gate.pass("malformed"), Some(2));
    }

    #[test]
    fn every_session_is_stamped_after_the_last() {
        let first = session_timestamp(None);
        let now = gridscada_tagdb::Timestamp::now_utc().as_millis();
        assert!((now - 1000..=now).contains(&first));
        // Twice within one millisecond, or after the clock stepped back.
        assert_eq!(session_timestamp(Some(now + 60_000)), now + 60_001);
        assert!(session_timestamp(Some(first)) > first);
    }

    #[test]
    fn the_state_body_is_sparkplug_3_json() {
        let v: serde_json::Value = serde_json::from_slice(&state_body(true, 1234)).unwrap();
        assert_eq!(v, serde_json::json!({"online": true, "timestamp": 1234}));
    }
}
