//! Tests of the driver against a fake field layer that models the panel:
//! writes land in the tag database at once, and the ELCB trips when an
//! energised load is faulty.

use std::path::Path;
use std::sync::Arc;
use std::time::Duration;

use gridscada_config::PanelConfig;
use gridscada_tagdb::{
    Quality, Sample, ScaledClock, TagDb, TagWriter, Timestamp, Value, WriteError, WriteFuture,
};
use std::sync::Mutex;
use tokio::sync::{mpsc, oneshot, watch};

use super::*;

const ZONES: u8 = 3;

fn plant_panel() -> (PanelConfig, Vec<gridscada_tagdb::TagMeta>) {
    let main = r#"
tag_files = ["t.toml"]
[[panel]]
id = "ss1"
name = "Service substation panel"
kind = "service"
prefix = "SS1"
zones = 3
reclose_delay_s = 3.0
dwell_s = 1.0
confirm_timeout_s = 2.0
max_trips = 8
"#;
    let mut tags = String::from(
        r#"
[[device]]
name = "IO"
protocol = "tcp"
address = "127.0.0.1:1502"
# The ELCB status must be read well within the dwell (validation).
scan_ms = 100
timeout_ms = 200
"#,
    );
    let mut n = 0;
    let mut tag = |name: &str, coil: bool| {
        let (kind, extra) = if coil {
            ("coil", "writable = true\nwrite_role = \"operator\"\n")
        } else {
            ("discrete_input", "")
        };
        tags.push_str(&format!(
            "[[tag]]\nname = \"{name}\"\ndevice = \"IO\"\nkind = \"{kind}\"\naddress = {n}\n{extra}\n"
        ));
        n += 1;
    };
    tag("SS1.ELCB.Closed", false);
    tag("SS1.MCCB.Closed", false);
    tag("SS1.ELCB.Reset", true);
    tag("SS1.MCCB.Cmd", true);
    for z in 1..=ZONES {
        tag(&format!("SS1.Zone{z}.Closed"), false);
        tag(&format!("SS1.Zone{z}.Cmd"), true);
    }
    let plant = gridscada_config::load_with(Path::new("/plant/gridscada.toml"), &|p: &Path| {
        if p.ends_with("gridscada.toml") {
            Ok(main.to_string())
        } else {
            Ok(tags.clone())
        }
    })
    .unwrap_or_else(|d| panic!("test plant does not load: {d:?}"));
    let panel = plant.panels[0].clone();
    let mut metas: Vec<_> = plant.tag_metas().collect();
    metas.extend(panel_tags(&panel));
    (panel, metas)
}

/// The panel behind the fake field layer.
struct FakePanel {
    db: Arc<TagDb>,
    faults: Mutex<Vec<bool>>,
}

impl FakePanel {
    fn b(&self, name: &str) -> bool {
        self.db
            .get_by_name(name)
            .and_then(|s| s.value.as_bool())
            .unwrap_or(false)
    }

    fn set(&self, pairs: &[(String, bool)]) {
        let ts = Timestamp::from_millis(0);
        self.db.apply(
            pairs
                .iter()
                .filter_map(|(n, v)| self.db.id(n).map(|id| (id, Sample::good(*v, ts)))),
        );
    }

    /// Trips the ELCB if an energised load is faulty.
    fn settle(&self) {
        let faults = self.faults.lock().unwrap().clone();
        let mccb = self.b("SS1.MCCB.Closed");
        let energised_fault = self.b("SS1.ELCB.Closed")
            && mccb
            && (faults[0]
                || (1..=ZONES)
                    .any(|z| faults[usize::from(z)] && self.b(&format!("SS1.Zone{z}.Closed"))));
        if energised_fault {
            self.set(&[("SS1.ELCB.Closed".into(), false)]);
        }
    }

    fn init(&self) {
        let mut v = vec![
            ("SS1.ELCB.Closed".to_string(), true),
            ("SS1.MCCB.Closed".into(), true),
            ("SS1.ELCB.Reset".into(), false),
            ("SS1.MCCB.Cmd".into(), true),
        ];
        for z in 1..=ZONES {
            v.push((format!("SS1.Zone{z}.Closed"), true));
            v.push((format!("SS1.Zone{z}.Cmd"), true));
        }
        self.set(&v);
    }
}

impl TagWriter for FakePanel {
    fn write<'a>(&'a self, name: &'a str, value: Value) -> WriteFuture<'a> {
        Box::pin(async move {
            let v = value.as_bool().ok_or_else(|| WriteError::BadValue {
                tag: name.into(),
                value: value.to_string(),
                reason: "not a bool".into(),
            })?;
            if self.db.id(name).is_none() {
                return Err(WriteError::UnknownTag(name.into()));
            }
            if name == "SS1.ELCB.Reset" {
                self.set(&[(name.into(), v)]);
                if v {
                    let faults = self.faults.lock().unwrap().clone();
                    let mccb = self.b("SS1.MCCB.Closed");
                    let would_fault = mccb
                        && (faults[0]
                            || (1..=ZONES).any(|z| {
                                faults[usize::from(z)] && self.b(&format!("SS1.Zone{z}.Closed"))
                            }));
                    if !would_fault {
                        self.set(&[("SS1.ELCB.Closed".into(), true)]);
                    }
                }
            } else if let Some(base) = name.strip_suffix(".Cmd") {
                self.set(&[(name.into(), v), (format!("{base}.Closed"), v)]);
                self.settle();
            }
            Ok(Sample::good(v, Timestamp::from_millis(0)))
        })
    }
}

struct Rig {
    db: Arc<TagDb>,
    fake: Arc<FakePanel>,
    cmd: mpsc::Sender<PanelCommand>,
    status: watch::Receiver<PanelStatus>,
    notices: mpsc::Receiver<PanelNotice>,
}

fn rig(speed: f64) -> Rig {
    let (panel, metas) = plant_panel();
    let db = Arc::new(TagDb::new(metas).unwrap());
    let fake = Arc::new(FakePanel {
        db: db.clone(),
        faults: Mutex::new(vec![false; usize::from(ZONES) + 1]),
    });
    fake.init();
    let clock = Arc::new(ScaledClock::new(Timestamp::from_millis(0), speed));
    let (cmd, cmd_rx) = mpsc::channel(8);
    let (status_tx, status) = watch::channel(PanelStatus::initial(&panel));
    let (notice_tx, notices) = mpsc::channel(10_000);
    tokio::spawn(run_panel(
        panel,
        db.clone(),
        fake.clone(),
        clock,
        cmd_rx,
        status_tx,
        notice_tx,
        None,
    ));
    Rig {
        db,
        fake,
        cmd,
        status,
        notices,
    }
}

impl Rig {
    async fn wait_step(&mut self, step: &str) -> PanelStatus {
        let got = match tokio::time::timeout(
            Duration::from_secs(20),
            self.status.wait_for(|s| s.step == step),
        )
        .await
        {
            Ok(Ok(s)) => Some(s.clone()),
            _ => None,
        };
        got.unwrap_or_else(|| panic!("step '{step}' not reached: {:?}", *self.status.borrow()))
    }

    async fn send(&self, kind: PanelCommandKind) -> Result<(), CommandError> {
        let (reply, rx) = oneshot::channel();
        self.cmd
            .send(PanelCommand {
                user: "alice".into(),
                kind,
                reply,
            })
            .await
            .unwrap();
        rx.await.unwrap()
    }

    fn fault(&self, load: usize, on: bool) {
        self.fake.faults.lock().unwrap()[load] = on;
        self.fake.settle();
    }

    fn tag(&self, name: &str) -> Value {
        self.db.get_by_name(name).unwrap().value
    }
}

#[tokio::test]
async fn driver_isolates_a_faulty_zone_and_publishes_status() {
    let mut r = rig(200.0);
    r.wait_step("idle").await;
    r.fault(2, true);
    let s = r.wait_step("isolated").await;
    let json = serde_json::to_value(&s).unwrap();
    assert_eq!(json["id"], "ss1");
    assert_eq!(json["mode"], "auto");
    assert_eq!(json["step"], "isolated");
    assert_eq!(json["count_L_cur_sv"], 2);
    assert!(json["count_L_cur_c"].is_u64());
    assert_eq!(json["zones"], 3);
    assert_eq!(json["faulty_zones"], serde_json::json!([2]));
    assert_eq!(json["lockout"], false);
    assert_eq!(json["breakers"]["elcb"]["closed"], true);
    assert_eq!(json["breakers"]["mccb"]["closed"], true);
    assert_eq!(json["breakers"]["zone1"]["closed"], true);
    assert_eq!(json["breakers"]["zone2"]["closed"], false);
    assert_eq!(json["breakers"]["zone3"]["closed"], true);
    let last = &json["last_sequence"];
    for k in ["restore_s", "switching_ops", "reenergisations", "bound_s"] {
        assert!(last[k].is_number(), "{k}");
    }
    assert_eq!(last["reenergisations"], 1);
    assert_eq!(last["bound_s"], 2.0 * 3.0 + 4.0 * 1.0);
    // Derived tags.
    assert_eq!(r.tag("SS1.Seq.Step"), Value::from("isolated"));
    assert_eq!(r.tag("SS1.Seq.FaultyZones"), Value::from("2"));
    assert_eq!(r.tag("SS1.Seq.count_L_cur_sv"), Value::Int(2));
    assert_eq!(r.tag("SS1.Seq.Mode"), Value::from("auto"));
    assert_eq!(r.tag("SS1.Seq.Lockout"), Value::Bool(false));
    // Events and alarms came through.
    let mut kinds = Vec::new();
    let mut alarms = Vec::new();
    while let Ok(n) = r.notices.try_recv() {
        match n {
            PanelNotice::Event { kind, panel, .. } => {
                assert_eq!(panel, "ss1");
                kinds.push(kind)
            }
            PanelNotice::Alarm { key, active, .. } => alarms.push((key, active)),
        }
    }
    assert!(kinds.iter().any(|k| k == "trip") && kinds.iter().any(|k| k == "fault_found"));
    assert!(alarms.contains(&("zone2.isolated".into(), true)));
    assert!(alarms.contains(&("elcb.trip".into(), false)));

    // Repair, Reset: zone 2 comes back.
    r.fault(2, false);
    r.send(PanelCommandKind::Reset).await.unwrap();
    let s = r.wait_step("idle").await;
    assert!(s.faulty_zones.is_empty());
    assert!(s.breakers.values().all(|b| b.closed && b.good), "{s:?}");
}

/// A sequence that locks out publishes no restoration time: `restore_s` is
/// `null` in the status the API serves, not 0.
#[tokio::test]
async fn driver_lockout_publishes_no_restore_time() {
    let mut r = rig(200.0);
    r.wait_step("idle").await;
    r.fault(0, true);
    let s = r.wait_step("lockout").await;
    let json = serde_json::to_value(&s).unwrap();
    let last = &json["last_sequence"];
    assert_eq!(last["outcome"], "lockout", "{json}");
    assert!(last["restore_s"].is_null(), "{json}");
    assert!(
        last.as_object().unwrap().contains_key("restore_s"),
        "{json}"
    );
}

#[tokio::test]
async fn driver_operator_commands_are_checked() {
    let mut r = rig(200.0);
    r.wait_step("idle").await;
    let zone1 = |close| PanelCommandKind::Breaker {
        breaker: "zone1".into(),
        close,
    };
    assert_eq!(r.send(zone1(false)).await, Err(CommandError::NotManual));
    r.send(PanelCommandKind::SetMode(Mode::Manual))
        .await
        .unwrap();
    r.wait_step("manual").await;
    assert!(matches!(
        r.send(PanelCommandKind::Breaker {
            breaker: "zone9".into(),
            close: true
        })
        .await,
        Err(CommandError::UnknownBreaker { .. })
    ));
    r.send(zone1(false)).await.unwrap();
    assert_eq!(r.tag("SS1.Zone1.Closed"), Value::Bool(false));
    // A fault trips the ELCB; in manual mode nothing switches by itself, and a
    // zone cannot be closed while the ELCB is open.
    r.fault(3, true);
    assert_eq!(r.tag("SS1.ELCB.Closed"), Value::Bool(false));
    assert!(matches!(
        r.send(zone1(true)).await,
        Err(CommandError::Interlocked(_))
    ));
    tokio::time::sleep(Duration::from_millis(100)).await; // 20 s of plant time
    assert_eq!(r.status.borrow().step, "manual");
    assert_eq!(r.tag("SS1.Zone3.Closed"), Value::Bool(true));
    // The audit trail names the user.
    let mut users = Vec::new();
    while let Ok(n) = r.notices.try_recv() {
        if let PanelNotice::Event { kind, user, .. } = n {
            if kind == "command" || kind == "command_refused" {
                users.push(user);
            }
        }
    }
    assert!(users.len() >= 4 && users.iter().all(|u| u.as_deref() == Some("alice")));
    // Back to automatic: the tripped ELCB starts the sequence.
    r.send(PanelCommandKind::SetMode(Mode::Auto)).await.unwrap();
    let s = r.wait_step("isolated").await;
    assert_eq!(s.faulty_zones, vec![3]);
    assert!(s.breakers["zone1"].closed && !s.breakers["zone3"].closed);
}

#[tokio::test]
async fn driver_suspends_on_bad_quality() {
    let mut r = rig(20.0);
    r.wait_step("idle").await;
    r.fault(1, true);
    r.wait_step("reclose_wait").await;
    let ids = r.db.ids_with_prefix("SS1.Zone");
    r.db.set_quality(
        &ids,
        &Quality::bad("device offline"),
        Timestamp::from_millis(1),
    );
    r.wait_step("suspended").await;
    assert!(!r.status.borrow().comm_ok);
    tokio::time::sleep(Duration::from_millis(50)).await;
    assert_eq!(
        r.tag("SS1.ELCB.Closed"),
        Value::Bool(false),
        "nothing switched while suspended"
    );
    r.db.set_quality(&ids, &Quality::GOOD, Timestamp::from_millis(2));
    let s = r.wait_step("isolated").await;
    assert_eq!(s.faulty_zones, vec![1]);
}

#[test]
fn panel_tags_names() {
    let (panel, _) = plant_panel();
    let names: Vec<String> = panel_tags(&panel)
        .iter()
        .map(|m| m.name.to_string())
        .collect();
    assert_eq!(
        names,
        [
            "SS1.Seq.Mode",
            "SS1.Seq.Step",
            "SS1.Seq.count_L_cur_c",
            "SS1.Seq.count_L_cur_sv",
            "SS1.Seq.FaultyZones",
            "SS1.Seq.Lockout"
        ]
    );
}
