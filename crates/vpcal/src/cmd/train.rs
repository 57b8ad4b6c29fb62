//! `vpcal train`: train the VP network (or a regression baseline) on a data source, with
//! per-epoch validation, checkpoints, metrics and curves in `--out` (crate `vpcal-net`).

use std::path::{Path, PathBuf};
use std::sync::Arc;

use anyhow::{bail, Context, Result};
use clap::{Args as ClapArgs, ValueEnum};
use vpcal_data::augment::AugmentConfig;
use vpcal_data::{SampleSource, Split};
use vpcal_geom::heatmap::HeatmapCodec;
use vpcal_net::regression::{NormLoss, RegressionConfig, Regressor};
use vpcal_net::train::EpochRecord;
use vpcal_net::{
    BatchSource, EncoderNet, LrSchedule, ModelConfig, PipelineSource, StackedHourglass, ToySource,
    TrainConfig, Trainer, VpNetwork,
};

/// The augmentation of a new run without `--augment`: the paper's.
const DEFAULT_AUGMENT: &str = "paper";

/// Which network to train.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Arch {
    /// The paper's stacked hourglass with diamond-space heatmaps.
    Heatmap,
    /// Ablation: ResNet-50 regressing the VPs with a normalised loss.
    Resnet50,
    /// Ablation: stacked hourglass + global pooling regressing the VPs.
    HourglassPool,
}

/// Normalised regression loss (regression architectures only).
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum LossArg {
    Nl1,
    Nl2,
}

#[derive(Debug, ClapArgs)]
#[command(
    after_help = "Examples:\n  vpcal train --data synth:2000 -o runs/try --epochs 2\n  \
vpcal train -o runs/try --resume\n\n\
Exit codes: 0 done; 1 an error; 2 a wrong command line."
)]
pub struct Args {
    /// Training data: `boxcars:DIR` (BoxCars116k), `synth:N` (N synthetic crops rendered on
    /// the fly), `synth-crops:DIR` (crops written by `vpcal synth crops` or self-labelled real
    /// crops written by `vpcal label`), `toy:N` (N toy crops of line segments, a smoke test).
    /// Several sources are joined with `+` (e.g. `synth-crops:SYN+synth-crops:REAL`; not
    /// `synth` or `toy`). Defaults to the run's own source with --resume.
    #[arg(long, value_name = "KIND:ARG")]
    pub data: Option<String>,
    /// Start a new run from these weights (fine-tuning, e.g.
    /// `models/default/model.safetensors`): the model's size comes from the file, --preset is
    /// ignored. Heatmap networks only.
    #[arg(long, value_name = "WEIGHTS", conflicts_with = "resume")]
    pub init: Option<PathBuf>,
    /// Run folder: checkpoints, metrics.csv/jsonl, curves.png.
    #[arg(short = 'o', long = "output", alias = "out", value_name = "DIR")]
    pub out: PathBuf,
    /// Continue the run in --out from its latest checkpoint.
    #[arg(long)]
    pub resume: bool,
    /// Model size: `paper` (the paper's stacked hourglass: 2 stacks, 128 px crops, 64 px
    /// heatmaps, 4 scales; a GPU is advised), `small`, `tiny` (CPU training and tests), or a
    /// pretrained encoder with an FPN-lite decoder (128 px crops, 32 px heatmaps; see
    /// --freeze-encoder): `yolox_nano` (the COCO-pretrained YOLOX-nano backbone, the bundled
    /// model's), `mobilenet_v2` or `efficientnet_lite0` (ImageNet; their weights are read from
    /// the repository's models/encoders, or from the folder named by $VPCAL_ENCODERS).
    #[arg(long, default_value = "paper")]
    pub preset: String,
    /// Keep the pretrained encoder (`--preset yolox_nano`, `mobilenet_v2`, `efficientnet_lite0`)
    /// fixed and train only its decoder
    /// (the first phase, e.g. --lr 1e-3). Fine-tune the whole network afterwards in a new run
    /// with `--init RUN/checkpoints/epoch-N/model.safetensors` without this flag and a low rate
    /// (--lr 1e-4 or less), so the pretrained features are not destroyed. A resumed run keeps
    /// its setting.
    #[arg(long)]
    pub freeze_encoder: bool,
    /// Network architecture.
    #[arg(long, value_enum, default_value_t = Arch::Heatmap)]
    pub arch: Arch,
    /// Loss of the regression architectures.
    #[arg(long, value_enum, default_value_t = LossArg::Nl1)]
    pub loss: LossArg,
    /// Epochs (default 75 = the paper's 60 + 15). The learning rate is --lr for the first
    /// 80 % of the epochs and --lr / 10 after (the paper's schedule). With --resume, a new
    /// total recomputes that schedule from the run's first rate.
    #[arg(long)]
    pub epochs: Option<usize>,
    /// Base learning rate (Adam).
    #[arg(long, default_value_t = 1e-3)]
    pub lr: f64,
    /// Keep --lr for all epochs instead of dropping it for the last 20 %.
    #[arg(long)]
    pub constant_lr: bool,
    /// Crops per step.
    #[arg(long, default_value_t = 32)]
    pub batch: usize,
    /// Seed of the initialisation, the data order and the augmentation.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Augmentation of training crops: `paper` (default), `reference`, `real` (the paper's plus
    /// sensor effects: occluders, exposure, colour, blur, low resolution, noise, JPEG),
    /// `real-small` (those, down-sampling up to 8x instead of 3.5x: the look of far, small
    /// vehicles) or `none`. A resumed run keeps its own unless this is given.
    #[arg(long)]
    pub augment: Option<String>,
    /// Stop each epoch after this many batches (quick runs on large data).
    #[arg(long)]
    pub max_batches: Option<usize>,
    /// Validate on at most this many batches.
    #[arg(long)]
    pub max_val_batches: Option<usize>,
    /// Data pipeline threads (default: one per core).
    #[arg(long)]
    pub workers: Option<usize>,
    /// Heatmap loss weighting: each pixel's squared error counts `1 + W * target`, so the
    /// Gaussian peaks are not drowned by the empty background (0 = the paper's plain MSE).
    /// Validation loss stays the plain MSE.
    /// A resumed run keeps the weight it was started with.
    #[arg(long, value_name = "W")]
    pub fg_weight: Option<f64>,
    /// Epoch checkpoints to keep.
    #[arg(long, default_value_t = 2)]
    pub keep: usize,
    /// Device: `cpu`, or `wgpu` in builds with the `wgpu` feature.
    #[arg(long, default_value = "cpu", value_parser = super::args::device)]
    pub device: String,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
}

/// Build the batch source named by `spec` for a model with `input_size` and `codec`.
fn open_data(
    spec: &str,
    input_size: usize,
    codec: HeatmapCodec,
    augment: &str,
    seed: u64,
    workers: Option<usize>,
) -> Result<Box<dyn BatchSource>> {
    if spec.contains('+') {
        return open_joined(spec, input_size, codec, augment, seed, workers);
    }
    let Some((kind, arg)) = spec.split_once(':') else {
        bail!("--data {spec:?}: expected KIND:ARG, e.g. boxcars:/data/BoxCars116k or toy:256");
    };
    let count = |what: &str| -> Result<usize> {
        arg.parse::<usize>()
            .ok()
            .filter(|n| *n > 0)
            .with_context(|| format!("--data {spec:?}: {what} needs a positive sample count"))
    };
    let aug = AugmentConfig::preset(augment).with_context(|| {
        format!(
            "unknown --augment {augment:?}: expected one of {}",
            AugmentConfig::PRESETS.join(", ")
        )
    })?;
    let pipeline = |train: Arc<dyn SampleSource>,
                    val: Arc<dyn SampleSource>|
     -> Result<Box<dyn BatchSource>> {
        let mut p = PipelineSource::new(
            spec,
            train,
            Some(val),
            aug.clone(),
            input_size,
            codec.clone(),
            seed,
        )?;
        if let Some(w) = workers {
            p = p.with_workers(w);
        }
        Ok(Box::new(p))
    };
    match kind {
        "toy" => {
            let n = count("toy")?;
            Ok(Box::new(ToySource::new(n, (n / 8).max(8), seed, input_size, codec)))
        }
        "boxcars" => pipeline(
            super::data::open_source(spec, Split::Train)?,
            super::data::open_source(spec, Split::Validation)?,
        ),
        "synth" => {
            let n = count("synth")?;
            let generator = vpcal_synth::CropGenerator::new(
                vpcal_synth::CropConfig::default(),
                seed,
                Arc::new(Vec::new()),
            )?;
            let train = vpcal_synth::SynthCropSource::new(generator.clone(), Split::Train, n);
            let val = vpcal_synth::SynthCropSource::new(generator, Split::Validation, (n / 8).max(8));
            pipeline(Arc::new(train), Arc::new(val))
        }
        "synth-crops" => {
            let dir = Path::new(arg);
            let train = vpcal_synth::CropDirSource::open(dir, Split::Train)
                .with_context(|| format!("opening synthetic crops in {}", dir.display()))?;
            let val = vpcal_synth::CropDirSource::open(dir, Split::Validation)
                .with_context(|| format!("opening synthetic crops in {}", dir.display()))?;
            pipeline(Arc::new(train), Arc::new(val))
        }
        other => bail!(
            "--data {spec:?}: unknown data kind {other:?} (supported: boxcars, synth, synth-crops, toy)"
        ),
    }
}

/// One sample source of a split named by a `KIND:ARG` part of a joined `--data`.
fn open_part(part: &str, split: Split) -> Result<Arc<dyn SampleSource>> {
    match part.split_once(':') {
        Some(("boxcars", _)) => super::data::open_source(part, split),
        Some(("synth-crops", dir)) => {
            let dir = Path::new(dir);
            let s = vpcal_synth::CropDirSource::open(dir, split)
                .with_context(|| format!("opening the crops in {}", dir.display()))?;
            Ok(Arc::new(s))
        }
        _ => bail!(
            "--data part {part:?}: only boxcars:DIR and synth-crops:DIR can be joined with '+'"
        ),
    }
}

/// `--data A+B+...`: the parts' training splits read as one, and their validation splits.
fn open_joined(
    spec: &str,
    input_size: usize,
    codec: HeatmapCodec,
    augment: &str,
    seed: u64,
    workers: Option<usize>,
) -> Result<Box<dyn BatchSource>> {
    let aug = AugmentConfig::preset(augment).with_context(|| {
        format!(
            "unknown --augment {augment:?}: expected one of {}",
            AugmentConfig::PRESETS.join(", ")
        )
    })?;
    let parts: Vec<&str> = spec.split('+').collect();
    let join = |split: Split| -> Result<Arc<dyn SampleSource>> {
        let sources = parts
            .iter()
            .map(|p| open_part(p, split))
            .collect::<Result<Vec<_>>>()?;
        Ok(Arc::new(vpcal_data::ConcatSource::new(sources)?))
    };
    let mut p = PipelineSource::new(
        spec,
        join(Split::Train)?,
        Some(join(Split::Validation)?),
        aug,
        input_size,
        codec,
        seed,
    )?;
    if let Some(w) = workers {
        p = p.with_workers(w);
    }
    Ok(Box::new(p))
}

fn fmt_err(v: f64) -> String {
    if v.is_finite() {
        format!("{:.2} %", 100.0 * v)
    } else {
        "inf".to_string()
    }
}

fn print_epoch(r: &EpochRecord, total: usize) {
    let mut line = format!(
        "epoch {}/{total}: lr {:.0e}, train loss {:.4e}",
        r.epoch, r.lr, r.train_loss
    );
    if let Some(v) = r.val_loss {
        line.push_str(&format!(", val loss {v:.4e}"));
    }
    if let Some(m) = &r.val {
        line.push_str(&format!(
            ", median rel. VP error VP1 {} VP2 {}",
            fmt_err(m.vp1_median_rel),
            fmt_err(m.vp2_median_rel)
        ));
    }
    line.push_str(&format!(
        ", {:.1} crops/s, {:.0} s",
        r.samples_per_s, r.seconds
    ));
    println!("{line}");
}

fn train_loop<N: VpNetwork>(mut trainer: Trainer<N>, source: &dyn BatchSource) -> Result<()> {
    let total = trainer.config().schedule.total_epochs();
    while trainer.state().epochs_done < total {
        let r = trainer
            .run_epoch(source)
            .with_context(|| format!("training epoch {}", trainer.state().epochs_done + 1))?;
        print_epoch(&r, total);
    }
    println!(
        "done: {} epochs in {}; metrics in {}, curves in {}",
        total,
        trainer.out_dir().display(),
        trainer.out_dir().join("metrics.csv").display(),
        trainer.out_dir().join("curves.png").display()
    );
    Ok(())
}

fn schedule(a: &Args, epochs: usize, lr: f64) -> LrSchedule {
    if a.constant_lr {
        LrSchedule::constant(epochs, lr)
    } else {
        LrSchedule::two_phase(epochs, lr)
    }
}

fn run_arch<N: VpNetwork>(a: &Args, model: N::Config) -> Result<()> {
    let device = vpcal_net::device::select(&a.device)?;
    let (trainer, source) = if a.resume {
        let mut t = Trainer::<N>::resume(&a.out, &device)
            .with_context(|| format!("resuming the run in {}", a.out.display()))?;
        if let Some(w) = a.fg_weight.filter(|w| *w != t.config().fg_weight) {
            bail!(
                "--fg-weight {w}: the run in {} was started with --fg-weight {} and a resumed \
                 run keeps its loss (start a new run to change it)",
                a.out.display(),
                t.config().fg_weight
            );
        }
        if a.freeze_encoder && !t.config().freeze_encoder {
            bail!(
                "--freeze-encoder: the run in {} trains its whole network; start a new run to \
                 freeze the encoder",
                a.out.display()
            );
        }
        if let Some(e) = a.epochs {
            let base = t.config().schedule.lr_at(0);
            t.set_schedule(schedule(a, e, base))?;
        }
        // The data of a resumed run is the one it was started with (same seed, so the same
        // batches per epoch), unless --data overrides it; train_config.json then records
        // each source with the first epoch it trained.
        let saved = t.config().data.clone();
        let (saved_spec, saved_aug) = match saved.split_once(" augment=") {
            Some((d, aug)) => (d.to_string(), Some(aug.to_string())),
            None => (saved.clone(), None),
        };
        let spec = a.data.clone().unwrap_or(saved_spec);
        let augment = a
            .augment
            .clone()
            .or(saved_aug)
            .unwrap_or_else(|| DEFAULT_AUGMENT.to_string());
        let model = &t.config().model;
        let source = open_data(
            &spec,
            N::input_size(model),
            N::target_codec(model),
            &augment,
            t.config().seed,
            a.workers,
        )?;
        t.set_data(&format!("{spec} augment={augment}"))?;
        (t, source)
    } else {
        let Some(data) = &a.data else {
            bail!("--data is required for a new run (e.g. --data toy:256)");
        };
        let augment = a.augment.as_deref().unwrap_or(DEFAULT_AUGMENT);
        // Open the data first: a bad --data leaves no half-made run folder behind.
        let source = open_data(
            data,
            N::input_size(&model),
            N::target_codec(&model),
            augment,
            a.seed,
            a.workers,
        )?;
        let init = a
            .init
            .as_deref()
            .map(|path| {
                vpcal_net::store::WeightsFile::read(path)
                    .with_context(|| format!("reading --init {}", path.display()))
            })
            .transpose()?;
        let mut tc = TrainConfig::new::<N>(model);
        tc.batch_size = a.batch;
        tc.schedule = schedule(a, a.epochs.unwrap_or(75), a.lr);
        tc.seed = a.seed;
        tc.max_train_batches = a.max_batches;
        tc.max_val_batches = a.max_val_batches;
        tc.data = format!("{data} augment={augment}");
        tc.keep_checkpoints = a.keep.max(1);
        let fg_weight = a.fg_weight.unwrap_or(0.0);
        if !(fg_weight.is_finite() && fg_weight >= 0.0) {
            bail!("--fg-weight {fg_weight}: expected a finite weight >= 0");
        }
        tc.fg_weight = fg_weight;
        tc.freeze_encoder = a.freeze_encoder;
        let t = match &init {
            Some(w) => Trainer::<N>::from_weights(tc, &a.out, &device, w),
            None => Trainer::<N>::new(tc, &a.out, &device),
        }
        .with_context(|| format!("starting a run in {}", a.out.display()))?;
        (t, source)
    };
    let trainer = trainer.with_progress(!a.quiet);
    eprintln!("data: {}", source.describe());
    eprintln!(
        "model: {} ({} parameters), {} epochs, batch {}, run folder {}",
        N::describe(&trainer.config().model),
        trainer.model().param_count(),
        trainer.config().schedule.total_epochs(),
        trainer.config().batch_size,
        a.out.display()
    );
    train_loop(trainer, source.as_ref())
}

/// Whether the run in `out` trains the pretrained-encoder network (its `train_config.json`
/// names [`EncoderNet::KIND`]); a missing file is left to the resume itself to report.
fn resumed_run_is_encoder(out: &Path) -> Result<bool> {
    let path = out.join("train_config.json");
    let Ok(text) = std::fs::read_to_string(&path) else {
        return Ok(false);
    };
    let value: serde_json::Value = serde_json::from_str(&text)
        .with_context(|| format!("{}: malformed JSON", path.display()))?;
    Ok(value.get("kind").and_then(|k| k.as_str()) == Some(EncoderNet::KIND))
}

/// Run `vpcal train`.
pub fn run(a: Args) -> Result<()> {
    let loss = match a.loss {
        LossArg::Nl1 => NormLoss::L1,
        LossArg::Nl2 => NormLoss::L2,
    };
    match a.arch {
        Arch::Heatmap => {
            let model = match &a.init {
                Some(path) => vpcal_net::store::WeightsFile::read(path)
                    .with_context(|| format!("reading --init {}", path.display()))?
                    .config::<ModelConfig>()?
                    .with_context(|| {
                        format!(
                            "--init {}: the file has no model config in its metadata",
                            path.display()
                        )
                    })?,
                None => ModelConfig::preset(&a.preset)?,
            };
            // A resumed run trains the network it was started with, whatever --preset says.
            let encoder = if a.resume {
                resumed_run_is_encoder(&a.out)?
            } else {
                !model.encoder.is_hourglass()
            };
            if encoder {
                run_arch::<EncoderNet>(&a, model)
            } else {
                run_arch::<StackedHourglass>(&a, model)
            }
        }
        Arch::Resnet50 | Arch::HourglassPool if a.init.is_some() => {
            bail!("--init: fine-tuning is for the heatmap network (--arch heatmap) only")
        }
        Arch::Resnet50 | Arch::HourglassPool => {
            let backbone = if a.arch == Arch::Resnet50 {
                "resnet50"
            } else {
                "hourglass-pool"
            };
            let config = match a.preset.as_str() {
                "paper" if a.arch == Arch::Resnet50 => RegressionConfig::resnet50(loss),
                "paper" => RegressionConfig::hourglass_pool(loss),
                "tiny" => RegressionConfig::tiny(backbone, loss)?,
                other => bail!("unknown --preset {other:?} (expected paper or tiny)"),
            };
            run_arch::<Regressor>(&a, config)
        }
    }
}
