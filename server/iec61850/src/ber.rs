//! BER (X.690) as MMS and the OSI upper layers use it: definite lengths
//! only, tags up to 2^21, one TLV at a time over a borrowed buffer.
//!
//! The decoder never panics and never trusts a length: every value is a
//! sub-slice checked against what is left, and every error names the octet
//! offset from the start of the PDU it came from. The encoder writes into a
//! `Vec<u8>`, patching each constructed value's length once its content is
//! known.

use std::fmt;

/// The class of a tag (the two high bits of its first octet).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Class {
    Universal,
    Application,
    Context,
    Private,
}

/// A tag: class, primitive or constructed, number.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Tag {
    pub class: Class,
    pub constructed: bool,
    pub number: u32,
}

impl Tag {
    pub const fn universal(number: u32, constructed: bool) -> Tag {
        Tag {
            class: Class::Universal,
            constructed,
            number,
        }
    }
    pub const fn context(number: u32, constructed: bool) -> Tag {
        Tag {
            class: Class::Context,
            constructed,
            number,
        }
    }
    pub const fn application(number: u32, constructed: bool) -> Tag {
        Tag {
            class: Class::Application,
            constructed,
            number,
        }
    }
    /// Context-specific tag number `n`, primitive (`[n] IMPLICIT`).
    pub const fn ctx(n: u32) -> Tag {
        Tag::context(n, false)
    }
    /// Context-specific tag number `n`, constructed.
    pub const fn ctx_c(n: u32) -> Tag {
        Tag::context(n, true)
    }
    pub const BOOLEAN: Tag = Tag::universal(1, false);
    pub const INTEGER: Tag = Tag::universal(2, false);
    pub const BIT_STRING: Tag = Tag::universal(3, false);
    pub const OCTET_STRING: Tag = Tag::universal(4, false);
    pub const NULL: Tag = Tag::universal(5, false);
    pub const OID: Tag = Tag::universal(6, false);
    pub const EXTERNAL: Tag = Tag::universal(8, true);
    pub const SEQUENCE: Tag = Tag::universal(16, true);
    pub const SET: Tag = Tag::universal(17, true);
    pub const VISIBLE_STRING: Tag = Tag::universal(26, false);
}

impl fmt::Display for Tag {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let class = match self.class {
            Class::Universal => "UNIVERSAL ",
            Class::Application => "APPLICATION ",
            Class::Context => "",
            Class::Private => "PRIVATE ",
        };
        write!(f, "[{class}{}]", self.number)
    }
}

/// What is wrong with a BER encoding, and where.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{what} at octet {offset}")]
pub struct BerError {
    /// Offset from the start of the PDU.
    pub offset: usize,
    pub what: String,
}

impl BerError {
    pub fn new(offset: usize, what: impl Into<String>) -> BerError {
        BerError {
            offset,
            what: what.into(),
        }
    }
}

/// One decoded TLV: its tag, its content and where the content starts.
#[derive(Debug, Clone, Copy)]
pub struct Tlv<'a> {
    pub tag: Tag,
    pub value: &'a [u8],
    /// Offset of the first content octet from the start of the PDU.
    pub offset: usize,
}

/// Deepest nesting the decoder follows: MMS data nests (structures of
/// arrays of structures) but an IED's model never needs more than this,
/// and a hostile peer must not recurse us off the stack.
pub const MAX_DEPTH: usize = 32;

impl<'a> Tlv<'a> {
    /// The TLVs inside a constructed value.
    pub fn children(&self) -> Reader<'a> {
        Reader::at(self.value, self.offset)
    }

    pub fn error(&self, what: impl Into<String>) -> BerError {
        BerError::new(self.offset, what)
    }

    /// Fails unless the tag is `tag`.
    pub fn expect(self, tag: Tag, what: &str) -> Result<Tlv<'a>, BerError> {
        if self.tag == tag {
            Ok(self)
        } else {
            Err(self.error(format!("{what}: expected tag {tag}, found {}", self.tag)))
        }
    }

    /// A two's-complement INTEGER of up to 8 octets.
    pub fn as_i64(&self) -> Result<i64, BerError> {
        let v = self.value;
        if v.is_empty() || v.len() > 8 {
            return Err(self.error(format!("integer of {} octets", v.len())));
        }
        let mut n: i64 = if v[0] & 0x80 != 0 { -1 } else { 0 };
        for &b in v {
            n = (n << 8) | i64::from(b);
        }
        Ok(n)
    }

    /// An unsigned INTEGER of up to 8 value octets (plus a leading zero).
    pub fn as_u64(&self) -> Result<u64, BerError> {
        let mut v = self.value;
        if v.len() == 9 && v[0] == 0 {
            v = &v[1..];
        }
        if v.is_empty() || v.len() > 8 {
            return Err(self.error(format!("unsigned of {} octets", self.value.len())));
        }
        if self.value.len() <= 8 && v[0] & 0x80 != 0 {
            return Err(self.error("negative value for an unsigned"));
        }
        Ok(v.iter().fold(0u64, |n, &b| (n << 8) | u64::from(b)))
    }

    pub fn as_u32(&self) -> Result<u32, BerError> {
        let n = self.as_u64()?;
        u32::try_from(n).map_err(|_| self.error(format!("{n} does not fit 32 bits")))
    }

    pub fn as_bool(&self) -> Result<bool, BerError> {
        match self.value {
            [b] => Ok(*b != 0),
            v => Err(self.error(format!("boolean of {} octets", v.len()))),
        }
    }

    /// A VisibleString (or any string MMS sends as ASCII/UTF-8).
    pub fn as_str(&self) -> Result<&'a str, BerError> {
        std::str::from_utf8(self.value)
            .map_err(|e| BerError::new(self.offset + e.valid_up_to(), "string is not valid UTF-8"))
    }

    /// A BIT STRING: the bits, and how many of them count.
    pub fn as_bits(&self) -> Result<BitString, BerError> {
        let Some((&unused, bits)) = self.value.split_first() else {
            return Err(self.error("bit string without its unused-bits octet"));
        };
        if unused > 7 || (bits.is_empty() && unused != 0) {
            return Err(self.error(format!("bit string with {unused} unused bits")));
        }
        Ok(BitString {
            octets: bits.to_vec(),
            len: bits.len() * 8 - usize::from(unused),
        })
    }

    /// An OBJECT IDENTIFIER's arcs.
    pub fn as_oid(&self) -> Result<Vec<u32>, BerError> {
        let mut arcs = Vec::new();
        let mut n: u32 = 0;
        for (i, &b) in self.value.iter().enumerate() {
            if n > (u32::MAX >> 7) {
                return Err(BerError::new(
                    self.offset + i,
                    "object identifier arc too large",
                ));
            }
            n = (n << 7) | u32::from(b & 0x7f);
            if b & 0x80 == 0 {
                if arcs.is_empty() {
                    let first = (n / 40).min(2);
                    arcs.push(first);
                    arcs.push(n - first * 40);
                } else {
                    arcs.push(n);
                }
                n = 0;
            }
        }
        if arcs.is_empty() || self.value.last().is_some_and(|b| b & 0x80 != 0) {
            return Err(self.error("truncated object identifier"));
        }
        Ok(arcs)
    }
}

/// A BIT STRING, bit 0 first (the most significant bit of the first octet).
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct BitString {
    pub octets: Vec<u8>,
    pub len: usize,
}

impl BitString {
    pub fn from_bits(bits: &[bool]) -> BitString {
        let mut octets = vec![0u8; bits.len().div_ceil(8)];
        for (i, _) in bits.iter().enumerate().filter(|(_, b)| **b) {
            octets[i / 8] |= 0x80 >> (i % 8);
        }
        BitString {
            octets,
            len: bits.len(),
        }
    }
    pub fn bit(&self, i: usize) -> bool {
        i < self.len
            && self
                .octets
                .get(i / 8)
                .is_some_and(|o| o & (0x80 >> (i % 8)) != 0)
    }
    /// The first (up to) 32 bits as a number, bit 0 the most significant of
    /// them: how IEC 61850 quality and Dbpos read as integers.
    pub fn to_u32(&self) -> u32 {
        (0..self.len.min(32)).fold(0, |n, i| (n << 1) | u32::from(self.bit(i)))
    }
}

/// A cursor over consecutive TLVs.
#[derive(Debug, Clone)]
pub struct Reader<'a> {
    buf: &'a [u8],
    pos: usize,
    /// Offset of `buf[0]` in the PDU.
    base: usize,
}

impl<'a> Reader<'a> {
    pub fn new(buf: &'a [u8]) -> Reader<'a> {
        Reader::at(buf, 0)
    }
    pub fn at(buf: &'a [u8], base: usize) -> Reader<'a> {
        Reader { buf, pos: 0, base }
    }
    pub fn is_empty(&self) -> bool {
        self.pos >= self.buf.len()
    }
    /// Offset of the next TLV in the PDU.
    pub fn offset(&self) -> usize {
        self.base + self.pos
    }

    /// The next TLV, or an error if none is left or it is malformed.
    pub fn read(&mut self, what: &str) -> Result<Tlv<'a>, BerError> {
        match self.next_tlv()? {
            Some(t) => Ok(t),
            None => Err(BerError::new(self.offset(), format!("{what} missing"))),
        }
    }

    /// The next TLV if its tag is `tag` (an optional element).
    pub fn optional(&mut self, tag: Tag) -> Result<Option<Tlv<'a>>, BerError> {
        let saved = self.pos;
        match self.next_tlv()? {
            Some(t) if t.tag == tag => Ok(Some(t)),
            _ => {
                self.pos = saved;
                Ok(None)
            }
        }
    }

    /// The next TLV whose tag is `tag`, as a required element.
    pub fn expect(&mut self, tag: Tag, what: &str) -> Result<Tlv<'a>, BerError> {
        self.read(what)?.expect(tag, what)
    }

    /// The next TLV, or `None` at the end.
    pub fn next_tlv(&mut self) -> Result<Option<Tlv<'a>>, BerError> {
        if self.is_empty() {
            return Ok(None);
        }
        let start = self.offset();
        let rest = &self.buf[self.pos..];
        let (tag, tag_len) = decode_tag(rest).map_err(|w| BerError::new(start, w))?;
        let (len, len_len) =
            decode_length(&rest[tag_len..]).map_err(|w| BerError::new(start + tag_len, w))?;
        let head = tag_len + len_len;
        if len > rest.len() - head {
            return Err(BerError::new(
                start,
                format!(
                    "{tag} claims {len} octets but {} are left",
                    rest.len() - head
                ),
            ));
        }
        let value = &rest[head..head + len];
        self.pos += head + len;
        Ok(Some(Tlv {
            tag,
            value,
            offset: start + head,
        }))
    }
}

impl<'a> Iterator for Reader<'a> {
    type Item = Result<Tlv<'a>, BerError>;
    fn next(&mut self) -> Option<Self::Item> {
        match self.next_tlv() {
            Ok(Some(t)) => Some(Ok(t)),
            Ok(None) => None,
            Err(e) => {
                self.pos = self.buf.len();
                Some(Err(e))
            }
        }
    }
}

fn decode_tag(b: &[u8]) -> Result<(Tag, usize), &'static str> {
    let first = *b.first().ok_or("truncated tag")?;
    let class = match first >> 6 {
        0 => Class::Universal,
        1 => Class::Application,
        2 => Class::Context,
        _ => Class::Private,
    };
    let constructed = first & 0x20 != 0;
    if first & 0x1f != 0x1f {
        return Ok((
            Tag {
                class,
                constructed,
                number: u32::from(first & 0x1f),
            },
            1,
        ));
    }
    let mut number: u32 = 0;
    for (i, &o) in b.iter().enumerate().skip(1).take(3) {
        number = (number << 7) | u32::from(o & 0x7f);
        if o & 0x80 == 0 {
            return Ok((
                Tag {
                    class,
                    constructed,
                    number,
                },
                i + 1,
            ));
        }
    }
    Err("truncated or oversized tag number")
}

fn decode_length(b: &[u8]) -> Result<(usize, usize), &'static str> {
    let first = *b.first().ok_or("truncated length")?;
    if first < 0x80 {
        return Ok((usize::from(first), 1));
    }
    let n = usize::from(first & 0x7f);
    if n == 0 {
        return Err("indefinite length (not used by MMS)");
    }
    if n > 4 {
        return Err("length of more than 4 octets");
    }
    let octets = b.get(1..1 + n).ok_or("truncated length")?;
    Ok((
        octets
            .iter()
            .fold(0usize, |l, &o| (l << 8) | usize::from(o)),
        1 + n,
    ))
}

/// Writes BER into a buffer.
#[derive(Debug, Default, Clone)]
pub struct Writer {
    pub buf: Vec<u8>,
}

impl Writer {
    pub fn new() -> Writer {
        Writer::default()
    }
    pub fn into_vec(self) -> Vec<u8> {
        self.buf
    }

    fn tag(&mut self, tag: Tag) {
        let class = match tag.class {
            Class::Universal => 0x00,
            Class::Application => 0x40,
            Class::Context => 0x80,
            Class::Private => 0xc0,
        } | if tag.constructed { 0x20 } else { 0 };
        if tag.number < 31 {
            self.buf.push(class | tag.number as u8);
        } else {
            self.buf.push(class | 0x1f);
            let mut groups = Vec::new();
            let mut n = tag.number;
            loop {
                groups.push((n & 0x7f) as u8);
                n >>= 7;
                if n == 0 {
                    break;
                }
            }
            for (i, g) in groups.iter().enumerate().rev() {
                self.buf.push(if i == 0 { *g } else { g | 0x80 });
            }
        }
    }

    fn length_octets(len: usize) -> Vec<u8> {
        if len < 0x80 {
            return vec![len as u8];
        }
        let bytes = len.to_be_bytes();
        let skip = bytes.iter().take_while(|b| **b == 0).count();
        let mut out = vec![0x80 | (bytes.len() - skip) as u8];
        out.extend_from_slice(&bytes[skip..]);
        out
    }

    /// A primitive value.
    pub fn primitive(&mut self, tag: Tag, value: &[u8]) {
        self.tag(tag);
        self.buf.extend(Self::length_octets(value.len()));
        self.buf.extend_from_slice(value);
    }

    /// A constructed value whose content `f` writes.
    pub fn constructed(&mut self, tag: Tag, f: impl FnOnce(&mut Writer)) {
        self.tag(tag);
        let start = self.buf.len();
        f(self);
        let len = Self::length_octets(self.buf.len() - start);
        self.buf.splice(start..start, len);
    }

    pub fn integer(&mut self, tag: Tag, n: i64) {
        let bytes = n.to_be_bytes();
        // Shortest two's complement: drop leading octets that only repeat the sign.
        let mut skip = 0;
        while skip < 7 {
            let (b, next) = (bytes[skip], bytes[skip + 1]);
            if (b == 0 && next & 0x80 == 0) || (b == 0xff && next & 0x80 != 0) {
                skip += 1;
            } else {
                break;
            }
        }
        self.primitive(tag, &bytes[skip..]);
    }

    pub fn unsigned(&mut self, tag: Tag, n: u64) {
        let bytes = n.to_be_bytes();
        let skip = bytes.iter().take(7).take_while(|b| **b == 0).count();
        if bytes[skip] & 0x80 != 0 {
            let mut v = vec![0];
            v.extend_from_slice(&bytes[skip..]);
            self.primitive(tag, &v);
        } else {
            self.primitive(tag, &bytes[skip..]);
        }
    }

    pub fn boolean(&mut self, tag: Tag, b: bool) {
        self.primitive(tag, &[if b { 0xff } else { 0 }]);
    }

    pub fn bits(&mut self, tag: Tag, bits: &BitString) {
        let unused = (bits.octets.len() * 8).saturating_sub(bits.len) as u8;
        let mut v = Vec::with_capacity(bits.octets.len() + 1);
        v.push(unused);
        v.extend_from_slice(&bits.octets);
        self.primitive(tag, &v);
    }

    pub fn oid(&mut self, tag: Tag, arcs: &[u32]) {
        let mut v = Vec::new();
        let mut push = |mut n: u32| {
            let mut groups = vec![(n & 0x7f) as u8];
            n >>= 7;
            while n > 0 {
                groups.push((n & 0x7f) as u8 | 0x80);
                n >>= 7;
            }
            v.extend(groups.iter().rev());
        };
        match arcs {
            [a, b, rest @ ..] => {
                push(a * 40 + b);
                rest.iter().for_each(|&n| push(n));
            }
            [a] => push(a * 40),
            [] => {}
        }
        self.primitive(tag, &v);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn integers_round_trip_in_their_shortest_form() {
        for (n, octets) in [
            (0i64, vec![0u8]),
            (127, vec![0x7f]),
            (128, vec![0, 0x80]),
            (-1, vec![0xff]),
            (-129, vec![0xff, 0x7f]),
            (65000, vec![0, 0xfd, 0xe8]),
        ] {
            let mut w = Writer::new();
            w.integer(Tag::INTEGER, n);
            assert_eq!(&w.buf[2..], &octets[..], "{n}");
            let t = Reader::new(&w.buf).read("n").unwrap();
            assert_eq!(t.as_i64().unwrap(), n);
        }
        let mut w = Writer::new();
        w.unsigned(Tag::INTEGER, 0xffff_ffff);
        assert_eq!(w.buf, [2, 5, 0, 0xff, 0xff, 0xff, 0xff]);
        assert_eq!(
            Reader::new(&w.buf).read("n").unwrap().as_u32().unwrap(),
            u32::MAX
        );
    }

    #[test]
    fn long_lengths_and_nesting_are_patched() {
        let mut w = Writer::new();
        w.constructed(Tag::SEQUENCE, |w| w.primitive(Tag::OCTET_STRING, &[7; 300]));
        assert_eq!(&w.buf[..4], &[0x30, 0x82, 0x01, 0x30]);
        assert_eq!(&w.buf[4..8], &[0x04, 0x82, 0x01, 0x2c]);
        let seq = Reader::new(&w.buf).expect(Tag::SEQUENCE, "seq").unwrap();
        let inner = seq.children().read("inner").unwrap();
        assert_eq!(inner.value.len(), 300);
        assert_eq!(inner.offset, 8);
    }

    #[test]
    fn object_identifiers_round_trip() {
        for arcs in [
            vec![1u32, 0, 9506, 2, 3],
            vec![2, 2, 1, 0, 1],
            vec![1, 1, 1, 999],
        ] {
            let mut w = Writer::new();
            w.oid(Tag::OID, &arcs);
            assert_eq!(
                Reader::new(&w.buf).read("oid").unwrap().as_oid().unwrap(),
                arcs
            );
        }
        let mut w = Writer::new();
        w.oid(Tag::OID, &[1, 0, 9506, 2, 1]);
        assert_eq!(w.buf, [6, 5, 0x28, 0xca, 0x22, 2, 1]);
    }

    #[test]
    fn lies_about_length_are_located_errors() {
        // A SEQUENCE claiming 200 octets with 3 present.
        let e = Reader::new(&[0x30, 0x81, 200, 1, 2, 3])
            .read("x")
            .unwrap_err();
        assert_eq!(e.offset, 0);
        assert!(e.what.contains("claims 200"), "{e}");
        let e = Reader::new(&[0x30, 0x80, 0, 0]).read("x").unwrap_err();
        assert!(e.what.contains("indefinite"), "{e}");
        let e = Reader::new(&[0x30, 0x85, 1, 1, 1, 1, 1])
            .read("x")
            .unwrap_err();
        assert!(e.what.contains("more than 4"), "{e}");
        // Nested: the inner error's offset is counted from the PDU's start.
        let seq = Reader::new(&[0x30, 4, 0x02, 5, 1, 0]).read("x").unwrap();
        let e = seq.children().read("int").unwrap_err();
        assert_eq!(e.offset, 2);
    }

    #[test]
    fn bit_strings_count_their_unused_bits() {
        let t = [0x84, 2, 6, 0x80]; // 2 bits: 1 0
        let b = Reader::new(&t).read("b").unwrap().as_bits().unwrap();
        assert_eq!((b.len, b.bit(0), b.bit(1), b.to_u32()), (2, true, false, 2));
        assert!(Reader::new(&[0x84, 1, 3])
            .read("b")
            .unwrap()
            .as_bits()
            .is_err());
        let q = BitString::from_bits(&[
            false, true, false, false, false, false, false, false, false, false, false, false,
            false,
        ]);
        assert_eq!((q.octets.clone(), q.len), (vec![0x40, 0], 13));
    }

    #[test]
    fn high_tag_numbers_round_trip() {
        let mut w = Writer::new();
        w.constructed(Tag::context(30, true), |w| w.primitive(Tag::NULL, &[]));
        assert_eq!(&w.buf[..2], &[0xbe, 2]);
        let mut w = Writer::new();
        w.primitive(Tag::context(200, false), &[]);
        let t = Reader::new(&w.buf).read("t").unwrap();
        assert_eq!(t.tag, Tag::ctx(200));
    }
}
