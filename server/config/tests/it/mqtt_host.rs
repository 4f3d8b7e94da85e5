//! `[mqtt.host]`: a central Sparkplug host loads without tag files of its
//! own, and every bad key is reported with its place.

use std::fs;

use gridscada_config::{load_path, Role};

fn load(main: &str) -> Result<gridscada_config::Plant, Vec<String>> {
    let dir = tempfile::tempdir().unwrap();
    fs::write(dir.path().join("gridscada.toml"), main).unwrap();
    let prefix = dir.path().display().to_string();
    load_path(dir.path()).map_err(|diags| {
        diags
            .iter()
            .map(|d| d.to_string().replace(&prefix, "DIR"))
            .collect()
    })
}

#[test]
fn a_central_host_needs_no_tag_files() {
    let plant = load(
        "[mqtt]\nbroker = \"mqtt://127.0.0.1:1883\"\ngroup = \"Grid\"\n[mqtt.host]\nhost_id = \"central\"\nnodes = [\"site-a\"]\n",
    )
    .unwrap();
    let host = plant.mqtt.as_ref().unwrap().host.as_ref().unwrap();
    assert!(plant.tags.is_empty());
    assert!(host.accepts("site-a") && !host.accepts("site-b"));
    assert_eq!(*host.write_role.get_ref(), Role::Operator);
    assert_eq!(*host.max_tags.get_ref(), 50_000);
    // An empty list is as good as none.
    load("tag_files = []\n[mqtt]\nbroker = \"mqtt://h:1883\"\ngroup = \"G\"\n[mqtt.host]\nhost_id = \"c\"\n")
        .unwrap();
    // Without [mqtt.host] the plant still needs tag files.
    assert_eq!(
        load("tag_files = []\n").unwrap_err(),
        ["DIR/gridscada.toml:1:1: error: tag_files is empty: a plant needs at least one tag file (or [mqtt.host], a central host)"]
    );
}

#[test]
fn bad_host_keys_are_located() {
    let main = r#"[mqtt]
broker = "http://127.0.0.1:1883"
group = "Grid/1"
[mqtt.host]
host_id = ""
nodes = ["a", "a", "b#"]
max_tags = 0
max_message_bytes = 10
rebirth_interval_s = -1.0
write_timeout_s = 0.0
write_role = "guest"
"#;
    let got = load(main).unwrap_err();
    let want = [
        "DIR/gridscada.toml:2:10: error: [mqtt] broker: 'http://127.0.0.1:1883' must start with mqtt:// or mqtts://, like mqtt://broker.example:1883",
        "DIR/gridscada.toml:3:9: error: [mqtt] group: 'Grid/1' must be a topic level: not empty, without '/', '+' or '#'",
        "DIR/gridscada.toml:5:11: error: [mqtt.host] host_id: '' must be a non-empty name without '/', '+' or '#'",
        "DIR/gridscada.toml:6:15: error: [mqtt.host] nodes: 'a' is listed twice",
        "DIR/gridscada.toml:6:20: error: [mqtt.host] nodes: 'b#' must be a non-empty name without '/', '+' or '#'",
        "DIR/gridscada.toml:7:12: error: [mqtt.host] max_tags: 0 must be 1 to 1000000",
        "DIR/gridscada.toml:8:21: error: [mqtt.host] max_message_bytes: 10 must be 1024 to 268435456",
        "DIR/gridscada.toml:9:22: error: [mqtt.host] rebirth_interval_s: -1 must be 0 to 3600 seconds",
        "DIR/gridscada.toml:10:19: error: [mqtt.host] write_timeout_s: 0 must be more than 0 and at most 600 seconds",
        "DIR/gridscada.toml:11:14: error: [mqtt.host] write_role: guest may command nothing; use operator or above",
    ];
    assert_eq!(got, want, "\ngot:\n{}\n", got.join("\n"));
}
