//! The audit trail over the full stack on PostgreSQL, with the database cut
//! in the middle of a fault-isolation sequence and an alarm flood: nothing is
//! lost, nothing is stored twice, the order is kept, the spool's figures and
//! system alarm go up and come back, and a command whose record can be
//! neither stored nor spooled is refused and never reaches the device.
//!
//! The shared PostgreSQL is never stopped: the stack reaches it through a
//! loopback TCP relay the test controls, which refuses new connections and
//! severs the open ones while the "database is down" (fault injection on the
//! real database).

use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use gridscada_config::{Plant, Role};
use gridscada_store::{AlarmHistoryFilter, EventFilter, OpenOptions, Store};
use gridscada_tagdb::{Clock, SystemClock};
use tokio::net::{TcpListener, TcpStream};
use tokio::task::JoinHandle;

use super::{web_state, Stack, StackOptions};
use crate::sinks;

/// A loopback TCP relay to the real database that can be cut and restored.
struct Relay {
    addr: std::net::SocketAddr,
    up: Arc<AtomicBool>,
    conns: Arc<Mutex<Vec<JoinHandle<()>>>>,
    _accept: JoinHandle<()>,
}

impl Relay {
    async fn start(upstream: String) -> Relay {
        let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
        let addr = listener.local_addr().unwrap();
        let up = Arc::new(AtomicBool::new(true));
        let conns: Arc<Mutex<Vec<JoinHandle<()>>>> = Arc::default();
        let (u, c) = (up.clone(), conns.clone());
        let accept = tokio::spawn(async move {
            while let Ok((mut client, _)) = listener.accept().await {
                if !u.load(Ordering::SeqCst) {
                    drop(client); // refused: the database is "down"
                    continue;
                }
                let upstream = upstream.clone();
                let task = tokio::spawn(async move {
                    if let Ok(mut server) = TcpStream::connect(&upstream).await {
                        let _ = tokio::io::copy_bidirectional(&mut client, &mut server).await;
                    }
                });
                c.lock().unwrap().push(task);
            }
        });
        Relay {
            addr,
            up,
            conns,
            _accept: accept,
        }
    }

    /// Refuses new connections and severs every open one.
    fn cut(&self) {
        self.up.store(false, Ordering::SeqCst);
        for t in self.conns.lock().unwrap().drain(..) {
            t.abort();
        }
    }

    fn restore(&self) {
        self.up.store(true, Ordering::SeqCst);
    }
}

/// `url` with its `host:port` replaced by `addr`.
fn via(url: &str, addr: std::net::SocketAddr) -> (String, String) {
    let rest = url.split_once("://").map_or(url, |(_, r)| r);
    let after_user = rest.rsplit_once('@').map_or(rest, |(_, h)| h);
    let hostport = after_user.split(['/', '?']).next().unwrap().to_string();
    let upstream = if hostport.contains(':') {
        hostport.clone()
    } else {
        format!("{hostport}:5432")
    };
    (url.replacen(&hostport, &addr.to_string(), 1), upstream)
}

async fn wait_for(what: &str, limit: Duration, mut ok: impl FnMut() -> bool) {
    let start = Instant::now();
    while !ok() {
        assert!(start.elapsed() < limit, "timed out waiting for {what}");
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

fn curl(args: &[&str]) -> (u16, String) {
    let out = std::process::Command::new("curl")
        .args(["-sS", "-o", "-", "-w", "\n%{http_code}", "--max-time", "20"])
        .args(args)
        .output()
        .expect("curl runs");
    let text = String::from_utf8_lossy(&out.stdout).to_string();
    let (body, code) = text.rsplit_once('\n').unwrap_or(("", "0"));
    (code.trim().parse().unwrap_or(0), body.to_string())
}

const FLOOD: usize = 300;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn postgres_down_during_fault_isolation_and_an_alarm_flood_loses_nothing() {
    let Ok(pg) = std::env::var("GRIDSCADA_TEST_PG_URL") else {
        assert!(
            std::env::var("GRIDSCADA_REQUIRE_PG").as_deref() != Ok("1"),
            "GRIDSCADA_REQUIRE_PG=1 but GRIDSCADA_TEST_PG_URL is not set"
        );
        use std::io::Write;
        let _ = std::io::stderr().write_all(
            b"\n!!!!!!!! SKIPPED audit trail PostgreSQL test: GRIDSCADA_TEST_PG_URL is not set !!!!!!!!\n",
        );
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let (_, upstream) = via(&pg, "127.0.0.1:1".parse().unwrap());
    let relay = Relay::start(upstream).await;
    let (url, _) = via(&pg, relay.addr);
    let mut options = OpenOptions::new(dir.path());
    options.acquire_timeout = Duration::from_secs(2);
    options.pg_schema = Some(format!(
        "audit_trail_{}_{}",
        std::process::id(),
        std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .unwrap()
            .subsec_nanos()
    ));
    let store = Store::open(&url, &options).await.unwrap();

    let tags = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tags");
    let plant: Plant = gridscada_config::load_path(&tags)
        .unwrap_or_else(|d| panic!("demo plant in {}: {d:?}", tags.display()));
    let panel = plant.panels[0].id.get_ref().clone();
    let clock: Arc<dyn Clock> = Arc::new(SystemClock);
    let stack = Stack::start(
        plant,
        store.clone(),
        StackOptions {
            clock: clock.clone(),
            simulate: true,
            real_devices: Vec::new(),
            simulator_pipes: false,
            dispatch_policy: Default::default(),
            restore_panels: false,
            data_dir: dir.path().to_path_buf(),
            notify: false,
        },
    )
    .await
    .unwrap();
    let audit = stack.audit.handle();
    let web = web_state(&stack).await;
    let (http, server) = gridscada_web::bind(
        "127.0.0.1:0".parse().unwrap(),
        gridscada_web::router(web.clone()),
        web.connections.clone(),
    )
    .await
    .unwrap();
    tokio::spawn(server);
    // An administrator logged in over HTTP before the outage.
    let password = "a-long-enough-password";
    let admin = gridscada_store::NewUser {
        name: "admin".into(),
        role: Role::Administrator,
        password_hash: gridscada_web::auth::hash_password(password.into())
            .await
            .unwrap(),
        group: "administrator".into(),
        created_at: clock.now(),
    };
    // The pool's short acquire timeout (for the outage below) can run out
    // while the stack's start writes through the same pool on a loaded
    // machine; setting up is not what this test is about, so it waits.
    let setting_up = tokio::time::Instant::now();
    while let Err(e) = store.create_user(&admin).await {
        let busy = e.to_string().contains("pool timed out");
        assert!(
            busy && setting_up.elapsed() < Duration::from_secs(60),
            "creating the administrator: {e}"
        );
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
    let jar = dir.path().join("cookies.txt");
    let jar = jar.to_str().unwrap();
    let origin = format!("Origin: http://{http}");
    let (code, body) = curl(&[
        "-c",
        jar,
        "-H",
        &origin,
        "-H",
        "Content-Type: application/json",
        "-d",
        &format!("{{\"username\":\"admin\",\"password\":\"{password}\"}}"),
        &format!("http://{http}/api/session"),
    ]);
    assert_eq!(code, 200, "login: {body}");
    // The panel's breakers read before the fault.
    tokio::time::sleep(Duration::from_secs(3)).await;

    // The database goes away in the middle of it all.
    relay.cut();
    let sim = stack.simulator.as_ref().unwrap().handle();
    sim.inject_zone_fault(&panel, 2, gridscada_sim::FaultKind::Permanent)
        .unwrap();
    for i in 0..FLOOD {
        stack
            .alarms
            .raise(
                &format!("flood:{i:03}"),
                500,
                "SYSTEM",
                &format!("Flood alarm {i:03}"),
            )
            .unwrap();
        let _ = stack
            .events
            .send(sinks::system_event(
                clock.as_ref(),
                "test",
                "flood",
                format!("flood event {i:03}"),
            ))
            .await;
    }
    for i in 0..FLOOD {
        stack.alarms.clear(&format!("flood:{i:03}")).unwrap();
    }
    wait_for("the spool in use", Duration::from_secs(20), || {
        audit.metrics().spooling && audit.metrics().pending > 0
    })
    .await;
    let spool_alarm = || {
        stack
            .alarms
            .id_of(sinks::AUDIT_SPOOL_ALARM)
            .and_then(|id| stack.alarms.view(id))
            .is_some_and(|v| v.active)
    };
    wait_for(
        "the spool's system alarm",
        Duration::from_secs(10),
        spool_alarm,
    )
    .await;
    let (code, body) = curl(&[&format!("http://{http}/metrics")]);
    assert_eq!(code, 200, "{body}");
    assert!(body.contains("gridscada_audit_spooling 1"), "{body}");
    // The control room works on through the outage: the logged-in
    // administrator keeps the rights the store last gave, and writes a tag;
    // its audit records go to the spool, and the device confirms the write.
    let tag = stack
        .plant
        .tags
        .iter()
        .find(|t| *t.writable.get_ref())
        .expect("the demo plant has a writable tag");
    let written = tag.name.get_ref().to_string();
    let value = stack.db.get(stack.db.id(&written).unwrap()).unwrap().value;
    let (code, body) = curl(&[
        "-b",
        jar,
        "-H",
        &origin,
        "-H",
        "Content-Type: application/json",
        "-d",
        &format!("{{\"value\":{}}}", serde_json::to_string(&value).unwrap()),
        &format!("http://{http}/api/tags/{written}/write"),
    ]);
    assert_eq!(code, 200, "a write during the outage: {body}");
    // And acknowledges every alarm: the operator is told it worked, and the
    // alarm states reach the store once it is back (the state sink retries).
    let (code, body) = curl(&[
        "-b",
        jar,
        "-H",
        &origin,
        "-H",
        "Content-Type: application/json",
        "-d",
        "{\"all\":true}",
        &format!("http://{http}/api/alarms/ack"),
    ]);
    assert_eq!(code, 200, "an acknowledgement during the outage: {body}");
    let acked: serde_json::Value = serde_json::from_str(&body).unwrap();
    assert!(acked["count"].as_u64().unwrap() > 0, "{body}");
    // The sequence runs on through the outage (about 10 s).
    tokio::time::sleep(Duration::from_secs(8)).await;
    relay.restore();
    wait_for("the spool replayed", Duration::from_secs(60), || {
        let m = audit.metrics();
        m.pending == 0 && !m.spooling
    })
    .await;
    wait_for("the spool's alarm cleared", Duration::from_secs(10), || {
        !spool_alarm()
    })
    .await;
    // The alarm states the store holds caught up with the engine's, the
    // acknowledgements made during the outage among them.
    let caught_up = Instant::now();
    loop {
        let engine: std::collections::HashMap<String, (bool, bool)> = stack
            .alarms
            .persisted_states()
            .into_iter()
            .map(|r| (r.key, (r.active, r.acked)))
            .collect();
        let stored: std::collections::HashMap<String, (bool, bool)> = store
            .alarm_states()
            .await
            .unwrap_or_default()
            .into_iter()
            .map(|r| (r.key, (r.active, r.acked)))
            .collect();
        let behind: Vec<_> = engine
            .iter()
            // A normal alarm never stored has nothing to catch up.
            .filter(|(k, v)| {
                (**v != (false, true) || stored.contains_key(*k)) && stored.get(*k) != Some(*v)
            })
            .collect();
        if behind.is_empty() {
            break;
        }
        assert!(
            caught_up.elapsed() < Duration::from_secs(30),
            "alarm states not stored after the outage: {behind:?}"
        );
        tokio::time::sleep(Duration::from_millis(250)).await;
    }
    let m = audit.metrics();
    eprintln!("audit trail after the outage: {m:?}");
    assert!(m.spooled > (2 * FLOOD) as u64, "{m:?}");
    assert_eq!(m.replayed, m.spooled, "{m:?}");
    assert_eq!(m.lost, 0, "{m:?}");

    // Every flood record once, in the order it was made.
    let mut events = store
        .events(&EventFilter {
            limit: 10_000,
            ..Default::default()
        })
        .await
        .unwrap();
    events.reverse(); // oldest first, by id
    let flood: Vec<&str> = events
        .iter()
        .filter(|e| e.source == "flood")
        .map(|e| e.message.as_str())
        .collect();
    let want: Vec<String> = (0..FLOOD).map(|i| format!("flood event {i:03}")).collect();
    assert_eq!(flood, want);
    let history = store
        .alarm_history(&AlarmHistoryFilter {
            limit: 10_000,
            oldest_first: true,
            ..Default::default()
        })
        .await
        .unwrap();
    let flood_all: Vec<(String, Option<String>)> = history
        .iter()
        .filter(|t| t.transition.alarm_key.starts_with("flood:"))
        .map(|t| (t.transition.alarm_key.clone(), t.transition.cause.clone()))
        .collect();
    // The acknowledgements of the outage come after (ack all), one each.
    let (flood_keys, acks): (Vec<_>, Vec<_>) = flood_all
        .into_iter()
        .partition(|(_, cause)| matches!(cause.as_deref(), Some("activate" | "return")));
    assert_eq!(
        acks.len(),
        FLOOD,
        "one acknowledgement per flood alarm: {:?}",
        &acks[..acks.len().min(5)]
    );
    let mut want: Vec<(String, Option<String>)> = (0..FLOOD)
        .map(|i| (format!("flood:{i:03}"), Some("activate".to_string())))
        .collect();
    want.extend((0..FLOOD).map(|i| (format!("flood:{i:03}"), Some("return".to_string()))));
    assert_eq!(flood_keys.len(), want.len());
    assert_eq!(flood_keys, want);
    // The write made during the outage is in the log: asked, then done.
    let writes: Vec<&str> = events
        .iter()
        .filter(|e| e.user.as_deref() == Some("admin") && e.message.contains(&written))
        .map(|e| e.kind.as_str())
        .collect();
    assert!(
        writes.len() >= 2 && writes[0] == "write_request" && writes.contains(&"write"),
        "the outage's write in the event log: {writes:?}"
    );
    // The fault-isolation sequence's records are there, once each, in time order.
    let seq: Vec<_> = events.iter().filter(|e| e.source == panel).collect();
    assert!(!seq.is_empty(), "no event of panel {panel}: {events:?}");
    assert!(seq.windows(2).all(|w| w[0].ts <= w[1].ts), "{seq:?}");
    let mut seen = std::collections::HashSet::new();
    for e in &events {
        assert!(
            seen.insert((e.ts, &e.source, &e.kind, &e.message)),
            "stored twice: {e:?}"
        );
    }
    let spool_rows: Vec<_> = history
        .iter()
        .filter(|t| t.transition.alarm_key == sinks::AUDIT_SPOOL_ALARM)
        .map(|t| t.transition.cause.clone().unwrap_or_default())
        .collect();
    assert_eq!(
        spool_rows.first().map(String::as_str),
        Some("activate"),
        "{spool_rows:?}"
    );
    assert!(spool_rows.iter().any(|c| c == "return"), "{spool_rows:?}");

    // Neither store nor spool: a command is refused and never goes out.
    // (The panel command on its handler, the tag write over HTTP with the
    // administrator's session, which outlives the outage.)
    use axum::extract::{Path as UrlPath, State};
    use axum::{Extension, Json};
    let admin = gridscada_web::auth::Principal {
        user: Some("admin".into()),
        role: Role::Administrator,
        group: Some("administrator".into()),
        screens: vec!["main".into()],
    };
    let web = web_state(&stack).await;
    let mode_before = stack.panels[0].status.borrow().mode;
    relay.cut();
    let spool_dir = dir.path().join("audit-spool");
    let _ = std::fs::remove_dir_all(&spool_dir);
    std::fs::write(&spool_dir, "the spool's place is taken").unwrap();
    let other = if format!("{mode_before:?}").to_lowercase().contains("auto") {
        "manual"
    } else {
        "auto"
    };
    let body: gridscada_web::api::panels::ModeBody =
        serde_json::from_value(serde_json::json!({ "mode": other })).unwrap();
    let refused = gridscada_web::api::panels::mode(
        State(web.clone()),
        Extension(admin.clone()),
        UrlPath(panel.clone()),
        Ok(Json(body)),
    )
    .await
    .expect_err("a panel command with no durable audit record is refused");
    assert_eq!(refused.status.as_u16(), 503, "{refused:?}");
    assert!(refused.detail.contains("audit record"), "{refused:?}");
    // A tag write likewise, before anything goes to the device. The tag is
    // one on a device no control loop is writing to (the dispatch loop
    // writes its units' setpoints every period; a panel's sequence its
    // breakers until it locks out), so any write counted on that device
    // below would be the refused command's. Quiet means no write for
    // longer than a sequence's longest wait between two commands (reclose
    // delay, dwell and confirm window), or a gap between reclose attempts
    // would pass for the end.
    let device_writes = |device: &str| {
        stack
            .poll_stats()
            .stats()
            .devices
            .iter()
            .filter(|d| d.device == device)
            .map(|d| d.writes)
            .sum::<u64>()
    };
    let quiet = stack
        .plant
        .panels
        .iter()
        .map(|p| p.reclose_delay_s.get_ref() + p.dwell_s.get_ref() + p.confirm_timeout_s.get_ref())
        .fold(2.0, f64::max);
    let writable: Vec<&gridscada_config::TagConfig> = stack
        .plant
        .tags
        .iter()
        .filter(|t| *t.writable.get_ref())
        .collect();
    assert!(!writable.is_empty(), "the demo plant has writable tags");
    let settle = Instant::now();
    let (tag, writes_before) = loop {
        let counts: Vec<u64> = writable
            .iter()
            .map(|t| device_writes(t.device.get_ref()))
            .collect();
        tokio::time::sleep(Duration::from_secs_f64(quiet + 1.0)).await;
        let quiet_tag = writable
            .iter()
            .zip(&counts)
            .find(|(t, n)| device_writes(t.device.get_ref()) == **n);
        if let Some((t, n)) = quiet_tag {
            break (*t, *n);
        }
        assert!(
            settle.elapsed() < Duration::from_secs(120),
            "every device with a writable tag is still being written to"
        );
    };
    let name = tag.name.get_ref().to_string();
    let device = tag.device.get_ref().to_string();
    let id = stack.db.id(&name).unwrap();
    let before = stack.db.get(id).unwrap();
    let (code, body) = curl(&[
        "-b",
        jar,
        "-H",
        &origin,
        "-H",
        "Content-Type: application/json",
        "-d",
        &format!(
            "{{\"value\":{}}}",
            serde_json::to_string(&before.value).unwrap()
        ),
        &format!("http://{http}/api/tags/{name}/write"),
    ]);
    assert_eq!(
        code, 503,
        "a tag write with no durable audit record: {body}"
    );
    assert!(body.contains("audit record"), "{body}");
    tokio::time::sleep(Duration::from_millis(500)).await;
    assert_eq!(stack.panels[0].status.borrow().mode, mode_before);
    assert_eq!(
        device_writes(&device),
        writes_before,
        "a write went out to device {device}"
    );
    std::fs::remove_file(&spool_dir).unwrap();
    relay.restore();
    stack.shutdown().await;
}
