//! `vpcal synth`: synthetic training crops, traffic scenes with ground truth, the benchmark
//! suite, contact sheets and a throughput benchmark (crate `vpcal-synth`).

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use vpcal_data::SampleSource;
use vpcal_synth::scene::{render_scene, suite_specs, SceneSpec, WriteOptions};
use vpcal_synth::world::LayoutKind;
use vpcal_synth::{CropConfig, CropGenerator, RealBackground};

/// Generate synthetic data: training crops, traffic scenes, the benchmark suite, pictures.
#[derive(Debug, clap::Subcommand)]
pub enum SynthCommand {
    /// BoxCars-like training crops (samples.jsonl + JPEGs, see FORMAT.md in the output).
    Crops(CropsArgs),
    /// One traffic scene: video.mp4 and BrnoCompSpeed-style ground truth.
    Scene(SceneArgs),
    /// The benchmark suite: 14 scenes with different cameras and layouts.
    Suite(SuiteArgs),
    /// A contact-sheet PNG of crops with their 3D boxes and VP directions drawn.
    Sheet(SheetArgs),
    /// Measure crop generation (crops/s) and scene rendering (frames/s) without writing files.
    Bench(BenchArgs),
}

#[derive(Debug, clap::Args)]
pub struct BgArgs {
    /// BrnoCompSpeed-like root (dataset/<view>/screen.png + results/<view>/system_dubska_bmvc14.json)
    /// whose views are used as real backgrounds for some crops, e.g. ../shared/data/bcs.
    #[arg(long)]
    pub real_bg: Option<PathBuf>,
    /// Fraction of crops rendered into real backgrounds (with --real-bg).
    #[arg(long, default_value_t = 0.2)]
    pub real_fraction: f64,
    /// Crops per vehicle (instances).
    #[arg(long, default_value_t = 4)]
    pub instances: u32,
    /// No blur/noise/low JPEG quality (JPEG 95).
    #[arg(long)]
    pub clean: bool,
    /// Camera heights above the road, metres (default 4,18: elevated traffic cameras; e.g.
    /// 1.2,4 for street-level and dashboard views).
    #[arg(long, value_delimiter = ',', value_name = "MIN,MAX")]
    pub camera_height: Option<Vec<f64>>,
    /// Camera pitch below the horizon, degrees (default 8,60; e.g. 0,12 at street level).
    #[arg(long, value_delimiter = ',', value_name = "MIN,MAX")]
    pub pitch: Option<Vec<f64>>,
    /// Size of the vehicle in the frame: its projected 3D box's larger side, pixels (default
    /// 50,300; e.g. 12,50 for far vehicles, which the network sees up-sampled). The range holds
    /// where each vehicle is placed; its lane-keeping jitter moves the size by up to ~15 %.
    #[arg(long, value_delimiter = ',', value_name = "MIN,MAX")]
    pub box_px: Option<Vec<f64>>,
}

#[derive(Debug, clap::Args)]
pub struct CropsArgs {
    /// Number of crops.
    #[arg(long)]
    pub count: u64,
    /// Output directory (created).
    #[arg(short = 'o', long = "output", alias = "out")]
    pub out: PathBuf,
    /// Random seed: the same seed gives the same crops.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    #[command(flatten)]
    pub bg: BgArgs,
    /// Also write sheet.png (the first 36 crops with their ground truth drawn).
    #[arg(long)]
    pub sheet: bool,
}

#[derive(Debug, clap::Args)]
pub struct SceneArgs {
    /// Road layout.
    #[arg(long, value_parser = parse_layout)]
    pub layout: LayoutKind,
    /// Number of frames.
    #[arg(long, default_value_t = 100)]
    pub frames: u32,
    /// Output root (gets dataset/<name>/ and results/<name>/).
    #[arg(short = 'o', long = "output", alias = "out")]
    pub out: PathBuf,
    /// Seed of the scene (camera, traffic, appearance).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Scene name (default: <layout>_s<seed>).
    #[arg(long)]
    pub name: Option<String>,
    /// Frame width in pixels.
    #[arg(long, default_value_t = 1280)]
    pub width: u32,
    /// Frame height in pixels.
    #[arg(long, default_value_t = 720)]
    pub height: u32,
    /// Frames per second of the video.
    #[arg(long, default_value_t = 25.0)]
    pub fps: f64,
    /// Focal length in pixels (default: drawn from the seed).
    #[arg(long)]
    pub focal: Option<f64>,
    /// Camera height above the road in metres (default: drawn from the seed).
    #[arg(long)]
    pub cam_height: Option<f64>,
    /// Pitch below the horizon in degrees (default: drawn from the seed).
    #[arg(long)]
    pub pitch: Option<f64>,
    /// Roll in degrees (default: drawn from the seed).
    #[arg(long, allow_hyphen_values = true)]
    pub roll: Option<f64>,
    /// Camera yaw relative to the road in degrees (default: drawn from the seed).
    #[arg(long, allow_hyphen_values = true)]
    pub yaw: Option<f64>,
    /// Samples per pixel along each axis: 3 (default) integrates over the pixel area as a
    /// camera sensor does; 1 is point sampling, whose pixel staircases pull nearly horizontal
    /// edges towards 0° (on the speed scenes the edgelets' roll then came out 0.5-1.4° flat).
    #[arg(long, default_value_t = 3)]
    pub supersample: u32,
    #[command(flatten)]
    pub output: OutputArgs,
}

#[derive(Debug, clap::Args)]
pub struct OutputArgs {
    /// Also write every frame as frames/NNNNNN.png.
    #[arg(long)]
    pub frames_dir: bool,
    /// Do not write video.mp4 (then use --frames-dir to get the frames).
    #[arg(long)]
    pub no_video: bool,
}

#[derive(Debug, clap::Args)]
pub struct SuiteArgs {
    /// Output root (gets dataset/<scene>/ and results/<scene>/ for every scene).
    #[arg(short = 'o', long = "output", alias = "out")]
    pub out: PathBuf,
    /// Frames per scene.
    /// Frames per scene (25 frames/s).
    #[arg(long, default_value_t = 150)]
    pub frames: u32,
    /// Seed of the suite's scenes.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Samples per pixel along each axis for every scene: 3 integrates over the pixel area as a
    /// camera sensor does (and as the training crops' 2); 1 is point sampling, whose pixel
    /// staircases pull nearly horizontal edges towards 0°.
    #[arg(long, default_value_t = 3)]
    pub supersample: u32,
    #[command(flatten)]
    pub output: OutputArgs,
}

#[derive(Debug, clap::Args)]
pub struct SheetArgs {
    /// Output PNG.
    #[arg(short = 'o', long = "output", alias = "out")]
    pub out: PathBuf,
    /// Read the crops from a `vpcal synth crops` directory instead of generating them.
    #[arg(long)]
    pub from: Option<PathBuf>,
    /// Number of crops shown.
    #[arg(long, default_value_t = 36)]
    pub count: usize,
    /// Crops per row (1-100).
    #[arg(long, default_value_t = 6,
          value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..=100))]
    pub cols: usize,
    /// Tile size in pixels (16-2048).
    #[arg(long, default_value_t = 220, value_parser = clap::value_parser!(u32).range(16..=2048))]
    pub cell: u32,
    /// Seed of the crops drawn.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Show the crops without the ground truth drawn over them.
    #[arg(long)]
    pub plain: bool,
    #[command(flatten)]
    pub bg: BgArgs,
}

#[derive(Debug, clap::Args)]
pub struct BenchArgs {
    /// Crops to generate.
    #[arg(long, default_value_t = 400)]
    pub count: u64,
    /// Frames to render per layout (0 skips the scene benchmark).
    #[arg(long, default_value_t = 30)]
    pub frames: u32,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    #[command(flatten)]
    pub bg: BgArgs,
}

fn parse_layout(s: &str) -> Result<LayoutKind, String> {
    s.parse()
}

fn bar(len: u64, what: &str) -> ProgressBar {
    let pb = ProgressBar::new(len);
    if let Ok(style) = ProgressStyle::with_template(&format!(
        "{what} {{bar:40}} {{pos}}/{{len}} [{{elapsed_precise}} eta {{eta}}] {{per_sec}}"
    )) {
        pb.set_style(style);
    }
    pb
}

fn generator(seed: u64, bg: &BgArgs) -> Result<CropGenerator> {
    if !(0.0..=1.0).contains(&bg.real_fraction) {
        bail!("--real-fraction {} must be within 0..1", bg.real_fraction);
    }
    let backgrounds = match &bg.real_bg {
        Some(root) => {
            let v = RealBackground::load_bcs_root(root)
                .with_context(|| format!("loading real backgrounds from {}", root.display()))?;
            if v.is_empty() {
                bail!("{}: no view with dataset/<v>/screen.png and results/<v>/system_dubska_bmvc14.json", root.display());
            }
            eprintln!(
                "real backgrounds: {}",
                v.iter()
                    .map(|b| b.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            );
            v
        }
        None => Vec::new(),
    };
    let defaults = CropConfig::default();
    let pair = |flag: &str, v: &Option<Vec<f64>>, default: [f64; 2]| match v.as_deref() {
        None => Ok(default),
        Some([a, b]) => Ok([*a, *b]),
        Some(other) => Err(anyhow::anyhow!(
            "{flag} takes two numbers MIN,MAX, got {} ({other:?})",
            other.len()
        )),
    };
    let cfg = CropConfig {
        real_fraction: bg.real_fraction,
        instances: bg.instances,
        artefacts: !bg.clean,
        height_m: pair("--camera-height", &bg.camera_height, defaults.height_m)?,
        pitch_deg: pair("--pitch", &bg.pitch, defaults.pitch_deg)?,
        box_px: pair("--box-px", &bg.box_px, defaults.box_px)?,
        ..defaults
    };
    Ok(CropGenerator::new(cfg, seed, Arc::new(backgrounds))?)
}

pub fn run(cmd: SynthCommand) -> Result<()> {
    match cmd {
        SynthCommand::Crops(a) => run_crops(&a),
        SynthCommand::Scene(a) => run_scene(&a),
        SynthCommand::Suite(a) => run_suite(&a),
        SynthCommand::Sheet(a) => run_sheet(&a),
        SynthCommand::Bench(a) => run_bench(&a),
    }
}

fn run_crops(a: &CropsArgs) -> Result<()> {
    if a.count == 0 {
        bail!("--count must be at least 1");
    }
    let generator = generator(a.seed, &a.bg)?;
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    let pb = bar(a.count, "crops");
    let t0 = Instant::now();
    vpcal_synth::write_crops(&a.out, &generator, a.count, &|n| pb.set_position(n))
        .with_context(|| format!("writing crops to {}", a.out.display()))?;
    pb.finish_and_clear();
    let dt = t0.elapsed().as_secs_f64();
    println!(
        "wrote {} crops to {} in {:.1} s ({:.1} crops/s on {} threads)",
        a.count,
        a.out.display(),
        dt,
        a.count as f64 / dt,
        rayon_threads()
    );
    if a.sheet {
        let src = vpcal_synth::CropDirSource::open(&a.out, vpcal_data::Split::Train)
            .context("re-reading the crops")?;
        let n = src.len().min(36);
        let samples = (0..n).map(|i| src.get(i)).collect::<Result<Vec<_>, _>>()?;
        let sheet = vpcal_synth::sheet::contact_sheet(&samples, 6, 220, true);
        let p = a.out.join("sheet.png");
        vpcal_video::draw::save_png(&sheet, &p)?;
        println!("contact sheet: {}", p.display());
    }
    Ok(())
}

fn rayon_threads() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

fn write_one(spec: &SceneSpec, out: &Path, output: &OutputArgs) -> Result<()> {
    let pb = bar(u64::from(spec.frames), &spec.name);
    let opts = WriteOptions {
        video: !output.no_video,
        frames_dir: output.frames_dir,
    };
    let summary = render_scene(spec, out, opts, &|k| pb.set_position(u64::from(k)))
        .with_context(|| format!("scene {}", spec.name))?;
    pb.finish_and_clear();
    println!(
        "{}: {} frames {}x{}, f = {:.0} px, {} detections; render {:.1} frames/s, total {:.1} s",
        summary.name,
        summary.frames,
        spec.width,
        spec.height,
        summary.focal_px,
        summary.detections,
        f64::from(summary.frames) / summary.render_s.max(1e-9),
        summary.total_s
    );
    Ok(())
}

fn run_scene(a: &SceneArgs) -> Result<()> {
    let name = a
        .name
        .clone()
        .unwrap_or_else(|| format!("{}_s{}", a.layout.name(), a.seed));
    let spec = SceneSpec {
        width: a.width,
        height: a.height,
        fps: a.fps,
        frames: a.frames,
        focal_px: a.focal,
        height_m: a.cam_height,
        pitch_deg: a.pitch,
        roll_deg: a.roll,
        yaw_rel_deg: a.yaw,
        supersample: a.supersample,
        ..SceneSpec::new(&name, a.layout, a.seed)
    };
    spec.validate()?;
    write_one(&spec, &a.out, &a.output)?;
    println!(
        "ground truth: {}/dataset/{name}/ and {}/results/{name}/",
        a.out.display(),
        a.out.display()
    );
    Ok(())
}

fn run_suite(a: &SuiteArgs) -> Result<()> {
    let mut specs = suite_specs(a.frames, a.seed);
    for spec in &mut specs {
        spec.supersample = a.supersample;
        spec.validate()?;
    }
    let t0 = Instant::now();
    for spec in &specs {
        write_one(spec, &a.out, &a.output)?;
    }
    println!(
        "suite: {} scenes in {:.1} s under {}",
        specs.len(),
        t0.elapsed().as_secs_f64(),
        a.out.display()
    );
    Ok(())
}

fn run_sheet(a: &SheetArgs) -> Result<()> {
    let samples = match &a.from {
        Some(dir) => {
            let mut v = Vec::new();
            for split in [
                vpcal_data::Split::Train,
                vpcal_data::Split::Validation,
                vpcal_data::Split::Test,
            ] {
                let src = vpcal_synth::CropDirSource::open(dir, split)?;
                for i in 0..src.len() {
                    if v.len() < a.count {
                        v.push(src.get(i)?);
                    }
                }
            }
            v
        }
        None => {
            let generator = generator(a.seed, &a.bg)?;
            let k = u64::from(generator.config().instances);
            // One instance per vehicle for variety.
            use rayon::prelude::*;
            (0..a.count as u64)
                .into_par_iter()
                .map(|i| generator.generate_index(i * k).map(|c| c.sample))
                .collect::<Result<Vec<_>, _>>()?
        }
    };
    if samples.is_empty() {
        bail!("no crops to show");
    }
    let sheet = vpcal_synth::sheet::contact_sheet(&samples, a.cols, a.cell, !a.plain);
    vpcal_video::draw::save_png(&sheet, &a.out)?;
    println!(
        "contact sheet of {} crops: {}",
        samples.len(),
        a.out.display()
    );
    Ok(())
}

fn run_bench(a: &BenchArgs) -> Result<()> {
    use rayon::prelude::*;
    let generator = generator(a.seed, &a.bg)?;
    if a.count > 0 {
        let t0 = Instant::now();
        let pixels: u64 = (0..a.count)
            .into_par_iter()
            .map(|i| {
                generator
                    .generate_index(i)
                    .map(|c| u64::from(c.sample.image.width()) * u64::from(c.sample.image.height()))
            })
            .collect::<Result<Vec<_>, _>>()?
            .iter()
            .sum();
        let dt = t0.elapsed().as_secs_f64();
        println!(
            "crops: {} in {:.2} s = {:.1} crops/s on {} threads (mean crop {:.0} px^2)",
            a.count,
            dt,
            a.count as f64 / dt,
            rayon_threads(),
            (pixels as f64 / a.count as f64).sqrt()
        );
    }
    if a.frames > 0 {
        for layout in LayoutKind::ALL {
            for (w, h) in [(1280u32, 720u32), (1920, 1080)] {
                let spec = SceneSpec {
                    width: w,
                    height: h,
                    frames: a.frames,
                    ..SceneSpec::new("bench", layout, a.seed)
                };
                let t0 = Instant::now();
                let mut r = vpcal_synth::scene::SceneRenderer::new(&spec)?;
                let setup = t0.elapsed().as_secs_f64();
                let t1 = Instant::now();
                for _ in 0..a.frames {
                    r.next_frame();
                }
                let dt = t1.elapsed().as_secs_f64();
                println!(
                    "scene {:>12} {w}x{h}: setup {:.2} s, {:.1} frames/s",
                    layout.name(),
                    setup,
                    f64::from(a.frames) / dt
                );
            }
        }
    }
    Ok(())
}
