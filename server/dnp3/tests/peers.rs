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
    assert_eq!((h.control.fir, h.control.fin, h.control.con), (true, true, true));
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
