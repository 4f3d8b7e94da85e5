//! What the controlled station sends and takes, pure: a tag's sample as an
//! information element of its exported point (quality back to IV/NT), the
//! deadband of spontaneous data, a command element as the value to write,
//! and packing objects of one type into ASDUs.

use gridscada_config::{Iec104Command, Iec104Point};
use gridscada_tagdb::{QualityCode, Sample, TagId, Value, ValueKind};

use crate::asdu::{HEADER_LEN, IOA_LEN, MAX_OBJECTS};
use crate::{
    normalized_from_f64, normalized_to_f64, Asdu, Cause, Cp56Time2a, DoublePoint, Element,
    InformationObject, Quality, TypeId,
};

/// One exported tag.
#[derive(Debug, Clone)]
pub(crate) struct Export {
    pub tag: String,
    pub id: TagId,
    pub kind: ValueKind,
    pub ioa: u32,
    pub point: Iec104Point,
    pub deadband: f64,
    pub command: Option<Iec104Command>,
    pub command_ioa: u32,
    pub select: bool,
}

/// The point's type identification, with or without time tag.
pub(crate) fn type_id(point: Iec104Point, with_time: bool) -> TypeId {
    use TypeId::*;
    match (point, with_time) {
        (Iec104Point::M_SP, false) => M_SP_NA_1,
        (Iec104Point::M_SP, true) => M_SP_TB_1,
        (Iec104Point::M_DP, false) => M_DP_NA_1,
        (Iec104Point::M_DP, true) => M_DP_TB_1,
        (Iec104Point::M_ST, false) => M_ST_NA_1,
        (Iec104Point::M_ST, true) => M_ST_TB_1,
        (Iec104Point::M_BO, false) => M_BO_NA_1,
        (Iec104Point::M_BO, true) => M_BO_TB_1,
        (Iec104Point::M_ME_NA, false) => M_ME_NA_1,
        (Iec104Point::M_ME_NA, true) => M_ME_TD_1,
        (Iec104Point::M_ME_NB, false) => M_ME_NB_1,
        (Iec104Point::M_ME_NB, true) => M_ME_TE_1,
        (Iec104Point::M_ME_NC, false) => M_ME_NC_1,
        (Iec104Point::M_ME_NC, true) => M_ME_TF_1,
        (Iec104Point::M_IT, false) => M_IT_NA_1,
        (Iec104Point::M_IT, true) => M_IT_TB_1,
    }
}

/// The sample as the point's element. Bad is IV (invalid), Uncertain NT
/// (not topical); a value the type cannot hold is clamped and marked OV.
pub(crate) fn element(point: Iec104Point, s: &Sample) -> Element {
    let mut q = Quality::GOOD;
    match s.quality.code {
        QualityCode::Good => {}
        QualityCode::Uncertain => q.set(Quality::NT, true),
        QualityCode::Bad => q.set(Quality::IV, true),
    }
    let f = s.value.as_f64().unwrap_or(0.0);
    let clamp = |lo: f64, hi: f64, q: &mut Quality| {
        if f < lo || f > hi || f.is_nan() {
            q.set(Quality::OV, true);
        }
        if f.is_nan() {
            0.0
        } else {
            f.clamp(lo, hi)
        }
    };
    match point {
        Iec104Point::M_SP => Element::Single {
            on: s.value.as_bool().unwrap_or(false),
            quality: q,
        },
        Iec104Point::M_DP => Element::Double {
            state: match &s.value {
                Value::Bool(true) => DoublePoint::On,
                Value::Bool(false) => DoublePoint::Off,
                v => DoublePoint::from_bits(v.as_f64().unwrap_or(3.0).clamp(0.0, 3.0) as u8),
            },
            quality: q,
        },
        Iec104Point::M_ST => {
            let v = clamp(-64.0, 63.0, &mut q);
            // OV is not a step position bit: invalid instead.
            if q.contains(Quality::OV) {
                q.set(Quality::OV, false);
                q.set(Quality::IV, true);
            }
            Element::Step {
                value: v as i8,
                transient: false,
                quality: q,
            }
        }
        Iec104Point::M_BO => Element::Bitstring {
            bits: clamp(0.0, f64::from(u32::MAX), &mut q) as u32,
            quality: q,
        },
        Iec104Point::M_ME_NA => {
            let v = clamp(-1.0, 1.0, &mut q);
            Element::Normalized {
                value: normalized_from_f64(v),
                quality: Some(q),
            }
        }
        Iec104Point::M_ME_NB => Element::Scaled {
            value: clamp(f64::from(i16::MIN), f64::from(i16::MAX), &mut q).round() as i16,
            quality: q,
        },
        Iec104Point::M_ME_NC => Element::Float {
            value: f as f32,
            quality: q,
        },
        Iec104Point::M_IT => {
            let v = clamp(f64::from(i32::MIN), f64::from(i32::MAX), &mut q);
            Element::Counter {
                value: v as i32,
                seq: 0,
                carry: q.contains(Quality::OV),
                adjusted: false,
                invalid: q.contains(Quality::IV),
            }
        }
    }
}

/// Whether a change from `last` (the value last sent) to `now` is worth a
/// spontaneous message: any change of a state, a move past the deadband of
/// a measurand, any change of quality.
pub(crate) fn worth_sending(e: &Export, last: Option<&Sample>, now: &Sample) -> bool {
    let Some(last) = last else { return true };
    if last.quality.code != now.quality.code {
        return true;
    }
    match e.point {
        Iec104Point::M_ME_NA | Iec104Point::M_ME_NB | Iec104Point::M_ME_NC if e.deadband > 0.0 => {
            match (last.value.as_f64(), now.value.as_f64()) {
                (Some(a), Some(b)) => (a - b).abs() > e.deadband,
                _ => last.value != now.value,
            }
        }
        _ => last.value != now.value,
    }
}

/// The value a command element asks for, as the tag's kind; `Err` in
/// words when the element is not the point's command or cannot be a value
/// of the tag. `current` is the tag's value (a step command moves it by one).
pub(crate) fn command_value(
    e: &Export,
    el: &Element,
    current: Option<&Value>,
) -> Result<Value, String> {
    let want = match (e.command, el) {
        (Some(Iec104Command::C_SC), Element::SingleCommand { on, .. }) => Value::Bool(*on),
        (Some(Iec104Command::C_DC), Element::DoubleCommand { state, .. }) => {
            match (state, e.kind) {
                (2, ValueKind::Bool) => Value::Bool(true),
                (1, ValueKind::Bool) => Value::Bool(false),
                (1 | 2, _) => Value::Int(i64::from(*state)),
                (s, _) => {
                    return Err(format!(
                        "double command state {s} is not permitted (1 off, 2 on)"
                    ))
                }
            }
        }
        (Some(Iec104Command::C_RC), Element::StepCommand { up, .. }) => {
            let now = current.and_then(Value::as_f64).unwrap_or(0.0);
            Value::Float(now + if *up { 1.0 } else { -1.0 })
        }
        (Some(Iec104Command::C_SE_NA), Element::SetpointNormalized { value, .. }) => {
            Value::Float(normalized_to_f64(*value))
        }
        (Some(Iec104Command::C_SE_NB), Element::SetpointScaled { value, .. }) => {
            Value::Float(f64::from(*value))
        }
        (Some(Iec104Command::C_SE_NC), Element::SetpointFloat { value, .. }) => {
            Value::Float(f64::from(*value))
        }
        (Some(Iec104Command::C_BO), Element::Bitstring32Command { bits }) => {
            Value::Int(i64::from(*bits))
        }
        (None, _) => return Err(format!("IOA {} takes no commands", e.command_ioa)),
        (Some(c), other) => {
            return Err(format!(
                "IOA {} takes {}, not {}",
                e.command_ioa,
                c.label(),
                other.kind()
            ))
        }
    };
    want.coerce(e.kind)
        .ok_or_else(|| format!("{want} is not a value of tag '{}'", e.tag))
}

/// Objects of one type, packed into as few ASDUs as fit (SQ=0, each with
/// its IOA).
pub(crate) fn pack(
    type_id: TypeId,
    cause: Cause,
    ca: u16,
    objects: Vec<InformationObject>,
) -> Vec<Asdu> {
    let per = ((crate::apci::MAX_ASDU_LEN - HEADER_LEN) / (IOA_LEN + type_id.element_len()))
        .clamp(1, MAX_OBJECTS);
    let mut out = Vec::new();
    let mut it = objects.into_iter().peekable();
    while it.peek().is_some() {
        let chunk: Vec<_> = it.by_ref().take(per).collect();
        // Elements come from `element`, which only makes valid ones.
        if let Ok(a) = Asdu::new(type_id, cause, ca, chunk) {
            out.push(a);
        }
    }
    out
}

/// The time tag of a sample.
pub(crate) fn time_of(s: &Sample) -> Option<Cp56Time2a> {
    Cp56Time2a::from_unix_ms(s.timestamp.as_millis()).ok()
}

#[cfg(test)]
mod tests {
    use super::*;
    use gridscada_tagdb::{Quality as TagQuality, Timestamp};

    fn export(point: Iec104Point, kind: ValueKind, command: Option<Iec104Command>) -> Export {
        Export {
            tag: "SS1.Q1".into(),
            id: TagId(0),
            kind,
            ioa: 100,
            point,
            deadband: 0.5,
            command,
            command_ioa: 200,
            select: false,
        }
    }

    fn sample(v: Value, q: TagQuality) -> Sample {
        Sample {
            value: v,
            quality: q,
            timestamp: Timestamp::from_millis(1_795_000_000_123),
        }
    }

    #[test]
    fn samples_become_elements_with_their_quality() {
        let good = sample(Value::Bool(true), TagQuality::GOOD);
        assert_eq!(
            element(Iec104Point::M_DP, &good),
            Element::Double {
                state: DoublePoint::On,
                quality: Quality::GOOD
            }
        );
        let bad = sample(Value::Float(3.5), TagQuality::bad("communication lost"));
        match element(Iec104Point::M_ME_NC, &bad) {
            Element::Float { value, quality } => {
                assert_eq!(value, 3.5);
                assert!(quality.contains(Quality::IV));
            }
            e => panic!("{e:?}"),
        }
        let big = sample(Value::Float(40000.0), TagQuality::uncertain("substituted"));
        match element(Iec104Point::M_ME_NB, &big) {
            Element::Scaled { value, quality } => {
                assert_eq!(value, i16::MAX);
                assert!(quality.contains(Quality::OV) && quality.contains(Quality::NT));
            }
            e => panic!("{e:?}"),
        }
    }

    #[test]
    fn the_deadband_holds_back_small_moves_only() {
        let e = export(Iec104Point::M_ME_NC, ValueKind::Float, None);
        let a = sample(Value::Float(10.0), TagQuality::GOOD);
        assert!(!worth_sending(
            &e,
            Some(&a),
            &sample(Value::Float(10.4), TagQuality::GOOD)
        ));
        assert!(worth_sending(
            &e,
            Some(&a),
            &sample(Value::Float(10.6), TagQuality::GOOD)
        ));
        assert!(worth_sending(
            &e,
            Some(&a),
            &sample(Value::Float(10.1), TagQuality::bad("x"))
        ));
        assert!(worth_sending(&e, None, &a));
    }

    #[test]
    fn commands_become_values_of_the_tag() {
        let dc = export(
            Iec104Point::M_DP,
            ValueKind::Bool,
            Some(Iec104Command::C_DC),
        );
        let on = Element::DoubleCommand {
            state: 2,
            select: false,
            qualifier: 0,
        };
        assert_eq!(command_value(&dc, &on, None).unwrap(), Value::Bool(true));
        let bad = Element::DoubleCommand {
            state: 3,
            select: false,
            qualifier: 0,
        };
        assert!(command_value(&dc, &bad, None)
            .unwrap_err()
            .contains("not permitted"));
        let sc = Element::SingleCommand {
            on: true,
            select: false,
            qualifier: 0,
        };
        assert!(command_value(&dc, &sc, None)
            .unwrap_err()
            .contains("takes C_DC"));
        let se = export(
            Iec104Point::M_ME_NC,
            ValueKind::Float,
            Some(Iec104Command::C_SE_NC),
        );
        let v = Element::SetpointFloat {
            value: 12.5,
            select: false,
            qualifier: 0,
        };
        assert_eq!(command_value(&se, &v, None).unwrap(), Value::Float(12.5));
    }

    #[test]
    fn a_large_interrogation_is_packed_into_full_asdus() {
        let objects: Vec<_> = (1..=1000)
            .map(|i| {
                InformationObject::new(
                    i,
                    Element::Float {
                        value: 1.0,
                        quality: Quality::GOOD,
                    },
                )
            })
            .collect();
        let asdus = pack(TypeId::M_ME_NC_1, Cause::InroGen, 1, objects);
        assert_eq!(asdus.iter().map(|a| a.objects().len()).sum::<usize>(), 1000);
        assert!(asdus
            .iter()
            .all(|a| a.encode().len() <= crate::apci::MAX_ASDU_LEN));
        assert_eq!(asdus[0].objects().len(), (249 - 6) / 8);
    }
}
