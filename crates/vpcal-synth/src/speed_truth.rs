//! Speed ground truth of a scene, BrnoCompSpeed style: measurement lines across the road,
//! lane-divider lines along it, and per vehicle its true speed and the times its contact
//! point crosses each measurement line (the `cars` of `gt_data.json`, which `vpcal eval
//! speed` reads).
//!
//! - The road measured is the scene's straight road: the road of a highway, road `a` of an
//!   intersection, the access road of a parking lot. A curved road has no straight lane
//!   dividers in the image, so a curve scene gets no speed truth (empty lists).
//! - [`SpeedGeometry::measurement_lines`]: 3 lines across the road
//!   at 15 %, 50 % and 85 % of the stretch of road whose centre line is seen well inside the
//!   image (at least 8 % of the image size from its border, within 150 m of the camera).
//! - [`SpeedGeometry::lane_div_lines`]: one line per lane boundary, sorted across the road;
//!   the outermost ones are the road edges (beyond the outer lane markings, the shoulders),
//!   so a vehicle in an outer lane stays inside the span. The strip between the two
//!   directions (the median) is a lane of its own that no vehicle drives in.
//! - A vehicle's *contact point* is the bottom centre of its true (unclipped) 2D box, the
//!   point a tracker reports (`vpcal calibrate --tracks`, DubskaCalib's `posX`/`posY`).
//!   Its crossing time of a line is interpolated linearly between the two frames whose
//!   contact points lie on either side of it; frame `k` is at `k / fps` seconds.
//! - A car is listed when it drives along the measured road (heading within 10° of it) and
//!   its contact point crosses `measurementLines[0]` during the video; its `intersections`
//!   are listed by decreasing line id, so the last one (which the evaluation matches against)
//!   is the crossing of line 0. It is `valid` when it crossed every line, its box was a
//!   detectable one (as in `detections.csv`) at the frames of the first and last crossings,
//!   and it moved faster than 1 m/s; its `speed` is its mean true speed over the frames
//!   between its first and last crossings, km/h; `laneIndex` holds the lanes (of the
//!   divider lines) of its contact point at those crossings.

use std::collections::BTreeMap;
use std::f64::consts::PI;

use crate::camera::Camera;
use crate::math::V3;
use crate::truth::VehicleTruth;
use crate::world::{wrap_angle, Ground, Road, RoadShape, World};

/// Lines of a scene's speed ground truth, homogeneous `[a, b, c]` in image pixels with
/// `a² + b² = 1`.
#[derive(Debug, Clone, PartialEq)]
pub struct SpeedGeometry {
    pub measurement_lines: Vec<[f64; 3]>,
    pub lane_div_lines: Vec<[f64; 3]>,
    /// Unit direction of the measured road (+s), world.
    heading: f64,
}

/// The straight road whose speeds are measured, if the scene has one.
fn speed_road(world: &World) -> Option<&Road> {
    let road = match &world.ground {
        Ground::Road(r) => r,
        Ground::Cross { a, .. } => a,
        Ground::Parking { access, .. } => access,
    };
    matches!(road.shape, RoadShape::Straight { .. }).then_some(road)
}

fn line_through(p: [f64; 2], q: [f64; 2]) -> Option<[f64; 3]> {
    let l = [p[1] - q[1], q[0] - p[0], p[0] * q[1] - p[1] * q[0]];
    let n = l[0].hypot(l[1]);
    (n > 1e-9 && l.iter().all(|v| v.is_finite())).then(|| [l[0] / n, l[1] / n, l[2] / n])
}

/// `l · (x, y, 1)`.
fn value(l: [f64; 3], p: [f64; 2]) -> f64 {
    l[0] * p[0] + l[1] * p[1] + l[2]
}

impl SpeedGeometry {
    /// The lines of `world` seen by `cam`; `None` without a straight road, or when too little
    /// of it is seen.
    pub fn new(world: &World, cam: &Camera) -> Option<SpeedGeometry> {
        let road = speed_road(world)?;
        let (w, h) = (f64::from(cam.width), f64::from(cam.height));
        let margin = 0.08 * w.min(h);
        let seen = |s: f64| {
            let p = road.pose(s, 0.0);
            let g = V3::new(p.x, p.y, 0.0);
            (g - cam.position).norm() < 150.0
                && cam.project(g).is_some_and(|q| {
                    q[0] > margin && q[1] > margin && q[0] < w - margin && q[1] < h - margin
                })
        };
        // The longest run of seen centre-line points, 0.5 m apart.
        let (mut best, mut run): ((f64, f64), Option<f64>) = ((0.0, 0.0), None);
        let mut s = -250.0;
        while s <= 250.0 {
            match (seen(s), run) {
                (true, None) => run = Some(s),
                (false, Some(a)) => {
                    if s - a > best.1 - best.0 {
                        best = (a, s - 0.5);
                    }
                    run = None;
                }
                _ => {}
            }
            s += 0.5;
        }
        if let Some(a) = run {
            if 250.0 - a > best.1 - best.0 {
                best = (a, 250.0);
            }
        }
        let (lo, hi) = best;
        if hi - lo < 10.0 {
            return None;
        }
        let xs = &road.xs;
        // Road points well in front of the camera only (a point beside or behind it would
        // project to the wrong side).
        let project = |s: f64, t: f64| {
            let p = road.pose(s, t);
            let g = V3::new(p.x, p.y, 0.0);
            if cam.to_camera(g).z < 1.0 {
                return None;
            }
            cam.project(g)
        };
        // Any two points of a line on the road give its image line: the cross-section
        // through two points near the (seen) centre line; a lane boundary through the first
        // pair of seen stretch's points in front of the camera.
        let mut measurement_lines = Vec::new();
        for f in [0.15, 0.5, 0.85] {
            let s = lo + f * (hi - lo);
            measurement_lines.push(line_through(project(s, -1.0)?, project(s, 1.0)?)?);
        }
        let mid = (lo + hi) / 2.0;
        let boundary = |t: f64| {
            [(mid, hi), (mid, lo), (lo, hi)]
                .into_iter()
                .find_map(|(a, b)| line_through(project(a, t)?, project(b, t)?))
        };
        // Lane boundaries, right edge to left edge (t grows to the left).
        let mut ts = vec![-xs.half_right()];
        for k in (0..xs.lanes_right).rev() {
            ts.push(-(xs.median + f64::from(k) * xs.lane_w));
        }
        for k in 0..xs.lanes_left {
            ts.push(xs.median + f64::from(k) * xs.lane_w);
        }
        ts.push(xs.half_left());
        let mut lane_div_lines = Vec::new();
        for t in ts {
            lane_div_lines.push(boundary(t)?);
        }
        let heading = road.pose(0.0, 0.0).heading;
        Some(SpeedGeometry {
            measurement_lines,
            lane_div_lines,
            heading,
        })
    }

    /// Whether a vehicle with this heading drives along the measured road (either way).
    fn along(&self, heading: f64) -> bool {
        let d = wrap_angle(heading - self.heading).abs();
        d.min(PI - d) < 10f64.to_radians()
    }

    /// The lane of image point `p` (as `vpcal eval speed` finds it).
    fn lane(&self, p: [f64; 2]) -> Option<usize> {
        vpcal_formats::bcs_speed::lane_of(vpcal_geom::Point2::new(p[0], p[1]), &self.lane_div_lines)
    }
}

/// The contact point of a vehicle: the bottom centre of its unclipped box.
pub fn contact_point(v: &VehicleTruth) -> [f64; 2] {
    [(v.box2d[0] + v.box2d[2]) / 2.0, v.box2d[3]]
}

/// Whether a vehicle's box is one a detector would report (the rule of `detections.csv`).
pub fn detectable(v: &VehicleTruth) -> bool {
    let b = v.box_clipped;
    let full = (v.box2d[2] - v.box2d[0]) * (v.box2d[3] - v.box2d[1]);
    let inside = (b[2] - b[0]) * (b[3] - b[1]) / full.max(1e-9);
    v.visible_fraction >= 0.3 && inside >= 0.6 && (b[2] - b[0]) >= 8.0 && (b[3] - b[1]) >= 8.0
}

/// Whether the whole box is inside the image (its bottom centre is then the contact point).
fn unclipped(v: &VehicleTruth) -> bool {
    v.box2d
        .iter()
        .zip(&v.box_clipped)
        .all(|(a, b)| (a - b).abs() < 0.5)
}

/// What one frame said about one moving vehicle.
#[derive(Debug, Clone, Copy)]
struct Seen {
    frame: u32,
    contact: [f64; 2],
    heading: f64,
    speed_mps: f64,
    detectable: bool,
    unclipped: bool,
}

/// A GT car of `gt_data.json`.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct TruthCar {
    #[serde(rename = "carId")]
    pub car_id: u32,
    /// km/h.
    pub speed: f64,
    pub valid: bool,
    #[serde(rename = "laneIndex")]
    pub lane_index: Vec<usize>,
    pub intersections: Vec<Intersection>,
}

/// When a car's contact point crossed a measurement line.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Intersection {
    #[serde(rename = "measurementLineId")]
    pub measurement_line_id: usize,
    /// Seconds from frame 0.
    #[serde(rename = "videoTime")]
    pub video_time: f64,
}

/// A true track in the layout of a BCS system file's `cars`.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct TruthTrack {
    pub id: u32,
    pub frames: Vec<u32>,
    #[serde(rename = "posX")]
    pub pos_x: Vec<f64>,
    #[serde(rename = "posY")]
    pub pos_y: Vec<f64>,
}

/// Collects the moving vehicles' contact points frame by frame.
#[derive(Debug, Default)]
pub struct SpeedTruth {
    seen: BTreeMap<u32, Vec<Seen>>,
}

impl SpeedTruth {
    pub fn new() -> SpeedTruth {
        SpeedTruth::default()
    }

    /// Record the vehicles of one rendered frame.
    pub fn push(&mut self, vehicles: &[VehicleTruth]) {
        for v in vehicles.iter().filter(|v| !v.parked) {
            self.seen.entry(v.id).or_default().push(Seen {
                frame: v.frame,
                contact: contact_point(v),
                heading: v.pose.heading,
                speed_mps: v.speed_mps,
                detectable: detectable(v),
                unclipped: unclipped(v),
            });
        }
    }

    /// The GT cars (module docs), by id, at `fps` frames per second.
    pub fn cars(&self, geom: &SpeedGeometry, fps: f64) -> Vec<TruthCar> {
        let mut out = Vec::new();
        for (&id, seen) in &self.seen {
            if !seen.iter().all(|s| geom.along(s.heading)) {
                continue;
            }
            // Per line: (fractional frame, contact point, index of the frame before it).
            let mut crossed: Vec<Option<(f64, [f64; 2], usize)>> = Vec::new();
            for &l in &geom.measurement_lines {
                let mut hit = None;
                for (k, w) in seen.windows(2).enumerate() {
                    if w[1].frame != w[0].frame + 1 {
                        continue;
                    }
                    let (a, b) = (value(l, w[0].contact), value(l, w[1].contact));
                    if (a <= 0.0) != (b <= 0.0) && a != b {
                        let f = a / (a - b);
                        let p = [
                            w[0].contact[0] + f * (w[1].contact[0] - w[0].contact[0]),
                            w[0].contact[1] + f * (w[1].contact[1] - w[0].contact[1]),
                        ];
                        hit = Some((f64::from(w[0].frame) + f, p, k));
                        break;
                    }
                }
                crossed.push(hit);
            }
            if crossed[0].is_none() {
                continue;
            }
            let intersections: Vec<Intersection> = crossed
                .iter()
                .enumerate()
                .rev()
                .filter_map(|(i, c)| {
                    c.map(|(f, _, _)| Intersection {
                        measurement_line_id: i,
                        video_time: f / fps,
                    })
                })
                .collect();
            let hits: Vec<(f64, [f64; 2], usize)> = crossed.iter().flatten().copied().collect();
            let first = hits.iter().map(|h| h.2).min().unwrap_or(0);
            let last = hits.iter().map(|h| h.2 + 1).max().unwrap_or(0);
            let span = &seen[first..=last.min(seen.len() - 1)];
            let speed_mps = span.iter().map(|s| s.speed_mps).sum::<f64>() / span.len() as f64;
            let mut lane_index: Vec<usize> = hits.iter().filter_map(|h| geom.lane(h.1)).collect();
            lane_index.sort_unstable();
            lane_index.dedup();
            let all_crossed = crossed.iter().all(Option::is_some);
            let valid = all_crossed
                && seen[first].detectable
                && seen[last.min(seen.len() - 1)].detectable
                && speed_mps > 1.0
                && !lane_index.is_empty();
            out.push(TruthCar {
                car_id: id,
                speed: speed_mps * 3.6,
                valid,
                lane_index,
                intersections,
            });
        }
        out
    }

    /// The true tracks of the moving vehicles: contact points of the frames where the box is
    /// detectable and wholly inside the image (a perfect tracker's `cars`). Tracks of fewer
    /// than 2 points are left out.
    pub fn tracks(&self) -> Vec<TruthTrack> {
        let mut out = Vec::new();
        for (&id, seen) in &self.seen {
            let kept: Vec<&Seen> = seen
                .iter()
                .filter(|s| s.detectable && s.unclipped)
                .collect();
            if kept.len() < 2 {
                continue;
            }
            out.push(TruthTrack {
                id,
                frames: kept.iter().map(|s| s.frame).collect(),
                pos_x: kept.iter().map(|s| s.contact[0]).collect(),
                pos_y: kept.iter().map(|s| s.contact[1]).collect(),
            });
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_line_through_two_points_is_unit_and_contains_them() {
        let l = line_through([1.0, 2.0], [4.0, 6.0]).unwrap();
        assert!((l[0].hypot(l[1]) - 1.0).abs() < 1e-12);
        assert!(value(l, [1.0, 2.0]).abs() < 1e-9);
        assert!(value(l, [4.0, 6.0]).abs() < 1e-9);
        assert!(line_through([1.0, 2.0], [1.0, 2.0]).is_none());
    }
}
