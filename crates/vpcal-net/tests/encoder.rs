#![allow(clippy::unwrap_used, clippy::expect_used)]
//! The pretrained YOLOX-nano encoder against onnxruntime's feature maps of the original
//! detector, MobileNetV2 and EfficientNet-Lite0 against a numpy forward of their source
//! weights, and the encoder network's training, freezing, checkpoints and inference.

use burn::tensor::{Device, Tensor, TensorData};
use vpcal_net::encoder::{Backbone, Features, YoloxNano};
use vpcal_net::mobile::{MobileFamily, MobileNet};
use vpcal_net::network::to_vec;
use vpcal_net::store::named_tensors;
use vpcal_net::train::LrSchedule;
use vpcal_net::{BatchSource, EncoderNet, ModelConfig, ToySource, TrainConfig, Trainer, VpNet};

const GOLDEN: &str = include_str!("data/yolox_nano_backbone_golden.json");

/// The golden input of `scripts/convert_yolox_backbone.py`: 1x3x128x128, BGR 0-255.
fn golden_input() -> Vec<f32> {
    let s = 128;
    let mut v = Vec::with_capacity(3 * s * s);
    for c in 0..3 {
        for h in 0..s {
            for w in 0..s {
                let (c, h, w) = (c as f64, h as f64, w as f64);
                let a = 0.07 * (c + 1.0) * h + 0.05 * (3.0 - c) * w + 0.3 * c;
                v.push((127.5 + 127.5 * a.sin()) as f32);
            }
        }
    }
    v
}

const MOBILE_GOLDEN: &str = include_str!("data/mobile_encoders_golden.json");

/// Largest error of a feature map against a golden entry (shape, mean, std, 16 samples),
/// relative to the map's standard deviation (values near zero have no relative precision).
fn golden_error(t: Tensor<4>, g: &serde_json::Value, what: &str) -> f64 {
    let shape: Vec<usize> = serde_json::from_value(g["shape"].clone()).unwrap();
    assert_eq!(t.dims().to_vec(), shape, "{what}");
    let v: Vec<f64> = to_vec(t).unwrap().into_iter().map(f64::from).collect();
    let n = v.len() as f64;
    let mean = v.iter().sum::<f64>() / n;
    let std = (v.iter().map(|a| (a - mean).powi(2)).sum::<f64>() / n).sqrt();
    let (gm, gs) = (g["mean"].as_f64().unwrap(), g["std"].as_f64().unwrap());
    let scale = gs.max(1e-6);
    let mut errs = vec![(mean - gm).abs() / scale, (std - gs).abs() / scale];
    for pair in g["samples"].as_array().unwrap() {
        let i = pair[0].as_u64().unwrap() as usize;
        let want = pair[1].as_f64().unwrap();
        errs.push((v[i] - want).abs() / scale);
    }
    errs.iter().cloned().fold(0.0, f64::max)
}

/// The golden input of `scripts/convert_mobile_encoders.py`: 1x3x128x128, RGB in [0, 1].
fn mobile_golden_input() -> Vec<f32> {
    golden_input()
        .into_iter()
        .map(|v| ((f64::from(v) - 127.5) / 255.0 + 0.5) as f32)
        .collect()
}

#[test]
fn mobile_encoders_match_the_numpy_forward_of_their_source_weights() {
    let device = Device::flex();
    let golden: serde_json::Value = serde_json::from_str(MOBILE_GOLDEN).unwrap();
    let x = Tensor::<4>::from_data(
        TensorData::new(mobile_golden_input(), [1, 3, 128, 128]),
        &device,
    );
    for family in [MobileFamily::MobilenetV2, MobileFamily::EfficientnetLite0] {
        let net = MobileNet::pretrained(family, &device).unwrap();
        let features = net.forward(x.clone()).coarse_to_fine();
        for (t, stride) in features.into_iter().zip([32, 16, 8, 4, 2]) {
            let level = (stride as u32).trailing_zeros() as usize - 1;
            assert_eq!(t.dims()[1], family.channels()[level]);
            let g = &golden["encoders"][family.name()]["features"][format!("s{stride}")];
            let what = format!("{} stride {stride}", family.name());
            let max = golden_error(t, g, &what);
            eprintln!("{what}: max error {max:.2e} of the map's std");
            assert!(max < 1e-4, "{what}: error {max:.3e} x std vs numpy");
        }
    }
}

fn by_stage(f: Features) -> Vec<(&'static str, Tensor<4>)> {
    vec![
        ("stem", f.stem),
        ("dark2", f.dark2),
        ("dark3", f.dark3),
        ("dark4", f.dark4),
        ("dark5", f.dark5),
    ]
}

#[test]
fn pretrained_backbone_matches_onnxruntime() {
    let device = Device::flex();
    let golden: serde_json::Value = serde_json::from_str(GOLDEN).unwrap();
    let backbone = YoloxNano::pretrained(&device).unwrap();
    let x = Tensor::<4>::from_data(TensorData::new(golden_input(), [1, 3, 128, 128]), &device);
    let mut worst = 0.0f64;
    for (stage, t) in by_stage(backbone.forward_bgr255(x.clone())) {
        let max = golden_error(t, &golden["features"][stage], stage);
        eprintln!("{stage}: max error {max:.2e} of the map's std");
        assert!(max < 1e-4, "{stage}: error {max:.3e} x std vs onnxruntime");
        worst = worst.max(max);
    }
    eprintln!("worst error {worst:.2e} std");

    // The VP-network convention (RGB in [0, 1]) is converted to the detector's.
    let rgb01 = x.flip([1]).div_scalar(255.0);
    let a = to_vec(backbone.forward(rgb01).dark5).unwrap();
    let golden_dark5 = &golden["features"]["dark5"];
    let mean = a.iter().map(|&v| f64::from(v)).sum::<f64>() / a.len() as f64;
    let gm = golden_dark5["mean"].as_f64().unwrap();
    assert!(
        (mean - gm).abs() < 1e-4,
        "RGB [0,1] path: mean {mean} vs {gm}"
    );
}

/// A small encoder network: 64 px crops, 16x16 heatmaps (stride 4), decoder width 16.
fn small_config() -> ModelConfig {
    ModelConfig {
        input_size: 64,
        heatmap_size: 16,
        channels: 16,
        ..ModelConfig::yolox_nano()
    }
}

fn encoder_bits(net: &EncoderNet) -> Vec<Vec<u32>> {
    named_tensors(net.encoder())
        .unwrap()
        .into_iter()
        .map(|t| t.values.iter().map(|v| v.to_bits()).collect())
        .collect()
}

#[test]
fn frozen_encoder_network_learns_checkpoints_and_loads_for_inference() {
    let config = small_config();
    config.validate().unwrap();
    let toy = ToySource::new(8, 4, 5, config.input_size, config.codec());
    let dir = tempfile::tempdir().unwrap();
    let mut tc = TrainConfig::new::<EncoderNet>(config.clone());
    tc.batch_size = 4;
    tc.schedule = LrSchedule::constant(1, 3e-3);
    tc.freeze_encoder = true;
    let device = Device::flex();
    let mut trainer = Trainer::<EncoderNet>::new(tc, dir.path(), &device)
        .unwrap()
        .with_progress(false);
    let pretrained = encoder_bits(
        &YoloxNano::pretrained(&device)
            .map(|b| EncoderNet::new(&config, &device).with_encoder(Backbone::YoloxNano(b)))
            .unwrap(),
    );
    assert_eq!(
        encoder_bits(trainer.model()),
        pretrained,
        "not the COCO weights"
    );
    assert!(trainer.model().encoder_frozen());

    let batch = toy.train_epoch(0, 4).next().unwrap().unwrap();
    let mut losses = Vec::new();
    for _ in 0..25 {
        let terms = trainer.step(&batch, 3e-3).unwrap();
        assert_eq!(terms.len(), 1);
        losses.push(f64::from(terms[0]));
    }
    let (first, last) = (losses[0], losses[losses.len() - 1]);
    eprintln!("frozen-encoder loss {first:.4e} -> {last:.4e}");
    assert!(
        last < first / 2.0,
        "loss fell only from {first:.3e} to {last:.3e}"
    );
    assert_eq!(
        encoder_bits(trainer.model()),
        pretrained,
        "frozen encoder changed"
    );

    // A checkpoint of the run loads for inference as the encoder network, and resumes frozen.
    trainer.save_checkpoint().unwrap();
    let net = VpNet::load(dir.path(), &device).unwrap();
    assert_eq!(net.model().kind(), "yolox_nano_fpn");
    assert_eq!(net.config(), &config);
    let preds = net.predict_prepared(&batch.images).unwrap();
    assert_eq!(preds.len(), 4);
    assert_eq!(preds[0].heatmaps.len(), config.outputs() * 16 * 16);
    let m = |p: &[f32], q: &[f32]| {
        p.iter()
            .zip(q)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f32::max)
    };
    // (Compared with a model reloaded from the checkpoint, not with the trainer's own: burn's
    // batch norm keeps the last step's running-statistics update pending until it is synced,
    // which saving does, so the trainer's clone would run with one-step-old statistics.)
    let b = net.heatmaps(&batch.images).unwrap();
    let file = vpcal_net::store::WeightsFile::read(&vpcal_net::train::checkpoint_weights(
        &vpcal_net::train::resolve_checkpoint(dir.path()).unwrap(),
    ))
    .unwrap();
    let reloaded = file.load_into(EncoderNet::new(&config, &device)).unwrap();
    // Freezing does not change the output.
    for frozen in [false, true] {
        let model = reloaded.clone().with_frozen_encoder(frozen);
        let a = VpNet::new(model, config.clone(), &device)
            .heatmaps(&batch.images)
            .unwrap();
        assert!(
            m(&a, &b) < 1e-6,
            "frozen {frozen}: differs by {}",
            m(&a, &b)
        );
    }
    let back = Trainer::<EncoderNet>::resume(dir.path(), &device).unwrap();
    assert!(back.model().encoder_frozen());
    assert!(back.config().freeze_encoder);
}

#[test]
fn the_previous_bundled_hourglass_still_loads_as_the_hourglass() {
    // Written before encoders existed (no `encoder` in its config): it must still load.
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../models/hourglass_small/model.safetensors");
    let net = VpNet::load(&path, &Device::flex()).unwrap();
    assert_eq!(net.model().kind(), "stacked_hourglass");
    assert_eq!(net.config().encoder, vpcal_net::Encoder::Hourglass);
    assert!(net.model().as_hourglass().is_some());
}
