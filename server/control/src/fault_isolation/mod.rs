//! OLUC/OLDC automatic fault isolation of LV substation panels.
//!
//! **Owns:** the sequence of each panel: a pure state machine ([`Sequence`],
//! in `machine/`) and a thin async driver ([`run_panel`], in `driver.rs`)
//! that feeds it snapshots of the panel's tags, runs its timers on the plant
//! [`Clock`](gridscada_tagdb::Clock), writes its commands through a
//! [`TagWriter`](gridscada_tagdb::TagWriter), publishes a [`PanelStatus`] and
//! the derived `{prefix}.Seq.*` tags, and reports [`PanelNotice`]s (events and
//! alarm conditions).
//!
//! **Must not touch:** Modbus, SQL, HTTP or roles. The web layer checks roles
//! before a [`PanelCommand`] arrives; the application wires notices to the
//! alarm engine and the event store.

mod driver;
mod machine;

#[cfg(test)]
mod driver_tests;
#[cfg(test)]
mod machine_async_tests;
#[cfg(test)]
mod machine_tests;

pub use driver::{
    panel_tags, run_panel, BreakerStatus, DriverError, PanelCommand, PanelCommandKind, PanelNotice,
    PanelStatus,
};
pub use machine::{
    priority, Breaker, CommandError, Input, Metrics, Mode, OperatorCommand, Outcome, Output,
    PanelState, Progress, Reading, Retained, Sequence, Settings, Snapshot, Step, Takeover, Timer,
    ELCB_TRIP_ALARM,
};
