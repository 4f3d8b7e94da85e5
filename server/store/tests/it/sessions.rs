//! Login sessions in the store, on both backends: they survive a reopen,
//! expired ones are swept (and reported expired before), and the users'
//! changes that end sessions delete them in the same call.

use crate::common;

use std::time::Duration;

use common::TestDb;
use gridscada_config::Role;
use gridscada_store::*;
use gridscada_tagdb::Timestamp;

fn ts(ms: i64) -> Timestamp {
    Timestamp::from_millis(ms)
}

async fn add_user(s: &Store, name: &str, role: Role) {
    s.create_user(&NewUser {
        name: name.into(),
        role,
        password_hash: "$argon2id$x".into(),
        group: role.label().into(),
        created_at: ts(1),
    })
    .await
    .unwrap();
}

fn session(token: &str, user: &str, role: Role, at: i64) -> SessionRecord {
    SessionRecord {
        key: SessionKey::of_token(token),
        user: user.into(),
        role,
        created_at: ts(at),
        last_seen: ts(at),
        idle: Some(Duration::from_secs(60)),
        expires_at: Some(ts(at + 3_600_000)),
        client: Some("192.0.2.7".into()),
        user_agent: Some("Firefox/1".into()),
    }
}

async fn keys_of(s: &Store, user: &str) -> Vec<SessionKey> {
    let mut k: Vec<SessionKey> = s
        .sessions()
        .await
        .unwrap()
        .into_iter()
        .filter(|r| r.user == user)
        .map(|r| r.key)
        .collect();
    k.sort();
    k
}

async fn sessions_survive_reopen(mut db: TestDb) {
    add_user(&db.store, "ann", Role::Operator).await;
    let a = session("token-a", "ann", Role::Operator, 1_000);
    db.store.create_session(&a, None).await.unwrap();
    db.store
        .touch_sessions(&[(a.key.clone(), ts(5_000))])
        .await
        .unwrap();
    // An older activity from another server does not move it back.
    db.store
        .touch_sessions(&[(a.key.clone(), ts(4_000))])
        .await
        .unwrap();
    db.reopen().await;
    let got = db.store.session(&a.key).await.unwrap().expect("stored");
    assert_eq!(
        got,
        SessionRecord {
            last_seen: ts(5_000),
            ..a.clone()
        }
    );
    assert!(!got.expired(ts(5_000 + 60_000)));
    assert!(got.expired(ts(5_000 + 60_001)), "idle from the stored time");
    // The token itself is nowhere in the table.
    assert_ne!(got.key.as_str(), "token-a");
    assert_eq!(got.key.as_str().len(), 64);

    // Rotation at login: the previous session ends with the new one's start.
    let b = session("token-b", "ann", Role::Operator, 6_000);
    db.store.create_session(&b, Some(&a.key)).await.unwrap();
    assert_eq!(keys_of(&db.store, "ann").await, vec![b.key.clone()]);
    // Logout.
    assert!(db.store.end_session(&b.key).await.unwrap());
    assert!(!db.store.end_session(&b.key).await.unwrap());
    assert!(db.store.session(&b.key).await.unwrap().is_none());
    db.cleanup().await;
}
both_backends!(survive_reopen, sessions_survive_reopen);

async fn expired_sessions_are_swept(db: TestDb) {
    let s = &db.store;
    add_user(s, "ann", Role::Operator).await;
    let idle = session("idle", "ann", Role::Operator, 0);
    let old = SessionRecord {
        idle: None,
        expires_at: Some(ts(10_000)),
        ..session("old", "ann", Role::Operator, 0)
    };
    let forever = SessionRecord {
        idle: None,
        expires_at: None,
        ..session("forever", "ann", Role::Display, 0)
    };
    let busy = session("busy", "ann", Role::Operator, 0);
    for r in [&idle, &old, &forever, &busy] {
        s.create_session(r, None).await.unwrap();
    }
    s.touch_sessions(&[(busy.key.clone(), ts(50_000))])
        .await
        .unwrap();
    // At 61 s the idle one has expired (and says so before any sweep), but
    // the sweep leaves it for the grace: another server may hold activity.
    let now = ts(61_000);
    let idle_row = s.session(&idle.key).await.unwrap().unwrap();
    assert!(idle_row.expired(now), "refused before the sweep");
    assert!(s.session(&old.key).await.unwrap().unwrap().expired(now));
    assert_eq!(
        s.sweep_sessions(now, Duration::from_secs(30))
            .await
            .unwrap(),
        1,
        "only the one past its absolute end"
    );
    assert!(s.session(&old.key).await.unwrap().is_none());
    assert!(s.session(&idle.key).await.unwrap().is_some());
    // Past the grace too: gone; the busy one (seen at 50 s) and the one
    // that never ends stay.
    assert_eq!(
        s.sweep_sessions(ts(91_000), Duration::from_secs(30))
            .await
            .unwrap(),
        1
    );
    let mut left = keys_of(s, "ann").await;
    left.sort();
    let mut want = vec![busy.key.clone(), forever.key.clone()];
    want.sort();
    assert_eq!(left, want);
    assert_eq!(
        s.sweep_sessions(ts(10_000_000_000), Duration::ZERO)
            .await
            .unwrap(),
        1,
        "the busy one, eventually; never the one without expiry"
    );
    assert_eq!(keys_of(s, "ann").await, vec![forever.key.clone()]);
    db.cleanup().await;
}
both_backends!(sweep, expired_sessions_are_swept);

async fn user_changes_revoke_sessions(db: TestDb) {
    let s = &db.store;
    for u in ["ann", "bob", "cid", "dan", "eve"] {
        add_user(s, u, Role::Operator).await;
    }
    let mut n = 0;
    let mut open = |user: &str| {
        n += 1;
        session(&format!("{user}-{n}"), user, Role::Operator, n)
    };
    let mut all = vec![];
    for u in ["ann", "ann", "bob", "cid", "dan", "dan", "eve"] {
        let r = open(u);
        s.create_session(&r, None).await.unwrap();
        all.push(r);
    }
    // Block: all of ann's go; unblocking brings none back, ends none.
    s.set_user_blocked("ann", true).await.unwrap();
    assert!(keys_of(s, "ann").await.is_empty());
    s.set_user_blocked("bob", false).await.unwrap();
    assert_eq!(keys_of(s, "bob").await.len(), 1, "unblock ends nothing");
    // Delete: bob's go with him.
    assert!(s.delete_user("bob").await.unwrap());
    assert!(keys_of(s, "bob").await.is_empty());
    // Role: cid's operator session goes when he becomes a supervisor; the
    // same role again ends nothing.
    s.set_user_role("dan", Role::Operator).await.unwrap();
    assert_eq!(keys_of(s, "dan").await.len(), 2);
    s.set_user_role("cid", Role::Supervisor).await.unwrap();
    assert!(keys_of(s, "cid").await.is_empty());
    // Password: all of dan's but the one that changed it.
    let keep = all[4].key.clone();
    s.set_password_hash("dan", "$argon2id$y", ts(9), Some(&keep))
        .await
        .unwrap();
    assert_eq!(keys_of(s, "dan").await, vec![keep]);
    s.set_password_hash("dan", "$argon2id$z", ts(10), None)
        .await
        .unwrap();
    assert!(keys_of(s, "dan").await.is_empty());
    // Nobody else's moved; a change of a missing user fails and ends nothing.
    assert_eq!(keys_of(s, "eve").await.len(), 1);
    assert!(matches!(
        s.set_user_role("ghost", Role::Guest).await,
        Err(StoreError::NotFound(_))
    ));
    assert_eq!(s.end_user_sessions("eve", None).await.unwrap(), 1);
    assert!(s.sessions().await.unwrap().is_empty());
    db.cleanup().await;
}
both_backends!(revocation, user_changes_revoke_sessions);

fn ticket(token: &str, origin: &SessionRecord, at: i64, lasts: i64) -> TicketRecord {
    TicketRecord {
        key: SessionKey::of_token(token),
        session: origin.key.clone(),
        user: origin.user.clone(),
        role: origin.role,
        created_at: ts(at),
        expires_at: ts(at + lasts),
        session_expires_at: origin.expires_at,
    }
}

/// Failover tickets are their own kind: no session lookup finds one, a
/// claim takes it once, only before it expires and while the session that
/// issued it lives (not after its logout, a revocation or its expiry); the
/// claim carries that session's absolute end; a renewal ends only the same
/// session's earlier ticket; the sweep deletes spent ones.
async fn failover_tickets(db: TestDb) {
    let s = &db.store;
    add_user(s, "ann", Role::Operator).await;
    add_user(s, "bob", Role::Operator).await;
    let origin = session("ann-1", "ann", Role::Operator, 1_000);
    s.create_session(&origin, None).await.unwrap();
    let t1 = ticket("ticket-1", &origin, 2_000, 180_000);
    s.create_ticket(&t1, None).await.unwrap();
    // Not a session, nor listed with them.
    assert_eq!(s.session(&t1.key).await.unwrap(), None);
    assert_eq!(s.sessions().await.unwrap().len(), 1);
    // Claimed once, carrying the session's end.
    let got = s.claim_ticket(&t1.key, ts(3_000)).await.unwrap();
    assert_eq!(got.as_ref(), Some(&t1));
    assert_eq!(got.unwrap().session_expires_at, Some(ts(3_601_000)));
    assert_eq!(s.claim_ticket(&t1.key, ts(3_000)).await.unwrap(), None);
    // Expired: refused (and gone).
    let t2 = ticket("ticket-2", &origin, 2_000, 1_000);
    s.create_ticket(&t2, None).await.unwrap();
    assert_eq!(s.claim_ticket(&t2.key, ts(3_001)).await.unwrap(), None);
    // The issuing session idled out (stored last_seen 1000, idle 60 s):
    // refused even before the sweep.
    let t3 = ticket("ticket-3", &origin, 2_000, 180_000);
    s.create_ticket(&t3, None).await.unwrap();
    assert_eq!(s.claim_ticket(&t3.key, ts(61_001)).await.unwrap(), None);
    // A renewal ends the same session's earlier ticket, not another's.
    let t4 = ticket("ticket-4", &origin, 2_000, 180_000);
    s.create_ticket(&t4, None).await.unwrap();
    let other = session("bob-1", "bob", Role::Operator, 1_000);
    s.create_session(&other, None).await.unwrap();
    let t5 = ticket("ticket-5", &other, 2_000, 180_000);
    s.create_ticket(&t5, Some(&t4.key)).await.unwrap();
    let t6 = ticket("ticket-6", &origin, 2_500, 180_000);
    s.create_ticket(&t6, Some(&t4.key)).await.unwrap();
    assert_eq!(s.claim_ticket(&t4.key, ts(3_000)).await.unwrap(), None);
    assert_eq!(
        s.claim_ticket(&t5.key, ts(3_000)).await.unwrap(),
        Some(t5.clone())
    );
    // Logout of the issuing session: its ticket dies with it.
    assert!(s.end_session(&origin.key).await.unwrap());
    assert_eq!(s.claim_ticket(&t6.key, ts(3_000)).await.unwrap(), None);
    // A revocation (block) ends the user's sessions and so their tickets.
    let t7 = ticket("ticket-7", &other, 2_000, 180_000);
    s.create_ticket(&t7, None).await.unwrap();
    s.set_user_blocked("bob", true).await.unwrap();
    assert_eq!(s.claim_ticket(&t7.key, ts(3_000)).await.unwrap(), None);
    // The sweep deletes tickets that expired or lost their session.
    let live = session("ann-2", "ann", Role::Operator, 10_000);
    s.create_session(&live, None).await.unwrap();
    let orphan = ticket("ticket-8", &other, 10_000, 180_000);
    let stale = ticket("ticket-9", &live, 10_000, 1_000);
    let kept = ticket("ticket-10", &live, 10_000, 180_000);
    for t in [&orphan, &stale, &kept] {
        s.create_ticket(t, None).await.unwrap();
    }
    s.sweep_sessions(ts(20_000), Duration::ZERO).await.unwrap();
    assert_eq!(db.count("SELECT count(*) FROM handover_tickets").await, 1);
    assert_eq!(
        s.claim_ticket(&kept.key, ts(20_000)).await.unwrap(),
        Some(kept)
    );
    db.cleanup().await;
}
both_backends!(tickets, failover_tickets);
