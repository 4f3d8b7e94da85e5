//! Panel sequence state that must survive a restart: each panel's mode,
//! faulty zones and lockout, as the JSON the control crate gives.
//!
//! **Owns:** the `panel_states` table. **Must not touch:** the sequence (the
//! JSON is stored and returned as it is; the control crate reads it).

use gridscada_tagdb::Timestamp;

use crate::error::db;
use crate::events::check_text;
use crate::{Result, Store, StoreError};

impl Store {
    /// Saves `panel`'s retained state (JSON), replacing the previous one;
    /// durable when it returns.
    pub async fn save_panel_state(
        &self,
        panel: &str,
        state: &serde_json::Value,
        at: Timestamp,
    ) -> Result<()> {
        check_text("panel id", panel, 256)?;
        let json = state.to_string();
        self.writable("saving a panel's state")?;
        on_backend!(self, writer, |p| {
            sqlx::query(
                "INSERT INTO panel_states (panel_id, state_json, updated_at, site) \
                 VALUES ($1, $2, $3, $4) \
                 ON CONFLICT (site, panel_id) DO UPDATE SET state_json = excluded.state_json, \
                 updated_at = excluded.updated_at",
            )
            .bind(panel)
            .bind(&json)
            .bind(at.as_millis())
            .bind(&*self.site)
            .execute(p)
            .await
            .map(|_| ())
            .map_err(db("saving a panel's state"))?
        });
        Ok(())
    }

    /// Every saved panel state, by panel id.
    pub async fn panel_states(&self) -> Result<Vec<(String, serde_json::Value)>> {
        let rows: Vec<(String, String)> = on_backend!(self, reader, |p| {
            sqlx::query_as(
                "SELECT panel_id, state_json FROM panel_states WHERE site = $1 ORDER BY panel_id",
            )
            .bind(&*self.site)
            .fetch_all(p)
            .await
            .map_err(db("reading the panels' states"))?
        });
        rows.into_iter()
            .map(|(id, json)| {
                serde_json::from_str(&json)
                    .map(|v| (id.clone(), v))
                    .map_err(|e| StoreError::Corrupt(format!("panel state of '{id}': {e}")))
            })
            .collect()
    }
}
