//! The central Sparkplug B host in the stack (`[mqtt.host]`): the room it
//! reserves in the tag database, its start, and its figures in `/metrics`.
//! The host itself is `gridscada_sparkplug::host`.

use std::sync::Arc;
use std::time::Duration;

use anyhow::anyhow;
use gridscada_alarms::AlarmEngine;
use gridscada_config::Plant;
use gridscada_sparkplug::host::{Host, HostOptions, HostStats, SiteNotice, SitesPolicy};
use gridscada_store::NewEvent;
use gridscada_tagdb::{Clock, TagDb, TagWriter};
use tokio::sync::mpsc;
use tokio::task::JoinSet;

/// A remote site offline is as grave as a device not answering.
const SITE_OFFLINE_PRIORITY: u32 = 700;

/// What `/metrics` reads from the host.
pub(crate) type HostStatsSource = Arc<dyn Fn() -> HostStats + Send + Sync>;

/// Slots the tag database reserves for remote tags (none without a host).
pub(super) fn room(plant: &Plant) -> usize {
    plant
        .mqtt
        .as_ref()
        .and_then(|m| m.host.as_ref())
        .map_or(0, |h| *h.max_tags.get_ref())
}

/// Starts the host if configured; its writer sends remote tags to their
/// edge and every other tag to `field`. A site going offline (or the
/// broker lost) is an event and a system alarm `sparkplug:NODE` (area: the
/// node) until it is born again (a task in `tasks`).
pub(super) fn start(
    plant: &Plant,
    db: Arc<TagDb>,
    clock: Arc<dyn Clock>,
    field: Arc<dyn TagWriter>,
    events: mpsc::Sender<NewEvent>,
    alarms: Arc<AlarmEngine>,
    tasks: &mut JoinSet<()>,
) -> anyhow::Result<Option<(Host, Arc<dyn TagWriter>)>> {
    let Some((mqtt, host)) = plant
        .mqtt
        .as_ref()
        .and_then(|m| Some((m, m.host.as_ref()?)))
    else {
        return Ok(None);
    };
    let opts = HostOptions {
        mqtt: mqtt.clone(),
        config_dir: plant
            .main_path
            .parent()
            .map(std::path::Path::to_path_buf)
            .unwrap_or_default(),
        host_id: host.host_id.get_ref().clone(),
        sites: SitesPolicy {
            group: mqtt.group.get_ref().clone(),
            nodes: host.nodes.iter().map(|n| n.get_ref().clone()).collect(),
            device_in_name: host.device_in_name,
            rebirth_interval: Duration::from_secs_f64(*host.rebirth_interval_s.get_ref()),
        },
        max_message_bytes: *host.max_message_bytes.get_ref(),
        write_timeout: Duration::from_secs_f64(*host.write_timeout_s.get_ref()),
    };
    let (notices_tx, mut notices) = mpsc::channel::<SiteNotice>(256);
    let started = Host::start(opts, db, clock.clone(), Some(notices_tx))
        .map_err(|e| anyhow!("starting the Sparkplug host: {e}"))?;
    tasks.spawn(async move {
        while let Some(n) = notices.recv().await {
            crate::sinks::system_alarm(
                &alarms,
                &format!("sparkplug:{}", n.source),
                !n.online,
                SITE_OFFLINE_PRIORITY,
                &n.source,
                &n.message,
            );
            let event =
                crate::sinks::system_event(clock.as_ref(), "sparkplug", &n.source, n.message);
            if events.send(event).await.is_err() {
                break;
            }
        }
    });
    let writer = started.writer(Some(field));
    Ok(Some((started, writer)))
}

/// The host's families in `/metrics`.
pub(super) fn render(s: &HostStats, out: &mut gridscada_web::metrics::Prom) {
    for (kind, n) in &s.messages {
        out.counter(
            "gridscada_sparkplug_host_messages_total",
            "Sparkplug messages the central host received, by type.",
            &[("type", kind)],
            *n as f64,
        );
    }
    out.counter(
        "gridscada_sparkplug_host_bytes_total",
        "Payload bytes the central host received.",
        &[],
        s.bytes as f64,
    );
    for (reason, n) in &s.problems {
        out.counter(
            "gridscada_sparkplug_host_refused_total",
            "Messages or metrics the central host refused (logged, nothing changed), by reason.",
            &[("reason", reason)],
            *n as f64,
        );
    }
    for (name, help, v) in [
        (
            "gridscada_sparkplug_host_reconnects_total",
            "Times the central host connected to the broker again after losing it.",
            s.reconnects,
        ),
        (
            "gridscada_sparkplug_host_rebirth_requests_total",
            "Rebirths the central host asked of edge nodes (NCMD Node Control/Rebirth).",
            s.rebirths_requested,
        ),
        (
            "gridscada_sparkplug_host_writes_confirmed_total",
            "Writes to remote tags that the edge's data confirmed.",
            s.writes_confirmed,
        ),
        (
            "gridscada_sparkplug_host_writes_failed_total",
            "Writes to remote tags that failed or timed out.",
            s.writes_failed,
        ),
    ] {
        out.counter(name, help, &[], v as f64);
    }
    out.gauge(
        "gridscada_sparkplug_host_connected",
        "1 while the central host is connected to the broker.",
        &[],
        f64::from(u8::from(s.connected)),
    );
    out.gauge(
        "gridscada_sparkplug_host_sites_online",
        "Edge nodes online (born, not dead).",
        &[],
        s.sites_online as f64,
    );
    out.gauge(
        "gridscada_sparkplug_host_tags",
        "Remote tags the births have declared.",
        &[],
        s.tags as f64,
    );
}
