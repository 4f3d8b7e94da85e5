//! Where a sequence stands ([`Step`]) and how the last one went
//! ([`Outcome`], [`Metrics`]).

use serde::{Deserialize, Serialize};

/// The steps of the sequence.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Step {
    /// Automatic, nothing to do, no faulty zone known.
    Idle,
    /// Opening the MCCB and all zones after a trip.
    Tripped,
    RecloseWait,
    /// ELCB reset pulse sent, waiting for its status to confirm.
    ElcbReset,
    /// Closing load `count_L_cur_c`, waiting for its status.
    Oluc,
    OlucDwell,
    /// Closing zone `oldc`, waiting for its status.
    Oldc,
    OldcDwell,
    /// Automatic, done, faulty zones left off.
    Isolated,
    Lockout,
    Suspended,
    Manual,
}

impl Step {
    pub fn name(self) -> &'static str {
        match self {
            Step::Idle => "idle",
            Step::Tripped => "tripped",
            Step::RecloseWait => "reclose_wait",
            Step::ElcbReset => "elcb_reset",
            Step::Oluc => "oluc",
            Step::OlucDwell => "oluc_dwell",
            Step::Oldc => "oldc",
            Step::OldcDwell => "oldc_dwell",
            Step::Isolated => "isolated",
            Step::Lockout => "lockout",
            Step::Suspended => "suspended",
            Step::Manual => "manual",
        }
    }

    /// The step named `name` (as [`Step::name`] gives it).
    pub fn from_name(name: &str) -> Option<Step> {
        [
            Step::Idle,
            Step::Tripped,
            Step::RecloseWait,
            Step::ElcbReset,
            Step::Oluc,
            Step::OlucDwell,
            Step::Oldc,
            Step::OldcDwell,
            Step::Isolated,
            Step::Lockout,
            Step::Suspended,
            Step::Manual,
        ]
        .into_iter()
        .find(|s| s.name() == name)
    }

    /// Whether an automatic sequence is in progress.
    pub fn is_running(self) -> bool {
        matches!(
            self,
            Step::Tripped
                | Step::RecloseWait
                | Step::ElcbReset
                | Step::Oluc
                | Step::OlucDwell
                | Step::Oldc
                | Step::OldcDwell
        )
    }

    /// Steps in which the ELCB is expected closed: an open ELCB is a trip.
    pub(super) fn expects_elcb_closed(self) -> bool {
        matches!(
            self,
            Step::Oluc | Step::OlucDwell | Step::Oldc | Step::OldcDwell
        )
    }
}

/// How the last sequence went.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Outcome {
    None,
    Running,
    /// Every load on (no faulty zone known).
    Restored,
    /// Healthy zones on, faulty zones isolated.
    Isolated,
    Lockout,
    /// Stopped by the operator (manual mode).
    Stopped,
}

/// Figures of the last sequence.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Metrics {
    /// From the first trip (or Reset) until every load not known faulty was
    /// confirmed closed after the last trip. `None` (JSON `null`) while no
    /// such moment came: before the first sequence, while one runs, and
    /// after a sequence that did not restore (ended in a lockout or stopped
    /// by manual mode), so no such sequence reads "restored in 0.0 s".
    pub restore_s: Option<f64>,
    /// Breaker state changes commanded (opens, closes, ELCB resets).
    pub switching_ops: u32,
    /// Switch-ons of a load that turned out faulty.
    pub reenergisations: u32,
    /// 2 × reclose delay + (N + 1) × dwell.
    pub bound_s: f64,
    pub trips: u32,
    pub elcb_resets: u32,
    pub outcome: Outcome,
}
