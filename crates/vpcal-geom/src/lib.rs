//! Pure f64 geometry for vpcal: no tensors, no I/O.
//!
//! Entry points:
//! - [`Point2`], [`Line`], [`BoxPx`]: points, homogeneous lines, vehicle boxes and the box
//!   frame (`vp_in_box` / `frame_from_box`).
//! - [`camera`]: focal length, horizon, vp3, road normal, rotation and BrnoCompSpeed
//!   back-projection from two orthogonal VPs ([`camera::Calibration`]).
//! - [`diamond`]: the diamond-space parametrisation of the projective plane.
//! - [`heatmap`]: the multi-scale heatmap codec (targets, decoding, scale selection).
//! - [`aggregate`]: per-vehicle VP pairs to one camera.
//! - [`rotation`]: rotation matrices and rotation vectors (OpenCV's `rvec`).
//! - [`solve`]: shared numerics (Nelder-Mead, SplitMix, medians, percentiles).
//! - [`metrics`]: BrnoCompSpeed / BrnoCarPark calibration errors and summary statistics.
//!
//! # Conventions
//! - Image pixels: x right, y down; a VP in *frame pixels* is in the coordinates of the whole
//!   frame, in the *box frame* it is relative to a vehicle box (centre at 0, the box spans
//!   [-1, 1] on both axes).
//! - All geometry is f64; angles are radians unless a name says `_deg`; lengths in pixels
//!   say `_px`, metres `_m`.
//! - Degenerate inputs give `None` or a typed error, never NaN in a result.

pub mod aggregate;
pub mod camera;
pub mod diamond;
pub mod heatmap;
pub mod metrics;
mod point;
pub mod rotation;
pub mod solve;
pub mod vehicle_dims;
pub mod vehicle_scale;

pub use point::{cross, dot3, normalize3, BoxPx, Line, Point2};
