//! VP1 where lines meet: the network's per-vehicle VP1 rays or the vehicles' tracks, each a
//! line through a box centre. The candidate lives on the sphere of homogeneous points (so a
//! far VP1 is no special case); RANSAC over pairs of lines (MSAC score on the angle between a
//! line and the direction to the candidate) starts a Nelder-Mead fit of a Cauchy loss of
//! those angles.

use super::tracks::RoadTracks;
use super::vehicles::Prepared;
use crate::point::Point2;
use crate::solve::{nelder_mead, SplitMix};

/// Sine of the angle between line `i` (through `c` with direction `d`) and the direction from
/// `c` to the homogeneous point `p` (unit vector; `p[2] >= 0`; coordinates in units of
/// `SCALE` pixels).
pub(super) const SCALE: f64 = 1000.0;

pub(super) fn sin_angle(p: [f64; 3], c: Point2, d: Point2) -> f64 {
    let vx = p[0] - p[2] * c.x / SCALE;
    let vy = p[1] - p[2] * c.y / SCALE;
    let n = vx.hypot(vy);
    if n < 1e-15 {
        return 1.0;
    }
    (vx * d.y - vy * d.x) / n
}

pub(super) fn sphere(q: [f64; 2]) -> [f64; 3] {
    let (st, ct) = q[0].sin_cos();
    let (sp, cp) = q[1].sin_cos();
    [cp * ct, cp * st, sp]
}

pub(super) fn from_sphere(p: [f64; 3]) -> [f64; 2] {
    let n = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
    let (mut x, mut y, mut w) = (p[0] / n, p[1] / n, p[2] / n);
    if w < 0.0 {
        x = -x;
        y = -y;
        w = -w;
    }
    [y.atan2(x), w.clamp(-1.0, 1.0).asin()]
}

/// Lines that should meet at VP1: through `centre[i]` with unit direction `dir[i]` (the
/// network's per-vehicle VP1 rays, or the vehicles' tracks).
#[derive(Debug, Clone, Copy)]
pub(super) struct LineSet<'a> {
    pub centre: &'a [Point2],
    pub dir: &'a [Point2],
}

/// Robust cost of VP1 candidate `q` (sphere parameters).
pub(super) fn vp1_cost(q: [f64; 2], lines: LineSet, w: &[f64], s: f64) -> f64 {
    let p = sphere(q);
    lines
        .centre
        .iter()
        .zip(lines.dir)
        .zip(w)
        .map(|((c, d), w)| {
            let r = sin_angle(p, *c, *d) / s;
            w * (1.0 + r * r).ln()
        })
        .sum()
}

/// RANSAC over pairs of VP1 lines, then Nelder-Mead on the robust angular cost.
pub(super) fn fit_vp1(
    lines_in: LineSet,
    w: &[f64],
    threshold_deg: f64,
    rng: &mut SplitMix,
    start: Option<[f64; 2]>,
) -> Option<[f64; 3]> {
    let n = lines_in.centre.len();
    if n < 2 {
        return None;
    }
    let s = threshold_deg.to_radians().sin();
    let q0 = match start {
        Some(q) => q,
        None => {
            // Lines in homogeneous form (scaled): l = (nx, ny, -n.c / SCALE).
            let lines: Vec<[f64; 3]> = lines_in
                .centre
                .iter()
                .zip(lines_in.dir)
                .map(|(c, d)| {
                    let (nx, ny) = (-d.y, d.x);
                    [nx, ny, -(nx * c.x + ny * c.y) / SCALE]
                })
                .collect();
            let total: f64 = w.iter().sum();
            if total <= 0.0 {
                return None;
            }
            let mut cum = Vec::with_capacity(n);
            let mut acc = 0.0;
            for x in w {
                acc += x;
                cum.push(acc);
            }
            let pick = |rng: &mut SplitMix| {
                let t = rng.next_f64() * total;
                cum.partition_point(|c| *c <= t).min(n - 1)
            };
            let mut best = (f64::NEG_INFINITY, None);
            for _ in 0..2000 {
                let (i, j) = (pick(rng), pick(rng));
                if i == j {
                    continue;
                }
                let p = crate::point::cross(lines[i], lines[j]);
                let norm = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
                if norm.is_nan() || norm <= 1e-12 {
                    continue;
                }
                let mut p = [p[0] / norm, p[1] / norm, p[2] / norm];
                if p[2] < 0.0 {
                    p = [-p[0], -p[1], -p[2]];
                }
                let score: f64 = lines_in
                    .centre
                    .iter()
                    .zip(lines_in.dir)
                    .zip(w)
                    .map(|((c, d), w)| {
                        let r = sin_angle(p, *c, *d) / s;
                        w * (1.0 - r * r).max(0.0)
                    })
                    .sum();
                if score > best.0 {
                    best = (score, Some(p));
                }
            }
            from_sphere(best.1?)
        }
    };
    let q = nelder_mead(
        |q| vp1_cost([q[0], q[1]], lines_in, w, s),
        &[q0[0], q0[1]],
        &[0.02, 0.02],
        VP1_ITERATIONS,
    )
    .x;
    Some(sphere([q[0], q[1]]))
}

/// Nelder-Mead budget of the VP1 fit on the sphere (2 parameters).
const VP1_ITERATIONS: usize = 300;

pub(super) const MIN_VP1_INLIERS: usize = 5;

/// The lines VP1 is fitted to, with their weights and the Cauchy scale of their angles.
#[derive(Debug, Clone)]
pub(super) struct Vp1Lines {
    pub centre: Vec<Point2>,
    pub dir: Vec<Point2>,
    pub weight: Vec<f64>,
    pub threshold_deg: f64,
    /// Tracks (true) or the network's per-vehicle rays (false).
    pub from_tracks: bool,
}

impl Vp1Lines {
    pub(super) fn lines(&self) -> LineSet<'_> {
        LineSet {
            centre: &self.centre,
            dir: &self.dir,
        }
    }

    /// Weighted median of the angles between the lines and the directions to `p`, degrees.
    pub(super) fn median_residual_deg(&self, p: [f64; 3]) -> Option<f64> {
        let angles: Vec<f64> = self
            .centre
            .iter()
            .zip(&self.dir)
            .map(|(c, d)| sin_angle(p, *c, *d).abs().min(1.0).asin().to_degrees())
            .collect();
        crate::metrics::weighted_median(&angles, &self.weight)
    }

    /// Lines within the threshold angle of the homogeneous point `p` (sphere form).
    pub(super) fn inliers(&self, p: [f64; 3]) -> usize {
        let s = self.threshold_deg.to_radians().sin();
        self.centre
            .iter()
            .zip(&self.dir)
            .filter(|(c, d)| sin_angle(p, **c, **d).abs() < s)
            .count()
    }
}

/// VP1 as a homogeneous point `[x, y, w]` (units of `SCALE` pixels) in frame pixels, when
impl Vp1Lines {
    /// The network's VP1 rays, weighted by the vehicle weight and the decoder spread.
    pub(super) fn network(prep: &Prepared, threshold_deg: f64) -> Vp1Lines {
        Vp1Lines {
            centre: prep.centre.clone(),
            dir: prep.dir1.clone(),
            weight: prep
                .weight
                .iter()
                .zip(&prep.spread1)
                .map(|(a, b)| a * b)
                .collect(),
            threshold_deg,
            from_tracks: false,
        }
    }
}

/// finite.
pub(super) fn vp1_of(p: [f64; 3]) -> Option<Point2> {
    let v = Point2::new(p[0] / p[2] * SCALE, p[1] / p[2] * SCALE);
    (p[2] > 1e-9 && v.is_finite()).then_some(v)
}

/// VP1 from the network's per-vehicle lines: RANSAC, and a second start from the weighted
/// median of the VP1 points; the better finite solution wins (RANSAC alone can settle in a
/// poor basin when the lines are nearly parallel).
pub(super) fn locate_vp1_from_network(
    lines: &Vp1Lines,
    points: &[Point2],
    pp: Point2,
    width: f64,
    rng: &mut SplitMix,
) -> Option<[f64; 3]> {
    let (w, t) = (&lines.weight, lines.threshold_deg);
    let mut p1 = fit_vp1(lines.lines(), w, t, rng, None)?;
    let xs: Vec<f64> = points.iter().map(|v| v.x).collect();
    let ys: Vec<f64> = points.iter().map(|v| v.y).collect();
    if let (Some(mx), Some(my)) = (
        crate::metrics::weighted_median(&xs, w),
        crate::metrics::weighted_median(&ys, w),
    ) {
        let start = from_sphere(homogeneous(Point2::new(mx, my)));
        let s = t.to_radians().sin();
        if let Some(alt) = fit_vp1(lines.lines(), w, t, rng, Some(start)) {
            let cost = |p: [f64; 3]| vp1_cost(from_sphere(p), lines.lines(), w, s);
            let finite = |p: [f64; 3]| vp1_of(p).is_some_and(|v| (v - pp).norm() < 20.0 * width);
            if finite(alt) && (!finite(p1) || cost(alt) < cost(p1)) {
                p1 = alt;
            }
        }
    }
    Some(p1)
}

/// The homogeneous point (sphere form, units of `SCALE` pixels) of the frame point `v`.
pub(super) fn homogeneous(v: Point2) -> [f64; 3] {
    [v.x / SCALE, v.y / SCALE, 1.0]
}

/// Which lines VP1 is fitted to: the fields of the same names of
/// [`RobustOptions`](super::robust::RobustOptions).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Vp1Choice {
    pub vp1_threshold_deg: f64,
    pub min_track_lines: usize,
    pub track_threshold_deg: f64,
    pub track_above_scatter_deg: f64,
    pub track_residual_ratio: f64,
}

/// VP1, and the lines it was fitted to.
#[derive(Debug, Clone)]
pub(super) struct Located {
    pub lines: Vp1Lines,
    /// VP1 in sphere form, and in frame pixels.
    pub p1: [f64; 3],
    pub vp1: Point2,
    /// The lines within the threshold angle of VP1 (every vehicle's where the network's rays
    /// gave it, not only the thinned ones the fit used).
    pub inliers: usize,
    /// The weighted median angle of the network's VP1 rays around the VP1 they alone give,
    /// and of the straight tracks' lines around theirs, degrees.
    pub network_scatter: Option<f64>,
    pub track_residual: Option<f64>,
    /// Enough straight tracks to place VP1 (`min_track_lines`), and they do not meet at one.
    pub tracks_disagree: bool,
}

/// VP1 from the straight tracks where there are enough that agree on one and the network's
/// rays scatter more than they do (or the road is not curved), else from the network's VP1
/// rays of the thinned vehicles `prep` (`full`: all of them, for the counts).
///
/// # Errors
/// The reason as a sentence, where the lines give no finite VP1 that enough of them agree on.
pub(super) fn locate(
    full: &Prepared,
    prep: &Prepared,
    road: &RoadTracks,
    pp: Point2,
    width: f64,
    choice: &Vp1Choice,
    rng: &mut SplitMix,
) -> Result<Located, String> {
    let network_lines = Vp1Lines::network(prep, choice.vp1_threshold_deg);
    let network = locate_vp1_from_network(&network_lines, &prep.vp1, pp, width, rng);
    // Residuals and inliers are counted on every vehicle, not only the thinned ones the fit
    // used.
    let all_network = Vp1Lines::network(full, choice.vp1_threshold_deg);
    let network_scatter = network.and_then(|p| all_network.median_residual_deg(p));
    // VP1 from the tracks alone, when there are enough of them and they agree.
    let straight = &road.straight;
    let tracked = (straight.len() >= choice.min_track_lines)
        .then(|| {
            let lines = Vp1Lines {
                centre: straight.iter().map(|t| t.point).collect(),
                dir: straight.iter().map(|t| t.dir).collect(),
                weight: vec![1.0; straight.len()],
                threshold_deg: choice.track_threshold_deg,
                from_tracks: true,
            };
            let t = lines.threshold_deg;
            let p1 = fit_vp1(lines.lines(), &lines.weight, t, rng, None)?;
            let inliers = lines.inliers(p1);
            let residual = lines.median_residual_deg(p1)?;
            (vp1_of(p1).is_some() && inliers >= MIN_VP1_INLIERS)
                .then_some((lines, p1, inliers, residual))
        })
        .flatten();
    let track_residual = tracked.as_ref().map(|t| t.3);
    let tracks_disagree = straight.len() >= choice.min_track_lines && tracked.is_none();
    let use_tracks = match (&tracked, network_scatter) {
        _ if road.road_curved => false,
        (None, _) => false,
        (Some(_), None) => true,
        (Some(t), Some(scatter)) => {
            scatter > choice.track_above_scatter_deg || t.3 < choice.track_residual_ratio * scatter
        }
    };
    let from_tracks = tracked
        .filter(|_| use_tracks)
        .map(|(lines, p1, inliers, _)| (lines, p1, inliers));
    let (lines, p1, inliers) = match from_tracks {
        Some(found) => found,
        None => {
            let p1 = network.ok_or("the VP1 lines do not intersect")?;
            let inliers = all_network.inliers(p1);
            (network_lines, p1, inliers)
        }
    };
    let vp1 = vp1_of(p1).ok_or(
        "VP1 lies at infinity (the road runs parallel to the image plane); a finite VP1 is \
         needed for a BrnoCompSpeed-style calibration",
    )?;
    if inliers < MIN_VP1_INLIERS {
        return Err(format!(
            "only {inliers} vehicles agree on a VP1 (within {}°)",
            choice.vp1_threshold_deg
        ));
    }
    Ok(Located {
        lines,
        p1,
        vp1,
        inliers,
        network_scatter,
        track_residual,
        tracks_disagree,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::aggregate::tracks::TrackLine;
    use crate::aggregate::vehicles::{prepare, vehicle_units, Weighting};
    use crate::aggregate::VehicleVps;
    use crate::point::BoxPx;

    const VP1: Point2 = Point2::new(700.0, -150.0);
    const PP: Point2 = Point2::new(640.0, 360.0);

    fn choice() -> Vp1Choice {
        Vp1Choice {
            vp1_threshold_deg: 2.0,
            min_track_lines: 5,
            track_threshold_deg: 1.0,
            track_above_scatter_deg: 3.0,
            track_residual_ratio: 0.15,
        }
    }

    /// `n` vehicles below VP1, each ray towards VP1 turned by `turn_deg(i)`.
    fn vehicles(n: usize, turn_deg: impl Fn(usize) -> f64) -> Prepared {
        let pairs: Vec<VehicleVps> = (0..n)
            .map(|i| {
                let c = Point2::new(200.0 + 22.0 * i as f64, 300.0 + 9.0 * (i % 7) as f64 * 4.0);
                let (s, k) = turn_deg(i).to_radians().sin_cos();
                let d = VP1 - c;
                let turned = Point2::new(k * d.x - s * d.y, s * d.x + k * d.y);
                VehicleVps {
                    box_px: Some(BoxPx::new(c.x - 40.0, c.y - 30.0, c.x + 40.0, c.y + 30.0)),
                    ..VehicleVps::new(c + turned, Point2::new(5000.0, -150.0), 0.9)
                }
            })
            .collect();
        let weighting = Weighting {
            min_score: 0.1,
            duplicate_iou: 0.7,
            duplicate_keep: 3.0,
            min_box_fraction: 0.023,
        };
        prepare(&pairs, &vehicle_units(&pairs), &weighting, 720.0)
    }

    /// `n` straight tracks whose lines meet at `vp`.
    fn road(n: usize, vp: Point2, curved: bool) -> RoadTracks {
        let straight = (0..n)
            .map(|i| {
                let point = Point2::new(300.0 + 80.0 * i as f64, 600.0);
                let d = vp - point;
                TrackLine {
                    point,
                    dir: d / d.norm(),
                    boxes: 20,
                    travel: 200.0,
                    rms: 0.5,
                    bend_t: 0.0,
                    bend_deg: 0.0,
                    bend_se_deg: 0.5,
                }
            })
            .collect();
        RoadTracks {
            boxes: Vec::new(),
            pairs: Vec::new(),
            links: Vec::new(),
            straight,
            curved_tracks: if curved { n } else { 0 },
            road_curved: curved,
        }
    }

    fn locate_with(prep: &Prepared, road: &RoadTracks) -> Result<Located, String> {
        locate(prep, prep, road, PP, 1280.0, &choice(), &mut SplitMix(7))
    }

    #[test]
    fn the_network_rays_meet_at_vp1() {
        let found = locate_with(&vehicles(40, |_| 0.0), &road(0, VP1, false)).unwrap();
        assert!(!found.lines.from_tracks);
        assert!((found.vp1 - VP1).norm() < 1.0, "{}", found.vp1);
        assert_eq!(found.inliers, 40);
        assert!(found.network_scatter.unwrap() < 0.01);
    }

    #[test]
    fn scattered_rays_give_way_to_tracks_that_agree() {
        // Rays turned by +-6 degrees alternately: VP1 near the truth, the rays 6 degrees off.
        let prep = vehicles(40, |i| if i % 2 == 0 { 6.0 } else { -6.0 });
        let elsewhere = VP1 + Point2::new(40.0, 0.0);
        let found = locate_with(&prep, &road(8, elsewhere, false)).unwrap();
        assert!(found.lines.from_tracks);
        assert!((found.vp1 - elsewhere).norm() < 1.0, "{}", found.vp1);
        assert!(found.track_residual.unwrap() < 0.01);
        // Too few tracks, or a curved road: the network's rays.
        for road in [road(4, elsewhere, false), road(8, elsewhere, true)] {
            let found = locate_with(&prep, &road).unwrap();
            assert!(!found.lines.from_tracks);
        }
    }

    #[test]
    fn straight_tracks_that_meet_nowhere_say_so() {
        // Eight track lines, each aimed at its own point of the horizon (cars on a curve, each
        // with its own heading): no five meet within a degree.
        let prep = vehicles(40, |_| 0.0);
        let mut scattered = road(8, VP1, false);
        let offsets = [0.0, 300.0, -200.0, 500.0, -400.0, 150.0, -350.0, 250.0];
        for (t, dx) in scattered.straight.iter_mut().zip(offsets) {
            let d = VP1 + Point2::new(dx, 0.0) - t.point;
            t.dir = d / d.norm();
        }
        let found = locate_with(&prep, &scattered).unwrap();
        assert!(found.tracks_disagree);
        assert!(!found.lines.from_tracks);
        // Tracks that meet, or too few to tell: no disagreement.
        for road in [road(8, VP1, false), road(4, VP1, false)] {
            assert!(!locate_with(&prep, &road).unwrap().tracks_disagree);
        }
    }

    #[test]
    fn rays_that_agree_on_no_point_give_no_vp1() {
        // Ten rays, each turned by its own angle, up to 60 degrees.
        let prep = vehicles(10, |i| (i as f64 * 47.0) % 120.0 - 60.0);
        let err = locate_with(&prep, &road(0, VP1, false)).unwrap_err();
        assert!(err.contains("agree on a VP1"), "{err}");
    }
}
