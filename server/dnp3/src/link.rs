//! The DNP3 data link layer (IEEE 1815-2012 clause 9): the FT3 frame.
//!
//! A frame is a ten-octet header (0x05 0x64, length, control, destination,
//! source, CRC) and up to 250 octets of user data, sent in blocks of 16
//! octets each followed by its own CRC. The length octet counts control,
//! addresses and user data (5..=255), not the CRCs.
//!
//! [`decode`] is a streaming decoder: give it what the socket has read so
//! far and it answers with a frame and the octets it used, "need more"
//! (`Ok(None)`), or what is wrong; every error says how many octets to
//! discard ([`LinkError::discard`]) so the caller resynchronises on the next
//! 0x05 0x64. It never panics and allocates at most the 250 octets a valid
//! header announces.

use thiserror::Error;

/// The two start octets of every frame.
pub const START: [u8; 2] = [0x05, 0x64];
/// Octets of the header, CRC included.
pub const HEADER_LEN: usize = 10;
/// Most user data one frame carries.
pub const MAX_USER_DATA: usize = 250;
/// User data octets per CRC block.
pub const BLOCK: usize = 16;

/// Control octet bits.
pub const DIR: u8 = 0x80;
pub const PRM: u8 = 0x40;
pub const FCB: u8 = 0x20;
/// FCV in a primary frame, DFC in a secondary one.
pub const FCV_DFC: u8 = 0x10;

/// The DNP CRC-16 (polynomial 0x3D65, reflected 0xA6BC, initial 0, final
/// complement), as sent: low octet first.
pub fn crc(data: &[u8]) -> u16 {
    let mut crc: u16 = 0;
    for &b in data {
        crc ^= u16::from(b);
        for _ in 0..8 {
            crc = if crc & 1 != 0 {
                (crc >> 1) ^ 0xA6BC
            } else {
                crc >> 1
            };
        }
    }
    !crc
}

/// The link function codes this master knows, primary and secondary.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum LinkFunction {
    /// Primary 0.
    ResetLinkStates,
    /// Primary 2.
    TestLink,
    /// Primary 3.
    ConfirmedUserData,
    /// Primary 4.
    UnconfirmedUserData,
    /// Primary 9.
    RequestLinkStatus,
    /// Secondary 0.
    Ack,
    /// Secondary 1.
    Nack,
    /// Secondary 11.
    LinkStatus,
    /// Secondary 15.
    NotSupported,
}

impl LinkFunction {
    const ALL: [LinkFunction; 9] = [
        LinkFunction::ResetLinkStates,
        LinkFunction::TestLink,
        LinkFunction::ConfirmedUserData,
        LinkFunction::UnconfirmedUserData,
        LinkFunction::RequestLinkStatus,
        LinkFunction::Ack,
        LinkFunction::Nack,
        LinkFunction::LinkStatus,
        LinkFunction::NotSupported,
    ];

    /// Whether the function is sent by a primary station (PRM = 1).
    pub fn is_primary(self) -> bool {
        matches!(
            self,
            LinkFunction::ResetLinkStates
                | LinkFunction::TestLink
                | LinkFunction::ConfirmedUserData
                | LinkFunction::UnconfirmedUserData
                | LinkFunction::RequestLinkStatus
        )
    }

    /// The four-bit function code.
    pub fn code(self) -> u8 {
        match self {
            LinkFunction::ResetLinkStates => 0,
            LinkFunction::TestLink => 2,
            LinkFunction::ConfirmedUserData => 3,
            LinkFunction::UnconfirmedUserData => 4,
            LinkFunction::RequestLinkStatus => 9,
            LinkFunction::Ack => 0,
            LinkFunction::Nack => 1,
            LinkFunction::LinkStatus => 11,
            LinkFunction::NotSupported => 15,
        }
    }

    /// The function of a PRM bit and a code.
    pub fn from_code(primary: bool, code: u8) -> Option<LinkFunction> {
        Self::ALL
            .into_iter()
            .find(|f| f.is_primary() == primary && f.code() == code)
    }

    /// The standard's name.
    pub fn name(self) -> &'static str {
        match self {
            LinkFunction::ResetLinkStates => "RESET_LINK_STATES",
            LinkFunction::TestLink => "TEST_LINK_STATES",
            LinkFunction::ConfirmedUserData => "CONFIRMED_USER_DATA",
            LinkFunction::UnconfirmedUserData => "UNCONFIRMED_USER_DATA",
            LinkFunction::RequestLinkStatus => "REQUEST_LINK_STATUS",
            LinkFunction::Ack => "ACK",
            LinkFunction::Nack => "NACK",
            LinkFunction::LinkStatus => "LINK_STATUS",
            LinkFunction::NotSupported => "NOT_SUPPORTED",
        }
    }
}

impl std::fmt::Display for LinkFunction {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// One link frame. `fcb` and `fcv_dfc` are the control octet's bits 5 and
/// 4 (FCB/FCV for a primary frame; bit 5 reserved and DFC for a secondary).
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct LinkFrame {
    /// DIR: set in frames from the master.
    pub dir: bool,
    pub function: LinkFunction,
    pub fcb: bool,
    pub fcv_dfc: bool,
    pub destination: u16,
    pub source: u16,
    /// User data (a transport segment), at most 250 octets.
    pub data: Vec<u8>,
}

impl LinkFrame {
    /// An UNCONFIRMED_USER_DATA frame from a master (DIR = 1).
    pub fn user_data(destination: u16, source: u16, data: Vec<u8>) -> LinkFrame {
        LinkFrame {
            dir: true,
            function: LinkFunction::UnconfirmedUserData,
            fcb: false,
            fcv_dfc: false,
            destination,
            source,
            data,
        }
    }

    /// A frame without user data.
    pub fn header_only(dir: bool, function: LinkFunction, destination: u16, source: u16) -> Self {
        LinkFrame {
            dir,
            function,
            fcb: false,
            fcv_dfc: false,
            destination,
            source,
            data: Vec::new(),
        }
    }

    /// The control octet.
    pub fn control(&self) -> u8 {
        let mut c = self.function.code();
        if self.dir {
            c |= DIR;
        }
        if self.function.is_primary() {
            c |= PRM;
        }
        if self.fcb {
            c |= FCB;
        }
        if self.fcv_dfc {
            c |= FCV_DFC;
        }
        c
    }

    /// The octets of the frame; fails only for user data past 250 octets.
    pub fn encode(&self) -> Result<Vec<u8>, LinkError> {
        if self.data.len() > MAX_USER_DATA {
            return Err(LinkError::DataTooLong(self.data.len()));
        }
        let blocks = self.data.len().div_ceil(BLOCK);
        let mut out = Vec::with_capacity(HEADER_LEN + self.data.len() + 2 * blocks);
        out.extend_from_slice(&START);
        // <= 250 + 5, checked above.
        out.push((self.data.len() + 5) as u8);
        out.push(self.control());
        out.extend_from_slice(&self.destination.to_le_bytes());
        out.extend_from_slice(&self.source.to_le_bytes());
        let c = crc(&out[..8]);
        out.extend_from_slice(&c.to_le_bytes());
        for block in self.data.chunks(BLOCK) {
            out.extend_from_slice(block);
            out.extend_from_slice(&crc(block).to_le_bytes());
        }
        Ok(out)
    }
}

/// What is wrong with the octets at the start of the buffer.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum LinkError {
    #[error("{skipped} octets of garbage before the next 0x05 0x64")]
    Garbage { skipped: usize },
    #[error("length octet {0} out of range 5..=255 (octet 2)")]
    Length(u8),
    #[error("header CRC 0x{found:04X}, computed 0x{computed:04X} (octets 8-9)")]
    HeaderCrc { found: u16, computed: u16 },
    #[error("CRC of user data block {block} is 0x{found:04X}, computed 0x{computed:04X} (octets {offset}..)")]
    BlockCrc {
        block: usize,
        offset: usize,
        found: u16,
        computed: u16,
        frame_len: usize,
    },
    #[error("unknown link function {code} with PRM = {primary} (control octet 0x{control:02X}, octet 3)")]
    UnknownFunction {
        primary: bool,
        code: u8,
        control: u8,
        frame_len: usize,
    },
    #[error("user data of {0} octets, at most 250 fit a frame")]
    DataTooLong(usize),
}

impl LinkError {
    /// How many octets the caller drops before decoding again.
    pub fn discard(&self) -> usize {
        match self {
            LinkError::Garbage { skipped } => *skipped,
            // A bad header: the length cannot be trusted; skip the start
            // octets and look for the next frame.
            LinkError::Length(_) | LinkError::HeaderCrc { .. } => START.len(),
            LinkError::BlockCrc { frame_len, .. }
            | LinkError::UnknownFunction { frame_len, .. } => *frame_len,
            LinkError::DataTooLong(_) => 0,
        }
    }
}

/// The octets a frame whose length octet is `length` takes on the wire.
pub fn frame_len(length: u8) -> usize {
    let data = usize::from(length).saturating_sub(5);
    HEADER_LEN + data + 2 * data.div_ceil(BLOCK)
}

/// Takes the next frame off the front of `rx` (octets as they arrived):
/// `Some(Ok(frame))`; `Some(Err(e))` after dropping the octets that are
/// wrong, so the stream resynchronises; `None` while `rx` holds no whole
/// frame yet.
pub fn take_frame(rx: &mut Vec<u8>) -> Option<Result<LinkFrame, LinkError>> {
    match decode(rx) {
        Ok(None) => None,
        Ok(Some((frame, n))) => {
            rx.drain(..n);
            Some(Ok(frame))
        }
        Err(e) => {
            let n = e.discard().clamp(1, rx.len());
            rx.drain(..n);
            Some(Err(e))
        }
    }
}

/// Decode the frame at the start of `buf`: `Ok(None)` when more octets are
/// needed, else the frame and the octets it took; on `Err`, drop
/// [`LinkError::discard`] octets and decode again.
pub fn decode(buf: &[u8]) -> Result<Option<(LinkFrame, usize)>, LinkError> {
    if buf.is_empty() {
        return Ok(None);
    }
    if buf[0] != START[0] || buf.get(1).is_some_and(|&b| b != START[1]) {
        // Resynchronise: everything before the next 0x05 0x64, keeping a
        // final 0x05 that may start one.
        let skipped = buf
            .windows(2)
            .skip(1)
            .position(|w| w == START)
            .map(|p| p + 1)
            .unwrap_or(if buf.last() == Some(&START[0]) {
                buf.len() - 1
            } else {
                buf.len()
            });
        return Err(LinkError::Garbage {
            skipped: skipped.max(1),
        });
    }
    let Some(header) = buf.get(..HEADER_LEN) else {
        return Ok(None);
    };
    let length = header[2];
    if length < 5 {
        return Err(LinkError::Length(length));
    }
    let found = u16::from_le_bytes([header[8], header[9]]);
    let computed = crc(&header[..8]);
    if found != computed {
        return Err(LinkError::HeaderCrc { found, computed });
    }
    let total = frame_len(length);
    let Some(frame) = buf.get(..total) else {
        return Ok(None);
    };
    let control = header[3];
    let primary = control & PRM != 0;
    let Some(function) = LinkFunction::from_code(primary, control & 0x0F) else {
        return Err(LinkError::UnknownFunction {
            primary,
            code: control & 0x0F,
            control,
            frame_len: total,
        });
    };
    let data_len = usize::from(length) - 5;
    let mut data = Vec::with_capacity(data_len);
    let mut offset = HEADER_LEN;
    let mut block = 0;
    while data.len() < data_len {
        let n = (data_len - data.len()).min(BLOCK);
        let chunk = &frame[offset..offset + n];
        let found = u16::from_le_bytes([frame[offset + n], frame[offset + n + 1]]);
        let computed = crc(chunk);
        if found != computed {
            return Err(LinkError::BlockCrc {
                block,
                offset,
                found,
                computed,
                frame_len: total,
            });
        }
        data.extend_from_slice(chunk);
        offset += n + 2;
        block += 1;
    }
    Ok(Some((
        LinkFrame {
            dir: control & DIR != 0,
            function,
            fcb: control & FCB != 0,
            fcv_dfc: control & FCV_DFC != 0,
            destination: u16::from_le_bytes([header[4], header[5]]),
            source: u16::from_le_bytes([header[6], header[7]]),
            data,
        },
        total,
    )))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_util::hex;

    #[test]
    fn crc_vector_from_the_standard() {
        let h = hex("05 64 05 C0 01 00 00 04");
        assert_eq!(crc(&h).to_le_bytes(), [0xE9, 0x21]);
        // A request link status from master 1 to outstation 1024.
        let f = LinkFrame::header_only(true, LinkFunction::ResetLinkStates, 1, 1024);
        assert_eq!(f.encode().unwrap(), hex("05 64 05 C0 01 00 00 04 E9 21"));
        assert_eq!(
            decode(&hex("05 64 05 C0 01 00 00 04 E9 21")),
            Ok(Some((f, 10)))
        );
    }

    #[test]
    fn every_function_round_trips_with_and_without_data() {
        for function in LinkFunction::ALL {
            for len in [0usize, 1, 15, 16, 17, 32, 33, 249, 250] {
                let data: Vec<u8> = (0..len).map(|i| (i * 7) as u8).collect();
                let f = LinkFrame {
                    dir: len % 2 == 0,
                    function,
                    fcb: function.is_primary() && len % 3 == 0,
                    fcv_dfc: len % 5 == 0,
                    destination: 0x1234,
                    source: 0xFFFE,
                    data,
                };
                let b = f.encode().unwrap();
                assert_eq!(b.len(), frame_len((len + 5) as u8));
                assert_eq!(
                    decode(&b),
                    Ok(Some((f.clone(), b.len()))),
                    "{function} {len}"
                );
                // Every prefix asks for more.
                for cut in 0..b.len() {
                    assert_eq!(decode(&b[..cut]), Ok(None), "{function} {len} cut {cut}");
                }
            }
        }
        let f = LinkFrame::user_data(1, 2, vec![0; 251]);
        assert_eq!(f.encode(), Err(LinkError::DataTooLong(251)));
    }

    #[test]
    fn resynchronises_on_garbage() {
        let frame = LinkFrame::user_data(10, 1, vec![0xC0, 0xC1, 0x01])
            .encode()
            .unwrap();
        let mut buf = hex("00 05 FF 64 05");
        buf.extend_from_slice(&frame);
        let err = decode(&buf).unwrap_err();
        assert_eq!(err, LinkError::Garbage { skipped: 5 });
        let rest = &buf[err.discard()..];
        assert_eq!(decode(rest).unwrap().unwrap().1, frame.len());
        // A trailing 0x05 is kept.
        assert_eq!(
            decode(&hex("11 22 05")),
            Err(LinkError::Garbage { skipped: 2 })
        );
        assert_eq!(decode(&hex("05")), Ok(None));
    }

    #[test]
    fn bad_crcs_say_where() {
        let mut b = LinkFrame::user_data(10, 1, (0..40).collect())
            .encode()
            .unwrap();
        b[9] ^= 1;
        assert!(matches!(decode(&b), Err(LinkError::HeaderCrc { .. })));
        b[9] ^= 1;
        // Second block: octets 28..44 and its CRC.
        b[30] ^= 0x80;
        let e = decode(&b).unwrap_err();
        assert!(
            matches!(
                e,
                LinkError::BlockCrc {
                    block: 1,
                    offset: 28,
                    ..
                }
            ),
            "{e}"
        );
        assert_eq!(e.discard(), b.len());
        assert!(e.to_string().contains("block 1"));
    }

    #[test]
    fn unknown_function_and_length() {
        // Primary function 5 does not exist.
        let mut h = hex("05 64 05 C5 01 00 00 04");
        let c = crc(&h);
        h.extend_from_slice(&c.to_le_bytes());
        assert!(matches!(
            decode(&h),
            Err(LinkError::UnknownFunction { code: 5, .. })
        ));
        let mut h = hex("05 64 04 C0 01 00 00 04");
        let c = crc(&h);
        h.extend_from_slice(&c.to_le_bytes());
        assert_eq!(decode(&h), Err(LinkError::Length(4)));
    }
}
