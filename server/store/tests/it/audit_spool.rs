//! The audit trail's spool on SQLite: records the store cannot take are
//! spooled, replayed in order, never stored twice, a torn line is cut off,
//! and a record that can be neither stored nor spooled is refused.

use std::path::Path;
use std::time::Duration;

use gridscada_store::{
    read_spool, AuditBody, AuditConfig, AuditError, AuditRecord, AuditTable, AuditTrail,
    EventFilter, NewEvent, OpenOptions, Store, SPOOL_FILE,
};
use gridscada_tagdb::Timestamp;

use crate::common;

async fn open(dir: &Path) -> Store {
    Store::open("sqlite://audit.db", &OpenOptions::new(dir))
        .await
        .unwrap()
}

/// A store whose every write fails: its pools are closed.
async fn broken(dir: &Path) -> Store {
    let s = open(dir).await;
    s.close().await;
    s
}

fn event(n: i64) -> NewEvent {
    NewEvent {
        ts: Timestamp::from_millis(1_000_000 + n),
        user: Some("alice".into()),
        source: "web".into(),
        kind: "command".into(),
        message: format!("record {n}"),
    }
}

fn config(dir: &Path) -> AuditConfig {
    let mut c = AuditConfig::new(dir);
    c.write_timeout = Duration::from_millis(500);
    c.max_backoff = Duration::from_millis(200);
    c
}

/// The stored events' messages, oldest first.
async fn messages(store: &Store) -> Vec<String> {
    let mut e = store
        .events(&EventFilter {
            limit: 10_000,
            ..Default::default()
        })
        .await
        .unwrap();
    e.reverse();
    e.into_iter().map(|e| e.message).collect()
}

async fn until_drained(trail: &AuditTrail) {
    let h = trail.handle();
    for _ in 0..200 {
        if h.metrics().pending == 0 && !h.metrics().spooling {
            return;
        }
        tokio::time::sleep(Duration::from_millis(25)).await;
    }
    panic!("the spool did not drain: {:?}", h.metrics());
}

fn expected(range: std::ops::RangeInclusive<i64>) -> Vec<String> {
    range.map(|n| format!("record {n}")).collect()
}

#[tokio::test]
async fn spooled_while_the_store_is_away_then_replayed_in_order() {
    let dir = tempfile::tempdir().unwrap();
    let trail = AuditTrail::start(broken(dir.path()).await, config(dir.path()))
        .await
        .unwrap();
    let h = trail.handle();
    for n in 1..=5 {
        h.record_durable(AuditBody::Event(event(n))).await.unwrap();
    }
    let m = h.metrics();
    assert_eq!((m.spooled, m.pending, m.stored, m.lost), (5, 5, 0, 0));
    assert!(m.spooling);
    trail.shutdown().await;
    let spool = read_spool(&dir.path().join("audit-spool").join(SPOOL_FILE)).unwrap();
    assert_eq!(spool.records.len(), 5);
    assert!(spool.records.windows(2).all(|w| w[0].seq < w[1].seq));

    // The next start replays the leftover spool before anything new.
    let store = open(dir.path()).await;
    let trail = AuditTrail::start(store.clone(), config(dir.path()))
        .await
        .unwrap();
    assert!(trail.handle().metrics().spooling);
    trail
        .handle()
        .record_durable(AuditBody::Event(event(6)))
        .await
        .unwrap();
    until_drained(&trail).await;
    assert_eq!(messages(&store).await, expected(1..=6));
    let m = trail.shutdown().await;
    assert_eq!((m.replayed, m.pending, m.lost), (6, 0, 0), "{m:?}");
    assert!(!dir.path().join("audit-spool").join(SPOOL_FILE).exists());
}

#[tokio::test]
async fn a_torn_last_line_is_reported_and_cut_off() {
    let dir = tempfile::tempdir().unwrap();
    let spool_dir = dir.path().join("audit-spool");
    std::fs::create_dir_all(&spool_dir).unwrap();
    let mut text = String::new();
    for n in 1..=2 {
        let r = AuditRecord {
            seq: n,
            body: AuditBody::Event(event(n)),
        };
        text += &serde_json::to_string(&r).unwrap();
        text.push('\n');
    }
    text += r#"{"seq":3,"event":{"ts":1000003,"us"#;
    std::fs::write(spool_dir.join(SPOOL_FILE), &text).unwrap();

    let store = open(dir.path()).await;
    let trail = AuditTrail::start(store.clone(), config(dir.path()))
        .await
        .unwrap();
    assert_eq!(trail.handle().metrics().torn_lines, 1);
    trail
        .handle()
        .record_durable(AuditBody::Event(event(4)))
        .await
        .unwrap();
    until_drained(&trail).await;
    assert_eq!(messages(&store).await, ["record 1", "record 2", "record 4"]);
    trail.shutdown().await;
}

#[tokio::test]
async fn a_replay_after_a_crash_between_commit_and_trim_stores_nothing_twice() {
    let dir = tempfile::tempdir().unwrap();
    let store = open(dir.path()).await;
    let records: Vec<AuditRecord> = (1..=4)
        .map(|n| AuditRecord {
            seq: n,
            body: AuditBody::Event(event(n)),
        })
        .collect();
    // Committed, but the spool was not trimmed (the process died).
    store.insert_audit(&records[..3]).await.unwrap();
    let spool_dir = dir.path().join("audit-spool");
    std::fs::create_dir_all(&spool_dir).unwrap();
    let text: String = records
        .iter()
        .map(|r| serde_json::to_string(r).unwrap() + "\n")
        .collect();
    std::fs::write(spool_dir.join(SPOOL_FILE), text).unwrap();

    let trail = AuditTrail::start(store.clone(), config(dir.path()))
        .await
        .unwrap();
    until_drained(&trail).await;
    trail.shutdown().await;
    assert_eq!(messages(&store).await, expected(1..=4));
    // And once more, the whole spool again.
    store.insert_audit(&records).await.unwrap();
    assert_eq!(messages(&store).await, expected(1..=4));
    // New records number on above the stored ones.
    assert!(store.max_audit_id().await.unwrap() >= 4);
}

#[tokio::test]
async fn a_record_neither_stored_nor_spooled_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let trail = AuditTrail::start(broken(dir.path()).await, config(dir.path()))
        .await
        .unwrap();
    // The spool folder's place is taken by a file: nothing can be spooled.
    std::fs::write(dir.path().join("audit-spool"), "not a folder").unwrap();
    let h = trail.handle();
    let e = h.record_durable(AuditBody::Event(event(1))).await;
    assert!(matches!(e, Err(AuditError::Unavailable { .. })), "{e:?}");
    assert!(h.probe().await.is_err());
    assert_eq!(h.metrics().lost, 1);
    trail.shutdown().await;

    // With the store back, the probe and records pass again.
    std::fs::remove_file(dir.path().join("audit-spool")).unwrap();
    let store = open(dir.path()).await;
    let trail = AuditTrail::start(store.clone(), config(dir.path()))
        .await
        .unwrap();
    trail.handle().probe().await.unwrap();
    trail
        .handle()
        .record_durable(AuditBody::Event(event(2)))
        .await
        .unwrap();
    assert_eq!(messages(&store).await, ["record 2"]);
    trail.shutdown().await;
}

#[tokio::test]
async fn retention_prunes_old_rows_in_batches() {
    let dir = tempfile::tempdir().unwrap();
    let store = open(dir.path()).await;
    let records: Vec<AuditRecord> = (1..=10)
        .map(|n| AuditRecord {
            seq: n,
            body: AuditBody::Event(event(n)),
        })
        .collect();
    store.insert_audit(&records).await.unwrap();
    // Rows before record 8 go, three at a time.
    let before = Timestamp::from_millis(1_000_008);
    let mut rounds = vec![];
    loop {
        let n = store
            .prune_audit(AuditTable::Events, before, 3)
            .await
            .unwrap();
        rounds.push(n);
        if n < 3 {
            break;
        }
    }
    assert_eq!(rounds, [3, 3, 1]);
    assert_eq!(messages(&store).await, expected(8..=10));
    for t in [AuditTable::AlarmHistory, AuditTable::Dispatches] {
        assert_eq!(store.prune_audit(t, before, 3).await.unwrap(), 0);
    }
}

/// The audit SQL on both backends: an idempotent insert by audit id (events
/// and alarm transitions), the last id, and batched retention.
#[tokio::test]
async fn audit_rows_on_both_backends() {
    for engine in [common::Engine::Sqlite, common::Engine::Postgres] {
        let Some(db) = common::TestDb::new(engine, "audit_rows").await else {
            continue;
        };
        let store = &db.store;
        let mut records: Vec<AuditRecord> = (1..=6)
            .map(|n| AuditRecord {
                seq: n,
                body: AuditBody::Event(event(n)),
            })
            .collect();
        records.push(AuditRecord {
            seq: 7,
            body: AuditBody::Transition(gridscada_store::AlarmTransition {
                ts: Timestamp::from_millis(1_000_007),
                alarm_key: "flood:1".into(),
                tag: String::new(),
                kind: "system".into(),
                from_state: "normal".into(),
                to_state: "unack_active".into(),
                cause: Some("activate".into()),
                activation: true,
                value: None,
                limit: None,
                user: None,
                message: "Flood".into(),
                priority: 500,
                selection: "SYSTEM".into(),
            }),
        });
        store.insert_audit(&records).await.unwrap();
        store.insert_audit(&records).await.unwrap();
        assert_eq!(messages(store).await, expected(1..=6), "{engine:?}");
        let history = store
            .alarm_history(&gridscada_store::AlarmHistoryFilter {
                limit: 100,
                ..Default::default()
            })
            .await
            .unwrap();
        assert_eq!(history.len(), 1, "{engine:?}");
        assert_eq!(store.max_audit_id().await.unwrap(), 7, "{engine:?}");
        let before = Timestamp::from_millis(1_000_005);
        assert_eq!(
            store
                .prune_audit(AuditTable::Events, before, 2)
                .await
                .unwrap(),
            2
        );
        assert_eq!(
            store
                .prune_audit(AuditTable::Events, before, 2)
                .await
                .unwrap(),
            2
        );
        assert_eq!(
            store
                .prune_audit(AuditTable::Events, before, 2)
                .await
                .unwrap(),
            0
        );
        assert_eq!(messages(store).await, expected(5..=6), "{engine:?}");
        let later = Timestamp::from_millis(2_000_000);
        assert_eq!(
            store
                .prune_audit(AuditTable::AlarmHistory, later, 10)
                .await
                .unwrap(),
            1
        );
        assert_eq!(
            store
                .prune_audit(AuditTable::Dispatches, later, 10)
                .await
                .unwrap(),
            0
        );
    }
}
