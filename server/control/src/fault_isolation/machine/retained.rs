//! What a sequence carries across a restart of the server ([`Retained`]):
//! saving it and taking over from it.

use std::collections::BTreeMap;
use std::fmt;

use serde::{Deserialize, Serialize};

use super::alarms::{event, faulty_alarm_key, priority, LOADS_OFF_ALARM, LOCKOUT_ALARM};
use super::io::{Output, Settings};
use super::step::{Outcome, Step};
use super::steps::Cause;
use super::{Mode, Sequence};

/// What a panel's sequence must carry across a restart of the server (or to
/// the other server of a pair): the mode the operators chose, the zones known
/// faulty and the lockout, and the progress of a sequence in the middle, so
/// the server taking over finishes it. Without it a fresh sequence would
/// find a locked-out panel's ELCB open, take it for a new trip and switch
/// onto the fault it had locked out on.
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
    /// How far the interrupted sequence had come (with `interrupted_at`);
    /// `None` at rest, and in what an older version saved.
    #[serde(default)]
    pub progress: Option<Progress>,
}

/// What a sequence in the middle has learnt, for the server that takes it
/// over (see "Taking over a sequence" in the module docs). What it does not
/// hold (timers, commands awaiting confirmation, when loads were closed) is
/// not known after a takeover, and is treated the conservative way.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Progress {
    /// The sequence began with an ELCB trip (else with an operator's Reset).
    pub after_trip: bool,
    /// Loads proven healthy in this sequence: re-closed without a dwell of
    /// their own, kept on when found on.
    pub proven: Vec<u8>,
    /// Whether proven loads may still be re-closed without a dwell (false
    /// once a trip could not be pinned on one load).
    pub fast_reclose: bool,
    /// ELCB trips so far: they count against the trip limit.
    pub trips: u32,
    pub elcb_resets: u32,
    pub switching_ops: u32,
    pub reenergisations: u32,
    /// Each blame of this sequence, with the loads energised at its trip
    /// that still cast doubt on it (see "Revisiting a blame").
    pub blames: BTreeMap<u8, Vec<u8>>,
    /// Loads whose blame was withdrawn once in this sequence.
    pub retested: Vec<u8>,
    /// A fault was found in this sequence (else it ends as a transient one).
    pub found_new: bool,
}

/// How the sequence came to a new server: the same one started again, or
/// the other server of a redundant pair took over.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Takeover {
    Restart,
    Failover,
}

impl fmt::Display for Takeover {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Takeover::Restart => "restart",
            Takeover::Failover => "failover",
        })
    }
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
        if self.lockout || (self.interrupted_at.is_some() && self.progress.is_none()) {
            keys.push(LOCKOUT_ALARM.into());
        } else if self.loads_off && self.mode == Mode::Auto {
            keys.push(LOADS_OFF_ALARM.into());
        }
        keys
    }
}

impl Sequence {
    /// A sequence taking over what a previous run of the server, or the
    /// other server of a pair, left (`Retained`): the mode, the faulty zones
    /// with their alarms raised again, and the lockout. A sequence
    /// interrupted in the middle waits for the first good read of the panel
    /// and finishes from there (see "Taking over a sequence"); one saved
    /// without its progress (an older version) locks out. Faulty loads
    /// beyond this panel's zones are dropped.
    pub fn restore(
        settings: Settings,
        r: &Retained,
        takeover: Takeover,
        out: &mut Vec<Output>,
    ) -> Sequence {
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
                "state restored after a {takeover}: {} mode, faulty loads {:?}, lockout {}",
                if r.mode == Mode::Manual {
                    "manual"
                } else {
                    "automatic"
                },
                s.faulty,
                if r.lockout { "on" } else { "off" }
            ),
        );
        let resumable = (r.mode == Mode::Auto)
            .then_some(())
            .and(r.progress.as_ref())
            .zip(r.interrupted_at.as_deref().and_then(Step::from_name))
            .filter(|(_, step)| step.is_running());
        match (&r.interrupted_at, r.lockout) {
            (_, true) => s.lock_out(&format!("locked out before the {takeover}"), out),
            (Some(_), false) if resumable.is_some() => {
                if let Some((p, step)) = resumable {
                    s.await_takeover(takeover, step, p, out);
                }
            }
            (Some(step), false) => s.lock_out(
                &format!(
                    "the {takeover} came during the sequence (step '{step}') and its progress \
                     was not saved; check the panel"
                ),
                out,
            ),
            (None, false) => {
                s.set_rest_step(&format!("restored after a {takeover}"), out);
                if r.loads_off && r.mode == Mode::Auto {
                    // Until the first snapshot says otherwise (see
                    // `check_loads_off`), loads are still off.
                    s.raise(
                        LOADS_OFF_ALARM,
                        priority::ZONE_ISOLATED,
                        format!(
                            "automatic mode with loads left off before the {takeover}: \
                             press Reset to restore them"
                        ),
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
        let interrupted = self.step == Step::Suspended || step.is_running();
        Retained {
            mode: self.mode,
            faulty: self.faulty.iter().copied().collect(),
            lockout: self.lockout,
            interrupted_at: interrupted.then(|| step.name().to_string()),
            loads_off: self.active_alarms.contains_key(LOADS_OFF_ALARM),
            progress: interrupted.then(|| Progress {
                after_trip: self.cause == Cause::Trip,
                proven: self.proven.iter().copied().collect(),
                fast_reclose: self.fast_reclose,
                trips: self.metrics.trips,
                elcb_resets: self.metrics.elcb_resets,
                switching_ops: self.metrics.switching_ops,
                reenergisations: self.metrics.reenergisations,
                blames: self
                    .marks
                    .iter()
                    .map(|(m, e)| (*m, e.iter().copied().collect()))
                    .collect(),
                retested: self.retested.iter().copied().collect(),
                found_new: self.found_new,
            }),
        }
    }
}
