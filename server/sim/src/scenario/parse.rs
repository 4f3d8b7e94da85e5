//! Reading scenario files: TOML syntax errors, then each section and each
//! `[[event]]` / `[[expect]]` entry deserialized on its own (so one bad
//! entry does not hide the others), then the meaning checks, every problem
//! with file, line and column, as `gridscada check` reports configuration.

use std::path::{Path, PathBuf};
use std::time::Duration;

use gridscada_config::{Diagnostic, PanelMode, Plant, SourceFile, UnitKind};
use serde::de::DeserializeOwned;
use serde::Deserialize;
use serde_spanned::Spanned;
use toml::de::{DeTable, DeValue, ValueDeserializer};

use super::expect::{Bound, ExpectKind, ExpectValue, Expectation};
use super::series::{parse_csv, Interpolate, Series};
use super::time::{parse_start, TimeValue};
use super::{Action, Event, Initial, InitialPanel, InitialUnit, Profiles, Scenario, ZoneProfile};
use crate::FaultKind;

/// Figures of the whole run that `[[expect]] figure = ...` may name
/// (documented in docs/SCENARIOS.md).
pub const FIGURE_NAMES: &[&str] = &[
    "demand_kwh",
    "served_kwh",
    "unserved_kwh",
    "curtailed_kwh",
    "surplus_kwh",
    "pv_kwh",
    "wind_kwh",
    "diesel_kwh",
    "diesel_fuel_l",
    "diesel_starts",
    "diesel_runtime_h",
    "storage_charged_kwh",
    "storage_discharged_kwh",
    "storage_throughput_kwh",
    "soc_min_pct",
    "soc_end_pct",
    "fuel_cost",
    "total_cost",
    "rule_total_cost",
    "cost_ratio",
    "dispatch_shed_kwh",
    "dispatch_fallback_periods",
    "alarm_activations",
    "alarm_active_end",
    "alarm_unacked_end",
    "alarm_floods",
    "alarm_max_per_10min",
    "alarm_avg_per_10min",
    "alarm_percent_in_flood",
    "alarm_chattering",
    "fault_sequences",
    "poll_timeouts",
    "historian_dropped",
    "wall_s",
    "speedup",
];

/// Figures per panel, named `<panel id>.<figure>` (e.g. `ss1.restore_s_max`).
pub const PANEL_FIGURE_NAMES: &[&str] = &[
    "sequences",
    "restore_s_max",
    "restore_s_last",
    "switching_ops",
    "reenergisations",
    "elcb_trips",
    "lockout",
    "zones_closed_end",
];

/// A name the scenario uses, kept to be checked against the plant.
#[derive(Debug, Clone)]
pub(crate) struct NameRef {
    kind: RefKind,
    name: String,
    at: (usize, usize),
}

#[derive(Debug, Clone, PartialEq)]
enum RefKind {
    Panel,
    /// Zone number of the named panel; whether zone 0 (busbar) is allowed.
    Zone(u8, bool),
    Breaker(String),
    Unit,
    StorageUnit,
    Device,
    Tag,
    Figure,
    /// A microgrid input: the plant must have a microgrid.
    Microgrid,
}

/// Reads a scenario and the CSV files it names.
pub fn load_path(path: &Path) -> Result<Scenario, Vec<Diagnostic>> {
    let text = std::fs::read_to_string(path).map_err(|e| {
        vec![Diagnostic {
            file: path.to_path_buf(),
            line: 0,
            column: 0,
            message: format!("cannot read the scenario: {e}"),
        }]
    })?;
    let file = SourceFile::new(path, text);
    parse(&file, &mut |p| std::fs::read_to_string(p))
}

/// Parses a scenario; `read` reads a CSV file (paths are resolved against
/// the scenario's folder before it is called).
pub fn parse(
    file: &SourceFile,
    read: &mut dyn FnMut(&Path) -> std::io::Result<String>,
) -> Result<Scenario, Vec<Diagnostic>> {
    let mut p = Parser {
        file,
        read,
        diags: Vec::new(),
        refs: Vec::new(),
        base: file
            .path()
            .parent()
            .map(Path::to_path_buf)
            .unwrap_or_default(),
        stream: 0,
    };
    let (root, errors) = DeTable::parse_recoverable(&file.text);
    if !errors.is_empty() {
        return Err(errors
            .iter()
            .map(|e| locate(file, e, "TOML syntax error: "))
            .collect());
    }
    let root = root.into_inner();
    let mut header = Header::default();
    let mut initial = Initial::default();
    let mut profiles = Profiles::default();
    let mut events = Vec::new();
    let mut expectations = Vec::new();
    let mut seen_duration = None;
    for (key, value) in root.iter() {
        let k = key.get_ref().as_ref();
        match k {
            "name" => header.name = p.de(value, "name"),
            "description" => header.description = p.de(value, "description"),
            "duration" => {
                seen_duration = Some(value.span());
                header.duration = p.time(value, "duration")
            }
            "step" => header.step = p.time(value, "step"),
            "sample" => header.sample = p.time(value, "sample"),
            "warmup" => {
                header.warmup = p.time(value, "warmup");
                if header.warmup.is_some_and(|w| w > Duration::from_secs(3600)) {
                    p.err(value.span(), "warmup must be at most 1 h");
                }
            }
            "start" => {
                if let Some(s) = p.de::<String>(value, "start") {
                    match parse_start(&s) {
                        Ok(t) => header.start = Some(t),
                        Err(e) => p.err(value.span(), format!("start: {e}")),
                    }
                }
            }
            "seed" => header.seed = p.de(value, "seed"),
            "plant" => header.plant = p.de::<String>(value, "plant").map(PathBuf::from),
            "fuel_price_per_l" => header.fuel_price = p.de(value, "fuel_price_per_l"),
            "compare_rule" => header.compare_rule = p.de(value, "compare_rule"),
            "initial" => {
                if let Some(raw) = p.de::<RawInitial>(value, "[initial]") {
                    initial = p.initial(raw);
                }
            }
            "profile" => profiles = p.profiles(value),
            "event" => {
                for (raw, span) in p.each::<RawEvent>(value, "event") {
                    if let Some(e) = p.event(raw, span) {
                        events.push(e);
                    }
                }
            }
            "expect" => {
                for (raw, span) in p.each::<RawExpect>(value, "expect") {
                    if let Some(e) = p.expect(raw, span) {
                        expectations.push(e);
                    }
                }
            }
            other => p.err(
                key.span(),
                format!(
                    "unknown key '{other}'; expected one of name, description, duration, step, start, seed, sample, warmup, plant, fuel_price_per_l, compare_rule, initial, profile, event, expect"
                ),
            ),
        }
    }
    let name = header.name.unwrap_or_default();
    if name.trim().is_empty() && p.diags.is_empty() {
        p.err(0..0, "missing 'name': give the scenario a name");
    }
    let Some(duration) = header.duration else {
        if seen_duration.is_none() {
            p.err(0..0, "missing 'duration' (e.g. duration = \"24:00:00\")");
        }
        return Err(p.diags);
    };
    if duration.is_zero() {
        p.err(
            seen_duration.unwrap_or(0..0),
            "duration must be longer than zero",
        );
    }
    let step = header.step.unwrap_or(Duration::from_secs(1));
    if step < Duration::from_millis(100) || step > Duration::from_secs(3600) {
        p.err(0..0, "step must be between 100 ms and 1 h");
    }
    for e in &events {
        if e.at > duration {
            p.diags.push(Diagnostic {
                file: file.path.clone(),
                line: e.line,
                column: 1,
                message: format!(
                    "event at {} is after the end of the scenario ({})",
                    super::time::format_offset(e.at),
                    super::time::format_offset(duration)
                ),
            });
        }
    }
    for x in &expectations {
        if x.due().is_some_and(|at| at > duration) {
            p.diags.push(Diagnostic {
                file: file.path.clone(),
                line: x.line,
                column: 1,
                message: "expectation is after the end of the scenario".into(),
            });
        }
    }
    let fuel_price = header.fuel_price.unwrap_or(1.5);
    if !(fuel_price.is_finite() && fuel_price >= 0.0) {
        p.err(0..0, "fuel_price_per_l must be a number >= 0");
    }
    // Pick up profile CSV problems etc. before returning.
    if !p.diags.is_empty() {
        return Err(p.diags);
    }
    events.sort_by_key(|e| e.at); // stable: file order within one time
    let sample = header.sample.unwrap_or_else(|| {
        // About 1500 points per plot, never finer than the step.
        let s = Duration::from_secs((duration.as_secs() / 1500).max(1));
        s.max(step)
    });
    let plant = header.plant.map(|rel| p.base.join(rel));
    Ok(Scenario {
        path: file.path.clone(),
        name,
        description: header.description.unwrap_or_default(),
        duration,
        step,
        start: header
            .start
            .unwrap_or(gridscada_tagdb::Timestamp::from_millis(1_718_928_000_000)),
        seed: header.seed.unwrap_or(0),
        plant,
        fuel_price_per_l: fuel_price,
        compare_rule: header.compare_rule.unwrap_or(true),
        sample,
        warmup: header.warmup.unwrap_or(Duration::from_secs(60)),
        initial,
        profiles,
        events,
        expectations,
        refs: p.refs,
    })
}

#[derive(Default)]
struct Header {
    name: Option<String>,
    description: Option<String>,
    duration: Option<Duration>,
    step: Option<Duration>,
    sample: Option<Duration>,
    warmup: Option<Duration>,
    start: Option<gridscada_tagdb::Timestamp>,
    seed: Option<u64>,
    plant: Option<PathBuf>,
    fuel_price: Option<f64>,
    compare_rule: Option<bool>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawInitial {
    #[serde(default)]
    unit: Vec<RawInitUnit>,
    #[serde(default)]
    panel: Vec<RawInitPanel>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawInitUnit {
    id: Spanned<String>,
    soc_pct: Option<Spanned<f64>>,
    #[serde(default)]
    tripped: bool,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawInitPanel {
    id: Spanned<String>,
    mode: Option<PanelMode>,
    #[serde(default)]
    door_open: bool,
    #[serde(default)]
    zone_kw: Vec<Spanned<f64>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSeries {
    csv: Option<Spanned<String>>,
    column: Option<String>,
    points: Option<Vec<(TimeValue, f64)>>,
    constant: Option<f64>,
    interpolate: Option<Interp>,
    scale: Option<f64>,
    noise: Option<f64>,
    // Zone profiles only.
    panel: Option<Spanned<String>>,
    zone: Option<Spanned<u8>>,
    pf: Option<f64>,
}

#[derive(Deserialize, Clone, Copy)]
#[serde(rename_all = "lowercase")]
enum Interp {
    Linear,
    Step,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawEvent {
    at: Spanned<TimeValue>,
    action: Spanned<String>,
    panel: Option<Spanned<String>>,
    zone: Option<Spanned<u8>>,
    kind: Option<FaultKind>,
    mode: Option<PanelMode>,
    breaker: Option<Spanned<String>>,
    close: Option<bool>,
    device: Option<Spanned<String>>,
    unit: Option<Spanned<String>>,
    soc_pct: Option<f64>,
    user: Option<String>,
    #[allow(dead_code)] // A comment for the reader of the file.
    note: Option<String>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawExpect {
    at: Option<Spanned<TimeValue>>,
    tag: Option<Spanned<String>>,
    figure: Option<Spanned<String>>,
    value: Option<ExpectValueRaw>,
    tolerance: Option<f64>,
    min: Option<f64>,
    max: Option<f64>,
    note: Option<String>,
    known_failure: Option<String>,
}

#[derive(Deserialize)]
#[serde(untagged)]
enum ExpectValueRaw {
    Bool(bool),
    Number(f64),
    Text(String),
}

struct Parser<'a> {
    file: &'a SourceFile,
    read: &'a mut dyn FnMut(&Path) -> std::io::Result<String>,
    diags: Vec<Diagnostic>,
    refs: Vec<NameRef>,
    base: PathBuf,
    stream: u64,
}

fn locate(file: &SourceFile, e: &toml::de::Error, prefix: &str) -> Diagnostic {
    let message = format!("{prefix}{}", e.message().trim());
    match e.span() {
        Some(span) => file.error_at(span, message),
        None => file.error(message),
    }
}

impl Parser<'_> {
    fn err(&mut self, span: std::ops::Range<usize>, msg: impl Into<String>) {
        self.diags.push(self.file.error_at(span, msg));
    }

    fn pos(&self, span: std::ops::Range<usize>) -> (usize, usize) {
        self.file.line_col(span.start)
    }

    fn name_ref(&mut self, kind: RefKind, name: &Spanned<String>) {
        let at = self.pos(name.span());
        self.refs.push(NameRef {
            kind,
            name: name.get_ref().clone(),
            at,
        });
    }

    fn de<T: DeserializeOwned>(&mut self, value: &Spanned<DeValue<'_>>, what: &str) -> Option<T> {
        match T::deserialize(ValueDeserializer::from(value.clone())) {
            Ok(v) => Some(v),
            Err(e) => {
                let mut d = locate(self.file, &e, &format!("{what}: "));
                if e.span().is_none() {
                    let (line, column) = self.file.line_col(value.span().start);
                    d.line = line;
                    d.column = column;
                }
                self.diags.push(d);
                None
            }
        }
    }

    fn time(&mut self, value: &Spanned<DeValue<'_>>, what: &str) -> Option<Duration> {
        let t: TimeValue = self.de(value, what)?;
        match t.to_duration() {
            Ok(d) => Some(d),
            Err(e) => {
                self.err(value.span(), format!("{what}: {e}"));
                None
            }
        }
    }

    fn spanned_time(&mut self, t: &Spanned<TimeValue>, what: &str) -> Option<Duration> {
        match t.get_ref().to_duration() {
            Ok(d) => Some(d),
            Err(e) => {
                self.err(t.span(), format!("{what}: {e}"));
                None
            }
        }
    }

    /// Each table of an array of tables, deserialized on its own.
    fn each<T: DeserializeOwned>(
        &mut self,
        value: &Spanned<DeValue<'_>>,
        section: &str,
    ) -> Vec<(T, std::ops::Range<usize>)> {
        let Some(array) = value.get_ref().as_array() else {
            self.err(
                value.span(),
                format!("'{section}' must be an array of tables ([[{section}]])"),
            );
            return vec![];
        };
        let mut out = Vec::new();
        for (i, entry) in array.iter().enumerate() {
            if let Some(v) = self.de(entry, &format!("{section} #{}", i + 1)) {
                out.push((v, entry.span()));
            }
        }
        out
    }

    fn initial(&mut self, raw: RawInitial) -> Initial {
        let mut out = Initial::default();
        for u in raw.unit {
            if let Some(soc) = &u.soc_pct {
                if !(0.0..=100.0).contains(soc.get_ref()) {
                    self.err(soc.span(), "soc_pct must be within 0..=100");
                }
                self.name_ref(RefKind::StorageUnit, &u.id);
            } else {
                self.name_ref(RefKind::Unit, &u.id);
            }
            out.units.push(InitialUnit {
                id: u.id.get_ref().clone(),
                soc_pct: u.soc_pct.map(|s| *s.get_ref()),
                tripped: u.tripped,
            });
        }
        for pnl in raw.panel {
            self.name_ref(RefKind::Panel, &pnl.id);
            for (i, kw) in pnl.zone_kw.iter().enumerate() {
                if !(kw.get_ref().is_finite() && *kw.get_ref() >= 0.0) {
                    self.err(kw.span(), "zone loads must be >= 0 kW");
                }
                let z = Spanned::new(pnl.id.span(), pnl.id.get_ref().clone());
                self.refs.push(NameRef {
                    kind: RefKind::Zone((i + 1).min(255) as u8, false),
                    name: z.get_ref().clone(),
                    at: self.pos(kw.span()),
                });
            }
            out.panels.push(InitialPanel {
                id: pnl.id.get_ref().clone(),
                mode: pnl.mode,
                door_open: pnl.door_open,
                zone_kw: pnl.zone_kw.iter().map(|k| *k.get_ref()).collect(),
            });
        }
        out
    }

    fn profiles(&mut self, value: &Spanned<DeValue<'_>>) -> Profiles {
        let mut out = Profiles::default();
        let Some(table) = value.get_ref().as_table() else {
            self.err(
                value.span(),
                "'profile' must be a table ([profile.demand] ...)",
            );
            return out;
        };
        for (key, v) in table.iter() {
            let k = key.get_ref().as_ref();
            let slot = match k {
                "irradiance" => &mut out.irradiance,
                "pv_available" => &mut out.pv_available,
                "wind_speed" => &mut out.wind_speed,
                "demand" => &mut out.demand,
                "zone" => {
                    for (raw, span) in self.each::<RawSeries>(v, "profile.zone") {
                        if let Some(z) = self.zone_profile(raw, span) {
                            out.zones.push(z);
                        }
                    }
                    continue;
                }
                other => {
                    self.err(
                        key.span(),
                        format!("unknown profile '{other}'; expected irradiance, pv_available, wind_speed, demand or [[profile.zone]]"),
                    );
                    continue;
                }
            };
            let label = format!("profile.{k}");
            let Some(raw) = self.de::<RawSeries>(v, &label) else {
                continue;
            };
            if raw.panel.is_some() || raw.zone.is_some() || raw.pf.is_some() {
                self.err(
                    v.span(),
                    format!("{label}: panel, zone and pf belong in [[profile.zone]]"),
                );
                continue;
            }
            self.refs.push(NameRef {
                kind: RefKind::Microgrid,
                name: k.to_string(),
                at: self.pos(key.span()),
            });
            *slot = self.series(raw, v.span(), &label);
        }
        if out.irradiance.is_some() && out.pv_available.is_some() {
            self.err(
                value.span(),
                "give either profile.irradiance or profile.pv_available, not both",
            );
        }
        out
    }

    fn zone_profile(
        &mut self,
        raw: RawSeries,
        span: std::ops::Range<usize>,
    ) -> Option<ZoneProfile> {
        let (Some(panel), Some(zone)) = (raw.panel.clone(), raw.zone.clone()) else {
            self.err(span, "[[profile.zone]] needs panel and zone");
            return None;
        };
        self.name_ref(RefKind::Panel, &panel);
        self.refs.push(NameRef {
            kind: RefKind::Zone(*zone.get_ref(), false),
            name: panel.get_ref().clone(),
            at: self.pos(zone.span()),
        });
        let pf = raw.pf.unwrap_or(0.9);
        if !(pf > 0.0 && pf <= 1.0) {
            self.err(span.clone(), "pf must be in (0, 1]");
        }
        let label = format!("zone profile {} zone {}", panel.get_ref(), zone.get_ref());
        let kw = self.series(raw, span, &label)?;
        Some(ZoneProfile {
            panel: panel.into_inner(),
            zone: zone.into_inner(),
            pf,
            kw,
        })
    }

    fn series(
        &mut self,
        raw: RawSeries,
        span: std::ops::Range<usize>,
        label: &str,
    ) -> Option<Series> {
        self.stream += 1;
        let sources = [
            raw.csv.is_some(),
            raw.points.is_some(),
            raw.constant.is_some(),
        ]
        .iter()
        .filter(|b| **b)
        .count();
        if sources != 1 {
            self.err(
                span,
                format!("{label}: give exactly one of csv, points or constant"),
            );
            return None;
        }
        let scale = raw.scale.unwrap_or(1.0);
        let noise = raw.noise.unwrap_or(0.0);
        if !(scale.is_finite() && (0.0..=1.0).contains(&noise)) {
            self.err(
                span.clone(),
                format!("{label}: scale must be finite and noise within 0..=1"),
            );
            return None;
        }
        let interpolate = match raw.interpolate {
            Some(Interp::Step) => Interpolate::Step,
            _ => Interpolate::Linear,
        };
        let (points, source) = if let Some(c) = raw.constant {
            if !c.is_finite() {
                self.err(span, format!("{label}: constant must be finite"));
                return None;
            }
            (vec![(Duration::ZERO, c)], format!("constant {c}"))
        } else if let Some(pts) = raw.points {
            let mut out = Vec::with_capacity(pts.len());
            for (t, v) in pts {
                match t.to_duration() {
                    Ok(d) => {
                        if out.last().is_some_and(|(p, _): &(Duration, f64)| *p >= d) {
                            self.err(
                                span.clone(),
                                format!("{label}: points must be in increasing time order"),
                            );
                            return None;
                        }
                        out.push((d, v));
                    }
                    Err(e) => {
                        self.err(span.clone(), format!("{label}: {e}"));
                        return None;
                    }
                }
            }
            if out.is_empty() {
                self.err(span, format!("{label}: points is empty"));
                return None;
            }
            (out, "points".to_string())
        } else {
            let csv = raw.csv?;
            let path = self.base.join(csv.get_ref());
            return self.csv_series(
                &csv,
                &path,
                raw.column.as_deref(),
                interpolate,
                scale,
                noise,
                label,
            );
        };
        Some(Series {
            points,
            interpolate,
            scale,
            noise,
            stream: self.stream,
            source,
        })
    }

    #[allow(clippy::too_many_arguments)]
    fn csv_series(
        &mut self,
        csv: &Spanned<String>,
        path: &Path,
        column: Option<&str>,
        interpolate: Interpolate,
        scale: f64,
        noise: f64,
        label: &str,
    ) -> Option<Series> {
        let text = match (self.read)(path) {
            Ok(t) => t,
            Err(e) => {
                self.err(
                    csv.span(),
                    format!("{label}: cannot read {}: {e}", path.display()),
                );
                return None;
            }
        };
        let f = SourceFile::new(path, text);
        let table = match parse_csv(&f) {
            Ok(t) => t,
            Err(d) => {
                self.diags.extend(d);
                return None;
            }
        };
        match table.column(column) {
            Ok(points) => Some(Series {
                points,
                interpolate,
                scale,
                noise,
                stream: self.stream,
                source: format!(
                    "{}:{}",
                    csv.get_ref(),
                    column.unwrap_or(table.columns.get(1).map(String::as_str).unwrap_or(""))
                ),
            }),
            Err(e) => {
                self.err(csv.span(), format!("{label}: {e}"));
                None
            }
        }
    }

    fn event(&mut self, raw: RawEvent, span: std::ops::Range<usize>) -> Option<Event> {
        let line = self.pos(span.clone()).0;
        let at = self.spanned_time(&raw.at, "at");
        let action_name = raw.action.get_ref().clone();
        // Which fields each action takes.
        let allowed: &[&str] = match action_name.as_str() {
            "fault" => &["panel", "zone", "kind"],
            "repair" => &["panel", "zone"],
            "mode" => &["panel", "mode", "user"],
            "reset" => &["panel", "user"],
            "breaker" => &["panel", "breaker", "close", "user"],
            "acknowledge" => &["user"],
            "comm_loss" | "comm_return" => &["device"],
            "trip" | "unit_reset" => &["unit"],
            "set_soc" => &["unit", "soc_pct"],
            other => {
                self.err(
                    raw.action.span(),
                    format!("unknown action '{other}'; expected fault, repair, mode, reset, breaker, acknowledge, comm_loss, comm_return, trip, unit_reset or set_soc"),
                );
                return None;
            }
        };
        let given: Vec<(&str, bool)> = vec![
            ("panel", raw.panel.is_some()),
            ("zone", raw.zone.is_some()),
            ("kind", raw.kind.is_some()),
            ("mode", raw.mode.is_some()),
            ("breaker", raw.breaker.is_some()),
            ("close", raw.close.is_some()),
            ("device", raw.device.is_some()),
            ("unit", raw.unit.is_some()),
            ("soc_pct", raw.soc_pct.is_some()),
            ("user", raw.user.is_some()),
        ];
        let mut ok = true;
        for (field, present) in &given {
            if *present && !allowed.contains(field) {
                self.err(
                    span.clone(),
                    format!("action '{action_name}' takes no '{field}'"),
                );
                ok = false;
            }
        }
        let mut need = |p: &mut Self, field: &str, present: bool| {
            if !present {
                p.err(
                    span.clone(),
                    format!("action '{action_name}' needs '{field}'"),
                );
                ok = false;
            }
        };
        let required: &[&str] = match action_name.as_str() {
            "fault" | "repair" => &["panel", "zone"],
            "mode" => &["panel", "mode"],
            "reset" => &["panel"],
            "breaker" => &["panel", "breaker", "close"],
            "comm_loss" | "comm_return" => &["device"],
            "trip" | "unit_reset" => &["unit"],
            "set_soc" => &["unit", "soc_pct"],
            _ => &[],
        };
        for f in required {
            let present = given.iter().any(|(g, p)| g == f && *p);
            need(self, f, present);
        }
        if !ok {
            return None;
        }
        let at = at?;
        let panel = raw.panel.clone();
        if let Some(p) = &panel {
            self.name_ref(RefKind::Panel, p);
        }
        let zone = |p: &mut Self, allow_zero: bool| -> u8 {
            let z = raw.zone.clone().expect("checked above");
            p.refs.push(NameRef {
                kind: RefKind::Zone(*z.get_ref(), allow_zero),
                name: panel
                    .as_ref()
                    .map(|x| x.get_ref().clone())
                    .unwrap_or_default(),
                at: p.pos(z.span()),
            });
            z.into_inner()
        };
        let name = |s: &Option<Spanned<String>>| {
            s.as_ref().map(|x| x.get_ref().clone()).unwrap_or_default()
        };
        let action = match action_name.as_str() {
            "fault" => Action::Fault {
                panel: name(&raw.panel),
                zone: zone(self, true),
                kind: raw.kind.unwrap_or(FaultKind::Permanent),
            },
            "repair" => Action::Repair {
                panel: name(&raw.panel),
                zone: zone(self, true),
            },
            "mode" => Action::Mode {
                panel: name(&raw.panel),
                mode: raw.mode?,
            },
            "reset" => Action::Reset {
                panel: name(&raw.panel),
            },
            "breaker" => {
                let b = raw.breaker.clone()?;
                self.refs.push(NameRef {
                    kind: RefKind::Breaker(b.get_ref().clone()),
                    name: name(&raw.panel),
                    at: self.pos(b.span()),
                });
                Action::Breaker {
                    panel: name(&raw.panel),
                    breaker: b.into_inner(),
                    close: raw.close?,
                }
            }
            "acknowledge" => Action::Acknowledge {
                user: raw.user.clone().unwrap_or_else(|| "operator".into()),
            },
            "comm_loss" | "comm_return" => {
                let d = raw.device.clone()?;
                self.name_ref(RefKind::Device, &d);
                if action_name == "comm_loss" {
                    Action::CommLoss {
                        device: d.into_inner(),
                    }
                } else {
                    Action::CommReturn {
                        device: d.into_inner(),
                    }
                }
            }
            "trip" | "unit_reset" | "set_soc" => {
                let u = raw.unit.clone()?;
                let kind = if action_name == "set_soc" {
                    RefKind::StorageUnit
                } else {
                    RefKind::Unit
                };
                self.name_ref(kind, &u);
                match action_name.as_str() {
                    "trip" => Action::Trip {
                        unit: u.into_inner(),
                    },
                    "unit_reset" => Action::UnitReset {
                        unit: u.into_inner(),
                    },
                    _ => {
                        let soc = raw.soc_pct?;
                        if !(0.0..=100.0).contains(&soc) {
                            self.err(span, "soc_pct must be within 0..=100");
                            return None;
                        }
                        Action::SetSoc {
                            unit: u.into_inner(),
                            soc_pct: soc,
                        }
                    }
                }
            }
            _ => return None,
        };
        Some(Event { at, action, line })
    }

    fn expect(&mut self, raw: RawExpect, span: std::ops::Range<usize>) -> Option<Expectation> {
        let line = self.pos(span.clone()).0;
        let value = raw.value.map(|v| match v {
            ExpectValueRaw::Bool(b) => ExpectValue::Bool(b),
            ExpectValueRaw::Number(n) => ExpectValue::Number(n),
            ExpectValueRaw::Text(t) => ExpectValue::Text(t),
        });
        match (&raw.tag, &raw.figure) {
            (Some(tag), None) => {
                if raw.min.is_some() || raw.max.is_some() {
                    self.err(
                        span.clone(),
                        "a tag expectation takes value (and tolerance), not min/max",
                    );
                    return None;
                }
                let Some(at) = &raw.at else {
                    self.err(span, "a tag expectation needs 'at' (when to look)");
                    return None;
                };
                let at = self.spanned_time(at, "at")?;
                let Some(value) = value else {
                    self.err(span, "a tag expectation needs 'value'");
                    return None;
                };
                let tolerance = raw.tolerance.unwrap_or(0.0);
                if !(tolerance.is_finite() && tolerance >= 0.0) {
                    self.err(span, "tolerance must be >= 0");
                    return None;
                }
                self.name_ref(RefKind::Tag, tag);
                let description = raw.note.unwrap_or_else(|| {
                    format!(
                        "{} = {value} at {}",
                        tag.get_ref(),
                        super::time::format_offset(at)
                    )
                });
                Some(Expectation {
                    kind: ExpectKind::Tag {
                        at,
                        tag: tag.get_ref().clone(),
                        value,
                        tolerance,
                    },
                    line,
                    description,
                    known_failure: raw.known_failure.clone(),
                })
            }
            (None, Some(fig)) => {
                if raw.at.is_some() {
                    self.err(
                        span,
                        "a figure expectation is judged at the end of the run; it takes no 'at'",
                    );
                    return None;
                }
                let bound = match (value, raw.min, raw.max) {
                    (Some(ExpectValue::Number(v)), None, None) => {
                        let tol = raw.tolerance.unwrap_or(0.0).abs();
                        Bound {
                            min: Some(v - tol),
                            max: Some(v + tol),
                        }
                    }
                    (None, min, max) if min.is_some() || max.is_some() => {
                        if raw.tolerance.is_some() {
                            self.err(span, "tolerance goes with value, not with min/max");
                            return None;
                        }
                        Bound { min, max }
                    }
                    _ => {
                        self.err(span, "a figure expectation needs a numeric 'value' (with optional 'tolerance'), or 'min' and/or 'max'");
                        return None;
                    }
                };
                self.name_ref(RefKind::Figure, fig);
                let description = raw
                    .note
                    .unwrap_or_else(|| format!("{} {bound}", fig.get_ref()));
                Some(Expectation {
                    kind: ExpectKind::Figure {
                        name: fig.get_ref().clone(),
                        bound,
                    },
                    line,
                    description,
                    known_failure: raw.known_failure.clone(),
                })
            }
            _ => {
                self.err(span, "an expectation needs either 'tag' (with at and value) or 'figure' (with value, min or max)");
                None
            }
        }
    }
}

impl Scenario {
    /// Checks every panel, zone, breaker, unit, device, tag and figure the
    /// scenario names against `plant`; `tag_exists` knows the tag database
    /// (which also holds derived tags such as `SS1.Seq.Step`).
    pub fn check_against(
        &self,
        plant: &Plant,
        tag_exists: &dyn Fn(&str) -> bool,
    ) -> Vec<Diagnostic> {
        let mut out = Vec::new();
        let mut err = |at: (usize, usize), message: String| {
            out.push(Diagnostic {
                file: self.path.clone(),
                line: at.0,
                column: at.1,
                message,
            })
        };
        let panel = |name: &str| {
            plant
                .panels
                .iter()
                .find(|p| p.id.get_ref() == name || p.prefix.get_ref() == name)
        };
        let panel_ids: Vec<String> = plant
            .panels
            .iter()
            .map(|p| p.id.get_ref().clone())
            .collect();
        let units: Vec<(String, String, UnitKind)> = plant
            .microgrid
            .as_ref()
            .map(|m| {
                m.units
                    .iter()
                    .map(|u| (u.id.get_ref().clone(), u.prefix.get_ref().clone(), u.kind))
                    .collect()
            })
            .unwrap_or_default();
        let mut seen_microgrid = false;
        for r in &self.refs {
            match &r.kind {
                RefKind::Panel => {
                    if panel(&r.name).is_none() {
                        err(
                            r.at,
                            format!(
                                "the plant has no panel '{}'; it has {}",
                                r.name,
                                panel_ids.join(", ")
                            ),
                        );
                    }
                }
                RefKind::Zone(z, allow_zero) => {
                    if let Some(p) = panel(&r.name) {
                        let n = *p.zones.get_ref();
                        if *z > n || (*z == 0 && !allow_zero) {
                            let lo = if *allow_zero { 0 } else { 1 };
                            err(
                                r.at,
                                format!(
                                    "panel '{}' has zones {lo}..={n}; there is no zone {z}",
                                    r.name
                                ),
                            );
                        }
                    }
                }
                RefKind::Breaker(b) => {
                    if let Some(p) = panel(&r.name) {
                        let n = *p.zones.get_ref();
                        let ok = b == "elcb"
                            || b == "mccb"
                            || b.strip_prefix("zone")
                                .and_then(|z| z.parse::<u8>().ok())
                                .is_some_and(|z| z >= 1 && z <= n);
                        if !ok {
                            err(r.at, format!("'{b}' is not a breaker of panel '{}'; use elcb, mccb or zone1..zone{n}", r.name));
                        }
                    }
                }
                RefKind::Unit | RefKind::StorageUnit => {
                    match units.iter().find(|(id, prefix, _)| *id == r.name || *prefix == r.name) {
                        None => err(
                            r.at,
                            if units.is_empty() {
                                format!("the plant has no microgrid, so no unit '{}'", r.name)
                            } else {
                                format!(
                                    "the plant has no microgrid unit '{}'; it has {}",
                                    r.name,
                                    units.iter().map(|u| u.0.as_str()).collect::<Vec<_>>().join(", ")
                                )
                            },
                        ),
                        Some((_, _, kind)) if r.kind == RefKind::StorageUnit && *kind != UnitKind::Storage => {
                            err(r.at, format!("'{}' is not a storage unit; only storage has a state of charge", r.name))
                        }
                        _ => {}
                    }
                }
                RefKind::Device => {
                    let known = plant.devices.iter().any(|d| {
                        d.name.get_ref() == &r.name
                            || d.address.as_ref().is_some_and(|a| a.get_ref() == &r.name)
                    });
                    if !known {
                        err(
                            r.at,
                            format!("the plant has no device or gateway address '{}'", r.name),
                        );
                    }
                }
                RefKind::Tag => {
                    if !tag_exists(&r.name) {
                        err(r.at, format!("the tag database has no tag '{}'", r.name));
                    }
                }
                RefKind::Figure => {
                    let ok = FIGURE_NAMES.contains(&r.name.as_str())
                        || r.name.split_once('.').is_some_and(|(p, f)| {
                            panel_ids.iter().any(|id| id == p) && PANEL_FIGURE_NAMES.contains(&f)
                        });
                    if !ok {
                        err(r.at, format!("'{}' is not a report figure; see docs/SCENARIOS.md for the list (per panel: <panel>.{})", r.name, PANEL_FIGURE_NAMES.join(", <panel>.")));
                    }
                }
                RefKind::Microgrid => {
                    if plant.microgrid.is_none() && !seen_microgrid {
                        seen_microgrid = true;
                        err(
                            r.at,
                            format!(
                                "profile '{}' drives the microgrid, but the plant has none",
                                r.name
                            ),
                        );
                    }
                }
            }
        }
        out
    }
}
