//! Modbus framing: request PDUs, MBAP (TCP) and RTU frames, and checking that
//! a response answers the request that was sent.
//!
//! **Owns:** bytes on the wire. Pure functions over buffers; the transports
//! feed them bytes and act on the verdict. Response PDUs are decoded by
//! tokio-modbus's own decoder (`Response::try_from`).
//!
//! **Must not touch:** sockets, timing, tags.
//!
//! Why our own framing rather than tokio-modbus's client: its TCP client
//! returns a header-mismatch *error* when a late reply with an old transaction
//! id arrives, instead of skipping it, and a request future dropped on timeout
//! can leave half a frame on the stream; its RTU client cannot tell a late reply
//! from the answer to the next request at all, and gives no way to drain the
//! line first. Here a TCP reply is matched by transaction id (others are
//! discarded), and an RTU reply is searched for by slave id, function code,
//! length and CRC after the line has been drained, so stray bytes are skipped.

use gridscada_config::RegisterKind;
use tokio_modbus::bytes::Bytes;
use tokio_modbus::{ExceptionCode, Request, Response};

/// MBAP header length, up to and including the unit id.
const MBAP_HEADER: usize = 7;
/// Largest PDU the protocol allows.
const MAX_PDU: usize = 253;

/// The read request for a table.
pub fn read_request(table: RegisterKind, start: u16, count: u16) -> Request<'static> {
    match table {
        RegisterKind::Coil => Request::ReadCoils(start, count),
        RegisterKind::DiscreteInput => Request::ReadDiscreteInputs(start, count),
        RegisterKind::InputRegister => Request::ReadInputRegisters(start, count),
        RegisterKind::HoldingRegister => Request::ReadHoldingRegisters(start, count),
    }
}

/// The request PDU: function code and data.
pub fn encode_request(req: &Request<'_>) -> Result<Vec<u8>, String> {
    let mut b = Vec::with_capacity(8);
    let put16 = |b: &mut Vec<u8>, v: u16| b.extend_from_slice(&v.to_be_bytes());
    match req {
        Request::ReadCoils(a, n)
        | Request::ReadDiscreteInputs(a, n)
        | Request::ReadInputRegisters(a, n)
        | Request::ReadHoldingRegisters(a, n) => {
            b.push(req.function_code().value());
            put16(&mut b, *a);
            put16(&mut b, *n);
        }
        Request::WriteSingleCoil(a, on) => {
            b.push(0x05);
            put16(&mut b, *a);
            put16(&mut b, if *on { 0xFF00 } else { 0x0000 });
        }
        Request::WriteSingleRegister(a, v) => {
            b.push(0x06);
            put16(&mut b, *a);
            put16(&mut b, *v);
        }
        Request::WriteMultipleCoils(a, bits) => {
            let n = u16::try_from(bits.len()).map_err(|_| "too many coils")?;
            let bytes = bits.len().div_ceil(8);
            b.push(0x0F);
            put16(&mut b, *a);
            put16(&mut b, n);
            b.push(u8::try_from(bytes).map_err(|_| "too many coils")?);
            let mut packed = vec![0u8; bytes];
            for (i, on) in bits.iter().enumerate() {
                if *on {
                    packed[i / 8] |= 1 << (i % 8);
                }
            }
            b.extend_from_slice(&packed);
        }
        Request::WriteMultipleRegisters(a, words) => {
            let n = u16::try_from(words.len()).map_err(|_| "too many registers")?;
            b.push(0x10);
            put16(&mut b, *a);
            put16(&mut b, n);
            b.push(u8::try_from(words.len() * 2).map_err(|_| "too many registers")?);
            for w in words.iter() {
                put16(&mut b, *w);
            }
        }
        other => return Err(format!("request {other:?} is not used by the poller")),
    }
    if b.len() > MAX_PDU {
        return Err(format!("request PDU of {} bytes is too long", b.len()));
    }
    Ok(b)
}

/// A Modbus TCP frame.
pub fn tcp_adu(transaction: u16, unit: u8, pdu: &[u8]) -> Vec<u8> {
    let mut f = Vec::with_capacity(MBAP_HEADER + pdu.len());
    f.extend_from_slice(&transaction.to_be_bytes());
    f.extend_from_slice(&0u16.to_be_bytes());
    f.extend_from_slice(&((pdu.len() + 1) as u16).to_be_bytes());
    f.push(unit);
    f.extend_from_slice(pdu);
    f
}

/// What the front of a TCP receive buffer holds.
#[derive(Debug, PartialEq, Eq)]
pub enum Mbap {
    /// A whole frame, removed from the buffer.
    Frame {
        transaction: u16,
        unit: u8,
        pdu: Vec<u8>,
    },
    /// Not a whole frame yet.
    NeedMore,
    /// The stream is not Modbus TCP (or lost its framing): reconnect.
    Garbage(String),
}

/// Takes one MBAP frame from the front of `buf`.
pub fn take_mbap(buf: &mut Vec<u8>) -> Mbap {
    if buf.len() < MBAP_HEADER {
        return Mbap::NeedMore;
    }
    let protocol = u16::from_be_bytes([buf[2], buf[3]]);
    let len = usize::from(u16::from_be_bytes([buf[4], buf[5]]));
    if protocol != 0 {
        return Mbap::Garbage(format!("protocol id {protocol} is not Modbus"));
    }
    if !(2..=MAX_PDU + 1).contains(&len) {
        return Mbap::Garbage(format!("frame length {len} is out of range"));
    }
    let total = 6 + len;
    if buf.len() < total {
        return Mbap::NeedMore;
    }
    let transaction = u16::from_be_bytes([buf[0], buf[1]]);
    let unit = buf[6];
    let pdu = buf[MBAP_HEADER..total].to_vec();
    buf.drain(..total);
    Mbap::Frame {
        transaction,
        unit,
        pdu,
    }
}

/// CRC-16/MODBUS.
pub fn crc16(data: &[u8]) -> u16 {
    let mut crc: u16 = 0xFFFF;
    for &byte in data {
        crc ^= u16::from(byte);
        for _ in 0..8 {
            crc = if crc & 1 != 0 {
                (crc >> 1) ^ 0xA001
            } else {
                crc >> 1
            };
        }
    }
    crc
}

/// A Modbus RTU frame: slave id, PDU, CRC (low byte first).
pub fn rtu_adu(unit: u8, pdu: &[u8]) -> Vec<u8> {
    let mut f = Vec::with_capacity(pdu.len() + 3);
    f.push(unit);
    f.extend_from_slice(pdu);
    let crc = crc16(&f);
    f.extend_from_slice(&crc.to_le_bytes());
    f
}

/// Finds the reply to a request for `unit` with function code `function` in
/// bytes received from the line. Returns the offset and length of the first
/// complete frame with a valid CRC; bytes before it are noise or stale.
pub fn find_rtu_reply(buf: &[u8], unit: u8, function: u8) -> Option<(usize, usize)> {
    for start in 0..buf.len() {
        let rest = &buf[start..];
        if rest.len() < 5 || rest[0] != unit {
            continue;
        }
        let len = if rest[1] == function | 0x80 {
            5
        } else if rest[1] == function {
            match function {
                0x01..=0x04 => 5 + usize::from(rest[2]),
                0x05 | 0x06 | 0x0F | 0x10 => 8,
                _ => continue,
            }
        } else {
            continue;
        };
        if rest.len() < len {
            continue;
        }
        let crc = u16::from_le_bytes([rest[len - 2], rest[len - 1]]);
        if crc16(&rest[..len - 2]) == crc {
            return Some((start, len));
        }
    }
    None
}

/// The result of one transaction as the device answered it.
pub type Answer = Result<Response, ExceptionCode>;

/// Decodes a response PDU and checks it answers `req`: function code, counts,
/// echoed address and value. Anything else is a protocol error (the device or
/// the line is not to be trusted for this answer).
pub fn parse_response(req: &Request<'_>, pdu: &[u8]) -> Result<Answer, String> {
    let fc = req.function_code().value();
    let Some(&got) = pdu.first() else {
        return Err("empty response".into());
    };
    if got == fc | 0x80 {
        let code = pdu
            .get(1)
            .copied()
            .ok_or("exception response without a code")?;
        return Ok(Err(ExceptionCode::new(code)));
    }
    if got != fc {
        return Err(format!(
            "response function 0x{got:02X} does not answer request 0x{fc:02X}"
        ));
    }
    let resp = Response::try_from(Bytes::copy_from_slice(pdu))
        .map_err(|e| format!("malformed response: {e}"))?;
    check_shape(req, resp).map(Ok)
}

fn check_shape(req: &Request<'_>, resp: Response) -> Result<Response, String> {
    let short = |what: &str, want: u16, got: usize| {
        format!("response holds {got} {what}, {want} were asked for")
    };
    Ok(match (req, resp) {
        (Request::ReadCoils(_, n), Response::ReadCoils(mut bits)) => {
            if bits.len() < usize::from(*n) || bits.len() >= usize::from(*n) + 8 {
                return Err(short("coils", *n, bits.len()));
            }
            bits.truncate(usize::from(*n));
            Response::ReadCoils(bits)
        }
        (Request::ReadDiscreteInputs(_, n), Response::ReadDiscreteInputs(mut bits)) => {
            if bits.len() < usize::from(*n) || bits.len() >= usize::from(*n) + 8 {
                return Err(short("inputs", *n, bits.len()));
            }
            bits.truncate(usize::from(*n));
            Response::ReadDiscreteInputs(bits)
        }
        (Request::ReadHoldingRegisters(_, n), Response::ReadHoldingRegisters(w)) => {
            if w.len() != usize::from(*n) {
                return Err(short("registers", *n, w.len()));
            }
            Response::ReadHoldingRegisters(w)
        }
        (Request::ReadInputRegisters(_, n), Response::ReadInputRegisters(w)) => {
            if w.len() != usize::from(*n) {
                return Err(short("registers", *n, w.len()));
            }
            Response::ReadInputRegisters(w)
        }
        (Request::WriteSingleCoil(a, v), r @ Response::WriteSingleCoil(ra, rv)) => {
            if (*a, *v) != (ra, rv) {
                return Err(format!("write echo {ra}={rv} does not match {a}={v}"));
            }
            r
        }
        (Request::WriteSingleRegister(a, v), r @ Response::WriteSingleRegister(ra, rv)) => {
            if (*a, *v) != (ra, rv) {
                return Err(format!("write echo {ra}={rv} does not match {a}={v}"));
            }
            r
        }
        (Request::WriteMultipleRegisters(a, w), r @ Response::WriteMultipleRegisters(ra, rn)) => {
            if (*a, w.len()) != (ra, usize::from(rn)) {
                return Err(format!(
                    "write echo {ra}+{rn} does not match {a}+{}",
                    w.len()
                ));
            }
            r
        }
        (Request::WriteMultipleCoils(a, w), r @ Response::WriteMultipleCoils(ra, rn)) => {
            if (*a, w.len()) != (ra, usize::from(rn)) {
                return Err(format!(
                    "write echo {ra}+{rn} does not match {a}+{}",
                    w.len()
                ));
            }
            r
        }
        (_, r) => return Err(format!("response {r:?} does not answer the request")),
    })
}

/// An operator-readable name of an exception.
pub fn exception_text(code: ExceptionCode) -> String {
    let n = u8::from(code);
    let name = match n {
        0x01 => "illegal function",
        0x02 => "illegal data address",
        0x03 => "illegal data value",
        0x04 => "server device failure",
        0x05 => "acknowledge",
        0x06 => "server device busy",
        0x08 => "memory parity error",
        0x0A => "gateway path unavailable",
        0x0B => "gateway target device failed to respond",
        _ => "unknown exception",
    };
    format!("exception 0x{n:02X}: {name}")
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::borrow::Cow;

    #[test]
    fn crc_matches_the_specification_example() {
        // Read holding registers, slave 1, address 0, 1 register: 01 03 00 00 00 01 84 0A.
        let f = rtu_adu(
            1,
            &encode_request(&Request::ReadHoldingRegisters(0, 1)).unwrap(),
        );
        assert_eq!(f, vec![0x01, 0x03, 0, 0, 0, 1, 0x84, 0x0A]);
    }

    #[test]
    fn encodes_every_request_the_poller_sends() {
        let e = |r: Request<'_>| encode_request(&r).unwrap();
        assert_eq!(e(Request::ReadCoils(1, 10)), vec![1, 0, 1, 0, 10]);
        assert_eq!(e(Request::ReadDiscreteInputs(2, 3)), vec![2, 0, 2, 0, 3]);
        assert_eq!(e(Request::ReadHoldingRegisters(3, 4)), vec![3, 0, 3, 0, 4]);
        assert_eq!(e(Request::ReadInputRegisters(4, 5)), vec![4, 0, 4, 0, 5]);
        assert_eq!(e(Request::WriteSingleCoil(5, true)), vec![5, 0, 5, 0xFF, 0]);
        assert_eq!(
            e(Request::WriteSingleRegister(6, 0x1234)),
            vec![6, 0, 6, 0x12, 0x34]
        );
        assert_eq!(
            e(Request::WriteMultipleRegisters(7, Cow::Owned(vec![1, 2]))),
            vec![0x10, 0, 7, 0, 2, 4, 0, 1, 0, 2]
        );
        assert_eq!(
            e(Request::WriteMultipleCoils(
                8,
                Cow::Owned(vec![true, false, true])
            )),
            vec![0x0F, 0, 8, 0, 3, 1, 0b101]
        );
        assert!(encode_request(&Request::ReportServerId).is_err());
    }

    #[test]
    fn mbap_frames_split_and_joined() {
        let mut buf = tcp_adu(7, 3, &[3, 2, 0, 42]);
        buf.extend(tcp_adu(8, 3, &[3, 2, 0, 43]));
        let partial = buf.split_off(buf.len() - 3);
        assert_eq!(
            take_mbap(&mut buf),
            Mbap::Frame {
                transaction: 7,
                unit: 3,
                pdu: vec![3, 2, 0, 42]
            }
        );
        assert_eq!(take_mbap(&mut buf), Mbap::NeedMore);
        buf.extend(partial);
        assert!(matches!(
            take_mbap(&mut buf),
            Mbap::Frame { transaction: 8, .. }
        ));
        assert!(buf.is_empty());
        let mut bad = vec![0, 1, 0, 9, 0, 3, 1, 3, 0];
        assert!(matches!(take_mbap(&mut bad), Mbap::Garbage(_)));
        let mut bad_len = vec![0, 1, 0, 0, 0x10, 0, 1];
        assert!(matches!(take_mbap(&mut bad_len), Mbap::Garbage(_)));
    }

    #[test]
    fn rtu_reply_found_after_garbage_and_stale_frames() {
        let reply = rtu_adu(5, &[3, 2, 0x12, 0x34]);
        // Noise, a stale reply from another slave, a frame with a broken CRC.
        let mut line = vec![0xFF, 0x00, 0x05, 0x03];
        line.extend(rtu_adu(6, &[3, 2, 0, 1]));
        let mut broken = rtu_adu(5, &[3, 2, 9, 9]);
        broken[3] ^= 0xFF;
        line.extend(&broken);
        let at = line.len();
        line.extend(&reply);
        assert_eq!(find_rtu_reply(&line, 5, 3), Some((at, reply.len())));
        // Incomplete: not found yet.
        assert_eq!(find_rtu_reply(&reply[..6], 5, 3), None);
        // Exception reply.
        let ex = rtu_adu(5, &[0x83, 2]);
        assert_eq!(find_rtu_reply(&ex, 5, 3), Some((0, 5)));
        // A garbage header claiming a long byte count does not hide a later frame.
        let mut line = vec![5, 3, 250];
        line.extend(&reply);
        assert_eq!(find_rtu_reply(&line, 5, 3), Some((3, reply.len())));
    }

    #[test]
    fn responses_are_checked_against_the_request() {
        let req = Request::ReadHoldingRegisters(0, 2);
        assert_eq!(
            parse_response(&req, &[3, 4, 0, 1, 0, 2]).unwrap(),
            Ok(Response::ReadHoldingRegisters(vec![1, 2]))
        );
        assert!(parse_response(&req, &[3, 2, 0, 1]).is_err());
        assert!(parse_response(&req, &[4, 4, 0, 1, 0, 2]).is_err());
        assert!(parse_response(&req, &[]).is_err());
        assert!(parse_response(&req, &[3, 4, 0]).is_err());
        assert_eq!(
            parse_response(&req, &[0x83, 2]).unwrap(),
            Err(ExceptionCode::IllegalDataAddress)
        );
        let coils = Request::ReadCoils(0, 3);
        assert_eq!(
            parse_response(&coils, &[1, 1, 0b101]).unwrap(),
            Ok(Response::ReadCoils(vec![true, false, true]))
        );
        let w = Request::WriteSingleRegister(4, 9);
        assert!(parse_response(&w, &[6, 0, 4, 0, 9]).unwrap().is_ok());
        assert!(parse_response(&w, &[6, 0, 4, 0, 8]).is_err());
        assert_eq!(
            exception_text(ExceptionCode::IllegalDataAddress),
            "exception 0x02: illegal data address"
        );
    }
}
