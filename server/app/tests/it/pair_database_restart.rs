//! A redundant pair while its PostgreSQL restarts under load: a throwaway
//! cluster of the test's own (`initdb`/`pg_ctl` of the Debian postgresql
//! package, on a free port), so it can be stopped without disturbing other
//! tests. Two `gridscada serve` processes on the demo plant, its simulator,
//! and an operator writing a tag many times a second while the historian,
//! the dispatch loop and the audit trail write too.
//!
//! - A quick restart (`pg_ctl restart -m immediate`, a crash of the
//!   database): the active server keeps control or hands it over cleanly.
//! - A long outage (stopped past the lease): the active server steps down,
//!   no server is active while the database is gone, and one takes over
//!   once it is back.
//! - Never two actives, from the record of every Modbus write (server and
//!   epoch), and no row committed before a restart (events, alarm history,
//!   historian samples) is lost.

use crate::common;

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use common::pair::*;
use common::{wait_for, Client};
use serde_json::json;

/// The Debian server binaries (one folder per major version), if installed.
fn bindir() -> Option<PathBuf> {
    let mut dirs: Vec<PathBuf> = std::fs::read_dir("/usr/lib/postgresql")
        .ok()?
        .filter_map(|e| Some(e.ok()?.path().join("bin")))
        .filter(|d| d.join("initdb").exists())
        .collect();
    dirs.sort_by_key(|d| {
        d.parent()
            .and_then(|v| v.file_name()?.to_str()?.parse::<u32>().ok())
            .unwrap_or(0)
    });
    dirs.pop()
}

/// A PostgreSQL cluster in a temporary folder, trust authentication on
/// 127.0.0.1 only. As root, it runs as the `postgres` system user (initdb
/// refuses root).
struct Cluster {
    dir: tempfile::TempDir,
    bin: PathBuf,
    port: u16,
    as_root: bool,
}

impl Cluster {
    fn run(&self, program: &str, args: &[&str]) -> std::process::Output {
        let program = self.bin.join(program);
        let mut c = if self.as_root {
            let mut c = Command::new("runuser");
            c.args(["-u", "postgres", "--"]).arg(program);
            c
        } else {
            Command::new(program)
        };
        c.args(args).output().expect("running a PostgreSQL program")
    }

    fn data(&self) -> String {
        self.dir.path().join("pg").display().to_string()
    }

    fn create() -> Option<Cluster> {
        let bin = bindir()?;
        let dir = tempfile::tempdir().unwrap();
        let as_root = Command::new("id")
            .arg("-u")
            .output()
            .is_ok_and(|o| String::from_utf8_lossy(&o.stdout).trim() == "0");
        if as_root {
            let ok = Command::new("chown")
                .args(["-R", "postgres"])
                .arg(dir.path())
                .status()
                .unwrap()
                .success();
            assert!(ok, "chown of the cluster's folder to postgres");
        }
        let c = Cluster {
            dir,
            bin,
            port: free_port(),
            as_root,
        };
        let out = c.run(
            "initdb",
            &[
                "-D",
                &c.data(),
                "-U",
                "postgres",
                "--auth=trust",
                "-E",
                "UTF8",
                "--no-locale",
            ],
        );
        assert!(
            out.status.success(),
            "initdb: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        c.start();
        Some(c)
    }

    fn options(&self) -> String {
        format!(
            "-p {} -k {} -c listen_addresses=127.0.0.1",
            self.port,
            self.dir.path().display()
        )
    }

    fn start(&self) {
        let log = self.dir.path().join("pg.log").display().to_string();
        let out = self.run(
            "pg_ctl",
            &[
                "-D",
                &self.data(),
                "-l",
                &log,
                "-w",
                "-t",
                "60",
                "-o",
                &self.options(),
                "start",
            ],
        );
        assert!(
            out.status.success(),
            "pg_ctl start: {}",
            common::tail(Path::new(&log))
        );
    }

    /// Stops at once, as a crash would: no checkpoint, recovery from the
    /// WAL at the next start.
    fn crash(&self) {
        let out = self.run("pg_ctl", &["-D", &self.data(), "-m", "immediate", "stop"]);
        assert!(
            out.status.success(),
            "pg_ctl stop: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }

    fn url(&self, db: &str) -> String {
        format!("postgres://postgres@127.0.0.1:{}/{db}", self.port)
    }
}

impl Drop for Cluster {
    fn drop(&mut self) {
        let _ = self.run("pg_ctl", &["-D", &self.data(), "-m", "immediate", "stop"]);
    }
}

/// What the database holds at one moment: the ids of events and alarm
/// transitions, and the historian samples (kept in a table of the test's,
/// by key; its row count kept here so that losing it would show).
struct Committed {
    events: Vec<i64>,
    transitions: Vec<i64>,
    samples_table: String,
    samples: usize,
}

fn ids(url: &str, table: &str) -> Vec<i64> {
    rows(url, &format!("SELECT id FROM {table} ORDER BY id"))
        .iter()
        .map(|r| r.parse().unwrap())
        .collect()
}

fn snapshot(url: &str, name: &str) -> Committed {
    let samples_table = format!("kept_{name}");
    psql(
        url,
        &format!("CREATE TABLE {samples_table} AS SELECT tag_id, ts FROM samples"),
    );
    let samples: usize = rows(url, &format!("SELECT count(*) FROM {samples_table}"))[0]
        .parse()
        .unwrap();
    Committed {
        events: ids(url, "events"),
        transitions: ids(url, "alarm_history"),
        samples_table,
        samples,
    }
}

/// Every row of `before` is still there.
fn nothing_lost(url: &str, before: &Committed, when: &str) {
    for (table, kept) in [
        ("events", &before.events),
        ("alarm_history", &before.transitions),
    ] {
        let now = ids(url, table);
        let lost: Vec<&i64> = kept
            .iter()
            .filter(|id| now.binary_search(id).is_err())
            .collect();
        assert!(lost.is_empty(), "{when}: {table} lost {lost:?}");
    }
    let t = &before.samples_table;
    assert_eq!(
        rows(url, &format!("SELECT count(*) FROM {t}"))[0],
        before.samples.to_string(),
        "{when}: the test's copy of the sample keys"
    );
    let missing = rows(
        url,
        &format!(
            "SELECT count(*) FROM {t} k WHERE NOT EXISTS \
             (SELECT 1 FROM samples s WHERE s.tag_id = k.tag_id AND s.ts = k.ts)"
        ),
    );
    assert_eq!(missing[0], "0", "{when}: historian samples lost");
}

/// Which of the pair says it is active (None: no answer).
fn roles(servers: &[&Server]) -> Vec<Option<bool>> {
    servers.iter().map(|s| s.active()).collect()
}

#[test]
fn the_pair_rides_through_database_restarts_under_load() {
    let _one_at_a_time = common::kill_test_lock();
    let Some(cluster) = Cluster::create() else {
        assert!(
            std::env::var("GRIDSCADA_REQUIRE_PG").as_deref() != Ok("1"),
            "GRIDSCADA_REQUIRE_PG=1 but the PostgreSQL server binaries are not installed"
        );
        eprintln!(
            "!!!!!!!! SKIPPED database restart test: no initdb in /usr/lib/postgresql !!!!!!!!"
        );
        return;
    };
    psql(&cluster.url("postgres"), "CREATE DATABASE gs");
    let url = cluster.url("gs");

    let dir = tempfile::tempdir().unwrap();
    let (pa, pb) = (free_port(), free_port());
    let pair = [("a", pa), ("b", pb)];
    let port_base = port_block(100);
    let ca = write_plant(&dir.path().join("a"), &url, "a", &pair, port_base);
    let cb = write_plant(&dir.path().join("b"), &url, "b", &pair, port_base);
    let _sim = Sim::start(&cb, &dir.path().join("sim.log"));
    add_operator(&cb);
    let mut a = Server {
        name: "a",
        config: ca,
        port: pa,
        log: dir.path().join("a.log"),
        child: None,
    };
    let mut b = Server {
        name: "b",
        config: cb,
        port: pb,
        log: dir.path().join("b.log"),
        child: None,
    };
    a.start();
    wait_for("a to become active", Duration::from_secs(20), || {
        (a.active() == Some(true)).then_some(())
    });
    b.start();
    wait_for("b on standby", Duration::from_secs(10), || {
        (b.active() == Some(false)).then_some(())
    });

    // The operator writes a tag many times a second to whichever server
    // takes it (the standby refuses); each write is a Modbus write and an
    // audit event.
    let stop = Arc::new(AtomicBool::new(false));
    let done = Arc::new(AtomicU64::new(0));
    let load = {
        let (stop, done) = (stop.clone(), done.clone());
        let mut clients: Vec<Client> = [a.addr(), b.addr()].iter().map(|x| login(x)).collect();
        std::thread::spawn(move || {
            while !stop.load(Ordering::Relaxed) {
                for c in clients.iter_mut() {
                    let r = c.try_request(
                        "POST",
                        "/api/tags/SS1.ELCB.Reset/write",
                        Some(json!({"value": false})),
                    );
                    if matches!(r, Ok((200, _))) {
                        done.fetch_add(1, Ordering::Relaxed);
                    }
                }
                std::thread::sleep(Duration::from_millis(50));
            }
        })
    };
    wait_for("the operator's writes", Duration::from_secs(20), || {
        (done.load(Ordering::Relaxed) > 20).then_some(())
    });

    // 1. A crash and immediate restart of the database.
    let before = snapshot(&url, "quick");
    let writes_before = done.load(Ordering::Relaxed);
    cluster.crash();
    cluster.start();
    let back = Instant::now();
    let servers = [&a, &b];
    let (active, took) = wait_active(&servers, Duration::from_secs(15));
    println!(
        "quick restart: {} active {took:?} after the database was back",
        servers[active].name
    );
    nothing_lost(&url, &before, "after a quick restart");
    wait_for("writes again", Duration::from_secs(15), || {
        (done.load(Ordering::Relaxed) > writes_before + 20).then_some(())
    });
    println!(
        "writes resumed {:?} after the database was back",
        back.elapsed()
    );

    // 2. The database gone past the lease: nobody may command.
    let before = snapshot(&url, "long");
    cluster.crash();
    let down = Instant::now();
    std::thread::sleep(Duration::from_secs(4));
    while down.elapsed() < Duration::from_secs(8) {
        let r = roles(&servers);
        assert!(
            !r.contains(&Some(true)),
            "a server is active {:?} after the database went: {r:?}",
            down.elapsed()
        );
        std::thread::sleep(Duration::from_millis(200));
    }
    let idle = done.load(Ordering::Relaxed);
    cluster.start();
    let (active, took) = wait_active(&servers, Duration::from_secs(15));
    println!(
        "long outage: {} active {took:?} after the database was back",
        servers[active].name
    );
    nothing_lost(&url, &before, "after a long outage");
    wait_for("writes again", Duration::from_secs(15), || {
        (done.load(Ordering::Relaxed) > idle + 20).then_some(())
    });
    stop.store(true, Ordering::Relaxed);
    load.join().unwrap();

    // Never two actives, from the write record.
    let writes = field_writes(&[&a.log, &b.log]);
    let epochs = assert_fenced(&writes);
    assert!(
        writes.iter().any(|w| w.tag == "SS1.ELCB.Reset"),
        "the operator's writes are in the record"
    );
    // Every write the operator was told succeeded is in the record.
    let recorded = writes.iter().filter(|w| w.tag == "SS1.ELCB.Reset").count() as u64;
    assert!(
        recorded >= done.load(Ordering::Relaxed),
        "{recorded} recorded, {} confirmed",
        done.load(Ordering::Relaxed)
    );
    println!(
        "{} operator writes confirmed; {} field writes over {epochs} epochs; {} events kept over the long outage",
        done.load(Ordering::Relaxed),
        writes.len(),
        before.events.len()
    );
}
