//! `[mqtt]`: the MQTT Sparkplug B northbound. `[mqtt.edge]` publishes this
//! server's tags to a broker; `[mqtt.host]` makes this server the central
//! host that builds its tags from the births of edge nodes. Off unless the
//! section is present.

use serde::Deserialize;
use serde_spanned::Spanned;

/// `[mqtt]`: the broker connection, shared by the edge and the host.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MqttConfig {
    /// `mqtt://host:port` or `mqtts://host:port` (TLS).
    pub broker: Spanned<String>,
    /// The Sparkplug group id (the topic's second level).
    pub group: Spanned<String>,
    /// The edge node (`[mqtt.edge]`), if this server publishes.
    #[serde(default)]
    pub edge: Option<MqttEdgeConfig>,

    /// The central host (`[mqtt.host]`), if this server subscribes.
    #[serde(default)]
    pub host: Option<MqttHostConfig>,
}

/// `[mqtt.edge]`: this server as a Sparkplug B edge node.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MqttEdgeConfig {
    /// The edge node id (the topic's fourth level), unique in the group.
    pub node: Spanned<String>,
}

/// `[mqtt.host]`: this server as the central Sparkplug B host.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MqttHostConfig {
    /// The host application id, published in `spBv1.0/STATE/HOST_ID`.
    pub host_id: Spanned<String>,
}
