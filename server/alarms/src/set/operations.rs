//! What operators and the application ask of alarms: acknowledge, shelve,
//! out of service, and raising or clearing system alarms; each request
//! checked before any state changes.

use std::time::Duration;

use gridscada_tagdb::Timestamp;

use crate::events::{Event, EventType};
use crate::machine::{Alarm, Condition};
use crate::model::{AlarmError, AlarmFilter, AlarmId};

use super::defs::system_def;
use super::{AlarmSet, Outputs, MAX_REASON_BYTES, MAX_SHELVE};

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

impl AlarmSet {
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

    /// Takes alarm `id` out of service (`out_of_service = true`, until
    /// `until` if given) or returns it. Ok(false) if it already was in that
    /// state.
    #[allow(clippy::too_many_arguments)]
    pub fn set_out_of_service(
        &mut self,
        id: AlarmId,
        user: &str,
        out_of_service: bool,
        reason: &str,
        until: Option<Timestamp>,
        now: Timestamp,
        out: &mut Outputs,
    ) -> Result<bool, AlarmError> {
        let user = check_user(user)?;
        let reason = check_reason("out of service", reason, out_of_service)?;
        if out_of_service && until.is_some_and(|u| u <= now) {
            return Err(AlarmError::invalid(
                "out of service",
                "the end must be in the future",
            ));
        }
        let alarm = self.get_mut(id)?;
        let until = until.filter(|_| out_of_service);
        if !alarm.set_out_of_service(
            out_of_service,
            user,
            reason,
            until,
            now,
            &mut out.transitions,
        ) {
            return Ok(false);
        }
        let what = if out_of_service {
            match until {
                Some(u) => {
                    let c = u.civil_utc();
                    format!(
                        "Out of service until {:04}-{:02}-{:02} {:02}:{:02} UTC ({reason})",
                        c.year, c.month, c.day, c.hour, c.minute
                    )
                }
                None => format!("Out of service ({reason})"),
            }
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
}

fn check_user(user: &str) -> Result<&str, AlarmError> {
    let user = user.trim();
    if user.is_empty() {
        return Err(AlarmError::invalid("user", "an operator name is required"));
    }
    Ok(user)
}

pub(super) fn secs(what: &str, s: f64) -> Result<Duration, AlarmError> {
    Duration::try_from_secs_f64(s).map_err(|_| {
        AlarmError::invalid(what, format!("delay {s} s must be a non-negative number"))
    })
}
