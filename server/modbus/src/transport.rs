//! The two transports: a Modbus TCP connection and a Modbus RTU serial line.
//!
//! **Owns:** one socket or serial port, its receive buffer, transaction ids,
//! the RTU inter-frame silence and draining the line after trouble. One
//! request at a time, always with a deadline.
//!
//! **Must not touch:** tags, scheduling, device health (the link task's).
//!
//! A reply that is late (after its request timed out) is never taken as the
//! answer to a later request: on TCP it carries an old transaction id and is
//! dropped; on RTU the line is drained until quiet before the next request and
//! the reply is searched for by slave id, function code, length and CRC.

use std::future::Future;
use std::io;
use std::pin::Pin;
use std::sync::Arc;
use std::task::{Context, Poll};
use std::time::Duration;

use gridscada_config::{Parity, SerialConfig};
use gridscada_field::Switchboard;
use gridscada_tagdb::SleepFuture;
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt, DuplexStream, ReadBuf};
use tokio::net::TcpStream;
use tokio::time::{timeout_at, Instant};
use tokio_modbus::Request;

use crate::frame::{self, Answer, Mbap};

/// When a request gives up: a wall-clock instant and, under a clock that
/// measures a device's silence otherwise ([`gridscada_tagdb::Clock::request_wait`]),
/// that clock's wait, whichever ends first.
pub struct Deadline {
    wall: Instant,
    /// The end of the wall-clock timeout as given (bounds RTU draining);
    /// `wall` itself is later under a clock's own wait.
    given: Instant,
    wait: Option<SleepFuture>,
    expired: bool,
}

/// Under a clock's own wait, the wall-clock time is only a backstop.
const WAIT_BACKSTOP: Duration = Duration::from_secs(10);

/// The deadline passed.
struct Expired;

impl Deadline {
    /// `wall` from now, or the clock's `wait` (with a long wall backstop).
    pub fn new(timeout: Duration, wait: Option<SleepFuture>) -> Self {
        let wall = if wait.is_some() {
            timeout.max(WAIT_BACKSTOP)
        } else {
            timeout
        };
        let now = Instant::now();
        Deadline {
            wall: now + wall,
            given: now + timeout,
            wait,
            expired: false,
        }
    }

    /// Runs `f` until it ends or the deadline passes. The operation is
    /// polled first, so an answer that is there wins over a deadline that
    /// passed at the same time.
    async fn run<F: Future>(&mut self, f: F) -> Result<F::Output, Expired> {
        if self.expired {
            return Err(Expired);
        }
        let wall = self.wall;
        let r = match self.wait.as_mut() {
            None => timeout_at(wall, f).await.map_err(|_| Expired),
            Some(wait) => tokio::select! {
                biased;
                r = f => Ok(r),
                _ = tokio::time::sleep_until(wall) => Err(Expired),
                _ = wait.as_mut() => Err(Expired),
            },
        };
        // A finished wait must not be polled again.
        self.expired = r.is_err();
        r
    }

    /// What is left of the wall-clock timeout as given (not the backstop).
    fn remaining(&self) -> Duration {
        self.given.saturating_duration_since(Instant::now())
    }
}

/// Why a transaction got no usable answer.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum LinkError {
    /// No answer within the request's timeout.
    Timeout,
    /// Not connected (or the port is not open).
    NotConnected(String),
    /// The connection or port failed; it has been closed.
    Io(String),
    /// Bytes that are not Modbus; on TCP the connection has been closed.
    Garbage(String),
    /// A well-framed answer that does not answer the request.
    Protocol(String),
}

impl std::fmt::Display for LinkError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            LinkError::Timeout => f.write_str("no answer (timeout)"),
            LinkError::NotConnected(s) => write!(f, "not connected: {s}"),
            LinkError::Io(s) => write!(f, "connection failed: {s}"),
            LinkError::Garbage(s) => write!(f, "garbled reply: {s}"),
            LinkError::Protocol(s) => write!(f, "bad reply: {s}"),
        }
    }
}

/// Counters a transport keeps about its line.
#[derive(Debug, Default, Clone, Copy)]
pub struct LineCounters {
    /// Replies discarded because they answered an earlier, timed-out request.
    pub late_replies: u64,
    /// Bytes skipped on an RTU line while looking for a reply.
    pub garbage_bytes: u64,
}

pub enum Transport {
    Tcp(TcpLine),
    Rtu(RtuLine),
}

impl Transport {
    pub fn is_connected(&self) -> bool {
        match self {
            Transport::Tcp(t) => t.stream.is_some(),
            Transport::Rtu(r) => r.stream.is_some(),
        }
    }

    pub fn counters(&self) -> LineCounters {
        match self {
            Transport::Tcp(t) => t.counters,
            Transport::Rtu(r) => r.counters,
        }
    }

    /// Opens the connection or port. `timeout` is wall time.
    pub async fn connect(&mut self, timeout: Duration) -> Result<(), String> {
        match self {
            Transport::Tcp(t) => t.connect(timeout).await,
            Transport::Rtu(r) => r.open(),
        }
    }

    pub fn disconnect(&mut self) {
        match self {
            Transport::Tcp(t) => {
                t.stream = None;
                t.buf.clear();
            }
            Transport::Rtu(r) => r.stream = None,
        }
    }

    /// One request and its answer, given up at `deadline`.
    pub async fn transact(
        &mut self,
        unit: u8,
        req: &Request<'_>,
        deadline: Deadline,
    ) -> Result<Answer, LinkError> {
        match self {
            Transport::Tcp(t) => t.transact(unit, req, deadline).await,
            Transport::Rtu(r) => r.transact(unit, req, deadline).await,
        }
    }
}

/// The byte stream under a Modbus TCP line: a socket, or an in-process pipe
/// to a device this process simulates itself (a replay's, see
/// [`Switchboard`]). The same frames cross either.
enum LineStream {
    Socket(TcpStream),
    Pipe(DuplexStream),
}

impl AsyncRead for LineStream {
    fn poll_read(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        match self.get_mut() {
            LineStream::Socket(s) => Pin::new(s).poll_read(cx, buf),
            LineStream::Pipe(p) => Pin::new(p).poll_read(cx, buf),
        }
    }
}

impl AsyncWrite for LineStream {
    fn poll_write(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        data: &[u8],
    ) -> Poll<io::Result<usize>> {
        match self.get_mut() {
            LineStream::Socket(s) => Pin::new(s).poll_write(cx, data),
            LineStream::Pipe(p) => Pin::new(p).poll_write(cx, data),
        }
    }

    fn poll_flush(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        match self.get_mut() {
            LineStream::Socket(s) => Pin::new(s).poll_flush(cx),
            LineStream::Pipe(p) => Pin::new(p).poll_flush(cx),
        }
    }

    fn poll_shutdown(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        match self.get_mut() {
            LineStream::Socket(s) => Pin::new(s).poll_shutdown(cx),
            LineStream::Pipe(p) => Pin::new(p).poll_shutdown(cx),
        }
    }
}

/// A Modbus TCP connection, possibly to a gateway serving several unit ids.
pub struct TcpLine {
    address: String,
    /// Addresses served in process; `None` (or an address it does not
    /// serve) connects over the network.
    pipes: Option<Arc<Switchboard>>,
    stream: Option<LineStream>,
    buf: Vec<u8>,
    transaction: u16,
    counters: LineCounters,
}

impl TcpLine {
    pub fn new(address: String, pipes: Option<Arc<Switchboard>>) -> Self {
        TcpLine {
            address,
            pipes,
            stream: None,
            buf: Vec::with_capacity(512),
            transaction: 0,
            counters: LineCounters::default(),
        }
    }

    async fn connect(&mut self, timeout: Duration) -> Result<(), String> {
        self.stream = None;
        self.buf.clear();
        if let Some(pipe) = self.pipes.as_ref().and_then(|p| p.dial(&self.address)) {
            let pipe = pipe.map_err(|e| format!("cannot connect to {}: {e}", self.address))?;
            self.stream = Some(LineStream::Pipe(pipe));
            return Ok(());
        }
        let stream = tokio::time::timeout(timeout, TcpStream::connect(&self.address))
            .await
            .map_err(|_| format!("connecting to {} timed out", self.address))?
            .map_err(|e| format!("cannot connect to {}: {e}", self.address))?;
        // Requests are small and answered one at a time: send at once.
        let _ = stream.set_nodelay(true);
        self.stream = Some(LineStream::Socket(stream));
        Ok(())
    }

    fn fail(&mut self, e: LinkError) -> LinkError {
        self.stream = None;
        self.buf.clear();
        e
    }

    async fn transact(
        &mut self,
        unit: u8,
        req: &Request<'_>,
        mut deadline: Deadline,
    ) -> Result<Answer, LinkError> {
        let pdu = frame::encode_request(req).map_err(LinkError::Protocol)?;
        self.transaction = self.transaction.wrapping_add(1);
        let tid = self.transaction;
        let adu = frame::tcp_adu(tid, unit, &pdu);
        let Some(stream) = self.stream.as_mut() else {
            return Err(LinkError::NotConnected(self.address.clone()));
        };
        match deadline.run(stream.write_all(&adu)).await {
            Ok(Ok(())) => {}
            Ok(Err(e)) => return Err(self.fail(LinkError::Io(e.to_string()))),
            // Part of the frame may be out: the stream can no longer be trusted.
            Err(_) => return Err(self.fail(LinkError::Io("send timed out".into()))),
        }
        let mut chunk = [0u8; 512];
        loop {
            match frame::take_mbap(&mut self.buf) {
                Mbap::Frame {
                    transaction,
                    unit: u,
                    pdu,
                } => {
                    if transaction == tid && u == unit {
                        return frame::parse_response(req, &pdu).map_err(LinkError::Protocol);
                    }
                    // The answer to an earlier request that timed out.
                    self.counters.late_replies += 1;
                    continue;
                }
                Mbap::Garbage(why) => return Err(self.fail(LinkError::Garbage(why))),
                Mbap::NeedMore => {}
            }
            let Some(stream) = self.stream.as_mut() else {
                return Err(LinkError::NotConnected(self.address.clone()));
            };
            match deadline.run(stream.read(&mut chunk)).await {
                Err(_) => return Err(LinkError::Timeout),
                Ok(Ok(0)) => {
                    return Err(self.fail(LinkError::Io("connection closed by the device".into())))
                }
                Ok(Ok(n)) => self.buf.extend_from_slice(&chunk[..n]),
                Ok(Err(e)) => return Err(self.fail(LinkError::Io(e.to_string()))),
            }
        }
    }
}

/// A Modbus RTU serial line shared by the slaves on it.
pub struct RtuLine {
    config: SerialConfig,
    stream: Option<tokio_serial::SerialStream>,
    /// Inter-frame silence: 3.5 character times (1.75 ms above 19200 baud).
    silence: Duration,
    /// When the line last carried a frame (ours or a reply).
    last_traffic: Instant,
    /// The last transaction went wrong: wait for a quiet line before sending.
    dirty: bool,
    buf: Vec<u8>,
    counters: LineCounters,
}

/// The inter-frame silence of the line (3.5 character times; 1.75 ms fixed
/// above 19200 baud, as the serial-line specification says).
pub fn inter_frame_silence(cfg: &SerialConfig) -> Duration {
    if cfg.baud > 19_200 {
        return Duration::from_micros(1750);
    }
    let parity = u32::from(cfg.parity != Parity::None);
    let bits =
        1 + u32::from(*cfg.data_bits.get_ref()) + parity + u32::from(*cfg.stop_bits.get_ref());
    let char_s = f64::from(bits) / f64::from(cfg.baud.max(1));
    Duration::from_secs_f64(3.5 * char_s)
}

impl RtuLine {
    pub fn new(config: SerialConfig) -> Self {
        RtuLine {
            silence: inter_frame_silence(&config),
            config,
            stream: None,
            last_traffic: Instant::now(),
            dirty: true,
            buf: Vec::with_capacity(512),
            counters: LineCounters::default(),
        }
    }

    fn open(&mut self) -> Result<(), String> {
        self.stream = None;
        let stream = gridscada_field::open_serial(&self.config)?;
        self.stream = Some(stream);
        self.dirty = true;
        Ok(())
    }

    /// Discards whatever is waiting on the line. After trouble, keeps reading
    /// until the line has been quiet for the inter-frame silence (at most
    /// `limit`), so a late reply still arriving cannot answer the next request.
    async fn drain(&mut self, limit: Duration) -> Result<(), LinkError> {
        let quiet = self.silence.max(Duration::from_millis(2));
        let until = Instant::now() + limit;
        let wait_for_quiet = self.dirty;
        let Some(stream) = self.stream.as_mut() else {
            return Err(LinkError::NotConnected(self.config.port.get_ref().clone()));
        };
        let mut chunk = [0u8; 256];
        loop {
            match stream.try_read(&mut chunk) {
                Ok(0) => break,
                Ok(n) => {
                    self.counters.garbage_bytes += n as u64;
                    self.last_traffic = Instant::now();
                    continue;
                }
                Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {}
                Err(e) => {
                    self.stream = None;
                    return Err(LinkError::Io(e.to_string()));
                }
            }
            if !wait_for_quiet || Instant::now() >= until {
                break;
            }
            match timeout_at(until.min(Instant::now() + quiet), stream.read(&mut chunk)).await {
                Err(_) => break, // quiet
                Ok(Ok(n)) => {
                    self.counters.garbage_bytes += n as u64;
                    self.last_traffic = Instant::now();
                }
                Ok(Err(e)) => {
                    self.stream = None;
                    return Err(LinkError::Io(e.to_string()));
                }
            }
        }
        self.dirty = false;
        Ok(())
    }

    async fn transact(
        &mut self,
        unit: u8,
        req: &Request<'_>,
        mut deadline: Deadline,
    ) -> Result<Answer, LinkError> {
        let pdu = frame::encode_request(req).map_err(LinkError::Protocol)?;
        let function = pdu[0];
        let adu = frame::rtu_adu(unit, &pdu);
        self.drain(deadline.remaining()).await?;
        tokio::time::sleep_until(self.last_traffic + self.silence).await;
        let port = self.config.port.get_ref().clone();
        let Some(stream) = self.stream.as_mut() else {
            return Err(LinkError::NotConnected(port));
        };
        let sent = deadline
            .run(async {
                stream.write_all(&adu).await?;
                stream.flush().await
            })
            .await;
        match sent {
            Ok(Ok(())) => {}
            Ok(Err(e)) => {
                self.stream = None;
                return Err(LinkError::Io(e.to_string()));
            }
            Err(_) => {
                self.dirty = true;
                return Err(LinkError::Timeout);
            }
        }
        self.last_traffic = Instant::now();
        self.buf.clear();
        let mut chunk = [0u8; 256];
        loop {
            if let Some((at, len)) = frame::find_rtu_reply(&self.buf, unit, function) {
                if at > 0 {
                    self.counters.garbage_bytes += at as u64;
                }
                // Anything after the reply is noise: drain it before the next request.
                self.dirty = at + len < self.buf.len();
                let pdu = self.buf[at + 1..at + len - 2].to_vec();
                self.last_traffic = Instant::now();
                return frame::parse_response(req, &pdu).map_err(LinkError::Protocol);
            }
            if self.buf.len() > 4096 {
                // A babbling line: start again from the newest bytes.
                let keep = self.buf.split_off(self.buf.len() - 512);
                self.counters.garbage_bytes += self.buf.len() as u64;
                self.buf = keep;
            }
            let Some(stream) = self.stream.as_mut() else {
                return Err(LinkError::NotConnected(port));
            };
            match deadline.run(stream.read(&mut chunk)).await {
                Err(_) => {
                    self.dirty = true;
                    if !self.buf.is_empty() {
                        self.counters.garbage_bytes += self.buf.len() as u64;
                        return Err(LinkError::Garbage(format!(
                            "{} bytes but no valid reply from slave {unit}",
                            self.buf.len()
                        )));
                    }
                    return Err(LinkError::Timeout);
                }
                Ok(Ok(0)) => {
                    self.stream = None;
                    return Err(LinkError::Io("serial port closed".into()));
                }
                Ok(Ok(n)) => {
                    self.buf.extend_from_slice(&chunk[..n]);
                    self.last_traffic = Instant::now();
                }
                Ok(Err(e)) => {
                    self.stream = None;
                    return Err(LinkError::Io(e.to_string()));
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn serial(text: &str) -> SerialConfig {
        toml::from_str(text).unwrap()
    }

    #[test]
    fn silence_follows_the_baud_rate() {
        // 10 bits per char at 9600 baud: 3.5 * 1.0417 ms = 3.65 ms.
        let s = inter_frame_silence(&serial("port = \"/dev/null\"\nbaud = 9600"));
        assert!(
            s > Duration::from_micros(3600) && s < Duration::from_micros(3700),
            "{s:?}"
        );
        let even = serial("port = \"/dev/null\"\nbaud = 9600\nparity = \"even\"");
        assert!(inter_frame_silence(&even) > Duration::from_micros(4000));
        let fast = serial("port = \"/dev/null\"\nbaud = 115200");
        assert_eq!(inter_frame_silence(&fast), Duration::from_micros(1750));
    }
}
