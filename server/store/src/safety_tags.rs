//! Safety tags on switching devices: placed, removed, and the history.
//!
//! **Owns:** the `safety_tags` table. **Must not touch:** what a tag blocks
//! (the network crate's switching guard decides) or who may remove one (the
//! web layer checks).

use gridscada_tagdb::Timestamp;
use serde::Serialize;

use crate::error::db;
use crate::events::check_text;
use crate::{Result, Store, StoreError};

/// A safety tag, standing or removed.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct SafetyTagRecord {
    pub id: i64,
    /// The switching device's id in `[network]`.
    pub device: String,
    /// do_not_operate, do_not_close or information.
    pub kind: String,
    pub reason: String,
    pub work_ref: String,
    pub placed_by: String,
    pub placed_at: Timestamp,
    pub removed_by: Option<String>,
    pub removed_at: Option<Timestamp>,
    pub removal_reason: Option<String>,
}

type Row = (
    i64,
    String,
    String,
    String,
    String,
    String,
    i64,
    Option<String>,
    Option<i64>,
    Option<String>,
);

fn record(r: Row) -> SafetyTagRecord {
    SafetyTagRecord {
        id: r.0,
        device: r.1,
        kind: r.2,
        reason: r.3,
        work_ref: r.4,
        placed_by: r.5,
        placed_at: Timestamp::from_millis(r.6),
        removed_by: r.7,
        removed_at: r.8.map(Timestamp::from_millis),
        removal_reason: r.9,
    }
}

const COLUMNS: &str = "id, device, kind, reason, work_ref, placed_by, placed_at, removed_by, removed_at, removal_reason";

impl Store {
    /// Places a tag; durable when it returns.
    pub async fn place_safety_tag(
        &self,
        device: &str,
        kind: &str,
        reason: &str,
        work_ref: &str,
        by: &str,
        at: Timestamp,
    ) -> Result<SafetyTagRecord> {
        check_text("device", device, 64)?;
        check_text("kind", kind, 32)?;
        check_text("reason", reason, 1024)?;
        check_text("work reference", work_ref, 256)?;
        let id: i64 = on_backend!(self, writer, |p| {
            sqlx::query_scalar(
                "INSERT INTO safety_tags (site, device, kind, reason, work_ref, placed_by, placed_at) \
                 VALUES ($1, $2, $3, $4, $5, $6, $7) RETURNING id",
            )
            .bind(&*self.site)
            .bind(device)
            .bind(kind)
            .bind(reason)
            .bind(work_ref)
            .bind(by)
            .bind(at.as_millis())
            .fetch_one(p)
            .await
            .map_err(db("placing a safety tag"))?
        });
        Ok(SafetyTagRecord {
            id,
            device: device.into(),
            kind: kind.into(),
            reason: reason.into(),
            work_ref: work_ref.into(),
            placed_by: by.into(),
            placed_at: at,
            removed_by: None,
            removed_at: None,
            removal_reason: None,
        })
    }

    /// Removes a standing tag; a tag already removed (or not this site's)
    /// is a [`StoreError::Conflict`] and nothing changes.
    pub async fn remove_safety_tag(
        &self,
        id: i64,
        by: &str,
        reason: &str,
        at: Timestamp,
    ) -> Result<SafetyTagRecord> {
        check_text("reason", reason, 1024)?;
        let changed: u64 = on_backend!(self, writer, |p| {
            sqlx::query(
                "UPDATE safety_tags SET removed_by = $3, removed_at = $4, removal_reason = $5 \
                 WHERE id = $1 AND site = $2 AND removed_at IS NULL",
            )
            .bind(id)
            .bind(&*self.site)
            .bind(by)
            .bind(at.as_millis())
            .bind(reason)
            .execute(p)
            .await
            .map_err(db("removing a safety tag"))?
            .rows_affected()
        });
        let now = self.safety_tag(id).await?;
        match now {
            Some(t) if changed == 1 => Ok(t),
            Some(t) => Err(StoreError::Conflict(format!(
                "safety tag {id} was already removed by {}",
                t.removed_by.as_deref().unwrap_or("someone")
            ))),
            None => Err(StoreError::Conflict(format!("there is no safety tag {id}"))),
        }
    }

    /// One tag of this site.
    pub async fn safety_tag(&self, id: i64) -> Result<Option<SafetyTagRecord>> {
        let row: Option<Row> = on_backend!(self, reader, |p| {
            sqlx::query_as(&format!(
                "SELECT {COLUMNS} FROM safety_tags WHERE id = $1 AND site = $2"
            ))
            .bind(id)
            .bind(&*self.site)
            .fetch_optional(p)
            .await
            .map_err(db("reading a safety tag"))?
        });
        Ok(row.map(record))
    }

    /// The standing tags of this site (from the writer's pool: a server
    /// that enforces them must see the last placement).
    pub async fn standing_safety_tags(&self) -> Result<Vec<SafetyTagRecord>> {
        let rows: Vec<Row> = on_backend!(self, writer, |p| {
            sqlx::query_as(&format!(
                "SELECT {COLUMNS} FROM safety_tags WHERE site = $1 AND removed_at IS NULL ORDER BY id"
            ))
            .bind(&*self.site)
            .fetch_all(p)
            .await
            .map_err(db("reading the standing safety tags"))?
        });
        Ok(rows.into_iter().map(record).collect())
    }

    /// The latest tags of this site, standing and removed, newest first.
    pub async fn safety_tag_history(&self, limit: u32) -> Result<Vec<SafetyTagRecord>> {
        let rows: Vec<Row> = on_backend!(self, reader, |p| {
            sqlx::query_as(&format!(
                "SELECT {COLUMNS} FROM safety_tags WHERE site = $1 ORDER BY id DESC LIMIT $2"
            ))
            .bind(&*self.site)
            .bind(i64::from(limit))
            .fetch_all(p)
            .await
            .map_err(db("reading the safety tag history"))?
        });
        Ok(rows.into_iter().map(record).collect())
    }
}
