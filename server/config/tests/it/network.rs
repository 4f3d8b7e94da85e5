//! `[network]`: every problem located, and the ring network plant loads.

use std::fs;

use gridscada_config::load_path;

const TAGS: &str = r#"[[device]]
name = "RTU"
protocol = "tcp"
address = "127.0.0.1:1502"

[[tag]]
name = "A.Closed"
device = "RTU"
kind = "discrete_input"
address = 0

[[tag]]
name = "A.Cmd"
device = "RTU"
kind = "coil"
address = 0
writable = true
write_role = "operator"

[[tag]]
name = "B.Closed"
device = "RTU"
kind = "discrete_input"
address = 1

[[tag]]
name = "B.Pos"
device = "RTU"
kind = "input_register"
address = 0
type = "u16"

[[tag]]
name = "P.kW"
device = "RTU"
kind = "input_register"
address = 1
type = "f32"
"#;

fn problems(network: &str) -> Vec<String> {
    let dir = tempfile::tempdir().unwrap();
    fs::write(
        dir.path().join("gridscada.toml"),
        format!("tag_files = [\"tags.toml\"]\n\n{network}"),
    )
    .unwrap();
    fs::write(dir.path().join("tags.toml"), TAGS).unwrap();
    let prefix = dir.path().display().to_string();
    match load_path(dir.path()) {
        Ok(_) => vec![],
        Err(diags) => diags
            .iter()
            .map(|d| d.to_string().replace(&prefix, "DIR"))
            .collect(),
    }
}

#[test]
fn a_good_network_loads() {
    let net = r#"[network]
level = [{ id = "mv", kv = 11.0 }]
node = [
  { id = "a_bb", busbar = true, level = "mv" },
  { id = "b_bb", busbar = true },
  { id = "lv" },
]
branch = [{ id = "tx", kind = "transformer", from = "b_bb", to = "lv", kv = [11.0, 0.4] }]
source = [{ id = "grid", kind = "grid", node = "a_bb" }]
switch = [
  { id = "a", kind = "circuit_breaker", from = "a_bb", to = "b_bb", status = "A.Closed", command = "A.Cmd" },
  { id = "b", kind = "earth_switch", from = "b_bb", status = "B.Pos" },
]
load = [{ id = "shop", node = "lv", customers = 3 }]
"#;
    assert_eq!(problems(net), Vec::<String>::new());
}

#[test]
fn every_network_problem_is_located() {
    let net = r#"[network]
prefix = "N.ET"
node = [
  { id = "a_bb", busbar = true, level = "hv" },
  { id = "b_bb" },
  { id = "b_bb" },
  { id = "Lonely" },
  { id = "x" },
  { id = "y" },
]
branch = [
  { id = "t1", kind = "transformer", from = "a_bb", to = "x", kv = [11.0, 0.4] },
  { id = "t2", kind = "transformer", from = "a_bb", to = "y", kv = [11.0, 0.25] },
  { id = "c", kind = "cable", from = "x", to = "y" },
  { id = "t3", kind = "transformer", from = "x", to = "nowhere" },
  { id = "l", kind = "line", from = "a_bb", to = "b_bb", kv = [1.0, 1.0] },
]
switch = [
  { id = "a", kind = "circuit_breaker", from = "a_bb", to = "b_bb", status = "A.Closed", command = "B.Closed" },
  { id = "b", kind = "earth_switch", from = "b_bb", to = "a_bb", status = "P.kW" },
  { id = "d", kind = "disconnector", from = "a_bb", to = "b_bb" },
  { id = "e", kind = "load_break_switch", from = "a_bb", to = "b_bb", status = "Nope", command = "A.Cmd" },
  { id = "f", kind = "load_break_switch", from = "a_bb", to = "b_bb", status = { open = "A.Closed", closed = "B.Closed" }, command = "A.Cmd" },
]
source = [{ id = "grid", kind = "grid", node = "a_bb", in_service = { tag = "P.kW", equals = 1 } }]
load = [{ id = "shop", node = "b_bb", energised = "B.Pos" }]
parallel = [{ groups = ["grid", "island"] }]
panel = [{ panel = "ss9", supply = "b_bb" }]
"#;
    let got = problems(net);
    let expected = [
        r#"DIR/gridscada.toml:4:10: error: [network] prefix 'N.ET' must be letters, digits and '_', starting with a letter"#,
        r#"DIR/gridscada.toml:6:41: error: [network] node 'a_bb': unknown level 'hv'"#,
        r#"DIR/gridscada.toml:8:10: error: [network] duplicate node or branch id 'b_bb' (first defined at DIR/gridscada.toml:7:10)"#,
        r#"DIR/gridscada.toml:9:10: error: [network] node or branch id 'Lonely' must start with a lowercase letter and hold only lowercase letters, digits and '_' (at most 64)"#,
        r#"DIR/gridscada.toml:9:10: error: [network] node 'Lonely' is dangling: no branch, switch, source or load connects to it"#,
        r#"DIR/gridscada.toml:15:10: error: [network] voltage conflict: transformer 't2' puts node 'y' at 0.25 kV, but transformer 't1' puts the part it is connected to at 0.4 kV"#,
        r#"DIR/gridscada.toml:17:10: error: [network] transformer 't3' needs kv = [from side, to side], its rated voltages"#,
        r#"DIR/gridscada.toml:17:10: error: [network] branch 't3': to names unknown node 'nowhere'"#,
        r#"DIR/gridscada.toml:18:63: error: [network] branch 'l': only a transformer has kv"#,
        r#"DIR/gridscada.toml:21:10: error: [network] switch 'a': tag 'B.Closed' is a command output and must be writable"#,
        r#"DIR/gridscada.toml:22:10: error: [network] switch 'b': an earth switch connects `from` to earth and has no `to`"#,
        r#"DIR/gridscada.toml:22:10: error: [network] switch 'b': tag 'P.kW' must be [Bool, Int], but it is Float"#,
        r#"DIR/gridscada.toml:23:10: error: [network] switch 'd': needs `status`, the tag its position is read from (only a fuse may go without)"#,
        r#"DIR/gridscada.toml:24:10: error: [network] switch 'e': needs tag 'Nope', which no tag file defines"#,
        r#"DIR/gridscada.toml:25:10: error: [network] switch 'f': command tag 'A.Cmd' already commands switch 'e'"#,
        r#"DIR/gridscada.toml:27:18: error: [network] source 'grid': tag 'P.kW' must be [Int], but it is Float"#,
        r#"DIR/gridscada.toml:28:16: error: [network] load 'shop': tag 'B.Pos' must be [Bool], but it is Int"#,
        r#"DIR/gridscada.toml:29:24: error: [network] parallel: no source is in group 'island'"#,
        r#"DIR/gridscada.toml:30:20: error: [network] panel 'ss9': no [[panel]] has this id"#,
    ];
    assert_eq!(got, expected, "\ngot:\n{}\n", got.join("\n"));
}

#[test]
fn the_demo_ring_network_has_its_sections_and_devices() {
    let plant = load_path(&std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tags"))
        .expect("the demo plant loads");
    let net = plant.network.as_ref().expect("the plant has a network");
    let e = net.elements(&plant.panels, plant.microgrid.as_ref(), &|t| {
        plant.tag(t).is_some()
    });
    // 21 telemetered MV devices and a fuse; ELCB, MCCB and four zones per panel.
    assert_eq!(e.switches.len(), 22 + 2 * 6);
    assert_eq!(
        e.sources.len(),
        1 + plant.microgrid.as_ref().unwrap().units.len()
    );
    let ss1_zone2 = e.loads.iter().find(|l| l.item.id == "ss1_zone2").unwrap();
    assert_eq!(ss1_zone2.item.customers, 40);
    assert_eq!(
        ss1_zone2.item.energised.as_deref(),
        Some("SS1.Zone2.Energised")
    );
    let (kv, conflicts) = gridscada_config::node_voltages(&e);
    assert!(conflicts.is_empty(), "{conflicts:?}");
    assert_eq!(kv["rmu2_c3"], 11.0);
    assert_eq!(kv["ss1_z3"], 0.433);
    assert_eq!(kv["mg_bb"], 0.433);
}
