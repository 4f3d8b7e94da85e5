//! `/api/pair`: this server's part in a redundant pair (active or standby,
//! the epoch, which server is active and at which URL, when each server of
//! the pair was last seen), for the HMI's header and its reconnection on a
//! failover; and the gate that refuses plant commands on a standby.
//!
//! The view comes from the application's lease keeper through a watch, so
//! this crate knows nothing of the lease itself.

use axum::extract::State;
use axum::Json;
use gridscada_tagdb::Leadership;
use serde::Serialize;
use tokio::sync::watch;
use utoipa::ToSchema;

use crate::error::{ApiError, ApiResult};
use crate::WebState;

/// One server of the pair as this one last saw it.
#[derive(Debug, Clone, Default, PartialEq, Serialize, ToSchema)]
pub struct PairMember {
    pub name: String,
    /// The URL operators reach its HMI by (configured).
    pub url: String,
    /// Whether it holds the lease now.
    pub active: bool,
    /// Milliseconds since it last reported to the database; absent if
    /// never seen.
    pub seen_ms_ago: Option<u64>,
}

/// The pair as this server sees it.
#[derive(Debug, Clone, Default, PartialEq, Serialize, ToSchema)]
pub struct PairView {
    /// This server's site.
    pub site: String,
    /// This server's name.
    pub server: String,
    /// `active` or `standby`.
    pub role: String,
    /// The fencing epoch of the lease this server holds.
    pub epoch: Option<u64>,
    /// The server holding the lease, if one does.
    pub active: Option<String>,
    /// Its URL, for the HMI to reconnect to.
    pub active_url: Option<String>,
    /// Every server of the pair, this one included.
    pub servers: Vec<PairMember>,
    /// One server active and every other one seen within the lease.
    pub healthy: bool,
    /// How many times this server's role changed since it started.
    pub role_changes: u64,
}

impl PairView {
    /// The view with this server's own leadership as it is now. The lease
    /// keeper publishes its view once a round, after its calls to the
    /// database; a grant that ran out (the server stepped down, commands
    /// are refused) shows at once, not a round or a hung call later.
    pub fn as_of(mut self, leadership: &Leadership) -> PairView {
        if self.role == "active" && leadership.permit().is_err() {
            self.role = "standby".into();
            self.epoch = None;
            if self.active.as_deref() == Some(self.server.as_str()) {
                self.active = None;
                self.active_url = None;
            }
            for m in self.servers.iter_mut().filter(|m| m.name == self.server) {
                m.active = false;
            }
            self.healthy = false;
        }
        self
    }
}

/// What the application hands the web layer for a pair.
#[derive(Clone)]
pub struct Pair {
    pub leadership: Leadership,
    pub view: watch::Receiver<PairView>,
}

/// Refuses a plant command (503, naming the active server) unless this
/// server may command now. A server without a pair always may.
pub fn active_ready(state: &WebState) -> ApiResult<()> {
    match &state.components.pair {
        Some(p) => p.leadership.permit().map(|_| ()).map_err(|e| {
            ApiError::new(
                axum::http::StatusCode::SERVICE_UNAVAILABLE,
                "standby",
                e.to_string(),
            )
        }),
        None => Ok(()),
    }
}

#[utoipa::path(get, path = "/api/pair", tag = "server", summary = "The redundant pair as this server sees it",
    responses((status = 200, description = "OK", body = PairView),
        (status = 404, description = "This server is not one of a pair (`/api/session` says `pair: false`)")))]
pub async fn view(State(s): State<WebState>) -> ApiResult<Json<PairView>> {
    match &s.components.pair {
        Some(p) => Ok(Json(p.view.borrow().clone().as_of(&p.leadership))),
        None => Err(ApiError::not_found(
            "this server is not one of a redundant pair",
        )),
    }
}

/// The sites with rows in this server's database.
#[derive(Debug, Clone, PartialEq, Serialize, ToSchema)]
pub struct SiteList {
    /// This server's site (`[server] site`).
    pub site: String,
    /// Every site known in the database, this one included, sorted: the
    /// values the history endpoints take as `site=`.
    pub sites: Vec<String>,
}

#[utoipa::path(get, path = "/api/sites", tag = "server", summary = "The sites sharing this server's database",
    responses((status = 200, description = "OK", body = SiteList), (status = 503)))]
pub async fn sites(State(s): State<WebState>) -> ApiResult<Json<SiteList>> {
    let own = s.store.site().to_string();
    let mut sites = s.store.sites().await?;
    // A site that has written nothing yet is still this server's.
    if !sites.contains(&own) {
        sites.push(own.clone());
    }
    sites.sort();
    Ok(Json(SiteList { site: own, sites }))
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::{Duration, Instant};

    fn active_view() -> PairView {
        PairView {
            site: "main".into(),
            server: "a".into(),
            role: "active".into(),
            epoch: Some(7),
            active: Some("a".into()),
            active_url: Some("http://a".into()),
            servers: vec![PairMember {
                name: "a".into(),
                url: "http://a".into(),
                active: true,
                seen_ms_ago: Some(0),
            }],
            healthy: true,
            role_changes: 1,
        }
    }

    #[test]
    fn a_grant_that_ran_out_shows_as_standby_before_the_next_round() {
        let leadership = Leadership::standby("a");
        leadership.grant(7, Instant::now() + Duration::from_secs(60));
        assert_eq!(active_view().as_of(&leadership), active_view());
        // The deadline passed; the keeper has not published since.
        leadership.grant(7, Instant::now() - Duration::from_millis(1));
        let v = active_view().as_of(&leadership);
        assert_eq!(v.role, "standby");
        assert_eq!((v.epoch, v.active, v.healthy), (None, None, false));
        assert!(!v.servers[0].active);
    }
}
