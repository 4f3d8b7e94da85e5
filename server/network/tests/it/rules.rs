//! Each interlock rule fires on the demo ring with its id and words, and an
//! allowed operation meets none.

use gridscada_network::*;

use crate::cases::ring;

fn check(inputs: &Inputs, device: &str, op: Operation) -> Vec<Interlock> {
    let m = ring();
    let i = m.switch(device).unwrap();
    let before = compute(&m, inputs);
    let after = compute(&m, &inputs.with(i, op.target()));
    let p = preview(&m, &before, &after);
    interlocks(&m, inputs, &before, &after, &p, i, op)
}

fn rules(found: &[Interlock]) -> Vec<RuleId> {
    found.iter().map(|i| i.rule).collect()
}

fn with(pairs: &[(&str, Pos)]) -> Inputs {
    let m = ring();
    let mut n = Inputs::normal(&m);
    for (id, p) in pairs {
        n = n.with(m.switch(id).unwrap(), *p);
    }
    n
}

#[test]
fn ordinary_switching_meets_no_interlock() {
    let n = with(&[]);
    assert!(check(&n, "f1", Operation::Open).is_empty());
    assert!(
        check(&n, "rmu2_s2", Operation::Close).is_empty(),
        "closing NOP1: one source"
    );
    assert!(check(
        &with(&[("rmu1_s2", Pos::Open), ("rmu2_s1", Pos::Open)]),
        "rmu1_e2",
        Operation::Close
    )
    .is_empty());
}

#[test]
fn closing_onto_an_earthed_cable_is_refused_without_override() {
    let n = with(&[
        ("rmu1_s2", Pos::Open),
        ("rmu2_s1", Pos::Open),
        ("rmu1_e2", Pos::Closed),
    ]);
    let found = check(&n, "rmu1_s2", Operation::Close);
    assert_eq!(rules(&found), [RuleId::ClosingOntoEarthed]);
    assert!(!found[0].overridable);
    assert!(found[0].text.contains("c2 is earthed"), "{}", found[0].text);
}

#[test]
fn earthing_a_live_or_unproved_section_is_refused() {
    let found = check(&with(&[]), "rmu1_e2", Operation::Close);
    assert_eq!(rules(&found), [RuleId::EarthingEnergised]);
    let n = with(&[("rmu2_s1", Pos::Open), ("rmu1_s2", Pos::Unknown)]);
    let found = check(&n, "rmu2_e2", Operation::Close);
    assert_eq!(rules(&found), [RuleId::EarthingEnergised]);
    assert!(
        found[0].text.contains("not proved dead"),
        "{}",
        found[0].text
    );
}

#[test]
fn paralleling_grid_and_microgrid_is_refused() {
    let found = check(&with(&[]), "mg_pcc", Operation::Close);
    assert_eq!(rules(&found), [RuleId::ForbiddenParallel]);
    assert!(
        found[0].text.contains("grid + microgrid"),
        "{}",
        found[0].text
    );
    assert!(!found[0].overridable);
}

#[test]
fn a_device_of_unknown_position_cannot_be_operated() {
    let found = check(
        &with(&[("rmu2_s2", Pos::Unknown)]),
        "rmu2_s2",
        Operation::Close,
    );
    assert_eq!(rules(&found), [RuleId::StateUnknown]);
}

#[test]
fn rule_ids_read_back() {
    for r in [
        RuleId::SafetyTag,
        RuleId::DisconnectorUnderLoad,
        RuleId::StateUnknown,
    ] {
        assert_eq!(RuleId::parse(r.as_str()), Some(r));
    }
}

#[test]
fn a_disconnector_may_not_break_or_make_load_current_unless_a_supervisor_overrides() {
    use crate::cases::Net;
    let m = Net::default()
        .source("grid", "a_bb", "grid")
        .switch("d", SwitchKind::Disconnector, "a_bb", "b_bb", true)
        .load("shop", "b_bb", 10)
        .switch("d2", SwitchKind::Disconnector, "a_bb", "c_bb", true)
        .build();
    let n = Inputs::normal(&m);
    let run = |inputs: &Inputs, dev: &str, op: Operation| {
        let i = m.switch(dev).unwrap();
        let before = compute(&m, inputs);
        let after = compute(&m, &inputs.with(i, op.target()));
        let p = preview(&m, &before, &after);
        interlocks(&m, inputs, &before, &after, &p, i, op)
    };
    let found = run(&n, "d", Operation::Open);
    assert_eq!(rules(&found), [RuleId::DisconnectorUnderLoad]);
    assert!(found[0].overridable);
    assert!(found[0].text.contains("10 customers"), "{}", found[0].text);
    // No load behind it: it only breaks the charging current.
    assert!(run(&n, "d2", Operation::Open).is_empty());
    let open = n.with(m.switch("d").unwrap(), Pos::Open);
    assert_eq!(
        rules(&run(&open, "d", Operation::Close)),
        [RuleId::DisconnectorUnderLoad]
    );
}

#[test]
fn a_listed_pair_parallels_freely_or_under_a_supervisors_override() {
    use crate::cases::Net;
    let build = |overridable| {
        Net::default()
            .source("grid_a", "a_bb", "grid_a")
            .source("grid_b", "b_bb", "grid_b")
            .switch(
                "bus_section",
                SwitchKind::CircuitBreaker,
                "a_bb",
                "b_bb",
                false,
            )
            .parallel("grid_a", "grid_b", overridable)
            .build()
    };
    for (overridable, want) in [(false, vec![]), (true, vec![RuleId::ForbiddenParallel])] {
        let m = build(overridable);
        let n = Inputs::normal(&m);
        let i = m.switch("bus_section").unwrap();
        let before = compute(&m, &n);
        let after = compute(&m, &n.with(i, Pos::Closed));
        let p = preview(&m, &before, &after);
        let found = interlocks(&m, &n, &before, &after, &p, i, Operation::Close);
        assert_eq!(rules(&found), want);
        assert!(found.iter().all(|f| f.overridable));
    }
}
