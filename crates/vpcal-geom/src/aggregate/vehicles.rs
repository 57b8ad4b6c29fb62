//! The vehicles as evidence: which pairs are usable, how much each weighs, and which boxes are
//! one physical vehicle.
//!
//! A pair counts with a detector score above `min_score`, finite VPs and a box. Boxes that
//! stay at one place over neighbouring frames (parked vehicles, static false detections) share
//! a total weight of `duplicate_keep` per place; boxes smaller than `min_box_fraction` of the
//! image height are down-weighted quadratically (their VP directions are unreliable). The
//! bootstraps resample physical vehicles ([`vehicle_units`]), not boxes.

use super::tracks::{self, TrackOptions};
use super::VehicleVps;
use crate::point::{BoxPx, Point2};

/// How the vehicles are weighed: the fields of the same names of
/// [`RobustOptions`](super::robust::RobustOptions).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Weighting {
    pub min_score: f64,
    pub duplicate_iou: f64,
    pub duplicate_keep: f64,
    pub min_box_fraction: f64,
}

/// Per-vehicle data prepared for fitting (frame pixels).
#[derive(Debug, Clone)]
pub(super) struct Prepared {
    pub centre: Vec<Point2>,
    /// Unit direction from the centre towards VP1.
    pub dir1: Vec<Point2>,
    /// Angle of the ray from the centre towards VP2, radians.
    pub angle2: Vec<f64>,
    /// VP1 points, frame pixels.
    pub vp1: Vec<Point2>,
    /// VP2 points, frame pixels.
    pub vp2: Vec<Point2>,
    /// Base weight (duplicates, size).
    pub weight: Vec<f64>,
    /// VP1-line weight factor from the decoder spread.
    pub spread1: Vec<f64>,
    /// The boxes.
    pub boxes: Vec<BoxPx>,
    /// The physical vehicle of each box ([`vehicle_units`]): the bootstrap's unit.
    pub unit: Vec<usize>,
    /// How many vehicles `unit` numbers.
    pub units: usize,
    pub repeated: usize,
}

impl Prepared {
    /// At most `max` vehicles, evenly spaced in input order, with weights rescaled so that
    /// their total equals the full total.
    pub(super) fn thinned(&self, max: usize) -> Prepared {
        let n = self.centre.len();
        if max == 0 || n <= max {
            return self.clone();
        }
        let idx: Vec<usize> = (0..max).map(|k| k * n / max).collect();
        let pick = |v: &Vec<Point2>| idx.iter().map(|&i| v[i]).collect::<Vec<_>>();
        let pickf = |v: &Vec<f64>| idx.iter().map(|&i| v[i]).collect::<Vec<_>>();
        let total: f64 = self.weight.iter().sum();
        let mut weight = pickf(&self.weight);
        let sub: f64 = weight.iter().sum();
        if sub > 0.0 {
            weight.iter_mut().for_each(|w| *w *= total / sub);
        }
        Prepared {
            centre: pick(&self.centre),
            dir1: pick(&self.dir1),
            angle2: pickf(&self.angle2),
            vp1: pick(&self.vp1),
            vp2: pick(&self.vp2),
            weight,
            spread1: pickf(&self.spread1),
            boxes: idx.iter().map(|&i| self.boxes[i]).collect(),
            unit: idx.iter().map(|&i| self.unit[i]).collect(),
            units: self.units,
            repeated: self.repeated,
        }
    }
}

fn unit(v: Point2) -> Option<Point2> {
    let n = v.norm();
    (n > 0.0 && n.is_finite()).then(|| v / n)
}

/// Buckets of box indices by the grid cell of their centre, for fast overlap queries.
struct BoxGrid<'a> {
    boxes: &'a [BoxPx],
    cells: std::collections::HashMap<(i64, i64), Vec<usize>>,
}

impl<'a> BoxGrid<'a> {
    const CELL: f64 = 32.0;

    fn key(p: Point2) -> (i64, i64) {
        (
            (p.x / Self::CELL).floor() as i64,
            (p.y / Self::CELL).floor() as i64,
        )
    }

    fn new(boxes: &'a [BoxPx], keep: impl Fn(usize) -> bool) -> BoxGrid<'a> {
        let mut cells: std::collections::HashMap<(i64, i64), Vec<usize>> =
            std::collections::HashMap::new();
        for (i, b) in boxes.iter().enumerate().filter(|(i, _)| keep(*i)) {
            cells.entry(Self::key(b.center())).or_default().push(i);
        }
        BoxGrid { boxes, cells }
    }

    /// Indices of the boxes of the grid overlapping box `i` with IoU above `iou` (boxes with
    /// IoU > 0.5 have centres within half the box size of each other).
    fn overlapping(&self, i: usize, iou: f64) -> impl Iterator<Item = usize> + '_ {
        let b = self.boxes[i];
        let (kx, ky) = Self::key(b.center());
        let rx = (b.width() / 2.0 / Self::CELL).ceil() as i64 + 1;
        let ry = (b.height() / 2.0 / Self::CELL).ceil() as i64 + 1;
        (kx - rx..=kx + rx)
            .flat_map(move |gx| (ky - ry..=ky + ry).map(move |gy| (gx, gy)))
            .filter_map(|k| self.cells.get(&k))
            .flatten()
            .copied()
            .filter(move |&j| b.iou(&self.boxes[j]) > iou)
    }
}

/// How far (in median frame steps) the stationary-box count looks back and ahead.
const REPEAT_WINDOW_STEPS: f64 = 100.0;

/// For each box, how many boxes share its place: the number of *stationary* boxes overlapping
/// it with IoU above `iou` (itself included) within [`REPEAT_WINDOW_STEPS`] frame steps, or 1
/// for a moving box.
///
/// A box is stationary when a box of a neighbouring frame (at most 1.5 median frame steps
/// away) overlaps it with IoU above `iou`: a parked vehicle or a static false detection. Cars
/// that pass the same spot at different times are not. Without frame numbers every box
/// counts as stationary (the conservative choice) and is compared with every other box
/// without a frame number.
///
/// Boxes are bucketed by (frame, grid cell), so the work grows with the boxes per frame and
/// the window, not with the square of the number of boxes.
fn repeat_counts(boxes: &[BoxPx], frames: &[Option<f64>], iou: f64) -> Vec<usize> {
    let n = boxes.len();
    let mut distinct: Vec<f64> = frames.iter().flatten().copied().collect();
    distinct.sort_by(f64::total_cmp);
    distinct.dedup();
    let steps: Vec<f64> = distinct.windows(2).map(|w| w[1] - w[0]).collect();
    let median_step = if steps.is_empty() {
        0.0
    } else {
        let mut s = steps.clone();
        s.sort_by(f64::total_cmp);
        s[s.len() / 2]
    };
    let max_gap = 1.5 * median_step;
    let window = REPEAT_WINDOW_STEPS * median_step;
    let key = |b: &BoxPx| BoxGrid::key(b.center());
    // Per grid cell, the (frame, box) entries sorted by frame.
    let mut cells: std::collections::HashMap<(i64, i64), Vec<(f64, usize)>> =
        std::collections::HashMap::new();
    for (i, b) in boxes.iter().enumerate() {
        if let Some(f) = frames[i] {
            cells.entry(key(b)).or_default().push((f, i));
        }
    }
    for v in cells.values_mut() {
        v.sort_by(|a, b| a.0.total_cmp(&b.0));
    }
    // Boxes with a frame in [lo, hi] overlapping box `i` above `iou`, among those `keep`
    // accepts.
    let overlapping_in = |i: usize, lo: f64, hi: f64, keep: &dyn Fn(usize) -> bool| -> usize {
        let b = boxes[i];
        let (kx, ky) = key(&b);
        let rx = (b.width() / 2.0 / BoxGrid::CELL).ceil() as i64 + 1;
        let ry = (b.height() / 2.0 / BoxGrid::CELL).ceil() as i64 + 1;
        let mut count = 0;
        for gx in kx - rx..=kx + rx {
            for gy in ky - ry..=ky + ry {
                if let Some(v) = cells.get(&(gx, gy)) {
                    let start = v.partition_point(|e| e.0 < lo);
                    count += v[start..]
                        .iter()
                        .take_while(|e| e.0 <= hi)
                        .filter(|e| keep(e.1) && b.iou(&boxes[e.1]) > iou)
                        .count();
                }
            }
        }
        count
    };
    let frameless_set: Vec<bool> = frames.iter().map(Option::is_none).collect();
    let still_frameless = BoxGrid::new(boxes, |i| frameless_set[i]);
    let stationary: Vec<bool> = (0..n)
        .map(|i| match frames[i] {
            None => true,
            Some(f) => overlapping_in(i, f - max_gap, f + max_gap, &|j| frames[j] != Some(f)) > 0,
        })
        .collect();
    (0..n)
        .map(|i| {
            if !stationary[i] {
                return 1;
            }
            match frames[i] {
                None => still_frameless.overlapping(i, iou).count().max(1),
                Some(f) => overlapping_in(i, f - window, f + window, &|j| stationary[j]).max(1),
            }
        })
        .collect()
}

/// The physical vehicle each pair belongs to, numbered `0..n` (returned with `n`): the boxes
/// of one vehicle seen in consecutive frames (a track of the box tracker, [`tracks::link`])
/// share a number; a box without a frame or a valid box is a vehicle of its own.
///
/// The boxes of one vehicle are not independent evidence: the network and the edges see the
/// same car, the same way, frame after frame. Bootstraps resample vehicles, not boxes:
/// resampling the 20 boxes of each of three cars as 60 independent samples gave intervals
/// that left out the estimate of longer footage of the same camera (20 frames of a real
/// highway clip, issue 41).
pub fn vehicle_units(pairs: &[VehicleVps]) -> (Vec<usize>, usize) {
    let linked: Vec<(f64, BoxPx)> = pairs
        .iter()
        .map(|p| match (p.frame, p.box_px) {
            (Some(f), Some(b)) if f.is_finite() && b.is_valid() => (f, b),
            // Not linked by the tracker (it skips non-finite frames).
            _ => (f64::NAN, BoxPx::new(0.0, 0.0, 0.0, 0.0)),
        })
        .collect();
    let mut unit = vec![usize::MAX; pairs.len()];
    let mut n = 0;
    for track in tracks::link(&linked, &TrackOptions::default()) {
        for i in track {
            unit[i] = n;
        }
        n += 1;
    }
    for u in &mut unit {
        if *u == usize::MAX {
            *u = n;
            n += 1;
        }
    }
    (unit, n)
}

/// The rows of the usable `pairs`, each with its vehicle (`units`: [`vehicle_units`] of
/// `pairs`).
pub(super) fn prepare(
    pairs: &[VehicleVps],
    units: &(Vec<usize>, usize),
    opts: &Weighting,
    image_h: f64,
) -> Prepared {
    let (pair_unit, units) = (&units.0, units.1);
    let mut boxes = Vec::new();
    let mut frames = Vec::new();
    let mut rows = Vec::new();
    let mut row_unit = Vec::new();
    for (p, u) in pairs.iter().zip(pair_unit) {
        if !p.is_ray(opts.min_score) {
            continue;
        }
        let Some(b) = p.box_px.filter(BoxPx::is_valid) else {
            continue;
        };
        let c = b.center();
        let (Some(d1), Some(d2)) = (unit(p.vp1 - c), unit(p.vp2 - c)) else {
            continue;
        };
        let s1 = p.vp1_spread.filter(|s| s.is_finite()).unwrap_or(10.0);
        boxes.push(b);
        frames.push(p.frame);
        row_unit.push(*u);
        rows.push((c, d1, d2.y.atan2(d2.x), s1, p.vp1, p.vp2));
    }
    let counts = repeat_counts(&boxes, &frames, opts.duplicate_iou);
    let threshold = (opts.min_box_fraction * image_h).max(1e-9);
    let mut out = Prepared {
        centre: Vec::with_capacity(rows.len()),
        dir1: Vec::with_capacity(rows.len()),
        angle2: Vec::with_capacity(rows.len()),
        vp1: Vec::with_capacity(rows.len()),
        vp2: Vec::with_capacity(rows.len()),
        weight: Vec::with_capacity(rows.len()),
        spread1: Vec::with_capacity(rows.len()),
        boxes: boxes.clone(),
        unit: row_unit,
        units,
        repeated: counts
            .iter()
            .filter(|c| **c as f64 > opts.duplicate_keep)
            .count(),
    };
    for ((c, d1, a2, s1, v1, v2), (b, count)) in rows.into_iter().zip(boxes.iter().zip(&counts)) {
        let size = (b.width() * b.height()).sqrt() / 2.0;
        let w_size = (size / threshold).min(1.0).powi(2);
        let w_dup = (opts.duplicate_keep / *count as f64).min(1.0);
        out.centre.push(c);
        out.dir1.push(d1);
        out.angle2.push(a2);
        out.vp1.push(v1);
        out.vp2.push(v2);
        out.weight.push(w_size * w_dup);
        out.spread1.push(1.0 / (s1 + 0.05));
    }
    out
}

/// The (frame, box) of every pair the tracker may use: a box, a frame and a score above the
/// threshold (its VPs do not matter).
pub(super) fn tracked_boxes(
    pairs: &[VehicleVps],
    opts: &Weighting,
) -> (Vec<(f64, BoxPx)>, Vec<usize>) {
    pairs
        .iter()
        .enumerate()
        .filter(|(_, p)| p.score > opts.min_score)
        .filter_map(|(i, p)| Some(((p.frame?, p.box_px.filter(BoxPx::is_valid)?), i)))
        .unzip()
}
