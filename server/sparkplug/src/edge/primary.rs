//! Following the primary host application's `STATE` (Sparkplug 3.0): the
//! edge births only while the host it names in `primary_host_id` says it is
//! online, so that data is never published to a host that is not there.
//!
//! A STATE is the retained JSON `{"online": bool, "timestamp": ms}`; its
//! timestamp is the host's session (its birth and its will carry the same
//! one). A STATE older than the last one taken is ignored: a will of an
//! earlier host session may arrive after the host's new birth, and must not
//! end the edge's session.

use crate::topic::Topic;

/// What a STATE message means for the edge.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Verdict {
    /// The primary host is online (this session of it, or a newer one).
    Online,
    /// The primary host is offline (its will, or an orderly stop).
    Offline,
    /// Older than the last STATE taken: ignored.
    Stale { timestamp: i64, last: i64 },
    /// Not a Sparkplug 3.0 STATE body.
    Malformed(String),
}

/// The primary host's STATE as the edge last took it.
#[derive(Debug, Clone)]
pub struct PrimaryHost {
    pub host_id: String,
    topic: String,
    /// The timestamp of the last STATE taken (kept across sessions).
    last: Option<i64>,
    online: bool,
}

impl PrimaryHost {
    pub fn new(host_id: &str) -> PrimaryHost {
        PrimaryHost {
            host_id: host_id.to_owned(),
            topic: Topic::State {
                host_id: host_id.to_owned(),
            }
            .to_string(),
            last: None,
            online: false,
        }
    }

    /// `spBv1.0/STATE/<host id>`.
    pub fn topic(&self) -> &str {
        &self.topic
    }

    /// Whether the last STATE taken said online.
    pub fn online(&self) -> bool {
        self.online
    }

    /// A new broker session: the host must be seen online on it again (its
    /// retained STATE comes right after the subscription).
    pub fn new_session(&mut self) {
        self.online = false;
    }

    /// Takes a STATE message, unless it is older than the last one taken
    /// (an equal timestamp is taken: a host's will carries its birth's).
    pub fn observe(&mut self, body: &[u8]) -> Verdict {
        let (online, timestamp) = match parse(body) {
            Ok(state) => state,
            Err(why) => return Verdict::Malformed(why),
        };
        if let Some(last) = self.last.filter(|last| timestamp < *last) {
            return Verdict::Stale { timestamp, last };
        }
        self.last = Some(timestamp);
        self.online = online;
        if online {
            Verdict::Online
        } else {
            Verdict::Offline
        }
    }
}

/// `{"online": bool, "timestamp": integer}`, or why not.
fn parse(body: &[u8]) -> Result<(bool, i64), String> {
    let value: serde_json::Value =
        serde_json::from_slice(body).map_err(|e| format!("STATE is not JSON ({e})"))?;
    let online = value
        .get("online")
        .and_then(|v| v.as_bool())
        .ok_or("STATE has no boolean 'online'")?;
    let timestamp = value
        .get("timestamp")
        .and_then(|v| v.as_i64())
        .ok_or("STATE has no integer 'timestamp' (UTC milliseconds)")?;
    Ok((online, timestamp))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn state(online: bool, timestamp: i64) -> Vec<u8> {
        serde_json::json!({ "online": online, "timestamp": timestamp })
            .to_string()
            .into_bytes()
    }

    #[test]
    fn the_topic_names_the_host() {
        assert_eq!(PrimaryHost::new("scada").topic(), "spBv1.0/STATE/scada");
    }

    #[test]
    fn online_then_its_will_then_a_newer_session() {
        let mut host = PrimaryHost::new("scada");
        assert!(!host.online());
        assert_eq!(host.observe(&state(true, 1000)), Verdict::Online);
        assert!(host.online());
        // The will carries the birth's timestamp: taken.
        assert_eq!(host.observe(&state(false, 1000)), Verdict::Offline);
        assert!(!host.online());
        assert_eq!(host.observe(&state(true, 2000)), Verdict::Online);
        assert!(host.online());
    }

    #[test]
    fn an_older_state_is_ignored() {
        let mut host = PrimaryHost::new("scada");
        assert_eq!(host.observe(&state(true, 2000)), Verdict::Online);
        // A late will of the host's earlier session.
        assert_eq!(
            host.observe(&state(false, 1000)),
            Verdict::Stale {
                timestamp: 1000,
                last: 2000
            }
        );
        assert!(host.online());
        assert_eq!(host.observe(&state(false, 2000)), Verdict::Offline);
        // A stale online does not bring it back.
        assert!(matches!(
            host.observe(&state(true, 1500)),
            Verdict::Stale { .. }
        ));
        assert!(!host.online());
    }

    #[test]
    fn a_new_session_waits_for_the_state_again() {
        let mut host = PrimaryHost::new("scada");
        host.observe(&state(true, 1000));
        host.new_session();
        assert!(!host.online());
        // The retained STATE of the same host session is taken again.
        assert_eq!(host.observe(&state(true, 1000)), Verdict::Online);
    }

    #[test]
    fn a_malformed_state_changes_nothing() {
        let mut host = PrimaryHost::new("scada");
        host.observe(&state(true, 1000));
        for (body, why) in [
            (&b"ONLINE"[..], "not JSON"),
            (br#"{"timestamp": 5000}"#, "'online'"),
            (br#"{"online": false, "timestamp": "5000"}"#, "'timestamp'"),
            (br#"{"online": "false", "timestamp": 5000}"#, "'online'"),
        ] {
            match host.observe(body) {
                Verdict::Malformed(m) => assert!(m.contains(why), "{m}"),
                other => panic!("{other:?} for {body:?}"),
            }
        }
        assert!(host.online());
    }
}
