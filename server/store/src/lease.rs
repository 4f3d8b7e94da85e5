//! The lease of a redundant pair: which server of a site is active, under
//! which fencing epoch.
//!
//! **Owns:** the `leadership` table (one row per site) and the fenced writes
//! of what only the active server may write (`panel_states`). **Must not
//! touch:** the timing policy (the app's lease keeper decides when to claim;
//! `ARCHITECTURE.md`, "Redundant pair", says why it is safe).
//!
//! Expiry is judged by the database's clock alone, so the servers' clocks
//! need not agree. A [`Lease`] talks over its own connection, not the
//! store's pool: a busy historian never delays a renewal, and a connection
//! that stops answering is dropped and opened afresh at the next claim.

use std::time::Duration;

use sqlx::postgres::{PgConnectOptions, PgConnection};
use sqlx::Connection;

use crate::error::db;
use crate::events::check_text;
use crate::store::Backend;
use crate::{Result, Store, StoreError};

/// The lease as a claim found it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum LeaseState {
    /// This server holds it under `epoch`, until `length` after the
    /// database took the claim.
    Held { epoch: u64 },
    /// Another server holds it (or held it: `remaining` is zero once it has
    /// expired and nobody has taken it yet).
    HeldBy {
        holder: String,
        epoch: u64,
        remaining: Duration,
    },
}

/// Who may write what only the active server writes: the site's lease
/// under this epoch, held by this server.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Fence {
    pub site: String,
    pub server: String,
    pub epoch: u64,
}

/// One server's handle on its site's lease.
pub struct Lease {
    options: PgConnectOptions,
    conn: Option<PgConnection>,
    site: String,
    server: String,
}

impl std::fmt::Debug for Lease {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Lease({} for {})", self.site, self.server)
    }
}

const NOW_MS: &str = "(extract(epoch from clock_timestamp()) * 1000)::bigint";

impl Store {
    /// The lease of `site` as server `server` sees it. PostgreSQL only: a
    /// pair on SQLite would not share a database.
    pub fn lease(&self, site: &str, server: &str) -> Result<Lease> {
        check_text("site", site, 64)?;
        check_text("server name", server, 64)?;
        match &self.inner.backend {
            Backend::Postgres(pool) => Ok(Lease {
                options: (*pool.connect_options()).clone(),
                conn: None,
                site: site.to_string(),
                server: server.to_string(),
            }),
            Backend::Sqlite(_) => Err(StoreError::Invalid(
                "a redundant pair needs PostgreSQL; this store is SQLite".into(),
            )),
        }
    }

    /// Saves `panel`'s retained state like [`Store::save_panel_state`], but
    /// only while `fence` still holds the site's lease: a deposed server's
    /// late write is dropped by the database, whatever its timing. Returns
    /// whether it was written.
    pub async fn save_panel_state_fenced(
        &self,
        panel: &str,
        state: &serde_json::Value,
        at: gridscada_tagdb::Timestamp,
        fence: &Fence,
    ) -> Result<bool> {
        check_text("panel id", panel, 256)?;
        let json = state.to_string();
        let epoch = i64::try_from(fence.epoch).unwrap_or(i64::MAX);
        self.writable("saving a panel's state under the lease")?;
        if fence.site != *self.site {
            return Err(StoreError::Invalid(format!(
                "saving panel {panel}: the lease of site '{}' does not fence site '{}'",
                fence.site, self.site
            )));
        }
        let done = on_backend!(self, writer, |p| {
            sqlx::query(
                "INSERT INTO panel_states (panel_id, state_json, updated_at, site) \
                 SELECT $1, $2, $3, $4 WHERE EXISTS (SELECT 1 FROM leadership \
                 WHERE site = $4 AND holder = $5 AND epoch = $6) \
                 ON CONFLICT (site, panel_id) DO UPDATE SET state_json = excluded.state_json, \
                 updated_at = excluded.updated_at",
            )
            .bind(panel)
            .bind(&json)
            .bind(at.as_millis())
            .bind(&fence.site)
            .bind(&fence.server)
            .bind(epoch)
            .execute(p)
            .await
            .map_err(db("saving a panel's state under the lease"))?
            .rows_affected()
        });
        Ok(done > 0)
    }
}

impl Lease {
    async fn conn(&mut self) -> Result<&mut PgConnection> {
        if self.conn.is_none() {
            let mut c = PgConnection::connect_with(&self.options)
                .await
                .map_err(db("connecting for the lease"))?;
            sqlx::query(&format!(
                "INSERT INTO leadership (site, holder, epoch, expires_ms, taken_ms) \
                 VALUES ($1, '', 0, 0, {NOW_MS}) ON CONFLICT (site) DO NOTHING"
            ))
            .bind(&self.site)
            .execute(&mut c)
            .await
            .map_err(db("creating the site's lease"))?;
            self.conn = Some(c);
        }
        Ok(self.conn.as_mut().expect("just connected"))
    }

    /// Forgets the connection (after an error or a claim that took too
    /// long): the next claim opens a new one.
    pub fn reset(&mut self) {
        self.conn = None;
    }

    /// Renews the lease if this server holds it under `held`, or takes it
    /// (under a new epoch) if it has expired; either way it then lasts
    /// `length` from the moment the database runs the claim. Otherwise
    /// says who holds it. One statement, so two servers claiming at once
    /// cannot both win.
    pub async fn claim(&mut self, length: Duration, held: Option<u64>) -> Result<LeaseState> {
        let length_ms = i64::try_from(length.as_millis()).unwrap_or(i64::MAX / 4);
        let held = held.map(|e| i64::try_from(e).unwrap_or(i64::MAX));
        let (site, server) = (self.site.clone(), self.server.clone());
        let c = self.conn().await?;
        let won: Option<(i64,)> = sqlx::query_as(&format!(
            "UPDATE leadership SET \
               epoch = CASE WHEN holder = $2 AND epoch = $3 AND expires_ms > {NOW_MS} \
                            THEN epoch ELSE epoch + 1 END, \
               taken_ms = CASE WHEN holder = $2 AND epoch = $3 AND expires_ms > {NOW_MS} \
                            THEN taken_ms ELSE {NOW_MS} END, \
               holder = $2, \
               expires_ms = {NOW_MS} + $4 \
             WHERE site = $1 AND (expires_ms <= {NOW_MS} OR (holder = $2 AND epoch = $3)) \
             RETURNING epoch"
        ))
        .bind(&site)
        .bind(&server)
        .bind(held)
        .bind(length_ms)
        .fetch_optional(&mut *c)
        .await
        .map_err(db("claiming the lease"))?;
        if let Some((epoch,)) = won {
            return Ok(LeaseState::Held {
                epoch: u64::try_from(epoch).unwrap_or(0),
            });
        }
        let (holder, epoch, remaining): (String, i64, i64) = sqlx::query_as(&format!(
            "SELECT holder, epoch, GREATEST(expires_ms - {NOW_MS}, 0) \
             FROM leadership WHERE site = $1"
        ))
        .bind(&site)
        .fetch_one(&mut *c)
        .await
        .map_err(db("reading the lease"))?;
        Ok(LeaseState::HeldBy {
            holder,
            epoch: u64::try_from(epoch).unwrap_or(0),
            remaining: Duration::from_millis(u64::try_from(remaining).unwrap_or(0)),
        })
    }

    /// Gives the lease up at once (an orderly stop), so a standby need not
    /// wait for it to expire. The caller has stopped commanding first.
    pub async fn release(&mut self, epoch: u64) -> Result<()> {
        let epoch = i64::try_from(epoch).unwrap_or(i64::MAX);
        let (site, server) = (self.site.clone(), self.server.clone());
        let c = self.conn().await?;
        sqlx::query(&format!(
            "UPDATE leadership SET expires_ms = {NOW_MS} \
             WHERE site = $1 AND holder = $2 AND epoch = $3"
        ))
        .bind(&site)
        .bind(&server)
        .bind(epoch)
        .execute(&mut *c)
        .await
        .map_err(db("releasing the lease"))?;
        Ok(())
    }
}

impl Lease {
    /// Reports this server alive (with its URL and whether it is active)
    /// and reads when each server of the site last did: `(server, url,
    /// active, milliseconds ago)`.
    pub async fn beat(
        &mut self,
        url: &str,
        active: bool,
    ) -> Result<Vec<(String, String, bool, u64)>> {
        let (site, server) = (self.site.clone(), self.server.clone());
        let c = self.conn().await?;
        sqlx::query(&format!(
            "INSERT INTO pair_servers (site, server, url, active, seen_ms) \
             VALUES ($1, $2, $3, $4, {NOW_MS}) ON CONFLICT (site, server) DO UPDATE SET \
             url = excluded.url, active = excluded.active, seen_ms = excluded.seen_ms"
        ))
        .bind(&site)
        .bind(&server)
        .bind(url)
        .bind(active)
        .execute(&mut *c)
        .await
        .map_err(db("reporting this server alive"))?;
        let rows: Vec<(String, String, bool, i64)> = sqlx::query_as(&format!(
            "SELECT server, url, active, GREATEST({NOW_MS} - seen_ms, 0) \
             FROM pair_servers WHERE site = $1 ORDER BY server"
        ))
        .bind(&site)
        .fetch_all(&mut *c)
        .await
        .map_err(db("reading the pair's servers"))?;
        Ok(rows
            .into_iter()
            .map(|(s, u, a, ago)| (s, u, a, u64::try_from(ago).unwrap_or(0)))
            .collect())
    }
}
