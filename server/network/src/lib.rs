//! # gridscada-network: the switching network
//!
//! **Owns:** the network model compiled from the configuration (sections,
//! switching devices, transformers, sources, loads: [`model`]), the topology
//! processor that colours each section energised, dead, earthed or unknown
//! from the switches' live states ([`topology`]), the effect of one switching
//! operation ([`preview`]) and the switching interlock rules ([`rules`]).
//! All of it is pure: state and time come in as arguments. Two thin shells
//! run it live: the topology driver ([`driver`]) and the switching guard
//! ([`guard`]) every command passes, which refuses what a safety tag
//! ([`safety`]), another operator's selection ([`selection`]) or an
//! interlock forbids. Switching programmes are checked step by step against
//! the topology ([`programme`]). What stands wrong in the network however it
//! came about (an earth switch closed on a live section, sources in a
//! forbidden parallel) is a system alarm ([`alarms`]).
//!
//! **Must not touch:** field protocols, SQL or HTTP. The live shell reads
//! switch states from the tag database and publishes section states back as
//! tags; commands go out through the stack's `TagWriter` like every other.

pub mod alarms;
pub mod driver;
mod dsu;
pub mod guard;
pub mod model;
pub mod plant;
pub mod preview;
pub mod programme;
pub mod rules;
pub mod safety;
pub mod selection;
pub mod topology;

pub use alarms::NetworkAlarm;
pub use driver::{network_tags, section_tag, Live, TopologyDriver};
pub use guard::SwitchingGuard;
pub use model::{
    BranchKind, BranchSpec, BuildError, LoadSpec, Model, NodeSpec, ParallelRule, SecIdx,
    SourceSpec, Spec, SwitchKind, SwitchSpec,
};
pub use plant::Network;
pub use preview::{preview, Preview};
pub use rules::{interlocks, Interlock, Operation, RuleId};
pub use safety::{SafetyTag, SafetyTags, TagKind};
pub use selection::{Override, SelectRefused, Selection, Selections};
pub use topology::{compute, Inputs, Parallel, Pos, SectionState, Topology, Unknown};
