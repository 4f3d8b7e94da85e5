//! A tag's alarms (limit and discrete) and its history logging policy.

use serde::{Deserialize, Serialize};
use serde_spanned::Spanned;

use super::*;

/// Alarm settings of a tag.
#[derive(Debug, Clone, Default, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct AlarmConfig {
    /// Default selection (alarm group) of this tag's alarms.
    pub selection: Option<String>,
    pub hihi: Option<LimitAlarm>,
    pub hi: Option<LimitAlarm>,
    pub lo: Option<LimitAlarm>,
    pub lolo: Option<LimitAlarm>,
    /// Discrete alarms: active while the value equals `when`.
    #[serde(default)]
    pub discrete: Vec<DiscreteAlarm>,
}

impl AlarmConfig {
    /// Whether one of the discrete alarms is active while a bool tag reads `v`.
    pub fn alarms_when(&self, v: bool) -> bool {
        self.discrete
            .iter()
            .any(|d| matches!(d.when.get_ref(), toml::Value::Boolean(b) if *b == v))
    }
}

#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct LimitAlarm {
    pub limit: Spanned<f64>,
    #[serde(default = "default_priority")]
    pub priority: u32,
    /// The value must come back past the limit by this much to clear.
    #[serde(default = "zero")]
    pub deadband: Spanned<f64>,
    /// Seconds the condition must hold before the alarm activates.
    #[serde(default = "zero")]
    pub on_delay_s: Spanned<f64>,
    /// Seconds the condition must be gone before the alarm clears.
    #[serde(default = "zero")]
    pub off_delay_s: Spanned<f64>,
    /// Message; `{tag}`, `{value}`, `{limit}` and `{units}` are substituted.
    pub message: Option<String>,
    pub selection: Option<String>,
}

#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct DiscreteAlarm {
    /// The alarm is active while the tag has this value.
    pub when: Spanned<toml::Value>,
    #[serde(default = "default_priority")]
    pub priority: u32,
    #[serde(default = "zero")]
    pub on_delay_s: Spanned<f64>,
    #[serde(default = "zero")]
    pub off_delay_s: Spanned<f64>,
    pub message: Option<String>,
    pub selection: Option<String>,
}

fn default_priority() -> u32 {
    500
}

/// Historian settings of a tag. By default every tag is logged on change.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct HistoryConfig {
    #[serde(default = "yes")]
    pub enabled: bool,
    /// A value is logged when it moves more than this from the last logged one.
    #[serde(default = "zero")]
    pub deadband: Spanned<f64>,
    /// A value is logged at least this often, changed or not.
    #[serde(default = "default_max_interval")]
    pub max_interval_s: Spanned<f64>,
    /// Retention in days; the storage default applies when absent.
    pub retention_days: Option<u32>,
}

impl Default for HistoryConfig {
    fn default() -> Self {
        HistoryConfig {
            enabled: true,
            deadband: Spanned::new(0..0, 0.0),
            max_interval_s: default_max_interval(),
            retention_days: None,
        }
    }
}

fn default_max_interval() -> Spanned<f64> {
    Spanned::new(0..0, 900.0)
}

/// `[[suppression]]`: suppression by design. While the alarm `trigger`
/// stands, the alarms matching one of `suppress` are suppressed (kept, but
/// out of the operator's list), and released `release_delay_s` after the
/// trigger clears. Each panel has a built-in rule (its ELCB trip suppresses
/// its zones and its analyzer's low alarms) unless the panel sets
/// `default_suppression = false`.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct SuppressionConfig {
    /// Unique name, shown in events.
    pub name: Spanned<String>,
    /// The key of the causing alarm: `TAG:discrete` (`TAG:discrete2`...),
    /// `TAG:hihi`, `TAG:hi`, `TAG:lo`, `TAG:lolo`, or `DEVICE:comm`.
    pub trigger: Spanned<String>,
    /// The alarms to suppress.
    pub suppress: Spanned<Vec<SuppressTarget>>,
    /// Seconds the suppression is held after the trigger clears.
    #[serde(default = "ten")]
    pub release_delay_s: Spanned<f64>,
}

/// The alarms of the tags whose name starts with `tag_prefix`, of the listed
/// kinds (`hihi`, `hi`, `lo`, `lolo`, `discrete`; all when empty).
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct SuppressTarget {
    pub tag_prefix: Spanned<String>,
    #[serde(default)]
    pub kinds: Vec<Spanned<String>>,
}

/// The alarm kinds a suppression target may name.
pub const SUPPRESSIBLE_KINDS: [&str; 5] = ["hihi", "hi", "lo", "lolo", "discrete"];

fn ten() -> Spanned<f64> {
    Spanned::new(0..0, 10.0)
}
