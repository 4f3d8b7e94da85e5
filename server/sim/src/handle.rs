//! The simulator's control interface: fault injection, plant inputs and the
//! read-only snapshot, for the HTTP admin routes, scenario replay and tests.
//!
//! Owns name resolution (panel / unit / device / gateway) and argument
//! checks. Must not touch sockets; every call takes the plant lock briefly
//! after advancing the plant to the clock's now, so calls are ordered with
//! Modbus requests in plant time.

use std::sync::Arc;
use std::time::Duration;

use gridscada_tagdb::Timestamp;
use tokio_modbus::ExceptionCode;

use crate::microgrid::Microgrid;
use crate::panel::{FaultKind, ZoneLoad};
use crate::plant::{DeviceSnapshot, SimSnapshot};
use crate::profile::Profile;
use crate::server::{CommFaults, Shared};
use crate::Error;

/// A cloneable handle on a running simulator.
#[derive(Clone)]
pub struct SimHandle {
    pub(crate) shared: Arc<Shared>,
}

impl std::fmt::Debug for SimHandle {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("SimHandle")
    }
}

impl SimHandle {
    // ----- Panels -----------------------------------------------------------

    /// Puts a fault on a zone of a panel (`panel`: id such as `ss1` or
    /// prefix such as `SS1`; `zone` 1..=N, or 0 for load 0 / the busbar
    /// behind the main MCCB). An energised faulted path trips the ELCB at once.
    pub fn inject_zone_fault(&self, panel: &str, zone: u8, kind: FaultKind) -> Result<(), Error> {
        self.shared.with_plant(|p| {
            let (pi, z) = zone_of(p, panel, zone, true)?;
            let now = p.now();
            p.panels[pi].inject_fault(z, kind, now);
            p.after_change();
            Ok(())
        })
    }

    /// Puts a transient fault on a zone that clears by itself after
    /// `clears_after` of plant time (1 s to 1 h); until then it trips the
    /// ELCB on every reclose, afterwards a reclose holds.
    pub fn inject_timed_fault(
        &self,
        panel: &str,
        zone: u8,
        clears_after: Duration,
    ) -> Result<(), Error> {
        if !(Duration::from_secs(1)..=Duration::from_secs(3600)).contains(&clears_after) {
            return Err(Error::BadValue(format!(
                "a transient fault clears after 1 s to 1 h; {} s is out of range",
                clears_after.as_secs_f64()
            )));
        }
        self.shared.with_plant(|p| {
            let (pi, z) = zone_of(p, panel, zone, true)?;
            let now = p.now();
            p.panels[pi].inject_timed_fault(z, clears_after, now);
            p.after_change();
            Ok(())
        })
    }

    /// Removes the fault of a zone (0 = busbar). The ELCB stays as it is.
    pub fn repair_zone(&self, panel: &str, zone: u8) -> Result<(), Error> {
        self.shared.with_plant(|p| {
            let (pi, z) = zone_of(p, panel, zone, true)?;
            let now = p.now();
            p.panels[pi].repair(z, now);
            p.after_change();
            Ok(())
        })
    }

    /// Freezes a breaker's contact (0 = main MCCB, 1..=N zone MCB): commands
    /// no longer move it, so status and command disagree.
    pub fn set_breaker_stuck(&self, panel: &str, breaker: u8, stuck: bool) -> Result<(), Error> {
        self.shared.with_plant(|p| {
            let (pi, b) = zone_of(p, panel, breaker, true)?;
            let now = p.now();
            p.panels[pi].set_stuck(b, stuck, now);
            p.after_change();
            Ok(())
        })
    }

    /// Opens or closes the panel door contact.
    pub fn set_door_open(&self, panel: &str, open: bool) -> Result<(), Error> {
        self.shared.with_plant(|p| {
            let pi = panel_of(p, panel)?;
            p.panels[pi].door_open = open;
            p.after_change();
            Ok(())
        })
    }

    /// Sets a zone's load (kW ≥ 0, 0 < PF ≤ 1).
    pub fn set_zone_load(&self, panel: &str, zone: u8, load: ZoneLoad) -> Result<(), Error> {
        if !(load.kw.is_finite() && load.kw >= 0.0 && load.pf > 0.0 && load.pf <= 1.0) {
            return Err(Error::BadValue(format!(
                "zone load {} kW at PF {}: need kW >= 0 and 0 < PF <= 1",
                load.kw, load.pf
            )));
        }
        self.shared.with_plant(|p| {
            let (pi, z) = zone_of(p, panel, zone, false)?;
            p.set_zone_load(pi, z, load);
            Ok(())
        })
    }

    // ----- Communication faults ---------------------------------------------

    /// A device (or every device of a gateway, by its configured address)
    /// stops answering: requests get no reply at all. Other units on the
    /// same gateway keep answering.
    pub fn set_device_offline(&self, target: &str, offline: bool) -> Result<(), Error> {
        self.comm(target, |f| f.offline = offline)
    }

    /// Replies come after `delay` of plant time (None: at once). A gateway
    /// serves one request at a time per connection, so a slow unit delays
    /// the others behind it on that connection, as on a serial sub-bus.
    pub fn set_slow_replies(&self, target: &str, delay: Option<Duration>) -> Result<(), Error> {
        self.comm(target, |f| f.slow = delay)
    }

    /// Every request is answered with this exception (None: normal replies).
    pub fn set_exception(&self, target: &str, code: Option<ExceptionCode>) -> Result<(), Error> {
        self.comm(target, |f| f.exception = code)
    }

    /// Replies are damaged on the wire (bad protocol id, wrong transaction
    /// id, wrong function code, in turn).
    pub fn set_corrupt_frames(&self, target: &str, corrupt: bool) -> Result<(), Error> {
        self.comm(target, |f| f.corrupt = corrupt)
    }

    /// Clears every communication fault of every device.
    pub fn clear_comm_faults(&self) {
        for f in self.shared.comm.write().iter_mut() {
            *f = CommFaults::default();
        }
    }

    fn comm(&self, target: &str, set: impl Fn(&mut CommFaults)) -> Result<(), Error> {
        let devices: Vec<usize> = {
            let p = self.shared.plant.lock();
            match p.devices.iter().position(|d| d.name == target) {
                Some(i) => vec![i],
                None => p
                    .devices
                    .iter()
                    .enumerate()
                    .filter(|(_, d)| d.address == target)
                    .map(|(i, _)| i)
                    .collect(),
            }
        };
        if devices.is_empty() {
            return Err(Error::NotFound(format!(
                "no simulated device or gateway address '{target}'"
            )));
        }
        let mut comm = self.shared.comm.write();
        for i in devices {
            if let Some(f) = comm.get_mut(i) {
                set(f);
            }
        }
        Ok(())
    }

    // ----- Microgrid --------------------------------------------------------

    /// Plane-of-array irradiance, W/m².
    pub fn set_irradiance(&self, profile: Profile) -> Result<(), Error> {
        self.microgrid(profile, |m, p| m.irradiance = p)
    }

    /// Hub wind speed, m/s.
    pub fn set_wind_speed(&self, profile: Profile) -> Result<(), Error> {
        self.microgrid(profile, |m, p| m.wind_speed = p)
    }

    /// Microgrid demand at the load meter, kW.
    pub fn set_demand(&self, profile: Profile) -> Result<(), Error> {
        self.microgrid(profile, |m, p| m.demand = p)
    }

    fn microgrid(
        &self,
        profile: Profile,
        set: impl FnOnce(&mut Microgrid, Profile),
    ) -> Result<(), Error> {
        profile.check().map_err(Error::BadValue)?;
        self.with_microgrid(|mg, _| set(mg, profile))
    }

    /// Runs `f` on the plant's microgrid at the plant's time.
    fn with_microgrid<R>(
        &self,
        f: impl FnOnce(&mut Microgrid, Timestamp) -> R,
    ) -> Result<R, Error> {
        self.shared.with_plant(|p| {
            let now = p.now();
            let mg = p
                .microgrid
                .as_mut()
                .ok_or_else(|| Error::NotFound("the plant has no microgrid".into()))?;
            Ok(f(mg, now))
        })
    }

    /// Reads the input profiles now instead of at the plant's next step, so
    /// a trainer's change shows on the meters at once. A replay sets its
    /// inputs every step and must not call this: it would move them a step
    /// earlier than the scenarios' expectations were measured with.
    pub fn sample_inputs_now(&self) -> Result<(), Error> {
        self.with_microgrid(|mg, now| mg.sample_environment(now))
    }

    /// Trips a unit (id such as `pv1` or prefix such as `MG.PV1`): State 2
    /// (fault), output zero, until [`SimHandle::reset_unit`].
    pub fn trip_unit(&self, unit: &str) -> Result<(), Error> {
        self.shared.with_plant(|p| {
            let i = unit_of(p, unit)?;
            let now = p.now();
            if let Some(mg) = p.microgrid.as_mut() {
                mg.trip(i, now);
            }
            p.after_change();
            Ok(())
        })
    }

    /// Clears a unit trip (a diesel comes back stopped).
    pub fn reset_unit(&self, unit: &str) -> Result<(), Error> {
        self.shared.with_plant(|p| {
            let i = unit_of(p, unit)?;
            let now = p.now();
            if let Some(mg) = p.microgrid.as_mut() {
                mg.reset(i, now);
            }
            p.after_change();
            Ok(())
        })
    }

    /// Sets a storage unit's stored energy, kWh (clamped to its SoC bounds).
    pub fn set_soc(&self, unit: &str, kwh: f64) -> Result<(), Error> {
        if !kwh.is_finite() {
            return Err(Error::BadValue(format!("stored energy {kwh} kWh")));
        }
        self.shared.with_plant(|p| {
            let i = unit_of(p, unit)?;
            p.set_soc(i, kwh);
            Ok(())
        })
    }

    // ----- Reading -----------------------------------------------------------

    /// The plant as it is now (advanced to the clock's now).
    pub fn snapshot(&self) -> SimSnapshot {
        let mut snap = self.shared.with_plant(|p| p.snapshot());
        let comm = self.shared.comm.read();
        let plant = self.shared.plant.lock();
        snap.devices = plant
            .devices
            .iter()
            .enumerate()
            .map(|(i, d)| {
                let f = comm.get(i).cloned().unwrap_or_default();
                DeviceSnapshot {
                    name: d.name.clone(),
                    address: d.address.clone(),
                    unit_id: d.unit_id,
                    offline: f.offline,
                    slow_reply_ms: f.slow.map(|d| d.as_millis() as u64),
                    exception: f.exception.map(u8::from),
                    corrupt_frames: f.corrupt,
                }
            })
            .collect();
        snap
    }
}

fn panel_of(p: &crate::plant::PlantSim, panel: &str) -> Result<usize, Error> {
    p.panel_index(panel)
        .ok_or_else(|| Error::NotFound(format!("no simulated panel '{panel}'")))
}

/// Resolves a panel and a zone number; `allow_zero` admits load 0.
fn zone_of(
    p: &crate::plant::PlantSim,
    panel: &str,
    zone: u8,
    allow_zero: bool,
) -> Result<(usize, usize), Error> {
    let pi = panel_of(p, panel)?;
    let n = p.panels[pi].zones();
    let z = usize::from(zone);
    if z > n || (z == 0 && !allow_zero) {
        let lo = if allow_zero { 0 } else { 1 };
        return Err(Error::NotFound(format!(
            "panel '{panel}' has zones {lo}..={n}; there is no zone {zone}"
        )));
    }
    Ok((pi, z))
}

fn unit_of(p: &crate::plant::PlantSim, unit: &str) -> Result<usize, Error> {
    p.unit_index(unit)
        .ok_or_else(|| Error::NotFound(format!("no simulated microgrid unit '{unit}'")))
}
