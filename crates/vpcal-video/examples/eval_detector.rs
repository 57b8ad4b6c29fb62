//! Scores the motion detector (and the per-frame filter) against the true boxes of a
//! synthetic scene made by `vpcal synth scene` (its `vehicles.jsonl`).
//!
//! ```text
//! vpcal synth scene --layout highway --frames 250 --out /tmp/syn --seed 1 --width 960 --height 540
//! cargo run --release -p vpcal-video --example eval_detector -- /tmp/syn/dataset/highway_s1 \
//!     [--every K] [--motion-config JSON] [--no-filter]
//! ```
//! A true box counts when its vehicle moves, is at least 80 % visible, is at least 0.04 % of
//! the frame and does not touch the border. A detection is a hit when its IoU with such a box
//! is at least 0.5; it is a false alarm when its IoU with every true box (parked and occluded
//! ones included) is below 0.3. Prints recall, precision and the mean IoU of hits.

use std::collections::HashMap;
use std::path::PathBuf;

use vpcal_geom::BoxPx;
use vpcal_video::detect::{iou, Detector, MotionConfig, MotionDetector};
use vpcal_video::filter::{FilterConfig, FrameFilter};
use vpcal_video::{open_source, SourceOptions};

struct Truth {
    bbox: BoxPx,
    detectable: bool,
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let mut dir = None;
    let mut opts = SourceOptions::default();
    let mut config = MotionConfig::default();
    let mut use_filter = true;
    while let Some(a) = args.next() {
        match a.as_str() {
            "--every" => opts.every = args.next().ok_or("--every needs a value")?.parse()?,
            "--motion-config" => {
                config = serde_json::from_str(&args.next().ok_or("--motion-config needs JSON")?)?
            }
            "--no-filter" => use_filter = false,
            _ => dir = Some(PathBuf::from(a)),
        }
    }
    let dir = dir
        .ok_or("usage: eval_detector SCENE_DIR [--every K] [--motion-config JSON] [--no-filter]")?;
    let source = open_source(&dir.join("video.mp4"), &opts)?;
    let (w, h) = (
        f64::from(source.info().width),
        f64::from(source.info().height),
    );
    let mut truth: HashMap<u64, Vec<Truth>> = HashMap::new();
    for line in std::fs::read_to_string(dir.join("vehicles.jsonl"))?.lines() {
        let v: serde_json::Value = serde_json::from_str(line)?;
        let b: Vec<f64> = serde_json::from_value(v["box_clipped"].clone())?;
        let bbox = BoxPx::new(b[0], b[1], b[2], b[3]);
        let parked = v["parked"].as_bool().unwrap_or(false);
        let visible = v["visible_fraction"].as_f64().unwrap_or(0.0);
        let inside = bbox.x0 > 1.0 && bbox.y0 > 1.0 && bbox.x1 < w - 1.0 && bbox.y1 < h - 1.0;
        let big = bbox.width() * bbox.height() >= 0.0004 * w * h;
        let frame = v["frame"].as_u64().ok_or("frame")?;
        truth.entry(frame).or_default().push(Truth {
            bbox,
            detectable: !parked && visible >= 0.8 && inside && big,
        });
    }
    let mut det = MotionDetector::new(config)?;
    let mut filter = FrameFilter::new(FilterConfig::default());
    let (mut targets, mut found, mut dets, mut false_alarms) = (0usize, 0usize, 0usize, 0usize);
    let mut iou_sum = 0f64;
    let mut near_misses = 0usize;
    for frame in source {
        let frame = frame?;
        let raw = det.detect(&frame)?;
        if det.is_warming_up() {
            continue;
        }
        let kept = if use_filter {
            filter.apply(&frame, raw).kept
        } else {
            raw
        };
        let empty = Vec::new();
        let t = truth.get(&frame.index).unwrap_or(&empty);
        for tb in t.iter().filter(|t| t.detectable) {
            targets += 1;
            let best = kept
                .iter()
                .map(|d| iou(&d.bbox, &tb.bbox))
                .fold(0.0, f64::max);
            if best >= 0.5 {
                found += 1;
                iou_sum += best;
            } else if best >= 0.2 {
                near_misses += 1;
            }
        }
        for d in &kept {
            dets += 1;
            if t.iter().all(|tb| iou(&d.bbox, &tb.bbox) < 0.3) {
                false_alarms += 1;
            }
        }
    }
    println!(
        "{}: recall {:.3} ({found}/{targets}; {near_misses} misses have a box with IoU 0.2-0.5), precision {:.3} ({} of {dets} detections are not false alarms), mean IoU of hits {:.3}",
        dir.display(),
        found as f64 / targets.max(1) as f64,
        1.0 - false_alarms as f64 / dets.max(1) as f64,
        dets - false_alarms,
        iou_sum / found.max(1) as f64,
    );
    Ok(())
}
