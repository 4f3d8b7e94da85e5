//! What the outer loop reports: its mode, the status of its last period
//! (for the HMI) and its notices (for the event log and the alarm engine).

use std::collections::BTreeMap;

use serde::Serialize;

use gridscada_tagdb::Timestamp;

use crate::dispatch::lookahead::HorizonPlan;
use crate::dispatch::single::DispatchProblem;
use crate::dispatch::Setpoints;

/// Name of the alarm raised while the loop runs on the fallback rule.
pub const FALLBACK_ALARM: &str = "dispatch fallback";

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum DispatchMode {
    /// Setpoints come from the LP.
    Optimal,
    /// Setpoints come from the rule (see `reason`).
    Fallback,
}

/// What the outer loop did in its last period; published on a watch channel
/// for the HMI.
#[derive(Debug, Clone, Serialize)]
pub struct DispatchStatus {
    /// Plant time of the period (0 before the first one).
    pub at: Timestamp,
    pub mode: DispatchMode,
    /// The solver's verdict: "optimal", "infeasible", "error", or "not solved"
    /// (inputs unusable) / "not run" (before the first period).
    pub status: String,
    /// Why the loop is in fallback (or why the solve failed).
    pub reason: Option<String>,
    /// The problem built from the measurements (in fallback: with substitutes).
    pub inputs: Option<DispatchProblem>,
    /// Setpoints written (or attempted), kW per unit id.
    pub setpoints_kw: Setpoints,
    /// Run command per diesel id.
    pub run_cmd: BTreeMap<String, bool>,
    pub shed_kw: f64,
    pub objective: Option<f64>,
    pub solve_ms: Option<f64>,
    /// Writes the field did not confirm in this period.
    pub write_failures: Vec<String>,
    /// The look-ahead plan in force (with `[microgrid.horizon]` only).
    pub horizon: Option<HorizonPlan>,
}

impl Default for DispatchStatus {
    fn default() -> Self {
        DispatchStatus {
            at: Timestamp::from_millis(0),
            mode: DispatchMode::Fallback,
            status: "not run".into(),
            reason: None,
            inputs: None,
            setpoints_kw: Setpoints::default(),
            run_cmd: BTreeMap::new(),
            shed_kw: 0.0,
            objective: None,
            solve_ms: None,
            write_failures: Vec::new(),
            horizon: None,
        }
    }
}

/// For the event log and the alarm engine.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "type", rename_all = "lowercase")]
pub enum DispatchNotice {
    /// A system event ("dispatch back to optimal", "dg1 start: ...").
    Event { at: Timestamp, message: String },
    /// Raise (`active`) or clear an alarm, e.g. [`FALLBACK_ALARM`].
    Alarm {
        at: Timestamp,
        name: String,
        active: bool,
        reason: String,
    },
}
