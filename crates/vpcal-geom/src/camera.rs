//! A camera from two orthogonal vanishing points (DESIGN.md §3, paper §3).
//!
//! With the principal point `pp` known (zero skew, square pixels, no distortion), two vanishing
//! points `u`, `v` of orthogonal directions give the focal length
//! `f = sqrt(-(u - pp)·(v - pp))`. Writing `V1 = (vp1 - pp, f)` and `V2 = (vp2 - pp, f)` for the
//! directions in camera coordinates, the third direction is `V3 = V1 x V2`, its vanishing point
//! `vp3 = V3[:2] / V3[2] · f + pp`, and the road-plane normal `n = normalize((vp3 - pp, f))`
//! (equivalently `n ∝ Kᵀ h` for the horizon `h`, the line through vp1 and vp2).
//!
//! # Back-projection (BrnoCompSpeed convention)
//! BrnoCompSpeed's evaluation places the camera centre at `C = (px, py, 0)`, gives pixel `p` the
//! ray `r = (p - pp, f)`, and intersects it with the plane `n·X + 10 = 0`:
//! `X(p) = C + t r`, `t = -(n·C + 10) / (n·r)`. A metric distance is `scale · |X(p1) - X(p2)|`.
//! [`Calibration::project_to_road`] reproduces this exactly so that BCS `scale` values keep
//! their meaning.
//!
//! # What is and isn't observable
//! Two VPs fix `f` (given `pp`), the horizon, the road normal and the camera rotation against
//! the road. They do not fix the camera height: distances are known up to one scale factor,
//! which needs one known road distance ([`Calibration::scale_from_distance`]).
//!
//! # The road frame (OpenCV exports)
//! [`Calibration::road_frame`] is the physical frame of the road for `cv2.projectPoints`: origin
//! on the road right under the camera, x along the traffic (towards vp1, away from the camera),
//! z up (out of the road, towards the camera), y = z × x; the camera stands
//! [`Calibration::plane_distance`] plane units above the origin (times a BCS scale: metres).
//! Unlike the BCS back-projection its road lies in front of the camera; distances are the same.

use crate::point::{cross, dot3, normalize3, Line, Point2};
use crate::rotation::{mat_t_vec, Mat3};

/// The constant of the BCS road plane `n·X + 10 = 0` (module docs).
pub const BCS_PLANE_OFFSET: f64 = 10.0;

/// The road frame of an export (module docs): `X_cam = rotation · X_road + translation`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RoadFrame {
    /// Road to camera; its columns are the road axes in camera coordinates.
    pub rotation: Mat3,
    /// The road origin in camera coordinates, plane units (multiply by a scale for metres).
    pub translation: [f64; 3],
}

/// Why no camera could be computed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GeomError {
    /// An input point is NaN or infinite.
    #[error("{what} is not finite ({value})")]
    NonFinite { what: &'static str, value: Point2 },
    /// The two vanishing points coincide.
    #[error("vp1 and vp2 coincide at {0}")]
    CoincidentVps(Point2),
    /// `-(vp1 - pp)·(vp2 - pp)` is not positive: the pair is not orthogonal for any real focal.
    #[error(
        "the vanishing points give no real focal length: VP1 and VP2 lie on the same side of \
         the principal point (-(vp1-pp)·(vp2-pp) = {} px², which must be positive)",
        fmt_square_px(*value)
    )]
    ImaginaryFocal { value: f64 },
    /// The horizon passes through the principal point: the camera looks parallel to the road
    /// and the road plane cannot be intersected.
    #[error("the horizon passes through the principal point: the road plane is edge-on")]
    EdgeOnRoad,
}

/// A squared pixel distance for a message: a few significant figures, not float noise.
fn fmt_square_px(value: f64) -> String {
    if !value.is_finite() {
        return format!("{value}");
    }
    let a = value.abs();
    if a >= 1e6 {
        format!("{value:.2e}")
    } else {
        format!("{value:.0}")
    }
}

/// Focal length in pixels from two orthogonal VPs and the principal point, or `None` when the
/// pair is inconsistent (non-positive value under the root, non-finite input).
pub fn focal_from_vps(vp1: Point2, vp2: Point2, pp: Point2) -> Option<f64> {
    let v = -(vp1 - pp).dot(vp2 - pp);
    (v > 0.0 && v.is_finite()).then(|| v.sqrt())
}

/// The point on `line` whose direction is orthogonal to `vp1`'s for focal `focal_px`:
/// `(vp1 - pp)·(vp2 - pp) = -f²`. `None` when that locus is parallel to `line`.
pub fn orthogonal_vp_on_line(vp1: Point2, line: Line, focal_px: f64, pp: Point2) -> Option<Point2> {
    let a = vp1.x - pp.x;
    let b = vp1.y - pp.y;
    // a (x - px) + b (y - py) + f² = 0
    let locus = Line([a, b, -(a * pp.x + b * pp.y) + focal_px * focal_px]);
    line.intersect(locus)
}

/// A calibrated camera: intrinsics (`focal_px`, `pp`) and the road plane, from two VPs.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Calibration {
    /// Focal length, pixels.
    pub focal_px: f64,
    /// Principal point, frame pixels.
    pub pp: Point2,
    /// Vanishing point of the traffic direction (vehicles' facing), frame pixels.
    pub vp1: Point2,
    /// Vanishing point orthogonal to vp1 in the road plane, frame pixels.
    pub vp2: Point2,
    /// Vanishing point of the road normal, frame pixels.
    pub vp3: Point2,
    /// The horizon (line through vp1 and vp2), homogeneous, normalised so `a² + b² = 1`.
    pub horizon: Line,
    /// Unit road-plane normal in camera coordinates (x right, y down, z forward), pointing
    /// towards `vp3` (the BCS convention: `normalize((vp3 - pp, f))`).
    pub road_normal: [f64; 3],
    /// Rotation from road coordinates to camera coordinates (determinant +1); its columns are
    /// the unit directions of vp1, of vp2 (signed to make the frame right-handed) and the road
    /// normal, in camera coordinates.
    pub rotation: [[f64; 3]; 3],
}

impl Calibration {
    /// The camera of two orthogonal vanishing points and a principal point.
    ///
    /// # Errors
    /// [`GeomError`] for non-finite input (VPs at infinity), coincident VPs, an imaginary
    /// focal length or an edge-on road plane.
    pub fn from_vps(vp1: Point2, vp2: Point2, pp: Point2) -> Result<Calibration, GeomError> {
        for (what, value) in [("vp1", vp1), ("vp2", vp2), ("principal point", pp)] {
            if !value.is_finite() {
                return Err(GeomError::NonFinite { what, value });
            }
        }
        if vp1 == vp2 {
            return Err(GeomError::CoincidentVps(vp1));
        }
        let focal_px = focal_from_vps(vp1, vp2, pp).ok_or(GeomError::ImaginaryFocal {
            value: -(vp1 - pp).dot(vp2 - pp),
        })?;
        let d1 = [vp1.x - pp.x, vp1.y - pp.y, focal_px];
        let d2 = [vp2.x - pp.x, vp2.y - pp.y, focal_px];
        let d3 = cross(d1, d2);
        // Relative test: the optical axis lies in the road plane when d3 has no z component.
        if d3[2].abs() <= 1e-12 * dot3(d3, d3).sqrt() {
            return Err(GeomError::EdgeOnRoad);
        }
        let vp3 = Point2::new(
            d3[0] / d3[2] * focal_px + pp.x,
            d3[1] / d3[2] * focal_px + pp.y,
        );
        let road_normal =
            normalize3([vp3.x - pp.x, vp3.y - pp.y, focal_px]).ok_or(GeomError::NonFinite {
                what: "vp3",
                value: vp3,
            })?;
        let horizon = Line::through(vp1, vp2)
            .and_then(Line::normalized)
            .ok_or(GeomError::CoincidentVps(vp1))?;
        let e1 = normalize3(d1).ok_or(GeomError::NonFinite {
            what: "vp1",
            value: vp1,
        })?;
        let e3 = road_normal;
        // Right-handed frame: e2 = e3 x e1 is vp2's direction up to sign and rounding (vp1 and
        // vp2 are orthogonal by construction of f); a VP fixes a direction only up to sign.
        let e2 = cross(e3, e1);
        let rotation = [
            [e1[0], e2[0], e3[0]],
            [e1[1], e2[1], e3[1]],
            [e1[2], e2[2], e3[2]],
        ];
        Ok(Calibration {
            focal_px,
            pp,
            vp1,
            vp2,
            vp3,
            horizon,
            road_normal,
            rotation,
        })
    }

    /// The intrinsic matrix `K = [[f, 0, px], [0, f, py], [0, 0, 1]]`.
    pub fn k(&self) -> [[f64; 3]; 3] {
        [
            [self.focal_px, 0.0, self.pp.x],
            [0.0, self.focal_px, self.pp.y],
            [0.0, 0.0, 1.0],
        ]
    }

    /// Angle between the optical axis and the road plane (camera pitch down), radians.
    pub fn tilt(&self) -> f64 {
        self.road_normal[2].abs().min(1.0).asin()
    }

    /// Roll: angle of the horizon against the image x axis, radians.
    pub fn roll(&self) -> f64 {
        self.horizon.angle()
    }

    /// Back-projection of pixel `p` onto the road plane in the BrnoCompSpeed convention
    /// (module docs). `None` when the ray is parallel to the plane.
    pub fn project_to_road(&self, p: Point2) -> Option<[f64; 3]> {
        let c = [self.pp.x, self.pp.y, 0.0];
        let r = [p.x - self.pp.x, p.y - self.pp.y, self.focal_px];
        let t = -(dot3(self.road_normal, c) + BCS_PLANE_OFFSET) / dot3(self.road_normal, r);
        let x = [c[0] + t * r[0], c[1] + t * r[1], c[2] + t * r[2]];
        x.iter().all(|v| v.is_finite()).then_some(x)
    }

    /// Distance between the road points under two pixels, in plane units (multiply by a BCS
    /// `scale` for metres).
    pub fn road_distance(&self, p1: Point2, p2: Point2) -> Option<f64> {
        let a = self.project_to_road(p1)?;
        let b = self.project_to_road(p2)?;
        let d = [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
        Some(dot3(d, d).sqrt())
    }

    /// The pixel that images road point `x` (the inverse of [`Calibration::project_to_road`]);
    /// `None` for a point at the camera centre's depth.
    pub fn image_of_road_point(&self, x: [f64; 3]) -> Option<Point2> {
        let rel = [x[0] - self.pp.x, x[1] - self.pp.y, x[2]];
        let p = Point2::new(
            self.pp.x + rel[0] / rel[2] * self.focal_px,
            self.pp.y + rel[1] / rel[2] * self.focal_px,
        );
        p.is_finite().then_some(p)
    }

    /// The BCS scale that makes the road distance between `p1` and `p2` equal `distance_m`.
    pub fn scale_from_distance(&self, p1: Point2, p2: Point2, distance_m: f64) -> Option<f64> {
        let d = self.road_distance(p1, p2)?;
        let s = distance_m / d;
        (d > 0.0 && s.is_finite() && s > 0.0).then_some(s)
    }

    /// Whether pixel `p` sees the road: its ray points to the road side of the horizon
    /// (`n·r > 0`; for a camera looking down at the road the normal `n` of the BCS convention
    /// points from the camera towards the ground).
    ///
    /// Note that the BCS back-projection also returns points for pixels above the horizon (and
    /// its plane may lie behind the camera centre); use this to tell road pixels apart.
    pub fn sees_road(&self, p: Point2) -> bool {
        let r = [p.x - self.pp.x, p.y - self.pp.y, self.focal_px];
        dot3(self.road_normal, r) > 0.0
    }

    /// Distance from the camera centre to the road, plane units: the BCS back-projection's
    /// `|n·C + 10|` with `C = (px, py, 0)`. A BCS `scale` times this is the camera's height
    /// above the road in metres.
    pub fn plane_distance(&self) -> f64 {
        (dot3(self.road_normal, [self.pp.x, self.pp.y, 0.0]) + BCS_PLANE_OFFSET).abs()
    }

    /// The physical road frame (module docs), in plane units.
    pub fn road_frame(&self) -> RoadFrame {
        let n = self.road_normal;
        let h = self.plane_distance();
        // The road is on the side of n (`sees_road`), h away.
        let z = [-n[0], -n[1], -n[2]];
        let d1 = [
            self.vp1.x - self.pp.x,
            self.vp1.y - self.pp.y,
            self.focal_px,
        ];
        // vp1's direction lies in the road plane; remove the rounding off it.
        let along = dot3(d1, n);
        let x = normalize3([
            d1[0] - along * n[0],
            d1[1] - along * n[1],
            d1[2] - along * n[2],
        ])
        .unwrap_or([1.0, 0.0, 0.0]);
        let y = cross(z, x);
        RoadFrame {
            rotation: [[x[0], y[0], z[0]], [x[1], y[1], z[1]], [x[2], y[2], z[2]]],
            translation: [h * n[0], h * n[1], h * n[2]],
        }
    }

    /// Road-frame coordinates `(x, y)` (plane units, z = 0) of the road point pixel `p` sees;
    /// `None` for pixels that do not see the road.
    pub fn road_point(&self, p: Point2) -> Option<[f64; 2]> {
        let r = [p.x - self.pp.x, p.y - self.pp.y, self.focal_px];
        let n_r = dot3(self.road_normal, r);
        if n_r.is_nan() || n_r <= 0.0 {
            return None;
        }
        let lambda = self.plane_distance() / n_r;
        let frame = self.road_frame();
        let t = frame.translation;
        let rel = [
            lambda * r[0] - t[0],
            lambda * r[1] - t[1],
            lambda * r[2] - t[2],
        ];
        let q = mat_t_vec(&frame.rotation, rel);
        (q[0].is_finite() && q[1].is_finite()).then_some([q[0], q[1]])
    }

    /// The homography from pixels to road-frame points in metres (`[x, y, 1] ~ H [u, v, 1]`,
    /// the road frame of [`Calibration::road_frame`]: origin under the camera, x along the
    /// road towards VP1, y across, z up) for a BCS scale of `m_per_unit` metres per plane
    /// unit, scaled so that `w = 1` at the principal point; `None` when it is singular.
    pub fn road_homography(&self, m_per_unit: f64) -> Option<Mat3> {
        let frame = self.road_frame();
        let r = frame.rotation;
        let t = frame.translation.map(|v| v * m_per_unit);
        // Road (x, y, 1) in metres to camera: [r1 r2 t]; then K.
        let g = [
            [r[0][0], r[0][1], t[0]],
            [r[1][0], r[1][1], t[1]],
            [r[2][0], r[2][1], t[2]],
        ];
        let k = self.k();
        let mut kg = [[0.0; 3]; 3];
        for (i, row) in kg.iter_mut().enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                *v = (0..3).map(|l| k[i][l] * g[l][j]).sum();
            }
        }
        let h = crate::rotation::inverse3(&kg)?;
        // w = 1 at the principal point (which sees the road for a camera looking down; a
        // pixel of the top-left corner may lie on the horizon, where w = 0).
        let n = h[2][0] * self.pp.x + h[2][1] * self.pp.y + h[2][2];
        (n != 0.0 && n.is_finite()).then(|| h.map(|row| row.map(|v| v / n)))
    }

    /// The pixel that sees road-frame point `(x, y)` (plane units), the inverse of
    /// [`Calibration::road_point`]; `None` behind the camera.
    pub fn pixel_of_road_point(&self, q: [f64; 2]) -> Option<Point2> {
        let frame = self.road_frame();
        let m = &frame.rotation;
        let t = frame.translation;
        let c = [
            m[0][0] * q[0] + m[0][1] * q[1] + t[0],
            m[1][0] * q[0] + m[1][1] * q[1] + t[1],
            m[2][0] * q[0] + m[2][1] * q[1] + t[2],
        ];
        if c[2].is_nan() || c[2] <= 0.0 {
            return None;
        }
        let p = Point2::new(
            self.pp.x + self.focal_px * c[0] / c[2],
            self.pp.y + self.focal_px * c[1] / c[2],
        );
        p.is_finite().then_some(p)
    }
}
