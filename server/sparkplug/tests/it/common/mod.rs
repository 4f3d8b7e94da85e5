//! Debian's mosquitto for the tests against a real broker: where it is, a
//! free loopback port, and a broker started on a configuration (waited for
//! until it takes connections). Tests skip with a note where mosquitto is
//! not installed; `scripts/test-all.sh` installs it. And an edge's
//! context for tests and benches without commands: a writer and an audit
//! that do nothing (`examples/edge_bench.rs` takes this file too).
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use gridscada_store::NewEvent;
use gridscada_tagdb::{TagWriter, WriteError, WriteFuture};

pub fn mosquitto() -> Option<PathBuf> {
    ["/usr/sbin/mosquitto", "/usr/bin/mosquitto"]
        .into_iter()
        .map(PathBuf::from)
        .find(|p| p.exists())
}

pub fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// A running broker; killed when dropped.
pub struct Broker(Child);

impl Broker {
    /// Starts `bin -c conf` and waits (at most 5 s) until `port` answers.
    pub async fn start(bin: &Path, conf: &Path, port: u16) -> Broker {
        let child = Command::new(bin)
            .arg("-c")
            .arg(conf)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        for _ in 0..100 {
            if std::net::TcpStream::connect(("127.0.0.1", port)).is_ok() {
                break;
            }
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
        Broker(child)
    }
}

impl Drop for Broker {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Commands are not part of these tests: every write is refused.
pub struct NoWrites;
impl TagWriter for NoWrites {
    fn write<'a>(&'a self, _name: &'a str, _value: gridscada_tagdb::Value) -> WriteFuture<'a> {
        Box::pin(async { Err(WriteError::Closed) })
    }
}

/// An audit trail that takes everything and keeps nothing.
pub struct NoAudit;
impl gridscada_store::command::CommandAudit for NoAudit {
    fn durable(
        &self,
        _event: NewEvent,
    ) -> std::pin::Pin<Box<dyn std::future::Future<Output = Result<(), String>> + Send + '_>> {
        Box::pin(async { Ok(()) })
    }
}
