//! The pinhole camera over the road plane, and the ground-truth quantities derived from it.
//!
//! # Conventions
//! - World: metres, right-handed, **z up**, the road is the plane z = 0.
//! - Camera frame: x right, y down, z forward (optical axis). `rotation` is camera-from-world:
//!   `X_cam = R (X_world - C)`.
//! - Image: continuous pixel coordinates, x right, y down; pixel (i, j) covers
//!   [i, i+1) x [j, j+1), so its centre is (i + 0.5, j + 0.5). A camera point projects to
//!   `(f x/z + px, f y/z + py)`; the principal point defaults to (W/2, H/2), the image centre.
//! - Angles: `yaw` is the heading of the optical axis on the ground (radians from +x towards +y),
//!   `pitch` its tilt below the horizontal (positive looks down), `roll` a rotation about the
//!   optical axis (positive turns the image content clockwise).

use crate::math::{mat_t_vec, mat_vec, M3, V3};

/// A pinhole camera: intrinsics (focal, principal point, image size) and pose.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Camera {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Focal length in pixels.
    pub focal_px: f64,
    /// Principal point, image pixels (continuous convention above).
    pub pp: [f64; 2],
    /// Camera centre in world metres; `position.z` is the height above the road.
    pub position: V3,
    /// Camera-from-world rotation (rows are the camera axes in world coordinates).
    pub rotation: M3,
}

impl Camera {
    /// A camera at `position` with the given yaw, pitch (down) and roll, principal point at the
    /// image centre.
    pub fn from_angles(
        width: u32,
        height: u32,
        focal_px: f64,
        position: V3,
        yaw: f64,
        pitch: f64,
        roll: f64,
    ) -> Camera {
        Camera {
            width,
            height,
            focal_px,
            pp: [f64::from(width) / 2.0, f64::from(height) / 2.0],
            position,
            rotation: rotation_from_angles(yaw, pitch, roll),
        }
    }

    /// Camera height above the road plane, metres.
    pub fn height_m(&self) -> f64 {
        self.position.z
    }

    /// (yaw, pitch, roll) in radians, recovered from the rotation.
    pub fn angles(&self) -> (f64, f64, f64) {
        let fwd = V3::new(
            self.rotation[2][0],
            self.rotation[2][1],
            self.rotation[2][2],
        );
        let right = V3::new(
            self.rotation[0][0],
            self.rotation[0][1],
            self.rotation[0][2],
        );
        let pitch = (-fwd.z).clamp(-1.0, 1.0).asin();
        let yaw = fwd.y.atan2(fwd.x);
        let base = rotation_from_angles(yaw, pitch, 0.0);
        let r0 = V3::new(base[0][0], base[0][1], base[0][2]);
        let d0 = V3::new(base[1][0], base[1][1], base[1][2]);
        let roll = right.dot(d0).atan2(right.dot(r0));
        (yaw, pitch, roll)
    }

    /// Intrinsic matrix K.
    pub fn k(&self) -> M3 {
        [
            [self.focal_px, 0.0, self.pp[0]],
            [0.0, self.focal_px, self.pp[1]],
            [0.0, 0.0, 1.0],
        ]
    }

    /// World point to camera frame.
    pub fn to_camera(&self, p: V3) -> V3 {
        mat_vec(&self.rotation, p - self.position)
    }

    /// World direction to camera frame.
    pub fn dir_to_camera(&self, d: V3) -> V3 {
        mat_vec(&self.rotation, d)
    }

    /// Camera-frame point to image pixels; `None` when not in front of the camera.
    pub fn project_cam(&self, c: V3) -> Option<[f64; 2]> {
        if c.z <= 1e-9 {
            return None;
        }
        Some([
            self.focal_px * c.x / c.z + self.pp[0],
            self.focal_px * c.y / c.z + self.pp[1],
        ])
    }

    /// World point to image pixels; `None` when not in front of the camera.
    pub fn project(&self, p: V3) -> Option<[f64; 2]> {
        self.project_cam(self.to_camera(p))
    }

    /// Homogeneous image point of the world direction `d` (its vanishing point): `K R d`.
    pub fn vp_homogeneous(&self, d: V3) -> [f64; 3] {
        let c = self.dir_to_camera(d);
        [
            self.focal_px * c.x + self.pp[0] * c.z,
            self.focal_px * c.y + self.pp[1] * c.z,
            c.z,
        ]
    }

    /// Vanishing point of the world direction `d` in image pixels; `None` when it is at
    /// infinity (direction parallel to the image plane, to 1e-12 relative).
    pub fn vp(&self, d: V3) -> Option<[f64; 2]> {
        let c = self.dir_to_camera(d.normalized());
        if c.z.abs() < 1e-12 {
            return None;
        }
        Some([
            self.focal_px * c.x / c.z + self.pp[0],
            self.focal_px * c.y / c.z + self.pp[1],
        ])
    }

    /// VP of a horizontal heading (radians from +x towards +y): a vehicle's VP1.
    pub fn vp_of_heading(&self, heading: f64) -> Option<[f64; 2]> {
        self.vp(heading_dir(heading))
    }

    /// VP of the vertical direction (VP3).
    pub fn vp3(&self) -> Option<[f64; 2]> {
        self.vp(V3::new(0.0, 0.0, 1.0))
    }

    /// The horizon as a homogeneous line [a, b, c] (a x + b y + c = 0) with a² + b² = 1,
    /// oriented so that points below the horizon on the image (road side) give a positive value.
    pub fn horizon(&self) -> [f64; 3] {
        // l = K^-T R e_z: l . (K R d) = e_z . d = 0 for every horizontal direction d.
        let n = mat_vec(&self.rotation, V3::new(0.0, 0.0, 1.0));
        let f = self.focal_px;
        let (px, py) = (self.pp[0], self.pp[1]);
        // K^-T = [[1/f, 0, 0], [0, 1/f, 0], [-px/f, -py/f, 1]]
        let a = n.x / f;
        let b = n.y / f;
        let c = -px / f * n.x - py / f * n.y + n.z;
        let s = (a * a + b * b).sqrt();
        // Ground points are below the camera: n . X_cam < 0 there. Sign so that they are positive.
        let sign = -1.0;
        if s > 0.0 {
            [sign * a / s, sign * b / s, sign * c / s]
        } else {
            [0.0, 0.0, sign * c]
        }
    }

    /// Viewing ray through image point (u, v), world direction (not normalised).
    pub fn ray(&self, u: f64, v: f64) -> V3 {
        mat_t_vec(
            &self.rotation,
            V3::new(u - self.pp[0], v - self.pp[1], self.focal_px),
        )
    }

    /// The road point seen at image point (u, v); `None` above the horizon.
    pub fn ground_point(&self, u: f64, v: f64) -> Option<V3> {
        let r = self.ray(u, v);
        if r.z >= -1e-12 {
            return None;
        }
        let t = -self.position.z / r.z;
        Some(self.position + r * t)
    }

    /// True when the image point lies inside the image.
    pub fn in_image(&self, p: [f64; 2]) -> bool {
        p[0] >= 0.0
            && p[1] >= 0.0
            && p[0] <= f64::from(self.width)
            && p[1] <= f64::from(self.height)
    }

    /// BrnoCompSpeed `scale` for this camera when the calibration is given as (vp1, vp2, pp):
    /// metres = scale * |X(p1) - X(p2)| with the BCS back-projection of DESIGN.md §3 (camera
    /// centre (px, py, 0), ray (p - pp, f), plane n.X + 10 = 0). That plane lies at distance
    /// |n.C + 10| from the centre, so scale = height / |n.C + 10|. `None` when the VPs are not
    /// an orthogonal pair.
    pub fn bcs_scale(&self, vp1: [f64; 2], vp2: [f64; 2]) -> Option<f64> {
        let n = bcs_plane_normal(vp1, vp2, self.pp)?;
        let d = (n.x * self.pp[0] + n.y * self.pp[1] + 10.0).abs();
        if d < 1e-9 {
            return None;
        }
        Some(self.height_m() / d)
    }
}

/// The unit road-plane normal of the BCS convention, from two VPs and the principal point:
/// V1 = (vp1 - pp, f), V2 = (vp2 - pp, f), V3 = V1 x V2, n = normalize((vp3 - pp, f)).
pub fn bcs_plane_normal(vp1: [f64; 2], vp2: [f64; 2], pp: [f64; 2]) -> Option<V3> {
    let f2 = -((vp1[0] - pp[0]) * (vp2[0] - pp[0]) + (vp1[1] - pp[1]) * (vp2[1] - pp[1]));
    if f2.is_nan() || f2 <= 0.0 {
        return None;
    }
    let f = f2.sqrt();
    let v1 = V3::new(vp1[0] - pp[0], vp1[1] - pp[1], f);
    let v2 = V3::new(vp2[0] - pp[0], vp2[1] - pp[1], f);
    let v3 = v1.cross(v2);
    if v3.z.abs() < 1e-300 {
        return None;
    }
    let n = V3::new(v3.x / v3.z * f, v3.y / v3.z * f, f).normalized();
    Some(n)
}

/// BCS back-projection of image point `p` (DESIGN.md §3), for writing and checking gt files.
pub fn bcs_backproject(p: [f64; 2], vp1: [f64; 2], vp2: [f64; 2], pp: [f64; 2]) -> Option<V3> {
    let f2 = -((vp1[0] - pp[0]) * (vp2[0] - pp[0]) + (vp1[1] - pp[1]) * (vp2[1] - pp[1]));
    if f2.is_nan() || f2 <= 0.0 {
        return None;
    }
    let f = f2.sqrt();
    let n = bcs_plane_normal(vp1, vp2, pp)?;
    let c = V3::new(pp[0], pp[1], 0.0);
    let r = V3::new(p[0] - pp[0], p[1] - pp[1], f);
    let den = n.dot(r);
    if den.abs() < 1e-300 {
        return None;
    }
    let t = -(n.dot(c) + 10.0) / den;
    Some(c + r * t)
}

/// Unit horizontal direction of a heading angle (radians from +x towards +y).
pub fn heading_dir(heading: f64) -> V3 {
    V3::new(heading.cos(), heading.sin(), 0.0)
}

/// Camera-from-world rotation for yaw, pitch (down) and roll; see the module conventions.
pub fn rotation_from_angles(yaw: f64, pitch: f64, roll: f64) -> M3 {
    let (sy, cy) = yaw.sin_cos();
    let (sp, cp) = pitch.sin_cos();
    let (sr, cr) = roll.sin_cos();
    let fwd = V3::new(cp * cy, cp * sy, -sp);
    let right = V3::new(sy, -cy, 0.0);
    let down = fwd.cross(right);
    let r = right * cr + down * sr;
    let d = right * (-sr) + down * cr;
    [[r.x, r.y, r.z], [d.x, d.y, d.z], [fwd.x, fwd.y, fwd.z]]
}

/// A camera whose road frame is defined by two orthogonal vanishing points, e.g. a real view
/// calibrated in BrnoCompSpeed format. World +x points towards VP1, z is up, the camera
/// stands at (0, 0, height_m).
///
/// Returns `None` when the VPs are not an orthogonal pair for `pp`.
pub fn camera_from_vps(
    width: u32,
    height: u32,
    vp1: [f64; 2],
    vp2: [f64; 2],
    pp: [f64; 2],
    height_m: f64,
) -> Option<Camera> {
    let f2 = -((vp1[0] - pp[0]) * (vp2[0] - pp[0]) + (vp1[1] - pp[1]) * (vp2[1] - pp[1]));
    if f2.is_nan() || f2 <= 0.0 {
        return None;
    }
    let f = f2.sqrt();
    let d1 = V3::new(vp1[0] - pp[0], vp1[1] - pp[1], f).normalized();
    let d2 = V3::new(vp2[0] - pp[0], vp2[1] - pp[1], f).normalized();
    // Up in camera coordinates: orthogonal to both, pointing to the image top (negative y).
    let mut up = d1.cross(d2).normalized();
    if up.y > 0.0 {
        up = -up;
    }
    let x = d1;
    let y = up.cross(x).normalized();
    // Columns of R (camera-from-world) are the world axes in camera coordinates.
    let rotation = [[x.x, y.x, up.x], [x.y, y.y, up.y], [x.z, y.z, up.z]];
    Some(Camera {
        width,
        height,
        focal_px: f,
        pp,
        position: V3::new(0.0, 0.0, height_m),
        rotation,
    })
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used)]
    use super::*;

    #[test]
    fn angles_round_trip() {
        let cam = Camera::from_angles(1920, 1080, 1500.0, V3::new(1.0, 2.0, 8.0), 0.7, 0.4, -0.05);
        let (y, p, r) = cam.angles();
        assert!((y - 0.7).abs() < 1e-12 && (p - 0.4).abs() < 1e-12 && (r + 0.05).abs() < 1e-12);
    }

    #[test]
    fn pitch_down_sees_ground_below_centre() {
        let cam = Camera::from_angles(1920, 1080, 1000.0, V3::new(0.0, 0.0, 10.0), 0.0, 0.3, 0.0);
        let g = cam.ground_point(960.0, 540.0).unwrap();
        assert!((g.x - 10.0 / 0.3f64.tan()).abs() < 1e-9 && g.y.abs() < 1e-9);
        let p = cam.project(g).unwrap();
        assert!((p[0] - 960.0).abs() < 1e-9 && (p[1] - 540.0).abs() < 1e-9);
        // The horizon is above the centre and the road below is on its positive side.
        let h = cam.horizon();
        assert!(h[0] * 960.0 + h[1] * 540.0 + h[2] > 0.0);
        assert!(h[0] * 960.0 + h[1] * 100.0 + h[2] < 0.0);
    }

    #[test]
    fn camera_from_vps_reproduces_vps() {
        let cam = Camera::from_angles(1920, 1080, 1300.0, V3::new(0.0, 0.0, 7.0), 0.5, 0.35, 0.04);
        let vp1 = cam.vp_of_heading(0.2).unwrap();
        let vp2 = cam
            .vp_of_heading(0.2 + std::f64::consts::FRAC_PI_2)
            .unwrap();
        let c2 = camera_from_vps(1920, 1080, vp1, vp2, cam.pp, 7.0).unwrap();
        assert!((c2.focal_px - 1300.0).abs() < 1e-6);
        let v = c2.vp_of_heading(0.0).unwrap();
        assert!((v[0] - vp1[0]).abs() < 1e-6 && (v[1] - vp1[1]).abs() < 1e-6);
        let w = c2.vp_of_heading(std::f64::consts::FRAC_PI_2).unwrap();
        assert!((w[0] - vp2[0]).abs() < 1e-5 && (w[1] - vp2[1]).abs() < 1e-5);
        // Same horizon.
        let (h1, h2) = (cam.horizon(), c2.horizon());
        for k in 0..3 {
            assert!((h1[k] - h2[k]).abs() < 1e-9, "{h1:?} {h2:?}");
        }
    }

    #[test]
    fn bcs_scale_converts_back_projected_distances_to_metres() {
        let cam = Camera::from_angles(1920, 1080, 1800.0, V3::new(0.0, 0.0, 9.0), 0.3, 0.25, 0.02);
        let vp1 = cam.vp_of_heading(0.1).unwrap();
        let vp2 = cam
            .vp_of_heading(0.1 + std::f64::consts::FRAC_PI_2)
            .unwrap();
        let scale = cam.bcs_scale(vp1, vp2).unwrap();
        let g1 = cam.ground_point(700.0, 800.0).unwrap();
        let g2 = cam.ground_point(1300.0, 900.0).unwrap();
        let p1 = cam.project(g1).unwrap();
        let p2 = cam.project(g2).unwrap();
        let x1 = bcs_backproject(p1, vp1, vp2, cam.pp).unwrap();
        let x2 = bcs_backproject(p2, vp1, vp2, cam.pp).unwrap();
        let metres = (g1 - g2).norm();
        assert!((scale * (x1 - x2).norm() - metres).abs() < 1e-6 * metres);
    }
}
