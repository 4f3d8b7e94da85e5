//! One IED's task: the association (re-opened with back-off), its report
//! control blocks enabled (buffered ones resumed from the last `EntryID`),
//! reports and polls into the tag database, controls run beside them, and
//! the status tags.

use std::collections::{HashMap, HashSet};
use std::sync::atomic::{AtomicU8, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use gridscada_config::CtlModel;
use gridscada_field::{Notices, StatusIds};
use gridscada_tagdb::{Clock, Quality as TagQuality, Sample, TagDb, Value, WriteError};
use tokio::sync::{mpsc, watch};

use super::points::{bind, flatten, sample, Binding, IedTag};
use super::{CommandRequest, ControlSpec, Counters};
use crate::acsi::{self, opt, trg, ControlParams, ControlValue, Report};
use crate::client::connection::{Connection, MmsError, Unsolicited};
use crate::data::{Data, UtcTime};
use crate::iso::Addressing;
use crate::mms::{bits, ObjectName, Request, Response, TypeSpec};

/// How long an association must last for the back-off to start over.
const STABLE_ASSOCIATION: Duration = Duration::from_secs(10);

/// A report control block to enable.
#[derive(Debug, Clone)]
pub(crate) struct ReportSettings {
    /// As configured (`LD/LN.BR.name`).
    pub label: String,
    pub domain: String,
    /// `LN$BR$name` or `LN$RP$name`.
    pub item: String,
    pub buffered: bool,
    /// The dataset it must report, `LD/LN$name`.
    pub dataset: Option<String>,
    pub integrity_ms: Option<u32>,
    pub buffer_ms: Option<u32>,
    pub gi: bool,
}

/// Everything the task needs from the configuration.
pub(crate) struct Settings {
    pub name: String,
    pub address: String,
    pub addressing: Addressing,
    pub response_timeout: Duration,
    pub command_timeout: Duration,
    pub scan: Duration,
    pub backoff_max: Duration,
    pub reports: Vec<ReportSettings>,
    pub or_cat: i64,
}

/// A report control block once enabled: how its members map to tags.
struct ActiveReport {
    settings: ReportSettings,
    rpt_id: String,
    members: Vec<Vec<Binding>>,
}

/// A data object read by polling.
struct PollGroup {
    object: ObjectName,
    bindings: Vec<Binding>,
}

pub(crate) struct Ied {
    s: Settings,
    tags: Vec<IedTag>,
    status: StatusIds,
    counters: Arc<Counters>,
    db: Arc<TagDb>,
    clock: Arc<dyn Clock>,
    commands: mpsc::Receiver<CommandRequest>,
    notices: Notices,
    /// The last entry of each buffered RCB, kept across associations so a
    /// reconnect resumes where the reports stopped.
    entry_ids: HashMap<String, Vec<u8>>,
    backoff: Duration,
    ctl_num: Arc<AtomicU8>,
}

impl Ied {
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        s: Settings,
        tags: Vec<IedTag>,
        status: StatusIds,
        counters: Arc<Counters>,
        db: Arc<TagDb>,
        clock: Arc<dyn Clock>,
        commands: mpsc::Receiver<CommandRequest>,
        notices: Notices,
    ) -> Ied {
        Ied {
            s,
            tags,
            status,
            counters,
            db,
            clock,
            commands,
            notices,
            entry_ids: HashMap::new(),
            backoff: Duration::from_millis(250),
            ctl_num: Arc::new(AtomicU8::new(0)),
        }
    }

    pub async fn run(mut self, mut shutdown: watch::Receiver<bool>) {
        self.publish_status();
        loop {
            if *shutdown.borrow() {
                break;
            }
            self.counters.requests.fetch_add(1, Ordering::Relaxed);
            let opened = tokio::select! {
                _ = shutdown.changed() => break,
                r = Connection::open(&self.s.address, self.s.addressing.clone(), self.s.response_timeout) => r,
            };
            let reason = match opened {
                Ok((conn, unsolicited)) => {
                    let opened_at = Instant::now();
                    self.counters.connects.fetch_add(1, Ordering::Relaxed);
                    self.counters.last_error.lock().clear();
                    tracing::info!(ied = %self.s.name, address = %self.s.address, "IEC 61850 association open");
                    let conn = Arc::new(conn);
                    let end = self.session(&conn, unsolicited, &mut shutdown).await;
                    if end.is_none() {
                        conn.conclude(Duration::from_millis(500)).await;
                        break;
                    }
                    self.counters.disconnects.fetch_add(1, Ordering::Relaxed);
                    if conn.ended_malformed() {
                        self.counters.malformed.fetch_add(1, Ordering::Relaxed);
                    }
                    // Only an association that lasted starts the back-off
                    // over: an IED that accepts and then fails at once is
                    // not hammered.
                    if opened_at.elapsed() >= STABLE_ASSOCIATION {
                        self.backoff = Duration::from_millis(250);
                    }
                    end
                }
                Err(e) => {
                    if matches!(e, MmsError::Timeout(_)) {
                        self.counters.timeouts.fetch_add(1, Ordering::Relaxed);
                    }
                    Some(e.to_string())
                }
            };
            if let Some(reason) = reason {
                self.lost(&reason);
            }
            let wait = self.backoff;
            self.backoff = (self.backoff * 2).min(self.s.backoff_max);
            tokio::select! {
                _ = shutdown.changed() => break,
                _ = tokio::time::sleep(wait) => {}
                // Commands while the IED is unreachable fail at once.
                Some(c) = self.commands.recv() => {
                    let _ = c.reply.send(Err(WriteError::Device {
                        device: self.s.name.clone(),
                        reason: "no association with the IED; nothing was sent".into(),
                    }));
                }
            }
        }
        self.counters.connected.store(false, Ordering::Relaxed);
    }

    /// One association, until it ends (`Some(reason)`) or shutdown (`None`).
    async fn session(
        &mut self,
        conn: &Arc<Connection>,
        mut unsolicited: mpsc::Receiver<Unsolicited>,
        shutdown: &mut watch::Receiver<bool>,
    ) -> Option<String> {
        let mut types: HashMap<ObjectName, TypeSpec> = HashMap::new();
        let setup = async {
            let groups = self.poll_groups(conn, &mut types).await?;
            self.read_groups(conn, &groups.iter().collect::<Vec<_>>())
                .await?;
            let mut reports = Vec::new();
            for r in self.s.reports.clone() {
                match self.enable_report(conn, &r, &mut types).await {
                    Ok(active) => reports.push(active),
                    Err(MmsError::Closed(why)) => return Err(MmsError::Closed(why)),
                    Err(e) => {
                        let msg = format!(
                            "report {}: could not be enabled, its data is polled instead: {e}",
                            r.label
                        );
                        tracing::warn!(ied = %self.s.name, "{msg}");
                        self.notices.send(&self.s.name, msg.clone());
                        self.set_error(&msg);
                    }
                }
            }
            Ok::<_, MmsError>((groups, reports))
        };
        let (groups, reports) = match setup.await {
            Ok(x) => x,
            Err(e) => return Some(e.to_string()),
        };
        self.counters.connected.store(true, Ordering::Relaxed);
        self.publish_status();
        // Tags a report covers are not polled after the first read.
        let covered: HashSet<usize> = reports
            .iter()
            .flat_map(|r| r.members.iter().flatten().map(|b| b.tag))
            .collect();
        let polled: Vec<&PollGroup> = groups
            .iter()
            .filter(|g| g.bindings.iter().any(|b| !covered.contains(&b.tag)))
            .collect();
        let mut tick = tokio::time::interval(self.s.scan);
        tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
        tick.tick().await;
        let mut in_flight: Option<tokio::task::JoinHandle<()>> = None;
        loop {
            tokio::select! {
                _ = shutdown.changed() => return None,
                _ = tick.tick(), if !polled.is_empty() => {
                    if let Err(e) = self.read_groups(conn, &polled).await {
                        if conn.is_closed() || !matches!(e, MmsError::Timeout(_)) {
                            return Some(e.to_string());
                        }
                        self.counters.timeouts.fetch_add(1, Ordering::Relaxed);
                        self.set_error(&e.to_string());
                    }
                    self.publish_status();
                }
                u = unsolicited.recv() => match u {
                    Some(Unsolicited::Report(r)) => self.on_report(&r, &reports),
                    Some(Unsolicited::Closed { reason }) => return Some(reason),
                    None => return Some("the association's reader stopped".into()),
                },
                Some(c) = self.commands.recv() => {
                    // One control at a time per IED, beside reports and polls.
                    if in_flight.as_ref().is_some_and(|h| !h.is_finished()) {
                        let _ = c.reply.send(Err(WriteError::Device {
                            device: self.s.name.clone(),
                            reason: "another control of this IED is in progress; nothing was sent".into(),
                        }));
                        continue;
                    }
                    let control = Control {
                        conn: Arc::clone(conn),
                        device: self.s.name.clone(),
                        command_timeout: self.s.command_timeout,
                        response_timeout: self.s.response_timeout,
                        or_cat: self.s.or_cat,
                        ctl_num: Arc::clone(&self.ctl_num),
                        clock: Arc::clone(&self.clock),
                        counters: Arc::clone(&self.counters),
                    };
                    in_flight = Some(tokio::spawn(async move {
                        let result = control.operate(&c.spec, &c.value, &c.originator).await;
                        let _ = c.reply.send(result);
                    }));
                }
            }
        }
    }

    /// Each data object the tags read, with its type's leaves bound.
    async fn poll_groups(
        &self,
        conn: &Connection,
        types: &mut HashMap<ObjectName, TypeSpec>,
    ) -> Result<Vec<PollGroup>, MmsError> {
        let mut objects: Vec<ObjectName> = Vec::new();
        for t in &self.tags {
            let o = t.object();
            if !objects.contains(&o) {
                objects.push(o);
            }
        }
        let mut groups = Vec::new();
        for object in objects {
            let ty = match type_of(conn, &object, types, self.s.response_timeout).await {
                Ok(t) => t,
                Err(MmsError::Service(e)) => {
                    self.mark_missing(&object, &e.to_string());
                    continue;
                }
                Err(e) => return Err(e),
            };
            let mut leaves = Vec::new();
            ty.leaves("", &mut leaves);
            let ObjectName::Domain(domain, item) = &object else {
                continue;
            };
            let bindings = bind(domain, item, &leaves, &self.tags);
            groups.push(PollGroup { object, bindings });
        }
        Ok(groups)
    }

    fn mark_missing(&self, object: &ObjectName, why: &str) {
        let ids: Vec<_> = self
            .tags
            .iter()
            .filter(|t| t.object() == *object)
            .map(|t| t.id)
            .collect();
        let q = TagQuality::bad(format!("the IED has no {object}: {why}"));
        self.db.set_quality(&ids, &q, self.clock.now());
        self.notices.send(
            &self.s.name,
            format!("the IED does not have {object} ({why}); its tags stay Bad"),
        );
    }

    /// Reads the groups marked in `which`, a few data objects per request.
    async fn read_groups(&self, conn: &Connection, groups: &[&PollGroup]) -> Result<(), MmsError> {
        for chunk in groups.chunks(16) {
            let names: Vec<ObjectName> = chunk.iter().map(|g| g.object.clone()).collect();
            let started = Instant::now();
            self.counters.requests.fetch_add(1, Ordering::Relaxed);
            let results = match conn
                .request(&Request::Read(names), self.s.response_timeout)
                .await?
            {
                Response::Read(r) => r,
                other => return Err(MmsError::Unexpected(format!("{other:?} to a read"))),
            };
            self.counters.observe(started.elapsed());
            let now = self.clock.now();
            let mut batch = Vec::new();
            for (g, r) in chunk.iter().zip(results) {
                match r {
                    Ok(d) => self.samples(&d, &g.bindings, now, &mut batch),
                    Err(e) => {
                        let ids: Vec<_> = g.bindings.iter().map(|b| self.tags[b.tag].id).collect();
                        self.db.set_quality(
                            &ids,
                            &TagQuality::bad(format!(
                                "the IED refused the read of {}: {e}",
                                g.object
                            )),
                            now,
                        );
                    }
                }
            }
            self.db.apply(batch);
        }
        Ok(())
    }

    fn samples(
        &self,
        d: &Data,
        bindings: &[Binding],
        received: gridscada_tagdb::Timestamp,
        out: &mut Vec<(gridscada_tagdb::TagId, Sample)>,
    ) {
        let mut leaves = Vec::new();
        flatten(d, &mut leaves);
        for b in bindings {
            let tag = &self.tags[b.tag];
            let Some(v) = leaves.get(b.value) else {
                out.push((
                    tag.id,
                    Sample {
                        value: self.db.get(tag.id).map_or(Value::Float(0.0), |s| s.value),
                        quality: TagQuality::bad(format!(
                            "the IED sent {} without {}",
                            tag.data_object, tag.item
                        )),
                        timestamp: received,
                    },
                ));
                continue;
            };
            let q = b.quality.and_then(|i| leaves.get(i).copied());
            let t = b.time.and_then(|i| leaves.get(i).copied());
            out.push((
                tag.id,
                sample(tag, v, q, t, received, |id| {
                    self.db.get(id).map(|s| s.value)
                }),
            ));
        }
    }

    /// Configures and enables one report control block.
    async fn enable_report(
        &mut self,
        conn: &Connection,
        r: &ReportSettings,
        types: &mut HashMap<ObjectName, TypeSpec>,
    ) -> Result<ActiveReport, MmsError> {
        let t = self.s.response_timeout;
        let attr = |a: &str| ObjectName::Domain(r.domain.clone(), format!("{}${a}", r.item));
        let read = Request::Read(vec![attr("RptID"), attr("DatSet"), attr("TrgOps")]);
        let Response::Read(v) = conn.request(&read, t).await? else {
            return Err(MmsError::Unexpected("not a read response".into()));
        };
        let text = |i: usize| match v.get(i) {
            Some(Ok(Data::VisibleString(s))) | Some(Ok(Data::MmsString(s))) => Ok(s.clone()),
            Some(Err(e)) => Err(MmsError::Unexpected(format!(
                "the IED has no such report control block ({e})"
            ))),
            _ => Err(MmsError::Unexpected(
                "the RCB's attributes are not strings".into(),
            )),
        };
        let rpt_id = text(0)?;
        let dataset = text(1)?;
        if let Some(want) = &r.dataset {
            if &dataset != want {
                return Err(MmsError::Unexpected(format!(
                    "it reports dataset '{dataset}', not '{want}'"
                )));
            }
        }
        let (ds_domain, ds_item) = dataset.split_once('/').ok_or_else(|| {
            MmsError::Unexpected(format!(
                "its dataset reference '{dataset}' has no logical device"
            ))
        })?;
        let list = ObjectName::Domain(ds_domain.to_string(), ds_item.to_string());
        let members = match conn
            .request(&Request::GetNamedVariableListAttributes(list), t)
            .await?
        {
            Response::GetNamedVariableListAttributes(m) => m,
            other => {
                return Err(MmsError::Unexpected(format!(
                    "{other:?} to the dataset's directory"
                )))
            }
        };
        let mut bound = Vec::with_capacity(members.len());
        for m in &members {
            let ty = type_of(conn, m, types, t).await?;
            let mut leaves = Vec::new();
            ty.leaves("", &mut leaves);
            let ObjectName::Domain(d, i) = m else {
                bound.push(Vec::new());
                continue;
            };
            bound.push(bind(d, i, &leaves, &self.tags));
        }
        let write = |a: &str, d: Data| Request::Write(attr(a), d);
        // Disable first: settings cannot change while it is enabled.
        let _ = conn
            .request(&write("RptEna", Data::Boolean(false)), t)
            .await;
        if r.buffered {
            // Reserve it for us over a reconnect (IEC 61850-8-1 Ed.2).
            let _ = conn.request(&write("ResvTms", Data::Integer(60)), t).await;
        } else {
            expect_written(
                conn.request(&write("Resv", Data::Boolean(true)), t).await,
                "Resv",
            )?;
        }
        let mut options = vec![
            opt::SEQ_NUM,
            opt::TIME_STAMP,
            opt::REASON,
            opt::DATA_SET,
            opt::CONF_REV,
        ];
        if r.buffered {
            options.extend([opt::ENTRY_ID, opt::BUFFER_OVERFLOW]);
        }
        expect_written(
            conn.request(&write("OptFlds", Data::BitString(bits(10, &options))), t)
                .await,
            "OptFlds",
        )?;
        let mut triggers: Vec<usize> = match v.get(2) {
            Some(Ok(Data::BitString(b))) => (0..b.len).filter(|i| b.bit(*i)).collect(),
            _ => vec![trg::DATA_CHANGE, trg::QUALITY_CHANGE],
        };
        triggers.push(trg::GI);
        if let Some(ms) = r.integrity_ms {
            if ms > 0 {
                triggers.push(trg::INTEGRITY);
            }
            expect_written(
                conn.request(&write("IntgPd", Data::Unsigned(u64::from(ms))), t)
                    .await,
                "IntgPd",
            )?;
        }
        if let Some(ms) = r.buffer_ms {
            expect_written(
                conn.request(&write("BufTm", Data::Unsigned(u64::from(ms))), t)
                    .await,
                "BufTm",
            )?;
        }
        expect_written(
            conn.request(&write("TrgOps", Data::BitString(bits(6, &triggers))), t)
                .await,
            "TrgOps",
        )?;
        if r.buffered {
            if let Some(entry) = self.entry_ids.get(&r.label) {
                if let Err(e) = expect_written(
                    conn.request(&write("EntryID", Data::OctetString(entry.clone())), t)
                        .await,
                    "EntryID",
                ) {
                    self.notices.send(
                        &self.s.name,
                        format!("report {}: could not resume after the last entry ({e}); events while the association was down may be lost", r.label),
                    );
                }
            }
        }
        expect_written(
            conn.request(&write("RptEna", Data::Boolean(true)), t).await,
            "RptEna",
        )?;
        if r.gi {
            expect_written(
                conn.request(&write("GI", Data::Boolean(true)), t).await,
                "GI",
            )?;
        }
        tracing::info!(ied = %self.s.name, rcb = %r.label, dataset = %dataset, members = members.len(), "report enabled");
        Ok(ActiveReport {
            rpt_id: if rpt_id.is_empty() {
                format!("{}/{}", r.domain, r.item)
            } else {
                rpt_id
            },
            settings: r.clone(),
            members: bound,
        })
    }

    fn on_report(&mut self, r: &crate::mms::InformationReport, reports: &[ActiveReport]) {
        if !Report::is_report(r) {
            return;
        }
        let rep = match Report::decode(r) {
            Ok(rep) => rep,
            Err(e) => {
                self.counters.malformed.fetch_add(1, Ordering::Relaxed);
                self.set_error(&e.to_string());
                return;
            }
        };
        let Some(active) = reports.iter().find(|a| a.rpt_id == rep.rpt_id) else {
            return;
        };
        self.counters
            .events
            .fetch_add(rep.entries.len() as u64, Ordering::Relaxed);
        if rep.buffer_overflow {
            self.counters.overflows.fetch_add(1, Ordering::Relaxed);
            self.notices.send(
                &self.s.name,
                format!(
                    "report {}: the IED's buffer overflowed; some events were lost",
                    active.settings.label
                ),
            );
        }
        let now = self.clock.now();
        let mut batch = Vec::new();
        for e in &rep.entries {
            if let Some(bindings) = active.members.get(e.member) {
                self.samples(&e.value, bindings, now, &mut batch);
            }
        }
        // Each entry is an event at the IED's time, even where it repeats
        // the current value (a buffered entry replayed after an outage).
        self.db.apply_events(batch);
        if let (Some(entry), true) = (rep.entry_id, active.settings.buffered) {
            self.entry_ids.insert(active.settings.label.clone(), entry);
        }
    }

    fn lost(&mut self, reason: &str) {
        let reason = format!("{}: {reason}", self.s.address);
        tracing::warn!(ied = %self.s.name, %reason, "IEC 61850 association lost");
        self.counters.connected.store(false, Ordering::Relaxed);
        self.set_error(&reason);
        let ids: Vec<_> = self.tags.iter().map(|t| t.id).collect();
        self.db.set_quality(
            &ids,
            &TagQuality::bad(format!("communication lost: {reason}")),
            self.clock.now(),
        );
        self.publish_status();
    }

    fn set_error(&self, reason: &str) {
        self.counters.errors.fetch_add(1, Ordering::Relaxed);
        *self.counters.last_error.lock() = reason.to_string();
        self.db.set(
            self.status.last_error,
            Value::Str(reason.into()),
            TagQuality::GOOD,
            self.clock.now(),
        );
    }

    fn publish_status(&self) {
        let c = &self.counters;
        let get = |a: &std::sync::atomic::AtomicU64| a.load(Ordering::Relaxed);
        self.status.publish(
            &self.db,
            self.clock.now(),
            gridscada_field::StatusFigures {
                connected: c.connected.load(Ordering::Relaxed),
                response_ms: get(&c.response_us) as f64 / 1000.0,
                requests: get(&c.requests),
                errors: get(&c.errors),
                timeouts: get(&c.timeouts),
            },
        );
    }
}

fn expect_written(r: Result<Response, MmsError>, what: &str) -> Result<(), MmsError> {
    match r? {
        Response::Write(results) => match results.first() {
            Some(Ok(())) => Ok(()),
            Some(Err(e)) => Err(MmsError::Unexpected(format!("writing {what}: {e}"))),
            None => Err(MmsError::Unexpected(format!(
                "writing {what}: an empty answer"
            ))),
        },
        other => Err(MmsError::Unexpected(format!("writing {what}: {other:?}"))),
    }
}

/// A variable's type, asked of the IED once per association.
async fn type_of(
    conn: &Connection,
    name: &ObjectName,
    types: &mut HashMap<ObjectName, TypeSpec>,
    timeout: Duration,
) -> Result<TypeSpec, MmsError> {
    if let Some(t) = types.get(name) {
        return Ok(t.clone());
    }
    match conn
        .request(&Request::GetVariableAccessAttributes(name.clone()), timeout)
        .await?
    {
        Response::GetVariableAccessAttributes(t) => {
            types.insert(name.clone(), t.clone());
            Ok(t)
        }
        other => Err(MmsError::Unexpected(format!(
            "{other:?} to the type of {name}"
        ))),
    }
}

/// One control's run, beside the IED's task.
struct Control {
    conn: Arc<Connection>,
    device: String,
    command_timeout: Duration,
    response_timeout: Duration,
    or_cat: i64,
    ctl_num: Arc<AtomicU8>,
    clock: Arc<dyn Clock>,
    counters: Arc<Counters>,
}

impl Control {
    fn fail(&self, reason: String) -> WriteError {
        self.counters
            .commands_failed
            .fetch_add(1, Ordering::Relaxed);
        WriteError::Device {
            device: self.device.clone(),
            reason,
        }
    }

    async fn operate(
        &self,
        spec: &ControlSpec,
        value: &Value,
        originator: &str,
    ) -> Result<(), WriteError> {
        self.counters.commands.fetch_add(1, Ordering::Relaxed);
        let t = self.response_timeout;
        let co = |a: &str| {
            ObjectName::Domain(
                spec.domain.clone(),
                format!("{}$CO${}${a}", spec.ln, spec.data_object),
            )
        };
        let model = match spec.ctl_model {
            Some(m) => m,
            None => {
                let name = ObjectName::Domain(
                    spec.domain.clone(),
                    format!("{}$CF${}$ctlModel", spec.ln, spec.data_object),
                );
                match self.conn.request(&Request::Read(vec![name]), t).await {
                    Ok(Response::Read(r)) => match r.first() {
                        Some(Ok(d)) => d
                            .as_f64()
                            .and_then(|n| CtlModel::from_code(n as i64))
                            .ok_or_else(|| {
                                self.fail(format!(
                                    "the IED's ctlModel of {} is {d:?}",
                                    spec.label()
                                ))
                            })?,
                        Some(Err(e)) => {
                            return Err(
                                self.fail(format!("reading the ctlModel of {}: {e}", spec.label()))
                            )
                        }
                        None => {
                            return Err(self.fail("an empty answer to the ctlModel read".into()))
                        }
                    },
                    Ok(other) => return Err(self.fail(format!("{other:?} to the ctlModel read"))),
                    Err(e) => {
                        return Err(
                            self.fail(format!("reading the ctlModel: {e}; nothing was sent"))
                        )
                    }
                }
            }
        };
        if model == CtlModel::StatusOnly {
            return Err(self.fail(format!(
                "{} is status-only on the IED: it cannot be operated",
                spec.label()
            )));
        }
        let oper = co("Oper");
        let oper_type = match self
            .conn
            .request(&Request::GetVariableAccessAttributes(oper.clone()), t)
            .await
        {
            Ok(Response::GetVariableAccessAttributes(ty)) => ty,
            Ok(other) => return Err(self.fail(format!("{other:?} to the type of {oper}"))),
            Err(e) => {
                return Err(self.fail(format!("the IED has no {oper}: {e}; nothing was sent")))
            }
        };
        let ctl_val = match value {
            Value::Bool(b) => ControlValue::Bool(*b),
            // A double-point status tag (1 off/open, 2 on/closed) commands
            // a boolean ctlVal.
            Value::Int(n) if spec.double_point => match n {
                2 => ControlValue::Bool(true),
                1 => ControlValue::Bool(false),
                other => {
                    return Err(WriteError::BadValue {
                        tag: spec.tag.to_string(),
                        value: other.to_string(),
                        reason: "a double-point control takes 2 (on, close) or 1 (off, open)"
                            .into(),
                    })
                }
            },
            other => match other.as_f64() {
                Some(n) => ControlValue::Number((n - spec.offset) / spec.scale),
                None => {
                    return Err(WriteError::BadValue {
                        tag: spec.tag.to_string(),
                        value: other.to_string(),
                        reason: "not a number or a bool".into(),
                    })
                }
            },
        };
        let params = ControlParams {
            or_cat: self.or_cat,
            or_ident: originator.as_bytes().iter().copied().take(64).collect(),
            ctl_num: self.ctl_num.fetch_add(1, Ordering::Relaxed),
            time: UtcTime::from_unix_ms(self.clock.now().as_millis(), 0x0a),
            test: spec.test,
            interlock_check: spec.interlock_check,
            synchro_check: spec.synchro_check,
        };
        let oper_value = acsi::control_value(&oper_type, &ctl_val, &params).map_err(|why| {
            WriteError::BadValue {
                tag: spec.tag.to_string(),
                value: value.to_string(),
                reason: why,
            }
        })?;
        let refusal = |step: &str, object: &ObjectName, e: String| {
            let key = object.to_string();
            match self.conn.take_last_appl_error(&key) {
                Some(err) => self.fail(format!(
                    "{step} of {} refused: {}",
                    spec.label(),
                    err.describe()
                )),
                None => self.fail(format!("{step} of {} refused: {e}", spec.label())),
            }
        };
        match model {
            CtlModel::SboWithNormalSecurity => {
                let sbo = co("SBO");
                match self
                    .conn
                    .request(&Request::Read(vec![sbo.clone()]), t)
                    .await
                {
                    Ok(Response::Read(r)) => match r.first() {
                        Some(Ok(Data::VisibleString(s))) if !s.is_empty() => {}
                        Some(Ok(_)) => {
                            return Err(self.fail(format!(
                                "select of {} refused by the IED (nothing was operated)",
                                spec.label()
                            )))
                        }
                        Some(Err(e)) => {
                            return Err(
                                self.fail(format!("select of {} refused: {e}", spec.label()))
                            )
                        }
                        None => return Err(self.fail("an empty answer to the select".into())),
                    },
                    Ok(other) => return Err(self.fail(format!("{other:?} to the select"))),
                    Err(e) => return Err(self.fail(format!("select of {}: {e}", spec.label()))),
                }
            }
            CtlModel::SboWithEnhancedSecurity => {
                let sbow = co("SBOw");
                self.conn.clear_last_appl_error(&sbow.to_string());
                let r = self
                    .conn
                    .request(&Request::Write(sbow.clone(), oper_value.clone()), t)
                    .await;
                if let Err(e) = expect_written(r, "SBOw") {
                    return Err(refusal("select", &sbow, e.to_string()));
                }
            }
            _ => {}
        }
        let termination = model
            .is_enhanced()
            .then(|| self.conn.expect_termination(&oper));
        self.conn.clear_last_appl_error(&oper.to_string());
        let r = self
            .conn
            .request(&Request::Write(oper.clone(), oper_value), t)
            .await;
        if let Err(e) = expect_written(r, "Oper") {
            return Err(refusal("operate", &oper, e.to_string()));
        }
        if let Some(rx) = termination {
            match tokio::time::timeout(self.command_timeout, rx).await {
                Ok(Ok(Ok(()))) => {}
                Ok(Ok(Err(e))) => {
                    return Err(self.fail(format!(
                        "{} operated, then ended negatively: {}",
                        spec.label(),
                        e.describe()
                    )))
                }
                Ok(Err(_)) => {
                    return Err(
                        self.fail("the association ended before the command terminated".into())
                    )
                }
                Err(_) => {
                    return Err(self.fail(format!(
                        "{} operated, but no command termination within {:.0} s",
                        spec.label(),
                        self.command_timeout.as_secs_f64()
                    )))
                }
            }
        }
        tracing::info!(device = %self.device, object = %spec.label(), model = model.label(), "control done");
        Ok(())
    }
}
