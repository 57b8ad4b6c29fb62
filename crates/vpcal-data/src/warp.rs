//! Plane homographies and image resampling for the augmentation.
//!
//! # Conventions
//! Continuous pixel coordinates: pixel (i, j) covers [i, i+1) x [j, j+1), so its centre is at
//! (i + 0.5, j + 0.5). Resampling evaluates the source at continuous points; sampling exactly at
//! pixel centres returns the pixels unchanged with every filter (the kernels interpolate).
//! Outside the image the border pixels repeat (OpenCV's `BORDER_REPLICATE`).

use image::RgbImage;
use serde::{Deserialize, Serialize};
use vpcal_geom::Point2;

/// A plane projective transformation `p' ~ H p` (homogeneous, row-major 3x3).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Homography(pub [[f64; 3]; 3]);

impl Homography {
    /// The identity.
    pub const IDENTITY: Homography =
        Homography([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]);

    /// The homography that maps each `src[k]` to `dst[k]` (4 point pairs, no three collinear),
    /// with `H[2][2] = 1`. `None` when the points are degenerate.
    pub fn from_points(src: [Point2; 4], dst: [Point2; 4]) -> Option<Homography> {
        // Unknowns h = (h00 h01 h02 h10 h11 h12 h20 h21); two equations per pair:
        //   x' (h20 x + h21 y + 1) = h00 x + h01 y + h02, likewise for y'.
        let mut a = [[0.0f64; 9]; 8];
        for k in 0..4 {
            let (x, y) = (src[k].x, src[k].y);
            let (u, v) = (dst[k].x, dst[k].y);
            a[2 * k] = [x, y, 1.0, 0.0, 0.0, 0.0, -u * x, -u * y, u];
            a[2 * k + 1] = [0.0, 0.0, 0.0, x, y, 1.0, -v * x, -v * y, v];
        }
        let h = solve8(a)?;
        let m = Homography([[h[0], h[1], h[2]], [h[3], h[4], h[5]], [h[6], h[7], 1.0]]);
        m.0.iter().flatten().all(|v| v.is_finite()).then_some(m)
    }

    /// Map a point; `None` when it goes to infinity (or beyond f64).
    pub fn apply(&self, p: Point2) -> Option<Point2> {
        let [x, y, w] = self.apply_h([p.x, p.y, 1.0]);
        if w == 0.0 {
            return None;
        }
        let q = Point2::new(x / w, y / w);
        q.is_finite().then_some(q)
    }

    /// Map homogeneous coordinates.
    pub fn apply_h(&self, p: [f64; 3]) -> [f64; 3] {
        let m = &self.0;
        [
            m[0][0] * p[0] + m[0][1] * p[1] + m[0][2] * p[2],
            m[1][0] * p[0] + m[1][1] * p[1] + m[1][2] * p[2],
            m[2][0] * p[0] + m[2][1] * p[1] + m[2][2] * p[2],
        ]
    }

    /// The inverse; `None` for a singular matrix.
    pub fn inverse(&self) -> Option<Homography> {
        let m = &self.0;
        let c00 = m[1][1] * m[2][2] - m[1][2] * m[2][1];
        let c01 = m[1][2] * m[2][0] - m[1][0] * m[2][2];
        let c02 = m[1][0] * m[2][1] - m[1][1] * m[2][0];
        let det = m[0][0] * c00 + m[0][1] * c01 + m[0][2] * c02;
        if det == 0.0 || !det.is_finite() {
            return None;
        }
        let inv = [
            [
                c00 / det,
                (m[0][2] * m[2][1] - m[0][1] * m[2][2]) / det,
                (m[0][1] * m[1][2] - m[0][2] * m[1][1]) / det,
            ],
            [
                c01 / det,
                (m[0][0] * m[2][2] - m[0][2] * m[2][0]) / det,
                (m[0][2] * m[1][0] - m[0][0] * m[1][2]) / det,
            ],
            [
                c02 / det,
                (m[0][1] * m[2][0] - m[0][0] * m[2][1]) / det,
                (m[0][0] * m[1][1] - m[0][1] * m[1][0]) / det,
            ],
        ];
        Some(Homography(inv))
    }
}

/// Gaussian elimination with partial pivoting on an 8x9 augmented matrix.
fn solve8(mut a: [[f64; 9]; 8]) -> Option<[f64; 8]> {
    for col in 0..8 {
        let pivot = (col..8).max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs()))?;
        if a[pivot][col].abs() < 1e-12 {
            return None;
        }
        a.swap(col, pivot);
        let pivot_row = a[col];
        for (r, row) in a.iter_mut().enumerate() {
            if r != col {
                let f = row[col] / pivot_row[col];
                if f != 0.0 {
                    for (x, p) in row.iter_mut().zip(&pivot_row).skip(col) {
                        *x -= f * p;
                    }
                }
            }
        }
    }
    let mut x = [0.0; 8];
    for (i, xi) in x.iter_mut().enumerate() {
        *xi = a[i][8] / a[i][i];
    }
    Some(x)
}

/// Interpolation filter for resampling.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Resample {
    Nearest,
    Bilinear,
    /// Cubic convolution with a = -0.75, as OpenCV's `INTER_CUBIC` (the reference code's).
    Bicubic,
}

impl Resample {
    /// Parse `nearest`, `bilinear` or `bicubic`.
    pub fn parse(name: &str) -> Option<Resample> {
        match name {
            "nearest" => Some(Resample::Nearest),
            "bilinear" => Some(Resample::Bilinear),
            "bicubic" => Some(Resample::Bicubic),
            _ => None,
        }
    }
}

const CUBIC_A: f64 = -0.75;

/// Cubic convolution weights for the 4 taps at offsets -1, 0, 1, 2 around fraction `t`.
fn cubic_weights(t: f64) -> [f64; 4] {
    fn near(x: f64) -> f64 {
        ((CUBIC_A + 2.0) * x - (CUBIC_A + 3.0)) * x * x + 1.0
    }
    fn far(x: f64) -> f64 {
        ((CUBIC_A * x - 5.0 * CUBIC_A) * x + 8.0 * CUBIC_A) * x - 4.0 * CUBIC_A
    }
    if t == 0.0 {
        return [0.0, 1.0, 0.0, 0.0];
    }
    [far(1.0 + t), near(t), near(1.0 - t), far(2.0 - t)]
}

/// `floor` without a libm call (exact for |x| < 2^52).
#[inline]
fn fast_floor(x: f64) -> i64 {
    let t = x as i64;
    t - i64::from((t as f64) > x)
}

/// Round a value in [0, 255] (after clamping) to u8.
#[inline]
fn to_u8(v: f64) -> u8 {
    (v.clamp(0.0, 255.0) + 0.5) as u8
}

/// Sample `src` at continuous point (x, y) (see the module conventions) into `out`.
fn sample_at(src: &RgbImage, x: f64, y: f64, filter: Resample, out: &mut [u8; 3]) {
    let (w, h) = (i64::from(src.width()), i64::from(src.height()));
    let raw = src.as_raw();
    // Clamped to the image, so the index is in range; the image is non-empty (checked by the
    // caller).
    let px = |ix: i64, iy: i64| -> usize {
        let ix = ix.clamp(0, w - 1);
        let iy = iy.clamp(0, h - 1);
        ((iy * w + ix) * 3) as usize
    };
    // index coordinates: pixel centres at integers; far-away points clamp to the border
    let fx = (x - 0.5).clamp(-4.0, w as f64 + 4.0);
    let fy = (y - 0.5).clamp(-4.0, h as f64 + 4.0);
    match filter {
        Resample::Nearest => {
            let i = px(fast_floor(fx + 0.5), fast_floor(fy + 0.5));
            out.copy_from_slice(&raw[i..i + 3]);
        }
        Resample::Bilinear => {
            let (x0, y0) = (fast_floor(fx), fast_floor(fy));
            let (tx, ty) = (fx - x0 as f64, fy - y0 as f64);
            let mut acc = [0.0f64; 3];
            for (dy, wy) in [(0, 1.0 - ty), (1, ty)] {
                for (dx, wx) in [(0, 1.0 - tx), (1, tx)] {
                    let wgt = wx * wy;
                    if wgt != 0.0 {
                        let i = px(x0 + dx, y0 + dy);
                        for c in 0..3 {
                            acc[c] += wgt * f64::from(raw[i + c]);
                        }
                    }
                }
            }
            *out = acc.map(to_u8);
        }
        Resample::Bicubic => {
            let (x0, y0) = (fast_floor(fx), fast_floor(fy));
            let wx = cubic_weights(fx - x0 as f64);
            let wy = cubic_weights(fy - y0 as f64);
            let mut acc = [0.0f64; 3];
            if x0 >= 1 && y0 >= 1 && x0 + 2 < w && y0 + 2 < h {
                // interior: no clamping
                let stride = (w * 3) as usize;
                let base = (((y0 - 1) * w + (x0 - 1)) * 3) as usize;
                for (j, wyj) in wy.iter().enumerate() {
                    if *wyj == 0.0 {
                        continue;
                    }
                    let row = &raw[base + j * stride..base + j * stride + 12];
                    let mut r = [0.0f64; 3];
                    for (i, wxi) in wx.iter().enumerate() {
                        for c in 0..3 {
                            r[c] += wxi * f64::from(row[i * 3 + c]);
                        }
                    }
                    for c in 0..3 {
                        acc[c] += wyj * r[c];
                    }
                }
            } else {
                for (j, wyj) in wy.iter().enumerate() {
                    if *wyj == 0.0 {
                        continue;
                    }
                    let mut r = [0.0f64; 3];
                    for (i, wxi) in wx.iter().enumerate() {
                        let k = px(x0 + i as i64 - 1, y0 + j as i64 - 1);
                        for c in 0..3 {
                            r[c] += wxi * f64::from(raw[k + c]);
                        }
                    }
                    for c in 0..3 {
                        acc[c] += wyj * r[c];
                    }
                }
            }
            *out = acc.map(to_u8);
        }
    }
}

/// Render a `size` x `size` image whose pixel centre (u + 0.5, v + 0.5) shows the source at
/// `to_source((u + 0.5, v + 0.5))`. Points that map to infinity get the nearest border pixel
/// of the source's top-left corner (they do not occur for the warps used here).
///
/// `src` must not be empty.
pub fn render<F>(src: &RgbImage, size: u32, filter: Resample, to_source: F) -> RgbImage
where
    F: Fn(Point2) -> Option<Point2>,
{
    let mut out = RgbImage::new(size, size);
    if src.width() == 0 || src.height() == 0 {
        return out;
    }
    let mut px = [0u8; 3];
    for (u, v, pixel) in out.enumerate_pixels_mut() {
        let q = Point2::new(f64::from(u) + 0.5, f64::from(v) + 0.5);
        let p = to_source(q).unwrap_or(Point2::new(0.5, 0.5));
        sample_at(src, p.x, p.y, filter, &mut px);
        pixel.0 = px;
    }
    out
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn four_point_homography_maps_the_points() {
        let src = [
            Point2::new(0.0, 0.0),
            Point2::new(100.0, 0.0),
            Point2::new(100.0, 60.0),
            Point2::new(0.0, 60.0),
        ];
        let dst = [
            Point2::new(3.0, -4.0),
            Point2::new(110.0, 7.0),
            Point2::new(95.0, 70.0),
            Point2::new(-8.0, 55.0),
        ];
        let h = Homography::from_points(src, dst).unwrap();
        let inv = h.inverse().unwrap();
        for (s, d) in src.iter().zip(&dst) {
            let m = h.apply(*s).unwrap();
            assert!((m - *d).norm() < 1e-9, "{m:?} vs {d:?}");
            assert!((inv.apply(*d).unwrap() - *s).norm() < 1e-9);
        }
        // collinear points have no homography
        let line = [src[0], src[1], Point2::new(50.0, 0.0), src[3]];
        assert!(Homography::from_points(line, dst).is_none());
    }

    #[test]
    fn resampling_at_pixel_centres_is_exact() {
        let mut img = RgbImage::new(7, 5);
        for (x, y, p) in img.enumerate_pixels_mut() {
            p.0 = [(x * 30) as u8, (y * 50) as u8, ((x * y) % 256) as u8];
        }
        for filter in [Resample::Nearest, Resample::Bilinear, Resample::Bicubic] {
            let mut px = [0u8; 3];
            for (x, y, p) in img.enumerate_pixels() {
                sample_at(
                    &img,
                    f64::from(x) + 0.5,
                    f64::from(y) + 0.5,
                    filter,
                    &mut px,
                );
                assert_eq!(px, p.0, "{filter:?} at ({x}, {y})");
            }
        }
    }

    #[test]
    fn cubic_weights_sum_to_one() {
        for i in 0..=20 {
            let t = f64::from(i) / 20.0;
            let w = cubic_weights(t);
            assert!((w.iter().sum::<f64>() - 1.0).abs() < 1e-12, "{t}: {w:?}");
        }
    }
}
