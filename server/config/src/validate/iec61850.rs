//! IEC 61850: an IED's association settings and reports, and each tag's
//! data attribute (reference, functional constraint, type, control).

use crate::model::*;

use super::Ctx;

/// `[device.iec61850]`: AP titles, selectors, timeouts, report control blocks.
pub(super) fn check_iec61850_device(
    cx: &mut Ctx<'_>,
    f: usize,
    name: &str,
    s: &Iec61850DeviceConfig,
) {
    for (field, v) in [
        ("remote_ap_title", &s.remote_ap_title),
        ("local_ap_title", &s.local_ap_title),
    ] {
        if parse_oid(v.get_ref()).is_none() {
            cx.err(
                f,
                v.span(),
                format!("device '{name}': {field} '{}' is not an object identifier (e.g. \"1.1.1.999\")", v.get_ref()),
            );
        }
    }
    for (field, v, max) in [
        ("remote_tsel", &s.remote_tsel, 4),
        ("remote_ssel", &s.remote_ssel, 16),
        ("remote_psel", &s.remote_psel, 16),
    ] {
        match parse_hex(v.get_ref()) {
            Some(b) if !b.is_empty() && b.len() <= max => {}
            _ => cx.err(
                f,
                v.span(),
                format!("device '{name}': {field} '{}' must be 1 to {max} octets in hex (e.g. \"0001\")", v.get_ref()),
            ),
        }
    }
    if !(100..=120_000).contains(s.response_timeout_ms.get_ref()) {
        cx.err(
            f,
            s.response_timeout_ms.span(),
            format!("device '{name}': response_timeout_ms must be 100 to 120000"),
        );
    }
    let c = *s.command_timeout_s.get_ref();
    if !(c.is_finite() && (0.1..=600.0).contains(&c)) {
        cx.err(
            f,
            s.command_timeout_s.span(),
            format!("device '{name}': command_timeout_s must be 0.1 to 600"),
        );
    }
    let mut seen = std::collections::HashSet::new();
    for r in &s.reports {
        let rcb = r.rcb.get_ref();
        if let Err(why) = rcb_parts(rcb) {
            cx.err(
                f,
                r.rcb.span(),
                format!("device '{name}': report rcb {why}"),
            );
        }
        if !seen.insert(rcb.clone()) {
            cx.err(
                f,
                r.rcb.span(),
                format!("device '{name}': report rcb '{rcb}' is listed twice"),
            );
        }
        if let Some(ds) = &r.dataset {
            match ObjectRef::parse(ds.get_ref()) {
                Ok(o) if o.path.len() == 1 => {}
                Ok(_) => cx.err(
                    f,
                    ds.span(),
                    format!(
                        "device '{name}': dataset '{}' is not LD/LN.name",
                        ds.get_ref()
                    ),
                ),
                Err(why) => cx.err(f, ds.span(), format!("device '{name}': dataset {why}")),
            }
        }
        if let Some(p) = &r.integrity_period_s {
            if !(p.get_ref().is_finite() && (0.0..=86_400.0).contains(p.get_ref())) {
                cx.err(
                    f,
                    p.span(),
                    format!("device '{name}': integrity_period_s must be 0 to 86400"),
                );
            }
        }
    }
}

/// The parts of an RCB reference `LD/LN.BR.name` or `LD/LN.RP.name`:
/// logical device, logical node, buffered, name.
pub fn rcb_parts(rcb: &str) -> Result<(&str, &str, bool, &str), String> {
    let o = ObjectRef::parse(rcb)?;
    match o.path.as_slice() {
        ["BR", n] => Ok((o.ld, o.ln, true, n)),
        ["RP", n] => Ok((o.ld, o.ln, false, n)),
        _ => Err(format!(
            "'{rcb}' is not LD/LN.BR.name (buffered) or LD/LN.RP.name (unbuffered)"
        )),
    }
}

/// Dotted decimal arcs, at least two.
pub fn parse_oid(s: &str) -> Option<Vec<u32>> {
    let arcs: Option<Vec<u32>> = s.split('.').map(|a| a.parse().ok()).collect();
    arcs.filter(|a| a.len() >= 2 && a[0] <= 2)
}

/// Octets written in hex (even number of digits).
pub fn parse_hex(s: &str) -> Option<Vec<u8>> {
    if !s.len().is_multiple_of(2) {
        return None;
    }
    (0..s.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(s.get(i..i + 2)?, 16).ok())
        .collect()
}

/// A tag of an IEC 61850 device: its reference, FC, type and control.
pub(super) fn check_iec61850_point(
    cx: &mut Ctx<'_>,
    f: usize,
    t: &TagConfig,
    device: Option<&DeviceConfig>,
) {
    let name = t.name.get_ref();
    let device_name = t.device.get_ref();
    for (field, span) in [
        ("kind", t.kind.as_ref().map(|k| k.span())),
        ("address", t.address.as_ref().map(|a| a.span())),
        ("bit", t.bit.as_ref().map(|b| b.span())),
        ("length", t.length.as_ref().map(|l| l.span())),
        ("iec104", t.iec104.as_ref().map(|p| p.ioa.span())),
        ("dnp3", t.dnp3.as_ref().map(|p| p.point.span())),
    ] {
        if let Some(span) = span {
            cx.err(
                f,
                span,
                format!("tag '{name}': {field} is not an IEC 61850 setting; device '{device_name}' speaks IEC 61850 (use iec61850 = {{ ref = \"LD/LN.DO.DA\", fc = \"ST\" }})"),
            );
        }
    }
    let Some(p) = &t.iec61850 else {
        if device.is_some() {
            cx.err(
                f,
                t.name.span(),
                format!("tag '{name}': a tag of IEC 61850 device '{device_name}' needs iec61850 = {{ ref = \"LD/LN.DO.DA\", fc = \"ST\" }}"),
            );
        }
        return;
    };
    match ObjectRef::parse(p.reference.get_ref()) {
        Ok(o) if o.path.len() >= 2 => {}
        Ok(_) => cx.err(
            f,
            p.reference.span(),
            format!("tag '{name}': ref '{}' names no data attribute (LD/LN.DO.DA, e.g. XCBR1.Pos.stVal)", p.reference.get_ref()),
        ),
        Err(why) => cx.err(f, p.reference.span(), format!("tag '{name}': ref {why}")),
    }
    match &t.data_type {
        None => cx.err(
            f,
            p.reference.span(),
            format!("tag '{name}': an IEC 61850 tag needs type (bool for an SPS stVal, u16 for a Dbpos, i32 for an INS, f32 for mag.f, i64 for a BCR actVal)"),
        ),
        Some(ty) if !iec61850_carries(*ty.get_ref()) => cx.err(
            f,
            ty.span(),
            format!("tag '{name}': type {} cannot carry an IEC 61850 value", ty.get_ref().label()),
        ),
        Some(_) => {}
    }
    let writable = *t.writable.get_ref();
    if let Some(c) = &p.control {
        match ObjectRef::parse(c.get_ref()) {
            Ok(o) if !o.path.is_empty() => {}
            Ok(_) => cx.err(
                f,
                c.span(),
                format!(
                    "tag '{name}': control '{}' names no data object (LD/LN.DO)",
                    c.get_ref()
                ),
            ),
            Err(why) => cx.err(f, c.span(), format!("tag '{name}': control {why}")),
        }
    }
    if !writable {
        for (field, set) in [
            ("control", p.control.is_some()),
            ("ctl_model", p.ctl_model.is_some()),
            ("interlock_check", p.interlock_check),
            ("synchro_check", p.synchro_check),
            ("test", p.test),
        ] {
            if set {
                cx.err(
                    f,
                    p.reference.span(),
                    format!("tag '{name}': {field} is for a writable tag (writable = true)"),
                );
            }
        }
    }
    if let Some(m) = &p.ctl_model {
        if *m.get_ref() == CtlModel::StatusOnly && writable {
            cx.err(
                f,
                m.span(),
                format!(
                    "tag '{name}': a status-only object cannot be operated; writable must be false"
                ),
            );
        }
    }
    if writable && *p.fc.get_ref() != Fc::St && *p.fc.get_ref() != Fc::Mx && p.control.is_none() {
        cx.err(
            f,
            p.fc.span(),
            format!("tag '{name}': a writable tag operates a controllable object; give control = \"LD/LN.DO\" or read its status (FC ST or MX)"),
        );
    }
}

/// Tags and reports of a device with `scl = "…"` checked against that
/// SCL file: every reference resolves in the IED's model with its FC, its
/// type can carry the attribute, every control has its `Oper`, every
/// report control block exists.
pub(super) fn check_against_scl(
    cx: &mut Ctx<'_>,
    devices: &[(usize, DeviceConfig)],
    tags: &[(usize, TagConfig)],
) {
    for (f, d) in devices {
        let (Protocol::Iec61850, Some(cfg)) = (d.protocol, &d.iec61850) else {
            continue;
        };
        let Some(scl_file) = &cfg.scl else { continue };
        let name = d.name.get_ref();
        let ied = cfg
            .ied
            .as_ref()
            .map_or(name.as_str(), |i| i.get_ref().as_str());
        let base = cx.files[*f]
            .path
            .parent()
            .map(|p| p.to_path_buf())
            .unwrap_or_default();
        let path = base.join(scl_file.get_ref());
        let filter = gridscada_scl::Filter {
            ieds: vec![ied.to_string()],
        };
        let scl = match gridscada_scl::read_path(&path, &filter) {
            Ok(s) => s,
            Err(e) => {
                cx.err(*f, scl_file.span(), format!("device '{name}': scl: {e}"));
                continue;
            }
        };
        let Some(model) = scl.ieds.first() else {
            cx.err(
                *f,
                scl_file.span(),
                format!(
                    "device '{name}': {} has no IED '{ied}' (it has: {})",
                    path.display(),
                    scl.all_ied_names.join(", ")
                ),
            );
            continue;
        };
        let find_ln = |ld: &str, ln: &str| {
            let ldev = model.ldevices.iter().find(|l| l.name(&model.name) == ld)?;
            ldev.lns.iter().find(|l| l.name() == ln)
        };
        for (tf, t) in tags.iter().filter(|(_, t)| t.device.get_ref() == name) {
            let Some(p) = &t.iec61850 else { continue };
            let tag = t.name.get_ref();
            let Ok(o) = ObjectRef::parse(p.reference.get_ref()) else {
                continue;
            };
            let Some(ln) = find_ln(o.ld, o.ln) else {
                cx.err(
                    *tf,
                    p.reference.span(),
                    format!(
                        "tag '{tag}': the SCL's IED '{ied}' has no {}/{}",
                        o.ld, o.ln
                    ),
                );
                continue;
            };
            let fc = p.fc.get_ref().label();
            match scl.templates.resolve(&ln.ln_type, &o.path, Some(fc)) {
                Ok(gridscada_scl::Resolved::Attribute { b_type, .. }) => {
                    if let Some(ty) = &t.data_type {
                        if !b_type_carried(&b_type, *ty.get_ref()) {
                            cx.err(
                                *tf,
                                ty.span(),
                                format!("tag '{tag}': {} is {b_type} in the SCL; a {} tag cannot carry it", p.reference.get_ref(), ty.get_ref().label()),
                            );
                        }
                    }
                }
                Ok(gridscada_scl::Resolved::DataObject { cdc }) => cx.err(
                    *tf,
                    p.reference.span(),
                    format!("tag '{tag}': {} is a data object ({cdc}) in the SCL; name its attribute (e.g. .stVal)", p.reference.get_ref()),
                ),
                Err(why) => cx.err(*tf, p.reference.span(), format!("tag '{tag}': not in the SCL: {why}")),
            }
            if *t.writable.get_ref() {
                let object = p
                    .control
                    .as_ref()
                    .map_or_else(|| p.reference.get_ref().clone(), |c| c.get_ref().clone());
                if let Ok(c) = ObjectRef::parse(&object) {
                    let mut path: Vec<&str> = if p.control.is_some() {
                        c.path.clone()
                    } else {
                        c.path.iter().take(1).copied().collect()
                    };
                    path.push("Oper");
                    let found = find_ln(c.ld, c.ln)
                        .map(|ln| scl.templates.resolve(&ln.ln_type, &path, Some("CO")));
                    if !matches!(found, Some(Ok(_))) {
                        cx.err(
                            *tf,
                            p.reference.span(),
                            format!(
                                "tag '{tag}': {}/{}.{} is not controllable in the SCL (no Oper)",
                                c.ld,
                                c.ln,
                                path[..path.len() - 1].join(".")
                            ),
                        );
                    }
                }
            }
        }
        for r in &cfg.reports {
            let Ok((ld, ln_name, buffered, rcb)) = rcb_parts(r.rcb.get_ref()) else {
                continue;
            };
            let found = find_ln(ld, ln_name).and_then(|ln| {
                ln.reports
                    .iter()
                    .find(|rc| rc.buffered == buffered && rc.instances().iter().any(|i| i == rcb))
                    .map(|rc| (ln, rc))
            });
            match found {
                None => cx.err(
                    *f,
                    r.rcb.span(),
                    format!(
                        "device '{name}': the SCL has no report control block {}",
                        r.rcb.get_ref()
                    ),
                ),
                Some((ln, rc)) => {
                    if let Some(ds) = &r.dataset {
                        let want = format!("{ld}/{}.{}", ln.name(), rc.dataset);
                        if ds.get_ref() != &want {
                            cx.err(
                                *f,
                                ds.span(),
                                format!(
                                    "device '{name}': {} reports dataset {want} in the SCL, not {}",
                                    r.rcb.get_ref(),
                                    ds.get_ref()
                                ),
                            );
                        }
                    }
                }
            }
        }
    }
}

/// Whether a tag of type `ty` can carry an attribute of SCL basic type `b`.
fn b_type_carried(b: &str, ty: DataType) -> bool {
    use DataType::*;
    let numeric = matches!(ty, I16 | U16 | I32 | U32 | I64 | U64 | F32 | F64);
    match b {
        "BOOLEAN" => ty == Bool || numeric,
        "Dbpos" | "Tcmd" | "Enum" => {
            ty == Bool && b == "Dbpos" || numeric || ty == DataType::String
        }
        b if b.starts_with("INT") => numeric || ty == DataType::String,
        "FLOAT32" | "FLOAT64" => numeric || ty == DataType::String,
        b if b.starts_with("VisString") || b.starts_with("Unicode") || b == "Octet64" => {
            ty == DataType::String
        }
        "Timestamp" => ty == DataType::String,
        _ => false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rcb_references_and_selectors() {
        assert_eq!(
            rcb_parts("IED1LD0/LLN0.BR.brcb01").unwrap(),
            ("IED1LD0", "LLN0", true, "brcb01")
        );
        assert!(rcb_parts("IED1LD0/LLN0.XX.brcb01").is_err());
        assert_eq!(parse_hex("0001"), Some(vec![0, 1]));
        assert_eq!(parse_hex("001"), None);
        assert_eq!(parse_oid("1.1.1.999"), Some(vec![1, 1, 1, 999]));
        assert_eq!(parse_oid("1"), None);
    }
}
