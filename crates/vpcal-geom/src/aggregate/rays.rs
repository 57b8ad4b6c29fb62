//! The network's VP2 rays: each vehicle's ray from its box centre towards its VP2, against
//! the horizon model.
//!
//! The camera is parametrised by the focal length `f`, the horizon's roll `θ` through VP1 and
//! a constant angular bias `δ` of the rays ([`Vp2Model`]); VP2 is the point of the horizon
//! orthogonal to VP1 for `f`, so every candidate is a valid camera. The rays are one focal
//! source in one of two ways:
//! - **trusted** ([`fit_camera`]) where the VP2 *points* imply the focal length the rays alone
//!   give (a network without the public CNNs' distance bias): VP1, `f` and `θ` are refined
//!   jointly with `δ` fixed at 0, and the bootstrap of that fit is the cue. The loss is then
//!   Geman-McClure (bounded: true outliers add a constant); in the biased regime it is Cauchy (its unbounded tail lets systematically deviating rays still
//!   pull, which measured better on the real CNN outputs: 8.8 / 22 / 9.1 % vs 9.3 / 21 /
//!   9.0 % pooled ratio error for the three public CNNs on BrnoCompSpeed 0-3);
//! - **untrusted** ([`rays_focal_likelihood`]): the rays alone still place VP2 on a horizon,
//!   off by an angle taken as [`RAY_SYSTEMATIC_PER_SCATTER`] times their scatter: a likelihood
//!   of `f` ([`RaysFocal`]). Their own roll (fitted with `f` held and `δ` under its prior)
//!   is weighed against the physical prior on the horizon's angle ([`RaysRoll`]): the rays
//!   barely see the roll (their number says nothing of their common error), so both are
//!   weighed by their measured spreads.

use super::edgelets as edge;
use super::focal::{self, FocalSource, Likelihood};
use super::line_angle_diff;
use super::vehicles::Prepared;
use super::vp1::{from_sphere, homogeneous, sphere, vp1_cost, vp1_of, Vp1Lines, SCALE};
use crate::point::Point2;
use crate::solve::nelder_mead;

/// The horizon model's settings: the fields of the same names of
/// [`RobustOptions`](super::robust::RobustOptions).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct RayOptions {
    pub focal_prior_ratio: f64,
    pub roll_prior_sigma_deg: f64,
    pub ray_bias_prior_sigma_deg: f64,
    pub ray_scale_deg: f64,
    pub prior_weight: f64,
    pub consistency_log_ratio: f64,
}

/// The Geman-McClure loss `r² / (1 + r²)`: quadratic near zero, bounded by 1, so that
/// outliers (wrong rays far from the model) add a constant rather than pulling the fit. Used
/// when the rays are trusted (module docs, step 4); the biased regime uses Cauchy.
fn geman_mcclure(r: f64) -> f64 {
    let r2 = r * r;
    r2 / (1.0 + r2)
}

/// The horizon model: VP1 (finite), pp, and the parameters (ln f, roll, bias).
#[derive(Clone, Copy)]
pub(super) struct Vp2Model<'a> {
    pub vp1: Point2,
    pub pp: Point2,
    pub prep: &'a Prepared,
    pub opts: RayOptions,
    pub f0: f64,
    /// When set, the ray bias is this value rather than a parameter.
    pub fixed_bias: Option<f64>,
    /// When set, `ln f` is this value rather than a parameter (an assumed focal length).
    pub fixed_ln_f: Option<f64>,
}

impl Vp2Model<'_> {
    /// VP2 as a direction from VP1: `VP2 = VP1 + h / u`, returning `(h, u)`.
    pub(super) fn vp2(&self, ln_f: f64, roll: f64) -> (Point2, f64) {
        edge::vp2_direction(self.vp1, self.pp, ln_f, roll)
    }

    pub(super) fn cost(&self, x: &[f64], w: &[f64]) -> f64 {
        let (h, u) = self.vp2(self.fixed_ln_f.unwrap_or(x[0]), x[1]);
        let predicted: Vec<f64> = self
            .prep
            .centre
            .iter()
            .map(|c| {
                let d = (self.vp1 - *c) * u + h;
                d.y.atan2(d.x)
            })
            .collect();
        self.cost_with(x, w, &predicted)
    }

    /// The cost with the predicted ray angles (from the centres towards VP2) given.
    fn cost_with(&self, x: &[f64], w: &[f64], predicted: &[f64]) -> f64 {
        let bias = self.fixed_bias.unwrap_or(x[2]);
        let s = self.opts.ray_scale_deg.to_radians();
        let mut c = 0.0;
        let mut total = 0.0;
        for ((a, p), w) in self.prep.angle2.iter().zip(predicted).zip(w) {
            total += w;
            if *w == 0.0 {
                continue;
            }
            let r = line_angle_diff(a - p - bias) / s;
            c += w * if self.fixed_bias.is_some() {
                geman_mcclure(r)
            } else {
                (1.0 + r * r).ln()
            };
        }
        let k = total * self.opts.prior_weight;
        let b = bias.to_degrees() / self.opts.ray_bias_prior_sigma_deg;
        c + k * 0.5 * b * b
    }

    /// Coarse grid over (ln f, roll, bias) then Nelder-Mead.
    pub(super) fn fit(&self, w: &[f64], start: Option<[f64; 3]>) -> [f64; 3] {
        let x0 = match start {
            Some(s) => s,
            None => {
                let [lo_w, hi_w] = HORIZON_FOCAL_GRID_WIDTHS;
                let lo = (lo_w * self.f0 / self.opts.focal_prior_ratio).max(1.0).ln();
                let hi = (hi_w * self.f0 / self.opts.focal_prior_ratio).ln();
                let roll_max = ROLL_GRID_DEG.to_radians();
                let bias_max = (3.0 * self.opts.ray_bias_prior_sigma_deg)
                    .min(15.0)
                    .to_radians();
                let (n_roll, n_bias) = if self.fixed_bias.is_some() {
                    (21, 1)
                } else {
                    (21, 13)
                };
                let mut best = (f64::INFINITY, [self.f0.ln(), 0.0, 0.0]);
                let mut predicted = vec![0.0; self.prep.centre.len()];
                let n_f = if self.fixed_ln_f.is_some() { 1 } else { 48 };
                for i in 0..n_f {
                    let ln_f = self.fixed_ln_f.unwrap_or(lo + (hi - lo) * i as f64 / 47.0);
                    for j in 0..n_roll {
                        let roll = -roll_max + 2.0 * roll_max * j as f64 / (n_roll - 1) as f64;
                        // The ray directions depend on (f, roll) only; the bias loop reuses them.
                        let (h, u) = self.vp2(ln_f, roll);
                        for (p, c) in predicted.iter_mut().zip(&self.prep.centre) {
                            let d = (self.vp1 - *c) * u + h;
                            *p = d.y.atan2(d.x);
                        }
                        for k in 0..n_bias {
                            let bias = match self.fixed_bias {
                                Some(b) => b,
                                None => -bias_max + 2.0 * bias_max * k as f64 / (n_bias - 1) as f64,
                            };
                            let x = [ln_f, roll, bias];
                            let c = self.cost_with(&x, w, &predicted);
                            if c < best.0 {
                                best = (c, x);
                            }
                        }
                    }
                }
                best.1
            }
        };
        let x = nelder_mead(
            |x| self.cost(x, w),
            &x0,
            &[0.05, 0.2f64.to_radians(), 0.3f64.to_radians()],
            HORIZON_ITERATIONS,
        )
        .x;
        [self.fixed_ln_f.unwrap_or(x[0]), x[1], x[2]]
    }
}

/// The focal length the VP2 *points* imply with VP1 fixed: the weighted median of
/// `-(vp1 - pp)·(vp2_i - pp)` (negative values included, so imaginary pairs do not bias it),
/// square-rooted; `None` when that median is not positive.
pub(super) fn points_focal(prep: &Prepared, w: &[f64], vp1: Point2, pp: Point2) -> Option<f64> {
    let mut v: Vec<(f64, f64)> = prep
        .vp2
        .iter()
        .zip(w)
        .map(|(p, w)| (-(vp1 - pp).dot(*p - pp), *w))
        .filter(|(x, w)| x.is_finite() && *w > 0.0)
        .collect();
    let values: Vec<f64> = v.iter().map(|x| x.0).collect();
    let weights: Vec<f64> = v.drain(..).map(|x| x.1).collect();
    let m = crate::metrics::weighted_median(&values, &weights)?;
    (m > 0.0).then(|| m.sqrt())
}

/// The systematic error of the VP2 that a network's rays give, as a multiple of the rays'
/// scatter around it (their weighted median angle, at least [`RAY_MIN_SCATTER_DEG`]): a
/// network's VP2 error is mostly common to the view, so the rays' agreement is no measure of
/// it, but networks whose rays scatter more also err more. Measured on two sources, the
/// rays' likelihood taken into the focal posterior (`super::focal`):
/// - BrnoCompSpeed sessions 0-3, the three public CNNs' VPout files against
///   `camera_truth.json` (`scripts/focal_coverage.py`; these CNNs put VP2 too near): with 5
///   the rays measured f on 21 of 35 videos, their intervals holding the reference for 57 %
///   (median focal error 20.7 %); with 8 on 12, holding it for 83 % (9.0 %).
/// - The synthetic suite with the bundled network (true boxes, 100 frames; this network puts
///   VP2 too far): at 5 the truth lay 0.6-1.8 standard errors from the rays' posterior,
///   always on the near side; at 8 within about one, and the rays no longer pulled the
///   edgelets' focal length off the truth (synth02 +15 % with 5, +7 % with 8).
pub const RAY_SYSTEMATIC_PER_SCATTER: f64 = 8.0;

/// The scatter below which the rays' systematic error is not taken to shrink, degrees: rays
/// that agree more closely than this still share a common error of about
/// [`RAY_SYSTEMATIC_PER_SCATTER`] times it. Measured with 1° and with 2°:
/// - BrnoCompSpeed sessions 0-3, the public CNNs' VPout (`scripts/focal_coverage.py`): with 1°
///   the rays measured f on 12 of 35 videos and their intervals held the reference on 10;
///   with 2° on 5, holding it on all 5, and the median focal error of all 35 fell from 13.7 %
///   to 11.5 % (pooled ratio error 12.38 / 10.22 / 9.81 % to 11.00 / 10.22 / 8.71 %).
/// - The six synthetic speed scenes (docs/accuracy.md §8; true boxes and the motion
///   detector, the bundled network): its rays scatter 0.5-1.1° and place f 0.99-2.83 times
///   the truth (median 1.6); with 1° they pulled the edgelets' focal length (0.94-1.00 of the
///   truth) to 1.07-1.14 on 7 of 12 calibrations, and 4 of the rays' own intervals held the
///   truth; with 2° the fused focal error's median fell from 10 % to 2.5 %.
/// - Per vehicle, where the bundled network's VP2 rays meet the true horizon depends on the
///   view (docs/accuracy.md §23): on the six speed scenes (VP2 2.9 widths out) at a focal
///   length whose median is 0.92-1.04 of the truth, on the suite's far-VP2 highways (10-19
///   widths) at 0.39-0.55; the rays' own fit then trades the horizon's roll for f. A common
///   error whose sign changes with the view is widened, not corrected.
pub const RAY_MIN_SCATTER_DEG: f64 = 2.0;

/// The error of the horizon's angle that the network's VP2 rays alone give (their own fit:
/// the roll free, VP1 and `f` held, the ray bias under its prior), as a multiple of their
/// scatter ([`RaysFocal::scatter_deg`], at least [`RAY_ROLL_MIN_SCATTER_DEG`]). The rays
/// barely see the roll: turning the horizon about VP1 moves a far VP2 up or down, which
/// turns every ray by nearly the same angle, as a common bias of the rays would. Measured
/// on two sources (`docs/accuracy.md` §27):
/// - BrnoCompSpeed sessions 0-3, the three public CNNs' VPout files against the reference
///   cameras (`vpcal aggregate VPOUT --pp bcs --image-size 1920x1080`, 12 views each): the
///   rays' own roll errs by an rms of 1.40° (median scatter 0.90°), 1.54° (1.63°) and 5.55°
///   (2.56°); with twice the scatter as its standard deviation, 75, 73 and 67 % of the 36
///   views lie within one posterior standard deviation ([`RaysRoll`]) of the truth.
/// - The bundled network: on 20 real clips whose edgelets or curved-road fit set the roll,
///   its rays' own roll lies within one standard deviation (both spreads) of it on 13; on
///   the six synthetic speed scenes and the point-sampled suite's seven straight highways
///   (true boxes) within one of the truth on 10 of 13.
pub const RAY_ROLL_SD_PER_SCATTER: f64 = 2.0;

/// The scatter below which the rays' roll error is not taken to shrink, degrees. With it the
/// three references of [`RAY_ROLL_SD_PER_SCATTER`] hold the truth within one standard
/// deviation 67-77 % of the time; with 1° the real clips' 85 % and the synthetic views' 100 %
/// (too wide), and the best public CNN's median roll error rises from 0.75° to 1.09°.
pub const RAY_ROLL_MIN_SCATTER_DEG: f64 = 0.5;

/// The rays' horizon angle weighed against the physical prior on it (level, standard
/// deviation `prior_sd_deg`): a normal likelihood of the rays' own roll with standard
/// deviation [`RAY_ROLL_SD_PER_SCATTER`] times their scatter. The roll is the posterior's
/// mean, the rays' own pulled towards level by [`RaysRoll::share`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RaysRoll {
    /// The rays' own roll's standard deviation, degrees.
    pub sd_deg: f64,
    pub prior_sd_deg: f64,
}

impl RaysRoll {
    /// The model for rays scattering `scatter_deg` around their own fit; `None` where the
    /// scatter or the prior is not a positive number.
    pub fn of(scatter_deg: f64, prior_sd_deg: f64) -> Option<RaysRoll> {
        let sd_deg = RAY_ROLL_SD_PER_SCATTER * scatter_deg.max(RAY_ROLL_MIN_SCATTER_DEG);
        let finite = scatter_deg.is_finite() && prior_sd_deg.is_finite();
        (finite && prior_sd_deg > 0.0).then_some(RaysRoll {
            sd_deg,
            prior_sd_deg,
        })
    }

    /// The model with the own roll's sampling spread `sampling_sd_deg` (its spread over the
    /// bootstrap's resamples of the vehicles, each with VP1 refitted) added in quadrature:
    /// the horizon runs through VP1, so where VP1 is placed loosely the rays' horizon turns
    /// with it, which their scatter around one fit does not see. Unchanged where the spread
    /// is not a finite number.
    pub fn with_sampling(self, sampling_sd_deg: f64) -> RaysRoll {
        if !sampling_sd_deg.is_finite() {
            return self;
        }
        RaysRoll {
            sd_deg: self.sd_deg.hypot(sampling_sd_deg),
            ..self
        }
    }

    /// The rays' share of the roll: their precision over the posterior's.
    pub fn share(&self) -> f64 {
        let (r, p) = (self.sd_deg.powi(-2), self.prior_sd_deg.powi(-2));
        r / (r + p)
    }

    /// The posterior's roll (radians) for the rays' own `roll` (radians).
    pub fn roll(&self, roll: f64) -> f64 {
        self.share() * roll
    }

    /// The posterior's standard deviation, degrees.
    pub fn sd_after_deg(&self) -> f64 {
        (self.sd_deg.powi(-2) + self.prior_sd_deg.powi(-2))
            .sqrt()
            .recip()
    }
}

/// The focal length's distribution given the network's VP2 rays and the physical prior:
/// [`rays_focal_likelihood`] within the prior uniform in `ln f` over `range_px`. Returns the
/// 16th, 50th and 84th percentiles, pixels; `None` when the rays' fit is not finite.
pub fn rays_focal_posterior(
    vp1: Point2,
    pp: Point2,
    range_px: [f64; 2],
    rays: [f64; 2],
    sd_deg: f64,
) -> Option<[f64; 3]> {
    let l = rays_focal_likelihood(vp1, pp, focal::support(range_px), rays, sd_deg)?;
    focal::alone(range_px, &l)
}

/// What the network's VP2 rays say about the focal length: `(ln f, roll)` is what the rays
/// alone fit (with VP1 at `vp1`), `sd_deg` the systematic error of the VP2 they place. For a
/// candidate `f`, the VP2 orthogonal to VP1 on the rays' horizon is compared with the rays'
/// VP2 as directions seen through a lens of that focal length; the likelihood is Gaussian in
/// that angle, tabulated over `range_px` (`[short, long]` focal lengths, pixels). `None` when
/// the rays' fit is not finite.
///
/// The angle, not `ln f`, carries the error because a network errs by angles: a VP2 far
/// along the horizon moves a long way for a small angle, so the same rays say little about f
/// there (a telephoto view) and much where VP2 is near (a wide view).
pub fn rays_focal_likelihood(
    vp1: Point2,
    pp: Point2,
    range_px: [f64; 2],
    rays: [f64; 2],
    sd_deg: f64,
) -> Option<Likelihood> {
    let [ln_fr, roll] = rays;
    let [short, long] = range_px;
    if !(ln_fr.is_finite() && roll.is_finite() && sd_deg > 0.0 && 0.0 < short && short < long) {
        return None;
    }
    let v = vp1 - pp;
    // VP2 = VP1 + h / u, seen as a direction through a lens of focal length f.
    let direction = |(h, u): (Point2, f64), f: f64| {
        let p = v * u + h;
        [p.x, p.y, u * f]
    };
    let angle = |a: [f64; 3], b: [f64; 3]| {
        let dot = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
        let na = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
        let nb = (b[0] * b[0] + b[1] * b[1] + b[2] * b[2]).sqrt();
        (dot.abs() / (na * nb)).min(1.0).acos()
    };
    let rays_vp2 = edge::vp2_direction(vp1, pp, ln_fr, roll);
    let (lo, hi) = (short.ln(), long.ln());
    let s = sd_deg.to_radians();
    let ln_f: Vec<f64> = (0..=focal::GRID)
        .map(|i| lo + (hi - lo) * i as f64 / focal::GRID as f64)
        .collect();
    let log_lik: Vec<f64> = ln_f
        .iter()
        .map(|&ln_f| {
            let f = ln_f.exp();
            let here = edge::vp2_direction(vp1, pp, ln_f, roll);
            let d = angle(direction(rays_vp2, f), direction(here, f)) / s;
            -0.5 * d * d
        })
        .collect();
    log_lik
        .iter()
        .all(|l| l.is_finite())
        .then(|| Likelihood::Table {
            ln_f,
            log_lik,
            own_px: ln_fr.exp(),
        })
}

/// What the VP2 rays alone say about the focal length.
#[derive(Debug, Clone)]
pub(super) struct RaysFocal {
    /// Their own fit, `(ln f, roll)`.
    pub fit: [f64; 2],
    /// The weighted median angle of the rays around that fit, and the systematic error
    /// taken for their VP2 from it, degrees.
    pub scatter_deg: f64,
    pub sd_deg: f64,
    /// Their likelihood of `ln f` ([`rays_focal_likelihood`], tabulated over all of the
    /// focal posterior's grid, past the band's soft edges), and its percentiles with the
    /// prior alone ([`rays_focal_posterior`]).
    pub likelihood: Option<Likelihood>,
    pub posterior: Option<[f64; 3]>,
}

/// The untrusted rays' likelihood ([`rays_focal_likelihood`]).
impl FocalSource for RaysFocal {
    fn name(&self) -> &'static str {
        "network_rays"
    }

    fn likelihood(&self) -> Option<Likelihood> {
        self.likelihood.clone()
    }
}

/// What the VP2 rays alone say about the focal length under `model` (its VP1, no priors, no
/// ray bias).
pub(super) fn rays_focal(model: &Vp2Model, w: &[f64], range_px: [f64; 2]) -> RaysFocal {
    let free = Vp2Model {
        fixed_bias: Some(0.0),
        fixed_ln_f: None,
        ..*model
    };
    let x = free.fit(w, None);
    let scatter = scatter_deg(&free, x, w);
    let sd = RAY_SYSTEMATIC_PER_SCATTER * scatter.max(RAY_MIN_SCATTER_DEG);
    let support = focal::support(range_px);
    let likelihood = scatter
        .is_finite()
        .then(|| rays_focal_likelihood(model.vp1, model.pp, support, [x[0], x[1]], sd))
        .flatten();
    let posterior = likelihood.as_ref().and_then(|l| focal::alone(range_px, l));
    RaysFocal {
        fit: [x[0], x[1]],
        scatter_deg: scatter,
        sd_deg: sd,
        likelihood,
        posterior,
    }
}

/// The weighted median angle (degrees) of the rays (weights `w`) around the VP2 of `model`
/// at `x` (`ln f`, roll); NaN without rays.
fn scatter_deg(model: &Vp2Model, x: [f64; 3], w: &[f64]) -> f64 {
    let (h, u) = model.vp2(x[0], x[1]);
    let (angles, weights): (Vec<f64>, Vec<f64>) = model
        .prep
        .centre
        .iter()
        .zip(&model.prep.angle2)
        .zip(w)
        .filter(|(_, w)| **w > 0.0)
        .map(|((c, a), w)| {
            let d = (model.vp1 - *c) * u + h;
            (line_angle_diff(a - d.y.atan2(d.x)).abs().to_degrees(), *w)
        })
        .unzip();
    crate::metrics::weighted_median(&angles, &weights).unwrap_or(f64::NAN)
}

/// The camera the rays fit ([`fit_camera`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct RaysCamera {
    /// VP1 (refined where the rays are trusted).
    pub vp1: Point2,
    /// `ln f`, the roll (radians) and the rays' bias (radians).
    pub x: [f64; 3],
    pub trusted: bool,
    /// Where they are not trusted: their own roll (radians, before its prior) and its model.
    pub own_roll: Option<(f64, RaysRoll)>,
}

/// Fit (ln f, roll, bias) for `model` with vehicle weights `w` (`w1` for the VP1 lines);
/// returns VP1 (refined when the rays are trusted), the parameters, whether the rays were
/// trusted and, where not, their own roll and its model ([`RaysCamera`]).
///
/// When the VP2 *points* agree with what the VP2 rays alone say (a network without the
/// distance bias of the public CNNs), the data are trusted: the ray bias is fixed at zero and
/// VP1, f and the roll are refined jointly, without priors, on the VP1 lines and VP2 rays. Real CNNs that put VP2 far too close fail this check; then the
/// focal length is held at `model.f0` (the prior's median, or the rays' posterior median
/// once [`rays_focal`] measured it; not fitted here: with a free ray bias the rays' pull on
/// `f` made it worse both on the public CNNs' BrnoCompSpeed outputs and on the synthetic
/// demo) and the roll is fitted freely, the ray bias under its prior (the roll's physical
/// prior is weighed in afterwards: [`RaysRoll`]).
pub(super) fn fit_camera(
    model: &Vp2Model,
    vp1_lines: &Vp1Lines,
    w1: &[f64],
    w: &[f64],
    start: Option<[f64; 3]>,
) -> RaysCamera {
    let unbiased = Vp2Model {
        fixed_bias: Some(0.0),
        ..*model
    };
    let x_rays = unbiased.fit(w, start.map(|s| [s[0], s[1], 0.0]));
    let f_points = points_focal(model.prep, w, model.vp1, model.pp);
    let trusted =
        f_points.is_some_and(|fp| (fp.ln() - x_rays[0]).abs() < model.opts.consistency_log_ratio);
    let assumed = Vp2Model {
        fixed_ln_f: Some(model.f0.ln()),
        ..*model
    };
    // Untrusted: f held, the roll free, then weighed against its prior.
    let untrusted = || {
        let mut x = assumed.fit(w, start);
        let scatter = scatter_deg(&unbiased, x_rays, w);
        let own_roll = RaysRoll::of(scatter, model.opts.roll_prior_sigma_deg).map(|rr| {
            let own = x[1];
            x[1] = rr.roll(own);
            (own, rr)
        });
        RaysCamera {
            vp1: model.vp1,
            x,
            trusted: false,
            own_roll,
        }
    };
    if !trusted {
        return untrusted();
    }
    let s1 = vp1_lines.threshold_deg.to_radians().sin();
    let q1 = from_sphere(homogeneous(model.vp1));
    let joint = |p: &[f64]| {
        let sp = sphere([p[0], p[1]]);
        if sp[2] <= 1e-9 {
            return f64::INFINITY;
        }
        let vp1 = Point2::new(sp[0] / sp[2] * SCALE, sp[1] / sp[2] * SCALE);
        let m = Vp2Model { vp1, ..unbiased };
        vp1_cost([p[0], p[1]], vp1_lines.lines(), w1, s1) + m.cost(&[p[2], p[3], 0.0], w)
    };
    let p = nelder_mead(
        joint,
        &[q1[0], q1[1], x_rays[0], x_rays[1]],
        &[0.002, 0.002, 0.02, 0.1f64.to_radians()],
        JOINT_ITERATIONS,
    )
    .x;
    match vp1_of(sphere([p[0], p[1]])) {
        Some(vp1) => RaysCamera {
            vp1,
            x: [p[2], p[3], 0.0],
            trusted: true,
            own_roll: None,
        },
        None => untrusted(),
    }
}

/// Nelder-Mead budgets of the horizon model (ln f, roll, ray bias: 3 parameters) and of VP1
/// with the horizon jointly (4).
const HORIZON_ITERATIONS: usize = 400;
const JOINT_ITERATIONS: usize = 600;

/// The horizon's angles the horizon model's grid spans, degrees either side of level: beyond
/// any traffic camera's (the roll prior's sources reach 4.9°:
/// [`RobustOptions::roll_prior_sigma_deg`](super::robust::RobustOptions::roll_prior_sigma_deg)).
const ROLL_GRID_DEG: f64 = 10.0;

/// Focal lengths the horizon model's grid spans, in image widths: 0.15 (a 147° view) to 15 (a
/// 4° view), beyond the physical range of traffic cameras so that the VP2 evidence (or the
/// prior), not the grid, bounds the fit.
const HORIZON_FOCAL_GRID_WIDTHS: [f64; 2] = [0.15, 15.0];
