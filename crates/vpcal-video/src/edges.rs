//! Canny edges with OpenCV's conventions, for the static-vehicle rule (DESIGN.md §7).
//!
//! The reference called `cv2.Canny(grey, 100, 200)`. OpenCV's Canny (aperture 3, L1 gradient,
//! the defaults) and `imageproc::edges::canny` differ enough that the thresholds 100/200 mean
//! different things:
//!
//! | step | OpenCV (`cv2.Canny`, reproduced here) | `imageproc::edges::canny` |
//! |---|---|---|
//! | smoothing | none | Gaussian blur σ = 1.4 first |
//! | gradient | 3×3 Sobel, border replicated | 3×3 Sobel on the blurred image |
//! | magnitude | L1: `|gx| + |gy|` | L2: `sqrt(gx² + gy²)` |
//! | thresholds | floored to integers; `m > low`, `m > high` | `m >= low`, `m >= high` |
//! | border pixels | can be edges (outside magnitude is 0) | never edges |
//!
//! The blur alone removes most weak texture edges, so at 100/200 imageproc finds far fewer
//! edges than OpenCV and the rule's threshold of 5 would drop more boxes. This module follows
//! OpenCV: non-maximum suppression in four directions with `tan 22.5°` sectors (a pixel must
//! be greater than the neighbour before it and at least the neighbour after it along the
//! gradient; diagonals strictly greater on both sides), then hysteresis over 8-neighbours.

use image::{GrayImage, RgbImage};

/// Grey levels as OpenCV's `cvtColor(.., COLOR_RGB2GRAY)` computes them for 8-bit images:
/// `(4899 R + 9617 G + 1868 B + 8192) >> 14`, i.e. 0.299 R + 0.587 G + 0.114 B rounded.
/// (`image::imageops::grayscale` uses the Rec. 709 weights 0.2126/0.7152/0.0722 instead.)
pub fn grey_opencv(rgb: &RgbImage) -> GrayImage {
    let mut out = GrayImage::new(rgb.width(), rgb.height());
    for (o, p) in out.iter_mut().zip(rgb.as_raw().chunks_exact(3)) {
        let v = 4899 * u32::from(p[0]) + 9617 * u32::from(p[1]) + 1868 * u32::from(p[2]) + 8192;
        // Why: the weights sum to 2^14, so the result is at most 255.
        *o = (v >> 14) as u8;
    }
    out
}

/// `tan(22.5°) · 2^15`, rounded; `tan(67.5°) = tan(22.5°) + 2`, so its test is
/// `tg22x + 2 · 2^15 · |gx|`.
const TAN_22_5_Q15: i64 = 13573;

/// Edges of `gray` as OpenCV's `cv2.Canny(gray, low, high)` finds them (aperture 3, L1
/// gradient): 255 on edges, 0 elsewhere.
pub fn canny_opencv(gray: &GrayImage, low: f32, high: f32) -> GrayImage {
    let (w, h) = gray.dimensions();
    let (wu, hu) = (w as usize, h as usize);
    let mut out = GrayImage::new(w, h);
    if wu == 0 || hu == 0 {
        return out;
    }
    let (low, high) = if low > high { (high, low) } else { (low, high) };
    // Why: OpenCV floors the thresholds for the integer (L1) magnitude.
    let low = low.floor().clamp(-1.0, 4096.0) as i16;
    let high = high.floor().clamp(-1.0, 4096.0) as i16;
    let px: &[u8] = gray;

    // The image with a replicated 1-pixel border (OpenCV's Sobel uses BORDER_REPLICATE).
    let pw = wu + 2;
    let mut padded = vec![0u8; pw * (hu + 2)];
    for py in 0..hu + 2 {
        let sy = py.saturating_sub(1).min(hu - 1);
        let row = &px[sy * wu..(sy + 1) * wu];
        let dst = &mut padded[py * pw..(py + 1) * pw];
        dst[0] = row[0];
        dst[pw - 1] = row[wu - 1];
        dst[1..pw - 1].copy_from_slice(row);
    }
    // Gradients and L1 magnitude; the magnitude has a zero border (outside the image).
    let n = wu * hu;
    // |gx|, |gy| <= 4 · 255 and their sum <= 2040: i16 holds them, as in OpenCV.
    let mut dx = vec![0i16; n];
    let mut dy = vec![0i16; n];
    let mut mag = vec![0i16; pw * (hu + 2)];
    for y in 0..hu {
        let r0 = &padded[y * pw..(y + 1) * pw];
        let r1 = &padded[(y + 1) * pw..(y + 2) * pw];
        let r2 = &padded[(y + 2) * pw..(y + 3) * pw];
        let dxr = &mut dx[y * wu..(y + 1) * wu];
        let dyr = &mut dy[y * wu..(y + 1) * wu];
        let mr = &mut mag[(y + 1) * pw + 1..(y + 1) * pw + 1 + wu];
        for x in 0..wu {
            let v = |r: &[u8], i: usize| i16::from(r[i]);
            let gx = (v(r0, x + 2) + 2 * v(r1, x + 2) + v(r2, x + 2))
                - (v(r0, x) + 2 * v(r1, x) + v(r2, x));
            let gy = (v(r2, x) + 2 * v(r2, x + 1) + v(r2, x + 2))
                - (v(r0, x) + 2 * v(r0, x + 1) + v(r0, x + 2));
            dxr[x] = gx;
            dyr[x] = gy;
            mr[x] = gx.abs() + gy.abs();
        }
    }
    // Non-maximum suppression on the padded grid. 0 = not an edge, 1 = weak candidate,
    // 2 = edge; the border stays 0.
    let mut state = vec![0u8; pw * (hu + 2)];
    let mut stack: Vec<usize> = Vec::new();
    for y in 0..hu {
        for x in 0..wu {
            let p = (y + 1) * pw + x + 1;
            let m = mag[p];
            if m <= low {
                continue;
            }
            let (gx, gy) = (dx[y * wu + x], dy[y * wu + x]);
            // tan 22.5° and tan 67.5° in 15-bit fixed point, as OpenCV compares them.
            let ax = i64::from(gx.abs());
            let ay = i64::from(gy.abs()) << 15;
            let tg22x = ax * TAN_22_5_Q15;
            let is_max = if ay < tg22x {
                m > mag[p - 1] && m >= mag[p + 1]
            } else if ay > tg22x + (ax << 16) {
                m > mag[p - pw] && m >= mag[p + pw]
            } else if (gx < 0) != (gy < 0) {
                m > mag[p - pw + 1] && m > mag[p + pw - 1]
            } else {
                m > mag[p - pw - 1] && m > mag[p + pw + 1]
            };
            if !is_max {
                continue;
            }
            if m > high {
                state[p] = 2;
                stack.push(p);
            } else {
                state[p] = 1;
            }
        }
    }
    // Hysteresis: weak candidates 8-connected to an edge become edges.
    let offsets = [pw + 1, pw, pw - 1, 1];
    while let Some(p) = stack.pop() {
        for &o in &offsets {
            for q in [p - o, p + o] {
                if state[q] == 1 {
                    state[q] = 2;
                    stack.push(q);
                }
            }
        }
    }
    for (y, row) in out.chunks_exact_mut(wu).enumerate() {
        let srow = &state[(y + 1) * pw + 1..(y + 1) * pw + 1 + wu];
        for (o, &s) in row.iter_mut().zip(srow) {
            *o = if s == 2 { 255 } else { 0 };
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_step_edge_gives_one_thin_line() {
        // Left half 0, right half 200: a vertical edge between x = 9 and x = 10.
        let img = GrayImage::from_fn(20, 10, |x, _| image::Luma([if x < 10 { 0 } else { 200 }]));
        let e = canny_opencv(&img, 100.0, 200.0);
        for y in 0..10 {
            let row: Vec<u32> = (0..20).filter(|&x| e.get_pixel(x, y)[0] == 255).collect();
            assert_eq!(row.len(), 1, "row {y}: {row:?}");
            assert!(row[0] == 9 || row[0] == 10);
        }
    }

    #[test]
    fn flat_and_weak_images_have_no_edges() {
        let flat = GrayImage::from_pixel(16, 16, image::Luma([128]));
        assert!(canny_opencv(&flat, 100.0, 200.0).iter().all(|&v| v == 0));
        // A step of 20 grey levels gives |gx| = 80 < 100.
        let weak = GrayImage::from_fn(16, 16, |x, _| image::Luma([if x < 8 { 100 } else { 120 }]));
        assert!(canny_opencv(&weak, 100.0, 200.0).iter().all(|&v| v == 0));
    }
}
