//! ACSI services mapped onto MMS (IEC 61850-8-1), pure: reports decoded
//! by their option fields, controls' `Oper`/`SBOw`/`Cancel` values built
//! from the object's own type, and the `LastApplError` a refused control
//! carries, with its `AddCause` in words.

use crate::ber::BitString;
use crate::data::{BinaryTime, Data, UtcTime};
use crate::mms::{AccessResult, InformationReport, ObjectName, ReportNames, TypeSpec};

/// A decoded report (`RPT`).
#[derive(Debug, Clone, PartialEq)]
pub struct Report {
    pub rpt_id: String,
    pub seq_num: Option<u64>,
    pub time_of_entry: Option<BinaryTime>,
    pub dataset: Option<String>,
    pub buffer_overflow: bool,
    pub entry_id: Option<Vec<u8>>,
    pub conf_rev: Option<u64>,
    /// Segmentation: sub-sequence number and whether more segments follow.
    pub segment: Option<(u64, bool)>,
    /// Included dataset members: index, value, reason for inclusion.
    pub entries: Vec<ReportEntry>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct ReportEntry {
    pub member: usize,
    pub value: Data,
    pub reason: Option<BitString>,
}

/// Option fields (`OptFlds`) bits.
pub mod opt {
    pub const SEQ_NUM: usize = 1;
    pub const TIME_STAMP: usize = 2;
    pub const REASON: usize = 3;
    pub const DATA_SET: usize = 4;
    pub const DATA_REF: usize = 5;
    pub const BUFFER_OVERFLOW: usize = 6;
    pub const ENTRY_ID: usize = 7;
    pub const CONF_REV: usize = 8;
    pub const SEGMENTATION: usize = 9;
}

/// Trigger options (`TrgOps`) bits.
pub mod trg {
    pub const DATA_CHANGE: usize = 1;
    pub const QUALITY_CHANGE: usize = 2;
    pub const DATA_UPDATE: usize = 3;
    pub const INTEGRITY: usize = 4;
    pub const GI: usize = 5;
}

/// A reason for inclusion in words.
pub fn reason_words(b: &BitString) -> String {
    let words = [
        (1, "data change"),
        (2, "quality change"),
        (3, "data update"),
        (4, "integrity"),
        (5, "general interrogation"),
        (6, "application trigger"),
    ];
    let set: Vec<&str> = words
        .iter()
        .filter(|(i, _)| b.bit(*i))
        .map(|(_, w)| *w)
        .collect();
    if set.is_empty() {
        "none".into()
    } else {
        set.join(", ")
    }
}

/// Why a report could not be decoded.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("report: {0}")]
pub struct ReportError(pub String);

fn take<'a>(
    it: &mut std::slice::Iter<'a, AccessResult>,
    what: &str,
) -> Result<&'a Data, ReportError> {
    match it.next() {
        Some(Ok(d)) => Ok(d),
        Some(Err(e)) => Err(ReportError(format!("{what}: {e}"))),
        None => Err(ReportError(format!("{what} missing"))),
    }
}

fn unsigned(d: &Data, what: &str) -> Result<u64, ReportError> {
    match d {
        Data::Unsigned(n) => Ok(*n),
        Data::Integer(n) if *n >= 0 => Ok(*n as u64),
        other => Err(ReportError(format!(
            "{what} is {} (unsigned expected)",
            other.kind()
        ))),
    }
}

fn string(d: &Data, what: &str) -> Result<String, ReportError> {
    match d {
        Data::VisibleString(s) | Data::MmsString(s) => Ok(s.clone()),
        other => Err(ReportError(format!(
            "{what} is {} (visible-string expected)",
            other.kind()
        ))),
    }
}

impl Report {
    /// Whether `r` is a report (`RPT`) rather than a command termination
    /// or `LastApplError`.
    pub fn is_report(r: &InformationReport) -> bool {
        matches!(&r.names, ReportNames::List(ObjectName::Vmd(n)) if n == "RPT")
    }

    /// Decodes a report by its option fields; the included members are
    /// those set in its inclusion bit string.
    pub fn decode(r: &InformationReport) -> Result<Report, ReportError> {
        let mut it = r.results.iter();
        let rpt_id = string(take(&mut it, "RptID")?, "RptID")?;
        let opt = match take(&mut it, "OptFlds")? {
            Data::BitString(b) => b.clone(),
            other => return Err(ReportError(format!("OptFlds is {}", other.kind()))),
        };
        let mut rep = Report {
            rpt_id,
            seq_num: None,
            time_of_entry: None,
            dataset: None,
            buffer_overflow: false,
            entry_id: None,
            conf_rev: None,
            segment: None,
            entries: Vec::new(),
        };
        if opt.bit(opt::SEQ_NUM) {
            rep.seq_num = Some(unsigned(take(&mut it, "SqNum")?, "SqNum")?);
        }
        if opt.bit(opt::TIME_STAMP) {
            rep.time_of_entry = match take(&mut it, "TimeOfEntry")? {
                Data::BinaryTime(t) => Some(*t),
                other => return Err(ReportError(format!("TimeOfEntry is {}", other.kind()))),
            };
        }
        if opt.bit(opt::DATA_SET) {
            rep.dataset = Some(string(take(&mut it, "DatSet")?, "DatSet")?);
        }
        if opt.bit(opt::BUFFER_OVERFLOW) {
            rep.buffer_overflow = matches!(take(&mut it, "BufOvfl")?, Data::Boolean(true));
        }
        if opt.bit(opt::ENTRY_ID) {
            rep.entry_id = match take(&mut it, "EntryID")? {
                Data::OctetString(o) => Some(o.clone()),
                other => return Err(ReportError(format!("EntryID is {}", other.kind()))),
            };
        }
        if opt.bit(opt::CONF_REV) {
            rep.conf_rev = Some(unsigned(take(&mut it, "ConfRev")?, "ConfRev")?);
        }
        if opt.bit(opt::SEGMENTATION) {
            let sub = unsigned(take(&mut it, "SubSeqNum")?, "SubSeqNum")?;
            let more = matches!(take(&mut it, "MoreSegmentsFollow")?, Data::Boolean(true));
            rep.segment = Some((sub, more));
        }
        let inclusion = match take(&mut it, "Inclusion")? {
            Data::BitString(b) => b.clone(),
            other => return Err(ReportError(format!("Inclusion is {}", other.kind()))),
        };
        let included: Vec<usize> = (0..inclusion.len).filter(|i| inclusion.bit(*i)).collect();
        if opt.bit(opt::DATA_REF) {
            for _ in &included {
                take(&mut it, "data reference")?;
            }
        }
        let mut values = Vec::with_capacity(included.len());
        for m in &included {
            values.push(take(&mut it, &format!("value of member {m}"))?.clone());
        }
        let mut reasons = Vec::with_capacity(included.len());
        if opt.bit(opt::REASON) {
            for m in &included {
                match take(&mut it, &format!("reason of member {m}"))? {
                    Data::BitString(b) => reasons.push(Some(b.clone())),
                    other => {
                        return Err(ReportError(format!(
                            "reason of member {m} is {}",
                            other.kind()
                        )))
                    }
                }
            }
        }
        rep.entries = included
            .into_iter()
            .zip(values)
            .enumerate()
            .map(|(i, (member, value))| ReportEntry {
                member,
                value,
                reason: reasons.get(i).cloned().flatten(),
            })
            .collect();
        Ok(rep)
    }
}

/// A control's refusal or failure as the IED reports it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LastApplError {
    /// The control object's service reference, e.g. `LD0/CSWI1$CO$Pos$Oper`.
    pub control_object: String,
    pub error: i64,
    pub ctl_num: u64,
    pub add_cause: i64,
}

impl LastApplError {
    /// From an information report naming `LastApplError`.
    pub fn from_report(r: &InformationReport) -> Option<LastApplError> {
        let ReportNames::Variables(names) = &r.names else {
            return None;
        };
        let i = names
            .iter()
            .position(|n| matches!(n, ObjectName::Vmd(v) if v == "LastApplError"))?;
        let Some(Ok(Data::Structure(f))) = r.results.get(i) else {
            return None;
        };
        let text = |d: Option<&Data>| match d {
            Some(Data::VisibleString(s)) | Some(Data::MmsString(s)) => s.clone(),
            _ => String::new(),
        };
        let int = |d: Option<&Data>| d.and_then(Data::as_f64).map_or(0, |n| n as i64);
        Some(LastApplError {
            control_object: text(f.first()),
            error: int(f.get(1)),
            ctl_num: int(f.get(3)).max(0) as u64,
            add_cause: int(f.get(4)),
        })
    }

    /// The refusal in words: cause and error.
    pub fn describe(&self) -> String {
        let error = match self.error {
            0 => "",
            1 => ", error unknown",
            2 => ", timeout test not ok",
            3 => ", operator test not ok",
            _ => ", error",
        };
        format!(
            "{} (AddCause {}){error}",
            add_cause_words(self.add_cause),
            self.add_cause
        )
    }
}

/// `AddCause` (IEC 61850-7-2, 20.5.2.9) in words.
pub fn add_cause_words(n: i64) -> &'static str {
    const WORDS: [&str; 28] = [
        "unknown",
        "not supported",
        "blocked by switching hierarchy",
        "select failed",
        "invalid position",
        "position reached",
        "parameter change in execution",
        "step limit",
        "blocked by mode",
        "blocked by process",
        "blocked by interlocking",
        "blocked by synchrocheck",
        "command already in execution",
        "blocked by health",
        "1 of n control",
        "abortion by cancel",
        "time limit over",
        "abortion by trip",
        "object not selected",
        "object already selected",
        "no access authority",
        "ended with overshoot",
        "abortion due to deviation",
        "abortion by communication loss",
        "blocked by command",
        "none",
        "inconsistent parameters",
        "locked by other client",
    ];
    usize::try_from(n)
        .ok()
        .and_then(|i| WORDS.get(i))
        .copied()
        .unwrap_or("unlisted cause")
}

/// Whether `r` is the command termination of control object `oper`
/// (`LD`, `LN$CO$DO$Oper`); `Some(Err)` carries the negative one's error.
pub fn command_termination(
    r: &InformationReport,
    oper: &ObjectName,
) -> Option<Result<(), LastApplError>> {
    let ReportNames::Variables(names) = &r.names else {
        return None;
    };
    if !names.contains(oper) {
        return None;
    }
    match LastApplError::from_report(r) {
        Some(e) => Some(Err(e)),
        None => Some(Ok(())),
    }
}

/// What a control carries besides its value.
#[derive(Debug, Clone, PartialEq)]
pub struct ControlParams {
    pub or_cat: i64,
    /// Who operates: the user's name.
    pub or_ident: Vec<u8>,
    pub ctl_num: u8,
    pub time: UtcTime,
    pub test: bool,
    pub interlock_check: bool,
    pub synchro_check: bool,
}

/// The `Oper` (or `SBOw`, `Cancel`) value for the object's type `ty`,
/// filled component by component, with `ctl_val` the commanded value
/// (as a number, or a bool).
pub fn control_value(
    ty: &TypeSpec,
    ctl_val: &ControlValue,
    p: &ControlParams,
) -> Result<Data, String> {
    let TypeSpec::Structure(components) = ty else {
        return Err("the control's type is not a structure".into());
    };
    components
        .iter()
        .map(|(name, t)| {
            Ok(match name.as_str() {
                "ctlVal" => ctl_val.as_type(t)?,
                "operTm" => Data::UtcTime(p.time),
                "origin" => Data::Structure(vec![
                    Data::Integer(p.or_cat),
                    Data::OctetString(p.or_ident.clone()),
                ]),
                "ctlNum" => Data::Unsigned(u64::from(p.ctl_num)),
                "T" => Data::UtcTime(p.time),
                "Test" => Data::Boolean(p.test),
                "Check" => {
                    Data::BitString(BitString::from_bits(&[p.synchro_check, p.interlock_check]))
                }
                other => {
                    return Err(format!(
                        "the control has a component '{other}' this client does not fill"
                    ))
                }
            })
        })
        .collect::<Result<Vec<_>, String>>()
        .map(Data::Structure)
}

/// A commanded value before it takes the `ctlVal`'s type.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ControlValue {
    Bool(bool),
    Number(f64),
}

impl ControlValue {
    fn as_type(&self, t: &TypeSpec) -> Result<Data, String> {
        let n = match self {
            ControlValue::Bool(b) => f64::from(u8::from(*b)),
            ControlValue::Number(n) => *n,
        };
        let whole = || {
            if n.fract() == 0.0 {
                Ok(n as i64)
            } else {
                Err(format!("{n} is not a whole number"))
            }
        };
        Ok(match t {
            TypeSpec::Boolean => match self {
                ControlValue::Bool(b) => Data::Boolean(*b),
                ControlValue::Number(n) if *n == 0.0 || *n == 1.0 => Data::Boolean(*n == 1.0),
                ControlValue::Number(n) => return Err(format!("{n} for a boolean control")),
            },
            TypeSpec::Integer(_) => Data::Integer(whole()?),
            TypeSpec::Unsigned(_) => {
                Data::Unsigned(u64::try_from(whole()?).map_err(|_| format!("{n} is negative"))?)
            }
            TypeSpec::Float => Data::Float(n),
            // A step command (BSC/ISC Tcmd): 0 stop, 1 lower, 2 higher.
            TypeSpec::BitString(_) => {
                let v = whole()?;
                if !(0..=3).contains(&v) {
                    return Err(format!("{v} for a 2-bit step command"));
                }
                Data::BitString(BitString::from_bits(&[v & 2 != 0, v & 1 != 0]))
            }
            // AnalogueValue: `i` and/or `f`.
            TypeSpec::Structure(c) => Data::Structure(
                c.iter()
                    .map(|(name, ty)| match (name.as_str(), ty) {
                        ("f", _) => Ok(Data::Float(n)),
                        ("i", _) => Ok(Data::Integer(n.round() as i64)),
                        (other, _) => Err(format!("ctlVal component '{other}'")),
                    })
                    .collect::<Result<_, String>>()?,
            ),
            other => return Err(format!("a ctlVal of type {other:?}")),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mms::bits;

    fn params() -> ControlParams {
        ControlParams {
            or_cat: 3,
            or_ident: b"operator1".to_vec(),
            ctl_num: 7,
            time: UtcTime::from_unix_ms(1_000, 0),
            test: false,
            interlock_check: true,
            synchro_check: false,
        }
    }

    #[test]
    fn oper_follows_the_object_type() {
        let ty = TypeSpec::Structure(vec![
            ("ctlVal".into(), TypeSpec::Boolean),
            ("origin".into(), TypeSpec::Structure(vec![])),
            ("ctlNum".into(), TypeSpec::Unsigned(8)),
            ("T".into(), TypeSpec::UtcTime),
            ("Test".into(), TypeSpec::Boolean),
            ("Check".into(), TypeSpec::BitString(2)),
        ]);
        let d = control_value(&ty, &ControlValue::Bool(true), &params()).unwrap();
        let Data::Structure(f) = d else { panic!() };
        assert_eq!(f[0], Data::Boolean(true));
        assert_eq!(f[2], Data::Unsigned(7));
        assert_eq!(f[5], Data::BitString(BitString::from_bits(&[false, true])));
        let apc = TypeSpec::Structure(vec![(
            "ctlVal".into(),
            TypeSpec::Structure(vec![("f".into(), TypeSpec::Float)]),
        )]);
        assert_eq!(
            control_value(&apc, &ControlValue::Number(2.5), &params()).unwrap(),
            Data::Structure(vec![Data::Structure(vec![Data::Float(2.5)])])
        );
        assert!(control_value(&ty, &ControlValue::Number(2.0), &params()).is_err());
    }

    #[test]
    fn a_report_decodes_by_its_option_fields() {
        let opt = bits(
            10,
            &[
                opt::SEQ_NUM,
                opt::DATA_SET,
                opt::ENTRY_ID,
                opt::REASON,
                opt::CONF_REV,
            ],
        );
        let r = InformationReport {
            names: ReportNames::List(ObjectName::Vmd("RPT".into())),
            results: vec![
                Ok(Data::VisibleString("brcb01".into())),
                Ok(Data::BitString(opt)),
                Ok(Data::Unsigned(4)),
                Ok(Data::VisibleString("LD0/LLN0$Events".into())),
                Ok(Data::OctetString(vec![1, 2, 3, 4, 5, 6, 7, 8])),
                Ok(Data::Unsigned(1)),
                Ok(Data::BitString(bits(3, &[0, 2]))),
                Ok(Data::Boolean(true)),
                Ok(Data::Float(4.0)),
                Ok(Data::BitString(bits(7, &[1]))),
                Ok(Data::BitString(bits(7, &[5]))),
            ],
        };
        assert!(Report::is_report(&r));
        let rep = Report::decode(&r).unwrap();
        assert_eq!(rep.seq_num, Some(4));
        assert_eq!(rep.entry_id.as_deref(), Some(&[1, 2, 3, 4, 5, 6, 7, 8][..]));
        assert_eq!(rep.entries.len(), 2);
        assert_eq!(
            (rep.entries[1].member, &rep.entries[1].value),
            (2, &Data::Float(4.0))
        );
        assert_eq!(
            reason_words(rep.entries[1].reason.as_ref().unwrap()),
            "general interrogation"
        );
        // One value short: an error naming what is missing.
        let mut short = r.clone();
        short.results.truncate(8);
        assert!(Report::decode(&short).unwrap_err().0.contains("member 2"));
    }

    #[test]
    fn last_appl_error_names_its_cause() {
        let r = InformationReport {
            names: ReportNames::Variables(vec![ObjectName::Vmd("LastApplError".into())]),
            results: vec![Ok(Data::Structure(vec![
                Data::VisibleString("TESTLD0/CSWI1$CO$Pos$SBOw".into()),
                Data::Integer(0),
                Data::Structure(vec![Data::Integer(3), Data::OctetString(vec![])]),
                Data::Unsigned(1),
                Data::Integer(10),
            ]))],
        };
        let e = LastApplError::from_report(&r).unwrap();
        assert_eq!(e.add_cause, 10);
        assert_eq!(e.describe(), "blocked by interlocking (AddCause 10)");
    }
}
