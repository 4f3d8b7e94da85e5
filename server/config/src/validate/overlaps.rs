//! Across tags: two tags on the same register (or bit) of one Modbus
//! device, on the same information object address of one IEC 104 device,
//! or on the same point or command index of one DNP3 device.

use std::collections::BTreeMap;

use crate::model::*;

use super::Ctx;

/// Two tags on the same register (or bit) of the same device and table would
/// fight over it. Bits of one register are fine as long as they differ.
pub(super) fn check_overlaps(cx: &mut Ctx<'_>, tags: &[(usize, TagConfig)]) {
    /// A tag's footprint: start, end (exclusive), bit, file, tag.
    type Span<'a> = (u32, u32, Option<u8>, usize, &'a TagConfig);
    let mut by_table: BTreeMap<(&str, RegisterKind), Vec<Span<'_>>> = BTreeMap::new();
    for (f, t) in tags {
        let Some((kind, start)) = t.register() else {
            continue;
        };
        let end = start + t.width().max(1) as u32;
        let bit = if kind.is_bit() {
            None
        } else {
            t.bit.as_ref().map(|b| *b.get_ref())
        };
        by_table
            .entry((t.device.get_ref().as_str(), kind))
            .or_default()
            .push((start, end, bit, *f, t));
    }
    for ((device, kind), mut list) in by_table {
        list.sort_by_key(|(s, e, b, _, _)| (*s, *e, *b));
        // Sweep: compare each tag with every earlier one still open.
        let mut open: Vec<Span<'_>> = Vec::new();
        for cur in list {
            open.retain(|o| o.1 > cur.0);
            for o in &open {
                let conflict = match (o.2, cur.2) {
                    (Some(a), Some(b)) => a == b,
                    // A bit and a whole register: reading a status word both
                    // ways is common, so only whole registers conflict.
                    (Some(_), None) | (None, Some(_)) => false,
                    (None, None) => true,
                };
                // Both have an address: they are in `by_table`.
                let (Some(first_at), Some(cur_at)) = (&o.4.address, &cur.4.address) else {
                    continue;
                };
                if conflict {
                    let first = cx.place(o.3, first_at.span());
                    cx.err(
                        cur.3,
                        cur_at.span(),
                        format!(
                            "tag '{}': {} {} on device '{device}' overlaps tag '{}' (at {first})",
                            cur.4.name.get_ref(),
                            kind.label(),
                            cur.0,
                            o.4.name.get_ref()
                        ),
                    );
                }
            }
            open.push(cur);
        }
    }
}

/// Two tags on the same information object address of one IEC 104 device:
/// a monitored point read into two tags would be fine, but which one a
/// command confirms would not be clear, so each IOA (monitored, and
/// commanded) belongs to one tag.
pub(super) fn check_ioa_reuse(cx: &mut Ctx<'_>, tags: &[(usize, TagConfig)]) {
    /// Device, commanded or monitored, IOA.
    type Key<'a> = (&'a str, bool, u32);
    /// The first tag on it: file, tag, where its IOA is written.
    type First<'a> = (usize, &'a TagConfig, &'a serde_spanned::Spanned<u32>);
    let mut seen: BTreeMap<Key<'_>, First<'_>> = BTreeMap::new();
    for (f, t) in tags {
        let Some(p) = &t.iec104 else { continue };
        let commanded = p
            .command
            .as_ref()
            .map(|_| p.command_ioa.as_ref().unwrap_or(&p.ioa));
        for (is_command, ioa) in [(false, Some(&p.ioa)), (true, commanded)] {
            let Some(ioa) = ioa else { continue };
            let key = (t.device.get_ref().as_str(), is_command, *ioa.get_ref());
            match seen.get(&key) {
                Some((pf, prev, prev_at)) => {
                    let first = cx.place(*pf, prev_at.span());
                    cx.err(
                        *f,
                        ioa.span(),
                        format!(
                            "tag '{}': {} information object address {} of device '{}' is used by tag '{}' too (at {first})",
                            t.name.get_ref(),
                            if is_command { "command" } else { "monitored" },
                            ioa.get_ref(),
                            t.device.get_ref(),
                            prev.name.get_ref()
                        ),
                    );
                }
                None => {
                    seen.insert(key, (*f, t, ioa));
                }
            }
        }
    }
}

/// Two tags on the same point (type and index) of one DNP3 device, or on
/// the same command index of one device: which tag a value or a command's
/// echo belongs to would not be clear.
pub(super) fn check_dnp3_index_reuse(cx: &mut Ctx<'_>, tags: &[(usize, TagConfig)]) {
    /// Device, commanded or monitored, point type or command label, index.
    type Key<'a> = (&'a str, bool, &'static str, u16);
    type First<'a> = (usize, &'a TagConfig, &'a serde_spanned::Spanned<u16>);
    let mut seen: BTreeMap<Key<'_>, First<'_>> = BTreeMap::new();
    for (f, t) in tags {
        let Some(p) = &t.dnp3 else { continue };
        let command = p.command.as_ref().map(|c| {
            (
                c.get_ref().label(),
                p.command_index.as_ref().unwrap_or(&p.index),
            )
        });
        for (what, index, is_command) in
            std::iter::once((p.point.get_ref().label(), &p.index, false))
                .chain(command.map(|(l, i)| (l, i, true)))
        {
            let key = (
                t.device.get_ref().as_str(),
                is_command,
                what,
                *index.get_ref(),
            );
            match seen.get(&key) {
                Some((pf, prev, prev_at)) => {
                    let first = cx.place(*pf, prev_at.span());
                    cx.err(
                        *f,
                        index.span(),
                        format!(
                            "tag '{}': {} {what} index {} of device '{}' is used by tag '{}' too (at {first})",
                            t.name.get_ref(),
                            if is_command { "command" } else { "point" },
                            index.get_ref(),
                            t.device.get_ref(),
                            prev.name.get_ref()
                        ),
                    );
                }
                None => {
                    seen.insert(key, (*f, t, index));
                }
            }
        }
    }
}
