//! # gridscada-control: control logic
//!
//! **Owns:** the OLUC/OLDC automatic fault-isolation sequence of LV substation
//! panels ([`fault_isolation`]) and the cascade outer loop of the microgrid, with
//! its dispatch LP solved by clarabel ([`dispatch`]). Each is a pure state machine
//! or function, driven by a thin driver over the tag database and a `TagWriter`.
//!
//! **Must not touch:** Modbus, SQL or HTTP. Drivers read the tag database, write
//! through `gridscada_tagdb::TagWriter`, and report events and alarm conditions
//! on channels that the application wires to the alarm engine and the store.

pub mod dispatch;
pub mod fault_isolation;
