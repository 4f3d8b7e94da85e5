//! The DNP3 application layer (IEEE 1815-2012 clause 4.2): the fragment
//! headers, function codes, internal indications (IIN) and object headers.
//!
//! A request is an application control octet (FIR, FIN, CON, UNS, SEQ), a
//! function code and object headers with their objects; a response has the
//! two IIN octets after the function code. The objects themselves are read
//! by [`crate::objects`]. Decoders never panic and say at which octet they
//! stopped.

use thiserror::Error;

pub const FIR: u8 = 0x80;
pub const FIN: u8 = 0x40;
pub const CON: u8 = 0x20;
pub const UNS: u8 = 0x10;
pub const SEQ_MASK: u8 = 0x0F;

/// The application control octet.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Control {
    pub fir: bool,
    pub fin: bool,
    pub con: bool,
    pub uns: bool,
    /// 0..=15.
    pub seq: u8,
}

impl Control {
    /// A single-fragment request with `seq`.
    pub fn request(seq: u8) -> Control {
        Control {
            fir: true,
            fin: true,
            con: false,
            uns: false,
            seq: seq & SEQ_MASK,
        }
    }

    pub fn from_octet(b: u8) -> Control {
        Control {
            fir: b & FIR != 0,
            fin: b & FIN != 0,
            con: b & CON != 0,
            uns: b & UNS != 0,
            seq: b & SEQ_MASK,
        }
    }

    pub fn octet(self) -> u8 {
        let mut b = self.seq & SEQ_MASK;
        for (on, bit) in [
            (self.fir, FIR),
            (self.fin, FIN),
            (self.con, CON),
            (self.uns, UNS),
        ] {
            if on {
                b |= bit;
            }
        }
        b
    }
}

macro_rules! function_codes {
    ($($name:ident = $code:literal, $text:literal;)*) => {
        /// Application function codes.
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
        pub enum FunctionCode {
            $($name,)*
        }

        impl FunctionCode {
            pub fn code(self) -> u8 {
                match self {
                    $(FunctionCode::$name => $code,)*
                }
            }

            pub fn from_code(code: u8) -> Option<FunctionCode> {
                match code {
                    $($code => Some(FunctionCode::$name),)*
                    _ => None,
                }
            }

            /// The standard's name, e.g. "DIRECT_OPERATE".
            pub fn name(self) -> &'static str {
                match self {
                    $(FunctionCode::$name => $text,)*
                }
            }
        }
    };
}

function_codes! {
    Confirm = 0, "CONFIRM";
    Read = 1, "READ";
    Write = 2, "WRITE";
    Select = 3, "SELECT";
    Operate = 4, "OPERATE";
    DirectOperate = 5, "DIRECT_OPERATE";
    DirectOperateNoResponse = 6, "DIRECT_OPERATE_NR";
    ImmediateFreeze = 7, "IMMED_FREEZE";
    ImmediateFreezeNoResponse = 8, "IMMED_FREEZE_NR";
    FreezeClear = 9, "FREEZE_CLEAR";
    FreezeClearNoResponse = 10, "FREEZE_CLEAR_NR";
    FreezeAtTime = 11, "FREEZE_AT_TIME";
    FreezeAtTimeNoResponse = 12, "FREEZE_AT_TIME_NR";
    ColdRestart = 13, "COLD_RESTART";
    WarmRestart = 14, "WARM_RESTART";
    InitializeData = 15, "INITIALIZE_DATA";
    InitializeApplication = 16, "INITIALIZE_APPL";
    StartApplication = 17, "START_APPL";
    StopApplication = 18, "STOP_APPL";
    SaveConfiguration = 19, "SAVE_CONFIG";
    EnableUnsolicited = 20, "ENABLE_UNSOLICITED";
    DisableUnsolicited = 21, "DISABLE_UNSOLICITED";
    AssignClass = 22, "ASSIGN_CLASS";
    DelayMeasure = 23, "DELAY_MEASURE";
    RecordCurrentTime = 24, "RECORD_CURRENT_TIME";
    OpenFile = 25, "OPEN_FILE";
    CloseFile = 26, "CLOSE_FILE";
    DeleteFile = 27, "DELETE_FILE";
    GetFileInfo = 28, "GET_FILE_INFO";
    AuthenticateFile = 29, "AUTHENTICATE_FILE";
    AbortFile = 30, "ABORT_FILE";
    ActivateConfig = 31, "ACTIVATE_CONFIG";
    AuthenticateRequest = 32, "AUTHENTICATE_REQ";
    AuthenticateRequestNoAck = 33, "AUTH_REQ_NO_ACK";
    Response = 129, "RESPONSE";
    UnsolicitedResponse = 130, "UNSOLICITED_RESPONSE";
    AuthenticateResponse = 131, "AUTHENTICATE_RESP";
}

impl std::fmt::Display for FunctionCode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// The internal indications: IIN1 in the low octet, IIN2 in the high one,
/// so that bit `n` is g80v1 index `n`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct Iin(pub u16);

impl Iin {
    pub const ALL_STATIONS: Iin = Iin(1 << 0);
    pub const CLASS1_EVENTS: Iin = Iin(1 << 1);
    pub const CLASS2_EVENTS: Iin = Iin(1 << 2);
    pub const CLASS3_EVENTS: Iin = Iin(1 << 3);
    pub const NEED_TIME: Iin = Iin(1 << 4);
    pub const LOCAL_CONTROL: Iin = Iin(1 << 5);
    pub const DEVICE_TROUBLE: Iin = Iin(1 << 6);
    pub const DEVICE_RESTART: Iin = Iin(1 << 7);
    pub const NO_FUNC_CODE_SUPPORT: Iin = Iin(1 << 8);
    pub const OBJECT_UNKNOWN: Iin = Iin(1 << 9);
    pub const PARAMETER_ERROR: Iin = Iin(1 << 10);
    pub const EVENT_BUFFER_OVERFLOW: Iin = Iin(1 << 11);
    pub const ALREADY_EXECUTING: Iin = Iin(1 << 12);
    pub const CONFIG_CORRUPT: Iin = Iin(1 << 13);
    pub const RESERVED_2_6: Iin = Iin(1 << 14);
    pub const RESERVED_2_7: Iin = Iin(1 << 15);

    const NAMES: [&'static str; 16] = [
        "ALL_STATIONS",
        "CLASS_1_EVENTS",
        "CLASS_2_EVENTS",
        "CLASS_3_EVENTS",
        "NEED_TIME",
        "LOCAL_CONTROL",
        "DEVICE_TROUBLE",
        "DEVICE_RESTART",
        "NO_FUNC_CODE_SUPPORT",
        "OBJECT_UNKNOWN",
        "PARAMETER_ERROR",
        "EVENT_BUFFER_OVERFLOW",
        "ALREADY_EXECUTING",
        "CONFIG_CORRUPT",
        "RESERVED_2_6",
        "RESERVED_2_7",
    ];

    pub fn from_octets(iin1: u8, iin2: u8) -> Iin {
        Iin(u16::from_le_bytes([iin1, iin2]))
    }

    pub fn contains(self, other: Iin) -> bool {
        self.0 & other.0 == other.0 && other.0 != 0
    }

    pub fn any(self, other: Iin) -> bool {
        self.0 & other.0 != 0
    }

    pub fn union(self, other: Iin) -> Iin {
        Iin(self.0 | other.0)
    }

    /// Bits that came on from `before` to `self`.
    pub fn raised_since(self, before: Iin) -> Iin {
        Iin(self.0 & !before.0)
    }

    /// The names of the bits set, e.g. `["NEED_TIME", "DEVICE_RESTART"]`.
    pub fn names(self) -> Vec<&'static str> {
        (0..16)
            .filter(|b| self.0 & (1 << b) != 0)
            .map(|b| Self::NAMES[b])
            .collect()
    }
}

impl std::ops::BitOr for Iin {
    type Output = Iin;
    fn bitor(self, rhs: Iin) -> Iin {
        self.union(rhs)
    }
}

impl std::fmt::Display for Iin {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.0 == 0 {
            return f.write_str("(none)");
        }
        f.write_str(&self.names().join(", "))
    }
}

/// The range (and prefix) of an object header, by qualifier code.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Range {
    /// 0x00: start and stop index, one octet each.
    StartStop8 { start: u8, stop: u8 },
    /// 0x01: start and stop index, two octets each.
    StartStop16 { start: u16, stop: u16 },
    /// 0x06: all objects, no range field.
    All,
    /// 0x07: a one-octet count.
    Count8(u8),
    /// 0x08: a two-octet count.
    Count16(u16),
    /// 0x17: a one-octet count, each object prefixed by a one-octet index.
    Indexed8(u8),
    /// 0x28: a two-octet count, each object prefixed by a two-octet index.
    Indexed16(u16),
}

impl Range {
    pub fn qualifier(self) -> u8 {
        match self {
            Range::StartStop8 { .. } => 0x00,
            Range::StartStop16 { .. } => 0x01,
            Range::All => 0x06,
            Range::Count8(_) => 0x07,
            Range::Count16(_) => 0x08,
            Range::Indexed8(_) => 0x17,
            Range::Indexed16(_) => 0x28,
        }
    }

    /// How many objects follow (0 for `All`).
    pub fn count(self) -> usize {
        match self {
            Range::StartStop8 { start, stop } => {
                usize::from(stop).saturating_sub(usize::from(start)) + 1
            }
            Range::StartStop16 { start, stop } => {
                usize::from(stop).saturating_sub(usize::from(start)) + 1
            }
            Range::All => 0,
            Range::Count8(n) | Range::Indexed8(n) => usize::from(n),
            Range::Count16(n) | Range::Indexed16(n) => usize::from(n),
        }
    }

    /// The octets of each object's index prefix.
    pub fn prefix_len(self) -> usize {
        match self {
            Range::Indexed8(_) => 1,
            Range::Indexed16(_) => 2,
            _ => 0,
        }
    }

    /// The first index of a start-stop range.
    pub fn start(self) -> Option<u16> {
        match self {
            Range::StartStop8 { start, .. } => Some(u16::from(start)),
            Range::StartStop16 { start, .. } => Some(start),
            _ => None,
        }
    }
}

/// An object header: group, variation and range.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct ObjectHeader {
    pub group: u8,
    pub variation: u8,
    pub range: Range,
}

impl ObjectHeader {
    pub fn new(group: u8, variation: u8, range: Range) -> ObjectHeader {
        ObjectHeader {
            group,
            variation,
            range,
        }
    }

    pub fn encode(&self, out: &mut Vec<u8>) {
        out.extend_from_slice(&[self.group, self.variation, self.range.qualifier()]);
        match self.range {
            Range::StartStop8 { start, stop } => out.extend_from_slice(&[start, stop]),
            Range::StartStop16 { start, stop } => {
                out.extend_from_slice(&start.to_le_bytes());
                out.extend_from_slice(&stop.to_le_bytes());
            }
            Range::All => {}
            Range::Count8(n) | Range::Indexed8(n) => out.push(n),
            Range::Count16(n) | Range::Indexed16(n) => out.extend_from_slice(&n.to_le_bytes()),
        }
    }

    /// Decode the header at `buf[at..]`; `Ok((header, octets))`.
    pub fn decode(buf: &[u8], at: usize) -> Result<(ObjectHeader, usize), AppError> {
        let short = |what: &'static str| AppError::Truncated { what, offset: at };
        let h = buf.get(at..at + 3).ok_or(short("object header"))?;
        let (group, variation, qualifier) = (h[0], h[1], h[2]);
        let field = |n: usize| buf.get(at + 3..at + 3 + n).ok_or(short("range field"));
        let (range, len) = match qualifier {
            0x00 => {
                let f = field(2)?;
                (
                    Range::StartStop8 {
                        start: f[0],
                        stop: f[1],
                    },
                    5,
                )
            }
            0x01 => {
                let f = field(4)?;
                (
                    Range::StartStop16 {
                        start: u16::from_le_bytes([f[0], f[1]]),
                        stop: u16::from_le_bytes([f[2], f[3]]),
                    },
                    7,
                )
            }
            0x06 => (Range::All, 3),
            0x07 => (Range::Count8(field(1)?[0]), 4),
            0x17 => (Range::Indexed8(field(1)?[0]), 4),
            0x08 => {
                let f = field(2)?;
                (Range::Count16(u16::from_le_bytes([f[0], f[1]])), 5)
            }
            0x28 => {
                let f = field(2)?;
                (Range::Indexed16(u16::from_le_bytes([f[0], f[1]])), 5)
            }
            q => {
                return Err(AppError::Qualifier {
                    qualifier: q,
                    group,
                    variation,
                    offset: at,
                })
            }
        };
        if let Range::StartStop8 { start, stop } = range {
            if stop < start {
                return Err(AppError::BadRange {
                    group,
                    variation,
                    start: start.into(),
                    stop: stop.into(),
                    offset: at,
                });
            }
        }
        if let Range::StartStop16 { start, stop } = range {
            if stop < start {
                return Err(AppError::BadRange {
                    group,
                    variation,
                    start,
                    stop,
                    offset: at,
                });
            }
        }
        Ok((
            ObjectHeader {
                group,
                variation,
                range,
            },
            len,
        ))
    }
}

/// What is wrong with a fragment's headers.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum AppError {
    #[error("fragment of {len} octets is too short for a {what} header")]
    Short { what: &'static str, len: usize },
    #[error("unknown function code {code} (octet 1)")]
    UnknownFunction { code: u8 },
    #[error("function {0} is not a response")]
    NotAResponse(FunctionCode),
    #[error("{what} truncated at octet {offset}")]
    Truncated { what: &'static str, offset: usize },
    #[error("unsupported qualifier 0x{qualifier:02X} for g{group}v{variation} at octet {offset}")]
    Qualifier {
        qualifier: u8,
        group: u8,
        variation: u8,
        offset: usize,
    },
    #[error("g{group}v{variation} range {start}..{stop} has stop before start at octet {offset}")]
    BadRange {
        group: u8,
        variation: u8,
        start: u16,
        stop: u16,
        offset: usize,
    },
}

/// A response (or unsolicited response) fragment's header; its objects
/// are `fragment[Response::OBJECTS_AT..]`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ResponseHeader {
    pub control: Control,
    pub function: FunctionCode,
    pub iin: Iin,
}

impl ResponseHeader {
    pub const LEN: usize = 4;

    pub fn decode(fragment: &[u8]) -> Result<ResponseHeader, AppError> {
        let h = fragment.get(..Self::LEN).ok_or(AppError::Short {
            what: "response",
            len: fragment.len(),
        })?;
        let function =
            FunctionCode::from_code(h[1]).ok_or(AppError::UnknownFunction { code: h[1] })?;
        if !matches!(
            function,
            FunctionCode::Response
                | FunctionCode::UnsolicitedResponse
                | FunctionCode::AuthenticateResponse
        ) {
            return Err(AppError::NotAResponse(function));
        }
        Ok(ResponseHeader {
            control: Control::from_octet(h[0]),
            function,
            iin: Iin::from_octets(h[2], h[3]),
        })
    }

    pub fn encode(&self, out: &mut Vec<u8>) {
        let [iin1, iin2] = self.iin.0.to_le_bytes();
        out.extend_from_slice(&[self.control.octet(), self.function.code(), iin1, iin2]);
    }
}

/// A request fragment's header.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RequestHeader {
    pub control: Control,
    pub function: FunctionCode,
}

impl RequestHeader {
    pub const LEN: usize = 2;

    pub fn decode(fragment: &[u8]) -> Result<RequestHeader, AppError> {
        let h = fragment.get(..Self::LEN).ok_or(AppError::Short {
            what: "request",
            len: fragment.len(),
        })?;
        let function =
            FunctionCode::from_code(h[1]).ok_or(AppError::UnknownFunction { code: h[1] })?;
        Ok(RequestHeader {
            control: Control::from_octet(h[0]),
            function,
        })
    }

    pub fn encode(&self, out: &mut Vec<u8>) {
        out.extend_from_slice(&[self.control.octet(), self.function.code()]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_util::hex;

    #[test]
    fn control_and_function_codes_round_trip() {
        for b in 0..=255u8 {
            assert_eq!(Control::from_octet(b).octet(), b);
            if let Some(f) = FunctionCode::from_code(b) {
                assert_eq!(f.code(), b);
            }
        }
        assert_eq!(
            FunctionCode::from_code(23),
            Some(FunctionCode::DelayMeasure)
        );
        assert_eq!(
            FunctionCode::from_code(24).unwrap().name(),
            "RECORD_CURRENT_TIME"
        );
        assert_eq!(
            FunctionCode::from_code(130),
            Some(FunctionCode::UnsolicitedResponse)
        );
        assert_eq!(FunctionCode::from_code(34), None);
    }

    #[test]
    fn response_header_and_iin() {
        let r = ResponseHeader::decode(&hex("E3 81 96 08")).unwrap();
        assert!(r.control.fir && r.control.fin && r.control.con && !r.control.uns);
        assert_eq!(r.control.seq, 3);
        assert_eq!(r.function, FunctionCode::Response);
        assert!(r.iin.contains(Iin::DEVICE_RESTART));
        assert!(r.iin.contains(Iin::NEED_TIME));
        assert!(r.iin.contains(Iin::CLASS1_EVENTS | Iin::CLASS2_EVENTS));
        assert!(r.iin.contains(Iin::EVENT_BUFFER_OVERFLOW));
        assert_eq!(
            r.iin.to_string(),
            "CLASS_1_EVENTS, CLASS_2_EVENTS, NEED_TIME, DEVICE_RESTART, EVENT_BUFFER_OVERFLOW"
        );
        let mut out = Vec::new();
        r.encode(&mut out);
        assert_eq!(out, hex("E3 81 96 08"));
        assert_eq!(
            ResponseHeader::decode(&hex("C0 81 00")),
            Err(AppError::Short {
                what: "response",
                len: 3
            })
        );
        assert_eq!(
            ResponseHeader::decode(&hex("C0 01 00 00")),
            Err(AppError::NotAResponse(FunctionCode::Read))
        );
        let q = RequestHeader::decode(&hex("C5 14")).unwrap();
        assert_eq!(q.function, FunctionCode::EnableUnsolicited);
        assert_eq!(q.control.seq, 5);
    }

    #[test]
    fn object_headers_round_trip() {
        for range in [
            Range::StartStop8 { start: 3, stop: 9 },
            Range::StartStop16 {
                start: 300,
                stop: 900,
            },
            Range::All,
            Range::Count8(4),
            Range::Count16(400),
            Range::Indexed8(2),
            Range::Indexed16(1000),
        ] {
            let h = ObjectHeader::new(30, 1, range);
            let mut b = vec![0xAA];
            h.encode(&mut b);
            assert_eq!(
                ObjectHeader::decode(&b, 1),
                Ok((h, b.len() - 1)),
                "{range:?}"
            );
            for cut in 1..b.len() {
                assert!(ObjectHeader::decode(&b[..cut], 1).is_err());
            }
        }
        assert_eq!(
            ObjectHeader::decode(&hex("01 02 5B 00"), 0),
            Err(AppError::Qualifier {
                qualifier: 0x5B,
                group: 1,
                variation: 2,
                offset: 0
            })
        );
        assert!(matches!(
            ObjectHeader::decode(&hex("01 02 00 05 04"), 0),
            Err(AppError::BadRange { .. })
        ));
    }
}
