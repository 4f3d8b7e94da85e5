//! Reading scenario files: TOML syntax errors, then each section and each
//! `[[event]]` / `[[expect]]` entry deserialized on its own (so one bad
//! entry does not hide the others), then the meaning checks, every problem
//! with file, line and column, as `gridscada check` reports configuration.
//!
//! This file holds the parse, the header and the initial state; the raw
//! shapes are in `raw.rs`, the sections and entries in `profiles.rs`,
//! `events.rs` and `expectations.rs`, the names and their check against a
//! plant in `names.rs`.

use std::path::{Path, PathBuf};
use std::time::Duration;

use gridscada_config::{Diagnostic, SourceFile};
use serde::de::DeserializeOwned;
use serde_spanned::Spanned;
use toml::de::{DeTable, DeValue, ValueDeserializer};

use super::time::{parse_start, TimeValue};
use super::{Initial, InitialPanel, InitialUnit, Profiles, Scenario};

mod events;
mod expectations;
mod names;
mod profiles;
mod raw;

pub(crate) use names::NameRef;
pub use names::{FIGURE_NAMES, PANEL_FIGURE_NAMES};

use names::RefKind;
use raw::{RawEvent, RawExpect, RawInitial};

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
    let fuel_price = header.fuel_price;
    if fuel_price.is_some_and(|f| !(f.is_finite() && f >= 0.0)) {
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
}
