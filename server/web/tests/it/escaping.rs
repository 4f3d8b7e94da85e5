//! Hostile names are data: user and group names holding markup, quotes and
//! path separators round-trip exactly through create, list, update and delete,
//! always as JSON, and percent-encoded in paths.

use crate::common;

use axum::http::{Method, StatusCode};
use common::*;
use serde_json::json;

const NAMES: &[&str] = &[
    "<script>alert(1)</script>",
    "\"'",
    "a/b",
    "..\\x",
    "<img src=x onerror=alert(1)>&amp;",
    "ünïcødé ☃",
];

#[tokio::test]
async fn hostile_user_and_group_names_round_trip_exactly() {
    let h = Harness::new(Options::default()).await;
    let admin = h.login("administrator", PASSWORD).await;
    for (i, name) in NAMES.iter().enumerate() {
        let group = format!("{name} group {i}");
        // Create.
        let r = h
            .call(
                Method::POST,
                "/api/users",
                Some(&admin),
                Some(
                    json!({"name": name, "role": "operator", "group": group, "password": PASSWORD}),
                ),
            )
            .await;
        assert_eq!(r.status, StatusCode::CREATED, "{name}: {}", r.text());
        assert!(r.content_type().starts_with("application/json"));
        let j = r.json();
        assert_eq!(j["user"]["name"], *name);
        assert_eq!(j["user"]["group"], group);
        assert!(
            j.get("password").is_none(),
            "no generated password when one is given"
        );
        // The raw body carries the name JSON-escaped.
        let escaped = serde_json::to_string(name).unwrap();
        assert!(r.text().contains(&escaped), "{}", r.text());

        // List.
        let r = h.call(Method::GET, "/api/users", Some(&admin), None).await;
        assert!(r.content_type().starts_with("application/json"));
        let users = r.json()["users"].as_array().unwrap().clone();
        let found: Vec<_> = users.iter().filter(|u| u["name"] == *name).collect();
        assert_eq!(found.len(), 1, "{name} listed once: {users:?}");
        assert_eq!(found[0]["group"], group);

        // The user can log in under that exact name.
        let own = h.login(name, PASSWORD).await;
        let me = h
            .call(Method::GET, "/api/session", Some(&own), None)
            .await
            .json();
        assert_eq!(me["user"], *name);
        assert_eq!(me["group"], group);

        // Group screens, addressed by the percent-encoded name.
        let gpath = format!("/api/groups/{}/screens", seg(&group));
        let r = h
            .call(
                Method::PUT,
                &gpath,
                Some(&admin),
                Some(json!({"screens": ["alarms", "events"]})),
            )
            .await;
        assert_eq!(r.status, StatusCode::OK, "{group}: {}", r.text());
        assert_eq!(r.json()["group"], group);
        let r = h.call(Method::GET, &gpath, Some(&admin), None).await;
        assert_eq!(r.json()["group"], group);
        assert_eq!(r.json()["screens"], json!(["alarms", "events"]));
        // And the user's session now has exactly those screens.
        let me = h
            .call(Method::GET, "/api/session", Some(&own), None)
            .await
            .json();
        assert_eq!(me["screens"], json!(["alarms", "events"]));

        // Update, addressed by the percent-encoded user name.
        let upath = format!("/api/users/{}", seg(name));
        let new_group = format!("{group} & more </b>");
        let r = h
            .call(
                Method::PATCH,
                &upath,
                Some(&admin),
                Some(json!({"group": new_group, "role": "supervisor"})),
            )
            .await;
        assert_eq!(r.status, StatusCode::OK, "{name}: {}", r.text());
        assert_eq!(r.json()["user"]["name"], *name);
        assert_eq!(r.json()["user"]["group"], new_group);
        assert_eq!(r.json()["user"]["role"], "supervisor");

        // The event log records the name as data too.
        let r = h
            .call(
                Method::GET,
                "/api/events?type=user&limit=500",
                Some(&admin),
                None,
            )
            .await;
        let events = r.json()["events"].as_array().unwrap().clone();
        assert!(
            events.iter().any(|e| e["message"]
                .as_str()
                .is_some_and(|m| m.contains(&format!("created user '{name}'")))),
            "{name}: {events:?}"
        );

        // Delete needs the exact name as confirmation.
        let r = h
            .call(
                Method::DELETE,
                &upath,
                Some(&admin),
                Some(json!({"confirm": format!("{name} ")})),
            )
            .await;
        assert_eq!(r.status, StatusCode::BAD_REQUEST, "{}", r.text());
        let r = h
            .call(
                Method::DELETE,
                &upath,
                Some(&admin),
                Some(json!({"confirm": name})),
            )
            .await;
        assert_eq!(r.status, StatusCode::NO_CONTENT, "{name}: {}", r.text());
        // Gone, and its session with it.
        let r = h.call(Method::GET, "/api/users", Some(&admin), None).await;
        assert!(!r.json()["users"]
            .as_array()
            .unwrap()
            .iter()
            .any(|u| u["name"] == *name));
        assert_eq!(
            h.call(Method::GET, "/api/tags", Some(&own), None)
                .await
                .status,
            StatusCode::UNAUTHORIZED
        );
    }
    // Names with control characters or edge spaces are refused, not mangled.
    for bad in ["tab\there", " lead", "trail ", "", "nul\u{0}byte"] {
        let r = h
            .call(
                Method::POST,
                "/api/users",
                Some(&admin),
                Some(json!({"name": bad, "role": "guest"})),
            )
            .await;
        assert_eq!(r.status, StatusCode::BAD_REQUEST, "{bad:?}: {}", r.text());
    }
}
