//! The plant's alarms as one pure state machine.
//!
//! **Owns:** the set of alarm state machines built from the configuration,
//! which tag feeds which alarm, the order a batch is evaluated in, suppression
//! rules, operator operations (acknowledge, shelve, out of service), system
//! alarms raised through the API, summaries and persistence records.
//!
//! **Must not touch:** clocks, channels, the tag database. The caller passes
//! time in and takes [`Outputs`] (transitions for history, events for the
//! event log) out; [`crate::AlarmEngine`] is the thin async shell that does.

use std::collections::HashMap;
use std::time::Duration;

use gridscada_config::{AlarmConfig, LimitAlarm, Plant, TagConfig};
use gridscada_tagdb::{Sample, Timestamp, Value};

use crate::events::{Event, EventType};
use crate::machine::{format_value, Alarm, AlarmDef, Condition};
use crate::model::{comm_key, discrete_key, limit_key};
use crate::model::{
    AlarmError, AlarmFilter, AlarmId, AlarmKind, AlarmStateRecord, AlarmTransition, AlarmView,
    TransitionCause,
};
use crate::suppression::SuppressionRule;

/// Priority of communication-failure alarms: high, since every value of the
/// device is stale while it stands.
pub const COMM_PRIORITY: u32 = 800;

/// Longest shelving an operator may ask for (7 days): shelving is temporary by
/// definition; longer removal is "out of service".
pub const MAX_SHELVE: Duration = Duration::from_secs(7 * 24 * 3600);
/// Longest shelve or out-of-service reason, in bytes (what the store keeps).
pub const MAX_REASON_BYTES: usize = 2048;

/// A reason an operator gives: required (when `required`), at most
/// [`MAX_REASON_BYTES`], one line of printable text. Checked before any
/// state changes, so a refused request changes nothing.
fn check_reason<'a>(what: &str, reason: &'a str, required: bool) -> Result<&'a str, AlarmError> {
    let reason = reason.trim();
    if required && reason.is_empty() {
        return Err(AlarmError::invalid(what, "a reason is required"));
    }
    if reason.len() > MAX_REASON_BYTES {
        return Err(AlarmError::invalid(
            what,
            format!(
                "the reason has {} bytes; at most {MAX_REASON_BYTES}",
                reason.len()
            ),
        ));
    }
    if reason.chars().any(char::is_control) {
        return Err(AlarmError::invalid(
            what,
            "the reason may not contain control characters (line breaks, tabs)",
        ));
    }
    Ok(reason)
}

/// Dense index of an input tag of an [`AlarmSet`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct InputId(pub u32);

/// What one step of the alarm set produced.
#[derive(Debug, Default, Clone)]
pub struct Outputs {
    pub transitions: Vec<AlarmTransition>,
    pub events: Vec<Event>,
    /// Something shown in the alarm list changed without a transition (e.g.
    /// the error text of a standing comm alarm).
    pub view_changed: bool,
}

impl Outputs {
    pub fn is_empty(&self) -> bool {
        self.transitions.is_empty() && self.events.is_empty() && !self.view_changed
    }
    pub fn clear(&mut self) {
        self.transitions.clear();
        self.events.clear();
        self.view_changed = false;
    }
}

/// What [`AlarmSet::restore`] did with the persisted records.
#[derive(Debug, Default, Clone, PartialEq, Eq)]
pub struct RestoreReport {
    pub restored: usize,
    /// System alarms recreated from their records.
    pub recreated: usize,
    /// Keys of records no alarm of the current configuration has.
    pub skipped: Vec<String>,
}

#[derive(Debug)]
struct Input {
    tag: String,
    /// Alarms whose condition this tag drives.
    evaluates: Vec<AlarmId>,
    /// Comm alarms whose error text this tag carries.
    detail_for: Vec<AlarmId>,
    /// Evaluation order within a batch: error texts, then suppression
    /// triggers, then the rest (so a trigger suppresses before its
    /// consequences in the same batch annunciate).
    rank: u8,
}

#[derive(Debug)]
struct Rule {
    trigger: AlarmId,
    targets: Vec<AlarmId>,
    release: Duration,
    engaged: bool,
    clear_since: Option<Timestamp>,
}

/// The plant's alarms.
#[derive(Debug)]
pub struct AlarmSet {
    alarms: Vec<Alarm>,
    by_key: HashMap<String, AlarmId>,
    inputs: Vec<Input>,
    input_by_tag: HashMap<String, InputId>,
    rules: Vec<Rule>,
    /// Per alarm: the rules that target it.
    rules_of: Vec<Vec<u32>>,
    evaluations: u64,
    /// No later than the earliest timer of any alarm or rule: kept up to date
    /// cheaply as alarms change, recomputed exactly on every tick.
    deadline_hint: Option<Timestamp>,
}

impl AlarmSet {
    /// Builds the set from alarm definitions and suppression rules.
    pub fn new(defs: Vec<AlarmDef>, rules: Vec<SuppressionRule>) -> Result<Self, AlarmError> {
        let mut set = AlarmSet {
            alarms: Vec::with_capacity(defs.len()),
            by_key: HashMap::with_capacity(defs.len()),
            inputs: Vec::new(),
            input_by_tag: HashMap::new(),
            rules: Vec::new(),
            rules_of: Vec::new(),
            evaluations: 0,
            deadline_hint: None,
        };
        for def in defs {
            set.add(def)?;
        }
        for rule in rules {
            set.add_rule(rule)?;
        }
        set.rank_inputs();
        Ok(set)
    }

    /// Builds the set from the plant configuration: the tags' limit and
    /// discrete alarms, a comm alarm per device, and `rules` (usually
    /// [`crate::suppression::default_rules`]).
    pub fn from_plant(plant: &Plant, rules: Vec<SuppressionRule>) -> Result<Self, AlarmError> {
        AlarmSet::new(plant_defs(plant)?, rules)
    }

    fn add(&mut self, def: AlarmDef) -> Result<AlarmId, AlarmError> {
        validate_def(&def)?;
        if self.by_key.contains_key(&def.key) {
            return Err(AlarmError::DuplicateKey(def.key));
        }
        let id = AlarmId(u32::try_from(self.alarms.len()).map_err(|_| AlarmError::TooMany)?);
        if let (Some(tag), false) = (&def.tag, def.condition == Condition::External) {
            let input = self.input(tag);
            self.inputs[input.0 as usize].evaluates.push(id);
        }
        if let (Condition::CommLost, Some(device)) = (&def.condition, &def.device) {
            let input = self.input(&format!("{device}.Comm.LastError"));
            self.inputs[input.0 as usize].detail_for.push(id);
        }
        self.by_key.insert(def.key.clone(), id);
        self.alarms.push(Alarm::new(id, def));
        self.rules_of.push(Vec::new());
        Ok(id)
    }

    fn input(&mut self, tag: &str) -> InputId {
        if let Some(id) = self.input_by_tag.get(tag) {
            return *id;
        }
        let id = InputId(self.inputs.len() as u32);
        self.inputs.push(Input {
            tag: tag.to_owned(),
            evaluates: Vec::new(),
            detail_for: Vec::new(),
            rank: 2,
        });
        self.input_by_tag.insert(tag.to_owned(), id);
        id
    }

    fn add_rule(&mut self, rule: SuppressionRule) -> Result<(), AlarmError> {
        let trigger =
            *self
                .by_key
                .get(&rule.trigger)
                .ok_or_else(|| AlarmError::UnknownTrigger {
                    rule: rule.name.clone(),
                    key: rule.trigger.clone(),
                })?;
        let release = secs(
            &format!("suppression rule '{}'", rule.name),
            rule.release_delay_s,
        )?;
        let index = self.rules.len() as u32;
        let targets: Vec<AlarmId> = self
            .alarms
            .iter()
            .filter(|a| a.id != trigger)
            .filter(|a| {
                rule.targets
                    .iter()
                    .any(|m| m.matches(a.def.tag.as_deref(), a.def.kind))
            })
            .map(|a| a.id)
            .collect();
        for t in &targets {
            self.rules_of[t.index()].push(index);
        }
        self.rules.push(Rule {
            trigger,
            targets,
            release,
            engaged: false,
            clear_since: None,
        });
        Ok(())
    }

    fn rank_inputs(&mut self) {
        let triggers: Vec<AlarmId> = self.rules.iter().map(|r| r.trigger).collect();
        for input in &mut self.inputs {
            input.rank = if !input.detail_for.is_empty() {
                0
            } else if input.evaluates.iter().any(|a| triggers.contains(a)) {
                1
            } else {
                2
            };
        }
    }

    pub fn len(&self) -> usize {
        self.alarms.len()
    }

    pub fn is_empty(&self) -> bool {
        self.alarms.is_empty()
    }

    pub fn id_of(&self, key: &str) -> Option<AlarmId> {
        self.by_key.get(key).copied()
    }

    pub fn alarm(&self, id: AlarmId) -> Option<&Alarm> {
        self.alarms.get(id.index())
    }

    pub fn view(&self, id: AlarmId) -> Option<AlarmView> {
        self.alarm(id).map(Alarm::view)
    }

    /// The tags the set reads, with their input ids.
    pub fn inputs(&self) -> impl Iterator<Item = (InputId, &str)> {
        self.inputs
            .iter()
            .enumerate()
            .map(|(i, inp)| (InputId(i as u32), inp.tag.as_str()))
    }

    pub fn input_id(&self, tag: &str) -> Option<InputId> {
        self.input_by_tag.get(tag).copied()
    }

    /// How many alarm conditions have been evaluated so far.
    pub fn evaluations(&self) -> u64 {
        self.evaluations
    }

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

    fn exact_deadline(&self) -> Option<Timestamp> {
        let alarms = self.alarms.iter().filter_map(Alarm::next_deadline);
        alarms.chain(self.rule_deadlines()).min()
    }

    fn rule_deadlines(&self) -> impl Iterator<Item = Timestamp> + '_ {
        self.rules
            .iter()
            .filter(|r| r.engaged)
            .filter_map(|r| r.clear_since.map(|s| s.add(r.release)))
    }

    fn note_deadline(&mut self, d: Option<Timestamp>) {
        if let Some(d) = d {
            self.deadline_hint = Some(self.deadline_hint.map_or(d, |h| h.min(d)));
        }
    }

    fn update_rules(&mut self, now: Timestamp, out: &mut Outputs) {
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

    fn suppression_wanted(&self, id: AlarmId) -> bool {
        self.rules_of[id.index()]
            .iter()
            .any(|r| self.rules[*r as usize].engaged)
    }

    fn get_mut(&mut self, id: AlarmId) -> Result<&mut Alarm, AlarmError> {
        self.alarms
            .get_mut(id.index())
            .ok_or(AlarmError::UnknownId(id))
    }

    /// Acknowledges alarm `id`. Ok(false) if it was not waiting for an ack.
    pub fn ack(
        &mut self,
        id: AlarmId,
        user: &str,
        now: Timestamp,
        out: &mut Outputs,
    ) -> Result<bool, AlarmError> {
        let user = check_user(user)?;
        let alarm = self.get_mut(id)?;
        let done = alarm.ack(user, now, &mut out.transitions);
        if done {
            out.events.push(
                Event::new(
                    now,
                    EventType::Ack,
                    &alarm.def.key,
                    format!("Acknowledged: {}", alarm.message()),
                )
                .by(user),
            );
        }
        Ok(done)
    }

    /// Acknowledges the listed alarms. Every id is checked first, so an
    /// unknown id acknowledges nothing. Returns the ids actually acknowledged.
    pub fn ack_ids(
        &mut self,
        ids: &[AlarmId],
        user: &str,
        now: Timestamp,
        out: &mut Outputs,
    ) -> Result<Vec<AlarmId>, AlarmError> {
        check_user(user)?;
        if let Some(bad) = ids.iter().find(|id| id.index() >= self.alarms.len()) {
            return Err(AlarmError::UnknownId(*bad));
        }
        let mut done = Vec::new();
        for id in ids {
            if self.ack(*id, user, now, out)? {
                done.push(*id);
            }
        }
        Ok(done)
    }

    /// "Ack Top": acknowledges the newest unacknowledged alarm the filter
    /// shows. Returns its id, or None if there was none.
    pub fn ack_top(
        &mut self,
        filter: &AlarmFilter,
        user: &str,
        now: Timestamp,
        out: &mut Outputs,
    ) -> Result<Option<AlarmId>, AlarmError> {
        check_user(user)?;
        let top = self
            .alarms
            .iter()
            .filter(|a| !a.is_acked() && !a.is_hidden())
            .map(Alarm::view)
            .filter(|v| filter.matches(v))
            .max_by_key(|v| (v.last_change, v.id))
            .map(|v| v.id);
        if let Some(id) = top {
            self.ack(id, user, now, out)?;
        }
        Ok(top)
    }

    /// "Ack All": acknowledges every unacknowledged alarm the filter shows.
    /// One event summarises it; each alarm's transition names the user.
    pub fn ack_all(
        &mut self,
        filter: &AlarmFilter,
        user: &str,
        now: Timestamp,
        out: &mut Outputs,
    ) -> Result<Vec<AlarmId>, AlarmError> {
        let user = check_user(user)?;
        let ids: Vec<AlarmId> = self
            .alarms
            .iter()
            .filter(|a| !a.is_acked() && !a.is_hidden())
            .map(Alarm::view)
            .filter(|v| filter.matches(v))
            .map(|v| v.id)
            .collect();
        for id in &ids {
            self.alarms[id.index()].ack(user, now, &mut out.transitions);
        }
        if !ids.is_empty() {
            out.events.push(
                Event::new(
                    now,
                    EventType::Ack,
                    "alarms",
                    format!("Acknowledged all: {} alarm(s)", ids.len()),
                )
                .by(user),
            );
        }
        Ok(ids)
    }

    /// Shelves alarm `id` for `duration` (at most [`MAX_SHELVE`]) with a reason.
    pub fn shelve(
        &mut self,
        id: AlarmId,
        user: &str,
        duration: Duration,
        reason: &str,
        now: Timestamp,
        out: &mut Outputs,
    ) -> Result<Timestamp, AlarmError> {
        let user = check_user(user)?;
        let reason = check_reason("shelve", reason, true)?;
        if duration.is_zero() || duration > MAX_SHELVE {
            return Err(AlarmError::invalid(
                "shelve",
                format!(
                    "duration must be between 1 minute and {} minutes",
                    MAX_SHELVE.as_secs() / 60
                ),
            ));
        }
        let until = now.add(duration);
        self.get_mut(id)?;
        self.note_deadline(Some(until));
        let alarm = self.get_mut(id)?;
        alarm.shelve(user, reason, until, now, &mut out.transitions);
        out.events.push(
            Event::new(
                now,
                EventType::Shelve,
                &alarm.def.key,
                format!(
                    "Shelved for {} min ({reason}): {}",
                    duration.as_secs().div_ceil(60),
                    alarm.message()
                ),
            )
            .by(user),
        );
        Ok(until)
    }

    pub fn unshelve(
        &mut self,
        id: AlarmId,
        user: &str,
        now: Timestamp,
        out: &mut Outputs,
    ) -> Result<(), AlarmError> {
        let user = check_user(user)?;
        let alarm = self.get_mut(id)?;
        if !alarm.unshelve(user, now, &mut out.transitions) {
            return Err(AlarmError::NotShelved(alarm.def.key.clone()));
        }
        out.events.push(
            Event::new(
                now,
                EventType::Unshelve,
                &alarm.def.key,
                format!("Unshelved: {}", alarm.message()),
            )
            .by(user),
        );
        Ok(())
    }

    /// Takes alarm `id` out of service (`out_of_service = true`) or returns it.
    /// Ok(false) if it already was in that state.
    pub fn set_out_of_service(
        &mut self,
        id: AlarmId,
        user: &str,
        out_of_service: bool,
        reason: &str,
        now: Timestamp,
        out: &mut Outputs,
    ) -> Result<bool, AlarmError> {
        let user = check_user(user)?;
        let reason = check_reason("out of service", reason, out_of_service)?;
        let alarm = self.get_mut(id)?;
        if !alarm.set_out_of_service(out_of_service, user, reason, now, &mut out.transitions) {
            return Ok(false);
        }
        let what = if out_of_service {
            format!("Out of service ({reason})")
        } else {
            "Returned to service".to_owned()
        };
        out.events.push(
            Event::new(
                now,
                EventType::OutOfService,
                &alarm.def.key,
                format!("{what}: {}", alarm.message()),
            )
            .by(user),
        );
        Ok(true)
    }

    /// Raises the system alarm `key` (creating it on first use). Raising a
    /// standing alarm again only updates its message.
    pub fn raise(
        &mut self,
        key: &str,
        priority: u32,
        selection: &str,
        message: &str,
        now: Timestamp,
        out: &mut Outputs,
    ) -> Result<AlarmId, AlarmError> {
        let id = match self.by_key.get(key) {
            Some(id) => *id,
            None => self.add(system_def(key, priority, selection, message))?,
        };
        let alarm = &mut self.alarms[id.index()];
        if alarm.def.condition != Condition::External {
            return Err(AlarmError::NotSystem {
                key: key.to_owned(),
                kind: alarm.def.kind,
            });
        }
        alarm.def.priority = priority;
        alarm.def.selection = selection.trim().to_owned();
        if alarm.set_message_template(message) {
            out.view_changed = true;
        }
        alarm.drive(true, now, &mut out.transitions);
        self.update_rules(now, out);
        Ok(id)
    }

    /// Clears the system alarm `key`. Ok(false) if it was not raised.
    pub fn clear(
        &mut self,
        key: &str,
        now: Timestamp,
        out: &mut Outputs,
    ) -> Result<bool, AlarmError> {
        let Some(id) = self.by_key.get(key).copied() else {
            return Ok(false);
        };
        let alarm = &mut self.alarms[id.index()];
        if alarm.def.condition != Condition::External {
            return Err(AlarmError::NotSystem {
                key: key.to_owned(),
                kind: alarm.def.kind,
            });
        }
        let was = alarm.is_active();
        alarm.drive(false, now, &mut out.transitions);
        self.update_rules(now, out);
        Ok(was)
    }

    /// The alarms the filter shows, newest change first (then higher priority).
    pub fn summary(&self, filter: &AlarmFilter) -> Vec<AlarmView> {
        let mut v: Vec<AlarmView> = self
            .alarms
            .iter()
            .filter(|a| {
                // Cheap pre-check before building a view: Normal alarms are
                // the vast majority and the default list never shows them.
                !filter.states.is_empty() || a.is_active() || !a.is_acked()
            })
            .map(Alarm::view)
            .filter(|v| filter.matches(v))
            .collect();
        v.sort_by(|a, b| {
            b.last_change
                .cmp(&a.last_change)
                .then(b.priority.cmp(&a.priority))
                .then(a.id.cmp(&b.id))
        });
        v
    }

    /// Every alarm's view, in id order.
    pub fn all_views(&self) -> Vec<AlarmView> {
        self.alarms.iter().map(Alarm::view).collect()
    }

    /// Every alarm's persistent state.
    pub fn records(&self) -> Vec<AlarmStateRecord> {
        self.alarms.iter().map(Alarm::record).collect()
    }

    pub fn record(&self, id: AlarmId) -> Option<AlarmStateRecord> {
        self.alarm(id).map(Alarm::record)
    }

    /// Restores persisted states at start-up, before any sample is applied.
    /// Records of system alarms are recreated; records of alarms the
    /// configuration no longer has are skipped. Suppression is recomputed from
    /// the restored triggers.
    pub fn restore(&mut self, records: &[AlarmStateRecord]) -> RestoreReport {
        let mut report = RestoreReport::default();
        for r in records {
            let id = match self.by_key.get(&r.key) {
                Some(id) => *id,
                None if r.kind == AlarmKind::System => {
                    match self.add(system_def(&r.key, r.priority, &r.selection, &r.message)) {
                        Ok(id) => {
                            report.recreated += 1;
                            id
                        }
                        Err(_) => {
                            report.skipped.push(r.key.clone());
                            continue;
                        }
                    }
                }
                None => {
                    report.skipped.push(r.key.clone());
                    continue;
                }
            };
            self.alarms[id.index()].restore(r);
            report.restored += 1;
        }
        for r in &mut self.rules {
            r.engaged = self.alarms[r.trigger.index()].is_active();
            r.clear_since = None;
        }
        for i in 0..self.alarms.len() {
            let want = self.suppression_wanted(AlarmId(i as u32));
            self.alarms[i].restore_suppressed(want);
        }
        self.deadline_hint = self.exact_deadline();
        report
    }
}

fn check_user(user: &str) -> Result<&str, AlarmError> {
    let user = user.trim();
    if user.is_empty() {
        return Err(AlarmError::invalid("user", "an operator name is required"));
    }
    Ok(user)
}

fn secs(what: &str, s: f64) -> Result<Duration, AlarmError> {
    Duration::try_from_secs_f64(s).map_err(|_| {
        AlarmError::invalid(what, format!("delay {s} s must be a non-negative number"))
    })
}

fn validate_def(def: &AlarmDef) -> Result<(), AlarmError> {
    if def.key.trim().is_empty() {
        return Err(AlarmError::invalid("alarm", "the key must not be empty"));
    }
    match &def.condition {
        Condition::Above { limit, deadband } | Condition::Below { limit, deadband } => {
            if !limit.is_finite() {
                return Err(AlarmError::invalid(
                    format!("alarm '{}'", def.key),
                    "the limit must be a finite number",
                ));
            }
            if !deadband.is_finite() || *deadband < 0.0 {
                return Err(AlarmError::invalid(
                    format!("alarm '{}'", def.key),
                    "the deadband must be a non-negative number",
                ));
            }
        }
        Condition::Equals(Value::Float(f)) if !f.is_finite() => {
            return Err(AlarmError::invalid(
                format!("alarm '{}'", def.key),
                "the alarm value must be a finite number",
            ));
        }
        _ => {}
    }
    Ok(())
}

fn system_def(key: &str, priority: u32, selection: &str, message: &str) -> AlarmDef {
    AlarmDef {
        key: key.trim().to_owned(),
        tag: None,
        kind: AlarmKind::System,
        priority,
        selection: selection.trim().to_owned(),
        message: message.to_owned(),
        units: String::new(),
        device: None,
        condition: Condition::External,
        on_delay: Duration::ZERO,
        off_delay: Duration::ZERO,
    }
}

/// The first segment of a dotted name (`SS1.PA.V_L1` -> `SS1`).
pub fn first_segment(name: &str) -> &str {
    name.split('.').next().unwrap_or(name)
}

/// The alarm definitions of a plant: every tag's limit and discrete alarms,
/// then one comm alarm per device.
pub fn plant_defs(plant: &Plant) -> Result<Vec<AlarmDef>, AlarmError> {
    let mut defs = Vec::new();
    for tag in &plant.tags {
        if let Some(a) = &tag.alarm {
            tag_defs(tag, a, &mut defs)?;
        }
    }
    for d in &plant.devices {
        let device = d.name.get_ref();
        defs.push(AlarmDef {
            key: comm_key(device),
            tag: Some(format!("{device}.Comm.Connected")),
            kind: AlarmKind::CommFail,
            priority: COMM_PRIORITY,
            selection: first_segment(device).to_owned(),
            message: "Communication lost with {device}: {error}".into(),
            units: String::new(),
            device: Some(device.clone()),
            condition: Condition::CommLost,
            on_delay: Duration::ZERO,
            off_delay: Duration::ZERO,
        });
    }
    Ok(defs)
}

fn tag_defs(tag: &TagConfig, a: &AlarmConfig, defs: &mut Vec<AlarmDef>) -> Result<(), AlarmError> {
    let name = tag.name.get_ref();
    let default_selection = a
        .selection
        .clone()
        .unwrap_or_else(|| first_segment(name).to_owned());
    let limits: [(AlarmKind, &Option<LimitAlarm>); 4] = [
        (AlarmKind::HiHi, &a.hihi),
        (AlarmKind::Hi, &a.hi),
        (AlarmKind::Lo, &a.lo),
        (AlarmKind::LoLo, &a.lolo),
    ];
    for (kind, l) in limits {
        let Some(l) = l else { continue };
        let key = limit_key(name, kind);
        let limit = *l.limit.get_ref();
        let deadband = *l.deadband.get_ref();
        let condition = match kind {
            AlarmKind::HiHi | AlarmKind::Hi => Condition::Above { limit, deadband },
            _ => Condition::Below { limit, deadband },
        };
        defs.push(AlarmDef {
            on_delay: secs(
                &format!("alarm '{key}' on_delay_s"),
                *l.on_delay_s.get_ref(),
            )?,
            off_delay: secs(
                &format!("alarm '{key}' off_delay_s"),
                *l.off_delay_s.get_ref(),
            )?,
            key,
            tag: Some(name.clone()),
            kind,
            priority: l.priority,
            selection: l
                .selection
                .clone()
                .unwrap_or_else(|| default_selection.clone()),
            message: l
                .message
                .clone()
                .unwrap_or_else(|| default_limit_message(kind, &tag.units)),
            units: tag.units.clone(),
            device: Some(tag.device.get_ref().clone()),
            condition,
        });
    }
    for (i, d) in a.discrete.iter().enumerate() {
        let key = discrete_key(name, i);
        let when = match d.when.get_ref() {
            toml::Value::Boolean(b) => Value::Bool(*b),
            toml::Value::Integer(i) => Value::Int(*i),
            toml::Value::Float(f) => Value::Float(*f),
            toml::Value::String(s) => Value::Str(s.as_str().into()),
            other => {
                return Err(AlarmError::invalid(
                    format!("alarm '{key}'"),
                    format!("'when = {other}' must be a boolean, number or string"),
                ))
            }
        };
        let message = d.message.clone().unwrap_or_else(|| {
            if tag.description.trim().is_empty() {
                "{tag} = {value}".to_owned()
            } else {
                format!("{{tag}} ({}) = {{value}}", tag.description.trim())
            }
        });
        defs.push(AlarmDef {
            on_delay: secs(
                &format!("alarm '{key}' on_delay_s"),
                *d.on_delay_s.get_ref(),
            )?,
            off_delay: secs(
                &format!("alarm '{key}' off_delay_s"),
                *d.off_delay_s.get_ref(),
            )?,
            key,
            tag: Some(name.clone()),
            kind: AlarmKind::Discrete,
            priority: d.priority,
            selection: d
                .selection
                .clone()
                .unwrap_or_else(|| default_selection.clone()),
            message,
            units: tag.units.clone(),
            device: Some(tag.device.get_ref().clone()),
            condition: Condition::Equals(when),
        });
    }
    Ok(())
}

fn default_limit_message(kind: AlarmKind, units: &str) -> String {
    let what = match kind {
        AlarmKind::HiHi => "very high",
        AlarmKind::Hi => "high",
        AlarmKind::Lo => "low",
        _ => "very low",
    };
    if units.trim().is_empty() {
        format!("{{tag}} {what}: {{value}} (limit {{limit}})")
    } else {
        format!("{{tag}} {what}: {{value}} {{units}} (limit {{limit}} {{units}})")
    }
}

/// Formats a value as messages do (exposed for the web layer's tables).
pub fn display_value(v: &Value) -> String {
    format_value(v)
}
