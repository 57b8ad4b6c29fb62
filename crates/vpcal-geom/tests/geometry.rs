#![allow(clippy::unwrap_used, clippy::expect_used)]
//! Geometry, diamond space and heatmap codec: worked examples from DESIGN.md §4, round trips,
//! and cameras built from a known rotation and recovered from their vanishing points.

use approx::assert_relative_eq;
use proptest::prelude::*;
use vpcal_geom::camera::{focal_from_vps, Calibration, GeomError};
use vpcal_geom::diamond::{diamond_to_point, point_to_diamond, point_to_diamond_2d};
use vpcal_geom::heatmap::{DecodeMode, HeatmapCodec};
use vpcal_geom::{BoxPx, Point2};

/// A pinhole camera looking down at a road: yaw about the road normal, then pitch and roll.
struct TestCamera {
    f: f64,
    pp: Point2,
    r: [[f64; 3]; 3], // camera-from-road
}

fn matmul(a: [[f64; 3]; 3], b: [[f64; 3]; 3]) -> [[f64; 3]; 3] {
    let mut c = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            c[i][j] = (0..3).map(|k| a[i][k] * b[k][j]).sum();
        }
    }
    c
}

impl TestCamera {
    /// Road frame: x, y in the road plane, z up. Camera: x right, y down, z forward.
    fn new(f: f64, pp: Point2, pitch: f64, roll: f64, yaw: f64) -> TestCamera {
        // Base: camera looking horizontally along road +y, road z up -> camera -y.
        let base = [[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]];
        let (sp, cp) = pitch.sin_cos();
        let pitch_m = [[1.0, 0.0, 0.0], [0.0, cp, -sp], [0.0, sp, cp]];
        let (sr, cr) = roll.sin_cos();
        let roll_m = [[cr, -sr, 0.0], [sr, cr, 0.0], [0.0, 0.0, 1.0]];
        let (sy, cy) = yaw.sin_cos();
        let yaw_m = [[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]];
        TestCamera {
            f,
            pp,
            r: matmul(roll_m, matmul(pitch_m, matmul(base, yaw_m))),
        }
    }

    fn dir(&self, d: [f64; 3]) -> [f64; 3] {
        let r = self.r;
        [
            r[0][0] * d[0] + r[0][1] * d[1] + r[0][2] * d[2],
            r[1][0] * d[0] + r[1][1] * d[1] + r[1][2] * d[2],
            r[2][0] * d[0] + r[2][1] * d[1] + r[2][2] * d[2],
        ]
    }

    /// The pixel of road point `p` for the camera centre at road (0, 0, `h`).
    fn project_from_height(&self, p: [f64; 3], h: f64) -> Point2 {
        let c = self.dir([p[0], p[1], p[2] - h]);
        Point2::new(
            self.pp.x + self.f * c[0] / c[2],
            self.pp.y + self.f * c[1] / c[2],
        )
    }

    fn vp(&self, d: [f64; 3]) -> Point2 {
        let c = self.dir(d);
        Point2::new(
            self.pp.x + self.f * c[0] / c[2],
            self.pp.y + self.f * c[1] / c[2],
        )
    }
}

#[test]
fn camera_recovered_from_its_vanishing_points() {
    let pp = Point2::new(960.0, 540.0);
    for &(f, pitch, roll, yaw) in &[
        (1200.0, 0.4, 0.02, 0.3),
        (3000.0, 0.25, -0.05, -0.6),
        (700.0, 0.9, 0.1, 1.2),
    ] {
        let cam = TestCamera::new(f, pp, pitch, roll, yaw);
        // Heading along road +y, axle along road x (both in the plane, orthogonal).
        let vp1 = cam.vp([0.0, 1.0, 0.0]);
        let vp2 = cam.vp([1.0, 0.0, 0.0]);
        let calib = Calibration::from_vps(vp1, vp2, pp).unwrap();
        assert_relative_eq!(calib.focal_px, f, max_relative = 1e-9);
        // The normal is the camera's image of road z, up to sign.
        let z = cam.dir([0.0, 0.0, 1.0]);
        let n = calib.road_normal;
        let dot = (n[0] * z[0] + n[1] * z[1] + n[2] * z[2]).abs();
        assert_relative_eq!(dot, 1.0, max_relative = 1e-9);
        // vp3 is the image of the road normal.
        let vp3 = cam.vp([0.0, 0.0, 1.0]);
        assert_relative_eq!(calib.vp3.x, vp3.x, max_relative = 1e-7);
        assert_relative_eq!(calib.vp3.y, vp3.y, max_relative = 1e-7);
        // Any other horizontal direction vanishes on the horizon.
        let other = cam.vp([0.6, 0.8, 0.0]);
        assert!(calib.horizon.signed_distance(other).unwrap().abs() < 1e-6);
        // The rotation is orthonormal with determinant +1.
        let r = calib.rotation;
        let det = r[0][0] * (r[1][1] * r[2][2] - r[1][2] * r[2][1])
            - r[0][1] * (r[1][0] * r[2][2] - r[1][2] * r[2][0])
            + r[0][2] * (r[1][0] * r[2][1] - r[1][1] * r[2][0]);
        assert_relative_eq!(det, 1.0, max_relative = 1e-9);
        assert_relative_eq!(calib.tilt(), pitch, max_relative = 1e-9);
        assert_relative_eq!(calib.roll(), roll, max_relative = 1e-9, epsilon = 1e-12);
    }
}

/// Height of [`road_camera`] above the road, metres.
const ROAD_CAMERA_HEIGHT: f64 = 8.0;

/// A camera looking down at a road (f = 1000 px, pp (640, 360)) and its calibration from the
/// true VPs of the road's directions.
fn road_camera() -> (TestCamera, Calibration) {
    let pp = Point2::new(640.0, 360.0);
    let cam = TestCamera::new(1000.0, pp, 0.35, 0.03, 0.2);
    let calib =
        Calibration::from_vps(cam.vp([0.0, 1.0, 0.0]), cam.vp([1.0, 0.0, 0.0]), pp).unwrap();
    (cam, calib)
}

#[test]
fn road_distances_match_a_known_camera_up_to_one_scale() {
    // Points on the road plane z = 0 seen by a camera at height h; the ratio of two projected
    // distances must equal the ratio of true distances.
    let (cam, calib) = road_camera();
    let h = ROAD_CAMERA_HEIGHT;
    let project = |p: [f64; 3]| cam.project_from_height(p, h);
    let a = (project([0.0, 20.0, 0.0]), project([3.0, 26.0, 0.0]));
    let b = (project([-4.0, 40.0, 0.0]), project([-4.0, 52.0, 0.0]));
    let da = calib.road_distance(a.0, a.1).unwrap();
    let db = calib.road_distance(b.0, b.1).unwrap();
    let true_a = (9.0f64 + 36.0).sqrt();
    assert_relative_eq!(da / db, true_a / 12.0, max_relative = 1e-9);
    // One known distance fixes the scale for all others.
    let s = calib.scale_from_distance(b.0, b.1, 12.0).unwrap();
    assert_relative_eq!(s * da, true_a, max_relative = 1e-9);
    // image_of_road_point inverts project_to_road.
    let x = calib.project_to_road(a.0).unwrap();
    let back = calib.image_of_road_point(x).unwrap();
    assert_relative_eq!(back.x, a.0.x, max_relative = 1e-9);
    assert_relative_eq!(back.y, a.0.y, max_relative = 1e-9);
    // Road pixels see the road, the sky does not.
    assert!(calib.sees_road(a.0) && calib.sees_road(b.1));
    assert!(!calib.sees_road(Point2::new(640.0, -2000.0)));
}

#[test]
fn the_road_frame_puts_the_camera_above_the_road_and_keeps_distances() {
    let (cam, calib) = road_camera();
    let h = ROAD_CAMERA_HEIGHT;
    let project = |p: [f64; 3]| cam.project_from_height(p, h);
    let frame = calib.road_frame();
    // The camera centre in road coordinates is (0, 0, +plane distance): above the road, z up.
    let t = frame.translation;
    let centre = vpcal_geom::rotation::mat_t_vec(&frame.rotation, [-t[0], -t[1], -t[2]]);
    assert!(
        centre[0].abs() < 1e-9 && centre[1].abs() < 1e-9,
        "{centre:?}"
    );
    assert_relative_eq!(centre[2], calib.plane_distance(), max_relative = 1e-12);
    // Road axes: x along the traffic (vp1), z up in the camera's world.
    let up = cam.dir([0.0, 0.0, 1.0]);
    let m = frame.rotation;
    assert_relative_eq!(
        m[0][2] * up[0] + m[1][2] * up[1] + m[2][2] * up[2],
        1.0,
        max_relative = 1e-9
    );
    let heading = cam.dir([0.0, 1.0, 0.0]);
    assert_relative_eq!(
        m[0][0] * heading[0] + m[1][0] * heading[1] + m[2][0] * heading[2],
        1.0,
        max_relative = 1e-9
    );
    // Road points of pixels: distances are the BCS ones, and the pixel comes back.
    let (a, b) = (project([0.0, 20.0, 0.0]), project([3.0, 26.0, 0.0]));
    let (qa, qb) = (calib.road_point(a).unwrap(), calib.road_point(b).unwrap());
    let d = ((qa[0] - qb[0]).powi(2) + (qa[1] - qb[1]).powi(2)).sqrt();
    assert_relative_eq!(d, calib.road_distance(a, b).unwrap(), max_relative = 1e-9);
    // Scaled to metres, the plane distance becomes the true height h.
    let s = calib
        .scale_from_distance(a, b, (9.0f64 + 36.0).sqrt())
        .unwrap();
    assert_relative_eq!(s * calib.plane_distance(), h, max_relative = 1e-9);
    // The homography in metres maps each pixel to its road point, scaled.
    let hm = calib.road_homography(s).unwrap();
    for (p, q) in [(a, qa), (b, qb)] {
        let v = vpcal_geom::rotation::mat_vec(&hm, [p.x, p.y, 1.0]);
        assert_relative_eq!(v[0] / v[2], s * q[0], epsilon = 1e-9, max_relative = 1e-9);
        assert_relative_eq!(v[1] / v[2], s * q[1], epsilon = 1e-9, max_relative = 1e-9);
    }
    let v = vpcal_geom::rotation::mat_vec(&hm, [calib.pp.x, calib.pp.y, 1.0]);
    assert_relative_eq!(v[2], 1.0, max_relative = 1e-12);
    let back = calib.pixel_of_road_point(qa).unwrap();
    assert_relative_eq!(back.x, a.x, max_relative = 1e-9);
    assert_relative_eq!(back.y, a.y, max_relative = 1e-9);
    assert!(calib.road_point(Point2::new(640.0, -2000.0)).is_none());
    // rvec round trip of the export.
    let rvec = vpcal_geom::rotation::rotation_vector(&frame.rotation);
    let again = vpcal_geom::rotation::rotation_matrix(rvec);
    for i in 0..3 {
        for j in 0..3 {
            assert!((again[i][j] - m[i][j]).abs() < 1e-12);
        }
    }
}

#[test]
fn degenerate_cameras_are_typed_errors() {
    let pp = Point2::new(960.5, 540.5);
    let inf = Point2::new(f64::INFINITY, 3.0);
    assert!(matches!(
        Calibration::from_vps(inf, Point2::new(0.0, 0.0), pp),
        Err(GeomError::NonFinite { what: "vp1", .. })
    ));
    let nan = Point2::new(f64::NAN, 3.0);
    assert!(matches!(
        Calibration::from_vps(Point2::new(0.0, 0.0), nan, pp),
        Err(GeomError::NonFinite { what: "vp2", .. })
    ));
    let p = Point2::new(100.0, -500.0);
    assert_eq!(
        Calibration::from_vps(p, p, pp),
        Err(GeomError::CoincidentVps(p))
    );
    // Both VPs on the same side of pp: (vp1-pp)·(vp2-pp) > 0 -> imaginary focal.
    let r = Calibration::from_vps(Point2::new(1500.0, -300.0), Point2::new(2500.0, -200.0), pp);
    assert!(matches!(r, Err(GeomError::ImaginaryFocal { .. })));
    assert_eq!(
        focal_from_vps(Point2::new(1500.0, -300.0), Point2::new(2500.0, -200.0), pp),
        None
    );
    // Horizon through the principal point: edge-on road plane.
    let r = Calibration::from_vps(Point2::new(-1000.0, 540.5), Point2::new(3000.0, 540.5), pp);
    assert_eq!(r, Err(GeomError::EdgeOnRoad));
}

#[test]
fn box_frame_round_trip_and_definition() {
    let b = BoxPx::new(776.0, 107.0, 929.0, 182.0);
    assert_eq!(b.center(), Point2::new(852.5, 144.5));
    assert_eq!(b.half_size(), Point2::new(76.5, 37.5));
    // A real VPout item: vp1_box (0, -7.162...) -> vp1 (852.5, -124.081...).
    let vp1 = b.frame_from_box(Point2::new(0.0, -7.16216216216216));
    assert_relative_eq!(vp1.x, 852.5);
    assert_relative_eq!(vp1.y, -124.08108108108098, max_relative = 1e-12);
    let back = b.vp_in_box(vp1);
    assert_relative_eq!(back.y, -7.16216216216216, max_relative = 1e-12);
}

#[test]
fn diamond_worked_values() {
    // d = w = 1: S = 1 + |x| + |y|, u = -sgn(y)/S, v = -sgn(y) x / S.
    let uv = point_to_diamond_2d(Point2::new(2.0, -3.0), 1.0).unwrap();
    assert_relative_eq!(uv.x, 1.0 / 6.0);
    assert_relative_eq!(uv.y, 2.0 / 6.0);
    // Ideal points land on u = 0.
    let uv = point_to_diamond([1.0, 2.0, 0.0], 1.0).unwrap();
    assert_eq!(uv.x, 0.0);
    // The singular axis y = 0 maps to the limit y -> 0+, and the origin to the corner (-1, 0).
    let on_axis = point_to_diamond_2d(Point2::new(3.0, 0.0), 1.0).unwrap();
    let near = point_to_diamond_2d(Point2::new(3.0, 1e-12), 1.0).unwrap();
    assert_relative_eq!(on_axis.x, near.x, epsilon = 1e-10);
    assert_relative_eq!(on_axis.y, near.y, epsilon = 1e-10);
    assert_eq!(
        point_to_diamond_2d(Point2::new(0.0, 0.0), 1.0),
        Some(Point2::new(-1.0, 0.0))
    );
    assert_eq!(point_to_diamond([0.0, 0.0, 0.0], 1.0), None);
    assert_eq!(point_to_diamond([f64::NAN, 0.0, 1.0], 1.0), None);
}

#[test]
fn heatmap_worked_examples_from_design() {
    // (box-frame VP, scale) -> pixel -> decoded at the pixel centre (DESIGN.md §4).
    let codec = HeatmapCodec::default();
    let cases = [
        ((0.0, 10.0), 0.03, (7, 7), (0.0, 10.42)),
        ((0.0, 10.0), 1.0, (28, 28), (0.0, 9.50)),
        ((100.0, 2.0), 0.03, (47, 0), (104.4, 2.22)),
        ((0.3, 0.2), 1.0, (16, 4), (0.286, 0.214)),
    ];
    for ((x, y), s, pixel, (dx, dy)) in cases {
        let h = codec.vp_to_heatmap(Point2::new(x, y), s).unwrap();
        assert_eq!(
            (h.x.floor() as usize, h.y.floor() as usize),
            pixel,
            "{x},{y} s {s}"
        );
        let centre = Point2::new(pixel.0 as f64 + 0.5, pixel.1 as f64 + 0.5);
        let d = codec.heatmap_to_vp(centre, s);
        assert!(
            (d.x - dx).abs() < 0.006 * dx.abs().max(1.0),
            "{d:?} vs {dx}"
        );
        assert!(
            (d.y - dy).abs() < 0.006 * dy.abs().max(1.0),
            "{d:?} vs {dy}"
        );
    }
}

#[test]
fn targets_have_the_documented_shape() {
    let codec = HeatmapCodec::default();
    let t = codec.render_targets(Point2::new(0.0, 10.0), Point2::new(100.0, 2.0));
    assert_eq!(t.len(), 8 * 64 * 64);
    let plane = 64 * 64;
    // VP1 at scale 0.03 peaks at (7, 7); VP2 at scale 0.03 (channel 4) peaks at (47, 0).
    assert_eq!(t[7 * 64 + 7], 1.0);
    assert_eq!(t[4 * plane + 47 * 64], 1.0);
    // Gaussian sigma 1: a neighbour is exp(-1/2), a diagonal exp(-1), 4 away exp(-8).
    assert_relative_eq!(t[8 * 64 + 7], (-0.5f32).exp());
    assert_relative_eq!(t[8 * 64 + 8], (-1.0f32).exp());
    assert_relative_eq!(t[11 * 64 + 7], (-8.0f32).exp());
    // Truncated to 9x9: 5 away is zero.
    assert_eq!(t[12 * 64 + 7], 0.0);
    // Patch clipped at the border: VP2 (47, 0) has no column -1 to write, and each channel has
    // exactly one peak.
    for c in 0..8 {
        let ch = &t[c * plane..(c + 1) * plane];
        assert_eq!(ch.iter().filter(|v| **v == 1.0).count(), 1, "channel {c}");
    }
}

#[test]
fn decode_selects_the_sharpest_scale_and_modes_differ() {
    let codec = HeatmapCodec::default();
    let vp1 = Point2::new(0.4, -6.0);
    let vp2 = Point2::new(25.0, 1.5);
    let t = codec.render_targets(vp1, vp2);
    let p = codec.decode(&t, DecodeMode::Centre);
    // Each scale decodes near the truth; the chosen one is the best of the four.
    for (si, pair) in p.per_scale.iter().enumerate() {
        assert!(pair[0].is_finite(), "scale {si}");
    }
    let err = |a: Point2, b: Point2| (a - b).norm() / b.norm();
    // The scale that suits each VP decodes it within the quantisation error.
    for (k, truth) in [(0, vp1), (1, vp2)] {
        let best = p
            .per_scale
            .iter()
            .map(|pair| err(pair[k], truth))
            .fold(f64::INFINITY, f64::min);
        assert!(best < 0.03, "vp{} best relative error {best}", k + 1);
    }
    // A clean target: P is the peak alone (neighbours are exp(-1/2) = 0.61 < 0.8), so every
    // centre-mode spread is exactly zero and the tie goes to the first scale.
    assert!(p.spreads.iter().flatten().all(|s| *s == 0.0));
    assert_eq!((p.vp1_scale, p.vp2_scale), (0, 0));
    // A blurred peak at the coarse scales makes the finest scale win.
    let mut blurred = t.clone();
    for si in 0..3 {
        for v in &mut blurred[si * 4096..(si + 1) * 4096] {
            if *v > 0.5 {
                *v = 1.0;
            }
        }
    }
    let b = codec.decode(&blurred, DecodeMode::Centre);
    assert_eq!(b.vp1_scale, 3);
    assert_eq!(b.vp1, p.per_scale[3][0]);
    // Reference mode decodes P at pixel corners: the spread is positive.
    let r = codec.decode(&t, DecodeMode::Reference);
    assert!(r.spreads.iter().all(|s| s[0] > 0.0), "{:?}", r.spreads);
    assert_eq!(r.vp1, codec.decode(&t, DecodeMode::Reference).vp1);
}

#[test]
fn decode_handles_flat_and_nan_heatmaps() {
    let codec = HeatmapCodec::default();
    let zeros = vec![0.0f32; codec.len()];
    let p = codec.decode(&zeros, DecodeMode::Centre);
    // All zero: argmax is pixel (0, 0) on every channel; spreads finite or inf, never NaN.
    assert!(p.spreads.iter().flatten().all(|s| !s.is_nan()));
    let nans = vec![f32::NAN; codec.len()];
    let p = codec.decode(&nans, DecodeMode::Centre);
    assert!(p.spreads.iter().flatten().all(|s| !s.is_nan()));
}

proptest! {
    /// Mirroring a crop left-right maps a box-frame VP (x, y) to (-x, y); its target heatmaps
    /// are then exactly the transposes of the original's (what `VpNet::with_flip_average`
    /// relies on to map a mirrored crop's heatmaps back).
    #[test]
    fn mirrored_vps_have_transposed_targets(x1 in -200.0f64..200.0, y1 in -200.0f64..200.0,
                                            x2 in -200.0f64..200.0, y2 in -200.0f64..200.0) {
        let codec = HeatmapCodec::default();
        let r = codec.resolution;
        let a = codec.render_targets(Point2::new(x1, y1), Point2::new(x2, y2));
        let m = codec.render_targets(Point2::new(-x1, y1), Point2::new(-x2, y2));
        for (ca, cm) in a.chunks_exact(r * r).zip(m.chunks_exact(r * r)) {
            for i in 0..r {
                for j in 0..r {
                    prop_assert_eq!(ca[i * r + j], cm[j * r + i]);
                }
            }
        }
    }

    #[test]
    fn diamond_round_trip(x in -1e4f64..1e4, y in -1e4f64..1e4, d in 0.1f64..10.0) {
        let uv = point_to_diamond([x, y, 1.0], d).unwrap();
        prop_assert!(uv.x.abs() + uv.y.abs() <= d * (1.0 + 1e-12));
        let h = diamond_to_point(uv, d);
        if y != 0.0 || x != 0.0 {
            prop_assert!((h[0] / h[2] - x).abs() <= 1e-9 * x.abs().max(1.0));
            prop_assert!((h[1] / h[2] - y).abs() <= 1e-9 * y.abs().max(1.0));
        }
    }

    #[test]
    fn ideal_points_round_trip(angle in 0.0f64..std::f64::consts::TAU) {
        let (s, c) = angle.sin_cos();
        prop_assume!(s.abs() > 1e-9);
        let uv = point_to_diamond([c, s, 0.0], 1.0).unwrap();
        let h = diamond_to_point(uv, 1.0);
        prop_assert_eq!(h[2], 0.0);
        // Same direction up to sign.
        let cross = h[0] * s - h[1] * c;
        prop_assert!(cross.abs() <= 1e-12 * h[0].hypot(h[1]));
    }

    #[test]
    fn box_frame_round_trip(x0 in -500.0f64..1500.0, y0 in -500.0f64..1000.0, w in 1.0f64..600.0,
                            h in 1.0f64..600.0, vx in -1e5f64..1e5, vy in -1e5f64..1e5) {
        let b = BoxPx::new(x0, y0, x0 + w, y0 + h);
        let p = Point2::new(vx, vy);
        let back = b.frame_from_box(b.vp_in_box(p));
        prop_assert!((back.x - vx).abs() <= 1e-9 * vx.abs().max(1.0));
        prop_assert!((back.y - vy).abs() <= 1e-9 * vy.abs().max(1.0));
    }

    #[test]
    fn heatmap_round_trip_within_one_pixel(x in -300.0f64..300.0, y in -300.0f64..300.0,
                                            si in 0usize..4) {
        let codec = HeatmapCodec::default();
        let s = codec.scales[si];
        let p = Point2::new(x, y);
        let h = codec.vp_to_heatmap(p, s).unwrap();
        prop_assert!(h.x >= 0.0 && h.x <= 63.0 && h.y >= 0.0 && h.y <= 63.0);
        let back = codec.heatmap_to_vp(h, s);
        if back.is_finite() {
            prop_assert!((back - p).norm() <= 1e-7 * p.norm().max(1.0));
        }
        // Render then decode: the decoded pixel is the rendered one.
        let t = codec.render_targets(p, p);
        let dec = codec.decode_channel(&t[si * 4096..(si + 1) * 4096], s, DecodeMode::Centre);
        prop_assert_eq!(dec.argmax, (h.x.floor() as usize, h.y.floor() as usize));
    }
}

/// Edgelets scattered over a box, each pointing exactly at `vp` (homogeneous).
fn edgelets_towards(
    centre: Point2,
    vp: [f64; 3],
    n: usize,
) -> Vec<vpcal_geom::aggregate::edgelets::Edgelet> {
    (0..n)
        .map(|i| {
            let p = centre + Point2::new((i % 7) as f64 * 6.0 - 18.0, (i / 7) as f64 * 5.0 - 10.0);
            let d = Point2::new(vp[0] - vp[2] * p.x, vp[1] - vp[2] * p.y);
            vpcal_geom::aggregate::edgelets::Edgelet {
                x: p.x,
                y: p.y,
                angle: d.y.atan2(d.x),
                strength: 1.0,
            }
        })
        .collect()
}

proptest! {
    /// A vehicle's edgelets that all point at one VP give that VP's direction back, near or
    /// at infinity, and the direction error metric reads it as zero.
    #[test]
    fn vehicle_vp_recovers_the_direction(
        angle in -1.5f64..1.5,
        distance in 300.0f64..1.0e6,
        behind in proptest::bool::ANY,
    ) {
        use vpcal_geom::aggregate::vehicle_vp::vehicle_vp;
        use vpcal_geom::metrics::direction_error_deg;
        let c = Point2::new(400.0, 300.0);
        let s = if behind { -1.0 } else { 1.0 };
        let vp = c + Point2::new(angle.cos(), angle.sin()) * (s * distance);
        let h = [vp.x, vp.y, 1.0];
        let e = edgelets_towards(c, h, 21);
        let fit = vehicle_vp(c, &e, 60.0, 1.0).unwrap();
        let err = direction_error_deg(c, fit.point, h).unwrap();
        prop_assert!(err < 0.05, "direction error {err}°");
    }
}

#[test]
fn direction_error_handles_points_at_infinity() {
    use vpcal_geom::metrics::{direction_error_deg, direction_towards};
    let c = Point2::new(10.0, 20.0);
    // A horizontal direction at infinity and a far point on the same row: the same line.
    let err = direction_error_deg(c, [1.0, 0.0, 0.0], [-1.0e9, 20.0, 1.0]).unwrap();
    assert!(err < 1e-9, "{err}");
    // Perpendicular lines are 90° apart; opposite directions are the same line.
    let err = direction_error_deg(c, [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]).unwrap();
    assert!((err - 90.0).abs() < 1e-9);
    assert!(direction_error_deg(c, [-3.0, 0.0, 0.0], [3.0, 0.0, 0.0]).unwrap() < 1e-9);
    // The centre itself has no direction.
    assert_eq!(direction_towards(c, [10.0, 20.0, 1.0]), None);
    assert!(vpcal_geom::aggregate::vehicle_vp::vehicle_vp(c, &[], 50.0, 1.0).is_none());
}

/// Boxes of vehicles standing on a road seen by a camera whose horizon is the row `horizon_y`
/// (roll 0): size proportional to the distance below it, with a spread of vehicle sizes.
fn road_boxes(horizon_y: f64, n: usize) -> Vec<BoxPx> {
    (0..n)
        .map(|i| {
            let y1 = horizon_y + 40.0 + (i as f64 * 37.0) % 600.0;
            let x = 100.0 + (i as f64 * 53.0) % 1500.0;
            let s = (y1 - horizon_y) * (0.15 + 0.05 * ((i % 5) as f64 / 4.0));
            BoxPx {
                x0: x,
                y0: y1 - 0.8 * s,
                x1: x + 1.2 * s,
                y1,
            }
        })
        .collect()
}

#[test]
fn vehicle_sizes_agree_with_the_true_horizon_and_contradict_a_wrong_one() {
    use vpcal_geom::aggregate::sizes::{size_slope, MIN_SIZE_SLOPE};
    use vpcal_geom::Line;
    let boxes = road_boxes(300.0, 200);
    let w = vec![1.0; boxes.len()];
    let row = |y: f64| Line([0.0, 1.0, -y]);
    let right = size_slope(&boxes, &w, row(300.0), 1920.0, 1080.0).unwrap();
    assert!((right.slope - 1.0).abs() < 0.05, "{right:?}");
    // A camera looking straight down sees all vehicles alike: against a horizon placed at
    // the top of the frame, their sizes do not grow.
    let alike: Vec<BoxPx> = (0..200)
        .map(|i| {
            let (x, y) = (
                100.0 + (i as f64 * 53.0) % 1500.0,
                50.0 + (i as f64 * 37.0) % 900.0,
            );
            BoxPx {
                x0: x,
                y0: y,
                x1: x + 90.0 + (i % 5) as f64 * 8.0,
                y1: y + 60.0,
            }
        })
        .collect();
    let wrong = size_slope(&alike, &w, row(20.0), 1920.0, 1080.0).unwrap();
    assert!(wrong.slope < MIN_SIZE_SLOPE, "{wrong:?}");
    // Repeated boxes of one static false detection, weighted down, do not outvote traffic.
    let mut mixed = boxes.clone();
    let mut mw = w.clone();
    for _ in 0..1000 {
        mixed.push(BoxPx {
            x0: 900.0,
            y0: 900.0,
            x1: 920.0,
            y1: 915.0,
        });
        mw.push(0.003);
    }
    let s = size_slope(&mixed, &mw, row(300.0), 1920.0, 1080.0).unwrap();
    assert!((s.slope - 1.0).abs() < 0.1, "{s:?}");
    // Too few boxes: no verdict.
    assert!(size_slope(&boxes[..10], &w[..10], row(300.0), 1920.0, 1080.0).is_none());
}
