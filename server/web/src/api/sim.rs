//! Fault injection for trainers and tests: only in `demo` and `replay`, and
//! only for administrators. `serve` has no such routes at all.

use axum::extract::{Path, State};
use axum::http::StatusCode;
use axum::{Extension, Json};
use serde::Deserialize;
use serde_json::{json, Value};

use crate::api::audit;
use crate::auth::Principal;
use crate::error::{ApiError, ApiResult};
use crate::WebState;

/// A zone fault that clears by itself when it trips the ELCB, or one that
/// stays until repaired.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum FaultKind {
    Permanent,
    Transient,
}

/// The simulator's control interface as the API needs it. Errors are
/// messages for the operator (unknown panel, zone out of range...).
pub trait SimControl: Send + Sync {
    fn inject_fault(&self, panel: &str, zone: u8, kind: FaultKind) -> Result<(), String>;
    fn repair(&self, panel: &str, zone: u8) -> Result<(), String>;
    fn set_offline(&self, device: &str, offline: bool) -> Result<(), String>;
}

fn sim(s: &WebState) -> ApiResult<&dyn SimControl> {
    s.sim
        .as_deref()
        .ok_or_else(|| ApiError::not_found("no simulator in this server"))
}

fn refused(e: String) -> ApiError {
    if e.contains("unknown")
        || e.contains("no panel")
        || e.contains("no device")
        || e.contains("not found")
    {
        ApiError::not_found(e)
    } else {
        ApiError::bad_request(e)
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FaultBody {
    pub panel: String,
    pub zone: u8,
    pub kind: FaultKind,
}

pub async fn inject_fault(
    State(s): State<WebState>,
    Extension(who): Extension<Principal>,
    body: Result<Json<FaultBody>, axum::extract::rejection::JsonRejection>,
) -> ApiResult<(StatusCode, Json<Value>)> {
    let Json(b) = body.map_err(|e| ApiError::bad_request(e.body_text()))?;
    sim(&s)?
        .inject_fault(&b.panel, b.zone, b.kind)
        .map_err(refused)?;
    let kind = match b.kind {
        FaultKind::Permanent => "permanent",
        FaultKind::Transient => "transient",
    };
    audit(
        &s,
        &who,
        "simulation",
        &b.panel,
        format!(
            "{} injected a {kind} fault on zone {} of panel {}",
            who.audit_name(),
            b.zone,
            b.panel
        ),
    )
    .await;
    Ok((
        StatusCode::CREATED,
        Json(json!({"panel": b.panel, "zone": b.zone, "kind": kind})),
    ))
}

pub async fn repair(
    State(s): State<WebState>,
    Extension(who): Extension<Principal>,
    Path((panel, zone)): Path<(String, u8)>,
) -> ApiResult<StatusCode> {
    sim(&s)?.repair(&panel, zone).map_err(refused)?;
    audit(
        &s,
        &who,
        "simulation",
        &panel,
        format!("{} repaired zone {zone} of panel {panel}", who.audit_name()),
    )
    .await;
    Ok(StatusCode::NO_CONTENT)
}

async fn set_offline(
    s: WebState,
    who: Principal,
    device: String,
    offline: bool,
) -> ApiResult<Json<Value>> {
    sim(&s)?.set_offline(&device, offline).map_err(refused)?;
    let what = if offline { "offline" } else { "online" };
    audit(
        &s,
        &who,
        "simulation",
        &device,
        format!("{} took simulated device {device} {what}", who.audit_name()),
    )
    .await;
    Ok(Json(json!({"device": device, "offline": offline})))
}

pub async fn offline(
    State(s): State<WebState>,
    Extension(who): Extension<Principal>,
    Path(device): Path<String>,
) -> ApiResult<Json<Value>> {
    set_offline(s, who, device, true).await
}

pub async fn online(
    State(s): State<WebState>,
    Extension(who): Extension<Principal>,
    Path(device): Path<String>,
) -> ApiResult<Json<Value>> {
    set_offline(s, who, device, false).await
}
