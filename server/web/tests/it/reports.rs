//! `/api/reports`: Supervisors and up list, make and open the reports in the
//! data folder; bad periods and formats are refused; the report page keeps
//! its own content security policy (no script, its inline stylesheet).

use crate::common;

use axum::http::{header, Method, StatusCode};
use common::*;
use gridscada_tagdb::Timestamp;
use serde_json::json;

#[tokio::test]
async fn supervisors_make_list_and_open_reports() {
    let h = Harness::new(Options::default()).await;
    let data = tempfile::tempdir().unwrap();
    let dir = data.path().to_path_buf();
    let app = h.app_with_plant(|p| p.data_dir = dir);
    let peer = "127.0.0.1:40000".parse().unwrap();
    let call = |method: Method, path: &str, cookie: &str, body: Option<serde_json::Value>| {
        send_to(&app, request(method, path, Some(cookie), body), peer)
    };
    let operator = h.login("operator", PASSWORD).await;
    let supervisor = h.login("supervisor", PASSWORD).await;

    let r = call(Method::GET, "/api/reports", &operator, None).await;
    assert_eq!(r.status, StatusCode::FORBIDDEN, "{}", r.text());
    let r = call(Method::GET, "/api/reports", &supervisor, None).await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text());
    assert_eq!(r.json()["reports"], json!([]));

    for bad in ["../../etc/passwd", "2024-13-01", "2999-01-01", "yesterday"] {
        let r = call(
            Method::POST,
            "/api/reports",
            &supervisor,
            Some(json!({"period": bad})),
        )
        .await;
        assert_eq!(r.status, StatusCode::BAD_REQUEST, "{bad}: {}", r.text());
        assert!(r.json()["detail"].as_str().is_some());
    }

    let yesterday = gridscada_reports::Period::day_of(Timestamp::now_utc()).previous();
    let id = yesterday.to_string();
    let r = call(
        Method::POST,
        "/api/reports",
        &supervisor,
        Some(json!({"period": id})),
    )
    .await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text());
    assert_eq!(r.json()["id"], json!(id));
    assert_eq!(r.json()["formats"], json!(["html", "csv", "json"]));
    assert!(data
        .path()
        .join("reports")
        .join(format!("{id}.html"))
        .is_file());

    let r = call(Method::GET, "/api/reports", &supervisor, None).await;
    assert_eq!(r.json()["reports"][0]["id"], json!(id));
    assert_eq!(r.json()["reports"][0]["kind"], json!("day"));

    let page = call(
        Method::GET,
        &format!("/api/reports/{id}/html"),
        &supervisor,
        None,
    )
    .await;
    assert_eq!(page.status, StatusCode::OK);
    assert!(page.content_type().starts_with("text/html"));
    assert!(page.text().contains(&format!("Daily report {id}")));
    let csp = page.headers[header::CONTENT_SECURITY_POLICY]
        .to_str()
        .unwrap();
    assert!(csp.starts_with("default-src 'none'"), "{csp}");
    assert!(!csp.contains("script-src"), "{csp}");

    let csv = call(
        Method::GET,
        &format!("/api/reports/{id}/csv?download=1"),
        &supervisor,
        None,
    )
    .await;
    assert_eq!(csv.status, StatusCode::OK);
    assert!(csv
        .text()
        .starts_with("section,subject,figure,value,unit\n"));
    let disp = csv.headers[header::CONTENT_DISPOSITION].to_str().unwrap();
    assert_eq!(disp, format!("attachment; filename=\"report-{id}.csv\""));

    let r = call(
        Method::GET,
        "/api/reports/2001-01-01/html",
        &supervisor,
        None,
    )
    .await;
    assert_eq!(r.status, StatusCode::NOT_FOUND);
    let r = call(
        Method::GET,
        &format!("/api/reports/{id}/exe"),
        &supervisor,
        None,
    )
    .await;
    assert_eq!(r.status, StatusCode::BAD_REQUEST);
    let r = call(
        Method::GET,
        &format!("/api/reports/{id}/html"),
        &operator,
        None,
    )
    .await;
    assert_eq!(r.status, StatusCode::FORBIDDEN);
}
