//! What an IEC 61850 client needs of an SCL file: the IEDs with their
//! logical devices, logical nodes, datasets and report control blocks, the
//! data type templates, and each IED's address on the station bus.

use std::collections::HashMap;

/// Where an element starts in the file (octet offset, 0-based).
pub type Offset = u64;

#[derive(Debug, Default, Clone)]
pub struct Scl {
    pub ieds: Vec<Ied>,
    pub templates: Templates,
    /// By IED name: the first MMS access point's address.
    pub addresses: HashMap<String, Address>,
    /// IED names in the file, including those not kept (`--ied`).
    pub all_ied_names: Vec<String>,
    /// The bays of the Substation section, with the logical nodes each
    /// one's functions are allocated to.
    pub bays: Vec<Bay>,
}

/// A bay of the single-line diagram (`Substation/VoltageLevel/Bay`).
#[derive(Debug, Default, Clone, PartialEq, Eq)]
pub struct Bay {
    pub substation: String,
    pub voltage_level: String,
    pub name: String,
    pub desc: String,
    /// `LNode`s in the bay or its equipment.
    pub lnodes: Vec<LNodeRef>,
}

/// An `LNode`: a logical node of an IED allocated to a function.
#[derive(Debug, Default, Clone, PartialEq, Eq)]
pub struct LNodeRef {
    pub ied: String,
    pub ld_inst: String,
    pub prefix: String,
    pub ln_class: String,
    pub ln_inst: String,
}

impl LNodeRef {
    /// The logical node's name, `prefix + lnClass + inst`.
    pub fn ln_name(&self) -> String {
        format!("{}{}{}", self.prefix, self.ln_class, self.ln_inst)
    }
}

#[derive(Debug, Default, Clone, PartialEq, Eq)]
pub struct Address {
    pub ip: Option<String>,
    /// `MMS-Port` where the file gives one (a vendor extension); else 102.
    pub port: Option<u16>,
    /// Dotted, from `OSI-AP-Title` (written with commas in SCL).
    pub ap_title: Option<String>,
    pub ae_qualifier: Option<i64>,
    pub psel: Option<String>,
    pub ssel: Option<String>,
    pub tsel: Option<String>,
}

#[derive(Debug, Default, Clone)]
pub struct Ied {
    pub name: String,
    pub manufacturer: String,
    pub ied_type: String,
    pub desc: String,
    pub ldevices: Vec<LDevice>,
    pub at: Offset,
}

#[derive(Debug, Default, Clone)]
pub struct LDevice {
    pub inst: String,
    /// `ldName`, when the LD is not named IED name + inst.
    pub ld_name: Option<String>,
    pub desc: String,
    pub lns: Vec<Ln>,
    pub at: Offset,
}

impl LDevice {
    /// The logical device's name on the wire (the MMS domain).
    pub fn name(&self, ied: &str) -> String {
        self.ld_name
            .clone()
            .unwrap_or_else(|| format!("{ied}{}", self.inst))
    }
}

#[derive(Debug, Default, Clone)]
pub struct Ln {
    pub prefix: String,
    pub class: String,
    pub inst: String,
    pub ln_type: String,
    pub desc: String,
    /// Instance values: `DO[.SDO].DA[.BDA]` -> `Val` (and `DO` -> its `desc`
    /// under the key `DO#desc`).
    pub values: HashMap<String, String>,
    pub datasets: Vec<DataSet>,
    pub reports: Vec<ReportControl>,
    pub at: Offset,
}

impl Ln {
    /// `prefix + lnClass + inst`, e.g. `CSWI1`, `LLN0`.
    pub fn name(&self) -> String {
        format!("{}{}{}", self.prefix, self.class, self.inst)
    }
}

#[derive(Debug, Default, Clone)]
pub struct DataSet {
    pub name: String,
    pub members: Vec<Fcda>,
    pub at: Offset,
}

#[derive(Debug, Default, Clone, PartialEq, Eq)]
pub struct Fcda {
    pub ld_inst: String,
    pub prefix: String,
    pub ln_class: String,
    pub ln_inst: String,
    pub do_name: String,
    pub da_name: String,
    pub fc: String,
}

#[derive(Debug, Default, Clone)]
pub struct ReportControl {
    pub name: String,
    pub rpt_id: String,
    pub dataset: String,
    pub buffered: bool,
    pub indexed: bool,
    pub max: u32,
    pub conf_rev: u32,
    pub intg_pd: u32,
    pub buf_time: u32,
    pub at: Offset,
}

impl ReportControl {
    /// The instance names an IED serves: `name01`, `name02`, … when
    /// indexed, else `name`.
    pub fn instances(&self) -> Vec<String> {
        if self.indexed {
            (1..=self.max.max(1))
                .map(|i| format!("{}{i:02}", self.name))
                .collect()
        } else {
            vec![self.name.clone()]
        }
    }
}

#[derive(Debug, Default, Clone)]
pub struct Templates {
    pub ln_types: HashMap<String, LnType>,
    pub do_types: HashMap<String, DoType>,
    pub da_types: HashMap<String, Vec<Attr>>,
    pub enum_types: HashMap<String, Vec<(i64, String)>>,
}

#[derive(Debug, Default, Clone)]
pub struct LnType {
    pub class: String,
    /// Data objects: name, DOType id.
    pub dos: Vec<(String, String)>,
    pub at: Offset,
}

#[derive(Debug, Default, Clone)]
pub struct DoType {
    pub cdc: String,
    pub children: Vec<DoChild>,
    pub at: Offset,
}

#[derive(Debug, Clone)]
pub enum DoChild {
    /// A sub data object: name, DOType id.
    Sdo(String, String),
    Da(Attr),
}

/// A data attribute (`DA`) or a basic data attribute of a struct (`BDA`).
#[derive(Debug, Default, Clone)]
pub struct Attr {
    pub name: String,
    /// Functional constraint (DAs only; BDAs inherit their DA's).
    pub fc: String,
    pub b_type: String,
    /// The DAType or EnumType id, for `Struct` and `Enum`.
    pub type_id: String,
    pub count: u32,
    /// A `Val` in the type.
    pub value: Option<String>,
}

/// What a reference resolves to in the templates.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Resolved {
    DataObject {
        cdc: String,
    },
    Attribute {
        b_type: String,
        fc: String,
        type_id: String,
    },
}

impl Templates {
    /// Follows `path` (`DO`, `SDO`…, `DA`, `BDA`…) from an LNodeType.
    /// `fc` restricts the data attributes considered.
    pub fn resolve(
        &self,
        ln_type: &str,
        path: &[&str],
        fc: Option<&str>,
    ) -> Result<Resolved, String> {
        let ln = self
            .ln_types
            .get(ln_type)
            .ok_or_else(|| format!("no LNodeType '{ln_type}'"))?;
        let (first, rest) = path.split_first().ok_or("an empty reference")?;
        let do_type = ln
            .dos
            .iter()
            .find(|(n, _)| n == first)
            .map(|(_, t)| t)
            .ok_or_else(|| format!("{} has no data object '{first}'", ln.class))?;
        let mut current = self
            .do_types
            .get(do_type)
            .ok_or_else(|| format!("no DOType '{do_type}'"))?;
        let mut rest = rest;
        loop {
            let Some((name, tail)) = rest.split_first() else {
                return Ok(Resolved::DataObject {
                    cdc: current.cdc.clone(),
                });
            };
            let child = current.children.iter().find(|c| match c {
                DoChild::Sdo(n, _) => n == name,
                DoChild::Da(a) => &a.name == name && fc.is_none_or(|f| a.fc == f),
            });
            match child {
                Some(DoChild::Sdo(_, t)) => {
                    current = self
                        .do_types
                        .get(t)
                        .ok_or_else(|| format!("no DOType '{t}'"))?;
                    rest = tail;
                }
                Some(DoChild::Da(a)) => return self.resolve_attr(a, tail, &a.fc),
                None => {
                    return Err(match fc {
                        Some(f) => format!(
                            "{} ({}) has no '{name}' with FC {f}",
                            path.join("."),
                            current.cdc
                        ),
                        None => format!("{} ({}) has no '{name}'", path.join("."), current.cdc),
                    })
                }
            }
        }
    }

    fn resolve_attr(&self, a: &Attr, path: &[&str], fc: &str) -> Result<Resolved, String> {
        let Some((name, tail)) = path.split_first() else {
            return Ok(Resolved::Attribute {
                b_type: a.b_type.clone(),
                fc: fc.to_string(),
                type_id: a.type_id.clone(),
            });
        };
        let bdas = self
            .da_types
            .get(&a.type_id)
            .ok_or_else(|| format!("'{}' is a {}, with no component '{name}'", a.name, a.b_type))?;
        let b = bdas
            .iter()
            .find(|b| &b.name == name)
            .ok_or_else(|| format!("'{}' has no component '{name}'", a.name))?;
        self.resolve_attr(b, tail, fc)
    }
}
