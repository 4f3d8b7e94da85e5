//! The `[server]` section (the HTTP address, the data folder, the session
//! policy per role in `[server.sessions]`), `[storage]`, and the roles
//! users and sessions are given.

use serde::{Deserialize, Serialize};
use serde_spanned::Spanned;

#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct ServerConfig {
    /// HTTP bind address of the API and HMI.
    #[serde(default = "default_http")]
    pub http: Spanned<String>,
    /// Folder for the SQLite database and other local state, relative to the
    /// main file's folder (resolved in [`crate::Plant::data_dir`]).
    #[serde(default = "default_data_dir")]
    pub data_dir: String,
    /// Host names (without port) the HMI may be reached by, besides IP
    /// addresses and `localhost`. A request naming another host is refused,
    /// which defeats DNS rebinding.
    #[serde(default)]
    pub allowed_hosts: Vec<String>,
    /// `/metrics`: a bearer token Prometheus must send. Without one, only
    /// loopback clients may scrape (`demo`: anyone who reaches it).
    #[serde(default)]
    pub metrics_token: Option<String>,
    /// `/metrics`: client addresses allowed without the token.
    #[serde(default)]
    pub metrics_allow: Vec<std::net::IpAddr>,
    /// When sessions end (`[server.sessions]`).
    #[serde(default)]
    pub sessions: SessionsConfig,
    /// HTTPS (`[server.tls]`); without it the server speaks plain HTTP.
    #[serde(default)]
    pub tls: Option<TlsConfig>,
    /// The origin browsers reach the HMI by through a reverse proxy
    /// (`https://scada.example.com`): the Origin check compares against it
    /// instead of the `Host` header, which proxies rewrite. See
    /// `docs/REVERSE_PROXY.md`.
    #[serde(default)]
    pub public_origin: Option<Spanned<String>>,
    /// Proxies (CIDRs) whose forwarding header is believed; nobody else's
    /// is.
    #[serde(default)]
    pub trusted_proxies: Vec<Spanned<String>>,
    /// The header the trusted proxies name the client in:
    /// `x-forwarded-for` (default, with `X-Forwarded-Proto`) or `forwarded`
    /// (RFC 7239). The other one is never read.
    #[serde(default)]
    pub forwarded_header: Option<Spanned<String>>,
    /// The sub-path everything is served under (`/scada`); empty: the root.
    #[serde(default)]
    pub base_path: Option<Spanned<String>>,
    /// The site this server runs (letters, digits, `-`, `_`): servers of
    /// one site share a lease and command the same plant; servers of other
    /// sites on the same database only read its history. Default `main`.
    #[serde(default)]
    pub site: Option<Spanned<String>>,
    /// Live push (`/api/live`): how long changes are gathered after the
    /// first one before they are sent, in ms; 0 sends each batch of changes
    /// as it comes. Longer windows send fewer, larger messages.
    #[serde(default = "default_live_merge_ms")]
    pub live_merge_ms: Spanned<u32>,
    /// Limits on the HTTP(S) listeners' connections
    /// (`[server.connections]`).
    #[serde(default)]
    pub connections: ConnectionsConfig,
    /// `[server.access.GROUP]`: what a user group may do beyond what its
    /// screens give it, by group name (docs/ACCESS.md).
    #[serde(default)]
    pub access: std::collections::BTreeMap<Spanned<String>, GroupAccess>,
}

/// `[server.connections]`: what one client, or all together, may hold open
/// on the HTTP, HTTPS and redirect listeners before a request is parsed.
/// Slow or idle connections are what exhaust a server's descriptors; these
/// bound them (the web crate's `listener.rs`).
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct ConnectionsConfig {
    /// Open connections on all listeners together. The server lowers it to
    /// fit the process's open-file limit (`LimitNOFILE`), keeping room for
    /// its database and field connections.
    #[serde(default = "default_max_open")]
    pub max_open: Spanned<u32>,
    /// Open connections from one client address (a trusted proxy's own
    /// address is exempt; its clients are counted per request instead).
    /// A control room behind one NAT address shares this.
    #[serde(default = "default_max_per_client")]
    pub max_per_client: Spanned<u32>,
    /// Seconds a connection may take to send a request's headers; a
    /// keep-alive connection idle this long is closed too.
    #[serde(default = "default_header_timeout_s")]
    pub header_timeout_s: Spanned<f64>,
    /// Seconds a client may take to finish the TLS handshake.
    #[serde(default = "default_tls_handshake_timeout_s")]
    pub tls_handshake_timeout_s: Spanned<f64>,
}

impl Default for ConnectionsConfig {
    fn default() -> Self {
        ConnectionsConfig {
            max_open: default_max_open(),
            max_per_client: default_max_per_client(),
            header_timeout_s: default_header_timeout_s(),
            tls_handshake_timeout_s: default_tls_handshake_timeout_s(),
        }
    }
}

fn default_max_open() -> Spanned<u32> {
    Spanned::new(0..0, 4096)
}
fn default_max_per_client() -> Spanned<u32> {
    Spanned::new(0..0, 256)
}
fn default_header_timeout_s() -> Spanned<f64> {
    Spanned::new(0..0, 10.0)
}
fn default_tls_handshake_timeout_s() -> Spanned<f64> {
    Spanned::new(0..0, 10.0)
}

/// `[server.access.GROUP]`: one user group's rights beyond its screens.
#[derive(Debug, Clone, Default, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct GroupAccess {
    /// Tags the group may write although no screen of theirs shows them:
    /// names, or a prefix ending in `*` (`SS2.*`). A user writes the tags
    /// they may read and these, each within the tag's `write_role`.
    #[serde(default)]
    pub write: Vec<Spanned<String>>,
}

impl ServerConfig {
    /// Whether `[server.access.GROUP] write` names `tag` for `group`.
    pub fn grants_write(&self, group: &str, tag: &str) -> bool {
        self.access.get(group).is_some_and(|a| {
            a.write
                .iter()
                .any(|p| crate::pattern_matches(p.get_ref(), tag))
        })
    }
}

/// A user or group name: 1 to 64 printable characters, without spaces at
/// either end.
pub fn is_account_name(name: &str) -> bool {
    name.trim() == name
        && !name.is_empty()
        && name.chars().count() <= 64
        && !name.chars().any(char::is_control)
}

/// Each batch as it comes: a message is serialized once per feed, whatever
/// the number of sockets, so merging saves little and costs latency (the
/// `ws_fanout` bench, docs/BENCHMARKS.md).
pub const DEFAULT_LIVE_MERGE_MS: u32 = 0;

fn default_live_merge_ms() -> Spanned<u32> {
    Spanned::new(0..0, DEFAULT_LIVE_MERGE_MS)
}

/// The site of a server that names none.
pub const DEFAULT_SITE: &str = "main";

/// The reverse-proxy settings in their normal forms (values that failed
/// validation are left out; `serve` does not start with them).
impl ServerConfig {
    /// The site id (`[server] site`, default [`DEFAULT_SITE`]).
    pub fn site(&self) -> &str {
        self.site
            .as_ref()
            .map(|s| s.get_ref().as_str())
            .unwrap_or(DEFAULT_SITE)
    }

    /// `""` or `/seg…` without a trailing slash.
    pub fn base_path(&self) -> String {
        self.base_path
            .as_ref()
            .and_then(|b| crate::normal_base_path(b.get_ref()).ok())
            .unwrap_or_default()
    }
    /// `scheme://host[:port]`, the default port left out.
    pub fn public_origin(&self) -> Option<String> {
        self.public_origin
            .as_ref()
            .and_then(|o| crate::normal_public_origin(o.get_ref()).ok())
    }
    pub fn trusted_proxies(&self) -> Vec<crate::Cidr> {
        self.trusted_proxies
            .iter()
            .filter_map(|c| crate::Cidr::parse(c.get_ref()).ok())
            .collect()
    }
    pub fn forwarded_header(&self) -> crate::ForwardedHeader {
        self.forwarded_header
            .as_ref()
            .and_then(|h| crate::ForwardedHeader::parse(h.get_ref()).ok())
            .unwrap_or_default()
    }
}

/// `[server.tls]`: serve HTTPS on `[server] http` with a PEM certificate
/// chain and its private key. The files are read at start and again on
/// SIGHUP, so a renewed certificate needs no restart.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct TlsConfig {
    /// The certificate chain (PEM, the server's own first), relative to the
    /// main file's folder (resolved in [`crate::Plant::tls`]).
    pub cert: Spanned<String>,
    /// The private key of the first certificate (PEM: PKCS#8, PKCS#1 or
    /// SEC1), relative to the main file's folder.
    pub key: Spanned<String>,
    /// A plain-HTTP address (e.g. `0.0.0.0:80`) that answers every request
    /// with a redirect to the HTTPS URL and serves nothing else.
    #[serde(default)]
    pub redirect_http: Option<Spanned<String>>,
    /// `Strict-Transport-Security: max-age`, in seconds; 0: no HSTS header.
    #[serde(default = "default_hsts_max_age_s")]
    pub hsts_max_age_s: Spanned<u64>,
}

/// One year, what HSTS preload lists ask for.
pub const DEFAULT_HSTS_MAX_AGE_S: u64 = 365 * 24 * 3600;

fn default_hsts_max_age_s() -> Spanned<u64> {
    Spanned::new(0..0, DEFAULT_HSTS_MAX_AGE_S)
}

/// When a logged-in session ends. The HMI's live connection counts as
/// activity while its screen is visible, so a screen on a wall stays logged
/// in; a hidden or closed one idles out.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct SessionsConfig {
    /// Minutes without activity before a session ends, per group (role);
    /// 0: never. Groups not named keep the default: 30, `display` 0.
    #[serde(default = "no_idle_overrides")]
    pub idle_minutes: Spanned<std::collections::BTreeMap<Role, f64>>,
    /// Hours after login when a session ends whatever its activity; 0:
    /// never. `display` sessions never end this way.
    #[serde(default = "default_absolute_hours")]
    pub absolute_hours: Spanned<f64>,
    /// Seconds before an idle expiry when the HMI warns.
    #[serde(default = "default_warn_s")]
    pub warn_s: Spanned<u64>,
    /// Milliseconds a request waits for the store to confirm its session's
    /// user; then (a database outage) it goes on with the rights the store
    /// last gave that user.
    #[serde(default = "default_store_wait_ms")]
    pub store_wait_ms: Spanned<u64>,
}

impl Default for SessionsConfig {
    fn default() -> Self {
        SessionsConfig {
            idle_minutes: no_idle_overrides(),
            absolute_hours: default_absolute_hours(),
            warn_s: default_warn_s(),
            store_wait_ms: default_store_wait_ms(),
        }
    }
}

impl SessionsConfig {
    /// The idle timeout of a group; `None`: never.
    pub fn idle(&self, role: Role) -> Option<std::time::Duration> {
        let default = if role == Role::Display { 0.0 } else { 30.0 };
        let minutes = self
            .idle_minutes
            .get_ref()
            .get(&role)
            .copied()
            .unwrap_or(default);
        (minutes > 0.0).then(|| std::time::Duration::from_secs_f64(minutes * 60.0))
    }

    /// The absolute lifetime of a group's sessions; `None`: never.
    pub fn absolute(&self, role: Role) -> Option<std::time::Duration> {
        let hours = *self.absolute_hours.get_ref();
        (role != Role::Display && hours > 0.0)
            .then(|| std::time::Duration::from_secs_f64(hours * 3600.0))
    }
}

fn no_idle_overrides() -> Spanned<std::collections::BTreeMap<Role, f64>> {
    Spanned::new(0..0, Default::default())
}
fn default_absolute_hours() -> Spanned<f64> {
    Spanned::new(0..0, 12.0)
}
fn default_warn_s() -> Spanned<u64> {
    Spanned::new(0..0, 60)
}
fn default_store_wait_ms() -> Spanned<u64> {
    Spanned::new(0..0, 500)
}

impl Default for ServerConfig {
    fn default() -> Self {
        ServerConfig {
            http: default_http(),
            data_dir: default_data_dir(),
            allowed_hosts: vec![],
            metrics_token: None,
            metrics_allow: vec![],
            sessions: SessionsConfig::default(),
            tls: None,
            public_origin: None,
            trusted_proxies: vec![],
            forwarded_header: None,
            base_path: None,
            site: None,
            live_merge_ms: default_live_merge_ms(),
            connections: ConnectionsConfig::default(),
            access: Default::default(),
        }
    }
}

fn default_http() -> Spanned<String> {
    Spanned::new(0..0, "127.0.0.1:8080".into())
}
fn default_data_dir() -> String {
    "data".into()
}

#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct StorageConfig {
    /// `sqlite://PATH` (relative paths are inside the data folder) or
    /// `postgres://user:pass@host/db`.
    #[serde(default = "default_storage_url")]
    pub url: Spanned<String>,
    /// Global historian retention, in days; a tag's own setting wins.
    #[serde(default = "default_retention_days")]
    pub retention_days: u32,
    /// `[storage.retention]`: how long the audit trail and the historian's
    /// roll-ups are kept.
    #[serde(default)]
    pub retention: AuditRetention,
}

/// How long the event log, the alarm history, the dispatch records and the
/// historian's roll-ups are kept, in days; 0 keeps them for ever. Pruned
/// daily, in small batches.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct AuditRetention {
    #[serde(default = "default_audit_days")]
    pub events_days: Spanned<u32>,
    #[serde(default = "default_audit_days")]
    pub alarm_history_days: Spanned<u32>,
    #[serde(default = "default_dispatch_days")]
    pub dispatch_days: Spanned<u32>,
    /// The historian's per-minute roll-ups (trends over days to months).
    #[serde(default = "default_minute_days")]
    pub minute_days: Spanned<u32>,
    /// The historian's per-hour roll-ups (trends over months to decades).
    #[serde(default = "default_hour_days")]
    pub hour_days: Spanned<u32>,
}

impl Default for AuditRetention {
    fn default() -> Self {
        AuditRetention {
            events_days: default_audit_days(),
            alarm_history_days: default_audit_days(),
            dispatch_days: default_dispatch_days(),
            minute_days: default_minute_days(),
            hour_days: default_hour_days(),
        }
    }
}

/// Two years: an incident is often investigated, or audited, a year later.
fn default_audit_days() -> Spanned<u32> {
    Spanned::new(0..0, 730)
}
/// Minute roll-ups: a few hundred bytes per tag and hour, two years.
fn default_minute_days() -> Spanned<u32> {
    Spanned::new(0..0, 730)
}
/// Hour roll-ups: the plant's long history, twenty years.
fn default_hour_days() -> Spanned<u32> {
    Spanned::new(0..0, 7300)
}
/// A dispatch record every period adds up fast, and is of use for weeks.
fn default_dispatch_days() -> Spanned<u32> {
    Spanned::new(0..0, 90)
}

impl Default for StorageConfig {
    fn default() -> Self {
        StorageConfig {
            url: default_storage_url(),
            retention_days: default_retention_days(),
            retention: AuditRetention::default(),
        }
    }
}

fn default_storage_url() -> Spanned<String> {
    Spanned::new(0..0, "sqlite://gridscada.db".into())
}
fn default_retention_days() -> u32 {
    90
}

/// Who may do what. Ordered: each role may do everything the ones below it may.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Role {
    /// A wall display: watches the screens its group may open, commands
    /// nothing, and by default its session never expires.
    Display,
    Guest,
    Operator,
    Supervisor,
    Administrator,
}

impl Role {
    /// Every role, lowest first.
    pub const ALL: [Role; 5] = [
        Role::Display,
        Role::Guest,
        Role::Operator,
        Role::Supervisor,
        Role::Administrator,
    ];

    /// The role with this label (`display`, `guest`, `operator`,
    /// `supervisor`, `administrator`).
    pub fn parse(label: &str) -> Option<Role> {
        Role::ALL.into_iter().find(|r| r.label() == label)
    }

    pub fn label(self) -> &'static str {
        match self {
            Role::Display => "display",
            Role::Guest => "guest",
            Role::Operator => "operator",
            Role::Supervisor => "supervisor",
            Role::Administrator => "administrator",
        }
    }
}
