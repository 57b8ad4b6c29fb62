//! `vpcal._native`: the vpcal library for Python (pyo3). The pure-Python package `vpcal`
//! (python/vpcal) wraps it with numpy arrays, classes and progress bars; this module speaks
//! plain Python values and JSON text (the calibration file, VPout records, tracks), so that
//! every file the package writes is the one the CLI writes.
//!
//! Everything here calls the library (`vpcal::pipeline`, `vpcal::output`, `vpcal::road`,
//! `vpcal::detector`, `vpcal::model`); nothing re-implements the CLI. Long work (the pipeline,
//! the aggregation, the network) runs with the interpreter detached, so other Python threads
//! run meanwhile.

use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use image::RgbImage;
use pyo3::create_exception;
use pyo3::exceptions::{PyException, PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict, PyTuple};
use vpcal::detector::{DetectorChoice, DetectorSettings};
use vpcal::output::{self, RecordSettings};
use vpcal::pipeline::{PipelineConfig, PipelineOutput, PrincipalPoint};
use vpcal::progress::{FrameProgress, Progress};
use vpcal::road::{KnownDistance, RoadCamera, RoadMeasure, ScaleInput};
use vpcal_formats::calib::CalibrationFile;
use vpcal_formats::json::Json;
use vpcal_formats::reference::{read_vpout, vpout_from_json, SceneRecord, VpOutItem};
use vpcal_geom::{BoxPx, Point2};
use vpcal_video::source::PictureSource;
use vpcal_video::{Frame, FrameSource, SourceInfo, SourceKind, SourceOptions};

create_exception!(
    _native,
    VpcalError,
    PyException,
    "An error of vpcal: a missing or malformed input (the message names the file and field), \
     an unwritable output, a failing tool. The message is the CLI's."
);
create_exception!(
    _native,
    NotCalibrated,
    VpcalError,
    "The run completed but the footage or records could not support a calibration (the CLI's \
     exit code 3). The message is the reason; `calibration_file` the calibration file (JSON \
     text) that says why."
);

/// An error of the library as a Python exception, with the CLI's message (`{e:#}`: the
/// whole chain of context).
fn err(e: anyhow::Error) -> PyErr {
    VpcalError::new_err(format!("{e:#}"))
}

/// Read an optional setting `key` of `d` (absent or None: `None`); a value of the wrong type
/// is a TypeError naming the setting.
fn opt<'py, T: for<'a> FromPyObject<'a, 'py>>(
    d: &Bound<'py, PyDict>,
    key: &str,
    expected: &str,
) -> PyResult<Option<T>> {
    match d.get_item(key)? {
        None => Ok(None),
        Some(v) if v.is_none() => Ok(None),
        Some(v) => v.extract::<T>().map(Some).map_err(|_| {
            let got = v
                .get_type()
                .name()
                .map_or_else(|_| "?".to_string(), |n| n.to_string());
            PyTypeError::new_err(format!("{key}: expected {expected}, got {got}"))
        }),
    }
}

/// A setting parsed from text by the library's parser (the CLI's flag values).
fn parsed<T: std::str::FromStr>(d: &Bound<'_, PyDict>, key: &str) -> PyResult<Option<T>>
where
    T::Err: std::fmt::Display,
{
    let Some(text) = opt::<String>(d, key, "a string")? else {
        return Ok(None);
    };
    text.parse::<T>()
        .map(Some)
        .map_err(|e| PyValueError::new_err(format!("{key}: {e}")))
}

/// A setting given as a pair of numbers or as text, parsed by the library's parser as the
/// CLI's `A,B` or word: the principal point (`"centre"`, `"bcs"` or `(x, y)`), the marking
/// standard (`(period, lane width)` in metres or a standard's key, `"us"`).
fn pair_or_text<T: std::str::FromStr>(d: &Bound<'_, PyDict>, key: &str) -> PyResult<Option<T>>
where
    T::Err: std::fmt::Display,
{
    if let Ok(Some((a, b))) = opt::<(f64, f64)>(d, key, "") {
        return format!("{a},{b}")
            .parse()
            .map(Some)
            .map_err(|e| PyValueError::new_err(format!("{key}: {e}")));
    }
    parsed(d, key)
}

/// The pipeline configuration of the settings in `d` (the CLI's flags by their Python
/// names); absent settings keep the library's defaults, which are the CLI's.
fn pipeline_config(d: &Bound<'_, PyDict>) -> PyResult<PipelineConfig> {
    let mut c = PipelineConfig::default();
    if let Some(v) = opt::<PathBuf>(d, "model", "a path")? {
        c.model = Some(v);
    }
    if let Some(v) = opt(d, "device", "a string")? {
        c.device = v;
    }
    if let Some(v) = opt(d, "batch", "an int")? {
        c.batch = v;
    }
    if let Some(v) = opt(d, "flip_average", "a bool")? {
        c.flip_average = v;
    }
    if let Some(v) = opt(d, "min_crop_px", "a number")? {
        c.min_crop_px = v;
    }
    if let Some(v) = opt(d, "edgelets", "a bool")? {
        c.edgelets = v;
    }
    if let Some(v) = opt(d, "replay", "a bool")? {
        c.replay = v;
    }
    c.frames = frame_options(d)?;
    c.detector = detector_settings(d)?;
    if let Some(v) = opt(d, "min_score", "a number")? {
        c.min_score = v;
    }
    if let Some(v) = opt(d, "keep_static", "a bool")? {
        c.keep_static = v;
    }
    if let Some(v) = opt(d, "max_per_frame", "an int")? {
        c.max_per_frame = v;
    }
    if let Some(v) = opt(d, "max_records", "an int")? {
        c.max_records = v;
    }
    if let Some(v) = parsed(d, "crops")? {
        c.crops = v;
    }
    if let Some(v) = parsed(d, "method")? {
        c.method = v;
    }
    if let Some(v) = opt(d, "bootstrap", "an int")? {
        c.bootstrap = v;
    }
    if let Some(v) = pair_or_text::<PrincipalPoint>(d, "pp")? {
        c.pp = v;
    }
    c.focal_px = opt(d, "focal", "a number of pixels")?;
    c.focal_range_px = opt(d, "focal_range", "(short, long) focal lengths in pixels")?;
    c.markings = pair_or_text(d, "markings")?;
    c.validate().map_err(err)?;
    Ok(c)
}

/// Frame selection: `every`, `max_frames`, `fps`, `start` (a frame index, or `"4.5s"`).
fn frame_options(d: &Bound<'_, PyDict>) -> PyResult<SourceOptions> {
    let mut o = SourceOptions::default();
    if let Some(v) = opt(d, "every", "an int")? {
        o.every = v;
    }
    o.max_frames = opt(d, "max_frames", "an int")?;
    o.image_fps = opt(d, "fps", "a number")?;
    if let Ok(Some(n)) = opt::<u64>(d, "start", "") {
        o.start = n
            .to_string()
            .parse()
            .map_err(|e: vpcal_video::VideoError| PyValueError::new_err(e.to_string()))?;
    } else if let Some(v) = parsed::<vpcal_video::Start>(d, "start")? {
        o.start = v;
    }
    Ok(o)
}

/// The detector settings: `detector` (`auto`, `yolox`, `motion`, `file:PATH`, ...), `tiles`,
/// `onnx_layout`, `motorcycles`, `road_mask`.
fn detector_settings(d: &Bound<'_, PyDict>) -> PyResult<DetectorSettings> {
    let mut s = DetectorSettings::default();
    if let Some(v) = parsed::<DetectorChoice>(d, "detector")? {
        s.choice = v;
    }
    s.tiles = opt(d, "tiles", "an int")?;
    if let Some(v) = opt(d, "tile_rotation", "a bool")? {
        s.tile_rotation = v;
    }
    if let Some(v) = parsed(d, "onnx_layout")? {
        s.onnx_layout = v;
    }
    if let Some(v) = opt(d, "motorcycles", "a bool")? {
        s.motorcycles = v;
    }
    s.road_mask = opt(d, "road_mask", "a path")?;
    s.validate().map_err(err)?;
    Ok(s)
}

/// The known road distance for the metric scale: `scale_points` `(x1, y1, x2, y2)` and
/// `scale_distance` (metres), both or neither.
fn known_distance(d: &Bound<'_, PyDict>) -> PyResult<Option<KnownDistance>> {
    let points: Option<(f64, f64, f64, f64)> =
        opt(d, "scale_points", "four numbers (x1, y1, x2, y2)")?;
    let distance: Option<f64> = opt(d, "scale_distance", "a number of metres")?;
    match (points, distance) {
        (None, None) => Ok(None),
        (Some((x1, y1, x2, y2)), Some(m)) => {
            if !(m.is_finite() && m > 0.0) {
                return Err(PyValueError::new_err(format!(
                    "--scale-distance {m}: expected a positive number of metres"
                )));
            }
            Ok(Some(KnownDistance {
                p1: Point2::new(x1, y1),
                p2: Point2::new(x2, y2),
                distance_m: m,
            }))
        }
        _ => Err(PyValueError::new_err(
            "scale_points and scale_distance go together: give both or neither",
        )),
    }
}

/// Progress reports to a Python callable `callback(frames_done, frames_expected_or_None,
/// vehicle_boxes)`. An exception it raises is kept and raised when the run returns.
struct PyProgress {
    callback: Option<Py<PyAny>>,
    total: Mutex<Option<u64>>,
    error: Mutex<Option<PyErr>>,
}

impl PyProgress {
    fn new(callback: Option<Py<PyAny>>) -> PyProgress {
        PyProgress {
            callback,
            total: Mutex::new(None),
            error: Mutex::new(None),
        }
    }

    fn report(&self, frames: u64, boxes: u64) {
        let Some(cb) = &self.callback else { return };
        let mut error = self.error.lock().unwrap_or_else(|e| e.into_inner());
        if error.is_some() {
            return;
        }
        let total = *self.total.lock().unwrap_or_else(|e| e.into_inner());
        Python::attach(|py| {
            if let Err(e) = cb.bind(py).call1((frames, total, boxes)) {
                *error = Some(e);
            }
        });
    }

    fn take_error(&self) -> Option<PyErr> {
        self.error.lock().unwrap_or_else(|e| e.into_inner()).take()
    }
}

impl Progress for PyProgress {
    fn start(&self, frames: Option<u64>) {
        *self.total.lock().unwrap_or_else(|e| e.into_inner()) = frames;
        self.report(0, 0);
    }

    fn add_frames(&self, more: u64) {
        let mut t = self.total.lock().unwrap_or_else(|e| e.into_inner());
        *t = t.map(|t| t + more);
    }

    fn frame_done(&self, at: &FrameProgress) {
        self.report(at.frames, at.vehicle_boxes);
    }
}

/// What a calibration run gives Python: the calibration file, and on request the vehicle
/// records and tracks, as JSON text; `ok` false when the footage supported no camera.
fn run_result(
    py: Python<'_>,
    out: &PipelineOutput,
    config: &PipelineConfig,
    options: &Bound<'_, PyDict>,
) -> PyResult<Py<PyDict>> {
    let known = known_distance(options)?;
    let want_vehicles: bool = opt(options, "vehicles", "a bool")?.unwrap_or(false);
    let want_tracks: bool = opt(options, "tracks", "a bool")?.unwrap_or(false);
    let want_overlay: bool = opt(options, "overlay", "a bool")?.unwrap_or(false);
    let result = py.detach(|| vpcal::calibrate(out, config));
    let r = PyDict::new(py);
    match &result {
        Ok((cal, agg)) => {
            let known: Vec<KnownDistance> = known.into_iter().collect();
            let output::CalibratedRun {
                file,
                camera,
                tracks,
                header,
                ..
            } = output::calibrated_run(out, config, cal, agg, &known).map_err(err)?;
            if want_tracks {
                r.set_item("tracks", output::tracks_json(&header, &tracks).to_string())?;
            }
            if want_overlay {
                let cam = Some((&camera, agg.track_lines.as_slice()));
                let scale = file.scale_m_per_unit;
                set_overlay(py, &r, out, config, cam, &tracks, scale)?;
            }
            r.set_item("ok", true)?;
            r.set_item("calibration", file.to_json_string())?;
        }
        Err(e) => {
            let file = output::failure_file(out, config, format!("{e:#}"));
            if want_tracks {
                let (tracks, header) = output::run_tracks(out, None, false, false);
                r.set_item("tracks", output::tracks_json(&header, &tracks).to_string())?;
            }
            if want_overlay {
                let (tracks, _) = output::run_tracks(out, None, false, false);
                set_overlay(py, &r, out, config, None, &tracks, None)?;
            }
            r.set_item("ok", false)?;
            r.set_item("reason", format!("{e:#}"))?;
            r.set_item("calibration", file.to_json_string())?;
        }
    }
    if want_vehicles {
        let items = output::vehicle_items(out);
        let json = Json::Array(items.iter().map(VpOutItem::to_json).collect());
        r.set_item("vehicles", json.to_strict_string())?;
    }
    r.set_item("warnings", out.warnings.clone())?;
    Ok(r.unbind())
}

/// The overlay picture of a run (`calibrate --overlay`'s) as PNG bytes in `r["overlay_png"]`,
/// when the run has a picture.
fn set_overlay(
    py: Python<'_>,
    r: &Bound<'_, PyDict>,
    out: &PipelineOutput,
    config: &PipelineConfig,
    cam: Option<(
        &vpcal_geom::camera::Calibration,
        &[vpcal_geom::aggregate::tracks::TrackLine],
    )>,
    tracks: &[vpcal::tracks::VehicleTrack],
    scale: Option<f64>,
) -> PyResult<()> {
    let png = py
        .detach(|| {
            vpcal::overlay::draw_run(out, &config.frames, cam, tracks, scale)
                .map(|img| vpcal_formats::fs::encode_png(&img))
                .transpose()
        })
        .map_err(|e| err(anyhow::anyhow!("the overlay picture: {e}")))?;
    if let Some(bytes) = png {
        r.set_item("overlay_png", PyBytes::new(py, &bytes))?;
    }
    Ok(())
}

/// Calibrate from the video, image folder or image at `path` with `options` (the CLI's
/// flags); `progress(frames_done, frames_expected, vehicle_boxes)` is called after each frame.
#[pyfunction]
#[pyo3(signature = (path, options, progress=None))]
fn calibrate_path(
    py: Python<'_>,
    path: PathBuf,
    options: &Bound<'_, PyDict>,
    progress: Option<Py<PyAny>>,
) -> PyResult<Py<PyDict>> {
    let config = pipeline_config(options)?;
    let reporter = PyProgress::new(progress);
    let out = py.detach(|| vpcal::run_pipeline(&path, &config, &reporter));
    if let Some(e) = reporter.take_error() {
        return Err(e);
    }
    let out = out.map_err(err)?;
    run_result(py, &out, &config, options)
}

/// Pictures from a Python iterator of `(height, width, rgb_bytes)` tuples (the package checks
/// and converts numpy arrays into them). An exception of the iterator is kept in `error`, so
/// that the caller sees it as it was raised.
struct PyPictures {
    iter: Py<PyAny>,
    label: PathBuf,
    error: Arc<Mutex<Option<PyErr>>>,
}

impl PyPictures {
    fn picture(item: &Bound<'_, PyAny>) -> PyResult<RgbImage> {
        let t = item.cast::<PyTuple>()?;
        let (h, w, data): (u32, u32, Bound<'_, PyBytes>) = t.extract()?;
        picture(h, w, data.as_bytes())
    }
}

impl Iterator for PyPictures {
    type Item = vpcal_video::Result<RgbImage>;

    fn next(&mut self) -> Option<Self::Item> {
        let got = Python::attach(|py| -> PyResult<Option<RgbImage>> {
            let it = self.iter.bind(py);
            match it.call_method0("__next__") {
                Ok(item) => Self::picture(&item).map(Some),
                Err(e) if e.is_instance_of::<pyo3::exceptions::PyStopIteration>(py) => Ok(None),
                Err(e) => Err(e),
            }
        });
        match got {
            Ok(Some(p)) => Some(Ok(p)),
            Ok(None) => None,
            Err(e) => {
                let message = e.to_string();
                *self.error.lock().unwrap_or_else(|e| e.into_inner()) = Some(e);
                Some(Err(vpcal_video::VideoError::Image {
                    path: self.label.clone(),
                    message,
                }))
            }
        }
    }
}

/// Calibrate from frames in memory: `open()` returns a fresh iterator of `(height, width,
/// rgb_bytes)` each time it is called (twice when the motion detector looks at its warm-up
/// again). `label` names the frames in results and messages.
#[pyfunction]
#[pyo3(signature = (open, label, options, progress=None))]
fn calibrate_frames(
    py: Python<'_>,
    open: Py<PyAny>,
    label: &str,
    options: &Bound<'_, PyDict>,
    progress: Option<Py<PyAny>>,
) -> PyResult<Py<PyDict>> {
    let config = pipeline_config(options)?;
    let reporter = PyProgress::new(progress);
    let error: Arc<Mutex<Option<PyErr>>> = Arc::new(Mutex::new(None));
    let label = vpcal_video::source::picture_label(label);
    let frames = config.frames.clone();
    let mut open_source = || -> anyhow::Result<Box<dyn FrameSource>> {
        let iter = Python::attach(|py| open.bind(py).call0().map(Bound::unbind));
        let iter = match iter {
            Ok(it) => it,
            Err(e) => {
                let message = e.to_string();
                *error.lock().unwrap_or_else(|e| e.into_inner()) = Some(e);
                anyhow::bail!("{message}");
            }
        };
        let pictures = PyPictures {
            iter,
            label: label.clone(),
            error: Arc::clone(&error),
        };
        Ok(Box::new(PictureSource::new(&label, pictures, &frames)?))
    };
    let out = py.detach(|| vpcal::run_pipeline_on(&mut open_source, &config, &reporter));
    if let Some(e) = error.lock().unwrap_or_else(|e| e.into_inner()).take() {
        return Err(e);
    }
    if let Some(e) = reporter.take_error() {
        return Err(e);
    }
    let out = out.map_err(err)?;
    run_result(py, &out, &config, options)
}

/// Aggregation settings: `method`, `pp`, `image_size` (w, h), `min_score`, `bootstrap`,
/// `focal`, `focal_range` (short, long).
fn record_settings(d: &Bound<'_, PyDict>) -> PyResult<RecordSettings> {
    let mut s = RecordSettings::default();
    if let Some(v) = parsed(d, "method")? {
        s.method = v;
    }
    if let Some(v) = pair_or_text::<PrincipalPoint>(d, "pp")? {
        s.pp = v;
    }
    s.image_size = opt(d, "image_size", "(width, height) in pixels")?;
    if let Some(v) = opt(d, "min_score", "a number")? {
        s.min_score = v;
    }
    if let Some(v) = opt(d, "bootstrap", "an int")? {
        s.bootstrap = v;
    }
    s.focal_px = opt(d, "focal", "a number of pixels")?;
    s.focal_range_px = opt(d, "focal_range", "(short, long) focal lengths in pixels")?;
    Ok(s)
}

/// Aggregate VPout records (from `path`, or `records` JSON text named `origin`) into a
/// calibration file (JSON text), as `vpcal aggregate` does. Raises NotCalibrated when the
/// records support no camera.
#[pyfunction]
#[pyo3(signature = (origin, settings, records=None))]
fn aggregate(
    py: Python<'_>,
    origin: &str,
    settings: &Bound<'_, PyDict>,
    records: Option<&str>,
) -> PyResult<String> {
    let s = record_settings(settings)?;
    let items = match records {
        None => read_vpout(Path::new(origin)).map_err(|e| err(e.into()))?,
        Some(text) => parse_records(text, origin).map_err(err)?,
    };
    let r = py
        .detach(|| output::aggregate_records(&items, &SceneRecord::default(), origin, &s))
        .map_err(err)?;
    match r.result {
        Ok(_) => Ok(r.file.to_json_string()),
        Err(e) => {
            let e = NotCalibrated::new_err(format!("{e:#}"));
            e.value(py)
                .setattr("calibration_file", r.file.to_json_string())?;
            Err(e)
        }
    }
}

/// VPout records from JSON text, with the file reader's field checks.
fn parse_records(text: &str, origin: &str) -> anyhow::Result<Vec<VpOutItem>> {
    let doc = vpcal_formats::json::parse(text).map_err(|e| anyhow::anyhow!("{origin}: {e}"))?;
    Ok(vpout_from_json(&doc, Path::new(origin))?)
}

/// Read a calibration file (any version vpcal reads; a calibrated one must describe a
/// camera); returns it as JSON text of the current version.
#[pyfunction]
fn read_calibration(path: PathBuf) -> PyResult<String> {
    let file = CalibrationFile::read(&path).map_err(|e| err(e.into()))?;
    if file.status.has_camera() {
        // A camera that `vpcal measure` would refuse is refused here, naming the file.
        RoadCamera::new(file.clone(), &path.display().to_string()).map_err(err)?;
    }
    Ok(file.to_json_string())
}

/// A calibration file from JSON text (`origin` names it in errors).
fn calibration_from_text(text: &str, origin: &str) -> PyResult<CalibrationFile> {
    CalibrationFile::from_json_str(text, Path::new(origin)).map_err(|e| err(e.into()))
}

/// Write calibration file JSON text to `path` (checked, atomically), exactly as the CLI
/// writes it.
#[pyfunction]
fn write_calibration(text: &str, path: PathBuf) -> PyResult<()> {
    let file = calibration_from_text(text, &path.display().to_string())?;
    file.write(&path).map_err(|e| err(e.into()))
}

/// The HTML report of calibration file JSON text `calibration` (as `calibrate --report`
/// writes it), with the run's `tracks` (vpcal-tracks/1 JSON text), overlay picture
/// (`overlay_png`, PNG bytes) and `run_warnings` when given.
#[pyfunction]
#[pyo3(signature = (calibration, tracks=None, overlay_png=None, run_warnings=Vec::new()))]
fn render_report(
    calibration: &str,
    tracks: Option<&str>,
    overlay_png: Option<&[u8]>,
    run_warnings: Vec<String>,
) -> PyResult<String> {
    let file = calibration_from_text(calibration, "calibration")?;
    let doc: Option<serde_json::Value> = tracks
        .map(serde_json::from_str)
        .transpose()
        .map_err(|e| PyValueError::new_err(format!("tracks: not a JSON document: {e}")))?;
    let list = doc
        .as_ref()
        .map(vpcal::output::tracks_from_doc)
        .transpose()
        .map_err(|e| PyValueError::new_err(format!("tracks: {e}")))?;
    let note = doc
        .as_ref()
        .and_then(|d| d.get("note"))
        .and_then(serde_json::Value::as_str);
    let input = vpcal::report::ReportInput {
        overlay_png,
        tracks: list.as_deref(),
        tracks_note: note,
        run_warnings: &run_warnings,
    };
    Ok(vpcal::report::render_with(&file, &input))
}

/// Write report `html` to `path` (atomically, as the CLI writes it).
#[pyfunction]
fn write_report(path: PathBuf, html: &str) -> PyResult<()> {
    vpcal::report::write(&path, html).map_err(err)
}

/// A known length on the road: two pixels `(x1, y1, x2, y2)` and metres.
type KnownLength = ((f64, f64, f64, f64), f64);

/// The calibration file JSON text `text` with the metric scale of known road `distances` and
/// lane `widths` (as `vpcal scale --points/--distance --lane-points/--lane-width`: their
/// geometric mean; lengths in two directions also measure the focal length unless
/// `keep_focal`); returns the file.
#[pyfunction]
#[pyo3(signature = (text, distances, widths=Vec::new(), keep_focal=false))]
fn set_scale(
    text: &str,
    distances: Vec<KnownLength>,
    widths: Vec<KnownLength>,
    keep_focal: bool,
) -> PyResult<String> {
    let mut cam =
        RoadCamera::new(calibration_from_text(text, "calibration")?, "calibration").map_err(err)?;
    let input = |kind: RoadMeasure, ((x1, y1, x2, y2), m): KnownLength| ScaleInput {
        kind,
        known: KnownDistance {
            p1: Point2::new(x1, y1),
            p2: Point2::new(x2, y2),
            distance_m: m,
        },
    };
    let n = distances.len();
    let mut inputs: Vec<ScaleInput> = distances
        .into_iter()
        .map(|d| input(RoadMeasure::Distance, d))
        .collect();
    inputs.extend(widths.into_iter().map(|w| input(RoadMeasure::LaneWidth, w)));
    let flag = |i: usize| {
        if i < n {
            format!("--points #{}", i + 1)
        } else {
            format!("--lane-points #{}", i - n + 1)
        }
    };
    cam.apply_lengths(&inputs, flag, "calibration", keep_focal)
        .map_err(err)?;
    Ok(cam.file.to_json_string())
}

/// The camera of a calibration file, for measurements on the road.
#[pyclass(name = "RoadCamera", module = "vpcal._native", frozen)]
struct PyRoadCamera {
    inner: RoadCamera,
}

#[pymethods]
impl PyRoadCamera {
    #[new]
    fn new(text: &str) -> PyResult<PyRoadCamera> {
        let file = calibration_from_text(text, "calibration")?;
        let inner = RoadCamera::new(file, "calibration").map_err(err)?;
        Ok(PyRoadCamera { inner })
    }

    /// Metres per road unit, or None without a scale.
    #[getter]
    fn scale(&self) -> Option<f64> {
        self.inner.scale
    }

    /// Road-frame points (x, y) of pixels, metres with a scale; None above the horizon.
    fn road_points(&self, pixels: Vec<(f64, f64)>) -> Vec<Option<(f64, f64)>> {
        pixels
            .into_iter()
            .map(|(x, y)| {
                self.inner
                    .road_point(Point2::new(x, y))
                    .map(|q| (q[0], q[1]))
            })
            .collect()
    }

    /// Pixels that see road-frame points (x, y); None behind the camera.
    fn pixels(&self, points: Vec<(f64, f64)>) -> Vec<Option<(f64, f64)>> {
        points
            .into_iter()
            .map(|(x, y)| self.inner.pixel([x, y]).map(|p| (p.x, p.y)))
            .collect()
    }

    /// Road distances between pixel pairs (x1, y1, x2, y2), as `vpcal measure`.
    fn distances(&self, pairs: Vec<(f64, f64, f64, f64)>) -> Vec<Option<f64>> {
        pairs
            .into_iter()
            .map(|(x1, y1, x2, y2)| {
                self.inner
                    .distance(Point2::new(x1, y1), Point2::new(x2, y2))
            })
            .collect()
    }
}

/// A frame from `(height, width, rgb_bytes)`.
fn picture(h: u32, w: u32, data: &[u8]) -> PyResult<RgbImage> {
    RgbImage::from_raw(w, h, data.to_vec()).ok_or_else(|| {
        PyValueError::new_err(format!(
            "a frame of {w}x{h} pixels needs {} bytes, got {}",
            u64::from(w) * u64::from(h) * 3,
            data.len()
        ))
    })
}

/// A detector's box: x0, y0, x1, y1 (frame pixels) and score.
type ScoredBox = (f64, f64, f64, f64, f64);

/// A vehicle detector of the pipeline, on frames in memory.
#[pyclass(name = "Detector", module = "vpcal._native", frozen)]
struct PyDetector {
    inner: Mutex<Box<dyn vpcal_video::Detector>>,
    name: String,
}

#[pymethods]
impl PyDetector {
    /// `settings`: `detector`, `tiles`, `onnx_layout`, `motorcycles`, `road_mask`, and
    /// `fps` (None: the frames are stills); `size` the frames' (width, height).
    #[new]
    fn new(settings: &Bound<'_, PyDict>, size: (u32, u32)) -> PyResult<PyDetector> {
        let s = detector_settings(settings)?;
        let fps: Option<f64> = opt(settings, "fps", "a number")?;
        let info = SourceInfo {
            path: vpcal_video::source::picture_label("frames"),
            kind: SourceKind::ImageFolder,
            width: size.0,
            height: size.1,
            fps,
            frame_count: None,
            codec: None,
        };
        let d = vpcal::detector::open_detector(&s, &info).map_err(err)?;
        let name = d.name();
        Ok(PyDetector {
            inner: Mutex::new(d),
            name,
        })
    }

    #[getter]
    fn name(&self) -> String {
        self.name.clone()
    }

    /// Boxes `(x0, y0, x1, y1, score)` in frame pixels of one frame (`index`: its frame
    /// number, for detectors that follow time).
    fn detect(
        &self,
        py: Python<'_>,
        h: u32,
        w: u32,
        data: &[u8],
        index: u64,
    ) -> PyResult<Vec<ScoredBox>> {
        let frame = Frame {
            index,
            time_s: index as f64,
            image: picture(h, w, data)?,
        };
        let dets = py
            .detach(|| {
                let mut d = self.inner.lock().unwrap_or_else(|e| e.into_inner());
                d.detect(&frame)
            })
            .map_err(|e| err(anyhow::Error::new(e).context(format!("frame {index}"))))?;
        Ok(dets
            .into_iter()
            .map(|d| {
                let b = d.bbox;
                (b.x0, b.y0, b.x1, b.y1, f64::from(d.score))
            })
            .collect())
    }
}

/// The VP network (the bundled model, or weights from a path).
#[pyclass(name = "Network", module = "vpcal._native", frozen)]
struct PyNetwork {
    /// Boxed: the network is 64-byte aligned, more than a Python object guarantees.
    net: Mutex<Box<vpcal_net::VpNet>>,
    model: String,
}

/// One prediction as a dict: VPs in the box frame (`vp1_box`, `vp2_box`), per-scale spreads,
/// and, when the box is known, the crop box and the VPs in frame pixels.
fn prediction_dict<'py>(
    py: Python<'py>,
    p: &vpcal_geom::heatmap::VpPrediction,
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("vp1_box", (p.vp1.x, p.vp1.y))?;
    d.set_item("vp2_box", (p.vp2.x, p.vp2.y))?;
    d.set_item("vp1_spread", p.vp1_spread())?;
    d.set_item("vp2_spread", p.vp2_spread())?;
    d.set_item("vp1_scale", p.vp1_scale)?;
    d.set_item("vp2_scale", p.vp2_scale)?;
    d.set_item("spreads", p.spreads.clone())?;
    Ok(d)
}

#[pymethods]
impl PyNetwork {
    #[new]
    #[pyo3(signature = (model=None, device="cpu"))]
    fn new(model: Option<PathBuf>, device: &str) -> PyResult<PyNetwork> {
        let (net, name) = vpcal::model::load_model(model.as_deref(), device).map_err(err)?;
        Ok(PyNetwork {
            net: Mutex::new(Box::new(net)),
            model: name,
        })
    }

    #[getter]
    fn model(&self) -> String {
        self.model.clone()
    }

    /// The network's input side in pixels.
    #[getter]
    fn input_size(&self) -> usize {
        self.net
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .config()
            .input_size
    }

    /// VPs of vehicle crops `(height, width, rgb_bytes)` (any size; each is resized to the
    /// input), in the box frame (the crop spans [-1, 1]²), as `vpcal predict`.
    fn predict_crops<'py>(
        &self,
        py: Python<'py>,
        crops: Vec<(u32, u32, Vec<u8>)>,
    ) -> PyResult<Vec<Bound<'py, PyDict>>> {
        let images = crops
            .iter()
            .map(|(h, w, data)| picture(*h, *w, data))
            .collect::<PyResult<Vec<_>>>()?;
        let preds = py
            .detach(|| {
                let net = self.net.lock().unwrap_or_else(|e| e.into_inner());
                net.predict(&images)
            })
            .map_err(|e| err(e.into()))?;
        preds.iter().map(|p| prediction_dict(py, &p.vp)).collect()
    }

    /// VPs of the vehicles in `boxes` `(x0, y0, x1, y1)` (any detector's) of one frame, cut
    /// as the pipeline cuts them; boxes that leave no crop are left out (`index` says which
    /// box each result is).
    fn predict_boxes<'py>(
        &self,
        py: Python<'py>,
        h: u32,
        w: u32,
        data: &[u8],
        boxes: Vec<(f64, f64, f64, f64)>,
    ) -> PyResult<Vec<Bound<'py, PyDict>>> {
        let image = picture(h, w, data)?;
        let boxes: Vec<BoxPx> = boxes
            .into_iter()
            .map(|(x0, y0, x1, y1)| BoxPx { x0, y0, x1, y1 })
            .collect();
        let found = py
            .detach(|| {
                let net = self.net.lock().unwrap_or_else(|e| e.into_inner());
                vpcal::pipeline::predict_boxes(&net, &image, &boxes)
            })
            .map_err(err)?;
        found
            .iter()
            .map(|b| {
                let d = prediction_dict(py, &b.prediction)?;
                d.set_item("index", b.source)?;
                let c = &b.crop_box;
                d.set_item("crop_box", (c.x0, c.y0, c.x1, c.y1))?;
                d.set_item("vp1", (b.vp1.x, b.vp1.y))?;
                d.set_item("vp2", (b.vp2.x, b.vp2.y))?;
                Ok(d)
            })
            .collect()
    }
}

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("VpcalError", py.get_type::<VpcalError>())?;
    m.add("NotCalibrated", py.get_type::<NotCalibrated>())?;
    m.add("BUNDLED_MODEL", vpcal::model::BUNDLED_MODEL_NAME)?;
    m.add_function(wrap_pyfunction!(calibrate_path, m)?)?;
    m.add_function(wrap_pyfunction!(calibrate_frames, m)?)?;
    m.add_function(wrap_pyfunction!(aggregate, m)?)?;
    m.add_function(wrap_pyfunction!(read_calibration, m)?)?;
    m.add_function(wrap_pyfunction!(write_calibration, m)?)?;
    m.add_function(wrap_pyfunction!(set_scale, m)?)?;
    m.add_function(wrap_pyfunction!(render_report, m)?)?;
    m.add_function(wrap_pyfunction!(write_report, m)?)?;
    m.add_class::<PyRoadCamera>()?;
    m.add_class::<PyDetector>()?;
    m.add_class::<PyNetwork>()?;
    Ok(())
}
