//! DNP3 objects (IEEE 1815-2012 clause 11 and annex A): the data an
//! outstation sends, read into one flat list of [`Measurement`]s, and the
//! command objects (g12v1 CROB, g41v1..v4 analog outputs) with their
//! status codes, both ways.
//!
//! [`parse`] walks the object headers of a response fragment. Every object
//! size is checked against the octets present before anything is read or
//! allocated; an object of unknown size ends the walk with an error that
//! names the octet, group, variation and index, and everything read before
//! it is kept. Objects of a known size that a SCADA master does not use
//! are skipped with a note.

use thiserror::Error;

use crate::app::{AppError, ObjectHeader, Range};

/// What a measurement is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum MeasurementKind {
    Binary,
    DoubleBit,
    BinaryOutputStatus,
    Counter,
    FrozenCounter,
    Analog,
    AnalogOutputStatus,
}

/// A double-bit binary's state.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum DoubleBit {
    /// 00: between positions (a breaker moving).
    Intermediate,
    /// 01: determined off (open).
    Off,
    /// 10: determined on (closed).
    On,
    /// 11: indeterminate (bad data, not a state).
    Indeterminate,
}

impl DoubleBit {
    pub fn from_bits(b: u8) -> DoubleBit {
        match b & 0x03 {
            0 => DoubleBit::Intermediate,
            1 => DoubleBit::Off,
            2 => DoubleBit::On,
            _ => DoubleBit::Indeterminate,
        }
    }
}

/// A measurement's value.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Value {
    Binary(bool),
    DoubleBit(DoubleBit),
    Counter(i64),
    Analog(f64),
}

/// A point's flags, one bit per meaning whatever the group: the octet's
/// bits 5 and 6 mean chatter filter (binaries), rollover and discontinuity
/// (counters), or over-range and reference error (analogs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct Flags(pub u16);

impl Flags {
    pub const ONLINE: Flags = Flags(1 << 0);
    pub const RESTART: Flags = Flags(1 << 1);
    pub const COMM_LOST: Flags = Flags(1 << 2);
    pub const REMOTE_FORCED: Flags = Flags(1 << 3);
    pub const LOCAL_FORCED: Flags = Flags(1 << 4);
    pub const CHATTER_FILTER: Flags = Flags(1 << 5);
    pub const OVER_RANGE: Flags = Flags(1 << 6);
    pub const REFERENCE_ERR: Flags = Flags(1 << 7);
    pub const ROLLOVER: Flags = Flags(1 << 8);
    pub const DISCONTINUITY: Flags = Flags(1 << 9);

    const WORDS: [(Flags, &'static str); 10] = [
        (Flags::ONLINE, "online"),
        (Flags::RESTART, "restart"),
        (Flags::COMM_LOST, "communication lost"),
        (Flags::REMOTE_FORCED, "remote forced"),
        (Flags::LOCAL_FORCED, "local forced"),
        (Flags::CHATTER_FILTER, "chatter filter"),
        (Flags::OVER_RANGE, "over range"),
        (Flags::REFERENCE_ERR, "reference error"),
        (Flags::ROLLOVER, "rollover"),
        (Flags::DISCONTINUITY, "discontinuity"),
    ];

    /// The flags of a flags octet for a kind of point.
    pub fn from_octet(kind: MeasurementKind, b: u8) -> Flags {
        let mut f = u16::from(b & 0x1F);
        let bit5 = b & 0x20 != 0;
        let bit6 = b & 0x40 != 0;
        match kind {
            MeasurementKind::Binary | MeasurementKind::DoubleBit => {
                if bit5 {
                    f |= Flags::CHATTER_FILTER.0;
                }
            }
            MeasurementKind::BinaryOutputStatus => {}
            MeasurementKind::Counter | MeasurementKind::FrozenCounter => {
                if bit5 {
                    f |= Flags::ROLLOVER.0;
                }
                if bit6 {
                    f |= Flags::DISCONTINUITY.0;
                }
            }
            MeasurementKind::Analog | MeasurementKind::AnalogOutputStatus => {
                if bit5 {
                    f |= Flags::OVER_RANGE.0;
                }
                if bit6 {
                    f |= Flags::REFERENCE_ERR.0;
                }
            }
        }
        Flags(f)
    }

    pub fn contains(self, other: Flags) -> bool {
        self.0 & other.0 == other.0
    }

    /// The flags in words, e.g. "online, local forced"; "offline" when the
    /// online flag is clear.
    pub fn describe(self) -> String {
        let mut words: Vec<&str> = Vec::new();
        if !self.contains(Flags::ONLINE) {
            words.push("offline");
        }
        words.extend(
            Self::WORDS
                .iter()
                .filter(|(f, _)| self.contains(*f))
                .map(|(_, w)| *w),
        );
        words.join(", ")
    }

    /// Good, uncertain or bad, with the reason in words. Online and nothing
    /// else is good; offline, communication lost or a reference error is
    /// bad; forced, over-range, restart, chatter, rollover or
    /// discontinuity is uncertain.
    pub fn quality(self) -> (Quality, String) {
        let pick = |set: &[Flags]| -> Vec<&'static str> {
            Self::WORDS
                .iter()
                .filter(|(f, _)| set.contains(f) && self.contains(*f))
                .map(|(_, w)| *w)
                .collect()
        };
        let mut bad = Vec::new();
        if !self.contains(Flags::ONLINE) {
            bad.push("offline");
        }
        bad.extend(pick(&[Flags::COMM_LOST, Flags::REFERENCE_ERR]));
        let uncertain = pick(&[
            Flags::RESTART,
            Flags::REMOTE_FORCED,
            Flags::LOCAL_FORCED,
            Flags::CHATTER_FILTER,
            Flags::OVER_RANGE,
            Flags::ROLLOVER,
            Flags::DISCONTINUITY,
        ]);
        if !bad.is_empty() {
            bad.extend(uncertain);
            (Quality::Bad, bad.join(", "))
        } else if !uncertain.is_empty() {
            (Quality::Uncertain, uncertain.join(", "))
        } else {
            (Quality::Good, "online".to_string())
        }
    }
}

impl std::ops::BitOr for Flags {
    type Output = Flags;
    fn bitor(self, rhs: Flags) -> Flags {
        Flags(self.0 | rhs.0)
    }
}

/// A measurement's quality class.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Quality {
    Good,
    Uncertain,
    Bad,
}

/// One point's value from a response.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Measurement {
    pub kind: MeasurementKind,
    pub index: u16,
    pub value: Value,
    pub flags: Flags,
    /// The device's time stamp, ms since 1970-01-01 UTC.
    pub time: Option<u64>,
    /// From an event object (a change), not a static one (a snapshot).
    pub is_event: bool,
}

macro_rules! statuses {
    ($($name:ident = $code:literal, $text:literal;)*) => {
        /// A command's status code (the CROB's and analog output's status octet).
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
        pub enum CommandStatus {
            $($name,)*
            /// A code the standard reserves.
            Reserved(u8),
        }

        impl CommandStatus {
            pub fn from_code(code: u8) -> CommandStatus {
                match code & 0x7F {
                    $($code => CommandStatus::$name,)*
                    c => CommandStatus::Reserved(c),
                }
            }

            pub fn code(self) -> u8 {
                match self {
                    $(CommandStatus::$name => $code,)*
                    CommandStatus::Reserved(c) => c,
                }
            }

            /// The standard's name, e.g. "NO_SELECT".
            pub fn name(self) -> &'static str {
                match self {
                    $(CommandStatus::$name => $text,)*
                    CommandStatus::Reserved(_) => "RESERVED",
                }
            }
        }
    };
}

statuses! {
    Success = 0, "SUCCESS";
    Timeout = 1, "TIMEOUT";
    NoSelect = 2, "NO_SELECT";
    FormatError = 3, "FORMAT_ERROR";
    NotSupported = 4, "NOT_SUPPORTED";
    AlreadyActive = 5, "ALREADY_ACTIVE";
    HardwareError = 6, "HARDWARE_ERROR";
    Local = 7, "LOCAL";
    TooManyObjs = 8, "TOO_MANY_OBJS";
    NotAuthorized = 9, "NOT_AUTHORIZED";
    AutomationInhibit = 10, "AUTOMATION_INHIBIT";
    ProcessingLimited = 11, "PROCESSING_LIMITED";
    OutOfRange = 12, "OUT_OF_RANGE";
    DownstreamLocal = 13, "DOWNSTREAM_LOCAL";
    AlreadyComplete = 14, "ALREADY_COMPLETE";
    Blocked = 15, "BLOCKED";
    Canceled = 16, "CANCELED";
    BlockedOtherMaster = 17, "BLOCKED_OTHER_MASTER";
    DownstreamFail = 18, "DOWNSTREAM_FAIL";
    NonParticipating = 126, "NON_PARTICIPATING";
    Undefined = 127, "UNDEFINED";
}

impl std::fmt::Display for CommandStatus {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} ({})", self.name(), self.code())
    }
}

/// The CROB's operation type (control code bits 0-3).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum OpType {
    Nul = 0,
    PulseOn = 1,
    PulseOff = 2,
    LatchOn = 3,
    LatchOff = 4,
}

/// The CROB's trip-close code (control code bits 6-7).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum TripClose {
    Nul = 0,
    Close = 1,
    Trip = 2,
}

/// A control relay output block (g12v1) without its status octet. `code`
/// is the whole control code octet, so an echo compares exactly.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Crob {
    pub code: u8,
    pub count: u8,
    pub on_time_ms: u32,
    pub off_time_ms: u32,
}

impl Crob {
    pub const LEN: usize = 11;

    /// An operation with a trip-close code, count 1, no times.
    pub fn new(op: OpType, tcc: TripClose) -> Crob {
        Crob {
            code: (op as u8) | ((tcc as u8) << 6),
            count: 1,
            on_time_ms: 0,
            off_time_ms: 0,
        }
    }

    pub fn latch(on: bool) -> Crob {
        Crob::new(
            if on {
                OpType::LatchOn
            } else {
                OpType::LatchOff
            },
            TripClose::Nul,
        )
    }

    pub fn pulse(on: bool, count: u8, on_time_ms: u32, off_time_ms: u32) -> Crob {
        Crob {
            count,
            on_time_ms,
            off_time_ms,
            ..Crob::new(
                if on {
                    OpType::PulseOn
                } else {
                    OpType::PulseOff
                },
                TripClose::Nul,
            )
        }
    }

    /// Close or trip (a pulse with the trip-close code).
    pub fn trip_close(close: bool, on_time_ms: u32) -> Crob {
        Crob {
            on_time_ms,
            ..Crob::new(
                OpType::PulseOn,
                if close {
                    TripClose::Close
                } else {
                    TripClose::Trip
                },
            )
        }
    }
}

/// An analog output block (g41v1..v4) without its status octet.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum AnalogOutput {
    I32(i32),
    I16(i16),
    F32(f32),
    F64(f64),
}

impl AnalogOutput {
    pub fn variation(self) -> u8 {
        match self {
            AnalogOutput::I32(_) => 1,
            AnalogOutput::I16(_) => 2,
            AnalogOutput::F32(_) => 3,
            AnalogOutput::F64(_) => 4,
        }
    }
}

/// A command object, as requested or as echoed (status aside).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum CommandObject {
    Crob(Crob),
    Analog(AnalogOutput),
}

impl CommandObject {
    pub fn group_variation(self) -> (u8, u8) {
        match self {
            CommandObject::Crob(_) => (12, 1),
            CommandObject::Analog(a) => (41, a.variation()),
        }
    }

    /// The object's octets with a status octet.
    pub fn encode(self, status: CommandStatus, out: &mut Vec<u8>) {
        match self {
            CommandObject::Crob(c) => {
                out.extend_from_slice(&[c.code, c.count]);
                out.extend_from_slice(&c.on_time_ms.to_le_bytes());
                out.extend_from_slice(&c.off_time_ms.to_le_bytes());
            }
            CommandObject::Analog(AnalogOutput::I32(v)) => out.extend_from_slice(&v.to_le_bytes()),
            CommandObject::Analog(AnalogOutput::I16(v)) => out.extend_from_slice(&v.to_le_bytes()),
            CommandObject::Analog(AnalogOutput::F32(v)) => out.extend_from_slice(&v.to_le_bytes()),
            CommandObject::Analog(AnalogOutput::F64(v)) => out.extend_from_slice(&v.to_le_bytes()),
        }
        out.push(status.code());
    }
}

/// A command object echoed in a response, with its status.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CommandEcho {
    pub index: u16,
    pub object: CommandObject,
    pub status: CommandStatus,
}

/// Why the walk over a fragment's objects stopped.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum ObjectError {
    #[error(transparent)]
    Header(#[from] AppError),
    #[error("g{group}v{variation} of unknown size at octet {offset}: the rest of the fragment is not read")]
    UnknownSize {
        group: u8,
        variation: u8,
        offset: usize,
    },
    #[error("g{group}v{variation} (object {object}, index {index}) needs {need} octets at octet {offset}, {have} left")]
    Truncated {
        group: u8,
        variation: u8,
        object: usize,
        index: u16,
        need: usize,
        have: usize,
        offset: usize,
    },
    #[error("g{group}v{variation} with qualifier 0x{qualifier:02X} at octet {offset}: packed objects need a start-stop range")]
    PackedWithoutRange {
        group: u8,
        variation: u8,
        qualifier: u8,
        offset: usize,
    },
}

/// Everything read from a fragment's objects.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Objects {
    pub measurements: Vec<Measurement>,
    pub commands: Vec<CommandEcho>,
    /// g80v1: (IIN bit index, value).
    pub iin_bits: Vec<(u16, bool)>,
    /// g50v1 (or v3): the device's time, ms since 1970.
    pub time: Option<u64>,
    /// g52v1/v2: the outstation's processing delay, ms.
    pub delay_ms: Option<u32>,
    /// Objects skipped (known size, not used) and other remarks, located.
    pub notes: Vec<String>,
    /// Why the walk stopped early, if it did.
    pub error: Option<ObjectError>,
}

#[derive(Clone, Copy)]
enum Size {
    Fixed(usize),
    /// Packed: this many bits per object.
    Packed(usize),
}

/// The size of one object, when known.
fn size(group: u8, variation: u8) -> Option<Size> {
    use Size::*;
    Some(match (group, variation) {
        (1, 1) | (10, 1) | (80, 1) => Packed(1),
        (3, 1) => Packed(2),
        (1, 2) | (2, 1) | (3, 2) | (4, 1) | (10, 2) => Fixed(1),
        (2, 2) | (4, 2) => Fixed(7),
        (2, 3) | (4, 3) => Fixed(3),
        (11, 1) | (13, 1) => Fixed(1),
        (11, 2) | (13, 2) => Fixed(7),
        (12, 1) => Fixed(Crob::LEN),
        (20..=23, 1) => Fixed(5),
        (20..=23, 2) => Fixed(3),
        (20, 5) | (21, 9) => Fixed(4),
        (20, 6) | (21, 10) => Fixed(2),
        (21..=23, 5) => Fixed(11),
        (21..=23, 6) => Fixed(9),
        (30, 1) | (30, 5) | (32, 1) | (32, 5) | (40, 1) | (40, 3) | (42, 1) | (42, 5) => Fixed(5),
        (30, 2) | (32, 2) | (40, 2) | (42, 2) => Fixed(3),
        (30, 3) => Fixed(4),
        (30, 4) => Fixed(2),
        (30, 6) | (32, 6) | (40, 4) | (42, 6) => Fixed(9),
        (32, 3) | (32, 7) | (42, 3) | (42, 7) => Fixed(11),
        (32, 4) | (42, 4) => Fixed(9),
        (32, 8) | (42, 8) => Fixed(15),
        (34, 1) => Fixed(2),
        (34, 2) | (34, 3) => Fixed(4),
        (41, 1) | (41, 3) => Fixed(5),
        (41, 2) => Fixed(3),
        (41, 4) => Fixed(9),
        (50, 1) | (50, 3) | (51, 1) | (51, 2) => Fixed(6),
        (50, 4) => Fixed(11),
        (52, 1) | (52, 2) => Fixed(2),
        _ => return None,
    })
}

fn u16_at(b: &[u8], at: usize) -> u16 {
    u16::from_le_bytes([b[at], b[at + 1]])
}
fn u32_at(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]])
}
fn time48_at(b: &[u8], at: usize) -> u64 {
    let mut t = [0u8; 8];
    t[..6].copy_from_slice(&b[at..at + 6]);
    u64::from_le_bytes(t)
}
fn f32_at(b: &[u8], at: usize) -> f64 {
    f64::from(f32::from_bits(u32_at(b, at)))
}
fn f64_at(b: &[u8], at: usize) -> f64 {
    let mut t = [0u8; 8];
    t.copy_from_slice(&b[at..at + 8]);
    f64::from_le_bytes(t)
}

/// A 48-bit DNP3 time (ms since 1970) as six octets.
pub fn time48(ms: u64) -> [u8; 6] {
    let b = ms.to_le_bytes();
    [b[0], b[1], b[2], b[3], b[4], b[5]]
}

/// Walk the objects of a response: `objects` is the fragment after its
/// header, `base` the octet offset of `objects[0]` in the fragment (4 for
/// a response), used in every error and note.
pub fn parse(objects: &[u8], base: usize) -> Objects {
    let mut out = Objects::default();
    let mut cto: Option<u64> = None;
    let mut at = 0;
    while at < objects.len() {
        let (h, hlen) = match ObjectHeader::decode(objects, at) {
            Ok(h) => h,
            Err(e) => {
                out.error = Some(ObjectError::Header(shift(e, base)));
                return out;
            }
        };
        let (g, v) = (h.group, h.variation);
        let header_at = base + at;
        at += hlen;
        if h.range == Range::All {
            out.notes.push(format!(
                "g{g}v{v} with qualifier 0x06 at octet {header_at} carries no objects"
            ));
            continue;
        }
        let Some(sz) = size(g, v) else {
            out.error = Some(ObjectError::UnknownSize {
                group: g,
                variation: v,
                offset: header_at,
            });
            return out;
        };
        let count = h.range.count();
        match sz {
            Size::Packed(bits) => {
                let Some(start) = h.range.start() else {
                    out.error = Some(ObjectError::PackedWithoutRange {
                        group: g,
                        variation: v,
                        qualifier: h.range.qualifier(),
                        offset: header_at,
                    });
                    return out;
                };
                let need = (count * bits).div_ceil(8);
                let have = objects.len() - at;
                if need > have {
                    out.error = Some(ObjectError::Truncated {
                        group: g,
                        variation: v,
                        object: 0,
                        index: start,
                        need,
                        have,
                        offset: base + at,
                    });
                    return out;
                }
                let data = &objects[at..at + need];
                for i in 0..count {
                    let bit = i * bits;
                    let raw = (data[bit / 8] >> (bit % 8)) & if bits == 1 { 1 } else { 3 };
                    // i < count <= stop - start + 1, so this fits.
                    let index = start.wrapping_add(i as u16);
                    let (kind, value) = match g {
                        1 => (MeasurementKind::Binary, Value::Binary(raw != 0)),
                        10 => (MeasurementKind::BinaryOutputStatus, Value::Binary(raw != 0)),
                        3 => (
                            MeasurementKind::DoubleBit,
                            Value::DoubleBit(DoubleBit::from_bits(raw)),
                        ),
                        _ => {
                            out.iin_bits.push((index, raw != 0));
                            continue;
                        }
                    };
                    out.measurements.push(Measurement {
                        kind,
                        index,
                        value,
                        flags: Flags::ONLINE,
                        time: None,
                        is_event: false,
                    });
                }
                at += need;
            }
            Size::Fixed(n) => {
                let per = n + h.range.prefix_len();
                for i in 0..count {
                    let have = objects.len() - at;
                    let index = match h.range {
                        Range::Indexed8(_) if have >= 1 => u16::from(objects[at]),
                        Range::Indexed16(_) if have >= 2 => u16_at(objects, at),
                        _ => h
                            .range
                            .start()
                            .unwrap_or(0)
                            .wrapping_add(i.min(usize::from(u16::MAX)) as u16),
                    };
                    if per > have {
                        out.error = Some(ObjectError::Truncated {
                            group: g,
                            variation: v,
                            object: i,
                            index,
                            need: per,
                            have,
                            offset: base + at,
                        });
                        return out;
                    }
                    let o = &objects[at + h.range.prefix_len()..at + per];
                    let offset = base + at;
                    at += per;
                    object(g, v, index, o, offset, &mut cto, &mut out);
                }
            }
        }
    }
    out
}

/// Errors of a header decoded from a slice starting at `base`.
fn shift(e: AppError, base: usize) -> AppError {
    match e {
        AppError::Truncated { what, offset } => AppError::Truncated {
            what,
            offset: offset + base,
        },
        AppError::Qualifier {
            qualifier,
            group,
            variation,
            offset,
        } => AppError::Qualifier {
            qualifier,
            group,
            variation,
            offset: offset + base,
        },
        AppError::BadRange {
            group,
            variation,
            start,
            stop,
            offset,
        } => AppError::BadRange {
            group,
            variation,
            start,
            stop,
            offset: offset + base,
        },
        other => other,
    }
}

/// One fixed-size object `o` (its size already checked).
fn object(
    g: u8,
    v: u8,
    index: u16,
    o: &[u8],
    offset: usize,
    cto: &mut Option<u64>,
    out: &mut Objects,
) {
    use MeasurementKind as K;
    let m = |kind, value, flags_octet: Option<u8>, time, is_event| Measurement {
        kind,
        index,
        value,
        flags: flags_octet.map_or(Flags::ONLINE, |b| Flags::from_octet(kind, b)),
        time,
        is_event,
    };
    let relative = |cto: &Option<u64>, out: &mut Objects| match cto {
        Some(t) => Some(t + u64::from(u16_at(o, 1))),
        None => {
            out.notes.push(format!(
                "g{g}v{v} index {index} at octet {offset} has a relative time but no g51 CTO precedes it: time unknown"
            ));
            None
        }
    };
    let meas = match (g, v) {
        (1, 2) => m(
            K::Binary,
            Value::Binary(o[0] & 0x80 != 0),
            Some(o[0]),
            None,
            false,
        ),
        (2, 1) => m(
            K::Binary,
            Value::Binary(o[0] & 0x80 != 0),
            Some(o[0]),
            None,
            true,
        ),
        (2, 2) => m(
            K::Binary,
            Value::Binary(o[0] & 0x80 != 0),
            Some(o[0]),
            Some(time48_at(o, 1)),
            true,
        ),
        (2, 3) => {
            let t = relative(cto, out);
            m(
                K::Binary,
                Value::Binary(o[0] & 0x80 != 0),
                Some(o[0]),
                t,
                true,
            )
        }
        (3, 2) | (4, 1) | (4, 2) | (4, 3) => {
            let value = Value::DoubleBit(DoubleBit::from_bits(o[0] >> 6));
            let time = match v {
                2 if g == 4 => Some(time48_at(o, 1)),
                3 => relative(cto, out),
                _ => None,
            };
            m(K::DoubleBit, value, Some(o[0]), time, g == 4)
        }
        (10, 2) | (11, 1) | (11, 2) => m(
            K::BinaryOutputStatus,
            Value::Binary(o[0] & 0x80 != 0),
            Some(o[0]),
            (g == 11 && v == 2).then(|| time48_at(o, 1)),
            g == 11,
        ),
        (20..=23, _) => {
            let kind = if g == 21 || g == 23 {
                K::FrozenCounter
            } else {
                K::Counter
            };
            let is_event = g == 22 || g == 23;
            let (flags, value, time) = match v {
                1 => (Some(o[0]), u32_at(o, 1), None),
                2 => (Some(o[0]), u32::from(u16_at(o, 1)), None),
                5 if g == 20 => (None, u32_at(o, 0), None),
                6 if g == 20 => (None, u32::from(u16_at(o, 0)), None),
                5 => (Some(o[0]), u32_at(o, 1), Some(time48_at(o, 5))),
                6 => (Some(o[0]), u32::from(u16_at(o, 1)), Some(time48_at(o, 3))),
                9 => (None, u32_at(o, 0), None),
                _ => (None, u32::from(u16_at(o, 0)), None),
            };
            m(
                kind,
                Value::Counter(i64::from(value)),
                flags,
                time,
                is_event,
            )
        }
        (30 | 32 | 40 | 42, _) => {
            let kind = if g == 40 || g == 42 {
                K::AnalogOutputStatus
            } else {
                K::Analog
            };
            let i32v = |at| f64::from(u32_at(o, at) as i32);
            let i16v = |at| f64::from(u16_at(o, at) as i16);
            let (flags, value, time) = match (g, v) {
                (30, 1) | (32 | 42, 1) | (40, 1) => (Some(o[0]), i32v(1), None),
                (30, 2) | (32 | 42, 2) | (40, 2) => (Some(o[0]), i16v(1), None),
                (30, 3) => (None, i32v(0), None),
                (30, 4) => (None, i16v(0), None),
                (30, 5) | (32 | 42, 5) | (40, 3) => (Some(o[0]), f32_at(o, 1), None),
                (30, 6) | (32 | 42, 6) | (40, 4) => (Some(o[0]), f64_at(o, 1), None),
                (32 | 42, 3) => (Some(o[0]), i32v(1), Some(time48_at(o, 5))),
                (32 | 42, 4) => (Some(o[0]), i16v(1), Some(time48_at(o, 3))),
                (32 | 42, 7) => (Some(o[0]), f32_at(o, 1), Some(time48_at(o, 5))),
                _ => (Some(o[0]), f64_at(o, 1), Some(time48_at(o, 9))),
            };
            m(kind, Value::Analog(value), flags, time, g == 32 || g == 42)
        }
        (12, 1) => {
            out.commands.push(CommandEcho {
                index,
                object: CommandObject::Crob(Crob {
                    code: o[0],
                    count: o[1],
                    on_time_ms: u32_at(o, 2),
                    off_time_ms: u32_at(o, 6),
                }),
                status: CommandStatus::from_code(o[10]),
            });
            return;
        }
        (41, _) => {
            let (value, status) = match v {
                1 => (AnalogOutput::I32(u32_at(o, 0) as i32), o[4]),
                2 => (AnalogOutput::I16(u16_at(o, 0) as i16), o[2]),
                3 => (AnalogOutput::F32(f32::from_bits(u32_at(o, 0))), o[4]),
                _ => {
                    let mut t = [0u8; 8];
                    t.copy_from_slice(&o[..8]);
                    (AnalogOutput::F64(f64::from_le_bytes(t)), o[8])
                }
            };
            out.commands.push(CommandEcho {
                index,
                object: CommandObject::Analog(value),
                status: CommandStatus::from_code(status),
            });
            return;
        }
        (50, 1) | (50, 3) => {
            out.time = Some(time48_at(o, 0));
            return;
        }
        (51, _) => {
            *cto = Some(time48_at(o, 0));
            if v == 2 {
                out.notes.push(format!(
                    "g51v2 at octet {offset}: the common time of occurrence is unsynchronised"
                ));
            }
            return;
        }
        (52, 1) => {
            out.delay_ms = Some(u32::from(u16_at(o, 0)) * 1000);
            return;
        }
        (52, 2) => {
            out.delay_ms = Some(u32::from(u16_at(o, 0)));
            return;
        }
        _ => {
            out.notes.push(format!(
                "g{g}v{v} index {index} at octet {offset} skipped (not used by the master)"
            ));
            return;
        }
    };
    out.measurements.push(meas);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::app::ResponseHeader;
    use crate::test_util::hex;

    fn objects_of(fragment: &[u8]) -> Objects {
        ResponseHeader::decode(fragment).unwrap();
        parse(&fragment[4..], 4)
    }

    #[test]
    fn class0_response_with_g1v2_g30v1_g20v1() {
        // RESPONSE, FIR FIN seq 1, IIN none.
        // g1v2 0x00 start 0 stop 2: online+0, online+1, comm lost
        // g30v1 0x01 start 0 stop 1: 1234 online, -5 over range
        // g20v1 0x00 start 5 stop 5: 100000 online
        let f = hex("C1 81 00 00 \
             01 02 00 00 02 01 81 05 \
             1E 01 01 00 00 01 00 01 D2 04 00 00 21 FB FF FF FF \
             14 01 00 05 05 01 A0 86 01 00");
        let o = objects_of(&f);
        assert_eq!(o.error, None);
        assert!(o.notes.is_empty());
        let m = &o.measurements;
        assert_eq!(m.len(), 6);
        assert_eq!(m[0].value, Value::Binary(false));
        assert_eq!(m[1].value, Value::Binary(true));
        assert_eq!(m[1].flags.quality().0, Quality::Good);
        assert_eq!(m[2].index, 2);
        assert_eq!(m[2].flags, Flags::ONLINE | Flags::COMM_LOST);
        assert_eq!(
            m[2].flags.quality(),
            (Quality::Bad, "communication lost".to_string())
        );
        assert_eq!(m[3].kind, MeasurementKind::Analog);
        assert_eq!(m[3].value, Value::Analog(1234.0));
        assert_eq!(m[4].value, Value::Analog(-5.0));
        assert_eq!(m[4].flags, Flags::ONLINE | Flags::OVER_RANGE);
        assert_eq!(
            m[4].flags.quality(),
            (Quality::Uncertain, "over range".to_string())
        );
        assert_eq!(m[5].kind, MeasurementKind::Counter);
        assert_eq!(m[5].index, 5);
        assert_eq!(m[5].value, Value::Counter(100_000));
        assert!(m.iter().all(|m| !m.is_event && m.time.is_none()));
    }

    #[test]
    fn events_with_time_and_cto() {
        // Unsolicited: g51v1 CTO 1_000_000 ms; g2v3 count 2 prefix 1 octet:
        // index 3 on +5 ms, index 4 off +10 ms; g32v3 index 7 with time;
        // g4v2 index 1 on with time; g22v5 index 2.
        let t = 1_700_000_000_123u64;
        let tb = time48(t);
        let tb = tb
            .iter()
            .map(|b| format!("{b:02X}"))
            .collect::<Vec<_>>()
            .join(" ");
        let f = hex(&format!(
            "F0 82 00 00 \
             33 01 07 01 40 42 0F 00 00 00 \
             02 03 17 02 03 81 05 00 04 01 0A 00 \
             20 03 28 01 00 07 00 01 10 00 00 00 {tb} \
             04 02 17 01 01 81 {tb} \
             16 05 17 01 02 01 2A 00 00 00 {tb}"
        ));
        let o = objects_of(&f);
        assert_eq!(o.error, None, "{:?}", o.notes);
        let m = &o.measurements;
        assert_eq!(m.len(), 5);
        assert_eq!(
            (m[0].index, m[0].value, m[0].time),
            (3, Value::Binary(true), Some(1_000_005))
        );
        assert_eq!(
            (m[1].index, m[1].value, m[1].time),
            (4, Value::Binary(false), Some(1_000_010))
        );
        assert!(m[0].is_event);
        assert_eq!(
            (m[2].kind, m[2].index, m[2].value, m[2].time),
            (MeasurementKind::Analog, 7, Value::Analog(16.0), Some(t))
        );
        assert_eq!(m[3].value, Value::DoubleBit(DoubleBit::On));
        assert_eq!(m[3].time, Some(t));
        assert_eq!(
            (m[4].kind, m[4].value, m[4].time, m[4].is_event),
            (MeasurementKind::Counter, Value::Counter(42), Some(t), true)
        );
    }

    #[test]
    fn every_listed_variation_parses() {
        // (group, variation, one object) with qualifier 0x17 count 1 index 9.
        let one: &[(u8, u8, &str, Value)] = &[
            (1, 2, "81", Value::Binary(true)),
            (2, 1, "01", Value::Binary(false)),
            (2, 2, "81 01 00 00 00 00 00", Value::Binary(true)),
            (3, 2, "41", Value::DoubleBit(super::DoubleBit::Off)),
            (
                4,
                1,
                "C1",
                Value::DoubleBit(super::DoubleBit::Indeterminate),
            ),
            (
                4,
                2,
                "01 01 00 00 00 00 00",
                Value::DoubleBit(super::DoubleBit::Intermediate),
            ),
            (10, 2, "81", Value::Binary(true)),
            (11, 1, "81", Value::Binary(true)),
            (11, 2, "01 01 00 00 00 00 00", Value::Binary(false)),
            (20, 1, "01 07 00 00 00", Value::Counter(7)),
            (20, 2, "01 07 00", Value::Counter(7)),
            (20, 5, "07 00 00 00", Value::Counter(7)),
            (20, 6, "07 00", Value::Counter(7)),
            (21, 1, "01 07 00 00 00", Value::Counter(7)),
            (21, 2, "01 07 00", Value::Counter(7)),
            (21, 5, "01 07 00 00 00 01 00 00 00 00 00", Value::Counter(7)),
            (21, 6, "01 07 00 01 00 00 00 00 00", Value::Counter(7)),
            (21, 9, "07 00 00 00", Value::Counter(7)),
            (21, 10, "07 00", Value::Counter(7)),
            (22, 1, "01 FF FF FF FF", Value::Counter(4_294_967_295)),
            (22, 2, "01 07 00", Value::Counter(7)),
            (22, 5, "01 07 00 00 00 01 00 00 00 00 00", Value::Counter(7)),
            (22, 6, "01 07 00 01 00 00 00 00 00", Value::Counter(7)),
            (30, 1, "01 FF FF FF FF", Value::Analog(-1.0)),
            (30, 2, "01 FF FF", Value::Analog(-1.0)),
            (30, 3, "02 00 00 00", Value::Analog(2.0)),
            (30, 4, "02 00", Value::Analog(2.0)),
            (30, 5, "01 00 00 C0 3F", Value::Analog(1.5)),
            (30, 6, "01 00 00 00 00 00 00 F8 3F", Value::Analog(1.5)),
            (32, 1, "01 02 00 00 00", Value::Analog(2.0)),
            (32, 2, "01 02 00", Value::Analog(2.0)),
            (
                32,
                3,
                "01 02 00 00 00 01 00 00 00 00 00",
                Value::Analog(2.0),
            ),
            (32, 4, "01 02 00 01 00 00 00 00 00", Value::Analog(2.0)),
            (32, 5, "01 00 00 C0 3F", Value::Analog(1.5)),
            (32, 6, "01 00 00 00 00 00 00 F8 3F", Value::Analog(1.5)),
            (
                32,
                7,
                "01 00 00 C0 3F 01 00 00 00 00 00",
                Value::Analog(1.5),
            ),
            (
                32,
                8,
                "01 00 00 00 00 00 00 F8 3F 01 00 00 00 00 00",
                Value::Analog(1.5),
            ),
            (40, 1, "01 02 00 00 00", Value::Analog(2.0)),
            (40, 2, "01 02 00", Value::Analog(2.0)),
            (40, 3, "01 00 00 C0 3F", Value::Analog(1.5)),
            (40, 4, "01 00 00 00 00 00 00 F8 3F", Value::Analog(1.5)),
            (42, 1, "01 02 00 00 00", Value::Analog(2.0)),
            (42, 2, "01 02 00", Value::Analog(2.0)),
            (
                42,
                3,
                "01 02 00 00 00 01 00 00 00 00 00",
                Value::Analog(2.0),
            ),
            (42, 4, "01 02 00 01 00 00 00 00 00", Value::Analog(2.0)),
            (42, 5, "01 00 00 C0 3F", Value::Analog(1.5)),
            (42, 6, "01 00 00 00 00 00 00 F8 3F", Value::Analog(1.5)),
            (
                42,
                7,
                "01 00 00 C0 3F 01 00 00 00 00 00",
                Value::Analog(1.5),
            ),
            (
                42,
                8,
                "01 00 00 00 00 00 00 F8 3F 01 00 00 00 00 00",
                Value::Analog(1.5),
            ),
        ];
        for (g, v, obj, value) in one {
            let f = hex(&format!("C0 81 00 00 {g:02X} {v:02X} 17 01 09 {obj}"));
            let o = objects_of(&f);
            assert_eq!(o.error, None, "g{g}v{v}");
            assert_eq!(o.measurements.len(), 1, "g{g}v{v}");
            let m = o.measurements[0];
            assert_eq!((m.index, m.value), (9, *value), "g{g}v{v}");
            assert!(m.flags.contains(Flags::ONLINE), "g{g}v{v}");
            let timed = matches!(
                (g, v),
                (2, 2) | (4, 2) | (11, 2) | (21 | 22, 5 | 6) | (32 | 42, 3 | 4 | 7 | 8)
            );
            assert_eq!(m.time.is_some(), timed, "g{g}v{v}");
            if timed {
                assert_eq!(m.time, Some(1));
            }
            assert_eq!(
                m.is_event,
                matches!(g, 2 | 4 | 11 | 22 | 32 | 42),
                "g{g}v{v}"
            );
        }
        // Packed: g1v1 start 0 stop 9, g10v1, g3v1 start 0 stop 4, g80v1.
        let o = objects_of(&hex(
            "C0 81 00 00 01 01 00 00 09 05 02 0A 01 00 02 03 05 03 01 00 00 04 E4 02 50 01 00 07 07 00",
        ));
        assert_eq!(o.error, None);
        let vals: Vec<Value> = o.measurements.iter().map(|m| m.value).collect();
        use Value::*;
        assert_eq!(
            vals[..10],
            [
                Binary(true),
                Binary(false),
                Binary(true),
                Binary(false),
                Binary(false),
                Binary(false),
                Binary(false),
                Binary(false),
                Binary(false),
                Binary(true)
            ]
        );
        assert_eq!(o.measurements[10].index, 2);
        assert_eq!(vals[10..12], [Binary(true), Binary(false)]);
        assert_eq!(
            vals[12..],
            [
                DoubleBit(super::DoubleBit::Intermediate),
                DoubleBit(super::DoubleBit::Off),
                DoubleBit(super::DoubleBit::On),
                DoubleBit(super::DoubleBit::Indeterminate),
                DoubleBit(super::DoubleBit::On)
            ]
        );
        assert_eq!(o.iin_bits, vec![(7, false)]);
    }

    #[test]
    fn command_echoes_and_status_names() {
        // g12v1 0x28 count 1 index 3: latch on, count 1, 100/200 ms, status 2.
        let f = hex("C0 81 00 00 0C 01 28 01 00 03 00 03 01 64 00 00 00 C8 00 00 00 02");
        let o = objects_of(&f);
        assert_eq!(o.error, None);
        assert_eq!(
            o.commands,
            vec![CommandEcho {
                index: 3,
                object: CommandObject::Crob(Crob {
                    code: 3,
                    count: 1,
                    on_time_ms: 100,
                    off_time_ms: 200
                }),
                status: CommandStatus::NoSelect,
            }]
        );
        assert_eq!(o.commands[0].status.to_string(), "NO_SELECT (2)");
        for (v, obj, value, st) in [
            (
                1u8,
                "E8 03 00 00 00",
                AnalogOutput::I32(1000),
                CommandStatus::Success,
            ),
            (
                2,
                "18 FC 04",
                AnalogOutput::I16(-1000),
                CommandStatus::NotSupported,
            ),
            (
                3,
                "00 00 C0 3F 0C",
                AnalogOutput::F32(1.5),
                CommandStatus::OutOfRange,
            ),
            (
                4,
                "00 00 00 00 00 00 F8 3F 7F",
                AnalogOutput::F64(1.5),
                CommandStatus::Undefined,
            ),
        ] {
            let f = hex(&format!("C0 81 00 00 29 {v:02X} 17 01 05 {obj}"));
            let o = objects_of(&f);
            assert_eq!(o.commands.len(), 1);
            assert_eq!(o.commands[0].object, CommandObject::Analog(value));
            assert_eq!(o.commands[0].status, st);
            // Re-encoding gives the same octets.
            let mut b = Vec::new();
            o.commands[0].object.encode(st, &mut b);
            assert_eq!(b, hex(obj));
        }
        for c in 0..=127u8 {
            let s = CommandStatus::from_code(c);
            assert_eq!(s.code(), c);
        }
        assert_eq!(CommandStatus::from_code(126).name(), "NON_PARTICIPATING");
        assert_eq!(CommandStatus::from_code(10).name(), "AUTOMATION_INHIBIT");
        assert_eq!(CommandStatus::from_code(11).name(), "PROCESSING_LIMITED");
    }

    #[test]
    fn unknown_and_truncated_objects_are_located() {
        // g1v2 index 0, then g70v1 (file, unknown size): stops, keeps the binary.
        let o = objects_of(&hex("C0 81 00 00 01 02 00 00 00 81 46 01 07 01 00"));
        assert_eq!(o.measurements.len(), 1);
        assert_eq!(
            o.error,
            Some(ObjectError::UnknownSize {
                group: 70,
                variation: 1,
                offset: 10
            })
        );
        // A known-size object the master does not use is skipped.
        let o = objects_of(&hex("C0 81 00 00 0D 01 17 01 02 81 01 02 00 00 00 81"));
        assert_eq!(o.error, None);
        assert_eq!(o.measurements.len(), 1);
        assert!(
            o.notes[0].contains("g13v1 index 2 at octet 8 skipped"),
            "{:?}",
            o.notes
        );
        // g30v1 with two objects but only one present.
        let o = objects_of(&hex(
            "C0 81 00 00 1E 01 28 02 00 05 00 01 01 00 00 00 06 00 01 02",
        ));
        assert_eq!(o.measurements.len(), 1);
        let e = o.error.unwrap();
        assert_eq!(
            e,
            ObjectError::Truncated {
                group: 30,
                variation: 1,
                object: 1,
                index: 6,
                need: 7,
                have: 4,
                offset: 16
            }
        );
        assert!(e.to_string().contains("index 6"));
        // Packed bits with an index prefix.
        let o = objects_of(&hex("C0 81 00 00 01 01 17 01 00 01"));
        assert!(matches!(
            o.error,
            Some(ObjectError::PackedWithoutRange { .. })
        ));
        // A bad qualifier is located in the fragment.
        let o = objects_of(&hex("C0 81 00 00 01 02 5B 01"));
        assert!(matches!(
            o.error,
            Some(ObjectError::Header(AppError::Qualifier { offset: 4, .. }))
        ));
        // g2v3 without a CTO keeps the value, without time, with a note.
        let o = objects_of(&hex("C0 81 00 00 02 03 17 01 00 81 05 00"));
        assert_eq!(o.measurements[0].time, None);
        assert!(o.notes[0].contains("no g51 CTO"));
    }

    #[test]
    fn flags_in_words_and_quality() {
        use MeasurementKind::*;
        assert_eq!(
            Flags::from_octet(Binary, 0x01).quality(),
            (Quality::Good, "online".into())
        );
        assert_eq!(
            Flags::from_octet(Binary, 0x00).quality(),
            (Quality::Bad, "offline".into())
        );
        assert_eq!(
            Flags::from_octet(Binary, 0x21).describe(),
            "online, chatter filter"
        );
        assert_eq!(
            Flags::from_octet(Counter, 0x61).describe(),
            "online, rollover, discontinuity"
        );
        assert_eq!(
            Flags::from_octet(Analog, 0x41).quality(),
            (Quality::Bad, "reference error".into())
        );
        assert_eq!(
            Flags::from_octet(Analog, 0x19).quality(),
            (Quality::Uncertain, "remote forced, local forced".into())
        );
        assert_eq!(
            Flags::from_octet(AnalogOutputStatus, 0x02).quality(),
            (Quality::Bad, "offline, restart".into())
        );
        assert_eq!(Flags::from_octet(BinaryOutputStatus, 0x61), Flags::ONLINE);
    }
}
