//! Substation panels over Modbus: register maps, ELCB trips, reset,
//! transient and permanent faults, the power analyzer, and a bigger plant.

use crate::common;

use std::time::Duration;

use common::*;
use gridscada_config::RegisterKind;
use gridscada_sim::FaultKind;
use serde_spanned::Spanned;
use tokio_modbus::client::Reader;

const SETTLE: Duration = Duration::from_millis(300);

#[tokio::test]
async fn every_demo_tag_reads_from_its_register() {
    let rig = rig(1.0).await;
    for t in rig.plant.tags.iter().filter(|t| t.register().is_some()) {
        let mut c = rig.client(t.device.get_ref()).await;
        let a = t.register().unwrap().1 as u16;
        let n = t.width();
        let ok = match &t.register().unwrap().0 {
            RegisterKind::Coil => c.read_coils(a, n).await.map(|r| r.is_ok()),
            RegisterKind::DiscreteInput => c.read_discrete_inputs(a, n).await.map(|r| r.is_ok()),
            RegisterKind::InputRegister => c.read_input_registers(a, n).await.map(|r| r.is_ok()),
            RegisterKind::HoldingRegister => {
                c.read_holding_registers(a, n).await.map(|r| r.is_ok())
            }
        };
        assert!(
            matches!(ok, Ok(true)),
            "tag {} did not read: {ok:?}",
            t.name.get_ref()
        );
    }
    // The seed's modules: I-7044 has 8 DO / 4 DI, I-7051 16 DI, I-7042 13 DO.
    let mut io1 = rig.client("SS1.IO1").await;
    assert!(io1.read_coils(0, 8).await.unwrap().is_ok());
    assert!(io1.read_discrete_inputs(0, 4).await.unwrap().is_ok());
    assert!(io1.read_coils(0, 9).await.unwrap().is_err());
    let mut io2 = rig.client("SS1.IO2").await;
    assert!(io2.read_discrete_inputs(0, 16).await.unwrap().is_ok());
    let mut io3 = rig.client("SS1.IO3").await;
    assert!(io3.read_coils(0, 13).await.unwrap().is_ok());
    assert!(io3.read_coils(0, 14).await.unwrap().is_err());

    // Healthy start: ELCB, MCCB and zones closed and energised.
    for p in ["SS1", "CSS1"] {
        assert!(rig.read_bool(&format!("{p}.ELCB.Closed")).await);
        assert!(rig.read_bool(&format!("{p}.MCCB.Closed")).await);
        assert!(rig.read_bool(&format!("{p}.MCCB.Cmd")).await);
        for z in 1..=4 {
            assert!(rig.read_bool(&format!("{p}.Zone{z}.Closed")).await);
            assert!(rig.read_bool(&format!("{p}.Zone{z}.Energised")).await);
        }
        let v = rig.read_f32(&format!("{p}.PA.V_L1")).await;
        assert!((225.0..235.0).contains(&v), "{p} V_L1 {v}");
        let hz = rig.read_f32(&format!("{p}.PA.Hz")).await;
        assert!((hz - 50.0).abs() < 0.1, "{hz}");
    }
}

#[tokio::test]
async fn zone_fault_trips_the_elcb_only_when_energised_and_reset_recloses() {
    let rig = rig(10.0).await;
    let h = rig.sim.handle();
    // Zone 3 open, then faulted: latent, nothing trips.
    rig.write_coil("SS1.Zone3.Cmd", false).await;
    rig.wait(SETTLE).await;
    assert!(!rig.read_bool("SS1.Zone3.Closed").await);
    h.inject_zone_fault("ss1", 3, FaultKind::Permanent).unwrap();
    rig.wait(SETTLE).await;
    assert!(rig.read_bool("SS1.ELCB.Closed").await);
    assert!(rig.read_bool("SS1.Zone1.Energised").await);

    // Closing onto the fault trips the ELCB; breakers keep their state.
    rig.write_coil("SS1.Zone3.Cmd", true).await;
    rig.wait(SETTLE).await;
    assert!(!rig.read_bool("SS1.ELCB.Closed").await);
    assert!(rig.read_bool("SS1.Zone3.Closed").await);
    assert!(rig.read_bool("SS1.MCCB.Closed").await);
    for z in 1..=4 {
        assert!(!rig.read_bool(&format!("SS1.Zone{z}.Energised")).await);
    }
    // The other panel is untouched.
    assert!(rig.read_bool("CSS1.ELCB.Closed").await);

    // Reset with the faulted zone still closed: recloses onto the permanent
    // fault and trips again at once.
    rig.pulse("SS1.ELCB.Reset").await;
    rig.wait(SETTLE).await;
    assert!(!rig.read_bool("SS1.ELCB.Closed").await);
    let snap = h.snapshot();
    let p = snap.panel("ss1").unwrap();
    assert_eq!(p.elcb_trips, 2);
    assert_eq!(p.zones[2].fault_energisations, 2);

    // Isolate zone 3, reset: the healthy zones come back.
    rig.write_coil("SS1.Zone3.Cmd", false).await;
    rig.wait(SETTLE).await;
    rig.pulse("SS1.ELCB.Reset").await;
    rig.wait(SETTLE).await;
    assert!(rig.read_bool("SS1.ELCB.Closed").await);
    assert!(rig.read_bool("SS1.Zone1.Energised").await);
    assert!(!rig.read_bool("SS1.Zone3.Energised").await);
    assert_eq!(
        h.snapshot().panel("ss1").unwrap().energised_zones(),
        vec![1, 2, 4]
    );

    // Repaired: closing zone 3 holds.
    h.repair_zone("ss1", 3).unwrap();
    rig.write_coil("SS1.Zone3.Cmd", true).await;
    rig.wait(SETTLE).await;
    assert!(rig.read_bool("SS1.ELCB.Closed").await);
    assert!(rig.read_bool("SS1.Zone3.Energised").await);
}

#[tokio::test]
async fn transient_fault_clears_after_its_trip() {
    let rig = rig(10.0).await;
    let h = rig.sim.handle();
    h.inject_zone_fault("CSS1", 2, FaultKind::Transient)
        .unwrap();
    rig.wait(SETTLE).await;
    assert!(!rig.read_bool("CSS1.ELCB.Closed").await);
    // Everything still closed: the reset holds because the fault is gone.
    rig.pulse("CSS1.ELCB.Reset").await;
    rig.wait(SETTLE).await;
    assert!(rig.read_bool("CSS1.ELCB.Closed").await);
    assert!(rig.read_bool("CSS1.Zone2.Energised").await);
    let snap = h.snapshot();
    let p = snap.panel("css1").unwrap();
    assert_eq!(p.elcb_trips, 1);
    assert_eq!(p.zones[1].fault, None);
}

#[tokio::test]
async fn busbar_fault_trips_through_the_mccb() {
    let rig = rig(10.0).await;
    let h = rig.sim.handle();
    rig.write_coil("SS1.MCCB.Cmd", false).await;
    rig.wait(SETTLE).await;
    h.inject_zone_fault("ss1", 0, FaultKind::Permanent).unwrap();
    assert!(rig.read_bool("SS1.ELCB.Closed").await);
    rig.write_coil("SS1.MCCB.Cmd", true).await;
    rig.wait(SETTLE).await;
    assert!(!rig.read_bool("SS1.ELCB.Closed").await);
    assert_eq!(
        h.snapshot()
            .panel("ss1")
            .unwrap()
            .last_trip
            .as_ref()
            .unwrap()
            .zones,
        vec![0]
    );
}

#[tokio::test]
async fn analyzer_follows_the_energised_loads() {
    let rig = rig(1.0).await;
    let h = rig.sim.handle();
    let p_all = rig.read_f32("SS1.PA.P_kW").await;
    let expected: f64 = h
        .snapshot()
        .panel("ss1")
        .unwrap()
        .zones
        .iter()
        .map(|z| z.load_kw_now)
        .sum();
    assert!(
        (p_all - expected).abs() / expected < 0.01,
        "{p_all} vs {expected}"
    );

    let z4 = h.snapshot().panel("ss1").unwrap().zones[3].load_kw_now;
    rig.write_coil("SS1.Zone4.Cmd", false).await;
    rig.wait(SETTLE).await;
    let p_three = rig.read_f32("SS1.PA.P_kW").await;
    assert!(
        (p_all - p_three - z4).abs() < 0.1,
        "{p_all} - {p_three} != {z4}"
    );
    let i1 = rig.read_f32("SS1.PA.I_L1").await;
    assert!(i1 > 1.0);
    let pf = rig.read_f32("SS1.PA.PF").await;
    assert!(pf > 0.85 && pf < 1.0, "{pf}");
    let q = rig.read_f32("SS1.PA.Q_kvar").await;
    assert!(q > 0.0);

    // kWh counts up in 0.1 kWh steps as u32.
    let mut c = rig.client("SS1.PA").await;
    let w = c.read_input_registers(20, 2).await.unwrap().unwrap();
    let kwh = f64::from((u32::from(w[0]) << 16) | u32::from(w[1])) * 0.1;
    assert!((kwh - h.snapshot().panel("ss1").unwrap().analyzer.kwh).abs() < 0.2);

    // Trip: no voltage, no load.
    h.inject_zone_fault("ss1", 1, FaultKind::Permanent).unwrap();
    assert_eq!(rig.read_f32("SS1.PA.V_L2").await, 0.0);
    assert_eq!(rig.read_f32("SS1.PA.P_kW").await, 0.0);
}

#[tokio::test]
async fn a_bigger_plant_from_configuration() {
    // A third panel with six zones on its own gateway, made from CSS1's tags.
    let mut plant = demo_plant();
    let demo_servers = {
        let mut a: Vec<String> = plant
            .devices
            .iter()
            .filter_map(|d| Some(d.address.as_ref()?.get_ref().clone()))
            .collect();
        a.sort();
        a.dedup();
        a.len()
    };
    let addr = "127.0.0.1:15099".to_string();
    let mut devices: Vec<_> = plant
        .devices
        .iter()
        .filter(|d| d.name.get_ref().starts_with("CSS1."))
        .cloned()
        .collect();
    for d in &mut devices {
        d.name = Spanned::new(0..0, d.name.get_ref().replace("CSS1.", "SS9."));
        d.address = Some(Spanned::new(0..0, addr.clone()));
    }
    let mut tags: Vec<_> = plant
        .tags
        .iter()
        .filter(|t| t.name.get_ref().starts_with("CSS1."))
        .cloned()
        .collect();
    for t in &mut tags {
        t.name = Spanned::new(0..0, t.name.get_ref().replace("CSS1.", "SS9."));
        t.device = Spanned::new(0..0, t.device.get_ref().replace("CSS1.", "SS9."));
    }
    for z in 5..=6u32 {
        for (suffix, dev, kind) in [
            ("Closed", "SS9.IO2", RegisterKind::DiscreteInput),
            ("Cmd", "SS9.IO3", RegisterKind::Coil),
        ] {
            let mut t = tags
                .iter()
                .find(|t| t.name.get_ref() == &format!("SS9.Zone1.{suffix}"))
                .unwrap()
                .clone();
            t.name = Spanned::new(0..0, format!("SS9.Zone{z}.{suffix}"));
            t.device = Spanned::new(0..0, dev.into());
            t.kind = Some(Spanned::new(0..0, kind));
            t.address = Some(Spanned::new(0..0, z - 1));
            tags.push(t);
        }
    }
    let mut panel = plant.panels[1].clone();
    panel.id = Spanned::new(0..0, "ss9".into());
    panel.prefix = Spanned::new(0..0, "SS9".into());
    panel.zones = Spanned::new(0..0, 6);
    plant.devices.extend(devices);
    plant.tags.extend(tags);
    plant.panels.push(panel);

    let rig = rig_with(plant, 10.0).await;
    // The demo's servers and the new panel's gateway.
    assert_eq!(rig.sim.addresses().len(), demo_servers + 1);
    let h = rig.sim.handle();
    rig.write_coil("SS9.Zone6.Cmd", false).await;
    rig.wait(SETTLE).await;
    assert!(!rig.read_bool("SS9.Zone6.Closed").await);
    assert!(rig.read_bool("SS9.Zone5.Closed").await);
    h.inject_zone_fault("ss9", 5, FaultKind::Permanent).unwrap();
    rig.wait(SETTLE).await;
    assert!(!rig.read_bool("SS9.ELCB.Closed").await);
    assert!(rig.read_bool("CSS1.ELCB.Closed").await);
    assert!(h.inject_zone_fault("ss9", 7, FaultKind::Permanent).is_err());
}

/// A trainer's transient fault with a clearing time: over Modbus, a reset
/// before that time recloses onto it and trips again; after it, a reset holds.
#[tokio::test]
async fn timed_transient_fault_retrips_until_its_clearing_time() {
    let rig = rig(10.0).await;
    let h = rig.sim.handle();
    assert!(h
        .inject_timed_fault("ss1", 2, Duration::from_millis(500))
        .is_err());
    assert!(h
        .inject_timed_fault("ss1", 2, Duration::from_secs(7200))
        .is_err());
    assert!(h
        .inject_timed_fault("ss1", 9, Duration::from_secs(5))
        .is_err());
    h.inject_timed_fault("ss1", 2, Duration::from_secs(20))
        .unwrap();
    rig.wait(SETTLE).await;
    assert!(!rig.read_bool("SS1.ELCB.Closed").await);
    let snap = h.snapshot();
    let z2 = &snap.panel("ss1").unwrap().zones[1];
    assert_eq!(z2.fault, Some(FaultKind::Transient));
    assert!(z2.fault_clears_at.is_some());
    // Before its time: the reclose trips again.
    rig.pulse("SS1.ELCB.Reset").await;
    rig.wait(SETTLE).await;
    assert!(!rig.read_bool("SS1.ELCB.Closed").await);
    assert_eq!(h.snapshot().panel("ss1").unwrap().elcb_trips, 2);
    // After it: gone, and the reclose holds with every zone on.
    rig.wait(Duration::from_secs(20)).await;
    assert_eq!(h.snapshot().panel("ss1").unwrap().zones[1].fault, None);
    rig.pulse("SS1.ELCB.Reset").await;
    rig.wait(SETTLE).await;
    assert!(rig.read_bool("SS1.ELCB.Closed").await);
    assert!(rig.read_bool("SS1.Zone2.Energised").await);
    assert_eq!(h.snapshot().panel("ss1").unwrap().elcb_trips, 2);
}
