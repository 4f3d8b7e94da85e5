//! Information elements (IEC 60870-5-101 7.2.6): the values an information
//! object carries, their quality descriptors and command qualifiers.

use std::fmt;
use std::ops::{BitOr, BitOrAssign};

use crate::time::Cp56Time2a;
use crate::types::TypeId;

/// Quality descriptor bits (QDS, and the quality half of SIQ and DIQ).
///
/// Written by hand rather than with a bitflags crate: five bits, and a
/// `describe` that names each in words for the event log.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct Quality(u8);

impl Quality {
    /// No bit set: the value is good.
    pub const GOOD: Quality = Quality(0);
    /// IV: invalid.
    pub const IV: Quality = Quality(0x80);
    /// NT: not topical (not updated successfully in time).
    pub const NT: Quality = Quality(0x40);
    /// SB: substituted (entered by an operator or automatic source).
    pub const SB: Quality = Quality(0x20);
    /// BL: blocked (frozen at the last value before blocking).
    pub const BL: Quality = Quality(0x10);
    /// OV: overflow (out of the value's range); only in QDS, not in SIQ/DIQ.
    pub const OV: Quality = Quality(0x01);
    /// Every known bit.
    pub const ALL: Quality = Quality(0xF1);
    /// The bits SIQ and DIQ carry (no OV).
    pub const POINT_BITS: Quality = Quality(0xF0);

    const NAMES: [(Quality, &'static str); 5] = [
        (Quality::IV, "invalid"),
        (Quality::NT, "not topical"),
        (Quality::SB, "substituted"),
        (Quality::BL, "blocked"),
        (Quality::OV, "overflow"),
    ];

    /// The bits as on the wire.
    pub fn bits(self) -> u8 {
        self.0
    }

    /// The quality in an octet, other bits (a value, reserved bits) dropped.
    pub fn from_bits_truncate(bits: u8) -> Quality {
        Quality(bits & Quality::ALL.0)
    }

    /// Whether every bit of `other` is set.
    pub fn contains(self, other: Quality) -> bool {
        self.0 & other.0 == other.0
    }

    /// Whether no bit is set.
    pub fn is_good(self) -> bool {
        self.0 == 0
    }

    /// Set or clear the bits of `other`.
    pub fn set(&mut self, other: Quality, on: bool) {
        if on {
            self.0 |= other.0;
        } else {
            self.0 &= !other.0;
        }
    }

    /// Each set bit in words, comma separated; "good" for none.
    pub fn describe(&self) -> String {
        if self.is_good() {
            return "good".to_string();
        }
        Quality::NAMES
            .iter()
            .filter(|(q, _)| self.contains(*q))
            .map(|(_, name)| *name)
            .collect::<Vec<_>>()
            .join(", ")
    }
}

impl BitOr for Quality {
    type Output = Quality;
    fn bitor(self, rhs: Quality) -> Quality {
        Quality(self.0 | rhs.0)
    }
}

impl BitOrAssign for Quality {
    fn bitor_assign(&mut self, rhs: Quality) {
        self.0 |= rhs.0;
    }
}

impl fmt::Display for Quality {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.describe())
    }
}

/// The DPI of a double point: a breaker's two auxiliary contacts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum DoublePoint {
    /// 0: neither contact (moving).
    Intermediate,
    /// 1: determined off (open).
    Off,
    /// 2: determined on (closed).
    On,
    /// 3: both contacts: faulty, not a position.
    Indeterminate,
}

impl DoublePoint {
    /// The DPI for the two low bits of `bits`.
    pub fn from_bits(bits: u8) -> DoublePoint {
        match bits & 0x03 {
            0 => DoublePoint::Intermediate,
            1 => DoublePoint::Off,
            2 => DoublePoint::On,
            _ => DoublePoint::Indeterminate,
        }
    }

    /// The two DPI bits.
    pub fn bits(self) -> u8 {
        self as u8
    }
}

/// A normalized value (NVA) as a fraction in -1 ..= 1 - 2^-15.
pub fn normalized_to_f64(value: i16) -> f64 {
    f64::from(value) / 32768.0
}

/// The NVA nearest to `x`, clamped to -1 ..= 1 - 2^-15; NaN gives 0.
pub fn normalized_from_f64(x: f64) -> i16 {
    if x.is_nan() {
        return 0;
    }
    // The clamp keeps the product within i16, so the cast cannot wrap.
    (x * 32768.0).round().clamp(-32768.0, 32767.0) as i16
}

/// The value of an information object, without its IOA and time tag.
///
/// Command qualifiers are kept as numbers: QU (0 none, 1 short pulse, 2 long
/// pulse, 3 persistent; 5 bits), QL (7 bits). `select` is the S/E bit:
/// true for select, false for execute.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Element {
    /// SIQ: M_SP_NA_1, M_SP_TB_1. The quality has no OV bit here.
    Single { on: bool, quality: Quality },
    /// DIQ: M_DP_NA_1, M_DP_TB_1. The quality has no OV bit here.
    Double {
        state: DoublePoint,
        quality: Quality,
    },
    /// VTI + QDS: M_ST_NA_1, M_ST_TB_1. `value` is -64..=63; `transient`
    /// means the equipment is moving.
    Step {
        value: i8,
        transient: bool,
        quality: Quality,
    },
    /// BSI + QDS: M_BO_NA_1, M_BO_TB_1.
    Bitstring { bits: u32, quality: Quality },
    /// NVA (+ QDS): M_ME_NA_1 and M_ME_TD_1 with quality, M_ME_ND_1 without.
    Normalized {
        value: i16,
        quality: Option<Quality>,
    },
    /// SVA + QDS: M_ME_NB_1, M_ME_TE_1.
    Scaled { value: i16, quality: Quality },
    /// IEEE STD 754 short float + QDS: M_ME_NC_1, M_ME_TF_1.
    Float { value: f32, quality: Quality },
    /// BCR: M_IT_NA_1, M_IT_TB_1. `seq` is 0..=31; `carry` is CY,
    /// `adjusted` CA, `invalid` IV.
    Counter {
        value: i32,
        seq: u8,
        carry: bool,
        adjusted: bool,
        invalid: bool,
    },
    /// COI: M_EI_NA_1. `cause` 0 local power on, 1 local manual reset,
    /// 2 remote reset (0..=127); `after_change` is BS1, initialized after a
    /// change of local parameters.
    EndOfInit { cause: u8, after_change: bool },
    /// SCO: C_SC_NA_1, C_SC_TA_1.
    SingleCommand {
        on: bool,
        select: bool,
        qualifier: u8,
    },
    /// DCO: C_DC_NA_1, C_DC_TA_1. `state` is DCS: 1 off, 2 on (0 and 3 are
    /// "not permitted" but kept, so a station can refuse them by name).
    DoubleCommand {
        state: u8,
        select: bool,
        qualifier: u8,
    },
    /// RCO: C_RC_NA_1, C_RC_TA_1. RCS 2 (`up`) next step higher, 1 lower.
    StepCommand {
        up: bool,
        select: bool,
        qualifier: u8,
    },
    /// NVA + QOS: C_SE_NA_1, C_SE_TA_1.
    SetpointNormalized {
        value: i16,
        select: bool,
        qualifier: u8,
    },
    /// SVA + QOS: C_SE_NB_1, C_SE_TB_1.
    SetpointScaled {
        value: i16,
        select: bool,
        qualifier: u8,
    },
    /// Short float + QOS: C_SE_NC_1, C_SE_TC_1.
    SetpointFloat {
        value: f32,
        select: bool,
        qualifier: u8,
    },
    /// BSI: C_BO_NA_1, C_BO_TA_1.
    Bitstring32Command { bits: u32 },
    /// QOI: C_IC_NA_1. 20 station interrogation, 21..=36 groups 1..=16.
    Interrogation { qoi: u8 },
    /// QCC: C_CI_NA_1. `request` (RQT, 6 bits) 1..=4 group, 5 general;
    /// `freeze` (FRZ, 2 bits) 0 read, 1 freeze, 2 freeze and reset, 3 reset.
    CounterInterrogation { request: u8, freeze: u8 },
    /// C_CS_NA_1: the time to set.
    ClockSync { time: Cp56Time2a },
    /// C_RD_NA_1: no element, the IOA names what to read.
    ReadCommand,
    /// TSC: C_TS_TA_1, the test sequence counter echoed back.
    TestCommand { counter: u16 },
}

impl Element {
    /// The type identification that carries this element, with or without
    /// a time tag; `None` where the standard has no such type (a normalized
    /// value with time but no quality, an interrogation with time ...).
    pub fn type_id(&self, with_time: bool) -> Option<TypeId> {
        use Element as E;
        use TypeId::*;
        let (plain, timed) = match self {
            E::Single { .. } => (Some(M_SP_NA_1), Some(M_SP_TB_1)),
            E::Double { .. } => (Some(M_DP_NA_1), Some(M_DP_TB_1)),
            E::Step { .. } => (Some(M_ST_NA_1), Some(M_ST_TB_1)),
            E::Bitstring { .. } => (Some(M_BO_NA_1), Some(M_BO_TB_1)),
            E::Normalized {
                quality: Some(_), ..
            } => (Some(M_ME_NA_1), Some(M_ME_TD_1)),
            E::Normalized { quality: None, .. } => (Some(M_ME_ND_1), None),
            E::Scaled { .. } => (Some(M_ME_NB_1), Some(M_ME_TE_1)),
            E::Float { .. } => (Some(M_ME_NC_1), Some(M_ME_TF_1)),
            E::Counter { .. } => (Some(M_IT_NA_1), Some(M_IT_TB_1)),
            E::EndOfInit { .. } => (Some(M_EI_NA_1), None),
            E::SingleCommand { .. } => (Some(C_SC_NA_1), Some(C_SC_TA_1)),
            E::DoubleCommand { .. } => (Some(C_DC_NA_1), Some(C_DC_TA_1)),
            E::StepCommand { .. } => (Some(C_RC_NA_1), Some(C_RC_TA_1)),
            E::SetpointNormalized { .. } => (Some(C_SE_NA_1), Some(C_SE_TA_1)),
            E::SetpointScaled { .. } => (Some(C_SE_NB_1), Some(C_SE_TB_1)),
            E::SetpointFloat { .. } => (Some(C_SE_NC_1), Some(C_SE_TC_1)),
            E::Bitstring32Command { .. } => (Some(C_BO_NA_1), Some(C_BO_TA_1)),
            E::Interrogation { .. } => (Some(C_IC_NA_1), None),
            E::CounterInterrogation { .. } => (Some(C_CI_NA_1), None),
            E::ClockSync { .. } => (Some(C_CS_NA_1), None),
            E::ReadCommand => (Some(C_RD_NA_1), None),
            E::TestCommand { .. } => (None, Some(C_TS_TA_1)),
        };
        if with_time {
            timed
        } else {
            plain
        }
    }

    /// The variant's name, for error messages.
    pub fn kind(&self) -> &'static str {
        match self {
            Element::Single { .. } => "Single",
            Element::Double { .. } => "Double",
            Element::Step { .. } => "Step",
            Element::Bitstring { .. } => "Bitstring",
            Element::Normalized { .. } => "Normalized",
            Element::Scaled { .. } => "Scaled",
            Element::Float { .. } => "Float",
            Element::Counter { .. } => "Counter",
            Element::EndOfInit { .. } => "EndOfInit",
            Element::SingleCommand { .. } => "SingleCommand",
            Element::DoubleCommand { .. } => "DoubleCommand",
            Element::StepCommand { .. } => "StepCommand",
            Element::SetpointNormalized { .. } => "SetpointNormalized",
            Element::SetpointScaled { .. } => "SetpointScaled",
            Element::SetpointFloat { .. } => "SetpointFloat",
            Element::Bitstring32Command { .. } => "Bitstring32Command",
            Element::Interrogation { .. } => "Interrogation",
            Element::CounterInterrogation { .. } => "CounterInterrogation",
            Element::ClockSync { .. } => "ClockSync",
            Element::ReadCommand => "ReadCommand",
            Element::TestCommand { .. } => "TestCommand",
        }
    }

    /// Whether every field fits its bits, so that encoding loses nothing;
    /// the error says which field does not.
    pub fn check(&self) -> Result<(), String> {
        let limit = |what: &str, v: i64, lo: i64, hi: i64| {
            if (lo..=hi).contains(&v) {
                Ok(())
            } else {
                Err(format!("{what} {v} out of range {lo}..={hi}"))
            }
        };
        match *self {
            Element::Single { quality, .. } | Element::Double { quality, .. } => {
                if quality.contains(Quality::OV) {
                    return Err(format!(
                        "{} point quality cannot carry OV (overflow)",
                        self.kind()
                    ));
                }
                Ok(())
            }
            Element::Step { value, .. } => limit("step value", value.into(), -64, 63),
            Element::Counter { seq, .. } => limit("counter sequence number", seq.into(), 0, 31),
            Element::EndOfInit { cause, .. } => {
                limit("cause of initialization", cause.into(), 0, 127)
            }
            Element::DoubleCommand {
                state, qualifier, ..
            } => {
                limit("double command state", state.into(), 0, 3)?;
                limit("command qualifier", qualifier.into(), 0, 31)
            }
            Element::SingleCommand { qualifier, .. } | Element::StepCommand { qualifier, .. } => {
                limit("command qualifier", qualifier.into(), 0, 31)
            }
            Element::SetpointNormalized { qualifier, .. }
            | Element::SetpointScaled { qualifier, .. }
            | Element::SetpointFloat { qualifier, .. } => {
                limit("set point qualifier", qualifier.into(), 0, 127)
            }
            Element::CounterInterrogation { request, freeze } => {
                limit("counter request", request.into(), 0, 63)?;
                limit("counter freeze", freeze.into(), 0, 3)
            }
            Element::ClockSync { time } => time.validate().map_err(|e| e.to_string()),
            _ => Ok(()),
        }
    }

    /// Decode the element of type `t` from exactly its octets (time tag
    /// excluded). Reserved bits are ignored.
    pub(crate) fn decode(t: TypeId, b: &[u8]) -> Result<Element, String> {
        use TypeId::*;
        // The caller hands over exactly the element's octets, so indexing
        // below is within bounds; `get` keeps it panic-free all the same.
        let u8_at = |i: usize| b.get(i).copied().unwrap_or(0);
        let i16_at = |i: usize| i16::from_le_bytes([u8_at(i), u8_at(i + 1)]);
        let u32_at =
            |i: usize| u32::from_le_bytes([u8_at(i), u8_at(i + 1), u8_at(i + 2), u8_at(i + 3)]);
        let qds = |i: usize| Quality::from_bits_truncate(u8_at(i));
        let point_quality = Quality(u8_at(0) & Quality::POINT_BITS.0);
        let select = u8_at(0) & 0x80 != 0;
        let qu = (u8_at(0) >> 2) & 0x1F;
        let e = match t {
            M_SP_NA_1 | M_SP_TB_1 => Element::Single {
                on: u8_at(0) & 0x01 != 0,
                quality: point_quality,
            },
            M_DP_NA_1 | M_DP_TB_1 => Element::Double {
                state: DoublePoint::from_bits(u8_at(0)),
                quality: point_quality,
            },
            M_ST_NA_1 | M_ST_TB_1 => Element::Step {
                // Sign-extend the seven-bit value.
                value: ((u8_at(0) << 1) as i8) >> 1,
                transient: u8_at(0) & 0x80 != 0,
                quality: qds(1),
            },
            M_BO_NA_1 | M_BO_TB_1 => Element::Bitstring {
                bits: u32_at(0),
                quality: qds(4),
            },
            M_ME_NA_1 | M_ME_TD_1 => Element::Normalized {
                value: i16_at(0),
                quality: Some(qds(2)),
            },
            M_ME_ND_1 => Element::Normalized {
                value: i16_at(0),
                quality: None,
            },
            M_ME_NB_1 | M_ME_TE_1 => Element::Scaled {
                value: i16_at(0),
                quality: qds(2),
            },
            M_ME_NC_1 | M_ME_TF_1 => Element::Float {
                value: f32::from_bits(u32_at(0)),
                quality: qds(4),
            },
            M_IT_NA_1 | M_IT_TB_1 => Element::Counter {
                value: u32_at(0) as i32,
                seq: u8_at(4) & 0x1F,
                carry: u8_at(4) & 0x20 != 0,
                adjusted: u8_at(4) & 0x40 != 0,
                invalid: u8_at(4) & 0x80 != 0,
            },
            M_EI_NA_1 => Element::EndOfInit {
                cause: u8_at(0) & 0x7F,
                after_change: u8_at(0) & 0x80 != 0,
            },
            C_SC_NA_1 | C_SC_TA_1 => Element::SingleCommand {
                on: u8_at(0) & 0x01 != 0,
                select,
                qualifier: qu,
            },
            C_DC_NA_1 | C_DC_TA_1 => Element::DoubleCommand {
                state: u8_at(0) & 0x03,
                select,
                qualifier: qu,
            },
            C_RC_NA_1 | C_RC_TA_1 => {
                let up = match u8_at(0) & 0x03 {
                    1 => false,
                    2 => true,
                    rcs => return Err(format!("regulating step RCS {rcs} is not permitted")),
                };
                Element::StepCommand {
                    up,
                    select,
                    qualifier: qu,
                }
            }
            C_SE_NA_1 | C_SE_TA_1 => Element::SetpointNormalized {
                value: i16_at(0),
                select: u8_at(2) & 0x80 != 0,
                qualifier: u8_at(2) & 0x7F,
            },
            C_SE_NB_1 | C_SE_TB_1 => Element::SetpointScaled {
                value: i16_at(0),
                select: u8_at(2) & 0x80 != 0,
                qualifier: u8_at(2) & 0x7F,
            },
            C_SE_NC_1 | C_SE_TC_1 => Element::SetpointFloat {
                value: f32::from_bits(u32_at(0)),
                select: u8_at(4) & 0x80 != 0,
                qualifier: u8_at(4) & 0x7F,
            },
            C_BO_NA_1 | C_BO_TA_1 => Element::Bitstring32Command { bits: u32_at(0) },
            C_IC_NA_1 => Element::Interrogation { qoi: u8_at(0) },
            C_CI_NA_1 => Element::CounterInterrogation {
                request: u8_at(0) & 0x3F,
                freeze: u8_at(0) >> 6,
            },
            C_RD_NA_1 => Element::ReadCommand,
            C_CS_NA_1 => Element::ClockSync {
                time: Cp56Time2a::decode(b).map_err(|e| e.to_string())?,
            },
            C_TS_TA_1 => Element::TestCommand {
                counter: i16_at(0) as u16,
            },
        };
        Ok(e)
    }

    /// Append the element's octets (time tag excluded). Fields are assumed
    /// checked ([`Element::check`]); out-of-range ones are masked.
    pub(crate) fn encode(&self, out: &mut Vec<u8>) {
        let flag = |on: bool, bit: u8| if on { bit } else { 0 };
        let command = |low: u8, select: bool, qualifier: u8| {
            low | ((qualifier & 0x1F) << 2) | flag(select, 0x80)
        };
        let qos = |select: bool, qualifier: u8| (qualifier & 0x7F) | flag(select, 0x80);
        match *self {
            Element::Single { on, quality } => {
                out.push(flag(on, 0x01) | (quality.bits() & Quality::POINT_BITS.0))
            }
            Element::Double { state, quality } => {
                out.push(state.bits() | (quality.bits() & Quality::POINT_BITS.0))
            }
            Element::Step {
                value,
                transient,
                quality,
            } => {
                out.push((value as u8 & 0x7F) | flag(transient, 0x80));
                out.push(quality.bits());
            }
            Element::Bitstring { bits, quality } => {
                out.extend_from_slice(&bits.to_le_bytes());
                out.push(quality.bits());
            }
            Element::Normalized { value, quality } => {
                out.extend_from_slice(&value.to_le_bytes());
                if let Some(q) = quality {
                    out.push(q.bits());
                }
            }
            Element::Scaled { value, quality } => {
                out.extend_from_slice(&value.to_le_bytes());
                out.push(quality.bits());
            }
            Element::Float { value, quality } => {
                out.extend_from_slice(&value.to_bits().to_le_bytes());
                out.push(quality.bits());
            }
            Element::Counter {
                value,
                seq,
                carry,
                adjusted,
                invalid,
            } => {
                out.extend_from_slice(&value.to_le_bytes());
                out.push(
                    (seq & 0x1F) | flag(carry, 0x20) | flag(adjusted, 0x40) | flag(invalid, 0x80),
                );
            }
            Element::EndOfInit {
                cause,
                after_change,
            } => out.push((cause & 0x7F) | flag(after_change, 0x80)),
            Element::SingleCommand {
                on,
                select,
                qualifier,
            } => out.push(command(flag(on, 0x01), select, qualifier)),
            Element::DoubleCommand {
                state,
                select,
                qualifier,
            } => out.push(command(state & 0x03, select, qualifier)),
            Element::StepCommand {
                up,
                select,
                qualifier,
            } => out.push(command(if up { 2 } else { 1 }, select, qualifier)),
            Element::SetpointNormalized {
                value,
                select,
                qualifier,
            }
            | Element::SetpointScaled {
                value,
                select,
                qualifier,
            } => {
                out.extend_from_slice(&value.to_le_bytes());
                out.push(qos(select, qualifier));
            }
            Element::SetpointFloat {
                value,
                select,
                qualifier,
            } => {
                out.extend_from_slice(&value.to_bits().to_le_bytes());
                out.push(qos(select, qualifier));
            }
            Element::Bitstring32Command { bits } => out.extend_from_slice(&bits.to_le_bytes()),
            Element::Interrogation { qoi } => out.push(qoi),
            Element::CounterInterrogation { request, freeze } => {
                out.push((request & 0x3F) | ((freeze & 0x03) << 6))
            }
            Element::ClockSync { time } => out.extend_from_slice(&time.encode()),
            Element::ReadCommand => {}
            Element::TestCommand { counter } => out.extend_from_slice(&counter.to_le_bytes()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quality_in_words() {
        assert_eq!(Quality::GOOD.describe(), "good");
        assert_eq!(
            (Quality::IV | Quality::NT).describe(),
            "invalid, not topical"
        );
        assert_eq!(
            Quality::from_bits_truncate(0xFF).describe(),
            "invalid, not topical, substituted, blocked, overflow"
        );
        assert_eq!(Quality::from_bits_truncate(0x0E), Quality::GOOD);
        let mut q = Quality::SB;
        q.set(Quality::BL, true);
        q.set(Quality::SB, false);
        assert_eq!(q, Quality::BL);
        q |= Quality::OV;
        assert!(q.contains(Quality::OV) && q.contains(Quality::BL));
        assert_eq!(q.to_string(), "blocked, overflow");
    }

    #[test]
    fn normalized_fractions() {
        assert_eq!(normalized_to_f64(i16::MIN), -1.0);
        assert_eq!(normalized_to_f64(16384), 0.5);
        assert_eq!(normalized_to_f64(i16::MAX), 1.0 - 2f64.powi(-15));
        assert_eq!(normalized_from_f64(-1.0), i16::MIN);
        assert_eq!(normalized_from_f64(0.5), 16384);
        assert_eq!(normalized_from_f64(1.0), i16::MAX);
        assert_eq!(normalized_from_f64(7.0), i16::MAX);
        assert_eq!(normalized_from_f64(-7.0), i16::MIN);
        assert_eq!(normalized_from_f64(f64::NAN), 0);
        for v in [i16::MIN, -1, 0, 1, 12345, i16::MAX] {
            assert_eq!(normalized_from_f64(normalized_to_f64(v)), v);
        }
    }

    #[test]
    fn step_value_sign_extends() {
        for (octet, value, transient) in [
            (0x00, 0, false),
            (0x3F, 63, false),
            (0x40, -64, false),
            (0x7F, -1, false),
            (0xC0, -64, true),
        ] {
            let e = Element::decode(TypeId::M_ST_NA_1, &[octet, 0]).unwrap();
            assert_eq!(
                e,
                Element::Step {
                    value,
                    transient,
                    quality: Quality::GOOD
                }
            );
            let mut out = vec![];
            e.encode(&mut out);
            assert_eq!(out, [octet, 0]);
        }
    }

    #[test]
    fn checks_name_the_field() {
        let e = Element::Step {
            value: 64,
            transient: false,
            quality: Quality::GOOD,
        };
        assert_eq!(
            e.check().unwrap_err(),
            "step value 64 out of range -64..=63"
        );
        let e = Element::Single {
            on: true,
            quality: Quality::OV,
        };
        assert!(e.check().unwrap_err().contains("OV"));
        let e = Element::SingleCommand {
            on: true,
            select: false,
            qualifier: 32,
        };
        assert!(e.check().is_err());
        assert_eq!(
            Element::decode(TypeId::C_RC_NA_1, &[0x03]).unwrap_err(),
            "regulating step RCS 3 is not permitted"
        );
    }
}
