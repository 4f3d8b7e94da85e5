//! # gridscada-iec104: the IEC 60870-5-104 codec
//!
//! **Owns:** bytes on the wire of IEC 104: the APCI frames (I, S, U) with a
//! streaming decoder and the sequence-number arithmetic for k and w
//! ([`apci`]), the ASDU with its type identifications, causes of transmission
//! and information elements ([`asdu`], [`types`], [`element`]), and the
//! CP56Time2a time tag ([`time`]). Pure functions over buffers; decoders never
//! panic and say what is wrong, and where.
//!
//! **Must not touch:** sockets, timers, tokio, tags. The link layer (t1/t2/t3,
//! k/w windows, STARTDT) and the mapping to tags live elsewhere and feed this
//! crate bytes.
//!
//! Why our own codec: the Rust IEC 104 crates on crates.io are unmaintained,
//! incomplete (no time-tagged types, no commands), or bind lib60870, which is
//! GPL; the codec itself is a few hundred lines of fixed-layout structures
//! (104's sizes: two-octet cause and common address, three-octet IOA).

pub mod apci;
pub mod asdu;
pub mod element;
pub mod time;
pub mod types;

pub use apci::{
    decode, encode, seq_ack_valid, seq_add, seq_distance, Frame, FrameError, UFunction,
};
pub use asdu::{Asdu, AsduError, InformationObject};
pub use element::{normalized_from_f64, normalized_to_f64, DoublePoint, Element, Quality};
pub use time::{Cp56Time2a, TimeError};
pub use types::{Cause, TypeId};
