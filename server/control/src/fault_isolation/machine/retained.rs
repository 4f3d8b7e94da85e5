//! What a sequence carries across a restart of the server ([`Retained`]):
//! saving it and taking over from it.

use serde::{Deserialize, Serialize};

use super::alarms::{event, faulty_alarm_key, priority, LOADS_OFF_ALARM, LOCKOUT_ALARM};
use super::io::{Output, Settings};
use super::step::{Outcome, Step};
use super::{Mode, Sequence};

/// What a panel's sequence must carry across a restart of the server: the
/// mode the operators chose, the zones known faulty and the lockout. Without
/// it a fresh sequence would find a locked-out panel's ELCB open, take it for
/// a new trip and switch onto the fault it had locked out on.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Retained {
    pub mode: Mode,
    /// Known-faulty loads (0 = MCCB / busbar).
    pub faulty: Vec<u8>,
    pub lockout: bool,
    /// The step a sequence was at (running or suspended) when this was
    /// saved: the server stopped in the middle of it.
    pub interrupted_at: Option<String>,
    /// The standing alarm of loads left off in automatic mode was active (a
    /// sequence stopped before it restored them, then automatic mode again):
    /// it stays standing across the restart until the panel is read.
    #[serde(default)]
    pub loads_off: bool,
}

impl Retained {
    /// The alarms [`Sequence::restore`] raises again at once: each faulty
    /// load's and the lockout's. The application keeps these standing
    /// across the restart (acknowledged ones stay acknowledged) instead of
    /// clearing and re-annunciating them.
    pub fn alarm_keys(&self, zones: u8) -> Vec<String> {
        let mut keys: Vec<String> = self
            .faulty
            .iter()
            .filter(|l| **l <= zones)
            .map(|l| faulty_alarm_key(*l))
            .collect();
        if self.lockout || self.interrupted_at.is_some() {
            keys.push(LOCKOUT_ALARM.into());
        } else if self.loads_off && self.mode == Mode::Auto {
            keys.push(LOADS_OFF_ALARM.into());
        }
        keys
    }
}

impl Sequence {
    /// A sequence taking over what a previous run of the server left
    /// (`Retained`): the mode, the faulty zones with their alarms raised
    /// again, and the lockout. A sequence the restart interrupted locks out
    /// (the panel's state is not what any step expects, and switching blind
    /// is never safe); Reset after checking the panel resumes automatic
    /// operation. Faulty loads beyond this panel's zones are dropped.
    pub fn restore(settings: Settings, r: &Retained, out: &mut Vec<Output>) -> Sequence {
        let mut s = Sequence::new(settings);
        s.mode = r.mode;
        s.step = if r.mode == Mode::Manual {
            Step::Manual
        } else {
            Step::Idle
        };
        s.metrics.outcome = Outcome::None;
        let zones = s.settings.zones;
        for &load in r.faulty.iter().filter(|l| **l <= zones) {
            s.faulty.insert(load);
            s.raise_faulty_alarm(load, out);
        }
        s.count_sv = s.faulty.iter().next_back().copied().unwrap_or(0);
        event(
            out,
            "restored",
            format!(
                "state restored after a server restart: {} mode, faulty loads {:?}, lockout {}",
                if r.mode == Mode::Manual {
                    "manual"
                } else {
                    "automatic"
                },
                s.faulty,
                if r.lockout { "on" } else { "off" }
            ),
        );
        match (&r.interrupted_at, r.lockout) {
            (_, true) => s.lock_out("locked out before the server restarted", out),
            (Some(step), false) => s.lock_out(
                &format!(
                    "the server restarted during the sequence (step '{step}'); check the panel"
                ),
                out,
            ),
            (None, false) => {
                s.set_rest_step("restored after a server restart", out);
                if r.loads_off && r.mode == Mode::Auto {
                    // Until the first snapshot says otherwise (see
                    // `check_loads_off`), loads are still off.
                    s.raise(
                        LOADS_OFF_ALARM,
                        priority::ZONE_ISOLATED,
                        "automatic mode with loads left off before the server restarted: \
                         press Reset to restore them"
                            .into(),
                        out,
                    );
                }
            }
        }
        s
    }

    /// What must survive a restart (see [`Retained`]).
    ///
    /// (The alarm keys a sequence restored from it raises at once are
    /// [`Retained::alarm_keys`].)
    pub fn retained(&self) -> Retained {
        let step = self
            .suspended_from
            .filter(|_| self.step == Step::Suspended)
            .unwrap_or(self.step);
        Retained {
            mode: self.mode,
            faulty: self.faulty.iter().copied().collect(),
            lockout: self.lockout,
            interrupted_at: (self.step == Step::Suspended || step.is_running())
                .then(|| step.name().to_string()),
            loads_off: self.active_alarms.contains_key(LOADS_OFF_ALARM),
        }
    }
}
