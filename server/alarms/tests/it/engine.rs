//! The engine over a real tag database and the demo plant: configuration
//! mapping, default suppression, channels, operations, restart.

use std::future::Future;
use std::path::Path;
use std::pin::Pin;
use std::sync::atomic::{AtomicI64, Ordering};
use std::sync::Arc;
use std::time::Duration;

use gridscada_alarms::{
    default_rules, AlarmChannels, AlarmEngine, AlarmFilter, AlarmKind, AlarmSet, AlarmState,
    AlarmStateRecord, AlarmTransition, EngineOptions, Event, EventType, TransitionCause,
};
use gridscada_config::Plant;
use gridscada_tagdb::{Clock, Quality, TagDb, TagMeta, Timestamp, Value, ValueKind};
use tokio::sync::mpsc;

/// Plant time set by the test; sleeps are short real waits so the engine
/// re-reads the time promptly.
struct ManualClock(AtomicI64);

impl ManualClock {
    fn set(&self, s: f64) {
        self.0.store((s * 1000.0) as i64, Ordering::SeqCst);
    }
}

impl Clock for ManualClock {
    fn now(&self) -> Timestamp {
        Timestamp::from_millis(self.0.load(Ordering::SeqCst))
    }
    fn sleep(&self, _d: Duration) -> Pin<Box<dyn Future<Output = ()> + Send>> {
        Box::pin(tokio::time::sleep(Duration::from_millis(2)))
    }
}

fn plant() -> Plant {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tags");
    gridscada_config::load_path(&dir).expect("the demo plant loads")
}

fn tagdb(plant: &Plant) -> Arc<TagDb> {
    let mut metas: Vec<TagMeta> = plant
        .tags
        .iter()
        .map(|t| TagMeta::new(t.name.get_ref().as_str(), t.value_kind()).units(t.units.clone()))
        .collect();
    for d in &plant.devices {
        let n = d.name.get_ref();
        metas.push(TagMeta::new(format!("{n}.Comm.Connected"), ValueKind::Bool));
        metas.push(TagMeta::new(format!("{n}.Comm.LastError"), ValueKind::Str));
    }
    Arc::new(TagDb::new(metas).unwrap())
}

struct Rig {
    engine: Arc<AlarmEngine>,
    db: Arc<TagDb>,
    clock: Arc<ManualClock>,
    transitions: mpsc::Receiver<AlarmTransition>,
    events: mpsc::Receiver<Event>,
    states: mpsc::Receiver<AlarmStateRecord>,
}

fn rig(restore: &[AlarmStateRecord]) -> Rig {
    let plant = plant();
    let db = tagdb(&plant);
    let clock = Arc::new(ManualClock(AtomicI64::new(1_000_000)));
    let (ttx, transitions) = mpsc::channel(1024);
    let (etx, events) = mpsc::channel(1024);
    let (stx, states) = mpsc::channel(1024);
    let engine = AlarmEngine::new(
        &plant,
        Arc::clone(&db),
        clock.clone(),
        AlarmChannels {
            transitions: ttx,
            events: etx,
            states: Some(stx),
        },
        restore,
        EngineOptions::default(),
    )
    .unwrap();
    tokio::spawn(Arc::clone(&engine).run());
    Rig {
        engine,
        db,
        clock,
        transitions,
        events,
        states,
    }
}

impl Rig {
    fn set(&self, tag: &str, v: impl Into<Value>) {
        let id = self.db.id(tag).unwrap_or_else(|| panic!("no tag {tag}"));
        self.db.set(id, v, Quality::GOOD, self.clock.now());
    }
    /// Sets a tag and waits until the engine has evaluated it, so the
    /// evaluation time is the current plant time.
    async fn set_and_wait(&self, tag: &str, v: impl Into<Value>) {
        let before = self.engine.evaluations_total();
        self.set(tag, v);
        tokio::time::timeout(Duration::from_secs(10), async {
            while self.engine.evaluations_total() == before {
                tokio::time::sleep(Duration::from_millis(1)).await;
            }
        })
        .await
        .expect("the engine evaluates the change");
    }
    async fn next_transition(&mut self, key: &str) -> AlarmTransition {
        loop {
            let t = tokio::time::timeout(Duration::from_secs(10), self.transitions.recv())
                .await
                .expect("a transition within 10 s")
                .expect("channel open");
            if t.key == key {
                return t;
            }
        }
    }
}

#[test]
fn plant_alarms_keys_and_default_suppression() {
    let plant = plant();
    let rules = default_rules(&plant);
    let triggers: Vec<&str> = rules.iter().map(|r| r.trigger.as_str()).collect();
    assert_eq!(
        triggers,
        vec!["SS1.ELCB.Closed:discrete", "CSS1.ELCB.Closed:discrete"]
    );
    let set = AlarmSet::from_plant(&plant, rules).unwrap();
    let lo = set.view(set.id_of("SS1.PA.V_L1:lo").unwrap()).unwrap();
    assert_eq!(
        (lo.kind, lo.priority, lo.selection.as_str()),
        (AlarmKind::Lo, 600, "SS1")
    );
    assert_eq!(lo.limit, Some(Value::Float(207.0)));
    assert_eq!(lo.units, "V");
    let comm = set.view(set.id_of("SS1.PA:comm").unwrap()).unwrap();
    assert_eq!(
        (comm.kind, comm.selection.as_str()),
        (AlarmKind::CommFail, "SS1")
    );
    assert_eq!(comm.tag.as_deref(), Some("SS1.PA.Comm.Connected"));
    let mg = set.view(set.id_of("MG.PV1:comm").unwrap()).unwrap();
    assert_eq!(mg.selection, "MG");
    assert!(set.id_of("MG.PV1.State:discrete").is_some());
    assert!(set.id_of("SS1.PA.Hz:lo").is_some());
}

#[tokio::test]
async fn engine_evaluates_suppresses_and_reports() {
    let mut r = rig(&[]);
    let mut version = r.engine.subscribe_version();
    r.set("SS1.ELCB.Closed", true);
    r.set("SS1.PA.V_L1", 230.0);
    r.set("SS1.PA.Comm.Connected", true);

    // ELCB trip: annunciated.
    r.clock.set(1010.0);
    r.set("SS1.ELCB.Closed", false);
    let t = r.next_transition("SS1.ELCB.Closed:discrete").await;
    assert_eq!(
        (t.cause, t.to),
        (TransitionCause::Activate, AlarmState::UnackActive)
    );
    assert_eq!(t.time, Timestamp::from_millis(1_010_000));
    assert_eq!(
        t.message,
        "Service substation panel: ELCB tripped, supply to all zones lost"
    );
    tokio::time::timeout(Duration::from_secs(10), version.changed())
        .await
        .unwrap()
        .unwrap();

    // Under-voltage follows: its 2 s/5 s on-delays run on the engine's
    // timer, and it activates suppressed.
    r.set_and_wait("SS1.PA.V_L1", 0.0).await;
    r.clock.set(1016.0);
    let t = r.next_transition("SS1.PA.V_L1:lolo").await;
    assert_eq!(
        (t.cause, t.to),
        (TransitionCause::Suppress, AlarmState::Suppressed),
        "suppressed at the trip"
    );
    let t = r.next_transition("SS1.PA.V_L1:lolo").await;
    assert_eq!(
        (t.cause, t.to, t.annunciated),
        (TransitionCause::Activate, AlarmState::Suppressed, false)
    );
    // The value and the limit with the tag's decimals, as the HMI shows them
    // (the demo's `[hmi] decimals = 1`).
    assert_eq!(t.message, "SS1.PA.V_L1 very low: 0.0 V (limit 195.0 V)");
    let list = r.engine.summary(&AlarmFilter::default());
    assert!(list.iter().all(|v| !v.key.starts_with("SS1.PA.V_L1")));
    assert!(list.iter().any(|v| v.key == "SS1.ELCB.Closed:discrete"));

    // Comm loss with the poller's error text, after the comm alarm's
    // on-delay (2 s by default).
    r.set("SS1.PA.Comm.LastError", "timeout after 1000 ms");
    r.set_and_wait("SS1.PA.Comm.Connected", false).await;
    r.clock.0.fetch_add(2_000, Ordering::SeqCst);
    let t = r.next_transition("SS1.PA:comm").await;
    assert_eq!(
        t.message,
        "Communication lost with SS1.PA: timeout after 1000 ms"
    );

    // Operator actions: transitions, events and state records.
    let top = r
        .engine
        .ack_top("alice", &AlarmFilter::default())
        .unwrap()
        .unwrap();
    assert_eq!(r.engine.view(top).unwrap().key, "SS1.PA:comm");
    let e = tokio::time::timeout(Duration::from_secs(10), r.events.recv())
        .await
        .unwrap()
        .unwrap();
    assert_eq!(
        (e.kind, e.user.as_deref(), e.source.as_str()),
        (EventType::Ack, Some("alice"), "SS1.PA:comm")
    );
    let elcb = r.engine.id_of("SS1.ELCB.Closed:discrete").unwrap();
    let until = r.engine.shelve(elcb, "sup", 30, "ELCB under test").unwrap();
    assert_eq!(until, Timestamp::from_millis(1_018_000 + 30 * 60_000));
    let e = tokio::time::timeout(Duration::from_secs(10), r.events.recv())
        .await
        .unwrap()
        .unwrap();
    assert_eq!(e.kind, EventType::Shelve);
    assert!(r.engine.shelve(elcb, "sup", 0, "x").is_err());

    let mut saw_shelved_record = false;
    while let Ok(Some(s)) = tokio::time::timeout(Duration::from_millis(200), r.states.recv()).await
    {
        if s.key == "SS1.ELCB.Closed:discrete" && s.state == AlarmState::Shelved {
            saw_shelved_record = true;
            assert_eq!(s.shelved_by.as_deref(), Some("sup"));
        }
    }
    assert!(saw_shelved_record);

    // The shelving expires on plant time, with an event and no user.
    r.clock.set(1018.0 + 30.0 * 60.0);
    let mut t = r.next_transition("SS1.ELCB.Closed:discrete").await;
    if t.cause == TransitionCause::Shelve {
        t = r.next_transition("SS1.ELCB.Closed:discrete").await;
    }
    assert_eq!(
        (t.cause, t.to),
        (TransitionCause::ShelveExpired, AlarmState::UnackActive)
    );
    let e = tokio::time::timeout(Duration::from_secs(10), r.events.recv())
        .await
        .unwrap()
        .unwrap();
    assert_eq!((e.kind, e.user), (EventType::Unshelve, None));

    // System alarm through the API.
    r.engine
        .raise(
            "ss1.sequence.lockout",
            900,
            "SS1",
            "SS1 sequence locked out",
        )
        .unwrap();
    let t = r.next_transition("ss1.sequence.lockout").await;
    assert_eq!(t.kind, AlarmKind::System);

    let stats = r.engine.stats();
    assert!(stats.evaluations_total > 0);
    assert!(stats.active >= 3 && stats.suppressed >= 2);

    // Restart: acknowledgements and states survive.
    let saved = r.engine.persisted_states();
    let r2 = rig(&saved);
    let comm = r2
        .engine
        .view(r2.engine.id_of("SS1.PA:comm").unwrap())
        .unwrap();
    assert_eq!(comm.state, AlarmState::AckActive);
    let lock = r2.engine.id_of("ss1.sequence.lockout").unwrap();
    assert_eq!(r2.engine.view(lock).unwrap().state, AlarmState::UnackActive);
    let lolo = r2.engine.id_of("SS1.PA.V_L1:lolo").unwrap();
    assert_eq!(r2.engine.view(lolo).unwrap().state, AlarmState::Suppressed);
}

/// A central Sparkplug host's remote tags appear after the engine started:
/// their alarms are defined then, and evaluated from the current value on.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn alarms_defined_at_run_time_watch_their_new_tags() {
    let plant = plant();
    let db =
        Arc::new(TagDb::with_room(tagdb(&plant).all_meta().map(|(_, m)| m.clone()), 10).unwrap());
    let clock = Arc::new(ManualClock(AtomicI64::new(1_000_000)));
    let (ttx, mut transitions) = mpsc::channel(1024);
    let (etx, _events) = mpsc::channel(1024);
    let engine = AlarmEngine::new(
        &plant,
        Arc::clone(&db),
        clock.clone(),
        AlarmChannels {
            transitions: ttx,
            events: etx,
            states: None,
        },
        &[],
        EngineOptions::default(),
    )
    .unwrap();
    tokio::spawn(Arc::clone(&engine).run());

    let tag = "site-1.SS1.PA.V_L1";
    let config: gridscada_config::AlarmConfig =
        toml::from_str("selection = \"site-1.SS1\"\nhi = { limit = 253.0, priority = 600 }\n")
            .unwrap();
    let source = gridscada_alarms::AlarmSource {
        name: tag,
        units: "V",
        description: "",
        device: None,
        states: None,
        decimals: None,
    };
    let defs = || gridscada_alarms::tag_alarm_defs(&source, &config).unwrap();
    assert!(
        engine.define(defs()).is_err(),
        "a tag not in the database yet is refused"
    );
    let id = db
        .add(TagMeta::new(tag, ValueKind::Float).units("V"))
        .unwrap();
    // Already high when its alarm is defined: it activates from the
    // current value, without waiting for a change.
    db.set(id, 260.0, Quality::GOOD, clock.now());
    assert_eq!(engine.define(defs()).unwrap(), ["site-1.SS1.PA.V_L1:hi"]);
    assert!(
        engine.define(defs()).unwrap().is_empty(),
        "a rebirth declaring the same alarm adds nothing"
    );
    let t = next_hi(&mut transitions).await;
    assert_eq!(
        (t.cause, t.to),
        (TransitionCause::Activate, AlarmState::UnackActive)
    );
    let view = engine
        .view(engine.id_of("site-1.SS1.PA.V_L1:hi").unwrap())
        .unwrap();
    assert_eq!(view.selection, "site-1.SS1");
    // And it follows the tag's changes.
    clock.set(1001.0);
    db.set(id, 230.0, Quality::GOOD, clock.now());
    let t = next_hi(&mut transitions).await;
    assert_eq!(t.cause, TransitionCause::Return);
}

async fn next_hi(rx: &mut mpsc::Receiver<AlarmTransition>) -> AlarmTransition {
    loop {
        let t = tokio::time::timeout(Duration::from_secs(10), rx.recv())
            .await
            .expect("a transition within 10 s")
            .expect("channel open");
        if t.key == "site-1.SS1.PA.V_L1:hi" {
            return t;
        }
    }
}

/// A live alarm list kept by the changes since its version: the same alarms,
/// in the same states, as the whole list at that version.
#[tokio::test]
async fn a_list_kept_by_changes_matches_the_whole_list() {
    use gridscada_alarms::{AlarmId, AlarmListUpdate, AlarmView};
    use std::collections::BTreeMap;

    /// Brings `list` (at `version`) up to date; returns how many updates
    /// came as changes.
    fn follow(
        engine: &AlarmEngine,
        list: &mut BTreeMap<AlarmId, AlarmView>,
        version: &mut u64,
    ) -> usize {
        let mut changes = 0;
        while let Some(u) = engine.summary_since(Some(*version)) {
            match u {
                AlarmListUpdate::Whole { version: v, alarms } => {
                    *list = alarms.into_iter().map(|a| (a.id, a)).collect();
                    *version = v;
                }
                AlarmListUpdate::Changes {
                    version: v,
                    since,
                    changed,
                    removed,
                } => {
                    assert_eq!(since, *version);
                    for id in removed {
                        list.remove(&id);
                    }
                    list.extend(changed.into_iter().map(|a| (a.id, a)));
                    *version = v;
                    changes += 1;
                }
            }
        }
        changes
    }
    /// The list kept equals the whole list of the same version ("value now"
    /// aside: a list kept by changes has each alarm's value at its own
    /// latest change).
    fn assert_same(
        engine: &AlarmEngine,
        list: &mut BTreeMap<AlarmId, AlarmView>,
        version: &mut u64,
    ) {
        let strip = |mut a: AlarmView| {
            a.value = None;
            a.value_text = None;
            a
        };
        loop {
            follow(engine, list, version);
            let Some(AlarmListUpdate::Whole { version: v, alarms }) = engine.summary_since(None)
            else {
                panic!("a client without a list gets the whole list");
            };
            if v != *version {
                continue; // the engine moved on in between
            }
            let whole: BTreeMap<_, _> = alarms.into_iter().map(|a| (a.id, strip(a))).collect();
            let kept: BTreeMap<_, _> = list
                .clone()
                .into_iter()
                .map(|(k, a)| (k, strip(a)))
                .collect();
            assert_eq!(kept, whole, "the list kept by changes, at version {v}");
            return;
        }
    }

    let mut r = rig(&[]);
    r.set("SS1.ELCB.Closed", true);
    r.set_and_wait("SS1.PA.V_L1", 230.0).await;
    let Some(AlarmListUpdate::Whole { version, alarms }) = r.engine.summary_since(None) else {
        panic!("the first list is whole");
    };
    let mut version = version;
    let mut list: BTreeMap<AlarmId, AlarmView> = alarms.into_iter().map(|a| (a.id, a)).collect();
    assert!(
        r.engine
            .summary_since(Some(version + 1_000))
            .is_some_and(|u| matches!(u, AlarmListUpdate::Whole { .. })),
        "a version the engine never had: the whole list"
    );

    // A trip: the ELCB alarm enters the list, the panel analyser's alarms
    // follow suppressed.
    r.clock.set(1010.0);
    r.set("SS1.ELCB.Closed", false);
    let trip = r.next_transition("SS1.ELCB.Closed:discrete").await;
    let changes = follow(&r.engine, &mut list, &mut version);
    assert!(changes > 0, "the trip comes as changes");
    assert!(list.contains_key(&trip.id));
    assert_same(&r.engine, &mut list, &mut version);
    assert!(
        r.engine.summary_since(Some(version)).is_none(),
        "nothing new"
    );

    // Acknowledged and back to normal: it leaves the list.
    r.engine.ack_ids("op", &[trip.id]).unwrap();
    r.clock.set(1020.0);
    r.set("SS1.ELCB.Closed", true);
    r.next_transition("SS1.ELCB.Closed:discrete").await;
    follow(&r.engine, &mut list, &mut version);
    assert_same(&r.engine, &mut list, &mut version);
    assert!(
        !list.contains_key(&trip.id),
        "normal and acknowledged: off the list"
    );

    // Taking over another server's states may change any alarm: whole.
    let records = r.engine.persisted_states();
    r.engine.adopt(&records);
    assert!(matches!(
        r.engine.summary_since(Some(version)),
        Some(AlarmListUpdate::Whole { .. })
    ));
}
