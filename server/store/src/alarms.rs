//! Alarm persistence: the current state of each alarm (so acknowledgements,
//! shelving and out-of-service survive a restart) and the history of every
//! state transition.
//!
//! **Owns:** the `alarm_states` and `alarm_history` tables. **Must not touch:**
//! the ISA-18.2 state machine and its metrics (server/alarms); states are opaque
//! strings here, and which transitions are activations is the caller's call.

use gridscada_tagdb::{Timestamp, Value};
use serde::{Deserialize, Serialize};

use crate::error::db;
use crate::events::{check_text, like_pattern, MAX_LIST};
use crate::{Result, Store, StoreError};

/// The persisted state of one alarm: the alarm engine's own record, stored
/// column for column so that a restart restores exactly what was there.
pub use gridscada_alarms::AlarmStateRecord;

/// One alarm state transition to record.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AlarmTransition {
    pub ts: Timestamp,
    pub alarm_key: String,
    pub tag: String,
    pub kind: String,
    pub from_state: String,
    pub to_state: String,
    /// Why it happened: the alarm engine's `TransitionCause` by name
    /// (`activate`, `return`, `ack`, `shelve`, `unshelve`, `shelve_expired`,
    /// `suppress`, `unsuppress`, `out_of_service`, `in_service`). It tells an
    /// activation from a return where the state stays the same (both
    /// "suppressed → suppressed"). `None` on rows recorded before it was kept.
    pub cause: Option<String>,
    /// Whether this transition is an annunciated activation (counts towards
    /// the alarm rate).
    pub activation: bool,
    pub value: Option<f64>,
    pub limit: Option<f64>,
    /// Who caused it (ack, shelve); `None` for the process.
    pub user: Option<String>,
    pub message: String,
    /// Higher is more important.
    pub priority: i32,
    /// The alarm group shown in the alarm screen's selection filter.
    pub selection: String,
}

impl From<&gridscada_alarms::AlarmTransition> for AlarmTransition {
    /// The engine's transition as a history row.
    fn from(t: &gridscada_alarms::AlarmTransition) -> Self {
        AlarmTransition {
            ts: t.time,
            alarm_key: t.key.clone(),
            tag: t.tag.clone().unwrap_or_default(),
            kind: t.kind.as_str().to_string(),
            from_state: t.from.as_str().to_string(),
            to_state: t.to.as_str().to_string(),
            cause: Some(t.cause.as_str().to_string()),
            activation: t.is_annunciated_activation(),
            value: t.value.as_ref().and_then(|v| v.as_f64()),
            limit: t.limit.as_ref().and_then(|v| v.as_f64()),
            user: t.user.clone(),
            message: t.message.clone(),
            priority: i32::try_from(t.priority).unwrap_or(i32::MAX),
            selection: t.selection.clone(),
        }
    }
}

/// A recorded transition.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct AlarmTransitionRecord {
    pub id: i64,
    #[serde(flatten)]
    pub transition: AlarmTransition,
}

/// Which transitions to list. Every filter is optional.
#[derive(Debug, Clone, Default)]
pub struct AlarmHistoryFilter {
    pub from: Option<Timestamp>,
    pub to: Option<Timestamp>,
    pub alarm_key: Option<String>,
    pub tag: Option<String>,
    pub kind: Option<String>,
    pub selection: Option<String>,
    pub min_priority: Option<i32>,
    /// Only activations.
    pub activations_only: bool,
    /// Case-insensitive substring of the message.
    pub text: Option<String>,
    /// At most this many (capped at 10,000).
    pub limit: u32,
    pub offset: u32,
    /// Oldest first instead of newest first (metrics replay in time order).
    pub oldest_first: bool,
}

/// The conditions of [`AlarmHistoryFilter`], binds `$1` to `$10`, the last the site (the list
/// and the CSV export filter alike).
pub(crate) const HISTORY_WHERE: &str =
    "WHERE ($1 IS NULL OR ts >= $1) AND ($2 IS NULL OR ts < $2) \
       AND ($3 IS NULL OR alarm_key = $3) AND ($4 IS NULL OR tag = $4) \
       AND ($5 IS NULL OR kind = $5) AND ($6 IS NULL OR selection = $6) \
       AND ($7 IS NULL OR priority >= $7) AND ($8 = FALSE OR activation = TRUE) \
       AND ($9 IS NULL OR lower(message) LIKE $9 ESCAPE '\\') AND site = $10";

/// Activations of one alarm in a time range.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct ActivationCount {
    pub alarm_key: String,
    pub count: u64,
}

pub(crate) type TransitionRow = (
    i64,
    i64,
    String,
    String,
    String,
    String,
    String,
    Option<String>,
    bool,
    Option<f64>,
    Option<f64>,
    Option<String>,
    String,
    i32,
    String,
);

type StateRow = (
    String,
    String,
    String,
    bool,
    bool,
    Option<i64>,
    i64,
    String,
    i64,
    String,
    (Option<String>, Option<i64>, Option<i64>, Option<String>),
    (bool, Option<String>, Option<i64>, Option<String>),
    Option<String>,
    Option<i64>,
);

fn ts(v: Option<i64>) -> Option<Timestamp> {
    v.map(Timestamp::from_millis)
}

/// The value at activation as stored: its type and its exact text
/// (`b:true`, `i:-5`, `u:18446744073709551615`, `f:230.5`, `s:text`), so it
/// reads back as the same value, a wide integer exactly.
///
/// `None` for a text too long to keep (or with a NUL, which PostgreSQL's
/// TEXT refuses): it is only shown, and must not stop the state being saved.
fn encode_value(v: &Value) -> Option<String> {
    let text = match v {
        Value::Bool(b) => format!("b:{b}"),
        Value::Int(i) => format!("i:{i}"),
        Value::UInt(u) => format!("u:{u}"),
        // `{}` of an f64 is its shortest exact form (and NaN, inf).
        Value::Float(f) => format!("f:{f}"),
        Value::Str(t) => format!("s:{t}"),
    };
    (text.len() <= 4096 && !text.contains('\0')).then_some(text)
}

/// Reads [`encode_value`]'s text back; `None` if it is not one.
fn decode_value(text: &str) -> Option<Value> {
    let (kind, rest) = text.split_once(':')?;
    Some(match kind {
        "b" => Value::Bool(rest.parse().ok()?),
        "i" => Value::Int(rest.parse().ok()?),
        "u" => Value::UInt(rest.parse().ok()?),
        "f" => Value::Float(rest.parse().ok()?),
        "s" => Value::Str(rest.into()),
        _ => return None,
    })
}

/// One transition's INSERT into `alarm_history`, bound: one statement for
/// the direct path (`audit_id` NULL) and the audit trail's (its record id),
/// so the two cannot drift apart. Yields the new row's id, or no row when a
/// record with the same audit id is already stored (a spool replay).
macro_rules! insert_alarm_transition {
    ($site:expr, $t:expr, $audit_id:expr) => {{
        let t = $t;
        sqlx::query_scalar::<_, i64>(
            "INSERT INTO alarm_history (ts, alarm_key, tag, kind, from_state, to_state, \
               cause, activation, value, limit_value, user_name, message, priority, \
               selection, audit_id, site) \
             VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10, $11, $12, $13, $14, $15, $16) \
             ON CONFLICT (site, audit_id) DO NOTHING \
             RETURNING id",
        )
        .bind(t.ts.as_millis())
        .bind(&t.alarm_key)
        .bind(&t.tag)
        .bind(&t.kind)
        .bind(&t.from_state)
        .bind(&t.to_state)
        .bind(t.cause.as_deref())
        .bind(t.activation)
        .bind(t.value.filter(|v| v.is_finite()))
        .bind(t.limit.filter(|v| v.is_finite()))
        .bind(t.user.as_deref())
        .bind(&t.message)
        .bind(t.priority)
        .bind(&t.selection)
        .bind($audit_id)
        .bind($site)
    }};
}
pub(crate) use insert_alarm_transition;

impl Store {
    /// Inserts or replaces the persisted state of alarms, in one transaction.
    /// A record older (by `last_change`) than the stored one is ignored, so two
    /// writers of the same state never roll it back.
    pub async fn upsert_alarm_states(&self, states: &[AlarmStateRecord]) -> Result<()> {
        for s in states {
            check_text("alarm key", &s.key, 512)?;
            check_text("alarm message", &s.message, 4096)?;
            check_text(
                "alarm shelve reason",
                s.shelve_reason.as_deref().unwrap_or(""),
                2048,
            )?;
            check_text(
                "out-of-service reason",
                s.out_of_service_reason.as_deref().unwrap_or(""),
                2048,
            )?;
        }
        self.writable("saving alarm states")?;
        on_backend!(self, writer, |p| {
            let mut tx = p.begin().await.map_err(db("saving alarm states"))?;
            for s in states {
                sqlx::query(
                    "INSERT INTO alarm_states (alarm_key, kind, state, active, acked, \
                       active_since, last_change, message, priority, selection, shelved_by, \
                       shelved_at, shelved_until, shelve_reason, out_of_service, \
                       out_of_service_by, out_of_service_since, out_of_service_reason, \
                       activation_value, out_of_service_until, site) \
                     VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10, $11, $12, $13, $14, $15, \
                       $16, $17, $18, $19, $20, $21) \
                     ON CONFLICT (site, alarm_key) DO UPDATE SET kind = excluded.kind, \
                       state = excluded.state, active = excluded.active, acked = excluded.acked, \
                       active_since = excluded.active_since, last_change = excluded.last_change, \
                       message = excluded.message, priority = excluded.priority, \
                       selection = excluded.selection, shelved_by = excluded.shelved_by, \
                       shelved_at = excluded.shelved_at, shelved_until = excluded.shelved_until, \
                       shelve_reason = excluded.shelve_reason, \
                       out_of_service = excluded.out_of_service, \
                       out_of_service_by = excluded.out_of_service_by, \
                       out_of_service_since = excluded.out_of_service_since, \
                       out_of_service_reason = excluded.out_of_service_reason, \
                       activation_value = excluded.activation_value, \
                       out_of_service_until = excluded.out_of_service_until \
                     WHERE excluded.last_change >= alarm_states.last_change",
                )
                .bind(&s.key)
                .bind(s.kind.as_str())
                .bind(s.state.as_str())
                .bind(s.active)
                .bind(s.acked)
                .bind(s.active_since.map(Timestamp::as_millis))
                .bind(s.last_change.as_millis())
                .bind(&s.message)
                .bind(i64::from(s.priority))
                .bind(&s.selection)
                .bind(s.shelved_by.as_deref())
                .bind(s.shelved_at.map(Timestamp::as_millis))
                .bind(s.shelved_until.map(Timestamp::as_millis))
                .bind(s.shelve_reason.as_deref())
                .bind(s.out_of_service)
                .bind(s.out_of_service_by.as_deref())
                .bind(s.out_of_service_since.map(Timestamp::as_millis))
                .bind(s.out_of_service_reason.as_deref())
                .bind(s.activation_value.as_ref().and_then(encode_value))
                .bind(s.out_of_service_until.map(Timestamp::as_millis))
                .bind(&*self.site)
                .execute(&mut *tx)
                .await
                .map_err(db("saving alarm states"))?;
            }
            tx.commit().await.map_err(db("saving alarm states"))?;
        });
        Ok(())
    }

    /// Forgets the persisted state of an alarm (e.g. it returned to normal and
    /// is acknowledged, or it left the configuration). Returns whether it existed.
    pub async fn delete_alarm_state(&self, alarm_key: &str) -> Result<bool> {
        self.writable("deleting an alarm state")?;
        Ok(on_backend!(self, writer, |p| {
            sqlx::query("DELETE FROM alarm_states WHERE site = $1 AND alarm_key = $2")
                .bind(&*self.site)
                .bind(alarm_key)
                .execute(p)
                .await
                .map_err(db("deleting an alarm state"))?
                .rows_affected()
                > 0
        }))
    }

    /// Every persisted alarm state, by key.
    pub async fn alarm_states(&self) -> Result<Vec<AlarmStateRecord>> {
        let rows: Vec<StateRow> = on_backend!(self, reader, |p| {
            use sqlx::Row;
            let rows = sqlx::query(
                "SELECT alarm_key, kind, state, active, acked, active_since, last_change, \
                   message, priority, selection, shelved_by, shelved_at, shelved_until, \
                   shelve_reason, out_of_service, out_of_service_by, out_of_service_since, \
                   out_of_service_reason, activation_value, out_of_service_until \
                 FROM alarm_states WHERE site = $1 ORDER BY alarm_key",
            )
            .bind(&*self.site)
            .fetch_all(p)
            .await
            .map_err(db("loading alarm states"))?;
            rows.iter()
                .map(|r| -> std::result::Result<StateRow, sqlx::Error> {
                    Ok((
                        r.try_get(0)?,
                        r.try_get(1)?,
                        r.try_get(2)?,
                        r.try_get(3)?,
                        r.try_get(4)?,
                        r.try_get(5)?,
                        r.try_get(6)?,
                        r.try_get(7)?,
                        r.try_get(8)?,
                        r.try_get(9)?,
                        (
                            r.try_get(10)?,
                            r.try_get(11)?,
                            r.try_get(12)?,
                            r.try_get(13)?,
                        ),
                        (
                            r.try_get(14)?,
                            r.try_get(15)?,
                            r.try_get(16)?,
                            r.try_get(17)?,
                        ),
                        r.try_get(18)?,
                        r.try_get(19)?,
                    ))
                })
                .collect::<std::result::Result<Vec<_>, _>>()
                .map_err(db("loading alarm states"))?
        });
        rows.into_iter()
            .map(|r| {
                let corrupt = |what: &str, v: &str| {
                    StoreError::Corrupt(format!("alarm '{}': unknown {what} '{v}'", r.0))
                };
                let kind = r.1.parse().map_err(|_| corrupt("kind", &r.1))?;
                let state = r.2.parse().map_err(|_| corrupt("state", &r.2))?;
                Ok(AlarmStateRecord {
                    key: r.0.clone(),
                    kind,
                    state,
                    active: r.3,
                    acked: r.4,
                    active_since: ts(r.5),
                    last_change: Timestamp::from_millis(r.6),
                    message: r.7,
                    priority: u32::try_from(r.8).unwrap_or(0),
                    selection: r.9,
                    shelved_by: r.10 .0,
                    shelved_at: ts(r.10 .1),
                    shelved_until: ts(r.10 .2),
                    shelve_reason: r.10 .3,
                    out_of_service: r.11 .0,
                    out_of_service_by: r.11 .1,
                    out_of_service_since: ts(r.11 .2),
                    out_of_service_reason: r.11 .3,
                    out_of_service_until: ts(r.13),
                    // Only shown beside the value now: an unreadable one is
                    // dropped rather than failing the restore of every alarm.
                    activation_value: r.12.as_deref().and_then(decode_value),
                })
            })
            .collect()
    }

    /// Records alarm transitions in one transaction; returns their ids.
    pub async fn insert_alarm_transitions(
        &self,
        transitions: &[AlarmTransition],
    ) -> Result<Vec<i64>> {
        for t in transitions {
            check_text("alarm key", &t.alarm_key, 512)?;
            check_text("alarm message", &t.message, 4096)?;
            check_text(
                "alarm transition cause",
                t.cause.as_deref().unwrap_or(""),
                64,
            )?;
        }
        self.writable("recording alarm transitions")?;
        Ok(on_backend!(self, writer, |p| {
            let mut tx = p.begin().await.map_err(db("recording alarm transitions"))?;
            let mut ids = Vec::with_capacity(transitions.len());
            for t in transitions {
                let id: i64 = insert_alarm_transition!(&*self.site, t, None::<i64>)
                    .fetch_one(&mut *tx)
                    .await
                    .map_err(db("recording alarm transitions"))?;
                ids.push(id);
            }
            tx.commit()
                .await
                .map_err(db("recording alarm transitions"))?;
            ids
        }))
    }

    /// Lists recorded transitions matching `filter`.
    pub async fn alarm_history(
        &self,
        f: &AlarmHistoryFilter,
    ) -> Result<Vec<AlarmTransitionRecord>> {
        let text = f.text.as_deref().map(like_pattern);
        let order = if f.oldest_first { "ASC" } else { "DESC" };
        let sql = format!(
            "SELECT id, ts, alarm_key, tag, kind, from_state, to_state, cause, activation, value, \
               limit_value, user_name, message, priority, selection FROM alarm_history \
             {HISTORY_WHERE} ORDER BY ts {order}, id {order} LIMIT $11 OFFSET $12"
        );
        let rows: Vec<TransitionRow> = on_backend!(self, reader, |p| {
            sqlx::query_as(&sql)
                .bind(f.from.map(Timestamp::as_millis))
                .bind(f.to.map(Timestamp::as_millis))
                .bind(f.alarm_key.as_deref())
                .bind(f.tag.as_deref())
                .bind(f.kind.as_deref())
                .bind(f.selection.as_deref())
                .bind(f.min_priority)
                .bind(f.activations_only)
                .bind(text.as_deref())
                .bind(&*self.site)
                .bind(f.limit.min(MAX_LIST) as i64)
                .bind(f.offset as i64)
                .fetch_all(p)
                .await
                .map_err(db("listing alarm history"))?
        });
        Ok(rows.into_iter().map(transition).collect())
    }

    /// Every activation in `from..to`, oldest first, for the alarm engine's
    /// ISA-18.2 metrics (alarm rate, floods, chattering, bad actors). Unlike
    /// [`Store::alarm_history`] this is not capped: the caller bounds the range.
    pub async fn alarm_activations(
        &self,
        from: Timestamp,
        to: Timestamp,
    ) -> Result<Vec<AlarmTransitionRecord>> {
        let rows: Vec<TransitionRow> = on_backend!(self, reader, |p| {
            sqlx::query_as(
                "SELECT id, ts, alarm_key, tag, kind, from_state, to_state, cause, activation, value, \
                   limit_value, user_name, message, priority, selection FROM alarm_history \
                 WHERE activation = TRUE AND ts >= $1 AND ts < $2 AND site = $3 ORDER BY ts, id",
            )
            .bind(from.as_millis())
            .bind(to.as_millis())
            .bind(&*self.site)
            .fetch_all(p)
            .await
            .map_err(db("listing alarm activations"))?
        });
        Ok(rows.into_iter().map(transition).collect())
    }

    /// Activations per alarm in `from..to`, most frequent first.
    pub async fn alarm_activation_counts(
        &self,
        from: Timestamp,
        to: Timestamp,
    ) -> Result<Vec<ActivationCount>> {
        let rows: Vec<(String, i64)> = on_backend!(self, reader, |p| {
            sqlx::query_as(
                "SELECT alarm_key, count(*) AS n FROM alarm_history \
                 WHERE activation = TRUE AND ts >= $1 AND ts < $2 AND site = $3 \
                 GROUP BY alarm_key ORDER BY n DESC, alarm_key",
            )
            .bind(from.as_millis())
            .bind(to.as_millis())
            .bind(&*self.site)
            .fetch_all(p)
            .await
            .map_err(db("counting alarm activations"))?
        });
        Ok(rows
            .into_iter()
            .map(|(alarm_key, n)| ActivationCount {
                alarm_key,
                count: n.max(0) as u64,
            })
            .collect())
    }
}

fn transition(r: TransitionRow) -> AlarmTransitionRecord {
    AlarmTransitionRecord {
        id: r.0,
        transition: AlarmTransition {
            ts: Timestamp::from_millis(r.1),
            alarm_key: r.2,
            tag: r.3,
            kind: r.4,
            from_state: r.5,
            to_state: r.6,
            cause: r.7,
            activation: r.8,
            value: r.9,
            limit: r.10,
            user: r.11,
            message: r.12,
            priority: r.13,
            selection: r.14,
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn activation_values_read_back_as_the_same_value() {
        for v in [
            Value::Bool(false),
            Value::Int(-5),
            Value::Int(i64::MIN),
            Value::UInt(u64::MAX),
            Value::Float(230.5),
            Value::Float(0.1 + 0.2),
            Value::Float(-0.0),
            Value::Float(f64::INFINITY),
            Value::Str("a:b".into()),
            Value::Str("".into()),
        ] {
            let text = encode_value(&v).unwrap();
            assert_eq!(decode_value(&text), Some(v.clone()), "{text}");
        }
        let nan = decode_value(&encode_value(&Value::Float(f64::NAN)).unwrap());
        assert!(matches!(nan, Some(Value::Float(f)) if f.is_nan()));
        assert_eq!(encode_value(&Value::Str("x".repeat(5000).into())), None);
        assert_eq!(encode_value(&Value::Str("a\0b".into())), None);
        assert_eq!(decode_value("x:1"), None);
        assert_eq!(decode_value("i:1.5"), None);
        assert_eq!(decode_value("230"), None);
    }
}
