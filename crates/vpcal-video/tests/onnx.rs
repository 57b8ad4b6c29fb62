//! The ONNX detector (feature `onnx`) on tiny models written by scripts/make_onnx_fixtures.py:
//! their scores are mean(image) × (1.0, 0.9, 0.2) for three fixed boxes, the first two
//! overlapping (IoU 0.88).
#![cfg(feature = "onnx")]
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::{Path, PathBuf};

use image::{Rgb, RgbImage};
use vpcal_video::detect::{Detector, OnnxConfig, OnnxDetector, OnnxLayout};
use vpcal_video::{Frame, VideoError};

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
