//! HTTPS: the certificate chain and key of `[server.tls]` read from their
//! PEM files, the TLS listener (rustls on `ring`), its reload on SIGHUP, and
//! the plain-HTTP listener that only redirects to HTTPS.
//!
//! A reload swaps the configuration new handshakes use; connections already
//! open (a WebSocket on `/api/live` among them) keep the keys they agreed.

use std::future::Future;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use axum::http::{header, HeaderMap, StatusCode, Uri};
use axum::response::{IntoResponse, Response};
use axum::Router;
use gridscada_config::TlsFiles;
use rustls::pki_types::pem::{PemObject, SectionKind};
use rustls::pki_types::{CertificateDer, PrivateKeyDer};
use rustls::sign::CertifiedKey;

use crate::listener::{self, Connections, Transport};
use crate::routes::HostPolicy;

/// Why a certificate or key cannot be used, naming the file and the setting
/// it came from.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TlsError {
    /// `[server.tls] cert` or `[server.tls] key`.
    pub setting: &'static str,
    pub file: PathBuf,
    pub reason: String,
}

impl std::fmt::Display for TlsError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} {}: {}",
            self.setting,
            self.file.display(),
            self.reason
        )
    }
}

impl std::error::Error for TlsError {}

const CERT: &str = "[server.tls] cert";
const KEY: &str = "[server.tls] key";

/// The TLS configuration of `files`: the chain of `cert` (the server's own
/// certificate first) with the key of `key`, checked to belong together.
/// Only HTTP/1.1 is offered, which every browser's WebSocket speaks.
pub fn server_config(files: &TlsFiles) -> Result<Arc<rustls::ServerConfig>, TlsError> {
    let provider = Arc::new(rustls::crypto::ring::default_provider());
    let certs = read_certs(&files.cert)?;
    let key = read_key(&files.key)?;
    let key_error = |reason: String| TlsError {
        setting: KEY,
        file: files.key.clone(),
        reason,
    };
    let signer = provider
        .key_provider
        .load_private_key(key.clone_key())
        .map_err(|e| key_error(format!("not a usable private key ({e})")))?;
    let certified = CertifiedKey::new(certs.clone(), signer);
    certified.keys_match().map_err(|e| {
        let why = match e {
            rustls::Error::InconsistentKeys(rustls::InconsistentKeys::KeyMismatch) => format!(
                "does not belong to the certificate in {} (its public key differs)",
                files.cert.display()
            ),
            other => format!(
                "cannot be matched to the certificate in {} ({other})",
                files.cert.display()
            ),
        };
        key_error(why)
    })?;
    let mut config = rustls::ServerConfig::builder_with_provider(provider)
        .with_safe_default_protocol_versions()
        .map_err(|e| key_error(e.to_string()))?
        .with_no_client_auth()
        .with_single_cert(certs, key)
        .map_err(|e| key_error(e.to_string()))?;
    config.alpn_protocols = vec![b"http/1.1".to_vec()];
    Ok(Arc::new(config))
}

/// The PEM sections of a file, or why it cannot be read.
fn read_pem(setting: &'static str, path: &Path) -> Result<Vec<(SectionKind, Vec<u8>)>, TlsError> {
    let error = |reason: String| TlsError {
        setting,
        file: path.to_path_buf(),
        reason,
    };
    let bytes = std::fs::read(path).map_err(|e| {
        error(match e.kind() {
            std::io::ErrorKind::NotFound => "no such file".into(),
            std::io::ErrorKind::PermissionDenied => {
                "permission denied (the server's user must be able to read it)".into()
            }
            _ => format!("cannot be read: {e}"),
        })
    })?;
    <(SectionKind, Vec<u8>)>::pem_slice_iter(&bytes)
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| error(format!("not valid PEM ({e})")))
}

/// What a file holds, for messages: "a private key", "2 certificates".
fn holds(sections: &[(SectionKind, Vec<u8>)]) -> String {
    if sections.is_empty() {
        return "it holds no PEM section (-----BEGIN ...-----)".into();
    }
    let kinds: Vec<String> = sections
        .iter()
        .map(|(k, _)| match k {
            SectionKind::Certificate => "CERTIFICATE".to_string(),
            SectionKind::PrivateKey => "PRIVATE KEY".into(),
            SectionKind::RsaPrivateKey => "RSA PRIVATE KEY".into(),
            SectionKind::EcPrivateKey => "EC PRIVATE KEY".into(),
            other => format!("{other:?}"),
        })
        .collect();
    format!("it holds {}", kinds.join(", "))
}

fn read_certs(path: &Path) -> Result<Vec<CertificateDer<'static>>, TlsError> {
    let sections = read_pem(CERT, path)?;
    let certs: Vec<CertificateDer<'static>> = sections
        .iter()
        .filter(|(k, _)| *k == SectionKind::Certificate)
        .map(|(_, der)| CertificateDer::from(der.clone()))
        .collect();
    if certs.is_empty() {
        return Err(TlsError {
            setting: CERT,
            file: path.to_path_buf(),
            reason: format!(
                "no certificate (-----BEGIN CERTIFICATE-----); {}",
                holds(&sections)
            ),
        });
    }
    Ok(certs)
}

fn read_key(path: &Path) -> Result<PrivateKeyDer<'static>, TlsError> {
    let sections = read_pem(KEY, path)?;
    let mut keys = sections
        .iter()
        .filter_map(|(k, der)| PrivateKeyDer::from_pem(*k, der.clone()));
    let (Some(key), None) = (keys.next(), keys.next()) else {
        let n = sections
            .iter()
            .filter_map(|(k, der)| PrivateKeyDer::from_pem(*k, der.clone()))
            .count();
        let reason = if n == 0 {
            format!(
                "no private key (-----BEGIN PRIVATE KEY-----, RSA or EC); {}",
                holds(&sections)
            )
        } else {
            format!("{n} private keys; give the one of the certificate alone")
        };
        return Err(TlsError {
            setting: KEY,
            file: path.to_path_buf(),
            reason,
        });
    };
    Ok(key)
}

/// The HTTPS side of a running server: what its listener serves, and where
/// to read it again.
#[derive(Clone)]
pub struct Https {
    config: Arc<parking_lot::RwLock<Arc<rustls::ServerConfig>>>,
    files: TlsFiles,
}

impl Https {
    /// Reads and checks the certificate and key.
    pub fn load(files: &TlsFiles) -> Result<Https, TlsError> {
        Ok(Https {
            config: Arc::new(parking_lot::RwLock::new(server_config(files)?)),
            files: files.clone(),
        })
    }

    /// Reads the files again; new connections use the new pair. A pair that
    /// does not load is refused and the one in use keeps serving.
    pub fn reload(&self) -> Result<(), TlsError> {
        let config = server_config(&self.files)?;
        *self.config.write() = config;
        Ok(())
    }

    /// The configuration a new handshake uses.
    pub fn current(&self) -> Arc<rustls::ServerConfig> {
        self.config.read().clone()
    }

    pub fn files(&self) -> &TlsFiles {
        &self.files
    }
}

/// Binds `addr` now and serves `router` over TLS, like [`crate::bind`].
pub async fn bind_tls(
    addr: SocketAddr,
    router: Router,
    https: &Https,
    connections: Arc<Connections>,
) -> std::io::Result<(SocketAddr, impl Future<Output = std::io::Result<()>>)> {
    let listener = tokio::net::TcpListener::bind(addr).await?;
    let local = listener.local_addr()?;
    let fut = listener::serve(listener, router, connections, Transport::Tls(https.clone()));
    Ok((local, fut))
}

/// Binds `addr` now for plain HTTP that answers every request with a
/// permanent redirect (308, which keeps the method) to the same path on
/// HTTPS at `https_port`, on the host `server`'s settings name (see
/// [`RedirectTarget`]). Its connections count against the same limits as
/// the HTTPS listener's.
pub async fn bind_redirect(
    addr: SocketAddr,
    https_port: u16,
    server: &gridscada_config::ServerConfig,
    connections: Arc<Connections>,
) -> std::io::Result<(SocketAddr, impl Future<Output = std::io::Result<()>>)> {
    let listener = tokio::net::TcpListener::bind(addr).await?;
    let local = listener.local_addr()?;
    let target = Arc::new(RedirectTarget::new(server, https_port));
    let router = Router::new().fallback(move |headers: HeaderMap, uri: Uri| async move {
        redirect(&headers, &uri, &target)
    });
    let fut = listener::serve(listener, router, connections, Transport::Plain);
    Ok((local, fut))
}

/// Where the redirect listener sends a browser. A 308 is cached, also by
/// shared caches, so its `Location` must not be whatever host a request
/// names: it is `[server] public_origin` when that is an HTTPS origin;
/// otherwise the request's `Host` (with `https_port`) only when it is a
/// host this server answers to anyway (an IP address, `localhost`,
/// `allowed_hosts`, the public origin's host, as [`HostPolicy`] decides).
pub struct RedirectTarget {
    /// `https://host[:port]`, normal form.
    public_origin: Option<String>,
    hosts: HostPolicy,
    https_port: u16,
}

impl RedirectTarget {
    pub fn new(server: &gridscada_config::ServerConfig, https_port: u16) -> Self {
        RedirectTarget {
            // An http:// public origin is a proxy's plain side, not where
            // this redirect should lead.
            public_origin: server.public_origin().filter(|o| o.starts_with("https://")),
            hosts: HostPolicy::of_server(server),
            https_port,
        }
    }
}

/// The redirect of one plain-HTTP request: 400 without a usable `Host`
/// (when it is needed), 421 for a host this server does not answer to.
fn redirect(headers: &HeaderMap, uri: &Uri, target: &RedirectTarget) -> Response {
    let path = uri.path_and_query().map_or("/", |p| p.as_str());
    let origin = match &target.public_origin {
        Some(origin) => origin.clone(),
        None => {
            let host = headers
                .get(header::HOST)
                .and_then(|h| h.to_str().ok())
                .and_then(|h| h.parse::<axum::http::uri::Authority>().ok());
            let Some(host) = host else {
                return (
                    StatusCode::BAD_REQUEST,
                    "HTTPS only: send a Host header, or use https:// directly\n",
                )
                    .into_response();
            };
            if !target.hosts.allows(host.as_str()) {
                return (
                    StatusCode::MISDIRECTED_REQUEST,
                    "this server does not answer to that host name; add it to [server] allowed_hosts\n",
                )
                    .into_response();
            }
            let name = host.host();
            if target.https_port == 443 {
                format!("https://{name}")
            } else {
                format!("https://{name}:{}", target.https_port)
            }
        }
    };
    let location = format!("{origin}{path}");
    match axum::http::HeaderValue::from_str(&location) {
        Ok(v) => (
            StatusCode::PERMANENT_REDIRECT,
            [(header::LOCATION, v)],
            format!("HTTPS only: {location}\n"),
        )
            .into_response(),
        Err(_) => (StatusCode::BAD_REQUEST, "bad request\n").into_response(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A self-signed pair in `dir` as `NAME.crt` and `NAME.key`.
    fn pair(dir: &Path, name: &str) -> (PathBuf, PathBuf) {
        let key = rcgen::KeyPair::generate().unwrap();
        let cert = rcgen::CertificateParams::new(vec!["localhost".to_string()])
            .unwrap()
            .self_signed(&key)
            .unwrap();
        let (c, k) = (
            dir.join(format!("{name}.crt")),
            dir.join(format!("{name}.key")),
        );
        std::fs::write(&c, cert.pem()).unwrap();
        std::fs::write(&k, key.serialize_pem()).unwrap();
        (c, k)
    }

    fn files(cert: &Path, key: &Path) -> TlsFiles {
        TlsFiles {
            cert: cert.to_path_buf(),
            key: key.to_path_buf(),
            redirect_http: None,
            hsts_max_age_s: 0,
        }
    }

    #[test]
    fn problems_name_the_file_and_why() {
        let dir = tempfile::tempdir().unwrap();
        let (c1, k1) = pair(dir.path(), "a");
        let (c2, k2) = pair(dir.path(), "b");
        server_config(&files(&c1, &k1)).unwrap();

        let e = server_config(&files(&dir.path().join("none.pem"), &k1)).unwrap_err();
        assert_eq!((e.setting, e.reason.as_str()), (CERT, "no such file"));
        assert!(e.to_string().contains("none.pem"), "{e}");

        let e = server_config(&files(&c1, &k2)).unwrap_err();
        assert_eq!((e.setting, &e.file), (KEY, &k2));
        assert!(
            e.reason.contains("does not belong to the certificate in"),
            "{e}"
        );

        // Swapped: the key file holds no certificate, the cert file no key.
        let e = server_config(&files(&k1, &c1)).unwrap_err();
        assert_eq!(e.setting, CERT);
        assert!(
            e.reason.contains("no certificate") && e.reason.contains("PRIVATE KEY"),
            "{e}"
        );
        let e = server_config(&files(&c1, &c1)).unwrap_err();
        assert_eq!(e.setting, KEY);
        assert!(
            e.reason.contains("no private key") && e.reason.contains("CERTIFICATE"),
            "{e}"
        );

        // Two keys in one file.
        let both = dir.path().join("both.key");
        let text = std::fs::read_to_string(&k1).unwrap() + &std::fs::read_to_string(&k2).unwrap();
        std::fs::write(&both, text).unwrap();
        let e = server_config(&files(&c1, &both)).unwrap_err();
        assert!(e.reason.contains("2 private keys"), "{e}");

        // Not PEM at all.
        let junk = dir.path().join("junk.pem");
        std::fs::write(&junk, "hello").unwrap();
        let e = server_config(&files(&junk, &k1)).unwrap_err();
        assert!(e.reason.contains("holds no PEM section"), "{e}");

        // A chain: the server's certificate first, then another.
        let chain = dir.path().join("chain.pem");
        let text = std::fs::read_to_string(&c2).unwrap() + &std::fs::read_to_string(&c1).unwrap();
        std::fs::write(&chain, text).unwrap();
        server_config(&files(&chain, &k2)).unwrap();
    }

    fn target(
        change: impl FnOnce(&mut gridscada_config::ServerConfig),
        port: u16,
    ) -> RedirectTarget {
        let mut server = gridscada_config::ServerConfig::default();
        change(&mut server);
        RedirectTarget::new(&server, port)
    }

    fn with_origin(origin: &str, port: u16) -> RedirectTarget {
        let origin = serde_spanned::Spanned::new(0..0, origin.to_string());
        target(|s| s.public_origin = Some(origin), port)
    }

    fn host(h: &str) -> HeaderMap {
        let mut m = HeaderMap::new();
        m.insert(header::HOST, h.parse().unwrap());
        m
    }

    #[test]
    fn redirect_keeps_host_path_and_query() {
        let names = target(|s| s.allowed_hosts = vec!["scada.example".into()], 8443);
        let uri: Uri = "/api/tags?x=1".parse().unwrap();
        let r = redirect(&host("scada.example:80"), &uri, &names);
        assert_eq!(r.status(), StatusCode::PERMANENT_REDIRECT);
        assert_eq!(
            r.headers()[header::LOCATION],
            "https://scada.example:8443/api/tags?x=1"
        );
        let r = redirect(&host("[::1]"), &"/".parse().unwrap(), &target(|_| {}, 443));
        assert_eq!(r.headers()[header::LOCATION], "https://[::1]/");
        let r = redirect(&host("127.0.0.1:80"), &uri, &target(|_| {}, 443));
        assert_eq!(
            r.headers()[header::LOCATION],
            "https://127.0.0.1/api/tags?x=1"
        );
        assert_eq!(
            redirect(&host("a b"), &uri, &names).status(),
            StatusCode::BAD_REQUEST
        );
        assert_eq!(
            redirect(&HeaderMap::new(), &uri, &names).status(),
            StatusCode::BAD_REQUEST
        );
    }

    #[test]
    fn a_forged_host_is_not_where_the_redirect_leads() {
        let uri: Uri = "/scada/api/tags?x=1".parse().unwrap();
        // With a public origin, Location is on it whatever the Host says.
        let public = with_origin("https://SCADA.example.com:8443/", 9443);
        for forged in ["evil.example", "evil.example:8443", "127.0.0.1"] {
            let r = redirect(&host(forged), &uri, &public);
            assert_eq!(r.status(), StatusCode::PERMANENT_REDIRECT, "{forged}");
            assert_eq!(
                r.headers()[header::LOCATION],
                "https://scada.example.com:8443/scada/api/tags?x=1",
                "{forged}"
            );
        }
        let r = redirect(&HeaderMap::new(), &uri, &public);
        assert_eq!(
            r.headers()[header::LOCATION],
            "https://scada.example.com:8443/scada/api/tags?x=1"
        );
        // Without one, a host this server does not answer to gets no redirect.
        for t in [
            target(|_| {}, 443),
            target(|s| s.allowed_hosts = vec!["scada.example".into()], 443),
            with_origin("http://scada.example", 443),
        ] {
            let r = redirect(&host("evil.example"), &uri, &t);
            assert_eq!(r.status(), StatusCode::MISDIRECTED_REQUEST);
            assert!(r.headers().get(header::LOCATION).is_none());
        }
        // An http:// public origin (a proxy's plain side) is not the target,
        // but its host is one of ours.
        let plain = with_origin("http://scada.example", 8443);
        let r = redirect(&host("scada.example"), &uri, &plain);
        assert_eq!(
            r.headers()[header::LOCATION],
            "https://scada.example:8443/scada/api/tags?x=1"
        );
    }
}
