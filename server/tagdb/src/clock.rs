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
