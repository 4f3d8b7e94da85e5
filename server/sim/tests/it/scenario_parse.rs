//! The scenario format: a good file parses into the expected model, and
//! broken files get located errors (file:line:column), several at once.

use std::path::Path;
use std::time::Duration;

use gridscada_config::SourceFile;
use gridscada_sim::scenario::{self, Action, ExpectKind, ExpectValue, Scenario};

fn parse_with(
    text: &str,
    csv: &[(&str, &str)],
) -> Result<Scenario, Vec<gridscada_config::Diagnostic>> {
    let file = SourceFile::new("/s/test.toml", text.to_string());
    let csv: Vec<(String, String)> = csv
        .iter()
        .map(|(a, b)| (a.to_string(), b.to_string()))
        .collect();
    scenario::parse(&file, &mut |p: &Path| {
        csv.iter()
            .find(|(name, _)| p == Path::new("/s").join(name))
            .map(|(_, t)| t.clone())
            .ok_or_else(|| std::io::Error::new(std::io::ErrorKind::NotFound, "no such file"))
    })
}

fn errors(text: &str) -> Vec<(usize, usize, String)> {
    match parse_with(text, &[]) {
        Ok(_) => panic!("expected errors"),
        Err(d) => d
            .into_iter()
            .map(|d| (d.line, d.column, d.message))
            .collect(),
    }
}

const GOOD: &str = r#"
name = "t"
duration = "00:10:00"
step = "500ms"
start = "2024-06-21T10:00:00Z"
seed = 9

[[initial.unit]]
id = "bess1"
soc_pct = 30

[profile.demand]
csv = "p.csv"
column = "kw"
noise = 0.1

[[profile.zone]]
panel = "ss1"
zone = 2
points = [["00:00", 1.0], ["00:05", 3.0]]

[[event]]
at = "00:02:00"
action = "repair"
panel = "ss1"
zone = 2

[[event]]
at = "00:01:00"
action = "fault"
panel = "ss1"
zone = 2
kind = "transient"

[[expect]]
at = "00:02:00"
tag = "SS1.Zone2.Closed"
value = false

[[expect]]
figure = "unserved_kwh"
value = 0
tolerance = 0.5
"#;

#[test]
fn a_good_scenario_parses() {
    let s = parse_with(GOOD, &[("p.csv", "time,kw\n00:00,50\n00:10,70\n")]).unwrap();
    assert_eq!(s.duration, Duration::from_secs(600));
    assert_eq!(s.step, Duration::from_millis(500));
    assert_eq!(s.seed, 9);
    assert_eq!(s.start.as_millis(), 1_718_964_000_000);
    // Sorted by time.
    assert!(matches!(s.events[0].action, Action::Fault { zone: 2, .. }));
    assert_eq!(s.events[0].at, Duration::from_secs(60));
    let d = s.profiles.demand.as_ref().unwrap();
    assert_eq!(d.points.len(), 2);
    assert_eq!(
        s.profiles.zones[0].kw.value_at(Duration::from_secs(150), 0),
        2.0
    );
    assert!(matches!(
        &s.expectations[0].kind,
        ExpectKind::Tag {
            value: ExpectValue::Bool(false),
            ..
        }
    ));
    match &s.expectations[1].kind {
        ExpectKind::Figure { bound, .. } => {
            assert_eq!((bound.min, bound.max), (Some(-0.5), Some(0.5)))
        }
        _ => panic!(),
    }
    assert_eq!(s.initial.units[0].soc_pct, Some(30.0));
}

#[test]
fn toml_syntax_errors_are_located() {
    let e = errors("name = \"x\"\nduration = \n");
    assert_eq!(e[0].0, 2, "{e:?}");
    assert!(e[0].2.starts_with("TOML syntax error"), "{e:?}");
}

#[test]
fn several_problems_are_reported_at_once_with_positions() {
    let text = r#"name = "x"
duration = "10 fortnights"
colour = "blue"

[[event]]
at = "00:01:00"
action = "explode"
panel = "ss1"

[[event]]
at = "00:01:00"
action = "fault"
zone = 2

[[expect]]
figure = "unserved_kwh"
"#;
    let e = errors(text);
    let at = |line: usize| {
        e.iter()
            .find(|d| d.0 == line)
            .unwrap_or_else(|| panic!("no error on line {line}: {e:?}"))
    };
    assert!(at(2).2.contains("not a time"), "{e:?}");
    assert_eq!(at(2).1, 12);
    assert!(at(3).2.contains("unknown key 'colour'"));
    assert!(at(7).2.contains("unknown action 'explode'"));
    assert_eq!(at(7).1, 10);
    assert!(at(10).2.contains("needs 'panel'"), "{e:?}");
    assert!(at(15).2.contains("needs a numeric 'value'"), "{e:?}");
}

#[test]
fn unknown_fields_and_wrong_types_are_located() {
    let text = "name = \"x\"\nduration = 60\n\n[[event]]\nat = 5\naction = \"reset\"\npanel = \"ss1\"\nspeed = 3\n\n[[expect]]\nat = \"00:00:10\"\ntag = \"A\"\nvalue = true\ntolerance = \"big\"\n";
    let e = errors(text);
    assert!(
        e.iter()
            .any(|d| d.0 == 8 && d.2.contains("unknown field `speed`")),
        "{e:?}"
    );
    assert!(
        e.iter()
            .any(|d| (d.0, d.1) == (14, 13) && d.2.contains("invalid type")),
        "{e:?}"
    );
}

#[test]
fn events_after_the_end_and_bad_csv_are_located() {
    let text = "name = \"x\"\nduration = \"00:01:00\"\n\n[profile.demand]\ncsv = \"d.csv\"\n\n[[event]]\nat = \"00:02:00\"\naction = \"reset\"\npanel = \"ss1\"\n";
    let e = parse_with(text, &[("d.csv", "time,kw\n0,1\n30,oops\n")]).unwrap_err();
    assert!(
        e.iter()
            .any(|d| d.file.ends_with("d.csv") && d.line == 3 && d.column == 4),
        "{e:?}"
    );
    assert!(
        e.iter()
            .any(|d| d.line == 7 && d.message.contains("after the end")),
        "{e:?}"
    );
    let e = parse_with(
        "name = \"x\"\nduration = 60\n[profile.demand]\ncsv = \"missing.csv\"\n",
        &[],
    )
    .unwrap_err();
    assert_eq!((e[0].line, e[0].column), (4, 7), "{e:?}");
    assert!(e[0].message.contains("cannot read"));
}

#[test]
fn names_are_checked_against_the_plant() {
    let plant =
        gridscada_config::load_path(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tags"))
            .expect("demo plant");
    let text = r#"name = "x"
duration = "00:05:00"

[[event]]
at = 10
action = "fault"
panel = "ss9"
zone = 1

[[event]]
at = 10
action = "fault"
panel = "ss1"
zone = 7

[[event]]
at = 10
action = "set_soc"
unit = "pv1"
soc_pct = 50

[[event]]
at = 10
action = "comm_loss"
device = "SS1.IO9"

[[event]]
at = 10
action = "breaker"
panel = "ss1"
breaker = "zone9"
close = true

[[expect]]
at = 20
tag = "SS1.Nope"
value = 1

[[expect]]
figure = "happiness"
min = 1
"#;
    let s = parse_with(text, &[]).unwrap();
    let d = s.check_against(&plant, &|t| plant.tag(t).is_some());
    let lines: Vec<(usize, &str)> = d.iter().map(|d| (d.line, d.message.as_str())).collect();
    let has = |line: usize, text: &str| lines.iter().any(|(l, m)| *l == line && m.contains(text));
    assert!(has(7, "no panel 'ss9'"), "{lines:?}");
    assert!(has(14, "no zone 7"), "{lines:?}");
    assert!(has(19, "not a storage unit"), "{lines:?}");
    assert!(has(25, "no device"), "{lines:?}");
    assert!(has(31, "'zone9' is not a breaker"), "{lines:?}");
    assert!(has(36, "no tag 'SS1.Nope'"), "{lines:?}");
    assert!(has(40, "not a report figure"), "{lines:?}");
    assert_eq!(d.len(), 7, "{lines:?}");
}

#[test]
fn shipped_scenarios_parse_and_match_the_demo_plant() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let plant = gridscada_config::load_path(&root.join("tags")).expect("demo plant");
    let mut n = 0;
    for entry in std::fs::read_dir(root.join("scenarios")).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().and_then(|e| e.to_str()) != Some("toml") {
            continue;
        }
        let s = scenario::load_path(&path).unwrap_or_else(|d| panic!("{}: {d:?}", path.display()));
        // Derived tags (Seq, Comm) are not in the plant's tag list; accept
        // names under a panel prefix or device for this check.
        let d = s.check_against(&plant, &|t| {
            plant.tag(t).is_some() || t.contains(".Seq.") || t.contains(".Comm.")
        });
        assert!(d.is_empty(), "{}: {d:?}", path.display());
        assert!(
            !s.expectations.is_empty(),
            "{} has no expectations",
            path.display()
        );
        n += 1;
    }
    assert!(n >= 7, "only {n} scenarios shipped");
}
