//! The horizon's LP (a QP with smoothing): variables, state-of-charge
//! dynamics, ramps, reserve, the renewable share and the objective.

use crate::dispatch::lp::{Model, Sense};

use super::{HorizonProblem, HorizonRenewable};

impl HorizonProblem {
    /// The on/off, start and stop variables of oil unit `k` in period `t`,
    /// whose output is `p`, with the rows that tie them together (the
    /// three-variable unit-commitment formulation, tight in its relaxation):
    /// - `min_kw·on ≤ p ≤ max_kw·on`;
    /// - `on_t − on_{t−1} = start_t − stop_t` (`on_{−1}` is `running`);
    /// - minimum up time: `Σ start` over the last `U` periods `≤ on_t`;
    /// - minimum down time: `Σ stop` over the last `D` periods `≤ 1 − on_t`;
    /// - the first periods are forced while the present state's minimum
    ///   time runs;
    /// - ramps between periods, lifted by `max_kw` on a start or stop.
    ///
    /// Costs: `dt·no_load` per period on, `start_cost` per start.
    fn commitment_vars(&self, m: &mut Model, v: &mut HVars, t: usize, k: usize, p: usize) -> usize {
        let u = &self.oil[k];
        let dt = self.dt_h;
        if v.commit.len() <= k {
            v.commit.resize(self.oil.len(), Vec::new());
        }
        let forced = (t < u.forced_periods(dt)).then_some(if u.running { 1.0 } else { 0.0 });
        let (lo, hi) = forced.map_or((0.0, 1.0), |f| (f, f));
        let on = m.var(
            format!("{} runs in period {t}", u.id),
            lo,
            hi,
            dt * u.no_load_cost_per_h,
        );
        let start = m.var(
            format!("{} starts in period {t}", u.id),
            0.0,
            1.0,
            u.start_cost,
        );
        let stop = m.var(format!("{} stops in period {t}", u.id), 0.0, 1.0, 0.0);
        m.row(
            format!("{} output within its rating in period {t}", u.id),
            vec![(p, 1.0), (on, -u.max_kw)],
            Sense::Le,
            0.0,
        );
        m.row(
            format!("{} minimum stable load in period {t}", u.id),
            vec![(p, -1.0), (on, u.min_kw)],
            Sense::Le,
            0.0,
        );
        let mut transition = vec![(on, 1.0), (start, -1.0), (stop, 1.0)];
        let mut rhs = 0.0;
        match v.commit[k].last() {
            Some(prev) => transition.push((prev.on, -1.0)),
            None => rhs = if u.running { 1.0 } else { 0.0 },
        }
        m.row(
            format!("{} start and stop in period {t}", u.id),
            transition,
            Sense::Eq,
            rhs,
        );
        v.commit[k].push(CommitVars { on, start, stop });
        let periods = |h: f64| ((h / dt) - 1e-9).ceil().max(1.0) as usize;
        let window = |n: usize| t + 1 - n.min(t + 1);
        let hist = &v.commit[k];
        if u.min_up_h > 0.0 {
            let mut row: Vec<(usize, f64)> = hist[window(periods(u.min_up_h))..]
                .iter()
                .map(|c| (c.start, 1.0))
                .collect();
            row.push((on, -1.0));
            m.row(
                format!("{} minimum up time in period {t}", u.id),
                row,
                Sense::Le,
                0.0,
            );
        }
        if u.min_down_h > 0.0 {
            let mut row: Vec<(usize, f64)> = hist[window(periods(u.min_down_h))..]
                .iter()
                .map(|c| (c.stop, 1.0))
                .collect();
            row.push((on, 1.0));
            m.row(
                format!("{} minimum down time in period {t}", u.id),
                row,
                Sense::Le,
                1.0,
            );
        }
        if u.ramp_kw_per_s > 0.0 {
            let r = u.ramp_kw_per_s * 3600.0 * dt;
            let prev_p = if t == 0 {
                None
            } else {
                // The output variable of the previous period is the one
                // named so; found through the unit list of that period.
                v.units[t - 1]
                    .iter()
                    .find(|(id, _)| *id == u.id)
                    .map(|(_, j)| *j)
            };
            // p − p_prev ≤ r + max·start and p_prev − p ≤ r + max·stop
            // (p_prev is the setpoint in force before the first period).
            let mut up = vec![(p, 1.0), (start, -u.max_kw)];
            let mut down = vec![(p, -1.0), (stop, -u.max_kw)];
            let rhs0 = match prev_p {
                Some(pp) => {
                    up.push((pp, -1.0));
                    down.push((pp, 1.0));
                    0.0
                }
                None => u.initial_kw.unwrap_or(0.0),
            };
            m.row(
                format!("{} ramp-up limit in period {t}", u.id),
                up,
                Sense::Le,
                rhs0 + r,
            );
            m.row(
                format!("{} ramp-down limit in period {t}", u.id),
                down,
                Sense::Le,
                r - rhs0,
            );
        }
        on
    }
}

impl HorizonProblem {
    pub(super) fn build(&self) -> (Model, HVars) {
        let dt = self.dt_h;
        let nt = self.periods.len();
        let w = self.smoothing_cost_per_kw2;
        let ramp = |r: f64| if r > 0.0 { Some(r * 3600.0 * dt) } else { None };
        let mut m = Model::default();
        let mut v = HVars::default();
        // Per unit: variable of the previous period, for ramps and smoothing.
        let mut prev_ren: Vec<Option<usize>> = vec![None; self.pv.len() + self.wind.len()];
        let mut prev_oil: Vec<Option<usize>> = vec![None; self.oil.len()];
        let mut prev_sto: Vec<Option<(usize, usize, usize)>> = vec![None; self.storage.len()];
        let renewables: Vec<(&HorizonRenewable, bool)> = self
            .pv
            .iter()
            .map(|u| (u, true))
            .chain(self.wind.iter().map(|u| (u, false)))
            .collect();
        for (t, per) in self.periods.iter().enumerate() {
            let mut units = Vec::new();
            let mut bal: Vec<(usize, f64)> = Vec::new();
            let mut adjust: Vec<(usize, f64)> = Vec::new();
            let mut ren_vars: Vec<(usize, bool)> = Vec::new();
            for (i, (u, is_pv)) in renewables.iter().enumerate() {
                let avail = per.available_kw.get(&u.id).copied().unwrap_or(0.0);
                let j = m.var(
                    format!("{} output in period {t}", u.id),
                    0.0,
                    avail,
                    dt * u.cost_per_kwh,
                );
                units.push((u.id.clone(), j));
                bal.push((j, 1.0));
                adjust.push((j, 1.0));
                ren_vars.push((j, *is_pv));
                if let Some(r) = ramp(u.ramp_kw_per_s) {
                    match (prev_ren[i], u.initial_kw) {
                        (Some(p), _) => m.row(
                            format!("{} ramp-up limit in period {t}", u.id),
                            vec![(j, 1.0), (p, -1.0)],
                            Sense::Le,
                            r,
                        ),
                        (None, Some(init)) => m.row(
                            format!("{} ramp-up limit in period {t}", u.id),
                            vec![(j, 1.0)],
                            Sense::Le,
                            init + r,
                        ),
                        (None, None) => {}
                    }
                }
                if w > 0.0 {
                    match (prev_ren[i], u.initial_kw) {
                        (Some(p), _) => m.add_square(w, &[(j, 1.0), (p, -1.0)], 0.0),
                        (None, Some(init)) => m.add_square(w, &[(j, 1.0)], init),
                        (None, None) => {}
                    }
                }
                prev_ren[i] = Some(j);
            }
            // (output, its on/off variable when decided here, max_kw)
            let mut oil_running: Vec<(usize, Option<usize>, f64)> = Vec::new();
            for (k, u) in self.oil.iter().enumerate() {
                let (lo, hi, run) = self.oil_band(t, k);
                let j = m.var(
                    format!("{} output in period {t}", u.id),
                    lo,
                    hi,
                    dt * u.cost_per_kwh,
                );
                units.push((u.id.clone(), j));
                bal.push((j, 1.0));
                if u.optimize_commitment {
                    let on = self.commitment_vars(&mut m, &mut v, t, k, j);
                    oil_running.push((j, Some(on), u.max_kw));
                    prev_oil[k] = Some(j);
                    continue;
                }
                if run {
                    adjust.push((j, 1.0));
                    oil_running.push((j, None, u.max_kw));
                }
                let was_running = if t == 0 {
                    u.initial_kw.is_some()
                } else {
                    self.oil_band(t - 1, k).2
                };
                if let (Some(r), true, true) = (ramp(u.ramp_kw_per_s), run, was_running) {
                    let (coefs, rhs0): (Vec<(usize, f64)>, f64) = match prev_oil[k] {
                        Some(p) => (vec![(j, 1.0), (p, -1.0)], 0.0),
                        None => (vec![(j, 1.0)], u.initial_kw.unwrap_or(0.0)),
                    };
                    let neg: Vec<(usize, f64)> = coefs.iter().map(|&(a, c)| (a, -c)).collect();
                    m.row(
                        format!("{} ramp-up limit in period {t}", u.id),
                        coefs,
                        Sense::Le,
                        rhs0 + r,
                    );
                    m.row(
                        format!("{} ramp-down limit in period {t}", u.id),
                        neg,
                        Sense::Le,
                        r - rhs0,
                    );
                }
                if w > 0.0 {
                    match (prev_oil[k], u.initial_kw) {
                        (Some(p), _) => m.add_square(w, &[(j, 1.0), (p, -1.0)], 0.0),
                        (None, Some(init)) => m.add_square(w, &[(j, 1.0)], init),
                        (None, None) => {}
                    }
                }
                prev_oil[k] = Some(j);
            }
            let mut sto_vars = Vec::new();
            let mut headroom: Vec<usize> = Vec::new();
            for (k, s) in self.storage.iter().enumerate() {
                let u = &s.unit;
                let c = dt * u.cycle_cost_per_kwh;
                let ch = m.var(
                    format!("{} charge in period {t}", u.id),
                    0.0,
                    u.max_charge_kw,
                    c,
                );
                let dis = m.var(
                    format!("{} discharge in period {t}", u.id),
                    0.0,
                    u.max_discharge_kw,
                    c,
                );
                let end_value = if t + 1 == nt {
                    -s.terminal_value_per_kwh
                } else {
                    0.0
                };
                let floor = match s.final_soc_min_kwh {
                    Some(f) if t + 1 == nt => f.clamp(u.soc_min_kwh, u.soc_max_kwh),
                    _ => u.soc_min_kwh,
                };
                let soc = m.var(
                    format!("{} state of charge at the end of period {t}", u.id),
                    floor,
                    u.soc_max_kwh,
                    end_value,
                );
                bal.push((ch, -1.0));
                bal.push((dis, 1.0));
                // soc_t − soc_{t−1} − eff_c·dt·ch + dt/eff_d·dis = 0
                let mut dyn_row = vec![
                    (soc, 1.0),
                    (ch, -u.eff_charge * dt),
                    (dis, dt / u.eff_discharge),
                ];
                let mut rhs = 0.0;
                match prev_sto[k] {
                    Some((_, _, ps)) => dyn_row.push((ps, -1.0)),
                    None => {
                        rhs = u.soc_kwh;
                        v.first_soc_row.push(m.rows.len());
                    }
                }
                if v.soc_rows.len() <= t {
                    v.soc_rows.push(Vec::new());
                }
                v.soc_rows[t].push(m.rows.len());
                m.row(
                    format!("{} state-of-charge dynamics in period {t}", u.id),
                    dyn_row,
                    Sense::Eq,
                    rhs,
                );
                let net = [(dis, 1.0), (ch, -1.0)];
                if let Some(r) = ramp(s.ramp_kw_per_s) {
                    let (coefs, rhs0): (Vec<(usize, f64)>, f64) = match (prev_sto[k], s.initial_kw)
                    {
                        (Some((pc, pd, _)), _) => {
                            (vec![net[0], net[1], (pd, -1.0), (pc, 1.0)], 0.0)
                        }
                        (None, Some(init)) => (net.to_vec(), init),
                        (None, None) => (Vec::new(), 0.0),
                    };
                    if !coefs.is_empty() {
                        let neg: Vec<(usize, f64)> = coefs.iter().map(|&(a, c)| (a, -c)).collect();
                        m.row(
                            format!("{} ramp-up limit in period {t}", u.id),
                            coefs,
                            Sense::Le,
                            rhs0 + r,
                        );
                        m.row(
                            format!("{} ramp-down limit in period {t}", u.id),
                            neg,
                            Sense::Le,
                            r - rhs0,
                        );
                    }
                }
                if w > 0.0 {
                    match (prev_sto[k], s.initial_kw) {
                        (Some((pc, pd, _)), _) => {
                            m.add_square(w, &[net[0], net[1], (pd, -1.0), (pc, 1.0)], 0.0)
                        }
                        (None, Some(init)) => m.add_square(w, &net, init),
                        (None, None) => {}
                    }
                }
                if self.reserve.is_some() {
                    let h = m.var(
                        format!("{} reserve headroom in period {t}", u.id),
                        0.0,
                        u.max_discharge_kw + u.max_charge_kw,
                        0.0,
                    );
                    // h ≤ max_dis − dis + ch
                    m.row(
                        format!("{} reserve power limit in period {t}", u.id),
                        vec![(h, 1.0), (dis, 1.0), (ch, -1.0)],
                        Sense::Le,
                        u.max_discharge_kw,
                    );
                    // h ≤ (soc_{t−1} − soc_min)·eff_d/dt − dis + ch
                    let g = u.eff_discharge / dt;
                    let mut row = vec![(h, 1.0), (dis, 1.0), (ch, -1.0)];
                    let rhs = match prev_sto[k] {
                        Some((_, _, ps)) => {
                            row.push((ps, -g));
                            -u.soc_min_kwh * g
                        }
                        None => (u.soc_kwh - u.soc_min_kwh) * g,
                    };
                    m.row(
                        format!("{} reserve energy limit in period {t}", u.id),
                        row,
                        Sense::Le,
                        rhs,
                    );
                    headroom.push(h);
                }
                sto_vars.push((ch, dis, soc));
                prev_sto[k] = Some((ch, dis, soc));
            }
            let shed = m.var(
                format!("load shed in period {t}"),
                0.0,
                per.demand_kw,
                dt * self.voll_per_kwh,
            );
            bal.push((shed, 1.0));
            adjust.insert(0, (shed, 1.0));
            v.balance_row.push(m.rows.len());
            m.row(
                format!("power balance in period {t}"),
                bal,
                Sense::Eq,
                per.demand_kw,
            );
            // Cuts for the commitment search, valid for every on/off
            // schedule and tightening its relaxation, which would otherwise
            // buy a fraction of a running hour for a fraction of the no-load
            // cost: (1) a unit that is off leaves the whole demand to the
            // rest (renewables, storage discharge, other oil units,
            // shedding); (2) a unit that is on produces no more than demand
            // plus what storage can take.
            let absorb: f64 = self.storage.iter().map(|s| s.unit.max_charge_kw).sum();
            for (k, u) in self.oil.iter().enumerate() {
                let Some(c) = v.commit.get(k).and_then(|c| c.get(t)) else {
                    continue;
                };
                let mut row: Vec<(usize, f64)> = ren_vars.iter().map(|&(j, _)| (j, -1.0)).collect();
                row.extend(sto_vars.iter().map(|&(_, dis, _)| (dis, -1.0)));
                row.extend(
                    oil_running
                        .iter()
                        .filter(|(j, _, _)| units.iter().all(|(id, uj)| uj != j || *id != u.id))
                        .map(|&(j, _, _)| (j, -1.0)),
                );
                row.push((shed, -1.0));
                row.push((c.on, -per.demand_kw));
                m.row(
                    format!("{} off leaves the demand to the rest in period {t}", u.id),
                    row,
                    Sense::Le,
                    -per.demand_kw,
                );
                let p = units.iter().find(|(id, _)| *id == u.id).map(|(_, j)| *j);
                let cap = u.max_kw.min(per.demand_kw + absorb);
                if let Some(p) = p {
                    m.row(
                        format!(
                            "{} on produces at most demand plus storage in period {t}",
                            u.id
                        ),
                        vec![(p, 1.0), (c.on, -cap)],
                        Sense::Le,
                        0.0,
                    );
                }
            }
            let mut shortfall = None;
            if let Some(r) = &self.reserve {
                let need_max = r.load_frac * per.demand_kw
                    + ren_vars
                        .iter()
                        .map(|&(j, is_pv)| m.ub[j] * if is_pv { r.pv_frac } else { r.wind_frac })
                        .sum::<f64>();
                let sf = m.var(
                    format!("reserve shortfall in period {t}"),
                    0.0,
                    need_max,
                    dt * r.shortfall_cost_per_kwh,
                );
                // Σ(max − p_oil) + Σh + sf ≥ load_frac·D + pv_frac·Σp_pv + wind_frac·Σp_wind
                let mut row: Vec<(usize, f64)> = oil_running
                    .iter()
                    .flat_map(|&(j, on, mx)| {
                        // A unit decided here offers max_kw only when on.
                        let on = on.map(|u| (u, -mx));
                        std::iter::once((j, 1.0)).chain(on)
                    })
                    .collect();
                row.extend(headroom.iter().map(|&h| (h, -1.0)));
                row.push((sf, -1.0));
                row.extend(
                    ren_vars
                        .iter()
                        .map(|&(j, is_pv)| (j, if is_pv { r.pv_frac } else { r.wind_frac })),
                );
                let rhs = oil_running
                    .iter()
                    .filter(|(_, on, _)| on.is_none())
                    .map(|&(_, _, mx)| mx)
                    .sum::<f64>()
                    - r.load_frac * per.demand_kw;
                m.row(
                    format!("spinning reserve in period {t}"),
                    row,
                    Sense::Le,
                    rhs,
                );
                shortfall = Some(sf);
            }
            if let Some(share) = self.max_renewable_share {
                m.row(
                    format!("renewable share cap in period {t}"),
                    ren_vars.iter().map(|&(j, _)| (j, 1.0)).collect(),
                    Sense::Le,
                    share * per.demand_kw,
                );
            }
            v.units.push(units);
            v.storage.push(sto_vars);
            v.shed.push(shed);
            v.shortfall.push(shortfall);
            v.balance_adjust.push(adjust);
        }
        (m, v)
    }
}

#[derive(Default)]
pub(super) struct HVars {
    pub(super) units: Vec<Vec<(String, usize)>>,
    /// Per period, per storage: (charge, discharge, soc at end).
    pub(super) storage: Vec<Vec<(usize, usize, usize)>>,
    pub(super) shed: Vec<usize>,
    pub(super) shortfall: Vec<Option<usize>>,
    pub(super) balance_row: Vec<usize>,
    pub(super) balance_adjust: Vec<Vec<(usize, f64)>>,
    /// Per storage: the model row of its first-period state-of-charge
    /// dynamics, whose right-hand side is the starting state of charge.
    pub(super) first_soc_row: Vec<usize>,
    /// Per period, per storage: the model row of its state-of-charge
    /// dynamics (its price is the worth of a kWh at the period's start).
    pub(super) soc_rows: Vec<Vec<usize>>,
    /// Per oil unit whose commitment is decided here, per period: its
    /// on/off (binary), start and stop variables.
    pub(super) commit: Vec<Vec<CommitVars>>,
}

#[derive(Debug, Clone, Copy)]
pub(super) struct CommitVars {
    pub(super) on: usize,
    pub(super) start: usize,
    pub(super) stop: usize,
}
