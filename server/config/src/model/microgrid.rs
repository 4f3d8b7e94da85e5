//! The microgrid (`[microgrid]`): its units and their tags
//! (`UnitConfig::io`), the dispatch period, reserve, diesel commitment,
//! forecasts and the look-ahead horizon.

use serde::{Deserialize, Serialize};
use serde_spanned::Spanned;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum UnitKind {
    Pv,
    Wind,
    Storage,
    Diesel,
}

/// The microgrid and its cascade outer loop.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct MicrogridConfig {
    /// Outer-loop period.
    #[serde(default = "default_dispatch_period")]
    pub dispatch_period_s: Spanned<f64>,
    /// Value of lost load: the price of shedding.
    #[serde(default = "default_voll")]
    pub voll_per_kwh: f64,
    /// Tag of the measured demand, kW.
    pub demand_tag: Spanned<String>,
    /// Measurements older than this are stale and force the fallback.
    #[serde(default = "default_stale")]
    pub stale_after_s: f64,
    /// Price of diesel fuel, per litre: with each diesel's fuel curve, the
    /// cost the dispatch minimises and the replay report counts
    /// ([`DieselCost`]). A scenario may set its own (`fuel_price_per_l`).
    #[serde(default)]
    pub fuel_price_per_l: Option<Spanned<f64>>,
    #[serde(default)]
    pub commitment: CommitmentConfig,
    /// Look-ahead of the outer loop (absent: each period on its own).
    #[serde(default)]
    pub horizon: Option<HorizonConfig>,
    #[serde(rename = "unit")]
    pub units: Vec<UnitConfig>,
}

/// Points of a daily curve: `[hour, value]` pairs, hour in [0, 24) UTC,
/// interpolated linearly and wrapping at midnight (see [`crate::daily`]).
pub type DailyPoints = Spanned<Vec<(f64, f64)>>;

/// The receding horizon: every `resolve_s` the outer loop solves the
/// multi-period problem over `periods` × `period_s` ahead, from the
/// measurements now and the forecasts, and prices stored energy in each
/// period's dispatch with what the horizon says a stored kWh is worth.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct HorizonConfig {
    /// Number of look-ahead periods.
    #[serde(default = "default_horizon_periods")]
    pub periods: Spanned<f64>,
    /// Length of one look-ahead period, s.
    #[serde(default = "default_horizon_period_s")]
    pub period_s: Spanned<f64>,
    /// How often the horizon is solved again, s (at least the dispatch period).
    #[serde(default = "default_horizon_resolve_s")]
    pub resolve_s: Spanned<f64>,
    /// Plant time from a plan's measurements to its use, s: the plan is
    /// solved on its own thread meanwhile and used at this fixed delay
    /// however long the solve took (so a replay is the same on every run).
    /// Absent: 0, the plan is used in the period it is made in.
    #[serde(default, rename = "adopt_after_s")]
    pub adopt_after: Option<Spanned<f64>>,
    /// How fast today's deviation from a daily forecast curve fades towards
    /// the curve, h (e-folding time of the ratio measured / curve).
    #[serde(default = "default_blend_h")]
    pub blend_h: Spanned<f64>,
    /// Daily demand curve, kW (absent: the demand now persists).
    #[serde(default)]
    pub demand_forecast_kw: Option<DailyPoints>,
    /// Spinning reserve to hold in every look-ahead period.
    #[serde(default)]
    pub reserve: Option<ReserveConfig>,
}

impl HorizonConfig {
    /// Plant time from a plan's measurements to its use, s: as configured,
    /// else 0 (the plan is used in the dispatch period it is made in).
    pub fn adopt_after_s(&self) -> f64 {
        self.adopt_after.as_ref().map_or(0.0, |v| *v.get_ref())
    }
}

fn default_horizon_periods() -> Spanned<f64> {
    Spanned::new(0..0, 16.0)
}
fn default_horizon_period_s() -> Spanned<f64> {
    Spanned::new(0..0, 900.0)
}
fn default_horizon_resolve_s() -> Spanned<f64> {
    Spanned::new(0..0, 60.0)
}
fn default_blend_h() -> Spanned<f64> {
    Spanned::new(0..0, 2.0)
}

/// Spinning reserve: online headroom (running diesels, storage discharge)
/// must cover these shares of load, PV and wind; a shortfall costs
/// `shortfall_cost_per_kwh`.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct ReserveConfig {
    #[serde(default)]
    pub load_frac: f64,
    #[serde(default)]
    pub pv_frac: f64,
    #[serde(default)]
    pub wind_frac: f64,
    pub shortfall_cost_per_kwh: f64,
}

fn default_dispatch_period() -> Spanned<f64> {
    Spanned::new(0..0, 5.0)
}
fn default_voll() -> f64 {
    5.0
}
fn default_stale() -> f64 {
    15.0
}

/// Diesel on/off rule with hysteresis, decided outside the LP.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct CommitmentConfig {
    /// Start a diesel when net load (demand - renewables) exceeds what storage
    /// can cover by this margin, or when SoC falls below `start_soc_frac`.
    #[serde(default = "default_start_soc")]
    pub start_soc_frac: f64,
    /// Stop when SoC is above this and renewables + storage cover the load.
    #[serde(default = "default_stop_soc")]
    pub stop_soc_frac: f64,
    #[serde(default = "default_min_run")]
    pub min_run_s: f64,
    #[serde(default = "default_min_stop")]
    pub min_stop_s: f64,
}

impl Default for CommitmentConfig {
    fn default() -> Self {
        CommitmentConfig {
            start_soc_frac: default_start_soc(),
            stop_soc_frac: default_stop_soc(),
            min_run_s: default_min_run(),
            min_stop_s: default_min_stop(),
        }
    }
}

fn default_start_soc() -> f64 {
    0.25
}
fn default_stop_soc() -> f64 {
    0.6
}
fn default_min_run() -> f64 {
    900.0
}
fn default_min_stop() -> f64 {
    300.0
}

/// One microgrid unit and its controller's tags (under `prefix`, see
/// [`UnitConfig::io`]).
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct UnitConfig {
    pub id: Spanned<String>,
    pub kind: UnitKind,
    pub name: String,
    pub prefix: Spanned<String>,
    /// Nameplate power (PV, wind), kW.
    #[serde(default)]
    pub rated_kw: f64,
    /// Production cost (PV, wind, diesel), per kWh.
    #[serde(default)]
    pub cost_per_kwh: f64,
    /// Diesel: minimum stable load and maximum output, kW.
    #[serde(default)]
    pub min_kw: f64,
    #[serde(default)]
    pub max_kw: f64,
    /// Ramp limit of the unit, kW per second (0 = unlimited).
    #[serde(default)]
    pub ramp_kw_per_s: f64,
    /// Storage.
    #[serde(default)]
    pub capacity_kwh: f64,
    #[serde(default)]
    pub soc_min_kwh: f64,
    #[serde(default)]
    pub soc_max_kwh: f64,
    #[serde(default)]
    pub max_charge_kw: f64,
    #[serde(default)]
    pub max_discharge_kw: f64,
    #[serde(default = "default_eff")]
    pub eff_charge: Spanned<f64>,
    #[serde(default = "default_eff")]
    pub eff_discharge: Spanned<f64>,
    #[serde(default)]
    pub cycle_cost_per_kwh: f64,
    /// PV, wind: daily curve of the power expected to be available, kW, for
    /// the horizon's forecast (absent: the availability now persists).
    #[serde(default)]
    pub forecast_kw: Option<DailyPoints>,
    /// Diesel fuel curve: litres per hour while running, whatever the load
    /// (no-load consumption), plus litres per kWh produced. With
    /// `[microgrid] fuel_price_per_l` they replace `cost_per_kwh`.
    #[serde(default)]
    pub fuel_no_load_l_per_h: Option<f64>,
    #[serde(default)]
    pub fuel_l_per_kwh: Option<f64>,
    /// Diesel: cost of one start (wear, start-up fuel), currency.
    #[serde(default)]
    pub start_cost: f64,
    /// Diesel: minimum up and down times, s (absent: `[microgrid.commitment]`
    /// `min_run_s` and `min_stop_s`).
    #[serde(default)]
    pub min_up_s: Option<f64>,
    #[serde(default)]
    pub min_down_s: Option<f64>,
}

/// What running a diesel costs: one function for the dispatch's objective
/// and the replay report, so "optimal" means optimal for the cost reported.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct DieselCost {
    /// Cost of each kWh produced (fuel per kWh × fuel price).
    pub marginal_per_kwh: f64,
    /// Cost of each hour running, at any load (no-load fuel × price).
    pub no_load_per_h: f64,
    /// Cost of each start.
    pub start_cost: f64,
    /// Minimum up and down times, h.
    pub min_up_h: f64,
    pub min_down_h: f64,
}

impl DieselCost {
    /// Cost of running `run_h` hours, producing `kwh`, with `starts` starts.
    pub fn cost(&self, run_h: f64, kwh: f64, starts: f64) -> f64 {
        self.no_load_per_h * run_h + self.marginal_per_kwh * kwh + self.start_cost * starts
    }

    /// Average cost per kWh when running at `kw`: what a kWh of diesel
    /// energy costs at that load.
    pub fn average_per_kwh(&self, kw: f64) -> f64 {
        if kw > 0.0 {
            self.marginal_per_kwh + self.no_load_per_h / kw
        } else {
            f64::INFINITY
        }
    }
}

/// What a unit did over a run or a plan: the quantities its cost is
/// computed from ([`MicrogridConfig::unit_cost`]).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct UnitUsage {
    /// Energy produced (storage: discharged), kWh.
    pub kwh: f64,
    /// Storage: energy taken in, kWh.
    pub charged_kwh: f64,
    /// Diesel: hours running, and starts.
    pub run_h: f64,
    pub starts: f64,
}

impl MicrogridConfig {
    /// What `usage` of `unit` costs at fuel price `price`: the one cost
    /// function of the plant. The dispatch's objective prices each kWh, hour
    /// and start with the same coefficients (`cost_per_kwh`, [`DieselCost`],
    /// `cycle_cost_per_kwh` on each kWh charged and each kWh discharged), and
    /// the replay report adds up this function over the run.
    pub fn unit_cost(&self, unit: &UnitConfig, price: Option<f64>, usage: &UnitUsage) -> f64 {
        match unit.kind {
            UnitKind::Pv | UnitKind::Wind => unit.cost_per_kwh * usage.kwh,
            UnitKind::Diesel => {
                self.diesel_cost(unit, price)
                    .cost(usage.run_h, usage.kwh, usage.starts)
            }
            UnitKind::Storage => unit.cycle_cost_per_kwh * (usage.kwh + usage.charged_kwh),
        }
    }

    /// The fuel price in force: `override_price` (a scenario's), else the
    /// configured one, else none (costs then come from `cost_per_kwh`).
    pub fn fuel_price(&self, override_price: Option<f64>) -> Option<f64> {
        override_price.or(self.fuel_price_per_l.as_ref().map(|p| *p.get_ref()))
    }

    /// Sets the fuel price (a scenario's cost model replacing the plant's).
    pub fn set_fuel_price(&mut self, price: f64) {
        self.fuel_price_per_l = Some(Spanned::new(0..0, price));
    }

    /// The cost model of diesel `unit` at fuel price `price` (see
    /// [`MicrogridConfig::fuel_price`]). Without a fuel curve or a price, a
    /// kWh costs `cost_per_kwh` and running costs nothing more.
    pub fn diesel_cost(&self, unit: &UnitConfig, price: Option<f64>) -> DieselCost {
        let (marginal, no_load) = match (price, unit.fuel_l_per_kwh) {
            (Some(price), Some(l_per_kwh)) => (
                price * l_per_kwh,
                price * unit.fuel_no_load_l_per_h.unwrap_or(0.0),
            ),
            _ => (unit.cost_per_kwh, 0.0),
        };
        DieselCost {
            marginal_per_kwh: marginal,
            no_load_per_h: no_load,
            start_cost: unit.start_cost,
            min_up_h: unit.min_up_s.unwrap_or(self.commitment.min_run_s).max(0.0) / 3600.0,
            min_down_h: unit
                .min_down_s
                .unwrap_or(self.commitment.min_stop_s)
                .max(0.0)
                / 3600.0,
        }
    }
}

fn default_eff() -> Spanned<f64> {
    Spanned::new(0..0, 0.95)
}

/// Names of a unit controller's tags.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct UnitIo {
    /// Power setpoint written by the outer loop, kW (storage: + discharge).
    pub setpoint_kw: String,
    /// Measured active power, kW.
    pub p_kw: String,
    pub voltage_v: String,
    pub current_a: String,
    /// Power the unit could produce now (PV, wind), kW.
    pub available_kw: String,
    /// Stored energy (storage), kWh.
    pub soc_kwh: String,
    /// Running state (diesel), and its start/stop command.
    pub running: String,
    pub run_cmd: String,
}

/// The last part of a unit's setpoint tag, `{prefix}.Setpoint_kW`.
pub const SETPOINT_KW: &str = "Setpoint_kW";

impl UnitConfig {
    pub fn io(&self) -> UnitIo {
        let p = self.prefix.get_ref();
        UnitIo {
            setpoint_kw: format!("{p}.{SETPOINT_KW}"),
            p_kw: format!("{p}.P_kW"),
            voltage_v: format!("{p}.V"),
            current_a: format!("{p}.I"),
            available_kw: format!("{p}.Available_kW"),
            soc_kwh: format!("{p}.SoC_kWh"),
            running: format!("{p}.Running"),
            run_cmd: format!("{p}.RunCmd"),
        }
    }

    /// The tags this kind of unit must have.
    pub fn required_tags(&self) -> Vec<String> {
        let io = self.io();
        let mut t = vec![io.setpoint_kw, io.p_kw, io.voltage_v, io.current_a];
        match self.kind {
            UnitKind::Pv | UnitKind::Wind => t.push(io.available_kw),
            UnitKind::Storage => t.push(io.soc_kwh),
            UnitKind::Diesel => {
                t.push(io.running);
                t.push(io.run_cmd);
            }
        }
        t
    }
}
