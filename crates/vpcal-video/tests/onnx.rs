//! The ONNX detector (feature `onnx`) on tiny models written by scripts/make_onnx_fixtures.py:
//! their scores are mean(image) × (1.0, 0.9, 0.2) for three fixed boxes, the first two
//! overlapping (IoU 0.88).
#![cfg(feature = "onnx")]
#![allow(clippy::unwrap_used, clippy::expect_used)]

use crate::common;

use std::path::{Path, PathBuf};

use image::{Rgb, RgbImage};
use vpcal_video::detect::{Detector, OnnxConfig, OnnxDetector, OnnxLayout};
use vpcal_video::{Detection, Frame, VideoError};

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name)
}

fn frame(w: u32, h: u32, v: u8) -> Frame {
    Frame {
        index: 0,
        time_s: 0.0,
        image: RgbImage::from_pixel(w, h, Rgb([v, v, v])),
    }
}

fn config(layout: OnnxLayout) -> OnnxConfig {
    OnnxConfig {
        layout,
        classes: None,
        ..OnnxConfig::default()
    }
}

#[test]
fn yolo_layout_scores_from_the_image_with_nms_and_scaling() {
    let mut d = OnnxDetector::open(&fixture("tiny_yolo.onnx"), config(OnnxLayout::Yolo)).unwrap();
    assert_eq!(d.input_size(), (32, 32));
    // White frame, 64x32: scores 1.0, 0.9, 0.2; box 1 is suppressed, box 2 under 0.25.
    let dets = d.detect(&frame(64, 32, 255)).unwrap();
    assert_eq!(dets.len(), 1, "{dets:?}");
    let b = dets[0].bbox;
    // Box 0: centre (10, 12), 8x6 in the 32x32 input -> x doubled in the 64-wide frame.
    assert!(
        (b.x0 - 12.0).abs() < 1e-4 && (b.x1 - 28.0).abs() < 1e-4,
        "{b:?}"
    );
    assert!(
        (b.y0 - 9.0).abs() < 1e-4 && (b.y1 - 15.0).abs() < 1e-4,
        "{b:?}"
    );
    assert!((dets[0].score - 1.0).abs() < 1e-5);
    // A darker frame gives proportionally lower scores: mean 0.2 -> 0.2, 0.18, 0.04: none pass.
    let dark = d.detect(&frame(64, 32, 51)).unwrap();
    assert!(dark.is_empty(), "{dark:?}");
    // Without NMS both overlapping boxes come back.
    let mut no_nms = OnnxDetector::open(
        &fixture("tiny_yolo.onnx"),
        OnnxConfig {
            nms_iou: 1.0,
            ..config(OnnxLayout::Yolo)
        },
    )
    .unwrap();
    assert_eq!(no_nms.detect(&frame(32, 32, 255)).unwrap().len(), 2);
    // Restricting to class 1 (always 0) finds nothing.
    let mut cls1 = OnnxDetector::open(
        &fixture("tiny_yolo.onnx"),
        OnnxConfig {
            classes: Some(vec![1]),
            ..config(OnnxLayout::Yolo)
        },
    )
    .unwrap();
    assert!(cls1.detect(&frame(32, 32, 255)).unwrap().is_empty());
}

#[test]
fn boxes_scores_layout() {
    let mut d = OnnxDetector::open(
        &fixture("tiny_boxes_scores.onnx"),
        config(OnnxLayout::BoxesScores),
    )
    .unwrap();
    let dets = d.detect(&frame(320, 320, 255)).unwrap();
    assert_eq!(dets.len(), 1);
    let b = dets[0].bbox;
    assert!(
        (b.x0 - 60.0).abs() < 1e-3 && (b.y1 - 150.0).abs() < 1e-3,
        "{b:?}"
    );
    // The wrong layout is a clear error, not garbage.
    let mut wrong =
        OnnxDetector::open(&fixture("tiny_boxes_scores.onnx"), config(OnnxLayout::Yolo)).unwrap();
    let err = wrong.detect(&frame(32, 32, 255)).unwrap_err();
    assert!(matches!(err, VideoError::Model { .. }), "{err}");
}

#[test]
fn a_file_that_is_not_onnx_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("model.onnx");
    std::fs::write(&path, b"definitely not protobuf").unwrap();
    let err = OnnxDetector::open(&path, OnnxConfig::default()).unwrap_err();
    assert!(matches!(err, VideoError::Model { .. }), "{err}");
    assert!(err.to_string().contains("model.onnx"));
    let err =
        OnnxDetector::open(&dir.path().join("missing.onnx"), OnnxConfig::default()).unwrap_err();
    assert!(matches!(err, VideoError::Io { .. }), "{err}");
}

// ------------------------------------------------- the bundled YOLOX-nano against onnxruntime

mod yolox {
    use super::common::data_dir;
    use super::*;
    use vpcal_video::detect::yolox::{
        Region, YoloxConfig, YoloxDetector, BUNDLED_YOLOX, BUNDLED_YOLOX_SHA1,
    };

    fn golden() -> serde_json::Value {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/golden/yolox.json");
        serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
    }

    fn num(v: &serde_json::Value) -> f64 {
        v.as_f64().unwrap()
    }

    /// Every golden case (scripts/yolox_goldens.py: onnxruntime on real frames, whole frames
    /// and tiles) decodes to the same boxes: corners within 0.5 px, scores within 1e-4.
    #[test]
    fn bundled_yolox_matches_onnxruntime_on_real_frames() {
        let Some(data) = data_dir() else { return };
        let g = golden();
        assert_eq!(g["model_sha1"].as_str(), Some(BUNDLED_YOLOX_SHA1));
        let config = YoloxConfig {
            classes: vec![2, 3, 5, 7],
            min_score: num(&g["min_score"]) as f32,
            nms_iou: num(&g["nms_iou"]),
            ..YoloxConfig::default()
        };
        let det = YoloxDetector::bundled(config.clone()).unwrap();
        assert_eq!(det.input_size(), 416);
        let mut compared = 0;
        let mut frames = std::collections::BTreeSet::new();
        for case in g["cases"].as_array().unwrap() {
            let rel = case["frame"].as_str().unwrap();
            let img = image::open(data.join(rel)).unwrap().to_rgb8();
            let r: Vec<u32> = case["region"]
                .as_array()
                .unwrap()
                .iter()
                .map(|v| v.as_u64().unwrap() as u32)
                .collect();
            let region = Region {
                x0: r[0],
                y0: r[1],
                width: r[2],
                height: r[3],
            };
            let (lb, cands) = det.candidates(&img, region).unwrap();
            assert_eq!(
                [lb.resized.0 as u64, lb.resized.1 as u64],
                [
                    case["resized"][0].as_u64().unwrap(),
                    case["resized"][1].as_u64().unwrap()
                ]
            );
            // The golden has no tile-border rule: map the region's candidates to the frame and
            // suppress, as a whole-frame pass of that region would.
            let dets: Vec<Detection> = cands
                .iter()
                .map(|c| Detection {
                    bbox: lb.to_frame(c.bbox),
                    score: c.score,
                })
                .collect();
            let ours = vpcal_video::detect::non_max_suppression(dets, config.nms_iou);
            let want = case["detections"].as_array().unwrap();
            assert_eq!(ours.len(), want.len(), "{rel} {r:?}: {ours:?}");
            for (o, w) in ours.iter().zip(want) {
                let b = &w["box"];
                let diffs = [
                    (o.bbox.x0 - num(&b[0])).abs(),
                    (o.bbox.y0 - num(&b[1])).abs(),
                    (o.bbox.x1 - num(&b[2])).abs(),
                    (o.bbox.y1 - num(&b[3])).abs(),
                ];
                assert!(diffs.iter().all(|d| *d < 0.5), "{rel} {r:?}: {o:?} vs {w}");
                assert!(
                    (f64::from(o.score) - num(&w["score"])).abs() < 1e-4,
                    "{rel} {r:?}: {o:?} vs {w}"
                );
                compared += 1;
            }
            frames.insert(rel.to_string());
        }
        assert!(frames.len() >= 2 && compared >= 10, "{frames:?} {compared}");
    }

    #[test]
    fn a_damaged_model_file_is_refused_with_its_sha1() {
        let mut bytes = BUNDLED_YOLOX.to_vec();
        bytes[1000] ^= 0xff;
        let e = YoloxDetector::from_bytes(
            &bytes,
            "damaged.onnx",
            Some(BUNDLED_YOLOX_SHA1),
            YoloxConfig::default(),
        )
        .unwrap_err();
        let msg = e.to_string();
        assert!(
            msg.contains("SHA-1")
                && msg.contains(BUNDLED_YOLOX_SHA1)
                && msg.contains("damaged.onnx"),
            "{msg}"
        );
        // Without the check, a truncated file is not a readable model.
        let e = YoloxDetector::from_bytes(&bytes[..5000], "cut.onnx", None, YoloxConfig::default())
            .unwrap_err();
        assert!(matches!(e, VideoError::Model { .. }), "{e}");
    }

    #[test]
    fn a_model_of_another_layout_is_refused() {
        let e =
            YoloxDetector::open(&fixture("tiny_yolo.onnx"), YoloxConfig::default()).unwrap_err();
        assert!(matches!(e, VideoError::Model { .. }), "{e}");
    }

    #[test]
    fn the_bundled_detector_finds_the_cars_of_a_real_frame_with_tiles() {
        let Some(data) = data_dir() else { return };
        let img = image::open(data.join("bcs/dataset/session0_center/screen.png"))
            .unwrap()
            .to_rgb8();
        let frame = Frame {
            index: 0,
            time_s: 0.0,
            image: img,
        };
        let mut whole = YoloxDetector::bundled(YoloxConfig::default()).unwrap();
        let mut tiled = YoloxDetector::bundled(YoloxConfig {
            tiles: 2,
            ..YoloxConfig::default()
        })
        .unwrap();
        let a = whole.detect(&frame).unwrap();
        let b = tiled.detect(&frame).unwrap();
        assert!(!a.is_empty());
        assert!(
            b.len() >= a.len(),
            "tiles {} < whole frame {}",
            b.len(),
            a.len()
        );
        assert!(tiled.name().contains("tiles"));
    }

    #[test]
    fn frames_detected_together_give_what_they_give_one_by_one() {
        let Some(data) = data_dir() else { return };
        let frames: Vec<Frame> = ["session0_center", "session1_left", "session2_right"]
            .iter()
            .enumerate()
            .map(|(i, v)| Frame {
                index: i as u64,
                time_s: i as f64,
                image: image::open(data.join(format!("bcs/dataset/{v}/screen.png")))
                    .unwrap()
                    .to_rgb8(),
            })
            .collect();
        for rotation in [false, true] {
            let config = YoloxConfig {
                tiles: 2,
                tile_rotation: rotation,
                ..YoloxConfig::default()
            };
            let mut one = YoloxDetector::bundled(config.clone()).unwrap();
            let mut together = YoloxDetector::bundled(config).unwrap();
            assert_eq!(together.batch_frames(), 2);
            let single: Vec<Vec<Detection>> =
                frames.iter().map(|f| one.detect(f).unwrap()).collect();
            let batched: Vec<Vec<Detection>> = together
                .detect_batch(&frames)
                .into_iter()
                .map(|r| r.unwrap())
                .collect();
            assert!(single.iter().all(|d| !d.is_empty()));
            assert_eq!(single, batched, "tile rotation {rotation}");
        }
    }
}
