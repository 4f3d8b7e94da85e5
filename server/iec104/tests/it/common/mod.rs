//! Sample objects of every type, shared by the round-trip and fuzz tests.

#![allow(dead_code)]

use gridscada_iec104::{
    Asdu, Cause, Cp56Time2a, DoublePoint, Element, InformationObject, Quality, TypeId,
};

/// A valid time tag that differs with `i`.
pub fn time(i: u32) -> Cp56Time2a {
    let base = 1_717_243_200_000i64; // 2024-06-01T12:00:00Z
    Cp56Time2a::from_unix_ms(base + i64::from(i) * 3_601_001)
        .unwrap()
        .with_invalid(i % 5 == 1)
        .with_summer_time(i % 3 == 2)
}

/// A quality that differs with `i`; `point` leaves out OV (SIQ/DIQ have none).
pub fn quality(i: u32, point: bool) -> Quality {
    let all = [
        Quality::GOOD,
        Quality::IV,
        Quality::NT | Quality::SB,
        Quality::BL,
        Quality::OV | Quality::IV,
    ];
    let q = all[i as usize % all.len()];
    if point && q.contains(Quality::OV) {
        Quality::IV
    } else {
        q
    }
}

/// The element of type `t` for the `i`th sample object.
pub fn element(t: TypeId, i: u32) -> Element {
    use TypeId::*;
    let odd = i % 2 == 1;
    match t {
        M_SP_NA_1 | M_SP_TB_1 => Element::Single {
            on: odd,
            quality: quality(i, true),
        },
        M_DP_NA_1 | M_DP_TB_1 => Element::Double {
            state: DoublePoint::from_bits(i as u8),
            quality: quality(i, true),
        },
        M_ST_NA_1 | M_ST_TB_1 => Element::Step {
            value: [-64i8, -1, 0, 17, 63][i as usize % 5],
            transient: odd,
            quality: quality(i, false),
        },
        M_BO_NA_1 | M_BO_TB_1 => Element::Bitstring {
            bits: 0xDEAD_BEEF ^ i,
            quality: quality(i, false),
        },
        M_ME_NA_1 | M_ME_TD_1 => Element::Normalized {
            value: [i16::MIN, -1, 0, 16384, i16::MAX][i as usize % 5],
            quality: Some(quality(i, false)),
        },
        M_ME_ND_1 => Element::Normalized {
            value: -12345 + i as i16,
            quality: None,
        },
        M_ME_NB_1 | M_ME_TE_1 => Element::Scaled {
            value: 1000 - 300 * i as i16,
            quality: quality(i, false),
        },
        M_ME_NC_1 | M_ME_TF_1 => Element::Float {
            value: [230.5f32, -0.0, f32::MAX, 1e-30, -17.25][i as usize % 5],
            quality: quality(i, false),
        },
        M_IT_NA_1 | M_IT_TB_1 => Element::Counter {
            value: [i32::MIN, -1, 0, 123_456_789, i32::MAX][i as usize % 5],
            seq: (i % 32) as u8,
            carry: odd,
            adjusted: i.is_multiple_of(3),
            invalid: i % 4 == 3,
        },
        M_EI_NA_1 => Element::EndOfInit {
            cause: (i % 3) as u8,
            after_change: odd,
        },
        C_SC_NA_1 | C_SC_TA_1 => Element::SingleCommand {
            on: !odd,
            select: odd,
            qualifier: (i % 4) as u8,
        },
        C_DC_NA_1 | C_DC_TA_1 => Element::DoubleCommand {
            state: 1 + (i % 2) as u8,
            select: !odd,
            qualifier: 31,
        },
        C_RC_NA_1 | C_RC_TA_1 => Element::StepCommand {
            up: odd,
            select: odd,
            qualifier: 2,
        },
        C_SE_NA_1 | C_SE_TA_1 => Element::SetpointNormalized {
            value: -16384,
            select: odd,
            qualifier: 127,
        },
        C_SE_NB_1 | C_SE_TB_1 => Element::SetpointScaled {
            value: 4000,
            select: !odd,
            qualifier: 0,
        },
        C_SE_NC_1 | C_SE_TC_1 => Element::SetpointFloat {
            value: 49.95,
            select: odd,
            qualifier: 5,
        },
        C_BO_NA_1 | C_BO_TA_1 => Element::Bitstring32Command { bits: 0x8000_0001 },
        C_IC_NA_1 => Element::Interrogation { qoi: 20 + i as u8 },
        C_CI_NA_1 => Element::CounterInterrogation {
            request: 5,
            freeze: (i % 4) as u8,
        },
        C_RD_NA_1 => Element::ReadCommand,
        C_CS_NA_1 => Element::ClockSync { time: time(i) },
        C_TS_TA_1 => Element::TestCommand {
            counter: 0xBEEF ^ i as u16,
        },
    }
}

/// `n` sample objects of type `t` at IOAs `first`, `first + 1`, ...
pub fn objects(t: TypeId, first: u32, n: u32) -> Vec<InformationObject> {
    (0..n)
        .map(|i| {
            let o = InformationObject::new(first + i, element(t, i));
            if t.carries_time() {
                o.with_time(time(i))
            } else {
                o
            }
        })
        .collect()
}

/// The most objects of type `t` that fit one ASDU.
pub fn max_objects(t: TypeId, sequence: bool) -> u32 {
    let room = 249 - 6;
    let n = if sequence {
        (room - 3) / t.element_len().max(1)
    } else {
        room / (3 + t.element_len())
    };
    n.min(127) as u32
}

/// Sample ASDUs of every type: SQ=0 with one, three and the most objects,
/// and SQ=1 with two and the most where the type allows it.
pub fn sample_asdus() -> Vec<Asdu> {
    let mut out = vec![];
    for &t in TypeId::ALL {
        let cause = if t.is_command() {
            Cause::Act
        } else {
            Cause::Spont
        };
        for n in [1, 3, max_objects(t, false)] {
            out.push(Asdu::new(t, cause, 0x1234, objects(t, 1000, n)).unwrap());
        }
        if t.allows_sequence() {
            for n in [2, max_objects(t, true)] {
                out.push(
                    Asdu::new_sequence(t, Cause::InroGen, 7, objects(t, 0xFF_FF00, n))
                        .unwrap()
                        .with_originator(3)
                        .with_test(true),
                );
            }
        }
    }
    out
}

/// Parse "68 04 07 00 00 00" into octets.
pub fn hex(s: &str) -> Vec<u8> {
    s.split_whitespace()
        .map(|b| u8::from_str_radix(b, 16).unwrap())
        .collect()
}
