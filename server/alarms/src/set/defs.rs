//! Alarm definitions: from the plant's tags and devices, for system alarms,
//! their validation, and how their messages show values.

use std::sync::Arc;
use std::time::Duration;

use gridscada_config::{AlarmConfig, LimitAlarm, Plant, TagConfig};
use gridscada_tagdb::Value;

use crate::machine::{format_value, AlarmDef, Condition};
use crate::model::{comm_key, discrete_key, limit_key};
use crate::model::{AlarmError, AlarmKind};

use super::operations::secs;

pub(super) fn validate_def(def: &AlarmDef) -> Result<(), AlarmError> {
    if def.key.trim().is_empty() {
        return Err(AlarmError::invalid("alarm", "the key must not be empty"));
    }
    match &def.condition {
        Condition::Above { limit, deadband } | Condition::Below { limit, deadband } => {
            if !limit.is_finite() {
                return Err(AlarmError::invalid(
                    format!("alarm '{}'", def.key),
                    "the limit must be a finite number",
                ));
            }
            if !deadband.is_finite() || *deadband < 0.0 {
                return Err(AlarmError::invalid(
                    format!("alarm '{}'", def.key),
                    "the deadband must be a non-negative number",
                ));
            }
        }
        Condition::Equals(Value::Float(f)) if !f.is_finite() => {
            return Err(AlarmError::invalid(
                format!("alarm '{}'", def.key),
                "the alarm value must be a finite number",
            ));
        }
        _ => {}
    }
    Ok(())
}

pub(super) fn system_def(key: &str, priority: u32, selection: &str, message: &str) -> AlarmDef {
    AlarmDef {
        key: key.trim().to_owned(),
        tag: None,
        kind: AlarmKind::System,
        priority,
        selection: selection.trim().to_owned(),
        message: message.to_owned(),
        units: String::new(),
        device: None,
        states: None,
        decimals: None,
        condition: Condition::External,
        on_delay: Duration::ZERO,
        off_delay: Duration::ZERO,
    }
}

/// The first segment of a dotted name (`SS1.PA.V_L1` -> `SS1`).
pub fn first_segment(name: &str) -> &str {
    name.split('.').next().unwrap_or(name)
}

/// The alarm definitions of a plant: every tag's limit and discrete alarms,
/// then one comm alarm per device.
pub fn plant_defs(plant: &Plant) -> Result<Vec<AlarmDef>, AlarmError> {
    let mut defs = Vec::new();
    for tag in &plant.tags {
        if let Some(a) = &tag.alarm {
            let decimals = plant.hmi.decimals_for(tag.value_kind(), tag.decimals());
            tag_defs(tag, a, decimals, &mut defs)?;
        }
    }
    let comm_states = Arc::new(std::collections::BTreeMap::from([
        ("false".to_string(), "COMM LOST".to_string()),
        ("true".to_string(), "CONNECTED".to_string()),
    ]));
    for d in &plant.devices {
        let device = d.name.get_ref();
        defs.push(AlarmDef {
            key: comm_key(device),
            tag: Some(format!("{device}.Comm.Connected")),
            kind: AlarmKind::CommFail,
            priority: d.comm_alarm.priority,
            selection: first_segment(device).to_owned(),
            message: "Communication lost with {device}: {error}".into(),
            units: String::new(),
            device: Some(device.clone()),
            // The status in words, as every other state is shown.
            states: Some(Arc::clone(&comm_states)),
            decimals: None,
            condition: Condition::CommLost,
            on_delay: Duration::from_secs_f64(*d.comm_alarm.on_delay_s.get_ref()),
            off_delay: Duration::from_secs_f64(*d.comm_alarm.off_delay_s.get_ref()),
        });
    }
    Ok(defs)
}

fn tag_defs(
    tag: &TagConfig,
    a: &AlarmConfig,
    decimals: Option<u8>,
    defs: &mut Vec<AlarmDef>,
) -> Result<(), AlarmError> {
    let source = AlarmSource {
        name: tag.name.get_ref(),
        units: &tag.units,
        description: &tag.description,
        device: Some(tag.device.get_ref()),
        states: tag.states.as_ref().map(|s| Arc::new(s.get_ref().clone())),
        decimals,
    };
    defs.extend(tag_alarm_defs(&source, a)?);
    Ok(())
}

/// The tag an alarm configuration belongs to: what its alarms need to know
/// of it.
pub struct AlarmSource<'a> {
    pub name: &'a str,
    pub units: &'a str,
    pub description: &'a str,
    /// The device the tag is read from (a local tag), if any.
    pub device: Option<&'a str>,
    pub states: Option<Arc<std::collections::BTreeMap<String, String>>>,
    /// The decimals its values are shown with (see `AlarmDef::decimals`).
    pub decimals: Option<u8>,
}

/// The limit and discrete alarms of one tag's `[tag.alarm]`: for a plant's
/// own tags, and for a central Sparkplug host's remote tags, whose edge
/// carries the same configuration in its births.
pub fn tag_alarm_defs(tag: &AlarmSource, a: &AlarmConfig) -> Result<Vec<AlarmDef>, AlarmError> {
    let mut defs = Vec::new();
    let name = tag.name;
    let default_selection = a
        .selection
        .clone()
        .unwrap_or_else(|| first_segment(name).to_owned());
    let limits: [(AlarmKind, &Option<LimitAlarm>); 4] = [
        (AlarmKind::HiHi, &a.hihi),
        (AlarmKind::Hi, &a.hi),
        (AlarmKind::Lo, &a.lo),
        (AlarmKind::LoLo, &a.lolo),
    ];
    for (kind, l) in limits {
        let Some(l) = l else { continue };
        let key = limit_key(name, kind);
        let limit = *l.limit.get_ref();
        let deadband = *l.deadband.get_ref();
        let condition = match kind {
            AlarmKind::HiHi | AlarmKind::Hi => Condition::Above { limit, deadband },
            _ => Condition::Below { limit, deadband },
        };
        defs.push(AlarmDef {
            on_delay: secs(
                &format!("alarm '{key}' on_delay_s"),
                *l.on_delay_s.get_ref(),
            )?,
            off_delay: secs(
                &format!("alarm '{key}' off_delay_s"),
                *l.off_delay_s.get_ref(),
            )?,
            key,
            tag: Some(name.to_owned()),
            kind,
            priority: l.priority,
            selection: l
                .selection
                .clone()
                .unwrap_or_else(|| default_selection.clone()),
            message: l
                .message
                .clone()
                .unwrap_or_else(|| default_limit_message(kind, tag.units)),
            units: tag.units.to_owned(),
            device: tag.device.map(str::to_owned),
            states: tag.states.clone(),
            decimals: tag.decimals,
            condition,
        });
    }
    for (i, d) in a.discrete.iter().enumerate() {
        let key = discrete_key(name, i);
        let when = match d.when.get_ref() {
            toml::Value::Boolean(b) => Value::Bool(*b),
            toml::Value::Integer(i) => Value::Int(*i),
            toml::Value::Float(f) => Value::Float(*f),
            toml::Value::String(s) => Value::Str(s.as_str().into()),
            other => {
                return Err(AlarmError::invalid(
                    format!("alarm '{key}'"),
                    format!("'when = {other}' must be a boolean, number or string"),
                ))
            }
        };
        let message = d.message.clone().unwrap_or_else(|| {
            if tag.description.trim().is_empty() {
                "{tag} = {value}".to_owned()
            } else {
                format!("{{tag}} ({}) = {{value}}", tag.description.trim())
            }
        });
        defs.push(AlarmDef {
            on_delay: secs(
                &format!("alarm '{key}' on_delay_s"),
                *d.on_delay_s.get_ref(),
            )?,
            off_delay: secs(
                &format!("alarm '{key}' off_delay_s"),
                *d.off_delay_s.get_ref(),
            )?,
            key,
            tag: Some(name.to_owned()),
            kind: AlarmKind::Discrete,
            priority: d.priority,
            selection: d
                .selection
                .clone()
                .unwrap_or_else(|| default_selection.clone()),
            message,
            units: tag.units.to_owned(),
            device: tag.device.map(str::to_owned),
            states: tag.states.clone(),
            decimals: tag.decimals,
            condition: Condition::Equals(when),
        });
    }
    Ok(defs)
}

fn default_limit_message(kind: AlarmKind, units: &str) -> String {
    let what = match kind {
        AlarmKind::HiHi => "very high",
        AlarmKind::Hi => "high",
        AlarmKind::Lo => "low",
        _ => "very low",
    };
    if units.trim().is_empty() {
        format!("{{tag}} {what}: {{value}} (limit {{limit}})")
    } else {
        format!("{{tag}} {what}: {{value}} {{units}} (limit {{limit}} {{units}})")
    }
}

/// Formats a value as messages do (exposed for the web layer's tables).
pub fn display_value(v: &Value) -> String {
    format_value(v, None)
}
