//! The integration tests of this crate, in one test binary: one link and
//! one set of generic instances instead of one per file, which is most of
//! the suite's build time on two cores. A new test file goes in this folder
//! and gets a `mod` line here; run one with `cargo test --test it NAME`.

#[macro_use]
mod common;

mod audit_spool;
mod durability;
mod exports;
mod lease;
mod notifications;
mod programmes;
mod rollups;
mod sessions;
mod store;
mod upgrade;
