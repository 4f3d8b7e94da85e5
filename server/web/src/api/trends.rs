//! Trends: downsampled series for charts, raw CSV for export.

use axum::extract::{Query, State};
use axum::response::Response;
use axum::{Extension, Json};
use gridscada_tagdb::Timestamp;
use serde::{Deserialize, Serialize};
use utoipa::{IntoParams, ToSchema};

use crate::api::parse_time;
use crate::auth::Principal;
use crate::error::{ApiError, ApiResult};
use crate::openapi::shapes;
use crate::WebState;

#[derive(Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct TrendQuery {
    /// Comma-separated tag names, at most 16
    pub tags: String,
    #[param(value_type = shapes::Time, inline)]
    pub from: String,
    #[param(value_type = shapes::Time, inline)]
    pub to: String,
    /// Points per series (buckets), at most 5000.
    #[param(minimum = 1, maximum = 5000)]
    pub points: Option<u32>,
    /// Another site on the same database whose history to read
    /// (read-only); this server's own site if absent (`GET /api/sites`).
    pub site: Option<String>,
}

const MAX_PENS: usize = 16;

/// The tags asked for, checked: known and readable here. Another site's
/// tags are not in this server's configuration, so only a user whose group
/// reads every tag may read them (a group limited to screens reads the tags
/// of this site's screens only).
fn tag_list<'a>(
    s: &WebState,
    who: &Principal,
    tags: &'a str,
    other_site: bool,
) -> ApiResult<Vec<&'a str>> {
    let list: Vec<&str> = tags
        .split(',')
        .map(str::trim)
        .filter(|t| !t.is_empty())
        .collect();
    if list.is_empty() {
        return Err(ApiError::bad_request("tags: name at least one tag"));
    }
    if list.len() > MAX_PENS {
        return Err(ApiError::bad_request(format!(
            "tags: at most {MAX_PENS} tags at once"
        )));
    }
    let readable = s.readable(who);
    if other_site {
        if !readable.all() {
            return Err(ApiError::forbidden(
                "another site's trends: your group reads only the tags of this site's screens",
            ));
        }
        return Ok(list);
    }
    if let Some(unknown) = list.iter().find(|t| s.db.id(t).is_none()) {
        return Err(ApiError::not_found(format!("no tag named '{unknown}'")));
    }
    if let Some(hidden) = list.iter().find(|t| !readable.may_read(t)) {
        return Err(ApiError::forbidden(format!(
            "tag '{hidden}' is on no screen your group may open"
        )));
    }
    Ok(list)
}

/// Downsampled series of some tags.
#[derive(Serialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct Trend {
    #[schema(value_type = shapes::Timestamp)]
    pub from: Timestamp,
    #[schema(value_type = shapes::Timestamp)]
    pub to: Timestamp,
    pub points: u32,
    #[schema(value_type = Vec<Object>)]
    pub series: Vec<gridscada_store::TagTrend>,
}

#[utoipa::path(get, path = "/api/trends", tag = "trends", summary = "Downsampled trend",
    params(TrendQuery),
    responses((status = 200, description = "OK", body = inline(Trend)), (status = 400), (status = 404)))]
pub async fn trend(
    State(s): State<WebState>,
    Extension(who): Extension<Principal>,
    Query(q): Query<TrendQuery>,
) -> ApiResult<Json<Trend>> {
    let store = crate::api::history_of(&s, q.site.as_deref()).await?;
    let tags = tag_list(&s, &who, &q.tags, store.site() != s.store.site())?;
    let from = parse_time("from", &q.from)?;
    let to = parse_time("to", &q.to)?;
    let points = q.points.unwrap_or(500);
    if !(1..=5000).contains(&points) {
        return Err(ApiError::bad_request("points must be 1 to 5000"));
    }
    let series = store.trend(&tags, from, to, points).await?;
    Ok(Json(Trend {
        from,
        to,
        points,
        series,
    }))
}

#[derive(Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct CsvQuery {
    /// Comma-separated tag names, at most 16
    pub tags: String,
    #[param(value_type = shapes::Time, inline)]
    pub from: String,
    #[param(value_type = shapes::Time, inline)]
    pub to: String,
    /// Another site on the same database whose history to read
    /// (read-only); this server's own site if absent (`GET /api/sites`).
    pub site: Option<String>,
}

/// Raw samples as CSV, streamed so that a long range never sits in memory.
#[utoipa::path(get, path = "/api/trends.csv", tag = "trends", summary = "Raw samples as CSV",
    params(CsvQuery),
    responses((status = 200, description = "CSV", body = String, content_type = "text/csv"),
        (status = 400), (status = 404)))]
pub async fn csv(
    State(s): State<WebState>,
    Extension(who): Extension<Principal>,
    Query(q): Query<CsvQuery>,
) -> ApiResult<Response> {
    let store = crate::api::history_of(&s, q.site.as_deref()).await?;
    let tags: Vec<String> = tag_list(&s, &who, &q.tags, store.site() != s.store.site())?
        .into_iter()
        .map(String::from)
        .collect();
    let from = parse_time("from", &q.from)?;
    let to = parse_time("to", &q.to)?;
    if from > to {
        return Err(ApiError::bad_request("from must not be after to"));
    }
    Ok(crate::api::csv_download(
        "trend.csv",
        "CSV export",
        move |mut tx| async move {
            let refs: Vec<&str> = tags.iter().map(String::as_str).collect();
            store.export_csv(&refs, from, to, &mut tx).await
        },
    ))
}
