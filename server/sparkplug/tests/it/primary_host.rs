//! The primary host's STATE (Sparkplug 3.0) against a real broker.
//!
//! The edge with `primary_host_id`: no birth while the host's retained STATE
//! says offline (samples buffered), births and the buffer as historical data
//! once it says online with a timestamp not older than the last, an older
//! STATE ignored, and on the host's offline STATE its NDEATH and the buffer
//! again. The central host: every MQTT session has its own, newer STATE
//! timestamp, in its birth and in its will.

use crate::common;

use std::path::Path;
use std::sync::Arc;
use std::time::Duration;

use common::{free_port, mosquitto, Broker, NoAudit, NoWrites};
use gridscada_sparkplug::edge::{EdgeContext, EdgeMetrics, EdgeNode};
use gridscada_sparkplug::host::{Host, HostOptions, HostOutputs, SitesPolicy};
use gridscada_sparkplug::proto::{MetricValue, Payload};
use gridscada_store::NewEvent;
use gridscada_tagdb::{SystemClock, TagDb, Timestamp};
use parking_lot::Mutex;
use prost::Message;
use rumqttc::{AsyncClient, Event, MqttOptions, Packet, QoS};

const GROUP: &str = "G";
const HOST: &str = "scada";
/// The longest any step here waits for the broker's answer.
const WAIT: Duration = Duration::from_secs(10);

/// A broker of its own, nothing kept on disk: (broker, port, folder).
async fn broker() -> Option<(Broker, u16, tempfile::TempDir)> {
    let Some(bin) = mosquitto() else {
        eprintln!("mosquitto not installed: primary host test skipped");
        return None;
    };
    let dir = tempfile::tempdir().unwrap();
    let port = free_port();
    let conf = dir.path().join("mosquitto.conf");
    std::fs::write(
        &conf,
        format!("listener {port} 127.0.0.1\nallow_anonymous true\npersistence false\n"),
    )
    .unwrap();
    Some((Broker::start(&bin, &conf, port).await, port, dir))
}

/// What a subscriber to everything Sparkplug saw: (topic, payload, retained).
type Seen = Arc<Mutex<Vec<(String, Vec<u8>, bool)>>>;

/// A client subscribed to `spBv1.0/#` (the group and every STATE), which
/// also publishes the primary host's STATE.
async fn watcher(port: u16, id: &str) -> (AsyncClient, Seen) {
    let (client, mut events) = AsyncClient::new(MqttOptions::new(id, "127.0.0.1", port), 64);
    let seen: Seen = Arc::default();
    let (subscribed, ready) = tokio::sync::oneshot::channel();
    let mut subscribed = Some(subscribed);
    let sink = seen.clone();
    let c = client.clone();
    tokio::spawn(async move {
        loop {
            match events.poll().await {
                Ok(Event::Incoming(Packet::ConnAck(_))) => {
                    let _ = c.subscribe("spBv1.0/#", QoS::AtLeastOnce).await;
                }
                Ok(Event::Incoming(Packet::SubAck(_))) => {
                    if let Some(tx) = subscribed.take() {
                        let _ = tx.send(());
                    }
                }
                Ok(Event::Incoming(Packet::Publish(p))) => {
                    sink.lock().push((p.topic, p.payload.to_vec(), p.retain))
                }
                Ok(_) => {}
                Err(_) => tokio::time::sleep(Duration::from_millis(100)).await,
            }
        }
    });
    tokio::time::timeout(WAIT, ready)
        .await
        .expect("the watcher's subscription")
        .unwrap();
    (client, seen)
}

async fn publish_state(client: &AsyncClient, online: bool, timestamp: i64) {
    let body = serde_json::json!({ "online": online, "timestamp": timestamp }).to_string();
    client
        .publish(
            format!("spBv1.0/STATE/{HOST}"),
            QoS::AtLeastOnce,
            true,
            body,
        )
        .await
        .unwrap();
}

/// Waits until `what` holds, at most [`WAIT`].
async fn until(what: &str, mut cond: impl FnMut() -> bool) {
    let start = std::time::Instant::now();
    while !cond() {
        assert!(start.elapsed() < WAIT, "waited {WAIT:?} for {what}");
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}

/// The Sparkplug messages of node n1 seen so far: (kind, payload).
fn node_messages(seen: &Seen) -> Vec<(String, Payload)> {
    seen.lock()
        .iter()
        .filter_map(|(topic, body, _)| {
            let kind = topic.split('/').nth(2)?;
            (topic.starts_with(&format!("spBv1.0/{GROUP}/"))
                && topic.split('/').nth(3) == Some("n1"))
            .then(|| (kind.to_string(), Payload::decode(body.as_slice()).unwrap()))
        })
        .collect()
}

fn count(seen: &Seen, kind: &str) -> usize {
    node_messages(seen)
        .iter()
        .filter(|(k, _)| k == kind)
        .count()
}

fn bd_seq(p: &Payload) -> Option<u64> {
    p.metrics
        .iter()
        .find(|m| m.name.as_deref() == Some("bdSeq"))
        .and_then(|m| match m.value {
            Some(MetricValue::Long(v)) => Some(v),
            _ => None,
        })
}

/// The values of tag `D1.V` in DDATA, with whether each was historical.
fn ddata_values(seen: &Seen) -> Vec<(f64, bool)> {
    node_messages(seen)
        .into_iter()
        .filter(|(k, _)| k == "DDATA")
        .flat_map(|(_, p)| p.metrics)
        .filter_map(|m| {
            let v = match m.value? {
                MetricValue::Float(f) => f64::from(f),
                MetricValue::Double(d) => d,
                _ => return None,
            };
            Some((v, m.is_historical.unwrap_or(false)))
        })
        .collect()
}

fn edge_plant(dir: &Path, port: u16) -> gridscada_config::Plant {
    let main = format!(
        "tag_files = [\"t.toml\"]\n[mqtt]\nbroker = \"mqtt://127.0.0.1:{port}\"\ngroup = \"{GROUP}\"\nkeep_alive_s = 5\n[mqtt.edge]\nnode = \"n1\"\nbatch_ms = 20\nprimary_host_id = \"{HOST}\"\n"
    );
    std::fs::write(dir.join("gridscada.toml"), main).unwrap();
    std::fs::write(
        dir.join("t.toml"),
        "[[device]]\nname = \"D1\"\nprotocol = \"tcp\"\naddress = \"127.0.0.1:1502\"\n\n[[tag]]\nname = \"D1.V\"\ndevice = \"D1\"\nkind = \"input_register\"\naddress = 0\ntype = \"f32\"\n",
    )
    .unwrap();
    gridscada_config::load_path(dir).unwrap_or_else(|d| panic!("{d:?}"))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_edge_follows_its_primary_hosts_state() {
    let Some((_broker, port, dir)) = broker().await else {
        return;
    };
    let (host, seen) = watcher(port, "primary-host").await;
    // The primary host was there and is gone: its will, retained.
    publish_state(&host, false, 1000).await;

    let plant = edge_plant(dir.path(), port);
    let db = Arc::new(TagDb::new(plant.tag_metas()).unwrap());
    let v = db.id("D1.V").unwrap();
    let (events, mut events_rx) = tokio::sync::mpsc::channel::<NewEvent>(64);
    tokio::spawn(async move { while events_rx.recv().await.is_some() {} });
    let mqtt = plant.mqtt.clone().unwrap();
    let data = tempfile::tempdir().unwrap();
    let ctx = EdgeContext {
        plant: Arc::new(plant),
        db: db.clone(),
        writer: Arc::new(NoWrites),
        audit: Arc::new(NoAudit),
        events,
        clock: Arc::new(SystemClock),
    };
    let edge = EdgeNode::start(ctx, &mqtt, dir.path(), data.path()).unwrap();
    let metrics = edge.metrics();
    let set = |value: f64| {
        db.set(
            v,
            value,
            gridscada_tagdb::Quality::GOOD,
            Timestamp::now_utc(),
        )
    };

    // Offline: connected, but no birth; the samples go to the buffer.
    until("the edge's session", || {
        EdgeMetrics::get(&metrics.connected) == 1
    })
    .await;
    for value in [1.0, 2.0, 3.0] {
        set(value);
        tokio::time::sleep(Duration::from_millis(60)).await;
    }
    until("3 samples buffered", || {
        EdgeMetrics::get(&metrics.buffered) >= 3
    })
    .await;
    // An online STATE older than the last one seen is ignored.
    publish_state(&host, true, 500).await;
    tokio::time::sleep(Duration::from_millis(500)).await;
    assert_eq!(
        count(&seen, "NBIRTH"),
        0,
        "no birth while the primary host is offline"
    );
    assert!(ddata_values(&seen).is_empty());
    assert_eq!(EdgeMetrics::get(&metrics.primary_host_online), 0);

    // Online (a newer session): births, then the buffer as historical data.
    publish_state(&host, true, 2000).await;
    until("NBIRTH and DBIRTH", || {
        count(&seen, "NBIRTH") == 1 && count(&seen, "DBIRTH") >= 1
    })
    .await;
    until("the buffered samples", || ddata_values(&seen).len() >= 3).await;
    assert_eq!(
        ddata_values(&seen),
        [(1.0, true), (2.0, true), (3.0, true)],
        "the buffered samples, in order, historical"
    );
    assert_eq!(EdgeMetrics::get(&metrics.primary_host_online), 1);
    let first_birth = bd_seq(&node_messages(&seen)[0].1).unwrap();

    // Live data; a late will of the host's earlier session changes nothing.
    set(4.0);
    until("live 4", || ddata_values(&seen).contains(&(4.0, false))).await;
    publish_state(&host, false, 1500).await;
    tokio::time::sleep(Duration::from_millis(200)).await;
    set(5.0);
    until("live 5", || ddata_values(&seen).contains(&(5.0, false))).await;
    assert_eq!(
        count(&seen, "NDEATH"),
        0,
        "an older offline STATE ends nothing"
    );

    // The host's death (its will: the same timestamp as its birth): NDEATH
    // with the birth's bdSeq, and buffering again, without a new birth.
    publish_state(&host, false, 2000).await;
    until("NDEATH", || count(&seen, "NDEATH") == 1).await;
    let death = node_messages(&seen)
        .into_iter()
        .find(|(k, _)| k == "NDEATH")
        .unwrap()
        .1;
    assert_eq!(
        bd_seq(&death),
        Some(first_birth),
        "the NDEATH ends that birth"
    );
    until("the edge's new session", || {
        EdgeMetrics::get(&metrics.connected) == 1
    })
    .await;
    set(6.0);
    until("6 buffered", || EdgeMetrics::get(&metrics.buffered) >= 1).await;
    tokio::time::sleep(Duration::from_millis(300)).await;
    assert_eq!(
        count(&seen, "NBIRTH"),
        1,
        "no birth while the host is offline again"
    );
    assert!(!ddata_values(&seen).contains(&(6.0, false)));

    // Back online: a new birth (a new bdSeq), and 6 as historical data.
    publish_state(&host, true, 3000).await;
    until("the second birth", || count(&seen, "NBIRTH") == 2).await;
    until("6 as history", || {
        ddata_values(&seen).contains(&(6.0, true))
    })
    .await;
    let births: Vec<u64> = node_messages(&seen)
        .iter()
        .filter(|(k, _)| k == "NBIRTH")
        .filter_map(|(_, p)| bd_seq(p))
        .collect();
    assert_ne!(births[0], births[1]);
    let all: Vec<f64> = ddata_values(&seen).iter().map(|(v, _)| *v).collect();
    for value in [1.0, 2.0, 3.0, 4.0, 5.0, 6.0] {
        assert!(all.contains(&value), "{value} lost: {all:?}");
    }
    edge.shutdown().await;
}

/// The retained STATE of the host as a fresh client reads it.
fn host_states(seen: &Seen) -> Vec<(bool, i64)> {
    seen.lock()
        .iter()
        .filter(|(topic, _, _)| topic == &format!("spBv1.0/STATE/{HOST}"))
        .filter_map(|(_, body, _)| {
            let v: serde_json::Value = serde_json::from_slice(body).ok()?;
            Some((v["online"].as_bool()?, v["timestamp"].as_i64()?))
        })
        .collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_central_host_stamps_every_session_anew() {
    let Some((broker, port, dir)) = broker().await else {
        return;
    };
    let plant = format!(
        "[mqtt]\nbroker = \"mqtt://127.0.0.1:{port}\"\ngroup = \"{GROUP}\"\nkeep_alive_s = 5\n[mqtt.host]\nhost_id = \"{HOST}\"\n"
    );
    std::fs::write(dir.path().join("gridscada.toml"), plant).unwrap();
    let plant = gridscada_config::load_path(dir.path()).unwrap_or_else(|d| panic!("{d:?}"));
    let opts = HostOptions {
        mqtt: plant.mqtt.clone().unwrap(),
        config_dir: dir.path().to_path_buf(),
        host_id: HOST.into(),
        sites: SitesPolicy {
            group: GROUP.into(),
            nodes: Vec::new(),
            device_in_name: false,
            rebirth_interval: Duration::from_secs(1),
        },
        max_message_bytes: 1 << 20,
        write_timeout: Duration::from_secs(3),
    };
    let db = Arc::new(TagDb::with_room(Vec::new(), 16).unwrap());
    let host = Host::start(opts, db, Arc::new(SystemClock), HostOutputs::default()).unwrap();
    let (_w, seen) = watcher(port, "watcher-1").await;
    until("the host's STATE", || !seen.lock().is_empty()).await;
    let first = host_states(&seen);
    assert!(matches!(first[..], [(true, _)]), "{first:?}");
    let t1 = first[0].1;

    // The broker restarts (forgetting everything): the host's new session
    // publishes a newer timestamp.
    let conf = dir.path().join("mosquitto.conf");
    drop(broker);
    let broker = Broker::start(&mosquitto().unwrap(), &conf, port).await;
    let (_w, seen) = watcher(port, "watcher-2").await;
    until("the host's STATE after the restart", || {
        !seen.lock().is_empty()
    })
    .await;
    let second = host_states(&seen);
    assert!(
        matches!(second[..], [(true, t2)] if t2 > t1),
        "a new session, a newer STATE than {t1}: {second:?}"
    );
    let t2 = second[0].1;

    // Its will carries that session's timestamp: a client that takes over
    // its client id cuts it, and the broker sends the will.
    let (kicker, mut kicked) = AsyncClient::new(
        MqttOptions::new(format!("gridscada-host-{HOST}"), "127.0.0.1", port),
        8,
    );
    let _ = tokio::time::timeout(Duration::from_secs(2), kicked.poll()).await;
    until("the will and the next session's birth", || {
        host_states(&seen).len() >= 3
    })
    .await;
    drop(kicker);
    let states = host_states(&seen);
    assert_eq!(
        states[1],
        (false, t2),
        "the will of the session stamped {t2}: {states:?}"
    );
    assert!(
        states[2].0 && states[2].1 > t2,
        "the next session is stamped later: {states:?}"
    );
    host.shutdown().await;
    drop(broker);
}
