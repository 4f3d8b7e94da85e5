//! The live shell of the topology processor: reads the devices' status and
//! the sources' in-service tags from the tag database, recomputes the
//! topology on every change, publishes each section's state as tags
//! (so alarms, the historian, screens and the northbound see them) and
//! hands the latest result to whoever checks a switching operation.

use std::collections::HashMap;
use std::sync::Arc;

use gridscada_tagdb::{Clock, Quality, Sample, TagDb, TagId, TagMeta, Timestamp, Value, ValueKind};
use tokio::sync::watch;

use crate::plant::{in_service, position, Network};
use crate::safety::SafetyTags;
use crate::topology::{compute, Inputs, Pos, SectionState, Topology, Unknown};

/// The name of a section's derived tag: `<prefix>.Sec.<section>.<signal>`,
/// `signal` one of `State`, `Energised`, `Sources`. The one place that
/// shapes it (the API and the drawn layout look names up through it).
pub fn section_tag(prefix: &str, section: &str, signal: &str) -> String {
    format!("{prefix}.Sec.{section}.{signal}")
}

/// The network's derived tags, under its prefix.
pub fn network_tags(net: &Network) -> Vec<TagMeta> {
    let p = &net.prefix;
    let mut tags = Vec::with_capacity(net.model.sections.len() * 3 + 4);
    for s in &net.model.sections {
        let id = &s.id;
        tags.push(
            TagMeta::new(section_tag(p, id, "State"), ValueKind::Str).describe(format!(
                "Section {id}: ENERGISED, DEAD, EARTHED, UNKNOWN or ENERGISED+EARTHED"
            )),
        );
        tags.push(
            TagMeta::new(section_tag(p, id, "Energised"), ValueKind::Bool).describe(format!(
                "Section {id}: energised (Uncertain quality when unknown)"
            )),
        );
        tags.push(
            TagMeta::new(section_tag(p, id, "Sources"), ValueKind::Str)
                .describe(format!("Section {id}: the sources feeding it")),
        );
    }
    for w in &net.model.switches {
        tags.push(
            TagMeta::new(format!("{p}.Sw.{}.Position", w.id), ValueKind::Str).describe(format!(
                "{}: OPEN, CLOSED or UNKNOWN (Uncertain quality when unknown), as the topology reads it",
                w.name
            )),
        );
        tags.push(
            TagMeta::new(format!("{p}.Sw.{}.Tag", w.id), ValueKind::Str).describe(format!(
                "{}: the strongest safety tag on it (DO NOT OPERATE, DO NOT CLOSE, INFORMATION), empty if none",
                w.name
            )),
        );
    }
    tags.push(
        TagMeta::new(format!("{p}.CustomersOff"), ValueKind::Int)
            .describe("Customers on dead or earthed sections"),
    );
    tags.push(
        TagMeta::new(format!("{p}.CustomersUnknown"), ValueKind::Int)
            .describe("Customers on sections of unknown state"),
    );
    tags.push(
        TagMeta::new(format!("{p}.Loops"), ValueKind::Int).describe("Loops in the closed network"),
    );
    tags.push(
        TagMeta::new(format!("{p}.Parallels"), ValueKind::Str)
            .describe("Sources running in parallel, and whether that is allowed"),
    );
    tags
}

/// The latest result: the inputs it was computed from and the topology.
#[derive(Debug, Clone)]
pub struct Live {
    /// Counts recomputes.
    pub version: u64,
    pub inputs: Inputs,
    pub topology: Arc<Topology>,
}

/// Why a section is unknown, in words.
pub fn unknown_reason(net: &Network, why: Option<Unknown>) -> String {
    match why {
        Some(Unknown::Switch(i)) => format!(
            "the position of {} is not known",
            net.model.switches[i].name
        ),
        Some(Unknown::Source(i)) => format!(
            "whether {} is in service is not known",
            net.model.sources[i].name
        ),
        None => "a device's position is not known".into(),
    }
}

/// The topology processor, bound to a tag database.
pub struct TopologyDriver {
    net: Arc<Network>,
    db: Arc<TagDb>,
    /// Input tag ids, by name.
    inputs: HashMap<String, TagId>,
    /// Derived tag ids: per section (state, energised, sources), then the
    /// four totals.
    sections: Vec<[Option<TagId>; 3]>,
    totals: [Option<TagId>; 4],
    /// Per device, its position's tag and its safety tag's tag.
    device_tags: Vec<[Option<TagId>; 2]>,
    safety: SafetyTags,
    /// What was last published, to publish only changes.
    last: HashMap<TagId, Sample>,
    version: u64,
}

impl TopologyDriver {
    pub fn new(net: Arc<Network>, db: Arc<TagDb>, safety: SafetyTags) -> TopologyDriver {
        let inputs = net
            .input_tags()
            .filter_map(|t| Some((t.to_string(), db.id(t)?)))
            .collect();
        let p = &net.prefix;
        let sections = net
            .model
            .sections
            .iter()
            .map(|s| {
                let id = &s.id;
                [
                    db.id(&section_tag(p, id, "State")),
                    db.id(&section_tag(p, id, "Energised")),
                    db.id(&section_tag(p, id, "Sources")),
                ]
            })
            .collect();
        let totals = ["CustomersOff", "CustomersUnknown", "Loops", "Parallels"]
            .map(|t| db.id(&format!("{p}.{t}")));
        let device_tags = net
            .model
            .switches
            .iter()
            .map(|w| {
                [
                    db.id(&format!("{p}.Sw.{}.Position", w.id)),
                    db.id(&format!("{p}.Sw.{}.Tag", w.id)),
                ]
            })
            .collect();
        TopologyDriver {
            device_tags,
            safety,
            net,
            db,
            inputs,
            sections,
            totals,
            last: HashMap::new(),
            version: 0,
        }
    }

    /// The inputs as the tag database holds them now.
    pub fn read_inputs(&self) -> Inputs {
        let samples: HashMap<&str, Sample> = self
            .inputs
            .iter()
            .filter_map(|(name, id)| Some((name.as_str(), self.db.get(*id)?)))
            .collect();
        let read = |t: &str| samples.get(t);
        let m = &self.net.model;
        Inputs {
            switches: m
                .switches
                .iter()
                .zip(&self.net.status)
                .map(|(s, b)| position(b.as_ref(), s.normally_closed, read))
                .collect(),
            sources: self
                .net
                .in_service
                .iter()
                .map(|b| in_service(b.as_ref(), read))
                .collect(),
        }
    }

    /// Recomputes from the tag database and publishes what changed.
    pub fn update(&mut self, now: Timestamp) -> Live {
        let inputs = self.read_inputs();
        let topology = compute(&self.net.model, &inputs);
        self.publish(&inputs, &topology, now);
        self.version += 1;
        Live {
            version: self.version,
            inputs,
            topology: Arc::new(topology),
        }
    }

    fn publish(&mut self, inputs: &Inputs, t: &Topology, now: Timestamp) {
        let m = &self.net.model;
        let mut batch = Vec::new();
        let mut put = |last: &mut HashMap<TagId, Sample>,
                       id: Option<TagId>,
                       value: Value,
                       quality: Quality| {
            let Some(id) = id else { return };
            let unchanged = last
                .get(&id)
                .is_some_and(|s| s.value == value && s.quality == quality);
            if !unchanged {
                let sample = Sample {
                    value,
                    quality,
                    timestamp: now,
                };
                last.insert(id, sample.clone());
                batch.push((id, sample));
            }
        };
        for (s, ids) in self.sections.iter().enumerate() {
            let state = t.state[s];
            let quality = if state == SectionState::Unknown {
                Quality::uncertain(unknown_reason(&self.net, t.unknown_because[s]))
            } else {
                Quality::GOOD
            };
            put(
                &mut self.last,
                ids[0],
                Value::Str(state.as_str().into()),
                Quality::GOOD,
            );
            put(
                &mut self.last,
                ids[1],
                Value::Bool(state.energised()),
                quality,
            );
            let sources: Vec<&str> = t
                .sources_of(s as u32)
                .iter()
                .map(|&i| m.sources[i].id.as_str())
                .collect();
            put(
                &mut self.last,
                ids[2],
                Value::Str(sources.join(",").into()),
                Quality::GOOD,
            );
        }
        let parallels: Vec<String> = t
            .parallels
            .iter()
            .map(|p| {
                let names: Vec<&str> = p
                    .sources
                    .iter()
                    .map(|&i| m.sources[i].id.as_str())
                    .collect();
                format!(
                    "{}{} ({})",
                    if p.certain { "" } else { "possibly " },
                    names.join(" + "),
                    match p.permission {
                        crate::model::ParallelPermission::Allowed => "allowed",
                        crate::model::ParallelPermission::Overridable => "by override only",
                        crate::model::ParallelPermission::Forbidden => "FORBIDDEN",
                    }
                )
            })
            .collect();
        for (i, w) in m.switches.iter().enumerate() {
            let pos = inputs.switches.get(i).copied().unwrap_or(Pos::Unknown);
            let quality = if pos == Pos::Unknown {
                Quality::uncertain(unknown_reason(&self.net, Some(Unknown::Switch(i))))
            } else {
                Quality::GOOD
            };
            put(
                &mut self.last,
                self.device_tags[i][0],
                Value::Str(pos.as_str().into()),
                quality,
            );
            let label = self.safety.strongest(&w.id).map_or("", |k| k.label());
            put(
                &mut self.last,
                self.device_tags[i][1],
                Value::Str(label.into()),
                Quality::GOOD,
            );
        }
        let totals = self.totals;
        put(
            &mut self.last,
            totals[0],
            Value::Int(t.customers_off as i64),
            Quality::GOOD,
        );
        put(
            &mut self.last,
            totals[1],
            Value::Int(t.customers_unknown as i64),
            Quality::GOOD,
        );
        put(
            &mut self.last,
            totals[2],
            Value::Int(t.loops() as i64),
            Quality::GOOD,
        );
        put(
            &mut self.last,
            totals[3],
            Value::Str(parallels.join("; ").into()),
            Quality::GOOD,
        );
        if !batch.is_empty() {
            self.db.apply(batch);
        }
    }

    /// Runs until the tag database goes away: one recompute per batch of
    /// input changes, each result sent on `tx`.
    pub async fn run(mut self, clock: Arc<dyn Clock>, tx: watch::Sender<Arc<Live>>) {
        let ids: Vec<TagId> = self.inputs.values().copied().collect();
        let mut sub = self.db.subscribe(&ids);
        let mut tags = self.safety.subscribe();
        tx.send_replace(Arc::new(self.update(clock.now())));
        loop {
            tokio::select! {
                update = sub.recv() => if update.is_none() { return },
                changed = tags.changed() => if changed.is_err() { return },
            }
            // Everything that is already waiting goes into this recompute.
            while sub.try_recv().is_some() {}
            tx.send_replace(Arc::new(self.update(clock.now())));
        }
    }
}
