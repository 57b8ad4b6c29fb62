//! `vpcal detect`: the vehicle boxes a detector finds in footage, as a detections file that
//! `calibrate --detector file:PATH` reads back (CSV or JSON rows of frame, box, score).
//!
//! For looking at a detector's output, measuring its recall against true boxes
//! (`scripts/detector_recall.py`) and its speed (`scripts/bench_detector.py`).

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use serde_json::json;
use vpcal_video::detect::file::write_detections;

use vpcal::detector::open_detector;
use vpcal::output::check_destination;

use super::calibrate::{DetectorArgs, FrameArgs};

#[derive(Debug, clap::Args)]
#[command(
    after_help = "Example:\n  vpcal detect clip.mp4 -o boxes.csv --picture boxes.png --max-frames 100\n\n\
Exit codes: 0 done; 1 an error; 2 a wrong command line."
)]
pub struct Args {
    /// Video file (anything FFmpeg reads), folder of images, or one image.
    pub input: PathBuf,
    /// Write the detections here (`.csv`: frame,x0,y0,x1,y1,score; other names: JSON).
    #[arg(short, long, value_name = "FILE")]
    pub output: PathBuf,
    #[command(flatten)]
    pub detect: DetectorArgs,
    #[command(flatten)]
    pub frames: FrameArgs,
    /// Also draw the boxes of the processed frame with the most of them (PNG), to check the
    /// detector by eye.
    #[arg(long, value_name = "PNG")]
    pub picture: Option<PathBuf>,
    /// Print a JSON summary (frames, boxes, seconds, detector) on stdout.
    #[arg(long)]
    pub json: bool,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
}

pub fn run(a: Args) -> Result<()> {
    check_destination("--output", &a.output)?;
    if let Some(p) = &a.picture {
        check_destination("--picture", p)?;
    }
    let options = a.frames.options();
    let mut source = a.frames.open(&a.input)?;
    let info = source.info().clone();
    let mut detector = open_detector(&a.detect.settings()?, &info)?;
    let pb = super::progress_bar(info.expected_frames(&options), "frames", a.quiet);
    let t0 = Instant::now();
    let mut rows = Vec::new();
    let mut frames = 0u64;
    let mut detect_s = 0.0;
    // The frame with the most boxes so far, for --picture.
    let mut busiest: Option<(usize, image::RgbImage, Vec<vpcal_geom::BoxPx>)> = None;
    // Frames go to the detector as many at a time as it gains from (YOLOX: two, whose
    // regions fill two cores where one frame's three leave one idle); the boxes are those of
    // one frame at a time.
    let batch = detector.batch_frames().max(1);
    let mut pending: Vec<vpcal_video::Frame> = Vec::with_capacity(batch);
    let mut source_done = false;
    while !source_done {
        while pending.len() < batch {
            let Some(frame) = source.next() else {
                source_done = true;
                break;
            };
            pending.push(frame.with_context(|| format!("reading {}", a.input.display()))?);
        }
        if pending.is_empty() {
            break;
        }
        let t = Instant::now();
        let results = detector.detect_batch(&pending);
        detect_s += t.elapsed().as_secs_f64();
        for (frame, dets) in pending.drain(..).zip(results) {
            let dets =
                dets.with_context(|| format!("detecting vehicles in frame {}", frame.index))?;
            frames += 1;
            if a.picture.is_some() && busiest.as_ref().is_none_or(|(n, _, _)| dets.len() > *n) {
                let boxes = dets.iter().map(|d| d.bbox).collect();
                busiest = Some((dets.len(), frame.image.clone(), boxes));
            }
            rows.extend(dets.into_iter().map(|d| (frame.index, d)));
            pb.inc(1);
        }
        pb.set_message(format!("{} boxes", rows.len()));
    }
    pb.finish_and_clear();
    for w in source.warnings() {
        eprintln!("warning: {}: {w}", a.input.display());
    }
    if frames == 0 {
        bail!("{}: no frames to process", a.input.display());
    }
    write_detections(&a.output, &rows)?;
    if let (Some(path), Some((_, image, boxes))) = (&a.picture, &busiest) {
        let colored: Vec<_> = boxes
            .iter()
            .map(|b| (*b, image::Rgb([255, 40, 40])))
            .collect();
        vpcal_video::draw::save_png(&vpcal_video::draw::draw_boxes(image, &colored), path)?;
    }
    let summary = json!({
        "input": a.input.display().to_string(),
        "image_size": [info.width, info.height],
        "detector": detector.name(),
        "frames": frames,
        "boxes": rows.len(),
        "seconds": t0.elapsed().as_secs_f64(),
        "detector_seconds": detect_s,
        "detector_frames_per_s": frames as f64 / detect_s.max(1e-9),
    });
    eprintln!(
        "vpcal detect: {} boxes in {frames} frames ({}x{}), {:.2} frames/s in the detector ({}); wrote {}",
        rows.len(),
        info.width,
        info.height,
        frames as f64 / detect_s.max(1e-9),
        detector.name(),
        a.output.display()
    );
    if a.json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    }
    Ok(())
}
