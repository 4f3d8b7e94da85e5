//! # Scenario replay: the scenario file format
//!
//! **Owns:** reading a scenario (TOML, with CSV profiles for long series)
//! into a checked [`Scenario`] with located errors ([`load_path`],
//! [`parse`]); checking its names against a plant ([`Scenario::check_against`]);
//! the values of its profiles at any offset; its timeline of events; judging
//! its expectations ([`expect`]); and the replay report model and its
//! single-file HTML rendering ([`report`], [`html`]). The format is
//! documented in `docs/SCENARIOS.md`.
//!
//! **Must not touch:** anything live. Nothing here starts a simulator, a
//! clock or a socket, and the only I/O is reading the scenario and its CSV
//! files. The runner (`gridscada replay`, in the app crate) drives the stack.

pub mod expect;
pub mod html;
mod parse;
pub mod report;
pub mod series;
pub mod time;

use std::path::PathBuf;
use std::time::Duration;

use gridscada_config::PanelMode;
use gridscada_tagdb::Timestamp;
use serde::Serialize;

pub use expect::{Bound, ExpectKind, ExpectValue, Expectation};
pub use parse::{load_path, parse, FIGURE_NAMES, PANEL_FIGURE_NAMES};
pub use series::{Interpolate, Series};

use crate::FaultKind;

/// A checked scenario.
#[derive(Debug, Clone)]
pub struct Scenario {
    /// The scenario file.
    pub path: PathBuf,
    pub name: String,
    pub description: String,
    /// Plant time covered.
    pub duration: Duration,
    /// Profiles are applied, and due events and expectations looked at,
    /// every `step` of plant time.
    pub step: Duration,
    /// Plant time at offset zero.
    pub start: Timestamp,
    /// Seed of every random draw (profile noise); recorded in the report.
    pub seed: u64,
    /// The plant configuration (main file or folder), relative paths
    /// resolved against the scenario's folder; `None` = the demo plant.
    pub plant: Option<PathBuf>,
    /// Price of diesel fuel per litre, for the dispatch and the report
    /// (absent: the plant's `[microgrid] fuel_price_per_l`).
    pub fuel_price_per_l: Option<f64>,
    /// Replay a second time with the rule-based dispatch for the cost comparison.
    pub compare_rule: bool,
    /// How often the report's plots are sampled.
    pub sample: Duration,
    /// Plant time the stack runs before offset zero (with the initial state
    /// and the inputs of offset zero) so that polling, alarms and the
    /// dispatch have settled; figures count from offset zero.
    pub warmup: Duration,
    pub initial: Initial,
    pub profiles: Profiles,
    /// Sorted by time; events at the same time keep their file order.
    pub events: Vec<Event>,
    pub expectations: Vec<Expectation>,
    /// Every name the scenario refers to, for [`Scenario::check_against`].
    pub(crate) refs: Vec<parse::NameRef>,
}

/// The state the plant starts in (before offset zero's events).
#[derive(Debug, Clone, Default, Serialize)]
pub struct Initial {
    pub units: Vec<InitialUnit>,
    pub panels: Vec<InitialPanel>,
}

#[derive(Debug, Clone, Serialize)]
pub struct InitialUnit {
    pub id: String,
    /// Storage state of charge, percent of capacity.
    pub soc_pct: Option<f64>,
    /// The unit starts tripped (State 2).
    pub tripped: bool,
}

#[derive(Debug, Clone, Serialize)]
pub struct InitialPanel {
    pub id: String,
    pub mode: Option<PanelMode>,
    pub door_open: bool,
    /// Zone loads, kW, zone 1 first (profiles override).
    pub zone_kw: Vec<f64>,
}

/// Plant inputs over time; `None` keeps the simulator's built-in curve.
#[derive(Debug, Clone, Default)]
pub struct Profiles {
    /// Plane-of-array irradiance, W/m².
    pub irradiance: Option<Series>,
    /// PV availability as a fraction of rated power (0..1); converted to
    /// irradiance by the runner. Exclusive with `irradiance`.
    pub pv_available: Option<Series>,
    /// Hub wind speed, m/s.
    pub wind_speed: Option<Series>,
    /// Microgrid demand at the load meter, kW.
    pub demand: Option<Series>,
    /// Zone loads of panels, kW.
    pub zones: Vec<ZoneProfile>,
}

#[derive(Debug, Clone)]
pub struct ZoneProfile {
    pub panel: String,
    pub zone: u8,
    pub pf: f64,
    pub kw: Series,
}

/// A timed event.
#[derive(Debug, Clone, Serialize)]
pub struct Event {
    /// Offset from the start.
    pub at: Duration,
    pub action: Action,
    /// Line of the event in the scenario file.
    pub line: usize,
}

/// What an event does.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "action", rename_all = "snake_case")]
pub enum Action {
    /// A zone fault (zone 0: the busbar behind the main MCCB).
    Fault {
        panel: String,
        zone: u8,
        kind: FaultKind,
    },
    Repair {
        panel: String,
        zone: u8,
    },
    /// Operator: Auto/Manual.
    Mode {
        panel: String,
        mode: PanelMode,
    },
    /// Operator: the panel's Reset.
    Reset {
        panel: String,
    },
    /// Operator: a manual breaker command ("elcb", "mccb", "zone1".."zoneN").
    Breaker {
        panel: String,
        breaker: String,
        close: bool,
    },
    /// Operator: acknowledge every unacknowledged alarm.
    Acknowledge {
        user: String,
    },
    /// A device (or a gateway address) stops answering.
    CommLoss {
        device: String,
    },
    /// It answers again.
    CommReturn {
        device: String,
    },
    /// A microgrid unit trips.
    Trip {
        unit: String,
    },
    /// A tripped unit is reset.
    UnitReset {
        unit: String,
    },
    /// A storage unit's state of charge is set, percent of capacity.
    SetSoc {
        unit: String,
        soc_pct: f64,
    },
}

impl std::fmt::Display for Action {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Action::Fault { panel, zone, kind } => {
                let kind = match kind {
                    FaultKind::Permanent => "permanent",
                    FaultKind::Transient => "transient",
                };
                write!(f, "{kind} fault on {panel} zone {zone}")
            }
            Action::Repair { panel, zone } => write!(f, "{panel} zone {zone} repaired"),
            Action::Mode { panel, mode } => write!(f, "operator sets {panel} to {mode:?}"),
            Action::Reset { panel } => write!(f, "operator presses Reset on {panel}"),
            Action::Breaker {
                panel,
                breaker,
                close,
            } => write!(
                f,
                "operator {} {panel} {breaker}",
                if *close { "closes" } else { "opens" }
            ),
            Action::Acknowledge { user } => write!(f, "{user} acknowledges all alarms"),
            Action::CommLoss { device } => write!(f, "communication lost with {device}"),
            Action::CommReturn { device } => write!(f, "communication back with {device}"),
            Action::Trip { unit } => write!(f, "{unit} trips"),
            Action::UnitReset { unit } => write!(f, "{unit} reset"),
            Action::SetSoc { unit, soc_pct } => {
                write!(f, "{unit} state of charge set to {soc_pct} %")
            }
        }
    }
}

impl Scenario {
    /// Number of steps in the scenario (the last one ends at `duration`).
    pub fn steps(&self) -> u64 {
        let step = self.step.as_millis().max(1);
        self.duration.as_millis().div_ceil(step) as u64
    }
}
