//! Health, metrics and the OpenAPI document.

use axum::extract::State;
use axum::http::header;
use axum::response::IntoResponse;
use axum::Json;
use serde_json::json;

use crate::WebState;

/// Liveness and a one-line picture of the server.
pub async fn healthz(State(s): State<WebState>) -> Json<serde_json::Value> {
    let db_ok = s.store.ping().await.is_ok();
    Json(json!({
        "status": if db_ok { "ok" } else { "degraded" },
        "version": env!("CARGO_PKG_VERSION"),
        "tags": s.db.len(),
        "database": if db_ok { "ok" } else { "unreachable" },
        "uptime_s": s.started.elapsed().as_secs(),
    }))
}

/// Prometheus text exposition.
pub async fn metrics(State(s): State<WebState>) -> impl IntoResponse {
    let mut out = String::new();
    let mut gauge = |name: &str, help: &str, value: f64| {
        out.push_str(&format!(
            "# HELP {name} {help}\n# TYPE {name} gauge\n{name} {value}\n"
        ));
    };
    gauge(
        "gridscada_uptime_seconds",
        "Seconds since the server started.",
        s.started.elapsed().as_secs_f64(),
    );
    gauge(
        "gridscada_tags",
        "Tags in the tag database.",
        s.db.len() as f64,
    );
    gauge(
        "gridscada_tagdb_batches_total",
        "Changing batches applied to the tag database.",
        s.db.seq() as f64,
    );
    ([(header::CONTENT_TYPE, "text/plain; version=0.0.4")], out)
}

/// The OpenAPI document of the API.
pub async fn openapi() -> impl IntoResponse {
    (
        [(header::CONTENT_TYPE, "application/json")],
        include_str!("../../openapi.json"),
    )
}
