//! From an IED in an SCL file to a gridscada tag file: one tag per data
//! object (or sub data object, e.g. a WYE's phases) that carries a value a
//! SCADA uses (`stVal`, `general`, `mag`, `cVal`, `actVal`, `mxVal`,
//! `valWTr`, `instMag`), with its type, its states (enumerations, double
//! points), its units (`SIUnit` and `multiplier`) and scaling (`sVC`), and
//! for a controllable object its `ctlModel`; and one report control block
//! per dataset, so the statuses and measurands arrive by report.

use std::collections::BTreeMap;
use std::fmt::Write;

use crate::model::*;

/// One tag to write.
#[derive(Debug, Clone, PartialEq)]
pub struct ImportedTag {
    pub name: String,
    /// The logical device's instance and the logical node the tag is in.
    pub ld_inst: String,
    pub ln: String,
    pub description: String,
    /// `LD/LN.DO[.SDO].DA[.BDA]`.
    pub reference: String,
    /// The data object it is in, `LD/LN.DO[.SDO]`: what a control operates.
    pub object: String,
    pub fc: String,
    pub data_type: &'static str,
    pub units: String,
    pub states: BTreeMap<i64, String>,
    /// For a controllable object: its control model.
    pub ctl_model: Option<String>,
    pub scale: f64,
    pub offset: f64,
}

/// A report control block to enable, and its dataset.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ImportedReport {
    pub rcb: String,
    pub dataset: String,
}

/// An IED as a gridscada device with its tags.
#[derive(Debug, Clone, PartialEq)]
pub struct Imported {
    pub ied: String,
    pub description: String,
    pub address: String,
    pub addressing: Address,
    pub tags: Vec<ImportedTag>,
    pub reports: Vec<ImportedReport>,
}

/// Value attributes a SCADA reads, in order of preference, with their FC
/// and the path below them to the number.
const VALUE_ATTRIBUTES: [(&str, &str); 8] = [
    ("stVal", "ST"),
    ("general", "ST"),
    ("actVal", "ST"),
    ("mag", "MX"),
    ("cVal", "MX"),
    ("mxVal", "MX"),
    ("valWTr", "ST"),
    ("instMag", "MX"),
];

/// The tags, reports and address of `ied`.
pub fn import(scl: &Scl, ied: &Ied) -> Imported {
    let t = &scl.templates;
    let mut tags = Vec::new();
    let mut reports = Vec::new();
    let mut reported_datasets = Vec::new();
    for ld in &ied.ldevices {
        let ld_name = ld.name(&ied.name);
        for ln in &ld.lns {
            let ln_name = ln.name();
            let Some(ln_type) = t.ln_types.get(&ln.ln_type) else {
                continue;
            };
            for (do_name, do_type) in &ln_type.dos {
                walk(
                    t,
                    ied,
                    ld,
                    &ld_name,
                    ln,
                    &ln_name,
                    &[do_name.as_str()],
                    do_type,
                    &mut tags,
                );
            }
            // One RCB per dataset, buffered first: the others are other clients'.
            let mut rcbs: Vec<&ReportControl> = ln.reports.iter().collect();
            rcbs.sort_by_key(|r| !r.buffered);
            for r in rcbs {
                if r.dataset.is_empty()
                    || reported_datasets.contains(&(
                        ld_name.clone(),
                        ln_name.clone(),
                        r.dataset.clone(),
                    ))
                {
                    continue;
                }
                reported_datasets.push((ld_name.clone(), ln_name.clone(), r.dataset.clone()));
                let instance = r.instances().into_iter().next().unwrap_or_default();
                reports.push(ImportedReport {
                    rcb: format!(
                        "{ld_name}/{ln_name}.{}.{instance}",
                        if r.buffered { "BR" } else { "RP" }
                    ),
                    dataset: format!("{ld_name}/{ln_name}.{}", r.dataset),
                });
            }
        }
    }
    let addressing = scl.addresses.get(&ied.name).cloned().unwrap_or_default();
    let address = format!(
        "{}:{}",
        addressing.ip.clone().unwrap_or_else(|| "127.0.0.1".into()),
        addressing.port.unwrap_or(102)
    );
    let description = [
        ied.manufacturer.as_str(),
        ied.ied_type.as_str(),
        ied.desc.as_str(),
    ]
    .iter()
    .filter(|s| !s.is_empty())
    .copied()
    .collect::<Vec<_>>()
    .join(" ");
    Imported {
        ied: ied.name.clone(),
        description,
        address,
        addressing,
        tags,
        reports,
    }
}

#[allow(clippy::too_many_arguments)]
fn walk(
    t: &Templates,
    ied: &Ied,
    ld: &LDevice,
    ld_name: &str,
    ln: &Ln,
    ln_name: &str,
    path: &[&str],
    do_type_id: &str,
    out: &mut Vec<ImportedTag>,
) {
    let Some(do_type) = t.do_types.get(do_type_id) else {
        return;
    };
    if path.len() > 6 {
        return;
    }
    let das: Vec<&Attr> = do_type
        .children
        .iter()
        .filter_map(|c| {
            if let DoChild::Da(a) = c {
                Some(a)
            } else {
                None
            }
        })
        .collect();
    let value = VALUE_ATTRIBUTES.iter().find_map(|(name, fc)| {
        das.iter()
            .find(|a| a.name == *name && a.fc == *fc)
            .map(|a| (*a, *fc))
    });
    if let Some((attr, fc)) = value {
        if let Some((leaf_path, leaf)) = leaf_of(t, attr) {
            let do_path = path.join(".");
            let key = |suffix: &str| ln.values.get(&format!("{do_path}.{suffix}")).cloned();
            let (data_type, mut states) = tag_type(t, leaf, path.first().copied().unwrap_or(""));
            if data_type.is_empty() {
                return;
            }
            let units = units(&key("units.SIUnit"), &key("units.multiplier"));
            let integer_mag = leaf_path.last().is_some_and(|l| l == "i");
            let (scale, offset) = if integer_mag {
                (
                    key("sVC.scaleFactor")
                        .and_then(|v| v.parse().ok())
                        .unwrap_or(1.0),
                    key("sVC.offset")
                        .and_then(|v| v.parse().ok())
                        .unwrap_or(0.0),
                )
            } else {
                (1.0, 0.0)
            };
            let controllable = das.iter().any(|a| a.name == "Oper" && a.fc == "CO");
            let ctl_model = if controllable {
                let declared = key("ctlModel").or_else(|| {
                    das.iter()
                        .find(|a| a.name == "ctlModel")
                        .and_then(|a| a.value.clone())
                });
                declared.map(|m| {
                    ctl_model_name(t, das.iter().find(|a| a.name == "ctlModel").copied(), &m)
                })
            } else {
                None
            };
            // A switch's position is a bool (closed = true, the way a
            // breaker symbol shows it; intermediate and bad positions become
            // the quality); any other double point keeps its four states.
            let data_type = if leaf.b_type == "Dbpos" && path.first() == Some(&"Pos") {
                states = [(0, "OPEN"), (1, "CLOSED")]
                    .into_iter()
                    .map(|(k, v)| (k, v.to_string()))
                    .collect();
                "bool"
            } else {
                if leaf.b_type == "Dbpos" {
                    states = dbpos_states();
                }
                data_type
            };
            let object = format!("{ld_name}/{ln_name}.{do_path}");
            let mut reference = format!("{object}.{}", attr.name);
            for p in &leaf_path {
                reference.push('.');
                reference.push_str(p);
            }
            let desc = ln
                .values
                .get(&format!("{do_path}#desc"))
                .cloned()
                .filter(|d| !d.is_empty())
                .unwrap_or_else(|| format!("{ln_name} {do_path} ({})", do_type.cdc));
            out.push(ImportedTag {
                name: tag_name(&[&ied.name, &ld.inst, ln_name, &do_path]),
                ld_inst: ld.inst.clone(),
                ln: ln_name.to_string(),
                description: desc,
                reference,
                object,
                fc: fc.to_string(),
                data_type,
                units,
                states,
                ctl_model: ctl_model.filter(|m| m != "status-only"),
                scale,
                offset,
            });
            return;
        }
    }
    for c in &do_type.children {
        if let DoChild::Sdo(name, ty) = c {
            let mut p = path.to_vec();
            p.push(name);
            walk(t, ied, ld, ld_name, ln, ln_name, &p, ty, out);
        }
    }
}

/// The tags of each bay of the SCL's Substation section that has any of
/// `imported`'s logical nodes, in the bay's order; when the file has no
/// bays for them, one group per IED. Each group: a name and its tags.
pub fn bays<'a>(
    scl: &Scl,
    imported: &'a [Imported],
) -> Vec<(String, Vec<(&'a Imported, &'a ImportedTag)>)> {
    let mut out = Vec::new();
    let mut placed = std::collections::HashSet::new();
    for bay in &scl.bays {
        let mut tags = Vec::new();
        for l in &bay.lnodes {
            let Some(imp) = imported.iter().find(|i| i.ied == l.ied) else {
                continue;
            };
            for t in imp
                .tags
                .iter()
                .filter(|t| t.ld_inst == l.ld_inst && t.ln == l.ln_name())
            {
                if placed.insert(t.name.as_str()) {
                    tags.push((imp, t));
                }
            }
        }
        if !tags.is_empty() {
            let name = [
                bay.substation.as_str(),
                bay.voltage_level.as_str(),
                bay.name.as_str(),
            ]
            .iter()
            .filter(|s| !s.is_empty())
            .copied()
            .collect::<Vec<_>>()
            .join(" / ");
            out.push((name, tags));
        }
    }
    if out.is_empty() {
        for imp in imported {
            let tags: Vec<_> = imp.tags.iter().map(|t| (imp, t)).collect();
            if !tags.is_empty() {
                out.push((imp.ied.clone(), tags));
            }
        }
    }
    out
}

/// Below a value attribute, the path to its number: `mag.f`, `cVal.mag.f`,
/// `mxVal.i`, `valWTr.posVal`.
fn leaf_of<'a>(t: &'a Templates, a: &'a Attr) -> Option<(Vec<String>, &'a Attr)> {
    if a.b_type != "Struct" {
        return Some((Vec::new(), a));
    }
    let bdas = t.da_types.get(&a.type_id)?;
    for want in ["f", "i", "posVal", "mag"] {
        if let Some(b) = bdas.iter().find(|b| b.name == want) {
            let (mut rest, leaf) = leaf_of(t, b)?;
            rest.insert(0, b.name.clone());
            return Some((rest, leaf));
        }
    }
    None
}

fn tag_type(t: &Templates, a: &Attr, _do_name: &str) -> (&'static str, BTreeMap<i64, String>) {
    let none = BTreeMap::new();
    match a.b_type.as_str() {
        "BOOLEAN" => ("bool", none),
        "Dbpos" => ("u16", none),
        "Tcmd" => ("u16", none),
        "Enum" => (
            "i32",
            t.enum_types
                .get(&a.type_id)
                .map(|v| v.iter().cloned().collect())
                .unwrap_or_default(),
        ),
        "INT8" | "INT16" | "INT32" => ("i32", none),
        "INT64" => ("i64", none),
        "INT8U" | "INT16U" | "INT24U" | "INT32U" => ("u32", none),
        "FLOAT32" => ("f32", none),
        "FLOAT64" => ("f64", none),
        b if b.starts_with("VisString") || b.starts_with("Unicode") => ("string", none),
        _ => ("", none),
    }
}

fn dbpos_states() -> BTreeMap<i64, String> {
    [(0, "INTERMEDIATE"), (1, "OFF"), (2, "ON"), (3, "BAD")]
        .into_iter()
        .map(|(k, v)| (k, v.to_string()))
        .collect()
}

/// The control model's name, from an SCL `Val` that is the enumeration's
/// literal or its ordinal.
fn ctl_model_name(t: &Templates, attr: Option<&Attr>, val: &str) -> String {
    const NAMES: [&str; 5] = [
        "status-only",
        "direct-with-normal-security",
        "sbo-with-normal-security",
        "direct-with-enhanced-security",
        "sbo-with-enhanced-security",
    ];
    let val = val.trim();
    if let Ok(n) = val.parse::<usize>() {
        if let Some(n) = NAMES.get(n) {
            return n.to_string();
        }
    }
    if let Some(a) = attr {
        if let Some(lits) = t.enum_types.get(&a.type_id) {
            if let Some((ord, _)) = lits.iter().find(|(_, l)| l == val) {
                if let Some(n) = usize::try_from(*ord).ok().and_then(|o| NAMES.get(o)) {
                    return n.to_string();
                }
            }
        }
    }
    val.to_string()
}

/// `SIUnit` and `multiplier` (literals or ordinals) as a unit, e.g. `kW`.
pub fn units(si: &Option<String>, multiplier: &Option<String>) -> String {
    let Some(si) = si.as_deref().map(str::trim).filter(|s| !s.is_empty()) else {
        return String::new();
    };
    let unit = match si.parse::<i64>() {
        Ok(n) => si_unit(n).to_string(),
        Err(_) => match si {
            "Watts" => "W".to_string(),
            "none" => String::new(),
            s => s.to_string(),
        },
    };
    let prefix = match multiplier.as_deref().map(str::trim).unwrap_or("") {
        "" | "0" => "",
        m => match m.parse::<i64>() {
            Ok(n) => match n {
                -24 => "y",
                -21 => "z",
                -18 => "a",
                -15 => "f",
                -12 => "p",
                -9 => "n",
                -6 => "µ",
                -3 => "m",
                -2 => "c",
                -1 => "d",
                1 => "da",
                2 => "h",
                3 => "k",
                6 => "M",
                9 => "G",
                12 => "T",
                15 => "P",
                18 => "E",
                21 => "Z",
                24 => "Y",
                _ => "",
            },
            Err(_) => {
                if m == "u" {
                    "µ"
                } else {
                    return format!("{m}{unit}");
                }
            }
        },
    };
    format!("{prefix}{unit}")
}

fn si_unit(n: i64) -> &'static str {
    match n {
        1 => "",
        2 => "m",
        3 => "kg",
        4 => "s",
        5 => "A",
        6 => "K",
        7 => "mol",
        8 => "cd",
        9 => "deg",
        10 => "rad",
        11 => "sr",
        21 => "Gy",
        22 => "Bq",
        23 => "°C",
        24 => "Sv",
        25 => "F",
        26 => "C",
        27 => "S",
        28 => "H",
        29 => "V",
        30 => "ohm",
        31 => "J",
        32 => "N",
        33 => "Hz",
        34 => "lx",
        35 => "Lm",
        36 => "Wb",
        37 => "T",
        38 => "W",
        39 => "Pa",
        41 => "m²",
        42 => "m³",
        43 => "m/s",
        44 => "m/s²",
        45 => "m³/s",
        46 => "m/m³",
        47 => "M",
        48 => "kg/m³",
        49 => "m²/s",
        50 => "W/m K",
        51 => "J/K",
        52 => "ppm",
        53 => "1/s",
        54 => "rad/s",
        55 => "W/m²",
        56 => "J/m²",
        57 => "S/m",
        58 => "K/s",
        59 => "Pa/s",
        60 => "J/kg K",
        61 => "VA",
        62 => "W",
        63 => "VAr",
        64 => "phi",
        65 => "cos(phi)",
        66 => "Vs",
        67 => "V²",
        68 => "As",
        69 => "A²",
        70 => "A²t",
        71 => "VAh",
        72 => "Wh",
        73 => "VArh",
        74 => "V/Hz",
        75 => "Hz/s",
        76 => "char",
        77 => "char/s",
        78 => "kgm²",
        79 => "dB",
        80 => "J/Wh",
        81 => "W/s",
        82 => "l/s",
        83 => "dBm",
        84 => "h",
        85 => "min",
        86 => "Ohm/m",
        87 => "percent/s",
        _ => "",
    }
}

/// A tag name from its parts: letters, digits, `_` and `-`, dot-joined.
fn tag_name(parts: &[&str]) -> String {
    parts
        .iter()
        .filter(|p| !p.is_empty())
        .map(|p| {
            p.chars()
                .map(|c| {
                    if c.is_ascii_alphanumeric() || c == '_' || c == '-' || c == '.' {
                        c
                    } else {
                        '_'
                    }
                })
                .collect::<String>()
        })
        .collect::<Vec<_>>()
        .join(".")
}

/// A TOML basic string.
fn quote(s: &str) -> String {
    let mut out = String::with_capacity(s.len() + 2);
    out.push('"');
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            '\n' => out.push_str("\\n"),
            '\t' => out.push_str("\\t"),
            c if c.is_control() => {
                let _ = write!(out, "\\u{:04X}", c as u32);
            }
            c => out.push(c),
        }
    }
    out.push('"');
    out
}

/// The tag file for `imp`: its device, reports and tags. `scl` is the SCL
/// file as the tag file should name it (relative to the tag file).
pub fn render(imp: &Imported, scl: &str, write_role: &str) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "# IED {} imported from {} by `gridscada scl import`.",
        imp.ied, scl
    );
    let _ = writeln!(s, "# One tag per data object a SCADA reads; `gridscada check` validates them against the SCL.");
    let _ = writeln!(
        s,
        "# Controllable objects are writable by role {write_role} and up; review before use.\n"
    );
    let _ = writeln!(s, "[[device]]");
    let _ = writeln!(s, "name = {}", quote(&imp.ied));
    if !imp.description.is_empty() {
        let _ = writeln!(s, "description = {}", quote(&imp.description));
    }
    let _ = writeln!(s, "protocol = \"iec61850\"");
    let _ = writeln!(s, "address = {}", quote(&imp.address));
    let _ = writeln!(s, "scan_ms = 1000\ntimeout_ms = 3000\n");
    let _ = writeln!(s, "[device.iec61850]");
    let _ = writeln!(s, "ied = {}", quote(&imp.ied));
    let _ = writeln!(s, "scl = {}", quote(scl));
    let a = &imp.addressing;
    if let Some(t) = &a.ap_title {
        let _ = writeln!(s, "remote_ap_title = {}", quote(t));
    }
    if let Some(q) = a.ae_qualifier {
        let _ = writeln!(s, "remote_ae_qualifier = {q}");
    }
    for (field, v) in [
        ("remote_psel", &a.psel),
        ("remote_ssel", &a.ssel),
        ("remote_tsel", &a.tsel),
    ] {
        if let Some(v) = v {
            let _ = writeln!(s, "{field} = {}", quote(v));
        }
    }
    for r in &imp.reports {
        let _ = writeln!(s, "\n[[device.iec61850.report]]");
        let _ = writeln!(s, "rcb = {}", quote(&r.rcb));
        let _ = writeln!(s, "dataset = {}", quote(&r.dataset));
    }
    for t in &imp.tags {
        let _ = writeln!(s, "\n[[tag]]");
        let _ = writeln!(s, "name = {}", quote(&t.name));
        let _ = writeln!(s, "description = {}", quote(&t.description));
        let _ = writeln!(s, "device = {}", quote(&imp.ied));
        let _ = writeln!(s, "type = \"{}\"", t.data_type);
        if !t.units.is_empty() {
            let _ = writeln!(s, "units = {}", quote(&t.units));
        }
        if t.scale != 1.0 {
            let _ = writeln!(s, "scale = {}", t.scale);
        }
        if t.offset != 0.0 {
            let _ = writeln!(s, "offset = {}", t.offset);
        }
        if !t.states.is_empty() {
            let key = |k: i64| match (t.data_type, k) {
                ("bool", 0) => "false".to_string(),
                ("bool", _) => "true".to_string(),
                (_, k) => k.to_string(),
            };
            let states: Vec<String> = t
                .states
                .iter()
                .map(|(k, v)| format!("{} = {}", key(*k), quote(v)))
                .collect();
            let _ = writeln!(s, "states = {{ {} }}", states.join(", "));
        }
        let mut point = format!("ref = {}, fc = {}", quote(&t.reference), quote(&t.fc));
        if let Some(m) = &t.ctl_model {
            let _ = writeln!(s, "writable = true");
            let _ = writeln!(s, "write_role = {}", quote(write_role));
            let _ = write!(
                point,
                ", control = {}, ctl_model = {}",
                quote(&t.object),
                quote(m)
            );
        }
        let _ = writeln!(s, "iec61850 = {{ {point} }}");
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn units_from_literals_and_ordinals() {
        assert_eq!(units(&Some("W".into()), &Some("k".into())), "kW");
        assert_eq!(units(&Some("38".into()), &Some("3".into())), "kW");
        assert_eq!(units(&Some("V".into()), &Some(String::new())), "V");
        assert_eq!(units(&None, &Some("k".into())), "");
        assert_eq!(quote("a\"b\\"), "\"a\\\"b\\\\\"");
    }
}
