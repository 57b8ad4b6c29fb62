//! Subcommands: one module each, with `Args` and `run`.

pub mod aggregate;
pub mod args;
pub mod bench_net;
pub mod data;
pub mod eval;
pub mod predict;
pub mod synth;
pub mod train;
