//! Joint-stiffness statics: joint torques of a wrench at a point
//! (`τ = J_Pᵀ W`), gravity torques of the links and the tool load, joint
//! deflection `Δθ = Kθ⁻¹ τ` and the small-deflection displacement of any
//! flange point `Δx = J_P Kθ⁻¹ τ`. Units: N, N·mm, mm, rad, kg, m/s².
//! All vectors are in the robot base frame unless stated.

use nalgebra::{Isometry3, Vector3, Vector6};

use super::dh::DhParams;
use super::kinematics::{Frames, flange, frames, jacobian};
use super::{Model, Robot};
use crate::process::Wrench;

impl Robot {
    /// Joint torques (N·mm) of a wrench `[F (N); M (N·mm)]`, robot base
    /// frame, acting at a point given in the flange frame: `τ = J_Pᵀ W`.
    pub fn wrench_torques(
        &self,
        model: Model,
        q: &[f64; 6],
        point_in_flange: &Vector3<f64>,
        wrench: &Vector6<f64>,
    ) -> Vector6<f64> {
        let f = self.frames(model, q);
        jacobian(&f, point_in_flange).transpose() * wrench
    }

    /// Gravity in the robot base frame, m/s².
    fn gravity_base(&self) -> Vector3<f64> {
        self.base().rotation.inverse() * self.gravity_m_per_s2()
    }

    /// Joint torques (N·mm) from the weight of the links and of the tool load.
    pub fn gravity_torques(&self, model: Model, q: &[f64; 6]) -> Vector6<f64> {
        self.gravity_torques_of(self.params(model), q)
    }

    /// [`Robot::gravity_torques`] for any parameter set.
    pub fn gravity_torques_of(&self, params: &DhParams, q: &[f64; 6]) -> Vector6<f64> {
        self.gravity_torques_at(&frames(params, q))
    }

    /// [`Robot::gravity_torques`] from joint frames already computed (the
    /// prediction shares one set of frames between gravity and process).
    ///
    /// One backward recursion over the links (O(n), no Jacobian):
    /// `τ_i = z_i · Σ_{j≥i} (c_j − o_i) × m_j g = z_i · (M_i − o_i × F_i)`
    /// with `F_i = Σ_{j≥i} m_j g` and `M_i = Σ_{j≥i} c_j × m_j g`
    /// (`c_j`: centre of mass of link `j`, the tool load counted with the
    /// flange; `o_i`, `z_i`: a point on and the direction of axis `i`).
    pub(crate) fn gravity_torques_at(&self, f: &Frames) -> Vector6<f64> {
        let g = self.gravity_base();
        let mut force = Vector3::zeros();
        let mut moment = Vector3::zeros();
        let mut tau = Vector6::zeros();
        let links = self.links();
        for i in (0..6).rev() {
            if i == 5 {
                if let Some(l) = self.tool_load() {
                    let c = f.link[5] * nalgebra::Point3::from(l.com_mm);
                    let w = g * l.mass_kg;
                    force += w;
                    moment += c.coords.cross(&w);
                }
            }
            let l = &links[i];
            let c = f.link[i] * nalgebra::Point3::from(l.com_mm);
            let w = g * l.mass_kg;
            force += w;
            moment += c.coords.cross(&w);
            tau[i] = f.axis_dir[i].dot(&(moment - f.axis_origin[i].cross(&force)));
        }
        tau
    }

    /// [`Robot::gravity_torques_at`] as the sum of `J_cᵀ W` over the links
    /// (one Jacobian per link): the reference of the recursion's test.
    #[cfg(test)]
    pub(crate) fn gravity_torques_jacobian(&self, f: &Frames) -> Vector6<f64> {
        use super::kinematics::jacobian_link;
        let g = self.gravity_base();
        let mut tau = Vector6::zeros();
        for (i, l) in self.links().iter().enumerate() {
            let w = force_wrench(g * l.mass_kg);
            tau += jacobian_link(f, i, &l.com_mm).transpose() * w;
        }
        if let Some(l) = self.tool_load() {
            tau += jacobian(f, &l.com_mm).transpose() * force_wrench(g * l.mass_kg);
        }
        tau
    }

    /// Process wrench at the TCP in the robot base frame, `[F (N); M (N·mm)]`;
    /// zero without one.
    pub fn process_wrench_base(
        &self,
        model: Model,
        q: &[f64; 6],
        wrench: Option<&Wrench>,
    ) -> Vector6<f64> {
        self.process_wrench_base_of(self.params(model), q, wrench)
    }

    /// [`Robot::process_wrench_base`] for any parameter set.
    pub fn process_wrench_base_of(
        &self,
        params: &DhParams,
        q: &[f64; 6],
        wrench: Option<&Wrench>,
    ) -> Vector6<f64> {
        if wrench.is_none() {
            return Vector6::zeros();
        }
        self.process_wrench_base_at(&flange(params, q), wrench)
    }

    /// [`Robot::process_wrench_base`] for a flange pose already computed.
    fn process_wrench_base_at(
        &self,
        flange: &Isometry3<f64>,
        wrench: Option<&Wrench>,
    ) -> Vector6<f64> {
        let Some(w) = wrench else {
            return Vector6::zeros();
        };
        let (f, m) = if w.in_tool_frame() {
            let r = (flange * self.flange_to_tool()).rotation;
            (r * w.force_n, r * w.moment_nmm)
        } else {
            (w.force_n, w.moment_nmm)
        };
        let mut out = Vector6::zeros();
        out.fixed_rows_mut::<3>(0).copy_from(&f);
        out.fixed_rows_mut::<3>(3).copy_from(&m);
        out
    }

    /// Joint torques (N·mm) of the process wrench acting at the TCP.
    pub fn process_torques(
        &self,
        model: Model,
        q: &[f64; 6],
        wrench: Option<&Wrench>,
    ) -> Vector6<f64> {
        self.process_torques_of(self.params(model), q, wrench)
    }

    /// [`Robot::process_torques`] for any parameter set.
    pub fn process_torques_of(
        &self,
        params: &DhParams,
        q: &[f64; 6],
        wrench: Option<&Wrench>,
    ) -> Vector6<f64> {
        self.process_torques_at(&frames(params, q), wrench)
    }

    /// [`Robot::process_torques`] from joint frames already computed.
    pub(crate) fn process_torques_at(&self, f: &Frames, wrench: Option<&Wrench>) -> Vector6<f64> {
        let w = self.process_wrench_base_at(&f.flange(), wrench);
        jacobian(f, &self.flange_to_tool().translation.vector).transpose() * w
    }

    /// [`Robot::gravity_torques`] plus [`Robot::process_torques`] of the
    /// nominal model, from one set of joint frames.
    pub(crate) fn nominal_load_torques(
        &self,
        q: &[f64; 6],
        wrench: Option<&Wrench>,
    ) -> Vector6<f64> {
        self.nominal_load_torques_and_flange(q, wrench).0
    }

    /// [`Robot::nominal_load_torques`] and the nominal flange pose at `q`
    /// (the last of the frames they come from).
    pub(crate) fn nominal_load_torques_and_flange(
        &self,
        q: &[f64; 6],
        wrench: Option<&Wrench>,
    ) -> (Vector6<f64>, Isometry3<f64>) {
        let f = super::kinematics::frames_prepared(self.nominal_prepared(), q, 6);
        let tau_g = self.gravity_torques_at(&f);
        let tau = if Self::process_torques_vanish(&tau_g, 1.0, wrench) {
            tau_g
        } else {
            tau_g + self.process_torques_at(&f, wrench)
        };
        (tau, f.flange())
    }

    /// True when adding the process torques (times `gain`) to `tau_g`
    /// gives `tau_g` to the bit, so that they need not be computed: without
    /// a process wrench they are `Jᵀ·0`, signed zeros (the Jacobian is
    /// finite where the gravity torques are: both come from the same
    /// frames), times a finite gain still signed zeros, and a signed zero
    /// added to a finite non-zero number or to `+0` leaves it unchanged
    /// (only `−0 + +0 = +0` would change a bit).
    pub(crate) fn process_torques_vanish(
        tau_g: &Vector6<f64>,
        gain: f64,
        wrench: Option<&Wrench>,
    ) -> bool {
        wrench.is_none()
            && gain.is_finite()
            && tau_g
                .iter()
                .all(|t| t.is_finite() && (*t != 0.0 || t.is_sign_positive()))
    }

    /// Joint deflection `Δθ = Kθ⁻¹ τ` (rad) for torques in N·mm.
    pub fn joint_deflection(&self, tau: &Vector6<f64>) -> [f64; 6] {
        let k = &self.d.k_nmm_per_rad;
        std::array::from_fn(|i| tau[i] / k[i])
    }

    /// Small-deflection displacement of a point fixed to the flange (given in
    /// the flange frame): `[Δp (mm); Δφ (rad)] = J_P Kθ⁻¹ τ`, robot base frame.
    pub fn point_deflection(
        &self,
        model: Model,
        q: &[f64; 6],
        point_in_flange: &Vector3<f64>,
        tau: &Vector6<f64>,
    ) -> Vector6<f64> {
        let f = self.frames(model, q);
        let dq = Vector6::from(self.joint_deflection(tau));
        jacobian(&f, point_in_flange) * dq
    }

    /// Flange pose (robot base frame) after the joints yield under `tau`:
    /// `FK(q + Kθ⁻¹ τ)`.
    pub fn deflected_flange(
        &self,
        model: Model,
        q: &[f64; 6],
        tau: &Vector6<f64>,
    ) -> Isometry3<f64> {
        let dq = self.joint_deflection(tau);
        let qd: [f64; 6] = std::array::from_fn(|i| q[i] + dq[i]);
        self.flange_pose(model, &qd)
    }
}

#[cfg(test)]
fn force_wrench(f: Vector3<f64>) -> Vector6<f64> {
    let mut w = Vector6::zeros();
    w.fixed_rows_mut::<3>(0).copy_from(&f);
    w
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::machine::Machine;
    use crate::machine::robot::PointMass;
    use approx::assert_abs_diff_eq;

    /// Recursion against the per-link Jacobian sum: the same terms summed
    /// in another order, so rounding only (torques are up to about 1e6 N·mm).
    const TORQUE_ROUNDING_NMM: f64 = 1e-7;

    fn robot(text: &str, file: &str) -> Robot {
        let Ok(Machine::Robot(r)) = Machine::from_yaml_str(text, file) else {
            panic!("{file} is a robot file")
        };
        r
    }

    #[test]
    fn recursive_gravity_torques_equal_the_jacobian_sum() {
        let robots = [
            robot(
                include_str!("../../../machines/abb-irb1600.yaml"),
                "abb-irb1600.yaml",
            ),
            robot(
                include_str!("../../../machines/staubli-tx200.yaml"),
                "staubli-tx200.yaml",
            ),
        ];
        let load = PointMass {
            mass_kg: 7.5,
            com_mm: Vector3::new(12.0, -30.0, 95.0),
        };
        // A fixed linear congruential sequence: random joints in ±π.
        let mut sequence = crate::machine::robot::test_sequence(0x2545_f491_4f6c_dd1d);
        let mut next = || sequence() * std::f64::consts::PI;
        for r in &robots {
            for view in [r.clone(), r.with_tool(*r.flange_to_tool(), Some(load))] {
                for _ in 0..200 {
                    let q: [f64; 6] = std::array::from_fn(|_| next());
                    for model in [Model::Nominal, Model::Actual] {
                        let f = view.frames(model, &q);
                        assert_abs_diff_eq!(
                            view.gravity_torques_at(&f),
                            view.gravity_torques_jacobian(&f),
                            epsilon = TORQUE_ROUNDING_NMM
                        );
                    }
                }
            }
        }
    }
}
