//! Sessions: the policy per role (`[server.sessions]`), idle and absolute
//! expiry, the tokens, and the cache in front of the store's `sessions`
//! table.
//!
//! The store is the truth: a login is recorded before its cookie is sent,
//! a logout deletes the row, and a change of the user that ends sessions
//! deletes them in the user's own transaction (`gridscada_store`'s
//! `users.rs`). So sessions survive a restart, and every server on one
//! database (and the `gridscada user` command) sees the same ones.
//!
//! This server keeps the sessions it has seen in memory, so a request costs
//! no database read for its session and no write for its activity:
//! - activity is written through by [`Sessions::sync`] every [`SYNC_EVERY`],
//!   only for the sessions used since; so the stored `last_seen` trails the
//!   last activity by at most that (plus the write). After a restart a
//!   session's idle timer resumes from the stored `last_seen`: it ends at
//!   most [`SYNC_EVERY`] early, never late;
//! - the same pass re-reads the table: a session deleted elsewhere (another
//!   process's revocation, another server's logout or sweep) leaves the
//!   cache and its live sockets close within [`SYNC_EVERY`]; a later
//!   `last_seen` written by another server is taken;
//! - a token not in the cache is looked up in the store;
//! - an expired session is refused whether or not the sweep has deleted it;
//!   the sweep ([`Sessions::sweep`], every [`SWEEP_EVERY`]) deletes the
//!   expired rows, idle ones only [`SWEEP_GRACE`] after their idle timeout
//!   (another server may hold activity not written yet).

use std::collections::HashMap;
use std::sync::{Arc, Weak};
use std::time::{Duration, Instant};

use gridscada_config::Role;
use gridscada_store::{SessionKey, SessionRecord, Store, StoreError, TicketRecord};
use gridscada_tagdb::Timestamp;
use parking_lot::Mutex;
use rand::Rng;

/// How often activity is written through and the cache re-checked against
/// the store: the bound on a revocation from elsewhere, and on how early an
/// idle expiry may come after a restart.
pub const SYNC_EVERY: Duration = Duration::from_secs(5);
/// How often expired sessions are deleted from the store.
pub const SWEEP_EVERY: Duration = Duration::from_secs(60);
/// How long after its idle timeout (by the stored `last_seen`) the sweep
/// deletes a session: more than the longest a server holds activity back.
pub const SWEEP_GRACE: Duration = Duration::from_secs(30);

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
    /// How long a request waits for the store to confirm its session's
    /// user before it goes on with the rights last known (an outage).
    pub store_wait: Duration,
}

/// The default of [`SessionPolicy::store_wait`] (`store_wait_ms`).
pub const STORE_WAIT: Duration = Duration::from_millis(500);

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
            store_wait: STORE_WAIT,
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
            store_wait: Duration::from_millis(*c.store_wait_ms.get_ref()),
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

/// A session this server has seen.
#[derive(Debug, Clone)]
struct Cached {
    record: SessionRecord,
    /// The last activity seen here (`record.last_seen` is what the store has).
    last_seen: Timestamp,
    /// When it entered the cache: a re-check that read the table before
    /// then cannot tell it is gone.
    loaded: Instant,
}

impl Cached {
    fn expired(&self, now: Timestamp) -> bool {
        SessionRecord {
            last_seen: self.last_seen,
            ..self.record.clone()
        }
        .expired(now)
    }
}

/// How long a failover ticket may be claimed (at most: never after its
/// session's absolute end): the HMI renews it every minute, so a takeover
/// plus the HMI's wait always finds one valid.
pub const HANDOVER_TICKET: Duration = Duration::from_secs(180);

/// The caller of a live session.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SessionUser {
    pub user: String,
    /// The role at login: the session ends if the user's role is now another.
    pub role: Role,
}

/// Who opens a session, for the administrator's view of the table.
#[derive(Debug, Clone, Default)]
pub struct Client {
    /// The client's address.
    pub address: Option<String>,
    /// The browser's `User-Agent`.
    pub user_agent: Option<String>,
}

/// Server-side sessions: the store's table with a cache in front (module docs).
pub struct Sessions {
    policy: SessionPolicy,
    store: Store,
    cache: Mutex<HashMap<SessionKey, Cached>>,
    /// Bumped whenever sessions end, so live sockets re-check theirs.
    ended: tokio::sync::watch::Sender<u64>,
}

impl Sessions {
    /// Sessions kept in `store`. Nothing runs by itself: see [`Sessions::upkeep`].
    pub fn new(policy: SessionPolicy, store: Store) -> Self {
        Sessions {
            policy,
            store,
            cache: Mutex::new(HashMap::new()),
            ended: tokio::sync::watch::channel(0).0,
        }
    }

    /// Starts the task that writes activity through and re-checks the
    /// cache every [`SYNC_EVERY`] and sweeps every [`SWEEP_EVERY`]; it ends
    /// when the sessions are dropped.
    pub fn upkeep(sessions: &Arc<Sessions>) -> tokio::task::JoinHandle<()> {
        let weak: Weak<Sessions> = Arc::downgrade(sessions);
        tokio::spawn(async move {
            let mut tick = tokio::time::interval(SYNC_EVERY);
            tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
            let mut last_sweep: Option<Instant> = None;
            loop {
                tick.tick().await;
                let Some(s) = weak.upgrade() else { return };
                s.sync().await;
                if last_sweep.is_none_or(|t| t.elapsed() >= SWEEP_EVERY) {
                    last_sweep = Some(Instant::now());
                    s.sweep().await;
                }
            }
        })
    }

    /// Starts a session for `user` (of `role`) and returns its new token,
    /// once the store holds it. Any token the client held before is ended
    /// (rotation on login).
    pub async fn create(
        &self,
        user: &str,
        role: Role,
        previous: Option<&str>,
        client: Client,
    ) -> Result<String, StoreError> {
        let expiry = self.policy.expiry(role);
        let ends = expiry.absolute.map(|d| after(Timestamp::now_utc(), d));
        self.create_with(user, role, previous, client, expiry.idle, ends)
            .await
    }

    /// Issues a failover ticket for the live session `session` (the
    /// caller's own token), which the HMI hands to the other server of a
    /// redundant pair when it moves there (the cookie of one host is not
    /// sent to another). A ticket is not a session: no cookie lookup finds
    /// it. It may be claimed once ([`Sessions::claim_ticket`]), within
    /// [`HANDOVER_TICKET`] and never after the session's own absolute end,
    /// and not after the session ended. `previous`, an earlier ticket of
    /// the same session, is ended. The ticket and when it expires; `None`:
    /// `session` is not live here.
    pub async fn create_ticket(
        &self,
        session: &str,
        previous: Option<&str>,
    ) -> Result<Option<(String, Timestamp)>, StoreError> {
        let key = SessionKey::of_token(session);
        let now = Timestamp::now_utc();
        let origin = self.cache.lock().get(&key).cloned();
        let Some(origin) = origin.filter(|o| !o.expired(now)) else {
            return Ok(None);
        };
        let token = new_token();
        let session_expires_at = origin.record.expires_at;
        let ticket = TicketRecord {
            key: SessionKey::of_token(&token),
            session: key,
            user: origin.record.user,
            role: origin.record.role,
            created_at: now,
            expires_at: session_expires_at.map_or(after(now, HANDOVER_TICKET), |end| {
                end.min(after(now, HANDOVER_TICKET))
            }),
            session_expires_at,
        };
        let previous = previous.map(SessionKey::of_token);
        self.store.create_ticket(&ticket, previous.as_ref()).await?;
        Ok(Some((token, ticket.expires_at)))
    }

    /// Claims a failover ticket: a new session of its user, with the idle
    /// timeout of its role and the absolute end of the session it was
    /// issued from (never a fresh lifetime); its token and user. `None`: no
    /// such ticket, used already, expired, or its session ended.
    pub async fn claim_ticket(
        &self,
        ticket: &str,
        client: Client,
    ) -> Result<Option<(String, SessionUser)>, StoreError> {
        let now = Timestamp::now_utc();
        let Some(t) = self
            .store
            .claim_ticket(&SessionKey::of_token(ticket), now)
            .await?
        else {
            return Ok(None);
        };
        let idle = self.policy.expiry(t.role).idle;
        let token = self
            .create_with(&t.user, t.role, None, client, idle, t.session_expires_at)
            .await?;
        Ok(Some((
            token,
            SessionUser {
                user: t.user,
                role: t.role,
            },
        )))
    }

    async fn create_with(
        &self,
        user: &str,
        role: Role,
        previous: Option<&str>,
        client: Client,
        idle: Option<Duration>,
        expires_at: Option<Timestamp>,
    ) -> Result<String, StoreError> {
        let token = new_token();
        let now = Timestamp::now_utc();
        let record = SessionRecord {
            key: SessionKey::of_token(&token),
            user: user.to_string(),
            role,
            created_at: now,
            last_seen: now,
            idle,
            expires_at,
            client: client.address,
            user_agent: client.user_agent,
        };
        let previous = previous.map(SessionKey::of_token);
        self.store
            .create_session(&record, previous.as_ref())
            .await?;
        let mut cache = self.cache.lock();
        if let Some(prev) = &previous {
            cache.remove(prev);
        }
        cache.insert(
            record.key.clone(),
            Cached {
                record,
                last_seen: now,
                loaded: Instant::now(),
            },
        );
        drop(cache);
        self.ended.send_modify(|v| *v += 1);
        Ok(token)
    }

    /// The caller of a live session, touching its idle timer.
    pub async fn user(&self, token: &str) -> Option<SessionUser> {
        self.lookup(token, true).await
    }

    /// The caller of a live session, without touching its idle timer: for
    /// a request the HMI makes on its own (a poll), which is not activity.
    pub async fn user_untouched(&self, token: &str) -> Option<SessionUser> {
        self.lookup(token, false).await
    }

    async fn lookup(&self, token: &str, touch: bool) -> Option<SessionUser> {
        let key = SessionKey::of_token(token);
        let now = Timestamp::now_utc();
        let cached = self.cache.lock().get(&key).cloned();
        let from_cache = cached.is_some();
        let mut entry = match cached {
            Some(c) => c,
            None => self.load(&key).await?,
        };
        if entry.expired(now) && from_cache {
            // Another server on the database may have seen it since this
            // one last re-read the table: its word before ending it.
            if let Some(stored) = self.load(&key).await {
                entry.last_seen = entry.last_seen.max(stored.last_seen);
            }
        }
        if entry.expired(now) {
            self.end_key(&key).await;
            return None;
        }
        if touch {
            entry.last_seen = now;
        }
        let who = SessionUser {
            user: entry.record.user.clone(),
            role: entry.record.role,
        };
        let mut cache = self.cache.lock();
        match cache.get_mut(&key) {
            Some(c) => c.last_seen = c.last_seen.max(entry.last_seen),
            None => {
                cache.insert(key, entry);
            }
        }
        Some(who)
    }

    /// The stored session of `key`, for the cache; `None` if there is
    /// none, or the store cannot say within the policy's `store_wait`
    /// (refused, not guessed: a session this server has not seen is
    /// anonymous until the store answers again).
    async fn load(&self, key: &SessionKey) -> Option<Cached> {
        let (store, k) = (self.store.clone(), key.clone());
        match self
            .within_store_wait(async move { store.session(&k).await })
            .await
        {
            Ok(Some(record)) => Some(Cached {
                last_seen: record.last_seen,
                record,
                loaded: Instant::now(),
            }),
            Ok(None) => None,
            Err(e) => {
                tracing::error!(error = %e, "reading a session");
                None
            }
        }
    }

    /// A store call the caller waits for at most the policy's
    /// `store_wait`: in a database outage the pool would hold the request
    /// until its own acquire timeout (tens of seconds). The call itself
    /// runs on to its end, so a slow store (a new connection on a loaded
    /// host) still warms the pool for the next request instead of being
    /// abandoned at every try.
    pub async fn within_store_wait<T: Send + 'static>(
        &self,
        call: impl std::future::Future<Output = Result<T, StoreError>> + Send + 'static,
    ) -> Result<T, StoreError> {
        match tokio::time::timeout(self.policy.store_wait, tokio::spawn(call)).await {
            Ok(Ok(answer)) => answer,
            Ok(Err(panicked)) => Err(StoreError::Database {
                context: "a store call",
                source: Box::new(panicked),
            }),
            Err(elapsed) => Err(StoreError::Database {
                context: "waiting for the store ([server.sessions] store_wait_ms)",
                source: Box::new(elapsed),
            }),
        }
    }

    /// Whether a token is a session this server holds live, without
    /// touching its idle timer (a live socket's re-check; the socket's
    /// session entered the cache when it connected).
    pub fn is_live(&self, token: &str) -> bool {
        let now = Timestamp::now_utc();
        self.cache
            .lock()
            .get(&SessionKey::of_token(token))
            .is_some_and(|s| !s.expired(now))
    }

    /// Ends a session (logout): its row goes.
    pub async fn end(&self, token: &str) {
        self.end_key(&SessionKey::of_token(token)).await;
    }

    async fn end_key(&self, key: &SessionKey) {
        self.cache.lock().remove(key);
        self.ended.send_modify(|v| *v += 1);
        // The request does not wait for a slow or absent store: the row is
        // deleted once the store answers (till then it is refused here; the
        // sweep deletes it if this fails).
        let (store, key) = (self.store.clone(), key.clone());
        let deleted = self
            .within_store_wait(async move { store.end_session(&key).await })
            .await;
        if let Err(e) = deleted {
            tracing::warn!(error = %e, "deleting an ended session");
        }
    }

    /// Drops `user`'s sessions but `keep` from the cache, at once, after the
    /// store has ended them (block, delete, password change).
    pub fn forget_user(&self, user: &str, keep: Option<&str>) {
        let keep = keep.map(SessionKey::of_token);
        self.forget(|k, s| s.record.user == user && Some(k) != keep.as_ref());
    }

    /// Drops `user`'s sessions started under another role than `role` from
    /// the cache, after the store has ended them.
    pub fn forget_role_change(&self, user: &str, role: Role) {
        self.forget(|_, s| s.record.user == user && s.record.role != role);
    }

    fn forget(&self, gone: impl Fn(&SessionKey, &Cached) -> bool) {
        let mut cache = self.cache.lock();
        let before = cache.len();
        cache.retain(|k, s| !gone(k, s));
        let changed = cache.len() != before;
        drop(cache);
        if changed {
            self.ended.send_modify(|v| *v += 1);
        }
    }

    /// Writes the activity seen since the last pass through to the store,
    /// then re-reads the table: sessions gone from it leave the cache (their
    /// sockets close), a later `last_seen` from another server is taken.
    /// Runs every [`SYNC_EVERY`] ([`Sessions::upkeep`]).
    pub async fn sync(&self) {
        let seen: Vec<(SessionKey, Timestamp)> = self
            .cache
            .lock()
            .iter()
            .filter(|(_, s)| s.last_seen > s.record.last_seen)
            .map(|(k, s)| (k.clone(), s.last_seen))
            .collect();
        match self.store.touch_sessions(&seen).await {
            Ok(()) => {
                let mut cache = self.cache.lock();
                for (k, at) in &seen {
                    if let Some(c) = cache.get_mut(k) {
                        c.record.last_seen = c.record.last_seen.max(*at);
                    }
                }
            }
            Err(e) => tracing::warn!(error = %e, "writing session activity"),
        }
        let read_at = Instant::now();
        let stored = match self.store.sessions().await {
            Ok(rows) => rows,
            Err(e) => {
                tracing::warn!(error = %e, "re-checking sessions");
                return;
            }
        };
        let stored: HashMap<SessionKey, SessionRecord> =
            stored.into_iter().map(|r| (r.key.clone(), r)).collect();
        let mut cache = self.cache.lock();
        let before = cache.len();
        cache.retain(|k, c| match stored.get(k) {
            Some(r) => {
                c.record.last_seen = c.record.last_seen.max(r.last_seen);
                c.last_seen = c.last_seen.max(r.last_seen);
                true
            }
            None => c.loaded > read_at,
        });
        let changed = cache.len() != before;
        drop(cache);
        if changed {
            self.ended.send_modify(|v| *v += 1);
        }
    }

    /// Forgets expired sessions here and deletes them from the store, so
    /// abandoned ones do not pile up. Runs every [`SWEEP_EVERY`]
    /// ([`Sessions::upkeep`]); returns how many rows went.
    pub async fn sweep(&self) -> u64 {
        let now = Timestamp::now_utc();
        self.forget(|_, s| s.expired(now));
        match self.store.sweep_sessions(now, SWEEP_GRACE).await {
            Ok(n) => {
                if n > 0 {
                    tracing::debug!(sessions = n, "expired sessions swept");
                }
                n
            }
            Err(e) => {
                tracing::warn!(error = %e, "sweeping expired sessions");
                0
            }
        }
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

/// `d` after `t`.
fn after(t: Timestamp, d: Duration) -> Timestamp {
    Timestamp::from_millis(
        t.as_millis()
            .saturating_add(i64::try_from(d.as_millis()).unwrap_or(i64::MAX)),
    )
}

fn new_token() -> String {
    let bytes: [u8; 32] = rand::rng().random();
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}
