//! The scene without its traffic: the per-pixel median of frames sampled evenly over the input,
//! and the edgelets of the lines it shows (lane lines, kerbs, rails: VP1 evidence that does
//! not move, `vpcal_geom::aggregate::scene_lines`).
//!
//! A fixed camera sees each road pixel free of vehicles most of the time, so the median of
//! frames spread over the clip is the empty road; on a single picture it is that picture.

use image::{GrayImage, RgbImage};
use vpcal_geom::aggregate::edgelets::Edgelet;
use vpcal_geom::BoxPx;

use crate::edgelets::{edgelets_in_grey, EdgeletOptions};

/// Grey copies of frames spread evenly over an input of unknown length: every `every`-th
/// frame is kept, and whenever `cap` are held every second one is dropped and `every`
/// doubles, so that between `cap / 2` and `cap` frames, evenly spaced, are held at any time.
#[derive(Debug, Clone)]
pub struct BackgroundSampler {
    cap: usize,
    every: u64,
    seen: u64,
    size: Option<(u32, u32)>,
    frames: Vec<Vec<u8>>,
}

impl BackgroundSampler {
    /// A sampler holding at most `cap` frames (at least 2).
    pub fn new(cap: usize) -> BackgroundSampler {
        BackgroundSampler {
            cap: cap.max(2),
            every: 1,
            seen: 0,
            size: None,
            frames: Vec::new(),
        }
    }

    /// Look at the next frame. Frames of another size than the first are ignored.
    pub fn push(&mut self, image: &RgbImage) {
        let size = (image.width(), image.height());
        if *self.size.get_or_insert(size) != size {
            return;
        }
        let k = self.seen;
        self.seen += 1;
        if k % self.every != 0 {
            return;
        }
        // ITU-R 601 luma, as the vehicles' edgelets take it (here in OpenCV's fixed point,
        // 8 bits a pixel for the median).
        self.frames
            .push(crate::edges::grey_opencv(image).into_raw());
        if self.frames.len() >= self.cap {
            // Keep the frames at even positions: those at multiples of twice the interval.
            let mut i = 0;
            self.frames.retain(|_| {
                i += 1;
                (i - 1) % 2 == 0
            });
            self.every *= 2;
        }
    }

    /// Frames held.
    pub fn len(&self) -> usize {
        self.frames.len()
    }

    pub fn is_empty(&self) -> bool {
        self.frames.is_empty()
    }

    /// The per-pixel median of the frames held (the lower middle of an even count); `None`
    /// before any frame.
    pub fn median(&self) -> Option<GrayImage> {
        let (w, h) = self.size?;
        if self.frames.is_empty() {
            return None;
        }
        let n = self.frames.len();
        let mid = (n - 1) / 2;
        let mut column = vec![0u8; n];
        let data = (0..(w as usize * h as usize))
            .map(|i| {
                for (c, f) in column.iter_mut().zip(&self.frames) {
                    *c = f[i];
                }
                *column.select_nth_unstable(mid).1
            })
            .collect();
        GrayImage::from_raw(w, h, data)
    }
}

/// Settings of [`scene_edgelets`]: the vehicles' edgelet filters, but every coherent pixel
/// (no cell suppression, not only the pixels on the edge) and kernels reaching 4 standard
/// deviations. The scene's lines are few and long, and VP1 lies far along them: on the six
/// synthetic speed scenes' backgrounds VP1 from the vehicles' settings (one edgelet per 6-px
/// cell, kernels cut at 3) ended 1.3-3.3 px from the truth, from these 0.1-0.7 px.
pub fn scene_edgelet_options() -> EdgeletOptions {
    EdgeletOptions {
        cell: 1,
        reach_sigmas: 4.0,
        on_edge_only: false,
        ..EdgeletOptions::default()
    }
}

/// The edgelets of a background picture, over the whole frame but the band along its
/// border that the filters see past (where the replicated border bends the edges), strongest
/// first.
pub fn scene_edgelets(background: &GrayImage, opts: &EdgeletOptions) -> Vec<Edgelet> {
    let opts = EdgeletOptions {
        inset: opts
            .inset
            .max((opts.reach_sigmas * opts.sigma_t).ceil() as u32),
        ..*opts
    };
    let whole = BoxPx::new(
        0.0,
        0.0,
        f64::from(background.width()),
        f64::from(background.height()),
    );
    edgelets_in_grey(background, &whole, &opts)
}

/// Drop the edgelets where `mask` (of the picture's size) is black: what is not the scene
/// (a camera's overlay, another carriageway left out).
pub fn keep_inside(edgelets: &mut Vec<Edgelet>, mask: &GrayImage) {
    edgelets.retain(|e| mask.get_pixel(e.x as u32, e.y as u32).0[0] > 0);
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::Rgb;

    fn flat(v: u8) -> RgbImage {
        RgbImage::from_pixel(8, 4, Rgb([v, v, v]))
    }

    #[test]
    fn the_sampler_keeps_evenly_spaced_frames_up_to_its_cap() {
        for total in [1u8, 5, 7, 8, 9, 31, 100, 255] {
            let mut s = BackgroundSampler::new(8);
            for k in 0..total {
                s.push(&flat(k));
            }
            assert!(
                s.len() <= 8 && s.len() >= 4.min(usize::from(total)),
                "{total}: {}",
                s.len()
            );
            // The values held are the frame indices: 0, every, 2 every, ...
            let held: Vec<u8> = s.frames.iter().map(|f| f[0]).collect();
            let every = s.every as u8;
            assert!(
                held.iter()
                    .enumerate()
                    .all(|(i, &v)| u64::from(v) == i as u64 * u64::from(every)),
                "{total}: {held:?}"
            );
            assert!(
                u64::from(*held.last().unwrap()) + s.every > u64::from(total) - 1,
                "{total}: {held:?} every {every}"
            );
        }
    }

    #[test]
    fn the_median_is_the_road_without_the_vehicles_that_pass() {
        let mut s = BackgroundSampler::new(16);
        for k in 0..30u32 {
            // Road grey 100; a bright "vehicle" covers a different column in each frame.
            let mut im = flat(100);
            for y in 0..4 {
                im.put_pixel(k % 8, y, Rgb([250, 250, 250]));
            }
            s.push(&im);
        }
        let m = s.median().unwrap();
        assert!(m.pixels().all(|p| p.0[0] == 100), "{:?}", m);
        // Frames of another size are ignored.
        s.push(&RgbImage::new(3, 3));
        assert_eq!(s.median().unwrap().dimensions(), (8, 4));
        assert!(BackgroundSampler::new(4).median().is_none());
    }

    #[test]
    fn scene_edgelets_follow_the_lines_of_the_background() {
        // A bright line from (10, 90) towards (150, 10) on a dark ground.
        let (a, b) = ((10.0f64, 90.0f64), (150.0f64, 10.0f64));
        let dir = (b.0 - a.0, b.1 - a.1);
        let len = dir.0.hypot(dir.1);
        let img = GrayImage::from_fn(160, 100, |x, y| {
            let (px, py) = (f64::from(x) + 0.5 - a.0, f64::from(y) + 0.5 - a.1);
            let d = (px * dir.1 - py * dir.0).abs() / len;
            image::Luma([if d < 1.5 { 220 } else { 40 }])
        });
        let e = scene_edgelets(&img, &scene_edgelet_options());
        assert!(e.len() > 10, "{}", e.len());
        let angle = dir.1.atan2(dir.0);
        for x in &e {
            let diff = (x.angle - angle).sin().abs();
            assert!(diff < 0.05, "{x:?}");
        }
    }
}
