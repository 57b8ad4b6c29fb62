#![allow(clippy::unwrap_used, clippy::expect_used)]
//! Inference with the mirrored-crop average.

use burn::tensor::Device;
use image::{Rgb, RgbImage};
use vpcal_net::{ModelConfig, StackedHourglass, VpNet};

/// A crop with structure (an asymmetric gradient and a bar) so that it differs from its mirror.
fn crop() -> RgbImage {
    RgbImage::from_fn(32, 32, |x, y| {
        let bar = if (8..14).contains(&x) && y > 10 {
            200
        } else {
            0
        };
        Rgb([(x * 7) as u8, (y * 5 + bar) as u8, ((x * y) % 251) as u8])
    })
}

#[test]
fn flip_average_maps_a_mirrored_crop_to_transposed_heatmaps() {
    let device = Device::flex();
    let config = ModelConfig::tiny();
    let model = StackedHourglass::new(&config, &device);
    let net = VpNet::new(model, config.clone(), &device).with_flip_average(true);
    let original = crop();
    let mirrored = image::imageops::flip_horizontal(&original);
    let a = net
        .predict(std::slice::from_ref(&original))
        .unwrap()
        .remove(0);
    let b = net.predict(&[mirrored]).unwrap().remove(0);
    let r = config.heatmap_size;
    let mut max_diff = 0.0f32;
    for (ca, cb) in a
        .heatmaps
        .chunks_exact(r * r)
        .zip(b.heatmaps.chunks_exact(r * r))
    {
        for i in 0..r {
            for j in 0..r {
                max_diff = max_diff.max((ca[i * r + j] - cb[j * r + i]).abs());
            }
        }
    }
    assert!(max_diff < 1e-5, "max difference {max_diff}");
    // Without the average the same untrained network is not mirror-symmetric, so the test
    // above checks the averaging and not a coincidence.
    let plain = net.with_flip_average(false);
    let a = plain
        .predict(std::slice::from_ref(&original))
        .unwrap()
        .remove(0);
    let b = plain
        .predict(&[image::imageops::flip_horizontal(&original)])
        .unwrap()
        .remove(0);
    let asym = a
        .heatmaps
        .chunks_exact(r * r)
        .zip(b.heatmaps.chunks_exact(r * r))
        .map(|(ca, cb)| {
            (0..r * r)
                .map(|k| (ca[k] - cb[(k % r) * r + k / r]).abs())
                .fold(0.0f32, f32::max)
        })
        .fold(0.0f32, f32::max);
    assert!(
        asym > 1e-4,
        "the untrained network is already symmetric ({asym})"
    );
}
