//! The integration tests of `vpcal`, one test binary (one link of the crate and its
//! dependencies) with a module per area.

mod calibrate;
mod cli;
mod common;
mod library;
mod net_cli;
mod report;
mod trust;
