//! The central Sparkplug B host in the stack (`[mqtt.host]`): the room it
//! reserves in the tag database, its start, and its figures in `/metrics`.
//! The host itself is `gridscada_sparkplug::host`.

use std::sync::Arc;
use std::time::Duration;

use anyhow::anyhow;
use gridscada_alarms::AlarmEngine;
use gridscada_config::Plant;
use gridscada_sparkplug::host::{
    Host, HostOptions, HostOutputs, HostStats, RemoteAlarms, SiteNotice, SitesPolicy,
};
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
/// node) until it is born again (a task in `tasks`). The alarms a
/// gridscada edge declares in its births are raised on the remote tags
/// here (another task), and its historical samples go to `history`.
#[allow(clippy::too_many_arguments)]
pub(super) fn start(
    plant: &Plant,
    db: Arc<TagDb>,
    clock: Arc<dyn Clock>,
    field: Arc<dyn TagWriter>,
    events: mpsc::Sender<NewEvent>,
    alarms: Arc<AlarmEngine>,
    history: gridscada_store::HistorianHandle,
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
    let (alarms_tx, mut remote_alarms) = mpsc::channel::<Vec<RemoteAlarms>>(256);
    let outputs = HostOutputs {
        notices: Some(notices_tx),
        alarms: Some(alarms_tx),
        history: Some(history),
    };
    let started = Host::start(opts, db, clock.clone(), outputs)
        .map_err(|e| anyhow!("starting the Sparkplug host: {e}"))?;
    let engine = alarms.clone();
    tasks.spawn(async move {
        while let Some(birth) = remote_alarms.recv().await {
            for r in &birth {
                define_remote_alarms(&engine, r);
            }
        }
    });
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

/// Raises on a remote tag the alarms its edge configured: the same limits,
/// delays and messages, keyed by the remote tag's name, in the area
/// `NODE.SELECTION` (the edge's selection, by default the first part of
/// the tag's name there). Refused definitions are logged.
fn define_remote_alarms(engine: &AlarmEngine, r: &RemoteAlarms) {
    let source = gridscada_alarms::AlarmSource {
        name: &r.tag,
        units: &r.units,
        description: &r.description,
        device: None,
        states: None,
        // The edge's display settings do not travel with its births.
        decimals: None,
    };
    let at_edge = gridscada_alarms::set::first_segment(&r.metric).to_owned();
    let mut config = r.config.clone();
    let area =
        |s: &Option<String>| Some(format!("{}.{}", r.node, s.as_deref().unwrap_or(&at_edge)));
    let default_area = area(&config.selection);
    for l in [
        &mut config.hihi,
        &mut config.hi,
        &mut config.lo,
        &mut config.lolo,
    ]
    .into_iter()
    .flatten()
    {
        l.selection = l.selection.as_ref().and(area(&l.selection));
    }
    for d in &mut config.discrete {
        d.selection = d.selection.as_ref().and(area(&d.selection));
    }
    config.selection = default_area;
    let defined =
        gridscada_alarms::tag_alarm_defs(&source, &config).and_then(|defs| engine.define(defs));
    match defined {
        Ok(keys) if !keys.is_empty() => {
            tracing::info!(tag = %r.tag, alarms = keys.len(), "alarms of a remote tag defined from its birth")
        }
        Ok(_) => {}
        Err(e) => tracing::warn!(tag = %r.tag, error = %e, "alarms of a remote tag refused"),
    }
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
        (
            "gridscada_sparkplug_host_historical_samples_total",
            "Historical samples (an edge's store and forward) handed to the historian at their own timestamps.",
            s.historical,
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
