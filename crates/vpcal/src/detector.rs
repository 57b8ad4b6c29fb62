//! Which vehicle detector looks at the frames, and its settings.

use std::path::PathBuf;

use anyhow::{bail, Result};
use vpcal_video::detect::{FileDetector, MotionConfig, MotionDetector, OnnxLayout};
use vpcal_video::{Detector, SourceInfo, SourceKind};

/// The detector and its settings.
#[derive(Debug, Clone)]
pub struct DetectorSettings {
    pub choice: DetectorChoice,
    /// Columns of square tiles a learned detector looks at besides the whole frame; `None`:
    /// [`default_tiles`] of the frame width.
    pub tiles: Option<u32>,
    /// Look at one tile per frame, in turn, instead of every tile in every frame (footage
    /// only).
    pub tile_rotation: bool,
    /// Output layout of an [`DetectorChoice::Onnx`] model.
    pub onnx_layout: OnnxLayout,
    /// Count COCO motorcycles as vehicles too.
    pub motorcycles: bool,
    /// Road mask of the motion detector (white = road).
    pub road_mask: Option<PathBuf>,
}

impl Default for DetectorSettings {
    fn default() -> DetectorSettings {
        DetectorSettings {
            choice: DetectorChoice::Auto,
            tiles: None,
            tile_rotation: false,
            onnx_layout: OnnxLayout::Yolo,
            motorcycles: false,
            road_mask: None,
        }
    }
}

impl DetectorSettings {
    /// Settings that contradict each other.
    ///
    /// # Errors
    /// A message naming the flags.
    pub fn validate(&self) -> Result<()> {
        if self.road_mask.is_some() && resolve_detector(&self.choice) != DetectorChoice::Motion {
            bail!("--road-mask applies to the motion detector (--detector motion) only");
        }
        Ok(())
    }
}

/// The vehicle detector `--detector` names.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum DetectorChoice {
    /// The built-in learned detector (the measured default).
    Auto,
    /// The built-in YOLOX-nano.
    Yolox,
    /// The weight-free motion detector.
    Motion,
    /// Boxes from a file.
    File(PathBuf),
    /// A YOLOX model file.
    YoloxFile(PathBuf),
    /// An ONNX model of the `--onnx-layout` layout.
    Onnx(PathBuf),
}

impl std::str::FromStr for DetectorChoice {
    type Err = String;

    fn from_str(s: &str) -> Result<DetectorChoice, String> {
        parse_detector(s)
    }
}

fn parse_detector(s: &str) -> Result<DetectorChoice, String> {
    let path = |p: &str, what: &str| {
        if p.is_empty() {
            Err(format!("`{s}`: give the {what} after the colon"))
        } else {
            Ok(PathBuf::from(p))
        }
    };
    match s.split_once(':') {
        None => match s {
            "auto" => Ok(DetectorChoice::Auto),
            "yolox" => Ok(DetectorChoice::Yolox),
            "motion" => Ok(DetectorChoice::Motion),
            _ => Err(format!(
                "unknown detector `{s}`: expected auto, yolox, motion, file:PATH, yolox:PATH or onnx:PATH"
            )),
        },
        Some(("file", p)) => path(p, "detections file").map(DetectorChoice::File),
        Some(("yolox", p)) => path(p, "YOLOX ONNX file").map(DetectorChoice::YoloxFile),
        Some(("onnx", p)) => path(p, "ONNX file").map(DetectorChoice::Onnx),
        Some((kind, _)) => Err(format!(
            "unknown detector kind `{kind}:` in `{s}`: expected file:PATH, yolox:PATH or onnx:PATH"
        )),
    }
}

/// Tile columns for the learned detector when `--tiles` is not given: none up to 960 px
/// wide, 2 above (see the README's measurement of recall against cost).
pub fn default_tiles(width: u32) -> u32 {
    if width > 960 {
        2
    } else {
        0
    }
}

/// The detector `choice` resolves to: `auto` is the learned detector.
pub fn resolve_detector(choice: &DetectorChoice) -> DetectorChoice {
    match choice {
        DetectorChoice::Auto => DetectorChoice::Yolox,
        other => other.clone(),
    }
}

/// The detector the settings ask for, for footage `info`.
///
/// # Errors
/// Settings that do not fit the detector or the input, an unreadable model or file.
pub fn open_detector(a: &DetectorSettings, info: &SourceInfo) -> Result<Box<dyn Detector>> {
    use vpcal_video::detect::{YoloxConfig, YoloxDetector};
    a.validate()?;
    let choice = resolve_detector(&a.choice);
    // COCO classes that count as vehicles, for both kinds of learned detector.
    let mut classes = vpcal_video::detect::yolox::COCO_CAR_BUS_TRUCK.to_vec();
    if a.motorcycles {
        classes.push(vpcal_video::detect::yolox::COCO_MOTORCYCLE);
    }
    let yolox_config = || YoloxConfig {
        classes: classes.clone(),
        tiles: a.tiles.unwrap_or_else(|| default_tiles(info.width)),
        // Stills are unrelated pictures: each must be looked at whole, every tile.
        tile_rotation: a.tile_rotation && !is_stills(info),
        ..YoloxConfig::default()
    };
    match choice {
        DetectorChoice::File(path) => Ok(Box::new(FileDetector::open(&path)?)),
        DetectorChoice::Yolox | DetectorChoice::Auto => {
            Ok(Box::new(YoloxDetector::bundled(yolox_config())?))
        }
        DetectorChoice::YoloxFile(path) => {
            Ok(Box::new(YoloxDetector::open(&path, yolox_config())?))
        }
        DetectorChoice::Onnx(path) => {
            let config = vpcal_video::detect::OnnxConfig {
                layout: a.onnx_layout,
                classes: Some(classes.clone()),
                ..vpcal_video::detect::OnnxConfig::default()
            };
            Ok(Box::new(vpcal_video::detect::OnnxDetector::open(
                &path, config,
            )?))
        }
        DetectorChoice::Motion => {
            if is_stills(info) {
                bail!(
                    "--detector motion needs consecutive frames (it learns the background from \
                     them): {} is a still or a folder of stills; use --detector yolox, or give \
                     a folder of consecutive frames its rate with --fps",
                    info.path.display()
                );
            }
            let mut d = MotionDetector::new(MotionConfig::default())?;
            if let Some(mask) = &a.road_mask {
                let m = vpcal_video::detect::motion::load_road_mask(mask)?;
                if m.dimensions() != (info.width, info.height) {
                    bail!(
                        "--road-mask {}: {}x{} pixels, but the frames are {}x{}",
                        mask.display(),
                        m.width(),
                        m.height(),
                        info.width,
                        info.height
                    );
                }
                d = d.with_road_mask(m, mask.clone());
            }
            Ok(Box::new(d))
        }
    }
}

/// Whether the input is stills rather than consecutive frames: one image, or a folder of
/// images without a frame rate (`--fps`) (with it, the folder is a frame sequence and is treated as video).
pub fn is_stills(info: &SourceInfo) -> bool {
    match info.kind {
        SourceKind::Video => false,
        SourceKind::SingleImage => true,
        SourceKind::ImageFolder => info.fps.is_none(),
    }
}
