//! The report of a run: the plots sampled while it ran, the energy and cost
//! figures, and the [`Report`] built from them.

use std::collections::BTreeMap;
use std::time::Duration;

use gridscada_config::{Plant, UnitKind, UnitUsage};
use gridscada_control::dispatch::DispatchStatus;
use gridscada_sim::scenario::report::{
    CostBreakdown, CostComparison, FaultRecord, Line, Plot, Report,
};
use gridscada_sim::scenario::Scenario;
use gridscada_sim::SimSnapshot;

use super::clock::Pace;
use super::foresight::perfect_foresight;
use super::run::RunOutcome;

/// The report's plots, sampled every `scenario.sample`.
pub(super) struct Sampler {
    t: Vec<f64>,
    lines: BTreeMap<(usize, String), Vec<f64>>,
    titles: Vec<(&'static str, &'static str)>,
    with_dispatch: bool,
}

impl Sampler {
    pub(super) fn new(_first: &SimSnapshot, with_dispatch: bool) -> Self {
        Sampler {
            t: Vec::new(),
            lines: BTreeMap::new(),
            titles: vec![
                ("Power by source and demand", "kW"),
                ("State of charge", "%"),
                ("Dispatch setpoints", "kW"),
                ("Panel load (power analyzers)", "kW"),
            ],
            with_dispatch,
        }
    }

    fn put(&mut self, plot: usize, name: &str, v: f64) {
        let n = self.t.len();
        let line = self.lines.entry((plot, name.to_string())).or_default();
        line.resize(n - 1, f64::NAN);
        line.push(v);
    }

    pub(super) fn push(
        &mut self,
        t: Duration,
        snap: &SimSnapshot,
        dispatch: Option<&DispatchStatus>,
    ) {
        self.t.push(t.as_secs_f64());
        if let Some(mg) = &snap.microgrid {
            for u in &mg.units {
                self.put(0, &u.id, u.p_kw);
                if let Some(p) = u.soc_pct {
                    self.put(1, &u.id, p);
                }
            }
            self.put(0, "demand", mg.demand_kw);
        }
        if self.with_dispatch {
            if let Some(d) = dispatch {
                for (id, v) in &d.setpoints_kw.0 {
                    self.put(2, id, *v);
                }
                self.put(2, "shed", d.shed_kw);
            }
        }
        for p in &snap.panels {
            self.put(3, &p.id, p.analyzer.p_kw);
        }
    }

    pub(super) fn plots(self) -> Vec<Plot> {
        let n = self.t.len();
        let mut out = Vec::new();
        for (i, (title, unit)) in self.titles.iter().enumerate() {
            let lines: Vec<Line> = self
                .lines
                .iter()
                .filter(|((p, _), _)| *p == i)
                .map(|((_, name), v)| {
                    let mut values = v.clone();
                    values.resize(n, f64::NAN);
                    Line {
                        name: name.clone(),
                        values,
                    }
                })
                .collect();
            if !lines.is_empty() {
                out.push(Plot {
                    title: title.to_string(),
                    unit: unit.to_string(),
                    t_s: self.t.clone(),
                    lines,
                });
            }
        }
        out
    }
}

/// Energy and cost figures of one run (end minus the start of the scenario).
fn energy_figures(
    plant: &Plant,
    scn: &Scenario,
    r: &RunOutcome,
) -> (BTreeMap<String, f64>, CostBreakdown) {
    let mut f = BTreeMap::new();
    let mut cost = CostBreakdown::default();
    let (Some(mg0), Some(mg1), Some(cfg)) =
        (&r.baseline.microgrid, &r.end.microgrid, &plant.microgrid)
    else {
        return (f, cost);
    };
    let e0 = &mg0.energy;
    let e1 = &mg1.energy;
    f.insert("demand_kwh".into(), e1.demand_kwh - e0.demand_kwh);
    f.insert("served_kwh".into(), e1.served_kwh - e0.served_kwh);
    let unserved = e1.unserved_kwh - e0.unserved_kwh;
    f.insert("unserved_kwh".into(), unserved);
    f.insert("curtailed_kwh".into(), e1.curtailed_kwh - e0.curtailed_kwh);
    f.insert("surplus_kwh".into(), e1.surplus_kwh - e0.surplus_kwh);
    let (mut pv, mut wind, mut dkwh, mut fuel, mut starts, mut run_s) =
        (0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
    let (mut charged, mut discharged, mut energy_cost, mut cycling) = (0.0, 0.0, 0.0, 0.0);
    let mut diesel_cost = 0.0;
    let price = cfg.fuel_price(scn.fuel_price_per_l);
    let mut soc_end = f64::NAN;
    for u1 in &mg1.units {
        let Some(u0) = mg0.units.iter().find(|u| u.id == u1.id) else {
            continue;
        };
        let Some(c) = cfg.units.iter().find(|c| c.id.get_ref() == &u1.id) else {
            continue;
        };
        let (a, b) = (&u0.counters, &u1.counters);
        let e = b.energy_kwh - a.energy_kwh;
        let usage = UnitUsage {
            kwh: e,
            charged_kwh: b.charged_kwh - a.charged_kwh,
            run_h: (b.runtime_s - a.runtime_s) / 3600.0,
            starts: (b.starts - a.starts) as f64,
        };
        // The plant's one cost function, the dispatch's objective's.
        let unit_cost = cfg.unit_cost(c, price, &usage);
        match u1.kind {
            UnitKind::Pv => {
                pv += e;
                energy_cost += unit_cost;
            }
            UnitKind::Wind => {
                wind += e;
                energy_cost += unit_cost;
            }
            UnitKind::Diesel => {
                diesel_cost += unit_cost;
                dkwh += e;
                fuel += b.fuel_l - a.fuel_l;
                starts += usage.starts;
                run_s += usage.run_h * 3600.0;
            }
            UnitKind::Storage => {
                discharged += e;
                charged += usage.charged_kwh;
                cycling += unit_cost;
                soc_end = u1.soc_pct.unwrap_or(f64::NAN);
            }
        }
    }
    f.insert("pv_kwh".into(), pv);
    f.insert("wind_kwh".into(), wind);
    f.insert("diesel_kwh".into(), dkwh);
    f.insert("diesel_fuel_l".into(), fuel);
    f.insert("diesel_starts".into(), starts);
    f.insert("diesel_runtime_h".into(), run_s / 3600.0);
    f.insert("storage_charged_kwh".into(), charged);
    f.insert("storage_discharged_kwh".into(), discharged);
    f.insert("storage_throughput_kwh".into(), charged + discharged);
    if r.soc_min_pct.is_finite() {
        f.insert("soc_min_pct".into(), r.soc_min_pct);
    }
    if soc_end.is_finite() {
        f.insert("soc_end_pct".into(), soc_end);
    }
    cost = CostBreakdown::new(
        diesel_cost,
        energy_cost,
        cycling,
        unserved * cfg.voll_per_kwh,
    );
    f.insert("fuel_cost".into(), cost.fuel);
    f.insert("total_cost".into(), cost.total);
    f.insert("dispatch_shed_kwh".into(), r.shed_kwh);
    f.insert(
        "dispatch_fallback_periods".into(),
        r.fallback_periods as f64,
    );
    (f, cost)
}

pub(super) fn build_report(
    scn: &Scenario,
    plant: &Plant,
    pace: Pace,
    main: RunOutcome,
    rule: Option<RunOutcome>,
) -> Report {
    let (mut figures, optimal) = energy_figures(plant, scn, &main);
    let rule_cost = rule.as_ref().map(|r| energy_figures(plant, scn, r).1);
    let ratio = rule_cost
        .as_ref()
        .filter(|r| r.total > 0.0)
        .map(|r| optimal.total / r.total);
    if let Some(r) = &rule_cost {
        figures.insert("rule_total_cost".into(), r.total);
    }
    if let Some(x) = ratio {
        figures.insert("cost_ratio".into(), x);
    }
    let fuel_price = plant
        .microgrid
        .as_ref()
        .and_then(|m| m.fuel_price(scn.fuel_price_per_l));
    let optimum = perfect_foresight(
        plant,
        fuel_price,
        &main.foresight,
        &main.baseline,
        &main.end,
    );
    if let Some(cost) = optimum.as_ref().and_then(|o| o.cost) {
        figures.insert("optimum_cost".into(), cost);
        if cost > 0.0 {
            figures.insert("optimum_ratio".into(), optimal.total / cost);
        }
    }
    // Against the proven lower bound: never flattering, whether or not the
    // search proved its schedule optimal.
    if let Some(bound) = optimum.as_ref().and_then(|o| o.lower_bound) {
        figures.insert("optimum_lower_bound".into(), bound);
        if bound > 0.0 {
            figures.insert("optimum_bound_ratio".into(), optimal.total / bound);
        }
    }
    let a = &main.alarms;
    figures.insert("alarm_activations".into(), f64::from(a.activations));
    figures.insert("alarm_active_end".into(), a.active_end as f64);
    figures.insert("alarm_unacked_end".into(), a.unacked_end as f64);
    figures.insert("alarm_floods".into(), f64::from(a.floods));
    figures.insert("alarm_max_per_10min".into(), a.max_per_10min);
    figures.insert("alarm_avg_per_10min".into(), a.average_per_10min);
    figures.insert("alarm_percent_in_flood".into(), a.percent_time_in_flood);
    figures.insert("alarm_chattering".into(), a.chattering.len() as f64);
    figures.insert("fault_sequences".into(), main.faults.len() as f64);
    figures.insert("poll_timeouts".into(), main.poll_timeouts as f64);
    figures.insert("historian_dropped".into(), main.historian_dropped as f64);
    for (i, p) in plant.panels.iter().enumerate() {
        let id = p.id.get_ref();
        let seqs: Vec<&FaultRecord> = main.faults.iter().filter(|f| &f.panel == id).collect();
        let put = |f: &mut BTreeMap<String, f64>, k: &str, v: f64| {
            f.insert(format!("{id}.{k}"), v);
        };
        put(&mut figures, "sequences", seqs.len() as f64);
        // Restoration times only of sequences that restored: a figure that
        // no sequence gives is left out (an expectation on it fails as "not
        // in this run's report") rather than reading 0 s.
        if let Some(max) = seqs.iter().filter_map(|f| f.restore_s).reduce(f64::max) {
            put(&mut figures, "restore_s_max", max);
        }
        if let Some(last) = seqs.last().and_then(|f| f.restore_s) {
            put(&mut figures, "restore_s_last", last);
        }
        put(
            &mut figures,
            "switching_ops",
            seqs.iter().map(|f| f64::from(f.switching_ops)).sum::<f64>() + 0.0,
        );
        put(
            &mut figures,
            "reenergisations",
            seqs.iter()
                .map(|f| f64::from(f.reenergisations))
                .sum::<f64>()
                + 0.0,
        );
        let trips = |s: &SimSnapshot| s.panels.get(i).map(|p| p.elcb_trips).unwrap_or(0);
        put(
            &mut figures,
            "elcb_trips",
            trips(&main.end).saturating_sub(trips(&main.baseline)) as f64,
        );
        put(
            &mut figures,
            "lockout",
            f64::from(u8::from(main.panel_end.get(i).is_some_and(|s| s.lockout))),
        );
        put(
            &mut figures,
            "zones_closed_end",
            main.end
                .panels
                .get(i)
                .map(|p| p.zones.iter().filter(|z| z.breaker.closed).count())
                .unwrap_or(0) as f64,
        );
    }
    let wall_s = main.wall.as_secs_f64().max(1e-6);
    let speedup = scn.duration.as_secs_f64() / wall_s;
    figures.insert("wall_s".into(), wall_s);
    figures.insert("speedup".into(), speedup);

    let mut expectations = main.results.clone();
    for x in &scn.expectations {
        if x.due().is_none() {
            expectations.push(x.judge_figure(&figures));
        }
    }
    expectations.sort_by_key(|e| e.line);
    let passed = expectations.iter().all(|e| e.acceptable());
    let mut notes = Vec::new();
    if main.historian_dropped > 0 {
        notes.push(format!(
            "the historian dropped {} samples (its writer fell behind the compressed clock)",
            main.historian_dropped
        ));
    }
    if let Some(r) = &rule {
        notes.push(format!(
            "rule-based baseline replayed in {:.1} s of wall time",
            r.wall.as_secs_f64()
        ));
    }
    Report {
        scenario: scn.name.clone(),
        description: scn.description.clone(),
        file: scn.path.display().to_string(),
        plant: scn
            .plant
            .as_ref()
            .map(|p| p.display().to_string())
            .unwrap_or_else(|| "embedded demo plant".into()),
        seed: scn.seed,
        start_ms: scn.start.as_millis(),
        duration_s: scn.duration.as_secs_f64(),
        step_s: scn.step.as_secs_f64(),
        clock: pace.label(),
        wall_s,
        speedup,
        passed,
        figures,
        cost: CostComparison {
            fuel_price_per_l: fuel_price.unwrap_or(0.0),
            voll_per_kwh: plant
                .microgrid
                .as_ref()
                .map(|m| m.voll_per_kwh)
                .unwrap_or(0.0),
            optimal,
            rule: rule_cost,
            optimum,
            ratio,
        },
        alarms: main.alarms,
        faults: main.faults,
        expectations,
        timeline: main.timeline,
        plots: main.plots,
        notes,
    }
}
