//! Dispatch: the latest outer-loop result and its history.

use axum::extract::{Query, State};
use axum::Json;
use gridscada_control::dispatch::DispatchStatus;
use gridscada_tagdb::Timestamp;
use serde::{Deserialize, Serialize};
use utoipa::{IntoParams, ToSchema};

use crate::api::parse_time;
use crate::error::{ApiError, ApiResult};
use crate::openapi::shapes;
use crate::WebState;

#[utoipa::path(get, path = "/api/dispatch", tag = "dispatch", summary = "Latest microgrid dispatch",
    responses((status = 200, description = "OK", body = shapes::DispatchStatus), (status = 503)))]
pub async fn latest(State(s): State<WebState>) -> ApiResult<Json<DispatchStatus>> {
    let rx = s
        .components
        .dispatch
        .as_ref()
        .ok_or_else(|| ApiError::unavailable("this plant has no microgrid dispatch"))?;
    let status = rx.borrow().clone();
    Ok(Json(status))
}

#[derive(Deserialize, Default, IntoParams)]
#[into_params(parameter_in = Query)]
#[serde(deny_unknown_fields)]
pub struct HistoryQuery {
    #[param(schema_with = shapes::time, required = false)]
    pub from: Option<String>,
    #[param(schema_with = shapes::time, required = false)]
    pub to: Option<String>,
    pub limit: Option<u32>,
    /// Another site on the same database whose history to read
    /// (read-only); this server's own site if absent (`GET /api/sites`).
    pub site: Option<String>,
}

/// Recorded dispatches.
#[derive(Serialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct DispatchHistory {
    #[schema(value_type = Vec<shapes::DispatchRecord>)]
    pub dispatches: Vec<gridscada_store::DispatchRecord>,
    pub count: usize,
}

#[utoipa::path(get, path = "/api/dispatch/history", tag = "dispatch", summary = "Dispatch history",
    params(HistoryQuery),
    responses((status = 200, description = "OK", body = inline(DispatchHistory)), (status = 400),
        (status = 404, description = "No such site")))]
pub async fn history(
    State(s): State<WebState>,
    Query(q): Query<HistoryQuery>,
) -> ApiResult<Json<DispatchHistory>> {
    let (from, to) = history_range(&s, &q)?;
    let rows = crate::api::history_of(&s, q.site.as_deref())
        .await?
        .dispatch_history(from, to, q.limit.unwrap_or(500).clamp(1, 10_000))
        .await?;
    Ok(Json(DispatchHistory {
        count: rows.len(),
        dispatches: rows,
    }))
}

/// The dispatch history as CSV (the setpoints as JSON text), with the
/// list's range (no row cap, `limit` ignored), newest first, streamed.
#[utoipa::path(get, path = "/api/dispatch/history.csv", tag = "dispatch", summary = "Dispatch history as CSV",
    params(HistoryQuery),
    responses((status = 200, description = "CSV", body = String, content_type = "text/csv"), (status = 400),
        (status = 404, description = "No such site")))]
pub async fn history_csv(
    State(s): State<WebState>,
    Query(q): Query<HistoryQuery>,
) -> ApiResult<axum::response::Response> {
    let (from, to) = history_range(&s, &q)?;
    let store = crate::api::history_of(&s, q.site.as_deref()).await?;
    Ok(crate::api::csv_download(
        "dispatch-history.csv",
        "dispatch CSV export",
        move |mut tx| async move { store.export_dispatches_csv(from, to, &mut tx).await },
    ))
}

/// `from..to` of a history request: the last hour by default.
fn history_range(s: &WebState, q: &HistoryQuery) -> ApiResult<(Timestamp, Timestamp)> {
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
    Ok((from, to))
}

/// The microgrid's units as configured (names, kinds, ratings), for the
/// overview and per-unit screens.
/// The microgrid's units, its demand tag and the prefix of its load tags.
#[derive(Serialize, ToSchema)]
pub struct Units {
    #[schema(value_type = Vec<shapes::MicrogridUnit>)]
    pub units: Vec<gridscada_config::UnitConfig>,
    pub demand_tag: String,
    pub load_prefix: String,
}

#[utoipa::path(get, path = "/api/microgrid/units", tag = "dispatch",
    summary = "The microgrid units as configured",
    responses((status = 200, description = "OK", body = inline(Units)), (status = 503)))]
pub async fn units(State(s): State<WebState>) -> ApiResult<Json<Units>> {
    let mg = s
        .plant
        .microgrid
        .as_ref()
        .ok_or_else(|| ApiError::unavailable("this plant has no microgrid"))?;
    let demand = mg.demand_tag.get_ref();
    let load_prefix = demand.rsplit_once('.').map(|(p, _)| p).unwrap_or_default();
    Ok(Json(Units {
        units: mg.units.clone(),
        demand_tag: demand.clone(),
        load_prefix: load_prefix.to_string(),
    }))
}
