//! Detections read from a file, for any external detector.
//!
//! Three formats are accepted; the reader picks one from the extension and content:
//!
//! 1. **CSV** (`.csv`), one box per line, frame pixels, 0-based frame index:
//!    ```text
//!    frame,x0,y0,x1,y1,score
//!    0,412.5,300,520,371.25,0.93
//!    ```
//!    The header line is optional; blank lines and lines starting with `#` are ignored.
//!    `(x0, y0)` is the top-left and `(x1, y1)` the bottom-right corner in continuous pixel
//!    coordinates (pixel (i, j) covers [i, i+1) × [j, j+1)); `score` is any finite number
//!    (a detector's confidence, usually in [0, 1]).
//! 2. **JSON** (`.json`), the same rows as objects:
//!    `[{"frame": 0, "x0": 412.5, "y0": 300, "x1": 520, "y1": 371.25, "score": 0.93}, ...]`.
//! 3. **The reference's `detections.json`** (deep_vp `object_detection/detect_bcs.py`):
//!    `[{"frame_cnt": 10.0, "boxes": [[ymin, xmin, ymax, xmax], ...], "scores": [...]}, ...]`
//!    with boxes normalised to [0, 1]. `frame_cnt` is OpenCV's `CAP_PROP_POS_FRAMES` read
//!    *after* grabbing the frame, i.e. the number of frames read so far, so the 0-based frame
//!    index is `frame_cnt − 1`. A box becomes `(W·xmin, H·ymin, W·xmax, H·ymax)` in a W×H
//!    frame; [`crate::crop::integer_box`] then reproduces the reference's integer crop
//!    `x_min = int(W·xmin)`, `x_max = int(W·xmax + 1)`.
//!
//! Frames without an entry have no detections.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use vpcal_geom::BoxPx;

use super::{Detection, Detector};
use crate::error::{Result, VideoError};
use crate::source::Frame;

/// A box as stored in the file.
#[derive(Debug, Clone, Copy, PartialEq)]
enum StoredBox {
    /// Frame pixels.
    Pixels(BoxPx),
    /// The reference's normalised `[ymin, xmin, ymax, xmax]`.
    Normalised([f64; 4]),
}

/// Which of the accepted formats a file is in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DetectionFormat {
    Csv,
    Json,
    Reference,
}

/// Boxes from a detections file, served frame by frame (see the module docs).
#[derive(Debug, Clone)]
pub struct FileDetector {
    path: PathBuf,
    format: DetectionFormat,
    frames: BTreeMap<u64, Vec<(StoredBox, f32)>>,
}

/// One row of our JSON format.
#[derive(Debug, serde::Deserialize, serde::Serialize)]
struct JsonRow {
    frame: u64,
    x0: f64,
    y0: f64,
    x1: f64,
    y1: f64,
    score: f64,
}

fn file_error(path: &Path, location: impl Into<String>, message: impl Into<String>) -> VideoError {
    VideoError::DetectionFile {
        path: path.to_path_buf(),
        location: location.into(),
        message: message.into(),
    }
}

fn check_box(path: &Path, at: &str, b: [f64; 4], score: f64) -> Result<()> {
    if b.iter().any(|v| !v.is_finite()) || !score.is_finite() {
        return Err(file_error(path, at, "non-finite box or score"));
    }
    if b[2] <= b[0] || b[3] <= b[1] {
        return Err(file_error(
            path,
            at,
            format!(
                "empty box ({}, {}, {}, {}): expected x0 < x1 and y0 < y1",
                b[0], b[1], b[2], b[3]
            ),
        ));
    }
    Ok(())
}

impl FileDetector {
    /// Reads a detections file in any of the accepted formats.
    ///
    /// # Errors
    /// [`VideoError::Io`] when it cannot be read, [`VideoError::DetectionFile`] naming the
    /// line or item that is malformed.
    pub fn open(path: &Path) -> Result<FileDetector> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| VideoError::io("cannot read detections file", path, e))?;
        let is_csv = path
            .extension()
            .and_then(|e| e.to_str())
            .is_some_and(|e| e.eq_ignore_ascii_case("csv"));
        if is_csv {
            return Self::parse_csv(path, &text);
        }
        let trimmed = text.trim_start();
        if !trimmed.starts_with('[') {
            return Err(file_error(
                path,
                "start",
                "expected a JSON list (or a .csv file with frame,x0,y0,x1,y1,score)",
            ));
        }
        // The reference's files are recognised by their `frame_cnt` key.
        if text.contains("\"frame_cnt\"") {
            return Self::read_reference(path);
        }
        let rows: Vec<JsonRow> = serde_json::from_str(&text).map_err(|e| {
            file_error(
                path,
                format!("line {} column {}", e.line(), e.column()),
                format!("expected [{{\"frame\", \"x0\", \"y0\", \"x1\", \"y1\", \"score\"}}, ...] ({e})"),
            )
        })?;
        let mut frames: BTreeMap<u64, Vec<(StoredBox, f32)>> = BTreeMap::new();
        for (i, r) in rows.iter().enumerate() {
            let at = format!("item {i}");
            check_box(path, &at, [r.x0, r.y0, r.x1, r.y1], r.score)?;
            // Why: scores are stored as f32 like every detector's.
            let score = r.score as f32;
            frames
                .entry(r.frame)
                .or_default()
                .push((StoredBox::Pixels(BoxPx::new(r.x0, r.y0, r.x1, r.y1)), score));
        }
        Ok(FileDetector {
            path: path.to_path_buf(),
            format: DetectionFormat::Json,
            frames,
        })
    }

    fn parse_csv(path: &Path, text: &str) -> Result<FileDetector> {
        let mut frames: BTreeMap<u64, Vec<(StoredBox, f32)>> = BTreeMap::new();
        let mut seen_data = false;
        for (k, line) in text.lines().enumerate() {
            let at = format!("line {}", k + 1);
            let line = line.trim();
            if line.is_empty() || line.starts_with('#') {
                continue;
            }
            let cols: Vec<&str> = line.split(',').map(str::trim).collect();
            if !seen_data
                && cols
                    .first()
                    .is_some_and(|c| c.eq_ignore_ascii_case("frame"))
            {
                seen_data = true;
                continue; // header
            }
            seen_data = true;
            if cols.len() != 6 {
                return Err(file_error(
                    path,
                    at,
                    format!(
                        "{} columns, expected 6: frame,x0,y0,x1,y1,score",
                        cols.len()
                    ),
                ));
            }
            let frame: u64 = cols[0].parse().map_err(|_| {
                file_error(
                    path,
                    at.clone(),
                    format!("frame {:?} is not a 0-based frame index", cols[0]),
                )
            })?;
            let mut v = [0f64; 5];
            for (j, (slot, name)) in v
                .iter_mut()
                .zip(["x0", "y0", "x1", "y1", "score"])
                .enumerate()
            {
                *slot = cols[j + 1].parse().map_err(|_| {
                    file_error(
                        path,
                        at.clone(),
                        format!("{name} {:?} is not a number", cols[j + 1]),
                    )
                })?;
            }
            check_box(path, &at, [v[0], v[1], v[2], v[3]], v[4])?;
            // Why: scores are stored as f32 like every detector's.
            let score = v[4] as f32;
            frames
                .entry(frame)
                .or_default()
                .push((StoredBox::Pixels(BoxPx::new(v[0], v[1], v[2], v[3])), score));
        }
        Ok(FileDetector {
            path: path.to_path_buf(),
            format: DetectionFormat::Csv,
            frames,
        })
    }

    fn read_reference(path: &Path) -> Result<FileDetector> {
        let items = vpcal_formats::reference::read_detections(path).map_err(|e| {
            // The formats error already names the file; keep its text, without the path twice.
            let text = e.to_string();
            let p = path.display().to_string();
            let message = text
                .strip_prefix(&p)
                .map(|r| r.trim_start_matches(':').trim().to_string())
                .unwrap_or(text);
            file_error(path, "reference detections.json", message)
        })?;
        let mut frames: BTreeMap<u64, Vec<(StoredBox, f32)>> = BTreeMap::new();
        for (i, item) in items.iter().enumerate() {
            let at = format!("item {i}");
            let fc = item.frame_cnt;
            if !(fc.is_finite() && fc >= 1.0 && fc.fract() == 0.0) {
                return Err(file_error(
                    path,
                    at,
                    format!("frame_cnt {fc} is not a frame count (a whole number >= 1)"),
                ));
            }
            // Why: a whole number >= 1 (checked above); saturates for absurd values.
            let index = fc as u64 - 1;
            let list = frames.entry(index).or_default();
            for (b, &s) in item.boxes.iter().zip(&item.scores) {
                let [ymin, xmin, ymax, xmax] = *b;
                check_box(path, &at, [xmin, ymin, xmax, ymax], s)?;
                // Why: scores are stored as f32 like every detector's.
                list.push((StoredBox::Normalised(*b), s as f32));
            }
        }
        Ok(FileDetector {
            path: path.to_path_buf(),
            format: DetectionFormat::Reference,
            frames,
        })
    }

    /// The format the file was read as.
    pub fn format(&self) -> DetectionFormat {
        self.format
    }

    /// The file read.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The 0-based indices of the frames that have an entry, ascending.
    pub fn frames(&self) -> impl Iterator<Item = u64> + '_ {
        self.frames.keys().copied()
    }

    /// Total number of boxes in the file.
    pub fn box_count(&self) -> usize {
        self.frames.values().map(Vec::len).sum()
    }

    /// The detections of frame `index` in a `width` × `height` frame.
    pub fn detections_for(&self, index: u64, width: u32, height: u32) -> Vec<Detection> {
        let (w, h) = (f64::from(width), f64::from(height));
        self.frames
            .get(&index)
            .map(|list| {
                list.iter()
                    .map(|&(b, score)| Detection {
                        bbox: match b {
                            StoredBox::Pixels(b) => b,
                            StoredBox::Normalised([ymin, xmin, ymax, xmax]) => {
                                BoxPx::new(w * xmin, h * ymin, w * xmax, h * ymax)
                            }
                        },
                        score,
                    })
                    .collect()
            })
            .unwrap_or_default()
    }
}

impl Detector for FileDetector {
    fn detect(&mut self, frame: &Frame) -> Result<Vec<Detection>> {
        Ok(self.detections_for(frame.index, frame.image.width(), frame.image.height()))
    }

    fn name(&self) -> String {
        format!("file:{}", self.path.display())
    }
}

/// Writes `(frame index, detection)` rows to `path` as our CSV (`.csv`) or JSON (any other
/// extension), atomically (a temporary file in the same folder, then a rename).
///
/// # Errors
/// [`VideoError::Io`] naming the file.
pub fn write_detections(path: &Path, rows: &[(u64, Detection)]) -> Result<()> {
    let is_csv = path
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("csv"));
    let mut out = Vec::new();
    if is_csv {
        out.extend_from_slice(b"frame,x0,y0,x1,y1,score\n");
        for (f, d) in rows {
            let b = d.bbox;
            out.extend_from_slice(
                format!("{f},{},{},{},{},{}\n", b.x0, b.y0, b.x1, b.y1, d.score).as_bytes(),
            );
        }
    } else {
        let json: Vec<JsonRow> = rows
            .iter()
            .map(|(f, d)| JsonRow {
                frame: *f,
                x0: d.bbox.x0,
                y0: d.bbox.y0,
                x1: d.bbox.x1,
                y1: d.bbox.y1,
                score: f64::from(d.score),
            })
            .collect();
        out = serde_json::to_vec_pretty(&json).map_err(|e| {
            VideoError::io("cannot write detections", path, std::io::Error::other(e))
        })?;
        out.push(b'\n');
    }
    write_atomic(path, &out)
}

/// Writes `bytes` atomically ([`vpcal_formats::fs::replace_bytes`]).
pub(crate) fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    vpcal_formats::fs::replace_bytes(path, bytes)
        .map_err(|e| VideoError::io("cannot write", path, e))
}
