//! Each tag on its own: its name, its register, bit and length against its
//! device, scaling, write access and limits, states and history logging
//! (its alarms are in `alarms.rs`).

use std::ops::Range;

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
    // Where the tag is read: a Modbus register or an IEC 104 point, as its
    // device's protocol asks. An unknown device is judged by what the tag has.
    let protocol = match device {
        Some(d) => Some(d.protocol),
        None if t.iec104.is_some() => Some(Protocol::Iec104),
        None if t.dnp3.is_some() => Some(Protocol::Dnp3),
        None if t.iec61850.is_some() => Some(Protocol::Iec61850),
        None => None,
    };
    if protocol != Some(Protocol::Iec61850) {
        if let Some(p) = &t.iec61850 {
            cx.err(
                f,
                p.reference.span(),
                format!(
                    "tag '{}': iec61850 is for tags of protocol = \"iec61850\" devices, and device '{}' is not one",
                    t.name.get_ref(),
                    t.device.get_ref()
                ),
            );
        }
    }
    if protocol != Some(Protocol::Dnp3) {
        if let Some(p) = &t.dnp3 {
            cx.err(
                f,
                p.point.span(),
                format!(
                    "tag '{}': dnp3 is for tags of protocol = \"dnp3\" devices, and device '{}' is not one",
                    t.name.get_ref(),
                    t.device.get_ref()
                ),
            );
        }
    }
    if protocol == Some(Protocol::Iec104) {
        check_iec104_point(cx, f, t, device);
    } else if protocol == Some(Protocol::Dnp3) {
        check_dnp3_point(cx, f, t, device);
    } else if protocol == Some(Protocol::Iec61850) {
        super::iec61850::check_iec61850_point(cx, f, t, device);
    } else {
        check_modbus_register(cx, f, t, device);
    }
    check_tag_common(cx, f, t);
}

/// A Modbus tag's table, address, bit, type, length and write access.
fn check_modbus_register(cx: &mut Ctx<'_>, f: usize, t: &TagConfig, device: Option<&DeviceConfig>) {
    let name = t.name.get_ref();
    let ty = t.data_type();
    if let Some(p) = &t.iec104 {
        cx.err(
            f,
            p.ioa.span(),
            format!(
                "tag '{name}': iec104 is for tags of protocol = \"iec104\" devices, and device '{}' is Modbus",
                t.device.get_ref()
            ),
        );
    }
    let (Some(kind), Some(address)) = (&t.kind, &t.address) else {
        cx.err(
            f,
            t.name.span(),
            format!(
                "tag '{name}': a tag of a Modbus device needs kind (coil, discrete_input, input_register or holding_register) and address"
            ),
        );
        return;
    };
    let kind = *kind.get_ref();
    let addr = *address.get_ref();
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
    if addr + width - 1 > 65_535 {
        cx.err(
            f,
            address.span(),
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
    if *t.writable.get_ref() && !kind.is_writable() {
        cx.err(f, t.writable.span(), format!("tag '{name}': a {} is read-only in Modbus; only coils and holding registers can be writable", kind.label()));
    }
}

/// An IEC 104 tag's point: information object addresses, the type its
/// values arrive as and the tag's type, the command of a writable tag.
fn check_iec104_point(cx: &mut Ctx<'_>, f: usize, t: &TagConfig, device: Option<&DeviceConfig>) {
    let name = t.name.get_ref();
    let ty = t.data_type();
    let device_name = t.device.get_ref();
    for (field, span) in [
        ("kind", t.kind.as_ref().map(|k| k.span())),
        ("address", t.address.as_ref().map(|a| a.span())),
        ("bit", t.bit.as_ref().map(|b| b.span())),
        ("length", t.length.as_ref().map(|l| l.span())),
    ] {
        if let Some(span) = span {
            cx.err(
                f,
                span,
                format!("tag '{name}': {field} is a Modbus setting; device '{device_name}' speaks IEC 104 (use iec104 = {{ ioa = …, point = … }})"),
            );
        }
    }
    let Some(p) = &t.iec104 else {
        if device.is_some() {
            cx.err(
                f,
                t.name.span(),
                format!("tag '{name}': a tag of IEC 104 device '{device_name}' needs iec104 = {{ ioa = …, point = \"M_SP\" }}"),
            );
        }
        return;
    };
    for ioa in std::iter::once(&p.ioa).chain(p.command_ioa.as_ref()) {
        if !(1..=0xFF_FFFF).contains(ioa.get_ref()) {
            cx.err(
                f,
                ioa.span(),
                format!(
                    "tag '{name}': information object address {} is outside 1..16777215",
                    ioa.get_ref()
                ),
            );
        }
    }
    let point = *p.point.get_ref();
    check_point_and_command(
        cx,
        f,
        t,
        PointAndCommand {
            point: format!("a {} point", point.label()),
            point_carries: point.carries(ty),
            point_span: p.point.span(),
            default_type: point.default_type(),
            command: p.command.as_ref().map(|c| CommandOfTag {
                label: c.get_ref().label(),
                carries: c.get_ref().carries(ty),
                span: c.span(),
                hint: "",
            }),
            command_needed: "a writable IEC 104 tag needs command (C_SC, C_DC, C_RC, C_SE_NA, C_SE_NB, C_SE_NC or C_BO)",
        },
    );
    if p.command.is_none() && (p.select || p.command_ioa.is_some()) {
        cx.err(
            f,
            p.ioa.span(),
            format!("tag '{name}': select and command_ioa are for a tag with a command"),
        );
    }
    let qualifier = *p.qualifier.get_ref();
    let max = match p.command.as_ref().map(|c| *c.get_ref()) {
        Some(Iec104Command::C_SC | Iec104Command::C_DC | Iec104Command::C_RC) => 31,
        Some(Iec104Command::C_SE_NA | Iec104Command::C_SE_NB | Iec104Command::C_SE_NC) => 127,
        _ => 0,
    };
    if qualifier > max {
        cx.err(
            f,
            p.qualifier.span(),
            format!("tag '{name}': qualifier {qualifier} is outside 0..={max} for this command"),
        );
    }
}

/// A DNP3 tag's point: the point type and the tag's type, the command of
/// a writable tag and the keys that go with it.
fn check_dnp3_point(cx: &mut Ctx<'_>, f: usize, t: &TagConfig, device: Option<&DeviceConfig>) {
    let name = t.name.get_ref();
    let ty = t.data_type();
    let device_name = t.device.get_ref();
    for (field, span) in [
        ("kind", t.kind.as_ref().map(|k| k.span())),
        ("address", t.address.as_ref().map(|a| a.span())),
        ("bit", t.bit.as_ref().map(|b| b.span())),
        ("length", t.length.as_ref().map(|l| l.span())),
    ] {
        if let Some(span) = span {
            cx.err(
                f,
                span,
                format!("tag '{name}': {field} is a Modbus setting; device '{device_name}' speaks DNP3 (use dnp3 = {{ point = …, index = … }})"),
            );
        }
    }
    if let Some(p) = &t.iec104 {
        cx.err(
            f,
            p.ioa.span(),
            format!("tag '{name}': iec104 is for tags of protocol = \"iec104\" devices; device '{device_name}' speaks DNP3"),
        );
    }
    let Some(p) = &t.dnp3 else {
        if device.is_some() {
            cx.err(
                f,
                t.name.span(),
                format!("tag '{name}': a tag of DNP3 device '{device_name}' needs dnp3 = {{ point = \"binary_input\", index = … }}"),
            );
        }
        return;
    };
    let point = *p.point.get_ref();
    check_point_and_command(
        cx,
        f,
        t,
        PointAndCommand {
            point: format!("a DNP3 {} point", point.label()),
            point_carries: point.carries(ty),
            point_span: p.point.span(),
            default_type: point.default_type(),
            command: p.command.as_ref().map(|c| CommandOfTag {
                label: c.get_ref().label(),
                carries: c.get_ref().carries(ty),
                span: c.span(),
                hint: if *c.get_ref() == Dnp3Command::Crob {
                    " (a CROB commands a bool tag)"
                } else {
                    ""
                },
            }),
            command_needed: "a writable DNP3 tag needs command (crob or analog_output)",
        },
    );
    let command = p.command.as_ref().map(|c| *c.get_ref());
    if command.is_none() {
        if let Some(at) = p.command_index.as_ref().map(|c| c.span()) {
            cx.err(
                f,
                at,
                format!("tag '{name}': command_index is for a tag with a command"),
            );
        }
        if p.select {
            cx.err(
                f,
                p.point.span(),
                format!("tag '{name}': select is for a tag with a command"),
            );
        }
    }
    if command != Some(Dnp3Command::Crob) {
        for (field, span) in [
            ("op", p.op.as_ref().map(|o| o.span())),
            ("on_ms", p.on_ms.as_ref().map(|o| o.span())),
            ("off_ms", p.off_ms.as_ref().map(|o| o.span())),
        ] {
            if let Some(span) = span {
                cx.err(
                    f,
                    span,
                    format!("tag '{name}': {field} belongs to a CROB (command = \"crob\")"),
                );
            }
        }
    } else {
        let op = p.op();
        let allowed: &[&str] = match op {
            Dnp3Op::Latch => &[],
            Dnp3Op::Pulse => &["on_ms", "off_ms"],
            Dnp3Op::TripClose => &["on_ms"],
        };
        for (field, span) in [
            ("on_ms", p.on_ms.as_ref().map(|o| o.span())),
            ("off_ms", p.off_ms.as_ref().map(|o| o.span())),
        ] {
            if let (Some(span), false) = (span, allowed.contains(&field)) {
                cx.err(
                    f,
                    span,
                    format!(
                        "tag '{name}': {field} does not apply to op = \"{}\"",
                        op.label()
                    ),
                );
            }
        }
    }
}

/// A telecontrol tag's point and command, as the checks that IEC 104 and
/// DNP3 tags share see them.
struct PointAndCommand {
    /// "a M_ME_NC_1 point", "a DNP3 analog_input point".
    point: String,
    point_carries: bool,
    point_span: Range<usize>,
    default_type: DataType,
    command: Option<CommandOfTag>,
    /// The error of a writable tag without a command.
    command_needed: &'static str,
}

struct CommandOfTag {
    label: &'static str,
    carries: bool,
    span: Range<usize>,
    /// Said after "cannot carry a … value".
    hint: &'static str,
}

/// The point carries the tag's type; a command only on a writable tag, and
/// one that carries its type; a writable tag has a command.
fn check_point_and_command(cx: &mut Ctx<'_>, f: usize, t: &TagConfig, p: PointAndCommand) {
    let name = t.name.get_ref();
    let ty = t.data_type();
    if !p.point_carries {
        let at = t
            .data_type
            .as_ref()
            .map(|d| d.span())
            .unwrap_or(p.point_span);
        cx.err(
            f,
            at,
            format!(
                "tag '{name}': {} cannot carry a {} value (use type = \"{}\")",
                p.point,
                ty.label(),
                p.default_type.label()
            ),
        );
    }
    let writable = *t.writable.get_ref();
    match p.command {
        Some(c) if !writable => cx.err(
            f,
            c.span,
            format!(
                "tag '{name}': command {} is set on a read-only tag (set writable = true and write_role)",
                c.label
            ),
        ),
        Some(c) if !c.carries => cx.err(
            f,
            c.span,
            format!(
                "tag '{name}': command {} cannot carry a {} value{}",
                c.label,
                ty.label(),
                c.hint
            ),
        ),
        None if writable => cx.err(
            f,
            t.writable.span(),
            format!("tag '{name}': {}", p.command_needed),
        ),
        _ => {}
    }
}

/// What every tag is checked for, whatever its protocol.
fn check_tag_common(cx: &mut Ctx<'_>, f: usize, t: &TagConfig) {
    let name = t.name.get_ref();
    let ty = t.data_type();
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
    if let Some(d) = &t.decimals {
        if !matches!(t.value_kind(), ValueKind::Int | ValueKind::Float) {
            cx.err(
                f,
                d.span(),
                format!("tag '{name}': decimals apply to numeric tags only"),
            );
        } else if !(0..=i64::from(MAX_DECIMALS)).contains(d.get_ref()) {
            cx.err(
                f,
                d.span(),
                format!(
                    "tag '{name}': decimals {} must be 0 to {MAX_DECIMALS}",
                    d.get_ref()
                ),
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
