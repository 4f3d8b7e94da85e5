//! The central Sparkplug B host (`[mqtt.host]`).
//!
//! Subscribes to `spBv1.0/GROUP/#`, builds remote tags from the births of
//! edge nodes into the tag database's reserved room (`sites.rs`, pure),
//! marks them Bad when a node or device dies, asks for a rebirth when `seq`
//! jumps or an alias is unknown, publishes its Sparkplug 3.0 `STATE`
//! (`link.rs`), and turns writes to remote tags into DCMD/NCMD confirmed by
//! the edge's next data (`writer.rs`). Figures for `/metrics`: `stats.rs`.

mod link;
mod sites;
mod stats;
mod writer;

pub use link::{Host, HostOptions, HostOutputs, SiteNotice};
pub use sites::{
    Effects, Problem, Remote, RemoteAlarms, Sites, SitesPolicy, DEVICE_OFFLINE, HOST_OFFLINE,
    PROP_ALARMS, REBIRTH, SITE_OFFLINE,
};
pub use stats::{HostStats, MESSAGE_KINDS};
pub use writer::RoutedWriter;

#[cfg(test)]
mod tests;
