//! Attribution of a trip to a load, and proven loads re-closed without a
//! dwell of their own: batches, their settle dwell, and a trip of a batch
//! (see "Proven loads" and "Attribution rule" in the module docs).

use super::alarms::event;
use super::io::{Breaker, Output, Timer};
use super::step::Step;
use super::Sequence;

impl Sequence {
    /// Whether `load` may be re-closed without a dwell of its own.
    pub(super) fn is_proven(&self, load: u8) -> bool {
        self.fast_reclose && self.proven.contains(&load)
    }

    /// The loads the walk of this pass would close next, from load 0, as
    /// long as they are proven (the walk skips closed and known-faulty loads
    /// exactly as `oluc_next` / `oldc_next` do). Starts with load 0.
    pub(super) fn proven_prefix(&self) -> Vec<u8> {
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
            // A zone the server will not close is passed over (the walk
            // says so when it gets there); the MCCB ends the batch.
            if self.blocked_reason(Breaker::load(c), true).is_some() {
                if c == 0 {
                    return loads;
                }
                continue;
            }
            if !self.is_proven(c) {
                return loads;
            }
            loads.push(c);
        }
        if let Some(stop) = stop.filter(|s| *s > 0) {
            for d in (stop + 1..=n).rev() {
                if self.faulty.contains(&d)
                    || closed(d)
                    || self.blocked_reason(Breaker::Zone(d), true).is_some()
                {
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
    pub(super) fn close_proven_batch(&mut self, loads: Vec<u8>, out: &mut Vec<Output>) {
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
    pub(super) fn settle_if_owed(&mut self, out: &mut Vec<Output>) -> bool {
        let Some(last) = self.batch.last().copied() else {
            return false;
        };
        if self.dwell_due {
            // The settle dwell ran from the batch's last close command and
            // has run out already.
            self.clear_doubts_of_energised();
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
    pub(super) fn continue_pass(&mut self, now_s: f64, out: &mut Vec<Output>) {
        if self.in_oldc {
            self.oldc_next(now_s, out);
        } else {
            self.oluc_next(now_s, out);
        }
    }

    /// The loads energised (or being closed) as far as the machine knows:
    /// closed in the last good snapshot, the batch being closed, and `also`.
    pub(super) fn energised_loads(&self, also: Option<u8>) -> Vec<u8> {
        let n = self.settings.zones;
        let closed = |l: u8| {
            self.known
                .as_ref()
                .is_some_and(|k| k.closed(Breaker::load(l)))
        };
        (0..=n)
            .filter(|l| closed(*l) || self.closing_batch.contains(l) || also == Some(*l))
            .collect()
    }

    /// The load being switched on when the ELCB tripped is faulty.
    pub(super) fn on_trip_during_sequence(&mut self, now_s: f64, out: &mut Vec<Output>) {
        if self.closing_proven || self.settling || !self.batch.is_empty() {
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
            let list: Vec<String> = suspects.iter().map(|l| l.to_string()).collect();
            self.on_unattributable_trip(
                "proven_load_trip",
                &format!(
                    "the ELCB tripped while re-closing load(s) {} that proved healthy earlier \
                     in this sequence: a new fault",
                    list.join(", ")
                ),
                suspects,
                now_s,
                out,
            );
            return;
        }
        let load = match self.step {
            Step::Oluc | Step::OlucDwell => self.count_c,
            _ => self.oldc,
        };
        let energised: std::collections::BTreeSet<u8> = self
            .energised_loads(Some(load))
            .into_iter()
            .filter(|l| *l != load)
            .collect();
        self.cancel(Timer::Dwell, out);
        self.cancel(Timer::Confirm, out);
        self.pending.clear();
        self.metrics.trips += 1;
        self.metrics.reenergisations += 1;
        self.restored = false;
        self.metrics.restore_s = None;
        self.count_sv = load;
        self.found_new = true;
        self.faulty.insert(load);
        self.marks.insert(load, energised);
        self.raise_trip_alarm(out);
        let b = Breaker::load(load);
        event(
            out,
            "fault_found",
            format!("ELCB tripped when {b} was switched on: load {load} is faulty"),
        );
        self.raise_faulty_alarm(load, out);
        self.revisit_blames(load, out);
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

    /// A dwell ran out with the ELCB holding: every load energised now has
    /// been on for a full dwell without a trip, so it was healthy then, and
    /// (faults being permanent) also when an earlier trip of this sequence
    /// was pinned on another load while it was energised. It no longer casts
    /// doubt on that blame (see "Revisiting a blame").
    pub(super) fn clear_doubts_of_energised(&mut self) {
        let Some(k) = self.known.as_ref().filter(|k| k.elcb && k.mccb) else {
            return;
        };
        let held: Vec<u8> = (0..=self.settings.zones)
            .filter(|l| k.closed(Breaker::load(*l)))
            .collect();
        for energised in self.marks.values_mut() {
            energised.retain(|l| !held.contains(l));
        }
    }

    /// A load just found faulty was energised when an earlier trip of this
    /// sequence was pinned on another load: that blame may have been this
    /// fault's, so it is withdrawn and the load is tested again (once; see
    /// "Revisiting a blame" in the module docs).
    fn revisit_blames(&mut self, found: u8, out: &mut Vec<Output>) {
        let doubtful: Vec<u8> = self
            .marks
            .iter()
            .filter(|(m, energised)| **m != found && energised.contains(&found))
            .map(|(m, _)| *m)
            .filter(|m| *m != 0 && !self.retested.contains(m))
            .collect();
        for m in doubtful {
            self.marks.remove(&m);
            self.faulty.remove(&m);
            self.retested.insert(m);
            self.clear(&super::alarms::faulty_alarm_key(m), out);
            event(
                out,
                "blame_withdrawn",
                format!(
                    "load {m} was blamed for a trip while load {found} was energised, and load \
                     {found} is faulty: load {m} is switched on again to be tested once more"
                ),
            );
        }
    }

    /// A trip that cannot be pinned on one load: while proven loads were
    /// being re-closed without dwell or during their settle dwell, or while
    /// communication with the panel was lost. None is marked faulty; the
    /// proofs are withdrawn and the sequence goes on with a full dwell on
    /// every load (see the module docs), which attributes the fault.
    pub(super) fn on_unattributable_trip(
        &mut self,
        kind: &'static str,
        why: &str,
        suspects: Vec<u8>,
        now_s: f64,
        out: &mut Vec<Output>,
    ) {
        self.cancel(Timer::Dwell, out);
        self.cancel(Timer::Confirm, out);
        self.pending.clear();
        self.metrics.trips += 1;
        self.restored = false;
        self.metrics.restore_s = None;
        self.proven.clear();
        self.fast_reclose = false;
        self.raise_trip_alarm(out);
        let list: Vec<String> = suspects.iter().map(|l| l.to_string()).collect();
        event(
            out,
            kind,
            format!(
                "{why}; the fault cannot be pinned on one of load(s) {}: none is marked \
                 faulty, every load is switched on again with a full dwell",
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
}
