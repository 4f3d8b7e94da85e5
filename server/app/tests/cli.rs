//! CLI smoke tests: `check` on good and broken plants, and `demo` serving /healthz.

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
    let (status, body) = http_get(&addr, "/healthz");
    assert_eq!(status, 200, "{body}");
    assert!(body.contains("\"status\":\"ok\""), "{body}");
    assert!(data.path().exists());
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
