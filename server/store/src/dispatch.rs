//! Dispatch records: what the microgrid dispatch decided, with its inputs, so
//! the overview shows the latest and an engineer can replay any past one.
//!
//! **Owns:** the `dispatches` table. **Must not touch:** the optimisation.

use gridscada_tagdb::Timestamp;
use serde::Serialize;

use crate::error::db;
use crate::events::{check_text, MAX_LIST};
use crate::{Result, Store, StoreError};

/// A dispatch to record.
#[derive(Debug, Clone, PartialEq)]
pub struct NewDispatch {
    pub ts: Timestamp,
    /// Solver outcome, e.g. `optimal`, `infeasible`, `fallback`.
    pub status: String,
    /// `auto`, `manual`...
    pub mode: String,
    /// Cost of the solution, if one was found.
    pub objective: Option<f64>,
    pub solve_ms: f64,
    /// The forecast, states of charge and limits the solver was given.
    pub inputs: serde_json::Value,
    /// The setpoints sent to each unit.
    pub setpoints: serde_json::Value,
    /// Why this dispatch ran or fell back.
    pub reason: Option<String>,
}

/// A recorded dispatch.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DispatchRecord {
    pub id: i64,
    pub ts: Timestamp,
    pub status: String,
    pub mode: String,
    pub objective: Option<f64>,
    pub solve_ms: f64,
    pub inputs: serde_json::Value,
    pub setpoints: serde_json::Value,
    pub reason: Option<String>,
}

pub(crate) type Row = (
    i64,
    i64,
    String,
    String,
    Option<f64>,
    f64,
    String,
    String,
    Option<String>,
);

fn record(r: Row) -> Result<DispatchRecord> {
    let parse = |what: &str, s: &str| {
        serde_json::from_str(s)
            .map_err(|e| StoreError::Corrupt(format!("dispatch {} {what}: {e}", r.0)))
    };
    Ok(DispatchRecord {
        id: r.0,
        ts: Timestamp::from_millis(r.1),
        inputs: parse("inputs", &r.6)?,
        setpoints: parse("setpoints", &r.7)?,
        status: r.2,
        mode: r.3,
        objective: r.4,
        solve_ms: r.5,
        reason: r.8,
    })
}

pub(crate) const COLS: &str =
    "id, ts, status, mode, objective, solve_ms, inputs_json, setpoints_json, reason";

impl Store {
    /// Records a dispatch; returns its id once committed.
    pub async fn insert_dispatch(&self, d: &NewDispatch) -> Result<i64> {
        check_text("dispatch status", &d.status, 64)?;
        check_text("dispatch mode", &d.mode, 64)?;
        let inputs = d.inputs.to_string();
        let setpoints = d.setpoints.to_string();
        self.writable("recording a dispatch")?;
        Ok(on_backend!(self, writer, |p| {
            sqlx::query_scalar(
                "INSERT INTO dispatches (ts, status, mode, objective, solve_ms, inputs_json, \
                   setpoints_json, reason, site) VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9) \
                 RETURNING id",
            )
            .bind(d.ts.as_millis())
            .bind(&d.status)
            .bind(&d.mode)
            .bind(d.objective.filter(|v| v.is_finite()))
            .bind(if d.solve_ms.is_finite() {
                d.solve_ms
            } else {
                0.0
            })
            .bind(inputs)
            .bind(setpoints)
            .bind(d.reason.as_deref())
            .bind(&*self.site)
            .fetch_one(p)
            .await
            .map_err(db("recording a dispatch"))?
        }))
    }

    /// The most recent dispatch.
    pub async fn latest_dispatch(&self) -> Result<Option<DispatchRecord>> {
        let row: Option<Row> = on_backend!(self, reader, |p| {
            sqlx::query_as(&format!(
                "SELECT {COLS} FROM dispatches WHERE site = $1 ORDER BY ts DESC, id DESC LIMIT 1"
            ))
            .bind(&*self.site)
            .fetch_optional(p)
            .await
            .map_err(db("reading the latest dispatch"))?
        });
        row.map(record).transpose()
    }

    /// Dispatches in `from..to`, newest first, at most `limit` (capped at 10,000).
    pub async fn dispatch_history(
        &self,
        from: Timestamp,
        to: Timestamp,
        limit: u32,
    ) -> Result<Vec<DispatchRecord>> {
        let rows: Vec<Row> = on_backend!(self, reader, |p| {
            sqlx::query_as(&format!(
                "SELECT {COLS} FROM dispatches WHERE ts >= $1 AND ts < $2 AND site = $4 \
                 ORDER BY ts DESC, id DESC LIMIT $3"
            ))
            .bind(from.as_millis())
            .bind(to.as_millis())
            .bind(limit.min(MAX_LIST) as i64)
            .bind(&*self.site)
            .fetch_all(p)
            .await
            .map_err(db("listing dispatches"))?
        });
        rows.into_iter().map(record).collect()
    }
}
