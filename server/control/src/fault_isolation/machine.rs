//! The OLUC/OLDC sequence of one panel as a pure state machine.
//!
//! **Owns:** every decision of the automatic fault-isolation sequence: when to
//! open breakers, when to reset the ELCB, which load to switch on next, which
//! zones are faulty, when to suspend or lock out, what to alarm.
//!
//! **Must not touch:** I/O or time. Inputs are snapshots of the panel's I/O
//! (value + quality), timer expiries and operator commands; outputs are breaker
//! commands, timer requests, events and alarm conditions. Every decision waits
//! on a timer expiry; the `now_s` argument time-stamps the metrics and ages
//! the confirmation window of commands (see "Asynchronous status inputs").
//!
//! ## The sequence (automatic mode)
//! Loads are numbered as in the seed: load 0 is the main MCCB, loads 1..=N are
//! the zone MCBs.
//! 1. `tripped`: the ELCB opened. Open the MCCB and every zone, wait for the
//!    status inputs to confirm. The reclose delay (`reclose_delay_s`) starts
//!    at the trip, concurrently with the opens.
//! 2. `reclose_wait`: every open confirmed, the delay still running. The ELCB
//!    is reset only when BOTH the delay has run out AND every open is
//!    confirmed (interlock: never reclose onto closed loads).
//! 3. `elcb_reset`: pulse the ELCB reset output; its status input must confirm
//!    within `confirm_timeout_s`, else lockout. Nothing is closed before it
//!    reads closed (interlock).
//! 4. `oluc` / `oluc_dwell`: close loads 0, 1, 2, ... one at a time
//!    (`count_L_cur_c` is the load being switched). Each dwell counts from the
//!    close command: the next load is closed only when the dwell has run out
//!    AND the close is confirmed AND the ELCB still reads closed.
//!    A load already closed is skipped. OLUC stops at the first zone known to be
//!    faulty. A trip while load `c` is being switched on or dwelling marks `c`
//!    faulty (`count_L_cur_sv = c`) and goes back to step 1. A fault on load 0
//!    locks out with everything off.
//! 5. `oldc` / `oldc_dwell`: close zones N, N-1, ... down to just above the
//!    zone where OLUC stopped, skipping known-faulty and already closed zones.
//!    A trip marks that zone faulty and goes back to step 1; the next pass skips
//!    every known-faulty zone, so each faulty zone is energised exactly once.
//!    Loads proven healthy earlier in the sequence are re-closed without their
//!    own dwell (see below).
//! 6. `idle` (no faulty zone) or `isolated` (faulty zones left off). A sequence
//!    that finds no new faulty zone logs a "transient fault" event.
//! 7. Reset (operator, after repair): clears counters, the faulty set and the
//!    lockout, then runs OLUC + OLDC again so repaired zones come back.
//!
//! ## Proven loads: re-closing without dwell
//! A load is *proven* once, in the current sequence, it was switched on and
//! its full dwell ran out without a trip. After the next trip every load is
//! opened again, and the next pass re-closes the proven loads with no dwell of
//! their own. When the MCCB (load 0) is among them (always after a trip) they
//! are closed together as one `oluc` step: the proven zone MCBs first, dead
//! because the MCCB is open (so no zone is closed onto a live bus and nothing
//! can trip yet), then the MCCB, which energises the batch at once, as a
//! return of supply would. Every close is checked by its status input. A
//! proven load reached with the MCCB already closed (only after a Reset,
//! which skips closed loads) is closed on its own, confirmed before the next.
//!
//! **Attribution rule.** Why a dwell at all: a trip may be seen late (after
//! the status input confirmed the close), and a trip must be pinned on one
//! load. So proven loads closed back to back form a *batch*, and the batch owes
//! one *settle dwell* (shown as the dwell step of its last close) before the
//! next unproven load is closed and before the sequence ends. After a trip,
//! proven loads normally come first in each walk (the pass that proved them
//! walked through them before reaching the trip), so a pass is: batch of
//! proven loads, one settle dwell, then the unproven loads with a full dwell
//! each. (After a Reset, loads found closed are skipped and not proven, so a
//! later pass may interleave; the rule is per batch.) Hence:
//! - A trip while an unproven load is being closed or dwells is that load's,
//!   exactly as before: a batch trip cannot leak into it, because the settle
//!   dwell lies in between.
//! - A trip while the batch is being closed or during its settle dwell means a
//!   new fault on a load that proved healthy minutes ago (or a fault outside
//!   the loads). It cannot be pinned on one load of the batch, so no load is
//!   marked faulty: the proofs are withdrawn, the sequence goes back to step 1
//!   (the trip counts against `max_trips`) and re-closes for the rest of the
//!   sequence every load with a full dwell, i.e. the plain seed algorithm,
//!   which then attributes the fault correctly. Guessing "the last load
//!   closed" could isolate a healthy zone; a lockout would leave every zone off
//!   for a fault the plain algorithm can isolate. Cost: the newly faulty load
//!   is energised once more than a fault present from the start.
//!
//! The batch's settle dwell counts from its last close command (the MCCB),
//! like any dwell.
//!
//! ## Timing
//! Restore time (`restore_s`: from the first trip read to all healthy loads
//! confirmed closed) for a permanent fault on zone k of N: 2 × reclose +
//! N × dwell + 4 × ℓ for every k, where ℓ is one status latency (breaker
//! operating time + up to one scan period of the status module + a request).
//! The seed's bound is 2 × reclose + (N + 1) × dwell, so it holds when
//! 4 × ℓ < dwell. Only four latencies stay on the critical path, because the
//! reclose delay overlaps the opens, each dwell overlaps its close
//! confirmation, and the proven batch is confirmed during its settle dwell.
//! The four that stay are needed:
//! - the ELCB reset must read closed before the first close (interlock), after
//!   each of the two trips;
//! - the trip of the faulty zone is seen only when the ELCB is read;
//! - `restore_s` ends when the last healthy load reads closed.
//!
//! Attribution requires `dwell_s` to exceed the ELCB status latency (its
//! module's scan period + request timeout + the breaker's operating time +
//! margin): a dwell counts from the close command, and a trip read after the
//! dwell would be pinned on the next load. Configuration validation refuses a
//! dwell not above scan + timeout of the ELCB status device.
//!
//! ## Limits, faults and takeover
//! - More than `max_trips` ELCB trips in one sequence: lockout.
//! - Every command is checked against its status input within
//!   `confirm_timeout_s`; otherwise a command/feedback mismatch alarm, and in
//!   automatic mode a lockout. A write the field layer refuses counts the same.
//! - Interlock: the MCCB or a zone is never commanded closed unless the last
//!   good snapshot shows the ELCB closed.
//! - During a sequence, a breaker that changes without having been commanded
//!   within the confirm window (someone operating the panel locally) locks
//!   out (see "Asynchronous status inputs").
//! - **Communication loss rule.** Any signal of the panel with non-Good quality
//!   during a sequence suspends it (`suspended`): timers are cancelled, nothing
//!   is switched, an alarm is raised. The sequence resumes only on the next
//!   snapshot in which every signal is Good again (a fresh re-read), and only if
//!   that state is consistent with what the machine knew: every MCCB/zone status
//!   equals its last known value, or is explained by a command (awaiting
//!   confirmation or within the confirm window); the ELCB has not closed unless a reset was pending. An ELCB
//!   that opened while blind is a trip and is handled as one at the step in
//!   progress. Anything else locks out. On resume the step in progress is
//!   restarted from its beginning (its timer runs again in full, an unconfirmed
//!   command is re-issued), which is never shorter than the original wait.
//! - Switching to manual mode stops the sequence at once (nothing further is
//!   switched); manual breaker commands are refused in automatic mode.
//!   In manual mode nothing switches by itself.
//!
//! ## Asynchronous status inputs
//! Over real I/O the panel's signals sit on different modules, each scanned on
//! its own: a status input lags its breaker by up to a scan period plus the
//! breaker's operating time, and readings of different modules arrive in any
//! order (the ELCB trip of a faulty zone is often read before that zone's
//! "closed" status). Readings of one input arrive in order. Hence:
//! - **Explained change.** A status change to `v` is explained by a command
//!   to `v` awaiting confirmation, or by *any* command to `v` issued within the
//!   last `confirm_timeout_s` (the confirm window), even one since superseded:
//!   a zone commanded closed, then open after the trip was read, may still be
//!   read closed once. Only a change with no such command is local operation.
//! - **Confirmation.** After every good snapshot, a breaker whose last command
//!   lies within the confirm window and whose status differs from it awaits
//!   confirmation (again): a late reading of the superseded state re-arms the
//!   check. A mismatch is raised only when the confirm timeout runs out with
//!   the status not at the *last* commanded state. A step that waits on
//!   confirmations waits on all of them, so OLUC never closes a load while an
//!   earlier opening is still unconfirmed.
//! - **Attribution** is unchanged: a trip is pinned on the load being closed
//!   or dwelling, so `dwell_s` must exceed the time from the close command to
//!   reading the ELCB (scan period of the ELCB's module plus margins; see
//!   "Timing").

use std::collections::{BTreeMap, BTreeSet};
use std::fmt;

use serde::{Deserialize, Serialize};

pub use gridscada_config::PanelMode as Mode;

/// Alarm priorities (the alarm engine's scale: higher is more urgent).
pub mod priority {
    pub const ELCB_TRIP: u32 = 900;
    pub const LOAD0_FAULT: u32 = 900;
    pub const LOCKOUT: u32 = 900;
    pub const MISMATCH: u32 = 800;
    pub const COMM_LOST: u32 = 800;
    pub const ZONE_ISOLATED: u32 = 700;
}

/// Per-panel timing and limits.
#[derive(Debug, Clone, PartialEq)]
pub struct Settings {
    pub zones: u8,
    pub reclose_delay_s: f64,
    pub dwell_s: f64,
    pub confirm_timeout_s: f64,
    pub max_trips: u32,
    pub start_mode: Mode,
}

impl Settings {
    /// Takes the settings of a configured panel. Values that validation should
    /// have refused (non-positive or non-finite times) fall back to the
    /// configuration defaults rather than make the machine misbehave.
    pub fn from_panel(panel: &gridscada_config::PanelConfig) -> Settings {
        fn secs(v: f64, default: f64) -> f64 {
            if v.is_finite() && v > 0.0 {
                v
            } else {
                default
            }
        }
        Settings {
            zones: *panel.zones.get_ref(),
            reclose_delay_s: secs(*panel.reclose_delay_s.get_ref(), 3.0),
            dwell_s: secs(*panel.dwell_s.get_ref(), 1.0),
            confirm_timeout_s: secs(*panel.confirm_timeout_s.get_ref(), 2.0),
            max_trips: u32::from(*panel.max_trips.get_ref()).max(2),
            start_mode: panel.start_mode,
        }
    }

    /// The seed's bound on restoration time: 2 × reclose delay + (N + 1) × dwell.
    pub fn bound_s(&self) -> f64 {
        2.0 * self.reclose_delay_s + (f64::from(self.zones) + 1.0) * self.dwell_s
    }
}

/// A breaker of the panel. As a command target, `Elcb` means its reset output.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Breaker {
    Elcb,
    /// The main MCCB, "load 0".
    Mccb,
    /// Zone MCB, numbered from 1.
    Zone(u8),
}

impl Breaker {
    /// The breaker switching load `n` (0 = MCCB).
    pub fn load(n: u8) -> Breaker {
        if n == 0 {
            Breaker::Mccb
        } else {
            Breaker::Zone(n)
        }
    }

    /// The API name: `elcb`, `mccb`, `zone1`...
    pub fn name(self) -> String {
        match self {
            Breaker::Elcb => "elcb".into(),
            Breaker::Mccb => "mccb".into(),
            Breaker::Zone(n) => format!("zone{n}"),
        }
    }

    /// Parses an API name for a panel with `zones` zones.
    pub fn parse(name: &str, zones: u8) -> Result<Breaker, CommandError> {
        let n = name.trim().to_ascii_lowercase();
        let unknown = || CommandError::UnknownBreaker {
            name: name.chars().take(40).collect(),
            zones,
        };
        match n.as_str() {
            "elcb" => Ok(Breaker::Elcb),
            "mccb" => Ok(Breaker::Mccb),
            _ => {
                let z: u8 = n
                    .strip_prefix("zone")
                    .and_then(|d| d.parse().ok())
                    .ok_or_else(unknown)?;
                if (1..=zones).contains(&z) {
                    Ok(Breaker::Zone(z))
                } else {
                    Err(unknown())
                }
            }
        }
    }
}

impl fmt::Display for Breaker {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Breaker::Elcb => f.write_str("ELCB"),
            Breaker::Mccb => f.write_str("main MCCB"),
            Breaker::Zone(n) => write!(f, "zone {n} MCB"),
        }
    }
}

/// One status input: its value and whether its quality is Good.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Reading {
    pub closed: bool,
    pub good: bool,
}

impl Reading {
    pub fn good(closed: bool) -> Reading {
        Reading { closed, good: true }
    }
    pub fn bad() -> Reading {
        Reading {
            closed: false,
            good: false,
        }
    }
}

/// The panel's I/O as read at one moment.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Snapshot {
    pub elcb: Reading,
    pub mccb: Reading,
    /// Zone 1 first.
    pub zones: Vec<Reading>,
    /// Whether the command outputs (reset and command coils) read back with
    /// Good quality, i.e. the output modules are reachable.
    pub outputs_good: bool,
}

impl Snapshot {
    /// A snapshot with every signal Good.
    pub fn good(elcb: bool, mccb: bool, zones: &[bool]) -> Snapshot {
        Snapshot {
            elcb: Reading::good(elcb),
            mccb: Reading::good(mccb),
            zones: zones.iter().map(|z| Reading::good(*z)).collect(),
            outputs_good: true,
        }
    }

    /// Whether every signal is Good (and the snapshot has the right shape).
    pub fn all_good(&self, zones: u8) -> bool {
        self.zones.len() == usize::from(zones)
            && self.outputs_good
            && self.elcb.good
            && self.mccb.good
            && self.zones.iter().all(|z| z.good)
    }
}

/// The state of the breakers, as last read with Good quality.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PanelState {
    pub elcb: bool,
    pub mccb: bool,
    pub zones: Vec<bool>,
}

impl PanelState {
    fn from_snapshot(s: &Snapshot) -> PanelState {
        PanelState {
            elcb: s.elcb.closed,
            mccb: s.mccb.closed,
            zones: s.zones.iter().map(|z| z.closed).collect(),
        }
    }

    /// Whether `b` is closed (unknown zones read as open).
    pub fn closed(&self, b: Breaker) -> bool {
        match b {
            Breaker::Elcb => self.elcb,
            Breaker::Mccb => self.mccb,
            Breaker::Zone(n) => n >= 1 && self.zones.get(usize::from(n) - 1) == Some(&true),
        }
    }

    /// MCCB and zones, load 0 first.
    fn loads(&self) -> impl Iterator<Item = Breaker> + '_ {
        (0..=self.zones.len() as u8).map(Breaker::load)
    }
}

/// The sequence's timers. At most one of each runs at a time.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Timer {
    RecloseDelay,
    Dwell,
    Confirm,
}

impl Timer {
    fn index(self) -> usize {
        match self {
            Timer::RecloseDelay => 0,
            Timer::Dwell => 1,
            Timer::Confirm => 2,
        }
    }
}

/// What the machine is told.
#[derive(Debug, Clone, PartialEq)]
pub enum Input {
    /// A fresh read of the panel's I/O.
    Snapshot(Snapshot),
    /// A timer started with this token ran out. Stale tokens are ignored, so a
    /// driver need not race cancellation.
    TimerExpired { timer: Timer, token: u64 },
    /// The field layer refused or lost a command. `comm` tells whether it was a
    /// communication failure (device offline, timeout) rather than a refusal.
    CommandFailed {
        breaker: Breaker,
        value: bool,
        reason: String,
        comm: bool,
    },
}

/// What an operator may ask (the role check is the web layer's).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum OperatorCommand {
    SetMode(Mode),
    Reset,
    /// Manual breaker command; closing the ELCB means a reset pulse.
    Breaker {
        breaker: Breaker,
        close: bool,
    },
}

/// Why an operator command was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CommandError {
    #[error(
        "manual breaker commands are only accepted in manual mode; the panel is in automatic mode"
    )]
    NotManual,
    #[error("interlock: {0}")]
    Interlocked(String),
    #[error(
        "communication with the panel's I/O is lost or not yet established; its state is unknown"
    )]
    CommLost,
    #[error("the automatic sequence is running (step '{0}'); wait for it to finish or switch to manual mode")]
    Busy(&'static str),
    #[error("unknown breaker '{name}': expected elcb, mccb or zone1..zone{zones}")]
    UnknownBreaker { name: String, zones: u8 },
    #[error("the ELCB has no trip output; it can only be reset (closed) from the SCADA")]
    ElcbCannotOpen,
}

/// What the machine asks for.
#[derive(Debug, Clone, PartialEq)]
pub enum Output {
    /// Write `value` to the breaker's command output (for the ELCB, its reset
    /// output: `true` then `false` is one reset pulse). In order.
    Command {
        breaker: Breaker,
        value: bool,
    },
    /// (Re)start `timer`; deliver `TimerExpired { timer, token }` after `after_s`.
    StartTimer {
        timer: Timer,
        after_s: f64,
        token: u64,
    },
    CancelTimer {
        timer: Timer,
    },
    /// For the event log.
    Event {
        kind: &'static str,
        message: String,
    },
    /// An alarm condition became active (`active`) or cleared.
    Alarm {
        key: String,
        active: bool,
        priority: u32,
        message: String,
    },
}

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
    fn expects_elcb_closed(self) -> bool {
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
    /// confirmed closed.
    pub restore_s: f64,
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

/// The commands last sent to one breaker.
#[derive(Debug, Clone, Copy, Default)]
struct CommandLog {
    /// The value of the last command.
    last: bool,
    /// When it was last commanded open (`[0]`) and closed (`[1]`).
    at: [Option<f64>; 2],
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Cause {
    Trip,
    Reset,
}

/// What a panel's sequence must carry across a restart of the server: the
/// mode the operators chose, the zones known faulty and the lockout. Without
/// it a fresh sequence would find a locked-out panel's ELCB open, take it for
/// a new trip and switch onto the fault it had locked out on.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Retained {
    pub mode: Mode,
    /// Known-faulty loads (0 = MCCB / busbar).
    pub faulty: Vec<u8>,
    pub lockout: bool,
    /// The step a sequence was at (running or suspended) when this was
    /// saved: the server stopped in the middle of it.
    pub interrupted_at: Option<String>,
}

impl Retained {
    /// The alarms [`Sequence::restore`] raises again at once: each faulty
    /// load's and the lockout's. The application keeps these standing
    /// across the restart (acknowledged ones stay acknowledged) instead of
    /// clearing and re-annunciating them.
    pub fn alarm_keys(&self, zones: u8) -> Vec<String> {
        let mut keys: Vec<String> = self
            .faulty
            .iter()
            .filter(|l| **l <= zones)
            .map(|l| faulty_alarm_key(*l))
            .collect();
        if self.lockout || self.interrupted_at.is_some() {
            keys.push(LOCKOUT_ALARM.into());
        }
        keys
    }
}

/// Key of the lockout alarm.
const LOCKOUT_ALARM: &str = "lockout";

/// Key of the alarm of a faulty load.
fn faulty_alarm_key(load: u8) -> String {
    if load == 0 {
        "load0.fault".into()
    } else {
        format!("zone{load}.isolated")
    }
}

/// The sequence of one panel.
#[derive(Debug, Clone)]
pub struct Sequence {
    settings: Settings,
    mode: Mode,
    step: Step,
    /// The step a suspension interrupted.
    suspended_from: Option<Step>,
    /// OLUC step counter (count_L_cur_c): the load being switched on.
    count_c: u8,
    /// Saved faulty load number (count_L_cur_sv).
    count_sv: u8,
    /// OLDC: the zone being switched on.
    oldc: u8,
    /// Where OLUC stopped (first known-faulty zone); OLDC stops above it.
    oluc_stop: u8,
    /// Whether the current pass has moved on from OLUC to OLDC.
    in_oldc: bool,
    /// Loads switched on in this sequence whose full dwell ran out without a
    /// trip.
    proven: BTreeSet<u8>,
    /// Whether proven loads may be re-closed without dwell (false for the rest
    /// of a sequence once a batch of them tripped).
    fast_reclose: bool,
    /// Proven loads closed without dwell since the last dwell: they owe one
    /// settle dwell before an unproven load is closed or the sequence ends.
    batch: Vec<u8>,
    /// The load being closed (`oluc`/`oldc`) is a proven one: no dwell of its
    /// own.
    closing_proven: bool,
    /// The dwell running is the batch's settle dwell, not a load's own.
    settling: bool,
    /// Proven loads commanded closed together, zones first with the MCCB
    /// open, then the MCCB (see "Proven loads"); empty when closing one load.
    closing_batch: Vec<u8>,
    /// The reclose delay of the last trip has run out (the ELCB is reset as
    /// soon as every open is confirmed).
    reclose_due: bool,
    /// The dwell timer of the last close command has run out (the next load
    /// is closed as soon as this one is confirmed).
    dwell_due: bool,
    /// Known-faulty loads (0 = MCCB / busbar).
    faulty: BTreeSet<u8>,
    lockout: bool,
    /// Last state read with every signal Good.
    known: Option<PanelState>,
    comm_good: bool,
    /// Commands awaiting confirmation by their status input.
    pending: Vec<(Breaker, bool)>,
    /// When each breaker was last commanded open / closed, and its last
    /// command (for the ELCB: reset pulses only).
    commanded: BTreeMap<Breaker, CommandLog>,
    /// The time of the input being handled.
    now_s: f64,
    timers: [Option<u64>; 3],
    next_token: u64,
    /// Active alarm keys and their priorities.
    active_alarms: BTreeMap<String, u32>,
    cause: Cause,
    found_new: bool,
    /// Whether every healthy load has been on since the last trip.
    restored: bool,
    started_s: f64,
    metrics: Metrics,
}

impl Sequence {
    pub fn new(settings: Settings) -> Sequence {
        let mode = settings.start_mode;
        let metrics = Metrics {
            restore_s: 0.0,
            switching_ops: 0,
            reenergisations: 0,
            bound_s: settings.bound_s(),
            trips: 0,
            elcb_resets: 0,
            outcome: Outcome::None,
        };
        Sequence {
            mode,
            step: if mode == Mode::Manual {
                Step::Manual
            } else {
                Step::Idle
            },
            settings,
            suspended_from: None,
            count_c: 0,
            count_sv: 0,
            oldc: 0,
            oluc_stop: 0,
            in_oldc: false,
            proven: BTreeSet::new(),
            fast_reclose: true,
            batch: Vec::new(),
            closing_proven: false,
            settling: false,
            closing_batch: Vec::new(),
            reclose_due: false,
            dwell_due: false,
            faulty: BTreeSet::new(),
            lockout: false,
            known: None,
            comm_good: false,
            pending: Vec::new(),
            commanded: BTreeMap::new(),
            now_s: 0.0,
            timers: [None; 3],
            next_token: 0,
            active_alarms: BTreeMap::new(),
            cause: Cause::Trip,
            found_new: false,
            restored: false,
            started_s: 0.0,
            metrics,
        }
    }

    /// A sequence taking over what a previous run of the server left
    /// (`Retained`): the mode, the faulty zones with their alarms raised
    /// again, and the lockout. A sequence the restart interrupted locks out
    /// (the panel's state is not what any step expects, and switching blind
    /// is never safe); Reset after checking the panel resumes automatic
    /// operation. Faulty loads beyond this panel's zones are dropped.
    pub fn restore(settings: Settings, r: &Retained, out: &mut Vec<Output>) -> Sequence {
        let mut s = Sequence::new(settings);
        s.mode = r.mode;
        s.step = if r.mode == Mode::Manual {
            Step::Manual
        } else {
            Step::Idle
        };
        s.metrics.outcome = Outcome::None;
        let zones = s.settings.zones;
        for &load in r.faulty.iter().filter(|l| **l <= zones) {
            s.faulty.insert(load);
            s.raise_faulty_alarm(load, out);
        }
        s.count_sv = s.faulty.iter().next_back().copied().unwrap_or(0);
        event(
            out,
            "restored",
            format!(
                "state restored after a server restart: {} mode, faulty loads {:?}, lockout {}",
                if r.mode == Mode::Manual {
                    "manual"
                } else {
                    "automatic"
                },
                s.faulty,
                if r.lockout { "on" } else { "off" }
            ),
        );
        match (&r.interrupted_at, r.lockout) {
            (_, true) => s.lock_out("locked out before the server restarted", out),
            (Some(step), false) => s.lock_out(
                &format!(
                    "the server restarted during the sequence (step '{step}'); check the panel"
                ),
                out,
            ),
            (None, false) => s.set_rest_step("restored after a server restart", out),
        }
        s
    }

    /// What must survive a restart (see [`Retained`]).
    ///
    /// (The alarm keys a sequence restored from it raises at once are
    /// [`Retained::alarm_keys`].)
    pub fn retained(&self) -> Retained {
        let step = self
            .suspended_from
            .filter(|_| self.step == Step::Suspended)
            .unwrap_or(self.step);
        Retained {
            mode: self.mode,
            faulty: self.faulty.iter().copied().collect(),
            lockout: self.lockout,
            interrupted_at: (self.step == Step::Suspended || step.is_running())
                .then(|| step.name().to_string()),
        }
    }

    pub fn settings(&self) -> &Settings {
        &self.settings
    }
    pub fn mode(&self) -> Mode {
        self.mode
    }
    pub fn step(&self) -> Step {
        self.step
    }
    pub fn step_name(&self) -> &'static str {
        self.step.name()
    }
    /// count_L_cur_c: the OLUC step counter.
    pub fn count_l_cur_c(&self) -> u8 {
        self.count_c
    }
    /// count_L_cur_sv: the saved faulty load number.
    pub fn count_l_cur_sv(&self) -> u8 {
        self.count_sv
    }
    /// Known-faulty zones (1..=N), in order.
    pub fn faulty_zones(&self) -> Vec<u8> {
        self.faulty.iter().copied().filter(|z| *z > 0).collect()
    }
    /// Whether load 0 (main MCCB / busbar) is known faulty.
    pub fn load0_faulty(&self) -> bool {
        self.faulty.contains(&0)
    }
    pub fn lockout(&self) -> bool {
        self.lockout
    }
    pub fn metrics(&self) -> &Metrics {
        &self.metrics
    }
    /// The last state read with every signal Good.
    pub fn known_state(&self) -> Option<&PanelState> {
        self.known.as_ref()
    }
    pub fn comm_good(&self) -> bool {
        self.comm_good
    }

    /// Feeds a plant input. `now_s` (plant seconds, any monotonic origin)
    /// time-stamps the metrics and ages the confirm window of commands.
    pub fn handle(&mut self, input: Input, now_s: f64) -> Vec<Output> {
        let mut out = Vec::new();
        self.set_now(now_s);
        match input {
            Input::Snapshot(s) => self.on_snapshot(&s, now_s, &mut out),
            Input::TimerExpired { timer, token } => {
                if self.timers[timer.index()] == Some(token) {
                    self.timers[timer.index()] = None;
                    self.on_timer(timer, now_s, &mut out);
                }
            }
            Input::CommandFailed {
                breaker,
                value,
                reason,
                comm,
            } => self.on_command_failed(breaker, value, &reason, comm, &mut out),
        }
        out
    }

    /// Applies an operator command, or says why not.
    pub fn command(
        &mut self,
        cmd: OperatorCommand,
        now_s: f64,
    ) -> Result<Vec<Output>, CommandError> {
        let mut out = Vec::new();
        self.set_now(now_s);
        match cmd {
            OperatorCommand::SetMode(Mode::Manual) => self.enter_manual_mode(&mut out),
            OperatorCommand::SetMode(Mode::Auto) => self.enter_auto_mode(now_s, &mut out),
            OperatorCommand::Reset => self.reset(now_s, &mut out)?,
            OperatorCommand::Breaker { breaker, close } => {
                self.manual_breaker(breaker, close, &mut out)?
            }
        }
        Ok(out)
    }

    // ---- inputs -------------------------------------------------------------

    fn on_snapshot(&mut self, s: &Snapshot, now_s: f64, out: &mut Vec<Output>) {
        if !s.all_good(self.settings.zones) {
            self.comm_good = false;
            if self.step.is_running() {
                self.suspend("a signal of the panel has bad quality", out);
            }
            return;
        }
        self.comm_good = true;
        let state = PanelState::from_snapshot(s);
        match self.step {
            Step::Suspended => self.resume(state, now_s, out),
            Step::Idle | Step::Isolated => {
                self.settle_pending(&state, out);
                let tripped = !state.elcb;
                self.known = Some(state);
                if tripped && self.mode == Mode::Auto {
                    self.start_sequence(Cause::Trip, now_s, out);
                }
            }
            Step::Manual | Step::Lockout => {
                self.settle_pending(&state, out);
                self.known = Some(state);
            }
            _ => self.on_running_snapshot(state, now_s, out),
        }
    }

    /// A good snapshot while a sequence runs.
    fn on_running_snapshot(&mut self, state: PanelState, now_s: f64, out: &mut Vec<Output>) {
        if let Some(why) = self.unexplained_change(&state) {
            self.known = Some(state);
            self.lock_out(
                &format!("{why} during the automatic sequence (local operation?)"),
                out,
            );
            return;
        }
        self.reconcile_pending(&state, out);
        let elcb = state.elcb;
        self.known = Some(state);
        if self.step.expects_elcb_closed() && !elcb {
            self.on_trip_during_sequence(now_s, out);
            return;
        }
        if self.pending.is_empty() && self.timers[Timer::Confirm.index()].is_some() {
            self.cancel(Timer::Confirm, out);
            self.on_confirmed(now_s, out);
        }
    }

    fn on_timer(&mut self, timer: Timer, now_s: f64, out: &mut Vec<Output>) {
        match (timer, self.step) {
            (Timer::RecloseDelay, Step::RecloseWait) => self.enter_elcb_reset(out),
            (Timer::RecloseDelay, Step::Tripped) => {
                // The delay runs from the trip; the opens are still being
                // confirmed. Never reclose onto closed loads: wait for them.
                if self.pending.is_empty() {
                    self.enter_elcb_reset(out);
                } else {
                    self.reclose_due = true;
                    event(
                        out,
                        "reclose_delay_elapsed",
                        "reclose delay elapsed; the ELCB is reset once every open is confirmed"
                            .into(),
                    );
                }
            }
            (Timer::Dwell, Step::Oluc | Step::Oldc) => {
                // The dwell runs from the close command; the close is not
                // confirmed yet. The next load waits for the confirmation.
                self.dwell_due = true;
            }
            (Timer::Dwell, Step::OlucDwell | Step::OldcDwell) if self.settling => {
                // The batch held for a full dwell: carry on where the walk is.
                self.settling = false;
                self.batch.clear();
                self.continue_pass(now_s, out);
            }
            (Timer::Dwell, Step::OlucDwell) => self.oluc_dwell_done(now_s, out),
            (Timer::Dwell, Step::OldcDwell) => self.oldc_dwell_done(now_s, out),
            (Timer::Confirm, _) => self.on_confirm_timeout(out),
            // A timer that belongs to a step we have left (tokens make this rare).
            _ => {}
        }
    }

    fn on_confirm_timeout(&mut self, out: &mut Vec<Output>) {
        let mut unmet = std::mem::take(&mut self.pending);
        if unmet.is_empty() {
            return;
        }
        let reset_failed =
            self.step == Step::ElcbReset && unmet.iter().any(|(b, _)| *b == Breaker::Elcb);
        if reset_failed {
            unmet.retain(|(b, _)| *b != Breaker::Elcb);
            self.raise(
                "elcb.reset_failed",
                priority::LOCKOUT,
                format!(
                    "ELCB reset not confirmed by its status input within {} s",
                    self.settings.confirm_timeout_s
                ),
                out,
            );
        }
        let mut names = Vec::new();
        for (b, v) in &unmet {
            let want = if *v { "closed" } else { "open" };
            self.raise(
                &format!("{}.mismatch", b.name()),
                priority::MISMATCH,
                format!(
                    "command/feedback mismatch: {b} commanded {want}, status did not follow within {} s",
                    self.settings.confirm_timeout_s
                ),
                out,
            );
            names.push(b.to_string());
        }
        if reset_failed {
            self.lock_out("ELCB reset failed", out);
            return;
        }
        if self.mode == Mode::Auto && self.step != Step::Lockout {
            self.lock_out(
                &format!("command/feedback mismatch on {}", names.join(", ")),
                out,
            );
        }
    }

    fn on_command_failed(
        &mut self,
        breaker: Breaker,
        value: bool,
        reason: &str,
        comm: bool,
        out: &mut Vec<Output>,
    ) {
        let what = if value { "close" } else { "open" };
        let what = if breaker == Breaker::Elcb {
            "reset"
        } else {
            what
        };
        event(
            out,
            "command_failed",
            format!("command to {what} {breaker} failed: {reason}"),
        );
        if self.step == Step::Suspended {
            // Already suspended: the resume rule re-reads the state.
            return;
        }
        if comm && self.step.is_running() {
            // The state is uncertain: suspend; the resume rule re-reads it.
            self.comm_good = false;
            self.suspend(&format!("command to {breaker} failed: {reason}"), out);
            return;
        }
        // A refusal: the command will never be confirmed.
        self.pending.retain(|(b, _)| *b != breaker);
        if self.pending.is_empty() {
            self.cancel(Timer::Confirm, out);
        }
        self.raise(
            &format!("{}.mismatch", breaker.name()),
            priority::MISMATCH,
            format!("command to {what} {breaker} was not carried out: {reason}"),
            out,
        );
        if self.mode == Mode::Auto && self.step != Step::Lockout {
            self.lock_out(&format!("command to {what} {breaker} failed"), out);
        }
    }

    // ---- operator -----------------------------------------------------------

    fn enter_manual_mode(&mut self, out: &mut Vec<Output>) {
        if self.mode == Mode::Manual {
            return;
        }
        self.mode = Mode::Manual;
        let was = self.step;
        self.cancel(Timer::RecloseDelay, out);
        self.cancel(Timer::Dwell, out);
        // Commands already sent stay checked against their status inputs.
        if was.is_running() || was == Step::Suspended {
            self.metrics.outcome = Outcome::Stopped;
            self.clear("comm", out);
            event(
                out,
                "sequence_stopped",
                format!(
                    "automatic sequence stopped at step '{}': manual mode",
                    was.name()
                ),
            );
        }
        self.suspended_from = None;
        if self.timers[Timer::Confirm.index()].is_none() {
            // Nothing is checking them any more (a suspension cancelled it).
            self.pending.clear();
        }
        self.set_step(
            Step::Manual,
            "manual mode: breakers are switched by the operator only",
            out,
        );
    }

    fn enter_auto_mode(&mut self, now_s: f64, out: &mut Vec<Output>) {
        if self.mode == Mode::Auto {
            return;
        }
        self.mode = Mode::Auto;
        if self.lockout {
            self.set_step(
                Step::Lockout,
                "automatic mode, locked out: press Reset",
                out,
            );
            return;
        }
        self.set_rest_step("automatic mode", out);
        if self.comm_good && self.known.as_ref().is_some_and(|k| !k.elcb) {
            self.start_sequence(Cause::Trip, now_s, out);
        }
    }

    fn reset(&mut self, now_s: f64, out: &mut Vec<Output>) -> Result<(), CommandError> {
        if self.step.is_running() {
            return Err(CommandError::Busy(self.step.name()));
        }
        if self.step == Step::Suspended || !self.comm_good || self.known.is_none() {
            return Err(CommandError::CommLost);
        }
        self.faulty.clear();
        self.count_c = 0;
        self.count_sv = 0;
        self.oldc = 0;
        self.lockout = false;
        let keys: Vec<String> = self
            .active_alarms
            .keys()
            .filter(|k| k.as_str() != "comm")
            .cloned()
            .collect();
        for k in keys {
            self.clear(&k, out);
        }
        event(
            out,
            "reset",
            "Reset: counters, faulty zones and lockout cleared".into(),
        );
        if self.mode == Mode::Manual {
            self.set_step(
                Step::Manual,
                "manual mode: nothing is switched by Reset",
                out,
            );
        } else {
            self.start_sequence(Cause::Reset, now_s, out);
        }
        Ok(())
    }

    fn manual_breaker(
        &mut self,
        breaker: Breaker,
        close: bool,
        out: &mut Vec<Output>,
    ) -> Result<(), CommandError> {
        if self.mode != Mode::Manual {
            return Err(CommandError::NotManual);
        }
        if let Breaker::Zone(n) = breaker {
            if n == 0 || n > self.settings.zones {
                return Err(CommandError::UnknownBreaker {
                    name: breaker.name(),
                    zones: self.settings.zones,
                });
            }
        }
        let known = match (&self.known, self.comm_good) {
            (Some(k), true) => k.clone(),
            _ => return Err(CommandError::CommLost),
        };
        match (breaker, close) {
            (Breaker::Elcb, false) => return Err(CommandError::ElcbCannotOpen),
            (Breaker::Elcb, true) => {
                event(out, "manual_command", "manual ELCB reset pulse".into());
                self.pulse_reset(out);
            }
            (b, true) if !known.elcb => {
                return Err(CommandError::Interlocked(format!(
                    "{b} cannot be closed while the ELCB is open"
                )))
            }
            (b, v) => {
                let what = if v { "close" } else { "open" };
                event(out, "manual_command", format!("manual command: {what} {b}"));
                self.switch(b, v, out);
            }
        }
        self.start_confirm_if_pending(out);
        Ok(())
    }

    // ---- the sequence -------------------------------------------------------

    fn start_sequence(&mut self, cause: Cause, now_s: f64, out: &mut Vec<Output>) {
        self.cause = cause;
        self.found_new = false;
        self.restored = false;
        self.started_s = now_s;
        self.metrics = Metrics {
            restore_s: 0.0,
            switching_ops: 0,
            reenergisations: 0,
            bound_s: self.settings.bound_s(),
            trips: 0,
            elcb_resets: 0,
            outcome: Outcome::Running,
        };
        self.count_c = 0;
        self.in_oldc = false;
        self.proven.clear();
        self.fast_reclose = true;
        self.batch.clear();
        self.closing_proven = false;
        self.settling = false;
        self.closing_batch.clear();
        self.dwell_due = false;
        self.reclose_due = false;
        let Some(known) = self.known.clone() else {
            return;
        };
        match cause {
            Cause::Trip => {
                self.metrics.trips = 1;
                self.raise_trip_alarm(out);
                event(
                    out,
                    "trip",
                    "ELCB tripped: supply to all zones lost, fault isolation started".into(),
                );
                self.enter_tripped(now_s, out);
            }
            Cause::Reset => {
                // OLUC must energise one load at a time: with the MCCB open, any
                // closed zone would be energised together with it.
                let zones_on_dead_mccb = !known.mccb && known.zones.iter().any(|z| *z);
                if !known.elcb || zones_on_dead_mccb {
                    self.enter_tripped(now_s, out);
                } else {
                    self.count_c = 0;
                    self.oluc_next(now_s, out);
                }
            }
        }
    }

    /// Open the MCCB and every zone.
    fn enter_tripped(&mut self, now_s: f64, out: &mut Vec<Output>) {
        self.cancel(Timer::RecloseDelay, out);
        self.cancel(Timer::Dwell, out);
        // Everything is opened: a new pass starts with nothing owed.
        self.in_oldc = false;
        self.batch.clear();
        self.closing_batch.clear();
        self.closing_proven = false;
        self.settling = false;
        self.dwell_due = false;
        self.reclose_due = false;
        if self.known.as_ref().is_none_or(|k| k.elcb) {
            self.set_step(
                Step::Tripped,
                "opening the main MCCB and all zone MCBs",
                out,
            );
        } else {
            // The reclose delay runs from the trip, while the opens are
            // confirmed; the reset waits for both.
            self.set_step(
                Step::Tripped,
                &format!(
                    "opening the main MCCB and all zone MCBs; ELCB reset in {} s",
                    self.settings.reclose_delay_s
                ),
                out,
            );
            self.start(Timer::RecloseDelay, self.settings.reclose_delay_s, out);
        }
        let Some(known) = self.known.clone() else {
            return;
        };
        // The reset output must not stay set either: "while true" recloses.
        self.emit(Breaker::Elcb, false, out);
        for b in known.loads().collect::<Vec<_>>() {
            // Written even when already open, so no command output stays set.
            self.emit(b, false, out);
            self.pending.retain(|(p, _)| *p != b);
            if known.closed(b) {
                self.metrics.switching_ops += 1;
                self.pending.push((b, false));
            }
        }
        if !self.start_confirm_if_pending(out) {
            self.on_confirmed_tripped(now_s, out);
        }
    }

    fn on_confirmed(&mut self, now_s: f64, out: &mut Vec<Output>) {
        match self.step {
            Step::Tripped => self.on_confirmed_tripped(now_s, out),
            Step::ElcbReset => {
                self.clear("elcb.trip", out);
                event(
                    out,
                    "elcb_reclosed",
                    "ELCB reclosed, supply restored to the panel".into(),
                );
                self.count_c = 0;
                self.oluc_next(now_s, out);
            }
            Step::Oluc if self.closing_proven && !self.closing_batch.is_empty() => {
                // The whole batch is on: go on with the walk, which skips the
                // loads now closed; the batch owes its settle dwell.
                self.note_restored(now_s);
                self.closing_proven = false;
                let loads = std::mem::take(&mut self.closing_batch);
                self.batch.extend(loads);
                self.count_c = 0;
                self.in_oldc = false;
                self.oluc_next(now_s, out);
            }
            Step::Oluc if self.closing_proven => {
                self.note_restored(now_s);
                self.closing_proven = false;
                self.batch.push(self.count_c);
                self.count_c = self.count_c.saturating_add(1);
                self.oluc_next(now_s, out);
            }
            Step::Oldc if self.closing_proven => {
                self.note_restored(now_s);
                self.closing_proven = false;
                self.batch.push(self.oldc);
                self.oldc = self.oldc.saturating_sub(1);
                self.oldc_next(now_s, out);
            }
            // The dwell runs from the close command: it may have run out
            // before the status confirmed the close.
            Step::Oluc if self.dwell_due => {
                self.note_restored(now_s);
                self.oluc_dwell_done(now_s, out);
            }
            Step::Oldc if self.dwell_due => {
                self.note_restored(now_s);
                self.oldc_dwell_done(now_s, out);
            }
            Step::Oluc => {
                self.note_restored(now_s);
                let load = self.count_c;
                self.set_step(
                    Step::OlucDwell,
                    &format!("OLUC: load {load} closed, dwelling"),
                    out,
                );
            }
            Step::Oldc => {
                self.note_restored(now_s);
                let zone = self.oldc;
                self.set_step(
                    Step::OldcDwell,
                    &format!("OLDC: zone {zone} closed, dwelling"),
                    out,
                );
            }
            _ => {}
        }
    }

    fn on_confirmed_tripped(&mut self, now_s: f64, out: &mut Vec<Output>) {
        if self.known.as_ref().is_some_and(|k| k.elcb) {
            // Only on Reset: the ELCB is closed already, go straight to OLUC.
            self.cancel(Timer::RecloseDelay, out);
            self.count_c = 0;
            self.oluc_next(now_s, out);
        } else if self.reclose_due {
            self.enter_elcb_reset(out);
        } else {
            self.set_step(
                Step::RecloseWait,
                "all breakers open; waiting for the reclose delay (it runs from the trip)",
                out,
            );
            if self.timers[Timer::RecloseDelay.index()].is_none() {
                // Defensive: the delay always runs here; never wait forever.
                self.start(Timer::RecloseDelay, self.settings.reclose_delay_s, out);
            }
        }
    }

    fn enter_elcb_reset(&mut self, out: &mut Vec<Output>) {
        self.reclose_due = false;
        self.set_step(Step::ElcbReset, "resetting the ELCB", out);
        self.pulse_reset(out);
        self.start_confirm_if_pending(out);
    }

    fn pulse_reset(&mut self, out: &mut Vec<Output>) {
        self.emit(Breaker::Elcb, true, out);
        self.emit(Breaker::Elcb, false, out);
        self.metrics.switching_ops += 1;
        self.metrics.elcb_resets += 1;
        self.pending.retain(|(b, _)| *b != Breaker::Elcb);
        self.pending.push((Breaker::Elcb, true));
    }

    /// OLUC: switch on the next load from `count_c` upwards.
    fn oluc_next(&mut self, now_s: f64, out: &mut Vec<Output>) {
        let n = self.settings.zones;
        loop {
            let c = self.count_c;
            if c > n {
                if !self.settle_if_owed(out) {
                    self.finish(now_s, out);
                }
                return;
            }
            if self.faulty.contains(&c) {
                if c == 0 {
                    self.lock_out("fault on load 0 (main MCCB / busbar)", out);
                    return;
                }
                event(
                    out,
                    "oluc_done",
                    format!("OLUC stops below faulty zone {c}; OLDC from zone {n} down"),
                );
                self.oluc_stop = c;
                self.oldc = n;
                self.in_oldc = true;
                self.oldc_next(now_s, out);
                return;
            }
            let b = Breaker::load(c);
            if self.known.as_ref().is_some_and(|k| k.closed(b)) {
                self.count_c = c + 1; // already on, and the ELCB holds: healthy
                continue;
            }
            let proven = self.is_proven(c);
            if c == 0 && proven {
                // The MCCB is open: the proven zones can be closed dead.
                let loads = self.proven_prefix();
                self.close_proven_batch(loads, out);
                return;
            }
            if !proven && self.settle_if_owed(out) {
                return;
            }
            if !self.interlock_ok(b, out) {
                return;
            }
            let why = if proven {
                format!("OLUC step {c}: re-closing {b} (proven healthy in this sequence: no dwell)")
            } else {
                format!("OLUC step {c}: closing {b}")
            };
            self.close_load(Step::Oluc, b, proven, &why, out);
            return;
        }
    }

    /// OLDC: switch on the next zone from `oldc` downwards.
    fn oldc_next(&mut self, now_s: f64, out: &mut Vec<Output>) {
        loop {
            let d = self.oldc;
            if d <= self.oluc_stop {
                if !self.settle_if_owed(out) {
                    self.finish(now_s, out);
                }
                return;
            }
            let b = Breaker::Zone(d);
            if self.faulty.contains(&d) || self.known.as_ref().is_some_and(|k| k.closed(b)) {
                self.oldc = d - 1;
                continue;
            }
            let proven = self.is_proven(d);
            if !proven && self.settle_if_owed(out) {
                return;
            }
            if !self.interlock_ok(b, out) {
                return;
            }
            let why = if proven {
                format!("OLDC: re-closing {b} (proven healthy in this sequence: no dwell)")
            } else {
                format!("OLDC: closing {b}")
            };
            self.close_load(Step::Oldc, b, proven, &why, out);
            return;
        }
    }

    /// Whether `load` may be re-closed without a dwell of its own.
    fn is_proven(&self, load: u8) -> bool {
        self.fast_reclose && self.proven.contains(&load)
    }

    /// A dwell ran out after load `count_c` was confirmed closed: it is
    /// proven; OLUC goes on.
    fn oluc_dwell_done(&mut self, now_s: f64, out: &mut Vec<Output>) {
        self.proven.insert(self.count_c);
        self.count_c = self.count_c.saturating_add(1);
        self.oluc_next(now_s, out);
    }

    fn oldc_dwell_done(&mut self, now_s: f64, out: &mut Vec<Output>) {
        self.proven.insert(self.oldc);
        self.oldc = self.oldc.saturating_sub(1);
        self.oldc_next(now_s, out);
    }

    /// Closes one load. Its dwell (or, for a proven load, the settle dwell
    /// its batch owes) runs from the close command, concurrently with the
    /// status confirmation.
    fn close_load(
        &mut self,
        step: Step,
        b: Breaker,
        proven: bool,
        why: &str,
        out: &mut Vec<Output>,
    ) {
        self.set_step(step, why, out);
        self.closing_proven = proven;
        self.closing_batch.clear();
        self.switch(b, true, out);
        self.start_dwell(out);
        self.start_confirm_if_pending(out);
    }

    fn start_dwell(&mut self, out: &mut Vec<Output>) {
        self.dwell_due = false;
        self.start(Timer::Dwell, self.settings.dwell_s, out);
    }

    /// The loads the walk of this pass would close next, from load 0, as
    /// long as they are proven (the walk skips closed and known-faulty loads
    /// exactly as `oluc_next` / `oldc_next` do). Starts with load 0.
    fn proven_prefix(&self) -> Vec<u8> {
        let n = self.settings.zones;
        let closed = |l: u8| {
            self.known
                .as_ref()
                .is_some_and(|k| k.closed(Breaker::load(l)))
        };
        let mut loads = Vec::new();
        let mut stop = None;
        for c in 0..=n {
            if self.faulty.contains(&c) {
                stop = Some(c);
                break;
            }
            if closed(c) {
                continue;
            }
            if !self.is_proven(c) {
                return loads;
            }
            loads.push(c);
        }
        if let Some(stop) = stop.filter(|s| *s > 0) {
            for d in (stop + 1..=n).rev() {
                if self.faulty.contains(&d) || closed(d) {
                    continue;
                }
                if !self.is_proven(d) {
                    return loads;
                }
                loads.push(d);
            }
        }
        loads
    }

    /// Closes a batch of proven loads (load 0 first in `loads`) with one
    /// energising operation: the zone MCBs first, dead because the MCCB is
    /// open, then the MCCB. No zone is closed onto a live bus, so a trip can
    /// only come with the MCCB close, after every command of the batch; the
    /// batch's settle dwell runs from that command.
    fn close_proven_batch(&mut self, loads: Vec<u8>, out: &mut Vec<Output>) {
        if !self.interlock_ok(Breaker::Mccb, out) {
            return;
        }
        let list: Vec<String> = loads.iter().map(|l| l.to_string()).collect();
        self.set_step(
            Step::Oluc,
            &format!(
                "OLUC step 0: re-closing proven load(s) {} (proven healthy in this sequence: \
                 no dwell of their own): zone MCBs first with the main MCCB open, then the main MCCB",
                list.join(", ")
            ),
            out,
        );
        self.closing_proven = true;
        for z in loads.iter().copied().filter(|l| *l > 0) {
            self.switch(Breaker::Zone(z), true, out);
        }
        self.switch(Breaker::Mccb, true, out);
        self.closing_batch = loads;
        self.start_dwell(out);
        self.start_confirm_if_pending(out);
    }

    /// If proven loads were closed without dwell since the last dwell, starts
    /// their one settle dwell (so a late trip of theirs cannot be pinned on
    /// the next load) and returns true.
    fn settle_if_owed(&mut self, out: &mut Vec<Output>) -> bool {
        let Some(last) = self.batch.last().copied() else {
            return false;
        };
        if self.dwell_due {
            // The settle dwell ran from the batch's last close command and
            // has run out already.
            self.batch.clear();
            return false;
        }
        // Shown as the dwell of the last load closed.
        let step = if self.in_oldc && last > self.oluc_stop {
            Step::OldcDwell
        } else {
            Step::OlucDwell
        };
        let list: Vec<String> = self.batch.iter().map(|l| l.to_string()).collect();
        self.settling = true;
        self.set_step(
            step,
            &format!(
                "proven load(s) {} re-closed; one dwell from the last close command before going on",
                list.join(", ")
            ),
            out,
        );
        if self.timers[Timer::Dwell.index()].is_none() {
            // Defensive: it runs from the last close command.
            self.start_dwell(out);
        }
        true
    }

    /// Goes on with the walk of the current pass after a settle dwell.
    fn continue_pass(&mut self, now_s: f64, out: &mut Vec<Output>) {
        if self.in_oldc {
            self.oldc_next(now_s, out);
        } else {
            self.oluc_next(now_s, out);
        }
    }

    fn interlock_ok(&mut self, b: Breaker, out: &mut Vec<Output>) -> bool {
        if self.known.as_ref().is_some_and(|k| k.elcb) {
            return true;
        }
        // Unreachable while snapshots arrive in order; kept as the last guard.
        self.lock_out(
            &format!("interlock: {b} not closed because the ELCB is open"),
            out,
        );
        false
    }

    /// The load being switched on when the ELCB tripped is faulty.
    fn on_trip_during_sequence(&mut self, now_s: f64, out: &mut Vec<Output>) {
        if self.closing_proven || self.settling || !self.batch.is_empty() {
            self.on_proven_batch_trip(now_s, out);
            return;
        }
        let load = match self.step {
            Step::Oluc | Step::OlucDwell => self.count_c,
            _ => self.oldc,
        };
        self.cancel(Timer::Dwell, out);
        self.cancel(Timer::Confirm, out);
        self.pending.clear();
        self.metrics.trips += 1;
        self.metrics.reenergisations += 1;
        self.restored = false;
        self.count_sv = load;
        self.found_new = true;
        self.faulty.insert(load);
        self.raise_trip_alarm(out);
        let b = Breaker::load(load);
        event(
            out,
            "fault_found",
            format!("ELCB tripped when {b} was switched on: load {load} is faulty"),
        );
        self.raise_faulty_alarm(load, out);
        // Leave everything off in every case, then decide.
        self.enter_tripped(now_s, out);
        if load == 0 {
            self.lock_out("fault on load 0 (main MCCB / busbar)", out);
        } else if self.metrics.trips > self.settings.max_trips {
            self.lock_out(
                &format!(
                    "{} ELCB trips in one sequence (limit {})",
                    self.metrics.trips, self.settings.max_trips
                ),
                out,
            );
        }
    }

    /// The ELCB tripped while proven loads were being re-closed without dwell
    /// or during their settle dwell: which one is faulty cannot be told, so
    /// none is marked faulty; the proofs are withdrawn and the sequence starts
    /// over with a full dwell on every load (see the module docs).
    fn on_proven_batch_trip(&mut self, now_s: f64, out: &mut Vec<Output>) {
        let mut suspects = self.batch.clone();
        if self.closing_proven && !self.closing_batch.is_empty() {
            suspects.extend(self.closing_batch.iter().copied());
        } else if self.closing_proven {
            suspects.push(if self.step == Step::Oldc {
                self.oldc
            } else {
                self.count_c
            });
        }
        self.cancel(Timer::Dwell, out);
        self.cancel(Timer::Confirm, out);
        self.pending.clear();
        self.metrics.trips += 1;
        self.restored = false;
        self.proven.clear();
        self.fast_reclose = false;
        self.raise_trip_alarm(out);
        let list: Vec<String> = suspects.iter().map(|l| l.to_string()).collect();
        event(
            out,
            "proven_load_trip",
            format!(
                "ELCB tripped while re-closing load(s) {} that proved healthy earlier in this \
                 sequence: new fault, not attributable to one load; none is marked faulty, \
                 every load is switched on again with a full dwell",
                list.join(", ")
            ),
        );
        self.enter_tripped(now_s, out);
        if self.metrics.trips > self.settings.max_trips {
            self.lock_out(
                &format!(
                    "{} ELCB trips in one sequence (limit {})",
                    self.metrics.trips, self.settings.max_trips
                ),
                out,
            );
        }
    }

    fn finish(&mut self, now_s: f64, out: &mut Vec<Output>) {
        self.note_restored(now_s);
        let faulty = self.faulty_zones();
        if self.cause == Cause::Trip && !self.found_new {
            event(
                out,
                "transient_fault",
                "transient fault: every load switched on again without a trip".into(),
            );
        }
        if faulty.is_empty() {
            self.metrics.outcome = Outcome::Restored;
            self.set_rest_step("all loads restored", out);
        } else {
            self.metrics.outcome = Outcome::Isolated;
            let list: Vec<String> = faulty.iter().map(|z| z.to_string()).collect();
            self.set_rest_step(
                &format!(
                    "healthy zones restored; faulty zone(s) {} isolated",
                    list.join(", ")
                ),
                out,
            );
        }
    }

    /// Records the restore time when every load not known faulty is first
    /// confirmed closed (after the last trip).
    fn note_restored(&mut self, now_s: f64) {
        if self.restored {
            return;
        }
        let Some(k) = &self.known else { return };
        let all_on = k.elcb
            && k.loads()
                .enumerate()
                .all(|(i, b)| self.faulty.contains(&(i as u8)) || k.closed(b));
        if all_on {
            self.restored = true;
            self.metrics.restore_s = (now_s - self.started_s).max(0.0);
        }
    }

    fn lock_out(&mut self, reason: &str, out: &mut Vec<Output>) {
        self.cancel(Timer::RecloseDelay, out);
        self.cancel(Timer::Dwell, out);
        self.lockout = true;
        self.suspended_from = None;
        if self.metrics.outcome == Outcome::Running {
            self.metrics.outcome = Outcome::Lockout;
        }
        self.raise(
            LOCKOUT_ALARM,
            priority::LOCKOUT,
            format!("fault isolation locked out: {reason}; operator action required (Reset)"),
            out,
        );
        if self.mode == Mode::Manual {
            return;
        }
        self.set_step(Step::Lockout, &format!("lockout: {reason}"), out);
    }

    // ---- communication loss -------------------------------------------------

    fn suspend(&mut self, reason: &str, out: &mut Vec<Output>) {
        let from = self.step;
        for t in [Timer::RecloseDelay, Timer::Dwell, Timer::Confirm] {
            self.cancel(t, out);
        }
        self.suspended_from = Some(from);
        self.raise(
            "comm",
            priority::COMM_LOST,
            format!(
                "communication with the panel lost during the sequence (step '{}'): {reason}; sequence suspended",
                from.name()
            ),
            out,
        );
        self.set_step(
            Step::Suspended,
            &format!("suspended at step '{}': {reason}", from.name()),
            out,
        );
    }

    fn resume(&mut self, state: PanelState, now_s: f64, out: &mut Vec<Output>) {
        let Some(from) = self.suspended_from.take() else {
            self.known = Some(state);
            self.set_rest_step("communication restored", out);
            return;
        };
        self.clear("comm", out);
        if let Some(why) = self.unexplained_change(&state) {
            self.known = Some(state);
            self.lock_out(&format!("{why} while communication was lost"), out);
            return;
        }
        self.reconcile_pending(&state, out);
        let elcb = state.elcb;
        self.known = Some(state.clone());
        self.set_step(
            from,
            &format!(
                "communication restored, state re-read and consistent: resuming step '{}'",
                from.name()
            ),
            out,
        );
        if from.expects_elcb_closed() && !elcb {
            self.on_trip_during_sequence(now_s, out);
            return;
        }
        // Restart the step from its beginning.
        match from {
            Step::Tripped => self.enter_tripped(now_s, out),
            Step::RecloseWait => {
                self.start(Timer::RecloseDelay, self.settings.reclose_delay_s, out)
            }
            Step::ElcbReset => {
                if elcb {
                    // Confirmed; a re-armed check of another breaker, if
                    // any, must confirm first.
                    self.pending.retain(|(b, _)| *b != Breaker::Elcb);
                    if !self.start_confirm_if_pending(out) {
                        self.on_confirmed(now_s, out);
                    }
                } else {
                    self.pulse_reset(out);
                    self.start_confirm_if_pending(out);
                }
            }
            Step::OlucDwell | Step::OldcDwell if self.settling => {
                // The batch's settle dwell runs again in full.
                self.start_dwell(out);
            }
            Step::Oluc if !self.closing_batch.is_empty() => {
                // Re-issue what is not closed yet, zones before the MCCB; the
                // settle dwell runs again in full.
                self.start_dwell(out);
                let loads = self.closing_batch.clone();
                let zones_first = loads
                    .iter()
                    .filter(|l| **l > 0)
                    .chain(loads.iter().filter(|l| **l == 0));
                for b in zones_first.map(|l| Breaker::load(*l)).collect::<Vec<_>>() {
                    if state.closed(b) {
                        self.pending.retain(|(p, _)| *p != b);
                    } else {
                        self.switch(b, true, out);
                    }
                }
                if !self.start_confirm_if_pending(out) {
                    self.on_confirmed(now_s, out);
                }
            }
            Step::Oluc | Step::OlucDwell | Step::Oldc | Step::OldcDwell => {
                let (b, closing, dwell) = if matches!(from, Step::Oluc | Step::OlucDwell) {
                    (Breaker::load(self.count_c), Step::Oluc, Step::OlucDwell)
                } else {
                    (Breaker::Zone(self.oldc), Step::Oldc, Step::OldcDwell)
                };
                // The dwell (or settle dwell) runs again in full.
                self.start_dwell(out);
                if state.closed(b) {
                    self.pending.retain(|(p, _)| *p != b);
                    self.step = closing;
                    if !self.start_confirm_if_pending(out) {
                        let proven = self.closing_proven;
                        // Dwell again in full, or (a proven load) go on with the pass.
                        self.on_confirmed(now_s, out);
                        debug_assert!(proven || self.step == dwell);
                    }
                } else {
                    self.step = closing;
                    self.switch(b, true, out);
                    self.start_confirm_if_pending(out);
                }
            }
            _ => {}
        }
    }

    /// A breaker status that differs from what the machine knows and that no
    /// command of the machine explains (see "Asynchronous status inputs"), as
    /// a description.
    fn unexplained_change(&self, state: &PanelState) -> Option<String> {
        let known = self.known.as_ref()?;
        for b in known.loads() {
            let now = state.closed(b);
            if now != known.closed(b) && !self.explained(b, now) {
                let how = if now { "closed" } else { "opened" };
                return Some(format!("{b} {how} without a command"));
            }
        }
        if state.elcb && !known.elcb && !self.explained(Breaker::Elcb, true) {
            return Some("ELCB closed without a reset".into());
        }
        None
    }

    // ---- asynchronous status inputs ------------------------------------------

    /// Takes the time of the input being handled. A non-finite time is
    /// ignored (the previous one stays), so it cannot poison the windows.
    fn set_now(&mut self, now_s: f64) {
        if now_s.is_finite() {
            self.now_s = now_s;
        }
    }

    /// Sends a command and logs it for the confirm window. For the ELCB only
    /// reset pulses count as commands (releasing the reset output does not
    /// open it).
    fn emit(&mut self, b: Breaker, value: bool, out: &mut Vec<Output>) {
        out.push(Output::Command { breaker: b, value });
        if b == Breaker::Elcb && !value {
            return;
        }
        let log = self.commanded.entry(b).or_default();
        log.last = value;
        log.at[usize::from(value)] = Some(self.now_s);
    }

    /// Whether `b` was commanded to `value` within the confirm window.
    fn commanded_recently(&self, b: Breaker, value: bool) -> bool {
        self.commanded
            .get(&b)
            .and_then(|log| log.at[usize::from(value)])
            .is_some_and(|t| self.now_s - t <= self.settings.confirm_timeout_s + 1e-9)
    }

    /// Whether a reading of `b` as `value` is explained by the machine's own
    /// commands: one awaiting confirmation, or any (even superseded) within
    /// the confirm window.
    fn explained(&self, b: Breaker, value: bool) -> bool {
        self.pending.contains(&(b, value)) || self.commanded_recently(b, value)
    }

    /// Drops confirmed commands, then re-arms the check of every breaker whose
    /// last command lies within the confirm window and whose status differs
    /// from it (a late reading of a superseded command). Starts the confirm
    /// timer for what it re-arms, for the rest of that command's window.
    fn reconcile_pending(&mut self, state: &PanelState, out: &mut Vec<Output>) {
        self.pending.retain(|(b, v)| state.closed(*b) != *v);
        let mut rearmed_at: Option<f64> = None;
        for b in state.loads() {
            let Some(log) = self.commanded.get(&b).copied() else {
                continue;
            };
            let Some(at) = log.at[usize::from(log.last)] else {
                continue;
            };
            if state.closed(b) != log.last
                && self.commanded_recently(b, log.last)
                && !self.pending.contains(&(b, log.last))
            {
                self.pending.retain(|(p, _)| *p != b);
                self.pending.push((b, log.last));
                rearmed_at = Some(rearmed_at.map_or(at, |a: f64| a.max(at)));
            }
        }
        if let Some(at) = rearmed_at {
            if self.timers[Timer::Confirm.index()].is_none() {
                let left = (at + self.settings.confirm_timeout_s - self.now_s).max(0.001);
                self.start(Timer::Confirm, left, out);
            }
        }
    }

    // ---- helpers ------------------------------------------------------------

    /// Commands `b` to `value`, expecting its status to follow.
    fn switch(&mut self, b: Breaker, value: bool, out: &mut Vec<Output>) {
        self.emit(b, value, out);
        self.pending.retain(|(p, _)| *p != b);
        if self.known.as_ref().is_some_and(|k| k.closed(b) != value) {
            self.metrics.switching_ops += 1;
            self.pending.push((b, value));
        }
    }

    /// Starts the confirmation timer if commands await confirmation.
    fn start_confirm_if_pending(&mut self, out: &mut Vec<Output>) -> bool {
        if self.pending.is_empty() {
            return false;
        }
        self.start(Timer::Confirm, self.settings.confirm_timeout_s, out);
        true
    }

    /// The resting step of the current mode.
    fn set_rest_step(&mut self, why: &str, out: &mut Vec<Output>) {
        let step = match (self.mode, self.lockout, self.faulty.is_empty()) {
            (Mode::Manual, _, _) => Step::Manual,
            (Mode::Auto, true, _) => Step::Lockout,
            (Mode::Auto, false, true) => Step::Idle,
            (Mode::Auto, false, false) => Step::Isolated,
        };
        self.set_step(step, why, out);
    }

    fn set_step(&mut self, step: Step, why: &str, out: &mut Vec<Output>) {
        self.step = step;
        event(out, "step", format!("{}: {why}", step.name()));
    }

    fn start(&mut self, timer: Timer, after_s: f64, out: &mut Vec<Output>) {
        self.next_token += 1;
        self.timers[timer.index()] = Some(self.next_token);
        out.push(Output::StartTimer {
            timer,
            after_s,
            token: self.next_token,
        });
    }

    fn cancel(&mut self, timer: Timer, out: &mut Vec<Output>) {
        if self.timers[timer.index()].take().is_some() {
            out.push(Output::CancelTimer { timer });
        }
    }

    fn raise_faulty_alarm(&mut self, load: u8, out: &mut Vec<Output>) {
        let (priority, message) = if load == 0 {
            (
                priority::LOAD0_FAULT,
                "fault on load 0 (main MCCB / busbar): nothing can be restored".to_string(),
            )
        } else {
            (
                priority::ZONE_ISOLATED,
                format!("zone {load} is faulty and isolated (left off)"),
            )
        };
        self.raise(&faulty_alarm_key(load), priority, message, out);
    }

    fn raise_trip_alarm(&mut self, out: &mut Vec<Output>) {
        self.raise(
            "elcb.trip",
            priority::ELCB_TRIP,
            "ELCB tripped: supply to all zones lost".into(),
            out,
        );
    }

    fn raise(&mut self, key: &str, priority: u32, message: String, out: &mut Vec<Output>) {
        if self
            .active_alarms
            .insert(key.to_string(), priority)
            .is_none()
        {
            out.push(Output::Alarm {
                key: key.to_string(),
                active: true,
                priority,
                message,
            });
        }
    }

    fn clear(&mut self, key: &str, out: &mut Vec<Output>) {
        if let Some(priority) = self.active_alarms.remove(key) {
            out.push(Output::Alarm {
                key: key.to_string(),
                active: false,
                priority,
                message: format!("{key}: cleared"),
            });
        }
    }

    /// Commands awaiting confirmation outside a running sequence (manual mode,
    /// lockout): drop those the status now confirms.
    fn settle_pending(&mut self, state: &PanelState, out: &mut Vec<Output>) {
        self.reconcile_pending(state, out);
        if self.pending.is_empty() {
            self.cancel(Timer::Confirm, out);
        }
    }
}

fn event(out: &mut Vec<Output>, kind: &'static str, message: String) {
    out.push(Output::Event { kind, message });
}
