//! Tag database semantics: only changes are delivered, quality and timestamps
//! are kept, and a slow subscriber gets a snapshot instead of blocking anyone.

use std::sync::Arc;

use gridscada_tagdb::{
    Quality, QualityCode, Sample, TagDb, TagId, TagMeta, Timestamp, Value, ValueKind,
};

fn db(n: usize) -> Arc<TagDb> {
    Arc::new(
        TagDb::new((0..n).map(|i| TagMeta::new(format!("SS1.Zone{i}.Current"), ValueKind::Float)))
            .unwrap(),
    )
}

fn ts(ms: i64) -> Timestamp {
    Timestamp::from_millis(ms)
}

#[test]
fn names_are_unique_and_lookups_agree() {
    let err = TagDb::new([
        TagMeta::new("SS1.ELCB.Closed", ValueKind::Bool),
        TagMeta::new("SS1.ELCB.Closed", ValueKind::Bool),
    ])
    .err()
    .unwrap();
    assert_eq!(err.to_string(), "duplicate tag name 'SS1.ELCB.Closed'");

    let db = db(100_000);
    let id = db.id("SS1.Zone99999.Current").unwrap();
    assert_eq!(id, TagId(99_999));
    assert_eq!(&*db.meta(id).unwrap().name, "SS1.Zone99999.Current");
    assert!(db.id("SS1.Zone100000.Current").is_none());
}

#[test]
fn tags_start_bad_until_read() {
    let db = db(1);
    let s = db.get(TagId(0)).unwrap();
    assert_eq!(s.quality.code, QualityCode::Bad);
    assert_eq!(s.quality.reason.as_deref(), Some("no value yet"));
}

#[tokio::test]
async fn only_changes_are_delivered_with_quality_and_timestamp() {
    let db = db(3);
    let mut sub = db.subscribe_all();

    let n = db.apply([
        (TagId(0), Sample::good(1.0, ts(10))),
        (TagId(1), Sample::good(2.0, ts(10))),
        (TagId(2), Sample::good(3.0, ts(10))),
    ]);
    assert_eq!(n, 3);
    // Same values again, newer timestamps: not a change, nothing published.
    let n = db.apply([
        (TagId(0), Sample::good(1.0, ts(20))),
        (TagId(1), Sample::good(2.0, ts(20))),
        (TagId(2), Sample::good(3.0, ts(20))),
    ]);
    assert_eq!(n, 0);
    // The database still records the newest confirmation time.
    assert_eq!(db.get(TagId(0)).unwrap().timestamp, ts(20));
    // One value and one quality change.
    db.apply([
        (TagId(1), Sample::good(2.5, ts(30))),
        (
            TagId(2),
            Sample {
                value: 3.0.into(),
                quality: Quality::bad("device offline"),
                timestamp: ts(30),
            },
        ),
    ]);

    let first = sub.recv().await.unwrap();
    assert!(!first.is_snapshot());
    assert_eq!(first.batch().changes.len(), 3);
    let second = sub.recv().await.unwrap();
    let changes = &second.batch().changes;
    assert_eq!(changes.len(), 2);
    assert_eq!(changes[0].0, TagId(1));
    assert_eq!(changes[0].1.value.as_f64(), Some(2.5));
    assert_eq!(changes[0].1.timestamp, ts(30));
    assert_eq!(changes[1].1.quality, Quality::bad("device offline"));
    assert!(sub.try_recv().is_none());
}

#[tokio::test]
async fn filtered_subscription_sees_only_its_tags() {
    let db = db(3);
    let mut sub = db.subscribe(&[TagId(2)]);
    db.apply([(TagId(0), Sample::good(1.0, ts(1)))]);
    db.apply([(TagId(2), Sample::good(7.0, ts(2)))]);
    let u = sub.recv().await.unwrap();
    assert_eq!(u.batch().changes.len(), 1);
    assert_eq!(u.batch().changes[0].0, TagId(2));
}

#[tokio::test]
async fn slow_subscriber_gets_a_snapshot_and_never_rolls_back() {
    let db = db(2);
    let mut slow = db.subscribe_all();
    // Far more batches than the ring holds; the writer never waits.
    for i in 0..10_000 {
        db.apply([(TagId(0), Sample::good(i as f64, ts(i)))]);
    }
    let u = slow.recv().await.unwrap();
    assert!(u.is_snapshot(), "a lagging subscriber must be snapshotted");
    let snap = u.batch();
    assert_eq!(snap.changes.len(), 2);
    assert_eq!(snap.changes[0].1.value.as_f64(), Some(9999.0));
    // After the snapshot, it continues with new changes only.
    db.apply([(TagId(1), Sample::good(5.0, ts(20_000)))]);
    let u = slow.recv().await.unwrap();
    assert!(!u.is_snapshot());
    assert_eq!(
        u.batch().changes,
        vec![(TagId(1), Sample::good(5.0, ts(20_000)))]
    );
}

#[tokio::test]
async fn watch_returns_snapshot_of_new_set() {
    let db = db(3);
    db.apply([(TagId(1), Sample::good(4.0, ts(1)))]);
    let mut sub = db.subscribe(&[]);
    let u = sub.watch(Some(&[TagId(1)]));
    assert!(u.is_snapshot());
    assert_eq!(u.batch().changes[0].1.value.as_f64(), Some(4.0));
    db.apply([(TagId(1), Sample::good(5.0, ts(2)))]);
    assert_eq!(sub.recv().await.unwrap().batch().changes.len(), 1);
}

#[test]
fn set_quality_keeps_last_value() {
    let db = db(2);
    db.apply([(TagId(0), Sample::good(42.0, ts(1)))]);
    db.set_quality(&[TagId(0), TagId(1)], &Quality::bad("timeout"), ts(2));
    let s = db.get(TagId(0)).unwrap();
    assert_eq!(s.value.as_f64(), Some(42.0));
    assert_eq!(s.quality, Quality::bad("timeout"));
}

/// A scan that read a register before a confirmed write, and applies its
/// batch after it, cannot roll the written value back.
#[test]
fn an_older_observation_never_replaces_a_newer_sample() {
    let db = TagDb::new([TagMeta::new("A.Set", ValueKind::Float)]).unwrap();
    let id = db.id("A.Set").unwrap();
    let t = Timestamp::from_millis;
    // A scan reads the register...
    let scan_ticket = db.ticket();
    // ...a write is confirmed meanwhile (observed now)...
    db.apply([(id, Sample::good(41.1, t(2000)))]);
    // ...and the scan's older batch arrives after it: dropped.
    let changed = db.apply_observed([(id, Sample::good(33.3, t(1000)), scan_ticket)]);
    assert_eq!(changed, 0);
    assert_eq!(db.get(id).unwrap().value, Value::Float(41.1));
    // A later observation does replace it.
    let next = db.ticket();
    db.apply_observed([(id, Sample::good(41.2, t(3000)), next)]);
    assert_eq!(db.get(id).unwrap().value, Value::Float(41.2));
}

#[tokio::test]
async fn tags_added_at_run_time_fill_the_room_and_reach_subscribers() {
    let db = Arc::new(TagDb::with_room([TagMeta::new("Local.A", ValueKind::Float)], 2).unwrap());
    let mut all = db.subscribe_all();
    let mut only_local = db.subscribe(&[TagId(0)]);
    assert_eq!((db.len(), db.room_left()), (1, 2));
    // A sample for a slot not taken yet is ignored, not stored for later.
    assert_eq!(db.apply([(TagId(1), Sample::good(1.0, ts(1)))]), 0);
    assert!(db.get(TagId(1)).is_none());

    let id = db
        .add(TagMeta::new("site-a.Feeder.P", ValueKind::Float).units("kW"))
        .unwrap();
    assert_eq!(id, TagId(1));
    assert_eq!(db.id("site-a.Feeder.P"), Some(id));
    assert!(db.get(id).unwrap().is_never_read());
    assert_eq!(db.all_meta().count(), 2);
    assert_eq!(
        db.add(TagMeta::new("Local.A", ValueKind::Float)),
        Err(gridscada_tagdb::TagDbError::Duplicate("Local.A".into()))
    );

    db.apply([(id, Sample::good(5.0, ts(2)))]);
    let update = all.recv().await.unwrap();
    assert_eq!(update.batch().changes[0].0, id);
    assert!(only_local.try_recv().is_none());
    assert_eq!(db.snapshot_all().changes.len(), 2);

    db.add(TagMeta::new("site-a.Feeder.Q", ValueKind::Float))
        .unwrap();
    assert!(matches!(
        db.add(TagMeta::new("site-a.Feeder.S", ValueKind::Float)),
        Err(gridscada_tagdb::TagDbError::Full { room: 2, .. })
    ));
}

#[test]
fn an_event_repeating_the_value_at_another_time_is_delivered() {
    let db = db(1);
    let id = TagId(0);
    let mut sub = db.subscribe(&[id]);
    let _ = sub.try_recv(); // the snapshot
    db.apply([(id, Sample::good(1.0, ts(1000)))]);
    assert!(sub.try_recv().is_some());
    // A scan of the same value later: not a change.
    db.apply([(id, Sample::good(1.0, ts(2000)))]);
    assert!(sub.try_recv().is_none());
    // A device's event of the same value at its own (earlier) time: delivered.
    assert_eq!(db.apply_events([(id, Sample::good(1.0, ts(500)))]), 1);
    let got = sub.try_recv().expect("the event");
    assert_eq!(got.batch().changes[0].1.timestamp, ts(500));
    // The same event again: nothing new.
    assert_eq!(db.apply_events([(id, Sample::good(1.0, ts(500)))]), 0);
}
