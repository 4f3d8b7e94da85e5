//! Health, metrics and the OpenAPI document.

use axum::extract::State;
use axum::http::{header, HeaderMap, StatusCode};
use axum::response::IntoResponse;
use axum::Json;
use serde::Serialize;
use utoipa::ToSchema;

use crate::error::ApiError;
use crate::WebState;

/// Who may scrape `/metrics` (it names every device and which one is down):
/// with `[server] metrics_token`, a client sending `Authorization: Bearer
/// TOKEN`; the addresses in `metrics_allow`; loopback clients when no token
/// is set; anyone in the demo.
fn metrics_allowed(
    s: &WebState,
    ip: Option<std::net::IpAddr>,
    headers: &HeaderMap,
) -> Result<(), ApiError> {
    if s.auth.metrics_open {
        return Ok(());
    }
    let cfg = &s.plant.server;
    if ip.is_some_and(|ip| cfg.metrics_allow.contains(&ip)) {
        return Ok(());
    }
    match cfg.metrics_token.as_deref() {
        Some(token) => {
            let sent = headers
                .get(header::AUTHORIZATION)
                .and_then(|v| v.to_str().ok())
                .and_then(|v| v.strip_prefix("Bearer "))
                .unwrap_or("");
            // Compared in constant time.
            let same = sent.len() == token.len()
                && sent
                    .bytes()
                    .zip(token.bytes())
                    .fold(0u8, |acc, (a, b)| acc | (a ^ b))
                    == 0;
            if same {
                Ok(())
            } else {
                Err(ApiError::new(
                    StatusCode::UNAUTHORIZED,
                    "unauthorized",
                    "/metrics needs Authorization: Bearer <metrics_token>",
                ))
            }
        }
        None if ip.is_some_and(|ip| ip.is_loopback()) => Ok(()),
        None => Err(ApiError::forbidden(
            "/metrics answers loopback clients only; set [server] metrics_token or metrics_allow",
        )),
    }
}

#[derive(Serialize, ToSchema, PartialEq)]
#[serde(rename_all = "lowercase")]
pub enum HealthStatus {
    /// Everything answers.
    Ok,
    /// The server works, but a field device does not answer or the
    /// historian's buffer is full (samples are being dropped).
    Degraded,
    /// The store does not answer: nothing can be recorded.
    Failing,
}

#[derive(Serialize, ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum DatabaseStatus {
    Ok,
    Unreachable,
}

/// Field I/O: how many devices answer.
#[derive(Serialize, ToSchema)]
pub struct FieldIoHealth {
    /// Devices that answer (their values are Good).
    pub good: usize,
    pub total: usize,
    /// The devices that do not answer.
    pub not_good: Vec<String>,
}

/// The historian's write buffer.
#[derive(Serialize, ToSchema)]
pub struct HistorianHealth {
    /// Samples waiting to be written.
    pub queued: u64,
    pub capacity: u64,
    /// Samples lost since start (mostly: dropped because the buffer was full).
    pub dropped: u64,
    /// The buffer overflowed and has not drained below half since: samples
    /// are being lost now.
    pub overflow: bool,
}

/// The server at a glance.
#[derive(Serialize, ToSchema)]
pub struct Health {
    #[schema(inline)]
    pub status: HealthStatus,
    pub version: &'static str,
    pub tags: usize,
    #[schema(inline)]
    pub database: DatabaseStatus,
    pub uptime_s: u64,
    /// Absent where no field I/O runs.
    #[serde(skip_serializing_if = "Option::is_none")]
    #[schema(inline)]
    pub field_io: Option<FieldIoHealth>,
    /// Absent where no historian runs.
    #[serde(skip_serializing_if = "Option::is_none")]
    #[schema(inline)]
    pub historian: Option<HistorianHealth>,
}

/// How long a health check waits for the store: a probe must answer even
/// when the database hangs.
const STORE_CHECK: std::time::Duration = std::time::Duration::from_secs(2);

async fn store_answers(s: &WebState) -> bool {
    matches!(
        tokio::time::timeout(STORE_CHECK, s.store.ping()).await,
        Ok(Ok(()))
    )
}

/// Liveness and a picture of the server: the store, field I/O and the
/// historian's backlog. Answers 200 while the store answers, even with
/// devices down (`status: degraded`): restarting the server would not bring
/// a device back. Answers 503 (`status: failing`) when the store does not
/// answer.
#[utoipa::path(get, path = "/healthz", tag = "server", summary = "Health",
    responses(
        (status = 200, description = "The store answers; `status` says whether field I/O and the historian are well", body = inline(Health)),
        (status = 503, description = "The store does not answer", body = inline(Health))))]
pub async fn healthz(State(s): State<WebState>) -> (StatusCode, Json<Health>) {
    let db_ok = store_answers(&s).await;
    let stack = s.metrics.as_ref().map(|m| m.health()).unwrap_or_default();
    let field_io = stack.field_io.map(|f| FieldIoHealth {
        good: f.total - f.not_good.len().min(f.total),
        total: f.total,
        not_good: f.not_good,
    });
    let historian = stack.historian.map(|h| HistorianHealth {
        queued: h.queued,
        capacity: h.capacity,
        dropped: h.dropped,
        overflow: h.overflow,
    });
    let devices_down = field_io.as_ref().is_some_and(|f| !f.not_good.is_empty());
    let historian_full = historian
        .as_ref()
        .is_some_and(|h| h.overflow || (h.capacity > 0 && h.queued >= h.capacity));
    let status = if !db_ok {
        HealthStatus::Failing
    } else if devices_down || historian_full {
        HealthStatus::Degraded
    } else {
        HealthStatus::Ok
    };
    let code = if status == HealthStatus::Failing {
        StatusCode::SERVICE_UNAVAILABLE
    } else {
        StatusCode::OK
    };
    (
        code,
        Json(Health {
            status,
            version: env!("CARGO_PKG_VERSION"),
            tags: s.db.len(),
            database: if db_ok {
                DatabaseStatus::Ok
            } else {
                DatabaseStatus::Unreachable
            },
            uptime_s: s.started.elapsed().as_secs(),
            field_io,
            historian,
        }),
    )
}

/// Readiness for a load balancer: 200 `ready` once the server serves (it
/// answers only after the whole stack has started) and its store answers;
/// 503 otherwise (the API's JSON error, like every refusal). Field devices
/// do not count: a server with a device down still serves the plant.
#[utoipa::path(get, path = "/readyz", tag = "server", summary = "Readiness",
    responses(
        (status = 200, description = "Ready", body = String, content_type = "text/plain"),
        (status = 503)))]
pub async fn readyz(
    State(s): State<WebState>,
) -> (
    StatusCode,
    [(header::HeaderName, &'static str); 2],
    &'static str,
) {
    let headers = [
        (header::CONTENT_TYPE, "text/plain; charset=utf-8"),
        (header::CACHE_CONTROL, "no-store"),
    ];
    if store_answers(&s).await {
        (StatusCode::OK, headers, "ready\n")
    } else {
        // Turned into the API's JSON error by `routes::json_errors`.
        (
            StatusCode::SERVICE_UNAVAILABLE,
            headers,
            "not ready: the store does not answer",
        )
    }
}

/// The version this binary was built from, and with what.
fn build_info(out: &mut crate::metrics::Prom) {
    let mut labels = vec![("version", env!("CARGO_PKG_VERSION"))];
    if let Some(commit) = option_env!("GRIDSCADA_COMMIT").filter(|c| !c.is_empty()) {
        labels.push(("commit", commit));
    }
    let rustc = env!("GRIDSCADA_RUSTC");
    if !rustc.is_empty() {
        labels.push(("rustc", rustc));
    }
    out.gauge(
        "gridscada_build_info",
        "Always 1; the labels name the build.",
        &labels,
        1.0,
    );
}

/// OpenMetrics text exposition: build, process, server, tag database, HTTP,
/// alarms, and the application's poller and historian figures.
#[utoipa::path(get, path = "/metrics", tag = "server", summary = "Prometheus metrics",
    responses((status = 200, description = "OpenMetrics text", body = String, content_type = "application/openmetrics-text")))]
pub async fn metrics(
    State(s): State<WebState>,
    axum::Extension(client): axum::Extension<crate::ClientInfo>,
    headers: HeaderMap,
) -> Result<impl IntoResponse, ApiError> {
    metrics_allowed(&s, Some(client.ip), &headers)?;
    let mut out = crate::metrics::Prom::default();
    build_info(&mut out);
    crate::metrics::render_process(&mut out);
    out.gauge(
        "gridscada_uptime_seconds",
        "Seconds since the server started.",
        &[],
        s.started.elapsed().as_secs_f64(),
    );
    out.gauge(
        "gridscada_tags",
        "Tags in the tag database.",
        &[],
        s.db.len() as f64,
    );
    out.counter(
        "gridscada_tagdb_batches_total",
        "Changing batches applied to the tag database.",
        &[],
        s.db.seq() as f64,
    );
    s.http_metrics.render(&mut out);
    s.connections.render(&mut out);
    if let Some(a) = &s.components.alarms {
        let st = a.stats();
        let g = [
            ("configured", st.alarms),
            ("active", st.active),
            ("unacked", st.unacked),
            ("shelved", st.shelved),
            ("suppressed", st.suppressed),
            ("out_of_service", st.out_of_service),
        ];
        for (which, n) in g {
            out.gauge(
                "gridscada_alarms",
                "Alarms by condition.",
                &[("which", which)],
                n as f64,
            );
        }
        out.counter(
            "gridscada_alarm_evaluations_total",
            "Alarm condition evaluations.",
            &[],
            st.evaluations_total as f64,
        );
        out.counter(
            "gridscada_alarm_evaluation_seconds_total",
            "Time spent evaluating alarm conditions and timers.",
            &[],
            st.evaluation_nanos_total as f64 / 1e9,
        );
        out.counter(
            "gridscada_alarm_transitions_total",
            "Alarm state transitions.",
            &[],
            st.transitions_total as f64,
        );
        out.gauge(
            "gridscada_alarm_queued_outputs",
            "Alarm records waiting for the store.",
            &[],
            st.queued_outputs as f64,
        );
    }
    if let Some(m) = &s.metrics {
        m.render(&mut out);
    }
    Ok((
        [(header::CONTENT_TYPE, crate::metrics::CONTENT_TYPE)],
        out.finish(),
    ))
}

/// The OpenAPI document of the API, generated (see [`crate::openapi`]).
#[utoipa::path(get, path = "/api/openapi.json", tag = "server", summary = "This document",
    responses((status = 200, description = "OK", body = Object)))]
pub async fn openapi(State(s): State<WebState>) -> impl IntoResponse {
    let base = s.plant.server.base_path();
    let text = if base.is_empty() {
        crate::openapi::document_text().to_string()
    } else {
        // Served under [server] base_path: the API is there.
        let mut doc = crate::openapi::document().clone();
        doc["servers"] = serde_json::json!([{ "url": format!("{base}/") }]);
        doc.to_string()
    };
    ([(header::CONTENT_TYPE, "application/json")], text)
}
