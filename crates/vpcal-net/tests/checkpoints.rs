#![allow(clippy::unwrap_used, clippy::expect_used)]
//! Checkpoints: bit-identical round trips, exact resume, refusal of mismatching weights.

use burn::tensor::Device;
use vpcal_net::store::{named_tensors, WeightsFile};
use vpcal_net::train::{resolve_checkpoint, LrSchedule, TrainState};
use vpcal_net::{ModelConfig, StackedHourglass, ToySource, TrainConfig, Trainer, VpNet};

/// A tiny-architecture model small enough for a few CI steps.
fn small_config() -> ModelConfig {
    ModelConfig {
        input_size: 32,
        heatmap_size: 16,
        front_channels: 8,
        channels: 16,
        depth: 2,
        ..ModelConfig::tiny()
    }
}

fn toy(config: &ModelConfig) -> ToySource {
    ToySource::new(8, 4, 21, config.input_size, config.codec())
}

fn train_config(config: &ModelConfig, epochs: usize) -> TrainConfig<ModelConfig> {
    let mut tc = TrainConfig::new::<StackedHourglass>(config.clone());
    tc.batch_size = 4;
    tc.schedule = LrSchedule::two_phase(epochs, 2e-3);
    tc.seed = 5;
    tc.data = "toy".into();
    tc
}

fn bits(model: &StackedHourglass) -> Vec<(String, Vec<usize>, Vec<u32>)> {
    named_tensors(model)
        .unwrap()
        .into_iter()
        .map(|t| {
            (
                t.name,
                t.shape,
                t.values.iter().map(|v| v.to_bits()).collect(),
            )
        })
        .collect()
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-4 * a.abs().max(b.abs()).max(1e-12)
}

#[test]
fn resumed_run_reproduces_the_uninterrupted_loss_curve() {
    let config = small_config();
    let source = toy(&config);
    let device = Device::flex();
    device.seed(9);
    let init = StackedHourglass::new(&config, &device);

    // Uninterrupted: 3 epochs.
    let dir_a = tempfile::tempdir().unwrap();
    let mut a = Trainer::with_model(
        train_config(&config, 3),
        dir_a.path(),
        &device,
        init.clone(),
    )
    .unwrap()
    .with_progress(false);
    let full = a.run(&source).unwrap().to_vec();
    assert_eq!(full.len(), 3);

    // Interrupted after 2 epochs, then resumed from disk.
    let dir_b = tempfile::tempdir().unwrap();
    let mut b = Trainer::with_model(train_config(&config, 3), dir_b.path(), &device, init)
        .unwrap()
        .with_progress(false);
    b.run_epoch(&source).unwrap();
    b.run_epoch(&source).unwrap();
    drop(b);
    // A crash while writing epoch 3 leaves a temporary folder behind: it must not matter.
    std::fs::create_dir_all(dir_b.path().join("checkpoints/.epoch-0003.tmp")).unwrap();
    std::fs::write(
        dir_b
            .path()
            .join("checkpoints/.epoch-0003.tmp/model.safetensors"),
        b"partial",
    )
    .unwrap();
    let mut resumed = Trainer::<StackedHourglass>::resume(dir_b.path(), &device)
        .unwrap()
        .with_progress(false);
    assert_eq!(resumed.state().epochs_done, 2);
    let curve = resumed.run(&source).unwrap().to_vec();
    assert_eq!(curve.len(), 3);

    for (x, y) in full.iter().zip(&curve) {
        assert_eq!(x.epoch, y.epoch);
        assert_eq!(x.lr, y.lr);
        assert_eq!(x.steps, y.steps);
        for (p, q) in [
            (x.train_loss, y.train_loss),
            (x.first_batch_loss, y.first_batch_loss),
            (x.last_batch_loss, y.last_batch_loss),
            (x.val_loss.unwrap(), y.val_loss.unwrap()),
        ] {
            assert!(close(p, q), "epoch {}: {p:e} vs {q:e}", x.epoch);
        }
    }
    // The curve actually moves (the test would be vacuous on a constant loss).
    assert!(full[2].train_loss < full[0].first_batch_loss);
    // The metrics files were rewritten from the resumed history: 3 rows + header.
    let csv = std::fs::read_to_string(dir_b.path().join("metrics.csv")).unwrap();
    assert_eq!(csv.lines().count(), 4, "{csv}");
    assert!(dir_b.path().join("curves.png").is_file());
    // Only the two newest checkpoints are kept.
    assert!(!dir_b.path().join("checkpoints/epoch-0001").exists());
    assert!(dir_b.path().join("checkpoints/epoch-0003").is_dir());
}

#[test]
fn checkpoint_round_trip_is_bit_identical() {
    let config = small_config();
    let source = toy(&config);
    let device = Device::flex();
    let dir = tempfile::tempdir().unwrap();
    let mut t = Trainer::<StackedHourglass>::new(train_config(&config, 1), dir.path(), &device)
        .unwrap()
        .with_progress(false);
    t.run(&source).unwrap();
    let trained = bits(t.model());

    // Through the trainer's resume path.
    let back = Trainer::<StackedHourglass>::resume(dir.path(), &device).unwrap();
    assert_eq!(bits(back.model()), trained);
    let state: TrainState = serde_json::from_str(
        &std::fs::read_to_string(resolve_checkpoint(dir.path()).unwrap().join("state.json"))
            .unwrap(),
    )
    .unwrap();
    assert_eq!(&state, back.state());

    // Through inference loading from the run folder.
    let net = VpNet::load(dir.path(), &device).unwrap();
    assert_eq!(bits(net.model().as_hourglass().unwrap()), trained);
    assert_eq!(net.config(), &config);

    // A new run refuses a folder that already holds one.
    let err = Trainer::<StackedHourglass>::new(train_config(&config, 1), dir.path(), &device)
        .unwrap_err()
        .to_string();
    assert!(err.contains("--resume"), "{err}");
}

#[test]
fn mismatching_weights_are_refused_with_names_and_shapes() {
    let config = small_config();
    let device = Device::flex();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("w.safetensors");
    let model = StackedHourglass::new(&config, &device);
    vpcal_net::store::save_weights(&model, &config, "stacked_hourglass", &path).unwrap();

    let mut other = config.clone();
    other.channels = 32;
    let err = VpNet::load_with_config(&path, other.clone(), &device)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("w.safetensors") && err.contains("channels: 32 vs 16"),
        "{err}"
    );

    // Force the tensors into a model of another size: every mismatch is listed with both shapes.
    let file = WeightsFile::read(&path).unwrap();
    let err = file
        .load_into(StackedHourglass::new(&other, &device))
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("tensor stacks.0.head.weight: file has shape [16, 16, 1, 1], model expects [32, 32, 1, 1]"),
        "{err}"
    );

    // A regression checkpoint is not a heatmap model.
    let reg = vpcal_net::regression::RegressionConfig::tiny(
        "resnet",
        vpcal_net::regression::NormLoss::L1,
    )
    .unwrap();
    let rmodel = vpcal_net::regression::Regressor::new(&reg, &device);
    let rpath = dir.path().join("reg.safetensors");
    vpcal_net::store::save_weights(&rmodel, &reg, "vp_regressor", &rpath).unwrap();
    let err = VpNet::load(&rpath, &device).unwrap_err().to_string();
    assert!(err.contains("reg.safetensors"), "{err}");
}

#[test]
fn a_run_started_from_a_weights_file_trains_from_those_weights() {
    let config = small_config();
    let source = toy(&config);
    let device = Device::flex();
    device.seed(4);
    let init = StackedHourglass::new(&config, &device);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("init.safetensors");
    vpcal_net::store::save_weights(&init, &config, "stacked_hourglass", &path).unwrap();
    let file = WeightsFile::read(&path).unwrap();

    let run = |out: &std::path::Path, from_file: bool| {
        let mut t = if from_file {
            Trainer::<StackedHourglass>::from_weights(train_config(&config, 1), out, &device, &file)
        } else {
            Trainer::with_model(train_config(&config, 1), out, &device, init.clone())
        }
        .unwrap()
        .with_progress(false);
        t.run(&source).unwrap().to_vec()
    };
    let a = run(&dir.path().join("file"), true);
    let b = run(&dir.path().join("model"), false);
    // The same start gives the same first step, and training moved the weights.
    assert!(close(a[0].first_batch_loss, b[0].first_batch_loss));
    assert!(a[0].last_batch_loss != a[0].first_batch_loss);
}

#[test]
fn regression_baseline_trains_checkpoints_and_resumes() {
    use vpcal_net::regression::{NormLoss, RegressionConfig, Regressor};
    let config = RegressionConfig::tiny("resnet", NormLoss::L1).unwrap();
    // Regression batches still carry (unused) heatmap targets: a small codec keeps them cheap.
    let source = ToySource::new(
        8,
        4,
        3,
        config.input_size,
        vpcal_geom::heatmap::HeatmapCodec::new(8, vec![1.0]),
    );
    let device = Device::flex();
    let dir = tempfile::tempdir().unwrap();
    let mut tc = TrainConfig::new::<Regressor>(config.clone());
    tc.batch_size = 4;
    tc.schedule = LrSchedule::constant(2, 1e-3);
    let mut t = Trainer::<Regressor>::new(tc, dir.path(), &device)
        .unwrap()
        .with_progress(false);
    let first = t.run_epoch(&source).unwrap();
    assert_eq!(
        first.train_loss_terms.len(),
        2,
        "one normalised-loss term per VP"
    );
    assert!(first.train_loss.is_finite() && first.train_loss > 0.0);
    let m = first.val.unwrap();
    assert_eq!(m.crops, 4);
    assert!(
        m.vp1_median_rel_per_scale.is_empty(),
        "regression has no scales"
    );
    drop(t);
    let mut t = Trainer::<Regressor>::resume(dir.path(), &device)
        .unwrap()
        .with_progress(false);
    assert_eq!(t.run(&source).unwrap().len(), 2);
    // The heatmap model refuses to resume a regression run.
    let err = Trainer::<StackedHourglass>::resume(dir.path(), &device)
        .unwrap_err()
        .to_string();
    assert!(err.contains("train_config.json"), "{err}");
}

#[test]
fn a_changed_data_source_is_recorded_with_its_first_epoch() {
    let config = small_config();
    let source = toy(&config);
    let device = Device::flex();
    let dir = tempfile::tempdir().unwrap();
    let mut t = Trainer::<StackedHourglass>::new(train_config(&config, 2), dir.path(), &device)
        .unwrap()
        .with_progress(false);
    // Before any epoch: a switch replaces the source, with no history.
    t.set_data("toy-b").unwrap();
    assert_eq!(t.config().data, "toy-b");
    assert!(t.config().data_history.is_empty());
    t.set_data("toy").unwrap();
    assert!(t.config().data_history.is_empty());
    t.set_schedule(LrSchedule::two_phase(1, 2e-3)).unwrap();
    t.run(&source).unwrap();

    // After epoch 1: both sources with their first epochs, saved in train_config.json.
    let mut back = Trainer::<StackedHourglass>::resume(dir.path(), &device).unwrap();
    back.set_data("toy-b").unwrap();
    back.set_data("toy-c").unwrap(); // replaces toy-b, which trained no epoch
    let saved: TrainConfig<ModelConfig> = serde_json::from_str(
        &std::fs::read_to_string(dir.path().join("train_config.json")).unwrap(),
    )
    .unwrap();
    let history: Vec<(usize, &str)> = saved
        .data_history
        .iter()
        .map(|s| (s.first_epoch, s.data.as_str()))
        .collect();
    assert_eq!(history, [(1, "toy"), (2, "toy-c")]);
    assert_eq!(saved.data, "toy-c");
    // Back to the first source before training: one source again.
    back.set_data("toy").unwrap();
    assert!(back.config().data_history.is_empty());
}
