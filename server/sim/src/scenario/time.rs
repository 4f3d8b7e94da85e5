//! Times and durations as scenario files write them.
//!
//! Owns parsing `"HH:MM[:SS[.fff]]"`, `"90s"`, `"15m"`, `"1h30m"`, plain
//! seconds and RFC 3339 UTC start times (`"2024-06-21T00:00:00Z"`), and the
//! inverse formatting for reports. Pure: no clock, no I/O.

use std::time::Duration;

use gridscada_tagdb::Timestamp;
use serde::Deserialize;

/// A time offset or duration as written: text or a number of seconds.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(untagged)]
pub enum TimeValue {
    Secs(f64),
    Text(String),
}

impl TimeValue {
    pub fn to_duration(&self) -> Result<Duration, String> {
        match self {
            TimeValue::Secs(s) => secs(*s),
            TimeValue::Text(t) => parse_duration(t),
        }
    }
}

fn secs(s: f64) -> Result<Duration, String> {
    if s.is_finite() && (0.0..=1.0e9).contains(&s) {
        Ok(Duration::from_millis((s * 1000.0).round() as u64))
    } else {
        Err(format!("{s} is not a time: need 0 <= seconds <= 1e9"))
    }
}

/// `"HH:MM"`, `"HH:MM:SS(.fff)"`, or a sum of `<number><unit>` terms with
/// units `d`, `h`, `m`, `s`, `ms` (`"1h30m"`, `"250ms"`), or bare seconds.
pub fn parse_duration(text: &str) -> Result<Duration, String> {
    let t = text.trim();
    let bad = || {
        format!("'{text}' is not a time; write \"HH:MM:SS\", \"HH:MM\", \"90s\", \"15m\", \"1h30m\" or a number of seconds")
    };
    if t.is_empty() {
        return Err(bad());
    }
    if t.contains(':') {
        let parts: Vec<&str> = t.split(':').collect();
        if !(2..=3).contains(&parts.len()) {
            return Err(bad());
        }
        let h: u64 = parts[0].parse().map_err(|_| bad())?;
        let m: u64 = parts[1].parse().map_err(|_| bad())?;
        let s: f64 = match parts.get(2) {
            Some(p) => p.parse().map_err(|_| bad())?,
            None => 0.0,
        };
        if m >= 60 || !(0.0..60.0).contains(&s) || parts[0].starts_with('-') {
            return Err(bad());
        }
        return secs(h as f64 * 3600.0 + m as f64 * 60.0 + s).map_err(|_| bad());
    }
    if let Ok(s) = t.parse::<f64>() {
        return secs(s).map_err(|_| bad());
    }
    let mut total = 0.0;
    let mut rest = t;
    while !rest.is_empty() {
        let n_end = rest
            .find(|c: char| !(c.is_ascii_digit() || c == '.'))
            .ok_or_else(bad)?;
        if n_end == 0 {
            return Err(bad());
        }
        let n: f64 = rest[..n_end].parse().map_err(|_| bad())?;
        let after = &rest[n_end..];
        let u_end = after
            .find(|c: char| c.is_ascii_digit() || c == '.')
            .unwrap_or(after.len());
        let factor = match after[..u_end].trim() {
            "d" => 86400.0,
            "h" => 3600.0,
            "m" | "min" => 60.0,
            "s" => 1.0,
            "ms" => 0.001,
            _ => return Err(bad()),
        };
        total += n * factor;
        rest = &after[u_end..];
    }
    secs(total).map_err(|_| bad())
}

/// `"YYYY-MM-DDTHH:MM:SS[.fff]Z"` (UTC) to a timestamp.
pub fn parse_start(text: &str) -> Result<Timestamp, String> {
    let bad = || format!("'{text}' is not a UTC start time like \"2024-06-21T00:00:00Z\"");
    let t = text.trim();
    let t = t
        .strip_suffix('Z')
        .or_else(|| t.strip_suffix("+00:00"))
        .ok_or_else(bad)?;
    let (date, time) = t.split_once(['T', ' ']).ok_or_else(bad)?;
    let d: Vec<&str> = date.split('-').collect();
    if d.len() != 3 {
        return Err(bad());
    }
    let y: i64 = d[0].parse().map_err(|_| bad())?;
    let mo: u32 = d[1].parse().map_err(|_| bad())?;
    let da: u32 = d[2].parse().map_err(|_| bad())?;
    if !(1970..=9999).contains(&y) || !(1..=12).contains(&mo) || !(1..=31).contains(&da) {
        return Err(bad());
    }
    let tod = parse_duration(time).map_err(|_| bad())?;
    if tod >= Duration::from_secs(86400) {
        return Err(bad());
    }
    let midnight = Timestamp::from_civil_utc(gridscada_tagdb::CivilTime {
        year: y,
        month: mo,
        day: da,
        hour: 0,
        minute: 0,
        second: 0,
        milli: 0,
    })
    .ok_or_else(bad)?;
    Ok(midnight.add(tod))
}

/// `HH:MM:SS` of an offset (hours may exceed 24).
pub fn format_offset(d: Duration) -> String {
    let s = d.as_secs();
    let ms = d.subsec_millis();
    if ms == 0 {
        format!("{:02}:{:02}:{:02}", s / 3600, (s / 60) % 60, s % 60)
    } else {
        format!(
            "{:02}:{:02}:{:02}.{:03}",
            s / 3600,
            (s / 60) % 60,
            s % 60,
            ms
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn durations() {
        assert_eq!(parse_duration("00:02:00"), Ok(Duration::from_secs(120)));
        assert_eq!(parse_duration("24:00"), Ok(Duration::from_secs(86400)));
        assert_eq!(parse_duration("1h30m"), Ok(Duration::from_secs(5400)));
        assert_eq!(parse_duration("250ms"), Ok(Duration::from_millis(250)));
        assert_eq!(parse_duration("1.5"), Ok(Duration::from_millis(1500)));
        assert!(parse_duration("00:61").is_err());
        assert!(parse_duration("2 fortnights").is_err());
        assert!(parse_duration("-5").is_err());
        assert!(parse_duration("").is_err());
        assert_eq!(format_offset(Duration::from_secs(3723)), "01:02:03");
    }

    #[test]
    fn start_times() {
        assert_eq!(parse_start("1970-01-01T00:00:00Z").unwrap().as_millis(), 0);
        assert_eq!(
            parse_start("2024-06-21T06:00:00Z").unwrap().as_millis(),
            1_718_949_600_000
        );
        assert!(parse_start("2024-13-01T00:00:00Z").is_err());
        assert!(parse_start("2024-06-21T00:00:00").is_err());
    }
}
