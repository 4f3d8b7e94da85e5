//! The integration tests of this crate, in one test binary: one link and
//! one set of generic instances instead of one per file, which is most of
//! the suite's build time on two cores. A new test file goes in this folder
//! and gets a `mod` line here; run one with `cargo test --test it NAME`.

mod fuzz;
mod master;
mod outstation;
mod outstation_machine;
mod outstation_py1815;
mod peers;
