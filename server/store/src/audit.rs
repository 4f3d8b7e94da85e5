//! The audit trail's rows: events and alarm transitions written with their
//! audit id (idempotent, so a record replayed from the spool twice is stored
//! once), and retention of the event log, alarm history and dispatch records.
//!
//! **Owns:** the SQL of [`crate::AuditTrail`] and of audit retention. **Must
//! not touch:** the spool file (that is `spool.rs`).

use gridscada_tagdb::Timestamp;
use serde::{Deserialize, Serialize};

use crate::error::db;
use crate::events::{check_text, escape_controls};
use crate::{AlarmTransition, NewEvent, Result, Store, StoreError};

/// What an audit record carries.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AuditBody {
    Event(NewEvent),
    Transition(AlarmTransition),
}

/// An audit record with its id: unique over the site's life and increasing
/// in the order records were handed to the trail.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AuditRecord {
    pub seq: i64,
    #[serde(flatten)]
    pub body: AuditBody,
}

/// A table the audit retention prunes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AuditTable {
    Events,
    AlarmHistory,
    Dispatches,
}

impl AuditTable {
    pub const ALL: [AuditTable; 3] = [
        AuditTable::Events,
        AuditTable::AlarmHistory,
        AuditTable::Dispatches,
    ];

    pub fn name(self) -> &'static str {
        match self {
            AuditTable::Events => "events",
            AuditTable::AlarmHistory => "alarm_history",
            AuditTable::Dispatches => "dispatches",
        }
    }
}

/// Why a record can never be stored (too long a field): retrying is futile.
fn check(body: &AuditBody) -> Result<()> {
    match body {
        AuditBody::Event(e) => {
            check_text("event source", &e.source, 256)?;
            check_text("event type", &e.kind, 64)?;
            check_text("event message", &e.message, 8192)?;
            if let Some(u) = &e.user {
                check_text("event user", u, 256)?;
            }
        }
        AuditBody::Transition(t) => {
            check_text("alarm key", &t.alarm_key, 512)?;
            check_text("alarm message", &t.message, 4096)?;
            check_text(
                "alarm transition cause",
                t.cause.as_deref().unwrap_or(""),
                64,
            )?;
        }
    }
    Ok(())
}

impl Store {
    /// Stores audit records in one transaction, in the given order. A record
    /// whose id is already stored is skipped (a replay after a crash between
    /// commit and spool trim). Records that can never be stored (a field too
    /// long) are left out and returned with the reason, by id; the others are
    /// stored.
    pub async fn insert_audit(&self, records: &[AuditRecord]) -> Result<Vec<(i64, StoreError)>> {
        let mut rejected = Vec::new();
        let mut ok = Vec::with_capacity(records.len());
        for r in records {
            match check(&r.body) {
                Ok(()) => ok.push(r),
                Err(e) => rejected.push((r.seq, e)),
            }
        }
        if ok.is_empty() {
            return Ok(rejected);
        }
        self.writable("recording the audit trail")?;
        on_backend!(self, writer, |p| {
            let mut tx = p.begin().await.map_err(db("recording the audit trail"))?;
            for r in &ok {
                match &r.body {
                    AuditBody::Event(e) => {
                        let e = escape_controls(e);
                        sqlx::query(
                            "INSERT INTO events (ts, user_name, source, kind, message, audit_id, \
                               site) \
                             VALUES ($1, $2, $3, $4, $5, $6, $7) \
                             ON CONFLICT (site, audit_id) DO NOTHING",
                        )
                        .bind(e.ts.as_millis())
                        .bind(e.user.as_deref())
                        .bind(&e.source)
                        .bind(&e.kind)
                        .bind(&e.message)
                        .bind(r.seq)
                        .bind(&*self.site)
                        .execute(&mut *tx)
                        .await
                        .map_err(db("recording events"))?;
                    }
                    AuditBody::Transition(t) => {
                        crate::alarms::insert_alarm_transition!(&*self.site, t, r.seq)
                            .fetch_optional(&mut *tx)
                            .await
                            .map_err(db("recording alarm transitions"))?;
                    }
                }
            }
            tx.commit().await.map_err(db("recording the audit trail"))?;
        });
        Ok(rejected)
    }

    /// The highest audit id stored (0 when none): the trail numbers on from
    /// above it, so a new record never collides with a stored one.
    pub async fn max_audit_id(&self) -> Result<i64> {
        let (e, a): (Option<i64>, Option<i64>) = on_backend!(self, reader, |p| {
            sqlx::query_as(
                "SELECT (SELECT max(audit_id) FROM events WHERE site = $1), \
                        (SELECT max(audit_id) FROM alarm_history WHERE site = $1)",
            )
            .bind(&*self.site)
            .fetch_one(p)
            .await
            .map_err(db("reading the last audit id"))?
        });
        Ok(e.unwrap_or(0).max(a.unwrap_or(0)))
    }

    /// Deletes at most `batch` rows of `table` older than `before`, oldest
    /// first. Returns how many were deleted: call again while it is `batch`,
    /// so a large backlog goes in short transactions that never hold up the
    /// writers for long.
    pub async fn prune_audit(
        &self,
        table: AuditTable,
        before: Timestamp,
        batch: u32,
    ) -> Result<u64> {
        self.writable("applying audit retention")?;
        let sql = format!(
            "DELETE FROM {t} WHERE id IN \
               (SELECT id FROM {t} WHERE ts < $1 AND site = $3 ORDER BY ts, id LIMIT $2)",
            t = table.name()
        );
        Ok(on_backend!(self, writer, |p| {
            sqlx::query(&sql)
                .bind(before.as_millis())
                .bind(batch.max(1) as i64)
                .bind(&*self.site)
                .execute(p)
                .await
                .map_err(db("applying audit retention"))?
                .rows_affected()
        }))
    }
}
