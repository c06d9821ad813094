//! Homogeneous transformation helpers (4×4, f64) for the kinematic chain:
//! translations, finite rotations about a coordinate axis and the
//! small-angle error HTM of docs/physics.md.

use nalgebra::{Matrix4, Vector3};

/// Pure translation by `v` (mm).
pub fn translation(v: &Vector3<f64>) -> Matrix4<f64> {
    let mut m = Matrix4::identity();
    m[(0, 3)] = v.x;
    m[(1, 3)] = v.y;
    m[(2, 3)] = v.z;
    m
}

/// Right-handed rotation by `angle` (rad) about coordinate axis `axis`
/// (0 = x, 1 = y, 2 = z; any other value gives the identity).
pub fn rotation(axis: usize, angle: f64) -> Matrix4<f64> {
    let (s, c) = angle.sin_cos();
    let mut m = Matrix4::identity();
    let (i, j) = match axis {
        0 => (1, 2),
        1 => (2, 0),
        2 => (0, 1),
        _ => return m,
    };
    m[(i, i)] = c;
    m[(i, j)] = -s;
    m[(j, i)] = s;
    m[(j, j)] = c;
    m
}

/// Derivative of [`rotation`] with respect to the angle (per rad).
pub fn d_rotation(axis: usize, angle: f64) -> Matrix4<f64> {
    let (s, c) = angle.sin_cos();
    let mut m = Matrix4::zeros();
    let (i, j) = match axis {
        0 => (1, 2),
        1 => (2, 0),
        2 => (0, 1),
        _ => return m,
    };
    m[(i, i)] = -s;
    m[(i, j)] = -c;
    m[(j, i)] = c;
    m[(j, j)] = -s;
    m
}

/// Small-angle error HTM with translation `d` (mm) and rotations `e` =
/// (εa, εb, εc) about x, y, z (rad):
/// `[[1, −εc, εb, δx], [εc, 1, −εa, δy], [−εb, εa, 1, δz], [0, 0, 0, 1]]`.
pub fn small_angle(d: &Vector3<f64>, e: &Vector3<f64>) -> Matrix4<f64> {
    Matrix4::new(
        1.0, -e.z, e.y, d.x, //
        e.z, 1.0, -e.x, d.y, //
        -e.y, e.x, 1.0, d.z, //
        0.0, 0.0, 0.0, 1.0,
    )
}

/// Derivative of [`small_angle`] when `d` and `e` change at rates `dd`, `de`
/// (the identity part drops out).
pub fn d_small_angle(dd: &Vector3<f64>, de: &Vector3<f64>) -> Matrix4<f64> {
    let mut m = small_angle(dd, de);
    m[(0, 0)] = 0.0;
    m[(1, 1)] = 0.0;
    m[(2, 2)] = 0.0;
    m[(3, 3)] = 0.0;
    m
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;

    const TOL: f64 = 1e-12;

    #[test]
    fn rotations_are_right_handed() {
        // +90° about z maps x̂ to ŷ; about x maps ŷ to ẑ; about y maps ẑ to x̂.
        let h = std::f64::consts::FRAC_PI_2;
        let v = rotation(2, h) * nalgebra::Vector4::new(1.0, 0.0, 0.0, 0.0);
        assert_abs_diff_eq!(v.y, 1.0, epsilon = TOL);
        let v = rotation(0, h) * nalgebra::Vector4::new(0.0, 1.0, 0.0, 0.0);
        assert_abs_diff_eq!(v.z, 1.0, epsilon = TOL);
        let v = rotation(1, h) * nalgebra::Vector4::new(0.0, 0.0, 1.0, 0.0);
        assert_abs_diff_eq!(v.x, 1.0, epsilon = TOL);
    }

    #[test]
    fn d_rotation_matches_finite_difference() {
        const H: f64 = 1e-6;
        const FD_TOL: f64 = 1e-8;
        for axis in 0..3 {
            let a = 0.7;
            let fd = (rotation(axis, a + H) - rotation(axis, a - H)) / (2.0 * H);
            assert_abs_diff_eq!(d_rotation(axis, a), fd, epsilon = FD_TOL);
        }
    }
}
