//! Passwords: the bounded pool of hashing threads (Argon2 memory reused per
//! thread), hashing and verifying, the decoy hash, generated passwords and
//! the strength rule.

use std::sync::Arc;
use std::time::{Duration, Instant};

use argon2::password_hash::{rand_core::OsRng, PasswordHash, PasswordHasher, SaltString};
use argon2::Argon2;
use parking_lot::Mutex;
use rand::Rng;

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
}
