//! Video files through the `ffmpeg` and `ffprobe` executables.
//!
//! `ffprobe` reads the stream's size, rate and length; `ffmpeg` then decodes the first video
//! stream and writes raw RGB24 frames to its stdout, which we read one frame at a time:
//!
//! ```text
//! ffmpeg -nostdin -hide_banner -loglevel error -noautorotate [-ss T] -i FILE -map 0:v:0 -an -sn -dn
//!        -vf select=...,setpts=N/(FRAME_RATE*TB) -fps_mode passthrough [-frames:v N] -f rawvideo -pix_fmt rgb24 pipe:1
//! ```
//!
//! - `-fps_mode passthrough` keeps FFmpeg from duplicating or dropping frames to fit a frame
//!   rate, so the k-th frame on the pipe is the k-th decoded frame.
//! - `select` implements `start` (frame) and `every` inside FFmpeg, so skipped frames are never
//!   converted to RGB or copied through the pipe; `setpts=N/(FRAME_RATE*TB)` gives the output
//!   frames evenly spaced timestamps, one nominal frame interval apart (otherwise the raw
//!   muxer logs spurious "non monotonically increasing dts" errors for variable-frame-rate
//!   files and after selection; such lines, should they still appear, are not counted as
//!   damage).
//! - `-noautorotate`: frames come in the stored orientation, the size `ffprobe` reports.
//! - stderr is drained by a thread into a bounded log; any line there is an error (we ask for
//!   `-loglevel error`) and is handled by [`DecodeErrors`].

use std::collections::VecDeque;
use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdout, Command, Stdio};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;

use super::{
    seconds_to_index, DecodeErrors, Frame, FrameSource, SourceInfo, SourceKind, SourceOptions,
    Start,
};
use crate::error::{Result, VideoError};

/// Environment variable naming the `ffmpeg` program.
pub const FFMPEG_ENV: &str = "VPCAL_FFMPEG";
/// Environment variable naming the `ffprobe` program.
pub const FFPROBE_ENV: &str = "VPCAL_FFPROBE";

/// How many stderr lines of FFmpeg we keep (the last ones).
const STDERR_KEEP_LINES: usize = 12;

fn program(explicit: Option<&Path>, env_var: &str, default: &str) -> PathBuf {
    explicit
        .map(Path::to_path_buf)
        .or_else(|| std::env::var_os(env_var).map(PathBuf::from))
        .unwrap_or_else(|| PathBuf::from(default))
}

fn spawn_error(program: &Path, env_var: &'static str, e: &std::io::Error) -> VideoError {
    let reason = if e.kind() == std::io::ErrorKind::NotFound {
        "program not found".to_string()
    } else {
        e.to_string()
    };
    VideoError::FfmpegMissing {
        program: program.to_path_buf(),
        env_var,
        reason,
    }
}

/// What `ffprobe` says about the first video stream of a file.
#[derive(Debug, Clone, PartialEq)]
pub struct VideoProbe {
    pub width: u32,
    pub height: u32,
    /// Average frame rate (falls back to the stream's base rate), when known.
    pub fps: Option<f64>,
    /// Frame count as the container reports it, else duration × fps rounded.
    pub frame_count: Option<u64>,
    /// Duration in seconds, when known.
    pub duration_s: Option<f64>,
    pub codec: String,
}

fn parse_rate(s: Option<&str>) -> Option<f64> {
    let s = s?;
    let (n, d) = s.split_once('/').unwrap_or((s, "1"));
    let n: f64 = n.trim().parse().ok()?;
    let d: f64 = d.trim().parse().ok()?;
    let r = n / d;
    (r.is_finite() && r > 0.0).then_some(r)
}

fn json_str<'a>(v: &'a serde_json::Value, key: &str) -> Option<&'a str> {
    v.get(key).and_then(serde_json::Value::as_str)
}

/// Runs `ffprobe` on `path`.
///
/// # Errors
/// [`VideoError::Io`] for a missing file, [`VideoError::Empty`] for a 0-byte file or a stream
/// without frames, [`VideoError::NotVideo`] when FFmpeg cannot read it or it has no video
/// stream, [`VideoError::FfmpegMissing`] when `ffprobe` cannot be run.
pub fn probe_video(path: &Path, ffprobe: Option<&Path>) -> Result<VideoProbe> {
    let meta = std::fs::metadata(path).map_err(|e| VideoError::io("cannot open video", path, e))?;
    if meta.len() == 0 {
        return Err(VideoError::Empty {
            path: path.to_path_buf(),
            reason: "the file is empty (0 bytes)".into(),
        });
    }
    let prog = program(ffprobe, FFPROBE_ENV, "ffprobe");
    let out = Command::new(&prog)
        .args(["-v", "error", "-select_streams", "v:0", "-show_entries"])
        .arg("stream=width,height,avg_frame_rate,r_frame_rate,nb_frames,duration,codec_name:format=duration")
        .args(["-of", "json"])
        .arg(path)
        .stdin(Stdio::null())
        .output()
        .map_err(|e| spawn_error(&prog, FFPROBE_ENV, &e))?;
    let stderr = String::from_utf8_lossy(&out.stderr);
    let first_err = stderr
        .lines()
        .map(|l| l.trim())
        .find(|l| !l.is_empty())
        .map(|l| strip_path_prefix(l, path))
        .unwrap_or_default();
    if !out.status.success() {
        return Err(VideoError::NotVideo {
            path: path.to_path_buf(),
            message: if first_err.is_empty() {
                format!("ffprobe failed with {}", out.status)
            } else {
                first_err
            },
        });
    }
    let json: serde_json::Value =
        serde_json::from_slice(&out.stdout).map_err(|e| VideoError::NotVideo {
            path: path.to_path_buf(),
            message: format!("unreadable ffprobe output: {e}"),
        })?;
    let stream = json
        .get("streams")
        .and_then(|s| s.as_array())
        .and_then(|s| s.first())
        .ok_or_else(|| VideoError::NotVideo {
            path: path.to_path_buf(),
            message: "no video stream".into(),
        })?;
    let dim = |k: &str| {
        stream
            .get(k)
            .and_then(serde_json::Value::as_u64)
            .and_then(|v| u32::try_from(v).ok())
            .filter(|&v| v > 0)
    };
    let (Some(width), Some(height)) = (dim("width"), dim("height")) else {
        return Err(VideoError::NotVideo {
            path: path.to_path_buf(),
            message: "the video stream has no frame size".into(),
        });
    };
    let fps = parse_rate(json_str(stream, "avg_frame_rate"))
        .or_else(|| parse_rate(json_str(stream, "r_frame_rate")));
    let duration_s = json_str(stream, "duration")
        .or_else(|| json.get("format").and_then(|f| json_str(f, "duration")))
        .and_then(|d| d.parse::<f64>().ok())
        .filter(|d| d.is_finite() && *d >= 0.0);
    let frame_count = json_str(stream, "nb_frames")
        .and_then(|n| n.parse::<u64>().ok())
        .or_else(|| match (duration_s, fps) {
            // Why: a rounded non-negative product; saturates for absurd values.
            (Some(d), Some(f)) => Some((d * f).round() as u64),
            _ => None,
        });
    if frame_count == Some(0) {
        return Err(VideoError::Empty {
            path: path.to_path_buf(),
            reason: "the video stream has zero length".into(),
        });
    }
    Ok(VideoProbe {
        width,
        height,
        fps,
        frame_count,
        duration_s,
        codec: json_str(stream, "codec_name")
            .unwrap_or("unknown")
            .to_string(),
    })
}

/// FFmpeg messages often start with the input path; drop it (the error names the path last).
fn strip_path_prefix(line: &str, path: &Path) -> String {
    let line = without_context_pointers(line);
    let p = path.to_string_lossy();
    line.strip_prefix(p.as_ref())
        .map(|r| r.trim_start_matches(':').trim())
        .unwrap_or(&line)
        .to_string()
}

/// An FFmpeg log line without its context prefixes `[demuxer,names @ 0x5641...] `, which name
/// a memory address: nothing a user can act on.
fn without_context_pointers(line: &str) -> String {
    let mut rest = line.trim();
    while let Some(inner) = rest.strip_prefix('[') {
        match inner.find(']') {
            Some(end) if inner[..end].contains(" @ 0x") => rest = inner[end + 1..].trim_start(),
            _ => break,
        }
    }
    rest.to_string()
}

/// The last lines FFmpeg wrote to stderr and how many there were.
#[derive(Debug, Default)]
struct StderrLog {
    lines: VecDeque<String>,
}

impl StderrLog {
    fn summary(&self, path: &Path) -> String {
        let mut seen: Vec<String> = Vec::new();
        for l in &self.lines {
            let l = strip_path_prefix(l, path);
            if !seen.contains(&l) {
                seen.push(l);
            }
        }
        seen.join(" | ")
    }
}

/// A video file decoded by an `ffmpeg` child process (see the module docs).
#[derive(Debug)]
pub struct FfmpegSource {
    info: SourceInfo,
    child: Option<Child>,
    stdout: Option<ChildStdout>,
    stderr_thread: Option<JoinHandle<()>>,
    stderr_log: Arc<Mutex<StderrLog>>,
    stderr_lines: Arc<AtomicUsize>,
    policy: DecodeErrors,
    frame_bytes: usize,
    next_index: u64,
    step: u64,
    remaining: Option<u64>,
    yielded: u64,
    start_index: u64,
    done: bool,
}

impl FfmpegSource {
    /// Probes `path` and starts decoding it.
    ///
    /// # Errors
    /// See [`probe_video`]; also [`VideoError::InvalidOption`] and a failure to start `ffmpeg`.
    pub fn open(path: &Path, options: &SourceOptions) -> Result<FfmpegSource> {
        options.validate()?;
        let probe = probe_video(path, options.ffprobe.as_deref())?;
        let fps = probe.fps;
        let mut cmd = Command::new(program(options.ffmpeg.as_deref(), FFMPEG_ENV, "ffmpeg"));
        cmd.args([
            "-nostdin",
            "-hide_banner",
            "-loglevel",
            "error",
            "-noautorotate",
        ]);
        let (start_index, select_from) = match options.start {
            Start::Beginning => (0, 0),
            Start::Frame(n) => (n, n),
            Start::Seconds(s) => {
                cmd.arg("-ss").arg(format!("{s:.6}"));
                (seconds_to_index(s, fps.unwrap_or(1.0)), 0)
            }
        };
        cmd.arg("-i").arg(path);
        cmd.args(["-map", "0:v:0", "-an", "-sn", "-dn"]);
        let every = options.every.max(1);
        let mut filters = Vec::new();
        match (select_from, every) {
            (0, 1) => {}
            (0, k) => filters.push(format!("select=not(mod(n\\,{k}))")),
            (s, 1) => filters.push(format!("select=gte(n\\,{s})")),
            (s, k) => filters.push(format!("select=gte(n\\,{s})*not(mod(n-{s}\\,{k}))")),
        }
        filters.push("setpts=N/(FRAME_RATE*TB)".to_string());
        cmd.arg("-vf").arg(filters.join(","));
        cmd.args(["-fps_mode", "passthrough"]);
        if let Some(n) = options.max_frames {
            cmd.arg("-frames:v").arg(n.to_string());
        }
        cmd.args(["-f", "rawvideo", "-pix_fmt", "rgb24", "pipe:1"]);
        cmd.stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped());
        let prog = program(options.ffmpeg.as_deref(), FFMPEG_ENV, "ffmpeg");
        let mut child = cmd
            .spawn()
            .map_err(|e| spawn_error(&prog, FFMPEG_ENV, &e))?;
        let stdout = child.stdout.take();
        let stderr = child.stderr.take();
        let stderr_log = Arc::new(Mutex::new(StderrLog::default()));
        let stderr_lines = Arc::new(AtomicUsize::new(0));
        let stderr_thread = stderr.map(|err| {
            let log = Arc::clone(&stderr_log);
            let count = Arc::clone(&stderr_lines);
            std::thread::spawn(move || {
                let reader = BufReader::new(err);
                for line in reader.split(b'\n') {
                    let Ok(line) = line else { break };
                    let line = String::from_utf8_lossy(&line).trim().to_string();
                    // Timestamp complaints of the raw muxer say nothing about the pictures.
                    if line.is_empty() || line.contains("non monotonically increasing dts") {
                        continue;
                    }
                    if let Ok(mut log) = log.lock() {
                        if log.lines.len() == STDERR_KEEP_LINES {
                            log.lines.pop_front();
                        }
                        log.lines.push_back(line);
                    }
                    count.fetch_add(1, Ordering::SeqCst);
                }
            })
        });
        let frame_bytes = probe.width as usize * probe.height as usize * 3;
        Ok(FfmpegSource {
            info: SourceInfo {
                path: path.to_path_buf(),
                kind: SourceKind::Video,
                width: probe.width,
                height: probe.height,
                fps,
                frame_count: probe.frame_count,
                codec: Some(probe.codec),
            },
            child: Some(child),
            stdout,
            stderr_thread,
            stderr_log,
            stderr_lines,
            policy: options.decode_errors,
            frame_bytes,
            next_index: start_index,
            step: every,
            remaining: options.max_frames,
            yielded: 0,
            start_index,
            done: false,
        })
    }

    /// Stops FFmpeg (if still running), reaps it and collects its stderr.
    /// Returns the exit status text when the process ended on its own.
    fn finish(&mut self, kill: bool) -> Option<std::process::ExitStatus> {
        self.stdout = None;
        let mut status = None;
        if let Some(mut child) = self.child.take() {
            if kill {
                // Why ignored: the process may already have exited; wait() below reaps it.
                let _ = child.kill();
            }
            status = child.wait().ok();
        }
        if let Some(t) = self.stderr_thread.take() {
            // Why ignored: the thread only collects text; a panic there loses messages only.
            let _ = t.join();
        }
        status
    }

    fn stderr_summary(&self) -> String {
        self.stderr_log
            .lock()
            .map(|l| l.summary(&self.info.path))
            .unwrap_or_default()
    }

    fn decode_error(&self, status: String, message: String) -> VideoError {
        VideoError::Decode {
            path: self.info.path.clone(),
            frames_read: self.yielded,
            status,
            message,
        }
    }

    /// Called at the end of the pipe: decide between a clean end and an error.
    fn at_end(&mut self, partial_bytes: usize) -> Option<Result<Frame>> {
        self.done = true;
        // We stop reading when max_frames is reached; FFmpeg stops by itself thanks to
        // -frames:v, so waiting is fine.
        let status = self.finish(false);
        let messages = self.stderr_summary();
        let ok_exit = status.is_some_and(|s| s.success());
        if !ok_exit {
            let status = status.map_or_else(|| "no exit status".to_string(), |s| s.to_string());
            let message = if messages.is_empty() {
                "ffmpeg failed without a message".into()
            } else {
                messages
            };
            return Some(Err(self.decode_error(status, message)));
        }
        if partial_bytes > 0 {
            return Some(Err(self.decode_error(
                "exit status 0".into(),
                format!(
                    "the last frame was cut short ({partial_bytes} of {} bytes){}",
                    self.frame_bytes,
                    if messages.is_empty() {
                        String::new()
                    } else {
                        format!(": {messages}")
                    }
                ),
            )));
        }
        if !messages.is_empty() && self.policy == DecodeErrors::Fail {
            return Some(Err(
                self.decode_error("exit status 0, damaged data".into(), messages)
            ));
        }
        if self.yielded == 0 {
            let reason = if self.start_index > 0 {
                format!(
                    "the start (frame {}) is past the end of the video",
                    self.start_index
                )
            } else if messages.is_empty() {
                "the video stream decoded to zero frames".to_string()
            } else {
                format!("the video stream decoded to zero frames ({messages})")
            };
            return Some(Err(VideoError::Empty {
                path: self.info.path.clone(),
                reason,
            }));
        }
        None
    }
}

impl Iterator for FfmpegSource {
    type Item = Result<Frame>;

    fn next(&mut self) -> Option<Result<Frame>> {
        if self.done {
            return None;
        }
        if self.remaining == Some(0) {
            self.done = true;
            self.finish(true);
            return None;
        }
        let stdout = self.stdout.as_mut()?;
        let mut buf = vec![0u8; self.frame_bytes];
        let mut filled = 0;
        while filled < buf.len() {
            match stdout.read(&mut buf[filled..]) {
                Ok(0) => break,
                Ok(n) => filled += n,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
                Err(e) => {
                    self.done = true;
                    self.finish(true);
                    return Some(Err(VideoError::io(
                        "cannot read frames from ffmpeg",
                        self.info.path.clone(),
                        e,
                    )));
                }
            }
        }
        if filled < buf.len() {
            return self.at_end(filled);
        }
        if self.policy == DecodeErrors::Fail && self.stderr_lines.load(Ordering::SeqCst) > 0 {
            self.done = true;
            self.finish(true);
            let messages = self.stderr_summary();
            return Some(Err(self.decode_error("damaged data".into(), messages)));
        }
        let Some(image) = image::RgbImage::from_raw(self.info.width, self.info.height, buf) else {
            self.done = true;
            self.finish(true);
            return Some(Err(self.decode_error(
                "internal".into(),
                "frame buffer size mismatch".into(),
            )));
        };
        let index = self.next_index;
        self.next_index += self.step;
        self.yielded += 1;
        if let Some(r) = self.remaining.as_mut() {
            *r -= 1;
        }
        let time_s = index as f64 / self.info.fps.unwrap_or(1.0);
        Some(Ok(Frame {
            index,
            time_s,
            image,
        }))
    }
}

impl FrameSource for FfmpegSource {
    fn info(&self) -> &SourceInfo {
        &self.info
    }

    /// FFmpeg's messages about the input, each once, without the memory addresses and the
    /// path they start with (the caller names the input).
    fn warnings(&self) -> Vec<String> {
        let Ok(log) = self.stderr_log.lock() else {
            return Vec::new();
        };
        let mut seen: Vec<String> = Vec::new();
        for line in &log.lines {
            let line = strip_path_prefix(line, &self.info.path);
            if !line.is_empty() && !seen.contains(&line) {
                seen.push(line);
            }
        }
        seen
    }
}

impl Drop for FfmpegSource {
    fn drop(&mut self) {
        self.finish(true);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ffmpeg_lines_lose_their_memory_addresses_and_the_path() {
        let path = Path::new("/tmp/clip.mp4");
        assert_eq!(
            strip_path_prefix(
                "[mov,mp4,m4a,3gp,3g2,mj2 @ 0x5641a2b3c4d0] /tmp/clip.mp4: moov atom not found",
                path
            ),
            "moov atom not found"
        );
        assert_eq!(
            strip_path_prefix("[h264 @ 0x55d0] error while decoding MB 3 4", path),
            "error while decoding MB 3 4"
        );
        assert_eq!(strip_path_prefix("[keep me] text", path), "[keep me] text");
    }

    #[test]
    fn rates_parse() {
        assert_eq!(parse_rate(Some("25/1")), Some(25.0));
        assert_eq!(parse_rate(Some("25/2")), Some(12.5));
        assert_eq!(parse_rate(Some("0/0")), None);
        assert_eq!(parse_rate(Some("30")), Some(30.0));
        assert_eq!(parse_rate(None), None);
    }
}
