//! `[redundancy]`: this server as one of a redundant pair (or more) sharing
//! one PostgreSQL database; exactly one of them is active at a time. The
//! timing argument (why a deposed server stops writing before another one
//! can start) is in `ARCHITECTURE.md`, "Redundant pair"; the operator's view
//! in `docs/REDUNDANCY.md`.

use serde::Deserialize;
use serde_spanned::Spanned;

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RedundancyConfig {
    /// This server's name: one of `servers`. Each machine's own file names
    /// itself; the rest of the plant configuration is the same.
    pub name: Spanned<String>,
    /// Every server of the pair (this one included), with the URL an
    /// operator's browser reaches it by: the HMI reconnects to the active
    /// one after a failover, and a refused command names it.
    #[serde(rename = "server")]
    pub servers: Vec<PairServer>,
    /// How long a lease lasts once written to the database, in seconds.
    #[serde(default = "default_lease_s")]
    pub lease_s: Spanned<f64>,
    /// How often the active server renews its lease, and a standby tries to
    /// take an expired one, in seconds.
    #[serde(default = "default_renew_s")]
    pub renew_s: Spanned<f64>,
    /// How long before its lease ends (by its own monotonic clock) the
    /// active server stops writing: covers clock-rate drift between the
    /// server and the database and a command's travel to its device.
    #[serde(default = "default_margin_s")]
    pub margin_s: Spanned<f64>,
    /// The bound on a takeover after the active server died, in seconds:
    /// `lease_s + renew_s` must fit in it.
    #[serde(default = "default_takeover_s")]
    pub takeover_s: Spanned<f64>,
}

/// One server of the pair.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PairServer {
    pub name: Spanned<String>,
    /// The URL of its HMI as operators reach it (`http://10.0.0.2:8080`).
    pub url: Spanned<String>,
}

impl RedundancyConfig {
    /// The configured URL of server `name`, if it is one of the pair.
    pub fn url_of(&self, name: &str) -> Option<&str> {
        self.servers
            .iter()
            .find(|s| s.name.get_ref() == name)
            .map(|s| s.url.get_ref().as_str())
    }

    pub fn lease(&self) -> std::time::Duration {
        secs(*self.lease_s.get_ref())
    }
    pub fn renew(&self) -> std::time::Duration {
        secs(*self.renew_s.get_ref())
    }
    pub fn margin(&self) -> std::time::Duration {
        secs(*self.margin_s.get_ref())
    }
    pub fn takeover(&self) -> std::time::Duration {
        secs(*self.takeover_s.get_ref())
    }
}

fn secs(s: f64) -> std::time::Duration {
    std::time::Duration::try_from_secs_f64(s).unwrap_or_default()
}

pub const DEFAULT_LEASE_S: f64 = 3.0;
pub const DEFAULT_RENEW_S: f64 = 0.5;
pub const DEFAULT_MARGIN_S: f64 = 0.5;
pub const DEFAULT_TAKEOVER_S: f64 = 5.0;

fn default_lease_s() -> Spanned<f64> {
    Spanned::new(0..0, DEFAULT_LEASE_S)
}
fn default_renew_s() -> Spanned<f64> {
    Spanned::new(0..0, DEFAULT_RENEW_S)
}
fn default_margin_s() -> Spanned<f64> {
    Spanned::new(0..0, DEFAULT_MARGIN_S)
}
fn default_takeover_s() -> Spanned<f64> {
    Spanned::new(0..0, DEFAULT_TAKEOVER_S)
}
