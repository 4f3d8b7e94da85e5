//! The Simulation panel's controls, translated from the web layer's terms
//! into the simulator's handle (`app` owns both ends; `web` never sees the
//! simulator).

use std::time::Duration;

use gridscada_sim::{ExceptionCode, Profile, SimHandle};
use gridscada_web::api::sim::{
    InputProfile, LinkFaults, PlantInput, ReplyFault, SimDevice, SimInputs, SimPanel, SimState,
    SimZone,
};

pub(super) fn inject_timed_fault(
    sim: &SimHandle,
    panel: &str,
    zone: u8,
    clears_after: Duration,
) -> Result<(), String> {
    sim.inject_timed_fault(panel, zone, clears_after)
        .map_err(|e| e.to_string())
}

/// Sets both link faults of a device at once, so the panel's one form
/// leaves no stale half behind.
pub(super) fn set_link(sim: &SimHandle, device: &str, link: &LinkFaults) -> Result<(), String> {
    let slow = link
        .slow_reply_ms
        .map(|ms| Duration::from_millis(u64::from(ms)));
    sim.set_slow_replies(device, slow)
        .map_err(|e| e.to_string())?;
    sim.set_corrupt_frames(device, link.replies == ReplyFault::Corrupt)
        .map_err(|e| e.to_string())?;
    sim.set_exception(
        device,
        (link.replies == ReplyFault::Exception).then_some(ExceptionCode::ServerDeviceFailure),
    )
    .map_err(|e| e.to_string())
}

pub(super) fn set_input(
    sim: &SimHandle,
    input: PlantInput,
    profile: &InputProfile,
) -> Result<(), String> {
    let p = match *profile {
        InputProfile::Builtin => Profile::Builtin,
        InputProfile::Scaled { factor } => Profile::Scaled(factor),
        InputProfile::Constant { value } => Profile::Constant(value),
        InputProfile::Daily => {
            return Err("a daily table comes from a scenario file, not the panel".into())
        }
    };
    match input {
        PlantInput::Irradiance => sim.set_irradiance(p),
        PlantInput::WindSpeed => sim.set_wind_speed(p),
        PlantInput::Demand => sim.set_demand(p),
    }
    .and_then(|()| sim.sample_inputs_now())
    .map_err(|e| e.to_string())
}

pub(super) fn set_zone_load(
    sim: &SimHandle,
    panel: &str,
    zone: u8,
    kw: f64,
    pf: f64,
) -> Result<(), String> {
    sim.set_zone_load(panel, zone, gridscada_sim::ZoneLoad { kw, pf })
        .map_err(|e| e.to_string())
}

/// A profile as the panel shows it.
fn profile_of(p: &Profile) -> InputProfile {
    match p {
        Profile::Builtin => InputProfile::Builtin,
        Profile::Scaled(f) => InputProfile::Scaled { factor: *f },
        Profile::Constant(v) => InputProfile::Constant { value: *v },
        Profile::Daily(_) => InputProfile::Daily,
    }
}

pub(super) fn state(sim: &SimHandle) -> SimState {
    let snap = sim.snapshot();
    SimState {
        devices: snap
            .devices
            .iter()
            .map(|d| SimDevice {
                name: d.name.clone(),
                offline: d.offline,
                slow_reply_ms: d
                    .slow_reply_ms
                    .map(|ms| u32::try_from(ms).unwrap_or(u32::MAX)),
                replies: if d.corrupt_frames {
                    ReplyFault::Corrupt
                } else if d.exception.is_some() {
                    ReplyFault::Exception
                } else {
                    ReplyFault::Normal
                },
            })
            .collect(),
        panels: snap
            .panels
            .iter()
            .map(|p| SimPanel {
                id: p.id.clone(),
                elcb_closed: p.elcb_closed,
                zones: p
                    .zones
                    .iter()
                    .map(|z| SimZone {
                        zone: z.zone,
                        fault: z.fault.map(|k| match k {
                            gridscada_sim::FaultKind::Permanent => {
                                gridscada_web::api::sim::FaultKind::Permanent
                            }
                            gridscada_sim::FaultKind::Transient => {
                                gridscada_web::api::sim::FaultKind::Transient
                            }
                        }),
                        fault_clears_at: z.fault_clears_at.map(|t| t.as_millis()),
                        load_kw: z.load.kw,
                        pf: z.load.pf,
                    })
                    .collect(),
            })
            .collect(),
        inputs: snap.microgrid.as_ref().map(|m| SimInputs {
            irradiance: profile_of(&m.irradiance_profile),
            wind_speed: profile_of(&m.wind_speed_profile),
            demand: profile_of(&m.demand_profile),
            irradiance_w_m2: m.irradiance_w_m2,
            wind_speed_m_s: m.wind_speed_m_s,
            demand_kw: m.demand_kw,
        }),
    }
}
