//! The streaming SCL reader: one pass over the file with a pull parser,
//! keeping only the IEDs asked for, the templates and the addresses, so a
//! substation's SCD of hundreds of IEDs reads in a few megabytes. Errors
//! name the file, line and column, and what is wrong; nothing panics, and
//! nesting, text and element counts are bounded.

use std::io::BufRead;
use std::path::Path;

use quick_xml::events::{BytesStart, Event};
use quick_xml::Reader;

use crate::model::*;

/// What is wrong with an SCL file, and where.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{file}:{line}:{column}: {message}")]
pub struct SclError {
    pub file: String,
    pub line: u64,
    pub column: u64,
    pub message: String,
}

/// Deepest element nesting accepted (SCL needs about 12).
const MAX_DEPTH: usize = 64;
/// Most elements kept from one file (an SCD of 500 IEDs keeps far fewer).
const MAX_KEPT: usize = 20_000_000;
/// Longest text kept for one `Val` or `P`.
const MAX_TEXT: usize = 64 * 1024;

/// Which IEDs to keep: all, or those named.
#[derive(Debug, Clone, Default)]
pub struct Filter {
    pub ieds: Vec<String>,
}

impl Filter {
    fn keeps(&self, ied: &str) -> bool {
        self.ieds.is_empty() || self.ieds.iter().any(|n| n == ied)
    }
}

/// Reads the SCL file at `path`.
pub fn read_path(path: &Path, filter: &Filter) -> Result<Scl, SclError> {
    let name = path.display().to_string();
    let file = std::fs::File::open(path).map_err(|e| SclError {
        file: name.clone(),
        line: 0,
        column: 0,
        message: format!("cannot open: {e}"),
    })?;
    read(std::io::BufReader::with_capacity(64 * 1024, file), filter).map_err(|(offset, message)| {
        let (line, column) = locate(
            std::fs::File::open(path).ok().map(std::io::BufReader::new),
            offset,
        );
        SclError {
            file: name,
            line,
            column,
            message,
        }
    })
}

/// Reads SCL from memory (`name` for the errors).
pub fn read_bytes(name: &str, bytes: &[u8], filter: &Filter) -> Result<Scl, SclError> {
    read(bytes, filter).map_err(|(offset, message)| {
        let (line, column) = locate(Some(bytes), offset);
        SclError {
            file: name.to_string(),
            line,
            column,
            message,
        }
    })
}

/// Line and column (1-based) of octet `offset`.
fn locate<R: BufRead>(source: Option<R>, offset: u64) -> (u64, u64) {
    let Some(mut r) = source else { return (0, 0) };
    let (mut line, mut col, mut pos) = (1u64, 1u64, 0u64);
    loop {
        let buf = match r.fill_buf() {
            Ok(b) if !b.is_empty() => b,
            _ => return (line, col),
        };
        let n = buf.len();
        for &b in buf {
            if pos >= offset {
                return (line, col);
            }
            pos += 1;
            if b == b'\n' {
                line += 1;
                col = 1;
            } else {
                col += 1;
            }
        }
        r.consume(n);
    }
}

type Failure = (u64, String);

/// Where the reader is, by the kept elements open above it.
#[derive(Default)]
struct Cursor {
    ied: Option<Ied>,
    skipping_ied: bool,
    ld: Option<LDevice>,
    ln: Option<Ln>,
    /// DOI / SDI / DAI names down to the current one.
    instance_path: Vec<String>,
    dataset: Option<DataSet>,
    report: Option<ReportControl>,
    ln_type: Option<(String, LnType)>,
    do_type: Option<(String, DoType)>,
    da_type: Option<(String, Vec<Attr>)>,
    enum_type: Option<(String, Vec<(i64, String)>)>,
    enum_ord: Option<i64>,
    /// The DA/BDA whose `Val` is being read.
    in_attr_val: bool,
    connected_ap: Option<String>,
    address_p: Option<String>,
    text: String,
    in_templates: bool,
    substation: Option<String>,
    voltage_level: Option<String>,
    bay: Option<Bay>,
}

fn attr(e: &BytesStart<'_>, name: &str, at: u64) -> Result<Option<String>, Failure> {
    for a in e.attributes() {
        let a = a.map_err(|err| (at, format!("bad attribute: {err}")))?;
        if a.key.as_ref() == name {
            let v = a
                .normalized_value(quick_xml::XmlVersion::Implicit1_0)
                .map_err(|err| (at, format!("attribute {name}: {err}")))?;
            return Ok(Some(v.into_owned()));
        }
    }
    Ok(None)
}

fn required(e: &BytesStart<'_>, element: &str, name: &str, at: u64) -> Result<String, Failure> {
    attr(e, name, at)?.ok_or_else(|| (at, format!("<{element}> without its {name} attribute")))
}

fn opt(e: &BytesStart<'_>, name: &str, at: u64) -> Result<String, Failure> {
    Ok(attr(e, name, at)?.unwrap_or_default())
}

fn number<T: std::str::FromStr>(
    e: &BytesStart<'_>,
    element: &str,
    name: &str,
    at: u64,
    default: T,
) -> Result<T, Failure> {
    match attr(e, name, at)? {
        None => Ok(default),
        Some(v) => v
            .trim()
            .parse()
            .map_err(|_| (at, format!("<{element}> {name}=\"{v}\" is not a number"))),
    }
}

fn boolean(e: &BytesStart<'_>, name: &str, at: u64, default: bool) -> Result<bool, Failure> {
    Ok(match attr(e, name, at)?.as_deref() {
        Some("true") | Some("1") => true,
        Some("false") | Some("0") => false,
        _ => default,
    })
}

fn read<R: BufRead>(source: R, filter: &Filter) -> Result<Scl, Failure> {
    let mut reader = Reader::from_reader(source);
    reader.config_mut().trim_text(true);
    let mut scl = Scl::default();
    let mut c = Cursor::default();
    let mut stack: Vec<Vec<u8>> = Vec::new();
    let mut buf = Vec::new();
    let mut kept: usize = 0;
    let mut saw_root = false;
    loop {
        buf.clear();
        let event = reader
            .read_event_into(&mut buf)
            .map_err(|e| (reader.error_position(), format!("not well-formed XML: {e}")))?;
        let after = reader.buffer_position();
        match event {
            Event::Start(e) | Event::Empty(e) if stack.len() >= MAX_DEPTH => {
                let _ = e;
                return Err((after, format!("elements nested deeper than {MAX_DEPTH}")));
            }
            Event::Start(ref e) | Event::Empty(ref e) => {
                let empty = matches!(event, Event::Empty(_));
                let at = after.saturating_sub(e.len() as u64 + if empty { 3 } else { 2 });
                let name = e.local_name().as_ref().as_bytes().to_vec();
                if stack.is_empty() {
                    if name != b"SCL" {
                        return Err((
                            at,
                            format!(
                                "the root element is <{}>, not <SCL>",
                                String::from_utf8_lossy(&name)
                            ),
                        ));
                    }
                    saw_root = true;
                }
                kept += 1;
                if kept > MAX_KEPT {
                    return Err((
                        at,
                        format!(
                            "more than {MAX_KEPT} elements: not an SCL file this reader accepts"
                        ),
                    ));
                }
                start(&mut scl, &mut c, &name, e, at, filter, &stack)?;
                if empty {
                    end(&mut scl, &mut c, &name, at)?;
                } else {
                    stack.push(name);
                }
            }
            Event::End(_) => {
                let name = stack.pop().unwrap_or_default();
                end(&mut scl, &mut c, &name, after)?;
            }
            Event::Text(t) if wants_text(&c) => {
                push_text(&mut c.text, &t.xml10_content(), after)?;
            }
            Event::GeneralRef(r) if wants_text(&c) => {
                let name = r.xml10_content();
                let s = match name.as_ref() {
                    "amp" => "&".to_string(),
                    "lt" => "<".to_string(),
                    "gt" => ">".to_string(),
                    "quot" => "\"".to_string(),
                    "apos" => "'".to_string(),
                    n => match r.resolve_char_ref() {
                        Ok(Some(ch)) => ch.to_string(),
                        _ => return Err((after, format!("unknown entity &{n};"))),
                    },
                };
                push_text(&mut c.text, &s, after)?;
            }
            Event::CData(t) if wants_text(&c) => {
                push_text(&mut c.text, &t.xml10_content(), after)?;
            }
            Event::Eof => break,
            _ => {}
        }
    }
    if !saw_root {
        return Err((0, "no <SCL> element: not an SCL file".into()));
    }
    if let Some(open) = stack.last() {
        return Err((
            reader.buffer_position(),
            format!("the file ends inside <{}>", String::from_utf8_lossy(open)),
        ));
    }
    Ok(scl)
}

fn wants_text(c: &Cursor) -> bool {
    c.in_attr_val || c.address_p.is_some() || c.enum_ord.is_some()
}

fn push_text(text: &mut String, s: &str, at: u64) -> Result<(), Failure> {
    if text.len() + s.len() > MAX_TEXT {
        return Err((at, format!("a text of more than {MAX_TEXT} octets")));
    }
    text.push_str(s);
    Ok(())
}

fn start(
    scl: &mut Scl,
    c: &mut Cursor,
    name: &[u8],
    e: &BytesStart<'_>,
    at: u64,
    filter: &Filter,
    stack: &[Vec<u8>],
) -> Result<(), Failure> {
    let parent = stack.last().map(|p| p.as_slice()).unwrap_or(b"");
    if c.skipping_ied {
        return Ok(());
    }
    match name {
        b"IED" if parent == b"SCL" => {
            let ied = required(e, "IED", "name", at)?;
            scl.all_ied_names.push(ied.clone());
            if filter.keeps(&ied) {
                c.ied = Some(Ied {
                    name: ied,
                    manufacturer: opt(e, "manufacturer", at)?,
                    ied_type: opt(e, "type", at)?,
                    desc: opt(e, "desc", at)?,
                    ldevices: Vec::new(),
                    at,
                });
            } else {
                c.skipping_ied = true;
            }
        }
        b"LDevice" if c.ied.is_some() => {
            c.ld = Some(LDevice {
                inst: required(e, "LDevice", "inst", at)?,
                ld_name: attr(e, "ldName", at)?,
                desc: opt(e, "desc", at)?,
                lns: Vec::new(),
                at,
            });
        }
        b"LN0" | b"LN" if c.ld.is_some() => {
            let element = if name == b"LN0" { "LN0" } else { "LN" };
            c.ln = Some(Ln {
                prefix: opt(e, "prefix", at)?,
                class: required(e, element, "lnClass", at)?,
                inst: opt(e, "inst", at)?,
                ln_type: required(e, element, "lnType", at)?,
                desc: opt(e, "desc", at)?,
                at,
                ..Ln::default()
            });
        }
        b"DataSet" if c.ln.is_some() => {
            c.dataset = Some(DataSet {
                name: required(e, "DataSet", "name", at)?,
                members: Vec::new(),
                at,
            });
        }
        b"FCDA" if c.dataset.is_some() => {
            let f = Fcda {
                ld_inst: opt(e, "ldInst", at)?,
                prefix: opt(e, "prefix", at)?,
                ln_class: opt(e, "lnClass", at)?,
                ln_inst: opt(e, "lnInst", at)?,
                do_name: opt(e, "doName", at)?,
                da_name: opt(e, "daName", at)?,
                fc: required(e, "FCDA", "fc", at)?,
            };
            if let Some(ds) = c.dataset.as_mut() {
                ds.members.push(f);
            }
        }
        b"ReportControl" if c.ln.is_some() => {
            c.report = Some(ReportControl {
                name: required(e, "ReportControl", "name", at)?,
                rpt_id: opt(e, "rptID", at)?,
                dataset: opt(e, "datSet", at)?,
                buffered: boolean(e, "buffered", at, false)?,
                indexed: boolean(e, "indexed", at, true)?,
                max: 1,
                conf_rev: number(e, "ReportControl", "confRev", at, 0)?,
                intg_pd: number(e, "ReportControl", "intgPd", at, 0)?,
                buf_time: number(e, "ReportControl", "bufTime", at, 0)?,
                at,
            });
        }
        b"RptEnabled" if c.report.is_some() => {
            let max = number(e, "RptEnabled", "max", at, 1u32)?;
            if let Some(r) = c.report.as_mut() {
                r.max = max.clamp(1, 99);
            }
        }
        b"DOI" | b"SDI" | b"DAI" if c.ln.is_some() => {
            let element = String::from_utf8_lossy(name).to_string();
            let n = required(e, &element, "name", at)?;
            let ix = attr(e, "ix", at)?;
            c.instance_path.push(match ix {
                Some(i) => format!("{n}({i})"),
                None => n,
            });
            if name == b"DOI" {
                if let (Some(desc), Some(ln)) = (attr(e, "desc", at)?, c.ln.as_mut()) {
                    ln.values
                        .insert(format!("{}#desc", c.instance_path.join(".")), desc);
                }
            }
        }
        b"Val"
            if (c.ln.is_some() && !c.instance_path.is_empty())
                || c.do_type.is_some()
                || c.da_type.is_some() =>
        {
            c.in_attr_val = true;
            c.text.clear();
        }
        b"ConnectedAP" => {
            let ied = required(e, "ConnectedAP", "iedName", at)?;
            c.connected_ap = Some(ied);
        }
        b"P" if c.connected_ap.is_some() => {
            c.address_p = Some(required(e, "P", "type", at)?);
            c.text.clear();
        }
        b"Substation" if parent == b"SCL" => c.substation = Some(opt(e, "name", at)?),
        b"VoltageLevel" if c.substation.is_some() => c.voltage_level = Some(opt(e, "name", at)?),
        b"Bay" if c.voltage_level.is_some() => {
            c.bay = Some(Bay {
                substation: c.substation.clone().unwrap_or_default(),
                voltage_level: c.voltage_level.clone().unwrap_or_default(),
                name: required(e, "Bay", "name", at)?,
                desc: opt(e, "desc", at)?,
                lnodes: Vec::new(),
            });
        }
        b"LNode" if c.bay.is_some() => {
            let l = LNodeRef {
                ied: opt(e, "iedName", at)?,
                ld_inst: opt(e, "ldInst", at)?,
                prefix: opt(e, "prefix", at)?,
                ln_class: required(e, "LNode", "lnClass", at)?,
                ln_inst: opt(e, "lnInst", at)?,
            };
            if let Some(b) = c.bay.as_mut() {
                if !l.ied.is_empty() && l.ied != "None" {
                    b.lnodes.push(l);
                }
            }
        }
        b"DataTypeTemplates" => c.in_templates = true,
        b"LNodeType" if c.in_templates => {
            let id = required(e, "LNodeType", "id", at)?;
            c.ln_type = Some((
                id,
                LnType {
                    class: required(e, "LNodeType", "lnClass", at)?,
                    dos: Vec::new(),
                    at,
                },
            ));
        }
        b"DO" if c.ln_type.is_some() => {
            let d = (
                required(e, "DO", "name", at)?,
                required(e, "DO", "type", at)?,
            );
            if let Some((_, t)) = c.ln_type.as_mut() {
                t.dos.push(d);
            }
        }
        b"DOType" if c.in_templates => {
            let id = required(e, "DOType", "id", at)?;
            c.do_type = Some((
                id,
                DoType {
                    cdc: required(e, "DOType", "cdc", at)?,
                    children: Vec::new(),
                    at,
                },
            ));
        }
        b"SDO" if c.do_type.is_some() => {
            let s = DoChild::Sdo(
                required(e, "SDO", "name", at)?,
                required(e, "SDO", "type", at)?,
            );
            if let Some((_, t)) = c.do_type.as_mut() {
                t.children.push(s);
            }
        }
        b"DA" if c.do_type.is_some() => {
            let a = attribute(e, "DA", at)?;
            if let Some((_, t)) = c.do_type.as_mut() {
                t.children.push(DoChild::Da(a));
            }
        }
        b"DAType" if c.in_templates => {
            c.da_type = Some((required(e, "DAType", "id", at)?, Vec::new()));
        }
        b"BDA" if c.da_type.is_some() => {
            let a = attribute(e, "BDA", at)?;
            if let Some((_, t)) = c.da_type.as_mut() {
                t.push(a);
            }
        }
        b"EnumType" if c.in_templates => {
            c.enum_type = Some((required(e, "EnumType", "id", at)?, Vec::new()));
        }
        b"EnumVal" if c.enum_type.is_some() => {
            c.enum_ord = Some(number(e, "EnumVal", "ord", at, 0i64)?);
            c.text.clear();
        }
        _ => {}
    }
    Ok(())
}

fn attribute(e: &BytesStart<'_>, element: &str, at: u64) -> Result<Attr, Failure> {
    Ok(Attr {
        name: required(e, element, "name", at)?,
        fc: opt(e, "fc", at)?,
        b_type: required(e, element, "bType", at)?,
        type_id: opt(e, "type", at)?,
        count: number(e, element, "count", at, 0)?,
        value: None,
    })
}

fn end(scl: &mut Scl, c: &mut Cursor, name: &[u8], at: u64) -> Result<(), Failure> {
    if c.skipping_ied {
        if name == b"IED" {
            c.skipping_ied = false;
        }
        return Ok(());
    }
    match name {
        b"IED" => {
            if let Some(ied) = c.ied.take() {
                scl.ieds.push(ied);
            }
        }
        b"LDevice" => {
            if let (Some(ld), Some(ied)) = (c.ld.take(), c.ied.as_mut()) {
                ied.ldevices.push(ld);
            }
        }
        b"LN0" | b"LN" => {
            if let (Some(ln), Some(ld)) = (c.ln.take(), c.ld.as_mut()) {
                ld.lns.push(ln);
            }
        }
        b"DataSet" => {
            if let (Some(ds), Some(ln)) = (c.dataset.take(), c.ln.as_mut()) {
                ln.datasets.push(ds);
            }
        }
        b"ReportControl" => {
            if let (Some(r), Some(ln)) = (c.report.take(), c.ln.as_mut()) {
                ln.reports.push(r);
            }
        }
        b"DOI" | b"SDI" | b"DAI" if c.ln.is_some() => {
            c.instance_path.pop();
        }
        b"Val" if c.in_attr_val => {
            c.in_attr_val = false;
            let text = std::mem::take(&mut c.text);
            if let (Some(ln), false) = (c.ln.as_mut(), c.instance_path.is_empty()) {
                ln.values.insert(c.instance_path.join("."), text);
            } else if let Some((_, t)) = c.da_type.as_mut() {
                if let Some(a) = t.last_mut() {
                    a.value = Some(text);
                }
            } else if let Some((_, t)) = c.do_type.as_mut() {
                if let Some(DoChild::Da(a)) = t.children.last_mut() {
                    a.value = Some(text);
                }
            }
        }
        b"P" => {
            if let (Some(kind), Some(ied)) = (c.address_p.take(), c.connected_ap.as_ref()) {
                let text = std::mem::take(&mut c.text).trim().to_string();
                let a = scl.addresses.entry(ied.clone()).or_default();
                match kind.as_str() {
                    "IP" => a.ip = Some(text),
                    "MMS-Port" => a.port = text.parse().ok(),
                    "OSI-AP-Title" => a.ap_title = Some(text.replace(',', ".")),
                    "OSI-AE-Qualifier" => a.ae_qualifier = text.parse().ok(),
                    "OSI-PSEL" => a.psel = Some(text),
                    "OSI-SSEL" => a.ssel = Some(text),
                    "OSI-TSEL" => a.tsel = Some(text),
                    _ => {}
                }
            }
        }
        b"ConnectedAP" => c.connected_ap = None,
        b"Substation" => c.substation = None,
        b"VoltageLevel" => c.voltage_level = None,
        b"Bay" => {
            if let Some(b) = c.bay.take() {
                scl.bays.push(b);
            }
        }
        b"DataTypeTemplates" => c.in_templates = false,
        b"LNodeType" => {
            if let Some((id, t)) = c.ln_type.take() {
                scl.templates.ln_types.insert(id, t);
            }
        }
        b"DOType" => {
            if let Some((id, t)) = c.do_type.take() {
                scl.templates.do_types.insert(id, t);
            }
        }
        b"DAType" => {
            if let Some((id, t)) = c.da_type.take() {
                scl.templates.da_types.insert(id, t);
            }
        }
        b"EnumType" => {
            if let Some((id, t)) = c.enum_type.take() {
                scl.templates.enum_types.insert(id, t);
            }
        }
        b"EnumVal" => {
            if let (Some(ord), Some((_, t))) = (c.enum_ord.take(), c.enum_type.as_mut()) {
                t.push((ord, std::mem::take(&mut c.text).trim().to_string()));
            }
        }
        _ => {}
    }
    let _ = at;
    Ok(())
}
