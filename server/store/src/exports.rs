//! CSV exports of the event log, the alarm history and the dispatch
//! history, with the same filters as their lists but no row cap.
//!
//! **Owns:** streaming a query's rows into CSV: the rows come off one
//! query's row stream (`fetch`, not `fetch_all`) and go out through
//! [`CsvWriter`] in 64 KiB pieces, so memory stays flat however many rows
//! the export has. Text fields pass the formula-injection guard of
//! `csv.rs`, as the historian export's do.

use futures::TryStreamExt;
use gridscada_tagdb::Timestamp;
use tokio::io::AsyncWrite;

use crate::alarms::{TransitionRow, HISTORY_WHERE};
use crate::csv::CsvWriter;
use crate::dispatch::{Row as DispatchRow, COLS as DISPATCH_COLS};
use crate::error::db;
use crate::events::{like_pattern, EVENTS_WHERE};
use crate::{AlarmHistoryFilter, EventFilter, Result, Store};

type EventRow = (i64, i64, Option<String>, String, String, String);

impl Store {
    /// The events `filter` selects (its `limit` and `offset` ignored), newest
    /// first like the event screen, as CSV; the number of rows.
    pub async fn export_events_csv<W: AsyncWrite + Unpin>(
        &self,
        filter: &EventFilter,
        out: &mut W,
    ) -> Result<u64> {
        let text = filter.text.as_deref().map(like_pattern);
        let sql = format!(
            "SELECT id, ts, user_name, source, kind, message FROM events {EVENTS_WHERE} \
             ORDER BY ts DESC, id DESC"
        );
        let mut w = CsvWriter::new(
            out,
            "an event CSV export",
            "time_utc,ts_ms,user,source,type,message",
        );
        on_backend!(self, reader, |p| {
            let mut rows = sqlx::query_as::<_, EventRow>(&sql)
                .bind(filter.from.map(Timestamp::as_millis))
                .bind(filter.to.map(Timestamp::as_millis))
                .bind(filter.kind.as_deref())
                .bind(filter.user.as_deref())
                .bind(filter.source.as_deref())
                .bind(text.as_deref())
                .bind(&*self.site)
                .fetch(p);
            while let Some((_, ts, user, source, kind, message)) =
                rows.try_next().await.map_err(db("exporting events"))?
            {
                w.time(ts);
                w.opt_text(user.as_deref());
                w.text(&source);
                w.text(&kind);
                w.text(&message);
                w.end_row().await?;
            }
        });
        w.finish().await
    }

    /// The alarm transitions `f` selects (its `limit` and `offset` ignored),
    /// in its order, as CSV; the number of rows.
    pub async fn export_alarm_history_csv<W: AsyncWrite + Unpin>(
        &self,
        f: &AlarmHistoryFilter,
        out: &mut W,
    ) -> Result<u64> {
        let text = f.text.as_deref().map(like_pattern);
        let order = if f.oldest_first { "ASC" } else { "DESC" };
        let sql = format!(
            "SELECT id, ts, alarm_key, tag, kind, from_state, to_state, cause, activation, value, \
               limit_value, user_name, message, priority, selection FROM alarm_history \
             {HISTORY_WHERE} ORDER BY ts {order}, id {order}"
        );
        let mut w = CsvWriter::new(
            out,
            "an alarm history CSV export",
            "time_utc,ts_ms,alarm,tag,kind,from_state,to_state,cause,activation,value,limit,user,message,priority,selection",
        );
        on_backend!(self, reader, |p| {
            let mut rows = sqlx::query_as::<_, TransitionRow>(&sql)
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
                .fetch(p);
            while let Some(r) = rows
                .try_next()
                .await
                .map_err(db("exporting alarm history"))?
            {
                w.time(r.1);
                w.text(&r.2);
                w.text(&r.3);
                w.text(&r.4);
                w.text(&r.5);
                w.text(&r.6);
                w.opt_text(r.7.as_deref());
                w.plain(r.8);
                w.opt_plain(r.9);
                w.opt_plain(r.10);
                w.opt_text(r.11.as_deref());
                w.text(&r.12);
                w.plain(r.13);
                w.text(&r.14);
                w.end_row().await?;
            }
        });
        w.finish().await
    }

    /// The dispatches in `from..to`, newest first like the history list, as
    /// CSV (the setpoints as their JSON text); the number of rows.
    pub async fn export_dispatches_csv<W: AsyncWrite + Unpin>(
        &self,
        from: Timestamp,
        to: Timestamp,
        out: &mut W,
    ) -> Result<u64> {
        let sql = format!(
            "SELECT {DISPATCH_COLS} FROM dispatches WHERE ts >= $1 AND ts < $2 AND site = $3 \
             ORDER BY ts DESC, id DESC"
        );
        let mut w = CsvWriter::new(
            out,
            "a dispatch CSV export",
            "time_utc,ts_ms,status,mode,objective,solve_ms,reason,setpoints",
        );
        on_backend!(self, reader, |p| {
            let mut rows = sqlx::query_as::<_, DispatchRow>(&sql)
                .bind(from.as_millis())
                .bind(to.as_millis())
                .bind(&*self.site)
                .fetch(p);
            while let Some(r) = rows.try_next().await.map_err(db("exporting dispatches"))? {
                w.time(r.1);
                w.text(&r.2);
                w.text(&r.3);
                w.opt_plain(r.4);
                w.plain(r.5);
                w.opt_text(r.8.as_deref());
                w.text(&r.7);
                w.end_row().await?;
            }
        });
        w.finish().await
    }
}
