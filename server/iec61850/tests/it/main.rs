//! Integration tests of the IEC 61850 codec against real wire captures of
//! libiec61850 (tests/fixtures), and a bounded fuzz run of the decoders.
mod fixtures;
mod fuzz;
