//! Sessions: the policy per role (`[server.sessions]`), the server-side
//! session table, idle and absolute expiry, and the tokens.

use std::collections::HashMap;
use std::time::{Duration, Instant};

use gridscada_config::Role;
use parking_lot::Mutex;
use rand::Rng;

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

#[cfg(test)]
mod tests {
    use super::*;

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
}
