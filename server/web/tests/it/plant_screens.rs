//! Screens come from the loaded plant and from what users draw; tag read
//! access follows the screens a group may open (docs/ACCESS.md).

use crate::common;

use axum::http::{Method, StatusCode};
use common::*;
use serde_json::{json, Value};

fn ids(catalog: &Value) -> Vec<String> {
    catalog["screens"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["id"].as_str().unwrap().to_string())
        .collect()
}

fn tag_names(list: &Value) -> Vec<String> {
    list["tags"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| t["name"].as_str().unwrap().to_string())
        .collect()
}

/// A screen of the test plant's tags, with a label that is markup.
fn feeder_screen(version: i64) -> Value {
    json!({
        "id": "feeder-1", "name": "Feeder 1", "version": version,
        "width": 800, "height": 600,
        "elements": [
            {"type": "text", "x": 10, "y": 10, "w": 200, "h": 20, "text": "<img src=x onerror=alert(1)>"},
            {"type": "breaker", "x": 10, "y": 40, "w": 40, "h": 40, "tag": TAG_OP, "label": "Zone 1"},
            {"type": "value", "x": 60, "y": 40, "w": 120, "h": 20, "tag": TAG_RO, "digits": 1},
            {"type": "button", "x": 60, "y": 70, "w": 120, "h": 24, "tag": TAG_OP, "label": "Reset", "value": true},
            {"type": "trend", "x": 10, "y": 100, "w": 300, "h": 150, "pens": [TAG_RO], "span_s": 600}
        ]
    })
}

#[tokio::test]
async fn the_catalog_is_the_plants_own() {
    let h = Harness::new(Options::default()).await;
    let admin = h.login("administrator", PASSWORD).await;
    let cat = h
        .call(Method::GET, "/api/screens", Some(&admin), None)
        .await;
    assert_eq!(cat.status, StatusCode::OK, "{}", cat.text());
    // The test plant has no panel and no microgrid: no screens for them.
    // It runs a simulator, so it has the Simulation screen.
    assert_eq!(
        ids(&cat.json()),
        [
            "alarms",
            "events",
            "trends",
            "tags",
            "devices",
            "editor",
            "simulation",
            "users",
            "reports",
            "alarmkpi"
        ]
    );
    let guest = h.login("guest", PASSWORD).await;
    let cat = h
        .call(Method::GET, "/api/screens", Some(&guest), None)
        .await;
    // A Guest lists only what it may open.
    assert_eq!(ids(&cat.json()), ["alarms", "trends"]);
    assert!(cat.json()["screens"]
        .as_array()
        .unwrap()
        .iter()
        .all(|s| s["allowed"] == true));
    // Screen access names only screens that exist here.
    let r = h
        .call(
            Method::PUT,
            "/api/groups/visitors/screens",
            Some(&admin),
            Some(json!({"screens": ["ss1"]})),
        )
        .await;
    assert_eq!(r.status, StatusCode::BAD_REQUEST);
    assert!(r.text().contains("unknown screen 'ss1'"), "{}", r.text());
}

#[tokio::test]
async fn no_change_leaves_administrators_unable_to_manage_users() {
    let h = Harness::new(Options::default()).await;
    let admin = h.login("administrator", PASSWORD).await;
    let r = h
        .call(
            Method::PUT,
            "/api/groups/administrator/screens",
            Some(&admin),
            Some(json!({"screens": ["alarms"]})),
        )
        .await;
    assert_eq!(r.status, StatusCode::CONFLICT, "{}", r.text());
    assert!(r.text().contains("manage users"), "{}", r.text());
    // Still allowed: user management stays reachable.
    let r = h.call(Method::GET, "/api/users", Some(&admin), None).await;
    assert_eq!(r.status, StatusCode::OK);
    // Another group may drop the users screen freely.
    let r = h
        .call(
            Method::PUT,
            "/api/groups/operator/screens",
            Some(&admin),
            Some(json!({"screens": ["alarms"]})),
        )
        .await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text());
}

#[tokio::test]
async fn tags_are_searched_paged_and_show_their_source() {
    let h = Harness::new(Options::default()).await;
    let op = h.login("operator", PASSWORD).await;
    let all = h
        .call(Method::GET, "/api/tags", Some(&op), None)
        .await
        .json();
    assert_eq!(all["total"], 3);
    assert_eq!(tag_names(&all).len(), 3);
    let src = &all["tags"].as_array().unwrap()[0]["source"];
    assert_eq!(src["device"], "D1");
    assert_eq!(src["table"], "input_register");
    assert_eq!(src["data_type"], "f32");
    assert_eq!(src["word_order"], "big");
    // Search is on name and description, ignoring case; paging keeps the total.
    let r = h
        .call(Method::GET, "/api/tags?search=SETPOINT", Some(&op), None)
        .await
        .json();
    assert_eq!(tag_names(&r), [TAG_SUP]);
    let r = h
        .call(
            Method::GET,
            "/api/tags?search=zone%201%20reset",
            Some(&op),
            None,
        )
        .await
        .json();
    assert_eq!(tag_names(&r), [TAG_OP]);
    let page = h
        .call(Method::GET, "/api/tags?offset=1&limit=1", Some(&op), None)
        .await
        .json();
    assert_eq!(
        (page["total"].as_u64(), tag_names(&page).len()),
        (Some(3), 1)
    );
    assert_eq!(tag_names(&page)[0], tag_names(&all)[1]);
    let r = h
        .call(Method::GET, "/api/tags?limit=0", Some(&op), None)
        .await;
    assert_eq!(r.status, StatusCode::BAD_REQUEST);
    // The tree follows the dots.
    let tree = h
        .call(Method::GET, "/api/tags/tree?prefix=", Some(&op), None)
        .await
        .json();
    assert_eq!(
        tree["children"],
        json!([{"name": "T", "label": "T", "count": 3, "is_tag": false, "has_children": true}])
    );
    let tree = h
        .call(
            Method::GET,
            "/api/tags/tree?prefix=T.Feeder1.",
            Some(&op),
            None,
        )
        .await
        .json();
    assert_eq!(
        tree["children"],
        json!([{"name": TAG_RO, "label": "P_kW", "count": 1, "is_tag": true, "has_children": false}])
    );
}

#[tokio::test]
async fn a_drawn_screen_is_validated_versioned_and_guarded() {
    let h = Harness::new(Options::default()).await;
    let admin = h.login("administrator", PASSWORD).await;
    let op = h.login("operator", PASSWORD).await;
    let guest = h.login("guest", PASSWORD).await;
    let path = "/api/screens/feeder-1";

    // Every problem named by element and field.
    let mut bad = feeder_screen(0);
    bad["elements"][1]["tag"] = json!(TAG_RO);
    bad["elements"][2]["tag"] = json!("No.Such.Tag");
    let r = h.call(Method::PUT, path, Some(&admin), Some(bad)).await;
    assert_eq!(r.status, StatusCode::BAD_REQUEST);
    let detail = r.json()["detail"].as_str().unwrap().to_string();
    assert!(detail.contains("element 1 (breaker) tag"), "{detail}");
    assert!(
        detail.contains("element 2 (value) tag: no tag named 'No.Such.Tag'"),
        "{detail}"
    );

    // Only administrators save.
    let r = h
        .call(Method::PUT, path, Some(&op), Some(feeder_screen(0)))
        .await;
    assert_eq!(r.status, StatusCode::FORBIDDEN);

    let r = h
        .call(Method::PUT, path, Some(&admin), Some(feeder_screen(0)))
        .await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text());
    assert_eq!(r.json()["version"], 1);
    // The label is kept as the text it is.
    assert_eq!(
        r.json()["elements"][0]["text"],
        "<img src=x onerror=alert(1)>"
    );
    // A save from a stale version is refused.
    let r = h
        .call(Method::PUT, path, Some(&admin), Some(feeder_screen(0)))
        .await;
    assert_eq!(r.status, StatusCode::CONFLICT, "{}", r.text());
    // So is one from a version that never was, the last one included
    // (found by schemathesis: the next version overflowed).
    let r = h
        .call(
            Method::PUT,
            path,
            Some(&admin),
            Some(feeder_screen(i64::MAX)),
        )
        .await;
    assert_eq!(r.status, StatusCode::CONFLICT, "{}", r.text());
    let r = h
        .call(Method::PUT, path, Some(&admin), Some(feeder_screen(1)))
        .await;
    assert_eq!(r.json()["version"], 2);
    let events = h
        .call(Method::GET, "/api/events?kind=config", Some(&admin), None)
        .await
        .json();
    assert!(
        events
            .to_string()
            .contains("saved screen 'feeder-1' (Feeder 1) as version 2"),
        "{events}"
    );

    // A Guest may neither open it nor read its tags, until its group may.
    assert_eq!(
        h.call(Method::GET, path, Some(&guest), None).await.status,
        StatusCode::FORBIDDEN
    );
    assert!(!ids(&h
        .call(Method::GET, "/api/screens", Some(&guest), None)
        .await
        .json())
    .contains(&"custom:feeder-1".to_string()));
    let tag_path = format!("/api/tags/{TAG_RO}");
    assert_eq!(
        h.call(Method::GET, &tag_path, Some(&guest), None)
            .await
            .status,
        StatusCode::FORBIDDEN
    );
    assert!(tag_names(
        &h.call(Method::GET, "/api/tags", Some(&guest), None)
            .await
            .json()
    )
    .is_empty());
    let trend = format!("/api/trends?tags={TAG_RO}&from=0&to=1000");
    assert_eq!(
        h.call(Method::GET, &trend, Some(&guest), None).await.status,
        StatusCode::FORBIDDEN
    );
    let r = h
        .call(
            Method::PUT,
            "/api/groups/guest/screens",
            Some(&admin),
            Some(json!({"screens": ["alarms", "custom:feeder-1"]})),
        )
        .await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text());
    let r = h.call(Method::GET, path, Some(&guest), None).await;
    assert_eq!(r.status, StatusCode::OK);
    assert_eq!(r.json()["name"], "Feeder 1");
    assert_eq!(
        h.call(Method::GET, &tag_path, Some(&guest), None)
            .await
            .status,
        StatusCode::OK
    );
    // Exactly the screen's tags, not the others.
    assert_eq!(
        tag_names(
            &h.call(Method::GET, "/api/tags", Some(&guest), None)
                .await
                .json()
        ),
        [TAG_RO, TAG_OP]
    );

    // Deleting it takes it out of every group's access.
    let r = h.call(Method::DELETE, path, Some(&admin), None).await;
    assert_eq!(r.status, StatusCode::NO_CONTENT);
    assert_eq!(
        h.state.store.group_screens("guest").await.unwrap(),
        ["alarms"]
    );
    assert_eq!(
        h.call(Method::GET, path, Some(&admin), None).await.status,
        StatusCode::NOT_FOUND
    );
}

#[tokio::test]
async fn devices_need_field_io() {
    let h = Harness::new(Options::default()).await;
    let op = h.login("operator", PASSWORD).await;
    let r = h.call(Method::GET, "/api/devices", Some(&op), None).await;
    assert_eq!(r.status, StatusCode::SERVICE_UNAVAILABLE, "{}", r.text());
    let guest = h.login("guest", PASSWORD).await;
    let r = h
        .call(Method::GET, "/api/devices", Some(&guest), None)
        .await;
    assert_eq!(r.status, StatusCode::FORBIDDEN);
}

/// A drawn screen with one value display per tag.
fn values_screen(id: &str, tags: &[&str]) -> Value {
    let elements: Vec<Value> = tags
        .iter()
        .enumerate()
        .map(|(i, t)| {
            json!({"type": "value", "x": 10, "y": 10 + 30 * i, "w": 120, "h": 20, "tag": t, "digits": 1})
        })
        .collect();
    json!({"id": id, "name": id, "version": 0, "width": 400, "height": 300, "elements": elements})
}

/// An administrator saves `screens` and gives the guest group `access`.
async fn guest_screens(h: &Harness, admin: &str, screens: &[Value], access: &[&str]) {
    for s in screens {
        let path = format!("/api/screens/{}", s["id"].as_str().unwrap());
        let r = h
            .call(Method::PUT, &path, Some(admin), Some(s.clone()))
            .await;
        assert_eq!(r.status, StatusCode::OK, "{}", r.text());
    }
    let r = h
        .call(
            Method::PUT,
            "/api/groups/guest/screens",
            Some(admin),
            Some(json!({ "screens": access })),
        )
        .await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text());
}

/// Sends `subscribe` on `ws`; the names in the snapshot that answers it.
async fn subscribe(ws: &mut LiveSocket, subscribe: Value) -> Vec<String> {
    use futures::SinkExt;
    ws.send(tokio_tungstenite::tungstenite::Message::Text(
        json!({ "subscribe": subscribe }).to_string().into(),
    ))
    .await
    .unwrap();
    let snap = next_message(ws).await.expect("a snapshot");
    assert_eq!(
        (&snap["type"], &snap["snapshot"]),
        (&json!("tags"), &json!(true)),
        "{snap}"
    );
    snap["values"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v["name"].as_str().unwrap().to_string())
        .collect()
}

/// Sets each of `tags` in the tag database in turn, the last one to `last`;
/// the tag names pushed on `ws` until the last change arrives. A tag set
/// earlier that the socket carried would be pushed before it, or with it.
async fn pushed_until_last(
    h: &Harness,
    ws: &mut LiveSocket,
    tags: &[&str],
    last: f64,
) -> Vec<String> {
    let t = gridscada_tagdb::Timestamp::now_utc();
    for (i, tag) in tags.iter().enumerate() {
        let v = if i + 1 == tags.len() { last } else { 77.0 };
        let id = h.state.db.id(tag).unwrap();
        h.state
            .db
            .apply([(id, gridscada_tagdb::Sample::good(v, t))]);
    }
    let target = *tags.last().unwrap();
    let mut seen = vec![];
    loop {
        let m = next_message(ws).await.expect("a push");
        assert_eq!(m["type"], "tags", "{m}");
        let mut done = false;
        for v in m["values"].as_array().unwrap() {
            let name = v["name"].as_str().unwrap().to_string();
            done |= name == target && v["value"] == last;
            seen.push(name);
        }
        if done {
            return seen;
        }
    }
}

/// Issue 12 #5: over `/api/live` a Guest gets values only of the tags on its
/// screens, whether it names a tag or a prefix, in the snapshot and in the
/// pushes that follow.
#[tokio::test]
async fn a_guests_live_socket_carries_only_what_it_may_read() {
    let h = Harness::new(Options::default()).await;
    let addr = h.serve().await;
    let admin = h.login("administrator", PASSWORD).await;
    guest_screens(
        &h,
        &admin,
        &[values_screen("feeder", &[TAG_RO])],
        &["alarms", "custom:feeder"],
    )
    .await;
    let guest = h.login("guest", PASSWORD).await;
    let mut ws = live_socket(addr, &guest).await.unwrap();
    assert_eq!(next_message(&mut ws).await.unwrap()["type"], "hello");

    let names = subscribe(&mut ws, json!({"tags": [TAG_SUP, TAG_RO, TAG_OP]})).await;
    assert_eq!(names, [TAG_RO]);
    let names = subscribe(&mut ws, json!({"prefixes": ["T."]})).await;
    assert_eq!(names, [TAG_RO]);
    let names = subscribe(&mut ws, json!({"tags": [TAG_SUP, TAG_OP]})).await;
    assert!(names.is_empty(), "{names:?}");
    // Changes of the others are not pushed; of its own, they are.
    subscribe(&mut ws, json!({"tags": [TAG_SUP, TAG_OP, TAG_RO]})).await;
    let pushed = pushed_until_last(&h, &mut ws, &[TAG_SUP, TAG_OP, TAG_RO], 42.25).await;
    assert!(pushed.iter().all(|n| n == TAG_RO), "{pushed:?}");
}

/// Issue 12 #5 and docs/ACCESS.md: after an administrator narrows the
/// Guest group's screens, a new subscription on a socket opened before no
/// longer carries the removed tags.
#[tokio::test]
async fn narrowed_screens_apply_to_an_open_socket_at_its_next_subscribe() {
    let h = Harness::new(Options::default()).await;
    let addr = h.serve().await;
    let admin = h.login("administrator", PASSWORD).await;
    let feeder = values_screen("feeder", &[TAG_RO, TAG_OP]);
    let zone = values_screen("zone", &[TAG_OP]);
    guest_screens(&h, &admin, &[feeder, zone], &["alarms", "custom:feeder"]).await;
    let guest = h.login("guest", PASSWORD).await;
    let mut ws = live_socket(addr, &guest).await.unwrap();
    assert_eq!(next_message(&mut ws).await.unwrap()["type"], "hello");
    let wanted = json!({"tags": [TAG_RO, TAG_OP]});
    let names = subscribe(&mut ws, wanted.clone()).await;
    assert_eq!(names, [TAG_RO, TAG_OP]);

    guest_screens(&h, &admin, &[], &["alarms", "custom:zone"]).await;
    let names = subscribe(&mut ws, wanted).await;
    assert_eq!(names, [TAG_OP], "the removed screen's tag is still sent");
    let pushed = pushed_until_last(&h, &mut ws, &[TAG_RO, TAG_OP], 3.0).await;
    assert!(pushed.iter().all(|n| n == TAG_OP), "{pushed:?}");
}

/// The HMI's display settings: each tag's decimals resolved in the tag
/// list, the plant's `[hmi]` with the session.
#[tokio::test]
async fn tags_carry_their_decimals_and_the_session_the_plant_s_display_settings() {
    let h = Harness::new(Options::default()).await;
    let op = h.login("operator", PASSWORD).await;
    let decimals = |app: axum::Router, tag: &'static str| {
        let op = op.clone();
        async move {
            let path = format!("/api/tags/{}", seg(tag));
            let r = send_to(
                &app,
                request(Method::GET, &path, Some(&op), None),
                "127.0.0.1:40000".parse().unwrap(),
            )
            .await;
            assert_eq!(r.status, StatusCode::OK, "{}", r.text());
            r.json()["decimals"].clone()
        }
    };
    // Without [hmi]: one decimal for an analog value; a bool is no number.
    assert_eq!(decimals(h.app.clone(), TAG_RO).await, json!(1));
    assert_eq!(decimals(h.app.clone(), TAG_OP).await, Value::Null);
    let session = h.call(Method::GET, "/api/session", Some(&op), None).await;
    assert_eq!(
        session.json()["hmi"],
        json!({"decimals": 1, "date_format": "YYYY-MM-DD"})
    );
    // The plant's default, and a tag's own, as configured.
    let app = h.app_with_plant(|p| {
        p.hmi.decimals = serde_spanned::Spanned::new(0..0, 3);
        p.hmi.date_format =
            serde_spanned::Spanned::new(0..0, gridscada_config::DateFormat::DayDotted);
        let sup = p
            .tags
            .iter_mut()
            .find(|t| t.name.get_ref() == TAG_SUP)
            .unwrap();
        sup.decimals = Some(serde_spanned::Spanned::new(0..0, 0i64));
    });
    assert_eq!(decimals(app.clone(), TAG_RO).await, json!(3));
    assert_eq!(decimals(app.clone(), TAG_SUP).await, json!(0));
    let session = send_to(
        &app,
        request(Method::GET, "/api/session", Some(&op), None),
        "127.0.0.1:40000".parse().unwrap(),
    )
    .await;
    assert_eq!(
        session.json()["hmi"],
        json!({"decimals": 3, "date_format": "DD.MM.YYYY"})
    );
    h.cleanup().await;
}
