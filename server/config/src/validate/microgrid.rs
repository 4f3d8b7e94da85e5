//! The microgrid: its units (ratings, costs, efficiencies) and their tags,
//! the dispatch period, daily forecast curves and the look-ahead horizon.

use std::collections::HashMap;

use gridscada_tagdb::ValueKind;
use serde_spanned::Spanned;

use crate::model::*;

use super::{need_tag, positive, Ctx};

/// Longest look-ahead the live loop accepts: a week of 15-minute periods.
pub(super) const MAX_HORIZON_PERIODS: f64 = 672.0;

pub(super) fn check_horizon(cx: &mut Ctx<'_>, mg: &MicrogridConfig, h: &HorizonConfig) {
    let owner = "[microgrid.horizon]";
    let n = *h.periods.get_ref();
    if !(n.fract() == 0.0 && (1.0..=MAX_HORIZON_PERIODS).contains(&n)) {
        cx.err(
            0,
            h.periods.span(),
            format!("{owner}: periods must be a whole number from 1 to {MAX_HORIZON_PERIODS}"),
        );
    }
    positive(cx, owner, "period_s", &h.period_s);
    positive(cx, owner, "resolve_s", &h.resolve_s);
    let dispatch = *mg.dispatch_period_s.get_ref();
    for (field, v) in [("period_s", &h.period_s), ("resolve_s", &h.resolve_s)] {
        if *v.get_ref() < dispatch {
            cx.err(
                0,
                v.span(),
                format!(
                    "{owner}: {field} ({} s) is shorter than dispatch_period_s ({dispatch} s)",
                    v.get_ref()
                ),
            );
        }
    }
    if let Some(adopt) = &h.adopt_after {
        let (a, resolve, period) = (
            *adopt.get_ref(),
            *h.resolve_s.get_ref(),
            *h.period_s.get_ref(),
        );
        if !(a.is_finite() && a >= 0.0 && a < resolve && a < period) {
            cx.err(
                0,
                adopt.span(),
                format!(
                    "{owner}: adopt_after_s ({a} s) must be 0 or more and shorter than \
                     resolve_s ({resolve} s) and period_s ({period} s): a plan is used \
                     before the next is due, while its first period lasts"
                ),
            );
        }
    }
    if !(h.blend_h.get_ref().is_finite() && *h.blend_h.get_ref() > 0.0) {
        cx.err(
            0,
            h.blend_h.span(),
            format!("{owner}: blend_h must be a positive number of hours"),
        );
    }
    if let Some(points) = &h.demand_forecast_kw {
        check_daily_points(cx, owner, "demand_forecast_kw", points, f64::INFINITY);
    }
    if let Some(r) = &h.reserve {
        let fracs = [r.load_frac, r.pv_frac, r.wind_frac];
        let fracs_ok = fracs.iter().all(|f| (0.0..=1.0).contains(f));
        let cost_ok = r.shortfall_cost_per_kwh.is_finite() && r.shortfall_cost_per_kwh >= 0.0;
        if !(fracs_ok && cost_ok) {
            cx.err(
                0,
                h.periods.span(),
                format!(
                    "{owner}: reserve needs load_frac, pv_frac and wind_frac in [0, 1] \
                     and a shortfall_cost_per_kwh of 0 or more"
                ),
            );
        }
    }
}

/// A daily curve: at least one point, hours distinct and in [0, 24), values
/// finite, not negative and at most `max`.
pub(super) fn check_daily_points(
    cx: &mut Ctx<'_>,
    owner: &str,
    field: &str,
    points: &DailyPoints,
    max: f64,
) {
    let pts = points.get_ref();
    if pts.is_empty() {
        cx.err(0, points.span(), format!("{owner}: {field} has no points"));
    }
    let mut seen: Vec<f64> = Vec::new();
    for (i, &(hour, value)) in pts.iter().enumerate() {
        let at = format!("{owner}: {field} point {} [{hour}, {value}]", i + 1);
        if !(hour.is_finite() && (0.0..24.0).contains(&hour)) {
            cx.err(
                0,
                points.span(),
                format!("{at}: the hour must be in [0, 24)"),
            );
        } else if seen.contains(&hour) {
            cx.err(
                0,
                points.span(),
                format!("{at}: hour {hour} is given twice"),
            );
        }
        seen.push(hour);
        if !(value.is_finite() && value >= 0.0) {
            cx.err(
                0,
                points.span(),
                format!("{at}: the value must be 0 or more"),
            );
        } else if value > max {
            cx.err(
                0,
                points.span(),
                format!("{at}: the value exceeds rated_kw {max}"),
            );
        }
    }
}

pub(super) fn check_microgrid<'t>(
    cx: &mut Ctx<'_>,
    mg: &MicrogridConfig,
    lookup: &dyn Fn(&str) -> Option<&'t TagConfig>,
) {
    let owner = "[microgrid]";
    positive(cx, owner, "dispatch_period_s", &mg.dispatch_period_s);
    let num = [ValueKind::Float, ValueKind::Int];
    need_tag(
        cx,
        mg.demand_tag.span(),
        owner,
        mg.demand_tag.get_ref(),
        lookup,
        &num,
        false,
    );
    if let Some(h) = &mg.horizon {
        check_horizon(cx, mg, h);
    }
    if let Some(price) = &mg.fuel_price_per_l {
        if !(price.get_ref().is_finite() && *price.get_ref() >= 0.0) {
            cx.err(
                0,
                price.span(),
                format!("{owner}: fuel_price_per_l must be 0 or more"),
            );
        }
    }
    let mut ids: HashMap<&str, &Spanned<String>> = HashMap::new();
    for u in &mg.units {
        let id = u.id.get_ref();
        let owner = format!("microgrid unit '{id}'");
        if let Some(points) = &u.forecast_kw {
            if matches!(u.kind, UnitKind::Pv | UnitKind::Wind) {
                check_daily_points(cx, &owner, "forecast_kw", points, u.rated_kw);
            } else {
                cx.err(
                    0,
                    points.span(),
                    format!("{owner}: forecast_kw is for PV and wind units only"),
                );
            }
        }
        if let Some(prev) = ids.insert(id, &u.id) {
            let first = cx.place(0, prev.span());
            cx.err(
                0,
                u.id.span(),
                format!("duplicate unit id '{id}' (first defined at {first})"),
            );
        }
        let io = u.io();
        for tag in u.required_tags() {
            let kinds: &[ValueKind] = if tag == io.running || tag == io.run_cmd {
                &[ValueKind::Bool]
            } else {
                &num
            };
            let writable = tag == io.setpoint_kw || tag == io.run_cmd;
            need_tag(cx, u.prefix.span(), &owner, &tag, lookup, kinds, writable);
        }
        match u.kind {
            UnitKind::Storage => {
                if !(0.0 <= u.soc_min_kwh
                    && u.soc_min_kwh < u.soc_max_kwh
                    && u.soc_max_kwh <= u.capacity_kwh)
                {
                    cx.err(
                        0,
                        u.id.span(),
                        format!(
                            "{owner}: storage needs 0 <= soc_min_kwh < soc_max_kwh <= capacity_kwh"
                        ),
                    );
                }
                for eff in [&u.eff_charge, &u.eff_discharge] {
                    if !(*eff.get_ref() > 0.0 && *eff.get_ref() <= 1.0) {
                        cx.err(
                            0,
                            eff.span(),
                            format!("{owner}: efficiencies must be in (0, 1]"),
                        );
                    }
                }
                if u.max_charge_kw <= 0.0 || u.max_discharge_kw <= 0.0 {
                    cx.err(
                        0,
                        u.id.span(),
                        format!(
                            "{owner}: storage needs positive max_charge_kw and max_discharge_kw"
                        ),
                    );
                }
            }
            UnitKind::Diesel => {
                if !(0.0 <= u.min_kw && u.min_kw <= u.max_kw && u.max_kw > 0.0) {
                    cx.err(
                        0,
                        u.id.span(),
                        format!("{owner}: diesel needs 0 <= min_kw <= max_kw, max_kw > 0"),
                    );
                }
                check_diesel_costs(cx, mg, u, &owner);
            }
            UnitKind::Pv | UnitKind::Wind => {
                if u.rated_kw <= 0.0 {
                    cx.err(
                        0,
                        u.id.span(),
                        format!("{owner}: rated_kw must be positive"),
                    );
                }
            }
        }
        if u.kind != UnitKind::Diesel {
            let diesel_only = [
                ("fuel_no_load_l_per_h", u.fuel_no_load_l_per_h.is_some()),
                ("fuel_l_per_kwh", u.fuel_l_per_kwh.is_some()),
                ("start_cost", u.start_cost != 0.0),
                ("min_up_s", u.min_up_s.is_some()),
                ("min_down_s", u.min_down_s.is_some()),
            ];
            for (field, set) in diesel_only {
                if set {
                    cx.err(
                        0,
                        u.id.span(),
                        format!("{owner}: {field} is for diesel units only"),
                    );
                }
            }
        }
        if u.cost_per_kwh < 0.0 || u.cycle_cost_per_kwh < 0.0 {
            cx.err(
                0,
                u.id.span(),
                format!("{owner}: costs must not be negative"),
            );
        }
    }
}

/// A diesel's fuel curve, start cost and minimum up/down times: each finite
/// and not negative, and a fuel curve only together with a fuel price.
fn check_diesel_costs(cx: &mut Ctx<'_>, mg: &MicrogridConfig, u: &UnitConfig, owner: &str) {
    let fields = [
        ("fuel_no_load_l_per_h", u.fuel_no_load_l_per_h),
        ("fuel_l_per_kwh", u.fuel_l_per_kwh),
        ("start_cost", Some(u.start_cost)),
        ("min_up_s", u.min_up_s),
        ("min_down_s", u.min_down_s),
    ];
    for (field, v) in fields {
        if let Some(v) = v {
            if !(v.is_finite() && v >= 0.0) {
                cx.err(
                    0,
                    u.id.span(),
                    format!("{owner}: {field} must be a number of 0 or more, not {v}"),
                );
            }
        }
    }
    if u.fuel_no_load_l_per_h.is_some() && u.fuel_l_per_kwh.is_none() {
        cx.err(
            0,
            u.id.span(),
            format!("{owner}: fuel_no_load_l_per_h needs fuel_l_per_kwh (the fuel curve's slope)"),
        );
    }
    if u.fuel_l_per_kwh.is_some() && mg.fuel_price_per_l.is_none() {
        cx.err(
            0,
            u.id.span(),
            format!("{owner}: a fuel curve needs [microgrid] fuel_price_per_l to become a cost"),
        );
    }
}
