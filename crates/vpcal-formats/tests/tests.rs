//! The integration tests of `vpcal-formats`, one test binary (one link of the crate and its
//! dependencies) with a module per area.

mod pickle;
mod real_data;
