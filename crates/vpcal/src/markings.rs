//! Lane lines and their dashes in the scene's background, and the known lengths a marking
//! standard makes of them (`calibrate --markings PERIOD,LANE`).
//!
//! The bright bars of the background ([`vpcal_video::markings::bright_bars`]) that are long
//! and point at VP1 lie on lines along the road; bars at nearly the same angle about VP1 are
//! one lane line. Along a line through a vanishing point, the inverse of a pixel's distance to
//! it, `u = 1/t`, is an affine function of the distance along the road, so a dashed line's
//! dashes, equally spaced on the road, are equally spaced in `u` whatever the camera: a line
//! is dashed when the gaps between its dashes' `u` are whole multiples of one period (their
//! spread under [`DASH_PERIOD_MAX_CV`]). No focal length goes into finding them.
//!
//! With a standard (the dash period, line plus gap, and the lane width, metres) the lines
//! become known lengths: along each dashed line, its nearest and farthest dash a whole number
//! of periods apart; across, each lane between a dashed line and its neighbour. They are then
//! what `--scale-points` lengths are ([`crate::road_focal`]): lengths in two directions fix the
//! focal length and the scale. Without one, the lines are still reported with the period and
//! lane width they measure on the calibrated camera, to compare with the local standard.

use serde_json::{json, Value};
use vpcal_geom::camera::Calibration;
use vpcal_geom::solve::median;
use vpcal_geom::Point2;
use vpcal_video::markings::{bright_bars, Bar, BarOptions};

use crate::road::{KnownDistance, RoadMeasure, ScaleInput};

/// The largest angle between a bar's axis and the direction from it to VP1 for it to lie on a
/// line along the road, degrees: BrnoCompSpeed's reference VP1 puts the dashes of its 12
/// views' lane lines within 1.5°; a 15-px dash's axis is good to about 2°.
pub const LINE_ANGLE_TOL_DEG: f64 = 3.0;

/// A bar whose principal axis misses VP1 is still along the road where its spread across the
/// direction to VP1 is at most this multiple of its own width plus
/// [`ALIGNED_WIDTH_SLACK_PX`] (the short dashes of an oblique view: on BrnoCompSpeed's
/// session0_center their axes lean 8-30° off VP1).
pub const ALIGNED_WIDTH_FACTOR: f64 = 1.5;
pub const ALIGNED_WIDTH_SLACK_PX: f64 = 2.0;

/// Bars closer than this across (pixels, at the bar's distance from VP1) to the previous bar
/// of a line belong to it.
pub const LINE_GAP_PX: f64 = 4.0;

/// The least length of the bars of a line that is not dashed, pixels: shorter ones are
/// specks (a stain, a reflector) more often than lines.
pub const LINE_MIN_LENGTH_PX: f64 = 50.0;

/// The least length of a marking bar, and of its length over its width.
pub const BAR_MIN_LENGTH_PX: f64 = 6.0;
pub const BAR_MIN_ELONGATION: f64 = 2.5;

/// Pieces of a line this close along it (pixels, or this share of the stretch so far) are
/// one stretch: a worn dash breaks into pieces a few pixels apart, while the gaps between
/// dashes are longer than the dashes in every standard.
pub const SEGMENT_GAP_PX: f64 = 3.0;
pub const SEGMENT_GAP_SHARE: f64 = 0.3;

/// The fewest dashes of a dashed line.
pub const MIN_DASHES: usize = 4;

/// The largest spread of a dashed line's dash centres about their lattice, over the period
/// (in `u`): dashes painted to a standard and found to a pixel or two. BrnoCompSpeed's
/// dashed lines spread by 0.008-0.055 about theirs; the texture of a worn solid edge line
/// (session2_center) made a lattice of 0.09.
pub const DASH_PERIOD_MAX_CV: f64 = 0.07;

/// The least share of the lattice points between a dashed line's nearest and farthest dash
/// that hold a dash (a dash may be worn or hidden; texture fills few).
pub const DASH_MIN_FILL: f64 = 0.6;

/// A bar is on a lattice point when within this share of a period of it.
pub const DASH_LATTICE_TOL: f64 = 0.2;

/// The dashes of one line are the same length in `u` to this factor (a dash's ends are found
/// to a pixel or two, which is much of a far dash).
pub const DASH_LENGTH_RATIO: f64 = 1.6;

/// The dashes are at least this share of a line's pieces: a dashed line is mostly dashes,
/// while a worn solid line's specks fall on a lattice only here and there (4 of 13 on
/// BrnoCompSpeed's session3_center, 4 of 18 on session1_left).
pub const DASH_MIN_OF_PIECES: f64 = 0.6;

/// A dash is at least this share of its period, in the median over a line's dashes (a
/// fifth to a half in the standards above; specks of a worn line's texture that happen to
/// fall on a lattice are much shorter).
pub const DASH_MIN_SHARE: f64 = 0.15;

/// A dash is at most this share of its period (dash over line plus gap: a third in the Czech,
/// German and UK motorway standards, a quarter in the US).
pub const DASH_MAX_SHARE: f64 = 0.75;

/// Dashed lines with a period at least this share of the longest are lane lines of the
/// standard (see [`standard_spans`]).
pub const STANDARD_PERIOD_SHARE: f64 = 0.85;

/// A lane is measured again where both its lines are seen farthest, when that is at most this
/// share of the nearest's distance from VP1: the lane is the same width there, so a horizon
/// that is turned shows as a misfit, which widens the focal length's interval.
pub const LANE_FAR_SHARE: f64 = 0.6;

/// Lane widths within this factor of the narrowest of a group count as one width (a missed
/// lane line doubles a lane, a shoulder or a median is no lane).
pub const LANE_WIDTH_TOLERANCE: f64 = 1.33;

/// Two lines closer than this many of their painted widths bound no lane: lanes are at least
/// 2.5 m wide and lane lines at most 0.3 m (lane separators are 0.10-0.25 m in the European,
/// British and US standards), at least 8 widths, and blur widens a thin line's bright bar by
/// a pixel or two. Measured (`gap_over_paint`): true lanes 12.5-33 on BrnoCompSpeed; the two
/// edges of one wide dash (a line wider than the top-hat's window comes out hollow) and a
/// line of specks beside a dashed line 1.7 and 4.3.
pub const LANE_MIN_PAINT_WIDTHS: f64 = 6.0;

/// The largest ratio of `u` between two edges of one painted line at the same depth: a line
/// up to 0.5 m wide at least 5 m to the side of the camera (the lanes beside it are then
/// 2.5 m or more farther, a factor of 1.1 for lines up to 25 m to the side).
pub const ECHO_MAX_FACTOR: f64 = 1.1;

/// A marking standard: the period of a dashed lane line (one line and one gap) and the lane
/// width, metres. For example 9 m (3 + 6) and 3.5-3.75 m on Czech and UK motorways, 12.2 m
/// (10 + 30 ft) and 3.66 m on US freeways, 18 m (6 + 12) and 3.75 m on German motorways: read
/// the road's own standard.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MarkingStandard {
    pub period_m: f64,
    pub lane_width_m: f64,
}

impl std::str::FromStr for MarkingStandard {
    type Err = String;

    fn from_str(s: &str) -> Result<MarkingStandard, String> {
        if let Some((_, _, standard)) = STANDARDS
            .iter()
            .find(|(key, _, _)| key.eq_ignore_ascii_case(s.trim()))
        {
            return Ok(*standard);
        }
        let v: Vec<Option<f64>> = s
            .split(',')
            .map(|p| {
                p.trim()
                    .parse::<f64>()
                    .ok()
                    .filter(|v| v.is_finite() && *v > 0.0)
            })
            .collect();
        match v[..] {
            [Some(period_m), Some(lane_width_m)] => Ok(MarkingStandard {
                period_m,
                lane_width_m,
            }),
            _ => Err(format!(
                "expected the dash period (line + gap) and the lane width in metres, two \
                 positive numbers PERIOD,LANE (e.g. 9,3.5), or one of the standards {}, got \
                 {s:?}",
                standard_keys()
            )),
        }
    }
}

/// Lane-line standards of motorways in several countries (national regulations' figures,
/// rounded): a key (what `--markings` also takes), a name, the dashed lane line's period
/// (line + gap) and the lane width. A road
/// may follow none of them; the list says what the lane lines would imply under each
/// ([`focal_by_standard`]), it does not choose.
pub const STANDARDS: [(&str, &str, MarkingStandard); 8] = [
    (
        "cz",
        "3 + 6 m, 3.5 m lanes (e.g. Czechia)",
        MarkingStandard {
            period_m: 9.0,
            lane_width_m: 3.5,
        },
    ),
    (
        "uk",
        "2 + 7 m, 3.65 m lanes (UK motorways)",
        MarkingStandard {
            period_m: 9.0,
            lane_width_m: 3.65,
        },
    ),
    (
        "nl",
        "3 + 9 m, 3.5 m lanes (e.g. Netherlands, Australia)",
        MarkingStandard {
            period_m: 12.0,
            lane_width_m: 3.5,
        },
    ),
    (
        "us",
        "10 + 30 ft, 12 ft lanes (US, MUTCD)",
        MarkingStandard {
            period_m: 12.19,
            lane_width_m: 3.66,
        },
    ),
    (
        "fr",
        "3 + 10 m, 3.5 m lanes (France)",
        MarkingStandard {
            period_m: 13.0,
            lane_width_m: 3.5,
        },
    ),
    (
        "cn",
        "6 + 9 m, 3.75 m lanes (China expressways)",
        MarkingStandard {
            period_m: 15.0,
            lane_width_m: 3.75,
        },
    ),
    (
        "de",
        "6 + 12 m, 3.75 m lanes (German motorways)",
        MarkingStandard {
            period_m: 18.0,
            lane_width_m: 3.75,
        },
    ),
    (
        "jp",
        "8 + 12 m, 3.5 m lanes (Japan expressways)",
        MarkingStandard {
            period_m: 20.0,
            lane_width_m: 3.5,
        },
    ),
];

/// The keys of [`STANDARDS`] with what each stands for, for messages: `cz (3 + 6 m, ...), ...`.
pub fn standard_keys() -> String {
    STANDARDS
        .iter()
        .map(|(key, name, _)| format!("{key} ({name})"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// The focal length the lane lines `lines` imply on camera `cal` (its VP1 and horizon held,
/// spread `spread`, frames `width` pixels wide) under each of [`STANDARDS`]: key, name, period,
/// lane width, and the fit's focal length, 68 % interval and misfit, or why none. Empty
/// without a dashed line and a lane (the ratio of a length along the road to one across it
/// is what carries `f`).
pub fn focal_by_standard(
    lines: &[LaneLine],
    cal: &Calibration,
    spread: crate::road_focal::CameraSpread,
    width: f64,
) -> Vec<Value> {
    use crate::road_focal::{fit_focal_from_lengths, LengthFocalFit};
    if standard_spans(lines, cal).is_empty() || lanes(lines, cal).is_empty() {
        return Vec::new();
    }
    STANDARDS
        .iter()
        .map(|(key, name, std)| {
            let lengths = standard_lengths(lines, cal, std);
            let mut row = json!({
                "key": key,
                "standard": name,
                "period_m": std.period_m,
                "lane_width_m": std.lane_width_m,
                "focal_px": Value::Null,
            });
            match fit_focal_from_lengths(cal, &lengths, spread, width) {
                LengthFocalFit::Measured(m) => {
                    row["focal_px"] = json!(m.focal_px);
                    row["interval_px"] = json!(m.interval_px);
                    row["chi2"] = json!(m.chi2);
                    row["dof"] = json!(m.dof);
                }
                LengthFocalFit::NotIdentified(why) | LengthFocalFit::Inconsistent(why) => {
                    row["why"] = json!(why);
                }
            }
            row
        })
        .collect()
}

/// The dashes of a dashed line.
#[derive(Debug, Clone, PartialEq)]
pub struct Dashes {
    /// The dashes' centres in `u = 1/t` (`t`: pixels from VP1), nearest (largest) first.
    pub centres_u: Vec<f64>,
    /// The period in `u`.
    pub period_u: f64,
    /// The spread of the gaps over the period.
    pub cv: f64,
    /// The dashes' median length in `u` over the period: the painted share of the line,
    /// which no camera changes (3 + 6 m: 0.33).
    pub duty: f64,
}

impl Dashes {
    /// Whole periods between the nearest and the farthest dash.
    pub fn span_periods(&self) -> f64 {
        let (near, far) = (self.centres_u[0], self.centres_u[self.centres_u.len() - 1]);
        ((near - far) / self.period_u).round()
    }
}

/// One lane line: the bars along one direction from VP1.
#[derive(Debug, Clone, PartialEq)]
pub struct LaneLine {
    /// The unit direction from VP1 along the line (towards the camera).
    pub direction: Point2,
    /// Its bars, as found.
    pub bars: Vec<Bar>,
    /// The pixels from VP1 of its nearest point.
    pub near_t: f64,
    /// The pixels from VP1 of its farthest point.
    pub far_t: f64,
    pub dashes: Option<Dashes>,
}

impl LaneLine {
    /// The pixel of the line at `u = 1/t`.
    pub fn pixel_at(&self, vp1: Point2, u: f64) -> Point2 {
        Point2::new(vp1.x + self.direction.x / u, vp1.y + self.direction.y / u)
    }
}

fn unit(p: Point2) -> Option<Point2> {
    let n = p.norm();
    (n > 0.0 && n.is_finite()).then(|| Point2::new(p.x / n, p.y / n))
}

/// The stretches of one line that `bars` cover, `[near, far]` pixels from VP1 (`t`), far
/// first: bars that overlap or nearly touch along the line (a worn dash found in pieces) are
/// one stretch.
fn segments(bars: &[Bar], vp1: Point2) -> Vec<[f64; 2]> {
    let dist = |p: Point2| (p - vp1).norm();
    let mut spans: Vec<[f64; 2]> = bars
        .iter()
        .map(|b| {
            let (a, c) = (dist(b.ends[0]), dist(b.ends[1]));
            [a.min(c), a.max(c)]
        })
        .filter(|s| s[0] > 0.0 && s[1].is_finite())
        .collect();
    spans.sort_by(|a, b| a[0].total_cmp(&b[0]));
    let mut merged: Vec<[f64; 2]> = Vec::new();
    for s in spans {
        match merged.last_mut() {
            Some(m) if s[0] - m[1] <= SEGMENT_GAP_PX.max(SEGMENT_GAP_SHARE * (m[1] - m[0])) => {
                m[1] = m[1].max(s[1]);
            }
            _ => merged.push(s),
        }
    }
    merged
}

/// The dashes of `bars` (one line's, seen from `vp1`), where they are regular: the most bars
/// whose centres lie on one lattice `u0 + k P` in `u` (within [`DASH_LATTICE_TOL`] of a
/// period) and whose lengths in `u` (the same on the road for every dash of a standard) agree
/// within [`DASH_LENGTH_RATIO`]; each lattice is seeded by two neighbouring bars. Other bars
/// on the line (a stain, a patch, a solid line's pieces) are left out.
fn dashes(bars: &[Bar], vp1: Point2) -> Option<Dashes> {
    let segments = segments(bars, vp1);
    if segments.len() < MIN_DASHES {
        return None;
    }
    // (centre, length) in u, nearest first.
    let mut items: Vec<(f64, f64)> = segments
        .iter()
        .map(|&[t0, t1]| {
            let (a, c) = (1.0 / t0, 1.0 / t1);
            (0.5 * (a + c), (a - c).abs())
        })
        .filter(|(u, du)| u.is_finite() && du.is_finite())
        .collect();
    items.sort_by(|a, b| b.0.total_cmp(&a.0));
    let mut best: Option<(usize, Vec<(f64, f64)>)> = None;
    for seed in items.windows(2) {
        let ((u0, du0), (u1, _)) = (seed[0], seed[1]);
        let period = u0 - u1;
        if period.is_nan() || period <= 0.0 || du0 > DASH_MAX_SHARE * period {
            continue;
        }
        // One bar per lattice point: the nearest to it.
        let mut on: Vec<(i64, f64, f64)> = Vec::new();
        for &(u, du) in &items {
            let k = (u0 - u) / period;
            let off = (k - k.round()).abs();
            let like = du <= du0 * DASH_LENGTH_RATIO && du * DASH_LENGTH_RATIO >= du0;
            if off <= DASH_LATTICE_TOL && like {
                let k = k.round() as i64;
                match on.iter_mut().find(|m| m.0 == k) {
                    Some(m) if off < ((u0 - m.1) / period - k as f64).abs() => *m = (k, u, du),
                    Some(_) => {}
                    None => on.push((k, u, du)),
                }
            }
        }
        if on.len() >= MIN_DASHES && best.as_ref().is_none_or(|b| on.len() > b.0) {
            let members = on.iter().map(|m| (m.1, m.2)).collect();
            best = Some((on.len(), members));
        }
    }
    let (_, mut members) = best?;
    members.sort_by(|a, b| b.0.total_cmp(&a.0));
    // Least squares of u = a - k P over the members, k from the seed period.
    let rough = members[0].0 - members[1].0;
    let ks: Vec<f64> = members
        .iter()
        .map(|m| ((members[0].0 - m.0) / rough).round())
        .collect();
    let n = ks.len() as f64;
    let (mk, mu) = (
        ks.iter().sum::<f64>() / n,
        members.iter().map(|m| m.0).sum::<f64>() / n,
    );
    let sxx: f64 = ks.iter().map(|k| (k - mk).powi(2)).sum();
    let sxy: f64 = ks
        .iter()
        .zip(&members)
        .map(|(k, m)| (k - mk) * (m.0 - mu))
        .sum();
    if sxx.is_nan() || sxx <= 0.0 {
        return None;
    }
    let period = -sxy / sxx;
    let residual = (ks
        .iter()
        .zip(&members)
        .map(|(k, m)| (m.0 - (mu - period * (k - mk))).powi(2))
        .sum::<f64>()
        / n)
        .sqrt();
    let cv = residual / period;
    let span = ks[ks.len() - 1] - ks[0];
    let filled = n / (span + 1.0);
    let duties: Vec<f64> = members.iter().map(|m| m.1 / period).collect();
    let duty = median(&duties).unwrap_or(f64::NAN);
    let regular = cv < DASH_PERIOD_MAX_CV
        && filled >= DASH_MIN_FILL
        && duty >= DASH_MIN_SHARE
        && n >= DASH_MIN_OF_PIECES * items.len() as f64;
    (period > 0.0 && regular && span >= (MIN_DASHES - 1) as f64).then(|| Dashes {
        centres_u: members.iter().map(|m| m.0).collect(),
        period_u: period,
        cv,
        duty,
    })
}

/// The lane lines `bars` show for a road whose VP1 is `vp1`, in order of their angle about
/// VP1. See the module docs.
pub fn lane_lines(bars: &[Bar], vp1: Point2) -> Vec<LaneLine> {
    let tol = LINE_ANGLE_TOL_DEG.to_radians().sin();
    let mut along: Vec<(f64, f64, Bar)> = bars
        .iter()
        .filter(|b| {
            b.length >= BAR_MIN_LENGTH_PX && b.length >= BAR_MIN_ELONGATION * b.width.max(1.0)
        })
        .filter_map(|b| {
            let d = Point2::new(b.centre.x - vp1.x, b.centre.y - vp1.y);
            let t = d.norm();
            let dir = unit(d)?;
            let cross = (dir.x * b.axis.y - dir.y * b.axis.x).abs();
            // A short dash seen obliquely is a sheared parallelogram whose principal axis
            // leans towards its slanted ends; its spread across the direction to VP1 is
            // then still its stripe's width.
            let across = b.extent_along(Point2::new(-dir.y, dir.x));
            let radial = b.extent_along(dir);
            let thin = across <= ALIGNED_WIDTH_FACTOR * b.width + ALIGNED_WIDTH_SLACK_PX
                && radial >= BAR_MIN_ELONGATION * across.max(1.0);
            (cross <= tol || thin).then(|| (dir.y.atan2(dir.x), t, *b))
        })
        .collect();
    along.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut groups: Vec<Vec<(f64, f64, Bar)>> = Vec::new();
    for bar in along {
        match groups.last_mut() {
            Some(g) if (bar.0 - g[g.len() - 1].0).abs() * bar.1 <= LINE_GAP_PX => g.push(bar),
            _ => groups.push(vec![bar]),
        }
    }
    let mut lines: Vec<LaneLine> = groups
        .into_iter()
        .filter_map(|g| line_of(g.into_iter().map(|(_, _, b)| b).collect(), vp1))
        .collect();
    let echo: Vec<bool> = lines
        .iter()
        .map(|a| {
            a.dashes.as_ref().is_some_and(|da| {
                lines
                    .iter()
                    .filter_map(|b| b.dashes.as_ref())
                    .any(|db| echoes(da, db))
            })
        })
        .collect();
    let mut echo = echo.into_iter();
    lines.retain(|_| !echo.next().unwrap_or(false));
    lines
        .into_iter()
        .filter(|l| {
            l.dashes.is_some() || l.bars.iter().map(|b| b.length).sum::<f64>() >= LINE_MIN_LENGTH_PX
        })
        .collect()
}

/// The line of `bars` (one group about VP1): its direction, extent and dashes.
fn line_of(bars: Vec<Bar>, vp1: Point2) -> Option<LaneLine> {
    let sum = bars
        .iter()
        .fold(Point2::new(0.0, 0.0), |s, b| s + (b.centre - vp1));
    let direction = unit(sum)?;
    let ts = || bars.iter().flat_map(|b| b.ends).map(|p| (p - vp1).norm());
    let near_t = ts().fold(0.0, f64::max);
    let far_t = ts().fold(f64::INFINITY, f64::min);
    let dashes = dashes(&bars, vp1);
    Some(LaneLine {
        direction,
        bars,
        near_t,
        far_t,
        dashes,
    })
}

/// Whether dashed line `a` is an echo of dashed line `b`: the other edge of the same dashes
/// (a dash wider than the top-hat's window comes out as its two edges), found on every other
/// dash only. At one depth, `u` on two lines through VP1 differs by a constant factor, the
/// ratio of their offsets from the camera; for the two edges of one painted line that factor
/// is within [`ECHO_MAX_FACTOR`] of 1. So `a` echoes `b` when, for some factor that close to
/// 1, every dash of `a` lies on `b`'s lattice and `a`'s period is a whole multiple (2 or
/// more) of `b`'s.
fn echoes(a: &Dashes, b: &Dashes) -> bool {
    const STEPS: i32 = 200;
    (-STEPS..=STEPS).any(|i| {
        let c = ECHO_MAX_FACTOR.powf(f64::from(i) / f64::from(STEPS));
        let k = a.period_u / c / b.period_u;
        k.round() >= 2.0
            && (k - k.round()).abs() <= DASH_LATTICE_TOL
            && a.centres_u.iter().all(|u| {
                let m = (u / c - b.centres_u[0]) / b.period_u;
                (m - m.round()).abs() <= DASH_LATTICE_TOL
            })
    })
}

/// The lane lines of background `grey` for a road whose VP1 is `vp1` ([`bright_bars`] with
/// its default options, then [`lane_lines`]).
pub fn lines_in(grey: &image::GrayImage, vp1: Point2) -> Vec<LaneLine> {
    lane_lines(&bright_bars(grey, None, &BarOptions::default()), vp1)
}

/// A lane: two neighbouring lines, at least one of them dashed, and a pixel on each where
/// both are seen nearest the camera; and, where both are seen far enough away too, a pair
/// there ([`LANE_FAR_SHARE`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Lane {
    pub lines: [usize; 2],
    pub pixels: [Point2; 2],
    pub far_pixels: Option<[Point2; 2]>,
    /// Its width on the camera it was found with (at `pixels`), road units.
    pub width_units: f64,
}

/// How many of their painted widths two lines through `vp1` lie apart: at each bar of either
/// line, the gap between the lines there over the bar's width, the median of these. Both
/// grow in proportion to the distance from VP1, so the ratio holds along the lines and on
/// any camera.
pub fn gap_over_paint(a: &LaneLine, b: &LaneLine, vp1: Point2) -> f64 {
    let sin = (a.direction.x * b.direction.y - a.direction.y * b.direction.x).abs();
    let ratios: Vec<f64> = a
        .bars
        .iter()
        .chain(&b.bars)
        .filter(|bar| bar.width > 0.0)
        .map(|bar| (bar.centre - vp1).norm() * sin / bar.width)
        .collect();
    median(&ratios).unwrap_or(f64::NAN)
}

/// The lanes of `lines` on camera `cal`: neighbouring lines (at least
/// [`LANE_MIN_PAINT_WIDTHS`] apart) with a dashed lane line of the standard
/// ([`standard_spans`]) among them, of the most common width (within
/// [`LANE_WIDTH_TOLERANCE`]; the narrowest such group on a tie). Ratios of widths across the
/// road do not depend on the focal length, so this choice holds on any camera with the same
/// VP1 and horizon.
pub fn lanes(lines: &[LaneLine], cal: &Calibration) -> Vec<Lane> {
    let standard: Vec<usize> = standard_spans(lines, cal).iter().map(|s| s.line).collect();
    // Each line and the next one at least a lane's worth of painted widths away: a tyre
    // track or a second stripe hugging a line is one boundary with it, which the first of
    // them in the lines' order stands for.
    let apart =
        |i: usize, k: usize| gap_over_paint(&lines[i], &lines[k], cal.vp1) >= LANE_MIN_PAINT_WIDTHS;
    let neighbours = (0..lines.len())
        .filter(|&i| (0..i).all(|j| apart(j, i)))
        .filter_map(|i| (i + 1..lines.len()).find(|&k| apart(i, k)).map(|k| (i, k)));
    let all: Vec<Lane> = neighbours
        .filter(|(i, k)| standard.contains(i) || standard.contains(k))
        .filter_map(|(i, k)| {
            let w = [&lines[i], &lines[k]];
            // Where both lines are seen: nearest, and farthest.
            let (t_near, t_far) = (w[0].near_t.min(w[1].near_t), w[0].far_t.max(w[1].far_t));
            let at = |t: f64| [0, 1].map(|m| w[m].pixel_at(cal.vp1, 1.0 / t));
            let pixels = at(t_near);
            let (a, b) = (cal.road_point(pixels[0])?, cal.road_point(pixels[1])?);
            let width_units = (a[1] - b[1]).abs();
            let far_pixels = (t_far <= LANE_FAR_SHARE * t_near)
                .then(|| at(t_far))
                .filter(|p| p.iter().all(|q| cal.road_point(*q).is_some()));
            (width_units.is_finite() && width_units > 0.0).then_some(Lane {
                lines: [i, k],
                pixels,
                far_pixels,
                width_units,
            })
        })
        .collect();
    // The lanes are the most common width, the narrowest where two are as common: a missed
    // line makes a lane look twice as wide, a shoulder or a median wider, and both are rarer
    // than the lanes themselves (ratios of widths across the road do not depend on `f`).
    let within = |w: f64, from: f64| w >= from && w <= from * LANE_WIDTH_TOLERANCE;
    let from = all
        .iter()
        .map(|l| {
            let n = all
                .iter()
                .filter(|o| within(o.width_units, l.width_units))
                .count();
            (n, l.width_units)
        })
        .max_by(|a, b| a.0.cmp(&b.0).then(b.1.total_cmp(&a.1)))
        .map_or(f64::NAN, |(_, w)| w);
    all.into_iter()
        .filter(|l| within(l.width_units, from))
        .collect()
}

/// One dashed line's span on a camera: its nearest and farthest dash's pixels, the whole
/// periods between them, and the period in road units.
#[derive(Debug, Clone, Copy, PartialEq)]
struct DashSpan {
    line: usize,
    pixels: [Point2; 2],
    periods: f64,
    period_units: f64,
}

/// The spans of the dashed lines of `lines` on camera `cal` that are lane lines of the
/// standard: those whose period is within [`STANDARD_PERIOD_SHARE`] of the longest. Every
/// standard we know paints its lane lines with the longest period of its dashed lines (the
/// Czech and German auxiliary-lane lines are 1.5 + 1.5 m and 6 + 6 m beside lane lines of
/// 3 + 6 m and 6 + 12 m; the US dotted extensions 3 + 9 ft beside 10 + 30 ft), and ratios of
/// lengths along parallel lines do not depend on the focal length.
fn standard_spans(lines: &[LaneLine], cal: &Calibration) -> Vec<DashSpan> {
    let spans: Vec<DashSpan> = lines
        .iter()
        .enumerate()
        .filter_map(|(line, l)| {
            let d = l.dashes.as_ref()?;
            let (near, far) = (d.centres_u[0], d.centres_u[d.centres_u.len() - 1]);
            let pixels = [l.pixel_at(cal.vp1, near), l.pixel_at(cal.vp1, far)];
            let (a, b) = (cal.road_point(pixels[0])?, cal.road_point(pixels[1])?);
            let units = ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt();
            let periods = d.span_periods();
            (periods >= 1.0 && units > 0.0).then_some(DashSpan {
                line,
                pixels,
                periods,
                period_units: units / periods,
            })
        })
        .collect();
    let longest = spans.iter().map(|s| s.period_units).fold(0.0, f64::max);
    spans
        .into_iter()
        .filter(|s| s.period_units >= STANDARD_PERIOD_SHARE * longest)
        .collect()
}

/// The known lengths standard `std` makes of `lines` on camera `cal`: one distance along each
/// dashed line, one or two lane widths per lane ([`lanes`]).
pub fn standard_lengths(
    lines: &[LaneLine],
    cal: &Calibration,
    std: &MarkingStandard,
) -> Vec<ScaleInput> {
    let along = standard_spans(lines, cal).into_iter().map(|s| ScaleInput {
        kind: RoadMeasure::Distance,
        known: KnownDistance {
            p1: s.pixels[0],
            p2: s.pixels[1],
            distance_m: s.periods * std.period_m,
        },
    });
    let across = lanes(lines, cal).into_iter().flat_map(|l| {
        std::iter::once(l.pixels)
            .chain(l.far_pixels)
            .map(|[p1, p2]| ScaleInput {
                kind: RoadMeasure::LaneWidth,
                known: KnownDistance {
                    p1,
                    p2,
                    distance_m: std.lane_width_m,
                },
            })
    });
    along.chain(across).collect()
}

/// What `lines` measure on camera `cal` with metric `scale` (metres per road unit, if any):
/// the counts, the median dash period and lane width (metres with a scale, road units
/// without), for the calibration file's `evidence.markings`.
pub fn summary(lines: &[LaneLine], cal: &Calibration, scale: Option<f64>) -> Value {
    let spans = standard_spans(lines, cal);
    let widths: Vec<f64> = lanes(lines, cal).iter().map(|l| l.width_units).collect();
    let s = scale.unwrap_or(1.0);
    let periods: Vec<f64> = spans.iter().map(|x| x.period_units).collect();
    let period = median(&periods).map(|p| s * p);
    let lane = median(&widths).map(|w| s * w);
    let unit = if scale.is_some() { "m" } else { "road_units" };
    json!({
        "lines": lines.len(),
        "dashed_lines": lines.iter().filter(|l| l.dashes.is_some()).count(),
        "standard_dashed_lines": spans.len(),
        "lanes": widths.len(),
        "unit": unit,
        "dash_period": period,
        "lane_width": lane,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use vpcal_geom::camera::Calibration;

    /// A 1280x720 camera with focal `f`, 8 m above a road whose lanes run along y.
    fn camera(f: f64) -> Calibration {
        let pp = Point2::new(640.0, 360.0);
        let vp1 = Point2::new(700.0, 100.0);
        let horizon = vpcal_geom::Line::through(vp1, Point2::new(1700.0, 110.0))
            .unwrap_or_else(|| unreachable!());
        let vp2 = vpcal_geom::camera::orthogonal_vp_on_line(vp1, horizon, f, pp)
            .unwrap_or_else(|| unreachable!());
        Calibration::from_vps(vp1, vp2, pp).unwrap_or_else(|e| panic!("{e}"))
    }

    /// Metres per road unit for a camera 8 m above the road.
    fn scale(cal: &Calibration) -> f64 {
        8.0 / cal.plane_distance()
    }

    /// A bar between two road points (units), 3 px wide.
    fn bar(cal: &Calibration, a: [f64; 2], b: [f64; 2]) -> Bar {
        let (p, q) = (
            cal.pixel_of_road_point(a).unwrap_or_else(|| unreachable!()),
            cal.pixel_of_road_point(b).unwrap_or_else(|| unreachable!()),
        );
        let axis = unit(Point2::new(q.x - p.x, q.y - p.y)).unwrap_or(Point2::new(1.0, 0.0));
        let len = ((q.x - p.x).powi(2) + (q.y - p.y).powi(2)).sqrt();
        Bar {
            centre: Point2::new(0.5 * (p.x + q.x), 0.5 * (p.y + q.y)),
            axis,
            length: len,
            width: 3.0,
            ends: [p, q],
            pixels: len as usize * 3,
            cov: {
                let (l2, w2) = (len * len / 12.0, 9.0 / 12.0);
                let (c, s) = (axis.x, axis.y);
                [
                    c * c * l2 + s * s * w2,
                    c * s * (l2 - w2),
                    s * s * l2 + c * c * w2,
                ]
            },
        }
    }

    /// Two dashed lines (3 m dashes every 9 m) between three solid lines, 3.5 m lanes, on
    /// camera `cal` whose scale is `s` metres per unit.
    fn scene(cal: &Calibration, s: f64) -> Vec<Bar> {
        let m = |v: f64| v / s;
        let mut bars = Vec::new();
        for lane in 0..4 {
            let x = m(-7.0 + 3.5 * f64::from(lane));
            if lane == 0 || lane == 3 {
                bars.push(bar(cal, [m(10.0), x], [m(120.0), x]));
            } else {
                for k in 0..10 {
                    let y0 = m(12.0 + 9.0 * f64::from(k));
                    bars.push(bar(cal, [y0, x], [y0 + m(3.0), x]));
                }
            }
        }
        bars
    }

    #[test]
    fn dashed_and_solid_lines_are_told_apart_without_the_focal_length() {
        let cal = camera(1500.0);
        let s = scale(&cal);
        let lines = lane_lines(&scene(&cal, s), cal.vp1);
        assert_eq!(lines.len(), 4, "{lines:?}");
        let dashed: Vec<bool> = lines.iter().map(|l| l.dashes.is_some()).collect();
        assert_eq!(dashed.iter().filter(|d| **d).count(), 2, "{dashed:?}");
        for l in lines.iter().filter_map(|l| l.dashes.as_ref()) {
            // The far dashes are too short to tell from dots; the nearer ones follow on.
            assert!(l.centres_u.len() >= 5, "{l:?}");
            assert_eq!(l.span_periods(), (l.centres_u.len() - 1) as f64);
            assert!(l.cv < 0.02, "{}", l.cv);
        }
        // Three lanes, each 3.5 m on the true camera.
        let summary = summary(&lines, &cal, Some(s));
        assert_eq!(summary["lanes"], 3);
        let lane = summary["lane_width"].as_f64().unwrap_or(f64::NAN);
        let period = summary["dash_period"].as_f64().unwrap_or(f64::NAN);
        assert!((lane - 3.5).abs() < 0.02, "{summary}");
        assert!((period - 9.0).abs() < 0.05, "{summary}");
    }

    #[test]
    fn the_standard_makes_lengths_that_measure_the_focal_length() {
        let truth = camera(1500.0);
        let s = scale(&truth);
        let lines = lane_lines(&scene(&truth, s), truth.vp1);
        // Found on a camera with the same VP1 and horizon and the wrong focal length.
        let wrong =
            crate::road_focal::camera_with_focal(&truth, 3000.0).unwrap_or_else(|| unreachable!());
        let std = MarkingStandard {
            period_m: 9.0,
            lane_width_m: 3.5,
        };
        let inputs = standard_lengths(&lines, &wrong, &std);
        // Two lane lines, three lanes measured near and far.
        assert_eq!(inputs.len(), 8);
        let fit = crate::road_focal::fit_focal_from_lengths(
            &wrong,
            &inputs,
            crate::road_focal::CameraSpread::floored(None, 1280.0),
            1280.0,
        );
        let crate::road_focal::LengthFocalFit::Measured(m) = fit else {
            panic!("{fit:?}");
        };
        assert!((m.focal_px / 1500.0 - 1.0).abs() < 0.01, "{m:?}");
        // A horizon turned by 2°: no confident wrong focal length (here the view looks along
        // the road from high up, where the roll moves f by under 1 %).
        let dir = Point2::new(truth.horizon.0[1], -truth.horizon.0[0]);
        let (sn, cs) = 2f64.to_radians().sin_cos();
        let turned_dir = Point2::new(cs * dir.x - sn * dir.y, sn * dir.x + cs * dir.y);
        let horizon = vpcal_geom::Line::through_with_direction(truth.vp1, turned_dir)
            .unwrap_or_else(|| unreachable!());
        let vp2 = vpcal_geom::camera::orthogonal_vp_on_line(truth.vp1, horizon, 3000.0, truth.pp)
            .unwrap_or_else(|| unreachable!());
        let turned =
            Calibration::from_vps(truth.vp1, vp2, truth.pp).unwrap_or_else(|e| panic!("{e}"));
        let inputs = standard_lengths(&lines, &turned, &std);
        let fit = crate::road_focal::fit_focal_from_lengths(
            &turned,
            &inputs,
            crate::road_focal::CameraSpread::floored(None, 1280.0),
            1280.0,
        );
        let crate::road_focal::LengthFocalFit::Measured(t) = fit else {
            panic!("{fit:?}");
        };
        let covers = t.interval_px[0] <= 1500.0 && 1500.0 <= t.interval_px[1];
        assert!(covers && t.chi2 > m.chi2, "{t:?}");
    }

    /// The lane widths (metres) that `lanes` finds in `bars` on camera `cal` of scale `s`.
    fn lane_widths(bars: &[Bar], cal: &Calibration, s: f64) -> Vec<f64> {
        let lines = lane_lines(bars, cal.vp1);
        lanes(&lines, cal)
            .iter()
            .map(|l| s * l.width_units)
            .collect()
    }

    #[test]
    fn the_other_edge_of_wide_dashes_neither_doubles_the_period_nor_makes_a_lane() {
        let cal = camera(1500.0);
        let s = scale(&cal);
        let m = |v: f64| v / s;
        let mut bars = scene(&cal, s);
        // Dashes wider than the top-hat come out as two edges; here the second edge of the
        // first dashed line (0.3 m beside it) is found on every other dash only.
        for k in (0..10).step_by(2) {
            let (y0, x) = (m(12.0 + 9.0 * f64::from(k)), m(-3.5 + 0.3));
            bars.push(bar(&cal, [y0, x], [y0 + m(3.0), x]));
        }
        let lines = lane_lines(&bars, cal.vp1);
        let summary = summary(&lines, &cal, Some(s));
        let period = summary["dash_period"].as_f64().unwrap_or(f64::NAN);
        assert!((period - 9.0).abs() < 0.1, "{summary}");
        let widths = lane_widths(&bars, &cal, s);
        assert!(
            !widths.is_empty() && widths.iter().all(|w| (w - 3.5).abs() < 0.4),
            "{widths:?}"
        );
    }

    #[test]
    fn a_stripe_beside_a_line_bounds_no_lane() {
        let cal = camera(1500.0);
        let s = scale(&cal);
        let m = |v: f64| v / s;
        let mut bars = scene(&cal, s);
        // A tyre track or a second stripe one paint width beside the first solid line.
        let x = m(-7.0 + 0.12);
        bars.push(bar(&cal, [m(10.0), x], [m(120.0), x]));
        let lines = lane_lines(&bars, cal.vp1);
        assert_eq!(lines.len(), 5, "{lines:?}");
        let widths = lane_widths(&bars, &cal, s);
        assert_eq!(widths.len(), 3, "{widths:?}");
        assert!(widths.iter().all(|w| (w - 3.5).abs() < 0.2), "{widths:?}");
    }

    #[test]
    fn each_standard_implies_its_own_focal_length() {
        // 3 + 6 m dashes and 3.5 m lanes (the first standard), seen at 1500 px and read on
        // a camera with the right VP1 and horizon and the wrong focal length.
        let truth = camera(1500.0);
        let lines = lane_lines(&scene(&truth, scale(&truth)), truth.vp1);
        let wrong =
            crate::road_focal::camera_with_focal(&truth, 3000.0).unwrap_or_else(|| unreachable!());
        let spread = crate::road_focal::CameraSpread::floored(None, 1280.0);
        let rows = focal_by_standard(&lines, &wrong, spread, 1280.0);
        assert_eq!(rows.len(), STANDARDS.len());
        let focal = |i: usize| rows[i]["focal_px"].as_f64().unwrap_or(f64::NAN);
        assert!((focal(0) / 1500.0 - 1.0).abs() < 0.01, "{}", rows[0]);
        // A longer period for the same painted lattice stretches the road: every other
        // standard reads another focal length, and the one with the ratio furthest from
        // the truth's (20 m over 3.5 m against 9 over 3.5) the furthest.
        let off: Vec<f64> = (0..rows.len())
            .map(|i| (focal(i) / 1500.0).ln().abs())
            .collect();
        assert!(off[1..].iter().all(|o| *o > 0.01), "{off:?}");
        let furthest = (0..off.len()).max_by(|a, b| off[*a].total_cmp(&off[*b]));
        assert_eq!(furthest, Some(STANDARDS.len() - 1), "{off:?}");
        // Without a dashed line there is nothing to say.
        let solid: Vec<LaneLine> = lines.into_iter().filter(|l| l.dashes.is_none()).collect();
        assert!(focal_by_standard(&solid, &wrong, spread, 1280.0).is_empty());
    }

    #[test]
    fn lengths_no_camera_explains_are_reported() {
        let cal = camera(1500.0);
        let lines = lane_lines(&scene(&cal, scale(&cal)), cal.vp1);
        let lengths = |period_m: f64, lane_width_m: f64| {
            let std = MarkingStandard {
                period_m,
                lane_width_m,
            };
            standard_lengths(&lines, &cal, &std)
        };
        let disagreement = |l: &[ScaleInput]| crate::road_focal::disagreement(&cal, l, 1280.0);
        assert_eq!(disagreement(&lengths(9.0, 3.5)), None);
        // Lanes said to be ten times their width: no focal length makes them agree with the
        // dashes (one a tenth of it still fits, at ten times the focal length).
        let why = disagreement(&lengths(9.0, 35.0));
        assert!(why.is_some_and(|w| w.contains("no focal length")));
    }

    #[test]
    fn standards_are_read_with_their_errors() {
        let s: MarkingStandard = "9, 3.5".parse().unwrap_or_else(|e| panic!("{e}"));
        assert_eq!((s.period_m, s.lane_width_m), (9.0, 3.5));
        for bad in ["9", "9,0", "a,3", "9,3.5,1", "-9,3", "xx"] {
            let e = bad.parse::<MarkingStandard>().unwrap_err();
            assert!(
                e.contains("PERIOD,LANE") && e.contains("us (10 + 30 ft"),
                "{e}"
            );
        }
        // A standard by its key, in either case: the same figures as the table's.
        let us: MarkingStandard = "US".parse().unwrap_or_else(|e| panic!("{e}"));
        assert_eq!((us.period_m, us.lane_width_m), (12.19, 3.66));
        for (key, _, standard) in STANDARDS {
            assert_eq!(key.parse::<MarkingStandard>(), Ok(standard));
        }
    }
}
