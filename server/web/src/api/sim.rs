//! The Simulation panel's API, for trainers and tests: zone faults
//! (permanent or transient), devices offline, slow or answering garbage,
//! the plant's input profiles and zone loads. Only in `demo` and `replay`
//! (a server with simulators), only for a caller whose group may open the
//! `simulation` screen (administrators by default, or a trainer group an
//! administrator gives it to). `serve` answers every such route with 404
//! and a message saying why ([`not_simulated`]).
//!
//! Every action is an event of type `training` with the user, so a drill
//! can be told apart from the plant's own history.

use axum::extract::{Path, State};
use axum::http::StatusCode;
use axum::{Extension, Json};
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use crate::api::audit;
use crate::auth::Principal;
use crate::error::{ApiError, ApiResult};
use crate::WebState;

/// A zone fault that clears by itself when it trips the ELCB, or one that
/// stays until repaired.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize, ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum FaultKind {
    Permanent,
    Transient,
}

/// The simulator's control interface as the API needs it. Errors are
/// messages for the operator (unknown panel, zone out of range...). The
/// training controls have defaults that refuse, for a simulator without them.
pub trait SimControl: Send + Sync {
    fn inject_fault(&self, panel: &str, zone: u8, kind: FaultKind) -> Result<(), String>;
    fn repair(&self, panel: &str, zone: u8) -> Result<(), String>;
    fn set_offline(&self, device: &str, offline: bool) -> Result<(), String>;
    /// A transient fault that clears by itself after `clears_after`.
    fn inject_timed_fault(
        &self,
        _panel: &str,
        _zone: u8,
        _clears_after: std::time::Duration,
    ) -> Result<(), String> {
        Err("this simulator has no timed transient faults".into())
    }
    /// Added reply latency and damaged replies of one device.
    fn set_link(&self, _device: &str, _link: &LinkFaults) -> Result<(), String> {
        Err("this simulator cannot slow or corrupt replies".into())
    }
    /// Overrides or scales one of the plant's input profiles.
    fn set_input(&self, _input: PlantInput, _profile: &InputProfile) -> Result<(), String> {
        Err("this simulator has no input profiles".into())
    }
    /// Sets a zone's load.
    fn set_zone_load(&self, _panel: &str, _zone: u8, _kw: f64, _pf: f64) -> Result<(), String> {
        Err("this simulator has no zone loads".into())
    }
    /// What the Simulation panel shows.
    fn state(&self) -> SimState {
        SimState::default()
    }
}

/// How a simulated device answers (besides being offline).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize, Serialize, ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum ReplyFault {
    /// Correct replies.
    #[default]
    Normal,
    /// Damaged frames (bad protocol id, wrong transaction id, wrong
    /// function code, in turn): the poller must reject them.
    Corrupt,
    /// A Modbus exception (Server Device Failure) to every request.
    Exception,
}

/// The link faults of one simulated device.
#[derive(Debug, Clone, Default, Deserialize, Serialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct LinkFaults {
    /// Added reply latency, ms (0 or absent: none; at most 60000).
    #[serde(default)]
    #[schema(maximum = 60000)]
    pub slow_reply_ms: Option<u32>,
    #[serde(default)]
    #[schema(inline)]
    pub replies: ReplyFault,
}

/// A plant input a trainer may change.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize, ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum PlantInput {
    /// Plane-of-array irradiance (W/m²), which drives the PV units.
    Irradiance,
    /// Hub wind speed (m/s), which drives the wind units.
    WindSpeed,
    /// The microgrid's demand at its load meter (kW).
    Demand,
}

impl PlantInput {
    pub fn label(self) -> &'static str {
        match self {
            PlantInput::Irradiance => "irradiance",
            PlantInput::WindSpeed => "wind speed",
            PlantInput::Demand => "demand",
        }
    }
}

/// An input profile: the built-in daily curve, that curve scaled, or a
/// fixed value.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize, ToSchema)]
#[serde(tag = "kind", rename_all = "lowercase", deny_unknown_fields)]
pub enum InputProfile {
    Builtin,
    /// The built-in curve times `factor` (0 to 10).
    Scaled {
        factor: f64,
    },
    /// A fixed value in the input's unit.
    Constant {
        value: f64,
    },
    /// A daily table from a scenario file (shown, never set here).
    Daily,
}

impl InputProfile {
    fn describe(&self) -> String {
        match self {
            InputProfile::Builtin => "the built-in profile".into(),
            InputProfile::Scaled { factor } => format!("the built-in profile × {factor}"),
            InputProfile::Constant { value } => format!("a constant {value}"),
            InputProfile::Daily => "a daily table".into(),
        }
    }
}

/// What the Simulation panel shows: the simulated devices, panels and
/// plant inputs, as the simulator has them now.
#[derive(Debug, Clone, Default, Serialize, ToSchema)]
pub struct SimState {
    pub devices: Vec<SimDevice>,
    pub panels: Vec<SimPanel>,
    /// Absent when the plant has no microgrid.
    pub inputs: Option<SimInputs>,
}

#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct SimDevice {
    pub name: String,
    pub offline: bool,
    pub slow_reply_ms: Option<u32>,
    #[schema(inline)]
    pub replies: ReplyFault,
}

#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct SimPanel {
    pub id: String,
    pub elcb_closed: bool,
    pub zones: Vec<SimZone>,
}

#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct SimZone {
    /// 0 = the busbar behind the main MCCB.
    pub zone: u8,
    #[schema(inline)]
    pub fault: Option<FaultKind>,
    /// When a timed transient fault clears (ms since the epoch, plant time).
    pub fault_clears_at: Option<i64>,
    pub load_kw: f64,
    pub pf: f64,
}

#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct SimInputs {
    #[schema(inline)]
    pub irradiance: InputProfile,
    #[schema(inline)]
    pub wind_speed: InputProfile,
    #[schema(inline)]
    pub demand: InputProfile,
    pub irradiance_w_m2: f64,
    pub wind_speed_m_s: f64,
    pub demand_kw: f64,
}

/// The answer of every simulation route in a server without simulators
/// (`serve`): the routes exist so that the refusal says why.
pub async fn not_simulated() -> ApiError {
    ApiError::not_found(
        "simulation and training exist only in `gridscada demo` (and replay); this server runs a real plant",
    )
}

/// Records a training action: an event of type `training` with the user.
async fn training(s: &WebState, who: &Principal, source: &str, what: String) {
    audit(
        s,
        who,
        "training",
        source,
        format!("Training: {} {what}", who.audit_name()),
    )
    .await;
}

fn sim(s: &WebState) -> ApiResult<&dyn SimControl> {
    s.sim
        .as_deref()
        .ok_or_else(|| ApiError::not_found("no simulator in this server"))
}

fn refused(e: String) -> ApiError {
    if e.contains("unknown")
        || e.contains("no simulated")
        || e.contains("has no")
        || e.contains("no panel")
        || e.contains("no device")
        || e.contains("not found")
    {
        ApiError::not_found(e)
    } else {
        ApiError::bad_request(e)
    }
}

#[derive(Deserialize, Serialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct FaultBody {
    pub panel: String,
    pub zone: u8,
    #[schema(inline)]
    pub kind: FaultKind,
    /// For a transient fault: it clears by itself after this many seconds
    /// (1 to 3600), so a reclose after that holds. Without it a transient
    /// fault is gone once it has tripped the ELCB.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(minimum = 1, maximum = 3600)]
    pub clears_after_s: Option<u32>,
}

#[utoipa::path(post, path = "/api/sim/faults", tag = "simulation",
    summary = "Inject a zone fault (demo and replay only)",
    request_body = FaultBody,
    responses((status = 201, description = "Injected", body = inline(FaultBody)),
        (status = 400), (status = 404), (status = 503, description = "Its audit record could be neither stored nor spooled")))]
pub async fn inject_fault(
    State(s): State<WebState>,
    Extension(who): Extension<Principal>,
    body: Result<Json<FaultBody>, axum::extract::rejection::JsonRejection>,
) -> ApiResult<(StatusCode, Json<FaultBody>)> {
    let Json(b) = body.map_err(|e| ApiError::bad_request(e.body_text()))?;
    if b.kind == FaultKind::Permanent && b.clears_after_s.is_some() {
        return Err(ApiError::bad_request(
            "clears_after_s: a permanent fault stays until repaired; use kind \"transient\" for one that clears by itself",
        ));
    }
    crate::api::audit_ready(&s).await?;
    let sim = sim(&s)?;
    let kind = match (b.kind, b.clears_after_s) {
        (FaultKind::Transient, Some(secs)) => {
            sim.inject_timed_fault(
                &b.panel,
                b.zone,
                std::time::Duration::from_secs(u64::from(secs)),
            )
            .map_err(refused)?;
            format!("transient fault (clears after {secs} s)")
        }
        (kind, _) => {
            sim.inject_fault(&b.panel, b.zone, kind).map_err(refused)?;
            match kind {
                FaultKind::Permanent => "permanent fault".into(),
                FaultKind::Transient => "transient fault (clears at its trip)".into(),
            }
        }
    };
    training(
        &s,
        &who,
        &b.panel,
        format!("injected a {kind} on zone {} of panel {}", b.zone, b.panel),
    )
    .await;
    Ok((StatusCode::CREATED, Json(b)))
}

#[utoipa::path(delete, path = "/api/sim/faults/{panel}/{zone}", tag = "simulation",
    summary = "Repair a zone fault",
    params(("panel" = String, Path, min_length = 1), ("zone" = u8, Path)),
    responses((status = 204, description = "Repaired"), (status = 400), (status = 404), (status = 503, description = "Its audit record could be neither stored nor spooled")))]
pub async fn repair(
    State(s): State<WebState>,
    Extension(who): Extension<Principal>,
    Path((panel, zone)): Path<(String, u8)>,
) -> ApiResult<StatusCode> {
    crate::api::audit_ready(&s).await?;
    sim(&s)?.repair(&panel, zone).map_err(refused)?;
    training(
        &s,
        &who,
        &panel,
        format!("repaired zone {zone} of panel {panel}"),
    )
    .await;
    Ok(StatusCode::NO_CONTENT)
}

async fn set_offline(
    s: WebState,
    who: Principal,
    device: String,
    offline: bool,
) -> ApiResult<Json<DeviceState>> {
    crate::api::audit_ready(&s).await?;
    sim(&s)?.set_offline(&device, offline).map_err(refused)?;
    let what = if offline { "offline" } else { "online" };
    training(
        &s,
        &who,
        &device,
        format!("took simulated device {device} {what}"),
    )
    .await;
    Ok(Json(DeviceState { device, offline }))
}

/// A simulated device and whether it is off line.
#[derive(Serialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct DeviceState {
    pub device: String,
    pub offline: bool,
}

#[utoipa::path(post, path = "/api/sim/devices/{device}/offline", tag = "simulation",
    summary = "Take a simulated device offline",
    params(("device" = String, Path, min_length = 1)),
    responses((status = 200, description = "OK", body = inline(DeviceState)), (status = 400), (status = 404), (status = 503, description = "Its audit record could be neither stored nor spooled")))]
pub async fn offline(
    State(s): State<WebState>,
    Extension(who): Extension<Principal>,
    Path(device): Path<String>,
) -> ApiResult<Json<DeviceState>> {
    set_offline(s, who, device, true).await
}

#[utoipa::path(post, path = "/api/sim/devices/{device}/online", tag = "simulation",
    summary = "Take a simulated device online",
    params(("device" = String, Path, min_length = 1)),
    responses((status = 200, description = "OK", body = inline(DeviceState)), (status = 400), (status = 404), (status = 503, description = "Its audit record could be neither stored nor spooled")))]
pub async fn online(
    State(s): State<WebState>,
    Extension(who): Extension<Principal>,
    Path(device): Path<String>,
) -> ApiResult<Json<DeviceState>> {
    set_offline(s, who, device, false).await
}

#[utoipa::path(get, path = "/api/sim/state", tag = "simulation",
    summary = "The simulated devices, panels and plant inputs (demo and replay only)",
    responses((status = 200, description = "OK", body = SimState), (status = 404)))]
pub async fn state(State(s): State<WebState>) -> ApiResult<Json<SimState>> {
    Ok(Json(sim(&s)?.state()))
}

#[utoipa::path(put, path = "/api/sim/devices/{device}/link", tag = "simulation",
    summary = "Slow a simulated device's replies or damage them",
    params(("device" = String, Path, min_length = 1)),
    request_body = LinkFaults,
    responses((status = 200, description = "OK", body = LinkFaults), (status = 400), (status = 404), (status = 503, description = "Its audit record could be neither stored nor spooled")))]
pub async fn link(
    State(s): State<WebState>,
    Extension(who): Extension<Principal>,
    Path(device): Path<String>,
    body: Result<Json<LinkFaults>, axum::extract::rejection::JsonRejection>,
) -> ApiResult<Json<LinkFaults>> {
    let Json(mut b) = body.map_err(|e| ApiError::bad_request(e.body_text()))?;
    if b.slow_reply_ms.is_some_and(|ms| ms > 60_000) {
        return Err(ApiError::bad_request(
            "slow_reply_ms: at most 60000 ms of added latency",
        ));
    }
    if b.slow_reply_ms == Some(0) {
        b.slow_reply_ms = None;
    }
    crate::api::audit_ready(&s).await?;
    sim(&s)?.set_link(&device, &b).map_err(refused)?;
    let slow = match b.slow_reply_ms {
        Some(ms) => format!("replies {ms} ms late"),
        None => "replies without delay".into(),
    };
    let replies = match b.replies {
        ReplyFault::Normal => "correct",
        ReplyFault::Corrupt => "corrupted",
        ReplyFault::Exception => "Modbus exceptions",
    };
    training(
        &s,
        &who,
        &device,
        format!("set simulated device {device} to {slow}, {replies}"),
    )
    .await;
    Ok(Json(b))
}

/// A zone's load.
#[derive(Debug, Deserialize, Serialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct ZoneLoadBody {
    /// Active power, kW (0 to 10000).
    #[schema(minimum = 0, maximum = 10000)]
    pub kw: f64,
    /// Power factor, above 0 and at most 1.
    #[schema(exclusive_minimum = 0, maximum = 1)]
    pub pf: f64,
}

#[utoipa::path(put, path = "/api/sim/zones/{panel}/{zone}/load", tag = "simulation",
    summary = "Change a simulated zone's load",
    params(("panel" = String, Path, min_length = 1), ("zone" = u8, Path)),
    request_body = ZoneLoadBody,
    responses((status = 200, description = "OK", body = ZoneLoadBody), (status = 400), (status = 404), (status = 503, description = "Its audit record could be neither stored nor spooled")))]
pub async fn zone_load(
    State(s): State<WebState>,
    Extension(who): Extension<Principal>,
    Path((panel, zone)): Path<(String, u8)>,
    body: Result<Json<ZoneLoadBody>, axum::extract::rejection::JsonRejection>,
) -> ApiResult<Json<ZoneLoadBody>> {
    let Json(b) = body.map_err(|e| ApiError::bad_request(e.body_text()))?;
    if !(b.kw.is_finite() && (0.0..=10_000.0).contains(&b.kw)) {
        return Err(ApiError::bad_request(format!(
            "kw: {} is not between 0 and 10000",
            b.kw
        )));
    }
    if !(b.pf.is_finite() && b.pf > 0.0 && b.pf <= 1.0) {
        return Err(ApiError::bad_request(format!(
            "pf: {} is not above 0 and at most 1",
            b.pf
        )));
    }
    crate::api::audit_ready(&s).await?;
    sim(&s)?
        .set_zone_load(&panel, zone, b.kw, b.pf)
        .map_err(refused)?;
    training(
        &s,
        &who,
        &panel,
        format!(
            "set the load of zone {zone} of panel {panel} to {} kW at PF {}",
            b.kw, b.pf
        ),
    )
    .await;
    Ok(Json(b))
}

/// The profile a plant input is to follow.
#[derive(Debug, Deserialize, Serialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct InputBody {
    pub profile: InputProfile,
}

#[utoipa::path(put, path = "/api/sim/inputs/{input}", tag = "simulation",
    summary = "Override or scale a plant input profile (irradiance, wind speed, demand)",
    params(("input" = String, Path, description = "irradiance, wind_speed or demand")),
    request_body = InputBody,
    responses((status = 200, description = "OK", body = InputBody), (status = 400), (status = 404), (status = 503, description = "Its audit record could be neither stored nor spooled")))]
pub async fn input(
    State(s): State<WebState>,
    Extension(who): Extension<Principal>,
    path: Result<Path<PlantInput>, axum::extract::rejection::PathRejection>,
    body: Result<Json<InputBody>, axum::extract::rejection::JsonRejection>,
) -> ApiResult<Json<InputBody>> {
    let Path(input) = path.map_err(|_| {
        ApiError::not_found("no such plant input; expected irradiance, wind_speed or demand")
    })?;
    let Json(b) = body.map_err(|e| ApiError::bad_request(e.body_text()))?;
    match b.profile {
        InputProfile::Scaled { factor }
            if !(factor.is_finite() && (0.0..=10.0).contains(&factor)) =>
        {
            return Err(ApiError::bad_request(format!(
                "factor: {factor} is not between 0 and 10"
            )));
        }
        InputProfile::Constant { value } if !(value.is_finite() && value >= 0.0) => {
            return Err(ApiError::bad_request(format!(
                "value: {value} is not a number of 0 or more"
            )));
        }
        InputProfile::Daily => {
            return Err(ApiError::bad_request(
                "profile: a daily table comes from a scenario file; here use builtin, scaled or constant",
            ));
        }
        _ => {}
    }
    crate::api::audit_ready(&s).await?;
    sim(&s)?.set_input(input, &b.profile).map_err(refused)?;
    training(
        &s,
        &who,
        "simulation",
        format!("set the {} to {}", input.label(), b.profile.describe()),
    )
    .await;
    Ok(Json(b))
}
