//! The trial door of the identification (`calibrate`) and diagnosis
//! (`diagnose`) loops: a copy of a [`Robot`] with some parameters set to
//! trial values, in the model's own units, without the checks of a file.
//!
//! A fit's intermediate step may leave the plausible range on its way to
//! the answer, so [`Robot::trial_with_params`] checks nothing; the edge
//! checks the result once: a calibration writes its values into the robot
//! file and reads that file back through the loader (range and
//! plausibility, each error naming its key), and a study that sets values
//! by key uses [`Robot::with_params`]. The nominal (controller) model and
//! its closed-form inverse never change.

use nalgebra::Isometry3;

use super::{DhParams, PointMass, Robot};

/// A trial value of one part of a robot's model, in the model's units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Trial {
    /// The actual (calibrated) DH parameters, mm and rad, in the robot's
    /// own convention.
    Actual(DhParams),
    /// The joint stiffnesses, N·m/rad (the unit of `k_nm_per_rad`).
    JointStiffness([f64; 6]),
    /// The base frame (robot base in the world).
    Base(Isometry3<f64>),
    /// The link masses and centres of mass.
    Links([PointMass; 6]),
}

impl Robot {
    /// The same robot with each trial value of `edits` set, unchecked (see
    /// the module doc); later edits of the same part win. The values of
    /// the robot file (`Robot::param_value`) are unchanged, so
    /// [`Robot::with_params`] on the result starts from the file again.
    pub fn trial_with_params(&self, edits: &[Trial]) -> Robot {
        let mut r = self.clone();
        for edit in edits {
            match *edit {
                Trial::Actual(actual) => r.set_actual(actual),
                Trial::JointStiffness(k) => {
                    r.d.k_nm_per_rad = k;
                    r.d.k_nmm_per_rad = k.map(|k| k * 1000.0);
                }
                Trial::Base(base) => {
                    r.d.base = base;
                    r.d.base_inv = base.inverse();
                }
                Trial::Links(links) => r.d.links = links,
            }
        }
        r
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::machine::robot::Model;

    #[test]
    fn a_trial_sets_what_it_names_and_checks_nothing() {
        let r = crate::machine::robot::test_irb1600();
        let mut dh = *r.params(Model::Nominal);
        dh.joints[1].a_mm += 0.25;
        // A negative stiffness: no file holds it, a fit's step may.
        let k = [-1.0, 2.0, 3.0, 4.0, 5.0, 6.0];
        let t = r.trial_with_params(&[Trial::Actual(dh), Trial::JointStiffness(k)]);
        assert_eq!(t.params(Model::Actual), &dh);
        assert_eq!(t.params(Model::Nominal), r.params(Model::Nominal));
        assert_eq!(t.k_nm_per_rad(), &k);
        let base = Isometry3::translation(1.0, 2.0, 3.0);
        let b = r.trial_with_params(&[Trial::Base(base)]);
        assert_eq!(b.base(), &base);
    }
}
