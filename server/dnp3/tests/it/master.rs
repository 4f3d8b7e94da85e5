//! The master's procedures against a scripted outstation: each test plays
//! the outstation's side octet by octet through the link and transport
//! layers and checks what the master sends and reports.

use std::time::{Duration, Instant};

use gridscada_dnp3::app::{FunctionCode, Iin, RequestHeader, ResponseHeader};
use gridscada_dnp3::link::{self, LinkFrame, LinkFunction};
use gridscada_dnp3::master::{Command, CommandError, CommandMode, Report};
use gridscada_dnp3::objects::{time48, AnalogOutput, CommandStatus, Crob};
use gridscada_dnp3::transport::{self, Reassembler};
use gridscada_dnp3::{Action, Clock, CommandObject, Master, MasterConfig, Value};

const MASTER: u16 = 1;
const OUTSTATION: u16 = 1024;

fn hex(s: &str) -> Vec<u8> {
    s.split_whitespace()
        .map(|b| u8::from_str_radix(b, 16).unwrap())
        .collect()
}

/// The outstation's end of the connection.
struct Outstation {
    master: Master,
    clock: Clock,
    reassembler: Reassembler,
    tseq: u8,
    /// Everything the master did, not yet looked at.
    actions: Vec<Action>,
}

impl Outstation {
    fn new(cfg: MasterConfig) -> Outstation {
        Outstation {
            master: Master::new(cfg),
            clock: Clock {
                mono: Instant::now(),
                unix_ms: 1_700_000_000_000,
            },
            reassembler: Reassembler::default(),
            tseq: 0,
            actions: Vec::new(),
        }
    }

    fn connect(cfg: MasterConfig) -> Outstation {
        let mut o = Outstation::new(cfg);
        let a = o.master.connected(o.clock);
        o.actions.extend(a);
        o
    }

    fn advance(&mut self, d: Duration) {
        self.clock.mono += d;
        self.clock.unix_ms += d.as_millis() as u64;
        let a = self.master.tick(self.clock);
        self.actions.extend(a);
    }

    /// The application fragments the master sent since the last call.
    fn requests(&mut self) -> Vec<Vec<u8>> {
        let mut out = Vec::new();
        for a in &self.actions {
            if let Action::Send(bytes) = a {
                let mut buf = &bytes[..];
                while !buf.is_empty() {
                    let (f, n) = link::decode(buf).unwrap().unwrap();
                    buf = &buf[n..];
                    assert!(f.dir, "DIR set from the master");
                    if f.function != LinkFunction::UnconfirmedUserData {
                        out.push(vec![0xFF, f.function.code()]);
                        continue;
                    }
                    assert_eq!((f.destination, f.source), (OUTSTATION, MASTER));
                    if let Some(apdu) = self.reassembler.push(&f.data).unwrap() {
                        out.push(apdu);
                    }
                }
            }
        }
        self.actions.retain(|a| !matches!(a, Action::Send(_)));
        out
    }

    /// The one request sent: its function and sequence number.
    fn request(&mut self) -> (FunctionCode, u8, Vec<u8>) {
        let r = self.requests();
        assert_eq!(r.len(), 1, "one request expected: {r:02X?}");
        let h = RequestHeader::decode(&r[0]).unwrap();
        (h.function, h.control.seq, r[0].clone())
    }

    fn nothing_sent(&mut self) {
        let r = self.requests();
        assert!(r.is_empty(), "nothing expected, got {r:02X?}");
    }

    /// A fragment as the outstation's link frames.
    fn wire(&mut self, apdu: &[u8]) -> Vec<u8> {
        let mut bytes = Vec::new();
        for seg in transport::segment(apdu, &mut self.tseq) {
            let f = LinkFrame {
                dir: false,
                ..LinkFrame::user_data(MASTER, OUTSTATION, seg)
            };
            bytes.extend(f.encode().unwrap());
        }
        bytes
    }

    /// Octets to the master.
    fn feed(&mut self, bytes: &[u8]) {
        let a = self.master.received(bytes, self.clock);
        self.actions.extend(a);
    }

    /// Send a fragment to the master through transport and link.
    fn send(&mut self, apdu: &[u8]) {
        let bytes = self.wire(apdu);
        self.feed(&bytes);
    }

    /// The connection closes the master asked for, with their reasons.
    fn disconnects(&mut self) -> Vec<String> {
        self.take(|a| match a {
            Action::Disconnect(r) => Some(r.clone()),
            _ => None,
        })
    }

    /// A response with `seq`, IIN, CON and objects.
    fn respond(&mut self, seq: u8, con: bool, iin: Iin, objects: &str) {
        let mut f = vec![0xC0 | (seq & 0x0F) | if con { 0x20 } else { 0 }, 0x81];
        f.extend(iin.0.to_le_bytes());
        f.extend(hex(objects));
        self.send(&f);
    }

    fn take<T>(&mut self, pick: impl Fn(&Action) -> Option<T>) -> Vec<T> {
        let out = self.actions.iter().filter_map(&pick).collect();
        self.actions.retain(|a| pick(a).is_none());
        out
    }

    fn reports(&mut self) -> Vec<Report> {
        self.take(|a| match a {
            Action::Report(r) => Some(r.clone()),
            _ => None,
        })
    }

    fn outcomes(&mut self) -> Vec<(u64, Result<(), CommandError>)> {
        self.take(|a| match a {
            Action::CommandOutcome { id, result } => Some((*id, result.clone())),
            _ => None,
        })
    }

    fn values(&mut self) -> Vec<(u16, Value)> {
        self.take(|a| match a {
            Action::Measurements(m) => {
                Some(m.iter().map(|m| (m.index, m.value)).collect::<Vec<_>>())
            }
            _ => None,
        })
        .concat()
    }

    /// Run the startup sequence with plain answers.
    fn startup(&mut self) {
        let (f, s, _) = self.request();
        assert_eq!(f, FunctionCode::DisableUnsolicited);
        self.respond(s, false, Iin::default(), "");
        let (f, s, _) = self.request();
        assert_eq!(f, FunctionCode::Read);
        self.respond(s, false, Iin::default(), "");
        let (f, s, _) = self.request();
        assert_eq!(f, FunctionCode::EnableUnsolicited);
        self.respond(s, false, Iin::default(), "");
        self.nothing_sent();
        assert!(!self.master.is_busy());
        // The startup's integrity poll is counted complete; the tests look
        // at what comes after.
        assert_eq!(self.reports(), vec![Report::IntegrityPollDone]);
    }
}

fn no_periodic() -> MasterConfig {
    MasterConfig {
        integrity_period: None,
        event_period: None,
        ..MasterConfig::default()
    }
}

#[test]
fn connect_integrity_enable_unsolicited() {
    let mut o = Outstation::connect(no_periodic());
    let (f, seq, apdu) = o.request();
    assert_eq!((f, seq), (FunctionCode::DisableUnsolicited, 0));
    assert_eq!(apdu, hex("C0 15 3C 02 06 3C 03 06 3C 04 06"));
    assert!(o.actions.iter().any(|a| matches!(a, Action::Timer(_))));
    o.respond(0, false, Iin::default(), "");
    let (f, seq, apdu) = o.request();
    assert_eq!((f, seq), (FunctionCode::Read, 1));
    assert_eq!(apdu, hex("C1 01 3C 02 06 3C 03 06 3C 04 06 3C 01 06"));
    // Class 0 with g1v2, g30v1, g20v1; CON asks for a confirmation.
    o.respond(
        1,
        true,
        Iin::default(),
        "01 02 00 00 01 01 81 1E 01 00 03 03 01 D2 04 00 00 14 01 00 00 00 01 0A 00 00 00",
    );
    let sent = o.requests();
    assert_eq!(sent[0], hex("C1 00"), "confirm with the response's seq");
    assert_eq!(
        RequestHeader::decode(&sent[1]).unwrap().function,
        FunctionCode::EnableUnsolicited
    );
    assert_eq!(
        o.values(),
        vec![
            (0, Value::Binary(false)),
            (1, Value::Binary(true)),
            (3, Value::Analog(1234.0)),
            (0, Value::Counter(10)),
        ]
    );
    o.respond(2, false, Iin::default(), "");
    o.nothing_sent();
    // An unsolicited response: confirmed with UNS, its events delivered.
    o.send(&hex("F3 82 00 00 02 01 17 01 05 81"));
    assert_eq!(o.requests(), vec![hex("D3 00")]);
    assert_eq!(o.values(), vec![(5, Value::Binary(true))]);
    // The same one again (our confirm was lost): confirmed, not delivered twice.
    o.send(&hex("F3 82 00 00 02 01 17 01 05 81"));
    assert_eq!(o.requests(), vec![hex("D3 00")]);
    assert!(o.values().is_empty());
}

#[test]
fn a_response_with_the_wrong_seq_is_ignored() {
    let mut o = Outstation::connect(no_periodic());
    let (_, seq, _) = o.request();
    o.respond(seq + 5, false, Iin::default(), "");
    o.nothing_sent();
    assert!(matches!(&o.reports()[..], [Report::Ignored(m)] if m.contains("seq 5")));
    o.respond(seq, false, Iin::default(), "");
    assert_eq!(o.request().0, FunctionCode::Read);
}

#[test]
fn restart_clears_iin_and_polls() {
    let mut o = Outstation::connect(no_periodic());
    o.startup();
    // The outstation restarts: a null unsolicited response with IIN1.7.
    o.send(&hex("F0 82 80 00"));
    let r = o.requests();
    assert_eq!(r[0], hex("D0 00"));
    let h = RequestHeader::decode(&r[1]).unwrap();
    assert_eq!(h.function, FunctionCode::Write);
    assert_eq!(
        &r[1][2..],
        &hex("50 01 00 07 07 00")[..],
        "WRITE g80v1 index 7 = 0"
    );
    assert!(o.reports().contains(&Report::DeviceRestart));
    assert!(o
        .actions
        .iter()
        .any(|a| matches!(a, Action::IinChanged { now, .. } if now.contains(Iin::DEVICE_RESTART))));
    o.respond(h.control.seq, false, Iin::default(), "");
    let (f, s, apdu) = o.request();
    assert_eq!(f, FunctionCode::Read);
    assert_eq!(apdu.len(), 14, "integrity poll");
    o.respond(s, false, Iin::default(), "");
    assert_eq!(o.request().0, FunctionCode::EnableUnsolicited);
}

#[test]
fn need_time_runs_the_lan_time_sync() {
    let mut o = Outstation::connect(no_periodic());
    let (_, s, _) = o.request();
    o.respond(s, false, Iin::NEED_TIME, "");
    let (f, s, _) = o.request();
    assert_eq!(f, FunctionCode::RecordCurrentTime);
    let recorded = o.clock.unix_ms;
    o.advance(Duration::from_millis(30));
    o.respond(s, false, Iin::NEED_TIME, "");
    let (f, s, apdu) = o.request();
    assert_eq!(f, FunctionCode::Write);
    let mut expect = hex("32 03 07 01");
    expect.extend(time48(recorded));
    assert_eq!(
        &apdu[2..],
        &expect[..],
        "WRITE g50v3 with the time of the record request"
    );
    o.respond(s, false, Iin::default(), "");
    assert!(o
        .reports()
        .contains(&Report::TimeSynced { unix_ms: recorded }));
    // Then the startup goes on.
    assert_eq!(o.request().0, FunctionCode::Read);
}

#[test]
fn a_refused_time_sync_is_not_asked_again_until_need_time_clears() {
    let mut o = Outstation::connect(no_periodic());
    let (_, s, _) = o.request();
    o.respond(s, false, Iin::NEED_TIME, "");
    let (f, s, _) = o.request();
    assert_eq!(f, FunctionCode::RecordCurrentTime);
    o.respond(s, false, Iin::NEED_TIME | Iin::NO_FUNC_CODE_SUPPORT, "");
    assert!(matches!(
        &o.reports()[..],
        [Report::Refused {
            task: "time sync",
            ..
        }]
    ));
    let (f, s, apdu) = o.request();
    assert_eq!(
        (f, apdu.len()),
        (FunctionCode::Read, 14),
        "integrity, no new sync"
    );
    o.respond(s, false, Iin::NEED_TIME, "");
    let (f, s, _) = o.request();
    assert_eq!(f, FunctionCode::EnableUnsolicited);
    o.respond(s, false, Iin::default(), "");
    o.nothing_sent();
    // Cleared, then asked for again: a new attempt.
    o.send(&hex("F1 82 10 00"));
    let r = o.requests();
    assert_eq!(r[0], hex("D1 00"));
    assert_eq!(
        RequestHeader::decode(&r[1]).unwrap().function,
        FunctionCode::RecordCurrentTime
    );
}

#[test]
fn without_unsolicited_the_class_bits_call_for_an_event_poll() {
    let mut o = Outstation::connect(no_periodic());
    let (_, s, _) = o.request();
    o.respond(s, false, Iin::default(), "");
    let (_, s, _) = o.request();
    o.respond(s, false, Iin::CLASS1_EVENTS, "");
    let (f, s, _) = o.request();
    assert_eq!(f, FunctionCode::EnableUnsolicited);
    o.respond(s, false, Iin::CLASS1_EVENTS | Iin::NO_FUNC_CODE_SUPPORT, "");
    let (f, s, apdu) = o.request();
    assert_eq!((f, apdu.len()), (FunctionCode::Read, 11), "event poll");
    o.respond(s, true, Iin::default(), "02 01 17 01 00 81");
    assert_eq!(o.requests(), vec![vec![0xC0 | s, 0x00]]);
    assert_eq!(o.values(), vec![(0, Value::Binary(true))]);
}

#[test]
fn event_buffer_overflow_polls_integrity_and_reports() {
    let mut o = Outstation::connect(no_periodic());
    o.startup();
    o.send(&hex("F1 82 00 08"));
    let r = o.requests();
    assert_eq!(r[0], hex("D1 00"));
    assert_eq!(r[1].len(), 14, "integrity poll");
    assert!(o.reports().contains(&Report::EventBufferOverflow));
}

fn crob_echo(index: u16, crob: Crob, status: u8) -> String {
    let mut b = Vec::new();
    CommandObject::Crob(crob).encode(CommandStatus::from_code(status), &mut b);
    let [lo, hi] = index.to_le_bytes();
    format!(
        "0C 01 28 01 00 {lo:02X} {hi:02X} {}",
        b.iter()
            .map(|x| format!("{x:02X}"))
            .collect::<Vec<_>>()
            .join(" ")
    )
}

#[test]
fn select_before_operate() {
    let mut o = Outstation::connect(no_periodic());
    o.startup();
    let crob = Crob::trip_close(true, 500);
    let cmd = Command {
        id: 7,
        index: 3,
        object: CommandObject::Crob(crob),
        mode: CommandMode::SelectBeforeOperate,
    };
    let a = o.master.command(cmd, o.clock);
    o.actions.extend(a);
    let (f, s, apdu) = o.request();
    assert_eq!(f, FunctionCode::Select);
    assert_eq!(&apdu[2..], &hex(&crob_echo(3, crob, 0))[..]);
    o.respond(s, false, Iin::default(), &crob_echo(3, crob, 0));
    let (f, s2, apdu2) = o.request();
    assert_eq!(f, FunctionCode::Operate);
    assert_eq!(s2, (s + 1) % 16);
    assert_eq!(apdu2[2..], apdu[2..], "OPERATE repeats the SELECT's object");
    o.respond(s2, false, Iin::default(), &crob_echo(3, crob, 0));
    assert_eq!(o.outcomes(), vec![(7, Ok(()))]);
}

#[test]
fn without_unsolicited_an_operated_control_fetches_its_returned_status() {
    let mut o = Outstation::connect(MasterConfig {
        enable_unsolicited: false,
        ..no_periodic()
    });
    let (f, s, _) = o.request();
    assert_eq!(f, FunctionCode::DisableUnsolicited);
    o.respond(s, false, Iin::default(), "");
    let (f, s, _) = o.request();
    assert_eq!(f, FunctionCode::Read, "integrity poll");
    o.respond(s, false, Iin::default(), "");
    o.nothing_sent();
    let crob = Crob::latch(true);
    let a = o.master.command(
        Command {
            id: 9,
            index: 0,
            object: CommandObject::Crob(crob),
            mode: CommandMode::DirectOperate,
        },
        o.clock,
    );
    o.actions.extend(a);
    let (f, s, _) = o.request();
    assert_eq!(f, FunctionCode::DirectOperate);
    o.respond(s, false, Iin::default(), &crob_echo(0, crob, 0));
    assert_eq!(o.outcomes(), vec![(9, Ok(()))]);
    // The output's status event is read now, not at the next poll.
    let (f, s, apdu) = o.request();
    assert_eq!((f, apdu.len()), (FunctionCode::Read, 11), "event poll");
    o.respond(s, false, Iin::default(), "0B 01 17 01 00 81");
    assert_eq!(o.values(), vec![(0, Value::Binary(true))]);
    o.nothing_sent();
}

#[test]
fn select_with_a_bad_echo_or_status_fails() {
    let mut o = Outstation::connect(no_periodic());
    o.startup();
    let crob = Crob::latch(true);
    let cmd = Command {
        id: 1,
        index: 3,
        object: CommandObject::Crob(crob),
        mode: CommandMode::SelectBeforeOperate,
    };
    let a = o.master.command(cmd, o.clock);
    o.actions.extend(a);
    let (_, s, _) = o.request();
    // Echo of another index.
    o.respond(s, false, Iin::default(), &crob_echo(4, crob, 0));
    o.nothing_sent();
    let out = o.outcomes();
    assert!(
        matches!(
            &out[..],
            [(
                1,
                Err(CommandError::EchoMismatch {
                    stage: FunctionCode::Select,
                    ..
                })
            )]
        ),
        "{out:?}"
    );
    // Status NO_SELECT on the OPERATE is named.
    let a = o.master.command(Command { id: 2, ..cmd }, o.clock);
    o.actions.extend(a);
    let (_, s, _) = o.request();
    o.respond(s, false, Iin::default(), &crob_echo(3, crob, 0));
    let (f, s, _) = o.request();
    assert_eq!(f, FunctionCode::Operate);
    o.respond(s, false, Iin::default(), &crob_echo(3, crob, 2));
    let out = o.outcomes();
    let Some((2, Err(e))) = out.first() else {
        panic!("{out:?}")
    };
    assert_eq!(e.to_string(), "OPERATE refused: status NO_SELECT (2)");
    // A direct operate refused with IIN2.1 OBJECT_UNKNOWN.
    let a = o.master.command(
        Command {
            id: 3,
            mode: CommandMode::DirectOperate,
            object: CommandObject::Analog(AnalogOutput::F32(2.5)),
            ..cmd
        },
        o.clock,
    );
    o.actions.extend(a);
    let (f, s, _) = o.request();
    assert_eq!(f, FunctionCode::DirectOperate);
    o.respond(s, false, Iin::OBJECT_UNKNOWN, "");
    let out = o.outcomes();
    assert!(
        matches!(&out[..], [(3, Err(CommandError::Iin { .. }))]),
        "{out:?}"
    );
}

#[test]
fn a_late_select_answer_does_not_operate() {
    let mut o = Outstation::connect(MasterConfig {
        select_timeout: Duration::from_secs(2),
        ..no_periodic()
    });
    o.startup();
    let crob = Crob::latch(false);
    let cmd = Command {
        id: 9,
        index: 0,
        object: CommandObject::Crob(crob),
        mode: CommandMode::SelectBeforeOperate,
    };
    let a = o.master.command(cmd, o.clock);
    o.actions.extend(a);
    let (_, s, _) = o.request();
    o.clock.mono += Duration::from_secs(3);
    o.respond(s, false, Iin::default(), &crob_echo(0, crob, 0));
    o.nothing_sent();
    assert!(matches!(
        &o.outcomes()[..],
        [(9, Err(CommandError::SelectExpired { .. }))]
    ));
}

#[test]
fn timeouts_fail_clearly_and_the_queue_goes_on() {
    let mut o = Outstation::connect(no_periodic());
    let (f, _, _) = o.request();
    assert_eq!(f, FunctionCode::DisableUnsolicited);
    // A command waits for the request in flight, then goes before the polls.
    let cmd = Command {
        id: 5,
        index: 1,
        object: CommandObject::Crob(Crob::pulse(true, 1, 100, 100)),
        mode: CommandMode::DirectOperate,
    };
    let a = o.master.command(cmd, o.clock);
    o.actions.extend(a);
    o.nothing_sent();
    o.advance(Duration::from_secs(4));
    o.nothing_sent();
    assert!(o.reports().is_empty());
    o.advance(Duration::from_secs(1));
    let r = o.reports();
    assert_eq!(r.len(), 1);
    assert_eq!(
        r[0].to_string(),
        "no response to DISABLE_UNSOLICITED (disable unsolicited) within 5s"
    );
    let (f, _, _) = o.request();
    assert_eq!(f, FunctionCode::DirectOperate, "commands before polls");
    o.advance(Duration::from_secs(5));
    let out = o.outcomes();
    assert_eq!(
        out,
        vec![(
            5,
            Err(CommandError::Timeout {
                stage: FunctionCode::DirectOperate,
                after: Duration::from_secs(5)
            })
        )]
    );
    assert_eq!(o.request().0, FunctionCode::Read);
}

#[test]
fn periodic_polls_and_multi_fragment_responses() {
    let mut o = Outstation::connect(MasterConfig {
        integrity_period: Some(Duration::from_secs(60)),
        event_period: Some(Duration::from_secs(10)),
        ..MasterConfig::default()
    });
    o.startup();
    o.advance(Duration::from_secs(10));
    let (f, s, apdu) = o.request();
    assert_eq!((f, apdu.len()), (FunctionCode::Read, 11), "event poll");
    // First fragment (FIR, CON) with the request's seq, then the last
    // (FIN, CON) with the next: each confirmed with its own.
    o.send(&hex(&format!(
        "{:02X} 81 00 00 01 02 00 00 00 81",
        0xA0 | s
    )));
    assert_eq!(o.requests(), vec![vec![0xC0 | s, 0x00]]);
    assert!(o.master.is_busy());
    // A repeat of the first fragment is not the one expected.
    o.send(&hex(&format!(
        "{:02X} 81 00 00 01 02 00 00 00 81",
        0xA0 | s
    )));
    o.nothing_sent();
    assert!(matches!(&o.reports()[..], [Report::Ignored(_)]));
    let s2 = (s + 1) % 16;
    o.send(&hex(&format!(
        "{:02X} 81 00 00 01 02 00 01 01 01",
        0x60 | s2
    )));
    assert_eq!(o.requests(), vec![vec![0xC0 | s2, 0x00]]);
    assert!(!o.master.is_busy());
    assert_eq!(
        o.values(),
        vec![(0, Value::Binary(true)), (1, Value::Binary(false))]
    );
    o.advance(Duration::from_secs(50));
    let (f, _, apdu) = o.request();
    assert_eq!((f, apdu.len()), (FunctionCode::Read, 14), "integrity poll");
}

#[test]
fn a_run_of_malformed_frames_closes_the_connection() {
    let mut o = Outstation::connect(no_periodic());
    o.startup();
    // A frame whose data CRC is wrong: discarded and reported.
    let bad_crc = |o: &mut Outstation| {
        let mut b = o.wire(&hex("F0 82 00 00"));
        let n = b.len();
        b[n - 3] ^= 0xFF;
        o.feed(&b);
    };
    bad_crc(&mut o);
    bad_crc(&mut o);
    assert_eq!(o.reports().len(), 2);
    assert!(
        o.disconnects().is_empty(),
        "two are discarded, the connection kept"
    );
    // A well-formed response ends the run.
    o.send(&hex("F1 82 00 00"));
    o.requests();
    bad_crc(&mut o);
    bad_crc(&mut o);
    assert!(o.disconnects().is_empty());
    bad_crc(&mut o);
    let closed = o.disconnects();
    assert!(
        matches!(&closed[..], [r] if r.contains("3 malformed frames in a row") && r.contains("link layer")),
        "{closed:?}"
    );
    assert!(o
        .reports()
        .iter()
        .all(|r| matches!(r, Report::Malformed(_))));

    // Fragments whose objects are cut short (two binary events announced,
    // one present) are malformed too.
    let mut o = Outstation::connect(no_periodic());
    o.startup();
    for seq in 1..=3u8 {
        o.send(&hex(&format!(
            "{:02X} 82 00 00 02 01 00 00 01 81",
            0xF0 | seq
        )));
    }
    let closed = o.disconnects();
    assert!(
        matches!(&closed[..], [r] if r.contains("objects")),
        "{closed:?}"
    );
}

#[test]
fn a_failed_integrity_poll_is_tried_again() {
    let mut o = Outstation::connect(MasterConfig {
        enable_unsolicited: false,
        ..no_periodic()
    });
    let (f, s, _) = o.request();
    assert_eq!(f, FunctionCode::DisableUnsolicited);
    o.respond(s, false, Iin::default(), "");
    let (f, _, apdu) = o.request();
    assert_eq!((f, apdu.len()), (FunctionCode::Read, 14), "integrity poll");
    // No answer: after the response timeout and the retry delay, again.
    o.advance(Duration::from_secs(5));
    assert!(matches!(&o.reports()[..], [Report::ResponseTimeout { .. }]));
    o.nothing_sent();
    o.advance(Duration::from_secs(5));
    let (f, s, apdu) = o.request();
    assert_eq!(
        (f, apdu.len()),
        (FunctionCode::Read, 14),
        "integrity poll again"
    );
    // Answered with objects cut short (two binaries announced, one
    // there): malformed, nothing of it used or confirmed, tried again.
    let before = o.master.discarded_octets();
    o.respond(s, true, Iin::default(), "01 02 00 00 01 81");
    assert!(
        o.values().is_empty(),
        "nothing of a malformed response is used"
    );
    o.nothing_sent();
    assert!(o.master.discarded_octets() > before);
    o.advance(Duration::from_secs(5));
    let (f, s, apdu) = o.request();
    assert_eq!(
        (f, apdu.len()),
        (FunctionCode::Read, 14),
        "integrity poll once more"
    );
    o.respond(s, false, Iin::default(), "01 02 00 00 01 81 01");
    assert_eq!(
        o.values(),
        vec![(0, Value::Binary(true)), (1, Value::Binary(false))]
    );
    // Done: no more retries.
    o.advance(Duration::from_secs(30));
    o.nothing_sent();
}

#[test]
fn garbage_is_not_the_outstation_answering() {
    let mut o = Outstation::connect(no_periodic());
    o.startup();
    let heard = o.master.frames_heard();
    o.feed(&hex("00 11 22 33 44 55"));
    assert_eq!(o.master.frames_heard(), heard);
    assert_eq!(o.master.discarded_octets(), 6);
    o.send(&hex("F0 82 00 00"));
    assert_eq!(o.master.frames_heard(), heard + 1);
}

#[test]
fn link_services_and_garbage() {
    let mut o = Outstation::connect(no_periodic());
    o.requests();
    let status = LinkFrame::header_only(false, LinkFunction::RequestLinkStatus, MASTER, OUTSTATION)
        .encode()
        .unwrap();
    let mut bytes = hex("00 11 22");
    bytes.extend(&status);
    let a = o.master.received(&bytes, o.clock);
    o.actions.extend(a);
    assert_eq!(
        o.requests(),
        vec![vec![0xFF, LinkFunction::LinkStatus.code()]]
    );
    assert!(matches!(&o.reports()[..], [Report::Malformed(m)] if m.contains("garbage")));
    // A frame for another master is ignored.
    let other = LinkFrame::header_only(false, LinkFunction::TestLink, 2, OUTSTATION)
        .encode()
        .unwrap();
    let a = o.master.received(&other, o.clock);
    o.actions.extend(a);
    o.nothing_sent();
    assert!(matches!(&o.reports()[..], [Report::Ignored(_)]));
    // Not connected: a command fails at once.
    let mut m = Master::new(no_periodic());
    let out = m.command(
        Command {
            id: 1,
            index: 0,
            object: CommandObject::Crob(Crob::latch(true)),
            mode: CommandMode::DirectOperate,
        },
        o.clock,
    );
    assert_eq!(
        out,
        vec![Action::CommandOutcome {
            id: 1,
            result: Err(CommandError::NotConnected)
        }]
    );
    let _ = ResponseHeader::LEN;
}
