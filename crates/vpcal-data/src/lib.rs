//! Training data for vpcal: the shared [`Sample`] type, data sources (BoxCars116k, synthetic
//! crops), the paper's augmentation, heatmap targets and a streaming batch pipeline.
//!
//! Entry points:
//! - [`Sample`], [`SampleSource`], [`Batch`]: the contracts every data source and the network
//!   share.
//! - [`boxcars::BoxCars`]: BoxCars116k (`dataset.pkl` + `atlas.pkl`), lazily decoded;
//!   [`boxcars::BoxCars::split`] gives a [`SampleSource`] per split.
//! - [`augment`]: the paper's augmentation ([`augment::AugmentConfig`] with the `paper` and
//!   `reference` presets).
//! - [`pipeline::Pipeline`]: multi-threaded, deterministic batches with heatmap targets from
//!   `vpcal_geom::heatmap::HeatmapCodec` (the project's one diamond-space implementation).
//! - [`preview`]: contact sheets of augmented crops with their geometry drawn.
//!
//! # Conventions
//! - Sample geometry is in crop pixels (x right, y down, pixel (0, 0) covers [0, 1)²); the
//!   network's VPs are in the box frame of the final crop (the crop spans [-1, 1]²).
//! - Images are RGB, 8 bit; batches hold NCHW f32 in [0, 1].

pub mod augment;
pub mod boxcars;
pub mod pipeline;
pub mod preview;
mod sample;
pub mod sensor;
mod source;
pub mod warp;

pub use sample::{
    Sample, SampleId, Split, BB3D_EDGES_VERTICAL, BB3D_EDGES_VP1, BB3D_EDGES_VP2, EXACT_LABELS,
};
pub use source::{channel_weights, Batch, ConcatSource, DataError, SampleSource};
