//! Subcommands: one module each, with `Args` and `run`.
