//! # Accepting connections: the limits an untrusted client meets first
//!
//! **Owns:** the accept loop of every HTTP(S) listener (plain HTTP, HTTPS,
//! the redirect), and what a connection may hold before and between its
//! requests: a global and a per-client cap on open connections, the TLS
//! handshake's and the request headers' deadlines (hyper's header-read
//! timeout, which also closes a keep-alive connection left idle), and
//! back-off when accepting fails (out of descriptors).
//!
//! **Must not touch:** what a request means: routing, sessions and rights
//! are the router's ([`crate::routes`]).
//!
//! A full server does not turn a newcomer away while it holds connections
//! that have nothing in flight: it closes the one that has waited longest
//! (a slow client's half-sent headers, an unfinished TLS handshake, an
//! idle keep-alive), so slow clients cannot starve `/healthz` or an
//! operator. A connection with a request in flight, or upgraded (a live
//! WebSocket), is never closed to make room; only when every one is busy is
//! the newcomer refused. Behind a trusted proxy the proxy's own address is
//! not capped (it carries everyone); its clients are counted per request,
//! on the address the proxy reports ([`crate::proxy`]).

use std::collections::{BTreeMap, HashMap};
use std::convert::Infallible;
use std::net::{IpAddr, SocketAddr};
use std::pin::Pin;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::Arc;
use std::task::{Context, Poll};
use std::time::{Duration, Instant};

use axum::body::Body;
use axum::extract::ConnectInfo;
use axum::http::{header, Request, Response, StatusCode};
use axum::Router;
use hyper::body::Incoming;
use hyper_util::rt::{TokioIo, TokioTimer};
use parking_lot::Mutex;
use tokio::io::{AsyncRead, AsyncWrite};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::Notify;
use tower::ServiceExt;

use crate::metrics::Prom;
use crate::proxy::TrustedProxies;

/// The limits of `[server.connections]`, fitted to the process.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ConnectionLimits {
    /// Open connections on all listeners together.
    pub max_open: usize,
    /// Open connections (or, behind a trusted proxy, requests in flight) of
    /// one client address.
    pub max_per_client: usize,
    /// A request's headers must arrive within this; a keep-alive connection
    /// idle this long is closed.
    pub header_timeout: Duration,
    /// A TLS handshake must finish within this.
    pub tls_handshake_timeout: Duration,
}

impl Default for ConnectionLimits {
    fn default() -> Self {
        ConnectionLimits::from_config(&gridscada_config::ConnectionsConfig::default())
    }
}

/// Descriptors kept for everything else the server opens (database pools,
/// field devices, files, the OPC UA and MQTT sides): a quarter of the
/// limit, at least this many.
const RESERVED_DESCRIPTORS: u64 = 128;

/// Sockets closed for room that may still be open beyond `max_open`, on top
/// of an eighth of it.
const CLOSING_SLACK: usize = 8;

impl ConnectionLimits {
    pub fn from_config(c: &gridscada_config::ConnectionsConfig) -> Self {
        let secs = |s: f64| Duration::from_secs_f64(s.clamp(0.1, 300.0));
        let max_open = (*c.max_open.get_ref()).max(1) as usize;
        ConnectionLimits {
            max_open,
            max_per_client: (*c.max_per_client.get_ref()).clamp(1, max_open as u32) as usize,
            header_timeout: secs(*c.header_timeout_s.get_ref()),
            tls_handshake_timeout: secs(*c.tls_handshake_timeout_s.get_ref()),
        }
    }

    /// These limits lowered to fit an open-file limit of `descriptors`:
    /// a server that runs out of descriptors cannot even answer
    /// `/healthz`, while one at its own cap still can (by closing a
    /// connection that waits).
    pub fn fitted_to(mut self, descriptors: u64) -> Self {
        let reserve = (descriptors / 4).max(RESERVED_DESCRIPTORS);
        let room = descriptors.saturating_sub(reserve) as usize;
        // `max_open` plus the sockets still closing must fit the room.
        let fits = (room.saturating_sub(CLOSING_SLACK) * 8 / 9).max(16);
        self.max_open = self.max_open.min(fits);
        self.max_per_client = self.max_per_client.min(self.max_open);
        self
    }

    /// How many connections may be open at once, counting those closed for
    /// room whose sockets have not closed yet (their task has yet to run):
    /// past it a newcomer is refused outright, which frees its descriptor
    /// at once.
    fn hard_cap(&self) -> usize {
        self.max_open + self.max_open / 8 + CLOSING_SLACK
    }
}

/// Raises the process's soft open-file limit to its hard limit (systemd's
/// `LimitNOFILE` sets both; a shell's soft limit is often 1024 under a far
/// higher hard one) and returns the soft limit in force (`None`:
/// unlimited).
pub fn raise_open_file_limit() -> Option<u64> {
    use rustix::process::{getrlimit, setrlimit, Resource, Rlimit};
    let limit = getrlimit(Resource::Nofile);
    if let (Some(current), Some(maximum)) = (limit.current, limit.maximum) {
        if current < maximum {
            let raised = Rlimit {
                current: Some(maximum),
                maximum: Some(maximum),
            };
            match setrlimit(Resource::Nofile, raised) {
                Ok(()) => return Some(maximum),
                Err(e) => tracing::debug!(error = %e, "the open-file limit stays as it is"),
            }
        }
    }
    limit.current
}

/// Why a connection or request was turned away, for `/metrics`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Refusal {
    /// Every connection was busy at `max_open`.
    Full,
    /// The client's every connection (or proxied request) was busy at
    /// `max_per_client`.
    PerClient,
}

/// The open connections of all listeners of one server, and their figures.
pub struct Connections {
    limits: ConnectionLimits,
    proxies: TrustedProxies,
    table: Mutex<Table>,
    epoch: Instant,
    refused_full: AtomicU64,
    refused_per_client: AtomicU64,
    closed_for_room: AtomicU64,
    accept_errors: AtomicU64,
    handshake_timeouts: AtomicU64,
    /// When the last refusal or accept error was logged (ms since `epoch`),
    /// so an attack does not flood the log.
    last_warned_ms: AtomicU64,
}

#[derive(Default)]
struct Table {
    next_id: u64,
    /// Open connections by id (ids rise with accept order), those closed
    /// for room included until their socket is closed.
    open: BTreeMap<u64, Entry>,
    /// Of `open`, those closed for room.
    closing: usize,
    /// Connections per client address, plus requests in flight per client
    /// behind a trusted proxy.
    per_client: HashMap<IpAddr, usize>,
}

struct Entry {
    /// The address counted against `max_per_client`; `None` for a trusted
    /// proxy's connection.
    client: Option<IpAddr>,
    state: Arc<ConnState>,
}

/// What the table knows of one connection while it is served.
struct ConnState {
    /// Requests whose response has not been sent whole.
    in_flight: AtomicUsize,
    /// Taken over by a WebSocket: never closed for room.
    upgraded: AtomicBool,
    /// Since when (ms since the table's epoch) nothing has been in flight.
    waiting_since_ms: AtomicU64,
    /// Closed to make room; the connection's task ends on `close`.
    closing: AtomicBool,
    close: Notify,
}

impl ConnState {
    fn waiting(&self) -> bool {
        self.in_flight.load(Ordering::Acquire) == 0
            && !self.upgraded.load(Ordering::Acquire)
            && !self.closing.load(Ordering::Acquire)
    }
}

impl Default for Connections {
    /// Default limits and no trusted proxies (tests, tools).
    fn default() -> Self {
        Connections::new(ConnectionLimits::default(), TrustedProxies::default())
    }
}

impl Connections {
    pub fn new(limits: ConnectionLimits, proxies: TrustedProxies) -> Self {
        Connections {
            limits,
            proxies,
            table: Mutex::new(Table::default()),
            epoch: Instant::now(),
            refused_full: AtomicU64::new(0),
            refused_per_client: AtomicU64::new(0),
            closed_for_room: AtomicU64::new(0),
            accept_errors: AtomicU64::new(0),
            handshake_timeouts: AtomicU64::new(0),
            last_warned_ms: AtomicU64::new(u64::MAX),
        }
    }

    pub fn limits(&self) -> ConnectionLimits {
        self.limits
    }

    /// Connections open now (those closed for room whose sockets are
    /// still closing included).
    pub fn open(&self) -> usize {
        self.table.lock().open.len()
    }

    fn now_ms(&self) -> u64 {
        self.epoch.elapsed().as_millis() as u64
    }

    /// Admits a connection from `peer`, closing the longest-waiting one to
    /// make room where a cap is reached, or refuses it.
    fn admit(self: &Arc<Self>, peer: IpAddr) -> Result<Ticket, Refusal> {
        let peer = peer.to_canonical();
        let client = (!self.proxies.trusts(peer)).then_some(peer);
        let mut table = self.table.lock();
        if let Some(ip) = client {
            if table.per_client.get(&ip).copied().unwrap_or(0) >= self.limits.max_per_client
                && !self.close_longest_waiting(&mut table, Some(ip))
            {
                return Err(self.refused(Refusal::PerClient, peer));
            }
        }
        if table.open.len() - table.closing >= self.limits.max_open
            && !self.close_longest_waiting(&mut table, None)
        {
            return Err(self.refused(Refusal::Full, peer));
        }
        if table.open.len() >= self.limits.hard_cap() {
            return Err(self.refused(Refusal::Full, peer));
        }
        let id = table.next_id;
        table.next_id += 1;
        let state = Arc::new(ConnState {
            in_flight: AtomicUsize::new(0),
            upgraded: AtomicBool::new(false),
            waiting_since_ms: AtomicU64::new(self.now_ms()),
            closing: AtomicBool::new(false),
            close: Notify::new(),
        });
        if let Some(ip) = client {
            *table.per_client.entry(ip).or_default() += 1;
        }
        table.open.insert(
            id,
            Entry {
                client,
                state: state.clone(),
            },
        );
        Ok(Ticket {
            connections: self.clone(),
            id,
            state,
            held: Arc::default(),
        })
    }

    /// Closes the connection (of `client`, or of anyone) that has waited
    /// longest with nothing in flight: it no longer counts against the
    /// caps, though its socket stays on the table until its task has
    /// closed it. False when every one is busy.
    fn close_longest_waiting(&self, table: &mut Table, client: Option<IpAddr>) -> bool {
        let victim = table
            .open
            .iter()
            .filter(|(_, e)| client.is_none() || e.client == client)
            .filter(|(_, e)| e.state.waiting())
            .min_by_key(|(id, e)| (e.state.waiting_since_ms.load(Ordering::Acquire), **id))
            .map(|(id, _)| *id);
        let Some(id) = victim else {
            return false;
        };
        let Some(entry) = table.open.get(&id) else {
            return false;
        };
        entry.state.closing.store(true, Ordering::Release);
        // `notify_one` keeps a permit if the task is not waiting yet.
        entry.state.close.notify_one();
        if let Some(ip) = entry.client {
            release(table, ip);
        }
        table.closing += 1;
        self.closed_for_room.fetch_add(1, Ordering::Relaxed);
        true
    }

    fn refused(&self, why: Refusal, peer: IpAddr) -> Refusal {
        match why {
            Refusal::Full => &self.refused_full,
            Refusal::PerClient => &self.refused_per_client,
        }
        .fetch_add(1, Ordering::Relaxed);
        if self.should_warn() {
            match why {
                Refusal::Full => tracing::warn!(
                    %peer, max_open = self.limits.max_open,
                    "connection refused: every open connection is busy ([server.connections] max_open)"
                ),
                Refusal::PerClient => tracing::warn!(
                    %peer, max_per_client = self.limits.max_per_client,
                    "connection refused: this client's every connection is busy ([server.connections] max_per_client)"
                ),
            }
        }
        why
    }

    /// At most one warning every ten seconds.
    fn should_warn(&self) -> bool {
        let now = self.now_ms();
        let last = self.last_warned_ms.load(Ordering::Relaxed);
        (last == u64::MAX || now.saturating_sub(last) >= 10_000)
            && self
                .last_warned_ms
                .compare_exchange(last, now, Ordering::Relaxed, Ordering::Relaxed)
                .is_ok()
    }

    /// A slot for one request of `client` behind a trusted proxy, or `None`
    /// at the client's cap.
    fn take_proxied_slot(self: &Arc<Self>, client: IpAddr) -> Option<ProxiedSlot> {
        let mut table = self.table.lock();
        let n = table.per_client.entry(client).or_default();
        if *n >= self.limits.max_per_client {
            drop(table);
            self.refused(Refusal::PerClient, client);
            return None;
        }
        *n += 1;
        Some(ProxiedSlot {
            connections: self.clone(),
            client,
        })
    }

    /// The figures for `/metrics`.
    pub fn render(&self, out: &mut Prom) {
        out.gauge(
            "gridscada_http_connections_open",
            "HTTP(S) connections open now, on all listeners.",
            &[],
            self.open() as f64,
        );
        out.gauge(
            "gridscada_http_connections_max",
            "The cap on open HTTP(S) connections ([server.connections] max_open, fitted to the open-file limit).",
            &[],
            self.limits.max_open as f64,
        );
        for (reason, n) in [
            ("full", &self.refused_full),
            ("per_client", &self.refused_per_client),
        ] {
            out.counter(
                "gridscada_http_connections_refused_total",
                "Connections (or proxied requests) turned away because every connection at a cap was busy.",
                &[("reason", reason)],
                n.load(Ordering::Relaxed) as f64,
            );
        }
        out.counter(
            "gridscada_http_connections_closed_for_room_total",
            "Waiting connections (unfinished headers or handshake, idle keep-alive) closed to admit a newer one at a cap.",
            &[],
            self.closed_for_room.load(Ordering::Relaxed) as f64,
        );
        out.counter(
            "gridscada_http_tls_handshake_timeouts_total",
            "TLS handshakes not finished within [server.connections] tls_handshake_timeout_s.",
            &[],
            self.handshake_timeouts.load(Ordering::Relaxed) as f64,
        );
        out.counter(
            "gridscada_http_accept_errors_total",
            "Failed accepts (out of descriptors, out of memory); the listener backs off after each.",
            &[],
            self.accept_errors.load(Ordering::Relaxed) as f64,
        );
    }
}

/// Takes `id` off the table with its count (a connection closed for room
/// gave its per-client count back then).
fn remove(table: &mut Table, id: u64) {
    let Some(entry) = table.open.remove(&id) else {
        return;
    };
    if entry.state.closing.load(Ordering::Acquire) {
        table.closing -= 1;
    } else if let Some(ip) = entry.client {
        release(table, ip);
    }
}

fn release(table: &mut Table, ip: IpAddr) {
    if let Some(n) = table.per_client.get_mut(&ip) {
        *n -= 1;
        if *n == 0 {
            table.per_client.remove(&ip);
        }
    }
}

/// An admitted connection's place in the table; dropping it frees the
/// place. It travels with the connection's socket ([`Counted`]), so a
/// connection upgraded to a WebSocket keeps its place for as long as the
/// socket lives.
struct Ticket {
    connections: Arc<Connections>,
    id: u64,
    state: Arc<ConnState>,
    /// A proxied client's slot held for the life of an upgraded
    /// connection (dropped after the ticket has left the table).
    held: Arc<Mutex<Option<ProxiedSlot>>>,
}

impl Drop for Ticket {
    fn drop(&mut self) {
        remove(&mut self.connections.table.lock(), self.id);
    }
}

/// One proxied request's count against its real client's cap.
struct ProxiedSlot {
    connections: Arc<Connections>,
    client: IpAddr,
}

impl Drop for ProxiedSlot {
    fn drop(&mut self) {
        release(&mut self.connections.table.lock(), self.client);
    }
}

/// A request in flight on a connection; dropped when its response has been
/// sent whole (or abandoned).
struct InFlight {
    state: Arc<ConnState>,
    epoch: Instant,
    proxied: Option<ProxiedSlot>,
}

impl InFlight {
    fn begin(state: &Arc<ConnState>, epoch: Instant, proxied: Option<ProxiedSlot>) -> Self {
        state.in_flight.fetch_add(1, Ordering::AcqRel);
        InFlight {
            state: state.clone(),
            epoch,
            proxied,
        }
    }
}

impl Drop for InFlight {
    fn drop(&mut self) {
        self.state
            .waiting_since_ms
            .store(self.epoch.elapsed().as_millis() as u64, Ordering::Release);
        self.state.in_flight.fetch_sub(1, Ordering::AcqRel);
    }
}

/// A response body that holds its request's [`InFlight`] until the last
/// byte is handed to the connection.
struct Tracked {
    body: Body,
    _in_flight: InFlight,
}

impl hyper::body::Body for Tracked {
    type Data = axum::body::Bytes;
    type Error = axum::Error;

    fn poll_frame(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
    ) -> Poll<Option<Result<hyper::body::Frame<Self::Data>, Self::Error>>> {
        Pin::new(&mut self.body).poll_frame(cx)
    }

    fn is_end_stream(&self) -> bool {
        self.body.is_end_stream()
    }

    fn size_hint(&self) -> hyper::body::SizeHint {
        self.body.size_hint()
    }
}

/// A connection's socket with its place in the table.
struct Counted<I> {
    io: I,
    _ticket: Ticket,
}

impl<I: AsyncRead + Unpin> AsyncRead for Counted<I> {
    fn poll_read(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut tokio::io::ReadBuf<'_>,
    ) -> Poll<std::io::Result<()>> {
        Pin::new(&mut self.io).poll_read(cx, buf)
    }
}

impl<I: AsyncWrite + Unpin> AsyncWrite for Counted<I> {
    fn poll_write(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<std::io::Result<usize>> {
        Pin::new(&mut self.io).poll_write(cx, buf)
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<std::io::Result<()>> {
        Pin::new(&mut self.io).poll_flush(cx)
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<std::io::Result<()>> {
        Pin::new(&mut self.io).poll_shutdown(cx)
    }

    fn poll_write_vectored(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        bufs: &[std::io::IoSlice<'_>],
    ) -> Poll<std::io::Result<usize>> {
        Pin::new(&mut self.io).poll_write_vectored(cx, bufs)
    }

    fn is_write_vectored(&self) -> bool {
        self.io.is_write_vectored()
    }
}

/// What a listener does with a connection once admitted: plain, or TLS
/// first.
#[derive(Clone)]
pub(crate) enum Transport {
    Plain,
    Tls(crate::tls::Https),
}

/// Serves `router` on `listener` under `connections`' limits until the
/// future is dropped. Accept errors (out of descriptors) back off from
/// 10 ms to 1 s instead of spinning.
pub(crate) async fn serve(
    listener: TcpListener,
    router: Router,
    connections: Arc<Connections>,
    transport: Transport,
) -> std::io::Result<()> {
    let mut backoff = Duration::from_millis(10);
    loop {
        let (stream, peer) = match listener.accept().await {
            Ok(accepted) => {
                backoff = Duration::from_millis(10);
                accepted
            }
            Err(e) if is_per_connection(&e) => continue,
            Err(e) => {
                connections.accept_errors.fetch_add(1, Ordering::Relaxed);
                if connections.should_warn() {
                    tracing::warn!(error = %e, retry_ms = backoff.as_millis() as u64,
                        "cannot accept connections (raise LimitNOFILE, or lower [server.connections] max_open)");
                }
                tokio::time::sleep(backoff).await;
                backoff = (backoff * 2).min(Duration::from_secs(1));
                continue;
            }
        };
        let Ok(ticket) = connections.admit(peer.ip()) else {
            // Dropping the stream closes it at once.
            continue;
        };
        if connections.table.lock().closing > 0 {
            // Let the connections closed for room run (and close their
            // sockets) before the next accept: under a flood of newcomers
            // this loop would otherwise starve them, and their descriptors
            // would pile up.
            tokio::task::yield_now().await;
        }
        let _ = stream.set_nodelay(true);
        let router = router.clone();
        let connections = connections.clone();
        let transport = transport.clone();
        tokio::spawn(async move {
            let state = ticket.state.clone();
            let held = ticket.held.clone();
            let stream = Counted {
                io: stream,
                _ticket: ticket,
            };
            let served =
                serve_admitted(stream, peer, router, &connections, transport, &state, held);
            // Closed for room: dropping the connection closes its socket.
            tokio::select! {
                _ = served => {}
                _ = state.close.notified() => {}
            }
        });
    }
}

/// Errors of one connection that failed before `accept` returned it; the
/// listener itself is fine.
fn is_per_connection(e: &std::io::Error) -> bool {
    use std::io::ErrorKind::*;
    matches!(
        e.kind(),
        ConnectionAborted | ConnectionReset | ConnectionRefused | Interrupted | WouldBlock
    )
}

async fn serve_admitted(
    stream: Counted<TcpStream>,
    peer: SocketAddr,
    router: Router,
    connections: &Arc<Connections>,
    transport: Transport,
    state: &Arc<ConnState>,
    held: Arc<Mutex<Option<ProxiedSlot>>>,
) {
    match transport {
        Transport::Plain => serve_http(stream, peer, router, connections, state, held).await,
        Transport::Tls(https) => {
            let acceptor = tokio_rustls::TlsAcceptor::from(https.current());
            let deadline = connections.limits.tls_handshake_timeout;
            match tokio::time::timeout(deadline, acceptor.accept(stream)).await {
                Ok(Ok(tls)) => serve_http(tls, peer, router, connections, state, held).await,
                Ok(Err(e)) => tracing::debug!(%peer, error = %e, "TLS handshake failed"),
                Err(_) => {
                    connections
                        .handshake_timeouts
                        .fetch_add(1, Ordering::Relaxed);
                    tracing::debug!(%peer, "TLS handshake not finished in time");
                }
            }
        }
    }
}

/// HTTP/1.1 on one connection, with upgrades (the live WebSocket).
async fn serve_http<I>(
    io: I,
    peer: SocketAddr,
    router: Router,
    connections: &Arc<Connections>,
    state: &Arc<ConnState>,
    held: Arc<Mutex<Option<ProxiedSlot>>>,
) where
    I: AsyncRead + AsyncWrite + Unpin + Send + 'static,
{
    let service = {
        let connections = connections.clone();
        let state = state.clone();
        hyper::service::service_fn(move |req: Request<Incoming>| {
            handle(
                req,
                peer,
                router.clone(),
                connections.clone(),
                state.clone(),
                held.clone(),
            )
        })
    };
    let mut builder = hyper::server::conn::http1::Builder::new();
    builder
        .timer(TokioTimer::new())
        .header_read_timeout(connections.limits.header_timeout);
    let conn = builder
        .serve_connection(TokioIo::new(io), service)
        .with_upgrades();
    if let Err(e) = conn.await {
        tracing::debug!(%peer, error = %e, "HTTP connection ended");
    }
}

/// One request: the real client's cap behind a trusted proxy, then the
/// router; the response's body carries the request's place in flight.
async fn handle(
    mut req: Request<Incoming>,
    peer: SocketAddr,
    router: Router,
    connections: Arc<Connections>,
    state: Arc<ConnState>,
    held: Arc<Mutex<Option<ProxiedSlot>>>,
) -> Result<Response<Tracked>, Infallible> {
    let mut proxied = None;
    if connections.proxies.trusts(peer.ip()) {
        let client = connections.proxies.client(peer.ip(), req.headers()).ip;
        match connections.take_proxied_slot(client) {
            Some(slot) => proxied = Some(slot),
            None => {
                let in_flight = InFlight::begin(&state, connections.epoch, None);
                return Ok(too_many(in_flight));
            }
        }
    }
    let mut in_flight = InFlight::begin(&state, connections.epoch, proxied);
    req.extensions_mut().insert(ConnectInfo(peer));
    let response = match router.oneshot(req.map(Body::new)).await {
        Ok(r) => r,
        Err(never) => match never {},
    };
    if response.status() == StatusCode::SWITCHING_PROTOCOLS {
        // A WebSocket now owns the connection for as long as it lives,
        // and a proxied client's slot with it.
        state.upgraded.store(true, Ordering::Release);
        *held.lock() = in_flight.proxied.take();
    }
    Ok(response.map(|body| Tracked {
        body,
        _in_flight: in_flight,
    }))
}

/// 503 for a client at its cap behind a proxy.
fn too_many(in_flight: InFlight) -> Response<Tracked> {
    let mut response = Response::new(Tracked {
        body: Body::from("too many requests in flight from your address; try again shortly\n"),
        _in_flight: in_flight,
    });
    *response.status_mut() = StatusCode::SERVICE_UNAVAILABLE;
    response
        .headers_mut()
        .insert(header::RETRY_AFTER, header::HeaderValue::from_static("1"));
    response.headers_mut().insert(
        header::CONTENT_TYPE,
        header::HeaderValue::from_static("text/plain; charset=utf-8"),
    );
    response
}

#[cfg(test)]
mod tests {
    use super::*;
    use gridscada_config::Cidr;

    fn limits(max_open: usize, max_per_client: usize) -> ConnectionLimits {
        ConnectionLimits {
            max_open,
            max_per_client,
            ..ConnectionLimits::default()
        }
    }

    fn ip(s: &str) -> IpAddr {
        s.parse().unwrap()
    }

    #[test]
    fn limits_fit_the_open_file_limit() {
        let l = limits(4096, 256).fitted_to(1024);
        assert_eq!(l.max_open, 675);
        assert!(l.hard_cap() <= 768, "{}", l.hard_cap());
        assert_eq!(l.max_per_client, 256);
        let l = limits(4096, 256).fitted_to(65536);
        assert_eq!(l.max_open, 4096);
        let l = limits(4096, 256).fitted_to(100);
        assert_eq!((l.max_open, l.max_per_client), (16, 16));
    }

    #[test]
    fn a_client_at_its_cap_closes_its_own_longest_waiting_connection() {
        let c = Arc::new(Connections::new(limits(100, 2), TrustedProxies::default()));
        let a1 = c.admit(ip("10.0.0.1")).unwrap();
        let a2 = c.admit(ip("10.0.0.1")).unwrap();
        let b = c.admit(ip("10.0.0.2")).unwrap();
        // a2 is busy: a third from 10.0.0.1 closes a1, not b.
        let _busy = InFlight::begin(&a2.state, c.epoch, None);
        let a3 = c.admit(ip("10.0.0.1")).unwrap();
        assert!(a1.state.closing.load(Ordering::Acquire));
        assert!(!b.state.closing.load(Ordering::Acquire));
        // a1's socket counts until its task has closed it.
        assert_eq!(c.open(), 4);
        // Both remaining ones busy: the next is refused.
        let _busy3 = InFlight::begin(&a3.state, c.epoch, None);
        assert_eq!(c.admit(ip("10.0.0.1")).err(), Some(Refusal::PerClient));
        assert_eq!(c.refused_per_client.load(Ordering::Relaxed), 1);
        // The closed one's ticket dropping later takes nothing back twice.
        drop(a1);
        assert_eq!(c.open(), 3);
        assert_eq!(c.table.lock().closing, 0);
        assert_eq!(c.table.lock().per_client[&ip("10.0.0.1")], 2);
    }

    #[test]
    fn sockets_still_closing_bound_the_descriptors() {
        let l = limits(8, 8);
        let c = Arc::new(Connections::new(l, TrustedProxies::default()));
        let mut held = vec![];
        // Every admission past 8 closes a waiting one for room, until the
        // closing ones reach the hard cap: then newcomers are refused.
        for _ in 0..l.hard_cap() {
            held.push(c.admit(ip("10.0.0.1")).unwrap());
        }
        assert_eq!(c.open(), l.hard_cap());
        assert_eq!(c.admit(ip("10.0.0.2")).err(), Some(Refusal::Full));
        // Once one closing socket is gone, there is room again.
        let closing = held
            .iter()
            .position(|t| t.state.closing.load(Ordering::Acquire));
        held.remove(closing.unwrap());
        assert!(c.admit(ip("10.0.0.2")).is_ok());
    }

    #[test]
    fn a_full_server_closes_the_longest_waiting_connection_of_anyone() {
        let c = Arc::new(Connections::new(limits(2, 2), TrustedProxies::default()));
        let a = c.admit(ip("10.0.0.1")).unwrap();
        let b = c.admit(ip("10.0.0.2")).unwrap();
        let upgraded = c.admit(ip("10.0.0.3"));
        assert!(upgraded.is_ok());
        assert!(a.state.closing.load(Ordering::Acquire));
        let upgraded = upgraded.unwrap();
        upgraded.state.upgraded.store(true, Ordering::Release);
        let _busy = InFlight::begin(&b.state, c.epoch, None);
        // b busy, the third upgraded: nothing can make room.
        assert_eq!(c.admit(ip("10.0.0.4")).err(), Some(Refusal::Full));
    }

    #[test]
    fn a_trusted_proxy_is_not_capped_but_its_clients_are() {
        let proxies = TrustedProxies::new(
            vec![Cidr::parse("127.0.0.1").unwrap()],
            gridscada_config::ForwardedHeader::default(),
        );
        let c = Arc::new(Connections::new(limits(100, 2), proxies));
        let tickets: Vec<_> = (0..5).map(|_| c.admit(ip("127.0.0.1")).unwrap()).collect();
        assert!(tickets
            .iter()
            .all(|t| !t.state.closing.load(Ordering::Acquire)));
        let s1 = c.take_proxied_slot(ip("203.0.113.7")).unwrap();
        let _s2 = c.take_proxied_slot(ip("203.0.113.7")).unwrap();
        assert!(c.take_proxied_slot(ip("203.0.113.7")).is_none());
        assert!(c.take_proxied_slot(ip("203.0.113.8")).is_some());
        drop(s1);
        assert!(c.take_proxied_slot(ip("203.0.113.7")).is_some());
    }
}
