//! The shapes of a scenario file's sections and entries, as deserialized
//! before their meaning is checked.

use gridscada_config::PanelMode;
use serde::Deserialize;
use serde_spanned::Spanned;

use crate::scenario::time::TimeValue;
use crate::FaultKind;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawInitial {
    #[serde(default)]
    pub(super) unit: Vec<RawInitUnit>,
    #[serde(default)]
    pub(super) panel: Vec<RawInitPanel>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawInitUnit {
    pub(super) id: Spanned<String>,
    pub(super) soc_pct: Option<Spanned<f64>>,
    #[serde(default)]
    pub(super) tripped: bool,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawInitPanel {
    pub(super) id: Spanned<String>,
    pub(super) mode: Option<PanelMode>,
    #[serde(default)]
    pub(super) door_open: bool,
    #[serde(default)]
    pub(super) zone_kw: Vec<Spanned<f64>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawSeries {
    pub(super) csv: Option<Spanned<String>>,
    pub(super) column: Option<String>,
    pub(super) points: Option<Vec<(TimeValue, f64)>>,
    pub(super) constant: Option<f64>,
    pub(super) interpolate: Option<Interp>,
    pub(super) scale: Option<f64>,
    pub(super) noise: Option<f64>,
    // Zone profiles only.
    pub(super) panel: Option<Spanned<String>>,
    pub(super) zone: Option<Spanned<u8>>,
    pub(super) pf: Option<f64>,
}

#[derive(Deserialize, Clone, Copy)]
#[serde(rename_all = "lowercase")]
pub(super) enum Interp {
    Linear,
    Step,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawEvent {
    pub(super) at: Spanned<TimeValue>,
    pub(super) action: Spanned<String>,
    pub(super) panel: Option<Spanned<String>>,
    pub(super) zone: Option<Spanned<u8>>,
    pub(super) kind: Option<FaultKind>,
    pub(super) mode: Option<PanelMode>,
    pub(super) breaker: Option<Spanned<String>>,
    pub(super) close: Option<bool>,
    pub(super) device: Option<Spanned<String>>,
    pub(super) unit: Option<Spanned<String>>,
    pub(super) soc_pct: Option<f64>,
    pub(super) user: Option<String>,
    #[allow(dead_code)] // A comment for the reader of the file.
    pub(super) note: Option<String>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawExpect {
    pub(super) at: Option<Spanned<TimeValue>>,
    pub(super) tag: Option<Spanned<String>>,
    pub(super) figure: Option<Spanned<String>>,
    pub(super) value: Option<ExpectValueRaw>,
    pub(super) tolerance: Option<f64>,
    pub(super) min: Option<f64>,
    pub(super) max: Option<f64>,
    pub(super) note: Option<String>,
    pub(super) known_failure: Option<String>,
}

#[derive(Deserialize)]
#[serde(untagged)]
pub(super) enum ExpectValueRaw {
    Bool(bool),
    Number(f64),
    Text(String),
}
