//! # gridscada-field: the protocol-neutral device interface
//!
//! **Owns:** what every field protocol (Modbus, IEC 60870-5-104, …) shares
//! with the rest of the server: the names of a device's communication status
//! tags, the device and link figures ([`PollStats`]) that the devices screen
//! and `/metrics` show, the engineering write limits every write is checked
//! against ([`check_limits`]), the returned status point that confirms a
//! telecontrol command ([`ReturnedStatus`]), the serial line settings
//! ([`open_serial`]), in-process pipes to the simulated devices a replay
//! serves itself ([`Switchboard`]), the notices a device's task leaves for the event
//! log ([`Notices`]), and the writer that sends each tag's write to
//! the protocol its device speaks ([`Router`]).
//!
//! **Must not touch:** any protocol's framing or connections (each protocol
//! crate owns its own), SQL, HTTP, alarms. A protocol crate implements
//! [`gridscada_tagdb::TagWriter`] and [`StatsSource`]; `app` puts them
//! together here.

mod feedback;
mod notice;
mod pipe;
mod round_trip;
mod serial;

use std::sync::Arc;

use gridscada_config::Plant;
use gridscada_tagdb::{
    TagDb, TagId, TagMeta, TagWriter, Value, ValueKind, WriteError, WriteFuture,
};

pub use feedback::{within_resolution, ReturnedStatus};
pub use notice::{DeviceNotice, Notices};
pub use pipe::Switchboard;
pub use round_trip::{RoundTripHistogram, RoundTrips, ROUND_TRIP_BOUNDS};
pub use serial::open_serial;

/// Names of a device's communication status tags.
pub fn status_tag_names(device: &str) -> [(String, ValueKind, &'static str, &'static str); 8] {
    [
        (
            format!("{device}.Comm.Connected"),
            ValueKind::Bool,
            "",
            "Device answers its requests",
        ),
        (
            format!("{device}.Comm.LastError"),
            ValueKind::Str,
            "",
            "Last communication error",
        ),
        (
            format!("{device}.Comm.ResponseMs"),
            ValueKind::Float,
            "ms",
            "Response time of the last answered request",
        ),
        (
            format!("{device}.Comm.Requests"),
            ValueKind::Int,
            "",
            "Requests sent",
        ),
        (
            format!("{device}.Comm.Errors"),
            ValueKind::Int,
            "",
            "Requests without a good answer (timeouts, exceptions, bad replies)",
        ),
        (
            format!("{device}.Comm.Timeouts"),
            ValueKind::Int,
            "",
            "Requests that timed out",
        ),
        (
            format!("{device}.Comm.Overruns"),
            ValueKind::Int,
            "",
            "Scan periods missed because the previous scan ran over",
        ),
        (
            format!("{device}.Comm.Retries"),
            ValueKind::Int,
            "",
            "Reads repeated at once after no answer (the device's retries)",
        ),
    ]
}

/// The ids of one device's status tags in the tag database, in the order
/// of [`status_tag_names`].
#[derive(Debug, Clone, Copy)]
pub struct StatusIds {
    pub connected: TagId,
    pub last_error: TagId,
    pub response_ms: TagId,
    pub requests: TagId,
    pub errors: TagId,
    pub timeouts: TagId,
    pub overruns: TagId,
    pub retries: TagId,
}

impl StatusIds {
    /// Looks up `device`'s status tags; `Err` is the name of one missing
    /// (the app registers them all before it starts a protocol).
    pub fn resolve(db: &TagDb, device: &str) -> Result<StatusIds, String> {
        let names = status_tag_names(device);
        let id = |i: usize| db.id(&names[i].0).ok_or_else(|| names[i].0.clone());
        Ok(StatusIds {
            connected: id(0)?,
            last_error: id(1)?,
            response_ms: id(2)?,
            requests: id(3)?,
            errors: id(4)?,
            timeouts: id(5)?,
            overruns: id(6)?,
            retries: id(7)?,
        })
    }
}

/// Why a protocol has no write target for `name`: the tag exists but is
/// read-only, or there is no such tag.
pub fn no_write_target(db: &TagDb, name: &str) -> WriteError {
    match db.id(name).and_then(|id| db.meta(id)) {
        Some(_) => WriteError::ReadOnly(name.to_string()),
        None => WriteError::UnknownTag(name.to_string()),
    }
}

/// What a telecontrol device's task shows in its status tags.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct StatusFigures {
    pub connected: bool,
    pub response_ms: f64,
    pub requests: u64,
    pub errors: u64,
    pub timeouts: u64,
}

impl StatusIds {
    /// Writes `f` into the status tags, stamped `ts`.
    pub fn publish(&self, db: &TagDb, ts: gridscada_tagdb::Timestamp, f: StatusFigures) {
        use gridscada_tagdb::Sample;
        db.apply([
            (self.connected, Sample::good(f.connected, ts)),
            (self.response_ms, Sample::good(f.response_ms, ts)),
            (self.requests, Sample::good(Value::from_u64(f.requests), ts)),
            (self.errors, Sample::good(Value::from_u64(f.errors), ts)),
            (self.timeouts, Sample::good(Value::from_u64(f.timeouts), ts)),
        ]);
    }
}

/// The communication status tags of every device, for the app to register
/// before it builds the [`TagDb`].
pub fn device_status_tags(plant: &Plant) -> Vec<TagMeta> {
    plant
        .devices
        .iter()
        .flat_map(|d| {
            status_tag_names(d.name.get_ref())
                .into_iter()
                .map(|(name, kind, units, desc)| {
                    TagMeta::new(name, kind)
                        .units(units)
                        .describe(format!("{}: {desc}", d.name.get_ref()))
                })
        })
        .collect()
}

/// Request and scan counters of one device.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct DeviceStats {
    pub device: String,
    /// The connection or port the device is on.
    pub link: String,
    pub connected: bool,
    pub requests: u64,
    /// Requests without a good answer (timeouts and exceptions included).
    pub errors: u64,
    pub timeouts: u64,
    pub exceptions: u64,
    pub writes: u64,
    pub scans: u64,
    /// Scans that started more than 10 % of their period after they were due.
    pub late_scans: u64,
    /// Scan periods skipped because a scan ran over.
    pub overruns: u64,
    /// Round trip of the last answered request, wall time.
    pub last_response_ms: f64,
    /// Round trips of every answered request, wall time.
    pub round_trip: RoundTripHistogram,
    /// Telecontrol links (IEC 104): the state of the device's connection
    /// ("started", "connected", "testing", "stopped"); empty for Modbus.
    pub state: String,
    /// Spontaneous or event data received.
    pub events: u64,
    /// General interrogations completed.
    pub interrogations: u64,
    /// When the last general interrogation completed, Unix ms.
    pub last_interrogation_ms: Option<i64>,
    /// Writes (commands) the device refused or did not confirm.
    pub writes_failed: u64,
    /// The device clock minus ours at the last clock synchronisation, ms.
    pub clock_offset_ms: Option<f64>,
    /// The device reported lost events (buffer overflow).
    pub overflows: u64,
}

/// Counters of one connection or serial port.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct LinkStats {
    pub link: String,
    pub connects: u64,
    pub disconnects: u64,
    /// Replies discarded because their request had already timed out.
    pub late_replies: u64,
    /// RTU bytes skipped as noise.
    pub garbage_bytes: u64,
    pub last_error: String,
}

#[derive(Debug, Clone, Default, PartialEq)]
pub struct PollStats {
    pub devices: Vec<DeviceStats>,
    pub links: Vec<LinkStats>,
}

impl PollStats {
    /// Sums over every device.
    pub fn total(&self) -> DeviceStats {
        let mut t = DeviceStats {
            device: "total".into(),
            ..Default::default()
        };
        for d in &self.devices {
            t.requests += d.requests;
            t.errors += d.errors;
            t.timeouts += d.timeouts;
            t.exceptions += d.exceptions;
            t.writes += d.writes;
            t.scans += d.scans;
            t.late_scans += d.late_scans;
            t.overruns += d.overruns;
        }
        t.connected = self.devices.iter().all(|d| d.connected);
        t
    }

    pub fn device(&self, name: &str) -> Option<&DeviceStats> {
        self.devices.iter().find(|d| d.device == name)
    }
}

/// A protocol's running devices, as the figures see them.
pub trait StatsSource: Send + Sync {
    /// Counters of the protocol's devices and links.
    fn stats(&self) -> PollStats;
    /// Connection attempts and requests waiting for an answer right now.
    /// Replay on a virtual clock advances plant time only when every
    /// protocol's count is zero, so no answer is ever outrun by the clock.
    fn in_flight(&self) -> u64;
}

/// The figures of every protocol together; cheap to clone, lives past the
/// protocols' tasks.
#[derive(Clone, Default)]
pub struct StatsHandle {
    sources: Vec<Arc<dyn StatsSource>>,
}

impl StatsHandle {
    pub fn new(sources: Vec<Arc<dyn StatsSource>>) -> StatsHandle {
        StatsHandle { sources }
    }

    pub fn in_flight(&self) -> u64 {
        self.sources.iter().map(|s| s.in_flight()).sum()
    }

    /// Counters of every device and link, in configuration order within
    /// each protocol.
    pub fn stats(&self) -> PollStats {
        let mut all = PollStats::default();
        for s in &self.sources {
            let PollStats { devices, links } = s.stats();
            all.devices.extend(devices);
            all.links.extend(links);
        }
        all
    }
}

/// Refuses a numeric value outside `limits`.
pub fn check_limits(
    name: &str,
    value: &Value,
    limits: (Option<f64>, Option<f64>),
) -> Result<(), WriteError> {
    let v = match value {
        Value::Float(_) | Value::Int(_) | Value::UInt(_) => value.as_f64().unwrap_or(f64::NAN),
        _ => return Ok(()),
    };
    let (lo, hi) = limits;
    let inside = !v.is_nan() && lo.is_none_or(|lo| v >= lo) && hi.is_none_or(|hi| v <= hi);
    if inside {
        return Ok(());
    }
    let limits = match (lo, hi) {
        (Some(lo), Some(hi)) => format!("{lo} to {hi}"),
        (Some(lo), None) => format!("at least {lo}"),
        (None, Some(hi)) => format!("at most {hi}"),
        (None, None) => "a number".to_string(),
    };
    Err(WriteError::OutOfLimits {
        tag: name.to_string(),
        value: value.to_string(),
        limits,
    })
}

/// The one writer of the field: each tag's write goes to the writer of the
/// protocol its device speaks. Control loops, the HMI and northbound hold
/// this, never a protocol's own.
pub struct Router {
    db: Arc<TagDb>,
    writers: Vec<Arc<dyn TagWriter>>,
    /// By tag id: the index in `writers` of the tag's protocol, `NO_ROUTE`
    /// for a tag no protocol serves. One byte a tag, not a map of names.
    route: Vec<u8>,
}

const NO_ROUTE: u8 = u8::MAX;

impl Router {
    /// `writers`: each protocol's writer with the tags it serves, by the
    /// names `db` knows them by (a name it does not know has no route).
    pub fn new<'a>(
        db: Arc<TagDb>,
        writers: impl IntoIterator<Item = (Arc<dyn TagWriter>, Vec<&'a str>)>,
    ) -> Router {
        let mut route = vec![NO_ROUTE; db.len()];
        let mut all = Vec::new();
        for (writer, tags) in writers {
            let index = u8::try_from(all.len())
                .ok()
                .filter(|i| *i != NO_ROUTE)
                .expect("fewer than 255 protocol writers");
            all.push(writer);
            for t in tags {
                if let Some(slot) = db.id(t).and_then(|id| route.get_mut(id.index())) {
                    *slot = index;
                }
            }
        }
        Router {
            db,
            writers: all,
            route,
        }
    }

    /// The tags of `plant` whose device's protocol satisfies `speaks`.
    pub fn tags_of(
        plant: &Plant,
        speaks: impl Fn(gridscada_config::Protocol) -> bool,
    ) -> Vec<&str> {
        plant
            .tags
            .iter()
            .filter(|t| {
                plant
                    .device(t.device.get_ref())
                    .is_some_and(|d| speaks(d.protocol))
            })
            .map(|t| t.name.get_ref().as_str())
            .collect()
    }
}

impl TagWriter for Router {
    fn write<'a>(&'a self, name: &'a str, value: Value) -> WriteFuture<'a> {
        let writer = self
            .db
            .id(name)
            .and_then(|id| self.route.get(id.index()))
            .and_then(|&i| self.writers.get(usize::from(i)));
        match writer {
            Some(w) => w.write(name, value),
            None => Box::pin(async move { Err(WriteError::UnknownTag(name.to_string())) }),
        }
    }
}

#[cfg(test)]
mod limit_tests {
    use super::*;

    #[test]
    fn writes_outside_the_engineering_limits_are_refused() {
        let pv = (Some(0.0), Some(100.0));
        for bad in [-1e6, 1e30, -5.0, f64::NAN] {
            let e = check_limits("MG.PV1.Setpoint_kW", &Value::Float(bad), pv).unwrap_err();
            assert!(
                e.to_string()
                    .contains("outside the engineering limits of 'MG.PV1.Setpoint_kW' (0 to 100)"),
                "{e}"
            );
        }
        for good in [0.0, 42.5, 100.0] {
            assert!(check_limits("T", &Value::Float(good), pv).is_ok());
        }
        assert!(check_limits("T", &Value::Int(-3), (Some(0.0), None)).is_err());
        assert!(check_limits("T", &Value::Int(3), (None, Some(2.0))).is_err());
        assert!(check_limits("T", &Value::Bool(true), pv).is_ok());
    }
}
