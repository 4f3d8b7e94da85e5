//! The outer loop's task: waiting for the first reading, then one
//! [`Dispatcher::step`](super::Dispatcher::step) every period of plant time,
//! publishing the status and sending the notices.

use std::collections::VecDeque;
use std::sync::Arc;
use std::time::Duration;

use tokio::sync::{mpsc, watch};

use gridscada_config::MicrogridConfig;
use gridscada_tagdb::{Clock, TagDb, TagWriter};

use super::status::{DispatchNotice, DispatchStatus};
use super::{DispatchPolicy, Dispatcher};

/// Runs the outer loop until the task is dropped: one [`Dispatcher::step`]
/// every `dispatch_period_s` of plant time.
pub async fn run_dispatch(
    cfg: MicrogridConfig,
    db: Arc<TagDb>,
    writer: Arc<dyn TagWriter>,
    clock: Arc<dyn Clock>,
    status: watch::Sender<DispatchStatus>,
    notices: mpsc::Sender<DispatchNotice>,
) {
    run_dispatch_with(
        cfg,
        db,
        writer,
        clock,
        status,
        notices,
        DispatchPolicy::Optimal,
    )
    .await
}

/// [`run_dispatch`] with an explicit [`DispatchPolicy`].
pub async fn run_dispatch_with(
    cfg: MicrogridConfig,
    db: Arc<TagDb>,
    writer: Arc<dyn TagWriter>,
    clock: Arc<dyn Clock>,
    status: watch::Sender<DispatchStatus>,
    notices: mpsc::Sender<DispatchNotice>,
    policy: DispatchPolicy,
) {
    let period = Duration::from_secs_f64(period_s(&cfg));
    wait_for_first_reading(&cfg, &db, &*clock).await;
    let mut d = Dispatcher::new(cfg, clock.now()).with_policy(policy);
    // Notices the channel had no room for; sent first next period, never dropped.
    let mut backlog: VecDeque<DispatchNotice> = VecDeque::new();
    loop {
        let (st, out) = d.step(&db, &*writer, clock.now()).await;
        status.send_replace(st);
        backlog.extend(out);
        while let Some(n) = backlog.pop_front() {
            match notices.try_send(n) {
                Ok(()) => {}
                Err(mpsc::error::TrySendError::Full(n)) => {
                    tracing::warn!(
                        "dispatch notice channel full; {} notices wait",
                        backlog.len() + 1
                    );
                    backlog.push_front(n);
                    break;
                }
                Err(mpsc::error::TrySendError::Closed(_)) => {
                    backlog.clear();
                    break;
                }
            }
        }
        clock.sleep(period).await;
    }
}

/// Lets the field I/O read the plant once before the first decision: acting
/// on "no value yet" would run the fallback (and start the diesel) on every
/// server start. Waits at most `stale_after_s`; after that, the loop runs
/// and the fallback handles whatever is still missing.
async fn wait_for_first_reading(cfg: &MicrogridConfig, db: &TagDb, clock: &dyn Clock) {
    let mut names = vec![cfg.demand_tag.get_ref().clone()];
    for u in &cfg.units {
        let io = u.io();
        names.extend(
            u.required_tags()
                .into_iter()
                .filter(|t| *t != io.setpoint_kw && *t != io.run_cmd),
        );
    }
    let ids: Vec<_> = names.iter().filter_map(|n| db.id(n)).collect();
    let give_up = clock
        .now()
        .add(Duration::from_secs_f64(cfg.stale_after_s.max(0.0)));
    loop {
        // Looked at after a first wait, never at once: when this task first
        // runs, the first scans may or may not have landed, and a replay
        // must start the loop at the same plant time either way.
        clock.sleep(Duration::from_millis(100)).await;
        let read_once = ids
            .iter()
            .all(|id| db.get(*id).is_some_and(|s| s.timestamp.as_millis() > 0));
        if read_once || clock.now() >= give_up {
            return;
        }
    }
}

pub(super) fn period_s(cfg: &MicrogridConfig) -> f64 {
    let p = *cfg.dispatch_period_s.get_ref();
    if p.is_finite() && p >= 0.1 {
        p
    } else {
        5.0
    }
}
