//! User-drawn screens: their JSON, name and version.
//!
//! **Owns:** the `user_screens` table and its optimistic concurrency (a save
//! names the version it started from and fails if another save came first).
//! **Must not touch:** the screen format: the body is stored and returned as
//! the configuration crate gives it; the web layer validates it.

use gridscada_tagdb::Timestamp;
use serde::Serialize;

use crate::error::db;
use crate::events::check_text;
use crate::{Result, Store, StoreError};

/// A stored screen.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ScreenRecord {
    pub id: String,
    pub name: String,
    pub version: i64,
    /// The screen's JSON as saved (with its `version` field as stored).
    pub body: serde_json::Value,
    pub updated_at: Timestamp,
    pub updated_by: String,
}

/// Largest screen JSON kept, in bytes.
pub const MAX_SCREEN_BYTES: usize = 2 * 1024 * 1024;

type Row = (String, String, i64, String, i64, String);

fn record(r: Row) -> Result<ScreenRecord> {
    let body = serde_json::from_str(&r.3)
        .map_err(|e| StoreError::Corrupt(format!("screen '{}': {e}", r.0)))?;
    Ok(ScreenRecord {
        id: r.0,
        name: r.1,
        version: r.2,
        body,
        updated_at: Timestamp::from_millis(r.4),
        updated_by: r.5,
    })
}

const COLUMNS: &str = "screen_id, name, version, body_json, updated_at, updated_by";

impl Store {
    /// Every stored screen, by id.
    pub async fn screens(&self) -> Result<Vec<ScreenRecord>> {
        let rows: Vec<Row> = on_backend!(self, reader, |p| {
            sqlx::query_as(&format!(
                "SELECT {COLUMNS} FROM user_screens ORDER BY screen_id"
            ))
            .fetch_all(p)
            .await
            .map_err(db("reading the screens"))?
        });
        rows.into_iter().map(record).collect()
    }

    /// One stored screen.
    pub async fn screen(&self, id: &str) -> Result<Option<ScreenRecord>> {
        let row: Option<Row> = on_backend!(self, reader, |p| {
            sqlx::query_as(&format!(
                "SELECT {COLUMNS} FROM user_screens WHERE screen_id = $1"
            ))
            .bind(id)
            .fetch_optional(p)
            .await
            .map_err(db("reading a screen"))?
        });
        row.map(record).transpose()
    }

    /// Saves a screen as version `expected + 1`, where `expected` is the
    /// version the editor started from (0 for a new screen). Another save
    /// since then, or a new screen whose id is taken, is a
    /// [`StoreError::Conflict`]; nothing is changed. `body`'s `version` field
    /// is set to the new version. Durable when it returns.
    pub async fn save_screen(
        &self,
        id: &str,
        name: &str,
        body: &serde_json::Value,
        expected: i64,
        by: &str,
        at: Timestamp,
    ) -> Result<ScreenRecord> {
        check_text("screen id", id, 64)?;
        check_text("screen name", name, 1024)?;
        // No screen reaches the last version: one claimed from there was
        // never loaded (and adding one would overflow).
        let version = expected.checked_add(1).ok_or_else(|| {
            StoreError::Conflict(format!(
                "screen '{id}' is at no version {expected}: load it again"
            ))
        })?;
        let mut body = body.clone();
        if let Some(o) = body.as_object_mut() {
            o.insert("version".into(), version.into());
        }
        let json = body.to_string();
        check_text("screen", &json, MAX_SCREEN_BYTES)?;
        let changed: u64 = on_backend!(self, writer, |p| {
            let q = if expected == 0 {
                sqlx::query(
                    "INSERT INTO user_screens (screen_id, name, version, body_json, updated_at, updated_by) \
                     VALUES ($1, $2, $3, $4, $5, $6) ON CONFLICT (screen_id) DO NOTHING",
                )
            } else {
                sqlx::query(
                    "UPDATE user_screens SET name = $2, version = $3, body_json = $4, \
                     updated_at = $5, updated_by = $6 WHERE screen_id = $1 AND version = $3 - 1",
                )
            };
            q.bind(id)
                .bind(name)
                .bind(version)
                .bind(&json)
                .bind(at.as_millis())
                .bind(by)
                .execute(p)
                .await
                .map_err(db("saving a screen"))?
                .rows_affected()
        });
        if changed == 0 {
            let now = self.screen(id).await?.map(|s| s.version);
            return Err(StoreError::Conflict(match now {
                Some(v) => format!(
                    "screen '{id}' is at version {v}, not {expected}: someone saved it since you loaded it"
                ),
                None => format!("screen '{id}' does not exist (it may have been deleted)"),
            }));
        }
        Ok(ScreenRecord {
            id: id.to_string(),
            name: name.to_string(),
            version,
            body,
            updated_at: at,
            updated_by: by.to_string(),
        })
    }

    /// Deletes a screen, and takes it out of every group's screen access, in
    /// one transaction; false if there was none.
    pub async fn delete_screen(&self, id: &str, access_id: &str) -> Result<bool> {
        let n: u64 = on_backend!(self, writer, |p| {
            let mut tx = p.begin().await.map_err(db("deleting a screen"))?;
            let n = sqlx::query("DELETE FROM user_screens WHERE screen_id = $1")
                .bind(id)
                .execute(&mut *tx)
                .await
                .map_err(db("deleting a screen"))?
                .rows_affected();
            sqlx::query("DELETE FROM group_screens WHERE screen = $1")
                .bind(access_id)
                .execute(&mut *tx)
                .await
                .map_err(db("deleting a screen"))?;
            tx.commit().await.map_err(db("deleting a screen"))?;
            n
        });
        Ok(n > 0)
    }
}
