//! One controlled station's task: a connection to each address of its
//! redundancy group (one started, the others kept tested with TESTFR), the
//! started connection's data (interrogations, spontaneous data, clock
//! synchronisation), one command at a time, and the status tags.
//!
//! The task owns every write half; a small reader task per connection only
//! cuts the byte stream into frames and hands them over, so all state
//! changes happen here, in one place, in order.

use std::collections::{HashMap, VecDeque};
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::{Duration, Instant};

use gridscada_field::{Notices, StatusIds};
use gridscada_tagdb::{Clock, Leadership, Quality as TagQuality, Sample, TagDb, TagId, WriteError};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::tcp::OwnedWriteHalf;
use tokio::net::TcpStream;
use tokio::sync::{mpsc, watch};
use tokio::task::JoinHandle;

use super::command::{with_select, Phase, Procedure, Step};
use super::points::{Outcome, PointMap};
use super::{CommandRequest, Counters};
use crate::session::{Parameters, Session};
use crate::{
    apci, Asdu, AsduError, Cause, Cp56Time2a, Element, Frame, InformationObject, TypeId, UFunction,
};

/// Everything the task needs from the configuration.
pub(crate) struct StationSettings {
    pub name: String,
    pub addresses: Vec<String>,
    pub common_address: u16,
    pub session: Parameters,
    pub t0: Duration,
    pub interrogation_period: Option<Duration>,
    pub counter_period: Option<Duration>,
    pub clock_sync_period: Option<Duration>,
    pub command_timeout: Duration,
    pub termination: bool,
    pub backoff_max: Duration,
}

/// What the readers and connectors tell the task.
enum Event {
    Connected(usize, u64, Result<(OwnedWriteHalf, JoinHandle<()>), String>),
    Frame(usize, u64, Frame),
    Closed(usize, u64, String),
}

struct Conn {
    generation: u64,
    write: OwnedWriteHalf,
    session: Session,
    reader: JoinHandle<()>,
}

struct Slot {
    address: String,
    conn: Option<Conn>,
    connecting: bool,
    next_attempt: Instant,
    backoff: Duration,
}

/// The command in progress, with its request.
struct Active {
    procedure: Procedure,
    request: CommandRequest,
    execute: Element,
}

pub(crate) struct Station {
    s: StationSettings,
    points: PointMap,
    status: StatusIds,
    counters: Arc<Counters>,
    db: Arc<TagDb>,
    clock: Arc<dyn Clock>,
    leadership: Leadership,
    commands: mpsc::Receiver<CommandRequest>,
    /// Notices for the event log (end of initialisation).
    notices: Notices,
    slots: Vec<Slot>,
    /// The started connection's slot, once STARTDT is confirmed.
    started: Option<usize>,
    /// A slot whose STARTDT act awaits its confirmation.
    starting: Option<usize>,
    /// ASDUs waiting for room in the k window of the started connection.
    outbox: VecDeque<Vec<u8>>,
    next_interrogation: Option<Instant>,
    next_counter: Option<Instant>,
    next_clock_sync: Option<Instant>,
    interrogation_sent: Option<Instant>,
    test_sent: HashMap<usize, Instant>,
    active: Option<Active>,
    events_tx: mpsc::Sender<Event>,
    events_rx: mpsc::Receiver<Event>,
    generation: u64,
    next_status: Instant,
}

impl Station {
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        s: StationSettings,
        points: PointMap,
        status: StatusIds,
        counters: Arc<Counters>,
        db: Arc<TagDb>,
        clock: Arc<dyn Clock>,
        leadership: Leadership,
        commands: mpsc::Receiver<CommandRequest>,
        notices: Notices,
    ) -> Station {
        let now = Instant::now();
        let slots = s
            .addresses
            .iter()
            .map(|a| Slot {
                address: a.clone(),
                conn: None,
                connecting: false,
                next_attempt: now,
                backoff: Duration::from_millis(250),
            })
            .collect();
        let (events_tx, events_rx) = mpsc::channel(256);
        Station {
            s,
            points,
            status,
            counters,
            db,
            clock,
            leadership,
            commands,
            notices,
            slots,
            started: None,
            starting: None,
            outbox: VecDeque::new(),
            next_interrogation: None,
            next_counter: None,
            next_clock_sync: None,
            interrogation_sent: None,
            test_sent: HashMap::new(),
            active: None,
            events_tx,
            events_rx,
            generation: 0,
            next_status: now,
        }
    }

    pub async fn run(mut self, mut shutdown: watch::Receiver<bool>) {
        self.publish_status();
        loop {
            let now = Instant::now();
            self.connect_due(now);
            self.start_if_needed(now).await;
            if let Err((slot, reason)) = self.tick(now).await {
                self.close(slot, &reason);
                continue;
            }
            let wake = tokio::time::Instant::from_std(self.next_wake(now));
            // One command at a time; without a started connection it is
            // refused at once rather than left waiting.
            let take_command = self.active.is_none();
            tokio::select! {
                _ = shutdown.changed() => break,
                Some(ev) = self.events_rx.recv() => self.on_event(ev).await,
                Some(cmd) = self.commands.recv(), if take_command => self.begin_command(cmd).await,
                _ = tokio::time::sleep_until(wake) => {}
            }
        }
        for i in 0..self.slots.len() {
            if let Some(c) = self.slots[i].conn.take() {
                c.reader.abort();
            }
        }
        if let Some(a) = self.active.take() {
            let _ = a.request.reply.send(Err(WriteError::Closed));
        }
    }

    /// Opens a connection to every address that has none and is due.
    fn connect_due(&mut self, now: Instant) {
        for (i, slot) in self.slots.iter_mut().enumerate() {
            if slot.conn.is_some() || slot.connecting || now < slot.next_attempt {
                continue;
            }
            slot.connecting = true;
            self.generation += 1;
            let generation = self.generation;
            let address = slot.address.clone();
            let events = self.events_tx.clone();
            let t0 = self.s.t0;
            let counters = Arc::clone(&self.counters);
            tokio::spawn(async move {
                let result = match tokio::time::timeout(t0, TcpStream::connect(&address)).await {
                    Err(_) => Err(format!("no connection to {address} within t0")),
                    Ok(Err(e)) => Err(format!("cannot connect to {address}: {e}")),
                    Ok(Ok(stream)) => {
                        let _ = stream.set_nodelay(true);
                        let (read, write) = stream.into_split();
                        let reader = tokio::spawn(read_frames(
                            read,
                            i,
                            generation,
                            events.clone(),
                            counters,
                        ));
                        Ok((write, reader))
                    }
                };
                let _ = events.send(Event::Connected(i, generation, result)).await;
            });
        }
    }

    /// With no started connection, starts data transfer on the first open one.
    async fn start_if_needed(&mut self, now: Instant) {
        if self.started.is_some() || self.starting.is_some() {
            return;
        }
        let Some(i) = self.slots.iter().position(|s| s.conn.is_some()) else {
            return;
        };
        let frame = {
            let conn = self.slots[i].conn.as_mut().expect("checked");
            conn.session.activate(UFunction::StartDtAct, now)
        };
        self.starting = Some(i);
        if let Err(e) = self.send(i, &frame).await {
            self.close(i, &e);
        }
    }

    /// Timers of every connection, the periodic requests, the command's
    /// deadline. An `Err` names a connection to close.
    async fn tick(&mut self, now: Instant) -> Result<(), (usize, String)> {
        for i in 0..self.slots.len() {
            let Some(conn) = self.slots[i].conn.as_mut() else {
                continue;
            };
            match conn.session.tick(now) {
                Ok(frames) => {
                    for f in frames {
                        if matches!(f, Frame::U(UFunction::TestFrAct)) {
                            self.test_sent.insert(i, now);
                        }
                        self.send(i, &f).await.map_err(|e| (i, e))?;
                    }
                }
                Err(e) => {
                    self.counters.timeouts.fetch_add(1, Ordering::Relaxed);
                    return Err((i, e.to_string()));
                }
            }
        }
        if let Some(started) = self.started {
            let ca = self.s.common_address;
            if self.next_interrogation.is_some_and(|t| now >= t) {
                self.next_interrogation = self.s.interrogation_period.map(|p| now + p);
                self.interrogation_sent = Some(now);
                self.queue(system(
                    TypeId::C_IC_NA_1,
                    ca,
                    Element::Interrogation { qoi: 20 },
                ));
            }
            if self.next_counter.is_some_and(|t| now >= t) {
                self.next_counter = self.s.counter_period.map(|p| now + p);
                self.queue(system(
                    TypeId::C_CI_NA_1,
                    ca,
                    Element::CounterInterrogation {
                        request: 5,
                        freeze: 0,
                    },
                ));
            }
            if self.next_clock_sync.is_some_and(|t| now >= t) {
                self.next_clock_sync = self.s.clock_sync_period.map(|p| now + p);
                if let Ok(time) = Cp56Time2a::from_unix_ms(self.clock.now().as_millis()) {
                    self.queue(system(TypeId::C_CS_NA_1, ca, Element::ClockSync { time }));
                }
            }
            self.flush(started, now).await.map_err(|e| (started, e))?;
        }
        if let Some(a) = &self.active {
            if now >= a.procedure.deadline {
                let what = match a.procedure.phase {
                    Phase::Selecting => "ACT_CON to the select",
                    Phase::Executing => "ACT_CON to the execute",
                    Phase::Terminating => "ACT_TERM",
                };
                let reason = format!(
                    "no {what} from the station within {:.0} s",
                    self.s.command_timeout.as_secs_f64()
                );
                self.finish_command(Err(reason));
            }
        }
        if now >= self.next_status {
            self.publish_status();
        }
        Ok(())
    }

    fn next_wake(&self, now: Instant) -> Instant {
        let mut at = now + Duration::from_secs(1);
        at = at.min(self.next_status);
        for s in &self.slots {
            match &s.conn {
                Some(c) => at = at.min(c.session.next_deadline()),
                None if !s.connecting => at = at.min(s.next_attempt),
                None => {}
            }
        }
        if self.started.is_some() {
            for t in [
                self.next_interrogation,
                self.next_counter,
                self.next_clock_sync,
            ]
            .into_iter()
            .flatten()
            {
                at = at.min(t);
            }
        }
        if let Some(a) = &self.active {
            at = at.min(a.procedure.deadline);
        }
        at.max(now)
    }

    async fn on_event(&mut self, ev: Event) {
        match ev {
            Event::Connected(i, generation, result) => {
                let slot = &mut self.slots[i];
                slot.connecting = false;
                match result {
                    Ok((write, reader)) => {
                        slot.conn = Some(Conn {
                            generation,
                            write,
                            session: Session::new(self.s.session, Instant::now()),
                            reader,
                        });
                        slot.backoff = Duration::from_millis(250);
                        self.counters.connects.fetch_add(1, Ordering::Relaxed);
                        if self.started.is_none() {
                            self.counters.state.store(2, Ordering::Relaxed);
                        }
                    }
                    Err(reason) => {
                        self.retry_later(i);
                        self.set_error(&reason);
                    }
                }
            }
            Event::Frame(i, generation, frame) => {
                if self.slots[i].conn.as_ref().map(|c| c.generation) != Some(generation) {
                    return;
                }
                let now = Instant::now();
                let conn = self.slots[i].conn.as_mut().expect("checked");
                let actions = match conn.session.receive(frame, now) {
                    Ok(a) => a,
                    Err(e) => {
                        self.counters.errors.fetch_add(1, Ordering::Relaxed);
                        self.close(i, &e.to_string());
                        return;
                    }
                };
                for f in &actions.send {
                    if let Err(e) = self.send(i, f).await {
                        self.close(i, &e);
                        return;
                    }
                }
                match actions.confirmed {
                    Some(UFunction::StartDtCon) if self.starting == Some(i) => {
                        self.starting = None;
                        self.started = Some(i);
                        self.on_started(now);
                    }
                    Some(UFunction::TestFrCon) => {
                        if let Some(sent) = self.test_sent.remove(&i) {
                            self.observe_round_trip(now.duration_since(sent));
                        }
                    }
                    _ => {}
                }
                for asdu in actions.asdus {
                    if let Err(reason) = self.on_asdu(&asdu) {
                        self.counters.malformed.fetch_add(1, Ordering::Relaxed);
                        self.close(i, &reason);
                        return;
                    }
                }
                if let Some(started) = self.started.filter(|s| *s == i) {
                    if let Err(e) = self.flush(started, now).await {
                        self.close(started, &e);
                    }
                }
            }
            Event::Closed(i, generation, reason) => {
                if self.slots[i].conn.as_ref().map(|c| c.generation) == Some(generation) {
                    self.close(i, &reason);
                }
            }
        }
    }

    /// Data transfer is started: interrogate at once, then on the periods.
    fn on_started(&mut self, now: Instant) {
        self.counters.connected.store(true, Ordering::Relaxed);
        self.counters.state.store(1, Ordering::Relaxed);
        self.outbox.clear();
        self.next_interrogation = Some(now);
        self.next_counter = self.s.counter_period.map(|_| now);
        self.next_clock_sync = self.s.clock_sync_period.map(|_| now);
        self.publish_status();
        tracing::info!(station = %self.s.name, address = %self.slots[self.started.unwrap_or(0)].address, "IEC 104 data transfer started");
    }

    /// One ASDU of the started connection (or a tested one: they send none).
    fn on_asdu(&mut self, bytes: &[u8]) -> Result<(), String> {
        let asdu = match Asdu::decode(bytes) {
            Ok(a) => a,
            // A type we do not take is not a broken frame: counted, skipped.
            Err(AsduError::UnknownTypeId(t)) => {
                self.set_error(&format!(
                    "the station sent type id {t}, which gridscada does not take; skipped"
                ));
                return Ok(());
            }
            Err(e) => return Err(format!("malformed ASDU from the station: {e}")),
        };
        if asdu.common_address() != self.s.common_address {
            self.set_error(&format!(
                "an ASDU for common address {} arrived, not {}; skipped",
                asdu.common_address(),
                self.s.common_address
            ));
            return Ok(());
        }
        let t = asdu.type_id();
        match t {
            TypeId::M_EI_NA_1 => {
                // The station restarted: what we knew may be stale.
                tracing::info!(station = %self.s.name, "end of initialisation: general interrogation");
                self.next_interrogation = Some(Instant::now());
                let why = match asdu.objects().first().map(|o| o.element) {
                    Some(Element::EndOfInit {
                        cause,
                        after_change,
                    }) => init_cause_words(cause, after_change),
                    _ => "cause not given".to_string(),
                };
                self.notices.send(
                    &self.s.name,
                    format!("the station ended its initialisation (M_EI_NA_1: {why}); general interrogation"),
                );
            }
            TypeId::C_IC_NA_1 => match (asdu.cause(), asdu.is_negative()) {
                (Cause::ActTerm, false) => {
                    self.counters.interrogations.fetch_add(1, Ordering::Relaxed);
                    // Wall time: the devices screen shows its age.
                    self.counters.last_interrogation_ms.store(
                        gridscada_tagdb::Timestamp::now_utc().as_millis(),
                        Ordering::Relaxed,
                    );
                    if let Some(sent) = self.interrogation_sent.take() {
                        self.observe_round_trip(sent.elapsed());
                    }
                }
                (_, true) => self.set_error("the station refused the general interrogation"),
                _ => {}
            },
            TypeId::C_CI_NA_1 => {
                if asdu.is_negative() {
                    self.set_error("the station refused the counter interrogation");
                }
            }
            TypeId::C_CS_NA_1 => {
                if asdu.is_negative() {
                    self.set_error("the station refused the clock synchronisation");
                } else if asdu.cause() == Cause::ActCon {
                    if let Some(Element::ClockSync { time }) =
                        asdu.objects().first().map(|o| o.element)
                    {
                        if let Ok(station_ms) = time.to_unix_ms() {
                            let offset = station_ms - self.clock.now().as_millis();
                            self.counters
                                .clock_offset_ms
                                .store(offset, Ordering::Relaxed);
                            self.counters.clock_synced.store(true, Ordering::Relaxed);
                        }
                    }
                }
            }
            t if t.is_command() => {
                let step = match self.active.as_mut() {
                    Some(a) => a.procedure.answer(&asdu),
                    None => Step::Ignore,
                };
                let deadline = Instant::now() + self.s.command_timeout;
                match step {
                    Step::Ignore => {}
                    Step::Execute => {
                        let ca = self.s.common_address;
                        if let Some(a) = self.active.as_mut() {
                            a.procedure.phase = Phase::Executing;
                            a.procedure.deadline = deadline;
                            let asdu =
                                command_asdu(a.procedure.type_id, ca, a.procedure.ioa, a.execute);
                            self.queue(asdu);
                        }
                    }
                    Step::Wait(_) => {
                        if let Some(a) = self.active.as_mut() {
                            a.procedure.deadline = deadline;
                        }
                    }
                    Step::Done => self.finish_command(Ok(())),
                    Step::Refused(reason) => self.finish_command(Err(reason)),
                }
            }
            _ => self.on_monitoring(asdu),
        }
        Ok(())
    }

    /// Monitoring data into the tag database. Objects of one ASDU go in
    /// one batch, split where a tag repeats, so a burst of events on one
    /// breaker (open, close, open) reaches every subscriber one by one.
    fn on_monitoring(&mut self, asdu: Asdu) {
        let received = self.clock.now();
        if matches!(asdu.cause(), Cause::Spont | Cause::RetRem | Cause::RetLoc) {
            self.counters
                .events
                .fetch_add(asdu.objects().len() as u64, Ordering::Relaxed);
        }
        let mut batch: Vec<(TagId, Sample)> = Vec::new();
        for o in asdu.objects() {
            let db = &self.db;
            let in_batch = |id: TagId| {
                batch
                    .iter()
                    .rev()
                    .find(|(b, _)| *b == id)
                    .map(|(_, s)| s.value.clone())
            };
            let outcome = self.points.sample(o, received, |id| {
                in_batch(id).or_else(|| db.get(id).map(|s| s.value))
            });
            match outcome {
                Outcome::Sample(id, sample) => {
                    if batch.iter().any(|(b, _)| *b == id) {
                        self.db.apply(std::mem::take(&mut batch));
                    }
                    batch.push((id, sample));
                }
                Outcome::Unmapped => {}
                Outcome::WrongType { tag, expected, got } => self.set_error(&format!(
                    "IOA {} of tag '{tag}' arrived as {got}, but the tag is configured as {expected}",
                    o.ioa
                )),
            }
        }
        if !batch.is_empty() {
            self.db.apply(batch);
        }
    }

    async fn begin_command(&mut self, request: CommandRequest) {
        let now = Instant::now();
        if self.started.is_none() {
            let last = self.counters.last_error.lock().clone();
            let _ = request.reply.send(Err(WriteError::Device {
                device: self.s.name.clone(),
                reason: format!("no started connection to the station ({last}); nothing was sent"),
            }));
            return;
        }
        let execute = match request.spec.element(&request.value) {
            Ok(e) => e,
            Err(reason) => {
                let _ = request.reply.send(Err(WriteError::BadValue {
                    tag: request.tag.to_string(),
                    value: request.value.to_string(),
                    reason,
                }));
                return;
            }
        };
        if let Err(e) = self.leadership.permit() {
            let _ = request.reply.send(Err(WriteError::NotActive(e)));
            return;
        }
        let type_id = execute
            .type_id(false)
            .expect("command elements have a type");
        let select = request.spec.select;
        let first = if select {
            with_select(execute, true)
        } else {
            execute
        };
        let asdu = command_asdu(type_id, self.s.common_address, request.spec.ioa, first);
        self.counters.commands.fetch_add(1, Ordering::Relaxed);
        tracing::info!(station = %self.s.name, tag = %request.tag, value = %request.value, command = type_id.name(), select, "IEC 104 command");
        self.active = Some(Active {
            procedure: Procedure {
                type_id,
                ioa: request.spec.ioa,
                phase: if select {
                    Phase::Selecting
                } else {
                    Phase::Executing
                },
                deadline: now + self.s.command_timeout,
                termination: self.s.termination,
            },
            request,
            execute,
        });
        self.queue(asdu);
        if let Some(started) = self.started {
            if let Err(e) = self.flush(started, now).await {
                self.close(started, &e);
            }
        }
    }

    fn finish_command(&mut self, result: Result<(), String>) {
        let Some(a) = self.active.take() else { return };
        let device = self.s.name.clone();
        let reply = match result {
            Ok(()) => Ok(()),
            Err(reason) => {
                self.counters
                    .commands_failed
                    .fetch_add(1, Ordering::Relaxed);
                tracing::warn!(station = %device, tag = %a.request.tag, %reason, "IEC 104 command failed");
                Err(WriteError::Device { device, reason })
            }
        };
        let _ = a.request.reply.send(reply);
    }

    fn queue(&mut self, asdu: Asdu) {
        self.outbox.push_back(asdu.encode());
    }

    /// Sends what the k window has room for.
    async fn flush(&mut self, slot: usize, now: Instant) -> Result<(), String> {
        while let Some(conn) = self.slots[slot].conn.as_mut() {
            if !conn.session.can_send() {
                break;
            }
            let Some(asdu) = self.outbox.pop_front() else {
                break;
            };
            let frame = conn.session.send_i(asdu, now);
            self.counters.i_frames_sent.fetch_add(1, Ordering::Relaxed);
            self.send(slot, &frame).await?;
        }
        Ok(())
    }

    /// Writes one frame; a peer that does not take it within t1 is gone.
    async fn send(&mut self, slot: usize, frame: &Frame) -> Result<(), String> {
        let bytes = apci::encode(frame).map_err(|e| format!("cannot encode a frame: {e}"))?;
        let t1 = self.s.session.t1;
        let Some(conn) = self.slots[slot].conn.as_mut() else {
            return Err("not connected".into());
        };
        match tokio::time::timeout(t1, conn.write.write_all(&bytes)).await {
            Ok(Ok(())) => Ok(()),
            Ok(Err(e)) => Err(format!("write failed: {e}")),
            Err(_) => Err("the station did not take our frame within t1".into()),
        }
    }

    /// Closes one connection. The started one takes its station's data with
    /// it: every point turns Bad until another connection is started and
    /// interrogated; a command in progress fails.
    fn close(&mut self, slot: usize, reason: &str) {
        let Some(conn) = self.slots[slot].conn.take() else {
            return;
        };
        conn.reader.abort();
        self.test_sent.remove(&slot);
        self.counters.disconnects.fetch_add(1, Ordering::Relaxed);
        let address = self.slots[slot].address.clone();
        let reason = format!("{address}: {reason}");
        tracing::warn!(station = %self.s.name, %reason, "IEC 104 connection closed");
        self.set_error(&reason);
        self.retry_later(slot);
        if self.starting == Some(slot) {
            self.starting = None;
        }
        if self.started == Some(slot) {
            self.started = None;
            self.outbox.clear();
            self.counters.connected.store(false, Ordering::Relaxed);
            let tested = self.slots.iter().any(|s| s.conn.is_some());
            self.counters
                .state
                .store(if tested { 2 } else { 0 }, Ordering::Relaxed);
            let q = TagQuality::bad(format!("communication lost: {reason}"));
            self.db
                .set_quality(&self.points.ids(), &q, self.clock.now());
            self.finish_command(Err(format!(
                "the connection closed before the station completed the command ({reason})"
            )));
            self.publish_status();
        } else if self.slots.iter().all(|s| s.conn.is_none()) {
            self.counters.state.store(0, Ordering::Relaxed);
        }
    }

    fn retry_later(&mut self, slot: usize) {
        let s = &mut self.slots[slot];
        s.next_attempt = Instant::now() + s.backoff;
        s.backoff = (s.backoff * 2).min(self.s.backoff_max);
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
        self.next_status = Instant::now() + Duration::from_secs(1);
        let c = &self.counters;
        let get = |a: &std::sync::atomic::AtomicU64| a.load(Ordering::Relaxed);
        self.status.publish(
            &self.db,
            self.clock.now(),
            gridscada_field::StatusFigures {
                connected: c.connected.load(Ordering::Relaxed),
                response_ms: get(&c.response_us) as f64 / 1000.0,
                requests: get(&c.i_frames_sent),
                errors: get(&c.errors),
                timeouts: get(&c.timeouts),
            },
        );
    }
}

/// An activation of a system command on IOA 0.
fn system(type_id: TypeId, ca: u16, e: Element) -> Asdu {
    Asdu::new(type_id, Cause::Act, ca, vec![InformationObject::new(0, e)])
        .expect("a system command is one valid object")
}

fn command_asdu(type_id: TypeId, ca: u16, ioa: u32, e: Element) -> Asdu {
    Asdu::new(
        type_id,
        Cause::Act,
        ca,
        vec![InformationObject::new(ioa, e)],
    )
    .expect("a command is one valid object")
}

/// Cuts one connection's byte stream into frames. A malformed frame ends
/// the connection: the stream cannot be trusted to be in step any more.
async fn read_frames(
    mut read: tokio::net::tcp::OwnedReadHalf,
    slot: usize,
    generation: u64,
    events: mpsc::Sender<Event>,
    counters: Arc<Counters>,
) {
    let mut buf = Vec::with_capacity(4096);
    let mut chunk = [0u8; 4096];
    loop {
        loop {
            match apci::decode(&buf) {
                Ok(Some((frame, used))) => {
                    buf.drain(..used);
                    if events
                        .send(Event::Frame(slot, generation, frame))
                        .await
                        .is_err()
                    {
                        return;
                    }
                }
                Ok(None) => break,
                Err(e) => {
                    counters.malformed.fetch_add(1, Ordering::Relaxed);
                    let _ = events
                        .send(Event::Closed(
                            slot,
                            generation,
                            format!("malformed frame: {e}"),
                        ))
                        .await;
                    return;
                }
            }
        }
        match read.read(&mut chunk).await {
            Ok(0) => {
                let _ = events
                    .send(Event::Closed(
                        slot,
                        generation,
                        "the station closed the connection".into(),
                    ))
                    .await;
                return;
            }
            Ok(n) => buf.extend_from_slice(&chunk[..n]),
            Err(e) => {
                let _ = events
                    .send(Event::Closed(slot, generation, format!("read failed: {e}")))
                    .await;
                return;
            }
        }
    }
}

/// The cause of initialisation (COI) of an M_EI_NA_1, in words.
fn init_cause_words(cause: u8, after_change: bool) -> String {
    let cause = match cause {
        0 => "local power on".to_string(),
        1 => "local manual reset".to_string(),
        2 => "remote reset".to_string(),
        c => format!("cause {c}"),
    };
    if after_change {
        format!("{cause}, after a change of local parameters")
    } else {
        cause
    }
}
