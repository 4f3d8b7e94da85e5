//! Round trips of every type, frames written out by hand from the standard's
//! examples, and the errors a station sees.

use crate::common;

use common::{element, hex, max_objects, objects, sample_asdus, time};
use gridscada_iec104::{
    apci, Asdu, AsduError, Cause, Cp56Time2a, DoublePoint, Element, Frame, InformationObject,
    Quality, TypeId, UFunction,
};

/// Decode a whole APDU that must hold one I frame, and its ASDU.
fn decode_i(bytes: &[u8]) -> (u16, u16, Asdu) {
    let (frame, used) = apci::decode(bytes).unwrap().unwrap();
    assert_eq!(used, bytes.len());
    match frame {
        Frame::I {
            send_seq,
            recv_seq,
            asdu,
        } => (send_seq, recv_seq, Asdu::decode(&asdu).unwrap()),
        other => panic!("expected an I frame, got {other:?}"),
    }
}

#[test]
fn every_type_round_trips_in_each_allowed_form() {
    let asdus = sample_asdus();
    let mut types_seen = std::collections::BTreeSet::new();
    let mut sequences = 0;
    for (i, asdu) in asdus.iter().enumerate() {
        types_seen.insert(asdu.type_id());
        sequences += usize::from(asdu.is_sequence());
        let bytes = asdu.encode();
        assert!(bytes.len() <= 249, "{:?}", asdu.type_id());
        let back = Asdu::decode(&bytes).unwrap_or_else(|e| panic!("{:?}: {e}", asdu.type_id()));
        assert_eq!(&back, asdu);
        // And inside an I frame, with wrapping sequence numbers.
        let frame = Frame::I {
            send_seq: (32760 + i as u16) % 32768,
            recv_seq: i as u16,
            asdu: bytes.clone(),
        };
        let apdu = apci::encode(&frame).unwrap();
        let (s, r, decoded) = decode_i(&apdu);
        assert_eq!((s, r), ((32760 + i as u16) % 32768, i as u16));
        assert_eq!(decoded, *asdu);
    }
    assert_eq!(types_seen.len(), TypeId::ALL.len());
    let monitoring = TypeId::ALL.iter().filter(|t| t.allows_sequence()).count();
    assert_eq!(sequences, 2 * monitoring);
}

#[test]
fn sequence_form_sends_one_ioa() {
    let t = TypeId::M_ME_NB_1;
    let a = Asdu::new_sequence(t, Cause::PerCyc, 1, objects(t, 0x010203, 3)).unwrap();
    let b = a.encode();
    assert_eq!(b[1], 0x83);
    assert_eq!(&b[6..9], &[0x03, 0x02, 0x01]);
    assert_eq!(b.len(), 6 + 3 + 3 * 3);
    let iaos: Vec<u32> = Asdu::decode(&b)
        .unwrap()
        .objects()
        .iter()
        .map(|o| o.ioa)
        .collect();
    assert_eq!(iaos, [0x010203, 0x010204, 0x010205]);
}

#[test]
fn sequence_form_is_refused_where_the_standard_has_none() {
    for &t in TypeId::ALL.iter().filter(|t| !t.allows_sequence()) {
        let err = Asdu::new_sequence(t, Cause::Act, 1, objects(t, 1, 2)).unwrap_err();
        assert_eq!(err, AsduError::SequenceNotAllowed(t));
        // On the wire too: set SQ in a valid SQ=0 ASDU of one object.
        let mut b = Asdu::new(t, Cause::Act, 1, objects(t, 1, 1))
            .unwrap()
            .encode();
        b[1] |= 0x80;
        assert_eq!(
            Asdu::decode(&b).unwrap_err(),
            AsduError::SequenceNotAllowed(t)
        );
    }
    let t = TypeId::M_SP_NA_1;
    let mut objs = objects(t, 10, 3);
    objs[2].ioa = 13;
    assert_eq!(
        Asdu::new_sequence(t, Cause::Spont, 1, objs).unwrap_err(),
        AsduError::NotConsecutive {
            index: 2,
            expected: 12,
            got: 13
        }
    );
    // A sequence may not run past the last 24-bit IOA.
    let mut b = Asdu::new_sequence(t, Cause::Spont, 1, objects(t, 0xFF_FFFE, 2))
        .unwrap()
        .encode();
    b[1] = 0x83;
    b.push(0x01);
    assert_eq!(
        Asdu::decode(&b).unwrap_err().to_string(),
        "object 2: IOA 16777216 out of range 0..=16777215"
    );
}

#[test]
fn startdt_act_and_testfr_con_from_the_standard() {
    for (s, f) in [
        ("68 04 07 00 00 00", UFunction::StartDtAct),
        ("68 04 83 00 00 00", UFunction::TestFrCon),
    ] {
        let b = hex(s);
        assert_eq!(apci::decode(&b), Ok(Some((Frame::U(f), 6))));
        assert_eq!(apci::encode(&Frame::U(f)).unwrap(), b);
    }
}

#[test]
fn general_interrogation_activation() {
    let b = hex("68 0E 00 00 00 00 64 01 06 00 01 00 00 00 00 14");
    let (s, r, asdu) = decode_i(&b);
    assert_eq!((s, r), (0, 0));
    assert_eq!(asdu.type_id(), TypeId::C_IC_NA_1);
    assert_eq!(asdu.cause(), Cause::Act);
    assert!(!asdu.is_negative() && !asdu.is_test() && !asdu.is_sequence());
    assert_eq!((asdu.originator(), asdu.common_address()), (0, 1));
    assert_eq!(
        asdu.objects(),
        &[InformationObject::new(
            0,
            Element::Interrogation { qoi: 20 }
        )]
    );
    // The station mirrors it as actcon, then actterm.
    let con = asdu.clone().with_cause(Cause::ActCon).unwrap();
    assert_eq!(
        con.encode(),
        hex("64 01 07 00 01 00 00 00 00 14"),
        "actcon differs only in the cause"
    );
    let made = Asdu::new(
        TypeId::C_IC_NA_1,
        Cause::Act,
        1,
        vec![InformationObject::new(
            0,
            Element::Interrogation { qoi: 20 },
        )],
    )
    .unwrap();
    let frame = Frame::I {
        send_seq: 0,
        recv_seq: 0,
        asdu: made.encode(),
    };
    assert_eq!(apci::encode(&frame).unwrap(), b);
}

#[test]
fn spontaneous_float_with_quality() {
    // M_ME_NC_1, spont, CA 1, IOA 0x004001 = 16385, 230.5 with IV.
    let b = hex("68 12 02 00 04 00 0D 01 03 00 01 00 01 40 00 00 80 66 43 80");
    let (s, r, asdu) = decode_i(&b);
    assert_eq!((s, r), (1, 2));
    assert_eq!(asdu.cause(), Cause::Spont);
    assert_eq!(
        asdu.objects(),
        &[InformationObject::new(
            16385,
            Element::Float {
                value: 230.5,
                quality: Quality::IV
            }
        )]
    );
}

#[test]
fn breaker_event_with_time_tag() {
    // M_DP_TB_1, spont, CA 3, IOA 100, ON, 2024-02-29 23:59:59.999, Thursday.
    let b = hex("68 15 00 00 00 00 1F 01 03 00 03 00 64 00 00 02 5F EA 3B 17 9D 02 18");
    let (_, _, asdu) = decode_i(&b);
    let o = asdu.objects()[0];
    assert_eq!(o.ioa, 100);
    assert_eq!(
        o.element,
        Element::Double {
            state: DoublePoint::On,
            quality: Quality::GOOD
        }
    );
    assert_eq!(o.time.unwrap().to_unix_ms(), Ok(1_709_251_199_999));
    assert_eq!(
        apci::encode(&apci::decode(&b).unwrap().unwrap().0).unwrap(),
        b
    );
}

#[test]
fn select_single_command_and_negative_confirmation() {
    // C_SC_NA_1 act, CA 1, IOA 5000, select ON, QU 0.
    let asdu_b = hex("2D 01 06 00 01 00 88 13 00 81");
    let asdu = Asdu::decode(&asdu_b).unwrap();
    assert_eq!(
        asdu.objects()[0].element,
        Element::SingleCommand {
            on: true,
            select: true,
            qualifier: 0
        }
    );
    let neg = asdu
        .with_cause(Cause::ActCon)
        .unwrap()
        .with_negative(true)
        .encode();
    assert_eq!(neg, hex("2D 01 47 00 01 00 88 13 00 81"));
    let back = Asdu::decode(&neg).unwrap();
    assert!(back.is_negative());
    assert_eq!(back.cause(), Cause::ActCon);
}

#[test]
fn clock_sync_carries_the_time_as_its_element() {
    let t = Cp56Time2a::from_unix_ms(1_700_000_000_123).unwrap();
    let a = Asdu::new(
        TypeId::C_CS_NA_1,
        Cause::Act,
        0xFFFF,
        vec![InformationObject::new(0, Element::ClockSync { time: t })],
    )
    .unwrap();
    let b = a.encode();
    assert_eq!(b.len(), 6 + 3 + 7);
    assert_eq!(&b[9..], &t.encode());
    assert_eq!(Asdu::decode(&b).unwrap(), a);
    // A broken time in a clock sync names the object and the field.
    let mut bad = b.clone();
    bad[14] = 13; // month
    assert_eq!(
        Asdu::decode(&bad).unwrap_err().to_string(),
        "object 0 (IOA 0) of type C_CS_NA_1: CP56Time2a month 13 out of range 1..=12"
    );
}

#[test]
fn errors_name_what_and_where() {
    let e = |s: &str| Asdu::decode(&hex(s)).unwrap_err().to_string();
    assert_eq!(
        e("0D 01 03 00"),
        "ASDU of 4 octets is shorter than its 6-octet header"
    );
    assert_eq!(e("02 01 03 00 01 00 01 00 00 00"), "unknown type id 2");
    assert_eq!(e("0D 00 03 00 01 00"), "type M_ME_NC_1 with object count 0");
    // Three floats need 6 + 3 * 8 = 30 octets.
    let mut three = Asdu::new(
        TypeId::M_ME_NC_1,
        Cause::Spont,
        1,
        objects(TypeId::M_ME_NC_1, 1, 3),
    )
    .unwrap()
    .encode();
    three.pop();
    assert_eq!(
        Asdu::decode(&three).unwrap_err().to_string(),
        "type M_ME_NC_1 with 3 objects needs 30 octets, got 29"
    );
    three.extend([0, 0]);
    assert_eq!(
        Asdu::decode(&three).unwrap_err().to_string(),
        "type M_ME_NC_1 with 3 objects needs 30 octets, got 31"
    );
    // 127 time-tagged floats cannot fit, whatever follows.
    assert_eq!(
        e("24 7F 03 00 01 00"),
        "type M_ME_TF_1 with 127 objects needs 1911 octets, more than the 249 an ASDU can hold"
    );
    // A time tag with a bad field, in the second object.
    let t = TypeId::M_SP_TB_1;
    let mut b = Asdu::new(t, Cause::Spont, 1, objects(t, 7, 2))
        .unwrap()
        .encode();
    let hour = 6 + 11 + 3 + 1 + 3;
    b[hour] = 24;
    assert_eq!(
        Asdu::decode(&b).unwrap_err().to_string(),
        "object 1 (IOA 8) of type M_SP_TB_1: time tag: CP56Time2a hour 24 out of range 0..=23"
    );
    // A regulating step command of RCS 0.
    assert_eq!(
        e("2F 01 06 00 01 00 01 00 00 00"),
        "object 0 (IOA 1) of type C_RC_NA_1: regulating step RCS 0 is not permitted"
    );
}

#[test]
fn hand_built_asdus_are_checked() {
    let single = InformationObject::new(
        1,
        Element::Single {
            on: true,
            quality: Quality::GOOD,
        },
    );
    // A time tag on a type without one, and the reverse.
    let err = Asdu::new(
        TypeId::M_SP_NA_1,
        Cause::Spont,
        1,
        vec![single.with_time(time(0))],
    )
    .unwrap_err();
    assert_eq!(
        err.to_string(),
        "object 0 (IOA 1): a Single element with time tag does not belong in type M_SP_NA_1"
    );
    assert!(matches!(
        Asdu::new(TypeId::M_SP_TB_1, Cause::Spont, 1, vec![single]),
        Err(AsduError::Mismatch { .. })
    ));
    // An element of another type.
    assert!(matches!(
        Asdu::new(TypeId::M_DP_NA_1, Cause::Spont, 1, vec![single]),
        Err(AsduError::Mismatch { .. })
    ));
    assert_eq!(
        Asdu::new(TypeId::M_SP_NA_1, Cause::Spont, 1, vec![]),
        Err(AsduError::NoObjects(TypeId::M_SP_NA_1))
    );
    let many = vec![single; 128];
    assert!(matches!(
        Asdu::new_sequence(TypeId::M_SP_NA_1, Cause::Spont, 1, many),
        Err(AsduError::TooManyObjects { count: 128, .. })
    ));
    let too_long = objects(
        TypeId::M_ME_NC_1,
        1,
        max_objects(TypeId::M_ME_NC_1, false) + 1,
    );
    assert!(matches!(
        Asdu::new(TypeId::M_ME_NC_1, Cause::Spont, 1, too_long),
        Err(AsduError::TooLong { .. })
    ));
    let mut far = single;
    far.ioa = 1 << 24;
    assert_eq!(
        Asdu::new(TypeId::M_SP_NA_1, Cause::Spont, 1, vec![far]),
        Err(AsduError::IoaRange {
            index: 0,
            ioa: 1 << 24
        })
    );
    assert_eq!(
        Asdu::new(TypeId::M_SP_NA_1, Cause::Inro(17), 1, vec![single]),
        Err(AsduError::Cause(Cause::Inro(17)))
    );
    let ov = InformationObject::new(
        1,
        Element::Double {
            state: DoublePoint::Off,
            quality: Quality::OV,
        },
    );
    assert!(matches!(
        Asdu::new(TypeId::M_DP_NA_1, Cause::Spont, 1, vec![ov]),
        Err(AsduError::Element { .. })
    ));
    // Normalized without quality but with time has no type.
    let nd = InformationObject::new(
        1,
        Element::Normalized {
            value: 1,
            quality: None,
        },
    )
    .with_time(time(0));
    assert!(Asdu::new(TypeId::M_ME_TD_1, Cause::Spont, 1, vec![nd]).is_err());
}

#[test]
fn cause_octet_carries_pn_and_test_bits() {
    let t = TypeId::C_SE_NC_1;
    let a = Asdu::new(t, Cause::Inro(16), 0xABCD, objects(t, 1, 1))
        .unwrap()
        .with_negative(true)
        .with_test(true)
        .with_originator(0x42)
        .with_common_address(0x0102);
    let b = a.encode();
    assert_eq!(&b[..6], &[50, 0x01, 0xC0 | 36, 0x42, 0x02, 0x01]);
    assert_eq!(Asdu::decode(&b).unwrap(), a);
    assert_eq!(element(t, 0), a.objects()[0].element);
}

/// `encode(decode(x)) == x` for well-formed frames: every sample ASDU in an
/// I frame, the hand-written frames above, S and U frames.
#[test]
fn encode_of_decode_is_identity_for_valid_frames() {
    let mut frames: Vec<Vec<u8>> = [
        "68 04 07 00 00 00",
        "68 04 0B 00 00 00",
        "68 04 13 00 00 00",
        "68 04 23 00 00 00",
        "68 04 43 00 00 00",
        "68 04 83 00 00 00",
        "68 04 01 00 FE FF",
        "68 0E 00 00 00 00 64 01 06 00 01 00 00 00 00 14",
        "68 12 02 00 04 00 0D 01 03 00 01 00 01 40 00 00 80 66 43 80",
        "68 15 00 00 00 00 1F 01 03 00 03 00 64 00 00 02 5F EA 3B 17 9D 02 18",
    ]
    .iter()
    .map(|s| hex(s))
    .collect();
    for (i, a) in sample_asdus().iter().enumerate() {
        let frame = Frame::I {
            send_seq: i as u16 * 97,
            recv_seq: 32767 - i as u16,
            asdu: a.encode(),
        };
        frames.push(apci::encode(&frame).unwrap());
    }
    for x in &frames {
        let (frame, used) = apci::decode(x).unwrap().unwrap();
        assert_eq!(used, x.len());
        assert_eq!(&apci::encode(&frame).unwrap(), x);
        if let Frame::I { asdu, .. } = &frame {
            assert_eq!(&Asdu::decode(asdu).unwrap().encode(), asdu);
        }
    }
    // The same frames back to back, as a socket would deliver them.
    let stream: Vec<u8> = frames.concat();
    let mut at = 0;
    let mut n = 0;
    while let Some((_, used)) = apci::decode(&stream[at..]).unwrap() {
        at += used;
        n += 1;
    }
    assert_eq!((at, n), (stream.len(), frames.len()));
}
