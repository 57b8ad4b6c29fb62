//! The spread of the camera under resampling of the physical vehicles: VP1 and the horizon
//! model refitted on Poisson(1) reweightings (one count per vehicle, shared by its boxes).

use super::edgelets::{self, BoxEdgelets, Edgelet, EdgeletFitOptions};
use super::rays::{fit_camera, Vp2Model};
use super::scene_lines::{self, SceneLineOptions};
use super::vehicles::Prepared;
use super::vp1::{fit_vp1, from_sphere, vp1_of, Vp1Lines};
use crate::point::Point2;
use crate::solve::{half_p16_p84, SplitMix};

/// The bootstrap's resamples ([`bootstrap`]).
pub(super) struct Samples {
    /// The focal length, the horizon's angle (degrees) and VP1 of each resample.
    pub focal_px: Vec<f64>,
    pub horizon_deg: Vec<f64>,
    pub vp1_x: Vec<f64>,
    pub vp1_y: Vec<f64>,
    /// Where the rays are not trusted, their own roll in each resample (degrees, before its
    /// prior: [`RaysRoll`](super::rays::RaysRoll)).
    pub rays_roll_own_deg: Vec<f64>,
}

impl Samples {
    /// The resamples' VP1 spread along the unit direction `normal` about `vp1`: half the
    /// 16th-84th percentile range of their offsets (0 with fewer than two resamples).
    pub fn vp1_spread_along(&self, vp1: Point2, normal: Point2) -> f64 {
        if self.vp1_x.len() < 2 {
            return 0.0;
        }
        let along: Vec<f64> = self
            .vp1_x
            .iter()
            .zip(&self.vp1_y)
            .map(|(x, y)| (Point2::new(*x, *y) - vp1).dot(normal))
            .collect();
        half_p16_p84(&along)
    }
}

/// Refit VP1 and the VP2 model (`x` the start) on `resamples` Poisson resamplings of the
/// physical vehicles (one count per vehicle, shared by its boxes: [`vehicle_units`](super::vehicles::vehicle_units); track
/// lines get one count per track). Where the edgelets along the vehicles moved VP1 (`edges`),
/// each resample's VP1 is moved by those of the vehicles it drew (each box as many times as
/// its vehicle's count); where the scene's lines placed VP1 (`scene`), it is moved by them
/// again: they do not change with the vehicles.
#[allow(clippy::too_many_arguments)]
pub(super) fn bootstrap(
    model: &Vp2Model,
    prep: &Prepared,
    vp1_lines: &Vp1Lines,
    p1: [f64; 3],
    x: [f64; 3],
    edges: Option<(&[BoxEdgelets], &EdgeletFitOptions)>,
    scene: Option<(&[Edgelet], &SceneLineOptions)>,
    resamples: usize,
    rng: &mut SplitMix,
) -> Samples {
    let mut out = Samples {
        focal_px: vec![],
        horizon_deg: vec![],
        vp1_x: vec![],
        vp1_y: vec![],
        rays_roll_own_deg: vec![],
    };
    let q1 = from_sphere(p1);
    let scaled =
        |w: &[f64], c: &[f64]| -> Vec<f64> { w.iter().zip(c).map(|(a, c)| a * c).collect() };
    // The draws in order, then the refits (independent of each other) over the cores: the
    // same resamples as drawing and fitting one after another.
    let weights: Vec<(Vec<f64>, Vec<f64>, Vec<f64>)> = (0..resamples)
        .map(|_| {
            let draws: Vec<f64> = (0..prep.units).map(|_| rng.poisson1()).collect();
            let counts: Vec<f64> = prep.unit.iter().map(|&u| draws[u]).collect();
            let w = scaled(&prep.weight, &counts);
            let wv1 = if vp1_lines.from_tracks {
                let counts1: Vec<f64> = (0..vp1_lines.weight.len())
                    .map(|_| rng.poisson1())
                    .collect();
                scaled(&vp1_lines.weight, &counts1)
            } else {
                scaled(&vp1_lines.weight, &counts)
            };
            (w, wv1, draws)
        })
        .collect();
    let refits = crate::solve::par_map(&weights, |(w, wv1, draws)| {
        let threshold = vp1_lines.threshold_deg;
        // With a start, the VP1 fit draws no random numbers.
        let mut unused = SplitMix(0);
        let pb = fit_vp1(vp1_lines.lines(), wv1, threshold, &mut unused, Some(q1))?;
        let vb = vp1_of(pb)?;
        let mb = Vp2Model { vp1: vb, ..*model };
        let fit = fit_camera(&mb, vp1_lines, wv1, w, Some(x));
        let (vb, xb) = (fit.vp1, fit.x);
        let vb = edges
            .and_then(|(boxes, eo)| {
                let drawn: Vec<BoxEdgelets> = boxes
                    .iter()
                    .flat_map(|b| std::iter::repeat_n(*b, draws[b.vehicle] as usize))
                    .collect();
                edgelets::fit_vp1(vb, &drawn, eo)
            })
            .map_or(vb, |e| e.0);
        let vb = scene
            .and_then(|(edgelets, so)| scene_lines::refine_vp1(vb, edgelets, so))
            .map_or(vb, |f| f.vp1);
        let mb = Vp2Model { vp1: vb, ..*model };
        let (hb, ub) = mb.vp2(xb[0], xb[1]);
        let own = fit.own_roll.map(|(own, _)| own.to_degrees());
        Some((vb, vb + hb / ub, xb[0].exp(), own))
    });
    for (vb, vp2b, focal, own) in refits.into_iter().flatten() {
        out.focal_px.push(focal);
        out.horizon_deg
            .push((vp2b.y - vb.y).atan2(vp2b.x - vb.x).to_degrees());
        out.vp1_x.push(vb.x);
        out.vp1_y.push(vb.y);
        out.rays_roll_own_deg.extend(own);
    }
    out
}
