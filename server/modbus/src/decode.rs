//! Tag values on the wire: decoding register and bit images into engineering
//! values, and encoding engineering values back into registers for writes.
//!
//! **Owns:** data types, word and byte order, bit-in-register, scale/offset and
//! their inverse, with range and type checks. Pure functions only.
//!
//! **Must not touch:** I/O, the tag database, scheduling.

use gridscada_config::{DataType, Endian, RegisterKind, TagConfig};
use gridscada_tagdb::{Quality, Sample, Timestamp, Value, ValueKind};

/// How one tag sits on the wire, taken from its configuration once at start.
#[derive(Debug, Clone, PartialEq)]
pub struct Codec {
    pub table: RegisterKind,
    pub data_type: DataType,
    /// Bit within a 16-bit register (0 = least significant).
    pub bit: Option<u8>,
    /// Registers (or bits) the tag occupies.
    pub width: u16,
    pub word_order: Endian,
    pub byte_order: Endian,
    pub scale: f64,
    pub offset: f64,
}

impl Codec {
    /// The codec of Modbus tag `t`, on its `table`.
    pub fn from_tag(t: &TagConfig, table: RegisterKind) -> Codec {
        Codec {
            table,
            data_type: t.data_type(),
            bit: if table.is_bit() {
                None
            } else {
                t.bit.as_ref().map(|b| *b.get_ref())
            },
            width: t.width().max(1),
            word_order: t.word_order,
            byte_order: t.byte_order,
            scale: *t.scale.get_ref(),
            offset: t.offset,
        }
    }

    fn scaled(&self) -> bool {
        self.scale != 1.0 || self.offset != 0.0
    }

    /// The engineering kind this codec produces (mirrors `TagConfig::value_kind`).
    pub fn value_kind(&self) -> ValueKind {
        match self.data_type {
            DataType::Bool => ValueKind::Bool,
            DataType::String | DataType::DateTime => ValueKind::Str,
            DataType::F32 | DataType::F64 => ValueKind::Float,
            _ if self.scaled() => ValueKind::Float,
            _ => ValueKind::Int,
        }
    }
}

/// A value ready to go on the wire.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Encoded {
    /// A coil.
    Coil(bool),
    /// Whole registers, in wire order.
    Registers(Vec<u16>),
    /// One bit of a holding register: needs read-modify-write.
    Bit { bit: u8, value: bool },
}

/// The value of a coil or discrete input.
pub fn decode_bit(on: bool) -> Value {
    Value::Bool(on)
}

/// Quality of a freshly decoded value: a NaN from the device is not a reading
/// an operator or a control loop should trust.
pub fn quality_of(value: &Value) -> Quality {
    match value {
        Value::Float(f) if f.is_nan() => Quality::uncertain("device reported NaN"),
        Value::Float(f) if f.is_infinite() => Quality::uncertain("device reported infinity"),
        _ => Quality::GOOD,
    }
}

/// The time a device clock tag reads: a `datetime` tag's text, or a number of
/// Unix seconds (scale it to seconds if the device counts milliseconds).
/// `None` when the reading is not Good or not a plausible time (before 1970 or
/// after 9999).
pub fn device_time(clock: &Sample) -> Option<Timestamp> {
    if !clock.quality.is_good() {
        return None;
    }
    let ms = match &clock.value {
        Value::Str(s) => Timestamp::parse_utc_text(s)?.as_millis(),
        v => {
            let secs = v.as_f64().filter(|s| s.is_finite())?;
            (secs * 1000.0).round() as i64
        }
    };
    (0..=253_402_300_799_000)
        .contains(&ms)
        .then(|| Timestamp::from_millis(ms))
}

/// Applies the byte order within each register.
fn byte_ordered(codec: &Codec, reg: u16) -> u16 {
    match codec.byte_order {
        Endian::Big => reg,
        Endian::Little => reg.swap_bytes(),
    }
}

/// The raw unsigned integer of a 1, 2 or 4 register value, most significant first.
fn raw_bits(codec: &Codec, regs: &[u16]) -> u64 {
    let mut v: u64 = 0;
    let mut push = |r: u16| v = (v << 16) | u64::from(byte_ordered(codec, r));
    match codec.word_order {
        Endian::Big => regs.iter().copied().for_each(&mut push),
        Endian::Little => regs.iter().rev().copied().for_each(&mut push),
    }
    v
}

/// Decodes the registers of one tag (exactly `codec.width` of them) into its
/// engineering value.
pub fn decode_registers(codec: &Codec, regs: &[u16]) -> Result<Value, String> {
    let need = if codec.bit.is_some() {
        1
    } else {
        usize::from(codec.width)
    };
    if regs.len() != need {
        return Err(format!(
            "{} needs {need} registers, got {}",
            codec.data_type.label(),
            regs.len()
        ));
    }
    if let Some(bit) = codec.bit {
        if bit > 15 {
            return Err(format!("bit {bit} is outside 0..=15"));
        }
        return Ok(Value::Bool((byte_ordered(codec, regs[0]) >> bit) & 1 == 1));
    }
    let raw = raw_bits(codec, regs);
    let int = |i: i128| -> Value {
        if codec.scaled() {
            Value::Float(i as f64 * codec.scale + codec.offset)
        } else if let Ok(v) = i64::try_from(i) {
            Value::Int(v)
        } else {
            // u64 above i64::MAX: exact, never rounded through a float.
            Value::from_u64(i as u64)
        }
    };
    let float = |f: f64| Value::Float(f * codec.scale + codec.offset);
    Ok(match codec.data_type {
        DataType::Bool => Value::Bool(raw != 0),
        DataType::I16 => int(i128::from(raw as u16 as i16)),
        DataType::U16 => int(i128::from(raw as u16)),
        DataType::I32 => int(i128::from(raw as u32 as i32)),
        DataType::U32 => int(i128::from(raw as u32)),
        DataType::I64 => int(i128::from(raw as i64)),
        DataType::U64 => int(i128::from(raw)),
        DataType::F32 => float(f64::from(f32::from_bits(raw as u32))),
        DataType::F64 => float(f64::from_bits(raw)),
        DataType::DateTime => {
            let r: Vec<u32> = regs
                .iter()
                .map(|r| u32::from(byte_ordered(codec, *r)))
                .collect();
            let civil = gridscada_tagdb::CivilTime {
                year: i64::from(r[0]),
                month: r[1],
                day: r[2],
                hour: r[3],
                minute: r[4],
                second: r[5],
                milli: 0,
            };
            let t = Timestamp::from_civil_utc(civil).ok_or_else(|| {
                format!(
                    "device clock reads {:04}-{:02}-{:02} {:02}:{:02}:{:02}: not a date and time",
                    r[0], r[1], r[2], r[3], r[4], r[5]
                )
            })?;
            Value::Str(t.utc_text().into())
        }
        DataType::String => {
            let mut bytes = Vec::with_capacity(regs.len() * 2);
            for r in regs {
                bytes.extend_from_slice(&byte_ordered(codec, *r).to_be_bytes());
            }
            while bytes.last() == Some(&0) {
                bytes.pop();
            }
            Value::Str(String::from_utf8_lossy(&bytes).as_ref().into())
        }
    })
}

/// Splits a raw integer (most significant first) into `n` registers in wire order.
fn to_registers(codec: &Codec, raw: u64, n: usize) -> Vec<u16> {
    let mut regs: Vec<u16> = (0..n)
        .rev()
        .map(|i| byte_ordered(codec, (raw >> (16 * i)) as u16))
        .collect();
    if codec.word_order == Endian::Little {
        regs.reverse();
    }
    regs
}

/// Encodes an engineering value for a write: inverse scaling, range and type
/// checks. The error says why in words an operator can act on.
pub fn encode(codec: &Codec, value: &Value) -> Result<Encoded, String> {
    if codec.table.is_bit() {
        let b = value
            .coerce(ValueKind::Bool)
            .and_then(|v| v.as_bool())
            .ok_or_else(|| format!("a {} takes true/false (or 1/0)", codec.table.label()))?;
        return Ok(Encoded::Coil(b));
    }
    if let Some(bit) = codec.bit {
        let b = value
            .coerce(ValueKind::Bool)
            .and_then(|v| v.as_bool())
            .ok_or_else(|| "a bit takes true/false (or 1/0)".to_string())?;
        return Ok(Encoded::Bit { bit, value: b });
    }
    let n = usize::from(codec.width);
    let ty = codec.data_type;
    match ty {
        DataType::Bool => {
            let b = value
                .coerce(ValueKind::Bool)
                .and_then(|v| v.as_bool())
                .ok_or_else(|| "a bool takes true/false (or 1/0)".to_string())?;
            Ok(Encoded::Registers(vec![u16::from(b)]))
        }
        DataType::DateTime => Err("a datetime tag is a device clock: it is read-only".into()),
        DataType::String => {
            let Value::Str(s) = value else {
                return Err("a string tag takes text".into());
            };
            let bytes = s.as_bytes();
            if bytes.len() > n * 2 {
                return Err(format!(
                    "text of {} bytes does not fit in {n} registers ({} bytes)",
                    bytes.len(),
                    n * 2
                ));
            }
            let mut padded = bytes.to_vec();
            padded.resize(n * 2, 0);
            Ok(Encoded::Registers(
                padded
                    .chunks(2)
                    .map(|c| byte_ordered(codec, u16::from_be_bytes([c[0], c[1]])))
                    .collect(),
            ))
        }
        DataType::F32 | DataType::F64 => {
            let eng = value
                .coerce(ValueKind::Float)
                .and_then(|v| v.as_f64())
                .ok_or_else(|| format!("a {} tag takes a finite number", ty.label()))?;
            let raw = (eng - codec.offset) / codec.scale;
            if !raw.is_finite() {
                return Err("the scaled value is not a finite number".into());
            }
            if ty == DataType::F32 {
                if raw.abs() > f64::from(f32::MAX) {
                    return Err(format!("raw value {raw} is outside the f32 range"));
                }
                Ok(Encoded::Registers(to_registers(
                    codec,
                    u64::from((raw as f32).to_bits()),
                    2,
                )))
            } else {
                Ok(Encoded::Registers(to_registers(codec, raw.to_bits(), 4)))
            }
        }
        _ => {
            let raw = integer_raw(codec, value)?;
            let (lo, hi): (i128, i128) = match ty {
                DataType::I16 => (i16::MIN.into(), i16::MAX.into()),
                DataType::U16 => (0, u16::MAX.into()),
                DataType::I32 => (i32::MIN.into(), i32::MAX.into()),
                DataType::U32 => (0, u32::MAX.into()),
                DataType::I64 => (i64::MIN.into(), i64::MAX.into()),
                _ => (0, u64::MAX.into()),
            };
            if raw < lo || raw > hi {
                let how = if codec.scaled() {
                    " after scaling (raw = (value - offset) / scale)"
                } else {
                    ""
                };
                return Err(format!(
                    "raw value {raw} is outside the {} range {lo}..={hi}{how}",
                    ty.label()
                ));
            }
            // Two's complement in the type's own width.
            let bits = (raw as u64) & mask(ty.registers(0));
            Ok(Encoded::Registers(to_registers(
                codec,
                bits,
                usize::from(ty.registers(0)),
            )))
        }
    }
}

fn mask(registers: u16) -> u64 {
    if registers >= 4 {
        u64::MAX
    } else {
        (1u64 << (16 * registers)) - 1
    }
}

/// The raw integer of a write to an integer tag.
fn integer_raw(codec: &Codec, value: &Value) -> Result<i128, String> {
    let ty = codec.data_type.label();
    if !codec.scaled() {
        // Unscaled: the value must be a whole number; keep 64-bit precision.
        return match value {
            Value::Int(_) | Value::UInt(_) => Ok(value.as_i128().unwrap_or_default()),
            Value::Bool(b) => Ok(i128::from(*b)),
            Value::Float(f) if f.is_finite() && f.fract() == 0.0 && f.abs() < 1.9e19 => {
                Ok(*f as i128)
            }
            Value::Float(_) => Err(format!("a {ty} tag takes a whole number")),
            // The JSON form of an integer beyond 2^53.
            Value::Str(_) => value
                .as_i128()
                .ok_or_else(|| format!("a {ty} tag takes a number, not text")),
        };
    }
    let eng = value
        .coerce(ValueKind::Float)
        .and_then(|v| v.as_f64())
        .ok_or_else(|| format!("a scaled {ty} tag takes a finite number"))?;
    let raw = ((eng - codec.offset) / codec.scale).round();
    if !raw.is_finite() || raw.abs() > 1.9e19 {
        return Err(format!(
            "raw value {raw} is outside the {ty} range after scaling"
        ));
    }
    Ok(raw as i128)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn codec(ty: DataType, width: u16) -> Codec {
        Codec {
            table: RegisterKind::HoldingRegister,
            data_type: ty,
            bit: None,
            width,
            word_order: Endian::Big,
            byte_order: Endian::Big,
            scale: 1.0,
            offset: 0.0,
        }
    }

    fn orders(c: &Codec) -> Vec<Codec> {
        let mut v = vec![];
        for w in [Endian::Big, Endian::Little] {
            for b in [Endian::Big, Endian::Little] {
                v.push(Codec {
                    word_order: w,
                    byte_order: b,
                    ..c.clone()
                });
            }
        }
        v
    }

    fn round_trip(c: &Codec, v: Value) -> Value {
        let Encoded::Registers(regs) = encode(c, &v).unwrap() else {
            panic!("expected registers")
        };
        assert_eq!(regs.len(), usize::from(c.width));
        decode_registers(c, &regs).unwrap()
    }

    #[test]
    fn every_integer_type_round_trips_in_every_order() {
        let cases: Vec<(DataType, u16, Vec<i64>)> = vec![
            (
                DataType::I16,
                1,
                vec![0, 1, -1, i16::MIN.into(), i16::MAX.into()],
            ),
            (DataType::U16, 1, vec![0, 1, 65535, 0x1234]),
            (
                DataType::I32,
                2,
                vec![0, -1, i32::MIN.into(), i32::MAX.into(), 0x1234_5678],
            ),
            (DataType::U32, 2, vec![0, u32::MAX.into(), 0x1234_5678]),
            (
                DataType::I64,
                4,
                vec![0, -1, i64::MIN, i64::MAX, 0x0102_0304_0506_0708],
            ),
            (DataType::U64, 4, vec![0, i64::MAX, 0x0102_0304_0506_0708]),
        ];
        for (ty, w, values) in cases {
            for c in orders(&codec(ty, w)) {
                for v in &values {
                    assert_eq!(
                        round_trip(&c, Value::Int(*v)),
                        Value::Int(*v),
                        "{ty:?} {c:?}"
                    );
                }
            }
        }
    }

    #[test]
    fn floats_round_trip_in_every_order() {
        for c in orders(&codec(DataType::F32, 2)) {
            for v in [0.0, -1.5, 230.25, f64::from(1.0e30_f32)] {
                assert_eq!(round_trip(&c, Value::Float(v)), Value::Float(v));
            }
        }
        for c in orders(&codec(DataType::F64, 4)) {
            for v in [0.0, -1.5, 50.012345678901, -1.0e300] {
                assert_eq!(round_trip(&c, Value::Float(v)), Value::Float(v));
            }
        }
    }

    #[test]
    fn known_wire_images() {
        // 0x12345678 big-endian words: [0x1234, 0x5678].
        let c = codec(DataType::U32, 2);
        assert_eq!(
            decode_registers(&c, &[0x1234, 0x5678]).unwrap(),
            Value::Int(0x1234_5678)
        );
        let little_words = Codec {
            word_order: Endian::Little,
            ..c.clone()
        };
        assert_eq!(
            decode_registers(&little_words, &[0x5678, 0x1234]).unwrap(),
            Value::Int(0x1234_5678)
        );
        let little_bytes = Codec {
            byte_order: Endian::Little,
            ..c.clone()
        };
        assert_eq!(
            decode_registers(&little_bytes, &[0x3412, 0x7856]).unwrap(),
            Value::Int(0x1234_5678)
        );
        // f32 230.0 = 0x43660000.
        let f = codec(DataType::F32, 2);
        assert_eq!(
            decode_registers(&f, &[0x4366, 0x0000]).unwrap(),
            Value::Float(230.0)
        );
        assert_eq!(
            encode(&f, &Value::Float(230.0)).unwrap(),
            Encoded::Registers(vec![0x4366, 0])
        );
        // i16 -2 = 0xFFFE.
        assert_eq!(
            decode_registers(&codec(DataType::I16, 1), &[0xFFFE]).unwrap(),
            Value::Int(-2)
        );
        assert_eq!(
            encode(&codec(DataType::I16, 1), &Value::Int(-2)).unwrap(),
            Encoded::Registers(vec![0xFFFE])
        );
    }

    #[test]
    fn u64_beyond_i64_is_exact() {
        let c = codec(DataType::U64, 4);
        assert_eq!(
            decode_registers(&c, &[0xFFFF, 0xFFFF, 0xFFFF, 0xFFFF]).unwrap(),
            Value::UInt(u64::MAX)
        );
        // 12345678901234567891 = 0xAB54_A98C_EB1F_0AD3, in and out exactly,
        // whether written as a number or as its JSON string form.
        let regs = [0xAB54, 0xA98C, 0xEB1F, 0x0AD3];
        let big = Value::UInt(12_345_678_901_234_567_891);
        assert_eq!(decode_registers(&c, &regs).unwrap(), big);
        assert_eq!(encode(&c, &big).unwrap(), Encoded::Registers(regs.to_vec()));
        assert_eq!(
            encode(&c, &Value::from("12345678901234567891")).unwrap(),
            Encoded::Registers(regs.to_vec())
        );
        // And a write of such a value encodes the right image.
        assert_eq!(
            encode(&c, &Value::Float(9_223_372_036_854_775_808.0)).unwrap(),
            Encoded::Registers(vec![0x8000, 0, 0, 0])
        );
    }

    #[test]
    fn a_datetime_reads_six_fields_and_refuses_an_impossible_date() {
        let c = codec(DataType::DateTime, 6);
        let v = decode_registers(&c, &[2026, 11, 25, 13, 30, 5]).unwrap();
        assert_eq!(v, Value::from("2026-11-25T13:30:05Z"));
        let at = Timestamp::parse_utc_text("2026-11-25T13:30:05Z").unwrap();
        assert_eq!(
            device_time(&Sample::good(v, Timestamp::from_millis(0))),
            Some(at)
        );
        let err = decode_registers(&c, &[2026, 2, 30, 0, 0, 0]).unwrap_err();
        assert!(err.contains("2026-02-30 00:00:00: not a date"), "{err}");
        // Unix seconds (a scaled millisecond counter works the same way).
        let secs = Sample::good(Value::Int(1_764_077_405), Timestamp::from_millis(0));
        assert_eq!(
            device_time(&secs),
            Some(Timestamp::from_millis(1_764_077_405_000))
        );
        let bad = Sample {
            quality: Quality::bad("x"),
            ..secs.clone()
        };
        assert_eq!(device_time(&bad), None);
        assert_eq!(
            device_time(&Sample::good(Value::Int(-5), Timestamp::from_millis(0))),
            None
        );
    }

    #[test]
    fn scale_and_offset() {
        let c = Codec {
            scale: 0.1,
            offset: -40.0,
            ..codec(DataType::I16, 1)
        };
        // raw 655 -> 65.5 - 40 = 25.5
        let Value::Float(v) = decode_registers(&c, &[655]).unwrap() else {
            panic!()
        };
        assert!((v - 25.5).abs() < 1e-9);
        assert_eq!(
            encode(&c, &Value::Float(25.5)).unwrap(),
            Encoded::Registers(vec![655])
        );
        // Out of range after scaling: 4000 -> raw 40400 > i16::MAX.
        let err = encode(&c, &Value::Float(4000.0)).unwrap_err();
        assert!(err.contains("outside the i16 range"), "{err}");
        assert!(err.contains("after scaling"), "{err}");
        // Scaled floats.
        let f = Codec {
            scale: 2.0,
            offset: 1.0,
            ..codec(DataType::F32, 2)
        };
        assert_eq!(round_trip(&f, Value::Float(11.0)), Value::Float(11.0));
        assert_eq!(c.value_kind(), ValueKind::Float);
        assert_eq!(codec(DataType::I16, 1).value_kind(), ValueKind::Int);
    }

    #[test]
    fn bit_in_register() {
        let c = Codec {
            bit: Some(3),
            data_type: DataType::Bool,
            ..codec(DataType::Bool, 1)
        };
        assert_eq!(decode_registers(&c, &[0b1000]).unwrap(), Value::Bool(true));
        assert_eq!(decode_registers(&c, &[0b0111]).unwrap(), Value::Bool(false));
        let c15 = Codec {
            bit: Some(15),
            ..c.clone()
        };
        assert_eq!(
            decode_registers(&c15, &[0x8000]).unwrap(),
            Value::Bool(true)
        );
        // Little byte order swaps before the bit is taken.
        let cl = Codec {
            byte_order: Endian::Little,
            ..c15
        };
        assert_eq!(decode_registers(&cl, &[0x0080]).unwrap(), Value::Bool(true));
        assert_eq!(
            encode(&c, &Value::Int(1)).unwrap(),
            Encoded::Bit {
                bit: 3,
                value: true
            }
        );
        assert!(encode(&c, &Value::Int(2)).is_err());
    }

    #[test]
    fn bools_on_bits_and_registers() {
        assert_eq!(decode_bit(true), Value::Bool(true));
        let coil = Codec {
            table: RegisterKind::Coil,
            ..codec(DataType::Bool, 1)
        };
        assert_eq!(
            encode(&coil, &Value::Bool(true)).unwrap(),
            Encoded::Coil(true)
        );
        assert_eq!(encode(&coil, &Value::Int(0)).unwrap(), Encoded::Coil(false));
        assert!(encode(&coil, &Value::from("on")).is_err());
        let reg = codec(DataType::Bool, 1);
        assert_eq!(decode_registers(&reg, &[7]).unwrap(), Value::Bool(true));
        assert_eq!(decode_registers(&reg, &[0]).unwrap(), Value::Bool(false));
        assert_eq!(
            encode(&reg, &Value::Bool(true)).unwrap(),
            Encoded::Registers(vec![1])
        );
    }

    #[test]
    fn strings() {
        let c = codec(DataType::String, 3);
        assert_eq!(
            encode(&c, &Value::from("ABC")).unwrap(),
            Encoded::Registers(vec![0x4142, 0x4300, 0])
        );
        assert_eq!(
            decode_registers(&c, &[0x4142, 0x4300, 0]).unwrap(),
            Value::from("ABC")
        );
        let little = Codec {
            byte_order: Endian::Little,
            ..c.clone()
        };
        assert_eq!(
            decode_registers(&little, &[0x4241, 0x0043, 0]).unwrap(),
            Value::from("ABC")
        );
        assert_eq!(
            round_trip(&little, Value::from("xyz12")),
            Value::from("xyz12")
        );
        let err = encode(&c, &Value::from("too long!")).unwrap_err();
        assert!(err.contains("does not fit"), "{err}");
        assert!(encode(&c, &Value::Int(1)).is_err());
        // Invalid UTF-8 from a device does not panic.
        assert!(decode_registers(&c, &[0xFFFE, 0, 0]).is_ok());
    }

    #[test]
    fn rejects_bad_values_and_short_input() {
        let u = codec(DataType::U16, 1);
        assert!(encode(&u, &Value::Int(-1)).unwrap_err().contains("outside"));
        assert!(encode(&u, &Value::Int(65536))
            .unwrap_err()
            .contains("outside"));
        assert!(encode(&u, &Value::Float(1.5))
            .unwrap_err()
            .contains("whole"));
        assert!(encode(&u, &Value::from("1x"))
            .unwrap_err()
            .contains("not text"));
        assert!(encode(&u, &Value::from("1.0")).is_err());
        // Digits are an integer's JSON form beyond 2^53: taken exactly.
        assert_eq!(
            encode(&u, &Value::from("7")).unwrap(),
            Encoded::Registers(vec![7])
        );
        // A device clock is read-only.
        assert!(encode(
            &codec(DataType::DateTime, 6),
            &Value::from("2026-01-01T00:00:00Z")
        )
        .is_err());
        assert!(encode(&codec(DataType::F32, 2), &Value::Float(f64::NAN)).is_err());
        assert!(encode(&codec(DataType::F32, 2), &Value::Float(1e300)).is_err());
        assert!(decode_registers(&codec(DataType::U32, 2), &[1]).is_err());
        assert!(decode_registers(&codec(DataType::U32, 2), &[]).is_err());
    }

    #[test]
    fn nan_is_uncertain() {
        let c = codec(DataType::F32, 2);
        let v = decode_registers(&c, &[0x7FC0, 0]).unwrap();
        assert_eq!(quality_of(&v).code, gridscada_tagdb::QualityCode::Uncertain);
        assert!(quality_of(&Value::Float(1.0)).is_good());
    }
}
