//! The electrical model of one LV substation panel:
//! supply -> ELCB -> main MCCB ("load 0", busbar) -> zone MCBs -> zone loads,
//! and the power analyzer on the panel's incomer (downstream of the ELCB).
//!
//! Owns breaker contacts and their mechanical delay, the ELCB trip on an
//! energised fault, faults themselves, zone loads and the analyzer's
//! readings. Must not touch registers or sockets: it is an explicit state
//! machine advanced in plant time, driven by commands and fault injection.
//!
//! Design decisions (documented in docs/REGISTER_MAPS.md):
//! - A trip opens only the ELCB. The MCCB and MCBs keep their commanded
//!   state (switching them off is the controller's job, as in the seed).
//! - A breaker's contact (and so its status input) follows its command after
//!   `breaker_delay` of plant time; a "stuck" breaker ignores commands.
//! - The ELCB recloses on a rising edge of its reset output, after the same
//!   mechanical delay; if it closes onto a faulted energised path it trips
//!   again at once.
//! - A transient fault is gone once it has tripped the ELCB, or, when it
//!   was given a clearing time, once that plant time has passed (until then
//!   it trips the ELCB on every reclose, like a permanent one).

use std::f64::consts::PI;
use std::time::Duration;

use gridscada_tagdb::Timestamp;
use serde::{Deserialize, Serialize};

/// How a zone fault behaves.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum FaultKind {
    /// Stays until repaired.
    Permanent,
    /// Clears by itself: after it has tripped the ELCB once, or at its
    /// clearing time when it has one.
    Transient,
}

/// A zone's load: active power and power factor (before the small
/// deterministic variation the simulator adds).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ZoneLoad {
    pub kw: f64,
    pub pf: f64,
}

impl ZoneLoad {
    /// The default load of zone `z` (1-based): a few kW, PF 0.88-0.95.
    pub fn default_for(z: usize) -> Self {
        const KW: [f64; 4] = [2.5, 4.0, 3.0, 5.5];
        const PF: [f64; 4] = [0.92, 0.88, 0.95, 0.9];
        let i = (z.max(1) - 1) % 4;
        ZoneLoad {
            kw: KW[i],
            pf: PF[i],
        }
    }
}

/// A breaker: its command, its contact, and a pending movement.
#[derive(Debug, Clone, Default)]
pub(crate) struct Breaker {
    pub cmd: bool,
    pub closed: bool,
    pub due: Option<Timestamp>,
    pub stuck: bool,
    pub operations: u64,
}

impl Breaker {
    fn new(closed: bool) -> Self {
        Breaker {
            cmd: closed,
            closed,
            ..Default::default()
        }
    }

    fn command(&mut self, v: bool, now: Timestamp, delay: Duration) {
        self.cmd = v;
        self.reschedule(now, delay);
    }

    fn reschedule(&mut self, now: Timestamp, delay: Duration) {
        if self.stuck || self.cmd == self.closed {
            self.due = None;
        } else if self.due.is_none() {
            self.due = Some(now.add(delay));
        }
    }
}

/// Why the ELCB last tripped.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TripRecord {
    pub at: Timestamp,
    /// Faulted paths that were energised: 0 = busbar (load 0), 1.. = zones.
    pub zones: Vec<u8>,
}

/// The analyzer's readings.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct AnalyzerReading {
    pub v: [f64; 3],
    pub i: [f64; 3],
    pub p_kw: f64,
    pub q_kvar: f64,
    pub pf: f64,
    pub hz: f64,
    pub kwh: f64,
}

#[derive(Debug, Clone)]
pub(crate) struct PanelModel {
    pub id: String,
    pub elcb_closed: bool,
    reset_coil: bool,
    reclose_due: Option<Timestamp>,
    pub elcb_trips: u64,
    pub mccb: Breaker,
    pub zone: Vec<Breaker>,
    /// Index 0 = busbar (load 0), 1..=zones.
    pub faults: Vec<Option<FaultKind>>,
    /// When a timed transient fault of each path clears by itself.
    pub fault_clears_at: Vec<Option<Timestamp>>,
    /// How often each faulted path was energised (each one tripped the ELCB).
    pub fault_energisations: Vec<u64>,
    pub door_open: bool,
    pub loads: Vec<ZoneLoad>,
    pub kwh: f64,
    pub last_trip: Option<TripRecord>,
    /// The incomer has voltage (always, unless the switching network feeds
    /// the panel and the topology says otherwise). Losing it does not trip
    /// the ELCB: nothing flows.
    pub supply: bool,
    last: Timestamp,
    delay: Duration,
}

/// Longest step of the energy integration.
const MAX_STEP: Duration = Duration::from_secs(1);
/// Source impedance per phase, ohm: gives a volt or so of drop at full load.
const SOURCE_OHM: f64 = 0.05;

impl PanelModel {
    pub fn new(
        id: &str,
        zones: usize,
        start_closed: bool,
        delay: Duration,
        now: Timestamp,
    ) -> Self {
        PanelModel {
            id: id.to_string(),
            elcb_closed: true,
            reset_coil: false,
            reclose_due: None,
            elcb_trips: 0,
            mccb: Breaker::new(start_closed),
            zone: (0..zones).map(|_| Breaker::new(start_closed)).collect(),
            faults: vec![None; zones + 1],
            fault_clears_at: vec![None; zones + 1],
            fault_energisations: vec![0; zones + 1],
            door_open: false,
            loads: (1..=zones).map(ZoneLoad::default_for).collect(),
            kwh: 0.0,
            last_trip: None,
            supply: true,
            last: now,
            delay,
        }
    }

    pub fn zones(&self) -> usize {
        self.zone.len()
    }

    pub fn busbar_energised(&self) -> bool {
        self.supply && self.elcb_closed && self.mccb.closed
    }

    /// The incomer gains or loses voltage at `now`. A fault on a closed
    /// path trips the ELCB when the supply returns.
    pub fn set_supply(&mut self, on: bool, now: Timestamp) {
        if self.supply == on {
            return;
        }
        self.integrate_to(now.max(self.last));
        self.supply = on;
        if on {
            self.check_trip(now);
        }
    }

    /// Zone `z` (1-based) has voltage.
    pub fn zone_energised(&self, z: usize) -> bool {
        self.busbar_energised() && self.zone.get(z.wrapping_sub(1)).is_some_and(|b| b.closed)
    }

    pub fn reset_coil(&self) -> bool {
        self.reset_coil
    }

    /// Runs the panel forward to `now`: breaker movements and ELCB reclosing
    /// in time order, each followed by the trip check; energy integrates.
    pub fn advance_to(&mut self, now: Timestamp) {
        loop {
            let mut next: Option<(Timestamp, Event)> = None;
            let mut consider = |t: Option<Timestamp>, e: Event| {
                if let Some(t) = t {
                    if t <= now && next.as_ref().is_none_or(|(n, _)| t < *n) {
                        next = Some((t, e));
                    }
                }
            };
            consider(self.reclose_due, Event::Reclose);
            for (z, at) in self.fault_clears_at.iter().enumerate() {
                consider(*at, Event::FaultClears(z));
            }
            consider(self.mccb.due, Event::Mccb);
            for (i, z) in self.zone.iter().enumerate() {
                consider(z.due, Event::Zone(i));
            }
            let Some((t, ev)) = next else { break };
            self.integrate_to(t);
            match ev {
                Event::Reclose => {
                    self.reclose_due = None;
                    self.elcb_closed = true;
                }
                Event::Mccb => settle(&mut self.mccb),
                Event::Zone(i) => settle(&mut self.zone[i]),
                Event::FaultClears(z) => {
                    self.fault_clears_at[z] = None;
                    self.faults[z] = None;
                }
            }
            self.check_trip(t);
        }
        self.integrate_to(now);
    }

    /// The main MCCB command output changed.
    pub fn command_mccb(&mut self, v: bool, now: Timestamp) {
        self.advance_to(now);
        self.mccb.command(v, now, self.delay);
        self.advance_to(now);
    }

    /// A zone MCB command output (zone 1-based) changed.
    pub fn command_zone(&mut self, z: usize, v: bool, now: Timestamp) {
        self.advance_to(now);
        if let Some(b) = self.zone.get_mut(z.wrapping_sub(1)) {
            b.command(v, now, self.delay);
        }
        self.advance_to(now);
    }

    /// The ELCB reset output changed; a rising edge starts a reclose.
    pub fn command_reset(&mut self, v: bool, now: Timestamp) {
        self.advance_to(now);
        if v && !self.reset_coil && !self.elcb_closed && self.reclose_due.is_none() {
            self.reclose_due = Some(now.add(self.delay));
        }
        self.reset_coil = v;
        self.advance_to(now);
    }

    /// Puts a fault on path `zone` (0 = busbar / load 0).
    pub fn inject_fault(&mut self, zone: usize, kind: FaultKind, now: Timestamp) {
        self.advance_to(now);
        if let Some(f) = self.faults.get_mut(zone) {
            *f = Some(kind);
            self.fault_clears_at[zone] = None;
        }
        self.check_trip(now);
    }

    /// Puts a transient fault on path `zone` that stays (tripping the ELCB
    /// on every reclose onto it) until `clears_after` of plant time has
    /// passed, so a reclose after that succeeds.
    pub fn inject_timed_fault(&mut self, zone: usize, clears_after: Duration, now: Timestamp) {
        self.advance_to(now);
        if let Some(f) = self.faults.get_mut(zone) {
            *f = Some(FaultKind::Transient);
            self.fault_clears_at[zone] = Some(now.add(clears_after));
        }
        self.check_trip(now);
    }

    pub fn repair(&mut self, zone: usize, now: Timestamp) {
        self.advance_to(now);
        if let Some(f) = self.faults.get_mut(zone) {
            *f = None;
            self.fault_clears_at[zone] = None;
        }
    }

    /// Freezes (or frees) a breaker's contact: 0 = MCCB, 1.. = zone MCBs.
    pub fn set_stuck(&mut self, breaker: usize, stuck: bool, now: Timestamp) {
        self.advance_to(now);
        let delay = self.delay;
        let b = if breaker == 0 {
            Some(&mut self.mccb)
        } else {
            self.zone.get_mut(breaker - 1)
        };
        if let Some(b) = b {
            b.stuck = stuck;
            b.reschedule(now, delay);
        }
    }

    /// Opens the ELCB if any faulted path is energised; transient faults that
    /// caused the trip are gone afterwards.
    fn check_trip(&mut self, t: Timestamp) {
        if !self.elcb_closed || !self.supply {
            return;
        }
        let mut faulted = vec![];
        if self.mccb.closed && self.faults[0].is_some() {
            faulted.push(0);
        }
        for z in 1..=self.zones() {
            if self.mccb.closed && self.zone[z - 1].closed && self.faults[z].is_some() {
                faulted.push(z);
            }
        }
        if faulted.is_empty() {
            return;
        }
        self.elcb_closed = false;
        self.elcb_trips += 1;
        for &z in &faulted {
            self.fault_energisations[z] += 1;
            if self.faults[z] == Some(FaultKind::Transient) && self.fault_clears_at[z].is_none() {
                self.faults[z] = None;
            }
        }
        self.last_trip = Some(TripRecord {
            at: t,
            zones: faulted.iter().map(|z| *z as u8).collect(),
        });
    }

    fn integrate_to(&mut self, t: Timestamp) {
        while self.last < t {
            let step = t.since(self.last).min(MAX_STEP);
            let mid = self.last.add(step / 2);
            let p = self.total_power(mid).0;
            self.kwh += p * step.as_secs_f64() / 3600.0;
            self.last = self.last.add(step);
            if step.is_zero() {
                break;
            }
        }
    }

    /// Zone `z` (1-based) load at time t, with its small variation: kW, kvar.
    pub fn zone_power(&self, z: usize, t: Timestamp) -> (f64, f64) {
        let Some(l) = self.loads.get(z.wrapping_sub(1)) else {
            return (0.0, 0.0);
        };
        // A slow ±5 % swing, phase-shifted per zone, so the trend is alive
        // but every run is the same.
        let s = t.as_secs_f64();
        let kw = (l.kw * (1.0 + 0.05 * (2.0 * PI * s / 900.0 + z as f64).sin())).max(0.0);
        let pf = l.pf.clamp(0.05, 1.0);
        (kw, kw * (1.0 / (pf * pf) - 1.0).max(0.0).sqrt())
    }

    /// Energised load of the panel: kW, kvar, per phase (kW, kvar).
    fn total_power(&self, t: Timestamp) -> (f64, f64, [(f64, f64); 3]) {
        let mut phases = [(0.0, 0.0); 3];
        let (mut p, mut q) = (0.0, 0.0);
        for z in 1..=self.zones() {
            if !self.zone_energised(z) {
                continue;
            }
            let (zp, zq) = self.zone_power(z, t);
            p += zp;
            q += zq;
            // Half of a zone's load on its own phase, a quarter on the others.
            let main = (z - 1) % 3;
            for (ph, acc) in phases.iter_mut().enumerate() {
                let share = if ph == main { 0.5 } else { 0.25 };
                acc.0 += zp * share;
                acc.1 += zq * share;
            }
        }
        (p, q, phases)
    }

    /// What the power analyzer shows at time t.
    pub fn analyzer(&self, t: Timestamp) -> AnalyzerReading {
        if !self.elcb_closed || !self.supply {
            return AnalyzerReading {
                kwh: self.kwh,
                ..Default::default()
            };
        }
        let (p, q, phases) = self.total_power(t);
        let s = t.as_secs_f64();
        let mut v = [0.0; 3];
        let mut i = [0.0; 3];
        for ph in 0..3 {
            let v0 = 231.0 + 0.8 * (2.0 * PI * s / 3600.0 + 2.1 * ph as f64).sin();
            let (pp, qq) = phases[ph];
            let amps = (pp * pp + qq * qq).sqrt() * 1000.0 / v0;
            v[ph] = v0 - SOURCE_OHM * amps;
            i[ph] = amps;
        }
        let sa = (p * p + q * q).sqrt();
        AnalyzerReading {
            v,
            i,
            p_kw: p,
            q_kvar: q,
            pf: if sa > 1e-9 { p / sa } else { 1.0 },
            hz: 50.0 + 0.02 * (2.0 * PI * s / 300.0).sin(),
            kwh: self.kwh,
        }
    }
}

#[derive(Debug, Clone, Copy)]
enum Event {
    Reclose,
    Mccb,
    Zone(usize),
    FaultClears(usize),
}

fn settle(b: &mut Breaker) {
    b.due = None;
    if b.closed != b.cmd {
        b.closed = b.cmd;
        b.operations += 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const D: Duration = Duration::from_millis(50);

    fn t(ms: i64) -> Timestamp {
        Timestamp::from_millis(ms)
    }

    fn panel() -> PanelModel {
        PanelModel::new("ss1", 4, true, D, t(0))
    }

    #[test]
    fn status_follows_command_after_the_mechanical_delay() {
        let mut p = panel();
        p.command_zone(2, false, t(1000));
        assert!(p.zone[1].closed);
        p.advance_to(t(1049));
        assert!(p.zone[1].closed);
        p.advance_to(t(1050));
        assert!(!p.zone[1].closed);
        assert!(!p.zone_energised(2));
        assert!(p.zone_energised(1));
    }

    #[test]
    fn fault_on_an_open_zone_is_latent_until_it_is_closed() {
        let mut p = panel();
        p.command_zone(3, false, t(0));
        p.advance_to(t(100));
        p.inject_fault(3, FaultKind::Permanent, t(200));
        assert!(p.elcb_closed);
        p.command_zone(3, true, t(300));
        p.advance_to(t(350));
        assert!(!p.elcb_closed);
        assert_eq!(p.elcb_trips, 1);
        assert_eq!(p.fault_energisations[3], 1);
        // Breakers keep their commanded state: only the ELCB trips.
        assert!(p.mccb.closed && p.zone[2].closed);
        assert!(!p.zone_energised(1));
    }

    #[test]
    fn reset_recloses_only_on_a_rising_edge_and_retrips_onto_a_permanent_fault() {
        let mut p = panel();
        p.inject_fault(1, FaultKind::Permanent, t(0));
        assert!(!p.elcb_closed);
        p.command_reset(true, t(100));
        p.advance_to(t(200));
        // Closed onto the fault again: tripped at once.
        assert!(!p.elcb_closed);
        assert_eq!(p.elcb_trips, 2);
        // Holding the output on does nothing more.
        p.advance_to(t(500));
        assert_eq!(p.elcb_trips, 2);
        p.command_reset(false, t(600));
        p.command_zone(1, false, t(600));
        p.advance_to(t(700));
        p.command_reset(true, t(700));
        p.advance_to(t(800));
        assert!(p.elcb_closed);
        assert!(p.zone_energised(2) && !p.zone_energised(1));
    }

    #[test]
    fn transient_fault_is_gone_after_its_trip() {
        let mut p = panel();
        p.inject_fault(4, FaultKind::Transient, t(0));
        assert!(!p.elcb_closed);
        assert_eq!(p.faults[4], None);
        p.command_reset(true, t(10));
        p.advance_to(t(100));
        assert!(p.elcb_closed);
        assert!(p.zone_energised(4));
    }

    #[test]
    fn timed_transient_fault_retrips_until_it_clears_then_a_reclose_holds() {
        let mut p = panel();
        p.inject_timed_fault(3, Duration::from_secs(2), t(0));
        assert!(!p.elcb_closed, "it trips at once");
        assert_eq!(p.faults[3], Some(FaultKind::Transient));
        // A reclose before the clearing time closes onto it again.
        p.command_reset(true, t(100));
        p.command_reset(false, t(200));
        p.advance_to(t(500));
        assert!(!p.elcb_closed);
        assert_eq!(p.elcb_trips, 2);
        // After it, the fault is gone and a reclose holds.
        p.advance_to(t(2_000));
        assert_eq!(p.faults[3], None);
        p.command_reset(true, t(2_100));
        p.advance_to(t(2_300));
        assert!(p.elcb_closed);
        assert!(p.zone_energised(3));
        assert_eq!(p.elcb_trips, 2);
    }

    #[test]
    fn repair_cancels_a_timed_fault() {
        let mut p = panel();
        p.inject_timed_fault(1, Duration::from_secs(60), t(0));
        p.repair(1, t(10));
        assert_eq!(p.fault_clears_at[1], None);
        p.command_reset(true, t(20));
        p.advance_to(t(200));
        assert!(p.elcb_closed);
    }

    #[test]
    fn busbar_fault_trips_with_the_mccb_closed() {
        let mut p = panel();
        p.command_mccb(false, t(0));
        p.advance_to(t(60));
        p.inject_fault(0, FaultKind::Permanent, t(100));
        assert!(p.elcb_closed);
        p.command_mccb(true, t(200));
        p.advance_to(t(250));
        assert!(!p.elcb_closed);
        assert_eq!(p.last_trip.as_ref().unwrap().zones, vec![0]);
    }

    #[test]
    fn stuck_breaker_ignores_commands() {
        let mut p = panel();
        p.set_stuck(2, true, t(0));
        p.command_zone(2, false, t(0));
        p.advance_to(t(1000));
        assert!(p.zone[1].closed);
        assert!(!p.zone[1].cmd);
        p.set_stuck(2, false, t(1000));
        p.advance_to(t(1050));
        assert!(!p.zone[1].closed);
    }

    #[test]
    fn analyzer_follows_the_energised_zones() {
        let mut p = panel();
        let all = p.analyzer(t(0));
        let expected: f64 = (1..=4).map(|z| p.zone_power(z, t(0)).0).sum();
        assert!((all.p_kw - expected).abs() < 1e-9);
        assert!(all.v.iter().all(|v| (225.0..235.0).contains(v)));
        assert!(all.pf > 0.85 && all.pf < 1.0);
        p.command_zone(4, false, t(0));
        p.advance_to(t(100));
        let three = p.analyzer(t(100));
        let expected: f64 = (1..=3).map(|z| p.zone_power(z, t(100)).0).sum();
        assert!((three.p_kw - expected).abs() < 1e-9);
        p.inject_fault(1, FaultKind::Permanent, t(200));
        let dead = p.analyzer(t(200));
        assert_eq!((dead.p_kw, dead.v[0], dead.hz), (0.0, 0.0, 0.0));
    }

    #[test]
    fn energy_integrates_the_energised_load() {
        let mut p = panel();
        p.advance_to(t(3_600_000));
        // About 15 kW for an hour, with a ±5 % swing.
        assert!(p.kwh > 14.0 && p.kwh < 16.0, "{}", p.kwh);
    }
}
