//! `[redundancy]` and `[server] site`: the pair's servers, the lease timing
//! (`ARCHITECTURE.md`, "Redundant pair", says why each bound holds), and the
//! database a pair needs.

use std::collections::HashMap;

use super::{positive, Ctx};
use crate::model::*;

pub(super) fn check_site(cx: &mut Ctx<'_>, server: &ServerConfig) {
    let Some(site) = &server.site else { return };
    let s = site.get_ref();
    if s.is_empty()
        || s.len() > 64
        || !s
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
    {
        cx.err(
            0,
            site.span(),
            format!("[server] site: '{s}' must be 1 to 64 letters, digits, '-' or '_'"),
        );
    }
}

pub(super) fn check_redundancy(cx: &mut Ctx<'_>, r: &RedundancyConfig, storage: &StorageConfig) {
    let url = &storage.url;
    if url.get_ref().starts_with("sqlite:") {
        cx.err(
            0,
            url.span(),
            "[redundancy] needs the servers of the pair to share one PostgreSQL database; [storage] url is SQLite, a file only this machine sees",
        );
    }
    let mut names: HashMap<&str, &PairServer> = HashMap::new();
    for s in &r.servers {
        let n = s.name.get_ref();
        if n.is_empty() || n.chars().any(|c| c.is_control()) || n.len() > 64 {
            cx.err(
                0,
                s.name.span(),
                format!("[[redundancy.server]] name: '{n}' must be 1 to 64 printable characters"),
            );
        }
        if let Some(prev) = names.insert(n, s) {
            let first = cx.place(0, prev.name.span());
            cx.err(
                0,
                s.name.span(),
                format!("[[redundancy.server]] name: duplicate server '{n}' (first at {first})"),
            );
        }
        let u = s.url.get_ref();
        let rest = u
            .strip_prefix("http://")
            .or_else(|| u.strip_prefix("https://"));
        if !rest.is_some_and(|r| !r.is_empty() && !r.starts_with('/')) {
            cx.err(
                0,
                s.url.span(),
                format!(
                    "[[redundancy.server]] url: '{u}' must be the HMI's address, like http://10.0.0.2:8080"
                ),
            );
        }
    }
    if r.servers.len() < 2 {
        cx.err(
            0,
            r.name.span(),
            format!(
                "[redundancy]: a pair needs at least two [[redundancy.server]] entries; {} given",
                r.servers.len()
            ),
        );
    }
    if !names.contains_key(r.name.get_ref().as_str()) {
        cx.err(
            0,
            r.name.span(),
            format!(
                "[redundancy] name: '{}' is not one of the [[redundancy.server]] names ({})",
                r.name.get_ref(),
                r.servers
                    .iter()
                    .map(|s| s.name.get_ref().as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        );
    }
    let before = cx.diags.len();
    for (field, v) in [
        ("lease_s", &r.lease_s),
        ("renew_s", &r.renew_s),
        ("margin_s", &r.margin_s),
        ("takeover_s", &r.takeover_s),
    ] {
        positive(cx, "[redundancy]", field, v);
    }
    if cx.diags.len() > before {
        return;
    }
    let (lease, renew, margin, takeover) = (
        *r.lease_s.get_ref(),
        *r.renew_s.get_ref(),
        *r.margin_s.get_ref(),
        *r.takeover_s.get_ref(),
    );
    if lease > 3600.0 {
        cx.err(
            0,
            r.lease_s.span(),
            "[redundancy] lease_s: at most 3600 seconds",
        );
    }
    // The active server keeps writing until lease - margin after a renewal
    // it sent; it must renew well before that, at least twice.
    if renew * 2.0 > lease - margin {
        cx.err(
            0,
            r.renew_s.span(),
            format!(
                "[redundancy] renew_s: {renew} s leaves no room for a failed renewal; it must be at most half of lease_s - margin_s ({:.3} s)",
                (lease - margin) / 2.0
            ),
        );
    }
    if margin * 2.0 > lease {
        cx.err(
            0,
            r.margin_s.span(),
            format!(
                "[redundancy] margin_s: {margin} s must be at most half of lease_s ({lease} s)"
            ),
        );
    }
    // A dead server's lease runs out after lease_s; a standby tries every
    // renew_s.
    if lease + renew > takeover {
        cx.err(
            0,
            r.takeover_s.span(),
            format!(
                "[redundancy] takeover_s: {takeover} s is shorter than the worst takeover, lease_s + renew_s = {} s",
                lease + renew
            ),
        );
    }
}
