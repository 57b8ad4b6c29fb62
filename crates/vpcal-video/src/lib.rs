//! vpcal-video: where vehicle crops come from.
//!
//! The first arrows of the vpcal data flow (DESIGN.md §2):
//!
//! ```text
//! frames (video via ffmpeg | image folder | single image), every k-th frame   source
//!   -> vehicle boxes (motion detector | detections file | learned detector)   detect
//!   -> per-frame filter: score threshold, drop static vehicles, best 10        filter (+ edges)
//!   -> crop each box, resize to the network input                              crop
//! ```
//!
//! # Entry points
//! - [`source::open_source`] opens a video, image folder or image as a [`FrameSource`]
//!   (an iterator of [`Frame`]s).
//! - [`detect::Detector`], implemented by [`detect::MotionDetector`] (default),
//!   [`detect::FileDetector`] and, with the `onnx` feature, `detect::OnnxDetector`.
//! - [`filter::FrameFilter`]: score threshold, static-vehicle rule, at most 10 per frame.
//! - [`crop::CropResizer`]: the network's input crops and the box frame they refer to.
//! - [`draw`]: debug pictures with boxes.
//! - [`background::BackgroundSampler`]: the median of frames sampled over the input (the road
//!   without its traffic) and [`background::scene_edgelets`], the lines it shows (VP1
//!   evidence).
//! - [`markings::bright_bars`]: the thin bright bars of the background (road markings).
//!
//! # Conventions
//! - Frame pixels: x right, y down, origin at the top-left corner; pixel (i, j) covers
//!   [i, i+1) × [j, j+1). Boxes ([`vpcal_geom::BoxPx`]) are continuous in these coordinates.
//! - Frames are RGB, 8 bit, full resolution.
//! - Frame indices are 0-based over all decoded frames of the source.

pub mod background;
pub mod crop;
pub mod detect;
pub mod draw;
pub mod edgelets;
pub mod edges;
pub mod error;
pub mod filter;
pub mod markings;
pub mod segments;
pub mod source;

pub use detect::{Detection, Detector};
pub use error::{Result, VideoError};
pub use source::{open_source, Frame, FrameSource, SourceInfo, SourceKind, SourceOptions, Start};
