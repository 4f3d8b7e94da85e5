//! Asynchronous status inputs: the log of commands sent, the confirm
//! window, which status changes the machine's commands explain, and the
//! commands awaiting confirmation.

use super::io::{Breaker, Output, PanelState, Timer};
use super::Sequence;

/// The commands last sent to one breaker.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct CommandLog {
    /// The value of the last command.
    last: bool,
    /// When it was last commanded open (`[0]`) and closed (`[1]`).
    at: [Option<f64>; 2],
}

impl Sequence {
    /// Takes the time of the input being handled. A non-finite time is
    /// ignored (the previous one stays), so it cannot poison the windows.
    pub(super) fn set_now(&mut self, now_s: f64) {
        if now_s.is_finite() {
            self.now_s = now_s;
        }
    }

    /// Sends a command and logs it for the confirm window. For the ELCB only
    /// reset pulses count as commands (releasing the reset output does not
    /// open it).
    pub(super) fn emit(&mut self, b: Breaker, value: bool, out: &mut Vec<Output>) {
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
    pub(super) fn explained(&self, b: Breaker, value: bool) -> bool {
        self.pending.contains(&(b, value)) || self.commanded_recently(b, value)
    }

    /// Drops confirmed commands, then re-arms the check of every breaker whose
    /// last command lies within the confirm window and whose status differs
    /// from it (a late reading of a superseded command). Starts the confirm
    /// timer for what it re-arms, for the rest of that command's window.
    pub(super) fn reconcile_pending(&mut self, state: &PanelState, out: &mut Vec<Output>) {
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

    /// Commands `b` to `value`, expecting its status to follow.
    pub(super) fn switch(&mut self, b: Breaker, value: bool, out: &mut Vec<Output>) {
        self.emit(b, value, out);
        self.pending.retain(|(p, _)| *p != b);
        if self.known.as_ref().is_some_and(|k| k.closed(b) != value) {
            self.metrics.switching_ops += 1;
            self.pending.push((b, value));
        }
    }

    /// Starts the confirmation timer if commands await confirmation.
    pub(super) fn start_confirm_if_pending(&mut self, out: &mut Vec<Output>) -> bool {
        if self.pending.is_empty() {
            return false;
        }
        self.start(Timer::Confirm, self.settings.confirm_timeout_s, out);
        true
    }

    /// Commands awaiting confirmation outside a running sequence (manual mode,
    /// lockout): drop those the status now confirms.
    pub(super) fn settle_pending(&mut self, state: &PanelState, out: &mut Vec<Output>) {
        self.reconcile_pending(state, out);
        if self.pending.is_empty() {
            self.cancel(Timer::Confirm, out);
        }
    }
}
