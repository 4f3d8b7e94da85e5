//! The integration tests of this crate, in one test binary: one link and
//! one set of generic instances instead of one per file, which is most of
//! the suite's build time on two cores. A new test file goes in this folder
//! and gets a `mod` line here; run one with `cargo test --test it NAME`.

#[macro_use]
mod common;

mod alarms_end_to_end;
mod cli;
mod dispatch_full_stack;
mod fault_isolation_full_stack;
mod fault_isolation_telecontrol;
mod field_faults;
mod own_plant;
mod pair_database_restart;
mod redundant_pair;
mod replay;
mod restart_kill9;
mod restart_mid_sequence;
mod sessions_restart;
mod settings_cli;
mod suppression_end_to_end;
mod training;
mod two_sites;
