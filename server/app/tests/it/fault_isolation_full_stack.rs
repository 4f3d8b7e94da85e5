//! Fault isolation over the full stack, as `gridscada demo` runs it: the
//! demo plant (`tags/`), the simulators serving it over Modbus TCP, the
//! poller (`FieldIo`) filling the tag database, and one `run_panel` sequence
//! per panel. The panel's signals sit on separate Modbus devices behind one
//! gateway, each scanned as the demo plant says (100-200 ms, plant time), so
//! status readings arrive asynchronously and out of order; the simulator's
//! breakers follow their commands after 50 ms and the ELCB trips the instant
//! a faulty zone is energised.
//!
//! The plant runs on a `ScaledClock` (scan periods, sim steps, panel timers
//! and Modbus timeouts all scale), with the seed's panel timings (reclose 3 s,
//! dwell 1 s, confirm 2 s). Restore times are asserted against the seed's
//! bound 2 × reclose + (N + 1) × dwell with no I/O allowance: the sequence
//! overlaps its status confirmations with the reclose delay and the dwells, so
//! only about four status latencies (scan + breaker time) stay on the
//! critical path. Tests wait on conditions with generous wall-time limits,
//! never on fixed sleeps, except where nothing must happen.

use std::path::Path;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use gridscada_config::{PanelMode, Plant};
use gridscada_control::fault_isolation::{
    self, Metrics, PanelCommand, PanelCommandKind, PanelNotice, PanelStatus,
};
use gridscada_sim::{BindMode, FaultKind, PanelSnapshot, SimHandle, Simulator};
use gridscada_tagdb::{Clock, ScaledClock, TagDb, Timestamp};
use tokio::sync::{mpsc, oneshot, watch};

/// Plant seconds per wall second. Kept low: a stall of the test process
/// counts `SPEED` times over in plant time. The ELCB must be read within the
/// dwell (1 s) after a load is energised (scan 0.1 s + breaker 0.05 s), a
/// device not answering for two scan periods (0.2 s) turns its signals Bad
/// (the sequence suspends and restarts its step, which costs a dwell), and
/// the restore time has about 0.6 s of margin to the bound. At 1.5 a stall
/// of up to ~130 ms of wall time goes unnoticed.
const SPEED: f64 = 1.5;
/// Wall-time limit on any one wait.
const WAIT: Duration = Duration::from_secs(45);

/// The scenarios run one at a time (each on its own stack), so they do not
/// compete for the CPU (see `SPEED`).
static ONE_AT_A_TIME: tokio::sync::Mutex<()> = tokio::sync::Mutex::const_new(());

struct Panel {
    commands: mpsc::Sender<PanelCommand>,
    status: watch::Receiver<PanelStatus>,
}

struct Stack {
    clock: Arc<dyn Clock>,
    sim: SimHandle,
    ss1: Panel,
    css1: Panel,
    notices: Arc<Mutex<Vec<PanelNotice>>>,
    panels: Vec<gridscada_config::PanelConfig>,
    // Kept alive for the test; dropped (stopped) at its end.
    _simulator: Simulator,
    _field: gridscada_modbus::FieldIo,
}

impl Stack {
    async fn start() -> Stack {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tags");
        let mut plant: Plant = gridscada_config::load_path(&dir)
            .unwrap_or_else(|d| panic!("demo plant in {}: {d:?}", dir.display()));
        let clock: Arc<dyn Clock> = Arc::new(ScaledClock::new(Timestamp::now_utc(), SPEED));
        let simulator = gridscada_sim::start(&plant, clock.clone(), BindMode::Ephemeral)
            .await
            .expect("simulator starts");
        simulator.patch_plant(&mut plant);
        // Generous request timeouts (plant time), so a loaded CI machine does
        // not turn into a comm fault. Scan periods stay as configured (100 ms
        // for the panel's status modules, 200 ms for the zone command module).
        for d in &mut plant.devices {
            *d.timeout_ms.get_mut() = 1000;
        }
        let mut tags: Vec<_> = plant.tag_metas().collect();
        tags.extend(gridscada_field::device_status_tags(&plant));
        for p in &plant.panels {
            tags.extend(fault_isolation::panel_tags(p));
        }
        let db = Arc::new(TagDb::new(tags).expect("tag database"));
        let field = gridscada_modbus::FieldIo::start(&plant, db.clone(), clock.clone())
            .expect("field I/O starts");
        let writer = field.writer();

        let notices = Arc::new(Mutex::new(Vec::new()));
        let (notices_tx, mut notices_rx) = mpsc::channel::<PanelNotice>(1024);
        let sink = notices.clone();
        tokio::spawn(async move {
            while let Some(n) = notices_rx.recv().await {
                sink.lock().unwrap().push(n);
            }
        });
        let mut panels = Vec::new();
        for p in &plant.panels {
            let (cmd_tx, cmd_rx) = mpsc::channel(16);
            let (status_tx, status_rx) = watch::channel(PanelStatus::initial(p));
            tokio::spawn(fault_isolation::run_panel(
                p.clone(),
                db.clone(),
                writer.clone(),
                clock.clone(),
                cmd_rx,
                status_tx,
                notices_tx.clone(),
                None,
            ));
            panels.push((
                p.id.get_ref().clone(),
                Panel {
                    commands: cmd_tx,
                    status: status_rx,
                },
            ));
        }
        let mut take = |id: &str| {
            let i = panels
                .iter()
                .position(|(p, _)| p == id)
                .unwrap_or_else(|| panic!("demo plant has no panel '{id}'"));
            panels.remove(i).1
        };
        let ss1 = take("ss1");
        let css1 = take("css1");
        let stack = Stack {
            clock,
            sim: simulator.handle(),
            ss1,
            css1,
            notices,
            panels: plant.panels.clone(),
            _simulator: simulator,
            _field: field,
        };
        // Both panels read, every signal Good, everything on.
        for id in ["ss1", "css1"] {
            stack
                .wait(&format!("{id} ready"), |s| {
                    let st = s.status(id);
                    let p = s.snap(id);
                    st.comm_ok
                        && st.step == "idle"
                        && st.breakers.values().all(|b| b.good && b.closed)
                        && p.elcb_closed
                        && p.mccb.closed
                        && p.zones.iter().all(|z| z.breaker.closed)
                })
                .await;
        }
        stack
    }

    fn panel(&self, id: &str) -> &Panel {
        match id {
            "ss1" => &self.ss1,
            "css1" => &self.css1,
            _ => panic!("no panel {id}"),
        }
    }

    fn plant_panel(&self, id: &str) -> gridscada_config::PanelConfig {
        self.panels
            .iter()
            .find(|p| p.id.get_ref() == id)
            .unwrap_or_else(|| panic!("demo plant has no panel '{id}'"))
            .clone()
    }

    fn status(&self, id: &str) -> PanelStatus {
        self.panel(id).status.borrow().clone()
    }

    fn snap(&self, id: &str) -> PanelSnapshot {
        self.sim
            .snapshot()
            .panel(id)
            .unwrap_or_else(|| panic!("simulator has no panel {id}"))
            .clone()
    }

    /// Waits (wall time, bounded) until `cond` holds.
    async fn wait(&self, what: &str, cond: impl Fn(&Stack) -> bool) {
        let start = Instant::now();
        while !cond(self) {
            if start.elapsed() > WAIT {
                panic!(
                    "timed out waiting for {what}\nss1: {:#?}\nss1 sim: {:#?}\nnotices: {:#?}",
                    self.status("ss1"),
                    self.snap("ss1"),
                    self.notices.lock().unwrap()
                );
            }
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
    }

    async fn command(&self, id: &str, kind: PanelCommandKind) {
        let (reply, rx) = oneshot::channel();
        self.panel(id)
            .commands
            .send(PanelCommand {
                user: "test".into(),
                kind: kind.clone(),
                reply,
            })
            .await
            .expect("panel task running");
        let r = tokio::time::timeout(WAIT, rx)
            .await
            .expect("command answered in time")
            .expect("reply sent");
        assert_eq!(r, Ok(()), "{kind:?}");
    }

    fn events(&self, panel: &str) -> Vec<(String, String)> {
        self.notices
            .lock()
            .unwrap()
            .iter()
            .filter_map(|n| match n {
                PanelNotice::Event {
                    panel: p,
                    kind,
                    message,
                    ..
                } if p == panel => Some((kind.clone(), message.clone())),
                _ => None,
            })
            .collect()
    }

    /// Waits until the sequence of `id` has ended after a trip (a rest step
    /// with a finished outcome).
    async fn wait_sequence_end(&self, id: &str) {
        self.wait(&format!("{id} sequence to end"), |s| {
            let st = s.status(id);
            st.last_sequence.trips >= 1
                && matches!(st.step.as_str(), "idle" | "isolated" | "lockout")
        })
        .await;
    }
}

fn closed_zones(p: &PanelSnapshot) -> Vec<u8> {
    p.zones
        .iter()
        .filter(|z| z.breaker.closed)
        .map(|z| z.zone)
        .collect()
}

fn energised_zones(p: &PanelSnapshot) -> Vec<u8> {
    p.zones
        .iter()
        .filter(|z| z.energised)
        .map(|z| z.zone)
        .collect()
}

/// Contact movements of every breaker of a panel.
fn operations(p: &PanelSnapshot) -> Vec<u64> {
    std::iter::once(p.mccb.operations)
        .chain(p.zones.iter().map(|z| z.breaker.operations))
        .collect()
}

/// Whether the sequence suspended on a communication gap. The seed's bound is
/// for an uninterrupted sequence; a test machine stalled long enough for the
/// poller to mark the panel's signals Bad (two 100 ms scans) makes the
/// sequence suspend and restart its step, as it must. Then the outcome is
/// still asserted in full, and the restore time is reported, not asserted.
fn was_suspended(events: &[(String, String)]) -> bool {
    events
        .iter()
        .any(|(k, m)| k == "step" && m.starts_with("suspended"))
}

/// Asserts `restore_s <= bound` unless the sequence was suspended.
fn assert_within(what: &str, restore_s: f64, bound: f64, events: &[(String, String)]) {
    if was_suspended(events) {
        println!("{what}: restore {restore_s:.2} s vs bound {bound:.1} s not asserted: the sequence suspended on a communication gap (machine stalled)");
        return;
    }
    assert!(
        restore_s <= bound,
        "{what}: restore {restore_s:.2} s over the bound {bound:.1} s\n{events:#?}"
    );
}

/// The healthy zones are back, the faulty one isolated: step, faulty set,
/// re-energisations, trips, and restore time within the seed's bound.
fn check_isolated(s: &Stack, id: &str, zone: u8) -> Metrics {
    let st = s.status(id);
    let m = st.last_sequence.clone();
    let ctx = format!("{id} zone {zone}: {st:#?}\n{:#?}", s.events(id));
    assert_eq!(st.step, "isolated", "{ctx}");
    assert!(!st.lockout, "{ctx}");
    assert_eq!(st.faulty_zones, vec![zone], "{ctx}");
    assert_eq!(m.reenergisations, 1, "{ctx}");
    assert_eq!(m.trips, 2, "{ctx}");
    let restore_s = m.restore_s.expect(&ctx);
    assert!(restore_s > 0.0, "{ctx}");
    assert_within(
        &format!("{id} zone {zone}"),
        restore_s,
        m.bound_s,
        &s.events(id),
    );
    m
}

/// Repairs `zone` of `id` and presses Reset: the zone comes back, closed
/// once, and no other breaker is switched.
async fn repair_and_reset(s: &Stack, id: &str, zone: u8) {
    let ops_before = operations(&s.snap(id));
    s.sim.repair_zone(id, zone).unwrap();
    s.command(id, PanelCommandKind::Reset).await;
    s.wait(&format!("{id} zone {zone} back after Reset"), |s| {
        let st = s.status(id);
        let p = s.snap(id);
        st.step == "idle"
            && st.faulty_zones.is_empty()
            && p.elcb_closed
            && closed_zones(&p) == [1, 2, 3, 4]
            && st.breakers.values().all(|b| b.closed && b.good)
    })
    .await;
    assert!(!s.status(id).lockout);
    let ops = operations(&s.snap(id));
    for (i, (now, before)) in ops.iter().zip(&ops_before).enumerate() {
        let want = before + u64::from(i == usize::from(zone));
        assert_eq!(
            *now, want,
            "{id}: load {i} switched on Reset after repairing zone {zone}"
        );
    }
}

/// The acceptance criterion: a permanent fault on any zone of either panel
/// is isolated and the healthy zones come back within the seed's bound
/// 2 × reclose + (N + 1) × dwell, over the real I/O path. Both panels run
/// their sequences at the same time (ss1 zone k, css1 zone 5 − k), then are
/// repaired and Reset for the next round.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn permanent_fault_on_any_zone_is_isolated_within_the_bound() {
    let _one = ONE_AT_A_TIME.lock().await;
    let s = Stack::start().await;
    let mut table = Vec::new();
    for k in 1..=4u8 {
        let faults = [("ss1", k), ("css1", 5 - k)];
        let trips_before: Vec<u64> = faults.iter().map(|(id, _)| s.snap(id).elcb_trips).collect();
        let wall = Instant::now();
        for (id, zone) in faults {
            s.sim
                .inject_zone_fault(id, zone, FaultKind::Permanent)
                .unwrap();
        }
        for (id, _) in faults {
            s.wait_sequence_end(id).await;
        }
        let wall_s = wall.elapsed().as_secs_f64();
        for ((id, zone), trips_before) in faults.into_iter().zip(trips_before) {
            let m = check_isolated(&s, id, zone);
            let restore_s = m.restore_s.unwrap_or(f64::NAN);
            table.push((id, zone, restore_s, m.bound_s, m.switching_ops, wall_s));
            let healthy: Vec<u8> = (1..=4).filter(|z| *z != zone).collect();
            s.wait(&format!("{id} breakers as isolated"), |s| {
                let p = s.snap(id);
                p.elcb_closed && p.mccb.closed && closed_zones(&p) == healthy
            })
            .await;
            let p = s.snap(id);
            assert_eq!(energised_zones(&p), healthy, "{id} zone {zone}");
            assert_eq!(
                p.elcb_trips - trips_before,
                2,
                "{id} zone {zone}: the injection trip and one re-energisation"
            );
            let found = format!("zone {zone} MCB");
            let events = s.events(id);
            assert!(
                events
                    .iter()
                    .any(|(k, m)| k == "fault_found" && m.contains(&found)),
                "{events:#?}"
            );
        }
        for (id, zone) in faults {
            repair_and_reset(&s, id, zone).await;
        }
    }
    println!("panel | faulty zone | restore_s | bound_s | switching_ops | wall_s (speed {SPEED})");
    for (id, zone, restore, bound, ops, wall) in &table {
        println!("{id} | {zone} | {restore:.2} | {bound:.1} | {ops} | {wall:.1}");
    }
    // Every sequence found its fault: none ended as a transient fault.
    for id in ["ss1", "css1"] {
        assert!(s.events(id).iter().all(|(k, _)| k != "transient_fault"));
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn manual_mode_switches_nothing_by_itself() {
    let _one = ONE_AT_A_TIME.lock().await;
    let s = Stack::start().await;
    s.command("ss1", PanelCommandKind::SetMode(PanelMode::Manual))
        .await;
    s.wait("ss1 in manual", |s| {
        let st = s.status("ss1");
        st.mode == PanelMode::Manual && st.step == "manual"
    })
    .await;
    let before = s.snap("ss1");
    s.sim
        .inject_zone_fault("ss1", 2, FaultKind::Permanent)
        .unwrap();
    s.wait("ss1 ELCB read open", |s| {
        s.status("ss1")
            .breakers
            .get("elcb")
            .is_some_and(|b| b.good && !b.closed)
    })
    .await;
    // Longer than an automatic sequence would need to act (reclose delay +
    // confirmation), in plant time: nothing may happen.
    s.clock.sleep(Duration::from_secs(5)).await;
    let p = s.snap("ss1");
    assert!(!p.elcb_closed, "ELCB must stay tripped in manual mode");
    assert_eq!(operations(&p), operations(&before), "no breaker switched");
    assert!(p.mccb.closed && closed_zones(&p) == [1, 2, 3, 4]);
    let st = s.status("ss1");
    assert_eq!(st.step, "manual");
    assert_eq!(st.mode, PanelMode::Manual);
    assert!(!st.lockout);
    assert!(s
        .events("ss1")
        .iter()
        .all(|(k, _)| k != "trip" && k != "fault_found"));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn transient_fault_restores_every_zone() {
    let _one = ONE_AT_A_TIME.lock().await;
    let s = Stack::start().await;
    s.sim
        .inject_zone_fault("ss1", 2, FaultKind::Transient)
        .unwrap();
    s.wait_sequence_end("ss1").await;
    let st = s.status("ss1");
    let m = &st.last_sequence;
    let restore_s = m.restore_s.expect("a restored sequence has a restore time");
    println!(
        "full stack, transient fault on zone 2 of ss1: restore_s = {restore_s:.2}, bound_s = {:.1}",
        m.bound_s
    );
    assert_eq!(st.step, "idle", "{st:#?}\n{:#?}", s.events("ss1"));
    assert!(!st.lockout && st.faulty_zones.is_empty());
    assert_eq!(m.trips, 1);
    assert!(restore_s > 0.0, "{m:?}");
    assert_within("transient fault", restore_s, m.bound_s, &s.events("ss1"));
    let events = s.events("ss1");
    assert!(
        events.iter().any(|(k, _)| k == "transient_fault"),
        "{events:#?}"
    );
    s.wait("ss1 all zones on", |s| {
        let p = s.snap("ss1");
        p.elcb_closed && p.mccb.closed && energised_zones(&p) == [1, 2, 3, 4]
    })
    .await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn two_faulty_zones_leave_exactly_the_healthy_ones_on() {
    let _one = ONE_AT_A_TIME.lock().await;
    let s = Stack::start().await;
    let trips_before = s.snap("ss1").elcb_trips;
    let css1_before = s.snap("css1");
    // Zone 4 develops its fault too (it is de-energised by zone 2's trip).
    s.sim
        .inject_zone_fault("ss1", 2, FaultKind::Permanent)
        .unwrap();
    s.sim
        .inject_zone_fault("ss1", 4, FaultKind::Permanent)
        .unwrap();
    s.wait_sequence_end("ss1").await;
    let st = s.status("ss1");
    let m = &st.last_sequence;
    let restore_s = m
        .restore_s
        .expect("an isolating sequence has a restore time");
    println!(
        "full stack, permanent faults on zones 2 and 4 of ss1: restore_s = {restore_s:.2}, bound_s = {:.1} \
         (trips {})",
        m.bound_s, m.trips
    );
    assert_eq!(st.step, "isolated", "{st:#?}\n{:#?}", s.events("ss1"));
    assert!(!st.lockout);
    assert_eq!(st.faulty_zones, vec![2, 4]);
    assert_eq!(m.reenergisations, 2, "each faulty zone re-energised once");
    assert_eq!(m.trips, 3);
    // The seed's bound is for one fault; each further fault costs one more
    // reclose delay and at most one more dwell.
    let settings = fault_isolation::Settings::from_panel(&s.plant_panel("ss1"));
    let bound = m.bound_s + settings.reclose_delay_s + settings.dwell_s;
    assert_within("two faulty zones", restore_s, bound, &s.events("ss1"));
    s.wait("ss1 exactly zones 1 and 3 on", |s| {
        let p = s.snap("ss1");
        p.elcb_closed && p.mccb.closed && closed_zones(&p) == [1, 3]
    })
    .await;
    let p = s.snap("ss1");
    assert_eq!(energised_zones(&p), [1, 3]);
    assert_eq!(p.elcb_trips - trips_before, 3);
    // The other panel was not touched.
    let css1 = s.snap("css1");
    assert_eq!(css1.elcb_trips, css1_before.elcb_trips);
    assert_eq!(operations(&css1), operations(&css1_before));
    assert!(css1.elcb_closed && closed_zones(&css1) == [1, 2, 3, 4]);
    let st = s.status("css1");
    assert_eq!((st.step.as_str(), st.lockout), ("idle", false));
    assert!(s.events("css1").iter().all(|(k, _)| k != "trip"));
}
