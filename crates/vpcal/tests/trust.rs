#![allow(clippy::unwrap_used, clippy::expect_used)]
//! Numbers a person can trust (issue 41): usage errors exit 2 naming the flag, outputs never
//! replace inputs or each other, `measure` refuses pixels it cannot measure, files whose
//! camera fields disagree are refused, `vpcal scale` leaves a file that describes itself, and
//! `vpcal speeds` measures saved tracks again.

use crate::common;

use common::{read_calibration, real_data, stderr, vpcal};
use std::path::{Path, PathBuf};

#[test]
fn values_out_of_range_are_usage_errors_naming_the_flag() {
    for (args, flag) in [
        (
            &["calibrate", "clip.mp4", "-o", "c.json", "--every", "0"][..],
            "--every",
        ),
        (
            &["calibrate", "clip.mp4", "-o", "c.json", "--max-frames", "0"],
            "--max-frames",
        ),
        (
            &["calibrate", "clip.mp4", "-o", "c.json", "--focal=-100"],
            "--focal",
        ),
        (
            &["calibrate", "clip.mp4", "-o", "c.json", "--focal", "-100"],
            "--focal",
        ),
        (
            &["calibrate", "clip.mp4", "-o", "c.json", "--fps", "0"],
            "--fps",
        ),
        (
            &["scale", "c.json", "--points", "1,2,3,4", "--distance", "0"],
            "--distance",
        ),
        (
            &["aggregate", "v.json", "-o", "c.json", "--focal", "-5"],
            "--focal",
        ),
    ] {
        let out = vpcal(args);
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains(flag), "{args:?}: {err}");
        assert!(!err.contains("unexpected argument"), "{args:?}: {err}");
    }
}

#[test]
fn outputs_never_replace_the_input_or_each_other() {
    let tmp = tempfile::tempdir().unwrap();
    let input = tmp.path().join("in.png");
    image::RgbImage::from_pixel(64, 48, image::Rgb([90, 90, 90]))
        .save(&input)
        .unwrap();
    let before = std::fs::read(&input).unwrap();
    let p = |name: &str| tmp.path().join(name).to_string_lossy().into_owned();
    let inp = input.to_string_lossy().into_owned();
    for args in [
        vec!["calibrate", &inp, "-o", &inp],
        vec!["calibrate", &inp, "-o", &p("c.json"), "--overlay", &inp],
        vec![
            "calibrate",
            &inp,
            "-o",
            &p("x.json"),
            "--bcs-json",
            &p("x.json"),
        ],
    ] {
        let out = vpcal(&args);
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
        assert!(
            err.contains("overwritten") || err.contains("the same file"),
            "{args:?}: {err}"
        );
    }
    assert_eq!(std::fs::read(&input).unwrap(), before);
    assert!(!tmp.path().join("x.json").exists() && !tmp.path().join("c.json").exists());
}

/// A calibration of a real BrnoCompSpeed view from a public CNN's per-vehicle VPs.
fn real_calibration(dir: &Path) -> Option<PathBuf> {
    let bcs = real_data("bcs")?;
    let vpout = common::vpout_file(bcs.parent()?, "session1_right", "_1.0s_");
    let path = dir.join("calib.json");
    let out = vpcal(&[
        "aggregate",
        vpout.to_str().unwrap(),
        "--pp",
        "bcs",
        "-o",
        path.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    Some(path)
}

#[test]
fn measure_refuses_pixels_off_the_road_and_files_that_contradict_themselves() {
    let tmp = tempfile::tempdir().unwrap();
    let Some(calib) = real_calibration(tmp.path()) else {
        return;
    };
    let c = calib.to_str().unwrap();
    let file = read_calibration(&calib);
    let [w, h] = file.image_size;
    let below = format!("{},{}", w / 2, h - 10);
    assert!(vpcal(&["measure", c, "--at", &below]).status.success());
    // Outside the frame: exit 1 with the reason, nothing on stdout.
    let outside = format!("{},{}", w + 100, h - 10);
    let out = vpcal(&["measure", c, "--at", &outside]);
    assert_eq!(out.status.code(), Some(1));
    assert!(stderr(&out).contains("outside the"), "{}", stderr(&out));
    assert!(out.stdout.is_empty());
    // A view whose horizon crosses the frame at row 200: above it, refused; five rows
    // below it, measured with a warning.
    let level = tmp.path().join("level.json");
    let cal = vpcal_geom::camera::Calibration::from_vps(
        vpcal_geom::Point2::new(700.0, 200.0),
        vpcal_geom::Point2::new(5000.0, 200.0),
        vpcal_geom::Point2::new(960.0, 540.0),
    )
    .unwrap();
    let input = vpcal_formats::calib::InputSummary {
        width: 1920,
        height: 1080,
        ..Default::default()
    };
    vpcal_formats::calib::CalibrationFile::calibrated(input, &cal)
        .write(&level)
        .unwrap();
    let l = level.to_str().unwrap();
    let out = vpcal(&["measure", l, "--at", "960,150"]);
    assert_eq!(out.status.code(), Some(1));
    assert!(
        stderr(&out).contains("above the horizon"),
        "{}",
        stderr(&out)
    );
    assert!(out.stdout.is_empty());
    let out = vpcal(&["measure", l, "--at", "960,205"]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(
        stderr(&out).contains("5.0 px below the horizon"),
        "{}",
        stderr(&out)
    );
    // An edited focal length that the VPs do not say, or a negative one: refused.
    let text = std::fs::read_to_string(&calib).unwrap();
    let mut doc: serde_json::Value = serde_json::from_str(&text).unwrap();
    for bad in [serde_json::json!(1234.5), serde_json::json!(-100.0)] {
        doc["focal_px"] = bad;
        let edited = tmp.path().join("edited.json");
        std::fs::write(&edited, serde_json::to_string(&doc).unwrap()).unwrap();
        for cmd in [
            vec!["measure", edited.to_str().unwrap(), "--at", &below],
            vec![
                "export",
                edited.to_str().unwrap(),
                "--opencv",
                "/tmp/never.yml",
            ],
        ] {
            let out = vpcal(&cmd);
            assert_eq!(out.status.code(), Some(1), "{cmd:?}");
            assert!(stderr(&out).contains("focal_px"), "{}", stderr(&out));
        }
    }
}

#[test]
fn scale_rewrites_the_summary_and_warnings_and_speeds_remeasures_tracks() {
    let tmp = tempfile::tempdir().unwrap();
    let Some(calib) = real_calibration(tmp.path()) else {
        return;
    };
    let c = calib.to_str().unwrap();
    let before = read_calibration(&calib);
    assert_eq!(
        before.scale_source.as_deref(),
        Some("vehicles"),
        "aggregate scales too"
    );
    assert!(before
        .warnings
        .iter()
        .any(|w| w.starts_with("the metric scale is automatic")));
    let [w, h] = before.image_size;
    let (x, y) = (f64::from(w) / 2.0, f64::from(h) - 20.0);
    let pts = format!("{},{},{},{}", x - 100.0, y, x + 100.0, y);
    let out = vpcal(&["scale", c, "--points", &pts, "--distance", "3.5"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let after = read_calibration(&calib);
    assert_eq!(after.scale_source.as_deref(), Some("distance"));
    assert!(
        after.warnings.iter().all(|w| !w.contains("automatic")),
        "{:?}",
        after.warnings
    );
    let summary = after.summary.unwrap();
    assert!(!summary.contains("as 4.4 x 1.8"), "{summary}");
    assert!(
        summary.contains("from 1 known length (distance)"),
        "{summary}"
    );
    // Tracks saved by an earlier run, measured with the scaled calibration: a vehicle
    // crossing 10 rows of the frame per frame at 25 frames/s.
    let csv = tmp.path().join("tracks.csv");
    let mut rows = String::from("id,frame,time_s,x_px,y_px,clipped\n");
    for f in 0..30 {
        rows.push_str(&format!(
            "1,{f},{},{},{},0\n",
            f64::from(f) / 25.0,
            x,
            f64::from(h) - 40.0 - f64::from(f) * 2.0
        ));
    }
    std::fs::write(&csv, rows).unwrap();
    let again = tmp.path().join("again.json");
    let out = vpcal(&[
        "speeds",
        c,
        csv.to_str().unwrap(),
        "-o",
        again.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let doc = common::read_json(&again);
    let t = &doc["tracks"][0];
    let kmh = t["speed_kmh"].as_f64().unwrap();
    assert!(kmh > 0.0, "{t}");
    assert!(t["speed_uncertainty_kmh"].as_f64().unwrap() > 0.0, "{t}");
    // The tracks file of the input may not be replaced by the output.
    let out = vpcal(&[
        "speeds",
        c,
        csv.to_str().unwrap(),
        "-o",
        csv.to_str().unwrap(),
    ]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
}
