//! The command path: how a write reaches the field.
//!
//! Control loops and the web API hold an `Arc<dyn TagWriter>`; the field I/O
//! layer implements it. A write answers only once the device's read-back
//! confirms the value (or with the error), so callers never act on a value the
//! field has not taken.

use std::future::Future;
use std::pin::Pin;

use crate::{Sample, Value};

pub type WriteFuture<'a> = Pin<Box<dyn Future<Output = Result<Sample, WriteError>> + Send + 'a>>;

/// Writes a tag's value to its device and confirms it by reading back.
pub trait TagWriter: Send + Sync {
    /// Writes `value` (in engineering units) to tag `name`. Resolves to the
    /// confirmed sample from the read-back.
    fn write<'a>(&'a self, name: &'a str, value: Value) -> WriteFuture<'a>;
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
            | WriteError::NotActive(_) => true,
            WriteError::Device { .. }
            | WriteError::Mismatch { .. }
            | WriteError::Timeout(_)
            | WriteError::Closed => false,
        }
    }
}
