//! Semantic checks across the whole configuration.

use std::collections::{BTreeMap, HashMap};
use std::net::SocketAddr;
use std::ops::Range;

use gridscada_tagdb::ValueKind;
use serde_spanned::Spanned;

use crate::diag::{Diagnostic, SourceFile};
use crate::model::*;

struct Ctx<'a> {
    files: &'a [SourceFile],
    diags: &'a mut Vec<Diagnostic>,
}

impl Ctx<'_> {
    fn err(&mut self, file: usize, span: Range<usize>, msg: impl Into<String>) {
        let d = self.files[file].error_at(span, msg);
        self.diags.push(d);
    }
    fn place(&self, file: usize, span: Range<usize>) -> String {
        let f = &self.files[file];
        let (l, c) = f.line_col(span.start);
        format!("{}:{l}:{c}", f.path.display())
    }
}

/// `files[0]` is the main file; items carry the index of their file.
pub(crate) fn check(
    files: &[SourceFile],
    main: &MainFile,
    devices: &[(usize, DeviceConfig)],
    broken_devices: &std::collections::HashSet<String>,
    tags: &[(usize, TagConfig)],
    diags: &mut Vec<Diagnostic>,
) {
    let mut cx = Ctx { files, diags };
    check_main(&mut cx, main);

    let mut device_by_name: HashMap<&str, (usize, &DeviceConfig)> = HashMap::new();
    for (f, d) in devices {
        check_device(&mut cx, *f, d);
        let name = d.name.get_ref().as_str();
        if let Some((pf, prev)) = device_by_name.get(name) {
            let first = cx.place(*pf, prev.name.span());
            cx.err(
                *f,
                d.name.span(),
                format!("duplicate device name '{name}' (first defined at {first})"),
            );
        } else {
            device_by_name.insert(name, (*f, d));
        }
    }

    let mut tag_by_name: HashMap<&str, (usize, &TagConfig)> = HashMap::new();
    for (f, t) in tags {
        let name = t.name.get_ref().as_str();
        check_tag_name(&mut cx, *f, &t.name);
        if let Some((pf, prev)) = tag_by_name.get(name) {
            let first = cx.place(*pf, prev.name.span());
            cx.err(
                *f,
                t.name.span(),
                format!("duplicate tag name '{name}' (first defined at {first})"),
            );
        } else {
            tag_by_name.insert(name, (*f, t));
        }
        match device_by_name.get(t.device.get_ref().as_str()) {
            Some((_, d)) => check_tag(&mut cx, *f, t, Some(d)),
            // Its device did not parse: that is reported once, at the device.
            None if broken_devices.contains(t.device.get_ref()) => check_tag(&mut cx, *f, t, None),
            None => {
                cx.err(
                    *f,
                    t.device.span(),
                    format!("tag '{name}': unknown device '{}'", t.device.get_ref()),
                );
                check_tag(&mut cx, *f, t, None);
            }
        }
    }
    check_overlaps(&mut cx, tags);
    check_time_tags(&mut cx, devices, tags, &device_by_name, &tag_by_name);

    let lookup = |name: &str| tag_by_name.get(name).map(|(_, t)| *t);
    let device = |name: &str| device_by_name.get(name).map(|(_, d)| *d);
    let mut panel_ids: HashMap<&str, &Spanned<String>> = HashMap::new();
    for p in &main.panels {
        if let Some(prev) = panel_ids.insert(p.id.get_ref(), &p.id) {
            let first = cx.place(0, prev.span());
            cx.err(
                0,
                p.id.span(),
                format!(
                    "duplicate panel id '{}' (first defined at {first})",
                    p.id.get_ref()
                ),
            );
        }
        check_panel(&mut cx, p, &lookup, &device);
    }
    if let Some(mg) = &main.microgrid {
        check_microgrid(&mut cx, mg, &lookup);
    }
}

fn check_main(cx: &mut Ctx<'_>, main: &MainFile) {
    let http = &main.server.http;
    if http.get_ref().parse::<SocketAddr>().is_err() {
        cx.err(
            0,
            http.span(),
            format!(
                "[server] http: '{}' is not an address like 127.0.0.1:8080",
                http.get_ref()
            ),
        );
    }
    let url = &main.storage.url;
    let u = url.get_ref();
    if !(u.starts_with("sqlite:") || u.starts_with("postgres://") || u.starts_with("postgresql://"))
    {
        cx.err(
            0,
            url.span(),
            format!("[storage] url: '{u}' must start with sqlite:, postgres:// or postgresql://"),
        );
    }
    if main.tag_files.is_empty() {
        cx.err(
            0,
            0..0,
            "tag_files is empty: a plant needs at least one tag file",
        );
    }
}

fn check_device(cx: &mut Ctx<'_>, f: usize, d: &DeviceConfig) {
    let name = d.name.get_ref();
    let at = d.name.span();
    for (field, v) in [
        ("on_delay_s", &d.comm_alarm.on_delay_s),
        ("off_delay_s", &d.comm_alarm.off_delay_s),
    ] {
        if !(v.get_ref().is_finite() && (0.0..=3600.0).contains(v.get_ref())) {
            cx.err(
                f,
                v.span(),
                format!("device '{name}': comm_alarm {field} must be 0 to 3600 seconds"),
            );
        }
    }
    match d.protocol {
        Protocol::Tcp => {
            match &d.address {
                None => cx.err(
                    f,
                    at.clone(),
                    format!("device '{name}': a tcp device needs address = \"host:port\""),
                ),
                Some(a) => {
                    let ok = a.get_ref().rsplit_once(':').is_some_and(|(host, port)| {
                        !host.is_empty() && port.parse::<u16>().is_ok_and(|p| p > 0)
                    });
                    if !ok {
                        cx.err(
                            f,
                            a.span(),
                            format!(
                                "device '{name}': address '{}' is not host:port",
                                a.get_ref()
                            ),
                        );
                    }
                }
            }
            if d.serial.is_some() {
                cx.err(
                    f,
                    at.clone(),
                    format!("device '{name}': [device.serial] is only for protocol = \"rtu\""),
                );
            }
        }
        Protocol::Rtu => {
            match &d.serial {
                None => cx.err(
                    f,
                    at.clone(),
                    format!(
                        "device '{name}': an rtu device needs a [device.serial] table with port"
                    ),
                ),
                Some(s) => {
                    if !(5..=8).contains(s.data_bits.get_ref()) {
                        cx.err(
                            f,
                            s.data_bits.span(),
                            format!("device '{name}': data_bits must be 5 to 8"),
                        );
                    }
                    if !(1..=2).contains(s.stop_bits.get_ref()) {
                        cx.err(
                            f,
                            s.stop_bits.span(),
                            format!("device '{name}': stop_bits must be 1 or 2"),
                        );
                    }
                    if s.port.get_ref().is_empty() {
                        cx.err(
                            f,
                            s.port.span(),
                            format!("device '{name}': serial port is empty"),
                        );
                    }
                }
            }
            if let Some(a) = &d.address {
                cx.err(f, a.span(), format!("device '{name}': address is only for protocol = \"tcp\"; use [device.serial]"));
            }
            if !(1..=247).contains(d.unit_id.get_ref()) {
                cx.err(
                    f,
                    d.unit_id.span(),
                    format!("device '{name}': an rtu unit_id must be 1 to 247"),
                );
            }
        }
    }
    if *d.scan_ms.get_ref() < 10 {
        cx.err(
            f,
            d.scan_ms.span(),
            format!("device '{name}': scan_ms must be at least 10"),
        );
    }
    if *d.timeout_ms.get_ref() == 0 {
        cx.err(
            f,
            d.timeout_ms.span(),
            format!("device '{name}': timeout_ms must be positive"),
        );
    }
    if let Some(b) = &d.backoff_max_ms {
        if !(100..=600_000).contains(b.get_ref()) {
            cx.err(
                f,
                b.span(),
                format!("device '{name}': backoff_max_ms must be 100 to 600000"),
            );
        }
    }
    limit_range(
        cx,
        f,
        name,
        "max_read_registers",
        &d.max_read_registers,
        125,
    );
    limit_range(cx, f, name, "max_read_bits", &d.max_read_bits, 2000);
    limit_range(
        cx,
        f,
        name,
        "max_write_registers",
        &d.max_write_registers,
        123,
    );
}

fn limit_range(cx: &mut Ctx<'_>, f: usize, dev: &str, field: &str, v: &Spanned<u16>, max: u16) {
    if !(1..=max).contains(v.get_ref()) {
        cx.err(
            f,
            v.span(),
            format!(
                "device '{dev}': {field} = {} is outside 1..={max} (the Modbus limit)",
                v.get_ref()
            ),
        );
    }
}

fn check_tag_name(cx: &mut Ctx<'_>, f: usize, name: &Spanned<String>) {
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

fn check_tag(cx: &mut Ctx<'_>, f: usize, t: &TagConfig, device: Option<&DeviceConfig>) {
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

fn check_alarms(cx: &mut Ctx<'_>, f: usize, name: &str, kind: ValueKind, a: &AlarmConfig) {
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

fn delays(
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

/// Two tags on the same register (or bit) of the same device and table would
/// fight over it. Bits of one register are fine as long as they differ.
fn check_overlaps(cx: &mut Ctx<'_>, tags: &[(usize, TagConfig)]) {
    /// A tag's footprint: start, end (exclusive), bit, file, tag.
    type Span<'a> = (u32, u32, Option<u8>, usize, &'a TagConfig);
    let mut by_table: BTreeMap<(&str, RegisterKind), Vec<Span<'_>>> = BTreeMap::new();
    for (f, t) in tags {
        let start = *t.address.get_ref();
        let end = start + t.width().max(1) as u32;
        let bit = if t.kind.get_ref().is_bit() {
            None
        } else {
            t.bit.as_ref().map(|b| *b.get_ref())
        };
        by_table
            .entry((t.device.get_ref().as_str(), *t.kind.get_ref()))
            .or_default()
            .push((start, end, bit, *f, t));
    }
    for ((device, kind), mut list) in by_table {
        list.sort_by_key(|(s, e, b, _, _)| (*s, *e, *b));
        // Sweep: compare each tag with every earlier one still open.
        let mut open: Vec<Span<'_>> = Vec::new();
        for cur in list {
            open.retain(|o| o.1 > cur.0);
            for o in &open {
                let conflict = match (o.2, cur.2) {
                    (Some(a), Some(b)) => a == b,
                    // A bit and a whole register: reading a status word both
                    // ways is common, so only whole registers conflict.
                    (Some(_), None) | (None, Some(_)) => false,
                    (None, None) => true,
                };
                if conflict {
                    let first = cx.place(o.3, o.4.address.span());
                    cx.err(
                        cur.3,
                        cur.4.address.span(),
                        format!(
                            "tag '{}': {} {} on device '{device}' overlaps tag '{}' (at {first})",
                            cur.4.name.get_ref(),
                            kind.label(),
                            cur.0,
                            o.4.name.get_ref()
                        ),
                    );
                }
            }
            open.push(cur);
        }
    }
}

/// Device clocks: a `time_tag` (of a device, or of a tag) names a numeric or
/// `datetime` tag of the same device, read at the same scan period, so each
/// scan stamps its values with the clock it read with them.
fn check_time_tags(
    cx: &mut Ctx<'_>,
    devices: &[(usize, DeviceConfig)],
    tags: &[(usize, TagConfig)],
    device_by_name: &HashMap<&str, (usize, &DeviceConfig)>,
    tag_by_name: &HashMap<&str, (usize, &TagConfig)>,
) {
    let clock_problem = |clock: &TagConfig, device: &str| -> Option<String> {
        if clock.device.get_ref() != device {
            return Some(format!(
                "'{}' is a tag of device '{}', not of '{device}'",
                clock.name.get_ref(),
                clock.device.get_ref()
            ));
        }
        let ty = clock.data_type();
        if matches!(ty, DataType::Bool | DataType::String) || clock.bit.is_some() {
            return Some(format!(
                "'{}' is a {}; a device clock is a datetime or a number of Unix seconds",
                clock.name.get_ref(),
                ty.label()
            ));
        }
        None
    };
    for (f, d) in devices {
        let Some(tt) = &d.time_tag else { continue };
        let dev = d.name.get_ref().as_str();
        match tag_by_name.get(tt.get_ref().as_str()) {
            None => cx.err(
                *f,
                tt.span(),
                format!("device '{dev}': time_tag '{}' is not a tag", tt.get_ref()),
            ),
            Some((_, clock)) => {
                if let Some(why) = clock_problem(clock, dev) {
                    cx.err(*f, tt.span(), format!("device '{dev}': time_tag {why}"));
                }
            }
        }
    }
    for (f, t) in tags {
        let name = t.name.get_ref();
        if let Some(tt) = &t.time_tag {
            if tt.get_ref() != RECEIVE_TIME {
                match tag_by_name.get(tt.get_ref().as_str()) {
                    None => cx.err(
                        *f,
                        tt.span(),
                        format!("tag '{name}': time_tag '{}' is not a tag (or \"{RECEIVE_TIME}\" for the receive time)", tt.get_ref()),
                    ),
                    Some((_, clock)) => {
                        if let Some(why) = clock_problem(clock, t.device.get_ref()) {
                            cx.err(*f, tt.span(), format!("tag '{name}': time_tag {why}"));
                        }
                    }
                }
            }
        }
        // The clock must be read in the same scan as the tag it stamps.
        let Some((_, d)) = device_by_name.get(t.device.get_ref().as_str()) else {
            continue;
        };
        let Some(clock_name) = t.time_tag(d) else {
            continue;
        };
        let Some((_, clock)) = tag_by_name.get(clock_name) else {
            continue;
        };
        let (own, theirs) = (t.scan_ms(d), clock.scan_ms(d));
        if own != theirs && clock.device.get_ref() == t.device.get_ref() {
            let at = t.time_tag.as_ref().map_or(t.name.span(), |s| s.span());
            cx.err(
                *f,
                at,
                format!("tag '{name}': scanned every {own} ms but its device clock '{clock_name}' every {theirs} ms; a clock stamps only the tags read in its own scan (give them the same scan_ms, or time_tag = \"{RECEIVE_TIME}\")"),
            );
        }
    }
}

fn need_tag<'t>(
    cx: &mut Ctx<'_>,
    at: Range<usize>,
    owner: &str,
    tag: &str,
    lookup: &dyn Fn(&str) -> Option<&'t TagConfig>,
    want: &[ValueKind],
    writable: bool,
) {
    match lookup(tag) {
        None => cx.err(
            0,
            at,
            format!("{owner}: needs tag '{tag}', which no tag file defines"),
        ),
        Some(t) => {
            let k = t.value_kind();
            if !want.contains(&k) {
                cx.err(
                    0,
                    at.clone(),
                    format!("{owner}: tag '{tag}' must be {want:?}, but it is {k:?}"),
                );
            }
            if writable && !*t.writable.get_ref() {
                cx.err(
                    0,
                    at,
                    format!("{owner}: tag '{tag}' is a command output and must be writable"),
                );
            }
        }
    }
}

fn positive(cx: &mut Ctx<'_>, owner: &str, field: &str, v: &Spanned<f64>) {
    if !(v.get_ref().is_finite() && *v.get_ref() > 0.0) {
        cx.err(
            0,
            v.span(),
            format!("{owner}: {field} must be a positive number of seconds"),
        );
    }
}

fn check_panel<'t, 'd>(
    cx: &mut Ctx<'_>,
    p: &PanelConfig,
    lookup: &dyn Fn(&str) -> Option<&'t TagConfig>,
    device: &dyn Fn(&str) -> Option<&'d DeviceConfig>,
) {
    let owner = format!("panel '{}'", p.id.get_ref());
    let zones = *p.zones.get_ref();
    if !(1..=32).contains(&zones) {
        cx.err(0, p.zones.span(), format!("{owner}: zones must be 1 to 32"));
    }
    positive(cx, &owner, "reclose_delay_s", &p.reclose_delay_s);
    positive(cx, &owner, "dwell_s", &p.dwell_s);
    positive(cx, &owner, "confirm_timeout_s", &p.confirm_timeout_s);
    if *p.max_trips.get_ref() < 2 {
        cx.err(
            0,
            p.max_trips.span(),
            format!("{owner}: max_trips must be at least 2 (isolating one fault takes two trips)"),
        );
    }
    if !(1..=32).contains(&zones) {
        return;
    }
    let io = p.io();
    let at = p.prefix.span();
    let b = [ValueKind::Bool];
    need_tag(cx, at.clone(), &owner, &io.elcb_closed, lookup, &b, false);
    need_tag(cx, at.clone(), &owner, &io.elcb_reset, lookup, &b, true);
    need_tag(cx, at.clone(), &owner, &io.mccb_cmd, lookup, &b, true);
    need_tag(cx, at.clone(), &owner, &io.mccb_closed, lookup, &b, false);
    for (cmd, closed) in io.zone_cmd.iter().zip(&io.zone_closed) {
        need_tag(cx, at.clone(), &owner, cmd, lookup, &b, true);
        need_tag(cx, at.clone(), &owner, closed, lookup, &b, false);
    }
    check_dwell_vs_elcb_latency(cx, p, &owner, &io.elcb_closed, lookup, device);
}

/// A trip is pinned on the load being switched on when the ELCB is read open
/// within its dwell, so the dwell must outlast the latest a trip can be read:
/// one scan period of the ELCB status plus a request timeout. (The breaker's
/// operating time comes on top; it is not configured, hence "exceed".)
fn check_dwell_vs_elcb_latency<'t, 'd>(
    cx: &mut Ctx<'_>,
    p: &PanelConfig,
    owner: &str,
    elcb_closed: &str,
    lookup: &dyn Fn(&str) -> Option<&'t TagConfig>,
    device: &dyn Fn(&str) -> Option<&'d DeviceConfig>,
) {
    let dwell = *p.dwell_s.get_ref();
    if !(dwell.is_finite() && dwell > 0.0) {
        return; // reported by `positive`
    }
    // A missing tag or device is reported on its own.
    let Some(tag) = lookup(elcb_closed) else {
        return;
    };
    let dev_name = tag.device.get_ref();
    let Some(dev) = device(dev_name) else {
        return;
    };
    let scan_ms = tag
        .scan_ms
        .as_ref()
        .map_or(*dev.scan_ms.get_ref(), |s| *s.get_ref());
    let timeout_ms = *dev.timeout_ms.get_ref();
    let latest_ms = scan_ms.saturating_add(timeout_ms);
    if dwell * 1000.0 > latest_ms as f64 {
        return;
    }
    // A defaulted dwell_s has no place in the file: point at the panel.
    let span = if p.dwell_s.span().is_empty() {
        p.id.span()
    } else {
        p.dwell_s.span()
    };
    cx.err(
        0,
        span,
        format!(
            "{owner}: dwell_s = {dwell} s is too short to attribute a trip: the ELCB status \
             ({dev_name}) is read every {scan_ms} ms with a {timeout_ms} ms timeout; dwell_s must \
             exceed {} s",
            latest_ms as f64 / 1000.0
        ),
    );
}

/// Longest look-ahead the live loop accepts: a week of 15-minute periods.
const MAX_HORIZON_PERIODS: f64 = 672.0;

fn check_horizon(cx: &mut Ctx<'_>, mg: &MicrogridConfig, h: &HorizonConfig) {
    let owner = "[microgrid.horizon]";
    let n = *h.periods.get_ref();
    if !(n.fract() == 0.0 && (1.0..=MAX_HORIZON_PERIODS).contains(&n)) {
        cx.err(
            0,
            h.periods.span(),
            format!("{owner}: periods must be a whole number from 1 to {MAX_HORIZON_PERIODS}"),
        );
    }
    positive(cx, owner, "period_s", &h.period_s);
    positive(cx, owner, "resolve_s", &h.resolve_s);
    let dispatch = *mg.dispatch_period_s.get_ref();
    for (field, v) in [("period_s", &h.period_s), ("resolve_s", &h.resolve_s)] {
        if *v.get_ref() < dispatch {
            cx.err(
                0,
                v.span(),
                format!(
                    "{owner}: {field} ({} s) is shorter than dispatch_period_s ({dispatch} s)",
                    v.get_ref()
                ),
            );
        }
    }
    if !(h.blend_h.get_ref().is_finite() && *h.blend_h.get_ref() > 0.0) {
        cx.err(
            0,
            h.blend_h.span(),
            format!("{owner}: blend_h must be a positive number of hours"),
        );
    }
    if let Some(points) = &h.demand_forecast_kw {
        check_daily_points(cx, owner, "demand_forecast_kw", points, f64::INFINITY);
    }
    if let Some(r) = &h.reserve {
        let fracs = [r.load_frac, r.pv_frac, r.wind_frac];
        let fracs_ok = fracs.iter().all(|f| (0.0..=1.0).contains(f));
        let cost_ok = r.shortfall_cost_per_kwh.is_finite() && r.shortfall_cost_per_kwh >= 0.0;
        if !(fracs_ok && cost_ok) {
            cx.err(
                0,
                h.periods.span(),
                format!(
                    "{owner}: reserve needs load_frac, pv_frac and wind_frac in [0, 1] \
                     and a shortfall_cost_per_kwh of 0 or more"
                ),
            );
        }
    }
}

/// A daily curve: at least one point, hours distinct and in [0, 24), values
/// finite, not negative and at most `max`.
fn check_daily_points(cx: &mut Ctx<'_>, owner: &str, field: &str, points: &DailyPoints, max: f64) {
    let pts = points.get_ref();
    if pts.is_empty() {
        cx.err(0, points.span(), format!("{owner}: {field} has no points"));
    }
    let mut seen: Vec<f64> = Vec::new();
    for (i, &(hour, value)) in pts.iter().enumerate() {
        let at = format!("{owner}: {field} point {} [{hour}, {value}]", i + 1);
        if !(hour.is_finite() && (0.0..24.0).contains(&hour)) {
            cx.err(
                0,
                points.span(),
                format!("{at}: the hour must be in [0, 24)"),
            );
        } else if seen.contains(&hour) {
            cx.err(
                0,
                points.span(),
                format!("{at}: hour {hour} is given twice"),
            );
        }
        seen.push(hour);
        if !(value.is_finite() && value >= 0.0) {
            cx.err(
                0,
                points.span(),
                format!("{at}: the value must be 0 or more"),
            );
        } else if value > max {
            cx.err(
                0,
                points.span(),
                format!("{at}: the value exceeds rated_kw {max}"),
            );
        }
    }
}

fn check_microgrid<'t>(
    cx: &mut Ctx<'_>,
    mg: &MicrogridConfig,
    lookup: &dyn Fn(&str) -> Option<&'t TagConfig>,
) {
    let owner = "[microgrid]";
    positive(cx, owner, "dispatch_period_s", &mg.dispatch_period_s);
    let num = [ValueKind::Float, ValueKind::Int];
    need_tag(
        cx,
        mg.demand_tag.span(),
        owner,
        mg.demand_tag.get_ref(),
        lookup,
        &num,
        false,
    );
    if let Some(h) = &mg.horizon {
        check_horizon(cx, mg, h);
    }
    let mut ids: HashMap<&str, &Spanned<String>> = HashMap::new();
    for u in &mg.units {
        let id = u.id.get_ref();
        let owner = format!("microgrid unit '{id}'");
        if let Some(points) = &u.forecast_kw {
            if matches!(u.kind, UnitKind::Pv | UnitKind::Wind) {
                check_daily_points(cx, &owner, "forecast_kw", points, u.rated_kw);
            } else {
                cx.err(
                    0,
                    points.span(),
                    format!("{owner}: forecast_kw is for PV and wind units only"),
                );
            }
        }
        if let Some(prev) = ids.insert(id, &u.id) {
            let first = cx.place(0, prev.span());
            cx.err(
                0,
                u.id.span(),
                format!("duplicate unit id '{id}' (first defined at {first})"),
            );
        }
        let io = u.io();
        for tag in u.required_tags() {
            let kinds: &[ValueKind] = if tag == io.running || tag == io.run_cmd {
                &[ValueKind::Bool]
            } else {
                &num
            };
            let writable = tag == io.setpoint_kw || tag == io.run_cmd;
            need_tag(cx, u.prefix.span(), &owner, &tag, lookup, kinds, writable);
        }
        match u.kind {
            UnitKind::Storage => {
                if !(0.0 <= u.soc_min_kwh
                    && u.soc_min_kwh < u.soc_max_kwh
                    && u.soc_max_kwh <= u.capacity_kwh)
                {
                    cx.err(
                        0,
                        u.id.span(),
                        format!(
                            "{owner}: storage needs 0 <= soc_min_kwh < soc_max_kwh <= capacity_kwh"
                        ),
                    );
                }
                for eff in [&u.eff_charge, &u.eff_discharge] {
                    if !(*eff.get_ref() > 0.0 && *eff.get_ref() <= 1.0) {
                        cx.err(
                            0,
                            eff.span(),
                            format!("{owner}: efficiencies must be in (0, 1]"),
                        );
                    }
                }
                if u.max_charge_kw <= 0.0 || u.max_discharge_kw <= 0.0 {
                    cx.err(
                        0,
                        u.id.span(),
                        format!(
                            "{owner}: storage needs positive max_charge_kw and max_discharge_kw"
                        ),
                    );
                }
            }
            UnitKind::Diesel => {
                if !(0.0 <= u.min_kw && u.min_kw <= u.max_kw && u.max_kw > 0.0) {
                    cx.err(
                        0,
                        u.id.span(),
                        format!("{owner}: diesel needs 0 <= min_kw <= max_kw, max_kw > 0"),
                    );
                }
            }
            UnitKind::Pv | UnitKind::Wind => {
                if u.rated_kw <= 0.0 {
                    cx.err(
                        0,
                        u.id.span(),
                        format!("{owner}: rated_kw must be positive"),
                    );
                }
            }
        }
        if u.cost_per_kwh < 0.0 || u.cycle_cost_per_kwh < 0.0 {
            cx.err(
                0,
                u.id.span(),
                format!("{owner}: costs must not be negative"),
            );
        }
    }
}
