//! Sinks: the tasks that carry what the components produce (events, alarm
//! transitions and states, historian samples, panel and dispatch notices) to
//! the store and the alarm engine. Each batches what it can, and none of them
//! ever blocks the producer's hot path: producers hand over through channels.

use std::collections::{HashMap, HashSet};
use std::sync::Arc;
use std::time::Duration;

use gridscada_alarms::AlarmEngine;
use gridscada_config::Plant;
use gridscada_control::dispatch::{self, DispatchMode, DispatchNotice, DispatchStatus};
use gridscada_control::fault_isolation::{self, PanelNotice, PanelStatus, Retained};
use gridscada_store::{
    AuditBody, AuditHandle, AuditTable, HistorianHandle, NewDispatch, NewEvent, RecordPolicy,
    Recorder, RetentionPolicy, Store,
};
use gridscada_tagdb::{Clock, TagDb};
use tokio::sync::{mpsc, watch};

/// Priority of the system alarms the application raises itself.
const SYSTEM_PRIORITY: u32 = 700;

pub fn system_event(clock: &dyn Clock, kind: &str, source: &str, message: String) -> NewEvent {
    NewEvent {
        ts: clock.now(),
        user: None,
        source: source.to_string(),
        kind: kind.to_string(),
        message,
    }
}

/// Events into the audit trail (which batches them into the store, or
/// spools them while the store is away).
pub async fn events(audit: AuditHandle, mut rx: mpsc::Receiver<NewEvent>) {
    while let Some(e) = rx.recv().await {
        audit.record(AuditBody::Event(e)).await;
    }
}

/// The alarm engine's operator events, into the event log.
pub async fn alarm_events(
    mut rx: mpsc::Receiver<gridscada_alarms::Event>,
    events: mpsc::Sender<NewEvent>,
) {
    while let Some(e) = rx.recv().await {
        let e = NewEvent {
            ts: e.time,
            user: e.user,
            source: e.source,
            kind: e.kind.as_str().to_string(),
            message: e.message,
        };
        if events.send(e).await.is_err() {
            return;
        }
    }
}

/// Alarm history into the audit trail, in the order the engine made it,
/// and a copy to the alarm notifier if it runs (never waited for: a
/// notifier that falls 4096 transitions behind loses the surplus, logged).
pub async fn alarm_transitions(
    audit: AuditHandle,
    mut rx: mpsc::Receiver<gridscada_alarms::AlarmTransition>,
    notify: Option<mpsc::Sender<gridscada_alarms::AlarmTransition>>,
) {
    while let Some(t) = rx.recv().await {
        if let Some(n) = &notify {
            if let Err(mpsc::error::TrySendError::Full(t)) = n.try_send(t.clone()) {
                tracing::error!(alarm = %t.key, "alarm notifier behind: transition not notified");
            }
        }
        audit.record(AuditBody::Transition((&t).into())).await;
    }
}

/// Raises a system alarm while the audit trail spools (the store cannot
/// take its records), and clears it once the spool is replayed.
pub async fn audit_spool_alarm(audit: AuditHandle, alarms: Arc<AlarmEngine>) {
    let mut spooling = audit.spooling();
    let mut raised = false;
    loop {
        let on = *spooling.borrow_and_update();
        if on != raised {
            let m = audit.metrics();
            let message = format!(
                "Database unavailable: audit records are spooled in the data folder ({} waiting); they are replayed when it is back",
                m.pending
            );
            system_alarm(&alarms, AUDIT_SPOOL_ALARM, on, 800, "SYSTEM", &message);
            raised = on;
        }
        if spooling.changed().await.is_err() {
            return;
        }
    }
}

/// The key of the system alarm that stands while the audit trail spools.
pub const AUDIT_SPOOL_ALARM: &str = "audit:spool";

/// Prunes the event log, the alarm history and the dispatch records past
/// their retention, once a day (and at start), a batch at a time with a
/// pause between, so ingest never waits long behind it.
pub async fn audit_retention(
    store: Store,
    retention: gridscada_config::AuditRetention,
    clock: Arc<dyn Clock>,
) {
    const DAY_MS: i64 = 86_400_000;
    const BATCH: u32 = 5_000;
    let days = |t: AuditTable| match t {
        AuditTable::Events => *retention.events_days.get_ref(),
        AuditTable::AlarmHistory => *retention.alarm_history_days.get_ref(),
        AuditTable::Dispatches => *retention.dispatch_days.get_ref(),
    };
    let mut tick = tokio::time::interval(Duration::from_secs(3600));
    let mut last_day = None;
    loop {
        tick.tick().await;
        let now = clock.now();
        let day = now.as_millis() / DAY_MS;
        if last_day == Some(day) {
            continue;
        }
        last_day = Some(day);
        for table in AuditTable::ALL {
            let d = days(table);
            if d == 0 {
                continue; // kept for ever
            }
            let before = gridscada_tagdb::Timestamp::from_millis(
                now.as_millis().saturating_sub(i64::from(d) * DAY_MS),
            );
            let mut deleted = 0;
            loop {
                match store.prune_audit(table, before, BATCH).await {
                    Ok(n) => {
                        deleted += n;
                        if n < u64::from(BATCH) {
                            break;
                        }
                    }
                    Err(e) => {
                        tracing::error!(table = table.name(), error = %e, "audit retention");
                        break;
                    }
                }
                tokio::time::sleep(Duration::from_millis(100)).await;
            }
            if deleted > 0 {
                tracing::info!(
                    table = table.name(),
                    deleted,
                    days = d,
                    "audit retention applied"
                );
            }
        }
    }
}

/// Alarm states, upserted so acknowledgements and shelving survive a restart.
/// Only the newest state of each alarm is written. A write the store refuses
/// (it is down) is kept and retried with back-off, newer states replacing
/// older ones meanwhile, so the store catches up once it is back: a state is
/// the latest word on its alarm, so nothing but the newest needs to wait.
pub async fn alarm_states(
    store: Store,
    mut rx: mpsc::Receiver<gridscada_alarms::AlarmStateRecord>,
) {
    const FIRST_RETRY: Duration = Duration::from_millis(200);
    const LAST_RETRY: Duration = Duration::from_secs(5);
    let mut pending: HashMap<String, gridscada_alarms::AlarmStateRecord> = HashMap::new();
    let mut batch = Vec::new();
    let mut retry = FIRST_RETRY;
    let mut closed = false;
    loop {
        if pending.is_empty() {
            if rx.recv_many(&mut batch, 512).await == 0 {
                return;
            }
        } else if !closed {
            // recv_many is cancel safe: a timeout loses nothing.
            if let Ok(0) = tokio::time::timeout(retry, rx.recv_many(&mut batch, 512)).await {
                closed = true;
            }
        }
        for r in batch.drain(..) {
            pending.insert(r.key.clone(), r);
        }
        let rows: Vec<_> = pending.values().cloned().collect();
        match store.upsert_alarm_states(&rows).await {
            Ok(()) => {
                if retry > FIRST_RETRY {
                    tracing::info!(
                        states = rows.len(),
                        "alarm states saved after the store came back"
                    );
                }
                pending.clear();
                retry = FIRST_RETRY;
            }
            Err(e) if closed => {
                tracing::error!(error = %e, states = rows.len(), "alarm states not saved at shutdown: the store is unavailable");
                return;
            }
            Err(e) => {
                if retry == FIRST_RETRY {
                    tracing::error!(error = %e, "could not save alarm states; retrying until the store is back");
                }
                retry = (retry * 2).min(LAST_RETRY);
            }
        }
        if closed && pending.is_empty() {
            return;
        }
    }
}

/// Raises or clears a system alarm, logging (not failing) on error.
pub(crate) fn system_alarm(
    alarms: &AlarmEngine,
    key: &str,
    active: bool,
    priority: u32,
    selection: &str,
    message: &str,
) {
    let r = if active {
        alarms.raise(key, priority, selection, message).map(|_| ())
    } else {
        alarms.clear(key).map(|_| ())
    };
    if let Err(e) = r {
        tracing::error!(%key, error = %e, "system alarm");
    }
}

/// Saves what a panel's sequence must carry across a restart (mode, faulty
/// zones, lockout) each time it changes, so the next start takes it over.
/// A failed save is retried with the next change and logged.
pub async fn panel_retained(
    store: Store,
    panel: String,
    mut status: watch::Receiver<PanelStatus>,
    clock: Arc<dyn Clock>,
    fence: Option<gridscada_store::Fence>,
) {
    // The channel's first value is a placeholder from before the sequence
    // started (it would overwrite what was saved): only changes are saved.
    let mut saved: Option<Retained> = None;
    while status.changed().await.is_ok() {
        let r = status.borrow_and_update().retained.clone();
        if saved.as_ref() != Some(&r) {
            let json = serde_json::to_value(&r).unwrap_or_default();
            // In a pair, only under the lease this server holds: a deposed
            // server's late save is dropped by the database.
            let result = match &fence {
                None => store.save_panel_state(&panel, &json, clock.now()).await,
                Some(f) => match store
                    .save_panel_state_fenced(&panel, &json, clock.now(), f)
                    .await
                {
                    Ok(true) => Ok(()),
                    Ok(false) => {
                        tracing::warn!(%panel, epoch = f.epoch, "panel state not saved: this server no longer holds the lease");
                        return;
                    }
                    Err(e) => Err(e),
                },
            };
            match result {
                Ok(()) => saved = Some(r),
                Err(e) => tracing::error!(%panel, error = %e, "could not save the panel's state"),
            }
        }
    }
}

/// What the previous run left for each panel (by id); unreadable entries
/// are logged and skipped, so that panel starts fresh.
pub async fn load_panel_retained(store: &Store) -> HashMap<String, Retained> {
    let rows = match store.panel_states().await {
        Ok(rows) => rows,
        Err(e) => {
            tracing::error!(error = %e, "could not read the panels' saved states; they start fresh");
            return HashMap::new();
        }
    };
    rows.into_iter()
        .filter_map(|(id, json)| match serde_json::from_value::<Retained>(json) {
            Ok(r) => Some((id, r)),
            Err(e) => {
                tracing::error!(panel = %id, error = %e, "unreadable saved panel state; it starts fresh");
                None
            }
        })
        .collect()
}

/// The alarm engine's key of panel `panel`'s sequence alarm `key`.
pub fn panel_alarm_key(panel: &str, key: &str) -> String {
    format!("{panel}:{key}")
}

/// The panels whose ELCB status tag has its own discrete alarm on "tripped"
/// (`when = false`): their trip is annunciated by that alarm, so the
/// sequence's ELCB trip alarm would only repeat it.
pub fn panels_annunciating_trips(plant: &Plant) -> HashSet<String> {
    plant
        .panels
        .iter()
        .filter(|p| {
            plant
                .tag(&p.io().elcb_closed)
                .and_then(|t| t.alarm.as_ref())
                .is_some_and(|a| a.alarms_when(false))
        })
        .map(|p| p.id.get_ref().clone())
        .collect()
}

/// Panel notices: events to the log, alarm conditions to the alarm engine
/// (keyed `PANEL:KEY`, in the panel's selection). The ELCB trip alarm of a
/// panel in `trip_on_tag` is dropped: its status tag's alarm annunciates it.
pub async fn panel_notices(
    mut rx: mpsc::Receiver<PanelNotice>,
    events: mpsc::Sender<NewEvent>,
    alarms: Arc<AlarmEngine>,
    selection_of: HashMap<String, String>,
    trip_on_tag: HashSet<String>,
    clock: Arc<dyn Clock>,
) {
    while let Some(n) = rx.recv().await {
        match n {
            PanelNotice::Event {
                panel,
                kind,
                message,
                user,
            } => {
                let e = NewEvent {
                    ts: clock.now(),
                    user,
                    source: panel,
                    kind,
                    message,
                };
                if events.send(e).await.is_err() {
                    return;
                }
            }
            PanelNotice::Alarm {
                panel,
                key,
                active,
                priority,
                message,
            } => {
                if key == fault_isolation::ELCB_TRIP_ALARM && trip_on_tag.contains(&panel) {
                    continue;
                }
                let selection = selection_of
                    .get(&panel)
                    .cloned()
                    .unwrap_or_else(|| panel.clone());
                system_alarm(
                    &alarms,
                    &panel_alarm_key(&panel, &key),
                    active,
                    priority,
                    &selection,
                    &message,
                );
            }
        }
    }
}

/// Dispatch: each period's result into the store and the dispatch tags;
/// notices into the event log and the alarm engine.
pub async fn dispatch_results(
    store: Store,
    db: Arc<TagDb>,
    mut status: watch::Receiver<DispatchStatus>,
    clock: Arc<dyn Clock>,
) {
    while status.changed().await.is_ok() {
        let s = status.borrow_and_update().clone();
        dispatch::tags::publish(&db, &s, clock.now());
        let record = NewDispatch {
            ts: s.at,
            status: s.status.clone(),
            mode: match s.mode {
                DispatchMode::Optimal => "optimal".into(),
                DispatchMode::Fallback => "fallback".into(),
            },
            objective: s.objective,
            solve_ms: s.solve_ms.unwrap_or(0.0),
            inputs: serde_json::to_value(&s.inputs).unwrap_or_default(),
            setpoints: serde_json::to_value(&s.setpoints_kw).unwrap_or_default(),
            reason: s.reason.clone(),
        };
        if let Err(e) = store.insert_dispatch(&record).await {
            tracing::error!(error = %e, "could not record the dispatch");
        }
    }
}

pub async fn dispatch_notices(
    mut rx: mpsc::Receiver<DispatchNotice>,
    events: mpsc::Sender<NewEvent>,
    alarms: Arc<AlarmEngine>,
) {
    while let Some(n) = rx.recv().await {
        match n {
            DispatchNotice::Event { at, message } => {
                let e = NewEvent {
                    ts: at,
                    user: None,
                    source: "dispatch".into(),
                    kind: "dispatch".into(),
                    message,
                };
                if events.send(e).await.is_err() {
                    return;
                }
            }
            DispatchNotice::Alarm {
                name,
                active,
                reason,
                ..
            } => {
                // `name` reads as a phrase ("dispatch fallback"); capitalise it.
                let mut message = format!("{name}: {reason}");
                if let Some(first) = message.get(..1) {
                    message = first.to_uppercase() + &message[1..];
                }
                system_alarm(
                    &alarms,
                    &format!("dispatch:{name}"),
                    active,
                    SYSTEM_PRIORITY,
                    "MG",
                    &message,
                );
            }
        }
    }
}

/// The historian's logging policy, per configured tag.
pub fn recorder(plant: &Plant, db: &TagDb) -> Recorder {
    let mut r = Recorder::new();
    r.reserve(db.len());
    for t in &plant.tags {
        if let Some(id) = db.id(t.name.get_ref()) {
            // The tag database's name, shared, not a copy per tag.
            let name = db.meta(id).map(|m| m.name.clone());
            r.set_policy(
                id,
                name.unwrap_or_else(|| t.name.get_ref().as_str().into()),
                RecordPolicy::from_config(&t.history),
            );
        }
    }
    r
}

/// Feeds tag changes through the logging policy into the historian's bounded
/// buffer, re-logs quiet tags at their maximum interval, applies retention
/// daily, and raises a system alarm while samples are being dropped.
///
/// When `stop` turns true (or its sender is dropped) it offers every change
/// already published (without waiting for more) and returns, dropping its
/// handle: the stack stops it after the producers of tag changes and before
/// the historian's writer, so an orderly shutdown offers every sample before
/// the writer's final flush and none after it.
#[allow(clippy::too_many_arguments)] // each is a separate part of the stack
pub async fn historian_feed(
    plant: Arc<Plant>,
    db: Arc<TagDb>,
    historian: HistorianHandle,
    store: Store,
    alarms: Arc<AlarmEngine>,
    clock: Arc<dyn Clock>,
    mut stop: watch::Receiver<bool>,
    leadership: gridscada_tagdb::Leadership,
) {
    // In a pair the active server writes the history; a standby's recorder
    // runs warm (its deadbands follow) but hands nothing on.
    let recording = || leadership.permit().is_ok();
    let mut recorder = recorder(&plant, &db);
    // Tags added at run time (a central Sparkplug host's remote tags) are
    // logged with the default policy, from the first change that follows.
    let mut known = db.len();
    let mut sub = db.subscribe_all();
    // Log the starting point of every tag.
    let start = db.snapshot_all();
    historian.push_all(
        start
            .changes
            .iter()
            .flat_map(|(id, s)| recorder.offer_rows(*id, s)),
    );
    // 0 keeps a roll-up level for ever.
    let level_days = |d: u32| (d > 0).then_some(d);
    let retention = RetentionPolicy {
        minute_days: level_days(*plant.storage.retention.minute_days.get_ref()),
        hour_days: level_days(*plant.storage.retention.hour_days.get_ref()),
        default_days: Some(plant.storage.retention_days),
        per_tag_days: plant
            .tags
            .iter()
            .filter_map(|t| {
                t.history
                    .retention_days
                    .map(|d| (t.name.get_ref().clone(), d))
            })
            .collect(),
    };
    let mut overflow = historian.overflow();
    // The max-interval re-logs are due in plant time: a wall-time tick
    // would re-log a steady tag only every few hundred plant seconds under
    // a replay's virtual clock, and a report would read its gaps as unknown.
    const TICK: Duration = Duration::from_secs(1);
    let mut tick = clock.sleep(TICK);
    let mut last_retention = None;
    loop {
        tokio::select! {
            // A stop already signalled wins over more changes.
            biased;
            r = stop.changed() => {
                if r.is_err() || *stop.borrow_and_update() {
                    break;
                }
            }
            update = sub.recv() => {
                let Some(update) = update else { return };
                if db.len() > known {
                    for (id, meta) in db.all_meta().skip(known) {
                        recorder.set_policy(id, meta.name.clone(), RecordPolicy::default());
                    }
                    known = db.len();
                }
                let samples: Vec<_> = update
                    .batch()
                    .changes
                    .iter()
                    .flat_map(|(id, s)| recorder.offer_rows(*id, s))
                    .collect();
                if recording() {
                    historian.push_all(samples);
                }
            }
            _ = &mut tick => {
                tick = clock.sleep(TICK);
                let now = clock.now();
                let due = recorder.tick(now);
                if recording() {
                    historian.push_all(due);
                }
                let day = now.as_millis() / 86_400_000;
                if last_retention != Some(day) {
                    last_retention = Some(day);
                    match store.apply_retention(&retention, now).await {
                        Ok(n) if n > 0 => tracing::info!(deleted = n, "historian retention applied"),
                        Ok(_) => {}
                        Err(e) => tracing::error!(error = %e, "historian retention"),
                    }
                }
            }
            changed = overflow.changed() => {
                if changed.is_err() {
                    return;
                }
                let over = *overflow.borrow_and_update();
                let m = historian.metrics();
                let message = format!(
                    "Historian buffer full: {} samples dropped so far (buffer {}/{})",
                    m.dropped, m.buffered, m.capacity
                );
                system_alarm(&alarms, "historian:overflow", over, 800, "SYSTEM", &message);
            }
        }
    }
    // Stopping: what was published before the stop is offered too.
    let mut offered = 0;
    while let Some(update) = sub.try_recv() {
        let samples: Vec<_> = update
            .batch()
            .changes
            .iter()
            .flat_map(|(id, s)| recorder.offer_rows(*id, s))
            .collect();
        offered += historian.push_all(samples);
    }
    tracing::debug!(offered, "historian feed stopped");
}

/// Reads the standing safety tags from the store into `tags`; a store that
/// does not answer leaves them as they were (and, at start, not loaded: the
/// switching guard refuses every switching operation until they are).
pub async fn load_safety_tags(store: &Store, tags: &gridscada_network::SafetyTags) -> bool {
    match store.standing_safety_tags().await {
        Ok(rows) => {
            tags.replace(
                rows.iter()
                    .filter_map(gridscada_web::api::network::standing)
                    .collect(),
            );
            true
        }
        Err(e) => {
            tracing::warn!(error = %e, "reading the safety tags");
            false
        }
    }
}

/// Reloads the safety tags every 2 s: tags placed or removed by the other
/// server of a pair (or before a failover) hold here too.
pub async fn reload_safety_tags(store: Store, tags: gridscada_network::SafetyTags) {
    let mut tick = tokio::time::interval(Duration::from_secs(2));
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    loop {
        tick.tick().await;
        load_safety_tags(&store, &tags).await;
    }
}

/// The network's system alarms (`gridscada_network::alarms`): after every
/// recompute of the topology, raises what newly stands (or stands with new
/// words) and clears what no longer does.
pub async fn network_alarms(
    net: Arc<gridscada_network::Network>,
    mut live: watch::Receiver<Arc<gridscada_network::Live>>,
    alarms: Arc<AlarmEngine>,
) {
    let mut raised: HashMap<String, String> = HashMap::new();
    loop {
        let now = {
            let l = live.borrow_and_update();
            gridscada_network::alarms::standing(&net.model, &l.inputs, &l.topology)
        };
        for gone in raised
            .keys()
            .filter(|k| !now.iter().any(|a| &a.key == *k))
            .cloned()
            .collect::<Vec<_>>()
        {
            system_alarm(&alarms, &gone, false, 0, &net.prefix, "");
            raised.remove(&gone);
        }
        for a in now {
            if raised.get(&a.key) != Some(&a.message) {
                system_alarm(&alarms, &a.key, true, a.priority, &net.prefix, &a.message);
                raised.insert(a.key, a.message);
            }
        }
        if live.changed().await.is_err() {
            return;
        }
    }
}
