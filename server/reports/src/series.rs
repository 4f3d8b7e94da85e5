//! Historian samples as step-held time series: a sample's value holds until
//! the next sample, or for at most `hold_ms` (the recorder re-logs a flat
//! value at the tag's max interval, so a longer silence means the server
//! saw nothing: that time is unknown, not the last value). Pure, no I/O.

/// One logged sample: time (ms since the epoch), its number, and whether
/// its quality was Good. A sample without a number, or not Good, makes the
/// time until the next one unknown.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    pub ts: i64,
    pub value: Option<f64>,
    pub good: bool,
}

impl Sample {
    pub fn new(ts: i64, value: f64) -> Self {
        Sample {
            ts,
            value: Some(value),
            good: true,
        }
    }
    fn known(&self) -> Option<f64> {
        self.value.filter(|v| self.good && v.is_finite())
    }
}

/// A stretch of time with one state: `value` is `None` where unknown.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Segment {
    pub start: i64,
    pub end: i64,
    pub value: Option<f64>,
}

impl Segment {
    pub fn hours(&self) -> f64 {
        (self.end - self.start) as f64 / 3_600_000.0
    }
}

/// The segments of `samples` (oldest first; the last one before `from` should
/// be included so the state at `from` is known) covering `from..to` exactly.
pub fn segments(samples: &[Sample], from: i64, to: i64, hold_ms: i64) -> Vec<Segment> {
    let mut out: Vec<Segment> = Vec::new();
    let mut push = |start: i64, end: i64, value: Option<f64>| {
        let (start, end) = (start.max(from), end.min(to));
        if end <= start {
            return;
        }
        match out.last_mut() {
            Some(last) if last.value == value && last.end == start => last.end = end,
            _ => out.push(Segment { start, end, value }),
        }
    };
    let mut cursor = from;
    for (i, s) in samples.iter().enumerate() {
        let next = samples.get(i + 1).map_or(to, |n| n.ts);
        if s.ts > cursor {
            push(cursor, s.ts, None);
        }
        let held = next.min(s.ts.saturating_add(hold_ms.max(0)));
        push(s.ts, held, s.known());
        push(held, next, None);
        cursor = cursor.max(next);
    }
    if cursor < to {
        push(cursor, to, None);
    }
    out
}

/// What integrating a power series gives: energy in value·hours (kWh for
/// kW), split by sign, and how much of the period was known.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Integral {
    /// ∫ max(v, 0) dt, value·h.
    pub positive: f64,
    /// ∫ max(−v, 0) dt, value·h (a positive number).
    pub negative: f64,
    /// Time with a known value, h.
    pub known_h: f64,
    /// Time with a value above `on_threshold` (see [`integrate`]), h.
    pub on_h: f64,
    /// Times the value rose to above `on_threshold` from a known value at or
    /// below it.
    pub rises: u32,
}

impl Integral {
    pub fn net(&self) -> f64 {
        self.positive - self.negative
    }
}

/// Integrates segments: energy by sign, known time, and the time and rising
/// edges above `on_threshold` (0.5 for a boolean's true).
pub fn integrate(segs: &[Segment], on_threshold: f64) -> Integral {
    let mut r = Integral::default();
    let mut prev: Option<f64> = None;
    for s in segs {
        let Some(v) = s.value else {
            continue;
        };
        let h = s.hours();
        r.known_h += h;
        if v > 0.0 {
            r.positive += v * h;
        } else {
            r.negative += -v * h;
        }
        if v > on_threshold {
            r.on_h += h;
            if prev.is_some_and(|p| p <= on_threshold) {
                r.rises += 1;
            }
        }
        prev = Some(v);
    }
    r
}

/// The mean of the known values over `segs`, time-weighted; `None` if no
/// time is known.
pub fn mean(segs: &[Segment]) -> Option<f64> {
    let i = integrate(segs, f64::INFINITY);
    (i.known_h > 0.0).then(|| i.net() / i.known_h)
}

/// The value at time `t`: that of the segment holding it.
pub fn value_at(segs: &[Segment], t: i64) -> Option<f64> {
    let i = segs.partition_point(|s| s.end <= t);
    segs.get(i).filter(|s| s.start <= t).and_then(|s| s.value)
}

/// The times at which any of `series` changes, with `from` and `to`: the
/// edges of the stretches over which all of them are constant.
pub fn edges(series: &[&[Segment]], from: i64, to: i64) -> Vec<i64> {
    let mut t: Vec<i64> = vec![from, to];
    for s in series {
        t.extend(s.iter().flat_map(|g| [g.start, g.end]));
    }
    t.retain(|&x| (from..=to).contains(&x));
    t.sort_unstable();
    t.dedup();
    t
}

#[cfg(test)]
mod tests {
    use super::*;

    const H: i64 = 3_600_000;

    #[test]
    fn a_constant_held_between_samples_integrates_to_power_times_time() {
        let s = [Sample::new(-10, 4.0), Sample::new(H, 4.0)];
        let segs = segments(&s, 0, 2 * H, 2 * H);
        let i = integrate(&segs, 0.5);
        assert!((i.positive - 8.0).abs() < 1e-9);
        assert!((i.known_h - 2.0).abs() < 1e-9);
    }

    #[test]
    fn a_silence_longer_than_the_hold_is_unknown_not_the_last_value() {
        let s = [Sample::new(0, 10.0)];
        let segs = segments(&s, 0, 4 * H, H);
        let i = integrate(&segs, 0.5);
        assert!((i.positive - 10.0).abs() < 1e-9);
        assert!((i.known_h - 1.0).abs() < 1e-9);
        assert_eq!(value_at(&segs, 2 * H), None);
    }

    #[test]
    fn bad_samples_and_time_before_the_first_sample_are_unknown() {
        let s = [
            Sample::new(H, 2.0),
            Sample {
                ts: 2 * H,
                value: Some(99.0),
                good: false,
            },
            Sample::new(3 * H, -1.0),
        ];
        let segs = segments(&s, 0, 4 * H, 10 * H);
        let i = integrate(&segs, 0.5);
        assert!((i.positive - 2.0).abs() < 1e-9);
        assert!((i.negative - 1.0).abs() < 1e-9);
        assert!((i.known_h - 2.0).abs() < 1e-9);
    }

    #[test]
    fn on_time_and_rises_count_a_boolean_switching() {
        let s = [
            Sample::new(0, 0.0),
            Sample::new(H, 1.0),
            Sample::new(2 * H, 0.0),
            Sample::new(3 * H, 1.0),
        ];
        let segs = segments(&s, 0, 4 * H, 10 * H);
        let i = integrate(&segs, 0.5);
        assert!((i.on_h - 2.0).abs() < 1e-9);
        assert_eq!(i.rises, 2);
    }

    #[test]
    fn mean_and_value_at() {
        let s = [Sample::new(0, 1.0), Sample::new(H, 3.0)];
        let segs = segments(&s, 0, 2 * H, 10 * H);
        assert_eq!(mean(&segs), Some(2.0));
        assert_eq!(value_at(&segs, H), Some(3.0));
        assert_eq!(value_at(&segs, H - 1), Some(1.0));
    }
}
