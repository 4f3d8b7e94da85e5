//! What a notification says: the subject, the text (with the link into the
//! HMI), and the alarm's fields for a webhook's receiver. Rendered once,
//! when queued, and kept in the outbox as JSON.

use gridscada_alarms::AlarmTransition;
use gridscada_tagdb::Timestamp;
use serde::{Deserialize, Serialize};

use crate::flood::Summary;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MessageKind {
    /// An alarm came in.
    Alarm,
    /// An alarm is still unacknowledged: told to the next contact.
    Escalation,
    /// A flood window's held alarms.
    FloodSummary,
}

/// The alarm a message is about.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AlarmInfo {
    pub key: String,
    pub tag: Option<String>,
    pub priority: u32,
    pub selection: String,
    pub message: String,
    /// When it activated (ms since the epoch, and as RFC 3339 UTC).
    pub time_ms: i64,
    pub time: String,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Message {
    pub kind: MessageKind,
    pub route: String,
    pub subject: String,
    /// The plain text, ending with the link.
    pub text: String,
    /// The HMI's alarm list.
    pub link: String,
    pub alarm: Option<AlarmInfo>,
    /// A flood summary's count of held alarms.
    pub held: Option<u32>,
}

/// The band name of an alarm priority (the HMI's bands).
pub fn priority_name(p: u32) -> &'static str {
    match p {
        800.. => "URGENT",
        600..=799 => "HIGH",
        400..=599 => "MEDIUM",
        _ => "LOW",
    }
}

/// RFC 3339 UTC, to the second.
pub fn utc(t: Timestamp) -> String {
    let c = t.civil_utc();
    format!(
        "{:04}-{:02}-{:02}T{:02}:{:02}:{:02}Z",
        c.year, c.month, c.day, c.hour, c.minute, c.second
    )
}

/// The link into the HMI's alarm list under `hmi_base`.
pub fn alarm_link(hmi_base: &str) -> String {
    format!("{}/#/alarms", hmi_base.trim_end_matches('/'))
}

/// The alarm of a transition.
pub fn info(t: &AlarmTransition) -> AlarmInfo {
    AlarmInfo {
        key: t.key.clone(),
        tag: t.tag.clone(),
        priority: t.priority,
        selection: t.selection.clone(),
        message: t.message.clone(),
        time_ms: t.time.as_millis(),
        time: utc(t.time),
    }
}

/// The message of an alarm (escalated: unacknowledged for `escalated_min`).
pub fn alarm_message(
    route: &str,
    a: &AlarmInfo,
    link: &str,
    escalated_min: Option<f64>,
) -> Message {
    let a = a.clone();
    let band = priority_name(a.priority);
    let (kind, subject, lead) = match escalated_min {
        None => (
            MessageKind::Alarm,
            format!("[{band}] {}: {}", a.selection, a.message),
            String::new(),
        ),
        Some(m) => (
            MessageKind::Escalation,
            format!("[{band}] UNACKNOWLEDGED {}: {}", a.selection, a.message),
            format!("Not acknowledged after {m} min: escalated to you.\n\n"),
        ),
    };
    let text = format!(
        "{lead}{}\n\nPriority: {band} ({})\nArea: {}\nAlarm: {}\nTime: {}\n\nOpen the alarm list: {link}\n",
        a.message, a.priority, a.selection, a.key, a.time
    );
    Message {
        kind,
        route: route.to_string(),
        subject,
        text,
        link: link.to_string(),
        alarm: Some(a),
        held: None,
    }
}

/// The one message of a flood window.
pub fn flood_message(route: &str, s: &Summary, link: &str) -> Message {
    let secs = (s.to_ms - s.from_ms) / 1000;
    let mut text = format!(
        "Alarm flood: {} more alarms in {secs} s from {} (after {} sent one by one).\n\n",
        s.held,
        utc(Timestamp::from_millis(s.from_ms)),
        s.sent
    );
    for l in &s.lines {
        text.push_str("- ");
        text.push_str(l);
        text.push('\n');
    }
    if s.held as usize > s.lines.len() {
        text.push_str(&format!("- and {} more\n", s.held as usize - s.lines.len()));
    }
    text.push_str(&format!("\nOpen the alarm list: {link}\n"));
    Message {
        kind: MessageKind::FloodSummary,
        route: route.to_string(),
        subject: format!("ALARM FLOOD: {} alarms in {secs} s", s.held + s.sent),
        text,
        link: link.to_string(),
        alarm: None,
        held: Some(s.held),
    }
}

/// A held alarm's line in a flood summary.
pub fn summary_line(t: &AlarmTransition) -> String {
    format!(
        "[{}] {}: {} ({})",
        priority_name(t.priority),
        t.selection,
        t.message,
        utc(t.time)
    )
}
