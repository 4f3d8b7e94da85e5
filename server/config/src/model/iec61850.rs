//! IEC 61850 (MMS, IEC 61850-8-1): an IED's association settings and the
//! report control blocks gridscada enables (`[device.iec61850]`), and a
//! tag's data attribute (`iec61850 = { ref = "IED1LD0/XCBR1.Pos.stVal",
//! fc = "ST" }`).
//!
//! References are the standard's object references: the logical device
//! as the IED names it on the wire (IED name + LD instance, e.g.
//! `IED1LD0`), then `LN.DO[.SDO].DA`. A tag carries one value attribute
//! (`stVal`, `mag.f`, `actVal`, …); the quality `q` and time `t` of the
//! same data object become the sample's quality and timestamp.

use serde::{Deserialize, Serialize};
use serde_spanned::Spanned;

use super::DataType;

/// `[device.iec61850]`: one IED and the association toward it.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Iec61850DeviceConfig {
    /// The IED's name in its SCL file (what `scl import` took the tags from).
    #[serde(default)]
    pub ied: Option<Spanned<String>>,
    /// The SCL file the tags were imported from, relative to the tag file;
    /// `check` then validates the tags against it.
    #[serde(default)]
    pub scl: Option<Spanned<String>>,
    /// The IED's ACSE AP title (dotted object identifier) and AE qualifier.
    #[serde(default = "default_remote_ap_title")]
    pub remote_ap_title: Spanned<String>,
    #[serde(default = "default_ae_qualifier")]
    pub remote_ae_qualifier: Spanned<i64>,
    /// Ours.
    #[serde(default = "default_local_ap_title")]
    pub local_ap_title: Spanned<String>,
    #[serde(default = "default_ae_qualifier")]
    pub local_ae_qualifier: Spanned<i64>,
    /// Transport, session and presentation selectors of the IED, in hex.
    #[serde(default = "default_tsel")]
    pub remote_tsel: Spanned<String>,
    #[serde(default = "default_ssel")]
    pub remote_ssel: Spanned<String>,
    #[serde(default = "default_psel")]
    pub remote_psel: Spanned<String>,
    /// How long the IED may take to answer a request, ms.
    #[serde(default = "default_response_timeout")]
    pub response_timeout_ms: Spanned<u64>,
    /// How long a control may take from Oper to its CommandTermination
    /// (enhanced security) or to the status showing the commanded value.
    #[serde(default = "default_command_timeout")]
    pub command_timeout_s: Spanned<f64>,
    /// The originator category gridscada's controls carry (`orCat`).
    #[serde(default)]
    pub originator_category: Iec61850OrCat,
    /// Report control blocks to enable, with their datasets; tags whose
    /// data is in none of them are polled at the device's `scan_ms`.
    #[serde(default, rename = "report")]
    pub reports: Vec<Iec61850ReportConfig>,
}

impl Default for Iec61850DeviceConfig {
    fn default() -> Self {
        Iec61850DeviceConfig {
            ied: None,
            scl: None,
            remote_ap_title: default_remote_ap_title(),
            remote_ae_qualifier: default_ae_qualifier(),
            local_ap_title: default_local_ap_title(),
            local_ae_qualifier: default_ae_qualifier(),
            remote_tsel: default_tsel(),
            remote_ssel: default_ssel(),
            remote_psel: default_psel(),
            response_timeout_ms: default_response_timeout(),
            command_timeout_s: default_command_timeout(),
            originator_category: Iec61850OrCat::default(),
            reports: Vec::new(),
        }
    }
}

fn default_remote_ap_title() -> Spanned<String> {
    Spanned::new(0..0, "1.1.1.999".into())
}
fn default_local_ap_title() -> Spanned<String> {
    Spanned::new(0..0, "1.1.1.999.1".into())
}
fn default_ae_qualifier() -> Spanned<i64> {
    Spanned::new(0..0, 12)
}
fn default_tsel() -> Spanned<String> {
    Spanned::new(0..0, "0001".into())
}
fn default_ssel() -> Spanned<String> {
    Spanned::new(0..0, "0001".into())
}
fn default_psel() -> Spanned<String> {
    Spanned::new(0..0, "00000001".into())
}
fn default_response_timeout() -> Spanned<u64> {
    Spanned::new(0..0, 5000)
}
fn default_command_timeout() -> Spanned<f64> {
    Spanned::new(0..0, 10.0)
}
fn yes() -> bool {
    true
}

/// The originator category (`orCat`, IEC 61850-7-3) of our controls.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Iec61850OrCat {
    BayControl,
    StationControl,
    #[default]
    RemoteControl,
    AutomaticBay,
    AutomaticStation,
    AutomaticRemote,
    Maintenance,
    Process,
}

impl Iec61850OrCat {
    /// The enumeration's value on the wire.
    pub fn code(self) -> i64 {
        match self {
            Iec61850OrCat::BayControl => 1,
            Iec61850OrCat::StationControl => 2,
            Iec61850OrCat::RemoteControl => 3,
            Iec61850OrCat::AutomaticBay => 4,
            Iec61850OrCat::AutomaticStation => 5,
            Iec61850OrCat::AutomaticRemote => 6,
            Iec61850OrCat::Maintenance => 7,
            Iec61850OrCat::Process => 8,
        }
    }
}

/// `[[device.iec61850.report]]`: one report control block to enable.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Iec61850ReportConfig {
    /// The RCB's reference: `LD/LN.BR.name` (buffered) or `LD/LN.RP.name`
    /// (unbuffered); an indexed instance (`brcb0101`) as the IED names it.
    pub rcb: Spanned<String>,
    /// The dataset the RCB must report (`LD/LN.name`), checked at enable.
    #[serde(default)]
    pub dataset: Option<Spanned<String>>,
    /// Integrity period to set (`IntgPd`), seconds; absent keeps the IED's.
    #[serde(default)]
    pub integrity_period_s: Option<Spanned<f64>>,
    /// Ask for a general interrogation after enabling.
    #[serde(default = "yes")]
    pub gi: bool,
    /// Buffer time to set (`BufTm`), ms; absent keeps the IED's.
    #[serde(default)]
    pub buffer_time_ms: Option<Spanned<u32>>,
}

/// IEC 61850 functional constraints a tag can read.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Deserialize, Serialize)]
#[serde(rename_all = "UPPERCASE")]
pub enum Fc {
    /// Status information.
    St,
    /// Measurands.
    Mx,
    /// Setpoints.
    Sp,
    /// Substituted values.
    Sv,
    /// Configuration.
    Cf,
    /// Description.
    Dc,
    /// Setting group.
    Sg,
    /// Setting group editable.
    Se,
    /// Extended definition.
    Ex,
    /// Blocking.
    Bl,
    /// Operate received.
    Or,
}

impl Fc {
    pub fn label(self) -> &'static str {
        match self {
            Fc::St => "ST",
            Fc::Mx => "MX",
            Fc::Sp => "SP",
            Fc::Sv => "SV",
            Fc::Cf => "CF",
            Fc::Dc => "DC",
            Fc::Sg => "SG",
            Fc::Se => "SE",
            Fc::Ex => "EX",
            Fc::Bl => "BL",
            Fc::Or => "OR",
        }
    }
}

/// The control model of a controllable object (`ctlModel`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Deserialize, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum CtlModel {
    StatusOnly,
    DirectWithNormalSecurity,
    SboWithNormalSecurity,
    DirectWithEnhancedSecurity,
    SboWithEnhancedSecurity,
}

impl CtlModel {
    pub fn from_code(n: i64) -> Option<CtlModel> {
        Some(match n {
            0 => CtlModel::StatusOnly,
            1 => CtlModel::DirectWithNormalSecurity,
            2 => CtlModel::SboWithNormalSecurity,
            3 => CtlModel::DirectWithEnhancedSecurity,
            4 => CtlModel::SboWithEnhancedSecurity,
            _ => return None,
        })
    }
    pub fn label(self) -> &'static str {
        match self {
            CtlModel::StatusOnly => "status-only",
            CtlModel::DirectWithNormalSecurity => "direct-with-normal-security",
            CtlModel::SboWithNormalSecurity => "sbo-with-normal-security",
            CtlModel::DirectWithEnhancedSecurity => "direct-with-enhanced-security",
            CtlModel::SboWithEnhancedSecurity => "sbo-with-enhanced-security",
        }
    }
    pub fn is_sbo(self) -> bool {
        matches!(
            self,
            CtlModel::SboWithNormalSecurity | CtlModel::SboWithEnhancedSecurity
        )
    }
    pub fn is_enhanced(self) -> bool {
        matches!(
            self,
            CtlModel::DirectWithEnhancedSecurity | CtlModel::SboWithEnhancedSecurity
        )
    }
}

/// `iec61850 = { ref = "…", fc = "ST", … }`: where a tag's value is.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Iec61850TagConfig {
    /// The value attribute: `LD/LN.DO[.SDO].DA[.DA]`.
    #[serde(rename = "ref")]
    pub reference: Spanned<String>,
    pub fc: Spanned<Fc>,
    /// For a writable tag: the controllable data object (`LD/LN.DO`) the
    /// write operates; by default the data object of `ref`.
    #[serde(default)]
    pub control: Option<Spanned<String>>,
    /// The object's control model; absent, it is read from the IED
    /// (`ctlModel`, FC CF) at every association.
    #[serde(default)]
    pub ctl_model: Option<Spanned<CtlModel>>,
    /// Ask the IED to check interlocks (`Check`, bit 1) and synchronism
    /// (bit 0) before it operates.
    #[serde(default)]
    pub interlock_check: bool,
    #[serde(default)]
    pub synchro_check: bool,
    /// Send controls in test mode (`Test` = true).
    #[serde(default)]
    pub test: bool,
}

/// A checked object reference: logical device, logical node, and the
/// names below it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ObjectRef<'a> {
    pub ld: &'a str,
    pub ln: &'a str,
    pub path: Vec<&'a str>,
}

impl<'a> ObjectRef<'a> {
    /// Parses `LD/LN.DO.DA…`; the error says what is wrong.
    pub fn parse(reference: &'a str) -> Result<ObjectRef<'a>, String> {
        let (ld, rest) = reference
            .split_once('/')
            .ok_or_else(|| format!("'{reference}' is not an object reference (LD/LN.DO.DA)"))?;
        let mut parts = rest.split('.');
        let ln = parts.next().unwrap_or("");
        let path: Vec<&str> = parts.collect();
        let bad = |what: &str, name: &str| {
            format!("'{reference}': {what} '{name}' (names are letters, digits and _, at most 64)")
        };
        let ok = |s: &str| {
            !s.is_empty()
                && s.len() <= 64
                && s.chars()
                    .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '(' || c == ')')
        };
        if !ok(ld) {
            return Err(bad("logical device", ld));
        }
        if !ok(ln) {
            return Err(bad("logical node", ln));
        }
        if let Some(p) = path.iter().find(|p| !ok(p)) {
            return Err(bad("name", p));
        }
        Ok(ObjectRef { ld, ln, path })
    }

    /// The MMS item id with functional constraint `fc`: `LN$FC$DO$DA`.
    pub fn mms_item(&self, fc: &str) -> String {
        let mut item = format!("{}${fc}", self.ln);
        for p in &self.path {
            item.push('$');
            item.push_str(p);
        }
        item
    }
}

/// Whether a tag of type `ty` can carry an IEC 61850 value attribute.
pub fn iec61850_carries(ty: DataType) -> bool {
    ty != DataType::DateTime
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn references_parse_and_map_to_mms_items() {
        let r = ObjectRef::parse("IED1LD0/MMXU1.PhV.phsA.cVal.mag.f").unwrap();
        assert_eq!((r.ld, r.ln), ("IED1LD0", "MMXU1"));
        assert_eq!(r.mms_item("MX"), "MMXU1$MX$PhV$phsA$cVal$mag$f");
        assert!(ObjectRef::parse("MMXU1.PhV")
            .unwrap_err()
            .contains("not an object reference"));
        assert!(ObjectRef::parse("LD0/MMXU1..f")
            .unwrap_err()
            .contains("name ''"));
    }
}
