//! DNP3 (IEEE 1815): an outstation's session settings (`[device.dnp3]`) and
//! a tag's point (`dnp3 = { point = "binary_input", index = 3, … }`).
//!
//! Point types are named after the standard's object groups without their
//! variations: `binary_input` covers g1 (static) and g2 (events),
//! `analog_input` g30 and g32, and so on; the master reads whatever
//! variation the outstation sends.

use serde::{Deserialize, Serialize};
use serde_spanned::Spanned;

use super::DataType;

/// `[device.dnp3]`: one outstation and the master's session toward it.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Dnp3DeviceConfig {
    /// Our link address (0..65519).
    #[serde(default = "default_master_address")]
    pub master_address: Spanned<u16>,
    /// The outstation's link address (0..65519).
    #[serde(default = "default_outstation_address")]
    pub outstation_address: Spanned<u16>,
    /// Period of the integrity poll (class 0/1/2/3) after the one at every
    /// connect, seconds; 0 = only at connect.
    #[serde(default = "default_integrity_period")]
    pub integrity_period_s: Spanned<f64>,
    /// Period of the event poll (class 1/2/3), seconds; 0 = none (events
    /// come unsolicited only).
    #[serde(default = "default_event_period")]
    pub event_poll_period_s: Spanned<f64>,
    /// Enable unsolicited responses after the first integrity poll.
    #[serde(default = "yes")]
    pub unsolicited: bool,
    /// How long a response may take, ms.
    #[serde(default = "default_response_timeout")]
    pub response_timeout_ms: Spanned<u64>,
    /// How long an OPERATE may follow its SELECT, seconds.
    #[serde(default = "default_select_timeout")]
    pub select_timeout_s: Spanned<f64>,
    /// Answer the outstation's NEED_TIME (IIN1.4): `lan` (record current
    /// time, then write it) or `none`.
    #[serde(default)]
    pub time_sync: Dnp3TimeSync,
    /// How long a command's returned status point may take to show the
    /// commanded value after the outstation's SUCCESS, seconds.
    #[serde(default = "default_command_timeout")]
    pub command_timeout_s: Spanned<f64>,
}

impl Default for Dnp3DeviceConfig {
    fn default() -> Self {
        Dnp3DeviceConfig {
            master_address: default_master_address(),
            outstation_address: default_outstation_address(),
            integrity_period_s: default_integrity_period(),
            event_poll_period_s: default_event_period(),
            unsolicited: true,
            response_timeout_ms: default_response_timeout(),
            select_timeout_s: default_select_timeout(),
            time_sync: Dnp3TimeSync::Lan,
            command_timeout_s: default_command_timeout(),
        }
    }
}

fn yes() -> bool {
    true
}
fn default_master_address() -> Spanned<u16> {
    Spanned::new(0..0, 1)
}
fn default_outstation_address() -> Spanned<u16> {
    Spanned::new(0..0, 1024)
}
fn default_integrity_period() -> Spanned<f64> {
    Spanned::new(0..0, 3600.0)
}
fn default_event_period() -> Spanned<f64> {
    Spanned::new(0..0, 5.0)
}
fn default_response_timeout() -> Spanned<u64> {
    Spanned::new(0..0, 5000)
}
fn default_select_timeout() -> Spanned<f64> {
    Spanned::new(0..0, 10.0)
}
fn default_command_timeout() -> Spanned<f64> {
    Spanned::new(0..0, 10.0)
}

/// How the outstation's clock is set when it asks.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Dnp3TimeSync {
    /// The LAN procedure: RECORD_CURRENT_TIME, then WRITE g50v3.
    #[default]
    Lan,
    /// Never.
    None,
}

/// The kind of point a tag is read from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Dnp3Point {
    /// Binary input (g1, events g2).
    BinaryInput,
    /// Double-bit binary input (g3, events g4): 0 intermediate, 1 off,
    /// 2 on, 3 indeterminate.
    DoubleBit,
    /// Binary output status (g10, events g11).
    BinaryOutput,
    /// Counter (g20, events g22).
    Counter,
    /// Frozen counter (g21, events g23).
    FrozenCounter,
    /// Analog input (g30, events g32).
    AnalogInput,
    /// Analog output status (g40, events g42).
    AnalogOutput,
}

impl Dnp3Point {
    pub fn label(self) -> &'static str {
        match self {
            Dnp3Point::BinaryInput => "binary_input",
            Dnp3Point::DoubleBit => "double_bit",
            Dnp3Point::BinaryOutput => "binary_output",
            Dnp3Point::Counter => "counter",
            Dnp3Point::FrozenCounter => "frozen_counter",
            Dnp3Point::AnalogInput => "analog_input",
            Dnp3Point::AnalogOutput => "analog_output",
        }
    }
    /// The tag type when the tag names none.
    pub fn default_type(self) -> DataType {
        match self {
            Dnp3Point::BinaryInput | Dnp3Point::BinaryOutput => DataType::Bool,
            Dnp3Point::DoubleBit => DataType::U16,
            Dnp3Point::Counter | Dnp3Point::FrozenCounter => DataType::U32,
            Dnp3Point::AnalogInput | Dnp3Point::AnalogOutput => DataType::F64,
        }
    }
    /// Whether a tag of type `ty` can carry this point's values.
    pub fn carries(self, ty: DataType) -> bool {
        use DataType::*;
        match self {
            Dnp3Point::BinaryInput | Dnp3Point::BinaryOutput => ty == Bool,
            // A breaker's position as on/off (intermediate and
            // indeterminate then show as quality), or the four states.
            Dnp3Point::DoubleBit => matches!(ty, Bool | U16 | I16 | U32 | I32 | I64 | U64),
            Dnp3Point::Counter | Dnp3Point::FrozenCounter => matches!(ty, U32 | I64 | U64),
            Dnp3Point::AnalogInput | Dnp3Point::AnalogOutput => {
                matches!(ty, I16 | U16 | I32 | U32 | I64 | F32 | F64)
            }
        }
    }
}

/// The command a writable tag is operated with.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Dnp3Command {
    /// Control relay output block (g12v1) on a binary output.
    Crob,
    /// Analog output block (g41) on an analog output.
    AnalogOutput,
}

impl Dnp3Command {
    pub fn label(self) -> &'static str {
        match self {
            Dnp3Command::Crob => "crob",
            Dnp3Command::AnalogOutput => "analog_output",
        }
    }
    /// Whether a tag of type `ty` can carry this command's value.
    pub fn carries(self, ty: DataType) -> bool {
        use DataType::*;
        match self {
            Dnp3Command::Crob => ty == Bool,
            Dnp3Command::AnalogOutput => matches!(ty, I16 | U16 | I32 | U32 | I64 | F32 | F64),
        }
    }
}

/// What a CROB does with true and false.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Dnp3Op {
    /// LATCH_ON for true, LATCH_OFF for false.
    #[default]
    Latch,
    /// PULSE_ON for true, PULSE_OFF for false, `on_ms`/`off_ms` long.
    Pulse,
    /// A pulse with the trip-close code: CLOSE for true, TRIP for false.
    TripClose,
}

impl Dnp3Op {
    pub fn label(self) -> &'static str {
        match self {
            Dnp3Op::Latch => "latch",
            Dnp3Op::Pulse => "pulse",
            Dnp3Op::TripClose => "trip_close",
        }
    }
}

/// A tag's DNP3 point: `dnp3 = { point = "binary_input", index = 3 }`, and
/// for a commanded tag `command = "crob"`, `command_index`, `select`, `op`,
/// `on_ms`, `off_ms`.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Dnp3TagConfig {
    pub point: Spanned<Dnp3Point>,
    /// The point's index (0..65535).
    pub index: Spanned<u16>,
    /// The command of a writable tag.
    #[serde(default)]
    pub command: Option<Spanned<Dnp3Command>>,
    /// The command's index; the point's by default.
    #[serde(default)]
    pub command_index: Option<Spanned<u16>>,
    /// Select before operate; direct operate when false.
    #[serde(default)]
    pub select: bool,
    /// What a CROB does (crob only).
    #[serde(default)]
    pub op: Option<Spanned<Dnp3Op>>,
    /// Pulse on time, ms (pulse and trip_close only; default 1000).
    #[serde(default)]
    pub on_ms: Option<Spanned<u32>>,
    /// Pulse off time, ms (pulse only; default 0).
    #[serde(default)]
    pub off_ms: Option<Spanned<u32>>,
}

impl Dnp3TagConfig {
    pub fn command_index(&self) -> u16 {
        self.command_index
            .as_ref()
            .map(|a| *a.get_ref())
            .unwrap_or(*self.index.get_ref())
    }
    pub fn op(&self) -> Dnp3Op {
        self.op.as_ref().map(|o| *o.get_ref()).unwrap_or_default()
    }
    pub fn on_ms(&self) -> u32 {
        self.on_ms.as_ref().map(|o| *o.get_ref()).unwrap_or(1000)
    }
    pub fn off_ms(&self) -> u32 {
        self.off_ms.as_ref().map(|o| *o.get_ref()).unwrap_or(0)
    }
}
