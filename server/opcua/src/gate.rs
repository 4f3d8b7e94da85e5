//! The OPC UA port's door. async-opcua 0.19 accepts on a `TcpListener` of
//! its own, with no cap on open connections, and retries a failed accept at
//! once (out of descriptors, it spins). So gridscada accepts on the public
//! port itself and relays each connection it admits to async-opcua on a
//! loopback port: a global and a per-client-address cap, a growing pause
//! after accept errors, and before each connection the sweep of trusted
//! certificates left in `rejected/` (`pki.rs`). A connection that does not
//! say Hello and open a secure channel in time is closed by async-opcua
//! (`hello_timeout`); the relay then closes the client's side too.

use std::collections::HashMap;
use std::net::{IpAddr, SocketAddr};
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::Duration;

use parking_lot::Mutex;
use tokio::net::{TcpListener, TcpStream};

use crate::pki::RejectedSweep;
use crate::Metrics;

/// The caps on open connections.
#[derive(Debug, Clone, Copy)]
pub struct Limits {
    pub max_connections: usize,
    pub max_per_client: usize,
}

/// The first pause after a failed accept, doubled up to [`MAX_PAUSE`].
const FIRST_PAUSE: Duration = Duration::from_millis(10);
const MAX_PAUSE: Duration = Duration::from_secs(1);

/// Open connections, in all and by client address.
#[derive(Default)]
struct Open {
    total: usize,
    by_client: HashMap<IpAddr, usize>,
}

/// One admitted connection's place; given back when dropped.
struct Place {
    open: Arc<Mutex<Open>>,
    metrics: Arc<Metrics>,
    client: IpAddr,
}

impl Drop for Place {
    fn drop(&mut self) {
        let mut o = self.open.lock();
        o.total -= 1;
        if let Some(n) = o.by_client.get_mut(&self.client) {
            *n -= 1;
            if *n == 0 {
                o.by_client.remove(&self.client);
            }
        }
        self.metrics.connections.fetch_sub(1, Ordering::Relaxed);
    }
}

/// Why a connection was not admitted.
#[derive(Debug, PartialEq, Eq)]
enum Refusal {
    Full,
    ClientFull,
}

fn admit(
    open: &Arc<Mutex<Open>>,
    metrics: &Arc<Metrics>,
    limits: Limits,
    client: IpAddr,
) -> Result<Place, Refusal> {
    let mut o = open.lock();
    if o.total >= limits.max_connections {
        return Err(Refusal::Full);
    }
    let n = o.by_client.entry(client).or_default();
    if *n >= limits.max_per_client {
        return Err(Refusal::ClientFull);
    }
    *n += 1;
    o.total += 1;
    metrics.connections.fetch_add(1, Ordering::Relaxed);
    Ok(Place {
        open: open.clone(),
        metrics: metrics.clone(),
        client,
    })
}

/// Accepts on `listener` until the task is aborted, relaying what it admits
/// to async-opcua at `inner`.
pub async fn run(
    listener: TcpListener,
    inner: SocketAddr,
    limits: Limits,
    metrics: Arc<Metrics>,
    mut sweep: RejectedSweep,
) {
    let open = Arc::new(Mutex::new(Open::default()));
    let mut pause = FIRST_PAUSE;
    loop {
        let (socket, peer) = match listener.accept().await {
            Ok(c) => {
                pause = FIRST_PAUSE;
                c
            }
            Err(e) => {
                // Out of descriptors, typically: retrying at once only burns
                // the CPU the open connections need to finish.
                metrics.accept_errors.fetch_add(1, Ordering::Relaxed);
                tracing::warn!(error = %e, pause_ms = pause.as_millis() as u64, "OPC UA: accepting a connection failed");
                tokio::time::sleep(pause).await;
                pause = (pause * 2).min(MAX_PAUSE);
                continue;
            }
        };
        let place = match admit(&open, &metrics, limits, peer.ip()) {
            Ok(p) => p,
            Err(why) => {
                metrics.connections_refused.fetch_add(1, Ordering::Relaxed);
                tracing::debug!(%peer, ?why, "OPC UA: connection refused, too many open");
                continue;
            }
        };
        for name in sweep.run() {
            tracing::info!(certificate = %name, "OPC UA: trusted, so removed from rejected/");
        }
        tokio::spawn(relay(socket, inner, place));
    }
}

/// Copies both ways until either side closes, then closes both.
async fn relay(client: TcpStream, inner: SocketAddr, _place: Place) {
    let Ok(server) = TcpStream::connect(inner).await else {
        tracing::warn!(%inner, "OPC UA: the server's loopback port does not answer");
        return;
    };
    let _ = client.set_nodelay(true);
    let _ = server.set_nodelay(true);
    let (mut cr, mut cw) = client.into_split();
    let (mut sr, mut sw) = server.into_split();
    tokio::select! {
        _ = tokio::io::copy(&mut cr, &mut sw) => {}
        _ = tokio::io::copy(&mut sr, &mut cw) => {}
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn caps_count_all_and_per_client_and_give_places_back() {
        let open = Arc::new(Mutex::new(Open::default()));
        let metrics = Arc::new(Metrics::default());
        let limits = Limits {
            max_connections: 3,
            max_per_client: 2,
        };
        let a: IpAddr = "10.0.0.1".parse().unwrap();
        let b: IpAddr = "10.0.0.2".parse().unwrap();
        let c: IpAddr = "10.0.0.3".parse().unwrap();
        let a1 = admit(&open, &metrics, limits, a).unwrap();
        let _a2 = admit(&open, &metrics, limits, a).unwrap();
        assert_eq!(
            admit(&open, &metrics, limits, a).err(),
            Some(Refusal::ClientFull)
        );
        let _b1 = admit(&open, &metrics, limits, b).unwrap();
        assert_eq!(admit(&open, &metrics, limits, c).err(), Some(Refusal::Full));
        assert_eq!(metrics.connections.load(Ordering::Relaxed), 3);
        drop(a1);
        assert_eq!(metrics.connections.load(Ordering::Relaxed), 2);
        admit(&open, &metrics, limits, c).unwrap();
    }
}
