//! Triangle meshes with flat materials, and the builders the vehicle and prop models use.

use crate::math::V3;

/// How a surface reflects light (see `shade::shade_triangle`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Surface {
    /// Car paint: diffuse base plus a clear-coat reflection of the sky and a sun highlight.
    Paint,
    /// Window glass: dark interior plus a strong, angle-dependent sky reflection.
    Glass,
    /// Tyres, seals: dark and matte.
    Rubber,
    /// Bumpers, trims, grilles: diffuse with a faint sheen.
    Plastic,
    /// Rims, chrome: mostly reflection.
    Metal,
    /// Head/tail lamp covers: a bright tinted diffuse plus reflection.
    Lamp,
    /// Concrete, bark, leaves, walls: plain Lambert.
    Matte,
}

/// A flat material: linear-RGB albedo and a reflection model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Material {
    pub albedo: [f32; 3],
    pub surface: Surface,
}

impl Material {
    pub const fn new(albedo: [f32; 3], surface: Surface) -> Material {
        Material { albedo, surface }
    }
    pub const fn matte(albedo: [f32; 3]) -> Material {
        Material::new(albedo, Surface::Matte)
    }
}

/// One triangle in metres (local or world frame, depending on the owner).
#[derive(Debug, Clone, Copy)]
pub struct Tri {
    pub p: [V3; 3],
    pub mat: Material,
    /// Vertex normals for smooth (Gouraud) shading, oriented like the face normal of
    /// `(p1 - p0) x (p2 - p0)` up to sign; `None` shades the triangle flat.
    pub n: Option<[V3; 3]>,
}

/// A triangle soup. Winding is irrelevant: shading orients each normal towards the viewer.
#[derive(Debug, Clone, Default)]
pub struct Mesh {
    pub tris: Vec<Tri>,
}

impl Mesh {
    pub fn new() -> Mesh {
        Mesh::default()
    }

    pub fn tri(&mut self, a: V3, b: V3, c: V3, mat: Material) {
        self.tris.push(Tri {
            p: [a, b, c],
            mat,
            n: None,
        });
    }

    /// Quad a-b-c-d (in order around the rim).
    pub fn quad(&mut self, a: V3, b: V3, c: V3, d: V3, mat: Material) {
        self.tri(a, b, c, mat);
        self.tri(a, c, d, mat);
    }

    /// Convex polygon as a fan.
    pub fn poly(&mut self, pts: &[V3], mat: Material) {
        for i in 1..pts.len().saturating_sub(1) {
            self.tri(pts[0], pts[i], pts[i + 1], mat);
        }
    }

    /// Axis-aligned box.
    pub fn cuboid(&mut self, lo: V3, hi: V3, mat: Material) {
        let c = |x: bool, y: bool, z: bool| {
            V3::new(
                if x { hi.x } else { lo.x },
                if y { hi.y } else { lo.y },
                if z { hi.z } else { lo.z },
            )
        };
        let (f, t) = (false, true);
        self.quad(c(f, f, f), c(t, f, f), c(t, t, f), c(f, t, f), mat);
        self.quad(c(f, f, t), c(t, f, t), c(t, t, t), c(f, t, t), mat);
        self.quad(c(f, f, f), c(t, f, f), c(t, f, t), c(f, f, t), mat);
        self.quad(c(f, t, f), c(t, t, f), c(t, t, t), c(f, t, t), mat);
        self.quad(c(f, f, f), c(f, t, f), c(f, t, t), c(f, f, t), mat);
        self.quad(c(t, f, f), c(t, t, f), c(t, t, t), c(t, f, t), mat);
    }

    /// A loft along x: each section is (x, closed polygon of (y, z) points); all sections have
    /// the same number of points. `mats[k]` colours the band between polygon points k and k+1.
    /// End caps use `cap` when given.
    pub fn loft(
        &mut self,
        sections: &[(f64, Vec<(f64, f64)>)],
        mats: &[Material],
        cap: Option<Material>,
    ) {
        for w in sections.windows(2) {
            let (x0, ref a) = w[0];
            let (x1, ref b) = w[1];
            let n = a.len().min(b.len());
            for k in 0..n {
                let k2 = (k + 1) % n;
                let mat = mats[k.min(mats.len() - 1)];
                self.quad(
                    V3::new(x0, a[k].0, a[k].1),
                    V3::new(x1, b[k].0, b[k].1),
                    V3::new(x1, b[k2].0, b[k2].1),
                    V3::new(x0, a[k2].0, a[k2].1),
                    mat,
                );
            }
        }
        if let Some(cap) = cap {
            for (x, pts) in [sections.first(), sections.last()].into_iter().flatten() {
                let p: Vec<V3> = pts.iter().map(|&(y, z)| V3::new(*x, y, z)).collect();
                self.poly(&p, cap);
            }
        }
    }

    /// A loft whose band materials depend on the segment (pair of sections) and the band (pair
    /// of polygon points): `mat(segment, band)`, `None` leaves the face out.
    pub fn loft_with(
        &mut self,
        sections: &[(f64, Vec<(f64, f64)>)],
        mat: &dyn Fn(usize, usize) -> Option<Material>,
        cap: Option<Material>,
    ) {
        for (seg, w) in sections.windows(2).enumerate() {
            let (x0, ref a) = w[0];
            let (x1, ref b) = w[1];
            let n = a.len().min(b.len());
            for k in 0..n {
                let Some(m) = mat(seg, k) else { continue };
                let k2 = (k + 1) % n;
                self.quad(
                    V3::new(x0, a[k].0, a[k].1),
                    V3::new(x1, b[k].0, b[k].1),
                    V3::new(x1, b[k2].0, b[k2].1),
                    V3::new(x0, a[k2].0, a[k2].1),
                    m,
                );
            }
        }
        if let Some(cap) = cap {
            for (x, pts) in [sections.first(), sections.last()].into_iter().flatten() {
                let p: Vec<V3> = pts.iter().map(|&(y, z)| V3::new(*x, y, z)).collect();
                self.poly(&p, cap);
            }
        }
    }

    /// Like [`Mesh::loft_with`], with smooth vertex normals: each corner's normal averages the
    /// (area-weighted) normals of the faces around it, except across the `creases` bands,
    /// which stay flat.
    pub fn loft_smooth(
        &mut self,
        sections: &[(f64, Vec<(f64, f64)>)],
        mat: &dyn Fn(usize, usize) -> Option<Material>,
        cap: Option<Material>,
        creases: &[usize],
    ) {
        let nseg = sections.len().saturating_sub(1);
        let npt = sections.iter().map(|s| s.1.len()).min().unwrap_or(0);
        if nseg == 0 || npt < 3 {
            return;
        }
        let at = |st: usize, k: usize| {
            let (x, ref pts) = sections[st];
            V3::new(x, pts[k % npt].0, pts[k % npt].1)
        };
        // Face normals (length = twice the area) of every (segment, band).
        let face = |seg: usize, band: usize| {
            let a = at(seg, band);
            let b = at(seg + 1, band);
            let c = at(seg + 1, band + 1);
            let d = at(seg, band + 1);
            (c - a).cross(d - b)
        };
        let faces: Vec<Vec<V3>> = (0..nseg)
            .map(|s| (0..npt).map(|b| face(s, b)).collect())
            .collect();
        let crease = |b: usize| creases.contains(&b);
        let corner = |seg: usize, band: usize, st: usize, pt: usize| {
            let own = faces[seg][band];
            if crease(band) {
                return own.normalized();
            }
            let mut sum = V3::default();
            for s2 in [st.wrapping_sub(1), st] {
                if s2 >= nseg {
                    continue;
                }
                for b2 in [(pt + npt - 1) % npt, pt % npt] {
                    if crease(b2) {
                        continue;
                    }
                    let f = faces[s2][b2];
                    // Keep orientation consistent with this face.
                    sum = sum + if f.dot(own) < 0.0 { -f } else { f };
                }
            }
            if sum.norm() > 1e-12 {
                sum.normalized()
            } else {
                own.normalized()
            }
        };
        for seg in 0..nseg {
            for band in 0..npt {
                let Some(m) = mat(seg, band) else { continue };
                let (a, b, c, d) = (
                    at(seg, band),
                    at(seg + 1, band),
                    at(seg + 1, band + 1),
                    at(seg, band + 1),
                );
                let (na, nb, nc, nd) = (
                    corner(seg, band, seg, band),
                    corner(seg, band, seg + 1, band),
                    corner(seg, band, seg + 1, band + 1),
                    corner(seg, band, seg, band + 1),
                );
                self.tris.push(Tri {
                    p: [a, b, c],
                    mat: m,
                    n: Some([na, nb, nc]),
                });
                self.tris.push(Tri {
                    p: [a, c, d],
                    mat: m,
                    n: Some([na, nc, nd]),
                });
            }
        }
        if let Some(cap) = cap {
            for (x, pts) in [sections.first(), sections.last()].into_iter().flatten() {
                let p: Vec<V3> = pts.iter().map(|&(y, z)| V3::new(*x, y, z)).collect();
                self.poly(&p, cap);
            }
        }
    }

    /// Cylinder with its axis along y, from y0 to y1, centre (x, z); caps at both ends. A
    /// vertex sits exactly at the bottom (z - r), so a wheel touches the road.
    #[allow(clippy::too_many_arguments)]
    // Why: centre, radius, extent, tessellation and two materials define the cylinder.
    pub fn cylinder_y(
        &mut self,
        x: f64,
        z: f64,
        r: f64,
        y0: f64,
        y1: f64,
        segs: usize,
        side: Material,
        cap: Material,
    ) {
        let pt = |k: usize, y: f64| {
            let a = -std::f64::consts::FRAC_PI_2 + std::f64::consts::TAU * k as f64 / segs as f64;
            V3::new(x + r * a.cos(), y, z + r * a.sin())
        };
        let mut c0 = Vec::with_capacity(segs);
        let mut c1 = Vec::with_capacity(segs);
        for k in 0..segs {
            self.quad(pt(k, y0), pt(k + 1, y0), pt(k + 1, y1), pt(k, y1), side);
            c0.push(pt(k, y0));
            c1.push(pt(k, y1));
        }
        self.poly(&c0, cap);
        self.poly(&c1, cap);
    }

    /// Vertical cylinder (pole) standing at (x, y) from z0 to z1.
    #[allow(clippy::too_many_arguments)]
    // Why: position, radius, extent, tessellation and material define the pole.
    pub fn cylinder_z(
        &mut self,
        x: f64,
        y: f64,
        r: f64,
        z0: f64,
        z1: f64,
        segs: usize,
        mat: Material,
    ) {
        let pt = |k: usize, z: f64| {
            let a = std::f64::consts::TAU * k as f64 / segs as f64;
            V3::new(x + r * a.cos(), y + r * a.sin(), z)
        };
        let mut top = Vec::with_capacity(segs);
        for k in 0..segs {
            self.quad(pt(k, z0), pt(k + 1, z0), pt(k + 1, z1), pt(k, z1), mat);
            top.push(pt(k, z1));
        }
        self.poly(&top, mat);
    }

    /// A low-poly blob (octahedron-based ellipsoid), for tree crowns and bushes.
    pub fn blob(
        &mut self,
        c: V3,
        rx: f64,
        ry: f64,
        rz: f64,
        mat: Material,
        jitter: &mut dyn FnMut() -> f64,
    ) {
        // A 2-frequency subdivided octahedron: 8 faces x 4 = 32 triangles.
        let base = [
            V3::new(1.0, 0.0, 0.0),
            V3::new(-1.0, 0.0, 0.0),
            V3::new(0.0, 1.0, 0.0),
            V3::new(0.0, -1.0, 0.0),
            V3::new(0.0, 0.0, 1.0),
            V3::new(0.0, 0.0, -1.0),
        ];
        let faces = [
            (0, 2, 4),
            (2, 1, 4),
            (1, 3, 4),
            (3, 0, 4),
            (2, 0, 5),
            (1, 2, 5),
            (3, 1, 5),
            (0, 3, 5),
        ];
        let place = |v: V3, s: f64| {
            let v = v.normalized() * s;
            V3::new(c.x + v.x * rx, c.y + v.y * ry, c.z + v.z * rz)
        };
        for (a, b, d) in faces {
            let (a, b, d) = (base[a], base[b], base[d]);
            let ab = (a + b) * 0.5;
            let bd = (b + d) * 0.5;
            let da = (d + a) * 0.5;
            let pa = place(a, 1.0 + 0.15 * jitter());
            let pb = place(b, 1.0 + 0.15 * jitter());
            let pd = place(d, 1.0 + 0.15 * jitter());
            let pab = place(ab, 1.0 + 0.2 * jitter());
            let pbd = place(bd, 1.0 + 0.2 * jitter());
            let pda = place(da, 1.0 + 0.2 * jitter());
            self.tri(pa, pab, pda, mat);
            self.tri(pab, pb, pbd, mat);
            self.tri(pda, pbd, pd, mat);
            self.tri(pab, pbd, pda, mat);
        }
    }

    /// A sub-rectangle of the (possibly degenerate) quad p00-p10-p11-p01, bilinear in (u, v),
    /// pushed by `offset` (e.g. 1 cm along the outward normal): windows, lamps, plates.
    #[allow(clippy::too_many_arguments)]
    // Why: the four corners and the four bounds are the natural parameters of a decal.
    pub fn decal(
        &mut self,
        q: [V3; 4],
        u0: f64,
        u1: f64,
        v0: f64,
        v1: f64,
        offset: V3,
        mat: Material,
    ) {
        let at = |u: f64, v: f64| {
            let bottom = q[0].lerp(q[1], u);
            let top = q[3].lerp(q[2], u);
            bottom.lerp(top, v) + offset
        };
        self.quad(at(u0, v0), at(u1, v0), at(u1, v1), at(u0, v1), mat);
    }

    /// Append another mesh.
    pub fn extend(&mut self, other: &Mesh) {
        self.tris.extend_from_slice(&other.tris);
    }

    /// Axis-aligned bounds (min, max); `None` for an empty mesh.
    pub fn bounds(&self) -> Option<(V3, V3)> {
        let first = self.tris.first()?.p[0];
        let (mut lo, mut hi) = (first, first);
        for t in &self.tris {
            for p in t.p {
                lo = V3::new(lo.x.min(p.x), lo.y.min(p.y), lo.z.min(p.z));
                hi = V3::new(hi.x.max(p.x), hi.y.max(p.y), hi.z.max(p.z));
            }
        }
        Some((lo, hi))
    }

    /// This mesh placed on the road at (x, y) with the given heading (rotation about z).
    pub fn placed(&self, pose: &Pose) -> Mesh {
        let (s, c) = pose.heading.sin_cos();
        let f = |p: V3| V3::new(pose.x + c * p.x - s * p.y, pose.y + s * p.x + c * p.y, p.z);
        Mesh {
            tris: self
                .tris
                .iter()
                .map(|t| Tri {
                    p: [f(t.p[0]), f(t.p[1]), f(t.p[2])],
                    mat: t.mat,
                    n: t.n
                        .map(|n| n.map(|v| V3::new(c * v.x - s * v.y, s * v.x + c * v.y, v.z))),
                })
                .collect(),
        }
    }
}

/// A placement on the road plane: translation (x, y) metres and heading (radians from +x
/// towards +y). The local frame of a vehicle has x forward, y left, z up, origin at the
/// centre of its footprint on the road.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Pose {
    pub x: f64,
    pub y: f64,
    pub heading: f64,
}

impl Pose {
    pub fn apply(&self, p: V3) -> V3 {
        let (s, c) = self.heading.sin_cos();
        V3::new(self.x + c * p.x - s * p.y, self.y + s * p.x + c * p.y, p.z)
    }
    /// World point to the local frame.
    pub fn inverse(&self, p: V3) -> V3 {
        let (s, c) = self.heading.sin_cos();
        let dx = p.x - self.x;
        let dy = p.y - self.y;
        V3::new(c * dx + s * dy, -s * dx + c * dy, p.z)
    }
}
