//! The pieces of the full-stack tests on PostgreSQL with several servers
//! (the redundant pair, several sites on one database): a database of the
//! test's own, the demo plant's files moved to free ports, the standalone
//! simulator, a `gridscada serve` process, the operator's login.

use std::collections::HashMap;
use std::io::{BufRead, BufReader, Write};
use std::net::TcpListener;
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use serde_json::{json, Value};

use super::{gridscada, wait_for, Client};

pub const PASSWORD: &str = "a-long-enough-password";

pub fn free_port() -> u16 {
    TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// A block of `len` consecutive loopback ports for a plant's simulated
/// devices (`gridscada sim` binds them as configured): free when handed
/// out, below the kernel's ephemeral range (32768..), so no connection
/// takes one meanwhile, and distinct for every call in this test process,
/// since its tests run side by side in one binary (one pid).
pub fn port_block(len: u16) -> u16 {
    use std::sync::atomic::{AtomicU32, Ordering};
    const LOW: u32 = 20000;
    const HIGH: u32 = 32000;
    static NEXT: AtomicU32 = AtomicU32::new(0);
    // Where this process starts, so that two test runs at once rarely meet.
    let start = (std::process::id() % 60) * 200;
    for _ in 0..500 {
        let k = NEXT.fetch_add(u32::from(len), Ordering::Relaxed);
        let base = LOW + (start + k) % (HIGH - LOW);
        if base + u32::from(len) > HIGH {
            continue;
        }
        let free = (base..base + u32::from(len))
            .all(|p| std::net::TcpListener::bind(("127.0.0.1", p as u16)).is_ok());
        if free {
            return base as u16;
        }
    }
    panic!("no block of {len} free loopback ports between {LOW} and {HIGH}");
}

/// A database of its own on the test cluster, dropped at the end.
pub struct Database {
    pub base: String,
    pub name: String,
    pub url: String,
}

impl Database {
    pub fn create(base: &str) -> Database {
        let name = format!(
            "gs_pair_{}_{}",
            std::process::id(),
            SystemTime::now()
                .duration_since(UNIX_EPOCH)
                .unwrap()
                .subsec_nanos()
        );
        psql(base, &format!("CREATE DATABASE {name}"));
        let (root, _) = base.rsplit_once('/').expect("URL with a database");
        Database {
            base: base.to_string(),
            url: format!("{root}/{name}"),
            name,
        }
    }
}

impl Drop for Database {
    fn drop(&mut self) {
        psql(
            &self.base,
            &format!("DROP DATABASE IF EXISTS {} WITH (FORCE)", self.name),
        );
    }
}

/// Runs `sql` by psql with `flag` (`-q` or `-At`); fails the test on an
/// error. Returns psql's output.
fn run_psql(url: &str, flag: &str, sql: &str) -> String {
    let out = Command::new("psql")
        .arg(url)
        .args([flag, "-v", "ON_ERROR_STOP=1", "-c", sql])
        .output()
        .expect("psql");
    assert!(
        out.status.success(),
        "{sql}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

pub fn psql(url: &str, sql: &str) {
    run_psql(url, "-q", sql);
}

/// One column of a query's rows, by psql.
pub fn rows(url: &str, sql: &str) -> Vec<String> {
    run_psql(url, "-At", sql)
        .lines()
        .map(str::to_string)
        .collect()
}

/// The demo plant's files in `dir`, its devices moved to ports from
/// `port_base` (so parallel tests do not collide), on `storage`, as server
/// `name` of the pair `servers`.
pub fn write_plant(
    dir: &Path,
    storage: &str,
    name: &str,
    servers: &[(&str, u16)],
    port_base: u16,
) -> PathBuf {
    let mut extra = format!("\n[redundancy]\nname = \"{name}\"\n");
    for (s, port) in servers {
        extra.push_str(&format!(
            "[[redundancy.server]]\nname = \"{s}\"\nurl = \"http://127.0.0.1:{port}\"\n"
        ));
    }
    demo_plant(dir, storage, port_base, "", &extra)
}

/// The demo plant's files in `dir` as site `site` of a database shared with
/// other sites: a server alone, its devices moved to ports from `port_base`.
pub fn write_site_plant(dir: &Path, storage: &str, site: &str, port_base: u16) -> PathBuf {
    demo_plant(dir, storage, port_base, &format!("site = \"{site}\"\n"), "")
}

/// The demo plant's files in `dir` on `storage`, its device ports moved to
/// `port_base..`, `in_server` added at the top of its `[server]` table and
/// `appended` at the end of its main file.
fn demo_plant(
    dir: &Path,
    storage: &str,
    port_base: u16,
    in_server: &str,
    appended: &str,
) -> PathBuf {
    std::fs::create_dir_all(dir).unwrap();
    let tags = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tags");
    for entry in std::fs::read_dir(&tags).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "toml") {
            let mut text = std::fs::read_to_string(&path).unwrap();
            for p in 15000..15100u16 {
                text = text.replace(
                    &format!("127.0.0.1:{p}\""),
                    &format!("127.0.0.1:{}\"", port_base + (p - 15000)),
                );
            }
            if path.file_name().unwrap() == "gridscada.toml" {
                text = text.replace("sqlite://gridscada.db", storage);
                assert!(
                    text.contains("\n[server]\n"),
                    "the demo has a [server] table"
                );
                text = text.replacen("\n[server]\n", &format!("\n[server]\n{in_server}"), 1);
                text.push_str(appended);
            }
            std::fs::write(dir.join(path.file_name().unwrap()), text).unwrap();
        }
    }
    dir.join("gridscada.toml")
}

/// `gridscada sim` on the plant's configured addresses, with its fault
/// injection on standard input.
pub struct Sim {
    pub child: Child,
    pub stdin: ChildStdin,
    pub answers: mpsc::Receiver<String>,
}

impl Sim {
    pub fn start(config: &Path, log: &Path) -> Sim {
        let log = std::fs::File::create(log).unwrap();
        let mut child = gridscada()
            .arg("sim")
            .arg("--config")
            .arg(config)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::from(log))
            .spawn()
            .unwrap();
        let stdin = child.stdin.take().unwrap();
        let stdout = child.stdout.take().unwrap();
        let (tx, answers) = mpsc::channel();
        std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines() {
                let Ok(line) = line else { return };
                let _ = tx.send(line);
            }
        });
        Sim {
            child,
            stdin,
            answers,
        }
    }

    pub fn cmd(&mut self, line: &str) {
        writeln!(self.stdin, "{line}").unwrap();
        let answer = self
            .answers
            .recv_timeout(Duration::from_secs(10))
            .unwrap_or_else(|_| panic!("the simulator did not answer '{line}'"));
        assert_eq!(answer, "ok", "{line}");
    }
}

impl Drop for Sim {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// One server of the pair.
pub struct Server {
    pub name: &'static str,
    pub config: PathBuf,
    pub port: u16,
    pub log: PathBuf,
    pub child: Option<Child>,
}

impl Server {
    pub fn addr(&self) -> String {
        format!("127.0.0.1:{}", self.port)
    }

    pub fn start(&mut self) {
        let log = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(&self.log)
            .unwrap();
        let mut child = gridscada()
            .args(["--log-json", "serve", "--config"])
            .arg(&self.config)
            .args(["--http", &self.addr()])
            .env("RUST_LOG", "info")
            .stdout(Stdio::piped())
            .stderr(Stdio::from(log))
            .spawn()
            .unwrap();
        let stdout = child.stdout.take().unwrap();
        let (tx, rx) = mpsc::channel();
        std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines().map_while(Result::ok) {
                if line.contains("HMI and API") {
                    let _ = tx.send(());
                }
            }
        });
        rx.recv_timeout(Duration::from_secs(60))
            .unwrap_or_else(|_| {
                panic!(
                    "server {} did not start: {}",
                    self.name,
                    super::tail(&self.log)
                )
            });
        self.child = Some(child);
    }

    pub fn pid(&self) -> u32 {
        self.child.as_ref().expect("running").id()
    }

    pub fn kill9(&mut self) {
        if let Some(mut c) = self.child.take() {
            let _ = c.kill();
            let _ = c.wait();
        }
    }

    pub fn signal(&self, sig: &str) {
        let ok = Command::new("kill")
            .args([sig, &self.pid().to_string()])
            .status()
            .unwrap()
            .success();
        assert!(ok, "kill {sig}");
    }

    /// `gridscada_pair_active` from its `/metrics` (None: no answer).
    pub fn active(&self) -> Option<bool> {
        let mut c = Client::new(&self.addr());
        let (status, body) = c.try_request("GET", "/metrics", None).ok()?;
        if status != 200 {
            return None;
        }
        let text = body.as_str()?.to_string();
        let line = text
            .lines()
            .find(|l| l.starts_with("gridscada_pair_active "))?;
        let value: f64 = line.rsplit(' ').next()?.parse().ok()?;
        Some(value == 1.0)
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        self.kill9();
    }
}

pub fn login(addr: &str) -> Client {
    let mut c = Client::new(addr);
    let (status, body) = c.post(
        "/api/session",
        json!({"username": "op", "password": PASSWORD}),
    );
    assert_eq!(status, 200, "{body}");
    c
}

/// Adds the operator `op` (password [`PASSWORD`]) to the database of the
/// plant at `config`.
pub fn add_operator(config: &Path) {
    let mut add = gridscada()
        .args(["user", "add", "op", "--role", "operator", "--config"])
        .arg(config)
        .stdin(Stdio::piped())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    add.stdin
        .take()
        .unwrap()
        .write_all(format!("{PASSWORD}\n").as_bytes())
        .unwrap();
    let out = add.wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// One Modbus write as the writer logged it.
#[derive(Debug, Clone)]
pub struct FieldWrite {
    pub t: f64,
    pub server: String,
    pub epoch: u64,
    pub tag: String,
    pub value: String,
}

/// RFC 3339 UTC (`2026-11-26T02:29:29.123456Z`) to seconds since 1970.
pub fn rfc3339(s: &str) -> Option<f64> {
    let (date, time) = s.trim_end_matches('Z').split_once('T')?;
    let mut d = date.split('-').map(|x| x.parse::<i64>());
    let (y, m, day) = (d.next()?.ok()?, d.next()?.ok()?, d.next()?.ok()?);
    // Days from civil (Howard Hinnant's algorithm).
    let y = if m <= 2 { y - 1 } else { y };
    let era = y.div_euclid(400);
    let yoe = y - era * 400;
    let doy = (153 * (m + if m > 2 { -3 } else { 9 }) + 2) / 5 + day - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    let days = era * 146097 + doe - 719468;
    let mut t = time.split(':');
    let (h, mi, sec) = (
        t.next()?.parse::<f64>().ok()?,
        t.next()?.parse::<f64>().ok()?,
        t.next()?.parse::<f64>().ok()?,
    );
    Some(days as f64 * 86400.0 + h * 3600.0 + mi * 60.0 + sec)
}

/// Every field write in the servers' logs, in time order.
pub fn field_writes(logs: &[&Path]) -> Vec<FieldWrite> {
    let mut out = Vec::new();
    for log in logs {
        let text = std::fs::read_to_string(log).unwrap_or_default();
        for line in text.lines() {
            let Ok(v) = serde_json::from_str::<Value>(line) else {
                continue;
            };
            if v["target"] != "gridscada::field_write" {
                continue;
            }
            let f = &v["fields"];
            out.push(FieldWrite {
                t: rfc3339(v["timestamp"].as_str().unwrap_or("")).expect("timestamp"),
                server: f["server"].as_str().unwrap_or("").to_string(),
                epoch: f["epoch"].as_u64().expect("epoch"),
                tag: f["tag"].as_str().unwrap_or("").to_string(),
                value: f["value"].to_string().trim_matches('"').to_string(),
            });
        }
    }
    out.sort_by(|a, b| a.t.total_cmp(&b.t));
    out
}

/// Waits until exactly one of the pair is active; its index and how long
/// that took.
pub fn wait_active(servers: &[&Server], limit: Duration) -> (usize, Duration) {
    let start = Instant::now();
    loop {
        let active: Vec<usize> = servers
            .iter()
            .enumerate()
            .filter(|(_, s)| s.child.is_some() && s.active() == Some(true))
            .map(|(i, _)| i)
            .collect();
        if active.len() == 1 {
            return (active[0], start.elapsed());
        }
        assert!(
            start.elapsed() < limit,
            "no single active server after {limit:?}: {active:?}"
        );
        std::thread::sleep(Duration::from_millis(25));
    }
}

/// The fencing as the write record shows it: each epoch belongs to one
/// server, and no write of an older epoch follows one of a newer epoch (so
/// two servers never commanded the plant at once). How many epochs wrote.
pub fn assert_fenced(writes: &[FieldWrite]) -> usize {
    let mut owner: HashMap<u64, &str> = HashMap::new();
    for w in writes {
        let o = owner.entry(w.epoch).or_insert(&w.server);
        assert_eq!(*o, w.server, "epoch {} used by two servers: {w:?}", w.epoch);
    }
    let mut newest = 0;
    for w in writes {
        assert!(
            w.epoch >= newest,
            "a write of epoch {} after one of epoch {newest}: {w:?}",
            w.epoch
        );
        newest = w.epoch;
    }
    owner.len()
}

/// Waits until `panel` on the server at `c` has finished with its fault:
/// isolated (faulty zones known, not running) or locked out.
pub fn settled(c: &mut Client, panel: &str, limit: Duration) -> Value {
    wait_for(&format!("{panel} to isolate or lock out"), limit, || {
        let (s, p) = c
            .try_request("GET", &format!("/api/panels/{panel}"), None)
            .ok()?;
        (s == 200
            && (p["lockout"] == true
                || (p["step"] == "isolated" && !p["faulty_zones"].as_array()?.is_empty())))
        .then_some(p)
    })
}

/// Repairs the zones, resets the panels on the active server and waits
/// until they are idle again.
pub fn recover(c: &mut Client, sim: &mut Sim, faults: &[(&str, u64)]) {
    for (panel, zone) in faults {
        sim.cmd(&format!("repair {panel} {zone}"));
    }
    for (panel, _) in faults {
        wait_for(&format!("{panel} reset"), Duration::from_secs(30), || {
            let (s, _) = c
                .try_request(
                    "POST",
                    &format!("/api/panels/{panel}/reset"),
                    Some(json!({})),
                )
                .ok()?;
            if s != 200 {
                return None;
            }
            let (_, p) = c
                .try_request("GET", &format!("/api/panels/{panel}"), None)
                .ok()?;
            (p["step"] == "idle" && p["lockout"] == false && p["faulty_zones"] == json!([]))
                .then_some(())
        });
    }
}

/// Waits until `panel` reads its ELCB, its MCCB and every zone but
/// `faulty` closed (and `faulty` open), all Good; its status then. `what`
/// names the run in the failure.
pub fn healthy_zones_on(
    c: &mut Client,
    panel: &str,
    faulty: u64,
    what: &str,
    limit: Duration,
) -> Value {
    wait_for(
        &format!("{what}: {panel}'s healthy zones on"),
        limit,
        || {
            let (s, q) = c
                .try_request("GET", &format!("/api/panels/{panel}"), None)
                .ok()?;
            let b = &q["breakers"];
            let on = |name: &str| b[name]["closed"] == true && b[name]["good"] == true;
            let zones = q["zones"].as_u64()?;
            (s == 200
                && on("elcb")
                && on("mccb")
                && (1..=zones).all(|z| on(&format!("zone{z}")) == (z != faulty)))
            .then_some(q)
        },
    )
}
