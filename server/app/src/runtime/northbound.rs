//! The northbound interfaces a configuration turns on: the MQTT Sparkplug B
//! edge node (`[mqtt.edge]`), started on a running stack; and what
//! `demo --mqtt URL` adds to the demo plant.

use std::sync::Arc;

use anyhow::Context;
use gridscada_config::{MqttConfig, MqttEdgeConfig, Plant, Role};
use gridscada_sparkplug::edge::{EdgeContext, EdgeNode};
use serde_spanned::Spanned;

use super::Stack;

/// The Sparkplug group of `demo --mqtt`.
pub const DEMO_GROUP: &str = "gridscada";
/// The edge node id of `demo --mqtt` unless `--mqtt-node` names another.
pub const DEMO_NODE: &str = "demo";

/// `demo --mqtt URL [--mqtt-node ID] [--mqtt-primary-host ID]`.
#[derive(Debug, Clone)]
pub struct DemoMqtt {
    pub broker: String,
    pub node: String,
    pub primary_host: Option<String>,
}

/// Turns on the edge node for the demo: the default group, the given node
/// id, and DCMD writes to every writable tag as an operator (the demo's
/// commands are the simulator's).
pub fn enable_demo(plant: &mut Plant, demo: &DemoMqtt) -> anyhow::Result<()> {
    gridscada_sparkplug::connection::Broker::parse(&demo.broker).context("--mqtt")?;
    if !gridscada_sparkplug::topic::valid_id(&demo.node) {
        anyhow::bail!(
            "--mqtt-node '{}' must not be empty nor contain '/', '+' or '#'",
            demo.node
        );
    }
    if let Some(id) = demo
        .primary_host
        .as_deref()
        .filter(|id| !gridscada_sparkplug::topic::valid_id(id))
    {
        anyhow::bail!("--mqtt-primary-host '{id}' must not be empty nor contain '/', '+' or '#'");
    }
    // What validation checks for a configured [mqtt.edge]: every device is a
    // Sparkplug device, named by a topic level, and none takes the name of
    // the server's own.
    if let Some(d) = plant.devices.iter().find(|d| {
        let name = d.name.get_ref();
        !gridscada_sparkplug::topic::valid_id(name) || name == gridscada_config::DERIVED_DEVICE
    }) {
        anyhow::bail!(
            "--mqtt: device '{}' cannot be a Sparkplug device (a topic level without '/', '+' or '#', and not '{}')",
            d.name.get_ref(),
            gridscada_config::DERIVED_DEVICE
        );
    }
    let s = |v: &str| Spanned::new(0..0, v.to_string());
    plant.mqtt = Some(MqttConfig {
        broker: s(&demo.broker),
        group: s(DEMO_GROUP),
        client_id: None,
        username: None,
        password: None,
        ca_file: None,
        keep_alive_s: Spanned::new(0..0, gridscada_config::DEFAULT_MQTT_KEEP_ALIVE_S),
        max_message_bytes: Spanned::new(0..0, gridscada_config::DEFAULT_MQTT_MAX_MESSAGE_BYTES),
        edge: Some(MqttEdgeConfig {
            node: s(&demo.node),
            deadband: Spanned::new(0..0, 0.0),
            batch_ms: Spanned::new(0..0, gridscada_config::DEFAULT_MQTT_BATCH_MS),
            buffer_samples: Spanned::new(0..0, gridscada_config::DEFAULT_MQTT_BUFFER_SAMPLES),
            commands: vec![s("*")],
            command_role: Spanned::new(0..0, Role::Operator),
            primary_host_id: demo.primary_host.as_deref().map(s),
        }),
        host: None,
    });
    Ok(())
}

/// Starts the edge node if the plant has `[mqtt.edge]`.
pub fn start_edge(stack: &Stack, data_dir: &std::path::Path) -> anyhow::Result<Option<EdgeNode>> {
    let Some(mqtt) = stack.plant.mqtt.as_ref().filter(|m| m.edge.is_some()) else {
        return Ok(None);
    };
    let config_dir = stack
        .plant
        .main_path
        .parent()
        .map(std::path::Path::to_path_buf)
        .unwrap_or_default();
    let ctx = EdgeContext {
        plant: stack.plant.clone(),
        db: stack.db.clone(),
        writer: stack.writer.clone(),
        audit: Arc::new(stack.audit.handle()),
        events: stack.events.clone(),
        clock: stack.clock.clone(),
    };
    let edge = EdgeNode::start(ctx, mqtt, &config_dir, data_dir)
        .context("starting the MQTT Sparkplug B edge node")?;
    tracing::info!(
        broker = %mqtt.broker.get_ref(),
        group = %mqtt.group.get_ref(),
        node = %mqtt.edge.as_ref().map(|e| e.node.get_ref().as_str()).unwrap_or_default(),
        "MQTT Sparkplug B edge node started"
    );
    Ok(Some(edge))
}
