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
//!
//! This file holds the set's state and how it is built; `set/` holds its
//! evaluation, the operations, the records and the alarm definitions.

use std::collections::HashMap;
use std::time::Duration;

use gridscada_config::Plant;
use gridscada_tagdb::Timestamp;

use crate::events::Event;
use crate::machine::{Alarm, AlarmDef, Condition};
use crate::model::{AlarmError, AlarmId, AlarmTransition, AlarmView};
use crate::suppression::SuppressionRule;

mod defs;
mod evaluate;
mod operations;
mod records;

pub use defs::{display_value, first_segment, plant_defs, tag_alarm_defs, AlarmSource};

use defs::validate_def;
use operations::secs;

/// Longest shelving an operator may ask for (7 days): shelving is temporary by
/// definition; longer removal is "out of service".
pub const MAX_SHELVE: Duration = Duration::from_secs(7 * 24 * 3600);
/// Longest shelve or out-of-service reason, in bytes (what the store keeps).
pub const MAX_REASON_BYTES: usize = 2048;

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

    /// Adds one alarm to a running set (see `AlarmEngine::define`).
    /// Suppression rules keep the targets they had: a rule does not take
    /// alarms defined after it.
    pub fn define(&mut self, def: AlarmDef) -> Result<AlarmId, AlarmError> {
        let id = self.add(def)?;
        self.rank_inputs();
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
}
