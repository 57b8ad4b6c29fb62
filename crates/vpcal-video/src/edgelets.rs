//! Edgelets: short straight pieces of image edges with a position and a direction, found
//! inside vehicle boxes. Edges of a car that run across it (bumpers, window sills, roof
//! edges) point at VP2; the robust aggregation uses them to place the horizon and, when VP2
//! is near enough to be located, the focal length (`vpcal_geom::aggregate::edgelets`).
//!
//! Orientation comes from the structure tensor: Gaussian-derivative gradients (`sigma_d`)
//! whose outer products are smoothed over `sigma_t`. The larger integration scale matters:
//! a nearly horizontal edge is drawn on the pixel grid as horizontal runs with steps, and at
//! `sigma_t` 1.5 px the tensor sees the runs (biasing roll towards 0°); at 3 px it sees the
//! line (measured on the synthetic suite: horizon roll from edgelets 4.7° off at 1.5 px,
//! 0.8° at 3 px on synth05).

use image::{GrayImage, RgbImage};
use vpcal_geom::aggregate::edgelets::Edgelet;
use vpcal_geom::BoxPx;

/// Settings of the edgelet extraction.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EdgeletOptions {
    /// Gaussian derivative scale of the gradients, pixels.
    pub sigma_d: f32,
    /// Integration scale of the structure tensor, pixels.
    pub sigma_t: f32,
    /// Least coherence `(λ1 - λ2) / (λ1 + λ2)`: how much one direction dominates.
    pub min_coherence: f32,
    /// Least RMS gradient magnitude (grey levels per pixel).
    pub min_magnitude: f32,
    /// Non-maximum suppression cell, pixels: at most one edgelet per cell (where the gradient
    /// is largest).
    pub cell: u32,
    /// Edgelets are kept this many pixels inside the box (the filters read the pixels
    /// around the box, so the box's border does not bias them).
    pub inset: u32,
    /// Boxes smaller than this (width, height) give none.
    pub min_box: (u32, u32),
    /// The Gaussian kernels reach this many standard deviations. The square of a separable
    /// kernel cut off at 3 is not quite round: it turns edges by a few hundredths of a degree
    /// depending on their angle, which a long line far from its vanishing point turns into
    /// pixels (`crate::background`).
    pub reach_sigmas: f32,
    /// Only pixels on an edge (whose gradient is at least the tensor's RMS) give edgelets;
    /// else every coherent pixel within the tensor's reach of one does.
    pub on_edge_only: bool,
}

impl Default for EdgeletOptions {
    fn default() -> Self {
        EdgeletOptions {
            sigma_d: 1.0,
            sigma_t: 3.0,
            min_coherence: 0.8,
            min_magnitude: 8.0,
            cell: 6,
            inset: 2,
            min_box: (16, 8),
            reach_sigmas: 3.0,
            on_edge_only: true,
        }
    }
}

/// A normalised 1-D Gaussian (`order` 0) or its derivative (`order` 1), radius `reach sigma`.
pub(crate) fn kernel(sigma: f32, order: u8, reach: f32) -> Vec<f32> {
    let r = (reach * sigma).ceil().max(1.0) as i32;
    let g: Vec<f32> = (-r..=r)
        .map(|i| (-(i * i) as f32 / (2.0 * sigma * sigma)).exp())
        .collect();
    let sum: f32 = g.iter().sum();
    if order == 0 {
        return g.iter().map(|v| v / sum).collect();
    }
    // d/dx of the Gaussian: -x / sigma² g(x); as a correlation kernel it gives the
    // derivative towards +x.
    (-r..=r)
        .zip(&g)
        .map(|(i, v)| i as f32 / (sigma * sigma) * v / sum)
        .collect()
}

/// Correlate each row (`horizontal`) or column with `k`, borders replicated.
///
/// Each output is `k[0] * a[0] + k[1] * a[1] + ...` summed in that order from -0.0 (as
/// `Iterator::sum` does), but written tap by tap over whole rows, so that the inner loops are
/// element-wise and vectorise: the columns' pass adds rows, the rows' pass shifted copies of
/// one padded row.
pub(crate) fn convolve(src: &[f32], w: usize, h: usize, k: &[f32], horizontal: bool) -> Vec<f32> {
    let r = k.len() / 2;
    let mut out = vec![-0.0f32; w * h];
    if w == 0 || h == 0 {
        return out;
    }
    if horizontal {
        let mut padded = vec![0.0f32; w + 2 * r];
        for (row, out) in src.chunks_exact(w).zip(out.chunks_exact_mut(w)) {
            for (i, p) in padded.iter_mut().enumerate() {
                *p = row[i.saturating_sub(r).min(w - 1)];
            }
            for (t, &kt) in k.iter().enumerate() {
                for (o, &a) in out.iter_mut().zip(&padded[t..t + w]) {
                    *o += kt * a;
                }
            }
        }
    } else {
        for (y, out) in out.chunks_exact_mut(w).enumerate() {
            for (t, &kt) in k.iter().enumerate() {
                let sy = (y + t).saturating_sub(r).min(h - 1);
                for (o, &a) in out.iter_mut().zip(&src[sy * w..(sy + 1) * w]) {
                    *o += kt * a;
                }
            }
        }
    }
    out
}

/// Edgelets of `image` inside `bx` (shrunk by the inset, clamped to the image), in frame
/// pixels, strongest first.
pub fn edgelets_in_box(image: &RgbImage, bx: &BoxPx, opts: &EdgeletOptions) -> Vec<Edgelet> {
    let grey = |x, y| {
        let p = image.get_pixel(x, y).0;
        0.299 * f32::from(p[0]) + 0.587 * f32::from(p[1]) + 0.114 * f32::from(p[2])
    };
    edgelets_in((image.width(), image.height()), grey, bx, opts)
}

/// Edgelets of a grey `image` (the same as [`edgelets_in_box`] of its RGB copy) inside `bx`.
pub fn edgelets_in_grey(image: &GrayImage, bx: &BoxPx, opts: &EdgeletOptions) -> Vec<Edgelet> {
    let grey = |x, y| f32::from(image.get_pixel(x, y).0[0]);
    edgelets_in((image.width(), image.height()), grey, bx, opts)
}

/// Edgelets of the image of `size` whose grey level at (x, y) is `grey(x, y)`, inside `bx`.
fn edgelets_in(
    size: (u32, u32),
    grey_at: impl Fn(u32, u32) -> f32,
    bx: &BoxPx,
    opts: &EdgeletOptions,
) -> Vec<Edgelet> {
    let (iw, ih) = (f64::from(size.0), f64::from(size.1));
    // Where edgelets may lie.
    let k = f64::from(opts.inset);
    let kx0 = (bx.x0 + k).ceil().clamp(0.0, iw);
    let ky0 = (bx.y0 + k).ceil().clamp(0.0, ih);
    let kx1 = (bx.x1 - k).floor().clamp(0.0, iw);
    let ky1 = (bx.y1 - k).floor().clamp(0.0, ih);
    let (bw, bh) = (bx.x1 - bx.x0, bx.y1 - bx.y0);
    if !(bw >= f64::from(opts.min_box.0)
        && bh >= f64::from(opts.min_box.1)
        && kx1 > kx0
        && ky1 > ky0)
    {
        return Vec::new();
    }
    // The pixels the filters read: the filters' reach around it.
    let reach = opts.reach_sigmas;
    let pad = (reach * opts.sigma_t).ceil() as f64 + (reach * opts.sigma_d).ceil() as f64;
    let x0 = (kx0 - pad).max(0.0) as u32;
    let y0 = (ky0 - pad).max(0.0) as u32;
    let x1 = (kx1 + pad).min(iw) as u32;
    let y1 = (ky1 + pad).min(ih) as u32;
    let (w, h) = ((x1 - x0) as usize, (y1 - y0) as usize);
    let mut grey = Vec::with_capacity(w * h);
    for y in y0..y1 {
        for x in x0..x1 {
            grey.push(grey_at(x, y));
        }
    }
    let g0 = kernel(opts.sigma_d, 0, reach);
    let g1 = kernel(opts.sigma_d, 1, reach);
    let gx = convolve(&convolve(&grey, w, h, &g1, true), w, h, &g0, false);
    let gy = convolve(&convolve(&grey, w, h, &g0, true), w, h, &g1, false);
    let gt = kernel(opts.sigma_t, 0, reach);
    let smooth = |v: Vec<f32>| convolve(&convolve(&v, w, h, &gt, true), w, h, &gt, false);
    let jxx = smooth(gx.iter().map(|v| v * v).collect());
    let jyy = smooth(gy.iter().map(|v| v * v).collect());
    let jxy = smooth(gx.iter().zip(&gy).map(|(a, b)| a * b).collect());
    // Keep the strongest qualifying pixel per cell of the inner box.
    let cell = opts.cell.max(1) as usize;
    let cols = w.div_ceil(cell);
    let mut best: Vec<Option<(f32, usize)>> = vec![None; cols * h.div_ceil(cell)];
    let (ix0, iy0) = ((kx0 as u32 - x0) as usize, (ky0 as u32 - y0) as usize);
    let (ix1, iy1) = ((kx1 as u32 - x0) as usize, (ky1 as u32 - y0) as usize);
    for y in iy0..iy1 {
        for x in ix0..ix1 {
            let i = y * w + x;
            let tr = jxx[i] + jyy[i];
            if tr <= 0.0 {
                continue;
            }
            let d = ((jxx[i] - jyy[i]).powi(2) + 4.0 * jxy[i] * jxy[i]).sqrt();
            let mag = tr.sqrt();
            if d / tr < opts.min_coherence || mag < opts.min_magnitude {
                continue;
            }
            // The cell's edgelet sits where the gradient itself is largest (on the edge);
            // the smoothed tensor is as wide as its integration scale.
            // Off the edge but inside the tensor's reach, the gradient is far below the
            // tensor's RMS; on it, above.
            let g = (gx[i] * gx[i] + gy[i] * gy[i]).sqrt();
            if opts.on_edge_only && g < mag {
                continue;
            }
            let c = (y / cell) * cols + x / cell;
            if best[c].is_none_or(|(b, _)| g > b) {
                best[c] = Some((g, i));
            }
        }
    }
    let mut out: Vec<Edgelet> = best
        .into_iter()
        .flatten()
        .map(|(g, i)| {
            let (x, y) = (i % w, i / w);
            // The dominant gradient direction is 0.5 atan2(2 jxy, jxx - jyy); the edge runs
            // across it.
            let grad = 0.5 * f64::from(2.0 * jxy[i]).atan2(f64::from(jxx[i] - jyy[i]));
            Edgelet {
                x: f64::from(x0) + x as f64 + 0.5,
                y: f64::from(y0) + y as f64 + 0.5,
                angle: grad + std::f64::consts::FRAC_PI_2,
                strength: f64::from(g),
            }
        })
        .collect();
    out.sort_by(|a, b| b.strength.total_cmp(&a.strength));
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each output as one dot product of the replicated-border window with the kernel.
    fn convolve_by_windows(
        src: &[f32],
        w: usize,
        h: usize,
        k: &[f32],
        horizontal: bool,
    ) -> Vec<f32> {
        let r = k.len() as i64 / 2;
        let mut out = vec![0.0f32; w * h];
        for y in 0..h {
            for x in 0..w {
                let at = |t: usize| {
                    let d = t as i64 - r;
                    let (sx, sy) = if horizontal {
                        ((x as i64 + d).clamp(0, w as i64 - 1) as usize, y)
                    } else {
                        (x, (y as i64 + d).clamp(0, h as i64 - 1) as usize)
                    };
                    src[sy * w + sx]
                };
                out[y * w + x] = (0..k.len()).map(|t| k[t] * at(t)).sum();
            }
        }
        out
    }

    #[test]
    fn convolution_is_the_windows_dot_products_bit_for_bit() {
        let k = kernel(1.5, 1, 3.0);
        for (w, h) in [(37, 23), (3, 2), (1, 9), (40, 1)] {
            let src: Vec<f32> = (0..w * h)
                .map(|i| ((i * 7919) % 257) as f32 * 0.37 - 40.0)
                .collect();
            for horizontal in [true, false] {
                let got = convolve(&src, w, h, &k, horizontal);
                let want = convolve_by_windows(&src, w, h, &k, horizontal);
                let same = got
                    .iter()
                    .zip(&want)
                    .all(|(a, b)| a.to_bits() == b.to_bits());
                assert!(same, "{w}x{h} horizontal {horizontal}");
            }
        }
    }
    use image::Rgb;

    /// The point the test edge runs through (off the sample grid, so that no subsample lies
    /// exactly on the edge).
    const ON: (f64, f64) = (100.37, 60.21);

    /// A 200x120 image: dark on one side of the line through `ON` at `deg`, bright on the
    /// other, antialiased by 4x4 supersampling.
    fn half_plane(deg: f64) -> RgbImage {
        let (s, c) = deg.to_radians().sin_cos();
        RgbImage::from_fn(200, 120, |x, y| {
            let mut on = 0u32;
            for sy in 0..4 {
                for sx in 0..4 {
                    let px = f64::from(x) + (f64::from(sx) + 0.5) / 4.0 - ON.0;
                    let py = f64::from(y) + (f64::from(sy) + 0.5) / 4.0 - ON.1;
                    // Signed distance from the line with direction (c, s).
                    if px * s - py * c > 0.0 {
                        on += 1;
                    }
                }
            }
            let v = (40 + on * 160 / 16) as u8;
            Rgb([v, v, v])
        })
    }

    fn line_diff_deg(a: f64, b: f64) -> f64 {
        let d = (a - b).rem_euclid(std::f64::consts::PI);
        d.min(std::f64::consts::PI - d).to_degrees()
    }

    #[test]
    fn edgelets_follow_an_edge_at_any_angle() {
        for deg in [0.0, 2.0, 3.5, 10.0, 45.0, 80.0, 93.0, 170.0] {
            let img = half_plane(deg);
            let e = edgelets_in_box(
                &img,
                &BoxPx::new(20.0, 20.0, 180.0, 100.0),
                &EdgeletOptions::default(),
            );
            assert!(e.len() >= 5, "{deg}°: {} edgelets", e.len());
            let (s, c) = deg.to_radians().sin_cos();
            for el in &e {
                assert!(
                    line_diff_deg(el.angle, deg.to_radians()) < 0.3,
                    "{deg}°: edgelet at {:.1},{:.1} has {:.2}°",
                    el.x,
                    el.y,
                    el.angle.to_degrees()
                );
                // On the edge: within the tensor's scale of the line.
                let dist = (el.x - ON.0) * s - (el.y - ON.1) * c;
                assert!(dist.abs() < 4.0, "{deg}°: {dist} px off the edge");
            }
        }
    }

    #[test]
    fn flat_and_tiny_boxes_give_none() {
        let flat = RgbImage::from_pixel(100, 100, Rgb([90, 90, 90]));
        let o = EdgeletOptions::default();
        assert!(edgelets_in_box(&flat, &BoxPx::new(10.0, 10.0, 90.0, 90.0), &o).is_empty());
        let img = half_plane(30.0);
        assert!(edgelets_in_box(&img, &BoxPx::new(90.0, 55.0, 100.0, 62.0), &o).is_empty());
        // A box outside the image.
        assert!(edgelets_in_box(&img, &BoxPx::new(300.0, 200.0, 400.0, 260.0), &o).is_empty());
    }
}
