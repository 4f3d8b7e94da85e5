//! Engineering value <-> register words, exactly as a tag's configuration
//! says (type, scale, offset, word and byte order, bit).
//!
//! Owns the wire encoding of simulated signals. Must not touch the plant
//! models or sockets: it is pure arithmetic, so the simulator serves whatever
//! encoding the plant configuration describes and the poller decodes it back.

use gridscada_config::{DataType, Endian, RegisterKind, TagConfig};

/// Where and how one tag's value sits in a device's register image.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Binding {
    /// The tag the binding comes from (for messages).
    pub tag: String,
    /// Index of the device in the simulator's device list.
    pub device: usize,
    pub kind: RegisterKind,
    pub address: u16,
    /// Bit within a register, for bool tags on registers.
    pub bit: Option<u8>,
    pub data_type: DataType,
    pub word_order: Endian,
    pub byte_order: Endian,
    pub scale: f64,
    pub offset: f64,
    /// Registers (or bits) occupied.
    pub width: u16,
}

impl Binding {
    pub fn from_tag(t: &TagConfig, device: usize) -> Result<Binding, String> {
        let (kind, address) = t
            .register()
            .ok_or_else(|| format!("tag '{}': no Modbus kind and address", t.name.get_ref()))?;
        let address = u16::try_from(address)
            .map_err(|_| format!("tag '{}': address beyond 65535", t.name.get_ref()))?;
        let width = t.width();
        if u32::from(address) + u32::from(width) > 65536 {
            return Err(format!(
                "tag '{}': address {address} + width {width} runs past the end of the table",
                t.name.get_ref()
            ));
        }
        let scale = *t.scale.get_ref();
        Ok(Binding {
            tag: t.name.get_ref().clone(),
            device,
            kind,
            address,
            bit: t.bit.as_ref().map(|b| *b.get_ref()),
            data_type: t.data_type(),
            word_order: t.word_order,
            byte_order: t.byte_order,
            scale: if scale == 0.0 || !scale.is_finite() {
                1.0
            } else {
                scale
            },
            offset: t.offset,
            width,
        })
    }

    /// One past the last address the binding occupies.
    pub fn end(&self) -> u32 {
        u32::from(self.address) + u32::from(self.width)
    }

    /// Whether the binding overlaps `[start, start + len)` of `kind`.
    pub fn overlaps(&self, kind: RegisterKind, start: u16, len: u16) -> bool {
        self.kind == kind
            && u32::from(self.address) < u32::from(start) + u32::from(len)
            && u32::from(start) < self.end()
    }

    /// Register words of an engineering value (register tables only).
    /// Values are clamped into the wire type's range; NaN encodes as 0 for
    /// integer types.
    pub fn encode_words(&self, value: f64) -> Vec<u16> {
        let raw = (value - self.offset) / self.scale;
        let mut words: Vec<u16> = match self.data_type {
            DataType::Bool => vec![u16::from(value != 0.0)],
            DataType::I16 => vec![round_clamp(raw, i16::MIN as f64, i16::MAX as f64) as i16 as u16],
            DataType::U16 => vec![round_clamp(raw, 0.0, u16::MAX as f64) as u16],
            DataType::I32 => split(
                round_clamp(raw, i32::MIN as f64, i32::MAX as f64) as i32 as u32 as u64,
                2,
            ),
            DataType::U32 => split(round_clamp(raw, 0.0, u32::MAX as f64) as u32 as u64, 2),
            DataType::I64 => split(
                round_clamp(raw, i64::MIN as f64, i64::MAX as f64) as i64 as u64,
                4,
            ),
            DataType::U64 => split(round_clamp(raw, 0.0, u64::MAX as f64) as u64, 4),
            DataType::F32 => split(u64::from((raw as f32).to_bits()), 2),
            DataType::F64 => split(raw.to_bits(), 4),
            // Strings are not simulated signals; they read as blanks.
            DataType::String => vec![0x2020; usize::from(self.width)],
            // A device clock: the signal is Unix seconds.
            DataType::DateTime => {
                let c = gridscada_tagdb::Timestamp::from_millis((raw.max(0.0) * 1000.0) as i64)
                    .civil_utc();
                [
                    c.year.clamp(0, 9999) as u32,
                    c.month,
                    c.day,
                    c.hour,
                    c.minute,
                    c.second,
                ]
                .iter()
                .map(|&v| v as u16)
                .collect()
            }
        };
        // A datetime's six registers are fields in a fixed order, not one number.
        if self.word_order == Endian::Little && self.data_type != DataType::DateTime {
            words.reverse();
        }
        if self.byte_order == Endian::Little {
            for w in &mut words {
                *w = w.swap_bytes();
            }
        }
        words
    }

    /// The engineering value of register words (as the master wrote them).
    /// `None` for strings and for words of the wrong count.
    pub fn decode_words(&self, words: &[u16]) -> Option<f64> {
        if let Some(bit) = self.bit {
            let w = *words.first()?;
            let w = if self.byte_order == Endian::Little {
                w.swap_bytes()
            } else {
                w
            };
            return Some(f64::from((w >> (bit & 15)) & 1));
        }
        if words.len() != usize::from(self.width) {
            return None;
        }
        let mut ws: Vec<u16> = words.to_vec();
        if self.byte_order == Endian::Little {
            for w in &mut ws {
                *w = w.swap_bytes();
            }
        }
        if self.word_order == Endian::Little {
            ws.reverse();
        }
        let joined = ws.iter().fold(0u64, |acc, w| (acc << 16) | u64::from(*w));
        let raw = match self.data_type {
            DataType::Bool => f64::from(u8::from(joined != 0)),
            DataType::I16 => f64::from(joined as u16 as i16),
            DataType::U16 => f64::from(joined as u16),
            DataType::I32 => f64::from(joined as u32 as i32),
            DataType::U32 => f64::from(joined as u32),
            DataType::I64 => joined as i64 as f64,
            DataType::U64 => joined as f64,
            DataType::F32 => f64::from(f32::from_bits(joined as u32)),
            DataType::F64 => f64::from_bits(joined),
            DataType::String => return None,
            DataType::DateTime => return None,
        };
        Some(raw * self.scale + self.offset)
    }
}

fn round_clamp(x: f64, lo: f64, hi: f64) -> f64 {
    if x.is_nan() {
        0.0
    } else {
        x.round().clamp(lo, hi)
    }
}

/// Splits `v` into `n` words, most significant first.
fn split(v: u64, n: usize) -> Vec<u16> {
    (0..n)
        .rev()
        .map(|i| (v >> (16 * i)) as u16)
        .collect::<Vec<_>>()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn binding(dt: DataType, word: Endian, byte: Endian, scale: f64) -> Binding {
        Binding {
            tag: "T".into(),
            device: 0,
            kind: RegisterKind::InputRegister,
            address: 0,
            bit: None,
            data_type: dt,
            word_order: word,
            byte_order: byte,
            scale,
            offset: 0.0,
            width: dt.registers(0),
        }
    }

    #[test]
    fn f32_big_endian_words() {
        let b = binding(DataType::F32, Endian::Big, Endian::Big, 1.0);
        let w = b.encode_words(230.0);
        assert_eq!(w, vec![0x4366, 0x0000]);
        assert_eq!(b.decode_words(&w), Some(230.0));
    }

    #[test]
    fn u32_scaled_kwh() {
        let b = binding(DataType::U32, Endian::Big, Endian::Big, 0.1);
        let w = b.encode_words(123_456.7);
        assert_eq!(w, vec![0x0012, 0xd687]); // 1_234_567
        assert!((b.decode_words(&w).unwrap() - 123_456.7).abs() < 1e-6);
    }

    #[test]
    fn little_word_and_byte_order_round_trip() {
        let b = binding(DataType::F32, Endian::Little, Endian::Little, 1.0);
        let w = b.encode_words(-12.5);
        assert_eq!(b.decode_words(&w), Some(-12.5));
        let be = binding(DataType::F32, Endian::Big, Endian::Big, 1.0).encode_words(-12.5);
        assert_eq!(w, vec![be[1].swap_bytes(), be[0].swap_bytes()]);
    }

    #[test]
    fn integers_clamp_instead_of_wrapping() {
        let b = binding(DataType::U16, Endian::Big, Endian::Big, 1.0);
        assert_eq!(b.encode_words(-5.0), vec![0]);
        assert_eq!(b.encode_words(1e9), vec![u16::MAX]);
        assert_eq!(b.encode_words(f64::NAN), vec![0]);
    }
}
