//! Z-Y-X Euler angles, the orientation of KUKA's `A, B, C` and FANUC's
//! `W, P, R`.
//!
//! Both makers write a frame's rotation as three angles in degrees turned
//! about the axes of the reference frame, x first: KUKA's
//! `R = Rz(A)·Ry(B)·Rx(C)` (KUKA System Software, "A, B, C: rotation about
//! Z, Y, X") and FANUC's `R = Rz(R)·Ry(P)·Rx(W)` (W yaw about x, P pitch
//! about y, R roll about z of the user frame). So FANUC's `(W, P, R)` is
//! KUKA's `(C, B, A)`; grammar/krl.md and grammar/tp.md cite the sources.
//!
//! Back from a rotation the angles are made unique as both controllers
//! show them: the middle angle in [−90°, 90°], the others in (−180°, 180°];
//! at the middle angle ±90° (gimbal lock) the first turn (x) is 0 and the
//! whole rotation about z goes to the last angle.

use nalgebra::{Rotation3, UnitQuaternion};

/// Below this cosine of the middle angle the rotation is taken as gimbal
/// locked (about 2e-6°).
const GIMBAL_COS: f64 = 1e-10;

/// The rotation `Rz(z)·Ry(y)·Rx(x)`, angles in degrees.
pub fn zyx_to_quaternion(z_deg: f64, y_deg: f64, x_deg: f64) -> UnitQuaternion<f64> {
    UnitQuaternion::from_euler_angles(x_deg.to_radians(), y_deg.to_radians(), z_deg.to_radians())
}

/// The angles `(z, y, x)` in degrees of `R = Rz(z)·Ry(y)·Rx(x)`, made
/// unique as the module documentation says.
pub fn quaternion_to_zyx(q: &UnitQuaternion<f64>) -> (f64, f64, f64) {
    let m = q.to_rotation_matrix();
    matrix_to_zyx(&m)
}

/// [`quaternion_to_zyx`] of a rotation matrix.
pub fn matrix_to_zyx(m: &Rotation3<f64>) -> (f64, f64, f64) {
    let r = m.matrix();
    // r20 = −sin(y); r00 = cos(y)cos(z), r10 = cos(y)sin(z);
    // r21 = cos(y)sin(x), r22 = cos(y)cos(x).
    let sy = (-r[(2, 0)]).clamp(-1.0, 1.0);
    let cy = r[(0, 0)].hypot(r[(1, 0)]);
    let (z, y, x) = if cy > GIMBAL_COS {
        (
            r[(1, 0)].atan2(r[(0, 0)]),
            sy.atan2(cy),
            r[(2, 1)].atan2(r[(2, 2)]),
        )
    } else {
        // y = ±90°: r01 = −sin(z ∓ x)…; with x = 0, r11 = cos(z), r01 = −sin(z).
        (
            (-r[(0, 1)]).atan2(r[(1, 1)]),
            sy.signum() * 90f64.to_radians(),
            0.0,
        )
    };
    (
        half_open(z.to_degrees()),
        y.to_degrees(),
        half_open(x.to_degrees()),
    )
}

/// An angle in degrees brought into (−180°, 180°].
fn half_open(a: f64) -> f64 {
    if a <= -180.0 { a + 360.0 } else { a }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Agreement of matrix entries, (rounding only).
    const ENTRY_TOL: f64 = 1e-12;
    /// Agreement of angles, degrees.
    const ANGLE_TOL_DEG: f64 = 1e-9;

    /// `Rz(z)·Ry(y)·Rx(x)` written out entry by entry (the product of the
    /// three elementary rotations, multiplied by hand).
    fn by_hand(z: f64, y: f64, x: f64) -> [[f64; 3]; 3] {
        let (sz, cz) = z.to_radians().sin_cos();
        let (sy, cy) = y.to_radians().sin_cos();
        let (sx, cx) = x.to_radians().sin_cos();
        [
            [cz * cy, cz * sy * sx - sz * cx, cz * sy * cx + sz * sx],
            [sz * cy, sz * sy * sx + cz * cx, sz * sy * cx - cz * sx],
            [-sy, cy * sx, cy * cx],
        ]
    }

    #[test]
    fn the_rotation_is_z_then_y_then_x_of_the_reference_frame() {
        for (z, y, x) in [
            (30.0, 45.0, 60.0),
            (-170.0, 10.0, 95.0),
            (0.0, -89.0, 180.0),
        ] {
            let m = zyx_to_quaternion(z, y, x).to_rotation_matrix();
            let want = by_hand(z, y, x);
            for (i, row) in want.iter().enumerate() {
                for (j, w) in row.iter().enumerate() {
                    assert!((m[(i, j)] - w).abs() <= ENTRY_TOL, "{z} {y} {x} [{i},{j}]");
                }
            }
        }
        // A = 90°: the x axis of the frame turns onto the reference y axis.
        let q = zyx_to_quaternion(90.0, 0.0, 0.0);
        assert!((q * nalgebra::Vector3::x() - nalgebra::Vector3::y()).norm() <= ENTRY_TOL);
    }

    #[test]
    fn angles_come_back_unique() {
        for (z, y, x) in [
            (30.0, 45.0, 60.0),
            (-170.0, 10.0, 95.0),
            (180.0, 0.0, -179.5),
        ] {
            let (a, b, c) = quaternion_to_zyx(&zyx_to_quaternion(z, y, x));
            assert!((a - z).abs() <= ANGLE_TOL_DEG, "{a} {z}");
            assert!((b - y).abs() <= ANGLE_TOL_DEG, "{b} {y}");
            assert!((c - x).abs() <= ANGLE_TOL_DEG, "{c} {x}");
        }
        // The same rotation written with B beyond 90°: (A+180, 180−B, C+180).
        let (a, b, c) = quaternion_to_zyx(&zyx_to_quaternion(10.0, 120.0, 20.0));
        assert!((a - -170.0).abs() <= ANGLE_TOL_DEG && (b - 60.0).abs() <= ANGLE_TOL_DEG);
        assert!((c - -160.0).abs() <= ANGLE_TOL_DEG);
        // Gimbal lock: B = 90°, the z turn holds A − C.
        let (a, b, c) = quaternion_to_zyx(&zyx_to_quaternion(50.0, 90.0, 20.0));
        assert!((b - 90.0).abs() <= 1e-6 && c == 0.0);
        assert!((a - 30.0).abs() <= 1e-6, "{a}");
    }
}
