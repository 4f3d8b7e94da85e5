//! The central host's counters, read by `/metrics`.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering::Relaxed};

/// Message kinds counted apart (the topic's message type, and STATE).
pub const MESSAGE_KINDS: [&str; 9] = [
    "NBIRTH", "NDEATH", "NDATA", "NCMD", "DBIRTH", "DDEATH", "DDATA", "DCMD", "STATE",
];

/// Problem labels (`sites::Problem::label`) and the host's own refusals.
const PROBLEMS: [&str; 9] = [
    "not_born",
    "seq_gap",
    "unknown_alias",
    "bad_metric",
    "stale_death",
    "refused",
    "oversized",
    "malformed",
    "bad_topic",
];

#[derive(Default)]
pub(crate) struct Counters {
    messages: [AtomicU64; 9],
    bytes: AtomicU64,
    problems: [AtomicU64; 9],
    reconnects: AtomicU64,
    rebirths_requested: AtomicU64,
    writes_confirmed: AtomicU64,
    writes_failed: AtomicU64,
    historical: AtomicU64,
    connected: AtomicBool,
    sites_online: AtomicU64,
    tags: AtomicU64,
}

/// A copy of the counters at one moment.
#[derive(Debug, Clone, Default)]
pub struct HostStats {
    /// Messages taken, by kind ([`MESSAGE_KINDS`]).
    pub messages: Vec<(&'static str, u64)>,
    /// Payload bytes received (every message, also those refused).
    pub bytes: u64,
    /// Messages or metrics refused, by reason.
    pub problems: Vec<(&'static str, u64)>,
    /// Connections to the broker lost and made again.
    pub reconnects: u64,
    pub rebirths_requested: u64,
    pub writes_confirmed: u64,
    pub writes_failed: u64,
    /// Historical samples (store and forward) handed to the historian.
    pub historical: u64,
    pub connected: bool,
    /// Edge nodes online (born and not dead).
    pub sites_online: u64,
    /// Remote tags in the tag database.
    pub tags: u64,
}

impl Counters {
    pub fn message(&self, kind: &str, bytes: usize) {
        if let Some(i) = MESSAGE_KINDS.iter().position(|k| *k == kind) {
            self.messages[i].fetch_add(1, Relaxed);
        }
        self.bytes.fetch_add(bytes as u64, Relaxed);
    }
    pub fn bytes(&self, bytes: usize) {
        self.bytes.fetch_add(bytes as u64, Relaxed);
    }
    pub fn problem(&self, label: &str) {
        if let Some(i) = PROBLEMS.iter().position(|k| *k == label) {
            self.problems[i].fetch_add(1, Relaxed);
        }
    }
    pub fn reconnect(&self) {
        self.reconnects.fetch_add(1, Relaxed);
    }
    pub fn rebirth(&self) {
        self.rebirths_requested.fetch_add(1, Relaxed);
    }
    pub fn write(&self, confirmed: bool) {
        let c = if confirmed {
            &self.writes_confirmed
        } else {
            &self.writes_failed
        };
        c.fetch_add(1, Relaxed);
    }
    pub fn historical(&self, n: usize) {
        self.historical.fetch_add(n as u64, Relaxed);
    }
    pub fn set_connected(&self, on: bool) {
        self.connected.store(on, Relaxed);
    }
    pub fn set_sites(&self, online: usize, tags: usize) {
        self.sites_online.store(online as u64, Relaxed);
        self.tags.store(tags as u64, Relaxed);
    }
    pub fn snapshot(&self) -> HostStats {
        HostStats {
            messages: MESSAGE_KINDS
                .iter()
                .zip(&self.messages)
                .map(|(k, c)| (*k, c.load(Relaxed)))
                .collect(),
            bytes: self.bytes.load(Relaxed),
            problems: PROBLEMS
                .iter()
                .zip(&self.problems)
                .map(|(k, c)| (*k, c.load(Relaxed)))
                .collect(),
            reconnects: self.reconnects.load(Relaxed),
            rebirths_requested: self.rebirths_requested.load(Relaxed),
            writes_confirmed: self.writes_confirmed.load(Relaxed),
            writes_failed: self.writes_failed.load(Relaxed),
            historical: self.historical.load(Relaxed),
            connected: self.connected.load(Relaxed),
            sites_online: self.sites_online.load(Relaxed),
            tags: self.tags.load(Relaxed),
        }
    }
}
