//! Switching programmes (docs/NETWORK.md): a supervisor prepares the steps
//! and approves them once the check against the live topology finds nothing
//! that refuses them; an operator takes them one at a time (an operate step
//! through select-before-operate), and may pause or abandon the programme.
//! Every step and change is in the event log.

use axum::extract::{Path, State};
use axum::http::StatusCode;
use axum::{Extension, Json};
use gridscada_config::Role;
use gridscada_network::programme::{self, Step, StepCheck, StepText};
use gridscada_store::{ProgrammeChange, ProgrammeRecord, StoreError};
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use crate::api::network::{view, InterlockInfo, NetworkView, SupplyChange};
use crate::auth::Principal;
use crate::error::{ApiError, ApiResult};
use crate::WebState;

/// One step's check against the topology, from the step to be done next on.
#[derive(Serialize, ToSchema)]
pub struct StepCheckInfo {
    /// What would refuse it at that point; empty: it may be done.
    pub refusals: Vec<InterlockInfo>,
    #[serde(flatten)]
    pub supply: SupplyChange,
    pub notes: Vec<String>,
}

#[derive(Serialize, ToSchema)]
pub struct StepInfo {
    /// From 1.
    pub n: usize,
    /// The step as written.
    #[schema(value_type = Object)]
    pub step: StepText,
    /// In words.
    pub text: String,
    pub done: bool,
    /// For the steps still to do.
    pub check: Option<StepCheckInfo>,
}

#[derive(Serialize, ToSchema)]
pub struct ProgrammeInfo {
    pub id: i64,
    pub name: String,
    /// draft, approved, running, paused, completed or abandoned.
    pub state: String,
    /// Steps done.
    pub done: usize,
    pub steps: Vec<StepInfo>,
    pub created_by: String,
    #[schema(value_type = crate::openapi::shapes::Timestamp)]
    pub created_at: gridscada_tagdb::Timestamp,
    pub approved_by: Option<String>,
    #[schema(value_type = Option<crate::openapi::shapes::Timestamp>)]
    pub approved_at: Option<gridscada_tagdb::Timestamp>,
    pub version: i64,
    /// Why it was abandoned.
    pub note: String,
}

#[derive(Serialize, ToSchema)]
pub struct ProgrammeList {
    pub programmes: Vec<ProgrammeInfo>,
}

fn steps_of(v: &NetworkView, r: &ProgrammeRecord) -> ApiResult<(Vec<StepText>, Vec<Step>)> {
    let texts: Vec<StepText> = serde_json::from_str(&r.steps).map_err(|e| {
        ApiError::new(
            StatusCode::CONFLICT,
            "stale",
            format!("programme {}'s steps cannot be read: {e}", r.id),
        )
    })?;
    // The network may have changed since it was written (a new configuration).
    let steps = programme::parse(&v.network.model, &texts).map_err(|errors| {
        ApiError::new(
            StatusCode::CONFLICT,
            "stale",
            format!(
                "programme {} no longer fits the network: {}",
                r.id,
                errors.join("; ")
            ),
        )
    })?;
    Ok((texts, steps))
}

/// The check of `steps[from..]` against the live topology and tags.
fn check_live(v: &NetworkView, steps: &[Step], from: usize) -> Vec<StepCheck> {
    let live = v.live.borrow().clone();
    programme::check(&v.network.model, &live.inputs, &v.tags.all(), steps, from)
}

fn check_info(v: &NetworkView, c: StepCheck) -> StepCheckInfo {
    StepCheckInfo {
        refusals: c.refusals.into_iter().map(InterlockInfo::from).collect(),
        supply: SupplyChange::of(&v.network.model, &c.effect.unwrap_or_default()),
        notes: c.notes,
    }
}

fn info(v: &NetworkView, r: &ProgrammeRecord, with_check: bool) -> ApiResult<ProgrammeInfo> {
    let (texts, steps) = steps_of(v, r)?;
    let done = usize::try_from(r.next_step).unwrap_or(0).min(steps.len());
    let live = matches!(
        r.state.as_str(),
        "draft" | "approved" | "running" | "paused"
    );
    let mut checks = if with_check && live {
        check_live(v, &steps, done).into_iter()
    } else {
        Vec::new().into_iter()
    };
    Ok(ProgrammeInfo {
        id: r.id,
        name: r.name.clone(),
        state: r.state.clone(),
        done,
        steps: texts
            .into_iter()
            .zip(&steps)
            .enumerate()
            .map(|(i, (text, step))| StepInfo {
                n: i + 1,
                text: step.describe(&v.network.model),
                done: i < done,
                check: if i >= done {
                    checks.next().map(|c| check_info(v, c))
                } else {
                    None
                },
                step: text,
            })
            .collect(),
        created_by: r.created_by.clone(),
        created_at: r.created_at,
        approved_by: r.approved_by.clone(),
        approved_at: r.approved_at,
        version: r.version,
        note: r.note.clone(),
    })
}

/// Puts a programme's change on record, its source the programme.
async fn record(s: &WebState, who: &Principal, kind: &str, id: i64, message: String) {
    crate::api::audit(s, who, kind, &format!("programme:{id}"), message).await;
}

async fn load(s: &WebState, id: i64) -> ApiResult<ProgrammeRecord> {
    s.store
        .programme(id)
        .await?
        .ok_or_else(|| ApiError::not_found(format!("no switching programme {id}")))
}

fn conflict(e: StoreError) -> ApiError {
    match e {
        StoreError::Conflict(why) => ApiError::new(StatusCode::CONFLICT, "changed", why),
        other => other.into(),
    }
}

#[utoipa::path(get, path = "/api/switching/programmes", tag = "network",
    summary = "Switching programmes, newest first",
    responses((status = 200, description = "OK", body = ProgrammeList),
        (status = 404, description = "No [network]")))]
pub async fn list(State(s): State<WebState>) -> ApiResult<Json<ProgrammeList>> {
    let v = view(&s)?;
    let rows = s.store.programmes(100).await?;
    Ok(Json(ProgrammeList {
        // A programme written for another network is left out of the list
        // (opening it says why).
        programmes: rows.iter().filter_map(|r| info(v, r, false).ok()).collect(),
    }))
}

#[utoipa::path(get, path = "/api/switching/programmes/{id}", tag = "network",
    summary = "A switching programme, the steps to do checked against the live topology",
    params(("id" = i64, Path, description = "Programme id")),
    responses((status = 200, description = "OK", body = ProgrammeInfo), (status = 400),
        (status = 404), (status = 409, description = "It no longer fits the network")))]
pub async fn one(State(s): State<WebState>, Path(id): Path<i64>) -> ApiResult<Json<ProgrammeInfo>> {
    let v = view(&s)?;
    let r = load(&s, id).await?;
    Ok(Json(info(v, &r, true)?))
}

#[derive(Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct NewProgramme {
    pub name: String,
    /// In order: {"kind": "operate", "device", "operation"}, {"kind":
    /// "place_tag", "device", "tag_kind", "reason", "work_ref"}, {"kind":
    /// "remove_tag", "device", "tag_kind"}, {"kind": "manual", "text"}.
    #[schema(value_type = Vec<Object>)]
    pub steps: Vec<StepText>,
}

#[utoipa::path(post, path = "/api/switching/programmes", tag = "network",
    summary = "Prepare a switching programme (a draft, checked step by step)",
    request_body = NewProgramme,
    responses((status = 201, description = "Stored as a draft", body = ProgrammeInfo), (status = 400),
        (status = 404, description = "No [network]"), (status = 503)))]
pub async fn create(
    State(s): State<WebState>,
    Extension(who): Extension<Principal>,
    body: Result<Json<NewProgramme>, axum::extract::rejection::JsonRejection>,
) -> ApiResult<(StatusCode, Json<ProgrammeInfo>)> {
    let Json(b) = body.map_err(|e| ApiError::bad_request(e.body_text()))?;
    let v = view(&s)?;
    let name = b.name.trim();
    if name.is_empty() || name.chars().count() > 200 {
        return Err(ApiError::bad_request(
            "a programme needs a name of 1 to 200 characters",
        ));
    }
    programme::parse(&v.network.model, &b.steps)
        .map_err(|errors| ApiError::bad_request(errors.join("; ")))?;
    crate::api::audit_ready(&s).await?;
    let steps = serde_json::to_string(&b.steps)
        .map_err(|e| ApiError::bad_request(format!("the steps: {e}")))?;
    let r = s
        .store
        .create_programme(name, &steps, "draft", &who.audit_name(), s.clock.now())
        .await?;
    record(
        &s,
        &who,
        "programme_created",
        r.id,
        format!(
            "switching programme {} '{name}' prepared, {} step(s)",
            r.id,
            b.steps.len()
        ),
    )
    .await;
    Ok((StatusCode::CREATED, Json(info(v, &r, true)?)))
}

/// The first refusal of a check, in words ("step 3 (close ...): rule: why").
fn first_refusal(
    v: &NetworkView,
    steps: &[Step],
    from: usize,
    checks: &[StepCheck],
) -> Option<(&'static str, String)> {
    checks.iter().enumerate().find_map(|(k, c)| {
        let f = c.refusals.first()?;
        let n = from + k;
        Some((
            f.rule.as_str(),
            format!(
                "step {} ({}): {}",
                n + 1,
                steps[n].describe(&v.network.model),
                f.text
            ),
        ))
    })
}

#[utoipa::path(post, path = "/api/switching/programmes/{id}/approve", tag = "network",
    summary = "Approve a draft programme: refused while any step would be refused on the live topology",
    params(("id" = i64, Path, description = "Programme id")),
    responses((status = 200, description = "Approved", body = ProgrammeInfo), (status = 400),
        (status = 404), (status = 409, description = "Not a draft, changed meanwhile, or a step is refused (the rule is the error)"),
        (status = 503)))]
pub async fn approve(
    State(s): State<WebState>,
    Extension(who): Extension<Principal>,
    Path(id): Path<i64>,
) -> ApiResult<Json<ProgrammeInfo>> {
    let v = view(&s)?;
    let r = load(&s, id).await?;
    if r.state != "draft" {
        return Err(ApiError::conflict(format!(
            "programme {id} is {}: only a draft is approved",
            r.state
        )));
    }
    let (_, steps) = steps_of(v, &r)?;
    let checks = check_live(v, &steps, 0);
    if let Some((rule, why)) = first_refusal(v, &steps, 0, &checks) {
        return Err(ApiError::new(StatusCode::CONFLICT, rule, why));
    }
    crate::api::audit_ready(&s).await?;
    let by = who.audit_name();
    let r = s
        .store
        .update_programme(
            id,
            r.version,
            ProgrammeChange {
                state: "approved",
                next_step: 0,
                approved_by: Some(&by),
                note: "",
                at: s.clock.now(),
            },
        )
        .await
        .map_err(conflict)?;
    record(
        &s,
        &who,
        "programme_approved",
        id,
        format!("switching programme {id} '{}' approved", r.name),
    )
    .await;
    Ok(Json(info(v, &r, true)?))
}

#[derive(Deserialize, ToSchema, Default)]
#[serde(deny_unknown_fields)]
pub struct StepBody {
    /// For an operate step on a device with a command: the caller's
    /// selection of that device and operation (`POST /api/switching/selections`).
    pub selection: Option<u64>,
    /// The version read; the step is refused if the programme changed since.
    pub version: Option<i64>,
}

#[utoipa::path(post, path = "/api/switching/programmes/{id}/step", tag = "network",
    summary = "Do the next step of an approved programme (an operate step through your selection)",
    params(("id" = i64, Path, description = "Programme id")),
    request_body = StepBody,
    responses((status = 200, description = "The step is done", body = ProgrammeInfo), (status = 400),
        (status = 403), (status = 404),
        (status = 409, description = "Not running, changed meanwhile, the device not where the step leaves it, or refused (the rule is the error)"),
        (status = 502, description = "The device did not take the command"),
        (status = 503), (status = 504, description = "The command timed out")))]
pub async fn step(
    State(s): State<WebState>,
    Extension(who): Extension<Principal>,
    Path(id): Path<i64>,
    body: Result<Json<StepBody>, axum::extract::rejection::JsonRejection>,
) -> ApiResult<Json<ProgrammeInfo>> {
    let Json(b) = body.map_err(|e| ApiError::bad_request(e.body_text()))?;
    let v = view(&s)?;
    let r = load(&s, id).await?;
    if !matches!(r.state.as_str(), "approved" | "running") {
        return Err(ApiError::conflict(format!(
            "programme {id} is {}: steps are taken from an approved or running programme",
            r.state
        )));
    }
    if b.version.is_some_and(|ver| ver != r.version) {
        return Err(ApiError::new(
            StatusCode::CONFLICT,
            "changed",
            format!("programme {id} was changed meanwhile: reload it"),
        ));
    }
    let (_, steps) = steps_of(v, &r)?;
    let n = usize::try_from(r.next_step).unwrap_or(0);
    let Some(this) = steps.get(n).cloned() else {
        return Err(ApiError::conflict(format!(
            "programme {id} has no step left"
        )));
    };
    let m = &v.network.model;
    let what = this.describe(m);
    crate::api::audit_ready(&s).await?;
    // Claim the step first (the version moves on), so that two operators or
    // two servers cannot both take it.
    let now = s.clock.now();
    let claimed = s
        .store
        .update_programme(
            id,
            r.version,
            ProgrammeChange {
                state: "running",
                next_step: r.next_step,
                approved_by: None,
                note: "",
                at: now,
            },
        )
        .await
        .map_err(conflict)?;
    let label = format!(
        "switching programme {id} '{}' step {} of {}",
        r.name,
        n + 1,
        steps.len()
    );
    let done: ApiResult<()> = async {
        match &this {
            Step::Operate { device, operation } => {
                if v.network.command[*device].is_some() {
                    let sel = b.selection.ok_or_else(|| {
                        ApiError::bad_request(format!(
                            "step {}: {what} needs your selection of it (select-before-operate)",
                            n + 1
                        ))
                    })?;
                    crate::api::network::execute_selection(
                        &s,
                        v,
                        &who,
                        sel,
                        Some((*device, *operation, &what)),
                    )
                    .await?;
                } else {
                    // Operated on site: done once its status says so.
                    let pos = v.live.borrow().inputs.switches.get(*device).copied();
                    if !pos.is_some_and(|p| programme::reached(&this, p)) {
                        return Err(ApiError::new(
                            StatusCode::CONFLICT,
                            "not_reached",
                            format!(
                                "step {}: {what} is done on site; {} reads {} (confirm once it has been operated)",
                                n + 1,
                                m.switches[*device].name,
                                pos.map_or("UNKNOWN", |p| p.as_str())
                            ),
                        ));
                    }
                }
            }
            Step::PlaceTag {
                device,
                kind,
                reason,
                work_ref,
            } => {
                let reason = format!("{reason} (programme {id})");
                crate::api::network::place_tag(&s, v, &who, *device, *kind, &reason, work_ref)
                    .await?;
            }
            Step::RemoveTag { device, kind } => {
                // The latest standing tag of that kind on the device: the
                // programme, approved by a supervisor, removes it.
                let tag = v
                    .tags
                    .on(&m.switches[*device].id)
                    .into_iter()
                    .filter(|t| t.kind == *kind)
                    .max_by_key(|t| t.id)
                    .ok_or_else(|| {
                        ApiError::new(
                            StatusCode::CONFLICT,
                            "safety_tag",
                            format!(
                                "step {}: {} carries no {} tag",
                                n + 1,
                                m.switches[*device].name,
                                kind.label()
                            ),
                        )
                    })?;
                crate::api::network::remove_tag(&s, v, &who, tag.id, &label).await?;
            }
            Step::Manual { .. } => {}
        }
        Ok(())
    }
    .await;
    if let Err(e) = done {
        record(
            &s,
            &who,
            "programme_step",
            id,
            format!("{label} not done: {what}: {} ({})", e.detail, e.code),
        )
        .await;
        return Err(e);
    }
    let last = n + 1 == steps.len();
    let r = s
        .store
        .update_programme(
            id,
            claimed.version,
            ProgrammeChange {
                state: if last { "completed" } else { "running" },
                next_step: r.next_step + 1,
                approved_by: None,
                note: "",
                at: s.clock.now(),
            },
        )
        .await
        .map_err(conflict)?;
    record(
        &s,
        &who,
        "programme_step",
        id,
        format!("{label} done: {what}"),
    )
    .await;
    if last {
        record(
            &s,
            &who,
            "programme_completed",
            id,
            format!("switching programme {id} '{}' completed", r.name),
        )
        .await;
    }
    Ok(Json(info(v, &r, true)?))
}

#[derive(Deserialize, ToSchema, Default)]
#[serde(deny_unknown_fields)]
pub struct StateBody {
    /// pause, resume or abandon.
    pub action: String,
    /// Why (needed to abandon).
    #[serde(default)]
    pub reason: String,
}

#[utoipa::path(post, path = "/api/switching/programmes/{id}/state", tag = "network",
    summary = "Pause, resume or abandon a programme",
    params(("id" = i64, Path, description = "Programme id")),
    request_body = StateBody,
    responses((status = 200, description = "OK", body = ProgrammeInfo), (status = 400),
        (status = 403), (status = 404), (status = 409, description = "Not in a state that allows it, or changed meanwhile"),
        (status = 503)))]
pub async fn set_state(
    State(s): State<WebState>,
    Extension(who): Extension<Principal>,
    Path(id): Path<i64>,
    body: Result<Json<StateBody>, axum::extract::rejection::JsonRejection>,
) -> ApiResult<Json<ProgrammeInfo>> {
    let Json(b) = body.map_err(|e| ApiError::bad_request(e.body_text()))?;
    let v = view(&s)?;
    let r = load(&s, id).await?;
    let reason = b.reason.trim();
    let (next, kind, allowed): (&str, &str, &[&str]) = match b.action.as_str() {
        "pause" => ("paused", "programme_paused", &["approved", "running"]),
        "resume" => ("running", "programme_resumed", &["paused"]),
        "abandon" => (
            "abandoned",
            "programme_abandoned",
            &["draft", "approved", "running", "paused"],
        ),
        other => {
            return Err(ApiError::bad_request(format!(
                "action '{other}': expected pause, resume or abandon"
            )))
        }
    };
    if next == "abandoned" && reason.is_empty() {
        return Err(ApiError::bad_request(
            "abandoning a programme needs a reason",
        ));
    }
    if next == "abandoned" && r.state == "draft" && who.role < Role::Supervisor {
        return Err(ApiError::forbidden("a draft is abandoned by a supervisor"));
    }
    if !allowed.contains(&r.state.as_str()) {
        return Err(ApiError::conflict(format!(
            "programme {id} is {}: it cannot be {next}",
            r.state
        )));
    }
    crate::api::audit_ready(&s).await?;
    let r2 = s
        .store
        .update_programme(
            id,
            r.version,
            ProgrammeChange {
                state: next,
                next_step: r.next_step,
                approved_by: None,
                note: reason,
                at: s.clock.now(),
            },
        )
        .await
        .map_err(conflict)?;
    let why = if reason.is_empty() {
        String::new()
    } else {
        format!(": {reason}")
    };
    record(
        &s,
        &who,
        kind,
        id,
        format!(
            "switching programme {id} '{}' {} after {} of its steps{why}",
            r.name, b.action, r.next_step
        ),
    )
    .await;
    Ok(Json(info(v, &r2, true)?))
}
