//! The audited tag write, shared by every path a command comes in by (the
//! HMI's HTTP API, OPC UA, a Sparkplug DCMD): the request is on record before it goes
//! to the device, and what came of it is recorded after.

use std::future::Future;
use std::pin::Pin;

use gridscada_tagdb::{Sample, TagWriter, Timestamp, Value, WriteError};

use crate::{AuditBody, AuditHandle, NewEvent};

/// Where a command's records go: the audit trail, or (without one) the store
/// directly. `durable` answers once the record is stored or spooled.
pub trait CommandAudit: Send + Sync {
    fn durable(
        &self,
        event: NewEvent,
    ) -> Pin<Box<dyn Future<Output = Result<(), String>> + Send + '_>>;
}

impl CommandAudit for AuditHandle {
    fn durable(
        &self,
        event: NewEvent,
    ) -> Pin<Box<dyn Future<Output = Result<(), String>> + Send + '_>> {
        Box::pin(async move {
            self.record_durable(AuditBody::Event(event))
                .await
                .map_err(|e| e.to_string())
        })
    }
}

/// Who writes, as the event log shows it.
#[derive(Debug, Clone)]
pub struct Commander {
    /// The event's user; `None` for the system.
    pub user: Option<String>,
    /// How the messages name them ("alice", "sparkplug DCMD").
    pub label: String,
}

/// Why an audited write did not happen or did not succeed.
#[derive(Debug, Clone, thiserror::Error)]
pub enum CommandError {
    /// Its request could not be made durable: nothing went out.
    #[error("command refused: its audit record can be neither stored nor spooled, and no command goes out unrecorded ({0})")]
    Unaudited(String),
    /// It went out and the device (or the field I/O) refused it.
    #[error(transparent)]
    Write(#[from] WriteError),
}

/// Writes `value` to tag `name` through `writer`, recording the request
/// (`write_request`, durable before the write) and its outcome: `write` with
/// the confirmed value, `write_refused` when the writer refused it before
/// the device (engineering limits, a standby server:
/// [`WriteError::is_refusal`]), or `write_failed` when the device or the link
/// failed it. `old` is the value before, as shown in the record.
pub async fn audited_write(
    audit: &dyn CommandAudit,
    writer: &dyn TagWriter,
    now: impl Fn() -> Timestamp,
    who: &Commander,
    name: &str,
    old: &str,
    value: Value,
) -> Result<Sample, CommandError> {
    let event = |kind: &str, message: String| NewEvent {
        ts: now(),
        user: who.user.clone(),
        source: name.to_string(),
        kind: kind.to_string(),
        message,
    };
    let label = &who.label;
    audit
        .durable(event(
            "write_request",
            format!("{label} requests {name}: {old} -> {value}"),
        ))
        .await
        .map_err(|why| {
            tracing::error!(%why, "command refused: its audit record cannot be made durable");
            CommandError::Unaudited(why)
        })?;
    let outcome = gridscada_tagdb::with_originator(label, writer.write(name, value.clone())).await;
    // The device may hold the value at its own resolution (a scaled
    // register): record what was asked and what it confirmed.
    let record = match &outcome {
        Ok(confirmed) => event(
            "write",
            format!(
                "{label} wrote {name}: {old} -> requested {value}, confirmed {}",
                confirmed.value
            ),
        ),
        Err(e) if e.is_refusal() => refused_event(now(), who, name, &e.to_string()),
        Err(e) => event(
            "write_failed",
            format!("{label} could not write {name} = {value}: {e}"),
        ),
    };
    // The write has happened: a record that cannot be kept is logged loudly.
    if let Err(e) = audit.durable(record).await {
        tracing::error!(error = %e, "could not record an audit event");
    }
    Ok(outcome?)
}

/// Records a refused command (`write_refused`): who tried to write what, and why.
pub async fn audit_refused(
    audit: &dyn CommandAudit,
    ts: Timestamp,
    who: &Commander,
    name: &str,
    why: &str,
) {
    if let Err(e) = audit.durable(refused_event(ts, who, name, why)).await {
        tracing::error!(error = %e, "could not record an audit event");
    }
}

/// The record of a refused write, whichever door refused it.
pub fn refused_event(ts: Timestamp, who: &Commander, name: &str, why: &str) -> NewEvent {
    NewEvent {
        ts,
        user: who.user.clone(),
        source: name.to_string(),
        kind: "write_refused".into(),
        message: format!("{} may not write {name}: {why}", who.label),
    }
}
