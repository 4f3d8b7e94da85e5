//! Switching programmes and safety tags in the store, on both backends: a
//! programme survives a reopen; every change names the version it read, so
//! a second change from the same version is refused and changes nothing;
//! approval is kept; a tag removed once cannot be removed again.

use crate::common;

use common::TestDb;
use gridscada_store::*;
use gridscada_tagdb::Timestamp;

fn ts(ms: i64) -> Timestamp {
    Timestamp::from_millis(ms)
}

fn change(state: &str, next_step: i64, at: i64) -> ProgrammeChange<'_> {
    ProgrammeChange {
        state,
        next_step,
        approved_by: None,
        note: "",
        at: ts(at),
    }
}

async fn programmes_move_on_one_version_at_a_time(mut db: TestDb) {
    let steps = r#"[{"kind":"manual","text":"a"},{"kind":"manual","text":"b"}]"#;
    let p = db
        .store
        .create_programme("C2 out", steps, "draft", "sam", ts(1_000))
        .await
        .unwrap();
    assert_eq!((p.state.as_str(), p.next_step, p.version), ("draft", 0, 1));
    let approved = db
        .store
        .update_programme(
            p.id,
            p.version,
            ProgrammeChange {
                approved_by: Some("sue"),
                ..change("approved", 0, 2_000)
            },
        )
        .await
        .unwrap();
    assert_eq!(approved.approved_by.as_deref(), Some("sue"));
    assert_eq!(approved.approved_at, Some(ts(2_000)));
    // Two operators took step 1 from the same version: the second is refused.
    let one = db
        .store
        .update_programme(p.id, approved.version, change("running", 1, 3_000))
        .await
        .unwrap();
    let again = db
        .store
        .update_programme(p.id, approved.version, change("running", 2, 3_001))
        .await;
    assert!(matches!(again, Err(StoreError::Conflict(_))), "{again:?}");
    db.reopen().await;
    let now = db.store.programme(p.id).await.unwrap().unwrap();
    assert_eq!(now, one);
    assert_eq!(now.approved_by.as_deref(), Some("sue"), "approval kept");
    assert_eq!(now.steps, steps);
    let list = db.store.programmes(10).await.unwrap();
    assert_eq!(list.len(), 1);
    assert!(db.store.programme(p.id + 100).await.unwrap().is_none());
    // Safety tags: removed once.
    let t = db
        .store
        .place_safety_tag(
            "rmu1_s2",
            "do_not_close",
            "C2 out",
            "WO-1",
            "sam",
            ts(4_000),
        )
        .await
        .unwrap();
    assert_eq!(
        db.store.standing_safety_tags().await.unwrap(),
        vec![t.clone()]
    );
    db.store
        .remove_safety_tag(t.id, "sue", "done", ts(5_000))
        .await
        .unwrap();
    let twice = db
        .store
        .remove_safety_tag(t.id, "sue", "done", ts(6_000))
        .await;
    assert!(matches!(twice, Err(StoreError::Conflict(_))), "{twice:?}");
    assert!(db.store.standing_safety_tags().await.unwrap().is_empty());
    assert_eq!(db.store.safety_tag_history(10).await.unwrap().len(), 1);
    db.cleanup().await;
}

both_backends!(programmes, programmes_move_on_one_version_at_a_time);
