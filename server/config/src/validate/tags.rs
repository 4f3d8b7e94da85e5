//! Each tag on its own: its name, its register, bit and length against its
//! device, scaling, write access and limits, states and history logging
//! (its alarms are in `alarms.rs`).

use gridscada_tagdb::ValueKind;
use serde_spanned::Spanned;

use crate::model::*;

use super::alarms::check_alarms;
use super::Ctx;

pub(super) fn check_tag_name(cx: &mut Ctx<'_>, f: usize, name: &Spanned<String>) {
    let n = name.get_ref();
    let valid_chars = n
        .chars()
        .all(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.'));
    if n.is_empty() || !valid_chars || n.starts_with('.') || n.ends_with('.') || n.contains("..") {
        cx.err(
            f,
            name.span(),
            format!("tag name '{n}' is not valid: use letters, digits, '_' and '-', in parts separated by single dots (e.g. SS1.Zone2.Closed)"),
        );
    }
}

pub(super) fn check_tag(cx: &mut Ctx<'_>, f: usize, t: &TagConfig, device: Option<&DeviceConfig>) {
    let name = t.name.get_ref();
    let kind = *t.kind.get_ref();
    let ty = t.data_type();
    if kind.is_bit() {
        if let Some(dt) = &t.data_type {
            if *dt.get_ref() != DataType::Bool {
                cx.err(
                    f,
                    dt.span(),
                    format!(
                        "tag '{name}': a {} holds one bit, so its type must be bool, not {}",
                        kind.label(),
                        dt.get_ref().label()
                    ),
                );
            }
        }
        if let Some(b) = &t.bit {
            cx.err(
                f,
                b.span(),
                format!(
                    "tag '{name}': bit is only for bool tags on registers, not on a {}",
                    kind.label()
                ),
            );
        }
    } else if let Some(b) = &t.bit {
        if *b.get_ref() > 15 {
            cx.err(
                f,
                b.span(),
                format!("tag '{name}': bit {} is outside 0..=15", b.get_ref()),
            );
        }
        if ty != DataType::Bool {
            let at = t.data_type.as_ref().map(|d| d.span()).unwrap_or(b.span());
            cx.err(
                f,
                at,
                format!(
                    "tag '{name}': a bit within a register is bool, not {}",
                    ty.label()
                ),
            );
        }
    }
    match (&t.length, ty) {
        (None, DataType::String) => cx.err(
            f,
            t.name.span(),
            format!("tag '{name}': a string tag needs length (registers, two characters each)"),
        ),
        (Some(l), DataType::String) if !(1..=125).contains(l.get_ref()) => cx.err(
            f,
            l.span(),
            format!("tag '{name}': length must be 1 to 125 registers"),
        ),
        (Some(l), t2) if t2 != DataType::String => cx.err(
            f,
            l.span(),
            format!(
                "tag '{name}': length is only for string tags, not {}",
                t2.label()
            ),
        ),
        _ => {}
    }
    let width = t.width().max(1) as u32;
    let addr = *t.address.get_ref();
    if addr + width - 1 > 65_535 {
        cx.err(
            f,
            t.address.span(),
            format!(
                "tag '{name}': address {addr} with {width} {} runs past 65535",
                if kind.is_bit() { "bits" } else { "registers" }
            ),
        );
    }
    if let Some(d) = device {
        let max = if kind.is_bit() {
            *d.max_read_bits.get_ref()
        } else {
            *d.max_read_registers.get_ref()
        } as u32;
        if width > max {
            cx.err(f, t.name.span(), format!("tag '{name}': {width} registers do not fit in one request to device '{}' (max {max})", d.name.get_ref()));
        }
    }
    let scale = *t.scale.get_ref();
    if scale == 0.0 || !scale.is_finite() {
        cx.err(
            f,
            t.scale.span(),
            format!("tag '{name}': scale must be a non-zero number"),
        );
    }
    if (scale != 1.0 || t.offset != 0.0)
        && matches!(ty, DataType::Bool | DataType::String | DataType::DateTime)
    {
        cx.err(
            f,
            t.scale.span(),
            format!(
                "tag '{name}': scale and offset apply to numbers, not {}",
                ty.label()
            ),
        );
    }
    if let Some(s) = &t.scan_ms {
        if *s.get_ref() < 10 {
            cx.err(
                f,
                s.span(),
                format!("tag '{name}': scan_ms must be at least 10"),
            );
        }
    }
    // Writes.
    let writable = *t.writable.get_ref();
    if let Some(states) = &t.states {
        let kind = t.value_kind();
        for (key, label) in states.get_ref() {
            let key_ok = match kind {
                ValueKind::Bool => key == "true" || key == "false",
                ValueKind::Int => key.parse::<i64>().is_ok(),
                _ => false,
            };
            if !key_ok {
                let want = match kind {
                    ValueKind::Bool => "true or false",
                    ValueKind::Int => "whole numbers",
                    _ => "nothing: states are for bool and integer tags",
                };
                cx.err(
                    f,
                    states.span(),
                    format!("tag '{name}': states key '{key}' is not a value of this tag (keys are {want})"),
                );
            }
            if label.trim().is_empty()
                || label.chars().count() > 40
                || label.chars().any(char::is_control)
            {
                cx.err(
                    f,
                    states.span(),
                    format!(
                        "tag '{name}': states label for {key} must be 1 to 40 printable characters"
                    ),
                );
            }
        }
    }
    if writable && ty == DataType::DateTime {
        cx.err(
            f,
            t.writable.span(),
            format!("tag '{name}': a datetime is a device clock, read-only; it cannot be writable"),
        );
    }
    if writable && !kind.is_writable() {
        cx.err(f, t.writable.span(), format!("tag '{name}': a {} is read-only in Modbus; only coils and holding registers can be writable", kind.label()));
    }
    match (&t.write_role, writable) {
        (None, true) => cx.err(f, t.writable.span(), format!("tag '{name}': writable tags need write_role (operator, supervisor or administrator)")),
        (Some(r), true) if *r.get_ref() == Role::Guest => {
            cx.err(f, r.span(), format!("tag '{name}': guests may not command the plant; write_role must be operator or above"))
        }
        (Some(r), false) => cx.err(f, r.span(), format!("tag '{name}': write_role is set but the tag is not writable")),
        _ => {}
    }
    for limit in [&t.min, &t.max].into_iter().flatten() {
        if !writable {
            cx.err(
                f,
                limit.span(),
                format!("tag '{name}': min and max are write limits; the tag is not writable"),
            );
        } else if !matches!(
            t.value_kind(),
            gridscada_tagdb::ValueKind::Int | gridscada_tagdb::ValueKind::Float
        ) {
            cx.err(
                f,
                limit.span(),
                format!("tag '{name}': min and max apply to numeric tags only"),
            );
        } else if !limit.get_ref().is_finite() {
            cx.err(
                f,
                limit.span(),
                format!("tag '{name}': a limit must be a finite number"),
            );
        }
    }
    if let (Some(lo), Some(hi)) = (&t.min, &t.max) {
        if lo.get_ref() > hi.get_ref() {
            cx.err(
                f,
                hi.span(),
                format!(
                    "tag '{name}': max {} is below min {}",
                    hi.get_ref(),
                    lo.get_ref()
                ),
            );
        }
    }
    if let Some(a) = &t.alarm {
        check_alarms(cx, f, name, t.value_kind(), a);
    }
    let h = &t.history;
    if *h.deadband.get_ref() < 0.0 {
        cx.err(
            f,
            h.deadband.span(),
            format!("tag '{name}': history deadband must not be negative"),
        );
    }
    if *h.max_interval_s.get_ref() <= 0.0 {
        cx.err(
            f,
            h.max_interval_s.span(),
            format!("tag '{name}': history max_interval_s must be positive"),
        );
    }
}
