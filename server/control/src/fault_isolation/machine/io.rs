//! What the machine is given and what it gives: the panel's settings, its
//! breakers, snapshots of its I/O, the inputs, operator commands and outputs.

use std::fmt;

use super::Mode;

/// Per-panel timing and limits.
#[derive(Debug, Clone, PartialEq)]
pub struct Settings {
    pub zones: u8,
    pub reclose_delay_s: f64,
    pub dwell_s: f64,
    pub confirm_timeout_s: f64,
    pub max_trips: u32,
    pub start_mode: Mode,
}

impl Settings {
    /// Takes the settings of a configured panel. Values that validation should
    /// have refused (non-positive or non-finite times) fall back to the
    /// configuration defaults rather than make the machine misbehave.
    pub fn from_panel(panel: &gridscada_config::PanelConfig) -> Settings {
        fn secs(v: f64, default: f64) -> f64 {
            if v.is_finite() && v > 0.0 {
                v
            } else {
                default
            }
        }
        Settings {
            zones: *panel.zones.get_ref(),
            reclose_delay_s: secs(*panel.reclose_delay_s.get_ref(), 3.0),
            dwell_s: secs(*panel.dwell_s.get_ref(), 1.0),
            confirm_timeout_s: secs(*panel.confirm_timeout_s.get_ref(), 2.0),
            max_trips: u32::from(*panel.max_trips.get_ref()).max(2),
            start_mode: panel.start_mode,
        }
    }

    /// The seed's bound on restoration time: 2 × reclose delay + (N + 1) × dwell.
    pub fn bound_s(&self) -> f64 {
        2.0 * self.reclose_delay_s + (f64::from(self.zones) + 1.0) * self.dwell_s
    }
}

/// A breaker of the panel. As a command target, `Elcb` means its reset output.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Breaker {
    Elcb,
    /// The main MCCB, "load 0".
    Mccb,
    /// Zone MCB, numbered from 1.
    Zone(u8),
}

impl Breaker {
    /// The breaker switching load `n` (0 = MCCB).
    pub fn load(n: u8) -> Breaker {
        if n == 0 {
            Breaker::Mccb
        } else {
            Breaker::Zone(n)
        }
    }

    /// The API name: `elcb`, `mccb`, `zone1`...
    pub fn name(self) -> String {
        match self {
            Breaker::Elcb => "elcb".into(),
            Breaker::Mccb => "mccb".into(),
            Breaker::Zone(n) => format!("zone{n}"),
        }
    }

    /// Parses an API name for a panel with `zones` zones.
    pub fn parse(name: &str, zones: u8) -> Result<Breaker, CommandError> {
        let n = name.trim().to_ascii_lowercase();
        let unknown = || CommandError::UnknownBreaker {
            name: name.chars().take(40).collect(),
            zones,
        };
        match n.as_str() {
            "elcb" => Ok(Breaker::Elcb),
            "mccb" => Ok(Breaker::Mccb),
            _ => {
                let z: u8 = n
                    .strip_prefix("zone")
                    .and_then(|d| d.parse().ok())
                    .ok_or_else(unknown)?;
                if (1..=zones).contains(&z) {
                    Ok(Breaker::Zone(z))
                } else {
                    Err(unknown())
                }
            }
        }
    }
}

impl fmt::Display for Breaker {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Breaker::Elcb => f.write_str("ELCB"),
            Breaker::Mccb => f.write_str("main MCCB"),
            Breaker::Zone(n) => write!(f, "zone {n} MCB"),
        }
    }
}

/// One status input: its value and whether its quality is Good.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Reading {
    pub closed: bool,
    pub good: bool,
}

impl Reading {
    pub fn good(closed: bool) -> Reading {
        Reading { closed, good: true }
    }
    pub fn bad() -> Reading {
        Reading {
            closed: false,
            good: false,
        }
    }
}

/// The panel's I/O as read at one moment.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Snapshot {
    pub elcb: Reading,
    pub mccb: Reading,
    /// Zone 1 first.
    pub zones: Vec<Reading>,
    /// Whether the command outputs (reset and command coils) read back with
    /// Good quality, i.e. the output modules are reachable.
    pub outputs_good: bool,
    /// Operations the server would refuse now (a safety tag, a switching
    /// interlock), with the reason: the sequence does not command them.
    pub blocked: Vec<BlockedOperation>,
}

/// An operation of a breaker the server refuses.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BlockedOperation {
    pub breaker: Breaker,
    /// Closing (for the ELCB: its reset) or opening.
    pub close: bool,
    pub reason: String,
}

impl Snapshot {
    /// A snapshot with every signal Good.
    pub fn good(elcb: bool, mccb: bool, zones: &[bool]) -> Snapshot {
        Snapshot {
            elcb: Reading::good(elcb),
            mccb: Reading::good(mccb),
            zones: zones.iter().map(|z| Reading::good(*z)).collect(),
            outputs_good: true,
            blocked: Vec::new(),
        }
    }

    /// Whether every signal is Good (and the snapshot has the right shape).
    pub fn all_good(&self, zones: u8) -> bool {
        self.zones.len() == usize::from(zones)
            && self.outputs_good
            && self.elcb.good
            && self.mccb.good
            && self.zones.iter().all(|z| z.good)
    }
}

/// The state of the breakers, as last read with Good quality.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PanelState {
    pub elcb: bool,
    pub mccb: bool,
    pub zones: Vec<bool>,
}

impl PanelState {
    pub(super) fn from_snapshot(s: &Snapshot) -> PanelState {
        PanelState {
            elcb: s.elcb.closed,
            mccb: s.mccb.closed,
            zones: s.zones.iter().map(|z| z.closed).collect(),
        }
    }

    /// Whether `b` is closed (unknown zones read as open).
    pub fn closed(&self, b: Breaker) -> bool {
        match b {
            Breaker::Elcb => self.elcb,
            Breaker::Mccb => self.mccb,
            Breaker::Zone(n) => n >= 1 && self.zones.get(usize::from(n) - 1) == Some(&true),
        }
    }

    /// MCCB and zones, load 0 first.
    pub(super) fn loads(&self) -> impl Iterator<Item = Breaker> + '_ {
        (0..=self.zones.len() as u8).map(Breaker::load)
    }
}

/// The sequence's timers. At most one of each runs at a time.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Timer {
    RecloseDelay,
    Dwell,
    Confirm,
}

impl Timer {
    pub(super) fn index(self) -> usize {
        match self {
            Timer::RecloseDelay => 0,
            Timer::Dwell => 1,
            Timer::Confirm => 2,
        }
    }
}

/// What the machine is told.
#[derive(Debug, Clone, PartialEq)]
pub enum Input {
    /// A fresh read of the panel's I/O.
    Snapshot(Snapshot),
    /// A timer started with this token ran out. Stale tokens are ignored, so a
    /// driver need not race cancellation.
    TimerExpired { timer: Timer, token: u64 },
    /// The field layer refused or lost a command. `comm` tells whether it was a
    /// communication failure (device offline, timeout) rather than a refusal.
    CommandFailed {
        breaker: Breaker,
        value: bool,
        reason: String,
        comm: bool,
    },
}

/// What an operator may ask (the role check is the web layer's).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum OperatorCommand {
    SetMode(Mode),
    Reset,
    /// Manual breaker command; closing the ELCB means a reset pulse.
    Breaker {
        breaker: Breaker,
        close: bool,
    },
}

/// Why an operator command was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CommandError {
    #[error(
        "manual breaker commands are only accepted in manual mode; the panel is in automatic mode"
    )]
    NotManual,
    #[error("interlock: {0}")]
    Interlocked(String),
    #[error(
        "communication with the panel's I/O is lost or not yet established; its state is unknown"
    )]
    CommLost,
    #[error("the automatic sequence is running (step '{0}'); wait for it to finish or switch to manual mode")]
    Busy(&'static str),
    #[error("unknown breaker '{name}': expected elcb, mccb or zone1..zone{zones}")]
    UnknownBreaker { name: String, zones: u8 },
    #[error("the ELCB has no trip output; it can only be reset (closed) from the SCADA")]
    ElcbCannotOpen,
    /// This server of a redundant pair is on standby: its sequences run
    /// only on the active server (the text names it).
    #[error("{0}")]
    Standby(String),
}

/// What the machine asks for.
#[derive(Debug, Clone, PartialEq)]
pub enum Output {
    /// Write `value` to the breaker's command output (for the ELCB, its reset
    /// output: `true` then `false` is one reset pulse). In order.
    Command {
        breaker: Breaker,
        value: bool,
    },
    /// (Re)start `timer`; deliver `TimerExpired { timer, token }` after `after_s`.
    StartTimer {
        timer: Timer,
        after_s: f64,
        token: u64,
    },
    CancelTimer {
        timer: Timer,
    },
    /// For the event log.
    Event {
        kind: &'static str,
        message: String,
    },
    /// An alarm condition became active (`active`) or cleared.
    Alarm {
        key: String,
        active: bool,
        priority: u32,
        message: String,
    },
}
