//! `[opcua]`: the listen address, the announced host name, the endpoints
//! offered, the certificate store's folder and the caps on connections.

use std::collections::HashSet;
use std::net::SocketAddr;

use crate::model::*;

use super::Ctx;

pub(super) fn check_opcua(cx: &mut Ctx<'_>, main: &MainFile, ua: &OpcUaConfig) {
    let listen = &ua.listen;
    match listen.get_ref().parse::<SocketAddr>() {
        Err(_) => cx.err(
            0,
            listen.span(),
            format!(
                "[opcua] listen: '{}' is not an address like 0.0.0.0:4840",
                listen.get_ref()
            ),
        ),
        Ok(addr) => {
            let http = main.server.http.get_ref().parse::<SocketAddr>().ok();
            if http.is_some_and(|h| h.port() == addr.port() && addr.port() != 0) {
                cx.err(
                    0,
                    listen.span(),
                    format!(
                        "[opcua] listen: port {} is the HMI's ([server] http); give OPC UA its own (4840 is usual)",
                        addr.port()
                    ),
                );
            }
        }
    }
    if let Some(host) = &ua.host {
        let h = host.get_ref();
        let ok = !h.is_empty()
            && h.len() <= 253
            && h.chars().all(|c| {
                c.is_ascii_alphanumeric() || matches!(c, '.' | '-' | '_' | ':' | '[' | ']')
            });
        if !ok {
            cx.err(
                0,
                host.span(),
                format!("[opcua] host: '{h}' is not a host name or IP address clients can resolve"),
            );
        }
    }
    let security = ua.security.get_ref();
    if security.is_empty() {
        cx.err(
            0,
            ua.security.span(),
            "[opcua] security: offer at least one endpoint (\"basic256sha256-sign-encrypt\" is the safe choice)",
        );
    }
    let mut seen = HashSet::new();
    for s in security {
        if !seen.insert(*s) {
            cx.err(
                0,
                ua.security.span(),
                format!("[opcua] security: '{}' is listed twice", s.label()),
            );
        }
    }
    let pki = ua.pki_dir.get_ref();
    if pki.trim().is_empty() {
        cx.err(
            0,
            ua.pki_dir.span(),
            "[opcua] pki_dir: must name a folder (relative to the data folder)",
        );
    }
    let max = &ua.max_connections;
    let per = &ua.max_connections_per_client;
    if !(1..=10_000).contains(max.get_ref()) {
        cx.err(
            0,
            max.span(),
            format!(
                "[opcua] max_connections: {} is out of range; 1 to 10000 open connections",
                max.get_ref()
            ),
        );
    } else if *per.get_ref() == 0 || (per.get_ref() > max.get_ref() && !per.span().is_empty()) {
        // The default per-client cap is lowered to a smaller max_connections
        // (`OpcUaConfig::per_client_cap`); only a written one is wrong.
        cx.err(
            0,
            per.span(),
            format!(
                "[opcua] max_connections_per_client: {} must be 1 to max_connections ({})",
                per.get_ref(),
                max.get_ref()
            ),
        );
    }
}
