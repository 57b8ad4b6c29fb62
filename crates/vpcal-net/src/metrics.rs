//! Validation metrics: relative VP errors in the box frame, per scale and after the `D^s`
//! scale selection (DESIGN.md §4).
//!
//! The relative error of a predicted VP `v̂` against the truth `v` is `|v̂ - v| / |v|`; a
//! non-finite prediction counts as `+inf` (it sorts last, so a median stays finite while most
//! predictions are).

use serde::{Deserialize, Serialize};
use vpcal_geom::heatmap::VpPrediction;
use vpcal_geom::Point2;

/// Relative error `|pred - truth| / |truth|`; `+inf` when the prediction is not finite or the
/// truth is the origin.
pub fn relative_error(pred: Point2, truth: Point2) -> f64 {
    let n = truth.norm();
    if !pred.is_finite() || !truth.is_finite() || n == 0.0 {
        return f64::INFINITY;
    }
    (pred - truth).norm() / n
}

/// Median of values (`+inf` allowed, NaN ignored); `None` when empty.
pub use vpcal_geom::solve::median;

/// Accumulates relative VP errors over a validation pass.
#[derive(Debug, Clone, Default)]
pub struct VpErrorAccumulator {
    /// `[vp][scale]` errors.
    per_scale: [Vec<Vec<f64>>; 2],
    /// `[vp]` errors after scale selection.
    selected: [Vec<f64>; 2],
    /// How often each scale was selected, `[vp][scale]`.
    chosen: [Vec<usize>; 2],
}

impl VpErrorAccumulator {
    /// Add one decoded crop with its true VPs (box frame).
    pub fn add(&mut self, pred: &VpPrediction, vp1: Point2, vp2: Point2) {
        let truth = [vp1, vp2];
        for (vp, t) in truth.iter().enumerate() {
            let n = pred.per_scale.len();
            if self.per_scale[vp].len() < n {
                self.per_scale[vp].resize(n, Vec::new());
                self.chosen[vp].resize(n, 0);
            }
            for (s, pair) in pred.per_scale.iter().enumerate() {
                self.per_scale[vp][s].push(relative_error(pair[vp], *t));
            }
            let (sel, idx) = if vp == 0 {
                (pred.vp1, pred.vp1_scale)
            } else {
                (pred.vp2, pred.vp2_scale)
            };
            self.selected[vp].push(relative_error(sel, *t));
            if let Some(c) = self.chosen[vp].get_mut(idx) {
                *c += 1;
            }
        }
    }

    /// Add a directly regressed VP pair (no scales).
    pub fn add_direct(&mut self, pred: [Point2; 2], truth: [Point2; 2]) {
        for vp in 0..2 {
            self.selected[vp].push(relative_error(pred[vp], truth[vp]));
        }
    }

    /// Number of crops seen.
    pub fn len(&self) -> usize {
        self.selected[0].len()
    }

    /// True when nothing was added.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The summary.
    pub fn summary(&self) -> VpMetrics {
        let med = |v: &[f64]| median(v).unwrap_or(f64::NAN);
        VpMetrics {
            crops: self.len(),
            vp1_median_rel: med(&self.selected[0]),
            vp2_median_rel: med(&self.selected[1]),
            vp1_median_rel_per_scale: self.per_scale[0].iter().map(|v| med(v)).collect(),
            vp2_median_rel_per_scale: self.per_scale[1].iter().map(|v| med(v)).collect(),
            vp1_scale_counts: self.chosen[0].clone(),
            vp2_scale_counts: self.chosen[1].clone(),
        }
    }
}

/// Median relative VP errors of a validation pass (box frame).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct VpMetrics {
    /// Crops evaluated.
    pub crops: usize,
    /// VP1 after `D^s` scale selection.
    #[serde(with = "inf_as_null")]
    pub vp1_median_rel: f64,
    /// VP2 after `D^s` scale selection.
    #[serde(with = "inf_as_null")]
    pub vp2_median_rel: f64,
    /// VP1 decoded at each scale (empty for regression models).
    #[serde(with = "inf_as_null_vec")]
    pub vp1_median_rel_per_scale: Vec<f64>,
    /// VP2 decoded at each scale.
    #[serde(with = "inf_as_null_vec")]
    pub vp2_median_rel_per_scale: Vec<f64>,
    /// How often each scale was selected for VP1.
    pub vp1_scale_counts: Vec<usize>,
    /// How often each scale was selected for VP2.
    pub vp2_scale_counts: Vec<usize>,
}

/// JSON has no infinity: a non-finite error is written as `null` and read back as `+inf`.
mod inf_as_null {
    use serde::{Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(v: &f64, s: S) -> Result<S::Ok, S::Error> {
        if v.is_finite() {
            s.serialize_f64(*v)
        } else {
            s.serialize_none()
        }
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
        Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::INFINITY))
    }
}

/// [`inf_as_null`] for vectors.
mod inf_as_null_vec {
    use serde::{Deserialize, Deserializer, Serialize, Serializer};

    pub fn serialize<S: Serializer>(v: &[f64], s: S) -> Result<S::Ok, S::Error> {
        let o: Vec<Option<f64>> = v.iter().map(|x| x.is_finite().then_some(*x)).collect();
        o.serialize(s)
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<f64>, D::Error> {
        let o = Vec::<Option<f64>>::deserialize(d)?;
        Ok(o.into_iter().map(|x| x.unwrap_or(f64::INFINITY)).collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn median_handles_even_odd_and_inf() {
        assert_eq!(median(&[3.0, 1.0, 2.0]), Some(2.0));
        assert_eq!(median(&[4.0, 1.0, 2.0, 3.0]), Some(2.5));
        assert_eq!(
            median(&[1.0, f64::INFINITY, f64::INFINITY]),
            Some(f64::INFINITY)
        );
        assert_eq!(median(&[]), None);
    }

    #[test]
    fn infinite_errors_survive_json() {
        let m = VpMetrics {
            crops: 1,
            vp1_median_rel: f64::INFINITY,
            vp2_median_rel: 0.5,
            vp1_median_rel_per_scale: vec![f64::INFINITY, 0.25],
            vp2_median_rel_per_scale: vec![],
            vp1_scale_counts: vec![0, 1],
            vp2_scale_counts: vec![],
        };
        let text = serde_json::to_string(&m).unwrap();
        assert!(text.contains("\"vp1_median_rel\":null"), "{text}");
        let back: VpMetrics = serde_json::from_str(&text).unwrap();
        assert_eq!(back, m);
    }

    #[test]
    fn relative_error_of_non_finite_is_inf() {
        let t = Point2::new(3.0, 4.0);
        assert_eq!(relative_error(Point2::new(3.0, 9.0), t), 1.0);
        assert!(relative_error(Point2::new(f64::INFINITY, 0.0), t).is_infinite());
    }

    #[test]
    fn accumulator_uses_the_codec_decode() {
        let codec = vpcal_geom::heatmap::HeatmapCodec::default();
        let (v1, v2) = (Point2::new(0.3, 0.2), Point2::new(-40.0, 3.0));
        let heat = codec.render_targets(v1, v2);
        let pred = codec.decode(&heat, vpcal_geom::heatmap::DecodeMode::Centre);
        let mut acc = VpErrorAccumulator::default();
        acc.add(&pred, v1, v2);
        let m = acc.summary();
        assert_eq!(m.crops, 1);
        assert_eq!(m.vp1_median_rel_per_scale.len(), 4);
        // At its best scale the codec alone is accurate to a few per cent (near VP1 at 1.0,
        // far VP2 at 0.03). The selected scale need not be that one: an ideal target has a
        // single pixel above 0.8 of its peak, so every spread is 0 and the first scale wins.
        let best = |v: &[f64]| v.iter().copied().fold(f64::INFINITY, f64::min);
        assert!(best(&m.vp1_median_rel_per_scale) < 0.1, "{m:?}");
        assert!(best(&m.vp2_median_rel_per_scale) < 0.1, "{m:?}");
        assert!(
            m.vp1_median_rel.is_finite() && m.vp2_median_rel.is_finite(),
            "{m:?}"
        );
        assert_eq!(m.vp1_scale_counts.iter().sum::<usize>(), 1);
    }
}
