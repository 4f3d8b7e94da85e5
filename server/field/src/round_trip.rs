//! The round trip of each request to a device (a Modbus read, an IEC 104
//! command or test frame), as a fixed-bucket histogram.
//!
//! Kept here, in plain atomics, so field I/O owes nothing to any exposition
//! format: `app` hands the snapshot to `/metrics`. The buckets are fixed
//! because they span what field links do, from about a millisecond over
//! Ethernet to a second or more on a slow serial line with many drops.

use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

/// Upper bounds of the buckets, in seconds; one more bucket holds the rest.
pub const ROUND_TRIP_BOUNDS: [f64; 12] = [
    0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0,
];

const BUCKETS: usize = ROUND_TRIP_BOUNDS.len() + 1;

/// Where the poller counts round trips: one per device, written by its link
/// task only, read by whoever reports.
#[derive(Default)]
pub struct RoundTrips {
    buckets: [AtomicU64; BUCKETS],
    sum_us: AtomicU64,
}

impl RoundTrips {
    pub fn observe(&self, elapsed: Duration) {
        let s = elapsed.as_secs_f64();
        let i = ROUND_TRIP_BOUNDS
            .iter()
            .position(|&b| s <= b)
            .unwrap_or(BUCKETS - 1);
        self.buckets[i].fetch_add(1, Ordering::Relaxed);
        self.sum_us.fetch_add(
            u64::try_from(elapsed.as_micros()).unwrap_or(u64::MAX),
            Ordering::Relaxed,
        );
    }

    pub fn snapshot(&self) -> RoundTripHistogram {
        let mut counts = [0; BUCKETS];
        for (c, b) in counts.iter_mut().zip(&self.buckets) {
            *c = b.load(Ordering::Relaxed);
        }
        RoundTripHistogram {
            counts,
            sum_s: self.sum_us.load(Ordering::Relaxed) as f64 / 1e6,
        }
    }
}

/// Round trips of the answered requests of one device (answers with an
/// exception included; timeouts are not round trips and are counted apart).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RoundTripHistogram {
    /// Requests per bucket (not cumulative): `counts[i]` took at most
    /// `ROUND_TRIP_BOUNDS[i]` and more than the bound before; the last took
    /// longer than every bound.
    pub counts: [u64; BUCKETS],
    /// Total time of all of them, seconds.
    pub sum_s: f64,
}

impl RoundTripHistogram {
    /// Requests counted.
    pub fn count(&self) -> u64 {
        self.counts.iter().sum()
    }

    /// Each bucket's upper bound (the last is infinity) with its count.
    pub fn buckets(&self) -> impl Iterator<Item = (f64, u64)> + '_ {
        ROUND_TRIP_BOUNDS
            .iter()
            .copied()
            .chain(std::iter::once(f64::INFINITY))
            .zip(self.counts.iter().copied())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_round_trip_lands_in_its_bucket() {
        let h = RoundTrips::default();
        h.observe(Duration::from_micros(800)); // ≤ 1 ms
        h.observe(Duration::from_millis(1)); // on the bound: ≤ 1 ms
        h.observe(Duration::from_millis(30)); // ≤ 50 ms
        h.observe(Duration::from_secs(9)); // past every bound
        let s = h.snapshot();
        assert_eq!(s.count(), 4);
        assert_eq!(s.counts[0], 2);
        assert_eq!(s.counts[5], 1);
        assert_eq!(s.counts[BUCKETS - 1], 1);
        assert!((s.sum_s - 9.0318).abs() < 1e-9, "{}", s.sum_s);
        let last = s.buckets().last().unwrap();
        assert_eq!(last, (f64::INFINITY, 1));
    }
}
