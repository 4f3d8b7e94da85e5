//! The integration tests of this crate, in one test binary: one link and
//! one set of generic instances instead of one per file, which is most of
//! the suite's build time on two cores. A new test file goes in this folder
//! and gets a `mod` line here; run one with `cargo test --test it NAME`.

mod broken_configs;
mod lookup;
mod mqtt_host;
mod network;
mod notify;
mod redundancy_config;
mod reports;
mod settings;
mod suppression;
mod tls;
