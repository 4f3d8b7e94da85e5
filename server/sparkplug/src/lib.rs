//! MQTT Sparkplug B northbound.
//!
//! Owns the Sparkplug B wire format (`proto`: the Eclipse Tahu payload as
//! prost messages; `topic`: the `spBv1.0/...` namespace; `datatype`: the
//! metric data types and how a tag value maps onto them), the broker
//! connection (`connection`), the edge node (`edge`: this server's tags
//! published), and the central host (`host`: remote sites' tags from their
//! births, commands to them).
//!
//! Must not touch: Modbus, SQL, HTTP. Writes that arrive as commands go
//! through the tag database's `TagWriter`, like every other command.

pub mod connection;
pub mod datatype;
pub mod edge;
pub mod host;
pub mod proto;
pub mod topic;
