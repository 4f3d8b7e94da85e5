//! Expectations of a scenario and how they are judged.
//!
//! Owns the two kinds (a tag's value at a time, within a tolerance; a report
//! figure within a bound) and the pure verdict given what was observed.
//! Must not touch the tag database: the runner hands in the sample it read.

use std::collections::BTreeMap;
use std::time::Duration;

use gridscada_tagdb::{Sample, Value};
use serde::Serialize;

use super::time::format_offset;

#[derive(Debug, Clone, Serialize)]
pub struct Expectation {
    pub kind: ExpectKind,
    /// Line in the scenario file.
    pub line: usize,
    /// The author's note, or a generated summary.
    pub description: String,
    /// A defect the author knows about: the verdict is still computed and
    /// shown, but a failure does not fail the run (like an expected failure
    /// in a test suite), so a shipped scenario can document it.
    pub known_failure: Option<String>,
}

#[derive(Debug, Clone, Serialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum ExpectKind {
    /// The tag (as the SCADA sees it, through the poller) at offset `at`.
    Tag {
        at: Duration,
        tag: String,
        value: ExpectValue,
        tolerance: f64,
    },
    /// A figure of the report, at the end of the run.
    Figure { name: String, bound: Bound },
}

#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(untagged)]
pub enum ExpectValue {
    Bool(bool),
    Number(f64),
    Text(String),
}

impl std::fmt::Display for ExpectValue {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ExpectValue::Bool(b) => write!(f, "{b}"),
            ExpectValue::Number(n) => write!(f, "{n}"),
            ExpectValue::Text(t) => write!(f, "\"{t}\""),
        }
    }
}

/// Inclusive bounds on a figure.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Bound {
    pub min: Option<f64>,
    pub max: Option<f64>,
}

impl std::fmt::Display for Bound {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match (self.min, self.max) {
            (Some(a), Some(b)) if a == b => write!(f, "= {a}"),
            (Some(a), Some(b)) => write!(f, "in [{a}, {b}]"),
            (Some(a), None) => write!(f, ">= {a}"),
            (None, Some(b)) => write!(f, "<= {b}"),
            (None, None) => write!(f, "anything"),
        }
    }
}

/// The verdict on one expectation.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ExpectationResult {
    pub line: usize,
    pub description: String,
    pub passed: bool,
    pub expected: String,
    pub actual: String,
    /// Why a failure here is known and tolerated (see [`Expectation::known_failure`]).
    pub known_failure: Option<String>,
}

impl ExpectationResult {
    /// Passed, or failed in a way the scenario declares as known.
    pub fn acceptable(&self) -> bool {
        self.passed || self.known_failure.is_some()
    }
}

impl Expectation {
    /// When a tag expectation is due (`None` for figures: at the end).
    pub fn due(&self) -> Option<Duration> {
        match &self.kind {
            ExpectKind::Tag { at, .. } => Some(*at),
            ExpectKind::Figure { .. } => None,
        }
    }

    /// Judges a tag expectation on the sample read at its time (`None`: the
    /// tag had no value). A sample without Good quality fails: the SCADA
    /// did not know the value.
    pub fn judge_tag(&self, sample: Option<&Sample>) -> ExpectationResult {
        let ExpectKind::Tag {
            at,
            tag,
            value,
            tolerance,
        } = &self.kind
        else {
            return self.result(false, "a tag expectation".into(), "a figure".into());
        };
        let expected = match value {
            ExpectValue::Number(_) if *tolerance > 0.0 => {
                format!("{tag} = {value} ± {tolerance} at {}", format_offset(*at))
            }
            _ => format!("{tag} = {value} at {}", format_offset(*at)),
        };
        let Some(s) = sample else {
            return self.result(false, expected, "no value".into());
        };
        let shown = match &s.value {
            gridscada_tagdb::Value::Float(f) => compact(*f),
            other => other.to_string(),
        };
        let actual = if s.quality.is_good() {
            shown
        } else {
            format!("{shown} ({})", s.quality)
        };
        let matches = match (value, &s.value) {
            (ExpectValue::Bool(b), v) => v.as_bool() == Some(*b),
            (ExpectValue::Number(n), v) => v
                .as_f64()
                .is_some_and(|x| (x - n).abs() <= tolerance.max(0.0) + 1e-9),
            (ExpectValue::Text(t), Value::Str(s)) => **s == **t,
            (ExpectValue::Text(_), _) => false,
        };
        self.result(matches && s.quality.is_good(), expected, actual)
    }

    /// Judges a figure expectation on the report's figures.
    pub fn judge_figure(&self, figures: &BTreeMap<String, f64>) -> ExpectationResult {
        let ExpectKind::Figure { name, bound } = &self.kind else {
            return self.result(false, "a figure expectation".into(), "a tag".into());
        };
        let expected = format!("{name} {bound}");
        match figures.get(name) {
            None => self.result(false, expected, "not in this run's report".into()),
            Some(v) => {
                let ok = v.is_finite()
                    && bound.min.is_none_or(|m| *v >= m - 1e-9)
                    && bound.max.is_none_or(|m| *v <= m + 1e-9);
                self.result(ok, expected, compact(*v))
            }
        }
    }

    fn result(&self, passed: bool, expected: String, actual: String) -> ExpectationResult {
        ExpectationResult {
            line: self.line,
            description: self.description.clone(),
            passed,
            expected,
            actual,
            known_failure: self.known_failure.clone(),
        }
    }
}

/// A number as a report shows it: at most four decimals, no float noise
/// (`10.400000000000006` reads `10.4`).
pub fn compact(v: f64) -> String {
    if !v.is_finite() {
        return v.to_string();
    }
    let s = format!("{:.4}", v);
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" {
        "0".into()
    } else {
        s.to_string()
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn compact_numbers_hide_float_noise() {
        assert_eq!(super::compact(10.400000000000006), "10.4");
        assert_eq!(super::compact(2.0), "2");
        assert_eq!(super::compact(-0.00001), "0");
        assert_eq!(super::compact(230.39999389648438), "230.4");
    }

    use super::*;
    use gridscada_tagdb::{Quality, Timestamp};

    fn tag(value: ExpectValue, tolerance: f64) -> Expectation {
        Expectation {
            kind: ExpectKind::Tag {
                at: Duration::from_secs(120),
                tag: "SS1.Zone2.Closed".into(),
                value,
                tolerance,
            },
            line: 3,
            description: "zone 2 open".into(),
            known_failure: None,
        }
    }

    fn sample(v: Value, good: bool) -> Sample {
        Sample {
            value: v,
            quality: if good {
                Quality::GOOD
            } else {
                Quality::bad("comm")
            },
            timestamp: Timestamp::from_millis(0),
        }
    }

    #[test]
    fn tag_values_tolerances_and_quality() {
        let e = tag(ExpectValue::Bool(false), 0.0);
        assert!(e.judge_tag(Some(&sample(Value::Bool(false), true))).passed);
        assert!(!e.judge_tag(Some(&sample(Value::Bool(true), true))).passed);
        assert!(!e.judge_tag(Some(&sample(Value::Bool(false), false))).passed);
        assert!(!e.judge_tag(None).passed);
        let n = tag(ExpectValue::Number(50.0), 0.5);
        assert!(n.judge_tag(Some(&sample(Value::Float(50.4), true))).passed);
        assert!(!n.judge_tag(Some(&sample(Value::Float(50.6), true))).passed);
    }

    #[test]
    fn figure_bounds() {
        let e = Expectation {
            kind: ExpectKind::Figure {
                name: "unserved_kwh".into(),
                bound: Bound {
                    min: None,
                    max: Some(0.0),
                },
            },
            line: 1,
            description: String::new(),
            known_failure: None,
        };
        let mut f = BTreeMap::new();
        assert!(!e.judge_figure(&f).passed);
        f.insert("unserved_kwh".to_string(), 0.0);
        assert!(e.judge_figure(&f).passed);
        f.insert("unserved_kwh".to_string(), 0.2);
        let r = e.judge_figure(&f);
        assert!(!r.passed);
        assert_eq!(r.expected, "unserved_kwh <= 0");
    }
}
