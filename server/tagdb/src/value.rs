//! Tag values, quality and samples.

use std::fmt;
use std::sync::Arc;

use serde::{Deserialize, Serialize};

use crate::Timestamp;

/// The engineering value of a tag, after decoding and scaling.
///
/// Integers are exact end to end. An unsigned 64-bit reading above `i64::MAX`
/// is `UInt`; every other integer is `Int` (construct through
/// [`Value::from_u64`] so that one number has one representation).
///
/// In JSON (the API, the live push, exports) an integer within ±2^53 is a
/// number; one outside it is a string of decimal digits, because a JSON
/// number beyond 2^53 is rounded by JavaScript and most JSON readers. A
/// string of digits written to an integer tag is taken exactly.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(untagged)]
pub enum Value {
    Bool(bool),
    Int(i64),
    /// Only above `i64::MAX` (a u64 register); below it a value is `Int`.
    UInt(u64),
    Float(f64),
    Str(Arc<str>),
}

/// The largest integer that every JSON reader holds exactly (2^53).
pub const JSON_SAFE_INTEGER: u64 = 1 << 53;

impl Serialize for Value {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self {
            Value::Bool(b) => s.serialize_bool(*b),
            Value::Int(i) if i.unsigned_abs() <= JSON_SAFE_INTEGER => s.serialize_i64(*i),
            Value::Int(i) => s.collect_str(i),
            Value::UInt(u) => s.collect_str(u),
            Value::Float(f) => s.serialize_f64(*f),
            Value::Str(t) => s.serialize_str(t),
        }
    }
}

impl Value {
    pub fn kind(&self) -> ValueKind {
        match self {
            Value::Bool(_) => ValueKind::Bool,
            Value::Int(_) | Value::UInt(_) => ValueKind::Int,
            Value::Float(_) => ValueKind::Float,
            Value::Str(_) => ValueKind::Str,
        }
    }

    /// The value as a number, for alarms, trends and control loops.
    /// Booleans read as 0/1; strings have no numeric value.
    pub fn as_f64(&self) -> Option<f64> {
        match self {
            Value::Bool(b) => Some(if *b { 1.0 } else { 0.0 }),
            Value::Int(i) => Some(*i as f64),
            Value::UInt(u) => Some(*u as f64),
            Value::Float(f) => Some(*f),
            Value::Str(_) => None,
        }
    }

    /// An unsigned integer in its one representation: `Int` up to `i64::MAX`.
    pub fn from_u64(u: u64) -> Value {
        i64::try_from(u).map_or(Value::UInt(u), Value::Int)
    }

    /// The exact integer, for integer values (and a string of decimal digits,
    /// the JSON form of an integer beyond 2^53).
    pub fn as_i128(&self) -> Option<i128> {
        match self {
            Value::Int(i) => Some(i128::from(*i)),
            Value::UInt(u) => Some(i128::from(*u)),
            Value::Str(s) => parse_integer(s),
            _ => None,
        }
    }

    /// Whether the value is an integer that a JSON number would not hold
    /// exactly (outside ±2^53).
    pub fn is_wide_integer(&self) -> bool {
        match self {
            Value::Int(i) => i.unsigned_abs() > JSON_SAFE_INTEGER,
            Value::UInt(_) => true,
            _ => false,
        }
    }

    /// The value as a boolean: non-zero numbers are true.
    pub fn as_bool(&self) -> Option<bool> {
        match self {
            Value::Bool(b) => Some(*b),
            Value::Int(i) => Some(*i != 0),
            Value::UInt(_) => Some(true),
            Value::Float(f) => Some(*f != 0.0),
            Value::Str(_) => None,
        }
    }

    /// Converts a value to the given kind, as a command would need before a
    /// write. Fails (None) where the conversion would lose meaning: a string
    /// into a number, a fractional float into an integer, NaN anywhere.
    pub fn coerce(&self, kind: ValueKind) -> Option<Value> {
        match (self, kind) {
            (v, k) if v.kind() == k => match v {
                Value::Float(f) if !f.is_finite() => None,
                _ => Some(v.clone()),
            },
            (Value::Bool(b), ValueKind::Int) => Some(Value::Int(*b as i64)),
            (Value::Bool(b), ValueKind::Float) => Some(Value::Float(*b as i64 as f64)),
            (Value::Int(i), ValueKind::Bool) if *i == 0 || *i == 1 => Some(Value::Bool(*i == 1)),
            (Value::Int(i), ValueKind::Float) => Some(Value::Float(*i as f64)),
            (Value::UInt(u), ValueKind::Float) => Some(Value::Float(*u as f64)),
            (Value::Str(s), ValueKind::Int) => {
                let i = parse_integer(s)?;
                i64::try_from(i)
                    .map(Value::Int)
                    .or_else(|_| u64::try_from(i).map(Value::UInt))
                    .ok()
            }
            (Value::Float(f), ValueKind::Bool) if *f == 0.0 || *f == 1.0 => {
                Some(Value::Bool(*f == 1.0))
            }
            (Value::Float(f), ValueKind::Int)
                if f.is_finite() && f.fract() == 0.0 && f.abs() < 9.0e15 =>
            {
                Some(Value::Int(*f as i64))
            }
            (Value::Float(f), ValueKind::Float) if f.is_finite() => Some(Value::Float(*f)),
            _ => None,
        }
    }
}

impl fmt::Display for Value {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Value::Bool(b) => write!(f, "{b}"),
            Value::Int(i) => write!(f, "{i}"),
            Value::UInt(u) => write!(f, "{u}"),
            Value::Float(x) => write!(f, "{x}"),
            Value::Str(s) => f.write_str(s),
        }
    }
}

impl From<bool> for Value {
    fn from(b: bool) -> Self {
        Value::Bool(b)
    }
}
impl From<i64> for Value {
    fn from(i: i64) -> Self {
        Value::Int(i)
    }
}
impl From<u64> for Value {
    fn from(u: u64) -> Self {
        Value::from_u64(u)
    }
}
impl From<f64> for Value {
    fn from(f: f64) -> Self {
        Value::Float(f)
    }
}
impl From<&str> for Value {
    fn from(s: &str) -> Self {
        Value::Str(s.into())
    }
}

/// A whole number written as text: optional sign, then decimal digits only.
fn parse_integer(s: &str) -> Option<i128> {
    let t = s.trim();
    let digits = t.strip_prefix(['-', '+']).unwrap_or(t);
    if digits.is_empty() || digits.len() > 20 || !digits.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    t.parse().ok()
}

/// The kind of engineering value a tag holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ValueKind {
    Bool,
    Int,
    Float,
    Str,
}

/// The three OPC-style quality classes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum QualityCode {
    Good,
    Uncertain,
    Bad,
}

/// Quality of a sample: Good, or Uncertain/Bad with a reason an operator can read
/// ("device offline", "exception 0x02 illegal data address", "not yet read").
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Quality {
    pub code: QualityCode,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reason: Option<Arc<str>>,
}

impl Quality {
    pub const GOOD: Quality = Quality {
        code: QualityCode::Good,
        reason: None,
    };

    pub fn bad(reason: impl Into<Arc<str>>) -> Self {
        Quality {
            code: QualityCode::Bad,
            reason: Some(reason.into()),
        }
    }

    pub fn uncertain(reason: impl Into<Arc<str>>) -> Self {
        Quality {
            code: QualityCode::Uncertain,
            reason: Some(reason.into()),
        }
    }

    pub fn is_good(&self) -> bool {
        self.code == QualityCode::Good
    }
}

impl fmt::Display for Quality {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let code = match self.code {
            QualityCode::Good => "Good",
            QualityCode::Uncertain => "Uncertain",
            QualityCode::Bad => "Bad",
        };
        match &self.reason {
            Some(r) => write!(f, "{code} ({r})"),
            None => f.write_str(code),
        }
    }
}

/// One reading of a tag: value, quality, and the source timestamp.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Sample {
    pub value: Value,
    pub quality: Quality,
    pub timestamp: Timestamp,
}

/// The reason of a tag that has never been read.
pub const NEVER_READ: &str = "no value yet";

/// One shared copy of [`NEVER_READ`]: every tag starts with it, and a
/// million tags should not hold a million copies.
fn never_read_reason() -> Arc<str> {
    static REASON: std::sync::OnceLock<Arc<str>> = std::sync::OnceLock::new();
    REASON.get_or_init(|| Arc::from(NEVER_READ)).clone()
}

impl Sample {
    /// What a tag holds before its first reading: Bad, at time 0.
    pub fn never_read(value: Value) -> Self {
        Sample {
            value,
            quality: Quality::bad(never_read_reason()),
            timestamp: Timestamp::from_millis(0),
        }
    }

    /// Whether this is a tag's state before its first reading.
    pub fn is_never_read(&self) -> bool {
        self.timestamp.as_millis() == 0
            && self.quality.code == QualityCode::Bad
            && self.quality.reason.as_deref() == Some(NEVER_READ)
    }

    pub fn good(value: impl Into<Value>, timestamp: Timestamp) -> Self {
        Sample {
            value: value.into(),
            quality: Quality::GOOD,
            timestamp,
        }
    }

    /// Whether `other` differs from `self` in what a subscriber sees: value or
    /// quality. A newer timestamp alone is not a change.
    pub fn differs_from(&self, other: &Sample) -> bool {
        self.quality != other.quality || !same_value(&self.value, &other.value)
    }
}

/// Value equality where NaN equals NaN, so a NaN reading is not a change on every scan.
fn same_value(a: &Value, b: &Value) -> bool {
    match (a, b) {
        (Value::Float(x), Value::Float(y)) => x == y || (x.is_nan() && y.is_nan()),
        _ => a == b,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn coerce_refuses_lossy_conversions() {
        assert_eq!(
            Value::Float(2.0).coerce(ValueKind::Int),
            Some(Value::Int(2))
        );
        assert_eq!(Value::Float(2.5).coerce(ValueKind::Int), None);
        assert_eq!(
            Value::Int(1).coerce(ValueKind::Bool),
            Some(Value::Bool(true))
        );
        assert_eq!(Value::Int(2).coerce(ValueKind::Bool), None);
        assert_eq!(Value::from("x").coerce(ValueKind::Float), None);
        assert_eq!(Value::Float(f64::NAN).coerce(ValueKind::Float), None);
    }

    #[test]
    fn nan_is_not_a_change() {
        let t = Timestamp::from_millis(1);
        let a = Sample::good(f64::NAN, t);
        let b = Sample::good(f64::NAN, Timestamp::from_millis(2));
        assert!(!a.differs_from(&b));
    }

    #[test]
    fn integers_beyond_2_pow_53_go_out_as_exact_strings() {
        let big = 12_345_678_901_234_567_891u64;
        let v = Value::from_u64(big);
        assert_eq!(v, Value::UInt(big));
        assert_eq!(Value::from_u64(7), Value::Int(7));
        let json = |v: &Value| serde_json::to_string(v).unwrap();
        assert_eq!(json(&v), "\"12345678901234567891\"");
        assert_eq!(json(&Value::Int(1 << 53)), "9007199254740992");
        assert_eq!(json(&Value::Int((1 << 53) + 1)), "\"9007199254740993\"");
        assert_eq!(json(&Value::Int(i64::MIN)), "\"-9223372036854775808\"");
        assert_eq!(json(&Value::Int(-42)), "-42");
        // Read back: a JSON number above i64::MAX and the digit string both
        // reach an integer tag exactly.
        let n: Value = serde_json::from_str("12345678901234567891").unwrap();
        assert_eq!(n, Value::UInt(big));
        let s: Value = serde_json::from_str("\"12345678901234567891\"").unwrap();
        assert_eq!(s.coerce(ValueKind::Int), Some(Value::UInt(big)));
        assert_eq!(s.as_i128(), Some(i128::from(big)));
        assert_eq!(Value::from("12a").coerce(ValueKind::Int), None);
        assert_eq!(
            Value::from("99999999999999999999").coerce(ValueKind::Int),
            None
        );
        assert_eq!(v.to_string(), "12345678901234567891");
        assert!(v.is_wide_integer() && !Value::Int(5).is_wide_integer());
    }
}
