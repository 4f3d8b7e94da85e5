//! Which alarms a route takes, and who is told: the contact on call now,
//! and on escalation the next one on call after the last told. Pure: time
//! comes in as an argument.

use gridscada_alarms::AlarmTransition;
use gridscada_config::{glob_match, parse_utc_offset, NotifyConfig, OnCallWindow};
use gridscada_tagdb::Timestamp;

/// The prefix of the notifier's own system alarms: never routed, so a
/// broken channel does not try to report itself through itself.
pub const SYSTEM_ALARM_PREFIX: &str = "notify:";

/// A contact of the escalation chain.
#[derive(Debug, Clone, PartialEq)]
pub struct Contact {
    pub name: String,
    pub address: String,
    /// Empty: always on call.
    pub on_call: Vec<OnCallWindow>,
}

impl Contact {
    /// Whether the contact is on call at `now`, `offset_min` east of UTC.
    pub fn on_call_at(&self, now: Timestamp, offset_min: i32) -> bool {
        if self.on_call.is_empty() {
            return true;
        }
        let local_min = now.as_millis().div_euclid(60_000) + i64::from(offset_min);
        let day = local_min.div_euclid(1440);
        // 1970-01-01 was a Thursday; 0 is Monday.
        let weekday = (day + 3).rem_euclid(7) as u8;
        let minute = local_min.rem_euclid(1440) as u16;
        self.on_call.iter().any(|w| w.covers(weekday, minute))
    }
}

/// A `[[notify]]` route, ready to match alarms.
#[derive(Debug, Clone)]
pub struct Route {
    pub name: String,
    pub min_priority: u32,
    pub selections: Vec<String>,
    pub tags: Vec<String>,
    pub contacts: Vec<Contact>,
    /// How long an alarm may stay unacknowledged before the next contact
    /// is told; `None`: no escalation.
    pub escalate_after_ms: Option<i64>,
    pub utc_offset_min: i32,
}

impl Route {
    /// From a checked configuration (its windows and offset parse).
    pub fn from_config(n: &NotifyConfig) -> Route {
        Route {
            name: n.name.get_ref().clone(),
            min_priority: *n.min_priority.get_ref(),
            selections: n.selections.iter().map(|s| s.get_ref().clone()).collect(),
            tags: n.tags.iter().map(|s| s.get_ref().clone()).collect(),
            contacts: n
                .contacts
                .iter()
                .map(|c| Contact {
                    name: c.name.get_ref().clone(),
                    address: c.address.get_ref().clone(),
                    on_call: c
                        .on_call
                        .iter()
                        .filter_map(|w| OnCallWindow::parse(w.get_ref()).ok())
                        .collect(),
                })
                .collect(),
            escalate_after_ms: n
                .escalate_after_min
                .as_ref()
                .map(|m| (*m.get_ref() * 60_000.0).round() as i64),
            utc_offset_min: n
                .utc_offset
                .as_ref()
                .and_then(|o| parse_utc_offset(o.get_ref()).ok())
                .unwrap_or(0),
        }
    }

    /// Whether an alarm of this priority, selection, key and tag is the
    /// route's.
    pub fn takes(&self, priority: u32, selection: &str, key: &str, tag: Option<&str>) -> bool {
        if key.starts_with(SYSTEM_ALARM_PREFIX) || priority < self.min_priority {
            return false;
        }
        let selected =
            self.selections.is_empty() || self.selections.iter().any(|p| glob_match(p, selection));
        let tagged = self.tags.is_empty()
            || self
                .tags
                .iter()
                .any(|p| glob_match(p, key) || tag.is_some_and(|t| glob_match(p, t)));
        selected && tagged
    }

    /// Whether a transition is an activation the route must announce: one
    /// the operator was shown (not shelved, suppressed or out of service).
    pub fn announces(&self, t: &AlarmTransition) -> bool {
        t.is_annunciated_activation()
            && self.takes(t.priority, &t.selection, &t.key, t.tag.as_deref())
    }

    /// The contact to tell at `now`: the first on call after position
    /// `after` in the chain (`None`: from the start). Nobody on call past
    /// `after`: `None`.
    pub fn contact_after(&self, after: Option<usize>, now: Timestamp) -> Option<usize> {
        let from = after.map_or(0, |a| a + 1);
        (from..self.contacts.len()).find(|&i| self.contacts[i].on_call_at(now, self.utc_offset_min))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// 2026-11-23 was a Monday.
    fn monday_at(h: i64, m: i64) -> Timestamp {
        let monday = 1_795_392_000_000i64; // 2026-11-23T00:00:00Z
        Timestamp::from_millis(monday + (h * 60 + m) * 60_000)
    }

    fn route() -> Route {
        let c = |name: &str, on: &[&str]| Contact {
            name: name.into(),
            address: format!("{name}@example.com"),
            on_call: on.iter().map(|w| OnCallWindow::parse(w).unwrap()).collect(),
        };
        Route {
            name: "r".into(),
            min_priority: 500,
            selections: vec!["SS1*".into()],
            tags: vec![],
            contacts: vec![
                c("day", &["mon-fri 07:00-19:00"]),
                c("night", &["19:00-07:00"]),
                c("boss", &[]),
            ],
            escalate_after_ms: Some(600_000),
            utc_offset_min: 0,
        }
    }

    #[test]
    fn monday_is_monday() {
        let c = Contact {
            name: "x".into(),
            address: "x".into(),
            on_call: vec![OnCallWindow::parse("mon 00:00-01:00").unwrap()],
        };
        assert!(c.on_call_at(monday_at(0, 30), 0));
        assert!(!c.on_call_at(monday_at(24, 30), 0), "Tuesday");
        assert!(!c.on_call_at(monday_at(0, 30), 60), "01:30 local");
        assert!(
            c.on_call_at(monday_at(-1, 30), 60),
            "Sunday 23:30 UTC is Monday 00:30 at +01:00"
        );
    }

    #[test]
    fn selection_priority_and_own_alarms() {
        let r = route();
        assert!(r.takes(700, "SS1", "SS1.Zone1.Trip", Some("SS1.Zone1.Trip")));
        assert!(
            !r.takes(400, "SS1", "SS1.Zone1.Trip", None),
            "below min_priority"
        );
        assert!(
            !r.takes(700, "SS2", "SS2.Zone1.Trip", None),
            "other selection"
        );
        assert!(
            !r.takes(900, "SS1", "notify:r", None),
            "the notifier's own alarm"
        );
        let mut t = r.clone();
        t.selections.clear();
        t.tags = vec!["*.Trip".into()];
        assert!(t.takes(700, "MG", "limit:MG.Bus.Trip:hi", Some("MG.Bus.Trip")));
        assert!(!t.takes(700, "MG", "limit:MG.Bus.Volts:hi", Some("MG.Bus.Volts")));
    }

    #[test]
    fn rota_and_escalation_chain() {
        let r = route();
        // Monday noon: the day engineer, escalating to the boss (the night
        // engineer is off).
        assert_eq!(r.contact_after(None, monday_at(12, 0)), Some(0));
        assert_eq!(r.contact_after(Some(0), monday_at(12, 10)), Some(2));
        assert_eq!(r.contact_after(Some(2), monday_at(12, 20)), None);
        // Monday night: the night engineer first.
        assert_eq!(r.contact_after(None, monday_at(22, 0)), Some(1));
        assert_eq!(r.contact_after(Some(1), monday_at(22, 10)), Some(2));
        // Saturday noon: the day engineer is off, the night one too.
        assert_eq!(r.contact_after(None, monday_at(5 * 24 + 12, 0)), Some(2));
    }
}
