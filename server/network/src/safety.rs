//! Safety tags (lockout/tagout): the standing tags on switching devices, as
//! the switching guard, the fault-isolation sequence and the screens read
//! them. The store holds them durably; this is the server's copy, replaced
//! from the store at start and whenever it may have changed elsewhere (the
//! other server of a pair).

use std::sync::{Arc, RwLock};

use gridscada_tagdb::Timestamp;
use tokio::sync::watch;

use crate::rules::Operation;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum TagKind {
    /// Blocks nothing: a note for whoever operates the device.
    Information,
    /// Blocks closing (for an earth switch: earthing).
    DoNotClose,
    /// Blocks opening and closing.
    DoNotOperate,
}

impl TagKind {
    pub const NAMES: &'static str = "do_not_operate, do_not_close, information";

    pub fn parse(s: &str) -> Option<TagKind> {
        Some(match s {
            "do_not_operate" => TagKind::DoNotOperate,
            "do_not_close" => TagKind::DoNotClose,
            "information" => TagKind::Information,
            _ => return None,
        })
    }
    pub fn as_str(self) -> &'static str {
        match self {
            TagKind::DoNotOperate => "do_not_operate",
            TagKind::DoNotClose => "do_not_close",
            TagKind::Information => "information",
        }
    }
    /// As printed on the tag.
    pub fn label(self) -> &'static str {
        match self {
            TagKind::DoNotOperate => "DO NOT OPERATE",
            TagKind::DoNotClose => "DO NOT CLOSE",
            TagKind::Information => "INFORMATION",
        }
    }
    pub fn blocks(self, op: Operation) -> bool {
        match self {
            TagKind::DoNotOperate => true,
            TagKind::DoNotClose => op == Operation::Close,
            TagKind::Information => false,
        }
    }
}

#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SafetyTag {
    pub id: i64,
    /// The switching device's id.
    pub device: String,
    pub kind: TagKind,
    pub reason: String,
    pub work_ref: String,
    pub placed_by: String,
    pub placed_at: Timestamp,
}

impl SafetyTag {
    /// "safety tag DO NOT CLOSE placed by alice at 2026-11-29 14:02:00 UTC
    /// for WO-1234: cable C2 out for jointing"
    pub fn describe(&self) -> String {
        format!(
            "safety tag {} placed by {} at {}{}: {}",
            self.kind.label(),
            self.placed_by,
            self.placed_at.utc_text(),
            for_work(&self.work_ref),
            self.reason
        )
    }
}

/// " for WO-1234", or nothing without a work reference.
pub fn for_work(work_ref: &str) -> String {
    if work_ref.is_empty() {
        String::new()
    } else {
        format!(" for {work_ref}")
    }
}

#[derive(Debug, Default)]
struct Standing {
    /// False until the store's tags were read: nothing switches before.
    loaded: bool,
    tags: Vec<SafetyTag>,
}

/// The standing safety tags, shared.
#[derive(Debug, Clone)]
pub struct SafetyTags {
    standing: Arc<RwLock<Standing>>,
    version: Arc<watch::Sender<u64>>,
}

impl Default for SafetyTags {
    fn default() -> Self {
        SafetyTags {
            standing: Arc::default(),
            version: Arc::new(watch::channel(0).0),
        }
    }
}

impl SafetyTags {
    /// Replaces every tag with the store's (a no-op when nothing changed).
    pub fn replace(&self, mut tags: Vec<SafetyTag>) {
        tags.sort_by_key(|t| t.id);
        let mut s = self.standing.write().unwrap_or_else(|e| e.into_inner());
        if s.loaded && s.tags == tags {
            return;
        }
        s.loaded = true;
        s.tags = tags;
        drop(s);
        self.version.send_modify(|v| *v += 1);
    }

    pub fn add(&self, tag: SafetyTag) {
        let mut s = self.standing.write().unwrap_or_else(|e| e.into_inner());
        s.tags.retain(|t| t.id != tag.id);
        s.tags.push(tag);
        drop(s);
        self.version.send_modify(|v| *v += 1);
    }

    pub fn remove(&self, id: i64) {
        let mut s = self.standing.write().unwrap_or_else(|e| e.into_inner());
        s.tags.retain(|t| t.id != id);
        drop(s);
        self.version.send_modify(|v| *v += 1);
    }

    pub fn loaded(&self) -> bool {
        self.standing
            .read()
            .unwrap_or_else(|e| e.into_inner())
            .loaded
    }

    pub fn all(&self) -> Vec<SafetyTag> {
        self.standing
            .read()
            .unwrap_or_else(|e| e.into_inner())
            .tags
            .clone()
    }

    pub fn on(&self, device: &str) -> Vec<SafetyTag> {
        let s = self.standing.read().unwrap_or_else(|e| e.into_inner());
        s.tags
            .iter()
            .filter(|t| t.device == device)
            .cloned()
            .collect()
    }

    /// The strongest tag that blocks `op` of `device`, if any.
    pub fn blocking(&self, device: &str, op: Operation) -> Option<SafetyTag> {
        self.on(device)
            .into_iter()
            .filter(|t| t.kind.blocks(op))
            .max_by_key(|t| (t.kind, -t.id))
    }

    /// The strongest tag on `device`, if any.
    pub fn strongest(&self, device: &str) -> Option<TagKind> {
        self.on(device).into_iter().map(|t| t.kind).max()
    }

    /// Bumped at every change.
    pub fn subscribe(&self) -> watch::Receiver<u64> {
        self.version.subscribe()
    }
}
