//! # gridscada-iec104: IEC 60870-5-104
//!
//! **Owns:** the IEC 104 field protocol of gridscada: the controlling
//! station (client) of the plant's `protocol = "iec104"` devices
//! ([`client`]: connections, interrogation, clock sync, commands, the
//! points' samples and status tags), the controlled station toward a control
//! centre ([`server`]: `[iec104_server]`, exported tags and the centre's
//! audited commands), the APCI procedures of one connection
//! ([`session`]: k, w, t1-t3, pure), and the codec underneath. The codec
//! covers bytes on the wire of IEC 104: the APCI frames (I, S, U) with a
//! streaming decoder and the sequence-number arithmetic for k and w
//! ([`apci`]), the ASDU with its type identifications, causes of transmission
//! and information elements ([`asdu`], [`types`], [`element`]), and the
//! CP56Time2a time tag ([`time`]). Pure functions over buffers; decoders never
//! panic and say what is wrong, and where.
//!
//! **Must not touch:** other protocols' devices, configuration parsing (it
//! takes a checked plant), alarms, SQL, HTTP. The codec modules stay pure
//! (no sockets, timers or tags); `client` is their I/O shell.
//!
//! Why our own codec: the Rust IEC 104 crates on crates.io are unmaintained,
//! incomplete (no time-tagged types, no commands), or bind lib60870, which is
//! GPL; the codec itself is a few hundred lines of fixed-layout structures
//! (104's sizes: two-octet cause and common address, three-octet IOA).

pub mod apci;
pub mod asdu;
pub mod client;
pub mod element;
pub mod server;
pub mod session;
pub mod time;
pub mod types;

pub use apci::{
    decode, encode, seq_ack_valid, seq_add, seq_distance, Frame, FrameError, UFunction,
};
pub use asdu::{Asdu, AsduError, InformationObject};
pub use client::{Iec104Io, StartError};
pub use element::{normalized_from_f64, normalized_to_f64, DoublePoint, Element, Quality};
pub use server::{Iec104Server, ServerContext, ServerCounters};
pub use time::{Cp56Time2a, TimeError};
pub use types::{Cause, TypeId};
