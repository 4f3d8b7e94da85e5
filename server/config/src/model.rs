//! The configuration schema, as serde types. Documented for engineers in
//! `docs/CONFIGURATION.md`; keep the two in step.
//!
//! Fields that validation must point at are `Spanned`, so an error can name
//! the file, line and column.

use serde::{Deserialize, Serialize};
use serde_spanned::Spanned;

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
}

#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct ServerConfig {
    /// HTTP bind address of the API and HMI.
    #[serde(default = "default_http")]
    pub http: Spanned<String>,
    /// Folder for the SQLite database and other local state, relative to the
    /// working directory.
    #[serde(default = "default_data_dir")]
    pub data_dir: String,
    /// Host names (without port) the HMI may be reached by, besides IP
    /// addresses and `localhost`. A request naming another host is refused,
    /// which defeats DNS rebinding.
    #[serde(default)]
    pub allowed_hosts: Vec<String>,
    /// `/metrics`: a bearer token Prometheus must send. Without one, only
    /// loopback clients may scrape (`demo`: anyone who reaches it).
    #[serde(default)]
    pub metrics_token: Option<String>,
    /// `/metrics`: client addresses allowed without the token.
    #[serde(default)]
    pub metrics_allow: Vec<std::net::IpAddr>,
}

impl Default for ServerConfig {
    fn default() -> Self {
        ServerConfig {
            http: default_http(),
            data_dir: default_data_dir(),
            allowed_hosts: vec![],
            metrics_token: None,
            metrics_allow: vec![],
        }
    }
}

fn default_http() -> Spanned<String> {
    Spanned::new(0..0, "127.0.0.1:8080".into())
}
fn default_data_dir() -> String {
    "data".into()
}

#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct StorageConfig {
    /// `sqlite://PATH` (relative paths are inside the data folder) or
    /// `postgres://user:pass@host/db`.
    #[serde(default = "default_storage_url")]
    pub url: Spanned<String>,
    /// Global historian retention, in days; a tag's own setting wins.
    #[serde(default = "default_retention_days")]
    pub retention_days: u32,
}

impl Default for StorageConfig {
    fn default() -> Self {
        StorageConfig {
            url: default_storage_url(),
            retention_days: default_retention_days(),
        }
    }
}

fn default_storage_url() -> Spanned<String> {
    Spanned::new(0..0, "sqlite://gridscada.db".into())
}
fn default_retention_days() -> u32 {
    90
}

/// A tag file: devices and the tags read from them.
#[derive(Debug, Clone, Default)]
pub struct TagFile {
    pub devices: Vec<DeviceConfig>,
    pub tags: Vec<TagConfig>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Protocol {
    Tcp,
    Rtu,
}

#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct DeviceConfig {
    /// Unique device name, e.g. `SS1.IO1`.
    pub name: Spanned<String>,
    #[serde(default)]
    pub description: String,
    pub protocol: Protocol,
    /// TCP: `host:port`.
    pub address: Option<Spanned<String>>,
    /// RTU: the serial line.
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

/// The four Modbus data tables.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum RegisterKind {
    Coil,
    DiscreteInput,
    InputRegister,
    HoldingRegister,
}

impl RegisterKind {
    /// Coils and discrete inputs hold bits; the others 16-bit registers.
    pub fn is_bit(self) -> bool {
        matches!(self, RegisterKind::Coil | RegisterKind::DiscreteInput)
    }
    /// Whether the protocol lets a master write this table.
    pub fn is_writable(self) -> bool {
        matches!(self, RegisterKind::Coil | RegisterKind::HoldingRegister)
    }
    pub fn label(self) -> &'static str {
        match self {
            RegisterKind::Coil => "coil",
            RegisterKind::DiscreteInput => "discrete_input",
            RegisterKind::InputRegister => "input_register",
            RegisterKind::HoldingRegister => "holding_register",
        }
    }
}

/// The wire type of a tag.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum DataType {
    Bool,
    I16,
    U16,
    I32,
    U32,
    I64,
    U64,
    F32,
    F64,
    String,
    /// A device clock as six registers: year, month, day, hour, minute,
    /// second (UTC), read as RFC 3339 text. Read-only.
    DateTime,
}

impl DataType {
    /// Registers the type occupies; strings take their configured length.
    pub fn registers(self, string_len: u16) -> u16 {
        match self {
            DataType::Bool | DataType::I16 | DataType::U16 => 1,
            DataType::I32 | DataType::U32 | DataType::F32 => 2,
            DataType::I64 | DataType::U64 | DataType::F64 => 4,
            DataType::String => string_len,
            DataType::DateTime => 6,
        }
    }
    pub fn label(self) -> &'static str {
        match self {
            DataType::Bool => "bool",
            DataType::I16 => "i16",
            DataType::U16 => "u16",
            DataType::I32 => "i32",
            DataType::U32 => "u32",
            DataType::I64 => "i64",
            DataType::U64 => "u64",
            DataType::F32 => "f32",
            DataType::F64 => "f64",
            DataType::String => "string",
            DataType::DateTime => "datetime",
        }
    }
}

/// Order of bytes within a register, or of registers within a wide value.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Endian {
    /// Most significant first (the Modbus convention).
    #[default]
    Big,
    Little,
}

/// Who may do what. Ordered: each role may do everything the ones below it may.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Role {
    Guest,
    Operator,
    Supervisor,
    Administrator,
}

impl Role {
    pub fn label(self) -> &'static str {
        match self {
            Role::Guest => "guest",
            Role::Operator => "operator",
            Role::Supervisor => "supervisor",
            Role::Administrator => "administrator",
        }
    }
}

#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct TagConfig {
    /// Unique hierarchical name, e.g. `SS1.Zone2.Closed`.
    pub name: Spanned<String>,
    #[serde(default)]
    pub description: String,
    /// The device the tag is read from.
    pub device: Spanned<String>,
    /// Modbus table.
    pub kind: Spanned<RegisterKind>,
    /// Zero-based address in that table.
    pub address: Spanned<u32>,
    /// Bit within a register (0 = least significant), for bool tags on registers.
    pub bit: Option<Spanned<u8>>,
    /// Wire type; `bool` by default for coils and discrete inputs, `u16` for registers.
    #[serde(rename = "type")]
    pub data_type: Option<Spanned<DataType>>,
    /// Registers of a string tag (two characters each).
    pub length: Option<Spanned<u16>>,
    /// Register order of 32/64-bit values.
    #[serde(default)]
    pub word_order: Endian,
    /// Byte order within each register.
    #[serde(default)]
    pub byte_order: Endian,
    /// Engineering value = raw * scale + offset.
    #[serde(default = "one")]
    pub scale: Spanned<f64>,
    #[serde(default)]
    pub offset: f64,
    #[serde(default)]
    pub units: String,
    #[serde(default = "no")]
    pub writable: Spanned<bool>,
    /// The least role that may write the tag; required when writable.
    pub write_role: Option<Spanned<Role>>,
    /// Engineering limits of a writable numeric tag: a write outside them
    /// is refused, whoever sends it (HMI, control loop, northbound).
    /// Microgrid setpoints default to their unit's ratings.
    #[serde(default)]
    pub min: Option<Spanned<f64>>,
    #[serde(default)]
    pub max: Option<Spanned<f64>>,
    /// Scan period of this tag, overriding the device's.
    pub scan_ms: Option<Spanned<u64>>,
    /// The device clock tag this tag takes its timestamp from, overriding
    /// the device's `time_tag`; `"receive"` keeps the time the reply arrived.
    #[serde(default)]
    pub time_tag: Option<Spanned<String>>,
    /// Words for the values of a bool or integer tag, shown instead of the
    /// number: `states = { false = "TRIPPED", true = "CLOSED" }`,
    /// `states = { 0 = "Stopped", 1 = "Manual", 2 = "Automatic" }`.
    #[serde(default)]
    pub states: Option<Spanned<std::collections::BTreeMap<String, String>>>,
    pub alarm: Option<AlarmConfig>,
    #[serde(default)]
    pub history: HistoryConfig,
}

fn one() -> Spanned<f64> {
    Spanned::new(0..0, 1.0)
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

impl TagConfig {
    /// The wire type, with its default applied.
    pub fn data_type(&self) -> DataType {
        match &self.data_type {
            Some(t) => *t.get_ref(),
            None if self.kind.get_ref().is_bit() || self.bit.is_some() => DataType::Bool,
            None => DataType::U16,
        }
    }
    /// Registers (or bits) the tag occupies.
    pub fn width(&self) -> u16 {
        if self.kind.get_ref().is_bit() || self.bit.is_some() {
            1
        } else {
            self.data_type()
                .registers(self.length.as_ref().map(|l| *l.get_ref()).unwrap_or(0))
        }
    }
    /// The engineering kind of the tag's value.
    pub fn value_kind(&self) -> gridscada_tagdb::ValueKind {
        use gridscada_tagdb::ValueKind;
        let scaled = *self.scale.get_ref() != 1.0 || self.offset != 0.0;
        match self.data_type() {
            DataType::Bool => ValueKind::Bool,
            DataType::String | DataType::DateTime => ValueKind::Str,
            DataType::F32 | DataType::F64 => ValueKind::Float,
            _ if scaled => ValueKind::Float,
            _ => ValueKind::Int,
        }
    }
    /// The effective scan period.
    /// The word configured for `value` in `states`, if any.
    pub fn state_label(&self, value: &gridscada_tagdb::Value) -> Option<&str> {
        let states = self.states.as_ref()?.get_ref();
        state_label(states, value)
    }

    /// The device clock tag that stamps this tag's samples, if any: the
    /// tag's own `time_tag`, else its device's; never the clock itself.
    /// `None` means the receive time.
    pub fn time_tag<'a>(&'a self, device: &'a DeviceConfig) -> Option<&'a str> {
        let name = self
            .time_tag
            .as_ref()
            .or(device.time_tag.as_ref())
            .map(|t| t.get_ref().as_str())?;
        (name != RECEIVE_TIME && name != self.name.get_ref()).then_some(name)
    }

    pub fn scan_ms(&self, device: &DeviceConfig) -> u64 {
        self.scan_ms
            .as_ref()
            .map(|s| *s.get_ref())
            .unwrap_or(*device.scan_ms.get_ref())
    }
}

/// The word for `value` in a `states` table: keyed `true`/`false` for a
/// bool, the decimal integer for a number (a bool reads as 0/1 there too).
pub fn state_label<'a>(
    states: &'a std::collections::BTreeMap<String, String>,
    value: &gridscada_tagdb::Value,
) -> Option<&'a str> {
    use gridscada_tagdb::Value;
    let key = match value {
        Value::Bool(b) => {
            if let Some(l) = states.get(if *b { "true" } else { "false" }) {
                return Some(l);
            }
            i64::from(*b).to_string()
        }
        Value::Float(f) if f.fract() == 0.0 && f.abs() < 1e15 => (*f as i64).to_string(),
        Value::Int(_) | Value::UInt(_) => value.to_string(),
        _ => return None,
    };
    states.get(&key).map(String::as_str)
}

/// The `time_tag` value that keeps a tag's receive time.
pub const RECEIVE_TIME: &str = "receive";

/// Alarm settings of a tag.
#[derive(Debug, Clone, Default, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct AlarmConfig {
    /// Default selection (alarm group) of this tag's alarms.
    pub selection: Option<String>,
    pub hihi: Option<LimitAlarm>,
    pub hi: Option<LimitAlarm>,
    pub lo: Option<LimitAlarm>,
    pub lolo: Option<LimitAlarm>,
    /// Discrete alarms: active while the value equals `when`.
    #[serde(default)]
    pub discrete: Vec<DiscreteAlarm>,
}

impl AlarmConfig {
    /// Whether one of the discrete alarms is active while a bool tag reads `v`.
    pub fn alarms_when(&self, v: bool) -> bool {
        self.discrete
            .iter()
            .any(|d| matches!(d.when.get_ref(), toml::Value::Boolean(b) if *b == v))
    }
}

#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct LimitAlarm {
    pub limit: Spanned<f64>,
    #[serde(default = "default_priority")]
    pub priority: u32,
    /// The value must come back past the limit by this much to clear.
    #[serde(default = "zero")]
    pub deadband: Spanned<f64>,
    /// Seconds the condition must hold before the alarm activates.
    #[serde(default = "zero")]
    pub on_delay_s: Spanned<f64>,
    /// Seconds the condition must be gone before the alarm clears.
    #[serde(default = "zero")]
    pub off_delay_s: Spanned<f64>,
    /// Message; `{tag}`, `{value}`, `{limit}` and `{units}` are substituted.
    pub message: Option<String>,
    pub selection: Option<String>,
}

#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct DiscreteAlarm {
    /// The alarm is active while the tag has this value.
    pub when: Spanned<toml::Value>,
    #[serde(default = "default_priority")]
    pub priority: u32,
    #[serde(default = "zero")]
    pub on_delay_s: Spanned<f64>,
    #[serde(default = "zero")]
    pub off_delay_s: Spanned<f64>,
    pub message: Option<String>,
    pub selection: Option<String>,
}

fn default_priority() -> u32 {
    500
}

/// Historian settings of a tag. By default every tag is logged on change.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct HistoryConfig {
    #[serde(default = "yes")]
    pub enabled: bool,
    /// A value is logged when it moves more than this from the last logged one.
    #[serde(default = "zero")]
    pub deadband: Spanned<f64>,
    /// A value is logged at least this often, changed or not.
    #[serde(default = "default_max_interval")]
    pub max_interval_s: Spanned<f64>,
    /// Retention in days; the storage default applies when absent.
    pub retention_days: Option<u32>,
}

impl Default for HistoryConfig {
    fn default() -> Self {
        HistoryConfig {
            enabled: true,
            deadband: Spanned::new(0..0, 0.0),
            max_interval_s: default_max_interval(),
            retention_days: None,
        }
    }
}

fn yes() -> bool {
    true
}
fn default_max_interval() -> Spanned<f64> {
    Spanned::new(0..0, 900.0)
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum PanelKind {
    /// The service substation panel.
    Service,
    /// A customer service substation panel.
    CustomerService,
}

/// An LV substation panel that runs the OLUC/OLDC fault-isolation sequence.
///
/// Its I/O tags follow a naming convention under `prefix` (see
/// [`PanelConfig::io`]); `gridscada check` verifies that they exist.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct PanelConfig {
    /// Short id used in the API, e.g. `ss1`.
    pub id: Spanned<String>,
    pub name: String,
    pub kind: PanelKind,
    /// Tag name prefix of the panel's I/O, e.g. `SS1`.
    pub prefix: Spanned<String>,
    /// Number of zone MCBs (the seed has 4).
    pub zones: Spanned<u8>,
    /// Delay before the ELCB is reset after a trip.
    #[serde(default = "default_reclose_delay")]
    pub reclose_delay_s: Spanned<f64>,
    /// Time after each switch-on for the ELCB to trip if the load is faulty.
    #[serde(default = "default_dwell")]
    pub dwell_s: Spanned<f64>,
    /// Time for a status input to confirm a command.
    #[serde(default = "default_confirm_timeout")]
    pub confirm_timeout_s: Spanned<f64>,
    /// ELCB trips allowed in one sequence before lockout.
    #[serde(default = "default_max_trips")]
    pub max_trips: Spanned<u8>,
    /// Mode at start-up.
    #[serde(default = "default_auto")]
    pub start_mode: PanelMode,
}

fn default_reclose_delay() -> Spanned<f64> {
    Spanned::new(0..0, 3.0)
}
fn default_dwell() -> Spanned<f64> {
    Spanned::new(0..0, 1.0)
}
fn default_confirm_timeout() -> Spanned<f64> {
    Spanned::new(0..0, 2.0)
}
fn default_max_trips() -> Spanned<u8> {
    Spanned::new(0..0, 8)
}
fn default_auto() -> PanelMode {
    PanelMode::Auto
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum PanelMode {
    Auto,
    Manual,
}

/// Names of a panel's I/O tags.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PanelIo {
    /// ELCB status input: true while closed.
    pub elcb_closed: String,
    /// ELCB reset output: a pulse closes a tripped ELCB.
    pub elcb_reset: String,
    /// Main MCCB (load 0) command output and status input.
    pub mccb_cmd: String,
    pub mccb_closed: String,
    /// Zone MCB command outputs and status inputs, zone 1 first.
    pub zone_cmd: Vec<String>,
    pub zone_closed: Vec<String>,
}

impl PanelConfig {
    pub fn io(&self) -> PanelIo {
        let p = self.prefix.get_ref();
        let n = *self.zones.get_ref();
        PanelIo {
            elcb_closed: format!("{p}.ELCB.Closed"),
            elcb_reset: format!("{p}.ELCB.Reset"),
            mccb_cmd: format!("{p}.MCCB.Cmd"),
            mccb_closed: format!("{p}.MCCB.Closed"),
            zone_cmd: (1..=n).map(|z| format!("{p}.Zone{z}.Cmd")).collect(),
            zone_closed: (1..=n).map(|z| format!("{p}.Zone{z}.Closed")).collect(),
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum UnitKind {
    Pv,
    Wind,
    Storage,
    Diesel,
}

/// The microgrid and its cascade outer loop.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct MicrogridConfig {
    /// Outer-loop period.
    #[serde(default = "default_dispatch_period")]
    pub dispatch_period_s: Spanned<f64>,
    /// Value of lost load: the price of shedding.
    #[serde(default = "default_voll")]
    pub voll_per_kwh: f64,
    /// Tag of the measured demand, kW.
    pub demand_tag: Spanned<String>,
    /// Measurements older than this are stale and force the fallback.
    #[serde(default = "default_stale")]
    pub stale_after_s: f64,
    #[serde(default)]
    pub commitment: CommitmentConfig,
    /// Look-ahead of the outer loop (absent: each period on its own).
    #[serde(default)]
    pub horizon: Option<HorizonConfig>,
    #[serde(rename = "unit")]
    pub units: Vec<UnitConfig>,
}

/// Points of a daily curve: `[hour, value]` pairs, hour in [0, 24) UTC,
/// interpolated linearly and wrapping at midnight (see [`crate::daily`]).
pub type DailyPoints = Spanned<Vec<(f64, f64)>>;

/// The receding horizon: every `resolve_s` the outer loop solves the
/// multi-period problem over `periods` × `period_s` ahead, from the
/// measurements now and the forecasts, and prices stored energy in each
/// period's dispatch with what the horizon says a stored kWh is worth.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct HorizonConfig {
    /// Number of look-ahead periods.
    #[serde(default = "default_horizon_periods")]
    pub periods: Spanned<f64>,
    /// Length of one look-ahead period, s.
    #[serde(default = "default_horizon_period_s")]
    pub period_s: Spanned<f64>,
    /// How often the horizon is solved again, s (at least the dispatch period).
    #[serde(default = "default_horizon_resolve_s")]
    pub resolve_s: Spanned<f64>,
    /// How fast today's deviation from a daily forecast curve fades towards
    /// the curve, h (e-folding time of the ratio measured / curve).
    #[serde(default = "default_blend_h")]
    pub blend_h: Spanned<f64>,
    /// Daily demand curve, kW (absent: the demand now persists).
    #[serde(default)]
    pub demand_forecast_kw: Option<DailyPoints>,
    /// Spinning reserve to hold in every look-ahead period.
    #[serde(default)]
    pub reserve: Option<ReserveConfig>,
}

fn default_horizon_periods() -> Spanned<f64> {
    Spanned::new(0..0, 16.0)
}
fn default_horizon_period_s() -> Spanned<f64> {
    Spanned::new(0..0, 900.0)
}
fn default_horizon_resolve_s() -> Spanned<f64> {
    Spanned::new(0..0, 60.0)
}
fn default_blend_h() -> Spanned<f64> {
    Spanned::new(0..0, 2.0)
}

/// Spinning reserve: online headroom (running diesels, storage discharge)
/// must cover these shares of load, PV and wind; a shortfall costs
/// `shortfall_cost_per_kwh`.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct ReserveConfig {
    #[serde(default)]
    pub load_frac: f64,
    #[serde(default)]
    pub pv_frac: f64,
    #[serde(default)]
    pub wind_frac: f64,
    pub shortfall_cost_per_kwh: f64,
}

fn default_dispatch_period() -> Spanned<f64> {
    Spanned::new(0..0, 5.0)
}
fn default_voll() -> f64 {
    5.0
}
fn default_stale() -> f64 {
    15.0
}

/// Diesel on/off rule with hysteresis, decided outside the LP.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct CommitmentConfig {
    /// Start a diesel when net load (demand - renewables) exceeds what storage
    /// can cover by this margin, or when SoC falls below `start_soc_frac`.
    #[serde(default = "default_start_soc")]
    pub start_soc_frac: f64,
    /// Stop when SoC is above this and renewables + storage cover the load.
    #[serde(default = "default_stop_soc")]
    pub stop_soc_frac: f64,
    #[serde(default = "default_min_run")]
    pub min_run_s: f64,
    #[serde(default = "default_min_stop")]
    pub min_stop_s: f64,
}

impl Default for CommitmentConfig {
    fn default() -> Self {
        CommitmentConfig {
            start_soc_frac: default_start_soc(),
            stop_soc_frac: default_stop_soc(),
            min_run_s: default_min_run(),
            min_stop_s: default_min_stop(),
        }
    }
}

fn default_start_soc() -> f64 {
    0.25
}
fn default_stop_soc() -> f64 {
    0.6
}
fn default_min_run() -> f64 {
    900.0
}
fn default_min_stop() -> f64 {
    300.0
}

/// One microgrid unit and its controller's tags (under `prefix`, see
/// [`UnitConfig::io`]).
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct UnitConfig {
    pub id: Spanned<String>,
    pub kind: UnitKind,
    pub name: String,
    pub prefix: Spanned<String>,
    /// Nameplate power (PV, wind), kW.
    #[serde(default)]
    pub rated_kw: f64,
    /// Production cost (PV, wind, diesel), per kWh.
    #[serde(default)]
    pub cost_per_kwh: f64,
    /// Diesel: minimum stable load and maximum output, kW.
    #[serde(default)]
    pub min_kw: f64,
    #[serde(default)]
    pub max_kw: f64,
    /// Ramp limit of the unit, kW per second (0 = unlimited).
    #[serde(default)]
    pub ramp_kw_per_s: f64,
    /// Storage.
    #[serde(default)]
    pub capacity_kwh: f64,
    #[serde(default)]
    pub soc_min_kwh: f64,
    #[serde(default)]
    pub soc_max_kwh: f64,
    #[serde(default)]
    pub max_charge_kw: f64,
    #[serde(default)]
    pub max_discharge_kw: f64,
    #[serde(default = "default_eff")]
    pub eff_charge: Spanned<f64>,
    #[serde(default = "default_eff")]
    pub eff_discharge: Spanned<f64>,
    #[serde(default)]
    pub cycle_cost_per_kwh: f64,
    /// PV, wind: daily curve of the power expected to be available, kW, for
    /// the horizon's forecast (absent: the availability now persists).
    #[serde(default)]
    pub forecast_kw: Option<DailyPoints>,
}

fn default_eff() -> Spanned<f64> {
    Spanned::new(0..0, 0.95)
}

/// Names of a unit controller's tags.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct UnitIo {
    /// Power setpoint written by the outer loop, kW (storage: + discharge).
    pub setpoint_kw: String,
    /// Measured active power, kW.
    pub p_kw: String,
    pub voltage_v: String,
    pub current_a: String,
    /// Power the unit could produce now (PV, wind), kW.
    pub available_kw: String,
    /// Stored energy (storage), kWh.
    pub soc_kwh: String,
    /// Running state (diesel), and its start/stop command.
    pub running: String,
    pub run_cmd: String,
}

impl UnitConfig {
    pub fn io(&self) -> UnitIo {
        let p = self.prefix.get_ref();
        UnitIo {
            setpoint_kw: format!("{p}.Setpoint_kW"),
            p_kw: format!("{p}.P_kW"),
            voltage_v: format!("{p}.V"),
            current_a: format!("{p}.I"),
            available_kw: format!("{p}.Available_kW"),
            soc_kwh: format!("{p}.SoC_kWh"),
            running: format!("{p}.Running"),
            run_cmd: format!("{p}.RunCmd"),
        }
    }

    /// The tags this kind of unit must have.
    pub fn required_tags(&self) -> Vec<String> {
        let io = self.io();
        let mut t = vec![io.setpoint_kw, io.p_kw, io.voltage_v, io.current_a];
        match self.kind {
            UnitKind::Pv | UnitKind::Wind => t.push(io.available_kw),
            UnitKind::Storage => t.push(io.soc_kwh),
            UnitKind::Diesel => {
                t.push(io.running);
                t.push(io.run_cmd);
            }
        }
        t
    }
}

fn zero() -> Spanned<f64> {
    Spanned::new(0..0, 0.0)
}
fn no() -> Spanned<bool> {
    Spanned::new(0..0, false)
}
