//! Throughput of the frame-source, detection, filter and crop stages on one input.
//!
//! ```text
//! ffmpeg -f lavfi -i testsrc2=size=1920x1080:rate=25 -t 60 -c:v libx264 -preset veryfast \
//!        -pix_fmt yuv420p /tmp/bench1080.mp4
//! cargo run --release -p vpcal-video --example bench -- /tmp/bench1080.mp4 [--every K] [--stage S]
//! ```
//! Stages: `decode` (frames through the pipe only), `motion` (decode + motion detector),
//! `filter` (decode + static-vehicle filter on 10 boxes per frame), `crop` (decode + 10
//! crops per frame), `all` (each in turn; the default). Times are per processed frame; the
//! decode time is subtracted from the other stages. For peak memory run it under
//! `/usr/bin/time -v`.

use std::path::PathBuf;
use std::time::Instant;

use vpcal_geom::BoxPx;
use vpcal_video::crop::{CropFilter, CropResizer};
use vpcal_video::detect::{Detection, Detector, MotionConfig, MotionDetector};
use vpcal_video::filter::{FilterConfig, FrameFilter};
use vpcal_video::{open_source, SourceOptions};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let mut input = None;
    let mut opts = SourceOptions::default();
    let mut stage = "all".to_string();
    while let Some(a) = args.next() {
        match a.as_str() {
            "--every" => opts.every = args.next().ok_or("--every needs a value")?.parse()?,
            "--max-frames" => {
                opts.max_frames = Some(args.next().ok_or("--max-frames needs a value")?.parse()?)
            }
            "--stage" => stage = args.next().ok_or("--stage needs a value")?,
            _ => input = Some(PathBuf::from(a)),
        }
    }
    let input = input.ok_or("usage: bench INPUT [--every K] [--max-frames N] [--stage S]")?;
    let stages: Vec<&str> = if stage == "all" {
        vec!["decode", "motion", "filter", "crop"]
    } else {
        vec![stage.as_str()]
    };
    for stage in stages {
        let source = open_source(&input, &opts)?;
        let info = source.info().clone();
        let mut motion = MotionDetector::new(MotionConfig::default())?;
        let mut filter = FrameFilter::new(FilterConfig {
            min_score: None,
            ..FilterConfig::default()
        });
        let mut crops = CropResizer::new(128, CropFilter::default())?;
        let (w, h) = (f64::from(info.width), f64::from(info.height));
        // Ten boxes of a typical vehicle size spread over the frame.
        let boxes: Vec<BoxPx> = (0..10)
            .map(|k| {
                let x = w * (0.05 + 0.09 * f64::from(k));
                let y = h * (0.3 + 0.04 * f64::from(k));
                BoxPx::new(x, y, x + w * 0.08, y + h * 0.1)
            })
            .collect();
        let mut out = vec![0f32; crops.crop_len()];
        let (mut frames, mut stage_s, mut found) = (0u64, 0f64, 0usize);
        let start = Instant::now();
        for frame in source {
            let frame = frame?;
            frames += 1;
            let t = Instant::now();
            match stage {
                "motion" => found += motion.detect(&frame)?.len(),
                "filter" => {
                    let dets = boxes
                        .iter()
                        .map(|&b| Detection {
                            bbox: b,
                            score: 1.0,
                        })
                        .collect();
                    found += filter.apply(&frame, dets).kept.len();
                }
                "crop" => {
                    for b in &boxes {
                        if crops.crop_into(&frame.image, b, &mut out)?.is_some() {
                            found += 1;
                        }
                    }
                }
                _ => {}
            }
            stage_s += t.elapsed().as_secs_f64();
        }
        let wall = start.elapsed().as_secs_f64();
        let n = frames.max(1) as f64;
        println!(
            "{stage:>6}: {}x{} {frames} frames in {wall:.2} s = {:.1} frames/s overall; stage {:.2} ms/frame ({:.0} frames/s){}",
            info.width,
            info.height,
            n / wall,
            1000.0 * stage_s / n,
            if stage_s > 0.0 { n / stage_s } else { f64::INFINITY },
            match stage {
                "motion" => format!("; {found} boxes"),
                "crop" => format!("; {:.3} ms/crop", 1000.0 * stage_s / found.max(1) as f64),
                _ => String::new(),
            }
        );
    }
    Ok(())
}
