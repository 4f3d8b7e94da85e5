//! Login throttling: failures counted per user and address, per address and
//! per user, reserved before the password check so concurrent attempts cannot
//! slip past.

use std::collections::HashMap;
use std::net::IpAddr;
use std::time::{Duration, Instant};

use parking_lot::Mutex;

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

#[cfg(test)]
mod tests {
    use super::*;

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
}
