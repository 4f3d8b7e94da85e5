//! How the machine takes each kind of input: snapshots, timer expiries,
//! confirmation timeouts and commands the field layer refused.

use super::alarms::{event, priority};
use super::io::{Breaker, Output, PanelState, Snapshot, Timer};
use super::step::Step;
use super::steps::Cause;
use super::{Mode, Sequence};

impl Sequence {
    pub(super) fn on_snapshot(&mut self, s: &Snapshot, now_s: f64, out: &mut Vec<Output>) {
        self.blocked.clone_from(&s.blocked);
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
                } else {
                    self.check_loads_off(out);
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

    pub(super) fn on_timer(&mut self, timer: Timer, now_s: f64, out: &mut Vec<Output>) {
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
                self.clear_doubts_of_energised();
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

    pub(super) fn on_command_failed(
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
}
