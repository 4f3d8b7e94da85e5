//! Bench: live-push fan-out over `/api/live`.
//!
//! N tags change at 1 Hz each (applied to the tag database in ten batches a
//! second, as a poller with many devices would), pushed to C WebSocket clients
//! subscribed to every tag over real loopback sockets. Each value is the wall
//! time of its change in microseconds, so a client measures change-to-receipt
//! latency directly. Reports p50/p99/max latency, values received, and the
//! process's CPU share (server and clients share the process: the clients' JSON
//! parsing is the same work in both runs).
//!
//! Peer, in the same run: a plain fan-out without our subscription layer: one
//! task serializes each batch once (same JSON shape) into a tokio broadcast
//! channel, and each socket forwards the text as it comes.
//!
//! Run: `cargo run --release -p gridscada-web --example ws_fanout -- [TAGS] [CLIENTS] [SECONDS]`
//! (defaults 10000 100 15).

mod bench_state;

use std::net::SocketAddr;
use std::sync::Arc;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use axum::extract::ws::{Message, WebSocket, WebSocketUpgrade};
use axum::extract::State;
use axum::response::Response;
use axum::routing::get;
use axum::Router;
use futures::{SinkExt, StreamExt};
use gridscada_tagdb::{Sample, TagDb, TagId, TagMeta, Timestamp, ValueKind};
use parking_lot::Mutex;
use serde_json::json;
use tokio::sync::broadcast;
use tokio_tungstenite::tungstenite::client::IntoClientRequest;
use tokio_tungstenite::tungstenite::Message as WsMessage;

/// Latency histogram in 100 µs buckets up to 60 s.
struct Histogram {
    buckets: Vec<u64>,
    count: u64,
    max_us: u64,
}

const BUCKET_US: u64 = 100;

impl Histogram {
    fn new() -> Self {
        Histogram {
            buckets: vec![0; 600_001],
            count: 0,
            max_us: 0,
        }
    }
    fn add(&mut self, us: u64) {
        let i = ((us / BUCKET_US) as usize).min(self.buckets.len() - 1);
        self.buckets[i] += 1;
        self.count += 1;
        self.max_us = self.max_us.max(us);
    }
    fn quantile_ms(&self, q: f64) -> f64 {
        let target = (self.count as f64 * q).ceil() as u64;
        let mut seen = 0;
        for (i, n) in self.buckets.iter().enumerate() {
            seen += n;
            if seen >= target.max(1) {
                return (i as u64 * BUCKET_US + BUCKET_US / 2) as f64 / 1000.0;
            }
        }
        f64::NAN
    }
}

fn now_us() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .unwrap_or_default()
        .as_micros() as u64
}

/// User + system CPU seconds of this process, from /proc/self/stat.
fn cpu_seconds() -> f64 {
    let Ok(stat) = std::fs::read_to_string("/proc/self/stat") else {
        return f64::NAN;
    };
    // Fields after the parenthesised command name; utime and stime are 14 and 15.
    let rest = stat.rsplit_once(')').map(|(_, r)| r).unwrap_or("");
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks = |i: usize| {
        f.get(i)
            .and_then(|v| v.parse::<f64>().ok())
            .unwrap_or(f64::NAN)
    };
    // f[0] is field 3 (state), so field n is f[n - 3]. Linux USER_HZ is 100.
    (ticks(11) + ticks(12)) / 100.0
}

/// The peer: serialize once, broadcast text to every socket.
async fn peer_upgrade(
    State(tx): State<broadcast::Sender<Arc<str>>>,
    ws: WebSocketUpgrade,
) -> Response {
    let rx = tx.subscribe();
    ws.on_upgrade(move |socket| peer_socket(socket, rx))
}

async fn peer_socket(mut socket: WebSocket, mut rx: broadcast::Receiver<Arc<str>>) {
    loop {
        match rx.recv().await {
            Ok(text) => {
                if socket
                    .send(Message::Text(text.as_ref().into()))
                    .await
                    .is_err()
                {
                    return;
                }
            }
            Err(broadcast::error::RecvError::Lagged(_)) => continue,
            Err(_) => return,
        }
    }
}

fn peer_publisher(db: Arc<TagDb>, tx: broadcast::Sender<Arc<str>>) {
    let mut sub = db.subscribe_all();
    tokio::spawn(async move {
        while let Some(update) = sub.recv().await {
            let values: Vec<_> = update
                .batch()
                .changes
                .iter()
                .map(|(id, s)| {
                    json!({
                        "name": db.meta(*id).map(|m| m.name.to_string()).unwrap_or_default(),
                        "value": s.value, "quality": s.quality, "timestamp": s.timestamp,
                    })
                })
                .collect();
            let msg = json!({"type": "tags", "snapshot": update.is_snapshot(), "values": values});
            let _ = tx.send(msg.to_string().into());
        }
    });
}

struct Run {
    hist: Arc<Mutex<Histogram>>,
    measuring: Arc<std::sync::atomic::AtomicBool>,
}

/// Client `k`: from loopback address 127.0.0.(2 + k / 32), as the server
/// allows 64 live sockets per address (and 8 per session: the caller gives
/// each client a cookie of its own session group).
async fn client(k: usize, url: String, cookie: Option<String>, subscribe: bool, run: Arc<Run>) {
    let mut req = url.clone().into_client_request().expect("request");
    if let Some(c) = cookie {
        req.headers_mut().insert("cookie", c.parse().unwrap());
        // A logged-in socket must say where it comes from, as a browser does.
        let origin = url.replace("ws://", "http://");
        let origin = &origin[..origin.find("/api").unwrap_or(origin.len())];
        req.headers_mut().insert("origin", origin.parse().unwrap());
    }
    let host = req.uri().authority().expect("host").as_str().to_string();
    let server: SocketAddr = host.parse().expect("server address");
    let socket = tokio::net::TcpSocket::new_v4().expect("socket");
    socket
        .bind(SocketAddr::from(([127, 0, 0, 2 + (k / 32) as u8], 0)))
        .expect("bind a loopback source address");
    let stream = socket.connect(server).await.expect("tcp connect");
    let (mut ws, _) = tokio_tungstenite::client_async(req, stream)
        .await
        .expect("connect");
    if subscribe {
        let sub = json!({"subscribe": {"prefixes": ["B."]}}).to_string();
        ws.send(WsMessage::Text(sub.into()))
            .await
            .expect("subscribe");
    }
    let mut local = Vec::with_capacity(4096);
    while let Some(Ok(msg)) = ws.next().await {
        let WsMessage::Text(text) = msg else { continue };
        let received = now_us();
        // Snapshots carry old values: not a change.
        if !text.contains("\"type\":\"tags\"") || text.contains("\"snapshot\":true") {
            continue;
        }
        if !run.measuring.load(std::sync::atomic::Ordering::Relaxed) {
            continue;
        }
        // A scan rather than a full JSON parse, so that the clients (which
        // share the process) cost as little as possible.
        local.clear();
        for (at, _) in text.match_indices("\"value\":") {
            let rest = &text[at + 8..];
            let end = rest.find([',', '}']).unwrap_or(rest.len());
            if let Ok(sent) = rest[..end].parse::<f64>() {
                local.push(received.saturating_sub(sent as u64));
            }
        }
        let mut h = run.hist.lock();
        for us in &local {
            h.add(*us);
        }
    }
}

/// Ten batches a second, each changing a tenth of the tags: every tag once a second.
fn producer(db: Arc<TagDb>, ids: Vec<TagId>, stop: Arc<std::sync::atomic::AtomicBool>) {
    tokio::spawn(async move {
        let slices = 10;
        let per = ids.len().div_ceil(slices);
        let mut tick = tokio::time::interval(Duration::from_millis(100));
        let mut k = 0;
        while !stop.load(std::sync::atomic::Ordering::Relaxed) {
            tick.tick().await;
            let part = &ids[(k % slices) * per..((k % slices + 1) * per).min(ids.len())];
            let t = now_us();
            let ts = Timestamp::now_utc();
            db.apply(part.iter().map(|id| (*id, Sample::good(t as f64, ts))));
            k += 1;
        }
    });
}

async fn measure(
    name: &str,
    url: String,
    cookies: Option<Vec<String>>,
    subscribe: bool,
    clients: usize,
    secs: u64,
    tags: usize,
) {
    let run = Arc::new(Run {
        hist: Arc::new(Mutex::new(Histogram::new())),
        measuring: Arc::new(false.into()),
    });
    let mut handles = vec![];
    for k in 0..clients {
        handles.push(tokio::spawn(client(
            k,
            url.clone(),
            cookies.as_ref().map(|c| c[k / 8 % c.len()].clone()),
            subscribe,
            run.clone(),
        )));
    }
    tokio::time::sleep(Duration::from_secs(3)).await; // connect, snapshot, settle
    let cpu0 = cpu_seconds();
    let t0 = Instant::now();
    run.measuring
        .store(true, std::sync::atomic::Ordering::Relaxed);
    tokio::time::sleep(Duration::from_secs(secs)).await;
    run.measuring
        .store(false, std::sync::atomic::Ordering::Relaxed);
    let wall = t0.elapsed().as_secs_f64();
    let cpu = cpu_seconds() - cpu0;
    for h in handles {
        h.abort();
    }
    let h = run.hist.lock();
    let expected = (tags * clients) as f64 * wall;
    println!(
        "{name:<34} p50 {:>7.1} ms  p99 {:>7.1} ms  max {:>7.1} ms  values {:>9} ({:>5.1}% of {:.0})  CPU {:>5.1}% of one core",
        h.quantile_ms(0.50),
        h.quantile_ms(0.99),
        h.max_us as f64 / 1000.0,
        h.count,
        100.0 * h.count as f64 / expected,
        expected,
        100.0 * cpu / wall,
    );
}

#[tokio::main]
async fn main() {
    let args: Vec<usize> = std::env::args()
        .skip(1)
        .map(|a| a.parse().expect("arguments: TAGS CLIENTS SECONDS"))
        .collect();
    let tags = args.first().copied().unwrap_or(10_000);
    let clients = args.get(1).copied().unwrap_or(100);
    let secs = args.get(2).copied().unwrap_or(15) as u64;
    println!(
        "ws_fanout: {tags} tags at 1 Hz (10 batches/s), {clients} clients, {secs} s measured per run, {} CPUs, live_merge_ms {}",
        std::thread::available_parallelism().map_or(0, |n| n.get()),
        std::env::var("LIVE_MERGE_MS").unwrap_or_else(|_| "default".into())
    );

    let db = Arc::new(
        TagDb::new((0..tags).map(|i| TagMeta::new(format!("B.T{i:05}"), ValueKind::Float)))
            .expect("tag db"),
    );
    let ids: Vec<TagId> = (0..tags).map(|i| TagId(i as u32)).collect();
    let dir = tempfile::tempdir().expect("temp dir");
    let (state, cookie) = bench_state::web_state(db.clone(), dir.path()).await;
    // A session per 8 clients (the server's cap per session).
    let mut cookies = vec![cookie];
    for _ in 0..clients.div_ceil(8) {
        let token = state
            .auth
            .sessions
            .create(
                "bench",
                gridscada_config::Role::Operator,
                None,
                Default::default(),
            )
            .await
            .expect("session");
        cookies.push(format!("{}={token}", gridscada_web::auth::COOKIE));
    }

    let any: SocketAddr = "127.0.0.1:0".parse().unwrap();
    let (addr, server) = gridscada_web::bind(any, gridscada_web::router(state), Default::default())
        .await
        .expect("bind");
    tokio::spawn(server);

    let (tx, _) = broadcast::channel::<Arc<str>>(64);
    let peer = Router::new()
        .route("/peer", get(peer_upgrade))
        .with_state(tx.clone());
    let (peer_addr, peer_server) = gridscada_web::bind(any, peer, Default::default())
        .await
        .expect("bind peer");
    tokio::spawn(peer_server);

    let stop = Arc::new(std::sync::atomic::AtomicBool::new(false));
    producer(db.clone(), ids, stop.clone());

    measure(
        "gridscada /api/live",
        format!("ws://{addr}/api/live"),
        Some(cookies),
        true,
        clients,
        secs,
        tags,
    )
    .await;
    tokio::time::sleep(Duration::from_secs(1)).await;
    peer_publisher(db.clone(), tx);
    measure(
        "peer: broadcast + serialize once",
        format!("ws://{peer_addr}/peer"),
        None,
        false,
        clients,
        secs,
        tags,
    )
    .await;
    stop.store(true, std::sync::atomic::Ordering::Relaxed);
}
