//! `/api/reports`: the daily and monthly reports in the data folder's
//! `reports/` (listed, opened, downloaded), and making one on demand. The
//! figures and files are `gridscada_reports`'s; this only serves them.

use axum::extract::{Path, Query, State};
use axum::http::header;
use axum::response::{IntoResponse, Response};
use axum::Json;
use gridscada_reports::{Archive, Period, ReportEntry};
use serde::{Deserialize, Serialize};
use utoipa::{IntoParams, ToSchema};

use crate::error::{ApiError, ApiResult};
use crate::WebState;

/// One report at a time: a month reads a month of samples.
static MAKING: tokio::sync::Mutex<()> = tokio::sync::Mutex::const_new(());

/// The report page's own policy: no script at all, its inline stylesheet.
const REPORT_CSP: &str =
    "default-src 'none'; style-src 'unsafe-inline'; img-src data:; base-uri 'none'; form-action 'none'; frame-ancestors 'none'";

fn archive(s: &WebState) -> Archive {
    Archive::in_data_dir(&s.plant.data_dir)
}

/// A report in the folder.
#[derive(Serialize, ToSchema)]
pub struct ReportView {
    /// `2024-06-21` (a day) or `2024-06` (a month), UTC.
    pub id: String,
    /// `day` or `month`.
    pub kind: String,
    /// When it was written, ms since the epoch.
    pub modified: i64,
    /// `html`, `csv`, `json`.
    pub formats: Vec<String>,
}

impl From<ReportEntry> for ReportView {
    fn from(e: ReportEntry) -> Self {
        ReportView {
            id: e.id,
            kind: e.kind.to_string(),
            modified: e.modified,
            formats: e.formats.into_iter().map(String::from).collect(),
        }
    }
}

#[derive(Serialize, ToSchema)]
pub struct ReportList {
    pub reports: Vec<ReportView>,
}

/// The reports made so far, newest period first.
#[utoipa::path(get, path = "/api/reports", tag = "reports", summary = "List the reports",
    responses((status = 200, description = "OK", body = ReportList)))]
pub async fn list(State(s): State<WebState>) -> ApiResult<Json<ReportList>> {
    let a = archive(&s);
    let entries = tokio::task::spawn_blocking(move || a.list())
        .await
        .map_err(|e| ApiError::internal("listing reports", e))?
        .map_err(|e| ApiError::internal("listing reports", e))?;
    Ok(Json(ReportList {
        reports: entries.into_iter().map(ReportView::from).collect(),
    }))
}

#[derive(Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct FileQuery {
    /// `1`: as an attachment (download) instead of inline.
    pub download: Option<u8>,
}

fn period_of(id: &str) -> ApiResult<Period> {
    Period::parse(id).map_err(|e| ApiError::bad_request(e.to_string()))
}

/// One report's file: `html` (with a print stylesheet), `csv` or `json`.
#[utoipa::path(get, path = "/api/reports/{id}/{format}", tag = "reports", summary = "A report's file",
    params(("id" = String, Path, description = "YYYY-MM-DD or YYYY-MM"),
        ("format" = String, Path, description = "html, csv or json"), FileQuery),
    responses((status = 200, description = "The file",
            content((String = "text/html"), (String = "text/csv"), (Object = "application/json"))),
        (status = 400), (status = 404)))]
pub async fn file(
    State(s): State<WebState>,
    Path((id, format)): Path<(String, String)>,
    Query(q): Query<FileQuery>,
) -> ApiResult<Response> {
    let period = period_of(&id)?;
    let mime = match format.as_str() {
        "html" => "text/html; charset=utf-8",
        "csv" => "text/csv; charset=utf-8",
        "json" => "application/json",
        _ => return Err(ApiError::bad_request("format must be html, csv or json")),
    };
    let path = archive(&s).path(period, &format);
    let body = match tokio::fs::read(&path).await {
        Ok(b) => b,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            return Err(ApiError::not_found(format!(
                "no {format} report for {period}"
            )))
        }
        Err(e) => return Err(ApiError::internal("reading a report", e)),
    };
    let disposition = format!(
        "{}; filename=\"report-{period}.{format}\"",
        if q.download == Some(1) {
            "attachment"
        } else {
            "inline"
        }
    );
    let mut resp = (
        [
            (header::CONTENT_TYPE, mime.to_string()),
            (header::CONTENT_DISPOSITION, disposition),
        ],
        body,
    )
        .into_response();
    resp.headers_mut().insert(
        header::CONTENT_SECURITY_POLICY,
        header::HeaderValue::from_static(REPORT_CSP),
    );
    Ok(resp)
}

#[derive(Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct MakeReport {
    /// `YYYY-MM-DD` (a day) or `YYYY-MM` (a month), UTC. A period still
    /// running is reported up to now.
    pub period: String,
}

/// Makes (or makes again) the report of a day or month now.
#[utoipa::path(post, path = "/api/reports", tag = "reports", summary = "Make a report now",
    request_body = MakeReport,
    responses((status = 200, description = "Made", body = ReportView), (status = 400),
        (status = 409, description = "Another report is being made")))]
pub async fn make(
    State(s): State<WebState>,
    Json(req): Json<MakeReport>,
) -> ApiResult<Json<ReportView>> {
    let period = period_of(&req.period)?;
    let Ok(_one) = MAKING.try_lock() else {
        return Err(ApiError::conflict(
            "another report is being made; try again shortly",
        ));
    };
    let report = gridscada_reports::generate(&s.store, &s.plant, period, s.clock.now())
        .await
        .map_err(|e| match e {
            gridscada_reports::ReportError::Future(_) => ApiError::bad_request(e.to_string()),
            other => ApiError::internal("making a report", other),
        })?;
    let a = archive(&s);
    let entry = tokio::task::spawn_blocking(move || {
        a.save(&report)?;
        a.list().map(|l| l.into_iter().find(|e| e.id == report.id))
    })
    .await
    .map_err(|e| ApiError::internal("writing a report", e))?
    .map_err(|e| ApiError::internal("writing a report", e))?
    .ok_or_else(|| ApiError::internal("writing a report", "not listed after writing"))?;
    Ok(Json(entry.into()))
}
