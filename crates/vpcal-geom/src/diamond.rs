//! The diamond space (Dubská et al.; paper §4, DESIGN.md §4).
//!
//! A point of the projective plane `(x, y, w)` maps to the diamond space with parameter `d` by
//! `(-d²w, -d·x, sgn(xy)·x + y + sgn(y)·d·w)` followed by division by the third coordinate;
//! the image is the closed diamond `|u| + |v| <= d`, and ideal points (w = 0) land on the
//! segment `u = 0`. The inverse is
//! `(u, v, 1) -> (d·v, sgn(u)·d·u + sgn(v)·d·v - d², u)`.
//!
//! # The singular axis
//! With `sgn(0) = 0` the formula divides by zero for every point on the x axis (`y = 0`), and
//! the map is discontinuous there (`y -> 0+` and `y -> 0-` land on opposite sides of the
//! diamond). We define `sgn(y)` for `y = 0` as `+1`, i.e. a point on the x axis maps to its
//! limit from below in the image (`y -> 0+`, y pointing down). With that rule every finite
//! point, including the origin (which lands on the corner `(-d, 0)`), has a finite image.

use crate::point::Point2;

/// `sgn` with `sgn(0) = +1` (see the module docs on the singular axis).
fn sgn_y(y: f64) -> f64 {
    if y < 0.0 {
        -1.0
    } else {
        1.0
    }
}

/// Diamond-space coordinates `(u, v)` of the homogeneous point `(x, y, w)` for parameter `d`.
///
/// Finite points are normalised to `w = 1` first (the formula is not invariant under
/// `(x, y, w) -> -(x, y, w)`). Returns `None` for non-finite input, `d <= 0`, or the null
/// vector.
pub fn point_to_diamond(p: [f64; 3], d: f64) -> Option<Point2> {
    let [mut x, mut y, mut w] = p;
    if !(x.is_finite() && y.is_finite() && w.is_finite() && d > 0.0 && d.is_finite()) {
        return None;
    }
    if w != 0.0 {
        x /= w;
        y /= w;
        w = 1.0;
    } else {
        // Ideal point: only the direction matters; scale to unit length for stability.
        let n = x.hypot(y);
        if n == 0.0 {
            return None;
        }
        x /= n;
        y /= n;
    }
    let s = sgn_y(y);
    // sgn(xy)·x = |x|·sgn(y) for x != 0, and 0 for x = 0.
    let third = x.abs() * s + y + s * d * w;
    let u = -d * d * w / third;
    let v = -d * x / third;
    let out = Point2::new(u, v);
    out.is_finite().then_some(out)
}

/// Diamond coordinates of a finite point.
pub fn point_to_diamond_2d(p: Point2, d: f64) -> Option<Point2> {
    point_to_diamond([p.x, p.y, 1.0], d)
}

/// The homogeneous point `(x, y, w)` of diamond coordinates `(u, v)` for parameter `d`.
/// `w = 0` (an ideal point) where `u = 0`.
pub fn diamond_to_point(uv: Point2, d: f64) -> [f64; 3] {
    let Point2 { x: u, y: v } = uv;
    let sgn = |t: f64| {
        if t > 0.0 {
            1.0
        } else if t < 0.0 {
            -1.0
        } else {
            0.0
        }
    };
    [d * v, sgn(u) * d * u + sgn(v) * d * v - d * d, u]
}

/// The finite point of diamond coordinates `(u, v)`, or `None` when it is an ideal point.
pub fn diamond_to_point_2d(uv: Point2, d: f64) -> Option<Point2> {
    Point2::from_h(diamond_to_point(uv, d))
}
