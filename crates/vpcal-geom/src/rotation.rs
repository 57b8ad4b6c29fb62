//! Rotation matrices and rotation vectors (axis times angle, OpenCV's `rvec`).

/// A 3x3 matrix, row-major.
pub type Mat3 = [[f64; 3]; 3];

/// The rotation vector (axis × angle in radians, angle in [0, π]) of rotation matrix `r`.
///
/// Goes through the unit quaternion (Shepperd's choice of the largest component), which
/// stays accurate near angles 0 and π where the axis-from-skew-part formula loses digits.
pub fn rotation_vector(r: &Mat3) -> [f64; 3] {
    let trace = r[0][0] + r[1][1] + r[2][2];
    // q = (w, x, y, z), computed from its largest component.
    let q = if trace > r[0][0].max(r[1][1]).max(r[2][2]) {
        let s = (1.0 + trace).max(0.0).sqrt() * 2.0;
        [
            0.25 * s,
            (r[2][1] - r[1][2]) / s,
            (r[0][2] - r[2][0]) / s,
            (r[1][0] - r[0][1]) / s,
        ]
    } else if r[0][0] >= r[1][1] && r[0][0] >= r[2][2] {
        let s = (1.0 + r[0][0] - r[1][1] - r[2][2]).max(0.0).sqrt() * 2.0;
        [
            (r[2][1] - r[1][2]) / s,
            0.25 * s,
            (r[0][1] + r[1][0]) / s,
            (r[0][2] + r[2][0]) / s,
        ]
    } else if r[1][1] >= r[2][2] {
        let s = (1.0 + r[1][1] - r[0][0] - r[2][2]).max(0.0).sqrt() * 2.0;
        [
            (r[0][2] - r[2][0]) / s,
            (r[0][1] + r[1][0]) / s,
            0.25 * s,
            (r[1][2] + r[2][1]) / s,
        ]
    } else {
        let s = (1.0 + r[2][2] - r[0][0] - r[1][1]).max(0.0).sqrt() * 2.0;
        [
            (r[1][0] - r[0][1]) / s,
            (r[0][2] + r[2][0]) / s,
            (r[1][2] + r[2][1]) / s,
            0.25 * s,
        ]
    };
    // The same rotation with w >= 0 has its angle in [0, π].
    let sign = if q[0] < 0.0 { -1.0 } else { 1.0 };
    let (w, v) = (sign * q[0], [sign * q[1], sign * q[2], sign * q[3]]);
    let sin_half = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    if sin_half == 0.0 {
        return [0.0; 3];
    }
    let angle = 2.0 * sin_half.atan2(w);
    [
        v[0] / sin_half * angle,
        v[1] / sin_half * angle,
        v[2] / sin_half * angle,
    ]
}

/// The rotation matrix of rotation vector `rvec` (Rodrigues' formula).
pub fn rotation_matrix(rvec: [f64; 3]) -> Mat3 {
    let angle = (rvec[0] * rvec[0] + rvec[1] * rvec[1] + rvec[2] * rvec[2]).sqrt();
    if angle == 0.0 {
        return [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    }
    let [x, y, z] = [rvec[0] / angle, rvec[1] / angle, rvec[2] / angle];
    let (s, c) = angle.sin_cos();
    let t = 1.0 - c;
    [
        [t * x * x + c, t * x * y - s * z, t * x * z + s * y],
        [t * x * y + s * z, t * y * y + c, t * y * z - s * x],
        [t * x * z - s * y, t * y * z + s * x, t * z * z + c],
    ]
}

/// `m · v`.
pub fn mat_vec(m: &Mat3, v: [f64; 3]) -> [f64; 3] {
    [
        m[0][0] * v[0] + m[0][1] * v[1] + m[0][2] * v[2],
        m[1][0] * v[0] + m[1][1] * v[1] + m[1][2] * v[2],
        m[2][0] * v[0] + m[2][1] * v[1] + m[2][2] * v[2],
    ]
}

/// `mᵀ · v`.
pub fn mat_t_vec(m: &Mat3, v: [f64; 3]) -> [f64; 3] {
    [
        m[0][0] * v[0] + m[1][0] * v[1] + m[2][0] * v[2],
        m[0][1] * v[0] + m[1][1] * v[1] + m[2][1] * v[2],
        m[0][2] * v[0] + m[1][2] * v[1] + m[2][2] * v[2],
    ]
}

/// The inverse of `m` (adjugate over determinant); `None` when `m` is singular.
pub fn inverse3(m: &Mat3) -> Option<Mat3> {
    let c =
        |r0: usize, c0: usize, r1: usize, c1: usize| m[r0][c0] * m[r1][c1] - m[r0][c1] * m[r1][c0];
    let adj = [
        [c(1, 1, 2, 2), -c(0, 1, 2, 2), c(0, 1, 1, 2)],
        [-c(1, 0, 2, 2), c(0, 0, 2, 2), -c(0, 0, 1, 2)],
        [c(1, 0, 2, 1), -c(0, 0, 2, 1), c(0, 0, 1, 1)],
    ];
    let det = m[0][0] * adj[0][0] + m[0][1] * adj[1][0] + m[0][2] * adj[2][0];
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    Some(adj.map(|row| row.map(|v| v / det)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn max_diff(a: &Mat3, b: &Mat3) -> f64 {
        let mut d: f64 = 0.0;
        for i in 0..3 {
            for j in 0..3 {
                d = d.max((a[i][j] - b[i][j]).abs());
            }
        }
        d
    }

    #[test]
    fn known_rotations() {
        let quarter_z = [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]];
        let v = rotation_vector(&quarter_z);
        assert!((v[2] - std::f64::consts::FRAC_PI_2).abs() < 1e-15 && v[0] == 0.0);
        let half_x = [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]];
        let v = rotation_vector(&half_x);
        assert!((v[0].abs() - std::f64::consts::PI).abs() < 1e-15, "{v:?}");
        assert_eq!(rotation_vector(&rotation_matrix([0.0; 3])), [0.0; 3]);
    }

    proptest! {
        #[test]
        fn vector_and_matrix_round_trip(
            x in -1.0f64..1.0, y in -1.0f64..1.0, z in -1.0f64..1.0, angle in 0.0f64..(std::f64::consts::PI - 1e-6),
        ) {
            let n = (x * x + y * y + z * z).sqrt();
            prop_assume!(n > 1e-3);
            let rvec = [x / n * angle, y / n * angle, z / n * angle];
            let m = rotation_matrix(rvec);
            let back = rotation_vector(&m);
            prop_assert!(max_diff(&rotation_matrix(back), &m) < 1e-12);
            for i in 0..3 {
                prop_assert!((back[i] - rvec[i]).abs() < 1e-9, "{:?} vs {:?}", back, rvec);
            }
            // Orthonormal: mᵀ m v = v.
            let v = [0.3, -1.2, 2.0];
            let w = mat_t_vec(&m, mat_vec(&m, v));
            for i in 0..3 {
                prop_assert!((w[i] - v[i]).abs() < 1e-12);
            }
        }
    }
}
