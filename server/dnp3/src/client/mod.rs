//! The DNP3 master's I/O shell: one task per configured outstation
//! (`protocol = "dnp3"`) that connects over TCP or opens its serial port,
//! feeds the bytes to [`crate::master::Master`] and carries out its
//! actions; the samples of
//! its points in the tag database, its status tags and figures, and its
//! commands (CROB, analog output; select-before-operate or direct)
//! through [`gridscada_tagdb::TagWriter`].
//!
//! **Must not touch:** other protocols' devices and tags, configuration
//! parsing (it takes a checked [`Plant`]), alarms, SQL.

mod outstation;
mod points;

use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Duration;

use gridscada_config::{
    DataType, Dnp3Command, Dnp3DeviceConfig, Dnp3Op, Dnp3Point, Dnp3TimeSync, Plant, Protocol,
};
use gridscada_field::{
    check_limits, within_resolution, DeviceNotice, DeviceStats, LinkStats, Notices, PollStats,
    ReturnedStatus, RoundTrips, StatsSource,
};
use gridscada_tagdb::{
    Clock, Leadership, Sample, TagDb, TagId, TagWriter, Value, WriteError, WriteFuture,
};
use parking_lot::Mutex;
use tokio::sync::{mpsc, oneshot, watch};
use tokio::task::JoinHandle;

use crate::master::{CommandMode, MasterConfig};
use crate::objects::{AnalogOutput, CommandObject, Crob};
use outstation::{Line, Outstation, Settings};
pub use points::kind_of;
use points::{PointMap, PointTag};

/// Why the master cannot start.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum StartError {
    #[error("tag '{0}' is in the configuration but not in the tag database")]
    MissingTag(String),
    #[error("device '{device}': {reason}")]
    Device { device: String, reason: String },
}

/// Counters of one outstation, written by its task.
#[derive(Default)]
pub(crate) struct Counters {
    pub connected: AtomicBool,
    pub requests: AtomicU64,
    pub errors: AtomicU64,
    pub timeouts: AtomicU64,
    pub events: AtomicU64,
    pub integrity_polls: AtomicU64,
    /// When the last integrity poll completed, ms since 1970; 0: never.
    pub last_integrity_ms: std::sync::atomic::AtomicI64,
    pub commands: AtomicU64,
    pub commands_failed: AtomicU64,
    pub overflows: AtomicU64,
    pub connects: AtomicU64,
    pub disconnects: AtomicU64,
    /// Octets discarded as malformed.
    pub malformed: AtomicU64,
    pub round_trips: RoundTrips,
    pub response_us: AtomicU64,
    pub last_error: Mutex<String>,
}

/// How a writable tag is commanded.
#[derive(Debug, Clone)]
pub(crate) struct CommandSpec {
    pub command: Dnp3Command,
    /// The tag's own point, which returns the commanded state.
    pub point: Dnp3Point,
    pub index: u16,
    pub select: bool,
    pub op: Dnp3Op,
    pub on_ms: u32,
    pub off_ms: u32,
    pub data_type: DataType,
    pub scale: f64,
    pub offset: f64,
}

impl CommandSpec {
    pub fn mode(&self) -> CommandMode {
        if self.select {
            CommandMode::SelectBeforeOperate
        } else {
            CommandMode::DirectOperate
        }
    }

    /// Whether the outstation's SUCCESS is to be followed by the tag's own
    /// point showing the commanded value. Not for a pulse on a binary
    /// output's own status, which is over before it is read back.
    pub fn awaits_returned_status(&self) -> bool {
        !(self.command == Dnp3Command::Crob
            && self.op == Dnp3Op::Pulse
            && self.point == Dnp3Point::BinaryOutput)
    }

    /// Whether the returned point's value `got` shows the command took:
    /// the written state, or the written set point within what the output
    /// object carries (one raw step for integer outputs).
    pub fn confirms(&self, written: &Value, got: &Value) -> bool {
        let resolution = match (self.command, self.data_type) {
            (Dnp3Command::Crob, _) => 0.0,
            (Dnp3Command::AnalogOutput, DataType::F32 | DataType::F64) => written
                .as_f64()
                .map_or(1e-9, |w| (w.abs() * 1e-6).max(1e-9)),
            (Dnp3Command::AnalogOutput, _) => self.scale.abs(),
        };
        within_resolution(written, got, resolution)
    }

    /// The command object that sets the tag to `value`.
    pub fn object(&self, value: &Value) -> Result<CommandObject, String> {
        match self.command {
            Dnp3Command::Crob => {
                let on = match value {
                    Value::Bool(b) => *b,
                    Value::Int(0) | Value::UInt(0) => false,
                    Value::Int(1) | Value::UInt(1) => true,
                    other => return Err(format!("a CROB takes true or false, not {other}")),
                };
                Ok(CommandObject::Crob(match self.op {
                    Dnp3Op::Latch => Crob::latch(on),
                    Dnp3Op::Pulse => Crob::pulse(on, 1, self.on_ms, self.off_ms),
                    Dnp3Op::TripClose => Crob::trip_close(on, self.on_ms),
                }))
            }
            Dnp3Command::AnalogOutput => {
                let v = value
                    .as_f64()
                    .filter(|v| v.is_finite())
                    .ok_or_else(|| format!("an analog output takes a number, not {value}"))?;
                let raw = (v - self.offset) / self.scale;
                let int = |lo: f64, hi: f64| -> Result<f64, String> {
                    let r = raw.round();
                    if r < lo || r > hi {
                        Err(format!(
                            "{raw} is outside {lo}..{hi} for a {} output",
                            self.data_type.label()
                        ))
                    } else {
                        Ok(r)
                    }
                };
                Ok(CommandObject::Analog(match self.data_type {
                    DataType::F32 => AnalogOutput::F32(raw as f32),
                    DataType::F64 => AnalogOutput::F64(raw),
                    DataType::I16 => AnalogOutput::I16(int(-32768.0, 32767.0)? as i16),
                    DataType::U16 => AnalogOutput::I32(int(0.0, 65535.0)? as i32),
                    DataType::U32 => AnalogOutput::I32(int(0.0, i32::MAX as f64)? as i32),
                    _ => AnalogOutput::I32(int(i32::MIN as f64, i32::MAX as f64)? as i32),
                }))
            }
        }
    }
}

/// A command on its way to an outstation's task.
pub(crate) struct CommandRequest {
    pub tag: Arc<str>,
    pub index: u16,
    pub object: CommandObject,
    pub mode: CommandMode,
    pub reply: oneshot::Sender<Result<(), WriteError>>,
}

struct Target {
    outstation: usize,
    /// The outstation's device name, for the failed write.
    device: String,
    id: TagId,
    spec: CommandSpec,
    limits: (Option<f64>, Option<f64>),
    command_timeout: Duration,
}

struct Shared {
    outstations: Vec<mpsc::Sender<CommandRequest>>,
    targets: HashMap<Arc<str>, Target>,
    leadership: Leadership,
    db: Arc<TagDb>,
    clock: Arc<dyn Clock>,
}

/// The running DNP3 master: one task per outstation.
pub struct Dnp3Io {
    shared: Arc<Shared>,
    stats: Arc<OutstationStats>,
    shutdown: watch::Sender<bool>,
    tasks: Vec<JoinHandle<()>>,
    notices: Option<mpsc::Receiver<DeviceNotice>>,
}

struct OutstationStats {
    outstations: Vec<(String, String, Arc<Counters>)>,
}

impl Dnp3Io {
    /// Starts a task for every `protocol = "dnp3"` device of `plant`. Its
    /// tags and the devices' status tags must already be in `db`. Commands
    /// ask `leadership` for permission as they go out.
    pub fn start(
        plant: &Plant,
        db: Arc<TagDb>,
        clock: Arc<dyn Clock>,
        leadership: Leadership,
    ) -> Result<Dnp3Io, StartError> {
        let (shutdown, shutdown_rx) = watch::channel(false);
        let mut senders = Vec::new();
        let mut outstations = Vec::new();
        let mut targets = HashMap::new();
        let mut to_start = Vec::new();
        let default_session = Dnp3DeviceConfig::default();
        let (notices, notices_rx) = Notices::channel(256);
        for d in plant
            .devices
            .iter()
            .filter(|d| d.protocol == Protocol::Dnp3)
        {
            let name = d.name.get_ref().clone();
            let session = d.dnp3.as_ref().unwrap_or(&default_session);
            let err = |reason: String| StartError::Device {
                device: name.clone(),
                reason,
            };
            let line = match (&d.address, &d.serial) {
                (Some(a), None) => Line::Tcp(a.get_ref().clone()),
                (None, Some(s)) => Line::Serial(s.clone()),
                _ => return Err(err(
                    "a dnp3 device needs either address = \"host:port\" or a [device.serial] table"
                        .into(),
                )),
            };
            let index = outstations.len();
            let mut map = PointMap::default();
            for t in plant.tags.iter().filter(|t| t.device.get_ref() == &name) {
                let tname = t.name.get_ref();
                let id = db
                    .id(tname)
                    .ok_or_else(|| StartError::MissingTag(tname.clone()))?;
                let Some(p) = &t.dnp3 else {
                    return Err(err(format!("tag '{tname}' has no dnp3 point")));
                };
                map.insert(*p.point.get_ref(), *p.index.get_ref(), PointTag::new(id, t));
                if let (Some(c), true) = (&p.command, *t.writable.get_ref()) {
                    targets.insert(
                        Arc::<str>::from(tname.as_str()),
                        Target {
                            outstation: index,
                            device: name.clone(),
                            id,
                            spec: CommandSpec {
                                command: *c.get_ref(),
                                point: *p.point.get_ref(),
                                index: p.command_index(),
                                select: p.select,
                                op: p.op(),
                                on_ms: p.on_ms(),
                                off_ms: p.off_ms(),
                                data_type: t.data_type(),
                                scale: *t.scale.get_ref(),
                                offset: t.offset,
                            },
                            limits: plant.write_limits(tname),
                            command_timeout: Duration::from_secs_f64(
                                session.command_timeout_s.get_ref().max(0.001),
                            ),
                        },
                    );
                }
            }
            let status =
                gridscada_field::StatusIds::resolve(&db, &name).map_err(StartError::MissingTag)?;
            let counters = Arc::new(Counters::default());
            outstations.push((name.clone(), line.label(), Arc::clone(&counters)));
            let (tx, rx) = mpsc::channel(16);
            senders.push(tx);
            let response_timeout = Duration::from_millis(*session.response_timeout_ms.get_ref());
            let master = MasterConfig {
                master_address: *session.master_address.get_ref(),
                outstation_address: *session.outstation_address.get_ref(),
                response_timeout,
                integrity_period: period(*session.integrity_period_s.get_ref()),
                event_period: period(*session.event_poll_period_s.get_ref()),
                disable_unsolicited_at_start: true,
                enable_unsolicited: session.unsolicited,
                time_sync: session.time_sync == Dnp3TimeSync::Lan,
                select_timeout: Duration::from_secs_f64(
                    session.select_timeout_s.get_ref().max(0.001),
                ),
                ..MasterConfig::default()
            };
            to_start.push(Outstation::new(
                Settings {
                    name: name.clone(),
                    line,
                    master,
                    connect_timeout: response_timeout.max(Duration::from_secs(1)),
                    backoff_max: d.backoff_max(Duration::from_millis(*d.scan_ms.get_ref())),
                },
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
        let tasks = to_start
            .into_iter()
            .map(|o| tokio::spawn(o.run(shutdown_rx.clone())))
            .collect();
        Ok(Dnp3Io {
            shared: Arc::new(Shared {
                outstations: senders,
                targets,
                leadership,
                db,
                clock,
            }),
            stats: Arc::new(OutstationStats { outstations }),
            shutdown,
            tasks,
            notices: Some(notices_rx),
        })
    }

    /// The outstations' notices for the event log (restart, lost events,
    /// clock set); `None` after the first call.
    pub fn take_notices(&mut self) -> Option<mpsc::Receiver<DeviceNotice>> {
        self.notices.take()
    }

    /// The command path to the outstations.
    pub fn writer(&self) -> Arc<dyn TagWriter> {
        Arc::new(Dnp3Writer {
            shared: Arc::clone(&self.shared),
        })
    }

    /// The outstations' figures, for the devices screen and `/metrics`.
    pub fn stats_source(&self) -> Arc<dyn StatsSource> {
        Arc::clone(&self.stats) as Arc<dyn StatsSource>
    }

    /// Stops every outstation's task and waits for them.
    pub async fn shutdown(self) {
        let _ = self.shutdown.send(true);
        for t in self.tasks {
            let _ = t.await;
        }
    }
}

fn period(s: f64) -> Option<Duration> {
    (s > 0.0 && s.is_finite()).then(|| Duration::from_secs_f64(s))
}

impl StatsSource for OutstationStats {
    fn stats(&self) -> PollStats {
        let get = |a: &AtomicU64| a.load(Ordering::Relaxed);
        let mut out = PollStats::default();
        for (device, link, c) in &self.outstations {
            let connected = c.connected.load(Ordering::Relaxed);
            out.devices.push(DeviceStats {
                device: device.clone(),
                link: link.clone(),
                connected,
                requests: get(&c.requests),
                errors: get(&c.errors),
                timeouts: get(&c.timeouts),
                writes: get(&c.commands),
                last_response_ms: get(&c.response_us) as f64 / 1000.0,
                round_trip: c.round_trips.snapshot(),
                // "connected"/"disconnected": the DNP3 states, apart from
                // IEC 104's started/tested/stopped (`/metrics` tells them so).
                state: if connected {
                    "connected"
                } else {
                    "disconnected"
                }
                .to_string(),
                events: get(&c.events),
                interrogations: get(&c.integrity_polls),
                last_interrogation_ms: {
                    let at = c.last_integrity_ms.load(Ordering::Relaxed);
                    (at > 0).then_some(at)
                },
                writes_failed: get(&c.commands_failed),
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

struct Dnp3Writer {
    shared: Arc<Shared>,
}

impl TagWriter for Dnp3Writer {
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
            let object = target
                .spec
                .object(&value)
                .map_err(|reason| WriteError::BadValue {
                    tag: name.to_string(),
                    value: value.to_string(),
                    reason,
                })?;
            let returned = ReturnedStatus::watch(&shared.db, target.id);
            let (reply, rx) = oneshot::channel();
            shared.outstations[target.outstation]
                .send(CommandRequest {
                    tag: Arc::from(name),
                    index: target.spec.index,
                    object,
                    mode: target.spec.mode(),
                    reply,
                })
                .await
                .map_err(|_| WriteError::Closed)?;
            // The outstation echoed the command with status SUCCESS; its
            // point must now show the commanded value.
            rx.await.map_err(|_| WriteError::Closed)??;
            if !target.spec.awaits_returned_status() {
                return Ok(Sample::good(value, shared.clock.now()));
            }
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

#[cfg(test)]
mod tests {
    use super::*;

    fn spec(command: Dnp3Command, op: Dnp3Op, data_type: DataType, scale: f64) -> CommandSpec {
        CommandSpec {
            command,
            point: Dnp3Point::BinaryOutput,
            index: 0,
            select: true,
            op,
            on_ms: 500,
            off_ms: 0,
            data_type,
            scale,
            offset: 0.0,
        }
    }

    #[test]
    fn crob_operations_follow_the_tags_op() {
        let latch = spec(Dnp3Command::Crob, Dnp3Op::Latch, DataType::Bool, 1.0);
        assert_eq!(
            latch.object(&Value::Bool(true)),
            Ok(CommandObject::Crob(Crob::latch(true)))
        );
        assert_eq!(
            latch.object(&Value::Bool(false)),
            Ok(CommandObject::Crob(Crob::latch(false)))
        );
        let tc = spec(Dnp3Command::Crob, Dnp3Op::TripClose, DataType::Bool, 1.0);
        assert_eq!(
            tc.object(&Value::Bool(false)),
            Ok(CommandObject::Crob(Crob::trip_close(false, 500)))
        );
        let pulse = spec(Dnp3Command::Crob, Dnp3Op::Pulse, DataType::Bool, 1.0);
        assert_eq!(
            pulse.object(&Value::Bool(true)),
            Ok(CommandObject::Crob(Crob::pulse(true, 1, 500, 0)))
        );
        assert!(latch.object(&Value::Float(0.5)).is_err());
        assert_eq!(latch.mode(), CommandMode::SelectBeforeOperate);
    }

    #[test]
    fn analog_outputs_are_unscaled_and_range_checked() {
        let f = spec(Dnp3Command::AnalogOutput, Dnp3Op::Latch, DataType::F32, 1.0);
        assert_eq!(
            f.object(&Value::Float(12.5)),
            Ok(CommandObject::Analog(AnalogOutput::F32(12.5)))
        );
        let i = spec(Dnp3Command::AnalogOutput, Dnp3Op::Latch, DataType::I16, 0.1);
        assert_eq!(
            i.object(&Value::Float(230.5)),
            Ok(CommandObject::Analog(AnalogOutput::I16(2305)))
        );
        let e = i.object(&Value::Float(1e6)).unwrap_err();
        assert!(e.contains("outside"), "{e}");
        assert!(i.object(&Value::Str("x".into())).is_err());
    }
}
