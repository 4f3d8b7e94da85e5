//! The ISA-18.2 state model of the pure alarm set: every transition, delays,
//! deadband, shelving, out of service, suppression, messages, comm and system
//! alarms. No I/O: samples and times are passed in.

use std::time::Duration;

use gridscada_alarms::{
    AlarmDef, AlarmFilter, AlarmId, AlarmKind, AlarmMatch, AlarmSet, AlarmState, Condition,
    EventType, Outputs, SuppressionRule, TransitionCause,
};
use gridscada_tagdb::{Quality, Sample, Timestamp, Value};

fn ts(s: f64) -> Timestamp {
    Timestamp::from_millis((s * 1000.0) as i64)
}

fn good(v: impl Into<Value>, t: f64) -> Sample {
    Sample::good(v, ts(t))
}

fn limit(tag: &str, kind: AlarmKind, limit: f64, deadband: f64, on: f64, off: f64) -> AlarmDef {
    let condition = match kind {
        AlarmKind::Hi | AlarmKind::HiHi => Condition::Above { limit, deadband },
        _ => Condition::Below { limit, deadband },
    };
    AlarmDef {
        key: format!("{tag}:{kind}"),
        tag: Some(tag.into()),
        kind,
        priority: 600,
        selection: "SS1".into(),
        message: "{tag} {value} {units} (limit {limit} {units})".into(),
        units: "V".into(),
        device: Some("SS1.PA".into()),
        states: None,
        decimals: None,
        condition,
        on_delay: Duration::from_secs_f64(on),
        off_delay: Duration::from_secs_f64(off),
    }
}

fn discrete(tag: &str, when: Value, priority: u32) -> AlarmDef {
    AlarmDef {
        key: format!("{tag}:discrete"),
        tag: Some(tag.into()),
        kind: AlarmKind::Discrete,
        priority,
        selection: tag.split('.').next().unwrap().into(),
        message: "{tag} is {value}".into(),
        units: String::new(),
        device: Some("SS1.IO1".into()),
        states: None,
        decimals: None,
        condition: Condition::Equals(when),
        on_delay: Duration::ZERO,
        off_delay: Duration::ZERO,
    }
}

fn comm(device: &str) -> AlarmDef {
    AlarmDef {
        key: format!("{device}:comm"),
        tag: Some(format!("{device}.Comm.Connected")),
        kind: AlarmKind::CommFail,
        priority: 800,
        selection: "SS1".into(),
        message: "Communication lost with {device}: {error}".into(),
        units: String::new(),
        device: Some(device.into()),
        states: None,
        decimals: None,
        condition: Condition::CommLost,
        on_delay: Duration::ZERO,
        off_delay: Duration::ZERO,
    }
}

struct Rig {
    set: AlarmSet,
    out: Outputs,
}

impl Rig {
    fn new(defs: Vec<AlarmDef>) -> Self {
        Rig::with_rules(defs, vec![])
    }
    fn with_rules(defs: Vec<AlarmDef>, rules: Vec<SuppressionRule>) -> Self {
        Rig {
            set: AlarmSet::new(defs, rules).unwrap(),
            out: Outputs::default(),
        }
    }
    fn feed(&mut self, tag: &str, v: impl Into<Value>, t: f64) {
        assert!(self.set.apply_tag(tag, &good(v, t), ts(t), &mut self.out));
    }
    fn tick(&mut self, t: f64) {
        self.set.tick(ts(t), &mut self.out);
    }
    fn state(&self, key: &str) -> AlarmState {
        self.set.view(self.id(key)).unwrap().state
    }
    fn id(&self, key: &str) -> AlarmId {
        self.set.id_of(key).unwrap()
    }
    /// The (cause, from, to) of the transitions since the last call.
    fn take(&mut self) -> Vec<(TransitionCause, AlarmState, AlarmState)> {
        let v = self
            .out
            .transitions
            .iter()
            .map(|t| (t.cause, t.from, t.to))
            .collect();
        self.out.clear();
        v
    }
}

use AlarmState::*;
use TransitionCause as C;

const V: &str = "SS1.PA.V_L1";
const HI: &str = "SS1.PA.V_L1:hi";

#[test]
fn activate_ack_return() {
    let mut r = Rig::new(vec![limit(V, AlarmKind::Hi, 253.0, 0.0, 0.0, 0.0)]);
    r.feed(V, 230.0, 1.0);
    assert_eq!(r.take(), vec![]);
    r.feed(V, 260.0, 2.0);
    assert_eq!(r.take(), vec![(C::Activate, Normal, UnackActive)]);
    assert!(r.set.ack(r.id(HI), "alice", ts(3.0), &mut r.out).unwrap());
    let t = r.out.transitions[0].clone();
    assert_eq!(t.user.as_deref(), Some("alice"));
    assert_eq!(r.out.events[0].kind, EventType::Ack);
    assert_eq!(r.take(), vec![(C::Ack, UnackActive, AckActive)]);
    // Acking again: nothing waits for it.
    assert!(!r.set.ack(r.id(HI), "alice", ts(3.5), &mut r.out).unwrap());
    r.feed(V, 240.0, 4.0);
    assert_eq!(r.take(), vec![(C::Return, AckActive, Normal)]);
}

#[test]
fn return_before_ack_then_ack_and_realarm_from_rtn() {
    let mut r = Rig::new(vec![limit(V, AlarmKind::Hi, 253.0, 0.0, 0.0, 0.0)]);
    r.feed(V, 260.0, 1.0);
    r.feed(V, 240.0, 2.0);
    assert_eq!(
        r.take(),
        vec![
            (C::Activate, Normal, UnackActive),
            (C::Return, UnackActive, UnackRtn)
        ]
    );
    // Re-alarm from RTN.
    r.feed(V, 261.0, 3.0);
    assert_eq!(r.take(), vec![(C::Activate, UnackRtn, UnackActive)]);
    r.feed(V, 240.0, 4.0);
    r.take();
    r.set.ack(r.id(HI), "bob", ts(5.0), &mut r.out).unwrap();
    assert_eq!(r.take(), vec![(C::Ack, UnackRtn, Normal)]);
}

/// A cleared alarm keeps its activation time, and shows when it cleared;
/// both survive a restart while the return waits for its acknowledgement.
#[test]
fn a_cleared_alarm_keeps_its_activation_time_and_shows_its_clear_time() {
    let mut r = Rig::new(vec![limit(V, AlarmKind::Hi, 253.0, 0.0, 0.0, 0.0)]);
    r.feed(V, 260.0, 1.0);
    let v = r.set.view(r.id(HI)).unwrap();
    assert_eq!((v.activated_at, v.cleared_at), (Some(ts(1.0)), None));
    r.feed(V, 240.0, 7.0);
    let v = r.set.view(r.id(HI)).unwrap();
    assert_eq!(v.state, UnackRtn);
    assert_eq!(v.active_since, None);
    assert_eq!(
        (v.activated_at, v.cleared_at),
        (Some(ts(1.0)), Some(ts(7.0)))
    );
    let mut r2 = Rig::new(vec![limit(V, AlarmKind::Hi, 253.0, 0.0, 0.0, 0.0)]);
    r2.set.restore(&r.set.records());
    let v = r2.set.view(r2.id(HI)).unwrap();
    assert_eq!(v.state, UnackRtn);
    assert_eq!(
        (v.activated_at, v.cleared_at),
        (Some(ts(1.0)), Some(ts(7.0)))
    );
    // Active again: a new activation time, no clear time.
    r2.feed(V, 261.0, 9.0);
    let v = r2.set.view(r2.id(HI)).unwrap();
    assert_eq!((v.activated_at, v.cleared_at), (Some(ts(9.0)), None));
}

#[test]
fn transitions_carry_value_limit_and_substituted_message() {
    let mut r = Rig::new(vec![limit(V, AlarmKind::Lo, 207.0, 2.0, 0.0, 0.0)]);
    r.feed(V, 203.456, 1.0);
    let t = &r.out.transitions[0];
    assert_eq!(t.value, Some(Value::Float(203.456)));
    assert_eq!(t.limit, Some(Value::Float(207.0)));
    assert_eq!(t.message, "SS1.PA.V_L1 203.46 V (limit 207 V)");
    assert_eq!(t.time, ts(1.0));
    assert_eq!(t.priority, 600);
    assert_eq!(t.selection, "SS1");
    assert!(t.user.is_none());
    assert!(t.is_annunciated_activation());
}

#[test]
fn deadband_holds_until_value_comes_back_past_it() {
    let mut r = Rig::new(vec![limit(V, AlarmKind::Hi, 253.0, 2.0, 0.0, 0.0)]);
    r.feed(V, 254.0, 1.0);
    r.take();
    r.feed(V, 252.0, 2.0); // below the limit, inside the deadband
    assert_eq!(r.state(HI), UnackActive);
    r.feed(V, 251.0, 3.0); // exactly limit - deadband: clears
    assert_eq!(r.take(), vec![(C::Return, UnackActive, UnackRtn)]);
    r.feed(V, 253.0, 4.0); // at the limit: not above it
    assert_eq!(r.state(HI), UnackRtn);
    // Low alarm mirrors it.
    let lo = "SS1.PA.V_L1:lo";
    let mut r = Rig::new(vec![limit(V, AlarmKind::Lo, 207.0, 2.0, 0.0, 0.0)]);
    r.feed(V, 206.0, 1.0);
    r.feed(V, 208.5, 2.0);
    assert_eq!(r.state(lo), UnackActive);
    r.feed(V, 209.0, 3.0);
    assert_eq!(r.state(lo), UnackRtn);
}

#[test]
fn on_delay_requires_the_condition_to_hold() {
    let mut r = Rig::new(vec![limit(V, AlarmKind::Hi, 253.0, 0.0, 5.0, 0.0)]);
    r.feed(V, 260.0, 10.0);
    assert_eq!(r.state(HI), Normal);
    assert_eq!(r.set.next_deadline(), Some(ts(15.0)));
    r.tick(14.9);
    assert_eq!(r.state(HI), Normal);
    // Dips back before the delay: the delay restarts.
    r.feed(V, 250.0, 14.95);
    r.tick(15.0);
    assert_eq!(r.state(HI), Normal);
    r.feed(V, 260.0, 16.0);
    r.tick(20.9);
    assert_eq!(r.state(HI), Normal);
    r.tick(21.0);
    assert_eq!(r.take(), vec![(C::Activate, Normal, UnackActive)]);
    assert_eq!(r.out.transitions.len(), 0);
    assert_eq!(r.set.view(r.id(HI)).unwrap().active_since, Some(ts(21.0)));
}

#[test]
fn off_delay_requires_the_clear_to_hold() {
    let mut r = Rig::new(vec![limit(V, AlarmKind::Hi, 253.0, 0.0, 0.0, 3.0)]);
    r.feed(V, 260.0, 0.0);
    r.take();
    r.feed(V, 240.0, 1.0);
    r.tick(3.9);
    assert_eq!(r.state(HI), UnackActive);
    // A later sample after the delay also completes it (no tick needed).
    r.feed(V, 241.0, 4.0);
    assert_eq!(r.take(), vec![(C::Return, UnackActive, UnackRtn)]);
}

#[test]
fn bad_quality_holds_state_and_restarts_delays() {
    let mut r = Rig::new(vec![limit(V, AlarmKind::Hi, 253.0, 0.0, 5.0, 0.0)]);
    r.feed(V, 260.0, 0.0);
    let bad = Sample {
        value: Value::Float(0.0),
        quality: Quality::bad("device offline"),
        timestamp: ts(2.0),
    };
    r.set.apply_tag(V, &bad, ts(2.0), &mut r.out);
    r.tick(5.0);
    assert_eq!(
        r.state(HI),
        Normal,
        "the delay must not run across bad data"
    );
    r.feed(V, 260.0, 6.0);
    r.tick(11.0);
    assert_eq!(r.state(HI), UnackActive);
    // Bad data while active: stays active (the comm alarm covers it).
    r.set.apply_tag(V, &bad, ts(12.0), &mut r.out);
    assert_eq!(r.state(HI), UnackActive);
    // NaN and strings are not judged either.
    r.feed(V, f64::NAN, 13.0);
    r.feed(V, "garbage", 14.0);
    assert_eq!(r.state(HI), UnackActive);
}

#[test]
fn shelving_hides_and_expiry_returns_to_the_right_state() {
    let mut r = Rig::new(vec![limit(V, AlarmKind::Hi, 253.0, 0.0, 0.0, 0.0)]);
    let id = r.id(HI);
    r.feed(V, 260.0, 0.0);
    r.take();
    let until = r
        .set
        .shelve(
            id,
            "sue",
            Duration::from_secs(600),
            "sensor fault",
            ts(1.0),
            &mut r.out,
        )
        .unwrap();
    assert_eq!(until, ts(601.0));
    assert_eq!(r.out.events[0].kind, EventType::Shelve);
    assert_eq!(r.out.events[0].user.as_deref(), Some("sue"));
    assert_eq!(r.take(), vec![(C::Shelve, UnackActive, Shelved)]);
    let v = r.set.view(id).unwrap();
    assert_eq!(v.shelved.as_ref().unwrap().reason, "sensor fault");
    assert!(v.acked, "shelving discards the pending ack");
    assert!(r.set.summary(&AlarmFilter::default()).is_empty());
    let shelved = AlarmFilter {
        states: vec![Shelved],
        ..Default::default()
    };
    assert_eq!(r.set.summary(&shelved).len(), 1);
    // Process changes while shelved are tracked, not annunciated.
    r.feed(V, 240.0, 10.0);
    r.feed(V, 262.0, 20.0);
    let t = r.out.transitions.last().unwrap().clone();
    assert_eq!(
        (t.cause, t.from, t.to, t.active, t.annunciated),
        (C::Activate, Shelved, Shelved, true, false)
    );
    r.take();
    assert_eq!(r.set.next_deadline(), Some(ts(601.0)));
    r.tick(600.0);
    assert_eq!(r.state(HI), Shelved);
    r.tick(601.0);
    // Still active at expiry: annunciated again as unacknowledged.
    assert_eq!(r.out.events[0].kind, EventType::Unshelve);
    assert!(r.out.events[0].user.is_none());
    assert_eq!(r.take(), vec![(C::ShelveExpired, Shelved, UnackActive)]);

    // Shelved while active, cleared meanwhile: unshelve goes to Normal.
    r.set
        .shelve(
            id,
            "sue",
            Duration::from_secs(60),
            "x",
            ts(700.0),
            &mut r.out,
        )
        .unwrap();
    r.feed(V, 240.0, 710.0);
    r.take();
    r.set.unshelve(id, "sue", ts(720.0), &mut r.out).unwrap();
    assert_eq!(r.take(), vec![(C::Unshelve, Shelved, Normal)]);
    assert!(r.set.unshelve(id, "sue", ts(721.0), &mut r.out).is_err());
}

#[test]
fn shelve_checks_its_arguments() {
    let mut r = Rig::new(vec![limit(V, AlarmKind::Hi, 253.0, 0.0, 0.0, 0.0)]);
    let id = r.id(HI);
    let mut out = Outputs::default();
    let d = Duration::from_secs(60);
    assert!(r.set.shelve(id, "sue", d, "  ", ts(0.0), &mut out).is_err());
    assert!(r.set.shelve(id, "", d, "why", ts(0.0), &mut out).is_err());
    assert!(r
        .set
        .shelve(id, "sue", Duration::ZERO, "why", ts(0.0), &mut out)
        .is_err());
    assert!(r
        .set
        .shelve(
            id,
            "sue",
            Duration::from_secs(8 * 24 * 3600),
            "why",
            ts(0.0),
            &mut out
        )
        .is_err());
    assert!(r
        .set
        .shelve(AlarmId(99), "sue", d, "why", ts(0.0), &mut out)
        .is_err());
    // A reason the store could not keep is refused before anything changes
    // (it used to shelve, then fail to persist, losing the audit record).
    let long = "x".repeat(9000);
    let err = r
        .set
        .shelve(id, "sue", d, &long, ts(0.0), &mut out)
        .unwrap_err();
    assert!(err.to_string().contains("at most 2048"), "{err}");
    assert!(r
        .set
        .shelve(id, "sue", d, "line\nbreak", ts(0.0), &mut out)
        .is_err());
    assert!(r
        .set
        .set_out_of_service(id, "sue", true, &long, None, ts(0.0), &mut out)
        .is_err());
    assert!(out.transitions.is_empty() && out.events.is_empty());
}

#[test]
fn out_of_service_hides_until_returned() {
    let mut r = Rig::new(vec![limit(V, AlarmKind::Hi, 253.0, 0.0, 0.0, 0.0)]);
    let id = r.id(HI);
    assert!(
        r.set
            .set_out_of_service(id, "tech", true, "", None, ts(0.0), &mut r.out)
            .is_err(),
        "a reason is required"
    );
    assert!(r
        .set
        .set_out_of_service(id, "tech", true, "calibration", None, ts(0.0), &mut r.out)
        .unwrap());
    assert_eq!(r.out.events[0].kind, EventType::OutOfService);
    assert_eq!(r.take(), vec![(C::OutOfService, Normal, OutOfService)]);
    assert!(!r
        .set
        .set_out_of_service(id, "tech", true, "again", None, ts(0.5), &mut r.out)
        .unwrap());
    r.feed(V, 270.0, 1.0);
    assert_eq!(r.state(HI), OutOfService);
    r.take();
    // Out of service wins over shelving in the displayed state.
    r.set
        .shelve(id, "sue", Duration::from_secs(60), "x", ts(2.0), &mut r.out)
        .unwrap();
    assert_eq!(r.state(HI), OutOfService);
    r.set.unshelve(id, "sue", ts(3.0), &mut r.out).unwrap();
    r.take();
    assert!(r
        .set
        .set_out_of_service(id, "tech", false, "", None, ts(4.0), &mut r.out)
        .unwrap());
    assert_eq!(r.take(), vec![(C::InService, OutOfService, UnackActive)]);
}

#[test]
fn out_of_service_ends_by_itself_at_its_expiry() {
    let mut r = Rig::new(vec![limit(V, AlarmKind::Hi, 253.0, 0.0, 0.0, 0.0)]);
    let id = r.id(HI);
    assert!(
        r.set
            .set_out_of_service(
                id,
                "sue",
                true,
                "sensor swap",
                Some(ts(0.0)),
                ts(1.0),
                &mut r.out
            )
            .is_err(),
        "an end in the past"
    );
    assert!(r
        .set
        .set_out_of_service(
            id,
            "sue",
            true,
            "sensor swap",
            Some(ts(10.0)),
            ts(1.0),
            &mut r.out
        )
        .unwrap());
    assert!(r.out.events[0]
        .message
        .starts_with("Out of service until 1970-01-01 00:00 UTC (sensor swap)"));
    r.take();
    r.feed(V, 270.0, 2.0);
    assert_eq!(r.state(HI), OutOfService);
    assert_eq!(r.set.next_deadline(), Some(ts(10.0)));
    r.tick(9.9);
    assert_eq!(r.state(HI), OutOfService);
    r.out.events.clear();
    r.take();
    r.tick(10.0);
    assert!(r
        .out
        .events
        .iter()
        .any(|e| e.kind == EventType::OutOfService
            && e.message.starts_with("Out of service expired")));
    // Back in service with the condition still active: annunciated anew.
    assert_eq!(r.take(), vec![(C::InService, OutOfService, UnackActive)]);
    // The expiry survives a restart through the record.
    let mut r2 = Rig::new(vec![limit(V, AlarmKind::Hi, 253.0, 0.0, 0.0, 0.0)]);
    r2.set
        .set_out_of_service(id, "sue", true, "x", Some(ts(20.0)), ts(11.0), &mut r2.out)
        .unwrap();
    let rec = r2.set.records().into_iter().find(|x| x.key == HI).unwrap();
    assert_eq!(rec.out_of_service_until, Some(ts(20.0)));
}

fn elcb_rig(release_s: f64) -> Rig {
    Rig::with_rules(
        vec![
            discrete("SS1.ELCB.Closed", Value::Bool(false), 900),
            limit(V, AlarmKind::Lo, 207.0, 2.0, 0.0, 0.0),
            limit(V, AlarmKind::Hi, 253.0, 2.0, 0.0, 0.0),
            discrete("SS1.Zone1.Energised", Value::Bool(false), 400),
            limit("CSS1.PA.V_L1", AlarmKind::Lo, 207.0, 2.0, 0.0, 0.0),
        ],
        vec![SuppressionRule {
            name: "ss1: ELCB trip".into(),
            trigger: "SS1.ELCB.Closed:discrete".into(),
            targets: vec![
                AlarmMatch::new("SS1.Zone", &[]),
                AlarmMatch::new("SS1.PA.V_", &[AlarmKind::Lo, AlarmKind::LoLo]),
            ],
            release_delay_s: release_s,
        }],
    )
}

#[test]
fn elcb_trip_suppresses_zone_and_undervoltage_alarms() {
    let mut r = elcb_rig(10.0);
    let lo = "SS1.PA.V_L1:lo";
    let zone = "SS1.Zone1.Energised:discrete";
    r.feed("SS1.ELCB.Closed", true, 0.0);
    r.feed(V, 230.0, 0.0);
    r.feed("SS1.Zone1.Energised", true, 0.0);
    r.take();
    // The trip: the ELCB alarm annunciates, its consequences do not.
    r.feed("SS1.ELCB.Closed", false, 1.0);
    r.feed(V, 0.0, 1.2);
    r.feed("SS1.Zone1.Energised", false, 1.3);
    r.feed("CSS1.PA.V_L1", 0.0, 1.3);
    assert_eq!(r.state("SS1.ELCB.Closed:discrete"), UnackActive);
    assert_eq!(r.state(lo), Suppressed);
    assert_eq!(r.state(zone), Suppressed);
    assert_eq!(
        r.state(HI),
        Normal,
        "high-voltage alarms are not suppressed"
    );
    assert_eq!(
        r.state("CSS1.PA.V_L1:lo"),
        UnackActive,
        "another panel is not suppressed"
    );
    let view = r.set.view(r.id(lo)).unwrap();
    assert!(view.active && view.suppressed && view.acked);
    // History still records the suppressed activation, as not annunciated.
    let hidden: Vec<_> = r
        .out
        .transitions
        .iter()
        .filter(|t| t.key == lo && t.cause == C::Activate)
        .collect();
    assert_eq!(hidden.len(), 1);
    assert!(!hidden[0].annunciated);
    let list = r.set.summary(&AlarmFilter::default());
    let keys: Vec<&str> = list.iter().map(|v| v.key.as_str()).collect();
    assert!(keys.contains(&"SS1.ELCB.Closed:discrete") && !keys.contains(&lo));
    let suppressed = AlarmFilter {
        states: vec![Suppressed],
        ..Default::default()
    };
    assert_eq!(r.set.summary(&suppressed).len(), 2);
    r.take();

    // Reclose; the voltage comes back on the next scan, inside the hold.
    r.feed("SS1.ELCB.Closed", true, 20.0);
    assert_eq!(r.state(lo), Suppressed, "held for the release delay");
    r.feed(V, 230.0, 21.0);
    r.feed("SS1.Zone1.Energised", true, 21.0);
    r.tick(29.9);
    assert_eq!(r.state(lo), Suppressed);
    r.tick(30.0);
    assert_eq!(r.state(lo), Normal);
    assert_eq!(r.state(zone), Normal);
    assert!(
        r.take().iter().all(|(c, _, _)| *c != C::Activate),
        "no consequential alarm was annunciated"
    );
}

#[test]
fn a_standing_consequence_is_annunciated_when_suppression_ends() {
    let mut r = elcb_rig(0.0);
    let lo = "SS1.PA.V_L1:lo";
    r.feed(V, 230.0, 0.0);
    r.feed("SS1.ELCB.Closed", false, 1.0);
    r.feed(V, 100.0, 2.0);
    assert_eq!(r.state(lo), Suppressed);
    r.take();
    r.feed("SS1.ELCB.Closed", true, 3.0);
    assert_eq!(
        r.take(),
        vec![
            (C::Return, UnackActive, UnackRtn),       // the ELCB alarm itself
            (C::Unsuppress, Suppressed, UnackActive), // the standing low voltage
            (C::Unsuppress, Suppressed, Normal),      // the zone alarm, clear
        ]
    );
}

/// An activation or a return while suppressed leaves the displayed state as
/// it was (Suppressed → Suppressed): the transition's cause is what tells
/// them apart in history, and neither is annunciated.
#[test]
fn activation_and_return_while_suppressed_carry_their_cause() {
    let mut r = elcb_rig(10.0);
    let lo = "SS1.PA.V_L1:lo";
    r.feed("SS1.ELCB.Closed", true, 0.0);
    r.feed(V, 230.0, 0.0);
    r.feed("SS1.ELCB.Closed", false, 1.0);
    r.out.clear();
    r.feed(V, 0.0, 2.0);
    r.feed(V, 230.0, 3.0);
    let of_lo: Vec<_> = r.out.transitions.iter().filter(|t| t.key == lo).collect();
    let seen: Vec<_> = of_lo
        .iter()
        .map(|t| (t.cause, t.from, t.to, t.active, t.annunciated))
        .collect();
    assert_eq!(
        seen,
        vec![
            (C::Activate, Suppressed, Suppressed, true, false),
            (C::Return, Suppressed, Suppressed, false, false),
        ]
    );
    let ret = of_lo[1];
    assert_eq!(
        ret.cause.as_str(),
        "return",
        "the cause as history keeps it"
    );
    assert_eq!(
        ret.cause.as_str().parse::<TransitionCause>().unwrap(),
        C::Return
    );
    assert_eq!(
        ret.value,
        Some(Value::Float(230.0)),
        "the value at the return"
    );
    assert!(!ret.is_annunciated_activation());
    assert!(!of_lo[0].is_annunciated_activation());
}

/// Every cause has a name that reads back as itself (the store keeps names).
#[test]
fn transition_causes_round_trip_by_name() {
    for c in TransitionCause::ALL {
        assert_eq!(c.as_str().parse::<TransitionCause>().unwrap(), c);
        assert_eq!(serde_json::to_value(c).unwrap(), c.as_str());
    }
    assert!("activated".parse::<TransitionCause>().is_err());
}

/// The message shows the value at activation; the view keeps that value
/// (labelled, beside the value now) after the value moves on and the alarm
/// clears, and across a restart.
#[test]
fn the_value_at_activation_is_kept_beside_the_value_now() {
    let lo = "SS1.PA.V_L1:lo";
    let mut r = Rig::new(vec![limit(V, AlarmKind::Lo, 207.0, 2.0, 0.0, 0.0)]);
    r.feed(V, 230.0, 0.0);
    assert_eq!(r.set.view(r.id(lo)).unwrap().activation_value, None);
    r.feed(V, 0.0, 1.0);
    r.feed(V, 100.0, 2.0);
    let v = r.set.view(r.id(lo)).unwrap();
    assert_eq!(v.message, "SS1.PA.V_L1 0 V (limit 207 V)");
    assert_eq!(v.activation_value, Some(Value::Float(0.0)));
    assert_eq!(v.value, Some(Value::Float(100.0)));
    r.feed(V, 231.0, 3.0);
    let v = r.set.view(r.id(lo)).unwrap();
    assert_eq!(v.state, UnackRtn);
    assert_eq!(
        v.activation_value,
        Some(Value::Float(0.0)),
        "kept once cleared"
    );
    assert_eq!(v.value, Some(Value::Float(231.0)));
    let records = r.set.records();
    assert_eq!(records[0].activation_value, Some(Value::Float(0.0)));
    let json = serde_json::to_string(&records).unwrap();
    let mut r2 = Rig::new(vec![limit(V, AlarmKind::Lo, 207.0, 2.0, 0.0, 0.0)]);
    r2.set
        .restore(&serde_json::from_str::<Vec<_>>(&json).unwrap());
    let v2 = r2.set.view(r2.id(lo)).unwrap();
    assert_eq!(v2.activation_value, Some(Value::Float(0.0)));
    // A record written before the field existed still reads.
    let old = json.replace(",\"activation_value\":0.0", "");
    assert_ne!(old, json);
    let old: Vec<gridscada_alarms::AlarmStateRecord> = serde_json::from_str(&old).unwrap();
    assert_eq!(old[0].activation_value, None);
}

#[test]
fn trigger_in_the_same_batch_suppresses_before_consequences_annunciate() {
    let mut r = elcb_rig(10.0);
    r.feed("SS1.ELCB.Closed", true, 0.0);
    r.feed(V, 230.0, 0.0);
    r.take();
    let v = r.set.input_id(V).unwrap();
    let e = r.set.input_id("SS1.ELCB.Closed").unwrap();
    let (sv, se) = (good(0.0, 1.0), good(false, 1.0));
    // Voltage listed first, ELCB second: the trigger still goes first.
    r.set.apply(&[(v, &sv), (e, &se)], ts(1.0), &mut r.out);
    assert!(r
        .out
        .transitions
        .iter()
        .filter(|t| t.key == "SS1.PA.V_L1:lo")
        .all(|t| !t.annunciated));
}

#[test]
fn discrete_alarms_match_bool_int_and_string() {
    let mut r = Rig::new(vec![
        discrete("MG.PV1.State", Value::Int(2), 800),
        discrete("SS1.Door.Open", Value::Bool(true), 300),
        discrete("MG.Mode", Value::Str("fault".into()), 300),
    ]);
    r.feed("MG.PV1.State", 1i64, 0.0);
    r.feed("MG.PV1.State", 2i64, 1.0);
    assert_eq!(r.state("MG.PV1.State:discrete"), UnackActive);
    assert_eq!(r.out.transitions[0].message, "MG.PV1.State is 2");
    assert_eq!(r.out.transitions[0].limit, Some(Value::Int(2)));
    r.feed("MG.PV1.State", 2.0, 2.0); // same value as a float
    assert_eq!(r.state("MG.PV1.State:discrete"), UnackActive);
    r.feed("SS1.Door.Open", 1i64, 0.0); // a bool alarm on a 0/1 register
    assert_eq!(r.state("SS1.Door.Open:discrete"), UnackActive);
    r.feed("MG.Mode", "ok", 0.0);
    assert_eq!(r.state("MG.Mode:discrete"), Normal);
    r.feed("MG.Mode", "fault", 1.0);
    assert_eq!(r.state("MG.Mode:discrete"), UnackActive);
}

#[test]
fn comm_alarm_follows_the_status_tag_with_the_last_error() {
    let mut r = Rig::new(vec![comm("SS1.IO1")]);
    let key = "SS1.IO1:comm";
    // Never written (timestamp 0, Bad "no value yet"): no alarm at start-up.
    let unset = Sample {
        value: Value::Bool(false),
        quality: Quality::bad("no value yet"),
        timestamp: Timestamp::from_millis(0),
    };
    r.set
        .apply_tag("SS1.IO1.Comm.Connected", &unset, ts(0.0), &mut r.out);
    assert_eq!(r.state(key), Normal);
    r.feed("SS1.IO1.Comm.Connected", true, 1.0);
    assert_eq!(r.state(key), Normal);
    r.feed("SS1.IO1.Comm.LastError", "connection refused", 2.0);
    r.feed("SS1.IO1.Comm.Connected", false, 2.0);
    assert_eq!(r.state(key), UnackActive);
    assert_eq!(
        r.out.transitions[0].message,
        "Communication lost with SS1.IO1: connection refused"
    );
    assert_eq!(r.out.transitions[0].kind, AlarmKind::CommFail);
    // A newer error text updates the standing alarm's message.
    r.feed("SS1.IO1.Comm.LastError", "timeout", 3.0);
    assert!(r.out.view_changed);
    assert_eq!(
        r.set.view(r.id(key)).unwrap().message,
        "Communication lost with SS1.IO1: timeout"
    );
    r.feed("SS1.IO1.Comm.Connected", true, 4.0);
    assert_eq!(r.state(key), UnackRtn);
    // A Bad status is a lost link too.
    let bad = Sample {
        value: Value::Bool(true),
        quality: Quality::bad("poller stopped"),
        timestamp: ts(5.0),
    };
    r.set
        .apply_tag("SS1.IO1.Comm.Connected", &bad, ts(5.0), &mut r.out);
    assert_eq!(r.state(key), UnackActive);
}

#[test]
fn system_alarms_raise_and_clear() {
    let mut r = Rig::new(vec![limit(V, AlarmKind::Hi, 253.0, 0.0, 0.0, 0.0)]);
    let id = r
        .set
        .raise(
            "ss1.sequence.lockout",
            900,
            "SS1",
            "SS1: sequence locked out after 8 trips",
            ts(1.0),
            &mut r.out,
        )
        .unwrap();
    assert_eq!(r.take(), vec![(C::Activate, Normal, UnackActive)]);
    let v = r.set.view(id).unwrap();
    assert_eq!(
        (v.kind, v.priority, v.selection.as_str()),
        (AlarmKind::System, 900, "SS1")
    );
    assert_eq!(v.message, "SS1: sequence locked out after 8 trips");
    // Raising again: same alarm, no new activation.
    assert_eq!(
        r.set
            .raise(
                "ss1.sequence.lockout",
                900,
                "SS1",
                "again",
                ts(2.0),
                &mut r.out
            )
            .unwrap(),
        id
    );
    assert_eq!(r.take(), vec![]);
    assert!(r
        .set
        .clear("ss1.sequence.lockout", ts(3.0), &mut r.out)
        .unwrap());
    assert_eq!(r.take(), vec![(C::Return, UnackActive, UnackRtn)]);
    assert!(!r.set.clear("never.raised", ts(3.0), &mut r.out).unwrap());
    // Configured alarms cannot be driven through the API.
    assert!(r.set.raise(HI, 1, "x", "y", ts(4.0), &mut r.out).is_err());
    assert!(r.set.clear(HI, ts(4.0), &mut r.out).is_err());
}

#[test]
fn ack_top_ack_all_and_filters() {
    let mut r = Rig::new(vec![
        limit(V, AlarmKind::Hi, 253.0, 0.0, 0.0, 0.0),
        limit("SS1.PA.V_L2", AlarmKind::Hi, 253.0, 0.0, 0.0, 0.0),
        discrete("MG.PV1.State", Value::Int(2), 800),
    ]);
    r.feed(V, 260.0, 1.0);
    r.feed("SS1.PA.V_L2", 260.0, 2.0);
    r.feed("MG.PV1.State", 2i64, 3.0);
    r.take();
    let mut sel = AlarmFilter {
        selection: Some("ss1".into()),
        ..Default::default()
    };
    // Newest unacknowledged within the filter.
    let top = r.set.ack_top(&sel, "op", ts(4.0), &mut r.out).unwrap();
    assert_eq!(top, Some(r.id("SS1.PA.V_L2:hi")));
    let pri = AlarmFilter {
        min_priority: Some(700),
        ..Default::default()
    };
    assert_eq!(r.set.summary(&pri).len(), 1);
    let text = AlarmFilter {
        text: Some("v_l1".into()),
        ..Default::default()
    };
    assert_eq!(r.set.summary(&text)[0].key, HI);
    sel.states = vec![UnackActive];
    assert_eq!(r.set.summary(&sel).len(), 1);
    r.out.clear();
    let acked = r
        .set
        .ack_all(&AlarmFilter::default(), "op", ts(5.0), &mut r.out)
        .unwrap();
    assert_eq!(acked.len(), 2);
    assert_eq!(r.out.events.len(), 1, "one event for the whole ack-all");
    assert_eq!(r.out.transitions.len(), 2);
    assert!(r
        .out
        .transitions
        .iter()
        .all(|t| t.user.as_deref() == Some("op")));
    assert_eq!(
        r.set
            .ack_top(&AlarmFilter::default(), "op", ts(6.0), &mut r.out)
            .unwrap(),
        None
    );
    // Ack by ids: an unknown id acknowledges nothing.
    assert!(r
        .set
        .ack_ids(&[AlarmId(0), AlarmId(42)], "op", ts(7.0), &mut r.out)
        .is_err());
    // Summary: newest first.
    let all = r.set.summary(&AlarmFilter::default());
    assert_eq!(all[0].key, "MG.PV1.State:discrete");
}

#[test]
fn restore_keeps_acks_shelving_and_system_alarms() {
    let defs = || {
        vec![
            discrete("SS1.ELCB.Closed", Value::Bool(false), 900),
            limit(V, AlarmKind::Lo, 207.0, 2.0, 0.0, 0.0),
            limit(V, AlarmKind::Hi, 253.0, 2.0, 0.0, 0.0),
        ]
    };
    let rule = || SuppressionRule {
        name: "elcb".into(),
        trigger: "SS1.ELCB.Closed:discrete".into(),
        targets: vec![AlarmMatch::new("SS1.PA.V_", &[AlarmKind::Lo])],
        release_delay_s: 0.0,
    };
    let mut r = Rig::with_rules(defs(), vec![rule()]);
    r.feed(V, 260.0, 1.0);
    let hi = r.id(HI);
    r.set.ack(hi, "op", ts(2.0), &mut r.out).unwrap();
    r.feed("SS1.ELCB.Closed", false, 3.0);
    r.set
        .raise(
            "historian.overflow",
            700,
            "SYS",
            "Historian queue overflow",
            ts(4.0),
            &mut r.out,
        )
        .unwrap();
    let elcb = r.id("SS1.ELCB.Closed:discrete");
    r.set
        .shelve(
            elcb,
            "sup",
            Duration::from_secs(3600),
            "maintenance",
            ts(5.0),
            &mut r.out,
        )
        .unwrap();
    let mut records = r.set.records();
    records.push(gridscada_alarms::AlarmStateRecord {
        key: "gone:hi".into(),
        ..records[0].clone()
    });
    // JSON round trip, as a store might keep it.
    let json = serde_json::to_string(&records).unwrap();
    let records: Vec<gridscada_alarms::AlarmStateRecord> = serde_json::from_str(&json).unwrap();

    let mut r2 = Rig::with_rules(defs(), vec![rule()]);
    let report = r2.set.restore(&records);
    assert_eq!(report.recreated, 1);
    assert_eq!(report.skipped, vec!["gone:hi".to_string()]);
    assert_eq!(r2.state(HI), AckActive);
    assert_eq!(r2.state("SS1.ELCB.Closed:discrete"), Shelved);
    assert_eq!(
        r2.state("SS1.PA.V_L1:lo"),
        Suppressed,
        "suppression follows the restored trigger"
    );
    assert_eq!(r2.state("historian.overflow"), UnackActive);
    // The same value after the restart: no new activation.
    r2.feed(V, 260.0, 10.0);
    assert!(r2.out.transitions.is_empty());
    // Shelving expiry still runs after the restart.
    assert_eq!(r2.set.next_deadline(), Some(ts(3605.0)));
}

#[test]
fn bad_definitions_are_refused_with_the_key() {
    let mut d = limit(V, AlarmKind::Hi, f64::NAN, 0.0, 0.0, 0.0);
    let e = AlarmSet::new(vec![d.clone()], vec![]).unwrap_err();
    assert!(e.to_string().contains("SS1.PA.V_L1:hi"), "{e}");
    d.condition = Condition::Above {
        limit: 1.0,
        deadband: -1.0,
    };
    assert!(AlarmSet::new(vec![d.clone()], vec![]).is_err());
    let ok = limit(V, AlarmKind::Hi, 1.0, 0.0, 0.0, 0.0);
    let e = AlarmSet::new(vec![ok.clone(), ok], vec![]).unwrap_err();
    assert_eq!(e.to_string(), "alarm key 'SS1.PA.V_L1:hi' is used twice");
    let rule = SuppressionRule {
        name: "r".into(),
        trigger: "nope".into(),
        targets: vec![],
        release_delay_s: 0.0,
    };
    let e = AlarmSet::new(vec![], vec![rule]).unwrap_err();
    assert!(e.to_string().contains("'nope'"));
}
