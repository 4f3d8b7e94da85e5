//! CSV rows of a historian export. Pure formatting, no I/O.

use std::fmt::Write;

use crate::RawSample;

/// Appends one CSV row: `time_utc,ts_ms,tag,value,quality`.
pub(crate) fn row(out: &mut String, s: &RawSample) {
    iso_utc(out, s.ts.as_millis());
    let _ = write!(out, ",{},", s.ts.as_millis());
    field(out, &s.tag);
    out.push(',');
    if let Some(i) = s.exact {
        let _ = write!(out, "{i}");
    } else if let Some(v) = s.value {
        let _ = write!(out, "{v}");
    }
    out.push(',');
    out.push_str(quality_label(s.quality));
    out.push('\n');
}

/// A CSV field, quoted when it holds a separator, quote or line break. A
/// leading `=`, `+`, `-` or `@` is prefixed with `'` so a spreadsheet does not
/// run a tag name as a formula.
pub fn field(out: &mut String, s: &str) {
    let formula = s.starts_with(['=', '+', '-', '@']);
    let quote = formula || s.contains([',', '"', '\n', '\r']);
    if quote {
        out.push('"');
    }
    if formula {
        out.push('\'');
    }
    for c in s.chars() {
        if c == '"' {
            out.push('"');
        }
        out.push(c);
    }
    if quote {
        out.push('"');
    }
}

/// `YYYY-MM-DDTHH:MM:SS.mmmZ` for milliseconds since the epoch.
pub(crate) fn iso_utc(out: &mut String, ms: i64) {
    let c = gridscada_tagdb::Timestamp::from_millis(ms).civil_utc();
    let _ = write!(
        out,
        "{:04}-{:02}-{:02}T{:02}:{:02}:{:02}.{:03}Z",
        c.year, c.month, c.day, c.hour, c.minute, c.second, c.milli
    );
}

/// The quality column's text.
fn quality_label(q: gridscada_tagdb::QualityCode) -> &'static str {
    match q {
        gridscada_tagdb::QualityCode::Good => "good",
        gridscada_tagdb::QualityCode::Uncertain => "uncertain",
        gridscada_tagdb::QualityCode::Bad => "bad",
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use gridscada_tagdb::{QualityCode, Timestamp};

    fn iso(ms: i64) -> String {
        let mut s = String::new();
        iso_utc(&mut s, ms);
        s
    }

    #[test]
    fn iso_dates() {
        assert_eq!(iso(0), "1970-01-01T00:00:00.000Z");
        assert_eq!(iso(951_782_400_123), "2000-02-29T00:00:00.123Z");
        assert_eq!(iso(1_735_689_599_999), "2024-12-31T23:59:59.999Z");
        assert_eq!(iso(-1), "1969-12-31T23:59:59.999Z");
    }

    #[test]
    fn fields_are_quoted_and_defused() {
        let mut s = String::new();
        row(
            &mut s,
            &RawSample {
                tag: "=cmd,\"x\"".into(),
                ts: Timestamp::from_millis(1500),
                value: Some(2.5),
                exact: None,
                quality: QualityCode::Bad,
            },
        );
        assert_eq!(
            s,
            "1970-01-01T00:00:01.500Z,1500,\"'=cmd,\"\"x\"\"\",2.5,bad\n"
        );
    }
}
