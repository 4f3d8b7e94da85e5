//! One control centre connection: the controlled side of the APCI
//! (STARTDT/STOPDT confirmed, test frames, k and w), interrogation and
//! counter interrogation answered from the tag database, spontaneous and
//! periodic data, clock synchronisation confirmed (the server's clock is
//! kept by the operating system, not by the centre), and commands.

use std::collections::{HashMap, VecDeque};
use std::net::SocketAddr;
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::Instant;

use gridscada_store::command::{audit_refused, audited_write, CommandError, Commander};
use gridscada_tagdb::{Sample, Update};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;
use tokio::sync::{mpsc, watch};

use super::export::{command_value, element, pack, time_of, type_id, worth_sending};
use super::Shared;
use crate::session::Session;
use crate::{
    apci, Asdu, AsduError, Cause, Cp56Time2a, Element, Frame, InformationObject, TypeId, UFunction,
};

/// Frames queued for a centre that does not acknowledge before it is
/// dropped: a slow reader must not hold the server's memory.
const MAX_OUTBOX: usize = 100_000;

/// A command's outcome, from its write task back to the connection.
struct Outcome {
    asdu: Asdu,
    ok: bool,
}

struct Conn {
    shared: Arc<Shared>,
    peer: SocketAddr,
    session: Session,
    outbox: VecDeque<Vec<u8>>,
    /// What was last sent of each export, for the deadband.
    last: HashMap<usize, Sample>,
    /// Selected commands by command IOA: when the select expires.
    selected: HashMap<u32, Instant>,
    next_cyclic: Vec<Instant>,
    outcomes_tx: mpsc::Sender<Outcome>,
}

pub(super) async fn serve(
    stream: TcpStream,
    peer: SocketAddr,
    shared: Arc<Shared>,
    mut shutdown: watch::Receiver<bool>,
) {
    let _ = stream.set_nodelay(true);
    let (mut read, mut write) = stream.into_split();
    let ids: Vec<_> = shared.exports.iter().map(|e| e.id).collect();
    let mut changes = shared.ctx.db.subscribe(&ids);
    let (outcomes_tx, mut outcomes) = mpsc::channel(16);
    let now = Instant::now();
    let mut c = Conn {
        next_cyclic: shared.cyclic.iter().map(|(_, p)| now + *p).collect(),
        session: Session::new(shared.session, now),
        shared,
        peer,
        outbox: VecDeque::new(),
        last: HashMap::new(),
        selected: HashMap::new(),
        outcomes_tx,
    };
    let mut buf = Vec::with_capacity(4096);
    let mut chunk = [0u8; 4096];
    let reason = loop {
        // Frames already in the buffer first.
        match apci::decode(&buf) {
            Ok(Some((frame, used))) => {
                buf.drain(..used);
                match c.on_frame(frame) {
                    Ok(send) => {
                        if let Err(e) = c.send(&mut write, send).await {
                            break e;
                        }
                    }
                    Err(e) => break e,
                }
                continue;
            }
            Ok(None) => {}
            Err(e) => {
                c.shared.counters.malformed.fetch_add(1, Ordering::Relaxed);
                break format!("malformed frame: {e}");
            }
        }
        if c.outbox.len() > MAX_OUTBOX {
            break format!(
                "more than {MAX_OUTBOX} frames waiting: the centre does not acknowledge"
            );
        }
        // Answers to what just arrived go out before we wait again.
        if let Err(e) = c.flush(&mut write).await {
            break e;
        }
        let wake = tokio::time::Instant::from_std(c.next_wake());
        let started = c.session.is_started();
        tokio::select! {
            _ = shutdown.changed() => break "the server is stopping".to_string(),
            r = read.read(&mut chunk) => match r {
                Ok(0) => break "the centre closed the connection".to_string(),
                Ok(n) => buf.extend_from_slice(&chunk[..n]),
                Err(e) => break format!("read failed: {e}"),
            },
            u = changes.recv(), if started => match u {
                Some(Update::Changes(batch)) => c.spontaneous(batch.changes.iter().map(|(id, s)| (*id, s.clone()))),
                Some(Update::Snapshot(snap)) => c.spontaneous(snap.changes.iter().map(|(id, s)| (*id, s.clone()))),
                None => break "the tag database is gone".to_string(),
            },
            Some(o) = outcomes.recv() => {
                let Outcome { asdu, ok } = o;
                let term = asdu.with_cause(Cause::ActTerm).map(|a| a.with_negative(!ok));
                if let Ok(a) = term {
                    c.outbox.push_back(a.encode());
                }
            }
            _ = tokio::time::sleep_until(wake) => {}
        }
        let now = Instant::now();
        match c.session.tick(now) {
            Ok(frames) => {
                if let Err(e) = c.send(&mut write, frames).await {
                    break e;
                }
            }
            Err(e) => break e.to_string(),
        }
        c.cyclic(now);
        if let Err(e) = c.flush(&mut write).await {
            break e;
        }
    };
    tracing::info!(%peer, %reason, "IEC 104 server: connection closed");
}

impl Conn {
    fn next_wake(&self) -> Instant {
        let mut at = self.session.next_deadline();
        if self.session.is_started() {
            for t in &self.next_cyclic {
                at = at.min(*t);
            }
        }
        at
    }

    /// Takes one frame; returns frames to send at once.
    fn on_frame(&mut self, frame: Frame) -> Result<Vec<Frame>, String> {
        let now = Instant::now();
        let actions = self
            .session
            .receive(frame, now)
            .map_err(|e| e.to_string())?;
        let mut send = actions.send;
        match actions.activated {
            Some(UFunction::StartDtAct) => {
                self.session.set_started(true);
                send.push(Frame::U(UFunction::StartDtCon));
            }
            Some(UFunction::StopDtAct) => {
                self.session.set_started(false);
                self.outbox.clear();
                send.push(Frame::U(UFunction::StopDtCon));
            }
            _ => {}
        }
        for bytes in actions.asdus {
            match Asdu::decode(&bytes) {
                Ok(a) => self.on_asdu(a),
                // A type we do not take is answered "unknown type" (44),
                // the rest of the stream is still in step.
                Err(AsduError::UnknownTypeId(t)) => {
                    let mut reply = bytes.clone();
                    if reply.len() >= 3 {
                        reply[2] = 44 | 0x40;
                        self.outbox.push_back(reply);
                    }
                    tracing::warn!(peer = %self.peer, type_id = t, "IEC 104 server: unknown type");
                }
                Err(e) => {
                    self.shared
                        .counters
                        .malformed
                        .fetch_add(1, Ordering::Relaxed);
                    return Err(format!("malformed ASDU: {e}"));
                }
            }
        }
        Ok(send)
    }

    fn on_asdu(&mut self, a: Asdu) {
        if a.common_address() != self.shared.common_address && a.common_address() != 0xFFFF {
            self.mirror(&a, Cause::UnknownCommonAddress, true);
            return;
        }
        if a.cause() != Cause::Act && a.cause() != Cause::Deact {
            self.mirror(&a, Cause::UnknownCause, true);
            return;
        }
        match a.type_id() {
            TypeId::C_IC_NA_1 => self.interrogation(&a),
            TypeId::C_CI_NA_1 => self.counter_interrogation(&a),
            TypeId::C_CS_NA_1 => {
                // Confirmed with our time: the server's clock is the
                // operating system's (NTP), not set by a centre.
                let now = self.shared.ctx.clock.now().as_millis();
                if let Some(Element::ClockSync { time }) = a.objects().first().map(|o| o.element) {
                    if let Ok(theirs) = time.to_unix_ms() {
                        tracing::info!(peer = %self.peer, offset_ms = theirs - now, "IEC 104 server: clock synchronisation received (not applied)");
                    }
                }
                let ours = Cp56Time2a::from_unix_ms(now).ok();
                match ours.and_then(|time| {
                    Asdu::new(
                        TypeId::C_CS_NA_1,
                        Cause::ActCon,
                        self.shared.common_address,
                        vec![InformationObject::new(0, Element::ClockSync { time })],
                    )
                    .ok()
                }) {
                    Some(reply) => self.outbox.push_back(reply.encode()),
                    None => self.mirror(&a, Cause::ActCon, true),
                }
            }
            TypeId::C_RD_NA_1 => {
                let Some(&i) = a
                    .objects()
                    .first()
                    .and_then(|o| self.shared.by_ioa.get(&o.ioa))
                else {
                    self.mirror(&a, Cause::UnknownIoa, true);
                    return;
                };
                if let Some(s) = self.shared.ctx.db.get(self.shared.exports[i].id) {
                    let e = &self.shared.exports[i];
                    let o = InformationObject::new(e.ioa, element(e.point, &s));
                    for asdu in pack(
                        type_id(e.point, false),
                        Cause::Req,
                        self.shared.common_address,
                        vec![o],
                    ) {
                        self.outbox.push_back(asdu.encode());
                    }
                }
            }
            t if t.is_command() => self.command(a),
            _ => self.mirror(&a, Cause::UnknownType, true),
        }
    }

    /// The ASDU sent back with another cause (and P/N).
    fn mirror(&mut self, a: &Asdu, cause: Cause, negative: bool) {
        if let Ok(reply) = a.clone().with_cause(cause) {
            self.outbox
                .push_back(reply.with_negative(negative).encode());
        }
    }

    fn interrogation(&mut self, a: &Asdu) {
        let qoi = match a.objects().first().map(|o| o.element) {
            Some(Element::Interrogation { qoi }) => qoi,
            _ => 0,
        };
        if qoi != 20 || a.cause() != Cause::Act {
            // Group interrogations (21-36) are not offered.
            self.mirror(a, Cause::ActCon, true);
            return;
        }
        self.shared
            .counters
            .interrogations
            .fetch_add(1, Ordering::Relaxed);
        self.mirror(a, Cause::ActCon, false);
        // Integrated totals answer the counter interrogation, not the
        // station interrogation.
        self.send_all(Cause::InroGen, |e| {
            e.point != gridscada_config::Iec104Point::M_IT
        });
        self.mirror(a, Cause::ActTerm, false);
    }

    fn counter_interrogation(&mut self, a: &Asdu) {
        self.mirror(a, Cause::ActCon, false);
        self.send_all(Cause::ReqCoGen, |e| {
            e.point == gridscada_config::Iec104Point::M_IT
        });
        self.mirror(a, Cause::ActTerm, false);
    }

    /// Every export that `which` picks, packed by type, with or without
    /// time tags (`interrogation_time_tags`).
    fn send_all(&mut self, cause: Cause, which: impl Fn(&super::Export) -> bool) {
        let shared = Arc::clone(&self.shared);
        let timed = shared.interrogation_time_tags;
        let mut by_type: Vec<(TypeId, Vec<InformationObject>)> = Vec::new();
        for (i, e) in shared.exports.iter().enumerate() {
            if !which(e) {
                continue;
            }
            let Some(s) = shared.ctx.db.get(e.id) else {
                continue;
            };
            let t = type_id(e.point, timed);
            let mut o = InformationObject::new(e.ioa, element(e.point, &s));
            if timed {
                o.time = time_of(&s);
            }
            match by_type.iter_mut().find(|(bt, _)| *bt == t) {
                Some((_, v)) => v.push(o),
                None => by_type.push((t, vec![o])),
            }
            self.last.insert(i, s);
        }
        for (t, objects) in by_type {
            for asdu in pack(t, cause, shared.common_address, objects) {
                self.outbox.push_back(asdu.encode());
            }
        }
    }

    /// Changes of exported tags, with their time tags.
    fn spontaneous(&mut self, changes: impl Iterator<Item = (gridscada_tagdb::TagId, Sample)>) {
        let shared = Arc::clone(&self.shared);
        let mut by_type: Vec<(TypeId, Vec<InformationObject>)> = Vec::new();
        for (id, s) in changes {
            let Some(&i) = shared.by_id.get(&id) else {
                continue;
            };
            let e = &shared.exports[i];
            if !worth_sending(e, self.last.get(&i), &s) {
                continue;
            }
            let t = type_id(e.point, true);
            let mut o = InformationObject::new(e.ioa, element(e.point, &s));
            o.time = time_of(&s);
            match by_type.iter_mut().find(|(bt, _)| *bt == t) {
                Some((_, v)) => v.push(o),
                None => by_type.push((t, vec![o])),
            }
            self.last.insert(i, s);
        }
        for (t, objects) in by_type {
            shared
                .counters
                .spontaneous
                .fetch_add(objects.len() as u64, Ordering::Relaxed);
            for asdu in pack(t, Cause::Spont, shared.common_address, objects) {
                self.outbox.push_back(asdu.encode());
            }
        }
    }

    /// Periodic data (cause 1), without time tag.
    fn cyclic(&mut self, now: Instant) {
        if !self.session.is_started() {
            return;
        }
        let shared = Arc::clone(&self.shared);
        for (n, (i, period)) in shared.cyclic.iter().enumerate() {
            if now < self.next_cyclic[n] {
                continue;
            }
            self.next_cyclic[n] = now + *period;
            let e = &shared.exports[*i];
            if let Some(s) = shared.ctx.db.get(e.id) {
                let o = InformationObject::new(e.ioa, element(e.point, &s));
                for asdu in pack(
                    type_id(e.point, false),
                    Cause::PerCyc,
                    shared.common_address,
                    vec![o],
                ) {
                    self.outbox.push_back(asdu.encode());
                }
            }
        }
    }

    /// A command from the centre: select, execute or cancel.
    fn command(&mut self, a: Asdu) {
        let shared = Arc::clone(&self.shared);
        let Some(o) = a.objects().first().copied() else {
            return;
        };
        let Some(&i) = shared.by_command_ioa.get(&o.ioa) else {
            self.mirror(&a, Cause::UnknownIoa, true);
            return;
        };
        let e = &shared.exports[i];
        let select = matches!(
            o.element,
            Element::SingleCommand { select: true, .. }
                | Element::DoubleCommand { select: true, .. }
                | Element::StepCommand { select: true, .. }
                | Element::SetpointNormalized { select: true, .. }
                | Element::SetpointScaled { select: true, .. }
                | Element::SetpointFloat { select: true, .. }
        );
        let who = format!(
            "IEC 104 control centre {} (as {})",
            self.peer.ip(),
            shared.role_label
        );
        let refuse = |c: &mut Conn, why: String| {
            shared
                .counters
                .commands_refused
                .fetch_add(1, Ordering::Relaxed);
            tracing::warn!(peer = %c.peer, tag = %e.tag, %why, "IEC 104 server: command refused");
            c.mirror(&a, Cause::ActCon, true);
        };
        if a.cause() == Cause::Deact {
            self.selected.remove(&o.ioa);
            self.mirror(&a, Cause::DeactCon, false);
            return;
        }
        let current = shared.ctx.db.get(e.id).map(|s| s.value);
        let value = match command_value(e, &o.element, current.as_ref()) {
            Ok(v) => v,
            Err(why) => return refuse(self, why),
        };
        if let Err(err) = gridscada_field::check_limits(
            &e.tag,
            &value,
            shared.limits.get(&e.tag).copied().unwrap_or((None, None)),
        ) {
            return refuse(self, err.to_string());
        }
        // What the switching guard would say of it now (a safety tag, an
        // operator's selection, an interlock): the centre gets a negative
        // ActCon at once, to the select as to the execute, and the refusal
        // is on record.
        if let Err(err) = shared.ctx.writer.precheck(&e.tag, &value) {
            if err.is_refusal() {
                let why = err.to_string();
                let (on_record, tag, label, reason) =
                    (Arc::clone(&shared), e.tag.clone(), who.clone(), why.clone());
                tokio::spawn(async move {
                    let commander = Commander { user: None, label };
                    let ctx = &on_record.ctx;
                    audit_refused(&*ctx.audit, ctx.clock.now(), &commander, &tag, &reason).await;
                });
                return refuse(self, why);
            }
        }
        let now = Instant::now();
        if select {
            self.selected.insert(o.ioa, now + shared.select_timeout);
            self.mirror(&a, Cause::ActCon, false);
            return;
        }
        if e.select && self.selected.remove(&o.ioa).is_none_or(|until| now > until) {
            return refuse(self, "the point needs select before operate, and it was not selected (or the select expired)".into());
        }
        shared.counters.commands.fetch_add(1, Ordering::Relaxed);
        self.mirror(&a, Cause::ActCon, false);
        let (tag, old) = (
            e.tag.clone(),
            current.map(|v| v.to_string()).unwrap_or_default(),
        );
        let tx = self.outcomes_tx.clone();
        tokio::spawn(async move {
            let ctx = &shared.ctx;
            let commander = Commander {
                user: None,
                label: who,
            };
            let r = audited_write(
                &*ctx.audit,
                &*ctx.writer,
                || ctx.clock.now(),
                &commander,
                &tag,
                &old,
                value,
            )
            .await;
            let ok = match r {
                Ok(_) => true,
                Err(CommandError::Write(e)) if e.is_refusal() => {
                    shared
                        .counters
                        .commands_refused
                        .fetch_add(1, Ordering::Relaxed);
                    false
                }
                Err(_) => {
                    shared
                        .counters
                        .commands_failed
                        .fetch_add(1, Ordering::Relaxed);
                    false
                }
            };
            let _ = tx.send(Outcome { asdu: a, ok }).await;
        });
    }

    async fn send(
        &mut self,
        write: &mut tokio::net::tcp::OwnedWriteHalf,
        frames: Vec<Frame>,
    ) -> Result<(), String> {
        for f in frames {
            let bytes = apci::encode(&f).map_err(|e| e.to_string())?;
            tokio::time::timeout(self.shared.session.t1, write.write_all(&bytes))
                .await
                .map_err(|_| "the centre did not take our frames within t1".to_string())?
                .map_err(|e| format!("write failed: {e}"))?;
        }
        Ok(())
    }

    /// Sends what the k window has room for.
    async fn flush(&mut self, write: &mut tokio::net::tcp::OwnedWriteHalf) -> Result<(), String> {
        let mut frames = Vec::new();
        let now = Instant::now();
        while self.session.can_send() {
            let Some(asdu) = self.outbox.pop_front() else {
                break;
            };
            frames.push(self.session.send_i(asdu, now));
        }
        self.send(write, frames).await
    }
}
