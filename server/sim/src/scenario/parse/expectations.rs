//! One `[[expect]]` entry: a tag's value at a time, or a figure of the
//! run.

use crate::scenario::expect::{Bound, ExpectKind, ExpectValue, Expectation};

use super::names::RefKind;
use super::raw::{ExpectValueRaw, RawExpect};
use super::Parser;

impl Parser<'_> {
    pub(super) fn expect(
        &mut self,
        raw: RawExpect,
        span: std::ops::Range<usize>,
    ) -> Option<Expectation> {
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
                        crate::scenario::time::format_offset(at)
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
