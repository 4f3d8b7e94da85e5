//! The controlling station (client) of IEC 104: one task per configured
//! station (`protocol = "iec104"`), its redundancy group of connections,
//! general and counter interrogation, clock synchronisation, the samples of
//! its points in the tag database, its status tags, and its commands
//! through [`gridscada_tagdb::TagWriter`].
//!
//! **Must not touch:** other protocols' devices and tags, configuration
//! parsing (it takes a checked [`Plant`]), alarms, SQL.

mod command;
mod points;
mod station;

use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, AtomicI64, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Duration;

use gridscada_config::{Iec104DeviceConfig, Plant, Protocol};
use gridscada_field::{
    check_limits, DeviceNotice, DeviceStats, LinkStats, Notices, PollStats, ReturnedStatus,
    RoundTrips, StatsSource,
};
use gridscada_tagdb::{Clock, Leadership, TagDb, TagId, TagWriter, Value, WriteError, WriteFuture};
use parking_lot::Mutex;
use tokio::sync::{mpsc, oneshot, watch};
use tokio::task::JoinHandle;

use command::CommandSpec;
use points::{PointMap, PointTag};
use station::{Station, StationSettings};

/// Why the client cannot start.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum StartError {
    #[error("tag '{0}' is in the configuration but not in the tag database")]
    MissingTag(String),
    #[error("device '{device}': {reason}")]
    Device { device: String, reason: String },
}

/// Counters of one station, written by its task.
#[derive(Default)]
pub(crate) struct Counters {
    pub connected: AtomicBool,
    /// 0 stopped, 1 started, 2 tested only.
    pub state: AtomicU64,
    pub i_frames_sent: AtomicU64,
    pub errors: AtomicU64,
    pub timeouts: AtomicU64,
    pub events: AtomicU64,
    pub interrogations: AtomicU64,
    pub last_interrogation_ms: AtomicI64,
    pub commands: AtomicU64,
    pub commands_failed: AtomicU64,
    pub clock_offset_ms: AtomicI64,
    pub clock_synced: AtomicBool,
    pub overflows: AtomicU64,
    pub connects: AtomicU64,
    pub disconnects: AtomicU64,
    pub malformed: AtomicU64,
    pub round_trips: RoundTrips,
    pub response_us: AtomicU64,
    pub last_error: Mutex<String>,
}

/// A command on its way to a station's task.
pub(crate) struct CommandRequest {
    pub tag: Arc<str>,
    pub spec: CommandSpec,
    pub value: Value,
    pub reply: oneshot::Sender<Result<(), WriteError>>,
}

struct Target {
    station: usize,
    device: String,
    id: TagId,
    spec: CommandSpec,
    limits: (Option<f64>, Option<f64>),
    command_timeout: Duration,
}

struct Shared {
    stations: Vec<mpsc::Sender<CommandRequest>>,
    targets: HashMap<Arc<str>, Target>,
    leadership: Leadership,
    db: Arc<TagDb>,
}

/// The running IEC 104 client: one task per station.
pub struct Iec104Io {
    shared: Arc<Shared>,
    stats: Arc<StationStats>,
    shutdown: watch::Sender<bool>,
    tasks: Vec<JoinHandle<()>>,
    notices: Option<mpsc::Receiver<DeviceNotice>>,
}

struct StationStats {
    stations: Vec<(String, String, Arc<Counters>)>,
}

impl Iec104Io {
    /// Starts a task for every `protocol = "iec104"` device of `plant`.
    /// Its tags and the devices' status tags must already be in `db`. Writes
    /// ask `leadership` for permission as they go out.
    pub fn start(
        plant: &Plant,
        db: Arc<TagDb>,
        clock: Arc<dyn Clock>,
        leadership: Leadership,
    ) -> Result<Iec104Io, StartError> {
        let (shutdown, shutdown_rx) = watch::channel(false);
        let (notices, notices_rx) = Notices::channel(256);
        let mut senders = Vec::new();
        let mut stations = Vec::new();
        let mut targets = HashMap::new();
        let mut tasks_to_start = Vec::new();
        let default_link = Iec104DeviceConfig::default();
        for d in plant
            .devices
            .iter()
            .filter(|d| d.protocol == Protocol::Iec104)
        {
            let name = d.name.get_ref().clone();
            let link = d.iec104.as_ref().unwrap_or(&default_link);
            let err = |reason: String| StartError::Device {
                device: name.clone(),
                reason,
            };
            let mut addresses: Vec<String> =
                d.address.iter().map(|a| a.get_ref().clone()).collect();
            addresses.extend(link.redundant_addresses.iter().map(|a| a.get_ref().clone()));
            if addresses.is_empty() {
                return Err(err("an iec104 device needs address = \"host:port\"".into()));
            }
            let index = stations.len();
            let mut map = PointMap::default();
            for t in plant.tags.iter().filter(|t| t.device.get_ref() == &name) {
                let tname = t.name.get_ref();
                let id = db
                    .id(tname)
                    .ok_or_else(|| StartError::MissingTag(tname.clone()))?;
                let Some(p) = &t.iec104 else {
                    return Err(err(format!("tag '{tname}' has no iec104 point")));
                };
                map.insert(*p.ioa.get_ref(), PointTag::new(id, t, *p.point.get_ref()));
                if let (Some(c), true) = (&p.command, *t.writable.get_ref()) {
                    targets.insert(
                        Arc::<str>::from(tname.as_str()),
                        Target {
                            station: index,
                            device: name.clone(),
                            id,
                            spec: CommandSpec {
                                command: *c.get_ref(),
                                ioa: p.command_ioa(),
                                select: p.select,
                                qualifier: *p.qualifier.get_ref(),
                                data_type: t.data_type(),
                                scale: *t.scale.get_ref(),
                                offset: t.offset,
                            },
                            limits: plant.write_limits(tname),
                            command_timeout: secs(*link.command_timeout_s.get_ref()),
                        },
                    );
                }
            }
            let status =
                gridscada_field::StatusIds::resolve(&db, &name).map_err(StartError::MissingTag)?;
            let counters = Arc::new(Counters::default());
            stations.push((name.clone(), addresses.join(","), Arc::clone(&counters)));
            let (tx, rx) = mpsc::channel(16);
            senders.push(tx);
            let settings = StationSettings {
                name: name.clone(),
                addresses,
                common_address: *link.common_address.get_ref(),
                session: crate::session::Parameters {
                    k: *link.k.get_ref(),
                    w: *link.w.get_ref(),
                    t1: secs(*link.t1_s.get_ref()),
                    t2: secs(*link.t2_s.get_ref()),
                    t3: secs(*link.t3_s.get_ref()),
                },
                t0: secs(*link.t0_s.get_ref()),
                interrogation_period: period(*link.interrogation_period_s.get_ref()),
                counter_period: period(*link.counter_interrogation_period_s.get_ref()),
                clock_sync_period: period(*link.clock_sync_period_s.get_ref()),
                command_timeout: secs(*link.command_timeout_s.get_ref()),
                termination: link.command_termination,
                backoff_max: d.backoff_max(Duration::from_millis(*d.scan_ms.get_ref())),
            };
            tasks_to_start.push(Station::new(
                settings,
                map,
                status,
                counters,
                Arc::clone(&db),
                Arc::clone(&clock),
                leadership.clone(),
                rx,
                notices.clone(),
            ));
        }
        let tasks = tasks_to_start
            .into_iter()
            .map(|s| tokio::spawn(s.run(shutdown_rx.clone())))
            .collect();
        Ok(Iec104Io {
            shared: Arc::new(Shared {
                stations: senders,
                targets,
                leadership,
                db,
            }),
            stats: Arc::new(StationStats { stations }),
            shutdown,
            tasks,
            notices: Some(notices_rx),
        })
    }

    /// The stations' notices for the event log (end of initialisation);
    /// `None` after the first call.
    pub fn take_notices(&mut self) -> Option<mpsc::Receiver<DeviceNotice>> {
        self.notices.take()
    }

    /// The command path to the stations.
    pub fn writer(&self) -> Arc<dyn TagWriter> {
        Arc::new(Iec104Writer {
            shared: Arc::clone(&self.shared),
        })
    }

    /// The stations' figures, for the devices screen and `/metrics`.
    pub fn stats_source(&self) -> Arc<dyn StatsSource> {
        Arc::clone(&self.stats) as Arc<dyn StatsSource>
    }

    /// Stops every station's task and waits for them.
    pub async fn shutdown(self) {
        let _ = self.shutdown.send(true);
        for t in self.tasks {
            let _ = t.await;
        }
    }
}

fn secs(s: f64) -> Duration {
    Duration::from_secs_f64(s.max(0.001))
}

fn period(s: f64) -> Option<Duration> {
    (s > 0.0).then(|| Duration::from_secs_f64(s))
}

impl StatsSource for StationStats {
    fn stats(&self) -> PollStats {
        let get = |a: &AtomicU64| a.load(Ordering::Relaxed);
        let mut out = PollStats::default();
        for (device, link, c) in &self.stations {
            let state = match c.state.load(Ordering::Relaxed) {
                1 => "started",
                2 => "tested",
                _ => "stopped",
            };
            let last_gi = c.last_interrogation_ms.load(Ordering::Relaxed);
            out.devices.push(DeviceStats {
                device: device.clone(),
                link: link.clone(),
                connected: c.connected.load(Ordering::Relaxed),
                requests: get(&c.i_frames_sent),
                errors: get(&c.errors),
                timeouts: get(&c.timeouts),
                writes: get(&c.commands),
                last_response_ms: get(&c.response_us) as f64 / 1000.0,
                round_trip: c.round_trips.snapshot(),
                state: state.to_string(),
                events: get(&c.events),
                interrogations: get(&c.interrogations),
                last_interrogation_ms: (last_gi > 0).then_some(last_gi),
                writes_failed: get(&c.commands_failed),
                clock_offset_ms: c
                    .clock_synced
                    .load(Ordering::Relaxed)
                    .then(|| c.clock_offset_ms.load(Ordering::Relaxed) as f64),
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

struct Iec104Writer {
    shared: Arc<Shared>,
}

impl TagWriter for Iec104Writer {
    fn write<'a>(&'a self, name: &'a str, value: Value) -> WriteFuture<'a> {
        Box::pin(async move {
            let shared = &self.shared;
            let target = shared
                .targets
                .get(name)
                .ok_or_else(|| gridscada_field::no_write_target(&shared.db, name))?;
            shared.leadership.permit().map_err(WriteError::NotActive)?;
            check_limits(name, &value, target.limits)?;
            // Refused here, before anything goes out, if it cannot be encoded.
            target
                .spec
                .element(&value)
                .map_err(|reason| WriteError::BadValue {
                    tag: name.to_string(),
                    value: value.to_string(),
                    reason,
                })?;
            let returned = ReturnedStatus::watch(&shared.db, target.id);
            let (reply, rx) = oneshot::channel();
            shared.stations[target.station]
                .send(CommandRequest {
                    tag: Arc::from(name),
                    spec: target.spec.clone(),
                    value: value.clone(),
                    reply,
                })
                .await
                .map_err(|_| WriteError::Closed)?;
            rx.await.map_err(|_| WriteError::Closed)??;
            returned
                .confirmed(
                    target.command_timeout,
                    name,
                    &target.device,
                    &value,
                    |got| target.spec.confirms(&value, got),
                )
                .await
        })
    }
}
