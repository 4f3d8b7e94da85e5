//! `[redundancy]`: this server as one of a redundant pair (or more) sharing
//! one PostgreSQL database; exactly one of them is active at a time.

use serde::Deserialize;

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RedundancyConfig {}
