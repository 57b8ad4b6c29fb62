//! The focal length as one posterior: every cue that says something about `f` is a
//! likelihood over `ln f`; the prior (uniform in `ln f` over the views a traffic camera can
//! have, or the user's range) times their product is the posterior, and its median and
//! 16th-84th percentiles are the focal length and its interval.
//!
//! A cue is accepted or left out for what it *is*, never for how sharp it is: a cue whose model
//! does not hold (one VP2 for all the rays on a curved road) is not built; one that contradicts
//! the prior (its own focal length outside the range by more than [`CONFLICT_SD`] of its own
//! error) is reported and left out, since it would pile the posterior against the range's end;
//! so is one further than that from the more informative cues (of the difference's error),
//! since no camera fits both and their product would hold neither; a weak cue just adds
//! little. Whether the result is *measured* or *assumed* is then a
//! property of the evidence: measured when the used cues together carry at least as much
//! information on `ln f` as the prior ([`measured`](FocalPosterior::measured)), and the cues
//! that carried it are named ([`FocalPosterior::carried_by`]).
//!
//! Where the evidence is weaker than the prior, the focal length stays the band's middle
//! (and its interval the band's central 68 %) while the posterior is still reported: the cues' noise
//! models are calibrated only roughly, and a likelihood wider than the prior then moves the
//! estimate by its miscalibration more than by the camera (on the BrnoCompSpeed dev videos,
//! the public CNNs' VP2 rays pulling an assumed focal length around doubled its median
//! error).

/// Horizontal fields of view of traffic cameras, degrees: from a telephoto view far along a
/// motorway (15°) to a wide-angle view of a junction (90°). The focal-length prior comes from
/// this range, not from any dataset's cameras.
pub const TRAFFIC_FOV_DEG: [f64; 2] = [15.0, 90.0];

/// The focal length of a horizontal field of view, in image widths: `0.5 / tan(fov / 2)`.
pub fn focal_widths(fov_deg: f64) -> f64 {
    0.5 / (fov_deg.to_radians() / 2.0).tan()
}

/// The focal-length prior as `(median, sd of ln f)` in image widths: a focal length uniform
/// in `ln f` over [`TRAFFIC_FOV_DEG`] has its median at the geometric mean of the range's
/// ends (1.38 widths, a 40° view) and a standard deviation of `ln(range) / sqrt(12)` (0.59).
pub fn physical_focal_prior() -> (f64, f64) {
    let (long, wide) = (
        focal_widths(TRAFFIC_FOV_DEG[0]),
        focal_widths(TRAFFIC_FOV_DEG[1]),
    );
    ((long * wide).sqrt(), (long / wide).ln() / 12f64.sqrt())
}

/// The focal-length prior's range in image widths, `[short, long]`: `range`, or the focal
/// lengths of [`TRAFFIC_FOV_DEG`] (0.5-3.8 widths).
pub fn focal_prior_range_widths(range: Option<[f64; 2]>) -> [f64; 2] {
    range.unwrap_or([
        focal_widths(TRAFFIC_FOV_DEG[1]),
        focal_widths(TRAFFIC_FOV_DEG[0]),
    ])
}

/// Points of the `ln f` grid over the prior's range.
pub const GRID: usize = 400;

/// A cue whose own focal length lies outside the prior's range by more than this many of its
/// own standard errors contradicts the prior and is left out (reported, not used); so does
/// one this many standard errors of the difference from the more informative cues.
pub const CONFLICT_SD: f64 = 2.0;

/// The least share of the cues' information for a cue to be named as carrying `f`.
pub const MIN_CARRY_SHARE: f64 = 0.2;

/// How softly the prior falls off beyond its range, standard deviation in `ln f`: the 15-90°
/// band holds most traffic cameras, but it is a convention, not a law (a 2.8 mm CCTV lens on
/// a 1/2.7" sensor sees about 100°, 0.17 beyond the band's wide end in `ln f`; the synthetic
/// suite has a 94° view), so evidence may carry `f` beyond it at a Gaussian cost. The price:
/// an evidence-free 68 % interval about a quarter wider in `ln f` than the hard band's.
pub const PRIOR_EDGE_LOG_SD: f64 = 0.2;

/// A measured focal length's model error, standard deviation in `ln f`, added to every
/// geometric cue built from a bootstrap (edgelets, the curved-road fit, trusted rays): on
/// the synthetic suite the edgelets' bootstrap intervals alone held the truth for none of
/// 9 scenes; 0.18 is the spread of their errors there.
pub const MODEL_LOG_SD: f64 = 0.18;

/// The standard deviation in `ln f` of a cue measured by a bootstrap whose focal lengths
/// spread over `[p16, p84]`: half their log width, in quadrature with `turn` (how far a
/// systematic turn of the evidence moves `ln f`; 0 where none was measured) and
/// [`MODEL_LOG_SD`]. A bootstrap without spread (or none) still leaves the model error.
pub fn measured_log_sd(bootstrap: [f64; 2], turn: f64) -> f64 {
    let b = bootstrap_log_sd(bootstrap);
    let t = if turn.is_finite() { turn } else { 0.0 };
    (b * b + t * t + MODEL_LOG_SD * MODEL_LOG_SD).sqrt()
}

/// The spread in `ln f` of a bootstrap whose focal lengths spread over `[p16, p84]`: half
/// their log width (0 where that is not finite).
pub fn bootstrap_log_sd(bootstrap: [f64; 2]) -> f64 {
    let b = 0.5 * (bootstrap[1] / bootstrap[0]).ln().abs();
    if b.is_finite() {
        b
    } else {
        0.0
    }
}

/// What a cue says about `ln f`.
#[derive(Debug, Clone, PartialEq)]
pub enum Likelihood {
    /// Gaussian in `ln f` around `focal_px` with standard deviation `log_sd`.
    LogNormal { focal_px: f64, log_sd: f64 },
    /// Tabulated log-likelihood at ascending `ln f` (linear in between, the end values held
    /// beyond), 0 at `own_px`, the cue's own focal length (which may lie outside the table).
    Table {
        ln_f: Vec<f64>,
        log_lik: Vec<f64>,
        own_px: f64,
    },
}

impl Likelihood {
    /// Log-likelihood at `ln_f`, 0 at the cue's own focal length.
    pub fn at(&self, ln_f: f64) -> f64 {
        match self {
            Likelihood::LogNormal { focal_px, log_sd } => {
                let z = (ln_f - focal_px.ln()) / log_sd;
                -0.5 * z * z
            }
            Likelihood::Table {
                ln_f: xs,
                log_lik: ys,
                ..
            } => interpolate(xs, ys, ln_f),
        }
    }

    /// The cue's own focal length (where its likelihood peaks).
    pub fn own_px(&self) -> f64 {
        match self {
            Likelihood::LogNormal { focal_px, .. } => *focal_px,
            Likelihood::Table { own_px, .. } => *own_px,
        }
    }
}

fn interpolate(xs: &[f64], ys: &[f64], x: f64) -> f64 {
    match xs.partition_point(|v| *v < x) {
        _ if xs.is_empty() => 0.0,
        0 => ys[0],
        i if i >= xs.len() => ys[xs.len() - 1],
        i => {
            let t = (x - xs[i - 1]) / (xs[i] - xs[i - 1]);
            ys[i - 1] + t * (ys[i] - ys[i - 1])
        }
    }
}

/// One piece of evidence on the focal length.
#[derive(Debug, Clone, PartialEq)]
pub struct Cue {
    /// Its name in `focal_source` and `evidence.focal_cues` (e.g. `edgelets`).
    pub source: &'static str,
    pub likelihood: Likelihood,
}

/// A source of evidence on the focal length: every fit that can say something about `f`
/// (the straight and the curved edgelet fits, the network's trusted and untrusted VP2 rays,
/// the user's known lengths) implements it, and the posterior ([`fuse`]) consumes what each
/// says ([`cues_of`]). Whether a source applies to the scene at all (a curved road, edges
/// parallel in the image) is the aggregator's choice of sources; whether its own fit holds
/// is the source's.
pub trait FocalSource {
    /// Its name in `focal_source` and `evidence.focal_cues` (e.g. `edgelets`).
    fn name(&self) -> &'static str;
    /// Its likelihood over `ln f`; `None` where its fit says nothing (failed, or not
    /// identified).
    fn likelihood(&self) -> Option<Likelihood>;
}

/// The cues of the `sources` that speak, in their order.
pub fn cues_of(sources: &[&dyn FocalSource]) -> Vec<Cue> {
    sources
        .iter()
        .filter_map(|s| {
            Some(Cue {
                source: s.name(),
                likelihood: s.likelihood()?,
            })
        })
        .collect()
}

/// A focal length measured by a fit with a bootstrap: log-normal around it, with the
/// bootstrap's spread, a systematic turn's and the model error ([`measured_log_sd`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Measured {
    pub name: &'static str,
    pub focal_px: f64,
    /// The bootstrap's 16th and 84th percentiles, pixels.
    pub bootstrap_px: [f64; 2],
    /// How far a systematic turn of the evidence moves `ln f` (0 where none was measured).
    pub turn: f64,
}

impl FocalSource for Measured {
    fn name(&self) -> &'static str {
        self.name
    }

    fn likelihood(&self) -> Option<Likelihood> {
        Some(Likelihood::LogNormal {
            focal_px: self.focal_px,
            log_sd: measured_log_sd(self.bootstrap_px, self.turn),
        })
    }
}

/// What became of one cue in the posterior.
#[derive(Debug, Clone, PartialEq)]
pub struct CueReport {
    pub source: &'static str,
    /// The cue's own focal length (its likelihood's peak), pixels.
    pub focal_px: f64,
    /// The 68 % interval of the prior and this cue alone, pixels.
    pub interval_px: [f64; 2],
    /// Its share of the used cues' information (their likelihoods' precisions), 0-1; 0 when
    /// not used.
    pub share: f64,
    /// Whether it entered the posterior; `false` when it contradicts the prior or a more
    /// informative cue.
    pub used: bool,
    /// What it contradicts when not used: `prior`, or the source of the more informative
    /// cue it disagrees with.
    pub contradicts: Option<&'static str>,
}

/// The focal length's posterior.
#[derive(Debug, Clone, PartialEq)]
pub struct FocalPosterior {
    /// The focal length and its 68 % interval, pixels: the posterior's median and 16th-84th
    /// percentiles where it is measured, the prior's where it is not.
    pub focal_px: f64,
    pub interval_px: [f64; 2],
    /// The posterior's 16th, 50th and 84th percentiles, pixels, measured or not.
    pub posterior_px: [f64; 3],
    /// Whether the used cues carry at least as much information on `ln f` as the prior (the
    /// sum of their likelihoods' precisions at least that of a uniform over the range).
    pub measured: bool,
    /// The used cues with at least [`MIN_CARRY_SHARE`] of the cues' information, most
    /// informative first; empty when nothing was measured.
    pub carried_by: Vec<&'static str>,
    pub cues: Vec<CueReport>,
}

/// Variance of `ln f` under weights `w` over `grid` (unnormalised).
fn variance(grid: &[f64], w: &[f64]) -> f64 {
    let total: f64 = w.iter().sum();
    let mean = grid.iter().zip(w).map(|(x, w)| x * w).sum::<f64>() / total;
    grid.iter()
        .zip(w)
        .map(|(x, w)| (x - mean) * (x - mean) * w)
        .sum::<f64>()
        / total
}

/// The 16th, 50th and 84th percentiles of the weights `w` on the evenly spaced `grid` (`ln f`),
/// pixels. Each weight is spread evenly over its cell, so the percentiles fall between grid
/// points: a precise cue (known lengths measure `ln f` to 0.02, two cells) keeps its width.
fn quantiles(grid: &[f64], w: &[f64]) -> [f64; 3] {
    let h = if grid.len() > 1 {
        grid[1] - grid[0]
    } else {
        0.0
    };
    let total: f64 = w.iter().sum();
    let q = |q: f64| {
        let target = q * total;
        let mut below = 0.0;
        for (x, v) in grid.iter().zip(w) {
            if *v > 0.0 && below + v >= target {
                let t = ((target - below) / v).clamp(0.0, 1.0);
                return (x - 0.5 * h + t * h).exp();
            }
            below += v;
        }
        grid.last().map_or(f64::NAN, |x| (x + 0.5 * h).exp())
    };
    [q(0.16), q(0.5), q(0.84)]
}

/// Weights `exp(log - max)` of the prior (log density on `grid`) times `cues`.
fn posterior_weights(grid: &[f64], prior: &[f64], cues: &[&Cue]) -> Vec<f64> {
    let log: Vec<f64> = grid
        .iter()
        .zip(prior)
        .map(|(&x, p)| p + cues.iter().map(|c| c.likelihood.at(x)).sum::<f64>())
        .collect();
    let top = log.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    log.iter().map(|l| (l - top).exp()).collect()
}

/// How far the posterior's grid reaches beyond the range, in `ln f`.
const TAIL_LOG: f64 = 4.0 * PRIOR_EDGE_LOG_SD;

/// The focal lengths the posterior is evaluated over, pixels: `range_px` widened by four
/// [`PRIOR_EDGE_LOG_SD`] either side (a tabulated cue should cover them).
pub fn support(range_px: [f64; 2]) -> [f64; 2] {
    [
        range_px[0] * (-TAIL_LOG).exp(),
        range_px[1] * TAIL_LOG.exp(),
    ]
}

/// The grid: the range widened by four [`PRIOR_EDGE_LOG_SD`] either side, `ln f` at cell
/// centres, with the prior's log density at each (0 inside the range); and the variance of a
/// prior uniform over the range, the information that measured evidence must match.
fn grid_of(range_px: [f64; 2]) -> Option<(Vec<f64>, Vec<f64>, f64)> {
    let (lo, hi) = log_range(range_px)?;
    let (a, b) = (lo - TAIL_LOG, hi + TAIL_LOG);
    let grid: Vec<f64> = (0..GRID)
        .map(|i| a + (b - a) * (i as f64 + 0.5) / GRID as f64)
        .collect();
    let prior = grid.iter().map(|&x| prior_log_density(lo, hi, x)).collect();
    Some((grid, prior, (hi - lo).powi(2) / 12.0))
}

/// `(ln short, ln long)` of a valid range `[short, long]` (pixels, `0 < short < long`).
fn log_range(range_px: [f64; 2]) -> Option<(f64, f64)> {
    let [short, long] = range_px;
    (short > 0.0 && long > short && long.is_finite()).then(|| (short.ln(), long.ln()))
}

fn prior_log_density(lo: f64, hi: f64, x: f64) -> f64 {
    let d = (lo - x).max(x - hi).max(0.0) / PRIOR_EDGE_LOG_SD;
    -0.5 * d * d
}

/// The focal length and 68 % interval of an assumed focal length, pixels: the 16th, 50th and
/// 84th percentiles of a distribution uniform in `ln f` over `range_px`, the band itself
/// without the soft edges that let evidence carry `f` beyond it ([`PRIOR_EDGE_LOG_SD`]).
pub fn prior_percentiles(range_px: [f64; 2]) -> Option<[f64; 3]> {
    let (lo, hi) = log_range(range_px)?;
    Some([0.16, 0.5, 0.84].map(|q| (lo + q * (hi - lo)).exp()))
}

/// The 16th, 50th and 84th percentiles of the prior and one likelihood, pixels.
pub fn alone(range_px: [f64; 2], likelihood: &Likelihood) -> Option<[f64; 3]> {
    let (grid, prior, _) = grid_of(range_px)?;
    let cue = Cue {
        source: "",
        likelihood: likelihood.clone(),
    };
    Some(quantiles(&grid, &posterior_weights(&grid, &prior, &[&cue])))
}

/// The posterior of `f` under the prior uniform in `ln f` over `range_px` (`[short, long]`,
/// pixels) and `cues`. `None` for an invalid range.
pub fn fuse(range_px: [f64; 2], cues: &[Cue]) -> Option<FocalPosterior> {
    let (grid, prior, prior_var) = grid_of(range_px)?;
    let (lo, hi) = log_range(range_px)?;
    // A cue whose own focal length lies outside the range contradicts the prior when its
    // likelihood at the range's nearer end is below that of CONFLICT_SD standard errors; a
    // tabulated one as soon as its peak lies outside (its table need not say how far).
    let conflicting = |c: &Cue| {
        let own = c.likelihood.own_px().ln();
        let end = if own < lo {
            lo
        } else if own > hi {
            hi
        } else {
            return !own.is_finite();
        };
        let at_end = c.likelihood.at(end);
        matches!(c.likelihood, Likelihood::Table { .. })
            || at_end.is_nan()
            || at_end < -0.5 * CONFLICT_SD * CONFLICT_SD
    };
    // Each cue alone with the prior: its interval; and its own information on ln f (the
    // precision of its likelihood, not of the prior it is cut by: a weak cue pointing past the
    // range's end piles the posterior against it, narrow but not measured).
    let alone: Vec<(f64, [f64; 3])> = cues
        .iter()
        .map(|c| {
            let info = match &c.likelihood {
                Likelihood::LogNormal { log_sd, .. } => 1.0 / (log_sd * log_sd).max(1e-12),
                Likelihood::Table { .. } => {
                    let flat = vec![0.0; grid.len()];
                    1.0 / variance(&grid, &posterior_weights(&grid, &flat, &[c])).max(1e-12)
                }
            };
            (
                info,
                quantiles(&grid, &posterior_weights(&grid, &prior, &[c])),
            )
        })
        .collect();
    let mut contradicts: Vec<Option<&'static str>> = cues
        .iter()
        .map(|c| conflicting(c).then_some("prior"))
        .collect();
    // Cues that contradict each other cannot both describe this camera: combined, they
    // would give a focal length neither supports, with an interval narrower than either's.
    // Most informative first, a cue further than CONFLICT_SD standard errors (of the
    // difference) from the cues taken so far is left out, reported against the cue that
    // carries most of them.
    let mut order: Vec<usize> = (0..cues.len())
        .filter(|&i| contradicts[i].is_none())
        .collect();
    order.sort_by(|&a, &b| alone[b].0.total_cmp(&alone[a].0));
    // The first cue taken is the most informative, the one a later cue is reported against.
    let (mut sum_w, mut sum_wx, mut strongest): (f64, f64, Option<usize>) = (0.0, 0.0, None);
    for i in order {
        let (info, x) = (alone[i].0, cues[i].likelihood.own_px().ln());
        if let Some(first) = strongest {
            let mean = sum_wx / sum_w;
            let sd = (1.0 / sum_w + 1.0 / info).sqrt();
            if (x - mean).abs() > CONFLICT_SD * sd {
                contradicts[i] = Some(cues[first].source);
                continue;
            }
        }
        strongest = strongest.or(Some(i));
        sum_w += info;
        sum_wx += info * x;
    }
    let used: Vec<bool> = contradicts.iter().map(Option::is_none).collect();
    let used_cues: Vec<&Cue> = cues
        .iter()
        .zip(&used)
        .filter(|(_, u)| **u)
        .map(|(c, _)| c)
        .collect();
    let total_info: f64 = alone
        .iter()
        .zip(&used)
        .filter(|(_, u)| **u)
        .map(|(a, _)| a.0)
        .sum();
    let w = posterior_weights(&grid, &prior, &used_cues);
    let [p16, p50, p84] = if used_cues.is_empty() {
        prior_percentiles(range_px)?
    } else {
        quantiles(&grid, &w)
    };
    let measured = total_info >= 1.0 / prior_var;
    let reports: Vec<CueReport> = cues
        .iter()
        .zip(&alone)
        .zip(&used)
        .zip(&contradicts)
        .map(|(((c, (info, [q16, _, q84])), &u), &against)| CueReport {
            source: c.source,
            focal_px: c.likelihood.own_px(),
            interval_px: [*q16, *q84],
            share: if u && total_info > 0.0 {
                info / total_info
            } else {
                0.0
            },
            used: u,
            contradicts: against,
        })
        .collect();
    let mut carried: Vec<&CueReport> = reports
        .iter()
        .filter(|r| measured && r.used && r.share >= MIN_CARRY_SHARE)
        .collect();
    carried.sort_by(|a, b| b.share.total_cmp(&a.share));
    // Evidence weaker than the prior does not move the focal length off the band's middle:
    // its noise model, not the camera, would then decide where it lands (module docs).
    let [r16, r50, r84] = if measured {
        [p16, p50, p84]
    } else {
        prior_percentiles(range_px)?
    };
    Some(FocalPosterior {
        focal_px: r50,
        interval_px: [r16, r84],
        posterior_px: [p16, p50, p84],
        measured,
        carried_by: carried.iter().map(|r| r.source).collect(),
        cues: reports,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    const RANGE: [f64; 2] = [500.0, 3800.0];

    /// A source that says nothing.
    struct Silent;

    impl FocalSource for Silent {
        fn name(&self) -> &'static str {
            "silent"
        }

        fn likelihood(&self) -> Option<Likelihood> {
            None
        }
    }

    #[test]
    fn the_sources_that_speak_become_cues_in_their_order() {
        let a = Measured {
            name: "edgelets",
            focal_px: 1200.0,
            bootstrap_px: [1100.0, 1300.0],
            turn: 0.1,
        };
        let b = Measured {
            name: "network",
            focal_px: 900.0,
            bootstrap_px: [1.0, 1.0],
            turn: 0.0,
        };
        let cues = cues_of(&[&a, &Silent, &b]);
        assert_eq!(
            cues.iter().map(|c| c.source).collect::<Vec<_>>(),
            ["edgelets", "network"]
        );
        // A measured fit's spread: its bootstrap, its turn and the model error together.
        let want = measured_log_sd([1100.0, 1300.0], 0.1);
        assert_eq!(
            cues[0].likelihood,
            Likelihood::LogNormal {
                focal_px: 1200.0,
                log_sd: want
            }
        );
        // A bootstrap without spread leaves the model error alone.
        assert_eq!(
            cues[1].likelihood,
            Likelihood::LogNormal {
                focal_px: 900.0,
                log_sd: MODEL_LOG_SD
            }
        );
        assert!(cues_of(&[&Silent]).is_empty());
    }

    fn log_normal(source: &'static str, f: f64, sd: f64) -> Cue {
        Cue {
            source,
            likelihood: Likelihood::LogNormal {
                focal_px: f,
                log_sd: sd,
            },
        }
    }

    #[test]
    fn a_measured_cue_carries_the_model_error() {
        // A bootstrap that agrees with itself still leaves the model's ±18 % in ln f.
        assert!((measured_log_sd([1000.0, 1000.0], 0.0) - MODEL_LOG_SD).abs() < 1e-12);
        assert!((measured_log_sd([f64::NAN, f64::NAN], f64::NAN) - MODEL_LOG_SD).abs() < 1e-12);
        // A wide bootstrap and a systematic turn add in quadrature.
        let b = [1000.0 * (-0.24f64).exp(), 1000.0 * 0.24f64.exp()];
        let s = (0.24f64 * 0.24 + 0.3 * 0.3 + MODEL_LOG_SD * MODEL_LOG_SD).sqrt();
        assert!((measured_log_sd(b, 0.3) - s).abs() < 1e-12);
    }

    #[test]
    fn without_cues_the_focal_length_is_the_bands() {
        let p = fuse(RANGE, &[]).unwrap();
        let mid = (RANGE[0] * RANGE[1]).sqrt();
        assert!((p.focal_px / mid - 1.0).abs() < 1e-9, "{}", p.focal_px);
        // The central 68 % of a uniform in ln f over the band.
        let span = (RANGE[1] / RANGE[0]).ln();
        let [lo, hi] = p.interval_px;
        assert!(((hi / lo).ln() / span - 0.68).abs() < 1e-9);
        assert!(!p.measured && p.carried_by.is_empty());
        // The prior with its soft edges is a little wider than the band.
        let (grid, prior, _) = grid_of(RANGE).unwrap();
        let [g16, _, g84] = quantiles(&grid, &posterior_weights(&grid, &prior, &[]));
        assert!(g16 < lo && g84 > hi && (g84 / g16).ln() < 1.4 * (hi / lo).ln());
    }

    #[test]
    fn a_sharp_cue_carries_the_focal_length() {
        let p = fuse(RANGE, &[log_normal("edgelets", 1200.0, 0.1)]).unwrap();
        assert!((p.focal_px / 1200.0 - 1.0).abs() < 0.01, "{}", p.focal_px);
        let [lo, hi] = p.interval_px;
        assert!((0.5 * (hi / lo).ln() - 0.1).abs() < 0.01);
        assert!(p.measured);
        assert_eq!(p.carried_by, vec!["edgelets"]);
        assert!((p.cues[0].share - 1.0).abs() < 1e-9);
        // Narrower than two of the grid's cells: still its own value and width.
        let p = fuse(RANGE, &[log_normal("distances", 1517.0, 0.02)]).unwrap();
        assert!((p.focal_px / 1517.0 - 1.0).abs() < 0.002, "{}", p.focal_px);
        let [lo, hi] = p.interval_px;
        assert!(
            (0.5 * (hi / lo).ln() / 0.02 - 1.0).abs() < 0.05,
            "{lo} {hi}"
        );
    }

    #[test]
    fn two_cues_meet_at_their_precision_weighted_mean() {
        let p = fuse(
            RANGE,
            &[
                log_normal("edgelets", 1000.0, 0.1),
                log_normal("network_rays", 1300.0, 0.15),
            ],
        )
        .unwrap();
        // 1.5 standard errors apart. Inverse-variance mean in ln f: weights 100 and 44.4.
        let (a, b) = (100.0, 1.0 / 0.0225);
        let expect = ((a * 1000f64.ln() + b * 1300f64.ln()) / (a + b)).exp();
        assert!(
            (p.focal_px / expect - 1.0).abs() < 0.01,
            "{} {expect}",
            p.focal_px
        );
        assert_eq!(p.carried_by, vec!["edgelets", "network_rays"]);
        assert!(p.cues[0].share > p.cues[1].share);
    }

    #[test]
    fn of_two_cues_that_contradict_each_other_the_less_informative_is_left_out() {
        // 0.86 apart in ln f, 2.5 standard errors of the difference (0.18 and 0.30): no
        // camera has both; their mean would be 25 % from each with an interval holding
        // neither.
        let p = fuse(
            RANGE,
            &[
                log_normal("network_rays", 2240.0, 0.30),
                log_normal("edgelets", 950.0, 0.18),
            ],
        )
        .unwrap();
        assert!((p.focal_px / 950.0 - 1.0).abs() < 0.02, "{}", p.focal_px);
        assert!(p.interval_px[0] < 950.0 && 950.0 < p.interval_px[1]);
        assert_eq!(p.carried_by, vec!["edgelets"]);
        let rays = &p.cues[0];
        assert!(!rays.used && rays.share == 0.0);
        assert_eq!(rays.contradicts, Some("edgelets"));
        assert_eq!(p.cues[1].contradicts, None);
    }

    #[test]
    fn a_weak_cue_moves_the_posterior_but_not_the_focal_length() {
        let p = fuse(RANGE, &[log_normal("network_rays", 1000.0, 1.0)]).unwrap();
        assert!(!p.measured && p.carried_by.is_empty());
        let mid = (RANGE[0] * RANGE[1]).sqrt();
        assert!(p.posterior_px[1] < mid, "{:?}", p.posterior_px);
        assert!((p.focal_px / mid - 1.0).abs() < 1e-9);
        assert!(p.cues[0].used);
    }

    #[test]
    fn a_cue_far_outside_the_prior_is_reported_and_left_out() {
        let p = fuse(RANGE, &[log_normal("edgelets", 40_000.0, 0.2)]).unwrap();
        assert!(!p.cues[0].used && !p.measured);
        let mid = (RANGE[0] * RANGE[1]).sqrt();
        assert!((p.focal_px / mid - 1.0).abs() < 0.01);
        // Just outside, within its own error: used, and the soft edge lets it through.
        let p = fuse(RANGE, &[log_normal("edgelets", 4200.0, 0.1)]).unwrap();
        assert!(
            p.cues[0].used && p.measured && p.focal_px > 3800.0,
            "{}",
            p.focal_px
        );
        // A table peaking outside the range is left out.
        let table = Likelihood::Table {
            ln_f: vec![6.0, 9.0],
            log_lik: vec![-3.0, -0.1],
            own_px: 1e7,
        };
        let p = fuse(
            RANGE,
            &[Cue {
                source: "network_rays",
                likelihood: table,
            }],
        )
        .unwrap();
        assert!(!p.cues[0].used);
    }

    #[test]
    fn a_table_interpolates_and_holds_its_ends() {
        let l = Likelihood::Table {
            ln_f: vec![1.0, 2.0, 3.0],
            log_lik: vec![-4.0, 0.0, -2.0],
            own_px: 2f64.exp(),
        };
        assert_eq!(l.at(0.0), -4.0);
        assert_eq!(l.at(1.5), -2.0);
        assert_eq!(l.at(2.5), -1.0);
        assert_eq!(l.at(9.0), -2.0);
        assert_eq!(l.own_px(), 2f64.exp());
    }

    #[test]
    fn an_invalid_range_has_no_posterior() {
        assert!(fuse([0.0, 100.0], &[]).is_none());
        assert!(fuse([100.0, 50.0], &[]).is_none());
    }
}
