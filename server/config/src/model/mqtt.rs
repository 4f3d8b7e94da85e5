//! `[mqtt]`: the MQTT Sparkplug B northbound. `[mqtt.edge]` publishes this
//! server's tags to a broker; `[mqtt.host]` makes this server the central
//! host that builds its tags from the births of edge nodes. Off unless the
//! section is present.

use serde::Deserialize;
use serde_spanned::Spanned;

use super::Role;

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

/// `[mqtt.host]`: this server as the central Sparkplug B host. It
/// subscribes to `spBv1.0/GROUP/#` and takes the tags of every edge node it
/// accepts from their births, named `NODE.METRIC` (or `NODE.DEVICE.METRIC`).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MqttHostConfig {
    /// The host application id, published in `spBv1.0/STATE/HOST_ID`.
    pub host_id: Spanned<String>,
    /// The edge nodes whose births are taken; empty: every node of the group.
    #[serde(default)]
    pub nodes: Vec<Spanned<String>>,
    /// Name device metrics `NODE.DEVICE.METRIC` instead of `NODE.METRIC`
    /// (for edge nodes whose metric names repeat across devices).
    #[serde(default)]
    pub device_in_name: bool,
    /// At most this many remote tags (the room is reserved at start).
    #[serde(default = "default_max_tags")]
    pub max_tags: Spanned<usize>,
    /// A larger message is dropped and counted, not decoded.
    #[serde(default = "default_max_message_bytes")]
    pub max_message_bytes: Spanned<usize>,
    /// Rebirth requests (NCMD `Node Control/Rebirth`) to one node are at
    /// least this many seconds apart.
    #[serde(default = "default_rebirth_interval_s")]
    pub rebirth_interval_s: Spanned<f64>,
    /// A write (a DCMD/NCMD) not confirmed by the edge's data within this
    /// many seconds fails with a timeout.
    #[serde(default = "default_write_timeout_s")]
    pub write_timeout_s: Spanned<f64>,
    /// The role needed to write a remote tag that its birth marks writable.
    #[serde(default = "default_write_role")]
    pub write_role: Spanned<Role>,
}

impl MqttHostConfig {
    /// Whether births of edge node `node` are taken.
    pub fn accepts(&self, node: &str) -> bool {
        self.nodes.is_empty() || self.nodes.iter().any(|n| n.get_ref() == node)
    }
}

fn default_max_tags() -> Spanned<usize> {
    Spanned::new(0..0, 50_000)
}
fn default_max_message_bytes() -> Spanned<usize> {
    Spanned::new(0..0, 4 * 1024 * 1024)
}
fn default_rebirth_interval_s() -> Spanned<f64> {
    Spanned::new(0..0, 5.0)
}
fn default_write_timeout_s() -> Spanned<f64> {
    Spanned::new(0..0, 10.0)
}
fn default_write_role() -> Spanned<Role> {
    Spanned::new(0..0, Role::Operator)
}
