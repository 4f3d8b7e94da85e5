//! What the scenario does as the operator and the weather: simulator inputs
//! (profiles, state of charge), panel commands and acknowledgements.

use std::time::Duration;

use anyhow::anyhow;
use gridscada_config::Plant;
use gridscada_control::fault_isolation::{PanelCommand, PanelCommandKind};
use gridscada_sim::scenario::{self, Action, Scenario};
use gridscada_sim::{Profile, SimHandle, ZoneLoad};
use tokio::sync::oneshot;

use crate::runtime::Stack;

fn set_soc_pct(sim: &SimHandle, plant: &Plant, unit: &str, pct: f64) -> anyhow::Result<()> {
    let cap = plant
        .microgrid
        .as_ref()
        .and_then(|m| {
            m.units
                .iter()
                .find(|u| u.id.get_ref() == unit || u.prefix.get_ref() == unit)
        })
        .map(|u| u.capacity_kwh)
        .ok_or_else(|| anyhow!("no storage unit '{unit}'"))?;
    sim.set_soc(unit, cap * pct / 100.0)?;
    Ok(())
}

/// What the scenario does as the operator and the weather: simulator
/// inputs, panel commands and acknowledgements, nothing else.
pub(super) struct Operator<'a> {
    pub(super) plant: &'a Plant,
    pub(super) alarms: &'a gridscada_alarms::AlarmEngine,
    pub(super) panels: &'a [gridscada_web::api::panels::PanelHandle],
    pub(super) sim: &'a SimHandle,
}

impl Operator<'_> {
    pub(super) fn of<'a>(stack: &'a Stack, sim: &'a SimHandle) -> Operator<'a> {
        Operator {
            plant: &stack.plant,
            alarms: &stack.alarms,
            panels: &stack.panels,
            sim,
        }
    }

    async fn command(&self, panel: &str, kind: PanelCommandKind) -> Result<(), String> {
        let handle = self
            .panels
            .iter()
            .find(|p| {
                p.id == panel
                    || self
                        .plant
                        .panels
                        .iter()
                        .any(|c| c.id.get_ref() == &p.id && c.prefix.get_ref() == panel)
            })
            .ok_or_else(|| format!("no panel '{panel}'"))?;
        let (reply, rx) = oneshot::channel();
        handle
            .commands
            .send(PanelCommand {
                user: "scenario".into(),
                kind,
                reply,
            })
            .await
            .map_err(|_| "the panel's sequence is not running".to_string())?;
        match rx.await {
            Ok(Ok(())) => Ok(()),
            Ok(Err(e)) => Err(e.to_string()),
            Err(_) => Err("the panel's sequence did not answer".into()),
        }
    }

    /// Performs one scenario event; `Err` is a refusal worth recording, not
    /// a reason to stop (an operator's command can be refused in the field too).
    pub(super) async fn apply(&self, action: &Action) -> Result<(), String> {
        let sim = self.sim;
        let s = |r: Result<(), gridscada_sim::Error>| r.map_err(|e| e.to_string());
        match action {
            Action::Fault { panel, zone, kind } => s(sim.inject_zone_fault(panel, *zone, *kind)),
            Action::Repair { panel, zone } => s(sim.repair_zone(panel, *zone)),
            Action::Mode { panel, mode } => {
                self.command(panel, PanelCommandKind::SetMode(*mode)).await
            }
            Action::Reset { panel } => self.command(panel, PanelCommandKind::Reset).await,
            Action::Breaker {
                panel,
                breaker,
                close,
            } => {
                self.command(
                    panel,
                    PanelCommandKind::Breaker {
                        breaker: breaker.clone(),
                        close: *close,
                    },
                )
                .await
            }
            Action::Acknowledge { user } => self
                .alarms
                .ack_all(user, &Default::default())
                .map(|_| ())
                .map_err(|e| e.to_string()),
            Action::CommLoss { device } => s(sim.set_device_offline(device, true)),
            Action::CommReturn { device } => s(sim.set_device_offline(device, false)),
            Action::Trip { unit } => s(sim.trip_unit(unit)),
            Action::UnitReset { unit } => s(sim.reset_unit(unit)),
            Action::SetSoc { unit, soc_pct } => {
                set_soc_pct(sim, self.plant, unit, *soc_pct).map_err(|e| e.to_string())
            }
        }
    }

    /// The initial state, before plant time starts running for the scenario.
    pub(super) async fn initial(&self, scn: &Scenario) -> anyhow::Result<()> {
        for u in &scn.initial.units {
            if let Some(pct) = u.soc_pct {
                set_soc_pct(self.sim, self.plant, &u.id, pct)?;
            }
            if u.tripped {
                self.sim.trip_unit(&u.id)?;
            }
        }
        for p in &scn.initial.panels {
            if p.door_open {
                self.sim.set_door_open(&p.id, true)?;
            }
            for (i, kw) in p.zone_kw.iter().enumerate() {
                let pf = ZoneLoad::default_for(i + 1).pf;
                self.sim
                    .set_zone_load(&p.id, (i + 1) as u8, ZoneLoad { kw: *kw, pf })?;
            }
            if let Some(mode) = p.mode {
                self.command(&p.id, PanelCommandKind::SetMode(mode))
                    .await
                    .map_err(|e| anyhow!("initial mode of panel {}: {e}", p.id))?;
            }
        }
        Ok(())
    }
}

/// The plant inputs at one step, compared to skip unchanged updates.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Inputs {
    irradiance: Option<f64>,
    wind: Option<f64>,
    demand: Option<f64>,
    zones: Vec<(String, u8, f64, f64)>,
}

impl Inputs {
    pub(super) fn at(scn: &Scenario, t: Duration) -> Inputs {
        let p = &scn.profiles;
        let v = |s: &Option<scenario::Series>| s.as_ref().map(|s| s.value_at(t, scn.seed));
        // PV availability (fraction of rated) as the irradiance that gives it.
        let derate = gridscada_sim::MicrogridParams::default().pv_derate;
        let irradiance = v(&p.irradiance)
            .or_else(|| v(&p.pv_available).map(|f| f.clamp(0.0, 1.0) * 1000.0 / derate.max(1e-6)));
        Inputs {
            irradiance: irradiance.map(|x| x.max(0.0)),
            wind: v(&p.wind_speed).map(|x| x.max(0.0)),
            demand: v(&p.demand).map(|x| x.max(0.0)),
            zones: p
                .zones
                .iter()
                .map(|z| {
                    (
                        z.panel.clone(),
                        z.zone,
                        z.kw.value_at(t, scn.seed).max(0.0),
                        z.pf,
                    )
                })
                .collect(),
        }
    }

    pub(super) fn apply(&self, sim: &SimHandle, plant: &Plant) -> anyhow::Result<()> {
        if plant.microgrid.is_some() {
            if let Some(x) = self.irradiance {
                sim.set_irradiance(Profile::Constant(x))?;
            }
            if let Some(x) = self.wind {
                sim.set_wind_speed(Profile::Constant(x))?;
            }
            if let Some(x) = self.demand {
                sim.set_demand(Profile::Constant(x))?;
            }
        }
        for (panel, zone, kw, pf) in &self.zones {
            sim.set_zone_load(panel, *zone, ZoneLoad { kw: *kw, pf: *pf })?;
        }
        Ok(())
    }
}
