//! Checks of the `[[notify]]` routes: channels with their settings, the
//! selection, escalation and flood limits, the contacts and their on-call
//! windows, and that every message can carry a link into the HMI.

use std::collections::HashMap;

use serde_spanned::Spanned;

use super::Ctx;
use crate::model::*;

pub(super) fn check_notify(cx: &mut Ctx<'_>, main: &MainFile) {
    let mut names: HashMap<&str, &Spanned<String>> = HashMap::new();
    for n in &main.notify {
        let name = n.name.get_ref().as_str();
        let owner = format!("notify '{name}'");
        if name.trim().is_empty() {
            cx.err(0, n.name.span(), "notify: name must not be empty");
        } else if let Some(prev) = names.insert(name, &n.name) {
            let first = cx.place(0, prev.span());
            cx.err(
                0,
                n.name.span(),
                format!("duplicate notify name '{name}' (first defined at {first})"),
            );
        }
        check_route(cx, main, n, &owner);
    }
}

fn check_route(cx: &mut Ctx<'_>, main: &MainFile, n: &NotifyConfig, owner: &str) {
    if *n.min_priority.get_ref() > 1000 {
        cx.err(
            0,
            n.min_priority.span(),
            format!("{owner}: min_priority must be 0 to 1000"),
        );
    }
    for p in n.selections.iter().chain(&n.tags) {
        if p.get_ref().trim().is_empty() {
            cx.err(
                0,
                p.span(),
                format!("{owner}: an empty pattern matches nothing"),
            );
        }
    }
    if let Some(e) = &n.escalate_after_min {
        let m = *e.get_ref();
        if !(m.is_finite() && m > 0.0 && m <= 1440.0) {
            cx.err(
                0,
                e.span(),
                format!("{owner}: escalate_after_min must be more than 0 and at most 1440"),
            );
        } else if n.contacts.len() < 2 {
            cx.err(
                0,
                e.span(),
                format!("{owner}: escalation needs a second [[notify.contact]] to escalate to"),
            );
        }
    }
    if *n.flood_limit.get_ref() == 0 {
        cx.err(
            0,
            n.flood_limit.span(),
            format!("{owner}: flood_limit must be at least 1"),
        );
    }
    if !(10..=3600).contains(n.flood_window_s.get_ref()) {
        cx.err(
            0,
            n.flood_window_s.span(),
            format!("{owner}: flood_window_s must be 10 to 3600 seconds"),
        );
    }
    if !(1..=10_080).contains(n.give_up_after_min.get_ref()) {
        cx.err(
            0,
            n.give_up_after_min.span(),
            format!("{owner}: give_up_after_min must be 1 to 10080 (a week)"),
        );
    }
    match &n.hmi_url {
        Some(u) => {
            let t = u.get_ref();
            if !(t.starts_with("http://") || t.starts_with("https://")) || t.contains(char::is_whitespace)
            {
                cx.err(
                    0,
                    u.span(),
                    format!("{owner}: hmi_url '{t}' must be an http:// or https:// address"),
                );
            }
        }
        None if main.server.public_origin.is_none() => cx.err(
            0,
            n.name.span(),
            format!(
                "{owner}: messages must link into the HMI: set hmi_url here or [server] public_origin"
            ),
        ),
        None => {}
    }
    if let Some(o) = &n.utc_offset {
        if let Err(e) = parse_utc_offset(o.get_ref()) {
            cx.err(0, o.span(), format!("{owner}: utc_offset: {e}"));
        }
    }
    match n.channel.get_ref() {
        NotifyChannel::Email => {
            match &n.smtp {
                Some(s) => check_smtp(cx, s, owner),
                None => cx.err(
                    0,
                    n.channel.span(),
                    format!("{owner}: channel \"email\" needs a [notify.smtp] table"),
                ),
            }
            if n.webhook.is_some() {
                cx.err(
                    0,
                    n.channel.span(),
                    format!("{owner}: [notify.webhook] is for channel \"webhook\"; this route sends email"),
                );
            }
        }
        NotifyChannel::Webhook => {
            match &n.webhook {
                Some(w) => check_webhook(cx, w, owner),
                None => cx.err(
                    0,
                    n.channel.span(),
                    format!("{owner}: channel \"webhook\" needs a [notify.webhook] table"),
                ),
            }
            if n.smtp.is_some() {
                cx.err(
                    0,
                    n.channel.span(),
                    format!("{owner}: [notify.smtp] is for channel \"email\"; this route calls a webhook"),
                );
            }
        }
        NotifyChannel::Mqtt => {
            match &n.mqtt {
                Some(m) => check_mqtt_topic(cx, &m.topic, owner),
                None => cx.err(
                    0,
                    n.channel.span(),
                    format!("{owner}: channel \"mqtt\" needs a [notify.mqtt] table with its topic"),
                ),
            }
            if main.mqtt.is_none() {
                cx.err(
                    0,
                    n.channel.span(),
                    format!("{owner}: channel \"mqtt\" publishes on the broker of [mqtt], which is not configured"),
                );
            }
            if n.smtp.is_some() || n.webhook.is_some() {
                cx.err(
                    0,
                    n.channel.span(),
                    format!("{owner}: [notify.smtp] and [notify.webhook] are for the other channels; this route publishes on MQTT"),
                );
            }
        }
    }
    if n.mqtt.is_some() && *n.channel.get_ref() != NotifyChannel::Mqtt {
        cx.err(
            0,
            n.channel.span(),
            format!("{owner}: [notify.mqtt] is for channel \"mqtt\""),
        );
    }
    if n.contacts.is_empty() {
        cx.err(
            0,
            n.name.span(),
            format!("{owner}: needs at least one [[notify.contact]]"),
        );
    }
    let mut seen: HashMap<&str, &Spanned<String>> = HashMap::new();
    for c in &n.contacts {
        let cname = c.name.get_ref().as_str();
        if let Some(prev) = seen.insert(cname, &c.name) {
            let first = cx.place(0, prev.span());
            cx.err(
                0,
                c.name.span(),
                format!("{owner}: duplicate contact '{cname}' (first defined at {first})"),
            );
        }
        let a = c.address.get_ref();
        let bad_address = match n.channel.get_ref() {
            NotifyChannel::Email => !is_address(a),
            NotifyChannel::Webhook | NotifyChannel::Mqtt => a.trim().is_empty(),
        };
        if bad_address {
            cx.err(
                0,
                c.address.span(),
                format!("{owner}: contact '{cname}': '{a}' is not an address for this channel"),
            );
        }
        for w in &c.on_call {
            if let Err(e) = OnCallWindow::parse(w.get_ref()) {
                cx.err(
                    0,
                    w.span(),
                    format!("{owner}: contact '{cname}': on_call {e}"),
                );
            }
        }
    }
}

fn check_smtp(cx: &mut Ctx<'_>, s: &SmtpConfig, owner: &str) {
    if s.host.get_ref().trim().is_empty() {
        cx.err(
            0,
            s.host.span(),
            format!("{owner}: smtp host must not be empty"),
        );
    }
    if s.port.as_ref().is_some_and(|p| *p.get_ref() == 0) {
        cx.err(
            0,
            s.port.as_ref().unwrap().span(),
            format!("{owner}: smtp port 0"),
        );
    }
    let from = s.from.get_ref();
    let address = from
        .rsplit_once('<')
        .and_then(|(_, a)| a.strip_suffix('>'))
        .unwrap_or(from);
    if !is_address(address) {
        cx.err(
            0,
            s.from.span(),
            format!(
                "{owner}: smtp from '{from}' is not an address like 'SCADA <scada@example.com>'"
            ),
        );
    }
    match (&s.username, &s.password_env) {
        (Some(u), None) => cx.err(
            0,
            u.span(),
            format!(
                "{owner}: smtp username needs password_env (the variable holding the password)"
            ),
        ),
        (None, Some(p)) => cx.err(
            0,
            p.span(),
            format!("{owner}: smtp password_env needs a username"),
        ),
        _ => {}
    }
    if let Some(p) = &s.password_env {
        env_name(cx, p, owner, "password_env");
    }
    if *s.security.get_ref() == SmtpSecurity::None && s.username.is_some() {
        cx.err(
            0,
            s.security.span(),
            format!("{owner}: a password is never sent unencrypted: use security \"starttls\" or \"tls\""),
        );
    }
}

fn check_webhook(cx: &mut Ctx<'_>, w: &WebhookConfig, owner: &str) {
    let u = w.url.get_ref();
    let rest = u
        .strip_prefix("https://")
        .or_else(|| u.strip_prefix("http://"));
    if rest.is_none_or(|r| r.is_empty() || r.starts_with('/') || r.contains(char::is_whitespace)) {
        cx.err(
            0,
            w.url.span(),
            format!("{owner}: webhook url '{u}' must be an http:// or https:// address"),
        );
    }
    env_name(cx, &w.secret_env, owner, "secret_env");
}

fn env_name(cx: &mut Ctx<'_>, v: &Spanned<String>, owner: &str, field: &str) {
    let n = v.get_ref();
    let ok = !n.is_empty()
        && !n.starts_with(|c: char| c.is_ascii_digit())
        && n.chars().all(|c| c.is_ascii_alphanumeric() || c == '_');
    if !ok {
        cx.err(
            0,
            v.span(),
            format!("{owner}: {field} '{n}' is not an environment variable name like GRIDSCADA_SMTP_PASSWORD"),
        );
    }
}

fn is_address(a: &str) -> bool {
    match a.split_once('@') {
        Some((local, domain)) => {
            !local.is_empty()
                && !domain.is_empty()
                && !domain.contains('@')
                && !a.contains(|c: char| c.is_whitespace() || c == '<' || c == '>')
        }
        None => false,
    }
}

/// An MQTT topic prefix: levels without wildcards, not the Sparkplug B
/// namespace (whose topics the host and edge nodes own).
fn check_mqtt_topic(cx: &mut Ctx<'_>, topic: &Spanned<String>, owner: &str) {
    let t = topic.get_ref();
    let why = if t.is_empty() {
        Some("is empty")
    } else if t.contains(['+', '#']) {
        Some("must not hold the wildcards + or #")
    } else if t.starts_with('/') || t.ends_with('/') || t.contains("//") {
        Some("must not start or end with / or have an empty level")
    } else if t.starts_with('$') || t.starts_with("spBv1.0") {
        Some("must not be in the broker's $ topics or the Sparkplug B namespace spBv1.0")
    } else if t.len() > 200 || t.contains('\0') {
        Some("is longer than 200 bytes or holds a NUL")
    } else {
        None
    };
    if let Some(why) = why {
        cx.err(0, topic.span(), format!("{owner}: mqtt topic '{t}' {why}"));
    }
}
