//! Switching programmes: an ordered list of steps (operate a device, place
//! or remove a safety tag, a manual step to confirm) prepared by a
//! supervisor, checked step by step against the topology before it is
//! approved, and executed one step at a time.
//!
//! Pure: [`parse`] turns the steps as written into checked steps (every
//! device known, every tag removal having a tag to remove), and [`check`]
//! plays them forward from a network state, giving each step's effect and
//! what would refuse it at that point. Storage, execution and who may do
//! what are the callers'.

use crate::model::Model;
use crate::preview::{preview, Preview};
use crate::rules::{interlocks, Interlock, Operation, RuleId};
use crate::safety::{SafetyTag, TagKind};
use crate::topology::{compute, Inputs, Pos};

/// One step as written (the API's and the store's form).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum StepText {
    Operate {
        device: String,
        operation: String,
    },
    PlaceTag {
        device: String,
        tag_kind: String,
        reason: String,
        #[serde(default)]
        work_ref: String,
    },
    RemoveTag {
        device: String,
        tag_kind: String,
    },
    Manual {
        text: String,
    },
}

/// One checked step.
#[derive(Debug, Clone, PartialEq)]
pub enum Step {
    Operate {
        device: usize,
        operation: Operation,
    },
    PlaceTag {
        device: usize,
        kind: TagKind,
        reason: String,
        work_ref: String,
    },
    RemoveTag {
        device: usize,
        kind: TagKind,
    },
    Manual {
        text: String,
    },
}

impl Step {
    /// The step in words: "open Feeder 1 breaker (f1)".
    pub fn describe(&self, model: &Model) -> String {
        let name = |d: &usize| {
            let w = &model.switches[*d];
            format!("{} ({})", w.name, w.id)
        };
        match self {
            Step::Operate { device, operation } => {
                format!("{} {}", operation.as_str(), name(device))
            }
            Step::PlaceTag { device, kind, .. } => {
                format!("place a {} tag on {}", kind.label(), name(device))
            }
            Step::RemoveTag { device, kind } => {
                format!("remove the {} tag from {}", kind.label(), name(device))
            }
            Step::Manual { text } => format!("confirm: {text}"),
        }
    }

    /// The device the step is about, if any.
    pub fn device(&self) -> Option<usize> {
        match self {
            Step::Operate { device, .. }
            | Step::PlaceTag { device, .. }
            | Step::RemoveTag { device, .. } => Some(*device),
            Step::Manual { .. } => None,
        }
    }
}

/// The most steps a programme may have.
pub const MAX_STEPS: usize = 200;

/// Checks the steps as written; every problem names its step (from 1).
pub fn parse(model: &Model, steps: &[StepText]) -> Result<Vec<Step>, Vec<String>> {
    let mut errors = vec![];
    let mut out = vec![];
    if steps.is_empty() {
        errors.push("a programme needs at least one step".to_string());
    }
    if steps.len() > MAX_STEPS {
        errors.push(format!(
            "a programme has at most {MAX_STEPS} steps; this one has {}",
            steps.len()
        ));
    }
    for (n, s) in steps.iter().enumerate() {
        let n = n + 1;
        let device = |id: &str, errors: &mut Vec<String>| {
            let d = model.switch(id);
            if d.is_none() {
                errors.push(format!("step {n}: no switching device '{id}'"));
            }
            d
        };
        let kind = |k: &str, errors: &mut Vec<String>| {
            let t = TagKind::parse(k);
            if t.is_none() {
                errors.push(format!(
                    "step {n}: tag kind '{k}': expected one of {}",
                    TagKind::NAMES
                ));
            }
            t
        };
        match s {
            StepText::Operate {
                device: id,
                operation,
            } => {
                let d = device(id, &mut errors);
                let op = match operation.as_str() {
                    "open" => Some(Operation::Open),
                    "close" => Some(Operation::Close),
                    other => {
                        errors.push(format!(
                            "step {n}: operation '{other}': expected open or close"
                        ));
                        None
                    }
                };
                if let (Some(device), Some(operation)) = (d, op) {
                    out.push(Step::Operate { device, operation });
                }
            }
            StepText::PlaceTag {
                device: id,
                tag_kind,
                reason,
                work_ref,
            } => {
                let d = device(id, &mut errors);
                let k = kind(tag_kind, &mut errors);
                if reason.trim().is_empty() {
                    errors.push(format!("step {n}: a safety tag needs a reason"));
                }
                if let (Some(device), Some(kind)) = (d, k) {
                    out.push(Step::PlaceTag {
                        device,
                        kind,
                        reason: reason.trim().to_string(),
                        work_ref: work_ref.trim().to_string(),
                    });
                }
            }
            StepText::RemoveTag {
                device: id,
                tag_kind,
            } => {
                let d = device(id, &mut errors);
                let k = kind(tag_kind, &mut errors);
                if let (Some(device), Some(kind)) = (d, k) {
                    out.push(Step::RemoveTag { device, kind });
                }
            }
            StepText::Manual { text } => {
                if text.trim().is_empty() {
                    errors.push(format!("step {n}: a manual step needs its instruction"));
                }
                out.push(Step::Manual {
                    text: text.trim().to_string(),
                });
            }
        }
    }
    if errors.is_empty() {
        Ok(out)
    } else {
        Err(errors)
    }
}

/// One step played forward.
#[derive(Debug, Clone, PartialEq)]
pub struct StepCheck {
    /// What would refuse it at that point (empty: it may be done).
    pub refusals: Vec<Interlock>,
    /// Its effect on the network (operate steps).
    pub effect: Option<Preview>,
    /// Said of the step without refusing it (the device is already there).
    pub notes: Vec<String>,
}

/// Plays `steps[from..]` forward from `inputs` with the `standing` safety
/// tags: each step's effect and refusals, assuming every step before it was
/// done. A refused step is assumed done too, so one check shows every
/// problem of the programme.
pub fn check(
    model: &Model,
    inputs: &Inputs,
    standing: &[SafetyTag],
    steps: &[Step],
    from: usize,
) -> Vec<StepCheck> {
    let mut inputs = inputs.clone();
    let mut tags: Vec<(usize, TagKind)> = standing
        .iter()
        .filter_map(|t| Some((model.switch(&t.device)?, t.kind)))
        .collect();
    let mut before = compute(model, &inputs);
    let mut out = Vec::with_capacity(steps.len().saturating_sub(from));
    for step in steps.iter().skip(from) {
        let mut c = StepCheck {
            refusals: vec![],
            effect: None,
            notes: vec![],
        };
        match step {
            Step::Operate { device, operation } => {
                let w = &model.switches[*device];
                if let Some(&(_, k)) = tags
                    .iter()
                    .filter(|(d, k)| d == device && k.blocks(*operation))
                    .max_by_key(|(_, k)| *k)
                {
                    c.refusals.push(Interlock {
                        rule: RuleId::SafetyTag,
                        text: format!("{} carries a {} tag at this step", w.name, k.label()),
                        overridable: false,
                    });
                }
                if inputs.switches.get(*device) == Some(&operation.target()) {
                    c.notes.push(format!(
                        "{} is already {} at this step",
                        w.name,
                        operation.target().as_str()
                    ));
                } else {
                    let next = inputs.with(*device, operation.target());
                    let after = compute(model, &next);
                    let p = preview(model, &before, &after);
                    c.refusals.extend(interlocks(
                        model, &inputs, &before, &after, &p, *device, *operation,
                    ));
                    c.effect = Some(p);
                    inputs = next;
                    before = after;
                }
            }
            Step::PlaceTag { device, kind, .. } => tags.push((*device, *kind)),
            Step::RemoveTag { device, kind } => {
                match tags.iter().position(|(d, k)| d == device && k == kind) {
                    Some(i) => {
                        tags.remove(i);
                    }
                    None => c.refusals.push(Interlock {
                        rule: RuleId::SafetyTag,
                        text: format!(
                            "{} carries no {} tag at this step",
                            model.switches[*device].name,
                            kind.label()
                        ),
                        overridable: false,
                    }),
                }
            }
            Step::Manual { .. } => {}
        }
        out.push(c);
    }
    out
}

/// Whether `pos` is where the step leaves its device (operate steps).
pub fn reached(step: &Step, pos: Pos) -> bool {
    match step {
        Step::Operate { operation, .. } => pos == operation.target(),
        _ => true,
    }
}
