//! # Microgrid dispatch: the cascade's outer loop
//!
//! **Owns:** the dispatch problem (seed section 3, eqs. 1-7, extended as in
//! `docs/DISPATCH.md`): the single-period LP the live loop solves every
//! dispatch period ([`single`]), the multi-period look-ahead LP/QP
//! ([`horizon`]), both solved in-process with clarabel ([`lp`]); the live
//! loop's receding horizon with its forecasts ([`lookahead`]); reading them
//! from untrusted JSON with located errors ([`input`]), counted first
//! against its limits ([`size`]); the rule-based
//! fallback dispatch and the diesel commitment rule ([`rules`]); and the live
//! driver that reads the tag database, solves, and writes setpoints ([`driver`]).
//!
//! **Must not touch:** Modbus, SQL, HTTP, the configuration schema. The driver
//! writes only through `gridscada_tagdb::TagWriter` and reports through
//! channels; the CLI (`gridscada dispatch solve`) is a thin shell over
//! [`solve_text`], so the command line and the live loop share one solve.

pub mod driver;
pub mod horizon;
mod input;
pub mod lookahead;
mod lp;
mod mip;
pub mod rules;
pub mod single;
mod size;
pub mod tags;

use serde::ser::{Serialize, SerializeMap, Serializer};
use serde_json::Value;

pub use driver::{
    run_dispatch, run_dispatch_with, DispatchMode, DispatchNotice, DispatchPolicy, DispatchStatus,
};
pub use horizon::{
    CommitmentResult, HorizonOil, HorizonProblem, HorizonRenewable, HorizonSolution,
    HorizonStorage, PeriodForecast, PeriodResult, ReserveRule,
};
pub use input::InputError;
pub use rules::{
    commit_diesels, fallback_dispatch, CommitmentDecision, DieselState, FallbackDispatch,
};
pub use single::{DispatchProblem, DispatchSolution, OilUnit, RenewableUnit, StorageUnit};
pub use size::{too_large, MAX_INPUT_BYTES};

/// Setpoints (or any per-unit value) in unit order; serialises as a JSON
/// object `{"pv1": 60.0, ...}` keeping that order.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Setpoints(pub Vec<(String, f64)>);

impl Setpoints {
    pub fn get(&self, id: &str) -> Option<f64> {
        self.0.iter().find(|(k, _)| k == id).map(|(_, v)| *v)
    }
}

impl Serialize for Setpoints {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut m = s.serialize_map(Some(self.0.len()))?;
        for (k, v) in &self.0 {
            m.serialize_entry(k, v)?;
        }
        m.end()
    }
}

/// Why a dispatch problem has no answer.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DispatchError {
    /// The input is malformed (exit code 1).
    #[error("{0}")]
    Invalid(InputError),
    /// No setpoints satisfy every constraint (exit code 2).
    #[error("infeasible: {0}")]
    Infeasible(String),
    /// The solver failed, or its answer failed the constraint check (exit code 3).
    #[error("solver failure: {0}")]
    Solver(String),
}

impl From<lp::SolveFailure> for DispatchError {
    fn from(e: lp::SolveFailure) -> Self {
        match e {
            lp::SolveFailure::Infeasible(r) => DispatchError::Infeasible(r),
            lp::SolveFailure::Solver(r) => DispatchError::Solver(r),
        }
    }
}

impl DispatchError {
    pub fn exit_code(&self) -> i32 {
        match self {
            DispatchError::Invalid(_) => 1,
            DispatchError::Infeasible(_) => 2,
            DispatchError::Solver(_) => 3,
        }
    }
}

/// A single-period or horizon problem, told apart by the `"periods"` key.
#[derive(Debug, Clone, PartialEq)]
pub enum AnyProblem {
    Single(DispatchProblem),
    Horizon(HorizonProblem),
}

impl AnyProblem {
    /// Reads a problem from parsed JSON at `path` (`""` for the document).
    pub fn from_value(v: &Value, path: &str) -> Result<AnyProblem, InputError> {
        if v.get("periods").is_some() {
            HorizonProblem::from_value(v, path).map(AnyProblem::Horizon)
        } else {
            DispatchProblem::from_value(v, path).map(AnyProblem::Single)
        }
    }

    /// Solves it; the JSON answer on success.
    pub fn solve_json(&self) -> Result<Value, DispatchError> {
        let v = match self {
            AnyProblem::Single(p) => serde_json::to_value(p.solve()?),
            AnyProblem::Horizon(p) => serde_json::to_value(p.solve()?),
        };
        v.map_err(|e| DispatchError::Solver(format!("cannot encode the answer: {e}")))
    }
}

/// What `gridscada dispatch solve` prints and returns.
#[derive(Debug, Clone, PartialEq)]
pub struct CliOutput {
    /// JSON answer (empty for malformed input).
    pub stdout: String,
    /// Human-readable error, if any.
    pub stderr: String,
    /// 0 optimal, 1 malformed input, 2 infeasible, 3 solver failure.
    pub exit_code: i32,
}

/// Solves the JSON text of `gridscada dispatch solve`.
///
/// - An object is one problem (single-period, or a horizon if it has
///   `"periods"`); the answer is one object: the solution, or
///   `{"status": "infeasible", "reason": ...}` (exit 2), or
///   `{"status": "error", "reason": ...}` (exit 3). Malformed input prints a
///   located error to stderr only (exit 1).
/// - A list is a batch (used by the optimality tests to avoid a process per
///   instance): the answer is a list with one object per problem, malformed
///   ones as `{"status": "malformed", "error": ...}`; the exit code is the
///   highest of the individual codes.
pub fn solve_text(text: &str) -> CliOutput {
    // Counted first: an oversized problem is never read into memory.
    if let Err(e) = size::within_limits(text) {
        return malformed(e);
    }
    let doc = match input::parse(text) {
        Ok(v) => v,
        Err(e) => return malformed(e),
    };
    match &doc {
        Value::Array(items) => {
            let mut out = Vec::with_capacity(items.len());
            let mut code = 0;
            let mut errors = String::new();
            for (i, item) in items.iter().enumerate() {
                let path = format!("[{i}]");
                let (v, c) = match solve_value(item, &path, text) {
                    Ok(v) => (v, 0),
                    Err(DispatchError::Invalid(e)) => {
                        errors.push_str(&format!("error: {e}\n"));
                        (
                            serde_json::json!({"status": "malformed", "error": e.to_string()}),
                            1,
                        )
                    }
                    Err(e) => (failure_json(&e), e.exit_code()),
                };
                code = code.max(c);
                out.push(v);
            }
            CliOutput {
                stdout: Value::Array(out).to_string(),
                stderr: errors,
                exit_code: code,
            }
        }
        _ => match solve_value(&doc, "", text) {
            Ok(v) => CliOutput {
                stdout: v.to_string(),
                stderr: String::new(),
                exit_code: 0,
            },
            Err(DispatchError::Invalid(e)) => malformed(e),
            Err(e) => CliOutput {
                stdout: failure_json(&e).to_string(),
                stderr: format!("{e}\n"),
                exit_code: e.exit_code(),
            },
        },
    }
}

fn solve_value(v: &Value, path: &str, text: &str) -> Result<Value, DispatchError> {
    let located = |e: InputError| DispatchError::Invalid(e.locate_in(text));
    let p = AnyProblem::from_value(v, path).map_err(located)?;
    let valid = match &p {
        AnyProblem::Single(s) => s.validate(path),
        AnyProblem::Horizon(h) => h.validate(path),
    };
    valid.map_err(located)?;
    p.solve_json()
}

fn failure_json(e: &DispatchError) -> Value {
    match e {
        DispatchError::Infeasible(r) => serde_json::json!({"status": "infeasible", "reason": r}),
        DispatchError::Solver(r) => serde_json::json!({"status": "error", "reason": r}),
        DispatchError::Invalid(i) => {
            serde_json::json!({"status": "malformed", "error": i.to_string()})
        }
    }
}

fn malformed(e: InputError) -> CliOutput {
    CliOutput {
        stdout: String::new(),
        stderr: format!("error: {e}\n"),
        exit_code: 1,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const EXAMPLE: &str = r#"{"dt_h": 0.25, "demand_kw": 180.0, "voll_per_kwh": 5.0,
 "pv":   [{"id": "pv1", "available_kw": 60.0, "cost_per_kwh": 0.0}],
 "wind": [{"id": "wt1", "available_kw": 25.0, "cost_per_kwh": 0.01}],
 "oil":  [{"id": "dg1", "running": true, "min_kw": 30.0, "max_kw": 150.0, "cost_per_kwh": 0.35}],
 "storage": [{"id": "bess1", "soc_kwh": 80.0, "soc_min_kwh": 20.0, "soc_max_kwh": 200.0, "max_charge_kw": 50.0, "max_discharge_kw": 60.0, "eff_charge": 0.95, "eff_discharge": 0.95, "cycle_cost_per_kwh": 0.02}]}"#;

    #[test]
    fn contract_example_solves_with_the_contract_fields() {
        let out = solve_text(EXAMPLE);
        assert_eq!(out.exit_code, 0, "{}", out.stderr);
        let v: Value = serde_json::from_str(&out.stdout).unwrap();
        assert_eq!(v["status"], "optimal");
        for id in ["pv1", "wt1", "dg1", "bess1"] {
            assert!(v["setpoints_kw"][id].is_number(), "{id}");
        }
        assert!(
            v["objective"].is_number() && v["shed_kw"].is_number() && v["solve_ms"].is_number()
        );
    }

    #[test]
    fn malformed_input_is_located() {
        let text = EXAMPLE.replace("\"eff_charge\": 0.95", "\"eff_charge\": 1.2");
        let out = solve_text(&text);
        assert_eq!(out.exit_code, 1);
        assert!(out.stdout.is_empty());
        assert!(
            out.stderr
                .contains("storage[0].eff_charge: 1.2 is outside (0, 1]"),
            "{}",
            out.stderr
        );
        assert!(out.stderr.contains("line 5, column"), "{}", out.stderr);

        let missing = EXAMPLE.replace("\"min_kw\": 30.0, ", "");
        let out = solve_text(&missing);
        assert_eq!(out.exit_code, 1);
        assert!(
            out.stderr.contains("oil[0].min_kw: missing field"),
            "{}",
            out.stderr
        );

        let dup = EXAMPLE.replace("\"id\": \"wt1\"", "\"id\": \"pv1\"");
        assert!(solve_text(&dup)
            .stderr
            .contains("wind[0].id: duplicate id 'pv1'"));

        let nan = EXAMPLE.replace("180.0", "NaN");
        let out = solve_text(&nan);
        assert_eq!(out.exit_code, 1);
        assert!(out.stderr.contains("line 1"), "{}", out.stderr);

        let typo = EXAMPLE.replace("\"voll_per_kwh\"", "\"vol_per_kwh\"");
        assert!(solve_text(&typo)
            .stderr
            .contains("voll_per_kwh: missing field"));
        let neg = EXAMPLE.replace("\"max_kw\": 150.0", "\"max_kw\": -150.0");
        assert!(solve_text(&neg)
            .stderr
            .contains("oil[0].max_kw: -150 is negative"));
    }

    #[test]
    fn every_input_error_is_reported_with_its_location() {
        let text = EXAMPLE
            .replace("\"eff_charge\": 0.95", "\"eff_charge\": 1.2")
            .replace("\"max_kw\": 150.0", "\"max_kw\": -150.0")
            .replace("\"dt_h\": 0.25", "\"dt_h\": 9000.0");
        let out = solve_text(&text);
        assert_eq!(out.exit_code, 1);
        let lines: Vec<&str> = out.stderr.lines().collect();
        assert_eq!(lines.len(), 4, "{}", out.stderr);
        assert!(lines
            .iter()
            .all(|l| l.starts_with("error: ") && l.contains("(line ")));
        assert!(out
            .stderr
            .contains("dt_h: 9000 is not a number of hours in (0, 8784]"));
        assert!(out.stderr.contains("oil[0].max_kw: -150 is negative"));
        assert!(out
            .stderr
            .contains("oil[0].max_kw: -150 is below min_kw 30"));
        assert!(out
            .stderr
            .contains("storage[0].eff_charge: 1.2 is outside (0, 1]"));
    }

    #[test]
    fn the_unit_limit_is_enforced_and_named() {
        let units: Vec<String> = (0..=single::MAX_UNITS)
            .map(|i| format!(r#"{{"id": "pv{i}", "available_kw": 1.0, "cost_per_kwh": 0.0}}"#))
            .collect();
        let text = format!(
            r#"{{"dt_h": 0.25, "demand_kw": 10.0, "voll_per_kwh": 5.0, "pv": [{}]}}"#,
            units.join(",")
        );
        let out = solve_text(&text);
        assert_eq!(out.exit_code, 1);
        assert!(
            out.stderr.contains("1001 units; at most 1000"),
            "{}",
            out.stderr
        );
        // A horizon asking for more on/off decisions than the limit.
        let periods: Vec<&str> = vec![r#"{"demand_kw": 50.0}"#; 700];
        let oil: Vec<String> = (0..3)
            .map(|i| format!(r#"{{"id": "dg{i}", "running": false, "min_kw": 10.0, "max_kw": 100.0, "cost_per_kwh": 0.3, "optimize_commitment": true}}"#))
            .collect();
        let text = format!(
            r#"{{"dt_h": 0.25, "voll_per_kwh": 5.0, "periods": [{}], "oil": [{}]}}"#,
            periods.join(","),
            oil.join(",")
        );
        let out = solve_text(&text);
        assert_eq!(out.exit_code, 1);
        assert!(
            out.stderr.contains("2100 on/off decisions; at most 2016"),
            "{}",
            out.stderr
        );
    }

    #[test]
    fn limits_are_counted_in_the_text_before_it_is_read() {
        let periods = vec![r#"{"demand_kw": 1.0}"#; horizon::MAX_PERIODS + 1];
        let text = format!(
            r#"{{"dt_h": 0.25, "voll_per_kwh": 5.0, "periods": [{}]}}"#,
            periods.join(",")
        );
        let out = solve_text(&text);
        assert_eq!(out.exit_code, 1);
        assert!(
            out.stderr.starts_with(
                "error: periods: 10001 periods; at most 10000 are accepted (line 1, column 48)"
            ),
            "{}",
            out.stderr
        );

        // A forecast map names units: no more entries than a problem has units.
        let forecast: Vec<String> = (0..=single::MAX_UNITS)
            .map(|i| format!(r#""pv{i}": 1.0"#))
            .collect();
        let text = format!(
            r#"{{"dt_h": 0.25, "voll_per_kwh": 5.0,
 "periods": [{{"demand_kw": 1.0}}, {{"demand_kw": 1.0, "available_kw": {{{}}}}}]}}"#,
            forecast.join(", ")
        );
        let out = solve_text(&text);
        assert_eq!(out.exit_code, 1);
        assert!(
            out.stderr.contains(
                "periods[1].available_kw: 1001 entries; at most 1000 (one per unit) are \
                 accepted (line 2, column 69)"
            ),
            "{}",
            out.stderr
        );

        // One oversized problem refuses its whole batch, naming it.
        let units: Vec<String> = (0..=single::MAX_UNITS)
            .map(|i| format!(r#"{{"id": "dg{i}", "running": false, "min_kw": 0.0, "max_kw": 1.0, "cost_per_kwh": 0.3}}"#))
            .collect();
        let big = format!(
            r#"{{"dt_h": 0.25, "demand_kw": 10.0, "voll_per_kwh": 5.0, "oil": [{}]}}"#,
            units.join(",")
        );
        let out = solve_text(&format!("[{EXAMPLE},\n{big}]"));
        assert_eq!(out.exit_code, 1);
        assert!(out.stdout.is_empty());
        assert!(
            out.stderr.starts_with("error: [1]: 1001 units; at most 1000 (PV, wind, oil and storage together) are accepted (line 6, column 1)"),
            "{}",
            out.stderr
        );

        // The text's size first, before any of it is scanned.
        let out = solve_text(&" ".repeat(MAX_INPUT_BYTES + 1));
        assert_eq!(
            out.stderr,
            "error: the input is 16777217 bytes; at most 16777216 bytes (16 MiB) are accepted\n"
        );
        // Syntax errors are still located, wherever the scan meets them.
        let out = solve_text(&format!("[{EXAMPLE}, {{\"dt_h\": NaN}}]"));
        assert_eq!(out.exit_code, 1);
        assert!(
            out.stderr
                .starts_with("error: invalid JSON: expected value at line 5")
                && out.stderr.contains("(line 5, column"),
            "{}",
            out.stderr
        );
    }

    #[test]
    fn many_problems_are_reported_up_to_a_screenful() {
        let periods = vec![r#"{"demand_kw": -1.0, "available_kw": {"pv1": 1.0}}"#; 2_000];
        let text = format!(
            r#"{{"dt_h": 0.25, "voll_per_kwh": 5.0, "periods": [{}],
 "pv": [{{"id": "pv1", "cost_per_kwh": 0.0}}]}}"#,
            periods.join(",")
        );
        let out = solve_text(&text);
        assert_eq!(out.exit_code, 1);
        let lines: Vec<&str> = out.stderr.lines().collect();
        assert_eq!(lines.len(), 21, "{}", out.stderr);
        assert!(lines[0].starts_with("error: periods[0].demand_kw: -1 is negative (line 1, column"));
        assert!(lines[19].starts_with("error: periods[19].demand_kw: -1 is negative"));
        assert_eq!(
            lines[20],
            "error: 1980 more problems not shown (at most 20 are reported)"
        );
    }

    #[test]
    fn infeasible_prints_a_reason_and_exits_2() {
        let text = EXAMPLE
            .replace("\"demand_kw\": 180.0", "\"demand_kw\": 5.0")
            .replace("\"soc_kwh\": 80.0", "\"soc_kwh\": 200.0");
        let out = solve_text(&text);
        assert_eq!(out.exit_code, 2);
        let v: Value = serde_json::from_str(&out.stdout).unwrap();
        assert_eq!(v["status"], "infeasible");
        assert!(v["reason"].as_str().unwrap().contains("dg1"));
    }

    #[test]
    fn batch_answers_each_problem_in_order() {
        let bad = EXAMPLE.replace("0.95", "0.0");
        let text = format!("[{EXAMPLE}, {bad}]");
        let out = solve_text(&text);
        assert_eq!(out.exit_code, 1);
        let v: Value = serde_json::from_str(&out.stdout).unwrap();
        assert_eq!(v[0]["status"], "optimal");
        assert_eq!(v[1]["status"], "malformed");
        assert!(v[1]["error"]
            .as_str()
            .unwrap()
            .contains("[1].storage[0].eff_charge"));
    }

    #[test]
    fn a_periods_key_selects_the_horizon_problem() {
        let text = r#"{"dt_h": 1.0, "voll_per_kwh": 5.0,
          "periods": [{"demand_kw": 50.0, "available_kw": {"pv1": 30.0}},
                      {"demand_kw": 60.0, "available_kw": {"pv1": 10.0}}],
          "pv": [{"id": "pv1", "cost_per_kwh": 0.0}],
          "oil": [{"id": "dg1", "running": true, "min_kw": 0.0, "max_kw": 100.0, "cost_per_kwh": 0.3}]}"#;
        let out = solve_text(text);
        assert_eq!(out.exit_code, 0, "{}", out.stderr);
        let v: Value = serde_json::from_str(&out.stdout).unwrap();
        assert_eq!(v["periods"].as_array().unwrap().len(), 2);
        assert!((v["objective"].as_f64().unwrap() - 0.3 * (20.0 + 50.0)).abs() < 1e-6);
    }
}
