//! IEC 60870-5-104: a device's link settings (`[device.iec104]`) and a tag's
//! point (`iec104 = { ioa = …, point = "M_DP", … }`).
//!
//! Names follow the standard: type identifications without their suffix
//! (`M_DP` covers both `M_DP_NA_1` and the time-tagged `M_DP_TB_1`, since
//! an RTU answers a general interrogation without time tags and reports
//! changes with them), and the APCI timers `t0`..`t3`, `k` and `w`.

use serde::{Deserialize, Serialize};
use serde_spanned::Spanned;

use gridscada_tagdb::ValueKind;

use super::DataType;

/// `[device.iec104]`: one controlled station (RTU) and its link.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Iec104DeviceConfig {
    /// The station's common address of ASDU (1..65534).
    #[serde(default = "default_common_address")]
    pub common_address: Spanned<u16>,
    /// Further `host:port` addresses of the same station: the standard's
    /// redundancy group. One connection is started, the others are kept
    /// tested, and the next one is started when the started one fails.
    #[serde(default)]
    pub redundant_addresses: Vec<Spanned<String>>,
    /// Most I-frames the station may send before we acknowledge (and we
    /// before it does).
    #[serde(default = "default_k")]
    pub k: Spanned<u16>,
    /// Acknowledge at the latest after receiving `w` I-frames.
    #[serde(default = "default_w")]
    pub w: Spanned<u16>,
    /// Connection establishment timeout, seconds.
    #[serde(default = "default_t0")]
    pub t0_s: Spanned<f64>,
    /// Timeout of a sent frame's acknowledgement (or a test frame's
    /// confirmation), seconds; on expiry the connection is closed.
    #[serde(default = "default_t1")]
    pub t1_s: Spanned<f64>,
    /// Acknowledge received I-frames at the latest after this, seconds (< t1).
    #[serde(default = "default_t2")]
    pub t2_s: Spanned<f64>,
    /// Send a test frame after this long without traffic, seconds.
    #[serde(default = "default_t3")]
    pub t3_s: Spanned<f64>,
    /// Period of the general interrogation after the one at every
    /// (re)start, seconds; 0 = only at start.
    #[serde(default = "default_gi_period")]
    pub interrogation_period_s: Spanned<f64>,
    /// Period of the counter interrogation (C_CI), seconds; 0 = never.
    #[serde(default = "never")]
    pub counter_interrogation_period_s: Spanned<f64>,
    /// Period of the clock synchronisation (C_CS), seconds; 0 = never.
    #[serde(default = "never")]
    pub clock_sync_period_s: Spanned<f64>,
    /// Wait for a command's ACT_CON, then for its ACT_TERM (and the
    /// feedback point), seconds.
    #[serde(default = "default_command_timeout")]
    pub command_timeout_s: Spanned<f64>,
    /// Whether the station ends each command with ACT_TERM (most RTUs do;
    /// some end set points at ACT_CON). When false, a positive ACT_CON and
    /// the returned status point confirm the command.
    #[serde(default = "yes")]
    pub command_termination: bool,
}

fn yes() -> bool {
    true
}

impl Default for Iec104DeviceConfig {
    fn default() -> Self {
        Iec104DeviceConfig {
            common_address: default_common_address(),
            redundant_addresses: Vec::new(),
            k: default_k(),
            w: default_w(),
            t0_s: default_t0(),
            t1_s: default_t1(),
            t2_s: default_t2(),
            t3_s: default_t3(),
            interrogation_period_s: default_gi_period(),
            counter_interrogation_period_s: never(),
            clock_sync_period_s: never(),
            command_timeout_s: default_command_timeout(),
            command_termination: true,
        }
    }
}

fn never() -> Spanned<f64> {
    Spanned::new(0..0, 0.0)
}
fn default_common_address() -> Spanned<u16> {
    Spanned::new(0..0, 1)
}
fn default_k() -> Spanned<u16> {
    Spanned::new(0..0, 12)
}
fn default_w() -> Spanned<u16> {
    Spanned::new(0..0, 8)
}
fn default_t0() -> Spanned<f64> {
    Spanned::new(0..0, 30.0)
}
fn default_t1() -> Spanned<f64> {
    Spanned::new(0..0, 15.0)
}
fn default_t2() -> Spanned<f64> {
    Spanned::new(0..0, 10.0)
}
fn default_t3() -> Spanned<f64> {
    Spanned::new(0..0, 20.0)
}
fn default_gi_period() -> Spanned<f64> {
    Spanned::new(0..0, 900.0)
}
fn default_command_timeout() -> Spanned<f64> {
    Spanned::new(0..0, 10.0)
}

/// The monitoring type a tag is read from.
#[allow(non_camel_case_types)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Deserialize, Serialize)]
pub enum Iec104Point {
    /// Single point (M_SP_NA_1, M_SP_TB_1).
    M_SP,
    /// Double point (M_DP_NA_1, M_DP_TB_1): 0 intermediate, 1 off, 2 on,
    /// 3 indeterminate.
    M_DP,
    /// Step position (M_ST_NA_1, M_ST_TB_1): -64..63.
    M_ST,
    /// Bitstring of 32 bits (M_BO_NA_1, M_BO_TB_1).
    M_BO,
    /// Normalized measured value (M_ME_NA_1, M_ME_TD_1, M_ME_ND_1): -1..+1.
    M_ME_NA,
    /// Scaled measured value (M_ME_NB_1, M_ME_TE_1): -32768..32767.
    M_ME_NB,
    /// Short floating point measured value (M_ME_NC_1, M_ME_TF_1).
    M_ME_NC,
    /// Integrated totals (M_IT_NA_1, M_IT_TB_1): a 32-bit counter.
    M_IT,
}

/// The command type a writable tag is commanded with.
#[allow(non_camel_case_types)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Deserialize, Serialize)]
pub enum Iec104Command {
    /// Single command (C_SC_NA_1).
    C_SC,
    /// Double command (C_DC_NA_1): off (1) or on (2).
    C_DC,
    /// Regulating step command (C_RC_NA_1): lower (1) or higher (2).
    C_RC,
    /// Set point, normalized (C_SE_NA_1).
    C_SE_NA,
    /// Set point, scaled (C_SE_NB_1).
    C_SE_NB,
    /// Set point, short floating point (C_SE_NC_1).
    C_SE_NC,
    /// Bitstring of 32 bits (C_BO_NA_1).
    C_BO,
}

impl Iec104Point {
    pub fn label(self) -> &'static str {
        match self {
            Iec104Point::M_SP => "M_SP",
            Iec104Point::M_DP => "M_DP",
            Iec104Point::M_ST => "M_ST",
            Iec104Point::M_BO => "M_BO",
            Iec104Point::M_ME_NA => "M_ME_NA",
            Iec104Point::M_ME_NB => "M_ME_NB",
            Iec104Point::M_ME_NC => "M_ME_NC",
            Iec104Point::M_IT => "M_IT",
        }
    }
    /// The tag type when the tag names none.
    pub fn default_type(self) -> DataType {
        match self {
            Iec104Point::M_SP => DataType::Bool,
            Iec104Point::M_DP => DataType::U16,
            Iec104Point::M_ST => DataType::I16,
            Iec104Point::M_BO => DataType::U32,
            Iec104Point::M_ME_NA | Iec104Point::M_ME_NC => DataType::F32,
            Iec104Point::M_ME_NB => DataType::I16,
            Iec104Point::M_IT => DataType::I32,
        }
    }
    /// Whether the IEC 104 server can send a tag of this engineering kind
    /// as this point (any number as a measurand, a bool or 0..3 as a
    /// double point).
    pub fn exports(self, kind: ValueKind) -> bool {
        match self {
            Iec104Point::M_SP => kind == ValueKind::Bool,
            Iec104Point::M_DP => matches!(kind, ValueKind::Bool | ValueKind::Int),
            Iec104Point::M_ST | Iec104Point::M_BO | Iec104Point::M_IT => kind == ValueKind::Int,
            Iec104Point::M_ME_NA | Iec104Point::M_ME_NB | Iec104Point::M_ME_NC => {
                matches!(kind, ValueKind::Int | ValueKind::Float)
            }
        }
    }

    /// Whether a tag of type `ty` can carry this point's values.
    pub fn carries(self, ty: DataType) -> bool {
        use DataType::*;
        match self {
            Iec104Point::M_SP => ty == Bool,
            // A breaker's position as on/off (intermediate and
            // indeterminate then show as quality), or the four states.
            Iec104Point::M_DP => matches!(ty, Bool | U16 | I16 | U32 | I32 | I64 | U64),
            Iec104Point::M_ST => matches!(ty, I16 | I32 | I64),
            Iec104Point::M_BO => matches!(ty, U32 | U64 | I64),
            Iec104Point::M_ME_NA | Iec104Point::M_ME_NC => matches!(ty, F32 | F64),
            Iec104Point::M_ME_NB => matches!(ty, I16 | I32 | I64 | F32 | F64),
            Iec104Point::M_IT => matches!(ty, I32 | I64 | U32 | U64),
        }
    }
}

impl Iec104Command {
    pub fn label(self) -> &'static str {
        match self {
            Iec104Command::C_SC => "C_SC",
            Iec104Command::C_DC => "C_DC",
            Iec104Command::C_RC => "C_RC",
            Iec104Command::C_SE_NA => "C_SE_NA",
            Iec104Command::C_SE_NB => "C_SE_NB",
            Iec104Command::C_SE_NC => "C_SE_NC",
            Iec104Command::C_BO => "C_BO",
        }
    }
    /// Whether the IEC 104 server can take this command for a tag of this
    /// engineering kind.
    pub fn exports(self, kind: ValueKind) -> bool {
        match self {
            Iec104Command::C_SC => kind == ValueKind::Bool,
            Iec104Command::C_DC => matches!(kind, ValueKind::Bool | ValueKind::Int),
            Iec104Command::C_RC | Iec104Command::C_BO => kind == ValueKind::Int,
            Iec104Command::C_SE_NA | Iec104Command::C_SE_NB | Iec104Command::C_SE_NC => {
                matches!(kind, ValueKind::Int | ValueKind::Float)
            }
        }
    }

    /// Whether a tag of type `ty` can carry this command's value.
    pub fn carries(self, ty: DataType) -> bool {
        use DataType::*;
        match self {
            Iec104Command::C_SC => ty == Bool,
            Iec104Command::C_DC => matches!(ty, Bool | U16 | I16 | U32 | I32 | I64 | U64),
            Iec104Command::C_RC => matches!(ty, I16 | I32 | I64),
            Iec104Command::C_SE_NA | Iec104Command::C_SE_NC => matches!(ty, F32 | F64),
            Iec104Command::C_SE_NB => matches!(ty, I16 | I32 | I64 | F32 | F64),
            Iec104Command::C_BO => matches!(ty, U32 | U64 | I64),
        }
    }
}

/// A tag's IEC 104 point: `iec104 = { ioa = 1001, point = "M_DP" }`, and
/// for a commanded tag `command = "C_DC"`, `command_ioa`, `select`.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Iec104TagConfig {
    /// Information object address of the monitored point (1..16777215).
    pub ioa: Spanned<u32>,
    pub point: Spanned<Iec104Point>,
    /// The command type of a writable tag.
    #[serde(default)]
    pub command: Option<Spanned<Iec104Command>>,
    /// The command's information object address; the monitored one by default.
    #[serde(default)]
    pub command_ioa: Option<Spanned<u32>>,
    /// Select before operate: a select, confirmed, then the execute.
    #[serde(default)]
    pub select: bool,
    /// Qualifier of command (QU) for C_SC/C_DC/C_RC: 0 none, 1 short
    /// pulse, 2 long pulse, 3 persistent; qualifier of set point (QL) for
    /// set points.
    #[serde(default = "no_qualifier")]
    pub qualifier: Spanned<u8>,
}

fn no_qualifier() -> Spanned<u8> {
    Spanned::new(0..0, 0)
}

impl Iec104TagConfig {
    pub fn command_ioa(&self) -> u32 {
        self.command_ioa
            .as_ref()
            .map(|a| *a.get_ref())
            .unwrap_or(*self.ioa.get_ref())
    }
}

/// `[iec104_server]`: gridscada as a controlled station toward a control
/// centre: the tags it exports, answered from the tag database, and the
/// commands it takes, through the same audited write as the HMI's.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Iec104ServerConfig {
    /// Where to listen, e.g. `0.0.0.0:2404`.
    pub listen: Spanned<String>,
    /// The IP addresses of the control centre's front ends allowed to
    /// connect; any other is closed at once (and counted).
    pub allowed_clients: Vec<Spanned<String>>,
    /// Most connections at once (a control centre's redundant front ends).
    #[serde(default = "default_max_connections")]
    pub max_connections: Spanned<u16>,
    /// Our common address of ASDU.
    #[serde(default = "default_common_address")]
    pub common_address: Spanned<u16>,
    #[serde(default = "default_k")]
    pub k: Spanned<u16>,
    #[serde(default = "default_w")]
    pub w: Spanned<u16>,
    #[serde(default = "default_t1")]
    pub t1_s: Spanned<f64>,
    #[serde(default = "default_t2")]
    pub t2_s: Spanned<f64>,
    #[serde(default = "default_t3")]
    pub t3_s: Spanned<f64>,
    /// The role the control centre's commands have: a tag whose
    /// `write_role` is above it cannot be commanded from the centre.
    #[serde(default = "default_command_role")]
    pub command_role: Spanned<super::Role>,
    /// How long a select holds before its execute must come.
    #[serde(default = "default_select_timeout")]
    pub select_timeout_s: Spanned<f64>,
    /// Answer an interrogation with the time-tagged types (M_SP_TB_1 …,
    /// each value with its timestamp), as lib60870 does; `false`: the types
    /// without time tag (M_SP_NA_1 …). Spontaneous data always carries its
    /// time tag.
    #[serde(default = "yes")]
    pub interrogation_time_tags: bool,
    /// The exported points.
    #[serde(default, rename = "point")]
    pub points: Vec<Iec104ExportConfig>,
}

fn default_max_connections() -> Spanned<u16> {
    Spanned::new(0..0, 2)
}
fn default_command_role() -> Spanned<super::Role> {
    Spanned::new(0..0, super::Role::Operator)
}
fn default_select_timeout() -> Spanned<f64> {
    Spanned::new(0..0, 30.0)
}

/// One exported tag: `[[iec104_server.point]]`.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Iec104ExportConfig {
    pub tag: Spanned<String>,
    /// Its information object address.
    pub ioa: Spanned<u32>,
    /// The monitored type it is sent as: spontaneous data with the
    /// CP56Time2a time tag (the TB form), interrogation without.
    pub point: Spanned<Iec104Point>,
    /// A measurand is sent spontaneously only when it moved more than this
    /// (engineering units) from the value last sent.
    #[serde(default = "never")]
    pub deadband: Spanned<f64>,
    /// Also sent every this many seconds with cause periodic; 0: never.
    #[serde(default = "never")]
    pub cyclic_s: Spanned<f64>,
    /// The command the centre may send to the tag (writable tags only).
    #[serde(default)]
    pub command: Option<Spanned<Iec104Command>>,
    /// Where the command comes; the point's `ioa` by default.
    #[serde(default)]
    pub command_ioa: Option<Spanned<u32>>,
    /// The command must be selected before it is executed.
    #[serde(default)]
    pub select: bool,
}

impl Iec104ExportConfig {
    pub fn command_ioa(&self) -> u32 {
        self.command_ioa
            .as_ref()
            .map(|a| *a.get_ref())
            .unwrap_or(*self.ioa.get_ref())
    }
}
