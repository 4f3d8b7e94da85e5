//! # gridscada-opcua: the OPC UA server northbound
//!
//! **Owns:** the OPC UA server (async-opcua) that shows the tag database to
//! OPC UA clients: the address space built from the tag names (`nodes.rs`),
//! the mapping of quality, types and values (`model.rs`), sessions checked
//! against gridscada's users and roles (`users.rs`), its endpoints and
//! certificate store, and its figures for `/metrics`.
//!
//! **Must not touch:** Modbus, SQL or HTTP. It reads the tag database, and
//! commands and logins go through the web layer's door-independent gates
//! (`gridscada_web::command`: the confirmed, audited write and the login
//! check), so an OPC UA write is checked and recorded exactly like an HMI
//! write.

mod gate;
mod model;
mod nodes;
pub mod pki;
mod users;

use std::net::SocketAddr;
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

use gridscada_config::{OpcUaConfig, OpcUaSecurity};
use gridscada_web::metrics::Prom;
use gridscada_web::WebState;
use opcua::crypto::SecurityPolicy;
use opcua::server::node_manager::memory::InMemoryNodeManagerBuilder;
use opcua::server::{ServerBuilder, ServerEndpoint, ServerHandle};
use opcua::types::{MessageSecurityMode, VariableId, Variant};

pub use model::{data_type_of, node_path, status_of};
pub use nodes::NAMESPACE_URI;

/// Counters for `/metrics`; sessions and subscriptions come from the
/// server's own diagnostics.
#[derive(Default)]
pub struct Metrics {
    /// Tag values read (one per node in a Read).
    pub reads: AtomicU64,
    /// Writes the device confirmed.
    pub writes: AtomicU64,
    /// Writes refused before the device (rights, area, read-only, bad
    /// value, engineering limits, a standby server).
    pub writes_refused: AtomicU64,
    /// Writes the device or the link failed (or did not confirm in time).
    pub writes_failed: AtomicU64,
    /// Username logins refused.
    pub logins_refused: AtomicU64,
    /// Tag changes handed to monitored items.
    pub notifications: AtomicU64,
    /// TCP connections open on the OPC UA port now.
    pub connections: AtomicU64,
    /// Connections closed at once: the global or the client's cap was
    /// reached.
    pub connections_refused: AtomicU64,
    /// Accepts that failed (out of descriptors, typically).
    pub accept_errors: AtomicU64,
}

/// How long a new connection has to say Hello, and then to open its secure
/// channel, before it is closed (async-opcua's `hello_timeout`).
pub const HELLO_TIMEOUT_S: u32 = 5;

/// The running OPC UA server.
pub struct OpcUaServer {
    handle: ServerHandle,
    metrics: Arc<Metrics>,
    addr: SocketAddr,
    endpoint: String,
    task: tokio::task::JoinHandle<()>,
    feed: tokio::task::JoinHandle<()>,
    gate: tokio::task::JoinHandle<()>,
}

impl OpcUaServer {
    /// Binds `[opcua] listen` and starts serving the tags of `web`'s tag
    /// database. The certificate store lives in `data_dir/pki_dir`.
    pub async fn start(
        cfg: &OpcUaConfig,
        data_dir: &Path,
        web: WebState,
    ) -> Result<OpcUaServer, String> {
        let listen: SocketAddr = cfg.listen.get_ref().parse().map_err(|_| {
            format!(
                "[opcua] listen: '{}' is not an address",
                cfg.listen.get_ref()
            )
        })?;
        let listener = tokio::net::TcpListener::bind(listen)
            .await
            .map_err(|e| format!("[opcua] listen: cannot bind {listen}: {e}"))?;
        let addr = listener.local_addr().map_err(|e| e.to_string())?;
        let host = match &cfg.host {
            Some(h) => h.get_ref().clone(),
            None if addr.ip().is_unspecified() => hostname(),
            None => addr.ip().to_string(),
        };
        let pki = data_dir.join(cfg.pki_dir.get_ref());
        let cert = pki.join("own/cert.der");
        if !cfg.create_certificate && !cert.exists() {
            return Err(format!(
                "[opcua] no server certificate at {} and create_certificate = false",
                cert.display()
            ));
        }
        let metrics = Arc::new(Metrics::default());
        let users = Arc::new(
            users::Users::new(web.clone(), cfg.anonymous, metrics.clone()).with_guest_reads(),
        );
        let anonymous_ids: Vec<String> = if cfg.anonymous {
            vec![opcua::server::ANONYMOUS_USER_TOKEN_ID.to_string()]
        } else {
            vec![]
        };
        let mut builder = ServerBuilder::new()
            .application_name("gridscada")
            .application_uri(format!("urn:{host}:gridscada"))
            .product_uri("urn:gridscada")
            .pki_dir(&pki)
            .create_sample_keypair(cfg.create_certificate)
            .certificate_path("own/cert.der")
            .private_key_path("private/private.pem")
            .trust_client_certs(cfg.trust_all_clients)
            .hello_timeout(HELLO_TIMEOUT_S)
            .host(host.clone())
            .port(addr.port())
            .discovery_urls(vec!["/".to_string()])
            .diagnostics_enabled(true)
            .with_authenticator(users.clone());
        for s in cfg.security.get_ref() {
            let (id, policy, mode) = match s {
                OpcUaSecurity::None => ("none", SecurityPolicy::None, MessageSecurityMode::None),
                OpcUaSecurity::Basic256Sha256Sign => (
                    "basic256sha256_sign",
                    SecurityPolicy::Basic256Sha256,
                    MessageSecurityMode::Sign,
                ),
                OpcUaSecurity::Basic256Sha256SignEncrypt => (
                    "basic256sha256_sign_encrypt",
                    SecurityPolicy::Basic256Sha256,
                    MessageSecurityMode::SignAndEncrypt,
                ),
            };
            let mut endpoint = ServerEndpoint::new("/", policy, mode, &anonymous_ids);
            if policy == SecurityPolicy::None {
                // Passwords never cross in clear, even here.
                endpoint.password_security_policy =
                    Some(SecurityPolicy::Basic256Sha256.to_string());
            }
            builder = builder.add_endpoint(id, endpoint);
        }
        // The node manager learns the tag namespace's index when the server
        // builds it, and hands back the tag space the feed needs.
        let built: Arc<std::sync::OnceLock<Arc<nodes::TagSpace>>> = Default::default();
        builder =
            builder.with_node_manager(InMemoryNodeManagerBuilder::new(nodes::TagNodesBuilder {
                web,
                metrics: metrics.clone(),
                users,
                built: built.clone(),
            }));
        let (server, handle) = builder
            .build()
            .map_err(|e| format!("[opcua]: the OPC UA server cannot start: {e}"))?;
        let space = built
            .get()
            .cloned()
            .ok_or("[opcua]: the tag node manager was not built")?;
        let endpoint = format!("opc.tcp://{host}:{}/", addr.port());
        // async-opcua serves on a loopback port of its own; the gate relays
        // what it admits from the public one (gate.rs).
        let inner = tokio::net::TcpListener::bind((std::net::Ipv4Addr::LOCALHOST, 0))
            .await
            .map_err(|e| format!("[opcua]: cannot bind the server's loopback port: {e}"))?;
        let inner_addr = inner.local_addr().map_err(|e| e.to_string())?;
        let task = tokio::spawn(async move {
            if let Err(e) = server.run_with(inner).await {
                tracing::error!(error = %e, "the OPC UA server stopped");
            }
        });
        // `run_with` records the port it listens on, which the endpoints'
        // URLs would then name: give them the public port back before the
        // first client comes.
        let info = handle.info().clone();
        let announced = tokio::time::timeout(std::time::Duration::from_secs(10), async {
            while info.port.load(Ordering::Relaxed) != inner_addr.port() {
                tokio::time::sleep(std::time::Duration::from_millis(5)).await;
            }
            info.port.store(addr.port(), Ordering::Relaxed);
        })
        .await;
        if announced.is_err() {
            handle.cancel();
            return Err("[opcua]: the OPC UA server did not start listening".into());
        }
        let gate = tokio::spawn(gate::run(
            listener,
            inner_addr,
            gate::Limits {
                max_connections: *cfg.max_connections.get_ref() as usize,
                max_per_client: cfg.per_client_cap() as usize,
            },
            metrics.clone(),
            pki::RejectedSweep::new(&pki),
        ));
        let feed = tokio::spawn(nodes::feed(space, handle.subscriptions().clone()));
        tracing::info!(%addr, %endpoint, "OPC UA server listening");
        Ok(OpcUaServer {
            handle,
            metrics,
            addr,
            endpoint,
            task,
            feed,
            gate,
        })
    }

    /// The address the server listens on.
    pub fn local_addr(&self) -> SocketAddr {
        self.addr
    }

    /// The endpoint URL it announces.
    pub fn endpoint(&self) -> &str {
        &self.endpoint
    }

    /// The server's figures, for `/metrics`.
    pub fn figures(&self) -> Figures {
        Figures {
            handle: self.handle.clone(),
            metrics: self.metrics.clone(),
        }
    }

    /// Stops accepting sessions and ends the server.
    pub async fn shutdown(self) {
        self.gate.abort();
        self.handle.cancel();
        self.feed.abort();
        let _ = tokio::time::timeout(std::time::Duration::from_secs(5), self.task).await;
    }
}

/// A handle on the running server's figures.
#[derive(Clone)]
pub struct Figures {
    handle: ServerHandle,
    metrics: Arc<Metrics>,
}

impl Figures {
    /// The counters of the server.
    pub fn metrics(&self) -> &Metrics {
        &self.metrics
    }

    /// Writes the server's figures in the Prometheus text format.
    pub fn render(&self, out: &mut Prom) {
        let summary = self.handle.info().summary();
        let count = |v: VariableId| match summary.get(v).and_then(|d| d.value) {
            Some(Variant::UInt32(n)) => f64::from(n),
            _ => 0.0,
        };
        out.gauge(
            "gridscada_opcua_sessions",
            "OPC UA sessions open now.",
            &[],
            count(
                VariableId::Server_ServerDiagnostics_ServerDiagnosticsSummary_CurrentSessionCount,
            ),
        );
        out.gauge(
            "gridscada_opcua_subscriptions",
            "OPC UA subscriptions open now.",
            &[],
            count(
                VariableId::Server_ServerDiagnostics_ServerDiagnosticsSummary_CurrentSubscriptionCount,
            ),
        );
        out.counter(
            "gridscada_opcua_sessions_opened_total",
            "OPC UA sessions opened since start.",
            &[],
            count(
                VariableId::Server_ServerDiagnostics_ServerDiagnosticsSummary_CumulatedSessionCount,
            ),
        );
        let m = &self.metrics;
        out.gauge(
            "gridscada_opcua_connections",
            "TCP connections open on the OPC UA port now.",
            &[],
            m.connections.load(Ordering::Relaxed) as f64,
        );
        for (name, help, v) in [
            (
                "gridscada_opcua_connections_refused_total",
                "OPC UA connections closed at once: the global or the client address's cap of open connections was reached.",
                &m.connections_refused,
            ),
            (
                "gridscada_opcua_accept_errors_total",
                "Failed accepts on the OPC UA port (out of descriptors, typically); each one pauses accepting.",
                &m.accept_errors,
            ),
            (
                "gridscada_opcua_reads_total",
                "Tag values read over OPC UA.",
                &m.reads,
            ),
            (
                "gridscada_opcua_writes_total",
                "OPC UA writes the device confirmed.",
                &m.writes,
            ),
            (
                "gridscada_opcua_writes_refused_total",
                "OPC UA writes refused before the device (rights, area, read-only tag, bad value, engineering limits, standby).",
                &m.writes_refused,
            ),
            (
                "gridscada_opcua_writes_failed_total",
                "OPC UA writes the device or the link failed, or did not confirm in time.",
                &m.writes_failed,
            ),
            (
                "gridscada_opcua_logins_refused_total",
                "OPC UA username logins refused.",
                &m.logins_refused,
            ),
            (
                "gridscada_opcua_notifications_total",
                "Tag changes handed to OPC UA monitored items.",
                &m.notifications,
            ),
        ] {
            out.counter(name, help, &[], v.load(Ordering::Relaxed) as f64);
        }
    }
}

/// This machine's host name, for the endpoint URL when listening on every
/// address.
fn hostname() -> String {
    std::fs::read_to_string("/proc/sys/kernel/hostname")
        .ok()
        .map(|h| h.trim().to_string())
        .filter(|h| !h.is_empty())
        .unwrap_or_else(|| "localhost".into())
}
