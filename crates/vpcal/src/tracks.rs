//! Vehicle tracks and their speeds, from the pipeline's detector boxes.
//!
//! ```text
//! boxes (frame, detector box) -> link (vpcal-geom's box tracker) -> per track: contact
//!   points (box bottom centre) -> road points in metres (camera + scale) -> pieces of one
//!   vehicle stitched on the road -> speed (median of window line fits) with an uncertainty
//! ```
//!
//! - **Linking** is [`vpcal_geom::aggregate::tracks::link`], the tracker whose straight tracks
//!   give VP1: greedy, by the overlap of a box with where the track's last box is predicted
//!   to be at constant image velocity. It needs closely spaced frames: with `--every K` the
//!   boxes are K frames apart, the tracker's gap limit scales with that step (2.5 steps) and
//!   times stay right (they come from the true frame indices), but a vehicle moves K times as
//!   far between boxes and stops overlapping its prediction; on highway footage K above ~3
//!   breaks tracks apart. A track also breaks where the detector misses a vehicle for more than
//!   8 steps (the VP1 tracker's 2.5 are raised: learned detectors miss a vehicle for a few
//!   frames now and then). The boxes are all the detector's boxes of possibly moving
//!   vehicles, including those `--max-per-frame` keeps from the network (on a busy highway a
//!   quarter of them).
//! - **Cutting at jumps** ([`split_at_jumps`], with a camera and scale): where a vehicle's box
//!   goes missing for a frame or a few, the image tracker can take another vehicle's box that
//!   lies where the first was predicted. On the road that is a jump across of about a lane
//!   (no vehicle moves sideways by 1.5 m plus 1 m/s of the time between two boxes), and the
//!   track is cut there before the pieces are stitched. On the synthetic speed scenes with the
//!   motion detector: recall 0.854 → 0.874, false positives 22 → 16 (with the uncertainty
//!   limit of the BrnoCompSpeed `cars`, [`BCS_MAX_SPEED_REL_UNCERTAINTY`]).
//! - **Stitching** ([`stitch`], with a camera and scale): the tracker cuts a track where a box
//!   changes suddenly (the boxes of two vehicles merge or split, a vehicle is missed for a
//!   while). On the road the pieces of one vehicle line up: a piece that starts within a
//!   second after another ends, where the earlier one's velocity puts it (within 1 m across
//!   and 2 m + 10 % of the gap's distance along), continues it. On the synthetic speed scenes
//!   with the motion detector this joined about a third of the broken tracks (recall of the
//!   speed evaluation 0.77 → 0.81, false positives 28 → 20).
//! - **Contact point**: the bottom centre of the detector's box, where the vehicle meets the
//!   road (as in DubskaCalib's BrnoCompSpeed files). A box that touches the image border
//!   ([`TrackSettings::border_px`]) is cut off, so its bottom centre is not the contact point:
//!   such points stay in the track (flagged `clipped`) but get no road point, no speed
//!   contribution and are left out of the BrnoCompSpeed `cars`, which also leave out tracks
//!   of fewer unclipped points than a speed window (`output::write_bcs_system_with_tracks`).
//! - **Path** ([`lateral_path`], with a camera and scale): per point, the running median over
//!   ±0.5 s of the track's distances across the road, at the point's own distance along it.
//!   The BrnoCompSpeed `cars` put the vehicle there (the tracks file keeps the contact
//!   points): the official protocol finds a car's line crossings by a line through its 6
//!   points nearest each line, and for a track that ends short of a line the jitter of those
//!   points could carry the crossing out of the lanes. On the synthetic speed scenes with the
//!   motion detector: recall 0.874 → 0.919, false positives 16 → 12.
//! - **Road points**: [`Calibration::road_point`] (road frame: x along VP1, y across, origin
//!   under the camera) times the scale (metres per road unit). Without a scale, tracks have
//!   image points and times only.
//! - **Speed** ([`estimate_speed`]): the road points are projected on the track's direction
//!   of travel (the line through its first and last thirds), a least-squares line of that
//!   distance against time is fitted over every window of [`TrackSettings::window_points`]
//!   consecutive points, and the speed is the median of the windows' slopes (robust to box
//!   jitter and to a few bad boxes). Its uncertainty is the standard error of that median:
//!   `max(1.4826 · MAD of the window speeds, median of the windows' own slope errors) /
//!   sqrt(n_independent)`, with `n_independent = points / window_points` (overlapping windows
//!   are not independent; a single window has no spread, only its residuals), combined with
//!   the pixel grid's part ([`pixel_speed_floor_kmh`]), so it is never zero. The
//!   fit over the whole track is reported too (`speed_fit_kmh`); the two differ when the
//!   vehicle accelerates.
//! - **Size**: not estimated. [`vpcal_geom::vehicle_dims`] fits a cuboid to a track's boxes
//!   and gets synthetic vehicles' lengths within a few percent, but on the real highway clip
//!   `bgslibrary_video02` (YOLOX boxes of 20-40 px, focal length known to ±20 %) its lengths
//!   spread from 0.4 to 40 m, so tracks do not report it.
//! - **Lane** ([`cluster_lanes`]): the vehicles' lateral positions (`lateral_m`, the median
//!   road y of their contact points) cluster around the lanes; lanes are the modes of their
//!   density, found for each direction of travel on its own (two carriageways are not one set
//!   of lanes), numbered 1, 2, ... in the order of the road frame's y. A track farther than
//!   a lane spacing from every lane is in none; on a curved road there are no lanes (the
//!   straight road frame's y is not a distance across a curve). The lane markings are not
//!   seen: a lane no vehicle drove in is not counted, and lanes closer than
//!   [`MIN_LANE_SPACING_M`] are one.
//! - **Direction**: `towards_vp1` when the vehicle drives towards VP1 (road x grows),
//!   `from_vp1` the other way.

use vpcal_formats::bcs::SystemCar;
use vpcal_geom::aggregate::tracks::{link, TrackOptions};
use vpcal_geom::camera::Calibration;
use vpcal_geom::{BoxPx, Point2};

use crate::pipeline::{TrackBox, VehicleRecord};

/// How tracks are built and speeds measured.
#[derive(Debug, Clone, PartialEq)]
pub struct TrackSettings {
    /// The box tracker's settings.
    pub link: TrackOptions,
    /// Tracks of fewer boxes are dropped.
    pub min_points: usize,
    /// Points per speed window (at 25 frames/s, 10 points are 0.4 s).
    pub window_points: usize,
    /// A box whose edge is within this many pixels of the image border is clipped.
    pub border_px: f64,
    /// When the pieces of one vehicle's track are joined.
    pub stitch: StitchSettings,
    /// Cluster the tracks into lanes (off on a curved road, where distances across a
    /// straight road frame are no lanes).
    pub lanes: bool,
}

/// When [`stitch`] joins two track pieces: the later one starts within `max_gap_s` after the
/// earlier one ends, where the earlier one's constant-velocity motion on the road predicts it,
/// within `max_lateral_m` across its direction and `along_m + along_frac · distance travelled
/// in the gap` along it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StitchSettings {
    pub max_gap_s: f64,
    pub max_lateral_m: f64,
    pub along_m: f64,
    pub along_frac: f64,
    /// A piece is cut where its road point moves across the road by more than
    /// `jump_lateral_m + jump_lateral_speed · (time between the points)` from one box to the
    /// next (the tracker took another vehicle's box) before the pieces are joined.
    pub jump_lateral_m: f64,
    pub jump_lateral_speed: f64,
}

impl Default for StitchSettings {
    fn default() -> StitchSettings {
        StitchSettings {
            // The box tracker bridges gaps of 8 frames in the image; on the road a vehicle can
            // be followed further (a second at 25 frames/s).
            max_gap_s: 1.0,
            // Half a lane: a vehicle in the next lane is about 3.5 m away.
            max_lateral_m: 1.0,
            // Contact points jitter by a few decimetres and a short piece's speed is known
            // to ~10 %.
            along_m: 2.0,
            along_frac: 0.1,
            jump_lateral_m: 1.5,
            jump_lateral_speed: 1.0,
        }
    }
}

impl Default for TrackSettings {
    fn default() -> TrackSettings {
        TrackSettings {
            // A learned detector misses a vehicle for a few frames now and then (YOLOX-nano on
            // the synthetic highways: runs of 3-5 frames); the VP1 tracker's 2.5 steps would
            // cut the track there. The constant-velocity prediction bridges 8.
            link: TrackOptions {
                max_gap_steps: 8.0,
                ..TrackOptions::default()
            },
            min_points: 3,
            window_points: 10,
            border_px: 2.0,
            stitch: StitchSettings::default(),
            lanes: true,
        }
    }
}

/// One box of a track.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackPoint {
    /// 0-based frame index in the source.
    pub frame: u64,
    /// `frame / fps`, seconds.
    pub time_s: f64,
    /// The contact point (box bottom centre), frame pixels.
    pub image: Point2,
    /// The box touches the image border: `image` is not the contact point.
    pub clipped: bool,
    /// Road-frame point under `image`, metres (with a scale, for unclipped points).
    pub road_m: Option<[f64; 2]>,
}

/// A speed with its uncertainty.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpeedEstimate {
    /// Median of the window speeds, km/h.
    pub kmh: f64,
    /// Standard error of `kmh` (the window speeds' spread, their residuals and the pixel grid;
    /// module docs), km/h: never zero for a measured track.
    pub uncertainty_kmh: f64,
    /// Slope of one line fitted to the whole track, km/h.
    pub fit_kmh: f64,
    /// Windows measured.
    pub windows: usize,
}

/// A linked vehicle track.
#[derive(Debug, Clone, PartialEq)]
pub struct VehicleTrack {
    /// 1-based, in the order of the tracks' first frames.
    pub id: u64,
    pub points: Vec<TrackPoint>,
    /// With a scale and enough unclipped points.
    pub speed: Option<SpeedEstimate>,
    /// Where across the road the vehicle drove, metres (with a scale): the median road y of
    /// its unclipped contact points.
    pub lateral_m: Option<f64>,
    /// 1-based lane ([`cluster_lanes`]), with a lateral position.
    pub lane: Option<usize>,
    /// With a scale and a moving track: `true` when it drives towards VP1.
    pub towards_vp1: Option<bool>,
    /// Per point (empty without a camera, or with fewer than [`MIN_PATH_POINTS`] road
    /// points): the pixel of the road point at the point's distance along the road and the
    /// track's fitted distance across it ([`lateral_path`]), `None` for points without a road
    /// point. The BrnoCompSpeed cars put the vehicle there.
    pub path: Vec<Option<Point2>>,
}

/// A track goes into the BrnoCompSpeed `cars` only when its speed's standard error is at most
/// this share of the speed (`output::bcs_cars`): the pieces of two vehicles one box held
/// (merged neighbours) give window speeds that disagree. On the six synthetic speed scenes
/// with the motion detector the tracks matched to a vehicle had 0.1-2.1 % (median 0.7 %)
/// except two that were mostly another vehicle's (15 %, 17 %; errors of 14 and 16 km/h). On
/// the real 320x240 highway clips (motion detector, automatic scale) the tracks' median is
/// 2.2 % (`bgslibrary_video02`) and 0.9 % (CDnet), and the limit left out 9 of 80 and 4 of
/// 39, mostly speeds the road's other vehicles do not drive (19-48 km/h where the kept ones
/// read 53-73). The tracks file keeps every track with its uncertainty.
pub const BCS_MAX_SPEED_REL_UNCERTAINTY: f64 = 0.10;

/// Kernel width of the lateral positions' density, metres: the scatter of vehicles' contact
/// points within a lane (lane keeping, box jitter) is a few decimetres.
pub const LANE_BANDWIDTH_M: f64 = 0.5;

/// Density modes closer than this are one lane, metres (the narrowest traffic lanes, urban
/// streets, are about 2.5-2.75 m wide; motorway lanes 3.5-3.75 m).
pub const MIN_LANE_SPACING_M: f64 = 2.2;

/// A lane needs this much of the lateral positions' kernel density at its centre: about two
/// vehicles (one vehicle alone, a lane change or a bad fit, is not a lane).
pub const MIN_LANE_DENSITY: f64 = 1.2;

/// A lane's density must fall below this share of its peak on both sides within
/// [`MIN_LANE_SPACING_M`]. Between two lanes 3.5 m apart, with vehicles scattered a few
/// decimetres, it falls to a few per cent; positions spread evenly across 20-30 m (a curve or
/// an assumed focal length seen through a straight road frame, a corpus clip's 16 "lanes"
/// 1.5-3 m apart) leave dips of 10-30 %, which are noise, not lanes.
pub const LANE_VALLEY_SHARE: f64 = 0.5;

/// How far from the supported positions' median a position may lie and still count towards
/// the lanes' density, metres. The widest roads (2 x 8 lanes with shoulders and a median) are
/// under 100 m across; a position farther off is a bad contact point (near the horizon a pixel
/// spans kilometres), and the density's grid must not stretch to it.
pub const LANE_SEARCH_HALF_WIDTH_M: f64 = 250.0;

/// The lane of each lateral position (metres; NaN gets none): the modes of the density of
/// the positions marked in `support` (within [`LANE_SEARCH_HALF_WIDTH_M`] of their median) (a Gaussian kernel of [`LANE_BANDWIDTH_M`]) that hold at
/// least a tenth of the highest mode's density and [`MIN_LANE_DENSITY`] and stand out
/// ([`LANE_VALLEY_SHARE`]), merged when closer than [`MIN_LANE_SPACING_M`] (the denser one
/// stays), and the supported positions at least that far from every mode and every other
/// position (a lane seen once); every position goes to its nearest mode, lanes numbered 1,
/// 2, ... by position.
pub fn cluster_lanes(lateral_m: &[f64], support: &[bool]) -> Vec<Option<usize>> {
    let finite: Vec<f64> = lateral_m
        .iter()
        .zip(support)
        .filter(|(v, s)| **s && v.is_finite())
        .map(|(v, _)| *v)
        .collect();
    let middle = vpcal_geom::solve::median(&finite).unwrap_or(0.0);
    let finite: Vec<f64> = finite
        .into_iter()
        .filter(|v| (v - middle).abs() <= LANE_SEARCH_HALF_WIDTH_M)
        .collect();
    let (Some(lo), Some(hi)) = (
        finite.iter().copied().reduce(f64::min),
        finite.iter().copied().reduce(f64::max),
    ) else {
        return vec![None; lateral_m.len()];
    };
    let step = 0.05;
    let (lo, hi) = (lo - 3.0 * LANE_BANDWIDTH_M, hi + 3.0 * LANE_BANDWIDTH_M);
    let n = ((hi - lo) / step).ceil() as usize + 1;
    let density: Vec<f64> = (0..n)
        .map(|i| {
            let x = lo + i as f64 * step;
            finite
                .iter()
                .map(|v| (-0.5 * ((x - v) / LANE_BANDWIDTH_M).powi(2)).exp())
                .sum()
        })
        .collect();
    let top = density.iter().copied().fold(0.0, f64::max);
    let least = (0.1 * top).max(MIN_LANE_DENSITY.min(0.99 * top));
    // A lane's density falls to LANE_VALLEY_SHARE of its peak on both sides within a lane
    // spacing, before it meets a denser point: a dip a vehicle in the lane next to it leaves.
    let reach = (MIN_LANE_SPACING_M / step).round() as usize;
    let dips = |i: usize, side: &mut dyn Iterator<Item = usize>| {
        side.take(reach)
            .take_while(|&j| density[j] <= density[i])
            .any(|j| density[j] < LANE_VALLEY_SHARE * density[i])
    };
    // Local maxima, densest first; a plateau counts once (its first sample).
    let mut peaks: Vec<(f64, f64)> = (0..n)
        .filter(|&i| {
            let d = density[i];
            d >= least
                && (i == 0 || d > density[i - 1])
                && (i + 1 == n || d >= density[i + 1])
                && dips(i, &mut (0..i).rev())
                && dips(i, &mut (i + 1..n))
        })
        .map(|i| (lo + i as f64 * step, density[i]))
        .collect();
    peaks.sort_by(|a, b| b.1.total_cmp(&a.1));
    let mut modes: Vec<f64> = Vec::new();
    for (x, _) in peaks {
        if modes.iter().all(|m| (m - x).abs() >= MIN_LANE_SPACING_M) {
            modes.push(x);
        }
    }
    // A vehicle farther than a lane spacing from every lane and every other vehicle drove in
    // a lane of its own (seen once); one between two lanes (changing lanes) did not, nor one
    // of positions spread evenly across the road (no lanes to be seen).
    let mut sorted = finite.clone();
    sorted.sort_by(f64::total_cmp);
    let alone = |k: usize| {
        let far = |j: Option<&f64>| j.is_none_or(|o| (o - sorted[k]).abs() >= MIN_LANE_SPACING_M);
        far(k.checked_sub(1).and_then(|j| sorted.get(j))) && far(sorted.get(k + 1))
    };
    for (k, &v) in sorted.iter().enumerate() {
        if alone(k) && modes.iter().all(|m| (m - v).abs() >= MIN_LANE_SPACING_M) {
            modes.push(v);
        }
    }
    modes.sort_by(f64::total_cmp);
    // A position farther than a lane spacing from every lane (a short track off the road's
    // lanes, a bad contact point) is in none: it is not stretched into the nearest.
    lateral_m
        .iter()
        .map(|v| {
            if !v.is_finite() || modes.is_empty() {
                return None;
            }
            let mut best = 0;
            for (k, m) in modes.iter().enumerate() {
                if (m - v).abs() < (modes[best] - v).abs() {
                    best = k;
                }
            }
            ((modes[best] - v).abs() < MIN_LANE_SPACING_M).then_some(best + 1)
        })
        .collect()
}

impl VehicleTrack {
    /// The track as a BrnoCompSpeed system car: its unclipped points, each at its place on
    /// the track's fitted path ([`VehicleTrack::path`]) where it has one, else the contact
    /// point.
    pub fn to_system_car(&self) -> SystemCar {
        let kept: Vec<(u64, Point2)> = self
            .points
            .iter()
            .enumerate()
            .filter(|(_, p)| !p.clipped)
            .map(|(i, p)| {
                let at = self.path.get(i).copied().flatten().unwrap_or(p.image);
                (p.frame, at)
            })
            .collect();
        SystemCar {
            id: self.id as i64,
            frames: kept.iter().map(|(f, _)| *f as f64).collect(),
            pos_x: kept.iter().map(|(_, p)| p.x).collect(),
            pos_y: kept.iter().map(|(_, p)| p.y).collect(),
        }
    }
}

/// The contact point of a box: its bottom centre.
pub fn contact_point(b: &BoxPx) -> Point2 {
    Point2::new((b.x0 + b.x1) / 2.0, b.y1)
}

/// Indices of `boxes` per track, in frame order (the box tracker's linking of the detector
/// boxes); every box is in exactly one track.
pub fn link_boxes(boxes: &[TrackBox], opts: &TrackOptions) -> Vec<Vec<usize>> {
    let boxes: Vec<(f64, BoxPx)> = boxes.iter().map(|b| (b.frame as f64, b.bbox)).collect();
    link(&boxes, opts)
}

/// The detector boxes of `records`, for [`link_boxes`] and [`build_tracks`].
pub fn record_boxes(records: &[VehicleRecord]) -> Vec<TrackBox> {
    records
        .iter()
        .map(|r| TrackBox {
            frame: r.frame,
            bbox: r.det_box,
            score: r.score,
        })
        .collect()
}

/// The tracks of the detector boxes `boxes` (a run's [`PipelineOutput::boxes`], module
/// docs): times from `fps`, road points and speeds when `road` gives a camera and its scale
/// (metres per road unit). `size` is the frame size.
///
/// [`PipelineOutput::boxes`]: crate::pipeline::PipelineOutput::boxes
pub fn build_tracks(
    boxes: &[TrackBox],
    fps: f64,
    road: Option<(&Calibration, f64)>,
    size: (u32, u32),
    settings: &TrackSettings,
) -> Vec<VehicleTrack> {
    let (w, h) = (f64::from(size.0), f64::from(size.1));
    let m = settings.border_px;
    let links = link_boxes(boxes, &settings.link);
    let mut pieces: Vec<Vec<TrackPoint>> = links
        .iter()
        .map(|t| {
            t.iter()
                .map(|&i| {
                    let r = &boxes[i];
                    let b = r.bbox;
                    let clipped = b.x0 <= m || b.y0 <= m || b.x1 >= w - m || b.y1 >= h - m;
                    let image = contact_point(&b);
                    let road_m = match road {
                        Some((cal, scale)) if !clipped => {
                            cal.road_point(image).map(|q| [q[0] * scale, q[1] * scale])
                        }
                        _ => None,
                    };
                    TrackPoint {
                        frame: r.frame,
                        time_s: r.frame as f64 / fps,
                        image,
                        clipped,
                        road_m,
                    }
                })
                .collect()
        })
        .collect();
    if road.is_some() {
        pieces = pieces
            .into_iter()
            .flat_map(|p| split_at_jumps(p, &settings.stitch))
            .collect();
        pieces = stitch(pieces, &settings.stitch);
    }
    measure_tracks(pieces, road, settings)
}

/// Tracks saved by an earlier run (their points' frames, times, contact points and clipped
/// flags), measured again with camera and scale `road`: road points, speeds, paths, lanes,
/// directions ([`measure_tracks`]). The pieces stay as they were linked and stitched.
pub fn remeasure_tracks(
    saved: Vec<Vec<TrackPoint>>,
    road: (&Calibration, f64),
    settings: &TrackSettings,
) -> Vec<VehicleTrack> {
    let (cal, scale) = road;
    let pieces = saved
        .into_iter()
        .map(|points| {
            points
                .into_iter()
                .map(|p| TrackPoint {
                    road_m: if p.clipped {
                        None
                    } else {
                        cal.road_point(p.image)
                            .map(|q| [q[0] * scale, q[1] * scale])
                    },
                    ..p
                })
                .collect()
        })
        .collect();
    measure_tracks(pieces, Some(road), settings)
}

/// The tracks of linked (and, with a camera, stitched) `pieces`: those of at least
/// [`TrackSettings::min_points`] points, numbered in the order of their first frames, with
/// their speeds, paths, lateral positions and directions when `road` gives a camera and
/// scale, and the lanes they drove in.
fn measure_tracks(
    mut pieces: Vec<Vec<TrackPoint>>,
    road: Option<(&Calibration, f64)>,
    settings: &TrackSettings,
) -> Vec<VehicleTrack> {
    pieces.retain(|t| t.len() >= settings.min_points.max(1));
    pieces.sort_by_key(|t| t[0].frame);
    let mut tracks: Vec<VehicleTrack> = pieces
        .into_iter()
        .enumerate()
        .map(|(k, points)| {
            let (times, pos): (Vec<f64>, Vec<[f64; 2]>) = points
                .iter()
                .filter_map(|p| p.road_m.map(|q| (p.time_s, q)))
                .unzip();
            let towards_vp1 = (pos.len() >= 2)
                .then(|| pos[pos.len() - 1][0] - pos[0][0])
                .filter(|dx| *dx != 0.0 && dx.is_finite())
                .map(|dx| dx > 0.0);
            let lateral_m = (!pos.is_empty()).then(|| median(pos.iter().map(|q| q[1]).collect()));
            let path = road.map_or_else(Vec::new, |(cal, scale)| {
                lateral_path(&points)
                    .map(|path| {
                        path.iter()
                            .map(|q| {
                                q.and_then(|q| {
                                    cal.pixel_of_road_point([q[0] / scale, q[1] / scale])
                                })
                            })
                            .collect()
                    })
                    .unwrap_or_default()
            });
            let speed = estimate_speed(&times, &pos, settings.window_points).map(|mut v| {
                // The pixel grid's part, which a track of perfectly consistent points (its
                // residuals and window spread both 0) still has.
                let floor = metres_per_px(&points).map_or(0.0, |mpp| {
                    pixel_speed_floor_kmh(
                        mpp,
                        times.len(),
                        times.last().copied().unwrap_or(0.0)
                            - times.first().copied().unwrap_or(0.0),
                    )
                });
                v.uncertainty_kmh = v.uncertainty_kmh.hypot(floor);
                v
            });
            VehicleTrack {
                id: k as u64 + 1,
                speed,
                lateral_m,
                lane: None,
                towards_vp1,
                points,
                path,
            }
        })
        .collect();
    if settings.lanes {
        let lanes = lanes_by_direction(&tracks);
        for (t, lane) in tracks.iter_mut().zip(lanes) {
            t.lane = lane;
        }
    }
    tracks
}

/// The lane of each track: the lanes are where the tracks with a speed (long and moving)
/// drove, clustered ([`cluster_lanes`]) separately for each direction of travel (the two
/// carriageways of a road are not one set of lanes), then numbered 1, 2, ... across the road
/// in the order of the lanes' mean lateral positions.
fn lanes_by_direction(tracks: &[VehicleTrack]) -> Vec<Option<usize>> {
    let mut lane_of: Vec<Option<(usize, usize)>> = vec![None; tracks.len()];
    let mut centres: Vec<((usize, usize), f64)> = Vec::new();
    for (d, direction) in [Some(true), Some(false), None].into_iter().enumerate() {
        let members: Vec<usize> = (0..tracks.len())
            .filter(|&i| tracks[i].towards_vp1 == direction)
            .collect();
        let lateral: Vec<f64> = members
            .iter()
            .map(|&i| tracks[i].lateral_m.unwrap_or(f64::NAN))
            .collect();
        let support: Vec<bool> = members.iter().map(|&i| tracks[i].speed.is_some()).collect();
        let lanes = cluster_lanes(&lateral, &support);
        let mut sums: std::collections::BTreeMap<usize, (f64, usize)> = Default::default();
        for ((&i, lane), x) in members.iter().zip(lanes).zip(&lateral) {
            if let Some(l) = lane {
                lane_of[i] = Some((d, l));
                let e = sums.entry(l).or_insert((0.0, 0));
                e.0 += x;
                e.1 += 1;
            }
        }
        centres.extend(sums.into_iter().map(|(l, (s, n))| ((d, l), s / n as f64)));
    }
    centres.sort_by(|a, b| a.1.total_cmp(&b.1));
    lane_of
        .iter()
        .map(|k| {
            let k = (*k)?;
            centres.iter().position(|(c, _)| *c == k).map(|p| p + 1)
        })
        .collect()
}

/// Where a piece of track is at its start and end on the road: the mean time and road point
/// of its first and last thirds of road points (jitter averages out), and its velocity
/// between them (m/s); the times of its first and last points.
#[derive(Debug, Clone, Copy)]
struct PieceEnds {
    first_time: f64,
    last_time: f64,
    start: [f64; 3],
    end: [f64; 3],
    velocity: Option<[f64; 2]>,
}

fn piece_ends(points: &[TrackPoint]) -> Option<PieceEnds> {
    let road: Vec<[f64; 3]> = points
        .iter()
        .filter_map(|p| p.road_m.map(|q| [p.time_s, q[0], q[1]]))
        .collect();
    let [start, end] = mean_of_thirds(&road)?;
    let dt = end[0] - start[0];
    let velocity = (dt > 0.0).then(|| [(end[1] - start[1]) / dt, (end[2] - start[2]) / dt]);
    Some(PieceEnds {
        first_time: points.first()?.time_s,
        last_time: points.last()?.time_s,
        start,
        end,
        velocity: velocity.filter(|v| v[0].hypot(v[1]) > 0.0 && v[0].is_finite()),
    })
}

/// How well piece `b` continues piece `a` (smaller is better, at most 2), or `None` when it
/// does not ([`StitchSettings`]): `b` starts after `a` ends, within `max_gap_s`, where `a`'s
/// end moved on at its velocity puts it, and does not drive the other way.
fn continuation_cost(a: &PieceEnds, b: &PieceEnds, s: &StitchSettings) -> Option<f64> {
    let seconds_gap = b.first_time - a.last_time;
    if seconds_gap <= 0.0 || seconds_gap > s.max_gap_s {
        return None;
    }
    let v = a.velocity?;
    if b.velocity.is_some_and(|w| w[0] * v[0] + w[1] * v[1] <= 0.0) {
        return None;
    }
    // From a's end anchor to b's start anchor: positive, as b's points all follow a's.
    let gap = b.start[0] - a.end[0];
    let speed = v[0].hypot(v[1]);
    let u = [v[0] / speed, v[1] / speed];
    let r = [
        b.start[1] - (a.end[1] + v[0] * gap),
        b.start[2] - (a.end[2] + v[1] * gap),
    ];
    let along = (r[0] * u[0] + r[1] * u[1]).abs();
    let lateral = (r[0] * u[1] - r[1] * u[0]).abs();
    let along_tol = s.along_m + s.along_frac * speed * gap;
    (lateral <= s.max_lateral_m && along <= along_tol)
        .then(|| along / along_tol + lateral / s.max_lateral_m)
}

/// A track's path needs at least this many road points.
pub const MIN_PATH_POINTS: usize = 5;

/// Half the time window of [`lateral_path`]'s running median, seconds.
pub const PATH_HALF_WINDOW_S: f64 = 0.5;

/// Per point of a track, its road point (metres) moved across the road onto the track's path:
/// the median distance across the road of the track's road points within
/// [`PATH_HALF_WINDOW_S`] of it in time. A vehicle moves across the road slowly (a lane change
/// takes seconds; so does the drift a road's bend or a VP1 a little off gives a straight
/// road frame), while a box's bottom centre jitters across it by decimetres from frame to
/// frame, and by more where a box holds part of a neighbour for a few frames; along the road
/// the point stays where it was (the speed is measured along it). `None` for points without
/// a road point; no path with fewer than [`MIN_PATH_POINTS`] road points.
///
/// Two global paths were measured and not used: one distance across for the whole track moved
/// the points of the real 320x240 clip `bgslibrary_video02`, whose road bends in the distance,
/// by 12.6 px at the 90th percentile; a line fitted across (`across = a + b · along`)
/// extrapolated a sparse track's slope by metres (52 px on the CDnet clip). On the synthetic
/// speed scenes all three did the same.
///
/// Why: the protocol of the BrnoCompSpeed cars extends a line through the 6 track points
/// nearest to each measurement line, and through jittery points of a track that ends short of
/// a line that line can leave the lanes (a crossing failure, and a missed vehicle).
pub fn lateral_path(points: &[TrackPoint]) -> Option<Vec<Option<[f64; 2]>>> {
    let road: Vec<(f64, [f64; 2])> = points
        .iter()
        .filter_map(|p| p.road_m.map(|q| (p.time_s, q)))
        .collect();
    if road.len() < MIN_PATH_POINTS {
        return None;
    }
    let mut lo = 0;
    let mut hi = 0;
    let mut smoothed = Vec::with_capacity(road.len());
    for &(t, q) in &road {
        while road[lo].0 < t - PATH_HALF_WINDOW_S {
            lo += 1;
        }
        while hi < road.len() && road[hi].0 <= t + PATH_HALF_WINDOW_S {
            hi += 1;
        }
        let across: Vec<f64> = road[lo..hi].iter().map(|(_, q)| q[1]).collect();
        smoothed.push([q[0], vpcal_geom::solve::median(&across).unwrap_or(q[1])]);
    }
    let mut next = smoothed.into_iter();
    Some(
        points
            .iter()
            .map(|p| p.road_m.and_then(|_| next.next()))
            .collect(),
    )
}

/// `piece` cut where its road point jumps across the road ([`StitchSettings::jump_lateral_m`]):
/// the box tracker links boxes in the image, and where a vehicle's box goes missing another
/// vehicle's box can lie where it was predicted; on the road that is a jump of about a lane.
/// Points without a road point stay with the piece they follow.
pub fn split_at_jumps(piece: Vec<TrackPoint>, s: &StitchSettings) -> Vec<Vec<TrackPoint>> {
    let mut out: Vec<Vec<TrackPoint>> = vec![];
    let mut current: Vec<TrackPoint> = vec![];
    let mut last: Option<(f64, f64)> = None;
    for p in piece {
        if let Some(q) = p.road_m {
            if let Some((t, y)) = last {
                if (q[1] - y).abs() > s.jump_lateral_m + s.jump_lateral_speed * (p.time_s - t) {
                    out.push(std::mem::take(&mut current));
                }
            }
            last = Some((p.time_s, q[1]));
        }
        current.push(p);
    }
    out.push(current);
    out.retain(|c| !c.is_empty());
    out
}

/// Joins the pieces of track that are one vehicle: the tracker cuts a track where a box
/// changes suddenly (two vehicles' boxes merge or split, a vehicle is missed for a while);
/// on the road the pieces line up in time and place. Greedy, best continuation first; a piece
/// continues at most one piece and is continued by at most one. Pieces that overlap in time
/// are never joined (two vehicles side by side), so a chain always runs forward in time.
pub fn stitch(pieces: Vec<Vec<TrackPoint>>, settings: &StitchSettings) -> Vec<Vec<TrackPoint>> {
    let ends: Vec<Option<PieceEnds>> = pieces.iter().map(|p| piece_ends(p)).collect();
    let mut candidates = Vec::new();
    for (i, a) in ends.iter().enumerate() {
        for (j, b) in ends.iter().enumerate() {
            if let (Some(a), Some(b)) = (a, b) {
                if let Some(c) = continuation_cost(a, b, settings) {
                    candidates.push((c, i, j));
                }
            }
        }
    }
    candidates.sort_by(|x, y| x.0.total_cmp(&y.0));
    let n = pieces.len();
    let (mut next, mut prev) = (vec![None; n], vec![None; n]);
    for (_, i, j) in candidates {
        if next[i].is_none() && prev[j].is_none() {
            next[i] = Some(j);
            prev[j] = Some(i);
        }
    }
    let mut slots: Vec<Option<Vec<TrackPoint>>> = pieces.into_iter().map(Some).collect();
    let mut out = Vec::new();
    for (start, p) in prev.iter().enumerate() {
        if p.is_some() {
            continue;
        }
        let mut chain = Vec::new();
        let mut k = Some(start);
        while let Some(x) = k {
            chain.extend(slots[x].take().unwrap_or_default());
            k = next[x];
        }
        out.push(chain);
    }
    out
}

/// Median of `v` (NaN when empty).
fn median(v: Vec<f64>) -> f64 {
    vpcal_geom::solve::median(&v).unwrap_or(f64::NAN)
}

/// Least-squares slope of `y` on `x`; `None` when `x` does not vary.
fn slope(x: &[f64], y: &[f64]) -> Option<f64> {
    let (s, _) = vpcal_formats::bcs_speed::least_squares(x, y);
    s.is_finite().then_some(s)
}

/// The means of the first and of the last third of `v` (at least one element each); `None`
/// when `v` is empty.
fn mean_of_thirds<const N: usize>(v: &[[f64; N]]) -> Option<[[f64; N]; 2]> {
    let n = v.len();
    if n == 0 {
        return None;
    }
    let third = (n / 3).max(1);
    let mean = |s: &[[f64; N]]| {
        let mut m = [0.0; N];
        for p in s {
            for (a, x) in m.iter_mut().zip(p) {
                *a += x;
            }
        }
        m.map(|a| a / s.len() as f64)
    };
    Some([mean(&v[..third]), mean(&v[n - third..])])
}

/// Distances of `pos` along the direction of travel (from the mean of the first third of the
/// points to the mean of the last third), metres; `None` when the track did not move.
pub fn along_track(pos: &[[f64; 2]]) -> Option<Vec<f64>> {
    let n = pos.len();
    if n < 2 {
        return None;
    }
    let [a, b] = mean_of_thirds(pos)?;
    let d = [b[0] - a[0], b[1] - a[1]];
    let len = d[0].hypot(d[1]);
    if !(len > 0.0 && len.is_finite()) {
        return None;
    }
    let u = [d[0] / len, d[1] / len];
    Some(pos.iter().map(|p| p[0] * u[0] + p[1] * u[1]).collect())
}

/// The speed of a track from its times (seconds, increasing) and road points (metres), with
/// windows of `window` points (module docs); `None` with fewer than `window` points (at least
/// 3), a track that did not move, or no finite window speed.
pub fn estimate_speed(times: &[f64], pos: &[[f64; 2]], window: usize) -> Option<SpeedEstimate> {
    let window = window.max(3);
    let n = times.len().min(pos.len());
    if n < window {
        return None;
    }
    let d = along_track(&pos[..n])?;
    let t = &times[..n];
    let fits: Vec<(f64, f64)> = (0..=n - window)
        .filter_map(|i| window_fit(&t[i..i + window], &d[i..i + window]))
        .map(|(v, se)| (v.abs() * 3.6, se * 3.6))
        .collect();
    if fits.is_empty() {
        return None;
    }
    let speeds: Vec<f64> = fits.iter().map(|f| f.0).collect();
    let kmh = median(speeds.clone());
    let mad = median(speeds.iter().map(|v| (v - kmh).abs()).collect());
    // The spread of the window speeds says how well the median is known when there are many
    // windows; with one or a few (their MAD is 0 for one) each window's own residuals do. The
    // larger of the two, over the independent windows.
    let window_se = median(fits.iter().map(|f| f.1).collect());
    let independent = (n as f64 / window as f64).max(1.0);
    let fit_kmh = slope(t, &d).map_or(f64::NAN, |v| v.abs() * 3.6);
    Some(SpeedEstimate {
        kmh,
        uncertainty_kmh: (1.4826 * mad).max(window_se) / independent.sqrt(),
        fit_kmh,
        windows: speeds.len(),
    })
}

/// The least-squares slope of `y` on `x` and its standard error from the residuals
/// (`sqrt(SSR / (n - 2) / Sxx)`); `None` when `x` does not vary or the slope is not finite.
fn window_fit(x: &[f64], y: &[f64]) -> Option<(f64, f64)> {
    let (slope, intercept) = vpcal_formats::bcs_speed::least_squares(x, y);
    if !slope.is_finite() || x.len() < 3 {
        return None;
    }
    let mx = x.iter().sum::<f64>() / x.len() as f64;
    let sxx: f64 = x.iter().map(|a| (a - mx) * (a - mx)).sum();
    let ssr: f64 = x
        .iter()
        .zip(y)
        .map(|(a, b)| (b - (slope * a + intercept)).powi(2))
        .sum();
    let se = (ssr / (x.len() - 2) as f64 / sxx).sqrt();
    se.is_finite().then_some((slope, se))
}

/// The standard error a speed has at least, km/h, when its road points are known to no
/// better than the pixel grid: a contact point rounded to whole pixels is off by
/// `1/sqrt(12)` px (sd), which at `metres_per_px` and over `n` points spanning `duration_s`
/// seconds (evenly spaced: `Sxx = duration² · n (n + 1) / (12 (n - 1))`) is the standard error
/// of a line's slope. `0` when the span is not positive.
pub fn pixel_speed_floor_kmh(metres_per_px: f64, n: usize, duration_s: f64) -> f64 {
    if n < 2 || duration_s.is_nan() || duration_s <= 0.0 || !metres_per_px.is_finite() {
        return 0.0;
    }
    let nf = n as f64;
    let sxx = duration_s * duration_s * nf * (nf + 1.0) / (12.0 * (nf - 1.0));
    let sd_m = metres_per_px / 12f64.sqrt();
    3.6 * sd_m / sxx.sqrt()
}

/// The median of the road distance per image pixel between a track's consecutive road
/// points (those at least a pixel apart), metres per pixel; `None` without such pairs.
fn metres_per_px(points: &[TrackPoint]) -> Option<f64> {
    let ratios: Vec<f64> = points
        .windows(2)
        .filter_map(|w| {
            let (a, b) = (w[0].road_m?, w[1].road_m?);
            let px = (w[1].image - w[0].image).norm();
            (px >= 1.0).then(|| (b[0] - a[0]).hypot(b[1] - a[1]) / px)
        })
        .filter(|r| r.is_finite())
        .collect();
    vpcal_geom::solve::median(&ratios)
}

/// Counts for the summary line: tracks, tracks with a speed, median speed (km/h).
pub fn summary(tracks: &[VehicleTrack]) -> (usize, usize, Option<f64>) {
    let speeds: Vec<f64> = tracks
        .iter()
        .filter_map(|t| t.speed.map(|s| s.kmh))
        .collect();
    let n = speeds.len();
    (tracks.len(), n, (n > 0).then(|| median(speeds)))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Uniform numbers in [-1, 1] from a seed (a 64-bit LCG: no dependency for a test).
    struct Lcg(u64);

    impl Lcg {
        fn next(&mut self) -> f64 {
            self.0 = self
                .0
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (self.0 >> 11) as f64 / (1u64 << 52) as f64 - 1.0
        }
    }

    /// A vehicle at `kmh` along direction `angle` from `start`, sampled at 25 frames/s, with
    /// uniform jitter of ±`jitter_m` on both road coordinates.
    fn drive(
        kmh: f64,
        angle: f64,
        n: usize,
        jitter_m: f64,
        seed: u64,
    ) -> (Vec<f64>, Vec<[f64; 2]>) {
        let mut rng = Lcg(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ 0xD1B5);
        let v = kmh / 3.6;
        let (s, c) = angle.sin_cos();
        let t: Vec<f64> = (0..n).map(|k| k as f64 / 25.0).collect();
        let p = t
            .iter()
            .map(|&t| {
                let mut j = || jitter_m * rng.next();
                [3.0 + v * t * c + j(), -7.0 + v * t * s + j()]
            })
            .collect();
        (t, p)
    }

    #[test]
    fn an_exact_track_gives_its_speed() {
        let (t, p) = drive(72.0, 0.3, 40, 0.0, 1);
        let s = estimate_speed(&t, &p, 10).unwrap();
        assert!((s.kmh - 72.0).abs() < 1e-9, "{s:?}");
        assert!((s.fit_kmh - 72.0).abs() < 1e-9, "{s:?}");
        assert!(s.uncertainty_kmh < 1e-9);
        assert_eq!(s.windows, 31);
    }

    #[test]
    fn jitter_of_30_cm_leaves_the_speed_within_its_uncertainty() {
        // 30 cm of box jitter is about a pixel at 30 m from a 1000 px camera.
        let mut misses = 0;
        for seed in 0..50 {
            let (t, p) = drive(90.0, -2.0, 50, 0.3, seed);
            let s = estimate_speed(&t, &p, 10).unwrap();
            assert!((s.kmh - 90.0).abs() < 4.0, "{seed}: {s:?}");
            assert!((s.fit_kmh - 90.0).abs() < 1.5, "{seed}: {s:?}");
            assert!(s.uncertainty_kmh > 0.0 && s.uncertainty_kmh < 5.0, "{s:?}");
            if (s.kmh - 90.0).abs() > 2.5 * s.uncertainty_kmh {
                misses += 1;
            }
        }
        // The uncertainty is honest: the error exceeds 2.5 of it rarely.
        assert!(misses <= 5, "{misses} of 50 outside 2.5 uncertainties");
    }

    #[test]
    fn a_few_bad_boxes_do_not_move_the_median() {
        let (t, mut p) = drive(50.0, 1.0, 60, 0.05, 3);
        // Two boxes 3 m off (a box that also covers the shadow, a merged pair).
        p[20][0] += 3.0;
        p[41][1] -= 3.0;
        let s = estimate_speed(&t, &p, 10).unwrap();
        assert!((s.kmh - 50.0).abs() < 3.0, "{s:?}");
    }

    #[test]
    fn too_short_or_standing_tracks_have_no_speed() {
        let (t, p) = drive(50.0, 0.0, 9, 0.0, 0);
        assert!(estimate_speed(&t, &p, 10).is_none());
        let t: Vec<f64> = (0..20).map(|k| f64::from(k) / 25.0).collect();
        assert!(estimate_speed(&t, &[[1.0, 2.0]; 20], 10).is_none());
    }

    /// A property over a sweep of speeds, directions, lengths and windows.
    #[test]
    fn exact_tracks_give_their_speed_in_any_direction() {
        let mut rng = Lcg(7);
        for _ in 0..500 {
            let kmh = 102.5 + 97.5 * rng.next();
            let angle = 3.2 * rng.next();
            let window = 3 + ((rng.next() + 1.0) * 4.5) as usize;
            let n = window + ((rng.next() + 1.0) * 35.0) as usize;
            let (t, p) = drive(kmh, angle, n, 0.0, 0);
            let s = estimate_speed(&t, &p, window).unwrap();
            assert!(
                (s.kmh - kmh).abs() < 1e-6 * kmh,
                "{kmh} {angle} {n} {window}: {s:?}"
            );
            assert!((s.fit_kmh - kmh).abs() < 1e-6 * kmh);
        }
    }

    #[test]
    fn lanes_are_the_clusters_of_lateral_positions() {
        // Three lanes 3.5 m apart, vehicles scattered ±0.4 m in each, given in mixed order.
        let mut rng = Lcg(11);
        let truth: Vec<usize> = (0..60).map(|i| (i * 7) % 3).collect();
        let lateral: Vec<f64> = truth
            .iter()
            .map(|&l| -4.0 + 3.5 * l as f64 + 0.4 * rng.next())
            .collect();
        let lanes = cluster_lanes(&lateral, &[true; 60]);
        for (t, l) in truth.iter().zip(&lanes) {
            assert_eq!(Some(t + 1), *l);
        }
        // One lane: one cluster. Nothing finite: no lanes.
        let one: Vec<f64> = (0..20).map(|_| 1.0 + 0.5 * rng.next()).collect();
        assert!(cluster_lanes(&one, &[true; 20])
            .iter()
            .all(|l| *l == Some(1)));
        assert_eq!(
            cluster_lanes(&[f64::NAN, 2.0], &[true; 2]),
            vec![None, Some(1)]
        );
        assert!(cluster_lanes(&[], &[]).is_empty());
        // A lone vehicle between two lanes (a lane change) is not a lane of its own, and
        // positions without support (short tracks) are assigned but make no lane.
        let mut with_stray = lateral.clone();
        with_stray.push(-4.0 + 1.75);
        with_stray.push(-4.0 + 5.25);
        let mut support = vec![true; 61];
        support.push(false);
        let lanes = cluster_lanes(&with_stray, &support);
        assert!(lanes.iter().all(|l| matches!(l, Some(1..=3))), "{lanes:?}");
        // A lone vehicle a lane's width beyond the others is a lane of its own.
        let mut beyond = lateral.clone();
        beyond.push(-4.0 + 3.5 * 3.0);
        let lanes = cluster_lanes(&beyond, &[true; 61]);
        assert_eq!(lanes[60], Some(4));
        assert_eq!(lanes[..60], cluster_lanes(&lateral, &[true; 60])[..]);
        // Contact points near the horizon, kilometres (or more) off: no lane, and the lanes
        // of the others as without them (the density's grid does not stretch to them).
        let mut far = lateral.clone();
        far.extend([1e9, -1e300, f64::MAX]);
        let lanes = cluster_lanes(&far, &[true; 63]);
        assert_eq!(lanes[..60], cluster_lanes(&lateral, &[true; 60])[..]);
        assert_eq!(lanes[60..], [None, None, None]);
        // Positions spread evenly over 28 m, as a road frame that does not fit the road
        // spreads them: the density's ripples are no lanes, and no position is a lane alone.
        let spread: Vec<f64> = (0..40)
            .map(|i| -24.0 + 0.7 * i as f64 + 0.3 * rng.next())
            .collect();
        let lanes = cluster_lanes(&spread, &[true; 40]);
        assert!(lanes.iter().all(Option::is_none), "{lanes:?}");
    }

    /// A property: lanes at least 2.8 m apart with ±0.5 m scatter are told apart, whatever
    /// their number, spacing and offset; a position's lane never depends on the order.
    #[test]
    fn lanes_are_found_for_any_spacing_and_order() {
        let mut rng = Lcg(5);
        for _ in 0..200 {
            let lanes = 1 + ((rng.next() + 1.0) * 2.5) as usize;
            let width = 3.15 + 0.35 * rng.next();
            let offset = 10.0 * rng.next();
            let truth: Vec<usize> = (0..8 * lanes).map(|i| i % lanes).collect();
            let lateral: Vec<f64> = truth
                .iter()
                .map(|&l| offset + width * l as f64 + 0.5 * rng.next())
                .collect();
            let all = vec![true; lateral.len()];
            let found = cluster_lanes(&lateral, &all);
            for (t, l) in truth.iter().zip(&found) {
                assert_eq!(Some(t + 1), *l, "{lanes} lanes of {width} m");
            }
            let reversed: Vec<f64> = lateral.iter().rev().copied().collect();
            let again: Vec<Option<usize>> =
                cluster_lanes(&reversed, &all).into_iter().rev().collect();
            assert_eq!(found, again);
        }
    }

    fn record(frame: u64, b: BoxPx) -> VehicleRecord {
        VehicleRecord::of_box(frame, b)
    }

    /// Track points of a vehicle driving along road x at `v` m/s, from frame `f0` to `f1`
    /// (exclusive), `y` metres across, starting at x = `x0` at frame 0 (25 frames/s).
    fn road_piece(f0: u64, f1: u64, x0: f64, y: f64, v: f64) -> Vec<TrackPoint> {
        (f0..f1)
            .map(|f| {
                let t = f as f64 / 25.0;
                TrackPoint {
                    frame: f,
                    time_s: t,
                    image: Point2::new(0.0, 0.0),
                    clipped: false,
                    road_m: Some([x0 + v * t, y]),
                }
            })
            .collect()
    }

    #[test]
    fn the_path_keeps_each_point_along_the_road_and_smooths_it_across() {
        // 30 m/s, 2 m across, with +-0.2 m of jitter across, 1 m along, and two boxes that
        // held a neighbour (1.5 m over); some points without a road point.
        let mut piece = road_piece(0, 40, 0.0, 0.0, 30.0);
        for (k, p) in piece.iter_mut().enumerate() {
            let jitter = if k % 2 == 0 { 0.2 } else { -0.2 };
            let stray = if k == 11 || k == 23 { 1.5 } else { 0.0 };
            p.road_m = p
                .road_m
                .map(|q| [q[0] + jitter * 5.0, 2.0 + jitter + stray]);
            if k % 9 == 4 {
                p.road_m = None;
            }
        }
        let path = lateral_path(&piece).expect("a path");
        assert_eq!(path.len(), piece.len());
        for (p, q) in piece.iter().zip(&path) {
            match (p.road_m, q) {
                (Some(r), Some(q)) => {
                    assert_eq!(q[0], r[0], "along the road the point stays");
                    // Within the jitter, the neighbour's boxes not followed.
                    assert!((q[1] - 2.0).abs() <= 0.2 + 1e-9, "{q:?} {r:?}");
                }
                (None, None) => {}
                other => panic!("{other:?}"),
            }
        }
        // A lane change (3.5 m over 4 s) is followed.
        let mut changing = road_piece(0, 150, 0.0, 0.0, 30.0);
        let across = |f: u64| 3.5 * ((f as f64 - 25.0) / 100.0).clamp(0.0, 1.0);
        for p in &mut changing {
            p.road_m = p.road_m.map(|q| [q[0], across(p.frame)]);
        }
        let path = lateral_path(&changing).expect("a path");
        for (p, q) in changing.iter().zip(&path) {
            let q = q.expect("a road point");
            assert!((q[1] - across(p.frame)).abs() < 1e-9, "{} {q:?}", p.frame);
        }
        // Too few road points: no path.
        assert!(lateral_path(&road_piece(0, 4, 0.0, 0.0, 30.0)).is_none());
        // The BrnoCompSpeed car takes a point's path pixel where it has one, else its
        // contact point, and leaves out clipped points.
        let mut points = road_piece(0, 3, 0.0, 0.0, 30.0);
        points[2].clipped = true;
        let track = VehicleTrack {
            id: 7,
            points,
            speed: None,
            lateral_m: None,
            lane: None,
            towards_vp1: None,
            path: vec![
                None,
                Some(Point2::new(5.0, 6.0)),
                Some(Point2::new(8.0, 9.0)),
            ],
        };
        let car = track.to_system_car();
        assert_eq!(car.frames, vec![0.0, 1.0]);
        assert_eq!((car.pos_x, car.pos_y), (vec![0.0, 5.0], vec![0.0, 6.0]));
    }

    #[test]
    fn a_piece_is_cut_where_it_jumps_across_the_road() {
        let s = StitchSettings::default();
        // A vehicle at 30 m/s; from frame 20 to 29 the tracker held the box of one 3.5 m over
        // (the next lane), then the first again. A slow lane change (0.4 m over 20 frames) and
        // points without a road point do not cut it.
        let mut piece = road_piece(0, 40, 0.0, 0.0, 30.0);
        for p in &mut piece[20..30] {
            p.road_m = p.road_m.map(|q| [q[0] - 5.0, q[1] + 3.5]);
        }
        let out = split_at_jumps(piece, &s);
        let lens: Vec<usize> = out.iter().map(Vec::len).collect();
        assert_eq!(lens, vec![20, 10, 10]);
        let mut changing = road_piece(0, 40, 0.0, 0.0, 30.0);
        for (k, p) in changing.iter_mut().enumerate() {
            p.road_m = p.road_m.map(|q| [q[0], 0.02 * k as f64]);
            if k % 7 == 3 {
                p.road_m = None;
            }
        }
        assert_eq!(split_at_jumps(changing, &s).len(), 1);
        // Cut and stitched, the vehicle's two pieces are one track again, the other vehicle's
        // ten points another.
        let mut piece = road_piece(0, 40, 0.0, 0.0, 30.0);
        for p in &mut piece[20..30] {
            p.road_m = p.road_m.map(|q| [q[0] - 5.0, q[1] + 3.5]);
        }
        let pieces: Vec<Vec<TrackPoint>> = split_at_jumps(piece, &s);
        let mut lens: Vec<usize> = stitch(pieces, &s).iter().map(Vec::len).collect();
        lens.sort_unstable();
        assert_eq!(lens, vec![10, 30]);
    }

    #[test]
    fn pieces_of_one_vehicle_are_stitched_and_neighbours_are_not() {
        let s = StitchSettings::default();
        // One vehicle at 30 m/s cut into three pieces (gaps of 5 and 15 frames), a second one
        // in the next lane (3.5 m over) and a third that starts where the first would be but
        // drives the other way.
        let pieces = vec![
            road_piece(0, 30, 0.0, 0.0, 30.0),
            road_piece(35, 60, 0.0, 0.2, 30.0),
            road_piece(75, 100, 0.0, -0.1, 30.0),
            road_piece(62, 90, 30.0, 3.5, 30.0),
            road_piece(31, 50, 80.0, 0.0, -30.0),
        ];
        let out = stitch(pieces, &s);
        let lens: Vec<usize> = out.iter().map(Vec::len).collect();
        assert_eq!(lens, vec![80, 28, 19], "{lens:?}");
        assert!(out[0].windows(2).all(|w| w[0].frame < w[1].frame));
        // A gap of more than a second, or a piece 6 m behind where the vehicle would be, stays
        // apart (3.7 m allowed here); pieces that overlap in time are two vehicles.
        for b in [
            road_piece(60, 90, 0.0, 0.0, 30.0),
            road_piece(35, 60, -6.0, 0.0, 30.0),
            road_piece(25, 60, 0.0, 0.0, 30.0),
        ] {
            let out = stitch(vec![road_piece(0, 30, 0.0, 0.0, 30.0), b], &s);
            assert_eq!(out.len(), 2);
        }
    }

    #[test]
    fn two_vehicles_become_two_tracks_with_times_and_border_flags() {
        let mut records = Vec::new();
        for f in 0..20u64 {
            let x = 100.0 + 6.0 * f as f64;
            records.push(record(f, BoxPx::new(x, 50.0, x + 40.0, 80.0)));
            let y = 300.0 - 3.0 * f as f64;
            records.push(record(f, BoxPx::new(500.0, y, 560.0, y + 40.0)));
        }
        records.sort_by_key(|r| r.frame);
        let tracks = build_tracks(
            &record_boxes(&records),
            25.0,
            None,
            (640, 342),
            &TrackSettings::default(),
        );
        assert_eq!(tracks.len(), 2);
        for t in &tracks {
            assert_eq!(t.points.len(), 20);
            assert_eq!(t.points[5].time_s, 0.2);
            assert!(t.speed.is_none(), "no scale, no speed");
        }
        // The second vehicle's first box reaches the bottom border (y1 = 340 of 342).
        let second = tracks
            .iter()
            .find(|t| t.points[0].image.x == 530.0)
            .unwrap();
        assert!(second.points[0].clipped && !second.points[1].clipped);
        assert_eq!(second.to_system_car().frames.len(), 19);
        assert_eq!(tracks[0].id, 1);
    }
}
