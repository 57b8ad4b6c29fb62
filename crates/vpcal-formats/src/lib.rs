//! File formats for vpcal.
//!
//! - [`pickle`]: a safe Python-pickle reader (no code execution; numpy arrays and scalars).

pub mod pickle;
