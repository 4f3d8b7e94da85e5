//! From the plant configuration to simulated devices: which devices are
//! served, on which gateway address and unit id, how big their tables are,
//! and which register carries which panel or unit signal.
//!
//! Owns the signal <-> tag naming convention on the simulator side (it
//! mirrors `PanelConfig::io()` and `UnitConfig::io()` plus the optional
//! signals listed in docs/REGISTER_MAPS.md). Must not touch the models'
//! behaviour or sockets.

use std::collections::HashMap;

use gridscada_config::{Plant, Protocol, RegisterKind, UnitKind};

use crate::codec::Binding;
use crate::image::{Limits, RegisterImage};
use crate::network::{NetworkSim, StatusShape};
use crate::Error;

/// A value the simulator produces (read by the master).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Source {
    Panel(usize, PanelOut),
    Unit(usize, UnitOut),
    Load(LoadOut),
    /// A network device's position: device, how the tag shows it, whether
    /// the tag is an integer double point.
    Switch(usize, StatusShape, bool),
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum PanelOut {
    ElcbClosed,
    MccbClosed,
    /// Zone number, 1-based.
    ZoneClosed(usize),
    ZoneEnergised(usize),
    DoorOpen,
    /// Phase index 0..3.
    V(usize),
    I(usize),
    P,
    Q,
    Pf,
    Hz,
    Kwh,
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum UnitOut {
    P,
    V,
    I,
    Available,
    SocKwh,
    SocPct,
    Running,
    State,
    Irradiance,
    WindSpeed,
    FuelRate,
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum LoadOut {
    P,
    Q,
    V,
    Hz,
}

/// A command the master writes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Target {
    ElcbReset(usize),
    Mccb(usize),
    /// Panel, zone (1-based).
    Zone(usize, usize),
    Setpoint(usize),
    RunCmd(usize),
    /// A network device's command.
    Switch(usize),
}

/// One simulated device.
#[derive(Debug, Clone)]
pub(crate) struct Device {
    pub name: String,
    /// The configured `host:port`.
    pub address: String,
    pub unit_id: u8,
    pub image: RegisterImage,
}

/// A simulated telecontrol station (a `protocol = "iec104"` or `"dnp3"`
/// device): its tags are driven by the models and its commands go to them
/// by tag name, not through a register image.
#[derive(Debug, Clone)]
pub(crate) struct StationSpec {
    pub name: String,
    /// The configured `host:port`, and the redundancy group's other
    /// addresses (served by the same station).
    pub address: String,
    pub redundant: Vec<String>,
    pub points: Vec<StationPoint>,
}

/// One tag of a simulated station.
#[derive(Debug, Clone)]
pub(crate) struct StationPoint {
    pub tag: String,
    /// The model output it shows; a command tag shows its command's state.
    pub source: Option<Source>,
    pub target: Option<Target>,
}

/// One listening address and the devices behind it.
#[derive(Debug, Clone)]
pub(crate) struct GatewaySpec {
    pub address: String,
    /// Unit id -> device index.
    pub units: HashMap<u8, usize>,
}

#[derive(Debug)]
pub(crate) struct Layout {
    pub devices: Vec<Device>,
    pub gateways: Vec<GatewaySpec>,
    pub stations: Vec<StationSpec>,
    pub outputs: Vec<(Binding, Source)>,
    pub inputs: Vec<(Binding, Target)>,
    /// Tags on simulated devices that no model drives (they read 0).
    pub unmodelled: Vec<String>,
    /// Signals the models have but the configuration puts on devices the
    /// simulator cannot serve (RTU), for the start-up log.
    pub unserved: Vec<String>,
}

/// The channel counts of the seed's I/O modules, recognised in a device's
/// description, so spare channels exist as on the real module.
fn module_sizes(description: &str) -> [u16; 4] {
    let d = description.to_ascii_uppercase();
    if d.contains("I-7044") {
        [8, 4, 0, 0]
    } else if d.contains("I-7051") {
        [0, 16, 0, 0]
    } else if d.contains("I-7042") {
        [13, 0, 0, 0]
    } else {
        [0; 4]
    }
}

fn kind_index(k: RegisterKind) -> usize {
    match k {
        RegisterKind::Coil => 0,
        RegisterKind::DiscreteInput => 1,
        RegisterKind::InputRegister => 2,
        RegisterKind::HoldingRegister => 3,
    }
}

pub(crate) fn build(plant: &Plant, network: Option<&NetworkSim>) -> Result<Layout, Error> {
    // Devices: every Modbus TCP device with an address, and every IEC 104
    // station.
    let mut devices = vec![];
    let mut index: HashMap<&str, usize> = HashMap::new();
    let mut stations: Vec<StationSpec> = vec![];
    let mut station_index: HashMap<&str, usize> = HashMap::new();
    let mut unserved = vec![];
    for d in &plant.devices {
        let name = d.name.get_ref();
        match (&d.protocol, &d.address) {
            (Protocol::Tcp, Some(addr)) => {
                index.insert(name.as_str(), devices.len());
                devices.push((d, addr.get_ref().clone()));
            }
            (Protocol::Iec104 | Protocol::Dnp3, Some(addr)) => {
                station_index.insert(name.as_str(), stations.len());
                stations.push(StationSpec {
                    name: name.clone(),
                    address: addr.get_ref().clone(),
                    redundant: d
                        .iec104
                        .as_ref()
                        .map(|c| {
                            c.redundant_addresses
                                .iter()
                                .map(|a| a.get_ref().clone())
                                .collect()
                        })
                        .unwrap_or_default(),
                    points: vec![],
                });
            }
            (Protocol::Iec61850, _) => unserved.push(format!(
                "device '{name}' (IEC 61850: there is no simulated IED; gridscada connects to the IED at its address)"
            )),
            _ => unserved.push(format!("device '{name}' (serial, or without an address)")),
        }
    }
    // Tags of the stations: tag name -> (station, point).
    let mut station_tags: HashMap<&str, (usize, usize)> = HashMap::new();
    for t in &plant.tags {
        if let Some(&si) = station_index.get(t.device.get_ref().as_str()) {
            let points = &mut stations[si].points;
            station_tags.insert(t.name.get_ref().as_str(), (si, points.len()));
            points.push(StationPoint {
                tag: t.name.get_ref().clone(),
                source: None,
                target: None,
            });
        }
    }

    // Bindings of every tag on a served device, and table sizes.
    let mut sizes: Vec<[u32; 4]> = devices
        .iter()
        .map(|(d, _)| module_sizes(&d.description).map(u32::from))
        .collect();
    let mut writable_holding: Vec<Vec<(u16, u16)>> = vec![vec![]; devices.len()];
    let mut bindings: HashMap<&str, Binding> = HashMap::new();
    for t in &plant.tags {
        let Some(&di) = index.get(t.device.get_ref().as_str()) else {
            continue;
        };
        let b = Binding::from_tag(t, di).map_err(Error::Config)?;
        let k = kind_index(b.kind);
        sizes[di][k] = sizes[di][k].max(b.end());
        if b.kind == RegisterKind::HoldingRegister && *t.writable.get_ref() {
            writable_holding[di].push((b.address, b.width));
        }
        bindings.insert(t.name.get_ref().as_str(), b);
    }

    let mut outputs = vec![];
    let mut inputs = vec![];
    let mut out = |name: &str, src: Source, used: &mut Vec<String>| {
        if let Some(b) = bindings.get(name) {
            outputs.push((b.clone(), src));
            used.push(name.to_string());
        } else if let Some(&(si, pi)) = station_tags.get(name) {
            stations[si].points[pi].source = Some(src);
            used.push(name.to_string());
        }
    };
    let mut used_names: Vec<String> = vec![];
    for (pi, p) in plant.panels.iter().enumerate() {
        let io = p.io();
        let prefix = p.prefix.get_ref();
        out(
            &io.elcb_closed,
            Source::Panel(pi, PanelOut::ElcbClosed),
            &mut used_names,
        );
        out(
            &io.mccb_closed,
            Source::Panel(pi, PanelOut::MccbClosed),
            &mut used_names,
        );
        for (z, name) in io.zone_closed.iter().enumerate() {
            out(
                name,
                Source::Panel(pi, PanelOut::ZoneClosed(z + 1)),
                &mut used_names,
            );
        }
        for z in 1..=usize::from(*p.zones.get_ref()) {
            out(
                &format!("{prefix}.Zone{z}.Energised"),
                Source::Panel(pi, PanelOut::ZoneEnergised(z)),
                &mut used_names,
            );
        }
        out(
            &format!("{prefix}.Door.Open"),
            Source::Panel(pi, PanelOut::DoorOpen),
            &mut used_names,
        );
        for ph in 0..3 {
            out(
                &format!("{prefix}.PA.V_L{}", ph + 1),
                Source::Panel(pi, PanelOut::V(ph)),
                &mut used_names,
            );
            out(
                &format!("{prefix}.PA.I_L{}", ph + 1),
                Source::Panel(pi, PanelOut::I(ph)),
                &mut used_names,
            );
        }
        for (suffix, o) in [
            ("P_kW", PanelOut::P),
            ("Q_kvar", PanelOut::Q),
            ("PF", PanelOut::Pf),
            ("Hz", PanelOut::Hz),
            ("kWh", PanelOut::Kwh),
        ] {
            out(
                &format!("{prefix}.PA.{suffix}"),
                Source::Panel(pi, o),
                &mut used_names,
            );
        }
    }
    if let Some(mg) = &plant.microgrid {
        for (ui, u) in mg.units.iter().enumerate() {
            let io = u.io();
            let prefix = u.prefix.get_ref();
            out(&io.p_kw, Source::Unit(ui, UnitOut::P), &mut used_names);
            out(&io.voltage_v, Source::Unit(ui, UnitOut::V), &mut used_names);
            out(&io.current_a, Source::Unit(ui, UnitOut::I), &mut used_names);
            out(
                &format!("{prefix}.State"),
                Source::Unit(ui, UnitOut::State),
                &mut used_names,
            );
            match u.kind {
                UnitKind::Pv => {
                    out(
                        &io.available_kw,
                        Source::Unit(ui, UnitOut::Available),
                        &mut used_names,
                    );
                    out(
                        &format!("{prefix}.Irradiance"),
                        Source::Unit(ui, UnitOut::Irradiance),
                        &mut used_names,
                    );
                }
                UnitKind::Wind => {
                    out(
                        &io.available_kw,
                        Source::Unit(ui, UnitOut::Available),
                        &mut used_names,
                    );
                    out(
                        &format!("{prefix}.WindSpeed"),
                        Source::Unit(ui, UnitOut::WindSpeed),
                        &mut used_names,
                    );
                }
                UnitKind::Storage => {
                    out(
                        &io.soc_kwh,
                        Source::Unit(ui, UnitOut::SocKwh),
                        &mut used_names,
                    );
                    out(
                        &format!("{prefix}.SoC_pct"),
                        Source::Unit(ui, UnitOut::SocPct),
                        &mut used_names,
                    );
                }
                UnitKind::Diesel => {
                    out(
                        &io.running,
                        Source::Unit(ui, UnitOut::Running),
                        &mut used_names,
                    );
                    out(
                        &format!("{prefix}.FuelRate"),
                        Source::Unit(ui, UnitOut::FuelRate),
                        &mut used_names,
                    );
                }
            }
        }
        // The load meter: the demand tag and its siblings.
        let demand = mg.demand_tag.get_ref();
        out(demand, Source::Load(LoadOut::P), &mut used_names);
        if let Some((meter, _)) = demand.rsplit_once('.') {
            out(
                &format!("{meter}.Q_kvar"),
                Source::Load(LoadOut::Q),
                &mut used_names,
            );
            out(
                &format!("{meter}.V"),
                Source::Load(LoadOut::V),
                &mut used_names,
            );
            out(
                &format!("{meter}.Hz"),
                Source::Load(LoadOut::Hz),
                &mut used_names,
            );
        }
    }

    // The network's own devices (the panels' breakers are bound above).
    if let Some(net) = network {
        for t in &plant.tags {
            let name = t.name.get_ref();
            if let Some((i, shape)) = net.status_of(name) {
                let integer = t.value_kind() == gridscada_tagdb::ValueKind::Int;
                out(name, Source::Switch(i, shape, integer), &mut used_names);
            }
        }
    }

    // Commands: must sit on a table the master can write.
    let mut command = |name: &str, target: Target| -> Result<(), Error> {
        if let Some(&(si, pi)) = station_tags.get(name) {
            stations[si].points[pi].target = Some(target);
            return Ok(());
        }
        let Some(b) = bindings.get(name) else {
            return Ok(());
        };
        if !b.kind.is_writable() {
            return Err(Error::Config(format!(
                "tag '{name}' is a command but sits on a {} table, which a Modbus master cannot write",
                b.kind.label()
            )));
        }
        inputs.push((b.clone(), target));
        Ok(())
    };
    let mut used_cmd: Vec<String> = vec![];
    for (pi, p) in plant.panels.iter().enumerate() {
        let io = p.io();
        command(&io.elcb_reset, Target::ElcbReset(pi))?;
        command(&io.mccb_cmd, Target::Mccb(pi))?;
        for (z, name) in io.zone_cmd.iter().enumerate() {
            command(name, Target::Zone(pi, z + 1))?;
        }
        used_cmd.push(io.elcb_reset.clone());
        used_cmd.push(io.mccb_cmd.clone());
        used_cmd.extend(io.zone_cmd.iter().cloned());
    }
    if let Some(mg) = &plant.microgrid {
        for (ui, u) in mg.units.iter().enumerate() {
            let io = u.io();
            command(&io.setpoint_kw, Target::Setpoint(ui))?;
            used_cmd.push(io.setpoint_kw.clone());
            if u.kind == UnitKind::Diesel {
                command(&io.run_cmd, Target::RunCmd(ui))?;
                used_cmd.push(io.run_cmd.clone());
            }
        }
    }
    if let Some(net) = network {
        for t in &plant.tags {
            let name = t.name.get_ref();
            if let Some(i) = net.command_of(name) {
                command(name, Target::Switch(i))?;
                used_cmd.push(name.clone());
            }
        }
    }
    used_names.extend(used_cmd);

    // Panel and unit signals that the configuration has but no served device carries.
    for name in &used_names {
        if !bindings.contains_key(name.as_str())
            && !station_tags.contains_key(name.as_str())
            && plant.tag(name).is_some()
        {
            unserved.push(format!("tag '{name}' (its device is not simulated)"));
        }
    }
    let mut unmodelled: Vec<String> = bindings
        .keys()
        .chain(station_tags.keys())
        .filter(|n| !used_names.iter().any(|u| u == *n))
        .map(|n| n.to_string())
        .collect();
    unmodelled.sort();

    // Images.
    let mut out_devices = vec![];
    for (i, (d, addr)) in devices.iter().enumerate() {
        let s = sizes[i].map(|v| v.min(65536) as u16);
        let limits = Limits {
            max_read_registers: *d.max_read_registers.get_ref(),
            max_read_bits: *d.max_read_bits.get_ref(),
            max_write_registers: *d.max_write_registers.get_ref(),
        };
        let mut image = RegisterImage::new(s, limits);
        for &(a, w) in &writable_holding[i] {
            for r in a..a.saturating_add(w) {
                if let Some(x) = image.holding_writable.get_mut(usize::from(r)) {
                    *x = true;
                }
            }
        }
        out_devices.push(Device {
            name: d.name.get_ref().clone(),
            address: addr.clone(),
            unit_id: *d.unit_id.get_ref(),
            image,
        });
    }

    // Gateways: devices grouped by configured address.
    let mut gateways: Vec<GatewaySpec> = vec![];
    for (i, d) in out_devices.iter().enumerate() {
        let gw = match gateways.iter_mut().find(|g| g.address == d.address) {
            Some(g) => g,
            None => {
                gateways.push(GatewaySpec {
                    address: d.address.clone(),
                    units: HashMap::new(),
                });
                gateways.last_mut().expect("just pushed")
            }
        };
        if let Some(&other) = gw.units.get(&d.unit_id) {
            return Err(Error::Config(format!(
                "devices '{}' and '{}' both use unit id {} at {}",
                out_devices[other].name, d.name, d.unit_id, d.address
            )));
        }
        gw.units.insert(d.unit_id, i);
    }

    Ok(Layout {
        devices: out_devices,
        gateways,
        stations,
        outputs,
        inputs,
        unmodelled,
        unserved,
    })
}
