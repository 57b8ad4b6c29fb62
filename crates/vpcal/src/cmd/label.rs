//! `vpcal label`: self-labelled training crops from real footage of straight roads
//! ([`vpcal::label`]).

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use vpcal::label::{label_footage, CameraReport, LabelSettings, LABEL_FORMAT, LABEL_SD0_DEG};

use super::calibrate::PipelineArgs;
use super::{Exit, FrameBar, UsageError};

/// Label the vehicles of real footage with the VPs of the camera calibrated from it, as
/// training crops (`vpcal train --data synth-crops:DIR`).
#[derive(Debug, clap::Args)]
#[command(
    after_help = "Example:\n  vpcal label highway1.mp4 highway2.mp4 -o labelled-crops\n\n\
Exit codes: 0 done; 1 an error; 2 a wrong command line; 3 no input could be labelled."
)]
pub struct Args {
    /// Videos (or image folders with --fps) of fixed cameras; each is one camera, named after
    /// its file stem. Straight roads label best; curves and intersections by the tracks'
    /// tangents.
    #[arg(required = true)]
    pub inputs: Vec<PathBuf>,
    /// Folder for the crops (`images/<camera>/`), `samples.jsonl`, `config.json`,
    /// `FORMAT.md` and `label_report.json`. Must not hold labelled crops already.
    #[arg(short, long, value_name = "DIR")]
    pub output: PathBuf,
    /// At most this many crops per vehicle track, evenly spaced along it.
    #[arg(long, default_value_t = LabelSettings::default().max_per_track)]
    pub per_track: usize,
    /// Label only boxes at least this tall, pixels (the camera is fitted on all boxes either
    /// way). `calibrate` sends smaller boxes to the network too: on far or low-resolution
    /// cameras most vehicles are 10-24 px.
    #[arg(long, value_name = "PX", default_value_t = LabelSettings::default().min_box_height_px,
          value_parser = super::args::positive_f64)]
    pub min_box_height: f64,
    /// Refuse a camera whose straight tracks point at VP1 worse than this (median, degrees).
    #[arg(long, default_value_t = LabelSettings::default().max_track_residual_deg)]
    pub max_track_residual: f64,
    /// Label only the vehicles of straight tracks that head for the road's VP1, with the
    /// camera's VPs: no vehicle by its own track's tangent, and no camera whose straight tracks
    /// do not share one VP1 (curves, intersections).
    #[arg(long)]
    pub no_tangents: bool,
    #[command(flatten)]
    pub pipeline: PipelineArgs,
    /// Print the per-camera report as JSON on stdout.
    #[arg(long)]
    pub json: bool,
}

/// Run `vpcal label`.
pub fn run(a: Args) -> Result<Exit> {
    let config = a.pipeline.config()?;
    let settings = LabelSettings {
        max_per_track: a.per_track,
        min_box_height_px: a.min_box_height,
        max_track_residual_deg: a.max_track_residual,
        tangents: !a.no_tangents,
        ..LabelSettings::default()
    };
    if a.output.join("samples.jsonl").exists() {
        return Err(UsageError(format!(
            "-o {}: already holds labelled crops (samples.jsonl); choose another folder",
            a.output.display()
        ))
        .into());
    }
    let mut cameras: Vec<String> = Vec::new();
    for input in &a.inputs {
        let name = input
            .file_stem()
            .map(|s| s.to_string_lossy().to_string())
            .filter(|s| !s.is_empty())
            .with_context(|| format!("{}: no file name to name the camera", input.display()))?;
        if cameras.contains(&name) {
            bail!(
                "{}: a second input named {name:?}; camera names (file stems) must differ",
                input.display()
            );
        }
        cameras.push(name);
    }
    std::fs::create_dir_all(&a.output)
        .with_context(|| format!("creating {}", a.output.display()))?;
    let mut reports: Vec<CameraReport> = Vec::new();
    let mut records = Vec::new();
    for (input, camera) in a.inputs.iter().zip(&cameras) {
        let bar = FrameBar::new("label", a.pipeline.quiet);
        let (report, mut recs) = label_footage(input, camera, &config, &settings, &a.output, &bar)
            .with_context(|| format!("labelling {}", input.display()))?;
        print_report(&report);
        reports.push(report);
        records.append(&mut recs);
    }
    let labelled = reports.iter().filter(|r| r.refused.is_none()).count();
    let report_json = serde_json::json!({
        "format": "vpcal-label-report",
        "version": 1,
        "label_sd0_deg": LABEL_SD0_DEG,
        "cameras": reports,
    });
    let mut text = serde_json::to_string_pretty(&report_json)?;
    text.push('\n');
    vpcal_formats::fs::write_atomic(&a.output.join("label_report.json"), text.as_bytes())?;
    if labelled == 0 {
        eprintln!(
            "vpcal label: no camera could be labelled; {} has the reasons",
            a.output.join("label_report.json").display()
        );
        if a.json {
            println!("{}", serde_json::to_string_pretty(&report_json)?);
        }
        return Ok(Exit::NotEnoughEvidence);
    }
    let config_json = serde_json::json!({
        "format": LABEL_FORMAT,
        "version": 1,
        "cameras": cameras,
        "count": records.len(),
        "model": config.model.as_ref().map(|p| p.display().to_string()),
        "detector": format!("{:?}", config.detector.choice),
        "every": config.frames.every,
        "label_sd0_deg": LABEL_SD0_DEG,
        "min_box_height_px": settings.min_box_height_px,
        "per_track": settings.max_per_track,
    });
    vpcal_synth::write_index(&a.output, &config_json, &records)?;
    eprintln!(
        "vpcal label: {} crops of {} vehicles from {labelled} of {} cameras in {}",
        records.len(),
        reports.iter().map(|r| r.vehicles).sum::<usize>(),
        reports.len(),
        a.output.display()
    );
    if a.json {
        println!("{}", serde_json::to_string_pretty(&report_json)?);
    }
    Ok(Exit::Success)
}

fn print_report(r: &CameraReport) {
    let f = |v: Option<f64>, unit: &str| v.map_or("-".to_string(), |v| format!("{v:.2}{unit}"));
    eprintln!("vpcal label: {} ({})", r.camera, r.source);
    eprintln!(
        "  frames {}, boxes {}, tracks {}, labelled vehicles {} ({} by their track's tangent), \
         crops {}",
        r.frames, r.boxes, r.tracks, r.vehicles, r.tangent_vehicles, r.crops
    );
    eprintln!(
        "  camera: {} straight tracks at {} from VP1, horizon ±{}, focal {} ({})",
        r.track_lines.map_or("-".into(), |n| n.to_string()),
        f(r.track_residual_deg, "°"),
        f(r.horizon_sd_deg, "°"),
        f(r.focal_px, " px"),
        r.focal_source.as_deref().unwrap_or("-")
    );
    if let Some(t) = r.tangent_check_deg {
        eprintln!("  straight tracks' tangents miss VP1 by {t:.2}° (median)");
    }
    if let (None, Some(why)) = (&r.refused, &r.tangents_only) {
        eprintln!("  every vehicle by its track's tangent: {why}");
    }
    match &r.refused {
        Some(why) => eprintln!("  REFUSED: {why}"),
        None => eprintln!(
            "  labels: VP1 ±{}, VP2 ±{} (median), weights {}",
            f(r.vp1_sd_deg, "°"),
            f(r.vp2_sd_deg, "°"),
            r.label_weight
                .map_or("-".into(), |[a, b]| format!("{a:.2} / {b:.2}"))
        ),
    }
}
