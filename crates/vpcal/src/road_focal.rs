//! The focal length from known road lengths in two directions (`vpcal scale` with a length
//! along the road and one across it, `calibrate --scale-points` given twice).
//!
//! The road plane's metric follows from the horizon, the principal point and `f` alone: its
//! normal is `∝ Kᵀh`, whatever VP1 is (VP1 only names the along axis). Lengths on parallel
//! lines keep their ratios for every `f` (ratios along one direction are invariant under the
//! affine part of the rectification), so lengths in one direction fix only the scale. A
//! length in another direction (across the road, a lane width, a diagonal) changes its ratio
//! to the first as `f` changes: the focal length is the one at which every known length
//! agrees with one scale. VP1 and the horizon stay; VP2 moves along the horizon to the point
//! orthogonal to VP1 for that `f` (as `--focal` does).
//!
//! The fit minimises, over `ln f`, the weighted spread of the lengths' own log scales
//! (`ln(known / measured)`), each weighted by the inverse variance of its clicks
//! ([`CLICK_SD_PX`] per coordinate) and its known length ([`DISTANCE_REL_SD`],
//! [`LANE_WIDTH_REL_SD`]). The 68 % interval propagates those and the camera's own spread (VP1
//! and the horizon's angle, floored at what the synthetic suite measured: [`HORIZON_SD_FLOOR_DEG`],
//! [`VP1_SD_FLOOR_WIDTHS`]) by refitting with each one moved by its standard deviation.
//! The focal length counts as measured only where the fit is identified: its minimum lies
//! inside the search range and moving `f` by a factor of two either way raises the misfit by
//! at least [`IDENTIFIED_DELTA_CHI2`].

use vpcal_geom::camera::{orthogonal_vp_on_line, Calibration};
use vpcal_geom::{Line, Point2};

use crate::road::{RoadMeasure, ScaleInput};
use vpcal_geom::aggregate::focal::{self, Cue, Likelihood};

/// Standard deviation of a clicked pixel, per coordinate: a person marking the ends of a lane
/// line or a taped distance on a frame.
pub const CLICK_SD_PX: f64 = 1.0;

/// Relative standard deviation of a known distance (taped, or read off a plan).
pub const DISTANCE_REL_SD: f64 = 0.01;

/// Relative standard deviation of a known lane width: a road's lanes are built to their
/// standard within a few centimetres, but which standard (3.5 m against 3.75 m) is often
/// read from the road class.
pub const LANE_WIDTH_REL_SD: f64 = 0.03;

/// The least standard deviation of the horizon's angle used in the interval, degrees. The
/// bootstrap's own spread underestimates it: on the synthetic suite (true boxes, 100 frames,
/// `scripts/suite_focal.sh`) the straight and intersection scenes' horizons erred by
/// 0.22-1.46° (median 0.43°) where the bootstrap said 0.07-0.28°.
pub const HORIZON_SD_FLOOR_DEG: f64 = 0.5;

/// The least standard deviation of VP1 used in the interval, image widths: the same scenes'
/// VP1 erred by 0.3-12 px at 1280 px (median 1.2 px) where the bootstrap said 0.
pub const VP1_SD_FLOOR_WIDTHS: f64 = 0.002;

/// How much the misfit (χ², in the lengths' standard deviations) must rise when `f` moves by
/// a factor of two either way for the lengths to count as fixing it: two standard deviations.
pub const IDENTIFIED_DELTA_CHI2: f64 = 4.0;

/// The focal lengths searched, image widths: far beyond any traffic camera's (a fisheye's
/// 0.3 widths to a 20-width telephoto).
pub const SEARCH_RANGE_WIDTHS: [f64; 2] = [0.1, 20.0];

/// How well the camera's VP1 and horizon are known (standard deviations), for the interval.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraSpread {
    pub vp1_sd_px: f64,
    pub horizon_angle_sd_deg: f64,
}

impl CameraSpread {
    /// The calibration's bootstrap spread (`None`: none measured), floored at
    /// [`VP1_SD_FLOOR_WIDTHS`] and [`HORIZON_SD_FLOOR_DEG`] for frames `width` pixels wide.
    pub fn floored(measured: Option<CameraSpread>, width: f64) -> CameraSpread {
        let m = measured.unwrap_or(CameraSpread {
            vp1_sd_px: 0.0,
            horizon_angle_sd_deg: 0.0,
        });
        let at_least = |v: f64, floor: f64| if v.is_finite() { v.max(floor) } else { floor };
        CameraSpread {
            vp1_sd_px: at_least(m.vp1_sd_px, VP1_SD_FLOOR_WIDTHS * width),
            horizon_angle_sd_deg: at_least(m.horizon_angle_sd_deg, HORIZON_SD_FLOOR_DEG),
        }
    }

    /// The spread calibration file `file` records (`confidence`), floored as
    /// [`CameraSpread::floored`] for frames `width` pixels wide.
    pub fn of_file(file: &vpcal_formats::calib::CalibrationFile, width: f64) -> CameraSpread {
        let measured = file.confidence.as_ref().map(|c| CameraSpread {
            vp1_sd_px: c.vp1_sd_px,
            horizon_angle_sd_deg: c.horizon_angle_sd_deg,
        });
        CameraSpread::floored(measured, width)
    }
}

/// The focal length the known lengths give, with the camera it makes.
#[derive(Debug, Clone, PartialEq)]
pub struct LengthFocal {
    pub focal_px: f64,
    /// 68 % interval, pixels: `f · exp(±log_sd)`.
    pub interval_px: [f64; 2],
    pub log_sd: f64,
    /// The camera with this focal length: VP1 and the horizon as before, VP2 moved.
    pub camera: Calibration,
    /// The weighted misfit at the minimum (χ²; 0 for two lengths, which fit exactly) and its
    /// degrees of freedom (lengths minus two).
    pub chi2: f64,
    pub dof: usize,
}

/// What the known lengths say about the focal length.
#[derive(Debug, Clone, PartialEq)]
pub enum LengthFocalFit {
    Measured(Box<LengthFocal>),
    /// They do not fix it, and why (one direction only, pixels that see no road).
    NotIdentified(String),
    /// No focal length makes them agree with each other on a camera with this VP1 and
    /// horizon (the best lies at the end of the searched range), and why: a length or a
    /// pixel is wrong, or the horizon is.
    Inconsistent(String),
}

/// The camera of `cal` with focal length `focal_px`: VP1, the horizon and the principal
/// point stay, VP2 is the point of the horizon orthogonal to VP1. `None` where none is.
pub fn camera_with_focal(cal: &Calibration, focal_px: f64) -> Option<Calibration> {
    with_focal(cal.vp1, cal.horizon, cal.pp, focal_px)
}

fn with_focal(vp1: Point2, horizon: Line, pp: Point2, focal_px: f64) -> Option<Calibration> {
    let vp2 = orthogonal_vp_on_line(vp1, horizon, focal_px, pp)?;
    Calibration::from_vps(vp1, vp2, pp).ok()
}

/// The length measurement `m` measures on camera `cal`, road units; `None` when a pixel does
/// not see the road or the length is zero.
fn units(cal: &Calibration, m: &ScaleInput) -> Option<f64> {
    let a = cal.road_point(m.known.p1)?;
    let b = cal.road_point(m.known.p2)?;
    let u = match m.kind {
        RoadMeasure::Distance => (a[0] - b[0]).hypot(a[1] - b[1]),
        RoadMeasure::LaneWidth => (a[1] - b[1]).abs(),
    };
    (u.is_finite() && u > 0.0).then_some(u)
}

/// Input `m` with coordinate `coord` of its pixels (0, 1: x, y of the first; 2, 3: of the
/// second) moved by `h` pixels.
fn nudged(mut m: ScaleInput, coord: usize, h: f64) -> ScaleInput {
    let p = if coord < 2 {
        &mut m.known.p1
    } else {
        &mut m.known.p2
    };
    if coord % 2 == 0 {
        p.x += h;
    } else {
        p.y += h;
    }
    m
}

/// The relative standard deviation of a known length of `kind`.
fn length_rel_sd(kind: RoadMeasure) -> f64 {
    match kind {
        RoadMeasure::Distance => DISTANCE_REL_SD,
        RoadMeasure::LaneWidth => LANE_WIDTH_REL_SD,
    }
}

/// The variance of `ln(measured length)` of each input on `cal`: its clicks (numerically,
/// [`CLICK_SD_PX`] per coordinate) and its known length's relative error.
fn log_variances(cal: &Calibration, inputs: &[ScaleInput]) -> Option<Vec<f64>> {
    inputs
        .iter()
        .map(|m| {
            let base = units(cal, m)?.ln();
            let mut var = 0.0;
            for coord in 0..4 {
                let moved = nudged(*m, coord, CLICK_SD_PX);
                let d = units(cal, &moved).map_or(0.0, |u| u.ln() - base);
                var += d * d;
            }
            Some(var + length_rel_sd(m.kind).powi(2))
        })
        .collect()
}

/// The weighted misfit of the inputs on the camera with focal length `f`: `Σ w_i (l_i -
/// l̄)²` over the lengths' own log scales `l_i = ln(known / measured)`; `None` where the
/// camera or a length does not exist.
fn misfit(
    vp1: Point2,
    horizon: Line,
    pp: Point2,
    inputs: &[ScaleInput],
    weights: &[f64],
    f: f64,
) -> Option<f64> {
    let cal = with_focal(vp1, horizon, pp, f)?;
    let logs: Vec<f64> = inputs
        .iter()
        .map(|m| units(&cal, m).map(|u| (m.known.distance_m / u).ln()))
        .collect::<Option<_>>()?;
    let wsum: f64 = weights.iter().sum();
    let mean = logs.iter().zip(weights).map(|(l, w)| l * w).sum::<f64>() / wsum;
    Some(
        logs.iter()
            .zip(weights)
            .map(|(l, w)| w * (l - mean).powi(2))
            .sum(),
    )
}

/// The `ln f` of least misfit over `[lo, hi]` (logs of pixels) and the misfit there: a grid,
/// then a golden-section search around its best point. `None` where no camera exists.
fn best_log_focal(cost: &dyn Fn(f64) -> Option<f64>, lo: f64, hi: f64) -> Option<(f64, f64)> {
    const STEPS: usize = 400;
    let step = (hi - lo) / STEPS as f64;
    let at = |x: f64| cost(x.exp()).unwrap_or(f64::INFINITY);
    let (mut best_x, mut best_c) = (lo, f64::INFINITY);
    for i in 0..=STEPS {
        let x = lo + step * i as f64;
        let c = at(x);
        if c < best_c {
            (best_x, best_c) = (x, c);
        }
    }
    if !best_c.is_finite() {
        return None;
    }
    let (mut a, mut b) = ((best_x - step).max(lo), (best_x + step).min(hi));
    let g = (5f64.sqrt() - 1.0) / 2.0;
    for _ in 0..60 {
        let (x1, x2) = (b - g * (b - a), a + g * (b - a));
        if at(x1) < at(x2) {
            b = x2;
        } else {
            a = x1;
        }
    }
    let x = 0.5 * (a + b);
    let c = at(x);
    Some(if c <= best_c {
        (x, c)
    } else {
        (best_x, best_c)
    })
}

/// The best focal length of the known lengths `inputs` on camera `cal` (frames `width` pixels
/// wide), before any check of how well it is pinned down.
struct BestFit {
    /// The lengths' weights (inverse variances in `ln` length).
    weights: Vec<f64>,
    /// The searched range and the best point, `ln f`, and its misfit.
    lo: f64,
    hi: f64,
    x: f64,
    chi2: f64,
}

/// [`BestFit`] of `inputs`, or why there is none: too few lengths, pixels off the road, no
/// camera ([`LengthFocalFit::NotIdentified`]), or lengths that no focal length in the range
/// reconciles ([`LengthFocalFit::Inconsistent`]).
fn best_fit(
    cal: &Calibration,
    inputs: &[ScaleInput],
    width: f64,
) -> Result<BestFit, LengthFocalFit> {
    if inputs.len() < 2 {
        return Err(LengthFocalFit::NotIdentified(
            "one known length fixes only the scale; give a second one in another direction \
             (across the road) to measure the focal length"
                .to_string(),
        ));
    }
    let Some(variances) = log_variances(cal, inputs) else {
        return Err(LengthFocalFit::NotIdentified(
            "a known length's pixels do not see the road".to_string(),
        ));
    };
    let weights: Vec<f64> = variances.iter().map(|v| 1.0 / v).collect();
    let [lo, hi] = SEARCH_RANGE_WIDTHS.map(|r| (r * width).ln());
    let cost = |f: f64| misfit(cal.vp1, cal.horizon, cal.pp, inputs, &weights, f);
    let Some((x, chi2)) = best_log_focal(&cost, lo, hi) else {
        return Err(LengthFocalFit::NotIdentified(
            "no focal length gives a camera for these lengths".to_string(),
        ));
    };
    if (x - lo).min(hi - x) < 0.02 * (hi - lo) {
        return Err(LengthFocalFit::Inconsistent(format!(
            "no focal length between {:.0} and {:.0} px makes the known lengths agree: check \
             their pixels and lengths",
            lo.exp(),
            hi.exp()
        )));
    }
    Ok(BestFit {
        weights,
        lo,
        hi,
        x,
        chi2,
    })
}

/// Why the known lengths `inputs` disagree with each other on every camera with `cal`'s VP1
/// and horizon (frames `width` pixels wide), if they do: a length or a pixel is wrong, or the
/// horizon is. Such lengths would only pull the scale between wrong values.
pub fn disagreement(cal: &Calibration, inputs: &[ScaleInput], width: f64) -> Option<String> {
    match best_fit(cal, inputs, width) {
        Err(LengthFocalFit::Inconsistent(why)) => Some(why),
        _ => None,
    }
}

/// The focal length the known lengths `inputs` give on camera `cal` (frames `width` pixels
/// wide), with the camera's spread `spread` for the interval. See the module docs.
pub fn fit_focal_from_lengths(
    cal: &Calibration,
    inputs: &[ScaleInput],
    spread: CameraSpread,
    width: f64,
) -> LengthFocalFit {
    let BestFit {
        weights,
        lo,
        hi,
        x,
        chi2,
    } = match best_fit(cal, inputs, width) {
        Ok(b) => b,
        Err(why) => return why,
    };
    let solve = |vp1: Point2, horizon: Line, inputs: &[ScaleInput]| {
        let cost = |f: f64| misfit(vp1, horizon, cal.pp, inputs, &weights, f);
        best_log_focal(&cost, lo, hi)
    };
    let cost = |f: f64| misfit(cal.vp1, cal.horizon, cal.pp, inputs, &weights, f);
    let rise = |factor: f64| {
        let f = (x.exp() * factor).clamp(lo.exp(), hi.exp());
        cost(f).map_or(f64::INFINITY, |c| c - chi2)
    };
    if rise(2.0) < IDENTIFIED_DELTA_CHI2 || rise(0.5) < IDENTIFIED_DELTA_CHI2 {
        return LengthFocalFit::NotIdentified(
            "the known lengths lie in one direction (or nearly): they fix the scale, not the \
             focal length; give one across the road too to measure it"
                .to_string(),
        );
    }
    // Propagation: refit with each input moved by one standard deviation, both ways. A move
    // after which no focal length fits (a pixel above the moved horizon) counts one-sided,
    // or, both ways, as the whole searched range: the lengths do not pin it down.
    let mut var = 0.0;
    let mut add = |plus: Option<(f64, f64)>, minus: Option<(f64, f64)>| {
        var += match (plus, minus) {
            (Some((a, _)), Some((b, _))) => (0.5 * (a - b)).powi(2),
            (Some((a, _)), None) | (None, Some((a, _))) => (a - x).powi(2),
            (None, None) => (0.5 * (hi - lo)).powi(2),
        };
    };
    for i in 0..inputs.len() {
        for coord in 0..4 {
            let moved = |h: f64| {
                let mut v = inputs.to_vec();
                v[i] = nudged(v[i], coord, h);
                v
            };
            add(
                solve(cal.vp1, cal.horizon, &moved(CLICK_SD_PX)),
                solve(cal.vp1, cal.horizon, &moved(-CLICK_SD_PX)),
            );
        }
        let rel = length_rel_sd(inputs[i].kind);
        let scaled = |k: f64| {
            let mut v = inputs.to_vec();
            v[i].known.distance_m *= k;
            v
        };
        add(
            solve(cal.vp1, cal.horizon, &scaled((rel).exp())),
            solve(cal.vp1, cal.horizon, &scaled((-rel).exp())),
        );
    }
    // VP1 moved (the horizon keeps its angle), the horizon turned about VP1.
    let shifted = |d: Point2| {
        let vp1 = cal.vp1 + d;
        let dir = Point2::new(cal.horizon.0[1], -cal.horizon.0[0]);
        Line::through_with_direction(vp1, dir).map(|h| (vp1, h))
    };
    for d in [
        Point2::new(spread.vp1_sd_px, 0.0),
        Point2::new(0.0, spread.vp1_sd_px),
    ] {
        let plus = shifted(d).and_then(|(v, h)| solve(v, h, inputs));
        let minus = shifted(Point2::new(-d.x, -d.y)).and_then(|(v, h)| solve(v, h, inputs));
        add(plus, minus);
    }
    let turned = |deg: f64| {
        let (s, c) = deg.to_radians().sin_cos();
        let dir = Point2::new(cal.horizon.0[1], -cal.horizon.0[0]);
        let dir = Point2::new(c * dir.x - s * dir.y, s * dir.x + c * dir.y);
        Line::through_with_direction(cal.vp1, dir).and_then(|h| solve(cal.vp1, h, inputs))
    };
    add(
        turned(spread.horizon_angle_sd_deg),
        turned(-spread.horizon_angle_sd_deg),
    );
    let dof = inputs.len() - 2;
    // More lengths than unknowns: a misfit beyond their noise widens the interval.
    let excess = if dof > 0 {
        (chi2 / dof as f64).max(1.0)
    } else {
        1.0
    };
    let log_sd = (var * excess).sqrt();
    let focal_px = x.exp();
    let Some(camera) = camera_with_focal(cal, focal_px) else {
        return LengthFocalFit::NotIdentified(
            "the fitted focal length gives no camera".to_string(),
        );
    };
    LengthFocalFit::Measured(Box::new(LengthFocal {
        focal_px,
        interval_px: [focal_px * (-log_sd).exp(), focal_px * log_sd.exp()],
        log_sd,
        camera,
        chi2,
        dof,
    }))
}

/// The calibration's focal length before the lengths: value, 68 % interval and source.
#[derive(Debug, Clone, PartialEq)]
pub struct PriorFocal {
    pub focal_px: f64,
    pub interval_px: Option<[f64; 2]>,
    pub source: String,
}

/// The focal length after the lengths: their measurement and the calibration's in one
/// posterior.
#[derive(Debug, Clone, PartialEq)]
pub struct CombinedFocal {
    pub focal_px: f64,
    pub interval_px: [f64; 2],
    /// The lengths' name (`distances`, `markings`), the calibration's source where the lengths
    /// carried too little, or `<name>+<source>` where both carried at least
    /// [`focal::MIN_CARRY_SHARE`] of the information.
    pub source: String,
    /// The lengths' share of the information, 0-1 (0 when they were left out).
    pub lengths_share: f64,
    /// Set when the lengths and the calibration's measured focal length contradict each other
    /// (more than [`focal::CONFLICT_SD`] standard errors of their difference apart): the less
    /// informative is left out, and this says which.
    pub disagreement: Option<String>,
}

/// The name of the calibration's own measured focal length among the cues of [`combine`].
const FOOTAGE: &str = "footage";

/// Half the log width of a 68 % interval: its standard deviation in `ln f`.
fn log_sd_of(interval: [f64; 2]) -> Option<f64> {
    let [lo, hi] = interval;
    (lo.is_finite() && lo > 0.0 && hi > lo).then(|| 0.5 * (hi / lo).ln())
}

/// One focal length from the lengths' `m` (called `name` in the source) and the calibration's
/// `prior`, by the same posterior as the footage's cues ([`focal::fuse`]): the lengths are a
/// log-normal cue, and so is a measured focal length (its interval's half log width). The
/// prior is uniform in `ln f` over `range_px` (the run's `--focal-range` or the 15-90° band),
/// widened to the lengths' own focal length where they lie beyond it and measure `f` better
/// than it: known lengths measure the camera, and the band is a convention about traffic
/// cameras, not a bound on them. An assumed focal length is that prior, not a cue.
///
/// `Err` (why) where the calibration keeps its focal length: a given one (`--focal`), or an
/// assumed one the lengths measure less well than the prior.
pub fn combine(
    m: &LengthFocal,
    prior: &PriorFocal,
    name: &'static str,
    range_px: [f64; 2],
) -> Result<CombinedFocal, String> {
    if prior.source == "given" {
        return Err(format!(
            "the focal length was given (--focal); the lengths alone give {:.0} px (68% \
             {:.0}-{:.0})",
            m.focal_px, m.interval_px[0], m.interval_px[1]
        ));
    }
    let lengths = Cue {
        source: name,
        likelihood: Likelihood::LogNormal {
            focal_px: m.focal_px,
            log_sd: m.log_sd.max(1e-9),
        },
    };
    let footage = prior
        .interval_px
        .and_then(log_sd_of)
        .filter(|_| prior.source != "prior" && prior.focal_px.is_finite() && prior.focal_px > 0.0)
        .map(|log_sd| Cue {
            source: FOOTAGE,
            likelihood: Likelihood::LogNormal {
                focal_px: prior.focal_px,
                log_sd,
            },
        });
    // Lengths that measure f better than the band would, with their peak beyond it, move the
    // band's end to their peak (the prior's soft edge then lets them carry f past it).
    let band_sd = (range_px[1] / range_px[0]).ln() / 12f64.sqrt();
    let range = if m.log_sd < band_sd && m.focal_px.is_finite() {
        [range_px[0].min(m.focal_px), range_px[1].max(m.focal_px)]
    } else {
        range_px
    };
    let cues: Vec<Cue> = std::iter::once(lengths).chain(footage).collect();
    let posterior =
        focal::fuse(range, &cues).ok_or_else(|| format!("invalid focal range {range_px:?}"))?;
    if !posterior.measured {
        return Err(format!(
            "the lengths give {:.0} px but only to 68% {:.0}-{:.0} px, less than the assumed \
             range says",
            m.focal_px, m.interval_px[0], m.interval_px[1]
        ));
    }
    let named = |s: &str| {
        if s == FOOTAGE {
            prior.source.clone()
        } else {
            s.to_string()
        }
    };
    // The lengths first, then the footage's source, as `focal_source` has always read.
    let carried: Vec<String> = [name, FOOTAGE]
        .iter()
        .filter(|s| posterior.carried_by.contains(s))
        .map(|s| named(s))
        .collect();
    let disagreement = posterior
        .cues
        .iter()
        .find(|c| c.contradicts == Some(FOOTAGE) || c.contradicts == Some(name))
        .map(|c| {
            format!(
                "the known lengths give a focal length of {:.0} px (68% {:.0}-{:.0}), the \
                 footage {:.0} px ({}): one of them is wrong, and {} was left out; check the \
                 lengths' pixels, or calibrate with --focal PX if the lens is known",
                m.focal_px,
                m.interval_px[0],
                m.interval_px[1],
                prior.focal_px,
                prior.source,
                if c.source == name {
                    "the less informative, the lengths',"
                } else {
                    "the less informative, the footage's,"
                }
            )
        });
    Ok(CombinedFocal {
        focal_px: posterior.focal_px,
        interval_px: posterior.interval_px,
        source: carried.join("+"),
        lengths_share: posterior.cues[0].share,
        disagreement,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::road::KnownDistance;

    /// A camera 1280x720 with focal `f`, VP1 up the middle, horizon tilted by `roll` rad.
    fn camera(f: f64, roll: f64) -> Calibration {
        let pp = Point2::new(640.0, 360.0);
        let vp1 = Point2::new(700.0, -150.0);
        let dir = Point2::new(roll.cos(), roll.sin());
        let h = Line::through_with_direction(vp1, dir).unwrap();
        with_focal(vp1, h, pp, f).unwrap()
    }

    /// The pixels of road points `a` and `b` (metres, scale `s`) and their distance.
    fn known(cal: &Calibration, s: f64, a: [f64; 2], b: [f64; 2]) -> KnownDistance {
        let p = |q: [f64; 2]| cal.pixel_of_road_point([q[0] / s, q[1] / s]).unwrap();
        KnownDistance {
            p1: p(a),
            p2: p(b),
            distance_m: (a[0] - b[0]).hypot(a[1] - b[1]),
        }
    }

    fn distance(k: KnownDistance) -> ScaleInput {
        ScaleInput {
            kind: RoadMeasure::Distance,
            known: k,
        }
    }

    #[test]
    fn an_along_and_an_across_length_give_the_true_focal_length() {
        for f_true in [700.0, 1400.0, 2600.0] {
            for roll in [0.0, 0.03] {
                let truth = camera(f_true, roll);
                let s = 0.05;
                let base = truth.road_point(Point2::new(640.0, 650.0)).unwrap();
                let o = [base[0] * s, base[1] * s];
                let along = known(&truth, s, o, [o[0] + 12.0, o[1]]);
                let across = known(&truth, s, o, [o[0], o[1] + 3.5]);
                // Start from a wrong focal length: VP1 and the horizon are what carry over.
                let start = camera_with_focal(&truth, f_true * 1.8).unwrap();
                let spread = CameraSpread::floored(None, 1280.0);
                let LengthFocalFit::Measured(fit) = fit_focal_from_lengths(
                    &start,
                    &[distance(along), distance(across)],
                    spread,
                    1280.0,
                ) else {
                    panic!("not identified at f {f_true}");
                };
                assert!(
                    (fit.focal_px / f_true - 1.0).abs() < 1e-4,
                    "{} vs {f_true}",
                    fit.focal_px
                );
                assert!(fit.interval_px[0] < f_true && f_true < fit.interval_px[1]);
                assert!(fit.log_sd > 0.0 && fit.log_sd < 0.5, "{}", fit.log_sd);
            }
        }
    }

    #[test]
    fn a_lane_width_and_a_length_along_fix_the_focal_length() {
        let truth = camera(1100.0, 0.01);
        let s = 0.04;
        let base = truth.road_point(Point2::new(600.0, 600.0)).unwrap();
        let o = [base[0] * s, base[1] * s];
        let along = known(&truth, s, o, [o[0] + 15.0, o[1]]);
        // Two pixels on two lane lines 3.5 m apart, 6 m apart along the road.
        let lane = known(&truth, s, o, [o[0] + 6.0, o[1] + 3.5]);
        let lane = ScaleInput {
            kind: RoadMeasure::LaneWidth,
            known: KnownDistance {
                distance_m: 3.5,
                ..lane
            },
        };
        let start = camera_with_focal(&truth, 2000.0).unwrap();
        let LengthFocalFit::Measured(fit) = fit_focal_from_lengths(
            &start,
            &[distance(along), lane],
            CameraSpread::floored(None, 1280.0),
            1280.0,
        ) else {
            panic!("not identified");
        };
        assert!(
            (fit.focal_px / 1100.0 - 1.0).abs() < 1e-4,
            "{}",
            fit.focal_px
        );
    }

    #[test]
    fn lengths_in_one_direction_do_not_fix_the_focal_length() {
        let truth = camera(1500.0, 0.0);
        let s = 0.05;
        let a = truth.road_point(Point2::new(500.0, 650.0)).unwrap();
        let b = truth.road_point(Point2::new(800.0, 500.0)).unwrap();
        let (a, b) = ([a[0] * s, a[1] * s], [b[0] * s, b[1] * s]);
        let k1 = known(&truth, s, a, [a[0] + 10.0, a[1]]);
        let k2 = known(&truth, s, b, [b[0] + 25.0, b[1]]);
        let fit = fit_focal_from_lengths(
            &truth,
            &[distance(k1), distance(k2)],
            CameraSpread::floored(None, 1280.0),
            1280.0,
        );
        assert!(
            matches!(&fit, LengthFocalFit::NotIdentified(why) if why.contains("one direction")),
            "{fit:?}"
        );
        let one = fit_focal_from_lengths(
            &truth,
            &[distance(k1)],
            CameraSpread::floored(None, 1280.0),
            1280.0,
        );
        assert!(matches!(one, LengthFocalFit::NotIdentified(_)));
    }

    #[test]
    fn a_third_length_that_disagrees_widens_the_interval() {
        let truth = camera(1200.0, 0.0);
        let s = 0.05;
        let base = truth.road_point(Point2::new(640.0, 620.0)).unwrap();
        let o = [base[0] * s, base[1] * s];
        let along = distance(known(&truth, s, o, [o[0] + 12.0, o[1]]));
        let across = distance(known(&truth, s, o, [o[0], o[1] + 3.5]));
        let diag = known(&truth, s, o, [o[0] + 8.0, o[1] + 3.0]);
        let spread = CameraSpread::floored(None, 1280.0);
        let LengthFocalFit::Measured(good) =
            fit_focal_from_lengths(&truth, &[along, across, distance(diag)], spread, 1280.0)
        else {
            panic!()
        };
        let bad = distance(KnownDistance {
            distance_m: diag.distance_m * 1.2,
            ..diag
        });
        let LengthFocalFit::Measured(worse) =
            fit_focal_from_lengths(&truth, &[along, across, bad], spread, 1280.0)
        else {
            panic!()
        };
        assert!((good.focal_px / 1200.0 - 1.0).abs() < 1e-3);
        assert!(
            worse.chi2 > 10.0 * good.chi2.max(1e-9),
            "{} {}",
            worse.chi2,
            good.chi2
        );
        assert!(worse.log_sd > good.log_sd);
    }

    fn measured(f: f64, sd: f64) -> LengthFocal {
        LengthFocal {
            focal_px: f,
            interval_px: [f * (-sd).exp(), f * sd.exp()],
            log_sd: sd,
            camera: camera(f, 0.0),
            chi2: 0.0,
            dof: 0,
        }
    }

    fn prior(f: f64, sd: f64, source: &str) -> PriorFocal {
        PriorFocal {
            focal_px: f,
            interval_px: Some([f * (-sd).exp(), f * sd.exp()]),
            source: source.to_string(),
        }
    }

    /// The 15-90° band of 1280-px frames.
    const BAND: [f64; 2] = [640.0, 4862.0];

    #[test]
    fn the_combination_weighs_each_focal_length_by_its_precision() {
        // Equal precision: the geometric mean, the interval narrower by sqrt(2).
        let c = combine(
            &measured(1000.0, 0.1),
            &prior(1210.0, 0.1, "edgelets"),
            "distances",
            BAND,
        )
        .unwrap();
        assert!((c.focal_px / 1100.0 - 1.0).abs() < 0.002, "{}", c.focal_px);
        assert_eq!(c.source, "distances+edgelets");
        let sd = log_sd_of(c.interval_px).unwrap();
        assert!((sd / (0.1 / 2f64.sqrt()) - 1.0).abs() < 0.03, "{sd}");
        assert!(c.disagreement.is_none());
        // Far more precise lengths that contradict the footage: the footage's is left out.
        let c = combine(
            &measured(1000.0, 0.02),
            &prior(1300.0, 0.05, "edgelets"),
            "distances",
            BAND,
        )
        .unwrap();
        assert_eq!(c.source, "distances");
        assert!((c.focal_px / 1000.0 - 1.0).abs() < 0.002, "{}", c.focal_px);
        assert!(
            c.disagreement
                .as_ref()
                .is_some_and(|d| d.contains("footage's")),
            "4.9 sd apart: {:?}",
            c.disagreement
        );
        let c = combine(
            &measured(1000.0, 0.02),
            &prior(1300.0, 0.2, "edgelets"),
            "distances",
            BAND,
        )
        .unwrap();
        assert!(c.disagreement.is_none(), "1.3 sd apart");
        assert_eq!(c.source, "distances");
        // Far vaguer lengths leave the footage's.
        let c = combine(
            &measured(300.0, 3.0),
            &prior(850.0, 0.2, "edgelets"),
            "distances",
            BAND,
        )
        .unwrap();
        assert_eq!(c.source, "edgelets");
        assert!((c.focal_px / 850.0 - 1.0).abs() < 0.01);
    }

    #[test]
    fn an_assumed_focal_length_gives_way_to_narrower_lengths_and_a_given_one_never() {
        let c = combine(
            &measured(3000.0, 0.05),
            &prior(2646.0, 0.7, "prior"),
            "distances",
            BAND,
        )
        .unwrap();
        assert_eq!(c.source, "distances");
        assert!((c.focal_px / 3000.0 - 1.0).abs() < 0.002, "{}", c.focal_px);
        assert!(combine(
            &measured(3000.0, 1.5),
            &prior(2646.0, 0.7, "prior"),
            "distances",
            BAND
        )
        .is_err());
        assert!(combine(
            &measured(3000.0, 0.01),
            &prior(2646.0, 0.0, "given"),
            "distances",
            BAND
        )
        .is_err());
    }

    #[test]
    fn precise_lengths_carry_the_focal_length_beyond_the_band() {
        // A telephoto narrower than 15°: the band is a convention, the lengths a measurement.
        for source in ["prior", "edgelets"] {
            let c = combine(
                &measured(7000.0, 0.03),
                &prior(4500.0, 0.4, source),
                "distances",
                BAND,
            )
            .unwrap();
            assert!((c.focal_px / 7000.0 - 1.0).abs() < 0.02, "{source}: {c:?}");
            assert_eq!(c.source, "distances");
        }
    }
}
