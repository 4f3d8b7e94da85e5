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

use argon2::password_hash::{rand_core::OsRng, PasswordHash, PasswordHasher, SaltString};
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

/// The password work (Argon2id, 19 MiB and tens of milliseconds each) runs
/// on a small pool of its own threads, one per core, behind a bounded queue:
/// a burst of logins queues briefly or is refused with "busy", and memory
/// stays at a few hashes' worth instead of one per request.
pub struct PasswordPool {
    jobs: std::sync::mpsc::SyncSender<Box<dyn FnOnce() + Send>>,
    /// Longest a request waits for a free thread before it is refused.
    pub max_wait: Duration,
}

/// The pool is full: too many password checks at once.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Busy;

/// How many password checks may wait for a thread.
const PASSWORD_QUEUE: usize = 32;

impl PasswordPool {
    pub fn new(threads: usize) -> Self {
        let (tx, rx) = std::sync::mpsc::sync_channel::<Box<dyn FnOnce() + Send>>(PASSWORD_QUEUE);
        let rx = Arc::new(Mutex::new(rx));
        for i in 0..threads.max(1) {
            let rx = rx.clone();
            let spawned = std::thread::Builder::new()
                .name(format!("password-{i}"))
                .spawn(move || loop {
                    let job = rx.lock().recv();
                    match job {
                        Ok(job) => job(),
                        Err(_) => return,
                    }
                });
            if let Err(e) = spawned {
                tracing::error!(error = %e, "starting a password thread");
            }
        }
        PasswordPool {
            jobs: tx,
            max_wait: Duration::from_secs(5),
        }
    }

    /// One thread per core (at least one, at most four).
    pub fn per_core() -> Self {
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        PasswordPool::new(cores.clamp(1, 4))
    }

    async fn run<T: Send + 'static>(
        &self,
        f: impl FnOnce() -> T + Send + 'static,
    ) -> Result<T, Busy> {
        let (tx, rx) = tokio::sync::oneshot::channel();
        let deadline = Instant::now() + self.max_wait;
        let job: Box<dyn FnOnce() + Send> = Box::new(move || {
            // A request that gave up meanwhile costs no hashing.
            if !tx.is_closed() && Instant::now() < deadline {
                let _ = tx.send(f());
            }
        });
        self.jobs.try_send(job).map_err(|_| Busy)?;
        match tokio::time::timeout(self.max_wait, rx).await {
            Ok(Ok(v)) => Ok(v),
            _ => Err(Busy),
        }
    }

    /// Hashes a password with Argon2id and a random salt.
    pub async fn hash(&self, password: String) -> Result<String, String> {
        self.run(move || make_hash(&password))
            .await
            .map_err(|_| "the server is busy checking passwords; try again".to_string())?
    }

    /// Checks a password against a stored hash.
    pub async fn verify(&self, password: String, hash: String) -> Result<bool, Busy> {
        self.run(move || check_hash(&password, &hash)).await
    }
}

thread_local! {
    /// Argon2's working memory, kept per thread and reused: allocating it
    /// afresh for every check left each freed 19 MiB buffer resident.
    static ARGON2_BLOCKS: std::cell::RefCell<Vec<argon2::Block>> =
        const { std::cell::RefCell::new(Vec::new()) };
}

/// Whether `password` matches the PHC string `hash` (Argon2 of any variant
/// and parameters), computed in this thread's reused working memory and
/// compared in constant time.
fn check_hash(password: &str, hash: &str) -> bool {
    let check = || -> Option<bool> {
        let parsed = PasswordHash::new(hash).ok()?;
        let algorithm = argon2::Algorithm::try_from(parsed.algorithm).ok()?;
        let version = match parsed.version {
            Some(v) => argon2::Version::try_from(v).ok()?,
            None => argon2::Version::default(),
        };
        let params = argon2::Params::try_from(&parsed).ok()?;
        let expected = parsed.hash?;
        let mut salt = [0u8; 64];
        let salt = parsed.salt?.decode_b64(&mut salt).ok()?;
        let mut out = vec![0u8; expected.len()];
        let blocks = params.block_count();
        let argon = Argon2::new(algorithm, version, params);
        ARGON2_BLOCKS.with(|b| {
            let mut b = b.borrow_mut();
            b.resize(blocks, argon2::Block::default());
            argon
                .hash_password_into_with_memory(
                    password.as_bytes(),
                    salt,
                    &mut out,
                    &mut b[..blocks],
                )
                .ok()
        })?;
        // `Output`'s equality is constant-time.
        Some(argon2::password_hash::Output::new(&out).ok()? == expected)
    };
    check().unwrap_or(false)
}

/// Hashes a password with Argon2id and a random salt, off the async runtime
/// (for tools and tests; the server goes through its [`PasswordPool`]).
pub async fn hash_password(password: String) -> Result<String, String> {
    tokio::task::spawn_blocking(move || make_hash(&password))
        .await
        .map_err(|e| e.to_string())?
}

/// An Argon2id PHC string of `password` with a fresh random salt.
fn make_hash(password: &str) -> Result<String, String> {
    let salt = SaltString::generate(&mut OsRng);
    Argon2::default()
        .hash_password(password.as_bytes(), &salt)
        .map(|h| h.to_string())
        .map_err(|e| e.to_string())
}

/// Checks a password against a stored hash, off the async runtime (for
/// tools and tests; the server goes through its [`PasswordPool`]).
pub async fn verify_password(password: String, hash: String) -> bool {
    tokio::task::spawn_blocking(move || check_hash(&password, &hash))
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

/// When sessions end: an idle timeout and an absolute lifetime, each per
/// role (group), `None` meaning never. The HMI's live connection counts as
/// activity while its screen is visible.
#[derive(Debug, Clone)]
pub struct SessionPolicy {
    /// The default idle timeout.
    pub idle: Duration,
    /// The default absolute lifetime.
    pub absolute: Duration,
    /// Per-role exceptions to the defaults (by default: a `display` session
    /// never ends by itself).
    pub by_role: std::collections::BTreeMap<Role, Expiry>,
    /// How long before an idle expiry the HMI warns.
    pub warn: Duration,
}

/// When one role's sessions end; `None`: never.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Expiry {
    pub idle: Option<Duration>,
    pub absolute: Option<Duration>,
}

impl Default for SessionPolicy {
    fn default() -> Self {
        SessionPolicy {
            idle: Duration::from_secs(30 * 60),
            absolute: Duration::from_secs(12 * 3600),
            by_role: [(
                Role::Display,
                Expiry {
                    idle: None,
                    absolute: None,
                },
            )]
            .into(),
            warn: Duration::from_secs(60),
        }
    }
}

impl SessionPolicy {
    /// The policy of `[server.sessions]`.
    pub fn from_config(c: &gridscada_config::SessionsConfig) -> Self {
        SessionPolicy {
            by_role: Role::ALL
                .into_iter()
                .map(|r| {
                    let e = Expiry {
                        idle: c.idle(r),
                        absolute: c.absolute(r),
                    };
                    (r, e)
                })
                .collect(),
            warn: Duration::from_secs(*c.warn_s.get_ref()),
            ..SessionPolicy::default()
        }
    }

    /// When sessions of `role` end.
    pub fn expiry(&self, role: Role) -> Expiry {
        self.by_role.get(&role).copied().unwrap_or(Expiry {
            idle: Some(self.idle),
            absolute: Some(self.absolute),
        })
    }
}

#[derive(Debug, Clone)]
struct Session {
    user: String,
    expiry: Expiry,
    created: Instant,
    last_seen: Instant,
}

impl Session {
    fn expired(&self, now: Instant) -> bool {
        self.expiry
            .idle
            .is_some_and(|d| now.duration_since(self.last_seen) > d)
            || self
                .expiry
                .absolute
                .is_some_and(|d| now.duration_since(self.created) > d)
    }
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

    /// Starts a session for `user` (of `role`) and returns its new token.
    /// Any token the client held before is ended (rotation on login).
    pub fn create(&self, user: &str, role: Role, previous: Option<&str>) -> String {
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
                expiry: self.policy.expiry(role),
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
        self.lookup(token, true)
    }

    /// The user of a live session, without touching its idle timer: for a
    /// request the HMI makes on its own (a poll), which is not activity.
    pub fn user_untouched(&self, token: &str) -> Option<String> {
        self.lookup(token, false)
    }

    fn lookup(&self, token: &str, touch: bool) -> Option<String> {
        let now = Instant::now();
        let mut map = self.by_token.lock();
        let s = map.get_mut(token)?;
        if s.expired(now) {
            map.remove(token);
            drop(map);
            self.ended.send_modify(|v| *v += 1);
            return None;
        }
        if touch {
            s.last_seen = now;
        }
        Some(s.user.clone())
    }

    /// Whether a token is still live, without touching its idle timer.
    pub fn is_live(&self, token: &str) -> bool {
        let now = Instant::now();
        self.by_token
            .lock()
            .get(token)
            .is_some_and(|s| !s.expired(now))
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

    /// Ends every session of `user` but `keep` (own password changed).
    pub fn end_others(&self, user: &str, keep: Option<&str>) {
        self.by_token
            .lock()
            .retain(|t, s| s.user != user || Some(t.as_str()) == keep);
        self.ended.send_modify(|v| *v += 1);
    }

    /// Forgets expired sessions (called now and then), so abandoned ones do
    /// not pile up.
    pub fn sweep(&self) {
        let now = Instant::now();
        self.by_token.lock().retain(|_, s| !s.expired(now));
    }

    /// The session policy.
    pub fn policy(&self) -> &SessionPolicy {
        &self.policy
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

/// Failed-login throttling. Three counters, each locking for a time that
/// doubles with every further failure (capped):
/// - per user name **and** address (5 free failures): someone guessing a
///   user's password from one address is slowed, while the real user at
///   their own address is not held out by someone else's failures;
/// - per address (20): spraying guesses over many names from one address;
/// - per user name from all addresses (50): the global ceiling on guesses
///   at one account.
///
/// An attempt is reserved before its password is checked and counted as a
/// failure until it succeeds, so concurrent attempts cannot slip past the
/// limit; a success clears only its own name's counters, never the
/// address's failures at other names.
pub struct Throttle {
    state: Mutex<HashMap<String, Failures>>,
    /// Free failures per user and address.
    pub free_attempts: u32,
    /// Free failures per address, over all names.
    pub free_per_address: u32,
    /// Free failures per user name, over all addresses.
    pub free_per_user: u32,
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
            free_per_address: 20,
            free_per_user: 50,
            window: Duration::from_secs(15 * 60),
            max_lock: Duration::from_secs(15 * 60),
        }
    }
}

/// A login attempt that has been counted; settle it with
/// [`Throttle::success`], or drop it to leave it counted as a failure.
#[must_use]
pub struct Attempt {
    user: String,
    ip: IpAddr,
}

impl Throttle {
    fn keys(&self, user: &str, ip: IpAddr) -> [(String, u32); 3] {
        let user = user.to_lowercase();
        [
            (format!("pair:{user}\u{0}{ip}"), self.free_attempts),
            (format!("ip:{ip}"), self.free_per_address),
            (format!("user:{user}"), self.free_per_user),
        ]
    }

    /// How long the caller must still wait, if locked.
    pub fn check(&self, user: &str, ip: IpAddr) -> Option<Duration> {
        let now = Instant::now();
        let map = self.state.lock();
        Self::wait(&map, &self.keys(user, ip), now)
    }

    fn wait(
        map: &HashMap<String, Failures>,
        keys: &[(String, u32)],
        now: Instant,
    ) -> Option<Duration> {
        keys.iter()
            .filter_map(|(k, _)| map.get(k)?.locked_until)
            .filter(|until| *until > now)
            .map(|until| until - now)
            .max()
    }

    /// Checks and counts an attempt in one step: `Err(wait)` if locked;
    /// otherwise the attempt counts as a failure until it succeeds.
    pub fn reserve(&self, user: &str, ip: IpAddr) -> Result<Attempt, Duration> {
        let now = Instant::now();
        let keys = self.keys(user, ip);
        let mut map = self.state.lock();
        if let Some(wait) = Self::wait(&map, &keys, now) {
            return Err(wait);
        }
        if map.len() > 100_000 {
            // Bound memory under a spray of made-up names: forget stale entries.
            map.retain(|_, f| now.duration_since(f.first) < self.window);
        }
        for (key, free) in keys {
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
            if f.count >= free {
                let doublings = (f.count - free).min(10);
                let lock = Duration::from_secs(1u64 << doublings).min(self.max_lock);
                f.locked_until = Some(now + lock);
            }
        }
        Ok(Attempt {
            user: user.to_string(),
            ip,
        })
    }

    /// Counts a failed attempt (for callers that do not reserve).
    pub fn failure(&self, user: &str, ip: IpAddr) {
        drop(self.reserve(user, ip));
    }

    /// The attempt was never judged (the server was busy): it no longer
    /// counts anywhere.
    pub fn cancel(&self, attempt: Attempt) {
        let keys = self.keys(&attempt.user, attempt.ip);
        let mut map = self.state.lock();
        for (k, free) in keys {
            if let Some(f) = map.get_mut(&k) {
                f.count = f.count.saturating_sub(1);
                if f.count < free {
                    f.locked_until = None;
                }
            }
        }
    }

    /// The attempt succeeded: it no longer counts, and the user's own
    /// counters are cleared. The address's failures at other names stay.
    pub fn success(&self, attempt: Attempt) {
        let keys = self.keys(&attempt.user, attempt.ip);
        let mut map = self.state.lock();
        map.remove(&keys[0].0);
        map.remove(&keys[2].0);
        if let Some(f) = map.get_mut(&keys[1].0) {
            f.count = f.count.saturating_sub(1);
            if f.count < self.free_per_address {
                f.locked_until = None;
            }
        }
    }
}

// --- live sockets --------------------------------------------------------------

/// Counts open live sockets per session and per address, so one client
/// cannot open hundreds.
#[derive(Default)]
pub struct SocketCounts {
    open: Mutex<HashMap<String, usize>>,
}

/// Most live sockets per session (several tabs) and per address.
pub const MAX_SOCKETS_PER_SESSION: usize = 8;
pub const MAX_SOCKETS_PER_ADDRESS: usize = 64;

/// One open socket; dropping it frees its places.
pub struct SocketSlot {
    counts: Arc<SocketCounts>,
    keys: Vec<String>,
}

impl Drop for SocketSlot {
    fn drop(&mut self) {
        let mut open = self.counts.open.lock();
        for k in &self.keys {
            if let Some(n) = open.get_mut(k) {
                *n -= 1;
                if *n == 0 {
                    open.remove(k);
                }
            }
        }
    }
}

impl SocketCounts {
    /// Takes a place for a socket of `session` from `ip`, or says which
    /// limit is reached.
    pub fn open(self: &Arc<Self>, session: Option<&str>, ip: IpAddr) -> Result<SocketSlot, String> {
        let mut keys = vec![(format!("ip:{ip}"), MAX_SOCKETS_PER_ADDRESS)];
        if let Some(t) = session {
            keys.push((format!("session:{t}"), MAX_SOCKETS_PER_SESSION));
        }
        let mut open = self.open.lock();
        for (k, max) in &keys {
            if open.get(k).copied().unwrap_or(0) >= *max {
                return Err(format!(
                    "too many live connections ({max} per {})",
                    if k.starts_with("ip:") {
                        "address"
                    } else {
                        "session"
                    }
                ));
            }
        }
        for (k, _) in &keys {
            *open.entry(k.clone()).or_insert(0) += 1;
        }
        Ok(SocketSlot {
            counts: self.clone(),
            keys: keys.into_iter().map(|(k, _)| k).collect(),
        })
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
}

impl Auth {
    /// Sessions with `policy`, fresh throttling, a password pool per core.
    pub async fn new(policy: SessionPolicy, secure_cookies: bool) -> Auth {
        Auth {
            sessions: Arc::new(Sessions::new(policy)),
            throttle: Arc::new(Throttle::default()),
            secure_cookies,
            decoy_hash: make_decoy_hash().await.into(),
            passwords: Arc::new(PasswordPool::per_core()),
            admin_guard: Default::default(),
            sockets: Default::default(),
            metrics_open: false,
        }
    }
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
        let a = s.create("ann", Role::Operator, None);
        assert_eq!(s.user(&a).as_deref(), Some("ann"));
        let b = s.create("ann", Role::Operator, Some(&a));
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
            ..Default::default()
        });
        let t = s.create("ann", Role::Operator, None);
        std::thread::sleep(Duration::from_millis(40));
        assert!(s.user(&t).is_none());
    }

    #[test]
    fn throttle_locks_a_user_at_one_address_not_everywhere() {
        let t = Throttle::default();
        let ip: IpAddr = "127.0.0.1".parse().unwrap();
        for _ in 0..4 {
            t.failure("ann", ip);
            assert!(t.check("ann", ip).is_none());
        }
        t.failure("ann", ip);
        assert!(t.check("ann", ip).is_some());
        // The real user at another address is not held out...
        let home: IpAddr = "10.0.0.9".parse().unwrap();
        assert!(t.check("ann", home).is_none());
        // ...until the global ceiling on guesses at that name.
        for i in 0..60u8 {
            t.failure("ann", IpAddr::from([10, 1, 0, i]));
        }
        assert!(t.check("ann", home).is_some());
    }

    #[test]
    fn reservations_hold_under_concurrency_and_success_clears_only_its_name() {
        let t = Throttle::default();
        let ip: IpAddr = "127.0.0.1".parse().unwrap();
        // Five attempts in flight at once: the sixth is refused before any
        // password is checked.
        let held: Vec<Attempt> = (0..5).map(|_| t.reserve("bob", ip).unwrap()).collect();
        assert!(t.reserve("bob", ip).is_err());
        drop(held);
        // Spraying other names, with one's own good login in between, is not
        // wiped by the success.
        let ip2: IpAddr = "10.9.9.9".parse().unwrap();
        for round in 0..10 {
            for name in ["a", "b", "c", "d"] {
                let _ = t.reserve(&format!("{name}{round}"), ip2);
            }
            if let Ok(me) = t.reserve("mallory", ip2) {
                t.success(me);
            }
        }
        assert!(t.check("zz", ip2).is_some(), "the address is throttled");
    }

    #[tokio::test]
    async fn the_password_pool_refuses_when_full() {
        let pool = PasswordPool::new(1);
        let h = pool.hash("correct horse battery".into()).await.unwrap();
        assert_eq!(
            pool.verify("correct horse battery".into(), h.clone()).await,
            Ok(true)
        );
        let pool = Arc::new(pool);
        let tries: Vec<_> = (0..(PASSWORD_QUEUE + 20))
            .map(|_| {
                let (p, h) = (pool.clone(), h.clone());
                tokio::spawn(async move { p.verify("wrong".into(), h).await })
            })
            .collect();
        let mut busy = 0;
        for t in tries {
            if t.await.unwrap() == Err(Busy) {
                busy += 1;
            }
        }
        assert!(busy >= 1, "a burst beyond the queue is refused");
    }

    #[test]
    fn socket_places_are_capped_and_freed() {
        let c = Arc::new(SocketCounts::default());
        let ip: IpAddr = "127.0.0.1".parse().unwrap();
        let slots: Vec<_> = (0..MAX_SOCKETS_PER_SESSION)
            .map(|_| c.open(Some("t"), ip).unwrap())
            .collect();
        assert!(c.open(Some("t"), ip).is_err());
        assert!(c.open(Some("u"), ip).is_ok());
        drop(slots);
        assert!(c.open(Some("t"), ip).is_ok());
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
