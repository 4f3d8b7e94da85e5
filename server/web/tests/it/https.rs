//! With TLS on (`WebState::tls`, `Auth::secure_cookies`): HSTS on every
//! answer, refusals included, with the configured max-age or none at 0, and
//! the session cookie `Secure`. Without TLS neither.

use crate::common;

use axum::http::{header, Method, StatusCode};
use common::*;
use gridscada_web::WebState;
use serde_json::json;

/// The harness's app as served over HTTPS with `hsts_max_age_s`.
fn https_app(h: &Harness, hsts_max_age_s: u64) -> axum::Router {
    let mut plant = (*h.state.plant).clone();
    plant.tls = Some(gridscada_config::TlsFiles {
        cert: "cert.pem".into(),
        key: "key.pem".into(),
        redirect_http: None,
        hsts_max_age_s,
    });
    let mut auth = h.state.auth.clone();
    auth.secure_cookies = true;
    gridscada_web::router(WebState {
        plant: std::sync::Arc::new(plant),
        auth,
        tls: true,
        live: Default::default(),
        ..h.state.clone()
    })
}

#[tokio::test]
async fn over_tls_answers_carry_hsts_and_the_cookie_is_secure() {
    let h = Harness::new(Options::default()).await;
    let app = https_app(&h, 600);
    let peer = "127.0.0.1:40000".parse().unwrap();
    let login = request(
        Method::POST,
        "/api/session",
        None,
        Some(json!({"username": "operator", "password": PASSWORD})),
    );
    let r = send_to(&app, login, peer).await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text());
    assert_eq!(r.headers[header::STRICT_TRANSPORT_SECURITY], "max-age=600");
    let cookie = r.headers[header::SET_COOKIE].to_str().unwrap();
    assert!(cookie.contains("; Secure"), "{cookie}");
    // A refusal and a static file carry it too.
    let r = send_to(&app, request(Method::GET, "/api/users", None, None), peer).await;
    assert_eq!(r.status, StatusCode::UNAUTHORIZED);
    assert_eq!(r.headers[header::STRICT_TRANSPORT_SECURITY], "max-age=600");
    let r = send_to(&app, request(Method::GET, "/", None, None), peer).await;
    assert!(r.headers.contains_key(header::STRICT_TRANSPORT_SECURITY));

    // hsts_max_age_s = 0: no header.
    let r = send_to(
        &https_app(&h, 0),
        request(Method::GET, "/healthz", None, None),
        peer,
    )
    .await;
    assert!(!r.headers.contains_key(header::STRICT_TRANSPORT_SECURITY));

    // Plain HTTP: neither.
    let r = h
        .call(
            Method::POST,
            "/api/session",
            None,
            Some(json!({"username": "operator", "password": PASSWORD})),
        )
        .await;
    assert!(!r.headers.contains_key(header::STRICT_TRANSPORT_SECURITY));
    let cookie = r.headers[header::SET_COOKIE].to_str().unwrap();
    assert!(!cookie.contains("Secure"), "{cookie}");
}
