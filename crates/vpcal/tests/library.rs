#![allow(clippy::unwrap_used, clippy::expect_used)]
//! The library in process: the pipeline, the calibration file and the OpenCV export, without
//! the binary.

use std::path::Path;

use vpcal::detector::DetectorChoice;
use vpcal::progress::Silent;
use vpcal::{calibrate, run_pipeline, CalibrationFile, PipelineConfig};
use vpcal_data::Split;
use vpcal_formats::bcs::read_system;
use vpcal_geom::camera::Calibration;
use vpcal_geom::rotation::{mat_vec, rotation_matrix};
use vpcal_geom::Point2;
use vpcal_synth::scene::{render_scene, SceneSpec, WriteOptions};
use vpcal_synth::world::LayoutKind;

/// A rendered 40-frame 320x240 highway clip (the demo's scene); its folder.
fn scene(dir: &Path) -> (std::path::PathBuf, Calibration) {
    scene_of(dir, 40)
}

fn scene_of(dir: &Path, frames: u32) -> (std::path::PathBuf, Calibration) {
    let mut spec = SceneSpec::new("lib", LayoutKind::Highway, 3);
    spec.frames = frames;
    spec.width = 320;
    spec.height = 240;
    let opts = WriteOptions {
        video: true,
        frames_dir: false,
    };
    render_scene(&spec, dir, opts, &|_| {}).unwrap();
    let t = read_system(&dir.join("results/lib/system_groundtruth.json")).unwrap();
    let c = t.calibration;
    (
        dir.join("dataset/lib"),
        Calibration::from_vps(c.vp1, c.vp2, c.pp).unwrap(),
    )
}

#[test]
fn the_pipeline_calibrates_a_synthetic_clip_in_process() {
    let dir = tempfile::tempdir().unwrap();
    let (dataset, truth) = scene(dir.path());
    let mut config = PipelineConfig::default();
    config.detector.choice = DetectorChoice::File(dataset.join("detections.csv"));
    config.bootstrap = 0;
    // A few crops per vehicle (the default above 960 px wide; this scene is smaller).
    config.crops = vpcal::pipeline::CropPolicy::Few;
    let out = run_pipeline(&dataset.join("video.mp4"), &config, &Silent).unwrap();
    assert_eq!(out.stats.frames, 40);
    // Every kept box is a record; a few per followed vehicle went through the network.
    assert_eq!(
        out.records.len() as u64,
        out.stats.crops + out.stats.crops_skipped
    );
    assert!(out.stats.crops_skipped > out.stats.crops, "{:?}", out.stats);
    assert_eq!(
        out.records
            .iter()
            .filter(|r| r.prediction.is_some())
            .count() as u64,
        out.stats.crops
    );
    // The boxes the network did not see carry their vehicle's VPs, copied, and their own
    // edgelets.
    let copied: Vec<_> = out
        .records
        .iter()
        .filter(|r| r.prediction.is_none())
        .collect();
    assert!(copied.iter().all(|r| r.to_vehicle().copied));
    assert!(
        copied.iter().filter(|r| r.vp1.is_finite()).count() * 10 >= copied.len() * 9,
        "most boxes not sent have their vehicle's VPs"
    );
    assert!(copied.iter().any(|r| !r.edgelets.is_empty()));
    let (cal, agg) = calibrate(&out, &config).unwrap();
    // The demo test's scene: within the same bounds.
    let focal_err = cal.focal_px / truth.focal_px - 1.0;
    assert!(
        focal_err.abs() < 0.15,
        "{} vs {}",
        cal.focal_px,
        truth.focal_px
    );
    // The calibration file is strict JSON and reads back as written.
    let file = vpcal::output::calibration_file(&out, &config, &cal, &agg);
    let text = file.to_json_string();
    assert!(!text.contains("Infinity") && !text.contains("NaN"));
    let back = CalibrationFile::from_json_str(&text, Path::new("calib.json")).unwrap();
    assert_eq!(back, file);
    assert_eq!(back.input.kind.as_deref(), Some("video"));
    assert_eq!(
        back.settings["detector"]
            .as_str()
            .map(|s| s.starts_with("file")),
        Some(true)
    );
    // A bad setting is refused before any work, naming the flag.
    let bad = PipelineConfig {
        batch: 0,
        ..config.clone()
    };
    let e = run_pipeline(&dataset.join("video.mp4"), &bad, &Silent).unwrap_err();
    assert!(format!("{e:#}").contains("--batch"), "{e:#}");
    let bad = PipelineConfig {
        min_crop_px: -1.0,
        ..config.clone()
    };
    let e = run_pipeline(&dataset.join("video.mp4"), &bad, &Silent).unwrap_err();
    assert!(format!("{e:#}").contains("--min-crop-px"), "{e:#}");

    // Cut with the road around every box: the same records and boxes (sizes, tracks and
    // edgelets use the detection's box), VPs decoded in the larger crops' frames.
    let wide_config = PipelineConfig {
        min_crop_px: 200.0,
        ..config.clone()
    };
    let out_wide = run_pipeline(&dataset.join("video.mp4"), &wide_config, &Silent).unwrap();
    assert_eq!(out_wide.records.len(), out.records.len());
    let seen = |o: &vpcal::PipelineOutput| -> Vec<_> {
        o.records
            .iter()
            .filter(|r| r.prediction.is_some())
            .map(|r| (r.frame, r.crop_box, r.vp1))
            .collect()
    };
    let (narrow, wide) = (seen(&out), seen(&out_wide));
    assert_eq!(narrow.len(), wide.len());
    assert!(narrow
        .iter()
        .zip(&wide)
        .all(|(a, b)| a.0 == b.0 && a.1 == b.1));
    assert!(
        narrow
            .iter()
            .zip(&wide)
            .any(|(a, b)| (a.2 - b.2).norm() > 1.0),
        "the network saw other crops"
    );
    assert_eq!(
        vpcal::output::calibration_file(&out_wide, &wide_config, &cal, &agg).settings
            ["min_crop_px"],
        serde_json::json!(200.0)
    );
}

/// Project road-frame points the way `cv2.projectPoints` does with zero distortion.
fn project(file: &CalibrationFile, q: [f64; 3]) -> Point2 {
    let cv = file.opencv.as_ref().unwrap();
    let c = mat_vec(&rotation_matrix(cv.rvec), q);
    let c = [c[0] + cv.tvec[0], c[1] + cv.tvec[1], c[2] + cv.tvec[2]];
    let k = cv.camera_matrix;
    Point2::new(
        k[0][0] * c[0] / c[2] + k[0][2],
        k[1][1] * c[1] / c[2] + k[1][2],
    )
}

#[test]
fn the_opencv_export_projects_road_points_where_measure_finds_them() {
    // f = 1000 px, pp (640, 360), horizon y = 0.
    let cal = Calibration::from_vps(
        Point2::new(840.0, 0.0),
        Point2::new(-5008.0, 0.0),
        Point2::new(640.0, 360.0),
    )
    .unwrap();
    let input = vpcal_formats::calib::InputSummary {
        width: 1280,
        height: 720,
        ..Default::default()
    };
    let mut file = CalibrationFile::calibrated(input, &cal);
    file.set_scale(0.35, None).unwrap();
    let h = file.camera_height_m.unwrap();
    assert!((h - 0.35 * cal.plane_distance()).abs() < 1e-12);
    let scale = file.scale_m_per_unit.unwrap();
    // Road points in metres along and across the road; their pixels' road distance (what
    // `vpcal measure` prints) is their distance.
    let points = [[5.0, -2.0], [30.0, 1.5], [12.0, 4.0], [60.0, -3.5]];
    for a in &points {
        for b in &points {
            let (pa, pb) = (
                project(&file, [a[0], a[1], 0.0]),
                project(&file, [b[0], b[1], 0.0]),
            );
            assert!(cal.sees_road(pa) && cal.sees_road(pb));
            let measured = cal.road_distance(pa, pb).unwrap() * scale;
            let truth = ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt();
            assert!(
                (measured - truth).abs() <= 1e-9 * truth.max(1.0),
                "{measured} vs {truth}"
            );
        }
    }
    // The camera centre is h above the road origin.
    let cv = file.opencv.as_ref().unwrap();
    let t = cv.tvec;
    assert!(((t[0] * t[0] + t[1] * t[1] + t[2] * t[2]).sqrt() - h).abs() < 1e-9);
}

/// The angle between the lines from `at` to `a` and to `b`, degrees (at most 90).
fn line_angle_deg(at: Point2, a: Point2, b: Point2) -> f64 {
    vpcal::label::direction_error_deg(at, a, b)
}

#[test]
fn label_writes_crops_whose_vp1_is_the_true_one_and_refuses_stills() {
    use vpcal::label::{label_footage, LabelSettings};
    use vpcal_data::SampleSource;
    let dir = tempfile::tempdir().unwrap();
    // Long enough for VP1 from tracks (the 40-frame clip has 3 straight tracks).
    let (dataset, truth) = scene_of(dir.path(), 150);
    let mut config = PipelineConfig::default();
    config.detector.choice = DetectorChoice::File(dataset.join("detections.csv"));
    config.bootstrap = 8;
    let out_dir = dir.path().join("labels");
    let settings = LabelSettings::default();
    let (report, records) = label_footage(
        &dataset.join("video.mp4"),
        "lib",
        &config,
        &settings,
        &out_dir,
        &Silent,
    )
    .unwrap();
    assert!(report.refused.is_none(), "{report:?}");
    assert!(
        report.vehicles >= 3 && report.crops == records.len(),
        "{report:?}"
    );
    assert!(records.len() <= report.vehicles * settings.max_per_track);
    // Every label's VP1, back in frame pixels, points where the true VP1 does.
    for r in &records {
        let vpcal_synth::SampleMeta::Real(m) = &r.meta else {
            panic!("not a real crop: {r:?}");
        };
        let o = Point2::from(m.crop_origin);
        let at = Point2::new(
            0.5 * (m.det_box[0] + m.det_box[2]),
            0.5 * (m.det_box[1] + m.det_box[3]),
        );
        assert!(m.det_box[3] - m.det_box[1] >= settings.min_box_height_px);
        let vp1 = Point2::from(r.vp1) + o;
        let err = line_angle_deg(at, vp1, truth.vp1);
        assert!(err < 1.5, "VP1 label {err:.2}° off at {at:?}");
        assert!(r.label_weight.iter().all(|w| (0.0..=1.0).contains(w)));
        assert!((m.vp1_sd_deg - report.track_residual_deg.unwrap()).abs() < 1e-12);
    }
    // The folder reads as training data once indexed.
    let cfg = serde_json::json!({"format": vpcal::label::LABEL_FORMAT, "version": 1});
    vpcal_synth::write_index(&out_dir, &cfg, &records).unwrap();
    let all: usize = [Split::Train, Split::Validation, Split::Test]
        .iter()
        .map(|&s| {
            let src = vpcal_synth::CropDirSource::open(&out_dir, s).unwrap();
            for i in 0..src.len() {
                let sample = src.get(i).unwrap();
                assert_eq!(sample.label_weight, src.records()[i].label_weight);
            }
            src.len()
        })
        .sum();
    assert_eq!(all, records.len());

    // One still has no tracks: refused, nothing written.
    let still_dir = dir.path().join("still");
    std::fs::create_dir_all(&still_dir).unwrap();
    image::RgbImage::from_pixel(320, 240, image::Rgb([120, 120, 120]))
        .save(still_dir.join("one.png"))
        .unwrap();
    let (report, records) = label_footage(
        &still_dir.join("one.png"),
        "still",
        &config,
        &settings,
        &dir.path().join("labels_still"),
        &Silent,
    )
    .unwrap();
    assert!(records.is_empty());
    assert!(
        report.refused.as_deref().unwrap_or("").contains("stills"),
        "{report:?}"
    );
}
