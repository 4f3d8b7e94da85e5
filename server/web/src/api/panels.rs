//! Panels: the fault-isolation status of each panel, and its commands.

use axum::extract::{Path, State};
use axum::http::StatusCode;
use axum::{Extension, Json};
use gridscada_control::fault_isolation::{
    CommandError, Mode, PanelCommand, PanelCommandKind, PanelStatus,
};
use serde::{Deserialize, Serialize};
use serde_json::{json, Value};
use tokio::sync::{mpsc, oneshot, watch};
use utoipa::ToSchema;

use crate::auth::Principal;
use crate::error::{ApiError, ApiResult};
use crate::openapi::shapes;
use crate::WebState;

/// One running panel sequence, as the web layer reaches it.
#[derive(Clone)]
pub struct PanelHandle {
    pub id: String,
    pub status: watch::Receiver<PanelStatus>,
    pub commands: mpsc::Sender<PanelCommand>,
}

/// A panel's status as the API shows it: the sequence's status plus the
/// panel's tag prefix, so a screen can find the panel's tags.
fn view(s: &WebState, status: &PanelStatus) -> Value {
    let mut v = serde_json::to_value(status).unwrap_or_default();
    if let Some(p) = s.plant.panels.iter().find(|p| *p.id.get_ref() == status.id) {
        v["prefix"] = json!(p.prefix.get_ref());
        if let Some(net) = &s.components.network {
            v["safety_tags"] = safety_tags(net, p);
        }
    }
    v
}

/// The standing safety tags on the panel's breakers that are switching
/// devices of the network, by breaker ("elcb", "mccb", "zone2"): the
/// strongest tag's label and every tag in words, so the diagrams flag a
/// tagged breaker as the network screen does.
fn safety_tags(
    net: &crate::api::network::NetworkView,
    panel: &gridscada_config::PanelConfig,
) -> Value {
    use gridscada_config::StatusBinding;
    let io = panel.io();
    let breaker_of = |tag: &str| -> Option<String> {
        if tag == io.elcb_closed {
            return Some("elcb".into());
        }
        if tag == io.mccb_closed {
            return Some("mccb".into());
        }
        let z = io.zone_closed.iter().position(|z| z == tag)?;
        Some(format!("zone{}", z + 1))
    };
    let mut out = serde_json::Map::new();
    for (w, status) in net.network.model.switches.iter().zip(&net.network.status) {
        let Some(StatusBinding::Tag(tag)) = status else {
            continue;
        };
        let Some(breaker) = breaker_of(tag) else {
            continue;
        };
        let Some(strongest) = net.tags.strongest(&w.id) else {
            continue;
        };
        let texts: Vec<String> = net.tags.on(&w.id).iter().map(|t| t.describe()).collect();
        out.insert(
            breaker,
            json!({ "device": w.id, "kind": strongest.as_str(), "label": strongest.label(), "tags": texts }),
        );
    }
    Value::Object(out)
}

fn find<'a>(s: &'a WebState, id: &str) -> ApiResult<&'a PanelHandle> {
    s.components
        .panels
        .iter()
        .find(|p| p.id == id)
        .ok_or_else(|| ApiError::not_found(format!("no panel '{id}'")))
}

/// A panel's screen is its id; the main screen shows every panel.
fn may_view(who: &Principal, id: &str) -> ApiResult<()> {
    if who.may_open(id) || who.may_open("main") {
        Ok(())
    } else {
        Err(ApiError::forbidden(format!(
            "your group may not open the {id} screen"
        )))
    }
}

/// The panels the caller may view.
#[derive(Serialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct PanelList {
    #[schema(value_type = Vec<shapes::PanelStatus>)]
    pub panels: Vec<Value>,
}

const PANEL_ID: &str = "Panel id";

#[utoipa::path(get, path = "/api/panels", tag = "panels", summary = "Panels' fault-isolation status",
    responses((status = 200, description = "OK", body = inline(PanelList))))]
pub async fn list(
    State(s): State<WebState>,
    Extension(who): Extension<Principal>,
) -> Json<PanelList> {
    let panels: Vec<Value> = s
        .components
        .panels
        .iter()
        .filter(|p| may_view(&who, &p.id).is_ok())
        .map(|p| view(&s, &p.status.borrow()))
        .collect();
    Json(PanelList { panels })
}

#[utoipa::path(get, path = "/api/panels/{id}", tag = "panels", summary = "One panel",
    params(("id" = String, Path, description = PANEL_ID, min_length = 1)),
    responses((status = 200, description = "OK", body = shapes::PanelStatus),
        (status = 400), (status = 404)))]
pub async fn one(
    State(s): State<WebState>,
    Extension(who): Extension<Principal>,
    Path(id): Path<String>,
) -> ApiResult<Json<Value>> {
    let p = find(&s, &id)?;
    may_view(&who, &id)?;
    let status = view(&s, &p.status.borrow());
    Ok(Json(status))
}

async fn send(s: &WebState, who: &Principal, id: &str, kind: PanelCommandKind) -> ApiResult<()> {
    let p = find(s, id)?;
    may_view(who, id)?;
    crate::api::pair::active_ready(s)?;
    // The sequence records the command through the audit trail: it goes
    // out only if that record can be made durable.
    crate::api::audit_ready(s).await?;
    let (reply, answer) = oneshot::channel();
    let cmd = PanelCommand {
        user: who.audit_name(),
        kind,
        reply,
    };
    p.commands.send(cmd).await.map_err(|_| {
        ApiError::unavailable(format!("the sequence of panel '{id}' is not running"))
    })?;
    match answer.await {
        Ok(Ok(())) => Ok(()),
        Ok(Err(e)) => Err(refusal(e)),
        Err(_) => Err(ApiError::unavailable(format!(
            "the sequence of panel '{id}' stopped"
        ))),
    }
}

fn refusal(e: CommandError) -> ApiError {
    let status = match e {
        CommandError::UnknownBreaker { .. } => StatusCode::NOT_FOUND,
        CommandError::CommLost | CommandError::Standby(_) => StatusCode::SERVICE_UNAVAILABLE,
        _ => StatusCode::CONFLICT,
    };
    ApiError::new(status, "refused", e.to_string())
}

type JsonBody<T> = Result<Json<T>, axum::extract::rejection::JsonRejection>;

#[derive(Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct ModeBody {
    #[schema(value_type = shapes::PanelMode, inline)]
    pub mode: Mode,
}

#[utoipa::path(post, path = "/api/panels/{id}/mode", tag = "panels", summary = "Set auto or manual mode",
    params(("id" = String, Path, description = PANEL_ID, min_length = 1)),
    request_body = ModeBody,
    responses((status = 200, description = "OK", body = shapes::PanelStatus),
        (status = 400), (status = 404), (status = 409), (status = 503)))]
pub async fn mode(
    State(s): State<WebState>,
    Extension(who): Extension<Principal>,
    Path(id): Path<String>,
    body: JsonBody<ModeBody>,
) -> ApiResult<Json<Value>> {
    let Json(b) = body.map_err(|e| ApiError::bad_request(e.body_text()))?;
    // The panel's sequence records each command with its user (one audit
    // record per action, refusals included).
    send(&s, &who, &id, PanelCommandKind::SetMode(b.mode)).await?;
    current(&s, &id).await
}

#[utoipa::path(post, path = "/api/panels/{id}/reset", tag = "panels",
    summary = "Reset (acknowledge a lockout)",
    params(("id" = String, Path, description = PANEL_ID, min_length = 1)),
    responses((status = 200, description = "OK", body = shapes::PanelStatus),
        (status = 400), (status = 404), (status = 409), (status = 503)))]
pub async fn reset(
    State(s): State<WebState>,
    Extension(who): Extension<Principal>,
    Path(id): Path<String>,
) -> ApiResult<Json<Value>> {
    send(&s, &who, &id, PanelCommandKind::Reset).await?;
    current(&s, &id).await
}

#[derive(Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct BreakerBody {
    pub closed: bool,
}

#[utoipa::path(post, path = "/api/panels/{id}/breakers/{breaker}", tag = "panels",
    summary = "Open or close a breaker (manual mode)",
    params(
        ("id" = String, Path, description = PANEL_ID, min_length = 1),
        ("breaker" = String, Path, description = "elcb, mccb, zone1..zoneN", min_length = 1),
    ),
    request_body = BreakerBody,
    responses((status = 200, description = "OK", body = shapes::PanelStatus),
        (status = 400), (status = 404), (status = 409), (status = 503)))]
pub async fn breaker(
    State(s): State<WebState>,
    Extension(who): Extension<Principal>,
    Path((id, breaker)): Path<(String, String)>,
    body: JsonBody<BreakerBody>,
) -> ApiResult<Json<Value>> {
    let Json(b) = body.map_err(|e| ApiError::bad_request(e.body_text()))?;
    let kind = PanelCommandKind::Breaker {
        breaker,
        close: b.closed,
    };
    send(&s, &who, &id, kind).await?;
    current(&s, &id).await
}

/// The status after a command, once the sequence has published it.
async fn current(s: &WebState, id: &str) -> ApiResult<Json<Value>> {
    let p = find(s, id)?;
    let status = view(s, &p.status.borrow());
    Ok(Json(status))
}
