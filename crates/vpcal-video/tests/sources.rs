//! Frame sources on tiny videos made here by FFmpeg's `testsrc`, on image folders, on broken
//! inputs, and on the real clips in `$VPCAL_DATA/traffic_video` (skipped when absent).
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::{Path, PathBuf};
use std::process::Command;

use vpcal_video::source::{DecodeErrors, FfmpegSource, ImageSequenceSource};
use vpcal_video::{open_source, Frame, SourceKind, SourceOptions, Start, VideoError};

fn ffmpeg_available() -> bool {
    let ok = Command::new("ffmpeg")
        .arg("-version")
        .output()
        .is_ok_and(|o| o.status.success())
        && Command::new("ffprobe")
            .arg("-version")
            .output()
            .is_ok_and(|o| o.status.success());
    if !ok {
        eprintln!("SKIP: ffmpeg/ffprobe not installed");
    }
    ok
}

fn has_encoder(name: &str) -> bool {
    Command::new("ffmpeg")
        .args(["-hide_banner", "-encoders"])
        .output()
        .is_ok_and(|o| String::from_utf8_lossy(&o.stdout).contains(name))
}

/// Writes `frames` frames of a 160x120, 25 fps test pattern with the given codec arguments.
fn make_video(dir: &Path, name: &str, frames: u32, codec: &[&str]) -> PathBuf {
    let path = dir.join(name);
    let status = Command::new("ffmpeg")
        .args([
            "-v",
            "error",
            "-y",
            "-f",
            "lavfi",
            "-i",
            "testsrc=size=160x120:rate=25",
        ])
        .arg("-frames:v")
        .arg(frames.to_string())
        .args(codec)
        .arg(&path)
        .status()
        .unwrap();
    assert!(status.success(), "ffmpeg could not write {name}");
    path
}

const H264: &[&str] = &["-c:v", "libx264", "-pix_fmt", "yuv420p", "-g", "12"];

fn read_all(src: impl Iterator<Item = vpcal_video::Result<Frame>>) -> Vec<Frame> {
    src.collect::<Result<Vec<_>, _>>().unwrap()
}

fn data_dir() -> Option<PathBuf> {
    let dir = std::env::var_os("VPCAL_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../../shared/data"))
        });
    let clips = dir.join("traffic_video");
    if clips.is_dir() {
        Some(clips)
    } else {
        eprintln!("SKIP: no real clips at {}", clips.display());
        None
    }
}

#[test]
fn h264_mp4_yields_every_frame_with_index_and_time() {
    if !ffmpeg_available() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    // More than 256 frames: the mp4 time base is 1/12800 s, which once exposed a timestamp
    // rounding problem in the raw output.
    let path = make_video(dir.path(), "a.mp4", 300, H264);
    let src = open_source(&path, &SourceOptions::default()).unwrap();
    let info = src.info().clone();
    assert_eq!(info.kind, SourceKind::Video);
    assert_eq!((info.width, info.height), (160, 120));
    assert_eq!(info.fps, Some(25.0));
    assert_eq!(info.frame_count, Some(300));
    assert_eq!(info.codec.as_deref(), Some("h264"));
    let frames = read_all(src);
    assert_eq!(frames.len(), 300);
    for (k, f) in frames.iter().enumerate() {
        assert_eq!(f.index, k as u64);
        assert!((f.time_s - k as f64 / 25.0).abs() < 1e-9);
        assert_eq!(f.image.dimensions(), (160, 120));
    }
    // Consecutive test-pattern frames differ (the pattern moves), so no frame was duplicated.
    assert!(frames.windows(2).all(|w| w[0].image != w[1].image));
}

#[test]
fn every_start_and_max_frames_select_the_same_pixels_as_a_full_decode() {
    if !ffmpeg_available() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let path = make_video(dir.path(), "a.mp4", 50, H264);
    let all = read_all(open_source(&path, &SourceOptions::default()).unwrap());

    let opts = SourceOptions {
        every: 5,
        start: Start::Frame(7),
        ..SourceOptions::default()
    };
    let src = open_source(&path, &opts).unwrap();
    assert_eq!(src.info().expected_frames(&opts), Some(9));
    let sel = read_all(src);
    let idx: Vec<u64> = sel.iter().map(|f| f.index).collect();
    assert_eq!(idx, vec![7, 12, 17, 22, 27, 32, 37, 42, 47]);
    for f in &sel {
        assert!(
            f.image == all[f.index as usize].image,
            "frame {} differs",
            f.index
        );
    }

    let opts = SourceOptions {
        every: 4,
        max_frames: Some(3),
        ..SourceOptions::default()
    };
    let sel = read_all(open_source(&path, &opts).unwrap());
    assert_eq!(
        sel.iter().map(|f| f.index).collect::<Vec<_>>(),
        vec![0, 4, 8]
    );
    assert!(sel[2].image == all[8].image);

    // Seeking by time: the first frame is the one at 1.0 s = frame 25.
    let opts = SourceOptions {
        start: Start::Seconds(1.0),
        every: 10,
        ..SourceOptions::default()
    };
    let sel = read_all(open_source(&path, &opts).unwrap());
    assert_eq!(
        sel.iter().map(|f| f.index).collect::<Vec<_>>(),
        vec![25, 35, 45]
    );
    assert!((sel[0].time_s - 1.0).abs() < 1e-9);
    for f in &sel {
        assert!(
            f.image == all[f.index as usize].image,
            "frame {} differs after seek",
            f.index
        );
    }
}

#[test]
fn mjpeg_avi_and_h265_decode() {
    if !ffmpeg_available() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let mut cases = vec![("m.avi", vec!["-c:v", "mjpeg"], "mjpeg")];
    if has_encoder("libx265") {
        cases.push((
            "h.mp4",
            vec!["-c:v", "libx265", "-x265-params", "log-level=error"],
            "hevc",
        ));
    } else {
        eprintln!("SKIP part: no libx265 encoder");
    }
    for (name, codec, codec_name) in cases {
        let path = make_video(dir.path(), name, 30, &codec);
        let src = open_source(
            &path,
            &SourceOptions {
                every: 3,
                ..SourceOptions::default()
            },
        )
        .unwrap();
        assert_eq!(src.info().codec.as_deref(), Some(codec_name));
        let frames = read_all(src);
        assert_eq!(frames.len(), 10, "{name}");
        assert_eq!(frames[9].index, 27);
        assert!(frames.iter().all(|f| f.image.dimensions() == (160, 120)));
    }
}

#[test]
fn stopping_early_ends_ffmpeg_cleanly() {
    if !ffmpeg_available() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let path = make_video(dir.path(), "long.mp4", 500, H264);
    let mut src = FfmpegSource::open(&path, &SourceOptions::default()).unwrap();
    assert!(src.next().unwrap().is_ok());
    assert!(src.next().unwrap().is_ok());
    drop(src); // kills and reaps the child; the test would hang otherwise
}

#[test]
fn missing_empty_and_non_video_files_are_clear_errors() {
    if !ffmpeg_available() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let opts = SourceOptions::default();

    let missing = dir.path().join("nope.mp4");
    let err = open_source(&missing, &opts).err().unwrap();
    assert!(matches!(err, VideoError::Io { .. }), "{err}");
    assert!(err.to_string().contains("nope.mp4"));

    let empty = dir.path().join("empty.mp4");
    std::fs::write(&empty, b"").unwrap();
    let err = open_source(&empty, &opts).err().unwrap();
    assert!(matches!(err, VideoError::Empty { .. }), "{err}");

    let text = dir.path().join("notes.mp4");
    std::fs::write(&text, b"hello, not a video\n").unwrap();
    let err = open_source(&text, &opts).err().unwrap();
    assert!(matches!(err, VideoError::NotVideo { .. }), "{err}");
    assert!(err.to_string().ends_with("notes.mp4"), "{err}");

    // A container without any video frame.
    let zero = make_video(dir.path(), "zero.avi", 0, &["-c:v", "mjpeg"]);
    let err = match open_source(&zero, &opts) {
        Err(e) => e,
        Ok(mut src) => src.next().unwrap().err().unwrap(),
    };
    assert!(matches!(err, VideoError::Empty { .. }), "{err}");
    let zero = make_video(dir.path(), "zero.mp4", 0, H264);
    let err = open_source(&zero, &opts).err().unwrap();
    assert!(
        matches!(err, VideoError::NotVideo { .. } | VideoError::Empty { .. }),
        "{err}"
    );

    // Start past the end.
    let short = make_video(dir.path(), "short.mp4", 10, H264);
    let mut src = open_source(
        &short,
        &SourceOptions {
            start: Start::Frame(20),
            ..opts.clone()
        },
    )
    .unwrap();
    let err = src.next().unwrap().err().unwrap();
    assert!(err.to_string().contains("past the end"), "{err}");
    assert!(src.next().is_none());
}

#[test]
fn corrupt_stream_fails_mid_way_unless_told_to_warn() {
    if !ffmpeg_available() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let good = make_video(
        dir.path(),
        "good.mp4",
        200,
        &[
            "-c:v",
            "libx264",
            "-pix_fmt",
            "yuv420p",
            "-movflags",
            "+faststart",
        ],
    );
    let mut bytes = std::fs::read(&good).unwrap();
    let n = bytes.len();
    // Overwrite every 100th byte of the second half with noise (deterministic).
    let mut state = 12345u32;
    for i in (n / 2..n - 2000).step_by(100) {
        state = state.wrapping_mul(1_103_515_245).wrapping_add(12345);
        bytes[i] = (state >> 16) as u8;
    }
    let bad = dir.path().join("bad.mp4");
    std::fs::write(&bad, &bytes).unwrap();

    let mut ok_frames = 0;
    let mut error = None;
    for f in open_source(&bad, &SourceOptions::default()).unwrap() {
        match f {
            Ok(_) => ok_frames += 1,
            Err(e) => {
                error = Some(e);
                break;
            }
        }
    }
    let error = error.expect("damaged stream must be reported");
    assert!(matches!(error, VideoError::Decode { .. }), "{error}");
    assert!(
        ok_frames > 10,
        "the clean first half decodes ({ok_frames} frames)"
    );
    assert!(error.to_string().contains("bad.mp4"));

    let opts = SourceOptions {
        decode_errors: DecodeErrors::Warn,
        ..SourceOptions::default()
    };
    let mut src = open_source(&bad, &opts).unwrap();
    let mut count = 0;
    for f in src.by_ref() {
        f.unwrap();
        count += 1;
    }
    assert!(count > ok_frames);
    let warnings = src.warnings();
    assert!(!warnings.is_empty());
    // FFmpeg's context prefixes (`[h264 @ 0x55d0...]`) and the path do not reach the user.
    assert!(
        warnings
            .iter()
            .all(|w| !w.contains(" @ 0x") && !w.contains("bad.mp4")),
        "{warnings:?}"
    );

    // Truncated file: the tail is missing.
    let cut = dir.path().join("cut.mp4");
    std::fs::write(&cut, &std::fs::read(&good).unwrap()[..n * 2 / 3]).unwrap();
    let res: Result<Vec<_>, _> = open_source(&cut, &SourceOptions::default())
        .unwrap()
        .collect();
    assert!(matches!(res, Err(VideoError::Decode { .. })), "{res:?}");
}

#[test]
fn missing_ffmpeg_says_how_to_install_it() {
    let dir = tempfile::tempdir().unwrap();
    let f = dir.path().join("x.mp4");
    std::fs::write(&f, b"0123").unwrap();
    let opts = SourceOptions {
        ffprobe: Some(PathBuf::from("/nonexistent/bin/ffprobe")),
        ..SourceOptions::default()
    };
    let err = open_source(&f, &opts).err().unwrap();
    assert!(matches!(err, VideoError::FfmpegMissing { .. }), "{err}");
    assert!(err.to_string().contains("apt-get install ffmpeg"), "{err}");
}

#[test]
fn image_folders_are_read_in_natural_order() {
    let dir = tempfile::tempdir().unwrap();
    for (name, v) in [
        ("f10.png", 10u8),
        ("f2.png", 2),
        ("f1.jpg", 1),
        ("notes.txt", 0),
    ] {
        let p = dir.path().join(name);
        if name.ends_with(".txt") {
            std::fs::write(&p, b"x").unwrap();
        } else {
            image::RgbImage::from_pixel(8, 6, image::Rgb([v * 20, 0, 0]))
                .save(&p)
                .unwrap();
        }
    }
    let opts = SourceOptions {
        image_fps: Some(2.0),
        ..SourceOptions::default()
    };
    let src = open_source(dir.path(), &opts).unwrap();
    assert_eq!(src.info().kind, SourceKind::ImageFolder);
    assert_eq!(src.info().frame_count, Some(3));
    let frames = read_all(src);
    let reds: Vec<u8> = frames.iter().map(|f| f.image.get_pixel(0, 0)[0]).collect();
    assert!(reds[0].abs_diff(20) <= 3, "jpeg f1 first: {reds:?}");
    assert_eq!(&reds[1..], &[40, 200]);
    assert_eq!(frames[2].index, 2);
    assert!((frames[2].time_s - 1.0).abs() < 1e-12);

    let sel = read_all(
        ImageSequenceSource::folder(
            dir.path(),
            &SourceOptions {
                start: Start::Frame(1),
                every: 5,
                ..SourceOptions::default()
            },
        )
        .unwrap(),
    );
    assert_eq!(sel.len(), 1);
    assert_eq!(sel[0].index, 1);

    // A differently sized image ends the stream with an error naming it.
    image::RgbImage::new(9, 6)
        .save(dir.path().join("f11.png"))
        .unwrap();
    let res: Result<Vec<_>, _> = open_source(dir.path(), &SourceOptions::default())
        .unwrap()
        .collect();
    let err = res.err().unwrap();
    assert!(
        err.to_string().contains("f11.png") && err.to_string().contains("9x6"),
        "{err}"
    );

    // Single image.
    let single =
        read_all(open_source(&dir.path().join("f2.png"), &SourceOptions::default()).unwrap());
    assert_eq!(single.len(), 1);

    // Empty folder.
    let empty = tempfile::tempdir().unwrap();
    assert!(matches!(
        open_source(empty.path(), &SourceOptions::default()),
        Err(VideoError::Empty { .. })
    ));
}

#[test]
fn real_clips_decode_to_their_reported_length() {
    if !ffmpeg_available() {
        return;
    }
    let Some(clips) = data_dir() else { return };
    let mut n = 0;
    for entry in std::fs::read_dir(&clips).unwrap() {
        let path = entry.unwrap().path();
        let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("");
        if !matches!(ext, "mp4" | "avi") {
            continue;
        }
        let opts = SourceOptions {
            every: 10,
            ..SourceOptions::default()
        };
        let src = open_source(&path, &opts).unwrap();
        let info = src.info().clone();
        let expected = info.expected_frames(&opts).unwrap();
        let name = path.file_name().unwrap().to_string_lossy().to_string();
        // The clip names end in their frame size, e.g. `..._640x352.mp4`.
        let size = name.rsplit('_').next().unwrap().split('.').next().unwrap();
        assert_eq!(format!("{}x{}", info.width, info.height), size, "{name}");
        let frames = read_all(src);
        assert_eq!(frames.len() as u64, expected, "{name}");
        assert!(frames
            .iter()
            .all(|f| f.image.dimensions() == (info.width, info.height)));
        n += 1;
    }
    assert_eq!(n, 5, "expected the five real clips");
    let frames = clips.join("wsdot_i5_s188th_frames");
    let src = open_source(&frames, &SourceOptions::default()).unwrap();
    assert_eq!(src.info().frame_count, Some(51));
    assert_eq!(read_all(src).len(), 51);
}
