//! The names a scenario uses (panels, zones, breakers, units, devices,
//! tags, figures), kept while parsing and checked against a plant
//! ([`Scenario::check_against`]).

use gridscada_config::{Diagnostic, Plant, UnitKind};

use crate::scenario::Scenario;

/// Figures of the whole run that `[[expect]] figure = ...` may name
/// (documented in docs/SCENARIOS.md).
pub const FIGURE_NAMES: &[&str] = &[
    "demand_kwh",
    "served_kwh",
    "unserved_kwh",
    "curtailed_kwh",
    "surplus_kwh",
    "pv_kwh",
    "wind_kwh",
    "diesel_kwh",
    "diesel_fuel_l",
    "diesel_starts",
    "diesel_runtime_h",
    "storage_charged_kwh",
    "storage_discharged_kwh",
    "storage_throughput_kwh",
    "soc_min_pct",
    "soc_end_pct",
    "fuel_cost",
    "total_cost",
    "rule_total_cost",
    "cost_ratio",
    "optimum_cost",
    "optimum_ratio",
    "optimum_lower_bound",
    "optimum_bound_ratio",
    "dispatch_shed_kwh",
    "dispatch_fallback_periods",
    "alarm_activations",
    "alarm_active_end",
    "alarm_unacked_end",
    "alarm_floods",
    "alarm_max_per_10min",
    "alarm_avg_per_10min",
    "alarm_percent_in_flood",
    "alarm_chattering",
    "fault_sequences",
    "poll_timeouts",
    "historian_dropped",
    "wall_s",
    "speedup",
];

/// Figures per panel, named `<panel id>.<figure>` (e.g. `ss1.restore_s_max`).
pub const PANEL_FIGURE_NAMES: &[&str] = &[
    "sequences",
    "restore_s_max",
    "restore_s_last",
    "switching_ops",
    "reenergisations",
    "elcb_trips",
    "lockout",
    "zones_closed_end",
];

/// A name the scenario uses, kept to be checked against the plant.
#[derive(Debug, Clone)]
pub(crate) struct NameRef {
    pub(super) kind: RefKind,
    pub(super) name: String,
    pub(super) at: (usize, usize),
}

#[derive(Debug, Clone, PartialEq)]
pub(super) enum RefKind {
    Panel,
    /// Zone number of the named panel; whether zone 0 (busbar) is allowed.
    Zone(u8, bool),
    Breaker(String),
    Unit,
    StorageUnit,
    Device,
    Tag,
    Figure,
    /// A microgrid input: the plant must have a microgrid.
    Microgrid,
}

impl Scenario {
    /// Checks every panel, zone, breaker, unit, device, tag and figure the
    /// scenario names against `plant`; `tag_exists` knows the tag database
    /// (which also holds derived tags such as `SS1.Seq.Step`).
    pub fn check_against(
        &self,
        plant: &Plant,
        tag_exists: &dyn Fn(&str) -> bool,
    ) -> Vec<Diagnostic> {
        let mut out = Vec::new();
        let mut err = |at: (usize, usize), message: String| {
            out.push(Diagnostic {
                file: self.path.clone(),
                line: at.0,
                column: at.1,
                message,
            })
        };
        let panel = |name: &str| {
            plant
                .panels
                .iter()
                .find(|p| p.id.get_ref() == name || p.prefix.get_ref() == name)
        };
        let panel_ids: Vec<String> = plant
            .panels
            .iter()
            .map(|p| p.id.get_ref().clone())
            .collect();
        let units: Vec<(String, String, UnitKind)> = plant
            .microgrid
            .as_ref()
            .map(|m| {
                m.units
                    .iter()
                    .map(|u| (u.id.get_ref().clone(), u.prefix.get_ref().clone(), u.kind))
                    .collect()
            })
            .unwrap_or_default();
        let mut seen_microgrid = false;
        for r in &self.refs {
            match &r.kind {
                RefKind::Panel => {
                    if panel(&r.name).is_none() {
                        err(
                            r.at,
                            format!(
                                "the plant has no panel '{}'; it has {}",
                                r.name,
                                panel_ids.join(", ")
                            ),
                        );
                    }
                }
                RefKind::Zone(z, allow_zero) => {
                    if let Some(p) = panel(&r.name) {
                        let n = *p.zones.get_ref();
                        if *z > n || (*z == 0 && !allow_zero) {
                            let lo = if *allow_zero { 0 } else { 1 };
                            err(
                                r.at,
                                format!(
                                    "panel '{}' has zones {lo}..={n}; there is no zone {z}",
                                    r.name
                                ),
                            );
                        }
                    }
                }
                RefKind::Breaker(b) => {
                    if let Some(p) = panel(&r.name) {
                        let n = *p.zones.get_ref();
                        let ok = b == "elcb"
                            || b == "mccb"
                            || b.strip_prefix("zone")
                                .and_then(|z| z.parse::<u8>().ok())
                                .is_some_and(|z| z >= 1 && z <= n);
                        if !ok {
                            err(r.at, format!("'{b}' is not a breaker of panel '{}'; use elcb, mccb or zone1..zone{n}", r.name));
                        }
                    }
                }
                RefKind::Unit | RefKind::StorageUnit => {
                    match units.iter().find(|(id, prefix, _)| *id == r.name || *prefix == r.name) {
                        None => err(
                            r.at,
                            if units.is_empty() {
                                format!("the plant has no microgrid, so no unit '{}'", r.name)
                            } else {
                                format!(
                                    "the plant has no microgrid unit '{}'; it has {}",
                                    r.name,
                                    units.iter().map(|u| u.0.as_str()).collect::<Vec<_>>().join(", ")
                                )
                            },
                        ),
                        Some((_, _, kind)) if r.kind == RefKind::StorageUnit && *kind != UnitKind::Storage => {
                            err(r.at, format!("'{}' is not a storage unit; only storage has a state of charge", r.name))
                        }
                        _ => {}
                    }
                }
                RefKind::Device => {
                    let known = plant.devices.iter().any(|d| {
                        d.name.get_ref() == &r.name
                            || d.address.as_ref().is_some_and(|a| a.get_ref() == &r.name)
                    });
                    if !known {
                        err(
                            r.at,
                            format!("the plant has no device or gateway address '{}'", r.name),
                        );
                    }
                }
                RefKind::Tag => {
                    if !tag_exists(&r.name) {
                        err(r.at, format!("the tag database has no tag '{}'", r.name));
                    }
                }
                RefKind::Figure => {
                    let ok = FIGURE_NAMES.contains(&r.name.as_str())
                        || r.name.split_once('.').is_some_and(|(p, f)| {
                            panel_ids.iter().any(|id| id == p) && PANEL_FIGURE_NAMES.contains(&f)
                        });
                    if !ok {
                        err(r.at, format!("'{}' is not a report figure; see docs/SCENARIOS.md for the list (per panel: <panel>.{})", r.name, PANEL_FIGURE_NAMES.join(", <panel>.")));
                    }
                }
                RefKind::Microgrid => {
                    if plant.microgrid.is_none() && !seen_microgrid {
                        seen_microgrid = true;
                        err(
                            r.at,
                            format!(
                                "profile '{}' drives the microgrid, but the plant has none",
                                r.name
                            ),
                        );
                    }
                }
            }
        }
        out
    }
}
