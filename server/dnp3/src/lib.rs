//! # gridscada-dnp3: DNP3 (IEEE 1815-2012)
//!
//! **Owns:** the DNP3 master of gridscada, phase 1: the codec and the
//! master's procedures, pure. The codec covers the bytes on the wire: the
//! data link layer with its CRCs and a streaming, resynchronising decoder
//! ([`link`]), transport segmentation and reassembly ([`transport`]), the
//! application layer's headers, function codes, IIN and object headers
//! ([`app`]), the objects an outstation sends as a flat list of
//! measurements with their flags, quality and time, and the command echoes
//! with their status codes ([`objects`]), and the requests a master sends
//! ([`request`]). [`master`] sequences one outstation's session (startup,
//! integrity and event polls, unsolicited responses, confirmations, IIN
//! handling, time sync, select-before-operate) as a state machine over
//! events and a clock. Decoders never panic, never allocate from an
//! unchecked length, and say what is wrong and where (octet offset, object
//! group/variation, index).
//!
//! [`client`] is the I/O shell: one tokio task per configured outstation
//! that connects over TCP, feeds [`master::Master`] and carries out its
//! actions, with the samples, status tags, figures and commands through
//! `gridscada-field` and the tag database.
//!
//! The other side, for gridscada's simulated outstations: [`outstation`]
//! is an outstation's procedures, pure (static and event objects, class
//! reads, confirmations, unsolicited responses, multi-fragment responses,
//! select-before-operate), and [`server`] its I/O shell over a tag database.
//!
//! **Must not touch:** sockets, tokio, timers, tags or configuration
//! outside [`client`] and [`server`]; SQL, HTTP.
//!
//! Why our own codec: the Rust DNP3 crate on crates.io (stepfunc `dnp3`)
//! is under a non-commercial licence, and opendnp3's bindings need C++
//! builds; the protocol is fixed-layout structures, a few hundred lines each.

pub mod app;
pub mod client;
pub mod link;
pub mod master;
pub mod objects;
pub mod outstation;
pub mod request;
pub mod server;
pub mod transport;

pub use app::{Control, FunctionCode, Iin, ObjectHeader, Range};
pub use client::{Dnp3Io, StartError};
pub use link::{LinkError, LinkFrame, LinkFunction};
pub use master::{Action, Clock, Master, MasterConfig};
pub use objects::{
    CommandEcho, CommandObject, CommandStatus, Crob, DoubleBit, Flags, Measurement,
    MeasurementKind, Quality, Value,
};
pub use transport::{Reassembler, TransportError};

#[cfg(test)]
pub(crate) mod test_util {
    /// Octets from "05 64 ..." (whitespace separated hex).
    pub fn hex(s: &str) -> Vec<u8> {
        s.split_whitespace()
            .map(|b| u8::from_str_radix(b, 16).unwrap())
            .collect()
    }
}
