//! Tests of the horizon LP/QP: dynamics, ramps and balance, stored energy,
//! relaxed commitment, smoothing, the renewable cap and located errors.

use super::*;

pub(crate) fn day(nt: usize) -> HorizonProblem {
    let periods = (0..nt)
        .map(|t| {
            let h = t as f64 * 24.0 / nt as f64;
            let sun = (((h - 6.0) / 12.0 * std::f64::consts::PI).sin()).max(0.0);
            PeriodForecast {
                demand_kw: 120.0 + 60.0 * ((h - 18.0) / 24.0 * 2.0 * std::f64::consts::PI).cos(),
                available_kw: [
                    ("pv1".to_string(), 100.0 * sun),
                    ("wt1".to_string(), 20.0 + 10.0 * (h / 5.0).sin()),
                ]
                .into_iter()
                .collect(),
                running: BTreeMap::new(),
            }
        })
        .collect();
    HorizonProblem {
        dt_h: 24.0 / nt as f64,
        voll_per_kwh: 5.0,
        periods,
        pv: vec![HorizonRenewable {
            id: "pv1".into(),
            cost_per_kwh: 0.0,
            ramp_kw_per_s: 0.0,
            initial_kw: None,
        }],
        wind: vec![HorizonRenewable {
            id: "wt1".into(),
            cost_per_kwh: 0.01,
            ramp_kw_per_s: 0.0,
            initial_kw: None,
        }],
        oil: vec![HorizonOil {
            id: "dg1".into(),
            running: true,
            min_kw: 30.0,
            max_kw: 150.0,
            cost_per_kwh: 0.35,
            ramp_kw_per_s: 0.01,
            initial_kw: Some(60.0),
            relaxed_commitment: false,
            ..HorizonOil::default()
        }],
        storage: vec![HorizonStorage {
            unit: StorageUnit {
                id: "bess1".into(),
                soc_kwh: 100.0,
                soc_min_kwh: 20.0,
                soc_max_kwh: 190.0,
                max_charge_kw: 50.0,
                max_discharge_kw: 60.0,
                eff_charge: 0.95,
                eff_discharge: 0.95,
                cycle_cost_per_kwh: 0.02,
                stored_value_per_kwh: 0.0,
            },
            ramp_kw_per_s: 0.0,
            initial_kw: Some(0.0),
            terminal_value_per_kwh: 0.2,
            final_soc_min_kwh: None,
        }],
        reserve: Some(ReserveRule {
            load_frac: 0.1,
            pv_frac: 0.2,
            wind_frac: 0.3,
            shortfall_cost_per_kwh: 1.0,
        }),
        max_renewable_share: None,
        smoothing_cost_per_kw2: 0.0,
        max_commitment_nodes: None,
    }
}

fn check_dynamics(p: &HorizonProblem, s: &HorizonSolution) {
    let u = &p.storage[0].unit;
    let mut soc = u.soc_kwh;
    for (t, r) in s.periods.iter().enumerate() {
        let ch = r.charge_kw.get("bess1").unwrap();
        let dis = r.discharge_kw.get("bess1").unwrap();
        soc += u.eff_charge * p.dt_h * ch - p.dt_h * dis / u.eff_discharge;
        assert!((soc - r.soc_kwh.get("bess1").unwrap()).abs() < 1e-9);
        assert!(soc >= u.soc_min_kwh - 1e-6 && soc <= u.soc_max_kwh + 1e-6);
        let supply: f64 = r.setpoints_kw.0.iter().map(|(_, v)| v).sum::<f64>() + r.shed_kw;
        assert!(
            (supply - p.periods[t].demand_kw).abs() < 1e-6,
            "balance in period {t}"
        );
    }
}

#[test]
fn a_day_ahead_lp_respects_dynamics_ramps_and_balance() {
    let p = day(24);
    let s = p.solve().unwrap();
    check_dynamics(&p, &s);
    let ramp = 0.01 * 3600.0 * p.dt_h;
    let mut prev = 60.0;
    for r in &s.periods {
        let d = r.setpoints_kw.get("dg1").unwrap();
        assert!((d - prev).abs() <= ramp + 1e-6);
        prev = d;
    }
}

#[test]
fn stored_energy_value_is_the_cost_saved_per_kwh_stored() {
    // Three cases: energy that displaces diesel later, energy that only
    // meets the terminal value, and energy that averts shedding.
    let cases = {
        let mut worth_diesel = day(24);
        worth_diesel.reserve = None;
        let mut surplus = worth_diesel.clone();
        surplus.oil.clear();
        for p in &mut surplus.periods {
            p.demand_kw = 10.0;
        }
        let mut short = surplus.clone();
        for p in &mut short.periods {
            p.demand_kw = 250.0;
        }
        [worth_diesel, surplus, short]
    };
    for p in cases {
        let s = p.solve().unwrap();
        let value = s.stored_energy_value_per_kwh.get("bess1").unwrap();
        let mut more = p.clone();
        more.storage[0].unit.soc_kwh += 0.01;
        let saved = (s.objective - more.solve().unwrap().objective) / 0.01;
        assert!(
            (value - saved).abs() <= 1e-3 * saved.abs().max(1.0),
            "value {value} vs saved {saved} per kWh"
        );
        assert!(value >= -1e-9, "{value}");
    }
}

#[test]
fn relaxed_commitment_frees_the_oil_unit_after_the_first_period() {
    let mut p = day(24);
    p.reserve = None;
    p.oil[0].running = false;
    p.oil[0].initial_kw = None;
    let fixed = p.solve().unwrap();
    p.oil[0].relaxed_commitment = true;
    let relaxed = p.solve().unwrap();
    check_dynamics(&p, &relaxed);
    let dg = |s: &HorizonSolution, t: usize| s.periods[t].setpoints_kw.get("dg1").unwrap();
    assert_eq!(dg(&relaxed, 0), 0.0, "period 0 keeps the commitment");
    assert!((1..24).all(|t| dg(&fixed, t) == 0.0));
    assert!((1..24).any(|t| dg(&relaxed, t) > 1.0 && dg(&relaxed, t) < 30.0));
    assert!(relaxed.objective < fixed.objective);
}

#[test]
fn smoothing_makes_it_a_qp_with_smaller_steps() {
    let mut p = day(24);
    p.oil[0].ramp_kw_per_s = 0.0;
    let lp = p.solve().unwrap();
    p.smoothing_cost_per_kw2 = 0.01;
    let qp = p.solve().unwrap();
    check_dynamics(&p, &qp);
    let steps = |s: &HorizonSolution| -> f64 {
        s.periods
            .windows(2)
            .map(|w| {
                (w[1].setpoints_kw.get("dg1").unwrap() - w[0].setpoints_kw.get("dg1").unwrap())
                    .powi(2)
            })
            .sum()
    };
    assert!(steps(&qp) < steps(&lp));
}

#[test]
fn renewable_share_cap_curtails() {
    let mut p = day(8);
    p.max_renewable_share = Some(0.3);
    let s = p.solve().unwrap();
    for (t, r) in s.periods.iter().enumerate() {
        let ren = r.setpoints_kw.get("pv1").unwrap() + r.setpoints_kw.get("wt1").unwrap();
        assert!(ren <= 0.3 * p.periods[t].demand_kw + 1e-6);
    }
}

#[test]
fn missing_forecast_is_located() {
    let mut p = day(3);
    p.periods[1].available_kw.remove("wt1");
    let e = p.validate("").unwrap_err();
    assert_eq!(e.path, "periods[1].available_kw");
    assert!(e.message.contains("wt1"));
}

#[test]
fn diesel_ramp_down_that_nothing_absorbs_is_infeasible() {
    let mut p = day(2);
    p.storage.clear();
    p.reserve = None;
    p.oil[0].initial_kw = Some(150.0);
    p.oil[0].ramp_kw_per_s = 0.001; // 3.6 kW per hour
    for per in &mut p.periods {
        per.demand_kw = 40.0;
    }
    assert!(matches!(p.solve(), Err(DispatchError::Infeasible(_))));
}

/// A night and morning with the demo's diesel priced by its fuel curve
/// (12.2 l/h no load, 0.246 l/kWh, 1.5 per litre) and the commitment decided.
fn committed(nt: usize, dt_h: f64, soc: f64) -> HorizonProblem {
    let mut p = day(nt);
    p.dt_h = dt_h;
    for (t, per) in p.periods.iter_mut().enumerate() {
        let h = t as f64 * dt_h;
        per.demand_kw = 60.0 + 25.0 * (h / 3.0).sin().abs();
        per.available_kw
            .insert("pv1".into(), (20.0 * (h - 2.0)).clamp(0.0, 80.0));
        per.available_kw.insert("wt1".into(), 5.0);
    }
    p.reserve = None;
    let dg = &mut p.oil[0];
    dg.running = false;
    dg.initial_kw = None;
    dg.ramp_kw_per_s = 0.0;
    dg.cost_per_kwh = 1.5 * 0.246;
    dg.no_load_cost_per_h = 1.5 * 12.2175;
    dg.start_cost = 2.0;
    dg.min_up_h = 0.5;
    dg.min_down_h = 0.25;
    dg.optimize_commitment = true;
    dg.hours_in_state = Some(10.0);
    p.storage[0].unit.soc_kwh = soc;
    p.storage[0].terminal_value_per_kwh = 0.3;
    p
}

/// Every on/off schedule that honours the minimum up and down times, each
/// solved as an LP: the exact optimum by enumeration.
fn enumerate_schedules(p: &HorizonProblem) -> f64 {
    let nt = p.periods.len();
    let u = &p.oil[0];
    let mut best = f64::INFINITY;
    for mask in 0..(1u32 << nt) {
        let sched: Vec<bool> = (0..nt).map(|t| (mask >> t) & 1 == 1).collect();
        // Minimum up and down times, as runs of periods.
        let up = ((u.min_up_h / p.dt_h) - 1e-9).ceil() as usize;
        let down = ((u.min_down_h / p.dt_h) - 1e-9).ceil() as usize;
        let mut ok = true;
        let mut prev = u.running;
        let mut run_start = 0usize;
        for t in 0..=nt {
            let on = sched.get(t).copied();
            if on == Some(prev) {
                continue;
            }
            // A run of `prev` ended before t (or at the end of the horizon).
            let len = t - run_start;
            let min = if prev { up } else { down };
            let ended_inside = on.is_some();
            let started_inside = run_start > 0 || prev != u.running;
            if ended_inside && started_inside && len < min {
                ok = false;
            }
            if let Some(on) = on {
                prev = on;
                run_start = t;
            }
        }
        if !ok {
            continue;
        }
        let mut map = BTreeMap::new();
        map.insert(u.id.clone(), sched.clone());
        let fixed = commitment::with_schedule(p, &map);
        if let Ok(s) = fixed.solve() {
            best = best.min(s.objective + commitment::fixed_costs(p, &map));
        }
    }
    best
}

#[test]
fn optimal_commitment_matches_every_schedule_enumerated() {
    for soc in [25.0, 60.0, 150.0] {
        let p = committed(8, 0.5, soc);
        let s = p.solve().unwrap();
        let c = s.commitment.as_ref().unwrap();
        assert!(c.proven, "soc {soc}: {c:?}");
        let exact = enumerate_schedules(&p);
        assert!(
            (s.objective - exact).abs() <= 1e-3 + 2e-4 * exact.abs(),
            "soc {soc}: branch and bound {} vs enumeration {exact}",
            s.objective
        );
        assert!(c.lower_bound <= s.objective + 1e-6);
        // The diesel runs exactly when the schedule says, within its band.
        let sched = &c.running["dg1"];
        for (t, r) in s.periods.iter().enumerate() {
            let kw = r.setpoints_kw.get("dg1").unwrap();
            if sched[t] {
                assert!(kw >= 30.0 - 1e-6, "period {t}: {kw}");
            } else {
                assert!(kw.abs() < 1e-6, "period {t}: {kw}");
            }
        }
    }
}

#[test]
fn a_running_diesel_is_held_on_for_its_minimum_up_time() {
    let mut p = committed(8, 0.25, 180.0);
    // Plenty of sun and a full battery: stopping at once would be cheapest.
    for per in &mut p.periods {
        per.available_kw.insert("pv1".into(), 100.0);
    }
    let dg = &mut p.oil[0];
    dg.running = true;
    dg.hours_in_state = Some(0.1);
    dg.min_up_h = 0.75;
    let s = p.solve().unwrap();
    let sched = &s.commitment.unwrap().running["dg1"];
    // 0.65 h left: periods 0, 1 and 2 (0.75 h) run, then it stops.
    assert_eq!(&sched[..4], &[true, true, true, false], "{sched:?}");
}

#[test]
fn a_four_hour_horizon_at_15_minutes_plans_quickly() {
    // The live loop's shape: 16 periods, a low battery at night.
    let p = committed(16, 0.25, 30.0);
    let s = p.solve().unwrap();
    let c = s.commitment.unwrap();
    assert!(c.proven, "{} nodes", c.nodes);
    assert!(c.nodes < 4000, "{} nodes", c.nodes);
}
