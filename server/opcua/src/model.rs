//! The pure mappings between gridscada's tag model and OPC UA's: quality to
//! status code, a dot-separated name to its folder path, a tag's kind and
//! register type to an OPC UA data type, and values both ways.

use gridscada_config::DataType;
use gridscada_tagdb::{Quality, QualityCode, Sample, Timestamp, Value, ValueKind};
use opcua::types::{DataTypeId, DataValue, DateTime, StatusCode, Variant};

/// The status code a sample of this quality carries. The class follows the
/// quality; the sub-code says why where the reason tells it, so a client
/// can tell a device that does not answer from one that has never been read.
pub fn status_of(q: &Quality) -> StatusCode {
    let reason = q.reason.as_deref().unwrap_or("");
    match q.code {
        QualityCode::Good => StatusCode::Good,
        QualityCode::Uncertain => {
            if reason.contains("NaN") || reason.contains("infinity") {
                StatusCode::UncertainEngineeringUnitsExceeded
            } else if reason.contains("clock") {
                // The value is fine; its timestamp is the receive time.
                StatusCode::UncertainSubstituteValue
            } else {
                StatusCode::Uncertain
            }
        }
        QualityCode::Bad => {
            if reason == gridscada_tagdb::NEVER_READ {
                StatusCode::BadWaitingForInitialData
            } else if [
                "no answer",
                "not answering",
                "communication lost",
                "offline",
                "timeout",
                "timed out",
            ]
            .iter()
            .any(|w| reason.contains(w))
            {
                StatusCode::BadNoCommunication
            } else if reason.contains("illegal data address") || reason.contains("illegal function")
            {
                // The device has no such register: the configuration is wrong.
                StatusCode::BadConfigurationError
            } else if reason.contains("exception")
                || reason.contains("cannot decode")
                || reason.contains("reply too short")
            {
                StatusCode::BadDeviceFailure
            } else {
                StatusCode::Bad
            }
        }
    }
}

/// Where a tag sits in the address space: the folders above it, outermost
/// first, each as (its full dotted path, its own name), and the tag's own
/// browse name. `SS1.Zone2.Closed` sits in `SS1`, then `SS1.Zone2`.
pub fn node_path(name: &str) -> (Vec<(&str, &str)>, &str) {
    let mut folders = Vec::new();
    let mut start = 0;
    for (i, _) in name.match_indices('.') {
        folders.push((&name[..i], &name[start..i]));
        start = i + 1;
    }
    (folders, &name[start..])
}

/// The OPC UA scalar type of a tag: its register's own type where the tag
/// keeps it (an unscaled integer register), otherwise the engineering kind.
/// Scaled registers carry fractions, so they are Double whatever the register.
pub fn data_type_of(kind: ValueKind, register: Option<DataType>) -> DataTypeId {
    match kind {
        ValueKind::Bool => DataTypeId::Boolean,
        ValueKind::Str => DataTypeId::String,
        ValueKind::Float => match register {
            Some(DataType::F32) => DataTypeId::Float,
            _ => DataTypeId::Double,
        },
        ValueKind::Int => match register {
            Some(DataType::I16) => DataTypeId::Int16,
            Some(DataType::U16) => DataTypeId::UInt16,
            Some(DataType::I32) => DataTypeId::Int32,
            Some(DataType::U32) => DataTypeId::UInt32,
            Some(DataType::U64) => DataTypeId::UInt64,
            _ => DataTypeId::Int64,
        },
    }
}

/// A value as a variant of the node's data type; `None` when it does not
/// fit (an integer register reading outside its type cannot happen, but a
/// client must then get a Bad status rather than a wrong number).
pub fn variant_of(value: &Value, ty: DataTypeId) -> Option<Variant> {
    Some(match (ty, value) {
        (DataTypeId::Boolean, v) => Variant::Boolean(v.as_bool()?),
        (DataTypeId::String, v) => Variant::String(v.to_string().into()),
        (DataTypeId::Double, v) => Variant::Double(v.as_f64()?),
        // A float register holds an f32 exactly; the f64 of it narrows back.
        (DataTypeId::Float, v) => Variant::Float(v.as_f64()? as f32),
        (DataTypeId::Int16, v) => Variant::Int16(v.as_i128()?.try_into().ok()?),
        (DataTypeId::UInt16, v) => Variant::UInt16(v.as_i128()?.try_into().ok()?),
        (DataTypeId::Int32, v) => Variant::Int32(v.as_i128()?.try_into().ok()?),
        (DataTypeId::UInt32, v) => Variant::UInt32(v.as_i128()?.try_into().ok()?),
        (DataTypeId::UInt64, v) => Variant::UInt64(v.as_i128()?.try_into().ok()?),
        (DataTypeId::Int64, v) => Variant::Int64(v.as_i128()?.try_into().ok()?),
        _ => return None,
    })
}

/// A written variant as a gridscada value; the command path then coerces it
/// to the tag's kind (refusing what would lose meaning).
pub fn value_of(v: &Variant) -> Option<Value> {
    Some(match v {
        Variant::Boolean(b) => Value::Bool(*b),
        Variant::SByte(i) => Value::Int((*i).into()),
        Variant::Byte(i) => Value::Int((*i).into()),
        Variant::Int16(i) => Value::Int((*i).into()),
        Variant::UInt16(i) => Value::Int((*i).into()),
        Variant::Int32(i) => Value::Int((*i).into()),
        Variant::UInt32(i) => Value::Int((*i).into()),
        Variant::Int64(i) => Value::Int(*i),
        Variant::UInt64(u) => Value::from_u64(*u),
        Variant::Float(f) => Value::Float((*f).into()),
        Variant::Double(f) => Value::Float(*f),
        Variant::String(s) => Value::Str(s.as_ref().into()),
        _ => return None,
    })
}

/// OPC UA time (100 ns ticks since 1601) of a Unix time in milliseconds.
pub fn opc_time(t: Timestamp) -> DateTime {
    const UNIX_EPOCH_MS_SINCE_1601: i64 = 11_644_473_600_000;
    DateTime::from(t.as_millis().saturating_add(UNIX_EPOCH_MS_SINCE_1601) * 10_000)
}

/// The data value of a sample: the value in the node's type, its status,
/// the source timestamp of the reading (none before the first one) and the
/// server timestamp `now`.
pub fn data_value(sample: &Sample, ty: DataTypeId, now: DateTime) -> DataValue {
    let never_read = sample.is_never_read();
    let (value, status) = match variant_of(&sample.value, ty) {
        _ if never_read => (None, StatusCode::BadWaitingForInitialData),
        Some(v) => (Some(v), status_of(&sample.quality)),
        None => (None, StatusCode::BadOutOfRange),
    };
    DataValue {
        value,
        status: Some(status),
        source_timestamp: (!never_read).then(|| opc_time(sample.timestamp)),
        source_picoseconds: None,
        server_timestamp: Some(now),
        server_picoseconds: None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quality_maps_to_a_status_with_a_telling_sub_code() {
        assert_eq!(status_of(&Quality::GOOD), StatusCode::Good);
        let cases = [
            (
                Quality::bad("no value yet"),
                StatusCode::BadWaitingForInitialData,
            ),
            (
                Quality::bad("communication lost: connection refused"),
                StatusCode::BadNoCommunication,
            ),
            (
                Quality::bad("device not answering: timeout"),
                StatusCode::BadNoCommunication,
            ),
            (
                Quality::bad("exception 0x02 illegal data address"),
                StatusCode::BadConfigurationError,
            ),
            (
                Quality::bad("exception 0x04 server device failure"),
                StatusCode::BadDeviceFailure,
            ),
            (Quality::bad("not solved"), StatusCode::Bad),
            (
                Quality::uncertain("device reported NaN"),
                StatusCode::UncertainEngineeringUnitsExceeded,
            ),
            (
                Quality::uncertain("device clock D1.Clock not read: receive time"),
                StatusCode::UncertainSubstituteValue,
            ),
            (Quality::uncertain("something else"), StatusCode::Uncertain),
        ];
        for (q, want) in cases {
            let got = status_of(&q);
            assert_eq!(got, want, "{q}");
            // The class always follows the quality.
            assert_eq!(got.is_bad(), q.code == QualityCode::Bad, "{q}");
            assert_eq!(got.is_uncertain(), q.code == QualityCode::Uncertain, "{q}");
        }
    }

    #[test]
    fn names_become_folder_paths() {
        assert_eq!(
            node_path("SS1.Zone2.Closed"),
            (vec![("SS1", "SS1"), ("SS1.Zone2", "Zone2")], "Closed")
        );
        assert_eq!(node_path("Alone"), (vec![], "Alone"));
        assert_eq!(node_path("A.B"), (vec![("A", "A")], "B"));
    }

    #[test]
    fn data_types_follow_the_register_unless_scaled() {
        use DataType as D;
        assert_eq!(
            data_type_of(ValueKind::Bool, Some(D::Bool)),
            DataTypeId::Boolean
        );
        assert_eq!(
            data_type_of(ValueKind::Int, Some(D::U16)),
            DataTypeId::UInt16
        );
        assert_eq!(
            data_type_of(ValueKind::Int, Some(D::I32)),
            DataTypeId::Int32
        );
        assert_eq!(
            data_type_of(ValueKind::Int, Some(D::U64)),
            DataTypeId::UInt64
        );
        assert_eq!(data_type_of(ValueKind::Int, None), DataTypeId::Int64);
        // A scaled u16 is a float in engineering units.
        assert_eq!(
            data_type_of(ValueKind::Float, Some(D::U16)),
            DataTypeId::Double
        );
        assert_eq!(
            data_type_of(ValueKind::Float, Some(D::F32)),
            DataTypeId::Float
        );
        assert_eq!(
            data_type_of(ValueKind::Str, Some(D::DateTime)),
            DataTypeId::String
        );
    }

    #[test]
    fn values_convert_both_ways_exactly() {
        let big = Value::from_u64(u64::MAX);
        let v = variant_of(&big, DataTypeId::UInt64).unwrap();
        assert_eq!(v, Variant::UInt64(u64::MAX));
        assert_eq!(value_of(&v), Some(big));
        assert_eq!(
            variant_of(&Value::Int(70000), DataTypeId::UInt16),
            None,
            "out of the register's range"
        );
        assert_eq!(
            variant_of(&Value::Int(-5), DataTypeId::Int16),
            Some(Variant::Int16(-5))
        );
        assert_eq!(
            variant_of(&Value::Float(1.5), DataTypeId::Double),
            Some(Variant::Double(1.5))
        );
        assert_eq!(value_of(&Variant::Float(2.5)), Some(Value::Float(2.5)));
        assert_eq!(value_of(&Variant::Empty), None);
    }

    #[test]
    fn samples_carry_status_and_both_timestamps() {
        let now = DateTime::now();
        let s = Sample::good(12.5, Timestamp::from_millis(1_700_000_000_123));
        let dv = data_value(&s, DataTypeId::Double, now);
        assert_eq!(dv.value, Some(Variant::Double(12.5)));
        assert_eq!(dv.status, Some(StatusCode::Good));
        let src = dv.source_timestamp.unwrap().as_chrono();
        assert_eq!(src.timestamp_millis(), 1_700_000_000_123);
        assert_eq!(dv.server_timestamp, Some(now));
        let never = Sample::never_read(Value::Float(0.0));
        let dv = data_value(&never, DataTypeId::Double, now);
        assert_eq!(dv.status, Some(StatusCode::BadWaitingForInitialData));
        assert_eq!((dv.value, dv.source_timestamp), (None, None));
    }
}
