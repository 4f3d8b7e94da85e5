//! Daily curves: a value that depends only on the hour of day (UTC), given
//! as `(hour, value)` points and interpolated linearly, wrapping at midnight.
//! The simulators' profiles and the dispatch forecasts read the same curves.

use gridscada_tagdb::Timestamp;

/// Hour of day (UTC) of a plant time, in [0, 24).
pub fn hour_of_day(t: Timestamp) -> f64 {
    (t.as_millis().rem_euclid(86_400_000)) as f64 / 3_600_000.0
}

/// The curve through `points` (any order) at hour `h`; between the last
/// point and the first it wraps through midnight. No points: 0.
pub fn interpolate_daily(points: &[(f64, f64)], h: f64) -> f64 {
    let mut pts: Vec<(f64, f64)> = points.to_vec();
    pts.sort_by(|a, b| a.0.total_cmp(&b.0));
    let Some(&first) = pts.first() else {
        return 0.0;
    };
    let last = pts[pts.len() - 1];
    if pts.len() == 1 {
        return first.1;
    }
    // Segment containing h, wrapping from the last point to the first + 24 h.
    for w in pts.windows(2) {
        if h >= w[0].0 && h <= w[1].0 {
            return lerp(w[0], w[1], h);
        }
    }
    let wrapped = (first.0 + 24.0, first.1);
    let hh = if h < first.0 { h + 24.0 } else { h };
    lerp(last, wrapped, hh)
}

fn lerp(a: (f64, f64), b: (f64, f64), x: f64) -> f64 {
    let span = b.0 - a.0;
    if span <= 0.0 {
        return a.1;
    }
    a.1 + (b.1 - a.1) * (x - a.0) / span
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interpolates_and_wraps_through_midnight() {
        let day = [(6.0, 0.0), (12.0, 600.0), (18.0, 0.0)];
        assert_eq!(interpolate_daily(&day, 9.0), 300.0);
        assert_eq!(interpolate_daily(&day, 12.0), 600.0);
        assert_eq!(interpolate_daily(&day, 0.0), 0.0);
        let two = [(12.0, 20.0), (0.0, 10.0)];
        assert_eq!(interpolate_daily(&two, 18.0), 15.0);
        assert_eq!(interpolate_daily(&[(3.0, 7.0)], 20.0), 7.0);
        assert_eq!(interpolate_daily(&[], 20.0), 0.0);
        assert_eq!(hour_of_day(Timestamp::from_millis(-3_600_000)), 23.0);
    }
}
