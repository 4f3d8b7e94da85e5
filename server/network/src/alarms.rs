//! The network's system alarms: what the live topology says is wrong with
//! the network as it stands, however it came to be so (a command that went
//! out before a rule existed, a device operated locally at the switchgear,
//! an override). The guard refuses the operations that would cause these;
//! these alarms tell the control room when the network is in such a state
//! anyway. Pure: from the model, the inputs and the topology.

use crate::model::{Model, ParallelPermission, SwitchKind};
use crate::rules::sources_in_words;
use crate::topology::{groups_of, Inputs, Pos, SectionState, Topology};

/// An earth switch closed on an energised section: an earth fault made by
/// switching, the most dangerous state a network can be in.
pub const EARTHED_LIVE_PRIORITY: u32 = 900;
/// Sources running in parallel that the model says must never be.
pub const FORBIDDEN_PARALLEL_PRIORITY: u32 = 850;
/// Sources running in parallel that only a supervisor's override allows:
/// the override was given, but the state is abnormal while it lasts.
pub const OVERRIDDEN_PARALLEL_PRIORITY: u32 = 700;

/// One standing network alarm.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct NetworkAlarm {
    /// Stable while the condition lasts: `network:earthed_live:<device>`,
    /// `network:parallel:<groups>`.
    pub key: String,
    pub priority: u32,
    pub message: String,
}

/// The alarms that stand for this topology, sorted by key. Only what is
/// certain: a state that depends on a device of unknown position is shown
/// as unknown on the screens, and the device's communication alarm says why.
pub fn standing(model: &Model, inputs: &Inputs, topology: &Topology) -> Vec<NetworkAlarm> {
    let mut out = Vec::new();
    for (i, w) in model.switches.iter().enumerate() {
        if w.kind != SwitchKind::EarthSwitch || inputs.switches.get(i) != Some(&Pos::Closed) {
            continue;
        }
        let section = w.a as usize;
        if topology.state.get(section) != Some(&SectionState::EnergisedEarthed) {
            continue;
        }
        let groups = groups_of(model, topology.sources_of(w.a));
        out.push(NetworkAlarm {
            key: format!("network:earthed_live:{}", w.id),
            priority: EARTHED_LIVE_PRIORITY,
            message: format!(
                "{} is closed on {}, which is energised from {}: an earth fault made by switching",
                w.name,
                model.sections[section].id,
                sources_in_words(model, &groups)
            ),
        });
    }
    for p in topology.parallels.iter().filter(|p| p.certain) {
        let (priority, why) = match p.permission {
            ParallelPermission::Allowed => continue,
            ParallelPermission::Forbidden => (
                FORBIDDEN_PARALLEL_PRIORITY,
                "which the network model says must never run in parallel",
            ),
            ParallelPermission::Overridable => (
                OVERRIDDEN_PARALLEL_PRIORITY,
                "which may run in parallel only under a supervisor's override",
            ),
        };
        let groups: Vec<&str> = p.groups.iter().map(|&g| model.groups[g].as_str()).collect();
        out.push(NetworkAlarm {
            key: format!("network:parallel:{}", groups.join("+")),
            priority,
            message: format!(
                "{} are running in parallel (through {}), {why}",
                sources_in_words(model, &p.groups),
                model.sections[p.section as usize].id
            ),
        });
    }
    out.sort_by(|a, b| a.key.cmp(&b.key));
    out.dedup_by(|a, b| a.key == b.key);
    out
}
