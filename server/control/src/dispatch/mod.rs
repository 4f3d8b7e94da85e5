//! Microgrid dispatch (placeholder, being written).
