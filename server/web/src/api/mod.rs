//! Route handlers, one module per area of the API.

pub mod alarms;
pub mod devices;
pub mod dispatch;
pub mod events;
pub mod live;
pub mod misc;
pub mod panels;
pub mod screens;
pub mod session;
pub mod sim;
pub mod tags;
pub mod trends;
pub mod users;

use gridscada_store::NewEvent;

use crate::auth::Principal;
use crate::WebState;

/// Handles to the running components the API reports on and commands.
#[derive(Clone, Default)]
pub struct Components {
    /// One per configured panel running its fault-isolation sequence.
    pub panels: Vec<panels::PanelHandle>,
    /// The alarm engine.
    pub alarms: Option<std::sync::Arc<gridscada_alarms::AlarmEngine>>,
    /// The latest result of the microgrid outer loop, if the plant has one.
    pub dispatch: Option<tokio::sync::watch::Receiver<gridscada_control::dispatch::DispatchStatus>>,
}

/// Records an operator action in the event log. An audit record that cannot be
/// written is logged loudly; the action itself has already happened.
pub async fn audit(state: &WebState, who: &Principal, kind: &str, source: &str, message: String) {
    let event = NewEvent {
        ts: state.clock.now(),
        user: who.user.clone(),
        source: source.to_string(),
        kind: kind.to_string(),
        message,
    };
    if let Err(e) = state.store.insert_event(&event).await {
        tracing::error!(error = %e, ?event, "could not record an audit event");
    }
}

/// Parses a time given as milliseconds since the epoch.
///
/// Also takes an RFC 3339 date and time (`2026-11-24T21:00:00Z`,
/// `2026-11-24T22:00:00+01:00`).
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
