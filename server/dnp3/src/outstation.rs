//! A DNP3 outstation's procedures, pure: the point database it reports
//! (static values and class 1 events with their time), the requests it
//! answers (class and static reads, confirmations, the restart clear, time
//! writes, unsolicited enable/disable, SELECT/OPERATE/DIRECT_OPERATE of
//! CROBs and analog outputs), unsolicited responses with their confirm and
//! retry, and multi-fragment responses, each fragment confirmed before the
//! next. gridscada's simulator serves its simulated outstations with it.
//!
//! A control is carried out by the caller: the machine checks a SELECT
//! (the point can be commanded) and an OPERATE (its SELECT is the same
//! object, the previous sequence number, within the select timeout), hands
//! the commands out as [`OutstationAction::Operate`], and answers with the
//! statuses the caller gives back to [`Outstation::operated`].
//!
//! Must not touch: sockets, tokio, tags, configuration.

use std::collections::{BTreeMap, HashSet, VecDeque};
use std::time::{Duration, Instant};

use crate::app::{Control, FunctionCode, Iin, ObjectHeader, Range, RequestHeader, ResponseHeader};
use crate::link::{self, LinkFrame, LinkFunction};
use crate::objects::{self, time48, CommandObject, CommandStatus, DoubleBit, MeasurementKind};
use crate::transport::{self, Reassembler};

/// The ONLINE flag of a point's flags octet.
const ONLINE: u8 = 0x01;
/// Events kept for the master; past this the oldest go and IIN2.3 is set.
const EVENT_CAPACITY: usize = 1000;

/// Settings of one outstation.
#[derive(Debug, Clone)]
pub struct OutstationConfig {
    /// Our link address.
    pub address: u16,
    /// The master's link address; frames from any other are ignored.
    pub master_address: u16,
    /// Largest response fragment, octets.
    pub max_fragment: usize,
    pub select_timeout: Duration,
    /// How long an unsolicited response or a confirmed fragment waits for
    /// its CONFIRM before it is sent again.
    pub confirm_timeout: Duration,
    /// An analog's move that makes an event, as a fraction of the value
    /// last reported (at least 0.001 in the value's units); 0: every
    /// change. The static value always follows.
    pub analog_deadband: f64,
}

impl Default for OutstationConfig {
    fn default() -> Self {
        OutstationConfig {
            address: 1024,
            master_address: 1,
            max_fragment: transport::DEFAULT_MAX_FRAGMENT,
            select_timeout: Duration::from_secs(10),
            confirm_timeout: Duration::from_secs(5),
            analog_deadband: 0.0,
        }
    }
}

/// A point's value as the outstation holds it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PointValue {
    Binary(bool),
    DoubleBit(DoubleBit),
    Counter(u32),
    /// An analog: sent as a 32-bit float, or as a 32-bit integer when the
    /// point is declared integer.
    Analog(f64),
}

/// One point of the database.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Point {
    pub kind: MeasurementKind,
    pub index: u16,
    /// Analogs sent as integers (v1/v3) rather than floats (v5/v7).
    pub integer: bool,
}

#[derive(Debug, Clone, Copy)]
struct Held {
    point: Point,
    value: PointValue,
    online: bool,
    /// The value of the last event.
    reported: PointValue,
}

#[derive(Debug, Clone, Copy)]
struct Event {
    point: Point,
    value: PointValue,
    online: bool,
    time_ms: u64,
}

/// What the caller must do, in order.
#[derive(Debug, Clone, PartialEq)]
pub enum OutstationAction {
    /// Write these octets (link frames) to the connection.
    Send(Vec<u8>),
    /// Carry out these controls (index, object) and call
    /// [`Outstation::operated`] with the request's objects and one status
    /// each, in order. `respond` is false for DIRECT_OPERATE_NR.
    Operate {
        seq: u8,
        function: FunctionCode,
        commands: Vec<(u16, CommandObject)>,
        /// The request's objects, echoed with the statuses.
        request: Vec<u8>,
        respond: bool,
    },
    /// The master set our clock (ms since 1970).
    TimeSet(u64),
    /// Call [`Outstation::tick`] at this instant.
    Timer(Instant),
}

/// A response waiting for its CONFIRM.
#[derive(Debug, Clone)]
struct AwaitingConfirm {
    seq: u8,
    unsolicited: bool,
    deadline: Instant,
    /// The fragment, to send again after the timeout (unsolicited only).
    fragment: Vec<u8>,
    /// Events it carried, removed when confirmed.
    events: usize,
    /// Fragments of a multi-fragment response still to send.
    rest: VecDeque<Vec<u8>>,
}

#[derive(Debug, Clone)]
struct Selected {
    seq: u8,
    /// The SELECT's objects: the OPERATE's must be identical.
    request: Vec<u8>,
    at: Instant,
}

/// One outstation's session.
pub struct Outstation {
    cfg: OutstationConfig,
    points: BTreeMap<(u8, u16), Held>,
    /// The points a CROB (g12) and an analog output block (g41) may command.
    crob_indices: HashSet<u16>,
    analog_output_indices: HashSet<u16>,
    events: VecDeque<Event>,
    overflow: bool,
    restart: bool,
    unsolicited_enabled: bool,
    unsolicited_seq: u8,
    tseq: u8,
    rx: Vec<u8>,
    reassembler: Reassembler,
    awaiting: Option<AwaitingConfirm>,
    selected: Option<Selected>,
}

fn kind_key(kind: MeasurementKind) -> u8 {
    kind as u8
}

impl Outstation {
    /// An outstation with `points` (all offline until set), commandable
    /// CROB and analog output indices.
    pub fn new(
        cfg: OutstationConfig,
        points: impl IntoIterator<Item = Point>,
        crob_indices: impl IntoIterator<Item = u16>,
        analog_output_indices: impl IntoIterator<Item = u16>,
    ) -> Outstation {
        let points = points
            .into_iter()
            .map(|p| {
                let value = match p.kind {
                    MeasurementKind::Binary | MeasurementKind::BinaryOutputStatus => {
                        PointValue::Binary(false)
                    }
                    MeasurementKind::DoubleBit => PointValue::DoubleBit(DoubleBit::Indeterminate),
                    MeasurementKind::Counter | MeasurementKind::FrozenCounter => {
                        PointValue::Counter(0)
                    }
                    MeasurementKind::Analog | MeasurementKind::AnalogOutputStatus => {
                        PointValue::Analog(0.0)
                    }
                };
                (
                    (kind_key(p.kind), p.index),
                    Held {
                        point: p,
                        value,
                        online: false,
                        reported: value,
                    },
                )
            })
            .collect();
        Outstation {
            cfg,
            points,
            crob_indices: crob_indices.into_iter().collect(),
            analog_output_indices: analog_output_indices.into_iter().collect(),
            events: VecDeque::new(),
            overflow: false,
            restart: true,
            unsolicited_enabled: false,
            unsolicited_seq: 0,
            tseq: 0,
            rx: Vec::new(),
            reassembler: Reassembler::default(),
            awaiting: None,
            selected: None,
        }
    }

    /// The master connected: a new session (the restart bit stays as it
    /// is; unsolicited responses wait for the master's enable).
    pub fn connected(&mut self) {
        self.rx.clear();
        self.reassembler.reset();
        self.awaiting = None;
        self.selected = None;
        self.unsolicited_enabled = false;
    }

    /// The internal indications as they stand.
    pub fn iin(&self) -> Iin {
        let mut iin = Iin::default();
        if self.restart {
            iin = iin.union(Iin::DEVICE_RESTART);
        }
        if !self.events.is_empty() {
            iin = iin.union(Iin::CLASS1_EVENTS);
        }
        if self.overflow {
            iin = iin.union(Iin::EVENT_BUFFER_OVERFLOW);
        }
        iin
    }

    /// A point's new value (online, or offline), observed at `time_ms`: a
    /// class 1 event when it changed, sent unsolicited when enabled.
    pub fn update(
        &mut self,
        kind: MeasurementKind,
        index: u16,
        value: PointValue,
        online: bool,
        time_ms: u64,
        now: Instant,
    ) -> Vec<OutstationAction> {
        let Some(held) = self.points.get_mut(&(kind_key(kind), index)) else {
            return Vec::new();
        };
        if held.value == value && held.online == online {
            return Vec::new();
        }
        let significant = match (held.reported, value) {
            (PointValue::Analog(was), PointValue::Analog(now)) if held.online == online => {
                let band = self.cfg.analog_deadband * was.abs();
                self.cfg.analog_deadband <= 0.0 || (now - was).abs() > band.max(0.001)
            }
            _ => true,
        };
        held.value = value;
        held.online = online;
        if !significant {
            return Vec::new();
        }
        held.reported = value;
        let point = held.point;
        if self.events.len() >= EVENT_CAPACITY {
            self.events.pop_front();
            self.overflow = true;
        }
        self.events.push_back(Event {
            point,
            value,
            online,
            time_ms,
        });
        let mut out = Vec::new();
        self.unsolicited(now, &mut out);
        out
    }

    /// Octets from the master.
    pub fn received(&mut self, octets: &[u8], now: Instant) -> Vec<OutstationAction> {
        let mut out = Vec::new();
        self.rx.extend_from_slice(octets);
        // Malformed frames are dropped: the master asks again.
        while let Some(frame) = link::take_frame(&mut self.rx) {
            if let Ok(frame) = frame {
                self.link_frame(frame, now, &mut out);
            }
        }
        out
    }

    /// Timers: a response not confirmed in time is sent again
    /// (unsolicited) or given up (solicited).
    pub fn tick(&mut self, now: Instant) -> Vec<OutstationAction> {
        let mut out = Vec::new();
        if let Some(a) = &mut self.awaiting {
            if now >= a.deadline {
                if a.unsolicited {
                    a.deadline = now + self.cfg.confirm_timeout;
                    let fragment = a.fragment.clone();
                    self.send_fragment(&fragment, &mut out);
                } else {
                    self.awaiting = None;
                }
            }
        }
        if let Some(a) = &self.awaiting {
            out.push(OutstationAction::Timer(a.deadline));
        }
        out
    }

    fn link_frame(&mut self, frame: LinkFrame, now: Instant, out: &mut Vec<OutstationAction>) {
        if frame.destination != self.cfg.address || frame.source != self.cfg.master_address {
            return;
        }
        match frame.function {
            LinkFunction::UnconfirmedUserData | LinkFunction::ConfirmedUserData => {
                if frame.function == LinkFunction::ConfirmedUserData {
                    self.send_link(LinkFunction::Ack, out);
                }
                // A segment out of sequence is dropped; the master asks again.
                if let Ok(Some(fragment)) = self.reassembler.push(&frame.data) {
                    self.request(&fragment, now, out);
                }
            }
            LinkFunction::RequestLinkStatus => self.send_link(LinkFunction::LinkStatus, out),
            LinkFunction::ResetLinkStates | LinkFunction::TestLink => {
                self.send_link(LinkFunction::Ack, out)
            }
            _ => {}
        }
    }

    fn request(&mut self, fragment: &[u8], now: Instant, out: &mut Vec<OutstationAction>) {
        let Ok(header) = RequestHeader::decode(fragment) else {
            return;
        };
        let seq = header.control.seq;
        let body = &fragment[RequestHeader::LEN..];
        match header.function {
            FunctionCode::Confirm => self.confirmed(header.control, now, out),
            FunctionCode::Read => self.read(seq, body, now, out),
            FunctionCode::Write => {
                let parsed = objects::parse(body, RequestHeader::LEN);
                let mut iin = Iin::default();
                for (bit, value) in &parsed.iin_bits {
                    if *bit == 7 && !value {
                        self.restart = false;
                    } else {
                        iin = iin.union(Iin::PARAMETER_ERROR);
                    }
                }
                if let Some(t) = parsed.time {
                    out.push(OutstationAction::TimeSet(t));
                }
                if parsed.error.is_some() {
                    iin = iin.union(Iin::PARAMETER_ERROR);
                }
                self.respond(seq, iin, Vec::new(), out);
            }
            FunctionCode::EnableUnsolicited | FunctionCode::DisableUnsolicited => {
                self.unsolicited_enabled = header.function == FunctionCode::EnableUnsolicited;
                self.respond(seq, Iin::default(), Vec::new(), out);
                if self.unsolicited_enabled {
                    self.unsolicited(now, out);
                }
            }
            FunctionCode::RecordCurrentTime => self.respond(seq, Iin::default(), Vec::new(), out),
            FunctionCode::Select => {
                let commands = commands_of(body);
                let statuses: Vec<CommandStatus> =
                    commands.iter().map(|c| self.can_command(c)).collect();
                if statuses.iter().all(|s| *s == CommandStatus::Success) && !commands.is_empty() {
                    self.selected = Some(Selected {
                        seq,
                        request: body.to_vec(),
                        at: now,
                    });
                }
                self.echo(seq, body, &statuses, out);
            }
            FunctionCode::Operate => {
                let commands = commands_of(body);
                let matches = self.selected.take().is_some_and(|s| {
                    s.request == body
                        && seq == (s.seq + 1) & crate::app::SEQ_MASK
                        && now.duration_since(s.at) <= self.cfg.select_timeout
                });
                if matches {
                    out.push(OutstationAction::Operate {
                        seq,
                        function: header.function,
                        commands,
                        request: body.to_vec(),
                        respond: true,
                    });
                } else {
                    let statuses = vec![CommandStatus::NoSelect; commands.len()];
                    self.echo(seq, body, &statuses, out);
                }
            }
            FunctionCode::DirectOperate | FunctionCode::DirectOperateNoResponse => {
                let commands = commands_of(body);
                let respond = header.function == FunctionCode::DirectOperate;
                let statuses: Vec<CommandStatus> =
                    commands.iter().map(|c| self.can_command(c)).collect();
                if statuses.iter().all(|s| *s == CommandStatus::Success) && !commands.is_empty() {
                    out.push(OutstationAction::Operate {
                        seq,
                        function: header.function,
                        commands,
                        request: body.to_vec(),
                        respond,
                    });
                } else if respond {
                    self.echo(seq, body, &statuses, out);
                }
            }
            _ => self.respond(seq, Iin::NO_FUNC_CODE_SUPPORT, Vec::new(), out),
        }
    }

    /// The caller carried out an OPERATE or DIRECT_OPERATE (`request`:
    /// its objects): answer it.
    pub fn operated(
        &mut self,
        seq: u8,
        request: &[u8],
        statuses: &[CommandStatus],
        respond: bool,
    ) -> Vec<OutstationAction> {
        let mut out = Vec::new();
        if respond {
            self.echo(seq, request, statuses, &mut out);
        }
        out
    }

    fn can_command(&self, (index, object): &(u16, CommandObject)) -> CommandStatus {
        let known = match object {
            CommandObject::Crob(_) => self.crob_indices.contains(index),
            CommandObject::Analog(_) => self.analog_output_indices.contains(index),
        };
        if known {
            CommandStatus::Success
        } else {
            CommandStatus::NotSupported
        }
    }

    /// The response to a control request: its objects as they came
    /// (headers, qualifiers and prefixes), each status octet set.
    fn echo(
        &mut self,
        seq: u8,
        request: &[u8],
        statuses: &[CommandStatus],
        out: &mut Vec<OutstationAction>,
    ) {
        let body = echo_of(request, statuses);
        let iin = if statuses.is_empty() {
            Iin::PARAMETER_ERROR
        } else {
            Iin::default()
        };
        self.respond(seq, iin, vec![body], out);
    }

    /// READ: class 0 (every point's static value), classes 1-3 (the
    /// events, all class 1 here), or one group's static values.
    fn read(&mut self, seq: u8, body: &[u8], now: Instant, out: &mut Vec<OutstationAction>) {
        let mut at = 0;
        let mut statics: Vec<Option<MeasurementKind>> = Vec::new();
        let mut events = false;
        let mut iin = Iin::default();
        while at < body.len() {
            let Ok((h, n)) = ObjectHeader::decode(body, at) else {
                iin = iin.union(Iin::PARAMETER_ERROR);
                break;
            };
            at += n;
            match (h.group, h.variation) {
                (60, 1) => statics.push(None),
                (60, 2..=4) => events = true,
                (1, _) => statics.push(Some(MeasurementKind::Binary)),
                (3, _) => statics.push(Some(MeasurementKind::DoubleBit)),
                (10, _) => statics.push(Some(MeasurementKind::BinaryOutputStatus)),
                (20, _) => statics.push(Some(MeasurementKind::Counter)),
                (21, _) => statics.push(Some(MeasurementKind::FrozenCounter)),
                (30, _) => statics.push(Some(MeasurementKind::Analog)),
                (40, _) => statics.push(Some(MeasurementKind::AnalogOutputStatus)),
                _ => iin = iin.union(Iin::OBJECT_UNKNOWN),
            }
        }
        let mut objects = Vec::new();
        let mut event_count = 0;
        let max_block = self.max_block();
        if events {
            event_count = self.events.len();
            encode_events(self.events.iter(), max_block, &mut objects);
        }
        for which in statics {
            encode_static(
                self.points
                    .values()
                    .filter(|h| which.is_none_or(|k| h.point.kind == k)),
                max_block,
                &mut objects,
            );
        }
        self.respond_events(seq, iin, objects, event_count, now, out);
    }

    /// The most object octets of one block, so that a block fits a
    /// fragment with its header.
    fn max_block(&self) -> usize {
        self.cfg
            .max_fragment
            .saturating_sub(ResponseHeader::LEN + 16)
            .max(64)
    }

    fn respond(
        &mut self,
        seq: u8,
        iin: Iin,
        objects: Vec<Vec<u8>>,
        out: &mut Vec<OutstationAction>,
    ) {
        let body: Vec<u8> = objects.concat();
        let fragment = self.fragment(
            Control {
                fir: true,
                fin: true,
                con: false,
                uns: false,
                seq,
            },
            FunctionCode::Response,
            iin,
            &body,
        );
        self.send_fragment(&fragment, out);
    }

    /// A response that may carry events (confirmed) and may need several
    /// fragments (each but the last confirmed before the next goes).
    fn respond_events(
        &mut self,
        seq: u8,
        iin: Iin,
        objects: Vec<Vec<u8>>,
        events: usize,
        now: Instant,
        out: &mut Vec<OutstationAction>,
    ) {
        // Objects packed into fragments; an object block never split.
        let room = self
            .cfg
            .max_fragment
            .saturating_sub(ResponseHeader::LEN)
            .max(64);
        let mut bodies: Vec<Vec<u8>> = vec![Vec::new()];
        for o in objects {
            let last = bodies.last_mut().expect("one body at least");
            if !last.is_empty() && last.len() + o.len() > room {
                bodies.push(o);
            } else {
                last.extend_from_slice(&o);
            }
        }
        let n = bodies.len();
        let mut fragments: VecDeque<Vec<u8>> = bodies
            .into_iter()
            .enumerate()
            .map(|(i, body)| {
                let s = (seq + i as u8) & crate::app::SEQ_MASK;
                let con = i + 1 < n || events > 0;
                self.fragment(
                    Control {
                        fir: i == 0,
                        fin: i + 1 == n,
                        con,
                        uns: false,
                        seq: s,
                    },
                    FunctionCode::Response,
                    iin,
                    &body,
                )
            })
            .collect();
        let first = fragments.pop_front().expect("one fragment at least");
        let con = Control::from_octet(first[0]).con;
        self.send_fragment(&first, out);
        if con {
            self.awaiting = Some(AwaitingConfirm {
                seq,
                unsolicited: false,
                deadline: now + self.cfg.confirm_timeout,
                fragment: Vec::new(),
                events: if fragments.is_empty() { events } else { 0 },
                rest: fragments,
            });
            out.push(OutstationAction::Timer(now + self.cfg.confirm_timeout));
        }
    }

    fn confirmed(&mut self, control: Control, now: Instant, out: &mut Vec<OutstationAction>) {
        let Some(a) = &self.awaiting else { return };
        if a.seq != control.seq || a.unsolicited != control.uns {
            return;
        }
        let mut a = self.awaiting.take().expect("checked above");
        if a.unsolicited {
            self.unsolicited_seq = (a.seq + 1) & crate::app::SEQ_MASK;
        }
        let confirmed_events = a.events.min(self.events.len());
        self.events.drain(..confirmed_events);
        if confirmed_events > 0 {
            self.overflow = false;
        }
        if let Some(next) = a.rest.pop_front() {
            let c = Control::from_octet(next[0]);
            self.send_fragment(&next, out);
            if c.con {
                let total_events = self.events.len();
                self.awaiting = Some(AwaitingConfirm {
                    seq: c.seq,
                    unsolicited: false,
                    deadline: now + self.cfg.confirm_timeout,
                    fragment: Vec::new(),
                    events: if a.rest.is_empty() && c.fin {
                        total_events
                    } else {
                        0
                    },
                    rest: std::mem::take(&mut a.rest),
                });
                out.push(OutstationAction::Timer(now + self.cfg.confirm_timeout));
            }
            return;
        }
        self.unsolicited(now, out);
    }

    /// Send the events unsolicited, when enabled and nothing is waiting.
    fn unsolicited(&mut self, now: Instant, out: &mut Vec<OutstationAction>) {
        if !self.unsolicited_enabled || self.awaiting.is_some() || self.events.is_empty() {
            return;
        }
        // As many events as fit one fragment.
        let room = self
            .cfg
            .max_fragment
            .saturating_sub(ResponseHeader::LEN + 16);
        let mut objects = Vec::new();
        let mut count = 0;
        for e in &self.events {
            let mut one = Vec::new();
            encode_events(std::iter::once(e), room, &mut one);
            let len: usize = objects.iter().map(Vec::len).sum::<usize>() + one[0].len();
            if len > room && count > 0 {
                break;
            }
            objects.extend(one);
            count += 1;
        }
        let seq = self.unsolicited_seq;
        let iin = self.iin();
        let fragment = self.fragment(
            Control {
                fir: true,
                fin: true,
                con: true,
                uns: true,
                seq,
            },
            FunctionCode::UnsolicitedResponse,
            iin,
            &objects.concat(),
        );
        self.send_fragment(&fragment, out);
        self.awaiting = Some(AwaitingConfirm {
            seq,
            unsolicited: true,
            deadline: now + self.cfg.confirm_timeout,
            fragment,
            events: count,
            rest: VecDeque::new(),
        });
        out.push(OutstationAction::Timer(now + self.cfg.confirm_timeout));
    }

    fn fragment(&self, control: Control, function: FunctionCode, iin: Iin, body: &[u8]) -> Vec<u8> {
        let mut f = Vec::with_capacity(ResponseHeader::LEN + body.len());
        ResponseHeader {
            control,
            function,
            iin: iin.union(self.iin()),
        }
        .encode(&mut f);
        f.extend_from_slice(body);
        f
    }

    fn send_fragment(&mut self, fragment: &[u8], out: &mut Vec<OutstationAction>) {
        let mut bytes = Vec::new();
        for seg in transport::segment(fragment, &mut self.tseq) {
            let frame = LinkFrame {
                dir: false,
                ..LinkFrame::user_data(self.cfg.master_address, self.cfg.address, seg)
            };
            // A segment is at most 250 octets, which a frame always takes.
            if let Ok(b) = frame.encode() {
                bytes.extend(b);
            }
        }
        out.push(OutstationAction::Send(bytes));
    }

    fn send_link(&mut self, function: LinkFunction, out: &mut Vec<OutstationAction>) {
        let frame =
            LinkFrame::header_only(false, function, self.cfg.master_address, self.cfg.address);
        if let Ok(b) = frame.encode() {
            out.push(OutstationAction::Send(b));
        }
    }
}

/// A control object's octets, its status octet last: g12v1, g41v1-v4.
fn control_size(group: u8, variation: u8) -> Option<usize> {
    match (group, variation) {
        (12, 1) => Some(crate::objects::Crob::LEN),
        (41, 1) | (41, 3) => Some(5),
        (41, 2) => Some(3),
        (41, 4) => Some(9),
        _ => None,
    }
}

/// The request's control objects with the status octet of the `k`-th set
/// to `statuses[k]`, in the order [`commands_of`] gives them; anything
/// after the last whole control object is left out.
fn echo_of(request: &[u8], statuses: &[CommandStatus]) -> Vec<u8> {
    let mut out = request.to_vec();
    let (mut at, mut k) = (0, 0);
    'headers: while at < request.len() {
        let Ok((h, n)) = ObjectHeader::decode(request, at) else {
            break;
        };
        let Some(size) = control_size(h.group, h.variation) else {
            break;
        };
        let mut next = at + n;
        for _ in 0..h.range.count() {
            let end = next + h.range.prefix_len() + size;
            if end > request.len() {
                break 'headers;
            }
            if let Some(s) = statuses.get(k) {
                out[end - 1] = s.code();
            }
            k += 1;
            next = end;
        }
        at = next;
    }
    out.truncate(at);
    out
}

/// The controls of a SELECT/OPERATE request (g12v1, g41), by index.
fn commands_of(body: &[u8]) -> Vec<(u16, CommandObject)> {
    objects::parse(body, RequestHeader::LEN)
        .commands
        .into_iter()
        .map(|c| (c.index, c.object))
        .collect()
}

fn flags(online: bool) -> u8 {
    if online {
        ONLINE
    } else {
        0
    }
}

/// The static objects of `points`, one start-stop block per run of
/// consecutive indices of one kind: g1v2, g3v2, g10v2, g20v1, g21v1,
/// g30v5 (v1 for integer points), g40v3 (v1).
fn encode_static<'a>(
    points: impl Iterator<Item = &'a Held>,
    max_block: usize,
    out: &mut Vec<Vec<u8>>,
) {
    let mut run: Option<(u8, u8, u16, u16, Vec<u8>)> = None;
    let flush = |run: &mut Option<(u8, u8, u16, u16, Vec<u8>)>, out: &mut Vec<Vec<u8>>| {
        if let Some((g, v, start, stop, data)) = run.take() {
            let mut block = Vec::with_capacity(7 + data.len());
            ObjectHeader::new(g, v, Range::StartStop16 { start, stop }).encode(&mut block);
            block.extend_from_slice(&data);
            out.push(block);
        }
    };
    for h in points {
        let f = flags(h.online);
        let (g, v, data): (u8, u8, Vec<u8>) = match (h.point.kind, h.value) {
            (MeasurementKind::Binary, PointValue::Binary(b)) => (1, 2, vec![f | u8::from(b) << 7]),
            (MeasurementKind::BinaryOutputStatus, PointValue::Binary(b)) => {
                (10, 2, vec![f | u8::from(b) << 7])
            }
            (MeasurementKind::DoubleBit, PointValue::DoubleBit(d)) => {
                (3, 2, vec![f | (d as u8) << 6])
            }
            (MeasurementKind::Counter, PointValue::Counter(c)) => (20, 1, counter(f, c)),
            (MeasurementKind::FrozenCounter, PointValue::Counter(c)) => (21, 1, counter(f, c)),
            (MeasurementKind::Analog, PointValue::Analog(a)) => {
                let (v, d) = analog(f, a, h.point.integer);
                (30, if v == 1 { 1 } else { 5 }, d)
            }
            (MeasurementKind::AnalogOutputStatus, PointValue::Analog(a)) => {
                let (v, d) = analog(f, a, h.point.integer);
                (40, if v == 1 { 1 } else { 3 }, d)
            }
            _ => continue,
        };
        let index = h.point.index;
        match &mut run {
            Some((rg, rv, _, stop, bytes))
                if *rg == g
                    && *rv == v
                    && stop.checked_add(1) == Some(index)
                    && bytes.len() + data.len() <= max_block =>
            {
                *stop = index;
                bytes.extend_from_slice(&data);
            }
            _ => {
                flush(&mut run, out);
                run = Some((g, v, index, index, data));
            }
        }
    }
    flush(&mut run, out);
}

fn counter(f: u8, c: u32) -> Vec<u8> {
    let mut d = vec![f];
    d.extend_from_slice(&c.to_le_bytes());
    d
}

/// Flags and value of an analog: `(1, …)` a 32-bit integer, `(5, …)` a
/// float.
fn analog(f: u8, a: f64, integer: bool) -> (u8, Vec<u8>) {
    let mut d = vec![f];
    if integer {
        let i = a.round().clamp(f64::from(i32::MIN), f64::from(i32::MAX)) as i32;
        d.extend_from_slice(&i.to_le_bytes());
        (1, d)
    } else {
        d.extend_from_slice(&(a as f32).to_le_bytes());
        (5, d)
    }
}

/// Events with their time, one 16-bit-index block per run of one
/// group/variation: g2v2, g4v2, g11v2, g22v5, g23v5, g32v7 (v3), g42v7 (v3).
fn encode_events<'a>(
    events: impl Iterator<Item = &'a Event>,
    max_block: usize,
    out: &mut Vec<Vec<u8>>,
) {
    let mut run: Option<(u8, u8, u16, Vec<u8>)> = None;
    let flush = |run: &mut Option<(u8, u8, u16, Vec<u8>)>, out: &mut Vec<Vec<u8>>| {
        if let Some((g, v, count, data)) = run.take() {
            let mut block = Vec::with_capacity(5 + data.len());
            ObjectHeader::new(g, v, Range::Indexed16(count)).encode(&mut block);
            block.extend_from_slice(&data);
            out.push(block);
        }
    };
    for e in events {
        let f = flags(e.online);
        let t = time48(e.time_ms);
        let (g, v, mut data): (u8, u8, Vec<u8>) = match (e.point.kind, e.value) {
            (MeasurementKind::Binary, PointValue::Binary(b)) => (2, 2, vec![f | u8::from(b) << 7]),
            (MeasurementKind::BinaryOutputStatus, PointValue::Binary(b)) => {
                (11, 2, vec![f | u8::from(b) << 7])
            }
            (MeasurementKind::DoubleBit, PointValue::DoubleBit(d)) => {
                (4, 2, vec![f | (d as u8) << 6])
            }
            (MeasurementKind::Counter, PointValue::Counter(c)) => (22, 5, counter(f, c)),
            (MeasurementKind::FrozenCounter, PointValue::Counter(c)) => (23, 5, counter(f, c)),
            (MeasurementKind::Analog, PointValue::Analog(a)) => {
                let (v, d) = analog(f, a, e.point.integer);
                (32, if v == 1 { 3 } else { 7 }, d)
            }
            (MeasurementKind::AnalogOutputStatus, PointValue::Analog(a)) => {
                let (v, d) = analog(f, a, e.point.integer);
                (42, if v == 1 { 3 } else { 7 }, d)
            }
            _ => continue,
        };
        data.extend_from_slice(&t);
        let mut prefixed = e.point.index.to_le_bytes().to_vec();
        prefixed.append(&mut data);
        match &mut run {
            Some((rg, rv, count, bytes))
                if *rg == g && *rv == v && bytes.len() + prefixed.len() <= max_block =>
            {
                *count += 1;
                bytes.extend_from_slice(&prefixed);
            }
            _ => {
                flush(&mut run, out);
                run = Some((g, v, 1, prefixed));
            }
        }
    }
    flush(&mut run, out);
}
