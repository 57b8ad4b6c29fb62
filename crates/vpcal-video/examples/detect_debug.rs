//! Runs the motion detector and the per-frame filter over a video, image folder or image and
//! writes pictures with the boxes drawn (green: kept, red: dropped by the filter), plus a
//! summary. For looking at what the detector does on real footage.
//!
//! ```text
//! cargo run --release -p vpcal-video --example detect_debug -- INPUT OUT_DIR \
//!     [--every K] [--max-frames N] [--mask MASK.png] [--pictures N] [--detections FILE]
//! ```
//! `--motion-config JSON` overrides motion settings, e.g. '{"min_difference": 15}'.
//! `--detections FILE` draws boxes from a detections file instead of the motion detector.

use std::path::PathBuf;
use std::time::Instant;

use vpcal_video::detect::{Detector, FileDetector, MotionConfig, MotionDetector};
use vpcal_video::draw::{draw_boxes, save_png, DROPPED, KEPT};
use vpcal_video::filter::{FilterConfig, FrameFilter};
use vpcal_video::{open_source, SourceOptions};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let mut positional = Vec::new();
    let mut opts = SourceOptions::default();
    let mut mask = None;
    let mut detections = None;
    let mut pictures = 8u64;
    let mut motion_config = MotionConfig::default();
    while let Some(a) = args.next() {
        let mut value = || args.next().ok_or(format!("{a} needs a value"));
        match a.as_str() {
            "--every" => opts.every = value()?.parse()?,
            "--max-frames" => opts.max_frames = Some(value()?.parse()?),
            "--mask" => mask = Some(PathBuf::from(value()?)),
            "--pictures" => pictures = value()?.parse()?,
            "--detections" => detections = Some(PathBuf::from(value()?)),
            "--motion-config" => motion_config = serde_json::from_str(&value()?)?,
            _ => positional.push(PathBuf::from(a)),
        }
    }
    let [input, out_dir] = positional.as_slice() else {
        return Err("usage: detect_debug INPUT OUT_DIR [--every K] [--max-frames N] [--mask PNG] [--pictures N] [--detections FILE]".into());
    };
    std::fs::create_dir_all(out_dir)?;
    let source = open_source(input, &opts)?;
    let info = source.info().clone();
    let expected = info.expected_frames(&opts).unwrap_or(1000);
    let pic_every = (expected / pictures.max(1)).max(1);
    let mut file_detector = match &detections {
        Some(p) => Some(FileDetector::open(p)?),
        None => None,
    };
    let mut motion = MotionDetector::new(motion_config)?;
    if let Some(m) = &mask {
        motion = motion.with_road_mask(vpcal_video::detect::motion::load_road_mask(m)?, m);
    }
    let mut filter = FrameFilter::new(FilterConfig::default());
    let (mut frames, mut raw, mut kept) = (0u64, 0usize, 0usize);
    let mut scores = Vec::new();
    let mut areas = Vec::new();
    let (mut t_detect, mut t_filter) = (0f64, 0f64);
    let start = Instant::now();
    let mut sheet = Vec::new();
    let mut masks = Vec::new();
    for (k, frame) in source.enumerate() {
        let frame = frame?;
        let t0 = Instant::now();
        let dets = match file_detector.as_mut() {
            Some(d) => d.detect(&frame)?,
            None => motion.detect(&frame)?,
        };
        let t1 = Instant::now();
        raw += dets.len();
        let res = filter.apply(&frame, dets);
        t_detect += (t1 - t0).as_secs_f64();
        t_filter += t1.elapsed().as_secs_f64();
        kept += res.kept.len();
        for d in &res.kept {
            scores.push(d.score);
            areas.push(d.bbox.width() * d.bbox.height() / f64::from(info.width * info.height));
        }
        frames += 1;
        if (k as u64) % pic_every == pic_every / 2 {
            let mut boxes: Vec<_> = res.dropped.iter().map(|(d, _)| (d.bbox, DROPPED)).collect();
            boxes.extend(res.kept.iter().map(|d| (d.bbox, KEPT)));
            let img = draw_boxes(&frame.image, &boxes);
            let path = out_dir.join(format!("frame_{:06}.png", frame.index));
            save_png(&img, &path)?;
            sheet.push(img);
            if let (Some(fg), Some(bg)) = (motion.last_foreground(), motion.background()) {
                let fg = image::DynamicImage::ImageLuma8(fg.clone()).into_rgb8();
                let mut pair = image::RgbImage::new(fg.width() * 2, fg.height());
                image::imageops::replace(&mut pair, &bg, 0, 0);
                image::imageops::replace(&mut pair, &fg, i64::from(fg.width()), 0);
                save_png(
                    &pair,
                    &out_dir.join(format!("model_{:06}.png", frame.index)),
                )?;
                masks.push(pair);
            }
            println!(
                "{}: {} kept, {} dropped ({:?})",
                path.display(),
                res.kept.len(),
                res.dropped.len(),
                res.dropped.iter().map(|(_, r)| *r).collect::<Vec<_>>()
            );
        }
    }
    let wall = start.elapsed().as_secs_f64();
    if !sheet.is_empty() {
        save_png(&contact_sheet(&sheet, 3), &out_dir.join("sheet.png"))?;
    }
    if !masks.is_empty() {
        save_png(&contact_sheet(&masks, 2), &out_dir.join("masks.png"))?;
    }
    scores.sort_by(f32::total_cmp);
    areas.sort_by(f64::total_cmp);
    let med = |v: &[f32]| v.get(v.len() / 2).copied().unwrap_or(f32::NAN);
    println!(
        "{}: {}x{}, {frames} frames in {wall:.1} s; detector {:.1} ms/frame, filter {:.1} ms/frame; \
         {raw} boxes, {kept} kept ({:.2}/frame); median score {:.2}; median box area {:.4} of the frame",
        input.display(),
        info.width,
        info.height,
        1000.0 * t_detect / frames.max(1) as f64,
        1000.0 * t_filter / frames.max(1) as f64,
        kept as f64 / frames.max(1) as f64,
        med(&scores),
        areas.get(areas.len() / 2).copied().unwrap_or(f64::NAN),
    );
    Ok(())
}

/// Tiles pictures `cols` to a row (all have the frame size).
fn contact_sheet(images: &[image::RgbImage], cols: usize) -> image::RgbImage {
    let (w, h) = images[0].dimensions();
    let rows = images.len().div_ceil(cols);
    let mut out = image::RgbImage::new(w * cols as u32, h * rows as u32);
    for (i, img) in images.iter().enumerate() {
        let (x, y) = (
            (i % cols) as i64 * i64::from(w),
            (i / cols) as i64 * i64::from(h),
        );
        image::imageops::replace(&mut out, img, x, y);
    }
    out
}
