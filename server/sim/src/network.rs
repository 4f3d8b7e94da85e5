//! The simulated switching network: every device of `[network]` that is
//! not a panel's own breaker follows its commands after the breaker delay,
//! as a real switch's mechanism does; and each panel whose supply node is
//! in the network loses and regains its supply as the topology says.
//!
//! Owns those devices' positions and the supply each panel sees. Must not
//! touch the panels' own breakers (the panel models hold them) or the units
//! (the microgrid model does); it reads both.

use std::time::Duration;

use gridscada_config::{CommandBinding, Normally, Plant, StatusBinding};
use gridscada_network::{compute, Inputs, Network, Pos};
use gridscada_tagdb::Timestamp;

use crate::microgrid::{Microgrid, UnitState};
use crate::panel::PanelModel;

/// What a network device is to the simulator.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Owner {
    /// Its own position, commanded through its tag.
    Own,
    /// A panel's ELCB, MCCB or zone MCB (zone 1-based): the panel model's.
    PanelElcb(usize),
    PanelMccb(usize),
    PanelZone(usize, usize),
}

#[derive(Debug, Clone)]
struct Mechanism {
    cmd: bool,
    closed: bool,
    due: Option<Timestamp>,
}

pub(crate) struct NetworkSim {
    network: Network,
    owner: Vec<Owner>,
    devices: Vec<Mechanism>,
    /// (panel, the section its ELCB's line side is on).
    supply: Vec<(usize, u32)>,
    /// Per source: the microgrid unit it is, if any.
    unit_of_source: Vec<Option<usize>>,
    delay: Duration,
    /// The positions the topology was last computed from, and whether each
    /// `supply` entry was energised then: the plant advances on every
    /// request, its switches move seldom.
    last: Option<(Inputs, Vec<bool>)>,
}

impl NetworkSim {
    /// The plant's network, if it has one.
    pub fn new(plant: &Plant, delay: Duration) -> Option<NetworkSim> {
        let network = Network::from_plant(plant)?.ok()?;
        let net = plant.network.as_ref()?;
        let owner = network
            .model
            .switches
            .iter()
            .zip(&network.status)
            .map(|(_, status)| {
                let Some(StatusBinding::Tag(tag)) = status else {
                    return Owner::Own;
                };
                for (pi, p) in plant.panels.iter().enumerate() {
                    let io = p.io();
                    if *tag == io.elcb_closed {
                        return Owner::PanelElcb(pi);
                    }
                    if *tag == io.mccb_closed {
                        return Owner::PanelMccb(pi);
                    }
                    if let Some(z) = io.zone_closed.iter().position(|z| z == tag) {
                        return Owner::PanelZone(pi, z + 1);
                    }
                }
                Owner::Own
            })
            .collect();
        let devices = network
            .model
            .switches
            .iter()
            .map(|s| Mechanism {
                cmd: s.normally_closed,
                closed: s.normally_closed,
                due: None,
            })
            .collect();
        let supply = net
            .panels
            .iter()
            .filter_map(|np| {
                let pi = plant
                    .panels
                    .iter()
                    .position(|p| p.id.get_ref() == np.panel.get_ref())?;
                let node = network
                    .model
                    .nodes
                    .iter()
                    .position(|n| n.id == *np.supply.get_ref())?;
                Some((pi, network.model.node_section[node]))
            })
            .collect();
        let units = plant
            .microgrid
            .as_ref()
            .map(|m| &m.units[..])
            .unwrap_or(&[]);
        let unit_of_source = network
            .model
            .sources
            .iter()
            .map(|s| units.iter().position(|u| *u.id.get_ref() == s.id))
            .collect();
        Some(NetworkSim {
            network,
            owner,
            devices,
            supply,
            unit_of_source,
            delay,
            last: None,
        })
    }

    /// The device whose status tag is `tag`, and whether the tag reads the
    /// "open" contact of a pair.
    pub fn status_of(&self, tag: &str) -> Option<(usize, StatusShape)> {
        self.network
            .status
            .iter()
            .enumerate()
            .filter(|(i, _)| self.owner[*i] == Owner::Own)
            .find_map(|(i, s)| match s.as_ref()? {
                StatusBinding::Tag(t) if t == tag => Some((i, StatusShape::Closed)),
                StatusBinding::Pair { open, .. } if open == tag => {
                    Some((i, StatusShape::OpenContact))
                }
                StatusBinding::Pair { closed, .. } if closed == tag => {
                    Some((i, StatusShape::Closed))
                }
                _ => None,
            })
    }

    /// The device commanded through `tag` (only the simulator's own).
    pub fn command_of(&self, tag: &str) -> Option<usize> {
        self.network
            .command
            .iter()
            .enumerate()
            .filter(|(i, _)| self.owner[*i] == Owner::Own)
            .find_map(|(i, c)| (c.as_ref()?.tag() == tag).then_some(i))
    }

    /// A write of `on` to device `i`'s command tag at `now`.
    pub fn command(&mut self, i: usize, on: bool, now: Timestamp) {
        let Some(binding) = self.network.command.get(i).cloned().flatten() else {
            return;
        };
        let target = match binding {
            CommandBinding::Tag(_) => on,
            CommandBinding::Pulse { pulse, .. } if on => pulse == Normally::Closed,
            CommandBinding::Pulse { .. } => return,
        };
        let d = &mut self.devices[i];
        d.cmd = target;
        d.due = (d.closed != target).then(|| now.add(self.delay));
    }

    /// What device `i`'s command output reads back.
    pub fn command_state(&self, i: usize) -> bool {
        match self.network.command.get(i) {
            Some(Some(CommandBinding::Tag(_))) => self.devices[i].cmd,
            _ => false,
        }
    }

    /// Device `i`'s position as its status tag shows it: a bool status 1/0,
    /// an integer double point 2/1, the open contact of a pair 1 when open.
    pub fn status_value(&self, i: usize, shape: StatusShape, integer: bool) -> f64 {
        let closed = self.devices[i].closed;
        match shape {
            StatusShape::OpenContact => f64::from(u8::from(!closed)),
            StatusShape::Closed if integer => {
                if closed {
                    2.0
                } else {
                    1.0
                }
            }
            StatusShape::Closed => f64::from(u8::from(closed)),
        }
    }

    /// Moves the mechanisms due by `now`, then gives each panel in the
    /// network the supply the topology gives its incomer.
    pub fn advance_to(
        &mut self,
        now: Timestamp,
        panels: &mut [PanelModel],
        microgrid: Option<&Microgrid>,
    ) {
        for d in &mut self.devices {
            if d.due.is_some_and(|t| t <= now) {
                d.closed = d.cmd;
                d.due = None;
            }
        }
        if self.supply.is_empty() {
            return;
        }
        let pos = |b: bool| if b { Pos::Closed } else { Pos::Open };
        let switches = self
            .owner
            .iter()
            .enumerate()
            .map(|(i, o)| match *o {
                Owner::Own => pos(self.devices[i].closed),
                Owner::PanelElcb(p) => pos(panels[p].elcb_closed),
                Owner::PanelMccb(p) => pos(panels[p].mccb.closed),
                Owner::PanelZone(p, z) => pos(panels[p].zone[z - 1].closed),
            })
            .collect();
        let sources = self
            .unit_of_source
            .iter()
            .map(|u| match (u, microgrid) {
                (None, _) => Pos::Closed,
                (Some(u), Some(mg)) => pos(mg
                    .units
                    .get(*u)
                    .is_some_and(|u| u.state == UnitState::Running)),
                (Some(_), None) => Pos::Open,
            })
            .collect();
        let inputs = Inputs { switches, sources };
        if self.last.as_ref().is_none_or(|(last, _)| *last != inputs) {
            let topology = compute(&self.network.model, &inputs);
            let energised = self
                .supply
                .iter()
                .map(|&(_, section)| topology.state[section as usize].energised())
                .collect();
            self.last = Some((inputs, energised));
        }
        if let Some((_, energised)) = &self.last {
            for (&(p, _), &on) in self.supply.iter().zip(energised) {
                panels[p].set_supply(on, now);
            }
        }
    }
}

/// Which way a status tag shows a position.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum StatusShape {
    /// True (or 2) when closed.
    Closed,
    /// The open contact of a pair: true when open.
    OpenContact,
}
