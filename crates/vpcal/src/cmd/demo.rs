//! `vpcal demo`: the whole method on a synthetic clip whose camera is known.
//!
//! Renders a seeded traffic scene (`vpcal-synth`), runs the `calibrate` pipeline on its video
//! with the default (learned) vehicle detector and the bundled model, and compares the result
//! with the true camera: focal length, horizon, and the BrnoCompSpeed pure-calibration ratio error of the
//! scene's ground-truth road distances.

use std::path::PathBuf;

use anyhow::{Context, Result};
use vpcal::output;
use vpcal::overlay;
use vpcal_formats::bcs::{read_gt, read_system};
use vpcal_formats::calib::{DemoComparison, RatioErrors};
use vpcal_geom::aggregate::line_angle_diff;
use vpcal_geom::camera::Calibration;
use vpcal_geom::metrics::{optimal_scale, ratio_errors, scaled_distance_errors, summarize};
use vpcal_synth::scene::{render_scene, SceneSpec, WriteOptions};
use vpcal_synth::world::LayoutKind;

use super::calibrate::{self, PipelineArgs};
use super::Exit;

/// Render a synthetic traffic clip with a known camera, calibrate it and compare.
#[derive(Debug, clap::Args)]
#[command(
    after_help = "Example:\n  vpcal demo --seed 5 --layout curve -o demo-curve\n\n\
Exit codes: 0 done; 1 an error; 2 a wrong command line; 3 the clip could not support a \
calibration."
)]
pub struct Args {
    /// Output folder: the scene (dataset/, results/), calib.json and overlay.png.
    #[arg(
        short = 'o',
        long = "output",
        alias = "out",
        default_value = "vpcal-demo"
    )]
    pub out: PathBuf,
    /// Seed of the scene (camera, traffic, appearance).
    #[arg(long, default_value_t = 3)]
    pub seed: u64,
    /// Road layout: highway, curve, intersection or parking.
    #[arg(long, default_value = "highway", value_parser = parse_layout)]
    pub layout: LayoutKind,
    /// Frames to render (25 frames/s).
    #[arg(long, default_value_t = 300)]
    pub frames: u32,
    /// Frame size WxH.
    #[arg(long, value_parser = super::args::size, default_value = "1280x720")]
    pub size: (u32, u32),
    /// Use the scene's true vehicle boxes instead of a detector.
    #[arg(long)]
    pub true_boxes: bool,
    #[command(flatten)]
    pub pipeline: PipelineArgs,
}

fn parse_layout(s: &str) -> Result<LayoutKind, String> {
    s.parse()
}

pub fn run(mut a: Args) -> Result<Exit> {
    let name = format!("demo_{}_s{}", a.layout.name(), a.seed);
    let mut spec = SceneSpec::new(&name, a.layout, a.seed);
    spec.frames = a.frames;
    spec.width = a.size.0;
    spec.height = a.size.1;
    spec.validate()?;
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;

    eprintln!(
        "rendering {} frames of a {} scene (seed {}) into {}",
        a.frames,
        a.layout.name(),
        a.seed,
        a.out.display()
    );
    let pb = super::progress_bar(Some(u64::from(a.frames)), "render", a.pipeline.quiet);
    let summary = render_scene(
        &spec,
        &a.out,
        WriteOptions {
            video: true,
            frames_dir: false,
        },
        &|n| pb.set_position(u64::from(n)),
    )?;
    pb.finish_and_clear();
    eprintln!(
        "rendered in {:.1} s ({:.1} frames/s)",
        summary.render_s,
        f64::from(summary.frames) / summary.render_s.max(1e-9)
    );
    let dataset = a.out.join("dataset").join(&name);
    let results = a.out.join("results").join(&name);
    let video = dataset.join("video.mp4");
    if a.true_boxes {
        a.pipeline.detect.detections = Some(dataset.join("detections.csv"));
    }
    // The synthetic camera's principal point is the image centre, the pipeline's default.
    let config = a.pipeline.config()?;
    let bar = super::FrameBar::new("frames", a.pipeline.quiet);
    let out = vpcal::run_pipeline(&video, &config, &bar)?;
    let result = vpcal::calibrate(&out, &config);
    calibrate::print_summary(&out, &result);

    let truth_sys = read_system(&results.join("system_groundtruth.json"))?;
    let t = &truth_sys.calibration;
    let truth = Calibration::from_vps(t.vp1, t.vp2, t.pp)
        .map_err(|e| anyhow::anyhow!("the scene's true camera: {e}"))?;
    let gt = read_gt(&dataset)?;
    let measurements = gt.road_measurements();

    let (cal, agg) = match result {
        Ok(r) => r,
        Err(e) => {
            eprintln!("vpcal demo: no calibration: {e:#}");
            return Ok(Exit::NotEnoughEvidence);
        }
    };
    let ratio = ratio_errors(&cal, &measurements)
        .and_then(|v| summarize(&v))
        .context("the ground-truth road points cannot be projected with the estimate")?;
    // Lines have no direction: the difference folded to within 90°.
    let horizon_diff = line_angle_diff(cal.horizon.angle() - truth.horizon.angle()).to_degrees();
    // Horizon height at the image centre, as a fraction of the image height.
    let cx = f64::from(out.info.width) / 2.0;
    let hy = |c: &Calibration| c.horizon.y_at(cx).unwrap_or(f64::NAN);
    let focal_err = (cal.focal_px / truth.focal_px - 1.0) * 100.0;

    let auto = vpcal::autoscale::vehicle_scale(&out, &cal, a.seed);
    let best_scale = optimal_scale(&cal, &measurements);
    let scale_err = auto
        .as_ref()
        .zip(best_scale)
        .map(|(s, b)| (s.m_per_unit / b - 1.0) * 100.0);
    let distance_err = auto
        .as_ref()
        .and_then(|s| scaled_distance_errors(&cal, s.m_per_unit, &measurements))
        .and_then(|v| vpcal_geom::solve::median(&v));
    let mut doc = output::calibration_file(&out, &config, &cal, &agg);
    doc.demo = Some(DemoComparison {
        scene: name.clone(),
        true_focal_px: truth.focal_px,
        focal_error_pct: focal_err,
        true_vp1: [truth.vp1.x, truth.vp1.y],
        true_vp2: [truth.vp2.x, truth.vp2.y],
        horizon_angle_error_deg: horizon_diff,
        horizon_y_at_centre: cal.horizon.y_at(cx),
        true_horizon_y_at_centre: truth.horizon.y_at(cx),
        bcs_ratio_error_pct: RatioErrors {
            mean: ratio.mean,
            median: ratio.median,
            p95: ratio.p95,
            max: ratio.max,
            pairs: ratio.n,
        },
        scale_error_pct: scale_err,
        distance_error_pct: distance_err,
    });
    doc.write(&a.out.join("calib.json"))?;
    output::write_bcs_system(&results.join("system_vpcal.json"), &cal, None)?;
    let overlay_path = a.out.join("overlay.png");
    if let Some(picture) = &out.picture {
        let img = overlay::draw(picture, &cal, &out.records, &agg.track_lines);
        vpcal_video::draw::save_png(&img, &overlay_path)?;
    }

    println!();
    println!("                      estimate      truth");
    println!(
        "focal length (px)   {:>10.1} {:>10.1}   ({focal_err:+.1} %)",
        cal.focal_px, truth.focal_px
    );
    println!(
        "horizon angle (deg) {:>10.2} {:>10.2}   ({horizon_diff:+.2}°)",
        cal.horizon.angle().to_degrees(),
        truth.horizon.angle().to_degrees()
    );
    println!(
        "horizon y at centre {:>10.1} {:>10.1}",
        hy(&cal),
        hy(&truth)
    );
    println!(
        "BCS ratio error: mean {:.2} %, median {:.2} %, p95 {:.2} %, max {:.2} % over {} distance pairs",
        ratio.mean, ratio.median, ratio.p95, ratio.max, ratio.n
    );
    match (&auto, best_scale, scale_err, distance_err) {
        (Some(s), Some(b), Some(e), Some(d)) => println!(
            "automatic scale: {:.4} m/unit from {} vehicles' sizes, best for this camera {b:.4} \
             ({e:+.1} %); road distances with it: median error {d:.1} %",
            s.m_per_unit, s.vehicles
        ),
        _ => println!("automatic scale: none (too few vehicles fit a car-shaped box)"),
    }
    println!(
        "wrote {}, {} and {}",
        a.out.join("calib.json").display(),
        overlay_path.display(),
        results.join("system_vpcal.json").display()
    );
    Ok(Exit::Success)
}
