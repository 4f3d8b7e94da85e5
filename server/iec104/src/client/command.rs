//! Commands of the controlling station: a tag's written value as a command
//! element, and the confirmation procedure (select, ACT_CON, execute,
//! ACT_CON, ACT_TERM) as a small state machine over the station's answers.
//! Pure.

use std::time::Instant;

use gridscada_config::{DataType, Iec104Command};
use gridscada_field::within_resolution;
use gridscada_tagdb::Value;

use crate::{normalized_from_f64, Asdu, Cause, Element, TypeId};

/// How one tag is commanded.
#[derive(Debug, Clone)]
pub(crate) struct CommandSpec {
    pub command: Iec104Command,
    pub ioa: u32,
    pub select: bool,
    pub qualifier: u8,
    pub data_type: DataType,
    pub scale: f64,
    pub offset: f64,
}

impl CommandSpec {
    /// The command element for `value` (execute form), or why it cannot
    /// carry it.
    pub fn element(&self, value: &Value) -> Result<Element, String> {
        let qualifier = self.qualifier;
        let number = || {
            value
                .as_f64()
                .filter(|f| f.is_finite())
                .ok_or_else(|| format!("{value} is not a number"))
        };
        // Engineering units back to the station's raw value.
        let raw = || number().map(|v| (v - self.offset) / self.scale);
        Ok(match self.command {
            Iec104Command::C_SC => Element::SingleCommand {
                on: bool_of(value)?,
                select: false,
                qualifier,
            },
            Iec104Command::C_DC => {
                let state = match (self.data_type, value) {
                    (DataType::Bool, v) => {
                        if bool_of(v)? {
                            2
                        } else {
                            1
                        }
                    }
                    (_, v) => match v.as_i128() {
                        Some(1) => 1,
                        Some(2) => 2,
                        _ => return Err(format!("a double command is 1 (off) or 2 (on), not {v}")),
                    },
                };
                Element::DoubleCommand {
                    state,
                    select: false,
                    qualifier,
                }
            }
            Iec104Command::C_RC => {
                let n = number()?;
                if n == 0.0 {
                    return Err(
                        "a regulating step command is +1 (higher) or -1 (lower), not 0".into(),
                    );
                }
                Element::StepCommand {
                    up: n > 0.0,
                    select: false,
                    qualifier,
                }
            }
            Iec104Command::C_SE_NA => {
                let r = raw()?;
                if !(-1.0..=1.0).contains(&r) {
                    return Err(format!(
                        "{value} is {r} normalized, outside -1..+1 of a normalized set point"
                    ));
                }
                Element::SetpointNormalized {
                    value: normalized_from_f64(r),
                    select: false,
                    qualifier,
                }
            }
            Iec104Command::C_SE_NB => {
                let r = raw()?.round();
                if !(f64::from(i16::MIN)..=f64::from(i16::MAX)).contains(&r) {
                    return Err(format!(
                        "{value} is {r} scaled, outside -32768..32767 of a scaled set point"
                    ));
                }
                Element::SetpointScaled {
                    value: r as i16,
                    select: false,
                    qualifier,
                }
            }
            Iec104Command::C_SE_NC => {
                let r = raw()?;
                if r.abs() > f64::from(f32::MAX) {
                    return Err(format!("{value} does not fit a short float"));
                }
                Element::SetpointFloat {
                    value: r as f32,
                    select: false,
                    qualifier,
                }
            }
            Iec104Command::C_BO => {
                let bits = value
                    .as_i128()
                    .and_then(|i| u32::try_from(i).ok())
                    .ok_or_else(|| format!("{value} is not a 32-bit bitstring (0..4294967295)"))?;
                Element::Bitstring32Command { bits }
            }
        })
    }

    /// Whether the confirmed feedback `got` shows the command took: the
    /// tag's monitored value equals what was written (set points within
    /// the station's resolution).
    pub fn confirms(&self, written: &Value, got: &Value) -> bool {
        match self.command {
            Iec104Command::C_SC | Iec104Command::C_DC | Iec104Command::C_BO => {
                within_resolution(written, got, 0.0)
            }
            // A step command moves the position by one: ACT_TERM confirms it.
            Iec104Command::C_RC => true,
            Iec104Command::C_SE_NA | Iec104Command::C_SE_NB | Iec104Command::C_SE_NC => {
                let resolution = match self.command {
                    Iec104Command::C_SE_NA => self.scale.abs() / 32768.0,
                    Iec104Command::C_SE_NB => self.scale.abs(),
                    _ => written
                        .as_f64()
                        .map_or(1e-9, |w| (w.abs() * 1e-6).max(1e-9)),
                };
                within_resolution(written, got, resolution)
            }
        }
    }
}

fn bool_of(value: &Value) -> Result<bool, String> {
    match value {
        Value::Bool(b) => Ok(*b),
        v => match v.as_i128() {
            Some(0) => Ok(false),
            Some(1) => Ok(true),
            _ => Err(format!("{v} is not on/off (true/false, 1/0)")),
        },
    }
}

/// The element with its S/E bit set to `select`.
pub(crate) fn with_select(e: Element, select: bool) -> Element {
    match e {
        Element::SingleCommand { on, qualifier, .. } => Element::SingleCommand {
            on,
            select,
            qualifier,
        },
        Element::DoubleCommand {
            state, qualifier, ..
        } => Element::DoubleCommand {
            state,
            select,
            qualifier,
        },
        Element::StepCommand { up, qualifier, .. } => Element::StepCommand {
            up,
            select,
            qualifier,
        },
        Element::SetpointNormalized {
            value, qualifier, ..
        } => Element::SetpointNormalized {
            value,
            select,
            qualifier,
        },
        Element::SetpointScaled {
            value, qualifier, ..
        } => Element::SetpointScaled {
            value,
            select,
            qualifier,
        },
        Element::SetpointFloat {
            value, qualifier, ..
        } => Element::SetpointFloat {
            value,
            select,
            qualifier,
        },
        other => other,
    }
}

/// Where a command stands.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Phase {
    /// The select is sent; its ACT_CON is awaited.
    Selecting,
    /// The execute is sent; its ACT_CON is awaited.
    Executing,
    /// Confirmed; the ACT_TERM is awaited.
    Terminating,
}

/// What an answer from the station does to the command in progress.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Step {
    /// Not an answer to this command.
    Ignore,
    /// The select is confirmed: send the execute now.
    Execute,
    /// Wait for the next answer.
    Wait(Phase),
    /// The station completed the command.
    Done,
    /// The station refused it, in words.
    Refused(String),
}

/// The command in progress on a station: one at a time, so answers cannot
/// be mistaken for another command's.
#[derive(Debug)]
pub(crate) struct Procedure {
    pub type_id: TypeId,
    pub ioa: u32,
    pub phase: Phase,
    pub deadline: Instant,
    /// Whether the station sends ACT_TERM (`command_termination`).
    pub termination: bool,
}

impl Procedure {
    /// Takes an answer from the station.
    pub fn answer(&mut self, asdu: &Asdu) -> Step {
        if asdu.type_id() != self.type_id || asdu.objects().first().map(|o| o.ioa) != Some(self.ioa)
        {
            // A mirrored unknown-type answer carries our type id; any other
            // type is another conversation.
            return Step::Ignore;
        }
        let what = match self.phase {
            Phase::Selecting => "select",
            Phase::Executing | Phase::Terminating => "execute",
        };
        match (asdu.cause(), asdu.is_negative(), self.phase) {
            (Cause::ActCon, true, _) => {
                Step::Refused(format!("the station refused the {what} (negative ACT_CON)"))
            }
            (Cause::ActCon, false, Phase::Selecting) => Step::Execute,
            (Cause::ActCon, false, Phase::Executing) if self.termination => {
                self.phase = Phase::Terminating;
                Step::Wait(Phase::Terminating)
            }
            (Cause::ActCon, false, Phase::Executing) => Step::Done,
            (Cause::ActTerm, false, Phase::Terminating | Phase::Executing) => Step::Done,
            (Cause::ActTerm, true, _) => Step::Refused(format!(
                "the station ended the {what} unsuccessfully (negative ACT_TERM)"
            )),
            (Cause::UnknownType, _, _) => Step::Refused(format!(
                "the station does not know the type {} (cause 44, unknown type identification)",
                self.type_id.name()
            )),
            (Cause::UnknownCause, _, _) => {
                Step::Refused("the station answered cause 45, unknown cause of transmission".into())
            }
            (Cause::UnknownCommonAddress, _, _) => Step::Refused(
                "the station answered cause 46, unknown common address of ASDU".into(),
            ),
            (Cause::UnknownIoa, _, _) => Step::Refused(format!(
                "the station answered cause 47, unknown information object address {}",
                self.ioa
            )),
            (cause, _, phase) => Step::Refused(format!(
                "the station answered the {what} with cause {cause} while {phase:?}"
            )),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::InformationObject;

    fn spec(command: Iec104Command, data_type: DataType) -> CommandSpec {
        CommandSpec {
            command,
            ioa: 2001,
            select: true,
            qualifier: 0,
            data_type,
            scale: 1.0,
            offset: 0.0,
        }
    }

    fn answer(cause: Cause, negative: bool) -> Asdu {
        let e = Element::DoubleCommand {
            state: 2,
            select: false,
            qualifier: 0,
        };
        Asdu::new(
            TypeId::C_DC_NA_1,
            cause,
            1,
            vec![InformationObject::new(2001, e)],
        )
        .unwrap()
        .with_negative(negative)
    }

    #[test]
    fn values_become_command_elements() {
        let dc = spec(Iec104Command::C_DC, DataType::Bool);
        assert_eq!(
            dc.element(&Value::Bool(true)).unwrap(),
            Element::DoubleCommand {
                state: 2,
                select: false,
                qualifier: 0
            }
        );
        let dci = spec(Iec104Command::C_DC, DataType::U16);
        assert!(dci
            .element(&Value::Int(3))
            .unwrap_err()
            .contains("1 (off) or 2 (on)"));
        let mut nb = spec(Iec104Command::C_SE_NB, DataType::F32);
        nb.scale = 0.1;
        assert_eq!(
            nb.element(&Value::Float(230.5)).unwrap(),
            Element::SetpointScaled {
                value: 2305,
                select: false,
                qualifier: 0
            }
        );
        assert!(nb
            .element(&Value::Float(1e9))
            .unwrap_err()
            .contains("outside"));
        let na = spec(Iec104Command::C_SE_NA, DataType::F32);
        assert!(na.element(&Value::Float(1.5)).is_err());
        assert!(nb.confirms(&Value::Float(230.5), &Value::Float(230.5000001)));
        assert!(!dc.confirms(&Value::Bool(true), &Value::Bool(false)));
    }

    #[test]
    fn select_then_execute_then_termination() {
        let t = Instant::now();
        let mut p = Procedure {
            type_id: TypeId::C_DC_NA_1,
            ioa: 2001,
            phase: Phase::Selecting,
            deadline: t,
            termination: true,
        };
        assert_eq!(p.answer(&answer(Cause::ActCon, false)), Step::Execute);
        p.phase = Phase::Executing;
        assert_eq!(
            p.answer(&answer(Cause::ActCon, false)),
            Step::Wait(Phase::Terminating)
        );
        assert_eq!(p.answer(&answer(Cause::ActTerm, false)), Step::Done);
    }

    #[test]
    fn refusals_are_named() {
        let t = Instant::now();
        let mut p = Procedure {
            type_id: TypeId::C_DC_NA_1,
            ioa: 2001,
            phase: Phase::Selecting,
            deadline: t,
            termination: true,
        };
        match p.answer(&answer(Cause::ActCon, true)) {
            Step::Refused(r) => assert!(r.contains("refused the select"), "{r}"),
            s => panic!("{s:?}"),
        }
        match p.answer(&answer(Cause::UnknownIoa, true)) {
            Step::Refused(r) => {
                assert!(r.contains("unknown information object address 2001"), "{r}")
            }
            s => panic!("{s:?}"),
        }
        // Another IOA is not this command's answer.
        let other = Asdu::new(
            TypeId::C_DC_NA_1,
            Cause::ActCon,
            1,
            vec![InformationObject::new(
                9,
                Element::DoubleCommand {
                    state: 2,
                    select: false,
                    qualifier: 0,
                },
            )],
        )
        .unwrap();
        assert_eq!(p.answer(&other), Step::Ignore);
    }
}
