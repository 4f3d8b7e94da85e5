//! User-drawn mimic screens: the JSON model the HMI's editor saves, the
//! server stores and a plant may keep in version control (`screens/*.json`
//! beside `gridscada.toml`), with validation against the running plant.
//!
//! **Owns:** the screen format and its rules (ids, geometry, element kinds,
//! bindings to tags that exist and have the right kind). **Must not touch:**
//! storage or HTTP: the store keeps the JSON, the web layer serves it.

use std::path::{Path, PathBuf};

use gridscada_tagdb::ValueKind;
use serde::{Deserialize, Serialize};

/// Most elements one screen may hold.
pub const MAX_ELEMENTS: usize = 2000;
/// Longest label, text or name, in characters.
pub const MAX_LABEL: usize = 256;
/// Largest coordinate or size, in pixels.
pub const MAX_COORD: i64 = 10_000;
/// Most pens of a small trend.
pub const MAX_PENS: usize = 8;

/// One user-defined screen.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Screen {
    pub id: String,
    pub name: String,
    /// Increases by one with every save; 0 for a screen never saved.
    #[serde(default)]
    pub version: i64,
    #[serde(default = "default_width")]
    pub width: i64,
    #[serde(default = "default_height")]
    pub height: i64,
    #[serde(default)]
    pub elements: Vec<Element>,
}

fn default_width() -> i64 {
    1200
}
fn default_height() -> i64 {
    700
}

/// One element: its box on the canvas and what it shows.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Element {
    pub x: i64,
    pub y: i64,
    pub w: i64,
    pub h: i64,
    #[serde(flatten)]
    pub kind: ElementKind,
}

/// A state of a multi-state indicator.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StateLabel {
    pub value: f64,
    pub label: String,
}

/// What an element is. Labels are plain text: the HMI inserts them as text,
/// never as markup.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "lowercase")]
pub enum ElementKind {
    Text {
        text: String,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        size: Option<i64>,
    },
    /// A wire or a busbar (drawn thick) along the longer side of its box,
    /// through its middle: horizontal when w >= h, else vertical.
    Line {
        #[serde(default)]
        busbar: bool,
        /// Coloured live by a network section: its state tag
        /// (`NET.Sec.<section>.State`), as on the network screen.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        section_tag: Option<String>,
    },
    Rect {
        #[serde(default)]
        label: String,
    },
    /// A breaker or switch bound to a bool tag (true = closed).
    Breaker {
        tag: String,
        #[serde(default)]
        label: String,
        /// Show the time of the position (the device's own time stamp
        /// where it sends one: an RTU's sequence-of-events record), to the
        /// millisecond.
        #[serde(default, skip_serializing_if = "std::ops::Not::not")]
        time: bool,
    },
    Value {
        tag: String,
        #[serde(default)]
        label: String,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        digits: Option<i64>,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        units: Option<String>,
        /// Show the time of the value, as for a breaker.
        #[serde(default, skip_serializing_if = "std::ops::Not::not")]
        time: bool,
    },
    Bar {
        tag: String,
        #[serde(default)]
        label: String,
        min: f64,
        max: f64,
    },
    Multistate {
        tag: String,
        #[serde(default)]
        label: String,
        states: Vec<StateLabel>,
    },
    /// Writes `value` to a writable tag, confirmed by the operator.
    Button {
        tag: String,
        label: String,
        value: serde_json::Value,
    },
    Trend {
        pens: Vec<String>,
        #[serde(default = "default_span")]
        span_s: i64,
        #[serde(default)]
        label: String,
    },
    /// A link to another screen (a built-in id or `custom:<id>`).
    Link { screen: String, label: String },
    /// A panel's whole single-line diagram, by the panel's id.
    Panel { panel: String },
}

fn default_span() -> i64 {
    600
}

/// What validation needs to know of the running plant.
pub trait PlantView {
    /// The kind of a tag and whether it is writable, if it exists.
    fn tag(&self, name: &str) -> Option<(ValueKind, bool)>;
    /// Whether a panel with this id is configured.
    fn has_panel(&self, id: &str) -> bool;
}

/// Whether `id` is a valid screen id: `^[a-z0-9][a-z0-9_-]{0,63}$`.
pub fn valid_id(id: &str) -> bool {
    let b = id.as_bytes();
    !b.is_empty()
        && b.len() <= 64
        && (b[0].is_ascii_lowercase() || b[0].is_ascii_digit())
        && b.iter()
            .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || *c == b'_' || *c == b'-')
}

/// The prefix that names a user-defined screen among the built-in ones in
/// screen-access lists (`custom:feeder-a`).
pub const CUSTOM_PREFIX: &str = "custom:";

impl Screen {
    /// The access name of this screen (`custom:<id>`).
    pub fn access_id(&self) -> String {
        format!("{CUSTOM_PREFIX}{}", self.id)
    }

    /// Every tag the screen shows or writes, without duplicates (a panel
    /// element's tags are not included: see [`Screen::panels`]).
    pub fn tags(&self) -> Vec<&str> {
        let mut out: Vec<&str> = vec![];
        for e in &self.elements {
            match &e.kind {
                ElementKind::Breaker { tag, .. }
                | ElementKind::Value { tag, .. }
                | ElementKind::Bar { tag, .. }
                | ElementKind::Multistate { tag, .. }
                | ElementKind::Button { tag, .. } => out.push(tag),
                ElementKind::Trend { pens, .. } => out.extend(pens.iter().map(String::as_str)),
                ElementKind::Line {
                    section_tag: Some(t),
                    ..
                } => out.push(t),
                _ => {}
            }
        }
        out.sort_unstable();
        out.dedup();
        out
    }

    /// The panels embedded whole.
    pub fn panels(&self) -> Vec<&str> {
        let mut out: Vec<&str> = self
            .elements
            .iter()
            .filter_map(|e| match &e.kind {
                ElementKind::Panel { panel } => Some(panel.as_str()),
                _ => None,
            })
            .collect();
        out.sort_unstable();
        out.dedup();
        out
    }

    /// Every problem, each naming the element (by index, from 0) and field.
    pub fn validate(&self, plant: &dyn PlantView) -> Vec<String> {
        let mut errs = vec![];
        if !valid_id(&self.id) {
            errs.push(format!(
                "id: '{}' is not a screen id (lowercase letters, digits, '-' and '_', at most 64, starting with a letter or digit)",
                clip(&self.id)
            ));
        }
        check_label(&mut errs, "name", &self.name, true);
        for (field, v) in [("width", self.width), ("height", self.height)] {
            if !(100..=MAX_COORD).contains(&v) {
                errs.push(format!("{field}: {v} is not 100 to {MAX_COORD} pixels"));
            }
        }
        if self.elements.len() > MAX_ELEMENTS {
            errs.push(format!(
                "elements: {} elements, at most {MAX_ELEMENTS}",
                self.elements.len()
            ));
            return errs;
        }
        for (i, e) in self.elements.iter().enumerate() {
            e.validate(i, plant, &mut errs);
        }
        errs
    }
}

impl Element {
    fn validate(&self, i: usize, plant: &dyn PlantView, errs: &mut Vec<String>) {
        let at = |field: &str| format!("element {i} ({}) {field}", self.kind.name());
        for (field, v, min) in [
            ("x", self.x, 0),
            ("y", self.y, 0),
            ("w", self.w, 1),
            ("h", self.h, 1),
        ] {
            if !(min..=MAX_COORD).contains(&v) {
                errs.push(format!("{}: {v} is not {min} to {MAX_COORD}", at(field)));
            }
        }
        let mut label = |field: &str, s: &str, required: bool| {
            let mut sub = vec![];
            check_label(&mut sub, &at(field), s, required);
            errs.extend(sub);
        };
        match &self.kind {
            ElementKind::Text { text, size } => {
                label("text", text, true);
                if let Some(sz) = size {
                    if !(6..=200).contains(sz) {
                        errs.push(format!("{}: {sz} is not 6 to 200", at("size")));
                    }
                }
            }
            ElementKind::Line { .. } => {}
            ElementKind::Rect { label: l }
            | ElementKind::Breaker { label: l, .. }
            | ElementKind::Value { label: l, .. }
            | ElementKind::Bar { label: l, .. }
            | ElementKind::Multistate { label: l, .. }
            | ElementKind::Trend { label: l, .. } => label("label", l, false),
            ElementKind::Button { label: l, .. } | ElementKind::Link { label: l, .. } => {
                label("label", l, true)
            }
            ElementKind::Panel { .. } => {}
        }
        let tag = |name: &str, errs: &mut Vec<String>| -> Option<(ValueKind, bool)> {
            let found = plant.tag(name);
            if found.is_none() {
                errs.push(format!("{}: no tag named '{}'", at("tag"), clip(name)));
            }
            found
        };
        match &self.kind {
            ElementKind::Breaker { tag: t, .. } => {
                if let Some((kind, _)) = tag(t, errs) {
                    if kind != ValueKind::Bool {
                        errs.push(format!(
                            "{}: '{t}' is a {kind:?} tag; a breaker shows a bool tag",
                            at("tag")
                        ));
                    }
                }
            }
            ElementKind::Value {
                tag: t,
                digits,
                units,
                ..
            } => {
                tag(t, errs);
                if let Some(d) = digits {
                    if !(0..=9).contains(d) {
                        errs.push(format!("{}: {d} is not 0 to 9", at("digits")));
                    }
                }
                if let Some(u) = units {
                    check_label(errs, &at("units"), u, false);
                }
            }
            ElementKind::Bar {
                tag: t, min, max, ..
            } => {
                if let Some((kind, _)) = tag(t, errs) {
                    if !matches!(kind, ValueKind::Int | ValueKind::Float) {
                        errs.push(format!(
                            "{}: '{t}' is a {kind:?} tag; a bar shows a number",
                            at("tag")
                        ));
                    }
                }
                if !(min.is_finite() && max.is_finite() && min < max) {
                    errs.push(format!("{}: need finite min < max", at("min/max")));
                }
            }
            ElementKind::Multistate { tag: t, states, .. } => {
                tag(t, errs);
                if states.is_empty() || states.len() > 64 {
                    errs.push(format!("{}: 1 to 64 states", at("states")));
                }
                for (k, s) in states.iter().enumerate() {
                    if !s.value.is_finite() {
                        errs.push(format!("{}: state {k} value is not a number", at("states")));
                    }
                    check_label(errs, &at(&format!("states[{k}].label")), &s.label, true);
                }
            }
            ElementKind::Button { tag: t, value, .. } => {
                if let Some((kind, writable)) = tag(t, errs) {
                    if !writable {
                        errs.push(format!("{}: '{t}' is read-only", at("tag")));
                    } else if !value_fits(value, kind) {
                        errs.push(format!(
                            "{}: {value} is not a valid {kind:?} value for '{t}'",
                            at("value")
                        ));
                    }
                }
            }
            ElementKind::Trend { pens, span_s, .. } => {
                if pens.is_empty() || pens.len() > MAX_PENS {
                    errs.push(format!("{}: 1 to {MAX_PENS} pens", at("pens")));
                }
                for p in pens {
                    if let Some((kind, _)) = tag(p, errs) {
                        if !matches!(kind, ValueKind::Int | ValueKind::Float | ValueKind::Bool) {
                            errs.push(format!(
                                "{}: '{p}' is a {kind:?} tag; a trend draws numbers",
                                at("pens")
                            ));
                        }
                    }
                }
                if !(10..=7 * 86_400).contains(span_s) {
                    errs.push(format!("{}: {span_s} is not 10 s to 7 days", at("span_s")));
                }
            }
            ElementKind::Link { screen, .. } => {
                let id = screen.strip_prefix(CUSTOM_PREFIX).unwrap_or(screen);
                if !valid_id(id) {
                    errs.push(format!(
                        "{}: '{}' is not a screen id",
                        at("screen"),
                        clip(screen)
                    ));
                }
            }
            ElementKind::Panel { panel } => {
                if !plant.has_panel(panel) {
                    errs.push(format!(
                        "{}: no panel with id '{}'",
                        at("panel"),
                        clip(panel)
                    ));
                }
            }
            ElementKind::Line {
                section_tag: Some(t),
                ..
            } => {
                let found = plant.tag(t);
                let is_state = t.contains(".Sec.") && t.ends_with(".State");
                if !is_state || found.is_some_and(|(kind, _)| kind != ValueKind::Str) {
                    errs.push(format!(
                        "{}: '{}' is not a network section's state tag (<prefix>.Sec.<section>.State)",
                        at("section_tag"),
                        clip(t)
                    ));
                } else if found.is_none() {
                    errs.push(format!(
                        "{}: no network section state tag named '{}'",
                        at("section_tag"),
                        clip(t)
                    ));
                }
            }
            ElementKind::Text { .. } | ElementKind::Line { .. } | ElementKind::Rect { .. } => {}
        }
    }
}

impl ElementKind {
    pub fn name(&self) -> &'static str {
        match self {
            ElementKind::Text { .. } => "text",
            ElementKind::Line { .. } => "line",
            ElementKind::Rect { .. } => "rect",
            ElementKind::Breaker { .. } => "breaker",
            ElementKind::Value { .. } => "value",
            ElementKind::Bar { .. } => "bar",
            ElementKind::Multistate { .. } => "multistate",
            ElementKind::Button { .. } => "button",
            ElementKind::Trend { .. } => "trend",
            ElementKind::Link { .. } => "link",
            ElementKind::Panel { .. } => "panel",
        }
    }
}

fn value_fits(v: &serde_json::Value, kind: ValueKind) -> bool {
    match kind {
        ValueKind::Bool => v.is_boolean(),
        ValueKind::Int => v.as_i64().is_some() || v.as_u64().is_some(),
        ValueKind::Float => v.as_f64().is_some_and(f64::is_finite),
        ValueKind::Str => v.is_string(),
    }
}

fn check_label(errs: &mut Vec<String>, field: &str, s: &str, required: bool) {
    if required && s.trim().is_empty() {
        errs.push(format!("{field}: must not be empty"));
    }
    if s.chars().count() > MAX_LABEL {
        errs.push(format!("{field}: at most {MAX_LABEL} characters"));
    }
    if s.chars().any(|c| c.is_control() && c != '\n') {
        errs.push(format!("{field}: control characters are not allowed"));
    }
}

/// At most 64 characters of user input, for error messages.
fn clip(s: &str) -> String {
    let mut out: String = s.chars().take(64).collect();
    if out.len() < s.len() {
        out.push('…');
    }
    out
}

/// Parses one screen file; the error names the file, line and column.
pub fn parse_file(path: &Path, text: &str) -> Result<Screen, String> {
    serde_json::from_str::<Screen>(text).map_err(|e| {
        format!(
            "{}:{}:{}: {}",
            path.display(),
            e.line(),
            e.column(),
            e.to_string().split(" at line ").next().unwrap_or_default()
        )
    })
}

/// The screens folder of a configuration: `screens/` beside the main file.
pub fn folder_of(main_path: &Path) -> PathBuf {
    main_path
        .parent()
        .unwrap_or_else(|| Path::new("."))
        .join("screens")
}

/// Reads every `*.json` in `dir` (sorted by name). A missing folder is no
/// screens; each unreadable or malformed file is one error naming it.
pub fn read_folder(dir: &Path) -> (Vec<(PathBuf, Screen)>, Vec<String>) {
    let mut screens = vec![];
    let mut errors = vec![];
    let entries = match std::fs::read_dir(dir) {
        Ok(e) => e,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return (screens, errors),
        Err(e) => {
            errors.push(format!("{}: {e}", dir.display()));
            return (screens, errors);
        }
    };
    let mut paths: Vec<PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "json"))
        .collect();
    paths.sort();
    for path in paths {
        match std::fs::read_to_string(&path) {
            Ok(text) => match parse_file(&path, &text) {
                Ok(s) => screens.push((path, s)),
                Err(e) => errors.push(e),
            },
            Err(e) => errors.push(format!("{}: {e}", path.display())),
        }
    }
    (screens, errors)
}

#[cfg(test)]
mod tests {
    use super::*;

    struct View;
    impl PlantView for View {
        fn tag(&self, name: &str) -> Option<(ValueKind, bool)> {
            match name {
                "A.Closed" => Some((ValueKind::Bool, false)),
                "A.Cmd" => Some((ValueKind::Bool, true)),
                "A.P_kW" => Some((ValueKind::Float, false)),
                "A.Setpoint" => Some((ValueKind::Float, true)),
                "NET.Sec.c2.State" | "A.Words" => Some((ValueKind::Str, false)),
                _ => None,
            }
        }
        fn has_panel(&self, id: &str) -> bool {
            id == "pa"
        }
    }

    fn screen(elements: serde_json::Value) -> Screen {
        serde_json::from_value(serde_json::json!({
            "id": "feeder-a", "name": "Feeder A", "elements": elements
        }))
        .unwrap()
    }

    #[test]
    fn a_good_screen_round_trips_and_lists_its_tags() {
        let s = screen(serde_json::json!([
            {"type": "breaker", "x": 10, "y": 10, "w": 40, "h": 40, "tag": "A.Closed", "label": "Incomer"},
            {"type": "value", "x": 60, "y": 10, "w": 80, "h": 20, "tag": "A.P_kW", "digits": 1},
            {"type": "button", "x": 60, "y": 40, "w": 80, "h": 20, "tag": "A.Cmd", "label": "Close", "value": true},
            {"type": "trend", "x": 0, "y": 100, "w": 300, "h": 150, "pens": ["A.P_kW"], "span_s": 600},
            {"type": "panel", "x": 0, "y": 300, "w": 600, "h": 400, "panel": "pa"},
            {"type": "text", "x": 0, "y": 0, "w": 100, "h": 20, "text": "<img src=x onerror=alert(1)>"}
        ]));
        assert_eq!(s.validate(&View), Vec::<String>::new());
        assert_eq!(s.tags(), vec!["A.Closed", "A.Cmd", "A.P_kW"]);
        assert_eq!(s.panels(), vec!["pa"]);
        let back: Screen = serde_json::from_str(&serde_json::to_string(&s).unwrap()).unwrap();
        assert_eq!(back, s);
        assert_eq!(s.access_id(), "custom:feeder-a");
    }

    #[test]
    fn every_problem_names_the_element_and_field() {
        let s = screen(serde_json::json!([
            {"type": "breaker", "x": 10, "y": 10, "w": 40, "h": 40, "tag": "A.P_kW"},
            {"type": "button", "x": 0, "y": 0, "w": 10, "h": 10, "tag": "A.Closed", "label": "x", "value": 1},
            {"type": "value", "x": -5, "y": 0, "w": 10, "h": 10, "tag": "Nope"},
            {"type": "panel", "x": 0, "y": 0, "w": 10, "h": 10, "panel": "zz"},
            {"type": "button", "x": 0, "y": 0, "w": 10, "h": 10, "tag": "A.Setpoint", "label": "x", "value": "high"}
        ]));
        let errs = s.validate(&View);
        let all = errs.join("\n");
        assert!(
            all.contains("element 0 (breaker) tag: 'A.P_kW' is a Float tag"),
            "{all}"
        );
        assert!(
            all.contains("element 1 (button) tag: 'A.Closed' is read-only"),
            "{all}"
        );
        assert!(all.contains("element 2 (value) x: -5"), "{all}");
        assert!(
            all.contains("element 2 (value) tag: no tag named 'Nope'"),
            "{all}"
        );
        assert!(
            all.contains("element 3 (panel) panel: no panel with id 'zz'"),
            "{all}"
        );
        assert!(all.contains("element 4 (button) value"), "{all}");
    }

    #[test]
    fn a_line_bound_to_a_section_shows_its_state_tag_and_a_bad_binding_is_named() {
        let s = screen(serde_json::json!([
            {"type": "line", "x": 0, "y": 0, "w": 200, "h": 10, "busbar": true, "section_tag": "NET.Sec.c2.State"},
            {"type": "line", "x": 0, "y": 20, "w": 200, "h": 10}
        ]));
        assert_eq!(s.validate(&View), Vec::<String>::new());
        assert_eq!(s.tags(), vec!["NET.Sec.c2.State"]);
        let back: Screen = serde_json::from_str(&serde_json::to_string(&s).unwrap()).unwrap();
        assert_eq!(back, s);
        let bad = screen(serde_json::json!([
            {"type": "line", "x": 0, "y": 0, "w": 200, "h": 10, "section_tag": "A.Words"},
            {"type": "line", "x": 0, "y": 0, "w": 200, "h": 10, "section_tag": "NET.Sec.c9.State"},
            {"type": "line", "x": 0, "y": 0, "w": 200, "h": 10, "section_tag": "A.Closed"}
        ]));
        let all = bad.validate(&View).join("\n");
        assert!(
            all.contains(
                "element 0 (line) section_tag: 'A.Words' is not a network section's state tag"
            ),
            "{all}"
        );
        assert!(
            all.contains("element 1 (line) section_tag: no network section state tag named 'NET.Sec.c9.State'"),
            "{all}"
        );
        assert!(
            all.contains("element 2 (line) section_tag: 'A.Closed'"),
            "{all}"
        );
    }

    #[test]
    fn ids_and_files() {
        assert!(valid_id("feeder-a"));
        assert!(valid_id("0_x"));
        assert!(!valid_id("Feeder"));
        assert!(!valid_id("-a"));
        assert!(!valid_id(""));
        assert!(!valid_id(&"a".repeat(65)));
        let err = parse_file(
            Path::new("screens/x.json"),
            "{\n  \"id\": \"x\",\n  \"name\": 3\n}",
        )
        .unwrap_err();
        assert!(err.starts_with("screens/x.json:3:"), "{err}");
        let err = parse_file(
            Path::new("s.json"),
            r#"{"id":"x","name":"n","elements":[{"type":"gauge","x":0,"y":0,"w":1,"h":1}]}"#,
        )
        .unwrap_err();
        assert!(err.contains("gauge"), "{err}");
    }
}
