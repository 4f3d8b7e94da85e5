//! The steps of the sequence: the opens after a trip, the ELCB reset, the
//! OLUC and OLDC walks with their dwells, the end of a sequence and the
//! lockout, and moving between steps and timers.

use super::alarms::{event, priority, ELCB_TRIP_ALARM, LOADS_OFF_ALARM, LOCKOUT_ALARM};
use super::io::{Breaker, Output, Timer};
use super::step::{Metrics, Outcome, Step};
use super::{Mode, Sequence};

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Cause {
    Trip,
    Reset,
}

impl Sequence {
    pub(super) fn start_sequence(&mut self, cause: Cause, now_s: f64, out: &mut Vec<Output>) {
        self.cause = cause;
        self.clear(LOADS_OFF_ALARM, out);
        self.found_new = false;
        self.restored = false;
        self.takeover = None;
        self.resumed = None;
        self.started_s = now_s;
        self.metrics = Metrics {
            restore_s: None,
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
        self.marks.clear();
        self.retested.clear();
        self.batch.clear();
        self.closing_proven = false;
        self.settling = false;
        self.closing_batch.clear();
        self.left_open.clear();
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
    pub(super) fn enter_tripped(&mut self, now_s: f64, out: &mut Vec<Output>) {
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
            if let Some(why) = self.blocked_reason(b, false) {
                // The server refuses to open it: leave it as it is.
                if known.closed(b) {
                    event(out, "breaker_blocked", format!("{b} left closed: {why}"));
                }
                continue;
            }
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

    pub(super) fn on_confirmed(&mut self, now_s: f64, out: &mut Vec<Output>) {
        match self.step {
            Step::Tripped => self.on_confirmed_tripped(now_s, out),
            Step::ElcbReset => {
                self.clear(ELCB_TRIP_ALARM, out);
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

    pub(super) fn enter_elcb_reset(&mut self, out: &mut Vec<Output>) {
        self.reclose_due = false;
        if let Some(why) = self.blocked_reason(Breaker::Elcb, true) {
            self.lock_out(&format!("the ELCB cannot be reset: {why}"), out);
            return;
        }
        self.set_step(Step::ElcbReset, "resetting the ELCB", out);
        self.pulse_reset(out);
        self.start_confirm_if_pending(out);
    }

    pub(super) fn pulse_reset(&mut self, out: &mut Vec<Output>) {
        self.emit(Breaker::Elcb, true, out);
        self.emit(Breaker::Elcb, false, out);
        self.metrics.switching_ops += 1;
        self.metrics.elcb_resets += 1;
        self.pending.retain(|(b, _)| *b != Breaker::Elcb);
        self.pending.push((Breaker::Elcb, true));
    }

    /// OLUC: switch on the next load from `count_c` upwards.
    pub(super) fn oluc_next(&mut self, now_s: f64, out: &mut Vec<Output>) {
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
            if let Some(why) = self.blocked_reason(b, true) {
                self.left_open.insert(c);
                if c == 0 {
                    event(
                        out,
                        "load_blocked",
                        format!("OLUC cannot close the main MCCB: {why}; no zone can be restored"),
                    );
                    if !self.settle_if_owed(out) {
                        self.finish(now_s, out);
                    }
                    return;
                }
                event(
                    out,
                    "load_blocked",
                    format!("OLUC leaves zone {c} open: {why}"),
                );
                self.count_c = c + 1;
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
    pub(super) fn oldc_next(&mut self, now_s: f64, out: &mut Vec<Output>) {
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
            if let Some(why) = self.blocked_reason(b, true) {
                if self.left_open.insert(d) {
                    event(
                        out,
                        "load_blocked",
                        format!("OLDC leaves zone {d} open: {why}"),
                    );
                }
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

    /// A dwell ran out after load `count_c` was confirmed closed: it is
    /// proven; OLUC goes on.
    pub(super) fn oluc_dwell_done(&mut self, now_s: f64, out: &mut Vec<Output>) {
        self.clear_doubts_of_energised();
        self.proven.insert(self.count_c);
        self.count_c = self.count_c.saturating_add(1);
        self.oluc_next(now_s, out);
    }

    pub(super) fn oldc_dwell_done(&mut self, now_s: f64, out: &mut Vec<Output>) {
        self.clear_doubts_of_energised();
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

    pub(super) fn start_dwell(&mut self, out: &mut Vec<Output>) {
        self.dwell_due = false;
        self.start(Timer::Dwell, self.settings.dwell_s, out);
    }

    /// Why the server would refuse to close (or open) `b` now, if it would.
    pub(super) fn blocked_reason(&self, b: Breaker, close: bool) -> Option<String> {
        self.blocked
            .iter()
            .find(|x| x.breaker == b && x.close == close)
            .map(|x| x.reason.clone())
    }

    pub(super) fn interlock_ok(&mut self, b: Breaker, out: &mut Vec<Output>) -> bool {
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

    pub(super) fn finish(&mut self, now_s: f64, out: &mut Vec<Output>) {
        self.note_restored(now_s);
        let faulty = self.faulty_zones();
        if self.cause == Cause::Trip && !self.found_new {
            event(
                out,
                "transient_fault",
                "transient fault: every load switched on again without a trip".into(),
            );
        }
        let took = match self.metrics.restore_s {
            Some(s) => format!(" in {s:.1} s"),
            None => String::new(),
        };
        let left: Vec<String> = self
            .left_open
            .iter()
            .map(|l| match l {
                0 => "the main MCCB".to_string(),
                z => format!("zone {z}"),
            })
            .collect();
        let took = if left.is_empty() {
            took
        } else {
            format!("{took}; {} left open (closing refused)", left.join(", "))
        };
        if faulty.is_empty() && self.left_open.is_empty() {
            self.metrics.outcome = Outcome::Restored;
            self.set_rest_step(&format!("all loads restored{took}"), out);
        } else if faulty.is_empty() {
            self.metrics.outcome = Outcome::Restored;
            self.set_rest_step(&format!("loads restored{took}"), out);
        } else {
            self.metrics.outcome = Outcome::Isolated;
            let list: Vec<String> = faulty.iter().map(|z| z.to_string()).collect();
            self.set_rest_step(
                &format!(
                    "healthy zones restored{took}; faulty zone(s) {} isolated",
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
            self.metrics.restore_s = Some((now_s - self.started_s).max(0.0));
        }
    }

    pub(super) fn lock_out(&mut self, reason: &str, out: &mut Vec<Output>) {
        self.cancel(Timer::RecloseDelay, out);
        self.cancel(Timer::Dwell, out);
        self.lockout = true;
        self.suspended_from = None;
        if self.metrics.outcome == Outcome::Running {
            // Whatever was on before, the sequence ended without restoring.
            self.metrics.outcome = Outcome::Lockout;
            self.metrics.restore_s = None;
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

    /// The resting step of the current mode.
    pub(super) fn set_rest_step(&mut self, why: &str, out: &mut Vec<Output>) {
        let step = match (self.mode, self.lockout, self.faulty.is_empty()) {
            (Mode::Manual, _, _) => Step::Manual,
            (Mode::Auto, true, _) => Step::Lockout,
            (Mode::Auto, false, true) => Step::Idle,
            (Mode::Auto, false, false) => Step::Isolated,
        };
        self.set_step(step, why, out);
    }

    pub(super) fn set_step(&mut self, step: Step, why: &str, out: &mut Vec<Output>) {
        self.step = step;
        event(out, "step", format!("{}: {why}", step.name()));
    }

    pub(super) fn start(&mut self, timer: Timer, after_s: f64, out: &mut Vec<Output>) {
        self.next_token += 1;
        self.timers[timer.index()] = Some(self.next_token);
        out.push(Output::StartTimer {
            timer,
            after_s,
            token: self.next_token,
        });
    }

    pub(super) fn cancel(&mut self, timer: Timer, out: &mut Vec<Output>) {
        if self.timers[timer.index()].take().is_some() {
            out.push(Output::CancelTimer { timer });
        }
    }
}
