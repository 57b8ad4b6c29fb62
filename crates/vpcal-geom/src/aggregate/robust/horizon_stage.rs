//! The horizon stage: the roll and what set it (the straight edgelet fit, the curved-road
//! fit, the rays' own roll under its prior), with the bootstrap's resamples.

use super::vp1_stage::PlacedVp1;
use super::{Input, RobustOptions, PARALLEL_EDGES_VP2_WIDTHS};
use crate::aggregate::bootstrap::{bootstrap, Samples};
use crate::aggregate::edgelets::{
    self as edge, BoxEdgelets, CurvedFit, CurvedVehicle, Edgelet, EdgeletFitOptions,
};
use crate::aggregate::line_angle_diff;
use crate::aggregate::rays::{RaysRoll, Vp2Model};
use crate::aggregate::robust::Evidence;
use crate::aggregate::tracks::{self, RoadTracks};
use crate::point::Point2;
use crate::solve::{half_p16_p84, sd, SplitMix};

/// A curved road's track tangents span this many boxes before and after each box.
pub(super) const CURVE_TANGENT_HALF: usize = 4;

/// The horizon through VP1: its roll and what set it ([`RollFrom`]), with the bootstrap's
/// resamples.
pub(super) struct Horizon<'a> {
    /// The rays' model around the final VP1 (the curved-road fit's on a curved road).
    pub(super) model: Vp2Model<'a>,
    /// `(ln f, roll, bias)`, the roll from [`RollFrom`].
    pub(super) x: [f64; 3],
    /// The straight edgelet fit, and whether it says the edges across the vehicles are
    /// parallel in the image ([`PARALLEL_EDGES_VP2_WIDTHS`]).
    pub(super) edge_fit: Option<edge::EdgeletFit>,
    pub(super) edges_parallel: bool,
    /// That fit where its roll is usable, its spread with VP1's.
    pub(super) usable: Option<edge::EdgeletFit>,
    pub(super) curved: Option<CurvedFit>,
    pub(super) samples: Option<Samples>,
    pub(super) roll_from: RollFrom,
    /// The untrusted rays' roll model with its sampling spread (`rays_roll_sampling_sd_deg`).
    pub(super) rays_roll: Option<RaysRoll>,
    pub(super) rays_roll_sampling_sd_deg: Option<f64>,
    pub(super) edgelet_roll_vp1_sd_deg: Option<f64>,
}

/// The horizon's roll (`super::edgelets`, `super::rays`): the straight edgelet fit where its
/// roll is usable, on a curved road the curved-road fit (each car's VP1 from its track's
/// tangent), else the rays' own roll under its prior; then the bootstrap's resamples
/// (`super::bootstrap`), whose VP1 spread widens the edgelets' roll and whose rays' rolls
/// widen the rays'.
pub(super) fn place_horizon<'a>(
    input: &Input,
    placed: &PlacedVp1<'a>,
    road: &RoadTracks,
    boxes: &[BoxEdgelets],
    unit: &[usize],
    rng: &mut SplitMix,
) -> Horizon<'a> {
    let (pp, opts, width) = (input.pp, input.opts, input.width());
    let (mut x, vp1, edge_opts) = (placed.x, placed.model.vp1, placed.edge_opts);
    let edge_fit = edge_opts.and_then(|eo| edge::fit(vp1, pp, width, boxes, x[1], eo, opts.seed));
    let edges_parallel = edge_fit.is_some_and(|e| {
        let w = (e.vp2 - pp).norm() / width;
        w.is_nan() || w > PARALLEL_EDGES_VP2_WIDTHS
    });
    let usable = edge_fit.filter(|e| e.roll_usable);
    if let Some(e) = usable {
        x[1] = e.roll;
    }
    // On a curved road every car has its own VP1 on the horizon: the horizon and the focal
    // length from the cars' track tangents and edgelets together.
    let curved = edge_opts.filter(|_| road.road_curved).and_then(|eo| {
        curved_road_fit(road, input.edgelets, unit, input.frame, pp, x[1], eo, opts)
    });
    let model = match curved {
        Some(c) => {
            x[1] = c.roll;
            Vp2Model {
                vp1: c.vp1,
                ..placed.model
            }
        }
        None => placed.model,
    };
    // The bootstrap's resamples: the focal lengths of trusted rays, the horizon and VP1.
    let samples = (opts.bootstrap > 0).then(|| {
        let moved = &placed.moved;
        let edges = moved.edges.and(edge_opts).map(|eo| (boxes, eo));
        let scene = moved
            .scene
            .and(placed.scene_opts)
            .map(|so| (input.scene.edgelets, so));
        let (lines, p1, n) = (&placed.located.lines, placed.located.p1, opts.bootstrap);
        bootstrap(&model, model.prep, lines, p1, x, edges, scene, n, rng)
    });
    // The rays' own roll moves with the vehicles drawn and with VP1, through which their
    // horizon runs: its spread over the resamples joins its error model.
    let spread = samples
        .as_ref()
        .filter(|b| b.rays_roll_own_deg.len() > 1)
        .map(|b| half_p16_p84(&b.rays_roll_own_deg));
    let rays_roll = placed
        .rays_roll
        .map(|(_, rr)| spread.map_or(rr, |s| rr.with_sampling(s)));
    // The straight edgelet fit held VP1 where it was placed; VP1's spread across the horizon
    // (its resamples') turns that fit's roll too (`edge::roll_vp1_sd_deg`).
    let mut edgelet_roll_vp1_sd_deg = None;
    let usable = match (usable, edge_opts) {
        (Some(e), Some(eo)) if curved.is_none() => {
            let normal = Point2::new(-e.roll.sin(), e.roll.cos());
            let shift = samples
                .as_ref()
                .map_or(0.0, |b| b.vp1_spread_along(vp1, normal));
            let sd = edge::roll_vp1_sd_deg(&e, vp1, pp, boxes, eo, shift);
            edgelet_roll_vp1_sd_deg = Some(sd).filter(|s| s.is_finite());
            Some(e.with_vp1_spread(sd))
        }
        (u, _) => u,
    };
    let roll_from = RollFrom::of(curved, usable, rays_roll);
    // Where the rays set the roll it is weighed against the prior again.
    if let (RollFrom::Rays(rr), Some((own, _))) = (roll_from, placed.rays_roll) {
        x[1] = rr.roll(own.to_radians());
    }
    Horizon {
        model,
        x,
        edge_fit,
        edges_parallel,
        usable,
        curved,
        samples,
        roll_from,
        rays_roll,
        rays_roll_sampling_sd_deg: spread,
        edgelet_roll_vp1_sd_deg,
    }
}

impl Horizon<'_> {
    /// Writes what the horizon's stage found; `width`: of the frames, pixels.
    pub(super) fn record(&self, width: f64, e: &mut Evidence) {
        e.rays_roll_sampling_sd_deg = self.rays_roll_sampling_sd_deg;
        if let Some(rr) = self.rays_roll {
            e.rays_roll_sd_deg = Some(rr.sd_deg);
        }
        e.edgelet_roll_vp1_sd_deg = self.edgelet_roll_vp1_sd_deg;
        if let Some(f) = self.edge_fit {
            e.edgelets = f.edgelets;
            e.edgelet_vehicles = f.vehicles;
            e.edgelet_focal_px = Some(f.focal_px);
            e.edgelet_roll_sd_deg = Some(f.roll_sd_deg);
            e.edgelet_roll_deg = Some(f.roll.to_degrees());
            e.edgelet_roll_turn_sd_deg = Some(f.roll_turn_sd_deg);
            e.edgelet_focal_log_spread = Some(f.focal_log_spread());
            e.edgelet_vp2_widths = Some((f.vp2 - self.model.pp).norm() / width);
            e.edgelet_focal_bias_log_spread = Some(f.focal_bias_log_spread);
        }
        e.roll_from_edgelets = self.usable.is_some();
        e.curved_fit = self.curved.is_some();
        e.curved_vehicles = self.curved.map_or(0, |c| c.vehicles);
    }

    /// The roll's standard deviation, degrees ([`RollFrom::sd_deg`]).
    pub(super) fn roll_sd_deg(&self) -> f64 {
        self.roll_from
            .sd_deg(self.samples.as_ref(), self.x[1].to_degrees())
    }
}

/// What set the horizon's roll, in order of precedence: the curved-road fit, the straight
/// edgelet fit where its roll is usable, the untrusted rays' own roll under its physical
/// prior, else the rays' joint fit (trusted) with the bootstrap's spread.
#[derive(Debug, Clone, Copy)]
pub(super) enum RollFrom {
    Curved(CurvedFit),
    Edgelets(edge::EdgeletFit),
    Rays(RaysRoll),
    Bootstrap,
}

impl RollFrom {
    pub(super) fn of(
        curved: Option<CurvedFit>,
        edges: Option<edge::EdgeletFit>,
        rays: Option<RaysRoll>,
    ) -> RollFrom {
        match (curved, edges, rays) {
            (Some(c), _, _) => RollFrom::Curved(c),
            (None, Some(e), _) => RollFrom::Edgelets(e),
            (None, None, Some(r)) => RollFrom::Rays(r),
            (None, None, None) => RollFrom::Bootstrap,
        }
    }

    /// The roll's standard deviation, degrees: the fit's own (the edgelets' with their turn,
    /// the rays' posterior), or the spread of the resamples `samples` around `roll_deg` (0
    /// with fewer than two).
    pub(super) fn sd_deg(&self, samples: Option<&Samples>, roll_deg: f64) -> f64 {
        match self {
            RollFrom::Curved(c) => c.roll_total_sd_deg(),
            RollFrom::Edgelets(e) => e.roll_total_sd_deg(),
            RollFrom::Rays(r) => r.sd_after_deg(),
            RollFrom::Bootstrap => samples
                .filter(|b| b.horizon_deg.len() > 1)
                .map_or(0.0, |b| horizon_sd_deg(b, roll_deg)),
        }
    }
}

/// The curved-road fit ([`edge::fit_curved`]) on the tracked vehicles with edgelets, each
/// with its track's tangent.
#[allow(clippy::too_many_arguments)]
pub(super) fn curved_road_fit(
    road: &RoadTracks,
    edgelets: &[Vec<Edgelet>],
    unit: &[usize],
    [width, height]: [f64; 2],
    pp: Point2,
    roll: f64,
    eo: &EdgeletFitOptions,
    opts: &RobustOptions,
) -> Option<CurvedFit> {
    let tangents = tracks::tangents(&road.boxes, &road.links, CURVE_TANGENT_HALF, 3.0);
    let vehicles: Vec<CurvedVehicle> = tangents
        .iter()
        .zip(&road.pairs)
        .filter_map(|(t, &i)| {
            let e = edgelets.get(i)?;
            (!e.is_empty()).then_some(CurvedVehicle {
                tangent: (*t)?,
                edgelets: e,
                vehicle: unit[i],
            })
        })
        .collect();
    edge::fit_curved(pp, width, height, &vehicles, roll, eo, opts.seed)
}

/// The standard deviation of the resamples' horizon angles, degrees, measured as line angles
/// around `a0_deg` (angles near ±180° wrap).
pub(super) fn horizon_sd_deg(b: &Samples, a0_deg: f64) -> f64 {
    let angles: Vec<f64> = b
        .horizon_deg
        .iter()
        .map(|a| line_angle_diff((a - a0_deg).to_radians()).to_degrees())
        .collect();
    sd(&angles)
}
