//! Two sites on one PostgreSQL database: two copies of the demo plant, each
//! run by its own `gridscada serve` with its own `[server] site` and its own
//! simulated devices (`gridscada sim`, on other ports).
//!
//! - Each server polls only its own devices: the south site's simulator
//!   stops, the south server's devices go offline and its comm alarms
//!   stand, while the north server's stay online and normal.
//! - Each reads the other's events, alarm history, trends and dispatches
//!   through `site=`, exactly as the other server serves them itself.
//! - No write of one touches the other's rows: the same alarm keys and
//!   panel ids are kept apart in the database (an active comm alarm of the
//!   south stays in its state row while the north writes the same key).

use crate::common;

use std::path::Path;
use std::time::Duration;

use common::pair::*;
use common::{now_ms, wait_for, Client};
use serde_json::Value;

fn ids(list: &Value, field: &str) -> Vec<i64> {
    list[field]
        .as_array()
        .unwrap_or_else(|| panic!("no {field} in {list}"))
        .iter()
        .map(|e| e["id"].as_i64().unwrap())
        .collect()
}

/// Whether every device of the server at `c` is connected (`true`) or none
/// is (`false`); `None` while they differ. Each address is checked to be in
/// the server's own port range.
fn devices_connected(c: &mut Client, ports: std::ops::Range<u16>) -> Option<bool> {
    let list = c.get_ok("/api/devices")["devices"]
        .as_array()
        .unwrap()
        .clone();
    assert!(!list.is_empty());
    for d in &list {
        let port: u16 = d["address"]
            .as_str()
            .and_then(|a| a.rsplit(':').next())
            .and_then(|p| p.parse().ok())
            .unwrap_or_else(|| panic!("device address {d}"));
        assert!(ports.contains(&port), "{} polls port {port}", d["name"]);
    }
    let connected: Vec<bool> = list
        .iter()
        .map(|d| d["connected"].as_bool().unwrap())
        .collect();
    if connected.iter().all(|c| *c) {
        Some(true)
    } else if connected.iter().all(|c| !*c) {
        Some(false)
    } else {
        None
    }
}

fn start(name: &'static str, config: &Path, dir: &Path) -> Server {
    let mut s = Server {
        name,
        config: config.to_path_buf(),
        port: free_port(),
        log: dir.join(format!("{name}.log")),
        child: None,
    };
    s.start();
    s
}

#[test]
fn two_sites_share_a_database_and_read_each_others_history() {
    let Ok(base) = std::env::var("GRIDSCADA_TEST_PG_URL") else {
        assert!(
            std::env::var("GRIDSCADA_REQUIRE_PG").as_deref() != Ok("1"),
            "GRIDSCADA_REQUIRE_PG=1 but GRIDSCADA_TEST_PG_URL is not set"
        );
        eprintln!("!!!!!!!! SKIPPED two-sites test: GRIDSCADA_TEST_PG_URL is not set !!!!!!!!");
        return;
    };
    let db = Database::create(&base);
    let dir = tempfile::tempdir().unwrap();
    let north_base = port_block(100);
    let south_base = port_block(100);
    let north_cfg = write_site_plant(&dir.path().join("north"), &db.url, "north", north_base);
    let south_cfg = write_site_plant(&dir.path().join("south"), &db.url, "south", south_base);
    let _north_sim = Sim::start(&north_cfg, &dir.path().join("north-sim.log"));
    let south_sim = Sim::start(&south_cfg, &dir.path().join("south-sim.log"));
    // Users are shared by the database: one operator for both sites.
    add_operator(&north_cfg);
    let started = now_ms();
    let north = start("north", &north_cfg, dir.path());
    let south = start("south", &south_cfg, dir.path());
    let mut n = login(&north.addr());
    let mut s = login(&south.addr());

    // Each polls its own devices, all of them answering.
    let north_ports = north_base..north_base + 100;
    let south_ports = south_base..south_base + 100;
    wait_for("north's devices online", Duration::from_secs(30), || {
        devices_connected(&mut n, north_ports.clone()).filter(|c| *c)
    });
    wait_for("south's devices online", Duration::from_secs(30), || {
        devices_connected(&mut s, south_ports.clone()).filter(|c| *c)
    });
    let sites = n.get_ok("/api/sites");
    assert_eq!(sites["site"], "north");
    assert_eq!(sites["sites"], serde_json::json!(["north", "south"]));

    // The south's devices stop answering: only the south sees it.
    drop(south_sim);
    wait_for("south's devices offline", Duration::from_secs(30), || {
        devices_connected(&mut s, south_ports.clone()).filter(|c| !*c)
    });
    const COMM: &str = "SS1.PA:comm";
    wait_for("the south's comm alarm", Duration::from_secs(30), || {
        (common::alarm(&mut s, COMM)["active"] == true).then_some(())
    });
    // Both servers' recorders have had time to write (states, history).
    std::thread::sleep(Duration::from_secs(3));
    // The north's devices still answer. On a loaded machine (the whole suite
    // runs beside this test) one of its hundred may miss a poll deadline for a
    // moment, so the north is given the time it takes to read them again.
    wait_for("north's devices online", Duration::from_secs(30), || {
        devices_connected(&mut n, north_ports.clone()).filter(|c| *c)
    });
    assert_eq!(common::alarm(&mut n, COMM)["active"], false);
    // The same alarm key in each site's own state row: the north's normal
    // state did not overwrite the south's standing alarm.
    let south_states = rows(
        &db.url,
        &format!("SELECT state FROM alarm_states WHERE site = 'south' AND alarm_key = '{COMM}'"),
    );
    assert_eq!(south_states.len(), 1, "{south_states:?}");
    assert_ne!(south_states[0], "normal");
    assert!(rows(
        &db.url,
        &format!("SELECT state FROM alarm_states WHERE site = 'north' AND alarm_key = '{COMM}'"),
    )
    .iter()
    .all(|s| s == "normal"));
    // Each site's panels have their own retained state, under the same ids.
    let panels = rows(
        &db.url,
        "SELECT site || ' ' || panel_id FROM panel_states ORDER BY 1",
    );
    let north_panels: Vec<&String> = panels.iter().filter(|p| p.starts_with("north ")).collect();
    let south_panels: Vec<&String> = panels.iter().filter(|p| p.starts_with("south ")).collect();
    assert!(!north_panels.is_empty(), "{panels:?}");
    assert_eq!(north_panels.len(), south_panels.len(), "{panels:?}");
    assert_eq!(
        rows(&db.url, "SELECT DISTINCT site FROM events ORDER BY 1"),
        vec!["north", "south"]
    );

    // Each reads the other's history as the other serves it, and its own is
    // its own.
    // A range that ended before the writers' last flush, so that both reads
    // see the same rows.
    let now = now_ms();
    std::thread::sleep(Duration::from_secs(3));
    let q = format!("from={started}&to={now}&limit=10000");
    for round in 0..2 {
        let (own, other, other_site) = if round == 0 {
            (&mut n, &mut s, "south")
        } else {
            (&mut s, &mut n, "north")
        };
        for (path, field) in [
            ("/api/events", "events"),
            ("/api/alarms/history", "transitions"),
        ] {
            let theirs = ids(&other.get_ok(&format!("{path}?{q}")), field);
            let read = ids(&own.get_ok(&format!("{path}?{q}&site={other_site}")), field);
            // The north has no alarm: only its events are sure to be there.
            if field == "events" || other_site == "south" {
                assert!(!theirs.is_empty(), "{other_site} has {field}");
            }
            assert_eq!(read, theirs, "{path} of {other_site}");
            let mine = ids(&own.get_ok(&format!("{path}?{q}")), field);
            assert!(
                mine.iter().all(|id| !theirs.contains(id)),
                "{path}: a row of {other_site} is in the other's own list"
            );
        }
        let trend = format!("/api/trends?tags=SS1.PA.V_L1&from={started}&to={now}&points=20");
        let theirs = other.get_ok(&trend);
        assert!(
            theirs["series"][0]["buckets"]
                .as_array()
                .is_some_and(|b| b.iter().any(|b| b["count"].as_u64() > Some(0))),
            "{theirs}"
        );
        assert_eq!(
            own.get_ok(&format!("{trend}&site={other_site}")),
            theirs,
            "trend of {other_site}"
        );
        let csv = format!("/api/trends.csv?tags=SS1.PA.V_L1&from={started}&to={now}");
        assert_eq!(
            own.get(&format!("{csv}&site={other_site}")),
            other.get(&csv),
            "CSV of {other_site}"
        );
        assert_eq!(
            own.get_ok(&format!(
                "/api/dispatch/history?from={started}&to={now}&site={other_site}"
            )),
            other.get_ok(&format!("/api/dispatch/history?from={started}&to={now}")),
        );
    }
    // The south's outage is in the south's alarm history only.
    let outage = |c: &mut Client, site: &str| -> usize {
        c.get_ok(&format!("/api/alarms/history?{q}&key={COMM}&site={site}"))["count"]
            .as_u64()
            .unwrap() as usize
    };
    assert!(outage(&mut n, "south") > 0);
    assert_eq!(outage(&mut n, "north"), 0);
    // A site not in the database, and a malformed one, are refused.
    assert_eq!(n.get(&format!("/api/events?{q}&site=west")).0, 404);
    assert_eq!(n.get(&format!("/api/events?{q}&site=a%20b")).0, 400);
}
