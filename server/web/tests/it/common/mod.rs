//! A small web stack for the integration tests: a three-tag plant, a temp
//! SQLite store, one user per role, a fake field writer and (optionally) a fake
//! simulator, driven in-process through `tower::ServiceExt::oneshot`. The
//! alarm engine runs, with its events and history stored, on request
//! ([`Harness::run_alarms`]).
//!
//! Owns nothing outside the tests; it builds `WebState` exactly as the app does
//! (`server/app/src/runtime.rs::web_state`) but with fakes behind it.

#![allow(dead_code)] // each test binary uses a different part

use std::collections::HashMap;
use std::future::Future;
use std::net::SocketAddr;
use std::path::Path;
use std::sync::Arc;
use std::time::{Duration, Instant};

use axum::body::Body;
use axum::extract::ConnectInfo;
use axum::http::{header, HeaderMap, Method, Request, StatusCode};
use axum::Router;
use gridscada_alarms::{AlarmChannels, AlarmEngine, EngineOptions};
use gridscada_config::Role;
use gridscada_store::{NewEvent, NewUser, OpenOptions, Store};
use gridscada_tagdb::{
    Quality, Sample, SystemClock, TagDb, TagWriter, Timestamp, Value, WriteError, WriteFuture,
};
use gridscada_web::api::sim::{FaultKind, SimControl};
use gridscada_web::auth::{self, SessionPolicy};
use gridscada_web::{Auth, Components, WebState};
use http_body_util::BodyExt;
use parking_lot::Mutex;
use serde_json::Value as Json;
use tower::ServiceExt;

/// The password of every test user (meets the strength rule).
pub const PASSWORD: &str = "correct horse battery";
/// The Host every request carries, and so the only same origin.
pub const HOST: &str = "scada.test";

/// Test tags: one read-only measurement, one setpoint an operator may write,
/// one a supervisor must write (within engineering limits of -50 to 50 kW).
pub const TAG_RO: &str = "T.Feeder1.P_kW";
pub const TAG_OP: &str = "T.Zone1.Reset";
pub const TAG_SUP: &str = "T.BESS.Setpoint_kW";

/// Group `east` may write zone 1's tags whatever its screens show.
const MAIN: &str = "tag_files = [\"tags.toml\"]\n[server]\nallowed_hosts = [\"scada.test\"]\n\
                    [server.access.east]\nwrite = [\"T.Zone1.*\"]\n";
const TAGS: &str = r#"
[[device]]
name = "D1"
protocol = "tcp"
address = "127.0.0.1:1502"

[[tag]]
name = "T.Feeder1.P_kW"
description = "Feeder 1 active power"
device = "D1"
kind = "input_register"
address = 0
type = "f32"
units = "kW"

[[tag]]
name = "T.Zone1.Reset"
description = "Zone 1 reset coil"
device = "D1"
kind = "coil"
address = 0
writable = true
write_role = "operator"

[[tag]]
name = "T.BESS.Setpoint_kW"
description = "Battery power setpoint"
device = "D1"
kind = "holding_register"
address = 0
type = "f32"
units = "kW"
writable = true
write_role = "supervisor"
min = -50.0
max = 50.0
"#;

/// A writer that takes every write and reports it back as confirmed, except
/// one outside the tag's engineering limits, which it refuses before it
/// reaches the "device" (`writes`), as the field writer does.
#[derive(Default)]
pub struct FakeWriter {
    /// What reached the device.
    pub writes: Mutex<Vec<(String, Value)>>,
    /// Engineering limits by tag (`Plant::write_limits`).
    pub limits: HashMap<String, (Option<f64>, Option<f64>)>,
}

impl FakeWriter {
    /// A writer with the engineering limits of `plant`'s tags.
    pub fn for_plant(plant: &gridscada_config::Plant) -> FakeWriter {
        let limits = plant
            .tags
            .iter()
            .map(|t| t.name.get_ref().clone())
            .map(|n| {
                let l = plant.write_limits(&n);
                (n, l)
            })
            .filter(|(_, l)| *l != (None, None))
            .collect();
        FakeWriter {
            limits,
            ..FakeWriter::default()
        }
    }
}

impl TagWriter for FakeWriter {
    fn write<'a>(&'a self, name: &'a str, value: Value) -> WriteFuture<'a> {
        Box::pin(async move {
            if name.is_empty() {
                return Err(WriteError::UnknownTag(name.into()));
            }
            if let (Some(&(lo, hi)), Some(v)) = (self.limits.get(name), value.as_f64()) {
                if v.is_nan() || lo.is_some_and(|lo| v < lo) || hi.is_some_and(|hi| v > hi) {
                    return Err(WriteError::OutOfLimits {
                        tag: name.into(),
                        value: value.to_string(),
                        limits: format!("{lo:?} to {hi:?}"),
                    });
                }
            }
            self.writes.lock().push((name.to_string(), value.clone()));
            Ok(Sample::good(value, Timestamp::now_utc()))
        })
    }
}

/// A simulator with one panel "ss1" (zones 1..=4) and one device "D1".
#[derive(Default)]
pub struct FakeSim {
    pub calls: Mutex<Vec<String>>,
}

impl SimControl for FakeSim {
    fn inject_fault(&self, panel: &str, zone: u8, kind: FaultKind) -> Result<(), String> {
        if panel != "ss1" {
            return Err(format!("unknown panel '{panel}'"));
        }
        if !(1..=4).contains(&zone) {
            return Err(format!("zone {zone} is out of range 1..=4"));
        }
        self.calls
            .lock()
            .push(format!("fault {panel} {zone} {kind:?}"));
        Ok(())
    }
    fn repair(&self, panel: &str, zone: u8) -> Result<(), String> {
        if panel != "ss1" {
            return Err(format!("unknown panel '{panel}'"));
        }
        self.calls.lock().push(format!("repair {panel} {zone}"));
        Ok(())
    }
    fn set_offline(&self, device: &str, offline: bool) -> Result<(), String> {
        if device != "D1" {
            return Err(format!("unknown device '{device}'"));
        }
        self.calls
            .lock()
            .push(format!("offline {device} {offline}"));
        Ok(())
    }
}

pub struct Options {
    pub sim: bool,
    pub policy: SessionPolicy,
    /// The database: a temp SQLite file by default, or a fresh schema in
    /// the PostgreSQL database at this URL.
    pub postgres: Option<String>,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            sim: true,
            policy: SessionPolicy::default(),
            postgres: None,
        }
    }
}

/// The PostgreSQL test database (`GRIDSCADA_TEST_PG_URL`), or `None` with a
/// loud notice: the PostgreSQL variant of `test` is skipped. Fails instead
/// when `GRIDSCADA_REQUIRE_PG=1`.
pub fn pg_url(test: &str) -> Option<String> {
    match std::env::var("GRIDSCADA_TEST_PG_URL") {
        Ok(u) if !u.is_empty() => Some(u),
        _ => {
            assert!(
                std::env::var("GRIDSCADA_REQUIRE_PG").as_deref() != Ok("1"),
                "{test}: GRIDSCADA_REQUIRE_PG=1 but GRIDSCADA_TEST_PG_URL is not set"
            );
            use std::io::Write;
            let _ = std::io::stderr().write_all(
                format!(
                    "\n!!!!!!!! SKIPPED PostgreSQL variant of {test}: GRIDSCADA_TEST_PG_URL is not set !!!!!!!!\n"
                )
                .as_bytes(),
            );
            None
        }
    }
}

pub struct Harness {
    pub app: Router,
    pub state: WebState,
    pub writer: Arc<FakeWriter>,
    pub sim: Arc<FakeSim>,
    /// The alarm engine's transitions and events, until [`Harness::run_alarms`]
    /// takes them into the store.
    alarm_outputs: Mutex<Option<AlarmOutputs>>,
    /// How the store was opened, so [`Harness::restart`] opens it again.
    store_url: String,
    store_options: OpenOptions,
    policy: SessionPolicy,
    _dir: tempfile::TempDir,
}

type AlarmOutputs = (
    tokio::sync::mpsc::Receiver<gridscada_alarms::AlarmTransition>,
    tokio::sync::mpsc::Receiver<gridscada_alarms::Event>,
);

/// A response, read whole.
#[derive(Debug)]
pub struct Resp {
    pub status: StatusCode,
    pub headers: HeaderMap,
    pub body: Vec<u8>,
}

impl Resp {
    pub fn json(&self) -> Json {
        serde_json::from_slice(&self.body).unwrap_or_else(|e| {
            panic!(
                "not JSON ({e}): {} {:?}",
                self.status,
                String::from_utf8_lossy(&self.body)
            )
        })
    }
    pub fn text(&self) -> String {
        String::from_utf8_lossy(&self.body).into_owned()
    }
    pub fn content_type(&self) -> &str {
        self.headers
            .get(header::CONTENT_TYPE)
            .and_then(|v| v.to_str().ok())
            .unwrap_or("")
    }
    /// The session cookie this response sets, as a `Cookie` header value.
    pub fn session_cookie(&self) -> Option<String> {
        let set = self.headers.get(header::SET_COOKIE)?.to_str().ok()?;
        let pair = set.split(';').next()?.trim();
        (pair.starts_with(auth::COOKIE) && pair.len() > auth::COOKIE.len() + 1)
            .then(|| pair.to_string())
    }
}

/// The test plant, loaded through the real configuration loader.
pub fn plant() -> gridscada_config::Plant {
    let read = |p: &Path| -> std::io::Result<String> {
        match p.file_name().and_then(|f| f.to_str()) {
            Some("gridscada.toml") => Ok(MAIN.into()),
            Some("tags.toml") => Ok(TAGS.into()),
            _ => Err(std::io::ErrorKind::NotFound.into()),
        }
    };
    gridscada_config::load_with(Path::new("/test/gridscada.toml"), &read)
        .unwrap_or_else(|d| panic!("test plant does not load: {d:?}"))
}

impl Harness {
    pub async fn new(opts: Options) -> Harness {
        let dir = tempfile::tempdir().expect("temp dir");
        let mut store_options = OpenOptions::new(dir.path());
        let store_url = match &opts.postgres {
            None => "sqlite://test.db".to_string(),
            Some(url) => {
                store_options.pg_schema = Some(format!(
                    "gs_webtest_{}_{}",
                    std::process::id(),
                    rand::random::<u32>()
                ));
                url.clone()
            }
        };
        let store = Store::open(&store_url, &store_options)
            .await
            .expect("open store");
        store.migrate().await.expect("migrate");
        let plant = plant();
        let db = Arc::new(TagDb::new(plant.tag_metas()).expect("tag db"));
        let now = Timestamp::now_utc();
        for (id, _) in db.all_meta().collect::<Vec<_>>() {
            db.apply([(
                id,
                Sample {
                    value: Value::Float(1.5),
                    quality: Quality::GOOD,
                    timestamp: now,
                },
            )]);
        }
        // The alarm engine (no alarms configured): its channels' receivers
        // live as long as the harness.
        let (ttx, trx) = tokio::sync::mpsc::channel(1024);
        let (etx, erx) = tokio::sync::mpsc::channel(1024);
        let alarms = AlarmEngine::new(
            &plant,
            db.clone(),
            Arc::new(SystemClock),
            AlarmChannels {
                transitions: ttx,
                events: etx,
                states: None,
            },
            &[],
            EngineOptions::default(),
        )
        .expect("alarm engine");
        let writer = Arc::new(FakeWriter::for_plant(&plant));
        let sim = Arc::new(FakeSim::default());
        let state = WebState {
            db,
            plant: Arc::new(plant),
            auth: Auth::new(opts.policy.clone(), false, store.clone()).await,
            store,
            audit: None,
            clock: Arc::new(SystemClock),
            writer: Some(writer.clone() as Arc<dyn TagWriter>),
            started: Instant::now(),
            components: Components {
                alarms: Some(alarms),
                ..Components::default()
            },
            sim: opts.sim.then(|| sim.clone() as Arc<dyn SimControl>),
            http_metrics: Default::default(),
            metrics: None,
            screens: Default::default(),
            devices: None,
            tls: false,
            live: Default::default(),
            connections: Default::default(),
        };
        let h = Harness {
            app: gridscada_web::router(state.clone()),
            state,
            writer,
            sim,
            alarm_outputs: Mutex::new(Some((trx, erx))),
            store_url,
            store_options,
            policy: opts.policy,
            _dir: dir,
        };
        for role in Role::ALL {
            h.add_user(role.label(), role, role.label()).await;
        }
        h
    }

    /// As a restart of the server: the store opened again on the same
    /// database, fresh sessions state (nothing cached, activity not yet
    /// written is lost as in a crash), a new app over them.
    pub async fn restart(&mut self) {
        let store = Store::open(&self.store_url, &self.store_options)
            .await
            .expect("reopen store");
        self.state = WebState {
            auth: Auth::new(self.policy.clone(), false, store.clone()).await,
            store,
            ..self.state.clone()
        };
        self.app = gridscada_web::router(self.state.clone());
    }

    /// The same database opened by another handle, as another process
    /// (`gridscada user`, a second server) would open it.
    pub async fn another_store(&self) -> Store {
        Store::open(&self.store_url, &self.store_options)
            .await
            .expect("open the store again")
    }

    /// A second server on the same database: its own store handle and
    /// sessions (nothing cached), the same plant and fakes.
    pub async fn another_server(&self) -> Router {
        let store = self.another_store().await;
        gridscada_web::router(WebState {
            auth: Auth::new(self.policy.clone(), false, store.clone()).await,
            store,
            ..self.state.clone()
        })
    }

    /// Drops the PostgreSQL test schema, if any.
    pub async fn cleanup(self) {
        if let Some(schema) = &self.store_options.pg_schema {
            self.state.store.close().await;
            // With psql, the real client: the web crate speaks no SQL.
            let out = std::process::Command::new("psql")
                .arg(&self.store_url)
                .args([
                    "-q",
                    "-c",
                    &format!("DROP SCHEMA IF EXISTS {schema} CASCADE"),
                ])
                .output();
            if !out.as_ref().is_ok_and(|o| o.status.success()) {
                eprintln!("test schema {schema} not dropped: {out:?}");
            }
        }
    }

    /// Runs the alarm engine, with its operator events going to the event log
    /// and its transitions to the alarm history, as the app's sinks carry
    /// them (`server/app/src/sinks.rs`). Call once.
    pub fn run_alarms(&self) {
        let engine = self.state.components.alarms.clone().expect("alarm engine");
        let (mut transitions, mut events) = self
            .alarm_outputs
            .lock()
            .take()
            .expect("run_alarms is called once");
        tokio::spawn(engine.run());
        let store = self.state.store.clone();
        tokio::spawn(async move {
            while let Some(e) = events.recv().await {
                let e = NewEvent {
                    ts: e.time,
                    user: e.user,
                    source: e.source,
                    kind: e.kind.as_str().to_string(),
                    message: e.message,
                };
                store
                    .insert_events(&[e])
                    .await
                    .expect("record an alarm event");
            }
        });
        let store = self.state.store.clone();
        tokio::spawn(async move {
            while let Some(t) = transitions.recv().await {
                store
                    .insert_alarm_transitions(&[(&t).into()])
                    .await
                    .expect("record an alarm transition");
            }
        });
    }

    /// The app over the harness's state with `change` made to its plant
    /// (e.g. `[server]` settings), for [`send_to`].
    pub fn app_with_plant(&self, change: impl FnOnce(&mut gridscada_config::Plant)) -> Router {
        let mut plant = (*self.state.plant).clone();
        change(&mut plant);
        gridscada_web::router(WebState {
            plant: Arc::new(plant),
            ..self.state.clone()
        })
    }

    /// Serves the app on a loopback port (for real sockets); its address.
    pub async fn serve(&self) -> SocketAddr {
        let (addr, server) = gridscada_web::bind(
            "127.0.0.1:0".parse().unwrap(),
            self.app.clone(),
            self.state.connections.clone(),
        )
        .await
        .unwrap();
        tokio::spawn(server);
        addr
    }

    /// Creates a user directly in the store (as `gridscada demo` does).
    pub async fn add_user(&self, name: &str, role: Role, group: &str) {
        let hash = auth::hash_password(PASSWORD.into()).await.expect("hash");
        self.state
            .store
            .create_user(&NewUser {
                name: name.into(),
                role,
                password_hash: hash,
                group: group.into(),
                created_at: Timestamp::now_utc(),
            })
            .await
            .expect("create user");
    }

    /// Sends a request from 127.0.0.1 and reads the whole answer.
    pub async fn send(&self, req: Request<Body>) -> Resp {
        self.send_from(req, "127.0.0.1:40000".parse().unwrap())
            .await
    }

    pub async fn send_from(&self, req: Request<Body>, peer: SocketAddr) -> Resp {
        send_to(&self.app, req, peer).await
    }

    /// A JSON call as a browser on the same origin would make it.
    pub async fn call(
        &self,
        method: Method,
        path: &str,
        cookie: Option<&str>,
        body: Option<Json>,
    ) -> Resp {
        self.send(request(method, path, cookie, body)).await
    }

    /// Logs in and returns the `Cookie` header value.
    pub async fn login(&self, user: &str, password: &str) -> String {
        let r = self
            .call(
                Method::POST,
                "/api/session",
                None,
                Some(serde_json::json!({"username": user, "password": password})),
            )
            .await;
        assert_eq!(r.status, StatusCode::OK, "login as {user}: {}", r.text());
        r.session_cookie().expect("login sets the session cookie")
    }
}

/// Sends a request to `app` from `peer` and reads the whole answer.
pub async fn send_to(app: &Router, mut req: Request<Body>, peer: SocketAddr) -> Resp {
    req.extensions_mut().insert(ConnectInfo(peer));
    let resp = app.clone().oneshot(req).await.expect("infallible");
    let (parts, body) = resp.into_parts();
    let body = body.collect().await.expect("body").to_bytes().to_vec();
    Resp {
        status: parts.status,
        headers: parts.headers,
        body,
    }
}

/// Polls `check` every 20 ms until it gives a value; panics naming `what`
/// after `within`.
pub async fn eventually<T, F>(what: &str, within: Duration, mut check: impl FnMut() -> F) -> T
where
    F: Future<Output = Option<T>>,
{
    let deadline = Instant::now() + within;
    loop {
        if let Some(v) = check().await {
            return v;
        }
        assert!(Instant::now() < deadline, "not within {within:?}: {what}");
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}

/// Builds a request with the test Host, an optional cookie and JSON body.
pub fn request(
    method: Method,
    path: &str,
    cookie: Option<&str>,
    body: Option<Json>,
) -> Request<Body> {
    let mut b = Request::builder()
        .method(method)
        .uri(path)
        .header(header::HOST, HOST);
    if let Some(c) = cookie {
        b = b.header(header::COOKIE, c);
        // A browser names its origin on every change (see routes::check_origin).
        if !matches!(method_of(&b), Some(m) if m == Method::GET || m == Method::HEAD) {
            b = b.header(header::ORIGIN, format!("http://{HOST}"));
        }
    }
    match body {
        Some(j) => b
            .header(header::CONTENT_TYPE, "application/json")
            .body(Body::from(j.to_string()))
            .unwrap(),
        None => b.body(Body::empty()).unwrap(),
    }
}

fn method_of(b: &axum::http::request::Builder) -> Option<Method> {
    b.method_ref().cloned()
}

/// Percent-encodes one path segment (everything but unreserved characters).
pub fn seg(s: &str) -> String {
    s.bytes()
        .map(|b| {
            if b.is_ascii_alphanumeric() || b"-._~".contains(&b) {
                (b as char).to_string()
            } else {
                format!("%{b:02X}")
            }
        })
        .collect()
}

/// A live socket.
#[allow(dead_code)]
pub type LiveSocket =
    tokio_tungstenite::WebSocketStream<tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>>;

/// The next message of a live socket as JSON, skipping heartbeats; a close
/// as `{"closed": code}`; `None` when the socket ends. Panics after 5 s of
/// silence.
#[allow(dead_code)]
pub async fn next_message(ws: &mut LiveSocket) -> Option<Json> {
    use futures::StreamExt;
    use tokio_tungstenite::tungstenite::Message;
    loop {
        let msg = tokio::time::timeout(Duration::from_secs(5), ws.next())
            .await
            .expect("a message within 5 s")?
            .ok()?;
        match msg {
            Message::Text(t) => {
                let v: Json = serde_json::from_str(&t).expect("JSON message");
                if v["type"] == "heartbeat" {
                    continue;
                }
                return Some(v);
            }
            Message::Close(frame) => {
                return Some(serde_json::json!({"closed": frame.map(|f| u16::from(f.code))}));
            }
            _ => continue,
        }
    }
}

/// Opens `/api/live` on `addr` with the session `cookie`, from our own origin.
#[allow(dead_code)]
pub async fn live_socket(
    addr: SocketAddr,
    cookie: &str,
) -> Result<LiveSocket, tokio_tungstenite::tungstenite::Error> {
    use tokio_tungstenite::tungstenite::client::IntoClientRequest;
    let mut req = format!("ws://{addr}/api/live").into_client_request()?;
    req.headers_mut().insert("cookie", cookie.parse().unwrap());
    req.headers_mut()
        .insert("origin", format!("http://{addr}").parse().unwrap());
    tokio_tungstenite::connect_async(req)
        .await
        .map(|(ws, _)| ws)
}
