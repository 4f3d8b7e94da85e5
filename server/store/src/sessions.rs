//! Login sessions, kept so that they survive a restart and so that every
//! server on one database sees the same ones.
//!
//! **Owns:** the `sessions` table and the failover tickets
//! (`handover_tickets`, a kind of their own: [`TicketRecord`]). Only the SHA-256 of a session's token is
//! stored ([`SessionKey`]); the browser's cookie holds the token, so a copy
//! of the table opens no session. The users' changes that end sessions
//! (block, delete, password, role) delete their rows in the same
//! transaction (`users.rs`). **Must not touch:** the session policy and the
//! in-memory cache (the web layer's); tokens themselves.

use std::time::Duration;

use gridscada_config::Role;
use gridscada_tagdb::Timestamp;
use sha2::{Digest, Sha256};

use crate::error::db;
use crate::events::check_text;
use crate::{Result, Store, StoreError};

/// What the table knows a session by: the SHA-256 of its token, in hex.
#[derive(Debug, Clone, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct SessionKey(String);

impl SessionKey {
    /// The key of a session token (the cookie's value).
    pub fn of_token(token: &str) -> SessionKey {
        let digest = Sha256::digest(token.as_bytes());
        SessionKey(digest.iter().map(|b| format!("{b:02x}")).collect())
    }

    pub fn as_str(&self) -> &str {
        &self.0
    }
}

/// A stored session.
#[derive(Debug, Clone, PartialEq)]
pub struct SessionRecord {
    pub key: SessionKey,
    pub user: String,
    /// The user's role at login: a session ends when the role changes.
    pub role: Role,
    pub created_at: Timestamp,
    /// The last activity written through (it may trail the real last
    /// activity by the writer's bound).
    pub last_seen: Timestamp,
    /// Idle timeout fixed at login from the role's policy; `None`: never.
    pub idle: Option<Duration>,
    /// Absolute end fixed at login; `None`: never.
    pub expires_at: Option<Timestamp>,
    /// The client's address at login, for the administrator.
    pub client: Option<String>,
    /// The browser's `User-Agent` at login (at most 256 bytes kept).
    pub user_agent: Option<String>,
}

impl SessionRecord {
    /// Whether the session has ended by `now` (idle too long since
    /// `last_seen`, or past its absolute end). The sweep deletes the same
    /// rows ([`Store::sweep_sessions`]).
    pub fn expired(&self, now: Timestamp) -> bool {
        let now = now.as_millis();
        self.expires_at.is_some_and(|e| now > e.as_millis())
            || self
                .idle
                .is_some_and(|d| now - self.last_seen.as_millis() > millis(d))
    }
}

fn millis(d: Duration) -> i64 {
    i64::try_from(d.as_millis()).unwrap_or(i64::MAX)
}

type SessionRow = (
    String,
    String,
    String,
    i64,
    i64,
    Option<i64>,
    Option<i64>,
    Option<String>,
    Option<String>,
);

const SESSION_COLS: &str = "token_hash, user_name, role, created_at, last_seen, idle_ms, \
                            expires_at, client, user_agent";

fn session(r: SessionRow) -> Result<SessionRecord> {
    let role = Role::parse(&r.2).ok_or_else(|| {
        StoreError::Corrupt(format!(
            "session of '{}' has an unknown role '{}'",
            r.1, r.2
        ))
    })?;
    Ok(SessionRecord {
        key: SessionKey(r.0),
        user: r.1,
        role,
        created_at: Timestamp::from_millis(r.3),
        last_seen: Timestamp::from_millis(r.4),
        idle: r.5.map(|ms| Duration::from_millis(ms.max(0) as u64)),
        expires_at: r.6.map(Timestamp::from_millis),
        client: r.7,
        user_agent: r.8,
    })
}

/// A redundant pair's failover ticket (the `handover_tickets` table): a
/// kind of its own, never a session. It carries a login from the session
/// that asked for it to a new session on another server of the pair, once.
#[derive(Debug, Clone, PartialEq)]
pub struct TicketRecord {
    /// The SHA-256 of the ticket, as for a session token.
    pub key: SessionKey,
    /// The session it was issued from: the ticket dies with it.
    pub session: SessionKey,
    pub user: String,
    pub role: Role,
    pub created_at: Timestamp,
    /// When it may no longer be claimed: never after `session_expires_at`.
    pub expires_at: Timestamp,
    /// The issuing session's absolute end, which the claimed session
    /// inherits; `None`: never.
    pub session_expires_at: Option<Timestamp>,
}

type TicketRow = (String, String, String, String, i64, i64, Option<i64>);

const TICKET_COLS: &str =
    "ticket_hash, session_hash, user_name, role, created_at, expires_at, session_expires_at";

fn ticket(r: TicketRow) -> Result<TicketRecord> {
    let role = Role::parse(&r.3).ok_or_else(|| {
        StoreError::Corrupt(format!(
            "failover ticket of '{}' has an unknown role '{}'",
            r.2, r.3
        ))
    })?;
    Ok(TicketRecord {
        key: SessionKey(r.0),
        session: SessionKey(r.1),
        user: r.2,
        role,
        created_at: Timestamp::from_millis(r.4),
        expires_at: Timestamp::from_millis(r.5),
        session_expires_at: r.6.map(Timestamp::from_millis),
    })
}

/// Which of a user's sessions a change of the user ends.
#[derive(Debug, Clone, Copy)]
pub(crate) enum Revoke<'a> {
    None,
    All,
    /// All but this one (one's own password changed in this session).
    AllBut(Option<&'a SessionKey>),
    /// Those started under another role than this one.
    RoleNot(Role),
}

/// The statement that deletes the sessions `revoke` names (`$1`: the user)
/// and its second argument, if any; `None`: nothing to delete.
pub(crate) fn revoke_sql<'a>(revoke: Revoke<'a>) -> Option<(&'static str, Option<&'a str>)> {
    match revoke {
        Revoke::None => None,
        Revoke::All | Revoke::AllBut(None) => {
            Some(("DELETE FROM sessions WHERE user_name = $1", None))
        }
        Revoke::AllBut(Some(k)) => Some((
            "DELETE FROM sessions WHERE user_name = $1 AND token_hash <> $2",
            Some(k.as_str()),
        )),
        Revoke::RoleNot(r) => Some((
            "DELETE FROM sessions WHERE user_name = $1 AND role <> $2",
            Some(r.label()),
        )),
    }
}

/// Runs [`revoke_sql`] for `$user` on `$conn` (a connection or transaction
/// of either backend); the number of sessions ended.
macro_rules! revoke_on {
    ($conn:expr, $user:expr, $revoke:expr) => {
        match $crate::sessions::revoke_sql($revoke) {
            None => Ok(0),
            Some((sql, extra)) => {
                let mut q = sqlx::query(sql).bind($user);
                if let Some(x) = extra {
                    q = q.bind(x);
                }
                q.execute($conn).await.map(|r| r.rows_affected())
            }
        }
    };
}

impl Store {
    /// Records a new session, ending `replaces` (the token the client held
    /// before: rotation at login) in the same transaction. Durable when it
    /// returns, so the cookie may be sent.
    pub async fn create_session(
        &self,
        s: &SessionRecord,
        replaces: Option<&SessionKey>,
    ) -> Result<()> {
        check_text("session client", s.client.as_deref().unwrap_or(""), 256)?;
        let agent = s.user_agent.as_deref().map(|a| truncate(a, 256));
        on_backend!(self, writer, |p| {
            let mut tx = p.begin().await.map_err(db("creating a session"))?;
            if let Some(old) = replaces {
                sqlx::query("DELETE FROM sessions WHERE token_hash = $1")
                    .bind(old.as_str())
                    .execute(&mut *tx)
                    .await
                    .map_err(db("creating a session"))?;
            }
            sqlx::query(&format!(
                "INSERT INTO sessions ({SESSION_COLS}) VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9)"
            ))
            .bind(s.key.as_str())
            .bind(&s.user)
            .bind(s.role.label())
            .bind(s.created_at.as_millis())
            .bind(s.last_seen.as_millis())
            .bind(s.idle.map(millis))
            .bind(s.expires_at.map(|t| t.as_millis()))
            .bind(s.client.as_deref())
            .bind(agent)
            .execute(&mut *tx)
            .await
            .map_err(db("creating a session"))?;
            tx.commit().await.map_err(db("creating a session"))?;
        });
        Ok(())
    }

    /// The session of that key, if stored (expired or not: see
    /// [`SessionRecord::expired`]).
    pub async fn session(&self, key: &SessionKey) -> Result<Option<SessionRecord>> {
        let row: Option<SessionRow> = on_backend!(self, reader, |p| {
            sqlx::query_as(&format!(
                "SELECT {SESSION_COLS} FROM sessions WHERE token_hash = $1"
            ))
            .bind(key.as_str())
            .fetch_optional(p)
            .await
            .map_err(db("reading a session"))?
        });
        row.map(session).transpose()
    }

    /// Every stored session, by user and age.
    pub async fn sessions(&self) -> Result<Vec<SessionRecord>> {
        let rows: Vec<SessionRow> = on_backend!(self, reader, |p| {
            sqlx::query_as(&format!(
                "SELECT {SESSION_COLS} FROM sessions ORDER BY user_name, created_at"
            ))
            .fetch_all(p)
            .await
            .map_err(db("listing sessions"))?
        });
        rows.into_iter().map(session).collect()
    }

    /// Ends one session (logout); returns whether it was stored.
    pub async fn end_session(&self, key: &SessionKey) -> Result<bool> {
        Ok(on_backend!(self, writer, |p| {
            sqlx::query("DELETE FROM sessions WHERE token_hash = $1")
                .bind(key.as_str())
                .execute(p)
                .await
                .map_err(db("ending a session"))?
                .rows_affected()
                > 0
        }))
    }

    /// Ends every session of `user` but `keep`; returns how many ended.
    pub async fn end_user_sessions(&self, user: &str, keep: Option<&SessionKey>) -> Result<u64> {
        Ok(on_backend!(self, writer, |p| {
            let n: std::result::Result<u64, sqlx::Error> =
                revoke_on!(p, user, Revoke::AllBut(keep));
            n.map_err(db("ending a user's sessions"))?
        }))
    }

    /// Writes the sessions' last activity through, in one transaction; a
    /// stored time later than the one given is kept (another server saw
    /// the session since).
    pub async fn touch_sessions(&self, seen: &[(SessionKey, Timestamp)]) -> Result<()> {
        if seen.is_empty() {
            return Ok(());
        }
        on_backend!(self, writer, |p| {
            let mut tx = p.begin().await.map_err(db("recording session activity"))?;
            for (key, at) in seen {
                sqlx::query(
                    "UPDATE sessions SET last_seen = $2 WHERE token_hash = $1 AND last_seen < $2",
                )
                .bind(key.as_str())
                .bind(at.as_millis())
                .execute(&mut *tx)
                .await
                .map_err(db("recording session activity"))?;
            }
            tx.commit()
                .await
                .map_err(db("recording session activity"))?;
        });
        Ok(())
    }

    /// Records a failover ticket, ending `replaces` (an earlier ticket of
    /// the same session; one of another session is left alone) in the same
    /// transaction.
    pub async fn create_ticket(
        &self,
        t: &TicketRecord,
        replaces: Option<&SessionKey>,
    ) -> Result<()> {
        on_backend!(self, writer, |p| {
            let mut tx = p.begin().await.map_err(db("issuing a failover ticket"))?;
            if let Some(old) = replaces {
                sqlx::query(
                    "DELETE FROM handover_tickets WHERE ticket_hash = $1 AND session_hash = $2",
                )
                .bind(old.as_str())
                .bind(t.session.as_str())
                .execute(&mut *tx)
                .await
                .map_err(db("issuing a failover ticket"))?;
            }
            sqlx::query(&format!(
                "INSERT INTO handover_tickets ({TICKET_COLS}) VALUES ($1, $2, $3, $4, $5, $6, $7)"
            ))
            .bind(t.key.as_str())
            .bind(t.session.as_str())
            .bind(&t.user)
            .bind(t.role.label())
            .bind(t.created_at.as_millis())
            .bind(t.expires_at.as_millis())
            .bind(t.session_expires_at.map(|e| e.as_millis()))
            .execute(&mut *tx)
            .await
            .map_err(db("issuing a failover ticket"))?;
            tx.commit().await.map_err(db("issuing a failover ticket"))?;
        });
        Ok(())
    }

    /// Claims the ticket of `key` at `now`: its row goes whatever the
    /// outcome (good once), and it is returned only if it had not expired
    /// and the session it was issued from is still stored, live and of the
    /// same user and role (a logout, a revocation or the sweep ended it
    /// otherwise).
    pub async fn claim_ticket(
        &self,
        key: &SessionKey,
        now: Timestamp,
    ) -> Result<Option<TicketRecord>> {
        let (row, origin): (Option<TicketRow>, Option<SessionRow>) =
            on_backend!(self, writer, |p| {
                let mut tx = p.begin().await.map_err(db("claiming a failover ticket"))?;
                let row: Option<TicketRow> = sqlx::query_as(&format!(
                    "DELETE FROM handover_tickets WHERE ticket_hash = $1 RETURNING {TICKET_COLS}"
                ))
                .bind(key.as_str())
                .fetch_optional(&mut *tx)
                .await
                .map_err(db("claiming a failover ticket"))?;
                let origin: Option<SessionRow> = match &row {
                    Some(r) => sqlx::query_as(&format!(
                        "SELECT {SESSION_COLS} FROM sessions WHERE token_hash = $1"
                    ))
                    .bind(&r.1)
                    .fetch_optional(&mut *tx)
                    .await
                    .map_err(db("claiming a failover ticket"))?,
                    None => None,
                };
                tx.commit()
                    .await
                    .map_err(db("claiming a failover ticket"))?;
                (row, origin)
            });
        let (Some(row), Some(origin)) = (row, origin) else {
            return Ok(None);
        };
        let (t, origin) = (ticket(row)?, session(origin)?);
        let good = now <= t.expires_at
            && !origin.expired(now)
            && origin.user == t.user
            && origin.role == t.role;
        Ok(good.then_some(t))
    }

    /// Deletes the sessions that ended by `now`: past their absolute end, or
    /// idle for longer than their timeout plus `grace` (how far the stored
    /// `last_seen` may trail the real last activity, so that a session
    /// still in use on a server that has not written its activity yet is
    /// not deleted). Returns how many went.
    /// Failover tickets that expired or whose session is gone go too.
    pub async fn sweep_sessions(&self, now: Timestamp, grace: Duration) -> Result<u64> {
        Ok(on_backend!(self, writer, |p| {
            let n = sqlx::query(
                "DELETE FROM sessions WHERE (expires_at IS NOT NULL AND expires_at < $1) \
                 OR (idle_ms IS NOT NULL AND last_seen + idle_ms + $2 < $1)",
            )
            .bind(now.as_millis())
            .bind(millis(grace))
            .execute(p)
            .await
            .map_err(db("sweeping expired sessions"))?
            .rows_affected();
            sqlx::query(
                "DELETE FROM handover_tickets WHERE expires_at < $1 \
                 OR session_hash NOT IN (SELECT token_hash FROM sessions)",
            )
            .bind(now.as_millis())
            .execute(p)
            .await
            .map_err(db("sweeping failover tickets"))?;
            n
        }))
    }
}

/// At most `max` bytes of `s`, cut at a character boundary.
fn truncate(s: &str, max: usize) -> &str {
    let mut end = s.len().min(max);
    while !s.is_char_boundary(end) {
        end -= 1;
    }
    &s[..end]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn key_is_the_tokens_sha256() {
        // SHA-256("abc") from FIPS 180-2.
        assert_eq!(
            SessionKey::of_token("abc").as_str(),
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
    }

    #[test]
    fn truncation_keeps_whole_characters() {
        assert_eq!(truncate("ab€", 3), "ab");
        assert_eq!(truncate("abc", 10), "abc");
    }
}
