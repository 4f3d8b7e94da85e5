//! Octets captured from third-party outstations (see PEERS.md) answering
//! the `dnp3_poll` example: decoded through link, transport, application
//! layer and objects, they give what the outstation was set to serve.

use gridscada_dnp3::app::{FunctionCode, Iin, ResponseHeader};
use gridscada_dnp3::link;
use gridscada_dnp3::objects::{self, Flags, MeasurementKind as K, Objects, Quality};
use gridscada_dnp3::transport::Reassembler;
use gridscada_dnp3::Value;

fn hex(s: &str) -> Vec<u8> {
    s.split_whitespace()
        .map(|b| u8::from_str_radix(b, 16).unwrap())
        .collect()
}

/// The one fragment in `wire`, its header and objects.
fn decode(wire: &str) -> (ResponseHeader, Objects) {
    let b = hex(wire);
    let (frame, n) = link::decode(&b).unwrap().unwrap();
    assert_eq!(n, b.len());
    assert_eq!((frame.destination, frame.source), (1, 1024));
    assert!(!frame.dir);
    let fragment = Reassembler::default().push(&frame.data).unwrap().unwrap();
    let h = ResponseHeader::decode(&fragment).unwrap();
    (h, objects::parse(&fragment[4..], 4))
}

type Row = (K, u16, Value, Option<u64>, bool);

fn rows(o: &Objects) -> Vec<Row> {
    o.measurements
        .iter()
        .map(|m| (m.kind, m.index, m.value, m.time, m.is_event))
        .collect()
}

#[test]
fn dnp3py_integrity_response() {
    // dnp3py 0.6.0: binaries 0..2 (1 on), one analog input (42, then 43
    // and 44 as events), counter 0 = 7, a binary and an analog output
    // never written (offline, restart).
    let (h, o) = decode(
        "05 64 64 44 01 00 00 04 9D 26 C4 C4 81 00 00 02 01 17 03 01 81 02 81 02 01 20 AC 46 \
         01 17 03 00 01 2A 00 00 00 00 01 2B 00 00 00 00 FD 16 01 2C 00 00 00 16 05 17 01 00 \
         01 07 00 00 00 B8 4E 8E EC 50 25 A2 01 01 02 00 00 02 02 81 01 0A 02 00 18 88 00 00 \
         02 1E 01 00 00 00 01 2C 00 00 00 28 02 00 3B FF 00 00 02 00 00 14 01 00 00 00 01 07 \
         00 00 00 A0 0F",
    );
    assert_eq!(h.function, FunctionCode::Response);
    assert_eq!(h.control.seq, 4);
    assert_eq!(h.iin, Iin::default());
    assert_eq!(o.error, None);
    assert!(o.notes.is_empty());
    use Value::*;
    assert_eq!(
        rows(&o),
        vec![
            (K::Binary, 1, Binary(true), None, true),
            (K::Binary, 2, Binary(true), None, true),
            (K::Binary, 2, Binary(false), None, true),
            (K::Analog, 0, Analog(42.0), None, true),
            (K::Analog, 0, Analog(43.0), None, true),
            (K::Analog, 0, Analog(44.0), None, true),
            (K::Counter, 0, Counter(7), Some(1_795_922_390_200), true),
            (K::Binary, 0, Binary(false), None, false),
            (K::Binary, 1, Binary(true), None, false),
            (K::Binary, 2, Binary(false), None, false),
            (K::BinaryOutputStatus, 0, Binary(false), None, false),
            (K::Analog, 0, Analog(44.0), None, false),
            (K::AnalogOutputStatus, 0, Analog(0.0), None, false),
            (K::Counter, 0, Counter(7), None, false),
        ]
    );
    let never_written = o.measurements[10].flags;
    assert_eq!(never_written, Flags::RESTART);
    assert_eq!(
        never_written.quality(),
        (Quality::Bad, "offline, restart".to_string())
    );
}

#[test]
fn py1815_response_with_a_common_time_of_occurrence() {
    // py1815 0.3.0: g51v2 CTO, g2v3 (relative time), g32v3, then class 0.
    let (h, o) = decode(
        "05 64 3D 44 01 00 00 04 1A DF C0 E4 81 00 00 33 02 07 01 DE 39 52 25 A2 01 02 45 \
         A2 03 17 01 01 81 00 00 20 03 17 01 00 01 D3 04 00 DB F7 00 DE 39 52 25 A2 01 01 \
         02 00 00 01 01 81 1E 01 3C 57 00 00 00 01 D2 04 00 00 25 DF",
    );
    assert_eq!(
        (h.control.fir, h.control.fin, h.control.con),
        (true, true, true)
    );
    assert_eq!(o.error, None);
    assert_eq!(o.notes.len(), 1, "the CTO is unsynchronised: {:?}", o.notes);
    use Value::*;
    let t = Some(1_795_922_475_486);
    assert_eq!(
        rows(&o),
        vec![
            (K::Binary, 1, Binary(true), t, true),
            (K::Analog, 0, Analog(1235.0), t, true),
            (K::Binary, 0, Binary(false), None, false),
            (K::Binary, 1, Binary(true), None, false),
            (K::Analog, 0, Analog(1234.0), None, false),
        ]
    );
}

#[test]
fn py1815_unsolicited_events() {
    let (h, o) = decode(
        "05 64 26 44 01 00 00 04 57 AE C0 F1 82 00 00 02 02 17 01 01 01 C7 3D 52 25 A2 D0 \
         FF 01 20 03 17 01 00 01 D4 04 00 00 C7 3D 52 25 A2 48 A9 01 A1 C9",
    );
    assert_eq!(h.function, FunctionCode::UnsolicitedResponse);
    assert!(h.control.uns && h.control.con);
    assert_eq!(h.control.seq, 1);
    use Value::*;
    let t = Some(1_795_922_476_487);
    assert_eq!(
        rows(&o),
        vec![
            (K::Binary, 1, Binary(false), t, true),
            (K::Analog, 0, Analog(1236.0), t, true),
        ]
    );
}

/// opendnp3 (through dnp3-python 0.3.0b1, `dnp3demo outstation
/// --init-random`): a fragment of two transport segments with g2v1, g11v1,
/// g32v1, g42v1 events, then g1v2, g3v2, g20v1, g21v1, g30v1, g10v2,
/// g40v1 and g50v4 static data.
pub const OPENDNP3_INTEGRITY: [&str; 2] = [
    "05 64 FF 44 01 00 00 04 53 46 43 E2 81 00 00 02 01 28 05 00 00 00 01 01 00 01 C7 46 \
         02 00 01 03 00 81 04 00 01 0B 01 28 05 00 00 00 00 66 01 01 00 81 02 00 81 03 00 01 \
         04 00 01 20 01 28 AB AE 05 00 00 00 01 00 00 00 00 01 00 01 06 00 00 00 3B 4D 02 00 \
         01 29 00 00 00 03 00 01 0D 00 00 00 04 00 10 83 01 D9 13 00 00 2A 01 28 05 00 00 00 \
         01 00 00 00 E5 CB 00 01 00 01 00 00 00 00 02 00 01 23 00 00 00 03 AA 70 00 01 96 02 \
         00 00 04 00 01 26 13 00 00 01 02 00 02 79 00 04 01 01 01 81 01 03 02 00 00 04 02 02 \
         02 02 11 31 02 14 01 00 00 04 02 00 00 00 00 02 00 00 00 00 68 7B 02 00 00 00 00 02 \
         00 00 00 00 02 00 00 00 00 15 01 32 01 00 00 04 02 00 00 00 00 02 00 00 00 00 02 00 \
         70 B2 00 00 00 02 00 00 00 00 02 00 00 00 00 1E 01 00 4A 88 00 04 01 00 00 00 00 01 \
         06 00 00 00 01 29 00 00 A0 68 00 01 0D 00 00 00 01 D9 13 00 00 0A 02 00 00 04 EE 73 \
         01 81 81 01 01 28 01 00 00 04 F7 6C",
    "05 64 5B 44 01 00 00 04 3C EB 84 01 00 00 00 00 01 00 00 00 00 01 23 00 00 00 B0 34 \
         01 96 02 00 00 01 26 13 00 00 32 04 00 00 04 00 B8 DD 00 00 00 00 00 00 00 00 00 00 \
         00 00 00 00 00 00 FF FF 00 00 00 00 00 00 00 00 00 00 00 00 00 00 00 00 FF FF 00 00 \
         00 00 00 00 00 00 00 00 00 00 00 00 00 00 FF FF 00 00 00 00 00 00 FF FF",
];

#[test]
fn opendnp3_integrity_response_in_two_segments() {
    let mut r = Reassembler::default();
    let mut fragment = None;
    for wire in OPENDNP3_INTEGRITY {
        let b = hex(wire);
        let (frame, n) = link::decode(&b).unwrap().unwrap();
        assert_eq!(n, b.len());
        fragment = r.push(&frame.data).unwrap();
    }
    let fragment = fragment.expect("FIN in the second segment");
    assert_eq!(fragment.len(), 249 + 85);
    let h = ResponseHeader::decode(&fragment).unwrap();
    assert!(h.control.con, "events: the master must confirm");
    let o = objects::parse(&fragment[4..], 4);
    assert_eq!(o.error, None);
    // g50v4 (indexed time and interval points) is not a measurement.
    assert_eq!(o.notes.len(), 5, "{:?}", o.notes);
    assert!(o.notes.iter().all(|n| n.starts_with("g50v4 index")));
    assert_eq!(o.time, None);
    let count = |k: K, event: bool| {
        o.measurements
            .iter()
            .filter(|m| m.kind == k && m.is_event == event)
            .count()
    };
    for k in [
        K::Binary,
        K::BinaryOutputStatus,
        K::Analog,
        K::AnalogOutputStatus,
    ] {
        assert_eq!(count(k, true), 5, "{k:?} events");
    }
    for k in [
        K::Binary,
        K::DoubleBit,
        K::Counter,
        K::FrozenCounter,
        K::Analog,
        K::BinaryOutputStatus,
        K::AnalogOutputStatus,
    ] {
        assert_eq!(count(k, false), 5, "{k:?} static");
    }
    let find = |k: K, i: u16| {
        o.measurements
            .iter()
            .find(|m| m.kind == k && m.index == i && !m.is_event)
            .unwrap()
    };
    assert_eq!(find(K::Analog, 4).value, Value::Analog(5081.0));
    assert_eq!(find(K::AnalogOutputStatus, 3).value, Value::Analog(662.0));
    assert_eq!(find(K::BinaryOutputStatus, 1).value, Value::Binary(true));
    let db = find(K::DoubleBit, 0);
    assert_eq!(
        db.value,
        Value::DoubleBit(gridscada_dnp3::DoubleBit::Intermediate)
    );
    assert_eq!(db.flags.quality().0, Quality::Bad);
}
