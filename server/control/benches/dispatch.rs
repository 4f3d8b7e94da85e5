//! Dispatch solve time: `cargo bench -p gridscada-control --bench dispatch`.
//! Prints p50/p99 for the single-period LP (the live loop's problem) and a
//! 96-period day-ahead horizon with 5 units, as LP and as QP (smoothing on).
//! Figures only; nothing is asserted.

use std::collections::BTreeMap;
use std::time::Instant;

use gridscada_control::dispatch::{
    DispatchProblem, HorizonOil, HorizonProblem, HorizonRenewable, HorizonStorage, OilUnit,
    PeriodForecast, RenewableUnit, ReserveRule, StorageUnit,
};

fn storage(id: &str) -> StorageUnit {
    StorageUnit {
        id: id.into(),
        soc_kwh: 100.0,
        soc_min_kwh: 20.0,
        soc_max_kwh: 190.0,
        max_charge_kw: 50.0,
        max_discharge_kw: 60.0,
        eff_charge: 0.95,
        eff_discharge: 0.95,
        cycle_cost_per_kwh: 0.02,
        stored_value_per_kwh: 0.0,
    }
}

fn single() -> DispatchProblem {
    DispatchProblem {
        dt_h: 5.0 / 3600.0,
        demand_kw: 180.0,
        voll_per_kwh: 5.0,
        pv: vec![RenewableUnit {
            id: "pv1".into(),
            available_kw: 60.0,
            cost_per_kwh: 0.0,
        }],
        wind: vec![RenewableUnit {
            id: "wt1".into(),
            available_kw: 25.0,
            cost_per_kwh: 0.01,
        }],
        oil: vec![OilUnit {
            id: "dg1".into(),
            running: true,
            min_kw: 30.0,
            max_kw: 150.0,
            cost_per_kwh: 0.35,
        }],
        storage: vec![storage("bess1")],
    }
}

fn horizon(smoothing: f64) -> HorizonProblem {
    let nt = 96;
    let periods = (0..nt)
        .map(|t| {
            let h = t as f64 * 0.25;
            let sun = ((h - 6.0) / 12.0 * std::f64::consts::PI).sin().max(0.0);
            let mut a = BTreeMap::new();
            a.insert("pv1".to_string(), 100.0 * sun);
            a.insert("wt1".to_string(), 25.0 + 15.0 * (h / 3.0).sin());
            PeriodForecast {
                demand_kw: 130.0 + 50.0 * ((h - 19.0) / 24.0 * std::f64::consts::TAU).cos(),
                available_kw: a,
                running: BTreeMap::new(),
            }
        })
        .collect();
    let ren = |id: &str, c: f64| HorizonRenewable {
        id: id.into(),
        cost_per_kwh: c,
        ramp_kw_per_s: 0.05,
        initial_kw: Some(0.0),
    };
    let oil = |id: &str, c: f64| HorizonOil {
        id: id.into(),
        running: true,
        min_kw: 20.0,
        max_kw: 120.0,
        cost_per_kwh: c,
        ramp_kw_per_s: 0.02,
        initial_kw: Some(40.0),
        relaxed_commitment: false,
    };
    HorizonProblem {
        dt_h: 0.25,
        voll_per_kwh: 5.0,
        periods,
        pv: vec![ren("pv1", 0.0)],
        wind: vec![ren("wt1", 0.01)],
        oil: vec![oil("dg1", 0.35), oil("dg2", 0.4)],
        storage: vec![HorizonStorage {
            unit: storage("bess1"),
            ramp_kw_per_s: 0.0,
            initial_kw: Some(0.0),
            terminal_value_per_kwh: 0.25,
        }],
        reserve: Some(ReserveRule {
            load_frac: 0.1,
            pv_frac: 0.2,
            wind_frac: 0.3,
            shortfall_cost_per_kwh: 1.0,
        }),
        max_renewable_share: None,
        smoothing_cost_per_kw2: smoothing,
    }
}

fn report(name: &str, mut ms: Vec<f64>) {
    ms.sort_by(f64::total_cmp);
    let q = |p: f64| ms[((ms.len() - 1) as f64 * p).round() as usize];
    println!(
        "{name:<40} n={:<5} p50 {:>8.3} ms  p99 {:>8.3} ms",
        ms.len(),
        q(0.5),
        q(0.99)
    );
}

fn time(n: usize, mut f: impl FnMut()) -> Vec<f64> {
    (0..n)
        .map(|_| {
            let t = Instant::now();
            f();
            t.elapsed().as_secs_f64() * 1e3
        })
        .collect()
}

fn main() {
    let p = single();
    report(
        "single period (4 units)",
        time(2000, || {
            p.solve().expect("single-period solve");
        }),
    );
    let h = horizon(0.0);
    report(
        "96-period horizon, 5 units, LP",
        time(50, || {
            h.solve().expect("horizon LP");
        }),
    );
    let q = horizon(0.001);
    report(
        "96-period horizon, 5 units, QP",
        time(50, || {
            q.solve().expect("horizon QP");
        }),
    );
}
