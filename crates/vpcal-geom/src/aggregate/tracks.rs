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
}

impl Default for TrackOptions {
    fn default() -> Self {
        TrackOptions {
            min_iou: 0.2,
            first_link_sizes: 1.0,
            max_gap_steps: 2.5,
            min_boxes: 5,
            min_travel_boxes: 1.0,
            max_rms_fraction: 0.03,
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

/// The line through a track's box centres (total least squares), or `None` when the track is
/// too short, travelled too little, or is not straight (see [`TrackOptions`]).
pub fn fit_line(boxes: &[(f64, BoxPx)], track: &[usize], opts: &TrackOptions) -> Option<TrackLine> {
    let n = track.len();
    if n < opts.min_boxes.max(2) {
        return None;
    }
    let centres: Vec<Point2> = track.iter().map(|&i| boxes[i].1.center()).collect();
    let mean = centres.iter().fold(Point2::new(0.0, 0.0), |a, c| a + *c) / n as f64;
    let (mut sxx, mut sxy, mut syy) = (0.0, 0.0, 0.0);
    for c in &centres {
        let d = *c - mean;
        sxx += d.x * d.x;
        sxy += d.x * d.y;
        syy += d.y * d.y;
    }
    // Eigen-decomposition of the 2x2 scatter matrix: the major axis is the direction.
    let half_trace = (sxx + syy) / 2.0;
    let root = (((sxx - syy) / 2.0).powi(2) + sxy * sxy).sqrt();
    let minor = (half_trace - root).max(0.0);
    let angle = 0.5 * (2.0 * sxy).atan2(sxx - syy);
    let dir = Point2::new(angle.cos(), angle.sin());
    let rms = (minor / n as f64).sqrt();
    let travel = (centres[n - 1] - centres[0]).dot(dir).abs();
    let mut sizes: Vec<f64> = track
        .iter()
        .map(|&i| (boxes[i].1.width() * boxes[i].1.height()).sqrt())
        .collect();
    sizes.sort_by(f64::total_cmp);
    let size = sizes[n / 2];
    let ok = travel.is_finite()
        && travel > 0.0
        && travel >= opts.min_travel_boxes * size
        && rms <= opts.max_rms_fraction * travel;
    ok.then_some(TrackLine {
        point: mean,
        dir,
        boxes: n,
        travel,
        rms,
    })
}

/// Link `boxes` into tracks and return the lines of the tracks that qualify.
pub fn track_lines(boxes: &[(f64, BoxPx)], opts: &TrackOptions) -> Vec<TrackLine> {
    link(boxes, opts)
        .iter()
        .filter_map(|t| fit_line(boxes, t, opts))
        .collect()
}
