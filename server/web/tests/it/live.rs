//! `/api/live` over a real socket: hello, subscription snapshot, pushed
//! changes in the documented shape, closing when the session ends, and
//! refusing a foreign Origin at the handshake.

use crate::common;

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
    let (addr, server) = gridscada_web::bind(
        "127.0.0.1:0".parse().unwrap(),
        h.app.clone(),
        h.state.connections.clone(),
    )
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

    // A screen of a large plant names every tag it binds: a network screen
    // of 20,000 sections and 10,000 devices, about 40,000 names (1.1 MB),
    // is one subscription. Over 64 KiB it once ended the socket, and the
    // screen showed every section UNKNOWN, again at every reconnect.
    let mut many: Vec<String> = (0..40_000)
        .map(|i| format!("NET.Sec.r{}u{}_lv{}.State", i / 400, i % 20, i % 6))
        .collect();
    many.push(TAG_RO.to_string());
    let text = json!({"subscribe": {"tags": many}}).to_string();
    assert!(text.len() > 1_000_000, "{}", text.len());
    ws.send(Message::Text(text.into())).await.unwrap();
    let snap = next_message(&mut ws).await.unwrap();
    assert_eq!(snap["type"], "tags");
    assert_eq!(snap["snapshot"], true);
    assert_eq!(snap["values"][0]["name"], TAG_RO);

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

/// Sockets subscribed to the same tags share one feed (one subscription,
/// each message serialized once); another set of tags gets its own.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sockets_with_the_same_tags_share_one_feed() {
    let h = Harness::new(Options::default()).await;
    let addr = h.serve().await;
    let cookie = h.login("operator", PASSWORD).await;
    let subscribe =
        |tags: &[&str]| Message::Text(json!({"subscribe": {"tags": tags}}).to_string().into());
    let mut sockets = Vec::new();
    for tags in [&[TAG_RO][..], &[TAG_RO], &[TAG_SUP, TAG_RO]] {
        let mut ws = live_socket(addr, &cookie).await.unwrap();
        assert_eq!(next_message(&mut ws).await.unwrap()["type"], "hello");
        ws.send(subscribe(tags)).await.unwrap();
        let snap = next_message(&mut ws).await.unwrap();
        assert_eq!(snap["snapshot"], true);
        assert_eq!(snap["values"].as_array().unwrap().len(), tags.len());
        sockets.push(ws);
    }
    assert_eq!(h.state.live.len(), 2, "two distinct sets of tags");
    let ro = h.state.db.id(TAG_RO).unwrap();
    let t = Timestamp::from_millis(1_800_000_000_000);
    h.state.db.apply([(ro, Sample::good(7.0, t))]);
    for ws in &mut sockets {
        let push = next_message(ws).await.unwrap();
        assert_eq!(push["snapshot"], false);
        assert_eq!(push["values"][0]["name"], TAG_RO);
        assert_eq!(push["values"][0]["value"], 7.0);
    }
    // The feed goes with its last socket.
    drop(sockets);
    for _ in 0..100 {
        if h.state.live.is_empty() {
            break;
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    assert!(h.state.live.is_empty(), "feeds end with their sockets");
}

/// A socket that does not read falls behind its feed: it is sent a fresh
/// snapshot, not every message it missed, and ends on the current value.
/// With `live_merge_ms = 0` each batch is its own message.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_slow_socket_gets_a_snapshot_instead_of_a_backlog() {
    let h = Harness::new(Options::default()).await;
    let app = h.app_with_plant(|p| p.server.live_merge_ms = serde_spanned::Spanned::new(0..0, 0));
    let (addr, server) =
        gridscada_web::bind("127.0.0.1:0".parse().unwrap(), app, Default::default())
            .await
            .unwrap();
    tokio::spawn(server);
    let cookie = h.login("operator", PASSWORD).await;
    let mut ws = live_socket(addr, &cookie).await.unwrap();
    assert_eq!(next_message(&mut ws).await.unwrap()["type"], "hello");
    ws.send(Message::Text(
        json!({"subscribe": {"tags": [TAG_SUP]}}).to_string().into(),
    ))
    .await
    .unwrap();
    assert_eq!(next_message(&mut ws).await.unwrap()["snapshot"], true);
    // Far more than the socket buffers and the feed's ring hold, unread.
    let id = h.state.db.id(TAG_SUP).unwrap();
    const CHANGES: u32 = 200_000;
    for i in 1..=CHANGES {
        let t = Timestamp::from_millis(1_800_000_000_000 + i as i64);
        h.state.db.apply([(id, Sample::good(i as f64, t))]);
        if i % 100 == 0 {
            tokio::task::yield_now().await;
        }
    }
    let (mut messages, mut snapshots) = (0u32, 0u32);
    loop {
        let m = next_message(&mut ws)
            .await
            .expect("messages until the last value");
        if m["type"] != "tags" {
            continue;
        }
        messages += 1;
        if m["snapshot"] == true {
            snapshots += 1;
        }
        if m["values"][0]["value"] == CHANGES as f64 {
            break;
        }
    }
    assert!(snapshots >= 1, "a snapshot replaced the backlog");
    assert!(
        messages < CHANGES / 2,
        "{messages} messages for {CHANGES} changes: the backlog was dropped"
    );
}

/// The alarm list on the socket: whole on every change for a client that
/// asks for `alarms` alone; whole once and then as its changes for one that
/// asks for `alarm_changes` too, so a flood of standing alarms is not sent
/// whole to every screen each time one of them changes.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_alarm_list_comes_whole_or_as_its_changes() {
    let h = Harness::new(Options::default()).await;
    h.run_alarms();
    let addr = h.serve().await;
    let cookie = h.login("operator", PASSWORD).await;
    let engine = h.state.components.alarms.clone().unwrap();
    // Two standing alarms before the clients come.
    engine.raise("test.a", 500, "Z1", "A stands").unwrap();
    let b = engine.raise("test.b", 700, "Z1", "B stands").unwrap();

    let mut whole = live_socket(addr, &cookie).await.unwrap();
    let mut changes = live_socket(addr, &cookie).await.unwrap();
    for (ws, sub) in [
        (&mut whole, json!({"alarms": true})),
        (&mut changes, json!({"alarms": true, "alarm_changes": true})),
    ] {
        assert_eq!(next_message(ws).await.unwrap()["type"], "hello");
        ws.send(Message::Text(
            json!({ "subscribe": sub }).to_string().into(),
        ))
        .await
        .unwrap();
        assert_eq!(next_message(ws).await.unwrap()["type"], "tags");
        let first = next_message(ws).await.unwrap();
        assert_eq!(first["type"], "alarms", "{first}");
        assert_eq!(first["alarms"].as_array().unwrap().len(), 2);
    }

    // A third alarm: the whole list, or that alarm alone.
    engine.raise("test.c", 300, "Z2", "C stands").unwrap();
    let m = next_message(&mut whole).await.unwrap();
    assert_eq!(m["type"], "alarms");
    assert_eq!(m["alarms"].as_array().unwrap().len(), 3);
    let m = next_message(&mut changes).await.unwrap();
    assert_eq!(m["type"], "alarm_changes", "{m}");
    assert_eq!(m["changed"].as_array().unwrap().len(), 1, "{m}");
    assert_eq!(m["changed"][0]["key"], "test.c");
    let mut version = m["version"].as_u64().unwrap();

    // B cleared (still unacknowledged: it stays), then acknowledged (it
    // leaves the list).
    engine.clear("test.b").unwrap();
    let m = next_message(&mut changes).await.unwrap();
    assert_eq!(m["type"], "alarm_changes", "{m}");
    assert_eq!(m["since"].as_u64(), Some(version));
    assert_eq!(m["removed"], json!([]));
    let changed = m["changed"].as_array().unwrap();
    assert_eq!(changed.len(), 1, "{m}");
    assert_eq!(changed[0]["key"], "test.b");
    assert_eq!(changed[0]["active"], false);
    version = m["version"].as_u64().unwrap();
    engine.ack_ids("operator", &[b]).unwrap();
    let m = next_message(&mut changes).await.unwrap();
    assert_eq!(m["type"], "alarm_changes", "{m}");
    assert_eq!(m["since"].as_u64(), Some(version));
    assert_eq!(m["changed"], json!([]));
    assert_eq!(m["removed"], json!([b.0]));
    version = m["version"].as_u64().unwrap();

    // A screen change: a new subscription naming the list held goes on with
    // the changes; one naming another version gets the list whole.
    let resubscribe = |held: u64| {
        Message::Text(
            json!({"subscribe": {"alarms": true, "alarm_changes": true, "alarm_version": held}})
                .to_string()
                .into(),
        )
    };
    changes.send(resubscribe(version)).await.unwrap();
    assert_eq!(next_message(&mut changes).await.unwrap()["type"], "tags");
    engine.raise("test.d", 400, "Z2", "D stands").unwrap();
    let m = next_message(&mut changes).await.unwrap();
    assert_eq!(m["type"], "alarm_changes", "not resent whole: {m}");
    assert_eq!(m["since"].as_u64(), Some(version));
    assert_eq!(m["changed"][0]["key"], "test.d");
    version = m["version"].as_u64().unwrap();
    changes.send(resubscribe(version + 1_000)).await.unwrap();
    assert_eq!(next_message(&mut changes).await.unwrap()["type"], "tags");
    let m = next_message(&mut changes).await.unwrap();
    assert_eq!(
        m["type"], "alarms",
        "a list it did not send: whole again: {m}"
    );
    assert_eq!(m["alarms"].as_array().unwrap().len(), 3);
    engine.clear("test.d").unwrap();

    // The other client saw the same states, whole each time.
    let mut last = json!(null);
    while !(last["alarms"][0]["key"] == "test.d" && last["alarms"][0]["active"] == false) {
        last = next_message(&mut whole).await.unwrap();
        assert_eq!(last["type"], "alarms", "{last}");
    }
    let keys: Vec<&str> = last["alarms"]
        .as_array()
        .unwrap()
        .iter()
        .map(|a| a["key"].as_str().unwrap())
        .collect();
    assert_eq!(keys, ["test.d", "test.c", "test.a"], "newest change first");
}
