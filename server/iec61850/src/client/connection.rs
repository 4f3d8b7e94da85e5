//! One MMS association over TCP: the handshake (COTP connect, session
//! connect with the presentation and ACSE requests and MMS initiate), then
//! confirmed requests matched to their responses by invoke id, and the
//! unconfirmed information reports passed on in order.
//!
//! A reader task owns the socket's read half and the upper layers'
//! reassembly; a malformed or unexpected PDU, or the peer's abort, ends
//! the association, and every request waiting on it fails with the reason.

use std::collections::HashMap;
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::Arc;
use std::time::Duration;

use parking_lot::Mutex;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::tcp::OwnedWriteHalf;
use tokio::net::TcpStream;
use tokio::sync::{mpsc, oneshot, Semaphore};

use crate::acsi::LastApplError;
use crate::iso::{Addressing, Incoming, Stack, TpktDecoder};
use crate::mms::{
    self, InformationReport, Negotiated, ObjectName, Pdu, ReportNames, Request, Response,
    ServiceError,
};

/// Why a request or the association failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MmsError {
    #[error("connecting to {0}: {1}")]
    Connect(String, String),
    #[error("the association was refused: {0}")]
    Refused(String),
    #[error("no answer within {0} ms")]
    Timeout(u64),
    #[error("the association ended: {0}")]
    Closed(String),
    #[error("{0}")]
    Service(ServiceError),
    #[error("the IED rejected the request: {0}")]
    Rejected(String),
    #[error("unexpected answer: {0}")]
    Unexpected(String),
}

/// What the reader task reports besides responses.
#[derive(Debug)]
pub enum Unsolicited {
    Report(InformationReport),
    /// The association ended, and why ([`Connection::ended_malformed`]
    /// says whether the IED sent something that does not decode).
    Closed {
        reason: String,
    },
}

type Pending = Arc<Mutex<HashMap<u32, oneshot::Sender<Result<Response, MmsError>>>>>;

/// What controls wait for besides their write responses: the IED's
/// `LastApplError` (sent just before a negative response) by control
/// object, and the command terminations of enhanced-security controls.
#[derive(Default)]
struct Controls {
    last_errors: HashMap<String, LastApplError>,
    terminations: HashMap<ObjectName, oneshot::Sender<Result<(), LastApplError>>>,
}

type SharedControls = Arc<Mutex<Controls>>;

/// A live association.
pub struct Connection {
    writer: tokio::sync::Mutex<OwnedWriteHalf>,
    stack: Mutex<Stack>,
    pending: Pending,
    closed: Arc<Mutex<Option<String>>>,
    malformed: Arc<std::sync::atomic::AtomicBool>,
    controls: SharedControls,
    next_invoke: AtomicU32,
    outstanding: Semaphore,
    pub negotiated: Negotiated,
    reader: tokio::task::JoinHandle<()>,
}

impl Drop for Connection {
    fn drop(&mut self) {
        self.reader.abort();
    }
}

/// Largest reassembled message we accept from an IED (its MMS PDU size
/// is negotiated lower; this bounds a hostile peer's segments).
const MAX_MESSAGE: usize = 1 << 20;

impl Connection {
    /// Connects and associates within `timeout`.
    pub async fn open(
        address: &str,
        addressing: Addressing,
        timeout: Duration,
    ) -> Result<(Connection, mpsc::Receiver<Unsolicited>), MmsError> {
        let ms = timeout.as_millis() as u64;
        tokio::time::timeout(timeout, Self::associate(address, addressing))
            .await
            .map_err(|_| MmsError::Timeout(ms))?
    }

    async fn associate(
        address: &str,
        addressing: Addressing,
    ) -> Result<(Connection, mpsc::Receiver<Unsolicited>), MmsError> {
        let connect_err = |e: std::io::Error| MmsError::Connect(address.to_string(), e.to_string());
        let mut socket = TcpStream::connect(address).await.map_err(connect_err)?;
        socket.set_nodelay(true).ok();
        let mut stack = Stack::new(addressing, MAX_MESSAGE);
        let mut decoder = TpktDecoder::default();
        socket
            .write_all(&stack.connect_request())
            .await
            .map_err(connect_err)?;
        match next_incoming(&mut socket, &mut decoder, &mut stack).await? {
            Incoming::Connected => {}
            other => {
                return Err(MmsError::Refused(format!(
                    "transport connection: {other:?}"
                )))
            }
        }
        for p in stack.associate_request(&mms::initiate_request()) {
            socket.write_all(&p).await.map_err(connect_err)?;
        }
        let initiate = match next_incoming(&mut socket, &mut decoder, &mut stack).await? {
            Incoming::Accepted(pdu) => pdu,
            Incoming::Refused(why) | Incoming::Closed(why) => return Err(MmsError::Refused(why)),
            other => return Err(MmsError::Refused(format!("unexpected answer {other:?}"))),
        };
        let negotiated = match Pdu::decode(&initiate) {
            Ok(Pdu::InitiateResponse(n)) => n,
            Ok(Pdu::InitiateError(e)) => {
                return Err(MmsError::Refused(format!("MMS initiate: {e}")))
            }
            Ok(other) => {
                return Err(MmsError::Refused(format!(
                    "MMS initiate answered with {other:?}"
                )))
            }
            Err(e) => return Err(MmsError::Refused(format!("MMS initiate response: {e}"))),
        };
        let (read, writer) = socket.into_split();
        let pending: Pending = Arc::default();
        let closed = Arc::new(Mutex::new(None));
        let controls = SharedControls::default();
        let malformed = Arc::new(std::sync::atomic::AtomicBool::new(false));
        let (tx, rx) = mpsc::channel(1024);
        let reader = tokio::spawn(read_loop(
            read,
            decoder,
            Stack::new(stack.addressing.clone(), MAX_MESSAGE),
            Arc::clone(&pending),
            Arc::clone(&closed),
            Arc::clone(&malformed),
            Arc::clone(&controls),
            tx,
        ));
        let outstanding = Semaphore::new(negotiated.max_outstanding.clamp(1, 64) as usize);
        Ok((
            Connection {
                writer: tokio::sync::Mutex::new(writer),
                stack: Mutex::new(stack),
                pending,
                closed,
                malformed,
                controls,
                next_invoke: AtomicU32::new(1),
                outstanding,
                negotiated,
                reader,
            },
            rx,
        ))
    }

    /// Sends a confirmed request and waits for its response.
    pub async fn request(&self, req: &Request, timeout: Duration) -> Result<Response, MmsError> {
        let ms = timeout.as_millis() as u64;
        let _permit = tokio::time::timeout(timeout, self.outstanding.acquire())
            .await
            .map_err(|_| MmsError::Timeout(ms))?
            .map_err(|_| self.closed_error())?;
        let invoke = self.next_invoke.fetch_add(1, Ordering::Relaxed);
        let (tx, rx) = oneshot::channel();
        if let Some(why) = self.closed.lock().clone() {
            return Err(MmsError::Closed(why));
        }
        self.pending.lock().insert(invoke, tx);
        let packets = self.stack.lock().data(&req.encode(invoke));
        let sent = async {
            let mut w = self.writer.lock().await;
            for p in packets {
                w.write_all(&p).await?;
            }
            Ok::<_, std::io::Error>(())
        };
        let result = tokio::time::timeout(timeout, async {
            sent.await
                .map_err(|e| MmsError::Closed(format!("sending: {e}")))?;
            rx.await.map_err(|_| self.closed_error())?
        })
        .await;
        self.pending.lock().remove(&invoke);
        result.map_err(|_| MmsError::Timeout(ms))?
    }

    fn closed_error(&self) -> MmsError {
        MmsError::Closed(
            self.closed
                .lock()
                .clone()
                .unwrap_or_else(|| "connection lost".into()),
        )
    }

    /// Forgets the last `LastApplError` of `control_object`
    /// (`LD/LN$CO$DO$Oper`), before a control is sent.
    pub fn clear_last_appl_error(&self, control_object: &str) {
        self.controls.lock().last_errors.remove(control_object);
    }

    /// The `LastApplError` the IED sent for `control_object`, if any.
    pub fn take_last_appl_error(&self, control_object: &str) -> Option<LastApplError> {
        self.controls.lock().last_errors.remove(control_object)
    }

    /// Resolves when the command termination of `oper` arrives (or fails
    /// when the association ends). Call before sending `Oper`.
    pub fn expect_termination(
        &self,
        oper: &ObjectName,
    ) -> oneshot::Receiver<Result<(), LastApplError>> {
        let (tx, rx) = oneshot::channel();
        self.controls.lock().terminations.insert(oper.clone(), tx);
        rx
    }

    /// Whether the association ended because the IED sent something that
    /// does not decode.
    pub fn ended_malformed(&self) -> bool {
        self.malformed.load(Ordering::Relaxed)
    }

    /// Whether the association has ended.
    pub fn is_closed(&self) -> bool {
        self.closed.lock().is_some()
    }

    /// Ends the association in order (MMS conclude), then closes.
    pub async fn conclude(&self, timeout: Duration) {
        let packets = self.stack.lock().data(&mms::conclude_request());
        let _ = tokio::time::timeout(timeout, async {
            let mut w = self.writer.lock().await;
            for p in packets {
                w.write_all(&p).await?;
            }
            w.shutdown().await
        })
        .await;
    }
}

async fn next_incoming(
    socket: &mut TcpStream,
    decoder: &mut TpktDecoder,
    stack: &mut Stack,
) -> Result<Incoming, MmsError> {
    let mut buf = [0u8; 4096];
    loop {
        while let Some(packet) = decoder
            .next_packet()
            .map_err(|e| MmsError::Refused(e.to_string()))?
        {
            match stack
                .receive(&packet)
                .map_err(|e| MmsError::Refused(e.to_string()))?
            {
                Incoming::Partial => continue,
                other => return Ok(other),
            }
        }
        let n = socket
            .read(&mut buf)
            .await
            .map_err(|e| MmsError::Closed(e.to_string()))?;
        if n == 0 {
            return Err(MmsError::Closed("the IED closed the connection".into()));
        }
        decoder.push(&buf[..n]);
    }
}

#[allow(clippy::too_many_arguments)]
async fn read_loop(
    mut read: tokio::net::tcp::OwnedReadHalf,
    mut decoder: TpktDecoder,
    mut stack: Stack,
    pending: Pending,
    closed: Arc<Mutex<Option<String>>>,
    malformed_flag: Arc<std::sync::atomic::AtomicBool>,
    controls: SharedControls,
    unsolicited: mpsc::Sender<Unsolicited>,
) {
    let mut buf = vec![0u8; 16 * 1024];
    let (reason, malformed) = 'outer: loop {
        loop {
            let packet = match decoder.next_packet() {
                Ok(Some(p)) => p,
                Ok(None) => break,
                Err(e) => break 'outer (e.to_string(), true),
            };
            let pdu = match stack.receive(&packet) {
                Ok(Incoming::Mms(pdu)) => pdu,
                Ok(Incoming::Partial) => continue,
                Ok(Incoming::Closed(why)) => break 'outer (why, false),
                Ok(other) => {
                    break 'outer (format!("unexpected {other:?} in the data phase"), true)
                }
                Err(e) => break 'outer (e.to_string(), true),
            };
            match Pdu::decode(&pdu) {
                Ok(Pdu::Response { invoke, response }) => answer(&pending, invoke, Ok(response)),
                Ok(Pdu::Error { invoke, error }) => {
                    answer(&pending, invoke, Err(MmsError::Service(error)))
                }
                Ok(Pdu::Reject {
                    invoke: Some(invoke),
                    reason,
                }) => answer(&pending, invoke, Err(MmsError::Rejected(reason))),
                Ok(Pdu::Reject {
                    invoke: None,
                    reason,
                }) => break 'outer (format!("the IED rejected a PDU: {reason}"), false),
                Ok(Pdu::InformationReport(r)) => {
                    if route_control_report(&controls, &r) {
                        continue;
                    }
                    if unsolicited.send(Unsolicited::Report(r)).await.is_err() {
                        break 'outer ("closed by gridscada".into(), false);
                    }
                }
                Ok(Pdu::ConcludeRequest) => {
                    break 'outer ("the IED concluded the association".into(), false)
                }
                Ok(Pdu::ConcludeResponse) => break 'outer ("concluded".into(), false),
                Ok(other) => break 'outer (format!("unexpected PDU {other:?}"), true),
                Err(e) => break 'outer (format!("malformed MMS PDU: {e}"), true),
            }
        }
        match read.read(&mut buf).await {
            Ok(0) => break ("the IED closed the connection".into(), false),
            Ok(n) => decoder.push(&buf[..n]),
            Err(e) => break (e.to_string(), false),
        }
    };
    malformed_flag.store(malformed, Ordering::Relaxed);
    *closed.lock() = Some(reason.clone());
    pending.lock().clear();
    let _ = unsolicited.send(Unsolicited::Closed { reason }).await;
}

/// Keeps a `LastApplError` and hands a command termination to its
/// control; true when the report was one of those.
fn route_control_report(controls: &SharedControls, r: &InformationReport) -> bool {
    let ReportNames::Variables(names) = &r.names else {
        return false;
    };
    let error = LastApplError::from_report(r);
    let mut c = controls.lock();
    if let Some(oper) = names.iter().find(|n| n.item().ends_with("$Oper")) {
        if let Some(tx) = c.terminations.remove(oper) {
            let _ = tx.send(match error {
                Some(e) => Err(e),
                None => Ok(()),
            });
        }
        return true;
    }
    match error {
        Some(e) => {
            c.last_errors.insert(e.control_object.clone(), e);
            true
        }
        None => false,
    }
}

fn answer(pending: &Pending, invoke: u32, result: Result<Response, MmsError>) {
    if let Some(tx) = pending.lock().remove(&invoke) {
        let _ = tx.send(result);
    }
}
