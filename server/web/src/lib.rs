//! # gridscada-web: the only door into the plant from the network
//!
//! **Owns:** the HTTP API (JSON), sessions and access control, the `/api/live`
//! WebSocket push, and serving the HMI's static files embedded at compile time.
//!
//! **Must not touch:** Modbus, SQL or control logic. It reads the tag database,
//! asks the alarm engine, the store and the control loops through the handles in
//! [`WebState`], and sends commands through `TagWriter`. Every route declares its
//! permission in one table; anything not declared is denied.

use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Instant;

use axum::extract::State;
use axum::routing::get;
use axum::{Json, Router};
use gridscada_tagdb::TagDb;
use serde_json::json;

/// What the HTTP layer can reach.
#[derive(Clone)]
pub struct WebState {
    pub db: Arc<TagDb>,
    pub started: Instant,
}

/// The application's routes.
pub fn router(state: WebState) -> Router {
    Router::new()
        .route("/healthz", get(healthz))
        .with_state(state)
}

/// Liveness and a one-line picture of the server, for load balancers and the
/// commissioning engineer's `curl`.
async fn healthz(State(s): State<WebState>) -> Json<serde_json::Value> {
    Json(json!({
        "status": "ok",
        "version": env!("CARGO_PKG_VERSION"),
        "tags": s.db.len(),
        "uptime_s": s.started.elapsed().as_secs(),
    }))
}

/// Binds `addr` now (so the caller can report a bind error before printing
/// the URL) and returns the listener's actual address with a server future.
pub async fn bind(
    addr: SocketAddr,
    router: Router,
) -> std::io::Result<(
    SocketAddr,
    impl std::future::Future<Output = std::io::Result<()>>,
)> {
    let listener = tokio::net::TcpListener::bind(addr).await?;
    let local = listener.local_addr()?;
    let fut = async move {
        axum::serve(
            listener,
            router.into_make_service_with_connect_info::<SocketAddr>(),
        )
        .await
    };
    Ok((local, fut))
}
