//! Shared helpers of the full-stack tests: start `gridscada demo` on an
//! ephemeral port, log in with the generated accounts, and talk to the API
//! with a minimal blocking HTTP/1.1 client (no extra dependencies: one
//! request per connection, JSON bodies, the session cookie kept by hand).
//!
//! Owns nothing of the product; must not reach into the server other than
//! through its command line, its data folder and its HTTP API.

#![allow(dead_code)] // Each test binary uses a different subset.

pub mod pair;

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use serde_json::Value;

pub const BIN: &str = env!("CARGO_BIN_EXE_gridscada");

/// The binary with none of the test process's own `GRIDSCADA_*` variables,
/// so a test's settings come only from what it passes.
pub fn gridscada() -> Command {
    let mut c = Command::new(BIN);
    for (k, _) in std::env::vars() {
        if k.starts_with("GRIDSCADA_") {
            c.env_remove(k);
        }
    }
    c
}

/// A running `gridscada demo`. Dropping it kills the process (SIGKILL).
pub struct Demo {
    child: Option<Child>,
    pub addr: String,
    pub data: PathBuf,
}

impl Demo {
    /// Starts the demo with its data in `data`, logging to `log` (appended),
    /// and waits for it to print its URL.
    pub fn start(data: &Path, log: &Path) -> Demo {
        Demo::start_with(data, log, &[])
    }

    /// Like [`Demo::start`], with more arguments (e.g. `--config PLANT`).
    pub fn start_with(data: &Path, log: &Path, args: &[&std::ffi::OsStr]) -> Demo {
        let log_file = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(log)
            .expect("opening the demo's log file");
        let mut child = Command::new(BIN)
            .args(["demo", "--http", "127.0.0.1:0", "--data"])
            .arg(data)
            .args(args)
            .env("RUST_LOG", "info")
            .stdout(Stdio::piped())
            .stderr(Stdio::from(log_file))
            .spawn()
            .expect("spawning gridscada demo");
        let stdout = child.stdout.take().expect("demo stdout");
        let mut demo = Demo {
            child: Some(child),
            addr: String::new(),
            data: data.to_path_buf(),
        };
        let (tx, rx) = std::sync::mpsc::channel();
        // Reads the banner, then keeps draining stdout so the demo never blocks on it.
        std::thread::spawn(move || {
            let mut sent = false;
            for line in BufReader::new(stdout).lines() {
                let Ok(line) = line else { break };
                if !sent {
                    if let Some(rest) = line.split("http://").nth(1) {
                        let addr = rest.trim_end_matches('/').split('/').next().unwrap_or("");
                        let _ = tx.send(addr.to_string());
                        sent = true;
                    }
                }
            }
        });
        match rx.recv_timeout(Duration::from_secs(60)) {
            Ok(addr) => demo.addr = addr,
            Err(_) => panic!(
                "the demo did not print its URL within 60 s; log: {}",
                tail(log)
            ),
        }
        demo
    }

    /// The demo's process id.
    pub fn pid(&self) -> u32 {
        self.child.as_ref().map(|c| c.id()).unwrap_or(0)
    }

    /// `kill -9`: no shutdown, no flush, nothing.
    pub fn kill9(&mut self) {
        if let Some(mut c) = self.child.take() {
            // std's Child::kill is SIGKILL on Unix.
            c.kill().expect("SIGKILL to the demo");
            let status = c.wait().expect("reaping the demo");
            assert!(!status.success(), "the demo exited cleanly: {status:?}");
        }
    }

    /// `ROLE USERNAME PASSWORD` lines of `credentials.txt` (rewritten at every start).
    pub fn credentials(&self) -> Vec<(String, String, String)> {
        let text = std::fs::read_to_string(self.data.join("credentials.txt"))
            .expect("reading credentials.txt");
        text.lines()
            .filter_map(|l| {
                let mut w = l.split_whitespace();
                Some((
                    w.next()?.to_string(),
                    w.next()?.to_string(),
                    w.next()?.to_string(),
                ))
            })
            .collect()
    }

    /// A client logged in with the generated account of `role`.
    pub fn login(&self, role: &str) -> Client {
        let (_, user, password) = self
            .credentials()
            .into_iter()
            .find(|(r, _, _)| r == role)
            .unwrap_or_else(|| panic!("no {role} account in credentials.txt"));
        let mut c = Client::new(&self.addr);
        let (status, body) = c.post(
            "/api/session",
            serde_json::json!({"username": user, "password": password}),
        );
        assert_eq!(status, 200, "login as {user}: {body}");
        assert!(c.cookie.is_some(), "login as {user} set no cookie");
        c.user = user;
        c
    }
}

impl Drop for Demo {
    fn drop(&mut self) {
        if let Some(mut c) = self.child.take() {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

/// The last lines of a log file, for failure messages.
pub fn tail(path: &Path) -> String {
    let text = std::fs::read_to_string(path).unwrap_or_default();
    let lines: Vec<&str> = text.lines().collect();
    lines[lines.len().saturating_sub(30)..].join("\n")
}

/// A blocking API client: one connection per request.
#[derive(Clone)]
pub struct Client {
    pub addr: String,
    pub cookie: Option<String>,
    /// The user name it logged in as.
    pub user: String,
}

/// Why a request got no HTTP answer (e.g. the server was killed).
#[derive(Debug)]
pub struct NoAnswer(pub String);

impl Client {
    pub fn new(addr: &str) -> Client {
        Client {
            addr: addr.to_string(),
            cookie: None,
            user: String::new(),
        }
    }

    pub fn get(&mut self, path: &str) -> (u16, Value) {
        self.request("GET", path, None)
    }

    pub fn post(&mut self, path: &str, body: Value) -> (u16, Value) {
        self.request("POST", path, Some(body))
    }

    pub fn delete(&mut self, path: &str) -> (u16, Value) {
        self.request("DELETE", path, None)
    }

    /// GET that must answer 200.
    pub fn get_ok(&mut self, path: &str) -> Value {
        let (status, body) = self.get(path);
        assert_eq!(status, 200, "GET {path}: {body}");
        body
    }

    pub fn request(&mut self, method: &str, path: &str, body: Option<Value>) -> (u16, Value) {
        self.try_request(method, path, body)
            .unwrap_or_else(|e| panic!("{method} {path}: {}", e.0))
    }

    /// A request that reports a dead server instead of panicking.
    pub fn try_request(
        &mut self,
        method: &str,
        path: &str,
        body: Option<Value>,
    ) -> Result<(u16, Value), NoAnswer> {
        let fail = |what: &str, e: std::io::Error| NoAnswer(format!("{what}: {e}"));
        let mut s = TcpStream::connect(&self.addr).map_err(|e| fail("connect", e))?;
        s.set_read_timeout(Some(Duration::from_secs(20)))
            .map_err(|e| fail("set timeout", e))?;
        let payload = body.map(|b| b.to_string()).unwrap_or_default();
        let mut head = format!(
            "{method} {path} HTTP/1.1\r\nHost: {}\r\nConnection: close\r\nContent-Length: {}\r\n",
            self.addr,
            payload.len()
        );
        if !payload.is_empty() {
            head.push_str("Content-Type: application/json\r\n");
        }
        if let Some(c) = &self.cookie {
            head.push_str(&format!("Cookie: {c}\r\n"));
            // As a browser does: a logged-in change names its origin.
            if method != "GET" {
                head.push_str(&format!("Origin: http://{}\r\n", self.addr));
            }
        }
        head.push_str("\r\n");
        s.write_all(head.as_bytes())
            .and_then(|_| s.write_all(payload.as_bytes()))
            .map_err(|e| fail("send", e))?;
        let mut raw = Vec::new();
        s.read_to_end(&mut raw).map_err(|e| fail("receive", e))?;
        let split = raw
            .windows(4)
            .position(|w| w == b"\r\n\r\n")
            .ok_or_else(|| NoAnswer(format!("incomplete response ({} bytes)", raw.len())))?;
        let head = String::from_utf8_lossy(&raw[..split]).to_string();
        let mut rest = raw[split + 4..].to_vec();
        let status: u16 = head
            .split_whitespace()
            .nth(1)
            .and_then(|s| s.parse().ok())
            .ok_or_else(|| NoAnswer(format!("bad status line in {head:?}")))?;
        let mut chunked = false;
        for line in head.lines().skip(1) {
            let Some((name, value)) = line.split_once(':') else {
                continue;
            };
            let (name, value) = (name.trim().to_ascii_lowercase(), value.trim());
            if name == "set-cookie" {
                let pair = value.split(';').next().unwrap_or("").trim();
                // A cleared cookie (logout) has an empty value.
                if pair.ends_with('=') {
                    self.cookie = None;
                } else {
                    self.cookie = Some(pair.to_string());
                }
            } else if name == "transfer-encoding" && value.eq_ignore_ascii_case("chunked") {
                chunked = true;
            }
        }
        if chunked {
            rest = dechunk(&rest).ok_or_else(|| NoAnswer("bad chunked body".into()))?;
        }
        let body = if rest.is_empty() {
            Value::Null
        } else {
            serde_json::from_slice(&rest)
                .unwrap_or_else(|_| Value::String(String::from_utf8_lossy(&rest).to_string()))
        };
        Ok((status, body))
    }
}

fn dechunk(mut b: &[u8]) -> Option<Vec<u8>> {
    let mut out = Vec::new();
    loop {
        let eol = b.windows(2).position(|w| w == b"\r\n")?;
        let size_text = std::str::from_utf8(&b[..eol]).ok()?;
        let size = usize::from_str_radix(size_text.split(';').next()?.trim(), 16).ok()?;
        b = &b[eol + 2..];
        if size == 0 {
            return Some(out);
        }
        out.extend_from_slice(b.get(..size)?);
        b = b.get(size + 2..)?;
    }
}

/// Polls `f` every 100 ms until it gives `Some`, or panics after `timeout`
/// saying what was awaited.
pub fn wait_for<T>(what: &str, timeout: Duration, mut f: impl FnMut() -> Option<T>) -> T {
    let deadline = Instant::now() + timeout;
    loop {
        if let Some(v) = f() {
            return v;
        }
        if Instant::now() > deadline {
            panic!("timed out after {timeout:?} waiting for {what}");
        }
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// Every alarm (all states), by the summary API.
pub const ALL_STATES: &str =
    "normal,unack_active,ack_active,unack_rtn,shelved,suppressed,out_of_service";

/// The alarm with `key`, in any state.
pub fn alarm(c: &mut Client, key: &str) -> Value {
    let list = c.get_ok(&format!("/api/alarms?state={ALL_STATES}"));
    list["alarms"]
        .as_array()
        .and_then(|a| a.iter().find(|x| x["key"] == key).cloned())
        .unwrap_or_else(|| panic!("no alarm '{key}' in the summary"))
}

/// The keys of the ordinary (default) alarm list.
pub fn default_list(c: &mut Client) -> Vec<Value> {
    c.get_ok("/api/alarms")["alarms"]
        .as_array()
        .cloned()
        .unwrap_or_default()
}

/// The newest `limit` events, newest first.
pub fn events(c: &mut Client, query: &str) -> Vec<Value> {
    c.get_ok(&format!("/api/events?{query}"))["events"]
        .as_array()
        .cloned()
        .unwrap_or_default()
}

/// Milliseconds since the epoch, wall time (the demo runs on the system clock).
pub fn now_ms() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_millis() as i64)
        .unwrap_or(0)
}

/// The tests that kill, freeze or restart servers and time their failovers
/// and recoveries in seconds run one at a time: since all integration tests
/// share one binary, two of them would otherwise run side by side on CI's two
/// cores, and each one's timing bounds assume the machine is not also
/// running another pair's failovers. Other tests still run beside them.
pub fn kill_test_lock() -> std::sync::MutexGuard<'static, ()> {
    static LOCK: std::sync::Mutex<()> = std::sync::Mutex::new(());
    // A failed test poisons the lock; the next one still runs.
    LOCK.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
}
