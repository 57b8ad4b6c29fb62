#![allow(clippy::unwrap_used, clippy::expect_used)]
//! Acceptance: the `tiny` model overfits a few fixed samples — the loss falls 100x and the VPs
//! decoded from its heatmaps match those decoded from the ideal targets at every scale.

use burn::tensor::Device;
use vpcal_geom::heatmap::DecodeMode;
use vpcal_net::metrics::relative_error;
use vpcal_net::train::LrSchedule;
use vpcal_net::{
    BatchSource, ModelConfig, StackedHourglass, ToySource, TrainConfig, Trainer, VpNet,
};

/// Optimizer steps on the fixed batch (about 50 s on a loaded 2-core machine).
const STEPS: usize = 500;
const LR: f64 = 1e-2;

#[test]
fn tiny_model_overfits_a_few_samples() {
    let config = ModelConfig::tiny();
    let mut toy = ToySource::new(4, 0, 11, config.input_size, config.codec());
    toy.shuffle = false;
    let dir = tempfile::tempdir().unwrap();
    let mut tc = TrainConfig::new::<StackedHourglass>(config.clone());
    tc.batch_size = 4;
    tc.schedule = LrSchedule::constant(1, LR);
    tc.seed = 3;
    let mut trainer = Trainer::<StackedHourglass>::new(tc, dir.path(), &Device::flex())
        .unwrap()
        .with_progress(false);
    let batch = toy.train_epoch(0, 4).next().unwrap().unwrap();
    // The loss of predicting all zeros: below it, the peaks themselves have been learned.
    let zero_loss: f64 = batch.targets.iter().map(|&t| f64::from(t * t)).sum::<f64>()
        / batch.targets.len() as f64
        * config.stacks as f64;
    let mut losses = Vec::with_capacity(STEPS);
    for _ in 0..STEPS {
        let terms = trainer.step(&batch, LR).unwrap();
        losses.push(terms.iter().map(|&v| f64::from(v)).sum::<f64>());
    }
    let (first, last) = (losses[0], losses[STEPS - 1]);
    eprintln!("loss {first:.4e} -> {last:.4e} (all-zero output: {zero_loss:.4e})");
    assert!(
        last < first / 100.0,
        "loss fell only from {first:.3e} to {last:.3e}"
    );
    assert!(
        last < zero_loss / 5.0,
        "loss {last:.3e} is not far below the all-zero output's {zero_loss:.3e}"
    );

    // Inference path: validation-mode model (running batch-norm statistics), batched predict.
    let net = VpNet::new(trainer.model().clone(), config.clone(), &Device::flex());
    let preds = net.predict_prepared(&batch.images).unwrap();
    let codec = config.codec();
    let per = codec.len();
    let mut compared = 0;
    for (i, p) in preds.iter().enumerate() {
        let ideal = codec.decode(&batch.targets[i * per..(i + 1) * per], DecodeMode::Centre);
        for s in 0..codec.scales.len() {
            for vp in 0..2 {
                let (got, want) = (p.vp.per_scale[s][vp], ideal.per_scale[s][vp]);
                if !want.is_finite() {
                    // The ideal peak sits on the line at infinity: no finite VP to match.
                    assert!(
                        !got.is_finite() || got.norm() > 1e3,
                        "crop {i} scale {s} vp{}: {got:?}",
                        vp + 1
                    );
                    continue;
                }
                let err = relative_error(got, want);
                assert!(
                    err < 0.02,
                    "crop {i} scale {} VP{}: decoded {got:?}, the ideal target decodes to {want:?} ({:.1} % off)",
                    codec.scales[s],
                    vp + 1,
                    100.0 * err
                );
                compared += 1;
            }
        }
    }
    assert!(compared >= 28, "only {compared} finite VPs compared");
}
