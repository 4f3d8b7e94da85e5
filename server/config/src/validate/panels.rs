//! Substation panels: their timings, the tags their sequence reads and
//! commands, and the dwell against the ELCB's read latency.

use gridscada_tagdb::ValueKind;

use crate::model::*;

use super::{need_tag, positive, Ctx};

pub(super) fn check_panel<'t, 'd>(
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
pub(super) fn check_dwell_vs_elcb_latency<'t, 'd>(
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
    // How late the master may learn of a trip: a Modbus scan and its
    // timeout; a DNP3 event poll and its response timeout; an IEC 104
    // station, or a DNP3 outstation with unsolicited responses, reports a
    // change when it happens.
    let (scan_ms, timeout_ms, read) = match dev.protocol {
        Protocol::Iec104 => return,
        // Reported by the IED when its report control blocks are enabled.
        Protocol::Iec61850 if dev.iec61850.as_ref().is_some_and(|s| !s.reports.is_empty()) => {
            return
        }
        Protocol::Dnp3 => {
            let d = dev.dnp3.clone().unwrap_or_default();
            if d.unsolicited {
                return;
            }
            let poll_s = match *d.event_poll_period_s.get_ref() {
                p if p > 0.0 => p,
                _ => *d.integrity_period_s.get_ref(),
            };
            (
                (poll_s * 1000.0).round() as u64,
                *d.response_timeout_ms.get_ref(),
                "polled for events",
            )
        }
        Protocol::Tcp | Protocol::Rtu | Protocol::Iec61850 => (
            tag.scan_ms
                .as_ref()
                .map_or(*dev.scan_ms.get_ref(), |s| *s.get_ref()),
            *dev.timeout_ms.get_ref(),
            "read",
        ),
    };
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
             ({dev_name}) is {read} every {scan_ms} ms with a {timeout_ms} ms timeout; dwell_s must \
             exceed {} s",
            latest_ms as f64 / 1000.0
        ),
    );
}
