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
