//! `[opcua]`: the OPC UA server that exposes the tag database. Off unless
//! the section is present.

use serde::Deserialize;
use serde_spanned::Spanned;

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OpcUaConfig {
    /// Address the OPC UA server listens on (`0.0.0.0:4840`).
    pub listen: Spanned<String>,
    /// The host name in the endpoint URLs the server announces
    /// (`opc.tcp://HOST:PORT/`); clients connect to what they are told, so
    /// it must be a name they resolve. Default: the listen address, or this
    /// machine's host name when that is `0.0.0.0`.
    #[serde(default)]
    pub host: Option<Spanned<String>>,
    /// The endpoints offered, by security policy and mode. Default: only
    /// Basic256Sha256 with Sign and with SignAndEncrypt; `none` (no signing,
    /// no encryption) only if listed.
    #[serde(default = "default_security")]
    pub security: Spanned<Vec<OpcUaSecurity>>,
    /// Anonymous sessions (read-only, the guest role). Off by default:
    /// every session then logs in as a gridscada user.
    #[serde(default)]
    pub anonymous: bool,
    /// The certificate store (own certificate and key, trusted and rejected
    /// client certificates), relative to the data folder.
    #[serde(default = "default_pki_dir")]
    pub pki_dir: Spanned<String>,
    /// Make a self-signed server certificate at start when there is none.
    /// Off: the operator puts one in `PKI/own/cert.der` and
    /// `PKI/private/private.pem`.
    #[serde(default = "yes")]
    pub create_certificate: bool,
    /// Trust every client certificate on first sight. Off: a new client's
    /// certificate lands in `PKI/rejected/` until an operator trusts it
    /// (`gridscada opcua trust`, or a move to `PKI/trusted/`). For
    /// commissioning only.
    #[serde(default)]
    pub trust_all_clients: bool,
    /// Open connections on the OPC UA port at most; more are closed at
    /// once. Each one holds descriptors while it lasts.
    #[serde(default = "default_max_connections")]
    pub max_connections: Spanned<u32>,
    /// Open connections from one client address at most (a gateway or a
    /// NAT may need more).
    #[serde(default = "default_max_connections_per_client")]
    pub max_connections_per_client: Spanned<u32>,
}

/// `[opcua] max_connections`' default: three times async-opcua's 20
/// sessions, for clients that discover endpoints on a connection of
/// their own.
pub const DEFAULT_OPCUA_MAX_CONNECTIONS: u32 = 64;
/// `[opcua] max_connections_per_client`'s default.
pub const DEFAULT_OPCUA_MAX_CONNECTIONS_PER_CLIENT: u32 = 8;

impl OpcUaConfig {
    /// The per-client cap in effect: never above the global one.
    pub fn per_client_cap(&self) -> u32 {
        (*self.max_connections_per_client.get_ref()).min(*self.max_connections.get_ref())
    }
}

fn default_max_connections() -> Spanned<u32> {
    Spanned::new(0..0, DEFAULT_OPCUA_MAX_CONNECTIONS)
}

fn default_max_connections_per_client() -> Spanned<u32> {
    Spanned::new(0..0, DEFAULT_OPCUA_MAX_CONNECTIONS_PER_CLIENT)
}

/// One endpoint's security policy and message security mode.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Deserialize)]
pub enum OpcUaSecurity {
    /// No signing or encryption: anyone on the path can read and alter the
    /// traffic (user passwords are still encrypted with the server's key).
    #[serde(rename = "none")]
    None,
    #[serde(rename = "basic256sha256-sign")]
    Basic256Sha256Sign,
    #[serde(rename = "basic256sha256-sign-encrypt")]
    Basic256Sha256SignEncrypt,
}

impl OpcUaSecurity {
    pub fn label(self) -> &'static str {
        match self {
            OpcUaSecurity::None => "none",
            OpcUaSecurity::Basic256Sha256Sign => "basic256sha256-sign",
            OpcUaSecurity::Basic256Sha256SignEncrypt => "basic256sha256-sign-encrypt",
        }
    }
}

fn default_security() -> Spanned<Vec<OpcUaSecurity>> {
    Spanned::new(
        0..0,
        vec![
            OpcUaSecurity::Basic256Sha256Sign,
            OpcUaSecurity::Basic256Sha256SignEncrypt,
        ],
    )
}

fn default_pki_dir() -> Spanned<String> {
    Spanned::new(0..0, "opcua-pki".into())
}

fn yes() -> bool {
    true
}
