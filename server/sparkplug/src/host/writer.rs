//! Writes to remote tags: a DCMD (or NCMD for a node metric) to the edge,
//! answered only once the edge's data reports the written value, like a
//! Modbus write answers only after its read-back.

use std::collections::HashMap;
use std::sync::Arc;

use gridscada_tagdb::{Sample, TagId, TagWriter, Value, WriteError, WriteFuture};
use prost::Message;
use rumqttc::QoS;
use tokio::sync::oneshot;

use super::link::Shared;

type Answer = oneshot::Sender<Result<Sample, WriteError>>;

struct Waiter {
    id: u64,
    expected: Value,
    /// The last value the edge reported meanwhile, if not the written one.
    seen: Option<Value>,
    answer: Answer,
}

/// Writes waiting for the edge's confirmation, by tag.
#[derive(Default)]
pub(crate) struct Pending {
    next: u64,
    waiting: HashMap<TagId, Vec<Waiter>>,
}

impl Pending {
    fn add(
        &mut self,
        tag: TagId,
        expected: Value,
    ) -> (u64, oneshot::Receiver<Result<Sample, WriteError>>) {
        let (answer, rx) = oneshot::channel();
        self.next += 1;
        let id = self.next;
        self.waiting.entry(tag).or_default().push(Waiter {
            id,
            expected,
            seen: None,
            answer,
        });
        (id, rx)
    }

    #[cfg(test)]
    pub(crate) fn add_for_test(
        &mut self,
        tag: TagId,
        expected: Value,
    ) -> (u64, oneshot::Receiver<Result<Sample, WriteError>>) {
        self.add(tag, expected)
    }

    fn remove(&mut self, tag: TagId, id: u64) -> Option<Waiter> {
        let list = self.waiting.get_mut(&tag)?;
        let i = list.iter().position(|w| w.id == id)?;
        let w = list.swap_remove(i);
        if list.is_empty() {
            self.waiting.remove(&tag);
        }
        Some(w)
    }

    /// Confirms the writes whose value the edge now reports (Good), fails
    /// those whose site or device went Bad. `place` names a tag's site for
    /// the error.
    pub(crate) fn offer(&mut self, samples: &[(TagId, Sample)], place: impl Fn(TagId) -> String) {
        if self.waiting.is_empty() {
            return;
        }
        for (tag, sample) in samples {
            let Some(list) = self.waiting.remove(tag) else {
                continue;
            };
            let mut keep = Vec::new();
            for mut w in list {
                if !sample.quality.is_good() {
                    let reason = sample.quality.reason.as_deref().unwrap_or("bad quality");
                    let _ = w.answer.send(Err(WriteError::Device {
                        device: place(*tag),
                        reason: format!("{reason} before it confirmed the write"),
                    }));
                } else if same(&sample.value, &w.expected) {
                    let _ = w.answer.send(Ok(sample.clone()));
                } else {
                    w.seen = Some(sample.value.clone());
                    keep.push(w);
                }
            }
            if !keep.is_empty() {
                self.waiting.insert(*tag, keep);
            }
        }
    }

    /// Fails every waiting write (the host lost the broker).
    pub(crate) fn fail_all(&mut self, reason: &str) -> u64 {
        let mut n = 0;
        for (_, list) in self.waiting.drain() {
            for w in list {
                let _ = w.answer.send(Err(WriteError::Device {
                    device: "broker".into(),
                    reason: reason.to_owned(),
                }));
                n += 1;
            }
        }
        n
    }
}

/// Equal as the wire carries them: floats within rounding.
fn same(a: &Value, b: &Value) -> bool {
    match (a.as_f64(), b.as_f64(), a, b) {
        (_, _, Value::Str(x), Value::Str(y)) => x == y,
        (Some(x), Some(y), _, _) => x == y || (x - y).abs() <= 1e-9 * x.abs().max(y.abs()),
        _ => a == b,
    }
}

/// The one writer the web layer and the control loops use: remote tags go
/// to their edge as commands, every other tag to the field writer.
pub struct RoutedWriter {
    pub(crate) shared: Arc<Shared>,
    pub(crate) local: Option<Arc<dyn TagWriter>>,
}

impl RoutedWriter {
    async fn write_remote(&self, name: &str, value: Value) -> Result<Sample, WriteError> {
        let result = self.command_and_confirm(name, value).await;
        self.shared.counters.write(result.is_ok());
        result
    }

    async fn command_and_confirm(&self, name: &str, value: Value) -> Result<Sample, WriteError> {
        let s = &self.shared;
        let now = s.clock.now();
        let (tag, topic, payload, expected) = s.sites.lock().command(&s.db, name, &value, now)?;
        let (id, rx) = s.pending.lock().add(tag, expected.clone());
        // Bounded too: the client's queue could be full behind a broker
        // that has stopped reading.
        let sent = tokio::time::timeout(
            s.write_timeout,
            s.client.publish(
                topic.to_string(),
                QoS::AtLeastOnce,
                false,
                payload.encode_to_vec(),
            ),
        )
        .await;
        let refused = match sent {
            Ok(Ok(())) => None,
            Ok(Err(e)) => Some(format!("the command could not be sent: {e}")),
            Err(_) => Some("the command could not be queued for the broker in time".to_owned()),
        };
        if let Some(reason) = refused {
            s.pending.lock().remove(tag, id);
            return Err(WriteError::Device {
                device: "broker".into(),
                reason,
            });
        }
        match tokio::time::timeout(s.write_timeout, rx).await {
            Ok(Ok(r)) => r,
            Ok(Err(_)) => Err(WriteError::Closed),
            Err(_) => match s.pending.lock().remove(tag, id).and_then(|w| w.seen) {
                Some(seen) => Err(WriteError::Mismatch {
                    tag: name.to_owned(),
                    written: expected.to_string(),
                    read_back: format!("{seen} (the site's last report)"),
                }),
                None => {
                    tracing::warn!(
                        tag = name,
                        timeout_s = s.write_timeout.as_secs_f64(),
                        "the site did not report the written value in time"
                    );
                    Err(WriteError::Timeout(name.to_owned()))
                }
            },
        }
    }

    /// Whether `name` is a remote tag.
    pub fn is_remote(&self, name: &str) -> bool {
        let s = &self.shared;
        s.db.id(name)
            .is_some_and(|id| s.sites.lock().remote(id).is_some())
    }
}

impl TagWriter for RoutedWriter {
    fn write<'a>(&'a self, name: &'a str, value: Value) -> WriteFuture<'a> {
        Box::pin(async move {
            if self.is_remote(name) {
                return self.write_remote(name, value).await;
            }
            match &self.local {
                Some(local) => local.write(name, value).await,
                None => Err(WriteError::UnknownTag(name.to_owned())),
            }
        })
    }
}
