//! Subcommands: one module each, with `Args` and `run`.

pub mod aggregate;
pub mod args;
pub mod data;
pub mod eval;
pub mod synth;
