//! `/api/live`: the WebSocket push of tag changes and the alarm summary.
//!
//! Sockets subscribed to the same set of tags share one feed: one
//! tag-database subscription that merges changes per tag over the merge
//! window (`[server] live_merge_ms`; 0 sends each batch as it comes) and
//! serializes each message once for all of them. A socket too slow to take
//! them falls behind the feed's ring and gets a fresh snapshot instead of an
//! unbounded queue. When the session ends (logout, expiry, user blocked), the
//! socket is closed.
//!
//! The alarm list (`"alarms": true` in the subscription) comes whole
//! (`alarms`) each time it changes; with `"alarm_changes": true` as well,
//! whole once and then as what changed (`alarm_changes`: the changed alarms'
//! views and the ids that left the list), so a flood of standing alarms is
//! not sent whole to every screen every time one of them changes. A new
//! subscription that names the version it holds (`alarm_version`, the one
//! this socket last sent) goes on with the changes; otherwise the list comes
//! whole again. An alarm's "value now" in a list kept by changes is the value
//! at its own latest change.

use std::collections::{BTreeMap, HashMap, VecDeque};
use std::sync::{Arc, Weak};
use std::time::Duration;

use axum::extract::ws::{CloseFrame, Message, Utf8Bytes, WebSocket, WebSocketUpgrade};
use axum::extract::State;
use axum::http::{header, HeaderMap, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::Extension;
use gridscada_alarms::AlarmListUpdate;
use gridscada_tagdb::{Quality, Sample, TagDb, TagId, Timestamp, Update, Value};
use serde::{Deserialize, Serialize};
use serde_json::json;

use crate::access::Readable;
use crate::auth::{token_from_cookies, Principal};
use crate::error::ApiError;
use crate::WebState;

/// Longest a client message may be. A subscription names every tag a screen
/// binds: a network screen of 20,000 sections and 10,000 devices names
/// about 40,000 (1.1 MB); the socket is a logged-in user's, and their
/// number is capped (`auth.sockets`).
const MAX_MESSAGE: usize = 2 * 1024 * 1024;
/// How often a socket sends its heartbeat and alarm summary and checks its
/// session.
const TICK: Duration = Duration::from_millis(100);
/// Messages a feed keeps for its slowest socket; one further behind is sent
/// a snapshot instead.
const FEED_RING: usize = 64;

/// The live feeds: one per distinct set of tags subscribed to, shared by
/// every socket subscribed to exactly that set, gone with its last socket.
#[derive(Default)]
pub struct LiveFeeds {
    feeds: parking_lot::Mutex<HashMap<Arc<[TagId]>, Weak<Feed>>>,
    /// The last `alarms` message and the alarm version it shows: built
    /// once per change of the alarms and sent to every socket that asked
    /// for them (the list does not depend on the user), not rebuilt and
    /// serialized per socket.
    alarm_summary: parking_lot::Mutex<Option<(u64, Utf8Bytes)>>,
    /// The last few `alarm_changes` messages, by the version they start
    /// from and the one they bring: sockets at the same version share one.
    alarm_changes: parking_lot::Mutex<VecDeque<(u64, u64, Utf8Bytes)>>,
}

/// `alarm_changes` messages kept for sockets at different versions.
const ALARM_CHANGES_KEPT: usize = 8;

/// One feed: its task and the ring of serialized `tags` messages.
struct Feed {
    tx: tokio::sync::broadcast::Sender<Utf8Bytes>,
    task: tokio::task::JoinHandle<()>,
}

impl Drop for Feed {
    fn drop(&mut self) {
        self.task.abort();
    }
}

impl LiveFeeds {
    /// The alarm list's message for a socket that has the list of version
    /// `since`, if the alarms changed since: the whole list (`alarms`), or,
    /// for a socket that asked for changes and has a list, what changed
    /// (`alarm_changes`). Each is made once for all sockets at the same
    /// versions.
    fn alarm_message(
        &self,
        s: &WebState,
        since: Option<u64>,
        changes: bool,
    ) -> Option<(u64, Utf8Bytes)> {
        let e = s.components.alarms.as_ref()?;
        let version = *e.subscribe_version().borrow();
        if since == Some(version) {
            return None;
        }
        let since = since.filter(|_| changes);
        if let Some(since) = since {
            let kept = self.alarm_changes.lock();
            if let Some((_, v, msg)) = kept.iter().find(|(s, v, _)| (*s, *v) == (since, version)) {
                return Some((*v, msg.clone()));
            }
        } else if let Some((v, msg)) = self
            .alarm_summary
            .lock()
            .as_ref()
            .filter(|(v, _)| *v == version)
        {
            return Some((*v, msg.clone()));
        }
        match e.summary_since(since)? {
            AlarmListUpdate::Whole { version, alarms } => {
                let msg: Utf8Bytes =
                    json!({"type": "alarms", "version": version, "alarms": alarms})
                        .to_string()
                        .into();
                *self.alarm_summary.lock() = Some((version, msg.clone()));
                Some((version, msg))
            }
            AlarmListUpdate::Changes {
                version,
                since,
                changed,
                removed,
            } => {
                let msg: Utf8Bytes = json!({"type": "alarm_changes", "version": version,
                    "since": since, "changed": changed, "removed": removed})
                .to_string()
                .into();
                let mut kept = self.alarm_changes.lock();
                kept.push_back((since, version, msg.clone()));
                while kept.len() > ALARM_CHANGES_KEPT {
                    kept.pop_front();
                }
                Some((version, msg))
            }
        }
    }

    /// The feed of `ids` (sorted, unique), started if none runs, and a
    /// receiver of its messages from now on.
    fn join(
        &self,
        db: &Arc<TagDb>,
        ids: Arc<[TagId]>,
        merge: Duration,
    ) -> (Arc<Feed>, tokio::sync::broadcast::Receiver<Utf8Bytes>) {
        let mut feeds = self.feeds.lock();
        feeds.retain(|_, f| f.strong_count() > 0);
        if let Some(feed) = feeds.get(&ids).and_then(Weak::upgrade) {
            let rx = feed.tx.subscribe();
            return (feed, rx);
        }
        let (tx, rx) = tokio::sync::broadcast::channel(FEED_RING);
        // Subscribed here, not in the task: a change made after `join`
        // returns (and after the caller's snapshot) must reach the feed even
        // if its task has not run yet.
        let sub = db.subscribe(&ids);
        let task = tokio::spawn(feed(db.clone(), sub, tx.clone(), merge));
        let feed = Arc::new(Feed { tx, task });
        feeds.insert(ids, Arc::downgrade(&feed));
        (feed, rx)
    }

    /// Feeds running (distinct subscriptions with at least one socket).
    pub fn len(&self) -> usize {
        self.feeds
            .lock()
            .values()
            .filter(|f| f.strong_count() > 0)
            .count()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// A feed's task: gathers the changes of its tags for `merge` after the
/// first, serializes them once, and hands the text to every socket.
async fn feed(
    db: Arc<TagDb>,
    mut sub: gridscada_tagdb::Subscription,
    tx: tokio::sync::broadcast::Sender<Utf8Bytes>,
    merge: Duration,
) {
    let mut pending: BTreeMap<TagId, Sample> = BTreeMap::new();
    let mut snapshot = false;
    let take = |update: Update, pending: &mut BTreeMap<TagId, Sample>, snapshot: &mut bool| {
        if let Update::Snapshot(_) = &update {
            // The feed itself fell behind: its next message replaces all.
            pending.clear();
            *snapshot = true;
        }
        for (id, sample) in &update.batch().changes {
            pending.insert(*id, sample.clone());
        }
    };
    loop {
        let Some(update) = sub.recv().await else {
            return;
        };
        take(update, &mut pending, &mut snapshot);
        if !merge.is_zero() {
            let until = tokio::time::Instant::now() + merge;
            loop {
                tokio::select! {
                    update = sub.recv() => match update {
                        Some(u) => take(u, &mut pending, &mut snapshot),
                        None => return,
                    },
                    _ = tokio::time::sleep_until(until) => break,
                }
            }
        }
        let text = tags_message(&db, &pending, snapshot);
        pending.clear();
        snapshot = false;
        // No socket listening (the last one is leaving): nothing to do.
        let _ = tx.send(text.into());
    }
}

#[utoipa::path(get, path = "/api/live", tag = "live",
    summary = "WebSocket push of tag changes and the alarm summary",
    responses((status = 101, description = "Switching to the WebSocket protocol"), (status = 400),
        (status = 426, description = "Not a WebSocket upgrade")))]
pub async fn upgrade(
    State(s): State<WebState>,
    Extension(who): Extension<Principal>,
    Extension(client): Extension<crate::ClientInfo>,
    headers: HeaderMap,
    ws: WebSocketUpgrade,
) -> Response {
    let token = token_from_cookies(headers.get(header::COOKIE).and_then(|v| v.to_str().ok()));
    let ip = client.ip;
    // Places are taken before the upgrade and freed when the socket ends.
    let slot = match s.auth.sockets.open(token.as_deref(), ip) {
        Ok(slot) => slot,
        Err(why) => {
            return ApiError::new(StatusCode::TOO_MANY_REQUESTS, "too_many_connections", why)
                .into_response()
        }
    };
    ws.max_message_size(MAX_MESSAGE)
        .on_upgrade(move |socket| async move {
            let _slot = slot;
            if let Err(e) = run(s, who.clone(), token, socket).await {
                // A message over the limit ends the socket, and the screen
                // would show nothing live, again at every reconnect: said.
                if e.to_string().contains("Message too long") {
                    tracing::warn!(user = ?who.user, error = %e, "live socket closed: a message over {MAX_MESSAGE} bytes");
                } else {
                    tracing::debug!(error = %e, "live socket closed");
                }
            }
        })
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ClientMessage {
    subscribe: Option<Subscribe>,
    /// Sent now and then by a screen that is on view: it keeps the session
    /// from idling out, so a wall display watching the plant stays logged
    /// in (a hidden tab does not send it).
    #[serde(default)]
    visible: Option<bool>,
}

/// How often the server says it is alive on the socket, so a client can tell
/// a frozen server from a quiet plant.
const HEARTBEAT: Duration = Duration::from_secs(1);

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct Subscribe {
    #[serde(default)]
    tags: Vec<String>,
    #[serde(default)]
    prefixes: Vec<String>,
    #[serde(default)]
    alarms: bool,
    /// With `alarms`: after the first whole list, send what changed
    /// (`alarm_changes`) instead of the whole list each time.
    #[serde(default)]
    alarm_changes: bool,
    /// With `alarms`: the version of the list the client holds. When
    /// it is the one this socket last sent, a new subscription (a screen
    /// change) goes on with the changes instead of resending the whole list.
    #[serde(default)]
    alarm_version: Option<u64>,
}

/// One tag in a `tags` message. Serialized straight from borrowed data:
/// building a `serde_json::Value` per tag per client dominated the cost of
/// fan-out (see the `ws_fanout` bench).
#[derive(Serialize)]
struct TagOut<'a> {
    name: &'a str,
    value: &'a Value,
    quality: &'a Quality,
    timestamp: Timestamp,
}

#[derive(Serialize)]
struct TagsMessage<'a> {
    #[serde(rename = "type")]
    kind: &'static str,
    snapshot: bool,
    values: Vec<TagOut<'a>>,
}

fn tags_message<'a>(
    db: &TagDb,
    samples: impl IntoIterator<Item = (&'a TagId, &'a Sample)>,
    snapshot: bool,
) -> String {
    let values = samples
        .into_iter()
        .filter_map(|(id, smp)| {
            Some(TagOut {
                name: db.meta(*id)?.name.as_ref(),
                value: &smp.value,
                quality: &smp.quality,
                timestamp: smp.timestamp,
            })
        })
        .collect();
    let msg = TagsMessage {
        kind: "tags",
        snapshot,
        values,
    };
    // Serializing plain data with string keys cannot fail.
    serde_json::to_string(&msg).unwrap_or_default()
}

/// What the socket's user may read now. Their group's screens are read
/// again at each subscription (one look-up of the user, one of the group),
/// so a change of screen access applies to an open socket when it next
/// (re)subscribes (docs/ACCESS.md). A user gone or blocked since, or a store
/// that cannot answer, reads nothing.
async fn readable_now(s: &WebState, who: &Principal) -> Readable {
    let Some(name) = who.user.as_deref() else {
        return s.readable(who);
    };
    let now = match s.store.user(name).await {
        Ok(Some(u)) if !u.blocked => Principal {
            screens: s.screens_of(&u.group, u.role).await,
            user: Some(u.name),
            role: u.role,
            group: Some(u.group),
        },
        Ok(_) => Principal::anonymous(),
        Err(e) => {
            tracing::error!(error = %e, "reading a live socket's user");
            Principal::anonymous()
        }
    };
    s.readable(&now)
}

/// A message with the current sample of every tag of `ids`.
fn snapshot_message(db: &TagDb, ids: &[TagId]) -> Utf8Bytes {
    let snap = db.snapshot(ids);
    tags_message(db, snap.changes.iter().map(|(id, s)| (id, s)), true).into()
}

/// A socket's place on a feed: the feed (kept alive by it), its tags, and
/// the receiver of its messages.
struct Joined {
    _feed: Arc<Feed>,
    ids: Arc<[TagId]>,
    rx: tokio::sync::broadcast::Receiver<Utf8Bytes>,
}

/// The next message of the socket's feed; never, without one.
async fn next_message(
    joined: &mut Option<Joined>,
) -> Result<Utf8Bytes, tokio::sync::broadcast::error::RecvError> {
    match joined {
        Some(j) => j.rx.recv().await,
        None => std::future::pending().await,
    }
}

async fn run(
    s: WebState,
    who: Principal,
    token: Option<String>,
    mut socket: WebSocket,
) -> Result<(), axum::Error> {
    use tokio::sync::broadcast::error::RecvError;
    let merge = Duration::from_millis(*s.plant.server.live_merge_ms.get_ref() as u64);
    let mut feed = None;
    let mut ended = s.auth.sessions.watch_ended();
    let mut alarms_wanted = false;
    let mut alarm_changes_wanted = false;
    let mut alarm_version = None::<u64>;
    let mut tick = tokio::time::interval(TICK);
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let mut last_heartbeat = std::time::Instant::now();

    let hello = json!({"type": "hello", "user": who.user, "role": who.role});
    socket.send(Message::Text(hello.to_string().into())).await?;

    loop {
        tokio::select! {
            msg = socket.recv() => {
                let Some(msg) = msg else { return Ok(()) };
                match msg? {
                    Message::Text(text) => match serde_json::from_str::<ClientMessage>(&text) {
                        Ok(ClientMessage { visible: Some(true), subscribe: None }) => {
                            if let Some(t) = token.as_deref() {
                                // Touches the idle timer; an ended session closes below.
                                let _ = s.auth.sessions.user(t).await;
                            }
                        }
                        Ok(ClientMessage { subscribe: Some(sub_req), .. }) => {
                            let readable = readable_now(&s, &who).await;
                            let mut ids: Vec<TagId> = sub_req.tags.iter().filter_map(|t| s.db.id(t)).collect();
                            for p in sub_req.prefixes.iter().filter(|p| !p.is_empty()) {
                                ids.extend(s.db.ids_with_prefix(p));
                            }
                            // Only what the caller's screens show (access::Readable).
                            if !readable.all() {
                                ids.retain(|id| s.db.meta(*id).is_some_and(|m| readable.may_read(&m.name)));
                            }
                            ids.sort();
                            ids.dedup();
                            let ids: Arc<[TagId]> = ids.into();
                            // Join first, then take the snapshot: a change
                            // between the two comes again in a later message.
                            let (f, rx) = s.live.join(&s.db, ids.clone(), merge);
                            let snap = snapshot_message(&s.db, &ids);
                            feed = Some(Joined { _feed: f, ids, rx });
                            // The client's list goes on if it is the one this
                            // socket last sent (None until one was sent).
                            if !sub_req.alarms || sub_req.alarm_version != alarm_version {
                                alarm_version = None;
                            }
                            alarms_wanted = sub_req.alarms;
                            alarm_changes_wanted = sub_req.alarm_changes;
                            socket.send(Message::Text(snap)).await?;
                        }
                        Ok(_) => {}
                        Err(e) => {
                            let err = json!({"type": "error", "detail": format!("bad message: {e}")});
                            socket.send(Message::Text(err.to_string().into())).await?;
                        }
                    },
                    Message::Close(_) => return Ok(()),
                    _ => {}
                }
            }
            msg = next_message(&mut feed) => match msg {
                Ok(text) => socket.send(Message::Text(text)).await?,
                Err(RecvError::Lagged(_)) => {
                    // Too slow for the feed: drop the backlog, send what
                    // holds now, and go on from here.
                    if let Some(j) = &mut feed {
                        j.rx = j.rx.resubscribe();
                        let snap = snapshot_message(&s.db, &j.ids);
                        socket.send(Message::Text(snap)).await?;
                    }
                }
                // The tag database is gone: the server is stopping.
                Err(RecvError::Closed) => return Ok(()),
            },
            _ = ended.changed() => {
                let live = token.as_deref().is_some_and(|t| s.auth.sessions.is_live(t));
                if !live {
                    let _ = socket.send(Message::Close(Some(CloseFrame { code: 4001, reason: "session ended".into() }))).await;
                    return Ok(());
                }
            }
            _ = tick.tick() => {
                if last_heartbeat.elapsed() >= HEARTBEAT {
                    last_heartbeat = std::time::Instant::now();
                    let beat = json!({"type": "heartbeat", "ts": s.clock.now()});
                    socket.send(Message::Text(beat.to_string().into())).await?;
                }
                if alarms_wanted {
                    if let Some((version, msg)) = s.live.alarm_message(&s, alarm_version, alarm_changes_wanted) {
                        alarm_version = Some(version);
                        socket.send(Message::Text(msg)).await?;
                    }
                }
                // Re-check the session now and then even without a logout event
                // (idle and absolute expiry).
                if let Some(t) = token.as_deref() {
                    if !s.auth.sessions.is_live(t) {
                        let _ = socket.send(Message::Close(Some(CloseFrame { code: 4001, reason: "session ended".into() }))).await;
                        return Ok(());
                    }
                }
            }
        }
    }
}
