//! The replay report: what a run measured, as JSON (serde) and as the model
//! the HTML page is rendered from ([`super::html`]).
//!
//! Owns the report's shape and the cost arithmetic. Must not touch the
//! running stack: the runner fills it in.

use std::collections::BTreeMap;

use serde::Serialize;

use super::expect::ExpectationResult;

#[derive(Debug, Clone, Serialize)]
pub struct Report {
    pub scenario: String,
    pub description: String,
    pub file: String,
    /// The plant configuration replayed ("embedded demo plant" or a path).
    pub plant: String,
    /// Seed of every random draw; the same seed gives the same run.
    pub seed: u64,
    /// Plant time of the start, ms since the Unix epoch (UTC).
    pub start_ms: i64,
    pub duration_s: f64,
    pub step_s: f64,
    /// How plant time ran ("virtual (--max)" or "scaled ×N").
    pub clock: String,
    pub wall_s: f64,
    /// Plant seconds per wall second of the main run.
    pub speedup: f64,
    /// Every expectation passed.
    pub passed: bool,
    /// Every figure by name (see docs/SCENARIOS.md); `[[expect]] figure`
    /// judges these.
    pub figures: BTreeMap<String, f64>,
    pub cost: CostComparison,
    pub alarms: AlarmSummary,
    /// One entry per completed fault-isolation sequence.
    pub faults: Vec<FaultRecord>,
    pub expectations: Vec<ExpectationResult>,
    pub timeline: Vec<TimelineEntry>,
    pub plots: Vec<Plot>,
    /// Anything the reader should know about the run itself.
    pub notes: Vec<String>,
}

/// Costs of one run, in the plant's currency.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct CostBreakdown {
    /// Diesel cost by the dispatch's cost model (`DieselCost`: fuel curve
    /// at the fuel price, starts).
    pub fuel: f64,
    /// Energy of non-diesel units × their cost_per_kwh.
    pub energy: f64,
    /// Storage throughput (charged + discharged) × cycle_cost_per_kwh / 2.
    pub storage_cycling: f64,
    /// Unserved energy × the value of lost load (voll_per_kwh).
    pub unserved: f64,
    pub total: f64,
}

impl CostBreakdown {
    pub fn new(fuel: f64, energy: f64, storage_cycling: f64, unserved: f64) -> Self {
        CostBreakdown {
            fuel,
            energy,
            storage_cycling,
            unserved,
            total: fuel + energy + storage_cycling + unserved,
        }
    }
}

/// The perfect-foresight optimum of the replayed day: the same cost model,
/// every period's demand and availability known in advance, the diesels'
/// commitment decided over the whole day.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Foresight {
    /// "optimal", or "failed" with the reason.
    pub status: String,
    pub reason: Option<String>,
    /// Cost of the best schedule found.
    pub cost: Option<f64>,
    /// No schedule costs less than this (equal to `cost` when proven).
    pub lower_bound: Option<f64>,
    /// The schedule is proven within 0.1 % of the optimum.
    pub proven: bool,
    /// Relaxations the commitment search solved.
    pub nodes: usize,
    pub periods: usize,
    pub period_s: f64,
    /// Hours of the run the optimum covers (whole periods).
    pub covered_h: f64,
    pub diesel_runtime_h: f64,
    pub diesel_starts: u32,
    pub solve_ms: f64,
}

#[derive(Debug, Clone, Default, Serialize)]
pub struct CostComparison {
    pub fuel_price_per_l: f64,
    pub voll_per_kwh: f64,
    /// The stack as configured (LP dispatch with its fallback).
    pub optimal: CostBreakdown,
    /// The same scenario replayed with the rule-based dispatch only.
    pub rule: Option<CostBreakdown>,
    /// The day's optimum with perfect foresight (see `optimum_ratio`).
    pub optimum: Option<Foresight>,
    /// optimal.total / rule.total (below 1: the LP saved money).
    pub ratio: Option<f64>,
}

#[derive(Debug, Clone, Default, Serialize)]
pub struct AlarmSummary {
    /// Annunciated activations during the run.
    pub activations: u32,
    /// (priority, activations), highest priority first.
    pub by_priority: Vec<(u32, u32)>,
    /// ISA-18.2: mean and peak activations per operator per 10 minutes.
    pub average_per_10min: f64,
    pub max_per_10min: f64,
    /// Periods of more than 10 activations per 10 minutes.
    pub floods: u32,
    pub percent_time_in_flood: f64,
    /// Alarms activated 3+ times within a minute.
    pub chattering: Vec<String>,
    /// Most frequent alarms (key, activations).
    pub top: Vec<(String, u32)>,
    pub active_end: usize,
    pub unacked_end: usize,
}

/// A completed fault-isolation sequence (from the panel's `last_sequence`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FaultRecord {
    pub panel: String,
    /// Offset when the sequence finished, s.
    pub at_s: f64,
    pub outcome: String,
    /// `None` when the sequence did not restore (lockout, stopped).
    pub restore_s: Option<f64>,
    pub bound_s: f64,
    pub switching_ops: u32,
    pub reenergisations: u32,
    pub trips: u32,
    pub elcb_resets: u32,
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TimelineEntry {
    /// Offset from the start, s.
    pub at_s: f64,
    /// "scenario", "alarm", "event" or "sequence".
    pub source: String,
    pub text: String,
    pub priority: Option<u32>,
}

/// One plot: shared time axis, one line per series.
#[derive(Debug, Clone, Serialize)]
pub struct Plot {
    pub title: String,
    pub unit: String,
    /// Offsets from the start, s.
    pub t_s: Vec<f64>,
    pub lines: Vec<Line>,
}

#[derive(Debug, Clone, Serialize)]
pub struct Line {
    pub name: String,
    pub values: Vec<f64>,
}

impl Report {
    /// Failed expectations.
    pub fn failures(&self) -> impl Iterator<Item = &ExpectationResult> {
        self.expectations.iter().filter(|e| !e.passed)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cost_total_is_the_sum() {
        let c = CostBreakdown::new(10.0, 1.0, 0.5, 2.0);
        assert_eq!(c.total, 13.5);
    }
}
