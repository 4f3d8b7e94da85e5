//! The procedures of a DNP3 master toward one outstation, as a pure state
//! machine (no sockets, no timers of its own): the I/O shell feeds it
//! events (connected, octets received, a timer fired, a command asked for)
//! with a [`Clock`], and carries out the [`Action`]s it answers with (send
//! these octets, deliver these measurements, a command's outcome, IIN
//! changes and reports, wake me at this instant).
//!
//! What it sequences: on connect, DISABLE_UNSOLICITED (optional), an
//! integrity poll, ENABLE_UNSOLICITED; every response with CON and every
//! unsolicited response confirmed; one request outstanding at a time with
//! a response timeout, the others queued with commands first; periodic
//! integrity and event polls; IIN1.7 DEVICE_RESTART -> clear it, then an
//! integrity poll; IIN1.4 NEED_TIME -> the LAN time sync
//! (RECORD_CURRENT_TIME, then WRITE g50v3); IIN2.3 EVENT_BUFFER_OVERFLOW
//! -> an integrity poll, reported; select-before-operate with the echo and
//! status of both steps checked, or direct operate.
//!
//! Link layer over TCP: requests go as UNCONFIRMED_USER_DATA; the master
//! answers an outstation's REQUEST_LINK_STATUS with LINK_STATUS and its
//! RESET_LINK_STATES, TEST_LINK and CONFIRMED_USER_DATA with ACK.

use std::time::{Duration, Instant};

use thiserror::Error;

use crate::app::{FunctionCode, Iin, Range, ResponseHeader};
use crate::link::{self, LinkFrame, LinkFunction};
use crate::objects::{self, CommandObject, CommandStatus, Measurement};
use crate::request;
use crate::transport::{self, Reassembler};

/// The time now: monotonic for timeouts, wall clock for time sync.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Clock {
    pub mono: Instant,
    /// Milliseconds since 1970-01-01 UTC.
    pub unix_ms: u64,
}

/// One outstation's settings.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MasterConfig {
    /// Our link address (source of our frames).
    pub master_address: u16,
    /// The outstation's link address.
    pub outstation_address: u16,
    /// How long a response may take.
    pub response_timeout: Duration,
    /// Integrity poll period (besides the one at start); `None`: only at start.
    pub integrity_period: Option<Duration>,
    /// Class 1/2/3 event poll period; `None`: no periodic event polls.
    pub event_period: Option<Duration>,
    /// DISABLE_UNSOLICITED before the first integrity poll.
    pub disable_unsolicited_at_start: bool,
    /// ENABLE_UNSOLICITED after the first integrity poll.
    pub enable_unsolicited: bool,
    /// Answer IIN1.4 NEED_TIME with a time sync.
    pub time_sync: bool,
    /// How long an OPERATE may follow its SELECT.
    pub select_timeout: Duration,
    /// The largest fragment reassembled.
    pub max_fragment: usize,
    /// How long after a failed integrity poll (no response, or a
    /// malformed one) it is tried again.
    pub integrity_retry: Duration,
}

impl Default for MasterConfig {
    fn default() -> Self {
        MasterConfig {
            master_address: 1,
            outstation_address: 1024,
            response_timeout: Duration::from_secs(5),
            integrity_period: Some(Duration::from_secs(3600)),
            event_period: Some(Duration::from_secs(5)),
            disable_unsolicited_at_start: true,
            enable_unsolicited: true,
            time_sync: true,
            select_timeout: Duration::from_secs(10),
            max_fragment: transport::DEFAULT_MAX_FRAGMENT,
            integrity_retry: Duration::from_secs(5),
        }
    }
}

/// Direct operate, or select then operate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CommandMode {
    SelectBeforeOperate,
    DirectOperate,
}

/// A command to carry out; `id` comes back with its outcome.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Command {
    pub id: u64,
    pub index: u16,
    pub object: CommandObject,
    pub mode: CommandMode,
}

/// Why a command failed; `stage` is the request it failed at.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum CommandError {
    #[error("{stage} refused: status {status}")]
    Status {
        stage: FunctionCode,
        status: CommandStatus,
    },
    #[error(
        "{stage}: the echo differs from the request (sent {sent:?} at index {index}, got {got})"
    )]
    EchoMismatch {
        stage: FunctionCode,
        index: u16,
        sent: CommandObject,
        got: String,
    },
    #[error("{stage} refused by the outstation: IIN {iin}")]
    Iin { stage: FunctionCode, iin: Iin },
    #[error("no response to {stage} within {after:?}")]
    Timeout {
        stage: FunctionCode,
        after: Duration,
    },
    #[error("the SELECT was answered after {after:?}, past the select timeout {timeout:?}: OPERATE not sent")]
    SelectExpired { after: Duration, timeout: Duration },
    #[error("{stage}: malformed response: {reason}")]
    Malformed { stage: FunctionCode, reason: String },
    #[error("not connected")]
    NotConnected,
    #[error("the connection closed before the command completed")]
    Disconnected,
}

/// Events worth a log line or a status tag.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum Report {
    #[error("no response to {function} ({task}) within {after:?}")]
    ResponseTimeout {
        function: FunctionCode,
        task: &'static str,
        after: Duration,
    },
    #[error("the outstation restarted (IIN1.7 DEVICE_RESTART)")]
    DeviceRestart,
    #[error("integrity poll complete")]
    IntegrityPollDone,
    #[error("the outstation's event buffer overflowed (IIN2.3): events were lost; integrity poll queued")]
    EventBufferOverflow,
    #[error("time synchronised (LAN procedure), recorded time {unix_ms} ms")]
    TimeSynced { unix_ms: u64 },
    #[error("{task} failed: IIN {iin}")]
    Refused { task: &'static str, iin: Iin },
    #[error("malformed input: {0}")]
    Malformed(String),
    #[error("ignored: {0}")]
    Ignored(String),
    #[error("{0}")]
    Note(String),
}

/// What the caller must do, in order.
#[derive(Debug, Clone, PartialEq)]
pub enum Action {
    /// Write these octets (link frames) to the connection.
    Send(Vec<u8>),
    /// Values from a response, in the order received.
    Measurements(Vec<Measurement>),
    /// A command's outcome.
    CommandOutcome {
        id: u64,
        result: Result<(), CommandError>,
    },
    /// The outstation's IIN changed.
    IinChanged {
        before: Iin,
        now: Iin,
    },
    Report(Report),
    /// Call [`Master::tick`] at this instant (the earliest deadline).
    Timer(Instant),
    /// Close the connection (and reconnect later): the outstation sent
    /// [`MALFORMED_IN_A_ROW`] malformed frames or fragments in a row.
    Disconnect(String),
}

/// Malformed link frames, segments or fragments in a row after which the
/// connection is closed. Over TCP nothing corrupts a frame on the way, so
/// a run of them is a broken or hostile peer; one is discarded and counted
/// as the standard's link layer does.
pub const MALFORMED_IN_A_ROW: u32 = 3;

#[derive(Debug, Clone, Copy, PartialEq)]
enum Task {
    Command(Command),
    ClearRestart,
    TimeSync,
    DisableUnsolicited,
    Integrity,
    EnableUnsolicited,
    Read(u8, u8, Range),
    EventPoll,
}

impl Task {
    fn priority(&self) -> u8 {
        match self {
            Task::Command(_) => 0,
            Task::ClearRestart => 1,
            Task::TimeSync => 2,
            Task::DisableUnsolicited => 3,
            Task::Integrity => 4,
            Task::EnableUnsolicited => 5,
            Task::Read(..) => 6,
            Task::EventPoll => 7,
        }
    }

    fn name(&self) -> &'static str {
        match self {
            Task::Command(_) => "command",
            Task::ClearRestart => "clear restart",
            Task::TimeSync => "time sync",
            Task::DisableUnsolicited => "disable unsolicited",
            Task::Integrity => "integrity poll",
            Task::EnableUnsolicited => "enable unsolicited",
            Task::Read(..) => "read",
            Task::EventPoll => "event poll",
        }
    }
}

/// The step a request in flight is at.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Step {
    Plain,
    Select,
    Operate { selected_at: Instant },
    Direct,
    RecordTime { unix_ms: u64 },
    WriteTime { unix_ms: u64 },
}

#[derive(Debug, Clone)]
struct InFlight {
    task: Task,
    step: Step,
    function: FunctionCode,
    /// The request's sequence number.
    seq: u8,
    /// The sequence number the next response fragment must carry: the
    /// request's for the first, one more for each following fragment.
    expect_seq: u8,
    sent_at: Instant,
    deadline: Instant,
}

/// One outstation's master session.
#[derive(Debug)]
pub struct Master {
    cfg: MasterConfig,
    connected: bool,
    rx: Vec<u8>,
    reassembler: Reassembler,
    transport_seq: u8,
    app_seq: u8,
    queue: Vec<Task>,
    in_flight: Option<InFlight>,
    iin: Iin,
    next_integrity: Option<Instant>,
    next_events: Option<Instant>,
    last_unsolicited: Option<Vec<u8>>,
    /// ENABLE_UNSOLICITED was accepted on this connection.
    unsolicited_enabled: bool,
    /// IIN bits whose procedure the outstation refused (restart clear, time
    /// sync): not acted on again until the outstation clears them.
    refused_bits: Iin,
    /// Malformed input since the last well-formed response.
    malformed_run: u32,
    /// Octets discarded as malformed, since the master was made.
    discarded_octets: u64,
    /// Link frames from the outstation to us, since the master was made.
    frames_heard: u64,
    /// When a failed integrity poll is tried again.
    integrity_retry_at: Option<Instant>,
}

impl Master {
    pub fn new(cfg: MasterConfig) -> Master {
        let reassembler = Reassembler::new(cfg.max_fragment);
        Master {
            cfg,
            connected: false,
            rx: Vec::new(),
            reassembler,
            transport_seq: 0,
            app_seq: 0,
            queue: Vec::new(),
            in_flight: None,
            iin: Iin::default(),
            next_integrity: None,
            next_events: None,
            last_unsolicited: None,
            unsolicited_enabled: false,
            refused_bits: Iin::default(),
            malformed_run: 0,
            discarded_octets: 0,
            frames_heard: 0,
            integrity_retry_at: None,
        }
    }

    pub fn config(&self) -> &MasterConfig {
        &self.cfg
    }

    /// The outstation's last IIN.
    pub fn iin(&self) -> Iin {
        self.iin
    }

    /// Octets discarded as malformed (frames with a bad CRC or length,
    /// garbage, segments out of sequence, fragments that do not parse).
    pub fn discarded_octets(&self) -> u64 {
        self.discarded_octets
    }

    /// Well-formed link frames from the outstation to us: whether it
    /// answers, as opposed to anything arriving on the connection.
    pub fn frames_heard(&self) -> u64 {
        self.frames_heard
    }

    pub fn is_connected(&self) -> bool {
        self.connected
    }

    /// Whether a request is waiting for its response.
    pub fn is_busy(&self) -> bool {
        self.in_flight.is_some()
    }

    /// The connection is up: start the startup sequence.
    pub fn connected(&mut self, now: Clock) -> Vec<Action> {
        self.connected = true;
        self.rx.clear();
        self.reassembler.reset();
        self.last_unsolicited = None;
        self.unsolicited_enabled = false;
        self.refused_bits = Iin::default();
        if self.cfg.disable_unsolicited_at_start {
            self.enqueue(Task::DisableUnsolicited);
        }
        self.enqueue(Task::Integrity);
        if self.cfg.enable_unsolicited {
            self.enqueue(Task::EnableUnsolicited);
        }
        self.next_integrity = self.cfg.integrity_period.map(|p| now.mono + p);
        self.next_events = self.cfg.event_period.map(|p| now.mono + p);
        let mut out = Vec::new();
        self.pump(now, &mut out);
        out
    }

    /// The connection closed: commands under way fail, the queue empties.
    pub fn disconnected(&mut self) -> Vec<Action> {
        self.connected = false;
        let mut out = Vec::new();
        if let Some(f) = self.in_flight.take() {
            if let Task::Command(c) = f.task {
                out.push(outcome(c.id, Err(CommandError::Disconnected)));
            }
        }
        for t in std::mem::take(&mut self.queue) {
            if let Task::Command(c) = t {
                out.push(outcome(c.id, Err(CommandError::Disconnected)));
            }
        }
        self.rx.clear();
        self.reassembler.reset();
        self.next_integrity = None;
        self.next_events = None;
        self.malformed_run = 0;
        self.integrity_retry_at = None;
        out
    }

    /// Queue a command (ahead of polls).
    pub fn command(&mut self, command: Command, now: Clock) -> Vec<Action> {
        if !self.connected {
            return vec![outcome(command.id, Err(CommandError::NotConnected))];
        }
        self.queue.push(Task::Command(command));
        let mut out = Vec::new();
        self.pump(now, &mut out);
        out
    }

    /// Queue a read of one group/variation over a range.
    pub fn read(&mut self, group: u8, variation: u8, range: Range, now: Clock) -> Vec<Action> {
        if self.connected {
            self.enqueue(Task::Read(group, variation, range));
        }
        let mut out = Vec::new();
        self.pump(now, &mut out);
        out
    }

    /// Queue an integrity poll now (e.g. on an operator's request).
    pub fn integrity_poll(&mut self, now: Clock) -> Vec<Action> {
        if self.connected {
            self.enqueue(Task::Integrity);
        }
        let mut out = Vec::new();
        self.pump(now, &mut out);
        out
    }

    /// Octets read from the connection.
    pub fn received(&mut self, octets: &[u8], now: Clock) -> Vec<Action> {
        let mut out = Vec::new();
        self.rx.extend_from_slice(octets);
        while let Some(frame) = link::take_frame(&mut self.rx) {
            match frame {
                Ok(frame) => self.link_frame(frame, now, &mut out),
                Err(e) => {
                    let octets = e.discard().max(1);
                    self.malformed(format!("link layer: {e}"), octets, &mut out)
                }
            }
        }
        self.pump(now, &mut out);
        out
    }

    /// A timer fired (or any time): timeouts and periodic polls.
    pub fn tick(&mut self, now: Clock) -> Vec<Action> {
        let mut out = Vec::new();
        if let Some(f) = &self.in_flight {
            if now.mono >= f.deadline {
                let f = self.in_flight.take().expect("checked above");
                self.reassembler.reset();
                let after = self.cfg.response_timeout;
                match f.task {
                    Task::Command(c) => out.push(outcome(
                        c.id,
                        Err(CommandError::Timeout {
                            stage: f.function,
                            after,
                        }),
                    )),
                    t => {
                        if t == Task::Integrity {
                            self.integrity_retry_at = Some(now.mono + self.cfg.integrity_retry);
                        }
                        out.push(Action::Report(Report::ResponseTimeout {
                            function: f.function,
                            task: t.name(),
                            after,
                        }))
                    }
                }
            }
        }
        if self.connected {
            if self.integrity_retry_at.is_some_and(|at| now.mono >= at) {
                self.integrity_retry_at = None;
                self.enqueue(Task::Integrity);
            }
            if let (Some(at), Some(p)) = (self.next_integrity, self.cfg.integrity_period) {
                if now.mono >= at {
                    self.enqueue(Task::Integrity);
                    self.next_integrity = Some(now.mono + p);
                }
            }
            if let (Some(at), Some(p)) = (self.next_events, self.cfg.event_period) {
                if now.mono >= at {
                    self.enqueue(Task::EventPoll);
                    self.next_events = Some(now.mono + p);
                }
            }
        }
        self.pump(now, &mut out);
        out
    }

    /// The earliest instant [`Master::tick`] has work.
    pub fn next_deadline(&self) -> Option<Instant> {
        [
            self.in_flight.as_ref().map(|f| f.deadline),
            self.next_integrity,
            self.next_events,
            self.integrity_retry_at,
        ]
        .into_iter()
        .flatten()
        .min()
    }

    fn enqueue(&mut self, task: Task) {
        let same = |t: &Task| std::mem::discriminant(t) == std::mem::discriminant(&task);
        let dup = !matches!(task, Task::Command(_) | Task::Read(..))
            && (self.queue.iter().any(same)
                || self
                    .in_flight
                    .as_ref()
                    .is_some_and(|f| same(&f.task) && task != Task::Integrity));
        if !dup {
            self.queue.push(task);
        }
    }

    /// Start the next request if none is in flight, and set the timer.
    fn pump(&mut self, now: Clock, out: &mut Vec<Action>) {
        if self.connected && self.in_flight.is_none() {
            if let Some(i) = (0..self.queue.len()).min_by_key(|&i| (self.queue[i].priority(), i)) {
                let task = self.queue.remove(i);
                let step = match task {
                    Task::Command(c) => match c.mode {
                        CommandMode::SelectBeforeOperate => Step::Select,
                        CommandMode::DirectOperate => Step::Direct,
                    },
                    Task::TimeSync => Step::RecordTime {
                        unix_ms: now.unix_ms,
                    },
                    _ => Step::Plain,
                };
                self.start(task, step, now, out);
            }
        }
        if let Some(t) = self.next_deadline() {
            out.push(Action::Timer(t));
        }
    }

    fn start(&mut self, task: Task, step: Step, now: Clock, out: &mut Vec<Action>) {
        let seq = self.app_seq;
        self.app_seq = (self.app_seq + 1) & crate::app::SEQ_MASK;
        let (function, apdu) = match (task, step) {
            (Task::Command(c), step) => {
                let f = match step {
                    Step::Select => FunctionCode::Select,
                    Step::Operate { .. } => FunctionCode::Operate,
                    _ => FunctionCode::DirectOperate,
                };
                (f, request::command(seq, f, c.index, c.object))
            }
            (_, Step::WriteTime { unix_ms }) => (
                FunctionCode::Write,
                request::write_recorded_time(seq, unix_ms),
            ),
            (Task::TimeSync, _) | (_, Step::RecordTime { .. }) => (
                FunctionCode::RecordCurrentTime,
                request::record_current_time(seq),
            ),
            (Task::ClearRestart, _) => (FunctionCode::Write, request::clear_restart(seq)),
            (Task::DisableUnsolicited, _) => (
                FunctionCode::DisableUnsolicited,
                request::unsolicited(seq, false),
            ),
            (Task::EnableUnsolicited, _) => (
                FunctionCode::EnableUnsolicited,
                request::unsolicited(seq, true),
            ),
            (Task::Integrity, _) => (FunctionCode::Read, request::integrity_poll(seq)),
            (Task::Read(g, v, r), _) => (FunctionCode::Read, request::read(seq, g, v, r)),
            (Task::EventPoll, _) => (FunctionCode::Read, request::event_poll(seq)),
        };
        self.send_apdu(&apdu, out);
        self.in_flight = Some(InFlight {
            task,
            step,
            function,
            seq,
            expect_seq: seq,
            sent_at: now.mono,
            deadline: now.mono + self.cfg.response_timeout,
        });
    }

    fn send_apdu(&mut self, apdu: &[u8], out: &mut Vec<Action>) {
        let mut bytes = Vec::new();
        for seg in transport::segment(apdu, &mut self.transport_seq) {
            let f = LinkFrame::user_data(self.cfg.outstation_address, self.cfg.master_address, seg);
            // Segments are at most 250 octets: encoding cannot fail.
            if let Ok(b) = f.encode() {
                bytes.extend_from_slice(&b);
            }
        }
        out.push(Action::Send(bytes));
    }

    fn send_link(&mut self, function: LinkFunction, out: &mut Vec<Action>) {
        let f = LinkFrame::header_only(
            true,
            function,
            self.cfg.outstation_address,
            self.cfg.master_address,
        );
        if let Ok(b) = f.encode() {
            out.push(Action::Send(b));
        }
    }

    fn link_frame(&mut self, frame: LinkFrame, now: Clock, out: &mut Vec<Action>) {
        if frame.destination != self.cfg.master_address
            || frame.source != self.cfg.outstation_address
        {
            out.push(Action::Report(Report::Ignored(format!(
                "link frame {} from {} to {} (expected from {} to {})",
                frame.function,
                frame.source,
                frame.destination,
                self.cfg.outstation_address,
                self.cfg.master_address
            ))));
            return;
        }
        self.frames_heard += 1;
        match frame.function {
            LinkFunction::UnconfirmedUserData => self.segment(&frame.data, now, out),
            LinkFunction::ConfirmedUserData => {
                self.send_link(LinkFunction::Ack, out);
                self.segment(&frame.data, now, out);
            }
            LinkFunction::RequestLinkStatus => self.send_link(LinkFunction::LinkStatus, out),
            LinkFunction::ResetLinkStates | LinkFunction::TestLink => {
                self.send_link(LinkFunction::Ack, out)
            }
            // Answers to primary frames we never send over TCP.
            LinkFunction::Ack
            | LinkFunction::Nack
            | LinkFunction::LinkStatus
            | LinkFunction::NotSupported => {}
        }
    }

    fn segment(&mut self, data: &[u8], now: Clock, out: &mut Vec<Action>) {
        match self.reassembler.push(data) {
            Ok(Some(fragment)) => self.fragment(&fragment, now, out),
            Ok(None) => {}
            Err(e) => self.malformed(format!("transport: {e}"), data.len(), out),
        }
    }

    fn fragment(&mut self, fragment: &[u8], now: Clock, out: &mut Vec<Action>) {
        let header = match ResponseHeader::decode(fragment) {
            Ok(h) => h,
            Err(e) => {
                self.malformed(format!("application layer: {e}"), fragment.len(), out);
                return;
            }
        };
        // The whole fragment is parsed before any of it is used or
        // confirmed: a fragment that does not parse is malformed, its
        // values dropped and not confirmed (the outstation sends it again).
        let objects = objects::parse(&fragment[ResponseHeader::LEN..], ResponseHeader::LEN);
        if let Some(e) = &objects.error {
            self.malformed(format!("objects: {e}"), fragment.len(), out);
            if header.function == FunctionCode::Response {
                self.response_failed(now, out);
            }
            return;
        }
        let unsolicited = header.function == FunctionCode::UnsolicitedResponse;
        if unsolicited {
            if header.control.con {
                self.send_apdu(&request::confirm(header.control.seq, true), out);
            }
            if self.last_unsolicited.as_deref() == Some(fragment) {
                out.push(Action::Report(Report::Ignored(format!(
                    "repeated unsolicited response seq {} (confirmed again)",
                    header.control.seq
                ))));
                return;
            }
            self.last_unsolicited = Some(fragment.to_vec());
            self.deliver(&objects, out);
            self.iin_changes(header.iin, out);
            return;
        }
        if header.function != FunctionCode::Response {
            out.push(Action::Report(Report::Ignored(format!(
                "{} fragment",
                header.function
            ))));
            return;
        }
        let Some(f) = self.in_flight.clone() else {
            out.push(Action::Report(Report::Ignored(format!(
                "response seq {} with no request outstanding",
                header.control.seq
            ))));
            return;
        };
        if header.control.seq != f.expect_seq {
            out.push(Action::Report(Report::Ignored(format!(
                "response seq {}, expected {} (request seq {})",
                header.control.seq, f.expect_seq, f.seq
            ))));
            return;
        }
        if header.control.con {
            self.send_apdu(&request::confirm(header.control.seq, false), out);
        }
        let refused = header
            .iin
            .any(Iin::NO_FUNC_CODE_SUPPORT | Iin::OBJECT_UNKNOWN | Iin::PARAMETER_ERROR);
        match f.task {
            Task::Command(c) => {
                self.in_flight = None;
                self.iin_changes(header.iin, out);
                let result = self.command_response(&c, &f, header.iin, &objects, now);
                if result.is_ok() {
                    self.malformed_run = 0;
                }
                match result {
                    Ok(true) => {
                        let selected_at = f.sent_at;
                        self.start(Task::Command(c), Step::Operate { selected_at }, now, out);
                    }
                    Ok(false) => {
                        out.push(outcome(c.id, Ok(())));
                        // The returned status confirms the command: fetch
                        // its event now rather than at the next poll.
                        if !self.unsolicited_enabled {
                            self.enqueue(Task::EventPoll);
                        }
                    }
                    Err(e) => out.push(outcome(c.id, Err(e))),
                }
            }
            task => {
                self.deliver(&objects, out);
                if !header.control.fin {
                    // More fragments follow: the timeout starts again.
                    if let Some(f) = &mut self.in_flight {
                        f.deadline = now.mono + self.cfg.response_timeout;
                        f.expect_seq = (f.expect_seq + 1) & crate::app::SEQ_MASK;
                    }
                    self.iin_changes(header.iin, out);
                    return;
                }
                self.in_flight = None;
                if refused {
                    out.push(Action::Report(Report::Refused {
                        task: task.name(),
                        iin: header.iin,
                    }));
                    // Asking again at every response would loop.
                    match task {
                        Task::TimeSync => self.refused_bits = self.refused_bits | Iin::NEED_TIME,
                        Task::ClearRestart => {
                            self.refused_bits = self.refused_bits | Iin::DEVICE_RESTART
                        }
                        _ => {}
                    }
                } else {
                    match task {
                        Task::EnableUnsolicited => self.unsolicited_enabled = true,
                        Task::DisableUnsolicited => self.unsolicited_enabled = false,
                        Task::Integrity => {
                            self.integrity_retry_at = None;
                            out.push(Action::Report(Report::IntegrityPollDone));
                        }
                        _ => {}
                    }
                    match f.step {
                        Step::RecordTime { unix_ms } => {
                            // NEED_TIME stays set until the WRITE: the
                            // sync under way answers it.
                            self.iin_changes(Iin(header.iin.0 & !Iin::NEED_TIME.0), out);
                            self.start(task, Step::WriteTime { unix_ms }, now, out);
                            return;
                        }
                        Step::WriteTime { unix_ms } => {
                            out.push(Action::Report(Report::TimeSynced { unix_ms }));
                            // The outstation may still show NEED_TIME in
                            // this response; do not start over at once.
                            self.iin_changes(Iin(header.iin.0 & !Iin::NEED_TIME.0), out);
                            return;
                        }
                        _ => {}
                    }
                }
                self.iin_changes(header.iin, out);
                if task != Task::EventPoll
                    && task != Task::Integrity
                    && header
                        .iin
                        .any(Iin::CLASS1_EVENTS | Iin::CLASS2_EVENTS | Iin::CLASS3_EVENTS)
                    && !self.unsolicited_enabled
                {
                    self.enqueue(Task::EventPoll);
                }
            }
        }
    }

    /// Check a command's response: `Ok(true)` when the SELECT succeeded
    /// and the OPERATE is due, `Ok(false)` when the command is done.
    fn command_response(
        &mut self,
        c: &Command,
        f: &InFlight,
        iin: Iin,
        objects: &objects::Objects,
        now: Clock,
    ) -> Result<bool, CommandError> {
        let stage = f.function;
        let bad_iin = iin.0
            & (Iin::NO_FUNC_CODE_SUPPORT.0
                | Iin::OBJECT_UNKNOWN.0
                | Iin::PARAMETER_ERROR.0
                | Iin::ALREADY_EXECUTING.0);
        if bad_iin != 0 {
            return Err(CommandError::Iin {
                stage,
                iin: Iin(bad_iin),
            });
        }
        if let Some(e) = &objects.error {
            return Err(CommandError::Malformed {
                stage,
                reason: e.to_string(),
            });
        }
        let echo = match objects.commands.as_slice() {
            [one] => one,
            other => {
                return Err(CommandError::EchoMismatch {
                    stage,
                    index: c.index,
                    sent: c.object,
                    got: format!("{} command objects", other.len()),
                })
            }
        };
        if echo.index != c.index || echo.object != c.object {
            return Err(CommandError::EchoMismatch {
                stage,
                index: c.index,
                sent: c.object,
                got: format!("{:?} at index {}", echo.object, echo.index),
            });
        }
        if echo.status != CommandStatus::Success {
            return Err(CommandError::Status {
                stage,
                status: echo.status,
            });
        }
        match f.step {
            Step::Select => {
                let after = now.mono.saturating_duration_since(f.sent_at);
                if after >= self.cfg.select_timeout {
                    return Err(CommandError::SelectExpired {
                        after,
                        timeout: self.cfg.select_timeout,
                    });
                }
                Ok(true)
            }
            _ => Ok(false),
        }
    }

    /// The response in flight was malformed: the request has failed; a
    /// failed integrity poll is tried again after `integrity_retry`.
    fn response_failed(&mut self, now: Clock, out: &mut Vec<Action>) {
        let Some(f) = self.in_flight.take() else {
            return;
        };
        self.reassembler.reset();
        match f.task {
            Task::Command(c) => out.push(outcome(
                c.id,
                Err(CommandError::Malformed {
                    stage: f.function,
                    reason: "the response does not parse".into(),
                }),
            )),
            Task::Integrity => self.integrity_retry_at = Some(now.mono + self.cfg.integrity_retry),
            _ => {}
        }
    }

    /// Malformed input (`octets` of it): reported, and the connection
    /// closed after a run.
    fn malformed(&mut self, reason: String, octets: usize, out: &mut Vec<Action>) {
        self.discarded_octets += octets as u64;
        self.malformed_run += 1;
        out.push(Action::Report(Report::Malformed(reason.clone())));
        if self.malformed_run >= MALFORMED_IN_A_ROW {
            self.malformed_run = 0;
            out.push(Action::Disconnect(format!(
                "{MALFORMED_IN_A_ROW} malformed frames in a row from the outstation (last: {reason})"
            )));
        }
    }

    fn deliver(&mut self, objects: &objects::Objects, out: &mut Vec<Action>) {
        for n in &objects.notes {
            out.push(Action::Report(Report::Note(n.clone())));
        }
        self.malformed_run = 0;
        if !objects.measurements.is_empty() {
            out.push(Action::Measurements(objects.measurements.clone()));
        }
    }

    /// Report a changed IIN and queue what its bits call for.
    fn iin_changes(&mut self, iin: Iin, out: &mut Vec<Action>) {
        let before = self.iin;
        if iin != before {
            out.push(Action::IinChanged { before, now: iin });
        }
        let raised = iin.raised_since(before);
        self.iin = iin;
        // A refused bit is acted on again once the outstation has cleared it.
        self.refused_bits = Iin(self.refused_bits.0 & iin.0);
        let act = Iin(iin.0 & !self.refused_bits.0);
        if raised.contains(Iin::DEVICE_RESTART) {
            out.push(Action::Report(Report::DeviceRestart));
        }
        if act.contains(Iin::DEVICE_RESTART) {
            let clearing = self.queue.contains(&Task::ClearRestart)
                || self
                    .in_flight
                    .as_ref()
                    .is_some_and(|f| f.task == Task::ClearRestart);
            if !clearing {
                self.enqueue(Task::ClearRestart);
                self.enqueue(Task::Integrity);
                if self.cfg.enable_unsolicited {
                    self.enqueue(Task::EnableUnsolicited);
                }
            }
        }
        if act.contains(Iin::NEED_TIME) && self.cfg.time_sync {
            self.enqueue(Task::TimeSync);
        }
        if raised.contains(Iin::EVENT_BUFFER_OVERFLOW) {
            out.push(Action::Report(Report::EventBufferOverflow));
            self.enqueue(Task::Integrity);
        }
    }
}

fn outcome(id: u64, result: Result<(), CommandError>) -> Action {
    Action::CommandOutcome { id, result }
}
