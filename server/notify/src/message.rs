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

/// Which server a message comes from: several sites (and both servers of a
/// pair) may feed one mailbox or one webhook, and the reader must tell them
/// apart.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Origin {
    /// `[server] site`.
    pub site: String,
    /// `[redundancy] name`: this server's name in a pair; none alone.
    pub server: Option<String>,
}

impl Origin {
    /// `site` or `site/server`, for a subject line.
    pub fn label(&self) -> String {
        match &self.server {
            Some(s) => format!("{}/{s}", self.site),
            None => self.site.clone(),
        }
    }

    /// The text's lines naming the site (and the server of a pair).
    fn lines(&self) -> String {
        match &self.server {
            Some(s) => format!("Site: {}\nServer: {s}\n", self.site),
            None => format!("Site: {}\n", self.site),
        }
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Message {
    pub kind: MessageKind,
    /// The sending server's site (messages queued before the site was
    /// carried have none).
    #[serde(default)]
    pub site: String,
    /// The sending server's name in a redundant pair.
    #[serde(default)]
    pub server: Option<String>,
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
    origin: &Origin,
    route: &str,
    a: &AlarmInfo,
    link: &str,
    escalated_min: Option<f64>,
) -> Message {
    let a = a.clone();
    let band = priority_name(a.priority);
    let site = origin.label();
    let (kind, subject, lead) = match escalated_min {
        None => (
            MessageKind::Alarm,
            format!("[{band}] {site}: {}: {}", a.selection, a.message),
            String::new(),
        ),
        Some(m) => (
            MessageKind::Escalation,
            format!(
                "[{band}] UNACKNOWLEDGED {site}: {}: {}",
                a.selection, a.message
            ),
            format!("Not acknowledged after {m} min: escalated to you.\n\n"),
        ),
    };
    let text = format!(
        "{lead}{}\n\n{}Priority: {band} ({})\nArea: {}\nAlarm: {}\nTime: {}\n\nOpen the alarm list: {link}\n",
        a.message,
        origin.lines(),
        a.priority,
        a.selection,
        a.key,
        a.time
    );
    Message {
        kind,
        site: origin.site.clone(),
        server: origin.server.clone(),
        route: route.to_string(),
        subject,
        text,
        link: link.to_string(),
        alarm: Some(a),
        held: None,
    }
}

/// The one message of a flood window.
pub fn flood_message(origin: &Origin, route: &str, s: &Summary, link: &str) -> Message {
    let secs = (s.to_ms - s.from_ms) / 1000;
    let mut text = format!(
        "Alarm flood: {} more alarms in {secs} s from {} (after {} sent one by one).\n{}\n",
        s.held,
        utc(Timestamp::from_millis(s.from_ms)),
        s.sent,
        origin.lines()
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
        site: origin.site.clone(),
        server: origin.server.clone(),
        route: route.to_string(),
        subject: format!(
            "ALARM FLOOD {}: {} alarms in {secs} s",
            origin.label(),
            s.held + s.sent
        ),
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

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// An alarm for the message tests of every channel.
    pub(crate) fn alarm() -> AlarmInfo {
        AlarmInfo {
            key: "RTU1:comm".into(),
            tag: None,
            priority: 900,
            selection: "Feeder 2".into(),
            message: "Communication lost with RTU1".into(),
            time_ms: 0,
            time: "1970-01-01T00:00:00Z".into(),
        }
    }

    fn pair() -> Origin {
        Origin {
            site: "substation-7".into(),
            server: Some("scada-b".into()),
        }
    }

    #[test]
    fn an_alarm_names_its_site_and_server_in_subject_and_text() {
        let m = alarm_message(&pair(), "on-call", &alarm(), "https://h/#/alarms", None);
        assert_eq!(
            m.subject,
            "[URGENT] substation-7/scada-b: Feeder 2: Communication lost with RTU1"
        );
        assert!(
            m.text.contains("\nSite: substation-7\nServer: scada-b\n"),
            "{}",
            m.text
        );
        assert_eq!(
            (m.site.as_str(), m.server.as_deref()),
            ("substation-7", Some("scada-b"))
        );
        let alone = Origin {
            site: "main".into(),
            server: None,
        };
        let e = alarm_message(&alone, "on-call", &alarm(), "https://h/#/alarms", Some(5.0));
        assert!(
            e.subject.starts_with("[URGENT] UNACKNOWLEDGED main: "),
            "{}",
            e.subject
        );
        assert!(e.text.contains("\nSite: main\nPriority"), "{}", e.text);
        assert!(!e.text.contains("Server:"), "{}", e.text);
    }

    #[test]
    fn a_flood_summary_names_its_site() {
        let s = Summary {
            from_ms: 0,
            to_ms: 10_000,
            sent: 1,
            held: 3,
            lines: vec!["[LOW] a: b (1970-01-01T00:00:00Z)".into()],
        };
        let m = flood_message(&pair(), "flood", &s, "https://h/#/alarms");
        assert_eq!(
            m.subject,
            "ALARM FLOOD substation-7/scada-b: 4 alarms in 10 s"
        );
        assert!(
            m.text.contains("Site: substation-7\nServer: scada-b\n"),
            "{}",
            m.text
        );
        assert_eq!(m.site, "substation-7");
    }

    #[test]
    fn a_message_queued_before_sites_were_carried_still_reads() {
        let mut old =
            serde_json::to_value(alarm_message(&pair(), "r", &alarm(), "l", None)).unwrap();
        let o = old.as_object_mut().unwrap();
        o.remove("site");
        o.remove("server");
        let m: Message = serde_json::from_value(old).unwrap();
        assert_eq!((m.site.as_str(), m.server), ("", None));
    }
}
