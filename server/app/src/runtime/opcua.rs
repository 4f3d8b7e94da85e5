//! The OPC UA server (`[opcua]`, or `demo --opcua PORT`): started on the
//! web layer's state, so its writes and logins pass the same gates, and its
//! figures added to `/metrics`.

use std::path::Path;
use std::sync::Arc;

use anyhow::anyhow;
use gridscada_config::{OpcUaConfig, OpcUaSecurity, Plant};
use gridscada_opcua::OpcUaServer;
use gridscada_web::metrics::{MetricsSource, Prom, StackHealth};
use gridscada_web::WebState;
use serde_spanned::Spanned;

/// What `demo --opcua PORT` serves: loopback, every endpoint (none too, for
/// trying clients out), a self-made certificate, client certificates trusted
/// on first sight, no anonymous sessions (the demo's accounts log in).
pub fn demo_config(port: u16) -> OpcUaConfig {
    OpcUaConfig {
        listen: Spanned::new(0..0, format!("127.0.0.1:{port}")),
        host: Some(Spanned::new(0..0, "127.0.0.1".into())),
        security: Spanned::new(
            0..0,
            vec![
                OpcUaSecurity::None,
                OpcUaSecurity::Basic256Sha256Sign,
                OpcUaSecurity::Basic256Sha256SignEncrypt,
            ],
        ),
        anonymous: false,
        pki_dir: Spanned::new(0..0, "opcua-pki".into()),
        create_certificate: true,
        trust_all_clients: true,
        max_connections: Spanned::new(0..0, gridscada_config::DEFAULT_OPCUA_MAX_CONNECTIONS),
        max_connections_per_client: Spanned::new(
            0..0,
            gridscada_config::DEFAULT_OPCUA_MAX_CONNECTIONS_PER_CLIENT,
        ),
    }
}

/// Starts the OPC UA server if the plant configures one, and adds its
/// figures to `web`'s `/metrics`.
pub async fn start(
    plant: &Plant,
    data: &Path,
    web: &mut WebState,
) -> anyhow::Result<Option<OpcUaServer>> {
    let Some(cfg) = &plant.opcua else {
        return Ok(None);
    };
    let server = OpcUaServer::start(cfg, data, web.clone())
        .await
        .map_err(|e| anyhow!(e))?;
    web.metrics = Some(Arc::new(WithOpcUa {
        inner: web.metrics.take(),
        opcua: server.figures(),
    }));
    Ok(Some(server))
}

/// The stack's figures, then the OPC UA server's.
struct WithOpcUa {
    inner: Option<Arc<dyn MetricsSource>>,
    opcua: gridscada_opcua::Figures,
}

impl MetricsSource for WithOpcUa {
    fn render(&self, out: &mut Prom) {
        if let Some(m) = &self.inner {
            m.render(out);
        }
        self.opcua.render(out);
    }

    fn health(&self) -> StackHealth {
        self.inner.as_ref().map(|m| m.health()).unwrap_or_default()
    }
}
