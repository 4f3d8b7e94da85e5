//! The switching guard: the `TagWriter` every command path of the server
//! goes through (HTTP, the HMI, OPC UA, Sparkplug DCMD, the IEC 104
//! server, the fault-isolation sequence, the dispatch), wrapped around the
//! field's writer. A write to a switching device's command tag is checked
//! against the device's safety tags and the interlock rules on the live
//! topology, with the operations still in flight counted as done, so two
//! commands that are each allowed cannot together break a rule. Every other
//! write passes through untouched.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use gridscada_config::{CommandBinding, Normally};
use gridscada_tagdb::{Blocked, Clock, TagWriter, Timestamp, Value, WriteError, WriteFuture};
use tokio::sync::watch;

use crate::driver::Live;
use crate::plant::Network;
use crate::rules::{interlocks, Operation, RuleId};
use crate::safety::SafetyTags;
use crate::selection::Selections;
use crate::topology::{compute, Pos};

/// How long (plant time) a confirmed operation still counts as in flight
/// while the topology catches up with the device's new position. Plant
/// time, not wall time: a replay at `--max` must judge the same write the
/// same way on every run, however loaded the machine.
const SETTLE: Duration = Duration::from_secs(1);

pub struct SwitchingGuard {
    net: Arc<Network>,
    inner: Arc<dyn TagWriter>,
    tags: SafetyTags,
    selections: Selections,
    live: watch::Receiver<Arc<Live>>,
    clock: Arc<dyn Clock>,
    /// Command tag -> device.
    by_command: HashMap<String, usize>,
    /// Operations checked and on their way: device -> its target position,
    /// and once the write is confirmed, until when it still counts (the
    /// topology has not shown the new position yet).
    pending: Mutex<HashMap<usize, (Pos, Option<Timestamp>)>>,
}

impl SwitchingGuard {
    pub fn new(
        net: Arc<Network>,
        inner: Arc<dyn TagWriter>,
        tags: SafetyTags,
        selections: Selections,
        live: watch::Receiver<Arc<Live>>,
        clock: Arc<dyn Clock>,
    ) -> SwitchingGuard {
        let by_command = net
            .command
            .iter()
            .enumerate()
            .filter_map(|(i, c)| Some((c.as_ref()?.tag().to_string(), i)))
            .collect();
        SwitchingGuard {
            net,
            inner,
            tags,
            selections,
            live,
            clock,
            by_command,
            pending: Mutex::default(),
        }
    }

    /// The device and operation a write of `value` to `name` is, if it is
    /// one (a pulse output's release, `false`, operates nothing).
    pub fn operation(&self, name: &str, value: &Value) -> Option<(usize, Operation)> {
        let &i = self.by_command.get(name)?;
        let on = value.as_bool()?;
        let op = match self.net.command[i].as_ref()? {
            CommandBinding::Tag(_) if on => Operation::Close,
            CommandBinding::Tag(_) => Operation::Open,
            CommandBinding::Pulse { pulse, .. } if on => match pulse {
                Normally::Closed => Operation::Close,
                Normally::Open => Operation::Open,
            },
            CommandBinding::Pulse { .. } => return None,
        };
        Some((i, op))
    }

    /// Why `op` of device `i` is refused now, if it is; the operations in
    /// `pending` count as done (those the topology shows, or whose time ran
    /// out, are dropped).
    fn check(
        &self,
        i: usize,
        op: Operation,
        pending: &mut HashMap<usize, (Pos, Option<Timestamp>)>,
    ) -> Result<(), Blocked> {
        let m = &self.net.model;
        let device = &m.switches[i];
        let blocked = |rule: RuleId, reason: String, overridable: bool| Blocked {
            device: device.name.clone(),
            operation: op.as_str(),
            rule: rule.as_str(),
            reason,
            overridable,
        };
        if !self.tags.loaded() {
            return Err(blocked(
                RuleId::SafetyTag,
                "the safety tags are not loaded from the store yet".into(),
                false,
            ));
        }
        if let Some(tag) = self.tags.blocking(&device.id, op) {
            return Err(blocked(RuleId::SafetyTag, tag.describe(), false));
        }
        // Select-before-operate: the holder executes by ending the
        // selection first (the HTTP layer), so a standing one is someone's.
        if let Some(held) = self.selections.held(i) {
            return Err(blocked(RuleId::Reserved, held.describe(), false));
        }
        // Opening anything but a disconnector meets no interlock (rules.rs):
        // no topology to compute (the panel sequence asks at every snapshot).
        if op == Operation::Open && device.kind != gridscada_config::SwitchKind::Disconnector {
            return Ok(());
        }
        let live = self.live.borrow().clone();
        let now = self.clock.now();
        pending.retain(|&d, (target, until)| {
            until.is_none_or(|t| t > now) && live.inputs.switches.get(d) != Some(target)
        });
        let mut inputs = live.inputs.clone();
        for (&d, &(p, _)) in pending.iter() {
            if let Some(slot) = inputs.switches.get_mut(d) {
                *slot = p;
            }
        }
        if inputs.switches.get(i) == Some(&op.target()) {
            return Ok(()); // already there: nothing changes in the network
        }
        let before = if pending.is_empty() {
            live.topology.clone()
        } else {
            Arc::new(compute(m, &inputs))
        };
        let after = compute(m, &inputs.with(i, op.target()));
        let p = crate::preview(m, &before, &after);
        let found = interlocks(m, &inputs, &before, &after, &p, i, op);
        // A device whose own position is unknown is left to the device
        // (it is offline, or moving): the rules about the network around it
        // still apply. An overridden selection being executed passes the
        // rules that allow an override.
        let granted = self.selections.granted(i, op);
        let own_position_unknown = inputs.switches.get(i) == Some(&Pos::Unknown);
        let waived = |f: &crate::Interlock| {
            (f.rule == RuleId::StateUnknown && own_position_unknown) || (granted && f.overridable)
        };
        match found.into_iter().find(|f| !waived(f)) {
            Some(f) => Err(blocked(f.rule, f.text, f.overridable)),
            None => Ok(()),
        }
    }
}

impl TagWriter for SwitchingGuard {
    fn write<'a>(&'a self, name: &'a str, value: Value) -> WriteFuture<'a> {
        Box::pin(async move {
            let Some((i, op)) = self.operation(name, &value) else {
                return self.inner.write(name, value).await;
            };
            {
                let mut pending = self.pending.lock().unwrap_or_else(|e| e.into_inner());
                self.check(i, op, &mut pending)
                    .map_err(WriteError::Blocked)?;
                self.selections.consume_grant(i, op);
                pending.insert(i, (op.target(), None));
            }
            let result = self.inner.write(name, value).await;
            let mut pending = self.pending.lock().unwrap_or_else(|e| e.into_inner());
            if result.is_ok() {
                // Until the topology shows the device at its new position
                // (or a while has passed), the operation still counts.
                pending.insert(i, (op.target(), Some(self.clock.now().add(SETTLE))));
            } else {
                pending.remove(&i);
            }
            result
        })
    }

    fn precheck(&self, name: &str, value: &Value) -> Result<(), WriteError> {
        if let Some((i, op)) = self.operation(name, value) {
            let mut pending = self.pending.lock().unwrap_or_else(|e| e.into_inner());
            self.check(i, op, &mut pending)
                .map_err(WriteError::Blocked)?;
        }
        self.inner.precheck(name, value)
    }
}
