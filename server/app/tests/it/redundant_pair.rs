//! A redundant pair on PostgreSQL, as two real `gridscada serve` processes
//! on one database and the same simulated devices (`gridscada sim`, a third
//! process, driven through its standard input):
//!
//! - kill -9 of the active server in the middle of fault-isolation
//!   sequences on both panels, at random points, many times: the standby
//!   takes over within the bound and finishes each interrupted sequence:
//!   the panel ends isolated on the right zone with every healthy zone on,
//!   without an operator's reset (issue 35);
//! - SIGSTOP of the active server longer than its lease, then SIGCONT: it
//!   finds itself deposed and sends nothing;
//! - its database connection cut through a relay the test controls: it
//!   steps down before its lease expires and the standby takes over; an
//!   operator's HMI on it keeps answering at once, and its `/api/pair`
//!   says standby;
//! - a command sent to the standby is refused, naming the active server;
//!   one login works on both (sessions are in the store).
//!
//! Every Modbus write is logged by the writer with its server and epoch
//! (`gridscada::field_write`, JSON logs); the fencing is asserted from that
//! record: each epoch belongs to one server, no write of an older epoch
//! follows a write of a newer one, and no zone known faulty is closed by a
//! later epoch.

use crate::common;

use std::collections::{BTreeMap, HashMap};
use std::net::{Shutdown, TcpListener, TcpStream};
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use common::pair::*;
use common::{wait_for, Client};
use serde_json::{json, Value};

/// The configured takeover bound (the default).
const TAKEOVER_BOUND: Duration = Duration::from_secs(5);

fn wall() -> f64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .unwrap()
        .as_secs_f64()
}

/// A small, seedable random source (no extra dependency).
struct Rng(u64);
impl Rng {
    fn below(&mut self, n: u64) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0 % n
    }
}

/// A loopback TCP relay to PostgreSQL that the test can cut.
struct Relay {
    port: u16,
    up: Arc<AtomicBool>,
    open: Arc<Mutex<Vec<TcpStream>>>,
    /// Connections accepted while cut, held unanswered (a database host
    /// gone quiet: a pool would wait its whole acquire timeout).
    held: Arc<Mutex<Vec<TcpStream>>>,
}

impl Relay {
    fn start(upstream: String) -> Relay {
        let listener = TcpListener::bind("127.0.0.1:0").unwrap();
        let port = listener.local_addr().unwrap().port();
        let up = Arc::new(AtomicBool::new(true));
        let open: Arc<Mutex<Vec<TcpStream>>> = Arc::default();
        let held: Arc<Mutex<Vec<TcpStream>>> = Arc::default();
        let (u, o, h) = (up.clone(), open.clone(), held.clone());
        std::thread::spawn(move || {
            for client in listener.incoming() {
                let Ok(client) = client else { continue };
                if !u.load(Ordering::SeqCst) {
                    h.lock().unwrap().push(client);
                    continue;
                }
                let Ok(server) = TcpStream::connect(&upstream) else {
                    continue;
                };
                {
                    let mut o = o.lock().unwrap();
                    o.push(client.try_clone().unwrap());
                    o.push(server.try_clone().unwrap());
                }
                for (mut from, mut to) in [
                    (client.try_clone().unwrap(), server.try_clone().unwrap()),
                    (server, client),
                ] {
                    std::thread::spawn(move || {
                        let _ = std::io::copy(&mut from, &mut to);
                        let _ = to.shutdown(Shutdown::Both);
                    });
                }
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
        for s in self.open.lock().unwrap().drain(..) {
            let _ = s.shutdown(Shutdown::Both);
        }
    }

    fn restore(&self) {
        self.up.store(true, Ordering::SeqCst);
        for s in self.held.lock().unwrap().drain(..) {
            let _ = s.shutdown(Shutdown::Both);
        }
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

/// The log lines of `log` whose message contains `what`, as times.
fn logged_at(log: &Path, what: &str) -> Vec<f64> {
    std::fs::read_to_string(log)
        .unwrap_or_default()
        .lines()
        .filter_map(|l| serde_json::from_str::<Value>(l).ok())
        .filter(|v| {
            v["fields"]["message"]
                .as_str()
                .is_some_and(|m| m.contains(what))
        })
        .filter_map(|v| rfc3339(v["timestamp"].as_str()?))
        .collect()
}

#[test]
fn the_pair_keeps_isolating_faults_through_kills_freezes_and_a_cut_database() {
    let _one_at_a_time = common::kill_test_lock();
    let Ok(base) = std::env::var("GRIDSCADA_TEST_PG_URL") else {
        assert!(
            std::env::var("GRIDSCADA_REQUIRE_PG").as_deref() != Ok("1"),
            "GRIDSCADA_REQUIRE_PG=1 but GRIDSCADA_TEST_PG_URL is not set"
        );
        eprintln!(
            "!!!!!!!! SKIPPED redundant pair test: GRIDSCADA_TEST_PG_URL is not set !!!!!!!!"
        );
        return;
    };
    let rounds: usize = std::env::var("GRIDSCADA_PAIR_ROUNDS")
        .ok()
        .and_then(|r| r.parse().ok())
        .unwrap_or(6);
    let seed = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .unwrap()
        .as_nanos() as u64
        | 1;
    println!("seed {seed}");
    let mut rng = Rng(seed);
    let db = Database::create(&base);
    // Server a reaches the database through a relay the test can cut.
    let (_, upstream) = via(&db.url, 0);
    let relay = Relay::start(upstream);
    let (a_url, _) = via(&db.url, relay.port);

    let dir = tempfile::tempdir().unwrap();
    let (pa, pb) = (free_port(), free_port());
    let pair = [("a", pa), ("b", pb)];
    let port_base = port_block(100);
    let ca = write_plant(&dir.path().join("a"), &a_url, "a", &pair, port_base);
    let cb = write_plant(&dir.path().join("b"), &db.url, "b", &pair, port_base);

    let mut sim = Sim::start(&cb, &dir.path().join("sim.log"));
    // The operator, in the shared database.
    add_operator(&cb);

    let mut servers = [
        Server {
            name: "a",
            config: ca,
            port: pa,
            log: dir.path().join("a.log"),
            child: None,
        },
        Server {
            name: "b",
            config: cb,
            port: pb,
            log: dir.path().join("b.log"),
            child: None,
        },
    ];
    servers[0].start();
    let start = Instant::now();
    while servers[0].active() != Some(true) {
        assert!(
            start.elapsed() < Duration::from_secs(20),
            "a did not become active: {}",
            common::tail(&servers[0].log)
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    servers[1].start();
    std::thread::sleep(Duration::from_secs(1));
    assert_eq!(servers[1].active(), Some(false), "b is on standby");

    // One login, both servers (sessions are in the store); the standby
    // refuses commands, naming the active server, and reports the pair.
    let op_a = login(&servers[0].addr());
    let mut op_b = Client::new(&servers[1].addr());
    op_b.cookie = op_a.cookie.clone();
    let (s, b) = op_b.post("/api/panels/ss1/reset", json!({}));
    assert_eq!(s, 503, "{b}");
    let detail = b.to_string();
    assert!(
        detail.contains(&format!("active server a (http://127.0.0.1:{pa})")),
        "{detail}"
    );
    let (s, b) = op_b.post("/api/tags/SS1.Zone4.Cmd/write", json!({"value": true}));
    assert_eq!(s, 503, "{b}");
    wait_for("b's view of the pair", Duration::from_secs(5), || {
        let v = op_b.get_ok("/api/pair");
        (v["role"] == "standby" && v["active"] == "a" && v["healthy"] == true).then_some(())
    });

    // Kill -9 in the middle of fault isolation, at random points.
    let prefixes: HashMap<&str, &str> = [("ss1", "SS1"), ("css1", "CSS1")].into();
    let mut takeovers = Vec::new();
    // (round, epoch before the kill, panel, zone known faulty at the kill)
    let mut known_faulty: Vec<(usize, u64, &str, u64)> = Vec::new();
    let mut outcomes: BTreeMap<String, usize> = BTreeMap::new();
    let mut round_windows = Vec::new();
    for round in 0..rounds {
        let (ai, _) = wait_active(&[&servers[0], &servers[1]], Duration::from_secs(10));
        let si = 1 - ai;
        let mut op = Client::new(&servers[ai].addr());
        op.cookie = op_a.cookie.clone();
        let epoch = op.get_ok("/api/pair")["epoch"].as_u64().unwrap();
        let faults = [("ss1", 1 + rng.below(4)), ("css1", 1 + rng.below(4))];
        for (panel, zone) in faults {
            sim.cmd(&format!("fault {panel} {zone} permanent"));
        }
        // Even rounds: a kill in the middle of the sequences; odd rounds:
        // mostly after a panel has isolated its zone, so the new active
        // server takes over a zone known faulty.
        let delay = if round % 2 == 0 {
            rng.below(6000)
        } else {
            6000 + rng.below(8000)
        };
        std::thread::sleep(Duration::from_millis(delay));
        // What the active server knows as faulty just before the kill.
        for (panel, zone) in faults {
            if let Ok((200, p)) = op.try_request("GET", &format!("/api/panels/{panel}"), None) {
                if p["faulty_zones"]
                    .as_array()
                    .is_some_and(|z| z.contains(&json!(zone)))
                {
                    known_faulty.push((round, epoch, panel, zone));
                }
            }
        }
        let killed_at = wall();
        servers[ai].kill9();
        let killed = Instant::now();
        let (now_active, _) = wait_active(&[&servers[0], &servers[1]], Duration::from_secs(15));
        let took = killed.elapsed();
        assert_eq!(now_active, si);
        assert!(
            took <= TAKEOVER_BOUND,
            "round {round}: takeover took {took:?}, over the bound"
        );
        takeovers.push(took);
        servers[ai].start();
        let mut op = Client::new(&servers[si].addr());
        op.cookie = op_a.cookie.clone();
        for (panel, _) in faults {
            let p = settled(&mut op, panel, Duration::from_secs(60));
            let outcome = if p["lockout"] == true {
                println!("round {round}: {panel} locked out: {p}");
                // Why, from both servers' logs and the simulator's.
                for s in &servers {
                    println!("--- {}.log ---\n{}", s.name, common::tail(&s.log));
                }
                println!(
                    "--- sim.log ---\n{}",
                    common::tail(&dir.path().join("sim.log"))
                );
                "lockout".to_string()
            } else {
                format!("isolated {}", p["faulty_zones"])
            };
            // The new active server finished the sequence: no lockout, the
            // right zone isolated, every healthy zone back on, no reset.
            assert_ne!(p["lockout"], true, "round {round}: {panel} locked out: {p}");
            let zone = faults.iter().find(|f| f.0 == panel).unwrap().1;
            assert_eq!(
                p["faulty_zones"],
                json!([zone]),
                "round {round}: {panel} isolated the wrong zone: {p}"
            );
            let healthy_on = healthy_zones_on(
                &mut op,
                panel,
                zone,
                &format!("round {round}"),
                Duration::from_secs(10),
            );
            if let Some(how) = healthy_on["resumed"].as_str() {
                println!("round {round}: {panel}: {how}");
            }
            *outcomes.entry(format!("{panel} {outcome}")).or_default() += 1;
            // The standby (the restarted server) shows what the active
            // server's sequence knows.
            let mut standby = Client::new(&servers[ai].addr());
            standby.cookie = op_a.cookie.clone();
            wait_for(
                &format!("the standby to follow {panel}"),
                Duration::from_secs(10),
                || {
                    let (s, q) = standby
                        .try_request("GET", &format!("/api/panels/{panel}"), None)
                        .ok()?;
                    (s == 200
                        && q["lockout"] == p["lockout"]
                        && q["faulty_zones"] == p["faulty_zones"])
                        .then_some(())
                },
            );
        }
        // Until the operator's recovery (repair, then Reset), no known
        // faulty zone may be closed.
        round_windows.push((killed_at, wall()));
        recover(&mut op, &mut sim, &faults);
    }

    // SIGSTOP the active server longer than its lease, with a fault for
    // the other one to isolate; SIGCONT: it finds itself deposed.
    let (ai, _) = wait_active(&[&servers[0], &servers[1]], Duration::from_secs(10));
    let si = 1 - ai;
    servers[ai].signal("-STOP");
    let stopped_at = wall();
    sim.cmd("fault ss1 2 permanent");
    let (now_active, took) = wait_active(&[&servers[si]], Duration::from_secs(15));
    assert_eq!(now_active, 0);
    takeovers.push(took);
    std::thread::sleep(Duration::from_secs(2));
    servers[ai].signal("-CONT");
    let resumed_at = wall();
    wait_for(
        "the frozen server to find itself deposed",
        Duration::from_secs(5),
        || (servers[ai].active() == Some(false)).then_some(()),
    );
    let mut op = Client::new(&servers[si].addr());
    op.cookie = op_a.cookie.clone();
    settled(&mut op, "ss1", Duration::from_secs(60));
    recover(&mut op, &mut sim, &[("ss1", 2)]);
    let frozen = servers[ai].name;
    let after_resume: Vec<FieldWrite> = field_writes(&[&servers[ai].log])
        .into_iter()
        .filter(|w| w.t >= stopped_at)
        .collect();
    assert!(
        after_resume.is_empty(),
        "server {frozen} wrote after it was frozen and deposed: {after_resume:?} (resumed at {resumed_at})"
    );

    // Cut server a's database connection while it is active: it steps
    // down before its lease expires, and b takes over.
    if servers[1].active() == Some(true) {
        // Make a the active one: stop b (orderly), a takes over at once.
        servers[1].signal("-TERM");
        let _ = servers[1].child.as_mut().unwrap().wait();
        servers[1].child = None;
        wait_for(
            "a to take over from a stopped b",
            Duration::from_secs(10),
            || (servers[0].active() == Some(true)).then_some(()),
        );
        servers[1].start();
        std::thread::sleep(Duration::from_secs(1));
    }
    // An operator's HMI on a, logged in before the cut.
    let mut hmi = Client::new(&servers[0].addr());
    hmi.cookie = op_a.cookie.clone();
    assert_eq!(hmi.get_ok("/api/pair")["role"], "active");
    let cut_at = wall();
    relay.cut();
    let cut = Instant::now();
    // Through the cut, the HMI's requests answer at once (its session is
    // not held waiting for the database), and a's own /api/pair stops
    // saying "active" when a steps down, not a hung request later.
    let mut a_says_standby: Option<Duration> = None;
    while servers[1].active() != Some(true) || a_says_standby.is_none() {
        assert!(
            cut.elapsed() < Duration::from_secs(15),
            "b did not take over from the cut-off a, or a's /api/pair kept saying active"
        );
        let asked = Instant::now();
        let pair = hmi.get_ok("/api/pair");
        let answered = asked.elapsed();
        assert!(
            answered < Duration::from_millis(1_500),
            "a's /api/pair with a session cookie took {answered:?} in the cut"
        );
        if pair["role"] == "standby" && a_says_standby.is_none() {
            a_says_standby = Some(cut.elapsed());
        }
        std::thread::sleep(Duration::from_millis(25));
    }
    let took = cut.elapsed();
    assert_eq!(servers[0].active(), Some(false), "a stepped down");
    let asked = Instant::now();
    let (status, _) = hmi.get("/healthz");
    assert_eq!(status, 503, "a's /healthz in the cut");
    assert!(
        asked.elapsed() < Duration::from_millis(2_500),
        "a's /healthz with a session cookie took {:?} in the cut",
        asked.elapsed()
    );
    println!("after the cut: a said standby at {a_says_standby:?}, b active at {took:?}");
    assert!(
        took <= TAKEOVER_BOUND,
        "takeover after the cut took {took:?}"
    );
    let stepped_down = logged_at(&servers[0].log, "could not be renewed in time")
        .into_iter()
        .filter(|t| *t >= cut_at)
        .fold(f64::INFINITY, f64::min);
    let b_active = logged_at(&servers[1].log, "this server holds the lease")
        .into_iter()
        .filter(|t| *t >= cut_at)
        .fold(f64::INFINITY, f64::min);
    assert!(
        stepped_down < b_active,
        "a stepped down at {stepped_down}, after b became active at {b_active}"
    );
    relay.restore();

    // The record of every write: one server per epoch; no write of an
    // older epoch after one of a newer; no zone known faulty closed again
    // by a later epoch in its round.
    let writes = field_writes(&[&servers[0].log, &servers[1].log]);
    assert!(!writes.is_empty(), "no field writes were logged");
    let epochs = assert_fenced(&writes);
    for (round, epoch, panel, zone) in &known_faulty {
        let (killed_at, recovering_at) = round_windows[*round];
        let tag = format!("{}.Zone{zone}.Cmd", prefixes[panel]);
        let closes: Vec<&FieldWrite> = writes
            .iter()
            .filter(|w| {
                w.t >= killed_at
                    && w.t < recovering_at
                    && w.epoch > *epoch
                    && w.tag == tag
                    && w.value == "true"
            })
            .collect();
        assert!(
            closes.is_empty(),
            "round {round}: zone {zone} of {panel}, known faulty under epoch {epoch}, closed again: {closes:?}"
        );
    }
    let mut sorted = takeovers.clone();
    sorted.sort();
    println!(
        "{} takeovers: p50 {:?}, max {:?}; outcomes {outcomes:?}; {} field writes over {} epochs; {} zones known faulty at a kill",
        sorted.len(),
        sorted[sorted.len() / 2],
        sorted[sorted.len() - 1],
        writes.len(),
        epochs,
        known_faulty.len()
    );
}
