//! Switching programmes: prepared, approved, executed step by step.
//!
//! **Owns:** the `switching_programmes` table. **Must not touch:** what a
//! step means or whether it may be done (the network crate checks the steps
//! against the topology; the web layer decides who may do what). Every
//! change names the version it read, so two servers or two operators cannot
//! both take the same step.

use gridscada_tagdb::Timestamp;
use serde::Serialize;

use crate::error::db;
use crate::events::check_text;
use crate::{Result, Store, StoreError};

/// A programme as stored.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct ProgrammeRecord {
    pub id: i64,
    pub name: String,
    /// The steps, as JSON (the network crate's `StepText`s).
    pub steps: String,
    /// draft, approved, running, paused, completed or abandoned.
    pub state: String,
    /// How many steps are done.
    pub next_step: i64,
    pub created_by: String,
    pub created_at: Timestamp,
    pub approved_by: Option<String>,
    pub approved_at: Option<Timestamp>,
    pub updated_at: Timestamp,
    pub version: i64,
    /// Why it was abandoned, or what paused it.
    pub note: String,
}

type Row = (
    i64,
    String,
    String,
    String,
    i64,
    String,
    i64,
    Option<String>,
    Option<i64>,
    i64,
    i64,
    String,
);

fn record(r: Row) -> ProgrammeRecord {
    ProgrammeRecord {
        id: r.0,
        name: r.1,
        steps: r.2,
        state: r.3,
        next_step: r.4,
        created_by: r.5,
        created_at: Timestamp::from_millis(r.6),
        approved_by: r.7,
        approved_at: r.8.map(Timestamp::from_millis),
        updated_at: Timestamp::from_millis(r.9),
        version: r.10,
        note: r.11,
    }
}

const COLUMNS: &str = "id, name, steps, state, next_step, created_by, created_at, approved_by, approved_at, updated_at, version, note";

/// A change of a programme's progress.
#[derive(Debug, Clone)]
pub struct ProgrammeChange<'a> {
    pub state: &'a str,
    pub next_step: i64,
    /// Set when it is approved.
    pub approved_by: Option<&'a str>,
    pub note: &'a str,
    pub at: Timestamp,
}

impl Store {
    /// Stores a new programme in `state` (a draft); durable when it returns.
    pub async fn create_programme(
        &self,
        name: &str,
        steps: &str,
        state: &str,
        by: &str,
        at: Timestamp,
    ) -> Result<ProgrammeRecord> {
        check_text("name", name, 200)?;
        check_text("steps", steps, 512 * 1024)?;
        let id: i64 = on_backend!(self, writer, |p| {
            sqlx::query_scalar(
                "INSERT INTO switching_programmes (site, name, steps, state, created_by, created_at, updated_at) \
                 VALUES ($1, $2, $3, $4, $5, $6, $6) RETURNING id",
            )
            .bind(&*self.site)
            .bind(name)
            .bind(steps)
            .bind(state)
            .bind(by)
            .bind(at.as_millis())
            .fetch_one(p)
            .await
            .map_err(db("storing a switching programme"))?
        });
        self.programme(id).await?.ok_or_else(|| {
            StoreError::Conflict(format!("programme {id} vanished as it was stored"))
        })
    }

    /// One programme of this site (from the writer's pool: the step taken
    /// last must be seen).
    pub async fn programme(&self, id: i64) -> Result<Option<ProgrammeRecord>> {
        let row: Option<Row> = on_backend!(self, writer, |p| {
            sqlx::query_as(&format!(
                "SELECT {COLUMNS} FROM switching_programmes WHERE id = $1 AND site = $2"
            ))
            .bind(id)
            .bind(&*self.site)
            .fetch_optional(p)
            .await
            .map_err(db("reading a switching programme"))?
        });
        Ok(row.map(record))
    }

    /// The latest programmes of this site, newest first.
    pub async fn programmes(&self, limit: u32) -> Result<Vec<ProgrammeRecord>> {
        let rows: Vec<Row> = on_backend!(self, reader, |p| {
            sqlx::query_as(&format!(
                "SELECT {COLUMNS} FROM switching_programmes WHERE site = $1 ORDER BY id DESC LIMIT $2"
            ))
            .bind(&*self.site)
            .bind(i64::from(limit))
            .fetch_all(p)
            .await
            .map_err(db("reading the switching programmes"))?
        });
        Ok(rows.into_iter().map(record).collect())
    }

    /// Moves programme `id` on, if it is still at `version`; a programme
    /// someone changed meanwhile is a [`StoreError::Conflict`] and nothing
    /// changes.
    pub async fn update_programme(
        &self,
        id: i64,
        version: i64,
        change: ProgrammeChange<'_>,
    ) -> Result<ProgrammeRecord> {
        check_text("note", change.note, 1024)?;
        let at = change.at.as_millis();
        let changed: u64 = on_backend!(self, writer, |p| {
            sqlx::query(
                "UPDATE switching_programmes SET state = $4, next_step = $5, \
                 approved_by = COALESCE($6, approved_by), \
                 approved_at = CASE WHEN $6 IS NULL THEN approved_at ELSE $7 END, \
                 note = $8, updated_at = $7, version = version + 1 \
                 WHERE id = $1 AND site = $2 AND version = $3",
            )
            .bind(id)
            .bind(&*self.site)
            .bind(version)
            .bind(change.state)
            .bind(change.next_step)
            .bind(change.approved_by)
            .bind(at)
            .bind(change.note)
            .execute(p)
            .await
            .map_err(db("updating a switching programme"))?
            .rows_affected()
        });
        let now = self
            .programme(id)
            .await?
            .ok_or_else(|| StoreError::Conflict(format!("there is no programme {id}")))?;
        if changed == 1 {
            Ok(now)
        } else {
            Err(StoreError::Conflict(format!(
                "programme {id} was changed meanwhile (now {}, {} step(s) done): reload it",
                now.state, now.next_step
            )))
        }
    }
}
