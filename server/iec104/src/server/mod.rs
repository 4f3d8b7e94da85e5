//! The controlled station (server) toward a control centre
//! (`[iec104_server]`): the exported tags answered from the tag database
//! (interrogation, spontaneous data on change with time tags and quality,
//! periodic data), and the centre's commands, direct or select-before-
//! operate, through the same audited write as the HMI's, answered with
//! ACT_CON and ACT_TERM or a negative confirmation.
//!
//! **Must not touch:** the field side (it reads the tag database and writes
//! through the one `TagWriter`), SQL (the audit record goes through
//! `gridscada_store::command`), HTTP.

mod conn;
mod export;

use std::collections::HashMap;
use std::net::{IpAddr, SocketAddr};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Duration;

use gridscada_config::{Iec104ServerConfig, Plant};
use gridscada_store::command::CommandAudit;
use gridscada_tagdb::{Clock, TagDb, TagWriter};
use tokio::net::TcpListener;
use tokio::sync::watch;
use tokio::task::JoinHandle;

use export::Export;

/// What the server needs from the running stack.
pub struct ServerContext {
    pub db: Arc<TagDb>,
    /// The one field writer (`gridscada_field::Router`).
    pub writer: Arc<dyn TagWriter>,
    pub audit: Arc<dyn CommandAudit>,
    pub clock: Arc<dyn Clock>,
    /// Where the server counts (the `/metrics` source holds it too).
    pub counters: Arc<ServerCounters>,
}

/// The server's figures, for `/metrics`.
#[derive(Debug, Default)]
pub struct ServerCounters {
    pub connections: AtomicU64,
    pub refused_connections: AtomicU64,
    pub interrogations: AtomicU64,
    pub spontaneous: AtomicU64,
    pub commands: AtomicU64,
    pub commands_refused: AtomicU64,
    pub commands_failed: AtomicU64,
    pub malformed: AtomicU64,
}

/// Settings every connection shares.
pub(crate) struct Shared {
    pub ctx: ServerContext,
    pub exports: Vec<Export>,
    /// Export index by monitored IOA, and by command IOA.
    pub by_ioa: HashMap<u32, usize>,
    pub by_command_ioa: HashMap<u32, usize>,
    /// Export index by tag id.
    pub by_id: HashMap<gridscada_tagdb::TagId, usize>,
    pub common_address: u16,
    pub session: crate::session::Parameters,
    pub select_timeout: Duration,
    /// Interrogation answered with time-tagged types.
    pub interrogation_time_tags: bool,
    pub limits: HashMap<String, (Option<f64>, Option<f64>)>,
    pub role_label: &'static str,
    pub cyclic: Vec<(usize, Duration)>,
    pub counters: Arc<ServerCounters>,
}

/// The running server.
pub struct Iec104Server {
    pub local_addr: SocketAddr,
    counters: Arc<ServerCounters>,
    shutdown: watch::Sender<bool>,
    task: JoinHandle<()>,
}

impl Iec104Server {
    /// Binds `[iec104_server] listen` and serves. Every exported tag must
    /// be in the tag database (configured or derived): `Err` names the one
    /// that is not.
    pub async fn start(
        cfg: &Iec104ServerConfig,
        plant: &Plant,
        ctx: ServerContext,
    ) -> Result<Iec104Server, String> {
        let listen: SocketAddr = cfg.listen.get_ref().parse().map_err(|_| {
            format!(
                "[iec104_server] listen: '{}' is not an address",
                cfg.listen.get_ref()
            )
        })?;
        let listener = TcpListener::bind(listen)
            .await
            .map_err(|e| format!("[iec104_server] cannot listen on {listen}: {e}"))?;
        Iec104Server::start_on(listener, cfg, plant, ctx)
    }

    /// Serves on `listener` (bound by the caller; `cfg.listen` is not
    /// used), e.g. the simulator's station on its own address.
    pub fn start_on(
        listener: TcpListener,
        cfg: &Iec104ServerConfig,
        plant: &Plant,
        ctx: ServerContext,
    ) -> Result<Iec104Server, String> {
        let mut exports = Vec::new();
        let (mut by_ioa, mut by_command_ioa, mut by_id) =
            (HashMap::new(), HashMap::new(), HashMap::new());
        let mut limits = HashMap::new();
        let mut cyclic = Vec::new();
        for p in &cfg.points {
            let tag = p.tag.get_ref();
            let id = ctx.db.id(tag).ok_or_else(|| {
                format!("[iec104_server] point '{tag}': no such tag in the plant (configured or derived)")
            })?;
            let kind = ctx.db.meta(id).map(|m| m.kind).ok_or("tag without meta")?;
            let point = *p.point.get_ref();
            if !point.exports(kind) {
                return Err(format!(
                    "[iec104_server] point '{tag}': a {} point cannot carry its {kind:?} values",
                    point.label()
                ));
            }
            let index = exports.len();
            by_ioa.insert(*p.ioa.get_ref(), index);
            by_id.insert(id, index);
            if p.command.is_some() {
                by_command_ioa.insert(p.command_ioa(), index);
                limits.insert(tag.clone(), plant.write_limits(tag));
            }
            if *p.cyclic_s.get_ref() > 0.0 {
                cyclic.push((index, Duration::from_secs_f64(*p.cyclic_s.get_ref())));
            }
            exports.push(Export {
                tag: tag.clone(),
                id,
                kind,
                ioa: *p.ioa.get_ref(),
                point,
                deadband: *p.deadband.get_ref(),
                command: p.command.as_ref().map(|c| *c.get_ref()),
                command_ioa: p.command_ioa(),
                select: p.select,
            });
        }
        let local_addr = listener.local_addr().map_err(|e| e.to_string())?;
        let allowed: Vec<IpAddr> = cfg
            .allowed_clients
            .iter()
            .filter_map(|a| a.get_ref().parse().ok())
            .collect();
        let counters = Arc::clone(&ctx.counters);
        let secs = |s: f64| Duration::from_secs_f64(s.max(0.001));
        let shared = Arc::new(Shared {
            ctx,
            exports,
            by_ioa,
            by_command_ioa,
            by_id,
            common_address: *cfg.common_address.get_ref(),
            session: crate::session::Parameters {
                k: *cfg.k.get_ref(),
                w: *cfg.w.get_ref(),
                t1: secs(*cfg.t1_s.get_ref()),
                t2: secs(*cfg.t2_s.get_ref()),
                t3: secs(*cfg.t3_s.get_ref()),
            },
            select_timeout: secs(*cfg.select_timeout_s.get_ref()),
            interrogation_time_tags: cfg.interrogation_time_tags,
            limits,
            role_label: cfg.command_role.get_ref().label(),
            cyclic,
            counters: Arc::clone(&counters),
        });
        let (shutdown, shutdown_rx) = watch::channel(false);
        let max = usize::from(*cfg.max_connections.get_ref());
        tracing::info!(%local_addr, points = shared.exports.len(), "IEC 104 server listening");
        let task = tokio::spawn(accept_loop(listener, allowed, max, shared, shutdown_rx));
        Ok(Iec104Server {
            local_addr,
            counters,
            shutdown,
            task,
        })
    }

    pub fn counters(&self) -> Arc<ServerCounters> {
        Arc::clone(&self.counters)
    }

    pub async fn shutdown(self) {
        let _ = self.shutdown.send(true);
        let _ = self.task.await;
    }
}

async fn accept_loop(
    listener: TcpListener,
    allowed: Vec<IpAddr>,
    max: usize,
    shared: Arc<Shared>,
    mut shutdown: watch::Receiver<bool>,
) {
    let mut conns: Vec<JoinHandle<()>> = Vec::new();
    loop {
        let accepted = tokio::select! {
            _ = shutdown.changed() => break,
            a = listener.accept() => a,
        };
        let (stream, peer) = match accepted {
            Ok(a) => a,
            Err(e) => {
                // Out of file descriptors and the like: wait, do not spin.
                tracing::warn!(error = %e, "IEC 104 server: accept failed");
                tokio::time::sleep(Duration::from_millis(200)).await;
                continue;
            }
        };
        conns.retain(|c| !c.is_finished());
        let ip = peer.ip().to_canonical();
        if !allowed.contains(&ip) {
            shared
                .counters
                .refused_connections
                .fetch_add(1, Ordering::Relaxed);
            tracing::warn!(%peer, "IEC 104 server: connection from an address not in allowed_clients, closed");
            continue;
        }
        if conns.len() >= max {
            shared
                .counters
                .refused_connections
                .fetch_add(1, Ordering::Relaxed);
            tracing::warn!(%peer, max, "IEC 104 server: max_connections reached, closed");
            continue;
        }
        shared.counters.connections.fetch_add(1, Ordering::Relaxed);
        tracing::info!(%peer, "IEC 104 server: control centre connected");
        conns.push(tokio::spawn(conn::serve(
            stream,
            peer,
            Arc::clone(&shared),
            shutdown.clone(),
        )));
    }
    for c in conns {
        c.abort();
    }
}
