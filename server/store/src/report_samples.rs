//! The historian reads a report needs beyond the raw range: the sample in
//! force at the start of a period (the newest one before it).

use gridscada_tagdb::Timestamp;

use crate::error::db;
use crate::historian::quality_from_code;
use crate::{RawSample, Result, Store};

impl Store {
    /// The newest sample of `tag` before `at`: the value in force at `at`.
    /// `None` if the tag has none (or is not in the historian).
    pub async fn sample_before(&self, tag: &str, at: Timestamp) -> Result<Option<RawSample>> {
        let ids = self.tag_ids(&[tag], false).await?;
        let Some(&id) = ids.values().next() else {
            return Ok(None);
        };
        let row: Option<(i64, Option<f64>, Option<String>, i32)> = on_backend!(self, reader, |p| {
            sqlx::query_as(
                "SELECT ts, value, exact, quality FROM samples \
                 WHERE tag_id = $1 AND ts < $2 ORDER BY ts DESC LIMIT 1",
            )
            .bind(id)
            .bind(at.as_millis())
            .fetch_optional(p)
            .await
            .map_err(db("reading the sample before a report's period"))?
        });
        Ok(row.map(|(ts, value, exact, q)| RawSample {
            tag: tag.to_string(),
            ts: Timestamp::from_millis(ts),
            value,
            exact: exact.and_then(|x| x.parse().ok()),
            quality: quality_from_code(q),
        }))
    }
}
