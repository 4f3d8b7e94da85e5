//! The broker connection shared by the edge node and the central host: the
//! client options from `[mqtt]` (client id, credentials, keep-alive, TLS on
//! rustls with ring), and the sizes of what goes over it.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use gridscada_config::MqttConfig;
use rumqttc::{MqttOptions, TlsConfiguration, Transport};

/// The most an MQTT packet may be (the protocol's limit, 256 MiB).
pub const MQTT_MAX_PACKET: usize = 268_435_455;

/// Why the connection cannot be set up (read once at start).
#[derive(Debug, thiserror::Error)]
pub enum ConnectionError {
    #[error("[mqtt] broker: {0}")]
    Broker(String),
    #[error("[mqtt] ca_file {}: {reason}", path.display())]
    Ca { path: PathBuf, reason: String },
}

/// Where the broker is, from `mqtt://host:port` or `mqtts://host:port`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Broker {
    pub host: String,
    pub port: u16,
    pub tls: bool,
}

impl Broker {
    pub fn parse(url: &str) -> Result<Broker, ConnectionError> {
        let bad = || {
            ConnectionError::Broker(format!(
                "'{url}' is not mqtt://host:port or mqtts://host:port"
            ))
        };
        let (tls, rest) = if let Some(r) = url.strip_prefix("mqtts://") {
            (true, r)
        } else if let Some(r) = url.strip_prefix("mqtt://") {
            (false, r)
        } else {
            return Err(bad());
        };
        let (host, port) = rest.rsplit_once(':').ok_or_else(bad)?;
        let port: u16 = port.parse().map_err(|_| bad())?;
        if host.is_empty() || port == 0 {
            return Err(bad());
        }
        // An IPv6 literal comes bracketed in a URL, bare to the resolver.
        let host = host
            .trim_start_matches('[')
            .trim_end_matches(']')
            .to_string();
        Ok(Broker { host, port, tls })
    }
}

/// The client options for one session. `config_dir` resolves a relative
/// `ca_file`; `incoming_max` is the largest packet read before the
/// connection is dropped (callers refuse smaller oversized messages
/// themselves, so that a rogue publisher cannot cut the session).
pub fn options(
    mqtt: &MqttConfig,
    client_id: &str,
    config_dir: &Path,
) -> Result<MqttOptions, ConnectionError> {
    let broker = Broker::parse(mqtt.broker.get_ref())?;
    let mut opts = MqttOptions::new(client_id, broker.host.clone(), broker.port);
    opts.set_keep_alive(Duration::from_secs(*mqtt.keep_alive_s.get_ref()));
    opts.set_clean_session(true);
    let incoming = mqtt
        .max_message_bytes
        .get_ref()
        .saturating_mul(4)
        .clamp(1 << 20, MQTT_MAX_PACKET);
    opts.set_max_packet_size(incoming, MQTT_MAX_PACKET);
    if let Some(user) = &mqtt.username {
        let password = mqtt
            .password
            .as_ref()
            .map(|p| p.get_ref().clone())
            .unwrap_or_default();
        opts.set_credentials(user.get_ref().clone(), password);
    }
    if broker.tls {
        let Some(ca) = &mqtt.ca_file else {
            return Err(ConnectionError::Broker(
                "an mqtts:// broker needs ca_file".into(),
            ));
        };
        let path = config_dir.join(ca.get_ref());
        opts.set_transport(Transport::tls_with_config(TlsConfiguration::Rustls(
            tls_config(&path)?,
        )));
    }
    Ok(opts)
}

/// A TLS client configuration trusting the CA certificates in `ca` (PEM),
/// on rustls with ring.
pub fn tls_config(ca: &Path) -> Result<Arc<rustls::ClientConfig>, ConnectionError> {
    use rustls::pki_types::pem::PemObject;
    use rustls::pki_types::CertificateDer;
    let error = |reason: String| ConnectionError::Ca {
        path: ca.to_path_buf(),
        reason,
    };
    let bytes = std::fs::read(ca).map_err(|e| error(e.to_string()))?;
    let mut roots = rustls::RootCertStore::empty();
    for cert in CertificateDer::pem_slice_iter(&bytes) {
        let cert = cert.map_err(|e| error(format!("not PEM certificates ({e})")))?;
        roots
            .add(cert)
            .map_err(|e| error(format!("not a usable CA certificate ({e})")))?;
    }
    if roots.is_empty() {
        return Err(error("holds no certificate".into()));
    }
    let provider = Arc::new(rustls::crypto::ring::default_provider());
    let config = rustls::ClientConfig::builder_with_provider(provider)
        .with_safe_default_protocol_versions()
        .map_err(|e| error(e.to_string()))?
        .with_root_certificates(roots)
        .with_no_client_auth();
    Ok(Arc::new(config))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn broker_urls_parse() {
        assert_eq!(
            Broker::parse("mqtts://broker.example:8883").unwrap(),
            Broker {
                host: "broker.example".into(),
                port: 8883,
                tls: true
            }
        );
        assert_eq!(Broker::parse("mqtt://[::1]:1883").unwrap().host, "::1");
        assert!(Broker::parse("http://x:1").is_err());
        assert!(Broker::parse("mqtt://x").is_err());
    }

    #[test]
    fn a_ca_file_without_certificates_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("ca.pem");
        std::fs::write(&path, "not a certificate").unwrap();
        let e = tls_config(&path).unwrap_err().to_string();
        assert!(e.contains("holds no certificate"), "{e}");
        let e = tls_config(&dir.path().join("missing.pem"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("ca_file"), "{e}");
    }
}
