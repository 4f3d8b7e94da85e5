//! CSV rows of the exports (historian samples, events, alarm history,
//! dispatches), with the formula-injection guard every text field goes
//! through; and [`CsvWriter`], which sends rows on in 64 KiB pieces as they
//! are made, so an export never holds its whole result.

use std::fmt::Write;

use tokio::io::{AsyncWrite, AsyncWriteExt};

use crate::{RawSample, Result, StoreError};

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

/// Rows of one CSV export on their way to `out`: fields are appended to a
/// buffer that is written out whenever it passes 64 KiB.
pub(crate) struct CsvWriter<'a, W> {
    out: &'a mut W,
    buf: String,
    /// No field yet on the current row.
    fresh: bool,
    rows: u64,
    what: &'static str,
}

const FLUSH_AT: usize = 64 * 1024;

impl<'a, W: AsyncWrite + Unpin> CsvWriter<'a, W> {
    /// A writer whose first line is `header` (comma-separated column names).
    pub(crate) fn new(out: &'a mut W, what: &'static str, header: &str) -> Self {
        let mut buf = String::with_capacity(FLUSH_AT + 4096);
        buf.push_str(header);
        buf.push('\n');
        CsvWriter {
            out,
            buf,
            fresh: true,
            rows: 0,
            what,
        }
    }

    fn sep(&mut self) {
        if !self.fresh {
            self.buf.push(',');
        }
        self.fresh = false;
    }

    /// A text field, quoted and defused ([`field`]).
    pub(crate) fn text(&mut self, s: &str) {
        self.sep();
        field(&mut self.buf, s);
    }

    /// A text field that may be absent (an empty field).
    pub(crate) fn opt_text(&mut self, s: Option<&str>) {
        self.sep();
        if let Some(s) = s {
            field(&mut self.buf, s);
        }
    }

    /// A number or another value whose text needs no quoting.
    pub(crate) fn plain(&mut self, v: impl std::fmt::Display) {
        self.sep();
        let _ = write!(self.buf, "{v}");
    }

    /// A number that may be absent.
    pub(crate) fn opt_plain(&mut self, v: Option<impl std::fmt::Display>) {
        self.sep();
        if let Some(v) = v {
            let _ = write!(self.buf, "{v}");
        }
    }

    /// Two fields: the time in UTC (ISO 8601) and in ms since the epoch.
    pub(crate) fn time(&mut self, ms: i64) {
        self.sep();
        iso_utc(&mut self.buf, ms);
        let _ = write!(self.buf, ",{ms}");
    }

    /// Ends the row; writes the buffer out when it is full.
    pub(crate) async fn end_row(&mut self) -> Result<()> {
        self.buf.push('\n');
        self.fresh = true;
        self.rows += 1;
        if self.buf.len() >= FLUSH_AT {
            self.write_out().await?;
        }
        Ok(())
    }

    async fn write_out(&mut self) -> Result<()> {
        let what = self.what;
        self.out
            .write_all(self.buf.as_bytes())
            .await
            .map_err(|source| StoreError::Io { what, source })?;
        self.buf.clear();
        Ok(())
    }

    /// Writes the rest and flushes; the number of rows.
    pub(crate) async fn finish(mut self) -> Result<u64> {
        self.write_out().await?;
        let what = self.what;
        self.out
            .flush()
            .await
            .map_err(|source| StoreError::Io { what, source })?;
        Ok(self.rows)
    }
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
