//! Device clocks: the `time_tag` of a device or a tag, checked against the
//! tag it names (same device, same scan period, a numeric or `datetime` tag).

use std::collections::HashMap;

use crate::model::*;

use super::Ctx;

/// Device clocks: a `time_tag` (of a device, or of a tag) names a numeric or
/// `datetime` tag of the same device, read at the same scan period, so each
/// scan stamps its values with the clock it read with them.
pub(super) fn check_time_tags(
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
