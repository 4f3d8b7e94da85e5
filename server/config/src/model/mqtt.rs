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
    /// The MQTT client id; unique on the broker. Default: `gridscada-`
    /// followed by the edge node id (or the host id).
    #[serde(default)]
    pub client_id: Option<Spanned<String>>,
    /// The broker account, if the broker asks for one.
    #[serde(default)]
    pub username: Option<Spanned<String>>,
    /// Its password; better given as `GRIDSCADA_MQTT_PASSWORD`.
    #[serde(default)]
    pub password: Option<Spanned<String>>,
    /// For `mqtts://`: the CA certificate(s) that signed the broker's
    /// certificate, PEM. A relative path is taken from the main file's folder.
    #[serde(default)]
    pub ca_file: Option<Spanned<String>>,
    /// The MQTT keep-alive: the broker declares this client dead (and
    /// publishes its NDEATH) after 1.5 times this without a packet.
    #[serde(default = "default_keep_alive")]
    pub keep_alive_s: Spanned<u64>,
    /// The largest message taken from the broker; a larger one is refused
    /// and counted (protects against a rogue publisher).
    #[serde(default = "default_max_message")]
    pub max_message_bytes: Spanned<usize>,
    /// The edge node (`[mqtt.edge]`), if this server publishes.
    #[serde(default)]
    pub edge: Option<MqttEdgeConfig>,

    /// The central host (`[mqtt.host]`), if this server subscribes.
    #[serde(default)]
    pub host: Option<MqttHostConfig>,
}

pub const DEFAULT_MQTT_KEEP_ALIVE_S: u64 = 10;
pub const DEFAULT_MQTT_MAX_MESSAGE_BYTES: usize = 256 * 1024;

fn default_keep_alive() -> Spanned<u64> {
    Spanned::new(0..0, DEFAULT_MQTT_KEEP_ALIVE_S)
}
fn default_max_message() -> Spanned<usize> {
    Spanned::new(0..0, DEFAULT_MQTT_MAX_MESSAGE_BYTES)
}

/// The Sparkplug device of an edge node that carries the tags of no Modbus
/// device (device status, panel sequence and dispatch tags). No configured
/// device may take this name while the edge is on.
pub const DERIVED_DEVICE: &str = "gridscada";

/// `[mqtt.edge]`: this server as a Sparkplug B edge node.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MqttEdgeConfig {
    /// The edge node id (the topic's fourth level), unique in the group.
    pub node: Spanned<String>,
    /// A change of a numeric tag smaller than this (in its engineering
    /// units) from the last value published is not published. 0: every change.
    #[serde(default = "zero_f64")]
    pub deadband: Spanned<f64>,
    /// Changes are gathered this long into one DDATA per device.
    #[serde(default = "default_batch_ms")]
    pub batch_ms: Spanned<u64>,
    /// While the broker is unreachable, at most this many samples are kept
    /// on disk (in `DATA/mqtt-buffer/`) to send as historical data; later
    /// ones are dropped and counted.
    #[serde(default = "default_buffer_samples")]
    pub buffer_samples: Spanned<usize>,
    /// The tags a DCMD may write: names, or a prefix ending in `*`
    /// (`SS1.*`). Empty: commands are refused.
    #[serde(default)]
    pub commands: Vec<Spanned<String>>,
    /// The role a DCMD write acts with: a tag whose `write_role` is above
    /// it is refused.
    #[serde(default = "default_command_role")]
    pub command_role: Spanned<Role>,
    /// The host application id of the primary host (Sparkplug 3.0): the
    /// edge births only while its retained `spBv1.0/STATE/ID` says online,
    /// and keeps samples in the buffer while it is offline. None: the edge
    /// births as soon as it has a broker session.
    #[serde(default)]
    pub primary_host_id: Option<Spanned<String>>,
}

pub const DEFAULT_MQTT_BATCH_MS: u64 = 100;
pub const DEFAULT_MQTT_BUFFER_SAMPLES: usize = 1_000_000;

fn zero_f64() -> Spanned<f64> {
    Spanned::new(0..0, 0.0)
}
fn default_batch_ms() -> Spanned<u64> {
    Spanned::new(0..0, DEFAULT_MQTT_BATCH_MS)
}
fn default_buffer_samples() -> Spanned<usize> {
    Spanned::new(0..0, DEFAULT_MQTT_BUFFER_SAMPLES)
}
fn default_command_role() -> Spanned<Role> {
    Spanned::new(0..0, Role::Operator)
}

impl MqttEdgeConfig {
    /// Whether the allow-list names this tag (exactly, or by a `PREFIX*`).
    pub fn allows_command(&self, tag: &str) -> bool {
        self.commands
            .iter()
            .any(|p| pattern_matches(p.get_ref(), tag))
    }
}

/// `name` exactly, or a prefix when the pattern ends in `*`.
pub fn pattern_matches(pattern: &str, tag: &str) -> bool {
    match pattern.strip_suffix('*') {
        Some(prefix) => tag.starts_with(prefix),
        None => pattern == tag,
    }
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
