//! The switching network: the model as the HMI draws it, the live topology
//! (which section is energised, dead, earthed or unknown, and why), and the
//! preview of one switching operation with the interlocks that refuse it.

use std::collections::BTreeMap;
use std::sync::Arc;

use axum::extract::{Path, Query, State};
use axum::http::StatusCode;
use axum::{Extension, Json};
use gridscada_config::Role;
use gridscada_network::driver::unknown_reason;
use gridscada_network::model::ParallelPermission;
use gridscada_network::{
    compute, interlocks, preview, Live, Network, Operation, Parallel, Pos, RuleId, Topology,
};
use serde::{Deserialize, Serialize};
use tokio::sync::watch;
use utoipa::{IntoParams, ToSchema};

use crate::auth::Principal;
use crate::error::{ApiError, ApiResult};
use crate::WebState;

/// The switching network and its live topology, as the web layer sees them.
#[derive(Clone)]
pub struct NetworkView {
    pub network: Arc<Network>,
    pub live: watch::Receiver<Arc<Live>>,
    /// The standing safety tags the switching guard enforces.
    pub tags: gridscada_network::SafetyTags,
    /// Select-before-operate reservations, which the guard enforces too.
    pub selections: gridscada_network::Selections,
}

pub(crate) fn view(s: &WebState) -> ApiResult<&NetworkView> {
    s.components
        .network
        .as_ref()
        .ok_or_else(|| ApiError::not_found("this plant has no switching network ([network])"))
}

#[derive(Serialize, ToSchema)]
pub struct SectionInfo {
    pub id: String,
    /// Nominal voltage, kV, where known.
    pub kv: Option<f64>,
    pub busbar: bool,
    pub customers: u64,
    /// Its connectivity nodes.
    pub nodes: Vec<String>,
    /// The tag that carries its state.
    pub state_tag: String,
}

#[derive(Serialize, ToSchema)]
pub struct SwitchInfo {
    pub id: String,
    pub name: String,
    /// circuit_breaker, load_break_switch, disconnector, earth_switch, fuse.
    pub kind: String,
    pub section: String,
    /// The section on its other side; none for an earth switch.
    pub other_section: Option<String>,
    /// "open" or "closed".
    pub normally: String,
    /// The tags its position is read from.
    pub status_tags: Vec<String>,
    /// The tag it is commanded through, if it can be.
    pub command_tag: Option<String>,
    /// Only one operation can be commanded ("close" for an ELCB's reset).
    pub command_only: Option<String>,
}

#[derive(Serialize, ToSchema)]
pub struct TransformerInfo {
    pub id: String,
    pub section: String,
    pub other_section: String,
}

#[derive(Serialize, ToSchema)]
pub struct SourceInfo {
    pub id: String,
    pub name: String,
    pub section: String,
    pub group: String,
}

#[derive(Serialize, ToSchema)]
pub struct LoadInfo {
    pub id: String,
    pub section: String,
    pub customers: u32,
}

/// The network model.
#[derive(Serialize, ToSchema)]
pub struct NetworkModel {
    pub prefix: String,
    pub select_timeout_s: f64,
    pub sections: Vec<SectionInfo>,
    pub switches: Vec<SwitchInfo>,
    pub transformers: Vec<TransformerInfo>,
    pub sources: Vec<SourceInfo>,
    pub loads: Vec<LoadInfo>,
    /// The layout an administrator adjusted in the screen editor: the drawn
    /// screen [`LAYOUT_SCREEN`], whose lines bound to a section place that
    /// section; none while no such screen is saved (the automatic layout).
    pub layout: Option<NetworkLayout>,
}

/// The drawn screen whose lines place the network screen's sections.
pub const LAYOUT_SCREEN: &str = "network";

/// Where the drawn screen [`LAYOUT_SCREEN`] puts sections.
#[derive(Serialize, ToSchema)]
pub struct NetworkLayout {
    pub screen: String,
    pub version: i64,
    pub width: i64,
    pub height: i64,
    /// Section id -> the box of the line bound to it (the first, if several).
    pub sections: BTreeMap<String, PlacedSection>,
}

#[derive(Serialize, ToSchema)]
pub struct PlacedSection {
    pub x: i64,
    pub y: i64,
    pub w: i64,
    pub h: i64,
}

/// The sections the drawn layout screen places, by their state tags.
fn drawn_layout(s: &WebState, net: &gridscada_network::Network) -> Option<NetworkLayout> {
    let screen = s.screens.get(LAYOUT_SCREEN)?;
    // A line places the section whose state tag it is bound to.
    let by_state_tag: BTreeMap<String, &str> = net
        .model
        .sections
        .iter()
        .map(|x| {
            (
                gridscada_network::section_tag(&net.prefix, &x.id, "State"),
                x.id.as_str(),
            )
        })
        .collect();
    let mut sections = BTreeMap::new();
    for e in &screen.elements {
        if let gridscada_config::screen::ElementKind::Line {
            section_tag: Some(tag),
            ..
        } = &e.kind
        {
            if let Some(id) = by_state_tag.get(tag.as_str()) {
                sections.entry(id.to_string()).or_insert(PlacedSection {
                    x: e.x,
                    y: e.y,
                    w: e.w,
                    h: e.h,
                });
            }
        }
    }
    Some(NetworkLayout {
        screen: screen.id.clone(),
        version: screen.version,
        width: screen.width,
        height: screen.height,
        sections,
    })
}

#[utoipa::path(get, path = "/api/network", tag = "network", summary = "The switching network model",
    responses((status = 200, description = "OK", body = NetworkModel), (status = 404, description = "No [network]")))]
pub async fn model(State(s): State<WebState>) -> ApiResult<Json<NetworkModel>> {
    let v = view(&s)?;
    let net = &v.network;
    let m = &net.model;
    let sec = |i: u32| m.sections[i as usize].id.clone();
    Ok(Json(NetworkModel {
        prefix: net.prefix.clone(),
        select_timeout_s: net.select_timeout.as_secs_f64(),
        sections: m
            .sections
            .iter()
            .map(|x| SectionInfo {
                id: x.id.clone(),
                kv: x.kv,
                busbar: x.busbar,
                customers: x.customers,
                nodes: x.nodes.iter().map(|&n| m.nodes[n].id.clone()).collect(),
                state_tag: gridscada_network::section_tag(&net.prefix, &x.id, "State"),
            })
            .collect(),
        switches: m
            .switches
            .iter()
            .enumerate()
            .map(|(i, w)| {
                use gridscada_config::{CommandBinding, Normally, StatusBinding};
                SwitchInfo {
                    id: w.id.clone(),
                    name: w.name.clone(),
                    kind: w.kind.as_str().into(),
                    section: sec(w.a),
                    other_section: w.b.map(sec),
                    normally: if w.normally_closed { "closed" } else { "open" }.into(),
                    status_tags: match &net.status[i] {
                        None => vec![],
                        Some(StatusBinding::Tag(t)) => vec![t.clone()],
                        Some(StatusBinding::Pair { open, closed }) => {
                            vec![open.clone(), closed.clone()]
                        }
                    },
                    command_tag: net.command[i].as_ref().map(|c| c.tag().to_string()),
                    command_only: match &net.command[i] {
                        Some(CommandBinding::Pulse { pulse, .. }) => Some(
                            if *pulse == Normally::Closed {
                                "close"
                            } else {
                                "open"
                            }
                            .into(),
                        ),
                        _ => None,
                    },
                }
            })
            .collect(),
        transformers: m
            .transformers
            .iter()
            .map(|t| TransformerInfo {
                id: t.id.clone(),
                section: sec(t.a),
                other_section: sec(t.b),
            })
            .collect(),
        sources: m
            .sources
            .iter()
            .map(|x| SourceInfo {
                id: x.id.clone(),
                name: x.name.clone(),
                section: sec(x.section),
                group: m.groups[x.group].clone(),
            })
            .collect(),
        loads: m
            .loads
            .iter()
            .map(|l| LoadInfo {
                id: l.id.clone(),
                section: sec(l.section),
                customers: l.customers,
            })
            .collect(),
        layout: drawn_layout(&s, net),
    }))
}

#[derive(Serialize, ToSchema)]
pub struct SectionState {
    pub id: String,
    /// ENERGISED, DEAD, EARTHED, UNKNOWN or ENERGISED+EARTHED.
    pub state: String,
    /// The sources in service feeding it.
    pub sources: Vec<String>,
    /// Why it is unknown, in words.
    pub unknown_because: Option<String>,
}

#[derive(Serialize, ToSchema)]
pub struct SwitchPosition {
    pub id: String,
    /// OPEN, CLOSED or UNKNOWN.
    pub position: String,
}

#[derive(Serialize, ToSchema)]
pub struct ParallelInfo {
    pub sources: Vec<String>,
    pub groups: Vec<String>,
    /// allowed, overridable or forbidden.
    pub permission: String,
    /// False: only through a device or source of unknown state.
    pub certain: bool,
}

/// The live topology.
#[derive(Serialize, ToSchema)]
pub struct TopologyInfo {
    /// Counts recomputes.
    pub version: u64,
    pub sections: Vec<SectionState>,
    pub switches: Vec<SwitchPosition>,
    pub loops: usize,
    pub parallels: Vec<ParallelInfo>,
    pub customers_off: u64,
    pub customers_unknown: u64,
}

fn parallel_info(net: &Network, p: &Parallel) -> ParallelInfo {
    let m = &net.model;
    ParallelInfo {
        sources: p.sources.iter().map(|&i| m.sources[i].id.clone()).collect(),
        groups: p.groups.iter().map(|&g| m.groups[g].clone()).collect(),
        permission: match p.permission {
            ParallelPermission::Allowed => "allowed",
            ParallelPermission::Overridable => "overridable",
            ParallelPermission::Forbidden => "forbidden",
        }
        .into(),
        certain: p.certain,
    }
}

fn sections_of(net: &Network, t: &Topology) -> Vec<SectionState> {
    let m = &net.model;
    m.sections
        .iter()
        .enumerate()
        .map(|(i, x)| SectionState {
            id: x.id.clone(),
            state: t.state[i].as_str().into(),
            sources: t
                .sources_of(i as u32)
                .iter()
                .map(|&s| m.sources[s].id.clone())
                .collect(),
            unknown_because: (t.state[i] == gridscada_network::SectionState::Unknown)
                .then(|| unknown_reason(net, t.unknown_because[i])),
        })
        .collect()
}

#[utoipa::path(get, path = "/api/network/topology", tag = "network", summary = "The live topology",
    responses((status = 200, description = "OK", body = TopologyInfo), (status = 404, description = "No [network]")))]
pub async fn topology(State(s): State<WebState>) -> ApiResult<Json<TopologyInfo>> {
    let v = view(&s)?;
    let live = v.live.borrow().clone();
    let net = &v.network;
    let t = &live.topology;
    Ok(Json(TopologyInfo {
        version: live.version,
        sections: sections_of(net, t),
        switches: net
            .model
            .switches
            .iter()
            .zip(&live.inputs.switches)
            .map(|(w, p)| SwitchPosition {
                id: w.id.clone(),
                position: p.as_str().into(),
            })
            .collect(),
        loops: t.loops(),
        parallels: t.parallels.iter().map(|p| parallel_info(net, p)).collect(),
        customers_off: t.customers_off,
        customers_unknown: t.customers_unknown,
    }))
}

#[derive(Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
#[serde(deny_unknown_fields)]
pub struct PreviewQuery {
    /// A switching device's id.
    pub device: String,
    /// "open" or "close".
    pub operation: String,
}

#[derive(Serialize, ToSchema)]
pub struct InterlockInfo {
    /// safety_tag, reserved, closing_onto_earthed, earthing_energised,
    /// disconnector_under_load, forbidden_parallel, state_unknown.
    pub rule: String,
    pub text: String,
    /// A supervisor may override it with a reason.
    pub overridable: bool,
}

impl From<gridscada_network::Interlock> for InterlockInfo {
    fn from(f: gridscada_network::Interlock) -> Self {
        InterlockInfo {
            rule: f.rule.as_str().into(),
            text: f.text,
            overridable: f.overridable,
        }
    }
}

/// How supply changes with an operation: the sections (and their
/// customers) that lose or gain it, and earthing made or removed.
#[derive(Serialize, ToSchema)]
pub struct SupplyChange {
    /// Sections that lose supply, and their customers.
    pub lose_supply: Vec<String>,
    pub customers_lose: u64,
    /// Sections that gain supply, and their customers.
    pub gain_supply: Vec<String>,
    pub customers_gain: u64,
    pub newly_earthed: Vec<String>,
    pub no_longer_earthed: Vec<String>,
}

impl SupplyChange {
    pub(crate) fn of(m: &gridscada_network::Model, p: &gridscada_network::Preview) -> SupplyChange {
        SupplyChange {
            lose_supply: m.section_ids(&p.lose_supply),
            customers_lose: p.customers_lose,
            gain_supply: m.section_ids(&p.gain_supply),
            customers_gain: p.customers_gain,
            newly_earthed: m.section_ids(&p.newly_earthed),
            no_longer_earthed: m.section_ids(&p.no_longer_earthed),
        }
    }
}

/// What one operation would do, on the topology now.
#[derive(Serialize, ToSchema)]
pub struct PreviewInfo {
    pub device: String,
    pub operation: String,
    /// The device's position now.
    pub position: String,
    #[serde(flatten)]
    pub supply: SupplyChange,
    pub becomes_unknown: Vec<String>,
    /// Sources that would run in parallel that do not now.
    pub new_parallels: Vec<ParallelInfo>,
    pub ended_parallels: Vec<ParallelInfo>,
    pub loops_before: usize,
    pub loops_after: usize,
    /// The interlocks that refuse it; empty: allowed.
    pub interlocks: Vec<InterlockInfo>,
}

#[utoipa::path(get, path = "/api/network/preview", tag = "network",
    summary = "What one switching operation would do, and the interlocks that refuse it",
    params(PreviewQuery),
    responses((status = 200, description = "OK", body = PreviewInfo), (status = 400),
        (status = 404, description = "No [network], or no such device")))]
pub async fn preview_operation(
    State(s): State<WebState>,
    Extension(who): Extension<Principal>,
    Query(q): Query<PreviewQuery>,
) -> ApiResult<Json<PreviewInfo>> {
    let v = view(&s)?;
    let i = device_index(v, &q.device)?;
    let op = parse_operation(&q.operation)?;
    Ok(Json(preview_info(v, i, op, &who.audit_name())))
}

fn device_index(v: &NetworkView, device: &str) -> ApiResult<usize> {
    v.network
        .model
        .switch(device)
        .ok_or_else(|| ApiError::not_found(format!("no switching device '{device}'")))
}

fn parse_operation(s: &str) -> ApiResult<Operation> {
    match s {
        "open" => Ok(Operation::Open),
        "close" => Ok(Operation::Close),
        other => Err(ApiError::bad_request(format!(
            "operation '{other}': expected open or close"
        ))),
    }
}

/// What `op` of device `i` would do on the live topology, with everything
/// that would refuse it for `user`: a safety tag, another operator's
/// selection, the interlocks.
fn preview_info(v: &NetworkView, i: usize, op: Operation, user: &str) -> PreviewInfo {
    let net = &v.network;
    let m = &net.model;
    let device = &m.switches[i];
    let live = v.live.borrow().clone();
    let before = &live.topology;
    let after = compute(m, &live.inputs.with(i, op.target()));
    let p = preview(m, before, &after);
    let mut refusals: Vec<InterlockInfo> = vec![];
    if let Some(tag) = v.tags.blocking(&device.id, op) {
        refusals.push(InterlockInfo {
            rule: RuleId::SafetyTag.as_str().into(),
            text: tag.describe(),
            overridable: false,
        });
    }
    if let Some(held) = v.selections.held(i).filter(|h| h.user != user) {
        refusals.push(InterlockInfo {
            rule: RuleId::Reserved.as_str().into(),
            text: held.describe(),
            overridable: false,
        });
    }
    refusals.extend(
        interlocks(m, &live.inputs, before, &after, &p, i, op)
            .into_iter()
            .map(InterlockInfo::from),
    );
    PreviewInfo {
        device: device.id.clone(),
        operation: op.as_str().into(),
        position: live
            .inputs
            .switches
            .get(i)
            .copied()
            .unwrap_or(Pos::Unknown)
            .as_str()
            .into(),
        supply: SupplyChange::of(m, &p),
        becomes_unknown: m.section_ids(&p.becomes_unknown),
        new_parallels: p
            .new_parallels
            .iter()
            .map(|x| parallel_info(net, x))
            .collect(),
        ended_parallels: p
            .ended_parallels
            .iter()
            .map(|x| parallel_info(net, x))
            .collect(),
        loops_before: p.loops_before,
        loops_after: p.loops_after,
        interlocks: refusals,
    }
}

/// A select-before-operate selection.
#[derive(Serialize, ToSchema)]
pub struct SelectionInfo {
    pub id: u64,
    pub device: String,
    pub device_name: String,
    /// "open" or "close".
    pub operation: String,
    /// Who holds it.
    pub user: String,
    #[schema(value_type = crate::openapi::shapes::Timestamp)]
    pub selected_at: gridscada_tagdb::Timestamp,
    /// It lapses then unless executed or cancelled.
    #[schema(value_type = crate::openapi::shapes::Timestamp)]
    pub expires_at: gridscada_tagdb::Timestamp,
    /// What the operation will do, as of the select (only to its holder).
    pub preview: Option<PreviewInfo>,
    /// The supervisor who overrode its overridable interlocks, and why.
    pub override_by: Option<String>,
    pub override_reason: Option<String>,
}

fn selection_info(
    v: &NetworkView,
    sel: &gridscada_network::Selection,
    preview: Option<PreviewInfo>,
) -> SelectionInfo {
    SelectionInfo {
        id: sel.id,
        device: sel.device_id.clone(),
        device_name: v.network.model.switches[sel.device].name.clone(),
        operation: sel.operation.as_str().into(),
        user: sel.user.clone(),
        selected_at: sel.selected_at,
        expires_at: sel.expires_at,
        preview,
        override_by: sel.overridden.as_ref().map(|o| o.by.clone()),
        override_reason: sel.overridden.as_ref().map(|o| o.reason.clone()),
    }
}

#[derive(Serialize, ToSchema)]
pub struct SelectionList {
    pub selections: Vec<SelectionInfo>,
    /// How long a selection stands, seconds.
    pub timeout_s: f64,
}

#[utoipa::path(get, path = "/api/switching/selections", tag = "network",
    summary = "Standing select-before-operate selections: which device each operator holds",
    responses((status = 200, description = "OK", body = SelectionList),
        (status = 404, description = "No [network]")))]
pub async fn selections(State(s): State<WebState>) -> ApiResult<Json<SelectionList>> {
    let v = view(&s)?;
    Ok(Json(SelectionList {
        selections: v
            .selections
            .all()
            .iter()
            .map(|x| selection_info(v, x, None))
            .collect(),
        timeout_s: v.selections.timeout().as_secs_f64(),
    }))
}

#[derive(Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct SelectBody {
    /// A switching device's id.
    pub device: String,
    /// "open" or "close".
    pub operation: String,
}

/// The command that performs `op` of device `i`: its tag and the value.
fn command_of(
    v: &NetworkView,
    i: usize,
    op: Operation,
) -> ApiResult<(String, gridscada_tagdb::Value)> {
    use gridscada_config::{CommandBinding, Normally};
    let name = &v.network.model.switches[i].name;
    let on = match v.network.command[i].as_ref() {
        None => {
            return Err(ApiError::new(
                StatusCode::CONFLICT,
                "not_commandable",
                format!("{name} has no command tag: it is operated on site"),
            ))
        }
        Some(CommandBinding::Tag(_)) => op == Operation::Close,
        Some(CommandBinding::Pulse { pulse, .. }) => {
            let only = match pulse {
                Normally::Closed => Operation::Close,
                Normally::Open => Operation::Open,
            };
            if op != only {
                return Err(ApiError::new(
                    StatusCode::CONFLICT,
                    "not_commandable",
                    format!("{name} can only be commanded to {}", only.as_str()),
                ));
            }
            true
        }
    };
    let tag = v.network.command[i].as_ref().map(|c| c.tag().to_string());
    Ok((tag.unwrap_or_default(), gridscada_tagdb::Value::Bool(on)))
}

#[utoipa::path(post, path = "/api/switching/selections", tag = "network",
    summary = "Select one operation of a switching device (reserves it for you) and preview it",
    request_body = SelectBody,
    responses((status = 201, description = "Selected", body = SelectionInfo), (status = 400),
        (status = 403, description = "You may not command this device"),
        (status = 404, description = "No [network], or no such device"),
        (status = 409, description = "Another operator holds it (reserved), or it has no command")))]
pub async fn select(
    State(s): State<WebState>,
    Extension(who): Extension<Principal>,
    body: Result<Json<SelectBody>, axum::extract::rejection::JsonRejection>,
) -> ApiResult<(StatusCode, Json<SelectionInfo>)> {
    let Json(b) = body.map_err(|e| ApiError::bad_request(e.body_text()))?;
    let v = view(&s)?;
    let i = device_index(v, &b.device)?;
    let op = parse_operation(&b.operation)?;
    let (tag, _) = command_of(v, i, op)?;
    // Selecting reserves the device: only for who may command it.
    let may = s
        .write_role(&tag)
        .is_some_and(|r| who.role >= r && s.in_write_area(&who, &tag));
    if !may {
        return Err(ApiError::forbidden(format!(
            "you may not command {} (its command tag '{tag}')",
            v.network.model.switches[i].name
        )));
    }
    let user = who.audit_name();
    let sel = v
        .selections
        .select(i, &b.device, op, &user, s.clock.now())
        .map_err(|gridscada_network::SelectRefused::HeldBy(h)| {
            ApiError::new(StatusCode::CONFLICT, "reserved", h.describe())
        })?;
    let p = preview_info(v, i, op, &user);
    let effect = if p.interlocks.is_empty() {
        format!(
            "{} section(s), {} customer(s) lose supply; {} section(s), {} customer(s) gain it",
            p.supply.lose_supply.len(),
            p.supply.customers_lose,
            p.supply.gain_supply.len(),
            p.supply.customers_gain
        )
    } else {
        format!(
            "refused as it stands: {}",
            p.interlocks
                .iter()
                .map(|x| x.rule.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        )
    };
    crate::api::audit(
        &s,
        &who,
        "switching_selected",
        &b.device,
        format!(
            "selected {} to {} (selection {}): {effect}",
            v.network.model.switches[i].name,
            op.as_str(),
            sel.id
        ),
    )
    .await;
    Ok((StatusCode::CREATED, Json(selection_info(v, &sel, Some(p)))))
}

/// The standing selection `id`, held by `who` (or, with `supervisor_may`,
/// any selection for a supervisor).
fn own_selection(
    v: &NetworkView,
    who: &Principal,
    id: u64,
    supervisor_may: bool,
) -> ApiResult<gridscada_network::Selection> {
    let sel = v.selections.get(id).ok_or_else(|| {
        ApiError::not_found(format!(
            "no selection {id}: it was executed, cancelled or timed out (select again)"
        ))
    })?;
    if sel.user != who.audit_name() && !(supervisor_may && who.role >= Role::Supervisor) {
        return Err(ApiError::forbidden(format!(
            "selection {id} is held by {}",
            sel.user
        )));
    }
    Ok(sel)
}

#[utoipa::path(post, path = "/api/switching/selections/{id}/execute", tag = "network",
    summary = "Execute your selection; answers once the device's position reads back",
    params(("id" = u64, Path, description = "Selection id")),
    responses((status = 200, description = "Executed: the device's new position", body = SelectionInfo),
        (status = 400), (status = 403, description = "Held by another operator, or the command is refused"),
        (status = 404, description = "No such selection (executed, cancelled or timed out)"),
        (status = 409, description = "Refused by a safety tag or an interlock (the rule is the error)"),
        (status = 502, description = "The device did not take the command"),
        (status = 503), (status = 504, description = "The command timed out")))]
pub async fn execute(
    State(s): State<WebState>,
    Extension(who): Extension<Principal>,
    Path(id): Path<u64>,
) -> ApiResult<Json<SelectionInfo>> {
    let v = view(&s)?;
    let sel = execute_selection(&s, v, &who, id, None).await?;
    Ok(Json(selection_info(v, &sel, None)))
}

/// Executes selection `id` held by `who` (for `step`, a programme's step:
/// the selection must be of that device and operation) and answers once the
/// device's position reads back. Audited either way.
pub(crate) async fn execute_selection(
    s: &WebState,
    v: &NetworkView,
    who: &Principal,
    id: u64,
    step: Option<(usize, Operation, &str)>,
) -> ApiResult<gridscada_network::Selection> {
    let sel = own_selection(v, who, id, false)?;
    if let Some((device, op, what)) = step {
        if sel.device != device || sel.operation != op {
            return Err(ApiError::bad_request(format!(
                "selection {id} is to {} {}, not {what}",
                sel.operation.as_str(),
                sel.device_id
            )));
        }
    }
    let (tag, value) = command_of(v, sel.device, sel.operation)?;
    // The selection ends as the command goes out: the guard then checks the
    // command like any other (safety tags, interlocks on the live topology).
    let sel = v
        .selections
        .take(id)
        .ok_or_else(|| ApiError::not_found(format!("selection {id} timed out (select again)")))?;
    let name = v.network.model.switches[sel.device].name.clone();
    if sel.overridden.is_some() {
        // The supervisor's override holds for this command only.
        v.selections.grant(sel.device, sel.operation);
    }
    let outcome = crate::command::write_tag(s, who, &tag, value, "select-before-operate")
        .await
        .map_err(crate::api::tags::write_refused);
    if outcome.is_ok() {
        if let Some(gridscada_config::CommandBinding::Pulse { .. }) = v.network.command[sel.device]
        {
            // A pulse output is released once the device took it.
            let _ = crate::command::write_tag(
                s,
                who,
                &tag,
                gridscada_tagdb::Value::Bool(false),
                "select-before-operate",
            )
            .await;
        }
    }
    let word = match &outcome {
        Ok(_) => "executed".to_string(),
        Err(e) => format!("not executed ({}): {}", e.code, e.detail),
    };
    crate::api::audit(
        s,
        who,
        "switching_executed",
        &sel.device_id,
        format!("{} {name} (selection {id}) {word}", sel.operation.as_str()),
    )
    .await;
    outcome?;
    Ok(sel)
}

#[derive(Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct OverrideBody {
    pub reason: String,
}

#[utoipa::path(post, path = "/api/switching/selections/{id}/override", tag = "network",
    summary = "A supervisor overrides the overridable interlocks of a standing selection, with a reason",
    params(("id" = u64, Path, description = "Selection id")),
    request_body = OverrideBody,
    responses((status = 200, description = "Overridden: its holder may execute it", body = SelectionInfo),
        (status = 400), (status = 404, description = "No such selection"),
        (status = 409, description = "A rule that allows no override refuses it, or nothing needs overriding")))]
pub async fn override_selection(
    State(s): State<WebState>,
    Extension(who): Extension<Principal>,
    Path(id): Path<u64>,
    body: Result<Json<OverrideBody>, axum::extract::rejection::JsonRejection>,
) -> ApiResult<Json<SelectionInfo>> {
    let Json(b) = body.map_err(|e| ApiError::bad_request(e.body_text()))?;
    let v = view(&s)?;
    let reason = b.reason.trim();
    if reason.is_empty() || reason.chars().count() > 500 {
        return Err(ApiError::bad_request(
            "an override needs a reason of 1 to 500 characters",
        ));
    }
    let sel = v.selections.get(id).ok_or_else(|| {
        ApiError::not_found(format!(
            "no selection {id}: it was executed, cancelled or timed out"
        ))
    })?;
    let p = preview_info(v, sel.device, sel.operation, &sel.user);
    if let Some(hard) = p.interlocks.iter().find(|x| !x.overridable) {
        return Err(ApiError::new(
            StatusCode::CONFLICT,
            "not_overridable",
            format!("{} allows no override: {}", hard.rule, hard.text),
        ));
    }
    if p.interlocks.is_empty() {
        return Err(ApiError::new(
            StatusCode::CONFLICT,
            "nothing_to_override",
            "no interlock refuses this operation now",
        ));
    }
    let by = who.audit_name();
    let sel = v
        .selections
        .set_override(id, &by, reason)
        .ok_or_else(|| ApiError::not_found(format!("selection {id} timed out")))?;
    let rules: Vec<&str> = p.interlocks.iter().map(|x| x.rule.as_str()).collect();
    crate::api::audit(
        &s,
        &who,
        "switching_override",
        &sel.device_id,
        format!(
            "overrode {} for {} {} (selection {id}, held by {}): {reason}",
            rules.join(", "),
            sel.operation.as_str(),
            v.network.model.switches[sel.device].name,
            sel.user
        ),
    )
    .await;
    Ok(Json(selection_info(v, &sel, Some(p))))
}

#[utoipa::path(delete, path = "/api/switching/selections/{id}", tag = "network",
    summary = "Cancel a selection (its holder, or a supervisor)",
    params(("id" = u64, Path, description = "Selection id")),
    responses((status = 204, description = "Cancelled"), (status = 400),
        (status = 403, description = "Held by another operator"),
        (status = 404, description = "No such selection")))]
pub async fn cancel(
    State(s): State<WebState>,
    Extension(who): Extension<Principal>,
    Path(id): Path<u64>,
) -> ApiResult<StatusCode> {
    let v = view(&s)?;
    let sel = own_selection(v, &who, id, true)?;
    if v.selections.take(id).is_some() {
        let name = &v.network.model.switches[sel.device].name;
        let whose = if sel.user == who.audit_name() {
            String::new()
        } else {
            format!(" held by {}", sel.user)
        };
        crate::api::audit(
            &s,
            &who,
            "switching_cancelled",
            &sel.device_id,
            format!(
                "cancelled the selection {id} to {} {name}{whose}",
                sel.operation.as_str()
            ),
        )
        .await;
    }
    Ok(StatusCode::NO_CONTENT)
}

/// A safety tag, as the API shows it.
#[derive(Serialize, ToSchema)]
pub struct SafetyTagInfo {
    pub id: i64,
    pub device: String,
    /// The device's name.
    pub device_name: String,
    /// do_not_operate, do_not_close or information.
    pub kind: String,
    /// As printed on the tag: DO NOT OPERATE, DO NOT CLOSE, INFORMATION.
    pub label: String,
    pub reason: String,
    pub work_ref: String,
    pub placed_by: String,
    #[schema(value_type = crate::openapi::shapes::Timestamp)]
    pub placed_at: gridscada_tagdb::Timestamp,
    pub removed_by: Option<String>,
    #[schema(value_type = Option<crate::openapi::shapes::Timestamp>)]
    pub removed_at: Option<gridscada_tagdb::Timestamp>,
    pub removal_reason: Option<String>,
}

fn tag_info(net: &Network, r: gridscada_store::SafetyTagRecord) -> SafetyTagInfo {
    let kind = gridscada_network::TagKind::parse(&r.kind);
    SafetyTagInfo {
        device_name: net
            .model
            .switch(&r.device)
            .map_or_else(|| r.device.clone(), |i| net.model.switches[i].name.clone()),
        label: kind.map_or("?", |k| k.label()).into(),
        id: r.id,
        device: r.device,
        kind: r.kind,
        reason: r.reason,
        work_ref: r.work_ref,
        placed_by: r.placed_by,
        placed_at: r.placed_at,
        removed_by: r.removed_by,
        removed_at: r.removed_at,
        removal_reason: r.removal_reason,
    }
}

/// The record as the guard holds it.
pub fn standing(r: &gridscada_store::SafetyTagRecord) -> Option<gridscada_network::SafetyTag> {
    Some(gridscada_network::SafetyTag {
        id: r.id,
        device: r.device.clone(),
        kind: gridscada_network::TagKind::parse(&r.kind)?,
        reason: r.reason.clone(),
        work_ref: r.work_ref.clone(),
        placed_by: r.placed_by.clone(),
        placed_at: r.placed_at,
    })
}

#[derive(Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
#[serde(deny_unknown_fields)]
pub struct TagsQuery {
    /// Also the removed tags (the latest 500).
    #[serde(default)]
    pub history: bool,
}

#[derive(Serialize, ToSchema)]
pub struct SafetyTagList {
    pub tags: Vec<SafetyTagInfo>,
}

#[utoipa::path(get, path = "/api/switching/tags", tag = "network", summary = "Safety tags on switching devices",
    params(TagsQuery),
    responses((status = 200, description = "OK", body = SafetyTagList), (status = 400),
        (status = 404, description = "No [network]")))]
pub async fn tags(
    State(s): State<WebState>,
    Query(q): Query<TagsQuery>,
) -> ApiResult<Json<SafetyTagList>> {
    let v = view(&s)?;
    let rows = if q.history {
        s.store.safety_tag_history(500).await?
    } else {
        s.store.standing_safety_tags().await?
    };
    Ok(Json(SafetyTagList {
        tags: rows.into_iter().map(|r| tag_info(&v.network, r)).collect(),
    }))
}

#[derive(Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct PlaceTag {
    /// A switching device's id.
    pub device: String,
    /// do_not_operate, do_not_close or information.
    pub kind: String,
    pub reason: String,
    #[serde(default)]
    pub work_ref: String,
}

#[utoipa::path(post, path = "/api/switching/tags", tag = "network", summary = "Place a safety tag",
    request_body = PlaceTag,
    responses((status = 201, description = "Placed", body = SafetyTagInfo), (status = 400),
        (status = 404, description = "No such device"), (status = 503)))]
pub async fn place(
    State(s): State<WebState>,
    Extension(who): Extension<Principal>,
    body: Result<Json<PlaceTag>, axum::extract::rejection::JsonRejection>,
) -> ApiResult<(StatusCode, Json<SafetyTagInfo>)> {
    let Json(b) = body.map_err(|e| ApiError::bad_request(e.body_text()))?;
    let v = view(&s)?;
    let net = &v.network;
    let i = net
        .model
        .switch(&b.device)
        .ok_or_else(|| ApiError::not_found(format!("no switching device '{}'", b.device)))?;
    let kind = gridscada_network::TagKind::parse(&b.kind).ok_or_else(|| {
        ApiError::bad_request(format!(
            "kind '{}': expected one of {}",
            b.kind,
            gridscada_network::TagKind::NAMES
        ))
    })?;
    let record = place_tag(&s, v, &who, i, kind, &b.reason, &b.work_ref).await?;
    Ok((StatusCode::CREATED, Json(tag_info(net, record))))
}

/// Places a safety tag of `kind` on device `i` for `who`: stored, enforced
/// at once, audited.
pub(crate) async fn place_tag(
    s: &WebState,
    v: &NetworkView,
    who: &Principal,
    i: usize,
    kind: gridscada_network::TagKind,
    reason: &str,
    work_ref: &str,
) -> ApiResult<gridscada_store::SafetyTagRecord> {
    let reason = reason.trim();
    if reason.is_empty() {
        return Err(ApiError::bad_request("a safety tag needs a reason"));
    }
    crate::api::pair::active_ready(s)?;
    crate::api::audit_ready(s).await?;
    let device = &v.network.model.switches[i];
    let by = who.audit_name();
    let record = s
        .store
        .place_safety_tag(
            &device.id,
            kind.as_str(),
            reason,
            work_ref.trim(),
            &by,
            s.clock.now(),
        )
        .await?;
    if let Some(t) = standing(&record) {
        v.tags.add(t);
    }
    let work = gridscada_network::safety::for_work(&record.work_ref);
    crate::api::audit(
        s,
        who,
        "safety_tag_placed",
        &device.id,
        format!(
            "{} placed on {}{work}: {reason} (tag {})",
            kind.label(),
            device.name,
            record.id
        ),
    )
    .await;
    Ok(record)
}

#[derive(Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct RemoveTag {
    pub reason: String,
}

#[utoipa::path(delete, path = "/api/switching/tags/{id}", tag = "network", summary = "Remove a safety tag",
    params(("id" = i64, Path, description = "Safety tag id")),
    request_body = RemoveTag,
    responses((status = 200, description = "Removed", body = SafetyTagInfo), (status = 400),
        (status = 403, description = "Neither the user who placed it nor a supervisor"),
        (status = 404), (status = 409, description = "Already removed"), (status = 503)))]
pub async fn remove(
    State(s): State<WebState>,
    Extension(who): Extension<Principal>,
    Path(id): Path<i64>,
    body: Result<Json<RemoveTag>, axum::extract::rejection::JsonRejection>,
) -> ApiResult<Json<SafetyTagInfo>> {
    let Json(b) = body.map_err(|e| ApiError::bad_request(e.body_text()))?;
    let v = view(&s)?;
    let reason = b.reason.trim();
    if reason.is_empty() {
        return Err(ApiError::bad_request(
            "removing a safety tag needs a reason",
        ));
    }
    let record = s
        .store
        .safety_tag(id)
        .await?
        .ok_or_else(|| ApiError::not_found(format!("no safety tag {id}")))?;
    let by = who.audit_name();
    if record.placed_by != by && who.role < Role::Supervisor {
        return Err(ApiError::new(
            StatusCode::FORBIDDEN,
            "forbidden",
            format!(
                "safety tag {id} was placed by {}: only they or a supervisor may remove it",
                record.placed_by
            ),
        ));
    }
    Ok(Json(remove_tag(&s, v, &who, id, reason).await?))
}

/// Removes safety tag `id` for `who` (whose right to has been checked):
/// stored, no longer enforced, audited.
pub(crate) async fn remove_tag(
    s: &WebState,
    v: &NetworkView,
    who: &Principal,
    id: i64,
    reason: &str,
) -> ApiResult<SafetyTagInfo> {
    crate::api::pair::active_ready(s)?;
    crate::api::audit_ready(s).await?;
    let record = s
        .store
        .remove_safety_tag(id, &who.audit_name(), reason, s.clock.now())
        .await?;
    v.tags.remove(id);
    let kind = gridscada_network::TagKind::parse(&record.kind).map_or("?", |k| k.label());
    let info = tag_info(&v.network, record);
    crate::api::audit(
        s,
        who,
        "safety_tag_removed",
        &info.device,
        format!(
            "{kind} removed from {} (tag {id}, placed by {}): {reason}",
            info.device_name, info.placed_by
        ),
    )
    .await;
    Ok(info)
}
