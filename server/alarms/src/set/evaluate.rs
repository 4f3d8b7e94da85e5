//! Evaluation: a batch of samples in rank order, the timers (delays,
//! shelving, suppression holds) and the suppression rules.

use gridscada_tagdb::{Sample, Timestamp, Value};

use crate::events::{Event, EventType};
use crate::machine::Alarm;
use crate::model::{AlarmId, TransitionCause};

use super::{AlarmSet, InputId, Outputs};

impl AlarmSet {
    /// Evaluates one batch of new samples (one tag database update) at `now`.
    pub fn apply(&mut self, batch: &[(InputId, &Sample)], now: Timestamp, out: &mut Outputs) {
        for rank in 0..=2u8 {
            for (input, sample) in batch {
                let Some(inp) = self.inputs.get(input.0 as usize) else {
                    continue;
                };
                if inp.rank != rank {
                    continue;
                }
                for id in &inp.detail_for {
                    let detail = match &sample.value {
                        Value::Str(s)
                            if sample.quality.code != gridscada_tagdb::QualityCode::Bad =>
                        {
                            Some(s.to_string())
                        }
                        _ => None,
                    };
                    if self.alarms[id.index()].set_detail(detail) {
                        out.view_changed = true;
                    }
                }
                for id in &inp.evaluates {
                    self.evaluations += 1;
                    let alarm = &mut self.alarms[id.index()];
                    alarm.evaluate(sample, now, &mut out.transitions);
                    if let Some(d) = alarm.next_deadline() {
                        self.deadline_hint = Some(self.deadline_hint.map_or(d, |h| h.min(d)));
                    }
                }
            }
            if rank == 1 && !self.rules.is_empty() {
                self.update_rules(now, out);
            }
        }
        if !self.rules.is_empty() {
            self.update_rules(now, out);
        }
    }

    /// Evaluates one sample of the tag `tag`. Returns false if no alarm reads it.
    pub fn apply_tag(
        &mut self,
        tag: &str,
        sample: &Sample,
        now: Timestamp,
        out: &mut Outputs,
    ) -> bool {
        match self.input_id(tag) {
            Some(id) => {
                self.apply(&[(id, sample)], now, out);
                true
            }
            None => false,
        }
    }

    /// Runs timers due at `now`: on/off delays, shelving expiry, suppression release.
    pub fn tick(&mut self, now: Timestamp, out: &mut Outputs) {
        let first = out.transitions.len();
        for a in &mut self.alarms {
            if a.next_deadline().is_some_and(|d| d <= now) {
                a.tick(now, &mut out.transitions);
            }
        }
        for t in &out.transitions[first..] {
            if t.cause == TransitionCause::ShelveExpired {
                out.events.push(Event::new(
                    now,
                    EventType::Unshelve,
                    &t.key,
                    format!("Shelving expired: {}", t.message),
                ));
            }
            if t.cause == TransitionCause::InService && t.user.is_none() {
                out.events.push(Event::new(
                    now,
                    EventType::OutOfService,
                    &t.key,
                    format!("Out of service expired: back in service: {}", t.message),
                ));
            }
        }
        if !self.rules.is_empty() {
            self.update_rules(now, out);
        }
        self.deadline_hint = self.exact_deadline();
    }

    /// When [`AlarmSet::tick`] should next run: no later than the earliest
    /// timer (on/off delay, shelving expiry, suppression release). It may be
    /// earlier than needed; a tick then does nothing and recomputes it.
    pub fn next_deadline(&self) -> Option<Timestamp> {
        self.deadline_hint
    }

    pub(super) fn exact_deadline(&self) -> Option<Timestamp> {
        let alarms = self.alarms.iter().filter_map(Alarm::next_deadline);
        alarms.chain(self.rule_deadlines()).min()
    }

    fn rule_deadlines(&self) -> impl Iterator<Item = Timestamp> + '_ {
        self.rules
            .iter()
            .filter(|r| r.engaged)
            .filter_map(|r| r.clear_since.map(|s| s.add(r.release)))
    }

    pub(super) fn note_deadline(&mut self, d: Option<Timestamp>) {
        if let Some(d) = d {
            self.deadline_hint = Some(self.deadline_hint.map_or(d, |h| h.min(d)));
        }
    }

    pub(super) fn update_rules(&mut self, now: Timestamp, out: &mut Outputs) {
        let mut changed = false;
        for r in &mut self.rules {
            let was = r.engaged;
            if self.alarms[r.trigger.index()].is_active() {
                r.engaged = true;
                r.clear_since = None;
            } else if r.engaged {
                let since = *r.clear_since.get_or_insert(now);
                if now.since(since) >= r.release {
                    r.engaged = false;
                    r.clear_since = None;
                }
            }
            changed |= was != r.engaged;
        }
        if changed {
            for r in 0..self.rules.len() {
                for i in 0..self.rules[r].targets.len() {
                    let t = self.rules[r].targets[i];
                    let want = self.suppression_wanted(t);
                    self.alarms[t.index()].set_suppressed(want, now, &mut out.transitions);
                }
            }
        }
        let next = self.rule_deadlines().min();
        self.note_deadline(next);
    }

    pub(super) fn suppression_wanted(&self, id: AlarmId) -> bool {
        self.rules_of[id.index()]
            .iter()
            .any(|r| self.rules[*r as usize].engaged)
    }
}
