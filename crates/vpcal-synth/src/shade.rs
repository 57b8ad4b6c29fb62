//! Lighting and shading: sun + sky + ground bounce, flat per-triangle shading with a simple
//! reflection model per surface, aerial haze, and the sRGB <-> linear conversions.

use std::sync::OnceLock;

use rand::Rng;

use crate::math::{fbm, RngExt, V3};
use crate::mesh::{Material, Surface};

pub type Rgb = [f32; 3];

/// sRGB 8-bit to linear.
pub fn srgb_to_linear(v: u8) -> f32 {
    static LUT: OnceLock<[f32; 256]> = OnceLock::new();
    let lut = LUT.get_or_init(|| {
        let mut t = [0.0f32; 256];
        for (i, x) in t.iter_mut().enumerate() {
            let c = i as f32 / 255.0;
            *x = if c <= 0.04045 {
                c / 12.92
            } else {
                ((c + 0.055) / 1.055).powf(2.4)
            };
        }
        t
    });
    lut[v as usize]
}

/// Entries of the linear -> sRGB table (index = value * (N - 1)).
pub const SRGB_LUT_N: usize = 4096;

/// The linear -> sRGB 8-bit table over [0, 1].
pub fn srgb_lut() -> &'static [u8] {
    static LUT: OnceLock<Vec<u8>> = OnceLock::new();
    LUT.get_or_init(|| {
        (0..SRGB_LUT_N)
            .map(|i| {
                let c = i as f32 / (SRGB_LUT_N - 1) as f32;
                let s = if c <= 0.003_130_8 {
                    c * 12.92
                } else {
                    1.055 * c.powf(1.0 / 2.4) - 0.055
                };
                (s * 255.0 + 0.5).clamp(0.0, 255.0) as u8
            })
            .collect()
    })
}

/// Linear [0, 1] to sRGB 8-bit (clamped).
pub fn linear_to_srgb(v: f32) -> u8 {
    let i = (v.clamp(0.0, 1.0) * (SRGB_LUT_N - 1) as f32 + 0.5) as usize;
    srgb_lut()[i.min(SRGB_LUT_N - 1)]
}

/// An sRGB colour given as 8-bit values, in linear RGB.
pub fn srgb(r: u8, g: u8, b: u8) -> Rgb {
    [srgb_to_linear(r), srgb_to_linear(g), srgb_to_linear(b)]
}

pub fn mul(a: Rgb, b: Rgb) -> Rgb {
    [a[0] * b[0], a[1] * b[1], a[2] * b[2]]
}
pub fn add(a: Rgb, b: Rgb) -> Rgb {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}
pub fn scale(a: Rgb, s: f32) -> Rgb {
    [a[0] * s, a[1] * s, a[2] * s]
}
pub fn mix(a: Rgb, b: Rgb, t: f32) -> Rgb {
    [
        a[0] + (b[0] - a[0]) * t,
        a[1] + (b[1] - a[1]) * t,
        a[2] + (b[2] - a[2]) * t,
    ]
}

/// The light of one scene: sun, sky, haze and the camera's exposure and white balance.
#[derive(Debug, Clone)]
pub struct Lighting {
    /// Unit vector towards the sun (z > 0).
    pub sun_dir: V3,
    /// Sun irradiance on a surface facing it.
    pub sun: Rgb,
    /// Sky irradiance on an upward surface.
    pub sky: Rgb,
    /// Light bounced from the ground onto a downward surface.
    pub bounce: Rgb,
    /// Sky radiance at the zenith and at the horizon (what reflections and the background see).
    pub sky_zenith: Rgb,
    pub sky_horizon: Rgb,
    /// Cloud cover 0..1 (texture on the sky).
    pub clouds: f32,
    /// Aerial haze colour and the distance (m) over which contrast drops to 1/e.
    pub haze: Rgb,
    pub visibility_m: f32,
    /// Fraction of light removed inside cast shadows (0 overcast .. 0.75 clear sun).
    pub shadow_strength: f32,
    /// Exposure multiplier and white-balance gains applied before sRGB encoding.
    pub exposure: f32,
    pub white_balance: Rgb,
    pub seed: u32,
}

impl Lighting {
    /// A random daylight condition: clear sun, hazy sun, overcast, or dusk.
    pub fn random<R: Rng>(rng: &mut R) -> Lighting {
        let kind = rng.weighted(&[0.45, 0.2, 0.3, 0.05]);
        let az = rng.uni(0.0, std::f64::consts::TAU);
        let (elev, sun_k, sky_k, shadow, vis, zen, hor) = match kind {
            0 => (
                rng.uni(0.35, 1.2),
                rng.uni(2.6, 3.4),
                rng.uni(0.55, 0.8),
                rng.uni(0.6, 0.75),
                rng.uni(1500.0, 5000.0),
                srgb(95, 140, 205),
                srgb(190, 210, 230),
            ),
            1 => (
                rng.uni(0.25, 1.0),
                rng.uni(1.4, 2.2),
                rng.uni(0.8, 1.0),
                rng.uni(0.35, 0.55),
                rng.uni(600.0, 1500.0),
                srgb(150, 170, 200),
                srgb(205, 210, 215),
            ),
            2 => (
                rng.uni(0.4, 1.2),
                rng.uni(0.0, 0.35),
                rng.uni(1.2, 1.6),
                rng.uni(0.0, 0.12),
                rng.uni(400.0, 1500.0),
                srgb(175, 180, 188),
                srgb(205, 207, 210),
            ),
            _ => (
                rng.uni(0.05, 0.2),
                rng.uni(1.0, 1.8),
                rng.uni(0.4, 0.6),
                rng.uni(0.4, 0.6),
                rng.uni(800.0, 3000.0),
                srgb(80, 100, 150),
                srgb(225, 170, 120),
            ),
        };
        let warm = if kind == 3 {
            [1.0, 0.75, 0.5]
        } else {
            [1.0, 0.97, 0.9]
        };
        let sun_dir = V3::new(elev.cos() * az.cos(), elev.cos() * az.sin(), elev.sin());
        let sky = scale(
            mix(zen, hor, 0.5),
            sky_k as f32 / mix(zen, hor, 0.5)[1].max(1e-3),
        );
        let wb_t = rng.normal() as f32 * 0.04;
        let mut l = Lighting {
            sun_dir,
            sun: scale(warm, sun_k as f32),
            sky,
            bounce: scale(sky, 0.25),
            sky_zenith: zen,
            sky_horizon: hor,
            clouds: if kind == 2 {
                rng.uni(0.6, 1.0) as f32
            } else {
                rng.uni(0.0, 0.6) as f32
            },
            haze: hor,
            visibility_m: vis as f32,
            shadow_strength: shadow as f32,
            exposure: 1.0,
            white_balance: [1.0 + wb_t, 1.0, 1.0 - wb_t],
            seed: rng.random(),
        };
        l.shadow_strength = l.physical_shadow_strength();
        l
    }

    /// Fraction of the road's irradiance that the sun provides: what a cast shadow removes.
    pub fn physical_shadow_strength(&self) -> f32 {
        let sun = self.sun[1] * self.sun_dir.z.max(0.0) as f32;
        sun / (sun + self.sky[1]).max(1e-6)
    }

    /// Soft overcast light like the BrnoCompSpeed sessions (for real backgrounds).
    pub fn overcast<R: Rng>(rng: &mut R) -> Lighting {
        let mut l = Lighting::random(rng);
        l.sun = scale([1.0, 0.97, 0.92], rng.uni(0.2, 0.7) as f32);
        l.sky = scale([0.95, 0.97, 1.0], rng.uni(1.2, 1.5) as f32);
        l.bounce = scale(l.sky, 0.25);
        l.sky_zenith = srgb(185, 190, 195);
        l.sky_horizon = srgb(210, 212, 214);
        l.shadow_strength = l.physical_shadow_strength();
        l.white_balance = [1.0, 1.0, 1.0];
        l
    }

    /// Irradiance on a Lambertian surface with unit normal `n` (outside shadow).
    pub fn irradiance(&self, n: V3) -> Rgb {
        let ndl = n.dot(self.sun_dir).max(0.0) as f32;
        let up = (0.5 + 0.5 * n.z) as f32;
        add(
            add(scale(self.sun, ndl), scale(self.sky, up)),
            scale(self.bounce, 1.0 - up),
        )
    }

    /// Irradiance on the road (upward normal), optionally inside a shadow (`shadow` in 0..1).
    pub fn ground_irradiance(&self, shadow: f32) -> Rgb {
        let ndl = self.sun_dir.z.max(0.0) as f32 * (1.0 - shadow);
        add(scale(self.sun, ndl), self.sky)
    }

    /// Radiance of the sky in direction `d` (unit), with clouds and a sun glow.
    pub fn sky_radiance(&self, d: V3) -> Rgb {
        let e = d.z.max(0.0);
        let t = (e.sqrt()) as f32;
        let mut c = mix(self.sky_horizon, self.sky_zenith, t);
        if self.clouds > 0.0 && d.z > 0.01 {
            let k = 1.0 / (d.z + 0.08);
            let n = fbm(d.x * k * 1.5, d.y * k * 1.5, 1.0, 5, 0.0, self.seed) + 0.5;
            let cover = crate::math::smoothstep(
                1.0 - f64::from(self.clouds),
                1.2 - 0.5 * f64::from(self.clouds),
                f64::from(n),
            ) as f32;
            c = mix(c, scale(self.sky_horizon, 1.05), cover * 0.85);
        }
        let glow = d.dot(self.sun_dir).max(0.0).powi(64) as f32;
        add(c, scale(self.sun, 0.15 * glow))
    }

    /// Radiance of the environment seen in a reflection (sky above, darkish ground below).
    pub fn env_radiance(&self, d: V3) -> Rgb {
        if d.z > 0.0 {
            mix(self.sky_horizon, self.sky_zenith, (d.z.sqrt()) as f32)
        } else {
            scale(self.ground_irradiance(0.0), 0.1)
        }
    }

    /// Blend a radiance with the haze over distance `dist_m`.
    pub fn hazed(&self, c: Rgb, dist_m: f64) -> Rgb {
        let t = (-(dist_m as f32) / self.visibility_m).exp();
        mix(self.haze, c, t)
    }
}

/// Outgoing radiance of a flat triangle with unit normal `n` (any orientation; it is turned
/// towards the viewer) seen from unit direction `v` (surface to eye).
pub fn shade_triangle(l: &Lighting, mat: &Material, n: V3, v: V3) -> Rgb {
    let n = if n.dot(v) < 0.0 { -n } else { n };
    shade_oriented(l, mat, n, v)
}

/// Like [`shade_triangle`] for a normal already on the viewer's side (a smooth vertex normal
/// may point slightly away near silhouettes; it is used as is).
pub fn shade_oriented(l: &Lighting, mat: &Material, n: V3, v: V3) -> Rgb {
    let ndv = n.dot(v).clamp(0.0, 1.0);
    let r = n * (2.0 * ndv) - v;
    let irr = l.irradiance(n);
    let sun_spec = r.dot(l.sun_dir).max(0.0);
    match mat.surface {
        Surface::Paint => {
            let f = 0.04 + 0.96 * (1.0 - ndv).powi(5);
            let refl = scale(l.env_radiance(r), (f * 0.9) as f32);
            // Flat faces would show a glint over their whole area: keep it a mild sheen.
            let hi = scale(l.sun, (sun_spec.powi(24) * 0.2) as f32);
            add(add(mul(mat.albedo, irr), refl), hi)
        }
        Surface::Glass => {
            let f = 0.05 + 0.45 * (1.0 - ndv).powi(4);
            let refl = scale(l.env_radiance(r), f as f32);
            let inside = scale(mul(mat.albedo, irr), 0.5);
            let hi = scale(l.sun, (sun_spec.powi(48) * 0.4) as f32);
            add(add(inside, refl), hi)
        }
        Surface::Rubber => mul(mat.albedo, irr),
        Surface::Plastic => {
            let f = 0.03 + 0.3 * (1.0 - ndv).powi(5);
            add(
                mul(mat.albedo, irr),
                scale(l.env_radiance(r), (f * 0.5) as f32),
            )
        }
        Surface::Metal => add(
            scale(mul(mat.albedo, l.env_radiance(r)), 0.8),
            scale(mul(mat.albedo, irr), 0.3),
        ),
        Surface::Lamp => {
            let f = 0.1 + 0.5 * (1.0 - ndv).powi(3);
            let hi = scale(l.sun, (sun_spec.powi(60) * 1.0) as f32);
            add(
                add(mul(mat.albedo, irr), scale(l.env_radiance(r), f as f32)),
                hi,
            )
        }
        Surface::Matte => mul(mat.albedo, irr),
    }
}
