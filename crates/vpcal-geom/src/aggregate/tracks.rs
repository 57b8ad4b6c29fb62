//! Vehicle tracks as VP1 evidence.
//!
//! A vehicle driving straight keeps its heading, so the centres of its boxes in successive
//! frames lie on a line through VP1. On the synthetic suite such lines (true boxes, fitted to
//! the box centres) point at the true VP1 to a median 0.04-0.1° on straight roads, where the
//! network's per-vehicle VP1 rays are off by a median 3-12°, with a per-scene bias of the same
//! size (`scripts/vp1_rays_vs_tracks.py`). The tracks need boxes from closely spaced frames;
//! with sparse frames (`calibrate --every 50`) few boxes link and the network's lines are used.
//!
//! [`link`] joins boxes of successive frames into tracks (greedy, by the overlap of each box
//! with where the track's last box is predicted to be at constant image velocity);
//! [`fit_line`] fits a line to a track's box centres and keeps it only when the track
//! travelled far enough and stayed straight.

use crate::point::{BoxPx, Point2};
use crate::vehicle_scale::BORDER_PX;

/// Settings of the tracker and of the line fit.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TrackOptions {
    /// A box continues a track when it overlaps the track's predicted box with IoU above this.
    pub min_iou: f64,
    /// A track of one box (no velocity yet) is also continued by a box of similar size (within
    /// a factor 1.5) whose centre lies within this many box sizes (0: overlap only). Sparse
    /// frames need it: a car moves most of its length between samples.
    pub first_link_sizes: f64,
    /// A track ends when it found no box for more than this many median frame steps.
    pub max_gap_steps: f64,
    /// A track needs at least this many boxes to give a line.
    pub min_boxes: usize,
    /// ... and its centre must travel at least this many box sizes (geometric mean of width
    /// and height, median over the track) along the line ...
    pub min_travel_boxes: f64,
    /// ... and the RMS distance of its centres from the line must stay below this fraction of
    /// the travel (a turning vehicle is no evidence of VP1).
    pub max_rms_fraction: f64,
    /// The picture's size `[width, height]`, where known: boxes cut by its edge
    /// ([`crate::vehicle_scale::BORDER_PX`]) do not count in a track's bend
    /// ([`TrackLine::bend_t`]).
    #[serde(default)]
    pub frame: Option<[f64; 2]>,
}

/// Only a track's boxes at least this share of its tallest box's height count in its bend.
/// Far away a box is a few pixels tall, and there the detector's box drifts with the traffic
/// around it (merged neighbours, a queue): on a straight urban arterial
/// (`cn_urban_arterial_cctv_2016`) the last 10 % of five tracks' travel, where the boxes were
/// under a third of their nearest size, turned each by 7-11°, where a rigid car's box on a
/// straight lane turns by under 1° (its corners' paths through VP1, projected for that view).
/// Over the part of the track within a factor of three of the vehicle's nearest size, a curve
/// still shows: the synthetic suite's three curves stay curved, its eight straight and
/// intersection scenes straight.
pub const BEND_MIN_HEIGHT_SHARE: f64 = 1.0 / 3.0;

impl Default for TrackOptions {
    fn default() -> Self {
        TrackOptions {
            min_iou: 0.2,
            first_link_sizes: 1.0,
            max_gap_steps: 2.5,
            min_boxes: 5,
            min_travel_boxes: 1.0,
            max_rms_fraction: 0.03,
            frame: None,
        }
    }
}

/// A track's line: through `point` (the mean box centre) with unit direction `dir`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackLine {
    pub point: Point2,
    pub dir: Point2,
    /// Boxes on the track.
    pub boxes: usize,
    /// Distance the centre travelled along the line, pixels.
    pub travel: f64,
    /// RMS distance of the centres from the line, pixels.
    pub rms: f64,
    /// How significantly the track bends: the t-statistic of the quadratic term of a parabola
    /// fitted to the centres across `dir` (signed: positive when it bends towards the left of
    /// `dir`, i.e. towards `(dir.y, -dir.x)` in image coordinates with y down). A straight
    /// track with noisy boxes gives |t| of a few at most; a car on a curved road, tens.
    pub bend_t: f64,
    /// The change of the parabola's direction from the first to the last centre, degrees
    /// (signed like `bend_t`): how much the vehicle turned, whether or not significantly.
    pub bend_deg: f64,
    /// The standard error of `bend_deg` (from the scatter of the centres around the
    /// parabola): how well this track can tell a turn from a straight drive.
    pub bend_se_deg: f64,
}

/// Join boxes into tracks. `boxes[i]` is `(frame, box)`; returns, per track, the indices of
/// its boxes in frame order. Every index appears in exactly one track (a box that continues
/// nothing starts a track of its own).
pub fn link(boxes: &[(f64, BoxPx)], opts: &TrackOptions) -> Vec<Vec<usize>> {
    let mut order: Vec<usize> = (0..boxes.len())
        .filter(|&i| boxes[i].0.is_finite() && boxes[i].1.is_valid())
        .collect();
    order.sort_by(|&a, &b| boxes[a].0.total_cmp(&boxes[b].0));
    let mut frames: Vec<f64> = order.iter().map(|&i| boxes[i].0).collect();
    frames.dedup();
    let mut steps: Vec<f64> = frames.windows(2).map(|w| w[1] - w[0]).collect();
    steps.sort_by(f64::total_cmp);
    let max_gap = steps.get(steps.len() / 2).copied().unwrap_or(1.0) * opts.max_gap_steps;

    let mut done: Vec<Vec<usize>> = Vec::new();
    let mut active: Vec<Vec<usize>> = Vec::new();
    let mut start = 0;
    while start < order.len() {
        let frame = boxes[order[start]].0;
        let end = start + order[start..].partition_point(|&i| boxes[i].0 == frame);
        let current = &order[start..end];
        // Retire the tracks that waited too long.
        let (keep, old): (Vec<_>, Vec<_>) = active
            .into_iter()
            .partition(|t| t.last().is_some_and(|&i| frame - boxes[i].0 <= max_gap));
        done.extend(old);
        active = keep;
        // Every (track, box) pair that overlaps enough, best first.
        let mut candidates: Vec<(f64, usize, usize)> = Vec::new();
        for (ti, t) in active.iter().enumerate() {
            let predicted = predict(boxes, t, frame);
            for (bi, &i) in current.iter().enumerate() {
                let iou = predicted.iou(&boxes[i].1);
                if iou > opts.min_iou {
                    candidates.push((iou, ti, bi));
                } else if t.len() == 1 {
                    if let Some(score) = near(&predicted, &boxes[i].1, opts.first_link_sizes) {
                        candidates.push((score * opts.min_iou, ti, bi));
                    }
                }
            }
        }
        candidates.sort_by(|a, b| b.0.total_cmp(&a.0));
        let mut track_taken = vec![false; active.len()];
        let mut box_taken = vec![false; current.len()];
        for (_, ti, bi) in candidates {
            if !track_taken[ti] && !box_taken[bi] {
                track_taken[ti] = true;
                box_taken[bi] = true;
                active[ti].push(current[bi]);
            }
        }
        for (bi, &i) in current.iter().enumerate() {
            if !box_taken[bi] {
                active.push(vec![i]);
            }
        }
        start = end;
    }
    done.extend(active);
    done
}

/// For a box `b` near `a` (similar size, centres within `sizes` box sizes), a score in (0, 1]
/// that falls with the distance.
fn near(a: &BoxPx, b: &BoxPx, sizes: f64) -> Option<f64> {
    let size = |x: &BoxPx| (x.width() * x.height()).sqrt();
    let (sa, sb) = (size(a), size(b));
    let ratio = sa.max(sb) / sa.min(sb);
    let limit = sizes * sa.max(sb);
    let d = (a.center() - b.center()).norm();
    (ratio < 1.5 && d < limit).then(|| 1.0 - d / limit)
}

/// Where the track's last box will be at `frame`: shifted by the track's last image velocity
/// (unchanged for a track of one box).
fn predict(boxes: &[(f64, BoxPx)], track: &[usize], frame: f64) -> BoxPx {
    let (f1, b1) = boxes[track[track.len() - 1]];
    if track.len() < 2 {
        return b1;
    }
    let (f0, b0) = boxes[track[track.len() - 2]];
    if f1 <= f0 {
        return b1;
    }
    let v = (b1.center() - b0.center()) / (f1 - f0);
    let d = v * (frame - f1);
    BoxPx::new(b1.x0 + d.x, b1.y0 + d.y, b1.x1 + d.x, b1.y1 + d.y)
}

/// The principal axes of a set of points (total least squares line).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Axis {
    pub mean: Point2,
    /// Unit direction of the major axis.
    pub dir: Point2,
    /// RMS distance of the points from the mean along, and across, the major axis.
    pub major_rms: f64,
    pub minor_rms: f64,
}

impl Axis {
    /// The axes of `points` (all zero for none; `major_rms` is zero when they do not spread).
    pub fn of(points: &[Point2]) -> Axis {
        let n = points.len().max(1) as f64;
        let mean = points.iter().fold(Point2::new(0.0, 0.0), |a, c| a + *c) / n;
        let (mut sxx, mut sxy, mut syy) = (0.0, 0.0, 0.0);
        for c in points {
            let d = *c - mean;
            sxx += d.x * d.x;
            sxy += d.x * d.y;
            syy += d.y * d.y;
        }
        // Eigen-decomposition of the 2x2 scatter matrix: the major axis is the direction.
        let half_trace = (sxx + syy) / 2.0;
        let root = (((sxx - syy) / 2.0).powi(2) + sxy * sxy).sqrt();
        let angle = 0.5 * (2.0 * sxy).atan2(sxx - syy);
        Axis {
            mean,
            dir: Point2::new(angle.cos(), angle.sin()),
            major_rms: ((half_trace + root) / n).sqrt(),
            minor_rms: ((half_trace - root).max(0.0) / n).sqrt(),
        }
    }
}

/// The line through a track's box centres (total least squares), or `None` when the track is
/// too short, travelled too little, or is not straight (see [`TrackOptions`]).
pub fn fit_line(boxes: &[(f64, BoxPx)], track: &[usize], opts: &TrackOptions) -> Option<TrackLine> {
    let n = track.len();
    if n < opts.min_boxes.max(2) {
        return None;
    }
    let centres: Vec<Point2> = track.iter().map(|&i| boxes[i].1.center()).collect();
    let axis = Axis::of(&centres);
    let (mean, dir) = (axis.mean, axis.dir);
    let rms = axis.minor_rms;
    let travel = (centres[n - 1] - centres[0]).dot(dir).abs();
    let mut sizes: Vec<f64> = track
        .iter()
        .map(|&i| (boxes[i].1.width() * boxes[i].1.height()).sqrt())
        .collect();
    sizes.sort_by(f64::total_cmp);
    let size = sizes[n / 2];
    let (bend_t, bend_deg, bend_se_deg) = bend_of_clear_boxes(boxes, track, dir, opts.frame);
    let ok = travel.is_finite()
        && travel > 0.0
        && travel >= opts.min_travel_boxes * size
        && straight_enough(rms, travel, opts);
    ok.then_some(TrackLine {
        point: mean,
        dir,
        boxes: n,
        travel,
        rms,
        bend_t,
        bend_deg,
        bend_se_deg,
    })
}

/// [`bend`] over the track's boxes that are neither cut by the picture's edge
/// ([`BORDER_PX`]) nor far smaller than its tallest box ([`BEND_MIN_HEIGHT_SHARE`]),
/// about their own line, signed as seen along `dir`.
fn bend_of_clear_boxes(
    boxes: &[(f64, BoxPx)],
    track: &[usize],
    dir: Point2,
    frame: Option<[f64; 2]>,
) -> (f64, f64, f64) {
    let tallest = track
        .iter()
        .map(|&i| boxes[i].1.height())
        .fold(0.0f64, f64::max);
    // A cut box's centre moves across the track as the car leaves the frame. In a prototype
    // of these rules (Python, on the recorded 300 frames), the straight M6 motorway's
    // tracks bent alike on 10 of 16 with cut boxes counted, and on 2 of 18 without them.
    let inside = |b: &BoxPx| {
        frame.is_none_or(|[w, h]| {
            b.x0 > BORDER_PX && b.y0 > BORDER_PX && b.x1 < w - BORDER_PX && b.y1 < h - BORDER_PX
        })
    };
    let centres: Vec<Point2> = track
        .iter()
        .map(|&i| &boxes[i].1)
        .filter(|b| inside(b) && b.height() >= BEND_MIN_HEIGHT_SHARE * tallest)
        .map(BoxPx::center)
        .collect();
    if centres.len() < 2 {
        return (0.0, 0.0, f64::INFINITY);
    }
    let axis = Axis::of(&centres);
    let own = if axis.dir.dot(dir) < 0.0 {
        -axis.dir
    } else {
        axis.dir
    };
    bend(&centres, axis.mean, own)
}

/// The t-statistic of `c` in `v = a + b u + c u^2`, least squares over the centres, where `u`
/// runs along `dir` and `v` across it (towards `(dir.y, -dir.x)`) from `mean`, and the change
/// of the parabola's direction between the extreme centres and its standard error, degrees.
/// (0, 0, inf) with fewer than 5 centres or a degenerate fit; the t is large when the noise is
/// nil.
fn bend(centres: &[Point2], mean: Point2, dir: Point2) -> (f64, f64, f64) {
    let n = centres.len();
    if n < 5 {
        return (0.0, 0.0, f64::INFINITY);
    }
    let across = Point2::new(dir.y, -dir.x);
    // Normal equations of the 3-parameter fit, with u scaled to about [-1, 1].
    let uv: Vec<(f64, f64)> = centres
        .iter()
        .map(|c| ((*c - mean).dot(dir), (*c - mean).dot(across)))
        .collect();
    let scale = uv.iter().fold(0.0f64, |m, (u, _)| m.max(u.abs()));
    if scale.is_nan() || scale <= 0.0 {
        return (0.0, 0.0, f64::INFINITY);
    }
    let mut ata = [[0.0f64; 3]; 3];
    let mut atb = [0.0f64; 3];
    for &(u, v) in &uv {
        let u = u / scale;
        let row = [1.0, u, u * u];
        for i in 0..3 {
            for j in 0..3 {
                ata[i][j] += row[i] * row[j];
            }
            atb[i] += row[i] * v;
        }
    }
    let Some(inv) = invert3(&ata) else {
        return (0.0, 0.0, f64::INFINITY);
    };
    let coef: Vec<f64> = (0..3)
        .map(|i| (0..3).map(|j| inv[i][j] * atb[j]).sum())
        .collect();
    let sse: f64 = uv
        .iter()
        .map(|&(u, v)| {
            let u = u / scale;
            (v - coef[0] - coef[1] * u - coef[2] * u * u).powi(2)
        })
        .sum();
    // A floor on the noise (0.05 px) keeps exact synthetic centres finite.
    let sigma2 = (sse / (n - 3) as f64).max(0.05 * 0.05);
    let se = (sigma2 * inv[2][2]).sqrt();
    if !(se > 0.0 && se.is_finite()) {
        return (0.0, 0.0, f64::INFINITY);
    }
    // dv/du = 2 c u / scale^2 (u unscaled) at the two ends.
    let (lo, hi) = uv
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), (u, _)| {
            (l.min(*u), h.max(*u))
        });
    let slope = |u: f64| 2.0 * coef[2] * u / (scale * scale);
    let turned = (slope(hi).atan() - slope(lo).atan()).to_degrees();
    // Small angles: the turn is about 2 c (hi - lo) / scale^2 radians.
    let turned_se = (2.0 * se * (hi - lo) / (scale * scale)).to_degrees();
    (coef[2] / se, turned, turned_se)
}

/// Inverse of a 3x3 matrix, `None` when (nearly) singular.
fn invert3(m: &[[f64; 3]; 3]) -> Option<[[f64; 3]; 3]> {
    let c =
        |r0: usize, r1: usize, c0: usize, c1: usize| m[r0][c0] * m[r1][c1] - m[r0][c1] * m[r1][c0];
    let cof = [
        [c(1, 2, 1, 2), -c(1, 2, 0, 2), c(1, 2, 0, 1)],
        [-c(0, 2, 1, 2), c(0, 2, 0, 2), -c(0, 2, 0, 1)],
        [c(0, 1, 1, 2), -c(0, 1, 0, 2), c(0, 1, 0, 1)],
    ];
    let det = m[0][0] * cof[0][0] + m[0][1] * cof[0][1] + m[0][2] * cof[0][2];
    let norm = m.iter().flatten().fold(0.0f64, |a, v| a.max(v.abs()));
    if det.is_nan() || det.abs() <= 1e-12 * norm.powi(3) {
        return None;
    }
    // inverse = adjugate / det, adjugate = transpose of the cofactors.
    let mut inv = [[0.0; 3]; 3];
    for (i, row) in inv.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            *v = cof[j][i] / det;
        }
    }
    Some(inv)
}

impl TrackLine {
    /// Whether the centres stayed close enough to the line to count as a straight drive
    /// ([`TrackOptions::max_rms_fraction`]), as [`fit_line`] requires.
    pub fn is_straight(&self, opts: &TrackOptions) -> bool {
        straight_enough(self.rms, self.travel, opts)
    }
}

fn straight_enough(rms: f64, travel: f64, opts: &TrackOptions) -> bool {
    rms <= opts.max_rms_fraction * travel
}

/// Link `boxes` into tracks and return the lines of the tracks that qualify.
pub fn track_lines(boxes: &[(f64, BoxPx)], opts: &TrackOptions) -> Vec<TrackLine> {
    link(boxes, opts)
        .iter()
        .filter_map(|t| fit_line(boxes, t, opts))
        .collect()
}

/// A vehicle's local direction of travel: the line through a box centre along the track.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tangent {
    pub point: Point2,
    /// Unit direction.
    pub dir: Point2,
    /// Standard error of the direction, radians, from the scatter of the window's centres
    /// across the axis (the boxes' jitter) against their spread along it.
    pub se_rad: f64,
}

/// Per box (indexed like `boxes`), the direction its track runs at that box: the major axis
/// of the centres of the `half` boxes before and after it in its track (total least
/// squares), and that direction's standard error. `None` for boxes without `half` neighbours on both sides, or whose neighbours
/// moved less than `min_spread_px` (RMS along the axis). On a curved road each car has its own
/// heading; these tangents follow it, where a line through the whole track does not.
pub fn tangents(
    boxes: &[(f64, BoxPx)],
    tracks: &[Vec<usize>],
    half: usize,
    min_spread_px: f64,
) -> Vec<Option<Tangent>> {
    let mut out = vec![None; boxes.len()];
    for track in tracks {
        if track.len() < 2 * half + 1 {
            continue;
        }
        for j in half..track.len() - half {
            let window = &track[j - half..=j + half];
            let centres: Vec<Point2> = window.iter().map(|&i| boxes[i].1.center()).collect();
            let axis = Axis::of(&centres);
            if axis.major_rms < min_spread_px {
                continue;
            }
            out[track[j]] = Some(Tangent {
                point: boxes[track[j]].1.center(),
                dir: axis.dir,
                // The slope error of a line fit: scatter across over spread along, sqrt(n - 2).
                se_rad: axis.minor_rms
                    / (axis.major_rms * (window.len() as f64 - 2.0).max(1.0).sqrt()),
            });
        }
    }
    out
}

/// How many of the track lines bend with `|bend_t| > min_t` and `|bend_deg| > min_deg`
/// towards the same side (the larger count of the two sides), the lines' directions first
/// oriented alike (doubled-angle mean).
pub fn bending_the_same_way(lines: &[TrackLine], min_t: f64, min_deg: f64) -> usize {
    let (c, s) = lines.iter().fold((0.0, 0.0), |(c, s), t| {
        let a = 2.0 * t.dir.y.atan2(t.dir.x);
        (c + a.cos(), s + a.sin())
    });
    let mean = 0.5 * f64::atan2(s, c);
    let reference = Point2::new(mean.cos(), mean.sin());
    let (mut left, mut right) = (0, 0);
    for t in lines {
        let sign = if t.dir.dot(reference) >= 0.0 {
            1.0
        } else {
            -1.0
        };
        let (bt, bd) = (sign * t.bend_t, sign * t.bend_deg);
        if bt > min_t && bd > min_deg {
            left += 1;
        } else if bt < -min_t && bd < -min_deg {
            right += 1;
        }
    }
    left.max(right)
}

/// When the tracks say the road curves: the fields `curved_bend_t`, `curved_bend_deg`,
/// `curved_share`, `min_curved_tracks` and `curved_max_se_deg` of
/// [`RobustOptions`](super::robust::RobustOptions).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct CurveTest {
    pub bend_t: f64,
    pub bend_deg: f64,
    pub share: f64,
    pub min_tracks: usize,
    pub max_se_deg: f64,
}

/// The vehicles' tracks and what they say about the road.
#[derive(Debug, Clone)]
pub(super) struct RoadTracks {
    /// The (frame, box) of every pair the tracker may use, and the pair each came from.
    pub boxes: Vec<(f64, BoxPx)>,
    pub pairs: Vec<usize>,
    /// The tracker's tracks (indices into `boxes`).
    pub links: Vec<Vec<usize>>,
    /// The lines of the straight tracks: VP1 evidence.
    pub straight: Vec<TrackLine>,
    /// Tracks that bend significantly the same way, and whether they make the road curved.
    pub curved_tracks: usize,
    pub road_curved: bool,
}

impl RoadTracks {
    /// Link `boxes` (`pairs[i]` the pair of `boxes[i]`) into tracks with `options` (`None`:
    /// no tracks) in a `frame` of `[width, height]` pixels, and test the road for a curve.
    pub(super) fn of(
        boxes: Vec<(f64, BoxPx)>,
        pairs: Vec<usize>,
        options: Option<&TrackOptions>,
        frame: [f64; 2],
        curve: &CurveTest,
    ) -> RoadTracks {
        let links = options.map_or_else(Vec::new, |t| link(&boxes, t));
        // Every track long enough, straight or not (a curve's tracks are the evidence that
        // the road curves), and the straight ones, which are VP1 evidence.
        let (moving, straight): (Vec<TrackLine>, Vec<TrackLine>) = match options {
            Some(t) => {
                let any_shape = TrackOptions {
                    max_rms_fraction: f64::INFINITY,
                    frame: Some(frame),
                    ..t.clone()
                };
                let moving: Vec<TrackLine> = links
                    .iter()
                    .filter_map(|l| fit_line(&boxes, l, &any_shape))
                    .collect();
                let straight = moving
                    .iter()
                    .filter(|l| l.is_straight(t))
                    .copied()
                    .collect();
                (moving, straight)
            }
            None => (Vec::new(), Vec::new()),
        };
        let telling: Vec<TrackLine> = moving
            .iter()
            .filter(|l| l.bend_se_deg < curve.max_se_deg)
            .copied()
            .collect();
        let curved_tracks = bending_the_same_way(&telling, curve.bend_t, curve.bend_deg);
        let road_curved = curved_tracks >= curve.min_tracks.max(1)
            && curved_tracks as f64 >= curve.share * telling.len() as f64;
        RoadTracks {
            boxes,
            pairs,
            links,
            straight,
            curved_tracks,
            road_curved,
        }
    }
}
