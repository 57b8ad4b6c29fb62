//! Subcommands: one module each, with `Args` and `run`.

pub mod data;
pub mod synth;
