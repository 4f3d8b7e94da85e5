//! Operator commands: the mode switch, Reset and manual breaker commands.

use super::alarms::{event, LOADS_OFF_ALARM};
use super::io::{Breaker, CommandError, Output, Timer};
use super::step::{Outcome, Step};
use super::steps::Cause;
use super::{Mode, Sequence};

impl Sequence {
    pub(super) fn enter_manual_mode(&mut self, out: &mut Vec<Output>) {
        if self.mode == Mode::Manual {
            return;
        }
        self.mode = Mode::Manual;
        self.clear(LOADS_OFF_ALARM, out);
        let was = self.step;
        self.cancel(Timer::RecloseDelay, out);
        self.cancel(Timer::Dwell, out);
        // Commands already sent stay checked against their status inputs.
        if was.is_running() || was == Step::Suspended {
            self.metrics.outcome = Outcome::Stopped;
            self.metrics.restore_s = None;
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

    pub(super) fn enter_auto_mode(&mut self, now_s: f64, out: &mut Vec<Output>) {
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
            return;
        }
        // Loads left off (an interrupted sequence, or switched off by hand)
        // are not switched on by a mode change: that is Reset's job, and the
        // operator is told so by a standing alarm.
        self.check_loads_off(out);
    }

    pub(super) fn reset(&mut self, now_s: f64, out: &mut Vec<Output>) -> Result<(), CommandError> {
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

    pub(super) fn manual_breaker(
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
}
