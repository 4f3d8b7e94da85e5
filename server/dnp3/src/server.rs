//! The outstation's I/O shell: a TCP listener whose master (one at a time;
//! a new connection replaces the old) is served by
//! [`crate::outstation::Outstation`] over points of a tag database, each
//! change an event with the sample's timestamp, and whose controls go
//! through a [`TagWriter`]. gridscada's simulator serves its simulated
//! DNP3 outstations with it, over a point database of their own.
//!
//! **Must not touch:** the master side ([`crate::client`]), configuration,
//! SQL, HTTP. Values are sent as they are in the database (no scaling).

use std::collections::HashMap;
use std::sync::Arc;
use std::time::Duration;

use gridscada_tagdb::{TagDb, TagId, TagWriter, Value};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::watch;
use tokio::task::JoinHandle;
use tokio::time::Instant;

use crate::objects::{CommandObject, CommandStatus, DoubleBit, MeasurementKind};
use crate::outstation::{Outstation, OutstationAction, OutstationConfig, Point, PointValue};

/// A point served from a tag.
#[derive(Debug, Clone)]
pub struct ServedPoint {
    pub id: TagId,
    pub point: Point,
}

/// What a control on an index writes.
#[derive(Debug, Clone)]
pub struct ServedControl {
    /// The tag written: `true`/`false` for a CROB (LATCH_ON, PULSE_ON and
    /// CLOSE are `true`), the output's value as a float for an analog
    /// output block.
    pub tag: String,
}

/// The points and controls of one outstation.
#[derive(Debug, Clone, Default)]
pub struct ServedDatabase {
    pub points: Vec<ServedPoint>,
    /// CROB (g12) controls by index.
    pub crobs: HashMap<u16, ServedControl>,
    /// Analog output block (g41) controls by index.
    pub analog_outputs: HashMap<u16, ServedControl>,
}

/// A running outstation.
pub struct Dnp3Outstation {
    shutdown: watch::Sender<bool>,
    task: JoinHandle<()>,
}

impl Dnp3Outstation {
    /// Serves `served` of `db` on `listener`, controls through `writer`.
    pub fn start_on(
        listener: TcpListener,
        cfg: OutstationConfig,
        served: ServedDatabase,
        db: Arc<TagDb>,
        writer: Arc<dyn TagWriter>,
    ) -> Dnp3Outstation {
        let (shutdown, rx) = watch::channel(false);
        let task = tokio::spawn(run(listener, cfg, served, db, writer, rx));
        Dnp3Outstation { shutdown, task }
    }

    pub async fn shutdown(self) {
        let _ = self.shutdown.send(true);
        let _ = self.task.await;
    }
}

/// The outstation's value of a tag's sample: binaries and double-bits
/// from a bool (or the double-bit's two bits as an integer), counters
/// from an integer, analogs as a number; `None` when the value cannot be
/// one.
fn point_value(kind: MeasurementKind, v: &Value) -> Option<PointValue> {
    Some(match kind {
        MeasurementKind::Binary | MeasurementKind::BinaryOutputStatus => {
            PointValue::Binary(v.as_bool()?)
        }
        MeasurementKind::DoubleBit => PointValue::DoubleBit(match v {
            Value::Bool(true) => DoubleBit::On,
            Value::Bool(false) => DoubleBit::Off,
            other => DoubleBit::from_bits(other.as_f64()?.clamp(0.0, 3.0) as u8),
        }),
        MeasurementKind::Counter | MeasurementKind::FrozenCounter => {
            PointValue::Counter(v.as_f64()?.clamp(0.0, f64::from(u32::MAX)) as u32)
        }
        MeasurementKind::Analog | MeasurementKind::AnalogOutputStatus => {
            PointValue::Analog(v.as_f64()?)
        }
    })
}

/// The value a control writes, or why it cannot.
fn control_value(object: &CommandObject) -> Result<Value, CommandStatus> {
    match object {
        CommandObject::Crob(c) => match (c.code >> 6, c.code & 0x0F) {
            (1, _) => Ok(Value::Bool(true)),
            (2, _) => Ok(Value::Bool(false)),
            (0, 1 | 3) => Ok(Value::Bool(true)),
            (0, 2 | 4) => Ok(Value::Bool(false)),
            _ => Err(CommandStatus::NotSupported),
        },
        CommandObject::Analog(a) => Ok(Value::Float(match *a {
            crate::objects::AnalogOutput::I32(v) => f64::from(v),
            crate::objects::AnalogOutput::I16(v) => f64::from(v),
            crate::objects::AnalogOutput::F32(v) => f64::from(v),
            crate::objects::AnalogOutput::F64(v) => v,
        })),
    }
}

struct Session {
    os: Outstation,
    served: ServedDatabase,
    db: Arc<TagDb>,
    writer: Arc<dyn TagWriter>,
    by_id: HashMap<TagId, Point>,
    timer: Option<Instant>,
}

impl Session {
    /// Every point's value as it stands (changes become events).
    fn sync_all(&mut self) -> Vec<OutstationAction> {
        let mut out = Vec::new();
        for p in &self.served.points {
            if let Some(s) = self.db.get(p.id) {
                if let Some(v) = point_value(p.point.kind, &s.value) {
                    out.extend(self.os.update(
                        p.point.kind,
                        p.point.index,
                        v,
                        s.quality.is_good(),
                        s.timestamp.as_millis().max(0) as u64,
                        Instant::now().into_std(),
                    ));
                }
            }
        }
        out
    }

    /// Carries out the machine's actions on `stream`.
    async fn carry_out(
        &mut self,
        mut actions: Vec<OutstationAction>,
        stream: &mut TcpStream,
    ) -> std::io::Result<()> {
        while !actions.is_empty() {
            let mut next = Vec::new();
            for a in actions {
                match a {
                    OutstationAction::Send(b) => stream.write_all(&b).await?,
                    OutstationAction::Timer(at) => {
                        let at = Instant::from_std(at);
                        self.timer = Some(self.timer.map_or(at, |t| t.min(at)));
                    }
                    OutstationAction::TimeSet(_) => {}
                    OutstationAction::Operate {
                        seq,
                        commands,
                        request,
                        respond,
                        ..
                    } => {
                        let mut statuses = Vec::with_capacity(commands.len());
                        for (index, object) in &commands {
                            statuses.push(self.operate(*index, object).await);
                        }
                        next.extend(self.os.operated(seq, &request, &statuses, respond));
                    }
                }
            }
            actions = next;
        }
        Ok(())
    }

    async fn operate(&self, index: u16, object: &CommandObject) -> CommandStatus {
        let control = match object {
            CommandObject::Crob(_) => self.served.crobs.get(&index),
            CommandObject::Analog(_) => self.served.analog_outputs.get(&index),
        };
        let Some(control) = control else {
            return CommandStatus::NotSupported;
        };
        let value = match control_value(object) {
            Ok(v) => v,
            Err(status) => return status,
        };
        match self.writer.write(&control.tag, value).await {
            Ok(_) => CommandStatus::Success,
            Err(e) if e.is_refusal() => CommandStatus::NotAuthorized,
            Err(_) => CommandStatus::HardwareError,
        }
    }
}

async fn run(
    listener: TcpListener,
    cfg: OutstationConfig,
    served: ServedDatabase,
    db: Arc<TagDb>,
    writer: Arc<dyn TagWriter>,
    mut shutdown: watch::Receiver<bool>,
) {
    let by_id: HashMap<TagId, Point> = served.points.iter().map(|p| (p.id, p.point)).collect();
    let ids: Vec<TagId> = served.points.iter().map(|p| p.id).collect();
    let mut session = Session {
        os: Outstation::new(
            cfg,
            served.points.iter().map(|p| p.point),
            served.crobs.keys().copied(),
            served.analog_outputs.keys().copied(),
        ),
        served,
        db: Arc::clone(&db),
        writer,
        by_id,
        timer: None,
    };
    // Changes while no master is connected are kept as events.
    let mut changes = db.subscribe(&ids);
    session.sync_all();
    let mut stream: Option<TcpStream> = None;
    let mut buf = vec![0u8; 4096];
    loop {
        let timer = session
            .timer
            .unwrap_or_else(|| Instant::now() + Duration::from_secs(3600));
        let actions = tokio::select! {
            _ = shutdown.changed() => return,
            accepted = listener.accept() => match accepted {
                Ok((s, peer)) => {
                    tracing::info!(%peer, "DNP3 outstation: master connected");
                    let _ = s.set_nodelay(true);
                    stream = Some(s);
                    session.os.connected();
                    session.timer = None;
                    Vec::new()
                }
                Err(e) => {
                    tracing::warn!(error = %e, "DNP3 outstation: accept failed");
                    tokio::time::sleep(Duration::from_millis(200)).await;
                    Vec::new()
                }
            },
            read = async {
                match stream.as_mut() {
                    Some(s) => s.read(&mut buf).await,
                    None => std::future::pending().await,
                }
            } => match read {
                Ok(0) | Err(_) => {
                    stream = None;
                    Vec::new()
                }
                Ok(n) => session.os.received(&buf[..n], Instant::now().into_std()),
            },
            update = changes.recv() => {
                let Some(update) = update else { return };
                let mut out = Vec::new();
                for (id, s) in update.batch().changes.iter() {
                    let Some(p) = session.by_id.get(id).copied() else { continue };
                    if let Some(v) = point_value(p.kind, &s.value) {
                        out.extend(session.os.update(
                            p.kind,
                            p.index,
                            v,
                            s.quality.is_good(),
                            s.timestamp.as_millis().max(0) as u64,
                            Instant::now().into_std(),
                        ));
                    }
                }
                out
            },
            _ = tokio::time::sleep_until(timer) => {
                session.timer = None;
                session.os.tick(Instant::now().into_std())
            }
        };
        if let Some(s) = stream.as_mut() {
            if session.carry_out(actions, s).await.is_err() {
                stream = None;
            }
        }
    }
}
