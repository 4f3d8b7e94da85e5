//! # gridscada-config: the plant configuration
//!
//! **Owns:** the TOML schema of `gridscada.toml` and the tag files ([`model`]),
//! loading them from disk or from embedded text, and validation that reports
//! every problem with file, line and column ([`Diagnostic`]); the
//! `GRIDSCADA_*` environment overrides of secrets, addresses and the data
//! folder ([`apply_env`]).
//!
//! **Must not touch:** anything live. It reads text and returns a checked
//! [`Plant`]; it opens no sockets, starts no tasks and knows nothing of how the
//! other crates use the configuration beyond the rules they need checked.

pub mod daily;
mod diag;
mod load;
pub mod model;
mod overrides;
pub mod screen;
mod validate;

pub use diag::{Diagnostic, SourceFile};
pub use load::{load_path, load_with, Plant, TlsFiles};
pub use model::*;
pub use overrides::{apply_env, has_plaintext_password, EnvVar, Warning, ENV_VARS};
pub use validate::iec61850::{parse_hex, parse_oid, rcb_parts};
