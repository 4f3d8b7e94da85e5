//! The I/O shell of a simulated telecontrol station: an IEC 60870-5-104
//! RTU (a `protocol = "iec104"` device, served by gridscada's own
//! controlled station, `gridscada_iec104::Iec104Server`) or a DNP3
//! outstation (`protocol = "dnp3"`, served by
//! `gridscada_dnp3::server::Dnp3Outstation`), over a point database of the
//! station's own which the plant models fill. The station answers
//! interrogations and integrity polls, reports changes with the plant's
//! time (spontaneous data, unsolicited responses and events), and takes
//! select-before-operate and direct commands as an RTU would.
//!
//! Owns that point database, its refresh from the models, the translation
//! between engineering values and the raw values the master scales back
//! (`raw * scale + offset`), and the command path into the models. Must
//! not touch the server's tag database (the station's points are private
//! to the simulator), the models' behaviour, or the Modbus gateways.

use std::sync::Arc;
use std::time::Duration;

use gridscada_config::{
    DataType, Dnp3Command, Dnp3Point, Iec104DeviceConfig, Iec104ExportConfig, Iec104Point,
    Iec104ServerConfig, Plant, Protocol, Role, TagConfig,
};
use gridscada_dnp3::outstation::{OutstationConfig, Point};
use gridscada_dnp3::server::{Dnp3Outstation, ServedControl, ServedDatabase, ServedPoint};
use gridscada_iec104::{Iec104Server, ServerContext, ServerCounters};
use gridscada_store::command::CommandAudit;
use gridscada_store::NewEvent;
use gridscada_tagdb::{
    Sample, TagDb, TagId, TagMeta, TagWriter, Value, ValueKind, WriteError, WriteFuture,
};
use serde_spanned::Spanned;
use tokio::net::TcpListener;
use tokio::sync::watch;

use crate::server::Shared;
use crate::Error;

/// How a station point's engineering value becomes what the station sends.
#[derive(Debug, Clone, Copy)]
struct Encoding {
    kind: ValueKind,
    scale: f64,
    offset: f64,
}

impl Encoding {
    /// How `tag`'s point is sent: binaries as bools (a double point of a
    /// bool tag too), counters and step positions as integers, measurands
    /// as floats; `None` when the tag has no point of the station's
    /// protocol.
    fn of(tag: &TagConfig, protocol: Protocol) -> Option<Encoding> {
        let bool_tag = tag.value_kind() == ValueKind::Bool;
        let kind = match protocol {
            Protocol::Dnp3 => match *tag.dnp3.as_ref()?.point.get_ref() {
                Dnp3Point::BinaryInput | Dnp3Point::BinaryOutput => ValueKind::Bool,
                Dnp3Point::DoubleBit if bool_tag => ValueKind::Bool,
                Dnp3Point::DoubleBit | Dnp3Point::Counter | Dnp3Point::FrozenCounter => {
                    ValueKind::Int
                }
                Dnp3Point::AnalogInput | Dnp3Point::AnalogOutput => ValueKind::Float,
            },
            _ => match *tag.iec104.as_ref()?.point.get_ref() {
                Iec104Point::M_SP => ValueKind::Bool,
                Iec104Point::M_DP if bool_tag => ValueKind::Bool,
                Iec104Point::M_DP | Iec104Point::M_ST | Iec104Point::M_BO | Iec104Point::M_IT => {
                    ValueKind::Int
                }
                Iec104Point::M_ME_NA | Iec104Point::M_ME_NB | Iec104Point::M_ME_NC => {
                    ValueKind::Float
                }
            },
        };
        let scale = *tag.scale.get_ref();
        Some(Encoding {
            kind,
            scale: if scale == 0.0 { 1.0 } else { scale },
            offset: tag.offset,
        })
    }

    /// The value the station sends for engineering value `v`.
    fn raw(self, v: f64) -> Value {
        match self.kind {
            ValueKind::Bool => Value::Bool(v != 0.0),
            ValueKind::Int => Value::Int(((v - self.offset) / self.scale).round() as i64),
            _ => Value::Float((v - self.offset) / self.scale),
        }
    }
}

/// The station's points: ids in its own database, parallel to the
/// station's points in the plant simulation.
struct Points {
    db: Arc<TagDb>,
    ids: Vec<TagId>,
    encodings: Vec<Encoding>,
}

impl Points {
    fn encoding_of(&self, tag: &str) -> Option<Encoding> {
        let id = self.db.id(tag)?;
        let i = self.ids.iter().position(|x| *x == id)?;
        self.encodings.get(i).copied()
    }

    /// Sets the points a model drives (`all`: every point) from the
    /// models' values, stamped with plant time.
    fn refresh(&self, shared: &Shared, station: usize, all: bool) {
        let (values, now) = shared.with_plant(|p| {
            let values = p.station_values(station);
            let picked: Vec<(usize, f64)> = if all {
                values.iter().copied().enumerate().collect()
            } else {
                p.station_driven(station)
                    .iter()
                    .filter_map(|&i| Some((i, *values.get(i)?)))
                    .collect()
            };
            (picked, p.now())
        });
        let batch: Vec<(TagId, Sample)> = values
            .into_iter()
            .filter_map(|(i, v)| {
                let (&id, e) = (self.ids.get(i)?, self.encodings.get(i)?);
                let raw = e.raw(v);
                let unchanged = self
                    .db
                    .get(id)
                    .is_some_and(|s| s.quality.is_good() && s.value == raw);
                (!unchanged).then(|| (id, Sample::good(raw, now)))
            })
            .collect();
        if !batch.is_empty() {
            self.db.apply(batch);
        }
    }
}

/// Commands from the master into the models.
struct StationWriter {
    shared: Arc<Shared>,
    station: usize,
    points: Arc<Points>,
    /// DNP3's analog outputs carry the raw value (`(v - offset) / scale`);
    /// IEC 104's set points the engineering value.
    raw_set_points: bool,
}

impl TagWriter for StationWriter {
    fn write<'a>(&'a self, name: &'a str, value: Value) -> WriteFuture<'a> {
        Box::pin(async move {
            let mut v = match &value {
                Value::Bool(b) => f64::from(u8::from(*b)),
                other => other.as_f64().ok_or_else(|| WriteError::BadValue {
                    tag: name.to_string(),
                    value: other.to_string(),
                    reason: "not a number".into(),
                })?,
            };
            if self.raw_set_points && !matches!(value, Value::Bool(_)) {
                if let Some(e) = self.points.encoding_of(name) {
                    v = v * e.scale + e.offset;
                }
            }
            let now = self.shared.clock.now();
            self.shared
                .plant
                .lock()
                .station_command(self.station, name, v, now)
                .map_err(|reason| WriteError::Device {
                    device: "simulated station".into(),
                    reason,
                })?;
            self.points.refresh(&self.shared, self.station, false);
            Ok(Sample::good(value, now))
        })
    }
}

/// The simulated RTU keeps no audit trail: gridscada audits the command
/// where it is given.
struct NoAudit;

impl CommandAudit for NoAudit {
    fn durable(
        &self,
        _event: NewEvent,
    ) -> std::pin::Pin<Box<dyn std::future::Future<Output = Result<(), String>> + Send + '_>> {
        Box::pin(async { Ok(()) })
    }
}

/// A running simulated station: one server per address (an IEC 104
/// station's redundancy group), over the same points.
pub(crate) struct Station {
    servers: Vec<Server>,
    refresh: tokio::task::JoinHandle<()>,
}

enum Server {
    Iec104(Iec104Server),
    Dnp3(Dnp3Outstation),
}

impl Station {
    /// Serves station `index` of the simulation, whose device is `device`
    /// of `plant`, on `listeners` (its address and its redundancy group's
    /// others), refreshing its points every `tick` of plant time.
    pub(crate) fn start(
        shared: Arc<Shared>,
        index: usize,
        plant: &Plant,
        device: &str,
        listeners: Vec<TcpListener>,
        tick: Duration,
        mut shutdown: watch::Receiver<bool>,
    ) -> Result<Station, Error> {
        let tags: Vec<&TagConfig> = {
            // One pass over the plant's tags, not one per point.
            let of_device: std::collections::HashMap<&str, &TagConfig> = plant
                .tags
                .iter()
                .filter(|t| t.device.get_ref() == device)
                .map(|t| (t.name.get_ref().as_str(), t))
                .collect();
            let sim = shared.plant.lock();
            sim.stations[index]
                .points
                .iter()
                .map(|p| {
                    of_device
                        .get(p.tag.as_str())
                        .copied()
                        .ok_or_else(|| Error::Config(format!("no tag '{}'", p.tag)))
                })
                .collect::<Result<_, _>>()?
        };
        let device_config = plant
            .devices
            .iter()
            .find(|d| d.name.get_ref() == device)
            .ok_or_else(|| Error::Config(format!("no device '{device}'")))?;
        let protocol = device_config.protocol;
        let mut metas = Vec::new();
        let mut encodings = Vec::new();
        for t in &tags {
            let e = Encoding::of(t, protocol).ok_or_else(|| {
                Error::Config(format!(
                    "tag '{}' of device '{device}' has no point of its protocol",
                    t.name.get_ref()
                ))
            })?;
            metas.push(TagMeta::new(t.name.get_ref().as_str(), e.kind));
            encodings.push(e);
        }
        let db = Arc::new(
            TagDb::new(metas).map_err(|e| Error::Config(format!("station '{device}': {e}")))?,
        );
        let ids: Vec<TagId> = tags
            .iter()
            .map(|t| db.id(t.name.get_ref()).expect("just added"))
            .collect();
        let points = Arc::new(Points {
            db: Arc::clone(&db),
            ids: ids.clone(),
            encodings,
        });
        points.refresh(&shared, index, true);
        let driven = !shared.plant.lock().station_driven(index).is_empty();

        let writer: Arc<dyn TagWriter> = Arc::new(StationWriter {
            shared: Arc::clone(&shared),
            station: index,
            points: Arc::clone(&points),
            raw_set_points: protocol == Protocol::Dnp3,
        });
        let mut servers = Vec::new();
        if protocol == Protocol::Dnp3 {
            let session = device_config.dnp3.clone().unwrap_or_default();
            let served = dnp3_database(&tags, &ids);
            for listener in listeners {
                servers.push(Server::Dnp3(Dnp3Outstation::start_on(
                    listener,
                    OutstationConfig {
                        address: *session.outstation_address.get_ref(),
                        master_address: *session.master_address.get_ref(),
                        // Analogs report moves of 1 %, as an RTU's deadband
                        // would, not every step of the plant model.
                        analog_deadband: 0.01,
                        ..OutstationConfig::default()
                    },
                    served.clone(),
                    Arc::clone(&db),
                    Arc::clone(&writer),
                )));
            }
        } else {
            let link = device_config.iec104.clone().unwrap_or_default();
            let cfg = station_config(&link, iec104_exports(&tags));
            for listener in listeners {
                let ctx = ServerContext {
                    db: Arc::clone(&db),
                    writer: Arc::clone(&writer),
                    audit: Arc::new(NoAudit),
                    clock: Arc::clone(&shared.clock),
                    counters: Arc::new(ServerCounters::default()),
                };
                servers.push(Server::Iec104(
                    Iec104Server::start_on(listener, &cfg, plant, ctx)
                        .map_err(|e| Error::Config(format!("station '{device}': {e}")))?,
                ));
            }
        }
        // A station no model drives never changes: nothing to refresh.
        let refresh = tokio::spawn(async move {
            if !driven {
                return;
            }
            loop {
                tokio::select! {
                    _ = shared.clock.sleep(tick) => {}
                    _ = shutdown.wait_for(|s| *s) => return,
                }
                points.refresh(&shared, index, false);
            }
        });
        Ok(Station { servers, refresh })
    }

    pub(crate) async fn shutdown(self) {
        self.refresh.abort();
        for s in self.servers {
            match s {
                Server::Iec104(s) => s.shutdown().await,
                Server::Dnp3(s) => s.shutdown().await,
            }
        }
    }
}

/// The exported points of an IEC 104 station: each tag's point as the
/// master expects it.
fn iec104_exports(tags: &[&TagConfig]) -> Vec<Iec104ExportConfig> {
    tags.iter()
        .filter_map(|t| {
            let c = t.iec104.as_ref()?;
            Some(Iec104ExportConfig {
                tag: t.name.clone(),
                ioa: c.ioa.clone(),
                point: c.point.clone(),
                deadband: Spanned::new(0..0, 0.0),
                cyclic_s: Spanned::new(0..0, 0.0),
                command: c.command.clone(),
                command_ioa: c.command_ioa.clone(),
                select: c.select,
            })
        })
        .collect()
}

/// The points and controls of a DNP3 outstation: each tag's point and
/// index, analogs of integer tags sent as integers, and its control
/// (CROB or analog output block) on its command index.
fn dnp3_database(tags: &[&TagConfig], ids: &[TagId]) -> ServedDatabase {
    let mut db = ServedDatabase::default();
    for (t, id) in tags.iter().zip(ids) {
        let Some(c) = &t.dnp3 else { continue };
        let kind = gridscada_dnp3::client::kind_of(*c.point.get_ref());
        db.points.push(ServedPoint {
            id: *id,
            point: Point {
                kind,
                index: *c.index.get_ref(),
                integer: !matches!(t.data_type(), DataType::F32 | DataType::F64),
            },
        });
        let control = ServedControl {
            tag: t.name.get_ref().clone(),
        };
        match c.command.as_ref().map(|c| *c.get_ref()) {
            Some(Dnp3Command::Crob) => {
                db.crobs.insert(c.command_index(), control);
            }
            Some(Dnp3Command::AnalogOutput) => {
                db.analog_outputs.insert(c.command_index(), control);
            }
            None => {}
        }
    }
    db
}

/// The controlled station's settings from the master's view of the device:
/// the same common address and APCI parameters, every point exported as
/// the master expects it, any master on loopback allowed.
fn station_config(
    link: &Iec104DeviceConfig,
    points: Vec<Iec104ExportConfig>,
) -> Iec104ServerConfig {
    Iec104ServerConfig {
        listen: Spanned::new(0..0, String::new()),
        allowed_clients: vec![Spanned::new(0..0, "127.0.0.1".to_string())],
        max_connections: Spanned::new(0..0, 4),
        common_address: link.common_address.clone(),
        k: link.k.clone(),
        w: link.w.clone(),
        t1_s: link.t1_s.clone(),
        t2_s: link.t2_s.clone(),
        t3_s: link.t3_s.clone(),
        // The plant's own roles and limits apply where the command is
        // given; the RTU takes what reaches it.
        command_role: Spanned::new(0..0, Role::Administrator),
        select_timeout_s: Spanned::new(0..0, 30.0),
        interrogation_time_tags: true,
        points,
    }
}
