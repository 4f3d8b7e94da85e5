//! Who is asking: passwords, sessions, login throttling and the caller's
//! [`Principal`].
//!
//! Sessions live on the server. The browser holds only a random 256-bit token
//! in an HttpOnly, SameSite=Strict cookie; the token rotates at every login and
//! dies on logout, after idle time, and after an absolute lifetime.

use std::collections::HashMap;
use std::net::IpAddr;
use std::sync::Arc;
use std::time::{Duration, Instant};

use argon2::password_hash::{
    rand_core::OsRng, PasswordHash, PasswordHasher, PasswordVerifier, SaltString,
};
use argon2::Argon2;
use gridscada_config::Role;
use parking_lot::Mutex;
use rand::Rng;
use serde::Serialize;

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

// --- passwords -------------------------------------------------------------

/// Hashes a password with Argon2id and a random salt. Slow on purpose, so it
/// runs on the blocking pool, never on the async runtime.
pub async fn hash_password(password: String) -> Result<String, String> {
    tokio::task::spawn_blocking(move || {
        let salt = SaltString::generate(&mut OsRng);
        Argon2::default()
            .hash_password(password.as_bytes(), &salt)
            .map(|h| h.to_string())
            .map_err(|e| e.to_string())
    })
    .await
    .map_err(|e| e.to_string())?
}

/// Checks a password against a stored hash, off the async runtime.
pub async fn verify_password(password: String, hash: String) -> bool {
    tokio::task::spawn_blocking(move || {
        PasswordHash::new(&hash)
            .map(|parsed| {
                Argon2::default()
                    .verify_password(password.as_bytes(), &parsed)
                    .is_ok()
            })
            .unwrap_or(false)
    })
    .await
    .unwrap_or(false)
}

/// A hash of a random password, to verify against when the user does not
/// exist, so that a failed login takes the same time either way.
pub async fn make_decoy_hash() -> String {
    hash_password(generate_password()).await.unwrap_or_default()
}

/// A random password an operator can type: 20 characters from an alphabet
/// without look-alikes (about 115 bits).
pub fn generate_password() -> String {
    const ALPHABET: &[u8] = b"abcdefghijkmnpqrstuvwxyzABCDEFGHJKLMNPQRSTUVWXYZ23456789";
    let mut rng = rand::rng();
    (0..20)
        .map(|_| ALPHABET[rng.random_range(0..ALPHABET.len())] as char)
        .collect()
}

/// Rules a new password must meet.
pub fn check_password_strength(password: &str) -> Result<(), String> {
    if password.chars().count() < 10 {
        return Err("a password needs at least 10 characters".into());
    }
    if password.len() > 1024 {
        return Err("a password may have at most 1024 bytes".into());
    }
    Ok(())
}

// --- sessions --------------------------------------------------------------

#[derive(Debug, Clone)]
pub struct SessionPolicy {
    pub idle: Duration,
    pub absolute: Duration,
}

impl Default for SessionPolicy {
    fn default() -> Self {
        SessionPolicy {
            idle: Duration::from_secs(30 * 60),
            absolute: Duration::from_secs(12 * 3600),
        }
    }
}

#[derive(Debug, Clone)]
struct Session {
    user: String,
    created: Instant,
    last_seen: Instant,
}

/// Server-side sessions, keyed by token.
pub struct Sessions {
    policy: SessionPolicy,
    by_token: Mutex<HashMap<String, Session>>,
    /// Bumped whenever sessions end, so live sockets re-check theirs.
    ended: tokio::sync::watch::Sender<u64>,
}

impl Sessions {
    pub fn new(policy: SessionPolicy) -> Self {
        Sessions {
            policy,
            by_token: Mutex::new(HashMap::new()),
            ended: tokio::sync::watch::channel(0).0,
        }
    }

    /// Starts a session for `user` and returns its new token. Any token the
    /// client held before is ended (rotation on login).
    pub fn create(&self, user: &str, previous: Option<&str>) -> String {
        let token = new_token();
        let now = Instant::now();
        let mut map = self.by_token.lock();
        if let Some(prev) = previous {
            map.remove(prev);
        }
        map.insert(
            token.clone(),
            Session {
                user: user.to_string(),
                created: now,
                last_seen: now,
            },
        );
        drop(map);
        self.ended.send_modify(|v| *v += 1);
        token
    }

    /// The user of a live session, touching its idle timer.
    pub fn user(&self, token: &str) -> Option<String> {
        let now = Instant::now();
        let mut map = self.by_token.lock();
        let s = map.get_mut(token)?;
        if now.duration_since(s.last_seen) > self.policy.idle
            || now.duration_since(s.created) > self.policy.absolute
        {
            map.remove(token);
            drop(map);
            self.ended.send_modify(|v| *v += 1);
            return None;
        }
        s.last_seen = now;
        Some(s.user.clone())
    }

    /// Whether a token is still live, without touching its idle timer.
    pub fn is_live(&self, token: &str) -> bool {
        let now = Instant::now();
        self.by_token.lock().get(token).is_some_and(|s| {
            now.duration_since(s.last_seen) <= self.policy.idle
                && now.duration_since(s.created) <= self.policy.absolute
        })
    }

    pub fn end(&self, token: &str) {
        if self.by_token.lock().remove(token).is_some() {
            self.ended.send_modify(|v| *v += 1);
        }
    }

    /// Ends every session of `user` (blocked, deleted, password changed by an admin).
    pub fn end_user(&self, user: &str) {
        self.by_token.lock().retain(|_, s| s.user != user);
        self.ended.send_modify(|v| *v += 1);
    }

    /// Notified whenever any session ends.
    pub fn watch_ended(&self) -> tokio::sync::watch::Receiver<u64> {
        self.ended.subscribe()
    }
}

fn new_token() -> String {
    let bytes: [u8; 32] = rand::rng().random();
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

// --- login throttling --------------------------------------------------------

/// Failed-login throttling, per user name and per client address: after a few
/// failures within the window, further attempts are refused for a lock time
/// that doubles with each further failure (capped).
pub struct Throttle {
    state: Mutex<HashMap<String, Failures>>,
    pub free_attempts: u32,
    pub window: Duration,
    pub max_lock: Duration,
}

#[derive(Debug, Clone)]
struct Failures {
    count: u32,
    first: Instant,
    locked_until: Option<Instant>,
}

impl Default for Throttle {
    fn default() -> Self {
        Throttle {
            state: Mutex::new(HashMap::new()),
            free_attempts: 5,
            window: Duration::from_secs(15 * 60),
            max_lock: Duration::from_secs(15 * 60),
        }
    }
}

impl Throttle {
    fn keys(user: &str, ip: IpAddr) -> [String; 2] {
        [format!("user:{}", user.to_lowercase()), format!("ip:{ip}")]
    }

    /// How long the caller must still wait, if locked.
    pub fn check(&self, user: &str, ip: IpAddr) -> Option<Duration> {
        let now = Instant::now();
        let map = self.state.lock();
        Self::keys(user, ip)
            .iter()
            .filter_map(|k| map.get(k)?.locked_until)
            .filter(|until| *until > now)
            .map(|until| until - now)
            .max()
    }

    pub fn failure(&self, user: &str, ip: IpAddr) {
        let now = Instant::now();
        let mut map = self.state.lock();
        if map.len() > 100_000 {
            // Bound memory under a spray of made-up names: forget stale entries.
            map.retain(|_, f| now.duration_since(f.first) < self.window);
        }
        for key in Self::keys(user, ip) {
            let f = map.entry(key).or_insert(Failures {
                count: 0,
                first: now,
                locked_until: None,
            });
            if now.duration_since(f.first) > self.window {
                *f = Failures {
                    count: 0,
                    first: now,
                    locked_until: None,
                };
            }
            f.count += 1;
            if f.count >= self.free_attempts {
                let doublings = (f.count - self.free_attempts).min(10);
                let lock = Duration::from_secs(1u64 << doublings).min(self.max_lock);
                f.locked_until = Some(now + lock);
            }
        }
    }

    pub fn success(&self, user: &str, ip: IpAddr) {
        let mut map = self.state.lock();
        for k in Self::keys(user, ip) {
            map.remove(&k);
        }
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
}

pub const COOKIE: &str = "gridscada_session";

/// The `Set-Cookie` value for a new session token.
pub fn session_cookie(token: &str, secure: bool) -> String {
    format!(
        "{COOKIE}={token}; Path=/; HttpOnly; SameSite=Strict{}",
        if secure { "; Secure" } else { "" }
    )
}

/// The `Set-Cookie` value that clears the session cookie.
pub fn clear_cookie(secure: bool) -> String {
    format!(
        "{COOKIE}=; Path=/; HttpOnly; SameSite=Strict; Max-Age=0{}",
        if secure { "; Secure" } else { "" }
    )
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

    #[tokio::test]
    async fn password_round_trip() {
        let h = hash_password("correct horse battery".into()).await.unwrap();
        assert!(h.starts_with("$argon2id$"));
        assert!(verify_password("correct horse battery".into(), h.clone()).await);
        assert!(!verify_password("wrong".into(), h).await);
        assert!(!verify_password("x".into(), "not a hash".into()).await);
    }

    #[test]
    fn sessions_rotate_and_end() {
        let s = Sessions::new(SessionPolicy::default());
        let a = s.create("ann", None);
        assert_eq!(s.user(&a).as_deref(), Some("ann"));
        let b = s.create("ann", Some(&a));
        assert_ne!(a, b);
        assert!(s.user(&a).is_none(), "the old token dies at login");
        s.end(&b);
        assert!(s.user(&b).is_none());
    }

    #[test]
    fn sessions_expire_when_idle() {
        let s = Sessions::new(SessionPolicy {
            idle: Duration::from_millis(20),
            absolute: Duration::from_secs(60),
        });
        let t = s.create("ann", None);
        std::thread::sleep(Duration::from_millis(40));
        assert!(s.user(&t).is_none());
    }

    #[test]
    fn throttle_locks_after_free_attempts() {
        let t = Throttle::default();
        let ip: IpAddr = "127.0.0.1".parse().unwrap();
        for _ in 0..4 {
            t.failure("ann", ip);
            assert!(t.check("ann", ip).is_none());
        }
        t.failure("ann", ip);
        assert!(t.check("ann", ip).is_some());
        // Another address trying the same user is locked too.
        assert!(t.check("ann", "10.0.0.9".parse().unwrap()).is_some());
    }

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
