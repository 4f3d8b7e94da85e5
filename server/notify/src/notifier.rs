//! The notifier's two tasks. The planner takes the alarm engine's
//! transitions, picks routes and contacts, holds what a flood brings on top
//! of the limit, escalates what stays unacknowledged, and queues messages in
//! the store's outbox. The delivery task sends what is due, retries with
//! back-off per route (the receiver is what is down), records each outcome
//! as an event, and raises a system alarm while a route cannot deliver.

use std::collections::HashMap;
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Duration;

use gridscada_alarms::{AlarmEngine, AlarmTransition, AlarmView};
use gridscada_config::{NotifyConfig, Plant};
use gridscada_store::{NewEvent, NewNotification, Notification, Store};
use gridscada_tagdb::{Clock, Timestamp};
use tokio::sync::{mpsc, Notify};

use crate::channels::Channel;
use crate::flood::{backoff_ms, FloodWindow, Offer};
use crate::message::{self, AlarmInfo, Message, Origin};
use crate::routing::{Route, SYSTEM_ALARM_PREFIX};

/// Priority of a route's "cannot deliver" system alarm.
const FAILURE_PRIORITY: u32 = 700;
/// How far back a restart looks for escalations to resume.
const RESUME_WINDOW_MS: i64 = 7 * 86_400_000;
/// Delivered and given-up messages are kept this long.
const KEEP_DONE_MS: i64 = 90 * 86_400_000;

/// One route's figures for `/metrics`.
#[derive(Debug, Default)]
pub struct RouteCounters {
    pub sent: AtomicU64,
    pub failed_attempts: AtomicU64,
    pub given_up: AtomicU64,
    /// Alarm messages held by the flood limit (told in a summary).
    pub held: AtomicU64,
}

/// The figures of every route, and the outbox's size.
#[derive(Debug, Default)]
pub struct NotifyFigures {
    pub routes: Vec<(String, RouteCounters)>,
    pub pending: AtomicU64,
    /// 1 per route that cannot deliver now.
    pub failing: parking_lot::Mutex<HashMap<String, bool>>,
}

/// What the rest of the server holds of the notifier.
#[derive(Clone)]
pub struct NotifyHandle {
    pub figures: Arc<NotifyFigures>,
}

struct RouteRt {
    route: Route,
    channel: Channel,
    origin: Origin,
    link: String,
    flood: FloodWindow,
    give_up_ms: i64,
    escalate_min: Option<f64>,
}

/// An alarm being escalated on a route.
struct Escalation {
    alarm: AlarmInfo,
    /// Position in the chain of the contact told last.
    contact: usize,
    deadline_ms: i64,
}

/// The notifier, built from a checked plant; run it with [`Notifier::run`].
pub struct Notifier {
    routes: Vec<RouteRt>,
    store: Store,
    alarms: Arc<AlarmEngine>,
    clock: Arc<dyn Clock>,
    events: mpsc::Sender<NewEvent>,
    transitions: mpsc::Receiver<AlarmTransition>,
    figures: Arc<NotifyFigures>,
}

/// The HMI's address for the links of route `n`.
fn hmi_base(plant: &Plant, n: &NotifyConfig) -> Option<String> {
    match &n.hmi_url {
        Some(u) => Some(u.get_ref().clone()),
        None => plant
            .server
            .public_origin()
            .map(|o| format!("{o}{}", plant.server.base_path())),
    }
}

impl Notifier {
    /// Builds every route's channel (reading secrets through `env`).
    /// `transitions` are the alarm engine's (a copy of what goes to the
    /// alarm history); events go to the event log.
    pub fn new(
        plant: &Plant,
        store: Store,
        alarms: Arc<AlarmEngine>,
        clock: Arc<dyn Clock>,
        events: mpsc::Sender<NewEvent>,
        transitions: mpsc::Receiver<AlarmTransition>,
        env: &dyn Fn(&str) -> Option<String>,
    ) -> Result<(Notifier, NotifyHandle), String> {
        let base = plant.main_path.parent().unwrap_or(Path::new(""));
        let origin = Origin {
            site: plant.server.site().to_string(),
            server: plant.redundancy.as_ref().map(|r| r.name.get_ref().clone()),
        };
        let mut routes = vec![];
        for n in &plant.notify {
            let name = n.name.get_ref();
            let link = hmi_base(plant, n)
                .map(|b| message::alarm_link(&b))
                .ok_or_else(|| {
                    format!("notify '{name}': no hmi_url and no [server] public_origin")
                })?;
            routes.push(RouteRt {
                route: Route::from_config(n),
                channel: Channel::build(n, base, env, plant.mqtt.as_ref())?,
                origin: origin.clone(),
                link,
                flood: FloodWindow::new(
                    *n.flood_limit.get_ref(),
                    i64::from(*n.flood_window_s.get_ref()) * 1000,
                ),
                give_up_ms: i64::from(*n.give_up_after_min.get_ref()) * 60_000,
                escalate_min: n.escalate_after_min.as_ref().map(|m| *m.get_ref()),
            });
        }
        let figures = Arc::new(NotifyFigures {
            routes: routes
                .iter()
                .map(|r| (r.route.name.clone(), RouteCounters::default()))
                .collect(),
            ..Default::default()
        });
        Ok((
            Notifier {
                routes,
                store,
                alarms,
                clock,
                events,
                transitions,
                figures: figures.clone(),
            },
            NotifyHandle { figures },
        ))
    }

    /// Plans and delivers until the transitions' sender is dropped (the
    /// planner stops then; delivery stops with the task).
    pub async fn run(self) {
        let Notifier {
            routes,
            store,
            alarms,
            clock,
            events,
            transitions,
            figures,
        } = self;
        let wake = Arc::new(Notify::new());
        let mut planner = Planner {
            routes: routes
                .iter()
                .map(|r| PlanRoute {
                    route: r.route.clone(),
                    origin: r.origin.clone(),
                    link: r.link.clone(),
                    flood: r.flood.clone(),
                    give_up_ms: r.give_up_ms,
                    escalate_min: r.escalate_min,
                })
                .collect(),
            escalations: HashMap::new(),
            store: store.clone(),
            alarms: alarms.clone(),
            clock: clock.clone(),
            figures: figures.clone(),
            wake: wake.clone(),
        };
        planner.resume().await;
        let delivery = Delivery {
            routes: routes
                .into_iter()
                .map(|r| (r.route.name.clone(), (r.channel, RouteHealth::default())))
                .collect(),
            store,
            alarms,
            clock,
            events,
            figures,
            wake,
        };
        tokio::select! {
            _ = planner.run(transitions) => {}
            _ = delivery.run() => {}
        }
    }
}

struct PlanRoute {
    route: Route,
    origin: Origin,
    link: String,
    flood: FloodWindow,
    give_up_ms: i64,
    escalate_min: Option<f64>,
}

struct Planner {
    routes: Vec<PlanRoute>,
    /// By route index and alarm key.
    escalations: HashMap<(usize, String), Escalation>,
    store: Store,
    alarms: Arc<AlarmEngine>,
    clock: Arc<dyn Clock>,
    figures: Arc<NotifyFigures>,
    wake: Arc<Notify>,
}

fn view_info(v: &AlarmView) -> AlarmInfo {
    let t = v.activated_at.unwrap_or(v.last_change);
    AlarmInfo {
        key: v.key.clone(),
        tag: v.tag.clone(),
        priority: v.priority,
        selection: v.selection.clone(),
        message: v.message.clone(),
        time_ms: t.as_millis(),
        time: message::utc(t),
    }
}

impl Planner {
    /// After a restart: escalation goes on for the alarms notified before
    /// it that are still unacknowledged, from the contact told last.
    async fn resume(&mut self) {
        let now = self.clock.now().as_millis();
        for (ri, r) in self.routes.iter().enumerate() {
            let Some(after) = r.route.escalate_after_ms else {
                continue;
            };
            let since = Timestamp::from_millis(now - RESUME_WINDOW_MS);
            let last = match self.store.last_notified(&r.route.name, since).await {
                Ok(l) => l,
                Err(e) => {
                    tracing::error!(route = %r.route.name, error = %e, "resuming escalations");
                    continue;
                }
            };
            for l in last {
                let Some(v) = self
                    .alarms
                    .id_of(&l.alarm_key)
                    .and_then(|id| self.alarms.view(id))
                else {
                    continue;
                };
                if v.state.is_unacked() && (l.level as usize) < r.route.contacts.len() {
                    self.escalations.insert(
                        (ri, l.alarm_key.clone()),
                        Escalation {
                            alarm: view_info(&v),
                            contact: l.level as usize,
                            deadline_ms: l.at.as_millis() + after,
                        },
                    );
                }
            }
        }
        if !self.escalations.is_empty() {
            tracing::info!(
                alarms = self.escalations.len(),
                "notification escalations resumed"
            );
        }
    }

    async fn run(&mut self, mut rx: mpsc::Receiver<AlarmTransition>) {
        let mut tick = tokio::time::interval(Duration::from_secs(1));
        tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        loop {
            tokio::select! {
                t = rx.recv() => match t {
                    Some(t) => self.transition(&t).await,
                    None => return,
                },
                _ = tick.tick() => self.timers().await,
            }
        }
    }

    async fn transition(&mut self, t: &AlarmTransition) {
        if t.key.starts_with(SYSTEM_ALARM_PREFIX) {
            return;
        }
        if !t.to.is_unacked() {
            // Acknowledged (or shelved, out of service...): nobody more to tell.
            self.escalations.retain(|(_, k), _| k != &t.key);
        }
        let now = self.clock.now().as_millis();
        self.flush_floods(now).await;
        for ri in 0..self.routes.len() {
            if !self.routes[ri].route.announces(t) {
                continue;
            }
            let info = message::info(t);
            let Some(c) = self.routes[ri].route.contact_after(None, t.time) else {
                tracing::warn!(route = %self.routes[ri].route.name, alarm = %t.key, "no contact on call");
                continue;
            };
            let r = &self.routes[ri];
            let m = message::alarm_message(&r.origin, &r.route.name, &info, &r.link, None);
            self.offer(ri, c, &info, m, now, || message::summary_line(t))
                .await;
            if let Some(after) = self.routes[ri].route.escalate_after_ms {
                self.escalations.insert(
                    (ri, t.key.clone()),
                    Escalation {
                        alarm: info,
                        contact: c,
                        deadline_ms: now + after,
                    },
                );
            }
        }
    }

    /// Queues `m` for contact `c` of route `ri` unless the flood limit
    /// holds it.
    async fn offer(
        &mut self,
        ri: usize,
        c: usize,
        alarm: &AlarmInfo,
        m: Message,
        now: i64,
        line: impl FnOnce() -> String,
    ) {
        if self.routes[ri].flood.offer(now, line) == Offer::Held {
            self.figures.routes[ri]
                .1
                .held
                .fetch_add(1, Ordering::Relaxed);
            return;
        }
        self.enqueue(ri, c, Some(alarm.key.clone()), m, now).await;
    }

    async fn enqueue(&self, ri: usize, c: usize, alarm_key: Option<String>, m: Message, now: i64) {
        let r = &self.routes[ri];
        let contact = &r.route.contacts[c];
        let message = match serde_json::to_string(&m) {
            Ok(s) => s,
            Err(e) => {
                tracing::error!(error = %e, "encoding a notification");
                return;
            }
        };
        let n = NewNotification {
            created_at: Timestamp::from_millis(now),
            route: r.route.name.clone(),
            contact: contact.name.clone(),
            address: contact.address.clone(),
            alarm_key,
            level: c as u32,
            subject: m.subject.clone(),
            message,
            give_up_at: Timestamp::from_millis(now + r.give_up_ms),
        };
        match self.store.enqueue_notification(&n).await {
            Ok(_) => self.wake.notify_one(),
            Err(e) => {
                // Counted like a failed attempt: the route's alarm tells.
                tracing::error!(route = %r.route.name, error = %e, "queueing a notification");
                self.figures.routes[ri]
                    .1
                    .failed_attempts
                    .fetch_add(1, Ordering::Relaxed);
            }
        }
    }

    async fn flush_floods(&mut self, now: i64) {
        for ri in 0..self.routes.len() {
            let Some(s) = self.routes[ri].flood.close_due(now) else {
                continue;
            };
            let r = &self.routes[ri];
            let Some(c) = r.route.contact_after(None, Timestamp::from_millis(now)) else {
                continue;
            };
            let m = message::flood_message(&r.origin, &r.route.name, &s, &r.link);
            self.enqueue(ri, c, None, m, now).await;
        }
    }

    async fn timers(&mut self) {
        let now = self.clock.now().as_millis();
        self.flush_floods(now).await;
        let due: Vec<(usize, String)> = self
            .escalations
            .iter()
            .filter(|(_, e)| e.deadline_ms <= now)
            .map(|(k, _)| k.clone())
            .collect();
        for key in due {
            let Some(e) = self.escalations.remove(&key) else {
                continue;
            };
            let (ri, alarm_key) = key;
            let unacked = self
                .alarms
                .id_of(&alarm_key)
                .and_then(|id| self.alarms.view(id))
                .is_some_and(|v| v.state.is_unacked());
            if !unacked {
                continue;
            }
            let r = &self.routes[ri];
            let Some(next) = r
                .route
                .contact_after(Some(e.contact), Timestamp::from_millis(now))
            else {
                tracing::warn!(route = %r.route.name, alarm = %alarm_key, "escalation chain ended unacknowledged");
                continue;
            };
            let m =
                message::alarm_message(&r.origin, &r.route.name, &e.alarm, &r.link, r.escalate_min);
            let line = format!("UNACKNOWLEDGED {}", e.alarm.message);
            let after = r.route.escalate_after_ms;
            self.offer(ri, next, &e.alarm, m, now, || line).await;
            if let Some(after) = after {
                self.escalations.insert(
                    (ri, alarm_key),
                    Escalation {
                        alarm: e.alarm,
                        contact: next,
                        deadline_ms: now + after,
                    },
                );
            }
        }
    }
}

/// A route's delivery health: consecutive failures and when to try again.
#[derive(Default)]
struct RouteHealth {
    failures: u32,
    blocked_until_ms: i64,
    last_error: String,
}

struct Delivery {
    routes: HashMap<String, (Channel, RouteHealth)>,
    store: Store,
    alarms: Arc<AlarmEngine>,
    clock: Arc<dyn Clock>,
    events: mpsc::Sender<NewEvent>,
    figures: Arc<NotifyFigures>,
    wake: Arc<Notify>,
}

impl Delivery {
    async fn run(mut self) {
        let mut last_prune: Option<i64> = None;
        loop {
            let now = self.clock.now().as_millis();
            match self
                .store
                .due_notifications(Timestamp::from_millis(now), 50)
                .await
            {
                Ok(due) => {
                    for n in due {
                        self.deliver(n).await;
                    }
                }
                Err(e) => tracing::error!(error = %e, "reading the notification outbox"),
            }
            if let Ok(p) = self.store.pending_notifications().await {
                self.figures.pending.store(p, Ordering::Relaxed);
            }
            if last_prune.is_none_or(|t| now - t > 86_400_000) {
                last_prune = Some(now);
                if let Err(e) = self
                    .store
                    .prune_notifications(Timestamp::from_millis(now - KEEP_DONE_MS), 5000)
                    .await
                {
                    tracing::error!(error = %e, "pruning the notification outbox");
                }
            }
            let wait = match self.store.next_notification_due().await {
                Ok(Some(t)) => {
                    let blocked = self
                        .routes
                        .values()
                        .map(|(_, h)| h.blocked_until_ms)
                        .filter(|&b| b > now)
                        .min();
                    // Due now but on a route backing off: wait for the route.
                    let at = if t.as_millis() > now {
                        t.as_millis()
                    } else {
                        blocked.unwrap_or(now + 1000)
                    };
                    Duration::from_millis((at - now).clamp(200, 5000) as u64)
                }
                _ => Duration::from_secs(5),
            };
            tokio::select! {
                _ = self.wake.notified() => {}
                _ = tokio::time::sleep(wait) => {}
            }
        }
    }

    async fn deliver(&mut self, n: Notification) {
        let now = self.clock.now();
        let route_name = n.new.route.clone();
        let ri = self
            .figures
            .routes
            .iter()
            .position(|(r, _)| *r == route_name);
        let Some((channel, health)) = self.routes.get_mut(&route_name) else {
            self.give_up(&n, now, "its route is no longer configured")
                .await;
            return;
        };
        if health.blocked_until_ms > now.as_millis() {
            if now >= n.new.give_up_at {
                let reason = format!("undelivered: {}", health.last_error);
                self.give_up(&n, now, &reason).await;
            }
            return;
        }
        let message: Message = match serde_json::from_str(&n.new.message) {
            Ok(m) => m,
            Err(e) => {
                self.give_up(&n, now, &format!("unreadable message: {e}"))
                    .await;
                return;
            }
        };
        let attempts = n.attempts + 1;
        match channel
            .send(n.id, &n.new.contact, &n.new.address, &message)
            .await
        {
            Ok(()) => {
                let recovered = health.failures > 0;
                *health = RouteHealth::default();
                if let Err(e) = self
                    .store
                    .notification_sent(n.id, self.clock.now(), attempts)
                    .await
                {
                    tracing::error!(error = %e, "recording a sent notification");
                }
                if let Some(ri) = ri {
                    self.figures.routes[ri]
                        .1
                        .sent
                        .fetch_add(1, Ordering::Relaxed);
                }
                self.event(
                    "notification",
                    format!(
                        "{} to {} <{}>: {}",
                        route_name, n.new.contact, n.new.address, n.new.subject
                    ),
                )
                .await;
                if recovered {
                    self.failing(&route_name, None);
                }
            }
            Err(e) => {
                tracing::warn!(route = %route_name, id = n.id, attempt = attempts, error = %e, "notification not delivered");
                health.failures += 1;
                health.blocked_until_ms = now.as_millis() + backoff_ms(health.failures);
                health.last_error = e.clone();
                if let Some(ri) = ri {
                    self.figures.routes[ri]
                        .1
                        .failed_attempts
                        .fetch_add(1, Ordering::Relaxed);
                }
                let next = (now < n.new.give_up_at)
                    .then(|| Timestamp::from_millis(now.as_millis() + backoff_ms(attempts)));
                if next.is_none() {
                    self.give_up(&n, now, &e).await;
                } else if let Err(err) = self
                    .store
                    .notification_attempt_failed(n.id, attempts, next, now, &e)
                    .await
                {
                    tracing::error!(error = %err, "recording a failed notification");
                }
                self.failing(&route_name, Some(&e));
            }
        }
    }

    async fn give_up(&mut self, n: &Notification, now: Timestamp, reason: &str) {
        if let Err(e) = self
            .store
            .notification_attempt_failed(n.id, n.attempts, None, now, reason)
            .await
        {
            tracing::error!(error = %e, "recording a failed notification");
        }
        if let Some((_, c)) = self.figures.routes.iter().find(|(r, _)| *r == n.new.route) {
            c.given_up.fetch_add(1, Ordering::Relaxed);
        }
        self.event(
            "notification_failed",
            format!(
                "{} to {} <{}> given up after {} attempts: {} ({reason})",
                n.new.route, n.new.contact, n.new.address, n.attempts, n.new.subject
            ),
        )
        .await;
    }

    async fn event(&self, kind: &str, message: String) {
        let e = NewEvent {
            ts: self.clock.now(),
            user: None,
            source: "notify".into(),
            kind: kind.into(),
            message,
        };
        if self.events.send(e).await.is_err() {
            tracing::warn!("event log closed; notification event lost");
        }
    }

    /// Raises (with the reason) or clears the route's system alarm.
    fn failing(&self, route: &str, error: Option<&str>) {
        let key = format!("{SYSTEM_ALARM_PREFIX}{route}");
        self.figures
            .failing
            .lock()
            .insert(route.to_string(), error.is_some());
        let r = match error {
            Some(e) => {
                let waiting = self.figures.pending.load(Ordering::Relaxed);
                let message = format!(
                    "Alarm notifications of route '{route}' cannot be delivered ({e}); {waiting} waiting, retried with back-off"
                );
                self.alarms
                    .raise(&key, FAILURE_PRIORITY, "SYSTEM", &message)
                    .map(|_| ())
            }
            None => self.alarms.clear(&key).map(|_| ()),
        };
        if let Err(e) = r {
            tracing::error!(%key, error = %e, "notification system alarm");
        }
    }
}
