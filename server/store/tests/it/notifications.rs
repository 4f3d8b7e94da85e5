//! The notification outbox on both backends: queue, due order, retries,
//! outcomes, the escalation record and pruning.

use crate::common;

use common::TestDb;
use gridscada_store::*;
use gridscada_tagdb::Timestamp;

fn msg(route: &str, key: Option<&str>, level: u32, at: i64) -> NewNotification {
    NewNotification {
        created_at: Timestamp::from_millis(at),
        route: route.into(),
        contact: "Day".into(),
        address: "day@example.com".into(),
        alarm_key: key.map(str::to_owned),
        level,
        subject: "subject".into(),
        message: "{}".into(),
        give_up_at: Timestamp::from_millis(at + 60_000),
    }
}

async fn the_outbox_keeps_retries_and_outcomes(db: TestDb) {
    let store = &db.store;
    let a = store
        .enqueue_notification(&msg("r", Some("A"), 0, 1000))
        .await
        .unwrap();
    let b = store
        .enqueue_notification(&msg("r", Some("A"), 1, 2000))
        .await
        .unwrap();
    let c = store
        .enqueue_notification(&msg("r", None, 0, 3000))
        .await
        .unwrap();
    assert_eq!(store.pending_notifications().await.unwrap(), 3);
    let due = store
        .due_notifications(Timestamp::from_millis(2500), 10)
        .await
        .unwrap();
    assert_eq!(due.iter().map(|n| n.id).collect::<Vec<_>>(), vec![a, b]);
    store
        .notification_sent(a, Timestamp::from_millis(2600), 1)
        .await
        .unwrap();
    store
        .notification_attempt_failed(
            b,
            1,
            Some(Timestamp::from_millis(9000)),
            Timestamp::from_millis(2600),
            "refused",
        )
        .await
        .unwrap();
    store
        .notification_attempt_failed(c, 3, None, Timestamp::from_millis(3100), "given up")
        .await
        .unwrap();
    assert_eq!(store.pending_notifications().await.unwrap(), 1);
    assert_eq!(
        store.next_notification_due().await.unwrap(),
        Some(Timestamp::from_millis(9000))
    );
    let all = store.notifications(10).await.unwrap();
    let by_id = |id| all.iter().find(|n| n.id == id).unwrap();
    assert_eq!(by_id(a).status, NotificationStatus::Sent);
    assert_eq!(by_id(b).last_error.as_deref(), Some("refused"));
    assert_eq!(by_id(c).status, NotificationStatus::Failed);
    let last = store
        .last_notified("r", Timestamp::from_millis(0))
        .await
        .unwrap();
    assert_eq!(
        last,
        vec![LastNotified {
            alarm_key: "A".into(),
            level: 1,
            at: Timestamp::from_millis(2000)
        }]
    );
    assert_eq!(
        store
            .prune_notifications(Timestamp::from_millis(5000), 10)
            .await
            .unwrap(),
        2
    );
    assert_eq!(store.notifications(10).await.unwrap().len(), 1);
}

both_backends!(outbox, the_outbox_keeps_retries_and_outcomes);
