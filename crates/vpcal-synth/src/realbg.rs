//! Real photographs as backgrounds: a BrnoCompSpeed view (`screen.png`, `video_mask.png`) with
//! the published calibration of that view (`system_dubska_bmvc14.json`: vp1, vp2, pp, scale).
//!
//! The files are read at run time from a path the user gives; nothing is copied.
//! The camera is rebuilt from the two VPs (focal, rotation) and the BCS `scale` (camera
//! height = scale * |n.C + 10|, see [`crate::camera::Camera::bcs_scale`]). Vehicles rendered
//! into the photo stand on the road plane of that calibration, inside the road mask.

use std::path::{Path, PathBuf};

use crate::camera::{bcs_plane_normal, camera_from_vps, Camera};
use crate::SynthError;

/// One real view usable as a background.
#[derive(Debug, Clone)]
pub struct RealBackground {
    pub name: String,
    pub image: image::RgbImage,
    /// Road mask (true = road), same size as the image; `None` when the view has none.
    pub mask: Option<image::GrayImage>,
    pub camera: Camera,
    /// Image points inside the mask (and below the horizon) on an 8-pixel grid.
    pub road_points: Vec<[f64; 2]>,
}

#[derive(serde::Deserialize)]
struct SystemFile {
    camera_calibration: CalibFile,
}

#[derive(serde::Deserialize)]
struct CalibFile {
    vp1: [f64; 2],
    vp2: [f64; 2],
    pp: [f64; 2],
    scale: f64,
}

impl RealBackground {
    /// Load one BCS view: `dataset_dir` holds `screen.png` (and optionally `video_mask.png`),
    /// `system_json` the calibration.
    ///
    /// # Errors
    /// [`SynthError::Io`]/[`SynthError::Image`] for unreadable files, [`SynthError::Format`] when
    /// the calibration is not a usable orthogonal VP pair.
    pub fn load_bcs(
        name: &str,
        dataset_dir: &Path,
        system_json: &Path,
    ) -> Result<RealBackground, SynthError> {
        let screen = dataset_dir.join("screen.png");
        let image = image::open(&screen)
            .map_err(|e| SynthError::Image {
                path: screen.clone(),
                source: e,
            })?
            .to_rgb8();
        let mask_path = dataset_dir.join("video_mask.png");
        let mask = if mask_path.exists() {
            Some(
                image::open(&mask_path)
                    .map_err(|e| SynthError::Image {
                        path: mask_path.clone(),
                        source: e,
                    })?
                    .to_luma8(),
            )
        } else {
            None
        };
        let text = std::fs::read_to_string(system_json).map_err(|e| SynthError::Io {
            path: system_json.to_path_buf(),
            source: e,
        })?;
        let sys: SystemFile = serde_json::from_str(&text).map_err(|e| SynthError::Format {
            path: system_json.to_path_buf(),
            message: format!("expected {{\"camera_calibration\": {{vp1, vp2, pp, scale}}}}: {e}"),
        })?;
        let c = sys.camera_calibration;
        let n = bcs_plane_normal(c.vp1, c.vp2, c.pp).ok_or_else(|| SynthError::Format {
            path: system_json.to_path_buf(),
            message: format!(
                "vp1 {:?} and vp2 {:?} are not an orthogonal pair for pp {:?}",
                c.vp1, c.vp2, c.pp
            ),
        })?;
        let height_m = c.scale * (n.x * c.pp[0] + n.y * c.pp[1] + 10.0).abs();
        if !(height_m > 0.5 && height_m < 200.0) {
            return Err(SynthError::Format {
                path: system_json.to_path_buf(),
                message: format!(
                    "scale {} gives an implausible camera height of {height_m} m",
                    c.scale
                ),
            });
        }
        let camera = camera_from_vps(image.width(), image.height(), c.vp1, c.vp2, c.pp, height_m)
            .ok_or_else(|| SynthError::Format {
            path: system_json.to_path_buf(),
            message: "VPs do not define a camera".to_string(),
        })?;
        let mut road_points = Vec::new();
        let h = camera.horizon();
        for y in (4..image.height()).step_by(8) {
            for x in (4..image.width()).step_by(8) {
                let (u, v) = (f64::from(x) + 0.5, f64::from(y) + 0.5);
                let on_road = mask.as_ref().is_none_or(|m| m.get_pixel(x, y)[0] > 127);
                // Keep a margin below the horizon so that vehicles are not microscopic.
                if on_road && h[0] * u + h[1] * v + h[2] > 20.0 {
                    road_points.push([u, v]);
                }
            }
        }
        Ok(RealBackground {
            name: name.to_string(),
            image,
            mask,
            camera,
            road_points,
        })
    }

    /// Every view under a BrnoCompSpeed-like root that has `dataset/<v>/screen.png` and
    /// `results/<v>/system_dubska_bmvc14.json`, sorted by name.
    ///
    /// # Errors
    /// When the root cannot be listed or a view fails to load.
    pub fn load_bcs_root(root: &Path) -> Result<Vec<RealBackground>, SynthError> {
        let ds = root.join("dataset");
        let mut names: Vec<(String, PathBuf)> = Vec::new();
        let rd = std::fs::read_dir(&ds).map_err(|e| SynthError::Io {
            path: ds.clone(),
            source: e,
        })?;
        for entry in rd {
            let entry = entry.map_err(|e| SynthError::Io {
                path: ds.clone(),
                source: e,
            })?;
            let name = entry.file_name().to_string_lossy().to_string();
            let dir = entry.path();
            let sys = root
                .join("results")
                .join(&name)
                .join("system_dubska_bmvc14.json");
            if dir.join("screen.png").exists() && sys.exists() {
                names.push((name, dir));
            }
        }
        names.sort();
        names
            .into_iter()
            .map(|(name, dir)| {
                let sys = root
                    .join("results")
                    .join(&name)
                    .join("system_dubska_bmvc14.json");
                RealBackground::load_bcs(&name, &dir, &sys)
            })
            .collect()
    }
}
