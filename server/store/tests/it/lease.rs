//! The lease of a redundant pair on PostgreSQL: one holder at a time, an
//! epoch that only rises, expiry by the database's clock, release, the
//! fenced panel-state write; and SQLite refuses to be a pair's store.

use crate::common;

use std::time::Duration;

use common::{Engine, TestDb};
use gridscada_store::*;
use gridscada_tagdb::Timestamp;

#[tokio::test]
async fn one_holder_at_a_time_and_the_epoch_only_rises() {
    let Some(t) = TestDb::new(Engine::Postgres, "lease").await else {
        return;
    };
    let lease_len = Duration::from_millis(600);
    let mut a = t.store.lease("north", "a").unwrap();
    let mut b = t.store.lease("north", "b").unwrap();
    let mut other_site = t.store.lease("south", "c").unwrap();

    let LeaseState::Held { epoch: e1 } = a.claim(lease_len, None).await.unwrap() else {
        panic!("a takes the free lease");
    };
    assert_eq!(e1, 1);
    // Another site's lease is its own.
    assert_eq!(
        other_site.claim(lease_len, None).await.unwrap(),
        LeaseState::Held { epoch: 1 }
    );
    // b cannot take it while a holds it; a renews under the same epoch.
    match b.claim(lease_len, None).await.unwrap() {
        LeaseState::HeldBy {
            holder,
            epoch,
            remaining,
        } => {
            assert_eq!((holder.as_str(), epoch), ("a", 1));
            assert!(remaining > Duration::ZERO && remaining <= lease_len);
        }
        s => panic!("b must not win: {s:?}"),
    }
    assert_eq!(
        a.claim(lease_len, Some(e1)).await.unwrap(),
        LeaseState::Held { epoch: 1 }
    );
    // A restarted a (no epoch in hand) is not the holder either.
    let mut a_again = t.store.lease("north", "a").unwrap();
    assert!(matches!(
        a_again.claim(lease_len, None).await.unwrap(),
        LeaseState::HeldBy { .. }
    ));

    // a stops renewing: once expired, b takes it under a higher epoch, and
    // a's renewal under the old epoch fails.
    tokio::time::sleep(lease_len + Duration::from_millis(100)).await;
    assert_eq!(
        b.claim(lease_len, None).await.unwrap(),
        LeaseState::Held { epoch: 2 }
    );
    assert!(matches!(
        a.claim(lease_len, Some(e1)).await.unwrap(),
        LeaseState::HeldBy { ref holder, epoch: 2, .. } if holder == "b"
    ));

    // The fenced write: only the holder under its epoch writes, into its
    // own site's rows.
    let north = Store::open(
        &t.url,
        &OpenOptions {
            site: "north".into(),
            ..t.options.clone()
        },
    )
    .await
    .unwrap();
    let at = Timestamp::from_millis(5);
    let state = serde_json::json!({"mode": "auto"});
    let fence = |server: &str, epoch| Fence {
        site: "north".into(),
        server: server.into(),
        epoch,
    };
    assert!(!north
        .save_panel_state_fenced("SS1", &state, at, &fence("a", 1))
        .await
        .unwrap());
    assert!(north.panel_states().await.unwrap().is_empty());
    assert!(north
        .save_panel_state_fenced("SS1", &state, at, &fence("b", 2))
        .await
        .unwrap());
    assert_eq!(north.panel_states().await.unwrap().len(), 1);
    // Another site's store neither sees the row nor writes under north's lease.
    assert!(t.store.panel_states().await.unwrap().is_empty());
    assert!(t
        .store
        .save_panel_state_fenced("SS1", &state, at, &fence("b", 2))
        .await
        .is_err());
    north.close().await;

    // An orderly release lets a take over at once, under epoch 3.
    b.release(2).await.unwrap();
    assert_eq!(
        a.claim(lease_len, None).await.unwrap(),
        LeaseState::Held { epoch: 3 }
    );
    t.cleanup().await;
}

#[tokio::test]
async fn two_servers_claiming_at_once_never_both_win() {
    let Some(t) = TestDb::new(Engine::Postgres, "lease race").await else {
        return;
    };
    let len = Duration::from_millis(200);
    let mut a = t.store.lease("s", "a").unwrap();
    let mut b = t.store.lease("s", "b").unwrap();
    let mut last_epoch = 0;
    for _ in 0..20 {
        let (ra, rb) = tokio::join!(a.claim(len, None), b.claim(len, None));
        let (ra, rb) = (ra.unwrap(), rb.unwrap());
        let winners: Vec<u64> = [&ra, &rb]
            .iter()
            .filter_map(|r| match r {
                LeaseState::Held { epoch } => Some(*epoch),
                _ => None,
            })
            .collect();
        assert_eq!(winners.len(), 1, "{ra:?} {rb:?}");
        assert!(winners[0] > last_epoch, "the epoch only rises");
        last_epoch = winners[0];
        tokio::time::sleep(len + Duration::from_millis(30)).await;
    }
    t.cleanup().await;
}

#[tokio::test]
async fn sqlite_is_no_store_for_a_pair() {
    let t = TestDb::new(Engine::Sqlite, "lease on sqlite")
        .await
        .unwrap();
    let e = t.store.lease("main", "a").unwrap_err();
    assert!(e.to_string().contains("needs PostgreSQL"), "{e}");
    t.cleanup().await;
}
