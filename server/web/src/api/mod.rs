//! Route handlers, one module per area of the API.

pub mod alarms;
pub mod devices;
pub mod dispatch;
pub mod events;
pub mod live;
pub mod misc;
pub mod network;
pub mod pair;
pub mod panels;
pub mod programmes;
pub mod reports;
pub mod screens;
pub mod session;
pub mod sim;
pub mod tags;
pub mod trends;
pub mod users;

use gridscada_store::{NewEvent, Store};

use crate::auth::Principal;
use crate::error::{ApiError, ApiResult};
use crate::WebState;

/// The store to read history from (`?site=`): this server's own site, or
/// another site on the same database, read-only. An unknown site is a 404,
/// so a misspelt id is not mistaken for an empty history.
pub async fn history_of(state: &WebState, site: Option<&str>) -> ApiResult<Store> {
    match site.filter(|v| !v.is_empty() && *v != state.store.site()) {
        None => Ok(state.store.clone()),
        Some(site) => {
            let view = state.store.site_reader(site)?;
            if !state.store.sites().await?.iter().any(|s| s == site) {
                return Err(ApiError::not_found(format!(
                    "no site '{site}' in this database"
                )));
            }
            Ok(view)
        }
    }
}

/// Handles to the running components the API reports on and commands.
#[derive(Clone, Default)]
pub struct Components {
    /// One per configured panel running its fault-isolation sequence.
    pub panels: Vec<panels::PanelHandle>,
    /// The alarm engine.
    pub alarms: Option<std::sync::Arc<gridscada_alarms::AlarmEngine>>,
    /// The latest result of the microgrid outer loop, if the plant has one.
    pub dispatch: Option<tokio::sync::watch::Receiver<gridscada_control::dispatch::DispatchStatus>>,
    /// This server's part in a redundant pair, if it is one of a pair.
    pub pair: Option<pair::Pair>,
    /// The switching network and its live topology, if configured.
    pub network: Option<network::NetworkView>,
}

fn audit_event(
    state: &WebState,
    who: &Principal,
    kind: &str,
    source: &str,
    message: String,
) -> NewEvent {
    NewEvent {
        ts: state.clock.now(),
        user: who.user.clone(),
        source: source.to_string(),
        kind: kind.to_string(),
        message,
    }
}

/// Records what came of an operator action (or a login) in the event log,
/// through the audit trail. A record that can be neither stored nor spooled
/// is logged loudly (and counted); the action itself has already happened.
pub async fn audit(state: &WebState, who: &Principal, kind: &str, source: &str, message: String) {
    let event = audit_event(state, who, kind, source, message);
    if let Err(e) = durable(state, event).await {
        tracing::error!(error = %e, "could not record an audit event");
    }
}

async fn durable(state: &WebState, event: NewEvent) -> Result<(), String> {
    match &state.audit {
        Some(a) => a
            .record_durable(gridscada_store::AuditBody::Event(event))
            .await
            .map_err(|e| e.to_string()),
        None => state
            .store
            .insert_event(&event)
            .await
            .map(|_| ())
            .map_err(|e| e.to_string()),
    }
}

/// The web layer's audit path (the trail, or the store without one) as the
/// shared audited write takes it.
pub struct WebAudit<'a>(pub &'a WebState);

impl gridscada_store::command::CommandAudit for WebAudit<'_> {
    fn durable(
        &self,
        event: NewEvent,
    ) -> std::pin::Pin<Box<dyn std::future::Future<Output = Result<(), String>> + Send + '_>> {
        Box::pin(durable(self.0, event))
    }
}

/// Before a command whose audit record the component itself makes through
/// the audit trail (a panel sequence, the alarm engine): refuses it (503)
/// when that record could be neither stored nor spooled now.
pub async fn audit_ready(state: &WebState) -> Result<(), crate::error::ApiError> {
    let r = match &state.audit {
        Some(a) => a.probe().await.map_err(|e| e.to_string()),
        None => state.store.ping().await.map_err(|e| e.to_string()),
    };
    r.map_err(refused_unaudited)
}

pub(crate) fn refused_unaudited(why: String) -> crate::error::ApiError {
    tracing::error!(%why, "command refused: its audit record cannot be made durable");
    crate::error::ApiError::unavailable(format!(
        "command refused: its audit record can be neither stored nor spooled, and no command goes out unrecorded ({why})"
    ))
}

/// Parses a time given as milliseconds since the epoch.
///
/// Also takes an RFC 3339 date and time (`2026-11-24T21:00:00Z`,
/// `2026-11-24T22:00:00+01:00`).
/// A CSV download whose body `write` streams (the store's exports write
/// into the pipe as rows come off the database; the client's pace holds
/// them back through the pipe's 64 KiB), so a long export never sits in
/// memory. `what` names the export in the log if it fails part-way.
pub fn csv_download<F, Fut>(
    filename: &str,
    what: &'static str,
    write: F,
) -> axum::response::Response
where
    F: FnOnce(tokio::io::DuplexStream) -> Fut + Send + 'static,
    Fut: std::future::Future<Output = gridscada_store::Result<u64>> + Send + 'static,
{
    use axum::http::header;
    use axum::response::IntoResponse;
    let (tx, rx) = tokio::io::duplex(64 * 1024);
    tokio::spawn(async move {
        if let Err(e) = write(tx).await {
            // The response has started; the client sees a truncated file.
            tracing::error!(error = %e, "{what} failed part-way");
        }
    });
    let body = axum::body::Body::from_stream(tokio_util::io::ReaderStream::new(rx));
    (
        [
            (header::CONTENT_TYPE, "text/csv; charset=utf-8".to_string()),
            (
                header::CONTENT_DISPOSITION,
                format!("attachment; filename=\"{filename}\""),
            ),
        ],
        body,
    )
        .into_response()
}

pub fn parse_time(
    field: &str,
    s: &str,
) -> Result<gridscada_tagdb::Timestamp, crate::error::ApiError> {
    let t = s.trim();
    if let Ok(ms) = t.parse::<i64>() {
        return Ok(gridscada_tagdb::Timestamp::from_millis(ms));
    }
    time::OffsetDateTime::parse(t, &time::format_description::well_known::Rfc3339)
        .ok()
        .and_then(|d| i64::try_from(d.unix_timestamp_nanos() / 1_000_000).ok())
        .map(gridscada_tagdb::Timestamp::from_millis)
        .ok_or_else(|| {
            crate::error::ApiError::bad_request(format!(
                "{field}: '{}' is neither milliseconds since 1970-01-01 UTC nor an RFC 3339 time such as 2026-11-24T21:00:00Z",
                s.escape_debug()
            ))
        })
}

#[cfg(test)]
mod time_tests {
    #[test]
    fn times_in_milliseconds_or_rfc_3339() {
        let ms = |s: &str| super::parse_time("from", s).map(|t| t.as_millis());
        assert_eq!(ms("1795557270579").unwrap(), 1_795_557_270_579);
        assert_eq!(ms("2026-11-24T21:00:00Z").unwrap(), 1_795_554_000_000);
        assert_eq!(ms("2026-11-24T22:00:00+01:00").unwrap(), 1_795_554_000_000);
        assert_eq!(ms("2026-11-24T21:00:00.250Z").unwrap(), 1_795_554_000_250);
        let err = ms("yesterday").unwrap_err();
        assert!(err.detail.contains("RFC 3339"), "{}", err.detail);
    }
}
