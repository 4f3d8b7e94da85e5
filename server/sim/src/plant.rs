//! The simulated plant as one state: panel and microgrid models, the devices'
//! register images, and the bindings between them.
//!
//! Owns advancing the models to a plant time, publishing their values into
//! the images, turning master writes into model commands, and the read-only
//! snapshot. Must not touch sockets or communication faults (those live in
//! the server shell): every function here is synchronous and deterministic
//! given the plant times it is called with.

use gridscada_config::{Plant, UnitKind};
use gridscada_tagdb::Timestamp;
use serde::Serialize;
use tokio_modbus::{ExceptionCode, Request, Response};

use crate::codec::Binding;
use crate::map::{
    self, Device, GatewaySpec, LoadOut, PanelOut, Source, StationSpec, Target, UnitOut,
};
use crate::microgrid::{BalanceCounters, Microgrid, UnitCounters, UnitState};
use crate::network::NetworkSim;
use crate::panel::{AnalyzerReading, FaultKind, PanelModel, TripRecord, ZoneLoad};
use crate::{Error, SimOptions};

pub(crate) struct PlantSim {
    pub devices: Vec<Device>,
    pub gateways: Vec<GatewaySpec>,
    pub stations: Vec<StationSpec>,
    /// Each station's point values, parallel to its `points`.
    station_values: Vec<Vec<f64>>,
    /// Each station's points that a model drives (the others stay 0): the
    /// only ones worth computing at every step.
    station_driven: Vec<Vec<usize>>,
    pub panels: Vec<PanelModel>,
    /// Panel prefixes, parallel to `panels`.
    pub panel_prefixes: Vec<String>,
    pub microgrid: Option<Microgrid>,
    /// The switching network's own devices and the panels' supply.
    network: Option<NetworkSim>,
    outputs: Vec<(Binding, Source)>,
    inputs: Vec<(Binding, Target)>,
    pub unmodelled: Vec<String>,
    pub unserved: Vec<String>,
    now: Timestamp,
    /// The plant time of the last publish, while nothing has changed since:
    /// the many requests of one scan arrive at the same instant, and the
    /// models are pure functions of their state and the time.
    published_at: Option<Timestamp>,
}

impl PlantSim {
    pub fn new(plant: &Plant, opts: &SimOptions, now: Timestamp) -> Result<Self, Error> {
        let network = NetworkSim::new(plant, opts.breaker_delay);
        let layout = map::build(plant, network.as_ref())?;
        let panels = plant
            .panels
            .iter()
            .map(|p| {
                PanelModel::new(
                    p.id.get_ref(),
                    usize::from(*p.zones.get_ref()),
                    opts.panels_start_closed,
                    opts.breaker_delay,
                    now,
                )
            })
            .collect();
        let microgrid = plant
            .microgrid
            .as_ref()
            .map(|mg| Microgrid::new(mg, opts.microgrid.clone(), now));
        let station_values = layout
            .stations
            .iter()
            .map(|s| vec![0.0; s.points.len()])
            .collect();
        let station_driven = layout
            .stations
            .iter()
            .map(|s| {
                s.points
                    .iter()
                    .enumerate()
                    .filter(|(_, p)| p.source.is_some() || p.target.is_some())
                    .map(|(i, _)| i)
                    .collect()
            })
            .collect();
        let mut sim = PlantSim {
            devices: layout.devices,
            gateways: layout.gateways,
            stations: layout.stations,
            station_values,
            station_driven,
            panels,
            panel_prefixes: plant
                .panels
                .iter()
                .map(|p| p.prefix.get_ref().clone())
                .collect(),
            microgrid,
            network,
            outputs: layout.outputs,
            inputs: layout.inputs,
            unmodelled: layout.unmodelled,
            unserved: layout.unserved,
            now,
            published_at: None,
        };
        sim.init_commands();
        sim.publish();
        Ok(sim)
    }

    /// Writes the models' initial command state into the images, so the
    /// master reads back what the plant is doing.
    fn init_commands(&mut self) {
        for (b, target) in &self.inputs {
            let v = self.command_state(*target);
            write_value(&mut self.devices[b.device].image, b, v);
        }
    }

    /// What a command output is set to now.
    fn command_state(&self, target: Target) -> f64 {
        match target {
            Target::ElcbReset(p) => bool_f(self.panels[p].reset_coil()),
            Target::Mccb(p) => bool_f(self.panels[p].mccb.cmd),
            Target::Zone(p, z) => bool_f(self.panels[p].zone[z - 1].cmd),
            Target::Setpoint(u) => self.unit(u).map(|u| u.setpoint_kw).unwrap_or(0.0),
            Target::RunCmd(u) => bool_f(self.unit(u).is_some_and(|u| u.run_cmd)),
            Target::Switch(i) => bool_f(self.network.as_ref().is_some_and(|n| n.command_state(i))),
        }
    }

    /// The points of a station that a model drives (indices into its
    /// points); the others never change.
    pub fn station_driven(&self, station: usize) -> &[usize] {
        self.station_driven
            .get(station)
            .map(Vec::as_slice)
            .unwrap_or(&[])
    }

    /// A station's point values (engineering units), parallel to its
    /// points.
    pub fn station_values(&self, station: usize) -> &[f64] {
        self.station_values
            .get(station)
            .map(Vec::as_slice)
            .unwrap_or(&[])
    }

    /// A command to a station's tag at plant time `now`.
    pub fn station_command(
        &mut self,
        station: usize,
        tag: &str,
        value: f64,
        now: Timestamp,
    ) -> Result<(), String> {
        self.advance_to(now);
        let target = self
            .stations
            .get(station)
            .and_then(|s| s.points.iter().find(|p| p.tag == tag))
            .ok_or_else(|| format!("no tag '{tag}' on this station"))?
            .target
            .ok_or_else(|| format!("tag '{tag}' is not a command the plant model takes"))?;
        if !value.is_finite() {
            return Err(format!("{value} is not a value for '{tag}'"));
        }
        self.command(target, value);
        self.publish();
        Ok(())
    }

    fn unit(&self, i: usize) -> Option<&crate::microgrid::Unit> {
        self.microgrid.as_ref().and_then(|m| m.units.get(i))
    }

    pub fn now(&self) -> Timestamp {
        self.now
    }

    /// Runs every model forward to `now` and publishes the values. Plant
    /// time never goes backwards here.
    pub fn advance_to(&mut self, now: Timestamp) {
        let now = now.max(self.now);
        if self.published_at == Some(now) {
            return;
        }
        for p in &mut self.panels {
            p.advance_to(now);
        }
        if let Some(mg) = &mut self.microgrid {
            mg.advance_to(now);
        }
        if let Some(net) = &mut self.network {
            net.advance_to(now, &mut self.panels, self.microgrid.as_ref());
        }
        self.now = now;
        self.publish();
    }

    /// Encodes every model output into its device image, and sets every
    /// station's point values.
    fn publish(&mut self) {
        let t = self.now;
        self.published_at = Some(t);
        let readings: Vec<AnalyzerReading> = self.panels.iter().map(|p| p.analyzer(t)).collect();
        for (b, src) in &self.outputs {
            if let Some(v) = output_value(
                &self.panels,
                self.microgrid.as_ref(),
                self.network.as_ref(),
                &readings,
                *src,
            ) {
                write_value(&mut self.devices[b.device].image, b, v);
            }
        }
        for si in 0..self.stations.len() {
            for &pi in &self.station_driven[si] {
                let point = &self.stations[si].points[pi];
                let v = match (point.source, point.target) {
                    (Some(src), _) => output_value(
                        &self.panels,
                        self.microgrid.as_ref(),
                        self.network.as_ref(),
                        &readings,
                        src,
                    ),
                    (None, Some(target)) => Some(self.command_state(target)),
                    (None, None) => None,
                };
                if let Some(v) = v {
                    self.station_values[si][pi] = v;
                }
            }
        }
    }

    /// Serves one request to device `dev` at plant time `now`.
    pub fn request(
        &mut self,
        dev: usize,
        req: &Request<'_>,
        now: Timestamp,
    ) -> Result<Response, ExceptionCode> {
        self.advance_to(now);
        let device = self
            .devices
            .get_mut(dev)
            .ok_or(ExceptionCode::GatewayTargetDevice)?;
        let (resp, written) = device.image.execute(req)?;
        let Some(w) = written else {
            return Ok(resp);
        };
        // Decode every command the write touched before acting on any, so a
        // bad value leaves the plant untouched.
        let mut commands = vec![];
        for (b, target) in &self.inputs {
            if b.device != dev || !b.overlaps(w.kind, w.start, w.len) {
                continue;
            }
            match read_value(&self.devices[dev].image, b) {
                Some(v) if v.is_finite() => commands.push((*target, v)),
                _ => {
                    self.devices[dev].image.restore(&w);
                    return Err(ExceptionCode::IllegalDataValue);
                }
            }
        }
        for (target, v) in commands {
            self.command(target, v);
        }
        self.publish();
        Ok(resp)
    }

    fn command(&mut self, target: Target, v: f64) {
        let now = self.now;
        let on = v != 0.0;
        match target {
            Target::ElcbReset(p) => self.panels[p].command_reset(on, now),
            Target::Mccb(p) => self.panels[p].command_mccb(on, now),
            Target::Zone(p, z) => self.panels[p].command_zone(z, on, now),
            Target::Setpoint(u) => {
                if let Some(u) = self.microgrid.as_mut().and_then(|m| m.units.get_mut(u)) {
                    u.setpoint_kw = v;
                }
            }
            Target::RunCmd(u) => {
                if let Some(u) = self.microgrid.as_mut().and_then(|m| m.units.get_mut(u)) {
                    u.run_cmd = on;
                }
            }
            Target::Switch(i) => {
                if let Some(net) = &mut self.network {
                    net.command(i, on, now);
                }
            }
        }
    }

    pub fn panel_index(&self, id: &str) -> Option<usize> {
        self.panels
            .iter()
            .zip(&self.panel_prefixes)
            .position(|(p, prefix)| p.id == id || prefix == id)
    }

    pub fn unit_index(&self, id: &str) -> Option<usize> {
        let mg = self.microgrid.as_ref()?;
        mg.units
            .iter()
            .position(|u| u.cfg.id.get_ref() == id || u.cfg.prefix.get_ref() == id)
    }

    pub fn snapshot(&self) -> SimSnapshot {
        let t = self.now;
        let panels = self
            .panels
            .iter()
            .map(|p| PanelSnapshot {
                id: p.id.clone(),
                elcb_closed: p.elcb_closed,
                elcb_trips: p.elcb_trips,
                last_trip: p.last_trip.clone(),
                mccb: BreakerSnapshot::of(&p.mccb),
                busbar_energised: p.busbar_energised(),
                busbar_fault: p.faults[0],
                busbar_fault_energisations: p.fault_energisations[0],
                zones: (1..=p.zones())
                    .map(|z| ZoneSnapshot {
                        zone: z as u8,
                        breaker: BreakerSnapshot::of(&p.zone[z - 1]),
                        energised: p.zone_energised(z),
                        fault: p.faults[z],
                        fault_clears_at: p.fault_clears_at[z],
                        fault_energisations: p.fault_energisations[z],
                        load: p.loads[z - 1],
                        load_kw_now: p.zone_power(z, t).0,
                    })
                    .collect(),
                door_open: p.door_open,
                analyzer: p.analyzer(t),
            })
            .collect();
        let microgrid = self.microgrid.as_ref().map(|mg| MicrogridSnapshot {
            hz: mg.hz,
            v: mg.v,
            demand_kw: mg.demand_kw,
            supply_kw: mg.supply_kw,
            irradiance_w_m2: mg.irradiance_w_m2,
            wind_speed_m_s: mg.wind_speed_m_s,
            irradiance_profile: mg.irradiance.clone(),
            wind_speed_profile: mg.wind_speed.clone(),
            demand_profile: mg.demand.clone(),
            energy: mg.counters.clone(),
            units: mg
                .units
                .iter()
                .map(|u| UnitSnapshot {
                    id: u.cfg.id.get_ref().clone(),
                    kind: u.cfg.kind,
                    state: u.state,
                    setpoint_kw: u.setpoint_kw,
                    p_kw: u.p_kw,
                    available_kw: u.available_kw,
                    soc_kwh: (u.cfg.kind == UnitKind::Storage).then_some(u.soc_kwh),
                    soc_pct: (u.cfg.kind == UnitKind::Storage).then(|| soc_pct(u)),
                    run_cmd: u.run_cmd,
                    fuel_rate_lph: u.fuel_rate_lph,
                    counters: u.counters.clone(),
                })
                .collect(),
        });
        SimSnapshot {
            time: t,
            panels,
            microgrid,
            devices: vec![],
        }
    }

    /// A zone's load (1-based zone).
    pub fn set_zone_load(&mut self, p: usize, z: usize, load: ZoneLoad) {
        let now = self.now;
        let panel = &mut self.panels[p];
        panel.advance_to(now);
        if let Some(l) = panel.loads.get_mut(z - 1) {
            *l = load;
        }
        self.publish();
    }

    pub fn set_soc(&mut self, u: usize, kwh: f64) {
        if let Some(unit) = self.microgrid.as_mut().and_then(|m| m.units.get_mut(u)) {
            let c = &unit.cfg;
            unit.soc_kwh = kwh.clamp(
                c.soc_min_kwh.min(c.soc_max_kwh),
                c.soc_max_kwh.max(c.soc_min_kwh),
            );
        }
        self.publish();
    }

    pub fn after_change(&mut self) {
        self.publish();
    }

    /// Something may have changed the models from outside (the handle):
    /// the next advance publishes again, even at the same instant.
    pub fn touched(&mut self) {
        self.published_at = None;
    }
}

/// The value of one model output at the panels' analyser `readings`.
fn output_value(
    panels: &[PanelModel],
    microgrid: Option<&Microgrid>,
    network: Option<&NetworkSim>,
    readings: &[AnalyzerReading],
    src: Source,
) -> Option<f64> {
    Some(match src {
        Source::Switch(i, shape, integer) => network?.status_value(i, shape, integer),
        Source::Panel(pi, o) => {
            let p = &panels[pi];
            let a = &readings[pi];
            match o {
                PanelOut::ElcbClosed => bool_f(p.elcb_closed),
                PanelOut::MccbClosed => bool_f(p.mccb.closed),
                PanelOut::ZoneClosed(z) => bool_f(p.zone[z - 1].closed),
                PanelOut::ZoneEnergised(z) => bool_f(p.zone_energised(z)),
                PanelOut::DoorOpen => bool_f(p.door_open),
                PanelOut::V(ph) => a.v[ph],
                PanelOut::I(ph) => a.i[ph],
                PanelOut::P => a.p_kw,
                PanelOut::Q => a.q_kvar,
                PanelOut::Pf => a.pf,
                PanelOut::Hz => a.hz,
                PanelOut::Kwh => a.kwh,
            }
        }
        Source::Unit(ui, o) => {
            let mg = microgrid?;
            let u = &mg.units[ui];
            match o {
                UnitOut::P => u.p_kw,
                UnitOut::V => mg.v,
                UnitOut::I => mg.current(u.p_kw),
                UnitOut::Available => u.available_kw,
                UnitOut::SocKwh => u.soc_kwh,
                UnitOut::SocPct => soc_pct(u),
                UnitOut::Running => bool_f(u.state == UnitState::Running),
                UnitOut::State => u.state as u8 as f64,
                UnitOut::Irradiance => mg.irradiance_w_m2,
                UnitOut::WindSpeed => mg.wind_speed_m_s,
                UnitOut::FuelRate => u.fuel_rate_lph,
            }
        }
        Source::Load(o) => {
            let mg = microgrid?;
            match o {
                LoadOut::P => mg.demand_kw,
                LoadOut::Q => mg.load_q_kvar(),
                LoadOut::V => mg.v,
                LoadOut::Hz => mg.hz,
            }
        }
    })
}

fn soc_pct(u: &crate::microgrid::Unit) -> f64 {
    if u.cfg.capacity_kwh > 0.0 {
        100.0 * u.soc_kwh / u.cfg.capacity_kwh
    } else {
        0.0
    }
}

fn bool_f(b: bool) -> f64 {
    if b {
        1.0
    } else {
        0.0
    }
}

/// Puts an engineering value where a binding says.
fn write_value(image: &mut crate::image::RegisterImage, b: &Binding, v: f64) {
    if b.kind.is_bit() || b.bit.is_some() {
        image.set_bit(b.kind, b.address, b.bit, v != 0.0);
    } else {
        let words = b.encode_words(v);
        image.set_words(b.kind, b.address, &words);
    }
}

/// Reads a binding's engineering value back from an image.
fn read_value(image: &crate::image::RegisterImage, b: &Binding) -> Option<f64> {
    if b.kind.is_bit() {
        return image.bit(b.kind, b.address).map(bool_f);
    }
    let len = if b.bit.is_some() { 1 } else { b.width };
    let words = image.words(b.kind, b.address, len)?;
    b.decode_words(words)
}

// ----- Snapshot -------------------------------------------------------------

/// A read-only picture of the whole simulated plant.
#[derive(Debug, Clone, Serialize)]
pub struct SimSnapshot {
    /// Plant time of the picture.
    pub time: Timestamp,
    pub panels: Vec<PanelSnapshot>,
    pub microgrid: Option<MicrogridSnapshot>,
    /// Communication faults in force, per simulated device.
    pub devices: Vec<DeviceSnapshot>,
}

impl SimSnapshot {
    pub fn panel(&self, id: &str) -> Option<&PanelSnapshot> {
        self.panels.iter().find(|p| p.id == id)
    }
    pub fn unit(&self, id: &str) -> Option<&UnitSnapshot> {
        self.microgrid.as_ref()?.units.iter().find(|u| u.id == id)
    }
}

#[derive(Debug, Clone, Serialize)]
pub struct PanelSnapshot {
    pub id: String,
    pub elcb_closed: bool,
    /// ELCB trips since start.
    pub elcb_trips: u64,
    pub last_trip: Option<TripRecord>,
    pub mccb: BreakerSnapshot,
    pub busbar_energised: bool,
    /// Fault on load 0 (main MCCB / busbar).
    pub busbar_fault: Option<FaultKind>,
    pub busbar_fault_energisations: u64,
    pub zones: Vec<ZoneSnapshot>,
    pub door_open: bool,
    pub analyzer: AnalyzerReading,
}

impl PanelSnapshot {
    /// Numbers of the energised zones.
    pub fn energised_zones(&self) -> Vec<u8> {
        self.zones
            .iter()
            .filter(|z| z.energised)
            .map(|z| z.zone)
            .collect()
    }
}

#[derive(Debug, Clone, Copy, Serialize)]
pub struct BreakerSnapshot {
    /// The command output.
    pub cmd: bool,
    /// The contact (and status input).
    pub closed: bool,
    pub stuck: bool,
    /// Contact movements since start.
    pub operations: u64,
}

impl BreakerSnapshot {
    fn of(b: &crate::panel::Breaker) -> Self {
        BreakerSnapshot {
            cmd: b.cmd,
            closed: b.closed,
            stuck: b.stuck,
            operations: b.operations,
        }
    }
}

#[derive(Debug, Clone, Serialize)]
pub struct ZoneSnapshot {
    pub zone: u8,
    pub breaker: BreakerSnapshot,
    pub energised: bool,
    pub fault: Option<FaultKind>,
    /// When a timed transient fault clears by itself (plant time).
    pub fault_clears_at: Option<Timestamp>,
    /// Times the zone was energised while faulted (each tripped the ELCB).
    pub fault_energisations: u64,
    pub load: ZoneLoad,
    /// The zone's load now (whether or not it is energised), kW.
    pub load_kw_now: f64,
}

#[derive(Debug, Clone, Serialize)]
pub struct MicrogridSnapshot {
    pub hz: f64,
    pub v: f64,
    pub demand_kw: f64,
    /// Sum of unit outputs (storage charging counts negative), kW.
    pub supply_kw: f64,
    pub irradiance_w_m2: f64,
    pub wind_speed_m_s: f64,
    /// The profiles in force (a trainer may have overridden or scaled them).
    pub irradiance_profile: crate::profile::Profile,
    pub wind_speed_profile: crate::profile::Profile,
    pub demand_profile: crate::profile::Profile,
    pub energy: BalanceCounters,
    pub units: Vec<UnitSnapshot>,
}

#[derive(Debug, Clone, Serialize)]
pub struct UnitSnapshot {
    pub id: String,
    pub kind: UnitKind,
    pub state: UnitState,
    pub setpoint_kw: f64,
    pub p_kw: f64,
    pub available_kw: f64,
    pub soc_kwh: Option<f64>,
    pub soc_pct: Option<f64>,
    pub run_cmd: bool,
    pub fuel_rate_lph: f64,
    pub counters: UnitCounters,
}

/// A simulated device and the communication faults in force on it.
#[derive(Debug, Clone, Serialize)]
pub struct DeviceSnapshot {
    pub name: String,
    /// Configured `host:port`.
    pub address: String,
    pub unit_id: u8,
    pub offline: bool,
    pub slow_reply_ms: Option<u64>,
    /// Modbus exception code answered to every request.
    pub exception: Option<u8>,
    pub corrupt_frames: bool,
}
