//! Pose helpers: ABB quaternions `[q1, q2, q3, q4]` (q1 scalar), roll-pitch-yaw
//! angles, and the small pose difference used by iterative solvers.

use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};

/// Rotation from an ABB quaternion `[q1, q2, q3, q4]` (q1 is the scalar part).
/// Returns `None` when the norm is zero or not finite. The quaternion is
/// normalised.
pub fn rotation_from_abb(q: [f64; 4]) -> Option<UnitQuaternion<f64>> {
    let quat = Quaternion::new(q[0], q[1], q[2], q[3]);
    let n = quat.norm();
    if !n.is_finite() || n < 1e-12 {
        return None;
    }
    Some(UnitQuaternion::from_quaternion(quat))
}

/// ABB quaternion `[q1, q2, q3, q4]` of a rotation, with `q1 ≥ 0`.
pub fn rotation_to_abb(r: &UnitQuaternion<f64>) -> [f64; 4] {
    let q = r.quaternion();
    let s = if q.w < 0.0 { -1.0 } else { 1.0 };
    [s * q.w, s * q.i, s * q.j, s * q.k]
}

/// Rotation from roll-pitch-yaw in radians: `R = Rz(yaw) Ry(pitch) Rx(roll)`.
pub fn rotation_from_rpy(roll: f64, pitch: f64, yaw: f64) -> UnitQuaternion<f64> {
    UnitQuaternion::from_euler_angles(roll, pitch, yaw)
}

/// Pose from a position (mm) and an ABB quaternion.
pub fn pose_from_abb(pos_mm: [f64; 3], q: [f64; 4]) -> Option<Isometry3<f64>> {
    let r = rotation_from_abb(q)?;
    Some(Isometry3::from_parts(
        Translation3::new(pos_mm[0], pos_mm[1], pos_mm[2]),
        r,
    ))
}

/// Difference `target − actual` of two poses in the frame they are both
/// expressed in: position difference (mm) and rotation vector (rad) of
/// `R_target · R_actualᵀ`.
pub fn pose_error(
    target: &Isometry3<f64>,
    actual: &Isometry3<f64>,
) -> (Vector3<f64>, Vector3<f64>) {
    let dp = target.translation.vector - actual.translation.vector;
    let dr = (target.rotation * actual.rotation.inverse()).scaled_axis();
    (dp, dr)
}
