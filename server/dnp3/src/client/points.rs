//! From DNP3 measurements to tag samples: which tag a point (type and
//! index) feeds, its engineering value (scaling, double-bit binaries), its
//! flags as quality with the reason in words, and the outstation's event
//! time as the sample's timestamp. Pure.

use std::collections::HashMap;

use gridscada_config::{Dnp3Point, TagConfig};
use gridscada_tagdb::{Quality as TagQuality, Sample, TagId, Timestamp, Value, ValueKind};

use crate::objects::{DoubleBit, Measurement, MeasurementKind, Quality, Value as DnpValue};

/// One monitored tag of an outstation.
#[derive(Debug, Clone)]
pub(crate) struct PointTag {
    pub id: TagId,
    pub kind: ValueKind,
    pub scale: f64,
    pub offset: f64,
}

impl PointTag {
    pub fn new(id: TagId, t: &TagConfig) -> PointTag {
        PointTag {
            id,
            kind: t.value_kind(),
            scale: *t.scale.get_ref(),
            offset: t.offset,
        }
    }
}

/// The measurement kind a configured point type arrives as.
pub fn kind_of(point: Dnp3Point) -> MeasurementKind {
    match point {
        Dnp3Point::BinaryInput => MeasurementKind::Binary,
        Dnp3Point::DoubleBit => MeasurementKind::DoubleBit,
        Dnp3Point::BinaryOutput => MeasurementKind::BinaryOutputStatus,
        Dnp3Point::Counter => MeasurementKind::Counter,
        Dnp3Point::FrozenCounter => MeasurementKind::FrozenCounter,
        Dnp3Point::AnalogInput => MeasurementKind::Analog,
        Dnp3Point::AnalogOutput => MeasurementKind::AnalogOutputStatus,
    }
}

/// The monitored tags of one outstation by point type and index.
#[derive(Debug, Default)]
pub(crate) struct PointMap {
    by_point: HashMap<(MeasurementKind, u16), PointTag>,
}

impl PointMap {
    pub fn insert(&mut self, point: Dnp3Point, index: u16, tag: PointTag) {
        self.by_point.insert((kind_of(point), index), tag);
    }

    pub fn ids(&self) -> Vec<TagId> {
        self.by_point.values().map(|t| t.id).collect()
    }

    /// The sample of `m`, received at `received`; `None` when no tag is on
    /// the point. `previous` is the tag's current value, kept where the
    /// measurement carries no usable one (a bool tag on a double-bit
    /// binary between positions).
    pub fn sample(
        &self,
        m: &Measurement,
        received: Timestamp,
        previous: impl FnOnce(TagId) -> Option<Value>,
    ) -> Option<(TagId, Sample)> {
        let tag = self.by_point.get(&(m.kind, m.index))?;
        let (class, words) = m.flags.quality();
        let mut reasons: Vec<(String, bool)> = match class {
            Quality::Good => Vec::new(),
            Quality::Uncertain => vec![(words, false)],
            Quality::Bad => vec![(words, true)],
        };
        let scaled = tag.scale != 1.0 || tag.offset != 0.0;
        let value = match (m.value, tag.kind) {
            (DnpValue::DoubleBit(state), ValueKind::Bool) => match state {
                DoubleBit::On => Value::Bool(true),
                DoubleBit::Off => Value::Bool(false),
                DoubleBit::Intermediate => {
                    reasons.push(("intermediate position (moving)".into(), false));
                    previous(tag.id).unwrap_or(Value::Bool(false))
                }
                DoubleBit::Indeterminate => {
                    reasons.push(("indeterminate (faulty) position".into(), true));
                    previous(tag.id).unwrap_or(Value::Bool(false))
                }
            },
            (DnpValue::DoubleBit(state), _) => {
                if state == DoubleBit::Indeterminate {
                    reasons.push(("indeterminate (faulty) position".into(), true));
                }
                Value::Int(match state {
                    DoubleBit::Intermediate => 0,
                    DoubleBit::Off => 1,
                    DoubleBit::On => 2,
                    DoubleBit::Indeterminate => 3,
                })
            }
            (DnpValue::Binary(b), _) => Value::Bool(b),
            (DnpValue::Counter(i), ValueKind::Float) => {
                Value::Float(i as f64 * tag.scale + tag.offset)
            }
            (DnpValue::Counter(i), _) if scaled => Value::Float(i as f64 * tag.scale + tag.offset),
            (DnpValue::Counter(i), _) => Value::Int(i),
            (DnpValue::Analog(f), ValueKind::Int) if !scaled => Value::Int(f.round() as i64),
            (DnpValue::Analog(f), _) => Value::Float(f * tag.scale + tag.offset),
        };
        let timestamp = m
            .time
            .and_then(|t| i64::try_from(t).ok())
            .map(Timestamp::from_millis)
            .unwrap_or(received);
        Some((
            tag.id,
            Sample {
                value,
                quality: tag_quality(&reasons),
                timestamp,
            },
        ))
    }
}

fn tag_quality(reasons: &[(String, bool)]) -> TagQuality {
    if reasons.is_empty() {
        return TagQuality::GOOD;
    }
    let words = reasons
        .iter()
        .map(|(r, _)| r.as_str())
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
    use crate::objects::Flags;
    use gridscada_tagdb::QualityCode;

    fn map(point: Dnp3Point, kind: ValueKind, scale: f64) -> PointMap {
        let mut m = PointMap::default();
        m.insert(
            point,
            7,
            PointTag {
                id: TagId(0),
                kind,
                scale,
                offset: 0.0,
            },
        );
        m
    }

    fn m(kind: MeasurementKind, value: DnpValue, flags: Flags, time: Option<u64>) -> Measurement {
        Measurement {
            kind,
            index: 7,
            value,
            flags,
            time,
            is_event: time.is_some(),
        }
    }

    #[test]
    fn flags_become_quality_in_words_and_event_time_the_timestamp() {
        let pm = map(Dnp3Point::AnalogInput, ValueKind::Float, 0.1);
        let (_, s) = pm
            .sample(
                &m(
                    MeasurementKind::Analog,
                    DnpValue::Analog(2305.0),
                    Flags::ONLINE,
                    Some(1_795_000_123_456),
                ),
                Timestamp::from_millis(5),
                |_| None,
            )
            .unwrap();
        assert!(s.quality.is_good());
        assert_eq!(s.timestamp.as_millis(), 1_795_000_123_456);
        assert!(matches!(s.value, Value::Float(v) if (v - 230.5).abs() < 1e-9));
        let (_, s) = pm
            .sample(
                &m(
                    MeasurementKind::Analog,
                    DnpValue::Analog(1.0),
                    Flags::ONLINE | Flags::OVER_RANGE,
                    None,
                ),
                Timestamp::from_millis(5),
                |_| None,
            )
            .unwrap();
        assert_eq!(s.quality.code, QualityCode::Uncertain);
        assert!(s.quality.reason.unwrap().contains("over range"));
        assert_eq!(s.timestamp.as_millis(), 5);
        let (_, s) = pm
            .sample(
                &m(
                    MeasurementKind::Analog,
                    DnpValue::Analog(1.0),
                    Flags(0),
                    None,
                ),
                Timestamp::from_millis(5),
                |_| None,
            )
            .unwrap();
        assert_eq!(s.quality.code, QualityCode::Bad);
        assert!(s.quality.reason.unwrap().contains("offline"));
        // Another point type on the same index feeds no tag.
        assert!(pm
            .sample(
                &m(
                    MeasurementKind::Counter,
                    DnpValue::Counter(1),
                    Flags::ONLINE,
                    None
                ),
                Timestamp::from_millis(5),
                |_| None,
            )
            .is_none());
    }

    #[test]
    fn double_bits_on_bool_tags_keep_the_last_position_while_moving() {
        let pm = map(Dnp3Point::DoubleBit, ValueKind::Bool, 1.0);
        let s = |d| {
            pm.sample(
                &m(
                    MeasurementKind::DoubleBit,
                    DnpValue::DoubleBit(d),
                    Flags::ONLINE,
                    None,
                ),
                Timestamp::from_millis(0),
                |_| Some(Value::Bool(true)),
            )
            .unwrap()
            .1
        };
        assert_eq!(s(DoubleBit::Off).value, Value::Bool(false));
        let moving = s(DoubleBit::Intermediate);
        assert_eq!(moving.value, Value::Bool(true));
        assert_eq!(moving.quality.code, QualityCode::Uncertain);
        assert_eq!(s(DoubleBit::Indeterminate).quality.code, QualityCode::Bad);
    }
}
