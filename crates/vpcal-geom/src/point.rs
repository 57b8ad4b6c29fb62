//! Points, homogeneous coordinates, lines and vehicle boxes.

use std::ops::{Add, Div, Mul, Neg, Sub};

/// A 2D point or vector, f64. Its space (frame pixels, box frame, crop pixels) is named by the
/// variable that holds it (`vp_in_frame`, `vp_in_box`, ...).
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize, serde::Deserialize)]
pub struct Point2 {
    pub x: f64,
    pub y: f64,
}

/// `(x, y)` with the precision asked for (default 2 decimals), for messages.
impl std::fmt::Display for Point2 {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let p = f.precision().unwrap_or(2);
        write!(f, "({:.p$}, {:.p$})", self.x, self.y)
    }
}

impl Point2 {
    pub const fn new(x: f64, y: f64) -> Point2 {
        Point2 { x, y }
    }

    pub fn dot(self, other: Point2) -> f64 {
        self.x * other.x + self.y * other.y
    }

    pub fn norm(self) -> f64 {
        self.x.hypot(self.y)
    }

    /// True when both coordinates are finite.
    pub fn is_finite(self) -> bool {
        self.x.is_finite() && self.y.is_finite()
    }

    /// Homogeneous coordinates (x, y, 1).
    pub fn to_h(self) -> [f64; 3] {
        [self.x, self.y, 1.0]
    }

    /// The point of homogeneous coordinates `h`, or `None` for an ideal point (w = 0) or
    /// non-finite input.
    pub fn from_h(h: [f64; 3]) -> Option<Point2> {
        let p = Point2::new(h[0] / h[2], h[1] / h[2]);
        (h[2] != 0.0 && p.is_finite()).then_some(p)
    }

    pub fn as_array(self) -> [f64; 2] {
        [self.x, self.y]
    }
}

impl From<[f64; 2]> for Point2 {
    fn from(a: [f64; 2]) -> Point2 {
        Point2::new(a[0], a[1])
    }
}

impl From<Point2> for [f64; 2] {
    fn from(p: Point2) -> [f64; 2] {
        [p.x, p.y]
    }
}

impl Add for Point2 {
    type Output = Point2;
    fn add(self, o: Point2) -> Point2 {
        Point2::new(self.x + o.x, self.y + o.y)
    }
}

impl Sub for Point2 {
    type Output = Point2;
    fn sub(self, o: Point2) -> Point2 {
        Point2::new(self.x - o.x, self.y - o.y)
    }
}

impl Mul<f64> for Point2 {
    type Output = Point2;
    fn mul(self, s: f64) -> Point2 {
        Point2::new(self.x * s, self.y * s)
    }
}

impl Div<f64> for Point2 {
    type Output = Point2;
    fn div(self, s: f64) -> Point2 {
        Point2::new(self.x / s, self.y / s)
    }
}

impl Neg for Point2 {
    type Output = Point2;
    fn neg(self) -> Point2 {
        Point2::new(-self.x, -self.y)
    }
}

/// Cross product of two 3-vectors (homogeneous join of points / meet of lines).
pub fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// Dot product of two 3-vectors.
pub fn dot3(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// `v / |v|`, or `None` for a zero or non-finite vector.
pub fn normalize3(v: [f64; 3]) -> Option<[f64; 3]> {
    let n = dot3(v, v).sqrt();
    (n > 0.0 && n.is_finite()).then(|| [v[0] / n, v[1] / n, v[2] / n])
}

/// A line `a x + b y + c = 0` in homogeneous form.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Line(pub [f64; 3]);

impl Line {
    /// The line through two distinct finite points, or `None` when they coincide.
    pub fn through(p: Point2, q: Point2) -> Option<Line> {
        let l = cross(p.to_h(), q.to_h());
        (l[0] != 0.0 || l[1] != 0.0)
            .then_some(Line(l))
            .filter(Line::is_finite)
    }

    /// The line through a finite point `p` with direction `dir` (non-zero).
    pub fn through_with_direction(p: Point2, dir: Point2) -> Option<Line> {
        Line::through(p, p + dir)
    }

    /// The line `y = slope * x + intercept`.
    pub fn from_slope_intercept(slope: f64, intercept: f64) -> Line {
        Line([slope, -1.0, intercept])
    }

    fn is_finite(&self) -> bool {
        self.0.iter().all(|v| v.is_finite())
    }

    /// The same line scaled so that `a² + b² = 1`, or `None` for the line at infinity.
    pub fn normalized(self) -> Option<Line> {
        let n = self.0[0].hypot(self.0[1]);
        (n > 0.0 && n.is_finite()).then(|| Line([self.0[0] / n, self.0[1] / n, self.0[2] / n]))
    }

    /// Signed distance of `p` from the line (positive on the side the normal (a, b) points to).
    pub fn signed_distance(self, p: Point2) -> Option<f64> {
        let l = self.normalized()?;
        Some(l.0[0] * p.x + l.0[1] * p.y + l.0[2])
    }

    /// Orthogonal projection of `p` onto the line.
    pub fn project(self, p: Point2) -> Option<Point2> {
        let l = self.normalized()?;
        let d = l.0[0] * p.x + l.0[1] * p.y + l.0[2];
        Some(Point2::new(p.x - d * l.0[0], p.y - d * l.0[1]))
    }

    /// Intersection with another line; `None` when parallel (meet at infinity).
    pub fn intersect(self, other: Line) -> Option<Point2> {
        Point2::from_h(cross(self.0, other.0))
    }

    /// Angle of the line's direction against the image x axis, radians in (-pi/2, pi/2].
    pub fn angle(self) -> f64 {
        let a = (-self.0[0]).atan2(self.0[1]);
        if a > std::f64::consts::FRAC_PI_2 {
            a - std::f64::consts::PI
        } else if a <= -std::f64::consts::FRAC_PI_2 {
            a + std::f64::consts::PI
        } else {
            a
        }
    }

    /// `y` of the line at `x`, or `None` for a vertical line.
    pub fn y_at(self, x: f64) -> Option<f64> {
        let [a, b, c] = self.0;
        let y = -(a * x + c) / b;
        (b != 0.0 && y.is_finite()).then_some(y)
    }
}

/// An axis-aligned vehicle box in frame pixels (continuous coordinates, x right, y down).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct BoxPx {
    pub x0: f64,
    pub y0: f64,
    pub x1: f64,
    pub y1: f64,
}

impl BoxPx {
    pub const fn new(x0: f64, y0: f64, x1: f64, y1: f64) -> BoxPx {
        BoxPx { x0, y0, x1, y1 }
    }

    pub fn center(&self) -> Point2 {
        Point2::new((self.x0 + self.x1) / 2.0, (self.y0 + self.y1) / 2.0)
    }

    /// Half width and half height (hw, hh).
    pub fn half_size(&self) -> Point2 {
        Point2::new((self.x1 - self.x0) / 2.0, (self.y1 - self.y0) / 2.0)
    }

    pub fn width(&self) -> f64 {
        self.x1 - self.x0
    }

    pub fn height(&self) -> f64 {
        self.y1 - self.y0
    }

    /// True when the box keeps at least `margin` pixels from every edge of a `width × height`
    /// picture: a box nearer an edge is cut by it, and its centre and size are not the
    /// vehicle's.
    pub fn clear_of_edges(&self, width: f64, height: f64, margin: f64) -> bool {
        self.x0 >= margin
            && self.y0 >= margin
            && self.x1 <= width - margin
            && self.y1 <= height - margin
    }

    /// True when the box has positive finite width and height.
    pub fn is_valid(&self) -> bool {
        [self.x0, self.y0, self.x1, self.y1]
            .iter()
            .all(|v| v.is_finite())
            && self.x1 > self.x0
            && self.y1 > self.y0
    }

    /// A frame point expressed in the box frame: `((vx - cx)/hw, (vy - cy)/hh)`.
    ///
    /// The box frame is anisotropic because the crop is resized to a square: the box spans
    /// [-1, 1] on both axes.
    pub fn vp_in_box(&self, vp_in_frame: Point2) -> Point2 {
        let c = self.center();
        let h = self.half_size();
        Point2::new((vp_in_frame.x - c.x) / h.x, (vp_in_frame.y - c.y) / h.y)
    }

    /// The inverse of [`BoxPx::vp_in_box`]: a box-frame point in frame pixels.
    pub fn frame_from_box(&self, vp_in_box: Point2) -> Point2 {
        let c = self.center();
        let h = self.half_size();
        Point2::new(vp_in_box.x * h.x + c.x, vp_in_box.y * h.y + c.y)
    }

    /// Intersection-over-union with another box (0 when either is empty).
    pub fn iou(&self, other: &BoxPx) -> f64 {
        let w = (self.x1.min(other.x1) - self.x0.max(other.x0)).max(0.0);
        let h = (self.y1.min(other.y1) - self.y0.max(other.y0)).max(0.0);
        let inter = w * h;
        let union = self.width() * self.height() + other.width() * other.height() - inter;
        if union > 0.0 {
            inter / union
        } else {
            0.0
        }
    }
}
