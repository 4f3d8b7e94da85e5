//! Training from the HMI, through the real demo (simulators as Modbus
//! servers, the poller, the fault-isolation sequences, the web API): the
//! Simulation panel's controls act on the plant the poller sees.
//! - a slow device (reply latency past the poller's timeout) and a device
//!   answering corrupted frames or exceptions turn its tags Bad with a
//!   reason, the server keeps serving, and clearing it brings them back;
//! - a transient fault that clears before the sequence recloses is
//!   restored without isolating anything;
//! - a scaled or overridden input profile reaches the field tags;
//! - every action is an event of type `training` with the trainer's name.

use crate::common;

use std::time::Duration;

use common::{events, wait_for, Client, Demo};
use serde_json::{json, Value};

fn put(c: &mut Client, path: &str, body: Value) -> Value {
    let (status, answer) = c.request("PUT", path, Some(body));
    assert_eq!(status, 200, "PUT {path}: {answer}");
    answer
}

fn quality(c: &mut Client, tag: &str) -> String {
    c.get_ok(&format!("/api/tags/{tag}"))["quality"]["code"]
        .as_str()
        .unwrap_or("")
        .to_string()
}

fn value(c: &mut Client, tag: &str) -> Option<f64> {
    let t = c.get_ok(&format!("/api/tags/{tag}"));
    (t["quality"]["code"] == "good")
        .then(|| t["value"].as_f64())
        .flatten()
}

fn device<'a>(state: &'a Value, name: &str) -> &'a Value {
    state["devices"]
        .as_array()
        .and_then(|d| d.iter().find(|d| d["name"] == name))
        .unwrap_or_else(|| panic!("no simulated device {name} in {state}"))
}

/// One link fault on `dev`, seen through the poller: its tag goes Bad, the
/// server answers meanwhile, and clearing the fault brings it back Good.
fn link_fault_turns_tags_bad(c: &mut Client, dev: &str, tag: &str, fault: Value) {
    wait_for(
        &format!("{tag} Good before {fault}"),
        Duration::from_secs(30),
        || (quality(c, tag) == "good").then_some(()),
    );
    put(c, &format!("/api/sim/devices/{dev}/link"), fault.clone());
    let state = c.get_ok("/api/sim/state");
    let shown = device(&state, dev);
    if let Some(ms) = fault["slow_reply_ms"].as_u64() {
        assert_eq!(shown["slow_reply_ms"], ms, "{shown}");
    }
    if let Some(r) = fault["replies"].as_str() {
        assert_eq!(shown["replies"], r, "{shown}");
    }
    wait_for(
        &format!("{tag} Bad under {fault}"),
        Duration::from_secs(30),
        || (quality(c, tag) == "bad").then_some(()),
    );
    let devices = c.get_ok("/api/devices");
    let d = devices["devices"]
        .as_array()
        .and_then(|d| d.iter().find(|d| d["name"] == dev))
        .cloned()
        .unwrap_or_default();
    assert!(
        !d["last_error"].as_str().unwrap_or("").is_empty(),
        "{dev} under {fault} has no error: {d}"
    );
    assert_eq!(c.get("/healthz").0, 200, "the server still answers");
    put(c, &format!("/api/sim/devices/{dev}/link"), json!({}));
    wait_for(
        &format!("{tag} Good after {fault}"),
        Duration::from_secs(30),
        || (quality(c, tag) == "good").then_some(()),
    );
}

#[test]
fn simulation_panel_controls_reach_the_poller_and_are_audited_as_training() {
    let dir = tempfile::tempdir().unwrap();
    let demo = Demo::start(dir.path(), &dir.path().join("demo.log"));
    let mut admin = demo.login("administrator");

    let state = admin.get_ok("/api/sim/state");
    assert!(state["inputs"].is_object(), "{state}");
    assert_eq!(state["inputs"]["demand"]["kind"], "builtin", "{state}");

    // Slow replies past the 500 ms timeout, corrupted frames, exceptions.
    link_fault_turns_tags_bad(
        &mut admin,
        "MG.PV1",
        "MG.PV1.P_kW",
        json!({"slow_reply_ms": 2000}),
    );
    link_fault_turns_tags_bad(
        &mut admin,
        "MG.PV1",
        "MG.PV1.P_kW",
        json!({"replies": "corrupt"}),
    );
    link_fault_turns_tags_bad(
        &mut admin,
        "MG.WT1",
        "MG.WT1.P_kW",
        json!({"replies": "exception"}),
    );
    let (status, body) = admin.request(
        "PUT",
        "/api/sim/devices/MG.PV1/link",
        Some(json!({"slow_reply_ms": 999_999})),
    );
    assert_eq!(status, 400, "{body}");
    let (status, body) =
        admin.request("PUT", "/api/sim/devices/NoSuchDevice/link", Some(json!({})));
    assert_eq!(status, 404, "{body}");

    // Profiles: an override reaches the meter; a scale multiplies the curve.
    put(
        &mut admin,
        "/api/sim/inputs/demand",
        json!({"profile": {"kind": "constant", "value": 42.0}}),
    );
    wait_for("the load meter at 42 kW", Duration::from_secs(30), || {
        value(&mut admin, "MG.Load.P_kW").filter(|v| (v - 42.0).abs() < 1.0)
    });
    put(
        &mut admin,
        "/api/sim/inputs/demand",
        json!({"profile": {"kind": "builtin"}}),
    );
    let builtin = admin.get_ok("/api/sim/state")["inputs"]["demand_kw"]
        .as_f64()
        .unwrap();
    put(
        &mut admin,
        "/api/sim/inputs/demand",
        json!({"profile": {"kind": "scaled", "factor": 2.0}}),
    );
    let state = admin.get_ok("/api/sim/state");
    let scaled = state["inputs"]["demand_kw"].as_f64().unwrap();
    assert!(
        (scaled / builtin - 2.0).abs() < 0.05,
        "scaled {scaled} kW against built-in {builtin} kW"
    );
    assert_eq!(state["inputs"]["demand"]["kind"], "scaled", "{state}");
    put(
        &mut admin,
        "/api/sim/inputs/irradiance",
        json!({"profile": {"kind": "constant", "value": 0.0}}),
    );
    wait_for("no sun at the PV array", Duration::from_secs(30), || {
        value(&mut admin, "MG.PV1.Irradiance").filter(|v| v.abs() < 1.0)
    });
    let (status, body) = admin.request(
        "PUT",
        "/api/sim/inputs/demand",
        Some(json!({"profile": {"kind": "scaled", "factor": -1.0}})),
    );
    assert_eq!(status, 400, "{body}");
    let (status, _) = admin.request(
        "PUT",
        "/api/sim/inputs/tide",
        Some(json!({"profile": {"kind": "builtin"}})),
    );
    assert_eq!(status, 404);

    // A zone's load.
    let panel = state["panels"][0]["id"].as_str().unwrap().to_string();
    let load = put(
        &mut admin,
        &format!("/api/sim/zones/{panel}/1/load"),
        json!({"kw": 7.5, "pf": 0.9}),
    );
    assert_eq!(load["kw"], 7.5);
    let state = admin.get_ok("/api/sim/state");
    assert_eq!(state["panels"][0]["zones"][0]["load_kw"], 7.5, "{state}");

    // A transient fault that clears (2 s) before the sequence's reclose
    // (3 s): the reclose holds and no zone is isolated.
    wait_for(&format!("{panel} idle"), Duration::from_secs(30), || {
        let p = admin.get_ok(&format!("/api/panels/{panel}"));
        (p["step"] == "idle" && p["comm_ok"] == true).then_some(())
    });
    let (status, body) = admin.post(
        "/api/sim/faults",
        json!({"panel": panel, "zone": 2, "kind": "transient", "clears_after_s": 2}),
    );
    assert_eq!(status, 201, "{body}");
    let state = admin.get_ok("/api/sim/state");
    let zone2 = &state["panels"][0]["zones"][1];
    assert_eq!(zone2["fault"], "transient", "{zone2}");
    assert!(zone2["fault_clears_at"].is_i64(), "{zone2}");
    wait_for(
        "the sequence to restore the panel",
        Duration::from_secs(60),
        || {
            let p = admin.get_ok(&format!("/api/panels/{panel}"));
            let restored = p["step"] == "idle"
                && p["last_sequence"]["trips"].as_u64().unwrap_or(0) >= 1
                && p["faulty_zones"].as_array().is_some_and(|z| z.is_empty())
                && !p["lockout"].as_bool().unwrap_or(true);
            restored.then_some(())
        },
    );
    let state = admin.get_ok("/api/sim/state");
    assert_eq!(state["panels"][0]["elcb_closed"], true, "{state}");
    assert!(state["panels"][0]["zones"][1]["fault"].is_null(), "{state}");

    // Every action above is recorded as training, by the administrator.
    let log = events(&mut admin, "type=training&limit=100");
    assert!(log.len() >= 12, "{log:#?}");
    for e in &log {
        assert_eq!(e["user"], admin.user.as_str(), "{e}");
        assert!(
            e["message"].as_str().unwrap_or("").starts_with("Training:"),
            "{e}"
        );
    }
    let said = |what: &str| {
        log.iter()
            .any(|e| e["message"].as_str().unwrap_or("").contains(what))
    };
    for what in [
        "replies 2000 ms late",
        "corrupted",
        "Modbus exceptions",
        "demand to a constant 42",
        "demand to the built-in profile × 2",
        "clears after 2 s",
        "7.5 kW",
    ] {
        assert!(said(what), "no training event saying '{what}': {log:#?}");
    }
}
