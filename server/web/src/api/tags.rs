//! Tags: list, read, and confirmed writes.

use axum::extract::{Path, Query, State};
use axum::http::StatusCode;
use axum::{Extension, Json};
use gridscada_config::{DataType, Dnp3Command, Endian, RegisterKind, Role};
use gridscada_tagdb::{Sample, TagId, TagMeta, Value, WriteError};
use serde::{Deserialize, Serialize};
use utoipa::{IntoParams, ToSchema};

use crate::api::refused_unaudited;
use crate::auth::Principal;
use crate::command::{write_tag, WriteRefused};
use crate::error::{ApiError, ApiResult};
use crate::openapi::shapes;
use crate::WebState;

/// A tag as the API shows it (its schema: [`shapes::Tag`], which spells out
/// the flattened sample).
#[derive(Serialize)]
pub struct TagView {
    pub name: String,
    pub description: String,
    pub units: String,
    pub kind: gridscada_tagdb::ValueKind,
    pub writable: bool,
    /// The least role that may write it, if writable.
    pub write_role: Option<Role>,
    /// Where the value comes from; `None` for derived tags (device status,
    /// sequence and dispatch tags).
    pub source: Option<TagSource>,
    /// Words for the tag's values (`states` in the configuration).
    pub states: Option<std::collections::BTreeMap<String, String>>,
    /// The engineering limits a write must respect, for a writable tag
    /// with any (`Plant::write_limits`); the write dialog shows them.
    pub limits: Option<WriteLimits>,
    /// Decimals the HMI shows the value with: the tag's `decimals`, else
    /// `[hmi] decimals` for an analog value, 0 for an integer; `None` for
    /// a bool or text.
    pub decimals: Option<u8>,
    #[serde(flatten)]
    pub sample: Sample,
}

/// A writable tag's engineering limits; either bound may be open (null).
#[derive(Serialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct WriteLimits {
    pub min: Option<f64>,
    pub max: Option<f64>,
}

/// The field register behind a tag.
#[derive(Serialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct TagSource {
    pub device: String,
    /// The device's protocol: tcp or rtu (Modbus), iec104, dnp3
    pub protocol: String,
    /// The Modbus table; null for a tag of another protocol
    #[schema(value_type = Option<shapes::RegisterKind>, inline, required = true)]
    pub table: Option<RegisterKind>,
    /// The Modbus address; null for a tag of another protocol
    #[schema(required = true)]
    pub address: Option<u32>,
    /// The IEC 104 point: type, information object address, command
    #[schema(required = true)]
    pub iec104: Option<Iec104Source>,
    /// The DNP3 point: type, index, command
    #[schema(required = true)]
    pub dnp3: Option<Dnp3Source>,
    #[schema(required = true)]
    pub bit: Option<u8>,
    #[schema(value_type = String)]
    pub data_type: DataType,
    #[schema(value_type = shapes::Endian, inline)]
    pub word_order: Endian,
    #[schema(value_type = shapes::Endian, inline)]
    pub byte_order: Endian,
    pub scale: f64,
    pub offset: f64,
    /// The device clock tag whose reading stamps this tag's samples; null:
    /// the time the reply arrived
    #[schema(required = true)]
    pub time_tag: Option<String>,
}

/// Where an IEC 104 tag is read and commanded.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct Iec104Source {
    /// Monitoring type without suffix, e.g. M_DP
    pub point: String,
    pub ioa: u32,
    /// Command type, e.g. C_DC; null: read-only
    #[schema(required = true)]
    pub command: Option<String>,
    #[schema(required = true)]
    pub command_ioa: Option<u32>,
    /// Select before operate
    pub select: bool,
}

/// Where a DNP3 tag is read and commanded.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct Dnp3Source {
    /// Point type, e.g. double_bit, analog_input
    pub point: String,
    pub index: u16,
    /// crob or analog_output; null: read-only
    #[schema(required = true)]
    pub command: Option<String>,
    #[schema(required = true)]
    pub command_index: Option<u16>,
    /// Select before operate
    pub select: bool,
    /// What a CROB does with true/false: latch, pulse or trip_close; null
    /// for an analog output or a read-only tag
    #[schema(required = true)]
    pub op: Option<String>,
}

impl WebState {
    pub fn write_role(&self, name: &str) -> Option<Role> {
        match self.plant.tag(name) {
            Some(t) => t
                .writable
                .get_ref()
                .then(|| t.write_role.as_ref().map(|r| *r.get_ref()))
                .flatten(),
            // A remote tag of a central Sparkplug host: writable as its
            // birth says, by `[mqtt.host] write_role`.
            None => {
                let host = self.plant.mqtt.as_ref()?.host.as_ref()?;
                let id = self.db.id(name)?;
                self.db
                    .meta(id)
                    .filter(|m| m.writable)
                    .map(|_| *host.write_role.get_ref())
            }
        }
    }

    pub fn tag_view(&self, id: TagId, meta: &TagMeta) -> Option<TagView> {
        let sample = self.db.get(id)?;
        let config = self.plant.tag(&meta.name);
        Some(TagView {
            name: meta.name.to_string(),
            description: meta.description.clone(),
            units: meta.units.clone(),
            kind: meta.kind,
            writable: meta.writable,
            write_role: self.write_role(&meta.name),
            source: config.map(|t| TagSource {
                device: t.device.get_ref().clone(),
                protocol: self
                    .plant
                    .device(t.device.get_ref())
                    .map(|d| d.protocol.label())
                    .unwrap_or_default()
                    .to_string(),
                table: t.kind.as_ref().map(|k| *k.get_ref()),
                address: t.address.as_ref().map(|a| *a.get_ref()),
                iec104: t.iec104.as_ref().map(|p| Iec104Source {
                    point: p.point.get_ref().label().to_string(),
                    ioa: *p.ioa.get_ref(),
                    command: p.command.as_ref().map(|c| c.get_ref().label().to_string()),
                    command_ioa: p.command.as_ref().map(|_| p.command_ioa()),
                    select: p.select,
                }),
                dnp3: t.dnp3.as_ref().map(|p| {
                    let command = p.command.as_ref().map(|c| *c.get_ref());
                    Dnp3Source {
                        point: p.point.get_ref().label().to_string(),
                        index: *p.index.get_ref(),
                        command: command.map(|c| c.label().to_string()),
                        command_index: command.map(|_| p.command_index()),
                        select: p.select,
                        op: (command == Some(Dnp3Command::Crob))
                            .then(|| p.op().label().to_string()),
                    }
                }),
                bit: t.bit.as_ref().map(|b| *b.get_ref()),
                data_type: t.data_type(),
                word_order: t.word_order,
                byte_order: t.byte_order,
                scale: *t.scale.get_ref(),
                offset: t.offset,
                time_tag: self
                    .plant
                    .device(t.device.get_ref())
                    .and_then(|d| t.time_tag(d))
                    .map(str::to_owned),
            }),
            states: config.and_then(|t| t.states.as_ref().map(|s| s.get_ref().clone())),
            limits: meta
                .writable
                .then(|| self.plant.write_limits(&meta.name))
                .filter(|(min, max)| min.is_some() || max.is_some())
                .map(|(min, max)| WriteLimits { min, max }),
            decimals: self
                .plant
                .hmi
                .decimals_for(meta.kind, config.and_then(|t| t.decimals())),
            sample,
        })
    }
}

/// Most tags one page may hold.
const MAX_PAGE: usize = 1000;

#[derive(Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct ListQuery {
    /// Only tags whose name starts with this
    #[serde(default)]
    #[param(required = false)]
    pub prefix: String,
    /// Only tags whose name or description contains this, ignoring case
    #[serde(default)]
    #[param(required = false, max_length = 256)]
    pub search: String,
    /// Skip this many matches
    #[serde(default)]
    #[param(required = false)]
    pub offset: usize,
    /// Page size; every match when absent
    #[param(minimum = 1, maximum = 1000)]
    pub limit: Option<usize>,
}

#[derive(Serialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct TagList {
    #[schema(value_type = Vec<shapes::Tag>)]
    pub tags: Vec<TagView>,
    /// Tags that match, before paging.
    pub total: usize,
    pub offset: usize,
    #[schema(required = true)]
    pub limit: Option<usize>,
}

/// The tags the caller may read, filtered and paged on the server so a
/// plant of 100,000 tags stays light in the browser.
#[utoipa::path(get, path = "/api/tags", tag = "tags",
    summary = "List the tags the caller may read (filtered and paged)",
    params(ListQuery),
    responses((status = 200, description = "OK", body = TagList), (status = 400)))]
pub async fn list(
    State(s): State<WebState>,
    Extension(who): Extension<Principal>,
    Query(q): Query<ListQuery>,
) -> ApiResult<Json<TagList>> {
    if let Some(l) = q.limit {
        if !(1..=MAX_PAGE).contains(&l) {
            return Err(ApiError::bad_request(format!(
                "limit must be 1 to {MAX_PAGE}"
            )));
        }
    }
    if q.search.chars().count() > 256 || q.prefix.chars().count() > 1024 {
        return Err(ApiError::bad_request(
            "search may have at most 256 characters, prefix 1024",
        ));
    }
    let readable = s.readable(&who);
    let needle = q.search.to_lowercase();
    let matching = s.db.all_meta().filter(|(_, m)| {
        m.name.starts_with(q.prefix.as_str())
            && readable.may_read(&m.name)
            && (needle.is_empty()
                || contains_ignoring_case(&m.name, &needle)
                || contains_ignoring_case(&m.description, &needle))
    });
    let mut total = 0;
    let mut tags = vec![];
    let end = q.limit.map(|l| q.offset.saturating_add(l));
    for (id, m) in matching {
        if total >= q.offset && end.is_none_or(|e| total < e) {
            tags.extend(s.tag_view(id, m));
        }
        total += 1;
    }
    Ok(Json(TagList {
        tags,
        total,
        offset: q.offset,
        limit: q.limit,
    }))
}

/// Whether `hay` contains `needle` (already lowercase), ignoring case; no
/// allocation for ASCII text, which searching 100,000 tags per keystroke needs.
fn contains_ignoring_case(hay: &str, needle: &str) -> bool {
    if hay.is_ascii() && needle.is_ascii() {
        let (h, n) = (hay.as_bytes(), needle.as_bytes());
        return n.len() <= h.len() && h.windows(n.len()).any(|w| w.eq_ignore_ascii_case(n));
    }
    hay.to_lowercase().contains(needle)
}

#[derive(Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct TreeQuery {
    /// Empty for the roots, or a branch name followed by a dot
    #[serde(default)]
    #[param(required = false, max_length = 1024)]
    pub prefix: String,
}

/// One node under a prefix of the dot-separated tag tree.
#[derive(Serialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct TreeNode {
    /// The full name of the node (a tag name, a branch, or both).
    pub name: String,
    /// Its last segment.
    pub label: String,
    /// Readable tags at or under it.
    #[schema(minimum = 1)]
    pub count: usize,
    pub is_tag: bool,
    pub has_children: bool,
}

/// The children of a node of the tag tree. `prefix` is "" for the roots, or
/// The children of a tree node.
#[derive(Serialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct TreeLevel {
    pub prefix: String,
    #[schema(inline)]
    pub children: Vec<TreeNode>,
}

/// a branch's name followed by a dot.
#[utoipa::path(get, path = "/api/tags/tree", tag = "tags",
    summary = "Children of a node of the dot-separated tag tree",
    params(TreeQuery),
    responses((status = 200, description = "OK", body = inline(TreeLevel)), (status = 400)))]
pub async fn tree(
    State(s): State<WebState>,
    Extension(who): Extension<Principal>,
    Query(q): Query<TreeQuery>,
) -> ApiResult<Json<TreeLevel>> {
    if q.prefix.chars().count() > 1024 {
        return Err(ApiError::bad_request(
            "prefix may have at most 1024 characters",
        ));
    }
    let readable = s.readable(&who);
    let mut nodes: std::collections::BTreeMap<&str, TreeNode> = Default::default();
    for (_, m) in s.db.all_meta() {
        let Some(rest) = m.name.strip_prefix(q.prefix.as_str()) else {
            continue;
        };
        if rest.is_empty() || !readable.may_read(&m.name) {
            continue;
        }
        let (label, deeper) = match rest.split_once('.') {
            Some((l, _)) => (l, true),
            None => (rest, false),
        };
        let name = &m.name[..q.prefix.len() + label.len()];
        let node = nodes.entry(name).or_insert_with(|| TreeNode {
            name: name.to_string(),
            label: label.to_string(),
            count: 0,
            is_tag: false,
            has_children: false,
        });
        node.count += 1;
        node.is_tag |= !deeper;
        node.has_children |= deeper;
    }
    let children: Vec<TreeNode> = nodes.into_values().collect();
    Ok(Json(TreeLevel {
        prefix: q.prefix,
        children,
    }))
}

#[utoipa::path(get, path = "/api/tags/{name}", tag = "tags", summary = "One tag",
    params(("name" = String, Path, description = "Tag name", min_length = 1)),
    responses((status = 200, description = "OK", body = shapes::Tag), (status = 400), (status = 404)))]
pub async fn one(
    State(s): State<WebState>,
    Extension(who): Extension<Principal>,
    Path(name): Path<String>,
) -> ApiResult<Json<TagView>> {
    let not_found = || ApiError::not_found(format!("no tag named '{}'", name.escape_debug()));
    let id = s.db.id(&name).ok_or_else(not_found)?;
    let meta = s.db.meta(id).ok_or_else(not_found)?;
    if !s.readable(&who).may_read(&name) {
        return Err(ApiError::forbidden(format!(
            "tag '{}' is on no screen your group may open",
            name.escape_debug()
        )));
    }
    s.tag_view(id, meta).map(Json).ok_or_else(not_found)
}

#[derive(Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct WriteBody {
    #[schema(value_type = shapes::TagValue)]
    pub value: Value,
}

/// Writes a tag and answers once the device's read-back confirms it.
#[utoipa::path(post, path = "/api/tags/{name}/write", tag = "tags",
    summary = "Write a tag; answers once the device confirms",
    params(("name" = String, Path, description = "Tag name", min_length = 1)),
    request_body = WriteBody,
    responses(
        (status = 200, description = "OK", body = shapes::Tag),
        (status = 400), (status = 404),
        (status = 502, description = "The device did not take the write"),
        (status = 503),
        (status = 504, description = "The write timed out"),
    ))]
pub async fn write(
    State(s): State<WebState>,
    Extension(who): Extension<Principal>,
    Path(name): Path<String>,
    body: Result<Json<WriteBody>, axum::extract::rejection::JsonRejection>,
) -> ApiResult<Json<TagView>> {
    let Json(body) = body.map_err(|e| ApiError::bad_request(e.body_text()))?;
    write_tag(&s, &who, &name, body.value, "")
        .await
        .map_err(write_refused)?;
    s.db.id(&name)
        .and_then(|id| s.tag_view(id, s.db.meta(id)?))
        .map(Json)
        .ok_or_else(|| ApiError::not_found(format!("no tag named '{name}'")))
}

/// A refused or failed write as the HTTP API answers it.
pub fn write_refused(e: WriteRefused) -> ApiError {
    match e {
        WriteRefused::UnknownTag(why) => ApiError::not_found(why),
        WriteRefused::Forbidden(why) => ApiError::forbidden(why),
        WriteRefused::BadValue(why) => ApiError::bad_request(why),
        WriteRefused::NoFieldIo => ApiError::unavailable("field I/O is not running"),
        WriteRefused::Unaudited(why) => refused_unaudited(why),
        WriteRefused::Failed(e) => write_error(e),
    }
}

pub fn write_error(e: WriteError) -> ApiError {
    let status = match &e {
        WriteError::UnknownTag(_) => StatusCode::NOT_FOUND,
        WriteError::ReadOnly(_) => StatusCode::FORBIDDEN,
        WriteError::BadValue { .. } | WriteError::OutOfLimits { .. } => StatusCode::BAD_REQUEST,
        WriteError::Device { .. } | WriteError::Mismatch { .. } => StatusCode::BAD_GATEWAY,
        WriteError::Timeout(_) => StatusCode::GATEWAY_TIMEOUT,
        WriteError::Closed => StatusCode::SERVICE_UNAVAILABLE,
        WriteError::NotActive(_) => StatusCode::SERVICE_UNAVAILABLE,
        WriteError::Blocked(_) => StatusCode::CONFLICT,
    };
    let code = match &e {
        // The rule's own id: safety_tag, closing_onto_earthed, ...
        WriteError::Blocked(b) => b.rule,
        WriteError::OutOfLimits { .. } => "out_of_limits",
        WriteError::BadValue { .. } => "bad_value",
        WriteError::NotActive(_) => "standby",
        _ => "write_failed",
    };
    ApiError::new(status, code, e.to_string())
}
