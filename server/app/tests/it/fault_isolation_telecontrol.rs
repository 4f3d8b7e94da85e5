//! Fault isolation over telecontrol: the test plant
//! `tests/plants/telecontrol` puts panel FX's breakers, ELCB and analyser
//! on a substation RTU reached over IEC 60870-5-104 (two addresses,
//! positions as double points, breaker commands as double commands with
//! select-before-operate), and panel FY's on a DNP3 outstation (positions
//! as double-bit inputs, CROBs with select-before-operate, unsolicited
//! events). The simulator serves both, driven by the panel models;
//! gridscada's IEC 104 controlling station (`Iec104Io`) and DNP3 master
//! (`Dnp3Io`) fill the tag database and carry the sequence's commands, each
//! confirmed by the station (ACT_CON and ACT_TERM; the echo's SUCCESS) and
//! by the returned status. The outcome must be the one the Modbus path
//! gives (`fault_isolation_full_stack`): the faulty zone isolated, the
//! healthy ones back, two ELCB trips and one re-energisation.

use std::path::Path;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use gridscada_config::{Plant, Protocol};
use gridscada_control::fault_isolation::{
    self, PanelCommand, PanelCommandKind, PanelNotice, PanelStatus,
};
use gridscada_sim::{BindMode, FaultKind};
use gridscada_tagdb::{Clock, Leadership, SystemClock, TagDb};
use tokio::sync::{mpsc, oneshot, watch};

const WAIT: Duration = Duration::from_secs(45);

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_permanent_fault_is_isolated_over_iec104_as_over_modbus() {
    isolate_a_permanent_fault("fx", Protocol::Iec104).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_permanent_fault_is_isolated_over_dnp3_as_over_modbus() {
    isolate_a_permanent_fault("fy", Protocol::Dnp3).await;
}

/// Panel `id`, whose I/O is on a device speaking `protocol`: zone 2 faulty,
/// isolated; repaired and reset, back.
async fn isolate_a_permanent_fault(id: &str, protocol: Protocol) {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/plants/telecontrol");
    let mut plant: Plant = gridscada_config::load_path(&dir)
        .unwrap_or_else(|d| panic!("test plant in {}: {d:?}", dir.display()));
    let clock: Arc<dyn Clock> = Arc::new(SystemClock);
    let simulator = gridscada_sim::start(&plant, clock.clone(), BindMode::Ephemeral)
        .await
        .expect("simulator starts");
    simulator.patch_plant(&mut plant);
    let sim = simulator.handle();

    let mut tags: Vec<_> = plant.tag_metas().collect();
    tags.extend(gridscada_field::device_status_tags(&plant));
    let panel = plant
        .panels
        .iter()
        .find(|p| p.id.get_ref() == id)
        .expect("panel of the test plant")
        .clone();
    tags.extend(fault_isolation::panel_tags(&panel));
    let db = Arc::new(TagDb::new(tags).expect("tag database"));
    let io = Field::start(protocol, &plant, db.clone(), clock.clone());

    let notices = Arc::new(Mutex::new(Vec::new()));
    let (notices_tx, mut notices_rx) = mpsc::channel::<PanelNotice>(1024);
    let sink = notices.clone();
    tokio::spawn(async move {
        while let Some(n) = notices_rx.recv().await {
            sink.lock().unwrap().push(n);
        }
    });
    let (commands, cmd_rx) = mpsc::channel(16);
    let (status_tx, status) = watch::channel(PanelStatus::initial(&panel));
    tokio::spawn(fault_isolation::run_panel(
        panel.clone(),
        db.clone(),
        io.writer(),
        clock.clone(),
        cmd_rx,
        status_tx,
        notices_tx,
        None,
    ));

    let events = || -> Vec<(String, String)> {
        notices
            .lock()
            .unwrap()
            .iter()
            .filter_map(|n| match n {
                PanelNotice::Event { kind, message, .. } => Some((kind.clone(), message.clone())),
                _ => None,
            })
            .collect()
    };
    let snap = || {
        sim.snapshot()
            .panel(id)
            .expect("panel of the plant")
            .clone()
    };
    let context = || format!("{:#?}\n{:#?}", status.borrow().clone(), events());
    // Everything read over IEC 104, Good, and on.
    until("the panel read, every breaker closed", &context, || {
        let st = status.borrow();
        st.comm_ok && st.step == "idle" && st.breakers.values().all(|b| b.good && b.closed)
    })
    .await;
    let p_kw = db
        .get_by_name(&format!("{}.PA.P_kW", panel.prefix.get_ref()))
        .expect("analyser power");
    assert!(p_kw.quality.is_good(), "{p_kw:?}");

    // A permanent fault on zone 2: the ELCB trips, the sequence opens
    // every zone, recloses, tries each zone in turn and isolates zone 2.
    let trips_before = snap().elcb_trips;
    sim.inject_zone_fault(id, 2, FaultKind::Permanent).unwrap();
    until("the sequence to end", &context, || {
        let st = status.borrow();
        st.last_sequence.trips >= 1 && matches!(st.step.as_str(), "idle" | "isolated" | "lockout")
    })
    .await;
    let st = status.borrow().clone();
    let ctx = format!("{st:#?}\n{:#?}", events());
    assert_eq!(st.step, "isolated", "{ctx}");
    assert!(!st.lockout, "{ctx}");
    assert_eq!(st.faulty_zones, vec![2], "{ctx}");
    let m = &st.last_sequence;
    assert_eq!((m.reenergisations, m.trips), (1, 2), "{ctx}");
    let restore_s = m.restore_s.expect("restore time");
    // The seed's bound is asserted on the Modbus path, whose test runs
    // alone; here the restore time is printed against it (9.3 s of 10 s
    // measured on an idle machine) and only a gross delay fails, since the
    // suite runs this test beside others on two cores.
    assert!(
        restore_s <= 2.0 * m.bound_s,
        "restore {restore_s:.2} s is over twice the bound {:.1} s\n{ctx}",
        m.bound_s
    );
    until(
        "zones 1 and 3 closed and energised, zone 2 open",
        &context,
        || {
            let p = snap();
            let closed: Vec<u8> = p
                .zones
                .iter()
                .filter(|z| z.breaker.closed)
                .map(|z| z.zone)
                .collect();
            let energised: Vec<u8> = p
                .zones
                .iter()
                .filter(|z| z.energised)
                .map(|z| z.zone)
                .collect();
            p.elcb_closed && p.mccb.closed && closed == [1, 3] && energised == [1, 3]
        },
    )
    .await;
    assert_eq!(snap().elcb_trips - trips_before, 2, "{ctx}");

    // Repaired and reset: zone 2 closes again.
    sim.repair_zone(id, 2).unwrap();
    let (reply, rx) = oneshot::channel();
    commands
        .send(PanelCommand {
            user: "test".into(),
            kind: PanelCommandKind::Reset,
            reply,
        })
        .await
        .expect("panel task running");
    assert_eq!(
        tokio::time::timeout(WAIT, rx)
            .await
            .expect("answered")
            .expect("reply"),
        Ok(())
    );
    until("zone 2 back after Reset", &context, || {
        let st = status.borrow();
        let p = snap();
        st.step == "idle"
            && st.faulty_zones.is_empty()
            && p.zones.iter().all(|z| z.breaker.closed)
            && st.breakers.values().all(|b| b.good && b.closed)
    })
    .await;
    println!(
        "panel {id} over {protocol:?}: zone 2 isolated, restore {restore_s:.2} s (bound {:.1} s), {} switching operations",
        m.bound_s, m.switching_ops
    );
    io.shutdown().await;
    simulator.shutdown().await;
}

/// The master of the panel's device.
enum Field {
    Iec104(gridscada_iec104::Iec104Io),
    Dnp3(gridscada_dnp3::Dnp3Io),
}

impl Field {
    fn start(protocol: Protocol, plant: &Plant, db: Arc<TagDb>, clock: Arc<dyn Clock>) -> Field {
        match protocol {
            Protocol::Iec104 => Field::Iec104(
                gridscada_iec104::Iec104Io::start(plant, db, clock, Leadership::sole())
                    .expect("IEC 104 controlling station starts"),
            ),
            _ => Field::Dnp3(
                gridscada_dnp3::Dnp3Io::start(plant, db, clock, Leadership::sole())
                    .expect("DNP3 master starts"),
            ),
        }
    }

    fn writer(&self) -> Arc<dyn gridscada_tagdb::TagWriter> {
        match self {
            Field::Iec104(io) => io.writer(),
            Field::Dnp3(io) => io.writer(),
        }
    }

    async fn shutdown(self) {
        match self {
            Field::Iec104(io) => io.shutdown().await,
            Field::Dnp3(io) => io.shutdown().await,
        }
    }
}

/// Waits (wall time, bounded) until `cond` holds; `context` says what the
/// panel was doing if it never does.
async fn until(what: &str, context: &dyn Fn() -> String, cond: impl Fn() -> bool) {
    let start = Instant::now();
    while !cond() {
        assert!(
            start.elapsed() < WAIT,
            "timed out waiting for {what}\n{}",
            context()
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}
