//! From IEC 61850 values to tag samples, pure: which leaf of a data
//! object (or dataset member) each tag reads, with the `q` and `t` of the
//! data object that holds it; the value converted to the tag's type and
//! scaled; the IED's quality as the sample's quality with the reason in
//! words; the IED's timestamp (and its time quality) as the sample's.

use std::collections::HashMap;

use gridscada_config::{DataType, Iec61850TagConfig, ObjectRef, TagConfig};
use gridscada_tagdb::{Quality as TagQuality, Sample, TagId, Timestamp, Value, ValueKind};

use crate::data::{Data, Quality, UtcTime};
use crate::mms::ObjectName;

/// One monitored tag of an IED.
#[derive(Debug, Clone)]
pub(crate) struct IedTag {
    pub id: TagId,
    /// The logical device (MMS domain).
    pub domain: String,
    /// `LN$FC$DO`: the data object the tag is read with.
    pub data_object: String,
    /// The full item of the value: `LN$FC$DO$DA…`.
    pub item: String,
    pub kind: ValueKind,
    pub data_type: DataType,
    pub scale: f64,
    pub offset: f64,
}

impl IedTag {
    pub fn new(id: TagId, t: &TagConfig, p: &Iec61850TagConfig) -> Result<IedTag, String> {
        let o = ObjectRef::parse(p.reference.get_ref())?;
        let fc = p.fc.get_ref().label();
        let Some(first) = o.path.first() else {
            return Err(format!(
                "ref '{}' names no data object",
                p.reference.get_ref()
            ));
        };
        Ok(IedTag {
            id,
            domain: o.ld.to_string(),
            data_object: format!("{}${fc}${first}", o.ln),
            item: o.mms_item(fc),
            kind: t.value_kind(),
            data_type: t.data_type(),
            scale: *t.scale.get_ref(),
            offset: t.offset,
        })
    }

    pub fn object(&self) -> ObjectName {
        ObjectName::Domain(self.domain.clone(), self.data_object.clone())
    }
}

/// Where one tag's value, quality and time are among a value's leaves.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct Binding {
    pub tag: usize,
    pub value: usize,
    pub quality: Option<usize>,
    pub time: Option<usize>,
}

/// The bindings of `tags` to the leaves of one variable: `item` in
/// `domain`, whose type has `leaves` (relative `$`-paths; one empty path
/// for a primitive variable).
pub(crate) fn bind(domain: &str, item: &str, leaves: &[String], tags: &[IedTag]) -> Vec<Binding> {
    let full = |leaf: &str| {
        if leaf.is_empty() {
            item.to_string()
        } else {
            format!("{item}${leaf}")
        }
    };
    let index: HashMap<String, usize> = leaves
        .iter()
        .enumerate()
        .map(|(i, l)| (full(l), i))
        .collect();
    let mut out = Vec::new();
    for (i, t) in tags.iter().enumerate().filter(|(_, t)| t.domain == domain) {
        let Some(&value) = index.get(&t.item) else {
            continue;
        };
        // The q and t of the innermost data object holding the value: try
        // each shorter prefix of the path down to the data object itself.
        let mut quality = None;
        let mut time = None;
        let parts: Vec<&str> = t.item.split('$').collect();
        for end in (3..parts.len()).rev() {
            let prefix = parts[..end].join("$");
            let q = index.get(&format!("{prefix}$q")).copied();
            let tm = index.get(&format!("{prefix}$t")).copied();
            if q.is_some() || tm.is_some() {
                quality = q;
                time = tm;
                break;
            }
        }
        out.push(Binding {
            tag: i,
            value,
            quality,
            time,
        });
    }
    out
}

/// The leaves of a value in the order of its type's leaves.
pub(crate) fn flatten<'a>(d: &'a Data, out: &mut Vec<&'a Data>) {
    match d {
        Data::Structure(items) => items.iter().for_each(|i| flatten(i, out)),
        other => out.push(other),
    }
}

/// The sample of `tag` from its value leaf and the quality and time
/// leaves beside it; `None` if the value cannot be the tag's (the reason
/// is then the quality of a bad sample instead).
pub(crate) fn sample(
    tag: &IedTag,
    value: &Data,
    quality: Option<&Data>,
    time: Option<&Data>,
    received: Timestamp,
    previous: impl Fn(TagId) -> Option<Value>,
) -> Sample {
    let mut uncertain: Vec<String> = Vec::new();
    let mut bad: Vec<String> = Vec::new();
    // Said of a good value without making it less than good.
    let mut notes: Vec<String> = Vec::new();
    if let Some(Data::BitString(b)) = quality {
        let q = Quality::from_bits(b);
        if let Some(words) = q.describe() {
            // Invalid is Bad; questionable, or good with a detail flag, Uncertain.
            if q.validity() == "invalid" {
                bad.push(words);
            } else {
                uncertain.push(words);
            }
        }
    }
    let mut timestamp = received;
    if let Some(Data::UtcTime(t)) = time {
        // An IED that never set the time sends 1970: keep the receive time.
        if t.seconds > 0 {
            timestamp = Timestamp::from_millis(t.unix_ms());
            // A failed clock makes the time unusable; an unsynchronised
            // one is still the IED's best account of when it happened.
            if t.quality & UtcTime::CLOCK_FAILURE != 0 {
                uncertain.push("time: the IED's clock has failed".into());
            } else if let Some(trouble) = t.clock_trouble() {
                notes.push(format!("time: {trouble}"));
            }
        }
    }
    let scaled = tag.scale != 1.0 || tag.offset != 0.0;
    let number = |n: f64| {
        if scaled || tag.kind == ValueKind::Float {
            Value::Float(n * tag.scale + tag.offset)
        } else {
            Value::Int(n.round() as i64)
        }
    };
    let v = match (value, tag.data_type) {
        // A Dbpos (2-bit string) on a bool tag: on/off, the others kept
        // with the reason in the quality.
        (Data::BitString(b), DataType::Bool) if b.len == 2 => match b.to_u32() {
            2 => Some(Value::Bool(true)),
            1 => Some(Value::Bool(false)),
            0 => {
                uncertain.push("intermediate position (moving)".into());
                Some(previous(tag.id).unwrap_or(Value::Bool(false)))
            }
            _ => {
                bad.push("bad position (both contacts)".into());
                Some(previous(tag.id).unwrap_or(Value::Bool(false)))
            }
        },
        (Data::BitString(b), _) => {
            if b.len == 2 && b.to_u32() == 3 {
                bad.push("bad position (both contacts)".into());
            }
            Some(number(f64::from(b.to_u32())))
        }
        (Data::Boolean(b), DataType::Bool) => Some(Value::Bool(*b)),
        (Data::Boolean(b), _) => Some(number(f64::from(u8::from(*b)))),
        (Data::Integer(_) | Data::Unsigned(_), DataType::Bool) => {
            value.as_f64().map(|n| Value::Bool(n != 0.0))
        }
        (Data::Integer(n), _) if !scaled && tag.kind == ValueKind::Int => Some(Value::Int(*n)),
        (Data::Unsigned(n), _) if !scaled && tag.kind == ValueKind::Int => {
            Some(Value::from_u64(*n))
        }
        (Data::Integer(_) | Data::Unsigned(_) | Data::Float(_), DataType::String) => {
            value.as_f64().map(|n| Value::Str(n.to_string().into()))
        }
        (Data::Integer(_) | Data::Unsigned(_) | Data::Float(_), _) => value.as_f64().map(number),
        (Data::VisibleString(s) | Data::MmsString(s), DataType::String) => {
            Some(Value::Str(s.as_str().into()))
        }
        (Data::UtcTime(t), DataType::String) => Some(Value::Str(
            Timestamp::from_millis(t.unix_ms()).utc_text().into(),
        )),
        _ => None,
    };
    let Some(v) = v else {
        return Sample {
            value: previous(tag.id).unwrap_or(Value::Float(0.0)),
            quality: TagQuality::bad(format!(
                "the IED sends {} for {}, which a {} tag cannot hold",
                value.kind(),
                tag.item,
                tag.data_type.label()
            )),
            timestamp,
        };
    };
    let quality = if !bad.is_empty() {
        bad.extend(uncertain);
        TagQuality::bad(bad.join("; "))
    } else if !uncertain.is_empty() {
        TagQuality::uncertain(uncertain.join("; "))
    } else if !notes.is_empty() {
        TagQuality {
            code: gridscada_tagdb::QualityCode::Good,
            reason: Some(notes.join("; ").into()),
        }
    } else {
        TagQuality::GOOD
    };
    Sample {
        value: v,
        quality,
        timestamp,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ber::BitString;
    use gridscada_tagdb::QualityCode;

    fn tag(item: &str, data_type: DataType, kind: ValueKind) -> IedTag {
        let parts: Vec<&str> = item.split('$').collect();
        IedTag {
            id: TagId(0),
            domain: "LD".into(),
            data_object: parts[..3].join("$"),
            item: item.into(),
            kind,
            data_type,
            scale: 1.0,
            offset: 0.0,
        }
    }

    #[test]
    fn bindings_find_the_innermost_q_and_t() {
        let leaves: Vec<String> = [
            "phsA$cVal$mag$f",
            "phsA$q",
            "phsA$t",
            "phsB$cVal$mag$f",
            "phsB$q",
            "phsB$t",
        ]
        .iter()
        .map(|s| s.to_string())
        .collect();
        let tags = vec![tag(
            "MMXU1$MX$PhV$phsB$cVal$mag$f",
            DataType::F32,
            ValueKind::Float,
        )];
        let b = bind("LD", "MMXU1$MX$PhV", &leaves, &tags);
        assert_eq!(
            b,
            vec![Binding {
                tag: 0,
                value: 3,
                quality: Some(4),
                time: Some(5)
            }]
        );
        // A dataset member at the attribute itself: no q or t beside it.
        let b = bind(
            "LD",
            "MMXU1$MX$PhV$phsB$cVal$mag$f",
            &[String::new()],
            &tags,
        );
        assert_eq!(
            b,
            vec![Binding {
                tag: 0,
                value: 0,
                quality: None,
                time: None
            }]
        );
        assert!(bind("OTHER", "MMXU1$MX$PhV", &leaves, &tags).is_empty());
    }

    #[test]
    fn samples_carry_the_ieds_quality_and_time() {
        let t = tag("XCBR1$ST$Pos$stVal", DataType::U16, ValueKind::Int);
        let pos = Data::BitString(BitString::from_bits(&[true, false]));
        let q = Data::BitString(BitString::from_bits(&[
            true, true, false, false, false, false, false, true,
        ]));
        let time = Data::UtcTime(UtcTime::from_unix_ms(
            1_764_000_000_500,
            UtcTime::CLOCK_NOT_SYNCHRONIZED,
        ));
        let s = sample(
            &t,
            &pos,
            Some(&q),
            Some(&time),
            Timestamp::from_millis(1),
            |_| None,
        );
        assert_eq!(s.value, Value::Int(2));
        assert_eq!(s.timestamp, Timestamp::from_millis(1_764_000_000_500));
        assert_eq!(s.quality.code, QualityCode::Uncertain);
        assert_eq!(s.quality.reason.as_deref(), Some("questionable: old data"));
        let s = sample(
            &t,
            &pos,
            None,
            Some(&time),
            Timestamp::from_millis(1),
            |_| None,
        );
        assert_eq!(s.quality.code, QualityCode::Good);
        assert_eq!(
            s.quality.reason.as_deref(),
            Some("time: the IED's clock is not synchronised")
        );
        let b = tag("XCBR1$ST$Pos$stVal", DataType::Bool, ValueKind::Bool);
        let moving = Data::BitString(BitString::from_bits(&[false, false]));
        let s = sample(&b, &moving, None, None, Timestamp::from_millis(1), |_| {
            Some(Value::Bool(true))
        });
        assert_eq!(
            (s.value, s.quality.code),
            (Value::Bool(true), QualityCode::Uncertain)
        );
        let s = sample(
            &b,
            &Data::VisibleString("x".into()),
            None,
            None,
            Timestamp::from_millis(1),
            |_| None,
        );
        assert_eq!(s.quality.code, QualityCode::Bad);
    }
}
