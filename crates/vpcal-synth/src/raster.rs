//! Software rasteriser: z-buffered flat-shaded triangles (clipped at a near plane), planar
//! sun shadows and contact shadows on the road, background fill (procedural world or a real
//! photograph), supersampling and tone mapping.
//!
//! A [`Target`] covers a rectangle of the camera image (the whole frame, a band of it, or one
//! crop) with `ss x ss` samples per pixel. Sample (i, j) sits at image point
//! `(x0 + (i + 0.5)/ss, y0 + (j + 0.5)/ss)`.

use crate::camera::Camera;
use crate::math::{smoothstep, V3};
use crate::mesh::{Pose, Tri};
use crate::shade::{shade_oriented, shade_triangle, srgb_to_linear, Lighting, Rgb};
use crate::world::World;

/// Samples closer than this (metres, camera z) are clipped.
pub const NEAR_M: f64 = 0.2;

/// Object id of samples showing the background (road, terrain, sky, photo).
pub const ID_BACKGROUND: u32 = 0;

/// A render target over a rectangle of the image.
#[derive(Debug, Clone)]
pub struct Target {
    /// Image coordinates of the target's top-left corner (pixels).
    pub x0: f64,
    pub y0: f64,
    /// Samples per pixel along each axis.
    pub ss: u32,
    /// Size in samples.
    pub w: usize,
    pub h: usize,
    /// Linear radiance per sample.
    pub color: Vec<Rgb>,
    /// 1 / camera depth of the nearest surface; 0 where only background.
    pub depth: Vec<f32>,
    /// Object id per sample ([`ID_BACKGROUND`] for background).
    pub id: Vec<u32>,
    /// Light factor on background samples (shadows), 1 = unshadowed.
    pub shade: Vec<f32>,
}

/// A background source for samples not covered by any mesh.
#[derive(Debug, Clone, Copy)]
pub enum Backdrop<'a> {
    /// The procedural road plane and sky of a world.
    World(&'a World),
    /// A photograph taken by this very camera (same size), 8-bit sRGB.
    Photo(&'a image::RgbImage),
}

impl Target {
    /// A target of `w x h` pixels whose top-left pixel corner is image point (x0, y0).
    pub fn new(x0: f64, y0: f64, w_px: usize, h_px: usize, ss: u32) -> Target {
        let ss_us = ss.max(1) as usize;
        let (w, h) = (w_px * ss_us, h_px * ss_us);
        Target {
            x0,
            y0,
            ss: ss.max(1),
            w,
            h,
            color: vec![[0.0; 3]; w * h],
            depth: vec![0.0; w * h],
            id: vec![ID_BACKGROUND; w * h],
            shade: vec![1.0; w * h],
        }
    }

    /// Image point of sample (i, j).
    pub fn sample_pos(&self, i: usize, j: usize) -> (f64, f64) {
        let s = f64::from(self.ss);
        (
            self.x0 + (i as f64 + 0.5) / s,
            self.y0 + (j as f64 + 0.5) / s,
        )
    }

    fn to_buffer(&self, cam: &Camera, c: V3) -> (f64, f64, f64) {
        let s = f64::from(self.ss);
        let u = cam.focal_px * c.x / c.z + cam.pp[0];
        let v = cam.focal_px * c.y / c.z + cam.pp[1];
        ((u - self.x0) * s, (v - self.y0) * s, 1.0 / c.z)
    }

    /// Draw triangles (world coordinates) with z-buffering, flat shading and haze.
    /// Returns the number of triangles that reached the rasteriser.
    pub fn draw(&mut self, cam: &Camera, light: &Lighting, tris: &[Tri], id: u32) -> usize {
        let mut drawn = 0;
        for t in tris {
            let c = [
                cam.to_camera(t.p[0]),
                cam.to_camera(t.p[1]),
                cam.to_camera(t.p[2]),
            ];
            if c.iter().all(|p| p.z < NEAR_M) {
                continue;
            }
            let n = (t.p[1] - t.p[0]).cross(t.p[2] - t.p[0]);
            let nn = n.norm();
            if nn < 1e-12 {
                continue;
            }
            let centroid = (t.p[0] + t.p[1] + t.p[2]) * (1.0 / 3.0);
            let to_eye = cam.position - centroid;
            let dist = to_eye.norm();
            let view = to_eye * (1.0 / dist.max(1e-9));
            let face = n * (1.0 / nn);
            let cols: [Rgb; 3] = match t.n {
                None => {
                    let col = light.hazed(shade_triangle(light, &t.mat, face, view), dist);
                    [col; 3]
                }
                Some(vn) => {
                    let face = if face.dot(view) < 0.0 { -face } else { face };
                    std::array::from_fn(|k| {
                        let e = cam.position - t.p[k];
                        let d = e.norm();
                        let nk = if vn[k].dot(face) < 0.0 { -vn[k] } else { vn[k] };
                        light.hazed(
                            shade_oriented(light, &t.mat, nk, e * (1.0 / d.max(1e-9))),
                            d,
                        )
                    })
                }
            };
            let flat = t.n.is_none();
            let poly = clip_near_attr(&c, &cols);
            if poly.len() < 3 {
                continue;
            }
            let pts: Vec<(f64, f64, f64)> =
                poly.iter().map(|&(p, _)| self.to_buffer(cam, p)).collect();
            if !self.overlaps(&pts) {
                continue;
            }
            drawn += 1;
            for k in 1..pts.len() - 1 {
                let (c0, c1, c2) = (poly[0].1, poly[k].1, poly[k + 1].1);
                self.raster_tri(pts[0], pts[k], pts[k + 1], |tg, idx, d, w| {
                    if d > tg.depth[idx] {
                        tg.depth[idx] = d;
                        tg.color[idx] = if flat {
                            c0
                        } else {
                            [
                                w[0] * c0[0] + w[1] * c1[0] + w[2] * c2[0],
                                w[0] * c0[1] + w[1] * c1[1] + w[2] * c2[1],
                                w[0] * c0[2] + w[1] * c1[2] + w[2] * c2[2],
                            ]
                        };
                        tg.id[idx] = id;
                    }
                });
            }
        }
        drawn
    }

    fn overlaps(&self, pts: &[(f64, f64, f64)]) -> bool {
        let (mut x0, mut y0, mut x1, mut y1) = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
        for p in pts {
            x0 = x0.min(p.0);
            x1 = x1.max(p.0);
            y0 = y0.min(p.1);
            y1 = y1.max(p.1);
        }
        x1 >= 0.0 && y1 >= 0.0 && x0 <= self.w as f64 && y0 <= self.h as f64
    }

    /// Rasterise one triangle in buffer coordinates (x, y, 1/z); `f` gets the sample index and
    /// the interpolated 1/z of every covered sample centre.
    fn raster_tri<F: FnMut(&mut Target, usize, f32, [f32; 3])>(
        &mut self,
        a: (f64, f64, f64),
        b: (f64, f64, f64),
        c: (f64, f64, f64),
        mut f: F,
    ) {
        let area = (b.0 - a.0) * (c.1 - a.1) - (b.1 - a.1) * (c.0 - a.0);
        if area.abs() < 1e-12 {
            return;
        }
        let minx = a.0.min(b.0).min(c.0);
        let maxx = a.0.max(b.0).max(c.0);
        let miny = a.1.min(b.1).min(c.1);
        let maxy = a.1.max(b.1).max(c.1);
        let i0 = ((minx - 0.5).ceil().max(0.0)) as i64;
        let i1 = ((maxx - 0.5).floor()).min(self.w as f64 - 1.0) as i64;
        let j0 = ((miny - 0.5).ceil().max(0.0)) as i64;
        let j1 = ((maxy - 0.5).floor()).min(self.h as f64 - 1.0) as i64;
        if i1 < i0 || j1 < j0 {
            return;
        }
        let inv = 1.0 / area;
        // Edge functions e(p) = A x + B y + C, normalised so the inside is positive.
        let edge = |p: (f64, f64, f64), q: (f64, f64, f64)| {
            let ea = (p.1 - q.1) * inv;
            let eb = (q.0 - p.0) * inv;
            let ec = (p.0 * q.1 - p.1 * q.0) * inv;
            (ea, eb, ec)
        };
        let e0 = edge(b, c); // weight of a
        let e1 = edge(c, a); // weight of b
        let e2 = edge(a, b); // weight of c
        for j in j0..=j1 {
            let y = j as f64 + 0.5;
            let row = j as usize * self.w;
            let x = i0 as f64 + 0.5;
            let mut w0 = e0.0 * x + e0.1 * y + e0.2;
            let mut w1 = e1.0 * x + e1.1 * y + e1.2;
            let mut w2 = e2.0 * x + e2.1 * y + e2.2;
            for i in i0..=i1 {
                if w0 >= 0.0 && w1 >= 0.0 && w2 >= 0.0 {
                    let d = (w0 * a.2 + w1 * b.2 + w2 * c.2) as f32;
                    f(self, row + i as usize, d, [w0 as f32, w1 as f32, w2 as f32]);
                }
                w0 += e0.0;
                w1 += e1.0;
                w2 += e2.0;
            }
        }
    }

    /// Number of samples the triangles cover when drawn alone (for occlusion ratios).
    pub fn coverage(&self, cam: &Camera, tris: &[Tri]) -> usize {
        let mut scratch = Target {
            x0: self.x0,
            y0: self.y0,
            ss: self.ss,
            w: self.w,
            h: self.h,
            color: Vec::new(),
            depth: Vec::new(),
            id: Vec::new(),
            shade: Vec::new(),
        };
        // Restrict to the projected bounds to keep the mask small.
        let mut bb = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
        let mut polys = Vec::with_capacity(tris.len());
        for t in tris {
            let c = [
                cam.to_camera(t.p[0]),
                cam.to_camera(t.p[1]),
                cam.to_camera(t.p[2]),
            ];
            let poly = clip_near(&c);
            if poly.len() < 3 {
                continue;
            }
            let pts: Vec<(f64, f64, f64)> = poly.iter().map(|&p| self.to_buffer(cam, p)).collect();
            for p in &pts {
                bb.0 = bb.0.min(p.0);
                bb.1 = bb.1.min(p.1);
                bb.2 = bb.2.max(p.0);
                bb.3 = bb.3.max(p.1);
            }
            polys.push(pts);
        }
        if polys.is_empty() {
            return 0;
        }
        let bx0 = bb.0.floor().max(0.0) as usize;
        let by0 = bb.1.floor().max(0.0) as usize;
        let bx1 = (bb.2.ceil().max(0.0) as usize).min(self.w);
        let by1 = (bb.3.ceil().max(0.0) as usize).min(self.h);
        if bx1 <= bx0 || by1 <= by0 {
            return 0;
        }
        scratch.w = bx1 - bx0;
        scratch.h = by1 - by0;
        let mut mask = vec![false; scratch.w * scratch.h];
        let (ox, oy) = (bx0 as f64, by0 as f64);
        for pts in polys {
            for k in 1..pts.len() - 1 {
                let sh = |p: (f64, f64, f64)| (p.0 - ox, p.1 - oy, p.2);
                scratch.raster_tri(sh(pts[0]), sh(pts[k]), sh(pts[k + 1]), |_, idx, _, _| {
                    mask[idx] = true
                });
            }
        }
        mask.iter().filter(|&&m| m).count()
    }

    /// Samples showing object `id`.
    pub fn count_id(&self, id: u32) -> usize {
        self.id.iter().filter(|&&i| i == id).count()
    }

    /// Darken background samples inside the sun shadow of the triangles (projected onto the
    /// road along the sun direction).
    pub fn draw_shadow(&mut self, cam: &Camera, light: &Lighting, tris: &[Tri]) {
        if light.shadow_strength <= 0.01 {
            return;
        }
        let l = light.sun_dir;
        let lz = l.z.max(0.08);
        let k = 1.0 - light.shadow_strength;
        let flat = |p: V3| V3::new(p.x - l.x * p.z / lz, p.y - l.y * p.z / lz, 0.0);
        for t in tris {
            let g = [flat(t.p[0]), flat(t.p[1]), flat(t.p[2])];
            let c = [
                cam.to_camera(g[0]),
                cam.to_camera(g[1]),
                cam.to_camera(g[2]),
            ];
            if c.iter().all(|p| p.z < NEAR_M) {
                continue;
            }
            let poly = clip_near(&c);
            if poly.len() < 3 {
                continue;
            }
            let pts: Vec<(f64, f64, f64)> = poly.iter().map(|&p| self.to_buffer(cam, p)).collect();
            if !self.overlaps(&pts) {
                continue;
            }
            for m in 1..pts.len() - 1 {
                self.raster_tri(pts[0], pts[m], pts[m + 1], |tg, idx, _, _| {
                    if tg.id[idx] == ID_BACKGROUND && tg.shade[idx] > k {
                        tg.shade[idx] = k;
                    }
                });
            }
        }
    }

    /// Soft dark patch under a vehicle footprint (ambient occlusion on the road).
    pub fn draw_contact_shadow(
        &mut self,
        cam: &Camera,
        pose: &Pose,
        length: f64,
        width: f64,
        strength: f32,
    ) {
        let margin = 0.5 + 0.1 * width;
        let (hl, hw) = (length / 2.0 + margin, width / 2.0 + margin);
        let corners = [
            V3::new(hl, hw, 0.0),
            V3::new(hl, -hw, 0.0),
            V3::new(-hl, -hw, 0.0),
            V3::new(-hl, hw, 0.0),
        ];
        let mut bb = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
        for p in corners {
            let c = cam.to_camera(pose.apply(p));
            if c.z < NEAR_M {
                return;
            }
            let (x, y, _) = self.to_buffer(cam, c);
            bb = (bb.0.min(x), bb.1.min(y), bb.2.max(x), bb.3.max(y));
        }
        let i0 = bb.0.floor().max(0.0) as usize;
        let j0 = bb.1.floor().max(0.0) as usize;
        let i1 = (bb.2.ceil().max(0.0) as usize).min(self.w);
        let j1 = (bb.3.ceil().max(0.0) as usize).min(self.h);
        let (l2, w2) = (length / 2.0 - 0.15, width / 2.0 - 0.1);
        for j in j0..j1 {
            for i in i0..i1 {
                let idx = j * self.w + i;
                if self.id[idx] != ID_BACKGROUND {
                    continue;
                }
                let (u, v) = self.sample_pos(i, j);
                let Some(g) = cam.ground_point(u, v) else {
                    continue;
                };
                let q = pose.inverse(g);
                let dx = (q.x.abs() - l2).max(0.0);
                let dy = (q.y.abs() - w2).max(0.0);
                let d = (dx * dx + dy * dy).sqrt();
                let ao = strength * (1.0 - smoothstep(0.0, margin, d) as f32);
                if ao > 0.0 {
                    self.shade[idx] *= 1.0 - ao;
                }
            }
        }
    }

    /// Fill every background sample from the backdrop, applying the shadow factors. The
    /// backdrop is evaluated once per pixel (its texture is filtered to the pixel footprint);
    /// the shadow factors are per sample.
    pub fn fill_background(&mut self, cam: &Camera, light: &Lighting, backdrop: Backdrop<'_>) {
        let ss = self.ss as usize;
        let inv_gain = [
            1.0 / (light.exposure * light.white_balance[0]).max(1e-6),
            1.0 / (light.exposure * light.white_balance[1]).max(1e-6),
            1.0 / (light.exposure * light.white_balance[2]).max(1e-6),
        ];
        let (pw, ph) = (self.w / ss, self.h / ss);
        for py in 0..ph {
            for px in 0..pw {
                let base = py * ss * self.w + px * ss;
                let any = (0..ss)
                    .any(|sj| (0..ss).any(|si| self.id[base + sj * self.w + si] == ID_BACKGROUND));
                if !any {
                    continue;
                }
                let (u, v) = (self.x0 + px as f64 + 0.5, self.y0 + py as f64 + 0.5);
                // Background radiance as lit * shade + unlit (haze).
                let (lit, unlit) = match backdrop {
                    Backdrop::World(world) => world_radiance(cam, light, world, u, v),
                    Backdrop::Photo(img) => {
                        let c = bilinear_linear(img, u, v);
                        (
                            [c[0] * inv_gain[0], c[1] * inv_gain[1], c[2] * inv_gain[2]],
                            [0.0; 3],
                        )
                    }
                };
                for sj in 0..ss {
                    for si in 0..ss {
                        let idx = base + sj * self.w + si;
                        if self.id[idx] != ID_BACKGROUND {
                            continue;
                        }
                        let sh = self.shade[idx];
                        self.color[idx] = [
                            lit[0] * sh + unlit[0],
                            lit[1] * sh + unlit[1],
                            lit[2] * sh + unlit[2],
                        ];
                    }
                }
            }
        }
    }

    /// Multiply background samples by their shadow factor (for a precomputed background).
    pub fn apply_shade(&mut self) {
        for ((c, &s), &id) in self.color.iter_mut().zip(&self.shade).zip(&self.id) {
            if id == ID_BACKGROUND && s < 1.0 {
                c[0] *= s;
                c[1] *= s;
                c[2] *= s;
            }
        }
    }

    /// Average the samples of each pixel and encode to 8-bit sRGB with the light's exposure and
    /// white balance.
    pub fn resolve(&self, light: &Lighting) -> image::RgbImage {
        let ss = self.ss as usize;
        let (w, h) = (self.w / ss, self.h / ss);
        let mut img = image::RgbImage::new(w as u32, h as u32);
        let norm = 1.0 / (ss * ss) as f32;
        let top = (crate::shade::SRGB_LUT_N - 1) as f32;
        let gain = [
            light.exposure * light.white_balance[0] * norm * top,
            light.exposure * light.white_balance[1] * norm * top,
            light.exposure * light.white_balance[2] * norm * top,
        ];
        let lut = crate::shade::srgb_lut();
        let enc = |v: f32, g: f32| lut[((v * g).clamp(0.0, top) + 0.5) as usize];
        let out = img.as_mut();
        if ss == 1 {
            for (px, c) in out.chunks_exact_mut(3).zip(&self.color) {
                px[0] = enc(c[0], gain[0]);
                px[1] = enc(c[1], gain[1]);
                px[2] = enc(c[2], gain[2]);
            }
            return img;
        }
        for (y, row) in out.chunks_exact_mut(w * 3).enumerate() {
            for (x, px) in row.chunks_exact_mut(3).enumerate() {
                let mut acc = [0.0f32; 3];
                for sj in 0..ss {
                    let base = (y * ss + sj) * self.w + x * ss;
                    for c in &self.color[base..base + ss] {
                        acc[0] += c[0].min(4.0);
                        acc[1] += c[1].min(4.0);
                        acc[2] += c[2].min(4.0);
                    }
                }
                px[0] = enc(acc[0], gain[0]);
                px[1] = enc(acc[1], gain[1]);
                px[2] = enc(acc[2], gain[2]);
            }
        }
        img
    }
}

/// Radiance of the procedural world at image point (u, v), split into the part that shadows
/// scale (road light after haze) and the part they do not (haze, sky).
pub fn world_radiance(cam: &Camera, light: &Lighting, world: &World, u: f64, v: f64) -> (Rgb, Rgb) {
    let r = cam.ray(u, v);
    let rn = r.norm();
    let dir = r * (1.0 / rn);
    if dir.z < -1e-6 {
        let t = -cam.position.z / r.z;
        let g = cam.position + r * t;
        let dist = rn * t;
        // Pixel footprint on the road: grows with distance and at grazing angles.
        let fp = dist / cam.focal_px / (-dir.z).max(0.02).sqrt();
        let alb = world.ground_albedo(g.x, g.y, fp);
        let irr = light.ground_irradiance(0.0);
        let tr = (-(dist as f32) / light.visibility_m).exp();
        let lit = [
            alb[0] * irr[0] * tr,
            alb[1] * irr[1] * tr,
            alb[2] * irr[2] * tr,
        ];
        let h = light.haze;
        (
            lit,
            [h[0] * (1.0 - tr), h[1] * (1.0 - tr), h[2] * (1.0 - tr)],
        )
    } else {
        ([0.0; 3], light.sky_radiance(dir))
    }
}

/// Bilinear sample of an sRGB image in linear RGB at image point (u, v) (pixel centres at
/// i + 0.5); clamps at the border.
pub fn bilinear_linear(img: &image::RgbImage, u: f64, v: f64) -> Rgb {
    let (w, h) = (img.width() as i64, img.height() as i64);
    let x = u - 0.5;
    let y = v - 0.5;
    let (ix, iy) = (crate::math::floor_i(x), crate::math::floor_i(y));
    let tx = (x - ix as f64) as f32;
    let ty = (y - iy as f64) as f32;
    let px = |ix: i64, iy: i64| {
        let p = img.get_pixel(ix.clamp(0, w - 1) as u32, iy.clamp(0, h - 1) as u32);
        [
            srgb_to_linear(p[0]),
            srgb_to_linear(p[1]),
            srgb_to_linear(p[2]),
        ]
    };
    let a = px(ix, iy);
    let b = px(ix + 1, iy);
    let c = px(ix, iy + 1);
    let d = px(ix + 1, iy + 1);
    let mut out = [0.0; 3];
    for k in 0..3 {
        let top = a[k] + (b[k] - a[k]) * tx;
        let bot = c[k] + (d[k] - c[k]) * tx;
        out[k] = top + (bot - top) * ty;
    }
    out
}

/// [`clip_near`] carrying a colour per vertex.
fn clip_near_attr(c: &[V3; 3], col: &[Rgb; 3]) -> Vec<(V3, Rgb)> {
    if c.iter().all(|p| p.z >= NEAR_M) {
        return vec![(c[0], col[0]), (c[1], col[1]), (c[2], col[2])];
    }
    let mut out = Vec::with_capacity(4);
    for k in 0..3 {
        let (a, ca) = (c[k], col[k]);
        let (b, cb) = (c[(k + 1) % 3], col[(k + 1) % 3]);
        let ain = a.z >= NEAR_M;
        let bin = b.z >= NEAR_M;
        if ain {
            out.push((a, ca));
        }
        if ain != bin {
            let t = (NEAR_M - a.z) / (b.z - a.z);
            let tf = t as f32;
            out.push((
                a.lerp(b, t),
                [
                    ca[0] + (cb[0] - ca[0]) * tf,
                    ca[1] + (cb[1] - ca[1]) * tf,
                    ca[2] + (cb[2] - ca[2]) * tf,
                ],
            ));
        }
    }
    out
}

/// Clip a camera-frame triangle against z >= NEAR_M (Sutherland-Hodgman).
fn clip_near(c: &[V3; 3]) -> Vec<V3> {
    if c.iter().all(|p| p.z >= NEAR_M) {
        return c.to_vec();
    }
    let mut out = Vec::with_capacity(4);
    for k in 0..3 {
        let a = c[k];
        let b = c[(k + 1) % 3];
        let ain = a.z >= NEAR_M;
        let bin = b.z >= NEAR_M;
        if ain {
            out.push(a);
        }
        if ain != bin {
            let t = (NEAR_M - a.z) / (b.z - a.z);
            out.push(a.lerp(b, t));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used)]
    use super::*;
    use crate::mesh::{Material, Mesh};

    #[test]
    fn a_square_covers_its_projected_area() {
        let cam = Camera::from_angles(
            200,
            200,
            100.0,
            V3::new(0.0, 0.0, 10.0),
            0.0,
            std::f64::consts::FRAC_PI_2,
            0.0,
        );
        // Looking straight down from 10 m with f = 100: 1 m on the road = 10 px.
        let mut m = Mesh::new();
        m.quad(
            V3::new(-2.0, -3.0, 0.0),
            V3::new(2.0, -3.0, 0.0),
            V3::new(2.0, 3.0, 0.0),
            V3::new(-2.0, 3.0, 0.0),
            Material::matte([0.5; 3]),
        );
        let mut t = Target::new(0.0, 0.0, 200, 200, 2);
        let light = Lighting::random(&mut crate::math::rng_for(1, &[]));
        t.draw(&cam, &light, &m.tris, 7);
        let n = t.count_id(7);
        // 40 x 60 px = 2400 px = 9600 samples at ss 2.
        assert!((n as i64 - 9600).abs() < 200, "{n}");
        assert_eq!(t.coverage(&cam, &m.tris), n);
    }

    #[test]
    fn nearer_triangle_wins_regardless_of_order() {
        let cam = Camera::from_angles(
            100,
            100,
            100.0,
            V3::new(0.0, 0.0, 10.0),
            0.0,
            std::f64::consts::FRAC_PI_2,
            0.0,
        );
        let mut low = Mesh::new();
        low.quad(
            V3::new(-1.0, -1.0, 0.0),
            V3::new(1.0, -1.0, 0.0),
            V3::new(1.0, 1.0, 0.0),
            V3::new(-1.0, 1.0, 0.0),
            Material::matte([0.1; 3]),
        );
        let mut high = Mesh::new();
        high.quad(
            V3::new(-1.0, -1.0, 2.0),
            V3::new(1.0, -1.0, 2.0),
            V3::new(1.0, 1.0, 2.0),
            V3::new(-1.0, 1.0, 2.0),
            Material::matte([0.9; 3]),
        );
        let light = Lighting::random(&mut crate::math::rng_for(1, &[]));
        for order in [0, 1] {
            let mut t = Target::new(0.0, 0.0, 100, 100, 1);
            if order == 0 {
                t.draw(&cam, &light, &low.tris, 1);
                t.draw(&cam, &light, &high.tris, 2);
            } else {
                t.draw(&cam, &light, &high.tris, 2);
                t.draw(&cam, &light, &low.tris, 1);
            }
            assert_eq!(t.id[50 * 100 + 50], 2);
        }
    }
}
