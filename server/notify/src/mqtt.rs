//! The MQTT channel: a message published at QoS 1 on the broker of the
//! plant's `[mqtt]` (its client options, credentials and TLS come from the
//! Sparkplug B connection's [`gridscada_sparkplug::connection::options`]),
//! on a topic per priority band, `{topic}/urgent` ... `{topic}/low`, or
//! `{topic}/summary` for a flood summary.
//!
//! Notifications are rare and each must be known delivered: an attempt
//! connects, publishes, waits for the broker's PUBACK and disconnects. A
//! failed attempt is the outbox's to retry, like an SMTP or webhook one.

use std::path::Path;
use std::time::Duration;

use gridscada_config::{MqttConfig, NotifyMqttConfig};
use rumqttc::{AsyncClient, ConnectReturnCode, Event, MqttOptions, Outgoing, Packet, QoS};

use crate::channels::Payload;
use crate::message::{priority_name, Message};

pub struct Mqtt {
    options: MqttOptions,
    topic: String,
    retain: bool,
}

impl Mqtt {
    pub(crate) fn build(
        route: &str,
        m: &NotifyMqttConfig,
        plant_mqtt: Option<&MqttConfig>,
        base: &Path,
    ) -> Result<Mqtt, String> {
        let plant_mqtt = plant_mqtt.ok_or("channel \"mqtt\" needs [mqtt], the broker")?;
        let prefix = plant_mqtt
            .client_id
            .as_ref()
            .map(|c| c.get_ref().as_str())
            .unwrap_or("gridscada");
        // Its own session beside the Sparkplug one: a broker drops the older
        // of two sessions with one client id.
        let client_id: String = format!("{prefix}-notify-{route}")
            .chars()
            .map(|c| {
                if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                    c
                } else {
                    '-'
                }
            })
            .collect();
        let options = gridscada_sparkplug::connection::options(plant_mqtt, &client_id, base)
            .map_err(|e| e.to_string())?;
        Ok(Mqtt {
            options,
            topic: m.topic.get_ref().clone(),
            retain: m.retain,
        })
    }

    /// The topic of `m`: by the band of its alarm's priority.
    pub fn topic_for(&self, m: &Message) -> String {
        let band = match &m.alarm {
            Some(a) => priority_name(a.priority).to_ascii_lowercase(),
            None => "summary".to_string(),
        };
        format!("{}/{band}", self.topic)
    }

    pub(crate) async fn send(
        &self,
        id: i64,
        contact: &str,
        address: &str,
        m: &Message,
    ) -> Result<(), String> {
        let body = serde_json::to_vec(&Payload {
            id,
            contact,
            address,
            message: m,
        })
        .map_err(|e| format!("encoding: {e}"))?;
        let topic = self.topic_for(m);
        let (client, mut events) = AsyncClient::new(self.options.clone(), 4);
        client
            .publish(topic.as_str(), QoS::AtLeastOnce, self.retain, body)
            .await
            .map_err(|e| format!("MQTT: {e}"))?;
        loop {
            match events.poll().await {
                Ok(Event::Incoming(Packet::ConnAck(ack)))
                    if ack.code != ConnectReturnCode::Success =>
                {
                    return Err(format!(
                        "the MQTT broker refused the connection: {:?}",
                        ack.code
                    ));
                }
                Ok(Event::Incoming(Packet::PubAck(_))) => break,
                Ok(_) => {}
                Err(e) => return Err(format!("MQTT broker: {e}")),
            }
        }
        // Delivered; a clean goodbye, so the broker does not log a lost client.
        let _ = client.disconnect().await;
        let _ = tokio::time::timeout(Duration::from_secs(2), async {
            while let Ok(e) = events.poll().await {
                if matches!(e, Event::Outgoing(Outgoing::Disconnect)) {
                    break;
                }
            }
        })
        .await;
        Ok(())
    }
}
