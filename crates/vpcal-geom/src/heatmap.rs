//! The heatmap codec: vanishing points in the box frame <-> multi-scale diamond-space heatmaps
//! (paper §4-5, DESIGN.md §4).
//!
//! For scale `s` a box-frame VP `v` is first multiplied by `s` (small `s` resolves far VPs,
//! large `s` near ones), mapped to the diamond space with `d = 1`, rotated by 45° onto the
//! square, `(a, b) = (u - v, u + v)` (it maps `|u| + |v| <= 1` onto `[-1, 1]²`), and placed in
//! a `R x R` heatmap at `h = ((a, b) + 1) · (R - 1) / 2`. The first array axis is `h[0]`.
//!
//! # Layout
//! A vehicle's heatmaps are `channels = 2 · scales.len()` planes of `R x R` f32, row-major
//! `[channel][h0][h1]`, VP1 at every scale first, then VP2 at every scale.
//!
//! # Targets
//! An unnormalised Gaussian (peak 1, sigma 1 px) truncated to a 9x9 patch centred on the
//! pixel `floor(h)`; patches merge with max.
//!
//! # Decoding
//! Per channel: the maximum `m` at pixel `(i, j)` decodes at its centre `(i + 0.5, j + 0.5)`
//! to `vp^s`. The spread `D^s` is the mean over the pixels `P = {value > 0.8 m}` of
//! `|vp^s - vp(p)| / |vp^s|`; per VP the scale with the smallest `D^s` wins. The reference
//! implementation decoded the pixels of `P` at their corners `(i, j)` instead of their centres;
//! [`DecodeMode::Reference`] reproduces that.

use crate::diamond::{diamond_to_point_2d, point_to_diamond_2d};
use crate::point::Point2;

/// The paper's heatmap resolution.
pub const PAPER_RESOLUTION: usize = 64;
/// The paper's scales.
pub const PAPER_SCALES: [f64; 4] = [0.03, 0.1, 0.3, 1.0];
/// Standard deviation of the target Gaussian, heatmap pixels.
pub const TARGET_SIGMA_PX: f64 = 1.0;
/// Half size of the target patch (9x9).
pub const TARGET_PATCH_RADIUS: i64 = 4;
/// Pixels above this fraction of the maximum count towards the spread `D^s`.
pub const SPREAD_THRESHOLD: f32 = 0.8;

/// How pixels of the near-maximum set `P` are decoded when computing the spread `D^s`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
pub enum DecodeMode {
    /// At pixel centres `(i + 0.5, j + 0.5)`, like the maximum (consistent).
    #[default]
    Centre,
    /// At pixel corners `(i, j)`, as the reference decoder did.
    Reference,
}

/// Encoder/decoder between box-frame VPs and heatmaps.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct HeatmapCodec {
    /// Heatmap side length R, pixels.
    pub resolution: usize,
    /// Scales, in channel order.
    pub scales: Vec<f64>,
}

impl Default for HeatmapCodec {
    /// The paper's codec: R = 64, scales (0.03, 0.1, 0.3, 1.0).
    fn default() -> Self {
        HeatmapCodec {
            resolution: PAPER_RESOLUTION,
            scales: PAPER_SCALES.to_vec(),
        }
    }
}

/// One channel decoded.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ChannelDecode {
    /// The VP at the maximum, box frame (already divided by the scale). May be non-finite
    /// when the maximum sits on the ideal-point line.
    pub vp: Point2,
    /// The spread `D^s`; `+inf` when `vp` is not finite or `P` is empty.
    pub spread: f64,
    /// Heatmap value at the maximum.
    pub peak: f32,
    /// Pixel `(h0, h1)` of the maximum.
    pub argmax: (usize, usize),
}

/// A vehicle's VPs decoded from its heatmaps.
#[derive(Debug, Clone, PartialEq)]
pub struct VpPrediction {
    /// VP1 in the box frame at the selected scale.
    pub vp1: Point2,
    /// VP2 in the box frame at the selected scale.
    pub vp2: Point2,
    /// Index into `scales` selected for VP1 (smallest spread).
    pub vp1_scale: usize,
    /// Index into `scales` selected for VP2.
    pub vp2_scale: usize,
    /// `D^s` per scale, `[vp1, vp2]`.
    pub spreads: Vec<[f64; 2]>,
    /// The decoded VP per scale, `[vp1, vp2]`, box frame.
    pub per_scale: Vec<[Point2; 2]>,
    /// Peak value per scale, `[vp1, vp2]`.
    pub peaks: Vec<[f32; 2]>,
}

impl VpPrediction {
    /// Spread of the selected VP1 scale.
    pub fn vp1_spread(&self) -> f64 {
        self.spreads
            .get(self.vp1_scale)
            .map_or(f64::INFINITY, |s| s[0])
    }
    /// Spread of the selected VP2 scale.
    pub fn vp2_spread(&self) -> f64 {
        self.spreads
            .get(self.vp2_scale)
            .map_or(f64::INFINITY, |s| s[1])
    }
}

impl HeatmapCodec {
    /// A codec with the given resolution and scales.
    pub fn new(resolution: usize, scales: Vec<f64>) -> HeatmapCodec {
        HeatmapCodec { resolution, scales }
    }

    /// Check that the codec is usable: resolution >= 2 and at least one positive finite scale.
    ///
    /// # Errors
    /// A message naming the offending value.
    pub fn validate(&self) -> Result<(), String> {
        if self.resolution < 2 {
            return Err(format!("heatmap resolution {} is below 2", self.resolution));
        }
        if self.scales.is_empty() {
            return Err("the heatmap codec has no scale".into());
        }
        if let Some(s) = self.scales.iter().find(|s| !(s.is_finite() && **s > 0.0)) {
            return Err(format!("heatmap scale {s} is not a positive finite number"));
        }
        Ok(())
    }

    /// Number of heatmap channels: VP1 and VP2 at every scale.
    pub fn channels(&self) -> usize {
        2 * self.scales.len()
    }

    /// Number of f32 values of one vehicle's heatmaps.
    pub fn len(&self) -> usize {
        self.channels() * self.resolution * self.resolution
    }

    /// True when the codec has no scale.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    fn half_extent(&self) -> f64 {
        (self.resolution as f64 - 1.0) / 2.0
    }

    /// Continuous heatmap coordinates `(h0, h1)` of a box-frame VP at `scale`.
    /// `None` when the VP is not finite.
    pub fn vp_to_heatmap(&self, vp_in_box: Point2, scale: f64) -> Option<Point2> {
        let uv = point_to_diamond_2d(vp_in_box * scale, 1.0)?;
        let (a, b) = (uv.x - uv.y, uv.x + uv.y);
        let k = self.half_extent();
        Some(Point2::new((a + 1.0) * k, (b + 1.0) * k))
    }

    /// The box-frame VP at continuous heatmap coordinates `h` for `scale` (inverse of
    /// [`HeatmapCodec::vp_to_heatmap`]); non-finite on the ideal-point line.
    pub fn heatmap_to_vp(&self, h: Point2, scale: f64) -> Point2 {
        let k = self.half_extent();
        let (a, b) = (h.x / k - 1.0, h.y / k - 1.0);
        let uv = Point2::new((a + b) / 2.0, (b - a) / 2.0);
        match diamond_to_point_2d(uv, 1.0) {
            Some(p) => p / scale,
            None => Point2::new(f64::INFINITY, f64::INFINITY),
        }
    }

    /// Render the target heatmaps of a vehicle (see the module docs for the layout).
    pub fn render_targets(&self, vp1_in_box: Point2, vp2_in_box: Point2) -> Vec<f32> {
        let mut out = vec![0.0; self.len()];
        self.render_targets_into(vp1_in_box, vp2_in_box, &mut out);
        out
    }

    /// Like [`HeatmapCodec::render_targets`], into `out` (length [`HeatmapCodec::len`]),
    /// which is overwritten. A non-finite VP leaves its channels at zero.
    ///
    /// # Panics
    /// When `out.len() != self.len()` (a caller bug).
    pub fn render_targets_into(&self, vp1_in_box: Point2, vp2_in_box: Point2, out: &mut [f32]) {
        assert_eq!(out.len(), self.len(), "heatmap buffer has the wrong length");
        out.fill(0.0);
        let plane = self.resolution * self.resolution;
        for (vp_index, vp) in [vp1_in_box, vp2_in_box].into_iter().enumerate() {
            for (si, &scale) in self.scales.iter().enumerate() {
                let channel = vp_index * self.scales.len() + si;
                if let Some(h) = self.vp_to_heatmap(vp, scale) {
                    let dst = &mut out[channel * plane..(channel + 1) * plane];
                    self.splat(dst, h.x.floor() as i64, h.y.floor() as i64);
                }
            }
        }
    }

    /// Max-merge a Gaussian centred on pixel `(c0, c1)` into one channel.
    fn splat(&self, dst: &mut [f32], c0: i64, c1: i64) {
        let r = self.resolution as i64;
        let two_sigma2 = 2.0 * TARGET_SIGMA_PX * TARGET_SIGMA_PX;
        for d0 in -TARGET_PATCH_RADIUS..=TARGET_PATCH_RADIUS {
            let i = c0 + d0;
            if !(0..r).contains(&i) {
                continue;
            }
            for d1 in -TARGET_PATCH_RADIUS..=TARGET_PATCH_RADIUS {
                let j = c1 + d1;
                if !(0..r).contains(&j) {
                    continue;
                }
                let g = (-((d0 * d0 + d1 * d1) as f64) / two_sigma2).exp() as f32;
                let cell = &mut dst[(i * r + j) as usize];
                *cell = cell.max(g);
            }
        }
    }

    /// Decode one channel (`R x R`, row-major) at `scale`.
    ///
    /// # Panics
    /// When `heat.len() != R²` (a caller bug).
    pub fn decode_channel(&self, heat: &[f32], scale: f64, mode: DecodeMode) -> ChannelDecode {
        let r = self.resolution;
        assert_eq!(heat.len(), r * r, "heatmap channel has the wrong length");
        // First maximum in row-major order (numpy's argmax); NaN values never win.
        let mut best = 0usize;
        let mut peak = f32::NEG_INFINITY;
        for (k, &v) in heat.iter().enumerate() {
            if v > peak {
                peak = v;
                best = k;
            }
        }
        let argmax = (best / r, best % r);
        let centre = |i: usize, j: usize| Point2::new(i as f64 + 0.5, j as f64 + 0.5);
        let vp = self.heatmap_to_vp(centre(argmax.0, argmax.1), scale);
        let spread = if vp.is_finite() && vp.norm() > 0.0 {
            let threshold = SPREAD_THRESHOLD * peak;
            let offset = match mode {
                DecodeMode::Centre => 0.5,
                DecodeMode::Reference => 0.0,
            };
            let mut sum = 0.0;
            let mut count = 0usize;
            for (k, &v) in heat.iter().enumerate() {
                if v > threshold {
                    let h = Point2::new((k / r) as f64 + offset, (k % r) as f64 + offset);
                    sum += (vp - self.heatmap_to_vp(h, scale)).norm();
                    count += 1;
                }
            }
            let d = sum / count as f64 / vp.norm();
            if count > 0 && d.is_finite() {
                d
            } else {
                f64::INFINITY
            }
        } else {
            f64::INFINITY
        };
        ChannelDecode {
            vp,
            spread,
            peak: if peak.is_finite() { peak } else { 0.0 },
            argmax,
        }
    }

    /// Decode a vehicle's heatmaps (layout in the module docs) and select, per VP, the scale
    /// with the smallest spread (the first one on ties).
    ///
    /// A codec without scales decodes to non-finite VPs.
    ///
    /// # Panics
    /// When `heat.len() != self.len()` (a caller bug).
    pub fn decode(&self, heat: &[f32], mode: DecodeMode) -> VpPrediction {
        assert_eq!(heat.len(), self.len(), "heatmaps have the wrong length");
        let plane = self.resolution * self.resolution;
        let n = self.scales.len();
        if n == 0 {
            let inf = Point2::new(f64::INFINITY, f64::INFINITY);
            return VpPrediction {
                vp1: inf,
                vp2: inf,
                vp1_scale: 0,
                vp2_scale: 0,
                spreads: vec![],
                per_scale: vec![],
                peaks: vec![],
            };
        }
        let mut spreads = Vec::with_capacity(n);
        let mut per_scale = Vec::with_capacity(n);
        let mut peaks = Vec::with_capacity(n);
        for (si, &scale) in self.scales.iter().enumerate() {
            let c1 = self.decode_channel(&heat[si * plane..(si + 1) * plane], scale, mode);
            let c2 =
                self.decode_channel(&heat[(n + si) * plane..(n + si + 1) * plane], scale, mode);
            spreads.push([c1.spread, c2.spread]);
            per_scale.push([c1.vp, c2.vp]);
            peaks.push([c1.peak, c2.peak]);
        }
        let select = |which: usize| {
            let mut best = 0;
            for si in 1..n {
                if spreads[si][which] < spreads[best][which] {
                    best = si;
                }
            }
            best
        };
        let (vp1_scale, vp2_scale) = (select(0), select(1));
        VpPrediction {
            vp1: per_scale[vp1_scale][0],
            vp2: per_scale[vp2_scale][1],
            vp1_scale,
            vp2_scale,
            spreads,
            per_scale,
            peaks,
        }
    }
}
