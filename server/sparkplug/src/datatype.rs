//! Sparkplug B metric data types, and a tag value on the wire.

use std::sync::Arc;

use gridscada_tagdb::{Value, ValueKind};

use crate::proto::MetricValue;

/// The metric data type codes of Sparkplug B (the `datatype` field).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum DataType {
    Int8 = 1,
    Int16 = 2,
    Int32 = 3,
    Int64 = 4,
    UInt8 = 5,
    UInt16 = 6,
    UInt32 = 7,
    UInt64 = 8,
    Float = 9,
    Double = 10,
    Boolean = 11,
    String = 12,
    DateTime = 13,
    Text = 14,
    Uuid = 15,
    Bytes = 17,
}

impl DataType {
    pub fn code(self) -> u32 {
        self as u32
    }

    pub fn from_code(code: u32) -> Option<DataType> {
        use DataType::*;
        Some(match code {
            1 => Int8,
            2 => Int16,
            3 => Int32,
            4 => Int64,
            5 => UInt8,
            6 => UInt16,
            7 => UInt32,
            8 => UInt64,
            9 => Float,
            10 => Double,
            11 => Boolean,
            12 => String,
            13 => DateTime,
            14 => Text,
            15 => Uuid,
            17 => Bytes,
            _ => return None,
        })
    }

    /// The data type a tag of this kind is published as. Integers go out as
    /// Int64 (UInt64 for a u64 register above `i64::MAX` would not fit a
    /// birth that must name one type, so a u64 tag is declared UInt64 by the
    /// caller that knows the register type).
    pub fn for_kind(kind: ValueKind) -> DataType {
        match kind {
            ValueKind::Bool => DataType::Boolean,
            ValueKind::Int => DataType::Int64,
            ValueKind::Float => DataType::Double,
            ValueKind::Str => DataType::String,
        }
    }
}

/// Why a metric value could not be read as a tag value.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ValueError {
    #[error("data type {0} is not one gridscada reads")]
    UnsupportedType(u32),
    #[error("a {expected:?} metric carries a value of another wire type")]
    WrongWireType { expected: DataType },
    #[error("the metric has no value")]
    Missing,
}

/// A tag value as a metric value of the given data type.
pub fn encode(value: &Value, datatype: DataType) -> MetricValue {
    use DataType::*;
    match (datatype, value) {
        (Boolean, v) => MetricValue::Boolean(v.as_f64().is_some_and(|f| f != 0.0)),
        (Float, v) => MetricValue::Float(v.as_f64().unwrap_or(f64::NAN) as f32),
        (Double, v) => MetricValue::Double(v.as_f64().unwrap_or(f64::NAN)),
        (String | Text | Uuid, v) => MetricValue::String(display(v)),
        (Int8 | Int16 | Int32 | UInt8 | UInt16 | UInt32, v) => MetricValue::Int(integer(v) as u32),
        (Int64 | UInt64 | DateTime, Value::UInt(u)) => MetricValue::Long(*u),
        (Int64 | UInt64 | DateTime, v) => MetricValue::Long(integer(v) as u64),
        (Bytes, v) => MetricValue::Bytes(display(v).into_bytes()),
    }
}

/// A metric value of the given data type as a tag value.
pub fn decode(value: Option<&MetricValue>, datatype: u32) -> Result<Value, ValueError> {
    let value = value.ok_or(ValueError::Missing)?;
    let ty = DataType::from_code(datatype).ok_or(ValueError::UnsupportedType(datatype))?;
    let wrong = || ValueError::WrongWireType { expected: ty };
    use DataType::*;
    Ok(match (ty, value) {
        (Boolean, MetricValue::Boolean(b)) => Value::Bool(*b),
        (Int8, MetricValue::Int(i)) => Value::Int(i64::from(*i as i8)),
        (Int16, MetricValue::Int(i)) => Value::Int(i64::from(*i as i16)),
        (Int32, MetricValue::Int(i)) => Value::Int(i64::from(*i as i32)),
        (UInt8 | UInt16 | UInt32, MetricValue::Int(i)) => Value::Int(i64::from(*i)),
        (Int64 | DateTime, MetricValue::Long(l)) => Value::Int(*l as i64),
        (UInt64, MetricValue::Long(l)) => Value::from_u64(*l),
        (Float, MetricValue::Float(f)) => Value::Float(f64::from(*f)),
        (Double, MetricValue::Double(f)) => Value::Float(*f),
        (String | Text | Uuid, MetricValue::String(s)) => Value::Str(Arc::from(s.as_str())),
        _ => return Err(wrong()),
    })
}

fn integer(v: &Value) -> i64 {
    match v {
        Value::Int(i) => *i,
        Value::UInt(u) => *u as i64,
        Value::Bool(b) => i64::from(*b),
        Value::Float(f) => f.round() as i64,
        Value::Str(s) => s.parse().unwrap_or(0),
    }
}

fn display(v: &Value) -> String {
    match v {
        Value::Str(s) => s.to_string(),
        Value::Bool(b) => b.to_string(),
        Value::Int(i) => i.to_string(),
        Value::UInt(u) => u.to_string(),
        Value::Float(f) => f.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_round_trip_through_their_data_types() {
        let cases = [
            (Value::Bool(true), DataType::Boolean),
            (Value::Int(-5), DataType::Int16),
            (Value::Int(-5), DataType::Int64),
            (Value::UInt(u64::MAX), DataType::UInt64),
            (Value::Float(230.5), DataType::Double),
            (Value::Str("LOCKOUT".into()), DataType::String),
        ];
        for (value, ty) in cases {
            let wire = encode(&value, ty);
            assert_eq!(decode(Some(&wire), ty.code()).unwrap(), value, "{ty:?}");
        }
    }

    #[test]
    fn a_mismatched_or_unknown_type_is_an_error_not_a_guess() {
        assert_eq!(
            decode(Some(&MetricValue::Double(1.0)), DataType::Boolean.code()),
            Err(ValueError::WrongWireType {
                expected: DataType::Boolean
            })
        );
        assert_eq!(
            decode(Some(&MetricValue::Int(1)), 99),
            Err(ValueError::UnsupportedType(99))
        );
        assert_eq!(decode(None, 11), Err(ValueError::Missing));
    }
}
