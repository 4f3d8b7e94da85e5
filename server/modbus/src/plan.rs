//! Block planning: which read requests a device's scan consists of.
//!
//! **Owns:** grouping one device's tags, per scan class and per Modbus table,
//! into the fewest read requests within the protocol limits (125 registers,
//! 2000 bits), the device's own per-request limits and its maximum gap of
//! unused addresses. Done once at start; pure.
//!
//! **Must not touch:** I/O, decoding, timing.
//!
//! Sorted by address, a greedy sweep that extends the open block while the
//! next tag fits (gap and length) and otherwise starts a new one is optimal:
//! any plan needs a new block at least as early as greedy does.

use std::collections::BTreeMap;

use gridscada_config::RegisterKind;

/// Protocol limits of one read request.
pub const MAX_READ_REGISTERS: u16 = 125;
pub const MAX_READ_BITS: u16 = 2000;

/// One tag as the planner sees it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Point {
    /// The caller's index of the tag.
    pub tag: usize,
    pub table: RegisterKind,
    pub address: u16,
    /// Registers or bits, at least 1.
    pub width: u16,
    pub scan_ms: u64,
}

/// Per-request limits of one device.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Limits {
    pub max_registers: u16,
    pub max_bits: u16,
    pub max_gap: u16,
}

impl Limits {
    fn max_for(&self, table: RegisterKind) -> u16 {
        if table.is_bit() {
            self.max_bits.clamp(1, MAX_READ_BITS)
        } else {
            self.max_registers.clamp(1, MAX_READ_REGISTERS)
        }
    }
}

/// One read request.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Block {
    pub table: RegisterKind,
    pub start: u16,
    pub count: u16,
    /// Tags read by this block, by the caller's index, in address order.
    pub tags: Vec<usize>,
}

/// The blocks read together at one scan period.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ScanClass {
    pub period_ms: u64,
    pub blocks: Vec<Block>,
}

#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum PlanError {
    #[error(
        "tag #{tag}: {width} {unit} at {address} do not fit in one request (device limit {limit})"
    )]
    TooWide {
        tag: usize,
        address: u16,
        width: u16,
        unit: &'static str,
        limit: u16,
    },
    #[error("tag #{tag}: address {address} with width {width} runs past 65535")]
    PastEnd {
        tag: usize,
        address: u16,
        width: u16,
    },
}

/// Plans one device: scan classes by increasing period, each with its blocks
/// ordered by table then address.
pub fn plan_device(points: &[Point], limits: Limits) -> Result<Vec<ScanClass>, PlanError> {
    let mut classes: BTreeMap<u64, BTreeMap<RegisterKind, Vec<Point>>> = BTreeMap::new();
    for p in points {
        let limit = limits.max_for(p.table);
        let width = p.width.max(1);
        if width > limit {
            return Err(PlanError::TooWide {
                tag: p.tag,
                address: p.address,
                width,
                unit: if p.table.is_bit() {
                    "bits"
                } else {
                    "registers"
                },
                limit,
            });
        }
        if u32::from(p.address) + u32::from(width) > 65_536 {
            return Err(PlanError::PastEnd {
                tag: p.tag,
                address: p.address,
                width,
            });
        }
        classes
            .entry(p.scan_ms)
            .or_default()
            .entry(p.table)
            .or_default()
            .push(Point { width, ..*p });
    }
    Ok(classes
        .into_iter()
        .map(|(period_ms, tables)| ScanClass {
            period_ms,
            blocks: tables
                .into_iter()
                .flat_map(|(table, pts)| plan_table(table, pts, limits))
                .collect(),
        })
        .collect())
}

fn plan_table(table: RegisterKind, mut pts: Vec<Point>, limits: Limits) -> Vec<Block> {
    let limit = u32::from(limits.max_for(table));
    let gap = u32::from(limits.max_gap);
    pts.sort_by_key(|p| (p.address, std::cmp::Reverse(p.width), p.tag));
    let mut blocks = Vec::new();
    // Open block: [start, end) and its tags.
    let mut open: Option<(u32, u32, Vec<usize>)> = None;
    for p in pts {
        let a = u32::from(p.address);
        let e = a + u32::from(p.width);
        if let Some((start, end, tags)) = &mut open {
            let new_end = (*end).max(e);
            let fits_gap = a <= *end || a - *end <= gap;
            if fits_gap && new_end - *start <= limit {
                *end = new_end;
                tags.push(p.tag);
                continue;
            }
        }
        if let Some((start, end, tags)) = open.take() {
            blocks.push(block(table, start, end, tags));
        }
        open = Some((a, e, vec![p.tag]));
    }
    if let Some((start, end, tags)) = open {
        blocks.push(block(table, start, end, tags));
    }
    blocks
}

fn block(table: RegisterKind, start: u32, end: u32, tags: Vec<usize>) -> Block {
    Block {
        table,
        start: start as u16,
        count: (end - start) as u16,
        tags,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const HR: RegisterKind = RegisterKind::HoldingRegister;
    const IR: RegisterKind = RegisterKind::InputRegister;
    const DI: RegisterKind = RegisterKind::DiscreteInput;

    fn pt(tag: usize, table: RegisterKind, address: u16, width: u16) -> Point {
        Point {
            tag,
            table,
            address,
            width,
            scan_ms: 1000,
        }
    }

    fn limits(gap: u16) -> Limits {
        Limits {
            max_registers: 125,
            max_bits: 2000,
            max_gap: gap,
        }
    }

    fn spans(classes: &[ScanClass]) -> Vec<(RegisterKind, u16, u16)> {
        classes
            .iter()
            .flat_map(|c| c.blocks.iter().map(|b| (b.table, b.start, b.count)))
            .collect()
    }

    #[test]
    fn contiguous_tags_make_one_request() {
        let pts: Vec<Point> = (0..10).map(|i| pt(i, HR, i as u16 * 2, 2)).collect();
        let plan = plan_device(&pts, limits(0)).unwrap();
        assert_eq!(spans(&plan), vec![(HR, 0, 20)]);
        assert_eq!(plan[0].blocks[0].tags, (0..10).collect::<Vec<_>>());
    }

    #[test]
    fn gap_within_limit_is_read_through() {
        let pts = vec![pt(0, HR, 0, 1), pt(1, HR, 5, 1), pt(2, HR, 30, 1)];
        // Gap 0..1 -> 5 is 4 unused registers: read through with max_gap 4.
        assert_eq!(
            spans(&plan_device(&pts, limits(4)).unwrap()),
            vec![(HR, 0, 6), (HR, 30, 1)]
        );
        assert_eq!(
            spans(&plan_device(&pts, limits(3)).unwrap()),
            vec![(HR, 0, 1), (HR, 5, 1), (HR, 30, 1)]
        );
    }

    #[test]
    fn protocol_and_device_limits_split_blocks() {
        // 300 consecutive registers: 125 + 125 + 50.
        let pts: Vec<Point> = (0..300).map(|i| pt(i, IR, i as u16, 1)).collect();
        assert_eq!(
            spans(&plan_device(&pts, limits(0)).unwrap()),
            vec![(IR, 0, 125), (IR, 125, 125), (IR, 250, 50)]
        );
        // A device that takes 60 at a time; a two-register tag never straddles.
        let pts: Vec<Point> = (0..50).map(|i| pt(i, IR, i as u16 * 2, 2)).collect();
        let small = Limits {
            max_registers: 61,
            ..limits(0)
        };
        assert_eq!(
            spans(&plan_device(&pts, small).unwrap()),
            vec![(IR, 0, 60), (IR, 60, 40)]
        );
        // Bits: 2500 discrete inputs -> 2000 + 500; a device limit above the
        // protocol limit is clamped.
        let pts: Vec<Point> = (0..2500).map(|i| pt(i, DI, i as u16, 1)).collect();
        let big = Limits {
            max_bits: 5000,
            ..limits(0)
        };
        assert_eq!(
            spans(&plan_device(&pts, big).unwrap()),
            vec![(DI, 0, 2000), (DI, 2000, 500)]
        );
    }

    #[test]
    fn tables_and_scan_classes_are_separate() {
        let mut pts = vec![pt(0, HR, 0, 1), pt(1, IR, 1, 1), pt(2, HR, 1, 1)];
        pts.push(Point {
            scan_ms: 100,
            ..pt(3, HR, 2, 1)
        });
        let plan = plan_device(&pts, limits(10)).unwrap();
        assert_eq!(plan.len(), 2);
        assert_eq!(plan[0].period_ms, 100);
        assert_eq!(spans(&plan[..1]), vec![(HR, 2, 1)]);
        assert_eq!(spans(&plan[1..]), vec![(IR, 1, 1), (HR, 0, 2)]);
    }

    #[test]
    fn overlapping_bit_tags_share_a_register() {
        // Status word read whole and bit by bit.
        let pts = vec![pt(0, HR, 10, 1), pt(1, HR, 10, 1), pt(2, HR, 10, 1)];
        let plan = plan_device(&pts, limits(0)).unwrap();
        assert_eq!(spans(&plan), vec![(HR, 10, 1)]);
        assert_eq!(plan[0].blocks[0].tags.len(), 3);
    }

    #[test]
    fn greedy_is_fewest_on_random_layouts() {
        // Compare with an exhaustive dynamic programme on small layouts.
        let mut seed: u64 = 0x9E37_79B9_7F4A_7C15;
        let mut next = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            seed
        };
        for _ in 0..200 {
            let n = (next() % 12 + 1) as usize;
            let mut addr = 0u16;
            let mut pts = vec![];
            for i in 0..n {
                addr += (next() % 6) as u16;
                let w = [1, 2, 4][(next() % 3) as usize];
                pts.push(pt(i, HR, addr, w));
                addr += w;
            }
            let lim = Limits {
                max_registers: (next() % 10 + 4) as u16,
                max_bits: 2000,
                max_gap: (next() % 4) as u16,
            };
            let got = plan_device(&pts, lim).unwrap()[0].blocks.len();
            assert_eq!(got, brute_force(&pts, lim), "{pts:?} {lim:?}");
        }
    }

    /// Fewest blocks covering sorted, non-overlapping points, by DP over
    /// contiguous runs.
    fn brute_force(pts: &[Point], lim: Limits) -> usize {
        let n = pts.len();
        let mut best = vec![usize::MAX; n + 1];
        best[0] = 0;
        for i in 0..n {
            if best[i] == usize::MAX {
                continue;
            }
            for j in i..n {
                let start = pts[i].address as u32;
                let end = (pts[j].address + pts[j].width) as u32;
                let gaps_ok = (i..j).all(|k| {
                    pts[k + 1].address as u32 - (pts[k].address + pts[k].width) as u32
                        <= lim.max_gap as u32
                });
                if end - start <= lim.max_registers as u32 && gaps_ok {
                    best[j + 1] = best[j + 1].min(best[i] + 1);
                }
            }
        }
        best[n]
    }

    #[test]
    fn too_wide_tag_is_an_error() {
        let pts = vec![pt(7, HR, 0, 4)];
        let lim = Limits {
            max_registers: 2,
            ..limits(0)
        };
        let err = plan_device(&pts, lim).unwrap_err();
        assert!(err.to_string().contains("tag #7"), "{err}");
        assert!(plan_device(&[pt(0, HR, 65535, 2)], limits(0)).is_err());
    }
}
