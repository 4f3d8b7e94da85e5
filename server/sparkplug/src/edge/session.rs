//! The MQTT sessions of the edge node. Each connection attempt gets a fresh
//! client with its own will: NDEATH carrying that session's `bdSeq`, so a
//! host can tell which birth a death ends. Nothing queued for a dead session
//! leaks into the next one (its client is dropped with it).

use std::path::PathBuf;
use std::time::Duration;

use prost::Message;
use rumqttc::{AsyncClient, ConnectReturnCode, Event, LastWill, MqttOptions, Packet, QoS};
use tokio::sync::{mpsc, watch};

use super::model::ndeath;

/// What the session task tells the edge node.
pub enum SessionEvent {
    /// Connected: publish births on this client.
    Up { client: AsyncClient, bd_seq: u64 },
    /// The session ended (broker gone, network cut, refused).
    Down { reason: String },
    /// A message on a subscribed topic.
    Message { topic: String, payload: Vec<u8> },
}

/// The first wait before reconnecting, and the longest.
const BACKOFF_MIN: Duration = Duration::from_millis(500);
const BACKOFF_MAX: Duration = Duration::from_secs(5);

/// The `bdSeq` of the next session, kept in the data folder so that it
/// keeps counting across restarts, as Sparkplug asks.
pub struct BdSeqFile(pub PathBuf);

impl BdSeqFile {
    fn load(&self) -> u64 {
        std::fs::read_to_string(&self.0)
            .ok()
            .and_then(|s| s.trim().parse::<u64>().ok())
            .map(|n| (n + 1) % 256)
            .unwrap_or(0)
    }
    fn store(&self, bd_seq: u64) {
        if let Err(e) = std::fs::write(&self.0, bd_seq.to_string()) {
            tracing::warn!(file = %self.0.display(), error = %e, "could not keep the MQTT bdSeq");
        }
    }
}

/// Connects, and reconnects with back-off, until `stop`.
pub async fn run(
    base: MqttOptions,
    death_topic: String,
    bd_seq_file: BdSeqFile,
    tx: mpsc::Sender<SessionEvent>,
    mut stop: watch::Receiver<bool>,
) {
    let mut bd_seq = bd_seq_file.load();
    let mut backoff = BACKOFF_MIN;
    loop {
        let mut opts = base.clone();
        opts.set_last_will(LastWill::new(
            death_topic.clone(),
            ndeath(bd_seq).encode_to_vec(),
            QoS::AtLeastOnce,
            false,
        ));
        bd_seq_file.store(bd_seq);
        let (client, mut eventloop) = AsyncClient::new(opts, 4096);
        let mut up = false;
        let reason = loop {
            let event = tokio::select! {
                _ = stop.changed() => return,
                e = eventloop.poll() => e,
            };
            match event {
                Ok(Event::Incoming(Packet::ConnAck(ack))) => {
                    if ack.code != ConnectReturnCode::Success {
                        break format!("the broker refused the connection: {:?}", ack.code);
                    }
                    up = true;
                    backoff = BACKOFF_MIN;
                    let client = client.clone();
                    if tx.send(SessionEvent::Up { client, bd_seq }).await.is_err() {
                        return;
                    }
                }
                Ok(Event::Incoming(Packet::Publish(p))) => {
                    let msg = SessionEvent::Message {
                        topic: p.topic,
                        payload: p.payload.to_vec(),
                    };
                    if tx.send(msg).await.is_err() {
                        return;
                    }
                }
                Ok(_) => {}
                Err(e) => break e.to_string(),
            }
        };
        if up {
            tracing::warn!(%reason, "MQTT session ended");
            if tx.send(SessionEvent::Down { reason }).await.is_err() {
                return;
            }
        } else {
            tracing::debug!(%reason, "MQTT connection failed");
        }
        drop(client);
        bd_seq = (bd_seq + 1) % 256;
        tokio::select! {
            _ = stop.changed() => return,
            _ = tokio::time::sleep(backoff) => {}
        }
        backoff = (backoff * 2).min(BACKOFF_MAX);
    }
}
