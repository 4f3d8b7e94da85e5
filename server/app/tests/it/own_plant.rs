//! A plant that is not the demo: `tests/plants/three-panels` (panels with
//! other ids and 2, 6 and 8 zones, no microgrid, one plain device), run by
//! `gridscada demo --config`, with a screen kept in its `screens/` folder.

use crate::common;

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use common::*;
use serde_json::{json, Value};

fn plant_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/plants/three-panels")
}

/// A copy of the plant in `dir`, with `screens` written to `screens/`.
fn plant_copy(dir: &Path, screens: &[(&str, String)]) -> PathBuf {
    let plant = dir.join("plant");
    std::fs::create_dir_all(plant.join("screens")).unwrap();
    for entry in std::fs::read_dir(plant_dir()).unwrap() {
        let p = entry.unwrap().path();
        if p.extension().is_some_and(|x| x == "toml") {
            std::fs::copy(&p, plant.join(p.file_name().unwrap())).unwrap();
        }
    }
    for (name, text) in screens {
        std::fs::write(plant.join("screens").join(name), text).unwrap();
    }
    plant
}

fn pump_screen() -> String {
    json!({
        "id": "pumps", "name": "Pumps",
        "elements": [
            {"type": "value", "x": 10, "y": 10, "w": 120, "h": 24, "tag": "RTU1.Setpoint"},
            {"type": "button", "x": 10, "y": 40, "w": 120, "h": 24, "tag": "RTU1.Setpoint", "label": "25 kW", "value": 25.0},
            {"type": "panel", "x": 10, "y": 80, "w": 700, "h": 420, "panel": "pb"}
        ]
    })
    .to_string()
}

#[test]
fn check_locates_problems_in_screen_files() {
    let dir = tempfile::tempdir().unwrap();
    let bad = "{\n  \"id\": \"x\",\n  \"name\": \"X\",\n  \"elements\": [\n    {\"type\": \"breaker\", \"x\": 0, \"y\": 0, \"w\": 10, \"h\": 10, \"tag\": \"PA.PA.V_L1\"}\n  ]\n}\n";
    let plant = plant_copy(
        dir.path(),
        &[
            ("good.json", pump_screen()),
            ("bad.json", bad.into()),
            ("broken.json", "{\"id\": \"y\",\n \"nme\": 1}".into()),
        ],
    );
    let out = Command::new(BIN).arg("check").arg(&plant).output().unwrap();
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("bad.json: element 0 (breaker) tag: 'PA.PA.V_L1' is a Float tag"),
        "{err}"
    );
    assert!(err.contains("broken.json:2:"), "{err}");
    assert!(err.contains("2 problem(s) found"), "{err}");
    std::fs::remove_file(plant.join("screens/bad.json")).unwrap();
    std::fs::remove_file(plant.join("screens/broken.json")).unwrap();
    let out = Command::new(BIN).arg("check").arg(&plant).output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

fn devices(c: &mut Client) -> Vec<Value> {
    c.get_ok("/api/devices")["devices"]
        .as_array()
        .unwrap()
        .clone()
}

#[test]
fn another_plant_is_usable_whole() {
    let dir = tempfile::tempdir().unwrap();
    let plant = plant_copy(dir.path(), &[("pumps.json", pump_screen())]);
    let data = dir.path().join("data");
    let demo = Demo::start_with(
        &data,
        &dir.path().join("demo.log"),
        &["--config".as_ref(), plant.as_os_str()],
    );
    let mut admin = demo.login("administrator");

    // The data folder and the database are the owner's only, whatever the umask.
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let mode = |p: &Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode(&data), 0o700);
        assert_eq!(mode(&data.join("gridscada.db")), 0o600);
        assert_eq!(mode(&data.join("credentials.txt")), 0o600);
        for side in ["gridscada.db-wal", "gridscada.db-shm"] {
            if data.join(side).exists() {
                assert_eq!(mode(&data.join(side)), 0o600, "{side}");
            }
        }
    }

    // Its panels, by their ids and zone counts; no microgrid screens.
    let screens = admin.get_ok("/api/screens");
    let ids: Vec<&str> = screens["screens"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["id"].as_str().unwrap())
        .collect();
    assert_eq!(
        ids,
        [
            "main",
            "pa",
            "pb",
            "pc",
            "custom:pumps",
            "alarms",
            "events",
            "trends",
            "tags",
            "devices",
            "editor",
            "simulation",
            "users",
            "reports",
            "alarmkpi"
        ]
    );
    let panels = admin.get_ok("/api/panels");
    let zones: Vec<(String, u64)> = panels["panels"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| {
            (
                p["id"].as_str().unwrap().into(),
                p["zones"].as_u64().unwrap(),
            )
        })
        .collect();
    assert_eq!(
        zones,
        [("pa".into(), 2), ("pb".into(), 6), ("pc".into(), 8)]
    );
    // The screen from the folder was taken in as version 1, audited.
    let s = admin.get_ok("/api/screens/pumps");
    assert_eq!(
        (s["name"].as_str(), s["version"].as_i64()),
        (Some("Pumps"), Some(1))
    );
    let ev = events(&mut admin, "kind=config");
    assert!(
        ev.iter().any(|e| e["message"]
            .as_str()
            .is_some_and(|m| m.contains("screen 'pumps' (Pumps) loaded from"))),
        "{ev:?}"
    );

    // Every device answers; the plain device's setpoint is written and
    // confirmed by the device's read-back.
    wait_for("every device connected", Duration::from_secs(20), || {
        let d = devices(&mut admin);
        (d.len() == 7 && d.iter().all(|d| d["connected"] == true)).then_some(())
    });
    let mut op = demo.login("operator");
    let (status, body) = op.post("/api/tags/RTU1.Setpoint/write", json!({"value": 31.5}));
    assert_eq!(status, 200, "{body}");
    assert_eq!(body["value"], 31.5);
    assert_eq!(body["quality"]["code"], "good");
    // Outside its engineering limits (0 to 75 kW) nothing reaches the
    // device, and the refusal is audited.
    for bad in [-5.0, 1e30, -1e6] {
        let (status, body) = op.post("/api/tags/RTU1.Setpoint/write", json!({"value": bad}));
        assert_eq!(status, 400, "{body}");
        assert_eq!(body["error"], "out_of_limits", "{body}");
    }
    assert_eq!(op.get_ok("/api/tags/RTU1.Setpoint")["value"], 31.5);
    let refused = events(&mut admin, "kind=write_refused");
    assert!(
        refused.iter().any(|e| e["message"]
            .as_str()
            .is_some_and(|m| m.contains("engineering limits"))),
        "{refused:?}"
    );
    // A u64 beyond 2^53 is exact end to end: written as a JSON number or as
    // its digits, read back over the API as digits, logged exactly.
    let big = "12345678901234567891";
    let (status, body) = op.post(
        "/api/tags/RTU1.Energy_Wh/write",
        json!({"value": 12_345_678_901_234_567_890u64}),
    );
    assert_eq!(status, 200, "{body}");
    assert_eq!(body["value"], "12345678901234567890", "{body}");
    let (status, body) = op.post("/api/tags/RTU1.Energy_Wh/write", json!({"value": big}));
    assert_eq!(status, 200, "{body}");
    assert_eq!(body["value"], big, "{body}");
    assert_eq!(op.get_ok("/api/tags/RTU1.Energy_Wh")["value"], big);
    let csv = wait_for(
        "the meter in the historian",
        Duration::from_secs(20),
        || {
            let to = now_ms() + 60_000;
            let (_, text) = admin.get(&format!(
                "/api/trends.csv?tags=RTU1.Energy_Wh&from=0&to={to}"
            ));
            let text = text.as_str().unwrap_or_default().to_string();
            text.contains(&format!(",RTU1.Energy_Wh,{big},good"))
                .then_some(text)
        },
    );
    assert!(
        csv.contains(",RTU1.Energy_Wh,12345678901234567890,good"),
        "{csv}"
    );
    let found = op.get_ok("/api/tags?search=rtu1.set&limit=10");
    assert_eq!(found["total"], 1);
    assert_eq!(found["tags"][0]["source"]["device"], "RTU1");
    assert_eq!(found["tags"][0]["source"]["table"], "holding_register");

    // A device taken offline shows within two scans (plus its timeout), and comes back.
    let (status, body) = admin.post("/api/sim/devices/RTU1/offline", json!({}));
    assert!(status < 300, "{status} {body}");
    wait_for("RTU1 shown as lost", Duration::from_secs(3), || {
        devices(&mut admin)
            .into_iter()
            .find(|d| d["name"] == "RTU1" && d["connected"] == false)
    });
    let (status, _) = admin.post("/api/sim/devices/RTU1/online", json!({}));
    assert!(status < 300);
    let back = wait_for("RTU1 back", Duration::from_secs(20), || {
        devices(&mut admin)
            .into_iter()
            .find(|d| d["name"] == "RTU1" && d["connected"] == true)
    });
    assert!(back["timeouts"].as_u64().unwrap() >= 1, "{back}");

    // A second start keeps the stored screen (unchanged file: no new version).
    drop(op);
    drop(admin);
    drop(demo);
    let demo = Demo::start_with(
        &data,
        &dir.path().join("demo.log"),
        &["--config".as_ref(), plant.as_os_str()],
    );
    let mut admin = demo.login("administrator");
    assert_eq!(admin.get_ok("/api/screens/pumps")["version"], 1);
}
