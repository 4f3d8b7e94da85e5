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
