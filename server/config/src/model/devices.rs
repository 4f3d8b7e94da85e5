//! Devices: `[[device]]` in the tag files, its protocol and transport
//! (Modbus over TCP or a serial line, IEC 60870-5-104 over TCP, DNP3 over
//! TCP or a serial line), its polling
//! limits and its comm alarm.

use serde::{Deserialize, Serialize};
use serde_spanned::Spanned;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Protocol {
    /// Modbus TCP.
    Tcp,
    /// Modbus RTU on a serial line.
    Rtu,
    /// IEC 60870-5-104 (`[device.iec104]`).
    Iec104,
    /// DNP3 over TCP or a serial line (`[device.dnp3]`).
    Dnp3,
    /// IEC 61850 MMS over TCP (`[device.iec61850]`).
    Iec61850,
}

impl Protocol {
    /// Modbus TCP or RTU: the tags are registers (`kind`, `address`).
    pub fn is_modbus(self) -> bool {
        matches!(self, Protocol::Tcp | Protocol::Rtu)
    }
    pub fn label(self) -> &'static str {
        match self {
            Protocol::Tcp => "tcp",
            Protocol::Rtu => "rtu",
            Protocol::Iec104 => "iec104",
            Protocol::Dnp3 => "dnp3",
            Protocol::Iec61850 => "iec61850",
        }
    }
}

#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct DeviceConfig {
    /// Unique device name, e.g. `SS1.IO1`.
    pub name: Spanned<String>,
    #[serde(default)]
    pub description: String,
    pub protocol: Protocol,
    /// TCP (Modbus TCP, IEC 104, DNP3 over TCP): `host:port`.
    pub address: Option<Spanned<String>>,
    /// RTU, or DNP3 on a serial line: the line.
    pub serial: Option<SerialConfig>,
    /// Modbus unit (slave) id.
    #[serde(default = "default_unit_id")]
    pub unit_id: Spanned<u8>,
    /// Default scan period of the device's tags.
    #[serde(default = "default_scan_ms")]
    pub scan_ms: Spanned<u64>,
    /// Per-request timeout.
    #[serde(default = "default_timeout_ms")]
    pub timeout_ms: Spanned<u64>,
    /// Retries of a failed read before the device counts as failing.
    #[serde(default = "default_retries")]
    pub retries: u32,
    /// Longest wait between probes of a failing device, in ms. Default:
    /// twice its fastest scan period, at least 2000 ms, so a device that
    /// recovers shows Good again within two scans and one probe interval.
    #[serde(default)]
    pub backoff_max_ms: Option<Spanned<u64>>,
    /// Most registers the device accepts in one read (protocol limit 125).
    #[serde(default = "default_max_registers")]
    pub max_read_registers: Spanned<u16>,
    /// Most bits the device accepts in one read (protocol limit 2000).
    #[serde(default = "default_max_bits")]
    pub max_read_bits: Spanned<u16>,
    /// Most registers the device accepts in one write (protocol limit 123).
    #[serde(default = "default_max_write_registers")]
    pub max_write_registers: Spanned<u16>,
    /// Largest run of unused addresses that block planning reads through to
    /// save a request.
    #[serde(default = "default_max_gap")]
    pub max_gap: u16,
    /// A tag of this device that holds the device's own clock (Unix seconds,
    /// or a `datetime`). The device's other tags read in the same scan take
    /// their timestamp from it instead of the time their reply arrived.
    #[serde(default)]
    pub time_tag: Option<Spanned<String>>,
    /// The device's communication-failure alarm.
    #[serde(default)]
    pub comm_alarm: CommAlarmConfig,
    /// IEC 104 link settings, for protocol = "iec104".
    #[serde(default)]
    pub iec104: Option<super::Iec104DeviceConfig>,
    /// DNP3 session settings, for protocol = "dnp3".
    #[serde(default)]
    pub dnp3: Option<super::Dnp3DeviceConfig>,
    /// IEC 61850 association and reports, for protocol = "iec61850".
    #[serde(default)]
    pub iec61850: Option<super::Iec61850DeviceConfig>,
}

/// A device's communication-failure alarm (`[device.comm_alarm]`): active
/// once the device has not answered for `on_delay_s`, cleared once it has
/// answered again for `off_delay_s`, so a device that drops out for a moment,
/// or answers in fits, does not chatter.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct CommAlarmConfig {
    #[serde(default = "default_comm_on_delay")]
    pub on_delay_s: Spanned<f64>,
    #[serde(default = "default_comm_off_delay")]
    pub off_delay_s: Spanned<f64>,
    #[serde(default = "default_comm_priority")]
    pub priority: u32,
}

impl Default for CommAlarmConfig {
    fn default() -> Self {
        CommAlarmConfig {
            on_delay_s: default_comm_on_delay(),
            off_delay_s: default_comm_off_delay(),
            priority: default_comm_priority(),
        }
    }
}

fn default_comm_on_delay() -> Spanned<f64> {
    Spanned::new(0..0, 2.0)
}
fn default_comm_off_delay() -> Spanned<f64> {
    Spanned::new(0..0, 5.0)
}
/// High: every value of the device is stale while it stands.
fn default_comm_priority() -> u32 {
    800
}

fn default_unit_id() -> Spanned<u8> {
    Spanned::new(0..0, 1)
}
fn default_scan_ms() -> Spanned<u64> {
    Spanned::new(0..0, 1000)
}
fn default_timeout_ms() -> Spanned<u64> {
    Spanned::new(0..0, 1000)
}
fn default_retries() -> u32 {
    1
}
fn default_max_registers() -> Spanned<u16> {
    Spanned::new(0..0, 125)
}
fn default_max_bits() -> Spanned<u16> {
    Spanned::new(0..0, 2000)
}
fn default_max_write_registers() -> Spanned<u16> {
    Spanned::new(0..0, 123)
}
fn default_max_gap() -> u16 {
    16
}

#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct SerialConfig {
    /// e.g. `/dev/ttyUSB0`.
    pub port: Spanned<String>,
    #[serde(default = "default_baud")]
    pub baud: u32,
    #[serde(default)]
    pub parity: Parity,
    #[serde(default = "default_data_bits")]
    pub data_bits: Spanned<u8>,
    #[serde(default = "default_stop_bits")]
    pub stop_bits: Spanned<u8>,
}

fn default_baud() -> u32 {
    9600
}
fn default_data_bits() -> Spanned<u8> {
    Spanned::new(0..0, 8)
}
fn default_stop_bits() -> Spanned<u8> {
    Spanned::new(0..0, 1)
}

#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Parity {
    #[default]
    None,
    Even,
    Odd,
}

impl DeviceConfig {
    /// The longest wait between probes of this device while it fails, given
    /// its fastest scan period.
    pub fn backoff_max(&self, fastest_scan: std::time::Duration) -> std::time::Duration {
        match &self.backoff_max_ms {
            Some(ms) => std::time::Duration::from_millis(*ms.get_ref()),
            None => (fastest_scan * 2).max(std::time::Duration::from_secs(2)),
        }
    }
}
