//! Dispatch solve time: `cargo bench -p gridscada-control --bench dispatch`.
//! Prints p50/p99 for the single-period LP (the live loop's problem) and a
//! 96-period day-ahead horizon with 5 units, as LP and as QP (smoothing on),
//! and the live look-ahead (16 periods of 15 minutes) with the diesel's
//! commitment decided by branch and bound, over every hour of the day.
//! Figures only; nothing is asserted.

use std::collections::BTreeMap;
use std::time::Instant;

use gridscada_control::dispatch::lookahead::LIVE_COMMITMENT_NODES;

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
        ..HorizonOil::default()
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
            final_soc_min_kwh: None,
        }],
        reserve: Some(ReserveRule {
            load_frac: 0.1,
            pv_frac: 0.2,
            wind_frac: 0.3,
            shortfall_cost_per_kwh: 1.0,
        }),
        max_renewable_share: None,
        smoothing_cost_per_kw2: smoothing,
        max_commitment_nodes: None,
    }
}

/// The live look-ahead's problem: 16 periods of 15 minutes from `start` (a
/// quarter-hour of the day), the demo's diesel priced by its fuel curve with
/// its commitment decided, the battery at `soc`.
fn lookahead(start: usize, soc: f64, running: bool) -> HorizonProblem {
    let mut p = horizon(0.0);
    p.periods = (0..16)
        .map(|t| p.periods[(start + t) % 96].clone())
        .collect();
    p.reserve = None;
    p.oil.truncate(1);
    let dg = &mut p.oil[0];
    dg.min_kw = 30.0;
    dg.max_kw = 150.0;
    dg.ramp_kw_per_s = 5.0;
    dg.running = running;
    dg.initial_kw = running.then_some(60.0);
    dg.cost_per_kwh = 1.5 * 0.246;
    dg.no_load_cost_per_h = 1.5 * 12.2175;
    dg.min_up_h = 0.25;
    dg.min_down_h = 5.0 / 60.0;
    dg.optimize_commitment = true;
    dg.hours_in_state = Some(1.0);
    p.storage[0].unit.soc_kwh = soc;
    p.storage[0].ramp_kw_per_s = 0.0;
    p
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
    let mut plans = Vec::new();
    let mut nodes = Vec::new();
    let mut proven = 0usize;
    let mut costs = Vec::new();
    for start in (0..96).step_by(4) {
        for soc in [30.0, 100.0, 170.0] {
            for running in [false, true] {
                let mut p = lookahead(start, soc, running);
                p.max_commitment_nodes = Some(LIVE_COMMITMENT_NODES);
                let t = Instant::now();
                let sol = p.solve().expect("look-ahead with commitment");
                plans.push(t.elapsed().as_secs_f64() * 1e3);
                costs.push(sol.objective);
                proven += usize::from(sol.commitment.as_ref().is_some_and(|c| c.proven));
                nodes.push(sol.commitment.map_or(0, |c| c.nodes) as f64);
            }
        }
    }
    // The total and the plans' summed cost: a faster search must find
    // schedules as good (docs/BENCHMARKS.md compares them between builds).
    println!(
        "look-ahead total {:.0} ms for {} plans, summed cost {:.4}",
        plans.iter().sum::<f64>(),
        plans.len(),
        costs.iter().sum::<f64>()
    );
    report("look-ahead 16 x 15 min, commitment (ms)", plans);
    let n = nodes.len();
    report("  relaxations per plan (count, not ms)", nodes);
    println!("  schedules proven optimal within 0.1 %: {proven} of {n}");
    // A day ahead with everything known (the replay's perfect-foresight
    // optimum): 96 periods, the commitment decided over the whole day.
    for soc in [30.0, 100.0] {
        let mut p = lookahead(0, soc, false);
        let day = horizon(0.0);
        p.periods = day.periods.clone();
        p.max_commitment_nodes = Some(1500);
        // For solving the same day with another solver (docs/BENCHMARKS.md).
        if let Some(dir) = std::env::var_os("BENCH_DUMP_DIR") {
            let path = std::path::Path::new(&dir).join(format!("day-ahead-soc{soc}.json"));
            std::fs::write(path, serde_json::to_string(&p).expect("problem as JSON"))
                .expect("writing the problem");
        }
        let t = Instant::now();
        let sol = p.solve().expect("day-ahead commitment");
        let c = sol.commitment.unwrap();
        println!(
            "day-ahead 96 x 15 min commitment, soc {soc:>5}: {:>8.0} ms, {} relaxations, cost {:.2}, bound {:.2} ({}proven)",
            t.elapsed().as_secs_f64() * 1e3,
            c.nodes,
            sol.objective,
            c.lower_bound,
            if c.proven { "" } else { "not " }
        );
    }
    let q = horizon(0.001);
    report(
        "96-period horizon, 5 units, QP",
        time(50, || {
            q.solve().expect("horizon QP");
        }),
    );
}
