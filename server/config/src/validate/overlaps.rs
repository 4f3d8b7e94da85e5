//! Across tags: two tags on the same register (or bit) of one device.

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
        let start = *t.address.get_ref();
        let end = start + t.width().max(1) as u32;
        let bit = if t.kind.get_ref().is_bit() {
            None
        } else {
            t.bit.as_ref().map(|b| *b.get_ref())
        };
        by_table
            .entry((t.device.get_ref().as_str(), *t.kind.get_ref()))
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
                if conflict {
                    let first = cx.place(o.3, o.4.address.span());
                    cx.err(
                        cur.3,
                        cur.4.address.span(),
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
