//! # gridscada-modbus: Modbus field I/O
//!
//! **Owns:** polling the plant's Modbus TCP and RTU devices into the tag
//! database, those devices' communication status tags, and writes to them
//! (confirmed by read-back) through [`gridscada_tagdb::TagWriter`]. Devices
//! of other protocols, and their tags, are left to their own crates; what
//! all protocols share (status tag names, figures, write limits) is in
//! `gridscada-field`.
//!
//! **Must not touch:** configuration parsing (it takes a checked [`Plant`]),
//! alarms, history, control logic. Everything it learns goes into the
//! [`TagDb`] in batches.
//!
//! Layout: [`decode`] (wire ⇄ engineering values) and [`plan`] (block
//! planning) are pure; `frame` holds the byte framing (pure); `transport`
//! one TCP connection or serial port; `link` the task that owns a transport
//! and every device (unit id) behind it.
//!
//! Devices are grouped by transport: all devices with the same TCP address
//! (a gateway and its unit ids) share one connection and one task; all devices
//! on one serial port share one task. A unit that stops answering is backed
//! off and probed so it cannot stall the others.

pub mod decode;
mod frame;
mod link;
pub mod plan;
mod transport;

use std::collections::HashMap;
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::Duration;

use gridscada_config::{DeviceConfig, Plant, Protocol};
use gridscada_field::{
    check_limits, no_write_target, DeviceStats, LinkStats, PollStats, StatsSource,
};
use gridscada_tagdb::{Clock, Leadership, TagDb, TagId, TagWriter, Value, WriteError, WriteFuture};
use parking_lot::Mutex;
use tokio::sync::{mpsc, oneshot, watch};
use tokio::task::JoinHandle;

pub use frame::exception_text;
pub use transport::inter_frame_silence;

use link::{ClassRt, Counters, DeviceRt, Link, LinkCounters, LinkTag, WriteCmd};
use transport::{RtuLine, TcpLine, Transport};

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Error {
    #[error("tag '{0}' is in the configuration but not in the tag database")]
    MissingTag(String),
    #[error("device '{device}': {reason}")]
    Device { device: String, reason: String },
    #[error("device '{device}': block planning failed: {reason}")]
    Plan { device: String, reason: String },
}

struct WriteTarget {
    link: usize,
    tag: usize,
    codec: decode::Codec,
    /// Engineering limits (`Plant::write_limits`), checked before anything
    /// is sent, for every writer: HMI, control loops, northbound.
    limits: (Option<f64>, Option<f64>),
}

struct Shared {
    links: Vec<mpsc::Sender<WriteCmd>>,
    /// The writable tags only: a read-only one is told apart from an
    /// unknown one by the tag database (most of a large plant is read-only).
    targets: HashMap<TagId, WriteTarget>,
    db: Arc<TagDb>,
    /// The fencing gate (asked again by the link as the frame goes out).
    leadership: Leadership,
}

struct DeviceStatsSource {
    device: String,
    link: String,
    counters: Arc<Counters>,
}

struct LinkStatsSource {
    link: String,
    counters: Arc<LinkCounters>,
    last_error: Arc<Mutex<String>>,
}

/// The running field I/O: one task per connection or serial port.
pub struct FieldIo {
    shared: Arc<Shared>,
    counters: ModbusStats,
    shutdown: watch::Sender<bool>,
    tasks: Vec<JoinHandle<()>>,
}

/// The key that groups devices onto one task.
fn transport_key(d: &DeviceConfig) -> Result<String, Error> {
    let err = |reason: &str| Error::Device {
        device: d.name.get_ref().clone(),
        reason: reason.into(),
    };
    match d.protocol {
        Protocol::Tcp => d
            .address
            .as_ref()
            .map(|a| format!("tcp://{}", a.get_ref()))
            .ok_or_else(|| err("a tcp device needs an address")),
        Protocol::Rtu => d
            .serial
            .as_ref()
            .map(|s| format!("rtu://{}", s.port.get_ref()))
            .ok_or_else(|| err("an rtu device needs a serial port")),
        Protocol::Iec104 | Protocol::Dnp3 | Protocol::Iec61850 => Err(err("not a Modbus device")),
    }
}

impl FieldIo {
    /// Plans every device's blocks and starts one task per connection or
    /// serial port. Must be called inside a Tokio runtime. The plant's tags
    /// and `gridscada_field::device_status_tags` must already be in `db`.
    pub fn start(plant: &Plant, db: Arc<TagDb>, clock: Arc<dyn Clock>) -> Result<FieldIo, Error> {
        Self::start_fenced(plant, db, clock, Leadership::sole(), None)
    }

    /// [`FieldIo::start`] for a server of a redundant pair: every write
    /// asks `leadership` for its epoch the moment its frame goes out, and
    /// is refused ([`WriteError::NotActive`]) without it. Polling goes on
    /// either way, so a standby's tag database stays warm. A TCP device
    /// whose address `pipes` serves is reached over an in-process pipe.
    pub fn start_fenced(
        plant: &Plant,
        db: Arc<TagDb>,
        clock: Arc<dyn Clock>,
        leadership: Leadership,
        pipes: Option<Arc<gridscada_field::Switchboard>>,
    ) -> Result<FieldIo, Error> {
        let (shutdown, shutdown_rx) = watch::channel(false);
        // Group devices by transport, keeping configuration order.
        let mut keys: Vec<String> = Vec::new();
        let mut groups: HashMap<String, Vec<&DeviceConfig>> = HashMap::new();
        for d in plant.devices.iter().filter(|d| d.protocol.is_modbus()) {
            let key = transport_key(d)?;
            if !groups.contains_key(&key) {
                keys.push(key.clone());
            }
            groups.entry(key).or_default().push(d);
        }
        let mut device_link: HashMap<&str, (usize, usize)> = HashMap::new();
        for (li, key) in keys.iter().enumerate() {
            for (di, d) in groups[key].iter().enumerate() {
                device_link.insert(d.name.get_ref().as_str(), (li, di));
            }
        }
        // Tags per link.
        let mut link_tags: Vec<Vec<LinkTag>> = keys.iter().map(|_| Vec::new()).collect();
        let mut points: Vec<Vec<Vec<plan::Point>>> = keys
            .iter()
            .map(|k| groups[k].iter().map(|_| Vec::new()).collect())
            .collect();
        let mut targets = HashMap::new();
        for t in &plant.tags {
            let name = t.name.get_ref();
            if plant
                .device(t.device.get_ref())
                .is_some_and(|d| !d.protocol.is_modbus())
            {
                continue;
            }
            let Some(&(li, di)) = device_link.get(t.device.get_ref().as_str()) else {
                return Err(Error::Device {
                    device: t.device.get_ref().clone(),
                    reason: format!("unknown device of tag '{name}'"),
                });
            };
            let id = db.id(name).ok_or_else(|| Error::MissingTag(name.clone()))?;
            let device = groups[&keys[li]][di];
            let Some((table, address)) = t.register() else {
                return Err(Error::Device {
                    device: device.name.get_ref().clone(),
                    reason: format!("tag '{name}' has no Modbus kind and address"),
                });
            };
            let codec = decode::Codec::from_tag(t, table);
            let address = u16::try_from(address).map_err(|_| Error::Device {
                device: device.name.get_ref().clone(),
                reason: format!("tag '{name}': address {address} is past 65535"),
            })?;
            let index = link_tags[li].len();
            points[li][di].push(plan::Point {
                tag: index,
                table: codec.table,
                address,
                width: codec.width,
                scan_ms: t.scan_ms(device).max(10),
            });
            if *t.writable.get_ref() && codec.table.is_writable() {
                targets.insert(
                    id,
                    WriteTarget {
                        link: li,
                        tag: index,
                        codec: codec.clone(),
                        limits: plant.write_limits(t.name.get_ref()),
                    },
                );
            }
            // The tag database's name, shared rather than copied.
            let name = db
                .meta(id)
                .map_or_else(|| Arc::from(name.as_str()), |m| m.name.clone());
            link_tags[li].push(LinkTag {
                name,
                id,
                device: di,
                address,
                codec,
                time_from: None,
            });
        }
        // Device clocks: each tag stamped by a clock knows the clock's index
        // in its link (same device, so same link; `check` guarantees it).
        for t in &plant.tags {
            let Some(&(li, di)) = device_link.get(t.device.get_ref().as_str()) else {
                continue;
            };
            let Some(clock) = t.time_tag(groups[&keys[li]][di]) else {
                continue;
            };
            let index_of = |n: &str| link_tags[li].iter().position(|x| &*x.name == n);
            if let (Some(i), Some(c)) = (index_of(t.name.get_ref()), index_of(clock)) {
                link_tags[li][i].time_from = Some(c);
            }
        }
        let now = clock.now();
        let mut senders = Vec::new();
        let mut stats = Vec::new();
        let mut link_stats = Vec::new();
        let mut links = Vec::new();
        for (li, key) in keys.iter().enumerate() {
            let devs = &groups[key];
            let mut devices = Vec::new();
            for (di, d) in devs.iter().enumerate() {
                let dname = d.name.get_ref().clone();
                let limits = plan::Limits {
                    max_registers: *d.max_read_registers.get_ref(),
                    max_bits: *d.max_read_bits.get_ref(),
                    max_gap: d.max_gap,
                };
                let classes =
                    plan::plan_device(&points[li][di], limits).map_err(|e| Error::Plan {
                        device: dname.clone(),
                        reason: e.to_string(),
                    })?;
                let status =
                    gridscada_field::StatusIds::resolve(&db, &dname).map_err(Error::MissingTag)?;
                let counters = Arc::new(Counters::default());
                stats.push(DeviceStatsSource {
                    device: dname.clone(),
                    link: key.clone(),
                    counters: Arc::clone(&counters),
                });
                let fastest_scan = classes
                    .iter()
                    .map(|c| Duration::from_millis(c.period_ms))
                    .min()
                    .unwrap_or(Duration::from_secs(1));
                devices.push(DeviceRt {
                    name: dname,
                    unit: *d.unit_id.get_ref(),
                    timeout: Duration::from_millis((*d.timeout_ms.get_ref()).max(1)),
                    retries: d.retries,
                    max_write_registers: *d.max_write_registers.get_ref(),
                    classes: classes
                        .into_iter()
                        .map(|c| ClassRt {
                            period: Duration::from_millis(c.period_ms),
                            tags: c.blocks.iter().flat_map(|b| b.tags.clone()).collect(),
                            blocks: c.blocks,
                            next_due: now,
                            last_answer: now,
                            stale: false,
                        })
                        .collect(),
                    status,
                    counters,
                    answering: false,
                    failures: 0,
                    failing: false,
                    probe_wait: Duration::ZERO,
                    probe_cap: d.backoff_max(fastest_scan),
                    next_probe: now,
                    last_error: String::new(),
                    response_ms: 0.0,
                });
            }
            let first = devs[0];
            let transport = match first.protocol {
                Protocol::Tcp | Protocol::Iec104 | Protocol::Dnp3 | Protocol::Iec61850 => {
                    Transport::Tcp(TcpLine::new(
                        first
                            .address
                            .as_ref()
                            .map(|a| a.get_ref().clone())
                            .unwrap_or_default(),
                        pipes.clone(),
                    ))
                }
                Protocol::Rtu => {
                    let serial = first.serial.clone().ok_or_else(|| Error::Device {
                        device: first.name.get_ref().clone(),
                        reason: "an rtu device needs a serial port".into(),
                    })?;
                    // Devices on one port must agree on the line settings.
                    for d in devs.iter().skip(1) {
                        let s = d.serial.as_ref();
                        let same = s.is_some_and(|s| {
                            s.baud == serial.baud
                                && s.parity == serial.parity
                                && s.data_bits.get_ref() == serial.data_bits.get_ref()
                                && s.stop_bits.get_ref() == serial.stop_bits.get_ref()
                        });
                        if !same {
                            return Err(Error::Device {
                                device: d.name.get_ref().clone(),
                                reason: format!(
                                    "serial settings differ from device '{}' on the same port {}",
                                    first.name.get_ref(),
                                    serial.port.get_ref()
                                ),
                            });
                        }
                    }
                    Transport::Rtu(RtuLine::new(serial))
                }
            };
            let (tx, rx) = mpsc::channel(64);
            senders.push(tx);
            let lc = Arc::new(LinkCounters::default());
            let last_error = Arc::new(Mutex::new(String::new()));
            link_stats.push(LinkStatsSource {
                link: key.clone(),
                counters: Arc::clone(&lc),
                last_error: Arc::clone(&last_error),
            });
            // The longest the link can be held by one request and its
            // retries: how late a neighbour's scan may be without being lost.
            let longest_hold = devices
                .iter()
                .map(|d| d.timeout * (1 + d.retries))
                .max()
                .unwrap_or_default();
            links.push(Link {
                name: key.clone(),
                transport,
                longest_hold,
                has_clocks: link_tags[li].iter().any(|t| t.time_from.is_some()),
                devices,
                tags: std::mem::take(&mut link_tags[li]),
                db: Arc::clone(&db),
                clock: Arc::clone(&clock),
                writes: rx,
                counters: lc,
                reconnect_wait: Duration::from_millis(250),
                next_connect: now,
                silent_timeouts: 0,
                last_link_error: last_error,
                leadership: leadership.clone(),
            });
        }
        let tasks = links
            .into_iter()
            .map(|l| tokio::spawn(l.run(shutdown_rx.clone())))
            .collect();
        Ok(FieldIo {
            shared: Arc::new(Shared {
                links: senders,
                targets,
                db: db.clone(),
                leadership,
            }),
            counters: ModbusStats {
                stats: Arc::new(stats),
                link_stats: Arc::new(link_stats),
            },
            shutdown,
            tasks,
        })
    }

    /// The command path into the field, for control loops and the web API.
    pub fn writer(&self) -> Arc<dyn TagWriter> {
        Arc::new(FieldWriter {
            shared: Arc::clone(&self.shared),
        })
    }

    /// Counters of every device and link, for `/metrics` and benchmarks.
    pub fn stats(&self) -> PollStats {
        self.counters.stats()
    }

    /// A reader of the same counters that lives past the poller, for
    /// whoever reports them (`gridscada_field::StatsHandle`).
    pub fn stats_source(&self) -> Arc<dyn StatsSource> {
        Arc::new(self.counters.clone())
    }

    /// Stops every task and waits for them. Writes still in flight answer
    /// [`WriteError::Closed`].
    pub async fn shutdown(self) {
        let _ = self.shutdown.send(true);
        for t in self.tasks {
            let _ = t.await;
        }
    }
}

/// Reads the poller's counters; cheap to clone, lives past the poller.
#[derive(Clone)]
struct ModbusStats {
    stats: Arc<Vec<DeviceStatsSource>>,
    link_stats: Arc<Vec<LinkStatsSource>>,
}

impl StatsSource for ModbusStats {
    /// Connection attempts and requests waiting for an answer right now, over
    /// every link.
    fn in_flight(&self) -> u64 {
        self.link_stats
            .iter()
            .map(|s| s.counters.in_flight.load(Ordering::SeqCst))
            .sum()
    }

    /// Counters of every device and link.
    fn stats(&self) -> PollStats {
        let get = |a: &std::sync::atomic::AtomicU64| a.load(Ordering::Relaxed);
        PollStats {
            devices: self
                .stats
                .iter()
                .map(|s| {
                    let c = &s.counters;
                    DeviceStats {
                        device: s.device.clone(),
                        link: s.link.clone(),
                        connected: c.connected.load(Ordering::Relaxed),
                        requests: get(&c.requests),
                        errors: get(&c.errors),
                        timeouts: get(&c.timeouts),
                        exceptions: get(&c.exceptions),
                        writes: get(&c.writes),
                        scans: get(&c.scans),
                        late_scans: get(&c.late_scans),
                        overruns: get(&c.overruns),
                        last_response_ms: get(&c.response_us) as f64 / 1000.0,
                        round_trip: c.round_trips.snapshot(),
                        ..Default::default()
                    }
                })
                .collect(),
            links: self
                .link_stats
                .iter()
                .map(|s| LinkStats {
                    link: s.link.clone(),
                    connects: get(&s.counters.connects),
                    disconnects: get(&s.counters.disconnects),
                    late_replies: get(&s.counters.late_replies),
                    garbage_bytes: get(&s.counters.garbage_bytes),
                    last_error: s.last_error.lock().clone(),
                })
                .collect(),
        }
    }
}

struct FieldWriter {
    shared: Arc<Shared>,
}

impl TagWriter for FieldWriter {
    fn write<'a>(&'a self, name: &'a str, value: Value) -> WriteFuture<'a> {
        Box::pin(async move {
            let shared = &self.shared;
            let target = shared
                .db
                .id(name)
                .and_then(|id| shared.targets.get(&id))
                .ok_or_else(|| no_write_target(&shared.db, name))?;
            // Refused early on a standby, with the active server's name; the
            // link asks again at the last moment.
            self.shared
                .leadership
                .permit()
                .map_err(WriteError::NotActive)?;
            check_limits(name, &value, target.limits)?;
            let encoded =
                decode::encode(&target.codec, &value).map_err(|reason| WriteError::BadValue {
                    tag: name.to_string(),
                    value: value.to_string(),
                    reason,
                })?;
            let (reply, rx) = oneshot::channel();
            let cmd = WriteCmd {
                tag: target.tag,
                value,
                encoded,
                reply,
            };
            self.shared.links[target.link]
                .send(cmd)
                .await
                .map_err(|_| WriteError::Closed)?;
            rx.await.map_err(|_| WriteError::Closed)?
        })
    }
}
