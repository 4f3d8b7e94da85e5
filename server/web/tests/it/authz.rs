//! The authorization matrix: every route of `routes::table()` against every
//! kind of caller, the expectation derived from the route's `Perm`, plus an
//! independent hand-written table of the rules that matter most, so that a
//! wrong `Perm` in the table is caught too.

use crate::common;

use axum::http::{Method, StatusCode};
use common::*;
use gridscada_config::Role;
use gridscada_web::access::default_screens;
use gridscada_web::auth::Principal;
use gridscada_web::routes::{table, Perm};
use serde_json::json;

/// The callers: anonymous, then one logged-in user per role (in the group
/// named after the role, so with that role's default screens).
const ROLES: [Role; 4] = [
    Role::Guest,
    Role::Operator,
    Role::Supervisor,
    Role::Administrator,
];

/// A concrete path for a route pattern. `{name}` becomes the caller's own
/// user name so that "own password" is exercised as its owner.
fn concrete(path: &str, me: &str) -> String {
    path.replace("{name}", me)
        .replace("{id}", "1")
        .replace("{group}", "operator")
        .replace("{panel}", "ss1")
        .replace("{zone}", "1")
        .replace("{device}", "D1")
        .replace("{breaker}", "zone1")
}

fn body_for(method: &Method) -> Option<serde_json::Value> {
    // A dummy (mostly invalid) body: the point is who gets past the door.
    (*method != Method::GET && *method != Method::DELETE).then(|| json!({}))
}

fn is_fallback_404(r: &Resp) -> bool {
    r.status == StatusCode::NOT_FOUND
        && serde_json::from_slice::<serde_json::Value>(&r.body)
            .map(|j| j["detail"] == "no such API route" || j["detail"] == "no such page")
            .unwrap_or(true)
}

#[tokio::test]
async fn every_route_against_every_caller() {
    let h = Harness::new(Options::default()).await;
    let mut routes = table();
    // Logging out ends the caller's session: do it last for each caller.
    routes.sort_by_key(|r| r.method == Method::DELETE && r.path == "/api/session");

    let mut failures = vec![];
    // Anonymous.
    for route in &routes {
        let path = concrete(route.path, "nobody");
        let r = h
            .call(route.method.clone(), &path, None, body_for(&route.method))
            .await;
        let expect_401 = route.perm != Perm::Public;
        if expect_401 != (r.status == StatusCode::UNAUTHORIZED) || r.status == StatusCode::FORBIDDEN
        {
            failures.push(format!(
                "anonymous {} {path}: got {} ({})",
                route.method,
                r.status,
                r.text()
            ));
        }
    }
    // Each role.
    for role in ROLES {
        let me = role.label();
        let cookie = h.login(me, PASSWORD).await;
        let principal = Principal {
            user: Some(me.to_string()),
            role,
            group: Some(me.to_string()),
            screens: default_screens(&h.state.plant, &h.state.screens, role),
        };
        for route in &routes {
            let path = concrete(route.path, me);
            let r = h
                .call(
                    route.method.clone(),
                    &path,
                    Some(&cookie),
                    body_for(&route.method),
                )
                .await;
            let absent = route.perm.screen().is_some_and(|screen| {
                !gridscada_web::access::screen_exists(&h.state.plant, &h.state.screens, screen)
            });
            let expected = if absent {
                Some(StatusCode::NOT_FOUND)
            } else {
                route.perm.check(&principal).err().map(|e| e.status)
            };
            let ok = match expected {
                Some(status) => r.status == status,
                None => r.status != StatusCode::UNAUTHORIZED && r.status != StatusCode::FORBIDDEN,
            };
            if !ok {
                failures.push(format!(
                    "{me} {} {path}: expected {}, got {} ({})",
                    route.method,
                    expected.map_or("allowed".to_string(), |s| s.to_string()),
                    r.status,
                    r.text()
                ));
            }
        }
    }
    assert!(failures.is_empty(), "\n{}", failures.join("\n"));
}

/// The rules an auditor would check by hand, written independently of the
/// route table. `None` = allowed (not 401/403).
#[tokio::test]
async fn key_rules_hold_independently_of_the_table() {
    use Role::*;
    let h = Harness::new(Options::default()).await;
    h.add_user("bystander", Role::Guest, "guest").await;
    let mut cookies = vec![];
    for role in ROLES {
        cookies.push((role, h.login(role.label(), PASSWORD).await));
    }
    let cookie = |role: Role| cookies.iter().find(|(r, _)| *r == role).unwrap().1.clone();

    // (method, path, body, the least role allowed)
    let rules: Vec<(Method, &str, serde_json::Value, Role)> = vec![
        (Method::GET, "/api/tags", json!(null), Guest),
        (
            Method::POST,
            "/api/alarms/ack",
            json!({"all": true}),
            Operator,
        ),
        (
            Method::POST,
            "/api/alarms/7/shelve",
            json!({"minutes": 5, "reason": "test"}),
            Supervisor,
        ),
        (
            Method::DELETE,
            "/api/alarms/7/shelve",
            json!(null),
            Supervisor,
        ),
        (
            Method::POST,
            "/api/alarms/7/out-of-service",
            json!({"hours": 1, "reason": "test"}),
            Supervisor,
        ),
        (
            Method::DELETE,
            "/api/alarms/7/out-of-service",
            json!(null),
            Supervisor,
        ),
        (
            Method::POST,
            "/api/panels/ss1/mode",
            json!({"mode": "manual"}),
            Supervisor,
        ),
        (Method::POST, "/api/panels/ss1/reset", json!(null), Operator),
        (
            Method::POST,
            "/api/panels/ss1/breakers/zone1",
            json!({"closed": true}),
            Operator,
        ),
        (Method::GET, "/api/users", json!(null), Administrator),
        (
            Method::POST,
            "/api/users",
            json!({"name": "x", "role": "guest"}),
            Administrator,
        ),
        (Method::PATCH, "/api/users/guest", json!({}), Administrator),
        (
            Method::DELETE,
            "/api/users/nobody",
            json!({"confirm": "nobody"}),
            Administrator,
        ),
        (
            Method::GET,
            "/api/groups/operator/screens",
            json!(null),
            Administrator,
        ),
        (
            Method::PUT,
            "/api/groups/visitors/screens",
            json!({"screens": ["events"]}),
            Administrator,
        ),
        (
            Method::POST,
            "/api/sim/faults",
            json!({"panel": "ss1", "zone": 1, "kind": "transient"}),
            Administrator,
        ),
        (
            Method::DELETE,
            "/api/sim/faults/ss1/1",
            json!(null),
            Administrator,
        ),
        (
            Method::POST,
            "/api/sim/devices/D1/offline",
            json!(null),
            Administrator,
        ),
        (
            Method::POST,
            "/api/sim/devices/D1/online",
            json!(null),
            Administrator,
        ),
        // The tag's own write_role, enforced by the server.
        (
            Method::POST,
            "/api/tags/T.Zone1.Reset/write",
            json!({"value": true}),
            Operator,
        ),
        (
            Method::POST,
            "/api/tags/T.BESS.Setpoint_kW/write",
            json!({"value": 10.0}),
            Supervisor,
        ),
        // Another user's password: administrators only.
        (
            Method::POST,
            "/api/users/bystander/password",
            json!({"password": "another long password"}),
            Administrator,
        ),
    ];
    let mut failures = vec![];
    for (method, path, body, least) in &rules {
        let r = h
            .call(
                method.clone(),
                path,
                None,
                (!body.is_null()).then(|| body.clone()),
            )
            .await;
        if r.status != StatusCode::UNAUTHORIZED {
            failures.push(format!("anonymous {method} {path}: got {}", r.status));
        }
        for role in ROLES {
            let r = h
                .call(
                    method.clone(),
                    path,
                    Some(&cookie(role)),
                    (!body.is_null()).then(|| body.clone()),
                )
                .await;
            let denied = r.status == StatusCode::FORBIDDEN || r.status == StatusCode::UNAUTHORIZED;
            let want_denied = role < *least;
            if denied != want_denied || (want_denied && r.status != StatusCode::FORBIDDEN) {
                failures.push(format!(
                    "{} {method} {path}: got {} ({}); least role allowed is {}",
                    role.label(),
                    r.status,
                    r.text(),
                    least.label()
                ));
            }
        }
    }
    assert!(failures.is_empty(), "\n{}", failures.join("\n"));

    // Screens, not roles: a guest may open trends but not events.
    let r = h
        .call(Method::GET, "/api/events", Some(&cookie(Guest)), None)
        .await;
    assert_eq!(r.status, StatusCode::FORBIDDEN);
    let r = h
        .call(Method::GET, "/api/events", Some(&cookie(Operator)), None)
        .await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text());

    // Writes that were allowed really reached the field writer; refused ones did not.
    let writes = h.writer.writes.lock().clone();
    let sup_writes = writes.iter().filter(|(n, _)| n == TAG_SUP).count();
    let op_writes = writes.iter().filter(|(n, _)| n == TAG_OP).count();
    assert_eq!(sup_writes, 2, "supervisor and administrator: {writes:?}");
    assert_eq!(
        op_writes, 3,
        "operator, supervisor, administrator: {writes:?}"
    );

    // A read-only tag refuses even an administrator.
    let r = h
        .call(
            Method::POST,
            &format!("/api/tags/{TAG_RO}/write"),
            Some(&cookie(Administrator)),
            Some(json!({"value": 1.0})),
        )
        .await;
    assert_eq!(r.status, StatusCode::FORBIDDEN, "{}", r.text());

    // Own password: allowed for anyone who knows the current one.
    let r = h
        .call(
            Method::POST,
            "/api/users/guest/password",
            Some(&cookie(Guest)),
            Some(json!({"password": "a new long password", "current_password": PASSWORD})),
        )
        .await;
    assert_eq!(r.status, StatusCode::NO_CONTENT, "{}", r.text());
}

#[tokio::test]
async fn sim_routes_are_absent_without_a_simulator() {
    let h = Harness::new(Options {
        sim: false,
        ..Default::default()
    })
    .await;
    let admin = h.login("administrator", PASSWORD).await;
    for route in table().iter().filter(|r| r.sim_only) {
        let path = concrete(route.path, "administrator");
        let r = h
            .call(
                route.method.clone(),
                &path,
                Some(&admin),
                body_for(&route.method),
            )
            .await;
        assert_eq!(r.status, StatusCode::NOT_FOUND, "{} {path}", route.method);
        // The refusal says why, in words for the trainer.
        assert!(
            r.text().contains("only in `gridscada demo`"),
            "{} {path}: {}",
            route.method,
            r.text()
        );
        // And anonymous callers learn nothing more than "not found" either.
        let r = h
            .call(route.method.clone(), &path, None, body_for(&route.method))
            .await;
        assert_eq!(r.status, StatusCode::NOT_FOUND, "{} {path}", route.method);
    }
    assert!(h.sim.calls.lock().is_empty());
    // Nor is there a Simulation screen to show or to grant to a group.
    let catalog = h
        .call(Method::GET, "/api/screens", Some(&admin), None)
        .await;
    assert_eq!(catalog.status, StatusCode::OK, "{}", catalog.text());
    assert!(
        !catalog.text().contains("\"simulation\""),
        "{}",
        catalog.text()
    );
    let r = h
        .call(
            Method::PUT,
            "/api/groups/trainers/screens",
            Some(&admin),
            Some(json!({"screens": ["simulation"]})),
        )
        .await;
    assert_eq!(r.status, StatusCode::BAD_REQUEST, "{}", r.text());
}

/// With a simulator (`demo`), the Simulation screen is an administrator's by
/// default, and an administrator may give it to a trainer group of operators.
#[tokio::test]
async fn a_trainer_group_gets_the_simulation_panel() {
    let h = Harness::new(Options::default()).await;
    let admin = h.login("administrator", PASSWORD).await;
    let catalog = h
        .call(Method::GET, "/api/screens", Some(&admin), None)
        .await;
    assert!(
        catalog.text().contains("\"simulation\""),
        "{}",
        catalog.text()
    );
    let fault = json!({"panel": "ss1", "zone": 2, "kind": "permanent"});
    let op = h.login("operator", PASSWORD).await;
    let r = h
        .call(
            Method::POST,
            "/api/sim/faults",
            Some(&op),
            Some(fault.clone()),
        )
        .await;
    assert_eq!(r.status, StatusCode::FORBIDDEN, "{}", r.text());
    h.add_user("trainer1", Role::Operator, "trainers").await;
    let r = h
        .call(
            Method::PUT,
            "/api/groups/trainers/screens",
            Some(&admin),
            Some(json!({"screens": ["alarms", "simulation"]})),
        )
        .await;
    assert!(r.status.is_success(), "{}", r.text());
    let trainer = h.login("trainer1", PASSWORD).await;
    let r = h
        .call(Method::POST, "/api/sim/faults", Some(&trainer), Some(fault))
        .await;
    assert_eq!(r.status, StatusCode::CREATED, "{}", r.text());
    assert_eq!(h.sim.calls.lock().as_slice(), ["fault ss1 2 Permanent"]);
    // Recorded as training, with the trainer's name.
    let events = h
        .call(Method::GET, "/api/events?type=training", Some(&admin), None)
        .await;
    assert!(
        events.text().contains("trainer1") && events.text().contains("Training:"),
        "{}",
        events.text()
    );
    // A permanent fault does not clear by itself.
    let r = h
        .call(
            Method::POST,
            "/api/sim/faults",
            Some(&trainer),
            Some(json!({"panel": "ss1", "zone": 2, "kind": "permanent", "clears_after_s": 5})),
        )
        .await;
    assert_eq!(r.status, StatusCode::BAD_REQUEST, "{}", r.text());
    assert!(r.text().contains("clears_after_s"), "{}", r.text());
}

/// Every path in the table is routed (no typo sends it to the HMI fallback)
/// and answers its declared method.
#[tokio::test]
async fn every_route_in_the_table_is_reachable() {
    let h = Harness::new(Options::default()).await;
    let admin = h.login("administrator", PASSWORD).await;
    let mut routes = table();
    routes.sort_by_key(|r| r.method == Method::DELETE && r.path == "/api/session");
    for route in &routes {
        let path = concrete(route.path, "administrator");
        let r = h
            .call(
                route.method.clone(),
                &path,
                Some(&admin),
                body_for(&route.method),
            )
            .await;
        assert!(
            !is_fallback_404(&r) && r.status != StatusCode::METHOD_NOT_ALLOWED,
            "{} {} is not routed: {} {}",
            route.method,
            route.path,
            r.status,
            r.text()
        );
    }
    // The table has no duplicates.
    let mut seen = std::collections::HashSet::new();
    for route in table() {
        assert!(
            seen.insert((route.method.clone(), route.path)),
            "duplicate route {} {}",
            route.method,
            route.path
        );
    }
}
