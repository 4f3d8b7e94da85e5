//! The OpenAPI document (generated from the handlers' annotations and the
//! route table, `gridscada_web::openapi`) and the route table cannot drift:
//! every route is documented with its method and its permission, nothing else
//! is, path parameters are declared, public and protected routes say so, and
//! every schema it refers to is in it.

use crate::common;

use std::collections::BTreeSet;

use axum::http::{Method, StatusCode};
use common::*;
use gridscada_web::openapi::permission_text;
use gridscada_web::routes::{table, Perm};
use serde_json::Value;

fn document() -> Value {
    gridscada_web::openapi::document().clone()
}

/// `schema`, or the component it refers to.
fn resolve<'a>(doc: &'a Value, schema: &'a Value) -> &'a Value {
    match schema["$ref"].as_str() {
        Some(r) => {
            let name = r
                .strip_prefix("#/components/schemas/")
                .unwrap_or_else(|| panic!("a reference outside the components: {r}"));
            &doc["components"]["schemas"][name]
        }
        None => schema,
    }
}

fn refs(v: &Value, out: &mut Vec<String>) {
    match v {
        Value::Object(o) => {
            if let Some(Value::String(r)) = o.get("$ref") {
                out.push(r.clone());
            }
            o.values().for_each(|v| refs(v, out));
        }
        Value::Array(a) => a.iter().for_each(|v| refs(v, out)),
        _ => {}
    }
}

#[test]
fn every_route_is_documented_and_nothing_else() {
    let doc = document();
    assert_eq!(doc["openapi"], "3.1.0");
    let paths = doc["paths"].as_object().expect("paths");
    let documented: BTreeSet<(String, String)> = paths
        .iter()
        .flat_map(|(path, item)| {
            item.as_object()
                .unwrap()
                .keys()
                .filter(|k| {
                    [
                        "get", "put", "post", "delete", "patch", "head", "options", "trace",
                    ]
                    .contains(&k.as_str())
                })
                .map(move |m| (m.to_uppercase(), path.clone()))
        })
        .collect();
    let routed: BTreeSet<(String, String)> = table()
        .iter()
        .map(|r| (r.method.to_string(), r.path.to_string()))
        .collect();
    let missing: Vec<_> = routed.difference(&documented).collect();
    let extra: Vec<_> = documented.difference(&routed).collect();
    assert!(
        missing.is_empty(),
        "routes missing from the OpenAPI document: {missing:?}"
    );
    assert!(
        extra.is_empty(),
        "the OpenAPI document has routes that do not exist: {extra:?}"
    );
}

#[test]
fn parameters_security_and_errors_match_the_table() {
    let doc = document();
    for route in table() {
        let what = format!("{} {}", route.method, route.path);
        let op = &doc["paths"][route.path][route.method.as_str().to_lowercase()];
        // Every `{param}` of the path is declared as a required path parameter.
        let declared: BTreeSet<String> = op["parameters"]
            .as_array()
            .map(|ps| {
                ps.iter()
                    .filter(|p| p["in"] == "path" && p["required"] == true)
                    .map(|p| p["name"].as_str().unwrap().to_string())
                    .collect()
            })
            .unwrap_or_default();
        let in_path: BTreeSet<String> = route
            .path
            .split('/')
            .filter_map(|s| s.strip_prefix('{')?.strip_suffix('}'))
            .map(String::from)
            .collect();
        assert_eq!(declared, in_path, "{what}: path parameters");
        // Public routes may be called without the cookie; others need it and
        // document 401 and 403.
        let security = op["security"]
            .as_array()
            .unwrap_or_else(|| panic!("{what}: no security"));
        let anonymous_ok = security
            .iter()
            .any(|s| s.as_object().is_some_and(|o| o.is_empty()));
        assert_eq!(anonymous_ok, route.perm == Perm::Public, "{what}: security");
        if route.perm != Perm::Public {
            for code in ["401", "403"] {
                assert_eq!(
                    op["responses"][code]["content"]["application/json"]["schema"]["$ref"],
                    "#/components/schemas/Error",
                    "{what}: {code}"
                );
            }
        }
        // A success answer is documented.
        let responses = op["responses"].as_object().unwrap();
        assert!(
            responses.keys().any(|k| k.starts_with('2') || k == "101"),
            "{what}: no success response"
        );
        // The permission of the route table, in words.
        assert_eq!(
            op["x-permission"],
            permission_text(route.perm),
            "{what}: x-permission"
        );
        // Request bodies are closed objects where the handler refuses unknown fields.
        let body = &op["requestBody"]["content"]["application/json"]["schema"];
        if !body.is_null() {
            assert_eq!(
                resolve(&doc, body)["additionalProperties"],
                false,
                "{what}: request body"
            );
        }
    }
    assert_eq!(
        doc["components"]["securitySchemes"]["session"]["name"],
        gridscada_web::auth::COOKIE
    );
}

/// Also writes the document to `$GRIDSCADA_OPENAPI_OUT` when set, to read
/// or compare it.
#[test]
fn every_reference_resolves() {
    let doc = document();
    if let Ok(path) = std::env::var("GRIDSCADA_OPENAPI_OUT") {
        std::fs::write(&path, gridscada_web::openapi::document_text()).expect("written");
    }
    let mut found = vec![];
    refs(&doc, &mut found);
    assert!(!found.is_empty());
    for r in found {
        assert!(
            !resolve(&doc, &serde_json::json!({ "$ref": r })).is_null(),
            "{r} is not in the components"
        );
    }
}

#[tokio::test]
async fn the_served_document_is_the_generated_one() {
    let h = Harness::new(Options::default()).await;
    let r = h.call(Method::GET, "/api/openapi.json", None, None).await;
    assert_eq!(r.status, StatusCode::OK);
    assert!(r.content_type().starts_with("application/json"));
    assert_eq!(r.json(), document());
}

/// The schemas kept by hand for other crates' types follow those types: the
/// roles are every `Role`, lowest first.
#[test]
fn hand_kept_shapes_follow_their_types() {
    let doc = document();
    let roles: Vec<&str> = doc["components"]["schemas"]["Role"]["enum"]
        .as_array()
        .expect("Role is an enum")
        .iter()
        .filter_map(|v| v.as_str())
        .collect();
    let want: Vec<&str> = gridscada_config::Role::ALL
        .iter()
        .map(|r| r.label())
        .collect();
    assert_eq!(roles, want);
    // A history row's cause is every `TransitionCause`, by its stored name.
    let cause = &doc["components"]["schemas"]["AlarmTransition"]["properties"]["cause"];
    let cause = cause["oneOf"]
        .as_array()
        .and_then(|v| v.iter().find(|s| s["$ref"].is_string()))
        .unwrap_or(cause);
    let causes: Vec<&str> = resolve(&doc, cause)["enum"]
        .as_array()
        .unwrap_or_else(|| panic!("the cause is an enum: {cause}"))
        .iter()
        .filter_map(|v| v.as_str())
        .collect();
    let want: Vec<&str> = gridscada_alarms::TransitionCause::ALL
        .iter()
        .map(|c| c.as_str())
        .collect();
    assert_eq!(causes, want);
}
