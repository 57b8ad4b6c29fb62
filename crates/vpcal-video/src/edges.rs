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

/// `tan(22.5°)`.
const TAN_22_5: f64 = 0.414_213_562_373_095_05;
/// `tan(67.5°)`.
const TAN_67_5: f64 = 2.414_213_562_373_095;

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
    let low = low.floor() as i32;
    let high = high.floor() as i32;
    let px: &[u8] = gray;
    let at = |x: isize, y: isize| -> i32 {
        let xc = x.clamp(0, wu as isize - 1) as usize;
        let yc = y.clamp(0, hu as isize - 1) as usize;
        i32::from(px[yc * wu + xc])
    };
    let n = wu * hu;
    let mut dx = vec![0i32; n];
    let mut dy = vec![0i32; n];
    let mut mag = vec![0i32; n];
    for y in 0..hu {
        for x in 0..wu {
            let (xi, yi) = (x as isize, y as isize);
            let gx = (at(xi + 1, yi - 1) + 2 * at(xi + 1, yi) + at(xi + 1, yi + 1))
                - (at(xi - 1, yi - 1) + 2 * at(xi - 1, yi) + at(xi - 1, yi + 1));
            let gy = (at(xi - 1, yi + 1) + 2 * at(xi, yi + 1) + at(xi + 1, yi + 1))
                - (at(xi - 1, yi - 1) + 2 * at(xi, yi - 1) + at(xi + 1, yi - 1));
            let i = y * wu + x;
            dx[i] = gx;
            dy[i] = gy;
            mag[i] = gx.abs() + gy.abs();
        }
    }
    let m_at = |x: isize, y: isize| -> i32 {
        if x < 0 || y < 0 || x >= wu as isize || y >= hu as isize {
            0
        } else {
            mag[y as usize * wu + x as usize]
        }
    };
    // 0 = not an edge, 1 = weak candidate, 2 = edge.
    let mut state = vec![0u8; n];
    let mut stack: Vec<usize> = Vec::new();
    for y in 0..hu {
        for x in 0..wu {
            let i = y * wu + x;
            let m = mag[i];
            if m <= low {
                continue;
            }
            let (xi, yi) = (x as isize, y as isize);
            let ax = f64::from(dx[i].abs());
            let ay = f64::from(dy[i].abs());
            let is_max = if ay < ax * TAN_22_5 {
                m > m_at(xi - 1, yi) && m >= m_at(xi + 1, yi)
            } else if ay > ax * TAN_67_5 {
                m > m_at(xi, yi - 1) && m >= m_at(xi, yi + 1)
            } else {
                let s: isize = if (dx[i] < 0) != (dy[i] < 0) { -1 } else { 1 };
                m > m_at(xi - s, yi - 1) && m > m_at(xi + s, yi + 1)
            };
            if !is_max {
                continue;
            }
            if m > high {
                state[i] = 2;
                stack.push(i);
            } else {
                state[i] = 1;
            }
        }
    }
    while let Some(i) = stack.pop() {
        let (x, y) = ((i % wu) as isize, (i / wu) as isize);
        for (ox, oy) in [
            (-1, -1),
            (0, -1),
            (1, -1),
            (-1, 0),
            (1, 0),
            (-1, 1),
            (0, 1),
            (1, 1),
        ] {
            let (nx, ny) = (x + ox, y + oy);
            if nx < 0 || ny < 0 || nx >= wu as isize || ny >= hu as isize {
                continue;
            }
            let j = ny as usize * wu + nx as usize;
            if state[j] == 1 {
                state[j] = 2;
                stack.push(j);
            }
        }
    }
    for (o, s) in out.iter_mut().zip(state) {
        *o = if s == 2 { 255 } else { 0 };
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
