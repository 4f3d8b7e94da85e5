//! Microgrid units over Modbus: setpoint tracking within ramp limits,
//! battery state of charge, diesel start and minimum load, unit trips.

use crate::common;

use std::time::Duration;

use common::*;
use gridscada_sim::{Profile, UnitState};

#[tokio::test]
async fn pv_tracks_its_setpoint_within_the_ramp_limit() {
    let rig = rig(20.0).await;
    let h = rig.sim.handle();
    h.set_irradiance(Profile::Constant(1000.0)).unwrap();
    rig.write_f32("MG.PV1.Setpoint_kW", 30.0).await;
    assert!(
        eventually(&rig, Duration::from_secs(30), || async {
            (rig.read_f32("MG.PV1.P_kW").await - 30.0).abs() < 0.01
        })
        .await
    );
    assert_eq!(rig.read_f32("MG.PV1.Setpoint_kW").await, 30.0);
    assert!((rig.read_f32("MG.PV1.Available_kW").await - 95.0).abs() < 0.01);
    assert_eq!(rig.read_u16("MG.PV1.State").await, 1);

    // Step the setpoint up by 50 kW: the rise is limited to 10 kW/s.
    rig.write_f32("MG.PV1.Setpoint_kW", 80.0).await;
    let start = h.snapshot();
    let t0 = start.time;
    let mut seen_between = false;
    for _ in 0..40 {
        rig.wait(Duration::from_millis(250)).await;
        let s = h.snapshot();
        let p = s.unit("pv1").unwrap().p_kw;
        let dt = s.time.since(t0).as_secs_f64();
        assert!(p <= 30.0 + 10.0 * (dt + 0.2) + 1e-6, "{p} kW after {dt} s");
        assert!(p <= 80.0 + 1e-9);
        seen_between |= p > 31.0 && p < 79.0;
    }
    assert!(seen_between, "the ramp was never observed");
    assert!((rig.read_f32("MG.PV1.P_kW").await - 80.0).abs() < 0.01);
    // Above what the sun gives: capped at available, the rest curtailed.
    rig.write_f32("MG.PV1.Setpoint_kW", 200.0).await;
    rig.wait(Duration::from_secs(5)).await;
    assert!((rig.read_f32("MG.PV1.P_kW").await - 95.0).abs() < 0.01);
}

#[tokio::test]
async fn battery_soc_integrates_with_charge_and_discharge_efficiency() {
    let rig = rig(300.0).await;
    let h = rig.sim.handle();
    h.set_soc("bess1", 100.0).unwrap();
    rig.write_f32("MG.BESS1.Setpoint_kW", -40.0).await;
    rig.wait(Duration::from_secs(5)).await; // past the ramp
    let a = h.snapshot();
    rig.wait(Duration::from_secs(600)).await;
    let b = h.snapshot();
    let hours = b.time.since(a.time).as_secs_f64() / 3600.0;
    let gained =
        b.unit("bess1").unwrap().soc_kwh.unwrap() - a.unit("bess1").unwrap().soc_kwh.unwrap();
    let expected = 40.0 * 0.95 * hours;
    assert!(
        (gained - expected).abs() < 0.02 * expected + 0.05,
        "{gained} vs {expected}"
    );
    assert!((rig.read_f32("MG.BESS1.P_kW").await + 40.0).abs() < 1e-3);

    rig.write_f32("MG.BESS1.Setpoint_kW", 40.0).await;
    rig.wait(Duration::from_secs(5)).await;
    let a = h.snapshot();
    rig.wait(Duration::from_secs(600)).await;
    let b = h.snapshot();
    let hours = b.time.since(a.time).as_secs_f64() / 3600.0;
    let lost =
        a.unit("bess1").unwrap().soc_kwh.unwrap() - b.unit("bess1").unwrap().soc_kwh.unwrap();
    let expected = 40.0 / 0.95 * hours;
    assert!(
        (lost - expected).abs() < 0.02 * expected + 0.05,
        "{lost} vs {expected}"
    );

    // The registers agree with the model.
    let soc = rig.read_f32("MG.BESS1.SoC_kWh").await;
    let pct = rig.read_f32("MG.BESS1.SoC_pct").await;
    assert!((pct - soc / 2.0).abs() < 0.01, "{pct}% of 200 kWh vs {soc}");
    let snap = h.snapshot();
    let counters = &snap.unit("bess1").unwrap().counters;
    assert!(counters.charged_kwh > 0.0 && counters.energy_kwh > 0.0);
}

#[tokio::test]
async fn diesel_starts_after_its_delay_and_holds_minimum_load() {
    let rig = rig(20.0).await;
    let h = rig.sim.handle();
    assert_eq!(rig.read_u16("MG.DG1.State").await, 0);
    rig.write_f32("MG.DG1.Setpoint_kW", 10.0).await;
    rig.write_coil("MG.DG1.RunCmd", true).await;
    rig.wait(Duration::from_secs(2)).await;
    assert_eq!(rig.read_u16("MG.DG1.State").await, 3, "starting");
    assert!(!rig.read_bool("MG.DG1.Running").await);
    assert!(rig.read_f32("MG.DG1.FuelRate").await > 0.0);
    // 10 s start, then 6 s to ramp to the 30 kW minimum at 5 kW/s.
    assert!(
        eventually(&rig, Duration::from_secs(30), || async {
            (rig.read_f32("MG.DG1.P_kW").await - 30.0).abs() < 0.01
        })
        .await
    );
    assert!(rig.read_bool("MG.DG1.Running").await);
    assert_eq!(rig.read_u16("MG.DG1.State").await, 1);
    let s = h.snapshot();
    let dg = s.unit("dg1").unwrap();
    assert_eq!(dg.counters.starts, 1);
    assert!(dg.counters.fuel_l > 0.0 && dg.counters.runtime_s > 5.0);

    // Stop: ramps down, then off.
    rig.write_coil("MG.DG1.RunCmd", false).await;
    assert!(
        eventually(&rig, Duration::from_secs(30), || async {
            !rig.read_bool("MG.DG1.Running").await
        })
        .await
    );
    assert_eq!(rig.read_f32("MG.DG1.P_kW").await, 0.0);
}

#[tokio::test]
async fn unit_trip_and_microgrid_balance() {
    let rig = rig(20.0).await;
    let h = rig.sim.handle();
    h.set_irradiance(Profile::Constant(1000.0)).unwrap();
    h.set_wind_speed(Profile::Constant(12.0)).unwrap();
    h.set_demand(Profile::Constant(100.0)).unwrap();
    rig.wait(Duration::from_secs(15)).await;
    // PV 95 + wind 50 = 145 kW against 100 kW demand: frequency high.
    assert!((rig.read_f32("MG.Load.P_kW").await - 100.0).abs() < 1e-3);
    let hz = rig.read_f32("MG.Load.Hz").await;
    assert!((hz - (50.0 + 0.02 * 45.0)).abs() < 0.05, "{hz}");
    assert!((rig.read_f32("MG.WT1.WindSpeed").await - 12.0).abs() < 1e-6);
    assert!((rig.read_f32("MG.WT1.Available_kW").await - 50.0).abs() < 1e-3);

    h.trip_unit("MG.PV1").unwrap();
    assert_eq!(rig.read_u16("MG.PV1.State").await, 2);
    assert_eq!(rig.read_f32("MG.PV1.P_kW").await, 0.0);
    rig.wait(Duration::from_secs(2)).await;
    // 50 kW short now: frequency low, unserved energy counting.
    let hz = rig.read_f32("MG.Load.Hz").await;
    assert!(hz < 49.1, "{hz}");
    let before = h.snapshot().microgrid.unwrap().energy.unserved_kwh;
    rig.wait(Duration::from_secs(10)).await;
    assert!(h.snapshot().microgrid.unwrap().energy.unserved_kwh > before);
    assert_eq!(h.snapshot().unit("pv1").unwrap().state, UnitState::Fault);

    h.reset_unit("pv1").unwrap();
    rig.wait(Duration::from_secs(15)).await;
    assert_eq!(rig.read_u16("MG.PV1.State").await, 1);
    assert!(rig.read_f32("MG.PV1.P_kW").await > 90.0);
    assert!(h.set_demand(Profile::Constant(f64::INFINITY)).is_err());
    assert!(h.trip_unit("nope").is_err());
}

/// A trainer scales the built-in curves: the registers follow the scaled
/// value, and a bad factor is refused.
#[tokio::test]
async fn scaled_profiles_reach_the_registers() {
    let rig = rig(1.0).await;
    let h = rig.sim.handle();
    h.set_demand(Profile::Builtin).unwrap();
    rig.wait(Duration::from_millis(300)).await;
    let builtin = h.snapshot().microgrid.unwrap().demand_kw;
    h.set_demand(Profile::Scaled(0.5)).unwrap();
    h.sample_inputs_now().unwrap();
    // At once, without waiting for the plant's next step.
    let snap = h.snapshot().microgrid.unwrap();
    assert!(
        (snap.demand_kw / builtin - 0.5).abs() < 0.01,
        "{} vs {builtin}",
        snap.demand_kw
    );
    assert_eq!(snap.demand_profile, Profile::Scaled(0.5));
    let read = rig.read_f32("MG.Load.P_kW").await;
    assert!(
        (read / snap.demand_kw - 1.0).abs() < 0.05,
        "{read} vs {}",
        snap.demand_kw
    );
    h.set_wind_speed(Profile::Scaled(0.0)).unwrap();
    rig.wait(Duration::from_secs(1)).await;
    assert_eq!(rig.read_f32("MG.WT1.WindSpeed").await, 0.0);
    assert!(h.set_irradiance(Profile::Scaled(-1.0)).is_err());
    assert!(h.set_irradiance(Profile::Scaled(f64::NAN)).is_err());
}
