//! Input profiles over scenario time: points written inline or read from a
//! CSV file, interpolated linearly or held (step), scaled, with optional
//! seeded noise.
//!
//! Owns the value of a profile at any scenario offset and reading CSV
//! columns with located errors. Pure: the CSV text is handed in.

use std::time::Duration;

use gridscada_config::{Diagnostic, SourceFile};
use serde::Serialize;

use super::time::parse_duration;

/// How values between two points are found.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Interpolate {
    Linear,
    /// Each value holds until the next point.
    Step,
}

/// A profile: `(offset, value)` points, sorted by offset.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Series {
    pub points: Vec<(Duration, f64)>,
    pub interpolate: Interpolate,
    pub scale: f64,
    /// Relative noise: each step's value is multiplied by 1 + u × noise, u
    /// uniform in [-1, 1] from the scenario's seed, so replays repeat.
    pub noise: f64,
    /// Distinguishes the noise streams of different profiles.
    pub stream: u64,
    /// Where the points came from, for reports ("profiles/day.csv:irradiance").
    pub source: String,
}

impl Series {
    pub fn constant(v: f64, source: impl Into<String>) -> Series {
        Series {
            points: vec![(Duration::ZERO, v)],
            interpolate: Interpolate::Step,
            scale: 1.0,
            noise: 0.0,
            stream: 0,
            source: source.into(),
        }
    }

    /// The value at offset `t` (before the first point: the first value;
    /// after the last: the last), scaled, with this step's noise.
    pub fn value_at(&self, t: Duration, seed: u64) -> f64 {
        let base = self.clean_at(t) * self.scale;
        if self.noise == 0.0 {
            return base;
        }
        let u = unit_noise(seed, self.stream, t.as_millis() as u64);
        base * (1.0 + u * self.noise)
    }

    fn clean_at(&self, t: Duration) -> f64 {
        let pts = &self.points;
        let Some(first) = pts.first() else {
            return 0.0;
        };
        if t <= first.0 {
            return first.1;
        }
        let i = pts.partition_point(|p| p.0 <= t);
        if i >= pts.len() {
            return pts[pts.len() - 1].1;
        }
        let (a, b) = (pts[i - 1], pts[i]);
        match self.interpolate {
            Interpolate::Step => a.1,
            Interpolate::Linear => {
                let span = (b.0 - a.0).as_secs_f64();
                if span <= 0.0 {
                    return b.1;
                }
                a.1 + (b.1 - a.1) * (t - a.0).as_secs_f64() / span
            }
        }
    }
}

/// A uniform number in [-1, 1] from (seed, stream, time): splitmix64, so
/// the noise of a step depends on nothing but these three.
fn unit_noise(seed: u64, stream: u64, t_ms: u64) -> f64 {
    let mut z = seed
        .wrapping_add(stream.wrapping_mul(0x9E37_79B9_7F4A_7C15))
        .wrapping_add(t_ms.wrapping_mul(0xBF58_476D_1CE4_E5B9));
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 31;
    (z >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
}

/// A parsed CSV file: a header row naming the columns (the first is the
/// time), then one row per point. `#` starts a comment line.
#[derive(Debug, Clone)]
pub struct CsvTable {
    pub columns: Vec<String>,
    /// (line, time, values) per data row.
    pub rows: Vec<(usize, Duration, Vec<f64>)>,
}

/// Parses CSV text, reporting every bad cell with its line and column.
pub fn parse_csv(file: &SourceFile) -> Result<CsvTable, Vec<Diagnostic>> {
    let mut diags = Vec::new();
    let mut columns: Option<Vec<String>> = None;
    let mut rows: Vec<(usize, Duration, Vec<f64>)> = Vec::new();
    let mut offset = 0usize;
    for (i, raw_line) in file.text.split('\n').enumerate() {
        let line_start = offset;
        offset += raw_line.len() + 1;
        let line = raw_line.trim_end_matches('\r');
        if line.trim().is_empty() || line.trim_start().starts_with('#') {
            continue;
        }
        // Cells with their byte offsets in the file.
        let mut cells = Vec::new();
        let mut start = 0usize;
        for cell in line.split(',') {
            let lead = cell.len() - cell.trim_start().len();
            cells.push((line_start + start + lead, cell.trim()));
            start += cell.len() + 1;
        }
        let Some(cols) = &columns else {
            if cells.len() < 2 {
                diags.push(file.error_at(
                    line_start..line_start,
                    "the CSV header needs a time column and at least one value column (e.g. time,irradiance)",
                ));
                return Err(diags);
            }
            columns = Some(cells.iter().map(|(_, c)| c.to_string()).collect());
            continue;
        };
        if cells.len() != cols.len() {
            diags.push(file.error_at(
                line_start..line_start,
                format!(
                    "row has {} cells but the header names {} columns",
                    cells.len(),
                    cols.len()
                ),
            ));
            continue;
        }
        let (t_off, t_text) = cells[0];
        let t = match parse_duration(t_text) {
            Ok(t) => t,
            Err(e) => {
                diags.push(file.error_at(t_off..t_off, e));
                continue;
            }
        };
        if let Some(prev) = rows.last() {
            if t <= prev.1 {
                diags.push(file.error_at(
                    t_off..t_off,
                    format!(
                        "time {t_text} is not after the previous row's (line {}); rows must be in time order",
                        prev.0
                    ),
                ));
                continue;
            }
        }
        let mut values = Vec::with_capacity(cells.len() - 1);
        let mut ok = true;
        for (off, text) in &cells[1..] {
            match text.parse::<f64>() {
                Ok(v) if v.is_finite() => values.push(v),
                _ => {
                    diags.push(file.error_at(*off..*off, format!("'{text}' is not a number")));
                    ok = false;
                }
            }
        }
        if ok {
            rows.push((i + 1, t, values));
        }
    }
    let Some(columns) = columns else {
        diags.push(file.error("the CSV file is empty: it needs a header row and data rows"));
        return Err(diags);
    };
    if rows.is_empty() && diags.is_empty() {
        diags.push(file.error("the CSV file has a header but no data rows"));
    }
    if diags.is_empty() {
        Ok(CsvTable { columns, rows })
    } else {
        Err(diags)
    }
}

impl CsvTable {
    /// The points of a value column (by name; `None` = the second column).
    pub fn column(&self, name: Option<&str>) -> Result<Vec<(Duration, f64)>, String> {
        let idx = match name {
            None => 1,
            Some(n) => self
                .columns
                .iter()
                .position(|c| c == n)
                .filter(|&i| i > 0)
                .ok_or_else(|| {
                    format!(
                        "the CSV file has no value column '{n}'; it has {}",
                        self.columns[1..].join(", ")
                    )
                })?,
        };
        Ok(self.rows.iter().map(|(_, t, v)| (*t, v[idx - 1])).collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn s(points: &[(u64, f64)], interpolate: Interpolate) -> Series {
        Series {
            points: points
                .iter()
                .map(|(t, v)| (Duration::from_secs(*t), *v))
                .collect(),
            interpolate,
            scale: 1.0,
            noise: 0.0,
            stream: 0,
            source: "test".into(),
        }
    }

    #[test]
    fn interpolation_and_ends() {
        let l = s(&[(10, 0.0), (20, 100.0)], Interpolate::Linear);
        assert_eq!(l.value_at(Duration::from_secs(0), 0), 0.0);
        assert_eq!(l.value_at(Duration::from_secs(15), 0), 50.0);
        assert_eq!(l.value_at(Duration::from_secs(99), 0), 100.0);
        let st = s(&[(10, 0.0), (20, 100.0)], Interpolate::Step);
        assert_eq!(st.value_at(Duration::from_secs(19), 0), 0.0);
        assert_eq!(st.value_at(Duration::from_secs(20), 0), 100.0);
    }

    #[test]
    fn noise_is_seeded_and_bounded() {
        let mut n = s(&[(0, 100.0)], Interpolate::Step);
        n.noise = 0.1;
        let a: Vec<f64> = (0..50)
            .map(|i| n.value_at(Duration::from_secs(i), 7))
            .collect();
        let b: Vec<f64> = (0..50)
            .map(|i| n.value_at(Duration::from_secs(i), 7))
            .collect();
        assert_eq!(a, b);
        assert!(a.iter().all(|v| (90.0..=110.0).contains(v)));
        assert!(a.iter().any(|v| (v - 100.0).abs() > 1.0));
        let c = n.value_at(Duration::from_secs(3), 8);
        assert_ne!(c, a[3]);
    }

    #[test]
    fn csv_errors_are_located() {
        let f = SourceFile::new(
            "p.csv",
            "# comment\ntime,kw\n00:00,1\n00:10,x\n00:00,2\n".into(),
        );
        let e = parse_csv(&f).unwrap_err();
        assert_eq!(e.len(), 2, "{e:?}");
        assert_eq!((e[0].line, e[0].column), (4, 7));
        assert!(e[0].message.contains("'x' is not a number"));
        assert_eq!((e[1].line, e[1].column), (5, 1));
        let ok = SourceFile::new("p.csv", "time,a,b\n0,1,2\n60,3,4\n".into());
        let t = parse_csv(&ok).unwrap();
        assert_eq!(
            t.column(Some("b")).unwrap(),
            vec![(Duration::ZERO, 2.0), (Duration::from_secs(60), 4.0)]
        );
        assert!(t.column(Some("c")).is_err());
    }
}
