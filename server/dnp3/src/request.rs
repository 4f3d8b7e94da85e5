//! The requests a DNP3 master sends, as application fragments (APDUs):
//! polls, unsolicited enable/disable, confirmations, the restart clear,
//! commands, delay measurement and the LAN time sync, and a plain read.
//! Each takes the application sequence number (0..=15) to use.

use crate::app::{Control, FunctionCode, ObjectHeader, Range, RequestHeader};
use crate::objects::{time48, CommandObject, CommandStatus};

/// A request fragment with `function` and the object octets `objects`.
pub fn fragment(seq: u8, function: FunctionCode, objects: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(RequestHeader::LEN + objects.len());
    RequestHeader {
        control: Control::request(seq),
        function,
    }
    .encode(&mut out);
    out.extend_from_slice(objects);
    out
}

fn classes(out: &mut Vec<u8>, variations: &[u8]) {
    for &v in variations {
        ObjectHeader::new(60, v, Range::All).encode(out);
    }
}

/// READ class 1, 2, 3 and 0 (g60v2, v3, v4, v1, qualifier 0x06).
pub fn integrity_poll(seq: u8) -> Vec<u8> {
    let mut o = Vec::new();
    classes(&mut o, &[2, 3, 4, 1]);
    fragment(seq, FunctionCode::Read, &o)
}

/// READ class 1, 2 and 3.
pub fn event_poll(seq: u8) -> Vec<u8> {
    let mut o = Vec::new();
    classes(&mut o, &[2, 3, 4]);
    fragment(seq, FunctionCode::Read, &o)
}

/// ENABLE_UNSOLICITED (or DISABLE_UNSOLICITED) for classes 1, 2 and 3.
pub fn unsolicited(seq: u8, enable: bool) -> Vec<u8> {
    let mut o = Vec::new();
    classes(&mut o, &[2, 3, 4]);
    let f = if enable {
        FunctionCode::EnableUnsolicited
    } else {
        FunctionCode::DisableUnsolicited
    };
    fragment(seq, f, &o)
}

/// CONFIRM of a response (`unsolicited` false) or an unsolicited response,
/// with that fragment's sequence number.
pub fn confirm(seq: u8, unsolicited: bool) -> Vec<u8> {
    let control = Control {
        uns: unsolicited,
        ..Control::request(seq)
    };
    let mut out = Vec::with_capacity(2);
    RequestHeader {
        control,
        function: FunctionCode::Confirm,
    }
    .encode(&mut out);
    out
}

/// WRITE g80v1 index 7 = 0: clear IIN1.7 DEVICE_RESTART.
pub fn clear_restart(seq: u8) -> Vec<u8> {
    let mut o = Vec::new();
    ObjectHeader::new(80, 1, Range::StartStop8 { start: 7, stop: 7 }).encode(&mut o);
    o.push(0x00);
    fragment(seq, FunctionCode::Write, &o)
}

/// SELECT, OPERATE, DIRECT_OPERATE or DIRECT_OPERATE_NR of one command
/// object (g12v1 or g41vN, qualifier 0x28, count 1).
pub fn command(seq: u8, function: FunctionCode, index: u16, object: CommandObject) -> Vec<u8> {
    let (g, v) = object.group_variation();
    let mut o = Vec::new();
    ObjectHeader::new(g, v, Range::Indexed16(1)).encode(&mut o);
    o.extend_from_slice(&index.to_le_bytes());
    object.encode(CommandStatus::Success, &mut o);
    fragment(seq, function, &o)
}

/// DELAY_MEASURE (no objects).
pub fn delay_measure(seq: u8) -> Vec<u8> {
    fragment(seq, FunctionCode::DelayMeasure, &[])
}

/// RECORD_CURRENT_TIME (LAN procedure, step 1; no objects).
pub fn record_current_time(seq: u8) -> Vec<u8> {
    fragment(seq, FunctionCode::RecordCurrentTime, &[])
}

/// WRITE g50v3 (last recorded time, qualifier 0x07 count 1): the LAN
/// procedure's step 2, with the master's time when step 1 was sent.
pub fn write_recorded_time(seq: u8, unix_ms: u64) -> Vec<u8> {
    let mut o = Vec::new();
    ObjectHeader::new(50, 3, Range::Count8(1)).encode(&mut o);
    o.extend_from_slice(&time48(unix_ms));
    fragment(seq, FunctionCode::Write, &o)
}

/// WRITE g50v1 (absolute time, for the non-LAN procedure).
pub fn write_time(seq: u8, unix_ms: u64) -> Vec<u8> {
    let mut o = Vec::new();
    ObjectHeader::new(50, 1, Range::Count8(1)).encode(&mut o);
    o.extend_from_slice(&time48(unix_ms));
    fragment(seq, FunctionCode::Write, &o)
}

/// READ of one group/variation over a range (e.g. `Range::All`, or a
/// start-stop range of indexes).
pub fn read(seq: u8, group: u8, variation: u8, range: Range) -> Vec<u8> {
    let mut o = Vec::new();
    ObjectHeader::new(group, variation, range).encode(&mut o);
    fragment(seq, FunctionCode::Read, &o)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::objects::{AnalogOutput, Crob};
    use crate::test_util::hex;

    #[test]
    fn requests_as_on_the_wire() {
        assert_eq!(
            integrity_poll(0),
            hex("C0 01 3C 02 06 3C 03 06 3C 04 06 3C 01 06")
        );
        assert_eq!(event_poll(17), hex("C1 01 3C 02 06 3C 03 06 3C 04 06"));
        assert_eq!(
            unsolicited(2, true),
            hex("C2 14 3C 02 06 3C 03 06 3C 04 06")
        );
        assert_eq!(
            unsolicited(3, false),
            hex("C3 15 3C 02 06 3C 03 06 3C 04 06")
        );
        assert_eq!(confirm(5, false), hex("C5 00"));
        assert_eq!(confirm(9, true), hex("D9 00"));
        assert_eq!(clear_restart(4), hex("C4 02 50 01 00 07 07 00"));
        assert_eq!(delay_measure(1), hex("C1 17"));
        assert_eq!(record_current_time(1), hex("C1 18"));
        assert_eq!(
            write_recorded_time(2, 0x0102_0304_0506),
            hex("C2 02 32 03 07 01 06 05 04 03 02 01")
        );
        assert_eq!(write_time(2, 1), hex("C2 02 32 01 07 01 01 00 00 00 00 00"));
        assert_eq!(
            read(6, 30, 1, Range::StartStop8 { start: 0, stop: 9 }),
            hex("C6 01 1E 01 00 00 09")
        );
        assert_eq!(
            command(
                7,
                FunctionCode::Select,
                3,
                CommandObject::Crob(Crob::latch(true))
            ),
            hex("C7 03 0C 01 28 01 00 03 00 03 01 00 00 00 00 00 00 00 00 00")
        );
        assert_eq!(
            command(
                8,
                FunctionCode::DirectOperate,
                1,
                CommandObject::Crob(Crob::pulse(true, 2, 1000, 500))
            ),
            hex("C8 05 0C 01 28 01 00 01 00 01 02 E8 03 00 00 F4 01 00 00 00")
        );
        assert_eq!(
            command(
                9,
                FunctionCode::Operate,
                2,
                CommandObject::Crob(Crob::trip_close(false, 100))
            )[9..11],
            [0x81, 0x01]
        );
        assert_eq!(
            command(
                10,
                FunctionCode::DirectOperate,
                4,
                CommandObject::Analog(AnalogOutput::F32(1.5))
            ),
            hex("CA 05 29 03 28 01 00 04 00 00 00 C0 3F 00")
        );
    }
}
