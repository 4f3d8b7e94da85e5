//! Configured suppression end to end, on a plant that is not the demo
//! (`tests/plants/three-panels`) run by `gridscada demo --config`: panel `pa`
//! turns its built-in rule off and a `[[suppression]]` rule of the plant's
//! own takes its place. A simulated zone fault trips the ELCB: the alarms
//! the rule names stand suppressed, one it does not name is shown; once the
//! sequence has isolated the zone and reclosed the ELCB, the rule releases
//! the isolated zone's alarm to the operator.

use crate::common;

use std::path::Path;
use std::time::Duration;

use common::{alarm, default_list, wait_for, Demo};
use serde_json::json;

const ELCB: &str = "PA.ELCB.Closed:discrete";
/// In the rule: suppressed while the ELCB is tripped.
const VOLTS: &str = "PA.PA.V_L1:lolo";
const ZONE2: &str = "PA.Zone2.Energised:discrete";
/// Not in the rule (and the panel's default is off): shown.
const ZONE1: &str = "PA.Zone1.Energised:discrete";

const RULE: &str = r#"
[[suppression]]
name = "Pump station ELCB trip"
trigger = "PA.ELCB.Closed:discrete"
suppress = [
  { tag_prefix = "PA.PA.V_", kinds = ["lo", "lolo"] },
  { tag_prefix = "PA.Zone2.", kinds = ["discrete"] },
]
release_delay_s = 2
"#;

fn dead_zone_alarm(n: u8) -> (String, String) {
    let tag = format!(
        "name = \"PA.Zone{n}.Energised\"\ndescription = \"Zone {n} load voltage present\"\ndevice = \"PA.IO\"\nkind = \"discrete_input\"\naddress = {}\n",
        47 + n
    );
    let with = format!("{tag}[[tag.alarm.discrete]]\nwhen = false\nmessage = \"Zone {n} dead\"\n");
    (tag, with)
}

/// The three-panel plant with the rule, panel `pa`'s default turned off and
/// alarms on its zones' supply and its L1 voltage.
fn plant_with_rule(dir: &Path) -> std::path::PathBuf {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/plants/three-panels");
    let plant = dir.join("plant");
    std::fs::create_dir_all(&plant).unwrap();
    let read = |f: &str| std::fs::read_to_string(src.join(f)).unwrap();
    let mut main = read("gridscada.toml");
    let pa = "prefix = \"PA\"\n";
    assert!(main.contains(pa));
    main = main.replacen(pa, &format!("{pa}default_suppression = false\n"), 1);
    main.push_str(RULE);
    std::fs::write(plant.join("gridscada.toml"), main).unwrap();
    let mut panels = read("panels.toml");
    let volts = "name = \"PA.PA.V_L1\"\ndescription = \"Phase L1 voltage\"\ndevice = \"PA.PA\"\nkind = \"input_register\"\naddress = 0\ntype = \"f32\"\nunits = \"V\"\nhistory = { deadband = 0.05, max_interval_s = 30.0 }\n";
    let mut edits = vec![
        (
            volts.to_string(),
            format!("{volts}[tag.alarm.lolo]\nlimit = 50.0\n"),
        ),
        dead_zone_alarm(1),
        dead_zone_alarm(2),
    ];
    for (from, to) in edits.drain(..) {
        assert!(panels.contains(&from), "{from}");
        panels = panels.replacen(&from, &to, 1);
    }
    std::fs::write(plant.join("panels.toml"), panels).unwrap();
    std::fs::copy(src.join("rtu1.toml"), plant.join("rtu1.toml")).unwrap();
    plant
}

#[test]
fn a_configured_rule_suppresses_what_it_names_while_its_trigger_stands_and_releases_after() {
    let dir = tempfile::tempdir().unwrap();
    let plant = plant_with_rule(dir.path());
    let demo = Demo::start_with(
        &dir.path().join("data"),
        &dir.path().join("demo.log"),
        &["--config".as_ref(), plant.as_os_str()],
    );
    let mut admin = demo.login("administrator");
    let mut sup = demo.login("supervisor");
    let mut op = demo.login("operator");

    // Manual first, so the tripped ELCB stays open while suppression is checked.
    let (s, b) = sup.post("/api/panels/pa/mode", json!({"mode": "manual"}));
    assert_eq!(s, 200, "{b}");
    let (s, b) = admin.post(
        "/api/sim/faults",
        json!({"panel": "pa", "zone": 2, "kind": "permanent"}),
    );
    assert_eq!(s, 201, "{b}");
    wait_for(
        "the ELCB trip alarm in the alarm list",
        Duration::from_secs(20),
        || default_list(&mut op).into_iter().find(|a| a["key"] == ELCB),
    );
    for key in [VOLTS, ZONE2] {
        let a = wait_for(&format!("{key} active"), Duration::from_secs(20), || {
            let a = alarm(&mut op, key);
            (a["active"] == true).then_some(a)
        });
        assert_eq!(a["state"], "suppressed", "{a}");
        assert_eq!(a["suppressed"], true, "{a}");
    }
    // Not named by the rule, and the panel's built-in rule (which would
    // suppress every PA.Zone alarm) is off: the operator sees it.
    let z1 = wait_for("zone 1 dead alarm listed", Duration::from_secs(20), || {
        default_list(&mut op)
            .into_iter()
            .find(|a| a["key"] == ZONE1)
    });
    assert_eq!(z1["state"], "unack_active", "{z1}");
    assert_eq!(z1["suppressed"], false, "{z1}");
    let listed = default_list(&mut op);
    assert!(
        !listed
            .iter()
            .any(|a| a["key"] == VOLTS || a["key"] == ZONE2),
        "suppressed alarms in the operator's list: {listed:?}"
    );

    // Automatic: the sequence isolates zone 2 and recloses the ELCB. The
    // trip clears; after the 2 s hold, zone 2's dead-supply alarm (still
    // true: the zone is isolated) is released to the operator. While the
    // sequence runs, the ELCB recloses and re-trips as it tries each zone,
    // so the rule may release and engage again: judge it once the sequence
    // has ended.
    let (s, b) = sup.post("/api/panels/pa/mode", json!({"mode": "auto"}));
    assert_eq!(s, 200, "{b}");
    wait_for(
        "panel pa's sequence ended with zone 2 isolated",
        Duration::from_secs(60),
        || {
            let p = op.get_ok("/api/panels/pa");
            (p["step"] == "isolated").then_some(())
        },
    );
    let z2 = wait_for(
        "zone 2's alarm released into the list",
        Duration::from_secs(60),
        || {
            default_list(&mut op)
                .into_iter()
                .find(|a| a["key"] == ZONE2)
        },
    );
    assert_eq!(z2["active"], true, "{z2}");
    assert_eq!(z2["suppressed"], false, "{z2}");
    let elcb = alarm(&mut op, ELCB);
    assert_eq!(elcb["active"], false, "the trigger cleared first: {elcb}");
    // The voltage came back with the ELCB: not suppressed any more either.
    wait_for("L1 voltage alarm cleared", Duration::from_secs(30), || {
        let a = alarm(&mut op, VOLTS);
        (a["active"] == false && a["suppressed"] == false).then_some(())
    });
}
