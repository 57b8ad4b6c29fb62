//! The scene's vertical lines (poles, posts, walls, tree trunks) as a focal cue.
//!
//! Lines that stand vertical in the world meet in the image at VP3, the road normal's
//! vanishing point. With VP1 and the horizon through it (its angle, the roll), VP3 lies on the
//! normal from the principal point to the horizon at `f² / d` beyond the principal point (`d`
//! its distance from the horizon), so VP3 measures `f` without VP2, which on views along the
//! road lies too far for the vehicles' edges to place it (docs/accuracy.md §24).
//!
//! The evidence is the scene's straight line segments ([`Segment`]: found in the background
//! picture, `vpcal_video::segments`): long ones, since poles are long and clutter (leaves,
//! grass, the road's texture) is not. Those that point at VP1 (lines along the road) or run
//! near the horizon's direction cannot be verticals and are left out. The fit is the most
//! likely (`ln f`, roll) under a likelihood of the segments' directions and a prior on the
//! roll: each segment points at VP3 to within its angle's uncertainty (one pixel over its
//! length, at least [`VerticalOptions::min_angle_sd_deg`]) or is clutter
//! ([`CLUTTER_DENSITY`]); the roll is Gaussian around the road horizon's, with that horizon's own
//! spread and the road's cross slope ([`VerticalOptions::cross_slope_roll_sd_deg`]: the
//! verticals stand plumb, the road's normal leans with its cross slope). Many verticals pin
//! VP3 in the picture and the roll with it; a few only tell a combination of `f` and the roll,
//! and the roll's prior then decides where on that ridge `f` lies. A maximum, not a
//! least-squares fit: most segments are not verticals, and the verticals' own VP3 is a peak
//! among them. A peak at the search's end of `ln f`, carried by fewer than
//! [`VerticalOptions::min_supporting`] segments, whose profile does not fall by
//! [`IDENTIFIED_DROP`] at half and twice its `f` (a far VP3: nearly parallel verticals bound
//! `f` on one side only), or no more likely than the same segments pointing anywhere
//! ([`VerticalOptions::null_draws`]) is not identified. The segments' bootstrap,
//! each resample with its own draw of the roll's prior centre, gives the spread (the ridge's
//! too); [`VERTICALS_MODEL_LOG_SD`] its model error.

use super::focal::{bootstrap_log_sd, FocalSource, Likelihood};
use super::line_angle_diff;
use crate::point::Point2;
use crate::solve::{half_p16_p84, par_map, percentile, SplitMix};

/// A straight line segment of the picture, between two ends, frame pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Segment {
    pub a: Point2,
    pub b: Point2,
}

impl Segment {
    pub fn length(&self) -> f64 {
        (self.b - self.a).norm()
    }

    pub fn middle(&self) -> Point2 {
        (self.a + self.b) * 0.5
    }

    /// Its direction, radians (undirected).
    pub fn angle(&self) -> f64 {
        let d = self.b - self.a;
        d.y.atan2(d.x)
    }
}

/// The vertical lines' model error, standard deviation in `ln f`, in quadrature with the
/// segments' bootstrap: given the true VP1 and horizon (`scripts/scene_verticals_focal.py`),
/// the identified fits' errors have an rms of 0.108 in `ln f` on the BrnoCompSpeed views of
/// sessions 0-3 (real, 1080p, against the reference cameras, whose own focal lengths are
/// fitted to taped distances; 8 of 12 identified) and 0.006 on the synthetic suite (9 of 14):
/// the real views' rms, rounded up with a margin for VP1 and horizon errors, which that
/// measurement leaves out. Trees lean, posts are not plumb, a view's few poles may all stand
/// on one side, and a road's grade tilts VP1 off gravity's horizon.
pub const VERTICALS_MODEL_LOG_SD: f64 = 0.14;

/// Settings of [`fit`].
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct VerticalOptions {
    /// Segments whose line passes within this angle of VP1 are taken for lines along the
    /// road, degrees. VP1 is placed to a few degrees: on BrnoCompSpeed two of the public
    /// CNNs' VP1 for session 3 right lie 140 px (about 8° as seen from the road) from the
    /// reference, and with a 5° cut the road's kerb line passed as a vertical and carried
    /// `f` to twice the truth. A vertical within 10° of VP1's direction lies near the line
    /// through VP1 and VP3 and turns by little with `f` (its angle to VP3 is about that to
    /// VP1 times VP1's distance over VP3's), so the cut loses little.
    pub vp1_exclusion_deg: f64,
    /// Segments whose line passes within this angle of the searched camera's VP2 are taken
    /// for lines across the road (stop lines, a crossing's stripes, a side road), degrees:
    /// on a view down onto a junction they otherwise meet at a false VP3 (the synthetic
    /// suite's synth11: 371 px for 700).
    pub vp2_exclusion_deg: f64,
    /// Segments within this angle of the horizon's direction cannot point at VP3, degrees.
    pub horizon_exclusion_deg: f64,
    /// The farthest the verticals' roll is searched from the road horizon's, degrees (the
    /// search spans four standard deviations of the roll's prior, at most this).
    pub roll_window_deg: f64,
    /// The spread of the verticals' roll about the road horizon's from the road's cross
    /// slope, degrees: plumb lines meet at gravity's VP3, the road's horizon is that of its
    /// surface, and a carriageway falls 2-2.5 % to its side (1.1-1.4°; more on a banked
    /// curve). Added in quadrature to the horizon's own spread.
    pub cross_slope_roll_sd_deg: f64,
    /// The least angle uncertainty of a segment, degrees (a long segment's one pixel over
    /// its length is smaller than what makes a pole not quite plumb).
    pub min_angle_sd_deg: f64,
    /// The fewest segments within two of their uncertainties of the peak's VP3.
    pub min_supporting: usize,
    /// Resamples of the segments for the spread.
    pub bootstrap: usize,
    /// Draws of the segments with random directions: the verticals are identified only
    /// where their peak is more likely than every draw's (19: chance alone does as well at
    /// most one time in twenty). A view without verticals (a junction seen from above) still
    /// has segments that meet somewhere; this tells them from poles.
    pub null_draws: usize,
    /// How far either side of the road horizon's roll the verticals' own roll (with no
    /// prior: [`VerticalsFit::own_roll`]) is searched, degrees.
    pub own_roll_window_deg: f64,
}

/// [`VerticalOptions::own_roll_window_deg`]'s default: beyond any road's cross slope and
/// the road horizon's error where the vehicles' cues mislead (a road that climbs as it
/// curves: 9° on a real clip, docs/accuracy.md §30).
pub const OWN_ROLL_WINDOW_DEG: f64 = 15.0;

/// The verticals' own roll is identified where their likelihood, maximised over `f`, falls by
/// [`IDENTIFIED_DROP`] this far either side of its peak, degrees.
pub const OWN_ROLL_PROBE_DEG: f64 = 3.0;

impl Default for VerticalOptions {
    fn default() -> VerticalOptions {
        VerticalOptions {
            vp1_exclusion_deg: 10.0,
            vp2_exclusion_deg: 10.0,
            horizon_exclusion_deg: 20.0,
            roll_window_deg: 8.0,
            cross_slope_roll_sd_deg: 1.5,
            min_angle_sd_deg: 0.5,
            min_supporting: 4,
            bootstrap: 30,
            null_draws: 19,
            own_roll_window_deg: OWN_ROLL_WINDOW_DEG,
        }
    }
}

/// What the vertical lines say.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VerticalsFit {
    /// The focal length at the peak, pixels.
    pub focal_px: f64,
    /// The verticals' roll at the peak, radians.
    pub roll: f64,
    /// Segments that could be verticals (not along the road, not along the horizon).
    pub candidates: usize,
    /// Segments within two of their uncertainties of the peak's VP3.
    pub supporting: usize,
    /// The bootstrap's 16th and 84th percentiles of the focal length, pixels.
    pub bootstrap_px: [f64; 2],
    /// Whether the peak is inside the search, stands out ([`IDENTIFIED_DROP`]), is carried
    /// by enough segments and is more likely than chance ([`VerticalOptions::null_draws`]).
    pub identified: bool,
    /// The verticals' own roll, radians, with no prior from the road (gravity's horizon:
    /// plumb lines meet at gravity's VP3): where the segments identify it
    /// ([`OWN_ROLL_PROBE_DEG`], [`VerticalOptions::min_supporting`] distinct lines
    /// ([`distinct_lines`]) pointing at its VP3, and where it lies beyond
    /// [`HORIZON_CONFLICT_Z`] of the road horizon's prior, more likely than every one of the
    /// chance draws [`VerticalOptions::null_draws`] searched as widely), else `None`.
    pub own_roll: Option<f64>,
    /// The spread of `own_roll` over the segments' resamples, radians (half the 16th-84th
    /// percentile range); NaN without resamples, and where `own_roll` lies within
    /// [`HORIZON_CONFLICT_Z`] of the road horizon's prior without it (its spread could only
    /// lower the contradiction, so it is not measured).
    pub own_roll_sd: f64,
}

/// The verticals' own roll contradicts the road horizon's where they differ by more than this
/// many standard deviations (the horizon's spread, the road's cross slope
/// [`VerticalOptions::cross_slope_roll_sd_deg`] and the own roll's resample spread, in
/// quadrature). Measured (docs/accuracy.md §30): on the twelve BrnoCompSpeed views against
/// their reference cameras the identified own rolls lie within 1.5 of these units (+1.8 to
/// +2.2° on three views of one road: its cross slope), on the rendered suite within 0.5, and on
/// the real clips within 2.3 but one: a road that climbs as it curves, whose vehicles put the
/// horizon 8.8° off the plumb lines (5.4). Four is beyond what a normal's tail gives one
/// clip in ten thousand.
pub const HORIZON_CONFLICT_Z: f64 = 4.0;

impl VerticalsFit {
    /// How far the verticals' own roll lies from the road horizon's `roll` (radians, its
    /// standard deviation `roll_sd`), in standard deviations ([`HORIZON_CONFLICT_Z`]'s), with
    /// the difference (radians, line angles); `None` where the own roll is not identified.
    pub fn against_horizon(
        &self,
        roll: f64,
        roll_sd: f64,
        opts: &VerticalOptions,
    ) -> Option<(f64, f64)> {
        let own = self.own_roll?;
        let d = line_angle_diff(own - roll);
        let own_sd = if self.own_roll_sd.is_finite() {
            self.own_roll_sd
        } else {
            0.0
        };
        let sd = roll_sd
            .hypot(opts.cross_slope_roll_sd_deg.to_radians())
            .hypot(own_sd);
        Some((d / sd, d)).filter(|(z, _)| z.is_finite())
    }
}

impl FocalSource for VerticalsFit {
    fn name(&self) -> &'static str {
        "verticals"
    }

    fn likelihood(&self) -> Option<Likelihood> {
        if !self.identified {
            return None;
        }
        let b = bootstrap_log_sd(self.bootstrap_px);
        Some(Likelihood::LogNormal {
            focal_px: self.focal_px,
            log_sd: (b * b + VERTICALS_MODEL_LOG_SD * VERTICALS_MODEL_LOG_SD).sqrt(),
        })
    }
}

/// A candidate segment: its middle, direction, weight (length) and angle uncertainty.
#[derive(Debug, Clone, Copy)]
struct Candidate {
    at: Point2,
    angle: f64,
    weight: f64,
    sd: f64,
}

/// The horizon as VP3 sees it: the unit normal `n` from the horizon towards the principal
/// point and the principal point's distance `d` from the horizon (VP3 = pp + n·f²/d).
#[derive(Debug, Clone, Copy)]
struct Horizon {
    n: Point2,
    d: f64,
}

/// The horizon through VP1 at angle `roll`, seen from the principal point.
fn horizon(vp1: Point2, pp: Point2, roll: f64) -> Horizon {
    let normal = Point2::new(-roll.sin(), roll.cos());
    let d = (pp - vp1).dot(normal);
    if d < 0.0 {
        Horizon {
            n: normal * -1.0,
            d: -d,
        }
    } else {
        Horizon { n: normal, d }
    }
}

/// The direction (not normalised) from `p` to VP3 for `f²`: `d·(pp − p) + f²·n`, which is
/// VP3 − p times `d` (finite also where the horizon passes through pp and the verticals are
/// parallel, along `n`).
fn towards_vp3(p: Point2, pp: Point2, h: Horizon, f2: f64) -> Point2 {
    (pp - p) * h.d + h.n * f2
}

/// The density of clutter (a segment that is no vertical) over that of a vertical pointing
/// straight at VP3: each segment's likelihood is `exp(-r²/2) + CLUTTER_DENSITY` in its miss
/// `r` (in its angle's uncertainties). At 1 the log-likelihood is nearly the segments'
/// length-weighted vote for VP3 (`ln(1 + x) ≈ x`): long segments pointing precisely at it
/// win over many that only pass near it. A lower clutter density rewards the count of
/// segments near VP3 over their precision, and the slanted outlines of the renders' tree
/// crowns then outvoted their posts (highway_s5 of the speed scenes: f 537 px for 1000 at a
/// floor of `exp(-2)`; the suite's rms error 0.086 against 0.045 at 1, the BrnoCompSpeed
/// views' 0.136 against 0.132).
pub const CLUTTER_DENSITY: f64 = 1.0;

/// The log-likelihood of the candidates' directions on camera `at`, weighted by each
/// segment's length over the candidates' mean (a long pole says more than a short edge; the
/// total weight is the number of segments): [`CLUTTER_DENSITY`]; a segment pointing at the
/// camera's VP2 is clutter.
fn log_likelihood(c: &[Candidate], at: Hypothesis) -> f64 {
    c.iter()
        .map(|c| match at.miss(c) {
            Some(r) => c.weight * ((-0.5 * r * r).exp() + CLUTTER_DENSITY).ln(),
            None => c.weight * CLUTTER_DENSITY.ln(),
        })
        .sum()
}

/// A camera the segments are weighed on: VP1, the principal point, `f²`, the roll, and how
/// near VP2's direction a segment is taken for a line across the road (radians).
#[derive(Debug, Clone, Copy)]
struct Hypothesis {
    vp1: Point2,
    pp: Point2,
    f2: f64,
    roll: f64,
    vp2_cut: f64,
}

/// What the cameras searched share: VP1, the principal point and the VP2 cut (radians).
#[derive(Debug, Clone, Copy)]
struct Frame {
    vp1: Point2,
    pp: Point2,
    vp2_cut: f64,
}

impl Frame {
    fn at(&self, ln_f: f64, roll: f64) -> Hypothesis {
        Hypothesis {
            vp1: self.vp1,
            pp: self.pp,
            f2: (2.0 * ln_f).exp(),
            roll,
            vp2_cut: self.vp2_cut,
        }
    }
}

impl Hypothesis {
    /// How far candidate `c` misses VP3, in its angle's uncertainties; `None` where it
    /// points at this camera's VP2 (a line across the road: a stop line, a crossing's
    /// stripe, a side road's edge), which no vertical does.
    fn miss(&self, c: &Candidate) -> Option<f64> {
        let to2 = towards_vp2(c.at, self.vp1, self.pp, self.roll, self.f2);
        if line_angle_diff(c.angle - to2.y.atan2(to2.x)).abs() < self.vp2_cut {
            return None;
        }
        let h = horizon(self.vp1, self.pp, self.roll);
        let t = towards_vp3(c.at, self.pp, h, self.f2);
        Some(line_angle_diff(c.angle - t.y.atan2(t.x)) / c.sd)
    }
}

/// The direction (not normalised, either sign) from `p` to VP2 on the horizon through `vp1`
/// at angle `roll` for `f²`: VP2 = VP1 + t·u with `(VP1 − pp)·(VP2 − pp) = −f²`, scaled by
/// `(VP1 − pp)·u` (finite where VP2 lies at infinity, along `u`).
fn towards_vp2(p: Point2, vp1: Point2, pp: Point2, roll: f64, f2: f64) -> Point2 {
    let u = Point2::new(roll.cos(), roll.sin());
    let a = vp1 - pp;
    (vp1 - p) * a.dot(u) - u * (f2 + a.dot(a))
}

/// The roll's prior: Gaussian around `centre` with standard deviation `sd` (radians).
#[derive(Debug, Clone, Copy)]
struct RollPrior {
    centre: f64,
    sd: f64,
}

impl RollPrior {
    fn log_density(&self, roll: f64) -> f64 {
        if self.sd.is_infinite() {
            return 0.0;
        }
        let z = (roll - self.centre) / self.sd;
        -0.5 * z * z
    }

    /// No prior: every roll within the search's window alike, the window centred on `centre`.
    fn flat(centre: f64) -> RollPrior {
        RollPrior {
            centre,
            sd: f64::INFINITY,
        }
    }
}

/// `n` evenly spaced values from `lo` to `hi`.
fn grid(lo: f64, hi: f64, n: usize) -> Vec<f64> {
    (0..n)
        .map(|i| lo + (hi - lo) * i as f64 / (n - 1).max(1) as f64)
        .collect()
}

/// The best (score, `ln f`, roll) over the grid `fs` × `rolls`: [`log_likelihood`] plus the
/// roll's `prior`.
fn best_over(
    c: &[Candidate],
    frame: Frame,
    fs: &[f64],
    rolls: &[f64],
    prior: RollPrior,
) -> (f64, f64, f64) {
    let mut best = (f64::NEG_INFINITY, fs[0], rolls[0]);
    for &r in rolls {
        let p = prior.log_density(r);
        for &lf in fs {
            let s = log_likelihood(c, frame.at(lf, r)) + p;
            if s > best.0 {
                best = (s, lf, r);
            }
        }
    }
    best
}

/// The best (score, `ln f`, roll) over `ln f` in `ln_range` (`[lf, lf]` for one value of the
/// profile) and the roll within `window` of the prior's centre: a coarse grid, then a fine
/// one around its best.
fn search(
    c: &[Candidate],
    frame: Frame,
    ln_range: [f64; 2],
    prior: RollPrior,
    window: f64,
) -> (f64, f64, f64) {
    let [lo, hi] = ln_range;
    let roll0 = prior.centre;
    let coarse_steps = if hi > lo {
        ((hi - lo) / 0.04).ceil() as usize + 1
    } else {
        1
    };
    let roll_steps = (2.0 * window / 0.5_f64.to_radians()).ceil() as usize + 1;
    let (_, lf, r) = best_over(
        c,
        frame,
        &grid(lo, hi, coarse_steps.max(1)),
        &grid(roll0 - window, roll0 + window, roll_steps.max(1)),
        prior,
    );
    let fine_f = if hi > lo {
        grid((lf - 0.04).max(lo), (lf + 0.04).min(hi), 17)
    } else {
        vec![lf]
    };
    let fine_r = grid(
        (r - 0.5_f64.to_radians()).max(roll0 - window),
        (r + 0.5_f64.to_radians()).min(roll0 + window),
        11,
    );
    best_over(c, frame, &fine_f, &fine_r, prior)
}

/// The maximum of [`log_likelihood`] and the roll's `prior` over `ln f` in `ln_range` and
/// the roll within `window` of the prior's centre. Returns `(ln f, roll)`.
fn peak(
    c: &[Candidate],
    frame: Frame,
    ln_range: [f64; 2],
    prior: RollPrior,
    window: f64,
) -> (f64, f64) {
    let (_, lf, r) = search(c, frame, ln_range, prior, window);
    (lf, r)
}

/// Segments whose lines towards VP3 lie closer than this share of the frame's width are one
/// line ([`distinct_lines`]): a pole's two edges and its pieces, a few pixels apart, count
/// once; two poles of a view seldom stand so close.
pub const DISTINCT_LINE_WIDTHS: f64 = 0.02;

/// How many distinct lines towards `at`'s VP3 the segments `c` lie on: taken longest first,
/// a segment starts a new line where its middle lies farther than [`DISTINCT_LINE_WIDTHS`]
/// of `width` (pixels) from every line started so far. The own roll needs several: with a
/// free roll, any two lines meet at some VP3 (a rendered curve's one pole and one lane dash,
/// five segments, put the own roll 14° off).
fn distinct_lines(c: &[Candidate], at: Hypothesis, width: f64) -> usize {
    let h = horizon(at.vp1, at.pp, at.roll);
    let mut sorted = c.to_vec();
    sorted.sort_by(|a, b| b.weight.total_cmp(&a.weight));
    let mut lines: Vec<(Point2, Point2)> = vec![];
    for s in sorted {
        let apart = |(q, t): &(Point2, Point2)| {
            let d = s.at - *q;
            (d.x * t.y - d.y * t.x).abs() / t.norm() > DISTINCT_LINE_WIDTHS * width
        };
        if lines.iter().all(apart) {
            lines.push((s.at, towards_vp3(s.at, at.pp, h, at.f2)));
        }
    }
    lines.len()
}

/// How much less likely (natural log) the segments must be with the focal length halved and
/// doubled (within the search) than at their peak for `f` to be identified: a flat
/// likelihood (parallel verticals of a level camera, a ridge no prior cuts) has its maximum
/// anywhere. One nat is about one and a half segments pointing straight at VP3.
pub const IDENTIFIED_DROP: f64 = 1.0;

/// The focal length from the `segments` given VP1 (finite), the principal point, the road
/// horizon's angle `roll` and its standard deviation `roll_sd` (radians; 0 where unknown),
/// and the search range `range_px` (pixels); `None` where no segment could be a vertical.
#[allow(clippy::too_many_arguments)]
pub fn fit(
    segments: &[Segment],
    vp1: Point2,
    pp: Point2,
    roll: f64,
    roll_sd: f64,
    range_px: [f64; 2],
    opts: &VerticalOptions,
    seed: u64,
) -> Option<VerticalsFit> {
    if !(vp1.is_finite() && pp.is_finite() && roll.is_finite()) {
        return None;
    }
    let ln_range = [range_px[0].ln(), range_px[1].ln()];
    if !(ln_range[0].is_finite() && ln_range[1].is_finite() && ln_range[1] > ln_range[0]) {
        return None;
    }
    let (vp1_cut, horizon_cut) = (
        opts.vp1_exclusion_deg.to_radians(),
        opts.horizon_exclusion_deg.to_radians(),
    );
    // A direction at `at` that could be a vertical's: not towards VP1 (a line along the
    // road), not along the horizon.
    let admissible = |at: Point2, angle: f64| {
        let to_vp1 = vp1 - at;
        let along_road = line_angle_diff(angle - to_vp1.y.atan2(to_vp1.x)).abs() < vp1_cut;
        let along_horizon = line_angle_diff(angle - roll).abs() < horizon_cut;
        !along_road && !along_horizon
    };
    let candidates: Vec<Candidate> = segments
        .iter()
        .filter_map(|s| {
            let (at, angle, length) = (s.middle(), s.angle(), s.length());
            (length > 0.0 && at.is_finite() && admissible(at, angle)).then(|| Candidate {
                at,
                angle,
                weight: length,
                sd: (1.0 / length)
                    .atan()
                    .max(opts.min_angle_sd_deg.to_radians()),
            })
        })
        .collect();
    if candidates.is_empty() {
        return None;
    }
    // Lengths over their mean: the total weight is the number of segments.
    let mean_length = candidates.iter().map(|c| c.weight).sum::<f64>() / candidates.len() as f64;
    let candidates: Vec<Candidate> = candidates
        .into_iter()
        .map(|c| Candidate {
            weight: c.weight / mean_length,
            ..c
        })
        .collect();
    let own_sd = if roll_sd.is_finite() { roll_sd } else { 0.0 };
    let prior_sd = own_sd.hypot(opts.cross_slope_roll_sd_deg.to_radians());
    // Zero or NaN (a NaN cross slope): no prior to search under.
    if prior_sd.is_nan() || prior_sd <= 0.0 {
        return None;
    }
    let prior = RollPrior {
        centre: roll,
        sd: prior_sd,
    };
    let window = (4.0 * prior_sd).min(opts.roll_window_deg.to_radians());
    let frame = Frame {
        vp1,
        pp,
        vp2_cut: opts.vp2_exclusion_deg.to_radians(),
    };
    let (ln_f, peak_roll) = peak(&candidates, frame, ln_range, prior, window);
    let best = frame.at(ln_f, peak_roll);
    let score = |c: &[Candidate], (lf, r): (f64, f64)| {
        log_likelihood(c, frame.at(lf, r)) + prior.log_density(r)
    };
    let peak_score = score(&candidates, (ln_f, peak_roll));
    // The same segments pointing anywhere (each direction redrawn among those a vertical
    // could have): how well chance alone meets at some VP3.
    let mut null_rng = SplitMix(seed ^ 0x0B5E_55ED);
    let nulls: Vec<Vec<Candidate>> = (0..opts.null_draws)
        .map(|_| {
            candidates
                .iter()
                .map(|c| {
                    let mut angle = c.angle;
                    for _ in 0..100 {
                        angle = (null_rng.next_f64() - 0.5) * std::f64::consts::PI;
                        if admissible(c.at, angle) {
                            break;
                        }
                    }
                    Candidate { angle, ..*c }
                })
                .collect()
        })
        .collect();
    let null_best = par_map(&nulls, |c| {
        score(c, peak(c, frame, ln_range, prior, window))
    })
    .into_iter()
    .fold(f64::NEG_INFINITY, f64::max);
    let beats_chance = peak_score > null_best;
    let supporting = candidates
        .iter()
        .filter(|c| best.miss(c).is_some_and(|r| r.abs() < 2.0))
        .count();
    // The grid's end cells: a peak there is the search's edge, not the verticals'.
    let edge = 0.04;
    let inside = ln_f > ln_range[0] + edge && ln_f < ln_range[1] - edge;
    // Half and twice the focal length must fit clearly worse.
    let profile = |lf: f64| {
        let lf = lf.clamp(ln_range[0], ln_range[1]);
        search(&candidates, frame, [lf, lf], prior, window).0
    };
    let peaked = peak_score
        - profile(ln_f - std::f64::consts::LN_2).max(profile(ln_f + std::f64::consts::LN_2))
        >= IDENTIFIED_DROP;
    // The resamples drawn in order, each with its own draw of the roll's prior centre (where
    // the segments leave a ridge, its spread is the roll's), refitted over the cores.
    let mut rng = SplitMix(seed ^ 0x7E27_1CA1);
    let n = candidates.len();
    let draws: Vec<(Vec<Candidate>, RollPrior)> = (0..opts.bootstrap)
        .map(|_| {
            let d = (0..n)
                .map(|_| candidates[((rng.next_f64() * n as f64) as usize).min(n - 1)])
                .collect();
            let centre = roll + prior_sd * rng.normal();
            (d, RollPrior { centre, ..prior })
        })
        .collect();
    let boots: Vec<f64> = par_map(&draws, |(d, p)| {
        peak(d, frame, ln_range, *p, window).0.exp()
    });
    // The verticals' own roll: the same search with no prior over a wide window, its
    // identification from the roll's profile, its spread from the same resamples.
    let flat = RollPrior::flat(roll);
    let own_window = opts.own_roll_window_deg.to_radians();
    let (own_score, own_lf, own) = search(&candidates, frame, ln_range, flat, own_window);
    let probe = OWN_ROLL_PROBE_DEG.to_radians();
    let coarse_f = grid(
        ln_range[0],
        ln_range[1],
        ((ln_range[1] - ln_range[0]) / 0.04).ceil() as usize + 1,
    );
    let roll_profile = |r: f64| best_over(&candidates, frame, &coarse_f, &[r], flat).0;
    let own_camera = frame.at(own_lf, own);
    let own_supporting: Vec<Candidate> = candidates
        .iter()
        .filter(|c| own_camera.miss(c).is_some_and(|r| r.abs() < 2.0))
        .copied()
        .collect();
    let own_identified = (own - roll).abs() < own_window - 0.5f64.to_radians()
        && distinct_lines(&own_supporting, own_camera, 2.0 * pp.x) >= opts.min_supporting
        && own_score - roll_profile(own - probe).max(roll_profile(own + probe)) >= IDENTIFIED_DROP;
    // Where the own roll could contradict the horizon, it must also beat chance as the fit
    // under the prior does, over the same wide window: a few segments meet somewhere within
    // ±15° more easily than within the prior's reach (a rendered curve's 11 candidates put
    // their own roll 14° off the truth). Only there are the chance draws searched and the
    // resamples' own rolls measured (their spread only lowers the contradiction): 30
    // searches over the wide window cost about two seconds on a view with 360 candidates.
    let could_contradict =
        own_identified && line_angle_diff(own - roll).abs() > HORIZON_CONFLICT_Z * prior_sd;
    let own_beats_chance = could_contradict && {
        let null_best = par_map(&nulls, |c| search(c, frame, ln_range, flat, own_window).0)
            .into_iter()
            .fold(f64::NEG_INFINITY, f64::max);
        own_score > null_best
    };
    let own_identified = own_identified && (!could_contradict || own_beats_chance);
    let own_rolls: Vec<f64> = if own_beats_chance {
        par_map(&draws, |(d, _)| {
            peak(d, frame, ln_range, flat, own_window).1
        })
    } else {
        vec![]
    };
    let own_roll_sd = if own_rolls.is_empty() {
        f64::NAN
    } else {
        half_p16_p84(&own_rolls)
    };
    let bootstrap_px = if boots.is_empty() {
        [ln_f.exp(); 2]
    } else {
        [percentile(boots.clone(), 16.0), percentile(boots, 84.0)]
    };
    Some(VerticalsFit {
        focal_px: ln_f.exp(),
        roll: peak_roll,
        candidates: n,
        supporting,
        bootstrap_px,
        identified: inside && peaked && supporting >= opts.min_supporting && beats_chance,
        own_roll: own_identified.then_some(own),
        own_roll_sd,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A camera looking down the road: VP1 above the principal point, the horizon tilted by
    /// `roll`, focal length `f`. Returns (VP1, pp, VP3).
    fn view(f: f64, roll: f64) -> (Point2, Point2, Point2) {
        let pp = Point2::new(960.0, 540.0);
        let vp1 = Point2::new(700.0, -300.0);
        let h = horizon(vp1, pp, roll);
        (vp1, pp, pp + h.n * (f * f / h.d))
    }

    /// Poles: segments on the lines from points of the frame towards VP3.
    fn poles(vp3: Point2, feet: &[(f64, f64)], length: f64) -> Vec<Segment> {
        feet.iter()
            .map(|&(x, y)| {
                let a = Point2::new(x, y);
                let u = (vp3 - a) * (1.0 / (vp3 - a).norm());
                Segment {
                    a,
                    b: a - u * length,
                }
            })
            .collect()
    }

    /// [`fit`] over 500-15,000 px with the default options.
    fn fit_default(
        segments: &[Segment],
        vp1: Point2,
        pp: Point2,
        roll: f64,
        seed: u64,
    ) -> Option<VerticalsFit> {
        fit(
            segments,
            vp1,
            pp,
            roll,
            0.0,
            [500.0, 15000.0],
            &VerticalOptions::default(),
            seed,
        )
    }

    const FEET: [(f64, f64); 8] = [
        (100.0, 900.0),
        (300.0, 700.0),
        (1800.0, 950.0),
        (1600.0, 600.0),
        (200.0, 400.0),
        (1750.0, 350.0),
        (500.0, 1000.0),
        (1400.0, 1050.0),
    ];

    #[test]
    fn poles_give_the_focal_length_and_roll() {
        for (f, roll_deg) in [(1200.0, 0.0), (2600.0, 2.0), (4000.0, -3.0)] {
            let roll = f64::to_radians(roll_deg);
            let (vp1, pp, vp3) = view(f, roll);
            let segments = poles(vp3, &FEET, 120.0);
            // The search starts 1.5° off the true roll.
            let start = roll + 1.5_f64.to_radians();
            let fit = fit_default(&segments, vp1, pp, start, 1).unwrap();
            assert!(fit.identified, "{fit:?}");
            assert!((fit.focal_px / f - 1.0).abs() < 0.02, "f {f}: {fit:?}");
            assert!((fit.roll - roll).abs() < 0.2_f64.to_radians(), "{fit:?}");
            assert_eq!(fit.supporting, FEET.len());
            let Some(Likelihood::LogNormal { log_sd, .. }) = fit.likelihood() else {
                panic!("no likelihood");
            };
            assert!((VERTICALS_MODEL_LOG_SD..0.25).contains(&log_sd), "{log_sd}");
        }
    }

    /// Plumb poles of a level camera, searched from a road horizon tilted 9° through the same
    /// VP1 (a horizon the vehicles' cues put wrong): the poles' own roll is gravity's, and
    /// it contradicts that horizon; a horizon near it does not.
    #[test]
    fn plumb_poles_find_their_own_roll_against_a_tilted_horizon() {
        let f = 2000.0;
        let (vp1, pp, vp3) = view(f, 0.0);
        let segments = poles(vp3, &FEET, 120.0);
        let opts = VerticalOptions::default();
        let tilted = 9f64.to_radians();
        let fit = fit(&segments, vp1, pp, tilted, 0.0, [500.0, 15000.0], &opts, 4).unwrap();
        let own = fit.own_roll.expect("the poles identify their roll");
        assert!(
            own.abs() < 0.3f64.to_radians(),
            "own roll {}°",
            own.to_degrees()
        );
        assert!(fit.own_roll_sd < 0.5f64.to_radians(), "{fit:?}");
        let (z, d) = fit
            .against_horizon(tilted, 0.4f64.to_radians(), &opts)
            .unwrap();
        assert!(z < -HORIZON_CONFLICT_Z, "z {z}");
        assert!((d.to_degrees() + 9.0).abs() < 0.3, "{}°", d.to_degrees());
        let (z, _) = fit
            .against_horizon(1f64.to_radians(), 0.4f64.to_radians(), &opts)
            .unwrap();
        assert!(z.abs() < 1.0, "z {z}");
        // Too few poles: no own roll, nothing to contradict.
        let few = fit_default(&segments[..2], vp1, pp, tilted, 4).unwrap();
        assert!(few.own_roll.is_none() && few.against_horizon(tilted, 0.0, &opts).is_none());
    }

    #[test]
    fn lines_along_the_road_and_clutter_are_not_verticals() {
        let f = 2000.0;
        let (vp1, pp, vp3) = view(f, 0.0);
        let mut segments = poles(vp3, &FEET, 100.0);
        // Lane lines towards VP1, longer than the poles.
        for x in [200.0, 700.0, 1200.0, 1700.0] {
            let a = Point2::new(x, 1080.0);
            let u = (vp1 - a) * (1.0 / (vp1 - a).norm());
            segments.push(Segment {
                a,
                b: a + u * 400.0,
            });
        }
        // Short segments in every direction (leaves, texture).
        let mut rng = SplitMix(7);
        for _ in 0..200 {
            let a = Point2::new(rng.next_f64() * 1920.0, rng.next_f64() * 1080.0);
            let t = rng.next_f64() * std::f64::consts::PI;
            segments.push(Segment {
                a,
                b: a + Point2::new(t.cos(), t.sin()) * 20.0,
            });
        }
        let fit = fit_default(&segments, vp1, pp, 0.0, 3).unwrap();
        assert!(fit.identified);
        assert!((fit.focal_px / f - 1.0).abs() < 0.03, "{fit:?}");
    }

    #[test]
    fn too_few_verticals_are_not_identified() {
        let (vp1, pp, vp3) = view(2000.0, 0.0);
        let segments = poles(vp3, &FEET[..2], 100.0);
        let fit = fit_default(&segments, vp1, pp, 0.0, 1).unwrap();
        assert!(!fit.identified);
        assert!(fit.likelihood().is_none());
        // Nothing but lines along the road: no candidate at all.
        let a = Point2::new(500.0, 1080.0);
        let along = Segment {
            a,
            b: a + (vp1 - a) * 0.3,
        };
        assert!(fit_default(&[along], vp1, pp, 0.0, 1).is_none());
    }

    #[test]
    fn a_level_camera_sees_parallel_verticals_that_say_nothing_of_f() {
        // The horizon through the principal point: VP3 at infinity for every f.
        let pp = Point2::new(960.0, 540.0);
        let vp1 = Point2::new(300.0, 540.0);
        let segments: Vec<Segment> = FEET
            .iter()
            .map(|&(x, y)| Segment {
                a: Point2::new(x, y),
                b: Point2::new(x, y - 100.0),
            })
            .collect();
        let fit = fit_default(&segments, vp1, pp, 0.0, 1).unwrap();
        assert!(!fit.identified, "{fit:?}");
    }

    #[test]
    fn segments_pointing_anywhere_are_rarely_identified() {
        // The chance test lets through one view in twenty by design; the focal length's
        // drop test catches some of those.
        let (vp1, pp, _) = view(2000.0, 0.0);
        let identified = (1..=12)
            .filter(|&seed| {
                let mut rng = SplitMix(seed);
                let segments: Vec<Segment> = (0..60)
                    .map(|_| {
                        let a = Point2::new(rng.next_f64() * 1920.0, rng.next_f64() * 1080.0);
                        let t = rng.next_f64() * std::f64::consts::PI;
                        let length = 40.0 + 80.0 * rng.next_f64();
                        Segment {
                            a,
                            b: a + Point2::new(t.cos(), t.sin()) * length,
                        }
                    })
                    .collect();
                let fit = fit_default(&segments, vp1, pp, 0.0, seed);
                // Nor do they contradict the horizon.
                let z = fit
                    .and_then(|f| f.against_horizon(0.0, 0.0, &VerticalOptions::default()))
                    .map_or(0.0, |(z, _)| z);
                assert!(z.abs() <= HORIZON_CONFLICT_Z, "seed {seed}: z {z}");
                fit.is_some_and(|f| f.identified)
            })
            .count();
        assert!(identified <= 2, "{identified} of 12");
    }

    #[test]
    fn lines_towards_vp2_are_not_verticals() {
        let f = 1500.0;
        let (vp1, pp, vp3) = view(f, 0.0);
        // VP2 on the horizon through VP1 with (VP1 - pp).(VP2 - pp) = -f².
        let a = vp1 - pp;
        let u = Point2::new(1.0, 0.0);
        let vp2 = vp1 + u * (-(f * f + a.dot(a)) / a.dot(u));
        let mut segments = poles(vp3, &FEET, 100.0);
        // A crossing's stripes and stop lines: long lines towards VP2.
        for k in 0..24 {
            let p = Point2::new(150.0 + 70.0 * k as f64, 500.0 + 20.0 * (k % 6) as f64);
            let d = (vp2 - p) * (1.0 / (vp2 - p).norm());
            segments.push(Segment {
                a: p,
                b: p + d * 250.0,
            });
        }
        let fit = fit_default(&segments, vp1, pp, 0.0, 2).unwrap();
        assert!(fit.identified, "{fit:?}");
        assert!((fit.focal_px / f - 1.0).abs() < 0.02, "{fit:?}");
        assert_eq!(fit.supporting, FEET.len());
    }

    #[test]
    fn a_few_poles_leave_the_roll_to_its_prior_and_widen_the_spread() {
        // Four poles close together: the direction to VP3 from one spot fixes only a
        // combination of f and the roll.
        let f = 2000.0;
        let (vp1, pp, vp3) = view(f, 0.0);
        let feet = [
            (900.0, 900.0),
            (960.0, 920.0),
            (1020.0, 880.0),
            (980.0, 960.0),
        ];
        let segments = poles(vp3, &feet, 150.0);
        let run = |roll_sd_deg: f64| {
            fit(
                &segments,
                vp1,
                pp,
                0.0,
                f64::to_radians(roll_sd_deg),
                [500.0, 15000.0],
                &VerticalOptions::default(),
                5,
            )
            .unwrap()
        };
        let (tight, loose) = (run(0.0), run(3.0));
        // On the ridge the prior's centre (the true roll) decides.
        assert!(tight.roll.abs() < 0.3_f64.to_radians(), "{tight:?}");
        assert!((tight.focal_px / f - 1.0).abs() < 0.05, "{tight:?}");
        let width = |v: &VerticalsFit| (v.bootstrap_px[1] / v.bootstrap_px[0]).ln();
        assert!(width(&loose) > width(&tight), "{tight:?} {loose:?}");
    }
}
