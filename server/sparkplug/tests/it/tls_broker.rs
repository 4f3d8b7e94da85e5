//! TLS to a real broker: Debian's mosquitto with a certificate signed by a
//! test CA. The connection options of `[mqtt]` (`mqtts://`, `ca_file`, on
//! rustls with ring) connect when they trust that CA, and fail on TLS when
//! they trust another. Skipped (with a note) where mosquitto is not
//! installed; `scripts/test-all.sh` installs it.

use crate::common;

use std::path::Path;
use std::time::Duration;

use common::{free_port, mosquitto, Broker};

use gridscada_sparkplug::connection;
use rumqttc::{AsyncClient, ConnectionError, Event, Packet};

/// A CA, and a certificate for localhost signed by it: (CA PEM, cert PEM, key PEM).
fn ca_and_server() -> (String, String, String) {
    let mut ca_params = rcgen::CertificateParams::new(Vec::<String>::new()).unwrap();
    ca_params.is_ca = rcgen::IsCa::Ca(rcgen::BasicConstraints::Unconstrained);
    ca_params
        .distinguished_name
        .push(rcgen::DnType::CommonName, "gridscada test CA");
    let ca_key = rcgen::KeyPair::generate().unwrap();
    let ca = ca_params.self_signed(&ca_key).unwrap();
    let params = rcgen::CertificateParams::new(vec!["localhost".to_string()]).unwrap();
    let key = rcgen::KeyPair::generate().unwrap();
    let cert = params.signed_by(&key, &ca, &ca_key).unwrap();
    (ca.pem(), cert.pem(), key.serialize_pem())
}

fn plant(dir: &Path, port: u16, ca_file: &str) -> gridscada_config::Plant {
    let main = format!(
        "tag_files = [\"t.toml\"]\n[mqtt]\nbroker = \"mqtts://localhost:{port}\"\ngroup = \"G\"\nca_file = \"{ca_file}\"\nkeep_alive_s = 5\n[mqtt.edge]\nnode = \"n1\"\n"
    );
    std::fs::write(dir.join("gridscada.toml"), main).unwrap();
    std::fs::write(
        dir.join("t.toml"),
        "[[device]]\nname = \"D1\"\nprotocol = \"tcp\"\naddress = \"127.0.0.1:1502\"\n",
    )
    .unwrap();
    gridscada_config::load_path(dir).unwrap_or_else(|d| panic!("{d:?}"))
}

/// Polls until the broker's ConnAck or the first error.
async fn first_outcome(opts: rumqttc::MqttOptions) -> Result<(), ConnectionError> {
    let (_client, mut eventloop) = AsyncClient::new(opts, 10);
    loop {
        match tokio::time::timeout(Duration::from_secs(10), eventloop.poll())
            .await
            .expect("no answer from the broker within 10 s")
        {
            Ok(Event::Incoming(Packet::ConnAck(_))) => return Ok(()),
            Ok(_) => {}
            Err(e) => return Err(e),
        }
    }
}

#[tokio::test]
async fn mqtts_connects_trusting_the_ca_file_and_not_otherwise() {
    let Some(bin) = mosquitto() else {
        eprintln!("mosquitto not installed: TLS broker test skipped");
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let (ca, cert, key) = ca_and_server();
    let (other_ca, _, _) = ca_and_server();
    std::fs::write(dir.path().join("ca.pem"), &ca).unwrap();
    std::fs::write(dir.path().join("other-ca.pem"), &other_ca).unwrap();
    std::fs::write(dir.path().join("server.pem"), &cert).unwrap();
    std::fs::write(dir.path().join("server.key"), &key).unwrap();
    let port = free_port();
    let conf = dir.path().join("mosquitto.conf");
    std::fs::write(
        &conf,
        format!(
            "listener {port} 127.0.0.1\nallow_anonymous true\ncertfile {}\nkeyfile {}\n",
            dir.path().join("server.pem").display(),
            dir.path().join("server.key").display()
        ),
    )
    .unwrap();
    let broker = Broker::start(&bin, &conf, port).await;

    let trusted = plant(dir.path(), port, "ca.pem");
    let opts = connection::options(trusted.mqtt.as_ref().unwrap(), "tls-test", dir.path()).unwrap();
    let ok = first_outcome(opts).await;

    let untrusted = plant(dir.path(), port, "other-ca.pem");
    let opts =
        connection::options(untrusted.mqtt.as_ref().unwrap(), "tls-test-2", dir.path()).unwrap();
    let refused = first_outcome(opts).await;

    drop(broker);
    assert!(ok.is_ok(), "trusting the broker's CA: {ok:?}");
    match refused {
        Err(ConnectionError::Tls(e)) => {
            let text = e.to_string();
            assert!(text.to_lowercase().contains("certificate"), "{text}");
        }
        other => panic!("trusting another CA must fail on TLS, got {other:?}"),
    }
}
