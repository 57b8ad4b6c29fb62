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
//! near the horizon's direction cannot be verticals and are left out. The fit is a search
//! over `ln f` and the roll near the horizon's for the VP3 that most segment length points
//! at: each segment supports a VP3 in the direction of its line with a Gaussian of its
//! angle's uncertainty (one pixel over its length, at least [`VerticalOptions::min_angle_sd_deg`]).
//! A search, not a least-squares fit: most segments are not verticals, and the verticals'
//! own VP3 is a peak among them. A peak at the search's end, or carried by fewer than
//! [`VerticalOptions::min_supporting`] segments, is not identified. The segments'
//! bootstrap gives its spread; [`VERTICALS_MODEL_LOG_SD`] its model error.

use super::focal::{bootstrap_log_sd, FocalSource, Likelihood};
use super::line_angle_diff;
use crate::point::Point2;
use crate::solve::{par_map, percentile, SplitMix};

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
/// segments' bootstrap: on the twelve BrnoCompSpeed views of sessions 0-3 (real, 1080p, the
/// reference cameras) and the fourteen scenes of the synthetic suite, given the true VP1
/// and horizon, the identified fits' errors have an rms of 0.20 in `ln f` (docs/accuracy.md
/// §24: real views 0.24 with a bias of -0.10, renders 0.13): trees lean, posts are not
/// plumb, and a view's few poles may all stand on one side.
pub const VERTICALS_MODEL_LOG_SD: f64 = 0.20;

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
    /// Segments within this angle of the horizon's direction cannot point at VP3, degrees.
    pub horizon_exclusion_deg: f64,
    /// How far the verticals' roll may differ from the horizon's given, degrees: the roll
    /// of the cue is a nuisance searched over, since VP3 depends on it as much as on `f`.
    pub roll_window_deg: f64,
    /// The least angle uncertainty of a segment, degrees (a long segment's one pixel over
    /// its length is smaller than what makes a pole not quite plumb).
    pub min_angle_sd_deg: f64,
    /// The fewest segments within two of their uncertainties of the peak's VP3.
    pub min_supporting: usize,
    /// Resamples of the segments for the spread.
    pub bootstrap: usize,
}

impl Default for VerticalOptions {
    fn default() -> VerticalOptions {
        VerticalOptions {
            vp1_exclusion_deg: 10.0,
            horizon_exclusion_deg: 20.0,
            roll_window_deg: 3.0,
            min_angle_sd_deg: 0.5,
            min_supporting: 4,
            bootstrap: 30,
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
    /// Whether the peak is inside the search and carried by enough segments.
    pub identified: bool,
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

/// The segment length pointing at VP3 for (`ln_f`, `roll`).
fn support(c: &[Candidate], vp1: Point2, pp: Point2, ln_f: f64, roll: f64) -> f64 {
    let h = horizon(vp1, pp, roll);
    let f2 = (2.0 * ln_f).exp();
    c.iter()
        .map(|c| {
            let t = towards_vp3(c.at, pp, h, f2);
            let r = line_angle_diff(c.angle - t.y.atan2(t.x)) / c.sd;
            c.weight * (-0.5 * r * r).exp()
        })
        .sum()
}

/// The peak of [`support`] over `ln f` in `ln_range` and the roll within `window` of
/// `roll0`: a coarse grid, then a fine one around its best. Returns `(ln f, roll)`.
fn peak(
    c: &[Candidate],
    vp1: Point2,
    pp: Point2,
    ln_range: [f64; 2],
    roll0: f64,
    window: f64,
) -> (f64, f64) {
    let grid = |lo: f64, hi: f64, n: usize| -> Vec<f64> {
        (0..n)
            .map(|i| lo + (hi - lo) * i as f64 / (n - 1).max(1) as f64)
            .collect()
    };
    let search = |fs: &[f64], rolls: &[f64]| {
        let mut best = (f64::NEG_INFINITY, fs[0], rolls[0]);
        for &lf in fs {
            for &r in rolls {
                let s = support(c, vp1, pp, lf, r);
                if s > best.0 {
                    best = (s, lf, r);
                }
            }
        }
        (best.1, best.2)
    };
    let [lo, hi] = ln_range;
    let coarse_steps = ((hi - lo) / 0.04).ceil() as usize + 1;
    let roll_steps = (2.0 * window / 0.5_f64.to_radians()).ceil() as usize + 1;
    let (lf, r) = search(
        &grid(lo, hi, coarse_steps.max(2)),
        &grid(roll0 - window, roll0 + window, roll_steps.max(1)),
    );
    let fine_f = grid((lf - 0.04).max(lo), (lf + 0.04).min(hi), 17);
    let fine_r = grid(
        (r - 0.5_f64.to_radians()).max(roll0 - window),
        (r + 0.5_f64.to_radians()).min(roll0 + window),
        11,
    );
    search(&fine_f, &fine_r)
}

/// The focal length from the `segments` given VP1 (finite), the principal point, the
/// horizon's angle `roll` (radians) and the search range `range_px` (pixels); `None` where
/// no segment could be a vertical.
pub fn fit(
    segments: &[Segment],
    vp1: Point2,
    pp: Point2,
    roll: f64,
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
    let candidates: Vec<Candidate> = segments
        .iter()
        .filter_map(|s| {
            let (at, angle, length) = (s.middle(), s.angle(), s.length());
            let to_vp1 = vp1 - at;
            let along_road = line_angle_diff(angle - to_vp1.y.atan2(to_vp1.x)).abs() < vp1_cut;
            let along_horizon = line_angle_diff(angle - roll).abs() < horizon_cut;
            (length > 0.0 && at.is_finite() && !along_road && !along_horizon).then(|| Candidate {
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
    let window = opts.roll_window_deg.to_radians();
    let (ln_f, peak_roll) = peak(&candidates, vp1, pp, ln_range, roll, window);
    let h = horizon(vp1, pp, peak_roll);
    let f2 = (2.0 * ln_f).exp();
    let supporting = candidates
        .iter()
        .filter(|c| {
            let t = towards_vp3(c.at, pp, h, f2);
            line_angle_diff(c.angle - t.y.atan2(t.x)).abs() < 2.0 * c.sd
        })
        .count();
    // The grid's end cells: a peak there is the search's edge, not the verticals'.
    let edge = 0.04;
    let inside = ln_f > ln_range[0] + edge && ln_f < ln_range[1] - edge;
    // The resamples drawn in order, refitted over the cores.
    let mut rng = SplitMix(seed ^ 0x7E27_1CA1);
    let n = candidates.len();
    let draws: Vec<Vec<Candidate>> = (0..opts.bootstrap)
        .map(|_| {
            (0..n)
                .map(|_| candidates[((rng.next_f64() * n as f64) as usize).min(n - 1)])
                .collect()
        })
        .collect();
    let boots: Vec<f64> = par_map(&draws, |d| peak(d, vp1, pp, ln_range, roll, window).0.exp());
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
        identified: inside && supporting >= opts.min_supporting,
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
}
