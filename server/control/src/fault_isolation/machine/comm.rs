//! The communication loss rule: suspending a sequence when a signal goes
//! bad, and resuming it (or locking out) on the next good snapshot.

use super::alarms::priority;
use super::io::{Breaker, Output, PanelState, Timer};
use super::step::Step;
use super::Sequence;

impl Sequence {
    pub(super) fn suspend(&mut self, reason: &str, out: &mut Vec<Output>) {
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

    pub(super) fn resume(&mut self, state: PanelState, now_s: f64, out: &mut Vec<Output>) {
        let takeover = self.takeover.take();
        let Some(from) = self.suspended_from.take() else {
            self.known = Some(state);
            self.set_rest_step("communication restored", out);
            return;
        };
        self.clear("comm", out);
        if let Some(how) = takeover {
            self.take_over(how, from, state, now_s, out);
            return;
        }
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
            // When it tripped, and what was energised then, is unknown: the
            // load dwelling when the panel went silent may be innocent.
            self.on_unattributable_trip(
                "comm_loss_trip",
                "the ELCB tripped while communication with the panel was lost",
                self.energised_loads(None),
                now_s,
                out,
            );
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
    pub(super) fn unexplained_change(&self, state: &PanelState) -> Option<String> {
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
}
