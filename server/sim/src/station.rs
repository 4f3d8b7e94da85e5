//! The I/O shell of a simulated IEC 60870-5-104 station (a `protocol =
//! "iec104"` device): gridscada's own controlled station
//! (`gridscada_iec104::Iec104Server`) over a point database of the
//! station's own, which the plant models fill, so the station answers
//! interrogations, sends spontaneous data with the plant's time tags, and
//! takes select-before-operate and direct commands as an RTU would.
//!
//! Owns that point database, its refresh from the models, the translation
//! between engineering values and the raw values the master scales back
//! (`raw * scale + offset`), and the command path into the models. Must
//! not touch the server's tag database (the station's points are private
//! to the simulator), the models' behaviour, or the Modbus gateways.

use std::sync::Arc;
use std::time::Duration;

use gridscada_config::{
    Iec104DeviceConfig, Iec104ExportConfig, Iec104Point, Iec104ServerConfig, Plant, Role, TagConfig,
};
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
    fn of(tag: &TagConfig, point: Iec104Point) -> Encoding {
        let kind = match point {
            Iec104Point::M_SP => ValueKind::Bool,
            Iec104Point::M_DP if tag.value_kind() == ValueKind::Bool => ValueKind::Bool,
            Iec104Point::M_DP | Iec104Point::M_ST | Iec104Point::M_BO | Iec104Point::M_IT => {
                ValueKind::Int
            }
            Iec104Point::M_ME_NA | Iec104Point::M_ME_NB | Iec104Point::M_ME_NC => ValueKind::Float,
        };
        let scale = *tag.scale.get_ref();
        Encoding {
            kind,
            scale: if scale == 0.0 { 1.0 } else { scale },
            offset: tag.offset,
        }
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
    /// Sets every point from the models' values, stamped with plant time.
    fn refresh(&self, shared: &Shared, station: usize) {
        let (values, now) = shared.with_plant(|p| (p.station_values(station).to_vec(), p.now()));
        let batch: Vec<(TagId, Sample)> = self
            .ids
            .iter()
            .zip(&self.encodings)
            .zip(values)
            .filter_map(|((&id, e), v)| {
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
}

impl TagWriter for StationWriter {
    fn write<'a>(&'a self, name: &'a str, value: Value) -> WriteFuture<'a> {
        Box::pin(async move {
            let v = match &value {
                Value::Bool(b) => f64::from(u8::from(*b)),
                other => other.as_f64().ok_or_else(|| WriteError::BadValue {
                    tag: name.to_string(),
                    value: other.to_string(),
                    reason: "not a number".into(),
                })?,
            };
            let now = self.shared.clock.now();
            self.shared
                .plant
                .lock()
                .station_command(self.station, name, v, now)
                .map_err(|reason| WriteError::Device {
                    device: "simulated station".into(),
                    reason,
                })?;
            self.points.refresh(&self.shared, self.station);
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

/// A running simulated station: one controlled station per address of
/// its redundancy group, over the same points.
pub(crate) struct Station {
    servers: Vec<Iec104Server>,
    refresh: tokio::task::JoinHandle<()>,
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
            let sim = shared.plant.lock();
            let station = &sim.stations[index];
            station
                .points
                .iter()
                .map(|p| {
                    plant
                        .tags
                        .iter()
                        .find(|t| t.name.get_ref() == &p.tag)
                        .ok_or_else(|| Error::Config(format!("no tag '{}'", p.tag)))
                })
                .collect::<Result<_, _>>()?
        };
        let mut metas = Vec::new();
        let mut encodings = Vec::new();
        let mut exports = Vec::new();
        for t in &tags {
            let Some(c) = &t.iec104 else {
                return Err(Error::Config(format!(
                    "tag '{}' of IEC 104 device '{device}' has no iec104 point",
                    t.name.get_ref()
                )));
            };
            let e = Encoding::of(t, *c.point.get_ref());
            metas.push(TagMeta::new(t.name.get_ref().as_str(), e.kind));
            encodings.push(e);
            exports.push(Iec104ExportConfig {
                tag: t.name.clone(),
                ioa: c.ioa.clone(),
                point: c.point.clone(),
                deadband: Spanned::new(0..0, 0.0),
                cyclic_s: Spanned::new(0..0, 0.0),
                command: c.command.clone(),
                command_ioa: c.command_ioa.clone(),
                select: c.select,
            });
        }
        let db = Arc::new(
            TagDb::new(metas).map_err(|e| Error::Config(format!("station '{device}': {e}")))?,
        );
        let ids = tags
            .iter()
            .map(|t| db.id(t.name.get_ref()).expect("just added"))
            .collect();
        let points = Arc::new(Points {
            db: Arc::clone(&db),
            ids,
            encodings,
        });
        points.refresh(&shared, index);

        let link = plant
            .devices
            .iter()
            .find(|d| d.name.get_ref() == device)
            .and_then(|d| d.iec104.clone())
            .unwrap_or_default();
        let cfg = station_config(&link, exports);
        let writer: Arc<dyn TagWriter> = Arc::new(StationWriter {
            shared: Arc::clone(&shared),
            station: index,
            points: Arc::clone(&points),
        });
        let mut servers = Vec::new();
        for listener in listeners {
            let ctx = ServerContext {
                db: Arc::clone(&db),
                writer: Arc::clone(&writer),
                audit: Arc::new(NoAudit),
                clock: Arc::clone(&shared.clock),
                counters: Arc::new(ServerCounters::default()),
            };
            servers.push(
                Iec104Server::start_on(listener, &cfg, plant, ctx)
                    .map_err(|e| Error::Config(format!("station '{device}': {e}")))?,
            );
        }
        let refresh = tokio::spawn(async move {
            loop {
                tokio::select! {
                    _ = shared.clock.sleep(tick) => {}
                    _ = shutdown.wait_for(|s| *s) => return,
                }
                points.refresh(&shared, index);
            }
        });
        Ok(Station { servers, refresh })
    }

    pub(crate) async fn shutdown(self) {
        self.refresh.abort();
        for s in self.servers {
            s.shutdown().await;
        }
    }
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
