//! Dispatch: the latest outer-loop result and its history.

use axum::extract::{Query, State};
use axum::Json;
use gridscada_control::dispatch::DispatchStatus;
use gridscada_tagdb::Timestamp;
use serde::Deserialize;
use serde_json::{json, Value};

use crate::api::parse_time;
use crate::error::{ApiError, ApiResult};
use crate::WebState;

pub async fn latest(State(s): State<WebState>) -> ApiResult<Json<DispatchStatus>> {
    let rx = s
        .components
        .dispatch
        .as_ref()
        .ok_or_else(|| ApiError::unavailable("this plant has no microgrid dispatch"))?;
    let status = rx.borrow().clone();
    Ok(Json(status))
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct HistoryQuery {
    pub from: Option<String>,
    pub to: Option<String>,
    pub limit: Option<u32>,
}

pub async fn history(
    State(s): State<WebState>,
    Query(q): Query<HistoryQuery>,
) -> ApiResult<Json<Value>> {
    let to = match q.to.as_deref().filter(|v| !v.is_empty()) {
        Some(v) => parse_time("to", v)?,
        None => s.clock.now(),
    };
    let from = match q.from.as_deref().filter(|v| !v.is_empty()) {
        Some(v) => parse_time("from", v)?,
        None => Timestamp::from_millis(to.as_millis().saturating_sub(3_600_000)),
    };
    if from > to {
        return Err(ApiError::bad_request("from must not be after to"));
    }
    let rows = s
        .store
        .dispatch_history(from, to, q.limit.unwrap_or(500).clamp(1, 10_000))
        .await?;
    Ok(Json(json!({ "dispatches": rows, "count": rows.len() })))
}

/// The microgrid's units as configured (names, kinds, ratings), for the
/// overview and per-unit screens.
pub async fn units(State(s): State<WebState>) -> ApiResult<Json<Value>> {
    let mg = s
        .plant
        .microgrid
        .as_ref()
        .ok_or_else(|| ApiError::unavailable("this plant has no microgrid"))?;
    let demand = mg.demand_tag.get_ref();
    let load_prefix = demand.rsplit_once('.').map(|(p, _)| p).unwrap_or_default();
    Ok(Json(json!({
        "units": mg.units,
        "demand_tag": demand,
        "load_prefix": load_prefix,
    })))
}
