//! Straight line segments of a picture, by growing regions of pixels whose edges run the
//! same way (the idea of Grompone von Gioi et al.'s LSD, without its a-contrario test: a
//! region counts as a segment when it is long and fills the rectangle around it).
//!
//! The picture is smoothed with a small Gaussian; each pixel's gradient comes from its 2×2
//! block, its level-line angle (the edge's direction, oriented by which side is brighter)
//! from the gradient. From the strongest unused pixel, a region takes in neighbours (8-way)
//! whose level-line angle lies within [`SegmentOptions::angle_tolerance_deg`] of the
//! region's mean; the region's rectangle is its principal axis and extents. Regions shorter
//! than [`SegmentOptions::min_length_1080p`] (scaled with the width) or filling less than
//! [`SegmentOptions::min_density`] of their rectangle are dropped. Used for the scene's
//! vertical lines (`vpcal_geom::aggregate::verticals`).

use image::GrayImage;
use vpcal_geom::aggregate::verticals::Segment;
use vpcal_geom::Point2;

use crate::edgelets::{convolve, kernel};

/// Settings of [`line_segments`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SegmentOptions {
    /// The Gaussian smoothing before the gradients, pixels (LSD's 0.8 downscale smooths
    /// with 0.6 / 0.8).
    pub sigma: f32,
    /// The least gradient magnitude of a region's pixel, grey levels per pixel: LSD's
    /// bound for a quantisation error of 2 grey levels at the angle tolerance
    /// (2 / sin 22.5°).
    pub min_gradient: f32,
    /// How far a pixel's level-line angle may turn from its region's, degrees.
    pub angle_tolerance_deg: f64,
    /// The least length of a segment at 1920 px wide, pixels (scaled with the width, at
    /// least 8).
    pub min_length_1080p: f64,
    /// The least share of its rectangle (length × width) that a region's pixels fill.
    pub min_density: f64,
}

impl Default for SegmentOptions {
    fn default() -> SegmentOptions {
        SegmentOptions {
            sigma: 0.75,
            min_gradient: 5.2,
            angle_tolerance_deg: 22.5,
            min_length_1080p: 20.0,
            min_density: 0.6,
        }
    }
}

/// The segments of `grey`, frame pixels (a pixel's centre at `x + 0.5`).
pub fn line_segments(grey: &GrayImage, opts: &SegmentOptions) -> Vec<Segment> {
    let (w, h) = (grey.width() as usize, grey.height() as usize);
    if w < 2 || h < 2 {
        return Vec::new();
    }
    let raw: Vec<f32> = grey.as_raw().iter().map(|&v| f32::from(v)).collect();
    let g = kernel(opts.sigma, 0, 3.0);
    let smooth = convolve(&convolve(&raw, w, h, &g, true), w, h, &g, false);
    // Gradients of the 2×2 blocks, at the blocks' centres (x + 1, y + 1 in pixel-corner
    // coordinates); the last row and column have none.
    let (gw, gh) = (w - 1, h - 1);
    let mut magnitude = vec![0.0f32; gw * gh];
    let mut angle = vec![0.0f64; gw * gh];
    for y in 0..gh {
        for x in 0..gw {
            let (a, b) = (smooth[y * w + x], smooth[y * w + x + 1]);
            let (c, d) = (smooth[(y + 1) * w + x], smooth[(y + 1) * w + x + 1]);
            let gx = 0.5 * (b + d - a - c);
            let gy = 0.5 * (c + d - a - b);
            let i = y * gw + x;
            magnitude[i] = gx.hypot(gy);
            // The level line runs across the gradient.
            angle[i] = f64::from(gx).atan2(-f64::from(gy));
        }
    }
    let mut order: Vec<usize> = (0..gw * gh)
        .filter(|&i| magnitude[i] >= opts.min_gradient)
        .collect();
    order.sort_by(|&a, &b| magnitude[b].total_cmp(&magnitude[a]));
    let mut used = vec![false; gw * gh];
    for (u, m) in used.iter_mut().zip(&magnitude) {
        *u = *m < opts.min_gradient;
    }
    let tolerance = opts.angle_tolerance_deg.to_radians();
    let min_length = (opts.min_length_1080p * w as f64 / 1920.0).max(8.0);
    let mut out = Vec::new();
    let mut region: Vec<usize> = Vec::new();
    for &seed in &order {
        if used[seed] {
            continue;
        }
        used[seed] = true;
        region.clear();
        region.push(seed);
        let (mut sum_cos, mut sum_sin) = (angle[seed].cos(), angle[seed].sin());
        let mut mean = angle[seed];
        let mut next = 0;
        while next < region.len() {
            let i = region[next];
            next += 1;
            let (x, y) = ((i % gw) as isize, (i / gw) as isize);
            for dy in -1..=1isize {
                for dx in -1..=1isize {
                    let (nx, ny) = (x + dx, y + dy);
                    if nx < 0 || ny < 0 || nx >= gw as isize || ny >= gh as isize {
                        continue;
                    }
                    let j = ny as usize * gw + nx as usize;
                    if used[j] || !within(angle[j], mean, tolerance) {
                        continue;
                    }
                    used[j] = true;
                    region.push(j);
                    sum_cos += angle[j].cos();
                    sum_sin += angle[j].sin();
                    mean = sum_sin.atan2(sum_cos);
                }
            }
        }
        if (region.len() as f64) < min_length {
            continue;
        }
        if let Some(s) = rectangle(&region, gw, &magnitude, min_length, opts.min_density) {
            out.push(s);
        }
    }
    out
}

/// Whether the oriented angle `a` lies within `tolerance` of `b`.
fn within(a: f64, b: f64, tolerance: f64) -> bool {
    let pi = std::f64::consts::PI;
    let d = (a - b + pi).rem_euclid(2.0 * pi) - pi;
    d.abs() <= tolerance
}

/// The region's rectangle as a segment through the middle of its width, if it is long and
/// dense enough.
fn rectangle(
    region: &[usize],
    gw: usize,
    magnitude: &[f32],
    min_length: f64,
    min_density: f64,
) -> Option<Segment> {
    // Block centres in frame pixels: the block at (x, y) covers pixels x..x+2.
    let at = |i: usize| Point2::new((i % gw) as f64 + 1.0, (i / gw) as f64 + 1.0);
    let mut sum = 0.0;
    let mut c = Point2::new(0.0, 0.0);
    for &i in region {
        let m = f64::from(magnitude[i]);
        sum += m;
        c = c + at(i) * m;
    }
    let c = c * (1.0 / sum);
    let (mut sxx, mut sxy, mut syy) = (0.0, 0.0, 0.0);
    for &i in region {
        let (m, d) = (f64::from(magnitude[i]), at(i) - c);
        sxx += m * d.x * d.x;
        sxy += m * d.x * d.y;
        syy += m * d.y * d.y;
    }
    let theta = 0.5 * (2.0 * sxy).atan2(sxx - syy);
    let (axis, across) = (
        Point2::new(theta.cos(), theta.sin()),
        Point2::new(-theta.sin(), theta.cos()),
    );
    let (mut t0, mut t1, mut s0, mut s1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for &i in region {
        let d = at(i) - c;
        let (t, s) = (d.dot(axis), d.dot(across));
        t0 = t0.min(t);
        t1 = t1.max(t);
        s0 = s0.min(s);
        s1 = s1.max(s);
    }
    let (length, width) = (t1 - t0 + 1.0, s1 - s0 + 1.0);
    let density = region.len() as f64 / (length * width);
    (length >= min_length && density >= min_density).then(|| Segment {
        a: c + axis * t0,
        b: c + axis * t1,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A dark picture with a bright bar between `a` and `b`, `half` pixels either side of
    /// the line (anti-aliased by 4×4 supersampling).
    fn bar(w: u32, h: u32, a: Point2, b: Point2, half: f64) -> GrayImage {
        let u = (b - a) * (1.0 / (b - a).norm());
        let n = Point2::new(-u.y, u.x);
        let len = (b - a).norm();
        GrayImage::from_fn(w, h, |x, y| {
            let mut inside = 0;
            for sy in 0..4 {
                for sx in 0..4 {
                    let p = Point2::new(
                        f64::from(x) + (f64::from(sx) + 0.5) / 4.0,
                        f64::from(y) + (f64::from(sy) + 0.5) / 4.0,
                    );
                    let d = p - a;
                    let t = d.dot(u);
                    if (0.0..=len).contains(&t) && d.dot(n).abs() <= half {
                        inside += 1;
                    }
                }
            }
            image::Luma([(40 + inside * 10) as u8])
        })
    }

    #[test]
    fn a_bar_gives_its_two_edges() {
        let (a, b) = (Point2::new(50.0, 30.0), Point2::new(90.0, 170.0));
        let img = bar(160, 200, a, b, 3.0);
        let segs = line_segments(&img, &SegmentOptions::default());
        let along = (b - a).y.atan2((b - a).x);
        let long: Vec<&Segment> = segs.iter().filter(|s| s.length() > 100.0).collect();
        assert_eq!(long.len(), 2, "{segs:?}");
        for s in long {
            let pi = std::f64::consts::PI;
            let d = (s.angle() - along + pi / 2.0).rem_euclid(pi) - pi / 2.0;
            assert!(d.abs() < 0.5_f64.to_radians(), "{s:?}");
            // Each edge lies 3 px from the bar's middle line.
            let u = (b - a) * (1.0 / (b - a).norm());
            let off = (s.middle() - a).dot(Point2::new(-u.y, u.x)).abs();
            assert!((off - 3.0).abs() < 0.7, "{off}");
        }
    }

    #[test]
    fn noise_gives_no_long_segments() {
        let mut state = 12345u64;
        let img = GrayImage::from_fn(300, 200, |_, _| {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            image::Luma([(100 + (state >> 59)) as u8])
        });
        let segs = line_segments(&img, &SegmentOptions::default());
        assert!(segs.iter().all(|s| s.length() < 20.0), "{segs:?}");
    }
}
