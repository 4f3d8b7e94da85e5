//! Sessions kept in the store, on both backends: a cookie outlives a
//! restart of the server and its idle timer goes on from the stored
//! activity; an expired session is refused before the sweep deletes it;
//! blocking, deleting, a password change and a role change end the user's
//! sessions and close their live sockets, made through the API or from
//! another process on the same database (as `gridscada user` runs).

use crate::common;

use std::time::{Duration, Instant};

use axum::http::{Method, StatusCode};
use common::*;
use futures::StreamExt;
use gridscada_config::Role;
use gridscada_store::SessionKey;
use gridscada_web::auth::{SessionPolicy, SYNC_EVERY};
use serde_json::json;
use tokio_tungstenite::tungstenite::Message;

/// Defines `NAME::sqlite` and `NAME::postgres`, running `body(options)`.
macro_rules! both_backends {
    ($name:ident, $body:path) => {
        mod $name {
            use super::*;
            #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
            async fn sqlite() {
                $body(Options::default()).await;
            }
            #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
            async fn postgres() {
                if let Some(url) = pg_url(concat!("sessions::", stringify!($name))) {
                    $body(Options {
                        postgres: Some(url),
                        ..Options::default()
                    })
                    .await;
                }
            }
        }
    };
}

/// The session's key in the store, from a `Cookie` header value.
fn key(cookie: &str) -> SessionKey {
    SessionKey::of_token(cookie.split_once('=').expect("name=token").1)
}

/// Who the session cookie is now (`None`: anonymous).
async fn whoami(h: &Harness, cookie: &str) -> Option<String> {
    let r = h
        .call(Method::GET, "/api/session", Some(cookie), None)
        .await;
    assert_eq!(r.status, StatusCode::OK);
    r.json()["user"].as_str().map(str::to_string)
}

async fn stored_sessions_of(h: &Harness, user: &str) -> usize {
    h.state
        .store
        .sessions()
        .await
        .unwrap()
        .iter()
        .filter(|s| s.user == user)
        .count()
}

async fn survive_a_restart(opts: Options) {
    let idle = Duration::from_secs(4);
    let mut h = Harness::new(Options {
        policy: SessionPolicy {
            idle,
            ..Default::default()
        },
        ..opts
    })
    .await;
    let used = h.login("operator", PASSWORD).await;
    let idle_one = h.login("supervisor", PASSWORD).await;
    let t0 = Instant::now();
    // The login is in the store before its cookie is out, with the client.
    let row = h.state.store.session(&key(&idle_one)).await.unwrap();
    let row = row.expect("stored at login");
    assert_eq!(
        (row.user.as_str(), row.role),
        ("supervisor", Role::Supervisor)
    );
    assert_eq!(row.client.as_deref(), Some("127.0.0.1"));
    assert_eq!(row.idle, Some(idle));

    // A restart: nothing cached, the same cookies still work.
    tokio::time::sleep(Duration::from_secs(2)).await;
    h.restart().await;
    assert_eq!(whoami(&h, &used).await.as_deref(), Some("operator"));
    // Its activity reaches the store within the write-through bound.
    h.state.auth.sessions.sync().await;
    let seen = h.state.store.session(&key(&used)).await.unwrap().unwrap();
    assert!(seen.last_seen > seen.created_at, "activity written through");

    // The idle timer went on from the stored activity: the session left
    // alone since its login idles out 4 s after it, restart or not, while
    // the one used after the restart lives on.
    tokio::time::sleep(
        (t0 + idle + Duration::from_millis(300)).saturating_duration_since(Instant::now()),
    )
    .await;
    h.restart().await;
    assert!(
        h.state
            .store
            .session(&key(&idle_one))
            .await
            .unwrap()
            .is_some(),
        "not swept yet"
    );
    assert_eq!(
        whoami(&h, &idle_one).await,
        None,
        "expired: refused before the sweep"
    );
    assert_eq!(whoami(&h, &used).await.as_deref(), Some("operator"));
    assert_eq!(
        stored_sessions_of(&h, "supervisor").await,
        0,
        "ended at first sight"
    );

    // Logout deletes the row; the cookie is dead after a restart too.
    let r = h
        .call(Method::DELETE, "/api/session", Some(&used), None)
        .await;
    assert_eq!(r.status, StatusCode::NO_CONTENT);
    assert_eq!(stored_sessions_of(&h, "operator").await, 0);
    h.restart().await;
    assert_eq!(whoami(&h, &used).await, None);
    h.cleanup().await;
}
both_backends!(restart, survive_a_restart);

/// Waits until the live socket closes; its close code, or `None` if it did
/// not close within `within`.
async fn closed_within(ws: &mut LiveSocket, within: Duration) -> Option<u16> {
    let deadline = tokio::time::Instant::now() + within;
    loop {
        match tokio::time::timeout_at(deadline, ws.next()).await {
            Err(_) => return None,
            Ok(None) | Ok(Some(Err(_))) => return Some(0),
            Ok(Some(Ok(Message::Close(f)))) => return Some(f.map_or(0, |f| u16::from(f.code))),
            Ok(Some(Ok(_))) => continue,
        }
    }
}

/// One user per change, each with a session and a live socket open.
const VICTIMS: [&str; 4] = ["v_block", "v_delete", "v_password", "v_role"];

async fn victims(h: &Harness) -> Vec<(String, LiveSocket)> {
    let addr = h.serve().await;
    let mut out = vec![];
    for v in VICTIMS {
        h.add_user(v, Role::Operator, "operator").await;
        let cookie = h.login(v, PASSWORD).await;
        let mut ws = live_socket(addr, &cookie).await.expect("live socket");
        let hello = next_message(&mut ws).await.unwrap();
        assert_eq!(hello["user"], v);
        out.push((cookie, ws));
    }
    out
}

async fn all_revoked(h: &Harness, sessions: &mut [(String, LiveSocket)], within: Duration) {
    for (v, (cookie, ws)) in VICTIMS.iter().zip(sessions.iter_mut()) {
        assert_eq!(
            closed_within(ws, within).await,
            Some(4001),
            "{v}'s live socket closes as its session ends"
        );
        assert_eq!(whoami(h, cookie).await, None, "{v}'s cookie is refused");
        assert_eq!(
            stored_sessions_of(h, v).await,
            0,
            "{v}'s sessions are gone from the store"
        );
    }
}

async fn revoked_through_the_api(opts: Options) {
    let h = Harness::new(opts).await;
    let mut open = victims(&h).await;
    let admin = h.login("administrator", PASSWORD).await;
    let ok =
        |r: Resp, what: &str| assert!(r.status.is_success(), "{what}: {} {}", r.status, r.text());
    ok(
        h.call(
            Method::PATCH,
            "/api/users/v_block",
            Some(&admin),
            Some(json!({"blocked": true})),
        )
        .await,
        "block",
    );
    ok(
        h.call(
            Method::DELETE,
            "/api/users/v_delete",
            Some(&admin),
            Some(json!({"confirm": "v_delete"})),
        )
        .await,
        "delete",
    );
    ok(
        h.call(
            Method::POST,
            "/api/users/v_password/password",
            Some(&admin),
            Some(json!({"password": "another good passphrase"})),
        )
        .await,
        "password",
    );
    ok(
        h.call(
            Method::PATCH,
            "/api/users/v_role",
            Some(&admin),
            Some(json!({"role": "supervisor"})),
        )
        .await,
        "role",
    );
    // This server drops them at once: no waiting for a re-check.
    all_revoked(&h, &mut open, Duration::from_secs(2)).await;
    assert_eq!(whoami(&h, &admin).await.as_deref(), Some("administrator"));

    // One's own password: the other sessions end, this one goes on.
    let mine = h.login("operator", PASSWORD).await;
    let other = h.login("operator", PASSWORD).await;
    ok(
        h.call(
            Method::POST,
            "/api/users/operator/password",
            Some(&mine),
            Some(json!({"password": "another good passphrase", "current_password": PASSWORD})),
        )
        .await,
        "own password",
    );
    assert_eq!(whoami(&h, &other).await, None);
    assert_eq!(whoami(&h, &mine).await.as_deref(), Some("operator"));
    assert_eq!(stored_sessions_of(&h, "operator").await, 1);
    // Unblocking brings no session back.
    ok(
        h.call(
            Method::PATCH,
            "/api/users/v_block",
            Some(&admin),
            Some(json!({"blocked": false})),
        )
        .await,
        "unblock",
    );
    assert_eq!(whoami(&h, &open[0].0).await, None);
    h.cleanup().await;
}
both_backends!(api_revocation, revoked_through_the_api);

/// The same changes made by another process on the same database (as the
/// `gridscada user` command does, or a second server): this server notices
/// within its re-check interval, with no request to prompt it.
async fn revoked_from_another_process(opts: Options) {
    let h = Harness::new(opts).await;
    let mut open = victims(&h).await;
    let other = h.another_store().await;
    let at = gridscada_tagdb::Timestamp::now_utc();
    other.set_user_blocked("v_block", true).await.unwrap();
    assert!(other.delete_user("v_delete").await.unwrap());
    other
        .set_password_hash("v_password", "$argon2id$elsewhere", at, None)
        .await
        .unwrap();
    other
        .set_user_role("v_role", Role::Supervisor)
        .await
        .unwrap();
    other.close().await;
    all_revoked(&h, &mut open, SYNC_EVERY + Duration::from_secs(3)).await;
    h.cleanup().await;
}
both_backends!(cli_revocation, revoked_from_another_process);

/// Two servers on one database: a login on one is good on the other, and a
/// logout or a block on one reaches the other within the re-check interval.
async fn two_servers_share_sessions(opts: Options) {
    let a = Harness::new(opts).await;
    let b = a.another_server().await;
    let peer = "127.0.0.1:40001".parse().unwrap();
    let who_on_b = |cookie: String| {
        let b = b.clone();
        async move {
            let r = send_to(
                &b,
                request(Method::GET, "/api/session", Some(&cookie), None),
                peer,
            )
            .await;
            assert_eq!(r.status, StatusCode::OK);
            r.json()["user"].as_str().map(str::to_string)
        }
    };
    let op = a.login("operator", PASSWORD).await;
    let sup = a.login("supervisor", PASSWORD).await;
    assert_eq!(who_on_b(op.clone()).await.as_deref(), Some("operator"));
    assert_eq!(who_on_b(sup.clone()).await.as_deref(), Some("supervisor"));
    // Logged out on B: A has it cached, and drops it within its re-check.
    let r = send_to(
        &b,
        request(Method::DELETE, "/api/session", Some(&op), None),
        peer,
    )
    .await;
    assert_eq!(r.status, StatusCode::NO_CONTENT);
    eventually(
        "A refuses a session ended on B",
        SYNC_EVERY + Duration::from_secs(3),
        || async { whoami(&a, &op).await.is_none().then_some(()) },
    )
    .await;
    // Blocked through A's API: B refuses at its next request.
    let admin = a.login("administrator", PASSWORD).await;
    let r = a
        .call(
            Method::PATCH,
            "/api/users/supervisor",
            Some(&admin),
            Some(json!({"blocked": true})),
        )
        .await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text());
    assert_eq!(who_on_b(sup.clone()).await, None);
    a.cleanup().await;
}
both_backends!(two_servers, two_servers_share_sessions);

/// Requests cost no database write: activity stays in memory until the
/// write-through pass, which writes it once, and a token is read from the
/// store only when this server has not seen it.
async fn activity_is_written_through_not_per_request(opts: Options) {
    use gridscada_web::auth::Sessions;
    let h = Harness::new(opts).await;
    // Sessions without their upkeep task, so only this test writes through.
    let sessions = Sessions::new(SessionPolicy::default(), h.state.store.clone());
    let token = sessions
        .create("operator", Role::Operator, None, Default::default())
        .await
        .unwrap();
    let k = SessionKey::of_token(&token);
    let at_login = h.state.store.session(&k).await.unwrap().unwrap().last_seen;
    tokio::time::sleep(Duration::from_millis(20)).await;
    for _ in 0..200 {
        assert!(sessions.user(&token).await.is_some());
    }
    let stored = h.state.store.session(&k).await.unwrap().unwrap();
    assert_eq!(stored.last_seen, at_login, "no write per request");
    sessions.sync().await;
    let stored = h.state.store.session(&k).await.unwrap().unwrap();
    assert!(stored.last_seen > at_login, "written through by the pass");
    // A poll marked as background is not activity: nothing more to write.
    tokio::time::sleep(Duration::from_millis(20)).await;
    assert!(sessions.user_untouched(&token).await.is_some());
    sessions.sync().await;
    let again = h.state.store.session(&k).await.unwrap().unwrap();
    assert_eq!(again.last_seen, stored.last_seen);
    h.cleanup().await;
}
both_backends!(write_through, activity_is_written_through_not_per_request);

/// A redundant pair's failover ticket: issued to a logged-in user on A,
/// claimed once on B (another host, which A's cookie does not reach) for an
/// ordinary session of the same user that ends when A's session would have
/// (never a fresh lifetime); a second claim, a made-up ticket, a session
/// token offered as a ticket and an anonymous request for a ticket are
/// refused; a ticket is never taken as a session cookie; a renewed ticket
/// ends the one before it; a logout on A ends its tickets.
async fn failover_ticket_carries_the_login(opts: Options) {
    let a = Harness::new(opts).await;
    let b = a.another_server().await;
    let peer = "127.0.0.2:40001".parse().unwrap();
    let anonymous = a
        .call(Method::POST, "/api/session/handover", None, Some(json!({})))
        .await;
    assert_eq!(anonymous.status, StatusCode::UNAUTHORIZED);
    let op = a.login("operator", PASSWORD).await;
    let ticket = |previous: Option<String>| {
        let (a, op) = (&a, op.clone());
        async move {
            let r = a
                .call(
                    Method::POST,
                    "/api/session/handover",
                    Some(&op),
                    Some(json!({ "previous": previous })),
                )
                .await;
            assert_eq!(r.status, StatusCode::OK, "{}", r.text());
            r.json()["ticket"].as_str().unwrap().to_string()
        }
    };
    let first = ticket(None).await;
    // Not a session: as a cookie it is anonymous, on either server.
    let as_cookie = format!("{}={first}", gridscada_web::auth::COOKIE);
    assert_eq!(whoami(&a, &as_cookie).await, None);
    let r = send_to(
        &b,
        request(Method::GET, "/api/session", Some(&as_cookie), None),
        peer,
    )
    .await;
    assert_eq!(r.json()["user"], serde_json::Value::Null);
    let second = ticket(Some(first.clone())).await;
    let claim = |t: String| {
        let b = b.clone();
        async move {
            send_to(
                &b,
                request(
                    Method::POST,
                    "/api/session/handover/claim",
                    None,
                    Some(json!({ "ticket": t })),
                ),
                peer,
            )
            .await
        }
    };
    // The renewed ticket ended the first one.
    assert_eq!(claim(first).await.status, StatusCode::UNAUTHORIZED);
    // A live session's token is no ticket.
    let op_token = op.split_once('=').unwrap().1.to_string();
    assert_eq!(claim(op_token).await.status, StatusCode::UNAUTHORIZED);
    assert_eq!(whoami(&a, &op).await.as_deref(), Some("operator"));
    assert_eq!(
        claim("not-a-ticket".into()).await.status,
        StatusCode::UNAUTHORIZED
    );
    let r = claim(second.clone()).await;
    assert_eq!(r.status, StatusCode::NO_CONTENT, "{}", r.text());
    let cookie = r.session_cookie().expect("the claim sets a session cookie");
    assert!(!cookie.contains(&second), "a new token, not the ticket");
    let r = send_to(
        &b,
        request(Method::GET, "/api/session", Some(&cookie), None),
        peer,
    )
    .await;
    assert_eq!(r.json()["user"], "operator");
    assert_eq!(r.json()["role"], "operator");
    // It ends when A's session would have, not 12 hours from the claim.
    let stored = |k: SessionKey| {
        let a = &a;
        async move { a.state.store.session(&k).await.unwrap().expect("stored") }
    };
    let (origin, claimed) = (stored(key(&op)).await, stored(key(&cookie)).await);
    assert!(origin.expires_at.is_some());
    assert_eq!(claimed.expires_at, origin.expires_at);
    assert_eq!(claimed.idle, origin.idle);
    // Good once.
    assert_eq!(claim(second).await.status, StatusCode::UNAUTHORIZED);
    // A's own session goes on.
    assert_eq!(whoami(&a, &op).await.as_deref(), Some("operator"));
    // A ticket of a session that logged out is void.
    let third = ticket(None).await;
    let r = a
        .call(Method::DELETE, "/api/session", Some(&op), None)
        .await;
    assert_eq!(r.status, StatusCode::NO_CONTENT);
    assert_eq!(claim(third).await.status, StatusCode::UNAUTHORIZED);
    a.cleanup().await;
}
both_backends!(failover_ticket, failover_ticket_carries_the_login);
