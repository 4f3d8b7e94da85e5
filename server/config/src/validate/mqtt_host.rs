//! `[mqtt.host]`: the central Sparkplug B host (`model/mqtt.rs`).

use serde_spanned::Spanned;

use super::Ctx;
use crate::{MqttConfig, Role};

/// A Sparkplug id (group, edge node, host id) is one topic level: not
/// empty, and none of MQTT's separator and wildcards.
fn sparkplug_id(cx: &mut Ctx<'_>, field: &str, id: &Spanned<String>) {
    let v = id.get_ref();
    if v.is_empty() || v.contains(['/', '+', '#']) {
        cx.err(
            0,
            id.span(),
            format!("{field}: '{v}' must be a non-empty name without '/', '+' or '#'"),
        );
    }
}

/// `[mqtt.host]`. The connection keys (broker, TLS, credentials, group)
/// are checked once for both modes (`mqtt.rs`).
pub(super) fn check_mqtt_host(cx: &mut Ctx<'_>, mqtt: &MqttConfig) {
    let Some(host) = &mqtt.host else { return };
    check_rest(cx, host);
}

fn check_rest(cx: &mut Ctx<'_>, host: &crate::MqttHostConfig) {
    sparkplug_id(cx, "[mqtt.host] host_id", &host.host_id);
    let mut seen = std::collections::HashSet::new();
    for node in &host.nodes {
        sparkplug_id(cx, "[mqtt.host] nodes", node);
        if !seen.insert(node.get_ref().as_str()) {
            cx.err(
                0,
                node.span(),
                format!("[mqtt.host] nodes: '{}' is listed twice", node.get_ref()),
            );
        }
    }
    let max_tags = *host.max_tags.get_ref();
    if !(1..=1_000_000).contains(&max_tags) {
        cx.err(
            0,
            host.max_tags.span(),
            format!("[mqtt.host] max_tags: {max_tags} must be 1 to 1000000"),
        );
    }
    let bytes = *host.max_message_bytes.get_ref();
    if !(1024..=256 * 1024 * 1024).contains(&bytes) {
        cx.err(
            0,
            host.max_message_bytes.span(),
            format!("[mqtt.host] max_message_bytes: {bytes} must be 1024 to 268435456"),
        );
    }
    let rebirth = *host.rebirth_interval_s.get_ref();
    if !(rebirth.is_finite() && (0.0..=3600.0).contains(&rebirth)) {
        cx.err(
            0,
            host.rebirth_interval_s.span(),
            format!("[mqtt.host] rebirth_interval_s: {rebirth} must be 0 to 3600 seconds"),
        );
    }
    let timeout = *host.write_timeout_s.get_ref();
    if !(timeout.is_finite() && timeout > 0.0 && timeout <= 600.0) {
        cx.err(
            0,
            host.write_timeout_s.span(),
            format!("[mqtt.host] write_timeout_s: {timeout} must be more than 0 and at most 600 seconds"),
        );
    }
    if *host.write_role.get_ref() < Role::Operator {
        cx.err(
            0,
            host.write_role.span(),
            format!(
                "[mqtt.host] write_role: {} may command nothing; use operator or above",
                host.write_role.get_ref().label()
            ),
        );
    }
}
