//! A tag's alarms: limit and discrete alarms, their priorities, deadbands
//! and on/off delays.

use gridscada_tagdb::ValueKind;
use serde_spanned::Spanned;

use crate::model::*;

use super::Ctx;

pub(super) fn check_alarms(
    cx: &mut Ctx<'_>,
    f: usize,
    name: &str,
    kind: ValueKind,
    a: &AlarmConfig,
) {
    let limits = [
        ("lolo", &a.lolo),
        ("lo", &a.lo),
        ("hi", &a.hi),
        ("hihi", &a.hihi),
    ];
    let present: Vec<(&str, &LimitAlarm)> = limits
        .iter()
        .filter_map(|(n, l)| l.as_ref().map(|l| (*n, l)))
        .collect();
    if !present.is_empty() && matches!(kind, ValueKind::Bool | ValueKind::Str) {
        cx.err(
            f,
            present[0].1.limit.span(),
            format!("tag '{name}': limit alarms need a numeric tag; use [[tag.alarm.discrete]] for states"),
        );
    }
    for (n, l) in &present {
        if !l.limit.get_ref().is_finite() {
            cx.err(
                f,
                l.limit.span(),
                format!("tag '{name}': {n} limit must be a finite number"),
            );
        }
        if *l.deadband.get_ref() < 0.0 {
            cx.err(
                f,
                l.deadband.span(),
                format!("tag '{name}': {n} deadband must not be negative"),
            );
        }
        delays(cx, f, name, n, &l.on_delay_s, &l.off_delay_s);
    }
    for w in present.windows(2) {
        let ((ln, lo), (hn, hi)) = (w[0], w[1]);
        if lo.limit.get_ref() >= hi.limit.get_ref() {
            cx.err(
                f,
                hi.limit.span(),
                format!(
                    "tag '{name}': alarm limits must be ordered LoLo < Lo < Hi < HiHi, but {ln} = {} is not below {hn} = {}",
                    lo.limit.get_ref(),
                    hi.limit.get_ref()
                ),
            );
        }
    }
    for d in &a.discrete {
        let ok = matches!(
            (kind, d.when.get_ref()),
            (ValueKind::Bool, toml::Value::Boolean(_))
                | (ValueKind::Int | ValueKind::Float, toml::Value::Integer(_))
                | (ValueKind::Str, toml::Value::String(_))
        );
        if !ok {
            cx.err(
                f,
                d.when.span(),
                format!("tag '{name}': discrete alarm 'when = {}' does not match the tag's {kind:?} values", d.when.get_ref()),
            );
        }
        delays(cx, f, name, "discrete", &d.on_delay_s, &d.off_delay_s);
    }
}

pub(super) fn delays(
    cx: &mut Ctx<'_>,
    f: usize,
    name: &str,
    which: &str,
    on: &Spanned<f64>,
    off: &Spanned<f64>,
) {
    for (field, v) in [("on_delay_s", on), ("off_delay_s", off)] {
        if !(v.get_ref().is_finite() && *v.get_ref() >= 0.0) {
            cx.err(
                f,
                v.span(),
                format!("tag '{name}': {which} {field} must be zero or more seconds"),
            );
        }
    }
}

/// `[[suppression]]` rules: a unique name, a trigger that is a configured
/// alarm, and targets that each match at least one configured alarm (a rule
/// that suppresses nothing is a typo, not a rule).
pub(super) fn check_suppression<'t>(
    cx: &mut Ctx<'_>,
    rules: &[SuppressionConfig],
    tags: &[(usize, TagConfig)],
    lookup: &dyn Fn(&str) -> Option<&'t TagConfig>,
    device_exists: &dyn Fn(&str) -> bool,
) {
    let mut names: std::collections::HashMap<&str, &Spanned<String>> = Default::default();
    for r in rules {
        let name = r.name.get_ref().as_str();
        let owner = format!("suppression '{name}'");
        if name.trim().is_empty() {
            cx.err(0, r.name.span(), "suppression: name must not be empty");
        } else if let Some(prev) = names.insert(name, &r.name) {
            let first = cx.place(0, prev.span());
            cx.err(
                0,
                r.name.span(),
                format!("duplicate suppression name '{name}' (first defined at {first})"),
            );
        }
        if let Err(why) = trigger_exists(r.trigger.get_ref(), lookup, device_exists) {
            cx.err(0, r.trigger.span(), format!("{owner}: trigger: {why}"));
        }
        let delay = *r.release_delay_s.get_ref();
        if !(delay.is_finite() && (0.0..=3600.0).contains(&delay)) {
            cx.err(
                0,
                r.release_delay_s.span(),
                format!("{owner}: release_delay_s must be 0 to 3600 seconds"),
            );
        }
        if r.suppress.get_ref().is_empty() {
            cx.err(
                0,
                r.suppress.span(),
                format!("{owner}: suppress is empty; name the alarms to suppress, e.g. [{{ tag_prefix = \"P1.Zone\" }}]"),
            );
        }
        for t in r.suppress.get_ref() {
            let mut kinds = Vec::new();
            for k in &t.kinds {
                if SUPPRESSIBLE_KINDS.contains(&k.get_ref().as_str()) {
                    kinds.push(k.get_ref().as_str());
                } else {
                    cx.err(
                        0,
                        k.span(),
                        format!(
                            "{owner}: unknown alarm kind '{}'; expected one of {}",
                            k.get_ref(),
                            SUPPRESSIBLE_KINDS.join(", ")
                        ),
                    );
                }
            }
            if kinds.len() != t.kinds.len() {
                continue;
            }
            let prefix = t.tag_prefix.get_ref();
            let matched = tags.iter().any(|(_, tag)| {
                tag.name.get_ref().starts_with(prefix.as_str())
                    && tag.alarm.as_ref().is_some_and(|a| has_kind(a, &kinds))
            });
            if prefix.is_empty() {
                cx.err(
                    0,
                    t.tag_prefix.span(),
                    format!("{owner}: tag_prefix is empty; it would suppress every alarm"),
                );
            } else if !matched {
                let what = if kinds.is_empty() {
                    "alarm".to_string()
                } else {
                    format!("{} alarm", kinds.join("/"))
                };
                cx.err(
                    0,
                    t.tag_prefix.span(),
                    format!("{owner}: no tag starting with '{prefix}' has a {what}; this target suppresses nothing"),
                );
            }
        }
    }
}

/// Whether `a` has an alarm of one of `kinds` (any when empty).
fn has_kind(a: &AlarmConfig, kinds: &[&str]) -> bool {
    let present = [
        ("hihi", a.hihi.is_some()),
        ("hi", a.hi.is_some()),
        ("lo", a.lo.is_some()),
        ("lolo", a.lolo.is_some()),
        ("discrete", !a.discrete.is_empty()),
    ];
    present
        .iter()
        .any(|(k, p)| *p && (kinds.is_empty() || kinds.contains(k)))
}

/// Checks that a trigger key names a configured alarm; the reason when not.
fn trigger_exists<'t>(
    key: &str,
    lookup: &dyn Fn(&str) -> Option<&'t TagConfig>,
    device_exists: &dyn Fn(&str) -> bool,
) -> Result<(), String> {
    let forms = "write TAG:discrete, TAG:hihi, TAG:hi, TAG:lo, TAG:lolo or DEVICE:comm";
    let Some((owner, suffix)) = key.rsplit_once(':') else {
        return Err(format!("'{key}' is not an alarm key; {forms}"));
    };
    if suffix == "comm" {
        return if device_exists(owner) {
            Ok(())
        } else {
            Err(format!("no device '{owner}' for '{key}'"))
        };
    }
    let Some(tag) = lookup(owner) else {
        return Err(format!("no tag '{owner}' for '{key}'; {forms}"));
    };
    let none = AlarmConfig::default();
    let a = tag.alarm.as_deref().unwrap_or(&none);
    let present = match suffix {
        "hihi" => a.hihi.is_some(),
        "hi" => a.hi.is_some(),
        "lo" => a.lo.is_some(),
        "lolo" => a.lolo.is_some(),
        "discrete" => !a.discrete.is_empty(),
        s => match s
            .strip_prefix("discrete")
            .and_then(|n| n.parse::<usize>().ok())
        {
            Some(n) if n >= 2 => a.discrete.len() >= n,
            _ => return Err(format!("'{key}': unknown alarm '{s}'; {forms}")),
        },
    };
    if present {
        Ok(())
    } else {
        Err(format!("tag '{owner}' has no {suffix} alarm"))
    }
}
