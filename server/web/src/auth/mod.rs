//! Who is asking: passwords, sessions, login throttling and the caller's
//! [`Principal`].
//!
//! Sessions live on the server, in the store (so they survive a restart).
//! The browser holds only a random 256-bit token in an HttpOnly,
//! SameSite=Strict cookie; the store only its SHA-256. The token rotates at
//! every login and dies on logout, after idle time, after an absolute
//! lifetime, and when its user is blocked, deleted, or changes password or
//! role.
//!
//! This file holds the caller ([`Principal`]), the shared state ([`Auth`])
//! and the session cookie. The parts, re-exported here: passwords and their
//! pool `passwords.rs`, sessions and their policy `sessions.rs`, login
//! throttling `throttle.rs`, live-socket caps `sockets.rs`.

use std::sync::Arc;

use gridscada_config::Role;
use gridscada_store::Store;
use serde::Serialize;

mod passwords;
mod sessions;
mod sockets;
mod throttle;

pub use passwords::*;
pub use sessions::*;
pub use sockets::*;
pub use throttle::*;

/// The caller of a request.
#[derive(Debug, Clone, Serialize)]
pub struct Principal {
    /// `None` for an anonymous client (shown as "Guest" in the HMI).
    pub user: Option<String>,
    pub role: Role,
    pub group: Option<String>,
    pub screens: Vec<String>,
}

impl Principal {
    pub fn anonymous() -> Self {
        Principal {
            user: None,
            role: Role::Guest,
            group: None,
            screens: vec![],
        }
    }
    pub fn is_logged_in(&self) -> bool {
        self.user.is_some()
    }
    pub fn may_open(&self, screen: &str) -> bool {
        self.screens.iter().any(|s| s == screen)
    }
    /// The name events record for this caller.
    pub fn audit_name(&self) -> String {
        self.user.clone().unwrap_or_else(|| "anonymous".into())
    }
}

/// Shared auth state.
#[derive(Clone)]
pub struct Auth {
    pub sessions: Arc<Sessions>,
    pub throttle: Arc<Throttle>,
    /// Set the cookie's Secure flag (served over TLS).
    pub secure_cookies: bool,
    /// See [`make_decoy_hash`].
    pub decoy_hash: Arc<str>,
    /// Where password hashing runs.
    pub passwords: Arc<PasswordPool>,
    /// Held across the check and the change of anything that could leave no
    /// usable administrator (block, demote, delete, group and screen
    /// changes), so two such requests cannot both pass the check.
    pub admin_guard: Arc<tokio::sync::Mutex<()>>,
    pub sockets: Arc<SocketCounts>,
    /// `/metrics` answers anyone (the demo, on loopback).
    pub metrics_open: bool,
    /// Each logged-in user as the store last described them (role, group,
    /// screens), by name: while the database does not answer, a live
    /// session keeps the rights it had rather than turning anonymous, so
    /// operators can still act (their commands' audit records go to the
    /// spool). Never wider than the store's last word.
    pub last_known: Arc<parking_lot::Mutex<std::collections::HashMap<String, Principal>>>,
}

impl Auth {
    /// Sessions with `policy` kept in `store` (their upkeep task started:
    /// [`Sessions::upkeep`]), fresh throttling, a password pool per core.
    pub async fn new(policy: SessionPolicy, secure_cookies: bool, store: Store) -> Auth {
        let sessions = Arc::new(Sessions::new(policy, store));
        Sessions::upkeep(&sessions);
        Auth {
            sessions,
            throttle: Arc::new(Throttle::default()),
            secure_cookies,
            decoy_hash: make_decoy_hash().await.into(),
            passwords: Arc::new(PasswordPool::per_core()),
            admin_guard: Default::default(),
            sockets: Default::default(),
            metrics_open: false,
            last_known: Default::default(),
        }
    }
}

pub const COOKIE: &str = "gridscada_session";

/// The `Set-Cookie` value for a new session token. `base_path`: `[server]
/// base_path` (`""` for the root), so the cookie goes only to this server's
/// paths behind a proxy that serves others too.
pub fn session_cookie(token: &str, secure: bool, base_path: &str) -> String {
    format!(
        "{COOKIE}={token}; Path={}; HttpOnly; SameSite=Strict{}",
        cookie_path(base_path),
        if secure { "; Secure" } else { "" }
    )
}

/// The `Set-Cookie` value that clears the session cookie.
pub fn clear_cookie(secure: bool, base_path: &str) -> String {
    format!(
        "{COOKIE}=; Path={}; HttpOnly; SameSite=Strict; Max-Age=0{}",
        cookie_path(base_path),
        if secure { "; Secure" } else { "" }
    )
}

fn cookie_path(base_path: &str) -> &str {
    if base_path.is_empty() {
        "/"
    } else {
        base_path
    }
}

/// The session token in a request's Cookie header, if any.
pub fn token_from_cookies(header: Option<&str>) -> Option<String> {
    header?
        .split(';')
        .filter_map(|kv| kv.trim().split_once('='))
        .find(|(k, _)| *k == COOKIE)
        .map(|(_, v)| v.to_string())
        .filter(|v| v.len() == 64 && v.bytes().all(|b| b.is_ascii_hexdigit()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cookie_parsing_rejects_junk() {
        let tok = "a".repeat(64);
        assert_eq!(
            token_from_cookies(Some(&format!("x=1; {COOKIE}={tok}"))),
            Some(tok)
        );
        assert_eq!(token_from_cookies(Some(&format!("{COOKIE}=../etc"))), None);
    }
}
