//! The returned status point of a telecontrol command. An IEC 104 station
//! (ACT_CON, ACT_TERM) or a DNP3 outstation (the SUCCESS echo) confirms
//! that it took a command, not that the process followed: the write counts
//! as done only when the tag's own monitored point shows the commanded
//! value. (Modbus reads the register back instead.)

use std::sync::Arc;
use std::time::Duration;

use gridscada_tagdb::{Sample, Subscription, TagDb, TagId, Value, WriteError};

/// What a command is checked against: one tag's monitored point, watched
/// from before the command goes out, so a spontaneous return that beats
/// the station's confirmation is not missed.
pub struct ReturnedStatus {
    db: Arc<TagDb>,
    id: TagId,
    watch: Subscription,
}

impl ReturnedStatus {
    /// Starts watching `id`. Call it before sending the command.
    pub fn watch(db: &Arc<TagDb>, id: TagId) -> ReturnedStatus {
        ReturnedStatus {
            db: Arc::clone(db),
            id,
            watch: db.subscribe(&[id]),
        }
    }

    /// Waits until the point is Good and `confirms` accepts its value.
    /// A value that does not confirm (a moving breaker's intermediate
    /// position first) is waited past; after `within`, the write fails
    /// naming what the point shows and which station completed the command.
    pub async fn confirmed(
        mut self,
        within: Duration,
        tag: &str,
        device: &str,
        written: &Value,
        confirms: impl Fn(&Value) -> bool,
    ) -> Result<Sample, WriteError> {
        let deadline = tokio::time::Instant::now() + within;
        loop {
            if let Some(s) = self.db.get(self.id) {
                if s.quality.is_good() && confirms(&s.value) {
                    return Ok(s);
                }
            }
            match tokio::time::timeout_at(deadline, self.watch.recv()).await {
                Ok(Some(_)) => continue,
                Ok(None) => return Err(WriteError::Closed),
                Err(_) => {
                    let now: Option<Sample> = self.db.get(self.id);
                    return Err(WriteError::Mismatch {
                        tag: tag.to_string(),
                        written: written.to_string(),
                        read_back: now.map_or("nothing".to_string(), |s| {
                            format!(
                                "{} ({}), {:.0} s after station {device} completed the command",
                                s.value,
                                s.quality,
                                within.as_secs_f64(),
                            )
                        }),
                    });
                }
            }
        }
    }
}

/// Whether a set point's returned value `got` equals the `written` one
/// within the station's `resolution` (engineering units).
pub fn within_resolution(written: &Value, got: &Value, resolution: f64) -> bool {
    match (written.as_f64(), got.as_f64()) {
        (Some(w), Some(g)) => (w - g).abs() <= resolution,
        _ => false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use gridscada_tagdb::{TagMeta, Timestamp, ValueKind};

    fn db() -> Arc<TagDb> {
        Arc::new(TagDb::new(vec![TagMeta::new("CB.Closed", ValueKind::Bool)]).unwrap())
    }

    #[tokio::test]
    async fn a_return_after_an_intermediate_value_confirms() {
        let db = db();
        let id = db.id("CB.Closed").unwrap();
        let status = ReturnedStatus::watch(&db, id);
        let writer = Arc::clone(&db);
        tokio::spawn(async move {
            tokio::time::sleep(Duration::from_millis(20)).await;
            writer.apply([(
                id,
                Sample::good(Value::Bool(false), Timestamp::from_millis(1)),
            )]);
            tokio::time::sleep(Duration::from_millis(20)).await;
            writer.apply([(
                id,
                Sample::good(Value::Bool(true), Timestamp::from_millis(2)),
            )]);
        });
        let s = status
            .confirmed(
                Duration::from_secs(5),
                "CB.Closed",
                "RTU",
                &Value::Bool(true),
                |v| v == &Value::Bool(true),
            )
            .await
            .unwrap();
        assert_eq!(s.value, Value::Bool(true));
    }

    #[tokio::test]
    async fn a_point_that_does_not_follow_fails_naming_what_it_shows() {
        let db = db();
        let id = db.id("CB.Closed").unwrap();
        db.apply([(
            id,
            Sample::good(Value::Bool(false), Timestamp::from_millis(1)),
        )]);
        let e = ReturnedStatus::watch(&db, id)
            .confirmed(
                Duration::from_secs(1),
                "CB.Closed",
                "RTU",
                &Value::Bool(true),
                |v| v == &Value::Bool(true),
            )
            .await
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("CB.Closed") && e.contains("false") && e.contains("1 s after station RTU"),
            "{e}"
        );
    }

    #[test]
    fn set_points_compare_within_the_resolution() {
        assert!(within_resolution(
            &Value::Float(10.0),
            &Value::Float(10.004),
            0.01
        ));
        assert!(!within_resolution(
            &Value::Float(10.0),
            &Value::Float(10.1),
            0.01
        ));
        assert!(!within_resolution(
            &Value::Float(10.0),
            &Value::Bool(true),
            0.01
        ));
    }
}
