//! # gridscada-iec61850: IEC 61850 MMS client (IEC 61850-8-1)
//!
//! **Owns:** gridscada's IEC 61850 client. The codec is pure and ours:
//! BER ([`ber`]), the OSI upper layers MMS rides on, TPKT/COTP/session/
//! presentation/ACSE ([`iso`]), MMS PDUs ([`mms`]) and the values they
//! carry with IEC 61850's quality and timestamps ([`data`]). Decoders
//! never panic, never allocate from an unchecked length, and say what is
//! wrong and where (octet offset).
//!
//! **Must not touch:** sockets, tokio, timers, tags or configuration
//! outside the I/O shell; SQL, HTTP.
//!
//! Why our own stack: libiec61850 is GPL and cannot be linked; the
//! permissively licensed Rust stacks (2026) are a few months old, 0.x and
//! single-author, and none of them is sans-I/O on the client side with
//! located decoding errors and the refusal causes (`AddCause`) IEC 61850
//! controls need. The subset a SCADA client uses is bounded: see
//! `docs/IEC61850.md` for what is built.

pub mod acsi;
pub mod ber;
pub mod client;
pub mod data;
pub mod iso;
pub mod mms;

pub use data::{Data, Quality, UtcTime};
pub use mms::{ObjectName, Pdu, Request, Response};
