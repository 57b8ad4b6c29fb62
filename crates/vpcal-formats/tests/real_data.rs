#![allow(clippy::unwrap_used, clippy::expect_used)]
//! The reference formats on the real BrnoCompSpeed files in `VPCAL_DATA` (default
//! `../shared/data`); every test skips with a message when the data is absent.

use std::path::{Path, PathBuf};
use vpcal_formats::bcs::{list_videos, read_gt, read_system};
use vpcal_formats::reference::{read_detections, read_vpout, write_vpout, ReferenceDetections};
use vpcal_geom::heatmap::HeatmapCodec;

fn bcs_dir() -> Option<PathBuf> {
    let root = std::env::var_os("VPCAL_DATA").map_or_else(
        || Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data"),
        PathBuf::from,
    );
    let dir = root.join("bcs");
    if dir.is_dir() {
        Some(dir)
    } else {
        eprintln!(
            "skipping: no BrnoCompSpeed data at {} (set VPCAL_DATA)",
            dir.display()
        );
        None
    }
}

fn vpout_files(bcs: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for session in std::fs::read_dir(bcs.join("vp_outputs")).unwrap() {
        for f in std::fs::read_dir(session.unwrap().path()).unwrap() {
            out.push(f.unwrap().path());
        }
    }
    out.sort();
    out
}

#[test]
fn every_gt_data_pkl_loads() {
    let Some(bcs) = bcs_dir() else { return };
    let videos = list_videos(&bcs.join("dataset")).unwrap();
    assert_eq!(videos.len(), 12);
    for (name, dir) in &videos {
        let gt = read_gt(dir).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert!(gt.fps == 25.0 || gt.fps == 50.0, "{name}: fps {}", gt.fps);
        assert!(gt.distance_measurements.len() >= 4, "{name}");
        assert!(!gt.cars.is_empty(), "{name}");
        for m in &gt.distance_measurements {
            assert!(m.p1.is_finite() && m.p2.is_finite() && m.distance_m > 0.0);
        }
    }
    // Spot values printed by Python's own pickle (numpy from a venv):
    // d = pickle.load(open('session0_left/gt_data.pkl','rb'), encoding='latin1')
    // d['distanceMeasurement'][0] -> p1 [147.10869806, 457.31102493, 1.], distance 7.0, toVP1 True;
    // len(d['measurementLines']) 5, len(d['laneDivLines']) 4, len(d['cars']) 115.
    let gt = read_gt(&bcs.join("dataset/session0_left")).unwrap();
    let m = &gt.distance_measurements[0];
    assert!((m.p1.x - 147.10869806).abs() < 1e-8 && (m.p1.y - 457.31102493).abs() < 1e-8);
    assert_eq!((m.distance_m, m.to_vp1), (7.0, true));
    assert_eq!(gt.fps, 50.0);
    assert_eq!(gt.distance_measurements.len(), 14);
    assert_eq!(
        (
            gt.measurement_lines.len(),
            gt.lane_div_lines.len(),
            gt.cars.len()
        ),
        (5, 4, 115)
    );
    assert!(gt.invalid_lanes.is_empty());
    assert_eq!(gt.cars[0].lane_index, vec![1]);
    assert!(gt.cars[0].valid);
}

#[test]
fn every_vpout_file_reads_without_loss() {
    let Some(bcs) = bcs_dir() else { return };
    let files = vpout_files(&bcs);
    assert_eq!(files.len(), 36);
    let mut non_finite = 0usize;
    for f in &files {
        let items = read_vpout(f).unwrap_or_else(|e| panic!("{e}"));
        assert!(!items.is_empty());
        non_finite += items
            .iter()
            .filter(|i| !(i.vp1.is_finite() && i.vp2.is_finite()))
            .count();
        // Round trip through our writer: the same values, the non-finite ones as null (strict
        // JSON, read back as NaN).
        let tmp = tempfile::NamedTempFile::new().unwrap();
        write_vpout(tmp.path(), &items).unwrap();
        let text = std::fs::read_to_string(tmp.path()).unwrap();
        assert!(serde_json::from_str::<serde_json::Value>(&text).is_ok());
        let again = read_vpout(tmp.path()).unwrap();
        assert_eq!(items.len(), again.len());
        for (a, b) in items.iter().zip(&again) {
            // PartialEq fails on NaN; compare the JSON text instead.
            assert_eq!(
                a.to_json().to_strict_string(),
                b.to_json().to_strict_string()
            );
        }
    }
    // Counted with Python's json module over all 36 files (items whose vp1 or vp2 has a
    // non-finite coordinate): `sum(not all(map(math.isfinite, it['vp1'] + it['vp2']))
    // for f in glob('vp_outputs/*/*.json') for it in json.load(open(f)))` -> 723.
    assert_eq!(non_finite, 723);
}

#[test]
fn decoded_vps_of_the_public_cnn_lie_on_our_pixel_centre_lattice() {
    // The multi-scale model (file name "128out ... 0.03-0.1-0.3-1.0s") decoded 128x128
    // heatmaps at pixel centres: re-encoding its per-scale VPs lands on (k + 0.5). This checks
    // our codec (diamond space, rotation, scale, +0.5 decoding) against the reference's real
    // output. A handful of values on the heatmap's first column do not round-trip exactly
    // (0.1 %); allow 0.5 %.
    let Some(bcs) = bcs_dir() else { return };
    let codec = HeatmapCodec::new(128, vec![0.03, 0.1, 0.3, 1.0]);
    let (mut total, mut on_lattice) = (0usize, 0usize);
    for f in vpout_files(&bcs)
        .iter()
        .filter(|f| f.to_string_lossy().contains("0.03-0.1-0.3-1.0s"))
    {
        for item in read_vpout(f).unwrap() {
            assert_eq!(item.pred_vps.len(), 4);
            for (k, &s) in codec.scales.iter().enumerate() {
                let row = item.pred_vps[k];
                for vp in [[row[0], row[1]], [row[2], row[3]]] {
                    let Some(h) = codec.vp_to_heatmap(vp.into(), s) else {
                        continue;
                    };
                    total += 1;
                    let off = |t: f64| (t - 0.5 - (t - 0.5).round()).abs();
                    if off(h.x) < 1e-6 && off(h.y) < 1e-6 {
                        on_lattice += 1;
                    }
                }
            }
            // The selected VP is the per-scale VP with the smallest spread.
            let best = (0..4)
                .min_by(|&a, &b| item.pred_vars[a][0].total_cmp(&item.pred_vars[b][0]))
                .unwrap();
            assert_eq!(item.vp1_box.unwrap().x, item.pred_vps[best][0]);
        }
    }
    assert!(total > 100_000, "{total}");
    assert!(
        on_lattice as f64 >= 0.995 * total as f64,
        "{on_lattice} of {total}"
    );
}

#[test]
fn detections_and_system_files_read() {
    let Some(bcs) = bcs_dir() else { return };
    let dets = read_detections(&bcs.join("dataset/session0_center/detections.json")).unwrap();
    assert!(dets.len() > 100);
    assert_eq!(dets[0].frame_cnt, 10.0);
    let with_boxes = dets.iter().find(|d| !d.boxes.is_empty()).unwrap();
    // The reference's integer box of the first VPout item of session4_center:
    // box [0.0993, 0.4042, 0.1683, 0.4835] -> vp_box [107, 776, 182, 929], centre (852.5, 144.5).
    let b = ReferenceDetections::box_px(
        [
            0.09926356375217438,
            0.4041927456855774,
            0.16834206879138947,
            0.48352164030075073,
        ],
        1920,
        1080,
    );
    assert_eq!((b.x0, b.y0, b.x1, b.y1), (776.0, 107.0, 929.0, 182.0));
    assert!(with_boxes.boxes.len() == with_boxes.scores.len());
    let sys = read_system(&bcs.join("results/session0_left/system_dubska_bmvc14.json")).unwrap();
    assert_eq!(sys.calibration.pp.x, 960.5);
    assert!(!sys.cars.is_empty());
}

/// The BrnoCompSpeed speed evaluation (`vpcal_formats::bcs_speed`) of session0_center's
/// DubskaCalib tracks, against the numbers printed by the independent numpy implementation
/// `scripts/bcs_speed_reference.py` (run from the workspace root with numpy):
///
/// ```text
/// python3 scripts/bcs_speed_reference.py ../shared/data/bcs/dataset ../shared/data/bcs/results \
///     dubska_bmvc14 --videos session0_center [--mode full] \
///     [--camera-truth ../shared/data/bcs/camera_truth.json]
/// ```
///
/// (a) the system file's own camera and scale, (b) camera_truth.json's camera with the scale
/// fitted to the taped distances; median and full modes. All four give 37 measured cars, no
/// crossing failure, 32 of 34 valid GT cars matched, 6 false positives.
#[test]
fn speed_evaluation_matches_the_numpy_reference() {
    use vpcal_formats::bcs_speed::{
        evaluate_video, read_camera_truth, Road, SpeedMode, BCS_IMAGE_SIZE,
    };
    use vpcal_geom::camera::Calibration;
    use vpcal_geom::metrics::optimal_scale;

    let Some(bcs) = bcs_dir() else { return };
    let gt = read_gt(&bcs.join("dataset/session0_center")).unwrap();
    let sys = read_system(&bcs.join("results/session0_center/system_dubska_bmvc14.json")).unwrap();
    let c = sys.calibration;
    let own = Calibration::from_vps(c.vp1, c.vp2, c.pp).unwrap();
    let truth = read_camera_truth(&bcs.join("camera_truth.json")).unwrap()["session0_center"];
    let truth_cam = Calibration::from_vps(truth.vp1, truth.vp2, truth.pp).unwrap();
    let fitted = optimal_scale(&truth_cam, &gt.road_measurements()).unwrap();
    assert!((fitted - 0.01801321071193049).abs() < 1e-15, "{fitted}");

    // (camera, scale, mode, [abs mean, median, p95, max], [rel mean, median, p95, max])
    let cases = [
        (
            &own,
            c.scale,
            SpeedMode::Median,
            [
                11.968324646162424,
                11.793631614327857,
                13.773106465662888,
                15.653690326942723,
            ],
            [
                14.95394788884921,
                15.386795762932998,
                17.48739522737558,
                17.88544130386934,
            ],
        ),
        (
            &own,
            c.scale,
            SpeedMode::Full,
            [
                12.600438109003996,
                12.665045560208313,
                14.769613212959452,
                16.673173645846717,
            ],
            [
                15.767903343341937,
                15.813637508249476,
                18.245940539553132,
                23.861904735100907,
            ],
        ),
        (
            &truth_cam,
            fitted,
            SpeedMode::Median,
            [
                1.0815279736129177,
                1.0548466595736983,
                1.851100248694567,
                2.163409629395545,
            ],
            [
                1.3643477353912914,
                1.3778222207923132,
                2.316915322217568,
                2.588020818074438,
            ],
        ),
        (
            &truth_cam,
            fitted,
            SpeedMode::Full,
            [
                1.893939957766532,
                1.0392987353690444,
                4.296318295840569,
                21.858829722524476,
            ],
            [
                2.468015054420139,
                1.3113756180207123,
                6.109709927519531,
                28.949505912691787,
            ],
        ),
    ];
    for (calib, scale, mode, abs, rel) in cases {
        let road = Road { calib, scale };
        let v = evaluate_video(&gt, &sys.cars, &road, mode, BCS_IMAGE_SIZE).unwrap();
        assert_eq!(
            (
                v.measured,
                v.crossing_failures,
                v.matched,
                v.valid,
                v.false_positives
            ),
            (37, 0, 32, 34, 6),
            "{mode:?}"
        );
        assert_eq!(v.recall, Some(32.0 / 34.0));
        for (got, want) in [(v.abs_kmh.unwrap(), abs), (v.rel_pct.unwrap(), rel)] {
            assert_eq!(got.n, 32);
            let got = [got.mean, got.median, got.p95, got.max];
            for (g, w) in got.iter().zip(want) {
                assert!(
                    (g - w).abs() < 1e-9,
                    "{mode:?} scale {scale}: {got:?} vs {want:?}"
                );
            }
        }
    }
}
