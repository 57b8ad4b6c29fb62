//! `vpcal bench-pipeline` (hidden): end-to-end frames/s of `calibrate` on a clip, and where
//! the time goes: decode, detect, filter, crop, edgelets, network, background (the pipeline's own
//! stage clocks), then the aggregation and the tracks. Takes `calibrate`'s pipeline flags.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Result;
use clap::Args as ClapArgs;
use vpcal::output;

#[derive(Debug, ClapArgs)]
#[command(after_help = "Example:\n  \
    vpcal bench-pipeline clip.mp4 --max-frames 300          # frames/s and per-stage time")]
pub struct Args {
    /// A video, an image folder or an image (as `calibrate`).
    pub input: PathBuf,
    #[command(flatten)]
    pub pipeline: super::calibrate::PipelineArgs,
    /// Print the results as JSON.
    #[arg(long)]
    pub json: bool,
}

pub fn run(a: Args) -> Result<()> {
    let config = a.pipeline.config()?;
    let bar = super::FrameBar::new("frames", a.pipeline.quiet);
    let t0 = Instant::now();
    let out = vpcal::run_pipeline(&a.input, &config, &bar)?;
    let pipeline_s = t0.elapsed().as_secs_f64();
    let t = Instant::now();
    let result = vpcal::calibrate(&out, &config);
    let aggregate_s = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let curved = result
        .as_ref()
        .ok()
        .and_then(|(_, agg)| agg.robust_evidence.as_ref())
        .is_some_and(|e| e.road_curved);
    let (tracks, _) = output::run_tracks(&out, None, result.is_ok(), curved);
    let tracks_s = t.elapsed().as_secs_f64();
    let total_s = t0.elapsed().as_secs_f64();
    let s = &out.stats;
    let frames = s.frames;
    let mut rows: Vec<(&str, f64)> = s.stages.named().to_vec();
    let other = pipeline_s - rows.iter().map(|(_, v)| v).sum::<f64>();
    rows.push(("other (planning, records)", other.max(0.0)));
    rows.push(("aggregate", aggregate_s));
    rows.push(("tracks", tracks_s));
    let fps = frames as f64 / total_s;
    if a.json {
        let stages: serde_json::Map<String, serde_json::Value> = rows
            .iter()
            .map(|(k, v)| (k.to_string(), serde_json::json!(v)))
            .collect();
        println!(
            "{}",
            serde_json::to_string_pretty(&serde_json::json!({
                "input": a.input.display().to_string(),
                "width": out.info.width,
                "height": out.info.height,
                "frames": frames,
                "replayed_frames": s.replayed_frames,
                "crops": s.crops,
                "vehicle_boxes": out.boxes.len(),
                "tracks": tracks.len(),
                "detector": out.detector,
                "calibrated": result.is_ok(),
                "seconds": total_s,
                "frames_per_s": fps,
                "stage_seconds": stages,
            }))?
        );
        return Ok(());
    }
    println!(
        "{}: {frames} frames {}x{} ({} replayed), {} crops for the network, {} tracks; {}",
        a.input.display(),
        out.info.width,
        out.info.height,
        s.replayed_frames,
        s.crops,
        tracks.len(),
        if result.is_ok() {
            "calibrated"
        } else {
            "not calibrated"
        }
    );
    println!(
        "{:<26} {:>9} {:>11} {:>7}",
        "stage", "seconds", "ms/frame", "share"
    );
    for (name, v) in &rows {
        println!(
            "{name:<26} {v:>9.2} {:>11.1} {:>6.1}%",
            1e3 * v / frames.max(1) as f64,
            100.0 * v / total_s
        );
    }
    println!(
        "{:<26} {total_s:>9.2} {:>11.1}   {fps:.2} frames/s end to end",
        "total",
        1e3 * total_s / frames.max(1) as f64
    );
    Ok(())
}
