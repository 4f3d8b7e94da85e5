//! The task that owns one TCP connection or serial port and every device
//! (unit id) behind it.
//!
//! **Owns:** scheduling of the planned scan classes, writes (which jump ahead
//! of scheduled reads), device health (retries, back-off and probes),
//! reconnection with exponential back-off, turning answers into tag samples and
//! the devices' communication status tags. One `TagDb::apply` per scan of a
//! device, per write, or per connection event.
//!
//! **Must not touch:** configuration parsing, other links. Scan periods and
//! back-off are plant time (the [`Clock`]); request timeouts are wall time via
//! `Clock::to_wall`.
//!
//! **Why one file (about 900 lines):** it is one task's state machine. Nearly
//! all of it is `impl Link`, whose methods (connect, schedule, request, scan,
//! write, probe, mark a device answered or silent, take the link down,
//! watch staleness) share and change the same
//! state: the connection, the per-device back-off and health, the pending
//! writes and the counters. Split across files, each piece would still need
//! the whole of that state, and a reader following one request from schedule
//! to status tags would jump between them. Decoding and planning, which do
//! not need it, already live in `decode.rs` and `plan.rs`.

use std::borrow::Cow;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Duration;

use gridscada_tagdb::{
    Clock, Leadership, Quality, Sample, TagDb, TagId, Timestamp, Value, WriteError,
};
use parking_lot::Mutex;
use tokio::sync::{mpsc, oneshot, watch};
use tokio_modbus::{Request, Response};

use crate::decode::{self, Codec, Encoded};
use crate::frame::{self, Answer};
use crate::plan::Block;
use crate::transport::{Deadline, LinkError, Transport};

/// First wait before reconnecting a dropped connection; doubles to the cap.
const RECONNECT_FIRST: Duration = Duration::from_millis(250);
const RECONNECT_CAP: Duration = Duration::from_secs(10);
/// A scan that starts more than this share of its period late counts as late.
const LATE_SHARE: f64 = 0.1;

/// One polled tag, as the link sees it.
pub(crate) struct LinkTag {
    pub name: Arc<str>,
    pub id: TagId,
    /// Index of the tag's device in the link.
    pub device: usize,
    pub address: u16,
    pub codec: Codec,
    /// The device clock tag (index in the link) whose reading in the same
    /// scan stamps this tag's samples; `None`: the time the reply arrived.
    pub time_from: Option<usize>,
}

/// Counters shared with [`crate::PollStats`].
#[derive(Default)]
pub(crate) struct Counters {
    pub requests: AtomicU64,
    pub errors: AtomicU64,
    pub timeouts: AtomicU64,
    pub exceptions: AtomicU64,
    pub scans: AtomicU64,
    pub late_scans: AtomicU64,
    pub overruns: AtomicU64,
    pub writes: AtomicU64,
    /// Reads repeated at once after no answer (the device's `retries`).
    pub retries: AtomicU64,
    pub response_us: AtomicU64,
    pub round_trips: gridscada_field::RoundTrips,
    pub connected: AtomicBool,
}

fn bump(c: &AtomicU64) -> u64 {
    c.fetch_add(1, Ordering::Relaxed) + 1
}

pub(crate) struct ClassRt {
    pub period: Duration,
    pub blocks: Vec<Block>,
    /// Every tag of the class, for marking them Bad.
    pub tags: Vec<usize>,
    pub next_due: Timestamp,
    /// When the class was last read with an answer.
    pub last_answer: Timestamp,
    /// Its tags have been marked Bad for want of answers.
    pub stale: bool,
}

pub(crate) struct DeviceRt {
    pub name: String,
    pub unit: u8,
    /// Plant time.
    pub timeout: Duration,
    pub retries: u32,
    pub max_write_registers: u16,
    pub classes: Vec<ClassRt>,
    pub status: gridscada_field::StatusIds,
    pub counters: Arc<Counters>,
    // Health.
    pub answering: bool,
    pub failures: u32,
    pub failing: bool,
    pub probe_wait: Duration,
    /// Longest wait between probes (the device's `backoff_max_ms`).
    pub probe_cap: Duration,
    pub next_probe: Timestamp,
    pub last_error: String,
    pub response_ms: f64,
}

/// A write on its way to a device; the value is already encoded.
pub(crate) struct WriteCmd {
    pub tag: usize,
    pub value: Value,
    pub encoded: Encoded,
    pub reply: oneshot::Sender<Result<Sample, WriteError>>,
}

/// Link-level counters shared with [`crate::PollStats`].
#[derive(Default)]
pub(crate) struct LinkCounters {
    /// Connection attempts and requests waiting for the transport now. Replay
    /// on a virtual clock advances plant time only while this is zero.
    pub in_flight: AtomicU64,
    pub connects: AtomicU64,
    pub disconnects: AtomicU64,
    pub late_replies: AtomicU64,
    pub garbage_bytes: AtomicU64,
}

pub(crate) struct Link {
    pub name: String,
    pub transport: Transport,
    /// The longest one device's request and its retries hold the link
    /// (timeout × (1 + retries)); see [`Link::stale_after`].
    pub longest_hold: Duration,
    /// Whether any tag on the link is stamped by a device clock; without
    /// one, a scan keeps no record of which tag each sample is.
    pub has_clocks: bool,
    pub devices: Vec<DeviceRt>,
    pub tags: Vec<LinkTag>,
    pub db: Arc<TagDb>,
    pub clock: Arc<dyn Clock>,
    pub writes: mpsc::Receiver<WriteCmd>,
    pub counters: Arc<LinkCounters>,
    pub reconnect_wait: Duration,
    pub next_connect: Timestamp,
    /// Timeouts in a row with no answer from anybody on the link.
    pub silent_timeouts: u32,
    pub last_link_error: Arc<Mutex<String>>,
    /// The fencing gate of a redundant pair, asked as a write goes out.
    pub leadership: Leadership,
}

/// What the link does next.
enum Work {
    Scan(usize, usize),
    Probe(usize),
}

impl Link {
    pub async fn run(mut self, mut shutdown: watch::Receiver<bool>) {
        tokio::select! {
            _ = self.serve() => {}
            _ = shutdown.wait_for(|s| *s) => {}
        }
    }

    async fn serve(&mut self) {
        loop {
            self.serve_writes().await;
            if !self.transport.is_connected() {
                self.connect().await;
                continue;
            }
            self.watch_staleness();
            let now = self.clock.now();
            let (due, work) = self.next_work();
            match work {
                Some(w) if due <= now => match w {
                    Work::Scan(d, c) => self.scan(d, c).await,
                    Work::Probe(d) => self.probe(d).await,
                },
                _ => {
                    let wake = due.min(self.next_stale_check());
                    self.idle(wake.since(now)).await;
                }
            }
        }
    }

    /// Waits `d` of plant time, or until a write arrives (served at once).
    async fn idle(&mut self, d: Duration) {
        if d.is_zero() {
            return;
        }
        let sleep = self.clock.sleep(d);
        tokio::select! {
            _ = sleep => {}
            cmd = self.writes.recv() => match cmd {
                Some(cmd) => self.write(cmd).await,
                // Only happens while shutting down; the select in `run` ends us.
                None => std::future::pending::<()>().await,
            },
        }
    }

    async fn serve_writes(&mut self) {
        while let Ok(cmd) = self.writes.try_recv() {
            self.write(cmd).await;
        }
    }

    /// The earliest due scan or probe (a failing device is only probed).
    fn next_work(&self) -> (Timestamp, Option<Work>) {
        let mut best: (Timestamp, Option<Work>) =
            (self.clock.now().add(Duration::from_secs(3600)), None);
        for (d, dev) in self.devices.iter().enumerate() {
            if dev.classes.is_empty() {
                continue;
            }
            if dev.failing {
                if dev.next_probe < best.0 {
                    best = (dev.next_probe, Some(Work::Probe(d)));
                }
                continue;
            }
            for (c, class) in dev.classes.iter().enumerate() {
                if class.next_due < best.0 {
                    best = (class.next_due, Some(Work::Scan(d, c)));
                }
            }
        }
        best
    }

    /// How long a scan class may go unanswered before it is stale: two scan
    /// periods, plus the longest a neighbour's request with its retries may
    /// hold the shared link. Without that allowance a fast-scanned device
    /// behind a gateway went stale, and showed as disconnected, every time a
    /// dead neighbour's request timed out (a comm alarm chattering on a
    /// healthy device).
    fn stale_after(&self, period: Duration) -> Duration {
        stale_after(period, self.longest_hold)
    }

    fn next_stale_check(&self) -> Timestamp {
        let mut t = self.clock.now().add(Duration::from_secs(3600));
        for dev in &self.devices {
            for c in dev.classes.iter().filter(|c| !c.stale) {
                t = t.min(c.last_answer.add(self.stale_after(c.period)));
            }
        }
        t
    }

    /// A class whose device has not answered within [`Link::stale_after`]
    /// turns Bad, whatever else is going on (a stalled line, retries still
    /// pending).
    fn watch_staleness(&mut self) {
        let now = self.clock.now();
        for d in 0..self.devices.len() {
            let hold = self.longest_hold;
            let dev = &mut self.devices[d];
            let mut ids = Vec::new();
            for c in dev.classes.iter_mut() {
                if !c.stale && now.since(c.last_answer) >= stale_after(c.period, hold) {
                    c.stale = true;
                    ids.extend(c.tags.iter().map(|&t| self.tags[t].id));
                }
            }
            if ids.is_empty() {
                continue;
            }
            let reason = if dev.last_error.is_empty() {
                "no answer from the device".to_string()
            } else {
                format!("no answer from the device: {}", dev.last_error)
            };
            // Not heard from in that time: not connected either.
            dev.answering = false;
            dev.counters.connected.store(false, Ordering::Relaxed);
            let q = Quality::bad(reason);
            let mut batch = bad_samples(&self.db, &ids, &q, now);
            batch.extend(status_samples(dev, now));
            self.db.apply(batch);
        }
    }

    async fn connect(&mut self) {
        let now = self.clock.now();
        if now < self.next_connect {
            self.idle(self.next_connect.since(now)).await;
            return;
        }
        let timeout = self
            .devices
            .iter()
            .map(|d| d.timeout)
            .max()
            .unwrap_or(Duration::from_secs(1));
        let wall = self.clock.to_wall(timeout.max(Duration::from_millis(100)));
        let busy = InFlight::new(&self.counters);
        let connected = self.transport.connect(wall).await;
        drop(busy);
        match connected {
            Ok(()) => {
                self.counters.connects.fetch_add(1, Ordering::Relaxed);
                self.reconnect_wait = RECONNECT_FIRST;
                self.silent_timeouts = 0;
                self.last_link_error.lock().clear();
                tracing::info!(link = %self.name, "connected");
                // Scan everything at once; failing devices keep their probes.
                let now = self.clock.now();
                for dev in &mut self.devices {
                    for c in &mut dev.classes {
                        c.next_due = now;
                    }
                }
            }
            Err(e) => {
                tracing::warn!(link = %self.name, error = %e, "connect failed");
                self.link_down(&e);
            }
        }
    }

    /// The connection is gone: every device on it is Bad until it is back.
    fn link_down(&mut self, reason: &str) {
        *self.last_link_error.lock() = reason.to_string();
        let now = self.clock.now();
        self.next_connect = now.add(self.reconnect_wait);
        self.reconnect_wait = (self.reconnect_wait * 2).min(RECONNECT_CAP);
        let q = Quality::bad(format!("communication lost: {reason}"));
        for d in 0..self.devices.len() {
            let dev = &mut self.devices[d];
            dev.answering = false;
            dev.last_error = reason.to_string();
            dev.counters.connected.store(false, Ordering::Relaxed);
            let mut batch: Vec<(TagId, Sample)> = Vec::new();
            for c in &mut dev.classes {
                c.stale = true;
                for &t in &c.tags {
                    let id = self.tags[t].id;
                    if let Some(s) = self.db.get(id) {
                        if s.quality != q {
                            batch.push((
                                id,
                                Sample {
                                    value: s.value,
                                    quality: q.clone(),
                                    timestamp: now,
                                },
                            ));
                        }
                    }
                }
            }
            batch.extend(status_samples(&self.devices[d], now));
            self.db.apply(batch);
        }
    }

    /// One request to device `d`, with its timeout, counted.
    async fn request(&mut self, d: usize, req: &Request<'_>) -> Result<Answer, LinkError> {
        let dev = &self.devices[d];
        let deadline = Deadline::new(
            self.clock.to_wall(dev.timeout),
            self.clock.request_wait(dev.timeout),
        );
        let unit = dev.unit;
        let started = tokio::time::Instant::now();
        let busy = InFlight::new(&self.counters);
        let result = self.transport.transact(unit, req, deadline).await;
        drop(busy);
        let elapsed = started.elapsed();
        let lc = self.transport.counters();
        self.counters
            .late_replies
            .store(lc.late_replies, Ordering::Relaxed);
        self.counters
            .garbage_bytes
            .store(lc.garbage_bytes, Ordering::Relaxed);
        let dev = &mut self.devices[d];
        bump(&dev.counters.requests);
        match &result {
            Ok(answer) => {
                self.silent_timeouts = 0;
                dev.response_ms = elapsed.as_secs_f64() * 1000.0;
                dev.counters
                    .response_us
                    .store(elapsed.as_micros() as u64, Ordering::Relaxed);
                dev.counters.round_trips.observe(elapsed);
                if let Err(code) = answer {
                    bump(&dev.counters.errors);
                    bump(&dev.counters.exceptions);
                    dev.last_error = frame::exception_text(*code);
                }
                self.answered(d);
            }
            Err(e) => {
                bump(&dev.counters.errors);
                if *e == LinkError::Timeout {
                    bump(&dev.counters.timeouts);
                    self.silent_timeouts += 1;
                }
                dev.last_error = e.to_string();
                if !self.transport.is_connected() {
                    bump_link_down(&self.counters);
                    let reason = e.to_string();
                    self.link_down(&reason);
                } else if self.silent_timeouts >= (self.devices.len() as u32).max(3)
                    && self.devices.iter().all(|d| !d.answering || d.failures > 0)
                {
                    // Nobody on the link answers: the connection may be
                    // half-open. Start it afresh.
                    self.transport.disconnect();
                    bump_link_down(&self.counters);
                    self.link_down("no device on the connection answers");
                }
            }
        }
        result
    }

    /// Device `d` answered (data or exception): it is alive.
    fn answered(&mut self, d: usize) {
        let dev = &mut self.devices[d];
        dev.failures = 0;
        dev.answering = true;
        dev.counters.connected.store(true, Ordering::Relaxed);
        if dev.failing {
            dev.failing = false;
            tracing::info!(device = %dev.name, "device answers again");
            let now = self.clock.now();
            for c in &mut dev.classes {
                c.next_due = now;
            }
        }
        dev.probe_wait = Duration::ZERO;
    }

    /// A request to device `d` got no answer. Returns whether the device is
    /// now failing (and its tags were marked Bad).
    fn no_answer(&mut self, d: usize) -> bool {
        let now = self.clock.now();
        let dev = &mut self.devices[d];
        dev.failures += 1;
        // The scan has already retried the read `retries` times.
        if dev.failing {
            return true;
        }
        dev.failing = true;
        dev.answering = false;
        dev.counters.connected.store(false, Ordering::Relaxed);
        let fastest = dev
            .classes
            .iter()
            .map(|c| c.period)
            .min()
            .unwrap_or(Duration::from_secs(1));
        dev.probe_wait = (fastest * 2)
            .max(Duration::from_millis(500))
            .min(dev.probe_cap);
        dev.next_probe = now.add(dev.probe_wait);
        tracing::warn!(device = %dev.name, error = %dev.last_error, "device not answering; backing off");
        let q = Quality::bad(format!("device not answering: {}", dev.last_error));
        let mut ids = Vec::new();
        for c in &mut dev.classes {
            c.stale = true;
            ids.extend(c.tags.iter().map(|&t| self.tags[t].id));
        }
        let mut batch = bad_samples(&self.db, &ids, &q, now);
        batch.extend(status_samples(&self.devices[d], now));
        self.db.apply(batch);
        true
    }

    /// Reads one scan class of a healthy device.
    async fn scan(&mut self, d: usize, c: usize) {
        let now = self.clock.now();
        let (due, period) = {
            let class = &self.devices[d].classes[c];
            (class.next_due, class.period)
        };
        let counters = Arc::clone(&self.devices[d].counters);
        bump(&counters.scans);
        if now.since(due).as_secs_f64() > period.as_secs_f64() * LATE_SHARE {
            bump(&counters.late_scans);
        }
        let mut batch: Vec<(TagId, Sample)> = Vec::new();
        // The observation ticket of each sample in `batch`, taken when its
        // block's answer arrived: a write confirmed between two blocks of
        // this scan is newer, and the scan's older reading of it is dropped
        // when the batch is applied (TagDb::apply_observed).
        let mut tickets: Vec<u64> = Vec::new();
        // The link tag index of each sample in `batch`.
        let mut read: Vec<usize> = Vec::new();
        let mut answered = false;
        let mut lost = false;
        let nblocks = self.devices[d].classes[c].blocks.len();
        for b in 0..nblocks {
            // Writes go before the reads still queued in this scan.
            self.serve_writes().await;
            if !self.transport.is_connected() || self.devices[d].failing {
                lost = true;
                break;
            }
            let block = self.devices[d].classes[c].blocks[b].clone();
            let req = frame::read_request(block.table, block.start, block.count);
            // A read without an answer is repeated at once, up to the
            // device's `retries`, before the device counts as failing.
            let mut retried = 0;
            let answer = loop {
                match self.request(d, &req).await {
                    Ok(answer) => break Some(answer),
                    Err(_)
                        if self.transport.is_connected() && retried < self.devices[d].retries =>
                    {
                        retried += 1;
                        bump(&counters.retries);
                    }
                    Err(_) => break None,
                }
            };
            match answer {
                Some(answer) => {
                    answered = true;
                    let ts = self.clock.now();
                    let ticket = self.db.ticket();
                    self.block_samples(&block, answer, ts, &mut batch);
                    tickets.resize(batch.len(), ticket);
                    if self.has_clocks {
                        read.extend_from_slice(&block.tags);
                    }
                }
                None => {
                    if self.transport.is_connected() {
                        self.no_answer(d);
                    }
                    lost = true;
                    // The rest of the scan would most likely time out too.
                    break;
                }
            }
        }
        self.stamp_device_time(&read, &mut batch);
        let now = self.clock.now();
        let dev = &mut self.devices[d];
        let class = &mut dev.classes[c];
        if answered && !lost {
            class.last_answer = now;
            class.stale = false;
        }
        // Next due: keep the phase; periods that already passed are overruns.
        let mut next = due.add(period);
        if next <= now {
            let missed = now.since(next).as_millis() / period.as_millis().max(1) + 1;
            counters
                .overruns
                .fetch_add(missed as u64, Ordering::Relaxed);
            next = next.add(period * missed as u32);
        }
        class.next_due = next;
        let status_ticket = self.db.ticket();
        let status = status_samples(&self.devices[d], now)
            .into_iter()
            .map(|(id, s)| (id, s, status_ticket));
        self.db.apply_observed(
            batch
                .into_iter()
                .zip(tickets)
                .map(|((id, s), t)| (id, s, t))
                .chain(status),
        );
    }

    /// Gives the samples of tags stamped by a device clock the time that
    /// clock read in this scan. Without a usable clock reading the receive
    /// time stays, and a Good value turns Uncertain to say so.
    fn stamp_device_time(&self, read: &[usize], batch: &mut [(TagId, Sample)]) {
        if !self.has_clocks {
            return;
        }
        let clock_time = |clock: usize, batch: &[(TagId, Sample)]| {
            read.iter()
                .position(|&t| t == clock)
                .and_then(|p| decode::device_time(&batch[p].1))
        };
        for (p, &t) in read.iter().enumerate() {
            let Some(clock) = self.tags[t].time_from else {
                continue;
            };
            let time = clock_time(clock, batch);
            let sample = &mut batch[p].1;
            match time {
                Some(ts) => sample.timestamp = ts,
                None if sample.quality.is_good() => {
                    sample.quality = Quality::uncertain(format!(
                        "device clock {} not read: receive time",
                        self.tags[clock].name
                    ));
                }
                None => {}
            }
        }
    }

    /// Decodes one block's answer into samples (exceptions make its tags Bad).
    fn block_samples(
        &self,
        block: &Block,
        answer: Answer,
        ts: Timestamp,
        out: &mut Vec<(TagId, Sample)>,
    ) {
        let bad = |out: &mut Vec<(TagId, Sample)>, reason: &str| {
            let q = Quality::bad(reason);
            for &t in &block.tags {
                let id = self.tags[t].id;
                let value = self
                    .db
                    .get(id)
                    .map(|s| s.value)
                    .unwrap_or(Value::Bool(false));
                out.push((
                    id,
                    Sample {
                        value,
                        quality: q.clone(),
                        timestamp: ts,
                    },
                ));
            }
        };
        let resp = match answer {
            Ok(r) => r,
            Err(code) => return bad(out, &frame::exception_text(code)),
        };
        match resp {
            Response::ReadCoils(bits) | Response::ReadDiscreteInputs(bits) => {
                for &t in &block.tags {
                    let tag = &self.tags[t];
                    let i = usize::from(tag.address - block.start);
                    let sample = match bits.get(i) {
                        Some(b) => Sample::good(decode::decode_bit(*b), ts),
                        None => Sample {
                            value: Value::Bool(false),
                            quality: Quality::bad("reply too short"),
                            timestamp: ts,
                        },
                    };
                    out.push((tag.id, sample));
                }
            }
            Response::ReadHoldingRegisters(words) | Response::ReadInputRegisters(words) => {
                for &t in &block.tags {
                    let tag = &self.tags[t];
                    let i = usize::from(tag.address - block.start);
                    let n = if tag.codec.bit.is_some() {
                        1
                    } else {
                        usize::from(tag.codec.width)
                    };
                    out.push((tag.id, decode_sample(tag, words.get(i..i + n), ts)));
                }
            }
            _ => bad(out, "reply of the wrong kind"),
        }
    }

    /// Probes a failing device with its first block.
    async fn probe(&mut self, d: usize) {
        let Some(block) = self.devices[d]
            .classes
            .first()
            .and_then(|c| c.blocks.first())
            .cloned()
        else {
            return;
        };
        let req = frame::read_request(block.table, block.start, block.count);
        let result = self.request(d, &req).await;
        let now = self.clock.now();
        let dev = &mut self.devices[d];
        if result.is_err() && dev.failing {
            dev.probe_wait = (dev.probe_wait * 2).min(dev.probe_cap);
            dev.next_probe = now.add(dev.probe_wait);
        }
        let status = status_samples(&self.devices[d], now);
        self.db.apply(status);
    }

    /// Writes a tag, reads it back, and answers the caller.
    async fn write(&mut self, cmd: WriteCmd) {
        let result = self.write_inner(&cmd).await;
        let _ = cmd.reply.send(result);
    }

    async fn write_inner(&mut self, cmd: &WriteCmd) -> Result<Sample, WriteError> {
        let t = cmd.tag;
        let (name, d, address, table, width) = {
            let tag = &self.tags[t];
            (
                tag.name.to_string(),
                tag.device,
                tag.address,
                tag.codec.table,
                tag.codec.width,
            )
        };
        let device = self.devices[d].name.clone();
        bump(&self.devices[d].counters.writes);
        if !self.transport.is_connected() {
            return Err(WriteError::Device {
                device,
                reason: format!("not connected to {}", self.name),
            });
        }
        let fail = |e: LinkError| match e {
            LinkError::Timeout => WriteError::Timeout(name.clone()),
            other => WriteError::Device {
                device: device.clone(),
                reason: other.to_string(),
            },
        };
        let exception = |code| WriteError::Device {
            device: device.clone(),
            reason: frame::exception_text(code),
        };
        let req: Request<'static> = match &cmd.encoded {
            Encoded::Coil(on) => Request::WriteSingleCoil(address, *on),
            Encoded::Registers(w) if w.len() == 1 => Request::WriteSingleRegister(address, w[0]),
            Encoded::Registers(w) => {
                let max = self.devices[d].max_write_registers;
                if w.len() > usize::from(max) {
                    return Err(WriteError::BadValue {
                        tag: name.clone(),
                        value: cmd.value.to_string(),
                        reason: format!(
                            "{} registers exceed device '{device}''s write limit of {max}",
                            w.len()
                        ),
                    });
                }
                Request::WriteMultipleRegisters(address, Cow::Owned(w.clone()))
            }
            Encoded::Bit { bit, value } => {
                // Read-modify-write of the register holding the bit.
                let read = Request::ReadHoldingRegisters(address, 1);
                let current = match self.request(d, &read).await.map_err(&fail)? {
                    Ok(Response::ReadHoldingRegisters(w)) if w.len() == 1 => w[0],
                    Ok(_) => {
                        return Err(WriteError::Device {
                            device,
                            reason: "reply of the wrong kind".into(),
                        })
                    }
                    Err(code) => return Err(exception(code)),
                };
                let codec = &self.tags[t].codec;
                let mask = swap_if(codec, 1u16 << bit);
                let next = if *value {
                    current | mask
                } else {
                    current & !mask
                };
                Request::WriteSingleRegister(address, next)
            }
        };
        // The fence: the epoch is taken as the frame goes out, so a server
        // whose lease ran out (by its own monotonic clock) sends nothing.
        // In a redundant pair each write is logged with server and epoch,
        // the record that the pair's tests check (alone, it is debug detail).
        let epoch = self.leadership.permit().map_err(WriteError::NotActive)?;
        if self.leadership.is_pair() {
            tracing::info!(
                target: "gridscada::field_write",
                server = self.leadership.server(),
                epoch,
                tag = %name,
                value = %cmd.value,
                "field write"
            );
        } else {
            tracing::debug!(target: "gridscada::field_write", tag = %name, value = %cmd.value, "field write");
        }
        match self.request(d, &req).await {
            Ok(Ok(_)) => {}
            Ok(Err(code)) => return Err(exception(code)),
            Err(e) => {
                let err = fail(e);
                self.db
                    .apply(status_samples(&self.devices[d], self.clock.now()));
                return Err(err);
            }
        }
        // Read back: the value shows Good only from this read.
        let back = frame::read_request(table, address, width);
        let answer = match self.request(d, &back).await {
            Ok(a) => a,
            Err(e) => {
                let err = fail(e);
                self.db
                    .apply(status_samples(&self.devices[d], self.clock.now()));
                return Err(err);
            }
        };
        let ts = self.clock.now();
        let tag = &self.tags[t];
        let (sample, confirmed) = match answer {
            Err(code) => return Err(exception(code)),
            Ok(Response::ReadCoils(bits)) => {
                let got = bits.first().copied().unwrap_or(false);
                (
                    Sample::good(got, ts),
                    matches!(cmd.encoded, Encoded::Coil(on) if on == got),
                )
            }
            Ok(Response::ReadHoldingRegisters(words)) => {
                let n = if tag.codec.bit.is_some() {
                    1
                } else {
                    usize::from(width)
                };
                let sample = decode_sample(tag, words.get(..n), ts);
                let confirmed = match &cmd.encoded {
                    Encoded::Registers(w) => words.get(..n) == Some(&w[..]),
                    Encoded::Bit { value, .. } => sample.value == Value::Bool(*value),
                    Encoded::Coil(_) => false,
                };
                (sample, confirmed)
            }
            Ok(_) => {
                return Err(WriteError::Device {
                    device,
                    reason: "read-back reply of the wrong kind".into(),
                })
            }
        };
        let mut batch = vec![(tag.id, sample.clone())];
        batch.extend(status_samples(&self.devices[d], ts));
        self.db.apply(batch);
        if confirmed {
            Ok(sample)
        } else {
            Err(WriteError::Mismatch {
                tag: name,
                written: cmd.value.to_string(),
                read_back: sample.value.to_string(),
            })
        }
    }
}

/// `ids` marked with `quality`, keeping their last values.
fn bad_samples(
    db: &TagDb,
    ids: &[TagId],
    quality: &Quality,
    ts: Timestamp,
) -> Vec<(TagId, Sample)> {
    ids.iter()
        .filter_map(|id| {
            db.get(*id).map(|s| {
                (
                    *id,
                    Sample {
                        value: s.value,
                        quality: quality.clone(),
                        timestamp: ts,
                    },
                )
            })
        })
        .collect()
}

/// Counts one transport operation in flight; released on drop, so a
/// cancelled request (shutdown) does not leave the gauge raised.
struct InFlight(Arc<LinkCounters>);

impl InFlight {
    fn new(c: &Arc<LinkCounters>) -> Self {
        c.in_flight.fetch_add(1, Ordering::SeqCst);
        InFlight(Arc::clone(c))
    }
}

impl Drop for InFlight {
    fn drop(&mut self) {
        self.0.in_flight.fetch_sub(1, Ordering::SeqCst);
    }
}

fn bump_link_down(c: &LinkCounters) {
    c.disconnects.fetch_add(1, Ordering::Relaxed);
}

/// The mask of a bit as it sits in the register on the wire.
fn swap_if(codec: &Codec, mask: u16) -> u16 {
    match codec.byte_order {
        gridscada_config::Endian::Big => mask,
        gridscada_config::Endian::Little => mask.swap_bytes(),
    }
}

fn decode_sample(tag: &LinkTag, words: Option<&[u16]>, ts: Timestamp) -> Sample {
    let decoded = words
        .ok_or_else(|| "reply too short".to_string())
        .and_then(|w| decode::decode_registers(&tag.codec, w));
    match decoded {
        Ok(value) => Sample {
            quality: decode::quality_of(&value),
            value,
            timestamp: ts,
        },
        Err(e) => Sample {
            value: Value::Float(f64::NAN),
            quality: Quality::bad(format!("cannot decode: {e}")),
            timestamp: ts,
        },
    }
}

/// See [`Link::stale_after`].
fn stale_after(period: Duration, longest_hold: Duration) -> Duration {
    period * 2 + longest_hold
}

/// The device's communication status tags, always Good: they are the
/// poller's own knowledge.
fn status_samples(dev: &DeviceRt, ts: Timestamp) -> Vec<(TagId, Sample)> {
    let c = &dev.counters;
    let n = |a: &AtomicU64| Value::Int(a.load(Ordering::Relaxed) as i64);
    let s = &dev.status;
    vec![
        (s.connected, Sample::good(dev.answering, ts)),
        (
            s.last_error,
            Sample::good(Value::Str(dev.last_error.as_str().into()), ts),
        ),
        (s.response_ms, Sample::good(dev.response_ms, ts)),
        (s.requests, Sample::good(n(&c.requests), ts)),
        (s.errors, Sample::good(n(&c.errors), ts)),
        (s.timeouts, Sample::good(n(&c.timeouts), ts)),
        (s.overruns, Sample::good(n(&c.overruns), ts)),
        (s.retries, Sample::good(n(&c.retries), ts)),
    ]
}
