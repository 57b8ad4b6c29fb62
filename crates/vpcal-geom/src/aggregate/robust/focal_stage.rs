//! The focal stage: each focal cue where its model holds, and their posterior.

use super::horizon_stage::Horizon;
use super::vp1_stage::PlacedVp1;
use super::{not_enough, Input};
use crate::aggregate::bootstrap::Samples;
use crate::aggregate::focal::{self, FocalPosterior, FocalSource};
use crate::aggregate::rays::{rays_focal, RaysFocal};
use crate::aggregate::robust::Evidence;
use crate::aggregate::tracks::RoadTracks;
use crate::aggregate::verticals;
use crate::aggregate::AggregateError;
use crate::solve::percentile;

/// The focal sources (`super::focal`) and their posterior.
pub(super) struct FocalCues {
    /// The untrusted rays' likelihood of f.
    pub(super) rays: Option<RaysFocal>,
    pub(super) verticals: Option<verticals::VerticalsFit>,
    /// The plumb lines' roll against the horizon's: `(z, difference)`, and the difference
    /// where it is a conflict ([`verticals::HORIZON_CONFLICT_Z`]).
    pub(super) against: Option<(f64, f64)>,
    pub(super) conflict: Option<(f64, f64)>,
    pub(super) posterior: FocalPosterior,
}

/// Each focal cue where its model holds, and their posterior: on a curved road only the
/// curved fit (every car has its own VP2, so neither the rays nor the straight edgelet fit
/// apply); the rays and the edges across the vehicles not where those edges are parallel in
/// the image (a view straight down, where f cannot be observed); the scene's vertical lines
/// wherever the horizon is placed; none where the plumb lines contradict the horizon.
pub(super) fn fuse_focal(
    input: &Input,
    placed: &PlacedVp1,
    horizon: &Horizon,
    road: &RoadTracks,
) -> Result<FocalCues, AggregateError> {
    let (pp, opts) = (input.pp, input.opts);
    let range_px = input.range_px();
    let weight = &placed.model.prep.weight;
    // Rays the VP2 points contradict still say something about f where VP2 is near: their
    // likelihood over ln f (`rays_focal_likelihood`), around VP1 before a curved-road fit.
    let rays = (!placed.rays_trusted).then(|| rays_focal(&placed.model, weight, range_px));
    let trusted = placed
        .rays_trusted
        .then(|| trusted_rays(horizon.x[0].exp(), horizon.samples.as_ref()));
    // The scene's vertical lines need only the horizon: VP1 on it and its roll, with the
    // roll's spread (the edgelets' where they set it, the rays' posterior's where they did,
    // else the bootstrap's).
    let horizon_placed = horizon.curved.is_some() || !road.road_curved;
    let roll_sd_deg = horizon.roll_sd_deg();
    let (vp1, roll) = (horizon.model.vp1, horizon.x[1]);
    let verticals = opts
        .verticals
        .as_ref()
        .filter(|_| horizon_placed && !input.scene.segments.is_empty())
        .and_then(|vo| {
            let support = focal::support(range_px);
            let roll_sd = roll_sd_deg.to_radians();
            verticals::fit(
                input.scene.segments,
                vp1,
                pp,
                roll,
                roll_sd,
                support,
                vo,
                opts.seed,
            )
        });
    // Plumb lines meet at gravity's VP3: where their own roll contradicts the road horizon's
    // beyond the road's cross slope and both errors, the horizon (or the verticals) is wrong,
    // and no focal cue is used: every one (the verticals under the horizon's roll, the
    // edgelets' and the rays' VP2 on it, the curved fit's one plane) rests on that horizon.
    let against = verticals
        .as_ref()
        .zip(opts.verticals.as_ref())
        .and_then(|(v, vo)| v.against_horizon(roll, roll_sd_deg.to_radians(), vo));
    let conflict = against.filter(|(z, _)| z.abs() > verticals::HORIZON_CONFLICT_Z);
    let vertical = verticals.as_ref().map(|v| v as &dyn FocalSource);
    let sources: Vec<&dyn FocalSource> = match &horizon.curved {
        _ if conflict.is_some() => vec![],
        Some(c) => [Some(c as &dyn FocalSource), vertical]
            .into_iter()
            .flatten()
            .collect(),
        None if !road.road_curved && !horizon.edges_parallel => {
            let edges = horizon.usable.as_ref().map(|e| e as &dyn FocalSource);
            let trusted = trusted.as_ref().map(|t| t as &dyn FocalSource);
            let rays = rays.as_ref().map(|r| r as &dyn FocalSource);
            [edges, trusted, rays, vertical]
                .into_iter()
                .flatten()
                .collect()
        }
        None => vertical.into_iter().collect(),
    };
    let posterior = focal::fuse(range_px, &focal::cues_of(&sources))
        .ok_or_else(|| not_enough(format!("invalid focal range {range_px:?} px")))?;
    Ok(FocalCues {
        rays,
        verticals,
        against,
        conflict,
        posterior,
    })
}

impl FocalCues {
    pub(super) fn record(&self, e: &mut Evidence) {
        let carried = |s: &str| self.posterior.carried_by.contains(&s);
        if let Some(r) = &self.rays {
            e.rays_focal_px = Some(r.fit[0].exp());
            e.rays_scatter_deg = Some(r.scatter_deg);
            e.rays_vp2_sd_deg = Some(r.sd_deg).filter(|s| s.is_finite());
            e.rays_posterior_px = r.posterior;
        }
        e.focal_from_rays = carried("network_rays");
        if let Some(v) = &self.verticals {
            e.vertical_candidates = v.candidates;
            e.vertical_supporting = v.supporting;
            e.verticals_focal_px = v.identified.then_some(v.focal_px);
            e.verticals_roll_deg = v.own_roll.map(f64::to_degrees);
            e.verticals_roll_sd_deg = v
                .own_roll
                .map(|_| v.own_roll_sd.to_degrees())
                .filter(|s| s.is_finite());
        }
        e.verticals_roll_z = self.against.map(|(z, _)| z);
        e.horizon_conflict_deg = self.conflict.map(|(_, d)| d.to_degrees());
        e.focal_from_verticals = carried("verticals");
        e.focal_from_edgelets = carried("edgelets");
        e.curved_focal = carried("curved_edgelets");
    }
}

/// The trusted rays' fit of f as a cue: its bootstrap's 16th-84th percentiles.
pub(super) fn trusted_rays(focal_px: f64, samples: Option<&Samples>) -> focal::Measured {
    let fs = samples.map_or(&[][..], |s| &s.focal_px[..]);
    let bootstrap_px = if fs.len() >= 2 {
        [percentile(fs.to_vec(), 16.0), percentile(fs.to_vec(), 84.0)]
    } else {
        [1.0, 1.0]
    };
    focal::Measured {
        name: "network",
        focal_px,
        bootstrap_px,
        turn: 0.0,
    }
}
