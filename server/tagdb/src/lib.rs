//! # gridscada-tagdb: the tag model and the in-memory tag database
//!
//! **Owns:** what a tag *is* (name, description, value kind, units), its live
//! [`Sample`] (value, [`Quality`], source [`Timestamp`]), the [`TagDb`] that holds
//! the current sample of every tag, change subscription, the plant [`Clock`], and
//! the [`TagWriter`] interface through which commands reach the field.
//!
//! **Must not touch:** sockets, files, SQL, Modbus. This crate does no I/O; the
//! poller pushes batches in, subscribers (alarms, historian, HMI push, control
//! loops) read changes out, and commands go out through a [`TagWriter`] that the
//! field I/O layer implements.

mod clock;
mod db;
mod leadership;
mod value;
mod write;

pub use clock::{CivilTime, Clock, ScaledClock, SleepFuture, SystemClock, Timestamp};
pub use db::{ChangeBatch, Subscription, TagDb, TagDbError, TagId, TagMeta, Update};
pub use leadership::{Leadership, NotActive, Role};
pub use value::{Quality, QualityCode, Sample, Value, ValueKind, NEVER_READ};
pub use write::{originator, with_originator, Blocked, TagWriter, WriteError, WriteFuture};
