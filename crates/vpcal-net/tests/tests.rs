//! The integration tests of `vpcal-net`, one test binary (one link of the crate and its
//! dependencies) with a module per area.

mod checkpoints;
mod encoder;
mod inference;
mod training;
