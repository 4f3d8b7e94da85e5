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
pub fn parse_time(
    field: &str,
    s: &str,
) -> Result<gridscada_tagdb::Timestamp, crate::error::ApiError> {
    s.trim()
        .parse::<i64>()
        .map(gridscada_tagdb::Timestamp::from_millis)
        .map_err(|_| {
            crate::error::ApiError::bad_request(format!(
                "{field}: '{s}' is not a time in milliseconds since 1970-01-01 UTC"
            ))
        })
}
