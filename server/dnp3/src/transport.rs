//! The DNP3 transport function (IEEE 1815-2012 clause 8): one header octet
//! (FIN 0x80, FIR 0x40, a six-bit sequence number) before each piece of an
//! application fragment, so that a fragment fits link frames of 250 octets.
//!
//! [`segment`] cuts an APDU into segments of at most 249 octets of payload;
//! [`Reassembler`] puts received segments back together, discarding what
//! is out of sequence and refusing a fragment past its size cap. Pure, no
//! panics; the reassembled buffer never grows past the cap.

use thiserror::Error;

pub const FIN: u8 = 0x80;
pub const FIR: u8 = 0x40;
pub const SEQ_MASK: u8 = 0x3F;
/// Payload octets per segment (a link frame's 250 minus the header).
pub const MAX_PAYLOAD: usize = 249;
/// The default cap of a reassembled fragment.
pub const DEFAULT_MAX_FRAGMENT: usize = 2048;

/// The transport header octet.
pub fn header(fir: bool, fin: bool, seq: u8) -> u8 {
    (if fir { FIR } else { 0 }) | (if fin { FIN } else { 0 }) | (seq & SEQ_MASK)
}

/// Cut `apdu` into segments (header octet and payload), numbering from
/// `*seq` and advancing it. An empty APDU gives one empty FIR|FIN segment.
pub fn segment(apdu: &[u8], seq: &mut u8) -> Vec<Vec<u8>> {
    let chunks: Vec<&[u8]> = if apdu.is_empty() {
        vec![&[]]
    } else {
        apdu.chunks(MAX_PAYLOAD).collect()
    };
    let last = chunks.len() - 1;
    chunks
        .into_iter()
        .enumerate()
        .map(|(i, chunk)| {
            let mut s = Vec::with_capacity(1 + chunk.len());
            s.push(header(i == 0, i == last, *seq));
            s.extend_from_slice(chunk);
            *seq = (*seq + 1) & SEQ_MASK;
            s
        })
        .collect()
}

/// Why a received segment was discarded.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum TransportError {
    #[error("empty segment (no transport header)")]
    Empty,
    #[error("segment {seq} without FIR and no fragment under way: discarded")]
    NoFirst { seq: u8 },
    #[error(
        "segment {got} out of sequence (expected {expected}): the fragment under way is discarded"
    )]
    OutOfSequence { got: u8, expected: u8 },
    #[error("segment {seq} repeats the previous one: discarded")]
    Duplicate { seq: u8 },
    #[error("fragment would exceed {max} octets: discarded")]
    TooLong { max: usize },
}

/// Reassembles one direction's segments into fragments.
#[derive(Debug, Clone)]
pub struct Reassembler {
    max: usize,
    buf: Vec<u8>,
    /// The sequence number of the last accepted segment, while a fragment
    /// is under way.
    last: Option<u8>,
}

impl Default for Reassembler {
    fn default() -> Self {
        Reassembler::new(DEFAULT_MAX_FRAGMENT)
    }
}

impl Reassembler {
    /// A reassembler refusing fragments longer than `max` octets.
    pub fn new(max: usize) -> Reassembler {
        Reassembler {
            max,
            buf: Vec::new(),
            last: None,
        }
    }

    /// Forget a fragment under way (after a reconnect).
    pub fn reset(&mut self) {
        self.buf.clear();
        self.last = None;
    }

    /// Feed one segment: `Ok(Some(fragment))` when FIN completes one,
    /// `Ok(None)` when more are needed, `Err` when the segment was discarded.
    pub fn push(&mut self, segment: &[u8]) -> Result<Option<Vec<u8>>, TransportError> {
        let Some((&h, payload)) = segment.split_first() else {
            return Err(TransportError::Empty);
        };
        let seq = h & SEQ_MASK;
        if h & FIR != 0 {
            // A first segment always starts afresh (any partial one is lost).
            self.buf.clear();
            self.last = None;
        } else {
            let Some(last) = self.last else {
                return Err(TransportError::NoFirst { seq });
            };
            if seq == last {
                return Err(TransportError::Duplicate { seq });
            }
            let expected = (last + 1) & SEQ_MASK;
            if seq != expected {
                self.reset();
                return Err(TransportError::OutOfSequence { got: seq, expected });
            }
        }
        if self.buf.len() + payload.len() > self.max {
            self.reset();
            return Err(TransportError::TooLong { max: self.max });
        }
        self.buf.extend_from_slice(payload);
        if h & FIN != 0 {
            self.last = None;
            return Ok(Some(std::mem::take(&mut self.buf)));
        }
        self.last = Some(seq);
        Ok(None)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn segments_and_reassembles() {
        for len in [0usize, 1, 248, 249, 250, 498, 1000, 2048] {
            let apdu: Vec<u8> = (0..len).map(|i| i as u8).collect();
            let mut seq = 62;
            let segs = segment(&apdu, &mut seq);
            assert_eq!(segs.len(), len.div_ceil(MAX_PAYLOAD).max(1));
            assert!(segs.iter().all(|s| s.len() <= MAX_PAYLOAD + 1));
            assert_eq!(segs[0][0] & FIR, FIR);
            assert_eq!(segs.last().unwrap()[0] & FIN, FIN);
            assert_eq!(seq, ((62 + segs.len()) % 64) as u8);
            let mut r = Reassembler::default();
            let mut out = None;
            for s in &segs {
                out = r.push(s).unwrap();
            }
            assert_eq!(out, Some(apdu), "{len}");
        }
    }

    #[test]
    fn out_of_order_duplicate_and_oversized() {
        let apdu: Vec<u8> = (0..600).map(|i| i as u8).collect();
        let mut seq = 0;
        let segs = segment(&apdu, &mut seq);
        assert_eq!(segs.len(), 3);
        let mut r = Reassembler::default();
        // Without a first segment.
        assert_eq!(r.push(&segs[1]), Err(TransportError::NoFirst { seq: 1 }));
        // A duplicate is dropped and the fragment goes on.
        assert_eq!(r.push(&segs[0]), Ok(None));
        assert_eq!(r.push(&segs[0][..]).unwrap(), None, "FIR restarts");
        assert_eq!(r.push(&segs[1]), Ok(None));
        assert_eq!(r.push(&segs[1]), Err(TransportError::Duplicate { seq: 1 }));
        assert_eq!(r.push(&segs[2]), Ok(Some(apdu.clone())));
        // Out of order: the fragment under way is discarded.
        assert_eq!(r.push(&segs[0]), Ok(None));
        assert_eq!(
            r.push(&segs[2]),
            Err(TransportError::OutOfSequence {
                got: 2,
                expected: 1
            })
        );
        assert_eq!(r.push(&segs[1]), Err(TransportError::NoFirst { seq: 1 }));
        // Oversized.
        let mut small = Reassembler::new(500);
        assert_eq!(small.push(&segs[0]), Ok(None));
        assert_eq!(small.push(&segs[1]), Ok(None));
        assert_eq!(
            small.push(&segs[2]),
            Err(TransportError::TooLong { max: 500 })
        );
        assert_eq!(small.push(&[]), Err(TransportError::Empty));
        // Sequence wraps 63 -> 0.
        let mut seq = 63;
        let segs = segment(&apdu, &mut seq);
        let mut r = Reassembler::default();
        assert_eq!(r.push(&segs[0]), Ok(None));
        assert_eq!(r.push(&segs[1]), Ok(None));
        assert_eq!(r.push(&segs[2]), Ok(Some(apdu)));
    }
}
