//! Paths relative to the main file, the `GRIDSCADA_*` environment
//! overrides, and the warning about a plaintext password in the file.

use std::collections::HashMap;
use std::fs;
use std::path::{Path, PathBuf};

use gridscada_config::{apply_env, load_path, Plant, ENV_VARS};

const TAGS: &str = r#"[[device]]
name = "D1"
protocol = "tcp"
address = "127.0.0.1:1502"

[[tag]]
name = "A.Volts"
device = "D1"
kind = "input_register"
address = 0
type = "f32"
"#;

/// A plant in `dir/conf/` with `extra` appended to its main file.
fn plant_in(dir: &Path, extra: &str) -> PathBuf {
    let conf = dir.join("conf");
    fs::create_dir_all(conf.join("sub")).unwrap();
    fs::write(
        conf.join("gridscada.toml"),
        format!("tag_files = [\"sub/tags.toml\"]\n{extra}"),
    )
    .unwrap();
    fs::write(conf.join("sub/tags.toml"), TAGS).unwrap();
    conf
}

fn load(dir: &Path, extra: &str) -> Plant {
    load_path(&plant_in(dir, extra)).unwrap_or_else(|d| panic!("{d:?}"))
}

fn env(vars: &[(&str, &str)]) -> impl Fn(&str) -> Option<String> {
    let map: HashMap<String, String> = vars
        .iter()
        .map(|(k, v)| (k.to_string(), v.to_string()))
        .collect();
    move |k: &str| map.get(k).cloned()
}

#[test]
fn data_dir_is_relative_to_the_main_file_like_tag_files() {
    let dir = tempfile::tempdir().unwrap();
    let conf = dir.path().join("conf");
    // Default "data", beside the main file, wherever the command runs.
    let p = load(dir.path(), "");
    assert_eq!(p.data_dir, conf.join("data"));
    // Loaded by the main file's path, not its folder: the same.
    let p = load_path(&conf.join("gridscada.toml")).unwrap();
    assert_eq!(p.data_dir, conf.join("data"));
    let p = load(dir.path(), "[server]\ndata_dir = \"../state/db\"\n");
    assert_eq!(p.data_dir, conf.join("../state/db"));
    // An absolute one stays as written.
    let abs = dir.path().join("elsewhere");
    let p = load(
        dir.path(),
        &format!("[server]\ndata_dir = \"{}\"\n", abs.display()),
    );
    assert_eq!(p.data_dir, abs);
}

#[test]
fn no_environment_changes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let mut p = load(dir.path(), "");
    let before = format!("{:?}", (&p.server, &p.storage, &p.data_dir));
    assert_eq!(apply_env(&mut p, &env(&[])).unwrap(), Vec::<&str>::new());
    assert_eq!(
        format!("{:?}", (&p.server, &p.storage, &p.data_dir)),
        before
    );
}

#[test]
fn every_override_replaces_its_setting() {
    let dir = tempfile::tempdir().unwrap();
    let mut p = load(
        dir.path(),
        "[server]\nhttp = \"127.0.0.1:8080\"\nmetrics_token = \"from-file\"\n[storage]\nurl = \"postgres://scada:old@db/scada\"\n[mqtt]\nbroker = \"mqtt://127.0.0.1:1883\"\ngroup = \"G\"\nusername = \"edge\"\n",
    );
    let applied = apply_env(
        &mut p,
        &env(&[
            (
                "GRIDSCADA_STORAGE_URL",
                "postgres://scada@db2:5433/plant?sslmode=require",
            ),
            ("GRIDSCADA_STORAGE_PASSWORD", "n3w p@ss"),
            ("GRIDSCADA_HTTP", "0.0.0.0:9443"),
            ("GRIDSCADA_DATA_DIR", "/var/lib/gridscada"),
            ("GRIDSCADA_METRICS_TOKEN", "from-env"),
            ("GRIDSCADA_TLS_CERT", "/etc/gridscada/cert.pem"),
            ("GRIDSCADA_TLS_KEY", "/etc/gridscada/key.pem"),
            ("GRIDSCADA_BASE_PATH", "/scada/"),
            ("GRIDSCADA_PUBLIC_ORIGIN", "https://SCADA.example.com:443"),
            ("GRIDSCADA_MQTT_PASSWORD", "broker secret"),
        ]),
    )
    .unwrap();
    assert_eq!(
        p.mqtt
            .as_ref()
            .and_then(|m| m.password.as_ref())
            .map(|p| p.get_ref().as_str()),
        Some("broker secret")
    );
    assert_eq!(applied, ENV_VARS.iter().map(|v| v.name).collect::<Vec<_>>());
    assert_eq!(
        p.storage.url.get_ref(),
        "postgres://scada:n3w%20p%40ss@db2:5433/plant?sslmode=require"
    );
    assert_eq!(p.server.http.get_ref(), "0.0.0.0:9443");
    assert_eq!(p.data_dir, PathBuf::from("/var/lib/gridscada"));
    assert_eq!(p.server.metrics_token.as_deref(), Some("from-env"));
    assert_eq!(p.server.base_path(), "/scada");
    assert_eq!(
        p.server.public_origin().as_deref(),
        Some("https://scada.example.com")
    );

    // The password alone goes into the file's URL (replacing its password).
    let mut p = load(
        dir.path(),
        "[storage]\nurl = \"postgresql://scada:old@db/scada\"\n",
    );
    apply_env(&mut p, &env(&[("GRIDSCADA_STORAGE_PASSWORD", "s3cret")])).unwrap();
    assert_eq!(
        p.storage.url.get_ref(),
        "postgresql://scada:s3cret@db/scada"
    );
    // A relative data folder from the environment is the working
    // directory's, like a command-line path.
    apply_env(&mut p, &env(&[("GRIDSCADA_DATA_DIR", "state")])).unwrap();
    assert_eq!(p.data_dir, PathBuf::from("state"));
}

#[test]
fn bad_overrides_are_refused_naming_the_variable_and_no_secret() {
    let dir = tempfile::tempdir().unwrap();
    let mut p = load(dir.path(), "");
    let errors: Vec<String> = apply_env(
        &mut p,
        &env(&[
            ("GRIDSCADA_STORAGE_URL", "mysql://root:hunter2@db/x"),
            ("GRIDSCADA_STORAGE_PASSWORD", "hunter3"),
            ("GRIDSCADA_HTTP", "localhost"),
            ("GRIDSCADA_DATA_DIR", " "),
            ("GRIDSCADA_METRICS_TOKEN", ""),
        ]),
    )
    .unwrap_err()
    .iter()
    .map(|d| d.to_string())
    .collect();
    assert_eq!(
        errors,
        [
            "environment: error: GRIDSCADA_STORAGE_URL (replacing [storage] url): a URL of scheme 'mysql:' is not storage; it must start with sqlite:, postgres:// or postgresql://",
            "environment: error: GRIDSCADA_STORAGE_PASSWORD (replacing the password of [storage] url): the storage URL is not PostgreSQL (postgres://…); SQLite has no password",
            "environment: error: GRIDSCADA_HTTP (replacing [server] http): 'localhost' is not an address like 127.0.0.1:8080",
            "environment: error: GRIDSCADA_DATA_DIR (replacing [server] data_dir): set but empty; unset it to keep the file's setting",
            "environment: error: GRIDSCADA_METRICS_TOKEN (replacing [server] metrics_token): set but empty; unset it to keep the file's setting",
        ]
    );
    assert!(errors.iter().all(|e| !e.contains("hunter")), "{errors:?}");

    // A password needs a user in the URL.
    let mut p = load(dir.path(), "[storage]\nurl = \"postgres://db/scada\"\n");
    let e = apply_env(&mut p, &env(&[("GRIDSCADA_STORAGE_PASSWORD", "x")])).unwrap_err();
    assert!(e[0].message.contains("names no user"), "{e:?}");
}

#[test]
fn a_plaintext_password_in_the_file_is_a_located_warning_not_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let p = load(
        dir.path(),
        "[storage]\nretention_days = 30\nurl = \"postgres://scada:s3cret@db/scada\"\n",
    );
    let w: Vec<String> = p.warnings.iter().map(|w| w.to_string()).collect();
    let main = dir.path().join("conf/gridscada.toml");
    assert_eq!(w.len(), 1, "{w:?}");
    assert!(
        w[0].starts_with(&format!(
            "{}:4:7: warning: [storage] url holds a plaintext password",
            main.display()
        )),
        "{w:?}"
    );
    assert!(w[0].contains("GRIDSCADA_STORAGE_PASSWORD"), "{w:?}");
    assert!(!w[0].contains("s3cret"), "{w:?}");
    // A broker password in the file: located, and not shown.
    let p = load(
        dir.path(),
        "[mqtt]\nbroker = \"mqtt://b:1883\"\ngroup = \"G\"\nusername = \"u\"\npassword = \"br0ker\"\n",
    );
    let w: Vec<String> = p.warnings.iter().map(|w| w.to_string()).collect();
    assert_eq!(w.len(), 1, "{w:?}");
    assert!(
        w[0].starts_with(&format!(
            "{}:6:12: warning: [mqtt] password is in the file",
            main.display()
        )),
        "{w:?}"
    );
    assert!(
        w[0].contains("GRIDSCADA_MQTT_PASSWORD") && !w[0].contains("br0ker"),
        "{w:?}"
    );
    // No password, or SQLite: no warning.
    for url in ["postgres://scada@db/scada", "sqlite://gridscada.db"] {
        let p = load(dir.path(), &format!("[storage]\nurl = \"{url}\"\n"));
        assert!(p.warnings.is_empty(), "{url}: {:?}", p.warnings);
    }
}

#[test]
fn a_bad_base_path_from_the_environment_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let mut p = load(dir.path(), "[server]\nbase_path = \"/scada\"\n");
    let errors: Vec<String> = apply_env(&mut p, &env(&[("GRIDSCADA_BASE_PATH", "scada")]))
        .unwrap_err()
        .iter()
        .map(|d| d.to_string())
        .collect();
    assert_eq!(
        errors,
        ["environment: error: GRIDSCADA_BASE_PATH (replacing [server] base_path): 'scada' must start with / (like /scada)"]
    );
    assert_eq!(p.server.base_path(), "/scada", "the file's setting stays");
}
