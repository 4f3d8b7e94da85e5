//! `/api/live` over a real socket: hello, subscription snapshot, pushed
//! changes in the documented shape, closing when the session ends, and
//! refusing a foreign Origin at the handshake.

mod common;

use std::time::Duration;

use axum::http::Method;
use common::*;
use futures::{SinkExt, StreamExt};
use gridscada_tagdb::{Sample, Timestamp};
use serde_json::{json, Value};
use tokio_tungstenite::tungstenite::client::IntoClientRequest;
use tokio_tungstenite::tungstenite::Message;

#[tokio::test]
async fn live_push_follows_the_session() {
    let h = Harness::new(Options::default()).await;
    let (addr, server) = gridscada_web::bind("127.0.0.1:0".parse().unwrap(), h.app.clone())
        .await
        .unwrap();
    tokio::spawn(server);
    // An operator's screens include the tag browser: every tag is readable
    // (what a Guest may read is tested in plant_screens.rs).
    let cookie = h.login("operator", PASSWORD).await;
    let connect = |origin: Option<String>| {
        let mut req = format!("ws://{addr}/api/live")
            .into_client_request()
            .unwrap();
        req.headers_mut().insert("cookie", cookie.parse().unwrap());
        if let Some(o) = origin {
            req.headers_mut().insert("origin", o.parse().unwrap());
        }
        tokio_tungstenite::connect_async(req)
    };

    // A foreign page cannot open the socket.
    let err = connect(Some("http://evil.test".into())).await.unwrap_err();
    assert!(err.to_string().contains("403"), "{err}");

    let (mut ws, _) = connect(Some(format!("http://{addr}"))).await.unwrap();
    let hello = next_message(&mut ws).await.unwrap();
    assert_eq!(hello["type"], "hello");
    assert_eq!(hello["user"], "operator");
    assert_eq!(hello["role"], "operator");

    ws.send(Message::Text(
        json!({"subscribe": {"tags": [TAG_RO, "No.Such.Tag"]}})
            .to_string()
            .into(),
    ))
    .await
    .unwrap();
    let snap = next_message(&mut ws).await.unwrap();
    assert_eq!(snap["type"], "tags");
    assert_eq!(snap["snapshot"], true);
    assert_eq!(
        snap["values"],
        json!([{"name": TAG_RO, "value": 1.5, "quality": {"code": "good"}, "timestamp": snap["values"][0]["timestamp"]}])
    );

    // A change is pushed; changes to tags not subscribed are not.
    let t = Timestamp::from_millis(1_800_000_000_000);
    let ro = h.state.db.id(TAG_RO).unwrap();
    let other = h.state.db.id(TAG_SUP).unwrap();
    h.state.db.apply([(other, Sample::good(99.0, t))]);
    h.state.db.apply([(ro, Sample::good(42.25, t))]);
    let push = next_message(&mut ws).await.unwrap();
    assert_eq!(
        push,
        json!({"type": "tags", "snapshot": false, "values": [
            {"name": TAG_RO, "value": 42.25, "quality": {"code": "good"}, "timestamp": 1_800_000_000_000i64}
        ]})
    );

    // A bad message gets an error, and the socket stays open.
    ws.send(Message::Text("{\"subscribe\": 5}".into()))
        .await
        .unwrap();
    let err = next_message(&mut ws).await.unwrap();
    assert_eq!(err["type"], "error");

    // Logging out closes the socket with 4001.
    let r = h
        .call(Method::DELETE, "/api/session", Some(&cookie), None)
        .await;
    assert_eq!(r.status, axum::http::StatusCode::NO_CONTENT);
    let closed = next_message(&mut ws).await.unwrap();
    assert_eq!(closed, json!({"closed": 4001}));

    // Anonymous clients cannot open it at all.
    let req = format!("ws://{addr}/api/live")
        .into_client_request()
        .unwrap();
    let err = tokio_tungstenite::connect_async(req).await.unwrap_err();
    assert!(err.to_string().contains("401"), "{err}");
}

/// A frozen server is told from a quiet plant by the heartbeat, and a
/// screen on view keeps its session alive past the idle timeout (a wall
/// display), while a socket that says nothing does not.
#[tokio::test]
async fn heartbeats_and_a_visible_screen_keep_a_watch_session() {
    let h = Harness::new(Options {
        policy: gridscada_web::auth::SessionPolicy {
            idle: Duration::from_millis(1500),
            absolute: Duration::from_secs(60),
            ..Default::default()
        },
        ..Options::default()
    })
    .await;
    let addr = h.serve().await;
    let watcher = h.login("guest", PASSWORD).await;
    let idle = h.login("operator", PASSWORD).await;
    let mut ws = live_socket(addr, &watcher).await.unwrap();
    let mut quiet = live_socket(addr, &idle).await.unwrap();
    // Heartbeats arrive every second, with the server's time.
    let mut beats = 0;
    let started = std::time::Instant::now();
    while started.elapsed() < Duration::from_secs(4) {
        ws.send(Message::Text(json!({"visible": true}).to_string().into()))
            .await
            .unwrap();
        let msg = tokio::time::timeout(Duration::from_millis(1500), ws.next())
            .await
            .expect("a heartbeat within 1.5 s")
            .unwrap()
            .unwrap();
        if let Message::Text(t) = msg {
            let v: Value = serde_json::from_str(&t).unwrap();
            if v["type"] == "heartbeat" {
                assert!(v["ts"].as_i64().unwrap() > 0);
                beats += 1;
            }
        }
    }
    assert!(beats >= 3, "{beats} heartbeats in 4 s");
    // 4 s on a 1.5 s idle timeout: the visible screen's session lives...
    let me = h
        .call(Method::GET, "/api/session", Some(&watcher), None)
        .await
        .json();
    assert_eq!(me["authenticated"], true);
    // ...the silent one's does not, and its socket is closed.
    let me = h
        .call(Method::GET, "/api/session", Some(&idle), None)
        .await
        .json();
    assert_eq!(me["authenticated"], false);
    let mut closed = next_message(&mut quiet).await.unwrap();
    if closed["type"] == "hello" {
        closed = next_message(&mut quiet).await.unwrap();
    }
    assert_eq!(closed, json!({"closed": 4001}));
}
