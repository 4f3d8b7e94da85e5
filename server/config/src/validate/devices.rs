//! Each device on its own: its transport (TCP address or serial port),
//! unit id, scan period, timeout and back-off, its comm alarm's delays, the
//! Modbus request limits, and an IEC 104 device's link settings.

use serde_spanned::Spanned;

use crate::model::*;

use super::Ctx;

pub(super) fn check_device(cx: &mut Ctx<'_>, f: usize, d: &DeviceConfig) {
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
        Protocol::Tcp | Protocol::Iec104 | Protocol::Iec61850 => {
            check_tcp_address(cx, f, d);
            if d.serial.is_some() {
                cx.err(
                    f,
                    at.clone(),
                    format!(
                        "device '{name}': [device.serial] is only for protocol = \"rtu\" or \"dnp3\""
                    ),
                );
            }
        }
        // DNP3 runs over TCP or a serial line: one of the two.
        Protocol::Dnp3 => match (&d.address, &d.serial) {
            (_, None) => check_tcp_address(cx, f, d),
            (None, Some(s)) => check_serial_line(cx, f, name, s),
            (Some(a), Some(_)) => cx.err(
                f,
                a.span(),
                format!(
                    "device '{name}': a dnp3 device has either address (TCP) or [device.serial], not both"
                ),
            ),
        },
        Protocol::Rtu => {
            match &d.serial {
                None => cx.err(
                    f,
                    at.clone(),
                    format!(
                        "device '{name}': an rtu device needs a [device.serial] table with port"
                    ),
                ),
                Some(s) => check_serial_line(cx, f, name, s),
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
    match (d.protocol, &d.iec104) {
        (Protocol::Iec104, Some(link)) => check_iec104_link(cx, f, name, link),
        (Protocol::Iec104, None) => {}
        (_, Some(link)) => cx.err(
            f,
            link.common_address.span(),
            format!("device '{name}': [device.iec104] is only for protocol = \"iec104\""),
        ),
        (_, None) => {}
    }
    match (d.protocol, &d.iec61850) {
        (Protocol::Iec61850, Some(s)) => super::iec61850::check_iec61850_device(cx, f, name, s),
        (Protocol::Iec61850, None) => {}
        (_, Some(s)) => cx.err(
            f,
            s.response_timeout_ms.span(),
            format!("device '{name}': [device.iec61850] is only for protocol = \"iec61850\""),
        ),
        (_, None) => {}
    }
    match (d.protocol, &d.dnp3) {
        (Protocol::Dnp3, Some(session)) => check_dnp3_session(cx, f, name, session),
        (Protocol::Dnp3, None) => {}
        (_, Some(session)) => cx.err(
            f,
            session.master_address.span(),
            format!("device '{name}': [device.dnp3] is only for protocol = \"dnp3\""),
        ),
        (_, None) => {}
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

pub(super) fn limit_range(
    cx: &mut Ctx<'_>,
    f: usize,
    dev: &str,
    field: &str,
    v: &Spanned<u16>,
    max: u16,
) {
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

/// `host:port` of a TCP device.
fn is_host_port(address: &str) -> bool {
    address
        .rsplit_once(':')
        .is_some_and(|(host, port)| !host.is_empty() && port.parse::<u16>().is_ok_and(|p| p > 0))
}

/// A DNP3 outstation on a serial port has the port to itself: the master
/// polls one outstation per line (several on one RS-485 line, or beside
/// Modbus RTU slaves, would need one task sharing the line between them).
pub(super) fn check_serial_sharing(cx: &mut Ctx<'_>, devices: &[(usize, DeviceConfig)]) {
    let mut by_port: std::collections::HashMap<&str, (usize, &DeviceConfig)> =
        std::collections::HashMap::new();
    for (f, d) in devices {
        let Some(s) = &d.serial else { continue };
        let port = s.port.get_ref().as_str();
        if let Some((pf, prev)) = by_port.get(port) {
            if d.protocol == Protocol::Dnp3 || prev.protocol == Protocol::Dnp3 {
                let first = cx.place(*pf, prev.name.span());
                cx.err(
                    *f,
                    s.port.span(),
                    format!(
                        "device '{}': serial port {port} is already used by device '{}' (at {first}); a DNP3 outstation needs a serial port of its own",
                        d.name.get_ref(),
                        prev.name.get_ref()
                    ),
                );
            }
        } else {
            by_port.insert(port, (*f, d));
        }
    }
}

fn check_serial_line(cx: &mut Ctx<'_>, f: usize, name: &str, s: &SerialConfig) {
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

fn check_tcp_address(cx: &mut Ctx<'_>, f: usize, d: &DeviceConfig) {
    let name = d.name.get_ref();
    match &d.address {
        None => cx.err(
            f,
            d.name.span(),
            format!(
                "device '{name}': a {} device needs address = \"host:port\"{}",
                d.protocol.label(),
                if d.protocol == Protocol::Dnp3 {
                    " or a [device.serial] table"
                } else {
                    ""
                }
            ),
        ),
        Some(a) if !is_host_port(a.get_ref()) => cx.err(
            f,
            a.span(),
            format!(
                "device '{name}': address '{}' is not host:port",
                a.get_ref()
            ),
        ),
        Some(_) => {}
    }
}

/// A DNP3 session's addresses, periods and timeouts.
fn check_dnp3_session(cx: &mut Ctx<'_>, f: usize, name: &str, s: &Dnp3DeviceConfig) {
    let (m, o) = (*s.master_address.get_ref(), *s.outstation_address.get_ref());
    for (field, v) in [
        ("master_address", &s.master_address),
        ("outstation_address", &s.outstation_address),
    ] {
        if *v.get_ref() > 65519 {
            cx.err(
                f,
                v.span(),
                format!("device '{name}': {field} must be 0 to 65519 (65520 and above are reserved and broadcast addresses)"),
            );
        }
    }
    if m == o {
        cx.err(
            f,
            s.outstation_address.span(),
            format!("device '{name}': outstation_address {o} is the master_address too"),
        );
    }
    for (field, v) in [
        ("integrity_period_s", &s.integrity_period_s),
        ("event_poll_period_s", &s.event_poll_period_s),
    ] {
        let p = *v.get_ref();
        if !(p.is_finite() && (p == 0.0 || (0.1..=604_800.0).contains(&p))) {
            cx.err(
                f,
                v.span(),
                format!("device '{name}': {field} must be 0 (off) or 0.1 to 604800 seconds"),
            );
        }
    }
    if !(100..=600_000).contains(s.response_timeout_ms.get_ref()) {
        cx.err(
            f,
            s.response_timeout_ms.span(),
            format!("device '{name}': response_timeout_ms must be 100 to 600000"),
        );
    }
    for (field, v, lo) in [
        ("select_timeout_s", &s.select_timeout_s, 0.1),
        ("command_timeout_s", &s.command_timeout_s, 1.0),
    ] {
        let t = *v.get_ref();
        if !(t.is_finite() && (lo..=600.0).contains(&t)) {
            cx.err(
                f,
                v.span(),
                format!("device '{name}': {field} must be {lo} to 600 seconds"),
            );
        }
    }
}

/// The APCI parameters and periods of an IEC 104 link, within the ranges
/// the standard gives (k 1..32767, w at most two thirds of k, t2 < t1).
fn check_iec104_link(cx: &mut Ctx<'_>, f: usize, name: &str, link: &Iec104DeviceConfig) {
    let ca = *link.common_address.get_ref();
    if ca == 0 || ca == 0xFFFF {
        cx.err(
            f,
            link.common_address.span(),
            format!("device '{name}': common_address must be 1 to 65534 (0 is unused, 65535 is the broadcast address)"),
        );
    }
    for a in &link.redundant_addresses {
        if !is_host_port(a.get_ref()) {
            cx.err(
                f,
                a.span(),
                format!(
                    "device '{name}': redundant address '{}' is not host:port",
                    a.get_ref()
                ),
            );
        }
    }
    let (k, w) = (*link.k.get_ref(), *link.w.get_ref());
    if !(1..=32767).contains(&k) {
        cx.err(
            f,
            link.k.span(),
            format!("device '{name}': k must be 1 to 32767"),
        );
    }
    if w == 0 || u32::from(w) * 3 > u32::from(k) * 2 {
        cx.err(
            f,
            link.w.span(),
            format!("device '{name}': w = {w} must be 1 to two thirds of k = {k}"),
        );
    }
    for (field, v, lo, hi) in [
        ("t0_s", &link.t0_s, 1.0, 255.0),
        ("t1_s", &link.t1_s, 1.0, 255.0),
        ("t2_s", &link.t2_s, 1.0, 255.0),
        ("t3_s", &link.t3_s, 1.0, 172_800.0),
        ("command_timeout_s", &link.command_timeout_s, 1.0, 600.0),
    ] {
        if !(v.get_ref().is_finite() && (lo..=hi).contains(v.get_ref())) {
            cx.err(
                f,
                v.span(),
                format!("device '{name}': {field} must be {lo} to {hi} seconds"),
            );
        }
    }
    if link.t2_s.get_ref() >= link.t1_s.get_ref() {
        cx.err(
            f,
            link.t2_s.span(),
            format!(
                "device '{name}': t2_s = {} must be below t1_s = {} (acknowledge before the peer gives up)",
                link.t2_s.get_ref(),
                link.t1_s.get_ref()
            ),
        );
    }
    for (field, v) in [
        ("interrogation_period_s", &link.interrogation_period_s),
        (
            "counter_interrogation_period_s",
            &link.counter_interrogation_period_s,
        ),
        ("clock_sync_period_s", &link.clock_sync_period_s),
    ] {
        let p = *v.get_ref();
        if !(p.is_finite() && (p == 0.0 || (1.0..=604_800.0).contains(&p))) {
            cx.err(
                f,
                v.span(),
                format!("device '{name}': {field} must be 0 (off) or 1 to 604800 seconds"),
            );
        }
    }
}
