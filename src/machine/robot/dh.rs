//! Denavit–Hartenberg link transforms, classic (distal) and modified (Craig,
//! proximal) conventions. Internal units: mm and rad.
//!
//! - Classic DH, joint `i` (1-based): `T_{i-1,i} = Rz(θi) Tz(di) Tx(ai) Rx(αi)`;
//!   joint `i` turns about the z axis of frame `i-1`.
//! - Modified DH (Craig): `T_{i-1,i} = Rx(α_{i-1}) Tx(a_{i-1}) Rz(θi) Tz(di)`;
//!   joint `i` turns about the z axis of frame `i`. In a machine file the row
//!   of joint `i` carries `a_{i-1}` and `α_{i-1}`.
//!
//! In both, `θi = qi + theta_offset_i` and frame `i` is fixed to link `i`;
//! frame 6 is the flange.

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

/// Which DH variant a parameter set uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Convention {
    /// Classic (distal) Denavit–Hartenberg.
    Dh,
    /// Modified (proximal, Craig) Denavit–Hartenberg.
    ModifiedDh,
}

/// The four parameters of one joint row (mm, rad).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DhJoint {
    /// Link length `a` (classic: `a_i`; modified: `a_{i-1}`), mm.
    pub a_mm: f64,
    /// Link twist `α` (classic: `α_i`; modified: `α_{i-1}`), rad.
    pub alpha_rad: f64,
    /// Link offset `d_i`, mm.
    pub d_mm: f64,
    /// Constant added to the joint value: `θi = qi + offset`, rad.
    pub theta_offset_rad: f64,
}

/// A full 6-joint parameter set in one convention.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DhParams {
    /// The convention the rows follow.
    pub convention: Convention,
    /// Rows of joints 1..6.
    pub joints: [DhJoint; 6],
}

fn rot_x(a: f64) -> UnitQuaternion<f64> {
    UnitQuaternion::from_axis_angle(&Vector3::x_axis(), a)
}

fn rot_z(a: f64) -> UnitQuaternion<f64> {
    UnitQuaternion::from_axis_angle(&Vector3::z_axis(), a)
}

fn tr(x: f64, y: f64, z: f64) -> Isometry3<f64> {
    Isometry3::from_parts(Translation3::new(x, y, z), UnitQuaternion::identity())
}

fn rot(r: UnitQuaternion<f64>) -> Isometry3<f64> {
    Isometry3::from_parts(Translation3::identity(), r)
}

impl DhJoint {
    /// Transform from frame `i-1` to frame `i` for joint value `q` (rad).
    pub fn transform(&self, convention: Convention, q: f64) -> Isometry3<f64> {
        let theta = q + self.theta_offset_rad;
        match convention {
            Convention::Dh => {
                rot(rot_z(theta)) * tr(self.a_mm, 0.0, self.d_mm) * rot(rot_x(self.alpha_rad))
            }
            Convention::ModifiedDh => {
                rot(rot_x(self.alpha_rad))
                    * tr(self.a_mm, 0.0, 0.0)
                    * rot(rot_z(theta))
                    * tr(0.0, 0.0, self.d_mm)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;

    const TOL: f64 = 1e-12;

    #[test]
    fn classic_and_modified_rows_match_hand_products() {
        // a=10, α=90°, d=5, θ=90°: classic = Rz(90) Tz(5) Tx(10) Rx(90):
        // origin = Rz(90)(10,0,5) = (0,10,5); z axis = Rz(90) Rx(90) ez
        // = Rz(90)(0,-1,0) = (1,0,0).
        let j = DhJoint {
            a_mm: 10.0,
            alpha_rad: std::f64::consts::FRAC_PI_2,
            d_mm: 5.0,
            theta_offset_rad: 0.0,
        };
        let t = j.transform(Convention::Dh, std::f64::consts::FRAC_PI_2);
        assert_abs_diff_eq!(
            t.translation.vector,
            Vector3::new(0.0, 10.0, 5.0),
            epsilon = TOL
        );
        assert_abs_diff_eq!(t.rotation * Vector3::z(), Vector3::x(), epsilon = TOL);
        // modified = Rx(90) Tx(10) Rz(90) Tz(5): origin = (10,0,0) + Rx(90)(0,0,5)
        // = (10,-5,0); z axis = Rx(90) ez = (0,-1,0).
        let m = j.transform(Convention::ModifiedDh, std::f64::consts::FRAC_PI_2);
        assert_abs_diff_eq!(
            m.translation.vector,
            Vector3::new(10.0, -5.0, 0.0),
            epsilon = TOL
        );
        assert_abs_diff_eq!(m.rotation * Vector3::z(), -Vector3::y(), epsilon = TOL);
    }
}
