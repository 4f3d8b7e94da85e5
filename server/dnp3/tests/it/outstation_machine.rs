//! The outstation machine against the master machine, in memory: every
//! octet one sends the other decodes, so the two agree on the wire format
//! of static and event objects, confirmations, unsolicited responses,
//! multi-fragment responses and select-before-operate. (Each is also
//! tested against independent peers: the master against dnp3py and
//! py1815, the outstation's objects through the master's parser, which
//! those peers' objects exercise.)

use std::time::{Duration, Instant};

use gridscada_dnp3::master::{Command, CommandError, CommandMode, Report};
use gridscada_dnp3::objects::{
    CommandObject, CommandStatus, Crob, DoubleBit, MeasurementKind, Value,
};
use gridscada_dnp3::outstation::{
    Outstation, OutstationAction, OutstationConfig, Point, PointValue,
};
use gridscada_dnp3::{Action, Clock, Master, MasterConfig};

struct Pair {
    master: Master,
    os: Outstation,
    now: Instant,
    unix_ms: u64,
    values: Vec<(MeasurementKind, u16, Value, Option<u64>, bool)>,
    outcomes: Vec<(u64, Result<(), CommandError>)>,
    reports: Vec<Report>,
    operated: Vec<(u16, CommandObject)>,
    /// The status the "field" gives each operated control.
    field_status: CommandStatus,
}

fn point(kind: MeasurementKind, index: u16) -> Point {
    Point {
        kind,
        index,
        integer: false,
    }
}

impl Pair {
    fn new(points: Vec<Point>, max_fragment: usize) -> Pair {
        Pair::with(
            points,
            OutstationConfig {
                max_fragment,
                ..OutstationConfig::default()
            },
        )
    }

    fn with(points: Vec<Point>, cfg: OutstationConfig) -> Pair {
        let os = Outstation::new(cfg, points, [0, 1], [0]);
        let master = Master::new(MasterConfig {
            integrity_period: None,
            event_period: None,
            ..MasterConfig::default()
        });
        Pair {
            master,
            os,
            now: Instant::now(),
            unix_ms: 1_700_000_000_000,
            values: Vec::new(),
            outcomes: Vec::new(),
            reports: Vec::new(),
            operated: Vec::new(),
            field_status: CommandStatus::Success,
        }
    }

    fn clock(&self) -> Clock {
        Clock {
            mono: self.now,
            unix_ms: self.unix_ms,
        }
    }

    fn connect(&mut self) {
        self.os.connected();
        let a = self.master.connected(self.clock());
        self.carry_master(a);
    }

    /// Everything the master does, carried to the outstation and back
    /// until both are quiet.
    fn carry_master(&mut self, actions: Vec<Action>) {
        let mut to_os: Vec<Vec<u8>> = Vec::new();
        for a in actions {
            match a {
                Action::Send(b) => to_os.push(b),
                Action::Measurements(ms) => self.values.extend(
                    ms.iter()
                        .map(|m| (m.kind, m.index, m.value, m.time, m.is_event)),
                ),
                Action::CommandOutcome { id, result } => self.outcomes.push((id, result)),
                Action::Report(r) => self.reports.push(r),
                Action::IinChanged { .. } | Action::Timer(_) => {}
                Action::Disconnect(r) => panic!("the master dropped the outstation: {r}"),
            }
        }
        for b in to_os {
            let a = self.os.received(&b, self.now);
            self.carry_outstation(a);
        }
    }

    fn carry_outstation(&mut self, actions: Vec<OutstationAction>) {
        for a in actions {
            match a {
                OutstationAction::Send(b) => {
                    let a = self.master.received(&b, self.clock());
                    self.carry_master(a);
                }
                OutstationAction::Operate {
                    seq,
                    commands,
                    request,
                    respond,
                    ..
                } => {
                    self.operated.extend(commands.iter().copied());
                    let statuses = vec![self.field_status; commands.len()];
                    let a = self.os.operated(seq, &request, &statuses, respond);
                    self.carry_outstation(a);
                }
                OutstationAction::TimeSet(_) | OutstationAction::Timer(_) => {}
            }
        }
    }

    fn update(&mut self, kind: MeasurementKind, index: u16, value: PointValue, time_ms: u64) {
        let a = self.os.update(kind, index, value, true, time_ms, self.now);
        self.carry_outstation(a);
    }

    fn command(&mut self, id: u64, index: u16, object: CommandObject, mode: CommandMode) {
        let a = self.master.command(
            Command {
                id,
                index,
                object,
                mode,
            },
            self.clock(),
        );
        self.carry_master(a);
    }
}

#[test]
fn integrity_poll_restart_clear_and_unsolicited_events() {
    let mut p = Pair::new(
        vec![
            point(MeasurementKind::Binary, 0),
            point(MeasurementKind::Binary, 1),
            point(MeasurementKind::DoubleBit, 0),
            point(MeasurementKind::BinaryOutputStatus, 0),
            point(MeasurementKind::Counter, 0),
            point(MeasurementKind::Analog, 0),
            Point {
                kind: MeasurementKind::Analog,
                index: 1,
                integer: true,
            },
            point(MeasurementKind::AnalogOutputStatus, 0),
        ],
        2048,
    );
    for (k, i, v) in [
        (MeasurementKind::Binary, 1, PointValue::Binary(true)),
        (
            MeasurementKind::DoubleBit,
            0,
            PointValue::DoubleBit(DoubleBit::On),
        ),
        (MeasurementKind::Counter, 0, PointValue::Counter(1234)),
        (MeasurementKind::Analog, 0, PointValue::Analog(230.5)),
        (MeasurementKind::Analog, 1, PointValue::Analog(-17.0)),
        (
            MeasurementKind::AnalogOutputStatus,
            0,
            PointValue::Analog(12.25),
        ),
        (MeasurementKind::Binary, 0, PointValue::Binary(false)),
        (
            MeasurementKind::BinaryOutputStatus,
            0,
            PointValue::Binary(true),
        ),
    ] {
        p.update(k, i, v, 1_700_000_000_000);
    }
    p.connect();
    // The restart bit was cleared by the master's WRITE.
    assert!(!p.os.iin().contains(gridscada_dnp3::Iin::DEVICE_RESTART));
    let statics: Vec<_> = p.values.iter().filter(|v| !v.4).collect();
    let find = |k: MeasurementKind, i: u16| {
        statics
            .iter()
            .rev()
            .find(|v| v.0 == k && v.1 == i)
            .map(|v| v.2)
    };
    assert_eq!(find(MeasurementKind::Binary, 1), Some(Value::Binary(true)));
    assert_eq!(find(MeasurementKind::Binary, 0), Some(Value::Binary(false)));
    assert_eq!(
        find(MeasurementKind::DoubleBit, 0),
        Some(Value::DoubleBit(DoubleBit::On))
    );
    assert_eq!(
        find(MeasurementKind::BinaryOutputStatus, 0),
        Some(Value::Binary(true))
    );
    assert_eq!(
        find(MeasurementKind::Counter, 0),
        Some(Value::Counter(1234))
    );
    assert_eq!(find(MeasurementKind::Analog, 0), Some(Value::Analog(230.5)));
    assert_eq!(find(MeasurementKind::Analog, 1), Some(Value::Analog(-17.0)));
    assert_eq!(
        find(MeasurementKind::AnalogOutputStatus, 0),
        Some(Value::Analog(12.25))
    );
    // The events of before the connection were read by the integrity poll
    // (class 1) and confirmed: none is left.
    assert!(!p.os.iin().contains(gridscada_dnp3::Iin::CLASS1_EVENTS));

    // A change: sent unsolicited with its time, confirmed.
    p.values.clear();
    p.update(
        MeasurementKind::DoubleBit,
        0,
        PointValue::DoubleBit(DoubleBit::Off),
        1_700_000_123_456,
    );
    assert_eq!(
        p.values,
        vec![(
            MeasurementKind::DoubleBit,
            0,
            Value::DoubleBit(DoubleBit::Off),
            Some(1_700_000_123_456),
            true
        )]
    );
    assert!(!p.os.iin().contains(gridscada_dnp3::Iin::CLASS1_EVENTS));
    // The same value again is no event.
    p.values.clear();
    p.update(
        MeasurementKind::DoubleBit,
        0,
        PointValue::DoubleBit(DoubleBit::Off),
        1_700_000_123_999,
    );
    assert!(p.values.is_empty());
}

#[test]
fn an_integrity_response_in_several_fragments() {
    let points: Vec<Point> = (0..600)
        .map(|i| point(MeasurementKind::Analog, i))
        .collect();
    let mut p = Pair::new(points, 600);
    for i in 0..600u16 {
        p.update(
            MeasurementKind::Analog,
            i,
            PointValue::Analog(f64::from(i) + 0.5),
            1_700_000_000_000,
        );
    }
    p.connect();
    let mut seen: Vec<(u16, f64)> = p
        .values
        .iter()
        .filter(|v| !v.4)
        .filter_map(|v| match v.2 {
            Value::Analog(a) => Some((v.1, a)),
            _ => None,
        })
        .collect();
    seen.sort_by_key(|v| v.0);
    seen.dedup_by_key(|v| v.0);
    assert_eq!(seen.len(), 600, "{:?}", p.reports);
    assert!(seen.iter().all(|(i, a)| *a == f64::from(*i) + 0.5));
}

#[test]
fn select_before_operate_direct_operate_and_refusals() {
    let mut p = Pair::new(vec![point(MeasurementKind::Binary, 0)], 2048);
    p.connect();
    let close = CommandObject::Crob(Crob::trip_close(true, 500));
    p.command(1, 0, close, CommandMode::SelectBeforeOperate);
    assert_eq!(p.outcomes, vec![(1, Ok(()))]);
    assert_eq!(p.operated, vec![(0, close)]);

    let set = CommandObject::Analog(gridscada_dnp3::objects::AnalogOutput::F32(42.5));
    p.command(2, 0, set, CommandMode::DirectOperate);
    assert_eq!(p.outcomes[1], (2, Ok(())));

    // An index with no control: refused at the SELECT, never operated.
    p.operated.clear();
    p.command(3, 7, close, CommandMode::SelectBeforeOperate);
    let (id, r) = &p.outcomes[2];
    assert_eq!(*id, 3);
    assert!(
        r.as_ref()
            .unwrap_err()
            .to_string()
            .contains("NOT_SUPPORTED"),
        "{r:?}"
    );
    assert!(p.operated.is_empty());

    // The field refuses: the status reaches the master.
    p.field_status = CommandStatus::Local;
    p.command(4, 1, close, CommandMode::DirectOperate);
    let (_, r) = &p.outcomes[3];
    assert!(
        r.as_ref().unwrap_err().to_string().contains("LOCAL"),
        "{r:?}"
    );
}

#[test]
fn an_operate_without_its_select_is_refused() {
    let mut os = Outstation::new(OutstationConfig::default(), [], [0], []);
    os.connected();
    let now = Instant::now();
    let crob = CommandObject::Crob(Crob::latch(true));
    let operate =
        gridscada_dnp3::request::command(5, gridscada_dnp3::FunctionCode::Operate, 0, crob);
    let out = os.received(&from_master(&operate), now + Duration::from_millis(1));
    assert!(
        !out.iter()
            .any(|a| matches!(a, OutstationAction::Operate { .. })),
        "{out:?}"
    );
    let objects = gridscada_dnp3::objects::parse(&response_objects(&out), 4);
    assert_eq!(objects.commands[0].status, CommandStatus::NoSelect);
}

/// A request as the master's link frames (master 1 to outstation 1024).
fn from_master(request: &[u8]) -> Vec<u8> {
    let mut tseq = 0;
    gridscada_dnp3::transport::segment(request, &mut tseq)
        .into_iter()
        .flat_map(|seg| {
            gridscada_dnp3::LinkFrame::user_data(1024, 1, seg)
                .encode()
                .unwrap()
        })
        .collect()
}

/// The frames an outstation sent: the first fragment's objects.
fn response_objects(out: &[OutstationAction]) -> Vec<u8> {
    let sent: Vec<u8> = out
        .iter()
        .filter_map(|a| match a {
            OutstationAction::Send(b) => Some(b.clone()),
            _ => None,
        })
        .flatten()
        .collect();
    let (frame, _) = gridscada_dnp3::link::decode(&sent).unwrap().unwrap();
    frame.data[1 + 4..].to_vec()
}

#[test]
fn the_echo_repeats_the_request_with_its_qualifier_and_headers() {
    let mut os = Outstation::new(OutstationConfig::default(), [], [0], []);
    os.connected();
    // SELECT of two CROBs under one header, one-octet count and indices
    // (qualifier 0x17), as some masters send them; index 5 has no control.
    let crob = "03 01 00 00 00 00 00 00 00 00 00";
    let objects = format!("0C 01 17 02 00 {crob} 05 {crob}");
    let select =
        gridscada_dnp3::request::fragment(3, gridscada_dnp3::FunctionCode::Select, &hex(&objects));
    let echo = response_objects(&os.received(&from_master(&select), Instant::now()));
    let mut want = hex(&objects);
    // The second control's status octet: NOT_SUPPORTED (4).
    let last = want.len() - 1;
    want[last] = 4;
    assert_eq!(echo, want, "the echo is the request with its statuses");
}

fn hex(s: &str) -> Vec<u8> {
    s.split_whitespace()
        .map(|b| u8::from_str_radix(b, 16).unwrap())
        .collect()
}

#[test]
fn an_analog_deadband_holds_back_small_moves_only() {
    let mut p = Pair::with(
        vec![point(MeasurementKind::Analog, 0)],
        OutstationConfig {
            analog_deadband: 0.01,
            ..OutstationConfig::default()
        },
    );
    p.update(MeasurementKind::Analog, 0, PointValue::Analog(230.0), 1);
    p.connect();
    p.values.clear();
    let events =
        |p: &Pair| -> Vec<Value> { p.values.iter().filter(|v| v.4).map(|v| v.2).collect() };
    // 1 V of 230 V is under 1 %: no event.
    p.update(MeasurementKind::Analog, 0, PointValue::Analog(231.0), 2);
    assert!(events(&p).is_empty());
    // 3 V past the last reported 230 V: an event.
    p.update(MeasurementKind::Analog, 0, PointValue::Analog(233.0), 3);
    assert_eq!(events(&p), vec![Value::Analog(233.0)]);
    // The static value follows every move.
    p.update(MeasurementKind::Analog, 0, PointValue::Analog(233.5), 4);
    p.values.clear();
    let a = p.master.integrity_poll(p.clock());
    p.carry_master(a);
    assert!(
        p.values.iter().any(|v| !v.4 && v.2 == Value::Analog(233.5)),
        "{:?}",
        p.values
    );
}
