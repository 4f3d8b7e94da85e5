//! One outstation's task: the TCP connection or serial line (re-opened
//! with back-off), the bytes both ways through [`Master`], its actions
//! carried out (send, timers, measurements into the tag database, commands'
//! outcomes, IIN reports), and the status tags.
//!
//! The task owns the write half and the master; the read half is read in
//! the same `select!`, so every state change happens here, in order.

use std::collections::HashMap;
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::{Duration, Instant};

use gridscada_config::SerialConfig;
use gridscada_field::{Notices, StatusIds};
use gridscada_tagdb::{Clock, Leadership, Quality as TagQuality, Sample, TagDb, TagId, WriteError};
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};
use tokio::net::TcpStream;
use tokio::sync::{mpsc, oneshot, watch};

use super::points::PointMap;
use super::{CommandRequest, Counters};
use crate::master::{self, Action, Command, Master, MasterConfig, Report};

/// Where the outstation is reached.
pub(crate) enum Line {
    /// `host:port`.
    Tcp(String),
    /// A serial port, one outstation on it.
    Serial(SerialConfig),
}

impl Line {
    /// The address or port, for logs and the devices screen.
    pub fn label(&self) -> String {
        match self {
            Line::Tcp(a) => a.clone(),
            Line::Serial(c) => c.port.get_ref().clone(),
        }
    }
}

type Reader = Box<dyn AsyncRead + Unpin + Send>;
type Writer = Box<dyn AsyncWrite + Unpin + Send>;

/// Everything the task needs from the configuration.
pub(crate) struct Settings {
    pub name: String,
    pub line: Line,
    pub master: MasterConfig,
    pub connect_timeout: Duration,
    pub backoff_max: Duration,
}

/// A command waiting for its outcome.
struct Pending {
    tag: Arc<str>,
    reply: oneshot::Sender<Result<(), WriteError>>,
}

pub(crate) struct Outstation {
    s: Settings,
    master: Master,
    points: PointMap,
    status: StatusIds,
    counters: Arc<Counters>,
    db: Arc<TagDb>,
    clock: Arc<dyn Clock>,
    leadership: Leadership,
    commands: mpsc::Receiver<CommandRequest>,
    notices: Notices,
    pending: HashMap<u64, Pending>,
    next_id: u64,
    backoff: Duration,
    /// When the last request went out with no octets back since.
    sent_at: Option<Instant>,
}

/// Why a connection ended.
enum End {
    Shutdown,
    Lost(String),
}

impl Outstation {
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        s: Settings,
        points: PointMap,
        status: StatusIds,
        counters: Arc<Counters>,
        db: Arc<TagDb>,
        clock: Arc<dyn Clock>,
        leadership: Leadership,
        commands: mpsc::Receiver<CommandRequest>,
        notices: Notices,
    ) -> Outstation {
        let master = Master::new(s.master.clone());
        Outstation {
            s,
            master,
            points,
            status,
            counters,
            db,
            clock,
            leadership,
            commands,
            notices,
            pending: HashMap::new(),
            next_id: 0,
            backoff: Duration::from_millis(250),
            sent_at: None,
        }
    }

    fn now(&self) -> master::Clock {
        master::Clock {
            mono: Instant::now(),
            unix_ms: u64::try_from(self.clock.now().as_millis()).unwrap_or(0),
        }
    }

    pub async fn run(mut self, mut shutdown: watch::Receiver<bool>) {
        self.publish_status();
        loop {
            if *shutdown.borrow() {
                break;
            }
            let opened = tokio::select! {
                _ = shutdown.changed() => break,
                r = self.open() => r,
            };
            match opened {
                Ok((read, write)) => {
                    self.backoff = Duration::from_millis(250);
                    // The reason of the last failure no longer holds.
                    self.counters.last_error.lock().clear();
                    self.counters.connects.fetch_add(1, Ordering::Relaxed);
                    tracing::info!(outstation = %self.s.name, line = %self.s.line.label(), "DNP3 line open");
                    match self.session(read, write, &mut shutdown).await {
                        End::Shutdown => break,
                        End::Lost(reason) => self.lost(&reason),
                    }
                }
                Err(reason) => {
                    self.set_error(&reason);
                    self.publish_status();
                }
            }
            // Back off; commands meanwhile are refused at once.
            let until = tokio::time::Instant::now() + self.backoff;
            self.backoff = (self.backoff * 2).min(self.s.backoff_max);
            loop {
                tokio::select! {
                    _ = shutdown.changed() => return self.stop(),
                    Some(c) = self.commands.recv() => self.refuse(c),
                    _ = tokio::time::sleep_until(until) => break,
                }
            }
        }
        self.stop();
    }

    /// Connects to the outstation's address, or opens its serial port.
    async fn open(&self) -> Result<(Reader, Writer), String> {
        match &self.s.line {
            Line::Tcp(address) => {
                match tokio::time::timeout(self.s.connect_timeout, TcpStream::connect(address))
                    .await
                {
                    Err(_) => Err(format!(
                        "no connection to {address} within {:?}",
                        self.s.connect_timeout
                    )),
                    Ok(Err(e)) => Err(format!("cannot connect to {address}: {e}")),
                    Ok(Ok(stream)) => {
                        let _ = stream.set_nodelay(true);
                        let (read, write) = stream.into_split();
                        Ok((Box::new(read) as Reader, Box::new(write) as Writer))
                    }
                }
            }
            Line::Serial(config) => {
                let port = gridscada_field::open_serial(config)?;
                let (read, write) = tokio::io::split(port);
                Ok((Box::new(read) as Reader, Box::new(write) as Writer))
            }
        }
    }

    fn stop(&mut self) {
        for (_, p) in self.pending.drain() {
            let _ = p.reply.send(Err(WriteError::Closed));
        }
    }

    fn refuse(&self, c: CommandRequest) {
        let last = self.counters.last_error.lock().clone();
        let _ = c.reply.send(Err(WriteError::Device {
            device: self.s.name.clone(),
            reason: format!("not connected to the outstation ({last}); nothing was sent"),
        }));
    }

    /// One connection, until it ends.
    async fn session(
        &mut self,
        mut read: Reader,
        mut write: Writer,
        shutdown: &mut watch::Receiver<bool>,
    ) -> End {
        let now = self.now();
        let actions = self.master.connected(now);
        if let Err(e) = self.carry_out(actions, &mut write).await {
            return End::Lost(e);
        }
        let mut buf = vec![0u8; 4096];
        let mut next_status = Instant::now() + Duration::from_secs(1);
        loop {
            let wake = self
                .master
                .next_deadline()
                .unwrap_or_else(|| Instant::now() + Duration::from_secs(3600))
                .min(next_status);
            let wake = tokio::time::Instant::from_std(wake);
            let actions = tokio::select! {
                _ = shutdown.changed() => return End::Shutdown,
                r = read.read(&mut buf) => match r {
                    Ok(0) => return End::Lost(match self.s.line {
                        Line::Tcp(_) => "the outstation closed the connection".into(),
                        Line::Serial(_) => "the serial port closed".into(),
                    }),
                    Err(e) => return End::Lost(format!("read failed: {e}")),
                    Ok(n) => {
                        let now = self.now();
                        let heard = self.master.frames_heard();
                        let actions = self.master.received(&buf[..n], now);
                        self.counters
                            .malformed
                            .store(self.master.discarded_octets(), Ordering::Relaxed);
                        // A well-formed frame from the outstation: it answers,
                        // connected (again, after a response timeout).
                        // Garbage on the connection is not an answer.
                        if self.master.frames_heard() > heard {
                            if let Some(at) = self.sent_at.take() {
                                self.observe_round_trip(at.elapsed());
                            }
                            if !self.counters.connected.swap(true, Ordering::Relaxed) {
                                self.publish_status();
                            }
                        }
                        actions
                    }
                },
                Some(c) = self.commands.recv() => self.begin_command(c),
                _ = tokio::time::sleep_until(wake) => {
                    let now = self.now();
                    self.master.tick(now)
                }
            };
            if let Err(e) = self.carry_out(actions, &mut write).await {
                return End::Lost(e);
            }
            if Instant::now() >= next_status {
                next_status = Instant::now() + Duration::from_secs(1);
                self.publish_status();
            }
        }
    }

    fn begin_command(&mut self, c: CommandRequest) -> Vec<Action> {
        if let Err(e) = self.leadership.permit() {
            let _ = c.reply.send(Err(WriteError::NotActive(e)));
            return Vec::new();
        }
        self.next_id += 1;
        let id = self.next_id;
        tracing::info!(outstation = %self.s.name, tag = %c.tag, index = c.index, object = ?c.object, mode = ?c.mode, "DNP3 command");
        self.counters.commands.fetch_add(1, Ordering::Relaxed);
        self.pending.insert(
            id,
            Pending {
                tag: c.tag,
                reply: c.reply,
            },
        );
        let now = self.now();
        self.master.command(
            Command {
                id,
                index: c.index,
                object: c.object,
                mode: c.mode,
            },
            now,
        )
    }

    /// Carries out the master's actions; `Err` when the connection failed.
    async fn carry_out(&mut self, actions: Vec<Action>, write: &mut Writer) -> Result<(), String> {
        for a in actions {
            match a {
                Action::Send(bytes) => {
                    self.counters.requests.fetch_add(1, Ordering::Relaxed);
                    self.sent_at.get_or_insert_with(Instant::now);
                    match tokio::time::timeout(
                        self.s.master.response_timeout,
                        write.write_all(&bytes),
                    )
                    .await
                    {
                        Ok(Ok(())) => {}
                        Ok(Err(e)) => return Err(format!("write failed: {e}")),
                        Err(_) => {
                            return Err(
                                "the outstation did not take our frame within the response timeout"
                                    .into(),
                            )
                        }
                    }
                }
                Action::Measurements(ms) => self.deliver(&ms),
                Action::CommandOutcome { id, result } => {
                    let Some(p) = self.pending.remove(&id) else {
                        continue;
                    };
                    let reply = match result {
                        Ok(()) => Ok(()),
                        Err(e) => {
                            self.counters
                                .commands_failed
                                .fetch_add(1, Ordering::Relaxed);
                            let reason = e.to_string();
                            tracing::warn!(outstation = %self.s.name, tag = %p.tag, %reason, "DNP3 command failed");
                            Err(WriteError::Device {
                                device: self.s.name.clone(),
                                reason,
                            })
                        }
                    };
                    let _ = p.reply.send(reply);
                }
                Action::IinChanged { before, now } => {
                    tracing::debug!(outstation = %self.s.name, %before, %now, "DNP3 IIN changed");
                }
                Action::Report(r) => self.report(r),
                // The loop asks the master for its next deadline.
                Action::Timer(_) => {}
                Action::Disconnect(reason) => return Err(reason),
            }
        }
        Ok(())
    }

    fn report(&mut self, r: Report) {
        match &r {
            Report::ResponseTimeout { task, .. } => {
                self.counters.timeouts.fetch_add(1, Ordering::Relaxed);
                self.counters.connected.store(false, Ordering::Relaxed);
                self.sent_at = None;
                if *task == "integrity poll" {
                    let q = TagQuality::bad(format!(
                        "no response from outstation {}: {r}",
                        self.s.name
                    ));
                    self.db
                        .set_quality(&self.points.ids(), &q, self.clock.now());
                }
                self.set_error(&r.to_string());
            }
            Report::EventBufferOverflow => {
                self.counters.overflows.fetch_add(1, Ordering::Relaxed);
                tracing::warn!(outstation = %self.s.name, "{r}");
                self.notices.send(&self.s.name, r.to_string());
            }
            // Counted in octets where they are read (`discarded_octets`).
            Report::Malformed(_) => self.set_error(&r.to_string()),
            Report::Refused { .. } => self.set_error(&r.to_string()),
            Report::IntegrityPollDone => {
                self.counters
                    .integrity_polls
                    .fetch_add(1, Ordering::Relaxed);
                self.counters
                    .last_integrity_ms
                    .store(self.clock.now().as_millis(), Ordering::Relaxed);
            }
            // In the event log: a restart means the outstation's state
            // (latched outputs, counters, its event buffer) may have been
            // lost; a clock set is part of the time stamps' record.
            Report::DeviceRestart => {
                tracing::info!(outstation = %self.s.name, "{r}");
                self.notices.send(&self.s.name, r.to_string());
            }
            Report::TimeSynced { .. } => {
                tracing::info!(outstation = %self.s.name, "{r}");
                self.notices.send(
                    &self.s.name,
                    "the outstation asked for the time (IIN1.4 NEED_TIME); its clock was set (LAN procedure)".into(),
                );
            }
            Report::Ignored(_) | Report::Note(_) => {
                tracing::debug!(outstation = %self.s.name, "{r}")
            }
        }
    }

    /// Measurements into the tag database, in one batch split where a tag
    /// repeats, so every event of a burst reaches the subscribers.
    fn deliver(&mut self, ms: &[crate::objects::Measurement]) {
        let received = self.clock.now();
        let events = ms.iter().filter(|m| m.is_event).count() as u64;
        self.counters.events.fetch_add(events, Ordering::Relaxed);
        let mut batch: Vec<(TagId, Sample)> = Vec::new();
        for m in ms {
            let db = &self.db;
            let in_batch = |id: TagId| {
                batch
                    .iter()
                    .rev()
                    .find(|(b, _)| *b == id)
                    .map(|(_, s)| s.value.clone())
            };
            let Some((id, sample)) = self.points.sample(m, received, |id| {
                in_batch(id).or_else(|| db.get(id).map(|s| s.value))
            }) else {
                continue;
            };
            if batch.iter().any(|(b, _)| *b == id) {
                self.db.apply(std::mem::take(&mut batch));
            }
            batch.push((id, sample));
        }
        if !batch.is_empty() {
            self.db.apply(batch);
        }
    }

    /// The connection is gone: its points turn bad, commands under way fail.
    fn lost(&mut self, reason: &str) {
        let reason = format!("{}: {reason}", self.s.line.label());
        tracing::warn!(outstation = %self.s.name, %reason, "DNP3 connection closed");
        self.counters.disconnects.fetch_add(1, Ordering::Relaxed);
        self.counters.connected.store(false, Ordering::Relaxed);
        self.sent_at = None;
        self.set_error(&reason);
        let actions = self.master.disconnected();
        for a in actions {
            if let Action::CommandOutcome { id, result } = a {
                if let Some(p) = self.pending.remove(&id) {
                    self.counters
                        .commands_failed
                        .fetch_add(1, Ordering::Relaxed);
                    let _ = p.reply.send(Err(WriteError::Device {
                        device: self.s.name.clone(),
                        reason: match result {
                            Ok(()) => "completed".into(),
                            Err(e) => format!("{e} ({reason})"),
                        },
                    }));
                }
            }
        }
        let q = TagQuality::bad(format!("communication lost: {reason}"));
        self.db
            .set_quality(&self.points.ids(), &q, self.clock.now());
        self.publish_status();
    }

    fn set_error(&mut self, reason: &str) {
        self.counters.errors.fetch_add(1, Ordering::Relaxed);
        *self.counters.last_error.lock() = reason.to_string();
        self.db.set(
            self.status.last_error,
            gridscada_tagdb::Value::Str(reason.into()),
            TagQuality::GOOD,
            self.clock.now(),
        );
    }

    fn observe_round_trip(&self, d: Duration) {
        self.counters.round_trips.observe(d);
        self.counters.response_us.store(
            u64::try_from(d.as_micros()).unwrap_or(u64::MAX),
            Ordering::Relaxed,
        );
    }

    /// The status tags from the counters.
    fn publish_status(&mut self) {
        let c = &self.counters;
        let get = |a: &std::sync::atomic::AtomicU64| a.load(Ordering::Relaxed);
        self.status.publish(
            &self.db,
            self.clock.now(),
            gridscada_field::StatusFigures {
                connected: c.connected.load(Ordering::Relaxed),
                response_ms: get(&c.response_us) as f64 / 1000.0,
                requests: get(&c.requests),
                errors: get(&c.errors),
                timeouts: get(&c.timeouts),
            },
        );
    }
}
