//! Findings of the security review, each reproduced: throttling and guards
//! under concurrency, CSRF defence in depth and host names, sessions after a
//! password change, headers and caching on every answer, `/metrics`, live
//! socket caps, and forged audit lines.

mod common;

use std::sync::Arc;

use axum::body::Body;
use axum::http::{header, Method, Request, StatusCode};
use common::*;
use gridscada_config::Role;
use gridscada_web::WebState;
use serde_json::json;
use tower::ServiceExt;

fn login_req(user: &str, pass: &str) -> Request<Body> {
    request(
        Method::POST,
        "/api/session",
        None,
        Some(json!({"username": user, "password": pass})),
    )
}

#[tokio::test]
async fn a_concurrent_burst_cannot_get_past_the_throttle() {
    let h = Arc::new(Harness::new(Options::default()).await);
    let tries: Vec<_> = (0..40)
        .map(|_| {
            let h = h.clone();
            tokio::spawn(async move {
                h.send(login_req("operator", "wrong password!"))
                    .await
                    .status
            })
        })
        .collect();
    let mut judged = 0;
    for t in tries {
        match t.await.unwrap() {
            StatusCode::UNAUTHORIZED => judged += 1,
            StatusCode::TOO_MANY_REQUESTS => {}
            other => panic!("unexpected {other}"),
        }
    }
    // Five free attempts per user and address: no more passwords were checked.
    assert!(judged <= 5, "{judged} passwords checked");
}

#[tokio::test]
async fn two_administrators_blocking_each_other_leave_one() {
    let h = Arc::new(Harness::new(Options::default()).await);
    h.add_user("admin2", Role::Administrator, "administrator")
        .await;
    let a = h.login("administrator", PASSWORD).await;
    let b = h.login("admin2", PASSWORD).await;
    for _ in 0..5 {
        let (ha, hb) = (h.clone(), h.clone());
        let (a2, b2) = (a.clone(), b.clone());
        let x = tokio::spawn(async move {
            ha.call(
                Method::PATCH,
                "/api/users/admin2",
                Some(&a2),
                Some(json!({"blocked": true})),
            )
            .await
            .status
        });
        let y = tokio::spawn(async move {
            hb.call(
                Method::PATCH,
                "/api/users/administrator",
                Some(&b2),
                Some(json!({"blocked": true})),
            )
            .await
            .status
        });
        let (x, y) = (x.await.unwrap(), y.await.unwrap());
        assert!(
            !(x == StatusCode::OK && y == StatusCode::OK),
            "both administrators were blocked"
        );
        let usable = h
            .state
            .store
            .users()
            .await
            .unwrap()
            .into_iter()
            .filter(|u| u.role == Role::Administrator && !u.blocked)
            .count();
        assert!(usable >= 1);
        if x != StatusCode::OK && y != StatusCode::OK {
            continue;
        }
        break;
    }
    // Moving the last usable administrator into a group without the users
    // screen is refused too.
    let users = h.state.store.users().await.unwrap();
    let last = users
        .iter()
        .find(|u| u.role == Role::Administrator && !u.blocked)
        .unwrap()
        .name
        .clone();
    for u in users
        .iter()
        .filter(|u| u.role == Role::Administrator && u.name != last)
    {
        h.state.store.set_user_blocked(&u.name, true).await.unwrap();
    }
    let cookie = h.login(&last, PASSWORD).await;
    let r = h
        .call(
            Method::PUT,
            "/api/groups/visitors/screens",
            Some(&cookie),
            Some(json!({"screens": ["alarms"]})),
        )
        .await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text());
    let r = h
        .call(
            Method::PATCH,
            &format!("/api/users/{last}"),
            Some(&cookie),
            Some(json!({"group": "visitors"})),
        )
        .await;
    assert_eq!(r.status, StatusCode::CONFLICT, "{}", r.text());
}

#[tokio::test]
async fn changes_must_name_their_origin_and_hosts_are_checked() {
    let h = Harness::new(Options::default()).await;
    let admin = h.login("administrator", PASSWORD).await;
    let put = |origin: Option<&str>, referer: Option<&str>| {
        let mut b = Request::builder()
            .method(Method::PUT)
            .uri("/api/groups/visitors/screens")
            .header(header::HOST, HOST)
            .header(header::COOKIE, &admin)
            .header(header::CONTENT_TYPE, "application/json");
        if let Some(o) = origin {
            b = b.header(header::ORIGIN, o);
        }
        if let Some(r) = referer {
            b = b.header(header::REFERER, r);
        }
        b.body(Body::from(json!({"screens": ["events"]}).to_string()))
            .unwrap()
    };
    // Neither Origin nor Referer, with the session cookie: refused.
    let r = h.send(put(None, None)).await;
    assert_eq!(r.status, StatusCode::FORBIDDEN, "{}", r.text());
    assert!(r.text().contains("Origin or Referer"));
    // A foreign Referer: refused; our own: accepted.
    let r = h.send(put(None, Some("http://evil.test/page"))).await;
    assert_eq!(r.status, StatusCode::FORBIDDEN);
    let r = h
        .send(put(None, Some(&format!("http://{HOST}/#/users"))))
        .await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text());
    // A name this server does not answer to (DNS rebinding), even for GET.
    let mut get = request(Method::GET, "/api/tags", Some(&admin), None);
    get.headers_mut()
        .insert(header::HOST, "rebind.evil.test".parse().unwrap());
    let r = h.send(get).await;
    assert_eq!(r.status, StatusCode::MISDIRECTED_REQUEST);
    // The refusal carries the security headers and is not cached.
    assert!(r.headers.contains_key("content-security-policy"));
    assert_eq!(r.headers[header::CACHE_CONTROL], "no-store");
    // IP addresses and localhost are always ours.
    for host in ["127.0.0.1:8080", "[::1]:8080", "localhost:8080", "10.1.2.3"] {
        let mut get = request(Method::GET, "/healthz", None, None);
        get.headers_mut()
            .insert(header::HOST, host.parse().unwrap());
        assert_eq!(h.send(get).await.status, StatusCode::OK, "{host}");
    }
    // Cross-origin refusals carry the headers too.
    let r = h.send(put(Some("http://evil.test"), None)).await;
    assert_eq!(r.status, StatusCode::FORBIDDEN);
    assert!(r.headers.contains_key("content-security-policy"));
    assert!(r.headers.contains_key("x-frame-options"));
    // API data is never cached.
    let r = h.call(Method::GET, "/api/tags", Some(&admin), None).await;
    assert_eq!(r.headers[header::CACHE_CONTROL], "no-store");
}

#[tokio::test]
async fn changing_ones_password_ends_ones_other_sessions() {
    let h = Harness::new(Options::default()).await;
    let here = h.login("operator", PASSWORD).await;
    let there = h.login("operator", PASSWORD).await;
    let r = h
        .call(
            Method::POST,
            "/api/users/operator/password",
            Some(&here),
            Some(json!({"password": "a new long password", "current_password": PASSWORD})),
        )
        .await;
    assert_eq!(r.status, StatusCode::NO_CONTENT, "{}", r.text());
    for (cookie, live) in [(&here, true), (&there, false)] {
        let me = h
            .call(Method::GET, "/api/session", Some(cookie), None)
            .await;
        assert_eq!(me.json()["authenticated"], live);
    }
}

#[tokio::test]
async fn metrics_answer_loopback_or_the_token() {
    let h = Harness::new(Options::default()).await;
    let get = || request(Method::GET, "/metrics", None, None);
    let r = h.send(get()).await;
    assert_eq!(r.status, StatusCode::OK);
    let r = h.send_from(get(), "10.0.0.7:4000".parse().unwrap()).await;
    assert_eq!(r.status, StatusCode::FORBIDDEN);
    // With a token, Prometheus sends it; no token, no figures.
    let mut plant = (*h.state.plant).clone();
    plant.server.metrics_token = Some("s3cret-token".into());
    let app = gridscada_web::router(WebState {
        plant: Arc::new(plant),
        ..h.state.clone()
    });
    let send =
        |req: Request<Body>| {
            let app = app.clone();
            async move {
                let mut req = req;
                req.extensions_mut().insert(axum::extract::ConnectInfo(
                    std::net::SocketAddr::from(([10, 0, 0, 7], 4000)),
                ));
                app.oneshot(req).await.unwrap().status()
            }
        };
    assert_eq!(send(get()).await, StatusCode::UNAUTHORIZED);
    let mut with = get();
    with.headers_mut().insert(
        header::AUTHORIZATION,
        "Bearer s3cret-token".parse().unwrap(),
    );
    assert_eq!(send(with).await, StatusCode::OK);
    let mut wrong = get();
    wrong.headers_mut().insert(
        header::AUTHORIZATION,
        "Bearer s3cret-tokex".parse().unwrap(),
    );
    assert_eq!(send(wrong).await, StatusCode::UNAUTHORIZED);
}

#[tokio::test]
async fn a_forged_login_name_cannot_add_a_line_to_the_log() {
    let h = Harness::new(Options::default()).await;
    let r = h
        .send(login_req(
            "x' from 10.9.9.9: ok\nadministrator logged in",
            "whatever password",
        ))
        .await;
    assert_eq!(r.status, StatusCode::UNAUTHORIZED);
    let admin = h.login("administrator", PASSWORD).await;
    let events = h
        .call(Method::GET, "/api/events?limit=50", Some(&admin), None)
        .await
        .json();
    for e in events["events"].as_array().unwrap() {
        let m = e["message"].as_str().unwrap();
        assert!(!m.contains('\n'), "{m:?}");
    }
}

#[tokio::test]
async fn one_session_cannot_open_hundreds_of_live_sockets() {
    let h = Harness::new(Options::default()).await;
    let addr = h.serve().await;
    let cookie = h.login("operator", PASSWORD).await;
    let mut open = vec![];
    let mut refused = 0;
    for _ in 0..12 {
        match live_socket(addr, &cookie).await {
            Ok(ws) => open.push(ws),
            Err(e) => {
                assert!(e.to_string().contains("429"), "{e}");
                refused += 1;
            }
        }
    }
    assert_eq!(open.len(), gridscada_web::auth::MAX_SOCKETS_PER_SESSION);
    assert_eq!(refused, 12 - gridscada_web::auth::MAX_SOCKETS_PER_SESSION);
    // Closing one frees its place.
    let mut first = open.remove(0);
    first.close(None).await.unwrap();
    drop(first);
    tokio::time::sleep(std::time::Duration::from_millis(200)).await;
    assert!(live_socket(addr, &cookie).await.is_ok());
}

#[tokio::test]
async fn writes_are_audited_with_what_was_asked_and_confirmed_and_refusals_too() {
    let h = Harness::new(Options::default()).await;
    let op = h.login("operator", PASSWORD).await;
    let path = format!("/api/tags/{TAG_SUP}/write");
    // An operator may not write a supervisor's setpoint: refused and logged.
    let r = h
        .call(Method::POST, &path, Some(&op), Some(json!({"value": 5.0})))
        .await;
    assert_eq!(r.status, StatusCode::FORBIDDEN);
    let path_op = format!("/api/tags/{TAG_OP}/write");
    let r = h
        .call(
            Method::POST,
            &path_op,
            Some(&op),
            Some(json!({"value": true})),
        )
        .await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text());
    let admin = h.login("administrator", PASSWORD).await;
    let events = h
        .call(Method::GET, "/api/events?limit=100", Some(&admin), None)
        .await
        .json()
        .to_string();
    assert!(events.contains("write_refused"), "{events}");
    assert!(
        events.contains("may not write T.BESS.Setpoint_kW"),
        "{events}"
    );
    assert!(
        events.contains("requested true, confirmed true"),
        "{events}"
    );
}
