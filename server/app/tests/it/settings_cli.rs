//! Where `serve`, `check` and `user add --config` take their settings from:
//! the configuration's folder for relative paths, the `GRIDSCADA_*`
//! environment over the file, and `serve --http/--data` over both; and
//! `check`'s warning about a plaintext password in the file.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use crate::common;

use common::gridscada;

/// A small plant in `dir/conf/`: one device nobody answers for, one tag;
/// `server` and `storage` are appended to the main file.
fn plant(dir: &Path, extra: &str) -> PathBuf {
    let conf = dir.join("conf");
    std::fs::create_dir_all(&conf).unwrap();
    std::fs::write(
        conf.join("gridscada.toml"),
        format!("tag_files = [\"tags.toml\"]\n{extra}"),
    )
    .unwrap();
    std::fs::write(
        conf.join("tags.toml"),
        "[[device]]\nname = \"D1\"\nprotocol = \"tcp\"\naddress = \"127.0.0.1:9\"\n\n\
         [[tag]]\nname = \"A.Volts\"\ndevice = \"D1\"\nkind = \"input_register\"\naddress = 0\ntype = \"f32\"\n",
    )
    .unwrap();
    conf
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

#[test]
fn check_warns_about_a_plaintext_password_and_still_passes() {
    let dir = tempfile::tempdir().unwrap();
    let conf = plant(
        dir.path(),
        "\n[storage]\nurl = \"postgres://scada:s3cret@db.example/scada\"\n",
    );
    let out = gridscada().arg("check").arg(&conf).output().unwrap();
    let (stdout, stderr) = (text(&out.stdout), text(&out.stderr));
    assert!(out.status.success(), "{stdout}\n{stderr}");
    assert!(stdout.contains("ok ("), "{stdout}");
    let want = format!(
        "{}:4:7: warning: [storage] url holds a plaintext password",
        conf.join("gridscada.toml").display()
    );
    assert!(stderr.contains(&want), "{stderr}");
    assert!(stderr.contains("GRIDSCADA_STORAGE_PASSWORD"), "{stderr}");
    assert!(!stderr.contains("s3cret") && !stdout.contains("s3cret"));
    // Without the password in the file: no warning.
    let conf = plant(
        dir.path(),
        "\n[storage]\nurl = \"postgres://scada@db.example/scada\"\n",
    );
    let out = gridscada().arg("check").arg(&conf).output().unwrap();
    assert!(out.status.success());
    assert!(
        !text(&out.stderr).contains("warning"),
        "{}",
        text(&out.stderr)
    );
}

#[test]
fn check_applies_the_environment_and_names_a_bad_variable() {
    let dir = tempfile::tempdir().unwrap();
    let conf = plant(dir.path(), "");
    let out = gridscada()
        .arg("check")
        .arg(&conf)
        .env("GRIDSCADA_HTTP", "0.0.0.0:8443")
        .env("GRIDSCADA_DATA_DIR", "/var/lib/gridscada")
        .output()
        .unwrap();
    let stdout = text(&out.stdout);
    assert!(out.status.success(), "{stdout}\n{}", text(&out.stderr));
    assert!(
        stdout.contains("settings from the environment: GRIDSCADA_HTTP, GRIDSCADA_DATA_DIR"),
        "{stdout}"
    );
    let out = gridscada()
        .arg("check")
        .arg(&conf)
        .env("GRIDSCADA_HTTP", "scada.example:https")
        .env("GRIDSCADA_STORAGE_PASSWORD", "hunter2")
        .output()
        .unwrap();
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("environment: error: GRIDSCADA_HTTP (replacing [server] http): 'scada.example:https' is not an address"),
        "{stderr}"
    );
    assert!(
        stderr.contains("environment: error: GRIDSCADA_STORAGE_PASSWORD"),
        "{stderr}"
    );
    assert!(!stderr.contains("hunter2"), "{stderr}");
    assert!(stderr.contains("2 problem(s) found"), "{stderr}");
}

fn user_add(config: &Path, cwd: &Path, name: &str) -> std::process::Output {
    let mut child = gridscada()
        .args(["user", "add", name, "--role", "operator", "--config"])
        .arg(config)
        .current_dir(cwd)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let _ = child
        .stdin
        .take()
        .unwrap()
        .write_all(b"a-long-enough-password\n");
    child.wait_with_output().unwrap()
}

/// `data_dir = "data"` is the configuration folder's `data`, wherever the
/// command runs: `user add --config` from two other folders writes to the
/// one database `serve` opens.
#[test]
fn user_add_from_any_folder_uses_the_configurations_data_folder() {
    let dir = tempfile::tempdir().unwrap();
    let conf = plant(dir.path(), "\n[server]\ndata_dir = \"data\"\n");
    let (a, b) = (dir.path().join("a"), dir.path().join("b"));
    std::fs::create_dir_all(&a).unwrap();
    std::fs::create_dir_all(&b).unwrap();
    let out = user_add(Path::new("../conf/gridscada.toml"), &a, "alice");
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(conf.join("data/gridscada.db").exists());
    assert!(!a.join("data").exists() && !a.join("../conf/../data").exists());
    // From elsewhere, by another path to the same file: the same database.
    let out = user_add(&conf, &b, "alice");
    assert_eq!(out.status.code(), Some(1));
    assert!(
        text(&out.stderr).contains("already exists"),
        "{}",
        text(&out.stderr)
    );
    assert!(!b.join("data").exists());
    // GRIDSCADA_DATA_DIR moves it (relative to the working directory).
    let mut child = gridscada()
        .args(["user", "add", "bob", "--role", "operator", "--config"])
        .arg(&conf)
        .current_dir(&b)
        .env("GRIDSCADA_DATA_DIR", "state")
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut err = String::new();
    child
        .stderr
        .take()
        .unwrap()
        .read_to_string(&mut err)
        .unwrap();
    assert!(child.wait().unwrap().success(), "{err}");
    assert!(b.join("state/gridscada.db").exists());
}

/// A running server; killed when dropped.
struct Server(Child);
impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Starts `cmd` (a `serve`) and returns it with the HTTP address and the
/// data folder it printed.
fn start(mut cmd: Command) -> (Server, String, PathBuf) {
    let mut child = cmd
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let stdout = child.stdout.take().unwrap();
    let mut stderr = child.stderr.take().unwrap();
    let server = Server(child);
    let mut lines = BufReader::new(stdout).lines();
    let deadline = Instant::now() + Duration::from_secs(60);
    let mut addr = None;
    while Instant::now() < deadline {
        let Some(Ok(line)) = lines.next() else { break };
        if let Some(rest) = line.split("HMI and API: http://").nth(1) {
            addr = Some(rest.trim_end_matches('/').to_string());
        }
        if let Some(d) = line.split("Data folder: ").nth(1) {
            let addr = addr.expect("the address comes first");
            std::thread::spawn(move || for _ in lines {});
            std::thread::spawn(move || std::io::copy(&mut stderr, &mut std::io::sink()));
            return (server, addr, PathBuf::from(d.trim()));
        }
    }
    let mut err = String::new();
    let _ = stderr.read_to_string(&mut err);
    panic!("serve did not start: {err}");
}

fn healthz(addr: &str) -> u16 {
    let mut s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    write!(
        s,
        "GET /healthz HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n"
    )
    .unwrap();
    let mut resp = String::new();
    s.read_to_string(&mut resp).unwrap();
    resp.split_whitespace().nth(1).unwrap().parse().unwrap()
}

#[test]
fn serve_takes_http_and_data_from_flags_over_the_environment_over_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let conf = plant(dir.path(), "\n[server]\nhttp = \"127.0.0.1:0\"\n");
    let cwd = dir.path().join("cwd");
    std::fs::create_dir_all(&cwd).unwrap();

    // The file: data beside the configuration.
    let mut cmd = gridscada();
    cmd.args(["serve", "--config"]).arg(&conf).current_dir(&cwd);
    let (s, addr, data) = start(cmd);
    assert_eq!(healthz(&addr), 200);
    assert_eq!(data, conf.join("data"));
    assert!(conf.join("data/gridscada.db").exists());
    drop(s);

    // The environment over the file.
    let mut cmd = gridscada();
    cmd.args(["serve", "--config"])
        .arg(&conf)
        .current_dir(&cwd)
        .env("GRIDSCADA_DATA_DIR", "env-data")
        .env("GRIDSCADA_HTTP", "127.0.0.1:0");
    let (s, addr, data) = start(cmd);
    assert_eq!(healthz(&addr), 200);
    assert_eq!(data, PathBuf::from("env-data"));
    assert!(cwd.join("env-data/gridscada.db").exists());
    drop(s);

    // The flags over both (the environment's address is never bound).
    let flag_data = dir.path().join("flag-data");
    let mut cmd = gridscada();
    cmd.args(["serve", "--config"])
        .arg(&conf)
        .args(["--http", "127.0.0.1:0", "--data"])
        .arg(&flag_data)
        .current_dir(&cwd)
        .env("GRIDSCADA_DATA_DIR", "env-data-2")
        .env("GRIDSCADA_HTTP", "192.0.2.1:1");
    let (s, addr, data) = start(cmd);
    assert_eq!(healthz(&addr), 200);
    assert_eq!(data, flag_data);
    assert!(flag_data.join("gridscada.db").exists());
    assert!(!cwd.join("env-data-2").exists());
    drop(s);

    // A bad flag is refused, naming it.
    let out = gridscada()
        .args(["serve", "--config"])
        .arg(&conf)
        .args(["--http", "localhost:http"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    assert!(
        text(&out.stderr).contains("--http 'localhost:http' is not an address like 127.0.0.1:8080"),
        "{}",
        text(&out.stderr)
    );
}
