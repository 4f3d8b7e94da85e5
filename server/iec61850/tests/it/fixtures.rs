//! Every packet libiec61850's server sent in the captures decodes through
//! our upper layers and MMS decoder; the reports, the LastApplError and the
//! command termination in them read as the capture's comments say.

use gridscada_iec61850::acsi::{command_termination, LastApplError, Report};
use gridscada_iec61850::ber::{Reader, Writer};
use gridscada_iec61850::data::Data;
use gridscada_iec61850::iso::{Addressing, Incoming, Stack, TpktDecoder};
use gridscada_iec61850::mms::{InformationReport, ObjectName, Pdu, Response};

pub fn fixture(name: &str) -> Vec<(bool, Vec<u8>)> {
    let path = format!("{}/tests/fixtures/{name}", env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{path}: {e}"));
    text.lines()
        .filter_map(|l| {
            let (from_server, hex) = match l.get(..2) {
                Some("< ") => (true, &l[2..]),
                Some("> ") => (false, &l[2..]),
                _ => return None,
            };
            let bytes = (0..hex.trim().len())
                .step_by(2)
                .map(|i| u8::from_str_radix(&hex.trim()[i..i + 2], 16).unwrap())
                .collect();
            Some((from_server, bytes))
        })
        .collect()
}

/// The server's packets of a fixture, peeled: what each carried.
pub fn server_side(name: &str) -> Vec<Incoming> {
    let mut stack = Stack::new(Addressing::default(), 1 << 20);
    let mut out = Vec::new();
    for (from_server, packet) in fixture(name) {
        if !from_server {
            continue;
        }
        let mut d = TpktDecoder::default();
        d.push(&packet);
        let payload = d.next_packet().unwrap().expect("a whole TPKT per line");
        match stack.receive(&payload) {
            Ok(Incoming::Partial) => {}
            Ok(i) => out.push(i),
            Err(e) => panic!("{name}: {e}"),
        }
    }
    out
}

fn pdus(name: &str) -> Vec<Pdu> {
    server_side(name)
        .into_iter()
        .filter_map(|i| match i {
            Incoming::Mms(p) | Incoming::Accepted(p) => {
                Some(Pdu::decode(&p).unwrap_or_else(|e| panic!("{name}: {e}")))
            }
            _ => None,
        })
        .collect()
}

#[test]
fn the_association_is_accepted_with_the_servers_limits() {
    let incoming = server_side("associate.hex");
    assert_eq!(incoming[0], Incoming::Connected);
    let Incoming::Accepted(initiate) = &incoming[1] else {
        panic!("{:?}", incoming[1])
    };
    let Pdu::InitiateResponse(n) = Pdu::decode(initiate).unwrap() else {
        panic!()
    };
    assert!(n.max_pdu >= 1000 && n.max_outstanding >= 1, "{n:?}");
}

#[test]
fn read_responses_decode_and_re_encode() {
    let mut values = 0;
    for p in pdus("read.hex") {
        if let Pdu::Response {
            response: Response::Read(results),
            ..
        } = p
        {
            for r in results.into_iter().flatten() {
                let mut w = Writer::new();
                r.encode(&mut w);
                let back = Data::decode(&Reader::new(&w.buf).read("data").unwrap()).unwrap();
                assert_eq!(back, r);
                values += 1;
            }
        }
    }
    assert!(values >= 5, "{values} values");
}

#[test]
fn reports_decode_with_their_entry_ids() {
    let reports: Vec<Report> = pdus("report.hex")
        .into_iter()
        .filter_map(|p| match p {
            Pdu::InformationReport(r) if Report::is_report(&r) => Some(Report::decode(&r).unwrap()),
            _ => None,
        })
        .collect();
    assert!(reports.len() >= 2, "{} reports", reports.len());
    for r in &reports {
        assert_eq!(r.rpt_id, "brcb01");
        assert_eq!(r.entry_id.as_ref().map(Vec::len), Some(8), "{r:?}");
        assert!(!r.entries.is_empty());
    }
}

#[test]
fn a_refused_control_names_its_cause_and_enhanced_controls_terminate() {
    let reports: Vec<InformationReport> = pdus("control.hex")
        .into_iter()
        .filter_map(|p| match p {
            Pdu::InformationReport(r) => Some(r),
            _ => None,
        })
        .collect();
    let errors: Vec<LastApplError> = reports
        .iter()
        .filter_map(LastApplError::from_report)
        .collect();
    assert!(errors.iter().any(|e| e.add_cause == 10), "{errors:?}");
    let oper = ObjectName::Domain("TESTLD0".into(), "CSWI1$CO$Pos$Oper".into());
    assert!(
        reports
            .iter()
            .any(|r| command_termination(r, &oper) == Some(Ok(()))),
        "no positive CommandTermination of CSWI1.Pos"
    );
}
