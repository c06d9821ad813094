//! Copies of a [`Robot`] with some calibrated quantities replaced: the
//! identification (`calibrate`) and diagnosis (`diagnose`) loops evaluate
//! the forward model for trial parameter values this way. The nominal
//! (controller) model and its closed-form inverse never change.

use nalgebra::Isometry3;

use super::{DhParams, PointMass, Robot};

impl Robot {
    /// The same robot with other actual (calibrated) DH parameters. The
    /// convention must be the robot's own; the nominal model is unchanged.
    pub fn with_actual(&self, actual: DhParams) -> Robot {
        let mut r = self.clone();
        r.set_actual(actual);
        r
    }

    /// The same robot with other joint stiffnesses, N·m/rad (the unit of
    /// the file's `k_nm_per_rad`).
    pub fn with_stiffness(&self, k_nm_per_rad: [f64; 6]) -> Robot {
        let mut r = self.clone();
        r.d.k_nm_per_rad = k_nm_per_rad;
        r.d.k_nmm_per_rad = k_nm_per_rad.map(|k| k * 1000.0);
        r
    }

    /// The same robot with another base frame (robot base in the world).
    pub fn with_base(&self, base: Isometry3<f64>) -> Robot {
        let mut r = self.clone();
        r.d.base = base;
        r.d.base_inv = base.inverse();
        r
    }

    /// The same robot with other link masses and centres of mass.
    pub fn with_links(&self, links: [PointMass; 6]) -> Robot {
        let mut r = self.clone();
        r.d.links = links;
        r
    }
}
