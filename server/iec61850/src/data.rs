//! MMS `Data` values (ISO 9506-2) and the IEC 61850 types carried in them:
//! quality (IEC 61850-7-3 §6.2), timestamps with their time quality
//! (IEC 61850-8-1 `UtcTime`, 8.1.3.7) and `BinaryTime` (`TimeOfEntry`).

use crate::ber::{BerError, BitString, Reader, Tag, Tlv, Writer, MAX_DEPTH};

/// A value as MMS carries it.
#[derive(Debug, Clone, PartialEq)]
pub enum Data {
    Array(Vec<Data>),
    Structure(Vec<Data>),
    Boolean(bool),
    BitString(BitString),
    Integer(i64),
    Unsigned(u64),
    Float(f64),
    OctetString(Vec<u8>),
    VisibleString(String),
    MmsString(String),
    UtcTime(UtcTime),
    /// Milliseconds since 1984-01-01 00:00 UTC (6 octets), or since
    /// midnight when the date is absent (4 octets).
    BinaryTime(BinaryTime),
    /// A type this client does not interpret (generalized time, BCD,
    /// object identifier): its tag number and raw octets.
    Other(u32, Vec<u8>),
}

impl Data {
    /// Decodes one `Data` TLV, following structures and arrays no deeper
    /// than [`MAX_DEPTH`].
    pub fn decode(t: &Tlv<'_>) -> Result<Data, BerError> {
        Self::decode_at(t, 0)
    }

    fn decode_at(t: &Tlv<'_>, depth: usize) -> Result<Data, BerError> {
        if t.tag.class != crate::ber::Class::Context {
            return Err(t.error(format!("Data with tag {}", t.tag)));
        }
        let constructed = |t: &Tlv<'_>| -> Result<Vec<Data>, BerError> {
            if depth >= MAX_DEPTH {
                return Err(t.error(format!("Data nested deeper than {MAX_DEPTH}")));
            }
            t.children()
                .map(|c| c.and_then(|c| Self::decode_at(&c, depth + 1)))
                .collect()
        };
        Ok(match (t.tag.number, t.tag.constructed) {
            (1, true) => Data::Array(constructed(t)?),
            (2, true) => Data::Structure(constructed(t)?),
            (3, false) => Data::Boolean(t.as_bool()?),
            (4, false) => Data::BitString(t.as_bits()?),
            (5, false) => Data::Integer(t.as_i64()?),
            (6, false) => Data::Unsigned(t.as_u64()?),
            (7, false) => Data::Float(decode_float(t)?),
            (9, false) => Data::OctetString(t.value.to_vec()),
            (10, false) => Data::VisibleString(t.as_str()?.to_string()),
            (16, false) => Data::MmsString(t.as_str()?.to_string()),
            (17, false) => Data::UtcTime(UtcTime::decode(t)?),
            (12, false) => Data::BinaryTime(BinaryTime::decode(t)?),
            (n, false) => Data::Other(n, t.value.to_vec()),
            (n, true) => return Err(t.error(format!("constructed Data [{n}]"))),
        })
    }

    /// Encodes the value as a `Data` TLV.
    pub fn encode(&self, w: &mut Writer) {
        match self {
            Data::Array(items) => {
                w.constructed(Tag::ctx_c(1), |w| items.iter().for_each(|d| d.encode(w)))
            }
            Data::Structure(items) => {
                w.constructed(Tag::ctx_c(2), |w| items.iter().for_each(|d| d.encode(w)))
            }
            Data::Boolean(b) => w.boolean(Tag::ctx(3), *b),
            Data::BitString(b) => w.bits(Tag::ctx(4), b),
            Data::Integer(n) => w.integer(Tag::ctx(5), *n),
            Data::Unsigned(n) => w.unsigned(Tag::ctx(6), *n),
            Data::Float(f) => {
                let mut v = vec![8];
                v.extend_from_slice(&(*f as f32).to_be_bytes());
                w.primitive(Tag::ctx(7), &v);
            }
            Data::OctetString(o) => w.primitive(Tag::ctx(9), o),
            Data::VisibleString(s) => w.primitive(Tag::ctx(10), s.as_bytes()),
            Data::MmsString(s) => w.primitive(Tag::ctx(16), s.as_bytes()),
            Data::UtcTime(t) => w.primitive(Tag::ctx(17), &t.encode()),
            Data::BinaryTime(t) => w.primitive(Tag::ctx(12), &t.encode()),
            Data::Other(n, v) => w.primitive(Tag::ctx(*n), v),
        }
    }

    /// The value as a number, where it is one (booleans 0/1, bit strings
    /// as their bits read most significant first, e.g. a `Dbpos`).
    pub fn as_f64(&self) -> Option<f64> {
        match self {
            Data::Boolean(b) => Some(f64::from(u8::from(*b))),
            Data::Integer(n) => Some(*n as f64),
            Data::Unsigned(n) => Some(*n as f64),
            Data::Float(f) => Some(*f),
            Data::BitString(b) => Some(f64::from(b.to_u32())),
            _ => None,
        }
    }

    /// What kind of value this is, in the standard's word.
    pub fn kind(&self) -> &'static str {
        match self {
            Data::Array(_) => "array",
            Data::Structure(_) => "structure",
            Data::Boolean(_) => "boolean",
            Data::BitString(_) => "bit-string",
            Data::Integer(_) => "integer",
            Data::Unsigned(_) => "unsigned",
            Data::Float(_) => "floating-point",
            Data::OctetString(_) => "octet-string",
            Data::VisibleString(_) => "visible-string",
            Data::MmsString(_) => "mms-string",
            Data::UtcTime(_) => "utc-time",
            Data::BinaryTime(_) => "binary-time",
            Data::Other(..) => "other",
        }
    }
}

fn decode_float(t: &Tlv<'_>) -> Result<f64, BerError> {
    match t.value {
        [8, a, b, c, d] => Ok(f64::from(f32::from_be_bytes([*a, *b, *c, *d]))),
        [11, rest @ ..] if rest.len() == 8 => {
            let mut o = [0u8; 8];
            o.copy_from_slice(rest);
            Ok(f64::from_be_bytes(o))
        }
        v => Err(t.error(format!(
            "floating-point of {} octets (exponent width {:?})",
            v.len(),
            v.first()
        ))),
    }
}

/// IEC 61850-8-1 `UtcTime`: seconds and fraction since 1970, and the
/// time quality octet.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct UtcTime {
    pub seconds: u32,
    /// Fraction of a second in units of 2^-24 s.
    pub fraction: u32,
    pub quality: u8,
}

impl UtcTime {
    pub const LEAP_SECONDS_KNOWN: u8 = 0x80;
    pub const CLOCK_FAILURE: u8 = 0x40;
    pub const CLOCK_NOT_SYNCHRONIZED: u8 = 0x20;

    fn decode(t: &Tlv<'_>) -> Result<UtcTime, BerError> {
        match t.value {
            [a, b, c, d, e, f, g, q] => Ok(UtcTime {
                seconds: u32::from_be_bytes([*a, *b, *c, *d]),
                fraction: u32::from_be_bytes([0, *e, *f, *g]),
                quality: *q,
            }),
            v => Err(t.error(format!("utc-time of {} octets (8 expected)", v.len()))),
        }
    }

    pub fn encode(&self) -> [u8; 8] {
        let s = self.seconds.to_be_bytes();
        let f = self.fraction.to_be_bytes();
        [s[0], s[1], s[2], s[3], f[1], f[2], f[3], self.quality]
    }

    /// Milliseconds since 1970.
    pub fn unix_ms(&self) -> i64 {
        i64::from(self.seconds) * 1000 + ((i64::from(self.fraction) * 1000) >> 24)
    }

    pub fn from_unix_ms(ms: i64, quality: u8) -> UtcTime {
        let ms = ms.max(0);
        UtcTime {
            seconds: u32::try_from(ms / 1000).unwrap_or(u32::MAX),
            fraction: u32::try_from(((ms % 1000) << 24) / 1000).unwrap_or(0),
            quality,
        }
    }

    /// Bits of accuracy of the fraction (0..24; 31 = unspecified).
    pub fn accuracy_bits(&self) -> u8 {
        self.quality & 0x1f
    }

    /// What is wrong with the source's clock, in words, if anything.
    pub fn clock_trouble(&self) -> Option<&'static str> {
        if self.quality & Self::CLOCK_FAILURE != 0 {
            Some("the IED's clock has failed")
        } else if self.quality & Self::CLOCK_NOT_SYNCHRONIZED != 0 {
            Some("the IED's clock is not synchronised")
        } else {
            None
        }
    }
}

/// MMS `BinaryTime` (`TimeOfDay`): milliseconds within a day and, when
/// six octets long, days since 1984-01-01.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BinaryTime {
    pub ms_of_day: u32,
    pub days_since_1984: Option<u16>,
}

/// 1984-01-01 in Unix days.
const EPOCH_1984_DAYS: i64 = 5113;

impl BinaryTime {
    fn decode(t: &Tlv<'_>) -> Result<BinaryTime, BerError> {
        match t.value {
            [a, b, c, d] => Ok(BinaryTime {
                ms_of_day: u32::from_be_bytes([*a, *b, *c, *d]),
                days_since_1984: None,
            }),
            [a, b, c, d, e, f] => Ok(BinaryTime {
                ms_of_day: u32::from_be_bytes([*a, *b, *c, *d]),
                days_since_1984: Some(u16::from_be_bytes([*e, *f])),
            }),
            v => Err(t.error(format!(
                "binary-time of {} octets (4 or 6 expected)",
                v.len()
            ))),
        }
    }
    fn encode(&self) -> Vec<u8> {
        let mut v = self.ms_of_day.to_be_bytes().to_vec();
        if let Some(d) = self.days_since_1984 {
            v.extend_from_slice(&d.to_be_bytes());
        }
        v
    }
    /// Milliseconds since 1970, when the date is present.
    pub fn unix_ms(&self) -> Option<i64> {
        self.days_since_1984
            .map(|d| (EPOCH_1984_DAYS + i64::from(d)) * 86_400_000 + i64::from(self.ms_of_day))
    }
}

/// IEC 61850-7-3 quality, from its 13-bit bit string.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Quality(pub u16);

impl Quality {
    const DETAIL: [&'static str; 9] = [
        "overflow",
        "out of range",
        "bad reference",
        "oscillatory",
        "failure",
        "old data",
        "inconsistent",
        "inaccurate",
        "substituted",
    ];

    /// From the bit string (bit 0 first).
    pub fn from_bits(b: &BitString) -> Quality {
        Quality((0..13).fold(0u16, |q, i| q | (u16::from(b.bit(i)) << i)))
    }
    fn bit(&self, i: u16) -> bool {
        self.0 & (1 << i) != 0
    }
    /// `validity`: good, invalid, reserved or questionable.
    pub fn validity(&self) -> &'static str {
        match (self.bit(0), self.bit(1)) {
            (false, false) => "good",
            (true, false) => "invalid",
            (false, true) => "reserved",
            (true, true) => "questionable",
        }
    }
    pub fn test(&self) -> bool {
        self.bit(11)
    }
    pub fn operator_blocked(&self) -> bool {
        self.bit(12)
    }
    pub fn substituted(&self) -> bool {
        self.bit(10)
    }
    /// The quality in words: its validity and every detail flag set, e.g.
    /// "questionable: old data, inaccurate"; `None` when good and plain.
    pub fn describe(&self) -> Option<String> {
        let mut flags: Vec<&str> = (0..9u16)
            .filter(|i| self.bit(2 + i))
            .map(|i| Self::DETAIL[usize::from(i)])
            .collect();
        if self.test() {
            flags.push("test");
        }
        if self.operator_blocked() {
            flags.push("operator blocked");
        }
        if self.validity() == "good" && flags.is_empty() {
            return None;
        }
        Some(if flags.is_empty() {
            self.validity().to_string()
        } else {
            format!("{}: {}", self.validity(), flags.join(", "))
        })
    }
}

/// Decodes a `Data` list, e.g. an access result list's successes.
pub fn decode_all(r: Reader<'_>) -> Result<Vec<Data>, BerError> {
    r.map(|t| t.and_then(|t| Data::decode(&t))).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn round_trip(d: &Data) -> Data {
        let mut w = Writer::new();
        d.encode(&mut w);
        Data::decode(&Reader::new(&w.buf).read("d").unwrap()).unwrap()
    }

    #[test]
    fn values_round_trip() {
        let t = UtcTime::from_unix_ms(1_764_000_000_250, UtcTime::LEAP_SECONDS_KNOWN | 10);
        for d in [
            Data::Boolean(true),
            Data::Integer(-5),
            Data::Unsigned(40000),
            Data::Float(1.5),
            Data::VisibleString("TESTLD0/LLN0$Events".into()),
            Data::UtcTime(t),
            Data::BitString(BitString::from_bits(&[false, true])),
            Data::Structure(vec![
                Data::Boolean(false),
                Data::Array(vec![Data::Integer(1)]),
            ]),
        ] {
            assert_eq!(round_trip(&d), d);
        }
        assert_eq!(t.unix_ms(), 1_764_000_000_250);
    }

    #[test]
    fn doubles_and_hostile_nesting() {
        let mut v = vec![0x87, 9, 11];
        v.extend_from_slice(&2.25f64.to_be_bytes());
        assert_eq!(
            Data::decode(&Reader::new(&v).read("d").unwrap()).unwrap(),
            Data::Float(2.25)
        );
        // 40 nested structures: refused, not recursed.
        let mut nested = vec![0x83u8, 1, 0];
        for _ in 0..40 {
            let mut w = Writer::new();
            w.constructed(Tag::ctx_c(2), |w| w.buf.extend_from_slice(&nested));
            nested = w.buf;
        }
        let e = Data::decode(&Reader::new(&nested).read("d").unwrap()).unwrap_err();
        assert!(e.what.contains("deeper"), "{e}");
    }

    #[test]
    fn quality_reads_in_words() {
        // questionable (bits 0,1), old data (bit 7)
        let q = Quality::from_bits(&BitString::from_bits(&[
            true, true, false, false, false, false, false, true, false, false, false, false, false,
        ]));
        assert_eq!(q.describe().as_deref(), Some("questionable: old data"));
        assert_eq!(Quality::default().describe(), None);
        let q = Quality::from_bits(&BitString::from_bits(&[
            true, false, false, false, false, false, true,
        ]));
        assert_eq!(q.describe().as_deref(), Some("invalid: failure"));
    }

    #[test]
    fn binary_time_counts_from_1984() {
        let t = BinaryTime {
            ms_of_day: 1000,
            days_since_1984: Some(0),
        };
        assert_eq!(t.unix_ms(), Some(441_763_200_000 + 1000));
    }
}
