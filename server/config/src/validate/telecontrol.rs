//! `[iec104_server]`: the listen address, the allow-list, the APCI
//! parameters, and each exported point against its tag: the tag exists,
//! its type fits the point, an IOA is used once, a command only on a
//! writable tag the centre's role may command.

use std::collections::HashMap;
use std::net::{IpAddr, SocketAddr};

use crate::model::*;

use super::Ctx;

pub(super) fn check_iec104_server<'a>(
    cx: &mut Ctx<'_>,
    server: &Iec104ServerConfig,
    lookup: &dyn Fn(&str) -> Option<&'a TagConfig>,
) {
    let at = "[iec104_server]";
    if server.listen.get_ref().parse::<SocketAddr>().is_err() {
        cx.err(
            0,
            server.listen.span(),
            format!(
                "{at} listen: '{}' is not an address like 0.0.0.0:2404",
                server.listen.get_ref()
            ),
        );
    }
    if server.allowed_clients.is_empty() {
        cx.err(
            0,
            server.listen.span(),
            format!("{at} allowed_clients: list the control centre's IP addresses; none means no one may connect"),
        );
    }
    for c in &server.allowed_clients {
        if c.get_ref().parse::<IpAddr>().is_err() {
            cx.err(
                0,
                c.span(),
                format!(
                    "{at} allowed_clients: '{}' is not an IP address",
                    c.get_ref()
                ),
            );
        }
    }
    if !(1..=64).contains(server.max_connections.get_ref()) {
        cx.err(
            0,
            server.max_connections.span(),
            format!("{at} max_connections must be 1 to 64"),
        );
    }
    let ca = *server.common_address.get_ref();
    if ca == 0 || ca == 0xFFFF {
        cx.err(
            0,
            server.common_address.span(),
            format!("{at} common_address must be 1 to 65534"),
        );
    }
    let (k, w) = (*server.k.get_ref(), *server.w.get_ref());
    if !(1..=32767).contains(&k) || w == 0 || u32::from(w) * 3 > u32::from(k) * 2 {
        cx.err(
            0,
            server.w.span(),
            format!("{at} k = {k} must be 1 to 32767 and w = {w} 1 to two thirds of k"),
        );
    }
    for (field, v) in [
        ("t1_s", &server.t1_s),
        ("t2_s", &server.t2_s),
        ("t3_s", &server.t3_s),
        ("select_timeout_s", &server.select_timeout_s),
    ] {
        if !(v.get_ref().is_finite() && (1.0..=3600.0).contains(v.get_ref())) {
            cx.err(
                0,
                v.span(),
                format!("{at} {field} must be 1 to 3600 seconds"),
            );
        }
    }
    if server.t2_s.get_ref() >= server.t1_s.get_ref() {
        cx.err(
            0,
            server.t2_s.span(),
            format!("{at} t2_s must be below t1_s"),
        );
    }
    let mut monitored: HashMap<u32, &Iec104ExportConfig> = HashMap::new();
    let mut commanded: HashMap<u32, &Iec104ExportConfig> = HashMap::new();
    for p in &server.points {
        let name = p.tag.get_ref();
        for ioa in std::iter::once(&p.ioa).chain(p.command_ioa.as_ref()) {
            if !(1..=0xFF_FFFF).contains(ioa.get_ref()) {
                cx.err(
                    0,
                    ioa.span(),
                    format!(
                        "{at} point '{name}': IOA {} is outside 1..16777215",
                        ioa.get_ref()
                    ),
                );
            }
        }
        if let Some(prev) = monitored.insert(*p.ioa.get_ref(), p) {
            let first = cx.place(0, prev.ioa.span());
            cx.err(
                0,
                p.ioa.span(),
                format!(
                    "{at} point '{name}': IOA {} is already point '{}' (at {first})",
                    p.ioa.get_ref(),
                    prev.tag.get_ref()
                ),
            );
        }
        if p.command.is_some() {
            if let Some(prev) = commanded.insert(p.command_ioa(), p) {
                cx.err(
                    0,
                    p.tag.span(),
                    format!(
                        "{at} point '{name}': command IOA {} is already the command of '{}'",
                        p.command_ioa(),
                        prev.tag.get_ref()
                    ),
                );
            }
        }
        for (field, v) in [("deadband", &p.deadband), ("cyclic_s", &p.cyclic_s)] {
            if !(v.get_ref().is_finite() && *v.get_ref() >= 0.0) {
                cx.err(
                    0,
                    v.span(),
                    format!("{at} point '{name}': {field} must be 0 or more"),
                );
            }
        }
        // A derived tag (a panel's sequence, the dispatch) is not in the
        // tag files: `gridscada check` and the server's start look it up
        // among every tag of the plant.
        let Some(t) = lookup(name) else {
            if p.command.is_some() {
                cx.err(
                    0,
                    p.tag.span(),
                    format!("{at} point '{name}': commands go to configured tags only, and this is not one"),
                );
            }
            continue;
        };
        let point = *p.point.get_ref();
        if !point.exports(t.value_kind()) {
            cx.err(
                0,
                p.point.span(),
                format!(
                    "{at} point '{name}': a {} point cannot carry the tag's {} values",
                    point.label(),
                    t.data_type().label()
                ),
            );
        }
        if let Some(c) = &p.command {
            let role = t.write_role.as_ref().map(|r| *r.get_ref());
            if !*t.writable.get_ref() {
                cx.err(
                    0,
                    c.span(),
                    format!(
                        "{at} point '{name}': command {} on a tag that is not writable",
                        c.get_ref().label()
                    ),
                );
            } else if role.is_some_and(|r| r > *server.command_role.get_ref()) {
                cx.err(
                    0,
                    c.span(),
                    format!(
                        "{at} point '{name}': the tag's write_role is {}, above the centre's command_role {}",
                        role.map(Role::label).unwrap_or_default(),
                        server.command_role.get_ref().label()
                    ),
                );
            } else if !c.get_ref().exports(t.value_kind()) {
                cx.err(
                    0,
                    c.span(),
                    format!(
                        "{at} point '{name}': command {} cannot carry the tag's {} values",
                        c.get_ref().label(),
                        t.data_type().label()
                    ),
                );
            }
        } else if p.select || p.command_ioa.is_some() {
            cx.err(
                0,
                p.tag.span(),
                format!(
                    "{at} point '{name}': select and command_ioa are for a point with a command"
                ),
            );
        }
    }
}
