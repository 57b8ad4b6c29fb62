//! Frame sources: video files (through the `ffmpeg` executable), image folders and single
//! images, all behind [`FrameSource`], an iterator of [`Frame`]s.
//!
//! Sources stream: a video is decoded by an `ffmpeg` child process that writes raw RGB24
//! frames to a pipe, and only the frame being handed out is held in memory. Frame selection
//! ([`SourceOptions::start`], [`SourceOptions::every`], [`SourceOptions::max_frames`]) happens
//! inside FFmpeg's filter graph, so skipped frames are never converted or copied.
//!
//! # Frame indices and times
//! [`Frame::index`] is the 0-based index of the frame in the source, counted over every
//! decoded frame (`-fps_mode passthrough`: FFmpeg neither drops nor duplicates frames).
//! [`Frame::time_s`] is `index / fps` with the stream's average frame rate; for
//! variable-frame-rate files it is the nominal time. Image folders have no clock: their
//! frames are `1 / image_fps` seconds apart (1 s when no rate is given).

mod ffmpeg;
mod images;
mod pictures;

pub use ffmpeg::{probe_video, FfmpegSource, VideoProbe};
pub use images::ImageSequenceSource;
pub use pictures::{picture_label, PictureSource};

use std::path::{Path, PathBuf};
use std::str::FromStr;

use crate::error::{Result, VideoError};

/// One decoded frame.
#[derive(Debug, Clone)]
pub struct Frame {
    /// 0-based index of this frame in the source (before `every`/`start` selection).
    pub index: u64,
    /// Presentation time in seconds from the start of the source (see the module docs).
    pub time_s: f64,
    /// The picture, RGB 8 bit, full resolution.
    pub image: image::RgbImage,
}

/// What kind of input a source reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SourceKind {
    /// A video file decoded by FFmpeg.
    Video,
    /// A folder of images, read in natural name order.
    ImageFolder,
    /// One image file.
    SingleImage,
}

/// Static facts about a source, known before the first frame.
#[derive(Debug, Clone, PartialEq)]
pub struct SourceInfo {
    /// The file or folder given by the user.
    pub path: PathBuf,
    pub kind: SourceKind,
    /// Frame width in pixels.
    pub width: u32,
    /// Frame height in pixels.
    pub height: u32,
    /// Frames per second (the stream's average rate; for image folders the configured
    /// `image_fps`), when known.
    pub fps: Option<f64>,
    /// Number of frames in the whole source when known (for video: as the container reports
    /// it, or duration × fps when it does not; treat it as an estimate).
    pub frame_count: Option<u64>,
    /// Codec name for video (`h264`, `hevc`, `mjpeg`, ...).
    pub codec: Option<String>,
}

impl SourceInfo {
    /// How many frames the source will yield with `options`, when the source's length is known
    /// (an estimate for video, see [`SourceInfo::frame_count`]). Useful for progress bars.
    pub fn expected_frames(&self, options: &SourceOptions) -> Option<u64> {
        let total = self.frame_count?;
        let first = options.start.to_frame_index(self.fps.unwrap_or(1.0));
        let available = total.saturating_sub(first);
        let every = options.every.max(1);
        let selected = available.div_ceil(every);
        Some(match options.max_frames {
            Some(max) => selected.min(max),
            None => selected,
        })
    }
}

/// Where reading starts.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum Start {
    /// From the beginning.
    #[default]
    Beginning,
    /// From this 0-based frame index (exact: earlier frames are decoded and dropped).
    Frame(u64),
    /// From this time in seconds. Videos seek (fast, without decoding what is skipped); the
    /// first frame yielded is the first one whose time is at or after this, and its index is
    /// `ceil(seconds × fps)` (exact for constant-frame-rate video).
    Seconds(f64),
}

impl Start {
    /// The index of the first frame at or after this start for a source of rate `fps`.
    pub fn to_frame_index(self, fps: f64) -> u64 {
        match self {
            Start::Beginning => 0,
            Start::Frame(n) => n,
            Start::Seconds(s) => seconds_to_index(s, fps),
        }
    }
}

/// `ceil(s × fps)` with a small tolerance for values that are meant to be integral.
pub(crate) fn seconds_to_index(seconds: f64, fps: f64) -> u64 {
    let v = (seconds * fps - 1e-6).ceil();
    if v.is_finite() && v > 0.0 {
        // Why: `v` is a non-negative whole number; the cast saturates for absurd values.
        v as u64
    } else {
        0
    }
}

impl FromStr for Start {
    type Err = VideoError;

    /// `120` is frame 120; `4.5s` is 4.5 seconds; `0` is the beginning.
    fn from_str(s: &str) -> Result<Start> {
        let t = s.trim();
        let invalid = || VideoError::InvalidOption {
            name: "start",
            value: s.to_string(),
            expected: "a frame index (e.g. 120) or a time in seconds (e.g. 4.5s)",
        };
        if let Some(sec) = t.strip_suffix('s') {
            let v: f64 = sec.trim().parse().map_err(|_| invalid())?;
            if !(v.is_finite() && v >= 0.0) {
                return Err(invalid());
            }
            Ok(if v == 0.0 {
                Start::Beginning
            } else {
                Start::Seconds(v)
            })
        } else {
            let v: u64 = t.parse().map_err(|_| invalid())?;
            Ok(if v == 0 {
                Start::Beginning
            } else {
                Start::Frame(v)
            })
        }
    }
}

/// What to do when FFmpeg reports damaged data but keeps decoding (it exits with status 0).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum DecodeErrors {
    /// Stop with [`VideoError::Decode`] as soon as FFmpeg reports an error (the default:
    /// damaged frames give garbage detections).
    #[default]
    Fail,
    /// Keep going; the messages are available from [`FrameSource::warnings`]. A non-zero exit
    /// status is still an error.
    Warn,
}

/// Frame selection and decoding options, shared by all sources.
#[derive(Debug, Clone, PartialEq)]
pub struct SourceOptions {
    /// Yield every `every`-th frame (counted from the start frame); `1` yields all.
    pub every: u64,
    /// Stop after yielding this many frames.
    pub max_frames: Option<u64>,
    /// Where to start.
    pub start: Start,
    /// Policy for damaged video data.
    pub decode_errors: DecodeErrors,
    /// Frame rate assigned to image folders (they carry no clock); `None` means 1 frame/s for
    /// `time_s` and an unknown rate in [`SourceInfo::fps`].
    pub image_fps: Option<f64>,
    /// The `ffmpeg` program; default: `$VPCAL_FFMPEG` or `ffmpeg` on the `PATH`.
    pub ffmpeg: Option<PathBuf>,
    /// The `ffprobe` program; default: `$VPCAL_FFPROBE` or `ffprobe` on the `PATH`.
    pub ffprobe: Option<PathBuf>,
}

impl Default for SourceOptions {
    fn default() -> Self {
        SourceOptions {
            every: 1,
            max_frames: None,
            start: Start::Beginning,
            decode_errors: DecodeErrors::Fail,
            image_fps: None,
            ffmpeg: None,
            ffprobe: None,
        }
    }
}

impl SourceOptions {
    /// Checks the option values.
    ///
    /// # Errors
    /// [`VideoError::InvalidOption`] for `every == 0`, `max_frames == Some(0)`, a negative or
    /// non-finite start time or image rate.
    pub fn validate(&self) -> Result<()> {
        if self.every == 0 {
            return Err(VideoError::InvalidOption {
                name: "every",
                value: "0".into(),
                expected: "a positive whole number of frames",
            });
        }
        if self.max_frames == Some(0) {
            return Err(VideoError::InvalidOption {
                name: "max_frames",
                value: "0".into(),
                expected: "a positive number of frames",
            });
        }
        if let Start::Seconds(s) = self.start {
            if !(s.is_finite() && s >= 0.0) {
                return Err(VideoError::InvalidOption {
                    name: "start",
                    value: s.to_string(),
                    expected: "a non-negative time in seconds",
                });
            }
        }
        if let Some(fps) = self.image_fps {
            if !(fps.is_finite() && fps > 0.0) {
                return Err(VideoError::InvalidOption {
                    name: "image_fps",
                    value: fps.to_string(),
                    expected: "a positive frame rate",
                });
            }
        }
        Ok(())
    }
}

/// A stream of frames. Iterating yields frames in order; an `Err` ends the stream.
pub trait FrameSource: Iterator<Item = Result<Frame>> + Send {
    /// Facts about the source known before reading.
    fn info(&self) -> &SourceInfo;

    /// Non-fatal problems reported so far (damaged data under [`DecodeErrors::Warn`]).
    fn warnings(&self) -> Vec<String> {
        Vec::new()
    }
}

/// A video read at a frame rate other than the one its container states (`--fps`: a
/// time-lapse, or a CCTV export whose stated rate is wrong): frame times become
/// `index / fps`; everything else passes through.
struct RateOverride {
    inner: Box<dyn FrameSource>,
    info: SourceInfo,
}

impl Iterator for RateOverride {
    type Item = Result<Frame>;

    fn next(&mut self) -> Option<Result<Frame>> {
        let fps = self.info.fps.unwrap_or(1.0);
        self.inner.next().map(|r| {
            r.map(|mut f| {
                f.time_s = f.index as f64 / fps;
                f
            })
        })
    }
}

impl FrameSource for RateOverride {
    fn info(&self) -> &SourceInfo {
        &self.info
    }

    fn warnings(&self) -> Vec<String> {
        self.inner.warnings()
    }
}

/// `source` with its frames timed at `fps` frames per second instead of its own rate (see
/// [`RateOverride`]); the stated rate is returned beside it.
pub fn with_frame_rate(
    source: Box<dyn FrameSource>,
    fps: f64,
) -> (Box<dyn FrameSource>, Option<f64>) {
    let mut info = source.info().clone();
    let stated = info.fps;
    info.fps = Some(fps);
    (
        Box::new(RateOverride {
            inner: source,
            info,
        }),
        stated,
    )
}

/// File extensions read as still images (case-insensitive).
pub const IMAGE_EXTENSIONS: &[&str] = &["png", "jpg", "jpeg"];

/// True when `path` has one of [`IMAGE_EXTENSIONS`].
pub fn is_image_path(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| IMAGE_EXTENSIONS.iter().any(|x| x.eq_ignore_ascii_case(e)))
}

/// Opens the right source for `path`: a folder of images, a single image (by extension), or
/// else a video file through FFmpeg.
///
/// # Errors
/// A missing path, an unreadable or empty input, invalid options, or FFmpeg missing.
pub fn open_source(path: &Path, options: &SourceOptions) -> Result<Box<dyn FrameSource>> {
    options.validate()?;
    let meta = std::fs::metadata(path).map_err(|e| VideoError::io("cannot open input", path, e))?;
    if meta.is_dir() {
        Ok(Box::new(ImageSequenceSource::folder(path, options)?))
    } else if is_image_path(path) {
        Ok(Box::new(ImageSequenceSource::single(path, options)?))
    } else {
        Ok(Box::new(FfmpegSource::open(path, options)?))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn start_parses_frames_and_seconds() {
        assert_eq!("120".parse::<Start>().ok(), Some(Start::Frame(120)));
        assert_eq!("4.5s".parse::<Start>().ok(), Some(Start::Seconds(4.5)));
        assert_eq!("0".parse::<Start>().ok(), Some(Start::Beginning));
        assert!("-3".parse::<Start>().is_err());
        assert!("abc".parse::<Start>().is_err());
        assert!("-1s".parse::<Start>().is_err());
    }

    #[test]
    fn seconds_map_to_the_first_frame_at_or_after() {
        assert_eq!(seconds_to_index(1.0, 25.0), 25);
        assert_eq!(seconds_to_index(1.01, 25.0), 26);
        assert_eq!(seconds_to_index(0.0, 25.0), 0);
    }

    #[test]
    fn expected_frames_counts_selection() {
        let info = SourceInfo {
            path: PathBuf::from("x"),
            kind: SourceKind::Video,
            width: 1,
            height: 1,
            fps: Some(25.0),
            frame_count: Some(50),
            codec: None,
        };
        let mut o = SourceOptions {
            every: 5,
            start: Start::Frame(7),
            ..SourceOptions::default()
        };
        assert_eq!(info.expected_frames(&o), Some(9));
        o.max_frames = Some(4);
        assert_eq!(info.expected_frames(&o), Some(4));
        o.start = Start::Frame(60);
        assert_eq!(info.expected_frames(&o), Some(0));
    }

    #[test]
    fn options_are_validated() {
        let bad = SourceOptions {
            every: 0,
            ..SourceOptions::default()
        };
        assert!(bad.validate().is_err());
        assert!(SourceOptions::default().validate().is_ok());
    }
}
