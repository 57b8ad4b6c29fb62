//! The crop directory format (see `FORMAT.md`): writer and reader.

use std::path::{Path, PathBuf};

use rayon::prelude::*;
use vpcal_data::{DataError, Sample, SampleId, Split};

use crate::crops::{CropConfig, CropGenerator, CropMeta, CropSample};
use crate::error::write_atomic;
use crate::SynthError;

/// The text of `FORMAT.md`, also written into every crop directory.
pub const FORMAT_MD: &str = include_str!("../FORMAT.md");

/// One line of `samples.jsonl`.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct SampleRecord {
    pub vehicle: u64,
    pub instance: u32,
    pub image: String,
    pub width: u32,
    pub height: u32,
    pub bb3d: [[f64; 2]; 8],
    pub vp1: [f64; 2],
    pub vp2: [f64; 2],
    pub box2d: [f64; 4],
    /// Loss weights of the VP1 and VP2 labels in [0, 1]; absent (exact, `[1, 1]`) for
    /// rendered crops.
    #[serde(default = "exact_labels", skip_serializing_if = "is_exact")]
    pub label_weight: [f32; 2],
    pub meta: SampleMeta,
}

fn exact_labels() -> [f32; 2] {
    vpcal_data::EXACT_LABELS
}

fn is_exact(w: &[f32; 2]) -> bool {
    *w == vpcal_data::EXACT_LABELS
}

/// Where a crop came from: the renderer, or real footage labelled by `vpcal label`.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
#[serde(untagged)]
pub enum SampleMeta {
    Synthetic(CropMeta),
    Real(RealMeta),
}

/// Provenance and label quality of a self-labelled crop of real footage (`vpcal label`).
///
/// Its VPs come from the camera that `vpcal label` estimated for the whole clip: VP1 from the
/// vehicles' straight tracks (or, `vp1_from_tangent`, the vehicle's own track's tangent met
/// with the horizon), VP2 from that VP1, the horizon and the focal length. The label
/// uncertainties are direction errors at the box centre, degrees, and set `label_weight`.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RealMeta {
    /// The footage file the crop was cut from.
    pub source: String,
    /// Camera name (the footage's file stem); whole cameras are held out for validation.
    pub camera: String,
    /// Frame index in the footage.
    pub frame: u64,
    /// Track (vehicle) index within the footage.
    pub track: u64,
    /// Detector score of the box.
    pub score: f32,
    /// The detector's box, frame pixels `[x0, y0, x1, y1]`.
    pub det_box: [f64; 4],
    /// Frame pixel of the crop's top-left corner.
    pub crop_origin: [f64; 2],
    pub frame_size: [u32; 2],
    /// The estimated camera: focal length (px), where it came from, principal point.
    pub focal_px: f64,
    pub focal_source: String,
    pub pp: [f64; 2],
    /// Uncertainty of the VP1 label's direction at the box centre, degrees.
    pub vp1_sd_deg: f64,
    /// Uncertainty of the VP2 label's direction at the box centre, degrees.
    pub vp2_sd_deg: f64,
    /// VP1 is the vehicle's own: its track's tangent at the box met with the horizon (a
    /// turning vehicle, a curve, an intersection), not the camera's VP1 of the road.
    #[serde(default)]
    pub vp1_from_tangent: bool,
}

/// Write a crop directory's `FORMAT.md`, `config.json` (the writer's own description, with
/// `format` and `version` keys) and, last, `samples.jsonl` for crops whose JPEGs are already
/// in `dir/images/`.
///
/// # Errors
/// I/O errors naming the file.
pub fn write_index(
    dir: &Path,
    config: &serde_json::Value,
    records: &[SampleRecord],
) -> Result<(), SynthError> {
    write_atomic(&dir.join("FORMAT.md"), FORMAT_MD.as_bytes())?;
    let format_err = |path: PathBuf, e: serde_json::Error| SynthError::Format {
        path,
        message: e.to_string(),
    };
    let cfg =
        serde_json::to_vec_pretty(config).map_err(|e| format_err(dir.join("config.json"), e))?;
    write_atomic(&dir.join("config.json"), &cfg)?;
    let mut lines = String::new();
    for r in records {
        lines.push_str(
            &serde_json::to_string(r).map_err(|e| format_err(dir.join("samples.jsonl"), e))?,
        );
        lines.push('\n');
    }
    write_atomic(&dir.join("samples.jsonl"), lines.as_bytes())
}

#[derive(Debug, serde::Serialize, serde::Deserialize)]
struct ConfigFile {
    format: String,
    version: u32,
    seed: u64,
    count: u64,
    config: CropConfig,
}

/// Generate `count` crops (global indices 0..count) into `dir`, in parallel. `progress` is
/// called with the number of crops finished so far.
///
/// # Errors
/// I/O errors (naming the file) and generation errors.
pub fn write_crops(
    dir: &Path,
    generator: &CropGenerator,
    count: u64,
    progress: &(dyn Fn(u64) + Sync),
) -> Result<(), SynthError> {
    let images = dir.join("images");
    std::fs::create_dir_all(&images).map_err(|e| SynthError::io(&images, e))?;
    write_atomic(&dir.join("FORMAT.md"), FORMAT_MD.as_bytes())?;
    let cfg = ConfigFile {
        format: "vpcal-synth-crops".into(),
        version: 1,
        seed: generator.seed(),
        count,
        config: generator.config().clone(),
    };
    let cfg_json = serde_json::to_vec_pretty(&cfg).map_err(|e| SynthError::Format {
        path: dir.join("config.json"),
        message: e.to_string(),
    })?;
    write_atomic(&dir.join("config.json"), &cfg_json)?;
    let mut lines = String::new();
    let chunk = 64u64;
    let mut start = 0u64;
    while start < count {
        let end = (start + chunk).min(count);
        let done: Vec<Result<String, SynthError>> = (start..end)
            .into_par_iter()
            .map(|i| {
                let c = generator.generate_index(i)?;
                let rec = record_of(&c);
                write_atomic(&dir.join(&rec.image), &c.jpeg)?;
                serde_json::to_string(&rec).map_err(|e| SynthError::Format {
                    path: dir.join("samples.jsonl"),
                    message: e.to_string(),
                })
            })
            .collect();
        for line in done {
            lines.push_str(&line?);
            lines.push('\n');
        }
        progress(end);
        start = end;
    }
    write_atomic(&dir.join("samples.jsonl"), lines.as_bytes())
}

/// The JSON record of a crop.
pub fn record_of(c: &CropSample) -> SampleRecord {
    let s = &c.sample;
    let h = crate::math::hull(&s.bb3d);
    SampleRecord {
        vehicle: s.id.vehicle,
        instance: s.id.instance,
        image: format!("images/{:07}_{}.jpg", s.id.vehicle, s.id.instance),
        width: s.image.width(),
        height: s.image.height(),
        bb3d: s.bb3d,
        vp1: s.vp1,
        vp2: s.vp2,
        box2d: [h.0, h.1, h.2, h.3],
        label_weight: s.label_weight,
        meta: SampleMeta::Synthetic(c.meta.clone()),
    }
}

/// Reads a crop directory as a [`vpcal_data::SampleSource`] of one split.
#[derive(Debug, Clone)]
pub struct CropDirSource {
    dir: PathBuf,
    split: Split,
    records: Vec<SampleRecord>,
}

impl CropDirSource {
    /// Open `dir` and keep the samples of `split`.
    ///
    /// # Errors
    /// [`DataError::File`] when `samples.jsonl` is missing or a line is malformed (with its
    /// line number and what was expected).
    pub fn open(dir: &Path, split: Split) -> Result<CropDirSource, DataError> {
        let all = read_records(dir)?;
        let records = all
            .into_iter()
            .filter(|r| Split::of_vehicle(r.vehicle) == split)
            .collect();
        Ok(CropDirSource {
            dir: dir.to_path_buf(),
            split,
            records,
        })
    }

    /// All records of this split (metadata without loading images).
    pub fn records(&self) -> &[SampleRecord] {
        &self.records
    }
}

/// Read and validate every line of `dir/samples.jsonl`.
///
/// # Errors
/// As [`CropDirSource::open`].
pub fn read_records(dir: &Path) -> Result<Vec<SampleRecord>, DataError> {
    let path = dir.join("samples.jsonl");
    let text = std::fs::read_to_string(&path).map_err(|e| DataError::File {
        path: path.clone(),
        message: format!("cannot read the crop index ({e}); is this a `vpcal synth crops` directory that finished writing?"),
    })?;
    let mut out = Vec::new();
    for (n, line) in text.lines().enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        let rec: SampleRecord = serde_json::from_str(line).map_err(|e| DataError::File {
            path: path.clone(),
            message: format!("line {}: {e} (see FORMAT.md for the fields)", n + 1),
        })?;
        let finite = rec
            .bb3d
            .iter()
            .flatten()
            .chain(&rec.vp1)
            .chain(&rec.vp2)
            .all(|v| v.is_finite());
        let weights_ok = rec
            .label_weight
            .iter()
            .all(|w| w.is_finite() && (0.0..=1.0).contains(w));
        if !weights_ok {
            return Err(DataError::File {
                path: path.clone(),
                message: format!(
                    "line {}: label_weight must hold two numbers in [0, 1], found {:?}",
                    n + 1,
                    rec.label_weight
                ),
            });
        }
        if !finite {
            return Err(DataError::File {
                path: path.clone(),
                message: format!("line {}: bb3d/vp1/vp2 must be finite numbers", n + 1),
            });
        }
        out.push(rec);
    }
    Ok(out)
}

impl vpcal_data::SampleSource for CropDirSource {
    fn len(&self) -> usize {
        self.records.len()
    }
    fn split(&self) -> Split {
        self.split
    }
    fn get(&self, index: usize) -> Result<Sample, DataError> {
        let rec = self.records.get(index).ok_or_else(|| DataError::File {
            path: self.dir.join("samples.jsonl"),
            message: format!(
                "index {index} out of range ({} samples)",
                self.records.len()
            ),
        })?;
        let path = self.dir.join(&rec.image);
        let sample_name = format!("{}_{}", rec.vehicle, rec.instance);
        let bytes = std::fs::read(&path).map_err(|e| DataError::Sample {
            path: path.clone(),
            sample: sample_name.clone(),
            message: e.to_string(),
        })?;
        let image = crate::post::decode_jpeg(&bytes).map_err(|e| DataError::Sample {
            path: path.clone(),
            sample: sample_name.clone(),
            message: format!("not a readable JPEG: {e}"),
        })?;
        if image.width() != rec.width || image.height() != rec.height {
            return Err(DataError::Sample {
                path,
                sample: sample_name,
                message: format!(
                    "image is {}x{}, samples.jsonl says {}x{}",
                    image.width(),
                    image.height(),
                    rec.width,
                    rec.height
                ),
            });
        }
        Ok(Sample {
            id: SampleId {
                vehicle: rec.vehicle,
                instance: rec.instance,
            },
            image,
            bb3d: rec.bb3d,
            vp1: rec.vp1,
            vp2: rec.vp2,
            label_weight: rec.label_weight,
        })
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use vpcal_data::SampleSource;

    fn real_record(vehicle: u64, weight: [f32; 2]) -> SampleRecord {
        let rect = [[2.0, 10.0], [14.0, 10.0], [14.0, 2.0], [2.0, 2.0]];
        SampleRecord {
            vehicle,
            instance: 0,
            image: "images/cam/a.jpg".into(),
            width: 16,
            height: 12,
            bb3d: [
                rect[0], rect[1], rect[2], rect[3], rect[0], rect[1], rect[2], rect[3],
            ],
            vp1: [8.0, -300.0],
            vp2: [4000.0, -290.0],
            box2d: [2.0, 2.0, 14.0, 10.0],
            label_weight: weight,
            meta: SampleMeta::Real(RealMeta {
                source: "clip.mp4".into(),
                camera: "cam".into(),
                frame: 12,
                track: 3,
                score: 0.8,
                det_box: [102.0, 52.0, 114.0, 60.0],
                crop_origin: [100.0, 50.0],
                frame_size: [320, 240],
                focal_px: 400.0,
                focal_source: "prior".into(),
                pp: [160.0, 120.0],
                vp1_sd_deg: 0.3,
                vp1_from_tangent: false,
                vp2_sd_deg: 2.0,
            }),
        }
    }

    #[test]
    fn real_crops_round_trip_with_their_label_weights() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::create_dir_all(dir.path().join("images/cam")).unwrap();
        let img = image::RgbImage::from_pixel(16, 12, image::Rgb([90, 100, 110]));
        let jpeg = crate::post::encode_jpeg(&img, 90).unwrap();
        std::fs::write(dir.path().join("images/cam/a.jpg"), jpeg).unwrap();
        let rec = real_record(12, [1.0, 0.5]);
        let cfg = serde_json::json!({"format": "vpcal-real-crops", "version": 1});
        write_index(dir.path(), &cfg, std::slice::from_ref(&rec)).unwrap();
        let text = std::fs::read_to_string(dir.path().join("samples.jsonl")).unwrap();
        assert!(text.contains("\"label_weight\":[1.0,0.5]"), "{text}");
        let src = CropDirSource::open(dir.path(), Split::Train).unwrap();
        assert_eq!(src.len(), 1);
        assert!(matches!(src.records()[0].meta, SampleMeta::Real(ref m) if m.camera == "cam"));
        let s = src.get(0).unwrap();
        assert_eq!(s.label_weight, [1.0, 0.5]);
        assert_eq!(s.vp2, [4000.0, -290.0]);
        // Exact labels are not written, and a line without them reads as exact.
        let exact = real_record(12, vpcal_data::EXACT_LABELS);
        write_index(dir.path(), &cfg, &[exact]).unwrap();
        let text = std::fs::read_to_string(dir.path().join("samples.jsonl")).unwrap();
        assert!(!text.contains("label_weight"), "{text}");
        let src = CropDirSource::open(dir.path(), Split::Train).unwrap();
        assert_eq!(src.get(0).unwrap().label_weight, vpcal_data::EXACT_LABELS);
        // A weight outside [0, 1] is refused with the line number.
        write_index(dir.path(), &cfg, &[real_record(12, [1.0, 1.5])]).unwrap();
        let e = CropDirSource::open(dir.path(), Split::Train).unwrap_err();
        assert!(e.to_string().contains("line 1: label_weight"), "{e}");
    }
}
