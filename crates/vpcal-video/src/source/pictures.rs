//! Frames from any iterator of pictures (frames already in memory, a Python iterable of
//! numpy arrays): the frame selection of [`SourceOptions`] applied as an image folder applies
//! it. Like a folder, the pictures are consecutive frames when a rate (`image_fps`) is given,
//! and stills of one camera without one.

use std::path::{Path, PathBuf};

use image::RgbImage;

use super::{seconds_to_index, Frame, FrameSource, SourceInfo, SourceKind, SourceOptions, Start};
use crate::error::{Result, VideoError};

/// A [`FrameSource`] over an iterator of RGB pictures of one size.
#[derive(Debug)]
pub struct PictureSource<I> {
    info: SourceInfo,
    pictures: I,
    /// The first selected picture, read to learn the size.
    first: Option<RgbImage>,
    /// Source index of the next picture the iterator gives.
    next_index: u64,
    /// Source index of the next picture to yield.
    wanted: u64,
    every: u64,
    remaining: Option<u64>,
    seconds_per_frame: f64,
    done: bool,
}

impl<I: Iterator<Item = Result<RgbImage>> + Send> PictureSource<I> {
    /// The pictures of `pictures`, named `label` in messages and results. Reads pictures up to
    /// the first selected one (its size is the source's).
    ///
    /// # Errors
    /// Invalid options, an iterator that fails or ends before the start.
    pub fn new(label: &Path, pictures: I, options: &SourceOptions) -> Result<PictureSource<I>> {
        options.validate()?;
        let fps = options.image_fps;
        let start = match options.start {
            Start::Beginning => 0,
            Start::Frame(n) => n,
            Start::Seconds(s) => seconds_to_index(s, fps.unwrap_or(1.0)),
        };
        let mut source = PictureSource {
            info: SourceInfo {
                path: label.to_path_buf(),
                kind: SourceKind::ImageFolder,
                width: 0,
                height: 0,
                fps,
                frame_count: None,
                codec: None,
            },
            pictures,
            first: None,
            next_index: 0,
            wanted: start,
            every: options.every,
            remaining: options.max_frames,
            seconds_per_frame: 1.0 / fps.unwrap_or(1.0),
            done: false,
        };
        let first = match source.read_wanted() {
            Some(r) => r?,
            None => {
                return Err(VideoError::Empty {
                    path: label.to_path_buf(),
                    reason: if start == 0 {
                        "no pictures".to_string()
                    } else {
                        format!(
                            "the start (frame {start}) is past the last picture (there are {})",
                            source.next_index
                        )
                    },
                })
            }
        };
        source.info.width = first.width();
        source.info.height = first.height();
        source.first = Some(first);
        Ok(source)
    }

    /// Skip to the wanted picture and read it.
    fn read_wanted(&mut self) -> Option<Result<RgbImage>> {
        loop {
            let picture = self.pictures.next()?;
            let index = self.next_index;
            self.next_index += 1;
            if index == self.wanted {
                return Some(picture);
            }
            // A picture that is skipped still ends the stream when it could not be read.
            if let Err(e) = picture {
                return Some(Err(e));
            }
        }
    }
}

impl<I: Iterator<Item = Result<RgbImage>> + Send> Iterator for PictureSource<I> {
    type Item = Result<Frame>;

    fn next(&mut self) -> Option<Result<Frame>> {
        if self.done || self.remaining == Some(0) {
            return None;
        }
        let picture = match self.first.take() {
            Some(p) => Ok(p),
            None => match self.read_wanted() {
                Some(p) => p,
                None => {
                    self.done = true;
                    return None;
                }
            },
        };
        let image = match picture {
            Ok(p) => p,
            Err(e) => {
                self.done = true;
                return Some(Err(e));
            }
        };
        let index = self.wanted;
        if image.dimensions() != (self.info.width, self.info.height) {
            self.done = true;
            return Some(Err(VideoError::Image {
                path: self.info.path.clone(),
                message: format!(
                    "frame {index} is {}x{} pixels, but the first frame is {}x{}",
                    image.width(),
                    image.height(),
                    self.info.width,
                    self.info.height
                ),
            }));
        }
        self.wanted += self.every;
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

impl<I: Iterator<Item = Result<RgbImage>> + Send> FrameSource for PictureSource<I> {
    fn info(&self) -> &SourceInfo {
        &self.info
    }
}

/// The label of pictures that have no file, e.g. `<frames>`.
pub fn picture_label(name: &str) -> PathBuf {
    PathBuf::from(format!("<{name}>"))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pictures(n: u8) -> impl Iterator<Item = Result<RgbImage>> + Send {
        (0..n).map(|k| Ok(RgbImage::from_pixel(4, 3, image::Rgb([k, 0, 0]))))
    }

    fn values(source: PictureSource<impl Iterator<Item = Result<RgbImage>> + Send>) -> Vec<u64> {
        source
            .map(|f| {
                let f = f.unwrap();
                assert_eq!(u64::from(f.image.get_pixel(0, 0)[0]), f.index);
                f.index
            })
            .collect()
    }

    #[test]
    fn the_selection_is_an_image_folders() {
        let label = picture_label("frames");
        let all = PictureSource::new(&label, pictures(10), &SourceOptions::default()).unwrap();
        assert_eq!(all.info().width, 4);
        assert_eq!(all.info().kind, SourceKind::ImageFolder);
        assert_eq!(values(all), (0..10).collect::<Vec<_>>());
        let options = SourceOptions {
            every: 3,
            start: Start::Frame(2),
            max_frames: Some(2),
            ..SourceOptions::default()
        };
        let some = PictureSource::new(&label, pictures(10), &options).unwrap();
        assert_eq!(values(some), vec![2, 5]);
        let timed = SourceOptions {
            start: Start::Seconds(0.5),
            image_fps: Some(10.0),
            every: 2,
            ..SourceOptions::default()
        };
        let source = PictureSource::new(&label, pictures(10), &timed).unwrap();
        assert_eq!(source.info().fps, Some(10.0));
        assert_eq!(values(source), vec![5, 7, 9]);
    }

    #[test]
    fn errors_name_the_frame_and_what_was_expected() {
        let label = picture_label("frames");
        let past = SourceOptions {
            start: Start::Frame(20),
            ..SourceOptions::default()
        };
        let Err(e) = PictureSource::new(&label, pictures(10), &past) else {
            panic!("a start past the end opened");
        };
        assert!(
            e.to_string()
                .contains("past the last picture (there are 10)"),
            "{e}"
        );
        assert!(PictureSource::new(&label, pictures(0), &SourceOptions::default()).is_err());
        let mixed = (0..3u32).map(|k| Ok(RgbImage::new(4 + k, 3)));
        let mut source = PictureSource::new(&label, mixed, &SourceOptions::default()).unwrap();
        assert!(source.next().unwrap().is_ok());
        let e = source.next().unwrap().unwrap_err().to_string();
        assert!(
            e.contains("frame 1 is 5x3 pixels, but the first frame is 4x3"),
            "{e}"
        );
        assert!(source.next().is_none());
    }
}
