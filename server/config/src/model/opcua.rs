//! `[opcua]`: the OPC UA server that exposes the tag database. Off unless
//! the section is present.

use serde::Deserialize;
use serde_spanned::Spanned;

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OpcUaConfig {
    /// Address the OPC UA server listens on (`0.0.0.0:4840`).
    pub listen: Spanned<String>,
}
