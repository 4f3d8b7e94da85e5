//! Hand cases: a radial feeder, an 11 kV ring with two normally-open points
//! and LV substations behind transformers, earthing, unknown positions,
//! a microgrid that must not parallel the grid.

use gridscada_network::model::{Model, ParallelPermission};
use gridscada_network::*;

/// A small network built by ids.
#[derive(Default)]
pub struct Net {
    spec: Spec,
}

impl Net {
    fn node_idx(&mut self, id: &str) -> usize {
        if let Some(i) = self.spec.nodes.iter().position(|n| n.id == id) {
            return i;
        }
        self.spec.nodes.push(NodeSpec {
            id: id.into(),
            busbar: id.ends_with("_bb"),
            ..NodeSpec::default()
        });
        self.spec.nodes.len() - 1
    }
    fn group(&mut self, g: &str) -> usize {
        if let Some(i) = self.spec.groups.iter().position(|x| x == g) {
            return i;
        }
        self.spec.groups.push(g.into());
        self.spec.groups.len() - 1
    }
    pub fn cable(mut self, id: &str, from: &str, to: &str) -> Self {
        let (from, to) = (self.node_idx(from), self.node_idx(to));
        self.spec.branches.push(BranchSpec {
            id: id.into(),
            kind: BranchKind::Cable,
            from,
            to,
        });
        self
    }
    pub fn transformer(mut self, id: &str, from: &str, to: &str) -> Self {
        let (from, to) = (self.node_idx(from), self.node_idx(to));
        self.spec.branches.push(BranchSpec {
            id: id.into(),
            kind: BranchKind::Transformer,
            from,
            to,
        });
        self
    }
    pub fn switch(
        mut self,
        id: &str,
        kind: SwitchKind,
        from: &str,
        to: &str,
        closed: bool,
    ) -> Self {
        let (from, to) = (self.node_idx(from), self.node_idx(to));
        self.spec.switches.push(SwitchSpec {
            id: id.into(),
            name: id.to_uppercase(),
            kind,
            from,
            to: Some(to),
            normally_closed: closed,
        });
        self
    }
    pub fn earth(mut self, id: &str, at: &str) -> Self {
        let from = self.node_idx(at);
        self.spec.switches.push(SwitchSpec {
            id: id.into(),
            name: id.to_uppercase(),
            kind: SwitchKind::EarthSwitch,
            from,
            to: None,
            normally_closed: false,
        });
        self
    }
    pub fn source(mut self, id: &str, at: &str, group: &str) -> Self {
        let (node, group) = (self.node_idx(at), self.group(group));
        self.spec.sources.push(SourceSpec {
            id: id.into(),
            name: id.into(),
            node,
            group,
        });
        self
    }
    pub fn load(mut self, id: &str, at: &str, customers: u32) -> Self {
        let node = self.node_idx(at);
        self.spec.loads.push(LoadSpec {
            id: id.into(),
            node,
            customers,
        });
        self
    }
    pub fn parallel(mut self, a: &str, b: &str, overridable: bool) -> Self {
        let groups = (self.group(a), self.group(b));
        self.spec.parallel.push(ParallelRule {
            groups,
            overridable,
        });
        self
    }
    pub fn build(self) -> Model {
        Model::build(self.spec).unwrap()
    }
}

use SwitchKind::*;

/// The demo's 11 kV network: two feeders from one primary busbar round a
/// ring of three RMUs, NOP1 (rmu2_s2) and NOP2 (rmu3_s3) open; a transformer
/// behind each RMU; a microgrid that may join CSS1's LV side through its
/// PCC breaker.
pub fn ring() -> Model {
    Net::default()
        .source("grid", "ps_bb", "grid")
        .switch("f1", CircuitBreaker, "ps_bb", "f1_out", true)
        .switch("f2", CircuitBreaker, "ps_bb", "f2_out", true)
        .cable("c1", "f1_out", "rmu1_c1")
        .switch("rmu1_s1", LoadBreakSwitch, "rmu1_c1", "rmu1_bb", true)
        .switch("rmu1_s2", LoadBreakSwitch, "rmu1_bb", "rmu1_c2", true)
        .switch("rmu1_s3", LoadBreakSwitch, "rmu1_bb", "rmu1_c5", true)
        .switch("rmu1_t", CircuitBreaker, "rmu1_bb", "rmu1_tx", true)
        .earth("rmu1_e2", "rmu1_c2")
        .cable("c2", "rmu1_c2", "rmu2_c2")
        .switch("rmu2_s1", LoadBreakSwitch, "rmu2_c2", "rmu2_bb", true)
        .switch("rmu2_s2", LoadBreakSwitch, "rmu2_bb", "rmu2_c3", false)
        .switch("rmu2_t", CircuitBreaker, "rmu2_bb", "rmu2_tx", true)
        .earth("rmu2_e2", "rmu2_c2")
        .cable("c3", "rmu2_c3", "rmu3_c3")
        .switch("rmu3_s1", LoadBreakSwitch, "rmu3_c3", "rmu3_bb", true)
        .switch("rmu3_s2", LoadBreakSwitch, "rmu3_bb", "rmu3_c4", true)
        .switch("rmu3_s3", LoadBreakSwitch, "rmu3_c5", "rmu3_bb", false)
        .switch("rmu3_t", Fuse, "rmu3_bb", "rmu3_tx", true)
        .cable("c4", "rmu3_c4", "f2_out")
        .cable("c5", "rmu1_c5", "rmu3_c5")
        .transformer("tx1", "rmu1_tx", "ss1_in")
        .transformer("tx2", "rmu2_tx", "css1_in")
        .transformer("tx3", "rmu3_tx", "estate_lv")
        .switch("ss1_elcb", CircuitBreaker, "ss1_in", "ss1_bb", true)
        .switch("ss1_z1", CircuitBreaker, "ss1_bb", "ss1_z1", true)
        .load("ss1_zone1", "ss1_z1", 25)
        .switch("ss1_z2", CircuitBreaker, "ss1_bb", "ss1_z2", true)
        .load("ss1_zone2", "ss1_z2", 40)
        .switch("css1_elcb", CircuitBreaker, "css1_in", "css1_bb", true)
        .load("css1_load", "css1_bb", 4)
        .load("estate", "estate_lv", 120)
        .switch("mg_pcc", CircuitBreaker, "css1_in", "mg_bb", false)
        .source("bess1", "mg_bb", "microgrid")
        .source("dg1", "mg_bb", "microgrid")
        .build()
}

fn sec(m: &Model, id: &str) -> u32 {
    m.section(id).unwrap_or_else(|| panic!("no section {id}"))
}
fn sw(m: &Model, id: &str) -> usize {
    m.switch(id).unwrap_or_else(|| panic!("no switch {id}"))
}
fn state(m: &Model, t: &Topology, id: &str) -> SectionState {
    t.state[sec(m, id) as usize]
}

#[test]
fn lines_and_cables_join_nodes_into_sections_named_by_busbar_or_cable() {
    let m = ring();
    // f1_out and rmu1_c1 are one section, named after the cable.
    assert_eq!(
        m.node_section[m.nodes.iter().position(|n| n.id == "f1_out").unwrap()],
        sec(&m, "c1")
    );
    assert_eq!(
        m.node_section[m.nodes.iter().position(|n| n.id == "rmu1_c1").unwrap()],
        sec(&m, "c1")
    );
    assert!(m.section("ps_bb").is_some());
    assert!(m.section("rmu1_bb").is_some());
    assert!(m.section("f1_out").is_none());
    // The transformer does not join: its two sides are two sections.
    assert_ne!(sec(&m, "rmu1_tx"), sec(&m, "ss1_in"));
}

#[test]
fn in_the_normal_state_everything_is_fed_from_the_grid_with_no_loop() {
    let m = ring();
    let t = compute(&m, &Inputs::normal(&m));
    for (i, s) in m.sections.iter().enumerate() {
        // The microgrid runs islanded on its own; the rest from the grid.
        assert_eq!(t.state[i], SectionState::Energised, "{}", s.id);
    }
    assert_eq!(t.loops(), 0);
    assert_eq!(t.customers_off, 0);
    let grid = m.sources.iter().position(|s| s.id == "grid").unwrap();
    assert_eq!(t.sources_of(sec(&m, "estate_lv")), [grid]);
    // The microgrid's two units run in parallel (one group: allowed).
    assert_eq!(t.parallels.len(), 1);
    assert_eq!(t.parallels[0].permission, ParallelPermission::Allowed);
}

#[test]
fn opening_a_feeder_breaker_takes_its_side_of_the_ring_dead_through_the_transformers() {
    let m = ring();
    let before = Inputs::normal(&m);
    let after = before.with(sw(&m, "f1"), Pos::Open);
    let t = compute(&m, &after);
    for id in [
        "c1", "rmu1_bb", "c2", "c5", "rmu2_bb", "rmu1_tx", "ss1_in", "ss1_bb", "css1_bb", "rmu2_tx",
    ] {
        assert_eq!(state(&m, &t, id), SectionState::Dead, "{id}");
    }
    for id in ["ps_bb", "c4", "rmu3_bb", "c3", "estate_lv"] {
        assert_eq!(state(&m, &t, id), SectionState::Energised, "{id}");
    }
    let p = preview(&m, &compute(&m, &before), &t);
    assert_eq!(p.customers_lose, 25 + 40 + 4);
    assert!(p.lose_supply.contains(&sec(&m, "ss1_z2")));
    assert!(p.gain_supply.is_empty());
}

#[test]
fn closing_a_normally_open_point_makes_a_loop_of_one_source_not_a_parallel() {
    let m = ring();
    let before = compute(&m, &Inputs::normal(&m));
    let after = compute(&m, &Inputs::normal(&m).with(sw(&m, "rmu2_s2"), Pos::Closed));
    assert_eq!(after.loops(), 1);
    let p = preview(&m, &before, &after);
    assert_eq!((p.loops_before, p.loops_after), (0, 1));
    assert!(p.new_parallels.is_empty());
    assert!(p.lose_supply.is_empty() && p.gain_supply.is_empty());
}

#[test]
fn closing_the_pcc_parallels_grid_and_microgrid_which_is_forbidden() {
    let m = ring();
    let inputs = Inputs::normal(&m);
    let before = compute(&m, &inputs);
    let pcc = sw(&m, "mg_pcc");
    let after = compute(&m, &inputs.with(pcc, Pos::Closed));
    let p = preview(&m, &before, &after);
    assert_eq!(p.new_parallels.len(), 1);
    assert_eq!(p.new_parallels[0].permission, ParallelPermission::Forbidden);
    assert_eq!(p.new_parallels[0].sources.len(), 3);
    // Backfeed: with F1 open and the PCC closed, the microgrid feeds RMU2
    // through TX2, and nothing else of F1's side.
    let islanded = inputs.with(sw(&m, "f1"), Pos::Open).with(pcc, Pos::Closed);
    let t = compute(&m, &islanded);
    assert_eq!(state(&m, &t, "rmu2_bb"), SectionState::Energised);
    assert_eq!(
        state(&m, &t, "c1"),
        SectionState::Energised,
        "back through c2 and rmu1"
    );
    let bess = m.sources.iter().position(|s| s.id == "bess1").unwrap();
    assert!(t.sources_of(sec(&m, "rmu2_bb")).contains(&bess));
}

#[test]
fn an_earth_switch_earths_a_dead_cable_and_marks_a_live_one_as_an_earth_fault() {
    let m = ring();
    let n = Inputs::normal(&m);
    let iso = n
        .with(sw(&m, "rmu1_s2"), Pos::Open)
        .with(sw(&m, "rmu2_s1"), Pos::Open)
        .with(sw(&m, "rmu1_e2"), Pos::Closed);
    let t = compute(&m, &iso);
    assert_eq!(state(&m, &t, "c2"), SectionState::Earthed);
    assert_eq!(
        state(&m, &t, "rmu2_bb"),
        SectionState::Dead,
        "NOP1 open: rmu2 lost its feed"
    );
    let live = n.with(sw(&m, "rmu1_e2"), Pos::Closed);
    assert_eq!(
        state(&m, &compute(&m, &live), "c2"),
        SectionState::EnergisedEarthed
    );
    // Earth does not pass a transformer; energy does.
    let earthed_tx = n
        .with(sw(&m, "f1"), Pos::Open)
        .with(sw(&m, "rmu1_e2"), Pos::Closed);
    let t = compute(&m, &earthed_tx);
    assert_eq!(state(&m, &t, "c2"), SectionState::Earthed);
    assert_eq!(state(&m, &t, "rmu2_bb"), SectionState::Earthed);
    assert_eq!(state(&m, &t, "css1_in"), SectionState::Dead);
}

#[test]
fn an_unknown_position_makes_downstream_unknown_but_not_what_is_surely_fed() {
    let m = ring();
    let n = Inputs::normal(&m);
    let t = compute(&m, &n.with(sw(&m, "f1"), Pos::Unknown));
    assert_eq!(state(&m, &t, "c1"), SectionState::Unknown);
    assert_eq!(
        t.unknown_because[sec(&m, "c1") as usize],
        Some(Unknown::Switch(sw(&m, "f1")))
    );
    assert_eq!(t.customers_unknown, 25 + 40 + 4);
    // Downstream of an energised path: an unknown ring switch leaves RMU1
    // energised (it is fed through F1) and only its far side is unknown.
    let t = compute(
        &m,
        &n.with(sw(&m, "rmu1_s2"), Pos::Unknown)
            .with(sw(&m, "rmu2_s1"), Pos::Open),
    );
    assert_eq!(state(&m, &t, "rmu1_bb"), SectionState::Energised);
    assert_eq!(state(&m, &t, "c2"), SectionState::Unknown);
    // An unknown earth switch on a dead cable: unknown (it may be earthed).
    let t = compute(
        &m,
        &n.with(sw(&m, "rmu1_s2"), Pos::Open)
            .with(sw(&m, "rmu2_s1"), Pos::Open)
            .with(sw(&m, "rmu2_e2"), Pos::Unknown),
    );
    assert_eq!(state(&m, &t, "c2"), SectionState::Unknown);
    assert!(t.maybe_earthed(sec(&m, "c2")));
    assert!(!t.maybe_energised(sec(&m, "c2")));
}

#[test]
fn a_source_out_of_service_feeds_nothing_and_one_of_unknown_service_may() {
    let m = ring();
    let mut n = Inputs::normal(&m);
    let grid = m.sources.iter().position(|s| s.id == "grid").unwrap();
    n.sources[grid] = Pos::Open;
    let t = compute(&m, &n);
    assert_eq!(state(&m, &t, "ps_bb"), SectionState::Dead);
    assert_eq!(state(&m, &t, "mg_bb"), SectionState::Energised);
    n.sources[grid] = Pos::Unknown;
    let t = compute(&m, &n);
    assert_eq!(state(&m, &t, "estate_lv"), SectionState::Unknown);
    assert_eq!(
        t.unknown_because[sec(&m, "estate_lv") as usize],
        Some(Unknown::Source(grid))
    );
}

#[test]
fn a_spec_naming_a_missing_node_is_an_error_not_a_panic() {
    let spec = Spec {
        nodes: vec![NodeSpec {
            id: "a".into(),
            ..NodeSpec::default()
        }],
        switches: vec![SwitchSpec {
            id: "s".into(),
            name: "S".into(),
            kind: LoadBreakSwitch,
            from: 0,
            to: Some(7),
            normally_closed: true,
        }],
        ..Spec::default()
    };
    let e = Model::build(spec).unwrap_err();
    assert!(e.0.contains("'s'"), "{e}");
}
