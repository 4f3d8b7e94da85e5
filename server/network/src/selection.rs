//! Select-before-operate reservations: an operator selects one operation of
//! one switching device, sees its effect, and executes it within the select
//! timeout or cancels it. While the selection stands the device is reserved
//! for that operator: another cannot select it, and the switching guard
//! refuses every command to it (rule `reserved`) from any door.
//!
//! Held in memory by the server that took the selection: a selection lives
//! seconds, and after a failover the operator selects again.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use gridscada_tagdb::Timestamp;

use crate::rules::Operation;

/// One standing selection.
#[derive(Debug, Clone, PartialEq)]
pub struct Selection {
    pub id: u64,
    /// The switching device's index in the model.
    pub device: usize,
    /// Its id, for messages.
    pub device_id: String,
    pub operation: Operation,
    /// Who holds it (their user name).
    pub user: String,
    pub selected_at: Timestamp,
    /// When it lapses, on the server's clock.
    pub expires_at: Timestamp,
    /// A supervisor's override of the rules that allow one, for this
    /// operation only.
    pub overridden: Option<Override>,
    deadline: Instant,
}

/// Who overrode the overridable interlocks of a selection, and why.
#[derive(Debug, Clone, PartialEq)]
pub struct Override {
    pub by: String,
    pub reason: String,
}

/// How long an override granted at execution waits for its command.
const GRANT: Duration = Duration::from_secs(5);

impl Selection {
    /// "selected by alice to close until 14:02:30 UTC"
    pub fn describe(&self) -> String {
        format!(
            "{} is selected by {} to {} until {}",
            self.device_id,
            self.user,
            self.operation.as_str(),
            self.expires_at.utc_text()
        )
    }
}

/// Why a selection was not taken.
#[derive(Debug, Clone, PartialEq)]
pub enum SelectRefused {
    /// Another operator holds the device.
    HeldBy(Box<Selection>),
}

#[derive(Debug, Default)]
struct Inner {
    next_id: u64,
    /// Device index -> its selection.
    by_device: HashMap<usize, Selection>,
    /// Overridden operations being executed: device -> (operation, until).
    grants: HashMap<usize, (Operation, Instant)>,
}

impl Inner {
    fn expire(&mut self, now: Instant) {
        self.by_device.retain(|_, s| s.deadline > now);
        self.grants.retain(|_, (_, until)| *until > now);
    }
}

/// The standing selections, shared by the HTTP layer (which takes, executes
/// and cancels them) and the switching guard (which refuses commands to a
/// device someone else holds).
#[derive(Debug, Clone)]
pub struct Selections {
    inner: Arc<Mutex<Inner>>,
    timeout: Duration,
}

impl Selections {
    pub fn new(timeout: Duration) -> Selections {
        Selections {
            inner: Arc::default(),
            timeout,
        }
    }

    pub fn timeout(&self) -> Duration {
        self.timeout
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Inner> {
        let mut g = self.inner.lock().unwrap_or_else(|e| e.into_inner());
        g.expire(Instant::now());
        g
    }

    /// Reserves `op` of `device` for `user` until the timeout. A user who
    /// already holds the device selects again (the operation may change, the
    /// timeout starts over); anyone else is refused with the holder.
    pub fn select(
        &self,
        device: usize,
        device_id: &str,
        op: Operation,
        user: &str,
        now: Timestamp,
    ) -> Result<Selection, SelectRefused> {
        let mut g = self.lock();
        if let Some(held) = g.by_device.get(&device) {
            if held.user != user {
                return Err(SelectRefused::HeldBy(Box::new(held.clone())));
            }
        }
        g.next_id += 1;
        let millis = i64::try_from(self.timeout.as_millis()).unwrap_or(i64::MAX);
        let s = Selection {
            id: g.next_id,
            device,
            device_id: device_id.to_string(),
            operation: op,
            user: user.to_string(),
            selected_at: now,
            expires_at: Timestamp::from_millis(now.as_millis().saturating_add(millis)),
            overridden: None,
            deadline: Instant::now() + self.timeout,
        };
        g.by_device.insert(device, s.clone());
        Ok(s)
    }

    /// The standing selection `id`, if it has not lapsed.
    pub fn get(&self, id: u64) -> Option<Selection> {
        self.lock().by_device.values().find(|s| s.id == id).cloned()
    }

    /// Ends selection `id` (executed or cancelled): it no longer reserves
    /// the device. None if there is no such selection or it lapsed.
    pub fn take(&self, id: u64) -> Option<Selection> {
        let mut g = self.lock();
        let device = g.by_device.values().find(|s| s.id == id)?.device;
        g.by_device.remove(&device)
    }

    /// Records a supervisor's override on selection `id` (standing).
    pub fn set_override(&self, id: u64, by: &str, reason: &str) -> Option<Selection> {
        let mut g = self.lock();
        let s = g.by_device.values_mut().find(|s| s.id == id)?;
        s.overridden = Some(Override {
            by: by.to_string(),
            reason: reason.to_string(),
        });
        Some(s.clone())
    }

    /// Lets the next command of `op` to `device` pass the overridable
    /// interlocks (an overridden selection being executed), for a few
    /// seconds.
    pub fn grant(&self, device: usize, op: Operation) {
        self.lock()
            .grants
            .insert(device, (op, Instant::now() + GRANT));
    }

    /// Whether `op` of `device` is granted an override now.
    pub fn granted(&self, device: usize, op: Operation) -> bool {
        self.lock()
            .grants
            .get(&device)
            .is_some_and(|(o, _)| *o == op)
    }

    /// Uses up the grant of `op` of `device` (its command went out).
    pub fn consume_grant(&self, device: usize, op: Operation) {
        let mut g = self.lock();
        if g.grants.get(&device).is_some_and(|(o, _)| *o == op) {
            g.grants.remove(&device);
        }
    }

    /// Who holds `device`, if anyone.
    pub fn held(&self, device: usize) -> Option<Selection> {
        self.lock().by_device.get(&device).cloned()
    }

    /// Every standing selection, oldest first.
    pub fn all(&self) -> Vec<Selection> {
        let mut v: Vec<Selection> = self.lock().by_device.values().cloned().collect();
        v.sort_by_key(|s| s.id);
        v
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(ms: i64) -> Timestamp {
        Timestamp::from_millis(ms)
    }

    #[test]
    fn one_operator_holds_a_device_until_it_is_executed_or_cancelled() {
        let sel = Selections::new(Duration::from_secs(30));
        let a = sel
            .select(3, "NOP1", Operation::Close, "alice", at(0))
            .unwrap();
        assert_eq!(a.expires_at, at(30_000));
        match sel.select(3, "NOP1", Operation::Open, "bob", at(1)) {
            Err(SelectRefused::HeldBy(h)) => assert_eq!(h.user, "alice"),
            other => panic!("bob selected a held device: {other:?}"),
        }
        // Another device is free; alice may select hers again.
        assert!(sel
            .select(4, "NOP2", Operation::Close, "bob", at(1))
            .is_ok());
        let again = sel
            .select(3, "NOP1", Operation::Open, "alice", at(2))
            .unwrap();
        assert_ne!(again.id, a.id);
        assert!(sel.get(a.id).is_none(), "the first selection was replaced");
        assert_eq!(sel.held(3).unwrap().operation, Operation::Open);
        assert_eq!(sel.take(again.id).unwrap().device, 3);
        assert!(sel.held(3).is_none());
        assert!(sel.take(again.id).is_none(), "taken once");
        assert!(sel
            .select(3, "NOP1", Operation::Close, "bob", at(3))
            .is_ok());
    }

    #[test]
    fn an_override_is_granted_for_one_operation_of_one_device() {
        let sel = Selections::new(Duration::from_secs(30));
        let a = sel.select(2, "D1", Operation::Open, "olly", at(0)).unwrap();
        assert!(sel.set_override(a.id + 1, "sue", "x").is_none());
        let o = sel
            .set_override(a.id, "sue", "load transferred by hand")
            .unwrap();
        assert_eq!(o.overridden.unwrap().by, "sue");
        assert!(!sel.granted(2, Operation::Open));
        sel.grant(2, Operation::Open);
        assert!(sel.granted(2, Operation::Open));
        assert!(!sel.granted(2, Operation::Close));
        assert!(!sel.granted(3, Operation::Open));
        sel.consume_grant(2, Operation::Open);
        assert!(!sel.granted(2, Operation::Open));
    }

    #[test]
    fn a_selection_lapses_at_its_timeout() {
        let sel = Selections::new(Duration::from_millis(30));
        let a = sel
            .select(0, "F1", Operation::Open, "alice", at(0))
            .unwrap();
        assert!(sel.get(a.id).is_some());
        std::thread::sleep(Duration::from_millis(60));
        assert!(sel.get(a.id).is_none());
        assert!(sel.held(0).is_none());
        assert!(sel.all().is_empty());
        assert!(sel.select(0, "F1", Operation::Open, "bob", at(70)).is_ok());
    }
}
