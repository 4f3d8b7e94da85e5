//! The configuration schema, as serde types. Documented for engineers in
//! `docs/CONFIGURATION.md`; keep the two in step.
//!
//! Fields that validation must point at are `Spanned`, so an error can name
//! the file, line and column.
//!
//! This file holds the main file and a tag file as a whole, and the small
//! defaults their parts share; each part has its own file, all re-exported
//! here: the server, storage, sessions and roles `server.rs`, devices
//! `devices.rs`, IEC 104 links and points `iec104.rs`, DNP3 sessions and points `dnp3.rs`, tags `tags.rs`, a tag's alarms and history `alarms.rs`,
//! panels `panels.rs`, the microgrid `microgrid.rs`, the MQTT Sparkplug B
//! northbound `mqtt.rs`, the OPC UA server `opcua.rs`, the redundant pair
//! `redundancy.rs`, alarm notification routes `notify.rs`, how the HMI shows
//! numbers and dates `hmi.rs`.

use serde::Deserialize;
use serde_spanned::Spanned;

mod alarms;
mod devices;
mod dnp3;
mod hmi;
mod iec104;
mod iec61850;
mod microgrid;
mod mqtt;
mod network;
mod notify;
mod opcua;
mod panels;
mod proxy;
mod redundancy;
mod reports;
mod server;
mod tags;

pub use alarms::*;
pub use devices::*;
pub use dnp3::*;
pub use hmi::*;
pub use iec104::*;
pub use iec61850::*;
pub use microgrid::*;
pub use mqtt::*;
pub use network::*;
pub use notify::*;
pub use opcua::*;
pub use panels::*;
pub use proxy::*;
pub use redundancy::*;
pub use reports::*;
pub use server::*;
pub use tags::*;

/// `gridscada.toml`: the plant's main file.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MainFile {
    /// Tag files, relative to the main file.
    pub tag_files: Vec<Spanned<String>>,
    #[serde(default)]
    pub server: ServerConfig,
    #[serde(default)]
    pub storage: StorageConfig,
    #[serde(default, rename = "panel")]
    pub panels: Vec<PanelConfig>,
    pub microgrid: Option<MicrogridConfig>,
    pub mqtt: Option<MqttConfig>,
    pub opcua: Option<OpcUaConfig>,
    /// `[iec104_server]`: the IEC 104 controlled station toward a control centre.
    pub iec104_server: Option<Iec104ServerConfig>,
    pub redundancy: Option<RedundancyConfig>,
    /// `[[notify]]`: alarm notification routes.
    #[serde(default)]
    pub notify: Vec<NotifyConfig>,
    /// `[[suppression]]`: configured suppression rules.
    #[serde(default)]
    pub suppression: Vec<SuppressionConfig>,
    /// `[reports]`: the report schedule.
    #[serde(default)]
    pub reports: ReportsConfig,
    /// `[network]`: the switching network, if configured.
    pub network: Option<NetworkConfig>,
    /// `[hmi]`: decimals and date format on the HMI.
    #[serde(default)]
    pub hmi: HmiConfig,
}

/// A tag file: devices and the tags read from them.
#[derive(Debug, Clone, Default)]
pub struct TagFile {
    pub devices: Vec<DeviceConfig>,
    pub tags: Vec<TagConfig>,
}

fn one() -> Spanned<f64> {
    Spanned::new(0..0, 1.0)
}

fn yes() -> bool {
    true
}
fn zero() -> Spanned<f64> {
    Spanned::new(0..0, 0.0)
}
fn no() -> Spanned<bool> {
    Spanned::new(0..0, false)
}
