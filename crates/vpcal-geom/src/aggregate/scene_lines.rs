//! VP1 from the lines of the scene that run along the road.
//!
//! Lane lines and dashes, kerbs, road edges, guard rails, barriers and walls run parallel to
//! the road, so their image lines meet at VP1, the point the vehicles drive towards. They are
//! long, straight and still; a vehicle's track is short and its box's centre is not a fixed
//! point of the vehicle. Given a VP1 from the vehicles (their tracks, or the network's rays and
//! the edgelets along the vehicles), [`refine_vp1`] moves it to where the edgelets of the
//! scene's background (`vpcal_video::background`) that point at it meet: the edgelets within
//! a tolerance of the direction to the current VP1 are fitted as the point their lines meet
//! (angles, Cauchy-weighted least squares), and the tolerance shrinks from 4° to 0.5°, so
//! that the lines of other directions (across the road, poles, a second road) drop out while
//! the lines along the road stay.
//!
//! Measured (`scripts/bcs_scene_vp1.py`): on BrnoCompSpeed sessions 0-3 (12 real 1080p views;
//! each one's `screen.png`, against the reference VP1 of `camera_truth.json`, fitted to the
//! annotated lane dividers; errors in % of VP1's distance from the principal point) the fit
//! ends within 3 % from 100, 100, 99 and 81 % of starts 2, 5, 10 and 20 % off in 8 directions
//! (median 0.8 %), and from the VP1 of deep_vp's detections' tracks (4.7 % median) at 0.9 %.
//! On the six synthetic speed scenes (the median of the frames) VP1 from the tracks of the
//! motion detector's boxes (1.4-4.2 px off) and YOLOX's (1.0-17.6 px) both end 0.04-1.04 px
//! from the truth.

use super::edgelets::Edgelet;
use crate::point::Point2;

/// Settings of [`refine_vp1`].
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SceneLineOptions {
    /// The edgelets within these angles of the direction to the current VP1 are fitted, in
    /// turn (degrees, widest first); the Cauchy scale of each step is half its tolerance.
    pub tolerances_deg: Vec<f64>,
    /// Reweighted least-squares steps per tolerance.
    pub iterations: usize,
    /// Fewer edgelets within the last tolerance than this: no fit.
    pub min_edgelets: usize,
    /// The fitted lines must run in more than one direction: the smaller eigenvalue of their
    /// weighted normal matrix at least this fraction of the larger (edgelets of one straight
    /// line fix a line, not a point).
    pub min_spread: f64,
}

impl Default for SceneLineOptions {
    fn default() -> Self {
        SceneLineOptions {
            tolerances_deg: vec![4.0, 2.0, 1.0, 0.5],
            iterations: 10,
            min_edgelets: 100,
            min_spread: 1e-4,
        }
    }
}

/// What [`refine_vp1`] found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SceneVp1 {
    pub vp1: Point2,
    /// Edgelets within the last tolerance of it.
    pub edgelets: usize,
}

/// The weighted normal equations of the lines through edgelets: each line `n · x = n · p`,
/// summed with its weight.
#[derive(Default)]
struct Normal {
    a: f64,
    b: f64,
    c: f64,
    r0: f64,
    r1: f64,
    lines: usize,
}

impl Normal {
    fn add(&mut self, n: Point2, rhs: f64, w: f64) {
        self.a += w * n.x * n.x;
        self.b += w * n.x * n.y;
        self.c += w * n.y * n.y;
        self.r0 += w * n.x * rhs;
        self.r1 += w * n.y * rhs;
        self.lines += 1;
    }

    /// The weighted least-squares point where the lines meet; `None` when they do not fix a
    /// point (their smaller eigenvalue under `min_spread` of the larger).
    fn meet(&self, min_spread: f64) -> Option<Point2> {
        let Normal {
            a, b, c, r0, r1, ..
        } = *self;
        let det = a * c - b * b;
        let tr = a + c;
        // Eigenvalues of [[a, b], [b, c]].
        let disc = ((a - c) * (a - c) + 4.0 * b * b).sqrt();
        let (lo, hi) = (0.5 * (tr - disc), 0.5 * (tr + disc));
        if !(hi > 0.0 && lo >= min_spread * hi && det.abs() > 0.0) {
            return None;
        }
        let v = Point2::new((c * r0 - b * r1) / det, (a * r1 - b * r0) / det);
        v.is_finite().then_some(v)
    }
}

/// VP1 moved from `start` to where the scene's edgelets that point at it meet (module docs);
/// `None` when too few edgelets point at it or their lines do not fix a point.
///
/// Each step weighs a line by its Cauchy weight over the squared distance from the current
/// VP1, so that the residuals are sines of angles seen from the edgelets. The steps run in
/// one pass over the edgelets each, with no square root and one division per line fitted
/// (the bootstrap calls this once per resample over up to
/// 150,000 edgelets, where it was half of the aggregation's time).
pub fn refine_vp1(
    start: Point2,
    edgelets: &[Edgelet],
    opts: &SceneLineOptions,
) -> Option<SceneVp1> {
    if !start.is_finite() || edgelets.is_empty() {
        return None;
    }
    // Per edgelet: its point, the normal of its edge (the edge runs along `angle`) and the
    // right-hand side of its line.
    let lines: Vec<(Point2, Point2, f64)> = edgelets
        .iter()
        .map(|e| {
            let p = e.point();
            let n = Point2::new(-e.angle.sin(), e.angle.cos());
            (p, n, n.x * p.x + n.y * p.y)
        })
        .collect();
    let mut v = start;
    let mut used = 0;
    for &tol in &opts.tolerances_deg {
        let s_tol2 = tol.to_radians().sin().powi(2);
        let inv_scale2 = 1.0 / (0.5 * tol).to_radians().sin().powi(2);
        for _ in 0..opts.iterations {
            let mut sum = Normal::default();
            for &(p, n, rhs) in &lines {
                let (dx, dy) = (v.x - p.x, v.y - p.y);
                let len2 = dx * dx + dy * dy;
                let dot = n.x * dx + n.y * dy;
                // `dot² / len2` is the squared sine of the angle between the edge and the
                // direction to `v`; the weight `1 / (1 + sin² / scale²) / len2` is written
                // with one division.
                let dot2 = dot * dot;
                if len2 >= 1.0 && dot2 < s_tol2 * len2 {
                    sum.add(n, rhs, 1.0 / (len2 + dot2 * inv_scale2));
                }
            }
            if sum.lines < opts.min_edgelets {
                return None;
            }
            v = sum.meet(opts.min_spread)?;
            used = sum.lines;
        }
    }
    Some(SceneVp1 {
        vp1: v,
        edgelets: used,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::solve::SplitMix;

    /// Edgelets every 4 px along the segment from `a` to `b`, their angles turned by a
    /// uniform draw with standard deviation `noise_deg`.
    fn segment(a: Point2, b: Point2, noise_deg: f64, rng: &mut SplitMix) -> Vec<Edgelet> {
        let d = b - a;
        let n = (d.norm() / 4.0) as usize;
        let angle = d.y.atan2(d.x);
        (0..n)
            .map(|k| {
                let p = a + d * (k as f64 / n as f64);
                Edgelet {
                    x: p.x,
                    y: p.y,
                    angle: angle + noise_deg.to_radians() * (rng.next_f64() - 0.5) * 12f64.sqrt(),
                    strength: 50.0,
                }
            })
            .collect()
    }

    /// Lines from the bottom of a 1920x1080 image towards `vp`, from `x` at the bottom,
    /// covering the lower `reach` of the way.
    fn road(vp: Point2, xs: &[f64], reach: f64, noise: f64, rng: &mut SplitMix) -> Vec<Edgelet> {
        xs.iter()
            .flat_map(|&x| {
                let a = Point2::new(x, 1080.0);
                segment(a, a + (vp - a) * reach, noise, rng)
            })
            .collect()
    }

    #[test]
    fn converges_to_where_the_road_lines_meet_from_starts_around_it() {
        let mut rng = SplitMix(7);
        let vp = Point2::new(700.0, 80.0);
        let mut e = road(
            vp,
            &[100.0, 500.0, 900.0, 1300.0, 1700.0],
            0.7,
            1.0,
            &mut rng,
        );
        // Lines of other directions: across the road (towards a far VP2) and poles.
        for k in 0..8 {
            let y = 500.0 + 60.0 * f64::from(k);
            e.extend(segment(
                Point2::new(300.0, y),
                Point2::new(1500.0, y + 40.0),
                1.0,
                &mut rng,
            ));
            let x = 150.0 + 220.0 * f64::from(k);
            e.extend(segment(
                Point2::new(x, 300.0),
                Point2::new(x + 5.0, 700.0),
                1.0,
                &mut rng,
            ));
        }
        let dist = (vp - Point2::new(960.0, 540.0)).norm();
        for k in 0..12 {
            let a = f64::from(k) * std::f64::consts::PI / 6.0;
            let start = vp + Point2::new(a.cos(), a.sin()) * (0.1 * dist);
            let r = refine_vp1(start, &e, &SceneLineOptions::default()).expect("a fit");
            assert!((r.vp1 - vp).norm() < 0.01 * dist, "from {start:?}: {r:?}");
            assert!(r.edgelets > 200, "{r:?}");
        }
    }

    #[test]
    fn one_line_or_too_few_edgelets_fix_no_point() {
        let mut rng = SplitMix(3);
        let vp = Point2::new(700.0, 80.0);
        let one = road(vp, &[900.0], 0.8, 0.3, &mut rng);
        assert!(refine_vp1(
            vp + Point2::new(20.0, 10.0),
            &one,
            &SceneLineOptions::default()
        )
        .is_none());
        let few = road(vp, &[100.0, 1700.0], 0.1, 0.3, &mut rng);
        assert!(few.len() < 100);
        assert!(refine_vp1(vp, &few, &SceneLineOptions::default()).is_none());
        assert!(refine_vp1(
            Point2::new(f64::NAN, 0.0),
            &few,
            &SceneLineOptions::default()
        )
        .is_none());
        assert!(refine_vp1(vp, &[], &SceneLineOptions::default()).is_none());
    }

    #[test]
    fn lines_of_a_second_road_do_not_pull_it() {
        // A crossing road whose lines meet 25° of view away: the tolerance leaves them out.
        let mut rng = SplitMix(11);
        let vp = Point2::new(500.0, 100.0);
        let other = Point2::new(1500.0, 60.0);
        let mut e = road(vp, &[0.0, 400.0, 800.0, 1200.0], 0.7, 0.5, &mut rng);
        e.extend(road(
            other,
            &[1000.0, 1400.0, 1800.0, 2200.0],
            0.7,
            0.5,
            &mut rng,
        ));
        let r = refine_vp1(
            vp + Point2::new(-30.0, 25.0),
            &e,
            &SceneLineOptions::default(),
        )
        .unwrap();
        assert!((r.vp1 - vp).norm() < 3.0, "{r:?}");
    }
}
