//! What the edge node publishes, as pure functions of the tag database: the
//! Sparkplug devices and their tags, aliases, births, data messages, the
//! deadband and the message sequence number.
//!
//! The devices: one Sparkplug device per configured Modbus device, carrying
//! exactly the tags of the tag files that name it; and one more,
//! [`DERIVED_DEVICE`], carrying every other tag of the database (device
//! status `DEVICE.Comm.*`, panel sequence and dispatch tags). Those belong to
//! the server, not to a field device: a device's status must stay readable
//! while the device itself is dead.

use gridscada_config::{MqttEdgeConfig, Plant, Role, DERIVED_DEVICE};
use gridscada_tagdb::{QualityCode, Sample, TagDb, TagId, Value, ValueKind};

use crate::datatype::{encode, DataType};
use crate::proto::{Metric, MetricValue, Payload, PropertySet, PropertyValue, PropertyValueKind};

/// The node metric that asks for a rebirth (NCMD) and is declared in NBIRTH.
pub const REBIRTH: &str = "Node Control/Rebirth";
/// The birth/death sequence metric of NBIRTH and NDEATH.
pub const BD_SEQ: &str = "bdSeq";

/// Property keys of a metric (Ignition's names, which most hosts read).
pub const PROP_QUALITY: &str = "Quality";
pub const PROP_QUALITY_REASON: &str = "QualityReason";
pub const PROP_UNITS: &str = "engUnit";
pub const PROP_WRITABLE: &str = "Writable";
/// gridscada's own property: the tag's `[tag.alarm]` as TOML text, so that
/// a central gridscada raises the same alarms on the remote tag. Other
/// hosts ignore it.
pub const PROP_ALARMS: &str = "gridscadaAlarms";

/// OPC-style quality codes as Sparkplug hosts read them.
pub const QUALITY_GOOD: i32 = 192;
pub const QUALITY_UNCERTAIN: i32 = 64;
pub const QUALITY_BAD: i32 = 0;

/// Property value type code of Int32 and Boolean and String (same codes as
/// metric data types).
const PT_INT32: u32 = 3;
const PT_BOOLEAN: u32 = 11;
const PT_STRING: u32 = 12;

/// One Sparkplug device of this node.
#[derive(Debug, Clone)]
pub struct Device {
    pub name: String,
    pub tags: Vec<TagId>,
    /// The tag whose value says the device communicates
    /// (`DEVICE.Comm.Connected`); `None` for the derived device, always up.
    pub comm: Option<TagId>,
}

/// Whether a DCMD may write a tag, or which of the node's rights it lacks.
/// A DCMD carries the rights of the node as configured: its area is
/// `[mqtt.edge] commands` (the write grant of the node, as
/// `[server.access.GROUP] write` is a group's), its role `command_role`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CommandRight {
    Allowed,
    ReadOnly,
    /// `[mqtt.edge] commands` does not name it.
    OutsideArea,
    /// Its write role, above the node's `command_role`.
    AboveRole(Role),
}

/// The node's devices, and per tag its device and whether a DCMD may write it.
#[derive(Debug, Clone)]
pub struct EdgeModel {
    pub devices: Vec<Device>,
    /// Per tag id: index into `devices`.
    device_of: Vec<usize>,
    /// Per tag id: whether a DCMD may write it (writable, in the node's
    /// area `commands`, its write role within `command_role`), or why not.
    commandable: Vec<CommandRight>,
    /// The role DCMDs act with (`[mqtt.edge] command_role`).
    pub command_role: Role,
    /// Per tag id: its data type on the wire.
    datatypes: Vec<DataType>,
    /// Per tag id: its alarm configuration as TOML ([`PROP_ALARMS`]).
    alarms: Vec<Option<String>>,
}

impl EdgeModel {
    pub fn new(plant: &Plant, db: &TagDb, edge: &MqttEdgeConfig) -> EdgeModel {
        let n = db.len();
        let mut devices: Vec<Device> = plant
            .devices
            .iter()
            .map(|d| Device {
                name: d.name.get_ref().clone(),
                tags: Vec::new(),
                comm: db.id(&format!("{}.Comm.Connected", d.name.get_ref())),
            })
            .collect();
        let derived = devices.len();
        devices.push(Device {
            name: DERIVED_DEVICE.to_string(),
            tags: Vec::new(),
            comm: None,
        });
        let mut device_of = vec![derived; n];
        // Tags of no tag file (derived ones) are in no `commands`.
        let mut commandable = vec![CommandRight::ReadOnly; n];
        for (id, meta) in db.all_meta() {
            if meta.writable {
                commandable[id.index()] = CommandRight::OutsideArea;
            }
        }
        let mut alarms = vec![None; n];
        let role: Role = *edge.command_role.get_ref();
        for t in &plant.tags {
            let Some(id) = db.id(t.name.get_ref()) else {
                continue;
            };
            if let Some(d) = plant
                .devices
                .iter()
                .position(|d| d.name.get_ref() == t.device.get_ref())
            {
                device_of[id.index()] = d;
            }
            let required = t
                .write_role
                .as_ref()
                .map(|r| *r.get_ref())
                .unwrap_or(Role::Operator);
            commandable[id.index()] = if !*t.writable.get_ref() {
                CommandRight::ReadOnly
            } else if !edge.allows_command(t.name.get_ref()) {
                CommandRight::OutsideArea
            } else if required > role {
                CommandRight::AboveRole(required)
            } else {
                CommandRight::Allowed
            };
            alarms[id.index()] = t.alarm.as_ref().and_then(|a| match toml::to_string(a) {
                Ok(text) => Some(text),
                Err(e) => {
                    tracing::warn!(tag = %t.name.get_ref(), error = %e, "alarm configuration not published");
                    None
                }
            });
        }
        let mut datatypes = Vec::with_capacity(n);
        for (id, meta) in db.all_meta() {
            devices[device_of[id.index()]].tags.push(id);
            datatypes.push(DataType::for_kind(meta.kind));
        }
        EdgeModel {
            devices,
            device_of,
            commandable,
            command_role: role,
            datatypes,
            alarms,
        }
    }

    /// The device (index into `devices`) a tag belongs to.
    pub fn device_of(&self, id: TagId) -> Option<usize> {
        self.device_of.get(id.index()).copied()
    }

    pub fn device_named(&self, name: &str) -> Option<usize> {
        self.devices.iter().position(|d| d.name == name)
    }

    pub fn commandable(&self, id: TagId) -> bool {
        self.command_right(id) == CommandRight::Allowed
    }

    pub fn command_right(&self, id: TagId) -> CommandRight {
        self.commandable
            .get(id.index())
            .copied()
            .unwrap_or(CommandRight::ReadOnly)
    }

    pub fn datatype(&self, id: TagId) -> DataType {
        self.datatypes
            .get(id.index())
            .copied()
            .unwrap_or(DataType::Double)
    }

    /// Whether a device communicates now: its `Comm.Connected` is Good and
    /// true (the derived device always is).
    pub fn device_up(&self, device: usize, db: &TagDb) -> bool {
        match self.devices.get(device).map(|d| d.comm) {
            Some(None) => true,
            Some(Some(comm)) => db
                .get(comm)
                .is_some_and(|s| s.quality.is_good() && s.value.as_bool() == Some(true)),
            None => false,
        }
    }
}

/// The alias of a tag: its id in the database, stable for one configuration
/// and unique in the node, as Sparkplug requires.
pub fn alias(id: TagId) -> u64 {
    u64::from(id.0)
}

/// The tag an alias names, if the database has it.
pub fn tag_of_alias(alias: u64, db: &TagDb) -> Option<TagId> {
    let id = TagId(u32::try_from(alias).ok()?);
    db.meta(id).map(|_| id)
}

/// The message sequence number: 0 at NBIRTH, then one more per message,
/// wrapping after 255.
#[derive(Debug, Default, Clone, Copy)]
pub struct Seq(u8);

impl Seq {
    /// Starts over (an NBIRTH): returns 0.
    pub fn reset(&mut self) -> u64 {
        self.0 = 0;
        0
    }
    /// The next message's number.
    pub fn advance(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(1);
        u64::from(self.0)
    }
}

fn quality_code(s: &Sample) -> i32 {
    match s.quality.code {
        QualityCode::Good => QUALITY_GOOD,
        QualityCode::Uncertain => QUALITY_UNCERTAIN,
        QualityCode::Bad => QUALITY_BAD,
    }
}

fn int_prop(v: i32) -> PropertyValue {
    PropertyValue {
        r#type: Some(PT_INT32),
        value: Some(PropertyValueKind::Int(v as u32)),
        ..Default::default()
    }
}

fn str_prop(v: &str) -> PropertyValue {
    PropertyValue {
        r#type: Some(PT_STRING),
        value: Some(PropertyValueKind::String(v.to_string())),
        ..Default::default()
    }
}

fn bool_prop(v: bool) -> PropertyValue {
    PropertyValue {
        r#type: Some(PT_BOOLEAN),
        value: Some(PropertyValueKind::Boolean(v)),
        ..Default::default()
    }
}

/// The quality of a sample as metric properties.
fn quality_props(s: &Sample, props: &mut PropertySet) {
    props.push(PROP_QUALITY, int_prop(quality_code(s)));
    if let Some(reason) = &s.quality.reason {
        props.push(PROP_QUALITY_REASON, str_prop(reason));
    }
}

/// One sample as a data metric: alias, own timestamp, value and quality.
/// The name is left out (the birth declared it), unless `with_name` (a
/// buffered sample, which must survive a restart with another alias map).
pub fn data_metric(id: TagId, name: Option<&str>, sample: &Sample, datatype: DataType) -> Metric {
    let mut props = PropertySet::default();
    quality_props(sample, &mut props);
    Metric {
        name: name.map(str::to_string),
        alias: Some(alias(id)),
        timestamp: Some(sample.timestamp.as_millis().max(0) as u64),
        datatype: Some(datatype.code()),
        properties: Some(props),
        value: Some(encode(&sample.value, datatype)),
        ..Default::default()
    }
}

/// NBIRTH: the node's `bdSeq` and its rebirth control.
pub fn nbirth(bd_seq: u64, now_ms: u64) -> Payload {
    Payload {
        timestamp: Some(now_ms),
        seq: Some(0),
        metrics: vec![
            Metric {
                name: Some(BD_SEQ.into()),
                timestamp: Some(now_ms),
                datatype: Some(DataType::Int64.code()),
                value: Some(MetricValue::Long(bd_seq)),
                ..Default::default()
            },
            Metric {
                name: Some(REBIRTH.into()),
                timestamp: Some(now_ms),
                datatype: Some(DataType::Boolean.code()),
                value: Some(MetricValue::Boolean(false)),
                ..Default::default()
            },
        ],
        ..Default::default()
    }
}

/// NDEATH, the MQTT will of a session: its `bdSeq` only.
pub fn ndeath(bd_seq: u64) -> Payload {
    Payload {
        timestamp: None,
        metrics: vec![Metric {
            name: Some(BD_SEQ.into()),
            datatype: Some(DataType::Int64.code()),
            value: Some(MetricValue::Long(bd_seq)),
            ..Default::default()
        }],
        ..Default::default()
    }
}

/// A DBIRTH and the samples it carries: the deadband must start from
/// exactly these, not from a second read of the database.
pub struct Birth {
    pub payload: Payload,
    pub carried: Vec<(TagId, Sample)>,
}

/// DBIRTH: every tag of the device with name, alias, data type, current
/// value, its timestamp, and properties (units, quality, writable by DCMD).
///
/// The samples are read once, in one snapshot of the database. A change
/// applied after that snapshot reaches the edge through its subscription
/// and is measured against what the birth carried; a second read (to start
/// the deadband) could see that change already and hold it back, leaving
/// the host with the birth's older value for good (it was a status tag
/// that turned Good while its device's birth was being built).
pub fn dbirth(model: &EdgeModel, device: usize, db: &TagDb, seq: u64, now_ms: u64) -> Birth {
    let tags = model
        .devices
        .get(device)
        .map(|d| d.tags.as_slice())
        .unwrap_or_default();
    let carried = db.snapshot(tags).changes;
    let metrics = carried
        .iter()
        .filter_map(|(id, sample)| {
            let meta = db.meta(*id)?;
            let datatype = model.datatype(*id);
            let mut m = data_metric(*id, Some(&meta.name), sample, datatype);
            let props = m.properties.get_or_insert_with(Default::default);
            if !meta.units.is_empty() {
                props.push(PROP_UNITS, str_prop(&meta.units));
            }
            props.push(PROP_WRITABLE, bool_prop(model.commandable(*id)));
            if let Some(Some(alarms)) = model.alarms.get(id.index()) {
                props.push(PROP_ALARMS, str_prop(alarms));
            }
            if sample.is_never_read() {
                m.timestamp = Some(now_ms);
            }
            Some(m)
        })
        .collect();
    Birth {
        payload: Payload {
            timestamp: Some(now_ms),
            seq: Some(seq),
            metrics,
            ..Default::default()
        },
        carried,
    }
}

/// DDEATH: the device stopped communicating.
pub fn ddeath(seq: u64, now_ms: u64) -> Payload {
    Payload {
        timestamp: Some(now_ms),
        seq: Some(seq),
        ..Default::default()
    }
}

/// The deadband: which changes are worth publishing. A change of quality
/// always is; a numeric value must move at least `deadband` from the last
/// value published; any other value must differ. A new timestamp alone is
/// not a change.
#[derive(Debug)]
pub struct Deadband {
    deadband: f64,
    last: Vec<Option<Sample>>,
}

impl Deadband {
    pub fn new(tags: usize, deadband: f64) -> Deadband {
        Deadband {
            deadband,
            last: vec![None; tags],
        }
    }

    /// Takes `sample` as published if it passes; returns whether it does.
    pub fn offer(&mut self, id: TagId, sample: &Sample) -> bool {
        let Some(slot) = self.last.get_mut(id.index()) else {
            return false;
        };
        let passes = match slot {
            None => true,
            Some(last) if last.quality != sample.quality => true,
            Some(last) => match (&last.value, &sample.value) {
                (Value::Float(_) | Value::Int(_), Value::Float(_) | Value::Int(_))
                    if self.deadband > 0.0 =>
                {
                    let (a, b) = (last.value.as_f64(), sample.value.as_f64());
                    match (a, b) {
                        (Some(a), Some(b)) if a.is_finite() && b.is_finite() => {
                            (a - b).abs() >= self.deadband
                        }
                        _ => sample.differs_from(last),
                    }
                }
                _ => sample.differs_from(last),
            },
        };
        if passes {
            *slot = Some(sample.clone());
        }
        passes
    }

    /// Takes the current sample as published without asking (a birth
    /// carries it).
    pub fn reset_to(&mut self, id: TagId, sample: &Sample) {
        if let Some(slot) = self.last.get_mut(id.index()) {
            *slot = Some(sample.clone());
        }
    }
}

/// A DCMD metric that may not be written: the name it was given by (for the
/// log and the audit record), and why.
#[derive(Debug, Clone, PartialEq)]
pub struct Refusal {
    pub tag: String,
    pub why: String,
}

/// Resolves one metric of a DCMD to device `device`: the tag (by alias, or
/// by name) and the value to write, or why it is refused.
pub fn resolve_command(
    model: &EdgeModel,
    db: &TagDb,
    device: usize,
    metric: &Metric,
) -> Result<(TagId, Value), Refusal> {
    let label = metric.name.clone().unwrap_or_else(|| match metric.alias {
        Some(a) => format!("alias {a}"),
        None => "a metric without name or alias".into(),
    });
    let refuse = |tag: &str, why: &str| Refusal {
        tag: tag.to_string(),
        why: why.to_string(),
    };
    let by_alias = metric.alias.and_then(|a| tag_of_alias(a, db));
    let by_name = metric.name.as_deref().and_then(|n| db.id(n));
    let id = match (by_alias, by_name) {
        (Some(a), Some(n)) if a != n => {
            return Err(refuse(&label, "its alias and its name are different tags"))
        }
        (Some(id), _) if metric.name.is_none() || by_name.is_some() => id,
        (None, Some(id)) if metric.alias.is_none() => id,
        _ => return Err(refuse(&label, "no such metric on this node")),
    };
    let meta = db
        .meta(id)
        .ok_or_else(|| refuse(&label, "no such metric on this node"))?;
    let name = meta.name.to_string();
    if model.device_of(id) != Some(device) {
        let owner = model
            .device_of(id)
            .and_then(|d| model.devices.get(d))
            .map(|d| d.name.as_str())
            .unwrap_or_default();
        return Err(refuse(
            &name,
            &format!("it is a metric of device '{owner}', not of the device addressed"),
        ));
    }
    match model.command_right(id) {
        CommandRight::Allowed => {}
        CommandRight::ReadOnly => return Err(refuse(&name, "it is read-only")),
        CommandRight::OutsideArea => {
            return Err(refuse(
                &name,
                "it is outside the node's area: [mqtt.edge] commands does not name it",
            ))
        }
        CommandRight::AboveRole(required) => {
            return Err(refuse(
                &name,
                &format!(
                    "writing it needs the {} role or above; the node commands as {} ([mqtt.edge] command_role)",
                    required.label(),
                    model.command_role.label()
                ),
            ))
        }
    }
    let value =
        command_value(metric, model.datatype(id), meta.kind).map_err(|why| refuse(&name, &why))?;
    Ok((id, value))
}

/// The value a DCMD metric carries, as a value of the tag's kind: read with
/// the metric's own data type if it has one, else the tag's.
pub fn command_value(
    metric: &Metric,
    tag_type: DataType,
    kind: ValueKind,
) -> Result<Value, String> {
    let datatype = metric.datatype.unwrap_or(tag_type.code());
    let value =
        crate::datatype::decode(metric.value.as_ref(), datatype).map_err(|e| e.to_string())?;
    value
        .coerce(kind)
        .ok_or_else(|| format!("{value} is not a valid {kind:?} value"))
}

#[cfg(test)]
mod tests {
    use std::path::Path;
    use std::sync::Arc;

    use gridscada_tagdb::{Quality, Timestamp};

    use super::*;

    const MAIN: &str = r#"
tag_files = ["tags.toml"]
[mqtt]
broker = "mqtt://127.0.0.1:1883"
group = "G"
[mqtt.edge]
node = "n1"
deadband = 0.5
commands = ["RTU1.Setpoint", "RTU1.Run", "RTU1.Limit"]
command_role = "operator"
"#;
    const TAGS: &str = r#"
[[device]]
name = "RTU1"
protocol = "tcp"
address = "127.0.0.1:1502"

[[tag]]
name = "RTU1.Volts"
device = "RTU1"
kind = "input_register"
address = 0
type = "f32"
units = "V"
[tag.alarm]
hi = { limit = 250.0, priority = 700 }

[[tag]]
name = "RTU1.Setpoint"
device = "RTU1"
kind = "holding_register"
address = 10
type = "f32"
writable = true
write_role = "operator"

[[tag]]
name = "RTU1.Run"
device = "RTU1"
kind = "coil"
address = 0
writable = true
write_role = "operator"

[[tag]]
name = "RTU1.Limit"
device = "RTU1"
kind = "holding_register"
address = 20
type = "f32"
writable = true
write_role = "supervisor"

[[tag]]
name = "RTU1.Trip"
device = "RTU1"
kind = "coil"
address = 1
writable = true
write_role = "operator"
"#;

    fn plant() -> (Plant, Arc<TagDb>) {
        let plant = gridscada_config::load_with(Path::new("/p/gridscada.toml"), &|p: &Path| {
            Ok(if p.ends_with("tags.toml") { TAGS } else { MAIN }.to_string())
        })
        .unwrap_or_else(|d| panic!("{d:?}"));
        let mut metas: Vec<_> = plant.tag_metas().collect();
        // A device status tag, as the poller adds it (a derived tag).
        metas.push(gridscada_tagdb::TagMeta::new(
            "RTU1.Comm.Connected",
            gridscada_tagdb::ValueKind::Bool,
        ));
        let db = Arc::new(TagDb::new(metas).unwrap());
        (plant, db)
    }

    fn model() -> (EdgeModel, Arc<TagDb>) {
        let (plant, db) = plant();
        let edge = plant.mqtt.as_ref().unwrap().edge.as_ref().unwrap();
        (EdgeModel::new(&plant, &db, edge), db)
    }

    #[test]
    fn devices_carry_their_tags_and_derived_tags_go_to_the_server_device() {
        let (m, db) = model();
        let names = |d: usize| -> Vec<String> {
            m.devices[d]
                .tags
                .iter()
                .map(|id| db.meta(*id).unwrap().name.to_string())
                .collect()
        };
        assert_eq!(m.devices.len(), 2);
        assert_eq!(m.devices[0].name, "RTU1");
        assert_eq!(
            names(0),
            [
                "RTU1.Volts",
                "RTU1.Setpoint",
                "RTU1.Run",
                "RTU1.Limit",
                "RTU1.Trip"
            ]
        );
        assert_eq!(m.devices[1].name, DERIVED_DEVICE);
        assert_eq!(names(1), ["RTU1.Comm.Connected"]);
        assert_eq!(m.devices[0].comm, db.id("RTU1.Comm.Connected"));
        // Down until its status says it communicates; the server's device always up.
        assert!(!m.device_up(0, &db));
        assert!(m.device_up(1, &db));
        db.set(
            db.id("RTU1.Comm.Connected").unwrap(),
            true,
            Quality::GOOD,
            Timestamp::from_millis(5),
        );
        assert!(m.device_up(0, &db));
    }

    #[test]
    fn a_dbirth_declares_every_tag_with_alias_type_and_properties() {
        let (m, db) = model();
        let volts = db.id("RTU1.Volts").unwrap();
        db.set(volts, 231.5, Quality::GOOD, Timestamp::from_millis(1_000));
        let p = dbirth(&m, 0, &db, 1, 9_000).payload;
        assert_eq!(p.seq, Some(1));
        assert_eq!(p.metrics.len(), 5);
        let v = &p.metrics[0];
        assert_eq!(v.name.as_deref(), Some("RTU1.Volts"));
        assert_eq!(v.alias, Some(alias(volts)));
        assert_eq!(v.datatype, Some(DataType::Double.code()));
        assert_eq!(v.value, Some(MetricValue::Double(231.5)));
        assert_eq!(v.timestamp, Some(1_000), "the sample's own timestamp");
        let props = v.properties.as_ref().unwrap();
        assert_eq!(
            props.get(PROP_QUALITY).unwrap().value,
            Some(PropertyValueKind::Int(192))
        );
        assert_eq!(
            props.get(PROP_UNITS).unwrap().value,
            Some(PropertyValueKind::String("V".into()))
        );
        assert_eq!(
            props.get(PROP_WRITABLE).unwrap().value,
            Some(PropertyValueKind::Boolean(false))
        );
        // Its alarms, as the TOML a central gridscada reads back.
        let Some(PropertyValueKind::String(alarms)) = &props.get(PROP_ALARMS).unwrap().value else {
            panic!("no alarm property");
        };
        let back: gridscada_config::AlarmConfig = toml::from_str(alarms).unwrap();
        let hi = back.hi.unwrap();
        assert_eq!((*hi.limit.get_ref(), hi.priority), (250.0, 700));
        assert!(
            p.metrics[1]
                .properties
                .as_ref()
                .unwrap()
                .get(PROP_ALARMS)
                .is_none(),
            "a tag without alarms has no alarm property"
        );
        // A tag never read: Bad with its reason, stamped with the birth time.
        let run = &p.metrics[2];
        let props = run.properties.as_ref().unwrap();
        assert_eq!(
            props.get(PROP_QUALITY).unwrap().value,
            Some(PropertyValueKind::Int(0))
        );
        assert_eq!(
            props.get(PROP_QUALITY_REASON).unwrap().value,
            Some(PropertyValueKind::String("no value yet".into()))
        );
        assert_eq!(run.timestamp, Some(9_000));
        assert_eq!(
            props.get(PROP_WRITABLE).unwrap().value,
            Some(PropertyValueKind::Boolean(true))
        );
        // Aliases are unique and map back to their tags.
        let mut aliases: Vec<u64> = p.metrics.iter().map(|m| m.alias.unwrap()).collect();
        for a in &aliases {
            assert!(tag_of_alias(*a, &db).is_some());
        }
        aliases.dedup();
        assert_eq!(aliases.len(), 5);
        assert_eq!(tag_of_alias(999, &db), None);
        assert_eq!(tag_of_alias(u64::MAX, &db), None);
    }

    /// The bug behind status tags stuck Bad at the centre: a status tag
    /// turned Good between the birth's read and a second read that started
    /// the deadband, so its change, arriving later, was held back as "no
    /// change" and the host kept the birth's Bad for good.
    #[test]
    fn a_change_just_after_the_birth_snapshot_is_published() {
        let (m, db) = model();
        let connected = db.id("RTU1.Comm.Connected").unwrap();
        let mut deadband = Deadband::new(db.len(), 0.0);
        let birth = dbirth(&m, 1, &db, 1, 9_000);
        // The poller's first scan lands while the birth is on its way.
        db.set(
            connected,
            true,
            Quality::GOOD,
            Timestamp::from_millis(9_001),
        );
        for (id, sample) in &birth.carried {
            deadband.reset_to(*id, sample);
        }
        let carried = &birth
            .carried
            .iter()
            .find(|(id, _)| *id == connected)
            .unwrap()
            .1;
        assert!(
            carried.is_never_read(),
            "the birth carried the tag as never read"
        );
        let metric = &birth.payload.metrics[0];
        assert_eq!(metric.alias, Some(alias(connected)));
        assert_eq!(
            metric
                .properties
                .as_ref()
                .unwrap()
                .get(PROP_QUALITY)
                .unwrap()
                .value,
            Some(PropertyValueKind::Int(0)),
            "the payload says what the carried samples say"
        );
        let now = db.get(connected).unwrap();
        assert!(
            deadband.offer(connected, &now),
            "the change after the birth's snapshot goes out as data"
        );
    }

    #[test]
    fn nbirth_and_ndeath_carry_the_bd_seq() {
        let b = nbirth(7, 100);
        assert_eq!(b.seq, Some(0));
        assert_eq!(b.metrics[0].name.as_deref(), Some(BD_SEQ));
        assert_eq!(b.metrics[0].value, Some(MetricValue::Long(7)));
        assert_eq!(b.metrics[1].name.as_deref(), Some(REBIRTH));
        let d = ndeath(7);
        assert_eq!(d.seq, None);
        assert_eq!(d.metrics[0].value, Some(MetricValue::Long(7)));
    }

    #[test]
    fn seq_wraps_after_255() {
        let mut s = Seq::default();
        assert_eq!(s.reset(), 0);
        let got: Vec<u64> = (0..257).map(|_| s.advance()).collect();
        assert_eq!(got[0], 1);
        assert_eq!(got[254], 255);
        assert_eq!(got[255], 0);
        assert_eq!(got[256], 1);
        assert_eq!(s.reset(), 0);
        assert_eq!(s.advance(), 1);
    }

    #[test]
    fn the_deadband_holds_small_moves_but_never_a_quality_change() {
        let mut d = Deadband::new(2, 0.5);
        let t = TagId(0);
        let at = |v: f64, ms: i64| Sample::good(v, Timestamp::from_millis(ms));
        assert!(d.offer(t, &at(10.0, 1)), "the first sample");
        assert!(!d.offer(t, &at(10.3, 2)), "within the deadband");
        assert!(!d.offer(t, &at(10.0, 3)), "a new timestamp alone");
        assert!(d.offer(t, &at(10.5, 4)), "a move of the deadband");
        assert!(
            !d.offer(t, &at(10.8, 5)),
            "measured from the last published"
        );
        let mut bad = at(10.8, 6);
        bad.quality = Quality::bad("device offline");
        assert!(d.offer(t, &bad), "quality changes always go");
        // Non-numeric values: any change.
        let s = TagId(1);
        assert!(d.offer(s, &Sample::good("A", Timestamp::from_millis(1))));
        assert!(!d.offer(s, &Sample::good("A", Timestamp::from_millis(2))));
        assert!(d.offer(s, &Sample::good("B", Timestamp::from_millis(3))));
        assert!(!d.offer(TagId(9), &at(1.0, 1)), "an unknown tag");
    }

    #[test]
    fn data_metrics_go_by_alias_with_their_own_timestamp_and_quality() {
        let mut s = Sample::good(3.5, Timestamp::from_millis(42));
        s.quality = Quality::uncertain("stale");
        let m = data_metric(TagId(3), None, &s, DataType::Double);
        assert_eq!(m.name, None);
        assert_eq!(m.alias, Some(3));
        assert_eq!(m.timestamp, Some(42));
        let props = m.properties.unwrap();
        assert_eq!(
            props.get(PROP_QUALITY).unwrap().value,
            Some(PropertyValueKind::Int(64))
        );
        assert_eq!(
            props.get(PROP_QUALITY_REASON).unwrap().value,
            Some(PropertyValueKind::String("stale".into()))
        );
    }

    fn cmd(alias: Option<u64>, name: Option<&str>, datatype: u32, value: MetricValue) -> Metric {
        Metric {
            alias,
            name: name.map(str::to_string),
            datatype: Some(datatype),
            value: Some(value),
            ..Default::default()
        }
    }

    #[test]
    fn commands_resolve_only_to_allowed_writable_tags_of_the_device() {
        let (m, db) = model();
        let sp = db.id("RTU1.Setpoint").unwrap();
        let run = db.id("RTU1.Run").unwrap();
        // By alias, by name, a value of another numeric type.
        assert_eq!(
            resolve_command(
                &m,
                &db,
                0,
                &cmd(Some(alias(sp)), None, 10, MetricValue::Double(12.5))
            ),
            Ok((sp, Value::Float(12.5)))
        );
        assert_eq!(
            resolve_command(
                &m,
                &db,
                0,
                &cmd(None, Some("RTU1.Run"), 11, MetricValue::Boolean(true))
            ),
            Ok((run, Value::Bool(true)))
        );
        assert_eq!(
            resolve_command(
                &m,
                &db,
                0,
                &cmd(Some(alias(sp)), None, 3, MetricValue::Int(7))
            ),
            Ok((sp, Value::Float(7.0)))
        );
        let why =
            |metric: Metric, device: usize| resolve_command(&m, &db, device, &metric).unwrap_err();
        let r = why(
            cmd(
                Some(alias(db.id("RTU1.Volts").unwrap())),
                None,
                10,
                MetricValue::Double(1.0),
            ),
            0,
        );
        assert_eq!(r.tag, "RTU1.Volts");
        assert_eq!(r.why, "it is read-only");
        let r = why(
            cmd(None, Some("RTU1.Trip"), 11, MetricValue::Boolean(true)),
            0,
        );
        // Each refusal says which of the node's rights it lacks: the area
        // (`commands`) or the role (`command_role`), not "one or the other".
        assert_eq!(
            r.why,
            "it is outside the node's area: [mqtt.edge] commands does not name it"
        );
        let r = why(
            cmd(None, Some("RTU1.Limit"), 10, MetricValue::Double(1.0)),
            0,
        );
        assert_eq!(
            r.why,
            "writing it needs the supervisor role or above; the node commands as operator ([mqtt.edge] command_role)",
            "a supervisor tag, operator node"
        );
        let r = why(cmd(Some(123_456), None, 11, MetricValue::Boolean(true)), 0);
        assert_eq!(
            (r.tag.as_str(), r.why.as_str()),
            ("alias 123456", "no such metric on this node")
        );
        let r = why(
            cmd(None, Some("No.Such"), 11, MetricValue::Boolean(true)),
            0,
        );
        assert_eq!(r.why, "no such metric on this node");
        let r = why(
            cmd(
                Some(alias(sp)),
                Some("RTU1.Run"),
                10,
                MetricValue::Double(1.0),
            ),
            0,
        );
        assert!(r.why.contains("different tags"), "{r:?}");
        let r = why(cmd(Some(alias(sp)), None, 10, MetricValue::Double(1.0)), 1);
        assert!(r.why.contains("metric of device 'RTU1'"), "{r:?}");
        let r = why(
            cmd(
                Some(alias(run)),
                None,
                12,
                MetricValue::String("yes".into()),
            ),
            0,
        );
        assert!(r.why.contains("not a valid Bool"), "{r:?}");
        let r = why(cmd(Some(alias(run)), None, 11, MetricValue::Double(1.0)), 0);
        assert!(r.why.contains("wire type"), "{r:?}");
        let mut no_value = cmd(Some(alias(run)), None, 11, MetricValue::Boolean(true));
        no_value.value = None;
        assert!(why(no_value, 0).why.contains("no value"));
    }
}
