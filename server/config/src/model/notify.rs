//! `[[notify]]`: alarm notification routes. Each route picks alarms (by
//! priority, selection and tag pattern), sends them over one channel (email
//! over SMTP, or a signed webhook) to the contact on call, and escalates to
//! the next contact while the alarm stays unacknowledged.
//!
//! Secrets (the SMTP password, the webhook's HMAC key) are never in the
//! file: the route names the environment variable that holds them.

use serde::Deserialize;
use serde_spanned::Spanned;

/// One notification route.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NotifyConfig {
    /// Unique name: in events, metrics and the route's system alarm.
    pub name: Spanned<String>,
    pub channel: Spanned<NotifyChannel>,
    /// Alarms of at least this priority (0..1000, like alarm priorities).
    #[serde(default = "zero_u32")]
    pub min_priority: Spanned<u32>,
    /// Selection (area) patterns, `*` and `?` wildcards, case-insensitive;
    /// empty: every selection.
    #[serde(default)]
    pub selections: Vec<Spanned<String>>,
    /// Tag (or alarm key) patterns, like `selections`; empty: every tag.
    #[serde(default)]
    pub tags: Vec<Spanned<String>>,
    /// Minutes an alarm may stay unacknowledged before the next contact on
    /// call is notified; absent: no escalation.
    pub escalate_after_min: Option<Spanned<f64>>,
    /// At most this many alarm messages per flood window; more are held and
    /// summed up in one summary at the window's end.
    #[serde(default = "five")]
    pub flood_limit: Spanned<u32>,
    #[serde(default = "sixty")]
    pub flood_window_s: Spanned<u32>,
    /// Minutes a message is retried (with back-off) before it is given up.
    #[serde(default = "one_day_min")]
    pub give_up_after_min: Spanned<u32>,
    /// The HMI's address for the links in messages
    /// (`https://scada.example.com/scada`); absent: `[server] public_origin`
    /// with `base_path`.
    pub hmi_url: Option<Spanned<String>>,
    /// The offset from UTC that the contacts' `on_call` times are in
    /// (`+01:00`); absent: UTC.
    pub utc_offset: Option<Spanned<String>>,
    pub smtp: Option<SmtpConfig>,
    pub webhook: Option<WebhookConfig>,
    /// `[notify.mqtt]`: publishing on the broker of the plant's `[mqtt]`.
    pub mqtt: Option<NotifyMqttConfig>,
    /// The escalation chain, in order.
    #[serde(default, rename = "contact")]
    pub contacts: Vec<ContactConfig>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum NotifyChannel {
    Email,
    Webhook,
    /// Published on the `[mqtt]` broker, a topic per priority band.
    Mqtt,
}

impl NotifyChannel {
    pub fn as_str(self) -> &'static str {
        match self {
            NotifyChannel::Email => "email",
            NotifyChannel::Webhook => "webhook",
            NotifyChannel::Mqtt => "mqtt",
        }
    }
}

/// How the SMTP connection is secured.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SmtpSecurity {
    /// Plain connection upgraded with STARTTLS (required), port 587.
    Starttls,
    /// TLS from the first byte (SMTPS), port 465.
    Tls,
    /// No encryption: only for a relay on the same host or network.
    None,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SmtpConfig {
    pub host: Spanned<String>,
    /// Absent: 587 for STARTTLS, 465 for TLS, 25 for none.
    pub port: Option<Spanned<u16>>,
    pub security: Spanned<SmtpSecurity>,
    /// The sender, `Name <address>` or an address.
    pub from: Spanned<String>,
    pub username: Option<Spanned<String>>,
    /// The environment variable holding the password.
    pub password_env: Option<Spanned<String>>,
    /// A PEM file of CA certificates to trust besides the public roots
    /// (a relay with a private CA); relative to the main file.
    pub ca_file: Option<Spanned<String>>,
}

impl SmtpConfig {
    pub fn port(&self) -> u16 {
        match &self.port {
            Some(p) => *p.get_ref(),
            None => match self.security.get_ref() {
                SmtpSecurity::Starttls => 587,
                SmtpSecurity::Tls => 465,
                SmtpSecurity::None => 25,
            },
        }
    }
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WebhookConfig {
    /// `http://` or `https://` address the JSON is POSTed to.
    pub url: Spanned<String>,
    /// The environment variable holding the HMAC-SHA256 key; the signature
    /// of the body goes in `X-Gridscada-Signature: sha256=<hex>`.
    pub secret_env: Spanned<String>,
    /// A PEM file of CA certificates to trust besides the public roots;
    /// relative to the main file.
    pub ca_file: Option<Spanned<String>>,
}

/// An MQTT route: each message is published (QoS 1) as JSON on
/// `{topic}/{band}`, the band of the alarm's priority (`urgent`, `high`,
/// `medium`, `low`), or `{topic}/summary` for a flood summary, so that a
/// subscriber takes the priorities it wants. The broker, credentials and TLS
/// are the plant's `[mqtt]` (the Sparkplug B connection's settings).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NotifyMqttConfig {
    /// The topic prefix, e.g. `site1/alarms`.
    pub topic: Spanned<String>,
    /// Whether the broker keeps the last message of each topic for new
    /// subscribers.
    #[serde(default)]
    pub retain: bool,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ContactConfig {
    pub name: Spanned<String>,
    /// The email address (email), or the contact's id the receiver knows
    /// (webhook).
    pub address: Spanned<String>,
    /// When the contact is on call (`mon-fri 07:00-19:00`, `19:00-07:00`,
    /// `sat,sun`); empty: always.
    #[serde(default)]
    pub on_call: Vec<Spanned<String>>,
}

fn zero_u32() -> Spanned<u32> {
    Spanned::new(0..0, 0)
}
fn five() -> Spanned<u32> {
    Spanned::new(0..0, 5)
}
fn sixty() -> Spanned<u32> {
    Spanned::new(0..0, 60)
}
fn one_day_min() -> Spanned<u32> {
    Spanned::new(0..0, 1440)
}

/// One on-call window: days of the week and a time of day. A window whose
/// end is before its start runs past midnight into the next day (the days
/// name the day it starts).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct OnCallWindow {
    /// Bit `d` for weekday `d` (0 = Monday).
    pub days: u8,
    /// Minutes after midnight.
    pub start_min: u16,
    /// Minutes after midnight, 1..=1440.
    pub end_min: u16,
}

const DAY_NAMES: [&str; 7] = ["mon", "tue", "wed", "thu", "fri", "sat", "sun"];

impl OnCallWindow {
    /// Reads `[days] [HH:MM-HH:MM]`: days as `mon-fri`, `sat,sun` or `mon`;
    /// either part may be left out (every day; the whole day).
    pub fn parse(text: &str) -> Result<OnCallWindow, String> {
        let mut days = 0u8;
        let mut times = None;
        let parts: Vec<&str> = text.split_whitespace().collect();
        if parts.is_empty() || parts.len() > 2 {
            return Err(format!(
                "'{text}' is not an on-call window like 'mon-fri 07:00-19:00'"
            ));
        }
        for part in parts {
            if part.contains(':') {
                if times.is_some() {
                    return Err(format!("'{text}': two time ranges"));
                }
                times = Some(parse_times(part)?);
            } else {
                if days != 0 {
                    return Err(format!("'{text}': two day lists"));
                }
                days = parse_days(part)?;
            }
        }
        let (start_min, end_min) = times.unwrap_or((0, 1440));
        Ok(OnCallWindow {
            days: if days == 0 { 0x7f } else { days },
            start_min,
            end_min,
        })
    }

    /// Whether the window covers `weekday` (0 = Monday) at `minute` after
    /// midnight, both local.
    pub fn covers(&self, weekday: u8, minute: u16) -> bool {
        let on = |d: u8| self.days & (1 << (d % 7)) != 0;
        if self.start_min < self.end_min {
            on(weekday) && (self.start_min..self.end_min).contains(&minute)
        } else {
            // Past midnight: the evening part today, the morning part from
            // yesterday's window.
            (on(weekday) && minute >= self.start_min)
                || (on((weekday + 6) % 7) && minute < self.end_min)
        }
    }
}

fn parse_days(s: &str) -> Result<u8, String> {
    let day = |d: &str| {
        DAY_NAMES
            .iter()
            .position(|n| n.eq_ignore_ascii_case(d))
            .ok_or_else(|| format!("'{d}' is not a day; use mon, tue, wed, thu, fri, sat, sun"))
    };
    let mut bits = 0u8;
    for item in s.split(',') {
        match item.split_once('-') {
            Some((a, b)) => {
                let (a, b) = (day(a)?, day(b)?);
                let mut d = a;
                loop {
                    bits |= 1 << d;
                    if d == b {
                        break;
                    }
                    d = (d + 1) % 7;
                }
            }
            None => bits |= 1 << day(item)?,
        }
    }
    Ok(bits)
}

fn parse_times(s: &str) -> Result<(u16, u16), String> {
    let (a, b) = s
        .split_once('-')
        .ok_or_else(|| format!("'{s}' is not a time range like 07:00-19:00"))?;
    let hm = |t: &str| -> Result<u16, String> {
        let bad = || format!("'{t}' is not a time of day like 07:30");
        let (h, m) = t.split_once(':').ok_or_else(bad)?;
        let (h, m): (u16, u16) = (h.parse().map_err(|_| bad())?, m.parse().map_err(|_| bad())?);
        if m > 59 || h > 24 || (h == 24 && m != 0) {
            return Err(bad());
        }
        Ok(h * 60 + m)
    };
    let (start, end) = (hm(a)?, hm(b)?);
    if start == end {
        return Err(format!("'{s}' is empty: start and end are the same"));
    }
    if start == 1440 {
        return Err(format!("'{s}' starts at 24:00; start at 00:00"));
    }
    Ok((start, if end == 0 { 1440 } else { end }))
}

/// `+HH:MM` / `-HH:MM` as minutes east of UTC.
pub fn parse_utc_offset(text: &str) -> Result<i32, String> {
    let bad = || format!("'{text}' is not an offset from UTC like +01:00 or -05:30");
    let (sign, rest) = match text.as_bytes().first() {
        Some(b'+') => (1, &text[1..]),
        Some(b'-') => (-1, &text[1..]),
        _ => return Err(bad()),
    };
    let (h, m) = rest.split_once(':').ok_or_else(bad)?;
    let (h, m): (i32, i32) = (h.parse().map_err(|_| bad())?, m.parse().map_err(|_| bad())?);
    if h > 14 || m > 59 {
        return Err(bad());
    }
    Ok(sign * (h * 60 + m))
}

/// Whether `text` matches `pattern` (`*` any run, `?` one character),
/// ignoring ASCII case.
pub fn glob_match(pattern: &str, text: &str) -> bool {
    let p: Vec<char> = pattern.chars().map(|c| c.to_ascii_lowercase()).collect();
    let t: Vec<char> = text.chars().map(|c| c.to_ascii_lowercase()).collect();
    let (mut pi, mut ti) = (0, 0);
    let mut star: Option<(usize, usize)> = None;
    while ti < t.len() {
        if pi < p.len() && (p[pi] == '?' || p[pi] == t[ti]) {
            pi += 1;
            ti += 1;
        } else if pi < p.len() && p[pi] == '*' {
            star = Some((pi, ti));
            pi += 1;
        } else if let Some((sp, st)) = star {
            pi = sp + 1;
            ti = st + 1;
            star = Some((sp, st + 1));
        } else {
            return false;
        }
    }
    p[pi..].iter().all(|&c| c == '*')
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn on_call_windows() {
        let w = OnCallWindow::parse("mon-fri 07:00-19:00").unwrap();
        assert!(w.covers(0, 7 * 60));
        assert!(!w.covers(0, 19 * 60));
        assert!(!w.covers(5, 12 * 60));
        let night = OnCallWindow::parse("fri 19:00-07:00").unwrap();
        assert!(night.covers(4, 23 * 60));
        assert!(
            night.covers(5, 6 * 60),
            "Saturday morning is Friday's night"
        );
        assert!(
            !night.covers(4, 6 * 60),
            "Friday morning is Thursday's night"
        );
        let weekend = OnCallWindow::parse("sat,sun").unwrap();
        assert!(weekend.covers(6, 0) && weekend.covers(5, 1439) && !weekend.covers(0, 0));
        let wrap = OnCallWindow::parse("sat-mon").unwrap();
        assert_eq!(wrap.days, 0b110_0001);
        assert_eq!(OnCallWindow::parse("00:00-24:00").unwrap().days, 0x7f);
        for bad in [
            "",
            "mon funday",
            "25:00-07:00",
            "07:00-07:00",
            "a b c",
            "7-19",
        ] {
            assert!(OnCallWindow::parse(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn offsets_and_patterns() {
        assert_eq!(parse_utc_offset("+01:00"), Ok(60));
        assert_eq!(parse_utc_offset("-05:30"), Ok(-330));
        assert!(parse_utc_offset("01:00").is_err());
        assert!(glob_match("SS1*", "ss1.Zone2.Trip"));
        assert!(glob_match("*.Trip", "SS1.Zone2.Trip"));
        assert!(glob_match("SS?.Zone*", "SS2.Zone1"));
        assert!(!glob_match("SS1*", "SS2.Zone1"));
        assert!(glob_match("*", ""));
        assert!(glob_match("a*b*c", "aXXbYYc") && !glob_match("a*b*c", "aXXbYY"));
    }
}
