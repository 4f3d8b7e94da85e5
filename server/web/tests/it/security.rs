//! Findings of the security review, each reproduced: throttling and guards
//! under concurrency, CSRF defence in depth and host names, sessions after a
//! password change, headers and caching on every answer, `/metrics`, live
//! socket caps, and forged audit lines.

use crate::common;

use std::sync::Arc;

use axum::body::Body;
use axum::http::{header, Method, Request, StatusCode};
use common::*;
use gridscada_config::Role;
use serde_json::{json, Value};

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
    let app = h.app_with_plant(|p| p.server.metrics_token = Some("s3cret-token".into()));
    let send = |req: Request<Body>| send_to(&app, req, "10.0.0.7:4000".parse().unwrap());
    assert_eq!(send(get()).await.status, StatusCode::UNAUTHORIZED);
    let mut with = get();
    with.headers_mut().insert(
        header::AUTHORIZATION,
        "Bearer s3cret-token".parse().unwrap(),
    );
    assert_eq!(send(with).await.status, StatusCode::OK);
    let mut wrong = get();
    wrong.headers_mut().insert(
        header::AUTHORIZATION,
        "Bearer s3cret-tokex".parse().unwrap(),
    );
    assert_eq!(send(wrong).await.status, StatusCode::UNAUTHORIZED);
}

/// Issue 22 #10: the addresses in `metrics_allow` scrape without the token,
/// with or without one configured; other addresses still need it, and
/// with a token set loopback is no longer let in on its own.
#[tokio::test]
async fn metrics_answer_an_allowed_address_without_the_token() {
    let h = Harness::new(Options::default()).await;
    let get = || request(Method::GET, "/metrics", None, None);
    let allowed: std::net::SocketAddr = "10.0.0.8:4000".parse().unwrap();
    let allowed_v6: std::net::SocketAddr = "[fd00::8]:4000".parse().unwrap();
    let other: std::net::SocketAddr = "10.0.0.7:4000".parse().unwrap();
    let loopback: std::net::SocketAddr = "127.0.0.1:4000".parse().unwrap();
    // Before: the allowed address is refused like any other.
    assert_eq!(
        h.send_from(get(), allowed).await.status,
        StatusCode::FORBIDDEN
    );

    // An allow-list alone.
    let app = h.app_with_plant(|p| {
        p.server.metrics_allow = vec![allowed.ip(), allowed_v6.ip()];
    });
    for peer in [allowed, allowed_v6, loopback] {
        let r = send_to(&app, get(), peer).await;
        assert_eq!(r.status, StatusCode::OK, "{peer}: {}", r.text());
        assert!(r.text().contains("gridscada_uptime_seconds"), "{peer}");
    }
    let r = send_to(&app, get(), other).await;
    assert_eq!(r.status, StatusCode::FORBIDDEN, "{}", r.text());
    assert!(!r.text().contains("gridscada_uptime_seconds"));

    // An allow-list beside a token: the listed address needs no token,
    // the others (loopback too) do.
    let app = h.app_with_plant(|p| {
        p.server.metrics_allow = vec![allowed.ip()];
        p.server.metrics_token = Some("s3cret-token".into());
    });
    let r = send_to(&app, get(), allowed).await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text());
    assert!(r.text().contains("gridscada_uptime_seconds"));
    for peer in [other, loopback] {
        let r = send_to(&app, get(), peer).await;
        assert_eq!(r.status, StatusCode::UNAUTHORIZED, "{peer}: {}", r.text());
    }
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

/// The one alarm whose text matches `key`, in whatever state, as the API shows it.
async fn alarm_view(h: &Harness, cookie: &str, key: &str) -> Value {
    let every_state = "normal,unack_active,ack_active,unack_rtn,shelved,suppressed,out_of_service";
    let q = format!("/api/alarms?state={every_state}&text={key}");
    let r = h.call(Method::GET, &q, Some(cookie), None).await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text());
    let list = r.json()["alarms"].as_array().unwrap().clone();
    assert_eq!(list.len(), 1, "{list:?}");
    list[0].clone()
}

/// Issue 22 #14: a shelve refused for its reason (9,000 characters, the
/// limit is 2,048 bytes) changes nothing and claims nothing: the alarm is
/// not shelved, in the engine or in the store, and neither the event log
/// nor the alarm history says it was.
#[tokio::test]
async fn a_refused_shelve_changes_nothing_and_claims_nothing() {
    let h = Harness::new(Options::default()).await;
    h.run_alarms();
    let engine = h.state.components.alarms.clone().unwrap();
    let key = "test.link_down";
    let id = engine.raise(key, 2, "Plant", "Link down").unwrap();
    let sup = h.login("supervisor", PASSWORD).await;
    let path = format!("/api/alarms/{}/shelve", id.0);

    let r = h
        .call(
            Method::POST,
            &path,
            Some(&sup),
            Some(json!({"minutes": 30, "reason": "x".repeat(9000)})),
        )
        .await;
    assert_eq!(r.status, StatusCode::BAD_REQUEST, "{}", r.text());
    assert!(r.text().contains("at most 2048"), "{}", r.text());

    // The alarm as the API shows it: still unshelved.
    let a = alarm_view(&h, &sup, key).await;
    assert_eq!(a["id"], id.0);
    assert_eq!(a["state"], "unack_active", "{a}");
    assert!(a["shelved"].is_null(), "{a}");
    let shelved = h
        .call(Method::GET, "/api/alarms?state=shelved", Some(&sup), None)
        .await
        .json();
    assert_eq!(shelved["count"], 0, "{shelved}");
    assert!(engine.view(id).unwrap().shelved.is_none());
    assert!(
        h.state
            .store
            .alarm_states()
            .await
            .unwrap()
            .iter()
            .all(|r| r.key != key || r.shelved_until.is_none()),
        "a shelving was persisted"
    );

    // A valid shelve afterwards is the marker: once its records are in,
    // anything the refused one had produced (earlier, in the same ordered
    // stream) would be in too.
    let r = h
        .call(
            Method::POST,
            &path,
            Some(&sup),
            Some(json!({"minutes": 30, "reason": "marker"})),
        )
        .await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text());
    assert_eq!(alarm_view(&h, &sup, key).await["state"], "shelved");
    let admin = h.login("administrator", PASSWORD).await;
    let (hr, admin, sup) = (&h, admin.as_str(), sup.as_str());
    let shelve_events = eventually(
        "the marker shelve's event is logged",
        std::time::Duration::from_secs(5),
        move || async move {
            let h = hr;
            let ev = h
                .call(
                    Method::GET,
                    &format!("/api/events?type=shelve&source={key}"),
                    Some(admin),
                    None,
                )
                .await
                .json();
            let ev: Vec<Value> = ev["events"].as_array().unwrap().clone();
            ev.iter()
                .any(|e| e["message"].as_str().unwrap().contains("(marker)"))
                .then_some(ev)
        },
    )
    .await;
    assert_eq!(shelve_events.len(), 1, "{shelve_events:?}");
    assert_eq!(shelve_events[0]["user"], "supervisor");
    let history = eventually(
        "the marker shelve's transition is stored",
        std::time::Duration::from_secs(5),
        move || async move {
            let h = hr;
            let hist = h
                .call(
                    Method::GET,
                    &format!("/api/alarms/history?key={key}"),
                    Some(sup),
                    None,
                )
                .await
                .json();
            let rows: Vec<Value> = hist["transitions"].as_array().unwrap().clone();
            rows.iter()
                .any(|t| t["to_state"] == "shelved")
                .then_some(rows)
        },
    )
    .await;
    let to_shelved = history
        .iter()
        .filter(|t| t["to_state"] == "shelved")
        .count();
    assert_eq!(to_shelved, 1, "{history:?}");
}

/// Issue 20: a supervisor takes an alarm out of service with a reason and
/// an end; bad input is refused with the field named, an operator is
/// refused, the end is kept in the store, it is audited with the user, and
/// the alarm returns to service by hand (twice is a conflict).
#[tokio::test]
async fn out_of_service_with_a_reason_and_an_end() {
    let h = Harness::new(Options::default()).await;
    h.run_alarms();
    let engine = h.state.components.alarms.clone().unwrap();
    let key = "test.sensor_fault";
    let id = engine.raise(key, 500, "Plant", "Sensor fault").unwrap();
    let sup = h.login("supervisor", PASSWORD).await;
    let op = h.login("operator", PASSWORD).await;
    let path = format!("/api/alarms/{}/out-of-service", id.0);
    let body = json!({"reason": "sensor swap", "hours": 2});

    let r = h
        .call(Method::POST, &path, Some(&op), Some(body.clone()))
        .await;
    assert_eq!(r.status, StatusCode::FORBIDDEN, "{}", r.text());
    for (bad, want) in [
        (
            json!({"reason": "x", "hours": 0}),
            "hours: 0 must be more than 0",
        ),
        (json!({"reason": "x", "hours": 3000}), "at most 2160"),
        (json!({"reason": " ", "hours": 1}), "a reason is required"),
        (json!({"reason": "x"}), "hours"),
    ] {
        let r = h
            .call(Method::POST, &path, Some(&sup), Some(bad.clone()))
            .await;
        assert_eq!(r.status, StatusCode::BAD_REQUEST, "{bad}: {}", r.text());
        assert!(r.text().contains(want), "{bad}: {}", r.text());
    }
    assert_eq!(alarm_view(&h, &sup, key).await["state"], "unack_active");

    let before = h.state.clock.now().as_millis();
    let r = h
        .call(Method::POST, &path, Some(&sup), Some(body.clone()))
        .await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text());
    let until = r.json()["until"].as_i64().unwrap();
    assert!(
        (until - before - 7_200_000).abs() < 60_000,
        "{until} vs {before}"
    );
    let a = alarm_view(&h, &sup, key).await;
    assert_eq!(a["state"], "out_of_service", "{a}");
    assert_eq!(a["out_of_service"]["reason"], "sensor swap", "{a}");
    assert_eq!(a["out_of_service"]["by"], "supervisor", "{a}");
    assert_eq!(a["out_of_service"]["until"], until, "{a}");
    let stored = h.state.store.alarm_states().await.unwrap();
    let rec = stored.iter().find(|r| r.key == key).unwrap();
    assert!(rec.out_of_service);
    assert_eq!(rec.out_of_service_until.map(|t| t.as_millis()), Some(until));
    let r = h.call(Method::POST, &path, Some(&sup), Some(body)).await;
    assert_eq!(r.status, StatusCode::CONFLICT, "{}", r.text());

    let admin = h.login("administrator", PASSWORD).await;
    let (hr, admin) = (&h, admin.as_str());
    let events = eventually(
        "the out-of-service event is logged",
        std::time::Duration::from_secs(5),
        move || async move {
            let ev = hr
                .call(
                    Method::GET,
                    &format!("/api/events?type=out_of_service&source={key}"),
                    Some(admin),
                    None,
                )
                .await
                .json();
            let ev: Vec<Value> = ev["events"].as_array().unwrap().clone();
            (!ev.is_empty()).then_some(ev)
        },
    )
    .await;
    assert_eq!(events[0]["user"], "supervisor");
    assert!(
        events[0]["message"]
            .as_str()
            .unwrap()
            .contains("Out of service until"),
        "{events:?}"
    );

    let r = h.call(Method::DELETE, &path, Some(&op), None).await;
    assert_eq!(r.status, StatusCode::FORBIDDEN, "{}", r.text());
    let r = h.call(Method::DELETE, &path, Some(&sup), None).await;
    assert_eq!(r.status, StatusCode::NO_CONTENT, "{}", r.text());
    assert_eq!(alarm_view(&h, &sup, key).await["state"], "unack_active");
    let r = h.call(Method::DELETE, &path, Some(&sup), None).await;
    assert_eq!(r.status, StatusCode::CONFLICT, "{}", r.text());
}

/// Issue 22 #15: a write outside the tag's engineering limits (-50 to 50 kW
/// in the test plant) answers `out_of_limits`, nothing reaches the device
/// and the value stays, and each refusal is in the event log. A value on
/// the limit passes.
#[tokio::test]
async fn a_write_outside_the_engineering_limits_is_refused_and_audited() {
    let h = Harness::new(Options::default()).await;
    assert_eq!(
        h.state.plant.write_limits(TAG_SUP),
        (Some(-50.0), Some(50.0))
    );
    let sup = h.login("supervisor", PASSWORD).await;
    let path = format!("/api/tags/{TAG_SUP}/write");
    let bad = [-1e6, 1e30, 50.5, -50.25];
    for v in bad {
        let r = h
            .call(Method::POST, &path, Some(&sup), Some(json!({"value": v})))
            .await;
        assert_eq!(r.status, StatusCode::BAD_REQUEST, "{v}: {}", r.text());
        let body = r.json();
        assert_eq!(body["error"], "out_of_limits", "{v}: {body}");
        assert!(
            body["detail"]
                .as_str()
                .unwrap()
                .contains("engineering limits of 'T.BESS.Setpoint_kW'"),
            "{v}: {body}"
        );
    }
    // Nothing reached the device, and the value is the one it had.
    assert!(
        h.writer.writes.lock().is_empty(),
        "{:?}",
        h.writer.writes.lock()
    );
    let tag = h
        .call(
            Method::GET,
            &format!("/api/tags/{TAG_SUP}"),
            Some(&sup),
            None,
        )
        .await
        .json();
    assert_eq!(tag["value"], 1.5, "{tag}");
    // Every refusal is audited as refused (issue 36 #11: the server refused
    // it, the device never saw it), naming the user, the tag and the reason.
    let admin = h.login("administrator", PASSWORD).await;
    let ev = h
        .call(
            Method::GET,
            &format!("/api/events?type=write_refused&source={TAG_SUP}"),
            Some(&admin),
            None,
        )
        .await
        .json();
    let refused = ev["events"].as_array().unwrap();
    assert_eq!(refused.len(), bad.len(), "{ev}");
    for e in refused {
        assert_eq!(e["user"], "supervisor", "{e}");
        let m = e["message"].as_str().unwrap();
        assert!(
            m.starts_with("supervisor may not write T.BESS.Setpoint_kW: "),
            "{m}"
        );
        assert!(m.contains("outside the engineering limits"), "{m}");
    }
    // None of them is counted as a failure of the device.
    let failed = h
        .call(
            Method::GET,
            &format!("/api/events?type=write_failed&source={TAG_SUP}"),
            Some(&admin),
            None,
        )
        .await
        .json();
    assert_eq!(failed["events"].as_array().unwrap().len(), 0, "{failed}");
    // A value of the wrong kind is refused before the device too, and on
    // record the same way.
    let r = h
        .call(
            Method::POST,
            &path,
            Some(&sup),
            Some(json!({"value": "full power"})),
        )
        .await;
    assert_eq!(r.status, StatusCode::BAD_REQUEST, "{}", r.text());
    let ev = h
        .call(
            Method::GET,
            &format!("/api/events?type=write_refused&source={TAG_SUP}"),
            Some(&admin),
            None,
        )
        .await
        .json();
    assert_eq!(
        ev["events"].as_array().unwrap().len(),
        bad.len() + 1,
        "{ev}"
    );
    // On the limit is inside.
    let r = h
        .call(
            Method::POST,
            &path,
            Some(&sup),
            Some(json!({"value": -50.0})),
        )
        .await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text());
    assert_eq!(
        *h.writer.writes.lock(),
        [(TAG_SUP.to_string(), gridscada_tagdb::Value::Float(-50.0))]
    );
}

/// Issue 36 #5: write access follows the areas of read access. An operator
/// whose group's screens show a tag neither reads nor writes it: the write
/// answers 403 naming the area, nothing reaches the device, and the refusal
/// is on record (`write_refused`, with the reason). Once the group's screens
/// show the tag, the same operator writes it.
#[tokio::test]
async fn a_write_outside_the_users_area_is_refused_and_audited() {
    let h = Harness::new(Options::default()).await;
    h.add_user("west", Role::Operator, "west").await;
    h.state
        .store
        .set_group_screens("west", &["alarms".to_string()])
        .await
        .unwrap();
    let west = h.login("west", PASSWORD).await;
    let tag = format!("/api/tags/{TAG_OP}");
    let r = h.call(Method::GET, &tag, Some(&west), None).await;
    assert_eq!(
        r.status,
        StatusCode::FORBIDDEN,
        "not readable: {}",
        r.text()
    );
    let write = format!("{tag}/write");
    let r = h
        .call(
            Method::POST,
            &write,
            Some(&west),
            Some(json!({"value": true})),
        )
        .await;
    assert_eq!(r.status, StatusCode::FORBIDDEN, "{}", r.text());
    let detail = r.json()["detail"].as_str().unwrap_or_default().to_string();
    assert!(detail.contains("area"), "{detail}");
    assert!(
        h.writer.writes.lock().is_empty(),
        "{:?}",
        h.writer.writes.lock()
    );
    let admin = h.login("administrator", PASSWORD).await;
    let refused = |kind: &'static str| {
        let (h, admin) = (&h, &admin);
        async move {
            h.call(
                Method::GET,
                &format!("/api/events?type={kind}&source={TAG_OP}"),
                Some(admin),
                None,
            )
            .await
            .json()["events"]
                .as_array()
                .unwrap()
                .clone()
        }
    };
    let ev = refused("write_refused").await;
    assert_eq!(ev.len(), 1, "{ev:?}");
    assert_eq!(ev[0]["user"], "west");
    let m = ev[0]["message"].as_str().unwrap();
    assert!(
        m.starts_with("west may not write T.Zone1.Reset: ") && m.contains("group 'west'"),
        "{m}"
    );
    assert!(refused("write_request").await.is_empty());

    // The tag on a screen of the group: written.
    h.state
        .store
        .set_group_screens("west", &["alarms".to_string(), "tags".to_string()])
        .await
        .unwrap();
    let r = h
        .call(
            Method::POST,
            &write,
            Some(&west),
            Some(json!({"value": true})),
        )
        .await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text());
    assert_eq!(h.writer.writes.lock().len(), 1);
}

/// Issue 36 #5: `[server.access.GROUP] write` grants a group writes beyond
/// its screens (the test plant grants group `east` `T.Zone1.*`), and only
/// those: the group's supervisor still may not write the battery setpoint,
/// which no screen of theirs shows.
#[tokio::test]
async fn a_configured_write_grant_reaches_beyond_the_groups_screens() {
    let h = Harness::new(Options::default()).await;
    h.add_user("east", Role::Operator, "east").await;
    h.add_user("east-sup", Role::Supervisor, "east").await;
    h.state
        .store
        .set_group_screens("east", &["alarms".to_string()])
        .await
        .unwrap();
    let east = h.login("east", PASSWORD).await;
    let r = h
        .call(
            Method::POST,
            &format!("/api/tags/{TAG_OP}/write"),
            Some(&east),
            Some(json!({"value": true})),
        )
        .await;
    assert_eq!(r.status, StatusCode::OK, "granted: {}", r.text());
    let sup = h.login("east-sup", PASSWORD).await;
    let r = h
        .call(
            Method::POST,
            &format!("/api/tags/{TAG_SUP}/write"),
            Some(&sup),
            Some(json!({"value": 5.0})),
        )
        .await;
    assert_eq!(r.status, StatusCode::FORBIDDEN, "not granted: {}", r.text());
    assert_eq!(
        *h.writer.writes.lock(),
        [(TAG_OP.to_string(), gridscada_tagdb::Value::Bool(true))]
    );
}

/// Issue 22 #12: the address cap. Sessions of one address together open at
/// most `MAX_SOCKETS_PER_ADDRESS` live sockets; the one past it is refused
/// (429) although its own session has room, another address is not held
/// out, and closing one frees a place.
#[tokio::test]
async fn one_address_cannot_open_more_than_its_live_sockets() {
    use gridscada_web::auth::{MAX_SOCKETS_PER_ADDRESS, MAX_SOCKETS_PER_SESSION};
    let started = std::time::Instant::now();
    let h = Harness::new(Options::default()).await;
    let addr = h.serve().await;
    let sessions = MAX_SOCKETS_PER_ADDRESS.div_ceil(MAX_SOCKETS_PER_SESSION) + 1;
    let mut cookies = vec![];
    for _ in 0..sessions {
        cookies.push(h.login("operator", PASSWORD).await);
    }
    // Fill the address, each session up to its own cap.
    let mut open = vec![];
    for i in 0..MAX_SOCKETS_PER_ADDRESS {
        let cookie = &cookies[i / MAX_SOCKETS_PER_SESSION];
        open.push(
            live_socket(addr, cookie)
                .await
                .unwrap_or_else(|e| panic!("socket {i}: {e}")),
        );
    }
    // The next session has room of its own but the address has none.
    let fresh = cookies.last().unwrap();
    let err = live_socket(addr, fresh).await.unwrap_err();
    assert!(err.to_string().contains("429"), "{err}");
    // Another address (of the loopback network) is not held out.
    let other = {
        use tokio_tungstenite::tungstenite::client::IntoClientRequest;
        let sock = tokio::net::TcpSocket::new_v4().unwrap();
        sock.bind("127.0.0.2:0".parse().unwrap()).unwrap();
        let stream = sock.connect(addr).await.unwrap();
        let mut req = format!("ws://{addr}/api/live")
            .into_client_request()
            .unwrap();
        req.headers_mut().insert("cookie", fresh.parse().unwrap());
        req.headers_mut()
            .insert("origin", format!("http://{addr}").parse().unwrap());
        tokio_tungstenite::client_async(req, stream).await
    };
    assert!(other.is_ok(), "{:?}", other.err());
    // Closing one of the address's sockets frees its place.
    let mut first = open.remove(0);
    first.close(None).await.unwrap();
    drop(first);
    eventually(
        "a place freed on the address",
        std::time::Duration::from_secs(5),
        move || async move { live_socket(addr, fresh).await.ok() },
    )
    .await;
    assert!(
        started.elapsed() < std::time::Duration::from_secs(30),
        "{:?}",
        started.elapsed()
    );
}
