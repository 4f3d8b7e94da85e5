//! What the sequence annunciates: alarm priorities and keys, raising and
//! clearing its alarms, and its events.

use super::io::{Breaker, Output};
use super::step::Step;
use super::{Mode, Sequence};

/// Alarm priorities (the alarm engine's scale: higher is more urgent).
pub mod priority {
    pub const ELCB_TRIP: u32 = 900;
    pub const LOAD0_FAULT: u32 = 900;
    pub const LOCKOUT: u32 = 900;
    pub const MISMATCH: u32 = 800;
    pub const COMM_LOST: u32 = 800;
    pub const ZONE_ISOLATED: u32 = 700;
}

/// Key of the ELCB trip alarm. A plant whose ELCB status tag carries its own
/// discrete alarm annunciates the trip there; the wiring then drops this one
/// so one trip is one alarm.
pub const ELCB_TRIP_ALARM: &str = "elcb.trip";

/// Key of the lockout alarm.
pub(super) const LOCKOUT_ALARM: &str = "lockout";

/// Key of the alarm of healthy loads left off in automatic mode (cleared by
/// the next sequence, by manual mode, or when they read closed again).
pub(super) const LOADS_OFF_ALARM: &str = "loads_off";

/// Key of the alarm of a faulty load.
pub(super) fn faulty_alarm_key(load: u8) -> String {
    if load == 0 {
        "load0.fault".into()
    } else {
        format!("zone{load}.isolated")
    }
}

impl Sequence {
    pub(super) fn raise_faulty_alarm(&mut self, load: u8, out: &mut Vec<Output>) {
        let (priority, message) = if load == 0 {
            (
                priority::LOAD0_FAULT,
                "fault on load 0 (main MCCB / busbar): nothing can be restored".to_string(),
            )
        } else {
            (
                priority::ZONE_ISOLATED,
                format!("zone {load} is faulty and isolated (left off)"),
            )
        };
        self.raise(&faulty_alarm_key(load), priority, message, out);
    }

    /// The standing alarm of loads left off in automatic mode: at rest
    /// (`idle` or `isolated`) with the ELCB closed, every load not known
    /// faulty should be on. One that is not (a sequence stopped by manual
    /// mode, or the server restarted, before it restored them; a breaker
    /// opened by hand) is not switched on by the machine, since that is
    /// Reset's job, so the operator is told. Checked on entering automatic
    /// mode and on every good snapshot at rest; cleared when they all read
    /// closed again.
    pub(super) fn check_loads_off(&mut self, out: &mut Vec<Output>) {
        let at_rest = self.mode == Mode::Auto
            && !self.lockout
            && matches!(self.step, Step::Idle | Step::Isolated);
        let off: Vec<String> = match &self.known {
            Some(k) if at_rest && self.comm_good && k.elcb => (0..=self.settings.zones)
                .filter(|l| !self.faulty.contains(l) && !k.closed(Breaker::load(*l)))
                .map(|l| l.to_string())
                .collect(),
            // Not at rest, or nothing known yet: left as it is.
            _ => return,
        };
        if off.is_empty() {
            self.clear(LOADS_OFF_ALARM, out);
        } else {
            self.raise(
                LOADS_OFF_ALARM,
                priority::ZONE_ISOLATED,
                format!(
                    "automatic mode with load(s) {} off and not known faulty: press Reset to restore them",
                    off.join(", ")
                ),
                out,
            );
        }
    }

    pub(super) fn raise_trip_alarm(&mut self, out: &mut Vec<Output>) {
        self.raise(
            ELCB_TRIP_ALARM,
            priority::ELCB_TRIP,
            "ELCB tripped: supply to all zones lost".into(),
            out,
        );
    }

    pub(super) fn raise(
        &mut self,
        key: &str,
        priority: u32,
        message: String,
        out: &mut Vec<Output>,
    ) {
        if self
            .active_alarms
            .insert(key.to_string(), priority)
            .is_none()
        {
            out.push(Output::Alarm {
                key: key.to_string(),
                active: true,
                priority,
                message,
            });
        }
    }

    pub(super) fn clear(&mut self, key: &str, out: &mut Vec<Output>) {
        if let Some(priority) = self.active_alarms.remove(key) {
            out.push(Output::Alarm {
                key: key.to_string(),
                active: false,
                priority,
                message: format!("{key}: cleared"),
            });
        }
    }
}

pub(super) fn event(out: &mut Vec<Output>, kind: &'static str, message: String) {
    out.push(Output::Event { kind, message });
}
