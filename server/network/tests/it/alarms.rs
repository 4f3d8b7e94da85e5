//! The network's system alarms on the demo ring: an earth switch closed on
//! a live section and a forbidden parallel stand while the state lasts, name
//! the device or the sources, and nothing stands in the normal state or
//! where only an unknown position could make it so.

use gridscada_network::alarms::{
    standing, EARTHED_LIVE_PRIORITY, FORBIDDEN_PARALLEL_PRIORITY, OVERRIDDEN_PARALLEL_PRIORITY,
};
use gridscada_network::model::Model;
use gridscada_network::*;

use crate::cases::{ring, Net};

fn alarms_of(m: &Model, pairs: &[(&str, Pos)]) -> Vec<NetworkAlarm> {
    let mut n = Inputs::normal(m);
    for (id, p) in pairs {
        n = n.with(m.switch(id).unwrap(), *p);
    }
    standing(m, &n, &compute(m, &n))
}

#[test]
fn the_normal_state_and_a_properly_earthed_cable_raise_nothing() {
    let m = ring();
    assert!(alarms_of(&m, &[]).is_empty());
    // C2 isolated at both ends, then earthed: as a programme leaves it.
    assert!(alarms_of(
        &m,
        &[
            ("rmu1_s2", Pos::Open),
            ("rmu2_s1", Pos::Open),
            ("rmu1_e2", Pos::Closed),
            ("rmu2_e2", Pos::Closed),
        ]
    )
    .is_empty());
}

#[test]
fn an_earth_switch_closed_on_a_live_cable_is_named_with_its_source() {
    let m = ring();
    let a = alarms_of(&m, &[("rmu1_e2", Pos::Closed)]);
    assert_eq!(a.len(), 1, "{a:?}");
    assert_eq!(a[0].key, "network:earthed_live:rmu1_e2");
    assert_eq!(a[0].priority, EARTHED_LIVE_PRIORITY);
    assert!(a[0].message.contains("RMU1_E2"), "{}", a[0].message);
    assert!(a[0].message.contains("c2"), "{}", a[0].message);
    assert!(a[0].message.contains("grid"), "{}", a[0].message);
    // Both ends earthed onto the live cable: one alarm per earth switch.
    let both = alarms_of(&m, &[("rmu1_e2", Pos::Closed), ("rmu2_e2", Pos::Closed)]);
    let keys: Vec<&str> = both.iter().map(|a| a.key.as_str()).collect();
    assert_eq!(
        keys,
        [
            "network:earthed_live:rmu1_e2",
            "network:earthed_live:rmu2_e2"
        ]
    );
}

#[test]
fn a_forbidden_parallel_stands_until_the_sources_are_apart() {
    let m = ring();
    let a = alarms_of(&m, &[("mg_pcc", Pos::Closed)]);
    assert_eq!(a.len(), 1, "{a:?}");
    assert_eq!(a[0].key, "network:parallel:grid+microgrid");
    assert_eq!(a[0].priority, FORBIDDEN_PARALLEL_PRIORITY);
    assert!(
        a[0].message.contains("grid + microgrid"),
        "{}",
        a[0].message
    );
    assert!(a[0].message.contains("must never"), "{}", a[0].message);
    // The transformer breaker behind CSS1 open: the microgrid is apart.
    assert!(alarms_of(&m, &[("mg_pcc", Pos::Closed), ("rmu2_t", Pos::Open)]).is_empty());
}

#[test]
fn an_overridable_parallel_is_a_lower_priority_alarm() {
    let m = Net::default()
        .source("grid", "ps_bb", "grid")
        .switch("f1", SwitchKind::CircuitBreaker, "ps_bb", "lv_bb", true)
        .switch("tie", SwitchKind::CircuitBreaker, "lv_bb", "gen_bb", true)
        .source("gen", "gen_bb", "generator")
        .parallel("grid", "generator", true)
        .build();
    let a = alarms_of(&m, &[]);
    assert_eq!(a.len(), 1, "{a:?}");
    assert_eq!(a[0].priority, OVERRIDDEN_PARALLEL_PRIORITY);
    assert!(a[0].message.contains("override"), "{}", a[0].message);
}

#[test]
fn what_only_an_unknown_position_could_cause_raises_nothing() {
    let m = ring();
    // The PCC's position unknown: the parallel is possible, not certain.
    assert!(alarms_of(&m, &[("mg_pcc", Pos::Unknown)]).is_empty());
    // The earth switch's position unknown.
    assert!(alarms_of(&m, &[("rmu1_e2", Pos::Unknown)]).is_empty());
}
