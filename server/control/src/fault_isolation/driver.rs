//! The thin async shell around one panel's [`Sequence`].
//!
//! **Owns:** turning the panel's tags into snapshots, running the machine's
//! timers on the plant clock, writing its commands through the `TagWriter`,
//! publishing [`PanelStatus`] and the derived `{prefix}.Seq.*` tags, and
//! forwarding events and alarm conditions as [`PanelNotice`]s.
//!
//! **Must not touch:** decisions. Everything about what to switch and when is
//! the machine's; the only rule here is a last interlock check before a close
//! command is written (the ELCB tag must read closed with Good quality).

use std::collections::{BTreeMap, VecDeque};
use std::sync::Arc;
use std::time::Duration;

use gridscada_config::PanelConfig;
use gridscada_tagdb::{
    Clock, Quality, TagDb, TagId, TagMeta, TagWriter, Timestamp, Value, ValueKind, WriteError,
};
use serde::Serialize;
use tokio::sync::{mpsc, oneshot, watch};

use super::machine::{
    BlockedOperation, Breaker, CommandError, Input, Metrics, Mode, OperatorCommand, Output,
    Reading, Retained, Sequence, Settings, Snapshot, Takeover, Timer,
};

/// An operator command for one panel, with the user for the audit trail.
/// Roles are checked by the web layer before it is sent.
#[derive(Debug)]
pub struct PanelCommand {
    pub user: String,
    pub kind: PanelCommandKind,
    /// Accepted (`Ok`) or refused with the reason.
    pub reply: oneshot::Sender<Result<(), CommandError>>,
}

#[derive(Debug, Clone, PartialEq, Eq)]
pub enum PanelCommandKind {
    SetMode(Mode),
    Reset,
    /// `breaker`: "elcb" (closing = reset pulse), "mccb", "zone1".."zoneN".
    Breaker {
        breaker: String,
        close: bool,
    },
}

/// Events and alarm conditions of a panel, for the event log and alarm engine.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum PanelNotice {
    Event {
        panel: String,
        kind: String,
        message: String,
        user: Option<String>,
    },
    Alarm {
        panel: String,
        key: String,
        active: bool,
        priority: u32,
        message: String,
    },
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BreakerStatus {
    pub closed: bool,
    /// Whether the status input has Good quality.
    pub good: bool,
}

/// What the HMI shows of a panel's sequence.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PanelStatus {
    pub id: String,
    pub name: String,
    pub mode: Mode,
    pub step: String,
    #[serde(rename = "count_L_cur_c")]
    pub count_l_cur_c: u8,
    #[serde(rename = "count_L_cur_sv")]
    pub count_l_cur_sv: u8,
    pub zones: u8,
    /// "elcb", "mccb", "zone1".."zoneN".
    pub breakers: BTreeMap<String, BreakerStatus>,
    pub faulty_zones: Vec<u8>,
    /// Fault on load 0 (main MCCB / busbar).
    pub load0_faulty: bool,
    pub lockout: bool,
    /// Every signal of the panel has Good quality.
    pub comm_ok: bool,
    pub last_sequence: Metrics,
    /// How the last sequence was resumed after a restart or a failover (at
    /// which step, what was tested again); `null` if it was not.
    pub resumed: Option<String>,
    /// What must survive a restart; the application saves it when it changes
    /// and hands it back to [`run_panel`] on the next start.
    #[serde(skip)]
    pub retained: Retained,
}

impl PanelStatus {
    /// The status before the driver has read anything (for `watch::channel`).
    pub fn initial(panel: &PanelConfig) -> PanelStatus {
        let seq = Sequence::new(Settings::from_panel(panel));
        let zones = *panel.zones.get_ref();
        let mut breakers = BTreeMap::new();
        for b in std::iter::once(Breaker::Elcb).chain((0..=zones).map(Breaker::load)) {
            breakers.insert(
                b.name(),
                BreakerStatus {
                    closed: false,
                    good: false,
                },
            );
        }
        PanelStatus {
            id: panel.id.get_ref().clone(),
            name: panel.name.clone(),
            mode: seq.mode(),
            step: seq.step_name().into(),
            count_l_cur_c: 0,
            count_l_cur_sv: 0,
            zones,
            breakers,
            faulty_zones: Vec::new(),
            load0_faulty: false,
            lockout: false,
            comm_ok: false,
            last_sequence: seq.metrics().clone(),
            resumed: None,
            retained: seq.retained(),
        }
    }
}

#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum DriverError {
    #[error("panel '{panel}': tag '{tag}' is not in the tag database")]
    MissingTag { panel: String, tag: String },
}

/// The derived tags of a panel, to register before building the `TagDb`.
pub fn panel_tags(panel: &PanelConfig) -> Vec<TagMeta> {
    let p = panel.prefix.get_ref();
    let id = panel.id.get_ref();
    vec![
        TagMeta::new(format!("{p}.Seq.Mode"), ValueKind::Str)
            .describe(format!("Panel {id}: sequence mode (auto/manual)")),
        TagMeta::new(format!("{p}.Seq.Step"), ValueKind::Str)
            .describe(format!("Panel {id}: fault-isolation step")),
        TagMeta::new(format!("{p}.Seq.count_L_cur_c"), ValueKind::Int)
            .describe(format!("Panel {id}: OLUC step counter")),
        TagMeta::new(format!("{p}.Seq.count_L_cur_sv"), ValueKind::Int)
            .describe(format!("Panel {id}: saved faulty load number")),
        TagMeta::new(format!("{p}.Seq.FaultyZones"), ValueKind::Str)
            .describe(format!("Panel {id}: faulty zones, comma separated")),
        TagMeta::new(format!("{p}.Seq.Lockout"), ValueKind::Bool)
            .describe(format!("Panel {id}: sequence locked out")),
    ]
}

struct Ids {
    elcb_closed: TagId,
    mccb_closed: TagId,
    zone_closed: Vec<TagId>,
    /// Command outputs; only their quality is read.
    outputs: Vec<TagId>,
    seq_mode: TagId,
    seq_step: TagId,
    seq_c: TagId,
    seq_sv: TagId,
    seq_faulty: TagId,
    seq_lockout: TagId,
}

impl Ids {
    fn resolve(db: &TagDb, panel: &PanelConfig) -> Result<Ids, DriverError> {
        let find = |name: &str| {
            db.id(name).ok_or_else(|| DriverError::MissingTag {
                panel: panel.id.get_ref().clone(),
                tag: name.to_string(),
            })
        };
        let io = panel.io();
        let derived: Vec<TagId> = panel_tags(panel)
            .iter()
            .map(|m| find(&m.name))
            .collect::<Result<_, _>>()?;
        let mut outputs = vec![find(&io.elcb_reset)?, find(&io.mccb_cmd)?];
        for c in &io.zone_cmd {
            outputs.push(find(c)?);
        }
        Ok(Ids {
            elcb_closed: find(&io.elcb_closed)?,
            mccb_closed: find(&io.mccb_closed)?,
            zone_closed: io
                .zone_closed
                .iter()
                .map(|n| find(n))
                .collect::<Result<_, _>>()?,
            outputs,
            seq_mode: derived[0],
            seq_step: derived[1],
            seq_c: derived[2],
            seq_sv: derived[3],
            seq_faulty: derived[4],
            seq_lockout: derived[5],
        })
    }

    fn watched(&self) -> Vec<TagId> {
        let mut v = vec![self.elcb_closed, self.mccb_closed];
        v.extend(&self.zone_closed);
        v.extend(&self.outputs);
        v
    }
}

/// Runs one panel's sequence until the command channel closes (application
/// shutdown) or the tag database goes away. Every panel runs its own task.
///
/// Timers run on `clock`; a write that does not resolve within the
/// confirmation timeout (in wall time, `clock.to_wall`) counts as a
/// communication failure. After a failed write the rest of that batch of
/// commands is dropped: the machine decides again with the failure in hand.
///
/// `retained` is what the previous run of the server (or the other server
/// of a pair) left for this panel (`PanelStatus::retained`), with how it
/// came here: with it the sequence takes over the mode, the faulty zones and
/// the lockout, and finishes a sequence that was interrupted
/// ([`Sequence::restore`]).
#[allow(clippy::too_many_arguments)]
pub async fn run_panel(
    panel: PanelConfig,
    db: Arc<TagDb>,
    writer: Arc<dyn TagWriter>,
    clock: Arc<dyn Clock>,
    mut commands: mpsc::Receiver<PanelCommand>,
    status: watch::Sender<PanelStatus>,
    notices: mpsc::Sender<PanelNotice>,
    retained: Option<(Retained, Takeover)>,
) -> Result<(), DriverError> {
    let ids = Ids::resolve(&db, &panel)?;
    let mut sub = db.subscribe(&ids.watched());
    let settings = Settings::from_panel(&panel);
    let t0 = clock.now();
    let mut restored = Vec::new();
    let seq = match &retained {
        Some((r, how)) => Sequence::restore(settings, r, *how, &mut restored),
        None => Sequence::new(settings),
    };
    let mut d = Driver {
        panel_id: panel.id.get_ref().clone(),
        io: panel.io(),
        seq,
        ids,
        db,
        writer,
        clock,
        t0,
        timers: [None; 3],
        status,
        notices,
        base: PanelStatus::initial(&panel),
        last_derived: None,
        last_blocked: Vec::new(),
    };
    d.execute(restored, None).await;
    d.publish();
    d.feed_snapshot().await;
    loop {
        let sleep = match d.next_deadline() {
            Some(at) => d.clock.sleep(at.since(d.clock.now())),
            None => Box::pin(std::future::pending()),
        };
        tokio::select! {
            // Fresh plant state always goes first, so no decision is taken on
            // a state older than what the tag database already holds.
            biased;
            update = sub.recv() => {
                if update.is_none() {
                    return Ok(());
                }
                while sub.try_recv().is_some() {}
                d.feed_snapshot().await;
            }
            cmd = commands.recv() => match cmd {
                Some(cmd) => {
                    // What the writer would refuse may have changed without
                    // a breaker moving (a safety tag removed, the network
                    // switched): a Reset must see it as it is now. Only
                    // then: a plant without refusals is fed as before.
                    if d.blocked() != d.last_blocked {
                        d.feed_snapshot().await;
                    }
                    d.on_command(cmd).await
                }
                None => return Ok(()),
            },
            _ = sleep => {
                if sub.try_recv().is_some() {
                    while sub.try_recv().is_some() {}
                    d.feed_snapshot().await;
                }
                d.expire_due().await;
            }
        }
    }
}

struct Driver {
    panel_id: String,
    io: gridscada_config::PanelIo,
    seq: Sequence,
    ids: Ids,
    db: Arc<TagDb>,
    writer: Arc<dyn TagWriter>,
    clock: Arc<dyn Clock>,
    t0: Timestamp,
    /// Deadline and token of each running timer.
    timers: [Option<(Timestamp, Timer, u64)>; 3],
    status: watch::Sender<PanelStatus>,
    notices: mpsc::Sender<PanelNotice>,
    base: PanelStatus,
    last_derived: Option<(String, String, u8, u8, String, bool)>,
    /// The refusals the sequence was last told of (`Snapshot::blocked`).
    last_blocked: Vec<BlockedOperation>,
}

fn timer_index(t: Timer) -> usize {
    match t {
        Timer::RecloseDelay => 0,
        Timer::Dwell => 1,
        Timer::Confirm => 2,
    }
}

impl Driver {
    fn now_s(&self) -> f64 {
        self.clock.now().since(self.t0).as_secs_f64()
    }

    fn reading(&self, id: TagId) -> Reading {
        match self.db.get(id) {
            Some(s) => match s.value.as_bool() {
                Some(closed) => Reading {
                    closed,
                    good: s.quality.is_good(),
                },
                None => Reading::bad(),
            },
            None => Reading::bad(),
        }
    }

    fn snapshot(&self) -> Snapshot {
        Snapshot {
            elcb: self.reading(self.ids.elcb_closed),
            mccb: self.reading(self.ids.mccb_closed),
            zones: self
                .ids
                .zone_closed
                .iter()
                .map(|id| self.reading(*id))
                .collect(),
            outputs_good: self
                .ids
                .outputs
                .iter()
                .all(|id| self.db.get(*id).is_some_and(|s| s.quality.is_good())),
            blocked: self.blocked(),
        }
    }

    async fn feed_snapshot(&mut self) {
        let snap = self.snapshot();
        self.last_blocked.clone_from(&snap.blocked);
        let out = self.seq.handle(Input::Snapshot(snap), self.now_s());
        self.execute(out, None).await;
    }

    fn next_deadline(&self) -> Option<Timestamp> {
        self.timers.iter().flatten().map(|(at, _, _)| *at).min()
    }

    async fn expire_due(&mut self) {
        // The earliest timer is due even if millisecond rounding says otherwise.
        let now = self.clock.now().add(Duration::from_millis(1));
        let earliest = self.next_deadline();
        let due: Vec<(Timer, u64)> = self
            .timers
            .iter()
            .flatten()
            .filter(|(at, _, _)| *at <= now || Some(*at) == earliest)
            .map(|(_, t, tok)| (*t, *tok))
            .collect();
        for (timer, token) in due {
            // Skip a timer the previous expiry's outputs cancelled or restarted.
            if self.timers[timer_index(timer)].map(|(_, _, t)| t) != Some(token) {
                continue;
            }
            self.timers[timer_index(timer)] = None;
            let out = self
                .seq
                .handle(Input::TimerExpired { timer, token }, self.now_s());
            self.execute(out, None).await;
        }
    }

    async fn on_command(&mut self, cmd: PanelCommand) {
        let PanelCommand { user, kind, reply } = cmd;
        let zones = self.seq.settings().zones;
        let (desc, parsed) = match &kind {
            PanelCommandKind::SetMode(m) => (
                format!("set mode {}", mode_name(*m)),
                Ok(OperatorCommand::SetMode(*m)),
            ),
            PanelCommandKind::Reset => ("Reset".to_string(), Ok(OperatorCommand::Reset)),
            PanelCommandKind::Breaker { breaker, close } => {
                let what = if *close { "close" } else { "open" };
                let shown: String = breaker.chars().take(40).collect();
                (
                    format!("{what} {shown}"),
                    Breaker::parse(breaker, zones).map(|b| OperatorCommand::Breaker {
                        breaker: b,
                        close: *close,
                    }),
                )
            }
        };
        let result = parsed.and_then(|c| self.seq.command(c, self.now_s()));
        match result {
            Ok(out) => {
                // The audit record of the operator's action (the web layer
                // does not log panel commands again).
                let kind = match &kind {
                    PanelCommandKind::SetMode(_) => "mode",
                    PanelCommandKind::Reset => "reset",
                    PanelCommandKind::Breaker { .. } => "command",
                };
                self.notice(PanelNotice::Event {
                    panel: self.panel_id.clone(),
                    kind: kind.into(),
                    message: format!("operator command: {desc}"),
                    user: Some(user.clone()),
                })
                .await;
                self.execute(out, Some(&user)).await;
                let _ = reply.send(Ok(()));
            }
            Err(e) => {
                self.notice(PanelNotice::Event {
                    panel: self.panel_id.clone(),
                    kind: "command_refused".into(),
                    message: format!("operator command refused: {desc}: {e}"),
                    user: Some(user),
                })
                .await;
                self.publish();
                let _ = reply.send(Err(e));
            }
        }
    }

    /// Carries out the machine's outputs in order.
    async fn execute(&mut self, outputs: Vec<Output>, user: Option<&str>) {
        let mut batches = vec![VecDeque::from(outputs)];
        while let Some(batch) = batches.last_mut() {
            let Some(output) = batch.pop_front() else {
                batches.pop();
                continue;
            };
            match output {
                Output::Command { breaker, value } => {
                    if let Err((reason, comm)) = self.write(breaker, value).await {
                        // The rest of this batch was decided without the failure.
                        batch.retain(|o| !matches!(o, Output::Command { .. }));
                        let more = self.seq.handle(
                            Input::CommandFailed {
                                breaker,
                                value,
                                reason,
                                comm,
                            },
                            self.now_s(),
                        );
                        batches.push(VecDeque::from(more));
                    }
                }
                Output::StartTimer {
                    timer,
                    after_s,
                    token,
                } => {
                    // Clamp so a silly setting cannot overflow the clock.
                    let secs = if after_s.is_finite() {
                        after_s.clamp(0.0, 1.0e7)
                    } else {
                        1.0e7
                    };
                    let at = self.clock.now().add(Duration::from_secs_f64(secs));
                    self.timers[timer_index(timer)] = Some((at, timer, token));
                }
                Output::CancelTimer { timer } => self.timers[timer_index(timer)] = None,
                Output::Event { kind, message } => {
                    tracing::debug!(panel = %self.panel_id, kind, %message, "sequence event");
                    self.notice(PanelNotice::Event {
                        panel: self.panel_id.clone(),
                        kind: kind.into(),
                        message,
                        user: user.map(str::to_string),
                    })
                    .await;
                }
                Output::Alarm {
                    key,
                    active,
                    priority,
                    message,
                } => {
                    self.notice(PanelNotice::Alarm {
                        panel: self.panel_id.clone(),
                        key,
                        active,
                        priority,
                        message,
                    })
                    .await;
                }
            }
        }
        self.publish();
    }

    /// Writes one command. Errors carry the reason and whether it was a
    /// communication failure.
    /// The command output of `breaker` (the ELCB's: its reset).
    fn command_tag(&self, breaker: Breaker) -> Option<&str> {
        match breaker {
            Breaker::Elcb => Some(&self.io.elcb_reset),
            Breaker::Mccb => Some(&self.io.mccb_cmd),
            Breaker::Zone(n) => usize::from(n)
                .checked_sub(1)
                .and_then(|i| self.io.zone_cmd.get(i))
                .map(String::as_str),
        }
    }

    /// The operations the stack's writer would refuse now (a safety tag, a
    /// switching interlock), so the sequence does not command them.
    fn blocked(&self) -> Vec<BlockedOperation> {
        let zones = self.io.zone_cmd.len() as u8;
        let breakers = [Breaker::Elcb, Breaker::Mccb]
            .into_iter()
            .chain((1..=zones).map(Breaker::Zone));
        let mut out = Vec::new();
        for b in breakers {
            let Some(tag) = self.command_tag(b) else {
                continue;
            };
            // The ELCB is only ever reset (closed) by its output.
            let ops: &[bool] = if b == Breaker::Elcb {
                &[true]
            } else {
                &[true, false]
            };
            for &close in ops {
                if let Err(WriteError::Blocked(why)) =
                    self.writer.precheck(tag, &Value::Bool(close))
                {
                    out.push(BlockedOperation {
                        breaker: b,
                        close,
                        // A safety tag's text says it is one.
                        reason: if why.rule == "safety_tag" {
                            why.reason
                        } else {
                            format!("interlock {}: {}", why.rule, why.reason)
                        },
                    });
                }
            }
        }
        out
    }

    async fn write(&self, breaker: Breaker, value: bool) -> Result<(), (String, bool)> {
        let Some(tag) = self.command_tag(breaker) else {
            return Err((format!("panel has no breaker {breaker}"), false));
        };
        if value && breaker != Breaker::Elcb {
            let elcb = self.reading(self.ids.elcb_closed);
            if !(elcb.good && elcb.closed) {
                return Err((
                    format!("interlock: '{tag}' not written because the ELCB is not known closed"),
                    false,
                ));
            }
        }
        let limit = self
            .clock
            .to_wall(Duration::from_secs_f64(
                self.seq.settings().confirm_timeout_s.clamp(0.001, 1.0e6),
            ))
            .max(Duration::from_secs(1));
        match tokio::time::timeout(limit, self.writer.write(tag, Value::Bool(value))).await {
            Ok(Ok(_)) => Ok(()),
            Ok(Err(e)) => {
                let comm = matches!(
                    e,
                    WriteError::Device { .. } | WriteError::Timeout(_) | WriteError::Closed
                );
                Err((e.to_string(), comm))
            }
            Err(_) => Err((format!("write to '{tag}' did not complete in time"), true)),
        }
    }

    async fn notice(&self, n: PanelNotice) {
        // A closed receiver means the application is shutting down.
        let _ = self.notices.send(n).await;
    }

    /// Publishes the status and the derived tags.
    fn publish(&mut self) {
        let seq = &self.seq;
        let mut breakers = BTreeMap::new();
        let mut put = |b: Breaker, r: Reading| {
            breakers.insert(
                b.name(),
                BreakerStatus {
                    closed: r.closed,
                    good: r.good,
                },
            );
        };
        put(Breaker::Elcb, self.reading(self.ids.elcb_closed));
        put(Breaker::Mccb, self.reading(self.ids.mccb_closed));
        for (i, id) in self.ids.zone_closed.iter().enumerate() {
            put(Breaker::Zone(i as u8 + 1), self.reading(*id));
        }
        let faulty = seq.faulty_zones();
        let status = PanelStatus {
            mode: seq.mode(),
            step: seq.step_name().into(),
            count_l_cur_c: seq.count_l_cur_c(),
            count_l_cur_sv: seq.count_l_cur_sv(),
            breakers,
            faulty_zones: faulty.clone(),
            load0_faulty: seq.load0_faulty(),
            lockout: seq.lockout(),
            comm_ok: seq.comm_good(),
            last_sequence: seq.metrics().clone(),
            resumed: seq.resumed().map(str::to_string),
            retained: seq.retained(),
            ..self.base.clone()
        };
        self.status.send_if_modified(|s| {
            if *s == status {
                false
            } else {
                *s = status;
                true
            }
        });
        let faulty_str = faulty
            .iter()
            .map(|z| z.to_string())
            .collect::<Vec<_>>()
            .join(",");
        let derived = (
            mode_name(seq.mode()).to_string(),
            seq.step_name().to_string(),
            seq.count_l_cur_c(),
            seq.count_l_cur_sv(),
            faulty_str,
            seq.lockout(),
        );
        if self.last_derived.as_ref() != Some(&derived) {
            let ts = self.clock.now();
            let good = |v: Value| gridscada_tagdb::Sample {
                value: v,
                quality: Quality::GOOD,
                timestamp: ts,
            };
            self.db.apply([
                (self.ids.seq_mode, good(Value::from(derived.0.as_str()))),
                (self.ids.seq_step, good(Value::from(derived.1.as_str()))),
                (self.ids.seq_c, good(Value::Int(i64::from(derived.2)))),
                (self.ids.seq_sv, good(Value::Int(i64::from(derived.3)))),
                (self.ids.seq_faulty, good(Value::from(derived.4.as_str()))),
                (self.ids.seq_lockout, good(Value::Bool(derived.5))),
            ]);
            self.last_derived = Some(derived);
        }
    }
}

fn mode_name(m: Mode) -> &'static str {
    match m {
        Mode::Auto => "auto",
        Mode::Manual => "manual",
    }
}
