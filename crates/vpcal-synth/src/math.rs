//! Small f64 vector helpers and deterministic random numbers used by the renderer.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// A 3-vector (metres for points, unitless for directions).
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize, serde::Deserialize)]
pub struct V3 {
    pub x: f64,
    pub y: f64,
    pub z: f64,
}

impl V3 {
    pub const fn new(x: f64, y: f64, z: f64) -> V3 {
        V3 { x, y, z }
    }
    pub fn dot(self, o: V3) -> f64 {
        self.x * o.x + self.y * o.y + self.z * o.z
    }
    pub fn cross(self, o: V3) -> V3 {
        V3::new(
            self.y * o.z - self.z * o.y,
            self.z * o.x - self.x * o.z,
            self.x * o.y - self.y * o.x,
        )
    }
    pub fn norm(self) -> f64 {
        self.dot(self).sqrt()
    }
    /// Unit vector; the zero vector stays zero.
    pub fn normalized(self) -> V3 {
        let n = self.norm();
        if n > 0.0 {
            self * (1.0 / n)
        } else {
            self
        }
    }
    pub fn to_array(self) -> [f64; 3] {
        [self.x, self.y, self.z]
    }
    pub fn lerp(self, o: V3, t: f64) -> V3 {
        self + (o - self) * t
    }
}

impl std::ops::Add for V3 {
    type Output = V3;
    fn add(self, o: V3) -> V3 {
        V3::new(self.x + o.x, self.y + o.y, self.z + o.z)
    }
}
impl std::ops::Sub for V3 {
    type Output = V3;
    fn sub(self, o: V3) -> V3 {
        V3::new(self.x - o.x, self.y - o.y, self.z - o.z)
    }
}
impl std::ops::Mul<f64> for V3 {
    type Output = V3;
    fn mul(self, s: f64) -> V3 {
        V3::new(self.x * s, self.y * s, self.z * s)
    }
}
impl std::ops::Neg for V3 {
    type Output = V3;
    fn neg(self) -> V3 {
        V3::new(-self.x, -self.y, -self.z)
    }
}

/// 3x3 matrix, row-major.
pub type M3 = [[f64; 3]; 3];

pub fn mat_vec(m: &M3, v: V3) -> V3 {
    V3::new(
        m[0][0] * v.x + m[0][1] * v.y + m[0][2] * v.z,
        m[1][0] * v.x + m[1][1] * v.y + m[1][2] * v.z,
        m[2][0] * v.x + m[2][1] * v.y + m[2][2] * v.z,
    )
}

pub fn mat_t_vec(m: &M3, v: V3) -> V3 {
    V3::new(
        m[0][0] * v.x + m[1][0] * v.y + m[2][0] * v.z,
        m[0][1] * v.x + m[1][1] * v.y + m[2][1] * v.z,
        m[0][2] * v.x + m[1][2] * v.y + m[2][2] * v.z,
    )
}

/// A seeded random stream derived from a seed and a path of integers, so that "item i of
/// seed s" is always the same stream regardless of what else was generated.
pub fn rng_for(seed: u64, path: &[u64]) -> ChaCha8Rng {
    let mut h = splitmix(seed ^ 0x5EED_CA11_B0A7_u64);
    for &p in path {
        h = splitmix(h ^ splitmix(p.wrapping_add(0x9E37_79B9_7F4A_7C15)));
    }
    ChaCha8Rng::seed_from_u64(h)
}

/// SplitMix64 finaliser (a good 64-bit mixer).
pub fn splitmix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Convenience sampling on any RNG.
pub trait RngExt: Rng {
    /// Uniform in [a, b).
    fn uni(&mut self, a: f64, b: f64) -> f64 {
        a + (b - a) * self.random::<f64>()
    }
    /// Log-uniform in [a, b) (a, b > 0).
    fn log_uni(&mut self, a: f64, b: f64) -> f64 {
        (self.uni(a.ln(), b.ln())).exp()
    }
    /// Standard normal (Box-Muller).
    fn normal(&mut self) -> f64 {
        let u1 = self.random::<f64>().max(1e-300);
        let u2 = self.random::<f64>();
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }
    /// True with probability p.
    fn chance(&mut self, p: f64) -> bool {
        self.random::<f64>() < p
    }
    /// Index drawn with the given (unnormalised, non-negative) weights.
    fn weighted(&mut self, weights: &[f64]) -> usize {
        let total: f64 = weights.iter().sum();
        let mut r = self.random::<f64>() * total;
        for (i, w) in weights.iter().enumerate() {
            if r < *w {
                return i;
            }
            r -= w;
        }
        weights.len().saturating_sub(1)
    }
    /// Uniform integer in [a, b] (inclusive).
    fn int(&mut self, a: i64, b: i64) -> i64 {
        if b <= a {
            return a;
        }
        a + (self.random::<u64>() % ((b - a + 1) as u64)) as i64
    }
}

impl<R: Rng + ?Sized> RngExt for R {}

/// Smooth Hermite step from 0 at `e0` to 1 at `e1`.
pub fn smoothstep(e0: f64, e1: f64, x: f64) -> f64 {
    let t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// Hash of two integers and a seed to [0, 1) (32-bit integer mixing; fast, not cryptographic).
pub fn hash2(ix: i64, iy: i64, seed: u32) -> f32 {
    let mut h = (ix as u32).wrapping_mul(0x8DA6_B343)
        ^ (iy as u32).wrapping_mul(0xD816_3841)
        ^ seed.wrapping_mul(0xCB1A_B31F);
    h ^= h >> 15;
    h = h.wrapping_mul(0x2C1B_3C6D);
    h ^= h >> 12;
    h = h.wrapping_mul(0x297A_2D39);
    h ^= h >> 15;
    (h >> 8) as f32 / 16_777_216.0
}

/// floor() as an integer without a libm call (the baseline x86-64 target has no SSE4.1 round).
#[inline]
pub fn floor_i(x: f64) -> i64 {
    let i = x as i64;
    if (i as f64) > x {
        i - 1
    } else {
        i
    }
}

/// 2D value noise in [0, 1), smooth, unit feature size.
pub fn value_noise(x: f64, y: f64, seed: u32) -> f32 {
    let ix = floor_i(x);
    let iy = floor_i(y);
    let tx = (x - ix as f64) as f32;
    let ty = (y - iy as f64) as f32;
    let sx = tx * tx * (3.0 - 2.0 * tx);
    let sy = ty * ty * (3.0 - 2.0 * ty);
    let a = hash2(ix, iy, seed);
    let b = hash2(ix + 1, iy, seed);
    let c = hash2(ix, iy + 1, seed);
    let d = hash2(ix + 1, iy + 1, seed);
    let top = a + (b - a) * sx;
    let bot = c + (d - c) * sx;
    top + (bot - top) * sy
}

/// Fractal value noise in about [-0.5, 0.5]: octaves whose feature size is below `min_feature`
/// (the pixel footprint, same units as x, y) are faded out, which anti-aliases the texture.
pub fn fbm(x: f64, y: f64, base_freq: f64, octaves: u32, min_feature: f64, seed: u32) -> f32 {
    let mut f = base_freq;
    let mut amp = 0.5f32;
    let mut sum = 0.0f32;
    for o in 0..octaves {
        let feature = 1.0 / f;
        let fade = smoothstep(min_feature * 0.7, min_feature * 2.0, feature) as f32;
        if fade <= 0.0 {
            break;
        }
        sum += amp * fade * (value_noise(x * f, y * f, seed.wrapping_add(o * 131)) - 0.5);
        f *= 2.03;
        amp *= 0.5;
    }
    sum
}

/// Axis-aligned hull (x0, y0, x1, y1) of points.
pub fn hull(p: &[[f64; 2]]) -> (f64, f64, f64, f64) {
    let mut h = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
    for q in p {
        h = (h.0.min(q[0]), h.1.min(q[1]), h.2.max(q[0]), h.3.max(q[1]));
    }
    h
}
