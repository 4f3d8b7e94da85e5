//! The SCL reader on the test IED's SCL (written by
//! tests/e2e/iec61850_peer.py from the model libiec61850 serves), on an SCD
//! of many IEDs, and on broken files: located errors, never a panic.

use gridscada_scl::{import, read_bytes, Filter, Resolved};

fn test_scd() -> Vec<u8> {
    std::fs::read(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/test.scd")).unwrap()
}

/// An SCD of `n` copies of the test IED (`IED0`, `IED1`, …), each with its
/// own address.
pub fn many_ieds(n: usize) -> Vec<u8> {
    let text = String::from_utf8(test_scd()).unwrap();
    let ied_start = text.find("<IED ").unwrap();
    let ied_end = text.find("</IED>").unwrap() + "</IED>".len();
    let ied = &text[ied_start..ied_end];
    let ap_start = text.find("<ConnectedAP").unwrap();
    let ap_end = text.find("</ConnectedAP>").unwrap() + "</ConnectedAP>".len();
    let ap = &text[ap_start..ap_end];
    let mut aps = String::new();
    let mut ieds = String::new();
    for i in 0..n {
        aps.push_str(
            &ap.replace("iedName=\"TEST\"", &format!("iedName=\"IED{i}\""))
                .replace("127.0.0.1", &format!("10.0.{}.{}", i / 250, i % 250 + 1)),
        );
        ieds.push_str(&ied.replace("name=\"TEST\"", &format!("name=\"IED{i}\"")));
    }
    format!(
        "{}{aps}{}{ieds}{}",
        &text[..ap_start],
        &text[ap_end..ied_start],
        &text[ied_end..]
    )
    .into_bytes()
}

#[test]
fn the_test_ied_reads_and_resolves() {
    let scl = read_bytes("test.scd", &test_scd(), &Filter::default()).unwrap();
    assert_eq!(scl.all_ied_names, vec!["TEST"]);
    let ied = &scl.ieds[0];
    assert_eq!(ied.ldevices[0].name("TEST"), "TESTLD0");
    let cswi = ied.ldevices[0]
        .lns
        .iter()
        .find(|l| l.name() == "CSWI1")
        .unwrap();
    assert_eq!(
        scl.templates
            .resolve(&cswi.ln_type, &["Pos", "stVal"], Some("ST")),
        Ok(Resolved::Attribute {
            b_type: "Dbpos".into(),
            fc: "ST".into(),
            type_id: String::new()
        })
    );
    assert!(scl
        .templates
        .resolve(&cswi.ln_type, &["Pos", "stVal"], Some("MX"))
        .is_err());
    assert!(scl
        .templates
        .resolve(&cswi.ln_type, &["Nope"], None)
        .unwrap_err()
        .contains("no data object 'Nope'"));
    let imp = import::import(&scl, ied);
    assert!(imp
        .tags
        .iter()
        .any(|t| t.reference == "TESTLD0/MMXU1.PhV.phsA.cVal.mag.f" && t.units == "kV"));
    assert_eq!(imp.reports.len(), 1);
    assert!(imp
        .address
        .ends_with(&format!(":{}", scl.addresses["TEST"].port.unwrap())));
}

#[test]
fn one_ied_of_many_is_kept() {
    let scd = many_ieds(50);
    let scl = read_bytes(
        "many.scd",
        &scd,
        &Filter {
            ieds: vec!["IED37".into()],
        },
    )
    .unwrap();
    assert_eq!(scl.all_ied_names.len(), 50);
    assert_eq!(scl.ieds.len(), 1);
    assert_eq!(scl.ieds[0].name, "IED37");
    assert_eq!(scl.addresses["IED37"].ip.as_deref(), Some("10.0.0.38"));
}

#[test]
fn broken_files_are_located_errors() {
    let good = String::from_utf8(test_scd()).unwrap();
    let cases: Vec<(String, &str)> = vec![
        (good.replacen("</LN0>", "", 1), "expected `</LN0>`"),
        (
            good[..good.find("<DataTypeTemplates>").unwrap()].to_string(),
            "ends inside",
        ),
        (
            good.replacen(
                "<LN0 lnClass=\"LLN0\" inst=\"\" lnType=\"LLN0_T\">",
                "<LN0 inst=\"\" lnType=\"LLN0_T\">",
                1,
            ),
            "without its lnClass",
        ),
        (
            good.replacen("<SCL ", "<Scl ", 1)
                .replacen("</SCL>", "</Scl>", 1),
            "not <SCL>",
        ),
        (
            good.replacen("confRev=\"1\"", "confRev=\"one\"", 1),
            "confRev=\"one\" is not a number",
        ),
        (
            good.replacen("<Val>on</Val>", "<Val>on &bogus; </Val>", 1),
            "bogus",
        ),
        ("<SCL>".to_string() + &"<a>".repeat(100), "deeper than 64"),
        (String::new(), "no <SCL>"),
    ];
    for (text, want) in cases {
        let e = read_bytes("bad.scd", text.as_bytes(), &Filter::default()).unwrap_err();
        let shown = e.to_string();
        assert!(shown.contains(want), "{shown} (wanted '{want}')");
        assert!(shown.starts_with("bad.scd:") && e.line >= 1, "{shown}");
    }
    // Where: the missing lnClass is on the line of its LN0.
    let text = good.replacen("<LN0 lnClass=\"LLN0\"", "<LN0", 1);
    let e = read_bytes("bad.scd", text.as_bytes(), &Filter::default()).unwrap_err();
    let line_of = text[..text.find("<LN0").unwrap()].matches('\n').count() as u64 + 1;
    assert_eq!(e.line, line_of, "{e}");
}

#[test]
fn mutated_files_never_panic() {
    let good = test_scd();
    let mut x: u64 = 0x5c1_0000_0001;
    let mut next = || {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        x
    };
    for _ in 0..3000 {
        let mut b = good.clone();
        for _ in 0..1 + next() % 6 {
            let i = (next() % b.len() as u64) as usize;
            match next() % 3 {
                0 => b[i] = next() as u8,
                1 => b[i] = b"<>/\"=&"[(next() % 6) as usize],
                _ => {
                    b.truncate(i.max(1));
                }
            }
        }
        let _ = read_bytes("m.scd", &b, &Filter::default());
    }
}
