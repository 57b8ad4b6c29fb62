//! BoxCars116k: `dataset.pkl` and `atlas.pkl` (DESIGN.md §6), read with the safe pickle reader.
//!
//! - `dataset["cameras"][name]` = {pp, vp1, vp2, vp3, focal} in full-frame pixels;
//! - `dataset["samples"][vehicle]` = {camera, instances, ...}; an instance has `3DBB` (8x2
//!   projected box corners, frame pixels), `3DBB_offset` (the crop's origin in the frame),
//!   `2DBB`, `instance_id`, `path`;
//! - `atlas[vehicle][instance]` = the JPEG bytes of the crop (a uint8 numpy array as
//!   `cv2.imencode` returns it, or a Python-2 byte string).
//!
//! Crop-frame geometry is frame geometry minus `3DBB_offset`. The split is by vehicle:
//! `vehicle % 10 == 0` validation, `== 1` test, else train.
//!
//! # Memory
//! `dataset.pkl` is parsed whole into compact per-instance records. `atlas.pkl` (several GB for
//! the real dataset) is read once as a stream that keeps only the byte range of every JPEG
//! ([`vpcal_formats::pickle::LoadOptions::defer_bytes_over`]); crops are read from the file
//! (positioned reads, no shared cursor) and decoded when a sample is requested. Resident memory
//! is therefore the index (tens of bytes per crop) plus the crops being decoded.

use std::fs::File;
use std::io::{self, Read};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use vpcal_formats::pickle::{self, ArrayData, ByteSpan, DtypeKind, LoadOptions, Value, View};

use crate::{DataError, Sample, SampleId, SampleSource, Split};

/// A BoxCars camera, full-frame pixels.
#[derive(Debug, Clone, PartialEq)]
pub struct Camera {
    pub name: String,
    pub pp: [f64; 2],
    pub vp1: [f64; 2],
    pub vp2: [f64; 2],
    pub vp3: [f64; 2],
    pub focal_px: f64,
}

/// One vehicle (track) and its instances.
#[derive(Debug, Clone, PartialEq)]
pub struct Vehicle {
    /// Index into [`BoxCars::cameras`].
    pub camera: usize,
    pub instances: Vec<Instance>,
}

/// One image of a vehicle.
#[derive(Debug, Clone, PartialEq)]
pub struct Instance {
    /// The 8 projected 3D box corners, full-frame pixels.
    pub bb3d_in_frame: [[f64; 2]; 8],
    /// Where the crop's pixel (0, 0) lies in the frame.
    pub crop_offset: [f64; 2],
    /// The annotated 2D box (x, y, w, h) in frame pixels, when present.
    pub bb2d: Option<[f64; 4]>,
}

#[derive(Debug, Clone)]
enum AtlasEntry {
    /// Byte range of the JPEG in `atlas.pkl`.
    Span(ByteSpan),
    /// A small crop kept in memory.
    Inline(Arc<[u8]>),
}

/// Progress of [`BoxCars::open_with_progress`]: bytes of `atlas.pkl` indexed so far, of total.
pub type ProgressFn<'a> = &'a dyn Fn(u64, u64);

/// A BoxCars116k dataset directory (`dataset.pkl` + `atlas.pkl`), indexed.
#[derive(Debug, Clone)]
pub struct BoxCars {
    inner: Arc<Inner>,
}

#[derive(Debug)]
struct Inner {
    dataset_path: PathBuf,
    atlas_path: PathBuf,
    atlas_file: File,
    cameras: Vec<Camera>,
    vehicles: Vec<Vehicle>,
    atlas: Vec<Vec<AtlasEntry>>,
}

fn file_err(path: &Path, message: impl Into<String>) -> DataError {
    DataError::File {
        path: path.to_path_buf(),
        message: message.into(),
    }
}

fn sample_name(vehicle: usize, instance: Option<usize>) -> String {
    match instance {
        Some(i) => format!("vehicle {vehicle} instance {i}"),
        None => format!("vehicle {vehicle}"),
    }
}

/// `[N][M]...` or `["samples"][N]["instances"][M]...` → (N, M).
fn sample_in_location(location: &str, dataset: bool) -> Option<(usize, Option<usize>)> {
    let rest = if dataset {
        location.strip_prefix(r#"["samples"]"#)?
    } else {
        location
    };
    let number = |s: &str| -> Option<(usize, usize)> {
        let s = s.strip_prefix('[')?;
        let end = s.find(']')?;
        Some((s[..end].parse().ok()?, end + 2))
    };
    let (vehicle, used) = number(rest)?;
    let rest = &rest[used..];
    let rest = if dataset {
        rest.strip_prefix(r#"["instances"]"#).unwrap_or("")
    } else {
        rest
    };
    Some((vehicle, number(rest).map(|(i, _)| i)))
}

fn pickle_err(path: &Path, mut e: pickle::PickleError, dataset: bool) -> DataError {
    e.path = None; // the DataError names the file
    let message = e.to_string();
    match e
        .location
        .as_deref()
        .and_then(|l| sample_in_location(l, dataset))
    {
        Some((vehicle, instance)) => DataError::Sample {
            path: path.to_path_buf(),
            sample: sample_name(vehicle, instance),
            message,
        },
        None => file_err(path, message),
    }
}

/// A reader that reports its progress.
struct Counting<'a, R> {
    inner: R,
    done: u64,
    total: u64,
    last_report: u64,
    progress: ProgressFn<'a>,
}

impl<R: Read> Read for Counting<'_, R> {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        let n = self.inner.read(buf)?;
        self.done += n as u64;
        if self.done - self.last_report >= 1 << 22 || n == 0 {
            self.last_report = self.done;
            (self.progress)(self.done, self.total);
        }
        Ok(n)
    }
}

fn xy(view: &View<'_>) -> Result<[f64; 2], String> {
    view.as_f64_array::<2>().map_err(|e| e.to_string())
}

impl BoxCars {
    /// Open and index a dataset directory.
    ///
    /// # Errors
    /// [`DataError::File`] for a missing or malformed file, [`DataError::Sample`] when the
    /// problem is inside one vehicle's record (a forbidden global in the pickle included).
    pub fn open(dir: &Path) -> Result<BoxCars, DataError> {
        BoxCars::open_with_progress(dir, &|_, _| {})
    }

    /// [`BoxCars::open`], reporting the progress of the atlas pass.
    ///
    /// # Errors
    /// As [`BoxCars::open`].
    pub fn open_with_progress(dir: &Path, progress: ProgressFn<'_>) -> Result<BoxCars, DataError> {
        let dataset_path = dir.join("dataset.pkl");
        let atlas_path = dir.join("atlas.pkl");
        let dataset = pickle::from_path(&dataset_path, &LoadOptions::default())
            .map_err(|e| pickle_err(&dataset_path, e, true))?;
        let (cameras, vehicles) = parse_dataset(&dataset, &dataset_path)?;
        drop(dataset);

        let atlas_file = File::open(&atlas_path)
            .map_err(|e| file_err(&atlas_path, format!("cannot open: {e}")))?;
        let total = atlas_file.metadata().map(|m| m.len()).unwrap_or(0);
        let reader = Counting {
            inner: &atlas_file,
            done: 0,
            total,
            last_report: 0,
            progress,
        };
        let opts = LoadOptions {
            defer_bytes_over: Some(256),
        };
        let atlas_value = pickle::from_reader_with(reader, &opts)
            .map_err(|e| pickle_err(&atlas_path, e, false))?;
        let atlas = index_atlas(&atlas_value, &vehicles, &atlas_path)?;
        Ok(BoxCars {
            inner: Arc::new(Inner {
                dataset_path,
                atlas_path,
                atlas_file,
                cameras,
                vehicles,
                atlas,
            }),
        })
    }

    /// The cameras, in the order of `dataset["cameras"]`.
    pub fn cameras(&self) -> &[Camera] {
        &self.inner.cameras
    }

    /// The vehicles, indexed by vehicle id.
    pub fn vehicles(&self) -> &[Vehicle] {
        &self.inner.vehicles
    }

    /// Path of `dataset.pkl`.
    pub fn dataset_path(&self) -> &Path {
        &self.inner.dataset_path
    }

    /// Path of `atlas.pkl`.
    pub fn atlas_path(&self) -> &Path {
        &self.inner.atlas_path
    }

    /// The instances of one split, in vehicle then instance order.
    pub fn split(&self, split: Split) -> BoxCarsSplit {
        let items = self
            .inner
            .vehicles
            .iter()
            .enumerate()
            .filter(|(vid, _)| Split::of_vehicle(*vid as u64) == split)
            .flat_map(|(vid, v)| (0..v.instances.len()).map(move |iid| (vid, iid)))
            .collect();
        BoxCarsSplit {
            data: self.clone(),
            split,
            items,
        }
    }

    /// The raw (encoded) crop of one instance.
    ///
    /// # Errors
    /// [`DataError::Sample`] when the ids are out of range or the bytes cannot be read.
    pub fn crop_bytes(&self, vehicle: usize, instance: usize) -> Result<Arc<[u8]>, DataError> {
        let entry = self
            .inner
            .atlas
            .get(vehicle)
            .and_then(|v| v.get(instance))
            .ok_or_else(|| DataError::Sample {
                path: self.inner.atlas_path.clone(),
                sample: sample_name(vehicle, Some(instance)),
                message: "no such vehicle/instance".into(),
            })?;
        match entry {
            AtlasEntry::Inline(bytes) => Ok(bytes.clone()),
            AtlasEntry::Span(span) => {
                read_span(&self.inner.atlas_file, &self.inner.atlas_path, *span)
                    .map(Arc::from)
                    .map_err(|e| DataError::Sample {
                        path: self.inner.atlas_path.clone(),
                        sample: sample_name(vehicle, Some(instance)),
                        message: format!(
                            "cannot read {} bytes at offset {}: {e}",
                            span.len, span.offset
                        ),
                    })
            }
        }
    }

    /// Decode one instance into a [`Sample`] (crop pixels).
    ///
    /// # Errors
    /// [`DataError::Sample`] naming `atlas.pkl` and the sample for unreadable or corrupt crops.
    pub fn sample(&self, vehicle: usize, instance: usize) -> Result<Sample, DataError> {
        let bytes = self.crop_bytes(vehicle, instance)?;
        let sample_err = |message: String| DataError::Sample {
            path: self.inner.atlas_path.clone(),
            sample: sample_name(vehicle, Some(instance)),
            message,
        };
        let image = image::load_from_memory(&bytes)
            .map_err(|e| sample_err(format!("cannot decode the crop image: {e}")))?
            .to_rgb8();
        let v = &self.inner.vehicles[vehicle];
        let inst = &v.instances[instance];
        let cam = &self.inner.cameras[v.camera];
        let [ox, oy] = inst.crop_offset;
        let rel = |p: [f64; 2]| [p[0] - ox, p[1] - oy];
        Ok(Sample {
            id: SampleId {
                vehicle: vehicle as u64,
                instance: instance as u32,
            },
            image,
            bb3d: inst.bb3d_in_frame.map(rel),
            vp1: rel(cam.vp1),
            vp2: rel(cam.vp2),
            label_weight: crate::EXACT_LABELS,
        })
    }
}

#[cfg(unix)]
fn read_span(file: &File, _path: &Path, span: ByteSpan) -> io::Result<Vec<u8>> {
    use std::os::unix::fs::FileExt;
    let len = usize::try_from(span.len).map_err(io::Error::other)?;
    let mut buf = vec![0u8; len];
    file.read_exact_at(&mut buf, span.offset)?;
    Ok(buf)
}

#[cfg(not(unix))]
fn read_span(_file: &File, path: &Path, span: ByteSpan) -> io::Result<Vec<u8>> {
    // No positioned reads: a private handle per read keeps workers independent.
    span.read_from(&mut File::open(path)?)
}

fn parse_dataset(v: &Value, path: &Path) -> Result<(Vec<Camera>, Vec<Vehicle>), DataError> {
    let root = v.view();
    let cams = root
        .get("cameras")
        .and_then(|c| c.entries())
        .map_err(|e| file_err(path, e.to_string()))?;
    let mut cameras = Vec::with_capacity(cams.len());
    for (key, cam) in cams {
        let name = match key {
            Value::Str(s) => s.clone(),
            other => other
                .to_decimal_string()
                .ok_or_else(|| file_err(path, format!("camera key {}", other.describe())))?,
        };
        let parse = || -> Result<Camera, String> {
            Ok(Camera {
                name: name.clone(),
                pp: xy(&cam.get("pp").map_err(|e| e.to_string())?)?,
                vp1: xy(&cam.get("vp1").map_err(|e| e.to_string())?)?,
                vp2: xy(&cam.get("vp2").map_err(|e| e.to_string())?)?,
                vp3: xy(&cam.get("vp3").map_err(|e| e.to_string())?)?,
                focal_px: cam
                    .get("focal")
                    .and_then(|f| f.as_f64())
                    .map_err(|e| e.to_string())?,
            })
        };
        let camera = parse().map_err(|m| file_err(path, format!("camera {name:?}: {m}")))?;
        if !camera.vp1.iter().chain(&camera.vp2).all(|x| x.is_finite()) {
            return Err(file_err(
                path,
                format!("camera {name:?}: VP1 or VP2 is not finite"),
            ));
        }
        cameras.push(camera);
    }
    let samples = root
        .get("samples")
        .map_err(|e| file_err(path, e.to_string()))?;
    let samples: Vec<(usize, View<'_>)> = match samples.value {
        Value::List(_) | Value::Tuple(_) => samples
            .items()
            .map_err(|e| file_err(path, e.to_string()))?
            .into_iter()
            .enumerate()
            .collect(),
        Value::Dict(_) => {
            // A dict keyed by vehicle id: accept it when the ids are 0..n.
            let entries = samples
                .entries()
                .map_err(|e| file_err(path, e.to_string()))?;
            let mut out = Vec::with_capacity(entries.len());
            for (k, view) in entries {
                let id = k
                    .as_i64()
                    .and_then(|i| usize::try_from(i).ok())
                    .ok_or_else(|| {
                        file_err(
                            path,
                            format!("samples key {} is not a vehicle id", k.describe()),
                        )
                    })?;
                out.push((id, view));
            }
            out.sort_by_key(|(id, _)| *id);
            if out.iter().enumerate().any(|(i, (id, _))| i != *id) {
                return Err(file_err(path, "samples ids are not 0..n"));
            }
            out
        }
        _ => {
            return Err(file_err(
                path,
                format!(
                    r#"["samples"]: expected a list, found {}"#,
                    samples.value.describe()
                ),
            ))
        }
    };
    let mut vehicles = Vec::with_capacity(samples.len());
    for (vid, s) in samples {
        let parse = || -> Result<Vehicle, (Option<usize>, String)> {
            let whole = |e: pickle::AccessError| (None, e.to_string());
            let cam_name = s.get("camera").map_err(whole)?;
            let camera = match cam_name.value {
                Value::Str(name) => cameras.iter().position(|c| &c.name == name),
                other => other
                    .to_decimal_string()
                    .and_then(|n| cameras.iter().position(|c| c.name == n)),
            }
            .ok_or_else(|| {
                (
                    None,
                    format!(
                        "camera {} is not in [\"cameras\"]",
                        cam_name.value.describe()
                    ),
                )
            })?;
            let mut instances = Vec::new();
            for (iid, inst) in s
                .get("instances")
                .and_then(|i| i.items())
                .map_err(whole)?
                .iter()
                .enumerate()
            {
                let one = |e: pickle::AccessError| (Some(iid), e.to_string());
                let bb = inst.get("3DBB").map_err(one)?;
                let (shape, data) = bb.as_array_f64().map_err(one)?;
                if data.len() != 16 {
                    return Err((
                        Some(iid),
                        format!("{}: expected 8x2 corners, found shape {shape:?}", bb.path()),
                    ));
                }
                let mut bb3d_in_frame = [[0.0; 2]; 8];
                for (k, c) in bb3d_in_frame.iter_mut().enumerate() {
                    *c = [data[2 * k], data[2 * k + 1]];
                }
                let crop_offset =
                    xy(&inst.get("3DBB_offset").map_err(one)?).map_err(|m| (Some(iid), m))?;
                let bb2d = match inst.get_opt("2DBB").map_err(one)? {
                    Some(b) => b.as_f64_array::<4>().ok(),
                    None => None,
                };
                if !bb3d_in_frame
                    .iter()
                    .flatten()
                    .chain(&crop_offset)
                    .all(|x| x.is_finite())
                {
                    return Err((Some(iid), "non-finite 3DBB or 3DBB_offset".into()));
                }
                instances.push(Instance {
                    bb3d_in_frame,
                    crop_offset,
                    bb2d,
                });
            }
            Ok(Vehicle { camera, instances })
        };
        vehicles.push(parse().map_err(|(iid, message)| DataError::Sample {
            path: path.to_path_buf(),
            sample: sample_name(vid, iid),
            message,
        })?);
    }
    Ok((cameras, vehicles))
}

fn atlas_entry(v: &Value) -> Option<AtlasEntry> {
    match v {
        Value::Deferred(span) => Some(AtlasEntry::Span(*span)),
        Value::Array(a)
            if matches!(a.dtype.kind, DtypeKind::UInt | DtypeKind::Int)
                && a.dtype.itemsize == 1 =>
        {
            match &a.data {
                ArrayData::Deferred { span, .. } => Some(AtlasEntry::Span(*span)),
                _ => v
                    .as_byte_string()
                    .map(|b| AtlasEntry::Inline(Arc::from(b.as_ref()))),
            }
        }
        Value::Bytes(_) | Value::Str(_) => v
            .as_byte_string()
            .map(|b| AtlasEntry::Inline(Arc::from(b.as_ref()))),
        _ => None,
    }
}

fn index_atlas(
    atlas: &Value,
    vehicles: &[Vehicle],
    path: &Path,
) -> Result<Vec<Vec<AtlasEntry>>, DataError> {
    let outer = atlas.as_list().ok_or_else(|| {
        file_err(
            path,
            format!("expected a list of vehicles, found {}", atlas.describe()),
        )
    })?;
    if outer.len() != vehicles.len() {
        return Err(file_err(
            path,
            format!(
                "holds {} vehicles but dataset.pkl has {}",
                outer.len(),
                vehicles.len()
            ),
        ));
    }
    let mut index = Vec::with_capacity(outer.len());
    for (vid, (crops, vehicle)) in outer.iter().zip(vehicles).enumerate() {
        let crops = crops.as_list().ok_or_else(|| DataError::Sample {
            path: path.to_path_buf(),
            sample: sample_name(vid, None),
            message: format!("expected a list of crops, found {}", crops.describe()),
        })?;
        if crops.len() != vehicle.instances.len() {
            return Err(DataError::Sample {
                path: path.to_path_buf(),
                sample: sample_name(vid, None),
                message: format!(
                    "{} crops for {} instances in dataset.pkl",
                    crops.len(),
                    vehicle.instances.len()
                ),
            });
        }
        let mut entries = Vec::with_capacity(crops.len());
        for (iid, crop) in crops.iter().enumerate() {
            entries.push(atlas_entry(crop).ok_or_else(|| DataError::Sample {
                path: path.to_path_buf(),
                sample: sample_name(vid, Some(iid)),
                message: format!("expected encoded image bytes, found {}", crop.describe()),
            })?);
        }
        index.push(entries);
    }
    Ok(index)
}

/// The instances of one split of a [`BoxCars`] dataset, as a [`SampleSource`].
#[derive(Debug, Clone)]
pub struct BoxCarsSplit {
    data: BoxCars,
    split: Split,
    items: Vec<(usize, usize)>,
}

impl BoxCarsSplit {
    /// (vehicle, instance) of each sample.
    pub fn items(&self) -> &[(usize, usize)] {
        &self.items
    }

    /// The dataset.
    pub fn dataset(&self) -> &BoxCars {
        &self.data
    }
}

impl SampleSource for BoxCarsSplit {
    fn len(&self) -> usize {
        self.items.len()
    }

    fn split(&self) -> Split {
        self.split
    }

    fn get(&self, index: usize) -> Result<Sample, DataError> {
        let &(vid, iid) = self.items.get(index).ok_or_else(|| {
            file_err(
                self.data.atlas_path(),
                format!(
                    "sample index {index} out of range (split has {})",
                    self.items.len()
                ),
            )
        })?;
        self.data.sample(vid, iid)
    }
}
