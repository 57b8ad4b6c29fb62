//! The integration tests of `vpcal-video`, one test binary (one link of the crate and its
//! dependencies) with a module per area.

mod common;
mod detection;
mod onnx;
mod sources;
