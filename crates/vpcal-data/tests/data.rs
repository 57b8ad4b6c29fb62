//! vpcal-data against a small dataset in the BoxCars116k format written by
//! `scripts/boxcars_fixture.py` (tests/fixtures/boxcars): loading, splits, decoding, the
//! augmentation's geometry, the pipeline's determinism, and broken inputs.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::{Path, PathBuf};
use std::sync::Arc;

use proptest::prelude::*;
use vpcal_data::augment::{augment, AugmentConfig, Augmented};
use vpcal_data::boxcars::BoxCars;
use vpcal_data::pipeline::{sample_rng, Pipeline, PipelineConfig};
use vpcal_data::warp::Resample;
use vpcal_data::{
    ConcatSource, DataError, Sample, SampleId, SampleSource, Split, BB3D_EDGES_VP1, BB3D_EDGES_VP2,
};
use vpcal_formats::pickle::{self, ArrayData, LoadOptions, Value};
use vpcal_geom::heatmap::HeatmapCodec;
use vpcal_geom::{BoxPx, Point2};

fn fixture() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/boxcars")
}

fn open() -> BoxCars {
    BoxCars::open(&fixture()).unwrap_or_else(|e| panic!("{e}"))
}

/// Intersection of the lines through (a, b) and (c, d).
fn meet(a: [f64; 2], b: [f64; 2], c: [f64; 2], d: [f64; 2]) -> Point2 {
    let cross = |p: [f64; 3], q: [f64; 3]| {
        [
            p[1] * q[2] - p[2] * q[1],
            p[2] * q[0] - p[0] * q[2],
            p[0] * q[1] - p[1] * q[0],
        ]
    };
    let l1 = cross([a[0], a[1], 1.0], [b[0], b[1], 1.0]);
    let l2 = cross([c[0], c[1], 1.0], [d[0], d[1], 1.0]);
    let x = cross(l1, l2);
    Point2::new(x[0] / x[2], x[1] / x[2])
}

fn assert_close(p: Point2, q: Point2, scale: f64, what: &str) {
    let tol = 1e-6 * q.norm().max(scale);
    assert!(
        (p - q).norm() <= tol,
        "{what}: {p:?} vs {q:?} (tolerance {tol})"
    );
}

#[test]
fn loads_the_dataset_and_splits_by_vehicle() {
    let bc = open();
    assert_eq!(bc.cameras().len(), 3);
    assert_eq!(bc.vehicles().len(), 30);
    let total: usize = bc.vehicles().iter().map(|v| v.instances.len()).sum();
    assert_eq!(total, 60);
    let sizes = [Split::Train, Split::Validation, Split::Test].map(|s| bc.split(s).len());
    // vehicles 0, 10, 20 validate; 1, 11, 21 test; vehicle v has 1 + v % 3 instances
    assert_eq!(sizes, [48, 6, 6]);
    for split in [Split::Train, Split::Validation, Split::Test] {
        let s = bc.split(split);
        assert_eq!(s.split(), split);
        assert!(s
            .items()
            .iter()
            .all(|&(v, _)| Split::of_vehicle(v as u64) == split));
    }
    // The projected box edges of every instance meet at its camera's VPs (frame pixels).
    for v in bc.vehicles() {
        let cam = &bc.cameras()[v.camera];
        for inst in &v.instances {
            let b = inst.bb3d_in_frame;
            for (edges, vp) in [(BB3D_EDGES_VP1, cam.vp1), (BB3D_EDGES_VP2, cam.vp2)] {
                let (i, j) = edges[0];
                let (k, l) = edges[1];
                let p = meet(b[i], b[j], b[k], b[l]);
                assert_close(p, Point2::new(vp[0], vp[1]), 1000.0, "frame VP");
            }
            assert!(inst.bb2d.is_some());
        }
    }
}

#[test]
fn decodes_every_crop_with_its_geometry() {
    let bc = open();
    let mut n = 0;
    for split in [Split::Train, Split::Validation, Split::Test] {
        let s = bc.split(split);
        for i in 0..s.len() {
            let sample = s.get(i).unwrap_or_else(|e| panic!("{e}"));
            let (w, h) = (
                f64::from(sample.image.width()),
                f64::from(sample.image.height()),
            );
            assert!(w >= 24.0 && h >= 24.0);
            for c in sample.bb3d {
                assert!(
                    c[0] >= 0.0 && c[0] <= w && c[1] >= 0.0 && c[1] <= h,
                    "{c:?} in {w}x{h}"
                );
            }
            // crop-frame VPs = camera VPs minus the crop offset
            let (vid, iid) = s.items()[i];
            let inst = &bc.vehicles()[vid].instances[iid];
            let cam = &bc.cameras()[bc.vehicles()[vid].camera];
            assert_eq!(sample.vp1[0], cam.vp1[0] - inst.crop_offset[0]);
            assert_eq!(sample.vp2[1], cam.vp2[1] - inst.crop_offset[1]);
            assert_eq!(
                sample.id,
                SampleId {
                    vehicle: vid as u64,
                    instance: iid as u32
                }
            );
            n += 1;
        }
    }
    assert_eq!(n, 60);
    // The JPEG bytes come from the atlas byte ranges: compare one with a full (non-deferred) read.
    let atlas = pickle::from_path(&fixture().join("atlas.pkl"), &LoadOptions::default()).unwrap();
    let direct = atlas
        .at(4)
        .unwrap()
        .at(0)
        .unwrap()
        .as_byte_string()
        .unwrap()
        .into_owned();
    assert_eq!(&*bc.crop_bytes(4, 0).unwrap(), direct.as_slice());
    let direct = atlas
        .at(10)
        .unwrap()
        .at(1)
        .unwrap()
        .as_byte_string()
        .unwrap()
        .into_owned();
    assert_eq!(
        &*bc.crop_bytes(10, 1).unwrap(),
        direct.as_slice(),
        "Python-2 string entry"
    );
}

fn check_vp_consistency(a: &Augmented, size: f64, what: &str) {
    let vp_px = |v: Point2| Point2::new((v.x + 1.0) * size / 2.0, (v.y + 1.0) * size / 2.0);
    let b = a.bb3d;
    for (edges, vp) in [(BB3D_EDGES_VP1, a.vp1_box), (BB3D_EDGES_VP2, a.vp2_box)] {
        let target = vp_px(vp);
        for pair in [(0, 1), (2, 3), (0, 3)] {
            let (i, j) = edges[pair.0];
            let (k, l) = edges[pair.1];
            assert_close(meet(b[i], b[j], b[k], b[l]), target, size, what);
        }
    }
}

#[test]
fn augmented_vps_stay_on_the_augmented_box_edges() {
    let bc = open();
    let train = bc.split(Split::Train);
    let mut flips = [0usize; 2];
    for (name, base) in [
        ("paper", AugmentConfig::paper()),
        ("reference", AugmentConfig::reference()),
    ] {
        for flip_probability in [0.0, 0.5, 1.0] {
            let cfg = AugmentConfig {
                flip_probability,
                ..base.clone()
            };
            for i in 0..train.len() {
                let sample = train.get(i).unwrap();
                for seed in 0..3u64 {
                    let mut rng = sample_rng(seed, 0, i);
                    let a = augment(&sample, &cfg, &mut rng).unwrap();
                    assert_eq!(a.image.width(), 128);
                    flips[usize::from(a.flipped)] += 1;
                    let what = format!("{name} flip {flip_probability} sample {i} seed {seed}");
                    check_vp_consistency(&a, 128.0, &what);
                    if flip_probability == 1.0 {
                        assert!(a.flipped, "{what}");
                    }
                }
            }
        }
    }
    assert!(flips[0] > 100 && flips[1] > 100, "{flips:?}");
}

#[test]
fn a_mirror_inside_the_homography_mirrors_the_crop() {
    let bc = open();
    let sample = bc.split(Split::Train).get(5).unwrap();
    let plain = AugmentConfig::evaluation(128);
    let mirror = AugmentConfig {
        flip_probability: 1.0,
        ..plain.clone()
    };
    let mut rng = sample_rng(1, 0, 0);
    let a = augment(&sample, &plain, &mut rng).unwrap();
    let b = augment(&sample, &mirror, &mut rng).unwrap();
    assert!(b.flipped && !a.flipped);
    let mirrored = image::imageops::flip_horizontal(&a.image);
    let diff = mirrored
        .as_raw()
        .iter()
        .zip(b.image.as_raw())
        .map(|(x, y)| x.abs_diff(*y))
        .max()
        .unwrap();
    assert!(diff <= 1, "max pixel difference {diff}");
    // VPs mirror in the box frame; VP1 stays VP1.
    assert!((b.vp1_box.x + a.vp1_box.x).abs() < 1e-9 && (b.vp1_box.y - a.vp1_box.y).abs() < 1e-9);
    assert!((b.vp2_box.x + a.vp2_box.x).abs() < 1e-9 && (b.vp2_box.y - a.vp2_box.y).abs() < 1e-9);
}

/// Samples held in memory.
struct MemSource(Vec<Sample>);

impl SampleSource for MemSource {
    fn len(&self) -> usize {
        self.0.len()
    }
    fn split(&self) -> Split {
        Split::Train
    }
    fn get(&self, index: usize) -> Result<Sample, DataError> {
        self.0.get(index).cloned().ok_or(DataError::File {
            path: PathBuf::new(),
            message: "out of range".into(),
        })
    }
}

prop_compose! {
    /// A sample whose 3D box hull spans its whole `size` x `size` image, with random pixels and VPs.
    fn full_frame_sample(size: u32)(
        pixels in proptest::collection::vec(any::<u8>(), (size * size * 3) as usize),
        inner in proptest::collection::vec((1.0..(size as f64 - 1.0), 1.0..(size as f64 - 1.0)), 6),
        vp1 in (-1e4f64..1e4, -1e4f64..1e4),
        vp2 in (-1e4f64..1e4, -1e4f64..1e4),
    ) -> Sample {
        let s = f64::from(size);
        let mut bb3d = [[0.0; 2]; 8];
        bb3d[0] = [0.0, 0.0];
        bb3d[6] = [s, s];
        for (k, p) in inner.iter().enumerate() {
            bb3d[[1, 2, 3, 4, 5, 7][k]] = [p.0, p.1];
        }
        Sample {
            id: SampleId { vehicle: 2, instance: 0 },
            image: image::RgbImage::from_raw(size, size, pixels).unwrap(),
            bb3d,
            vp1: [vp1.0, vp1.1],
            vp2: [vp2.0, vp2.1],
            label_weight: vpcal_data::EXACT_LABELS,
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// With sigma 0 and no jitter or flip, the pipeline returns the un-augmented crop and VPs
    /// exactly.
    #[test]
    fn no_augmentation_returns_the_crop_and_vps_exactly(
        samples in proptest::collection::vec(full_frame_sample(32), 1..5),
        filter in prop_oneof![Just(Resample::Bicubic), Just(Resample::Bilinear), Just(Resample::Nearest)],
        seed in any::<u64>(),
    ) {
        let cfg = AugmentConfig {
            perspective_sigma_px: 0.0,
            box_jitter_px: 0.0,
            flip_probability: 0.0,
            output_size: 32,
            filter,
            ..AugmentConfig::paper()
        };
        let codec = HeatmapCodec::default();
        let source = Arc::new(MemSource(samples.clone()));
        let pipeline = Pipeline::new(source, PipelineConfig {
            batch_size: 3,
            workers: 2,
            shuffle: false,
            augment: cfg,
            warn_on_skip: false,
            ..PipelineConfig::training(3, seed)
        }).unwrap();
        let batches: Vec<_> = pipeline.epoch(0).map(|b| b.unwrap()).collect();
        let mut k = 0;
        let frame = BoxPx::new(0.0, 0.0, 32.0, 32.0);
        for b in &batches {
            for i in 0..b.size {
                let s = &samples[k];
                let raw = s.image.as_raw();
                let plane = 32 * 32;
                for c in 0..3 {
                    for p in 0..plane {
                        prop_assert_eq!(b.images[i * 3 * plane + c * plane + p], f32::from(raw[p * 3 + c]) / 255.0);
                    }
                }
                let vp1 = frame.vp_in_box(Point2::new(s.vp1[0], s.vp1[1]));
                let vp2 = frame.vp_in_box(Point2::new(s.vp2[0], s.vp2[1]));
                prop_assert_eq!(b.vp1_box[i], vp1.as_array());
                prop_assert_eq!(b.vp2_box[i], vp2.as_array());
                let t = codec.render_targets(vp1, vp2);
                prop_assert_eq!(&b.targets[i * codec.len()..(i + 1) * codec.len()], t.as_slice());
                k += 1;
            }
        }
        prop_assert_eq!(k, samples.len());
    }
}

#[test]
fn batches_are_deterministic_for_a_seed_whatever_the_workers() {
    let bc = open();
    let train: Arc<dyn SampleSource> = Arc::new(bc.split(Split::Train));
    let run = |workers: usize, seed: u64, epoch: u64| {
        let cfg = PipelineConfig {
            workers,
            warn_on_skip: false,
            ..PipelineConfig::training(7, seed)
        };
        let p = Pipeline::new(Arc::clone(&train), cfg).unwrap();
        assert_eq!(p.batches_per_epoch(), 7);
        p.epoch(epoch).map(|b| b.unwrap()).collect::<Vec<_>>()
    };
    let a = run(1, 42, 0);
    let b = run(3, 42, 0);
    assert_eq!(a.len(), 7);
    let sizes: Vec<usize> = a.iter().map(|x| x.size).collect();
    assert_eq!(sizes, [7, 7, 7, 7, 7, 7, 6]);
    for (x, y) in a.iter().zip(&b) {
        assert_eq!(x.ids, y.ids);
        assert_eq!(x.images, y.images);
        assert_eq!(x.targets, y.targets);
        assert_eq!(x.vp1_box, y.vp1_box);
        assert_eq!(x.channels, 8);
        assert_eq!(x.heatmap_res, 64);
        assert_eq!(x.images.len(), x.size * 3 * 128 * 128);
        assert_eq!(x.targets.len(), x.size * 8 * 64 * 64);
    }
    // every sample exactly once per epoch
    let mut ids: Vec<SampleId> = a.iter().flat_map(|x| x.ids.clone()).collect();
    ids.sort();
    ids.dedup();
    assert_eq!(ids.len(), 48);
    // another seed or epoch: another order and other augmentations
    let c = run(2, 43, 0);
    let d = run(2, 42, 1);
    assert_ne!(a[0].ids, c[0].ids);
    assert_ne!(a[0].ids, d[0].ids);
}

#[test]
fn joined_sources_read_as_one_and_label_weights_reach_the_batch() {
    let bc = open();
    let boxcars: Arc<dyn SampleSource> = Arc::new(bc.split(Split::Train));
    let n = boxcars.len();
    // A self-labelled sample: VP1 trusted, VP2 half.
    let mut real = boxcars.get(0).unwrap();
    real.id = SampleId {
        vehicle: 7_000_002,
        instance: 0,
    };
    real.label_weight = [1.0, 0.5];
    let mem: Arc<dyn SampleSource> = Arc::new(MemSource(vec![real]));
    let joined = ConcatSource::new(vec![Arc::clone(&boxcars), mem]).unwrap();
    assert_eq!(joined.len(), n + 1);
    assert_eq!(joined.get(n).unwrap().id.vehicle, 7_000_002);
    assert_eq!(joined.get(1).unwrap().id, boxcars.get(1).unwrap().id);
    assert!(joined.get(n + 1).is_err());
    let val: Arc<dyn SampleSource> = Arc::new(bc.split(Split::Validation));
    let e = ConcatSource::new(vec![Arc::clone(&boxcars), val]).unwrap_err();
    assert!(e.to_string().contains("Validation"), "{e}");
    assert!(ConcatSource::new(Vec::new()).is_err());

    let cfg = PipelineConfig {
        workers: 1,
        warn_on_skip: false,
        ..PipelineConfig::training(n + 1, 5)
    };
    let p = Pipeline::new(Arc::new(joined), cfg).unwrap();
    let batch = p.epoch(0).next().unwrap().unwrap();
    assert_eq!(batch.weights.len(), batch.size * batch.channels);
    assert!(batch.is_weighted());
    for (k, id) in batch.ids.iter().enumerate() {
        let w = &batch.weights[k * batch.channels..(k + 1) * batch.channels];
        let expect: Vec<f32> = if id.vehicle == 7_000_002 {
            vec![1.0, 1.0, 1.0, 1.0, 0.5, 0.5, 0.5, 0.5]
        } else {
            vec![1.0; 8]
        };
        assert_eq!(w, &expect[..], "{id:?}");
    }
}

#[test]
fn sensor_effects_change_pixels_not_geometry() {
    let bc = open();
    let sample = bc.split(Split::Train).get(0).unwrap();
    let plain = AugmentConfig::paper();
    let real = AugmentConfig::real();
    assert!(AugmentConfig::PRESETS.contains(&"real"));
    let mut changed = 0;
    for seed in 0..6u64 {
        let a = augment(&sample, &plain, &mut sample_rng(seed, 0, 0)).unwrap();
        let b = augment(&sample, &real, &mut sample_rng(seed, 0, 0)).unwrap();
        // The geometry is drawn first, from the same stream: the same crop and VPs.
        assert_eq!(a.crop, b.crop);
        assert_eq!(a.vp1_box, b.vp1_box);
        assert_eq!(a.vp2_box, b.vp2_box);
        changed += usize::from(a.image != b.image);
    }
    assert!(changed >= 4, "sensor effects changed {changed} of 6 crops");
    let bad = AugmentConfig {
        sensor_probability: 1.5,
        ..AugmentConfig::paper()
    };
    assert!(bad.validate().unwrap_err().contains("sensor_probability"));
    // The far-vehicle preset: the same geometry, blurrier pictures where it down-samples.
    let small = AugmentConfig::preset("real-small").unwrap();
    assert!(small.validate().is_ok() && small.max_downsample > real.max_downsample);
    let (mut differ, mut softer) = (0, 0);
    for seed in 0..12u64 {
        let a = augment(&sample, &real, &mut sample_rng(seed, 0, 0)).unwrap();
        let b = augment(&sample, &small, &mut sample_rng(seed, 0, 0)).unwrap();
        assert_eq!(
            (a.crop, a.vp1_box, a.vp2_box),
            (b.crop, b.vp1_box, b.vp2_box)
        );
        if a.image != b.image {
            differ += 1;
            softer += usize::from(detail(&b.image) < detail(&a.image));
        }
    }
    assert!(
        differ >= 1 && softer == differ,
        "{softer} of {differ} softer"
    );
    let bad = AugmentConfig {
        max_downsample: 1.0,
        ..AugmentConfig::real()
    };
    assert!(bad.validate().unwrap_err().contains("max_downsample"));
}

/// Sum of absolute differences between horizontal neighbours: how much fine detail a
/// picture has.
fn detail(img: &image::RgbImage) -> u64 {
    let (w, h) = img.dimensions();
    let mut sum = 0u64;
    for y in 0..h {
        for x in 1..w {
            let (a, b) = (img.get_pixel(x - 1, y), img.get_pixel(x, y));
            sum += (0..3).map(|c| u64::from(a[c].abs_diff(b[c]))).sum::<u64>();
        }
    }
    sum
}

/// A copy of the fixture in a temporary directory.
fn copy_fixture() -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    for f in ["dataset.pkl", "atlas.pkl"] {
        std::fs::copy(fixture().join(f), dir.path().join(f)).unwrap();
    }
    dir
}

/// Byte range of the crop of (vehicle, instance) inside atlas.pkl.
fn crop_span(vehicle: usize, instance: usize) -> (usize, usize) {
    let atlas = pickle::from_path(
        &fixture().join("atlas.pkl"),
        &LoadOptions {
            defer_bytes_over: Some(0),
        },
    )
    .unwrap();
    let entry = atlas.at(vehicle).unwrap().at(instance).unwrap();
    let span = match entry {
        Value::Deferred(span) => *span,
        Value::Array(a) => match a.data {
            ArrayData::Deferred { span, .. } => span,
            _ => panic!("not deferred"),
        },
        other => panic!("unexpected {other:?}"),
    };
    (span.offset as usize, span.len as usize)
}

#[test]
fn a_corrupt_jpeg_skips_that_sample_with_a_count() {
    let dir = copy_fixture();
    let (offset, len) = crop_span(13, 1);
    let path = dir.path().join("atlas.pkl");
    let mut bytes = std::fs::read(&path).unwrap();
    bytes[offset..offset + len].fill(0);
    std::fs::write(&path, &bytes).unwrap();

    let bc = BoxCars::open(dir.path()).unwrap();
    let err = bc.sample(13, 1).unwrap_err();
    let msg = err.to_string();
    assert!(matches!(err, DataError::Sample { .. }), "{msg}");
    assert!(
        msg.contains("atlas.pkl") && msg.contains("vehicle 13 instance 1"),
        "{msg}"
    );

    let train: Arc<dyn SampleSource> = Arc::new(bc.split(Split::Train));
    let cfg = PipelineConfig {
        workers: 2,
        warn_on_skip: false,
        ..PipelineConfig::training(8, 5)
    };
    let p = Pipeline::new(train, cfg).unwrap();
    let mut epoch = p.epoch(0);
    let total: usize = epoch.by_ref().map(|b| b.unwrap().size).sum();
    assert_eq!(total, 47);
    assert_eq!(epoch.skipped().len(), 1);
    assert!(
        epoch.skipped()[0].reason.contains("vehicle 13 instance 1"),
        "{:?}",
        epoch.skipped()
    );
}

#[test]
fn a_truncated_atlas_names_the_file_and_the_sample() {
    // Vehicle v has 1 + v % 3 crops, numpy arrays except when v % 7 == 3 (Python-2 strings):
    // cut inside a crop with and without siblings, of both kinds.
    for (vehicle, instance) in [(14, 1), (9, 0), (10, 1), (3, 0), (29, 2)] {
        let dir = copy_fixture();
        let (offset, len) = crop_span(vehicle, instance);
        let path = dir.path().join("atlas.pkl");
        let bytes = std::fs::read(&path).unwrap();
        std::fs::write(&path, &bytes[..offset + len / 2]).unwrap();
        let err = BoxCars::open(dir.path()).unwrap_err();
        let msg = err.to_string();
        assert!(
            msg.contains("atlas.pkl") && msg.contains("truncated"),
            "{msg}"
        );
        assert!(
            msg.contains(&format!("vehicle {vehicle} instance {instance}")),
            "{vehicle}/{instance}: {msg}"
        );
    }
}

#[test]
fn a_forbidden_global_names_the_file_and_the_sample() {
    let dir = copy_fixture();
    let path = dir.path().join("dataset.pkl");
    let mut bytes = std::fs::read(&path).unwrap();
    let needle = b"U\x0fsynthetic box 7";
    let at = bytes
        .windows(needle.len())
        .position(|w| w == needle)
        .unwrap();
    let evil = b"cos\nsystem\n(U\x02idtR";
    bytes.splice(at..at + needle.len(), evil.iter().copied());
    std::fs::write(&path, &bytes).unwrap();
    let err = BoxCars::open(dir.path()).unwrap_err();
    let msg = err.to_string();
    assert!(msg.contains("dataset.pkl"), "{msg}");
    assert!(msg.contains("refusing to load global os.system"), "{msg}");
    assert!(msg.contains("vehicle 7"), "{msg}");
}

#[test]
fn missing_files_are_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let msg = BoxCars::open(dir.path()).unwrap_err().to_string();
    assert!(msg.contains("dataset.pkl"), "{msg}");
    std::fs::copy(
        fixture().join("dataset.pkl"),
        dir.path().join("dataset.pkl"),
    )
    .unwrap();
    let msg = BoxCars::open(dir.path()).unwrap_err().to_string();
    assert!(msg.contains("atlas.pkl"), "{msg}");
}
