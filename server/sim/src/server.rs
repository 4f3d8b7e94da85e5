//! The I/O shell: one Modbus TCP listener per gateway address, serving the
//! devices behind it by unit id, with communication faults applied; or, in
//! a replay, the same gateways answering in-process pipes
//! ([`gridscada_field::Switchboard`]) with the same Modbus TCP frames.
//!
//! Owns sockets and pipes, the tokio-modbus service, and the byte-level link
//! wrapper that (a) answers malformed requests with an exception before the
//! protocol decoder sees them and (b) corrupts outgoing frames on request.
//! Must not touch plant behaviour: every request goes to `PlantSim::request`.

use std::collections::HashMap;
use std::future::Future;
use std::io;
use std::pin::Pin;
use std::sync::Arc;
use std::task::{Context, Poll};
use std::time::Duration;

use gridscada_tagdb::Clock;
use parking_lot::{Mutex, RwLock};
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt, DuplexStream, ReadBuf};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{mpsc, watch};
use tokio_modbus::bytes::Bytes;
use tokio_modbus::server::tcp::Server;
use tokio_modbus::server::Service;
use tokio_modbus::{ExceptionCode, Request, Response, SlaveRequest};

use crate::plant::PlantSim;

/// Communication faults of one device.
#[derive(Debug, Clone, Default)]
pub(crate) struct CommFaults {
    pub offline: bool,
    pub slow: Option<Duration>,
    pub exception: Option<ExceptionCode>,
    pub corrupt: bool,
}

/// State shared by the servers, the tick task and the handles.
pub(crate) struct Shared {
    pub plant: Mutex<PlantSim>,
    /// Per device index.
    pub comm: RwLock<Vec<CommFaults>>,
    pub clock: Arc<dyn Clock>,
}

impl Shared {
    /// Advances the plant to the clock's now and runs `f` on it.
    pub fn with_plant<R>(&self, f: impl FnOnce(&mut PlantSim) -> R) -> R {
        let now = self.clock.now();
        let mut plant = self.plant.lock();
        plant.advance_to(now);
        let r = f(&mut plant);
        plant.touched();
        r
    }
}

/// A gateway at run time: unit id -> device index.
pub(crate) struct Gateway {
    pub label: String,
    pub units: HashMap<u8, usize>,
}

/// The Modbus service of one connection to a gateway.
struct GatewayService {
    shared: Arc<Shared>,
    gateway: Arc<Gateway>,
}

type ServiceFuture = Pin<Box<dyn Future<Output = Result<Option<Response>, ExceptionCode>> + Send>>;

impl Service for GatewayService {
    type Request = SlaveRequest<'static>;
    type Response = Option<Response>;
    type Exception = ExceptionCode;
    type Future = ServiceFuture;

    fn call(&self, req: Self::Request) -> Self::Future {
        let shared = self.shared.clone();
        let dev = self.gateway.units.get(&req.slave).copied();
        Box::pin(async move {
            // A gateway answers for a unit it does not know with 0x0B.
            let Some(dev) = dev else {
                return Err(ExceptionCode::GatewayTargetDevice);
            };
            let faults = shared.comm.read().get(dev).cloned().unwrap_or_default();
            if faults.offline {
                return Ok(None); // no answer: the master times out
            }
            if let Some(d) = faults.slow {
                // Plant time, so the delay shrinks with the poller's timeouts
                // on a compressed clock.
                shared.clock.sleep(d).await;
                if shared.comm.read().get(dev).is_some_and(|f| f.offline) {
                    return Ok(None);
                }
            }
            if let Some(code) = faults.exception {
                return Err(code);
            }
            let now = shared.clock.now();
            let result = shared.plant.lock().request(dev, &req.request, now);
            result.map(Some)
        })
    }
}

/// Serves one gateway until `shutdown` flips.
pub(crate) async fn serve(
    listener: TcpListener,
    shared: Arc<Shared>,
    gateway: Arc<Gateway>,
    mut shutdown: watch::Receiver<bool>,
) {
    let server = Server::new(listener);
    let label = gateway.label.clone();
    let on_connected = {
        let shared = shared.clone();
        let gateway = gateway.clone();
        move |stream: TcpStream, peer: std::net::SocketAddr| {
            let service = GatewayService {
                shared: shared.clone(),
                gateway: gateway.clone(),
            };
            let link = FieldLink::new(stream, shared.clone(), gateway.clone());
            tracing::debug!(gateway = %gateway.label, %peer, "simulator: master connected");
            async move { Ok(Some((service, link))) }
        }
    };
    let on_error = {
        let label = label.clone();
        move |e: io::Error| {
            tracing::debug!(gateway = %label, error = %e, "simulator: connection closed on error");
        }
    };
    tokio::select! {
        r = server.serve(&on_connected, on_error) => {
            if let Err(e) = r {
                tracing::error!(gateway = %label, error = %e, "simulator: listener failed");
            }
        }
        _ = shutdown.wait_for(|s| *s) => {}
    }
}

/// How a gateway is reached: a TCP listener, or the in-process pipes a
/// switchboard hands over (a replay).
pub(crate) enum Wire {
    Socket(TcpListener),
    Pipes(mpsc::UnboundedReceiver<DuplexStream>),
}

/// Serves one gateway over in-process pipes until `shutdown` flips: each
/// pipe the switchboard hands over is one master connection.
pub(crate) async fn serve_pipes(
    mut incoming: mpsc::UnboundedReceiver<DuplexStream>,
    shared: Arc<Shared>,
    gateway: Arc<Gateway>,
    mut shutdown: watch::Receiver<bool>,
) {
    let mut connections = tokio::task::JoinSet::new();
    loop {
        tokio::select! {
            pipe = incoming.recv() => {
                let Some(pipe) = pipe else { break };
                let service = GatewayService {
                    shared: shared.clone(),
                    gateway: gateway.clone(),
                };
                let link = FieldLink::new(pipe, shared.clone(), gateway.clone());
                let label = gateway.label.clone();
                connections.spawn(async move {
                    if let Err(e) = answer_requests(link, service).await {
                        tracing::debug!(gateway = %label, error = %e, "simulator: connection closed on error");
                    }
                });
            }
            Some(_) = connections.join_next(), if !connections.is_empty() => {}
            _ = shutdown.wait_for(|s| *s) => break,
        }
    }
}

/// One master connection over a pipe, request by request, as tokio-modbus's
/// TCP server does over a socket: a request that does not decode closes the
/// connection; an offline device gives no answer.
async fn answer_requests<S: AsyncRead + AsyncWrite + Unpin>(
    mut link: FieldLink<S>,
    service: GatewayService,
) -> io::Result<()> {
    let mut inbuf: Vec<u8> = Vec::with_capacity(512);
    let mut chunk = [0u8; 512];
    loop {
        // The link passes whole, checked frames only.
        while inbuf.len() >= MBAP_LEN {
            let total = 6 + usize::from(u16::from_be_bytes([inbuf[4], inbuf[5]]));
            if inbuf.len() < total {
                break;
            }
            let (transaction, unit) = ([inbuf[0], inbuf[1]], inbuf[6]);
            let function = inbuf[MBAP_LEN];
            let request = Request::try_from(Bytes::copy_from_slice(&inbuf[MBAP_LEN..total]))
                .map_err(|e| io::Error::new(io::ErrorKind::InvalidData, e.to_string()));
            inbuf.drain(..total);
            let request = request?;
            let pdu = match service
                .call(SlaveRequest {
                    slave: unit,
                    request,
                })
                .await
            {
                Ok(Some(response)) => encode_response(&response),
                Ok(None) => continue,
                Err(code) => vec![function | 0x80, u8::from(code)],
            };
            let mut adu = Vec::with_capacity(MBAP_LEN + pdu.len());
            push_adu(&mut adu, transaction, unit, &pdu);
            link.write_all(&adu).await?;
            link.flush().await?;
        }
        let n = link.read(&mut chunk).await?;
        if n == 0 {
            return Ok(());
        }
        inbuf.extend_from_slice(&chunk[..n]);
    }
}

/// Appends a Modbus TCP frame: the MBAP header (transaction, protocol 0,
/// length, unit) and `pdu`.
fn push_adu(out: &mut Vec<u8>, transaction: [u8; 2], unit: u8, pdu: &[u8]) {
    out.extend_from_slice(&transaction);
    out.extend_from_slice(&[0, 0]);
    out.extend_from_slice(&(pdu.len() as u16 + 1).to_be_bytes());
    out.push(unit);
    out.extend_from_slice(pdu);
}

/// A response PDU on the wire (function code first), as the Modbus
/// application protocol specification lays it out.
fn encode_response(response: &Response) -> Vec<u8> {
    let mut pdu = vec![response.function_code().value()];
    let word = |pdu: &mut Vec<u8>, w: u16| pdu.extend_from_slice(&w.to_be_bytes());
    match response {
        Response::ReadCoils(bits) | Response::ReadDiscreteInputs(bits) => {
            let mut packed = vec![0u8; bits.len().div_ceil(8)];
            for (i, b) in bits.iter().enumerate() {
                packed[i / 8] |= u8::from(*b) << (i % 8);
            }
            pdu.push(packed.len() as u8);
            pdu.extend_from_slice(&packed);
        }
        Response::ReadInputRegisters(words)
        | Response::ReadHoldingRegisters(words)
        | Response::ReadWriteMultipleRegisters(words) => {
            pdu.push((2 * words.len()) as u8);
            for w in words {
                word(&mut pdu, *w);
            }
        }
        Response::WriteSingleCoil(address, on) => {
            word(&mut pdu, *address);
            word(&mut pdu, if *on { 0xFF00 } else { 0x0000 });
        }
        Response::WriteMultipleCoils(address, quantity)
        | Response::WriteMultipleRegisters(address, quantity) => {
            word(&mut pdu, *address);
            word(&mut pdu, *quantity);
        }
        Response::WriteSingleRegister(address, value) => {
            word(&mut pdu, *address);
            word(&mut pdu, *value);
        }
        Response::MaskWriteRegister(address, and, or) => {
            word(&mut pdu, *address);
            word(&mut pdu, *and);
            word(&mut pdu, *or);
        }
        Response::ReportServerId(id, running, data) => {
            pdu.push(2 + data.len() as u8);
            pdu.push(*id);
            pdu.push(if *running { 0xFF } else { 0x00 });
            pdu.extend_from_slice(data);
        }
        Response::ReadDeviceIdentification(r) => {
            pdu.push(0x0E); // MEI type: read device identification
            pdu.push(r.read_code.value());
            pdu.push(r.conformity_level.value());
            pdu.push(if r.more_follows { 0xFF } else { 0x00 });
            pdu.push(r.next_object_id);
            pdu.push(r.device_id_objects.len() as u8);
            for o in &r.device_id_objects {
                pdu.push(o.id);
                pdu.push(o.value.len() as u8);
                pdu.extend_from_slice(&o.value);
            }
        }
        Response::Custom(_, data) => pdu.extend_from_slice(data),
    }
    pdu
}

// ----- The link wrapper -----------------------------------------------------

const MBAP_LEN: usize = 7;

/// The byte stream of one master connection (a socket, or an in-process
/// pipe), seen frame by frame.
struct FieldLink<S = TcpStream> {
    io: S,
    shared: Arc<Shared>,
    gateway: Arc<Gateway>,
    /// Received bytes not yet framed.
    inbuf: Vec<u8>,
    /// Checked request frames for the protocol decoder.
    ready: Vec<u8>,
    /// Response bytes from the encoder not yet framed.
    out_raw: Vec<u8>,
    /// Bytes to send, and how many are sent.
    out: Vec<u8>,
    out_pos: usize,
    corrupted: u64,
}

impl<S: AsyncRead + AsyncWrite + Unpin> FieldLink<S> {
    fn new(io: S, shared: Arc<Shared>, gateway: Arc<Gateway>) -> Self {
        FieldLink {
            io,
            shared,
            gateway,
            inbuf: vec![],
            ready: vec![],
            out_raw: vec![],
            out: vec![],
            out_pos: 0,
            corrupted: 0,
        }
    }

    /// Moves complete request frames from `inbuf` to `ready`, answering the
    /// malformed ones directly.
    fn frame_requests(&mut self) -> io::Result<()> {
        while self.inbuf.len() >= MBAP_LEN {
            let protocol = u16::from_be_bytes([self.inbuf[2], self.inbuf[3]]);
            let len = usize::from(u16::from_be_bytes([self.inbuf[4], self.inbuf[5]]));
            if protocol != 0 || len < 2 {
                // Not Modbus TCP: drop the connection, as a device would.
                return Err(io::Error::new(
                    io::ErrorKind::InvalidData,
                    format!("bad MBAP header (protocol {protocol}, length {len})"),
                ));
            }
            let total = 6 + len;
            if self.inbuf.len() < total {
                break;
            }
            let frame: Vec<u8> = self.inbuf.drain(..total).collect();
            let pdu = &frame[MBAP_LEN..];
            if malformed_request(pdu) {
                let fc = pdu[0];
                let exception = [fc | 0x80, u8::from(ExceptionCode::IllegalDataValue)];
                push_adu(&mut self.out, [frame[0], frame[1]], frame[6], &exception);
            } else {
                self.ready.extend_from_slice(&frame);
            }
        }
        Ok(())
    }

    /// Moves complete response frames from `out_raw` to `out`, corrupting
    /// them if their unit is set to.
    fn frame_responses(&mut self) {
        while self.out_raw.len() >= MBAP_LEN {
            let len = usize::from(u16::from_be_bytes([self.out_raw[4], self.out_raw[5]]));
            let total = 6 + len.max(1);
            if self.out_raw.len() < total {
                break;
            }
            let mut frame: Vec<u8> = self.out_raw.drain(..total).collect();
            let unit = frame[6];
            let corrupt = self
                .gateway
                .units
                .get(&unit)
                .and_then(|d| self.shared.comm.read().get(*d).map(|f| f.corrupt))
                .unwrap_or(false);
            if corrupt {
                corrupt_frame(&mut frame, self.corrupted);
                self.corrupted += 1;
            }
            self.out.extend_from_slice(&frame);
        }
    }

    fn poll_send(&mut self, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        while self.out_pos < self.out.len() {
            match Pin::new(&mut self.io).poll_write(cx, &self.out[self.out_pos..]) {
                Poll::Ready(Ok(0)) => {
                    return Poll::Ready(Err(io::ErrorKind::WriteZero.into()));
                }
                Poll::Ready(Ok(n)) => self.out_pos += n,
                Poll::Ready(Err(e)) => return Poll::Ready(Err(e)),
                Poll::Pending => return Poll::Pending,
            }
        }
        self.out.clear();
        self.out_pos = 0;
        Poll::Ready(Ok(()))
    }
}

/// Requests the protocol decoder would mis-handle (or panic on): answered
/// with IllegalDataValue as the Modbus spec asks.
fn malformed_request(pdu: &[u8]) -> bool {
    let u16_at = |i: usize| u16::from_be_bytes([pdu[i], pdu[i + 1]]);
    match pdu.first() {
        Some(0x05) if pdu.len() >= 5 => !matches!(u16_at(3), 0xFF00 | 0x0000),
        Some(0x0F) if pdu.len() >= 6 => {
            let q = u16_at(3);
            q == 0 || q > 1968 || usize::from(pdu[5]) != usize::from(q).div_ceil(8)
        }
        Some(0x10) if pdu.len() >= 6 => {
            let q = u16_at(3);
            q == 0 || q > 123 || usize::from(pdu[5]) != 2 * usize::from(q)
        }
        Some(0x17) if pdu.len() >= 10 => {
            let (rq, wq) = (u16_at(3), u16_at(7));
            rq == 0 || rq > 125 || wq == 0 || wq > 121 || usize::from(pdu[9]) != 2 * usize::from(wq)
        }
        _ => false,
    }
}

/// Damages a response so that a client can tell: a bad protocol id, a wrong
/// transaction id, or a wrong function code, in turn.
fn corrupt_frame(frame: &mut [u8], n: u64) {
    match n % 3 {
        0 => {
            frame[2] = 0xDE;
            frame[3] = 0xAD;
        }
        1 => {
            let tid = u16::from_be_bytes([frame[0], frame[1]]).wrapping_add(0x1111);
            frame[..2].copy_from_slice(&tid.to_be_bytes());
        }
        _ => {
            if let Some(fc) = frame.get_mut(MBAP_LEN) {
                *fc ^= 0x40;
            }
        }
    }
}

impl<S: AsyncRead + AsyncWrite + Unpin> AsyncRead for FieldLink<S> {
    fn poll_read(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        let this = self.get_mut();
        // Exceptions queued for malformed requests go out first.
        if let Poll::Ready(Err(e)) = this.poll_send(cx) {
            return Poll::Ready(Err(e));
        }
        loop {
            if !this.ready.is_empty() {
                let n = this.ready.len().min(buf.remaining());
                buf.put_slice(&this.ready[..n]);
                this.ready.drain(..n);
                return Poll::Ready(Ok(()));
            }
            let mut tmp = [0u8; 1024];
            let mut rb = ReadBuf::new(&mut tmp);
            match Pin::new(&mut this.io).poll_read(cx, &mut rb) {
                Poll::Pending => return Poll::Pending,
                Poll::Ready(Err(e)) => return Poll::Ready(Err(e)),
                Poll::Ready(Ok(())) => {
                    if rb.filled().is_empty() {
                        return Poll::Ready(Ok(())); // end of stream
                    }
                    this.inbuf.extend_from_slice(rb.filled());
                    this.frame_requests()?;
                    if let Poll::Ready(Err(e)) = this.poll_send(cx) {
                        return Poll::Ready(Err(e));
                    }
                }
            }
        }
    }
}

impl<S: AsyncRead + AsyncWrite + Unpin> AsyncWrite for FieldLink<S> {
    fn poll_write(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        data: &[u8],
    ) -> Poll<io::Result<usize>> {
        let this = self.get_mut();
        this.out_raw.extend_from_slice(data);
        this.frame_responses();
        if let Poll::Ready(Err(e)) = this.poll_send(cx) {
            return Poll::Ready(Err(e));
        }
        Poll::Ready(Ok(data.len()))
    }

    fn poll_flush(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        let this = self.get_mut();
        this.frame_responses();
        match this.poll_send(cx) {
            Poll::Ready(Ok(())) => Pin::new(&mut this.io).poll_flush(cx),
            other => other,
        }
    }

    fn poll_shutdown(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        let this = self.get_mut();
        match this.poll_send(cx) {
            Poll::Ready(Ok(())) => Pin::new(&mut this.io).poll_shutdown(cx),
            other => other,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn malformed_requests_are_recognised() {
        // Write multiple coils: 9 coils need 2 bytes.
        assert!(malformed_request(&[0x0F, 0, 0, 0, 9, 1, 0xFF]));
        assert!(!malformed_request(&[0x0F, 0, 0, 0, 9, 2, 0xFF, 1]));
        // Write multiple registers: a quantity that would overflow ×2.
        assert!(malformed_request(&[0x10, 0, 0, 0x80, 0, 0]));
        assert!(!malformed_request(&[0x10, 0, 0, 0, 1, 2, 0, 7]));
        // Write single coil with a value other than 0xFF00 / 0x0000.
        assert!(malformed_request(&[0x05, 0, 0, 0x12, 0x34]));
        assert!(!malformed_request(&[0x03, 0, 0, 0, 200]));
    }

    #[test]
    fn responses_are_encoded_as_a_client_decodes_them() {
        let responses = [
            Response::ReadCoils(vec![
                true, false, true, true, false, false, false, false, true,
            ]),
            Response::ReadDiscreteInputs(vec![
                false, true, false, false, false, false, false, false,
            ]),
            Response::ReadHoldingRegisters(vec![0x1234, 0, 0xFFFF]),
            Response::ReadInputRegisters(vec![7]),
            Response::ReadWriteMultipleRegisters(vec![0x0FF0, 9]),
            Response::WriteSingleCoil(17, true),
            Response::WriteSingleCoil(18, false),
            Response::WriteMultipleCoils(100, 9),
            Response::WriteSingleRegister(3, 0xBEEF),
            Response::WriteMultipleRegisters(40, 2),
            Response::MaskWriteRegister(5, 0xF0F0, 0x0101),
            Response::ReportServerId(9, true, vec![1, 2, 3]),
        ];
        for r in responses {
            let pdu = encode_response(&r);
            let back = Response::try_from(Bytes::from(pdu.clone()))
                .unwrap_or_else(|e| panic!("{r:?} -> {pdu:02x?}: {e}"));
            // Coils come back padded to whole bytes.
            match (&r, &back) {
                (Response::ReadCoils(a), Response::ReadCoils(b))
                | (Response::ReadDiscreteInputs(a), Response::ReadDiscreteInputs(b)) => {
                    assert_eq!(a[..], b[..a.len()], "{pdu:02x?}");
                    assert!(b[a.len()..].iter().all(|x| !x));
                }
                _ => assert_eq!(r, back, "{pdu:02x?}"),
            }
        }
    }

    #[test]
    fn corruption_changes_what_a_client_checks() {
        let good = vec![0, 7, 0, 0, 0, 5, 1, 4, 2, 0, 1];
        for n in 0..3 {
            let mut f = good.clone();
            corrupt_frame(&mut f, n);
            assert_ne!(f[..8], good[..8], "mode {n}");
        }
    }
}
