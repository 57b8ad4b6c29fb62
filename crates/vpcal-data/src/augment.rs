//! The paper's training augmentation (DeepVPCalib §3.3; DESIGN.md §6).
//!
//! For a training crop:
//! 1. a random homography `H` moves each corner of the crop by N(0, σ) px in x and y, and with
//!    probability `flip_probability` mirrors the crop horizontally (the mirror is part of `H`:
//!    the source corners are matched to the destination corners in mirrored order, so VP1 stays
//!    VP1 and VP2 stays VP2);
//! 2. `H` maps the 3D box corners and both VPs;
//! 3. the new 2D box is the hull of the warped 3D box (outward to whole pixels), each side moved
//!    by U(-j, j) px and clipped to the warped image;
//! 4. that box is cut out and resampled (bicubic by default) to `output_size`² px: warp, crop
//!    and resize happen in one resampling pass (output pixel → warped point → `H⁻¹` → source).
//!
//! A draw whose crop is smaller than `min_crop_px` or whose VPs go to infinity is redrawn, up to
//! `max_tries` times, then the sample is used without warp (as the reference code did).
//! Validation and test use [`AugmentConfig::evaluation`]: no warp, no jitter, no flip, the tight
//! hull of the 3D box.
//!
//! The VPs of the result are in the *box frame* of the final crop (`vpcal_geom::BoxPx::vp_in_box`),
//! ready for the heatmap codec.

use image::RgbImage;
use rand::Rng;
use serde::{Deserialize, Serialize};
use vpcal_geom::{BoxPx, Point2};

use crate::warp::{self, Homography, Resample};
use crate::Sample;

/// Every constant of the augmentation (DESIGN.md §6), with the paper's and the reference code's
/// settings as presets.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AugmentConfig {
    /// Standard deviation of the random displacement of each crop corner, px (source crop
    /// pixels). 0 disables the perspective warp.
    pub perspective_sigma_px: f64,
    /// Each side of the 2D box moves by U(-j, j) px (warped pixels). 0 disables the jitter.
    pub box_jitter_px: f64,
    /// Probability of a horizontal mirror.
    pub flip_probability: f64,
    /// Side of the square output crop, px (the network input).
    pub output_size: u32,
    /// Resampling filter for the warp and resize.
    pub filter: Resample,
    /// Smallest accepted side of the jittered 2D box, px; smaller draws are redrawn.
    pub min_crop_px: f64,
    /// Random draws before falling back to the un-warped crop.
    pub max_tries: u32,
    /// Probability of each sensor effect (a partial occluder, exposure and colour, blur, low
    /// resolution, noise, JPEG; [`crate::sensor`]); 0 (the paper) applies none.
    #[serde(default)]
    pub sensor_probability: f64,
    /// Largest factor of the sensor effects' down-sampling (drawn uniformly from 1.5 to it).
    #[serde(default = "default_max_downsample")]
    pub max_downsample: f64,
}

/// The sensor effects' largest down-sampling in the `real` preset: the corpus's webcams.
pub const REAL_MAX_DOWNSAMPLE: f64 = 3.5;

/// The largest down-sampling of the `real-small` preset: a vehicle 16 px tall, its crop
/// upsampled to the network's 128 px, has about an eighth of the crop's resolution.
pub const SMALL_MAX_DOWNSAMPLE: f64 = 8.0;

fn default_max_downsample() -> f64 {
    REAL_MAX_DOWNSAMPLE
}

impl AugmentConfig {
    /// The paper's settings: σ = 12.5 px, box jitter ±5 px, flips with p = 0.5, 128 px bicubic.
    pub fn paper() -> AugmentConfig {
        AugmentConfig {
            perspective_sigma_px: 12.5,
            box_jitter_px: 5.0,
            flip_probability: 0.5,
            output_size: 128,
            filter: Resample::Bicubic,
            min_crop_px: 12.5,
            max_tries: 4,
            sensor_probability: 0.0,
            max_downsample: REAL_MAX_DOWNSAMPLE,
        }
    }

    /// The paper's settings plus the sensor effects of real cameras, each with p = 0.3
    /// (sim-to-real for synthetic crops).
    pub fn real() -> AugmentConfig {
        AugmentConfig {
            sensor_probability: 0.3,
            ..AugmentConfig::paper()
        }
    }

    /// As [`AugmentConfig::real`], with the down-sampling reaching [`SMALL_MAX_DOWNSAMPLE`]:
    /// crops as blurred as those of the small vehicles that far traffic cameras see most.
    pub fn real_small() -> AugmentConfig {
        AugmentConfig {
            max_downsample: SMALL_MAX_DOWNSAMPLE,
            ..AugmentConfig::real()
        }
    }

    /// What the reference code effectively did: σ = 25 px at the original resolution (it drew
    /// 25 px and then doubled the image), otherwise as [`AugmentConfig::paper`].
    pub fn reference() -> AugmentConfig {
        AugmentConfig {
            perspective_sigma_px: 25.0,
            ..AugmentConfig::paper()
        }
    }

    /// Validation/test: the tight hull of the 3D box, no warp, jitter or flip.
    pub fn evaluation(output_size: u32) -> AugmentConfig {
        AugmentConfig {
            perspective_sigma_px: 0.0,
            box_jitter_px: 0.0,
            flip_probability: 0.0,
            sensor_probability: 0.0,
            output_size,
            ..AugmentConfig::paper()
        }
    }

    /// A preset by name: `paper`, `reference`, `real` (the paper's plus sensor effects),
    /// `real-small` (those with stronger down-sampling) or `none` (=
    /// [`AugmentConfig::evaluation`] at 128 px).
    pub fn preset(name: &str) -> Option<AugmentConfig> {
        match name {
            "paper" => Some(AugmentConfig::paper()),
            "real" => Some(AugmentConfig::real()),
            "real-small" => Some(AugmentConfig::real_small()),
            "reference" => Some(AugmentConfig::reference()),
            "none" => Some(AugmentConfig::evaluation(128)),
            _ => None,
        }
    }

    /// Names accepted by [`AugmentConfig::preset`].
    pub const PRESETS: [&'static str; 5] = ["paper", "reference", "real", "real-small", "none"];

    /// Check that every value is usable.
    ///
    /// # Errors
    /// A message naming the first bad field.
    pub fn validate(&self) -> Result<(), String> {
        let nonneg = |name: &str, v: f64| {
            if v.is_finite() && v >= 0.0 {
                Ok(())
            } else {
                Err(format!(
                    "augmentation {name} must be finite and >= 0, got {v}"
                ))
            }
        };
        nonneg("perspective_sigma_px", self.perspective_sigma_px)?;
        nonneg("box_jitter_px", self.box_jitter_px)?;
        nonneg("min_crop_px", self.min_crop_px)?;
        if !(0.0..=1.0).contains(&self.flip_probability) {
            return Err(format!(
                "augmentation flip_probability must be in [0, 1], got {}",
                self.flip_probability
            ));
        }
        if self.output_size == 0 {
            return Err("augmentation output_size must be > 0".into());
        }
        if !(0.0..=1.0).contains(&self.sensor_probability) {
            return Err(format!(
                "augmentation sensor_probability must be in [0, 1], got {}",
                self.sensor_probability
            ));
        }
        if !(self.max_downsample.is_finite() && self.max_downsample > 1.5) {
            return Err(format!(
                "augmentation max_downsample must be finite and > 1.5, got {}",
                self.max_downsample
            ));
        }
        Ok(())
    }

    /// True when this configuration never warps, jitters or flips.
    pub fn is_deterministic(&self) -> bool {
        self.perspective_sigma_px == 0.0
            && self.box_jitter_px == 0.0
            && self.flip_probability == 0.0
    }
}

impl Default for AugmentConfig {
    fn default() -> Self {
        AugmentConfig::paper()
    }
}

/// An augmented crop with its geometry.
#[derive(Debug, Clone)]
pub struct Augmented {
    /// The crop, `output_size` x `output_size`, RGB.
    pub image: RgbImage,
    /// VP1 in the box frame of the crop (the crop spans [-1, 1]²).
    pub vp1_box: Point2,
    /// VP2 in the box frame of the crop.
    pub vp2_box: Point2,
    /// The warped 3D box corners in output pixels (order as [`Sample::bb3d`]).
    pub bb3d: [[f64; 2]; 8],
    /// The tight hull of the warped 3D box (before jitter) in output pixels.
    pub hull: BoxPx,
    /// The crop rectangle in warped pixels.
    pub crop: BoxPx,
    /// Source crop pixels → warped pixels (identity when not warped).
    pub homography: Homography,
    /// Whether the homography mirrors.
    pub flipped: bool,
}

/// Why a sample could not be augmented.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum AugmentError {
    #[error("invalid augmentation settings: {0}")]
    Config(String),
    #[error("unusable sample: {0}")]
    Sample(String),
}

/// A standard normal draw (Box-Muller).
fn normal<R: Rng + ?Sized>(rng: &mut R) -> f64 {
    let u1: f64 = 1.0 - rng.random::<f64>(); // (0, 1]
    let u2: f64 = rng.random::<f64>();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

fn uniform_sym<R: Rng + ?Sized>(rng: &mut R, half_width: f64) -> f64 {
    if half_width > 0.0 {
        rng.random_range(-half_width..=half_width)
    } else {
        0.0
    }
}

/// The homography of one draw: corners moved by N(0, σ), mirrored with probability p.
fn random_homography<R: Rng + ?Sized>(
    w: f64,
    h: f64,
    cfg: &AugmentConfig,
    rng: &mut R,
) -> (Option<Homography>, bool) {
    let corners = [
        Point2::new(0.0, 0.0),
        Point2::new(w, 0.0),
        Point2::new(w, h),
        Point2::new(0.0, h),
    ];
    let mut dst = corners;
    if cfg.perspective_sigma_px > 0.0 {
        for p in dst.iter_mut() {
            p.x += cfg.perspective_sigma_px * normal(rng);
            p.y += cfg.perspective_sigma_px * normal(rng);
        }
    }
    let flip = cfg.flip_probability > 0.0 && rng.random::<f64>() < cfg.flip_probability;
    let src = if flip {
        [corners[1], corners[0], corners[3], corners[2]]
    } else {
        corners
    };
    if !flip && cfg.perspective_sigma_px == 0.0 {
        return (Some(Homography::IDENTITY), false);
    }
    (Homography::from_points(src, dst), flip)
}

fn hull(points: &[Point2]) -> BoxPx {
    let mut b = BoxPx {
        x0: f64::INFINITY,
        y0: f64::INFINITY,
        x1: f64::NEG_INFINITY,
        y1: f64::NEG_INFINITY,
    };
    for p in points {
        b.x0 = b.x0.min(p.x);
        b.y0 = b.y0.min(p.y);
        b.x1 = b.x1.max(p.x);
        b.y1 = b.y1.max(p.y);
    }
    b
}

struct Draw {
    homography: Homography,
    flipped: bool,
    bb3d: [Point2; 8],
    vp1: Point2,
    vp2: Point2,
    crop: BoxPx,
}

/// One attempt; `None` when the draw is unusable.
fn attempt<R: Rng + ?Sized>(
    sample: &Sample,
    cfg: &AugmentConfig,
    warp_it: bool,
    rng: &mut R,
) -> Option<Draw> {
    let (w, h) = (
        f64::from(sample.image.width()),
        f64::from(sample.image.height()),
    );
    let (homography, flipped) = if warp_it {
        random_homography(w, h, cfg, rng)
    } else {
        (Some(Homography::IDENTITY), false)
    };
    let homography = homography?;
    let map = |p: [f64; 2]| homography.apply(Point2::new(p[0], p[1]));
    let mut bb3d = [Point2::new(0.0, 0.0); 8];
    for (dst, src) in bb3d.iter_mut().zip(&sample.bb3d) {
        *dst = map(*src)?;
    }
    let vp1 = map(sample.vp1)?;
    let vp2 = map(sample.vp2)?;
    // The warped image's extent: the hull of its warped corners.
    let extent = hull(&[
        homography.apply(Point2::new(0.0, 0.0))?,
        homography.apply(Point2::new(w, 0.0))?,
        homography.apply(Point2::new(w, h))?,
        homography.apply(Point2::new(0.0, h))?,
    ]);
    let tight = hull(&bb3d);
    let jitter = if warp_it { cfg.box_jitter_px } else { 0.0 };
    let crop = BoxPx {
        x0: (tight.x0.floor() + uniform_sym(rng, jitter)).max(extent.x0),
        y0: (tight.y0.floor() + uniform_sym(rng, jitter)).max(extent.y0),
        x1: (tight.x1.ceil() + uniform_sym(rng, jitter)).min(extent.x1),
        y1: (tight.y1.ceil() + uniform_sym(rng, jitter)).min(extent.y1),
    };
    let min = cfg.min_crop_px.max(1.0);
    let ok = crop.is_valid() && crop.width() >= min && crop.height() >= min;
    ok.then_some(Draw {
        homography,
        flipped,
        bb3d,
        vp1,
        vp2,
        crop,
    })
}

/// Augment one sample (see the module docs).
///
/// # Errors
/// [`AugmentError::Config`] for invalid settings, [`AugmentError::Sample`] when even the
/// un-warped crop is unusable (empty image, non-finite geometry, a box smaller than
/// `min_crop_px`).
pub fn augment<R: Rng + ?Sized>(
    sample: &Sample,
    cfg: &AugmentConfig,
    rng: &mut R,
) -> Result<Augmented, AugmentError> {
    cfg.validate().map_err(AugmentError::Config)?;
    if sample.image.width() == 0 || sample.image.height() == 0 {
        return Err(AugmentError::Sample("the crop image is empty".into()));
    }
    let finite = sample.bb3d.iter().flatten().all(|v| v.is_finite())
        && sample.vp1.iter().chain(&sample.vp2).all(|v| v.is_finite());
    if !finite {
        return Err(AugmentError::Sample(
            "non-finite 3D box corner or VP".into(),
        ));
    }
    let mut draw = None;
    if !cfg.is_deterministic() {
        for _ in 0..cfg.max_tries {
            draw = attempt(sample, cfg, true, rng);
            if draw.is_some() {
                break;
            }
        }
    }
    let draw = match draw {
        Some(d) => d,
        None => attempt(sample, cfg, false, rng).ok_or_else(|| {
            AugmentError::Sample(format!(
                "the 3D box hull inside the {}x{} crop is smaller than {} px",
                sample.image.width(),
                sample.image.height(),
                cfg.min_crop_px.max(1.0)
            ))
        })?,
    };

    let size = cfg.output_size;
    let s = f64::from(size);
    let crop = draw.crop;
    let (sx, sy) = (crop.width() / s, crop.height() / s);
    let inverse = draw
        .homography
        .inverse()
        .ok_or_else(|| AugmentError::Sample("singular augmentation homography".into()))?;
    let image = warp::render(&sample.image, size, cfg.filter, |q| {
        inverse.apply(Point2::new(crop.x0 + q.x * sx, crop.y0 + q.y * sy))
    });
    let image =
        crate::sensor::sensor_effects(image, cfg.sensor_probability, cfg.max_downsample, rng);
    let to_out = |p: Point2| [(p.x - crop.x0) / sx, (p.y - crop.y0) / sy];
    let bb3d = draw.bb3d.map(to_out);
    let tight = hull(&draw.bb3d);
    let [hx0, hy0] = to_out(Point2::new(tight.x0, tight.y0));
    let [hx1, hy1] = to_out(Point2::new(tight.x1, tight.y1));
    Ok(Augmented {
        image,
        vp1_box: crop.vp_in_box(draw.vp1),
        vp2_box: crop.vp_in_box(draw.vp2),
        bb3d,
        hull: BoxPx {
            x0: hx0,
            y0: hy0,
            x1: hx1,
            y1: hy1,
        },
        crop,
        homography: draw.homography,
        flipped: draw.flipped,
    })
}
