//! # gridscada-scl: the SCL reader (IEC 61850-6)
//!
//! **Owns:** reading ICD/CID/SCD files into the model an IEC 61850 client
//! needs ([`model`]): IEDs, logical devices and nodes with their instance
//! values, datasets, report control blocks, the data type templates, and
//! each IED's address; resolving a reference against the templates; and
//! the import of an IED into a gridscada tag file ([`import`]).
//!
//! **Must not touch:** sockets, the tag database, gridscada's
//! configuration types (it writes tag files as text; `gridscada-config`
//! reads them), SQL, HTTP.

pub mod import;
pub mod model;
pub mod read;

pub use model::*;
pub use read::{read_bytes, read_path, Filter, SclError};
