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
//! ## Revisiting a blame
//! A trip while load `k` dwells is pinned on `k`, but a fault may also arise
//! during the sequence on a load energised beside `k` (one proven earlier).
//! The two cannot be told apart at the trip. So each blame of a sequence
//! remembers the other loads energised when its trip came; when one of them
//! is later found faulty (which the plain algorithm does, after the batch of
//! proven loads trips), every blame it may have caused is withdrawn: the
//! load's faulty mark and alarm are cleared (event `blame_withdrawn`) and it
//! is switched on again, with a full dwell, in the next pass. A load's blame
//! is withdrawn at most once per sequence. Only where the evidence is
//! ambiguous: a load held energised for a full dwell without a trip after
//! the blame (re-closed while the blamed load was open) was healthy then,
//! hence also at the blamed trip (faults are permanent), and no longer casts
//! doubt on it; its own fault, found later, arose after that trip, and the
//! blamed load is not switched back onto its fault.
//!
//! A trip read only after a **communication loss** (the ELCB found open on
//! resume) came at an unknown moment, with unknown loads energised: it is
//! pinned on no load (event `comm_loss_trip`) and handled like a trip of a
//! proven batch: the proofs are withdrawn and every load is switched on
//! again with a full dwell.
//!
//! **Bounds.** With faults present from the start nothing is withdrawn:
//! each faulty zone is energised exactly once and there are F + 1 trips for F
//! faulty zones. Each trip that cannot be pinned (a proven batch, or one seen
//! after a communication loss) re-energises a faulty load at most once more
//! and adds at most two trips; each withdrawn blame re-energises a healthy
//! load once more. The exhaustive test with one fault arising at any step
//! (watched or blind) on top of one or two present from the start measures
//! at most 3 × F + 1 trips. Whatever happens, more than `max_trips` trips
//! lock out with everything off, so a panel never cycles.
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
//! A sequence that does not restore (a lockout, or stopped by manual mode)
//! has no restore time (`None`), nor has one while it runs; a trip after the
//! healthy loads were all on withdraws the time noted until then.
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
//!   that opened while blind is a trip, pinned on no load (see "Revisiting a
//!   blame"). Anything else locks out. On resume the step in progress is
//!   restarted from its beginning (its timer runs again in full, an unconfirmed
//!   command is re-issued), which is never shorter than the original wait.
//! - Switching to manual mode stops the sequence at once (nothing further is
//!   switched); manual breaker commands are refused in automatic mode.
//!   In manual mode nothing switches by itself. Back in automatic mode,
//!   loads left off and not known faulty stay off (a mode change switches
//!   nothing on) under a standing `loads_off` alarm until Reset restores
//!   them. The alarm is checked on every good snapshot at rest in automatic
//!   mode (so it also comes when automatic mode was chosen while the panel
//!   was unreadable, or a breaker was opened by hand, and goes when the
//!   loads read closed again), and it stays standing across a restart
//!   (`Retained::loads_off`). A sequence interrupted by a restart or a
//!   failover is finished by the server taking over (next section).
//!
//! ## Taking over a sequence
//! The server that takes over (the same one after a restart, the other one
//! of a pair after a failover) finishes an interrupted sequence from the
//! retained state (mode, faulty loads, lockout, and the sequence's
//! [`Progress`]: the step, the loads proven healthy, the trip count, the
//! blames) and the panel as read now. Nothing is switched before a read
//! with every signal Good (as after a communication loss; the sequence waits
//! at `suspended`). Then, with event `resumed` ("sequence resumed after a
//! restart|failover at step X: what was tested again") shown on the panel
//! screen (`PanelStatus::resumed`):
//! - a known-faulty load read on with the ELCB closed is contradictory (no
//!   step does it): lockout, saying so;
//! - interrupted while opening, waiting to reclose or resetting the ELCB:
//!   every breaker is opened again, the reclose delay and the reset run
//!   again in full;
//! - interrupted in OLUC/OLDC with the ELCB read open: a trip while no
//!   server watched, pinned on no load (event `takeover_trip`, counted
//!   against the trip limit), as after a communication loss;
//! - with the ELCB closed: proven loads found on stay on. One load on but
//!   not proven, where the walk leaves it (every load the walk closes before
//!   it is on), is tested again with a full dwell, then the walk goes on.
//!   No unproven load on: the proven ones owe one settle dwell (when they
//!   were closed is not known), then the walk goes on from load 0, skipping
//!   what is on. Anything else (several unproven loads on, zones on with the
//!   MCCB open): everything is opened and the walk starts again, proven
//!   loads re-closed together, the others with a full dwell.
//!
//! The trip count goes on from the saved one, so the trip limit counts the
//! trips before the interruption. The retained state is saved on every change
//! (`PanelStatus::retained`); a save that had not landed when the server was
//! lost leaves a state one step behind the panel, which the rules above
//! handle the same way (the exhaustive test takes over at every step, with
//! the last save landed and lagging). The restore time of a resumed sequence
//! counts from the takeover. A sequence saved without its progress (an older
//! version) locks out, as before.
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
//!
//! ## Files
//! This file holds the [`Sequence`] and its entry points. What it is given
//! and gives: `io.rs`; steps and metrics: `step.rs`; taking each input:
//! `inputs.rs`; the steps of the sequence: `steps.rs`; attribution and proven
//! loads: `attribution.rs`; the communication loss rule: `comm.rs`;
//! asynchronous status inputs: `confirm.rs`; operator commands:
//! `operator.rs`; alarms and events: `alarms.rs`; what survives a restart:
//! `retained.rs`; taking over an interrupted sequence: `takeover.rs`.

use std::collections::{BTreeMap, BTreeSet};

mod alarms;
mod attribution;
mod comm;
mod confirm;
mod inputs;
mod io;
mod operator;
mod retained;
mod step;
mod steps;
mod takeover;

pub use gridscada_config::PanelMode as Mode;

pub use alarms::{priority, ELCB_TRIP_ALARM};
pub use io::{
    BlockedOperation, Breaker, CommandError, Input, OperatorCommand, Output, PanelState, Reading,
    Settings, Snapshot, Timer,
};
pub use retained::{Progress, Retained, Takeover};
pub use step::{Metrics, Outcome, Step};

use confirm::CommandLog;
use steps::Cause;

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
    /// Operations the server refuses now (safety tags, interlocks), from
    /// the latest snapshot.
    blocked: Vec<io::BlockedOperation>,
    /// Loads this sequence left open because closing them is refused.
    left_open: BTreeSet<u8>,
    /// The reclose delay of the last trip has run out (the ELCB is reset as
    /// soon as every open is confirmed).
    reclose_due: bool,
    /// The dwell timer of the last close command has run out (the next load
    /// is closed as soon as this one is confirmed).
    dwell_due: bool,
    /// Known-faulty loads (0 = MCCB / busbar).
    faulty: BTreeSet<u8>,
    /// The loads marked faulty in this sequence, each with the other loads
    /// that were energised when its trip came (see "Revisiting a blame").
    marks: BTreeMap<u8, BTreeSet<u8>>,
    /// Loads whose blame was withdrawn once in this sequence: never again,
    /// so each is re-energised at most once more.
    retested: BTreeSet<u8>,
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
    /// The sequence was taken over from a previous run (a restart or a
    /// failover): it finishes on the first good read of the panel.
    takeover: Option<Takeover>,
    /// How this sequence was resumed after a takeover, for the panel screen.
    resumed: Option<String>,
    started_s: f64,
    metrics: Metrics,
}

impl Sequence {
    pub fn new(settings: Settings) -> Sequence {
        let mode = settings.start_mode;
        let metrics = Metrics {
            restore_s: None,
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
            blocked: Vec::new(),
            left_open: BTreeSet::new(),
            reclose_due: false,
            dwell_due: false,
            faulty: BTreeSet::new(),
            marks: BTreeMap::new(),
            retested: BTreeSet::new(),
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
            takeover: None,
            resumed: None,
            started_s: 0.0,
            metrics,
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
    /// How the last sequence was resumed after a restart or a failover (at
    /// which step, what was tested again), if it was.
    pub fn resumed(&self) -> Option<&str> {
        self.resumed.as_deref()
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
}
