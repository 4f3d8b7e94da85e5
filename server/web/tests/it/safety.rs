//! Request safety: cross-site requests, the session life cycle, login
//! throttling, blocked users, cookie attributes, security headers, and error
//! bodies that never leak internals.

use crate::common;

use std::time::Duration;

use axum::body::Body;
use axum::http::{header, Method, Request, StatusCode};
use common::*;
use gridscada_config::Role;
use gridscada_web::auth::SessionPolicy;
use serde_json::json;

#[tokio::test]
async fn a_foreign_origin_is_refused_for_unsafe_methods_and_websockets() {
    let h = Harness::new(Options::default()).await;
    let admin = h.login("administrator", PASSWORD).await;
    let with_origin = |method: Method, path: &str, origin: &str| {
        let mut r = request(
            method,
            path,
            Some(&admin),
            Some(json!({"screens": ["events"]})),
        );
        r.headers_mut()
            .insert(header::ORIGIN, origin.parse().unwrap());
        r
    };
    // Foreign origin: refused before any handler runs.
    let r = h
        .send(with_origin(
            Method::PUT,
            "/api/groups/visitors/screens",
            "http://evil.test",
        ))
        .await;
    assert_eq!(r.status, StatusCode::FORBIDDEN, "{}", r.text());
    assert_eq!(r.json()["error"], "forbidden");
    assert!(h
        .state
        .store
        .group_screens("visitors")
        .await
        .unwrap()
        .is_empty());
    // A look-alike host is foreign too.
    let r = h
        .send(with_origin(
            Method::PUT,
            "/api/groups/visitors/screens",
            &format!("http://{HOST}.evil.test"),
        ))
        .await;
    assert_eq!(r.status, StatusCode::FORBIDDEN);
    // Same origin: allowed.
    let r = h
        .send(with_origin(
            Method::PUT,
            "/api/groups/visitors/screens",
            &format!("http://{HOST}"),
        ))
        .await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text());
    // A safe method with a foreign origin is fine (reading gives nothing away
    // that the same-origin policy does not already protect).
    let mut get = request(Method::GET, "/api/tags", Some(&admin), None);
    get.headers_mut()
        .insert(header::ORIGIN, "http://evil.test".parse().unwrap());
    assert_eq!(h.send(get).await.status, StatusCode::OK);

    // A WebSocket upgrade from a foreign page.
    let ws = |origin: &str| {
        Request::builder()
            .method(Method::GET)
            .uri("/api/live")
            .header(header::HOST, HOST)
            .header(header::COOKIE, &admin)
            .header(header::ORIGIN, origin)
            .header(header::CONNECTION, "upgrade")
            .header(header::UPGRADE, "websocket")
            .header(header::SEC_WEBSOCKET_VERSION, "13")
            .header(header::SEC_WEBSOCKET_KEY, "dGhlIHNhbXBsZSBub25jZQ==")
            .body(Body::empty())
            .unwrap()
    };
    let r = h.send(ws("http://evil.test")).await;
    assert_eq!(r.status, StatusCode::FORBIDDEN, "{}", r.text());
    let r = h.send(ws(&format!("http://{HOST}"))).await;
    assert_ne!(r.status, StatusCode::FORBIDDEN, "{}", r.text());
}

#[tokio::test]
async fn login_rotates_and_logout_kills_the_session() {
    let h = Harness::new(Options::default()).await;
    let first = h.login("operator", PASSWORD).await;
    assert_eq!(
        h.call(Method::GET, "/api/tags", Some(&first), None)
            .await
            .status,
        StatusCode::OK
    );
    // Logging in again with the old cookie rotates it.
    let r = h
        .call(
            Method::POST,
            "/api/session",
            Some(&first),
            Some(json!({"username": "operator", "password": PASSWORD})),
        )
        .await;
    assert_eq!(r.status, StatusCode::OK);
    let second = r.session_cookie().unwrap();
    assert_ne!(first, second);
    assert_eq!(
        h.call(Method::GET, "/api/tags", Some(&first), None)
            .await
            .status,
        StatusCode::UNAUTHORIZED,
        "the old token dies at login"
    );
    let me = h
        .call(Method::GET, "/api/session", Some(&second), None)
        .await
        .json();
    assert_eq!(me["authenticated"], true);
    assert_eq!(me["user"], "operator");

    // Logout: 204, the cookie is cleared, the token is dead.
    let r = h
        .call(Method::DELETE, "/api/session", Some(&second), None)
        .await;
    assert_eq!(r.status, StatusCode::NO_CONTENT);
    let set = r.headers[header::SET_COOKIE].to_str().unwrap();
    assert!(set.starts_with("gridscada_session=;"), "{set}");
    assert!(set.contains("Max-Age=0"), "{set}");
    assert_eq!(
        h.call(Method::GET, "/api/tags", Some(&second), None)
            .await
            .status,
        StatusCode::UNAUTHORIZED
    );
    let me = h
        .call(Method::GET, "/api/session", Some(&second), None)
        .await
        .json();
    assert_eq!(me["authenticated"], false);
}

/// A harness whose sessions idle out after `idle_ms` (absolute: 60 s).
async fn short_idle_harness(idle_ms: u64) -> Harness {
    Harness::new(Options {
        policy: SessionPolicy {
            idle: Duration::from_millis(idle_ms),
            absolute: Duration::from_secs(60),
            ..Default::default()
        },
        ..Default::default()
    })
    .await
}

#[tokio::test]
async fn an_idle_session_expires() {
    let h = short_idle_harness(150).await;
    let c = h.login("guest", PASSWORD).await;
    assert_eq!(
        h.call(Method::GET, "/api/tags", Some(&c), None)
            .await
            .status,
        StatusCode::OK
    );
    tokio::time::sleep(Duration::from_millis(400)).await;
    assert_eq!(
        h.call(Method::GET, "/api/tags", Some(&c), None)
            .await
            .status,
        StatusCode::UNAUTHORIZED
    );
}

/// A wall display stays logged in however long it idles, and commands
/// nothing; the session says when each group idles out, for the HMI's
/// warning.
#[tokio::test]
async fn a_display_session_never_idles_out_and_commands_nothing() {
    let h = short_idle_harness(150).await;
    let display = h.login("display", PASSWORD).await;
    let guest = h.login("guest", PASSWORD).await;
    let session = |c: String| {
        let h = &h;
        async move {
            h.call(Method::GET, "/api/session", Some(&c), None)
                .await
                .json()
        }
    };
    let d = session(display.clone()).await;
    assert_eq!(
        (d["role"].as_str(), d["idle_timeout_s"].is_null()),
        (Some("display"), true),
        "{d}"
    );
    let g = session(guest.clone()).await;
    assert_eq!(g["idle_timeout_s"], 0, "150 ms rounds down to 0 s: {g}");
    assert_eq!(g["warn_s"], 60);
    tokio::time::sleep(Duration::from_millis(400)).await;
    let get = |c: String| {
        let h = &h;
        async move {
            h.call(Method::GET, "/api/tags", Some(&c), None)
                .await
                .status
        }
    };
    assert_eq!(
        get(display.clone()).await,
        StatusCode::OK,
        "the display is still logged in"
    );
    assert_eq!(
        get(guest).await,
        StatusCode::UNAUTHORIZED,
        "the guest idled out"
    );
    for (path, body) in [
        (
            "/api/tags/T.Zone1.Reset/write",
            serde_json::json!({"value": true}),
        ),
        ("/api/alarms/ack", serde_json::json!({"ids": []})),
    ] {
        let r = h.call(Method::POST, path, Some(&display), Some(body)).await;
        assert_eq!(r.status, StatusCode::FORBIDDEN, "{path}: {}", r.text());
    }
    assert!(
        h.writer.writes.lock().is_empty(),
        "nothing reached the field"
    );
}

/// A poll the HMI makes while its screen is hidden says so, and does not
/// keep the session alive; the same request without the mark does.
#[tokio::test]
async fn background_polls_do_not_keep_a_session_alive() {
    let h = short_idle_harness(300).await;
    let poll = |c: String, background: bool| {
        let h = &h;
        async move {
            let mut req = axum::http::Request::builder()
                .method(Method::GET)
                .uri("/api/panels")
                .header(header::HOST, "127.0.0.1")
                .header(header::COOKIE, c);
            if background {
                req = req.header("x-gridscada-background", "1");
            }
            h.send(req.body(axum::body::Body::empty()).unwrap())
                .await
                .status
        }
    };
    let watched = h.login("operator", PASSWORD).await;
    let hidden = h.login("supervisor", PASSWORD).await;
    for _ in 0..6 {
        tokio::time::sleep(Duration::from_millis(100)).await;
        assert_eq!(poll(watched.clone(), false).await, StatusCode::OK);
        let _ = poll(hidden.clone(), true).await;
    }
    // 600 ms of polls: the hidden screen's session idled out after 300 ms.
    assert_eq!(poll(watched, false).await, StatusCode::OK);
    assert_eq!(poll(hidden, false).await, StatusCode::UNAUTHORIZED);
}

#[tokio::test]
async fn cookie_attributes_are_strict() {
    let h = Harness::new(Options::default()).await;
    let r = h
        .call(
            Method::POST,
            "/api/session",
            None,
            Some(json!({"username": "guest", "password": PASSWORD})),
        )
        .await;
    let set = r.headers[header::SET_COOKIE].to_str().unwrap();
    let attrs: Vec<&str> = set.split(';').map(str::trim).collect();
    assert!(attrs.contains(&"HttpOnly"), "{set}");
    assert!(attrs.contains(&"SameSite=Strict"), "{set}");
    assert!(attrs.contains(&"Path=/"), "{set}");
    let token = attrs[0].strip_prefix("gridscada_session=").unwrap();
    assert_eq!(token.len(), 64, "256-bit token in hex");
    // The body never carries the token.
    assert!(!r.text().contains(token));
}

/// Throttling per user and address, per address, and per user name from
/// everywhere (docs/ACCESS.md); a failure never says which part was wrong.
#[tokio::test]
async fn login_failures_are_throttled_and_uninformative() {
    let h = Harness::new(Options::default()).await;
    let login = |user: &str, pass: &str, ip: &str| {
        let req = request(
            Method::POST,
            "/api/session",
            None,
            Some(json!({"username": user, "password": pass})),
        );
        h.send_from(req, format!("{ip}:5000").parse().unwrap())
    };

    // Unknown user and wrong password answer the same, byte for byte.
    let unknown = login("nobody-here", "wrong password!", "10.0.0.1").await;
    let wrong = login("supervisor", "wrong password!", "10.0.0.2").await;
    assert_eq!(unknown.status, StatusCode::UNAUTHORIZED);
    assert_eq!(unknown.status, wrong.status);
    assert_eq!(unknown.body, wrong.body);
    assert_eq!(unknown.content_type(), wrong.content_type());

    // Per user and address: five failures from one address lock that
    // address out of that name...
    let mut last = None;
    for _ in 0..6 {
        last = Some(login("operator", "wrong password!", "10.1.0.1").await);
    }
    assert_eq!(last.unwrap().status, StatusCode::TOO_MANY_REQUESTS);
    let r = login("operator", PASSWORD, "10.1.0.1").await;
    assert_eq!(r.status, StatusCode::TOO_MANY_REQUESTS, "{}", r.text());
    assert_eq!(r.json()["error"], "throttled");
    // ...but the real operator at their own address is not held out.
    let r = login("operator", PASSWORD, "10.9.9.9").await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text());

    // Per user from everywhere: the global ceiling locks the name.
    for i in 0..60 {
        login(
            "supervisor",
            "wrong password!",
            &format!("10.3.{}.{}", i / 200, i % 200),
        )
        .await;
    }
    let r = login("supervisor", PASSWORD, "10.8.8.8").await;
    assert_eq!(r.status, StatusCode::TOO_MANY_REQUESTS);

    // Per address: many names from one address lock the address, and the
    // attacker's own good login in between does not clear it.
    let mut last = None;
    for i in 0..25 {
        last = Some(login(&format!("made-up-{i}"), "wrong password!", "10.2.0.1").await);
        if i % 4 == 3 {
            login("guest", PASSWORD, "10.2.0.1").await;
        }
    }
    assert_eq!(last.unwrap().status, StatusCode::TOO_MANY_REQUESTS);
    let r = login("guest", PASSWORD, "10.2.0.1").await;
    assert_eq!(r.status, StatusCode::TOO_MANY_REQUESTS);
    // Another address and another user are unaffected.
    let r = login("guest", PASSWORD, "10.3.0.1").await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text());

    // Failed logins are in the event log, naming the reason for the auditor.
    let admin = h.login("administrator", PASSWORD).await;
    let ev = h
        .call(
            Method::GET,
            "/api/events?type=login_failed&limit=100",
            Some(&admin),
            None,
        )
        .await
        .json();
    let messages: Vec<String> = ev["events"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e["message"].as_str().unwrap().to_string())
        .collect();
    assert!(
        messages.iter().any(|m| m.contains("unknown user")),
        "{messages:?}"
    );
    assert!(
        messages.iter().any(|m| m.contains("wrong password")),
        "{messages:?}"
    );
}

#[tokio::test]
async fn a_blocked_user_is_out_at_once() {
    let h = Harness::new(Options::default()).await;
    let admin = h.login("administrator", PASSWORD).await;
    let op = h.login("operator", PASSWORD).await;
    assert_eq!(
        h.call(Method::GET, "/api/tags", Some(&op), None)
            .await
            .status,
        StatusCode::OK
    );
    let r = h
        .call(
            Method::PATCH,
            "/api/users/operator",
            Some(&admin),
            Some(json!({"blocked": true})),
        )
        .await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text());
    assert_eq!(r.json()["user"]["blocked"], true);
    // The existing session no longer works.
    assert_eq!(
        h.call(Method::GET, "/api/tags", Some(&op), None)
            .await
            .status,
        StatusCode::UNAUTHORIZED
    );
    // Logging in is refused with the usual uninformative answer.
    let r = h
        .call(
            Method::POST,
            "/api/session",
            None,
            Some(json!({"username": "operator", "password": PASSWORD})),
        )
        .await;
    assert_eq!(r.status, StatusCode::UNAUTHORIZED);
    assert_eq!(r.json()["error"], "invalid_credentials");

    // Blocked directly in the store (e.g. by another server process): the
    // next request of a live session notices.
    let sup = h.login("supervisor", PASSWORD).await;
    h.state
        .store
        .set_user_blocked("supervisor", true)
        .await
        .unwrap();
    assert_eq!(
        h.call(Method::GET, "/api/tags", Some(&sup), None)
            .await
            .status,
        StatusCode::UNAUTHORIZED
    );
    // The last administrator cannot be blocked.
    let r = h
        .call(
            Method::PATCH,
            "/api/users/administrator",
            Some(&admin),
            Some(json!({"blocked": true})),
        )
        .await;
    assert_eq!(r.status, StatusCode::CONFLICT, "{}", r.text());
}

fn assert_security_headers(r: &Resp, what: &str) {
    let get = |k: &str| {
        r.headers
            .get(k)
            .and_then(|v| v.to_str().ok())
            .unwrap_or_else(|| panic!("{what}: no {k} header"))
            .to_string()
    };
    let csp = get("content-security-policy");
    assert!(!csp.contains("unsafe-inline"), "{what}: {csp}");
    assert!(!csp.contains("unsafe-eval"), "{what}: {csp}");
    assert!(csp.contains("frame-ancestors 'none'"), "{what}: {csp}");
    assert!(csp.contains("default-src 'self'"), "{what}: {csp}");
    assert_eq!(get("x-content-type-options"), "nosniff", "{what}");
    assert_eq!(get("referrer-policy"), "same-origin", "{what}");
    assert_eq!(get("x-frame-options"), "DENY", "{what}");
}

#[tokio::test]
async fn every_response_carries_the_security_headers() {
    let h = Harness::new(Options::default()).await;
    let admin = h.login("administrator", PASSWORD).await;
    let cases: Vec<(Method, &str, Option<&str>)> = vec![
        (Method::GET, "/", None),
        (Method::GET, "/healthz", None),
        (Method::GET, "/metrics", None),
        (Method::GET, "/api/openapi.json", None),
        (Method::GET, "/api/tags", None),
        (Method::GET, "/api/tags", Some(&admin)),
        (Method::GET, "/api/users", Some(&admin)),
        (Method::GET, "/api/no-such-route", Some(&admin)),
        (Method::GET, "/no-such-page.html", None),
        (Method::PUT, "/api/tags", Some(&admin)),
        (Method::POST, "/api/session", None),
    ];
    for (method, path, cookie) in cases {
        let r = h.call(method.clone(), path, cookie, None).await;
        assert_security_headers(&r, &format!("{method} {path} ({})", r.status));
    }
}

/// Internals that must never reach a client.
fn assert_clean_error(r: &Resp, what: &str) {
    assert!(
        r.status.is_client_error() || r.status.is_server_error(),
        "{what}: expected an error, got {} {}",
        r.status,
        r.text()
    );
    assert!(
        r.content_type().starts_with("application/json"),
        "{what}: error body is not JSON ({}): {}",
        r.content_type(),
        r.text()
    );
    let j = r.json();
    let obj = j.as_object().unwrap_or_else(|| panic!("{what}: {j}"));
    assert!(
        obj["error"].is_string() && obj["detail"].is_string(),
        "{what}: {j}"
    );
    assert_eq!(obj.len(), 2, "{what}: only error and detail: {j}");
    let text = r.text();
    let lower = text.to_lowercase();
    for bad in [
        "select ",
        "sqlx",
        "sqlite",
        "panicked",
        "/src/",
        ".rs:",
        "/work/",
        "/root/",
        "/home/",
        "root:x:0",
        "[workspace]",
        "stack backtrace",
    ] {
        assert!(!lower.contains(bad), "{what}: body leaks '{bad}': {text}");
    }
}

#[tokio::test]
async fn error_bodies_are_json_and_leak_nothing() {
    let h = Harness::new(Options::default()).await;
    let admin = h.login("administrator", PASSWORD).await;
    let raw = |method: Method, path: &str, ctype: Option<&str>, body: Vec<u8>| {
        let mut b = Request::builder()
            .method(method)
            .uri(path)
            .header(header::HOST, HOST)
            .header(header::ORIGIN, format!("http://{HOST}"))
            .header(header::COOKIE, &admin);
        if let Some(c) = ctype {
            b = b.header(header::CONTENT_TYPE, c);
        }
        b.body(Body::from(body)).unwrap()
    };
    let json_ct = Some("application/json");
    let cases: Vec<(&str, Request<Body>)> = vec![
        (
            "malformed JSON",
            raw(Method::POST, "/api/users", json_ct, b"{\"name\": ".to_vec()),
        ),
        (
            "not an object",
            raw(Method::POST, "/api/users", json_ct, b"[1,2,3]".to_vec()),
        ),
        (
            "wrong type",
            raw(
                Method::POST,
                "/api/users",
                json_ct,
                br#"{"name": 5, "role": "guest"}"#.to_vec(),
            ),
        ),
        (
            "unknown role",
            raw(
                Method::POST,
                "/api/users",
                json_ct,
                br#"{"name": "x", "role": "root"}"#.to_vec(),
            ),
        ),
        (
            "unknown field",
            raw(
                Method::POST,
                "/api/users",
                json_ct,
                br#"{"name": "x", "role": "guest", "admin": true}"#.to_vec(),
            ),
        ),
        (
            "no content type",
            raw(
                Method::POST,
                "/api/users",
                None,
                br#"{"name": "x", "role": "guest"}"#.to_vec(),
            ),
        ),
        (
            "wrong content type",
            raw(
                Method::POST,
                "/api/users",
                Some("text/plain"),
                br#"{"name": "x", "role": "guest"}"#.to_vec(),
            ),
        ),
        (
            "huge body",
            raw(Method::POST, "/api/users", json_ct, {
                let mut v = b"{\"name\": \"".to_vec();
                v.extend(std::iter::repeat_n(b'a', 3 << 20));
                v.extend(b"\", \"role\": \"guest\"}");
                v
            }),
        ),
        (
            "deeply nested",
            raw(Method::POST, "/api/alarms/ack", json_ct, {
                let mut v = b"{\"filter\": ".to_vec();
                v.extend(std::iter::repeat_n(b'[', 10_000));
                v
            }),
        ),
        (
            "non-UTF-8",
            raw(
                Method::POST,
                "/api/session",
                json_ct,
                vec![b'{', 0xff, 0xfe, b'}'],
            ),
        ),
        (
            "bad alarm id",
            raw(
                Method::POST,
                "/api/alarms/abc/shelve",
                json_ct,
                br#"{"minutes": 1, "reason": "x"}"#.to_vec(),
            ),
        ),
        (
            "negative alarm id",
            raw(Method::DELETE, "/api/alarms/-1/shelve", None, vec![]),
        ),
        (
            "overflowing alarm id",
            raw(
                Method::DELETE,
                "/api/alarms/99999999999999999999/shelve",
                None,
                vec![],
            ),
        ),
        (
            "bad zone",
            raw(Method::DELETE, "/api/sim/faults/ss1/300", None, vec![]),
        ),
        (
            "missing query",
            raw(Method::GET, "/api/trends", None, vec![]),
        ),
        (
            "bad query number",
            raw(Method::GET, "/api/events?limit=lots", None, vec![]),
        ),
        (
            "bad query time",
            raw(Method::GET, "/api/events?from=yesterday", None, vec![]),
        ),
        (
            "unknown query field",
            raw(Method::GET, "/api/alarms/history?evil=1", None, vec![]),
        ),
        (
            "bad csv range",
            raw(
                Method::GET,
                "/api/trends.csv?tags=T.Feeder1.P_kW&from=10&to=1",
                None,
                vec![],
            ),
        ),
        (
            "unknown tag",
            raw(Method::GET, "/api/tags/No.Such.Tag", None, vec![]),
        ),
        (
            "unknown user",
            raw(Method::PATCH, "/api/users/ghost", json_ct, b"{}".to_vec()),
        ),
        ("wrong method", raw(Method::PUT, "/api/tags", None, vec![])),
        (
            "unknown API route",
            raw(Method::GET, "/api/../../etc/passwd", None, vec![]),
        ),
        (
            "traversal",
            raw(Method::GET, "/../../etc/passwd", None, vec![]),
        ),
        (
            "encoded traversal",
            raw(Method::GET, "/%2e%2e/%2e%2e/etc/passwd", None, vec![]),
        ),
        (
            "encoded slash traversal",
            raw(Method::GET, "/..%2f..%2fetc%2fpasswd", None, vec![]),
        ),
        (
            "backslash traversal",
            raw(Method::GET, "/..%5c..%5cCargo.toml", None, vec![]),
        ),
        (
            "traversal to source",
            raw(Method::GET, "/../server/web/src/lib.rs", None, vec![]),
        ),
        (
            "traversal in a tag name",
            raw(
                Method::GET,
                "/api/tags/..%2f..%2fetc%2fpasswd",
                None,
                vec![],
            ),
        ),
        (
            "NUL in a path",
            raw(Method::GET, "/api/tags/a%00b", None, vec![]),
        ),
        (
            "unbounded metrics range",
            raw(
                Method::GET,
                "/api/alarms/metrics?from=-7307505257910",
                None,
                vec![],
            ),
        ),
        (
            "reversed metrics range",
            raw(
                Method::GET,
                "/api/alarms/metrics?from=10&to=1",
                None,
                vec![],
            ),
        ),
        (
            "write to a read-only tag",
            raw(
                Method::POST,
                "/api/tags/T.Feeder1.P_kW/write",
                json_ct,
                br#"{"value": 1}"#.to_vec(),
            ),
        ),
        (
            "NaN-like value",
            raw(
                Method::POST,
                "/api/tags/T.BESS.Setpoint_kW/write",
                json_ct,
                br#"{"value": "NaN"}"#.to_vec(),
            ),
        ),
    ];
    for (what, req) in cases {
        let r = h.send(req).await;
        assert_clean_error(&r, what);
        assert!(
            !r.status.is_server_error(),
            "{what}: {} {}",
            r.status,
            r.text()
        );
    }
    // The earliest representable time is a (silly but) valid, empty range.
    let r = h
        .send(raw(
            Method::GET,
            "/api/alarms/metrics?to=-9223372036854775808",
            None,
            vec![],
        ))
        .await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text());
    assert_eq!(r.json()["per_interval"], json!([]));
    let r = h
        .send(raw(
            Method::GET,
            "/api/dispatch/history?to=-9223372036854775808",
            None,
            vec![],
        ))
        .await;
    // The test plant has no microgrid: its routes are absent, cleanly.
    assert_eq!(r.status, StatusCode::NOT_FOUND, "{}", r.text());
    assert_eq!(r.json()["detail"], "this plant has no microgrid screen");
    // The server is still fine afterwards.
    let r = h.call(Method::GET, "/healthz", None, None).await;
    assert_eq!(r.status, StatusCode::OK);
    assert_eq!(r.json()["status"], "ok");
    let _ = Role::Guest;
}
