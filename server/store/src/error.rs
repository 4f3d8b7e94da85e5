//! Errors of the store. Each names what was being done, so an operator's log
//! line says "inserting alarm transitions: ..." rather than a bare driver error.
//! The driver's error is kept as an opaque source: no sqlx type leaks out.

use std::error::Error as StdError;

#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    /// The storage URL is not one we can open.
    #[error("storage URL '{url}': {reason}")]
    Url { url: String, reason: String },
    /// Opening or migrating the database failed.
    #[error("opening {what}: {source}")]
    Open {
        what: String,
        #[source]
        source: Box<dyn StdError + Send + Sync>,
    },
    /// A query failed (connection lost, disk full, constraint...).
    #[error("{context}: {source}")]
    Database {
        context: &'static str,
        #[source]
        source: Box<dyn StdError + Send + Sync>,
    },
    /// The request itself is wrong (empty tag name, reversed time range...).
    #[error("invalid request: {0}")]
    Invalid(String),
    /// A row with that unique key already exists (e.g. a user name).
    #[error("already exists: {0}")]
    Conflict(String),
    /// The row to change does not exist.
    #[error("not found: {0}")]
    NotFound(String),
    /// The database holds something this version cannot read.
    #[error("unreadable row: {0}")]
    Corrupt(String),
    /// Writing an export failed.
    #[error("writing {what}: {source}")]
    Io {
        what: &'static str,
        #[source]
        source: std::io::Error,
    },
}

/// Maps a driver error to [`StoreError::Database`] with a context.
pub(crate) fn db(context: &'static str) -> impl FnOnce(sqlx::Error) -> StoreError {
    move |e| StoreError::Database {
        context,
        source: Box::new(e),
    }
}

/// Whether a driver error is a unique-constraint violation.
pub(crate) fn is_unique_violation(e: &sqlx::Error) -> bool {
    match e {
        sqlx::Error::Database(d) => d.is_unique_violation(),
        _ => false,
    }
}
