//! Per-vehicle vanishing points on real KITTI vehicles with exact truth.
//!
//! `../shared/data/real/kitti_object/vp_gt.json` gives, for 16 real KITTI frames (a
//! car-mounted camera), every labelled vehicle's 2D box and its exact VP1 (length axis) and VP2
//! (axle axis), derived from the 3D label and the projection matrix. This module measures, per
//! vehicle, the direction errors (at the box centre, the angle between the lines towards the
//! estimate and towards the truth, modulo 180°) of
//!
//! - the network's VP1 and VP2 (the crop the pipeline would cut from that box);
//! - the constant guess "VP1 at the principal point" (a car-mounted camera looks along the
//!   road, so this guess is strong here: a network must beat it);
//! - VP2 from the vehicle's own edgelets ([`vpcal_geom::aggregate::vehicle_vp`]) after the
//!   pipeline's edgelet selection ([`EdgeletRule`]).
//!
//! "Clean" vehicles are the ones a network can be asked about: not occluded, not truncated, box
//! at least [`CLEAN_MIN_HEIGHT_PX`] tall.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};
use vpcal_geom::aggregate::edgelets::{near_ray, Edgelet};
use vpcal_geom::aggregate::vehicle_vp::vehicle_vp;
use vpcal_geom::metrics::{direction_error_deg, direction_towards, signed_direction_error_deg};
use vpcal_geom::{BoxPx, Point2};
use vpcal_net::infer::VpNet;
use vpcal_video::crop::{CropFilter, CropResizer};
use vpcal_video::edgelets::{edgelets_in_box, EdgeletOptions};

/// A vehicle is clean when it is not occluded, not truncated and its box is at least this tall.
pub const CLEAN_MIN_HEIGHT_PX: f64 = 20.0;

#[derive(Debug, Deserialize)]
struct TruthFile {
    frames: std::collections::BTreeMap<String, TruthFrame>,
}

#[derive(Debug, Deserialize)]
struct TruthFrame {
    image: PathBuf,
    pp: [f64; 2],
    #[serde(default)]
    fx: Option<f64>,
    #[serde(default)]
    ground_plane_avod: Option<[f64; 4]>,
    vehicles: Vec<TruthVehicle>,
}

#[derive(Debug, Deserialize)]
struct TruthVehicle {
    #[serde(rename = "type")]
    kind: String,
    truncated: f64,
    occluded: i64,
    box2d_label: [f64; 4],
    vp1_h: [f64; 3],
    vp2_h: [f64; 3],
    #[serde(default)]
    dims_hwl: Option<[f64; 3]>,
    #[serde(default)]
    rotation_y: Option<f64>,
}

/// One labelled vehicle with its exact VPs.
#[derive(Debug, Clone)]
pub struct KittiVehicle {
    pub kind: String,
    pub truncated: f64,
    pub occluded: i64,
    /// The label's 2D box, frame pixels.
    pub bbox: BoxPx,
    /// Exact VPs, homogeneous `[x, y, w]` (`w ≈ 0`: at infinity).
    pub vp1: [f64; 3],
    pub vp2: [f64; 3],
    /// The 3D label's height, width and length, metres.
    pub dims_hwl: Option<[f64; 3]>,
    /// The 3D label's heading about the camera's y axis, radians (KITTI `rotation_y`).
    pub rotation_y: Option<f64>,
}

impl KittiVehicle {
    /// Not occluded, not truncated, at least [`CLEAN_MIN_HEIGHT_PX`] tall.
    pub fn is_clean(&self) -> bool {
        self.occluded == 0 && self.truncated == 0.0 && self.bbox.height() >= CLEAN_MIN_HEIGHT_PX
    }
}

/// One KITTI frame: its image and vehicles.
#[derive(Debug, Clone)]
pub struct KittiFrame {
    pub id: String,
    pub image: PathBuf,
    pub pp: Point2,
    /// Focal length of the left colour camera, pixels.
    pub fx: Option<f64>,
    /// The road plane `a x + b y + c z + d = 0` in camera coordinates (metres; the AVOD
    /// ground planes: `d` is the camera's height above the road).
    pub ground_plane: Option<[f64; 4]>,
    pub vehicles: Vec<KittiVehicle>,
}

/// Read `DIR/vp_gt.json` (image paths resolved against `DIR`).
///
/// # Errors
/// A missing or malformed file (named), a vehicle with an empty box.
pub fn read_truth(dir: &Path) -> Result<Vec<KittiFrame>> {
    let path = dir.join("vp_gt.json");
    let text =
        std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
    let file: TruthFile = serde_json::from_str(&text).with_context(|| {
        format!(
            "{}: expected KITTI vanishing-point truth ({{\"frames\": {{id: {{image, pp, vehicles}}}}}})",
            path.display()
        )
    })?;
    let mut frames = Vec::with_capacity(file.frames.len());
    for (id, f) in file.frames {
        let mut vehicles = Vec::with_capacity(f.vehicles.len());
        for (k, v) in f.vehicles.into_iter().enumerate() {
            let [x0, y0, x1, y1] = v.box2d_label;
            let bbox = BoxPx { x0, y0, x1, y1 };
            if !bbox.is_valid() {
                bail!(
                    "{}: frame {id}, vehicle {k}: box2d_label {:?} is empty",
                    path.display(),
                    v.box2d_label
                );
            }
            vehicles.push(KittiVehicle {
                kind: v.kind,
                truncated: v.truncated,
                occluded: v.occluded,
                bbox,
                vp1: v.vp1_h,
                vp2: v.vp2_h,
                dims_hwl: v.dims_hwl,
                rotation_y: v.rotation_y,
            });
        }
        frames.push(KittiFrame {
            id,
            image: dir.join(f.image),
            pp: Point2::new(f.pp[0], f.pp[1]),
            fx: f.fx,
            ground_plane: f.ground_plane_avod,
            vehicles,
        });
    }
    Ok(frames)
}

/// The per-vehicle VP2 fit's nearest VP, in box diagonals. Measured on the 25 clean KITTI
/// vehicles (`vpcal eval kitti --edgelet-reach R`, median / 90th percentile): 1 diagonal
/// 2.3° / 11.9°, 3 diagonals 1.6° / 4.9°, 10 diagonals 2.3° / 4.1°.
pub const MIN_VP_DISTANCE_DIAGONALS: f64 = 3.0;

/// Which of a vehicle's edgelets its VP2 is fitted to: the pipeline's selection.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct EdgeletRule {
    /// Within this angle of the network's VP2 ray, degrees.
    pub gate_vp2_deg: f64,
    /// ... and farther than this from the direction to the network's VP1, degrees.
    pub exclude_vp1_deg: f64,
    /// At most this many (the strongest).
    pub max_per_vehicle: usize,
    /// The fitted VP2 lies at least this many box diagonals from the box centre (a vehicle's
    /// VP lies far outside its box; closer points let two nearly parallel edges swing the
    /// direction by tens of degrees).
    pub min_vp_distance_diagonals: f64,
}

impl Default for EdgeletRule {
    /// The pipeline's selection ([`vpcal_geom::aggregate::edgelets::EdgeletFitOptions`]).
    fn default() -> Self {
        let o = vpcal_geom::aggregate::edgelets::EdgeletFitOptions::default();
        EdgeletRule {
            gate_vp2_deg: o.gate_vp2_deg,
            exclude_vp1_deg: o.exclude_vp1_deg,
            max_per_vehicle: o.max_per_vehicle,
            min_vp_distance_diagonals: MIN_VP_DISTANCE_DIAGONALS,
        }
    }
}

impl EdgeletRule {
    /// The edgelets of a vehicle at `centre` that this rule keeps for its VP2, given the
    /// network's VP1 and VP2 (frame pixels).
    pub fn select(
        &self,
        centre: Point2,
        vp1: Point2,
        vp2: Point2,
        all: &[Edgelet],
    ) -> Vec<Edgelet> {
        let ex1 = self.exclude_vp1_deg.to_radians();
        near_ray(centre, vp2, all, self.gate_vp2_deg, self.max_per_vehicle)
            .into_iter()
            .filter(|e| {
                direction_towards(e.point(), vp1.to_h())
                    .is_none_or(|a| angle_between(a, e.angle) > ex1)
            })
            .collect()
    }
}

/// The angle between two undirected lines, radians in `[0, π/2]`.
fn angle_between(a: f64, b: f64) -> f64 {
    let pi = std::f64::consts::PI;
    let d = (a - b).rem_euclid(pi);
    d.min(pi - d)
}

/// The per-vehicle measurements.
#[derive(Debug, Clone, Serialize)]
pub struct VehicleResult {
    pub frame: String,
    /// Index of the vehicle in its frame's list.
    pub index: usize,
    pub kind: String,
    pub clean: bool,
    /// The box, `[x0, y0, x1, y1]`.
    pub bbox: [f64; 4],
    /// The network's VP1 and VP2 direction errors, degrees (`None`: not decodable).
    pub network_vp1_deg: Option<f64>,
    pub network_vp2_deg: Option<f64>,
    /// The guess "VP1 at the principal point", degrees.
    pub pp_vp1_deg: Option<f64>,
    /// The network's VP2 error with a sign: positive when its direction is turned from the
    /// true one towards the direction to the true VP1 (a VP2 placed too near VP1 gives a
    /// traffic camera too short a focal length, one turned away too long).
    pub network_vp2_signed_deg: Option<f64>,
    /// VP2 from the vehicle's edgelets, degrees (`None`: too few edgelets).
    pub edgelet_vp2_deg: Option<f64>,
    /// The same with a sign: positive when the edgelet VP2's direction is turned from the
    /// true one towards the direction to the true VP1.
    pub edgelet_vp2_signed_deg: Option<f64>,
    /// Edgelets found in the box, and kept for the VP2 fit.
    pub edgelets_found: usize,
    pub edgelets_used: usize,
    /// The network's VPs in frame pixels (`null` when not finite).
    pub network_vp1: Option<[f64; 2]>,
    pub network_vp2: Option<[f64; 2]>,
    /// Every edgelet found in the box `[x, y, angle, strength]` (only with `keep_edgelets`).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub edgelets: Vec<[f64; 4]>,
    /// The exact VPs, homogeneous.
    pub truth_vp1: [f64; 3],
    pub truth_vp2: [f64; 3],
}

/// The direction error at `centre` of `vp2` (homogeneous) against vehicle `v`'s true VP2,
/// degrees, positive when turned towards the direction to its true VP1.
fn towards_vp1_deg(centre: Point2, vp2: [f64; 3], v: &KittiVehicle) -> Option<f64> {
    let err = signed_direction_error_deg(centre, vp2, v.vp2)?;
    let vp1_side = signed_direction_error_deg(centre, v.vp1, v.vp2)?;
    Some(err * vp1_side.signum())
}

/// Measure every vehicle of `frames` (`clean_only`: only the clean ones). `keep_edgelets` keeps
/// each vehicle's raw edgelets in its result (for studying the selection rule).
///
/// # Errors
/// An unreadable image (named), a network failure.
pub fn evaluate(
    frames: &[KittiFrame],
    net: &VpNet,
    rule: &EdgeletRule,
    clean_only: bool,
    keep_edgelets: bool,
) -> Result<Vec<VehicleResult>> {
    let mut resizer = CropResizer::new(net.config().input_size as u32, CropFilter::default())?;
    let options = EdgeletOptions::default();
    let mut out = Vec::new();
    for frame in frames {
        let picked: Vec<(usize, &KittiVehicle)> = frame
            .vehicles
            .iter()
            .enumerate()
            .filter(|(_, v)| !clean_only || v.is_clean())
            .collect();
        if picked.is_empty() {
            continue;
        }
        let image = image::open(&frame.image)
            .with_context(|| format!("reading {}", frame.image.display()))?
            .to_rgb8();
        let boxes: Vec<BoxPx> = picked.iter().map(|(_, v)| v.bbox).collect();
        let batch = resizer.crop_batch(&image, &boxes)?;
        let preds = net.predict_prepared(&batch.images)?;
        for ((&src, crop_box), p) in batch.source.iter().zip(&batch.boxes).zip(preds) {
            let (index, v) = picked[src];
            let centre = v.bbox.center();
            let vp1 = crop_box.frame_from_box(p.vp.vp1);
            let vp2 = crop_box.frame_from_box(p.vp.vp2);
            let found = edgelets_in_box(&image, &v.bbox, &options);
            let used = rule.select(centre, vp1, vp2, &found);
            let reach = rule.min_vp_distance_diagonals * v.bbox.width().hypot(v.bbox.height());
            let fit = vehicle_vp(centre, &used, reach, 1.0);
            let finite = |p: Point2| p.is_finite().then_some([p.x, p.y]);
            out.push(VehicleResult {
                frame: frame.id.clone(),
                index,
                kind: v.kind.clone(),
                clean: v.is_clean(),
                bbox: [v.bbox.x0, v.bbox.y0, v.bbox.x1, v.bbox.y1],
                network_vp1_deg: direction_error_deg(centre, vp1.to_h(), v.vp1),
                network_vp2_deg: direction_error_deg(centre, vp2.to_h(), v.vp2),
                pp_vp1_deg: direction_error_deg(centre, frame.pp.to_h(), v.vp1),
                edgelet_vp2_deg: fit.and_then(|f| direction_error_deg(centre, f.point, v.vp2)),
                network_vp2_signed_deg: towards_vp1_deg(centre, vp2.to_h(), v),
                edgelet_vp2_signed_deg: fit.and_then(|f| towards_vp1_deg(centre, f.point, v)),
                edgelets_found: found.len(),
                edgelets_used: used.len(),
                network_vp1: finite(vp1),
                network_vp2: finite(vp2),
                edgelets: if keep_edgelets {
                    found
                        .iter()
                        .map(|e| [e.x, e.y, e.angle, e.strength])
                        .collect()
                } else {
                    Vec::new()
                },
                truth_vp1: v.vp1,
                truth_vp2: v.vp2,
            });
        }
    }
    Ok(out)
}

/// Median and 90th percentile of one measurement over a set of vehicles.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct ErrorSummary {
    /// Vehicles with a value (the others had none: not decodable, too few edgelets).
    pub n: usize,
    pub median_deg: f64,
    pub p90_deg: f64,
}

/// Median and 90th percentile of the finite `values`; `None` when there are none.
pub fn summarize(values: impl Iterator<Item = Option<f64>>) -> Option<ErrorSummary> {
    let mut v: Vec<f64> = values.flatten().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    Some(ErrorSummary {
        n: v.len(),
        median_deg: vpcal_geom::solve::percentile_sorted(&v, 50.0),
        p90_deg: vpcal_geom::solve::percentile_sorted(&v, 90.0),
    })
}

/// The camera of a KITTI frame from its focal length and ground plane, with the road frame's
/// x axis 45° off the view direction (so both VPs are finite), and the true metres per
/// plane unit (the plane's `d`, the camera height, over the camera's height in plane units);
/// `None` without a plane or focal length.
pub fn frame_camera(frame: &KittiFrame) -> Option<(vpcal_geom::camera::Calibration, f64)> {
    let [a, b, c, d] = frame.ground_plane?;
    let f = frame.fx?;
    let norm = (a * a + b * b + c * c).sqrt();
    let n = [a / norm, b / norm, c / norm];
    let along = vpcal_geom::normalize3([-n[2] * n[0], -n[2] * n[1], 1.0 - n[2] * n[2]])?;
    let across = vpcal_geom::cross(n, along);
    let e1: Vec<f64> = (0..3).map(|i| along[i] + across[i]).collect();
    let e2 = vpcal_geom::cross(n, [e1[0], e1[1], e1[2]]);
    let pp = frame.pp;
    let vp = |v: &[f64]| Point2::new(pp.x + f * v[0] / v[2], pp.y + f * v[1] / v[2]);
    let cal = vpcal_geom::camera::Calibration::from_vps(vp(&e1), vp(&e2), pp).ok()?;
    // The BrnoCompSpeed convention has the camera look down at the road; where the road
    // rises ahead of this car-mounted camera (the plane normal leans towards it) the
    // convention's normal points the wrong way, and the frame is left out.
    let down = -(0..3).map(|i| cal.road_normal[i] * n[i]).sum::<f64>();
    if down <= 0.0 {
        return None;
    }
    let m_per_unit = d / norm / cal.plane_distance();
    m_per_unit.is_finite().then_some((cal, m_per_unit))
}

/// One KITTI car's size, read by the automatic scale's cuboid fit
/// ([`vpcal_geom::vehicle_scale`]) on the true camera: metres per plane unit it implies over
/// the truth.
#[derive(Debug, Clone, Serialize)]
pub struct ScaleVehicle {
    pub frame: String,
    pub index: usize,
    pub bbox: [f64; 4],
    /// With the car's own labelled dimensions and the typical cabin: the outline model's bias
    /// alone.
    pub own_dims_ratio: Option<f64>,
    pub own_dims_rms: Option<f64>,
    /// With the typical car ([`vpcal_geom::vehicle_scale::PASSENGER_CAR`]): what the
    /// automatic scale sees (bias and the car's departure from the typical one).
    pub typical_ratio: Option<f64>,
    pub typical_rms: Option<f64>,
}

/// The outline fit (body and cabin) on every clean car of `frames` with a 3D label and a
/// ground plane.
pub fn scale_check(frames: &[KittiFrame]) -> Vec<ScaleVehicle> {
    use vpcal_geom::vehicle_scale::{fit_vehicle, PASSENGER_CAR, PASSENGER_CAR_CABIN};
    let mut out = Vec::new();
    for frame in frames {
        let Some((cal, truth)) = frame_camera(frame) else {
            continue;
        };
        let axes = cal.road_frame().rotation;
        for (index, v) in frame.vehicles.iter().enumerate() {
            let (Some([h, w, l]), Some(ry)) = (v.dims_hwl, v.rotation_y) else {
                continue;
            };
            if v.kind != "Car" || !v.is_clean() {
                continue;
            }
            // The car's length axis in camera coordinates, then in the road frame.
            let d = [ry.cos(), 0.0, -ry.sin()];
            let on = |k: usize| (0..3).map(|i| axes[i][k] * d[i]).sum::<f64>();
            let heading = on(1).atan2(on(0));
            let read = |dims: [f64; 3]| {
                fit_vehicle(&cal, v.bbox, heading, dims, PASSENGER_CAR_CABIN)
                    .map(|fit| (1.0 / fit.size / truth, fit.rms))
            };
            let own = read([l, w, h]);
            let typical = read(PASSENGER_CAR);
            out.push(ScaleVehicle {
                frame: frame.id.clone(),
                index,
                bbox: [v.bbox.x0, v.bbox.y0, v.bbox.x1, v.bbox.y1],
                own_dims_ratio: own.map(|o| o.0),
                own_dims_rms: own.map(|o| o.1),
                typical_ratio: typical.map(|o| o.0),
                typical_rms: typical.map(|o| o.1),
            });
        }
    }
    out
}
