//! The VP1 stage: where the tracks' or the network's VP1 lines meet, the network's VP2 rays
//! fitted around it, then the moves by the edges along the vehicles and the scene's lines.

use super::{not_enough, Input, RobustOptions};
use crate::aggregate::edgelets::{self as edge, BoxEdgelets, Edgelet, EdgeletFitOptions};
use crate::aggregate::rays::{fit_camera, RaysRoll, Vp2Model};
use crate::aggregate::robust::Evidence;
use crate::aggregate::scene_lines::{self, SceneLineOptions, SceneVp1};
use crate::aggregate::tracks::RoadTracks;
use crate::aggregate::vehicles::Prepared;
use crate::aggregate::vp1::{self, homogeneous, Vp1Lines};
use crate::aggregate::AggregateError;
use crate::point::Point2;
use crate::solve::SplitMix;

/// VP1 and what placed it (`super::vp1`, then the moves of [`move_vp1`]), with the network's
/// VP2 rays fitted around it (`super::rays`).
pub(super) struct PlacedVp1<'a> {
    pub(super) located: vp1::Located,
    /// The rays' horizon model, around VP1 where the moves left it.
    pub(super) model: Vp2Model<'a>,
    /// The rays' fit: `(ln f, roll, bias)`, and whether they were trusted.
    pub(super) x: [f64; 3],
    pub(super) rays_trusted: bool,
    /// Untrusted, the rays' own roll (degrees) and its model, weighed against the physical
    /// prior on the horizon's angle.
    pub(super) rays_roll: Option<(f64, RaysRoll)>,
    pub(super) moved: MovedVp1,
    /// The edgelet and scene-line settings where there is something for them to fit.
    pub(super) edge_opts: Option<&'a EdgeletFitOptions>,
    pub(super) scene_opts: Option<&'a SceneLineOptions>,
}

/// VP1 where the tracks' or the network's VP1 lines meet (`super::vp1`), the network's VP2
/// rays around it (trusted, they fit f, the roll and VP1 with it; else the roll and their bias
/// are fitted with f held at the prior's middle), then moved by the edges along the vehicles
/// and the scene's lines along the road ([`move_vp1`]).
pub(super) fn place_vp1<'a>(
    input: &Input<'a>,
    full: &Prepared,
    prep: &'a Prepared,
    road: &mut RoadTracks,
    boxes: &[BoxEdgelets],
    rng: &mut SplitMix,
) -> Result<PlacedVp1<'a>, AggregateError> {
    let (pp, opts, width) = (input.pp, input.opts, input.width());
    let choice = opts.vp1_choice();
    let located = vp1::locate(full, prep, road, pp, width, &choice, rng).map_err(not_enough)?;
    // Straight tracks that do not meet at one VP1, while at least `min_curved_tracks` bend
    // alike: the road curves through part of the view, and the share test had counted the
    // straight stretch's tracks against it.
    if located.tracks_disagree && road.curved_tracks >= opts.min_curved_tracks.max(1) {
        road.road_curved = true;
    }
    let model = Vp2Model {
        vp1: located.vp1,
        pp,
        prep,
        opts: opts.ray_options(),
        f0: opts.focal_prior_ratio * width,
        fixed_bias: None,
        fixed_ln_f: None,
    };
    let lines = &located.lines;
    let fit = fit_camera(&model, lines, &lines.weight, &prep.weight, None);
    let scene = input.scene.edgelets;
    let edge_opts = opts.edgelets.as_ref().filter(|_| !boxes.is_empty());
    let scene_opts = opts
        .scene_lines
        .as_ref()
        .filter(|_| !road.road_curved && !scene.is_empty());
    let moved = move_vp1(fit.vp1, lines, boxes, edge_opts, scene, scene_opts, opts);
    Ok(PlacedVp1 {
        model: Vp2Model {
            vp1: moved.vp1,
            ..model
        },
        x: fit.x,
        rays_trusted: fit.trusted,
        rays_roll: fit.own_roll.map(|(own, rr)| (own.to_degrees(), rr)),
        moved,
        edge_opts,
        scene_opts,
        located,
    })
}

impl PlacedVp1<'_> {
    pub(super) fn record(&self, road: &RoadTracks, e: &mut Evidence) {
        e.track_lines = road.straight.len();
        e.curved_tracks = road.curved_tracks;
        e.road_curved = road.road_curved;
        e.vp1_inliers = self.located.inliers;
        e.vp1_from_tracks = self.located.lines.from_tracks;
        e.vp1_ray_scatter_deg = self.located.network_scatter;
        e.track_residual_deg = self.located.track_residual;
        e.rays_trusted = self.rays_trusted;
        e.rays_roll_own_deg = self.rays_roll.map(|(own, _)| own);
        self.moved.record(e);
    }
}

/// VP1 after the edges along the vehicles and the scene's lines moved it.
#[derive(Debug, Clone, Copy)]
pub(super) struct MovedVp1 {
    pub(super) vp1: Point2,
    /// The edgelets' VP1 and how many edgelets gave it.
    pub(super) edges: Option<(Point2, usize, usize)>,
    /// The scene lines' VP1 where used, how far it moved VP1 (pixels), and how much it raised
    /// the median angle of the vehicles' VP1 lines, whether used or not (degrees).
    pub(super) scene: Option<SceneVp1>,
    pub(super) scene_shift_px: Option<f64>,
    pub(super) scene_extra_deg: Option<f64>,
}

impl MovedVp1 {
    pub(super) fn record(&self, e: &mut Evidence) {
        e.vp1_from_edgelets = self.edges.is_some();
        e.vp1_edgelets = self.edges.map_or(0, |e| e.1);
        e.vp1_from_scene_lines = self.scene.is_some();
        e.vp1_scene_edgelets = self.scene.map_or(0, |f| f.edgelets);
        e.vp1_scene_shift_px = self.scene_shift_px;
        e.vp1_scene_extra_deg = self.scene_extra_deg;
    }
}

/// Without tracks, the edgelets along the vehicles place VP1 better than the network's VP1
/// rays (module docs of `edgelets`); the scene's lines along the road place it better than
/// the vehicles (module docs of `scene_lines`) where the vehicles' lines still agree with the
/// point they give (`opts.scene_max_extra_deg`).
pub(super) fn move_vp1(
    vp1: Point2,
    lines: &Vp1Lines,
    boxes: &[BoxEdgelets],
    edge_opts: Option<&EdgeletFitOptions>,
    scene: &[Edgelet],
    scene_opts: Option<&SceneLineOptions>,
    opts: &RobustOptions,
) -> MovedVp1 {
    let edges = edge_opts
        .filter(|_| !lines.from_tracks)
        .and_then(|eo| edge::fit_vp1(vp1, boxes, eo));
    let vp1 = edges.map_or(vp1, |e| e.0);
    let fit = scene_opts.and_then(|so| scene_lines::refine_vp1(vp1, scene, so));
    let residual_at = |v: Point2| lines.median_residual_deg(homogeneous(v));
    let extra = fit.and_then(|f| Some(residual_at(f.vp1)? - residual_at(vp1)?));
    let used = fit.filter(|_| extra.is_some_and(|x| x <= opts.scene_max_extra_deg));
    MovedVp1 {
        vp1: used.map_or(vp1, |f| f.vp1),
        edges,
        scene: used,
        scene_shift_px: used.map(|f| (f.vp1 - vp1).norm()),
        scene_extra_deg: extra,
    }
}
