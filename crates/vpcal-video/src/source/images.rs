//! Image folders and single images as frame sources.
//!
//! A folder's images (`png`, `jpg`, `jpeg`, any case) are read in natural name order
//! (`frame2.png` before `frame10.png`; digit runs compare as numbers), one file per frame,
//! decoded only when its frame is reached. All images must have the size of the first one.

use std::cmp::Ordering;
use std::path::{Path, PathBuf};

use super::{
    is_image_path, seconds_to_index, Frame, FrameSource, SourceInfo, SourceKind, SourceOptions,
    Start,
};
use crate::error::{Result, VideoError};

/// Frames from a list of image files (a folder or one image).
#[derive(Debug)]
pub struct ImageSequenceSource {
    info: SourceInfo,
    files: Vec<PathBuf>,
    /// Index of the next frame to yield.
    next: u64,
    every: u64,
    remaining: Option<u64>,
    seconds_per_frame: f64,
    done: bool,
}

/// Compares file names so that digit runs are ordered by value (`a2` < `a10`).
pub fn natural_cmp(a: &str, b: &str) -> Ordering {
    let (mut a, mut b) = (a.as_bytes(), b.as_bytes());
    loop {
        match (a.first(), b.first()) {
            (None, None) => return Ordering::Equal,
            (None, Some(_)) => return Ordering::Less,
            (Some(_), None) => return Ordering::Greater,
            (Some(x), Some(y)) if x.is_ascii_digit() && y.is_ascii_digit() => {
                let da = a.iter().take_while(|c| c.is_ascii_digit()).count();
                let db = b.iter().take_while(|c| c.is_ascii_digit()).count();
                let (na, nb) = (&a[..da], &b[..db]);
                let ta = trim_zeros(na);
                let tb = trim_zeros(nb);
                let ord = ta
                    .len()
                    .cmp(&tb.len())
                    .then_with(|| ta.cmp(tb))
                    .then(da.cmp(&db));
                if ord != Ordering::Equal {
                    return ord;
                }
                a = &a[da..];
                b = &b[db..];
            }
            (Some(x), Some(y)) => {
                if x != y {
                    return x.cmp(y);
                }
                a = &a[1..];
                b = &b[1..];
            }
        }
    }
}

fn trim_zeros(d: &[u8]) -> &[u8] {
    let n = d.iter().take_while(|&&c| c == b'0').count();
    &d[n..]
}

fn load_rgb(path: &Path) -> Result<image::RgbImage> {
    let img = image::open(path).map_err(|e| VideoError::Image {
        path: path.to_path_buf(),
        message: format!("cannot decode image ({e})"),
    })?;
    Ok(img.into_rgb8())
}

impl ImageSequenceSource {
    /// All images in `folder` (not recursive), in natural name order.
    ///
    /// # Errors
    /// [`VideoError::Io`] when the folder cannot be listed, [`VideoError::Empty`] when it
    /// holds no image, [`VideoError::Image`] when the first image cannot be decoded.
    pub fn folder(folder: &Path, options: &SourceOptions) -> Result<ImageSequenceSource> {
        let entries = std::fs::read_dir(folder)
            .map_err(|e| VideoError::io("cannot list image folder", folder, e))?;
        let mut files = Vec::new();
        for entry in entries {
            let entry = entry.map_err(|e| VideoError::io("cannot list image folder", folder, e))?;
            let path = entry.path();
            if path.is_file() && is_image_path(&path) {
                files.push(path);
            }
        }
        if files.is_empty() {
            return Err(VideoError::Empty {
                path: folder.to_path_buf(),
                reason: "the folder holds no png/jpg image".into(),
            });
        }
        files.sort_by(|a, b| {
            let na = a
                .file_name()
                .map(|n| n.to_string_lossy())
                .unwrap_or_default();
            let nb = b
                .file_name()
                .map(|n| n.to_string_lossy())
                .unwrap_or_default();
            natural_cmp(&na, &nb)
        });
        Self::from_files(folder, SourceKind::ImageFolder, files, options)
    }

    /// One image as a one-frame source.
    ///
    /// # Errors
    /// [`VideoError::Image`] when it cannot be decoded.
    pub fn single(path: &Path, options: &SourceOptions) -> Result<ImageSequenceSource> {
        Self::from_files(
            path,
            SourceKind::SingleImage,
            vec![path.to_path_buf()],
            options,
        )
    }

    fn from_files(
        path: &Path,
        kind: SourceKind,
        files: Vec<PathBuf>,
        options: &SourceOptions,
    ) -> Result<ImageSequenceSource> {
        options.validate()?;
        let first_path = files.first().ok_or_else(|| VideoError::Empty {
            path: path.to_path_buf(),
            reason: "no image".into(),
        })?;
        // Only the header is needed for the size.
        let (width, height) =
            image::image_dimensions(first_path).map_err(|e| VideoError::Image {
                path: first_path.clone(),
                message: format!("cannot read image size ({e})"),
            })?;
        let fps = options.image_fps;
        let start = match options.start {
            Start::Beginning => 0,
            Start::Frame(n) => n,
            Start::Seconds(s) => seconds_to_index(s, fps.unwrap_or(1.0)),
        };
        if start >= files.len() as u64 {
            return Err(VideoError::Empty {
                path: path.to_path_buf(),
                reason: format!(
                    "the start (frame {start}) is past the last image (there are {})",
                    files.len()
                ),
            });
        }
        Ok(ImageSequenceSource {
            info: SourceInfo {
                path: path.to_path_buf(),
                kind,
                width,
                height,
                fps,
                frame_count: Some(files.len() as u64),
                codec: None,
            },
            files,
            next: start,
            every: options.every.max(1),
            remaining: options.max_frames,
            seconds_per_frame: 1.0 / fps.unwrap_or(1.0),
            done: false,
        })
    }
}

impl Iterator for ImageSequenceSource {
    type Item = Result<Frame>;

    fn next(&mut self) -> Option<Result<Frame>> {
        if self.done || self.remaining == Some(0) {
            return None;
        }
        let Ok(i) = usize::try_from(self.next) else {
            self.done = true;
            return None;
        };
        let path = self.files.get(i)?;
        let image = match load_rgb(path) {
            Ok(img) => img,
            Err(e) => {
                self.done = true;
                return Some(Err(e));
            }
        };
        if image.dimensions() != (self.info.width, self.info.height) {
            self.done = true;
            return Some(Err(VideoError::Image {
                path: path.clone(),
                message: format!(
                    "image is {}x{} but the sequence is {}x{}",
                    image.width(),
                    image.height(),
                    self.info.width,
                    self.info.height
                ),
            }));
        }
        let index = self.next;
        self.next += self.every;
        if let Some(r) = self.remaining.as_mut() {
            *r -= 1;
        }
        Some(Ok(Frame {
            index,
            time_s: index as f64 * self.seconds_per_frame,
            image,
        }))
    }
}

impl FrameSource for ImageSequenceSource {
    fn info(&self) -> &SourceInfo {
        &self.info
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn natural_order_compares_numbers_by_value() {
        let mut v = vec!["f10.png", "f2.png", "f1.png", "f02.png", "g.png", "f.png"];
        v.sort_by(|a, b| natural_cmp(a, b));
        assert_eq!(
            v,
            ["f.png", "f1.png", "f2.png", "f02.png", "f10.png", "g.png"]
        );
    }
}
