//! CLI smoke tests: `check` on good and broken plants, and `demo` serving
//! /healthz; `/metrics`, `/healthz` and `/readyz` of a running server.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

const BIN: &str = env!("CARGO_BIN_EXE_gridscada");

fn repo() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

#[test]
fn check_accepts_the_demo_plant() {
    let out = Command::new(BIN)
        .arg("check")
        .arg(repo().join("tags"))
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "stdout: {stdout}\nstderr: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(stdout.contains("ok ("), "{stdout}");
}

#[test]
fn check_reports_located_errors_and_fails() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("gridscada.toml"),
        "tag_files = [\"t.toml\"]\n",
    )
    .unwrap();
    std::fs::write(
        dir.path().join("t.toml"),
        "[[device]]\nname = \"D1\"\nprotocol = \"tcp\"\naddress = \"127.0.0.1:1502\"\n\n[[tag]]\nname = \"X\"\ndevice = \"D2\"\nkind = \"coil\"\naddress = 0\n",
    )
    .unwrap();
    let out = Command::new(BIN)
        .arg("check")
        .arg(dir.path())
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("t.toml:8:10: error: tag 'X': unknown device 'D2'"),
        "{stderr}"
    );
    assert!(stderr.contains("1 problem(s) found"), "{stderr}");
}

#[test]
fn serve_refuses_a_broken_configuration() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("gridscada.toml"),
        "tag_files = [\"missing.toml\"]\n",
    )
    .unwrap();
    let out = Command::new(BIN)
        .args(["serve", "--config"])
        .arg(dir.path())
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("not starting"), "{stderr}");
    assert!(stderr.contains("missing.toml': no such file"), "{stderr}");
}

struct Demo(Child);
impl Drop for Demo {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Starts `gridscada demo` on an ephemeral port and returns the HTTP address it printed.
fn start_demo(data: &std::path::Path) -> (Demo, String) {
    let mut child = Command::new(BIN)
        .args(["demo", "--http", "127.0.0.1:0", "--data"])
        .arg(data)
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let stdout = child.stdout.take().unwrap();
    let demo = Demo(child);
    let mut lines = BufReader::new(stdout).lines();
    let deadline = Instant::now() + Duration::from_secs(60);
    while Instant::now() < deadline {
        let Some(Ok(line)) = lines.next() else { break };
        if let Some(rest) = line.split("http://").nth(1) {
            let addr = rest
                .trim_end_matches('/')
                .split('/')
                .next()
                .unwrap()
                .to_string();
            std::thread::spawn(move || for _ in lines {});
            return (demo, addr);
        }
    }
    panic!("demo did not print its URL");
}

fn http_get(addr: &str, path: &str) -> (u16, String) {
    let mut s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    write!(
        s,
        "GET {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n"
    )
    .unwrap();
    let mut resp = String::new();
    s.read_to_string(&mut resp).unwrap();
    let status = resp.split_whitespace().nth(1).unwrap().parse().unwrap();
    let body = resp
        .split("\r\n\r\n")
        .nth(1)
        .unwrap_or_default()
        .to_string();
    (status, body)
}

#[test]
fn demo_serves_healthz() {
    let data = tempfile::tempdir().unwrap();
    let (_demo, addr) = start_demo(data.path());
    // Every simulated device answers within moments of the start.
    let deadline = Instant::now() + Duration::from_secs(30);
    loop {
        let (status, body) = http_get(&addr, "/healthz");
        assert_eq!(status, 200, "{body}");
        if body.contains("\"status\":\"ok\"") {
            assert!(body.contains("\"not_good\":[]"), "{body}");
            assert!(body.contains("\"historian\":{\"queued\":"), "{body}");
            break;
        }
        assert!(Instant::now() < deadline, "never ok: {body}");
        std::thread::sleep(Duration::from_millis(200));
    }
    let (status, body) = http_get(&addr, "/readyz");
    assert_eq!((status, body.as_str()), (200, "ready\n"));
    assert!(data.path().exists());
}

/// The value of the first sample line starting with `prefix`.
fn sample(text: &str, prefix: &str) -> Option<f64> {
    text.lines()
        .find(|l| l.starts_with(prefix))
        .and_then(|l| l.rsplit(' ').next())
        .and_then(|v| v.parse().ok())
}

/// Each family is declared once (`# HELP` then `# TYPE`), and all its
/// samples follow it before the next family begins.
fn assert_grouped(text: &str) {
    let mut declared = std::collections::HashSet::new();
    let mut current: Option<(String, String)> = None;
    for line in text.lines() {
        if line == "# EOF" {
            continue;
        }
        if let Some(rest) = line.strip_prefix("# HELP ") {
            let name = rest.split(' ').next().unwrap().to_string();
            assert!(declared.insert(name.clone()), "{name} declared twice");
            current = Some((name, String::new()));
        } else if let Some(rest) = line.strip_prefix("# TYPE ") {
            let mut parts = rest.split(' ');
            let (name, kind) = (parts.next().unwrap(), parts.next().unwrap());
            let cur = current.as_mut().expect("TYPE after HELP");
            assert_eq!(cur.0, name, "TYPE of {name} without its HELP");
            assert!(cur.1.is_empty(), "{name}: TYPE twice");
            cur.1 = kind.to_string();
        } else {
            let (family, kind) = current.as_ref().expect("a sample before any family");
            let name = line.split(['{', ' ']).next().unwrap();
            let suffixes: &[&str] = match kind.as_str() {
                "counter" => &["_total", "_created"],
                "histogram" => &["_bucket", "_sum", "_count", "_created"],
                _ => &[""],
            };
            assert!(
                suffixes.iter().any(|s| name == format!("{family}{s}")),
                "{name} is not a sample of {family} ({kind}): its family is interleaved"
            );
        }
    }
    assert!(text.ends_with("# EOF\n"));
}

#[test]
fn demo_metrics_are_grouped_with_latency_and_round_trips() {
    let data = tempfile::tempdir().unwrap();
    let (_demo, addr) = start_demo(data.path());
    for _ in 0..3 {
        assert_eq!(http_get(&addr, "/healthz").0, 200);
        assert_eq!(http_get(&addr, "/api/alarms").0, 401);
    }
    // The poller answers within moments; wait for a few round trips.
    let deadline = Instant::now() + Duration::from_secs(30);
    let text = loop {
        let (status, text) = http_get(&addr, "/metrics");
        assert_eq!(status, 200, "{text}");
        let polled = text
            .lines()
            .filter(|l| l.starts_with("gridscada_poll_round_trip_seconds_count{"))
            .filter_map(|l| l.rsplit(' ').next()?.parse::<u64>().ok())
            .sum::<u64>();
        if polled >= 10 {
            break text;
        }
        assert!(Instant::now() < deadline, "no Modbus round trips:\n{text}");
        std::thread::sleep(Duration::from_millis(200));
    };
    assert_grouped(&text);
    for family in [
        "gridscada_build_info",
        "gridscada_uptime_seconds",
        "gridscada_http_requests",
        "gridscada_http_request_duration_seconds",
        "gridscada_poll_requests",
        "gridscada_poll_round_trip_seconds",
        "gridscada_historian_buffered",
        "process_cpu_seconds",
        "process_resident_memory_bytes",
        "process_virtual_memory_bytes",
        "process_open_fds",
        "process_max_fds",
        "process_start_time_seconds",
    ] {
        assert!(
            text.contains(&format!("# TYPE {family} ")),
            "{family} missing:\n{text}"
        );
    }
    assert!(
        text.contains(&format!(
            "gridscada_build_info{{version=\"{}\"",
            env!("CARGO_PKG_VERSION")
        )),
        "{text}"
    );
    // Latency by route template, method and status class.
    let healthz = "gridscada_http_request_duration_seconds_count{route=\"/healthz\",method=\"GET\",status=\"2xx\"}";
    assert!(sample(&text, healthz).unwrap() >= 3.0, "{text}");
    let refused = "gridscada_http_request_duration_seconds_count{route=\"/api/alarms\",method=\"GET\",status=\"4xx\"}";
    assert_eq!(sample(&text, refused), Some(3.0), "{text}");
    // Each bucket series ends in +Inf holding every observation.
    let inf = "gridscada_http_request_duration_seconds_bucket{le=\"+Inf\",route=\"/healthz\",method=\"GET\",status=\"2xx\"}";
    assert_eq!(sample(&text, inf), sample(&text, healthz), "{text}");
}

#[test]
fn serve_without_its_devices_is_live_and_ready_but_degraded() {
    let dir = tempfile::tempdir().unwrap();
    let config = plant_in(dir.path());
    // No simulators: every device of the plant is a closed port.
    let mut child = Command::new(BIN)
        .args(["serve", "--http", "127.0.0.1:0", "--config"])
        .arg(&config)
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let stdout = child.stdout.take().unwrap();
    let _server = Demo(child);
    let mut lines = BufReader::new(stdout).lines().map_while(Result::ok);
    let addr = lines
        .find_map(|l| {
            let rest = l.split("HMI and API: http://").nth(1)?;
            Some(rest.trim_end_matches('/').to_string())
        })
        .expect("serve printed its address");
    // Read on, so the server never writes into a closed pipe.
    std::thread::spawn(move || for _ in lines {});
    let (status, body) = http_get(&addr, "/healthz");
    assert_eq!(status, 200, "{body}");
    assert!(body.contains("\"status\":\"degraded\""), "{body}");
    assert!(body.contains("\"database\":\"ok\""), "{body}");
    assert!(body.contains("\"field_io\":{\"good\":0,"), "{body}");
    assert!(body.contains("\"not_good\":[\""), "{body}");
    let (status, body) = http_get(&addr, "/readyz");
    assert_eq!((status, body.as_str()), (200, "ready\n"));
    // `serve` runs a real plant: no Simulation panel, and its API says why.
    let (status, body) = http_get(&addr, "/api/sim/state");
    assert_eq!(status, 404, "{body}");
    assert!(body.contains("only in `gridscada demo`"), "{body}");
}

/// A copy of the demo plant whose data folder is inside `dir`.
fn plant_in(dir: &std::path::Path) -> std::path::PathBuf {
    for f in std::fs::read_dir(repo().join("tags")).unwrap() {
        let f = f.unwrap().path();
        std::fs::copy(&f, dir.join(f.file_name().unwrap())).unwrap();
    }
    let main = dir.join("gridscada.toml");
    let text = std::fs::read_to_string(&main).unwrap().replace(
        "data_dir = \"data\"",
        &format!("data_dir = \"{}\"", dir.join("data").display()),
    );
    std::fs::write(&main, text).unwrap();
    main
}

fn user_add(config: &std::path::Path, name: &str, role: &str, stdin: &str) -> std::process::Output {
    let mut child = Command::new(BIN)
        .args(["user", "add", name, "--role", role, "--config"])
        .arg(config)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // The command may refuse its arguments and exit before it reads a byte;
    // the write then meets a closed pipe, which is not the test's concern.
    match child.stdin.take().unwrap().write_all(stdin.as_bytes()) {
        Ok(()) => {}
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => {}
        Err(e) => panic!("writing the password to `user add`: {e}"),
    }
    child.wait_with_output().unwrap()
}

#[test]
fn user_add_reads_or_generates_the_password() {
    let dir = tempfile::tempdir().unwrap();
    let config = plant_in(dir.path());
    // Piped: used as given, never printed.
    let out = user_add(&config, "alice", "operator", "a-long-enough-password\n");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout} {}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        stdout.contains("Created user 'alice' (operator)."),
        "{stdout}"
    );
    assert!(!stdout.contains("a-long-enough-password"));
    // Nothing on stdin: one is generated and shown once.
    let out = user_add(&config, "bob", "administrator", "");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success());
    assert!(stdout.contains("Password (shown once): "), "{stdout}");
    // A weak password, a taken name and an unknown role are refused.
    let out = user_add(&config, "carol", "operator", "short\n");
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("at least 10 characters"));
    let out = user_add(&config, "alice", "operator", "another-good-password\n");
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("already exists"));
    let out = user_add(&config, "dave", "root", "another-good-password\n");
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("'root' is not a role"));
}
