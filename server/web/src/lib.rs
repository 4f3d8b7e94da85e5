//! # gridscada-web: the only door into the plant from the network
//!
//! **Owns:** the HTTP API (JSON), sessions and access control, the `/api/live`
//! WebSocket push, and serving the HMI's static files embedded at compile time.
//!
//! **Must not touch:** Modbus, SQL or control logic. It reads the tag database,
//! asks the alarm engine, the store and the control loops through the handles in
//! [`WebState`], and sends commands through `TagWriter`. Every route declares its
//! permission in one table ([`routes::table`]); anything not declared is denied.

pub mod access;
pub mod api;
pub mod auth;
pub mod command;
pub mod error;
mod hmi;
pub mod listener;
pub mod metrics;
pub mod openapi;
pub mod proxy;
pub mod routes;
pub mod tls;

use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Instant;

use axum::Router;
use gridscada_config::Plant;
use gridscada_store::Store;
use gridscada_tagdb::{Clock, TagDb, TagWriter};

pub use api::network::NetworkView;
pub use api::Components;
pub use auth::Auth;
pub use proxy::ClientInfo;

/// What the HTTP layer can reach.
#[derive(Clone)]
pub struct WebState {
    pub db: Arc<TagDb>,
    pub plant: Arc<Plant>,
    pub store: Store,
    /// The audit trail (stored, or spooled while the store is away);
    /// `None` writes audit records straight to the store.
    pub audit: Option<gridscada_store::AuditHandle>,
    pub auth: Auth,
    pub clock: Arc<dyn Clock>,
    /// Commands to the field; `None` when no field I/O runs.
    pub writer: Option<Arc<dyn TagWriter>>,
    pub started: Instant,
    /// The alarm engine, panels, dispatch and simulator, where running.
    pub components: Components,
    /// Fault injection: only in `demo` and `replay`.
    pub sim: Option<Arc<dyn api::sim::SimControl>>,
    /// HTTP counters for `/metrics`.
    pub http_metrics: Arc<metrics::HttpMetrics>,
    /// The application's own figures for `/metrics` (poller, historian).
    pub metrics: Option<Arc<dyn metrics::MetricsSource>>,
    /// The screens users drew, as last saved.
    pub screens: Arc<access::ScreenLibrary>,
    /// Communication figures of the field devices, where field I/O runs.
    pub devices: Option<Arc<dyn api::devices::DeviceSource>>,
    /// This server itself speaks HTTPS (`[server.tls]`): responses carry
    /// HSTS. (Cookies are `Secure` through [`Auth::secure_cookies`].)
    pub tls: bool,
    /// The live push's shared feeds (`/api/live`); start with the default.
    pub live: Arc<api::live::LiveFeeds>,
    /// The listeners' open connections and their limits
    /// (`[server.connections]`), for `/metrics`; hand the same one to
    /// [`bind`].
    pub connections: Arc<listener::Connections>,
}

/// The application's routes.
pub fn router(state: WebState) -> Router {
    routes::build(state)
}

/// Binds `addr` now (so the caller can report a bind error before printing
/// the URL) and returns the listener's actual address with a server future
/// that serves plain HTTP under `connections`' limits.
pub async fn bind(
    addr: SocketAddr,
    router: Router,
    connections: Arc<listener::Connections>,
) -> std::io::Result<(
    SocketAddr,
    impl std::future::Future<Output = std::io::Result<()>>,
)> {
    let listener = tokio::net::TcpListener::bind(addr).await?;
    let local = listener.local_addr()?;
    let fut = listener::serve(listener, router, connections, listener::Transport::Plain);
    Ok((local, fut))
}
