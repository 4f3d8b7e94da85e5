//! The OpenAPI document, generated: each handler's `#[utoipa::path]`
//! annotation gives its operation (parameters, request body, answers), the
//! types give the schemas, and the route table ([`crate::routes::table`])
//! gives the paths, methods and permissions. From the permission follow the
//! operation's security, its 401 and 403 answers and `x-permission`; every
//! error answer carries the [`shapes::ErrorBody`] schema.
//!
//! A new route costs its line in the route table and one annotation on its
//! handler. `tests/openapi.rs` checks that every route is documented, and
//! `tests/e2e/schemathesis.sh` fuzzes the server against the document.

pub mod shapes;

use std::sync::OnceLock;

use serde_json::{json, Map, Value};
use utoipa::openapi::path::{HttpMethod, Operation};
use utoipa::openapi::schema::Schema;
use utoipa::openapi::RefOr;

use crate::routes::{table, Perm};

/// What the annotation of one handler gives: its path, methods, operation,
/// and the schemas it refers to.
pub struct Doc {
    pub path: String,
    pub methods: Vec<HttpMethod>,
    pub operation: Operation,
    pub schemas: Vec<(String, RefOr<Schema>)>,
}

/// The documentation of handler `P` (the `__path_<handler>` type that
/// `#[utoipa::path]` makes). Its schemas and tags come through
/// `utoipa::__dev`, the traits utoipa-axum reads them with: a change there
/// shows here at compile time.
pub fn doc<P>() -> Doc
where
    P: utoipa::Path + utoipa::__dev::SchemaReferences + for<'t> utoipa::__dev::Tags<'t>,
{
    let mut schemas = Vec::new();
    P::schemas(&mut schemas);
    let mut operation = P::operation();
    let tags = P::tags();
    if !tags.is_empty() {
        operation
            .tags
            .get_or_insert_with(Vec::new)
            .extend(tags.into_iter().map(String::from));
    }
    Doc {
        path: P::path(),
        methods: P::methods(),
        operation,
        schemas,
    }
}

const DESCRIPTION: &str = "The HTTP API of gridscada. Log in with POST /api/session; the session lives in an HttpOnly, SameSite=Strict cookie. Unsafe methods from another Origin are refused (403). Every error answers JSON {error, detail}. Routes under /api/sim exist only in `demo` and `replay`. Each operation's `x-permission` says who may call it.";

/// The usual meaning of an error status, for answers annotated without one.
fn error_description(status: &str) -> &'static str {
    match status {
        "400" => "Bad request: the body, path or query does not parse or is invalid",
        "401" => "Not logged in",
        "403" => "Logged in but not allowed (role, screen, tag write role) or a cross-site request",
        "404" => "No such object",
        "409" => "Conflicts with the current state",
        "503" => "The component is not running",
        "default" => "Any other error",
        _ => "Error",
    }
}

/// The permission in words, as `x-permission` carries it.
pub fn permission_text(perm: Perm) -> String {
    match perm {
        Perm::Public => "public".into(),
        Perm::LoggedIn => "logged in".into(),
        Perm::Screen(s) => format!("screen {s}"),
        Perm::Role(r) => format!("role {}", r.label().to_lowercase()),
        Perm::RoleScreen(r, s) => format!("role {}, screen {s}", r.label().to_lowercase()),
    }
}

/// `post_api_tags_name_write` for `POST /api/tags/{name}/write`.
fn operation_id(method: &str, path: &str) -> String {
    let mut id = method.to_lowercase();
    for part in path.split(|c: char| !c.is_ascii_alphanumeric()) {
        if !part.is_empty() {
            id.push('_');
            id.push_str(part);
        }
    }
    id
}

/// The document, built once.
pub fn document() -> &'static Value {
    static DOC: OnceLock<Value> = OnceLock::new();
    DOC.get_or_init(build)
}

/// The document as served.
pub fn document_text() -> &'static str {
    static TEXT: OnceLock<String> = OnceLock::new();
    TEXT.get_or_init(|| serde_json::to_string_pretty(document()).expect("JSON"))
}

/// Gives each integer schema the bounds of its Rust type: utoipa names the
/// type in `format` (`u-int32`, `int8`...); JSON Schema needs `minimum` and
/// `maximum`. The formats OpenAPI does not define are dropped.
fn integer_bounds(v: &mut Value) {
    match v {
        Value::Object(o) => {
            let integer = match o.get("type") {
                Some(Value::String(t)) => t == "integer",
                Some(Value::Array(ts)) => ts.contains(&json!("integer")),
                _ => false,
            };
            if integer {
                let bounds: Option<(i64, Option<i64>)> =
                    match o.get("format").and_then(Value::as_str) {
                        Some("u-int8") => Some((0, Some(u8::MAX.into()))),
                        Some("u-int16") => Some((0, Some(u16::MAX.into()))),
                        Some("u-int32") => Some((0, Some(u32::MAX.into()))),
                        Some("u-int64") => Some((0, None)),
                        Some("int8") => Some((i8::MIN.into(), Some(i8::MAX.into()))),
                        Some("int16") => Some((i16::MIN.into(), Some(i16::MAX.into()))),
                        Some("int32") => Some((i32::MIN.into(), Some(i32::MAX.into()))),
                        _ => None,
                    };
                if let Some((min, max)) = bounds {
                    // utoipa writes the bounds given by attributes as floats.
                    let given = |k: &str| o.get(k).and_then(Value::as_f64).map(|f| f as i64);
                    let lowest = given("minimum").map_or(min, |g| g.max(min));
                    let highest = max.map(|max| given("maximum").map_or(max, |g| g.min(max)));
                    o.insert("minimum".into(), json!(lowest));
                    if let Some(highest) = highest {
                        o.insert("maximum".into(), json!(highest));
                    }
                }
                if !matches!(
                    o.get("format").and_then(Value::as_str),
                    Some("int32" | "int64") | None
                ) {
                    o.remove("format");
                }
            }
            o.values_mut().for_each(integer_bounds);
        }
        Value::Array(a) => a.iter_mut().for_each(integer_bounds),
        _ => {}
    }
}

fn build() -> Value {
    let mut doc = assemble();
    integer_bounds(&mut doc);
    doc
}

fn assemble() -> Value {
    let mut paths = Map::new();
    let mut schemas = Map::new();
    let mut tags = std::collections::BTreeSet::new();
    schemas.insert(
        "Error".into(),
        serde_json::to_value(<shapes::ErrorBody as utoipa::PartialSchema>::schema())
            .expect("schema"),
    );
    let error_ref = json!({"application/json": {"schema": {"$ref": "#/components/schemas/Error"}}});
    for route in table() {
        let d = (route.doc)();
        let method = route.method.as_str().to_lowercase();
        assert_eq!(
            d.path, route.path,
            "the annotation of {} {} names another path",
            route.method, route.path
        );
        assert!(
            d.methods
                .iter()
                .any(|m| serde_json::to_value(m).ok() == Some(json!(method))),
            "the annotation of {} {} names other methods",
            route.method,
            route.path
        );
        for (name, schema) in d.schemas {
            let schema = serde_json::to_value(schema).expect("schema");
            if let Some(other) = schemas.get(&name) {
                assert_eq!(
                    other, &schema,
                    "two types make the component schema {name}: give one `#[schema(as = ...)]`"
                );
            }
            schemas.insert(name, schema);
        }
        let mut op = serde_json::to_value(d.operation).expect("operation");
        let o = op.as_object_mut().expect("operation object");
        o.insert(
            "operationId".into(),
            json!(operation_id(&method, route.path)),
        );
        for tag in o
            .get("tags")
            .and_then(Value::as_array)
            .into_iter()
            .flatten()
        {
            tags.insert(tag.as_str().unwrap_or_default().to_string());
        }
        if o.get("description").and_then(Value::as_str) == Some("") {
            o.remove("description");
        }
        o.insert(
            "security".into(),
            if route.perm == Perm::Public {
                json!([{}, {"session": []}])
            } else {
                json!([{"session": []}])
            },
        );
        o.insert("x-permission".into(), json!(permission_text(route.perm)));
        let responses = o
            .entry("responses")
            .or_insert_with(|| json!({}))
            .as_object_mut()
            .expect("responses");
        if route.perm != Perm::Public {
            for status in ["401", "403"] {
                responses.entry(status).or_insert_with(|| json!({}));
            }
        }
        responses.entry("default").or_insert_with(|| json!({}));
        for (status, answer) in responses.iter_mut() {
            if !(status.starts_with('4') || status.starts_with('5') || status == "default") {
                continue;
            }
            let answer = answer.as_object_mut().expect("response");
            if answer
                .get("description")
                .and_then(Value::as_str)
                .unwrap_or("")
                .is_empty()
            {
                answer.insert("description".into(), json!(error_description(status)));
            }
            answer.entry("content").or_insert_with(|| error_ref.clone());
        }
        paths
            .entry(route.path.to_string())
            .or_insert_with(|| json!({}))
            .as_object_mut()
            .expect("path item")
            .insert(method, op);
    }
    json!({
        "openapi": "3.1.0",
        "info": {
            "title": "gridscada API",
            "version": env!("CARGO_PKG_VERSION"),
            "description": DESCRIPTION,
        },
        "servers": [{"url": "/"}],
        "tags": tags.into_iter().map(|name| json!({"name": name})).collect::<Vec<_>>(),
        "paths": paths,
        "components": {
            "schemas": schemas,
            "securitySchemes": {
                "session": {"type": "apiKey", "in": "cookie", "name": crate::auth::COOKIE}
            }
        }
    })
}
