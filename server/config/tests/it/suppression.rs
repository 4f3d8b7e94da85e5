//! `[[suppression]]`: a rule loads with its defaults, a panel can turn its
//! built-in rule off, and every mistake is reported at its line with the
//! rule's name.

use std::fs;
use std::path::{Path, PathBuf};

use gridscada_config::load_path;

const TAGS: &str = r#"[[device]]
name = "D1"
protocol = "tcp"
address = "127.0.0.1:1502"

[[tag]]
name = "F1.Breaker.Closed"
device = "D1"
kind = "discrete_input"
address = 0
[[tag.alarm.discrete]]
when = false

[[tag]]
name = "F1.Volts"
device = "D1"
kind = "input_register"
address = 0
type = "f32"
[tag.alarm.lo]
limit = 200.0
"#;

fn plant_in(dir: &Path, extra: &str) -> PathBuf {
    fs::write(
        dir.join("gridscada.toml"),
        format!("tag_files = [\"tags.toml\"]\n{extra}"),
    )
    .unwrap();
    fs::write(dir.join("tags.toml"), TAGS).unwrap();
    dir.to_path_buf()
}

fn errors(extra: &str) -> Vec<String> {
    let dir = tempfile::tempdir().unwrap();
    match load_path(&plant_in(dir.path(), extra)) {
        Ok(_) => vec![],
        Err(d) => d.iter().map(|d| d.to_string()).collect(),
    }
}

const RULE: &str = r#"
[[suppression]]
name = "Feeder 1 trip"
trigger = "F1.Breaker.Closed:discrete"
suppress = [{ tag_prefix = "F1.Volts", kinds = ["lo", "lolo"] }]
"#;

#[test]
fn a_rule_loads_with_its_defaults() {
    let dir = tempfile::tempdir().unwrap();
    let p = load_path(&plant_in(dir.path(), RULE)).unwrap();
    let r = &p.suppression[0];
    assert_eq!(r.name.get_ref(), "Feeder 1 trip");
    assert_eq!(*r.release_delay_s.get_ref(), 10.0);
    assert_eq!(r.suppress.get_ref()[0].kinds.len(), 2);
}

#[test]
fn mistakes_are_located() {
    let cases: &[(&str, &str, &str)] = &[
        (
            "trigger = \"F1.Breaker.Closed:discrete\"",
            "trigger = \"F1.Breaker.Open:discrete\"",
            ":5:11: error: suppression 'Feeder 1 trip': trigger: no tag 'F1.Breaker.Open'",
        ),
        (
            "trigger = \"F1.Breaker.Closed:discrete\"",
            "trigger = \"F1.Volts:hi\"",
            ":5:11: error: suppression 'Feeder 1 trip': trigger: tag 'F1.Volts' has no hi alarm",
        ),
        (
            "trigger = \"F1.Breaker.Closed:discrete\"",
            "trigger = \"F1.Breaker.Closed\"",
            "is not an alarm key; write TAG:discrete",
        ),
        (
            "trigger = \"F1.Breaker.Closed:discrete\"",
            "trigger = \"D2:comm\"",
            "trigger: no device 'D2'",
        ),
        (
            "tag_prefix = \"F1.Volts\"",
            "tag_prefix = \"F2.\"",
            ":6:28: error: suppression 'Feeder 1 trip': no tag starting with 'F2.' has a lo/lolo alarm; this target suppresses nothing",
        ),
        (
            "kinds = [\"lo\", \"lolo\"]",
            "kinds = [\"hi\"]",
            "no tag starting with 'F1.Volts' has a hi alarm",
        ),
        (
            "kinds = [\"lo\", \"lolo\"]",
            "kinds = [\"low\"]",
            ":6:49: error: suppression 'Feeder 1 trip': unknown alarm kind 'low'; expected one of hihi, hi, lo, lolo, discrete",
        ),
        (
            "suppress = [{ tag_prefix = \"F1.Volts\", kinds = [\"lo\", \"lolo\"] }]",
            "suppress = []",
            ":6:12: error: suppression 'Feeder 1 trip': suppress is empty",
        ),
        (
            "suppress = [",
            "release_delay_s = -1\nsuppress = [",
            ":6:19: error: suppression 'Feeder 1 trip': release_delay_s must be 0 to 3600 seconds",
        ),
        (
            "suppress = [",
            "when = \"tripped\"\nsuppress = [",
            "unknown field `when`",
        ),
    ];
    for (from, to, want) in cases {
        let broken = RULE.replacen(from, to, 1);
        assert_ne!(broken, RULE, "case {from} -> {to} did not apply");
        let errs = errors(&broken);
        assert!(
            errs.iter().any(|e| e.contains(want)),
            "{from} -> {to}: want '{want}', got {errs:#?}"
        );
    }
    let twice = format!("{RULE}{RULE}");
    let errs = errors(&twice);
    assert!(
        errs.iter().any(|e| e
            .contains(":9:8: error: duplicate suppression name 'Feeder 1 trip' (first defined at")),
        "{errs:#?}"
    );
}
