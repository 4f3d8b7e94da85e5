//! End to end on the demo plant, through the HTTP API only: a simulated zone
//! fault raises the ELCB trip alarm and suppresses its consequences; the
//! operator acknowledges (Ack Top and by id), the supervisor shelves and
//! unshelves; the fault is repaired and the alarm clears; a device goes
//! offline and its communication alarm comes and goes; trends hold the
//! outage; and every operator action is in the event log under the user's name.

use crate::common;

use std::time::Duration;

use common::{alarm, default_list, events, now_ms, wait_for, Client, Demo};
use serde_json::{json, Value};

const ELCB: &str = "SS1.ELCB.Closed:discrete";
const LOLO: &str = "SS1.PA.V_L1:lolo";
const PA_COMM: &str = "SS1.PA:comm";

fn state(c: &mut Client, key: &str) -> String {
    alarm(c, key)["state"].as_str().unwrap_or("").to_string()
}

fn wait_state(c: &mut Client, key: &str, want: &str, secs: u64) -> Value {
    wait_for(
        &format!("alarm {key} in state {want}"),
        Duration::from_secs(secs),
        || {
            let a = alarm(c, key);
            (a["state"] == want).then_some(a)
        },
    )
}

#[test]
fn zone_fault_alarms_are_raised_acknowledged_shelved_and_cleared_and_every_action_is_logged() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("demo.log");
    let demo = Demo::start(&dir.path().join("data"), &log);
    let started = now_ms() - 1000;
    let mut admin = demo.login("administrator");
    let mut sup = demo.login("supervisor");
    let mut op = demo.login("operator");

    // Manual mode first, so that the tripped ELCB stays open (no automatic
    // reclose) while the suppression is checked.
    let (s, b) = sup.post("/api/panels/ss1/mode", json!({"mode": "manual"}));
    assert_eq!(s, 200, "{b}");
    assert_eq!(b["mode"], "manual");

    // A permanent fault on zone 2 trips the ELCB.
    let (s, b) = admin.post(
        "/api/sim/faults",
        json!({"panel": "ss1", "zone": 2, "kind": "permanent"}),
    );
    assert_eq!(s, 201, "{b}");
    let trip = wait_for(
        "the ELCB trip alarm in the alarm list",
        Duration::from_secs(20),
        || default_list(&mut op).into_iter().find(|a| a["key"] == ELCB),
    );
    assert_eq!(trip["state"], "unack_active", "{trip}");
    assert_eq!(trip["priority"], 900, "{trip}");
    assert_eq!(trip["active"], true);
    assert_eq!(trip["selection"], "SS1");
    assert!(
        trip["message"].as_str().unwrap().contains("ELCB tripped"),
        "{trip}"
    );
    // The value in the tag's words, not FALSE.
    assert_eq!(trip["value_text"], "TRIPPED", "{trip}");
    // The value at activation, the one the message was written with.
    assert_eq!(trip["activation_value_text"], "TRIPPED", "{trip}");
    let trip_id = trip["id"].as_u64().unwrap();

    // Dead zones and zero voltage are consequences: the under-voltage alarms
    // go active but stay suppressed, out of the ordinary list.
    let lolo = wait_for(
        "the very-low-voltage alarm active and suppressed",
        Duration::from_secs(20),
        || {
            let a = alarm(&mut op, LOLO);
            (a["active"] == true).then_some(a)
        },
    );
    assert_eq!(lolo["state"], "suppressed", "{lolo}");
    assert_eq!(lolo["suppressed"], true);
    assert!(
        lolo["activation_value"].as_f64().is_some_and(|v| v < 50.0),
        "the dead voltage at activation: {lolo}"
    );
    let listed = default_list(&mut op);
    let leaked: Vec<&Value> = listed
        .iter()
        .filter(|a| a["tag"].as_str().is_some_and(|t| t.starts_with("SS1.PA.")))
        .collect();
    assert!(
        leaked.is_empty(),
        "consequential alarms in the list: {leaked:?}"
    );
    let suppressed = op.get_ok("/api/alarms?state=suppressed")["alarms"]
        .as_array()
        .cloned()
        .unwrap();
    assert!(
        suppressed.iter().any(|a| a["key"] == LOLO),
        "{suppressed:?}"
    );

    // Ack Top acknowledges the newest unacknowledged alarm, and only it.
    let unacked_before: Vec<Value> = listed
        .iter()
        .filter(|a| a["acked"] == false)
        .cloned()
        .collect();
    assert!(!unacked_before.is_empty());
    let (s, b) = op.post("/api/alarms/ack", json!({"top": true}));
    assert_eq!(s, 200, "{b}");
    assert_eq!(b["count"], 1, "{b}");
    let top = b["acknowledged"][0].as_u64().unwrap();
    assert!(
        unacked_before.iter().any(|a| a["id"] == top),
        "Ack Top acknowledged {top}, which was not waiting: {unacked_before:?}"
    );
    let acked_top = common::ALL_STATES;
    let acked_top = op.get_ok(&format!("/api/alarms?state={acked_top}"))["alarms"]
        .as_array()
        .unwrap()
        .iter()
        .find(|a| a["id"] == top)
        .cloned()
        .unwrap();
    assert_eq!(acked_top["acked"], true, "{acked_top}");
    println!("Ack Top acknowledged {}", acked_top["key"]);

    // And by id (acknowledging an acknowledged alarm is harmless).
    let (s, b) = op.post("/api/alarms/ack", json!({"ids": [trip_id]}));
    assert_eq!(s, 200, "{b}");
    assert_eq!(state(&mut op, ELCB), "ack_active");

    // Shelving needs a supervisor.
    let path = format!("/api/alarms/{trip_id}/shelve");
    let (s, b) = op.post(&path, json!({"minutes": 30, "reason": "operator try"}));
    assert_eq!(s, 403, "an operator shelved an alarm: {b}");
    let (s, b) = sup.post(
        &path,
        json!({"minutes": 30, "reason": "ELCB under test by maintenance"}),
    );
    assert_eq!(s, 200, "{b}");
    let until = b["shelved_until"].as_i64().unwrap();
    let expected = now_ms() + 30 * 60_000;
    assert!(
        (until - expected).abs() < 60_000,
        "shelved until {until}, expected about {expected}"
    );
    let shelved = alarm(&mut op, ELCB);
    assert_eq!(shelved["state"], "shelved");
    assert_eq!(shelved["shelved"]["by"], "supervisor");
    assert_eq!(
        shelved["shelved"]["reason"],
        "ELCB under test by maintenance"
    );
    assert!(
        !default_list(&mut op).iter().any(|a| a["key"] == ELCB),
        "a shelved alarm is in the ordinary list"
    );
    let (s, b) = op.delete(&path);
    assert_eq!(s, 403, "an operator unshelved an alarm: {b}");
    let (s, b) = sup.delete(&path);
    assert_eq!(s, 204, "{b}");
    // Unshelved while still active, it is annunciated again (ISA-18.2) and
    // needs a fresh acknowledgement.
    let back = alarm(&mut op, ELCB);
    assert_eq!(back["state"], "unack_active", "{back}");
    assert!(back["shelved"].is_null(), "{back}");
    let (s, b) = op.post("/api/alarms/ack", json!({"ids": [trip_id]}));
    assert_eq!(s, 200, "{b}");
    assert_eq!(b["acknowledged"], json!([trip_id]));
    assert_eq!(state(&mut op, ELCB), "ack_active");

    // Repair, back to automatic: the sequence recloses the ELCB and the
    // (acknowledged) trip alarm returns to normal.
    let (s, b) = admin.delete("/api/sim/faults/ss1/2");
    assert_eq!(s, 204, "{b}");
    let (s, b) = sup.post("/api/panels/ss1/mode", json!({"mode": "auto"}));
    assert_eq!(s, 200, "{b}");
    wait_state(&mut op, ELCB, "normal", 45);
    // One trip, one alarm: the sequence's own ELCB trip alarm is not raised
    // beside the status tag's (the sequence ran on that trip when the panel
    // went back to automatic).
    let everything = op.get_ok(&format!("/api/alarms?state={}", common::ALL_STATES));
    let high: Vec<&Value> = everything["alarms"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|a| a["key"].as_str().is_some_and(|k| k.contains("elcb")))
        .collect();
    assert!(high.is_empty(), "a second ELCB trip alarm: {high:?}");
    wait_for(
        "panel ss1 idle with every breaker closed",
        Duration::from_secs(45),
        || {
            let p = op.get_ok("/api/panels/ss1");
            let all_closed = p["breakers"]
                .as_object()
                .is_some_and(|b| b.values().all(|x| x["closed"] == true));
            (p["step"] == "idle" && all_closed).then_some(())
        },
    );

    // History says why each row happened: the very-low-voltage alarm
    // activated and returned while suppressed (its state stayed
    // "suppressed" both times), the trip alarm was acknowledged, shelved...
    let causes = wait_for(
        "the return while suppressed in the alarm history",
        Duration::from_secs(20),
        || {
            let h = op.get_ok(&format!("/api/alarms/history?from={started}&limit=10000"));
            let rows = h["transitions"].as_array().cloned().unwrap_or_default();
            let of = |key: &str| -> Vec<(String, String, String)> {
                rows.iter()
                    .filter(|t| t["alarm_key"] == key)
                    .map(|t| {
                        let f = |n: &str| t[n].as_str().unwrap_or("").to_string();
                        (f("cause"), f("from_state"), f("to_state"))
                    })
                    .collect()
            };
            let (lolo, elcb) = (of(LOLO), of(ELCB));
            let ret = ("return".into(), "suppressed".into(), "suppressed".into());
            lolo.contains(&ret).then_some((lolo, elcb))
        },
    );
    let (lolo_rows, elcb_rows) = causes;
    let act = ("activate".into(), "suppressed".into(), "suppressed".into());
    assert!(lolo_rows.contains(&act), "{lolo_rows:?}");
    let elcb_causes: Vec<&str> = elcb_rows.iter().map(|r| r.0.as_str()).collect();
    for c in ["activate", "ack", "shelve", "unshelve", "return"] {
        assert!(elcb_causes.contains(&c), "{c} missing: {elcb_rows:?}");
    }

    // A confirmed write, then Reset.
    let (s, b) = op.post("/api/tags/SS1.Zone4.Cmd/write", json!({"value": true}));
    assert_eq!(s, 200, "{b}");
    assert_eq!(b["value"], true, "{b}");
    let (s, b) = op.post("/api/panels/ss1/reset", json!({}));
    assert_eq!(s, 200, "{b}");

    // Communication failure of the power analyzer.
    let (s, b) = admin.post("/api/sim/devices/SS1.PA/offline", json!({}));
    assert_eq!(s, 200, "{b}");
    let comm = wait_for(
        "the SS1.PA communication alarm",
        Duration::from_secs(30),
        || {
            default_list(&mut op)
                .into_iter()
                .find(|a| a["key"] == PA_COMM && a["state"] == "unack_active")
        },
    );
    assert_eq!(comm["kind"], "comm_fail", "{comm}");
    let comm_id = comm["id"].as_u64().unwrap();
    let (s, b) = admin.post("/api/sim/devices/SS1.PA/online", json!({}));
    assert_eq!(s, 200, "{b}");
    wait_state(&mut op, PA_COMM, "unack_rtn", 30);
    let (s, b) = op.post("/api/alarms/ack", json!({"ids": [comm_id]}));
    assert_eq!(s, 200, "{b}");
    assert_eq!(b["acknowledged"], json!([comm_id]));
    assert_eq!(state(&mut op, PA_COMM), "normal");

    // The trend of the phase voltage holds the outage and the normal supply.
    let series = wait_for(
        "the trend of SS1.PA.V_L1 to show the outage",
        Duration::from_secs(30),
        || {
            let t = op.get_ok(&format!(
                "/api/trends?tags=SS1.PA.V_L1&from={started}&to={}&points=60",
                now_ms() + 1000
            ));
            let s = t["series"][0].clone();
            let buckets = s["buckets"].as_array()?;
            let low = buckets
                .iter()
                .any(|b| b["min"].as_f64().is_some_and(|v| v < 50.0));
            let normal = buckets
                .iter()
                .any(|b| b["max"].as_f64().is_some_and(|v| v > 200.0 && v < 260.0));
            (low && normal).then_some(s)
        },
    );
    assert_eq!(series["tag"], "SS1.PA.V_L1");

    // Every operator action is in the event log with the user's name.
    let expected: &[(&str, &str, usize)] = &[
        ("login", "admin", 1),
        ("login", "supervisor", 1),
        ("login", "operator", 1),
        ("mode", "supervisor", 2),
        ("training", "admin", 4),
        ("ack", "operator", 3), // Ack Top, the re-ack after unshelving, the comm alarm
        ("shelve", "supervisor", 1),
        ("unshelve", "supervisor", 1),
        ("write", "operator", 1),
        ("reset", "operator", 1),
    ];
    let deadline = std::time::Instant::now() + Duration::from_secs(20);
    let log = loop {
        let all = events(&mut admin, "limit=10000");
        let missing: Vec<_> = expected
            .iter()
            .filter(|(kind, user, n)| {
                all.iter()
                    .filter(|e| e["kind"] == *kind && e["user"] == *user)
                    .count()
                    < *n
            })
            .collect();
        if missing.is_empty() {
            break all;
        }
        if std::time::Instant::now() > deadline {
            let seen: Vec<String> = all
                .iter()
                .filter(|e| e["user"].is_string())
                .map(|e| format!("{} {} {}", e["kind"], e["user"], e["message"]))
                .collect();
            panic!(
                "not in the event log: {missing:?}\nuser events seen:\n{}",
                seen.join("\n")
            );
        }
        std::thread::sleep(Duration::from_millis(200));
    };
    // The user filter of the API finds them too.
    let by_sup = events(&mut admin, "user=supervisor&type=shelve");
    assert!(!by_sup.is_empty());
    assert!(
        by_sup
            .iter()
            .all(|e| e["user"] == "supervisor" && e["kind"] == "shelve"),
        "{by_sup:?}"
    );
    // No action was recorded without a user, apart from the system's own.
    for e in &log {
        let kind = e["kind"].as_str().unwrap_or("");
        if [
            "ack", "shelve", "unshelve", "write", "mode", "reset", "training",
        ]
        .contains(&kind)
        {
            assert!(e["user"].is_string(), "operator action without a user: {e}");
        }
    }
}
