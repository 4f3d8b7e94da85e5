//! OLUC/OLDC fault isolation (placeholder, being written).
