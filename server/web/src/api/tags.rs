//! Tags: list, read, and confirmed writes.

use axum::extract::{Path, Query, State};
use axum::http::StatusCode;
use axum::{Extension, Json};
use gridscada_config::Role;
use gridscada_tagdb::{Sample, TagId, TagMeta, Value, WriteError};
use serde::{Deserialize, Serialize};

use crate::api::audit;
use crate::auth::Principal;
use crate::error::{ApiError, ApiResult};
use crate::WebState;

/// A tag as the API shows it.
#[derive(Serialize)]
pub struct TagView {
    pub name: String,
    pub description: String,
    pub units: String,
    pub kind: gridscada_tagdb::ValueKind,
    pub writable: bool,
    /// The least role that may write it, if writable.
    pub write_role: Option<Role>,
    #[serde(flatten)]
    pub sample: Sample,
}

impl WebState {
    pub fn write_role(&self, name: &str) -> Option<Role> {
        self.plant
            .tag(name)
            .filter(|t| *t.writable.get_ref())
            .and_then(|t| t.write_role.as_ref().map(|r| *r.get_ref()))
    }

    pub fn tag_view(&self, id: TagId, meta: &TagMeta) -> Option<TagView> {
        let sample = self.db.get(id)?;
        Some(TagView {
            name: meta.name.to_string(),
            description: meta.description.clone(),
            units: meta.units.clone(),
            kind: meta.kind,
            writable: meta.writable,
            write_role: self.write_role(&meta.name),
            sample,
        })
    }
}

#[derive(Deserialize)]
pub struct ListQuery {
    #[serde(default)]
    pub prefix: String,
}

#[derive(Serialize)]
pub struct TagList {
    pub tags: Vec<TagView>,
}

pub async fn list(State(s): State<WebState>, Query(q): Query<ListQuery>) -> Json<TagList> {
    let tags =
        s.db.all_meta()
            .filter(|(_, m)| m.name.starts_with(q.prefix.as_str()))
            .filter_map(|(id, m)| s.tag_view(id, m))
            .collect();
    Json(TagList { tags })
}

pub async fn one(State(s): State<WebState>, Path(name): Path<String>) -> ApiResult<Json<TagView>> {
    let id =
        s.db.id(&name)
            .ok_or_else(|| ApiError::not_found(format!("no tag named '{name}'")))?;
    let meta =
        s.db.meta(id)
            .ok_or_else(|| ApiError::not_found(format!("no tag named '{name}'")))?;
    s.tag_view(id, meta)
        .map(Json)
        .ok_or_else(|| ApiError::not_found(format!("no tag named '{name}'")))
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WriteBody {
    pub value: Value,
}

/// Writes a tag and answers once the device's read-back confirms it.
pub async fn write(
    State(s): State<WebState>,
    Extension(who): Extension<Principal>,
    Path(name): Path<String>,
    body: Result<Json<WriteBody>, axum::extract::rejection::JsonRejection>,
) -> ApiResult<Json<TagView>> {
    let Json(body) = body.map_err(|e| ApiError::bad_request(e.body_text()))?;
    let id =
        s.db.id(&name)
            .ok_or_else(|| ApiError::not_found(format!("no tag named '{name}'")))?;
    let meta =
        s.db.meta(id)
            .cloned()
            .ok_or_else(|| ApiError::not_found(format!("no tag named '{name}'")))?;
    let Some(required) = s.write_role(&name) else {
        return Err(ApiError::forbidden(format!("tag '{name}' is read-only")));
    };
    if who.role < required {
        return Err(ApiError::forbidden(format!(
            "writing '{name}' needs the {} role or above; you are {}",
            required.label(),
            who.role.label()
        )));
    }
    let value = body.value.coerce(meta.kind).ok_or_else(|| {
        ApiError::bad_request(format!(
            "{} is not a valid {:?} value for '{name}'",
            body.value, meta.kind
        ))
    })?;
    let writer = s
        .writer
        .clone()
        .ok_or_else(|| ApiError::unavailable("field I/O is not running"))?;
    let old =
        s.db.get(id)
            .map(|o| o.value.to_string())
            .unwrap_or_default();
    match writer.write(&name, value.clone()).await {
        Ok(_) => {
            audit(
                &s,
                &who,
                "write",
                &name,
                format!("{} wrote {name}: {old} -> {value}", who.audit_name()),
            )
            .await;
            s.tag_view(id, &meta)
                .map(Json)
                .ok_or_else(|| ApiError::not_found(format!("no tag named '{name}'")))
        }
        Err(e) => {
            audit(
                &s,
                &who,
                "write_failed",
                &name,
                format!("{} could not write {name} = {value}: {e}", who.audit_name()),
            )
            .await;
            Err(write_error(e))
        }
    }
}

pub fn write_error(e: WriteError) -> ApiError {
    let status = match &e {
        WriteError::UnknownTag(_) => StatusCode::NOT_FOUND,
        WriteError::ReadOnly(_) => StatusCode::FORBIDDEN,
        WriteError::BadValue { .. } => StatusCode::BAD_REQUEST,
        WriteError::Device { .. } | WriteError::Mismatch { .. } => StatusCode::BAD_GATEWAY,
        WriteError::Timeout(_) => StatusCode::GATEWAY_TIMEOUT,
        WriteError::Closed => StatusCode::SERVICE_UNAVAILABLE,
    };
    ApiError::new(status, "write_failed", e.to_string())
}
