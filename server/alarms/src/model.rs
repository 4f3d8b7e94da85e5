//! The plain data types of the alarm system: kinds, ISA-18.2 states, the
//! transition records that make up alarm history, the state records that let
//! acknowledgements and shelving survive a restart, views for the HMI, filters
//! and errors.
//!
//! **Owns:** types only. No logic beyond small helpers; no I/O.

use std::fmt;
use std::str::FromStr;

use gridscada_tagdb::{Timestamp, Value};
use serde::{Deserialize, Serialize};

/// Dense, stable-within-a-run numeric id of an alarm (its index). Alarms from
/// the configuration get the same ids on every start with the same
/// configuration; keys ([`AlarmView::key`]) are stable across configuration
/// changes and are what persistence uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(transparent)]
pub struct AlarmId(pub u32);

impl AlarmId {
    pub fn index(self) -> usize {
        self.0 as usize
    }
}

impl fmt::Display for AlarmId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.0)
    }
}

/// What raises an alarm.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AlarmKind {
    HiHi,
    Hi,
    Lo,
    LoLo,
    /// A discrete state (a breaker tripped, a door open, a unit fault).
    Discrete,
    /// Communication with a device lost.
    CommFail,
    /// Raised by another part of the server (sequence lockout, dispatch
    /// fallback, historian overflow).
    System,
}

impl AlarmKind {
    pub const ALL: [AlarmKind; 7] = [
        AlarmKind::HiHi,
        AlarmKind::Hi,
        AlarmKind::Lo,
        AlarmKind::LoLo,
        AlarmKind::Discrete,
        AlarmKind::CommFail,
        AlarmKind::System,
    ];

    pub fn as_str(self) -> &'static str {
        match self {
            AlarmKind::HiHi => "hihi",
            AlarmKind::Hi => "hi",
            AlarmKind::Lo => "lo",
            AlarmKind::LoLo => "lolo",
            AlarmKind::Discrete => "discrete",
            AlarmKind::CommFail => "comm_fail",
            AlarmKind::System => "system",
        }
    }
}

impl fmt::Display for AlarmKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl FromStr for AlarmKind {
    type Err = AlarmError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        AlarmKind::ALL
            .iter()
            .copied()
            .find(|k| k.as_str() == s)
            .ok_or_else(|| AlarmError::UnknownName {
                what: "alarm kind",
                name: s.to_owned(),
            })
    }
}

/// The state an alarm is shown in (ISA-18.2 / IEC 62682).
///
/// The first four are the process states, from whether the condition is
/// active and whether the operator has acknowledged. The last three take an
/// alarm out of annunciation; while in them the process condition is still
/// tracked (see [`AlarmView::active`]) and recorded in history.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AlarmState {
    /// Condition clear, nothing to acknowledge.
    Normal,
    /// Condition active, not yet acknowledged.
    UnackActive,
    /// Condition active, acknowledged.
    AckActive,
    /// Condition returned to normal before it was acknowledged.
    UnackRtn,
    /// Shelved by an operator for a limited time.
    Shelved,
    /// Suppressed by design: a rule hides it while another alarm stands.
    Suppressed,
    /// Taken out of service (e.g. instrument under maintenance).
    OutOfService,
}

impl AlarmState {
    pub const ALL: [AlarmState; 7] = [
        AlarmState::Normal,
        AlarmState::UnackActive,
        AlarmState::AckActive,
        AlarmState::UnackRtn,
        AlarmState::Shelved,
        AlarmState::Suppressed,
        AlarmState::OutOfService,
    ];

    pub fn as_str(self) -> &'static str {
        match self {
            AlarmState::Normal => "normal",
            AlarmState::UnackActive => "unack_active",
            AlarmState::AckActive => "ack_active",
            AlarmState::UnackRtn => "unack_rtn",
            AlarmState::Shelved => "shelved",
            AlarmState::Suppressed => "suppressed",
            AlarmState::OutOfService => "out_of_service",
        }
    }

    /// Whether an alarm in this state waits for an acknowledgement.
    pub fn is_unacked(self) -> bool {
        matches!(self, AlarmState::UnackActive | AlarmState::UnackRtn)
    }

    /// The states of the ordinary alarm list: active or unacknowledged.
    pub fn is_annunciated(self) -> bool {
        matches!(
            self,
            AlarmState::UnackActive | AlarmState::AckActive | AlarmState::UnackRtn
        )
    }
}

impl fmt::Display for AlarmState {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl FromStr for AlarmState {
    type Err = AlarmError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        AlarmState::ALL
            .iter()
            .copied()
            .find(|k| k.as_str() == s)
            .ok_or_else(|| AlarmError::UnknownName {
                what: "alarm state",
                name: s.to_owned(),
            })
    }
}

/// Why a transition happened. Recorded with each history row, because the
/// states alone do not tell: an activation or a return while the alarm is
/// suppressed (or shelved, or out of service) leaves the displayed state as
/// it was ("Suppressed → Suppressed"); the cause says which it was.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TransitionCause {
    /// The condition became active (after its on-delay).
    Activate,
    /// The condition cleared (past the deadband, after its off-delay).
    Return,
    Ack,
    Shelve,
    Unshelve,
    /// The shelving time ran out.
    ShelveExpired,
    Suppress,
    Unsuppress,
    OutOfService,
    InService,
}

impl TransitionCause {
    pub const ALL: [TransitionCause; 10] = [
        TransitionCause::Activate,
        TransitionCause::Return,
        TransitionCause::Ack,
        TransitionCause::Shelve,
        TransitionCause::Unshelve,
        TransitionCause::ShelveExpired,
        TransitionCause::Suppress,
        TransitionCause::Unsuppress,
        TransitionCause::OutOfService,
        TransitionCause::InService,
    ];

    pub fn as_str(self) -> &'static str {
        match self {
            TransitionCause::Activate => "activate",
            TransitionCause::Return => "return",
            TransitionCause::Ack => "ack",
            TransitionCause::Shelve => "shelve",
            TransitionCause::Unshelve => "unshelve",
            TransitionCause::ShelveExpired => "shelve_expired",
            TransitionCause::Suppress => "suppress",
            TransitionCause::Unsuppress => "unsuppress",
            TransitionCause::OutOfService => "out_of_service",
            TransitionCause::InService => "in_service",
        }
    }
}

impl fmt::Display for TransitionCause {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl FromStr for TransitionCause {
    type Err = AlarmError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        TransitionCause::ALL
            .iter()
            .copied()
            .find(|k| k.as_str() == s)
            .ok_or_else(|| AlarmError::UnknownName {
                what: "transition cause",
                name: s.to_owned(),
            })
    }
}

/// One alarm state change: a row of alarm history.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AlarmTransition {
    pub time: Timestamp,
    pub id: AlarmId,
    pub key: String,
    pub tag: Option<String>,
    pub kind: AlarmKind,
    pub cause: TransitionCause,
    pub from: AlarmState,
    pub to: AlarmState,
    /// The process condition after the transition.
    pub active: bool,
    /// Whether the alarm was annunciated (not shelved, suppressed or out of
    /// service) after the transition.
    pub annunciated: bool,
    /// The tag's value at the transition, if any.
    pub value: Option<Value>,
    /// The limit (analog) or alarm value (discrete), if any.
    pub limit: Option<Value>,
    /// The user who caused it (ack, shelve...); `None` for the process.
    pub user: Option<String>,
    pub priority: u32,
    pub selection: String,
    /// The alarm message, with value and limit substituted at activation.
    pub message: String,
}

impl AlarmTransition {
    /// Whether this is an activation the operator was shown: what the
    /// ISA-18.2 rate metrics count.
    pub fn is_annunciated_activation(&self) -> bool {
        self.cause == TransitionCause::Activate && self.annunciated
    }
}

/// The persistent state of one alarm, so that active conditions,
/// acknowledgements, shelving and out-of-service survive a restart. Flat so
/// the store can keep it as one row keyed by `key`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AlarmStateRecord {
    pub key: String,
    pub kind: AlarmKind,
    /// The displayed state when recorded (informative; `active` and `acked`
    /// are what restore uses).
    pub state: AlarmState,
    pub active: bool,
    pub acked: bool,
    pub active_since: Option<Timestamp>,
    pub last_change: Timestamp,
    pub message: String,
    /// Kept so system alarms can be recreated on restore.
    pub priority: u32,
    pub selection: String,
    pub shelved_by: Option<String>,
    pub shelved_at: Option<Timestamp>,
    pub shelved_until: Option<Timestamp>,
    pub shelve_reason: Option<String>,
    pub out_of_service: bool,
    pub out_of_service_by: Option<String>,
    pub out_of_service_since: Option<Timestamp>,
    pub out_of_service_reason: Option<String>,
    #[serde(default)]
    pub out_of_service_until: Option<Timestamp>,
    /// The tag's value at the latest activation (what the message's `{value}`
    /// shows), kept after the alarm clears, so the alarm list can label it
    /// beside the value now also after a restart.
    #[serde(default)]
    pub activation_value: Option<Value>,
}

/// Who shelved an alarm, why, and until when.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct ShelveInfo {
    pub by: String,
    pub reason: String,
    pub since: Timestamp,
    pub until: Timestamp,
}

/// Who took an alarm out of service, why, since when and until when.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct ServiceInfo {
    pub by: String,
    pub reason: String,
    pub since: Timestamp,
    /// When it returns to service by itself; `None`: only by hand.
    #[serde(default)]
    pub until: Option<Timestamp>,
}

/// An alarm as the alarm list shows it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AlarmView {
    pub id: AlarmId,
    pub key: String,
    pub tag: Option<String>,
    pub kind: AlarmKind,
    pub state: AlarmState,
    /// The process condition (also while shelved, suppressed or out of service).
    pub active: bool,
    /// False while an acknowledgement is pending.
    pub acked: bool,
    pub priority: u32,
    pub selection: String,
    pub message: String,
    /// The tag's latest value (the value now).
    pub value: Option<Value>,
    /// The value in the tag's words (`states`), e.g. `TRIPPED`.
    pub value_text: Option<String>,
    /// The tag's value at the latest activation: the value the message
    /// shows (its `{value}` is substituted at activation), kept after the
    /// alarm clears. `None` if it never activated since it was recorded.
    pub activation_value: Option<Value>,
    /// [`AlarmView::activation_value`] in the tag's words.
    pub activation_value_text: Option<String>,
    pub limit: Option<Value>,
    pub units: String,
    pub active_since: Option<Timestamp>,
    /// The latest activation, kept after the alarm clears ("Since" in a list).
    pub activated_at: Option<Timestamp>,
    /// When the condition cleared; `None` while active.
    pub cleared_at: Option<Timestamp>,
    /// The time of the latest transition (what "newest" means for Ack Top).
    pub last_change: Timestamp,
    pub shelved: Option<ShelveInfo>,
    pub out_of_service: Option<ServiceInfo>,
    pub suppressed: bool,
}

/// Which alarms a summary or a bulk acknowledgement covers. Every set field
/// must match.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct AlarmFilter {
    /// Selection (alarm group), case-insensitive exact match.
    pub selection: Option<String>,
    /// Least priority shown.
    pub min_priority: Option<u32>,
    /// States shown. Empty: the ordinary alarm list (unacknowledged or
    /// active: [`AlarmState::is_annunciated`]). Shelved, suppressed and
    /// out-of-service alarms are only listed when asked for here.
    pub states: Vec<AlarmState>,
    /// Case-insensitive text searched in the key, tag, message and selection.
    pub text: Option<String>,
}

impl AlarmFilter {
    pub fn matches(&self, v: &AlarmView) -> bool {
        let state_ok = if self.states.is_empty() {
            v.state.is_annunciated()
        } else {
            self.states.contains(&v.state)
        };
        if !state_ok {
            return false;
        }
        if let Some(p) = self.min_priority {
            if v.priority < p {
                return false;
            }
        }
        if let Some(sel) = &self.selection {
            if !v.selection.eq_ignore_ascii_case(sel.trim()) {
                return false;
            }
        }
        if let Some(text) = &self.text {
            let needle = text.trim().to_lowercase();
            if !needle.is_empty() {
                let hay = [
                    Some(v.key.as_str()),
                    v.tag.as_deref(),
                    Some(v.message.as_str()),
                    Some(v.selection.as_str()),
                ];
                if !hay
                    .iter()
                    .flatten()
                    .any(|h| h.to_lowercase().contains(&needle))
                {
                    return false;
                }
            }
        }
        true
    }
}

/// Errors of alarm operations and configuration.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum AlarmError {
    #[error("no alarm with id {0}")]
    UnknownId(AlarmId),
    #[error("no alarm with key '{0}'")]
    UnknownKey(String),
    #[error("alarm key '{0}' is used twice")]
    DuplicateKey(String),
    #[error("alarm '{key}' is a {kind} alarm; only system alarms can be raised and cleared through the API")]
    NotSystem { key: String, kind: AlarmKind },
    #[error("{what}: {reason}")]
    Invalid { what: String, reason: String },
    #[error("unknown {what} '{name}'")]
    UnknownName { what: &'static str, name: String },
    #[error("alarm '{0}' is not shelved")]
    NotShelved(String),
    #[error("suppression rule '{rule}': no alarm with key '{key}' to trigger it")]
    UnknownTrigger { rule: String, key: String },
    #[error("too many alarms (at most {} are supported)", u32::MAX)]
    TooMany,
}

impl AlarmError {
    pub(crate) fn invalid(what: impl Into<String>, reason: impl Into<String>) -> Self {
        AlarmError::Invalid {
            what: what.into(),
            reason: reason.into(),
        }
    }
}

// --- alarm keys (stable names, persisted and used in the API) ---------------

/// The key of a tag's limit alarm, e.g. `SS1.PA.V_L1:lo`.
pub fn limit_key(tag: &str, kind: AlarmKind) -> String {
    format!("{tag}:{kind}")
}

/// The key of a tag's `index`-th discrete alarm: `TAG:discrete` for the first,
/// `TAG:discrete2`, `TAG:discrete3`... for further ones (so adding one does
/// not rename the first).
pub fn discrete_key(tag: &str, index: usize) -> String {
    if index == 0 {
        format!("{tag}:discrete")
    } else {
        format!("{tag}:discrete{}", index + 1)
    }
}

/// The key of a device's communication-failure alarm, e.g. `SS1.IO1:comm`.
pub fn comm_key(device: &str) -> String {
    format!("{device}:comm")
}
