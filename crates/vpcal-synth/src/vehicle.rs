//! Procedural vehicles: cars (sedan, hatchback, wagon, SUV), vans, trucks and buses built from
//! lofted bodies, a glass cabin with pillars, wheels in arches, lamps, grille and plates.
//!
//! Local frame: x forward, y left, z up; origin at the centre of the footprint on the road.
//! The 3D bounding box is `[-length/2, length/2] x [-width/2, width/2] x [0, height]`
//! (mirrors stick out of it, as on BoxCars boxes).

use rand::Rng;

use crate::math::{RngExt, V3};
use crate::mesh::{Material, Mesh, Pose, Surface};
use crate::shade::{srgb, Rgb};

/// Vehicle class.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum VehicleKind {
    Sedan,
    Hatchback,
    Wagon,
    Suv,
    Pickup,
    Van,
    Truck,
    Bus,
}

impl VehicleKind {
    pub fn name(self) -> &'static str {
        match self {
            VehicleKind::Sedan => "sedan",
            VehicleKind::Hatchback => "hatchback",
            VehicleKind::Wagon => "wagon",
            VehicleKind::Suv => "suv",
            VehicleKind::Pickup => "pickup",
            VehicleKind::Van => "van",
            VehicleKind::Truck => "truck",
            VehicleKind::Bus => "bus",
        }
    }

    /// A class drawn with roughly European traffic frequencies.
    pub fn random<R: Rng>(rng: &mut R) -> VehicleKind {
        const KINDS: [VehicleKind; 8] = [
            VehicleKind::Sedan,
            VehicleKind::Hatchback,
            VehicleKind::Wagon,
            VehicleKind::Suv,
            VehicleKind::Pickup,
            VehicleKind::Van,
            VehicleKind::Truck,
            VehicleKind::Bus,
        ];
        KINDS[rng.weighted(&[0.23, 0.23, 0.13, 0.16, 0.04, 0.11, 0.06, 0.04])]
    }
}

/// Everything that defines one vehicle's shape and colours; `build` turns it into a mesh.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct VehicleSpec {
    pub kind: VehicleKind,
    /// Bounding box length (x), width (y, without mirrors) and height (z), metres.
    pub length: f64,
    pub width: f64,
    pub height: f64,
    pub wheel_radius: f64,
    /// Shape knobs in 0..1 (meaning depends on the class).
    pub shape: [f64; 8],
    /// Paint and secondary colours, linear RGB.
    pub paint: Rgb,
    pub second: Rgb,
    pub glass: Rgb,
    pub rim: Rgb,
    pub trim: Rgb,
    /// Extra windows on the side (vans) / two-tone (buses) etc.
    pub variant: u32,
}

fn paint_colour<R: Rng>(rng: &mut R) -> Rgb {
    let palette: [(f64, [u8; 3]); 15] = [
        (0.20, [232, 232, 228]),
        (0.16, [20, 20, 22]),
        (0.14, [98, 100, 104]),
        (0.13, [168, 170, 174]),
        (0.06, [30, 40, 78]),
        (0.05, [45, 80, 150]),
        (0.06, [165, 22, 24]),
        (0.03, [95, 18, 24]),
        (0.03, [35, 72, 45]),
        (0.03, [196, 182, 150]),
        (0.03, [85, 60, 45]),
        (0.02, [220, 180, 30]),
        (0.02, [210, 100, 30]),
        (0.02, [120, 150, 180]),
        (0.02, [60, 110, 110]),
    ];
    let w: Vec<f64> = palette.iter().map(|p| p.0).collect();
    let c = palette[rng.weighted(&w)].1;
    // Brightness varies more than hue (whites stay white, not pink).
    let bright = 1.0 + 0.07 * rng.normal();
    let mut j =
        |v: u8| (f64::from(v) * bright * (1.0 + 0.02 * rng.normal())).clamp(3.0, 250.0) as u8;
    let (r, g, b) = (j(c[0]), j(c[1]), j(c[2]));
    srgb(r, g, b)
}

impl VehicleSpec {
    /// A random vehicle of the given class with realistic dimensions.
    pub fn random<R: Rng>(rng: &mut R, kind: VehicleKind) -> VehicleSpec {
        let (length, width, height, wheel) = match kind {
            VehicleKind::Sedan => (
                rng.uni(4.3, 5.1),
                rng.uni(1.72, 1.92),
                rng.uni(1.38, 1.52),
                rng.uni(0.30, 0.34),
            ),
            VehicleKind::Hatchback => (
                rng.uni(3.6, 4.4),
                rng.uni(1.64, 1.82),
                rng.uni(1.42, 1.6),
                rng.uni(0.29, 0.33),
            ),
            VehicleKind::Wagon => (
                rng.uni(4.4, 5.0),
                rng.uni(1.75, 1.9),
                rng.uni(1.45, 1.58),
                rng.uni(0.30, 0.34),
            ),
            VehicleKind::Suv => (
                rng.uni(4.2, 5.0),
                rng.uni(1.8, 2.0),
                rng.uni(1.6, 1.85),
                rng.uni(0.34, 0.39),
            ),
            VehicleKind::Pickup => (
                rng.uni(5.0, 5.9),
                rng.uni(1.85, 2.05),
                rng.uni(1.72, 1.95),
                rng.uni(0.36, 0.40),
            ),
            VehicleKind::Van => (
                rng.uni(4.8, 6.6),
                rng.uni(1.9, 2.1),
                rng.uni(1.9, 2.7),
                rng.uni(0.33, 0.37),
            ),
            VehicleKind::Truck => (
                if rng.chance(0.35) {
                    rng.uni(13.0, 16.5)
                } else {
                    rng.uni(7.0, 10.5)
                },
                rng.uni(2.4, 2.55),
                rng.uni(3.2, 4.0),
                rng.uni(0.47, 0.53),
            ),
            VehicleKind::Bus => (
                rng.uni(10.5, 13.5),
                rng.uni(2.5, 2.55),
                rng.uni(3.0, 3.4),
                rng.uni(0.48, 0.52),
            ),
        };
        let mut shape = [0.0; 8];
        for s in &mut shape {
            *s = rng.random();
        }
        let paint = match kind {
            VehicleKind::Bus if rng.chance(0.5) => {
                let b = [
                    (200, 30, 30),
                    (230, 230, 225),
                    (30, 90, 170),
                    (240, 190, 30),
                    (40, 130, 70),
                ];
                let c = b[rng.int(0, 4) as usize];
                srgb(c.0, c.1, c.2)
            }
            _ => paint_colour(rng),
        };
        let second = match kind {
            VehicleKind::Truck => {
                if rng.chance(0.6) {
                    srgb(230, 230, 226)
                } else {
                    paint_colour(rng)
                }
            }
            _ => paint_colour(rng),
        };
        let gl = rng.uni(8.0, 30.0) as u8;
        let glass = srgb(
            gl,
            gl.saturating_add(rng.uni(0.0, 6.0) as u8),
            gl.saturating_add(rng.uni(0.0, 10.0) as u8),
        );
        let rim = if rng.chance(0.6) {
            srgb(170, 172, 176)
        } else {
            srgb(40, 40, 42)
        };
        let tv = rng.uni(15.0, 40.0) as u8;
        let trim = if rng.chance(0.5) {
            srgb(tv, tv, tv)
        } else {
            paint
        };
        VehicleSpec {
            kind,
            length,
            width,
            height,
            wheel_radius: wheel,
            shape,
            paint,
            second,
            glass,
            rim,
            trim,
            variant: rng.random(),
        }
    }

    /// A random vehicle of a random class.
    pub fn random_any<R: Rng>(rng: &mut R) -> VehicleSpec {
        let kind = VehicleKind::random(rng);
        VehicleSpec::random(rng, kind)
    }

    /// The 8 corners of the 3D bounding box in the local frame. Order: bottom (z = 0)
    /// front-left, front-right, rear-right, rear-left, then the same four at the top.
    pub fn bb3d_local(&self) -> [V3; 8] {
        let (l, w, h) = (self.length / 2.0, self.width / 2.0, self.height);
        [
            V3::new(l, w, 0.0),
            V3::new(l, -w, 0.0),
            V3::new(-l, -w, 0.0),
            V3::new(-l, w, 0.0),
            V3::new(l, w, h),
            V3::new(l, -w, h),
            V3::new(-l, -w, h),
            V3::new(-l, w, h),
        ]
    }

    /// The 3D box corners placed in the world.
    pub fn bb3d_world(&self, pose: &Pose) -> [V3; 8] {
        self.bb3d_local().map(|p| pose.apply(p))
    }

    /// A box roughly filling the body, for cheap cast shadows.
    pub fn shadow_box(&self) -> Mesh {
        let mut m = Mesh::new();
        let (l, w) = (self.length / 2.0, self.width / 2.0 * 0.95);
        m.cuboid(
            V3::new(-l, -w, 0.3),
            V3::new(l, w, self.height * 0.92),
            Material::matte([0.0; 3]),
        );
        m
    }

    /// Build the mesh in the local frame.
    pub fn build(&self) -> Mesh {
        self.build_model().mesh
    }

    /// Build the mesh and a low-poly proxy of it (for cast shadows), in the local frame.
    pub fn build_model(&self) -> VehicleModel {
        let mut b = Builder::new(self);
        match self.kind {
            VehicleKind::Sedan
            | VehicleKind::Hatchback
            | VehicleKind::Wagon
            | VehicleKind::Suv
            | VehicleKind::Pickup => b.car(),
            VehicleKind::Van => b.van(),
            VehicleKind::Truck => b.truck(),
            VehicleKind::Bus => b.bus(),
        }
        VehicleModel {
            mesh: b.mesh,
            shadow: b.proxy,
        }
    }
}

/// A vehicle's mesh and its shadow proxy (a few boxes), local frame.
#[derive(Debug, Clone)]
pub struct VehicleModel {
    pub mesh: Mesh,
    pub shadow: Mesh,
}

struct Builder<'a> {
    s: &'a VehicleSpec,
    mesh: Mesh,
    proxy: Mesh,
    paint: Material,
    glass: Material,
    rubber: Material,
    rim: Material,
    trim: Material,
    dark: Material,
    head: Material,
    tail: Material,
    plate: Material,
    arch: Material,
}

const EPS: f64 = 0.012;

impl<'a> Builder<'a> {
    fn new(s: &'a VehicleSpec) -> Builder<'a> {
        Builder {
            s,
            mesh: Mesh::new(),
            proxy: Mesh::new(),
            paint: Material::new(s.paint, Surface::Paint),
            glass: Material::new(s.glass, Surface::Glass),
            rubber: Material::new(srgb(22, 22, 23), Surface::Rubber),
            rim: Material::new(s.rim, Surface::Metal),
            trim: Material::new(s.trim, Surface::Plastic),
            dark: Material::new(srgb(14, 14, 15), Surface::Plastic),
            head: Material::new(srgb(200, 205, 210), Surface::Lamp),
            tail: Material::new(srgb(150, 15, 15), Surface::Lamp),
            plate: Material::new(srgb(225, 225, 220), Surface::Plastic),
            arch: Material::new(srgb(10, 10, 10), Surface::Rubber),
        }
    }

    /// Lower-body cross-section: bottom, shoulder (widest) and top edge.
    fn body_section(hw: f64, zb: f64, zm: f64, zt: f64, top_k: f64) -> Vec<(f64, f64)> {
        vec![
            (-hw * 0.94, zb),
            (hw * 0.94, zb),
            (hw, zm),
            (hw * top_k, zt),
            (-hw * top_k, zt),
            (-hw, zm),
        ]
    }

    /// Wheels with arches on both sides at axle position x.
    fn axle(&mut self, x: f64, r: f64, hw: f64, tyre_w: f64, dual: bool) {
        for side in [-1.0, 1.0] {
            // Arch: a dark half disc on the body side behind the wheel.
            let ya = side * (hw + EPS * 0.5);
            let ra = r * 1.13;
            let mut pts = vec![V3::new(x + ra, ya, r * 0.55)];
            for k in 0..=10 {
                let a = std::f64::consts::PI * k as f64 / 10.0;
                pts.push(V3::new(x + ra * a.cos(), ya, r + ra * a.sin()));
            }
            pts.push(V3::new(x - ra, ya, r * 0.55));
            self.mesh.poly(&pts, self.arch);
            let y_out = side * (hw + EPS);
            let y_in = side * (hw - tyre_w * if dual { 2.0 } else { 1.0 });
            self.mesh
                .cylinder_y(x, r, r, y_in, y_out, 14, self.rubber, self.rubber);
            // Rim disc on the outer face.
            let yr = side * (hw + EPS * 1.5);
            let rr = r * 0.62;
            let rim: Vec<V3> = (0..12)
                .map(|k| {
                    let a = std::f64::consts::TAU * k as f64 / 12.0;
                    V3::new(x + rr * a.cos(), yr, r + rr * a.sin())
                })
                .collect();
            self.mesh.poly(&rim, self.rim);
            let hub: Vec<V3> = (0..8)
                .map(|k| {
                    let a = std::f64::consts::TAU * k as f64 / 8.0;
                    V3::new(
                        x + rr * 0.3 * a.cos(),
                        yr + side * EPS * 0.5,
                        r + rr * 0.3 * a.sin(),
                    )
                })
                .collect();
            self.mesh.poly(&hub, self.dark);
        }
    }

    /// Rectangle on a plane x = const, facing +x (front) or -x (rear), y in [y0, y1], z in [z0, z1].
    fn x_plate(&mut self, x: f64, y0: f64, y1: f64, z0: f64, z1: f64, mat: Material) {
        self.mesh.quad(
            V3::new(x, y0, z0),
            V3::new(x, y1, z0),
            V3::new(x, y1, z1),
            V3::new(x, y0, z1),
            mat,
        );
    }

    /// Rectangle on the side plane y = const.
    fn y_plate(&mut self, y: f64, x0: f64, x1: f64, z0: f64, z1: f64, mat: Material) {
        self.mesh.quad(
            V3::new(x0, y, z0),
            V3::new(x1, y, z0),
            V3::new(x1, y, z1),
            V3::new(x0, y, z1),
            mat,
        );
    }

    /// Rounded lower-body cross-section (12 points): `wf` scales the half width (plan-view
    /// rounding at the ends), zb/zt are the bottom and top heights.
    fn rounded_section(hw: f64, zb: f64, zm: f64, zt: f64) -> Vec<(f64, f64)> {
        let zl = zb + 0.3 * (zm - zb);
        let zu = zm + 0.6 * (zt - zm);
        let right = [
            (hw * 0.92, zb),
            (hw * 0.99, zl),
            (hw, zm),
            (hw * 0.985, zu),
            (hw * 0.95, zt - 0.03),
            (hw * 0.85, zt),
        ];
        let mut v: Vec<(f64, f64)> = vec![(-hw * 0.92, zb)];
        v.extend(right.iter().copied());
        v.extend(right.iter().rev().skip(1).map(|&(y, z)| (-y, z)));
        v
    }

    fn car(&mut self) {
        let s = self.s;
        let k = s.shape;
        let (len, w, h) = (s.length, s.width, s.height);
        let hw = w / 2.0;
        let x0 = -len / 2.0;
        let at = |f: f64| x0 + f * len;
        let kind = s.kind;
        let pickup = kind == VehicleKind::Pickup;
        let suv = kind == VehicleKind::Suv || pickup;
        let sedan = kind == VehicleKind::Sedan;
        let r = s.wheel_radius;
        let zb = if suv {
            0.26 + 0.06 * k[0]
        } else {
            0.16 + 0.05 * k[0]
        };
        let belt = h * (0.58 + 0.06 * k[1]).min(0.66);
        let zm = zb + (belt - zb) * (0.5 + 0.15 * k[2]);
        let hood_front = belt - (0.16 + 0.12 * k[3]);
        let (x_rw, x_rr) = match kind {
            VehicleKind::Sedan => (0.17 + 0.04 * k[4], 0.31 + 0.05 * k[5]),
            VehicleKind::Hatchback => (0.015, 0.1 + 0.05 * k[5]),
            VehicleKind::Wagon => (0.02, 0.05 + 0.03 * k[5]),
            // Pickup: the cab ends where the bed begins.
            VehicleKind::Pickup => (0.38 + 0.06 * k[4], 0.38 + 0.06 * k[4]),
            _ => (0.02, 0.06 + 0.04 * k[5]),
        };
        let x_ws = 0.68 + 0.06 * k[6]
            - if kind == VehicleKind::Hatchback {
                0.04
            } else {
                0.0
            };
        let rake = if suv {
            1.1 + 0.5 * k[7]
        } else {
            1.45 + 0.5 * k[7]
        };
        let x_rf = x_ws - (h - belt) * rake / len;
        let trunk = if sedan { belt - 0.03 } else { belt };
        let dark_bumpers = s.variant % 4 == 0;

        // Lower body: (x fraction, width factor, bottom, top).
        let mid_hood = (x_ws + 0.93) / 2.0;
        let stations = [
            (0.0, 0.86, zb + 0.1, trunk - 0.09),
            (0.012, 0.93, zb + 0.05, trunk - 0.04),
            (0.035, 0.985, zb + 0.01, trunk - 0.01),
            (x_rw.max(0.08), 1.0, zb, trunk),
            (x_ws, 1.0, zb, belt),
            (mid_hood, 1.0, zb, (belt + hood_front) / 2.0 + 0.02),
            (0.93, 1.0, zb, hood_front),
            (0.965, 0.985, zb + 0.01, hood_front - 0.03),
            (0.988, 0.94, zb + 0.04, hood_front - 0.07),
            (1.0, 0.87, zb + 0.08, hood_front - 0.12),
        ];
        let secs: Vec<(f64, Vec<(f64, f64)>)> = stations
            .iter()
            .map(|&(f, wf, b, t)| {
                (
                    at(f),
                    Self::rounded_section(hw * wf, b, zm.min(t - 0.05), t),
                )
            })
            .collect();
        let nseg = secs.len() - 1;
        let (paint, trim, dark) = (self.paint, self.trim, self.dark);
        self.mesh.loft_smooth(
            &secs,
            &|seg, band| {
                let bumper = seg < 2 || seg + 2 >= nseg;
                match band {
                    0 => Some(dark),
                    // Open load bed of a pickup.
                    6 if pickup && seg == 2 => None,
                    1 | 11 if bumper && dark_bumpers => Some(trim),
                    1 | 11 => Some(if seg > 1 && seg + 2 < nseg {
                        trim
                    } else {
                        paint
                    }),
                    _ => Some(paint),
                }
            },
            Some(paint),
            &[0],
        );
        self.proxy.cuboid(
            V3::new(at(0.0), -hw * 0.95, zb),
            V3::new(at(1.0), hw * 0.95, belt),
            paint,
        );

        // Cabin: 8-point sections; bands 1/7 side windows, 2/6 frames, 3/5 roof edges, 4 top.
        let hb = hw * 0.9;
        let ht = hw * (0.68 + 0.08 * k[2]);
        let rr = 0.06;
        let cab = |top: f64| {
            let zwt = (top - rr - 0.035).max(belt + 0.05);
            let f = (zwt - belt) / (top - rr - belt).max(1e-3);
            let hm = hb + (ht - hb) * f;
            vec![
                (-hb, belt),
                (hb, belt),
                (hm, zwt),
                (ht, top - rr),
                (ht * 0.72, top),
                (-ht * 0.72, top),
                (-ht, top - rr),
                (-hm, zwt),
            ]
        };
        let flat = vec![
            (-hb, belt),
            (hb, belt),
            (hb, belt),
            (hb * 0.95, belt),
            (hb * 0.85, belt),
            (-hb * 0.85, belt),
            (-hb * 0.95, belt),
            (-hb, belt),
        ];
        let x_b = if pickup {
            (x_rf + x_rw + 0.03) / 2.0
        } else {
            (x_rf + x_rr) / 2.0 + 0.03
        };
        let pil = 0.012;
        let rear_top = belt + (h - belt) * 0.15;
        // (x fraction, section) from the rear; `side` says which side-window segments are glass.
        let mut csecs: Vec<(f64, Vec<(f64, f64)>)> = Vec::new();
        let side: Vec<bool> = if pickup {
            csecs.push((at(x_rw), cab(h)));
            csecs.push((at(x_rw + 0.03), cab(h)));
            vec![false, false, true, false, true, false]
        } else if sedan {
            csecs.push((at(x_rw), flat.clone()));
            csecs.push((at(x_rr), cab(h)));
            csecs.push((at(x_rr + 0.035), cab(h)));
            vec![false, false, true, false, true, false]
        } else {
            let x_q = x_rr
                + if kind == VehicleKind::Hatchback {
                    0.10
                } else {
                    0.13
                };
            csecs.push((at(x_rw), cab(rear_top)));
            csecs.push((at(x_rr), cab(h)));
            csecs.push((at(x_rr + 0.03), cab(h)));
            csecs.push((at(x_q), cab(h)));
            csecs.push((at(x_q + 0.025), cab(h)));
            vec![
                false,
                false,
                kind != VehicleKind::Hatchback,
                false,
                true,
                false,
                true,
                false,
            ]
        };
        csecs.push((at(x_b - pil), cab(h)));
        csecs.push((at(x_b + pil), cab(h)));
        csecs.push((at(x_rf), cab(h)));
        csecs.push((at(x_ws), flat));
        let nc = csecs.len() - 1;
        let glass = self.glass;
        let b_pillar = if k[0] > 0.4 { dark } else { paint };
        self.mesh.loft_smooth(
            &csecs,
            &|seg, band| {
                let first = seg == 0;
                let last = seg + 1 == nc;
                match band {
                    0 => None,
                    // Rear window and windshield.
                    4 if (first && !pickup) || last => Some(glass),
                    1 | 7 if seg + 3 == nc => Some(b_pillar),
                    // The front door glass runs on under the A pillar.
                    1 | 7 if last || side.get(seg).copied().unwrap_or(false) => Some(glass),
                    _ => Some(paint),
                }
            },
            Some(paint),
            &[0],
        );
        self.proxy
            .loft_with(&csecs, &|_, _| Some(paint), Some(paint));

        if pickup {
            let (bx0, bx1) = (at(0.035), at(x_rw));
            let (yi, zf) = (hw * 0.85, zb + 0.35);
            let floor = Material::new(srgb(30, 30, 32), Surface::Plastic);
            self.mesh.quad(
                V3::new(bx0, -yi, zf),
                V3::new(bx1, -yi, zf),
                V3::new(bx1, yi, zf),
                V3::new(bx0, yi, zf),
                floor,
            );
            for sd in [-1.0, 1.0] {
                self.y_plate(sd * (yi - EPS), bx0, bx1, zf, trunk, paint);
            }
            self.x_plate(bx0 + EPS, -yi, yi, zf, trunk - 0.01, paint);
            self.x_plate(bx1 - EPS, -yi, yi, zf, belt, paint);
            // Cab rear window.
            self.x_plate(
                bx1 - EPS,
                -ht * 0.8,
                ht * 0.8,
                belt + 0.08,
                h - rr - 0.06,
                glass,
            );
        }
        for sd in [-1.0, 1.0] {
            // Mirror.
            let mx = at(x_rf) - 0.05;
            let my = sd * (hb + 0.02);
            self.mesh.cuboid(
                V3::new(mx - 0.12, my.min(my + sd * 0.17), belt + 0.02),
                V3::new(mx + 0.04, my.max(my + sd * 0.17), belt + 0.16),
                if k[4] > 0.5 { trim } else { paint },
            );
            // Door handles.
            for xf in [x_b + 0.06, (x_b + x_rr) / 2.0] {
                let y = sd * (hw * 0.995 + EPS);
                let z = zm + 0.55 * (belt - zm);
                self.y_plate(y, at(xf) - 0.1, at(xf), z - 0.02, z + 0.02, trim);
            }
        }
        // Wheels.
        let wb_rear = 0.17 + 0.04 * k[3];
        let wb_front = 0.82 - 0.03 * k[5];
        self.axle(at(wb_rear), r, hw, 0.22, false);
        self.axle(at(wb_front), r, hw, 0.22, false);

        // Front: lamps, grille, intake, plate.
        let xf = at(1.0) + EPS;
        let fhw = hw * 0.87;
        let zt = hood_front - 0.12;
        let lamp_h = (0.08 + 0.06 * k[6]).min((zt - zb - 0.1) * 0.5);
        for sd in [-1.0, 1.0] {
            let (ya, yb) = (sd * fhw * 0.55, sd * fhw * 0.95);
            self.x_plate(
                xf,
                ya.min(yb),
                ya.max(yb),
                zt - lamp_h - 0.02,
                zt - 0.02,
                self.head,
            );
        }
        let grille_w = fhw * (0.3 + 0.22 * k[0]);
        self.x_plate(xf, -grille_w, grille_w, zt - lamp_h - 0.03, zt - 0.03, dark);
        self.x_plate(xf, -fhw * 0.6, fhw * 0.6, zb + 0.1, zb + 0.2, dark);
        self.x_plate(xf + EPS, -0.26, 0.26, zb + 0.2, zb + 0.31, self.plate);
        // Rear: lamps, plate, bumper strip.
        let xr = at(0.0) - EPS;
        let rhw = hw * 0.86;
        let rzt = trunk - 0.09;
        for sd in [-1.0, 1.0] {
            let (ya, yb) = (sd * rhw * 0.55, sd * rhw * 0.96);
            self.x_plate(
                xr,
                ya.min(yb),
                ya.max(yb),
                rzt - 0.17,
                rzt - 0.03,
                self.tail,
            );
        }
        self.x_plate(xr, -0.26, 0.26, zb + 0.27, zb + 0.38, self.plate);
        self.x_plate(xr, -rhw * 0.9, rhw * 0.9, zb + 0.12, zb + 0.2, trim);
    }

    fn van(&mut self) {
        let s = self.s;
        let k = s.shape;
        let (len, w, h) = (s.length, s.width, s.height);
        let hw = w / 2.0;
        let x0 = -len / 2.0;
        let zb = 0.2 + 0.05 * k[0];
        let belt = 1.0 + 0.15 * k[1];
        let zm = zb + (belt - zb) * 0.55;
        let hood_len = 0.8 + 0.4 * k[2];
        let hood_front = belt - 0.2 - 0.1 * k[3];
        let x_ws = x0 + len - hood_len;
        let x_rf = x_ws - (h - belt) * (0.45 + 0.35 * k[4]);
        let tk = 0.98;
        let secs = vec![
            (x0, Self::body_section(hw * 0.97, zb + 0.05, zm, belt, tk)),
            (x_ws, Self::body_section(hw, zb, zm, belt, tk)),
            (
                x0 + len - 0.12,
                Self::body_section(hw * 0.98, zb, zm, hood_front, tk),
            ),
            (
                x0 + len,
                Self::body_section(hw * 0.9, zb + 0.06, zm, hood_front - 0.1, 0.86),
            ),
        ];
        self.mesh.loft(
            &secs,
            &[
                self.trim, self.paint, self.paint, self.paint, self.paint, self.paint,
            ],
            Some(self.paint),
        );
        let hb = hw * tk;
        let ht = hw * 0.9;
        let cab = |top: f64| vec![(-hb, belt), (hb, belt), (ht, top), (-ht, top)];
        let flat = vec![(-hb, belt), (hb, belt), (hb, belt), (-hb, belt)];
        let csecs = vec![(x0, cab(h)), (x_rf, cab(h)), (x_ws, flat)];
        self.mesh.loft(&csecs, &[self.paint], Some(self.paint));
        self.proxy.loft(&csecs, &[self.paint], Some(self.paint));
        self.proxy.cuboid(
            V3::new(x0, -hw, zb),
            V3::new(x0 + len, hw, belt),
            self.paint,
        );
        let p = V3::new;
        let q = [
            p(x_ws, -hb, belt),
            p(x_ws, hb, belt),
            p(x_rf, ht, h),
            p(x_rf, -ht, h),
        ];
        let n = face_normal(&q, V3::new(0.0, 0.0, belt));
        self.mesh
            .decal(q, 0.04, 0.96, 0.05, 0.92, n * EPS, self.glass);
        let passenger = s.variant % 3 == 0;
        for side in [-1.0, 1.0] {
            let out = V3::new(0.0, side, (hb - ht) / (h - belt)).normalized() * EPS;
            let sq = |xa: f64, xb: f64| {
                [
                    p(xa, side * hb, belt),
                    p(xb, side * hb, belt),
                    p(xb, side * ht, h),
                    p(xa, side * ht, h),
                ]
            };
            // Door window (front cab).
            let xb_door = x_rf - 0.9;
            self.mesh
                .decal(sq(xb_door, x_rf), 0.05, 0.98, 0.1, 0.85, out, self.glass);
            // Under the A pillar.
            let tri = [
                p(x_rf, side * hb, belt),
                p(x_ws, side * hb, belt),
                p(x_ws, side * hb, belt),
                p(x_rf, side * ht, h),
            ];
            self.mesh.decal(tri, 0.1, 0.6, 0.08, 0.6, out, self.glass);
            if passenger {
                let n_win = ((xb_door - x0 - 0.4) / 1.1).floor().max(1.0) as usize;
                let span = (xb_door - 0.1 - (x0 + 0.3)) / n_win as f64;
                for i in 0..n_win {
                    let xa = x0 + 0.3 + span * i as f64;
                    self.mesh
                        .decal(sq(xa, xa + span), 0.06, 0.94, 0.12, 0.85, out, self.glass);
                }
            } else if s.variant % 5 == 1 {
                // A company stripe on cargo vans.
                let stripe = Material::new(s.second, Surface::Paint);
                self.y_plate(
                    side * (hw + EPS),
                    x0 + 0.2,
                    xb_door - 0.2,
                    zm - 0.1,
                    zm + 0.1,
                    stripe,
                );
            }
            self.mesh.cuboid(
                V3::new(
                    x_rf - 0.15,
                    (side * (hb + 0.02)).min(side * (hb + 0.22)),
                    belt + 0.1,
                ),
                V3::new(
                    x_rf + 0.05,
                    (side * (hb + 0.02)).max(side * (hb + 0.22)),
                    belt + 0.4,
                ),
                self.dark,
            );
        }
        // Rear doors: split line and two windows.
        let xr = x0 - EPS;
        self.x_plate(xr, -0.015, 0.015, zb + 0.1, h - 0.05, self.dark);
        if s.variant % 2 == 0 {
            self.x_plate(xr, -ht * 0.9, -0.06, belt + 0.15, h - 0.15, self.glass);
            self.x_plate(xr, 0.06, ht * 0.9, belt + 0.15, h - 0.15, self.glass);
        }
        for side in [-1.0, 1.0] {
            let (ya, yb) = (side * hw * 0.8, side * hw * 0.95);
            self.x_plate(
                xr,
                ya.min(yb),
                ya.max(yb),
                belt - 0.3,
                belt + 0.05,
                self.tail,
            );
        }
        self.x_plate(xr, -0.26, 0.26, zb + 0.2, zb + 0.31, self.plate);
        let r = s.wheel_radius;
        self.axle(x0 + len * 0.18 + 0.2 * k[5], r, hw, 0.23, false);
        self.axle(x0 + len - hood_len * 0.75, r, hw, 0.23, false);
        let xf = x0 + len + EPS;
        let zt = hood_front - 0.1;
        for side in [-1.0, 1.0] {
            let (ya, yb) = (side * hw * 0.5, side * hw * 0.85);
            self.x_plate(xf, ya.min(yb), ya.max(yb), zt - 0.15, zt - 0.02, self.head);
        }
        self.x_plate(xf, -hw * 0.45, hw * 0.45, zt - 0.2, zt - 0.04, self.dark);
        self.x_plate(xf, -hw * 0.85, hw * 0.85, zb + 0.06, zb + 0.22, self.trim);
        self.x_plate(xf + EPS, -0.26, 0.26, zb + 0.22, zb + 0.33, self.plate);
    }

    fn truck(&mut self) {
        let s = self.s;
        let k = s.shape;
        let (len, w, h) = (s.length, s.width, s.height);
        let hw = w / 2.0;
        let x0 = -len / 2.0;
        let x1 = len / 2.0;
        let cab_len = 2.0 + 0.5 * k[0];
        let cab_h = (2.7 + 0.5 * k[1]).min(h);
        let cab_w = hw * 0.98;
        let zb = 0.45;
        let belt = 1.55 + 0.2 * k[2];
        let xc = x1 - cab_len;
        let cabin = Material::new(s.paint, Surface::Paint);
        // Cab: box-like with a slightly raked windshield.
        let secs = vec![
            (xc, Self::body_section(cab_w, zb, belt * 0.6, belt, 0.99)),
            (
                x1 - 0.06,
                Self::body_section(cab_w, zb, belt * 0.6, belt, 0.99),
            ),
            (
                x1,
                Self::body_section(cab_w * 0.97, zb + 0.05, belt * 0.6, belt - 0.05, 0.97),
            ),
        ];
        self.mesh.loft(
            &secs,
            &[self.dark, cabin, cabin, cabin, cabin, cabin],
            Some(cabin),
        );
        let hb = cab_w * 0.99;
        let ht = cab_w * 0.95;
        let rake = 0.15 + 0.15 * k[3];
        let cab_sec = |top: f64| vec![(-hb, belt), (hb, belt), (ht, top), (-ht, top)];
        let csecs = vec![
            (xc, cab_sec(cab_h)),
            (x1 - rake, cab_sec(cab_h)),
            (x1 - 0.04, cab_sec(belt)),
        ];
        self.mesh.loft(&csecs, &[cabin], Some(cabin));
        let p = V3::new;
        let q = [
            p(x1 - 0.04, -hb, belt),
            p(x1 - 0.04, hb, belt),
            p(x1 - rake, ht, cab_h),
            p(x1 - rake, -ht, cab_h),
        ];
        let n = face_normal(&q, V3::new(x1 - 2.0, 0.0, belt));
        self.mesh
            .decal(q, 0.04, 0.96, 0.06, 0.9, n * EPS, self.glass);
        for side in [-1.0, 1.0] {
            let out = V3::new(0.0, side, 0.0) * EPS;
            let q = [
                p(x1 - 0.9, side * hb, belt),
                p(x1 - 0.2, side * hb, belt),
                p(x1 - 0.2, side * ht, cab_h),
                p(x1 - 0.9, side * ht, cab_h),
            ];
            self.mesh.decal(q, 0.05, 0.95, 0.1, 0.8, out, self.glass);
            self.mesh.cuboid(
                V3::new(
                    x1 - 0.3,
                    (side * (hb + 0.05)).min(side * (hb + 0.3)),
                    belt + 0.1,
                ),
                V3::new(
                    x1 - 0.2,
                    (side * (hb + 0.05)).max(side * (hb + 0.3)),
                    belt + 0.7,
                ),
                self.dark,
            );
        }
        // Cargo box or trailer.
        let cargo = Material::new(s.second, Surface::Paint);
        let bx0 = x0 + 0.05;
        let bx1 = xc - 0.35;
        let bz0 = 1.1 + 0.15 * k[4];
        self.mesh
            .cuboid(V3::new(bx0, -hw, bz0), V3::new(bx1, hw, h), cargo);
        self.proxy
            .cuboid(V3::new(bx0, -hw, bz0), V3::new(bx1, hw, h), cargo);
        self.proxy
            .cuboid(V3::new(xc, -cab_w, zb), V3::new(x1, cab_w, cab_h), cargo);
        self.proxy.cuboid(
            V3::new(bx0, -hw * 0.5, 0.5),
            V3::new(xc, hw * 0.5, bz0),
            cargo,
        );
        if s.variant % 3 == 0 {
            let stripe = Material::new(s.paint, Surface::Paint);
            for side in [-1.0, 1.0] {
                self.y_plate(
                    side * (hw + EPS),
                    bx0 + 0.3,
                    bx1 - 0.3,
                    bz0 + 0.5,
                    bz0 + 0.9,
                    stripe,
                );
            }
        }
        // Rear doors outline.
        self.x_plate(bx0 - EPS, -0.02, 0.02, bz0 + 0.05, h - 0.05, self.dark);
        // Chassis.
        self.mesh.cuboid(
            V3::new(x0 + 0.3, -hw * 0.4, 0.6),
            V3::new(x1 - 0.3, hw * 0.4, bz0.min(1.05)),
            self.dark,
        );
        for side in [-1.0, 1.0] {
            let (ya, yb) = (side * hw * 0.7, side * hw * 0.95);
            self.x_plate(x0 - EPS, ya.min(yb), ya.max(yb), 0.75, 0.95, self.tail);
            let (ya, yb) = (side * hw * 0.55, side * hw * 0.9);
            self.x_plate(
                x1 + EPS,
                ya.min(yb),
                ya.max(yb),
                zb + 0.3,
                zb + 0.45,
                self.head,
            );
        }
        self.x_plate(
            x1 + EPS,
            -hw * 0.5,
            hw * 0.5,
            zb + 0.55,
            belt - 0.1,
            self.dark,
        );
        let r = s.wheel_radius;
        self.axle(x1 - 1.2, r, hw * 0.98, 0.3, false);
        let rear = x0 + len * 0.2;
        self.axle(rear, r, hw * 0.98, 0.28, true);
        if len > 9.0 {
            self.axle(rear + 1.35, r, hw * 0.98, 0.28, true);
        }
        if len > 12.5 {
            self.axle(rear - 1.35, r, hw * 0.98, 0.28, true);
            self.axle(x1 - cab_len - 0.5, r, hw * 0.98, 0.28, true);
        }
    }

    fn bus(&mut self) {
        let s = self.s;
        let k = s.shape;
        let (len, w, h) = (s.length, s.width, s.height);
        let hw = w / 2.0;
        let x0 = -len / 2.0;
        let x1 = len / 2.0;
        let zb = 0.3;
        let sec = |hwk: f64, top: f64| {
            vec![
                (-hw * hwk, zb),
                (hw * hwk, zb),
                (hw * hwk, top - 0.3),
                (hw * hwk * 0.9, top),
                (-hw * hwk * 0.9, top),
                (-hw * hwk, top - 0.3),
            ]
        };
        let secs = vec![
            (x0, sec(0.97, h - 0.05)),
            (x0 + 0.15, sec(1.0, h)),
            (x1 - 0.2, sec(1.0, h)),
            (x1, sec(0.96, h - 0.08)),
        ];
        let body = Material::new(s.paint, Surface::Paint);
        self.mesh.loft(
            &secs,
            &[self.trim, body, body, body, body, body],
            Some(body),
        );
        self.proxy
            .cuboid(V3::new(x0, -hw, zb), V3::new(x1, hw, h), body);
        let win_lo = 1.05 + 0.15 * k[0];
        let win_hi = h - 0.35;
        for side in [-1.0, 1.0] {
            let y = side * (hw + EPS);
            // Window band with pillars.
            let xa = x0 + 0.6;
            let xb = x1 - 1.6;
            let n = ((xb - xa) / 1.4).floor().max(1.0) as usize;
            let span = (xb - xa) / n as f64;
            for i in 0..n {
                let a = xa + span * i as f64;
                self.y_plate(y, a + 0.06, a + span - 0.06, win_lo, win_hi, self.glass);
            }
            // Driver / door window at the front.
            self.y_plate(
                y,
                x1 - 1.45,
                x1 - 0.25,
                win_lo - if side < 0.0 { 0.8 } else { 0.0 },
                win_hi,
                self.glass,
            );
            if s.variant % 2 == 0 {
                let stripe = Material::new(s.second, Surface::Paint);
                self.y_plate(y, x0 + 0.2, x1 - 0.2, zb + 0.05, win_lo - 0.35, stripe);
            }
        }
        // Windshield and rear window.
        self.x_plate(x1 + EPS, -hw * 0.88, hw * 0.88, 0.95, h - 0.22, self.glass);
        self.x_plate(
            x0 - EPS,
            -hw * 0.75,
            hw * 0.75,
            win_lo + 0.3,
            h - 0.4,
            self.glass,
        );
        for side in [-1.0, 1.0] {
            let (ya, yb) = (side * hw * 0.6, side * hw * 0.9);
            self.x_plate(
                x1 + EPS,
                ya.min(yb),
                ya.max(yb),
                zb + 0.25,
                zb + 0.4,
                self.head,
            );
            self.x_plate(
                x0 - EPS,
                ya.min(yb),
                ya.max(yb),
                zb + 0.3,
                zb + 0.7,
                self.tail,
            );
        }
        self.x_plate(x1 + 2.0 * EPS, -0.26, 0.26, zb + 0.1, zb + 0.21, self.plate);
        let r = s.wheel_radius;
        self.axle(x1 - 2.6, r, hw, 0.3, false);
        self.axle(x0 + 3.2 + 0.6 * k[1], r, hw, 0.3, true);
    }
}

/// Unit normal of a quad face pointing away from `inside`.
fn face_normal(q: &[V3; 4], inside: V3) -> V3 {
    let c = (q[0] + q[1] + q[2] + q[3]) * 0.25;
    let mut best = V3::default();
    // The quad may be degenerate on one side; use the largest cross product.
    for (a, b) in [(0, 2), (1, 3)] {
        let n = (q[b] - q[a]).cross(q[(a + 1) % 4] - q[a]);
        let n2 = (q[(b + 1) % 4] - q[(a + 1) % 4]).cross(q[(a + 2) % 4] - q[a]);
        for cand in [n, n2] {
            if cand.norm() > best.norm() {
                best = cand;
            }
        }
    }
    let n = best.normalized();
    if n.dot(c - inside) < 0.0 {
        -n
    } else {
        n
    }
}

/// Project the 8 box corners; `None` when any is closer than 1 m to the camera plane.
pub fn project_box(
    cam: &crate::camera::Camera,
    spec: &VehicleSpec,
    pose: &Pose,
) -> Option<[[f64; 2]; 8]> {
    let w = spec.bb3d_world(pose);
    let mut out = [[0.0; 2]; 8];
    for (o, p) in out.iter_mut().zip(w) {
        let c = cam.to_camera(p);
        if c.z < 1.0 {
            return None;
        }
        *o = cam.project_cam(c)?;
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used)]
    use super::*;
    use crate::math::rng_for;

    #[test]
    fn every_class_stays_inside_its_box_except_mirrors() {
        for i in 0..200u64 {
            let mut rng = rng_for(3, &[i]);
            let s = VehicleSpec::random_any(&mut rng);
            let m = s.build();
            assert!(
                m.tris.len() > 60,
                "{:?} has only {} triangles",
                s.kind,
                m.tris.len()
            );
            let (lo, hi) = m.bounds().unwrap();
            let tol = 0.05;
            assert!(
                lo.x >= -s.length / 2.0 - tol && hi.x <= s.length / 2.0 + tol,
                "{:?} x {lo:?} {hi:?}",
                s.kind
            );
            assert!(
                lo.z >= -1e-9 && hi.z <= s.height + tol,
                "{:?} z {lo:?} {hi:?} h {}",
                s.kind,
                s.height
            );
            // Mirrors may stick out sideways by up to ~35 cm.
            assert!(
                lo.y >= -s.width / 2.0 - 0.35 && hi.y <= s.width / 2.0 + 0.35,
                "{:?} y",
                s.kind
            );
            // The body fills the box: it reaches the ground (wheels), the roof and both ends.
            assert!(
                lo.z < 0.01 && hi.z > s.height - 0.1,
                "{:?} z {lo:?} {hi:?}",
                s.kind
            );
            assert!(
                lo.x < -s.length / 2.0 + 0.05 && hi.x > s.length / 2.0 - 0.05,
                "{:?}",
                s.kind
            );
        }
    }
}
