//! `[reports]`: the schedule's defaults, and its errors located.

use std::fs;

use gridscada_config::load_path;

const TAGS: &str = r#"[[device]]
name = "D1"
protocol = "tcp"
address = "127.0.0.1:1502"

[[tag]]
name = "A.Volts"
device = "D1"
kind = "input_register"
address = 0
type = "f32"
"#;

fn load(extra: &str) -> Result<gridscada_config::Plant, Vec<gridscada_config::Diagnostic>> {
    let dir = tempfile::tempdir().unwrap();
    fs::write(dir.path().join("tags.toml"), TAGS).unwrap();
    fs::write(
        dir.path().join("gridscada.toml"),
        format!("tag_files = [\"tags.toml\"]\n{extra}"),
    )
    .unwrap();
    load_path(dir.path())
}

#[test]
fn both_reports_are_scheduled_by_default_and_can_be_turned_off() {
    let p = load("").unwrap();
    assert!(p.reports.daily && p.reports.monthly);
    assert_eq!(*p.reports.delay_min.get_ref(), 15.0);
    let p = load("[reports]\nmonthly = false\ndelay_min = 60\n").unwrap();
    assert!(p.reports.daily && !p.reports.monthly);
    assert_eq!(*p.reports.delay_min.get_ref(), 60.0);
}

#[test]
fn a_bad_delay_or_an_unknown_key_is_located() {
    let d = load("[reports]\ndaily = true\ndelay_min = 2000\n").unwrap_err();
    assert_eq!(d.len(), 1, "{d:?}");
    assert_eq!(d[0].line, 4, "{}", d[0]);
    assert!(d[0].message.contains("[reports] delay_min"), "{}", d[0]);
    let d = load("[reports]\nweekly = true\n").unwrap_err();
    assert_eq!(d[0].line, 3, "{}", d[0]);
    assert!(d[0].message.contains("weekly"), "{}", d[0]);
}

#[test]
fn the_currency_is_optional_and_an_iso_4217_code() {
    assert_eq!(load("").unwrap().reports.currency(), None);
    let p = load("[reports]\ncurrency = \"EUR\"\n").unwrap();
    assert_eq!(p.reports.currency(), Some("EUR"));
    for bad in ["eur", "EURO", "€", ""] {
        let d = load(&format!("[reports]\ndaily = true\ncurrency = \"{bad}\"\n")).unwrap_err();
        assert_eq!(d.len(), 1, "{bad}: {d:?}");
        assert_eq!(d[0].line, 4, "{}", d[0]);
        assert!(d[0].message.contains("[reports] currency"), "{}", d[0]);
        assert!(d[0].message.contains("ISO 4217"), "{}", d[0]);
    }
}
