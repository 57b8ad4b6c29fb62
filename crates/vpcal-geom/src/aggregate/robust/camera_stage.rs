//! The camera stage: the camera of VP1, the horizon and the focal posterior's f, checked
//! against the vehicles, with the estimate's spread.

use super::focal_stage::FocalCues;
use super::horizon_stage::{Horizon, RollFrom};
use super::{not_enough, Input};
use crate::aggregate::bootstrap::Samples;
use crate::aggregate::line_angle_diff;
use crate::aggregate::rays::Vp2Model;
use crate::aggregate::robust::{Confidence, Evidence, RobustResult};
use crate::aggregate::sizes;
use crate::aggregate::tracks::RoadTracks;
use crate::aggregate::vehicles::Prepared;
use crate::aggregate::AggregateError;
use crate::camera::Calibration;
use crate::solve::{half_p16_p84, percentile};

/// The camera of VP1, the horizon's roll and the focal posterior's f: where f moved off the
/// value the VP2 model held, the roll and the rays' bias are refitted with f held there
/// (unless another source set the roll), the roll weighed against its prior again; then the
/// horizon against the vehicles (`super::sizes`) and the spread of the estimate.
pub(super) fn make_camera(
    input: &Input,
    full: &Prepared,
    horizon: Horizon,
    cues: FocalCues,
    mut evidence: Evidence,
    road: RoadTracks,
) -> Result<RobustResult, AggregateError> {
    let (pp, opts) = (input.pp, input.opts);
    let (focal, roll_from, mut x) = (cues.posterior, horizon.roll_from, horizon.x);
    let model = Vp2Model {
        f0: focal.focal_px,
        ..horizon.model
    };
    let (vp1, prep) = (model.vp1, model.prep);
    if let (true, RollFrom::Rays(rr)) = (focal.measured, roll_from) {
        x = Vp2Model {
            fixed_ln_f: Some(focal.focal_px.ln()),
            ..model
        }
        .fit(&prep.weight, Some([focal.focal_px.ln(), x[1], x[2]]));
        evidence.rays_roll_own_deg = Some(x[1].to_degrees());
        x[1] = rr.roll(x[1]);
    }
    x[0] = focal.focal_px.ln();
    let (h, u) = model.vp2(x[0], x[1]);
    let calibration = Calibration::from_vps(vp1, vp1 + h / u, pp)
        .map_err(|e| not_enough(format!("the estimate is not a valid camera: {e}")))?;
    // Vanishing points billions of pixels away (lines parallel in the image: a view straight
    // down) hold the focal length only to rounding: such a camera is not measured.
    if (calibration.focal_px / focal.focal_px - 1.0).abs() > FOCAL_ROUNDING_TOLERANCE {
        return Err(not_enough(format!(
            "the vanishing points lie too far out to place the camera (VP1 {:.3e} px from \
             the principal point, VP2 {:.3e} px: the lines along and across the road are \
             parallel in the image, as in a view straight down)",
            (vp1 - pp).norm(),
            (calibration.vp2 - pp).norm()
        )));
    }
    // The vehicles stand below the horizon and grow away from it (`super::sizes`).
    evidence.size_slope = sizes::check_horizon(
        &full.centre,
        &full.boxes,
        &full.weight,
        calibration.horizon,
        pp,
        input.frame,
        opts.max_above_horizon,
    )
    .map_err(not_enough)?;
    let s2 = opts.ray_scale_deg.to_radians();
    evidence.vp2_inliers = full
        .centre
        .iter()
        .zip(&full.angle2)
        .filter(|(c, a)| {
            let d = (vp1 - **c) * u + h;
            line_angle_diff(**a - d.y.atan2(d.x) - x[2]).abs() < 3.0 * s2
        })
        .count();
    let confidence = horizon.samples.and_then(|b| {
        // Where an edgelet fit carried f, its bootstrap is f's.
        let edge_focal = match roll_from {
            RollFrom::Curved(c) if evidence.curved_focal => Some([c.focal_px_p16, c.focal_px_p84]),
            RollFrom::Edgelets(e) if evidence.focal_from_edgelets => {
                Some([e.focal_px_p16, e.focal_px_p84])
            }
            _ => None,
        };
        let horizon_sd = roll_from.sd_deg(Some(&b), calibration.horizon.angle().to_degrees());
        // Contradicted by the plumb lines, the horizon is known no better than the two differ.
        let horizon_sd = cues
            .conflict
            .map_or(horizon_sd, |(_, d)| horizon_sd.hypot(d.to_degrees()));
        confidence(&b, &model, prep, horizon_sd, edge_focal)
    });
    Ok(RobustResult {
        calibration,
        roll: x[1],
        ray_bias: x[2],
        evidence,
        confidence,
        focal,
        track_lines: road.straight,
    })
}

/// How far the focal length of the camera built from VP1 and VP2 may differ from the one
/// fitted, relative: in exact arithmetic they are equal, and they part only where the
/// vanishing points lie so far out that rounding their coordinates swamps the focal length.
pub(super) const FOCAL_ROUNDING_TOLERANCE: f64 = 1e-6;

/// The estimate's spread from the bootstrap's resamples `b`; `horizon_sd`: the roll's
/// ([`RollFrom::sd_deg`]); `edge_focal`: where an edgelet fit carried f, its bootstrap's 16th
/// and 84th percentiles of f.
pub(super) fn confidence(
    b: &Samples,
    model: &Vp2Model,
    prep: &Prepared,
    horizon_sd: f64,
    edge_focal: Option<[f64; 2]>,
) -> Option<Confidence> {
    if b.focal_px.is_empty() {
        return None;
    }
    let data_only = Vp2Model {
        fixed_bias: Some(0.0),
        ..*model
    }
    .fit(&prep.weight, None)[0]
        .exp();
    // Where f is held (untrusted rays), all of this bootstrap's resamples agree.
    let [p16, p84] = edge_focal.unwrap_or_else(|| {
        [
            percentile(b.focal_px.clone(), 16.0),
            percentile(b.focal_px.clone(), 84.0),
        ]
    });
    Some(Confidence {
        focal_px_p16: p16,
        focal_px_p84: p84,
        horizon_angle_sd_deg: horizon_sd,
        // One VP1 per resample, and there is at least one.
        vp1_sd_px: ((half_p16_p84(&b.vp1_x).powi(2) + half_p16_p84(&b.vp1_y).powi(2)) / 2.0).sqrt(),
        focal_px_data_only: data_only,
        resamples: b.focal_px.len(),
    })
}
