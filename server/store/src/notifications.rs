//! The outbox of alarm notifications: messages waiting to be delivered
//! (kept so that delivery is retried across a restart), and the record of
//! what was sent or given up.
//!
//! **Owns:** the `notifications` table. **Must not touch:** what a message
//! says, who gets it or how it is sent (the notifier's); the message is
//! opaque text here.

use gridscada_tagdb::Timestamp;

use crate::error::db;
use crate::events::check_text;
use crate::{Result, Store, StoreError};

/// A message to queue.
#[derive(Debug, Clone, PartialEq)]
pub struct NewNotification {
    pub created_at: Timestamp,
    /// The `[[notify]]` route's name.
    pub route: String,
    pub contact: String,
    pub address: String,
    /// The alarm it is about; `None` for a flood summary.
    pub alarm_key: Option<String>,
    /// The step of the escalation chain (0: the first contact notified).
    pub level: u32,
    pub subject: String,
    /// The rendered message (the notifier's JSON).
    pub message: String,
    /// When to stop retrying.
    pub give_up_at: Timestamp,
}

/// Where a queued message stands.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NotificationStatus {
    Pending,
    Sent,
    /// Given up after retrying.
    Failed,
}

impl NotificationStatus {
    pub fn as_str(self) -> &'static str {
        match self {
            NotificationStatus::Pending => "pending",
            NotificationStatus::Sent => "sent",
            NotificationStatus::Failed => "failed",
        }
    }
    fn parse(s: &str) -> Option<Self> {
        [Self::Pending, Self::Sent, Self::Failed]
            .into_iter()
            .find(|x| x.as_str() == s)
    }
}

/// A queued (or delivered) message.
#[derive(Debug, Clone, PartialEq)]
pub struct Notification {
    pub id: i64,
    pub new: NewNotification,
    pub status: NotificationStatus,
    pub attempts: u32,
    pub next_attempt: Timestamp,
    pub last_error: Option<String>,
    pub done_at: Option<Timestamp>,
}

type Row = (
    i64,
    i64,
    String,
    String,
    String,
    Option<String>,
    i64,
    String,
    String,
    String,
    i64,
    i64,
    i64,
    Option<String>,
    Option<i64>,
);

const COLS: &str = "id, created_at, route, contact, address, alarm_key, level, subject, message, \
                    status, attempts, next_attempt, give_up_at, last_error, done_at";

fn notification(r: Row) -> Result<Notification> {
    let status = NotificationStatus::parse(&r.9)
        .ok_or_else(|| StoreError::Corrupt(format!("notification {} has status '{}'", r.0, r.9)))?;
    Ok(Notification {
        id: r.0,
        new: NewNotification {
            created_at: Timestamp::from_millis(r.1),
            route: r.2,
            contact: r.3,
            address: r.4,
            alarm_key: r.5,
            level: u32::try_from(r.6).unwrap_or(0),
            subject: r.7,
            message: r.8,
            give_up_at: Timestamp::from_millis(r.12),
        },
        status,
        attempts: u32::try_from(r.10).unwrap_or(0),
        next_attempt: Timestamp::from_millis(r.11),
        last_error: r.13,
        done_at: r.14.map(Timestamp::from_millis),
    })
}

/// The longest error text kept with a message.
const MAX_ERROR: usize = 1000;

/// The last escalation step notified for an alarm on a route.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LastNotified {
    pub alarm_key: String,
    pub level: u32,
    pub at: Timestamp,
}

impl Store {
    /// Queues a message, due now; durable when it returns. Its id.
    pub async fn enqueue_notification(&self, n: &NewNotification) -> Result<i64> {
        check_text("notification subject", &n.subject, 1000)?;
        check_text("notification message", &n.message, 64 * 1024)?;
        self.writable("queueing a notification")?;
        let id: i64 = on_backend!(self, writer, |p| {
            sqlx::query_scalar(
                "INSERT INTO notifications (created_at, route, contact, address, alarm_key, level, \
                 subject, message, status, attempts, next_attempt, give_up_at, site) \
                 VALUES ($1, $2, $3, $4, $5, $6, $7, $8, 'pending', 0, $1, $9, $10) RETURNING id",
            )
            .bind(n.created_at.as_millis())
            .bind(&n.route)
            .bind(&n.contact)
            .bind(&n.address)
            .bind(n.alarm_key.as_deref())
            .bind(i64::from(n.level))
            .bind(&n.subject)
            .bind(&n.message)
            .bind(n.give_up_at.as_millis())
            .bind(&*self.site)
            .fetch_one(p)
            .await
            .map_err(db("queueing a notification"))?
        });
        Ok(id)
    }

    /// Pending messages due by `now`, oldest first, at most `limit`.
    pub async fn due_notifications(&self, now: Timestamp, limit: u32) -> Result<Vec<Notification>> {
        let rows: Vec<Row> = on_backend!(self, reader, |p| {
            sqlx::query_as(&format!(
                "SELECT {COLS} FROM notifications WHERE status = 'pending' AND next_attempt <= $1 \
                 AND site = $3 ORDER BY next_attempt, id LIMIT $2"
            ))
            .bind(now.as_millis())
            .bind(i64::from(limit))
            .bind(&*self.site)
            .fetch_all(p)
            .await
            .map_err(db("reading due notifications"))?
        });
        rows.into_iter().map(notification).collect()
    }

    /// When the next pending message is due, if any.
    pub async fn next_notification_due(&self) -> Result<Option<Timestamp>> {
        let t: Option<i64> = on_backend!(self, reader, |p| {
            sqlx::query_scalar(
                "SELECT MIN(next_attempt) FROM notifications WHERE status = 'pending' AND site = $1",
            )
            .bind(&*self.site)
            .fetch_one(p)
            .await
            .map_err(db("reading due notifications"))?
        });
        Ok(t.map(Timestamp::from_millis))
    }

    /// How many messages wait for delivery.
    pub async fn pending_notifications(&self) -> Result<u64> {
        let n: i64 = on_backend!(self, reader, |p| {
            sqlx::query_scalar(
                "SELECT COUNT(*) FROM notifications WHERE status = 'pending' AND site = $1",
            )
            .bind(&*self.site)
            .fetch_one(p)
            .await
            .map_err(db("counting pending notifications"))?
        });
        Ok(u64::try_from(n).unwrap_or(0))
    }

    /// Marks a message delivered.
    pub async fn notification_sent(&self, id: i64, at: Timestamp, attempts: u32) -> Result<()> {
        on_backend!(self, writer, |p| {
            sqlx::query(
                "UPDATE notifications SET status = 'sent', done_at = $2, attempts = $3, \
                 last_error = NULL WHERE id = $1",
            )
            .bind(id)
            .bind(at.as_millis())
            .bind(i64::from(attempts))
            .execute(p)
            .await
            .map_err(db("recording a sent notification"))?;
        });
        Ok(())
    }

    /// Records a failed attempt: retried at `next`, or given up (`None`).
    pub async fn notification_attempt_failed(
        &self,
        id: i64,
        attempts: u32,
        next: Option<Timestamp>,
        at: Timestamp,
        error: &str,
    ) -> Result<()> {
        let error: String = error.chars().take(MAX_ERROR).collect();
        on_backend!(self, writer, |p| {
            match next {
                Some(next) => sqlx::query(
                    "UPDATE notifications SET attempts = $2, next_attempt = $3, last_error = $4 \
                     WHERE id = $1",
                )
                .bind(id)
                .bind(i64::from(attempts))
                .bind(next.as_millis())
                .bind(&error)
                .execute(p)
                .await,
                None => {
                    sqlx::query(
                        "UPDATE notifications SET status = 'failed', attempts = $2, done_at = $3, \
                     last_error = $4 WHERE id = $1",
                    )
                    .bind(id)
                    .bind(i64::from(attempts))
                    .bind(at.as_millis())
                    .bind(&error)
                    .execute(p)
                    .await
                }
            }
            .map_err(db("recording a failed notification"))?;
        });
        Ok(())
    }

    /// For each alarm notified on `route` since `since`, its latest
    /// escalation step: what a restart resumes escalation from.
    pub async fn last_notified(&self, route: &str, since: Timestamp) -> Result<Vec<LastNotified>> {
        let rows: Vec<(String, i64, i64)> = on_backend!(self, reader, |p| {
            sqlx::query_as(
                "SELECT alarm_key, MAX(level), MAX(created_at) FROM notifications \
                 WHERE route = $1 AND alarm_key IS NOT NULL AND created_at >= $2 AND site = $3 \
                 GROUP BY alarm_key",
            )
            .bind(route)
            .bind(since.as_millis())
            .bind(&*self.site)
            .fetch_all(p)
            .await
            .map_err(db("reading notified alarms"))?
        });
        Ok(rows
            .into_iter()
            .map(|(alarm_key, level, at)| LastNotified {
                alarm_key,
                level: u32::try_from(level).unwrap_or(0),
                at: Timestamp::from_millis(at),
            })
            .collect())
    }

    /// The newest messages, newest first (for tests and the record).
    pub async fn notifications(&self, limit: u32) -> Result<Vec<Notification>> {
        let rows: Vec<Row> = on_backend!(self, reader, |p| {
            sqlx::query_as(&format!(
                "SELECT {COLS} FROM notifications WHERE site = $2 ORDER BY id DESC LIMIT $1"
            ))
            .bind(i64::from(limit))
            .bind(&*self.site)
            .fetch_all(p)
            .await
            .map_err(db("listing notifications"))?
        });
        rows.into_iter().map(notification).collect()
    }

    /// Deletes delivered and given-up messages finished before `before`, at
    /// most `limit`; how many.
    pub async fn prune_notifications(&self, before: Timestamp, limit: u32) -> Result<u64> {
        Ok(on_backend!(self, writer, |p| {
            sqlx::query(
                "DELETE FROM notifications WHERE id IN (SELECT id FROM notifications \
                 WHERE status <> 'pending' AND done_at < $1 AND site = $3 ORDER BY id LIMIT $2)",
            )
            .bind(before.as_millis())
            .bind(i64::from(limit))
            .bind(&*self.site)
            .execute(p)
            .await
            .map_err(db("pruning notifications"))?
            .rows_affected()
        }))
    }
}
