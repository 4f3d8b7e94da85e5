//! Fault isolation over the full stack, as `gridscada demo` runs it: the
//! demo plant (`tags/`), the simulators serving it over Modbus TCP, the
//! poller (`FieldIo`) filling the tag database, and one `run_panel` sequence
//! per panel. The panel's signals sit on separate Modbus devices behind one
//! gateway, each scanned every 500 ms (plant time), so status readings arrive
//! asynchronously and out of order; the simulator's breakers follow their
//! commands after 50 ms and the ELCB trips the instant a faulty zone is
//! energised.
//!
//! The plant runs on a `ScaledClock` (scan periods, sim steps, panel timers
//! and Modbus timeouts all scale), with the seed's panel timings (reclose 3 s,
//! dwell 1 s, confirm 2 s). Tests wait on conditions with generous wall-time
//! limits, never on fixed sleeps, except where nothing must happen.

use std::path::Path;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use gridscada_config::{PanelMode, Plant};
use gridscada_control::fault_isolation::{
    self, PanelCommand, PanelCommandKind, PanelNotice, PanelStatus,
};
use gridscada_sim::{BindMode, FaultKind, PanelSnapshot, SimHandle, Simulator};
use gridscada_tagdb::{Clock, ScaledClock, TagDb, Timestamp};
use tokio::sync::{mpsc, oneshot, watch};

/// Plant seconds per wall second. Kept low: a stall of the test process
/// counts `SPEED` times over in plant time, and the ELCB must still be read
/// within the dwell (1 s) after a load is energised: scan 0.5 s + breaker
/// 0.05 s leaves 0.45 s of plant time, i.e. 225 ms of wall time at speed 2.
const SPEED: f64 = 2.0;
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
        // Generous request timeouts (plant time; 500 ms of wall time at this
        // speed), so a loaded CI machine does not turn into a comm fault.
        // Scan periods stay as configured (500 ms for the panel I/O).
        for d in &mut plant.devices {
            *d.timeout_ms.get_mut() = 1000;
        }
        let mut tags: Vec<_> = plant.tag_metas().collect();
        tags.extend(gridscada_modbus::device_status_tags(&plant));
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

/// Status inputs lag by up to a scan period (500 ms) plus the breaker delay,
/// and the seed's bound counts only reclose delays and dwells. Allowance: one
/// scan plus margin for each status confirmation on the critical path (the
/// opens and the ELCB reset after each trip, each close, each trip read).
fn io_allowance_s(zones: u8, trips: u32) -> f64 {
    let confirmations = f64::from(zones) + 1.0 + 3.0 * f64::from(trips);
    confirmations * 0.6
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn permanent_fault_on_zone_2_is_isolated_then_restored_after_repair() {
    let _one = ONE_AT_A_TIME.lock().await;
    let s = Stack::start().await;
    let css1_before = s.snap("css1");
    let ss1_trips_before = s.snap("ss1").elcb_trips;
    let wall = Instant::now();
    s.sim
        .inject_zone_fault("ss1", 2, FaultKind::Permanent)
        .unwrap();
    s.wait_sequence_end("ss1").await;
    let st = s.status("ss1");
    let m = &st.last_sequence;
    println!(
        "full stack, permanent fault on zone 2 of ss1: restore_s = {:.2}, bound_s = {:.1} \
         (trips {}, switching ops {}, wall {:.1} s at speed {SPEED})",
        m.restore_s,
        m.bound_s,
        m.trips,
        m.switching_ops,
        wall.elapsed().as_secs_f64()
    );
    assert_eq!(st.step, "isolated", "{st:#?}\n{:#?}", s.events("ss1"));
    assert!(!st.lockout);
    assert_eq!(st.faulty_zones, vec![2]);
    assert_eq!(m.reenergisations, 1);
    assert_eq!(m.trips, 2);
    assert!(m.restore_s > 0.0);
    assert!(
        m.restore_s <= m.bound_s + io_allowance_s(4, m.trips),
        "restore {} vs bound {} + I/O allowance",
        m.restore_s,
        m.bound_s
    );
    // The plant agrees: zone 2 open, the rest on, ELCB closed.
    s.wait("ss1 breakers as isolated", |s| {
        let p = s.snap("ss1");
        p.elcb_closed && p.mccb.closed && closed_zones(&p) == [1, 3, 4]
    })
    .await;
    let p = s.snap("ss1");
    assert_eq!(energised_zones(&p), [1, 3, 4]);
    assert_eq!(
        p.elcb_trips - ss1_trips_before,
        2,
        "the injection trip and one re-energisation of zone 2"
    );
    let events = s.events("ss1");
    assert!(events
        .iter()
        .any(|(k, m)| k == "fault_found" && m.contains("zone 2")));
    assert!(
        !events.iter().any(|(k, _)| k == "transient_fault"),
        "{events:#?}"
    );
    // The other panel was not touched.
    let css1 = s.snap("css1");
    assert_eq!(css1.elcb_trips, css1_before.elcb_trips);
    assert_eq!(operations(&css1), operations(&css1_before));
    assert!(css1.elcb_closed && closed_zones(&css1) == [1, 2, 3, 4]);
    let st = s.status("css1");
    assert_eq!((st.step.as_str(), st.lockout), ("idle", false));
    assert!(s.events("css1").iter().all(|(k, _)| k != "trip"));

    // Repair, then Reset: zone 2 comes back, healthy zones are not touched.
    let ops_before = operations(&s.snap("ss1"));
    s.sim.repair_zone("ss1", 2).unwrap();
    s.command("ss1", PanelCommandKind::Reset).await;
    s.wait("ss1 zone 2 back after Reset", |s| {
        let st = s.status("ss1");
        let p = s.snap("ss1");
        st.step == "idle"
            && st.faulty_zones.is_empty()
            && p.elcb_closed
            && closed_zones(&p) == [1, 2, 3, 4]
    })
    .await;
    let st = s.status("ss1");
    assert!(!st.lockout && st.breakers.values().all(|b| b.closed && b.good));
    let ops = operations(&s.snap("ss1"));
    assert_eq!(ops[0], ops_before[0], "MCCB not switched on Reset");
    assert_eq!(ops[1], ops_before[1], "zone 1 not switched on Reset");
    assert_eq!(ops[2], ops_before[2] + 1, "zone 2 closed once");
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
    // Longer than a whole automatic sequence would need to act (reclose
    // delay + confirmation), in plant time: nothing may happen.
    s.clock.sleep(Duration::from_secs(8)).await;
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
    println!(
        "full stack, transient fault on zone 2 of ss1: restore_s = {:.2}, bound_s = {:.1}",
        m.restore_s, m.bound_s
    );
    assert_eq!(st.step, "idle", "{st:#?}\n{:#?}", s.events("ss1"));
    assert!(!st.lockout && st.faulty_zones.is_empty());
    assert_eq!(m.trips, 1);
    assert!(
        m.restore_s <= m.bound_s + io_allowance_s(4, m.trips),
        "{m:?}"
    );
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
    println!(
        "full stack, permanent faults on zones 2 and 4 of ss1: restore_s = {:.2}, bound_s = {:.1} \
         (trips {})",
        m.restore_s, m.bound_s, m.trips
    );
    assert_eq!(st.step, "isolated", "{st:#?}\n{:#?}", s.events("ss1"));
    assert!(!st.lockout);
    assert_eq!(st.faulty_zones, vec![2, 4]);
    assert_eq!(m.reenergisations, 2, "each faulty zone re-energised once");
    assert_eq!(m.trips, 3);
    s.wait("ss1 exactly zones 1 and 3 on", |s| {
        let p = s.snap("ss1");
        p.elcb_closed && p.mccb.closed && closed_zones(&p) == [1, 3]
    })
    .await;
    let p = s.snap("ss1");
    assert_eq!(energised_zones(&p), [1, 3]);
    assert_eq!(p.elcb_trips - trips_before, 3);
    assert_eq!(s.snap("css1").elcb_trips, 0);
}
