//! Plant time.
//!
//! Every loop that waits (scan periods, sequence timers, the dispatch period)
//! asks a [`Clock`] rather than the OS, so that scenario replay can run the whole
//! stack on a compressed clock and have everything advance together.

use std::fmt;
use std::future::Future;
use std::pin::Pin;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use serde::{Deserialize, Serialize};

/// Milliseconds since the Unix epoch, UTC.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(transparent)]
pub struct Timestamp(i64);

impl Timestamp {
    pub const fn from_millis(ms: i64) -> Self {
        Timestamp(ms)
    }
    pub const fn as_millis(self) -> i64 {
        self.0
    }
    pub fn as_secs_f64(self) -> f64 {
        self.0 as f64 / 1000.0
    }
    pub fn now_utc() -> Self {
        let d = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .unwrap_or(Duration::ZERO);
        Timestamp(d.as_millis() as i64)
    }
    /// `self + d`, saturating.
    // Named like the std method on purpose: `t.add(d)` reads naturally and
    // needs no trait import. Saturates instead of panicking.
    #[allow(clippy::should_implement_trait)]
    pub fn add(self, d: Duration) -> Self {
        Timestamp(self.0.saturating_add(d.as_millis() as i64))
    }
    /// Time from `earlier` to `self`; zero if `earlier` is later.
    pub fn since(self, earlier: Timestamp) -> Duration {
        Duration::from_millis(self.0.saturating_sub(earlier.0).max(0) as u64)
    }
}

/// A UTC calendar date and time of day (proleptic Gregorian).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CivilTime {
    pub year: i64,
    pub month: u32,
    pub day: u32,
    pub hour: u32,
    pub minute: u32,
    pub second: u32,
    pub milli: u32,
}

impl Timestamp {
    /// The UTC calendar date and time (H. Hinnant's civil-from-days).
    pub fn civil_utc(self) -> CivilTime {
        let secs = self.0.div_euclid(1000);
        let days = secs.div_euclid(86_400);
        let sod = secs.rem_euclid(86_400) as u32;
        let z = days + 719_468;
        let era = z.div_euclid(146_097);
        let doe = z.rem_euclid(146_097);
        let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
        let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
        let mp = (5 * doy + 2) / 153;
        let day = (doy - (153 * mp + 2) / 5 + 1) as u32;
        let month = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
        CivilTime {
            year: yoe + era * 400 + i64::from(month <= 2),
            month,
            day,
            hour: sod / 3600,
            minute: sod % 3600 / 60,
            second: sod % 60,
            milli: self.0.rem_euclid(1000) as u32,
        }
    }

    /// The instant of a UTC calendar date and time; `None` for a date or time
    /// that does not exist (month 13, 31 April, 24:00, second 60).
    pub fn from_civil_utc(c: CivilTime) -> Option<Timestamp> {
        let days_in_month = match c.month {
            1 | 3 | 5 | 7 | 8 | 10 | 12 => 31,
            4 | 6 | 9 | 11 => 30,
            2 if c.year % 4 == 0 && (c.year % 100 != 0 || c.year % 400 == 0) => 29,
            2 => 28,
            _ => return None,
        };
        if c.day == 0
            || c.day > days_in_month
            || c.hour > 23
            || c.minute > 59
            || c.second > 59
            || c.milli > 999
        {
            return None;
        }
        // Days since 1970-01-01 (H. Hinnant's days-from-civil).
        let y = if c.month <= 2 { c.year - 1 } else { c.year };
        let era = y.div_euclid(400);
        let yoe = y - era * 400;
        let mp = (i64::from(c.month) + 9) % 12;
        let doy = (153 * mp + 2) / 5 + i64::from(c.day) - 1;
        let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
        let days = era * 146_097 + doe - 719_468;
        let secs = days * 86_400 + i64::from(c.hour * 3600 + c.minute * 60 + c.second);
        Some(Timestamp(
            secs.checked_mul(1000)?.checked_add(i64::from(c.milli))?,
        ))
    }

    /// RFC 3339 UTC to the second: `2026-11-25T13:30:00Z`.
    pub fn utc_text(self) -> String {
        let c = self.civil_utc();
        format!(
            "{:04}-{:02}-{:02}T{:02}:{:02}:{:02}Z",
            c.year, c.month, c.day, c.hour, c.minute, c.second
        )
    }

    /// Reads [`Timestamp::utc_text`]'s form back (milliseconds allowed:
    /// `…T13:30:00.250Z`).
    pub fn parse_utc_text(text: &str) -> Option<Timestamp> {
        let t = text.trim().strip_suffix('Z')?;
        let (date, time) = t.split_once('T')?;
        let mut d = date.splitn(3, '-');
        let (year, month, day) = (
            d.next()?.parse().ok()?,
            d.next()?.parse().ok()?,
            d.next()?.parse().ok()?,
        );
        let (hms, frac) = time.split_once('.').unwrap_or((time, "0"));
        let mut h = hms.splitn(3, ':');
        let (hour, minute, second) = (
            h.next()?.parse().ok()?,
            h.next()?.parse().ok()?,
            h.next()?.parse().ok()?,
        );
        if frac.is_empty() || frac.len() > 3 || !frac.bytes().all(|b| b.is_ascii_digit()) {
            return None;
        }
        let milli = frac.parse::<u32>().ok()? * 10u32.pow(3 - frac.len() as u32);
        Timestamp::from_civil_utc(CivilTime {
            year,
            month,
            day,
            hour,
            minute,
            second,
            milli,
        })
    }
}

#[cfg(test)]
mod civil_tests {
    use super::*;

    #[test]
    fn civil_dates_round_trip_and_impossible_ones_are_refused() {
        for ms in [
            0,
            -1,
            951_782_400_000,
            1_735_689_599_999,
            4_102_444_800_123,
            -62_135_596_800_000,
        ] {
            let t = Timestamp::from_millis(ms);
            assert_eq!(Timestamp::from_civil_utc(t.civil_utc()), Some(t), "{ms}");
        }
        let c = |year, month, day, hour| CivilTime {
            year,
            month,
            day,
            hour,
            minute: 0,
            second: 0,
            milli: 0,
        };
        assert_eq!(
            Timestamp::from_civil_utc(c(2000, 2, 29, 0)),
            Some(Timestamp::from_millis(951_782_400_000))
        );
        assert_eq!(Timestamp::from_civil_utc(c(1900, 2, 29, 0)), None);
        assert_eq!(Timestamp::from_civil_utc(c(2026, 4, 31, 0)), None);
        assert_eq!(Timestamp::from_civil_utc(c(2026, 13, 1, 0)), None);
        assert_eq!(Timestamp::from_civil_utc(c(2026, 1, 1, 24)), None);
        let t = Timestamp::from_millis(1_764_077_400_000);
        assert_eq!(t.utc_text(), "2025-11-25T13:30:00Z");
        assert_eq!(Timestamp::parse_utc_text("2025-11-25T13:30:00Z"), Some(t));
        assert_eq!(
            Timestamp::parse_utc_text("2025-11-25T13:30:00.25Z"),
            Some(Timestamp::from_millis(1_764_077_400_250))
        );
        assert_eq!(Timestamp::parse_utc_text("2025-11-25 13:30:00"), None);
    }
}

impl fmt::Display for Timestamp {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}ms", self.0)
    }
}

pub type SleepFuture = Pin<Box<dyn Future<Output = ()> + Send>>;

/// The source of plant time.
pub trait Clock: Send + Sync + 'static {
    /// The current plant time.
    fn now(&self) -> Timestamp;
    /// Waits for `d` of plant time.
    fn sleep(&self, d: Duration) -> SleepFuture;
    /// How many plant seconds pass per wall second (1 for the live plant).
    fn speed(&self) -> f64 {
        1.0
    }
    /// A wall-clock duration for `d` of plant time, e.g. for Modbus timeouts
    /// that must shrink with the clock's speed.
    fn to_wall(&self, d: Duration) -> Duration {
        d.div_f64(self.speed().max(1e-9))
    }
    /// How long a request to a device waits for its answer, where this
    /// clock measures that otherwise than [`Clock::to_wall`] of wall time:
    /// a replay's virtual clock counts only the time its runtime sat idle
    /// waiting, so a runtime that was busy (a long solve) or descheduled
    /// never times out a device that did answer. `None`: wall time.
    fn request_wait(&self, _d: Duration) -> Option<SleepFuture> {
        None
    }
}

/// The live plant: plant time is wall time.
#[derive(Debug, Default, Clone, Copy)]
pub struct SystemClock;

impl Clock for SystemClock {
    fn now(&self) -> Timestamp {
        Timestamp::now_utc()
    }
    fn sleep(&self, d: Duration) -> SleepFuture {
        Box::pin(tokio::time::sleep(d))
    }
}

/// A compressed clock for replay: plant time starts at `start` and runs `speed`
/// times faster than the wall clock.
#[derive(Debug, Clone)]
pub struct ScaledClock {
    start: Timestamp,
    origin: Instant,
    speed: f64,
}

impl ScaledClock {
    pub fn new(start: Timestamp, speed: f64) -> Self {
        assert!(
            speed > 0.0 && speed.is_finite(),
            "clock speed must be positive"
        );
        ScaledClock {
            start,
            origin: Instant::now(),
            speed,
        }
    }
}

impl Clock for ScaledClock {
    fn now(&self) -> Timestamp {
        let plant = self.origin.elapsed().mul_f64(self.speed);
        self.start.add(plant)
    }
    fn sleep(&self, d: Duration) -> SleepFuture {
        Box::pin(tokio::time::sleep(d.div_f64(self.speed)))
    }
    fn speed(&self) -> f64 {
        self.speed
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn since_saturates() {
        let a = Timestamp::from_millis(1000);
        let b = Timestamp::from_millis(1500);
        assert_eq!(b.since(a), Duration::from_millis(500));
        assert_eq!(a.since(b), Duration::ZERO);
    }

    #[tokio::test]
    async fn scaled_clock_runs_faster() {
        let c = ScaledClock::new(Timestamp::from_millis(0), 100.0);
        c.sleep(Duration::from_secs(2)).await; // 20 ms of wall time
        assert!(c.now().as_millis() >= 2000);
    }
}
