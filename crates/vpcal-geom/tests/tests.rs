//! The integration tests of `vpcal-geom`, one test binary (one link of the crate and its
//! dependencies) with a module per area.

mod geometry;
mod robust;
mod tracks;
mod vehicle_scale;
