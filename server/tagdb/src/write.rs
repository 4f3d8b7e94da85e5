//! The command path: how a write reaches the field.
//!
//! Control loops and the web API hold an `Arc<dyn TagWriter>`; the field I/O
//! layer implements it. A write answers only once the device's read-back
//! confirms the value (or with the error), so callers never act on a value the
//! field has not taken.

use std::future::Future;
use std::pin::Pin;

use crate::{Sample, Value};

tokio::task_local! {
    static ORIGINATOR: std::sync::Arc<str>;
}

/// Runs `write` on behalf of `who` (a user's name, or the system path a
/// command came by): protocols whose commands carry their originator
/// (IEC 61850's `orIdent`) read it with [`originator`].
pub async fn with_originator<F: Future>(who: &str, write: F) -> F::Output {
    ORIGINATOR.scope(std::sync::Arc::from(who), write).await
}

/// Who the write being made is for, if the caller said.
pub fn originator() -> Option<std::sync::Arc<str>> {
    ORIGINATOR.try_with(std::sync::Arc::clone).ok()
}

pub type WriteFuture<'a> = Pin<Box<dyn Future<Output = Result<Sample, WriteError>> + Send + 'a>>;

/// Writes a tag's value to its device and confirms it by reading back.
pub trait TagWriter: Send + Sync {
    /// Writes `value` (in engineering units) to tag `name`. Resolves to the
    /// confirmed sample from the read-back.
    fn write<'a>(&'a self, name: &'a str, value: Value) -> WriteFuture<'a>;

    /// Whether a write of `value` to `name` would be refused before it
    /// reaches the device by a rule of the server's (a safety tag, a
    /// switching interlock), without writing: for callers that must answer
    /// before they write (a control centre's select) or must not command
    /// what would be refused (the fault-isolation sequence).
    fn precheck(&self, _name: &str, _value: &Value) -> Result<(), WriteError> {
        Ok(())
    }
}

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum WriteError {
    #[error("unknown tag '{0}'")]
    UnknownTag(String),
    #[error("tag '{0}' is read-only")]
    ReadOnly(String),
    #[error("value {value} does not fit tag '{tag}': {reason}")]
    BadValue {
        tag: String,
        value: String,
        reason: String,
    },
    #[error(
        "{value} is outside the engineering limits of '{tag}' ({limits}); nothing was written"
    )]
    OutOfLimits {
        tag: String,
        value: String,
        /// In words, e.g. "0 to 100".
        limits: String,
    },
    #[error("device '{device}' did not take the write: {reason}")]
    Device { device: String, reason: String },
    #[error("read-back of '{tag}' gave {read_back}, not the written {written}")]
    Mismatch {
        tag: String,
        written: String,
        read_back: String,
    },
    #[error("write to '{0}' timed out")]
    Timeout(String),
    #[error("field I/O is shutting down")]
    Closed,
    /// This server of a redundant pair does not hold the lease.
    #[error("{0}")]
    NotActive(crate::NotActive),
    /// A switching operation refused by a safety tag or an interlock.
    #[error("{0}")]
    Blocked(Blocked),
}

/// A switching operation the server refuses: which rule, and why in words.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{operation} of {device} refused: {reason}")]
pub struct Blocked {
    /// The switching device's name.
    pub device: String,
    /// "open" or "close".
    pub operation: &'static str,
    /// The rule's id (safety_tag, closing_onto_earthed, ...).
    pub rule: &'static str,
    pub reason: String,
    /// A supervisor may override it.
    pub overridable: bool,
}

impl WriteError {
    /// Whether the server refused the write before it reached the device
    /// (unknown or read-only tag, a value that does not fit, outside the
    /// engineering limits, a standby server), as opposed to a write the
    /// device or the link failed. The audit trail and the counters tell the
    /// two apart (`write_refused`, `write_failed`).
    pub fn is_refusal(&self) -> bool {
        match self {
            WriteError::UnknownTag(_)
            | WriteError::ReadOnly(_)
            | WriteError::BadValue { .. }
            | WriteError::OutOfLimits { .. }
            | WriteError::NotActive(_)
            | WriteError::Blocked(_) => true,
            WriteError::Device { .. }
            | WriteError::Mismatch { .. }
            | WriteError::Timeout(_)
            | WriteError::Closed => false,
        }
    }
}
