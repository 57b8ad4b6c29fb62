//! `vpcal data`: look at and measure the training data pipeline.
//!
//! - `vpcal data preview --data boxcars:DIR --count 16 -o sheet.png`: augmented crops with
//!   their VP directions and 2D/3D boxes (exactly what epoch 0 of the pipeline feeds with that
//!   seed).
//! - `vpcal data bench --data boxcars:DIR`: index the dataset, run the batch pipeline and
//!   report samples/s.
//! - `vpcal data info --data boxcars:DIR`: cameras, vehicles and split sizes.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use anyhow::{bail, Context};
use clap::{Args as ClapArgs, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use vpcal_data::augment::{augment, AugmentConfig};
use vpcal_data::boxcars::BoxCars;
use vpcal_data::pipeline::{epoch_order, sample_rng, Pipeline, PipelineConfig};
use vpcal_data::{SampleSource, Split};

/// Subcommands of `vpcal data`.
#[derive(Debug, Subcommand)]
pub enum DataCommand {
    /// Draw augmented crops with their VP directions and 2D/3D boxes into one PNG.
    Preview(PreviewArgs),
    /// Run the batch pipeline (decode, augment, targets) and report samples/s.
    Bench(BenchArgs),
    /// Print the cameras, vehicles and split sizes of a dataset.
    Info(InfoArgs),
}

/// Flags shared by the data subcommands.
#[derive(Debug, ClapArgs)]
pub struct SourceArgs {
    /// The data: `boxcars:DIR` (a BoxCars116k directory with dataset.pkl and atlas.pkl).
    #[arg(long, value_name = "KIND:PATH")]
    pub data: String,
    /// Which split: train, validation or test.
    #[arg(long, default_value = "train", value_parser = parse_split)]
    pub split: Split,
}

#[derive(Debug, ClapArgs)]
pub struct PreviewArgs {
    #[command(flatten)]
    pub source: SourceArgs,
    /// Number of crops.
    #[arg(long, default_value_t = 16)]
    pub count: usize,
    /// Augmentation preset: paper, reference or none (validation and test splits always use
    /// none).
    #[arg(long, default_value = "paper")]
    pub augment: String,
    /// Seed of the sample choice and the augmentation.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Enlargement of each crop in the sheet (1-16).
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u32).range(1..=16))]
    pub scale: u32,
    /// Output PNG.
    #[arg(short = 'o', long)]
    pub output: PathBuf,
}

#[derive(Debug, ClapArgs)]
pub struct BenchArgs {
    #[command(flatten)]
    pub source: SourceArgs,
    /// Samples per batch.
    #[arg(long, default_value_t = 32)]
    pub batch_size: usize,
    /// Worker threads (default: one per core).
    #[arg(long)]
    pub workers: Option<usize>,
    /// Batches to run (0: the whole epoch).
    #[arg(long, default_value_t = 0)]
    pub batches: usize,
    /// Augmentation preset: paper, reference or none.
    #[arg(long, default_value = "paper")]
    pub augment: String,
    /// Seed of the samples drawn.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
}

#[derive(Debug, ClapArgs)]
pub struct InfoArgs {
    /// The data: `boxcars:DIR`.
    #[arg(long, value_name = "KIND:PATH")]
    pub data: String,
}

fn parse_split(s: &str) -> Result<Split, String> {
    match s {
        "train" => Ok(Split::Train),
        "validation" | "val" => Ok(Split::Validation),
        "test" => Ok(Split::Test),
        _ => Err(format!(
            "unknown split {s:?}: expected train, validation or test"
        )),
    }
}

fn augment_config(name: &str, split: Split) -> anyhow::Result<AugmentConfig> {
    let cfg = AugmentConfig::preset(name).with_context(|| {
        format!(
            "unknown augmentation preset {name:?}: expected one of {}",
            AugmentConfig::PRESETS.join(", ")
        )
    })?;
    Ok(if split == Split::Train {
        cfg
    } else {
        AugmentConfig::evaluation(cfg.output_size)
    })
}

/// Open a BoxCars directory with a progress bar over the atlas pass.
fn open_boxcars(dir: &Path) -> anyhow::Result<BoxCars> {
    let bar = ProgressBar::new(0).with_style(
        ProgressStyle::with_template(
            "indexing atlas.pkl {bar:40} {bytes}/{total_bytes} ({bytes_per_sec}, {eta})",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let bc = BoxCars::open_with_progress(dir, &|done, total| {
        bar.set_length(total);
        bar.set_position(done);
    })
    .with_context(|| format!("opening the BoxCars dataset in {}", dir.display()))?;
    bar.finish_and_clear();
    Ok(bc)
}

/// `KIND:PATH` → a data source of one split (shared with other subcommands that read training
/// data; add new kinds here).
///
/// # Errors
/// An unknown kind, or the source's own error (naming the file).
pub fn open_source(spec: &str, split: Split) -> anyhow::Result<Arc<dyn SampleSource>> {
    let Some((kind, path)) = spec.split_once(':') else {
        bail!("--data {spec:?}: expected KIND:PATH, e.g. boxcars:/data/BoxCars116k");
    };
    match kind {
        "boxcars" => Ok(Arc::new(open_boxcars(Path::new(path))?.split(split))),
        other => bail!("--data {spec:?}: unknown data kind {other:?} (supported: boxcars)"),
    }
}

/// Run a `vpcal data` subcommand.
pub fn run(cmd: DataCommand) -> anyhow::Result<()> {
    match cmd {
        DataCommand::Preview(a) => preview(a),
        DataCommand::Bench(a) => bench(a),
        DataCommand::Info(a) => info(a),
    }
}

fn preview(a: PreviewArgs) -> anyhow::Result<()> {
    if a.count == 0 {
        bail!("--count must be at least 1");
    }
    let cfg = augment_config(&a.augment, a.source.split)?;
    let source = open_source(&a.source.data, a.source.split)?;
    if source.is_empty() {
        bail!(
            "the {:?} split of {} holds no sample",
            a.source.split,
            a.source.data
        );
    }
    let order = epoch_order(source.len(), a.seed, 0, a.source.split == Split::Train);
    let mut items = Vec::with_capacity(a.count);
    let mut skipped = 0usize;
    for &index in &order {
        if items.len() == a.count {
            break;
        }
        let sample = match source.get(index) {
            Ok(s) => s,
            Err(e @ vpcal_data::DataError::Sample { .. }) => {
                eprintln!("warning: skipping sample {index}: {e}");
                skipped += 1;
                continue;
            }
            Err(e) => return Err(e).context("reading a sample"),
        };
        let mut rng = sample_rng(a.seed, 0, index);
        match augment(&sample, &cfg, &mut rng) {
            Ok(x) => items.push(x),
            Err(e) => {
                eprintln!("warning: skipping sample {index}: {e}");
                skipped += 1;
            }
        }
    }
    let sheet = vpcal_data::preview::contact_sheet(&items, 0, a.scale);
    vpcal_video::draw::save_png(&sheet, &a.output)?;
    println!(
        "{}: {} crops ({:?} split, augmentation {}), {}x{} px{}",
        a.output.display(),
        items.len(),
        a.source.split,
        if a.source.split == Split::Train {
            a.augment.as_str()
        } else {
            "none"
        },
        sheet.width(),
        sheet.height(),
        if skipped > 0 {
            format!(", {skipped} samples skipped")
        } else {
            String::new()
        }
    );
    Ok(())
}

fn bench(a: BenchArgs) -> anyhow::Result<()> {
    let t_open = Instant::now();
    let source = open_source(&a.source.data, a.source.split)?;
    let open_s = t_open.elapsed().as_secs_f64();
    let mut cfg = PipelineConfig::training(a.batch_size, a.seed);
    cfg.augment = augment_config(&a.augment, a.source.split)?;
    cfg.shuffle = a.source.split == Split::Train;
    cfg.warn_on_skip = false;
    if let Some(w) = a.workers {
        cfg.workers = w;
    }
    let workers = cfg.workers;
    let pipeline = Pipeline::new(source, cfg).map_err(anyhow::Error::msg)?;
    let total = if a.batches == 0 {
        pipeline.batches_per_epoch()
    } else {
        a.batches.min(pipeline.batches_per_epoch())
    };
    let bar = ProgressBar::new(total as u64).with_style(
        ProgressStyle::with_template("batches {bar:40} {pos}/{len} ({per_sec}, {eta})")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let start = Instant::now();
    let mut epoch = pipeline.epoch(0);
    let mut samples = 0usize;
    for batch in epoch.by_ref().take(total) {
        samples += batch.context("building a batch")?.size;
        bar.inc(1);
    }
    bar.finish_and_clear();
    let secs = start.elapsed().as_secs_f64();
    println!(
        "indexed in {open_s:.2} s; {samples} samples in {total} batches in {secs:.2} s with {workers} workers: {:.1} samples/s",
        samples as f64 / secs.max(1e-9)
    );
    if !epoch.skipped().is_empty() {
        println!("{} samples skipped:", epoch.skipped().len());
        for s in epoch.skipped().iter().take(10) {
            println!("  sample {}: {}", s.index, s.reason);
        }
    }
    Ok(())
}

fn info(a: InfoArgs) -> anyhow::Result<()> {
    let Some(("boxcars", dir)) = a.data.split_once(':') else {
        bail!("--data {:?}: expected boxcars:DIR", a.data);
    };
    let bc = open_boxcars(Path::new(dir))?;
    println!(
        "{} cameras, {} vehicles",
        bc.cameras().len(),
        bc.vehicles().len()
    );
    for split in [Split::Train, Split::Validation, Split::Test] {
        println!("  {:?}: {} instances", split, bc.split(split).len());
    }
    for c in bc.cameras() {
        println!(
            "  camera {}: f = {:.1} px, vp1 = ({:.1}, {:.1}), vp2 = ({:.1}, {:.1})",
            c.name, c.focal_px, c.vp1[0], c.vp1[1], c.vp2[0], c.vp2[1]
        );
    }
    Ok(())
}
