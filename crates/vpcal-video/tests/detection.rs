//! Detectors, the per-frame filter, OpenCV-compatible Canny and crops: synthetic scenes with
//! known answers, golden files made by OpenCV (scripts/make_canny_golden.py), and the real data
//! in `$VPCAL_DATA` (skipped when absent).
#![allow(clippy::unwrap_used, clippy::expect_used)]

use crate::common;

use std::path::{Path, PathBuf};

use image::{GrayImage, Rgb, RgbImage};
use vpcal_geom::BoxPx;
use vpcal_video::crop::{integer_box, CropFilter, CropResizer};
use vpcal_video::detect::file::{write_detections, DetectionFormat};
use vpcal_video::detect::{iou, Detection, Detector, FileDetector, MotionConfig, MotionDetector};
use vpcal_video::edges::canny_opencv;
use vpcal_video::filter::{FilterConfig, FrameFilter};
use vpcal_video::{open_source, Frame, SourceOptions, VideoError};

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name)
}

use common::data_dir;

// ---------------------------------------------------------------- synthetic traffic scene

/// A 640x360 road with texture and noise; a "car" (a 60x30 box with a windscreen) drives from
/// left to right at 8 px per frame; 25 fps.
struct Scene {
    rng: u64,
}

impl Scene {
    fn noise(&mut self) -> i32 {
        self.rng = self
            .rng
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((self.rng >> 33) % 9) as i32 - 4
    }

    fn car_box(k: u64) -> BoxPx {
        let x0 = 40.0 + 8.0 * k as f64;
        BoxPx::new(x0, 200.0, x0 + 60.0, 230.0)
    }

    fn frame(&mut self, k: u64, with_car: bool, brightness: i32) -> Frame {
        let mut img = RgbImage::new(640, 360);
        for (x, y, p) in img.enumerate_pixels_mut() {
            let base = 110 + ((x / 7 + y / 5) % 3) as i32 * 6 + brightness;
            let v = base.clamp(0, 255) as u8;
            *p = Rgb([v, v, (v as i32 + 8).min(255) as u8]);
        }
        if with_car {
            let b = Self::car_box(k);
            for y in b.y0 as u32..b.y1 as u32 {
                for x in b.x0 as u32..b.x1 as u32 {
                    if x < 640 {
                        let windscreen = (x as f64) > b.x0 + 40.0 && (x as f64) < b.x0 + 50.0;
                        let c = if windscreen {
                            Rgb([40, 50, 70])
                        } else {
                            Rgb([200, 30, 30])
                        };
                        img.put_pixel(x, y, c);
                    }
                }
            }
        }
        for p in img.pixels_mut() {
            for c in 0..3 {
                p[c] = (i32::from(p[c]) + self.noise()).clamp(0, 255) as u8;
            }
        }
        Frame {
            index: k,
            time_s: k as f64 / 25.0,
            image: img,
        }
    }
}

#[test]
fn motion_detector_finds_a_moving_car_and_hugs_it() {
    let mut scene = Scene { rng: 1 };
    let mut det = MotionDetector::new(MotionConfig::default()).unwrap();
    let mut hits = 0;
    let mut frames_with_car = 0;
    for k in 0..120u64 {
        // The car appears after the warm-up (3 s = 75 frames).
        let with_car = k >= 76;
        let frame = scene.frame(k - if with_car { 76 } else { 0 }, with_car, 0);
        let frame = Frame {
            index: k,
            time_s: k as f64 / 25.0,
            ..frame
        };
        let dets = det.detect(&frame).unwrap();
        if !with_car {
            assert!(dets.is_empty(), "frame {k}: false detections {dets:?}");
            continue;
        }
        let truth = Scene::car_box(k - 76);
        if truth.x1 > 630.0 {
            continue;
        }
        frames_with_car += 1;
        if let Some(d) = dets.iter().find(|d| iou(&d.bbox, &truth) > 0.75) {
            hits += 1;
            assert!(d.score > 0.5 && d.score <= 1.0, "score {}", d.score);
        }
        assert!(dets.len() <= 1, "frame {k}: {dets:?}");
    }
    assert!(
        hits as f64 >= 0.9 * frames_with_car as f64,
        "{hits} of {frames_with_car}"
    );
}

#[test]
fn motion_detector_replays_its_warm_up_frames_with_the_background_they_built() {
    // The car drives from the first frame, so the whole of its pass falls in the warm-up
    // (10 frames over 3 s): the main pass sees nothing of it, the replay finds it.
    let mut scene = Scene { rng: 7 };
    let frames: Vec<Frame> = (0..90u64).map(|k| scene.frame(k, true, 0)).collect();
    let mut det = MotionDetector::new(MotionConfig::default()).unwrap();
    for frame in &frames {
        let learning = det.learned_until().is_none();
        assert_eq!(det.replay().is_some(), !learning, "frame {}", frame.index);
        let dets = det.detect(frame).unwrap();
        if det.learned_until().is_none() {
            assert!(dets.is_empty(), "frame {}: {dets:?}", frame.index);
        }
    }
    let until = det.learned_until().expect("the warm-up ended");
    assert!((60..=80).contains(&until), "warm-up ended at frame {until}");
    let mut replay = det.replay().expect("a replay detector");
    assert_eq!(
        replay.learned_until(),
        None,
        "the replay learns nothing new"
    );
    let (mut hits, mut visible) = (0, 0);
    for frame in frames.iter().take_while(|f| f.index < until) {
        let dets = replay.detect(frame).unwrap();
        let truth = Scene::car_box(frame.index);
        assert!(dets.len() <= 1, "frame {}: {dets:?}", frame.index);
        if truth.x1 > 630.0 {
            continue;
        }
        visible += 1;
        hits += usize::from(dets.iter().any(|d| iou(&d.bbox, &truth) > 0.75));
    }
    assert!(visible > 50, "{visible}");
    assert!(hits as f64 >= 0.9 * visible as f64, "{hits} of {visible}");
}

#[test]
fn motion_detector_ignores_global_brightness_and_masked_areas() {
    // A sudden exposure change of +30 on every pixel is not motion.
    let mut scene = Scene { rng: 2 };
    let mut det = MotionDetector::new(MotionConfig::default()).unwrap();
    for k in 0..100u64 {
        let frame = scene.frame(0, false, if k >= 80 { 30 } else { 0 });
        let frame = Frame {
            index: k,
            time_s: k as f64 / 25.0,
            ..frame
        };
        assert!(det.detect(&frame).unwrap().is_empty(), "frame {k}");
    }
    // A road mask that excludes the car's lane hides it.
    let mask = GrayImage::from_fn(1280, 720, |_, y| {
        image::Luma([if y < 300 { 255 } else { 0 }])
    });
    let mut det = MotionDetector::new(MotionConfig::default())
        .unwrap()
        .with_road_mask(mask, "mask.png");
    let mut scene = Scene { rng: 3 };
    for k in 0..120u64 {
        let with_car = k >= 76;
        let frame = scene.frame(k.saturating_sub(76), with_car, 0);
        let frame = Frame {
            index: k,
            time_s: k as f64 / 25.0,
            ..frame
        };
        assert!(det.detect(&frame).unwrap().is_empty(), "frame {k}");
    }
    // A mask of another shape is refused with its name.
    let bad = GrayImage::from_pixel(100, 100, image::Luma([255]));
    let mut det = MotionDetector::new(MotionConfig::default())
        .unwrap()
        .with_road_mask(bad, "bad_mask.png");
    let err = det
        .detect(&Scene { rng: 4 }.frame(0, false, 0))
        .unwrap_err();
    assert!(err.to_string().contains("bad_mask.png"), "{err}");
}

#[test]
fn motion_detector_on_a_real_highway_clip_gives_plausible_boxes() {
    let Some(data) = data_dir() else { return };
    let clip = data.join("traffic_video/bgslibrary_video03_cdnet_highway_320x240.avi");
    if !clip.exists()
        || std::process::Command::new("ffmpeg")
            .arg("-version")
            .output()
            .is_err()
    {
        eprintln!("SKIP: {} or ffmpeg missing", clip.display());
        return;
    }
    let opts = SourceOptions {
        every: 4,
        ..SourceOptions::default()
    };
    let mut det = MotionDetector::new(MotionConfig::default()).unwrap();
    let mut filter = FrameFilter::new(FilterConfig::default());
    let (mut frames, mut with_boxes, mut boxes) = (0, 0, 0);
    for frame in open_source(&clip, &opts).unwrap() {
        let frame = frame.unwrap();
        let kept = filter.apply(&frame, det.detect(&frame).unwrap()).kept;
        frames += 1;
        if !kept.is_empty() {
            with_boxes += 1;
        }
        for d in &kept {
            boxes += 1;
            let b = d.bbox;
            assert!(
                b.x0 >= 0.0 && b.y0 >= 0.0 && b.x1 <= 320.0 && b.y1 <= 240.0,
                "{b:?}"
            );
            // Vehicles on this highway are between ~8 and ~120 px wide.
            assert!(b.width() >= 4.0 && b.width() <= 200.0, "{b:?}");
            assert!((0.0..=1.0).contains(&d.score));
        }
    }
    // The highway is busy: after the 3 s warm-up, most processed frames show a vehicle.
    eprintln!("{frames} frames, {with_boxes} with boxes, {boxes} boxes");
    assert!(
        with_boxes as f64 > 0.5 * frames as f64,
        "{with_boxes} of {frames}"
    );
}

// ---------------------------------------------------------------- detections files

fn det(x0: f64, y0: f64, x1: f64, y1: f64, score: f32) -> Detection {
    Detection {
        bbox: BoxPx::new(x0, y0, x1, y1),
        score,
    }
}

#[test]
fn csv_and_json_detection_files_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let rows = vec![
        (0u64, det(10.0, 20.0, 50.5, 60.25, 0.9)),
        (0, det(100.0, 20.0, 150.0, 60.0, 0.4)),
        (7, det(1.0, 2.0, 3.0, 4.0, 0.5)),
    ];
    for name in ["d.csv", "d.json"] {
        let path = dir.path().join(name);
        write_detections(&path, &rows).unwrap();
        let mut fd = FileDetector::open(&path).unwrap();
        assert_eq!(
            fd.format(),
            if name.ends_with("csv") {
                DetectionFormat::Csv
            } else {
                DetectionFormat::Json
            }
        );
        assert_eq!(fd.frames().collect::<Vec<_>>(), vec![0, 7]);
        assert_eq!(fd.box_count(), 3);
        let frame = Frame {
            index: 0,
            time_s: 0.0,
            image: RgbImage::new(200, 100),
        };
        let got = fd.detect(&frame).unwrap();
        assert_eq!(got, vec![rows[0].1, rows[1].1]);
        let none = fd.detect(&Frame { index: 3, ..frame }).unwrap();
        assert!(none.is_empty());
    }
}

#[test]
fn malformed_detection_files_name_the_line() {
    let dir = tempfile::tempdir().unwrap();
    let cases: &[(&str, &str, &str)] = &[
        (
            "a.csv",
            "frame,x0,y0,x1,y1,score\n0,1,2,3,4,0.5\n1,1,2,3\n",
            "line 3",
        ),
        ("b.csv", "0,1,2,3,4,0.5\n-1,1,2,3,4,0.5\n", "line 2"),
        ("c.csv", "# comment\n\n0,5,2,3,4,0.5\n", "line 3"),
        ("d.csv", "0,1,2,3,4,abc\n", "score"),
        ("e.json", "[{\"frame\": 0, \"x0\": 1}]", "line 1"),
        ("f.json", "{\"frame\": 0}", "JSON list"),
    ];
    for (name, text, expect) in cases {
        let path = dir.path().join(name);
        std::fs::write(&path, text).unwrap();
        let err = FileDetector::open(&path).unwrap_err();
        assert!(
            matches!(err, VideoError::DetectionFile { .. }),
            "{name}: {err}"
        );
        let msg = err.to_string();
        assert!(msg.contains(expect) && msg.contains(name), "{name}: {msg}");
    }
    let missing = FileDetector::open(&dir.path().join("none.csv")).unwrap_err();
    assert!(matches!(missing, VideoError::Io { .. }));
}

#[test]
fn reference_detections_map_frame_cnt_to_zero_based_frames() {
    let Some(data) = data_dir() else { return };
    let path = data.join("bcs/dataset/session0_center/detections.json");
    if !path.exists() {
        eprintln!("SKIP: {} absent", path.display());
        return;
    }
    let mut fd = FileDetector::open(&path).unwrap();
    assert_eq!(fd.format(), DetectionFormat::Reference);
    let frames: Vec<u64> = fd.frames().collect();
    // frame_cnt 10, 20, ... 15000 -> 0-based 9, 19, ... 14999.
    assert_eq!(frames.len(), 1500);
    assert_eq!(frames[0], 9);
    assert_eq!(frames[3], 39);
    assert_eq!(*frames.last().unwrap(), 14999);
    let frame = Frame {
        index: 39,
        time_s: 0.0,
        image: RgbImage::new(1920, 1080),
    };
    let got = fd.detect(&frame).unwrap();
    assert_eq!(got.len(), 2);
    // The first box of frame_cnt 40: [ymin, xmin, ymax, xmax] normalised.
    let b = [
        0.4385480284690857,
        0.21754090487957,
        0.5421082973480225,
        0.27849507331848145,
    ];
    let ib = integer_box(&got[0].bbox, 1920, 1080).unwrap();
    assert_eq!(ib.x0, (1920.0 * b[1]) as u32);
    assert_eq!(ib.y0, (1080.0 * b[0]) as u32);
    assert_eq!(ib.x1, (1920.0 * b[3] + 1.0) as u32);
    assert_eq!(ib.y1, (1080.0 * b[2] + 1.0) as u32);
    assert!((got[0].score - 0.5152385).abs() < 1e-6);
}

// ---------------------------------------------------------------- Canny and crops

fn load_gray(name: &str) -> GrayImage {
    image::open(fixture(name)).unwrap().into_luma8()
}

#[test]
fn canny_matches_opencv_on_the_golden_image() {
    let input = load_gray("canny_input.png");
    for (lo, hi, golden) in [
        (100.0, 200.0, "canny_opencv_100_200.png"),
        (30.0, 90.0, "canny_opencv_30_90.png"),
    ] {
        let expected = load_gray(golden);
        let ours = canny_opencv(&input, lo, hi);
        let differ = ours
            .iter()
            .zip(expected.iter())
            .filter(|(a, b)| a != b)
            .count();
        let edges = expected.iter().filter(|&&v| v > 0).count();
        assert!(edges > 100, "the golden image has edges");
        assert_eq!(
            differ, 0,
            "{golden}: {differ} pixels differ from OpenCV ({edges} edges)"
        );
        // imageproc's Canny (Gaussian blur first, L2 magnitude) finds fewer edges at the same
        // thresholds: this is why the reference rule needs OpenCV's variant.
        let ip = imageproc::edges::canny(&input, lo, hi);
        let ip_edges = ip.iter().filter(|&&v| v > 0).count();
        eprintln!("{golden}: OpenCV {edges} edges, imageproc {ip_edges}");
    }
}

#[test]
fn crops_match_opencv_resize_and_return_the_integer_box() {
    let g = load_gray("canny_input.png");
    let rgb = RgbImage::from_fn(g.width(), g.height(), |x, y| {
        let v = g.get_pixel(x, y)[0];
        Rgb([v, 255 - v, v / 2])
    });
    // Rows 5..40, columns 10..50 as a continuous box whose reference integer box is that.
    let bbox = BoxPx::new(10.0, 5.0, 49.0, 39.0);
    // fast_image_resize renormalises the kernel at the crop border where OpenCV replicates
    // the border pixels: the cubic results differ by a few levels in the outermost pixels.
    for (filter, golden, tol, mean_tol) in [
        (CropFilter::OpenCvLinear, "crop_opencv_linear.png", 1.0, 0.5),
        (CropFilter::OpenCvCubic, "crop_opencv_cubic.png", 4.0, 0.5),
    ] {
        let expected = image::open(fixture(golden)).unwrap().into_rgb8();
        let mut cr = CropResizer::new(128, filter).unwrap();
        let mut out = vec![0f32; cr.crop_len()];
        let got_box = cr.crop_into(&rgb, &bbox, &mut out).unwrap().unwrap();
        assert_eq!(got_box, BoxPx::new(10.0, 5.0, 50.0, 40.0));
        let (mut max_diff, mut sum) = (0f32, 0f32);
        for (i, p) in expected.pixels().enumerate() {
            for c in 0..3 {
                let d = (out[c * 128 * 128 + i] * 255.0 - f32::from(p[c])).abs();
                max_diff = max_diff.max(d);
                sum += d;
            }
        }
        let mean = sum / (3.0 * 128.0 * 128.0);
        eprintln!("{golden}: max difference {max_diff}, mean {mean}");
        assert!(
            max_diff <= tol && mean <= mean_tol,
            "{golden}: max {max_diff}, mean {mean}"
        );
    }
    // The default bicubic filter on a flat region gives the flat colour.
    let flat = RgbImage::from_pixel(300, 200, Rgb([255, 51, 0]));
    let mut cr = CropResizer::new(128, CropFilter::default()).unwrap();
    let batch = cr
        .crop_batch(
            &flat,
            &[
                BoxPx::new(20.0, 30.0, 220.0, 150.0),
                BoxPx::new(400.0, 0.0, 500.0, 10.0),
            ],
        )
        .unwrap();
    assert_eq!(batch.len(), 1, "the second box misses the frame");
    assert_eq!(batch.source, vec![0]);
    assert_eq!(batch.images.len(), 3 * 128 * 128);
    let plane = 128 * 128;
    assert!(batch.images[..plane]
        .iter()
        .all(|&v| (v - 1.0).abs() < 1e-6));
    assert!(batch.images[plane..2 * plane]
        .iter()
        .all(|&v| (v - 0.2).abs() < 1e-6));
    assert!(batch.images[2 * plane..].iter().all(|&v| v.abs() < 1e-6));
    assert_eq!(batch.boxes[0], BoxPx::new(20.0, 30.0, 221.0, 151.0));
}
