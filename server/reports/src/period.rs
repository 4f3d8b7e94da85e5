//! The period a report covers: one UTC day or one UTC month.

use std::fmt;

use gridscada_tagdb::{CivilTime, Timestamp};
use serde::{Deserialize, Serialize};

/// A report's period. Its id (`2024-06-21` or `2024-06`) names its files.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase")]
pub enum Period {
    Day { year: i64, month: u32, day: u32 },
    Month { year: i64, month: u32 },
}

/// Why a period's text was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("`{0}` is not a day (YYYY-MM-DD) or a month (YYYY-MM) between 1970 and 9999")]
pub struct BadPeriod(pub String);

fn civil(year: i64, month: u32, day: u32) -> CivilTime {
    CivilTime {
        year,
        month,
        day,
        hour: 0,
        minute: 0,
        second: 0,
        milli: 0,
    }
}

impl Period {
    /// Reads `YYYY-MM-DD` or `YYYY-MM`.
    pub fn parse(text: &str) -> Result<Period, BadPeriod> {
        let bad = || BadPeriod(text.chars().take(40).collect());
        let parts: Vec<&str> = text.split('-').collect();
        let num = |s: &str, len: usize| -> Option<u32> {
            (s.len() == len && s.bytes().all(|b| b.is_ascii_digit()))
                .then(|| s.parse().ok())
                .flatten()
        };
        let year = parts.first().and_then(|y| num(y, 4)).ok_or_else(bad)? as i64;
        let month = parts.get(1).and_then(|m| num(m, 2)).ok_or_else(bad)?;
        let p = match parts.len() {
            2 => Period::Month { year, month },
            3 => Period::Day {
                year,
                month,
                day: num(parts[2], 2).ok_or_else(bad)?,
            },
            _ => return Err(bad()),
        };
        if year < 1970 || Timestamp::from_civil_utc(p.start_civil()).is_none() {
            return Err(bad());
        }
        Ok(p)
    }

    fn start_civil(&self) -> CivilTime {
        match *self {
            Period::Day { year, month, day } => civil(year, month, day),
            Period::Month { year, month } => civil(year, month, 1),
        }
    }

    /// The first instant of the period.
    pub fn start(&self) -> Timestamp {
        Timestamp::from_civil_utc(self.start_civil()).unwrap_or(Timestamp::from_millis(0))
    }

    /// The first instant after the period.
    pub fn end(&self) -> Timestamp {
        match *self {
            Period::Day { .. } => self.start().add(std::time::Duration::from_secs(86_400)),
            Period::Month { year, month } => {
                let (y, m) = if month == 12 {
                    (year + 1, 1)
                } else {
                    (year, month + 1)
                };
                Timestamp::from_civil_utc(civil(y, m, 1)).unwrap_or(self.start())
            }
        }
    }

    /// The day holding `t`, and the month holding it.
    pub fn day_of(t: Timestamp) -> Period {
        let c = t.civil_utc();
        Period::Day {
            year: c.year,
            month: c.month,
            day: c.day,
        }
    }
    pub fn month_of(t: Timestamp) -> Period {
        let c = t.civil_utc();
        Period::Month {
            year: c.year,
            month: c.month,
        }
    }

    /// The period just before this one (yesterday, last month).
    pub fn previous(&self) -> Period {
        match self {
            Period::Day { .. } => {
                Period::day_of(Timestamp::from_millis(self.start().as_millis() - 1))
            }
            Period::Month { .. } => {
                Period::month_of(Timestamp::from_millis(self.start().as_millis() - 1))
            }
        }
    }

    pub fn is_month(&self) -> bool {
        matches!(self, Period::Month { .. })
    }

    /// "Daily report" or "Monthly report".
    pub fn label(&self) -> &'static str {
        if self.is_month() {
            "Monthly report"
        } else {
            "Daily report"
        }
    }
}

impl fmt::Display for Period {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Period::Day { year, month, day } => write!(f, "{year:04}-{month:02}-{day:02}"),
            Period::Month { year, month } => write!(f, "{year:04}-{month:02}"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn days_and_months_parse_print_and_span() {
        let d = Period::parse("2024-02-29").unwrap();
        assert_eq!(d.to_string(), "2024-02-29");
        assert_eq!(d.end().as_millis() - d.start().as_millis(), 86_400_000);
        let m = Period::parse("2024-02").unwrap();
        assert_eq!(m.end().as_millis() - m.start().as_millis(), 29 * 86_400_000);
        assert_eq!(
            Period::parse("2024-12").unwrap().end(),
            Period::parse("2025-01").unwrap().start()
        );
        assert_eq!(d.previous().to_string(), "2024-02-28");
        assert_eq!(
            Period::parse("2024-01").unwrap().previous().to_string(),
            "2023-12"
        );
    }

    #[test]
    fn nonsense_is_refused() {
        for t in [
            "2023-02-29",
            "2024-13",
            "24-01",
            "2024-1-01",
            "../x",
            "",
            "2024-01-01-01",
        ] {
            assert!(Period::parse(t).is_err(), "{t}");
        }
    }
}
