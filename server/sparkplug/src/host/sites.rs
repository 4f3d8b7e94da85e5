//! The central host's picture of its edge nodes, without I/O: what each
//! node's births declared (aliases, devices, tags), whether it is online,
//! the `bdSeq` of its session and the `seq` it must send next. One message
//! in, its effects out (samples to apply, a rebirth to request, problems
//! to log and count); the task in `link.rs` does the I/O around it.
//!
//! Tags are named `NODE.METRIC` (or `NODE.DEVICE.METRIC`), a metric's `/`
//! folders becoming `.` levels, and added to the tag database the first
//! time a birth declares them. A tag keeps its id for the life of the
//! process: a rebirth re-binds aliases to the same tags.

use std::collections::HashMap;
use std::time::Duration;

use gridscada_tagdb::{
    Quality, Sample, TagDb, TagDbError, TagId, TagMeta, Timestamp, Value, ValueKind, WriteError,
};

use crate::datatype::{self, DataType};
use crate::proto::{Metric, MetricValue, Payload, PropertySet, PropertyValueKind};
use crate::topic::{MessageType, Topic};

/// Quality reasons the central host gives remote tags.
pub const SITE_OFFLINE: &str = "site offline";
pub const DEVICE_OFFLINE: &str = "device offline";
pub const HOST_OFFLINE: &str = "central host lost the broker";

/// A gridscada edge's metric property with the tag's alarm configuration
/// (TOML of `[tag.alarm]`).
pub const PROP_ALARMS: &str = crate::edge::model::PROP_ALARMS;

/// The metric that carries a node's birth/death session number.
const BD_SEQ: &str = "bdSeq";
/// The node control metric that asks an edge node for a rebirth.
pub const REBIRTH: &str = "Node Control/Rebirth";

/// How the host names and accepts sites (from `[mqtt.host]`).
#[derive(Debug, Clone)]
pub struct SitesPolicy {
    /// The Sparkplug group (topic's second level).
    pub group: String,
    /// Edge nodes whose messages are taken; empty: all of the group.
    pub nodes: Vec<String>,
    /// `NODE.DEVICE.METRIC` instead of `NODE.METRIC` for device metrics.
    pub device_in_name: bool,
    /// Rebirth requests to one node are at least this far apart.
    pub rebirth_interval: Duration,
}

/// Something wrong with a message: logged and counted, never applied.
#[derive(Debug, Clone, PartialEq)]
pub enum Problem {
    /// Data from a node or device whose birth this host has not seen.
    NotBorn { node: String },
    /// `seq` did not follow the previous message's.
    SeqGap {
        node: String,
        expected: u8,
        got: u64,
    },
    /// A data message named an alias the birth did not declare.
    UnknownAlias { node: String, alias: u64 },
    /// A metric without name or alias, or with no usable value.
    BadMetric { node: String, reason: String },
    /// An NDEATH whose `bdSeq` is not the current session's (a stale will).
    StaleDeath { node: String },
    /// A birth that could not add its tags (name clash, room full).
    Refused { node: String, reason: String },
}

impl Problem {
    /// Short label for the `/metrics` counter.
    pub fn label(&self) -> &'static str {
        match self {
            Problem::NotBorn { .. } => "not_born",
            Problem::SeqGap { .. } => "seq_gap",
            Problem::UnknownAlias { .. } => "unknown_alias",
            Problem::BadMetric { .. } => "bad_metric",
            Problem::StaleDeath { .. } => "stale_death",
            Problem::Refused { .. } => "refused",
        }
    }
}

impl std::fmt::Display for Problem {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Problem::NotBorn { node } => write!(f, "{node}: data before a birth"),
            Problem::SeqGap {
                node,
                expected,
                got,
            } => write!(f, "{node}: seq {got}, expected {expected}"),
            Problem::UnknownAlias { node, alias } => write!(f, "{node}: unknown alias {alias}"),
            Problem::BadMetric { node, reason } => write!(f, "{node}: {reason}"),
            Problem::StaleDeath { node } => {
                write!(
                    f,
                    "{node}: NDEATH of an earlier session (bdSeq differs), ignored"
                )
            }
            Problem::Refused { node, reason } => write!(f, "{node}: {reason}"),
        }
    }
}

/// What one message does.
#[derive(Debug, Default)]
pub struct Effects {
    /// New samples for the tag database (one batch).
    pub samples: Vec<(TagId, Sample)>,
    /// Ask this edge node for a rebirth (already rate-limited).
    pub rebirth: Option<String>,
    pub problems: Vec<Problem>,
    /// Tags added to the database by this message's birth.
    pub added: usize,
    /// The node went online (a birth) or offline (a death).
    pub online_changed: bool,
    /// Alarm configurations a birth carried (a gridscada edge's
    /// `gridscadaAlarms` property), for the alarm engine.
    pub alarms: Vec<RemoteAlarms>,
    /// Historical samples (an edge's store and forward): for the historian
    /// at their own timestamps, never the current value.
    pub historical: Vec<(TagId, Sample)>,
}

/// The alarms an edge declared for one of its metrics, to be raised on the
/// remote tag here.
#[derive(Debug, Clone)]
pub struct RemoteAlarms {
    /// The remote tag's name here (`NODE.METRIC`).
    pub tag: String,
    /// The edge node: the alarms' area.
    pub node: String,
    /// The metric's name at the edge.
    pub metric: String,
    pub units: String,
    pub description: String,
    pub config: gridscada_config::AlarmConfig,
}

/// Where a remote tag comes from: what a command to it must name.
#[derive(Debug, Clone)]
pub struct Remote {
    pub node: String,
    pub device: Option<String>,
    pub metric: String,
    pub alias: Option<u64>,
    pub datatype: DataType,
    pub writable: bool,
}

#[derive(Default)]
struct Node {
    online: bool,
    bd_seq: Option<u64>,
    /// The `seq` the next message must carry.
    next_seq: u8,
    aliases: HashMap<u64, TagId>,
    /// By (device, metric name), for peers that send names in data.
    names: HashMap<(Option<String>, String), TagId>,
    /// Devices born in this session, with their tags and whether online.
    devices: HashMap<String, (bool, Vec<TagId>)>,
    node_tags: Vec<TagId>,
    last_rebirth: Option<Timestamp>,
}

/// Every edge node the host has heard of.
pub struct Sites {
    policy: SitesPolicy,
    nodes: HashMap<String, Node>,
    remotes: HashMap<TagId, Remote>,
}

impl Sites {
    pub fn new(policy: SitesPolicy) -> Sites {
        Sites {
            policy,
            nodes: HashMap::new(),
            remotes: HashMap::new(),
        }
    }

    /// The remote tag behind `id`, if it is one.
    pub fn remote(&self, id: TagId) -> Option<&Remote> {
        self.remotes.get(&id)
    }

    /// How many remote tags the births have declared.
    pub fn remote_tags(&self) -> usize {
        self.remotes.len()
    }

    /// Edge nodes online now.
    pub fn online(&self) -> usize {
        self.nodes.values().filter(|n| n.online).count()
    }

    /// Whether the node (and the device, if any) of a remote tag is online.
    pub fn reachable(&self, remote: &Remote) -> Result<(), &'static str> {
        let node = self.nodes.get(&remote.node).filter(|n| n.online);
        let Some(node) = node else {
            return Err(SITE_OFFLINE);
        };
        match &remote.device {
            Some(d) if !node.devices.get(d).is_some_and(|(on, _)| *on) => Err(DEVICE_OFFLINE),
            _ => Ok(()),
        }
    }

    /// Handles one message of the group. Messages of nodes not accepted and
    /// STATE messages do nothing.
    pub fn handle(
        &mut self,
        db: &TagDb,
        topic: &Topic,
        payload: &Payload,
        now: Timestamp,
    ) -> Effects {
        let mut fx = Effects::default();
        let Topic::Message {
            group,
            kind,
            edge_node,
            device,
        } = topic
        else {
            return fx;
        };
        if *group != self.policy.group || !self.accepts(edge_node) {
            return fx;
        }
        match kind {
            MessageType::NBirth => self.node_birth(db, edge_node, payload, now, &mut fx),
            MessageType::NDeath => self.node_death(db, edge_node, payload, now, &mut fx),
            MessageType::DBirth | MessageType::DData | MessageType::NData | MessageType::DDeath => {
                if self.in_sequence(edge_node, payload, now, &mut fx) {
                    let device = device.as_deref();
                    match kind {
                        MessageType::DBirth => {
                            self.device_birth(db, edge_node, device, payload, now, &mut fx)
                        }
                        MessageType::DDeath => {
                            self.device_death(db, edge_node, device, now, &mut fx)
                        }
                        _ => self.data(db, edge_node, device, payload, now, &mut fx),
                    }
                }
            }
            // Commands are what hosts send, not what they take.
            MessageType::NCmd | MessageType::DCmd => {}
        }
        fx
    }

    /// Every remote tag Bad: the host lost the broker, so it no longer
    /// knows. Each node must be born again (a rebirth is asked of each).
    pub fn host_offline(&mut self, db: &TagDb, now: Timestamp) -> Vec<(TagId, Sample)> {
        let quality = Quality::bad(HOST_OFFLINE);
        let ids: Vec<TagId> = self.remotes.keys().copied().collect();
        for node in self.nodes.values_mut() {
            node.online = false;
            node.last_rebirth = None;
        }
        bad_samples(db, &ids, &quality, now)
    }

    /// The nodes to ask for a rebirth after the host reconnects.
    pub fn known_nodes(&self) -> Vec<String> {
        self.nodes.keys().cloned().collect()
    }

    fn accepts(&self, node: &str) -> bool {
        self.policy.nodes.is_empty() || self.policy.nodes.iter().any(|n| n == node)
    }

    fn request_rebirth(&mut self, node: &str, now: Timestamp, fx: &mut Effects) {
        let interval = self.policy.rebirth_interval;
        let n = self.nodes.entry(node.to_owned()).or_default();
        if n.last_rebirth.is_none_or(|t| now.since(t) >= interval) {
            n.last_rebirth = Some(now);
            fx.rebirth = Some(node.to_owned());
        }
    }

    /// Checks `seq` of a message after the birth; false if the node is not
    /// born (the message cannot be read without its birth).
    fn in_sequence(
        &mut self,
        node: &str,
        payload: &Payload,
        now: Timestamp,
        fx: &mut Effects,
    ) -> bool {
        let Some(n) = self.nodes.get_mut(node).filter(|n| n.online) else {
            fx.problems.push(Problem::NotBorn {
                node: node.to_owned(),
            });
            self.request_rebirth(node, now, fx);
            return false;
        };
        let expected = n.next_seq;
        let got = payload.seq.unwrap_or(u64::MAX);
        if got != u64::from(expected) {
            fx.problems.push(Problem::SeqGap {
                node: node.to_owned(),
                expected,
                got,
            });
            if let Ok(s) = u8::try_from(got) {
                n.next_seq = s.wrapping_add(1);
            }
            self.request_rebirth(node, now, fx);
        } else {
            n.next_seq = expected.wrapping_add(1);
        }
        true
    }

    fn node_birth(
        &mut self,
        db: &TagDb,
        node: &str,
        payload: &Payload,
        now: Timestamp,
        fx: &mut Effects,
    ) {
        let bd_seq = payload
            .metrics
            .iter()
            .find(|m| m.name.as_deref() == Some(BD_SEQ))
            .and_then(|m| match m.value {
                Some(MetricValue::Long(v)) => Some(v),
                Some(MetricValue::Int(v)) => Some(u64::from(v)),
                _ => None,
            });
        let n = self.nodes.entry(node.to_owned()).or_default();
        // A birth starts the session afresh: aliases and devices are the
        // new birth's; devices must be born again.
        n.online = true;
        n.bd_seq = bd_seq;
        n.next_seq = payload
            .seq
            .and_then(|s| u8::try_from(s).ok())
            .unwrap_or(0)
            .wrapping_add(1);
        n.aliases.clear();
        n.names.clear();
        n.devices.clear();
        n.node_tags.clear();
        fx.online_changed = true;
        let metrics = payload
            .metrics
            .iter()
            .filter(|m| !m.name.as_deref().is_some_and(is_control));
        self.declare(db, node, None, metrics, payload.timestamp, now, fx);
    }

    fn device_birth(
        &mut self,
        db: &TagDb,
        node: &str,
        device: Option<&str>,
        payload: &Payload,
        now: Timestamp,
        fx: &mut Effects,
    ) {
        let Some(device) = device else { return };
        if let Some(n) = self.nodes.get_mut(node) {
            // A device reborn declares its metrics anew.
            if let Some((_, old)) = n.devices.remove(device) {
                n.aliases.retain(|_, id| !old.contains(id));
                n.names.retain(|(d, _), _| d.as_deref() != Some(device));
            }
            n.devices.insert(device.to_owned(), (true, Vec::new()));
        }
        self.declare(
            db,
            node,
            Some(device),
            payload.metrics.iter(),
            payload.timestamp,
            now,
            fx,
        );
    }

    /// Takes the metrics of a birth: adds (or finds) their tags, binds their
    /// aliases, and gives each its birth value.
    #[allow(clippy::too_many_arguments)]
    fn declare<'m>(
        &mut self,
        db: &TagDb,
        node: &str,
        device: Option<&str>,
        metrics: impl Iterator<Item = &'m Metric>,
        sent: Option<u64>,
        now: Timestamp,
        fx: &mut Effects,
    ) {
        for m in metrics {
            let Some(name) = m.name.as_deref().filter(|n| !n.is_empty()) else {
                fx.problems.push(Problem::BadMetric {
                    node: node.to_owned(),
                    reason: "a birth metric without a name".into(),
                });
                continue;
            };
            let code = m.datatype.unwrap_or(0);
            let Some((datatype, kind)) =
                DataType::from_code(code).and_then(|t| Some((t, kind_of(t)?)))
            else {
                fx.problems.push(Problem::BadMetric {
                    node: node.to_owned(),
                    reason: format!("metric '{name}': data type {code} is not one gridscada reads"),
                });
                continue;
            };
            let tag = self.tag_name(node, device, name);
            let props = m.properties.as_ref();
            let same_source =
                |r: &Remote| r.node == node && r.device.as_deref() == device && r.metric == name;
            let id = match db.id(&tag) {
                Some(id) if self.remotes.get(&id).is_some_and(same_source) => {
                    if db.meta(id).is_some_and(|meta| meta.kind != kind) {
                        fx.problems.push(Problem::Refused {
                            node: node.to_owned(),
                            reason: format!(
                                "metric '{name}' changed its data type; tag '{tag}' keeps its first one until the central host restarts"
                            ),
                        });
                    }
                    id
                }
                Some(id) => {
                    let reason = match self.remotes.get(&id) {
                        Some(r) => format!(
                            "metric '{name}': tag '{tag}' is already metric '{}' of {}{} (device_in_name = true keeps devices apart)",
                            r.metric,
                            r.node,
                            r.device.as_deref().map(|d| format!("/{d}")).unwrap_or_default()
                        ),
                        None => format!("metric '{name}': tag '{tag}' is a local tag of the central host"),
                    };
                    fx.problems.push(Problem::Refused {
                        node: node.to_owned(),
                        reason,
                    });
                    continue;
                }
                None => {
                    let meta = TagMeta::new(tag.as_str(), kind)
                        .units(
                            string_prop(props, &["engUnit", "units", "Units"]).unwrap_or_default(),
                        )
                        .describe(
                            string_prop(props, &["Documentation", "description", "Description"])
                                .unwrap_or_default(),
                        )
                        // gridscada's edge says "Writable"; other edges "writable".
                        .writable(
                            bool_prop(props, "Writable").or_else(|| bool_prop(props, "writable"))
                                == Some(true),
                        );
                    match db.add(meta) {
                        Ok(id) => {
                            fx.added += 1;
                            id
                        }
                        Err(e) => {
                            let reason = match e {
                                TagDbError::Full { room, .. } => format!(
                                    "metric '{name}': no room for more remote tags (max_tags = {room})"
                                ),
                                e => format!("metric '{name}': {e}"),
                            };
                            fx.problems.push(Problem::Refused {
                                node: node.to_owned(),
                                reason,
                            });
                            continue;
                        }
                    }
                }
            };
            self.remotes.insert(
                id,
                Remote {
                    node: node.to_owned(),
                    device: device.map(str::to_owned),
                    metric: name.to_owned(),
                    alias: m.alias,
                    datatype,
                    writable: db.meta(id).is_some_and(|meta| meta.writable),
                },
            );
            if let Some(text) = string_prop(props, &[PROP_ALARMS]) {
                match toml::from_str::<gridscada_config::AlarmConfig>(&text) {
                    Ok(config) => fx.alarms.push(RemoteAlarms {
                        tag: tag.clone(),
                        node: node.to_owned(),
                        metric: name.to_owned(),
                        units: db.meta(id).map(|m| m.units.to_string()).unwrap_or_default(),
                        description: db
                            .meta(id)
                            .map(|m| m.description.to_string())
                            .unwrap_or_default(),
                        config,
                    }),
                    Err(e) => fx.problems.push(Problem::BadMetric {
                        node: node.to_owned(),
                        reason: format!(
                            "metric '{name}': its {PROP_ALARMS} property is no alarm configuration ({})",
                            e.message()
                        ),
                    }),
                }
            }
            let n = self.nodes.entry(node.to_owned()).or_default();
            if let Some(alias) = m.alias {
                n.aliases.insert(alias, id);
            }
            n.names
                .insert((device.map(str::to_owned), name.to_owned()), id);
            match device.and_then(|d| n.devices.get_mut(d)) {
                Some((_, tags)) => tags.push(id),
                None => n.node_tags.push(id),
            }
            let kind = db.meta(id).map_or(kind, |meta| meta.kind);
            let last = db.get(id).map(|s| s.value);
            fx.samples
                .push((id, sample_of(m, datatype, kind, last, sent, now)));
        }
    }

    fn data(
        &mut self,
        db: &TagDb,
        node: &str,
        device: Option<&str>,
        payload: &Payload,
        now: Timestamp,
        fx: &mut Effects,
    ) {
        let Some(n) = self.nodes.get(node) else {
            return;
        };
        if let Some(d) = device {
            if !n.devices.get(d).is_some_and(|(on, _)| *on) {
                fx.problems.push(Problem::NotBorn {
                    node: format!("{node}/{d}"),
                });
                self.request_rebirth(node, now, fx);
                return;
            }
        }
        let mut unknown = None;
        for m in &payload.metrics {
            // An alias is the node's, but must name a metric of this
            // message's device (or of the node, for NDATA).
            let of_here = |id: &TagId| {
                self.remotes
                    .get(id)
                    .is_some_and(|r| r.device.as_deref() == device)
            };
            let id = match (m.alias, m.name.as_deref()) {
                (Some(alias), _) if n.aliases.get(&alias).is_some_and(of_here) => n.aliases[&alias],
                (_, Some(name))
                    if n.names
                        .contains_key(&(device.map(str::to_owned), name.to_owned())) =>
                {
                    n.names[&(device.map(str::to_owned), name.to_owned())]
                }
                (Some(alias), _) => {
                    unknown = Some(alias);
                    continue;
                }
                (None, name) => {
                    // A control metric in NDATA is no tag.
                    if !name.is_some_and(is_control) {
                        fx.problems.push(Problem::BadMetric {
                            node: node.to_owned(),
                            reason: format!(
                                "a data metric that no birth declared ({})",
                                name.unwrap_or("no name, no alias")
                            ),
                        });
                    }
                    continue;
                }
            };
            let (Some(remote), Some(meta)) = (self.remotes.get(&id), db.meta(id)) else {
                continue;
            };
            let datatype = m
                .datatype
                .and_then(DataType::from_code)
                .unwrap_or(remote.datatype);
            let last = db.get(id).map(|s| s.value);
            let sample = sample_of(m, datatype, meta.kind, last, payload.timestamp, now);
            // Historical samples (store and forward) are the edge's past:
            // the historian takes them at their timestamps; they do not
            // replace the current value.
            if m.is_historical == Some(true) {
                fx.historical.push((id, sample));
            } else {
                fx.samples.push((id, sample));
            }
        }
        if let Some(alias) = unknown {
            fx.problems.push(Problem::UnknownAlias {
                node: node.to_owned(),
                alias,
            });
            self.request_rebirth(node, now, fx);
        }
    }

    fn node_death(
        &mut self,
        db: &TagDb,
        node: &str,
        payload: &Payload,
        now: Timestamp,
        fx: &mut Effects,
    ) {
        let Some(n) = self.nodes.get_mut(node) else {
            return;
        };
        let bd_seq = payload
            .metrics
            .iter()
            .find(|m| m.name.as_deref() == Some(BD_SEQ))
            .and_then(|m| match m.value {
                Some(MetricValue::Long(v)) => Some(v),
                Some(MetricValue::Int(v)) => Some(u64::from(v)),
                _ => None,
            });
        // The will of an earlier session arriving late must not kill this one.
        if n.bd_seq.is_some() && bd_seq.is_some() && n.bd_seq != bd_seq {
            fx.problems.push(Problem::StaleDeath {
                node: node.to_owned(),
            });
            return;
        }
        if !n.online {
            return;
        }
        n.online = false;
        fx.online_changed = true;
        let mut ids = n.node_tags.clone();
        for (on, tags) in n.devices.values_mut() {
            *on = false;
            ids.extend_from_slice(tags);
        }
        fx.samples = bad_samples(db, &ids, &Quality::bad(SITE_OFFLINE), now);
    }

    fn device_death(
        &mut self,
        db: &TagDb,
        node: &str,
        device: Option<&str>,
        now: Timestamp,
        fx: &mut Effects,
    ) {
        let Some((on, tags)) = device.and_then(|d| self.nodes.get_mut(node)?.devices.get_mut(d))
        else {
            return;
        };
        *on = false;
        fx.samples = bad_samples(db, tags, &Quality::bad(DEVICE_OFFLINE), now);
    }

    fn tag_name(&self, node: &str, device: Option<&str>, metric: &str) -> String {
        let metric = metric.replace('/', ".");
        match device {
            Some(d) if self.policy.device_in_name => format!("{node}.{d}.{metric}"),
            _ => format!("{node}.{metric}"),
        }
    }

    /// The NCMD/DCMD that writes `value` to a remote tag, and the value the
    /// edge will report once it has taken it (the value as the wire carries
    /// it: a Float metric holds f32).
    pub fn command(
        &self,
        db: &TagDb,
        name: &str,
        value: &Value,
        now: Timestamp,
    ) -> Result<(TagId, Topic, Payload, Value), WriteError> {
        let unknown = || WriteError::UnknownTag(name.to_owned());
        let id = db.id(name).ok_or_else(unknown)?;
        let remote = self.remotes.get(&id).ok_or_else(unknown)?;
        let meta = db.meta(id).ok_or_else(unknown)?;
        if !remote.writable {
            return Err(WriteError::ReadOnly(name.to_owned()));
        }
        self.reachable(remote).map_err(|why| WriteError::Device {
            device: match &remote.device {
                Some(d) => format!("{}/{d}", remote.node),
                None => remote.node.clone(),
            },
            reason: why.to_owned(),
        })?;
        let value = value
            .coerce(meta.kind)
            .ok_or_else(|| WriteError::BadValue {
                tag: name.to_owned(),
                value: value.to_string(),
                reason: format!("the tag is {:?}", meta.kind),
            })?;
        let wire = datatype::encode(&value, remote.datatype);
        let expected = datatype::decode(Some(&wire), remote.datatype.code()).map_err(|e| {
            WriteError::BadValue {
                tag: name.to_owned(),
                value: value.to_string(),
                reason: e.to_string(),
            }
        })?;
        let ms = u64::try_from(now.as_millis()).unwrap_or(0);
        let payload = Payload {
            timestamp: Some(ms),
            metrics: vec![Metric {
                name: Some(remote.metric.clone()),
                alias: remote.alias,
                timestamp: Some(ms),
                datatype: Some(remote.datatype.code()),
                value: Some(wire),
                ..Default::default()
            }],
            ..Default::default()
        };
        let topic = match &remote.device {
            Some(d) => Topic::device(&self.policy.group, MessageType::DCmd, &remote.node, d),
            None => Topic::node(&self.policy.group, MessageType::NCmd, &remote.node),
        };
        Ok((id, topic, payload, expected))
    }

    /// The NCMD that asks `node` for a rebirth.
    pub fn rebirth_command(&self, node: &str, now: Timestamp) -> (Topic, Payload) {
        let ms = u64::try_from(now.as_millis()).unwrap_or(0);
        (
            Topic::node(&self.policy.group, MessageType::NCmd, node),
            Payload {
                timestamp: Some(ms),
                metrics: vec![Metric {
                    name: Some(REBIRTH.to_owned()),
                    timestamp: Some(ms),
                    datatype: Some(DataType::Boolean.code()),
                    value: Some(MetricValue::Boolean(true)),
                    ..Default::default()
                }],
                ..Default::default()
            },
        )
    }
}

/// Node and device control metrics, and the session number: no tags.
fn is_control(name: &str) -> bool {
    name == BD_SEQ || name.starts_with("Node Control/") || name.starts_with("Device Control/")
}

/// The tag kind a metric of this data type becomes; `None` for types
/// gridscada does not hold (bytes, files, templates).
fn kind_of(t: DataType) -> Option<ValueKind> {
    use DataType::*;
    Some(match t {
        Boolean => ValueKind::Bool,
        Int8 | Int16 | Int32 | Int64 | UInt8 | UInt16 | UInt32 | UInt64 | DateTime => {
            ValueKind::Int
        }
        Float | Double => ValueKind::Float,
        String | Text | Uuid => ValueKind::Str,
        Bytes => return None,
    })
}

/// A metric as a sample: its own timestamp (else the message's, else now),
/// Bad when null or when the edge says its quality is not good.
fn sample_of(
    m: &Metric,
    datatype: DataType,
    kind: ValueKind,
    last: Option<Value>,
    sent: Option<u64>,
    now: Timestamp,
) -> Sample {
    let timestamp = m
        .timestamp
        .or(sent)
        .and_then(|t| i64::try_from(t).ok())
        .map_or(now, Timestamp::from_millis);
    // A Bad sample keeps the last value (or the kind's zero), as a
    // device going offline does.
    let bad = |reason: String| Sample {
        value: last.clone().unwrap_or(match kind {
            ValueKind::Bool => Value::Bool(false),
            ValueKind::Int => Value::Int(0),
            ValueKind::Float => Value::Float(0.0),
            ValueKind::Str => Value::Str("".into()),
        }),
        quality: Quality::bad(reason),
        timestamp,
    };
    if m.is_null == Some(true) {
        return bad("no value at the edge".into());
    }
    let value = match datatype::decode(m.value.as_ref(), datatype.code()) {
        Ok(v) => v,
        Err(e) => return bad(format!("unreadable at the edge: {e}")),
    };
    let Some(value) = value.coerce(kind) else {
        return bad(format!("the edge sent {value}, not a {kind:?}"));
    };
    // Ignition's convention: an Int32 "Quality" property, 192 is good.
    let quality = match int_prop(m.properties.as_ref(), "Quality")
        .or(int_prop(m.properties.as_ref(), "quality"))
    {
        Some(q) if q != 192 => Quality::bad(format!("quality {q} at the edge")),
        _ => Quality::GOOD,
    };
    Sample {
        value,
        quality,
        timestamp,
    }
}

fn bad_samples(
    db: &TagDb,
    ids: &[TagId],
    quality: &Quality,
    now: Timestamp,
) -> Vec<(TagId, Sample)> {
    ids.iter()
        .filter_map(|id| {
            let last = db.get(*id)?;
            Some((
                *id,
                Sample {
                    value: last.value,
                    quality: quality.clone(),
                    timestamp: now,
                },
            ))
        })
        .collect()
}

fn prop<'p>(props: Option<&'p PropertySet>, key: &str) -> Option<&'p PropertyValueKind> {
    props?.get(key)?.value.as_ref()
}

fn string_prop(props: Option<&PropertySet>, keys: &[&str]) -> Option<String> {
    keys.iter().find_map(|k| match prop(props, k) {
        Some(PropertyValueKind::String(s)) => Some(s.clone()),
        _ => None,
    })
}

fn bool_prop(props: Option<&PropertySet>, key: &str) -> Option<bool> {
    match prop(props, key) {
        Some(PropertyValueKind::Boolean(b)) => Some(*b),
        _ => None,
    }
}

fn int_prop(props: Option<&PropertySet>, key: &str) -> Option<i64> {
    match prop(props, key) {
        Some(PropertyValueKind::Int(i)) => Some(i64::from(*i as i32)),
        Some(PropertyValueKind::Long(l)) => Some(*l as i64),
        _ => None,
    }
}
