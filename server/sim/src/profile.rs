//! Deterministic input profiles of the plant: irradiance, wind speed, demand.
//!
//! Owns how an environmental input is defined over plant time (built-in daily
//! curve, a constant, or a daily table). Must not touch the models' state:
//! a profile is a pure function of the time of day, so a replay at any clock
//! speed sees the same inputs.

use std::f64::consts::PI;

use gridscada_tagdb::Timestamp;
use serde::{Deserialize, Serialize};

/// How one plant input varies with time.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Profile {
    /// The simulator's built-in curve for this input (see docs/REGISTER_MAPS.md).
    Builtin,
    /// A fixed value.
    Constant(f64),
    /// The built-in curve times a factor (0.5: half the sun, 2: double the
    /// demand).
    Scaled(f64),
    /// `(hour of day UTC, value)` points, linearly interpolated and wrapping
    /// around midnight. Hours are in [0, 24).
    Daily(Vec<(f64, f64)>),
}

impl Profile {
    /// Checks a profile given through the control interface.
    pub fn check(&self) -> Result<(), String> {
        match self {
            Profile::Builtin => Ok(()),
            Profile::Constant(v) if v.is_finite() => Ok(()),
            Profile::Constant(v) => Err(format!("constant {v} is not a finite number")),
            Profile::Scaled(f) if f.is_finite() && (0.0..=10.0).contains(f) => Ok(()),
            Profile::Scaled(f) => Err(format!("scale factor {f} must be between 0 and 10")),
            Profile::Daily(points) => {
                if points.is_empty() {
                    return Err("a daily profile needs at least one point".into());
                }
                for (h, v) in points {
                    if !(h.is_finite() && (0.0..24.0).contains(h) && v.is_finite()) {
                        return Err(format!(
                            "daily point ({h}, {v}): hour must be in [0, 24) and value finite"
                        ));
                    }
                }
                Ok(())
            }
        }
    }

    /// The value at plant time `t`; `builtin` gives the built-in curve.
    pub fn value(&self, t: Timestamp, builtin: fn(f64) -> f64) -> f64 {
        let h = hour_of_day(t);
        match self {
            Profile::Builtin => builtin(h),
            Profile::Constant(v) => *v,
            Profile::Scaled(f) => f * builtin(h),
            Profile::Daily(points) => interpolate_daily(points, h),
        }
    }
}

pub use gridscada_config::daily::{hour_of_day, interpolate_daily};

/// Clear-sky plane-of-array irradiance, W/m²: a half sine from 06:00 to
/// 18:00 UTC peaking at 1000 W/m² at noon.
pub fn builtin_irradiance(h: f64) -> f64 {
    if (6.0..=18.0).contains(&h) {
        1000.0 * (PI * (h - 6.0) / 12.0).sin().max(0.0)
    } else {
        0.0
    }
}

/// Hub wind speed, m/s: a constant moderate wind.
pub fn builtin_wind_speed(_h: f64) -> f64 {
    8.0
}

/// Microgrid demand, kW: a 60 kW base with a morning peak at 08:00 and an
/// evening peak at 19:00.
pub fn builtin_demand(h: f64) -> f64 {
    let bump = |centre: f64, width: f64| {
        // Distance around the clock, so the evening peak wraps past midnight.
        let d = ((h - centre + 12.0).rem_euclid(24.0)) - 12.0;
        (-(d / width).powi(2)).exp()
    };
    60.0 + 25.0 * bump(8.0, 2.0) + 45.0 * bump(19.0, 2.5)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn daily_table_interpolates_and_wraps() {
        let p = Profile::Daily(vec![(6.0, 0.0), (12.0, 600.0), (18.0, 0.0)]);
        let at = |h: f64| p.value(Timestamp::from_millis((h * 3_600_000.0) as i64), |_| -1.0);
        assert_eq!(at(9.0), 300.0);
        assert_eq!(at(12.0), 600.0);
        assert_eq!(at(0.0), 0.0);
        let p = Profile::Daily(vec![(0.0, 10.0), (12.0, 20.0)]);
        let at = |h: f64| p.value(Timestamp::from_millis((h * 3_600_000.0) as i64), |_| -1.0);
        assert_eq!(at(18.0), 15.0); // between 12:00 (20) and 24:00 (10)
    }

    #[test]
    fn builtin_curves_are_plausible() {
        assert_eq!(builtin_irradiance(3.0), 0.0);
        assert!((builtin_irradiance(12.0) - 1000.0).abs() < 1e-9);
        let d = builtin_demand(19.0);
        assert!(d > 100.0 && d < 106.0, "{d}");
        assert!(builtin_demand(3.0) < 62.0);
    }

    #[test]
    fn check_refuses_bad_points() {
        assert!(Profile::Constant(f64::NAN).check().is_err());
        assert!(Profile::Daily(vec![]).check().is_err());
        assert!(Profile::Daily(vec![(24.0, 1.0)]).check().is_err());
        assert!(Profile::Daily(vec![(1.0, 1.0)]).check().is_ok());
        assert!(Profile::Scaled(-0.5).check().is_err());
        assert!(Profile::Scaled(f64::INFINITY).check().is_err());
        assert!(Profile::Scaled(0.0).check().is_ok());
    }

    #[test]
    fn scaled_profile_follows_the_builtin_curve() {
        let noon = Timestamp::from_millis(12 * 3_600_000);
        let p = Profile::Scaled(0.5);
        assert!((p.value(noon, builtin_irradiance) - 500.0).abs() < 1e-9);
        assert_eq!(Profile::Scaled(2.0).value(noon, |_| 30.0), 60.0);
    }
}
