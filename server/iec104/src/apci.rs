//! The APCI: the 104 frame around an ASDU (IEC 60870-5-104 clause 5).
//!
//! Every APDU starts with 0x68, a length octet (4..=253, counting the four
//! control octets and the ASDU) and four control octets whose low bits tell
//! the format: I (numbered information transfer, carries an ASDU), S
//! (numbered supervisory, acknowledges) or U (unnumbered control functions).
//!
//! [`decode`] is a streaming decoder: give it what the socket has read so far
//! and it answers with a frame and the octets it used, with "need more", or
//! with what is wrong. Decoding is strict (reserved control bits must be
//! zero), so any frame it accepts re-encodes to the same octets.

use thiserror::Error;

/// First octet of every APDU.
pub const START: u8 = 0x68;
/// Octets before the length counts: start and length.
pub const HEADER_LEN: usize = 2;
/// Shortest length octet: the four control octets.
pub const MIN_LENGTH: u8 = 4;
/// Longest length octet (APDU of 255 octets).
pub const MAX_LENGTH: u8 = 253;
/// Longest ASDU an I frame can carry.
pub const MAX_ASDU_LEN: usize = (MAX_LENGTH - MIN_LENGTH) as usize;
/// Sequence numbers count modulo 2^15.
pub const SEQ_MODULUS: u16 = 1 << 15;

/// The unnumbered control functions; each is a single bit of control octet 1.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum UFunction {
    StartDtAct,
    StartDtCon,
    StopDtAct,
    StopDtCon,
    TestFrAct,
    TestFrCon,
}

impl UFunction {
    const ALL: [UFunction; 6] = [
        UFunction::StartDtAct,
        UFunction::StartDtCon,
        UFunction::StopDtAct,
        UFunction::StopDtCon,
        UFunction::TestFrAct,
        UFunction::TestFrCon,
    ];

    /// The function bit in control octet 1 (the format bits 0b11 not included).
    pub fn bit(self) -> u8 {
        match self {
            UFunction::StartDtAct => 0x04,
            UFunction::StartDtCon => 0x08,
            UFunction::StopDtAct => 0x10,
            UFunction::StopDtCon => 0x20,
            UFunction::TestFrAct => 0x40,
            UFunction::TestFrCon => 0x80,
        }
    }

    /// The function named by one bit of control octet 1.
    pub fn from_bit(bit: u8) -> Option<UFunction> {
        Self::ALL.into_iter().find(|f| f.bit() == bit)
    }

    /// The answer a peer owes to an activation; `None` for a confirmation.
    pub fn confirmation(self) -> Option<UFunction> {
        match self {
            UFunction::StartDtAct => Some(UFunction::StartDtCon),
            UFunction::StopDtAct => Some(UFunction::StopDtCon),
            UFunction::TestFrAct => Some(UFunction::TestFrCon),
            _ => None,
        }
    }

    /// The standard's name, e.g. "STARTDT act".
    pub fn name(self) -> &'static str {
        match self {
            UFunction::StartDtAct => "STARTDT act",
            UFunction::StartDtCon => "STARTDT con",
            UFunction::StopDtAct => "STOPDT act",
            UFunction::StopDtCon => "STOPDT con",
            UFunction::TestFrAct => "TESTFR act",
            UFunction::TestFrCon => "TESTFR con",
        }
    }
}

impl std::fmt::Display for UFunction {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// One APDU.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub enum Frame {
    /// Information transfer: N(S), N(R) (15 bits each) and the ASDU's octets.
    I {
        send_seq: u16,
        recv_seq: u16,
        asdu: Vec<u8>,
    },
    /// Supervisory: acknowledges I frames up to `recv_seq` - 1.
    S { recv_seq: u16 },
    /// Unnumbered control function.
    U(UFunction),
}

/// What is wrong with a frame, found while decoding or encoding.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum FrameError {
    #[error("bad start byte 0x{0:02X}, expected 0x68")]
    BadStart(u8),
    #[error("length {0} out of range 4..=253")]
    Length(u8),
    #[error("I frame without ASDU")]
    IWithoutAsdu,
    #[error("{format} frame with length {length}, must be 4")]
    ShortFormatLength { format: &'static str, length: u8 },
    #[error("U frame with several function bits (control octet 1 = 0x{0:02X})")]
    SeveralFunctions(u8),
    #[error("U frame with no function bit (control octet 1 = 0x{0:02X})")]
    NoFunction(u8),
    #[error("{format} frame with reserved bits set in control octet {octet} (0x{value:02X})")]
    Reserved {
        format: &'static str,
        octet: u8,
        value: u8,
    },
    #[error("{which} sequence number {value} out of range 0..=32767")]
    Sequence { which: &'static str, value: u16 },
    #[error("ASDU of {0} octets out of range 1..=249")]
    AsduLength(usize),
}

/// The octets of a frame. Fails only for a hand-built frame that the format
/// cannot carry: a sequence number past 15 bits, an ASDU empty or longer
/// than 249 octets.
pub fn encode(frame: &Frame) -> Result<Vec<u8>, FrameError> {
    let (control, asdu): ([u8; 4], &[u8]) = match frame {
        Frame::I {
            send_seq,
            recv_seq,
            asdu,
        } => {
            if asdu.is_empty() || asdu.len() > MAX_ASDU_LEN {
                return Err(FrameError::AsduLength(asdu.len()));
            }
            let s = seq_field("send", *send_seq)?;
            let r = seq_field("receive", *recv_seq)?;
            ([s[0], s[1], r[0], r[1]], asdu)
        }
        Frame::S { recv_seq } => {
            let r = seq_field("receive", *recv_seq)?;
            ([0x01, 0x00, r[0], r[1]], &[])
        }
        Frame::U(f) => ([f.bit() | 0x03, 0, 0, 0], &[]),
    };
    let mut out = Vec::with_capacity(HEADER_LEN + 4 + asdu.len());
    out.push(START);
    // asdu.len() <= 249 was checked above, so this fits an octet.
    out.push(MIN_LENGTH + asdu.len() as u8);
    out.extend_from_slice(&control);
    out.extend_from_slice(asdu);
    Ok(out)
}

/// A sequence number shifted into its two control octets (bit 0 left clear).
fn seq_field(which: &'static str, value: u16) -> Result<[u8; 2], FrameError> {
    if value >= SEQ_MODULUS {
        return Err(FrameError::Sequence { which, value });
    }
    Ok((value << 1).to_le_bytes())
}

/// Decode the frame at the start of `buf`: `Ok(None)` when more octets are
/// needed, else the frame and how many octets it took. Never panics, and
/// allocates at most the ASDU the length octet announces (<= 249 octets).
pub fn decode(buf: &[u8]) -> Result<Option<(Frame, usize)>, FrameError> {
    let Some(&start) = buf.first() else {
        return Ok(None);
    };
    if start != START {
        return Err(FrameError::BadStart(start));
    }
    let Some(&length) = buf.get(1) else {
        return Ok(None);
    };
    if !(MIN_LENGTH..=MAX_LENGTH).contains(&length) {
        return Err(FrameError::Length(length));
    }
    let total = HEADER_LEN + usize::from(length);
    let Some(apdu) = buf.get(..total) else {
        return Ok(None);
    };
    let c = [apdu[2], apdu[3], apdu[4], apdu[5]];
    let frame = if c[0] & 0x01 == 0 {
        if length == MIN_LENGTH {
            return Err(FrameError::IWithoutAsdu);
        }
        check_recv_bit("I", c[2])?;
        Frame::I {
            send_seq: u16::from_le_bytes([c[0], c[1]]) >> 1,
            recv_seq: u16::from_le_bytes([c[2], c[3]]) >> 1,
            asdu: apdu[6..].to_vec(),
        }
    } else if c[0] & 0x03 == 0x01 {
        if length != MIN_LENGTH {
            return Err(FrameError::ShortFormatLength {
                format: "S",
                length,
            });
        }
        if c[0] != 0x01 || c[1] != 0 {
            let (octet, value) = if c[0] != 0x01 { (1, c[0]) } else { (2, c[1]) };
            return Err(FrameError::Reserved {
                format: "S",
                octet,
                value,
            });
        }
        check_recv_bit("S", c[2])?;
        Frame::S {
            recv_seq: u16::from_le_bytes([c[2], c[3]]) >> 1,
        }
    } else {
        if length != MIN_LENGTH {
            return Err(FrameError::ShortFormatLength {
                format: "U",
                length,
            });
        }
        if let Some(i) = (1..4).find(|&i| c[i] != 0) {
            return Err(FrameError::Reserved {
                format: "U",
                octet: i as u8 + 1,
                value: c[i],
            });
        }
        let bits = c[0] & 0xFC;
        match bits.count_ones() {
            0 => return Err(FrameError::NoFunction(c[0])),
            1 => {}
            _ => return Err(FrameError::SeveralFunctions(c[0])),
        }
        // Exactly one of the six function bits is set, so this always finds one.
        Frame::U(UFunction::from_bit(bits).ok_or(FrameError::NoFunction(c[0]))?)
    };
    Ok(Some((frame, total)))
}

/// Bit 0 of control octet 3 is reserved (zero) in I and S frames.
fn check_recv_bit(format: &'static str, octet3: u8) -> Result<(), FrameError> {
    if octet3 & 0x01 != 0 {
        return Err(FrameError::Reserved {
            format,
            octet: 3,
            value: octet3,
        });
    }
    Ok(())
}

/// Steps from `from` forward to `to`, modulo 2^15: how many I frames are
/// outstanding between an acknowledged N(R) and the next N(S), to hold the
/// k and w limits. Inputs are taken modulo 2^15.
pub fn seq_distance(from: u16, to: u16) -> u16 {
    to.wrapping_sub(from) % SEQ_MODULUS
}

/// `seq` advanced by `n`, modulo 2^15.
pub fn seq_add(seq: u16, n: u16) -> u16 {
    seq.wrapping_add(n) % SEQ_MODULUS
}

/// Whether a received N(R) acknowledges a valid span: it must lie between the
/// oldest unacknowledged N(S) `oldest` and the next N(S) `next`, inclusive.
/// An N(R) outside that span is a protocol error (the standard closes the
/// connection).
pub fn seq_ack_valid(recv_seq: u16, oldest: u16, next: u16) -> bool {
    seq_distance(oldest, recv_seq) <= seq_distance(oldest, next)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hex(s: &str) -> Vec<u8> {
        s.split_whitespace()
            .map(|b| u8::from_str_radix(b, 16).unwrap())
            .collect()
    }

    #[test]
    fn u_frames_from_the_standard() {
        for (bytes, f) in [
            ("68 04 07 00 00 00", UFunction::StartDtAct),
            ("68 04 0B 00 00 00", UFunction::StartDtCon),
            ("68 04 13 00 00 00", UFunction::StopDtAct),
            ("68 04 23 00 00 00", UFunction::StopDtCon),
            ("68 04 43 00 00 00", UFunction::TestFrAct),
            ("68 04 83 00 00 00", UFunction::TestFrCon),
        ] {
            let b = hex(bytes);
            assert_eq!(decode(&b), Ok(Some((Frame::U(f), 6))), "{bytes}");
            assert_eq!(encode(&Frame::U(f)).unwrap(), b);
        }
        assert_eq!(
            UFunction::StartDtAct.confirmation(),
            Some(UFunction::StartDtCon)
        );
        assert_eq!(UFunction::TestFrCon.confirmation(), None);
    }

    #[test]
    fn i_and_s_frames() {
        // N(S) = 5, N(R) = 3, then an S frame acknowledging 0x1234.
        let b = hex("68 05 0A 00 06 00 AB");
        assert_eq!(
            decode(&b),
            Ok(Some((
                Frame::I {
                    send_seq: 5,
                    recv_seq: 3,
                    asdu: vec![0xAB]
                },
                7
            )))
        );
        let s = Frame::S { recv_seq: 0x1234 };
        let b = encode(&s).unwrap();
        assert_eq!(b, hex("68 04 01 00 68 24"));
        assert_eq!(decode(&b), Ok(Some((s, 6))));
        // The largest sequence numbers.
        let i = Frame::I {
            send_seq: 32767,
            recv_seq: 32767,
            asdu: vec![1; MAX_ASDU_LEN],
        };
        let b = encode(&i).unwrap();
        assert_eq!(&b[..6], &hex("68 FD FE FF FE FF")[..]);
        assert_eq!(decode(&b), Ok(Some((i, 255))));
    }

    #[test]
    fn streaming_needs_more_then_leaves_the_rest() {
        let mut stream = encode(&Frame::U(UFunction::TestFrAct)).unwrap();
        stream.extend(hex("68 04 01 00 02 00 68"));
        for n in 0..6 {
            assert_eq!(decode(&stream[..n]), Ok(None), "prefix {n}");
        }
        let (f, used) = decode(&stream).unwrap().unwrap();
        assert_eq!((f, used), (Frame::U(UFunction::TestFrAct), 6));
        let (f, used) = decode(&stream[used..]).unwrap().unwrap();
        assert_eq!((f, used), (Frame::S { recv_seq: 1 }, 6));
        assert_eq!(decode(&stream[12..]), Ok(None));
    }

    #[test]
    fn errors_name_what_is_wrong() {
        let e = |s: &str| decode(&hex(s)).unwrap_err().to_string();
        assert_eq!(e("16"), "bad start byte 0x16, expected 0x68");
        assert_eq!(e("68 03"), "length 3 out of range 4..=253");
        assert_eq!(e("68 FE"), "length 254 out of range 4..=253");
        assert_eq!(e("68 04 00 00 00 00"), "I frame without ASDU");
        assert_eq!(
            e("68 05 01 00 00 00 00"),
            "S frame with length 5, must be 4"
        );
        assert_eq!(
            e("68 05 07 00 00 00 00"),
            "U frame with length 5, must be 4"
        );
        assert_eq!(
            e("68 04 0F 00 00 00"),
            "U frame with several function bits (control octet 1 = 0x0F)"
        );
        assert_eq!(
            e("68 04 03 00 00 00"),
            "U frame with no function bit (control octet 1 = 0x03)"
        );
        assert_eq!(
            e("68 04 07 00 01 00"),
            "U frame with reserved bits set in control octet 3 (0x01)"
        );
        assert_eq!(
            e("68 04 05 00 00 00"),
            "S frame with reserved bits set in control octet 1 (0x05)"
        );
        assert_eq!(
            e("68 05 00 00 01 00 AA"),
            "I frame with reserved bits set in control octet 3 (0x01)"
        );
        let long = Frame::I {
            send_seq: 0,
            recv_seq: 0,
            asdu: vec![0; 250],
        };
        assert_eq!(encode(&long), Err(FrameError::AsduLength(250)));
        let bad = Frame::S { recv_seq: 32768 };
        assert_eq!(
            encode(&bad).unwrap_err().to_string(),
            "receive sequence number 32768 out of range 0..=32767"
        );
    }

    #[test]
    fn sequence_arithmetic_wraps_at_2_pow_15() {
        assert_eq!(seq_distance(0, 0), 0);
        assert_eq!(seq_distance(10, 12), 2);
        assert_eq!(seq_distance(32767, 0), 1);
        assert_eq!(seq_distance(32760, 5), 13);
        assert_eq!(seq_distance(5, 4), 32767);
        assert_eq!(seq_add(32767, 1), 0);
        assert_eq!(seq_add(32000, 1000), 232);
        // Outstanding 32766, 32767, 0, 1; next N(S) = 2.
        assert!(seq_ack_valid(32766, 32766, 2));
        assert!(seq_ack_valid(0, 32766, 2));
        assert!(seq_ack_valid(2, 32766, 2));
        assert!(!seq_ack_valid(3, 32766, 2));
        assert!(!seq_ack_valid(32765, 32766, 2));
    }
}
