//! The schemas of what the API carries that is not the web crate's own type:
//! values and records of the tag database, the alarm engine, the control
//! loops and the store. Each is named after the component schema it makes
//! and follows the serde form of the type it stands for; the web crate's own
//! request and answer types derive their schemas where they are declared.
//!
//! They stand here, not in the crates that own the types, so that those
//! crates need not depend on an OpenAPI library.

#![allow(dead_code)]

use std::collections::BTreeMap;

use utoipa::openapi::schema::Schema;
use utoipa::openapi::RefOr;
use utoipa::{PartialSchema, ToSchema};

/// A schema written out as JSON, for the few whose serde form no derive
/// describes (a value that is a number or a string of digits, a time that is
/// milliseconds or RFC 3339 text).
fn from_json(v: serde_json::Value) -> RefOr<Schema> {
    serde_json::from_value(v).expect("a valid schema")
}

/// Every error answer.
#[derive(ToSchema)]
#[schema(as = Error)]
#[serde(deny_unknown_fields)]
pub struct ErrorBody {
    pub error: String,
    pub detail: String,
}

/// `gridscada_tagdb::Timestamp`: milliseconds since 1970-01-01 UTC.
pub struct Timestamp;
impl PartialSchema for Timestamp {
    fn schema() -> RefOr<Schema> {
        from_json(serde_json::json!({
            "type": "integer",
            "description": "Milliseconds since 1970-01-01 UTC"
        }))
    }
}
impl ToSchema for Timestamp {}

/// `gridscada_tagdb::Value` in its JSON form (`server/tagdb/src/value.rs`),
/// the component `Value`. (Not named `Value`: utoipa takes a field of a type
/// of that name for `serde_json::Value`.)
pub struct TagValue;
impl PartialSchema for TagValue {
    fn schema() -> RefOr<Schema> {
        from_json(serde_json::json!({
            "description": "A tag value. An integer within ±2^53 is a number; an integer outside it (a u64 or i64 register) is a string of its decimal digits, exact; a datetime tag is RFC 3339 text. A string of digits written to an integer tag is taken exactly.",
            "anyOf": [
                {"type": "boolean"},
                {"type": "integer"},
                {"type": "number"},
                {"type": "string"}
            ]
        }))
    }
}
impl ToSchema for TagValue {
    fn name() -> std::borrow::Cow<'static, str> {
        "Value".into()
    }
}

/// A time in a query, as `api::parse_time` takes it: for a required
/// parameter `#[param(value_type = shapes::Time, inline)]`, for an optional
/// one `#[param(schema_with = shapes::time, required = false)]`.
pub struct Time;
impl PartialSchema for Time {
    fn schema() -> RefOr<Schema> {
        time()
    }
}
impl ToSchema for Time {}

/// The schema of [`Time`].
pub fn time() -> RefOr<Schema> {
    from_json(serde_json::json!({
        "anyOf": [
            {"type": "string", "pattern": "^\\s*-?[0-9]+\\s*$"},
            {"type": "string", "format": "date-time"}
        ],
        "description": "Milliseconds since 1970-01-01 UTC, or an RFC 3339 date and time"
    }))
}

/// A screen id (`gridscada_config::ScreenId` as text).
pub struct Screen;
impl PartialSchema for Screen {
    fn schema() -> RefOr<Schema> {
        from_json(serde_json::json!({
            "type": "string",
            "minLength": 1,
            "maxLength": 128,
            "description": "A screen id: a built-in screen, a panel's id, or custom:<id> for a user-drawn screen"
        }))
    }
}
impl ToSchema for Screen {}

/// `gridscada_config::Role`.
#[derive(ToSchema)]
#[schema(as = Role)]
#[serde(rename_all = "lowercase")]
pub enum Role {
    Display,
    Guest,
    Operator,
    Supervisor,
    Administrator,
}

#[derive(ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum QualityCode {
    Good,
    Uncertain,
    Bad,
}

/// `gridscada_tagdb::Quality`.
#[derive(ToSchema)]
#[schema(as = Quality)]
#[serde(deny_unknown_fields)]
pub struct Quality {
    #[schema(inline)]
    pub code: QualityCode,
    #[schema(required = false)]
    pub reason: String,
}

/// `gridscada_tagdb::ValueKind`.
#[derive(ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum ValueKind {
    Bool,
    Int,
    Float,
    Str,
}

/// `gridscada_config::RegisterKind`.
#[derive(ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum RegisterKind {
    Coil,
    DiscreteInput,
    InputRegister,
    HoldingRegister,
}

/// `gridscada_config::DateFormat`, by its pattern.
#[derive(ToSchema)]
pub enum DateFormat {
    #[serde(rename = "YYYY-MM-DD")]
    Iso,
    #[serde(rename = "DD.MM.YYYY")]
    DayDotted,
    #[serde(rename = "DD/MM/YYYY")]
    DaySlashed,
    #[serde(rename = "MM/DD/YYYY")]
    MonthSlashed,
}

/// `gridscada_config::Endian`.
#[derive(ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum Endian {
    Big,
    Little,
}

/// A tag as the API shows it (`api::tags::TagView`, its sample flattened).
#[derive(ToSchema)]
#[schema(as = Tag)]
#[serde(deny_unknown_fields)]
pub struct Tag {
    pub name: String,
    pub description: String,
    pub units: String,
    #[schema(inline)]
    pub kind: ValueKind,
    pub writable: bool,
    #[schema(required = true)]
    pub write_role: Option<Role>,
    pub value: TagValue,
    pub quality: Quality,
    pub timestamp: Timestamp,
    /// The field register behind the tag; null for derived tags
    #[schema(required = true)]
    pub source: Option<crate::api::tags::TagSource>,
    /// Words for the tag's values (keys "true"/"false" or whole numbers), e.g. {"false": "TRIPPED", "true": "CLOSED"}; null when none are configured
    #[schema(required = true)]
    pub states: Option<BTreeMap<String, String>>,
    /// The engineering limits a write must respect (either bound may be null); null for a tag that is not writable or has none
    #[schema(required = true)]
    pub limits: Option<crate::api::tags::WriteLimits>,
    /// Decimals the HMI shows the value with (the tag's `decimals`, else the plant's `[hmi] decimals` for an analog value, 0 for an integer); null for a bool or text
    #[schema(required = true, minimum = 0, maximum = 6)]
    pub decimals: Option<u8>,
}

/// `gridscada_store::UserSummary`.
#[derive(ToSchema)]
#[schema(as = User)]
#[serde(deny_unknown_fields)]
pub struct User {
    pub name: String,
    pub role: Role,
    pub blocked: bool,
    pub group: String,
    pub created_at: Timestamp,
    pub password_changed_at: Timestamp,
}

/// `gridscada_store::Event`.
#[derive(ToSchema)]
#[schema(as = Event)]
pub struct Event {
    pub id: i64,
    pub ts: Timestamp,
    #[schema(required = true)]
    pub user: Option<String>,
    pub source: String,
    pub kind: String,
    pub message: String,
}

#[derive(ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum AlarmState {
    Normal,
    UnackActive,
    AckActive,
    UnackRtn,
    Shelved,
    Suppressed,
    OutOfService,
}

/// An alarm as the alarm list shows it (more fields: tag, kind, value (the value now), value_text (the value in the tag's words, e.g. TRIPPED), activation_value (the value at the latest activation, which the message shows; kept after it clears, null if unknown), activation_value_text (it in the tag's words), limit, units, active_since (while active), activated_at (the latest activation, kept after it clears), cleared_at (when it cleared, null while active), shelved, out_of_service, suppressed).
#[derive(ToSchema)]
#[schema(as = Alarm)]
pub struct Alarm {
    #[schema(maximum = 4294967295_u32)]
    pub id: u32,
    pub key: String,
    #[schema(inline)]
    pub state: AlarmState,
    pub active: bool,
    pub acked: bool,
    #[schema(maximum = 4294967295_u32)]
    pub priority: u32,
    pub selection: String,
    pub message: String,
    pub last_change: Timestamp,
}

/// `gridscada_alarms::AlarmMetrics` (more fields: the ISA-18.2 figures; `positions`, the load of each selection as if one operator position had it alone; `shelved`, the alarms shelved now; `targets`, the ISA-18.2 targets).
#[derive(ToSchema)]
pub struct AlarmMetrics {
    pub from: Timestamp,
    pub to: Timestamp,
    #[schema(maximum = 4294967295_u32)]
    pub operators: u32,
    #[schema(maximum = 4294967295_u32)]
    pub total_activations: u32,
}

/// One recorded alarm transition (more fields: ts, alarm_key, tag, kind, from_state, to_state, activation (an annunciated activation), value (at the transition), limit, user, message, priority, selection).
#[derive(ToSchema)]
#[schema(as = AlarmTransition)]
pub struct AlarmTransition {
    pub id: i64,
    /// Why it happened. An activation or a return while the alarm is suppressed, shelved or out of service leaves from_state equal to to_state: the cause tells which. Null on rows recorded before causes were kept
    #[schema(required = true)]
    pub cause: Option<TransitionCause>,
}

/// `gridscada_alarms::TransitionCause`: why an alarm transition happened.
#[derive(ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum TransitionCause {
    Activate,
    Return,
    Ack,
    Shelve,
    Unshelve,
    ShelveExpired,
    Suppress,
    Unsuppress,
    OutOfService,
    InService,
}

#[derive(ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum PanelMode {
    Auto,
    Manual,
}

/// `gridscada_control::fault_isolation::PanelStatus`, with the panel's tag
/// prefix.
#[derive(ToSchema)]
#[schema(as = PanelStatus)]
pub struct PanelStatus {
    pub id: String,
    pub name: String,
    #[schema(inline)]
    pub mode: PanelMode,
    pub step: String,
    pub zones: u8,
    #[schema(value_type = Object)]
    pub breakers: (),
    pub faulty_zones: Vec<u8>,
    pub load0_faulty: bool,
    pub lockout: bool,
    pub comm_ok: bool,
    pub last_sequence: SequenceFigures,
    /// How the last sequence was resumed after a restart or a failover:
    /// "sequence resumed after a restart|failover at step '...': ..." (at
    /// which step, what was tested again); null if it was not
    #[schema(required = true)]
    pub resumed: Option<String>,
    /// Tag prefix of the panel's I/O, e.g. SS1
    #[schema(required = false)]
    pub prefix: String,
    /// With a switching network: the standing safety tags on the panel's
    /// breakers, by breaker ("elcb", "mccb", "zone2"): `device` (the
    /// network's id), `kind` and `label` of the strongest, `tags` (each in
    /// words)
    #[schema(required = false, value_type = Object)]
    pub safety_tags: (),
}

#[derive(ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum SequenceOutcome {
    None,
    Running,
    Restored,
    Isolated,
    Lockout,
    Stopped,
}

/// `gridscada_control::fault_isolation::Metrics`: how the panel's last
/// sequence went.
#[derive(ToSchema)]
#[schema(as = SequenceFigures)]
pub struct SequenceFigures {
    /// Seconds from the first trip (or Reset) until every load not known
    /// faulty was confirmed closed; null before the first sequence, while one
    /// runs, and when it did not restore (lockout, stopped)
    #[schema(required = true)]
    pub restore_s: Option<f64>,
    pub switching_ops: u32,
    pub reenergisations: u32,
    /// 2 × reclose delay + (N + 1) × dwell
    pub bound_s: f64,
    pub trips: u32,
    pub elcb_resets: u32,
    #[schema(inline)]
    pub outcome: SequenceOutcome,
}

#[derive(ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum DispatchMode {
    Optimal,
    Fallback,
}

/// `gridscada_control::dispatch::DispatchStatus`.
#[derive(ToSchema)]
#[schema(as = DispatchStatus)]
pub struct DispatchStatus {
    pub at: Timestamp,
    #[schema(inline)]
    pub mode: DispatchMode,
    pub status: String,
    pub reason: Option<String>,
    #[schema(value_type = Object, required = false)]
    pub setpoints_kw: (),
    #[schema(required = false)]
    pub run_cmd: BTreeMap<String, bool>,
    #[schema(required = false)]
    pub shed_kw: f64,
    pub objective: Option<f64>,
    pub solve_ms: Option<f64>,
    #[schema(required = false)]
    pub write_failures: Vec<String>,
    pub horizon: Option<HorizonPlan>,
}

/// The look-ahead plan in force (with [microgrid.horizon] only): forecasts,
/// planned state of charge and diesel output per period, and the worth of a
/// stored kWh that prices storage in each dispatch.
#[derive(ToSchema)]
#[schema(as = HorizonPlan)]
pub struct HorizonPlan {
    pub at: Timestamp,
    pub periods: u64,
    pub period_s: f64,
    /// optimal, infeasible or error
    pub status: String,
    pub reason: Option<String>,
    pub objective: Option<f64>,
    pub solve_ms: Option<f64>,
    #[schema(required = false)]
    pub demand_kw: Vec<f64>,
    #[schema(required = false)]
    pub renewable_kw: Vec<f64>,
    #[schema(required = false)]
    pub soc_kwh: BTreeMap<String, Vec<f64>>,
    #[schema(required = false)]
    pub diesel_kw: BTreeMap<String, Vec<f64>>,
    #[schema(required = false)]
    pub stored_energy_value_per_kwh: BTreeMap<String, f64>,
}

/// `gridscada_store::DispatchRecord`.
#[derive(ToSchema)]
#[schema(as = DispatchRecord)]
pub struct DispatchRecord {
    pub id: i64,
    pub ts: Timestamp,
    pub status: String,
    pub mode: String,
    #[schema(required = true)]
    pub objective: Option<f64>,
    pub solve_ms: f64,
    pub inputs: serde_json::Value,
    pub setpoints: serde_json::Value,
    #[schema(required = true)]
    pub reason: Option<String>,
}

#[derive(ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum UnitKind {
    Pv,
    Wind,
    Storage,
    Diesel,
}

/// `gridscada_config::UnitConfig`: the ratings present depend on the kind.
#[derive(ToSchema)]
#[schema(as = MicrogridUnit)]
pub struct MicrogridUnit {
    pub id: String,
    #[schema(inline)]
    pub kind: UnitKind,
    pub name: String,
    pub prefix: String,
    #[schema(required = false)]
    pub rated_kw: f64,
    #[schema(required = false)]
    pub cost_per_kwh: f64,
    #[schema(required = false)]
    pub min_kw: f64,
    #[schema(required = false)]
    pub max_kw: f64,
    #[schema(required = false)]
    pub ramp_kw_per_s: f64,
    #[schema(required = false)]
    pub capacity_kwh: f64,
    #[schema(required = false)]
    pub soc_min_kwh: f64,
    #[schema(required = false)]
    pub soc_max_kwh: f64,
    #[schema(required = false)]
    pub max_charge_kw: f64,
    #[schema(required = false)]
    pub max_discharge_kw: f64,
    #[schema(required = false)]
    pub eff_charge: f64,
    #[schema(required = false)]
    pub eff_discharge: f64,
    #[schema(required = false)]
    pub cycle_cost_per_kwh: f64,
}

#[derive(ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum ScreenKind {
    Builtin,
    Panel,
    Custom,
}

/// Where a screen sits in the HMI's navigation (`access::ScreenGroup`).
#[derive(ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum ScreenGroup {
    Process,
    Alarms,
    Trends,
    Engineering,
    Administration,
}

/// A screen of the catalog (`api::screens::CatalogEntry`, its
/// `access::ScreenEntry` flattened).
#[derive(ToSchema)]
#[serde(deny_unknown_fields)]
pub struct CatalogEntry {
    pub id: Screen,
    pub label: String,
    #[schema(inline)]
    pub kind: ScreenKind,
    #[schema(inline)]
    pub group: ScreenGroup,
    #[schema(required = false)]
    pub panel: String,
    #[schema(required = false)]
    pub version: i64,
    pub allowed: bool,
}

#[derive(ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum ElementType {
    Text,
    Line,
    Rect,
    Breaker,
    Value,
    Bar,
    Multistate,
    Button,
    Trend,
    Link,
    Panel,
}

/// One element of a drawn screen (its other fields depend on the type).
#[derive(ToSchema)]
pub struct ScreenElement {
    #[schema(inline)]
    #[serde(rename = "type")]
    pub kind: ElementType,
    pub x: i64,
    pub y: i64,
    pub w: i64,
    pub h: i64,
}

/// A screen drawn in the editor (see docs/OWN_PLANT.md for the element types)
#[derive(ToSchema)]
#[schema(as = UserScreen)]
#[serde(deny_unknown_fields)]
pub struct UserScreen {
    #[schema(pattern = "^[a-z0-9][a-z0-9_-]{0,63}$")]
    pub id: String,
    #[schema(min_length = 1, max_length = 256)]
    pub name: String,
    #[schema(minimum = 0, required = false)]
    pub version: i64,
    #[schema(minimum = 100, maximum = 10000, required = false)]
    pub width: i64,
    #[schema(minimum = 100, maximum = 10000, required = false)]
    pub height: i64,
    #[schema(max_items = 2000, inline, required = false)]
    pub elements: Vec<ScreenElement>,
}
