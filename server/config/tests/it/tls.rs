//! `[server.tls]`: paths relative to the main file, defaults, located
//! errors, and the GRIDSCADA_TLS_CERT / GRIDSCADA_TLS_KEY overrides.

use std::collections::HashMap;
use std::fs;
use std::path::{Path, PathBuf};

use gridscada_config::{apply_env, load_path, Plant, TlsFiles, DEFAULT_HSTS_MAX_AGE_S};

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

/// `dir/conf/gridscada.toml` with `extra` after the tag files line.
fn plant_in(dir: &Path, extra: &str) -> PathBuf {
    let conf = dir.join("conf");
    fs::create_dir_all(&conf).unwrap();
    fs::write(
        conf.join("gridscada.toml"),
        format!("tag_files = [\"tags.toml\"]\n{extra}"),
    )
    .unwrap();
    fs::write(conf.join("tags.toml"), TAGS).unwrap();
    conf
}

fn errors(dir: &Path, extra: &str) -> Vec<String> {
    match load_path(&plant_in(dir, extra)) {
        Ok(_) => vec![],
        Err(d) => d.iter().map(|d| d.to_string()).collect(),
    }
}

fn env(vars: &[(&str, &str)]) -> impl Fn(&str) -> Option<String> {
    let map: HashMap<String, String> = vars
        .iter()
        .map(|(k, v)| (k.to_string(), v.to_string()))
        .collect();
    move |k: &str| map.get(k).cloned()
}

#[test]
fn paths_are_relative_to_the_main_file_with_defaults() {
    let dir = tempfile::tempdir().unwrap();
    let conf = plant_in(
        dir.path(),
        "[server.tls]\ncert = \"tls/cert.pem\"\nkey = \"/etc/keys/key.pem\"\n",
    );
    let p: Plant = load_path(&conf).unwrap();
    assert_eq!(
        p.tls,
        Some(TlsFiles {
            cert: conf.join("tls/cert.pem"),
            key: PathBuf::from("/etc/keys/key.pem"),
            redirect_http: None,
            hsts_max_age_s: DEFAULT_HSTS_MAX_AGE_S,
        })
    );
    assert_eq!(DEFAULT_HSTS_MAX_AGE_S, 31_536_000);
    let p = load_path(&plant_in(
        dir.path(),
        "[server.tls]\ncert = \"c.pem\"\nkey = \"k.pem\"\nredirect_http = \"0.0.0.0:80\"\nhsts_max_age_s = 0\n",
    ))
    .unwrap();
    let tls = p.tls.unwrap();
    assert_eq!(tls.redirect_http, Some("0.0.0.0:80".parse().unwrap()));
    assert_eq!(tls.hsts_max_age_s, 0);
    // Without the section: plain HTTP.
    assert_eq!(load_path(&plant_in(dir.path(), "")).unwrap().tls, None);
}

#[test]
fn bad_settings_are_located() {
    let dir = tempfile::tempdir().unwrap();
    let e = errors(
        dir.path(),
        "[server.tls]\ncert = \"c.pem\"\nkey = \"k.pem\"\nredirect_http = \"port 80\"\n",
    );
    assert_eq!(e.len(), 1, "{e:?}");
    assert!(
        e[0].contains("gridscada.toml:5:")
            && e[0].contains("redirect_http: 'port 80' is not an address"),
        "{e:?}"
    );

    let e = errors(
        dir.path(),
        "[server]\nhttp = \"0.0.0.0:8443\"\n[server.tls]\ncert = \"c.pem\"\nkey = \"k.pem\"\nredirect_http = \"0.0.0.0:8443\"\n",
    );
    assert!(
        e.len() == 1 && e[0].contains(":7:") && e[0].contains("is [server] http itself"),
        "{e:?}"
    );

    let e = errors(dir.path(), "[server.tls]\ncert = \"\"\nkey = \"k.pem\"\n");
    assert!(
        e.len() == 1 && e[0].contains(":3:") && e[0].contains("[server.tls] cert: empty"),
        "{e:?}"
    );

    let e = errors(dir.path(), "[server.tls]\ncert = \"c.pem\"\n");
    assert!(e.iter().any(|m| m.contains("missing field `key`")), "{e:?}");

    let e = errors(
        dir.path(),
        "[server.tls]\ncert = \"c.pem\"\nkey = \"k.pem\"\nhsts = 5\n",
    );
    assert!(
        e.iter().any(|m| m.contains("unknown field `hsts`")),
        "{e:?}"
    );

    let e = errors(
        dir.path(),
        "[server.tls]\ncert = \"c.pem\"\nkey = \"k.pem\"\nhsts_max_age_s = -1\n",
    );
    assert_eq!(e.len(), 1, "{e:?}");
}

#[test]
fn the_environment_replaces_or_supplies_the_pair() {
    let dir = tempfile::tempdir().unwrap();
    let conf = plant_in(
        dir.path(),
        "[server.tls]\ncert = \"c.pem\"\nkey = \"k.pem\"\nhsts_max_age_s = 60\n",
    );
    let mut p = load_path(&conf).unwrap();
    let applied = apply_env(
        &mut p,
        &env(&[("GRIDSCADA_TLS_KEY", "/run/secrets/key.pem")]),
    )
    .unwrap();
    assert_eq!(applied, vec!["GRIDSCADA_TLS_KEY"]);
    let tls = p.tls.as_ref().unwrap();
    assert_eq!(tls.cert, conf.join("c.pem"));
    assert_eq!(tls.key, PathBuf::from("/run/secrets/key.pem"));
    assert_eq!(tls.hsts_max_age_s, 60);

    // No section: both variables turn HTTPS on, with the defaults.
    let mut p = load_path(&plant_in(dir.path(), "")).unwrap();
    apply_env(
        &mut p,
        &env(&[
            ("GRIDSCADA_TLS_CERT", "c.pem"),
            ("GRIDSCADA_TLS_KEY", "k.pem"),
        ]),
    )
    .unwrap();
    let tls = p.tls.unwrap();
    assert_eq!((tls.cert, tls.key), ("c.pem".into(), "k.pem".into()));
    assert_eq!(tls.hsts_max_age_s, DEFAULT_HSTS_MAX_AGE_S);

    // One alone is a mistake, named.
    let mut p = load_path(&plant_in(dir.path(), "")).unwrap();
    let e = apply_env(&mut p, &env(&[("GRIDSCADA_TLS_CERT", "c.pem")])).unwrap_err();
    assert!(
        e[0].to_string().contains("GRIDSCADA_TLS_CERT")
            && e[0].to_string().contains("set GRIDSCADA_TLS_KEY too"),
        "{e:?}"
    );
    let e = apply_env(&mut p, &env(&[("GRIDSCADA_TLS_KEY", " ")])).unwrap_err();
    assert!(e[0].to_string().contains("set but empty"), "{e:?}");
}
