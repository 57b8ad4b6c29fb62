//! Sensor and photometric augmentation: what real traffic cameras do to a picture and the
//! renderer does not (sim-to-real for synthetic crops; also varies real crops).
//!
//! Each effect is applied independently with the same probability `p`, in the order a camera
//! would: a partial occluder in the scene (a flat-ish patch entering from one side of the crop,
//! as a pole, a sign or a neighbouring vehicle does), exposure and colour (gain, offset, white
//! balance, saturation), optics (Gaussian blur), resolution (down-sampling then up-sampling
//! back), sensor noise (Gaussian), and compression (JPEG at a low quality). Geometry is
//! untouched: the VPs stay exact.
//!
//! The ranges cover what the real corpus shows (`../shared/data/traffic_corpus`: 320x240
//! webcams with heavy compression, hazy motorway webcams, night scenes, telephoto blur):
//! gain 0.55-1.45, offset ±30, per-channel gain ±12 %, saturation 0.3-1.2, blur σ 0.3-1.6 px,
//! down-sampling by 1.5-3.5 (1.5-8 in the `real-small` preset, for far vehicles), noise σ 2-10 (8-bit levels), JPEG quality 15-70; occluders cover
//! 8-30 % of the crop's width or height.

use image::{ImageBuffer, Rgb, RgbImage};
use rand::Rng;

/// Apply each sensor effect with probability `p` (0 returns the image unchanged and draws
/// nothing from `rng`), the down-sampling by a factor from 1.5 to `max_downsample`.
pub fn sensor_effects<R: Rng + ?Sized>(
    image: RgbImage,
    p: f64,
    max_downsample: f64,
    rng: &mut R,
) -> RgbImage {
    if p <= 0.0 {
        return image;
    }
    let mut img = image;
    if rng.random::<f64>() < p {
        occlude(&mut img, rng);
    }
    if rng.random::<f64>() < p {
        img = exposure(&img, rng);
    }
    if rng.random::<f64>() < p {
        let sigma = rng.random_range(0.3..1.6);
        img = image::imageops::blur(&img, sigma);
    }
    if rng.random::<f64>() < p {
        img = low_resolution(&img, rng.random_range(1.5..max_downsample));
    }
    if rng.random::<f64>() < p {
        let sigma = rng.random_range(2.0..10.0);
        add_noise(&mut img, sigma, rng);
    }
    if rng.random::<f64>() < p {
        let quality = rng.random_range(15..=70u8);
        if let Some(j) = jpeg_round_trip(&img, quality) {
            img = j;
        }
    }
    img
}

fn exposure<R: Rng + ?Sized>(img: &RgbImage, rng: &mut R) -> RgbImage {
    let gain = rng.random_range(0.55..1.45);
    let offset = rng.random_range(-30.0..30.0);
    let wb = [
        rng.random_range(0.88..1.12),
        rng.random_range(0.88..1.12),
        rng.random_range(0.88..1.12),
    ];
    let sat: f64 = rng.random_range(0.3..1.2);
    ImageBuffer::from_fn(img.width(), img.height(), |x, y| {
        let p = img.get_pixel(x, y).0.map(f64::from);
        let grey = 0.299 * p[0] + 0.587 * p[1] + 0.114 * p[2];
        let mut out = [0u8; 3];
        for c in 0..3 {
            let v = (grey + sat * (p[c] - grey)) * gain * wb[c] + offset;
            out[c] = v.round().clamp(0.0, 255.0) as u8;
        }
        Rgb(out)
    })
}

/// Cover a band along one side of the image (8-30 % of its extent) with a textured flat colour.
fn occlude<R: Rng + ?Sized>(img: &mut RgbImage, rng: &mut R) {
    let (w, h) = img.dimensions();
    let side = rng.random_range(0..4u8);
    let frac = rng.random_range(0.08..0.30);
    let along = rng.random_range(0.3..1.0);
    let (bw, bh) = if side < 2 {
        (
            (f64::from(w) * frac).ceil() as u32,
            (f64::from(h) * along).ceil() as u32,
        )
    } else {
        (
            (f64::from(w) * along).ceil() as u32,
            (f64::from(h) * frac).ceil() as u32,
        )
    };
    let (bw, bh) = (bw.clamp(1, w), bh.clamp(1, h));
    let (x0, y0) = match side {
        0 => (0, rng.random_range(0..=h - bh)),
        1 => (w - bw, rng.random_range(0..=h - bh)),
        2 => (rng.random_range(0..=w - bw), 0),
        _ => (rng.random_range(0..=w - bw), h - bh),
    };
    let base: [f64; 3] = [
        rng.random_range(0.0..255.0),
        rng.random_range(0.0..255.0),
        rng.random_range(0.0..255.0),
    ];
    for y in y0..y0 + bh {
        for x in x0..x0 + bw {
            let t = rng.random_range(-12.0..12.0);
            let px = base.map(|c| (c + t).round().clamp(0.0, 255.0) as u8);
            img.put_pixel(x, y, Rgb(px));
        }
    }
}

fn low_resolution(img: &RgbImage, factor: f64) -> RgbImage {
    let (w, h) = img.dimensions();
    let small_w = ((f64::from(w) / factor).round() as u32).max(2);
    let small_h = ((f64::from(h) / factor).round() as u32).max(2);
    let small =
        image::imageops::resize(img, small_w, small_h, image::imageops::FilterType::Triangle);
    image::imageops::resize(&small, w, h, image::imageops::FilterType::Triangle)
}

fn add_noise<R: Rng + ?Sized>(img: &mut RgbImage, sigma: f64, rng: &mut R) {
    for v in img.iter_mut() {
        // Box-Muller.
        let u1: f64 = 1.0 - rng.random::<f64>();
        let u2: f64 = rng.random::<f64>();
        let n = (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos();
        *v = (f64::from(*v) + sigma * n).round().clamp(0.0, 255.0) as u8;
    }
}

fn jpeg_round_trip(img: &RgbImage, quality: u8) -> Option<RgbImage> {
    let mut bytes = Vec::new();
    let encoder = image::codecs::jpeg::JpegEncoder::new_with_quality(&mut bytes, quality);
    img.write_with_encoder(encoder).ok()?;
    image::load_from_memory_with_format(&bytes, image::ImageFormat::Jpeg)
        .ok()
        .map(|d| d.to_rgb8())
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    fn gradient() -> RgbImage {
        ImageBuffer::from_fn(64, 64, |x, y| Rgb([(x * 4) as u8, (y * 4) as u8, 128]))
    }

    #[test]
    fn probability_zero_changes_nothing_and_draws_nothing() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        let img = gradient();
        assert_eq!(sensor_effects(img.clone(), 0.0, 3.5, &mut rng), img);
        let mut fresh = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        assert_eq!(rng.random::<u64>(), fresh.random::<u64>());
    }

    #[test]
    fn every_effect_keeps_the_size_and_changes_the_pixels() {
        let img = gradient();
        for seed in 0..8 {
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
            let out = sensor_effects(img.clone(), 1.0, 3.5, &mut rng);
            assert_eq!(out.dimensions(), img.dimensions());
            assert_ne!(out, img, "seed {seed}");
        }
    }

    #[test]
    fn an_occluder_covers_one_side_and_leaves_the_rest() {
        for seed in 0..16 {
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
            let img = gradient();
            let mut out = img.clone();
            occlude(&mut out, &mut rng);
            let changed: Vec<(u32, u32)> = out
                .enumerate_pixels()
                .filter(|(x, y, p)| *p != img.get_pixel(*x, *y))
                .map(|(x, y, _)| (x, y))
                .collect();
            let n = changed.len() as f64 / (64.0 * 64.0);
            assert!(n > 0.0 && n <= 0.31, "seed {seed}: {n}");
            // The band touches a border of the crop.
            assert!(changed
                .iter()
                .any(|&(x, y)| x == 0 || y == 0 || x == 63 || y == 63));
        }
    }

    #[test]
    fn low_resolution_removes_fine_detail() {
        // A one-pixel checkerboard averages out to grey when down-sampled by 2 or more.
        let board = ImageBuffer::from_fn(32, 32, |x, y| {
            if (x + y) % 2 == 0 {
                Rgb([255u8, 255, 255])
            } else {
                Rgb([0u8, 0, 0])
            }
        });
        let out = low_resolution(&board, 3.0);
        let contrast = out.pixels().map(|p| i32::from(p.0[0])).max().unwrap()
            - out.pixels().map(|p| i32::from(p.0[0])).min().unwrap();
        assert!(contrast < 128, "{contrast}");
    }
}
