//! The state machine of one alarm (ISA-18.2 / IEC 62682).
//!
//! **Owns:** how one alarm's condition is evaluated (limit with deadband,
//! discrete value, communication status, external raise/clear), its on- and
//! off-delays, and its state: Normal, Unack-Active, Ack-Active, Unack-RTN, and
//! the out-of-annunciation overlays Shelved, Suppressed-by-design and
//! Out-of-service. Every change is reported as an [`AlarmTransition`].
//!
//! **Must not touch:** clocks, channels, the tag database. Time is an input
//! ([`Timestamp`]); outputs are pushed onto a caller's vector. That keeps every
//! transition testable without I/O.
//!
//! Rules chosen here, following ISA-18.2:
//! - entering Shelved, Suppressed or Out-of-service discards a pending
//!   acknowledgement; while in them, the condition is still tracked and
//!   recorded (with `annunciated = false`) but never asks for an ack;
//! - leaving them (when none of the three remain) returns the alarm to Normal
//!   if the condition is clear, or to Unack-Active if it is still active, so a
//!   standing problem is annunciated again;
//! - Bad-quality data holds the alarm where it is (the communication-failure
//!   alarm covers the cause), and restarts any running delay.

use std::time::Duration;

use gridscada_tagdb::{QualityCode, Sample, Timestamp, Value};

use crate::model::{
    AlarmId, AlarmKind, AlarmState, AlarmStateRecord, AlarmTransition, AlarmView, ServiceInfo,
    ShelveInfo, TransitionCause,
};

/// How an alarm's condition is computed from its input.
#[derive(Debug, Clone, PartialEq)]
pub enum Condition {
    /// Active above `limit`; clears at or below `limit - deadband`.
    Above { limit: f64, deadband: f64 },
    /// Active below `limit`; clears at or above `limit + deadband`.
    Below { limit: f64, deadband: f64 },
    /// Active while the value equals `when`.
    Equals(Value),
    /// The device's `Comm.Connected` status: active while false or Bad.
    CommLost,
    /// Raised and cleared through the API (system alarms).
    External,
}

impl Condition {
    /// The limit (or alarm value) to show with the alarm.
    pub fn limit(&self) -> Option<Value> {
        match self {
            Condition::Above { limit, .. } | Condition::Below { limit, .. } => {
                Some(Value::Float(*limit))
            }
            Condition::Equals(v) => Some(v.clone()),
            Condition::CommLost | Condition::External => None,
        }
    }
}

/// The static definition of an alarm.
#[derive(Debug, Clone, PartialEq)]
pub struct AlarmDef {
    /// Stable key, e.g. `SS1.PA.V_L1:lo`, `SS1.IO1:comm`.
    pub key: String,
    /// The tag the condition reads (for comm alarms, the `Comm.Connected` tag).
    pub tag: Option<String>,
    pub kind: AlarmKind,
    pub priority: u32,
    pub selection: String,
    /// Message template; `{tag}`, `{value}`, `{limit}`, `{units}`, `{device}`
    /// and `{error}` are substituted at activation.
    pub message: String,
    pub units: String,
    /// For comm alarms, the device name.
    pub device: Option<String>,
    /// The tag's words for its values (`states` in the configuration):
    /// `{value}` and the alarm list show `TRIPPED`, not `false`.
    pub states: Option<std::sync::Arc<std::collections::BTreeMap<String, String>>>,
    /// The decimals `{value}` and `{limit}` are written with: the tag's, as
    /// the HMI shows it (`HmiConfig::decimals_for`); `None` for at most two.
    pub decimals: Option<u8>,
    pub condition: Condition,
    pub on_delay: Duration,
    pub off_delay: Duration,
}

/// The live state of one alarm.
#[derive(Debug, Clone)]
pub struct Alarm {
    pub id: AlarmId,
    pub def: AlarmDef,
    /// The condition after delays and deadband.
    active: bool,
    acked: bool,
    /// The condition wants to change to `.0` since `.1` (delay running).
    pending: Option<(bool, Timestamp)>,
    active_since: Option<Timestamp>,
    /// The latest activation, kept after the alarm clears.
    activated_at: Option<Timestamp>,
    /// When the condition last cleared (`None` while active).
    cleared_at: Option<Timestamp>,
    last_change: Timestamp,
    value: Option<Value>,
    /// The value at the latest activation (what the message shows), kept
    /// after the alarm clears.
    activation_value: Option<Value>,
    message: String,
    /// Comm alarms: the device's last error text.
    detail: Option<String>,
    shelved: Option<ShelveInfo>,
    out_of_service: Option<ServiceInfo>,
    suppressed: bool,
}

impl Alarm {
    pub fn new(id: AlarmId, def: AlarmDef) -> Self {
        let message = render(&def, None, None);
        Alarm {
            id,
            def,
            active: false,
            acked: true,
            pending: None,
            active_since: None,
            activated_at: None,
            cleared_at: None,
            last_change: Timestamp::from_millis(0),
            value: None,
            activation_value: None,
            message,
            detail: None,
            shelved: None,
            out_of_service: None,
            suppressed: false,
        }
    }

    pub fn is_active(&self) -> bool {
        self.active
    }
    pub fn is_acked(&self) -> bool {
        self.acked
    }
    pub fn is_suppressed(&self) -> bool {
        self.suppressed
    }
    pub fn shelved(&self) -> Option<&ShelveInfo> {
        self.shelved.as_ref()
    }
    pub fn out_of_service(&self) -> Option<&ServiceInfo> {
        self.out_of_service.as_ref()
    }
    pub fn active_since(&self) -> Option<Timestamp> {
        self.active_since
    }
    pub fn last_change(&self) -> Timestamp {
        self.last_change
    }
    pub fn message(&self) -> &str {
        &self.message
    }

    /// Whether the alarm is out of annunciation (shelved, suppressed, out of service).
    pub fn is_hidden(&self) -> bool {
        self.shelved.is_some() || self.out_of_service.is_some() || self.suppressed
    }

    /// The displayed state. Out of service wins over shelved over suppressed.
    pub fn state(&self) -> AlarmState {
        if self.out_of_service.is_some() {
            AlarmState::OutOfService
        } else if self.shelved.is_some() {
            AlarmState::Shelved
        } else if self.suppressed {
            AlarmState::Suppressed
        } else {
            match (self.active, self.acked) {
                (false, true) => AlarmState::Normal,
                (true, false) => AlarmState::UnackActive,
                (true, true) => AlarmState::AckActive,
                (false, false) => AlarmState::UnackRtn,
            }
        }
    }

    /// Evaluates a new sample of the alarm's input tag at `now`.
    pub fn evaluate(&mut self, sample: &Sample, now: Timestamp, out: &mut Vec<AlarmTransition>) {
        let raw = match &self.def.condition {
            Condition::CommLost => {
                // A status tag never written yet says nothing: hold, so a
                // start-up does not raise a comm alarm for every device.
                if sample.timestamp.as_millis() == 0 {
                    return;
                }
                self.value = Some(sample.value.clone());
                sample.quality.code == QualityCode::Bad || sample.value.as_bool() != Some(true)
            }
            Condition::External => return,
            cond => {
                if sample.quality.code == QualityCode::Bad {
                    // Hold: do not let a delay run across a gap in the data.
                    self.pending = None;
                    return;
                }
                let Some(raw) = self.raw_condition(cond, &sample.value) else {
                    self.pending = None;
                    return;
                };
                self.value = Some(sample.value.clone());
                raw
            }
        };
        self.drive(raw, now, out);
    }

    /// The undelayed condition, with deadband applied against the current
    /// state. `None` when the value cannot be judged (NaN, wrong type).
    fn raw_condition(&self, cond: &Condition, value: &Value) -> Option<bool> {
        match cond {
            Condition::Above { limit, deadband } => {
                let v = value.as_f64().filter(|v| !v.is_nan())?;
                Some(if self.active {
                    v > limit - deadband
                } else {
                    v > *limit
                })
            }
            Condition::Below { limit, deadband } => {
                let v = value.as_f64().filter(|v| !v.is_nan())?;
                Some(if self.active {
                    v < limit + deadband
                } else {
                    v < *limit
                })
            }
            Condition::Equals(when) => discrete_equals(value, when),
            Condition::CommLost | Condition::External => None,
        }
    }

    /// Feeds the undelayed condition `raw` at `now`, running the on/off delay.
    pub fn drive(&mut self, raw: bool, now: Timestamp, out: &mut Vec<AlarmTransition>) {
        if raw == self.active {
            self.pending = None;
            return;
        }
        let delay = if raw {
            self.def.on_delay
        } else {
            self.def.off_delay
        };
        let since = match self.pending {
            Some((want, since)) if want == raw => since,
            _ => {
                self.pending = Some((raw, now));
                now
            }
        };
        if now.since(since) >= delay {
            self.pending = None;
            self.set_active(raw, now, out);
        }
    }

    /// Runs timers: a finished delay, an expired shelving, the end of an
    /// out-of-service period.
    pub fn tick(&mut self, now: Timestamp, out: &mut Vec<AlarmTransition>) {
        if let Some((want, since)) = self.pending {
            let delay = if want {
                self.def.on_delay
            } else {
                self.def.off_delay
            };
            if now.since(since) >= delay {
                self.pending = None;
                self.set_active(want, now, out);
            }
        }
        if let Some(s) = &self.shelved {
            if now >= s.until {
                self.transition(now, TransitionCause::ShelveExpired, None, out, |a| {
                    a.shelved = None;
                    a.after_release();
                });
            }
        }
        if self
            .out_of_service
            .as_ref()
            .and_then(|s| s.until)
            .is_some_and(|u| now >= u)
        {
            // Back in service by itself: no user.
            self.transition(now, TransitionCause::InService, None, out, |a| {
                a.out_of_service = None;
                a.after_release();
            });
        }
    }

    /// The earliest time [`Alarm::tick`] has something to do.
    pub fn next_deadline(&self) -> Option<Timestamp> {
        let delay = self.pending.map(|(want, since)| {
            since.add(if want {
                self.def.on_delay
            } else {
                self.def.off_delay
            })
        });
        let shelve = self.shelved.as_ref().map(|s| s.until);
        let service = self.out_of_service.as_ref().and_then(|s| s.until);
        [delay, shelve, service].into_iter().flatten().min()
    }

    fn set_active(&mut self, active: bool, now: Timestamp, out: &mut Vec<AlarmTransition>) {
        let cause = if active {
            TransitionCause::Activate
        } else {
            TransitionCause::Return
        };
        self.transition(now, cause, None, out, |a| {
            a.active = active;
            if active {
                a.active_since = Some(now);
                a.activated_at = Some(now);
                a.cleared_at = None;
                a.activation_value = a.value.clone();
                a.message = render(&a.def, a.value.as_ref(), a.detail.as_deref());
                if !a.is_hidden() {
                    a.acked = false;
                }
            } else {
                a.active_since = None;
                a.cleared_at = Some(now);
            }
        });
    }

    /// Acknowledges the alarm. Returns false if nothing was waiting for an ack.
    pub fn ack(&mut self, user: &str, now: Timestamp, out: &mut Vec<AlarmTransition>) -> bool {
        if self.acked || self.is_hidden() {
            return false;
        }
        self.transition(now, TransitionCause::Ack, Some(user), out, |a| {
            a.acked = true;
        });
        true
    }

    /// Shelves the alarm until `until`. Re-shelving replaces the previous shelving.
    pub fn shelve(
        &mut self,
        user: &str,
        reason: &str,
        until: Timestamp,
        now: Timestamp,
        out: &mut Vec<AlarmTransition>,
    ) {
        self.transition(now, TransitionCause::Shelve, Some(user), out, |a| {
            a.shelved = Some(ShelveInfo {
                by: user.to_owned(),
                reason: reason.to_owned(),
                since: now,
                until,
            });
            a.acked = true;
        });
    }

    /// Unshelves the alarm. Returns false if it was not shelved.
    pub fn unshelve(&mut self, user: &str, now: Timestamp, out: &mut Vec<AlarmTransition>) -> bool {
        if self.shelved.is_none() {
            return false;
        }
        self.transition(now, TransitionCause::Unshelve, Some(user), out, |a| {
            a.shelved = None;
            a.after_release();
        });
        true
    }

    /// Takes the alarm out of service, or returns it. Returns false if it
    /// already was in the requested service state.
    pub fn set_out_of_service(
        &mut self,
        out_of_service: bool,
        user: &str,
        reason: &str,
        until: Option<Timestamp>,
        now: Timestamp,
        out: &mut Vec<AlarmTransition>,
    ) -> bool {
        if out_of_service == self.out_of_service.is_some() {
            return false;
        }
        let cause = if out_of_service {
            TransitionCause::OutOfService
        } else {
            TransitionCause::InService
        };
        self.transition(now, cause, Some(user), out, |a| {
            if out_of_service {
                a.out_of_service = Some(ServiceInfo {
                    by: user.to_owned(),
                    reason: reason.to_owned(),
                    since: now,
                    until,
                });
                a.acked = true;
            } else {
                a.out_of_service = None;
                a.after_release();
            }
        });
        true
    }

    /// Suppresses the alarm by design, or lifts the suppression.
    pub fn set_suppressed(
        &mut self,
        suppressed: bool,
        now: Timestamp,
        out: &mut Vec<AlarmTransition>,
    ) {
        if suppressed == self.suppressed {
            return;
        }
        let cause = if suppressed {
            TransitionCause::Suppress
        } else {
            TransitionCause::Unsuppress
        };
        self.transition(now, cause, None, out, |a| {
            a.suppressed = suppressed;
            if suppressed {
                a.acked = true;
            } else {
                a.after_release();
            }
        });
    }

    /// After an overlay is removed: if none is left, a standing condition is
    /// annunciated again (ISA-18.2: back to Unack-Active, not Ack-Active).
    fn after_release(&mut self) {
        if !self.is_hidden() {
            self.acked = !self.active;
        }
    }

    /// Comm alarms: the device's latest error text. Updates the message of a
    /// standing alarm so the operator sees the current cause.
    pub fn set_detail(&mut self, detail: Option<String>) -> bool {
        let detail = detail.filter(|d| !d.trim().is_empty());
        if detail == self.detail {
            return false;
        }
        self.detail = detail;
        if self.active {
            self.message = render(&self.def, self.value.as_ref(), self.detail.as_deref());
        }
        true
    }

    /// System alarms: a new message for a standing alarm, without a transition.
    pub fn set_message_template(&mut self, template: &str) -> bool {
        if self.def.message == template {
            return false;
        }
        self.def.message = template.to_owned();
        self.message = render(&self.def, self.value.as_ref(), self.detail.as_deref());
        true
    }

    /// Applies `f` and records a transition if the displayed state or the
    /// process condition changed (or if the cause is an operator action).
    fn transition(
        &mut self,
        now: Timestamp,
        cause: TransitionCause,
        user: Option<&str>,
        out: &mut Vec<AlarmTransition>,
        f: impl FnOnce(&mut Self),
    ) {
        let from = self.state();
        let was_active = self.active;
        f(self);
        let to = self.state();
        if from == to && was_active == self.active && user.is_none() {
            return;
        }
        self.last_change = now;
        out.push(AlarmTransition {
            time: now,
            id: self.id,
            key: self.def.key.clone(),
            tag: self.def.tag.clone(),
            kind: self.def.kind,
            cause,
            from,
            to,
            active: self.active,
            annunciated: !self.is_hidden(),
            value: self.value.clone(),
            limit: self.def.condition.limit(),
            user: user.map(str::to_owned),
            priority: self.def.priority,
            selection: self.def.selection.clone(),
            message: self.message.clone(),
        });
    }

    pub fn view(&self) -> AlarmView {
        AlarmView {
            id: self.id,
            key: self.def.key.clone(),
            tag: self.def.tag.clone(),
            kind: self.def.kind,
            state: self.state(),
            active: self.active,
            acked: self.acked,
            priority: self.def.priority,
            selection: self.def.selection.clone(),
            message: self.message.clone(),
            value_text: self.value.as_ref().and_then(|v| value_text(&self.def, v)),
            value: self.value.clone(),
            activation_value_text: self
                .activation_value
                .as_ref()
                .and_then(|v| value_text(&self.def, v)),
            activation_value: self.activation_value.clone(),
            limit: self.def.condition.limit(),
            units: self.def.units.clone(),
            active_since: self.active_since,
            activated_at: self.activated_at,
            cleared_at: self.cleared_at,
            last_change: self.last_change,
            shelved: self.shelved.clone(),
            out_of_service: self.out_of_service.clone(),
            suppressed: self.suppressed,
        }
    }

    pub fn record(&self) -> AlarmStateRecord {
        AlarmStateRecord {
            key: self.def.key.clone(),
            kind: self.def.kind,
            state: self.state(),
            active: self.active,
            acked: self.acked,
            // The latest activation, also once cleared (an unacknowledged
            // return keeps its activation time across a restart).
            active_since: self.activated_at,
            last_change: self.last_change,
            message: self.message.clone(),
            priority: self.def.priority,
            selection: self.def.selection.clone(),
            shelved_by: self.shelved.as_ref().map(|s| s.by.clone()),
            shelved_at: self.shelved.as_ref().map(|s| s.since),
            shelved_until: self.shelved.as_ref().map(|s| s.until),
            shelve_reason: self.shelved.as_ref().map(|s| s.reason.clone()),
            out_of_service: self.out_of_service.is_some(),
            out_of_service_by: self.out_of_service.as_ref().map(|s| s.by.clone()),
            out_of_service_since: self.out_of_service.as_ref().map(|s| s.since),
            out_of_service_reason: self.out_of_service.as_ref().map(|s| s.reason.clone()),
            out_of_service_until: self.out_of_service.as_ref().and_then(|s| s.until),
            activation_value: self.activation_value.clone(),
        }
    }

    /// Restores a persisted state without recording transitions. The
    /// suppression flag is not restored: it follows from its trigger.
    pub fn restore(&mut self, r: &AlarmStateRecord) {
        self.active = r.active;
        self.active_since = if r.active {
            r.active_since.or(Some(r.last_change))
        } else {
            None
        };
        self.activated_at = self.active_since.or(r.active_since);
        // A return not yet acknowledged was the last change.
        self.cleared_at = (!r.active && r.active_since.is_some()).then_some(r.last_change);
        self.last_change = r.last_change;
        self.activation_value = r.activation_value.clone();
        self.pending = None;
        if !r.message.is_empty() {
            self.message = r.message.clone();
        }
        self.shelved = match (&r.shelved_by, r.shelved_until) {
            (Some(by), Some(until)) => Some(ShelveInfo {
                by: by.clone(),
                reason: r.shelve_reason.clone().unwrap_or_default(),
                since: r.shelved_at.unwrap_or(r.last_change),
                until,
            }),
            _ => None,
        };
        self.out_of_service = r.out_of_service.then(|| ServiceInfo {
            by: r.out_of_service_by.clone().unwrap_or_default(),
            reason: r.out_of_service_reason.clone().unwrap_or_default(),
            since: r.out_of_service_since.unwrap_or(r.last_change),
            until: r.out_of_service_until,
        });
        // A hidden alarm never waits for an ack, whatever the record says.
        self.acked = r.acked || self.is_hidden();
    }

    /// Restores the suppression flag silently (at start-up, from the trigger).
    pub(crate) fn restore_suppressed(&mut self, suppressed: bool) {
        self.suppressed = suppressed;
        if suppressed {
            self.acked = true;
        }
    }
}

/// Whether a tag value equals a discrete alarm's `when` value. Booleans match
/// numbers as 0/1; numbers match numerically; strings match exactly.
pub fn discrete_equals(value: &Value, when: &Value) -> Option<bool> {
    match when {
        Value::Bool(w) => value.as_bool().map(|b| b == *w),
        // Integers compare exactly, whatever their width.
        Value::Int(_) | Value::UInt(_) => match (value.as_i128(), when.as_i128()) {
            (Some(v), Some(w)) if !matches!(value, Value::Str(_)) => Some(v == w),
            _ => value
                .as_f64()
                .filter(|v| !v.is_nan())
                .map(|v| Some(v) == when.as_f64()),
        },
        Value::Float(w) => value.as_f64().filter(|v| !v.is_nan()).map(|v| v == *w),
        Value::Str(w) => match value {
            Value::Str(s) => Some(s == w),
            _ => None,
        },
    }
}

/// Formats a value for a message: a float with `decimals` (the tag's, as
/// the HMI shows it), or without them to at most two decimals, without
/// trailing zeros. Never "-0".
pub fn format_value(v: &Value, decimals: Option<u8>) -> String {
    match v {
        Value::Float(f) if f.is_finite() => {
            let s = match decimals {
                Some(d) => format!("{f:.*}", usize::from(d)),
                None => {
                    let s = format!("{f:.2}");
                    s.trim_end_matches('0').trim_end_matches('.').to_owned()
                }
            };
            match s.strip_prefix('-') {
                Some(rest) if rest.chars().all(|c| c == '0' || c == '.') => rest.to_owned(),
                _ => s,
            }
        }
        other => other.to_string(),
    }
}

/// Substitutes `{tag}`, `{value}`, `{limit}`, `{units}`, `{device}` and
/// `{error}` in the alarm's message template. Unknown placeholders stay as written.
/// The configured word for a value of the alarm's tag, if any.
pub fn value_text(def: &AlarmDef, value: &Value) -> Option<String> {
    let states = def.states.as_ref()?;
    gridscada_config::state_label(states, value).map(str::to_owned)
}

pub fn render(def: &AlarmDef, value: Option<&Value>, detail: Option<&str>) -> String {
    let template = &def.message;
    let mut out = String::with_capacity(template.len() + 16);
    let mut rest = template.as_str();
    while let Some(open) = rest.find('{') {
        out.push_str(&rest[..open]);
        let after = &rest[open..];
        let Some(close) = after.find('}') else {
            out.push_str(after);
            return out;
        };
        let name = &after[1..close];
        let text = match name {
            "tag" => Some(def.tag.clone().unwrap_or_else(|| def.key.clone())),
            "value" => Some(
                value
                    .map(|v| value_text(def, v).unwrap_or_else(|| format_value(v, def.decimals)))
                    .unwrap_or_else(|| "?".into()),
            ),
            "limit" => Some(
                def.condition
                    .limit()
                    .map(|l| format_value(&l, def.decimals))
                    .unwrap_or_default(),
            ),
            "units" => Some(def.units.clone()),
            "device" => Some(def.device.clone().unwrap_or_default()),
            "error" => Some(detail.unwrap_or("no response").to_owned()),
            _ => None,
        };
        match text {
            Some(t) => out.push_str(&t),
            None => out.push_str(&after[..=close]),
        }
        rest = &after[close + 1..];
    }
    out.push_str(rest);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_value_is_written_with_its_tags_decimals_or_at_most_two() {
        let f = |v: f64, d| format_value(&Value::Float(v), d);
        assert_eq!(f(253.456, Some(1)), "253.5");
        assert_eq!(f(253.0, Some(1)), "253.0");
        assert_eq!(f(0.95, Some(2)), "0.95");
        assert_eq!(f(1234.5, Some(0)), "1234");
        assert_eq!(f(-0.04, Some(1)), "0.0", "never -0.0");
        assert_eq!(f(203.456, None), "203.46");
        assert_eq!(f(207.0, None), "207");
        assert_eq!(f(-0.001, None), "0");
        assert_eq!(format_value(&Value::Int(3), Some(1)), "3");
    }
}
