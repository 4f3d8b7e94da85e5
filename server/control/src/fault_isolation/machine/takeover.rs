//! Taking over a sequence interrupted by a restart of the server or a
//! failover of a pair: waiting for the first good read of the panel, then
//! finishing the sequence from that read and the retained [`Progress`]
//! (see "Taking over a sequence" in the module docs).

use super::alarms::{event, ELCB_TRIP_ALARM};
use super::io::{Breaker, Output, PanelState};
use super::retained::{Progress, Takeover};
use super::step::{Outcome, Step};
use super::steps::Cause;
use super::Sequence;

impl Sequence {
    /// Takes the retained progress of a sequence interrupted at `step`;
    /// nothing is switched until the panel is read with every signal Good.
    pub(super) fn await_takeover(
        &mut self,
        how: Takeover,
        step: Step,
        p: &Progress,
        out: &mut Vec<Output>,
    ) {
        let zones = self.settings.zones;
        let ours = |l: &u8| *l <= zones;
        self.cause = if p.after_trip {
            Cause::Trip
        } else {
            Cause::Reset
        };
        self.proven = p.proven.iter().copied().filter(ours).collect();
        self.fast_reclose = p.fast_reclose;
        self.marks = p
            .blames
            .iter()
            .filter(|(m, _)| ours(m))
            .map(|(m, e)| (*m, e.iter().copied().filter(ours).collect()))
            .collect();
        self.retested = p.retested.iter().copied().filter(ours).collect();
        self.found_new = p.found_new;
        self.metrics.trips = p.trips;
        self.metrics.elcb_resets = p.elcb_resets;
        self.metrics.switching_ops = p.switching_ops;
        self.metrics.reenergisations = p.reenergisations;
        self.metrics.outcome = Outcome::Running;
        self.takeover = Some(how);
        self.suspended_from = Some(step);
        self.set_step(
            Step::Suspended,
            &format!(
                "sequence interrupted by a {how} at step '{}': it resumes once the panel \
                 is read with every signal Good",
                step.name()
            ),
            out,
        );
    }

    /// Finishes the interrupted sequence from the panel as read now. Proven
    /// loads found on stay on; a load found on whose health is not proven is
    /// tested again with a full dwell; anything the read does not explain
    /// opens everything and walks again; an ELCB found open where the step
    /// expected it closed is a trip pinned on no load.
    pub(super) fn take_over(
        &mut self,
        how: Takeover,
        from: Step,
        state: PanelState,
        now_s: f64,
        out: &mut Vec<Output>,
    ) {
        self.started_s = now_s;
        self.known = Some(state.clone());
        let at = from.name();
        let energised = |l: u8| state.elcb && state.mccb && state.closed(Breaker::load(l));
        if let Some(l) = self.faulty.iter().copied().find(|l| energised(*l)) {
            self.resumed = Some(format!("not resumed: known-faulty load {l} reads on"));
            self.lock_out(
                &format!(
                    "after a {how} at step '{at}', load {l}, known faulty, reads on with the \
                     ELCB closed, which no step of the sequence does; check the panel"
                ),
                out,
            );
            return;
        }
        let list = |loads: &[u8]| {
            loads
                .iter()
                .map(|l| l.to_string())
                .collect::<Vec<_>>()
                .join(", ")
        };
        let n = self.settings.zones;
        let closed: Vec<u8> = (0..=n)
            .filter(|l| state.closed(Breaker::load(*l)))
            .collect();
        let unproven: Vec<u8> = closed
            .iter()
            .copied()
            .filter(|l| !self.proven.contains(l))
            .collect();
        let under_test = if from.expects_elcb_closed() && state.mccb {
            self.single_load_under_test(&state, &unproven)
        } else {
            None
        };
        let what;
        if !from.expects_elcb_closed() {
            // Opening, waiting to reclose, resetting: all done again in full.
            if state.elcb {
                self.clear(ELCB_TRIP_ALARM, out);
            } else {
                self.raise_trip_alarm(out);
            }
            what = "every breaker opened again, the reclose delay and the ELCB reset run again \
                    in full"
                .to_string();
            self.note_resumed(how, at, &what, out);
            self.enter_tripped(now_s, out);
        } else if let Some((u, walk)) = under_test.filter(|_| !state.elcb) {
            // Nothing was switched after the load under test was closed: the
            // trip is pinned on it as if read at once (a proven load found
            // faulty later withdraws the blame, see "Revisiting a blame").
            what = format!(
                "the ELCB was found open while load {u}, not proven healthy, was on under \
                 test: the trip is pinned on load {u}"
            );
            self.note_resumed(how, at, &what, out);
            self.place_walk_at(u, walk);
            self.on_trip_during_sequence(now_s, out);
        } else if !state.elcb {
            what = "the ELCB was found open: a trip while no server watched the panel, pinned \
                    on no load; every load is tested again with a full dwell"
                .to_string();
            self.note_resumed(how, at, &what, out);
            self.on_unattributable_trip(
                "takeover_trip",
                &format!("the ELCB tripped during the {how}"),
                closed,
                now_s,
                out,
            );
        } else if let Some((u, walk)) = under_test {
            let proven_on: Vec<_> = closed.iter().copied().filter(|l| *l != u).collect();
            let kept = if proven_on.is_empty() {
                String::new()
            } else {
                format!("; proven load(s) {} kept on", list(&proven_on))
            };
            what = format!(
                "load {u}, on but not proven healthy, is tested again with a full dwell{kept}"
            );
            self.note_resumed(how, at, &what, out);
            self.place_walk_at(u, walk);
            self.start_dwell(out);
            self.on_confirmed(now_s, out);
        } else if unproven.is_empty() && (state.mccb || closed.is_empty()) {
            // When the proven loads on were closed is not known: they owe
            // one settle dwell before the next unproven load is closed.
            what = if closed.is_empty() {
                "nothing was on: the walk starts again from load 0".to_string()
            } else {
                format!(
                    "proven load(s) {} kept on, one settle dwell, then the walk goes on",
                    list(&closed)
                )
            };
            self.note_resumed(how, at, &what, out);
            self.batch = closed;
            self.closing_batch.clear();
            self.closing_proven = false;
            self.settling = false;
            self.dwell_due = false;
            self.count_c = 0;
            self.in_oldc = false;
            self.oluc_next(now_s, out);
        } else {
            what = format!(
                "the breakers read ({} on, {} not proven) are not where one step leaves \
                 them: every breaker is opened and the walk starts again, proven loads \
                 re-closed together, the others tested with a full dwell",
                list(&closed),
                list(&unproven)
            );
            self.note_resumed(how, at, &what, out);
            self.enter_tripped(now_s, out);
        }
    }

    /// The load under test, if the read is what the walk leaves while a
    /// load dwells: `u`, the last load on but not proven in the order of the
    /// walk, with every load the walk closes before it on. Those of them not
    /// proven in the save were proven by the walk (it closes an unproven
    /// load only after the previous one held a full dwell; the save of that
    /// step had not landed) and are marked so. With `Some(stop)` `u` is an
    /// OLDC zone (OLUC stopped below faulty zone `stop`).
    fn single_load_under_test(
        &mut self,
        state: &PanelState,
        unproven: &[u8],
    ) -> Option<(u8, Option<u8>)> {
        let n = self.settings.zones;
        let stop = (1..=n).find(|z| self.faulty.contains(z));
        let mut walk: Vec<u8> = (0..stop.unwrap_or(n + 1)).collect();
        if let Some(stop) = stop {
            walk.extend((stop + 1..=n).rev().filter(|z| !self.faulty.contains(z)));
        }
        let last = walk.iter().rposition(|l| unproven.contains(l))?;
        let u = walk[last];
        let before = &walk[..last];
        let placed = before.iter().all(|l| state.closed(Breaker::load(*l)))
            && unproven.iter().all(|l| *l == u || before.contains(l));
        if !placed {
            return None;
        }
        self.proven
            .extend(unproven.iter().copied().filter(|l| *l != u));
        Some((u, stop.filter(|s| u > *s)))
    }

    /// The walk closing load `u` (an OLDC zone when `walk` names the zone
    /// OLUC stopped below), with nothing owed by proven loads.
    fn place_walk_at(&mut self, u: u8, walk: Option<u8>) {
        self.in_oldc = walk.is_some();
        if let Some(stop) = walk {
            self.oluc_stop = stop;
            self.oldc = u;
            self.step = Step::Oldc;
        } else {
            self.count_c = u;
            self.step = Step::Oluc;
        }
        self.closing_proven = false;
        self.closing_batch.clear();
        self.batch.clear();
        self.settling = false;
    }

    fn note_resumed(&mut self, how: Takeover, at: &str, what: &str, out: &mut Vec<Output>) {
        let text = format!("sequence resumed after a {how} at step '{at}': {what}");
        self.resumed = Some(text.clone());
        event(out, "resumed", text);
    }
}
