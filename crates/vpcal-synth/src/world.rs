//! Road layouts (highway, curve, intersection, parking lot), the procedural road texture, lane
//! paths for traffic, parking stalls, and roadside props (poles, rails, walls, gantries,
//! buildings, trees).
//!
//! All positions are world metres on the road plane z = 0 (see `camera` for the frame).

use std::f64::consts::{FRAC_PI_2, PI, TAU};

use rand::Rng;

use crate::math::{fbm, hash2, smoothstep, value_noise, RngExt, V3};
use crate::mesh::{Material, Mesh, Pose, Surface};
use crate::shade::{mix, scale, srgb, Rgb};

/// The four scene layouts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum LayoutKind {
    Highway,
    Curve,
    Intersection,
    Parking,
}

impl LayoutKind {
    pub fn name(self) -> &'static str {
        match self {
            LayoutKind::Highway => "highway",
            LayoutKind::Curve => "curve",
            LayoutKind::Intersection => "intersection",
            LayoutKind::Parking => "parking",
        }
    }
    pub const ALL: [LayoutKind; 4] = [
        LayoutKind::Highway,
        LayoutKind::Curve,
        LayoutKind::Intersection,
        LayoutKind::Parking,
    ];
}

impl std::str::FromStr for LayoutKind {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "highway" => Ok(LayoutKind::Highway),
            "curve" => Ok(LayoutKind::Curve),
            "intersection" => Ok(LayoutKind::Intersection),
            "parking" => Ok(LayoutKind::Parking),
            _ => Err(format!(
                "unknown layout {s:?}: expected highway, curve, intersection or parking"
            )),
        }
    }
}

/// A path on the road plane, parametrised by arc length.
#[derive(Debug, Clone)]
pub enum Path {
    Line {
        start: [f64; 2],
        heading: f64,
        length: f64,
    },
    /// Circular arc around `centre` of `radius`, starting at `start_angle` (polar angle of the
    /// start point) and sweeping `sweep` radians (positive = counter-clockwise).
    Arc {
        centre: [f64; 2],
        radius: f64,
        start_angle: f64,
        sweep: f64,
    },
    Chain(Vec<Path>),
}

impl Path {
    pub fn length(&self) -> f64 {
        match self {
            Path::Line { length, .. } => *length,
            Path::Arc { radius, sweep, .. } => radius * sweep.abs(),
            Path::Chain(parts) => parts.iter().map(Path::length).sum(),
        }
    }

    /// Position and heading at arc length `s` (clamped to the path).
    pub fn pose_at(&self, s: f64) -> Pose {
        match self {
            Path::Line {
                start,
                heading,
                length,
            } => {
                let s = s.clamp(0.0, *length);
                Pose {
                    x: start[0] + s * heading.cos(),
                    y: start[1] + s * heading.sin(),
                    heading: *heading,
                }
            }
            Path::Arc {
                centre,
                radius,
                start_angle,
                sweep,
            } => {
                let len = radius * sweep.abs();
                let s = s.clamp(0.0, len);
                let sign = sweep.signum();
                let phi = start_angle + sign * s / radius;
                Pose {
                    x: centre[0] + radius * phi.cos(),
                    y: centre[1] + radius * phi.sin(),
                    heading: wrap_angle(phi + sign * FRAC_PI_2),
                }
            }
            Path::Chain(parts) => {
                let mut s = s;
                for (i, p) in parts.iter().enumerate() {
                    let l = p.length();
                    if s <= l || i + 1 == parts.len() {
                        return p.pose_at(s);
                    }
                    s -= l;
                }
                Pose {
                    x: 0.0,
                    y: 0.0,
                    heading: 0.0,
                }
            }
        }
    }
}

/// Angle in (-pi, pi].
pub fn wrap_angle(a: f64) -> f64 {
    let mut a = a.rem_euclid(TAU);
    if a > PI {
        a -= TAU;
    }
    a
}

/// A traffic lane: its path, desired speed and (at intersections) its signal phase and the
/// arc length of its stop line.
#[derive(Debug, Clone)]
pub struct Lane {
    pub path: Path,
    pub speed_mps: f64,
    /// Relative traffic intensity (vehicles per second when free).
    pub rate: f64,
    /// Signal phase (0 or 1) and stop-line arc length, for signalised approaches.
    pub signal: Option<(u32, f64)>,
}

/// How the strip between the two directions looks.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Median {
    /// Painted centre line(s) only.
    Painted,
    Grass,
    /// Concrete strip with a barrier prop.
    Concrete,
}

/// What lies beside the road.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Verge {
    Grass,
    Gravel,
    Sidewalk,
}

/// Cross-section of a road: lane counts per side, widths, marking pattern.
#[derive(Debug, Clone)]
pub struct CrossSection {
    /// Lanes on the left (t > 0, traffic towards -s) and on the right (t < 0, towards +s).
    pub lanes_left: u32,
    pub lanes_right: u32,
    pub lane_w: f64,
    /// Half width of the median strip.
    pub median: f64,
    pub median_kind: Median,
    pub shoulder: f64,
    pub line_w: f64,
    pub dash: f64,
    pub gap: f64,
    pub verge: Verge,
    pub verge_w: f64,
    pub yellow_centre: bool,
}

impl CrossSection {
    /// Its markings as a standard: lane width, dash and gap of the lane lines, metres.
    pub fn markings_json(&self) -> serde_json::Value {
        serde_json::json!({
            "lane_width_m": self.lane_w,
            "dash_m": self.dash,
            "gap_m": self.gap,
            "period_m": self.dash + self.gap,
        })
    }

    pub fn half_left(&self) -> f64 {
        self.median + f64::from(self.lanes_left) * self.lane_w + self.shoulder
    }
    pub fn half_right(&self) -> f64 {
        self.median + f64::from(self.lanes_right) * self.lane_w + self.shoulder
    }
    /// Lateral offset of lane i (0 next to the median) on the given side (+1 left, -1 right).
    pub fn lane_t(&self, side: f64, i: u32) -> f64 {
        side * (self.median + (f64::from(i) + 0.5) * self.lane_w)
    }

    fn random<R: Rng>(rng: &mut R, highway: bool) -> CrossSection {
        let lanes = if highway {
            rng.int(2, 4) as u32
        } else {
            rng.int(1, 2) as u32
        };
        let median_kind = if highway {
            [Median::Grass, Median::Concrete, Median::Painted][rng.weighted(&[0.4, 0.45, 0.15])]
        } else {
            Median::Painted
        };
        let median = match median_kind {
            Median::Painted => rng.uni(0.1, 0.4),
            Median::Grass => rng.uni(2.0, 6.0),
            Median::Concrete => rng.uni(0.8, 1.6),
        };
        CrossSection {
            lanes_left: lanes,
            lanes_right: lanes,
            lane_w: if highway {
                rng.uni(3.5, 3.8)
            } else {
                rng.uni(3.0, 3.6)
            },
            median,
            median_kind,
            shoulder: if highway {
                rng.uni(0.5, 3.2)
            } else {
                rng.uni(0.2, 1.0)
            },
            line_w: if highway {
                rng.uni(0.15, 0.25)
            } else {
                rng.uni(0.1, 0.15)
            },
            dash: if highway {
                rng.uni(3.0, 6.0)
            } else {
                rng.uni(2.0, 4.0)
            },
            gap: if highway {
                rng.uni(6.0, 12.0)
            } else {
                rng.uni(2.0, 6.0)
            },
            verge: [Verge::Grass, Verge::Gravel, Verge::Sidewalk][rng.weighted(if highway {
                &[0.7, 0.25, 0.05]
            } else {
                &[0.25, 0.1, 0.65]
            })],
            verge_w: rng.uni(2.0, 6.0),
            yellow_centre: rng.chance(0.15),
        }
    }
}

/// Centre line of a road.
#[derive(Debug, Clone, Copy)]
pub enum RoadShape {
    Straight {
        origin: [f64; 2],
        heading: f64,
    },
    /// Counter-clockwise circle: +s runs counter-clockwise, +t points to the centre.
    Arc {
        centre: [f64; 2],
        radius: f64,
        ref_angle: f64,
    },
}

/// A road: centre-line shape and cross-section.
#[derive(Debug, Clone)]
pub struct Road {
    pub shape: RoadShape,
    pub xs: CrossSection,
}

impl Road {
    /// Road coordinates (s along, t left) of a ground point.
    pub fn local(&self, x: f64, y: f64) -> (f64, f64) {
        match self.shape {
            RoadShape::Straight { origin, heading } => {
                let (sn, cs) = heading.sin_cos();
                let dx = x - origin[0];
                let dy = y - origin[1];
                (dx * cs + dy * sn, -dx * sn + dy * cs)
            }
            RoadShape::Arc {
                centre,
                radius,
                ref_angle,
            } => {
                let dx = x - centre[0];
                let dy = y - centre[1];
                let r = (dx * dx + dy * dy).sqrt();
                let phi = wrap_angle(dy.atan2(dx) - ref_angle);
                (phi * radius, radius - r)
            }
        }
    }

    /// World pose at road coordinates (s, t), heading along +s.
    pub fn pose(&self, s: f64, t: f64) -> Pose {
        match self.shape {
            RoadShape::Straight { origin, heading } => {
                let (sn, cs) = heading.sin_cos();
                Pose {
                    x: origin[0] + s * cs - t * sn,
                    y: origin[1] + s * sn + t * cs,
                    heading,
                }
            }
            RoadShape::Arc {
                centre,
                radius,
                ref_angle,
            } => {
                let phi = ref_angle + s / radius;
                let r = radius - t;
                Pose {
                    x: centre[0] + r * phi.cos(),
                    y: centre[1] + r * phi.sin(),
                    heading: wrap_angle(phi + FRAC_PI_2),
                }
            }
        }
    }

    /// Lane path on `side` (+1 left: towards -s, -1 right: towards +s), lane i, from road
    /// coordinate s0 to s1 (s0 < s1).
    pub fn lane_path(&self, side: f64, i: u32, s0: f64, s1: f64) -> Path {
        let t = self.xs.lane_t(side, i);
        match self.shape {
            RoadShape::Straight { .. } => {
                let (a, heading_off) = if side < 0.0 { (s0, 0.0) } else { (s1, PI) };
                let p = self.pose(a, t);
                Path::Line {
                    start: [p.x, p.y],
                    heading: wrap_angle(p.heading + heading_off),
                    length: s1 - s0,
                }
            }
            RoadShape::Arc {
                centre,
                radius,
                ref_angle,
            } => {
                let r = radius - t;
                if side < 0.0 {
                    Path::Arc {
                        centre,
                        radius: r,
                        start_angle: ref_angle + s0 / radius,
                        sweep: (s1 - s0) / radius,
                    }
                } else {
                    Path::Arc {
                        centre,
                        radius: r,
                        start_angle: ref_angle + s1 / radius,
                        sweep: -(s1 - s0) / radius,
                    }
                }
            }
        }
    }
}

/// A parking lot: rows of stalls along aisles, in lot coordinates (u along the aisles, w across).
#[derive(Debug, Clone)]
pub struct Lot {
    pub origin: [f64; 2],
    pub heading: f64,
    pub len_u: f64,
    pub bands: u32,
    pub stall_depth: f64,
    pub aisle: f64,
    pub stall_w: f64,
    /// Stall angle per band (radians; pi/2 = perpendicular).
    pub angles: Vec<f64>,
    pub line_w: f64,
}

impl Lot {
    fn module(&self) -> f64 {
        2.0 * self.stall_depth + self.aisle
    }
    pub fn width(&self) -> f64 {
        self.module() * f64::from(self.bands)
    }
    pub fn to_lot(&self, x: f64, y: f64) -> (f64, f64) {
        let (sn, cs) = self.heading.sin_cos();
        let dx = x - self.origin[0];
        let dy = y - self.origin[1];
        (dx * cs + dy * sn, -dx * sn + dy * cs)
    }
    pub fn to_world(&self, u: f64, w: f64) -> [f64; 2] {
        let (sn, cs) = self.heading.sin_cos();
        [
            self.origin[0] + u * cs - w * sn,
            self.origin[1] + u * sn + w * cs,
        ]
    }

    /// Centre and inward axis heading of every stall.
    pub fn stalls(&self) -> Vec<Pose> {
        let mut out = Vec::new();
        let d = self.stall_depth;
        for b in 0..self.bands {
            let th = self.angles[b as usize % self.angles.len()];
            let sw = self.stall_w / th.sin();
            let n = ((self.len_u - d / th.tan().max(0.01)) / sw)
                .floor()
                .max(0.0) as usize;
            let w0 = f64::from(b) * self.module();
            let cot = th.cos() / th.sin();
            for k in 0..n {
                let u = (k as f64 + 0.5) * sw + d / 2.0 * cot;
                // Row A (towards -w), row B (towards +w).
                for (w, ew) in [
                    (w0 + d / 2.0, -th.sin()),
                    (w0 + d + self.aisle + d / 2.0, th.sin()),
                ] {
                    let p = self.to_world(u, w);
                    let heading = wrap_angle(self.heading + ew.atan2(th.cos()));
                    out.push(Pose {
                        x: p[0],
                        y: p[1],
                        heading,
                    });
                }
            }
        }
        out
    }

    /// Aisle centre lines (w values).
    pub fn aisles(&self) -> Vec<f64> {
        (0..self.bands)
            .map(|b| f64::from(b) * self.module() + self.stall_depth + self.aisle / 2.0)
            .collect()
    }

    /// Marking coverage (0..1) at lot coordinates, with pixel footprint `fp`.
    fn marking(&self, u: f64, w: f64, fp: f64) -> f64 {
        let lw = self.line_w;
        if u < -0.5 || u > self.len_u + 0.5 || w < -0.5 || w > self.width() + 0.5 {
            return 0.0;
        }
        let mut cov = 0.0f64;
        let line = |dist: f64| ((lw / 2.0 + fp / 2.0 - dist.abs()) / fp.max(1e-6)).clamp(0.0, 1.0);
        // Lot outline.
        cov = cov
            .max(line(u))
            .max(line(u - self.len_u))
            .max(line(w))
            .max(line(w - self.width()));
        let b = (w / self.module())
            .floor()
            .clamp(0.0, f64::from(self.bands) - 1.0);
        let wl = w - b * self.module();
        let th = self.angles[b as usize % self.angles.len()];
        let sw = self.stall_w / th.sin();
        let cot = th.cos() / th.sin();
        let d = self.stall_depth;
        if u > 0.0 && u < self.len_u {
            if wl <= d {
                let uu = u - (d - wl) * cot;
                let m = uu.rem_euclid(sw);
                let dist = m.min(sw - m) * th.sin();
                if uu > 0.0 {
                    cov = cov.max(line(dist));
                }
                cov = cov.max(line(wl));
            } else if wl >= d + self.aisle {
                let uu = u - (wl - d - self.aisle) * cot;
                let m = uu.rem_euclid(sw);
                let dist = m.min(sw - m) * th.sin();
                if uu > 0.0 {
                    cov = cov.max(line(dist));
                }
            }
        }
        cov
    }
}

/// What the road plane looks like.
#[derive(Debug, Clone)]
pub enum Ground {
    Road(Road),
    /// Two straight roads crossing at the origin of `a` (which is also on `b`'s centre line).
    Cross {
        a: Road,
        b: Road,
    },
    /// A lot beside an access road.
    Parking {
        lot: Lot,
        access: Road,
    },
}

/// Colours and noise seeds of the road texture.
#[derive(Debug, Clone)]
pub struct GroundStyle {
    pub asphalt: Rgb,
    pub asphalt2: Rgb,
    pub marking: Rgb,
    pub yellow: Rgb,
    pub grass: Rgb,
    pub dry: Rgb,
    pub concrete: Rgb,
    pub gravel: Rgb,
    pub wear: f64,
    pub seed: u32,
}

impl GroundStyle {
    pub fn random<R: Rng>(rng: &mut R) -> GroundStyle {
        // Grey levels with a small common tint, so that nothing turns pink or green by chance.
        let grey = |lo: f64, hi: f64, tint: f64, rng: &mut R| {
            let v = rng.uni(lo, hi);
            let t = [
                rng.normal() * tint,
                rng.normal() * tint,
                rng.normal() * tint,
            ];
            let c = |k: usize| (v * (1.0 + t[k])).clamp(0.0, 255.0) as u8;
            srgb(c(0), c(1), c(2))
        };
        let asphalt = grey(55.0, 115.0, 0.03, rng);
        let asphalt2 = grey(50.0, 125.0, 0.03, rng);
        let marking = grey(200.0, 240.0, 0.015, rng);
        let concrete = grey(150.0, 195.0, 0.025, rng);
        let gravel = {
            let v = rng.uni(110.0, 150.0);
            srgb(v as u8, (v * 0.95) as u8, (v * 0.86) as u8)
        };
        let g = rng.uni(0.7, 1.2);
        GroundStyle {
            asphalt,
            asphalt2,
            marking,
            yellow: srgb(220, 175, 40),
            grass: srgb(
                (rng.uni(60.0, 100.0) * g) as u8,
                (rng.uni(95.0, 125.0) * g) as u8,
                (rng.uni(40.0, 65.0) * g) as u8,
            ),
            dry: srgb(
                rng.uni(125.0, 160.0) as u8,
                rng.uni(115.0, 140.0) as u8,
                rng.uni(75.0, 95.0) as u8,
            ),
            concrete,
            gravel,
            wear: rng.uni(0.0, 0.6),
            seed: rng.random(),
        }
    }
}

/// A static object with its world bounds (for culling).
#[derive(Debug, Clone)]
pub struct Prop {
    pub mesh: Mesh,
    pub lo: V3,
    pub hi: V3,
    /// True for thin objects whose shadow is worth drawing.
    pub casts_shadow: bool,
}

impl Prop {
    pub fn new(mesh: Mesh, casts_shadow: bool) -> Option<Prop> {
        let (lo, hi) = mesh.bounds()?;
        Some(Prop {
            mesh,
            lo,
            hi,
            casts_shadow,
        })
    }
}

/// A complete static world: ground, props, lanes and stalls.
#[derive(Debug, Clone)]
pub struct World {
    pub layout: LayoutKind,
    pub ground: Ground,
    pub style: GroundStyle,
    pub props: Vec<Prop>,
    pub lanes: Vec<Lane>,
    pub stalls: Vec<Pose>,
    /// The principal road direction (heading of the scene's VP1).
    pub main_heading: f64,
    /// Signal cycle (s) for intersections.
    pub signal_cycle_s: f64,
}

fn line_cov(dist: f64, half_w: f64, fp: f64) -> f64 {
    ((half_w + fp / 2.0 - dist.abs()) / fp.max(1e-6)).clamp(0.0, 1.0)
}

fn dash_cov(s: f64, dash: f64, gap: f64, fp: f64) -> f64 {
    let period = dash + gap;
    let m = s.rem_euclid(period);
    let centre = dash / 2.0;
    // Distance from the dash centre along s, periodic.
    let d = (m - centre)
        .abs()
        .min((m - centre - period).abs())
        .min((m - centre + period).abs());
    line_cov(d, dash / 2.0, fp)
}

impl World {
    /// Albedo of the road plane at (x, y), for a pixel footprint of `fp` metres.
    pub fn ground_albedo(&self, x: f64, y: f64, fp: f64) -> Rgb {
        let st = &self.style;
        let seed = st.seed;
        match &self.ground {
            Ground::Road(road) => {
                let (s, t) = road.local(x, y);
                self.road_albedo(road, s, t, x, y, fp, None)
            }
            Ground::Cross { a, b } => {
                let (sa, ta) = a.local(x, y);
                let (sb, tb) = b.local(x, y);
                let in_a = ta < a.xs.half_left() && ta > -a.xs.half_right();
                let in_b = tb < b.xs.half_left() && tb > -b.xs.half_right();
                if in_a && in_b {
                    return self.asphalt(x, y, fp, 0.0);
                }
                if in_a {
                    return self.road_albedo(a, sa, ta, x, y, fp, Some((sb, tb, b)));
                }
                if in_b {
                    return self.road_albedo(b, sb, tb, x, y, fp, Some((sa, ta, a)));
                }
                // Corners: sidewalk near both roads, then plots.
                let da = (ta - a.xs.half_left()).max(-ta - a.xs.half_right());
                let db = (tb - b.xs.half_left()).max(-tb - b.xs.half_right());
                let d = da.min(db);
                if d < 0.25 {
                    return scale(st.concrete, 0.9);
                }
                if d < 4.5 {
                    return self.sidewalk(x, y, fp);
                }
                self.terrain(x, y, fp)
            }
            Ground::Parking { lot, access } => {
                let (s, t) = access.local(x, y);
                if t < access.xs.half_left() + 0.3 && t > -access.xs.half_right() - 0.3 {
                    return self.road_albedo(access, s, t, x, y, fp, None);
                }
                let (u, w) = lot.to_lot(x, y);
                let margin = 3.0;
                if u > -margin && u < lot.len_u + margin && w > -margin && w < lot.width() + margin
                {
                    let base = self.asphalt(x, y, fp, 0.0);
                    let cov = lot.marking(u, w, fp)
                        * (1.0
                            - st.wear * 0.5 * f64::from(value_noise(x * 0.7, y * 0.7, seed + 9)));
                    return mix(base, st.marking, cov as f32);
                }
                let d = (-u - margin)
                    .max(u - lot.len_u - margin)
                    .max(-w - margin)
                    .max(w - lot.width() - margin);
                if d < 0.3 {
                    return scale(st.concrete, 0.95);
                }
                if d < 3.0 {
                    return self.sidewalk(x, y, fp);
                }
                self.terrain(x, y, fp)
            }
        }
    }

    fn asphalt(&self, x: f64, y: f64, fp: f64, track: f64) -> Rgb {
        let st = &self.style;
        let seed = st.seed;
        let large = fbm(x, y, 0.03, 2, fp, seed) as f64;
        let medium = fbm(x, y, 0.4, 2, fp, seed + 1) as f64;
        let fine = fbm(x, y, 5.0, 3, fp, seed + 2) as f64;
        let mut c = mix(
            st.asphalt,
            st.asphalt2,
            smoothstep(-0.15, 0.15, large) as f32,
        );
        let k = 1.0 + 0.35 * medium + 0.5 * fine - 0.12 * track;
        // Patches: rectangular repairs on a 9 m grid.
        let (gx, gy) = (crate::math::floor_i(x / 9.0), crate::math::floor_i(y / 9.0));
        let h = hash2(gx, gy, seed + 3);
        if h < 0.12 {
            let fx = (x / 9.0).fract().abs();
            let fy = (y / 9.0).fract().abs();
            if fx > 0.15 && fx < 0.75 && fy > 0.2 && fy < 0.7 {
                c = scale(c, 0.8 + 0.4 * hash2(gx, gy, seed + 4));
            }
        }
        scale(c, k as f32)
    }

    fn sidewalk(&self, x: f64, y: f64, fp: f64) -> Rgb {
        let st = &self.style;
        let tile = 0.6;
        let mx = (x / tile).rem_euclid(1.0);
        let my = (y / tile).rem_euclid(1.0);
        let joint_w = 0.02 / tile;
        let j = (1.0 - line_cov(mx.min(1.0 - mx), joint_w, fp / tile))
            .min(1.0 - line_cov(my.min(1.0 - my), joint_w, fp / tile));
        let n = 1.0
            + 0.25 * f64::from(fbm(x, y, 0.5, 3, fp, st.seed + 11))
            + 0.3 * f64::from(fbm(x, y, 4.0, 2, fp, st.seed + 12));
        scale(st.concrete, (n * (0.75 + 0.25 * j)) as f32)
    }

    fn terrain(&self, x: f64, y: f64, fp: f64) -> Rgb {
        let st = &self.style;
        let fields = f64::from(fbm(x, y, 0.01, 3, fp, st.seed + 20));
        let patchy = f64::from(fbm(x, y, 0.15, 4, fp, st.seed + 21));
        let fine = f64::from(fbm(x, y, 3.0, 3, fp, st.seed + 22));
        let c = mix(
            st.grass,
            st.dry,
            smoothstep(-0.2, 0.25, fields + 0.5 * patchy) as f32,
        );
        scale(c, (1.0 + 0.5 * patchy + 0.45 * fine) as f32)
    }

    #[allow(clippy::too_many_arguments)]
    // Why: road coordinates, world coordinates (for texture) and the crossing road belong together.
    fn road_albedo(
        &self,
        road: &Road,
        s: f64,
        t: f64,
        x: f64,
        y: f64,
        fp: f64,
        cross: Option<(f64, f64, &Road)>,
    ) -> Rgb {
        let xs = &road.xs;
        let st = &self.style;
        let hl = xs.half_left();
        let hr = xs.half_right();
        let at = t.abs();
        let side_half = if t >= 0.0 { hl } else { hr };
        // Outside the paved area.
        if at > side_half {
            let d = at - side_half;
            if d < 0.2 && xs.verge == Verge::Sidewalk {
                return scale(st.concrete, 0.95);
            }
            if d < xs.verge_w {
                return match xs.verge {
                    Verge::Sidewalk => self.sidewalk(x, y, fp),
                    Verge::Gravel => {
                        let n = 1.0 + 0.4 * f64::from(fbm(x, y, 2.0, 3, fp, st.seed + 30));
                        scale(st.gravel, n as f32)
                    }
                    Verge::Grass => self.terrain(x, y, fp),
                };
            }
            return self.terrain(x, y, fp);
        }
        if at < xs.median {
            match xs.median_kind {
                Median::Grass => {
                    if at > xs.median - 0.5 {
                        return self.asphalt(x, y, fp, 0.0);
                    }
                    return self.terrain(x, y, fp);
                }
                Median::Concrete => {
                    return scale(st.concrete, 0.85 + 0.2 * value_noise(x, y, st.seed + 40))
                }
                Median::Painted => {}
            }
        }
        // Tyre tracks: darker bands about 0.9 m either side of each lane centre.
        let lanes = if t >= 0.0 {
            xs.lanes_left
        } else {
            xs.lanes_right
        };
        let lane_pos = (at - xs.median) / xs.lane_w;
        let track = if lane_pos > 0.0 && lane_pos < f64::from(lanes) {
            let off = (lane_pos.fract() - 0.5).abs() * xs.lane_w;
            1.0 - smoothstep(0.15, 0.4, (off - 0.9).abs())
        } else {
            0.0
        };
        let base = self.asphalt(x, y, fp, track);
        let mut cov = 0.0f64;
        let hw = xs.line_w / 2.0;
        let mut colour = st.marking;
        // Centre line(s) when there is no physical median.
        if xs.median_kind == Median::Painted {
            let c = if xs.median < 0.2 {
                line_cov(t, hw, fp)
            } else {
                line_cov(at - xs.median + hw, hw, fp)
            };
            if c > 0.0 {
                if xs.yellow_centre {
                    colour = st.yellow;
                }
                cov = cov.max(c);
            }
        } else {
            cov = cov.max(line_cov(at - xs.median - hw - 0.1, hw, fp));
        }
        // Lane separators (dashed) and the edge line (solid).
        for i in 1..lanes {
            let c = line_cov(at - xs.median - f64::from(i) * xs.lane_w, hw, fp)
                * dash_cov(s, xs.dash, xs.gap, fp);
            cov = cov.max(c);
        }
        let edge = xs.median + f64::from(lanes) * xs.lane_w;
        cov = cov.max(line_cov(at - edge - hw, hw, fp));
        // Junction approaches: zebra crossing and stop line next to the crossing road.
        if let Some((_, tb, b)) = cross {
            let half_b = if tb >= 0.0 {
                b.xs.half_left()
            } else {
                b.xs.half_right()
            };
            let d = tb.abs() - half_b;
            if d < 0.8 {
                cov = 0.0;
            } else if d < 4.8 {
                // Zebra stripes parallel to this road: pattern across t.
                let m = (t / 1.0).rem_euclid(1.0);
                cov = line_cov(m.min(1.0 - m) * 1.0, 0.25, fp) * f64::from(at < edge);
            } else if d < 5.7 {
                // Stop line on the approaching half (right-hand traffic).
                let approaching = (t < 0.0) == (s < 0.0);
                if approaching && at < edge {
                    cov = cov.max(line_cov(d - 5.3, 0.2, fp));
                }
            }
        }
        let wear = 1.0 - st.wear * f64::from(value_noise(x * 0.5, y * 0.5, st.seed + 50));
        mix(base, colour, (cov * wear) as f32)
    }
}

/// Parameters for generating a world.
#[derive(Debug, Clone, Copy)]
pub struct WorldParams {
    pub layout: LayoutKind,
    /// Where the interesting part should be (usually where the camera looks).
    pub focus: [f64; 2],
    /// Heading of the main road.
    pub heading: f64,
    /// How much roadside clutter (0..1).
    pub clutter: f64,
}

/// Generate a random world of the given layout.
pub fn generate_world<R: Rng>(rng: &mut R, p: WorldParams) -> World {
    let style = GroundStyle::random(rng);
    match p.layout {
        LayoutKind::Highway => highway(rng, p, style, false),
        LayoutKind::Curve => highway(rng, p, style, true),
        LayoutKind::Intersection => intersection(rng, p, style),
        LayoutKind::Parking => parking(rng, p, style),
    }
}

fn highway<R: Rng>(rng: &mut R, p: WorldParams, style: GroundStyle, curved: bool) -> World {
    let wide = !curved || rng.chance(0.5);
    let xs = CrossSection::random(rng, wide);
    let span = 420.0;
    let shape = if curved {
        let radius = rng.uni(90.0, 500.0);
        // The centre lies to the left of the road heading at the focus.
        let left = [-p.heading.sin(), p.heading.cos()];
        let centre = [p.focus[0] + left[0] * radius, p.focus[1] + left[1] * radius];
        let ref_angle = (p.focus[1] - centre[1]).atan2(p.focus[0] - centre[0]);
        RoadShape::Arc {
            centre,
            radius,
            ref_angle,
        }
    } else {
        RoadShape::Straight {
            origin: p.focus,
            heading: p.heading,
        }
    };
    let road = Road {
        shape,
        xs: xs.clone(),
    };
    let smax = if let RoadShape::Arc { radius, .. } = shape {
        (span / 2.0f64).min(radius * 2.6)
    } else {
        span / 2.0
    };
    let mut lanes = Vec::new();
    let speed = if curved {
        rng.uni(14.0, 25.0)
    } else {
        rng.uni(22.0, 36.0)
    };
    for side in [-1.0, 1.0] {
        let n = if side < 0.0 {
            xs.lanes_right
        } else {
            xs.lanes_left
        };
        for i in 0..n {
            lanes.push(Lane {
                path: road.lane_path(side, i, -smax, smax),
                // Inner lanes are faster.
                speed_mps: speed * (1.0 + 0.1 * f64::from(n - 1 - i)) * rng.uni(0.9, 1.1),
                rate: rng.uni(0.35, 1.0),
                signal: None,
            });
        }
    }
    let mut props = Vec::new();
    roadside_props(rng, &road, -smax, smax, p.clutter, &mut props);
    World {
        layout: if curved {
            LayoutKind::Curve
        } else {
            LayoutKind::Highway
        },
        ground: Ground::Road(road),
        style,
        props,
        lanes,
        stalls: Vec::new(),
        main_heading: p.heading,
        signal_cycle_s: 0.0,
    }
}

fn intersection<R: Rng>(rng: &mut R, p: WorldParams, style: GroundStyle) -> World {
    let xa = CrossSection::random(rng, false);
    let mut xb = CrossSection::random(rng, false);
    xb.verge = xa.verge;
    let cross_angle = rng.uni(70.0, 110.0).to_radians();
    let a = Road {
        shape: RoadShape::Straight {
            origin: p.focus,
            heading: p.heading,
        },
        xs: xa.clone(),
    };
    let b = Road {
        shape: RoadShape::Straight {
            origin: p.focus,
            heading: wrap_angle(p.heading + cross_angle),
        },
        xs: xb.clone(),
    };
    let reach = 160.0;
    let speed = rng.uni(9.0, 15.0);
    let mut lanes = Vec::new();
    // Through lanes with stop lines, and right turns from the outer lane.
    for (phase, road, other) in [(0u32, &a, &b), (1u32, &b, &a)] {
        let half_other = other.xs.half_left().max(other.xs.half_right());
        let sin_x = cross_angle.sin().abs().max(0.3);
        let stop = reach - (half_other / sin_x + 5.4);
        for side in [-1.0, 1.0] {
            let n = if side < 0.0 {
                road.xs.lanes_right
            } else {
                road.xs.lanes_left
            };
            for i in 0..n {
                lanes.push(Lane {
                    path: road.lane_path(side, i, -reach, reach),
                    speed_mps: speed * rng.uni(0.9, 1.1),
                    rate: rng.uni(0.1, 0.25),
                    signal: Some((phase, stop)),
                });
            }
            // Right turn from the outermost lane into the other road's outer lane.
            let lane_in = road.lane_path(side, n - 1, -reach, reach);
            if let Some(turn) = right_turn(&lane_in, other, reach, rng.uni(6.0, 10.0)) {
                lanes.push(Lane {
                    path: turn,
                    speed_mps: speed * 0.7,
                    rate: rng.uni(0.04, 0.1),
                    signal: Some((phase, stop)),
                });
            }
        }
    }
    let mut props = Vec::new();
    for road in [&a, &b] {
        roadside_props(rng, road, -reach, reach, p.clutter, &mut props);
    }
    // Remove props standing on the other road.
    props.retain(|pr| {
        let c = (pr.lo + pr.hi) * 0.5;
        let on = |r: &Road| {
            let (_, t) = r.local(c.x, c.y);
            t < r.xs.half_left() + 1.0 && t > -r.xs.half_right() - 1.0
        };
        !(on(&a) || on(&b))
    });
    // Buildings in the four corners, kept off both roads.
    let sin_x = cross_angle.sin().abs().max(0.3);
    for qa in [-1.0, 1.0] {
        for qb in [-1.0, 1.0] {
            if !rng.chance(0.75 * p.clutter + 0.2) {
                continue;
            }
            let w = rng.uni(10.0, 25.0);
            let d = rng.uni(10.0, 25.0);
            let half_a = if qa > 0.0 {
                a.xs.half_left()
            } else {
                a.xs.half_right()
            };
            let half_b = b.xs.half_left().max(b.xs.half_right());
            let t = qa * (half_a + rng.uni(6.0, 12.0) + d / 2.0);
            let s = qb
                * ((half_b + rng.uni(6.0, 12.0)) / sin_x + w / 2.0 + (t / cross_angle.tan()).abs());
            let c = a.pose(s, t);
            let mesh = building(rng, [c.x, c.y], p.heading, w, d);
            let clear = |r: &Road| {
                mesh.tris.iter().all(|tr| {
                    tr.p.iter().all(|q| {
                        let (_, tt) = r.local(q.x, q.y);
                        tt > r.xs.half_left() + 4.0 || tt < -r.xs.half_right() - 4.0
                    })
                })
            };
            if clear(&a) && clear(&b) {
                if let Some(pr) = Prop::new(mesh, false) {
                    props.push(pr);
                }
            }
        }
    }
    World {
        layout: LayoutKind::Intersection,
        ground: Ground::Cross { a, b },
        style,
        props,
        lanes,
        stalls: Vec::new(),
        main_heading: p.heading,
        signal_cycle_s: rng.uni(16.0, 30.0),
    }
}

/// A right-turn path: `lane_in` until near the crossing, a circular arc, then the outer lane
/// of `other` (the side whose traffic goes the way we turn).
fn right_turn(lane_in: &Path, other: &Road, reach: f64, radius: f64) -> Option<Path> {
    let (start, h_in) = match lane_in {
        Path::Line { start, heading, .. } => (*start, *heading),
        _ => return None,
    };
    // Right turn: new heading = h_in - 90 deg-ish; pick the side of `other` travelling that way.
    let oh = match other.shape {
        RoadShape::Straight { heading, .. } => heading,
        RoadShape::Arc { .. } => return None,
    };
    let target = wrap_angle(h_in - FRAC_PI_2);
    let (side, h_out) = if wrap_angle(oh - target).abs() < FRAC_PI_2 {
        (-1.0, oh)
    } else {
        (1.0, wrap_angle(oh + PI))
    };
    let n_out = if side < 0.0 {
        other.xs.lanes_right
    } else {
        other.xs.lanes_left
    };
    let t_out = other.xs.lane_t(side, n_out.saturating_sub(1));
    // Out-lane line: points other.pose(s, t_out).
    let p0 = other.pose(0.0, t_out);
    let d1 = [h_in.cos(), h_in.sin()];
    let d2 = [h_out.cos(), h_out.sin()];
    // Intersection X of the two lines: start + a d1 = p0 + b d2.
    let det = d1[0] * (-d2[1]) - d1[1] * (-d2[0]);
    if det.abs() < 1e-6 {
        return None;
    }
    let rx = p0.x - start[0];
    let ry = p0.y - start[1];
    let a = (rx * (-d2[1]) - ry * (-d2[0])) / det;
    let delta = wrap_angle(h_out - h_in);
    if delta > -0.2 {
        return None;
    }
    let tlen = radius * (delta.abs() / 2.0).tan();
    let l1 = a - tlen;
    if l1 < 10.0 {
        return None;
    }
    let arc_start = [start[0] + d1[0] * l1, start[1] + d1[1] * l1];
    // Right turn: centre on the right of d1.
    let centre = [arc_start[0] + d1[1] * radius, arc_start[1] - d1[0] * radius];
    let start_angle = (arc_start[1] - centre[1]).atan2(arc_start[0] - centre[0]);
    let arc = Path::Arc {
        centre,
        radius,
        start_angle,
        sweep: delta,
    };
    let end = arc.pose_at(arc.length());
    Some(Path::Chain(vec![
        Path::Line {
            start,
            heading: h_in,
            length: l1,
        },
        arc,
        Path::Line {
            start: [end.x, end.y],
            heading: h_out,
            length: reach * 0.8,
        },
    ]))
}

fn parking<R: Rng>(rng: &mut R, p: WorldParams, style: GroundStyle) -> World {
    let bands = rng.int(2, 4) as u32;
    let mut angles = Vec::new();
    for _ in 0..bands {
        angles.push(
            [FRAC_PI_2, 60f64.to_radians(), 45f64.to_radians()][rng.weighted(&[0.6, 0.25, 0.15])],
        );
    }
    let lot = Lot {
        origin: [0.0, 0.0],
        heading: p.heading,
        len_u: rng.uni(40.0, 90.0),
        bands,
        stall_depth: rng.uni(4.8, 5.5),
        aisle: rng.uni(6.0, 7.5),
        stall_w: rng.uni(2.4, 2.8),
        angles,
        line_w: rng.uni(0.1, 0.15),
    };
    // Centre the lot on the focus.
    let (sn, cs) = p.heading.sin_cos();
    let cu = lot.len_u / 2.0;
    let cw = lot.width() / 2.0;
    let origin = [
        p.focus[0] - cu * cs + cw * sn,
        p.focus[1] - cu * sn - cw * cs,
    ];
    let lot = Lot { origin, ..lot };
    let mut xs = CrossSection::random(rng, false);
    xs.lanes_left = 1;
    xs.lanes_right = 1;
    xs.verge = Verge::Sidewalk;
    xs.verge_w = 0.0;
    // Access road along the lot's -w edge.
    let road_off = rng.uni(4.0, 7.0) + xs.half_left();
    let ro = lot.to_world(0.0, -road_off);
    let access = Road {
        shape: RoadShape::Straight {
            origin: ro,
            heading: p.heading,
        },
        xs,
    };
    let mut lanes = Vec::new();
    for side in [-1.0, 1.0] {
        lanes.push(Lane {
            path: access.lane_path(side, 0, -120.0, lot.len_u + 120.0),
            speed_mps: rng.uni(8.0, 13.0),
            rate: rng.uni(0.08, 0.2),
            signal: None,
        });
    }
    for w in lot.aisles() {
        let dir_pos = rng.chance(0.5);
        let (u0, h) = if dir_pos {
            (-5.0, p.heading)
        } else {
            (lot.len_u + 5.0, wrap_angle(p.heading + PI))
        };
        let s = lot.to_world(u0, w);
        lanes.push(Lane {
            path: Path::Line {
                start: s,
                heading: h,
                length: lot.len_u + 10.0,
            },
            speed_mps: rng.uni(2.5, 5.0),
            rate: rng.uni(0.01, 0.04),
            signal: None,
        });
    }
    let mut props = Vec::new();
    let pole_mat = Material::matte(srgb(110, 112, 115));
    // Light poles on the lot, trees and buildings around.
    for b in 0..=lot.bands {
        let w = f64::from(b) * lot.module();
        let mut u = rng.uni(5.0, 15.0);
        while u < lot.len_u {
            if rng.chance(0.5) {
                let pp = lot.to_world(u, w);
                let mut m = Mesh::new();
                m.cylinder_z(pp[0], pp[1], 0.12, 0.0, rng.uni(7.0, 10.0), 6, pole_mat);
                m.cylinder_z(
                    pp[0],
                    pp[1],
                    0.35,
                    0.0,
                    0.6,
                    6,
                    Material::matte(style.concrete),
                );
                if let Some(pr) = Prop::new(m, true) {
                    props.push(pr);
                }
            }
            u += rng.uni(20.0, 35.0);
        }
    }
    for _ in 0..((6.0 + 14.0 * p.clutter) as usize) {
        let edge = rng.int(0, 3);
        let (u, w) = match edge {
            0 => (
                rng.uni(-10.0, lot.len_u + 10.0),
                lot.width() + rng.uni(4.0, 12.0),
            ),
            1 => (-rng.uni(5.0, 12.0), rng.uni(0.0, lot.width())),
            2 => (lot.len_u + rng.uni(5.0, 12.0), rng.uni(0.0, lot.width())),
            _ => (
                rng.uni(-10.0, lot.len_u + 10.0),
                -road_off - access.xs.half_left() - rng.uni(4.0, 12.0),
            ),
        };
        let pp = lot.to_world(u, w);
        if let Some(pr) = Prop::new(tree(rng, pp), true) {
            props.push(pr);
        }
    }
    if rng.chance(0.3 + 0.6 * p.clutter) {
        let c = lot.to_world(
            lot.len_u / 2.0 + rng.uni(-20.0, 20.0),
            lot.width() + rng.uni(20.0, 35.0),
        );
        let (bw, bd) = (rng.uni(30.0, 70.0), rng.uni(15.0, 30.0));
        if let Some(pr) = Prop::new(building(rng, c, p.heading, bw, bd), false) {
            props.push(pr);
        }
    }
    let stalls = lot.stalls();
    World {
        layout: LayoutKind::Parking,
        ground: Ground::Parking { lot, access },
        style,
        props,
        lanes,
        stalls,
        main_heading: p.heading,
        signal_cycle_s: 0.0,
    }
}

/// Poles, guard rails, noise walls, gantries, trees and buildings along a road.
fn roadside_props<R: Rng>(
    rng: &mut R,
    road: &Road,
    s0: f64,
    s1: f64,
    clutter: f64,
    out: &mut Vec<Prop>,
) {
    let xs = &road.xs;
    let pole_mat = Material::matte(srgb(120, 122, 126));
    let rail_mat = Material::new(srgb(170, 172, 175), Surface::Metal);
    let concrete = Material::matte(srgb(165, 165, 160));
    // Median barrier.
    if xs.median_kind == Median::Concrete {
        let mut m = Mesh::new();
        strip(
            road, s0, s1, 0.0, 0.3, 0.0, 0.85, 0.2, 8.0, concrete, &mut m,
        );
        if let Some(p) = Prop::new(m, false) {
            out.push(p);
        }
    }
    for side in [-1.0, 1.0] {
        let half = if side > 0.0 {
            xs.half_left()
        } else {
            xs.half_right()
        };
        // Guard rail on posts at the edge of the shoulder.
        if rng.chance(0.55) {
            let t = side * (half + 0.4);
            let mut m = Mesh::new();
            strip(
                road, s0, s1, t, 0.08, 0.55, 0.32, 0.0, 6.0, rail_mat, &mut m,
            );
            let mut s = s0;
            while s < s1 {
                let pp = road.pose(s, t + side * 0.1);
                m.cuboid(
                    V3::new(pp.x - 0.05, pp.y - 0.05, 0.0),
                    V3::new(pp.x + 0.05, pp.y + 0.05, 0.75),
                    pole_mat,
                );
                s += 4.0;
            }
            if let Some(p) = Prop::new(m, true) {
                out.push(p);
            }
        }
        // Noise wall or hedge further out.
        if rng.chance(0.25 * clutter + 0.1) {
            let t = side * (half + xs.verge_w + rng.uni(0.5, 4.0));
            let h = rng.uni(2.5, 4.5);
            let wall = Material::matte(srgb(
                rng.uni(70.0, 140.0) as u8,
                rng.uni(80.0, 140.0) as u8,
                rng.uni(80.0, 130.0) as u8,
            ));
            let mut m = Mesh::new();
            strip(road, s0, s1, t, 0.15, 0.0, h, 0.0, 5.0, wall, &mut m);
            if let Some(p) = Prop::new(m, false) {
                out.push(p);
            }
        }
        // Lamp posts.
        if rng.chance(0.7) {
            let spacing = rng.uni(25.0, 45.0);
            let t = side * (half + rng.uni(0.8, 2.0));
            let h = rng.uni(8.0, 12.0);
            let mut s = s0 + rng.uni(0.0, spacing);
            while s < s1 {
                let pp = road.pose(s, t);
                let mut m = Mesh::new();
                m.cylinder_z(pp.x, pp.y, 0.1, 0.0, h, 6, pole_mat);
                // Arm over the road.
                let arm = rng.uni(1.0, 2.5);
                let inward = road.pose(s, t - side * arm);
                let mid = Pose {
                    x: (pp.x + inward.x) / 2.0,
                    y: (pp.y + inward.y) / 2.0,
                    heading: (inward.y - pp.y).atan2(inward.x - pp.x),
                };
                let mut a = Mesh::new();
                a.cuboid(
                    V3::new(-arm / 2.0, -0.05, h - 0.06),
                    V3::new(arm / 2.0, 0.05, h + 0.04),
                    pole_mat,
                );
                m.extend(&a.placed(&mid));
                m.cuboid(
                    V3::new(inward.x - 0.3, inward.y - 0.3, h - 0.2),
                    V3::new(inward.x + 0.3, inward.y + 0.3, h),
                    Material::matte(srgb(60, 60, 62)),
                );
                if let Some(p) = Prop::new(m, true) {
                    out.push(p);
                }
                s += spacing;
            }
        }
        // Trees and bushes beyond the verge.
        let n_trees = (rng.uni(0.0, 30.0) * clutter) as usize;
        for _ in 0..n_trees {
            let s = rng.uni(s0, s1);
            let t = side * (half + xs.verge_w + rng.uni(2.0, 25.0));
            let pp = road.pose(s, t);
            if let Some(p) = Prop::new(tree(rng, [pp.x, pp.y]), true) {
                out.push(p);
            }
        }
        // Buildings far out.
        let n_b = (rng.uni(0.0, 6.0) * clutter) as usize;
        for _ in 0..n_b {
            let s = rng.uni(s0, s1);
            let t = side * (half + xs.verge_w + rng.uni(25.0, 80.0));
            let pp = road.pose(s, t);
            let (bw, bd) = (rng.uni(12.0, 40.0), rng.uni(10.0, 25.0));
            if let Some(p) = Prop::new(building(rng, [pp.x, pp.y], pp.heading, bw, bd), false) {
                out.push(p);
            }
        }
        // Traffic signs.
        let n_s = (rng.uni(0.0, 4.0) * clutter) as usize;
        for _ in 0..n_s {
            let s = rng.uni(s0, s1);
            let t = side * (half + rng.uni(0.5, 2.0));
            let pp = road.pose(s, t);
            let mut m = Mesh::new();
            let h = rng.uni(2.0, 3.0);
            m.cylinder_z(pp.x, pp.y, 0.04, 0.0, h, 5, pole_mat);
            let col = [
                srgb(30, 70, 160),
                srgb(200, 30, 30),
                srgb(230, 230, 230),
                srgb(30, 120, 60),
            ][rng.int(0, 3) as usize];
            let (sn, cs) = pp.heading.sin_cos();
            let w = rng.uni(0.5, 1.0);
            let hs = rng.uni(0.5, 1.0);
            // A plate facing along the road.
            let a = V3::new(pp.x - sn * w / 2.0, pp.y + cs * w / 2.0, h);
            let b = V3::new(pp.x + sn * w / 2.0, pp.y - cs * w / 2.0, h);
            m.quad(
                a,
                b,
                b + V3::new(0.0, 0.0, hs),
                a + V3::new(0.0, 0.0, hs),
                Material::matte(col),
            );
            if let Some(p) = Prop::new(m, true) {
                out.push(p);
            }
        }
    }
    // Gantry with signs across a straight road.
    if matches!(road.shape, RoadShape::Straight { .. }) && rng.chance(0.3 * clutter + 0.1) {
        let s = rng.uni(s0 * 0.4, s1 * 0.4);
        let tl = xs.half_left() + 1.0;
        let tr = -xs.half_right() - 1.0;
        let h = rng.uni(6.0, 7.5);
        let mut m = Mesh::new();
        for t in [tl, tr] {
            let pp = road.pose(s, t);
            m.cuboid(
                V3::new(pp.x - 0.2, pp.y - 0.2, 0.0),
                V3::new(pp.x + 0.2, pp.y + 0.2, h + 0.6),
                pole_mat,
            );
        }
        {
            // Build the beam as an oriented box along t.
            oriented_box(
                &mut m,
                road,
                s,
                (tl + tr) / 2.0,
                0.3,
                (tl - tr).abs(),
                h,
                h + 0.5,
                pole_mat,
            );
            let sign_col = if rng.chance(0.5) {
                srgb(25, 60, 150)
            } else {
                srgb(20, 110, 60)
            };
            let n_signs = rng.int(1, 3);
            for k in 0..n_signs {
                let tc = tr + (tl - tr) * (k as f64 + 0.5) / n_signs as f64;
                let w = rng
                    .uni(2.5, 4.5)
                    .min((tl - tr).abs() / n_signs as f64 - 0.3);
                oriented_box(
                    &mut m,
                    road,
                    s - 0.25,
                    tc,
                    0.1,
                    w,
                    h - rng.uni(1.5, 2.5),
                    h + 0.4,
                    Material::matte(sign_col),
                );
            }
        }
        if let Some(p) = Prop::new(m, true) {
            out.push(p);
        }
    }
}

/// A box aligned with the road at (s, t): `ds` long along the road, `dt` wide across, z0..z1.
#[allow(clippy::too_many_arguments)]
// Why: position, extents and height of an oriented box.
fn oriented_box(
    m: &mut Mesh,
    road: &Road,
    s: f64,
    t: f64,
    ds: f64,
    dt: f64,
    z0: f64,
    z1: f64,
    mat: Material,
) {
    let c = road.pose(s, t);
    let mut b = Mesh::new();
    b.cuboid(
        V3::new(-ds / 2.0, -dt / 2.0, z0),
        V3::new(ds / 2.0, dt / 2.0, z1),
        mat,
    );
    m.extend(&b.placed(&c));
}

/// A strip along the road at lateral offset t (thickness `th` across), from height z0 to z0 + h,
/// tapered to `top_th` at the top (0 keeps it straight), in segments of `seg` metres.
#[allow(clippy::too_many_arguments)]
// Why: the strip's shape needs all of these.
fn strip(
    road: &Road,
    s0: f64,
    s1: f64,
    t: f64,
    th: f64,
    z0: f64,
    h: f64,
    top_th: f64,
    seg: f64,
    mat: Material,
    m: &mut Mesh,
) {
    if s1 <= s0 {
        return;
    }
    let n = ((s1 - s0) / seg).ceil().max(1.0) as usize;
    let tt = if top_th > 0.0 { top_th } else { th };
    let sec = [
        (-th / 2.0, z0),
        (th / 2.0, z0),
        (tt / 2.0, z0 + h),
        (-tt / 2.0, z0 + h),
    ];
    for k in 0..n {
        let sa = s0 + (s1 - s0) * k as f64 / n as f64;
        let sb = s0 + (s1 - s0) * (k + 1) as f64 / n as f64;
        let pa: Vec<V3> = sec
            .iter()
            .map(|&(dt, z)| {
                let p = road.pose(sa, t + dt);
                V3::new(p.x, p.y, z)
            })
            .collect();
        let pb: Vec<V3> = sec
            .iter()
            .map(|&(dt, z)| {
                let p = road.pose(sb, t + dt);
                V3::new(p.x, p.y, z)
            })
            .collect();
        for i in 1..4 {
            // Skip the bottom face (i = 0 band).
            let j = (i + 1) % 4;
            m.quad(pa[i], pb[i], pb[j], pa[j], mat);
        }
        if k == 0 {
            m.poly(&pa, mat);
        }
        if k + 1 == n {
            m.poly(&pb, mat);
        }
    }
}

/// A tree: trunk and a lumpy crown.
pub fn tree<R: Rng>(rng: &mut R, at: [f64; 2]) -> Mesh {
    let mut m = Mesh::new();
    let h = rng.uni(4.0, 14.0);
    let trunk = Material::matte(srgb(70, 55, 40));
    m.cylinder_z(at[0], at[1], 0.12 + 0.02 * h / 4.0, 0.0, h * 0.5, 5, trunk);
    let g = rng.uni(0.6, 1.1);
    let leaf = Material::matte(srgb(
        (45.0 * g) as u8,
        (75.0 * g + rng.uni(0.0, 25.0)) as u8,
        (35.0 * g) as u8,
    ));
    let conifer = rng.chance(0.3);
    let r = h * rng.uni(0.2, 0.35);
    let mut jit = {
        let mut s: u64 = rng.random();
        move || {
            s = crate::math::splitmix(s);
            (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        }
    };
    if conifer {
        m.blob(
            V3::new(at[0], at[1], h * 0.55),
            r * 0.7,
            r * 0.7,
            h * 0.45,
            leaf,
            &mut jit,
        );
    } else {
        m.blob(
            V3::new(at[0], at[1], h * 0.65),
            r,
            r,
            r * 0.85,
            leaf,
            &mut jit,
        );
        let off = r * 0.5;
        m.blob(
            V3::new(at[0] + off * jit(), at[1] + off * jit(), h * 0.75),
            r * 0.7,
            r * 0.7,
            r * 0.6,
            leaf,
            &mut jit,
        );
    }
    m
}

/// A building: box with a window grid on its facades.
pub fn building<R: Rng>(rng: &mut R, centre: [f64; 2], heading: f64, w: f64, d: f64) -> Mesh {
    let floors = rng.int(1, 8);
    let fh = rng.uni(3.0, 3.6);
    let h = f64::from(floors as u32) * fh + rng.uni(0.3, 1.5);
    let facade = Material::matte(srgb(
        rng.uni(120.0, 220.0) as u8,
        rng.uni(110.0, 210.0) as u8,
        rng.uni(100.0, 200.0) as u8,
    ));
    let window = Material::new(srgb(25, 30, 38), Surface::Glass);
    let mut m = Mesh::new();
    m.cuboid(
        V3::new(-w / 2.0, -d / 2.0, 0.0),
        V3::new(w / 2.0, d / 2.0, h),
        facade,
    );
    let roof = Material::matte(srgb(70, 65, 62));
    m.quad(
        V3::new(-w / 2.0, -d / 2.0, h + 0.01),
        V3::new(w / 2.0, -d / 2.0, h + 0.01),
        V3::new(w / 2.0, d / 2.0, h + 0.01),
        V3::new(-w / 2.0, d / 2.0, h + 0.01),
        roof,
    );
    let ww = rng.uni(1.0, 2.0);
    let spacing = ww + rng.uni(0.8, 2.0);
    for f in 0..floors {
        let z0 = f64::from(f as u32) * fh + 0.9;
        let z1 = z0 + fh * 0.5;
        for (len, fixed, along_x) in [
            (w, d / 2.0, true),
            (w, -d / 2.0, true),
            (d, w / 2.0, false),
            (d, -w / 2.0, false),
        ] {
            let n = ((len - 1.0) / spacing).floor() as i64;
            let off = fixed + fixed.signum() * 0.02;
            for k in 0..n {
                let a = -len / 2.0 + 0.5 + spacing * k as f64 + (spacing - ww) / 2.0;
                let b = a + ww;
                if along_x {
                    m.quad(
                        V3::new(a, off, z0),
                        V3::new(b, off, z0),
                        V3::new(b, off, z1),
                        V3::new(a, off, z1),
                        window,
                    );
                } else {
                    m.quad(
                        V3::new(off, a, z0),
                        V3::new(off, b, z0),
                        V3::new(off, b, z1),
                        V3::new(off, a, z1),
                        window,
                    );
                }
            }
        }
    }
    m.placed(&Pose {
        x: centre[0],
        y: centre[1],
        heading,
    })
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used)]
    use super::*;
    use crate::math::rng_for;

    #[test]
    fn paths_are_continuous_and_tangent() {
        for layout in LayoutKind::ALL {
            for seed in 0..5u64 {
                let mut rng = rng_for(seed, &[7]);
                let w = generate_world(
                    &mut rng,
                    WorldParams {
                        layout,
                        focus: [10.0, -5.0],
                        heading: 0.4,
                        clutter: 0.5,
                    },
                );
                assert!(!w.lanes.is_empty(), "{layout:?}");
                for lane in &w.lanes {
                    let len = lane.path.length();
                    assert!(len > 20.0);
                    let mut prev = lane.path.pose_at(0.0);
                    let ds = 0.05;
                    let mut s = ds;
                    while s < len {
                        let p = lane.path.pose_at(s);
                        let step = ((p.x - prev.x).powi(2) + (p.y - prev.y).powi(2)).sqrt();
                        assert!((step - ds).abs() < 1e-3, "{layout:?} jump {step} at {s}");
                        // Heading is the direction of motion.
                        let mh = (p.y - prev.y).atan2(p.x - prev.x);
                        assert!(
                            wrap_angle(mh - p.heading).abs() < 0.02,
                            "{layout:?} heading at {s}"
                        );
                        prev = p;
                        s += ds;
                    }
                }
            }
        }
    }

    #[test]
    fn parking_stalls_cover_many_headings() {
        let mut headings = Vec::new();
        for seed in 0..6u64 {
            let mut rng = rng_for(seed, &[8]);
            let w = generate_world(
                &mut rng,
                WorldParams {
                    layout: LayoutKind::Parking,
                    focus: [0.0, 0.0],
                    heading: 0.3 * seed as f64,
                    clutter: 0.5,
                },
            );
            assert!(w.stalls.len() > 20);
            headings.extend(w.stalls.iter().map(|s| s.heading));
        }
        // At least 8 distinct 20-degree bins of heading are used.
        let mut bins = std::collections::HashSet::new();
        for h in headings {
            bins.insert(((h + PI) / 20f64.to_radians()) as i64);
        }
        assert!(bins.len() >= 8, "{bins:?}");
    }
}
