//! A database outage as an operator meets it: the store's PostgreSQL
//! connection goes through a relay the test cuts, after which new
//! connections are accepted and never answered (a database host gone
//! quiet, so the pool would wait its whole acquire timeout). A logged-in
//! operator's requests still answer within about a second, with the rights
//! the store last gave them, and the health probes answer by their own
//! store check whatever cookie they carry.

use crate::common;

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use axum::http::{Method, StatusCode};
use common::*;
use parking_lot::Mutex;
use tokio::net::{TcpListener, TcpStream};
use tokio::task::JoinHandle;

/// A loopback relay to PostgreSQL that the test can cut.
struct Relay {
    port: u16,
    up: Arc<AtomicBool>,
    /// The tasks carrying open connections (aborting one closes both ends),
    /// and the connections accepted while cut, held unanswered.
    open: Arc<Mutex<Vec<JoinHandle<()>>>>,
    held: Arc<Mutex<Vec<TcpStream>>>,
}

impl Relay {
    async fn start(upstream: String) -> Relay {
        let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
        let port = listener.local_addr().unwrap().port();
        let up = Arc::new(AtomicBool::new(true));
        let open: Arc<Mutex<Vec<JoinHandle<()>>>> = Arc::default();
        let held: Arc<Mutex<Vec<TcpStream>>> = Arc::default();
        let (u, o, h) = (up.clone(), open.clone(), held.clone());
        tokio::spawn(async move {
            while let Ok((mut client, _)) = listener.accept().await {
                if !u.load(Ordering::SeqCst) {
                    h.lock().push(client);
                    continue;
                }
                let upstream = upstream.clone();
                o.lock().push(tokio::spawn(async move {
                    if let Ok(mut server) = TcpStream::connect(&upstream).await {
                        let _ = tokio::io::copy_bidirectional(&mut client, &mut server).await;
                    }
                }));
            }
        });
        Relay {
            port,
            up,
            open,
            held,
        }
    }

    /// Severs the open connections; new ones are accepted, never answered.
    fn cut(&self) {
        self.up.store(false, Ordering::SeqCst);
        for t in self.open.lock().drain(..) {
            t.abort();
        }
    }

    fn restore(&self) {
        self.up.store(true, Ordering::SeqCst);
        self.held.lock().clear();
    }
}

/// `url` with its `host:port` replaced by the relay's; and the upstream.
fn via(url: &str, port: u16) -> (String, String) {
    let rest = url.split_once("://").map_or(url, |(_, r)| r);
    let after_user = rest.rsplit_once('@').map_or(rest, |(_, h)| h);
    let hostport = after_user.split(['/', '?']).next().unwrap().to_string();
    let upstream = if hostport.contains(':') {
        hostport.clone()
    } else {
        format!("{hostport}:5432")
    };
    (
        url.replacen(&hostport, &format!("127.0.0.1:{port}"), 1),
        upstream,
    )
}

/// A request's answer and how long it took; a panic instead of a hang.
async fn timed(h: &Harness, path: &str, cookie: &str) -> (Resp, Duration) {
    let t = Instant::now();
    let r = tokio::time::timeout(
        Duration::from_secs(5),
        h.call(Method::GET, path, Some(cookie), None),
    )
    .await
    .unwrap_or_else(|_| panic!("GET {path} with a session cookie: no answer within 5 s"));
    (r, t.elapsed())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_logged_in_operator_keeps_working_through_a_database_outage() {
    let Some(url) = pg_url("outage") else { return };
    let relay = Relay::start(via(&url, 0).1).await;
    let (through, _) = via(&url, relay.port);
    let h = Harness::new(Options {
        postgres: Some(through),
        ..Options::default()
    })
    .await;
    let op = h.login("operator", PASSWORD).await;
    let tag = format!("/api/tags/{}", seg(TAG_RO));
    let (r, _) = timed(&h, &tag, &op).await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text());
    let before = timed(&h, "/api/session", &op).await.0.json();

    relay.cut();
    // The rights the store last gave, within the default store_wait_ms
    // (500 ms) and some slack, not after the pool's acquire timeout.
    for _ in 0..2 {
        let (r, took) = timed(&h, "/api/session", &op).await;
        assert!(
            took < Duration::from_millis(1_200),
            "/api/session took {took:?}"
        );
        assert_eq!(r.json(), before);
        let (r, took) = timed(&h, &tag, &op).await;
        assert!(took < Duration::from_millis(1_200), "{tag} took {took:?}");
        assert_eq!(r.status, StatusCode::OK, "{}", r.text());
    }
    // The probes never look at the session: they answer by their own store
    // check (2 s), whatever cookie they carry.
    for probe in ["/healthz", "/readyz"] {
        let (r, took) = timed(&h, probe, &op).await;
        assert!(took < Duration::from_millis(2_500), "{probe} took {took:?}");
        assert_eq!(r.status, StatusCode::SERVICE_UNAVAILABLE, "{probe}");
    }

    relay.restore();
    h.cleanup().await;
}
