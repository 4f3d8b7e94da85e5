//! The report's figures from plain inputs: the plant configuration, the
//! historian's samples of the tags it names, and the alarm history. Pure:
//! [`crate::gather`] reads the store, this computes.
//!
//! Which tags measure what comes from the configuration only: a panel's
//! meter is a read-only tag in kW (or W, MW) under its prefix and outside
//! its zones; a zone's meter one under `PREFIX.ZoneN.`; a unit's power is
//! `UnitConfig::io().p_kw`; a panel's breakers are `PanelConfig::io()`.

use std::collections::{BTreeMap, HashMap};

use gridscada_config::{MicrogridConfig, PanelConfig, Plant, UnitConfig, UnitKind, UnitUsage};
use gridscada_store::AlarmTransition;
use serde::Serialize;

use crate::series::{self, edges, integrate, mean, segments, value_at, Sample, Segment};

/// Interruptions shorter than this are momentary (IEEE 1366: 5 minutes);
/// longer ones are sustained and count in SAIFI and SAIDI.
pub const SUSTAINED_S: f64 = 300.0;

/// The load before an interruption is its mean over this window: 15 minutes,
/// a whole number of the usual load cycles, so one reading's swing does not
/// set the energy not supplied.
pub const BASELINE_MS: i64 = 15 * 60_000;

/// How long a sample holds when its tag has no configured max interval
/// (the derived tags): the recorder's default, 900 s.
const DEFAULT_HOLD_S: f64 = 900.0;

/// Samples of each tag, oldest first, from the last one before
/// `from - BASELINE_MS` to `to`.
pub type SampleMap = HashMap<String, Vec<Sample>>;

/// Energy per panel, zone and microgrid unit.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Energy {
    pub panels: Vec<PanelEnergy>,
    pub units: Vec<UnitEnergy>,
    /// The microgrid's demand (`demand_tag`), kWh.
    pub demand_kwh: Option<f64>,
    /// PV and wind, kWh; all production (storage: discharge), kWh.
    pub renewable_kwh: f64,
    pub produced_kwh: f64,
    /// PV and wind over all production, 0..1.
    pub renewable_share: Option<f64>,
    /// Sum of the units' costs (the plant's cost model).
    pub cost: Option<f64>,
}

#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct PanelEnergy {
    pub id: String,
    pub name: String,
    /// The meter integrated; `None`: the panel has no power tag.
    pub meter: Option<String>,
    pub kwh: Option<f64>,
    /// Share of the period the meter's value was known, 0..1.
    pub coverage: f64,
    pub zones: Vec<ZoneEnergy>,
}

#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct ZoneEnergy {
    pub zone: u8,
    /// `None`: the zone has no meter of its own.
    pub meter: Option<String>,
    pub kwh: Option<f64>,
}

#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct UnitEnergy {
    pub id: String,
    pub name: String,
    pub kind: UnitKind,
    /// Produced (storage: discharged), kWh.
    pub kwh: f64,
    /// Storage: charged, kWh.
    pub charged_kwh: f64,
    /// Diesel: hours running, starts, fuel burnt (with a fuel curve).
    pub run_h: f64,
    pub starts: u32,
    pub fuel_l: Option<f64>,
    /// Storage: equivalent full cycles, (charged + discharged) / (2 × capacity).
    pub cycles: Option<f64>,
    pub cost: f64,
    pub coverage: f64,
}

/// One zone's loss of supply: its MCB, the main MCCB or the ELCB open.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Interruption {
    pub panel: String,
    pub zone: u8,
    /// ms since the epoch; `start` is the period's start when it began before.
    pub start: i64,
    pub began_before: bool,
    /// `None`: still out at the period's end.
    pub end: Option<i64>,
    /// Within the period, s.
    pub duration_s: f64,
    pub sustained: bool,
    /// Energy not supplied, kWh: the zone's load before the interruption
    /// over its duration (see [`outages`]); `None` where no load was known.
    pub ens_kwh: Option<f64>,
}

/// SAIDI/SAIFI-style figures of one panel, its zones standing for customers.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct PanelReliability {
    pub id: String,
    pub name: String,
    pub zones: u8,
    pub sustained: u32,
    pub momentary: u32,
    /// Sustained interruptions per zone.
    pub saifi: f64,
    /// Minutes of sustained interruption per zone.
    pub saidi_min: f64,
    /// Momentary interruptions per zone.
    pub maifi: f64,
    pub ens_kwh: f64,
    /// Share of the period every breaker state of the panel was known, 0..1.
    pub coverage: f64,
}

#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Outages {
    pub interruptions: Vec<Interruption>,
    pub panels: Vec<PanelReliability>,
    /// The loads before the interruptions still running at the end: the
    /// next day's baselines (see [`outages`]).
    #[serde(skip)]
    pub open_baselines: Baselines,
}

#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct TopAlarm {
    pub alarm_key: String,
    /// Empty for an alarm of the server's own (a panel sequence's).
    pub tag: String,
    /// Where it is, by its configured name (see [`alarm_place`]).
    pub place: String,
    pub priority: i32,
    pub message: String,
    pub count: u64,
}

/// Alarm figures of the period (annunciated activations, as ISA-18.2 counts
/// them).
#[derive(Debug, Clone, Serialize, PartialEq, Default)]
pub struct AlarmFigures {
    pub activations: u64,
    /// (priority, activations), highest priority first.
    pub by_priority: Vec<(i32, u64)>,
    /// The ten most frequent.
    pub top: Vec<TopAlarm>,
    /// Activations acknowledged within the period, and not.
    pub acknowledged: u64,
    pub unacknowledged: u64,
    /// Time to acknowledge, s.
    pub ack_mean_s: Option<f64>,
    pub ack_median_s: Option<f64>,
    pub ack_p90_s: Option<f64>,
    pub ack_max_s: Option<f64>,
}

/// kW per unit of a power tag's `units`, or `None` if it is not power.
fn kw_factor(units: &str) -> Option<f64> {
    match units.trim() {
        "kW" => Some(1.0),
        "W" => Some(0.001),
        "MW" => Some(1000.0),
        _ => None,
    }
}

/// Reads a plant's tags: power meters, hold times.
pub struct TagIndex<'a> {
    plant: &'a Plant,
}

impl<'a> TagIndex<'a> {
    pub fn new(plant: &'a Plant) -> Self {
        TagIndex { plant }
    }

    fn tag(&self, name: &str) -> Option<&'a gridscada_config::TagConfig> {
        self.plant.tag(name)
    }

    /// How long a sample of `name` holds: twice its max interval and 5
    /// minutes more. The recorder re-logs a flat value at the max interval on
    /// a timer that a busy server (or a replay's leaping clock) runs late, so
    /// only a longer silence means nothing was recorded (the server was off).
    pub fn hold_ms(&self, name: &str) -> i64 {
        let s = self
            .tag(name)
            .map(|t| *t.history.max_interval_s.get_ref())
            .filter(|s| s.is_finite() && *s > 0.0)
            .unwrap_or(DEFAULT_HOLD_S);
        ((2.0 * s + 300.0) * 1000.0).min(1.0e12) as i64
    }

    /// kW per unit of `name`'s value (1 when its units are not power).
    pub fn factor(&self, name: &str) -> f64 {
        self.tag(name)
            .and_then(|t| kw_factor(&t.units))
            .unwrap_or(1.0)
    }

    fn meters_under(&self, prefix: &str) -> impl Iterator<Item = &'a str> + '_ {
        let prefix = prefix.to_string();
        self.plant.tags.iter().filter_map(move |t| {
            let n = t.name.get_ref();
            (n.starts_with(&prefix)
                && !*t.writable.get_ref()
                && t.history.enabled
                && kw_factor(&t.units).is_some())
            .then_some(n.as_str())
        })
    }

    /// The panel's meter: its first power tag outside its zones.
    pub fn panel_meter(&self, panel: &PanelConfig) -> Option<&'a str> {
        let p = format!("{}.", panel.prefix.get_ref());
        let zone = format!("{p}Zone");
        self.meters_under(&p).find(|n| !n.starts_with(&zone))
    }

    /// Zone `z`'s meter (1-based), if it has one.
    pub fn zone_meter(&self, panel: &PanelConfig, z: u8) -> Option<&'a str> {
        self.meters_under(&format!("{}.Zone{z}.", panel.prefix.get_ref()))
            .next()
    }

    /// Every tag the report reads.
    pub fn report_tags(&self) -> Vec<String> {
        let mut t = Vec::new();
        for panel in &self.plant.panels {
            let io = panel.io();
            t.extend(self.panel_meter(panel).map(str::to_string));
            t.push(io.elcb_closed);
            t.push(io.mccb_closed);
            for z in 1..=*panel.zones.get_ref() {
                t.extend(self.zone_meter(panel, z).map(str::to_string));
                t.push(io.zone_closed[z as usize - 1].clone());
            }
        }
        if let Some(mg) = &self.plant.microgrid {
            t.push(mg.demand_tag.get_ref().clone());
            for u in &mg.units {
                let io = u.io();
                t.push(io.p_kw);
                if u.kind == UnitKind::Diesel {
                    t.push(io.running);
                }
            }
        }
        t.sort();
        t.dedup();
        t
    }

    /// The segments of `name` over `from..to`, scaled to kW for power.
    pub fn segs(&self, data: &SampleMap, name: &str, from: i64, to: i64) -> Vec<Segment> {
        let f = self.factor(name);
        let samples = data.get(name).map(Vec::as_slice).unwrap_or(&[]);
        let mut s = segments(samples, from, to, self.hold_ms(name));
        for g in &mut s {
            g.value = g.value.map(|v| v * f);
        }
        s
    }
}

fn coverage(i: &series::Integral, from: i64, to: i64) -> f64 {
    let span = (to - from) as f64 / 3_600_000.0;
    if span > 0.0 {
        (i.known_h / span).clamp(0.0, 1.0)
    } else {
        0.0
    }
}

/// Energy per panel, zone and unit over `from..to`.
pub fn energy(plant: &Plant, data: &SampleMap, from: i64, to: i64) -> Energy {
    let ix = TagIndex::new(plant);
    let panels = plant
        .panels
        .iter()
        .map(|panel| {
            let meter = ix.panel_meter(panel);
            let i = meter.map(|m| integrate(&ix.segs(data, m, from, to), f64::INFINITY));
            PanelEnergy {
                id: panel.id.get_ref().clone(),
                name: panel.name.clone(),
                meter: meter.map(str::to_string),
                kwh: i.filter(|i| i.known_h > 0.0).map(|i| i.net()),
                coverage: i.map_or(0.0, |i| coverage(&i, from, to)),
                zones: (1..=*panel.zones.get_ref())
                    .map(|z| {
                        let m = ix.zone_meter(panel, z);
                        ZoneEnergy {
                            zone: z,
                            meter: m.map(str::to_string),
                            kwh: m
                                .map(|m| integrate(&ix.segs(data, m, from, to), f64::INFINITY))
                                .filter(|i| i.known_h > 0.0)
                                .map(|i| i.net()),
                        }
                    })
                    .collect(),
            }
        })
        .collect();
    let Some(mg) = &plant.microgrid else {
        return Energy {
            panels,
            units: Vec::new(),
            demand_kwh: None,
            renewable_kwh: 0.0,
            produced_kwh: 0.0,
            renewable_share: None,
            cost: None,
        };
    };
    let units: Vec<UnitEnergy> = mg
        .units
        .iter()
        .map(|u| unit_energy(&ix, mg, u, data, from, to))
        .collect();
    let demand = integrate(
        &ix.segs(data, mg.demand_tag.get_ref(), from, to),
        f64::INFINITY,
    );
    let renewable_kwh: f64 = units
        .iter()
        .filter(|u| matches!(u.kind, UnitKind::Pv | UnitKind::Wind))
        .map(|u| u.kwh)
        .sum();
    let produced_kwh: f64 = units.iter().map(|u| u.kwh).sum();
    Energy {
        panels,
        demand_kwh: (demand.known_h > 0.0).then(|| demand.net()),
        renewable_kwh,
        produced_kwh,
        renewable_share: (produced_kwh > 0.0).then(|| renewable_kwh / produced_kwh),
        cost: (!units.is_empty()).then(|| units.iter().map(|u| u.cost).sum()),
        units,
    }
}

fn unit_energy(
    ix: &TagIndex<'_>,
    mg: &MicrogridConfig,
    u: &UnitConfig,
    data: &SampleMap,
    from: i64,
    to: i64,
) -> UnitEnergy {
    let io = u.io();
    let p_segs = ix.segs(data, &io.p_kw, from, to);
    let p = integrate(&p_segs, 0.0);
    let (kwh, charged_kwh) = match u.kind {
        UnitKind::Storage => (p.positive, p.negative),
        // A generator's small negative readings (auxiliaries) are not production.
        _ => (p.positive, 0.0),
    };
    let (run_h, starts) = if u.kind == UnitKind::Diesel {
        let r = integrate(&ix.segs(data, &io.running, from, to), 0.5);
        if r.known_h > 0.0 {
            (r.on_h, r.rises)
        } else {
            (p.on_h, p.rises)
        }
    } else {
        (0.0, 0)
    };
    let fuel_l = (u.kind == UnitKind::Diesel)
        .then_some(u.fuel_l_per_kwh)
        .flatten()
        .map(|l| l * kwh + u.fuel_no_load_l_per_h.unwrap_or(0.0) * run_h);
    let usage = UnitUsage {
        kwh,
        charged_kwh,
        run_h,
        starts: starts as f64,
    };
    UnitEnergy {
        id: u.id.get_ref().clone(),
        name: u.name.clone(),
        kind: u.kind,
        kwh,
        charged_kwh,
        run_h,
        starts,
        fuel_l,
        cycles: (u.kind == UnitKind::Storage && u.capacity_kwh > 0.0)
            .then(|| (kwh + charged_kwh) / (2.0 * u.capacity_kwh)),
        cost: mg.unit_cost(u, mg.fuel_price(None), &usage),
        coverage: coverage(&p, from, to),
    }
}

/// A zone's supply over `from..to`: 1 supplied, 0 not, unknown where a
/// breaker's state is unknown and none known is open.
fn supply(
    ix: &TagIndex<'_>,
    data: &SampleMap,
    panel: &PanelConfig,
    z: u8,
    from: i64,
    to: i64,
) -> Vec<Segment> {
    let io = panel.io();
    let parts = [
        ix.segs(data, &io.elcb_closed, from, to),
        ix.segs(data, &io.mccb_closed, from, to),
        ix.segs(data, &io.zone_closed[z as usize - 1], from, to),
    ];
    let refs: Vec<&[Segment]> = parts.iter().map(Vec::as_slice).collect();
    let mut out: Vec<Segment> = Vec::new();
    for w in edges(&refs, from, to).windows(2) {
        let states: Vec<Option<f64>> = parts.iter().map(|p| value_at(p, w[0])).collect();
        let value = if states.iter().any(|s| s.is_some_and(|v| v <= 0.5)) {
            Some(0.0)
        } else if states.iter().all(Option::is_some) {
            Some(1.0)
        } else {
            None
        };
        match out.last_mut() {
            Some(l) if l.value == value => l.end = w[1],
            _ => out.push(Segment {
                start: w[0],
                end: w[1],
                value,
            }),
        }
    }
    out
}

/// The load before an interruption still running at a day's end, by panel id
/// (from the panel's meter) or `PANEL/ZONE` (a zone's meter): the next day
/// starts with the zones already out, so its own window before shows no load.
pub type Baselines = HashMap<String, f64>;

/// Interruptions of every zone, and each panel's reliability figures.
///
/// Energy not supplied: with a zone meter, the zone's mean load over the
/// [`BASELINE_MS`] before the interruption times its duration. Without one,
/// from the panel's meter: when a panel goes from no zone out to some, its
/// mean load over the window before is the baseline; while zones are out,
/// the drop below it (baseline − load) is shared equally among the zones out.
/// Exact for one zone out; an estimate when several are out at once.
pub fn outages(
    plant: &Plant,
    data: &SampleMap,
    from: i64,
    to: i64,
    carried: &Baselines,
) -> Outages {
    let ix = TagIndex::new(plant);
    let mut interruptions = Vec::new();
    let mut open_baselines = Baselines::new();
    let mut panels = Vec::new();
    for panel in &plant.panels {
        let n = *panel.zones.get_ref();
        let zone_supply: Vec<Vec<Segment>> = (1..=n)
            .map(|z| supply(&ix, data, panel, z, from, to))
            .collect();
        let mut mine: Vec<Interruption> = Vec::new();
        for (zi, segs) in zone_supply.iter().enumerate() {
            let mut open: Option<Interruption> = None;
            for s in segs {
                match (s.value, open.as_mut()) {
                    (Some(v), None) if v < 0.5 => {
                        open = Some(Interruption {
                            panel: panel.id.get_ref().clone(),
                            zone: zi as u8 + 1,
                            start: s.start,
                            began_before: s.start == from,
                            end: None,
                            duration_s: 0.0,
                            sustained: false,
                            ens_kwh: None,
                        })
                    }
                    (Some(v), Some(i)) if v >= 0.5 => {
                        i.end = Some(s.start);
                        mine.push(open.take().expect("open"));
                    }
                    _ => {}
                }
            }
            mine.extend(open);
        }
        for i in &mut mine {
            i.duration_s = (i.end.unwrap_or(to) - i.start) as f64 / 1000.0;
            i.sustained = i.duration_s >= SUSTAINED_S;
        }
        let day = Day { from, to, carried };
        energy_not_supplied(
            &ix,
            data,
            panel,
            &zone_supply,
            &mut mine,
            day,
            &mut open_baselines,
        );
        let zones = f64::from(n.max(1));
        let sustained: Vec<&Interruption> = mine.iter().filter(|i| i.sustained).collect();
        let momentary = mine.len() - sustained.len();
        let known: f64 = zone_supply
            .iter()
            .map(|s| integrate(s, 0.5).known_h)
            .fold(f64::INFINITY, f64::min);
        panels.push(PanelReliability {
            id: panel.id.get_ref().clone(),
            name: panel.name.clone(),
            zones: n,
            sustained: sustained.len() as u32,
            momentary: momentary as u32,
            saifi: sustained.len() as f64 / zones,
            saidi_min: sustained.iter().map(|i| i.duration_s).sum::<f64>() / 60.0 / zones,
            maifi: momentary as f64 / zones,
            ens_kwh: mine.iter().filter_map(|i| i.ens_kwh).sum(),
            coverage: if known.is_finite() {
                (known * 3_600_000.0 / (to - from).max(1) as f64).clamp(0.0, 1.0)
            } else {
                1.0
            },
        });
        interruptions.extend(mine);
    }
    interruptions.sort_by(|a, b| (a.start, &a.panel, a.zone).cmp(&(b.start, &b.panel, b.zone)));
    Outages {
        interruptions,
        panels,
        open_baselines,
    }
}

/// The stretch of time computed (ms), with the baselines carried into it.
#[derive(Clone, Copy)]
struct Day<'a> {
    from: i64,
    to: i64,
    carried: &'a Baselines,
}

fn energy_not_supplied(
    ix: &TagIndex<'_>,
    data: &SampleMap,
    panel: &PanelConfig,
    zone_supply: &[Vec<Segment>],
    list: &mut [Interruption],
    Day { from, to, carried }: Day<'_>,
    open: &mut Baselines,
) {
    let id = panel.id.get_ref();
    let owner = |list: &[Interruption], zone: u8, t: i64| {
        list.iter()
            .position(|i| i.zone == zone && i.start <= t && i.end.is_none_or(|e| t < e))
    };
    // Zones with their own meter.
    let mut metered = vec![false; zone_supply.len()];
    for (zi, m) in metered.iter_mut().enumerate() {
        let z = zi as u8 + 1;
        let Some(meter) = ix.zone_meter(panel, z) else {
            continue;
        };
        *m = true;
        let key = format!("{id}/{z}");
        for i in list.iter_mut().filter(|i| i.zone == z) {
            let kw = match (i.began_before, carried.get(&key)) {
                (true, Some(&kw)) => Some(kw),
                _ => mean(&ix.segs(data, meter, i.start - BASELINE_MS, i.start)),
            };
            i.ens_kwh = kw.map(|kw| kw.max(0.0) * i.duration_s / 3600.0);
            if let (None, Some(kw)) = (i.end, kw) {
                open.insert(key.clone(), kw);
            }
        }
    }
    let Some(meter) = ix.panel_meter(panel) else {
        return;
    };
    let p = ix.segs(data, meter, from - BASELINE_MS, to);
    let mut series: Vec<&[Segment]> = zone_supply.iter().map(Vec::as_slice).collect();
    series.push(&p);
    let mut baseline: Option<f64> = None;
    let mut sums: Vec<Option<f64>> = vec![None; list.len()];
    for w in edges(&series, from, to).windows(2) {
        let out: Vec<u8> = zone_supply
            .iter()
            .enumerate()
            .filter(|(_, s)| value_at(s, w[0]).is_some_and(|v| v < 0.5))
            .map(|(zi, _)| zi as u8 + 1)
            .collect();
        if out.is_empty() {
            baseline = None;
            continue;
        }
        if baseline.is_none() && w[0] == from {
            baseline = carried.get(id).copied();
        }
        if baseline.is_none() {
            let before: Vec<Segment> = p
                .iter()
                .filter(|s| s.end > w[0] - BASELINE_MS && s.start < w[0])
                .map(|s| Segment {
                    start: s.start.max(w[0] - BASELINE_MS),
                    end: s.end.min(w[0]),
                    value: s.value,
                })
                .collect();
            baseline = mean(&before);
        }
        if let (true, Some(b)) = (w[1] == to, baseline) {
            // Still out at the end: the next day goes on from this baseline.
            open.insert(id.clone(), b);
        }
        let (Some(base), Some(now)) = (baseline, value_at(&p, w[0])) else {
            continue;
        };
        let unmetered: Vec<u8> = out
            .iter()
            .copied()
            .filter(|z| !metered[*z as usize - 1])
            .collect();
        if unmetered.is_empty() {
            continue;
        }
        let share =
            (base - now).max(0.0) * (w[1] - w[0]) as f64 / 3_600_000.0 / unmetered.len() as f64;
        for z in unmetered {
            if let Some(k) = owner(list, z, w[0]) {
                *sums[k].get_or_insert(0.0) += share;
            }
        }
    }
    for (i, s) in list.iter_mut().zip(sums) {
        if !metered[i.zone as usize - 1] {
            i.ens_kwh = s;
        }
    }
}

/// Where an alarm is, by its configured name: the panel or microgrid unit
/// whose prefix its tag is under (the longest such prefix), else the one
/// whose prefix is its selection (a panel sequence's alarms have no tag and
/// are grouped under their panel's prefix), else the selection itself (the
/// alarm screen's area).
pub fn alarm_place(plant: &Plant, tag: &str, selection: &str) -> String {
    let panels = plant
        .panels
        .iter()
        .map(|p| (p.prefix.get_ref().as_str(), p.name.as_str()));
    let units = plant
        .microgrid
        .iter()
        .flat_map(|mg| &mg.units)
        .map(|u| (u.prefix.get_ref().as_str(), u.name.as_str()));
    let owners: Vec<(&str, &str)> = panels.chain(units).collect();
    let tag_owner = owners
        .iter()
        .filter(|(prefix, _)| {
            tag.strip_prefix(prefix)
                .is_some_and(|rest| rest.starts_with('.'))
        })
        .max_by_key(|(prefix, _)| prefix.len());
    let selection_owner = || {
        owners
            .iter()
            .find(|(prefix, _)| prefix.eq_ignore_ascii_case(selection.trim()))
    };
    match tag_owner.or_else(selection_owner) {
        Some((_, name)) => name.to_string(),
        None => selection.trim().to_string(),
    }
}

/// Alarm figures from the transitions of the period, oldest first; the top
/// alarms are placed in `plant` ([`alarm_place`]).
pub fn alarm_figures(plant: &Plant, transitions: &[AlarmTransition]) -> AlarmFigures {
    let mut by_priority: BTreeMap<i32, u64> = BTreeMap::new();
    let mut per_alarm: HashMap<&str, TopAlarm> = HashMap::new();
    // Activations waiting for their acknowledgement, per alarm.
    let mut waiting: HashMap<&str, Vec<i64>> = HashMap::new();
    let mut ack_s: Vec<f64> = Vec::new();
    let mut activations = 0u64;
    for t in transitions {
        if t.activation {
            activations += 1;
            *by_priority.entry(t.priority).or_default() += 1;
            per_alarm
                .entry(&t.alarm_key)
                .or_insert_with(|| TopAlarm {
                    alarm_key: t.alarm_key.clone(),
                    tag: t.tag.clone(),
                    place: alarm_place(plant, &t.tag, &t.selection),
                    priority: t.priority,
                    message: t.message.clone(),
                    count: 0,
                })
                .count += 1;
            waiting
                .entry(&t.alarm_key)
                .or_default()
                .push(t.ts.as_millis());
        } else if t.cause.as_deref() == Some("ack") {
            // One acknowledgement acknowledges every activation before it.
            for at in waiting.remove(t.alarm_key.as_str()).unwrap_or_default() {
                ack_s.push((t.ts.as_millis() - at).max(0) as f64 / 1000.0);
            }
        }
    }
    let mut top: Vec<TopAlarm> = per_alarm.into_values().collect();
    top.sort_by(|a, b| b.count.cmp(&a.count).then(a.alarm_key.cmp(&b.alarm_key)));
    top.truncate(10);
    ack_s.sort_by(f64::total_cmp);
    let pct = |q: f64| -> Option<f64> {
        (!ack_s.is_empty()).then(|| ack_s[((ack_s.len() - 1) as f64 * q).round() as usize])
    };
    AlarmFigures {
        activations,
        by_priority: by_priority.into_iter().rev().collect(),
        top,
        acknowledged: ack_s.len() as u64,
        unacknowledged: waiting.values().map(|v| v.len() as u64).sum(),
        ack_mean_s: (!ack_s.is_empty()).then(|| ack_s.iter().sum::<f64>() / ack_s.len() as f64),
        ack_median_s: pct(0.5),
        ack_p90_s: pct(0.9),
        ack_max_s: ack_s.last().copied(),
    }
}
