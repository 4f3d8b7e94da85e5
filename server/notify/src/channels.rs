//! The ways a message leaves the server: email over SMTP (STARTTLS, TLS or,
//! for a local relay, plain), a webhook (a JSON POST signed with
//! HMAC-SHA256), and MQTT (`mqtt.rs`). Each send is one attempt; retrying is
//! the outbox's.

use std::path::Path;
use std::sync::Arc;
use std::time::Duration;

use bytes::Bytes;
use gridscada_config::{
    MqttConfig, NotifyChannel, NotifyConfig, SmtpConfig, SmtpSecurity, WebhookConfig,
};
use hmac::{Hmac, Mac};
use http_body_util::{BodyExt, Full};
use lettre::message::Mailbox;
use lettre::transport::smtp::authentication::Credentials;
use lettre::transport::smtp::client::{Certificate, Tls, TlsParameters};
use lettre::{AsyncSmtpTransport, AsyncTransport, Tokio1Executor};
use rustls::pki_types::pem::PemObject;
use rustls::pki_types::{CertificateDer, ServerName};
use serde::Serialize;
use sha2::Sha256;

use crate::message::Message;
use crate::mqtt::Mqtt;

/// The header carrying the webhook body's signature: `sha256=<hex>`.
pub const SIGNATURE_HEADER: &str = "x-gridscada-signature";

/// How long one attempt may take.
const ATTEMPT_TIMEOUT: Duration = Duration::from_secs(30);

/// A route's way out, built once at start.
pub enum Channel {
    Email(Email),
    Webhook(Webhook),
    Mqtt(Mqtt),
}

impl Channel {
    /// Builds the channel of a checked route, reading its secret through
    /// `env` and its CA file relative to `base`; an MQTT route publishes on
    /// the broker of `plant_mqtt`.
    pub fn build(
        n: &NotifyConfig,
        base: &Path,
        env: &dyn Fn(&str) -> Option<String>,
        plant_mqtt: Option<&MqttConfig>,
    ) -> Result<Channel, String> {
        let route = n.name.get_ref();
        if let (NotifyChannel::Mqtt, Some(m)) = (n.channel.get_ref(), &n.mqtt) {
            return Mqtt::build(route, m, plant_mqtt, base)
                .map(Channel::Mqtt)
                .map_err(|e| format!("notify '{route}': {e}"));
        }
        match (n.channel.get_ref(), &n.smtp, &n.webhook) {
            (NotifyChannel::Email, Some(s), _) => Email::build(s, base, env)
                .map(Channel::Email)
                .map_err(|e| format!("notify '{route}': {e}")),
            (NotifyChannel::Webhook, _, Some(w)) => Webhook::build(w, base, env)
                .map(Channel::Webhook)
                .map_err(|e| format!("notify '{route}': {e}")),
            _ => Err(format!("notify '{route}': channel settings missing")),
        }
    }

    /// One attempt to deliver `m` to `contact` at `address`; the reason on
    /// failure.
    pub async fn send(
        &self,
        id: i64,
        contact: &str,
        address: &str,
        m: &Message,
    ) -> Result<(), String> {
        let attempt = async {
            match self {
                Channel::Email(e) => e.send(address, m).await,
                Channel::Webhook(w) => w.send(id, contact, address, m).await,
                Channel::Mqtt(q) => q.send(id, contact, address, m).await,
            }
        };
        tokio::time::timeout(ATTEMPT_TIMEOUT, attempt)
            .await
            .unwrap_or_else(|_| Err(format!("no answer in {} s", ATTEMPT_TIMEOUT.as_secs())))
    }
}

fn read_ca(base: &Path, file: &str) -> Result<Vec<u8>, String> {
    let path = base.join(file);
    std::fs::read(&path).map_err(|e| format!("ca_file '{}': {e}", path.display()))
}

pub struct Email {
    transport: AsyncSmtpTransport<Tokio1Executor>,
    from: Mailbox,
}

impl Email {
    fn build(
        s: &SmtpConfig,
        base: &Path,
        env: &dyn Fn(&str) -> Option<String>,
    ) -> Result<Email, String> {
        let host = s.host.get_ref().clone();
        let from: Mailbox = s
            .from
            .get_ref()
            .parse()
            .map_err(|e| format!("smtp from '{}': {e}", s.from.get_ref()))?;
        let tls = || -> Result<TlsParameters, String> {
            let mut b = TlsParameters::builder(host.clone());
            if let Some(ca) = &s.ca_file {
                let pem = read_ca(base, ca.get_ref())?;
                let cert = Certificate::from_pem(&pem)
                    .map_err(|e| format!("ca_file '{}': {e}", ca.get_ref()))?;
                b = b.add_root_certificate(cert);
            }
            b.build_rustls().map_err(|e| format!("smtp TLS: {e}"))
        };
        let tls = match s.security.get_ref() {
            SmtpSecurity::Starttls => Tls::Required(tls()?),
            SmtpSecurity::Tls => Tls::Wrapper(tls()?),
            SmtpSecurity::None => Tls::None,
        };
        let mut b = AsyncSmtpTransport::<Tokio1Executor>::builder_dangerous(host)
            .port(s.port())
            .tls(tls)
            .timeout(Some(ATTEMPT_TIMEOUT));
        if let (Some(user), Some(var)) = (&s.username, &s.password_env) {
            let password = env(var.get_ref()).ok_or_else(|| {
                format!(
                    "the SMTP password is read from {}, which is not set",
                    var.get_ref()
                )
            })?;
            b = b.credentials(Credentials::new(user.get_ref().clone(), password));
        }
        Ok(Email {
            transport: b.build(),
            from,
        })
    }

    async fn send(&self, address: &str, m: &Message) -> Result<(), String> {
        let to: Mailbox = address
            .parse()
            .map_err(|e| format!("address '{address}': {e}"))?;
        let mail = lettre::Message::builder()
            .from(self.from.clone())
            .to(to)
            .subject(&m.subject)
            .header(lettre::message::header::ContentType::TEXT_PLAIN)
            .body(m.text.clone())
            .map_err(|e| format!("building the mail: {e}"))?;
        self.transport
            .send(mail)
            .await
            .map(|_| ())
            .map_err(|e| format!("SMTP: {e}"))
    }
}

pub struct Webhook {
    url: hyper::Uri,
    secret: Vec<u8>,
    tls: Option<tokio_rustls::TlsConnector>,
}

/// What a webhook (or an MQTT subscriber) receives: the message with who it
/// is for.
#[derive(Serialize)]
pub(crate) struct Payload<'a> {
    /// The outbox id: the same id comes again if a delivery is retried.
    pub id: i64,
    pub contact: &'a str,
    pub address: &'a str,
    #[serde(flatten)]
    pub message: &'a Message,
}

/// `sha256=<hex>` of the body under `secret`.
pub fn signature(secret: &[u8], body: &[u8]) -> String {
    let mut mac = Hmac::<Sha256>::new_from_slice(secret).expect("HMAC takes any key length");
    mac.update(body);
    format!("sha256={}", hex::encode(mac.finalize().into_bytes()))
}

impl Webhook {
    fn build(
        w: &WebhookConfig,
        base: &Path,
        env: &dyn Fn(&str) -> Option<String>,
    ) -> Result<Webhook, String> {
        let url: hyper::Uri = w
            .url
            .get_ref()
            .parse()
            .map_err(|e| format!("webhook url '{}': {e}", w.url.get_ref()))?;
        let secret = env(w.secret_env.get_ref())
            .filter(|s| !s.is_empty())
            .ok_or_else(|| {
                format!(
                    "the webhook's HMAC key is read from {}, which is not set",
                    w.secret_env.get_ref()
                )
            })?;
        let tls = if url.scheme_str() == Some("https") {
            let mut roots = rustls::RootCertStore::empty();
            roots.extend(webpki_roots::TLS_SERVER_ROOTS.iter().cloned());
            if let Some(ca) = &w.ca_file {
                let pem = read_ca(base, ca.get_ref())?;
                for c in CertificateDer::pem_slice_iter(&pem) {
                    let c = c.map_err(|e| format!("ca_file '{}': {e}", ca.get_ref()))?;
                    roots
                        .add(c)
                        .map_err(|e| format!("ca_file '{}': {e}", ca.get_ref()))?;
                }
            }
            let config = rustls::ClientConfig::builder_with_provider(Arc::new(
                rustls::crypto::ring::default_provider(),
            ))
            .with_safe_default_protocol_versions()
            .map_err(|e| format!("webhook TLS: {e}"))?
            .with_root_certificates(roots)
            .with_no_client_auth();
            Some(tokio_rustls::TlsConnector::from(Arc::new(config)))
        } else {
            None
        };
        Ok(Webhook {
            url,
            secret: secret.into_bytes(),
            tls,
        })
    }

    async fn send(&self, id: i64, contact: &str, address: &str, m: &Message) -> Result<(), String> {
        let body = serde_json::to_vec(&Payload {
            id,
            contact,
            address,
            message: m,
        })
        .map_err(|e| format!("encoding: {e}"))?;
        let host = self
            .url
            .host()
            .ok_or("webhook url has no host")?
            .to_string();
        let port = self
            .url
            .port_u16()
            .unwrap_or(if self.tls.is_some() { 443 } else { 80 });
        let tcp = tokio::net::TcpStream::connect((host.trim_matches(['[', ']']), port))
            .await
            .map_err(|e| format!("connecting to {host}:{port}: {e}"))?;
        let authority = self
            .url
            .authority()
            .map(|a| a.as_str().to_string())
            .unwrap_or(host.clone());
        let path = self.url.path_and_query().map(|p| p.as_str()).unwrap_or("/");
        let request = hyper::Request::post(path)
            .header(hyper::header::HOST, authority)
            .header(hyper::header::CONTENT_TYPE, "application/json")
            .header(hyper::header::USER_AGENT, "gridscada-notify")
            .header(SIGNATURE_HEADER, signature(&self.secret, &body))
            .body(Full::new(Bytes::from(body)))
            .map_err(|e| format!("request: {e}"))?;
        let status = match &self.tls {
            Some(tls) => {
                let name = ServerName::try_from(host.trim_matches(['[', ']']).to_string())
                    .map_err(|e| format!("webhook host '{host}': {e}"))?;
                let stream = tls
                    .connect(name, tcp)
                    .await
                    .map_err(|e| format!("TLS with {host}: {e}"))?;
                post(stream, request).await?
            }
            None => post(tcp, request).await?,
        };
        if status.is_success() {
            Ok(())
        } else {
            Err(format!("the webhook answered {status}"))
        }
    }
}

async fn post<S>(
    stream: S,
    request: hyper::Request<Full<Bytes>>,
) -> Result<hyper::StatusCode, String>
where
    S: tokio::io::AsyncRead + tokio::io::AsyncWrite + Unpin + Send + 'static,
{
    let (mut sender, conn) =
        hyper::client::conn::http1::handshake(hyper_util::rt::TokioIo::new(stream))
            .await
            .map_err(|e| format!("HTTP: {e}"))?;
    let conn = tokio::spawn(conn);
    let response = sender
        .send_request(request)
        .await
        .map_err(|e| format!("HTTP: {e}"))?;
    let status = response.status();
    // Read the (small) answer so the connection ends cleanly.
    let _ = response.into_body().collect().await;
    conn.abort();
    Ok(status)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn signature_is_hmac_sha256_in_hex() {
        // RFC 4231 test case 2.
        assert_eq!(
            signature(b"Jefe", b"what do ya want for nothing?"),
            "sha256=5bdcc146bf60754e6a042426089575c75a003f089d2739839dec58b964ec3843"
        );
    }
}

#[cfg(test)]
mod payload_tests {
    use super::*;
    use crate::message::{alarm_message, Origin};

    /// The webhook's body and the MQTT payload are this one JSON.
    #[test]
    fn the_webhook_and_mqtt_json_names_the_site_and_server() {
        let origin = Origin {
            site: "substation-7".into(),
            server: Some("scada-a".into()),
        };
        let a = crate::message::tests::alarm();
        let m = alarm_message(&origin, "hook", &a, "https://h/#/alarms", None);
        let j: serde_json::Value = serde_json::to_value(Payload {
            id: 1,
            contact: "Dispatcher",
            address: "desk",
            message: &m,
        })
        .unwrap();
        assert_eq!(j["site"], "substation-7");
        assert_eq!(j["server"], "scada-a");
        let alone = Origin {
            site: "main".into(),
            server: None,
        };
        let m = alarm_message(&alone, "hook", &a, "https://h/#/alarms", None);
        let j = serde_json::to_value(Payload {
            id: 1,
            contact: "Dispatcher",
            address: "desk",
            message: &m,
        })
        .unwrap();
        assert_eq!(j["site"], "main");
        assert!(j["server"].is_null(), "{j}");
    }
}
