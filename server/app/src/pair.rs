//! A server of a redundant pair (`[redundancy]`): keeping the lease, and
//! running what only the active server runs.
//!
//! - [`keep_lease`] claims or renews the site's lease in PostgreSQL every
//!   `renew_s` and grants the shared [`Leadership`] until `lease_s -
//!   margin_s` after each claim was *sent*; the field writer asks that gate
//!   as each write frame goes out. It publishes the pair's view for
//!   `/api/pair` and `/metrics`.
//! - [`announce`] turns each change of role into an event and a system
//!   alarm, and, on becoming active, takes over the alarm states the
//!   previous active server stored.
//! - [`panel_host`] and [`dispatch_host`] run a panel's fault-isolation
//!   sequence and the microgrid's outer loop only while this server is
//!   active: each activation starts them afresh from the store's
//!   `panel_states`, as a restart does, and a standby refuses their
//!   commands with the active server's name.
//! - [`gate`] drops the alarm engine's records while on standby (the active
//!   server records the same alarms), so nothing is stored twice.
//!
//! The timing argument is in `ARCHITECTURE.md`, "Redundant pair".

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Instant;

use gridscada_alarms::AlarmEngine;
use gridscada_config::{PanelConfig, RedundancyConfig};
use gridscada_control::dispatch::{self, DispatchNotice, DispatchStatus};
use gridscada_control::fault_isolation::{
    self, CommandError, PanelCommand, PanelNotice, PanelStatus,
};
use gridscada_store::{Fence, Lease, LeaseState, NewEvent, Store};
use gridscada_tagdb::{Clock, Leadership, Role, TagDb, TagWriter};
use gridscada_web::api::pair::{PairMember, PairView};
use tokio::sync::{mpsc, watch};

use crate::sinks;

/// The key of the system alarm raised at each change of role.
pub const ROLE_ALARM: &str = "pair:role";
/// The key of the system alarm that stands while a server of the pair is
/// not seen.
pub const DEGRADED_ALARM: &str = "pair:degraded";

/// What the rest of the stack holds of the pair.
#[derive(Clone)]
pub struct PairHandle {
    pub leadership: Leadership,
    pub view: watch::Receiver<PairView>,
    pub role_changes: Arc<AtomicU64>,
}

/// "b (http://10.0.0.2:8080)": a server as a refusal names it.
fn described(cfg: &RedundancyConfig, name: &str) -> String {
    match cfg.url_of(name) {
        Some(url) => format!("{name} ({url})"),
        None => name.to_string(),
    }
}

/// Keeps the lease until `stop`; then stops commanding and gives the lease
/// up so a standby takes over at once.
pub async fn keep_lease(
    mut lease: Lease,
    cfg: RedundancyConfig,
    site: String,
    leadership: Leadership,
    view: watch::Sender<PairView>,
    role_changes: Arc<AtomicU64>,
    mut stop: watch::Receiver<bool>,
) {
    let me = cfg.name.get_ref().clone();
    let my_url = cfg.url_of(&me).unwrap_or_default().to_string();
    let (length, renew, margin) = (cfg.lease(), cfg.renew(), cfg.margin());
    // The epoch held and the deadline of its grant (monotonic).
    let mut held: Option<(u64, Instant)> = None;
    let mut holder: Option<String> = None;
    let mut members: Vec<(String, String, bool, u64)> = Vec::new();
    let mut roles = leadership.subscribe();
    loop {
        let sent = Instant::now();
        // No call may outlast the grant: the step down is noticed (and
        // announced) at its deadline, not after a hung call.
        let limit = |held: Option<(u64, Instant)>| match held {
            Some((_, until)) => renew
                .min(until.saturating_duration_since(Instant::now()))
                .max(std::time::Duration::from_millis(1)),
            None => renew,
        };
        match tokio::time::timeout(limit(held), lease.claim(length, held.map(|h| h.0))).await {
            Ok(Ok(LeaseState::Held { epoch })) => {
                // From when the claim was sent: the database started the
                // lease later than that, so this deadline comes first.
                let until = sent + length.saturating_sub(margin);
                if held.map(|h| h.0) != Some(epoch) {
                    tracing::info!(epoch, "this server holds the lease: active");
                }
                leadership.grant(epoch, until);
                held = Some((epoch, until));
                holder = Some(me.clone());
            }
            Ok(Ok(LeaseState::HeldBy {
                holder: other,
                epoch,
                remaining,
            })) => {
                if held.take().is_some() {
                    tracing::warn!(holder = %other, epoch, "the lease is held by another server: standby");
                }
                let live = !remaining.is_zero() && !other.is_empty();
                holder = live.then_some(other.clone());
                leadership.revoke(live.then(|| described(&cfg, &other)));
            }
            Ok(Err(e)) => {
                tracing::warn!(error = %e, "could not claim the lease");
                lease.reset();
            }
            Err(_) => {
                tracing::warn!(
                    after_ms = renew.as_millis() as u64,
                    "the lease claim did not answer in time"
                );
                lease.reset();
            }
        }
        // A grant that ran out without a renewal: step down (the gate
        // already refuses every write since the deadline).
        if let Some((epoch, until)) = held {
            if Instant::now() >= until {
                tracing::warn!(
                    epoch,
                    "the lease could not be renewed in time: standby, no more commands"
                );
                leadership.revoke(None);
                held = None;
                holder = None;
            }
        }
        match tokio::time::timeout(limit(held), lease.beat(&my_url, held.is_some())).await {
            Ok(Ok(m)) => members = m,
            Ok(Err(_)) | Err(_) => lease.reset(),
        }
        let _ = roles.borrow_and_update();
        view.send_replace(pair_view(
            &cfg,
            &site,
            &me,
            held.map(|h| h.0),
            holder.as_deref(),
            &members,
            role_changes.load(Ordering::Relaxed),
        ));
        let next = sent + renew;
        let wake = held.map_or(next, |(_, until)| next.min(until));
        let stopping = tokio::select! {
            _ = tokio::time::sleep_until(wake.into()) => false,
            r = stop.wait_for(|s| *s) => { drop(r); true }
        };
        if stopping {
            leadership.revoke(None);
            if let Some((epoch, _)) = held {
                match tokio::time::timeout(renew, lease.release(epoch)).await {
                    Ok(Ok(())) => tracing::info!(epoch, "lease released"),
                    _ => tracing::warn!(epoch, "could not release the lease; it expires by itself"),
                }
            }
            return;
        }
    }
}

fn pair_view(
    cfg: &RedundancyConfig,
    site: &str,
    me: &str,
    epoch: Option<u64>,
    holder: Option<&str>,
    members: &[(String, String, bool, u64)],
    role_changes: u64,
) -> PairView {
    let lease_ms = cfg.lease().as_millis() as u64;
    let servers: Vec<PairMember> = cfg
        .servers
        .iter()
        .map(|s| {
            let name = s.name.get_ref();
            let seen = members.iter().find(|m| &m.0 == name);
            PairMember {
                name: name.clone(),
                url: s.url.get_ref().clone(),
                active: holder == Some(name.as_str()),
                seen_ms_ago: if name == me && epoch.is_some() {
                    Some(0)
                } else {
                    seen.map(|m| m.3)
                },
            }
        })
        .collect();
    let healthy = holder.is_some()
        && servers
            .iter()
            .all(|s| s.seen_ms_ago.is_some_and(|ms| ms <= lease_ms));
    PairView {
        site: site.to_string(),
        server: me.to_string(),
        role: if epoch.is_some() { "active" } else { "standby" }.into(),
        epoch,
        active: holder.map(str::to_string),
        active_url: holder.and_then(|h| cfg.url_of(h)).map(str::to_string),
        servers,
        healthy,
        role_changes,
    }
}

/// Each change of role: an event, a system alarm (raised and cleared at
/// once, so it waits for an operator's acknowledgement), the count for
/// `/metrics`; on becoming active, the stored alarm states are taken over
/// first. Also raises [`DEGRADED_ALARM`] while the pair is not whole.
pub async fn announce(
    leadership: Leadership,
    mut view: watch::Receiver<PairView>,
    store: Store,
    alarms: Arc<AlarmEngine>,
    events: mpsc::Sender<NewEvent>,
    clock: Arc<dyn Clock>,
    role_changes: Arc<AtomicU64>,
) {
    let me = leadership.server().to_string();
    let mut roles = leadership.subscribe();
    let mut last = roles.borrow_and_update().clone();
    let mut degraded: Option<bool> = None;
    loop {
        tokio::select! {
            r = roles.changed() => {
                if r.is_err() {
                    return;
                }
                let role = roles.borrow_and_update().clone();
                if role.is_active() == last.is_active() {
                    last = role;
                    continue;
                }
                role_changes.fetch_add(1, Ordering::Relaxed);
                let message = match &role {
                    Role::Active { epoch } => {
                        match store.alarm_states().await {
                            Ok(states) => alarms.adopt(&states),
                            Err(e) => tracing::error!(error = %e, "could not take over the stored alarm states"),
                        }
                        format!("Server {me} became active (lease epoch {epoch})")
                    }
                    Role::Standby { active: Some(a) } => {
                        format!("Server {me} is on standby; {a} is active")
                    }
                    Role::Standby { active: None } => format!(
                        "Server {me} stepped down: its lease could not be renewed in time"
                    ),
                };
                tracing::warn!("{message}");
                let _ = events
                    .send(sinks::system_event(clock.as_ref(), "pair", "pair", message.clone()))
                    .await;
                // Only the active server records alarms: raised by the one
                // that becomes active, or by a standby for the record it
                // keeps in memory.
                if let Err(e) = alarms.raise(ROLE_ALARM, 500, "SYSTEM", &message) {
                    tracing::error!(error = %e, "role change alarm");
                }
                let _ = alarms.clear(ROLE_ALARM);
                last = role;
            }
            r = view.changed() => {
                if r.is_err() {
                    return;
                }
                let v = view.borrow_and_update().clone();
                if v.role != "active" {
                    continue;
                }
                let now = !v.healthy;
                if degraded != Some(now) {
                    degraded = Some(now);
                    let missing: Vec<&str> = v
                        .servers
                        .iter()
                        .filter(|s| !s.active && s.seen_ms_ago.is_none_or(|ms| ms > 10_000))
                        .map(|s| s.name.as_str())
                        .collect();
                    let message = format!(
                        "Redundant pair degraded: no standby seen ({})",
                        if missing.is_empty() { "late".to_string() } else { missing.join(", ") }
                    );
                    let r = if now {
                        alarms.raise(DEGRADED_ALARM, 700, "SYSTEM", &message).map(|_| ())
                    } else {
                        alarms.clear(DEGRADED_ALARM).map(|_| ())
                    };
                    if let Err(e) = r {
                        tracing::error!(error = %e, "pair degraded alarm");
                    }
                }
            }
        }
    }
}

/// A standby's panel as the active server left it in the store.
struct Follow<'a> {
    store: &'a Store,
    panel: &'a str,
    status: &'a watch::Sender<PanelStatus>,
}

impl Follow<'_> {
    /// Shows the active server's retained state (mode, faulty zones,
    /// lockout) in this standby's status, so its HMI and API read what the
    /// plant's sequence knows.
    async fn refresh(&self) {
        let Some(r) = sinks::load_panel_retained(self.store)
            .await
            .remove(self.panel)
        else {
            return;
        };
        self.status.send_if_modified(|s| {
            if s.retained == r {
                return false;
            }
            s.mode = r.mode;
            s.lockout = r.lockout;
            s.load0_faulty = r.faulty.contains(&0);
            s.faulty_zones = r.faulty.iter().copied().filter(|z| *z > 0).collect();
            if r.lockout {
                s.step = "lockout".into();
            } else if s.step == "lockout" {
                s.step = "idle".into();
            }
            s.retained = r;
            true
        });
    }
}

/// How often a standby reads the active server's panel states.
const FOLLOW_EVERY: std::time::Duration = std::time::Duration::from_secs(2);

/// Waits until this server is active; meanwhile answers `commands` with a
/// refusal naming the active server, and follows the panel's stored state.
/// `None` once the stack stops.
async fn until_active(
    roles: &mut watch::Receiver<Role>,
    commands: Option<&mut mpsc::Receiver<PanelCommand>>,
    follow: Option<Follow<'_>>,
) -> Option<u64> {
    let mut commands = commands;
    let mut tick = tokio::time::interval(FOLLOW_EVERY);
    loop {
        if let Role::Active { epoch } = *roles.borrow_and_update() {
            return Some(epoch);
        }
        tokio::select! {
            r = roles.changed() => r.ok()?,
            _ = tick.tick() => {
                if let Some(f) = &follow {
                    f.refresh().await;
                }
            }
            cmd = async {
                match commands.as_mut() {
                    Some(c) => c.recv().await,
                    None => std::future::pending().await,
                }
            } => {
                let cmd = cmd?;
                let why = match &*roles.borrow() {
                    Role::Standby { active: Some(a) } => format!("this server is on standby; commands go to the active server {a}"),
                    _ => "this server is on standby and no server of the pair is active now".to_string(),
                };
                let _ = cmd.reply.send(Err(CommandError::Standby(why)));
            }
        }
    }
}

/// What a panel host needs.
pub struct PanelHost {
    pub panel: PanelConfig,
    pub db: Arc<TagDb>,
    pub writer: Arc<dyn TagWriter>,
    pub clock: Arc<dyn Clock>,
    pub store: Store,
    pub site: String,
    pub leadership: Leadership,
    pub notices: mpsc::Sender<PanelNotice>,
}

/// Runs the panel's sequence while this server is active, restored from
/// the store at each activation; refuses its commands on standby.
pub async fn panel_host(
    h: PanelHost,
    mut commands: mpsc::Receiver<PanelCommand>,
    status: watch::Sender<PanelStatus>,
) {
    let id = h.panel.id.get_ref().clone();
    let mut roles = h.leadership.subscribe();
    loop {
        let follow = Follow {
            store: &h.store,
            panel: &id,
            status: &status,
        };
        let Some(epoch) = until_active(&mut roles, Some(&mut commands), Some(follow)).await else {
            return;
        };
        let retained = sinks::load_panel_retained(&h.store).await.remove(&id);
        tracing::info!(panel = %id, epoch, restored = retained.is_some(), "panel sequence starts on this active server");
        let (inner_tx, inner_rx) = mpsc::channel(16);
        let driver = fault_isolation::run_panel(
            h.panel.clone(),
            h.db.clone(),
            h.writer.clone(),
            h.clock.clone(),
            inner_rx,
            status.clone(),
            h.notices.clone(),
            retained.map(|r| (r, fault_isolation::Takeover::Failover)),
        );
        let saver = sinks::panel_retained(
            h.store.clone(),
            id.clone(),
            status.subscribe(),
            h.clock.clone(),
            Some(Fence {
                site: h.site.clone(),
                server: h.leadership.server().to_string(),
                epoch,
            }),
        );
        let forward = async {
            while let Some(cmd) = commands.recv().await {
                if inner_tx.send(cmd).await.is_err() {
                    break;
                }
            }
        };
        let deposed = roles.wait_for(|r| !r.is_active());
        tokio::select! {
            r = driver => {
                if let Err(e) = r {
                    tracing::error!(panel = %id, error = %e, "fault-isolation sequence stopped");
                }
                return;
            }
            _ = saver => return,
            _ = forward => return,
            r = deposed => {
                if r.is_err() {
                    return;
                }
                tracing::warn!(panel = %id, "panel sequence stopped: this server is no longer active");
            }
        }
    }
}

/// Runs the microgrid's outer loop while this server is active.
#[allow(clippy::too_many_arguments)]
pub async fn dispatch_host(
    cfg: gridscada_config::MicrogridConfig,
    db: Arc<TagDb>,
    writer: Arc<dyn TagWriter>,
    clock: Arc<dyn Clock>,
    status: watch::Sender<DispatchStatus>,
    notices: mpsc::Sender<DispatchNotice>,
    policy: dispatch::DispatchPolicy,
    leadership: Leadership,
) {
    let mut roles = leadership.subscribe();
    loop {
        if until_active(&mut roles, None, None).await.is_none() {
            return;
        }
        let run = dispatch::run_dispatch_with(
            cfg.clone(),
            db.clone(),
            writer.clone(),
            clock.clone(),
            status.clone(),
            notices.clone(),
            policy,
        );
        tokio::select! {
            _ = run => return,
            r = roles.wait_for(|r| !r.is_active()) => {
                if r.is_err() {
                    return;
                }
                tracing::warn!("dispatch stopped: this server is no longer active");
            }
        }
    }
}

/// Passes on what `rx` carries only while this server may command; on a
/// standby the alarm engine runs warm but its records are the active
/// server's to store.
pub fn gate<T: Send + 'static>(
    mut rx: mpsc::Receiver<T>,
    leadership: &Leadership,
) -> mpsc::Receiver<T> {
    if !leadership.is_pair() {
        return rx;
    }
    let leadership = leadership.clone();
    let (tx, out) = mpsc::channel(4096);
    tokio::spawn(async move {
        while let Some(item) = rx.recv().await {
            if leadership.permit().is_ok() && tx.send(item).await.is_err() {
                return;
            }
        }
    });
    out
}

/// The pair's figures for `/metrics`.
pub fn render_metrics(p: &PairHandle, out: &mut gridscada_web::metrics::Prom) {
    let v = p.view.borrow().clone();
    out.gauge(
        "gridscada_pair_active",
        "1 while this server holds the lease and commands the plant.",
        &[],
        f64::from(u8::from(p.leadership.permit().is_ok())),
    );
    out.gauge(
        "gridscada_pair_epoch",
        "The fencing epoch of the lease this server holds (0 on standby).",
        &[],
        v.epoch.unwrap_or(0) as f64,
    );
    out.gauge(
        "gridscada_pair_healthy",
        "1 while one server is active and every server of the pair is seen.",
        &[],
        f64::from(u8::from(v.healthy)),
    );
    out.counter(
        "gridscada_pair_role_changes_total",
        "Changes of this server's role (active, standby) since it started.",
        &[],
        p.role_changes.load(Ordering::Relaxed) as f64,
    );
    for s in &v.servers {
        if let Some(ms) = s.seen_ms_ago {
            out.gauge(
                "gridscada_pair_server_seen_seconds",
                "Seconds since each server of the pair last reported to the database.",
                &[("server", s.name.as_str())],
                ms as f64 / 1000.0,
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cfg() -> RedundancyConfig {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(
            dir.path().join("gridscada.toml"),
            "tag_files = [\"tags.toml\"]\n[storage]\nurl = \"postgres://db/x\"\n\
             [redundancy]\nname = \"a\"\n\
             [[redundancy.server]]\nname = \"a\"\nurl = \"http://10.0.0.1:8080\"\n\
             [[redundancy.server]]\nname = \"b\"\nurl = \"http://10.0.0.2:8080\"\n",
        )
        .unwrap();
        std::fs::write(
            dir.path().join("tags.toml"),
            "[[device]]\nname = \"D1\"\nprotocol = \"tcp\"\naddress = \"127.0.0.1:9\"\n",
        )
        .unwrap();
        gridscada_config::load_path(dir.path())
            .unwrap()
            .redundancy
            .unwrap()
    }

    #[test]
    fn the_pair_is_healthy_only_with_an_active_server_and_every_server_seen() {
        let c = cfg();
        let seen = |b_ms| {
            vec![
                ("a".to_string(), "http://10.0.0.1:8080".to_string(), true, 0),
                (
                    "b".to_string(),
                    "http://10.0.0.2:8080".to_string(),
                    false,
                    b_ms,
                ),
            ]
        };
        let v = pair_view(&c, "main", "a", Some(4), Some("a"), &seen(400), 1);
        assert!(v.healthy);
        assert_eq!(v.role, "active");
        assert_eq!(v.active_url.as_deref(), Some("http://10.0.0.1:8080"));
        assert!(v.servers[0].active && !v.servers[1].active);
        // b has not reported for longer than the lease.
        let v = pair_view(&c, "main", "a", Some(4), Some("a"), &seen(3_500), 1);
        assert!(!v.healthy);
        // Nobody holds the lease.
        let v = pair_view(&c, "main", "b", None, None, &seen(0), 2);
        assert!(!v.healthy);
        assert_eq!(v.role, "standby");
        assert_eq!(described(&c, "a"), "a (http://10.0.0.1:8080)");
    }

    #[tokio::test]
    async fn a_standby_passes_no_records_on() {
        let l = Leadership::standby("a");
        let (tx, rx) = mpsc::channel(8);
        let mut out = gate(rx, &l);
        tx.send(1).await.unwrap();
        // The gate decides as it takes each record.
        tokio::time::sleep(std::time::Duration::from_millis(50)).await;
        l.grant(1, Instant::now() + std::time::Duration::from_secs(60));
        tx.send(2).await.unwrap();
        assert_eq!(out.recv().await, Some(2), "only what came while active");
        // A server alone passes everything, without a task between.
        let (tx, rx) = mpsc::channel(8);
        let mut out = gate(rx, &Leadership::sole());
        tx.send(3).await.unwrap();
        assert_eq!(out.recv().await, Some(3));
    }
}
