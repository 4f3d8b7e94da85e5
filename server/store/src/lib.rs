//! # gridscada-store: persistence, and the only crate that speaks SQL
//!
//! **Owns:** the database schema (one logical schema, two backends: SQLite
//! embedded by default, PostgreSQL for large or shared sites), its migrations,
//! and every query: historian samples, the event log, alarm states and alarm
//! history, users and screen access, login sessions, dispatch records. Also the historian's
//! logging policy ([`Recorder`], pure) and its bounded writer task
//! ([`Historian`]), and the audit trail's writer with its spool
//! ([`AuditTrail`]).
//!
//! **Must not touch:** plant logic (alarm state machine, fault isolation,
//! dispatch), sockets other than the database's, and the tag database's live
//! values. No `sqlx` type appears in the public API, so callers never depend on
//! the driver.
//!
//! ## Durability
//! SQLite runs in WAL mode with `synchronous=NORMAL` by default: every commit is
//! appended to the WAL before the call returns, so a process crash (kill -9,
//! panic, OOM kill) loses nothing that was reported committed; only an OS crash
//! or power cut can lose the last commits since the last WAL sync, and even then
//! the database stays consistent. That keeps historian ingest fast on SD cards
//! and cheap SSDs. Sites without a UPS that want power-cut durability for every
//! commit choose [`SqliteSync::Full`] in [`OpenOptions`].

/// Runs `$body` with `$p` bound to the pool of the store's backend: for SQLite
/// the single writer connection (`writer`) or the read pool (`reader`); for
/// PostgreSQL the one pool. The body is expanded once per backend, so it is
/// type-checked against each driver.
macro_rules! on_backend {
    ($store:expr, $role:ident, |$p:ident| $body:expr) => {
        match &$store.inner.backend {
            $crate::store::Backend::Sqlite(s) => {
                let $p = s.$role();
                $body
            }
            $crate::store::Backend::Postgres(pool) => {
                let $p = pool;
                $body
            }
        }
    };
    // SQLite's writer or reader pool by a condition (PostgreSQL has one).
    ($store:expr, if $c:expr => $yes:ident else $no:ident, |$p:ident| $body:expr) => {
        match &$store.inner.backend {
            $crate::store::Backend::Sqlite(s) => {
                let $p = if $c { s.$yes() } else { s.$no() };
                $body
            }
            $crate::store::Backend::Postgres(pool) => {
                let $p = pool;
                $body
            }
        }
    };
}

mod alarms;
mod audit;
pub mod command;
mod csv;
mod dispatch;
mod error;
mod events;
mod exports;
mod historian;
mod lease;
mod notifications;
mod open_minutes;
mod panels;
mod programmes;
mod recorder;
mod report_samples;
mod rollup;
mod safety_tags;
mod screens;
#[macro_use]
mod sessions;
mod spool;
mod store;
mod users;
mod writer;

pub use alarms::{
    ActivationCount, AlarmHistoryFilter, AlarmStateRecord, AlarmTransition, AlarmTransitionRecord,
};
pub use audit::{AuditBody, AuditRecord, AuditTable};
pub use csv::field as csv_field;
pub use dispatch::{DispatchRecord, NewDispatch};
pub use error::StoreError;
pub use events::{Event, EventFilter, NewEvent};
pub use historian::{
    quality_from_code, quality_to_code, HistorySample, RawSample, RetentionPolicy, TagTrend,
    TrendBucket, MAX_TREND_BUCKETS,
};
pub use lease::{Fence, Lease, LeaseState};
pub use notifications::{LastNotified, NewNotification, Notification, NotificationStatus};
pub use programmes::{ProgrammeChange, ProgrammeRecord};
pub use recorder::{RecordPolicy, Recorder};
pub use safety_tags::SafetyTagRecord;
pub use screens::{ScreenRecord, MAX_SCREEN_BYTES};
pub use sessions::{SessionKey, SessionRecord, TicketRecord};
pub use spool::{
    read_spool, AuditConfig, AuditError, AuditHandle, AuditMetrics, AuditTrail, SpoolContents,
    SPOOL_FILE,
};
pub use store::{BackendKind, OpenOptions, SqliteSync, Store, DEFAULT_SITE};
pub use users::{NewUser, User, UserSummary};
pub use writer::{Historian, HistorianConfig, HistorianHandle, HistorianMetrics};

/// Result of every store call.
pub type Result<T, E = StoreError> = std::result::Result<T, E>;
