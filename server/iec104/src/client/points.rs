//! From information objects to tag samples: which tag an IOA feeds, its
//! engineering value (scaling, double points), the quality descriptor in
//! words, and the station's time tag as the sample's timestamp. Pure.

use std::collections::HashMap;

use gridscada_config::{Iec104Point, TagConfig};
use gridscada_tagdb::{Quality as TagQuality, Sample, TagId, Timestamp, Value, ValueKind};

use crate::{normalized_to_f64, DoublePoint, Element, InformationObject, Quality};

/// One monitored tag of a station.
#[derive(Debug, Clone)]
pub(crate) struct PointTag {
    pub id: TagId,
    pub name: String,
    pub point: Iec104Point,
    pub kind: ValueKind,
    pub scale: f64,
    pub offset: f64,
}

impl PointTag {
    pub fn new(id: TagId, t: &TagConfig, point: Iec104Point) -> PointTag {
        PointTag {
            id,
            name: t.name.get_ref().clone(),
            point,
            kind: t.value_kind(),
            scale: *t.scale.get_ref(),
            offset: t.offset,
        }
    }
}

/// The monitored tags of one station by information object address.
#[derive(Debug, Default)]
pub(crate) struct PointMap {
    by_ioa: HashMap<u32, PointTag>,
}

/// What became of one information object.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Outcome {
    /// The tag's new sample.
    Sample(TagId, Sample),
    /// No tag is configured on this IOA: counted, not an error.
    Unmapped,
    /// The IOA's tag takes another type (a configuration mismatch with the
    /// station): named in the device's last error.
    WrongType {
        tag: String,
        expected: &'static str,
        got: &'static str,
    },
}

impl PointMap {
    pub fn insert(&mut self, ioa: u32, tag: PointTag) {
        self.by_ioa.insert(ioa, tag);
    }

    pub fn ids(&self) -> Vec<TagId> {
        self.by_ioa.values().map(|t| t.id).collect()
    }

    /// The sample of `object`, received at `received`. `previous` is the
    /// tag's current value, kept where the object carries no usable one
    /// (a bool tag on a double point in its intermediate position).
    pub fn sample(
        &self,
        object: &InformationObject,
        received: Timestamp,
        previous: impl FnOnce(TagId) -> Option<Value>,
    ) -> Outcome {
        let Some(tag) = self.by_ioa.get(&object.ioa) else {
            return Outcome::Unmapped;
        };
        let (raw, quality) = match raw_value(&object.element) {
            Some(v) => v,
            None => return Outcome::Unmapped,
        };
        if !fits(tag.point, &object.element) {
            return Outcome::WrongType {
                tag: tag.name.clone(),
                expected: tag.point.label(),
                got: object.element.kind(),
            };
        }
        let mut reasons = quality_reasons(quality);
        let value = match (raw, tag.kind) {
            (Raw::Double(state), ValueKind::Bool) => match state {
                DoublePoint::On => Value::Bool(true),
                DoublePoint::Off => Value::Bool(false),
                DoublePoint::Intermediate => {
                    reasons.push(("intermediate position (moving)", false));
                    previous(tag.id).unwrap_or(Value::Bool(false))
                }
                DoublePoint::Indeterminate => {
                    reasons.push(("indeterminate (faulty) position", true));
                    previous(tag.id).unwrap_or(Value::Bool(false))
                }
            },
            (Raw::Double(state), _) => {
                if state == DoublePoint::Indeterminate {
                    reasons.push(("indeterminate (faulty) position", true));
                }
                Value::Int(i64::from(state.bits()))
            }
            (Raw::Bool(b), _) => Value::Bool(b),
            (Raw::Int(i), ValueKind::Float) => Value::Float(i as f64 * tag.scale + tag.offset),
            (Raw::Int(i), _) if tag.scale != 1.0 || tag.offset != 0.0 => {
                Value::Float(i as f64 * tag.scale + tag.offset)
            }
            (Raw::Int(i), _) => Value::Int(i),
            (Raw::Float(f), _) => Value::Float(f * tag.scale + tag.offset),
        };
        // The station's own time tag is the sequence-of-events record; one
        // it marks invalid (IV of CP56Time2a) gives way to the receive time.
        let timestamp = object
            .time
            .filter(|t| !t.invalid)
            .and_then(|t| t.to_unix_ms().ok())
            .map(Timestamp::from_millis)
            .unwrap_or(received);
        if object.time.is_some_and(|t| t.invalid) {
            reasons.push((
                "the station marked its time tag invalid: receive time",
                false,
            ));
        }
        Outcome::Sample(
            tag.id,
            Sample {
                value,
                quality: tag_quality(&reasons),
                timestamp,
            },
        )
    }
}

/// The raw value of a monitoring element with its quality descriptor.
enum Raw {
    Bool(bool),
    Double(DoublePoint),
    Int(i64),
    Float(f64),
}

fn raw_value(e: &Element) -> Option<(Raw, Quality)> {
    Some(match *e {
        Element::Single { on, quality } => (Raw::Bool(on), quality),
        Element::Double { state, quality } => (Raw::Double(state), quality),
        // A transient step (the tap changer moving) is still a value.
        Element::Step { value, quality, .. } => (Raw::Int(i64::from(value)), quality),
        Element::Bitstring { bits, quality } => (Raw::Int(i64::from(bits)), quality),
        Element::Normalized { value, quality } => (
            Raw::Float(normalized_to_f64(value)),
            quality.unwrap_or(Quality::GOOD),
        ),
        Element::Scaled { value, quality } => (Raw::Int(i64::from(value)), quality),
        Element::Float { value, quality } => (Raw::Float(f64::from(value)), quality),
        Element::Counter {
            value,
            carry,
            adjusted,
            invalid,
            ..
        } => {
            let mut q = Quality::GOOD;
            q.set(Quality::IV, invalid);
            // Carry (the counter wrapped in the period) and adjusted are
            // worth a word, like overflow.
            q.set(Quality::OV, carry || adjusted);
            (Raw::Int(i64::from(value)), q)
        }
        _ => return None,
    })
}

/// Whether a monitoring element is of the tag's configured point type.
fn fits(point: Iec104Point, e: &Element) -> bool {
    matches!(
        (point, e),
        (Iec104Point::M_SP, Element::Single { .. })
            | (Iec104Point::M_DP, Element::Double { .. })
            | (Iec104Point::M_ST, Element::Step { .. })
            | (Iec104Point::M_BO, Element::Bitstring { .. })
            | (Iec104Point::M_ME_NA, Element::Normalized { .. })
            | (Iec104Point::M_ME_NB, Element::Scaled { .. })
            | (Iec104Point::M_ME_NC, Element::Float { .. })
            | (Iec104Point::M_IT, Element::Counter { .. })
    )
}

/// Each quality bit in words, and whether it makes the value bad (IV) or
/// only uncertain (NT, SB, BL, OV).
fn quality_reasons(q: Quality) -> Vec<(&'static str, bool)> {
    let mut out = Vec::new();
    if q.contains(Quality::IV) {
        out.push(("invalid (IV)", true));
    }
    if q.contains(Quality::NT) {
        out.push(("not topical (NT): not updated by the station lately", false));
    }
    if q.contains(Quality::SB) {
        out.push(("substituted (SB) by an operator or automation", false));
    }
    if q.contains(Quality::BL) {
        out.push(("blocked (BL) for transmission", false));
    }
    if q.contains(Quality::OV) {
        out.push(("overflow (OV)", false));
    }
    out
}

fn tag_quality(reasons: &[(&str, bool)]) -> TagQuality {
    if reasons.is_empty() {
        return TagQuality::GOOD;
    }
    let words = reasons
        .iter()
        .map(|(r, _)| *r)
        .collect::<Vec<_>>()
        .join("; ");
    if reasons.iter().any(|(_, bad)| *bad) {
        TagQuality::bad(words)
    } else {
        TagQuality::uncertain(words)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Cp56Time2a;
    use gridscada_tagdb::QualityCode;

    fn tag(point: Iec104Point, kind: ValueKind, scale: f64) -> PointTag {
        PointTag {
            id: TagId(0),
            name: "RTU1.Q1".into(),
            point,
            kind,
            scale,
            offset: 0.0,
        }
    }

    fn map(t: PointTag) -> PointMap {
        let mut m = PointMap::default();
        m.insert(1001, t);
        m
    }

    fn sample(m: &PointMap, e: Element, time: Option<Cp56Time2a>) -> Sample {
        let mut o = InformationObject::new(1001, e);
        o.time = time;
        match m.sample(&o, Timestamp::from_millis(5_000), |_| {
            Some(Value::Bool(true))
        }) {
            Outcome::Sample(_, s) => s,
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn the_station_time_tag_is_the_timestamp_to_the_millisecond() {
        let m = map(tag(Iec104Point::M_SP, ValueKind::Bool, 1.0));
        let at = 1_795_000_123_456;
        let t = Cp56Time2a::from_unix_ms(at).unwrap();
        let s = sample(
            &m,
            Element::Single {
                on: true,
                quality: Quality::GOOD,
            },
            Some(t),
        );
        assert_eq!(s.timestamp.as_millis(), at);
        assert!(s.quality.is_good());
        // No time tag: the receive time.
        let s = sample(
            &m,
            Element::Single {
                on: false,
                quality: Quality::GOOD,
            },
            None,
        );
        assert_eq!(s.timestamp.as_millis(), 5_000);
        // A time tag marked invalid: the receive time, said in words.
        let s = sample(
            &m,
            Element::Single {
                on: false,
                quality: Quality::GOOD,
            },
            Some(t.with_invalid(true)),
        );
        assert_eq!(s.timestamp.as_millis(), 5_000);
        assert_eq!(s.quality.code, QualityCode::Uncertain);
    }

    #[test]
    fn every_quality_bit_is_named_and_iv_is_bad() {
        let m = map(tag(Iec104Point::M_ME_NC, ValueKind::Float, 1.0));
        let s = sample(
            &m,
            Element::Float {
                value: 1.5,
                quality: Quality::ALL,
            },
            None,
        );
        assert_eq!(s.quality.code, QualityCode::Bad);
        let r = s.quality.reason.unwrap();
        for word in [
            "invalid",
            "not topical",
            "substituted",
            "blocked",
            "overflow",
        ] {
            assert!(r.contains(word), "{r}");
        }
        let s = sample(
            &m,
            Element::Float {
                value: 1.5,
                quality: Quality::NT,
            },
            None,
        );
        assert_eq!(s.quality.code, QualityCode::Uncertain);
        assert_eq!(s.value, Value::Float(1.5));
    }

    #[test]
    fn double_points_on_bool_and_integer_tags() {
        let b = map(tag(Iec104Point::M_DP, ValueKind::Bool, 1.0));
        let d = |state| Element::Double {
            state,
            quality: Quality::GOOD,
        };
        assert_eq!(
            sample(&b, d(DoublePoint::On), None).value,
            Value::Bool(true)
        );
        assert_eq!(
            sample(&b, d(DoublePoint::Off), None).value,
            Value::Bool(false)
        );
        let moving = sample(&b, d(DoublePoint::Intermediate), None);
        assert_eq!(moving.quality.code, QualityCode::Uncertain);
        assert_eq!(moving.value, Value::Bool(true), "keeps the last position");
        let faulty = sample(&b, d(DoublePoint::Indeterminate), None);
        assert_eq!(faulty.quality.code, QualityCode::Bad);
        let i = map(tag(Iec104Point::M_DP, ValueKind::Int, 1.0));
        assert_eq!(sample(&i, d(DoublePoint::On), None).value, Value::Int(2));
        assert!(sample(&i, d(DoublePoint::Intermediate), None)
            .quality
            .is_good());
    }

    #[test]
    fn measurands_are_scaled_and_the_wrong_type_is_named() {
        let m = map(tag(Iec104Point::M_ME_NB, ValueKind::Float, 0.1));
        let s = sample(
            &m,
            Element::Scaled {
                value: 2305,
                quality: Quality::GOOD,
            },
            None,
        );
        assert_eq!(s.value, Value::Float(230.5));
        let o = InformationObject::new(
            1001,
            Element::Single {
                on: true,
                quality: Quality::GOOD,
            },
        );
        assert!(matches!(
            m.sample(&o, Timestamp::from_millis(0), |_| None),
            Outcome::WrongType {
                expected: "M_ME_NB",
                ..
            }
        ));
        let o = InformationObject::new(
            7,
            Element::Single {
                on: true,
                quality: Quality::GOOD,
            },
        );
        assert_eq!(
            m.sample(&o, Timestamp::from_millis(0), |_| None),
            Outcome::Unmapped
        );
    }
}
