//! Switching interlocks: the rules a switching operation is checked against
//! on the topology before and after it. Each refusal names its rule, says
//! why in words, and says whether a supervisor may override it.
//!
//! Safety tags and selections are checked where they are held (the
//! switching guard); their rule ids are here so every refusal speaks one
//! vocabulary.

use crate::model::{Model, ParallelPermission, SwitchKind};
use crate::preview::Preview;
use crate::topology::{Inputs, Pos, Topology};

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Operation {
    Open,
    Close,
}

impl Operation {
    pub fn as_str(self) -> &'static str {
        match self {
            Operation::Open => "open",
            Operation::Close => "close",
        }
    }
    pub fn target(self) -> Pos {
        match self {
            Operation::Open => Pos::Open,
            Operation::Close => Pos::Closed,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum RuleId {
    SafetyTag,
    Reserved,
    ClosingOntoEarthed,
    EarthingEnergised,
    DisconnectorUnderLoad,
    ForbiddenParallel,
    StateUnknown,
}

impl RuleId {
    pub fn as_str(self) -> &'static str {
        match self {
            RuleId::SafetyTag => "safety_tag",
            RuleId::Reserved => "reserved",
            RuleId::ClosingOntoEarthed => "closing_onto_earthed",
            RuleId::EarthingEnergised => "earthing_energised",
            RuleId::DisconnectorUnderLoad => "disconnector_under_load",
            RuleId::ForbiddenParallel => "forbidden_parallel",
            RuleId::StateUnknown => "state_unknown",
        }
    }
    pub fn parse(s: &str) -> Option<RuleId> {
        [
            RuleId::SafetyTag,
            RuleId::Reserved,
            RuleId::ClosingOntoEarthed,
            RuleId::EarthingEnergised,
            RuleId::DisconnectorUnderLoad,
            RuleId::ForbiddenParallel,
            RuleId::StateUnknown,
        ]
        .into_iter()
        .find(|r| r.as_str() == s)
    }
}

/// One rule that refuses an operation.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Interlock {
    pub rule: RuleId,
    pub text: String,
    /// A supervisor may override it, with a reason.
    pub overridable: bool,
}

fn section_name(model: &Model, s: u32) -> &str {
    &model.sections[s as usize].id
}

/// Source groups in words: "grid + microgrid".
pub(crate) fn sources_in_words(model: &Model, groups: &[usize]) -> String {
    groups
        .iter()
        .map(|&g| model.groups[g].as_str())
        .collect::<Vec<_>>()
        .join(" + ")
}

/// The interlocks that refuse `op` of `switch`, given the inputs and
/// topology before it and the topology after it (with the device at its
/// target). Empty: the operation is allowed.
pub fn interlocks(
    model: &Model,
    inputs: &Inputs,
    before: &Topology,
    after: &Topology,
    preview: &Preview,
    switch: usize,
    op: Operation,
) -> Vec<Interlock> {
    let w = &model.switches[switch];
    let mut out = Vec::new();
    let refuse = |out: &mut Vec<Interlock>, rule, text: String, overridable| {
        out.push(Interlock {
            rule,
            text,
            overridable,
        })
    };
    if inputs.switches.get(switch).copied().unwrap_or(Pos::Unknown) == Pos::Unknown {
        refuse(
            &mut out,
            RuleId::StateUnknown,
            format!("the position of {} is not known", w.name),
            false,
        );
        return out;
    }
    match (op, w.b) {
        (Operation::Close, None) => {
            // Earthing: the section must be proved dead.
            let s = w.a;
            let name = section_name(model, s);
            if before.state[s as usize].energised() {
                refuse(
                    &mut out,
                    RuleId::EarthingEnergised,
                    format!("{name} is energised: it cannot be earthed"),
                    false,
                );
            } else if before.maybe_energised(s) {
                refuse(
                    &mut out,
                    RuleId::EarthingEnergised,
                    format!("{name} is not proved dead: a device or source that could feed it is in an unknown state"),
                    false,
                );
            }
        }
        (Operation::Close, Some(b)) => {
            let a = w.a;
            let earthed = |s: u32| before.state[s as usize].earthed();
            let live = |s: u32| before.state[s as usize].energised() || before.maybe_energised(s);
            let (ea, eb) = (earthed(a), earthed(b));
            if ea != eb {
                let (earthed_side, other) = if ea { (a, b) } else { (b, a) };
                let what = if live(other) { "energised" } else { "another" };
                refuse(
                    &mut out,
                    RuleId::ClosingOntoEarthed,
                    format!(
                        "{} is earthed: closing {} would connect it to {what} section ({})",
                        section_name(model, earthed_side),
                        w.name,
                        section_name(model, other)
                    ),
                    false,
                );
            } else if !ea && (before.maybe_earthed(a) || before.maybe_earthed(b)) {
                let s = if before.maybe_earthed(a) { a } else { b };
                refuse(
                    &mut out,
                    RuleId::ClosingOntoEarthed,
                    format!(
                        "{} may be earthed (an earth switch or a device on its path is in an unknown state)",
                        section_name(model, s)
                    ),
                    false,
                );
            }
            if let Some(&s) = preview.energised_earthed.first() {
                if !out.iter().any(|i| i.rule == RuleId::ClosingOntoEarthed) {
                    refuse(
                        &mut out,
                        RuleId::ClosingOntoEarthed,
                        format!(
                            "closing {} would energise {}, which is earthed",
                            w.name,
                            section_name(model, s)
                        ),
                        false,
                    );
                }
            }
            for p in &preview.new_parallels {
                match p.permission {
                    ParallelPermission::Allowed => {}
                    permission => refuse(
                        &mut out,
                        RuleId::ForbiddenParallel,
                        format!(
                            "closing {} would parallel {}, which must not run in parallel",
                            w.name,
                            sources_in_words(model, &p.groups)
                        ),
                        permission == ParallelPermission::Overridable,
                    ),
                }
            }
            let uncertain = after.parallels.iter().find(|p| {
                !p.certain
                    && p.permission != ParallelPermission::Allowed
                    && !before
                        .parallels
                        .iter()
                        .any(|q| q.sources == p.sources && !q.certain)
            });
            if let Some(p) = uncertain {
                refuse(
                    &mut out,
                    RuleId::StateUnknown,
                    format!(
                        "closing {} may parallel {} through a device or source in an unknown state",
                        w.name,
                        sources_in_words(model, &p.groups)
                    ),
                    true,
                );
            }
            if w.kind == SwitchKind::Disconnector && !before.same_component(a, b) {
                let loaded = |s: u32| {
                    let part = before.component[s as usize];
                    model
                        .sections
                        .iter()
                        .enumerate()
                        .any(|(i, sec)| before.component[i] == part && (!sec.loads.is_empty()))
                };
                let (la, lb) = (
                    before.state[a as usize].energised(),
                    before.state[b as usize].energised(),
                );
                if (la && (lb || loaded(b))) || (lb && loaded(a)) {
                    refuse(
                        &mut out,
                        RuleId::DisconnectorUnderLoad,
                        format!(
                            "{} is a disconnector: closing it would make load or parallel current between {} and {}",
                            w.name,
                            section_name(model, a),
                            section_name(model, b)
                        ),
                        true,
                    );
                }
            }
        }
        (Operation::Open, _) => {
            if w.kind == SwitchKind::Disconnector {
                let loaded: Vec<u32> = preview
                    .lose_supply
                    .iter()
                    .copied()
                    .filter(|&s| !model.sections[s as usize].loads.is_empty())
                    .collect();
                if !loaded.is_empty() {
                    refuse(
                        &mut out,
                        RuleId::DisconnectorUnderLoad,
                        format!(
                            "{} is a disconnector: opening it would break the load current of {} ({} customers)",
                            w.name,
                            loaded
                                .iter()
                                .map(|&s| section_name(model, s))
                                .collect::<Vec<_>>()
                                .join(", "),
                            model.customers(&loaded)
                        ),
                        true,
                    );
                }
            }
        }
    }
    out
}
