//! The OSI upper layers MMS rides on (IEC 61850-8-1's A-profile over
//! TCP): TPKT framing (RFC 1006), the COTP class-0 transport (ISO 8073),
//! the session kernel (ISO 8327), the presentation kernel (ISO 8823) and
//! ACSE (ISO 8650), each only as far as an MMS client needs it.
//!
//! Pure: [`Stack`] turns an MMS PDU into the octets to send and a received
//! TPKT packet into what it carries, reassembling segmented COTP data and
//! splitting our own to the negotiated TPDU size. Nothing here touches a
//! socket.

use crate::ber::{BerError, Reader, Tag, Writer};

/// Object identifiers of the upper layers.
pub mod oid {
    /// ACSE's abstract syntax (2.2.1.0.1).
    pub const ACSE: &[u32] = &[2, 2, 1, 0, 1];
    /// BER transfer syntax (2.1.1).
    pub const BER: &[u32] = &[2, 1, 1];
    /// MMS's abstract syntax (1.0.9506.2.1).
    pub const MMS: &[u32] = &[1, 0, 9506, 2, 1];
    /// MMS's application context (1.0.9506.2.3).
    pub const MMS_CONTEXT: &[u32] = &[1, 0, 9506, 2, 3];
}

/// Presentation context identifiers we propose: 1 for ACSE, 3 for MMS (as
/// every IEC 61850 client does).
const ACSE_CONTEXT: i64 = 1;
const MMS_CONTEXT: i64 = 3;

/// Largest TPKT packet (its length field is 16 bits).
pub const MAX_TPKT: usize = 65_535;

/// What is wrong with a packet of the upper layers, and where.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum IsoError {
    #[error("TPKT: {0}")]
    Tpkt(String),
    #[error("COTP: {0}")]
    Cotp(String),
    #[error("session: {0}")]
    Session(String),
    #[error("presentation: {0}")]
    Presentation(BerError),
    #[error("ACSE: {0}")]
    Acse(BerError),
}

/// The addresses of both ends above TCP: transport, session and
/// presentation selectors, and the ACSE AP titles and AE qualifiers.
/// The defaults are those of most IEC 61850 clients and IEDs.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Addressing {
    pub local_tsel: Vec<u8>,
    pub remote_tsel: Vec<u8>,
    pub local_ssel: Vec<u8>,
    pub remote_ssel: Vec<u8>,
    pub local_psel: Vec<u8>,
    pub remote_psel: Vec<u8>,
    pub local_ap_title: Option<Vec<u32>>,
    pub local_ae_qualifier: Option<i64>,
    pub remote_ap_title: Option<Vec<u32>>,
    pub remote_ae_qualifier: Option<i64>,
}

impl Default for Addressing {
    fn default() -> Self {
        Addressing {
            local_tsel: vec![0, 1],
            remote_tsel: vec![0, 1],
            local_ssel: vec![0, 1],
            remote_ssel: vec![0, 1],
            local_psel: vec![0, 0, 0, 1],
            remote_psel: vec![0, 0, 0, 1],
            local_ap_title: Some(vec![1, 1, 1, 999, 1]),
            local_ae_qualifier: Some(12),
            remote_ap_title: Some(vec![1, 1, 1, 999]),
            remote_ae_qualifier: Some(12),
        }
    }
}

/// Splits a TCP byte stream into TPKT packets.
#[derive(Debug, Default)]
pub struct TpktDecoder {
    buf: Vec<u8>,
}

impl TpktDecoder {
    pub fn push(&mut self, octets: &[u8]) {
        self.buf.extend_from_slice(octets);
    }

    /// The next whole packet's payload (after the 4-octet header), if one
    /// has arrived. An error means the stream cannot be resynchronised.
    pub fn next_packet(&mut self) -> Result<Option<Vec<u8>>, IsoError> {
        if self.buf.len() < 4 {
            return Ok(None);
        }
        if self.buf[0] != 3 {
            return Err(IsoError::Tpkt(format!(
                "version {} (expected 3)",
                self.buf[0]
            )));
        }
        let len = usize::from(u16::from_be_bytes([self.buf[2], self.buf[3]]));
        if len < 7 {
            return Err(IsoError::Tpkt(format!(
                "packet length {len} is too short for COTP"
            )));
        }
        if self.buf.len() < len {
            return Ok(None);
        }
        let payload = self.buf[4..len].to_vec();
        self.buf.drain(..len);
        Ok(Some(payload))
    }

    /// Octets received that are not yet a whole packet.
    pub fn pending(&self) -> usize {
        self.buf.len()
    }
}

/// A TPKT packet around `payload`.
pub fn tpkt(payload: &[u8]) -> Vec<u8> {
    let len = (payload.len() + 4) as u16;
    let mut out = vec![3, 0];
    out.extend_from_slice(&len.to_be_bytes());
    out.extend_from_slice(payload);
    out
}

/// What an incoming packet carried, once its layers are peeled.
#[derive(Debug, Clone, PartialEq)]
pub enum Incoming {
    /// COTP connection confirmed.
    Connected,
    /// The association was accepted; the MMS initiate-ResponsePDU.
    Accepted(Vec<u8>),
    /// The association was refused, with the reason in words.
    Refused(String),
    /// An MMS PDU in the data phase.
    Mms(Vec<u8>),
    /// A segment of a longer COTP data unit: more to come.
    Partial,
    /// The peer ended the connection (disconnect, abort, finish), why in words.
    Closed(String),
}

/// The client side of the upper layers for one TCP connection.
#[derive(Debug)]
pub struct Stack {
    pub addressing: Addressing,
    /// Largest COTP TPDU the peer accepts (from its CC).
    tpdu_size: usize,
    reassembly: Vec<u8>,
    /// Largest reassembled COTP data unit we accept.
    max_message: usize,
}

/// TPDU size we propose (8192 octets, code 0x0d).
const PROPOSED_TPDU_SIZE_CODE: u8 = 0x0d;

impl Stack {
    pub fn new(addressing: Addressing, max_message: usize) -> Stack {
        Stack {
            addressing,
            tpdu_size: 1 << PROPOSED_TPDU_SIZE_CODE,
            reassembly: Vec::new(),
            max_message,
        }
    }

    /// The COTP connection request, as a TPKT packet.
    pub fn connect_request(&self) -> Vec<u8> {
        let a = &self.addressing;
        let mut cr = vec![0, 0xe0, 0, 0, 0, 1, 0];
        cr.extend([0xc0, 1, PROPOSED_TPDU_SIZE_CODE]);
        cr.push(0xc1);
        cr.push(a.local_tsel.len() as u8);
        cr.extend_from_slice(&a.local_tsel);
        cr.push(0xc2);
        cr.push(a.remote_tsel.len() as u8);
        cr.extend_from_slice(&a.remote_tsel);
        cr[0] = (cr.len() - 1) as u8;
        tpkt(&cr)
    }

    /// The association request (session CN, presentation CP, ACSE AARQ)
    /// carrying the MMS initiate-RequestPDU, as TPKT packets.
    pub fn associate_request(&self, initiate: &[u8]) -> Vec<Vec<u8>> {
        let aarq = self.aarq(initiate);
        let cp = self.presentation_connect(&aarq);
        let cn = self.session_connect(&cp);
        self.cotp_data(&cn)
    }

    /// An MMS PDU in the data phase, as TPKT packets.
    pub fn data(&self, mms: &[u8]) -> Vec<Vec<u8>> {
        let mut spdu = vec![0x01, 0x00, 0x01, 0x00]; // Give tokens, Data transfer
        spdu.extend(presentation_user_data(mms));
        self.cotp_data(&spdu)
    }

    /// COTP DT units no larger than the peer's TPDU size.
    fn cotp_data(&self, payload: &[u8]) -> Vec<Vec<u8>> {
        let room = self.tpdu_size.saturating_sub(3).max(1);
        let chunks: Vec<&[u8]> = if payload.is_empty() {
            vec![&[]]
        } else {
            payload.chunks(room).collect()
        };
        let last = chunks.len() - 1;
        chunks
            .iter()
            .enumerate()
            .map(|(i, chunk)| {
                let mut dt = vec![2, 0xf0, if i == last { 0x80 } else { 0 }];
                dt.extend_from_slice(chunk);
                tpkt(&dt)
            })
            .collect()
    }

    fn session_connect(&self, user_data: &[u8]) -> Vec<u8> {
        let a = &self.addressing;
        let mut params = vec![
            0x05, 0x06, 0x13, 0x01, 0x00, 0x16, 0x01,
            0x02, // connect/accept item: options 0, version 2
            0x14, 0x02, 0x00, 0x02, // session user requirements: duplex
        ];
        session_param(&mut params, 0x33, &a.local_ssel);
        session_param(&mut params, 0x34, &a.remote_ssel);
        session_param(&mut params, 0xc1, user_data);
        let mut spdu = vec![0x0d];
        session_length(&mut spdu, params.len());
        spdu.extend(params);
        spdu
    }

    fn presentation_connect(&self, aarq: &[u8]) -> Vec<u8> {
        let a = &self.addressing;
        let mut w = Writer::new();
        w.constructed(Tag::SET, |w| {
            w.constructed(Tag::ctx_c(0), |w| w.integer(Tag::ctx(0), 1)); // normal mode
            w.constructed(Tag::ctx_c(2), |w| {
                w.primitive(Tag::ctx(1), &a.local_psel);
                w.primitive(Tag::ctx(2), &a.remote_psel);
                w.constructed(Tag::ctx_c(4), |w| {
                    for (id, syntax) in [(ACSE_CONTEXT, oid::ACSE), (MMS_CONTEXT, oid::MMS)] {
                        w.constructed(Tag::SEQUENCE, |w| {
                            w.integer(Tag::INTEGER, id);
                            w.oid(Tag::OID, syntax);
                            w.constructed(Tag::SEQUENCE, |w| w.oid(Tag::OID, oid::BER));
                        });
                    }
                });
                fully_encoded(w, ACSE_CONTEXT, aarq);
            });
        });
        w.into_vec()
    }

    fn aarq(&self, initiate: &[u8]) -> Vec<u8> {
        let a = &self.addressing;
        let mut w = Writer::new();
        w.constructed(Tag::application(0, true), |w| {
            w.constructed(Tag::ctx_c(1), |w| w.oid(Tag::OID, oid::MMS_CONTEXT));
            if let Some(t) = &a.remote_ap_title {
                w.constructed(Tag::ctx_c(2), |w| w.oid(Tag::OID, t));
            }
            if let Some(q) = a.remote_ae_qualifier {
                w.constructed(Tag::ctx_c(3), |w| w.integer(Tag::INTEGER, q));
            }
            if let Some(t) = &a.local_ap_title {
                w.constructed(Tag::ctx_c(6), |w| w.oid(Tag::OID, t));
            }
            if let Some(q) = a.local_ae_qualifier {
                w.constructed(Tag::ctx_c(7), |w| w.integer(Tag::INTEGER, q));
            }
            w.constructed(Tag::ctx_c(30), |w| {
                w.constructed(Tag::EXTERNAL, |w| {
                    w.integer(Tag::INTEGER, MMS_CONTEXT);
                    w.constructed(Tag::ctx_c(0), |w| w.buf.extend_from_slice(initiate));
                });
            });
        });
        w.into_vec()
    }

    /// Peels one received TPKT payload.
    pub fn receive(&mut self, packet: &[u8]) -> Result<Incoming, IsoError> {
        let li = usize::from(
            *packet
                .first()
                .ok_or_else(|| IsoError::Cotp("empty TPDU".into()))?,
        );
        if li + 1 > packet.len() || li < 1 {
            return Err(IsoError::Cotp(format!(
                "header length {li} but {} octets",
                packet.len()
            )));
        }
        let (header, user) = (&packet[1..=li], &packet[li + 1..]);
        match header[0] & 0xf0 {
            0xd0 => {
                // CC: parameters after dst-ref(2) src-ref(2) class(1).
                if let Some(size) = cotp_param(header.get(6..).unwrap_or(&[]), 0xc0) {
                    if let Some(&code) = size.first() {
                        if (7..=13).contains(&code) {
                            self.tpdu_size = 1 << code;
                        }
                    }
                }
                Ok(Incoming::Connected)
            }
            0xf0 => {
                let eot = header.get(1).is_some_and(|n| n & 0x80 != 0);
                if self.reassembly.len() + user.len() > self.max_message {
                    self.reassembly.clear();
                    return Err(IsoError::Cotp(format!(
                        "a message longer than {} octets",
                        self.max_message
                    )));
                }
                self.reassembly.extend_from_slice(user);
                if !eot {
                    return Ok(Incoming::Partial);
                }
                let spdu = std::mem::take(&mut self.reassembly);
                self.session(&spdu)
            }
            0x80 => Ok(Incoming::Closed(format!(
                "transport disconnect (reason {})",
                header.get(5).copied().unwrap_or(0)
            ))),
            0x70 => Ok(Incoming::Closed("transport error TPDU".into())),
            other => Err(IsoError::Cotp(format!(
                "unexpected TPDU code 0x{other:02x}"
            ))),
        }
    }

    fn session(&self, spdu: &[u8]) -> Result<Incoming, IsoError> {
        let (si, params, rest) = session_spdu(spdu)?;
        match si {
            // Give tokens, then the Data transfer SPDU and its user data.
            0x01 => {
                let (si2, _, user) = session_spdu(rest)?;
                if si2 != 0x01 {
                    return Err(IsoError::Session(format!(
                        "SPDU 0x{si2:02x} after give-tokens"
                    )));
                }
                presentation_data(user).map(Incoming::Mms)
            }
            0x0e => {
                let user = session_find(params, 0xc1)?
                    .ok_or_else(|| IsoError::Session("ACCEPT without user data".into()))?;
                accept(user)
            }
            0x0c => Ok(Incoming::Refused("session refused (REFUSE SPDU)".into())),
            0x19 => Ok(Incoming::Closed("session aborted by the peer".into())),
            0x09 => Ok(Incoming::Closed("session finished by the peer".into())),
            0x0a => Ok(Incoming::Closed("session disconnected by the peer".into())),
            other => Err(IsoError::Session(format!("unexpected SPDU 0x{other:02x}"))),
        }
    }
}

fn session_length(out: &mut Vec<u8>, len: usize) {
    if len < 255 {
        out.push(len as u8);
    } else {
        out.push(0xff);
        out.extend_from_slice(&(len as u16).to_be_bytes());
    }
}

fn session_param(out: &mut Vec<u8>, code: u8, value: &[u8]) {
    out.push(code);
    session_length(out, value.len());
    out.extend_from_slice(value);
}

/// One SPDU: its identifier, its parameters, and what follows it.
fn session_spdu(b: &[u8]) -> Result<(u8, &[u8], &[u8]), IsoError> {
    let (&si, rest) = b
        .split_first()
        .ok_or_else(|| IsoError::Session("empty SPDU".into()))?;
    let (len, head) = session_li(rest)?;
    let params = rest.get(head..head + len).ok_or_else(|| {
        IsoError::Session(format!(
            "SPDU 0x{si:02x} claims {len} octets, {} left",
            rest.len().saturating_sub(head)
        ))
    })?;
    Ok((si, params, &rest[head + len..]))
}

fn session_li(b: &[u8]) -> Result<(usize, usize), IsoError> {
    match b {
        [0xff, hi, lo, ..] => Ok((usize::from(u16::from_be_bytes([*hi, *lo])), 3)),
        [0xff, ..] | [] => Err(IsoError::Session("truncated length".into())),
        [n, ..] => Ok((usize::from(*n), 1)),
    }
}

/// The value of the (possibly nested) parameter `code`.
fn session_find(mut params: &[u8], code: u8) -> Result<Option<&[u8]>, IsoError> {
    while let Some((&pi, rest)) = params.split_first() {
        let (len, head) = session_li(rest)?;
        let value = rest.get(head..head + len).ok_or_else(|| {
            IsoError::Session(format!("parameter 0x{pi:02x} claims {len} octets"))
        })?;
        if pi == code {
            return Ok(Some(value));
        }
        params = &rest[head + len..];
    }
    Ok(None)
}

fn cotp_param(mut params: &[u8], code: u8) -> Option<&[u8]> {
    while let [c, len, rest @ ..] = params {
        let value = rest.get(..usize::from(*len))?;
        if *c == code {
            return Some(value);
        }
        params = &rest[usize::from(*len)..];
    }
    None
}

fn fully_encoded(w: &mut Writer, context: i64, pdu: &[u8]) {
    w.constructed(Tag::application(1, true), |w| {
        w.constructed(Tag::SEQUENCE, |w| {
            w.integer(Tag::INTEGER, context);
            w.constructed(Tag::ctx_c(0), |w| w.buf.extend_from_slice(pdu));
        });
    });
}

/// Presentation user data (fully encoded, MMS context) around an MMS PDU.
fn presentation_user_data(mms: &[u8]) -> Vec<u8> {
    let mut w = Writer::new();
    fully_encoded(&mut w, MMS_CONTEXT, mms);
    w.into_vec()
}

/// The PDU inside fully-encoded presentation user data.
fn presentation_data(b: &[u8]) -> Result<Vec<u8>, IsoError> {
    let ud = Reader::new(b).expect(Tag::application(1, true), "user data");
    pdv_content(ud.map_err(IsoError::Presentation)?)
}

/// The single PDU of a fully-encoded user data's PDV list.
fn pdv_content(user_data: crate::ber::Tlv<'_>) -> Result<Vec<u8>, IsoError> {
    let p = IsoError::Presentation;
    let pdv = user_data
        .children()
        .expect(Tag::SEQUENCE, "PDV list")
        .map_err(p)?;
    let mut r = pdv.children();
    r.optional(Tag::OID).map_err(p)?; // transfer-syntax-name
    r.expect(Tag::INTEGER, "presentation context identifier")
        .map_err(p)?;
    let single = r.expect(Tag::ctx_c(0), "single-ASN1-type").map_err(p)?;
    Ok(single.value.to_vec())
}

/// The presentation CPA and the AARE inside an ACCEPT SPDU.
fn accept(user: &[u8]) -> Result<Incoming, IsoError> {
    let p = IsoError::Presentation;
    let cpa = Reader::new(user).read("CPA").map_err(p)?;
    if cpa.tag != Tag::SET {
        return Ok(Incoming::Refused("presentation connection refused".into()));
    }
    let mut normal = None;
    for t in cpa.children() {
        let t = t.map_err(p)?;
        if t.tag == Tag::ctx_c(2) {
            normal = Some(t);
        }
    }
    let normal = normal.ok_or_else(|| p(BerError::new(0, "CPA without normal-mode parameters")))?;
    let mut aare = None;
    for t in normal.children() {
        let t = t.map_err(p)?;
        if t.tag == Tag::application(1, true) {
            aare = Some(pdv_content(t)?);
        }
    }
    let aare = aare.ok_or_else(|| p(BerError::new(normal.offset, "CPA without user data")))?;
    acse_response(&aare)
}

/// The AARE's result, and the MMS initiate-ResponsePDU it carries.
fn acse_response(b: &[u8]) -> Result<Incoming, IsoError> {
    let a = IsoError::Acse;
    let aare = Reader::new(b)
        .expect(Tag::application(1, true), "AARE")
        .map_err(a)?;
    let mut result = None;
    let mut diagnostic = None;
    let mut user = None;
    for t in aare.children() {
        let t = t.map_err(a)?;
        match t.tag {
            tag if tag == Tag::ctx_c(2) => {
                result = Some(
                    t.children()
                        .expect(Tag::INTEGER, "result")
                        .and_then(|r| r.as_i64())
                        .map_err(a)?,
                )
            }
            tag if tag == Tag::ctx_c(3) => {
                let source = t.children().read("result source diagnostic").map_err(a)?;
                let n = source
                    .children()
                    .expect(Tag::INTEGER, "diagnostic")
                    .and_then(|r| r.as_i64())
                    .map_err(a)?;
                diagnostic = Some((source.tag.number, n));
            }
            tag if tag == Tag::ctx_c(30) => {
                let ext = t
                    .children()
                    .expect(Tag::EXTERNAL, "user information")
                    .map_err(a)?;
                let mut r = ext.children();
                r.optional(Tag::OID).map_err(a)?;
                r.optional(Tag::INTEGER).map_err(a)?;
                user = Some(
                    r.expect(Tag::ctx_c(0), "single-ASN1-type")
                        .map_err(a)?
                        .value
                        .to_vec(),
                );
            }
            _ => {}
        }
    }
    match result {
        Some(0) => user.map(Incoming::Accepted).ok_or_else(|| {
            a(BerError::new(
                aare.offset,
                "accepted AARE without the MMS initiate response",
            ))
        }),
        Some(r) => Ok(Incoming::Refused(format!(
            "association {} ({})",
            match r {
                1 => "rejected permanently",
                2 => "rejected transiently",
                _ => "rejected",
            },
            diagnostic.map_or_else(
                || "no diagnostic".to_string(),
                |(source, n)| acse_diagnostic(source, n)
            ),
        ))),
        None => Err(a(BerError::new(aare.offset, "AARE without a result"))),
    }
}

fn acse_diagnostic(source: u32, n: i64) -> String {
    if source != 1 {
        return format!("service provider diagnostic {n}");
    }
    const USER: [&str; 15] = [
        "null",
        "no reason given",
        "application context name not supported",
        "calling AP title not recognized",
        "calling AP invocation identifier not recognized",
        "calling AE qualifier not recognized",
        "calling AE invocation identifier not recognized",
        "called AP title not recognized",
        "called AP invocation identifier not recognized",
        "called AE qualifier not recognized",
        "called AE invocation identifier not recognized",
        "authentication mechanism name not recognized",
        "authentication mechanism name required",
        "authentication failure",
        "authentication required",
    ];
    usize::try_from(n)
        .ok()
        .and_then(|i| USER.get(i))
        .map_or_else(|| format!("user diagnostic {n}"), |s| s.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_connect_request_carries_both_transport_selectors() {
        let cr = Stack::new(Addressing::default(), 1 << 20).connect_request();
        assert_eq!(
            cr,
            [
                3, 0, 0, 0x16, 0x11, 0xe0, 0, 0, 0, 1, 0, 0xc0, 1, 0x0d, 0xc1, 2, 0, 1, 0xc2, 2, 0,
                1
            ]
        );
    }

    #[test]
    fn tpkt_packets_are_split_from_a_stream_in_any_chunks() {
        let mut d = TpktDecoder::default();
        let a = tpkt(&[2, 0xf0, 0x80, 1, 2, 3]);
        let b = tpkt(&[2, 0xf0, 0x80, 4]);
        let stream: Vec<u8> = a.iter().chain(b.iter()).copied().collect();
        for chunk in stream.chunks(3) {
            d.push(chunk);
        }
        assert_eq!(d.next_packet().unwrap().unwrap(), [2, 0xf0, 0x80, 1, 2, 3]);
        assert_eq!(d.next_packet().unwrap().unwrap(), [2, 0xf0, 0x80, 4]);
        assert_eq!(d.next_packet().unwrap(), None);
        let mut bad = TpktDecoder::default();
        bad.push(&[4, 0, 0, 8]);
        assert!(bad.next_packet().is_err());
    }

    #[test]
    fn data_round_trips_through_our_own_layers_and_segments() {
        let mut s = Stack::new(Addressing::default(), 1 << 20);
        s.tpdu_size = 128;
        let mms: Vec<u8> = (0..300u32).map(|i| i as u8).collect();
        let mut w = Writer::new();
        w.primitive(Tag::ctx(9), &mms);
        let packets = s.data(&w.buf);
        assert!(packets.len() > 2);
        let mut last = None;
        for p in &packets {
            let mut d = TpktDecoder::default();
            d.push(p);
            last = Some(s.receive(&d.next_packet().unwrap().unwrap()).unwrap());
        }
        assert_eq!(last, Some(Incoming::Mms(w.buf)));
    }

    #[test]
    fn a_message_past_the_limit_is_refused_not_buffered() {
        let mut s = Stack::new(Addressing::default(), 100);
        let mut seg = vec![2, 0xf0, 0];
        seg.extend([0u8; 80]);
        assert_eq!(s.receive(&seg).unwrap(), Incoming::Partial);
        assert!(s.receive(&seg).is_err());
        assert!(s.reassembly.is_empty());
    }
}
