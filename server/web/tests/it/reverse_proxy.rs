//! Behind a reverse proxy: `[server] public_origin` for the Origin check,
//! `trusted_proxies` for the real client (throttling, Secure cookies), and
//! `base_path` for serving under a sub-path. The same, behind a real nginx:
//! `tests/e2e/nginx.sh`.

use crate::common;

use axum::body::Body;
use axum::http::{header, Method, Request, StatusCode};
use axum::Router;
use common::*;
use serde_json::json;
use serde_spanned::Spanned;

const PROXY: &str = "10.0.0.2:40000";

fn proxied(h: &Harness) -> Router {
    h.app_with_plant(|p| {
        p.server.public_origin = Some(Spanned::new(0..0, "https://scada.example.com".into()));
        p.server.trusted_proxies = vec![Spanned::new(0..0, "10.0.0.0/24".into())];
        p.server.base_path = Some(Spanned::new(0..0, "/scada/".into()));
        // The Host the proxy sends.
        p.server.allowed_hosts = vec!["backend.internal".into()];
    })
}

/// A login as the browser at the public origin sends it, through `headers`.
fn login(user: &str, password: &str, headers: &[(&str, &str)]) -> Request<Body> {
    let mut b = Request::builder()
        .method(Method::POST)
        .uri("/scada/api/session")
        .header(header::HOST, "backend.internal:8080")
        .header(header::ORIGIN, "https://scada.example.com")
        .header(header::CONTENT_TYPE, "application/json");
    for (k, v) in headers {
        b = b.header(*k, *v);
    }
    b.body(Body::from(
        json!({"username": user, "password": password}).to_string(),
    ))
    .unwrap()
}

fn get(path: &str, host: &str) -> Request<Body> {
    Request::builder()
        .uri(path)
        .header(header::HOST, host)
        .body(Body::empty())
        .unwrap()
}

#[tokio::test]
async fn everything_is_served_under_the_base_path() {
    let h = Harness::new(Options::default()).await;
    let app = proxied(&h);
    let peer = PROXY.parse().unwrap();
    let r = send_to(&app, get("/scada/healthz", "10.0.0.1"), peer).await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text());
    let r = send_to(&app, get("/scada/", "10.0.0.1"), peer).await;
    assert_eq!(r.status, StatusCode::OK);
    assert!(r.text().contains("js/app.js"), "the HMI page");
    let r = send_to(&app, get("/scada/api/openapi.json", "10.0.0.1"), peer).await;
    assert_eq!(r.json()["servers"], json!([{"url": "/scada/"}]));
    let r = send_to(&app, get("/scada?x=1", "10.0.0.1"), peer).await;
    assert_eq!(r.status, StatusCode::PERMANENT_REDIRECT);
    assert_eq!(r.headers[header::LOCATION], "/scada/?x=1");
    for outside in ["/healthz", "/api/session", "/scadax/healthz", "/"] {
        let r = send_to(&app, get(outside, "10.0.0.1"), peer).await;
        assert_eq!(r.status, StatusCode::NOT_FOUND, "{outside}");
    }
    // The cookie goes to this server's paths only.
    let r = send_to(&app, login("operator", PASSWORD, &[]), peer).await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text());
    let set = r.headers[header::SET_COOKIE].to_str().unwrap();
    assert!(set.contains("; Path=/scada;"), "{set}");
}

#[tokio::test]
async fn the_origin_check_holds_to_the_public_origin() {
    let h = Harness::new(Options::default()).await;
    let app = proxied(&h);
    let peer = PROXY.parse().unwrap();
    // The public origin's host is one of ours; another name is not.
    let r = send_to(&app, get("/scada/healthz", "scada.example.com"), peer).await;
    assert_eq!(r.status, StatusCode::OK);
    let r = send_to(&app, get("/scada/healthz", "evil.example.com"), peer).await;
    assert_eq!(r.status, StatusCode::MISDIRECTED_REQUEST);
    // The public Origin passes whatever Host the proxy sends (10.0.0.1 here) ...
    let mut req = login("operator", "wrong password!", &[]);
    req.headers_mut()
        .insert(header::HOST, "10.0.0.1:8080".parse().unwrap());
    let r = send_to(&app, req, peer).await;
    assert_eq!(r.status, StatusCode::UNAUTHORIZED, "{}", r.text());
    // ... and an Origin that names the Host, or another scheme or port, does not.
    for origin in [
        "http://10.0.0.1:8080",
        "http://scada.example.com",
        "https://scada.example.com:8443",
        "https://scada.example.com.evil.test",
    ] {
        let mut req = login("operator", PASSWORD, &[]);
        req.headers_mut()
            .insert(header::HOST, "10.0.0.1:8080".parse().unwrap());
        req.headers_mut()
            .insert(header::ORIGIN, origin.parse().unwrap());
        let r = send_to(&app, req, peer).await;
        assert_eq!(r.status, StatusCode::FORBIDDEN, "{origin}: {}", r.text());
    }
}

#[tokio::test]
async fn throttling_and_cookies_follow_the_real_client() {
    let h = Harness::new(Options::default()).await;
    let app = proxied(&h);
    let proxy = PROXY.parse().unwrap();
    // Six failures from one client behind the proxy lock that client out ...
    let via = |client: &'static str| [("x-forwarded-for", client)];
    let mut last = None;
    for _ in 0..6 {
        last = Some(
            send_to(
                &app,
                login("operator", "wrong password!", &via("198.51.100.7")),
                proxy,
            )
            .await,
        );
    }
    assert_eq!(last.unwrap().status, StatusCode::TOO_MANY_REQUESTS);
    let r = send_to(
        &app,
        login("operator", PASSWORD, &via("198.51.100.7")),
        proxy,
    )
    .await;
    assert_eq!(r.status, StatusCode::TOO_MANY_REQUESTS);
    // ... not another client of the same proxy, nor one that claims, left
    // of the proxy's own entry, to be someone else.
    let r = send_to(
        &app,
        login("operator", PASSWORD, &via("198.51.100.8")),
        proxy,
    )
    .await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text());
    let r = send_to(
        &app,
        login(
            "operator",
            PASSWORD,
            &[("x-forwarded-for", "198.51.100.9, 198.51.100.7")],
        ),
        proxy,
    )
    .await;
    assert_eq!(
        r.status,
        StatusCode::TOO_MANY_REQUESTS,
        "the nearest untrusted hop counts"
    );

    // From an untrusted peer, the headers are ignored: its own address is
    // throttled whatever it claims.
    let direct = "203.0.113.5:5000".parse().unwrap();
    for i in 0..6 {
        let forged = format!("10.0.0.{}", 10 + i);
        let req = login(
            "supervisor",
            "wrong password!",
            &[
                ("x-forwarded-for", forged.as_str()),
                ("forwarded", "for=10.0.0.99"),
            ],
        );
        send_to(&app, req, direct).await;
    }
    let r = send_to(
        &app,
        login("supervisor", PASSWORD, &via("10.0.0.77")),
        direct,
    )
    .await;
    assert_eq!(r.status, StatusCode::TOO_MANY_REQUESTS, "{}", r.text());

    // HTTPS at the proxy: a Secure cookie; the same claim from anyone else: none.
    let https = [
        ("x-forwarded-for", "2001:db8::5"),
        ("x-forwarded-proto", "https"),
    ];
    let r = send_to(&app, login("administrator", PASSWORD, &https), proxy).await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text());
    let set = r.headers[header::SET_COOKIE].to_str().unwrap();
    assert!(set.ends_with("; Secure"), "{set}");
    let r = send_to(
        &app,
        login("administrator", PASSWORD, &[("x-forwarded-proto", "https")]),
        "203.0.113.6:5000".parse().unwrap(),
    )
    .await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text());
    let set = r.headers[header::SET_COOKIE].to_str().unwrap();
    assert!(!set.contains("Secure"), "{set}");
}

/// Six failed logins from `peer`, each with its own `forged` header; then
/// the right password: throttled (429) or not.
async fn forging(
    app: &Router,
    peer: &str,
    user: &str,
    forged: &dyn Fn(u32) -> Vec<(String, String)>,
) -> StatusCode {
    let peer = peer.parse().unwrap();
    for i in 0..6 {
        let h = forged(i);
        let h: Vec<(&str, &str)> = h.iter().map(|(k, v)| (k.as_str(), v.as_str())).collect();
        send_to(app, login(user, "wrong password!", &h), peer).await;
    }
    let h = forged(99);
    let h: Vec<(&str, &str)> = h.iter().map(|(k, v)| (k.as_str(), v.as_str())).collect();
    send_to(app, login(user, PASSWORD, &h), peer).await.status
}

#[tokio::test]
async fn only_the_configured_forwarding_header_is_believed() {
    let h = Harness::new(Options::default()).await;
    // The default, x-forwarded-for: a proxy that sets it (as nginx does)
    // passes the client's own Forwarded through, and that is never read.
    let app = proxied(&h);
    let nginx = |i: u32| {
        vec![
            ("x-forwarded-for".to_string(), "198.51.100.20".to_string()),
            ("forwarded".to_string(), format!("for=192.0.2.{i}")),
        ]
    };
    assert_eq!(
        forging(&app, PROXY, "operator", &nginx).await,
        StatusCode::TOO_MANY_REQUESTS,
        "a new Forwarded on every try escaped the lockout"
    );
    // Nor does it open /metrics to an address in metrics_allow.
    let metrics_app = h.app_with_plant(|p| {
        p.server.trusted_proxies = vec![Spanned::new(0..0, "10.0.0.0/24".into())];
        p.server.metrics_token = Some("scrape-secret".into());
        p.server.metrics_allow = vec!["192.0.2.50".parse().unwrap()];
    });
    let scrape = |headers: &[(&str, &str)]| {
        let mut b = Request::builder()
            .uri("/metrics")
            .header(header::HOST, "10.0.0.1");
        for (k, v) in headers {
            b = b.header(*k, *v);
        }
        b.body(Body::empty()).unwrap()
    };
    let peer = PROXY.parse().unwrap();
    let r = send_to(
        &metrics_app,
        scrape(&[
            ("x-forwarded-for", "198.51.100.20"),
            ("forwarded", "for=192.0.2.50"),
        ]),
        peer,
    )
    .await;
    assert_eq!(r.status, StatusCode::UNAUTHORIZED, "{}", r.text());
    let r = send_to(
        &metrics_app,
        scrape(&[("x-forwarded-for", "192.0.2.50")]),
        peer,
    )
    .await;
    assert_eq!(r.status, StatusCode::OK, "the proxy's own word is believed");

    // forwarded_header = "forwarded": the other way round.
    let app = h.app_with_plant(|p| {
        p.server.public_origin = Some(Spanned::new(0..0, "https://scada.example.com".into()));
        p.server.trusted_proxies = vec![Spanned::new(0..0, "10.0.0.0/24".into())];
        p.server.forwarded_header = Some(Spanned::new(0..0, "forwarded".into()));
        p.server.base_path = Some(Spanned::new(0..0, "/scada/".into()));
        p.server.allowed_hosts = vec!["backend.internal".into()];
    });
    let rfc_proxy = |i: u32| {
        vec![
            ("forwarded".to_string(), "for=198.51.100.21".to_string()),
            ("x-forwarded-for".to_string(), format!("192.0.2.{i}")),
        ]
    };
    assert_eq!(
        forging(&app, PROXY, "supervisor", &rfc_proxy).await,
        StatusCode::TOO_MANY_REQUESTS,
        "a new X-Forwarded-For on every try escaped the lockout"
    );
    let https = [
        ("forwarded", "for=198.51.100.22;proto=https"),
        ("x-forwarded-proto", "http"),
    ];
    let r = send_to(
        &app,
        login("administrator", PASSWORD, &https),
        PROXY.parse().unwrap(),
    )
    .await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text());
    let set = r.headers[header::SET_COOKIE].to_str().unwrap();
    assert!(
        set.ends_with("; Secure"),
        "proto=https of Forwarded counts: {set}"
    );
    let r = send_to(
        &app,
        login(
            "administrator",
            PASSWORD,
            &[
                ("x-forwarded-for", "198.51.100.23"),
                ("x-forwarded-proto", "https"),
            ],
        ),
        PROXY.parse().unwrap(),
    )
    .await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text());
    let set = r.headers[header::SET_COOKIE].to_str().unwrap();
    assert!(
        !set.contains("Secure"),
        "X-Forwarded-Proto is not read: {set}"
    );
}
