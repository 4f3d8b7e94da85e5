//! The islanded microgrid: PV, wind, storage and diesel units, each with the
//! seed's inner-loop controller, a load, and the power balance.
//!
//! Owns the unit physics (available power, state of charge, diesel start,
//! minimum load and ramp), the controllers that track each unit's power
//! setpoint, the environment (irradiance, wind, demand), frequency and the
//! energy counters. Must not touch registers or sockets: it is advanced in
//! plant time by the simulator and read back as numbers.

use std::time::Duration;

use gridscada_config::{MicrogridConfig, UnitConfig, UnitKind};
use gridscada_tagdb::Timestamp;
use serde::Serialize;

use crate::profile::{builtin_demand, builtin_irradiance, builtin_wind_speed, Profile};

/// A unit controller's state, as its `State` register reports it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum UnitState {
    Off = 0,
    Running = 1,
    Fault = 2,
    Starting = 3,
}

/// Physical constants of the microgrid model that are not in the plant
/// configuration.
#[derive(Debug, Clone)]
pub struct MicrogridParams {
    /// PV losses (inverter, soiling, temperature): available = rated × G/1000 × derate.
    pub pv_derate: f64,
    /// Wind power curve: cut-in, rated and cut-out speeds, m/s.
    pub wind_cut_in: f64,
    pub wind_rated: f64,
    pub wind_cut_out: f64,
    /// Diesel: time from the run command to synchronised.
    pub diesel_start_delay: Duration,
    /// Diesel fuel line where the unit configures none: l/h = f0 × max_kw +
    /// f1 × P. A unit's `fuel_no_load_l_per_h` and `fuel_l_per_kwh` replace
    /// `f0 × max_kw` and `f1`, so the simulated diesel burns what the
    /// dispatch's cost model says it burns.
    pub diesel_fuel_f0: f64,
    pub diesel_fuel_f1: f64,
    /// Frequency deviation per kW of imbalance (supply − demand), Hz/kW.
    pub hz_per_kw: f64,
    /// Voltage deviation per kW of imbalance, V/kW.
    pub v_per_kw: f64,
    /// Nominal phase voltage, V.
    pub v_nominal: f64,
    /// Load power factor.
    pub load_pf: f64,
    /// Initial state of charge as a fraction of capacity (clamped to the bounds).
    pub initial_soc_frac: f64,
    /// Storage inverters are grid-forming: they take up the island's
    /// instantaneous imbalance on top of their setpoints (see `form_grid`).
    /// Off, storage follows its setpoint only, like the other units.
    pub storage_grid_forming: bool,
}

impl Default for MicrogridParams {
    fn default() -> Self {
        MicrogridParams {
            pv_derate: 0.95,
            wind_cut_in: 3.0,
            wind_rated: 12.0,
            wind_cut_out: 25.0,
            diesel_start_delay: Duration::from_secs(10),
            diesel_fuel_f0: 0.08145,
            diesel_fuel_f1: 0.246,
            hz_per_kw: 0.02,
            v_per_kw: 0.1,
            v_nominal: 230.0,
            load_pf: 0.95,
            initial_soc_frac: 0.5,
            storage_grid_forming: true,
        }
    }
}

/// One unit and its inner-loop controller.
#[derive(Debug, Clone)]
pub(crate) struct Unit {
    pub cfg: UnitConfig,
    pub state: UnitState,
    /// Setpoint from the outer loop, kW (storage: + discharge, − charge).
    pub setpoint_kw: f64,
    pub p_kw: f64,
    pub available_kw: f64,
    pub soc_kwh: f64,
    pub run_cmd: bool,
    /// Diesel: when the start completes.
    start_due: Option<Timestamp>,
    /// Diesel: ramping down to stop.
    stopping: bool,
    pub fuel_rate_lph: f64,
    pub counters: UnitCounters,
}

/// Energy counters of one unit since the simulator started.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct UnitCounters {
    /// Energy delivered (storage: discharged), kWh.
    pub energy_kwh: f64,
    /// PV / wind: available but not produced, kWh.
    pub curtailed_kwh: f64,
    /// Storage: energy taken in at the terminals, kWh.
    pub charged_kwh: f64,
    /// Diesel.
    pub fuel_l: f64,
    pub starts: u64,
    pub runtime_s: f64,
    /// Trips (injected).
    pub trips: u64,
}

/// Energy balance counters of the microgrid.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct BalanceCounters {
    pub demand_kwh: f64,
    pub served_kwh: f64,
    pub unserved_kwh: f64,
    /// Supply above demand (neither stored nor curtailed), kWh.
    pub surplus_kwh: f64,
    /// PV and wind curtailment, kWh.
    pub curtailed_kwh: f64,
}

#[derive(Debug, Clone)]
pub(crate) struct Microgrid {
    pub units: Vec<Unit>,
    pub irradiance: Profile,
    pub wind_speed: Profile,
    pub demand: Profile,
    /// Current environment values.
    pub irradiance_w_m2: f64,
    pub wind_speed_m_s: f64,
    pub demand_kw: f64,
    pub supply_kw: f64,
    pub hz: f64,
    pub v: f64,
    pub counters: BalanceCounters,
    params: MicrogridParams,
    last: Timestamp,
}

/// Longest integration step.
const MAX_STEP: Duration = Duration::from_millis(100);

impl Microgrid {
    pub fn new(cfg: &MicrogridConfig, params: MicrogridParams, now: Timestamp) -> Self {
        let units = cfg
            .units
            .iter()
            .map(|u| {
                let soc = (u.capacity_kwh * params.initial_soc_frac)
                    .clamp(u.soc_min_kwh, u.soc_max_kwh.max(u.soc_min_kwh));
                Unit {
                    cfg: u.clone(),
                    state: match u.kind {
                        UnitKind::Diesel => UnitState::Off,
                        _ => UnitState::Running,
                    },
                    // Renewables start uncurtailed, as an inverter without a
                    // limit does; storage and diesel start at zero.
                    setpoint_kw: match u.kind {
                        UnitKind::Pv | UnitKind::Wind => u.rated_kw,
                        _ => 0.0,
                    },
                    p_kw: 0.0,
                    available_kw: 0.0,
                    soc_kwh: if u.kind == UnitKind::Storage {
                        soc
                    } else {
                        0.0
                    },
                    run_cmd: false,
                    start_due: None,
                    stopping: false,
                    fuel_rate_lph: 0.0,
                    counters: UnitCounters::default(),
                }
            })
            .collect();
        let mut mg = Microgrid {
            units,
            irradiance: Profile::Builtin,
            wind_speed: Profile::Builtin,
            demand: Profile::Builtin,
            irradiance_w_m2: 0.0,
            wind_speed_m_s: 0.0,
            demand_kw: 0.0,
            supply_kw: 0.0,
            hz: 50.0,
            v: params.v_nominal,
            counters: BalanceCounters::default(),
            params,
            last: now,
        };
        mg.sample_environment(now);
        for i in 0..mg.units.len() {
            mg.units[i].available_kw = mg.available(i);
        }
        mg.balance();
        mg
    }

    /// Integrates the microgrid from its last time to `now`.
    pub fn advance_to(&mut self, now: Timestamp) {
        // A clock jump of hours would take many steps; cap the count and
        // lengthen the step instead (the model is stable for long steps).
        let gap = now.since(self.last);
        let step = MAX_STEP.max(gap / 100_000);
        while self.last < now {
            let dt = now.since(self.last).min(step);
            if dt.is_zero() {
                break;
            }
            let t = self.last.add(dt);
            self.step(t, dt.as_secs_f64());
            self.last = t;
        }
    }

    /// Reads the input profiles at `t` (also at once after a profile
    /// changes, so the meters show the new input without waiting a step).
    pub(crate) fn sample_environment(&mut self, t: Timestamp) {
        self.irradiance_w_m2 = self.irradiance.value(t, builtin_irradiance).max(0.0);
        self.wind_speed_m_s = self.wind_speed.value(t, builtin_wind_speed).max(0.0);
        self.demand_kw = self.demand.value(t, builtin_demand).max(0.0);
    }

    /// What unit `i` could produce now from its resource (PV, wind).
    fn available(&self, i: usize) -> f64 {
        let u = &self.units[i];
        let p = &self.params;
        match u.cfg.kind {
            UnitKind::Pv => (u.cfg.rated_kw * self.irradiance_w_m2 / 1000.0 * p.pv_derate)
                .clamp(0.0, u.cfg.rated_kw),
            UnitKind::Wind => {
                let v = self.wind_speed_m_s;
                if v < p.wind_cut_in || v >= p.wind_cut_out {
                    0.0
                } else if v >= p.wind_rated {
                    u.cfg.rated_kw
                } else {
                    let (a, b) = (p.wind_cut_in.powi(3), p.wind_rated.powi(3));
                    u.cfg.rated_kw * (v.powi(3) - a) / (b - a)
                }
            }
            UnitKind::Storage => u.cfg.max_discharge_kw,
            UnitKind::Diesel => {
                if u.state == UnitState::Running && !u.stopping {
                    u.cfg.max_kw
                } else {
                    0.0
                }
            }
        }
    }

    fn step(&mut self, t: Timestamp, dt: f64) {
        self.sample_environment(t);
        for i in 0..self.units.len() {
            let avail = self.available(i);
            let start_delay = self.params.diesel_start_delay;
            let u = &mut self.units[i];
            let no_load = u
                .cfg
                .fuel_no_load_l_per_h
                .unwrap_or(self.params.diesel_fuel_f0 * u.cfg.max_kw);
            let per_kwh = u.cfg.fuel_l_per_kwh.unwrap_or(self.params.diesel_fuel_f1);
            u.available_kw = avail;
            if u.state == UnitState::Fault {
                u.p_kw = 0.0;
                u.fuel_rate_lph = 0.0;
                continue;
            }
            let ramp = u.cfg.ramp_kw_per_s;
            match u.cfg.kind {
                UnitKind::Pv | UnitKind::Wind => {
                    let target = finite_or(u.setpoint_kw, 0.0).clamp(0.0, avail);
                    // The resource caps output at once; the ramp limits only
                    // what the controller asks for.
                    u.p_kw = ramp_to(u.p_kw, target, ramp, dt).min(avail).max(0.0);
                    u.counters.curtailed_kwh += (avail - u.p_kw).max(0.0) * dt / 3600.0;
                    u.counters.energy_kwh += u.p_kw * dt / 3600.0;
                }
                UnitKind::Storage => {
                    // The inverter tracks its setpoint; the state of charge is
                    // integrated below, once grid-forming has set the power.
                    let (max_ch, max_dis) = storage_limits(u, dt);
                    let target = finite_or(u.setpoint_kw, 0.0).clamp(-max_ch, max_dis);
                    u.p_kw = ramp_to(u.p_kw, target, ramp, dt).clamp(-max_ch, max_dis);
                }
                UnitKind::Diesel => {
                    step_diesel(u, t, dt, start_delay, no_load, per_kwh);
                }
            }
        }
        self.form_grid(dt);
        self.balance();
        let h = dt / 3600.0;
        let served = self.supply_kw.clamp(0.0, self.demand_kw);
        let c = &mut self.counters;
        c.demand_kwh += self.demand_kw * h;
        c.served_kwh += served * h;
        c.unserved_kwh += (self.demand_kw - served) * h;
        c.surplus_kwh += (self.supply_kw - self.demand_kw).max(0.0) * h;
        c.curtailed_kwh = self.units.iter().map(|u| u.counters.curtailed_kwh).sum();
    }

    /// Grid-forming: in an island the storage inverters hold the balance.
    /// Whatever the other units and the setpoints leave between demand and
    /// supply, the storage takes up at once, within its power and state-of-
    /// charge limits (on top of its setpoint, as a droop response). Only what
    /// it cannot cover moves the frequency and counts as unserved or surplus.
    /// Then the state of charge is integrated with the power actually flowed.
    fn form_grid(&mut self, dt: f64) {
        let mut residual = self.demand_kw - self.units.iter().map(|u| u.p_kw).sum::<f64>();
        let grid_forming = self.params.storage_grid_forming;
        let h = dt / 3600.0;
        for u in &mut self.units {
            if u.cfg.kind != UnitKind::Storage {
                continue;
            }
            if grid_forming && u.state != UnitState::Fault {
                let (max_ch, max_dis) = storage_limits(u, dt);
                let p = (u.p_kw + residual).clamp(-max_ch, max_dis);
                residual -= p - u.p_kw;
                u.p_kw = p;
            }
            let c = &u.cfg;
            let eff_c = c.eff_charge.get_ref().clamp(0.01, 1.0);
            let eff_d = c.eff_discharge.get_ref().clamp(0.01, 1.0);
            if u.p_kw >= 0.0 {
                u.soc_kwh -= u.p_kw * h / eff_d;
                u.counters.energy_kwh += u.p_kw * h;
            } else {
                u.soc_kwh += -u.p_kw * h * eff_c;
                u.counters.charged_kwh += -u.p_kw * h;
            }
            // Rounding must not carry the state of charge past its bounds.
            let (lo, hi) = (
                c.soc_min_kwh.min(c.soc_max_kwh),
                c.soc_max_kwh.max(c.soc_min_kwh),
            );
            u.soc_kwh = u.soc_kwh.clamp(lo, hi);
        }
    }

    /// Islanded balance: frequency and voltage move with supply − demand.
    fn balance(&mut self) {
        self.supply_kw = self.units.iter().map(|u| u.p_kw).sum();
        let imbalance = self.supply_kw - self.demand_kw;
        self.hz = (50.0 + self.params.hz_per_kw * imbalance).clamp(47.5, 52.5);
        let vn = self.params.v_nominal;
        self.v = (vn + self.params.v_per_kw * imbalance).clamp(0.85 * vn, 1.15 * vn);
    }

    /// Current of a unit at the microgrid voltage (3-phase, per phase), A.
    pub fn current(&self, p_kw: f64) -> f64 {
        if self.v <= 0.0 {
            0.0
        } else {
            p_kw.abs() * 1000.0 / (3.0 * self.v)
        }
    }

    pub fn load_q_kvar(&self) -> f64 {
        let pf = self.params.load_pf.clamp(0.05, 1.0);
        self.demand_kw * (1.0 / (pf * pf) - 1.0).max(0.0).sqrt()
    }

    /// Trips unit `i`: fault state, output zero, until reset.
    pub fn trip(&mut self, i: usize, now: Timestamp) {
        self.advance_to(now);
        let u = &mut self.units[i];
        if u.state != UnitState::Fault {
            u.counters.trips += 1;
        }
        u.state = UnitState::Fault;
        u.p_kw = 0.0;
        u.start_due = None;
        u.stopping = false;
        u.fuel_rate_lph = 0.0;
        self.balance();
    }

    /// Clears a unit trip. A diesel comes back stopped and starts again if
    /// its run command is still on.
    pub fn reset(&mut self, i: usize, now: Timestamp) {
        self.advance_to(now);
        let u = &mut self.units[i];
        if u.state == UnitState::Fault {
            u.state = match u.cfg.kind {
                UnitKind::Diesel => UnitState::Off,
                _ => UnitState::Running,
            };
        }
    }
}

fn step_diesel(
    u: &mut Unit,
    t: Timestamp,
    dt: f64,
    start_delay: Duration,
    no_load_lph: f64,
    l_per_kwh: f64,
) {
    let c = &u.cfg;
    let ramp = c.ramp_kw_per_s;
    match u.state {
        UnitState::Off => {
            u.p_kw = 0.0;
            if u.run_cmd {
                u.state = UnitState::Starting;
                u.start_due = Some(t.add(start_delay));
                u.counters.starts += 1;
            }
        }
        UnitState::Starting => {
            if !u.run_cmd {
                u.state = UnitState::Off;
                u.start_due = None;
            } else if u.start_due.is_none_or(|d| t >= d) {
                u.state = UnitState::Running;
                u.start_due = None;
                u.stopping = false;
            }
        }
        UnitState::Running => {
            u.stopping = !u.run_cmd;
            let target = if u.stopping {
                0.0
            } else {
                // Never below minimum stable load while running.
                finite_or(u.setpoint_kw, 0.0).clamp(c.min_kw, c.max_kw)
            };
            u.p_kw = ramp_to(u.p_kw, target, ramp, dt).clamp(0.0, c.max_kw);
            if u.stopping && u.p_kw <= 0.0 {
                u.state = UnitState::Off;
                u.stopping = false;
            } else {
                u.counters.runtime_s += dt;
            }
        }
        UnitState::Fault => {}
    }
    u.fuel_rate_lph = match u.state {
        UnitState::Running | UnitState::Starting => no_load_lph + l_per_kwh * u.p_kw,
        _ => 0.0,
    };
    u.counters.fuel_l += u.fuel_rate_lph * dt / 3600.0;
    u.counters.energy_kwh += u.p_kw * dt / 3600.0;
}

/// Moves `from` toward `to` by at most `rate × dt` (rate 0 = unlimited).
/// The charge and discharge power a storage unit can take over a step of
/// `dt` seconds: its power limits, and what its state of charge allows.
fn storage_limits(u: &Unit, dt: f64) -> (f64, f64) {
    let c = &u.cfg;
    let h = dt / 3600.0;
    let eff_c = c.eff_charge.get_ref().clamp(0.01, 1.0);
    let eff_d = c.eff_discharge.get_ref().clamp(0.01, 1.0);
    let max_dis = c
        .max_discharge_kw
        .min(((u.soc_kwh - c.soc_min_kwh) * eff_d / h).max(0.0));
    let max_ch = c
        .max_charge_kw
        .min(((c.soc_max_kwh - u.soc_kwh) / (eff_c * h)).max(0.0));
    (max_ch, max_dis)
}

fn ramp_to(from: f64, to: f64, rate: f64, dt: f64) -> f64 {
    if rate <= 0.0 || !rate.is_finite() {
        return to;
    }
    let max = rate * dt;
    from + (to - from).clamp(-max, max)
}

fn finite_or(v: f64, d: f64) -> f64 {
    if v.is_finite() {
        v
    } else {
        d
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_spanned::Spanned;

    fn unit(id: &str, kind: UnitKind) -> UnitConfig {
        UnitConfig {
            id: Spanned::new(0..0, id.into()),
            kind,
            name: id.into(),
            prefix: Spanned::new(0..0, format!("MG.{id}")),
            rated_kw: 0.0,
            cost_per_kwh: 0.0,
            min_kw: 0.0,
            max_kw: 0.0,
            ramp_kw_per_s: 0.0,
            capacity_kwh: 0.0,
            soc_min_kwh: 0.0,
            soc_max_kwh: 0.0,
            max_charge_kw: 0.0,
            max_discharge_kw: 0.0,
            eff_charge: Spanned::new(0..0, 0.95),
            eff_discharge: Spanned::new(0..0, 0.95),
            cycle_cost_per_kwh: 0.0,
            forecast_kw: None,
            fuel_no_load_l_per_h: None,
            fuel_l_per_kwh: None,
            start_cost: 0.0,
            min_up_s: None,
            min_down_s: None,
        }
    }

    fn grid(units: Vec<UnitConfig>) -> Microgrid {
        let cfg = MicrogridConfig {
            dispatch_period_s: Spanned::new(0..0, 5.0),
            voll_per_kwh: 5.0,
            demand_tag: Spanned::new(0..0, "MG.Load.P_kW".into()),
            stale_after_s: 15.0,
            fuel_price_per_l: None,
            commitment: Default::default(),
            horizon: None,
            units,
        };
        let mut mg = Microgrid::new(&cfg, MicrogridParams::default(), Timestamp::from_millis(0));
        mg.irradiance = Profile::Constant(800.0);
        mg.wind_speed = Profile::Constant(8.0);
        mg.demand = Profile::Constant(50.0);
        mg
    }

    fn secs(s: f64) -> Timestamp {
        Timestamp::from_millis((s * 1000.0) as i64)
    }

    #[test]
    fn pv_tracks_setpoint_within_ramp_and_availability() {
        let mut u = unit("pv", UnitKind::Pv);
        u.rated_kw = 100.0;
        u.ramp_kw_per_s = 10.0;
        let mut mg = grid(vec![u]);
        mg.units[0].setpoint_kw = 50.0;
        mg.advance_to(secs(2.0));
        assert!(
            (mg.units[0].p_kw - 20.0).abs() < 1e-6,
            "{}",
            mg.units[0].p_kw
        );
        mg.advance_to(secs(10.0));
        assert!((mg.units[0].p_kw - 50.0).abs() < 1e-6);
        // Setpoint above what the sun gives: capped at available (76 kW).
        mg.units[0].setpoint_kw = 100.0;
        mg.advance_to(secs(20.0));
        assert!((mg.units[0].p_kw - 76.0).abs() < 1e-6);
        assert!((mg.units[0].available_kw - 76.0).abs() < 1e-6);
        // A cloud: output drops with the resource at once.
        mg.irradiance = Profile::Constant(200.0);
        mg.advance_to(secs(20.1));
        assert!((mg.units[0].p_kw - 19.0).abs() < 1e-6);
    }

    #[test]
    fn wind_power_curve() {
        let mut u = unit("wt", UnitKind::Wind);
        u.rated_kw = 50.0;
        let mut mg = grid(vec![u]);
        for (v, kw) in [(2.0, 0.0), (12.0, 50.0), (20.0, 50.0), (25.0, 0.0)] {
            mg.wind_speed = Profile::Constant(v);
            mg.advance_to(mg.last.add(Duration::from_millis(100)));
            assert!((mg.units[0].available_kw - kw).abs() < 1e-9, "{v} m/s");
        }
        mg.wind_speed = Profile::Constant(7.5);
        mg.advance_to(mg.last.add(Duration::from_millis(100)));
        let expected = 50.0 * (7.5f64.powi(3) - 27.0) / (1728.0 - 27.0);
        assert!((mg.units[0].available_kw - expected).abs() < 1e-9);
    }

    #[test]
    fn storage_integrates_with_efficiencies_and_respects_bounds() {
        let mut u = unit("bess", UnitKind::Storage);
        u.capacity_kwh = 200.0;
        u.soc_min_kwh = 20.0;
        u.soc_max_kwh = 190.0;
        u.max_charge_kw = 50.0;
        u.max_discharge_kw = 60.0;
        u.eff_charge = Spanned::new(0..0, 0.9);
        u.eff_discharge = Spanned::new(0..0, 0.8);
        let mut mg = grid(vec![u]);
        // The integration alone: the battery follows its setpoint only.
        mg.params.storage_grid_forming = false;
        assert_eq!(mg.units[0].soc_kwh, 100.0);
        mg.units[0].setpoint_kw = -40.0;
        mg.advance_to(secs(3600.0));
        // 40 kW for an hour at 90 %: +36 kWh.
        assert!(
            (mg.units[0].soc_kwh - 136.0).abs() < 0.01,
            "{}",
            mg.units[0].soc_kwh
        );
        mg.units[0].setpoint_kw = 40.0;
        mg.advance_to(secs(7200.0));
        // 40 kW out for an hour at 80 %: −50 kWh.
        assert!(
            (mg.units[0].soc_kwh - 86.0).abs() < 0.01,
            "{}",
            mg.units[0].soc_kwh
        );
        // Discharge at the limit until empty: stops at soc_min.
        mg.units[0].setpoint_kw = 1000.0;
        mg.advance_to(secs(7200.0 + 4.0 * 3600.0));
        assert!((mg.units[0].soc_kwh - 20.0).abs() < 1e-6);
        assert_eq!(mg.units[0].p_kw, 0.0);
    }

    #[test]
    fn grid_forming_storage_takes_up_the_imbalance_within_its_limits() {
        let mut pv = unit("pv", UnitKind::Pv);
        pv.rated_kw = 100.0;
        let mut b = unit("bess", UnitKind::Storage);
        b.capacity_kwh = 200.0;
        b.soc_min_kwh = 20.0;
        b.soc_max_kwh = 190.0;
        b.max_charge_kw = 50.0;
        b.max_discharge_kw = 60.0;
        let mut mg = grid(vec![pv, b]);
        mg.irradiance = Profile::Constant(0.0);
        mg.demand = Profile::Constant(30.0);
        mg.units[0].setpoint_kw = 0.0;
        mg.units[1].setpoint_kw = 10.0;
        mg.advance_to(secs(10.0));
        // Setpoint 10 kW, demand 30 kW, nothing else: the battery gives 30.
        assert!(
            (mg.units[1].p_kw - 30.0).abs() < 1e-9,
            "{}",
            mg.units[1].p_kw
        );
        assert!((mg.hz - 50.0).abs() < 1e-9);
        let unserved = mg.counters.unserved_kwh;
        // Beyond its discharge limit the rest is unserved, and shows in Hz.
        mg.demand = Profile::Constant(80.0);
        mg.advance_to(secs(20.0));
        assert!((mg.units[1].p_kw - 60.0).abs() < 1e-9);
        assert!(mg.counters.unserved_kwh > unserved);
        assert!(mg.hz < 50.0);
    }

    #[test]
    fn diesel_starts_after_delay_holds_min_load_and_ramps() {
        let mut u = unit("dg", UnitKind::Diesel);
        u.min_kw = 30.0;
        u.max_kw = 150.0;
        u.ramp_kw_per_s = 5.0;
        let mut mg = grid(vec![u]);
        mg.units[0].setpoint_kw = 10.0;
        mg.units[0].run_cmd = true;
        mg.advance_to(secs(5.0));
        assert_eq!(mg.units[0].state, UnitState::Starting);
        assert_eq!(mg.units[0].p_kw, 0.0);
        assert!(mg.units[0].fuel_rate_lph > 0.0);
        mg.advance_to(secs(30.0));
        assert_eq!(mg.units[0].state, UnitState::Running);
        // Setpoint below minimum load: held at 30 kW.
        assert!((mg.units[0].p_kw - 30.0).abs() < 1e-6);
        mg.units[0].setpoint_kw = 100.0;
        mg.advance_to(secs(32.0));
        assert!((mg.units[0].p_kw - 40.0).abs() < 1e-6);
        mg.units[0].run_cmd = false;
        mg.advance_to(secs(60.0));
        assert_eq!(mg.units[0].state, UnitState::Off);
        assert_eq!(mg.units[0].counters.starts, 1);
        assert!(mg.units[0].counters.fuel_l > 0.0);
    }

    #[test]
    fn imbalance_moves_frequency_and_counts_unserved_energy() {
        let mut u = unit("pv", UnitKind::Pv);
        u.rated_kw = 100.0;
        let mut mg = grid(vec![u]);
        mg.irradiance = Profile::Constant(0.0);
        mg.advance_to(secs(3600.0));
        assert!((mg.hz - 49.0).abs() < 1e-9); // 50 kW short at 0.02 Hz/kW
        assert!((mg.counters.unserved_kwh - 50.0).abs() < 0.01);
    }

    #[test]
    fn tripped_unit_produces_nothing_until_reset() {
        let mut u = unit("pv", UnitKind::Pv);
        u.rated_kw = 100.0;
        let mut mg = grid(vec![u]);
        mg.advance_to(secs(1.0));
        assert!(mg.units[0].p_kw > 0.0);
        mg.trip(0, secs(1.0));
        mg.advance_to(secs(2.0));
        assert_eq!(
            (mg.units[0].state, mg.units[0].p_kw),
            (UnitState::Fault, 0.0)
        );
        mg.reset(0, secs(2.0));
        mg.advance_to(secs(3.0));
        assert!(mg.units[0].p_kw > 0.0);
    }
}
