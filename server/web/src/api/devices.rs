//! `/api/devices`: the communication state of every field device and link,
//! for the engineer commissioning them.
//!
//! The figures come from the application through a [`DeviceSource`], so this
//! crate needs no knowledge of Modbus.

use axum::extract::State;
use axum::Json;
use serde::Serialize;
use utoipa::ToSchema;

use crate::error::{ApiError, ApiResult};
use crate::WebState;

/// One device as the devices screen shows it.
#[derive(Debug, Clone, Default, PartialEq, Serialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct DeviceView {
    pub name: String,
    pub description: String,
    /// The connection or serial port it shares with others.
    pub link: String,
    pub protocol: String,
    /// `host:port` for TCP, the serial port for RTU.
    pub address: String,
    pub unit_id: u8,
    /// The fastest scan period configured for its tags.
    pub scan_ms: u64,
    /// Scans completed per second, over the last few seconds.
    #[schema(minimum = 0)]
    pub achieved_scans_per_s: f64,
    /// Round trip of the last answered request.
    pub response_ms: f64,
    pub requests: u64,
    pub errors: u64,
    pub timeouts: u64,
    pub exceptions: u64,
    pub writes: u64,
    pub late_scans: u64,
    pub overruns: u64,
    pub connected: bool,
    /// A failing device is not scanned; it is probed at growing intervals
    /// until it answers again.
    pub backing_off: bool,
    pub last_error: String,
    /// A telecontrol station's link (IEC 104, DNP3, IEC 61850); null for Modbus devices.
    #[schema(required = true)]
    pub telecontrol: Option<TelecontrolView>,
}

/// The link of a telecontrol station (IEC 104, DNP3, IEC 61850).
#[derive(Debug, Clone, Default, PartialEq, Serialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct TelecontrolView {
    /// started (data transfer on), tested (connected, kept as standby),
    /// stopped (no connection)
    pub state: String,
    /// Spontaneous data received (objects)
    pub events: u64,
    /// General interrogations completed
    pub interrogations: u64,
    /// Seconds since the last general interrogation completed; null: none yet
    #[schema(required = true)]
    pub interrogation_age_s: Option<f64>,
    /// Commands sent
    pub commands: u64,
    /// Commands refused or not confirmed
    pub commands_failed: u64,
    /// The station's clock minus ours at the last clock synchronisation, ms; null: not synchronised
    #[schema(required = true)]
    pub clock_offset_ms: Option<f64>,
    /// Events the station reported lost (buffer overflow)
    pub overflows: u64,
}

/// One connection or serial port.
#[derive(Debug, Clone, Default, PartialEq, Serialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct LinkView {
    pub link: String,
    pub protocol: String,
    pub devices: Vec<String>,
    /// Every device on it answers.
    pub connected: bool,
    pub connects: u64,
    pub disconnects: u64,
    /// Replies that came after their request had timed out (discarded).
    pub late_replies: u64,
    /// RTU bytes skipped as line noise.
    pub garbage_bytes: u64,
    pub last_error: String,
}

#[derive(Debug, Clone, Default, PartialEq, Serialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct DevicesView {
    pub devices: Vec<DeviceView>,
    pub links: Vec<LinkView>,
}

/// Where the application gets the figures (the poller, in `app`).
pub trait DeviceSource: Send + Sync {
    fn devices(&self) -> DevicesView;
}

#[utoipa::path(get, path = "/api/devices", tag = "devices",
    summary = "Communication state of every field device and link",
    responses((status = 200, description = "OK", body = inline(DevicesView)), (status = 503)))]
pub async fn list(State(s): State<WebState>) -> ApiResult<Json<DevicesView>> {
    let source = s
        .devices
        .as_ref()
        .ok_or_else(|| ApiError::unavailable("field I/O is not running"))?;
    Ok(Json(source.devices()))
}
