//! The event log: operator actions (commands, resets, acknowledgements,
//! logins) and system events (sequence steps, dispatch).
//!
//! **Owns:** the `events` table. **Must not touch:** deciding what is an event;
//! callers do.

use gridscada_tagdb::Timestamp;
use serde::{Deserialize, Serialize};

use crate::error::db;
use crate::{Result, Store, StoreError};

/// An event to record.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NewEvent {
    pub ts: Timestamp,
    /// The user who caused it; `None` for the system.
    pub user: Option<String>,
    /// What raised it, e.g. `SS1.Panel`, `dispatch`, `web`.
    pub source: String,
    /// Its type, e.g. `command`, `reset`, `ack`, `login`, `sequence`.
    pub kind: String,
    pub message: String,
}

/// A recorded event.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Event {
    pub id: i64,
    pub ts: Timestamp,
    pub user: Option<String>,
    pub source: String,
    pub kind: String,
    pub message: String,
}

/// Which events to list. Every filter is optional; results are newest first.
#[derive(Debug, Clone, Default)]
pub struct EventFilter {
    /// `from..to`; pass the bounds of the local day for "Today".
    pub from: Option<Timestamp>,
    pub to: Option<Timestamp>,
    pub kind: Option<String>,
    pub user: Option<String>,
    pub source: Option<String>,
    /// Case-insensitive substring of the message.
    pub text: Option<String>,
    /// At most this many (capped at 10,000).
    pub limit: u32,
    pub offset: u32,
}

/// The conditions of [`EventFilter`], binds `$1` to `$7`, the last the site (the list and the
/// CSV export filter alike).
pub(crate) const EVENTS_WHERE: &str = "WHERE ($1 IS NULL OR ts >= $1) AND ($2 IS NULL OR ts < $2) \
       AND ($3 IS NULL OR kind = $3) AND ($4 IS NULL OR user_name = $4) \
       AND ($5 IS NULL OR source = $5) \
       AND ($6 IS NULL OR lower(message) LIKE $6 ESCAPE '\\') AND site = $7";

/// The most rows one list query returns.
pub(crate) const MAX_LIST: u32 = 10_000;

/// A `LIKE` pattern matching `text` as a literal substring, lowercased.
pub(crate) fn like_pattern(text: &str) -> String {
    let mut p = String::with_capacity(text.len() + 2);
    p.push('%');
    for c in text.to_lowercase().chars() {
        if matches!(c, '%' | '_' | '\\') {
            p.push('\\');
        }
        p.push(c);
    }
    p.push('%');
    p
}

pub(crate) fn check_text(what: &str, s: &str, max: usize) -> Result<()> {
    if s.len() > max {
        return Err(StoreError::Invalid(format!(
            "{what} is {} bytes; at most {max}",
            s.len()
        )));
    }
    Ok(())
}

/// `s` with every control character escaped as Rust writes it.
pub(crate) fn escape_control_chars(s: &str) -> std::borrow::Cow<'_, str> {
    if !s.chars().any(char::is_control) {
        return std::borrow::Cow::Borrowed(s);
    }
    std::borrow::Cow::Owned(
        s.chars()
            .map(|c| {
                if c.is_control() {
                    c.escape_default().to_string()
                } else {
                    c.to_string()
                }
            })
            .collect(),
    )
}

pub(crate) fn escape_controls(e: &NewEvent) -> NewEvent {
    NewEvent {
        ts: e.ts,
        user: e
            .user
            .as_deref()
            .map(|u| escape_control_chars(u).into_owned()),
        source: escape_control_chars(&e.source).into_owned(),
        kind: escape_control_chars(&e.kind).into_owned(),
        message: escape_control_chars(&e.message).into_owned(),
    }
}

impl Store {
    /// Records one event; returns its id once committed.
    pub async fn insert_event(&self, event: &NewEvent) -> Result<i64> {
        Ok(self
            .insert_events(std::slice::from_ref(event))
            .await?
            .pop()
            .unwrap_or_default())
    }

    /// Records events in one transaction; returns their ids once committed.
    ///
    /// Control characters in any field are stored escaped (`\n`, `\u{1b}`),
    /// so text from outside (a login name, a tag value) can never forge a
    /// second line in the log.
    pub async fn insert_events(&self, events: &[NewEvent]) -> Result<Vec<i64>> {
        let events: Vec<NewEvent> = events.iter().map(escape_controls).collect();
        let events = &events[..];
        for e in events {
            check_text("event source", &e.source, 256)?;
            check_text("event type", &e.kind, 64)?;
            check_text("event message", &e.message, 8192)?;
            if let Some(u) = &e.user {
                check_text("event user", u, 256)?;
            }
        }
        self.writable("recording events")?;
        Ok(on_backend!(self, writer, |p| {
            let mut tx = p.begin().await.map_err(db("recording events"))?;
            let mut ids = Vec::with_capacity(events.len());
            for e in events {
                let id: i64 = sqlx::query_scalar(
                    "INSERT INTO events (ts, user_name, source, kind, message, site) \
                     VALUES ($1, $2, $3, $4, $5, $6) RETURNING id",
                )
                .bind(e.ts.as_millis())
                .bind(e.user.as_deref())
                .bind(&e.source)
                .bind(&e.kind)
                .bind(&e.message)
                .bind(&*self.site)
                .fetch_one(&mut *tx)
                .await
                .map_err(db("recording events"))?;
                ids.push(id);
            }
            tx.commit().await.map_err(db("recording events"))?;
            ids
        }))
    }

    /// Lists events matching `filter`, newest first.
    pub async fn events(&self, filter: &EventFilter) -> Result<Vec<Event>> {
        let text = filter.text.as_deref().map(like_pattern);
        let limit = filter.limit.min(MAX_LIST) as i64;
        let sql = format!(
            "SELECT id, ts, user_name, source, kind, message FROM events {EVENTS_WHERE} \
             ORDER BY ts DESC, id DESC LIMIT $8 OFFSET $9"
        );
        let rows: Vec<(i64, i64, Option<String>, String, String, String)> =
            on_backend!(self, reader, |p| {
                sqlx::query_as(&sql)
                    .bind(filter.from.map(Timestamp::as_millis))
                    .bind(filter.to.map(Timestamp::as_millis))
                    .bind(filter.kind.as_deref())
                    .bind(filter.user.as_deref())
                    .bind(filter.source.as_deref())
                    .bind(text.as_deref())
                    .bind(&*self.site)
                    .bind(limit)
                    .bind(filter.offset as i64)
                    .fetch_all(p)
                    .await
                    .map_err(db("listing events"))?
            });
        Ok(rows
            .into_iter()
            .map(|(id, ts, user, source, kind, message)| Event {
                id,
                ts: Timestamp::from_millis(ts),
                user,
                source,
                kind,
                message,
            })
            .collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn like_patterns_are_literal() {
        assert_eq!(like_pattern("Breaker"), "%breaker%");
        assert_eq!(like_pattern("50%_a\\"), "%50\\%\\_a\\\\%");
    }
}
