//! The ground truth a rendered frame carries per vehicle.

use crate::mesh::Pose;
use crate::vehicle::VehicleKind;

/// Ground truth of one vehicle in one frame.
#[derive(Debug, Clone, serde::Serialize)]
pub struct VehicleTruth {
    pub frame: u32,
    pub id: u32,
    pub kind: VehicleKind,
    /// Hull of the projected 3D box (image pixels, may extend outside the image).
    #[serde(rename = "box")]
    pub box2d: [f64; 4],
    /// The hull clipped to the image.
    pub box_clipped: [f64; 4],
    pub bb3d: [[f64; 2]; 8],
    /// VPs in image pixels; `None` (null) when at infinity.
    pub vp1: Option<[f64; 2]>,
    pub vp2: Option<[f64; 2]>,
    pub pose: Pose,
    pub dims_m: [f64; 3],
    pub speed_mps: f64,
    pub parked: bool,
    /// Fraction of the vehicle's own silhouette that is visible (not occluded, inside the image).
    pub visible_fraction: f64,
}
