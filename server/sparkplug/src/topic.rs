//! The Sparkplug B topic namespace:
//! `spBv1.0/GROUP/MESSAGE_TYPE/EDGE_NODE[/DEVICE]`, and the primary host's
//! `spBv1.0/STATE/HOST_ID` (Sparkplug 3.0).

use std::fmt;

pub const NAMESPACE: &str = "spBv1.0";

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum MessageType {
    NBirth,
    NDeath,
    NData,
    NCmd,
    DBirth,
    DDeath,
    DData,
    DCmd,
}

impl MessageType {
    pub fn as_str(self) -> &'static str {
        match self {
            MessageType::NBirth => "NBIRTH",
            MessageType::NDeath => "NDEATH",
            MessageType::NData => "NDATA",
            MessageType::NCmd => "NCMD",
            MessageType::DBirth => "DBIRTH",
            MessageType::DDeath => "DDEATH",
            MessageType::DData => "DDATA",
            MessageType::DCmd => "DCMD",
        }
    }

    fn parse(s: &str) -> Option<MessageType> {
        Some(match s {
            "NBIRTH" => MessageType::NBirth,
            "NDEATH" => MessageType::NDeath,
            "NDATA" => MessageType::NData,
            "NCMD" => MessageType::NCmd,
            "DBIRTH" => MessageType::DBirth,
            "DDEATH" => MessageType::DDeath,
            "DDATA" => MessageType::DData,
            "DCMD" => MessageType::DCmd,
            _ => return None,
        })
    }

    /// Device-level messages name a device in the topic.
    pub fn is_device(self) -> bool {
        matches!(
            self,
            MessageType::DBirth | MessageType::DDeath | MessageType::DData | MessageType::DCmd
        )
    }
}

/// A parsed Sparkplug B topic.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Topic {
    /// A node or device message.
    Message {
        group: String,
        kind: MessageType,
        edge_node: String,
        device: Option<String>,
    },
    /// A primary host application's state (`spBv1.0/STATE/HOST_ID`).
    State { host_id: String },
}

impl Topic {
    pub fn node(group: &str, kind: MessageType, edge_node: &str) -> Topic {
        Topic::Message {
            group: group.to_owned(),
            kind,
            edge_node: edge_node.to_owned(),
            device: None,
        }
    }

    pub fn device(group: &str, kind: MessageType, edge_node: &str, device: &str) -> Topic {
        Topic::Message {
            group: group.to_owned(),
            kind,
            edge_node: edge_node.to_owned(),
            device: Some(device.to_owned()),
        }
    }

    /// Reads a topic; `None` for anything outside the Sparkplug B namespace
    /// or malformed (a device message without a device, an extra level).
    pub fn parse(topic: &str) -> Option<Topic> {
        let mut parts = topic.split('/');
        if parts.next()? != NAMESPACE {
            return None;
        }
        let second = parts.next()?;
        if second == "STATE" {
            let host_id = parts.next()?;
            return (parts.next().is_none() && !host_id.is_empty()).then(|| Topic::State {
                host_id: host_id.to_owned(),
            });
        }
        let kind = MessageType::parse(parts.next()?)?;
        let edge_node = parts.next()?;
        let device = parts.next();
        if parts.next().is_some()
            || second.is_empty()
            || edge_node.is_empty()
            || kind.is_device() != device.is_some()
            || device.is_some_and(str::is_empty)
        {
            return None;
        }
        Some(Topic::Message {
            group: second.to_owned(),
            kind,
            edge_node: edge_node.to_owned(),
            device: device.map(str::to_owned),
        })
    }
}

impl fmt::Display for Topic {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Topic::Message {
                group,
                kind,
                edge_node,
                device,
            } => {
                write!(f, "{NAMESPACE}/{group}/{}/{edge_node}", kind.as_str())?;
                if let Some(device) = device {
                    write!(f, "/{device}")?;
                }
                Ok(())
            }
            Topic::State { host_id } => write!(f, "{NAMESPACE}/STATE/{host_id}"),
        }
    }
}

/// Whether a name can be a topic level: not empty, and none of the MQTT
/// separators and wildcards (`/`, `+`, `#`).
pub fn valid_id(name: &str) -> bool {
    !name.is_empty() && !name.contains(['/', '+', '#'])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn topics_parse_and_print_back() {
        for text in [
            "spBv1.0/Plant/NBIRTH/site-a",
            "spBv1.0/Plant/DDATA/site-a/PANEL1",
            "spBv1.0/STATE/central",
        ] {
            assert_eq!(Topic::parse(text).unwrap().to_string(), text);
        }
    }

    #[test]
    fn malformed_topics_are_refused() {
        for text in [
            "spBv1.0/Plant/DDATA/site-a",
            "spBv1.0/Plant/NDATA/site-a/dev",
            "spBv1.0/Plant/XDATA/site-a",
            "spBv2.0/Plant/NBIRTH/site-a",
            "spBv1.0//NBIRTH/site-a",
            "spBv1.0/Plant/DDATA/site-a/dev/extra",
            "spBv1.0/STATE/",
        ] {
            assert_eq!(Topic::parse(text), None, "{text}");
        }
    }
}
