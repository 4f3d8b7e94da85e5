//! Field faults through the real stack (simulators as Modbus servers, the
//! poller over loopback): a device sending corrupted frames, a device
//! answering with exceptions, and a device that stops answering. Each turns
//! only its own tags Bad, with a reason, and every other device keeps Good
//! values; clearing the fault brings the tags back without a restart.

use std::path::Path;
use std::sync::Arc;
use std::time::{Duration, Instant};

use gridscada_config::Plant;
use gridscada_sim::{BindMode, ExceptionCode, SimHandle, Simulator};
use gridscada_tagdb::{Clock, QualityCode, SystemClock, TagDb};

struct Rig {
    plant: Plant,
    db: Arc<TagDb>,
    sim: Simulator,
    field: gridscada_modbus::FieldIo,
}

async fn rig() -> Rig {
    let mut plant =
        gridscada_config::load_path(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tags"))
            .unwrap_or_else(|d| panic!("{d:?}"));
    let clock: Arc<dyn Clock> = Arc::new(SystemClock);
    let sim = gridscada_sim::start(&plant, clock.clone(), BindMode::Ephemeral)
        .await
        .unwrap();
    sim.patch_plant(&mut plant);
    let mut tags: Vec<_> = plant.tag_metas().collect();
    tags.extend(gridscada_field::device_status_tags(&plant));
    let db = Arc::new(TagDb::new(tags).unwrap());
    let field = gridscada_modbus::FieldIo::start(&plant, db.clone(), clock).unwrap();
    Rig {
        plant,
        db,
        sim,
        field,
    }
}

impl Rig {
    fn handle(&self) -> SimHandle {
        self.sim.handle()
    }

    /// Tags of `device`.
    fn tags_of(&self, device: &str) -> Vec<String> {
        self.plant
            .tags
            .iter()
            .filter(|t| t.device.get_ref() == device)
            .map(|t| t.name.get_ref().clone())
            .collect()
    }

    fn all_have(&self, tags: &[String], code: QualityCode) -> bool {
        tags.iter().all(|t| {
            self.db
                .get_by_name(t)
                .is_some_and(|s| s.quality.code == code)
        })
    }

    /// Waits until `cond` holds, or fails with `what` after `limit`.
    async fn wait(&self, what: &str, limit: Duration, cond: impl Fn(&Rig) -> bool) -> Duration {
        let t0 = Instant::now();
        while !cond(self) {
            assert!(
                t0.elapsed() < limit,
                "timed out after {limit:?} waiting for: {what}"
            );
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
        t0.elapsed()
    }

    /// Every tag of every Modbus device (what this rig polls) except
    /// `except` is Good.
    fn others_good(&self, except: &[&str]) -> bool {
        self.plant
            .devices
            .iter()
            .filter(|d| d.protocol.is_modbus() && !except.contains(&d.name.get_ref().as_str()))
            .all(|d| self.all_have(&self.tags_of(d.name.get_ref()), QualityCode::Good))
    }
}

const SETTLE: Duration = Duration::from_secs(10);

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn corrupted_frames_exceptions_and_silence_stay_contained() {
    let rig = rig().await;
    rig.wait("every tag Good at start", SETTLE, |r| r.others_good(&[]))
        .await;

    // Corrupted frames from the PV controller (its own connection).
    let pv = rig.tags_of("MG.PV1");
    rig.handle().set_corrupt_frames("MG.PV1", true).unwrap();
    rig.wait("MG.PV1 tags Bad on corrupted frames", SETTLE, |r| {
        r.all_have(&pv, QualityCode::Bad)
    })
    .await;
    assert!(
        rig.others_good(&["MG.PV1"]),
        "a corrupting device must not disturb the others"
    );
    let links = rig.field.stats().links;
    assert!(
        links
            .iter()
            .any(|l| l.garbage_bytes > 0 || l.late_replies > 0 || l.disconnects > 0),
        "corruption is counted: {links:?}"
    );
    rig.handle().set_corrupt_frames("MG.PV1", false).unwrap();
    rig.wait("MG.PV1 recovers", SETTLE, |r| {
        r.all_have(&pv, QualityCode::Good)
    })
    .await;

    // Exceptions from the power analyzer, behind the same gateway as the
    // panel's I/O modules: the modules keep their values.
    let pa = rig.tags_of("SS1.PA");
    rig.handle()
        .set_exception("SS1.PA", Some(ExceptionCode::ServerDeviceFailure))
        .unwrap();
    rig.wait("SS1.PA tags Bad on exceptions", SETTLE, |r| {
        r.all_have(&pa, QualityCode::Bad)
    })
    .await;
    let reason = rig
        .db
        .get_by_name("SS1.PA.V_L1")
        .unwrap()
        .quality
        .reason
        .unwrap_or_default();
    assert!(
        reason.contains("exception"),
        "the exception is named: {reason}"
    );
    assert!(
        rig.others_good(&["SS1.PA"]),
        "the gateway's other units keep Good values"
    );
    rig.handle().set_exception("SS1.PA", None).unwrap();
    rig.wait("SS1.PA recovers", SETTLE, |r| {
        r.all_have(&pa, QualityCode::Good)
    })
    .await;

    // A unit that stops answering goes Bad within two scan periods (plus one
    // request timeout for the answer it is waiting on); its neighbours on the
    // same connection stay Good.
    let io2 = rig.tags_of("SS1.IO2");
    let dev = rig.plant.device("SS1.IO2").unwrap();
    let scan = Duration::from_millis(*dev.scan_ms.get_ref());
    let timeout = Duration::from_millis(*dev.timeout_ms.get_ref());
    rig.handle().set_device_offline("SS1.IO2", true).unwrap();
    let took = rig
        .wait("SS1.IO2 tags Bad when it stops answering", SETTLE, |r| {
            r.all_have(&io2, QualityCode::Bad)
        })
        .await;
    assert!(
        took <= 2 * scan + timeout + Duration::from_millis(300),
        "went Bad after {took:?}"
    );
    assert!(
        rig.others_good(&["SS1.IO2"]),
        "a silent unit must not stall the others"
    );
    let connected = rig.db.get_by_name("SS1.IO2.Comm.Connected").unwrap();
    assert_eq!(connected.value.as_bool(), Some(false));
    rig.handle().set_device_offline("SS1.IO2", false).unwrap();
    rig.wait("SS1.IO2 recovers", Duration::from_secs(30), |r| {
        r.all_have(&io2, QualityCode::Good)
    })
    .await;

    rig.field.shutdown().await;
    rig.sim.shutdown().await;
}
