//! Road markings in the scene's background: thin bright bars (lane lines, their dashes) found
//! by a white top-hat of the background's grey levels.
//!
//! A marking is brighter than the asphalt around it and narrower than the top-hat's window:
//! the grey opening (erosion then dilation over a square window) removes it, so the image
//! minus its opening keeps it. Pixels whose top-hat stands out from the image's own spread
//! (its median plus [`BarOptions::mad_k`] robust standard deviations, at least
//! [`BarOptions::min_contrast`] grey levels) form connected bars; each bar is summarised by
//! its principal axis. Which bars are lane lines, and which of those are dashed, is geometry
//! (`vpcal::markings`): it needs the road's vanishing point.

use image::GrayImage;
use imageproc::region_labelling::{connected_components, Connectivity};
use vpcal_geom::Point2;

/// Settings of [`bright_bars`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BarOptions {
    /// Half the top-hat's window at 1920 px wide, pixels (scaled with the image's width, at
    /// least 3): markings narrower than the window are kept. 7 (a 15-px window) holds the lane
    /// lines of BrnoCompSpeed's 1080p views, which are 3-12 px wide.
    pub radius_1080p: u32,
    /// The least top-hat contrast of a marking, grey levels.
    pub min_contrast: f64,
    /// How many robust standard deviations (1.4826 MAD) above the median top-hat a marking's
    /// pixels lie.
    pub mad_k: f64,
    /// The fewest pixels of a bar.
    pub min_pixels: usize,
}

impl Default for BarOptions {
    fn default() -> BarOptions {
        BarOptions {
            radius_1080p: 7,
            min_contrast: 12.0,
            mad_k: 6.0,
            min_pixels: 8,
        }
    }
}

/// Components wider than this many top-hat windows are not markings (see [`bright_bars`]).
pub const MAX_WIDTH_WINDOWS: f64 = 1.5;

/// One bright bar: a connected set of top-hat pixels and its principal axis.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bar {
    /// The mean of its pixel centres.
    pub centre: Point2,
    /// The unit direction of its long axis.
    pub axis: Point2,
    /// Its extent along the axis, pixels (one pixel more than the ends' distance).
    pub length: f64,
    /// Its width across the axis, pixels (a uniform bar's, from the spread across it).
    pub width: f64,
    /// The ends of its extent along the axis.
    pub ends: [Point2; 2],
    pub pixels: usize,
    /// The covariance of its pixel centres, `[xx, xy, yy]`.
    pub cov: [f64; 3],
}

impl Bar {
    /// Its spread along unit direction `d`: the width of a uniform bar whose pixels vary
    /// as much along `d`, pixels.
    pub fn extent_along(&self, d: Point2) -> f64 {
        let [xx, xy, yy] = self.cov;
        (12.0 * (d.x * d.x * xx + 2.0 * d.x * d.y * xy + d.y * d.y * yy).max(0.0)).sqrt()
    }
}

/// A component's centre, unit long axis, variance across it and covariance `[xx, xy, yy]`.
type Axis = (Point2, Point2, f64, [f64; 3]);

/// The half window of the top-hat for an image `width` pixels wide.
pub fn top_hat_radius(options: &BarOptions, width: u32) -> usize {
    let r = f64::from(options.radius_1080p) * f64::from(width) / 1920.0;
    (r.round() as usize).max(3)
}

/// Running minimum (`max` false) or maximum over `2r + 1` samples of each row of `src`
/// (`w` wide), clamped at the ends, into `dst`.
fn running_extreme_rows(src: &[u8], dst: &mut [u8], w: usize, r: usize, max: bool) {
    for (row_in, row_out) in src.chunks_exact(w).zip(dst.chunks_exact_mut(w)) {
        for (x, out) in row_out.iter_mut().enumerate() {
            let window = &row_in[x.saturating_sub(r)..(x + r + 1).min(w)];
            let v = if max {
                window.iter().max()
            } else {
                window.iter().min()
            };
            *out = v.copied().unwrap_or(0);
        }
    }
}

/// `src` (`w` x `h`) transposed.
fn transposed(src: &[u8], w: usize, h: usize) -> Vec<u8> {
    let mut out = vec![0u8; src.len()];
    for y in 0..h {
        for x in 0..w {
            out[x * h + y] = src[y * w + x];
        }
    }
    out
}

/// The minimum (`max` false) or maximum over the `(2r + 1)²` square around each pixel,
/// separably (rows, then columns).
fn square_extreme(src: &[u8], w: usize, h: usize, r: usize, max: bool) -> Vec<u8> {
    let mut rows = vec![0u8; src.len()];
    running_extreme_rows(src, &mut rows, w, r, max);
    let t = transposed(&rows, w, h);
    let mut cols = vec![0u8; src.len()];
    running_extreme_rows(&t, &mut cols, h, r, max);
    transposed(&cols, h, w)
}

/// The white top-hat of `grey` over a `(2r + 1)²` window: each pixel minus the grey opening.
pub fn white_top_hat(grey: &GrayImage, r: usize) -> Vec<u8> {
    let (w, h) = (grey.width() as usize, grey.height() as usize);
    let src = grey.as_raw();
    let eroded = square_extreme(src, w, h, r, false);
    let opened = square_extreme(&eroded, w, h, r, true);
    src.iter()
        .zip(&opened)
        .map(|(&v, &o)| v - o.min(v))
        .collect()
}

/// The median and the robust standard deviation (1.4826 MAD) of `values`.
fn median_and_spread(values: &[u8]) -> (f64, f64) {
    let mut hist = [0usize; 256];
    for &v in values {
        hist[usize::from(v)] += 1;
    }
    let quantile = |hist: &[usize], n: usize| {
        let half = n.div_ceil(2).max(1);
        let mut seen = 0;
        for (v, &c) in hist.iter().enumerate() {
            seen += c;
            if seen >= half {
                return v as f64;
            }
        }
        0.0
    };
    let med = quantile(&hist, values.len());
    let mut dev = [0usize; 256];
    for (v, &c) in hist.iter().enumerate() {
        dev[(v as f64 - med).abs() as usize] += c;
    }
    (med, 1.4826 * quantile(&dev, values.len()))
}

/// The bright bars of `grey` (the scene's background), inside `mask` where one is given
/// (non-zero pixels; the same size). See the module docs.
pub fn bright_bars(grey: &GrayImage, mask: Option<&GrayImage>, options: &BarOptions) -> Vec<Bar> {
    let (w, h) = grey.dimensions();
    if w == 0 || h == 0 {
        return Vec::new();
    }
    let inside = |i: usize| mask.is_none_or(|m| m.as_raw().get(i).is_some_and(|&v| v > 0));
    let r = top_hat_radius(options, w);
    let top = white_top_hat(grey, r);
    let inner: Vec<u8> = (0..top.len())
        .filter(|&i| inside(i))
        .map(|i| top[i])
        .collect();
    if inner.is_empty() {
        return Vec::new();
    }
    let (med, sd) = median_and_spread(&inner);
    let threshold = (med + options.mad_k * sd).max(options.min_contrast);
    let binary = GrayImage::from_fn(w, h, |x, y| {
        let i = y as usize * w as usize + x as usize;
        image::Luma([u8::from(inside(i) && f64::from(top[i]) > threshold)])
    });
    let labels = connected_components(&binary, Connectivity::Eight, image::Luma([0u8]));
    // Moments per label: count, sums of x, y, xx, xy, yy (pixel centres).
    let mut moments: Vec<[f64; 6]> = Vec::new();
    for (x, y, l) in labels.enumerate_pixels() {
        let l = l[0] as usize;
        if l == 0 {
            continue;
        }
        if moments.len() < l {
            moments.resize(l, [0.0; 6]);
        }
        let (px, py) = (f64::from(x) + 0.5, f64::from(y) + 0.5);
        let m = &mut moments[l - 1];
        m[0] += 1.0;
        m[1] += px;
        m[2] += py;
        m[3] += px * px;
        m[4] += px * py;
        m[5] += py * py;
    }
    let axes: Vec<Option<Axis>> = moments
        .iter()
        .map(|m| {
            let n = m[0];
            if (n as usize) < options.min_pixels {
                return None;
            }
            let c = Point2::new(m[1] / n, m[2] / n);
            let sxx = m[3] / n - c.x * c.x;
            let sxy = m[4] / n - c.x * c.y;
            let syy = m[5] / n - c.y * c.y;
            // The larger eigenvalue's eigenvector of [[sxx, sxy], [sxy, syy]].
            let half_diff = 0.5 * (sxx - syy);
            let root = (half_diff * half_diff + sxy * sxy).sqrt();
            let minor = 0.5 * (sxx + syy) - root;
            let angle = 0.5 * (2.0 * sxy).atan2(sxx - syy);
            let axis = Point2::new(angle.cos(), angle.sin());
            Some((c, axis, minor.max(0.0), [sxx, sxy, syy]))
        })
        .collect();
    // Extent along each axis.
    let mut extent = vec![[f64::INFINITY, f64::NEG_INFINITY]; axes.len()];
    for (x, y, l) in labels.enumerate_pixels() {
        let l = l[0] as usize;
        let Some(Some((c, a, _, _))) = l.checked_sub(1).and_then(|i| axes.get(i)) else {
            continue;
        };
        let t = (f64::from(x) + 0.5 - c.x) * a.x + (f64::from(y) + 0.5 - c.y) * a.y;
        let e = &mut extent[l - 1];
        e[0] = e[0].min(t);
        e[1] = e[1].max(t);
    }
    axes.iter()
        .zip(&extent)
        .zip(&moments)
        .filter_map(|((axis, e), m)| {
            let (c, a, minor, cov) = (*axis)?;
            // The top-hat keeps structures narrower than its window; a component much wider is
            // a cluster of bright texture, not a marking.
            let width = (12.0 * minor).sqrt();
            if width > MAX_WIDTH_WINDOWS * (2 * r + 1) as f64 {
                return None;
            }
            let at = |t: f64| Point2::new(c.x + a.x * t, c.y + a.y * t);
            Some(Bar {
                centre: c,
                axis: a,
                length: e[1] - e[0] + 1.0,
                width,
                ends: [at(e[0]), at(e[1])],
                pixels: m[0] as usize,
                cov,
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A grey road (level 90, a little texture) with white bars drawn as `(x0, y0, x1, y1, w)`
    /// thick segments.
    fn road(w: u32, h: u32, bars: &[(f64, f64, f64, f64, f64)]) -> GrayImage {
        GrayImage::from_fn(w, h, |x, y| {
            let p = Point2::new(f64::from(x) + 0.5, f64::from(y) + 0.5);
            let on = bars.iter().any(|&(x0, y0, x1, y1, width)| {
                let (dx, dy) = (x1 - x0, y1 - y0);
                let len2 = dx * dx + dy * dy;
                let t = (((p.x - x0) * dx + (p.y - y0) * dy) / len2).clamp(0.0, 1.0);
                let (qx, qy) = (x0 + t * dx, y0 + t * dy);
                ((p.x - qx).powi(2) + (p.y - qy).powi(2)).sqrt() <= width / 2.0
            });
            let texture = ((x * 7 + y * 13) % 5) as u8;
            image::Luma([if on { 220 } else { 90 + texture }])
        })
    }

    #[test]
    fn the_top_hat_keeps_thin_bright_lines_and_drops_wide_bright_areas() {
        let mut img = road(200, 100, &[(10.0, 50.0, 190.0, 50.0, 3.0)]);
        // A bright square wider than the window.
        for y in 10..40 {
            for x in 100..140 {
                img.put_pixel(x, y, image::Luma([230]));
            }
        }
        let top = white_top_hat(&img, 7);
        assert!(top[50 * 200 + 100] > 100, "{}", top[50 * 200 + 100]);
        assert_eq!(top[25 * 200 + 120], 0);
    }

    #[test]
    fn bars_have_their_drawn_axis_length_and_width() {
        let img = road(
            640,
            360,
            &[
                (100.0, 300.0, 160.0, 200.0, 4.0),
                (400.0, 100.0, 520.0, 110.0, 3.0),
            ],
        );
        let mut bars = bright_bars(&img, None, &BarOptions::default());
        assert_eq!(bars.len(), 2, "{bars:?}");
        bars.sort_by(|a, b| a.centre.x.total_cmp(&b.centre.x));
        let b = bars[0];
        let drawn = (60.0f64.powi(2) + 100.0f64.powi(2)).sqrt();
        assert!(
            (b.centre.x - 130.0).abs() < 1.0 && (b.centre.y - 250.0).abs() < 1.0,
            "{b:?}"
        );
        let cross = (b.axis.x * 100.0 + b.axis.y * 60.0).abs() / drawn;
        assert!(cross < 0.01, "axis {:?}", b.axis);
        assert!((b.length - (drawn + 4.0)).abs() < 3.0, "{}", b.length);
        assert!((b.width - 4.0).abs() < 1.5, "{}", b.width);
        assert!((bars[1].length - 124.4).abs() < 3.0, "{}", bars[1].length);
    }

    #[test]
    fn a_mask_hides_bars_outside_it() {
        let img = road(320, 180, &[(20.0, 90.0, 300.0, 90.0, 3.0)]);
        let mask = GrayImage::from_fn(320, 180, |x, _| image::Luma([u8::from(x < 160) * 255]));
        let bars = bright_bars(&img, Some(&mask), &BarOptions::default());
        assert_eq!(bars.len(), 1);
        assert!(bars[0].ends.iter().all(|p| p.x < 161.0), "{:?}", bars[0]);
    }

    #[test]
    fn a_plain_image_has_no_bars() {
        assert!(bright_bars(&road(100, 80, &[]), None, &BarOptions::default()).is_empty());
        assert!(bright_bars(&GrayImage::new(0, 0), None, &BarOptions::default()).is_empty());
    }
}
