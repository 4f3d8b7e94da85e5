//! Substation panels (`[[panel]]`): their kind, timings, mode and the I/O
//! names their sequence uses under the panel's prefix (`PanelConfig::io`).

use serde::{Deserialize, Serialize};
use serde_spanned::Spanned;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum PanelKind {
    /// The service substation panel.
    Service,
    /// A customer service substation panel.
    CustomerService,
}

/// An LV substation panel that runs the OLUC/OLDC fault-isolation sequence.
///
/// Its I/O tags follow a naming convention under `prefix` (see
/// [`PanelConfig::io`]); `gridscada check` verifies that they exist.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct PanelConfig {
    /// Short id used in the API, e.g. `ss1`.
    pub id: Spanned<String>,
    pub name: String,
    pub kind: PanelKind,
    /// Tag name prefix of the panel's I/O, e.g. `SS1`.
    pub prefix: Spanned<String>,
    /// Number of zone MCBs (the seed has 4).
    pub zones: Spanned<u8>,
    /// Delay before the ELCB is reset after a trip.
    #[serde(default = "default_reclose_delay")]
    pub reclose_delay_s: Spanned<f64>,
    /// Time after each switch-on for the ELCB to trip if the load is faulty.
    #[serde(default = "default_dwell")]
    pub dwell_s: Spanned<f64>,
    /// Time for a status input to confirm a command.
    #[serde(default = "default_confirm_timeout")]
    pub confirm_timeout_s: Spanned<f64>,
    /// ELCB trips allowed in one sequence before lockout.
    #[serde(default = "default_max_trips")]
    pub max_trips: Spanned<u8>,
    /// Mode at start-up.
    #[serde(default = "default_auto")]
    pub start_mode: PanelMode,
    /// The built-in suppression rule (the ELCB trip suppresses the zones'
    /// alarms and the analyzer's low alarms); `false` to turn it off, e.g.
    /// to write a `[[suppression]]` rule of the plant's own instead.
    #[serde(default = "default_true")]
    pub default_suppression: Spanned<bool>,
}

fn default_true() -> Spanned<bool> {
    Spanned::new(0..0, true)
}

fn default_reclose_delay() -> Spanned<f64> {
    Spanned::new(0..0, 3.0)
}
fn default_dwell() -> Spanned<f64> {
    Spanned::new(0..0, 1.0)
}
fn default_confirm_timeout() -> Spanned<f64> {
    Spanned::new(0..0, 2.0)
}
fn default_max_trips() -> Spanned<u8> {
    Spanned::new(0..0, 8)
}
fn default_auto() -> PanelMode {
    PanelMode::Auto
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum PanelMode {
    Auto,
    Manual,
}

/// Names of a panel's I/O tags.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PanelIo {
    /// ELCB status input: true while closed.
    pub elcb_closed: String,
    /// ELCB reset output: a pulse closes a tripped ELCB.
    pub elcb_reset: String,
    /// Main MCCB (load 0) command output and status input.
    pub mccb_cmd: String,
    pub mccb_closed: String,
    /// Zone MCB command outputs and status inputs, zone 1 first.
    pub zone_cmd: Vec<String>,
    pub zone_closed: Vec<String>,
}

impl PanelConfig {
    pub fn io(&self) -> PanelIo {
        let p = self.prefix.get_ref();
        let n = *self.zones.get_ref();
        PanelIo {
            elcb_closed: format!("{p}.ELCB.Closed"),
            elcb_reset: format!("{p}.ELCB.Reset"),
            mccb_cmd: format!("{p}.MCCB.Cmd"),
            mccb_closed: format!("{p}.MCCB.Closed"),
            zone_cmd: (1..=n).map(|z| format!("{p}.Zone{z}.Cmd")).collect(),
            zone_closed: (1..=n).map(|z| format!("{p}.Zone{z}.Closed")).collect(),
        }
    }
}
