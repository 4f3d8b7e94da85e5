//! Daily and monthly reports: energy per panel, zone and microgrid unit
//! (with renewable share, diesel fuel and run hours, battery throughput and
//! cycles, cost), alarms (counts by priority, top alarms, time to
//! acknowledge) and outages (interruptions per zone with energy not supplied,
//! SAIDI/SAIFI-style figures per panel), as HTML (with a print stylesheet),
//! CSV and JSON, generated on demand or on a schedule into `DATA/reports/`.
//!
//! **Owns:** the figures (`figures.rs`, pure, over step-held series from
//! `series.rs`), reading what they need from the store (`gather.rs`), the
//! report's pages (`render.rs`), the report folder and the schedule
//! (`archive.rs`).
//!
//! **Must not touch:** SQL (it calls the store's API), HTTP (the web layer
//! serves the files), Modbus, the alarm engine or the control loops: a
//! report only reads what was recorded.

pub mod archive;
pub mod figures;
pub mod gather;
pub mod period;
pub mod render;
pub mod series;

use serde::Serialize;

pub use archive::{Archive, ReportEntry, Schedule};
pub use figures::{AlarmFigures, Energy, Outages};
pub use gather::{generate, ReportError};
pub use period::{BadPeriod, Period};

/// One report: its period, when it was made, and its figures.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Report {
    /// The site it reports on: `[server] site`, else the main file's name.
    pub site: String,
    /// `[reports] currency`: the ISO 4217 code of every cost; `None`: the
    /// prices' own unit ("cost units").
    pub currency: Option<String>,
    pub period: Period,
    /// Its id: `2024-06-21` or `2024-06`.
    pub id: String,
    /// ms since the epoch.
    pub from: i64,
    pub to: i64,
    pub generated_at: i64,
    pub energy: Energy,
    pub alarms: AlarmFigures,
    pub outages: Outages,
}

impl Report {
    /// "Daily report 2024-06-21".
    pub fn title(&self) -> String {
        format!("{} {}", self.period.label(), self.id)
    }

    /// Nothing was recorded in the period: no sample of any tag the report
    /// reads, no alarm.
    pub fn is_empty(&self) -> bool {
        self.energy.panels.iter().all(|p| p.coverage == 0.0)
            && self.energy.units.iter().all(|u| u.coverage == 0.0)
            && self.energy.demand_kwh.is_none()
            && self.outages.panels.iter().all(|p| p.coverage == 0.0)
            && self.alarms.activations == 0
    }
}
