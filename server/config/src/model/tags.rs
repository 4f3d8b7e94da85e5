//! Tags: `[[tag]]` in the tag files, where each is read (a Modbus register,
//! or an IEC 104 point), data type and byte order, write access, value words
//! (`states`) and device clock.

use serde::{Deserialize, Serialize};
use serde_spanned::Spanned;

use super::*;

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

#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct TagConfig {
    /// Unique hierarchical name, e.g. `SS1.Zone2.Closed`.
    pub name: Spanned<String>,
    #[serde(default)]
    pub description: String,
    /// The device the tag is read from.
    pub device: Spanned<String>,
    /// Modbus table (Modbus devices).
    #[serde(default)]
    pub kind: Option<Spanned<RegisterKind>>,
    /// Zero-based address in that table (Modbus devices).
    #[serde(default)]
    pub address: Option<Spanned<u32>>,
    /// The IEC 104 point (IEC 104 devices). Boxed, as the other optional
    /// sections: a plant of a million tags keeps every tag's configuration,
    /// and inline each tag would pay for every protocol's and the alarms'
    /// room (docs/research/million-tags.md).
    #[serde(default)]
    pub iec104: Option<Box<Iec104TagConfig>>,
    /// The DNP3 point (DNP3 devices).
    #[serde(default)]
    pub dnp3: Option<Box<Dnp3TagConfig>>,
    /// The IEC 61850 data attribute (IEC 61850 devices).
    #[serde(default)]
    pub iec61850: Option<Box<Iec61850TagConfig>>,
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
    /// Decimals the HMI shows the value with (0 to 6), overriding `[hmi]
    /// decimals`; numeric tags only. Read as any integer so that a value
    /// out of range is reported by name (`validate`), not as a type error.
    #[serde(default)]
    pub decimals: Option<Spanned<i64>>,
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
    pub alarm: Option<Box<AlarmConfig>>,
    #[serde(default)]
    pub history: HistoryConfig,
}

impl TagConfig {
    /// The Modbus register: its table and address. `None` for a tag of
    /// another protocol (`check` makes sure a Modbus device's tags have one).
    pub fn register(&self) -> Option<(RegisterKind, u32)> {
        Some((
            *self.kind.as_ref()?.get_ref(),
            *self.address.as_ref()?.get_ref(),
        ))
    }
    /// Whether the tag is one Modbus bit (coil, discrete input, or a bit of a register).
    fn is_bit(&self) -> bool {
        self.kind.as_ref().is_some_and(|k| k.get_ref().is_bit()) || self.bit.is_some()
    }
    /// The wire type, with its default applied.
    pub fn data_type(&self) -> DataType {
        match (&self.data_type, &self.iec104, &self.dnp3) {
            (Some(t), _, _) => *t.get_ref(),
            (None, Some(p), _) => p.point.get_ref().default_type(),
            (None, None, Some(p)) => p.point.get_ref().default_type(),
            (None, None, None) if self.is_bit() => DataType::Bool,
            (None, None, None) => DataType::U16,
        }
    }
    /// Registers (or bits) the tag occupies.
    pub fn width(&self) -> u16 {
        if self.is_bit() {
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
    /// The tag's own `decimals`, if set (and in range: `check` refuses
    /// others).
    pub fn decimals(&self) -> Option<u8> {
        self.decimals
            .as_ref()
            .and_then(|d| u8::try_from(*d.get_ref()).ok())
    }

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

    /// The effective scan period.
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

#[cfg(test)]
mod tests {
    use super::*;

    /// A plant keeps every tag's configuration for the server's life: a
    /// tag pays inline only for what every tag has, and a million tags stay
    /// within a few hundred MiB here (docs/research/million-tags.md).
    #[test]
    fn a_tag_configuration_is_compact() {
        let size = std::mem::size_of::<TagConfig>();
        println!("TagConfig: {size} B inline");
        assert!(
            size <= 700,
            "TagConfig is {size} B inline (1,768 B with its optional sections inline)"
        );
    }
}
