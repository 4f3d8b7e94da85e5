//! `gridscada cert self-signed`: a certificate and key for a first start
//! over HTTPS, before the site's own CA or ACME issues a real one.

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{anyhow, bail, Context};

/// What `cert self-signed` was asked for.
pub struct SelfSigned {
    /// DNS names and IP addresses the certificate is valid for; empty: the
    /// defaults ([`default_hosts`]).
    pub hosts: Vec<String>,
    pub days: u32,
    /// Where to write; `None`: the configuration's folder, else the working
    /// directory.
    pub out: Option<PathBuf>,
    /// The configuration (main file or folder) the lines are printed for.
    pub config: Option<PathBuf>,
    pub force: bool,
}

pub const CERT_FILE: &str = "cert.pem";
pub const KEY_FILE: &str = "key.pem";

/// localhost, the loopback addresses and this machine's name.
pub fn default_hosts() -> Vec<String> {
    let mut hosts: Vec<String> = ["localhost", "127.0.0.1", "::1"].map(String::from).to_vec();
    if let Some(name) = machine_name() {
        if !hosts.contains(&name) {
            hosts.push(name);
        }
    }
    hosts
}

fn machine_name() -> Option<String> {
    ["/proc/sys/kernel/hostname", "/etc/hostname"]
        .iter()
        .find_map(|p| std::fs::read_to_string(p).ok())
        .map(|s| s.trim().to_string())
        .filter(|s| !s.is_empty() && valid_dns_name(s))
}

/// A host name as a certificate may name it (a leading `*.` allowed).
fn valid_dns_name(name: &str) -> bool {
    let name = name.strip_prefix("*.").unwrap_or(name);
    !name.is_empty()
        && name.len() <= 253
        && name.split('.').all(|label| {
            !label.is_empty()
                && label.len() <= 63
                && !label.starts_with('-')
                && !label.ends_with('-')
                && label.chars().all(|c| c.is_ascii_alphanumeric() || c == '-')
        })
}

/// The folder of a configuration given as its main file or its folder.
fn config_folder(config: &Path) -> PathBuf {
    if config.is_dir() {
        config.to_path_buf()
    } else {
        config
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .map_or_else(|| PathBuf::from("."), Path::to_path_buf)
    }
}

/// Generates the pair, writes it and prints the `[server.tls]` lines.
pub fn self_signed(args: SelfSigned) -> anyhow::Result<()> {
    let hosts = if args.hosts.is_empty() {
        default_hosts()
    } else {
        args.hosts
    };
    for h in &hosts {
        if h.parse::<std::net::IpAddr>().is_err() && !valid_dns_name(h) {
            bail!("--host {h}: not a host name or IP address");
        }
    }
    if !(1..=3650).contains(&args.days) {
        bail!("--days {}: give 1 to 3650", args.days);
    }
    let config_dir = args.config.as_deref().map(config_folder);
    let out = match (&args.out, &config_dir) {
        (Some(o), _) => o.clone(),
        (None, Some(c)) => c.clone(),
        (None, None) => PathBuf::from("."),
    };
    std::fs::create_dir_all(&out).with_context(|| format!("cannot create {}", out.display()))?;
    let (cert_path, key_path) = (out.join(CERT_FILE), out.join(KEY_FILE));
    if !args.force {
        for p in [&cert_path, &key_path] {
            if p.exists() {
                bail!(
                    "{} exists; not overwriting it (give --force to replace both files)",
                    p.display()
                );
            }
        }
    }

    let (cert_pem, key_pem) = generate(&hosts, args.days)?;
    write_file(&key_path, key_pem.as_bytes(), 0o600)?;
    write_file(&cert_path, cert_pem.as_bytes(), 0o644)?;

    println!(
        "Wrote {} and {} (self-signed, {} days, for {}).",
        cert_path.display(),
        key_path.display(),
        args.days,
        hosts.join(", ")
    );
    // Relative to the configuration's folder when they are in it, as
    // `[server.tls]` paths are resolved there.
    let shown = |p: &Path| -> String {
        match &config_dir {
            Some(c) if out == *c => p.file_name().map_or_else(
                || p.display().to_string(),
                |n| n.to_string_lossy().into_owned(),
            ),
            _ => std::path::absolute(p)
                .unwrap_or_else(|_| p.to_path_buf())
                .display()
                .to_string(),
        }
    };
    println!("Add to gridscada.toml:\n");
    println!("[server.tls]");
    println!("cert = {:?}", shown(&cert_path));
    println!("key = {:?}", shown(&key_path));
    println!(
        "\nBrowsers will warn until they trust it: import {} as a trusted certificate, \
         or give curl --cacert {}.",
        cert_path.display(),
        cert_path.display()
    );
    Ok(())
}

/// A self-signed ECDSA P-256 certificate for `hosts`, valid from an hour ago
/// (clocks differ) for `days` days; (certificate PEM, key PEM).
fn generate(hosts: &[String], days: u32) -> anyhow::Result<(String, String)> {
    let mut params = rcgen::CertificateParams::new(hosts.to_vec())
        .map_err(|e| anyhow!("cannot make the certificate: {e}"))?;
    params
        .distinguished_name
        .push(rcgen::DnType::CommonName, hosts[0].as_str());
    params
        .distinguished_name
        .push(rcgen::DnType::OrganizationName, "gridscada self-signed");
    let now = time::OffsetDateTime::now_utc();
    params.not_before = now - time::Duration::hours(1);
    params.not_after = now + time::Duration::days(i64::from(days));
    let key = rcgen::KeyPair::generate().map_err(|e| anyhow!("cannot make a key: {e}"))?;
    let cert = params
        .self_signed(&key)
        .map_err(|e| anyhow!("cannot sign the certificate: {e}"))?;
    Ok((cert.pem(), key.serialize_pem()))
}

/// Writes `bytes` to a new file of mode `mode` (replacing one there: the
/// check against overwriting is the caller's).
fn write_file(path: &Path, bytes: &[u8], mode: u32) -> anyhow::Result<()> {
    let mut options = std::fs::OpenOptions::new();
    options.write(true).create(true).truncate(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::{OpenOptionsExt, PermissionsExt};
        options.mode(mode);
        // An existing file keeps its mode through open(); a key must not.
        if path.exists() {
            std::fs::set_permissions(path, std::fs::Permissions::from_mode(mode))
                .with_context(|| format!("cannot set the mode of {}", path.display()))?;
        }
    }
    #[cfg(not(unix))]
    let _ = mode;
    let mut f = options
        .open(path)
        .with_context(|| format!("cannot write {}", path.display()))?;
    f.write_all(bytes)
        .and_then(|()| f.sync_all())
        .with_context(|| format!("cannot write {}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn writes_a_pair_the_server_accepts_and_refuses_to_overwrite() {
        let dir = tempfile::tempdir().unwrap();
        let args = |force| SelfSigned {
            hosts: vec!["scada.example".into(), "10.0.0.5".into()],
            days: 30,
            out: Some(dir.path().to_path_buf()),
            config: None,
            force,
        };
        self_signed(args(false)).unwrap();
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            let mode = std::fs::metadata(dir.path().join(KEY_FILE))
                .unwrap()
                .permissions()
                .mode();
            assert_eq!(mode & 0o777, 0o600);
        }
        let files = gridscada_config::TlsFiles {
            cert: dir.path().join(CERT_FILE),
            key: dir.path().join(KEY_FILE),
            redirect_http: None,
            hsts_max_age_s: 0,
        };
        gridscada_web::tls::server_config(&files).unwrap();
        let before = std::fs::read(&files.cert).unwrap();
        let e = self_signed(args(false)).unwrap_err().to_string();
        assert!(e.contains("--force"), "{e}");
        self_signed(args(true)).unwrap();
        assert_ne!(std::fs::read(&files.cert).unwrap(), before);
        gridscada_web::tls::server_config(&files).unwrap();
    }

    #[test]
    fn bad_hosts_and_days_are_refused() {
        for (hosts, days) in [(vec!["bad host".to_string()], 30), (vec![], 0)] {
            let dir = tempfile::tempdir().unwrap();
            assert!(self_signed(SelfSigned {
                hosts,
                days,
                out: Some(dir.path().to_path_buf()),
                config: None,
                force: false,
            })
            .is_err());
        }
        assert!(default_hosts().contains(&"::1".to_string()));
    }
}
