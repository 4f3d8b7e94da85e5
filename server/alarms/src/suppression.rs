//! Suppression by design: rules that hide consequential alarms while a
//! causing alarm stands, so one fault does not flood the operator.
//!
//! **Owns:** the rule model ([`SuppressionRule`], [`AlarmMatch`]) and the
//! default rules derived from the plant's panels. Applying rules to live
//! alarms is [`crate::AlarmSet`]'s job.
//!
//! The default rule of a panel with prefix `P`: while the ELCB trip alarm
//! (the discrete alarm of `P.ELCB.Closed` with `when = false`) stands, the
//! alarms of `P.Zone*` tags and the low/low-low alarms of the panel's power
//! analyzer (`P.PA.V_*`, `P.PA.I_*`, `P.PA.Hz`) are suppressed: with the ELCB
//! open, dead zones and zero voltage are expected, not news. A panel with
//! `default_suppression = false` has no default rule; `[[suppression]]`
//! rules of the configuration are added to the defaults ([`plant_rules`]).

use gridscada_config::{PanelConfig, Plant, SuppressionConfig};
use serde::{Deserialize, Serialize};

use crate::model::AlarmKind;

/// Which alarms a rule suppresses: those of tags whose name starts with
/// `tag_prefix`, of the listed kinds (all kinds when empty).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct AlarmMatch {
    pub tag_prefix: String,
    #[serde(default)]
    pub kinds: Vec<AlarmKind>,
}

impl AlarmMatch {
    pub fn new(tag_prefix: impl Into<String>, kinds: &[AlarmKind]) -> Self {
        AlarmMatch {
            tag_prefix: tag_prefix.into(),
            kinds: kinds.to_vec(),
        }
    }

    pub fn matches(&self, tag: Option<&str>, kind: AlarmKind) -> bool {
        let Some(tag) = tag else { return false };
        tag.starts_with(&self.tag_prefix) && (self.kinds.is_empty() || self.kinds.contains(&kind))
    }
}

/// While the alarm `trigger` (a key) is active, the alarms matching `targets`
/// are suppressed. The suppression is held for `release_delay_s` after the
/// trigger clears, because the consequential values (read from another
/// device, on another scan) take a moment to come back; without the hold the
/// operator would see them flash up as the breaker recloses.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SuppressionRule {
    pub name: String,
    pub trigger: String,
    pub targets: Vec<AlarmMatch>,
    #[serde(default = "default_release_delay")]
    pub release_delay_s: f64,
}

/// Default hold of a suppression after its trigger clears.
pub const DEFAULT_RELEASE_DELAY_S: f64 = 10.0;

fn default_release_delay() -> f64 {
    DEFAULT_RELEASE_DELAY_S
}

/// The default rules of the plant: one per panel whose ELCB status tag has a
/// discrete alarm on `false` (the trip), unless the panel turned its default
/// off. Panels without that alarm get no rule.
pub fn default_rules(plant: &Plant) -> Vec<SuppressionRule> {
    plant
        .panels
        .iter()
        .filter(|p| *p.default_suppression.get_ref())
        .filter_map(|p| panel_rule(plant, p))
        .collect()
}

/// Every rule of the plant: the panels' defaults, then the configured
/// `[[suppression]]` rules (validated when the configuration was loaded).
pub fn plant_rules(plant: &Plant) -> Vec<SuppressionRule> {
    let mut rules = default_rules(plant);
    rules.extend(plant.suppression.iter().map(configured_rule));
    rules
}

fn configured_rule(c: &SuppressionConfig) -> SuppressionRule {
    SuppressionRule {
        name: c.name.get_ref().clone(),
        trigger: c.trigger.get_ref().clone(),
        targets: c
            .suppress
            .get_ref()
            .iter()
            .map(|t| AlarmMatch {
                tag_prefix: t.tag_prefix.get_ref().clone(),
                kinds: t
                    .kinds
                    .iter()
                    .filter_map(|k| {
                        AlarmKind::ALL
                            .into_iter()
                            .find(|a| a.as_str() == k.get_ref())
                    })
                    .collect(),
            })
            .collect(),
        release_delay_s: *c.release_delay_s.get_ref(),
    }
}

fn panel_rule(plant: &Plant, panel: &PanelConfig) -> Option<SuppressionRule> {
    let io = panel.io();
    let tag = plant.tag(&io.elcb_closed)?;
    let alarm = tag.alarm.as_ref()?;
    let index = alarm
        .discrete
        .iter()
        .position(|d| matches!(d.when.get_ref(), toml::Value::Boolean(false)))?;
    let p = panel.prefix.get_ref();
    let low = [AlarmKind::Lo, AlarmKind::LoLo];
    Some(SuppressionRule {
        name: format!("{}: ELCB trip", panel.id.get_ref()),
        trigger: crate::model::discrete_key(&io.elcb_closed, index),
        targets: vec![
            AlarmMatch::new(format!("{p}.Zone"), &[]),
            AlarmMatch::new(format!("{p}.PA.V_"), &low),
            AlarmMatch::new(format!("{p}.PA.I_"), &low),
            AlarmMatch::new(format!("{p}.PA.Hz"), &low),
        ],
        release_delay_s: DEFAULT_RELEASE_DELAY_S,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn match_by_prefix_and_kind() {
        let m = AlarmMatch::new("SS1.PA.V_", &[AlarmKind::Lo, AlarmKind::LoLo]);
        assert!(m.matches(Some("SS1.PA.V_L1"), AlarmKind::Lo));
        assert!(!m.matches(Some("SS1.PA.V_L1"), AlarmKind::Hi));
        assert!(!m.matches(Some("CSS1.PA.V_L1"), AlarmKind::Lo));
        assert!(!m.matches(None, AlarmKind::Lo));
        let all = AlarmMatch::new("SS1.Zone", &[]);
        assert!(all.matches(Some("SS1.Zone3.Closed"), AlarmKind::Discrete));
    }
}
