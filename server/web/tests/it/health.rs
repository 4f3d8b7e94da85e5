//! `/healthz` and `/readyz` when the store stops answering.

use crate::common;

use axum::http::{Method, StatusCode};
use common::*;

#[tokio::test]
async fn a_store_that_does_not_answer_fails_health_and_readiness() {
    let h = Harness::new(Options::default()).await;
    let r = h.call(Method::GET, "/readyz", None, None).await;
    assert_eq!((r.status, r.text().as_str()), (StatusCode::OK, "ready\n"));
    let r = h.call(Method::GET, "/healthz", None, None).await;
    assert_eq!(r.status, StatusCode::OK);
    assert_eq!(r.json()["database"], "ok");

    // The store's pools closed: every query fails, as with a database gone.
    h.state.store.close().await;
    let r = h.call(Method::GET, "/readyz", None, None).await;
    assert_eq!(r.status, StatusCode::SERVICE_UNAVAILABLE);
    // As every refusal of the API: its JSON error.
    assert_eq!(r.json()["error"], "internal");
    let r = h.call(Method::GET, "/healthz", None, None).await;
    assert_eq!(r.status, StatusCode::SERVICE_UNAVAILABLE);
    assert_eq!(r.json()["status"], "failing");
    assert_eq!(r.json()["database"], "unreachable");
}
