//! The ASDU (IEC 60870-5-101 clause 7, with 104's fixed field sizes): type
//! identification, variable structure qualifier, cause of transmission (two
//! octets: cause with P/N and T bits, originator address), common address
//! (two octets), then the information objects (three-octet IOAs).
//!
//! An [`Asdu`] is checked when it is made, by [`Asdu::new`],
//! [`Asdu::new_sequence`] or [`Asdu::decode`]: its type, elements, time tags
//! and length always agree, so [`Asdu::encode`] cannot fail and whatever is
//! decoded encodes back to an ASDU that decodes equal.

use thiserror::Error;

use crate::apci::MAX_ASDU_LEN;
use crate::element::Element;
use crate::time::{Cp56Time2a, TimeError, CP56_LEN};
use crate::types::{Cause, TypeId};

/// Octets before the first information object.
pub const HEADER_LEN: usize = 6;
/// Octets of an information object address.
pub const IOA_LEN: usize = 3;
/// The largest IOA (24 bits).
pub const MAX_IOA: u32 = 0xFF_FFFF;
/// The most objects the seven-bit count of the VSQ can announce.
pub const MAX_OBJECTS: usize = 127;

/// What is wrong with an ASDU, and where.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum AsduError {
    #[error("ASDU of {0} octets is shorter than its 6-octet header")]
    TooShort(usize),
    #[error("unknown type id {0}")]
    UnknownTypeId(u8),
    #[error("type {0} with object count 0")]
    NoObjects(TypeId),
    #[error("type {type_id} with {count} objects: more than 127")]
    TooManyObjects { type_id: TypeId, count: usize },
    #[error("type {0} does not allow SQ=1 (a sequence of elements)")]
    SequenceNotAllowed(TypeId),
    #[error("type {type_id} with {count} objects needs {needed} octets, got {got}")]
    Length {
        type_id: TypeId,
        count: usize,
        needed: usize,
        got: usize,
    },
    #[error("type {type_id} with {count} objects needs {needed} octets, more than the 249 an ASDU can hold")]
    TooLong {
        type_id: TypeId,
        count: usize,
        needed: usize,
    },
    #[error("cause of transmission {0:?} has no number")]
    Cause(Cause),
    #[error("object {index}: IOA {ioa} out of range 0..=16777215")]
    IoaRange { index: usize, ioa: u32 },
    #[error("object {index}: IOA {got} breaks the sequence, expected {expected}")]
    NotConsecutive {
        index: usize,
        expected: u32,
        got: u32,
    },
    #[error("object {index} (IOA {ioa}): a {kind} element {with_time} does not belong in type {type_id}")]
    Mismatch {
        index: usize,
        ioa: u32,
        kind: &'static str,
        with_time: &'static str,
        type_id: TypeId,
    },
    #[error("object {index} (IOA {ioa}) of type {type_id}: {what}")]
    Element {
        index: usize,
        ioa: u32,
        type_id: TypeId,
        what: String,
    },
    #[error("object {index} (IOA {ioa}) of type {type_id}: time tag: {error}")]
    Time {
        index: usize,
        ioa: u32,
        type_id: TypeId,
        error: TimeError,
    },
}

/// One information object: its address, element and, for the time-tagged
/// types, its CP56Time2a.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InformationObject {
    /// Information object address, 24 bits. 0 is accepted (it is what
    /// station-wide commands such as C_IC_NA_1 use).
    pub ioa: u32,
    pub element: Element,
    /// The time tag, for the types that carry one (`TypeId::carries_time`).
    pub time: Option<Cp56Time2a>,
}

impl InformationObject {
    /// An object without time tag.
    pub fn new(ioa: u32, element: Element) -> Self {
        InformationObject {
            ioa,
            element,
            time: None,
        }
    }

    /// The same object with a time tag.
    pub fn with_time(mut self, time: Cp56Time2a) -> Self {
        self.time = Some(time);
        self
    }
}

/// An application service data unit, checked.
#[derive(Debug, Clone, PartialEq)]
pub struct Asdu {
    type_id: TypeId,
    sequence: bool,
    cause: Cause,
    negative: bool,
    test: bool,
    originator: u8,
    common_address: u16,
    objects: Vec<InformationObject>,
}

impl Asdu {
    /// An ASDU with SQ=0: each object with its own IOA. Originator 0, P/N
    /// and T clear (see the `with_` methods).
    pub fn new(
        type_id: TypeId,
        cause: Cause,
        common_address: u16,
        objects: Vec<InformationObject>,
    ) -> Result<Asdu, AsduError> {
        Self::build(type_id, false, cause, common_address, objects)
    }

    /// An ASDU with SQ=1: the objects' IOAs must be consecutive, and only the
    /// first is sent.
    pub fn new_sequence(
        type_id: TypeId,
        cause: Cause,
        common_address: u16,
        objects: Vec<InformationObject>,
    ) -> Result<Asdu, AsduError> {
        Self::build(type_id, true, cause, common_address, objects)
    }

    fn build(
        type_id: TypeId,
        sequence: bool,
        cause: Cause,
        common_address: u16,
        objects: Vec<InformationObject>,
    ) -> Result<Asdu, AsduError> {
        if cause.to_u8().is_none() {
            return Err(AsduError::Cause(cause));
        }
        check_shape(type_id, sequence, objects.len())?;
        for (index, o) in objects.iter().enumerate() {
            check_object(type_id, index, o)?;
            if sequence {
                let expected = objects[0].ioa.saturating_add(index as u32);
                if o.ioa != expected {
                    return Err(AsduError::NotConsecutive {
                        index,
                        expected,
                        got: o.ioa,
                    });
                }
            }
        }
        Ok(Asdu {
            type_id,
            sequence,
            cause,
            negative: false,
            test: false,
            originator: 0,
            common_address,
            objects,
        })
    }

    /// The same ASDU with another cause: how a station mirrors a command
    /// back as actcon or actterm.
    pub fn with_cause(mut self, cause: Cause) -> Result<Asdu, AsduError> {
        if cause.to_u8().is_none() {
            return Err(AsduError::Cause(cause));
        }
        self.cause = cause;
        Ok(self)
    }

    /// The same ASDU with the P/N bit set (negative confirmation) or clear.
    pub fn with_negative(mut self, negative: bool) -> Asdu {
        self.negative = negative;
        self
    }

    /// The same ASDU with the T (test) bit set or clear.
    pub fn with_test(mut self, test: bool) -> Asdu {
        self.test = test;
        self
    }

    /// The same ASDU with an originator address (0 when unused).
    pub fn with_originator(mut self, originator: u8) -> Asdu {
        self.originator = originator;
        self
    }

    /// The same ASDU for another common address (station).
    pub fn with_common_address(mut self, common_address: u16) -> Asdu {
        self.common_address = common_address;
        self
    }

    pub fn type_id(&self) -> TypeId {
        self.type_id
    }

    /// SQ=1: one IOA, then consecutive elements.
    pub fn is_sequence(&self) -> bool {
        self.sequence
    }

    pub fn cause(&self) -> Cause {
        self.cause
    }

    /// P/N: a negative confirmation.
    pub fn is_negative(&self) -> bool {
        self.negative
    }

    /// T: a test ASDU, not to be acted on.
    pub fn is_test(&self) -> bool {
        self.test
    }

    pub fn originator(&self) -> u8 {
        self.originator
    }

    pub fn common_address(&self) -> u16 {
        self.common_address
    }

    pub fn objects(&self) -> &[InformationObject] {
        &self.objects
    }

    pub fn into_objects(self) -> Vec<InformationObject> {
        self.objects
    }

    /// Decode an ASDU that fills `b` exactly (the ASDU of an I frame).
    /// Never panics; allocates at most 127 objects, after the length has
    /// been checked against `b`.
    pub fn decode(b: &[u8]) -> Result<Asdu, AsduError> {
        if b.len() < HEADER_LEN {
            return Err(AsduError::TooShort(b.len()));
        }
        let type_id = TypeId::from_u8(b[0]).ok_or(AsduError::UnknownTypeId(b[0]))?;
        let sequence = b[1] & 0x80 != 0;
        let count = usize::from(b[1] & 0x7F);
        check_shape(type_id, sequence, count)?;
        let needed = encoded_len(type_id, sequence, count);
        if b.len() != needed {
            return Err(AsduError::Length {
                type_id,
                count,
                needed,
                got: b.len(),
            });
        }
        let elen = type_id.element_len();
        let time_len = if type_id.carries_time() { CP56_LEN } else { 0 };
        let mut objects = Vec::with_capacity(count);
        let mut at = HEADER_LEN;
        let mut first_ioa = 0;
        for index in 0..count {
            let ioa = if sequence && index > 0 {
                first_ioa + index as u32
            } else {
                let ioa = read_ioa(&b[at..at + IOA_LEN]);
                at += IOA_LEN;
                first_ioa = ioa;
                ioa
            };
            if ioa > MAX_IOA {
                return Err(AsduError::IoaRange { index, ioa });
            }
            let body = &b[at..at + elen];
            at += elen;
            let (value, stamp) = body.split_at(elen - time_len);
            let element = Element::decode(type_id, value).map_err(|what| AsduError::Element {
                index,
                ioa,
                type_id,
                what,
            })?;
            let time = if time_len > 0 {
                Some(Cp56Time2a::decode(stamp).map_err(|error| AsduError::Time {
                    index,
                    ioa,
                    type_id,
                    error,
                })?)
            } else {
                None
            };
            objects.push(InformationObject { ioa, element, time });
        }
        Ok(Asdu {
            type_id,
            sequence,
            cause: Cause::from_u8(b[2]),
            negative: b[2] & 0x40 != 0,
            test: b[2] & 0x80 != 0,
            originator: b[3],
            common_address: u16::from_le_bytes([b[4], b[5]]),
            objects,
        })
    }

    /// The ASDU's octets (at most 249, checked when it was made).
    pub fn encode(&self) -> Vec<u8> {
        let mut out =
            Vec::with_capacity(encoded_len(self.type_id, self.sequence, self.objects.len()));
        // Checked at construction: the count fits seven bits, the cause six.
        let vsq = self.objects.len() as u8 | if self.sequence { 0x80 } else { 0 };
        let cot = self.cause.to_u8().unwrap_or(0)
            | if self.negative { 0x40 } else { 0 }
            | if self.test { 0x80 } else { 0 };
        out.extend_from_slice(&[self.type_id.as_u8(), vsq, cot, self.originator]);
        out.extend_from_slice(&self.common_address.to_le_bytes());
        for (index, o) in self.objects.iter().enumerate() {
            if !self.sequence || index == 0 {
                out.extend_from_slice(&o.ioa.to_le_bytes()[..IOA_LEN]);
            }
            o.element.encode(&mut out);
            if let Some(t) = o.time {
                out.extend_from_slice(&t.encode());
            }
        }
        out
    }
}

/// Octets of an ASDU of `count` objects of `type_id`.
fn encoded_len(type_id: TypeId, sequence: bool, count: usize) -> usize {
    let elen = type_id.element_len();
    if sequence {
        HEADER_LEN + IOA_LEN + count * elen
    } else {
        HEADER_LEN + count * (IOA_LEN + elen)
    }
}

/// The checks on type, SQ and count that do not need the objects.
fn check_shape(type_id: TypeId, sequence: bool, count: usize) -> Result<(), AsduError> {
    if count == 0 {
        return Err(AsduError::NoObjects(type_id));
    }
    if count > MAX_OBJECTS {
        return Err(AsduError::TooManyObjects { type_id, count });
    }
    if sequence && !type_id.allows_sequence() {
        return Err(AsduError::SequenceNotAllowed(type_id));
    }
    let needed = encoded_len(type_id, sequence, count);
    if needed > MAX_ASDU_LEN {
        return Err(AsduError::TooLong {
            type_id,
            count,
            needed,
        });
    }
    Ok(())
}

/// Whether a hand-built object fits its type: IOA, element kind, time tag
/// present exactly where the type has one, fields within their bits.
fn check_object(type_id: TypeId, index: usize, o: &InformationObject) -> Result<(), AsduError> {
    let ioa = o.ioa;
    if ioa > MAX_IOA {
        return Err(AsduError::IoaRange { index, ioa });
    }
    if o.element.type_id(o.time.is_some()) != Some(type_id) {
        return Err(AsduError::Mismatch {
            index,
            ioa,
            kind: o.element.kind(),
            with_time: if o.time.is_some() {
                "with time tag"
            } else {
                "without time tag"
            },
            type_id,
        });
    }
    o.element.check().map_err(|what| AsduError::Element {
        index,
        ioa,
        type_id,
        what,
    })?;
    if let Some(t) = o.time {
        t.validate().map_err(|error| AsduError::Time {
            index,
            ioa,
            type_id,
            error,
        })?;
    }
    Ok(())
}

fn read_ioa(b: &[u8]) -> u32 {
    u32::from_le_bytes([b[0], b[1], b[2], 0])
}
