//! Each device on its own: its transport (TCP address or serial port),
//! unit id, scan period, timeout and back-off, its comm alarm's delays and
//! the Modbus request limits.

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
