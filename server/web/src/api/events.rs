//! The event log: every operator and system action.

use axum::extract::{Query, State};
use axum::response::Response;
use axum::Json;
use gridscada_store::EventFilter;
use gridscada_tagdb::Timestamp;
use serde::{Deserialize, Serialize};
use utoipa::{IntoParams, ToSchema};

use crate::api::parse_time;
use crate::error::{ApiError, ApiResult};
use crate::openapi::shapes;
use crate::WebState;

#[derive(Deserialize, Default, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct EventQuery {
    #[param(schema_with = shapes::time, required = false)]
    pub from: Option<String>,
    #[param(schema_with = shapes::time, required = false)]
    pub to: Option<String>,
    /// Today in the caller's time zone (see `tz_offset_min`).
    pub today: Option<bool>,
    /// Minutes east of UTC of the operator's time zone, for "today".
    #[param(minimum = -840, maximum = 840)]
    pub tz_offset_min: Option<i32>,
    #[serde(rename = "type")]
    pub kind: Option<String>,
    pub user: Option<String>,
    pub source: Option<String>,
    pub text: Option<String>,
    pub limit: Option<u32>,
    pub offset: Option<u32>,
    /// Another site on the same database whose history to read
    /// (read-only); this server's own site if absent (`GET /api/sites`).
    pub site: Option<String>,
}

/// Start of the local day containing `now`, for a zone `offset_min` east of UTC.
pub fn start_of_day(now: Timestamp, offset_min: i32) -> Timestamp {
    const DAY: i64 = 86_400_000;
    let offset = offset_min as i64 * 60_000;
    let local = now.as_millis() + offset;
    Timestamp::from_millis(local - local.rem_euclid(DAY) - offset)
}

/// A page of the event log.
#[derive(Serialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct EventList {
    #[schema(value_type = Vec<shapes::Event>)]
    pub events: Vec<gridscada_store::Event>,
    pub count: usize,
}

#[utoipa::path(get, path = "/api/events", tag = "events", summary = "The event log",
    params(EventQuery),
    responses((status = 200, description = "OK", body = inline(EventList)), (status = 400),
        (status = 404, description = "No such site")))]
pub async fn list(
    State(s): State<WebState>,
    Query(q): Query<EventQuery>,
) -> ApiResult<Json<EventList>> {
    let store = crate::api::history_of(&s, q.site.as_deref()).await?;
    let filter = event_filter(&s, q)?;
    let events = store.events(&filter).await?;
    Ok(Json(EventList {
        count: events.len(),
        events,
    }))
}

/// The event log as CSV, with the list's filters (no row cap, `limit` and
/// `offset` ignored), newest first, streamed.
#[utoipa::path(get, path = "/api/events.csv", tag = "events", summary = "The event log as CSV",
    params(EventQuery),
    responses((status = 200, description = "CSV", body = String, content_type = "text/csv"), (status = 400),
        (status = 404, description = "No such site")))]
pub async fn csv(State(s): State<WebState>, Query(q): Query<EventQuery>) -> ApiResult<Response> {
    let store = crate::api::history_of(&s, q.site.as_deref()).await?;
    let filter = event_filter(&s, q)?;
    Ok(crate::api::csv_download(
        "events.csv",
        "event CSV export",
        move |mut tx| async move { store.export_events_csv(&filter, &mut tx).await },
    ))
}

/// The store's filter for the list and the CSV alike.
fn event_filter(s: &WebState, q: EventQuery) -> ApiResult<EventFilter> {
    let mut filter = EventFilter {
        limit: q.limit.unwrap_or(500).clamp(1, 10_000),
        offset: q.offset.unwrap_or(0),
        kind: q.kind.filter(|v| !v.is_empty()),
        user: q.user.filter(|v| !v.is_empty()),
        source: q.source.filter(|v| !v.is_empty()),
        text: q.text.filter(|v| !v.is_empty()),
        ..Default::default()
    };
    if let Some(offset) = q.tz_offset_min {
        if !(-14 * 60..=14 * 60).contains(&offset) {
            return Err(ApiError::bad_request(
                "tz_offset_min must be within -840..=840",
            ));
        }
    }
    if q.today == Some(true) {
        let now = s.clock.now();
        filter.from = Some(start_of_day(now, q.tz_offset_min.unwrap_or(0)));
        filter.to = Some(Timestamp::from_millis(i64::MAX / 2));
    } else {
        filter.from = q
            .from
            .as_deref()
            .filter(|v| !v.is_empty())
            .map(|v| parse_time("from", v))
            .transpose()?;
        filter.to =
            q.to.as_deref()
                .filter(|v| !v.is_empty())
                .map(|v| parse_time("to", v))
                .transpose()?;
    }
    Ok(filter)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn start_of_day_respects_the_zone() {
        // 2026-11-21 01:30 UTC is still 2026-11-20 in UTC-3.
        let now = Timestamp::from_millis(1_763_688_600_000);
        let utc = start_of_day(now, 0);
        assert_eq!(utc.as_millis() % 86_400_000, 0);
        let west = start_of_day(now, -180);
        assert_eq!(
            west.as_millis(),
            utc.as_millis() - 86_400_000 + 3 * 3_600_000
        );
    }
}
