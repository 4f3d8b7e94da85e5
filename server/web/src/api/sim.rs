//! Fault injection for trainers and tests: only in `demo` and `replay`, and
//! only for administrators. `serve` has no such routes at all.

use axum::extract::{Path, State};
use axum::http::StatusCode;
use axum::{Extension, Json};
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use crate::api::audit;
use crate::auth::Principal;
use crate::error::{ApiError, ApiResult};
use crate::WebState;

/// A zone fault that clears by itself when it trips the ELCB, or one that
/// stays until repaired.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize, ToSchema)]
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

#[derive(Deserialize, Serialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct FaultBody {
    pub panel: String,
    pub zone: u8,
    #[schema(inline)]
    pub kind: FaultKind,
}

#[utoipa::path(post, path = "/api/sim/faults", tag = "simulation",
    summary = "Inject a zone fault (demo and replay only)",
    request_body = FaultBody,
    responses((status = 201, description = "Injected", body = inline(FaultBody)),
        (status = 400), (status = 404), (status = 503, description = "Its audit record could be neither stored nor spooled")))]
pub async fn inject_fault(
    State(s): State<WebState>,
    Extension(who): Extension<Principal>,
    body: Result<Json<FaultBody>, axum::extract::rejection::JsonRejection>,
) -> ApiResult<(StatusCode, Json<FaultBody>)> {
    let Json(b) = body.map_err(|e| ApiError::bad_request(e.body_text()))?;
    crate::api::audit_ready(&s).await?;
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
    Ok((StatusCode::CREATED, Json(b)))
}

#[utoipa::path(delete, path = "/api/sim/faults/{panel}/{zone}", tag = "simulation",
    summary = "Repair a zone fault",
    params(("panel" = String, Path, min_length = 1), ("zone" = u8, Path)),
    responses((status = 204, description = "Repaired"), (status = 400), (status = 404), (status = 503, description = "Its audit record could be neither stored nor spooled")))]
pub async fn repair(
    State(s): State<WebState>,
    Extension(who): Extension<Principal>,
    Path((panel, zone)): Path<(String, u8)>,
) -> ApiResult<StatusCode> {
    crate::api::audit_ready(&s).await?;
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
) -> ApiResult<Json<DeviceState>> {
    crate::api::audit_ready(&s).await?;
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
    Ok(Json(DeviceState { device, offline }))
}

/// A simulated device and whether it is off line.
#[derive(Serialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct DeviceState {
    pub device: String,
    pub offline: bool,
}

#[utoipa::path(post, path = "/api/sim/devices/{device}/offline", tag = "simulation",
    summary = "Take a simulated device offline",
    params(("device" = String, Path, min_length = 1)),
    responses((status = 200, description = "OK", body = inline(DeviceState)), (status = 400), (status = 404), (status = 503, description = "Its audit record could be neither stored nor spooled")))]
pub async fn offline(
    State(s): State<WebState>,
    Extension(who): Extension<Principal>,
    Path(device): Path<String>,
) -> ApiResult<Json<DeviceState>> {
    set_offline(s, who, device, true).await
}

#[utoipa::path(post, path = "/api/sim/devices/{device}/online", tag = "simulation",
    summary = "Take a simulated device online",
    params(("device" = String, Path, min_length = 1)),
    responses((status = 200, description = "OK", body = inline(DeviceState)), (status = 400), (status = 404), (status = 503, description = "Its audit record could be neither stored nor spooled")))]
pub async fn online(
    State(s): State<WebState>,
    Extension(who): Extension<Principal>,
    Path(device): Path<String>,
) -> ApiResult<Json<DeviceState>> {
    set_offline(s, who, device, false).await
}
