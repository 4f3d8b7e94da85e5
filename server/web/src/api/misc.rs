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

#[derive(Serialize, ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum HealthStatus {
    Ok,
    Degraded,
}

#[derive(Serialize, ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum DatabaseStatus {
    Ok,
    Unreachable,
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
}

/// Liveness and a one-line picture of the server.
#[utoipa::path(get, path = "/healthz", tag = "server", summary = "Liveness",
    responses((status = 200, description = "OK", body = inline(Health))))]
pub async fn healthz(State(s): State<WebState>) -> Json<Health> {
    let db_ok = s.store.ping().await.is_ok();
    Json(Health {
        status: if db_ok {
            HealthStatus::Ok
        } else {
            HealthStatus::Degraded
        },
        version: env!("CARGO_PKG_VERSION"),
        tags: s.db.len(),
        database: if db_ok {
            DatabaseStatus::Ok
        } else {
            DatabaseStatus::Unreachable
        },
        uptime_s: s.started.elapsed().as_secs(),
    })
}

/// Prometheus text exposition: server, tag database, HTTP, alarms, and the
/// application's poller and historian figures.
#[utoipa::path(get, path = "/metrics", tag = "server", summary = "Prometheus metrics",
    responses((status = 200, description = "Prometheus text", body = String, content_type = "text/plain")))]
pub async fn metrics(
    State(s): State<WebState>,
    axum::Extension(client): axum::Extension<crate::ClientInfo>,
    headers: HeaderMap,
) -> Result<impl IntoResponse, ApiError> {
    metrics_allowed(&s, Some(client.ip), &headers)?;
    let mut out = crate::metrics::Prom::default();
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
        [(header::CONTENT_TYPE, "text/plain; version=0.0.4")],
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
