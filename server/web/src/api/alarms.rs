//! Alarms: summary, acknowledge, shelve, history and ISA-18.2 metrics.
//!
//! Acknowledge and shelve are recorded by the alarm engine itself (a
//! transition naming the user, and an event), so they are not audited twice here.

use axum::extract::{Path, Query, State};
use axum::http::StatusCode;
use axum::{Extension, Json};
use gridscada_alarms::{AlarmEngine, AlarmError, AlarmFilter, AlarmId, AlarmState};
use gridscada_store::AlarmHistoryFilter;
use gridscada_tagdb::Timestamp;
use serde::{Deserialize, Serialize};
use serde_json::{json, Value};
use std::collections::BTreeMap;
use std::sync::Arc;
use utoipa::{IntoParams, ToSchema};

use crate::api::parse_time;
use crate::auth::Principal;
use crate::error::{ApiError, ApiResult};
use crate::openapi::shapes;
use crate::WebState;

fn engine(s: &WebState) -> ApiResult<&Arc<AlarmEngine>> {
    s.components
        .alarms
        .as_ref()
        .ok_or_else(|| ApiError::unavailable("the alarm engine is not running"))
}

/// Writes the new state of `ids` to the store before the API answers, so
/// an acknowledgement or shelving the operator was told about survives even
/// an immediate crash. (The engine's own state sink writes the same records
/// later; the store keeps whichever is newest.) While the store is down the
/// operation still stands: the engine has done it, its transition is in the
/// audit trail (spooled), and the state sink saves the state once the store
/// is back; the operator is not told it failed.
async fn persist(s: &WebState, e: &AlarmEngine, ids: &[AlarmId]) -> ApiResult<()> {
    let keys: Vec<String> = ids
        .iter()
        .filter_map(|id| e.view(*id))
        .map(|v| v.key)
        .collect();
    let records: Vec<_> = e
        .persisted_states()
        .into_iter()
        .filter(|r| keys.contains(&r.key))
        .collect();
    if !records.is_empty() {
        if let Err(e) = s.store.upsert_alarm_states(&records).await {
            tracing::warn!(error = %e, "alarm state not saved now; the state sink retries it");
        }
    }
    Ok(())
}

fn alarm_error(e: AlarmError) -> ApiError {
    let text = e.to_string();
    if text.contains("no alarm") || text.contains("unknown") {
        ApiError::not_found(text)
    } else {
        ApiError::bad_request(text)
    }
}

/// Filters as query parameters (the summary) or JSON (ack all).
#[derive(Deserialize, Default, Clone, IntoParams, ToSchema)]
#[into_params(parameter_in = Query)]
#[schema(as = AlarmFilter)]
#[serde(deny_unknown_fields)]
pub struct FilterParams {
    pub selection: Option<String>,
    #[schema(maximum = 4294967295_u32)]
    #[param(maximum = 4294967295_u32)]
    pub min_priority: Option<u32>,
    /// Comma-separated states: normal, unack_active, ack_active, unack_rtn, shelved, suppressed, out_of_service
    pub state: Option<String>,
    pub text: Option<String>,
}

impl FilterParams {
    fn to_filter(&self) -> ApiResult<AlarmFilter> {
        let states = match self.state.as_deref().filter(|s| !s.is_empty()) {
            None => vec![],
            Some(list) => list
                .split(',')
                .map(|st| {
                    st.trim().parse::<AlarmState>().map_err(|_| {
                        ApiError::bad_request(format!(
                            "state '{st}' is not one of normal, unack_active, ack_active, unack_rtn, shelved, suppressed, out_of_service"
                        ))
                    })
                })
                .collect::<ApiResult<_>>()?,
        };
        Ok(AlarmFilter {
            selection: self.selection.clone().filter(|s| !s.is_empty()),
            min_priority: self.min_priority,
            states,
            text: self.text.clone().filter(|s| !s.is_empty()),
        })
    }
}

/// The alarms that pass a filter.
#[derive(Serialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct AlarmList {
    #[schema(value_type = Vec<shapes::Alarm>)]
    pub alarms: Vec<gridscada_alarms::AlarmView>,
    pub count: usize,
}

#[utoipa::path(get, path = "/api/alarms", tag = "alarms", summary = "Alarm summary",
    params(FilterParams),
    responses((status = 200, description = "OK", body = inline(AlarmList)), (status = 400), (status = 503)))]
pub async fn summary(
    State(s): State<WebState>,
    Query(q): Query<FilterParams>,
) -> ApiResult<Json<AlarmList>> {
    let filter = q.to_filter()?;
    let alarms = engine(&s)?.summary(&filter);
    Ok(Json(AlarmList {
        count: alarms.len(),
        alarms,
    }))
}

#[derive(Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct AckBody {
    #[schema(value_type = Option<Vec<u32>>)]
    pub ids: Option<Vec<u32>>,
    pub top: Option<bool>,
    pub all: Option<bool>,
    pub filter: Option<FilterParams>,
}

/// The alarms an acknowledgement took.
#[derive(Serialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct Acked {
    #[schema(value_type = Vec<u32>)]
    pub acknowledged: Vec<AlarmId>,
    pub count: usize,
}

#[utoipa::path(post, path = "/api/alarms/ack", tag = "alarms",
    summary = "Acknowledge alarms: exactly one of ids, top or all",
    request_body = AckBody,
    responses((status = 200, description = "OK", body = inline(Acked)),
        (status = 400), (status = 404), (status = 503)))]
pub async fn ack(
    State(s): State<WebState>,
    Extension(who): Extension<Principal>,
    body: Result<Json<AckBody>, axum::extract::rejection::JsonRejection>,
) -> ApiResult<Json<Acked>> {
    let Json(b) = body.map_err(|e| ApiError::bad_request(e.body_text()))?;
    let e = engine(&s)?;
    // The engine records it through the audit trail: not unless durable.
    crate::api::pair::active_ready(&s)?;
    crate::api::audit_ready(&s).await?;
    let user = who.audit_name();
    let filter = b.filter.unwrap_or_default().to_filter()?;
    let acked: Vec<AlarmId> = match (b.ids, b.top, b.all) {
        (Some(ids), None, None) => {
            let ids: Vec<AlarmId> = ids.into_iter().map(AlarmId).collect();
            e.ack_ids(&user, &ids).map_err(alarm_error)?
        }
        (None, Some(true), None) => e.ack_top(&user, &filter).map_err(alarm_error)?.into_iter().collect(),
        (None, None, Some(true)) => e.ack_all(&user, &filter).map_err(alarm_error)?,
        _ => {
            return Err(ApiError::bad_request(
                "send exactly one of {\"ids\": [...]}, {\"top\": true} or {\"all\": true, \"filter\": {...}}",
            ))
        }
    };
    persist(&s, e, &acked).await?;
    Ok(Json(Acked {
        count: acked.len(),
        acknowledged: acked,
    }))
}

#[derive(Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct ShelveBody {
    pub minutes: u32,
    pub reason: String,
}

/// A shelved alarm.
#[derive(Serialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct Shelved {
    pub id: u32,
    #[schema(value_type = shapes::Timestamp)]
    pub shelved_until: Timestamp,
}

#[utoipa::path(post, path = "/api/alarms/{id}/shelve", tag = "alarms", summary = "Shelve an alarm",
    params(("id" = u32, Path, description = "Alarm id")),
    request_body = ShelveBody,
    responses((status = 200, description = "OK", body = inline(Shelved)),
        (status = 400), (status = 404), (status = 503)))]
pub async fn shelve(
    State(s): State<WebState>,
    Extension(who): Extension<Principal>,
    Path(id): Path<u32>,
    body: Result<Json<ShelveBody>, axum::extract::rejection::JsonRejection>,
) -> ApiResult<Json<Shelved>> {
    let Json(b) = body.map_err(|e| ApiError::bad_request(e.body_text()))?;
    let e = engine(&s)?;
    // The engine records it through the audit trail: not unless durable.
    crate::api::pair::active_ready(&s)?;
    crate::api::audit_ready(&s).await?;
    let until = e
        .shelve(AlarmId(id), &who.audit_name(), b.minutes, &b.reason)
        .map_err(alarm_error)?;
    persist(&s, e, &[AlarmId(id)]).await?;
    Ok(Json(Shelved {
        id,
        shelved_until: until,
    }))
}

#[utoipa::path(delete, path = "/api/alarms/{id}/shelve", tag = "alarms", summary = "Unshelve an alarm",
    params(("id" = u32, Path, description = "Alarm id")),
    responses((status = 204, description = "Unshelved"), (status = 400), (status = 404), (status = 503)))]
pub async fn unshelve(
    State(s): State<WebState>,
    Extension(who): Extension<Principal>,
    Path(id): Path<u32>,
) -> ApiResult<StatusCode> {
    let e = engine(&s)?;
    // The engine records it through the audit trail: not unless durable.
    crate::api::pair::active_ready(&s)?;
    crate::api::audit_ready(&s).await?;
    e.unshelve(AlarmId(id), &who.audit_name())
        .map_err(alarm_error)?;
    persist(&s, e, &[AlarmId(id)]).await?;
    Ok(StatusCode::NO_CONTENT)
}

/// The longest an alarm may be out of service before it returns by itself.
pub const MAX_OUT_OF_SERVICE_HOURS: f64 = 2160.0;

#[derive(Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct OutOfServiceBody {
    /// Why (required): it is audited and shown in the alarm list.
    pub reason: String,
    /// Hours until it returns to service by itself (more than 0, at most
    /// 2160: 90 days).
    pub hours: f64,
}

/// An alarm taken out of service.
#[derive(Serialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct OutOfService {
    pub id: u32,
    #[schema(value_type = shapes::Timestamp)]
    pub until: Timestamp,
}

#[utoipa::path(post, path = "/api/alarms/{id}/out-of-service", tag = "alarms",
    summary = "Take an alarm out of service, with a reason, until a set time",
    params(("id" = u32, Path, description = "Alarm id")),
    request_body = OutOfServiceBody,
    responses((status = 200, description = "OK", body = inline(OutOfService)),
        (status = 400), (status = 404), (status = 409, description = "Already out of service"), (status = 503)))]
pub async fn out_of_service(
    State(s): State<WebState>,
    Extension(who): Extension<Principal>,
    Path(id): Path<u32>,
    body: Result<Json<OutOfServiceBody>, axum::extract::rejection::JsonRejection>,
) -> ApiResult<Json<OutOfService>> {
    let Json(b) = body.map_err(|e| ApiError::bad_request(e.body_text()))?;
    if !(b.hours.is_finite() && b.hours > 0.0 && b.hours <= MAX_OUT_OF_SERVICE_HOURS) {
        return Err(ApiError::bad_request(format!(
            "hours: {} must be more than 0 and at most {MAX_OUT_OF_SERVICE_HOURS} (90 days)",
            b.hours
        )));
    }
    let e = engine(&s)?;
    // The engine records it through the audit trail: not unless durable.
    crate::api::audit_ready(&s).await?;
    let until = Timestamp::from_millis(s.clock.now().as_millis() + (b.hours * 3_600_000.0) as i64);
    if !e
        .out_of_service_until(AlarmId(id), &who.audit_name(), &b.reason, until)
        .map_err(alarm_error)?
    {
        return Err(ApiError::conflict(
            "the alarm is already out of service; return it to service first",
        ));
    }
    persist(&s, e, &[AlarmId(id)]).await?;
    Ok(Json(OutOfService { id, until }))
}

#[utoipa::path(delete, path = "/api/alarms/{id}/out-of-service", tag = "alarms",
    summary = "Return an alarm to service",
    params(("id" = u32, Path, description = "Alarm id")),
    responses((status = 204, description = "Returned to service"), (status = 404),
        (status = 409, description = "Not out of service"), (status = 503)))]
pub async fn in_service(
    State(s): State<WebState>,
    Extension(who): Extension<Principal>,
    Path(id): Path<u32>,
) -> ApiResult<StatusCode> {
    let e = engine(&s)?;
    // The engine records it through the audit trail: not unless durable.
    crate::api::audit_ready(&s).await?;
    if !e
        .set_out_of_service(AlarmId(id), &who.audit_name(), false, "")
        .map_err(alarm_error)?
    {
        return Err(ApiError::conflict("the alarm is not out of service"));
    }
    persist(&s, e, &[AlarmId(id)]).await?;
    Ok(StatusCode::NO_CONTENT)
}

#[derive(Deserialize, Default, IntoParams)]
#[into_params(parameter_in = Query)]
#[serde(deny_unknown_fields)]
pub struct HistoryQuery {
    #[param(schema_with = shapes::time, required = false)]
    pub from: Option<String>,
    #[param(schema_with = shapes::time, required = false)]
    pub to: Option<String>,
    pub key: Option<String>,
    pub tag: Option<String>,
    pub selection: Option<String>,
    pub min_priority: Option<i32>,
    pub text: Option<String>,
    pub limit: Option<u32>,
    pub offset: Option<u32>,
    /// Another site on the same database whose history to read
    /// (read-only); this server's own site if absent (`GET /api/sites`).
    pub site: Option<String>,
}

fn opt_time(field: &str, v: &Option<String>) -> ApiResult<Option<Timestamp>> {
    v.as_deref()
        .filter(|v| !v.is_empty())
        .map(|v| parse_time(field, v))
        .transpose()
}

/// Recorded alarm transitions.
#[derive(Serialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct Transitions {
    #[schema(value_type = Vec<shapes::AlarmTransition>)]
    pub transitions: Vec<gridscada_store::AlarmTransitionRecord>,
    pub count: usize,
}

#[utoipa::path(get, path = "/api/alarms/history", tag = "alarms", summary = "Alarm transitions",
    params(HistoryQuery),
    responses((status = 200, description = "OK", body = inline(Transitions)), (status = 400),
        (status = 404, description = "No such site")))]
pub async fn history(
    State(s): State<WebState>,
    Query(q): Query<HistoryQuery>,
) -> ApiResult<Json<Transitions>> {
    let store = crate::api::history_of(&s, q.site.as_deref()).await?;
    let filter = history_filter(q)?;
    let rows = store.alarm_history(&filter).await?;
    Ok(Json(Transitions {
        count: rows.len(),
        transitions: rows,
    }))
}

/// The alarm history as CSV, with the list's filters (no row cap, `limit`
/// and `offset` ignored), newest first, streamed.
#[utoipa::path(get, path = "/api/alarms/history.csv", tag = "alarms", summary = "Alarm transitions as CSV",
    params(HistoryQuery),
    responses((status = 200, description = "CSV", body = String, content_type = "text/csv"), (status = 400),
        (status = 404, description = "No such site")))]
pub async fn history_csv(
    State(s): State<WebState>,
    Query(q): Query<HistoryQuery>,
) -> ApiResult<axum::response::Response> {
    let store = crate::api::history_of(&s, q.site.as_deref()).await?;
    let filter = history_filter(q)?;
    Ok(crate::api::csv_download(
        "alarm-history.csv",
        "alarm history CSV export",
        move |mut tx| async move { store.export_alarm_history_csv(&filter, &mut tx).await },
    ))
}

/// The store's filter for the list and the CSV alike.
fn history_filter(q: HistoryQuery) -> ApiResult<AlarmHistoryFilter> {
    Ok(AlarmHistoryFilter {
        from: opt_time("from", &q.from)?,
        to: opt_time("to", &q.to)?,
        alarm_key: q.key.filter(|v| !v.is_empty()),
        tag: q.tag.filter(|v| !v.is_empty()),
        selection: q.selection.filter(|v| !v.is_empty()),
        min_priority: q.min_priority,
        text: q.text.filter(|v| !v.is_empty()),
        limit: q.limit.unwrap_or(500).clamp(1, 10_000),
        offset: q.offset.unwrap_or(0),
        ..Default::default()
    })
}

#[derive(Deserialize, Default, IntoParams)]
#[into_params(parameter_in = Query)]
#[serde(deny_unknown_fields)]
pub struct MetricsQuery {
    #[param(schema_with = shapes::time, required = false)]
    pub from: Option<String>,
    #[param(schema_with = shapes::time, required = false)]
    pub to: Option<String>,
    /// Operator positions sharing the alarm load (1-100, default 1): the
    /// rates per operator are the plant's divided by this.
    #[param(minimum = 1, maximum = 100)]
    pub operators: Option<u32>,
}

/// The widest range the alarm metrics cover in one request.
const MAX_METRICS_RANGE_MS: i64 = 366 * 24 * 3_600_000;

#[utoipa::path(get, path = "/api/alarms/metrics", tag = "alarms", summary = "ISA-18.2 alarm metrics",
    params(MetricsQuery),
    responses((status = 200, description = "OK", body = inline(shapes::AlarmMetrics)),
        (status = 400), (status = 503)))]
pub async fn metrics(
    State(s): State<WebState>,
    Query(q): Query<MetricsQuery>,
) -> ApiResult<Json<Value>> {
    let e = engine(&s)?;
    let to = opt_time("to", &q.to)?.unwrap_or_else(|| s.clock.now());
    let from = opt_time("from", &q.from)?.unwrap_or(Timestamp::from_millis(
        to.as_millis().saturating_sub(24 * 3_600_000),
    ));
    if from > to {
        return Err(ApiError::bad_request("from must not be after to"));
    }
    // The metrics hold one count per 10-minute interval of the range: an
    // unbounded range would allocate without limit.
    if to.as_millis().saturating_sub(from.as_millis()) > MAX_METRICS_RANGE_MS {
        return Err(ApiError::bad_request(
            "the metrics range may span at most 366 days",
        ));
    }
    let operators = q.operators.unwrap_or(1);
    if !(1..=100).contains(&operators) {
        return Err(ApiError::bad_request("operators must be 1 to 100"));
    }
    let rows = s.store.alarm_activations(from, to).await?;
    let mut by_selection: BTreeMap<String, Vec<gridscada_alarms::Activation>> = BTreeMap::new();
    let activations: Vec<gridscada_alarms::Activation> = rows
        .into_iter()
        .map(|r| {
            let a = gridscada_alarms::Activation {
                time: r.transition.ts,
                key: r.transition.alarm_key,
                priority: r.transition.priority.max(0) as u32,
            };
            by_selection
                .entry(r.transition.selection)
                .or_default()
                .push(a.clone());
            a
        })
        .collect();
    let states = e.persisted_states();
    let options = gridscada_alarms::MetricsOptions {
        operators,
        ..Default::default()
    };
    let m = gridscada_alarms::compute_metrics(&activations, &states, from, to, &options);
    // The load of each selection (the area one console watches), as if one
    // operator position had it alone.
    let positions: Vec<Value> = by_selection
        .iter()
        .map(|(selection, acts)| {
            let p = gridscada_alarms::compute_metrics(acts, &[], from, to, &Default::default());
            json!({
                "selection": selection,
                "total_activations": p.total_activations,
                "average_per_interval": p.average_per_interval_per_operator,
                "max_per_interval": p.max_per_interval_per_operator,
                "floods": p.floods.len(),
                "percent_time_in_flood": p.percent_time_in_flood,
            })
        })
        .collect();
    let shelved: Vec<Value> = states
        .iter()
        .filter(|a| a.shelved_by.is_some())
        .map(|a| {
            json!({
                "key": a.key,
                "message": a.message,
                "by": a.shelved_by,
                "since": a.shelved_at,
                "until": a.shelved_until,
                "reason": a.shelve_reason,
            })
        })
        .collect();
    let mut out =
        serde_json::to_value(m).map_err(|e| ApiError::internal("serializing metrics", e))?;
    out["positions"] = json!(positions);
    out["shelved"] = json!(shelved);
    out["targets"] = json!(gridscada_alarms::MetricTargets::default());
    Ok(Json(out))
}
