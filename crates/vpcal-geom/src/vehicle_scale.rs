//! The metric scale of a calibration from the sizes of the vehicles it sees (DESIGN.md's
//! metric scale; the idea of Dubská et al. 2014: 3D boxes of passing cars against the typical
//! dimensions of the traffic).
//!
//! A calibration from vanishing points knows the road plane up to scale: in its plane units
//! a car is some size `c` times its size in metres, the same `c` everywhere. For each
//! detector box this module finds the 3D box — a cuboid standing on the road, heading along
//! the road (or a given heading), with the proportions of a typical passenger car — whose
//! image fills the detector box best; its size gives that vehicle's `c`. Vehicles differ
//! (a small hatchback, a van, a truck), so the scale is the centre of the vehicles' densest
//! half (the shorth, [`crate::solve::weighted_shorth`], over vehicles, or over tracks when
//! the boxes of one vehicle are linked), read as the size of the traffic's most common
//! vehicle: a passenger car wherever most traffic is cars.
//!
//! # The fleet's tail
//! Cars are a tight cluster in size (a small hatchback to a large saloon, about ±8 % linear);
//! vans, pickups, trucks and buses are a tail on one side whose share differs from road to
//! road (a few percent in a town centre, a quarter or more on a highway). A median moves
//! with that share; the densest half stays on the cars while they are at least half the
//! vehicles. On the rendered highway of `vpcal synth scene --layout highway --seed 9173`
//! (29 % of its vehicles vans, pickups, trucks or a bus, 14 % SUVs), on the scene's true
//! camera with YOLOX's boxes (`examples/scale_synth.rs`), the hatchbacks, saloons and
//! estates alone put the camera 1.04, 0.98 and 0.93 times its true height, the vans 0.72 and
//! the trucks 0.45; the median of all put it 0.88 times as high, the densest half 0.97. The
//! box tracker splitting a long vehicle's track into several adds to the tail (118 tracks
//! for 66 vehicles there). On the twelve BrnoCompSpeed views, whose reference boxes show no
//! such tail (per box, the 10th-90th percentiles of the size lie within 0.85-1.05 of the
//! typical car's on the reference camera), the two agree: the scale over the truth is
//! 0.95-1.11, median 1.04, with the densest half, and 0.98-1.10, median 1.05, with the
//! median (`examples/scale_bcs.rs`). A maximum-likelihood mixture of a normal car cluster
//! and a uniform tail of larger vehicles was tried as well: it read the BrnoCompSpeed views
//! 1.05 (interval holding the truth on 7 of 12, against 10 of 12) and two of six unseen
//! rendered highways 9-13 % off.
//!
//! # Body and cabin, not a cuboid
//! A car is not its bounding cuboid: above the beltline its cabin (glasshouse and roof) is
//! shorter and narrower than the body. Seen from above, as a traffic camera sees it, the top
//! of its image box is the roof's far edge, well inside the cuboid's top face, so a car's box
//! is smaller than its cuboid's and a cuboid fit reads the car small (the scale, metres per
//! unit, large). The fit therefore uses the hull of two stacked boxes: the body, the full
//! length and width up to the beltline, and the cabin, [`PASSENGER_CAR_CABIN`] of the length
//! and width, from the beltline to the roof. Measured (`examples/scale_bcs.rs`, the twelve
//! BrnoCompSpeed views' reference boxes against their taped distances): the cuboid read the
//! scale 1.05-1.15 of the truth (median 1.13, within 10 % on 4 of 12), the car's outline
//! 0.98-1.10 (median 1.05, 11 of 12). From KITTI's low viewpoint the top of a box is the
//! roof's near edge and the outline changes little (`vpcal eval kitti-scale`: 0.987 → 0.975
//! with the typical car). Vans, trucks and buses are closer to cuboids; they are the tail the
//! densest half leaves out.

use crate::camera::Calibration;
use crate::point::{BoxPx, Point2};
use crate::solve::{nelder_mead, weighted_shorth, SplitMix};

/// Typical passenger-car dimensions `[length, width, height]`, metres (module docs).
pub const PASSENGER_CAR: [f64; 3] = [4.4, 1.8, 1.5];

/// Where a car's cabin lies inside its bounding cuboid, as fractions of the cuboid's length,
/// width and height.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cabin {
    /// Length of the roof, fraction of the vehicle's length (centred).
    pub length: f64,
    /// Width of the roof, fraction of the vehicle's width (centred).
    pub width: f64,
    /// Height of the beltline (top of the body, bottom of the cabin), fraction of the height.
    pub belt: f64,
}

impl Cabin {
    /// No cabin: the vehicle is its cuboid (a van, a box truck, a synthetic cuboid's box).
    pub const NONE: Cabin = Cabin {
        length: 1.0,
        width: 1.0,
        belt: 1.0,
    };
}

/// The typical passenger car's cabin (module docs): a roof of about 1.8-2 m on a 4.3-4.7 m
/// compact or mid-size car, 1.3-1.4 m wide on a 1.8 m body, the beltline at about 0.95 m of
/// 1.45-1.5 m (rounded figures of VW Golf and Škoda Octavia class bodies, not fitted to any
/// data).
pub const PASSENGER_CAR_CABIN: Cabin = Cabin {
    length: 0.45,
    width: 0.75,
    belt: 0.65,
};

/// Spread of the traffic's typical car size between fleets, in `ln` of linear size (module
/// docs): part of every automatic scale's uncertainty.
pub const FLEET_LOG_SD: f64 = 0.08;

/// Largest RMS misfit of a box's four sides, as a fraction of the box diagonal, for the
/// vehicle to count: above it the box is not one cuboid (two merged vehicles, a partial
/// occlusion, a shadow).
pub const MAX_FIT_RMS: f64 = 0.06;

/// Boxes within this many pixels of the image border are cut off by it and are not used.
pub const BORDER_PX: f64 = 2.0;

/// Fewest vehicles (or tracks) for an automatic scale.
pub const MIN_VEHICLES: usize = 5;

/// A vehicle's detector box, with what is known about it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SizedBox {
    pub bbox: BoxPx,
    /// Heading on the road, radians from the road frame's x axis (the direction towards
    /// VP1); `None`: along the road.
    pub heading: Option<f64>,
    /// Boxes with the same group are one vehicle (a track): it counts once.
    pub group: Option<u64>,
}

/// The cuboid fitted to one box.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CuboidFit {
    /// Plane units per metre of the typical car: the cuboid is `size × dims` in plane units.
    pub size: f64,
    /// The cuboid's centre on the road, road frame, plane units.
    pub centre: [f64; 2],
    /// RMS misfit of the four box sides, fraction of the box diagonal.
    pub rms: f64,
}

/// The pixel of road-frame point `q` (plane units; `q[2]` up from the road), `None` behind
/// the camera.
fn pixel_of(cal: &Calibration, frame: &crate::camera::RoadFrame, q: [f64; 3]) -> Option<Point2> {
    let m = &frame.rotation;
    let t = frame.translation;
    let c: Vec<f64> = (0..3)
        .map(|i| m[i][0] * q[0] + m[i][1] * q[1] + m[i][2] * q[2] + t[i])
        .collect();
    if c[2].is_nan() || c[2] <= 1e-9 {
        return None;
    }
    let p = Point2::new(
        cal.pp.x + cal.focal_px * c[0] / c[2],
        cal.pp.y + cal.focal_px * c[1] / c[2],
    );
    p.is_finite().then_some(p)
}

/// The image bounding box of a cuboid on the road: centre `centre` (road frame), heading
/// `heading`, dimensions `dims` (plane units); `None` when a corner is behind the camera.
pub fn cuboid_box(
    cal: &Calibration,
    centre: [f64; 2],
    heading: f64,
    dims: [f64; 3],
) -> Option<BoxPx> {
    cuboid_box_in(cal, &cal.road_frame(), centre, heading, dims)
}

/// [`cuboid_box`] with the camera's road frame computed once by the caller.
pub fn cuboid_box_in(
    cal: &Calibration,
    frame: &crate::camera::RoadFrame,
    centre: [f64; 2],
    heading: f64,
    dims: [f64; 3],
) -> Option<BoxPx> {
    vehicle_box_in(cal, frame, centre, heading, dims, Cabin::NONE)
}

/// The image bounding box of a vehicle with bounding cuboid `dims` (plane units) and cabin
/// `cabin` (the hull of its body and its cabin, module docs); otherwise as [`cuboid_box`].
pub fn vehicle_box(
    cal: &Calibration,
    centre: [f64; 2],
    heading: f64,
    dims: [f64; 3],
    cabin: Cabin,
) -> Option<BoxPx> {
    vehicle_box_in(cal, &cal.road_frame(), centre, heading, dims, cabin)
}

/// [`vehicle_box`] with the camera's road frame computed once by the caller.
pub fn vehicle_box_in(
    cal: &Calibration,
    frame: &crate::camera::RoadFrame,
    centre: [f64; 2],
    heading: f64,
    dims: [f64; 3],
    cabin: Cabin,
) -> Option<BoxPx> {
    let (s, c) = heading.sin_cos();
    let mut b = BoxPx {
        x0: f64::INFINITY,
        y0: f64::INFINITY,
        x1: f64::NEG_INFINITY,
        y1: f64::NEG_INFINITY,
    };
    // The hull's corners: the body's (full footprint, road to beltline) and the roof's (the
    // cabin's footprint at the top). The cabin's bottom corners lie inside the body's top face
    // and never bound the image; a cuboid (beltline at the top) is its body alone.
    // (length fraction, width fraction, heights as fractions of the height)
    let body: (f64, f64, &[f64]) = (1.0, 1.0, &[0.0, cabin.belt]);
    let roof: (f64, f64, &[f64]) = (cabin.length, cabin.width, &[1.0]);
    let parts: &[_] = if cabin.belt < 1.0 {
        &[body, roof]
    } else {
        &[body]
    };
    for &(lf, wf, zs) in parts {
        for a in [-0.5, 0.5] {
            for w in [-0.5, 0.5] {
                let (dx, dy) = (a * lf * dims[0], w * wf * dims[1]);
                let x = centre[0] + dx * c - dy * s;
                let y = centre[1] + dx * s + dy * c;
                for &z in zs {
                    let p = pixel_of(cal, frame, [x, y, z * dims[2]])?;
                    b.x0 = b.x0.min(p.x);
                    b.y0 = b.y0.min(p.y);
                    b.x1 = b.x1.max(p.x);
                    b.y1 = b.y1.max(p.y);
                }
            }
        }
    }
    Some(b)
}

/// Squared misfit of a cuboid's image `fitted` against the detector box `bbox`: the sum of
/// the four sides' squared offsets over the box's squared diagonal (infinite without an
/// image).
pub fn box_misfit(bbox: &BoxPx, fitted: Option<BoxPx>) -> f64 {
    let diag2 = bbox.width().powi(2) + bbox.height().powi(2);
    match fitted {
        Some(b) => {
            ((b.x0 - bbox.x0).powi(2)
                + (b.y0 - bbox.y0).powi(2)
                + (b.x1 - bbox.x1).powi(2)
                + (b.y1 - bbox.y1).powi(2))
                / diag2
        }
        None => f64::INFINITY,
    }
}

/// The cuboid of proportions `dims` (metres) heading `heading` whose image fits `bbox`
/// best; `None` when the box's bottom does not see the road.
pub fn fit_cuboid(
    cal: &Calibration,
    bbox: BoxPx,
    heading: f64,
    dims: [f64; 3],
) -> Option<CuboidFit> {
    fit_vehicle(cal, bbox, heading, dims, Cabin::NONE)
}

/// The vehicle of bounding cuboid proportions `dims` (metres) and cabin `cabin` heading
/// `heading` whose image ([`vehicle_box`]) fits `bbox` best; `None` when the box's bottom
/// does not see the road.
pub fn fit_vehicle(
    cal: &Calibration,
    bbox: BoxPx,
    heading: f64,
    dims: [f64; 3],
    cabin: Cabin,
) -> Option<CuboidFit> {
    let bottom = Point2::new(0.5 * (bbox.x0 + bbox.x1), bbox.y1);
    let q0 = cal.road_point(bottom)?;
    let left = cal.road_point(Point2::new(bbox.x0, bbox.y1))?;
    let right = cal.road_point(Point2::new(bbox.x1, bbox.y1))?;
    let across = ((left[0] - right[0]).powi(2) + (left[1] - right[1]).powi(2)).sqrt();
    if across.is_nan() || across <= 0.0 {
        return None;
    }
    let frame = cal.road_frame();
    let misfit = |p: &[f64]| -> f64 {
        let size = p[2].exp();
        let d = [size * dims[0], size * dims[1], size * dims[2]];
        box_misfit(
            &bbox,
            vehicle_box_in(cal, &frame, [p[0], p[1]], heading, d, cabin),
        )
    };
    // The box's width on the road at its bottom is roughly the car's width or length seen
    // obliquely: start from a few sizes around it.
    let size0 = across / dims[1];
    let mut best: Option<(f64, Vec<f64>)> = None;
    for k in [0.4, 0.7, 1.0] {
        let size = size0 * k;
        // The bottom of the box is the near edge of the footprint: the centre lies beyond.
        let start = [q0[0], q0[1], size.ln()];
        let step = [0.5 * size * dims[0], 0.5 * size * dims[1], 0.2];
        let m = nelder_mead(misfit, &start, &step, 600);
        if best.as_ref().is_none_or(|b| m.value < b.0) {
            best = Some((m.value, m.x));
        }
    }
    let (value, x) = best?;
    let fit = CuboidFit {
        size: x[2].exp(),
        centre: [x[0], x[1]],
        rms: (value / 4.0).sqrt(),
    };
    (fit.size.is_finite() && fit.rms.is_finite()).then_some(fit)
}

/// An automatic metric scale.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct VehicleScale {
    /// Metres per plane unit (the BCS `scale`).
    pub m_per_unit: f64,
    /// 68 % interval of it: sampling spread (bootstrap over vehicles) and the fleet's
    /// ([`FLEET_LOG_SD`]) together.
    pub interval: [f64; 2],
    /// Sampling spread alone, in `ln`.
    pub sampling_log_sd: f64,
    /// Vehicles (tracks, or single boxes without a track) that counted, and boxes.
    pub vehicles: usize,
    pub boxes: usize,
    /// Boxes fitted but rejected for their misfit, and cut by the border.
    pub rejected_misfit: usize,
    pub rejected_border: usize,
    /// Median misfit of the used boxes (fraction of the diagonal).
    pub median_rms: f64,
}

/// The metric scale of `cal` from `boxes` in a `width` x `height` image, with the typical
/// vehicle `dims` (metres, e.g. [`PASSENGER_CAR`]) and its `cabin` (e.g.
/// [`PASSENGER_CAR_CABIN`]); `None` with fewer than [`MIN_VEHICLES`] usable vehicles.
pub fn scale_from_vehicles(
    cal: &Calibration,
    boxes: &[SizedBox],
    width: f64,
    height: f64,
    dims: [f64; 3],
    cabin: Cabin,
    seed: u64,
) -> Option<VehicleScale> {
    let mut rejected_border = 0;
    let mut rejected_misfit = 0;
    // (group, ln metres-per-unit, rms)
    let mut fits: Vec<(Option<u64>, f64, f64)> = Vec::new();
    let mut clear: Vec<&SizedBox> = Vec::new();
    for b in boxes.iter().filter(|b| b.bbox.is_valid()) {
        if b.bbox.clear_of_edges(width, height, BORDER_PX) {
            clear.push(b);
        } else {
            rejected_border += 1;
        }
    }
    // One fit per box, independent: spread over the cores.
    let cuboids = crate::solve::par_map(&clear, |b| {
        fit_vehicle(cal, b.bbox, b.heading.unwrap_or(0.0), dims, cabin)
    });
    for (b, fit) in clear.iter().zip(cuboids) {
        let Some(fit) = fit else {
            continue;
        };
        if fit.rms > MAX_FIT_RMS {
            rejected_misfit += 1;
            continue;
        }
        fits.push((b.group, -fit.size.ln(), fit.rms));
    }
    // One value per vehicle: the median of its boxes.
    let mut groups: std::collections::BTreeMap<u64, Vec<f64>> = Default::default();
    let mut values = Vec::new();
    for (g, v, _) in &fits {
        match g {
            Some(g) => groups.entry(*g).or_default().push(*v),
            None => values.push(*v),
        }
    }
    for g in groups.values() {
        values.extend(crate::solve::median(g));
    }
    if values.len() < MIN_VEHICLES {
        return None;
    }
    let ones = vec![1.0; values.len()];
    let centre = weighted_shorth(&values, &ones)?;
    let mut rng = SplitMix(seed ^ 0x5CA1_E000);
    let mut resampled = Vec::with_capacity(200);
    for _ in 0..200 {
        let w: Vec<f64> = values.iter().map(|_| rng.poisson1()).collect();
        resampled.extend(weighted_shorth(&values, &w));
    }
    let sampling = crate::solve::sd(&resampled);
    let total = (sampling * sampling + FLEET_LOG_SD * FLEET_LOG_SD).sqrt();
    let rms: Vec<f64> = fits.iter().map(|f| f.2).collect();
    Some(VehicleScale {
        m_per_unit: centre.exp(),
        interval: [(centre - total).exp(), (centre + total).exp()],
        sampling_log_sd: sampling,
        vehicles: values.len(),
        boxes: fits.len(),
        rejected_misfit,
        rejected_border,
        median_rms: crate::solve::median(&rms).unwrap_or(f64::NAN),
    })
}
