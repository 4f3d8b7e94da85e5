//! `[mqtt]` and `[mqtt.edge]`: the broker connection and the edge node.
//! (`[mqtt.host]` is checked by its own function.)

use std::collections::HashMap;

use crate::model::{DeviceConfig, MqttConfig, MqttEdgeConfig, TagConfig, DERIVED_DEVICE};

use super::Ctx;

/// A topic level: not empty, none of MQTT's separators and wildcards.
fn topic_level(name: &str) -> bool {
    !name.is_empty() && !name.contains(['/', '+', '#'])
}

pub(super) fn check_mqtt(
    cx: &mut Ctx<'_>,
    mqtt: &MqttConfig,
    devices: &HashMap<&str, (usize, &DeviceConfig)>,
    tags: &HashMap<&str, (usize, &TagConfig)>,
) {
    let broker = mqtt.broker.get_ref();
    match broker_problem(broker) {
        Some(why) => cx.err(0, mqtt.broker.span(), format!("[mqtt] broker: {why}")),
        None => {
            if broker.starts_with("mqtt://") && mqtt.ca_file.is_some() {
                let at = mqtt.ca_file.as_ref().map(|c| c.span()).unwrap_or(0..0);
                cx.err(
                    0,
                    at,
                    "[mqtt] ca_file: only used with an mqtts:// broker; this one is plain mqtt://",
                );
            }
            if broker.starts_with("mqtts://") && mqtt.ca_file.is_none() {
                cx.err(
                    0,
                    mqtt.broker.span(),
                    "[mqtt] broker: an mqtts:// broker needs ca_file, the CA certificate(s) that signed the broker's certificate (PEM)",
                );
            }
        }
    }
    if !topic_level(mqtt.group.get_ref()) {
        cx.err(
            0,
            mqtt.group.span(),
            format!(
                "[mqtt] group: '{}' must be a topic level: not empty, without '/', '+' or '#'",
                mqtt.group.get_ref()
            ),
        );
    }
    if let Some(id) = &mqtt.client_id {
        if id.get_ref().is_empty() || id.get_ref().len() > 128 {
            cx.err(0, id.span(), "[mqtt] client_id: 1 to 128 characters");
        }
    }
    if let (Some(p), None) = (&mqtt.password, &mqtt.username) {
        cx.err(0, p.span(), "[mqtt] password: given without a username");
    }
    let keep_alive = *mqtt.keep_alive_s.get_ref();
    if !(1..=3600).contains(&keep_alive) {
        cx.err(
            0,
            mqtt.keep_alive_s.span(),
            format!("[mqtt] keep_alive_s: {keep_alive} must be 1 to 3600 seconds"),
        );
    }
    let max = *mqtt.max_message_bytes.get_ref();
    if !(1024..=256 * 1024 * 1024).contains(&max) {
        cx.err(
            0,
            mqtt.max_message_bytes.span(),
            format!("[mqtt] max_message_bytes: {max} must be 1024 to 268435456"),
        );
    }
    if let Some(edge) = &mqtt.edge {
        check_edge(cx, edge, devices, tags);
    }
}

/// Why a broker URL is not usable, if it is not.
fn broker_problem(url: &str) -> Option<String> {
    let Some(rest) = url
        .strip_prefix("mqtt://")
        .or_else(|| url.strip_prefix("mqtts://"))
    else {
        return Some(format!(
            "'{url}' must start with mqtt:// or mqtts://, like mqtt://broker.example:1883"
        ));
    };
    let Some((host, port)) = rest.rsplit_once(':') else {
        return Some(format!("'{url}' needs a port, like mqtt://{rest}:1883"));
    };
    if host.is_empty() || host.contains('/') {
        return Some(format!("'{url}' has no host name"));
    }
    match port.parse::<u16>() {
        Ok(p) if p > 0 => None,
        _ => Some(format!("'{url}': '{port}' is not a port number")),
    }
}

fn check_edge(
    cx: &mut Ctx<'_>,
    edge: &MqttEdgeConfig,
    devices: &HashMap<&str, (usize, &DeviceConfig)>,
    tags: &HashMap<&str, (usize, &TagConfig)>,
) {
    if !topic_level(edge.node.get_ref()) {
        cx.err(
            0,
            edge.node.span(),
            format!(
                "[mqtt.edge] node: '{}' must be a topic level: not empty, without '/', '+' or '#'",
                edge.node.get_ref()
            ),
        );
    }
    if let Some(id) = &edge.primary_host_id {
        if !topic_level(id.get_ref()) {
            cx.err(
                0,
                id.span(),
                format!(
                    "[mqtt.edge] primary_host_id: '{}' must be a topic level: not empty, without '/', '+' or '#'",
                    id.get_ref()
                ),
            );
        }
    }
    // Every device is a Sparkplug device: its name is a topic level.
    let mut sorted: Vec<_> = devices.iter().collect();
    sorted.sort_by_key(|(name, _)| **name);
    for (name, (file, d)) in sorted {
        if !topic_level(name) {
            cx.err(
                *file,
                d.name.span(),
                format!("device '{name}': with [mqtt.edge], a device name must not contain '/', '+' or '#' (it is a topic level)"),
            );
        } else if *name == DERIVED_DEVICE {
            cx.err(
                *file,
                d.name.span(),
                format!("device '{name}': with [mqtt.edge], this name is taken by the Sparkplug device of the server's own tags"),
            );
        }
    }
    let deadband = *edge.deadband.get_ref();
    if !(deadband.is_finite() && deadband >= 0.0) {
        cx.err(
            0,
            edge.deadband.span(),
            format!("[mqtt.edge] deadband: {deadband} must be 0 or more"),
        );
    }
    let batch = *edge.batch_ms.get_ref();
    if !(10..=60_000).contains(&batch) {
        cx.err(
            0,
            edge.batch_ms.span(),
            format!("[mqtt.edge] batch_ms: {batch} must be 10 to 60000"),
        );
    }
    if *edge.buffer_samples.get_ref() > 100_000_000 {
        cx.err(
            0,
            edge.buffer_samples.span(),
            "[mqtt.edge] buffer_samples: at most 100000000",
        );
    }
    super::check_write_patterns(cx, "[mqtt.edge] commands", &edge.commands, tags, false);
}

#[cfg(test)]
mod tests {
    use super::broker_problem;

    #[test]
    fn broker_urls() {
        assert_eq!(broker_problem("mqtt://127.0.0.1:1883"), None);
        assert_eq!(broker_problem("mqtts://broker.example:8883"), None);
        assert!(broker_problem("tcp://x:1")
            .unwrap()
            .contains("must start with"));
        assert!(broker_problem("mqtt://x").unwrap().contains("needs a port"));
        assert!(broker_problem("mqtt://x:http")
            .unwrap()
            .contains("not a port"));
        assert!(broker_problem("mqtt://:1883").unwrap().contains("no host"));
    }
}
