//! Semantic checks across the whole configuration.
//!
//! This file holds the walk over the whole configuration ([`check`]), the
//! main file's own settings, and the helpers the checks share (the error
//! context, a tag a panel or the microgrid needs, a positive duration). Each
//! kind of item is checked in its own file: devices `devices.rs`, tags
//! `tags.rs`, their alarms `alarms.rs`, register overlaps `overlaps.rs`,
//! device clocks `clocks.rs`, panels `panels.rs`, the microgrid
//! `microgrid.rs`, the redundant pair and the site `redundancy.rs`, the MQTT northbound `mqtt.rs` and
//! `mqtt_host.rs`, the OPC UA server `opcua.rs`, alarm notification
//! routes `notify.rs`, the switching network `network.rs`.

use std::collections::HashMap;
use std::net::SocketAddr;
use std::ops::Range;

use gridscada_tagdb::ValueKind;
use serde_spanned::Spanned;

use crate::diag::{Diagnostic, SourceFile};
use crate::model::*;

mod alarms;
mod clocks;
mod devices;
pub mod iec61850;
mod microgrid;
mod mqtt;
mod mqtt_host;
mod network;
mod notify;
mod opcua;
mod overlaps;
mod panels;
mod redundancy;
mod tags;
mod telecontrol;

use clocks::check_time_tags;
use devices::check_device;
use microgrid::check_microgrid;
use mqtt_host::check_mqtt_host;
use notify::check_notify;
use opcua::check_opcua;
use overlaps::{check_dnp3_index_reuse, check_ioa_reuse, check_overlaps};
use panels::check_panel;
use tags::{check_tag, check_tag_name};

struct Ctx<'a> {
    files: &'a [SourceFile],
    diags: &'a mut Vec<Diagnostic>,
}

impl Ctx<'_> {
    fn err(&mut self, file: usize, span: Range<usize>, msg: impl Into<String>) {
        let d = self.files[file].error_at(span, msg);
        self.diags.push(d);
    }
    fn place(&self, file: usize, span: Range<usize>) -> String {
        let f = &self.files[file];
        let (l, c) = f.line_col(span.start);
        format!("{}:{l}:{c}", f.path.display())
    }
}

/// `files[0]` is the main file; items carry the index of their file.
pub(crate) fn check(
    files: &[SourceFile],
    main: &MainFile,
    devices: &[(usize, DeviceConfig)],
    broken_devices: &std::collections::HashSet<String>,
    tags: &[(usize, TagConfig)],
    diags: &mut Vec<Diagnostic>,
) {
    let mut cx = Ctx { files, diags };
    check_main(&mut cx, main);
    check_notify(&mut cx, main);

    let mut device_by_name: HashMap<&str, (usize, &DeviceConfig)> = HashMap::new();
    for (f, d) in devices {
        check_device(&mut cx, *f, d);
        let name = d.name.get_ref().as_str();
        if let Some((pf, prev)) = device_by_name.get(name) {
            let first = cx.place(*pf, prev.name.span());
            cx.err(
                *f,
                d.name.span(),
                format!("duplicate device name '{name}' (first defined at {first})"),
            );
        } else {
            device_by_name.insert(name, (*f, d));
        }
    }
    devices::check_serial_sharing(&mut cx, devices);

    let mut tag_by_name: HashMap<&str, (usize, &TagConfig)> = HashMap::new();
    for (f, t) in tags {
        let name = t.name.get_ref().as_str();
        check_tag_name(&mut cx, *f, &t.name);
        if let Some((pf, prev)) = tag_by_name.get(name) {
            let first = cx.place(*pf, prev.name.span());
            cx.err(
                *f,
                t.name.span(),
                format!("duplicate tag name '{name}' (first defined at {first})"),
            );
        } else {
            tag_by_name.insert(name, (*f, t));
        }
        match device_by_name.get(t.device.get_ref().as_str()) {
            Some((_, d)) => check_tag(&mut cx, *f, t, Some(d)),
            // Its device did not parse: that is reported once, at the device.
            None if broken_devices.contains(t.device.get_ref()) => check_tag(&mut cx, *f, t, None),
            None => {
                cx.err(
                    *f,
                    t.device.span(),
                    format!("tag '{name}': unknown device '{}'", t.device.get_ref()),
                );
                check_tag(&mut cx, *f, t, None);
            }
        }
    }
    check_overlaps(&mut cx, tags);
    check_ioa_reuse(&mut cx, tags);
    check_dnp3_index_reuse(&mut cx, tags);
    iec61850::check_against_scl(&mut cx, devices, tags);
    check_time_tags(&mut cx, devices, tags, &device_by_name, &tag_by_name);

    let lookup = |name: &str| tag_by_name.get(name).map(|(_, t)| *t);
    let device = |name: &str| device_by_name.get(name).map(|(_, d)| *d);
    let mut panel_ids: HashMap<&str, &Spanned<String>> = HashMap::new();
    for p in &main.panels {
        if let Some(prev) = panel_ids.insert(p.id.get_ref(), &p.id) {
            let first = cx.place(0, prev.span());
            cx.err(
                0,
                p.id.span(),
                format!(
                    "duplicate panel id '{}' (first defined at {first})",
                    p.id.get_ref()
                ),
            );
        }
        check_panel(&mut cx, p, &lookup, &device);
    }
    if let Some(mg) = &main.microgrid {
        check_microgrid(&mut cx, mg, &lookup);
    }
    if let Some(server) = &main.iec104_server {
        telecontrol::check_iec104_server(&mut cx, server, &lookup);
    }
    if let Some(net) = &main.network {
        network::check_network(&mut cx, net, main, &lookup);
    }
    alarms::check_suppression(&mut cx, &main.suppression, tags, &lookup, &|d| {
        device_by_name.contains_key(d)
    });
    if let Some(m) = &main.mqtt {
        mqtt::check_mqtt(&mut cx, m, &device_by_name, &tag_by_name);
    }
    check_access(&mut cx, main, &tag_by_name);
}

/// `[server.access.GROUP]`: the group's name, and its write grants. On a
/// central host a grant may name remote tags, which no tag file holds.
fn check_access(cx: &mut Ctx<'_>, main: &MainFile, tags: &HashMap<&str, (usize, &TagConfig)>) {
    let remote = main.mqtt.as_ref().is_some_and(|m| m.host.is_some());
    for (group, access) in &main.server.access {
        if !crate::is_account_name(group.get_ref()) {
            cx.err(
                0,
                group.span(),
                format!(
                    "[server.access] '{}': a group name needs 1 to 64 printable characters, without spaces at either end",
                    group.get_ref().escape_debug()
                ),
            );
            continue;
        }
        let what = format!("[server.access.{}] write", group.get_ref());
        check_write_patterns(cx, &what, &access.write, tags, remote);
    }
}

/// Tag patterns that allow writes (`[mqtt.edge] commands`,
/// `[server.access.GROUP] write`): each a tag name or a prefix ending in
/// `*`, naming a writable tag of the tag files (or, with `remote`, possibly
/// a tag no file holds).
fn check_write_patterns(
    cx: &mut Ctx<'_>,
    what: &str,
    patterns: &[Spanned<String>],
    tags: &HashMap<&str, (usize, &TagConfig)>,
    remote: bool,
) {
    for pattern in patterns {
        let p = pattern.get_ref();
        if p.is_empty() || p.strip_suffix('*').is_some_and(|s| s.contains('*')) {
            cx.err(
                0,
                pattern.span(),
                format!("{what}: '{p}' must be a tag name or a prefix ending in '*'"),
            );
            continue;
        }
        let writable = |t: &TagConfig| *t.writable.get_ref();
        let matched: Vec<&TagConfig> = tags
            .iter()
            .filter(|(name, _)| crate::pattern_matches(p, name))
            .map(|(_, (_, t))| *t)
            .collect();
        if matched.is_empty() {
            if !remote {
                cx.err(
                    0,
                    pattern.span(),
                    format!("{what}: '{p}' names no tag of the tag files"),
                );
            }
        } else if !p.ends_with('*') && !matched.iter().copied().any(writable) {
            cx.err(
                0,
                pattern.span(),
                format!("{what}: tag '{p}' is not writable"),
            );
        } else if !matched.iter().copied().any(writable) {
            cx.err(
                0,
                pattern.span(),
                format!("{what}: '{p}' matches no writable tag"),
            );
        }
    }
}

/// `public_origin`, `trusted_proxies`, `forwarded_header` and `base_path`
/// (`model/proxy.rs`).
fn check_proxy(cx: &mut Ctx<'_>, server: &crate::ServerConfig) {
    if let Some(o) = &server.public_origin {
        if let Err(why) = crate::normal_public_origin(o.get_ref()) {
            cx.err(0, o.span(), format!("[server] public_origin: {why}"));
        }
    }
    for c in &server.trusted_proxies {
        if let Err(why) = crate::Cidr::parse(c.get_ref()) {
            cx.err(
                0,
                c.span(),
                format!(
                    "[server] trusted_proxies: {why} (write a block like 10.0.0.0/8 or ::1/128)"
                ),
            );
        }
    }
    if let Some(h) = &server.forwarded_header {
        if let Err(why) = crate::ForwardedHeader::parse(h.get_ref()) {
            cx.err(0, h.span(), format!("[server] forwarded_header: {why}"));
        }
    }
    if let Some(b) = &server.base_path {
        if let Err(why) = crate::normal_base_path(b.get_ref()) {
            cx.err(0, b.span(), format!("[server] base_path: {why}"));
        }
    }
}

/// `[server.connections]`: caps of at least one connection, a per-client
/// cap within the global one, timeouts of a tenth of a second to five
/// minutes (longer ones are what slow clients feed on).
fn check_connections(cx: &mut Ctx<'_>, c: &crate::ConnectionsConfig) {
    let max_open = *c.max_open.get_ref();
    if max_open == 0 {
        cx.err(
            0,
            c.max_open.span(),
            "[server.connections] max_open: must be at least 1",
        );
    }
    let per_client = *c.max_per_client.get_ref();
    if per_client == 0 || per_client > max_open.max(1) {
        cx.err(
            0,
            c.max_per_client.span(),
            format!("[server.connections] max_per_client: {per_client} must be 1 to max_open ({max_open})"),
        );
    }
    for (key, secs) in [
        ("header_timeout_s", &c.header_timeout_s),
        ("tls_handshake_timeout_s", &c.tls_handshake_timeout_s),
    ] {
        let s = *secs.get_ref();
        if !(s.is_finite() && (0.1..=300.0).contains(&s)) {
            cx.err(
                0,
                secs.span(),
                format!("[server.connections] {key}: {s} must be 0.1 to 300 seconds"),
            );
        }
    }
}

/// `[server.tls]` as written; the files themselves are read (and their
/// certificate matched to their key) when the server starts or `gridscada
/// check` runs, by the web crate's TLS loader.
fn check_tls(cx: &mut Ctx<'_>, tls: &TlsConfig, http: &Spanned<String>) {
    for (key, path) in [("cert", &tls.cert), ("key", &tls.key)] {
        if path.get_ref().trim().is_empty() {
            cx.err(
                0,
                path.span(),
                format!("[server.tls] {key}: empty; name a PEM file"),
            );
        }
    }
    if let Some(addr) = &tls.redirect_http {
        if addr.get_ref().parse::<SocketAddr>().is_err() {
            cx.err(
                0,
                addr.span(),
                format!(
                    "[server.tls] redirect_http: '{}' is not an address like 0.0.0.0:80",
                    addr.get_ref()
                ),
            );
        } else if addr.get_ref().parse::<SocketAddr>().ok() == http.get_ref().parse().ok() {
            cx.err(
                0,
                addr.span(),
                format!(
                    "[server.tls] redirect_http: {} is [server] http itself, where HTTPS is served; give the plain-HTTP address (e.g. port 80)",
                    addr.get_ref()
                ),
            );
        }
    }
}

/// The form of an ISO 4217 code: three capital letters (whether the code is
/// assigned is not checked: a new one must not need a new release).
fn is_currency_code(code: &str) -> bool {
    code.len() == 3 && code.bytes().all(|b| b.is_ascii_uppercase())
}

fn check_main(cx: &mut Ctx<'_>, main: &MainFile) {
    let http = &main.server.http;
    if http.get_ref().parse::<SocketAddr>().is_err() {
        cx.err(
            0,
            http.span(),
            format!(
                "[server] http: '{}' is not an address like 127.0.0.1:8080",
                http.get_ref()
            ),
        );
    }
    if let Some(tls) = &main.server.tls {
        check_tls(cx, tls, &main.server.http);
    }
    check_proxy(cx, &main.server);
    redundancy::check_site(cx, &main.server);
    if let Some(r) = &main.redundancy {
        redundancy::check_redundancy(cx, r, &main.storage);
    }
    if let Some(ua) = &main.opcua {
        check_opcua(cx, main, ua);
    }
    let delay = &main.reports.delay_min;
    if !(delay.get_ref().is_finite() && (0.0..=1440.0).contains(delay.get_ref())) {
        cx.err(
            0,
            delay.span(),
            format!(
                "[reports] delay_min: {} must be 0 to 1440 minutes",
                delay.get_ref()
            ),
        );
    }
    if let Some(currency) = &main.reports.currency {
        if !is_currency_code(currency.get_ref()) {
            cx.err(
                0,
                currency.span(),
                format!(
                    "[reports] currency: '{}' is not an ISO 4217 currency code: three capital letters, like EUR or USD",
                    currency.get_ref()
                ),
            );
        }
    }
    let sessions = &main.server.sessions;
    for (role, minutes) in sessions.idle_minutes.get_ref() {
        if !(minutes.is_finite() && (0.0..=10_080.0).contains(minutes)) {
            cx.err(
                0,
                sessions.idle_minutes.span(),
                format!(
                    "[server.sessions] idle_minutes.{}: {minutes} must be 0 (never) to 10080 (a week)",
                    role.label()
                ),
            );
        }
    }
    let hours = *sessions.absolute_hours.get_ref();
    if !(hours.is_finite() && (0.0..=720.0).contains(&hours)) {
        cx.err(
            0,
            sessions.absolute_hours.span(),
            format!("[server.sessions] absolute_hours: {hours} must be 0 (never) to 720"),
        );
    }
    if *sessions.warn_s.get_ref() > 3600 {
        cx.err(
            0,
            sessions.warn_s.span(),
            "[server.sessions] warn_s: at most 3600 seconds",
        );
    }
    let wait = *sessions.store_wait_ms.get_ref();
    if !(10..=10_000).contains(&wait) {
        cx.err(
            0,
            sessions.store_wait_ms.span(),
            format!("[server.sessions] store_wait_ms: {wait} must be 10 to 10000 milliseconds"),
        );
    }
    let url = &main.storage.url;
    let u = url.get_ref();
    if !(u.starts_with("sqlite:") || u.starts_with("postgres://") || u.starts_with("postgresql://"))
    {
        cx.err(
            0,
            url.span(),
            format!("[storage] url: '{u}' must start with sqlite:, postgres:// or postgresql://"),
        );
    }
    check_connections(cx, &main.server.connections);
    let decimals = &main.hmi.decimals;
    if !(0..=i64::from(MAX_DECIMALS)).contains(decimals.get_ref()) {
        cx.err(
            0,
            decimals.span(),
            format!(
                "[hmi] decimals: {} must be 0 to {MAX_DECIMALS}",
                decimals.get_ref()
            ),
        );
    }
    let merge = &main.server.live_merge_ms;
    if *merge.get_ref() > 1_000 {
        cx.err(
            0,
            merge.span(),
            format!(
                "[server] live_merge_ms: {} ms is more than a second; screens would lag (0 sends each change at once)",
                merge.get_ref()
            ),
        );
    }
    let r = &main.storage.retention;
    for (key, days) in [
        ("events_days", &r.events_days),
        ("alarm_history_days", &r.alarm_history_days),
        ("dispatch_days", &r.dispatch_days),
        ("minute_days", &r.minute_days),
        ("hour_days", &r.hour_days),
    ] {
        if *days.get_ref() > 36_500 {
            cx.err(
                0,
                days.span(),
                format!(
                    "[storage.retention] {key}: {} days is more than 100 years; 0 keeps for ever",
                    days.get_ref()
                ),
            );
        }
    }
    if let Some(mqtt) = &main.mqtt {
        check_mqtt_host(cx, mqtt);
    }
    // A central Sparkplug host may have no devices of its own.
    let central = main.mqtt.as_ref().is_some_and(|m| m.host.is_some());
    if main.tag_files.is_empty() && !central {
        cx.err(
            0,
            0..0,
            "tag_files is empty: a plant needs at least one tag file (or [mqtt.host], a central host)",
        );
    }
}

fn need_tag<'t>(
    cx: &mut Ctx<'_>,
    at: Range<usize>,
    owner: &str,
    tag: &str,
    lookup: &dyn Fn(&str) -> Option<&'t TagConfig>,
    want: &[ValueKind],
    writable: bool,
) {
    match lookup(tag) {
        None => cx.err(
            0,
            at,
            format!("{owner}: needs tag '{tag}', which no tag file defines"),
        ),
        Some(t) => {
            let k = t.value_kind();
            if !want.contains(&k) {
                cx.err(
                    0,
                    at.clone(),
                    format!("{owner}: tag '{tag}' must be {want:?}, but it is {k:?}"),
                );
            }
            if writable && !*t.writable.get_ref() {
                cx.err(
                    0,
                    at,
                    format!("{owner}: tag '{tag}' is a command output and must be writable"),
                );
            }
        }
    }
}

fn positive(cx: &mut Ctx<'_>, owner: &str, field: &str, v: &Spanned<f64>) {
    if !(v.get_ref().is_finite() && *v.get_ref() > 0.0) {
        cx.err(
            0,
            v.span(),
            format!("{owner}: {field} must be a positive number of seconds"),
        );
    }
}
