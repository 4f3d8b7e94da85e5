//! The event log model: what happened, when, by whom.
//!
//! **Owns:** the [`Event`] record and the closed list of [`EventType`] names
//! that every crate uses when it reports something to the event log (a login,
//! a command, an acknowledgement, a sequence step, a dispatch fallback).
//!
//! **Must not touch:** storage. Producers hand events to a channel; the store
//! persists them and the web layer lists them.

use std::fmt;
use std::str::FromStr;

use gridscada_tagdb::Timestamp;
use serde::{Deserialize, Serialize};

/// The kind of an event. The string names (`as_str`) are what the store keeps
/// and the API filters on; do not rename them.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum EventType {
    /// A user logged in.
    Login,
    /// A user logged out (or the session expired).
    Logout,
    /// A login was refused (bad password, blocked user).
    LoginFailed,
    /// An alarm was acknowledged.
    Ack,
    /// An alarm was shelved.
    Shelve,
    /// An alarm was unshelved, by a user or by its shelving time running out.
    Unshelve,
    /// An alarm was taken out of service or returned to service.
    OutOfService,
    /// A tag was written (a command to the field).
    Write,
    /// A panel changed mode (manual/automatic).
    Mode,
    /// A panel's Reset was pressed.
    Reset,
    /// User administration (new, delete, block, password).
    User,
    /// A configuration change (alarm limits, dispatch settings).
    Config,
    /// A fault-isolation sequence step, trip or lockout.
    Sequence,
    /// A dispatch result or fallback.
    Dispatch,
    /// Communication with a device was lost or restored.
    Comm,
    /// Server start, stop and internal faults.
    Server,
}

impl EventType {
    pub const ALL: [EventType; 16] = [
        EventType::Login,
        EventType::Logout,
        EventType::LoginFailed,
        EventType::Ack,
        EventType::Shelve,
        EventType::Unshelve,
        EventType::OutOfService,
        EventType::Write,
        EventType::Mode,
        EventType::Reset,
        EventType::User,
        EventType::Config,
        EventType::Sequence,
        EventType::Dispatch,
        EventType::Comm,
        EventType::Server,
    ];

    pub fn as_str(self) -> &'static str {
        match self {
            EventType::Login => "login",
            EventType::Logout => "logout",
            EventType::LoginFailed => "login_failed",
            EventType::Ack => "ack",
            EventType::Shelve => "shelve",
            EventType::Unshelve => "unshelve",
            EventType::OutOfService => "out_of_service",
            EventType::Write => "write",
            EventType::Mode => "mode",
            EventType::Reset => "reset",
            EventType::User => "user",
            EventType::Config => "config",
            EventType::Sequence => "sequence",
            EventType::Dispatch => "dispatch",
            EventType::Comm => "comm",
            EventType::Server => "server",
        }
    }
}

impl fmt::Display for EventType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// A name that is not one of the [`EventType`]s (e.g. read back from a database
/// written by a newer version).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown event type '{0}'")]
pub struct UnknownEventType(pub String);

impl FromStr for EventType {
    type Err = UnknownEventType;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        EventType::ALL
            .iter()
            .copied()
            .find(|t| t.as_str() == s)
            .ok_or_else(|| UnknownEventType(s.to_owned()))
    }
}

/// One entry of the event log.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Event {
    pub time: Timestamp,
    /// The user who caused it; `None` for the system.
    pub user: Option<String>,
    /// What it concerns: a tag, a panel id, an alarm key, a device, "server".
    pub source: String,
    #[serde(rename = "type")]
    pub kind: EventType,
    pub message: String,
}

impl Event {
    /// A system event (no user).
    pub fn new(
        time: Timestamp,
        kind: EventType,
        source: impl Into<String>,
        message: impl Into<String>,
    ) -> Self {
        Event {
            time,
            user: None,
            source: source.into(),
            kind,
            message: message.into(),
        }
    }

    /// The same event, caused by `user`.
    pub fn by(mut self, user: impl Into<String>) -> Self {
        self.user = Some(user.into());
        self
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_match_serde() {
        for t in EventType::ALL {
            assert_eq!(t.as_str().parse::<EventType>().unwrap(), t);
            let json = serde_json::to_string(&t).unwrap();
            assert_eq!(json, format!("\"{}\"", t.as_str()));
        }
        assert_eq!(
            "nope".parse::<EventType>().unwrap_err().to_string(),
            "unknown event type 'nope'"
        );
    }

    #[test]
    fn event_serializes_with_type_field() {
        let e = Event::new(
            Timestamp::from_millis(5),
            EventType::Ack,
            "SS1.PA.V_L1:lo",
            "acknowledged",
        )
        .by("alice");
        let v: serde_json::Value = serde_json::to_value(&e).unwrap();
        assert_eq!(v["type"], "ack");
        assert_eq!(v["user"], "alice");
        assert_eq!(v["time"], 5);
    }
}
