//! The I/O shell of the IEC 61850 client: one task per configured IED
//! (`protocol = "iec61850"`), its association and reports, its tags'
//! samples in the tag database, its status tags, and its controls through
//! [`gridscada_tagdb::TagWriter`].
//!
//! **Must not touch:** other protocols' devices and tags, configuration
//! parsing (it takes a checked [`Plant`]), alarms, SQL.

pub mod connection;
mod ied;
mod points;

use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Duration;

use gridscada_config::{
    rcb_parts, CtlModel, DataType, Iec61850DeviceConfig, ObjectRef, Plant, Protocol,
};
use gridscada_field::{
    check_limits, within_resolution, DeviceNotice, DeviceStats, LinkStats, Notices, PollStats,
    ReturnedStatus, RoundTrips, StatsSource,
};
use gridscada_tagdb::{Clock, Leadership, TagDb, TagId, TagWriter, Value, WriteError, WriteFuture};
use parking_lot::Mutex;
use tokio::sync::{mpsc, oneshot, watch};
use tokio::task::JoinHandle;

pub use connection::{Connection, MmsError, Unsolicited};
use ied::{Ied, ReportSettings, Settings};
use points::IedTag;

use crate::iso::Addressing;

/// Why the client cannot start.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum StartError {
    #[error("tag '{0}' is in the configuration but not in the tag database")]
    MissingTag(String),
    #[error("device '{device}': {reason}")]
    Device { device: String, reason: String },
}

/// Counters of one IED, written by its task.
#[derive(Default)]
pub(crate) struct Counters {
    pub connected: AtomicBool,
    pub requests: AtomicU64,
    pub errors: AtomicU64,
    pub timeouts: AtomicU64,
    pub events: AtomicU64,
    pub commands: AtomicU64,
    pub commands_failed: AtomicU64,
    pub overflows: AtomicU64,
    pub connects: AtomicU64,
    pub disconnects: AtomicU64,
    pub malformed: AtomicU64,
    pub round_trips: RoundTrips,
    pub response_us: AtomicU64,
    pub last_error: Mutex<String>,
}

impl Counters {
    fn observe(&self, d: Duration) {
        self.round_trips.observe(d);
        self.response_us.store(
            u64::try_from(d.as_micros()).unwrap_or(u64::MAX),
            Ordering::Relaxed,
        );
    }
}

/// How a writable tag operates its controllable object.
#[derive(Debug, Clone)]
pub(crate) struct ControlSpec {
    pub tag: Arc<str>,
    pub domain: String,
    pub ln: String,
    /// The data object's path below the logical node, `$`-joined.
    pub data_object: String,
    pub ctl_model: Option<CtlModel>,
    pub interlock_check: bool,
    pub synchro_check: bool,
    pub test: bool,
    /// The tag reads a Dbpos (1 off, 2 on) and commands a boolean.
    pub double_point: bool,
    pub scale: f64,
    pub offset: f64,
}

impl ControlSpec {
    /// The object as the standard names it, `LD/LN.DO`.
    pub fn label(&self) -> String {
        format!(
            "{}/{}.{}",
            self.domain,
            self.ln,
            self.data_object.replace('$', ".")
        )
    }
}

/// A control on its way to an IED's task.
pub(crate) struct CommandRequest {
    pub spec: ControlSpec,
    pub value: Value,
    pub originator: String,
    pub reply: oneshot::Sender<Result<(), WriteError>>,
}

struct Target {
    ied: usize,
    device: String,
    id: TagId,
    spec: ControlSpec,
    limits: (Option<f64>, Option<f64>),
    command_timeout: Duration,
}

struct Shared {
    ieds: Vec<mpsc::Sender<CommandRequest>>,
    targets: HashMap<Arc<str>, Target>,
    leadership: Leadership,
    db: Arc<TagDb>,
}

/// The running IEC 61850 client: one task per IED.
pub struct Iec61850Io {
    shared: Arc<Shared>,
    stats: Arc<IedStats>,
    shutdown: watch::Sender<bool>,
    tasks: Vec<JoinHandle<()>>,
    notices: Option<mpsc::Receiver<DeviceNotice>>,
}

struct IedStats {
    ieds: Vec<(String, String, Arc<Counters>)>,
}

fn addressing(c: &Iec61850DeviceConfig) -> Result<Addressing, String> {
    let oid = |s: &str, field: &str| {
        gridscada_config::parse_oid(s)
            .ok_or_else(|| format!("{field} '{s}' is not an object identifier"))
    };
    let hex = |s: &str, field: &str| {
        gridscada_config::parse_hex(s).ok_or_else(|| format!("{field} '{s}' is not hex"))
    };
    Ok(Addressing {
        remote_ap_title: Some(oid(c.remote_ap_title.get_ref(), "remote_ap_title")?),
        remote_ae_qualifier: Some(*c.remote_ae_qualifier.get_ref()),
        local_ap_title: Some(oid(c.local_ap_title.get_ref(), "local_ap_title")?),
        local_ae_qualifier: Some(*c.local_ae_qualifier.get_ref()),
        remote_tsel: hex(c.remote_tsel.get_ref(), "remote_tsel")?,
        remote_ssel: hex(c.remote_ssel.get_ref(), "remote_ssel")?,
        remote_psel: hex(c.remote_psel.get_ref(), "remote_psel")?,
        ..Addressing::default()
    })
}

impl Iec61850Io {
    /// Starts a task for every `protocol = "iec61850"` device of `plant`.
    /// Its tags and the devices' status tags must already be in `db`.
    /// Controls ask `leadership` for permission as they go out.
    pub fn start(
        plant: &Plant,
        db: Arc<TagDb>,
        clock: Arc<dyn Clock>,
        leadership: Leadership,
    ) -> Result<Iec61850Io, StartError> {
        let (shutdown, shutdown_rx) = watch::channel(false);
        let (notices, notices_rx) = Notices::channel(256);
        let mut senders = Vec::new();
        let mut ieds = Vec::new();
        let mut targets = HashMap::new();
        let mut to_start = Vec::new();
        let default_settings = Iec61850DeviceConfig::default();
        for d in plant
            .devices
            .iter()
            .filter(|d| d.protocol == Protocol::Iec61850)
        {
            let name = d.name.get_ref().clone();
            let cfg = d.iec61850.as_ref().unwrap_or(&default_settings);
            let err = |reason: String| StartError::Device {
                device: name.clone(),
                reason,
            };
            let address = d
                .address
                .as_ref()
                .map(|a| a.get_ref().clone())
                .ok_or_else(|| err("an iec61850 device needs address = \"host:port\"".into()))?;
            let index = ieds.len();
            let mut tags = Vec::new();
            for t in plant.tags.iter().filter(|t| t.device.get_ref() == &name) {
                let tname = t.name.get_ref();
                let id = db
                    .id(tname)
                    .ok_or_else(|| StartError::MissingTag(tname.clone()))?;
                let Some(p) = &t.iec61850 else {
                    return Err(err(format!("tag '{tname}' has no iec61850 attribute")));
                };
                tags.push(IedTag::new(id, t, p).map_err(|e| err(format!("tag '{tname}': {e}")))?);
                if *t.writable.get_ref() {
                    let object = p
                        .control
                        .as_ref()
                        .map_or_else(|| p.reference.get_ref().as_str(), |c| c.get_ref().as_str());
                    let o =
                        ObjectRef::parse(object).map_err(|e| err(format!("tag '{tname}': {e}")))?;
                    let data_object = if p.control.is_some() {
                        o.path.join("$")
                    } else {
                        o.path.first().map(|s| s.to_string()).unwrap_or_default()
                    };
                    let spec = ControlSpec {
                        tag: Arc::from(tname.as_str()),
                        domain: o.ld.to_string(),
                        ln: o.ln.to_string(),
                        data_object,
                        ctl_model: p.ctl_model.as_ref().map(|m| *m.get_ref()),
                        interlock_check: p.interlock_check,
                        synchro_check: p.synchro_check,
                        test: p.test,
                        double_point: t.data_type() != DataType::Bool
                            && p.reference.get_ref().ends_with("Pos.stVal"),
                        scale: *t.scale.get_ref(),
                        offset: t.offset,
                    };
                    targets.insert(
                        Arc::<str>::from(tname.as_str()),
                        Target {
                            ied: index,
                            device: name.clone(),
                            id,
                            spec,
                            limits: plant.write_limits(tname),
                            command_timeout: Duration::from_secs_f64(
                                cfg.command_timeout_s.get_ref().max(0.1),
                            ),
                        },
                    );
                }
            }
            let mut reports = Vec::new();
            for r in &cfg.reports {
                let (ld, ln, buffered, rcb) = rcb_parts(r.rcb.get_ref()).map_err(err)?;
                reports.push(ReportSettings {
                    label: r.rcb.get_ref().clone(),
                    domain: ld.to_string(),
                    item: format!("{ln}${}${rcb}", if buffered { "BR" } else { "RP" }),
                    buffered,
                    dataset: r.dataset.as_ref().map(|d| {
                        let d = d.get_ref();
                        match d.split_once('/') {
                            Some((ld, rest)) => format!("{ld}/{}", rest.replace('.', "$")),
                            None => d.clone(),
                        }
                    }),
                    integrity_ms: r
                        .integrity_period_s
                        .as_ref()
                        .map(|p| (p.get_ref() * 1000.0).round() as u32),
                    buffer_ms: r.buffer_time_ms.as_ref().map(|b| *b.get_ref()),
                    gi: r.gi,
                });
            }
            let status =
                gridscada_field::StatusIds::resolve(&db, &name).map_err(StartError::MissingTag)?;
            let counters = Arc::new(Counters::default());
            ieds.push((name.clone(), address.clone(), Arc::clone(&counters)));
            let (tx, rx) = mpsc::channel(16);
            senders.push(tx);
            let scan = Duration::from_millis(*d.scan_ms.get_ref());
            let settings = Settings {
                name: name.clone(),
                address,
                addressing: addressing(cfg).map_err(err)?,
                response_timeout: Duration::from_millis(*cfg.response_timeout_ms.get_ref()),
                command_timeout: Duration::from_secs_f64(cfg.command_timeout_s.get_ref().max(0.1)),
                scan,
                backoff_max: d.backoff_max(scan),
                reports,
                or_cat: cfg.originator_category.code(),
            };
            to_start.push(Ied::new(
                settings,
                tags,
                status,
                counters,
                Arc::clone(&db),
                Arc::clone(&clock),
                rx,
                notices.clone(),
            ));
        }
        let tasks = to_start
            .into_iter()
            .map(|i| tokio::spawn(i.run(shutdown_rx.clone())))
            .collect();
        Ok(Iec61850Io {
            shared: Arc::new(Shared {
                ieds: senders,
                targets,
                leadership,
                db,
            }),
            stats: Arc::new(IedStats { ieds }),
            shutdown,
            tasks,
            notices: Some(notices_rx),
        })
    }

    /// The IEDs' notices for the event log; `None` after the first call.
    pub fn take_notices(&mut self) -> Option<mpsc::Receiver<DeviceNotice>> {
        self.notices.take()
    }

    /// The control path to the IEDs.
    pub fn writer(&self) -> Arc<dyn TagWriter> {
        Arc::new(Iec61850Writer {
            shared: Arc::clone(&self.shared),
        })
    }

    /// The IEDs' figures, for the devices screen and `/metrics`.
    pub fn stats_source(&self) -> Arc<dyn StatsSource> {
        Arc::clone(&self.stats) as Arc<dyn StatsSource>
    }

    /// Stops every IED's task and waits for them.
    pub async fn shutdown(self) {
        let _ = self.shutdown.send(true);
        for t in self.tasks {
            let _ = t.await;
        }
    }
}

impl StatsSource for IedStats {
    fn stats(&self) -> PollStats {
        let get = |a: &AtomicU64| a.load(Ordering::Relaxed);
        let mut out = PollStats::default();
        for (device, link, c) in &self.ieds {
            let connected = c.connected.load(Ordering::Relaxed);
            out.devices.push(DeviceStats {
                device: device.clone(),
                link: link.clone(),
                connected,
                requests: get(&c.requests),
                errors: get(&c.errors),
                timeouts: get(&c.timeouts),
                writes: get(&c.commands),
                writes_failed: get(&c.commands_failed),
                last_response_ms: get(&c.response_us) as f64 / 1000.0,
                round_trip: c.round_trips.snapshot(),
                state: if connected {
                    "associated"
                } else {
                    "not associated"
                }
                .to_string(),
                events: get(&c.events),
                overflows: get(&c.overflows),
                ..Default::default()
            });
            out.links.push(LinkStats {
                link: link.clone(),
                connects: get(&c.connects),
                disconnects: get(&c.disconnects),
                garbage_bytes: get(&c.malformed),
                last_error: c.last_error.lock().clone(),
                ..Default::default()
            });
        }
        out
    }

    fn in_flight(&self) -> u64 {
        0
    }
}

struct Iec61850Writer {
    shared: Arc<Shared>,
}

impl TagWriter for Iec61850Writer {
    fn write<'a>(&'a self, name: &'a str, value: Value) -> WriteFuture<'a> {
        Box::pin(async move {
            let shared = &self.shared;
            let target = shared
                .targets
                .get(name)
                .ok_or_else(|| gridscada_field::no_write_target(&shared.db, name))?;
            shared.leadership.permit().map_err(WriteError::NotActive)?;
            check_limits(name, &value, target.limits)?;
            let returned = ReturnedStatus::watch(&shared.db, target.id);
            let (reply, rx) = oneshot::channel();
            let originator = gridscada_tagdb::originator()
                .map_or_else(|| "gridscada".to_string(), |o| o.to_string());
            shared.ieds[target.ied]
                .send(CommandRequest {
                    spec: target.spec.clone(),
                    value: value.clone(),
                    originator,
                    reply,
                })
                .await
                .map_err(|_| WriteError::Closed)?;
            rx.await.map_err(|_| WriteError::Closed)??;
            // What the status shows once the control is done: a double
            // point commanded with a bool shows 2 (on) or 1 (off).
            let expected = match (&value, target.spec.double_point) {
                (Value::Bool(b), true) => Value::Int(if *b { 2 } else { 1 }),
                _ => value.clone(),
            };
            returned
                .confirmed(
                    target.command_timeout,
                    name,
                    &target.device,
                    &value,
                    |got| within_resolution(&expected, got, 1e-6),
                )
                .await
        })
    }
}
