//! The expanded uncertainty U (k = 2) of a robot target's predicted
//! deviation: the kinematics covariance a calibration wrote into the robot
//! file (`calibrate kinematics`, a `covariance` block of kind
//! `kinematics`) through the robot's sensitivities at the target's
//! programmed joints, to first order
//! ([`crate::predict::uncertainty::BlockUncertainty::robot`]), stated for
//! the length of the deviation (along it). The sensitivities are those of
//! the robot file's own tool; a program's tool levers the joint-offset
//! parameters by its length beyond the file's.
//!
//! The annotation of a compensated target writes it after the deviation,
//! ` U 0.012` in the deviation's three decimals.

use nalgebra::Vector3;

use crate::predict::uncertainty::BlockUncertainty;

/// U (k = 2) of the deviation `dev` (mm) predicted at the programmed
/// joints `q` (rad), mm; `None` when `u` is a machine tool's.
pub fn target_u_mm(u: &BlockUncertainty, q: &[f64; 6], dev: &Vector3<f64>) -> Option<f64> {
    u.robot_total_mm(q, dev)
}

/// Decimals of U in a robot annotation (those of the deviation).
pub const ANNOTATION_DECIMALS: usize = 3;

/// Appends ` U …` (mm, [`ANNOTATION_DECIMALS`]) to an annotation; nothing
/// for `None`.
pub fn push_u(out: &mut String, u_mm: Option<f64>) {
    if let Some(u) = u_mm {
        use std::fmt::Write;
        let _ = write!(out, " U {u:.ANNOTATION_DECIMALS$}");
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::machine::robot::{DhField, Model, Robot, RobotParam};
    use crate::machine::{Machine, MachineFile};
    use crate::predict::uncertainty::{COVERAGE_K, CovarianceBlock};
    use approx::assert_abs_diff_eq;

    /// Agreement of two first-order propagations, mm.
    const U_TOL_MM: f64 = 1e-6;

    fn robot() -> Robot {
        match MachineFile::bundled("abb-irb1600").unwrap().load().unwrap() {
            Machine::Robot(r) => r,
            Machine::Tool(_) => panic!("a robot"),
        }
    }

    fn uncertainty(r: &Robot, params: &[&str], u: &[f64], rho: f64) -> BlockUncertainty {
        let n = params.len();
        let block = CovarianceBlock {
            kind: "kinematics".into(),
            observations: "hand.csv".into(),
            observations_sha256: "00".into(),
            rows: 30,
            parameters: params.iter().map(|p| p.to_string()).collect(),
            u: u.to_vec(),
            correlation: (0..n)
                .map(|i| (0..n).map(|j| if i == j { 1.0 } else { rho }).collect())
                .collect(),
        };
        BlockUncertainty::of_machine(&Machine::Robot(r.clone()), &[block], "r.yaml")
            .unwrap()
            .expect("a kinematics block")
    }

    #[test]
    fn the_base_height_moves_every_target_one_to_one() {
        // d of joint 1 is a length along the base's z axis, before any
        // joint turns: the TCP moves by it whatever the joints, so a
        // deviation along z has U = 2 u and one across z has U = 0.
        let r = robot();
        let u = uncertainty(&r, &["actual[0].d_mm"], &[0.05], 0.0);
        for q in [[0.0; 6], [0.3, -0.2, 0.4, 0.5, -0.6, 0.7]] {
            let along = target_u_mm(&u, &q, &Vector3::new(0.0, 0.0, 0.02)).unwrap();
            assert_abs_diff_eq!(along, COVERAGE_K * 0.05, epsilon = U_TOL_MM);
            let across = target_u_mm(&u, &q, &Vector3::new(0.02, 0.0, 0.0)).unwrap();
            assert_abs_diff_eq!(across, 0.0, epsilon = U_TOL_MM);
        }
    }

    #[test]
    fn u_is_the_spread_of_the_tcp_over_the_parameters_moved_by_their_u() {
        // Two correlated parameters, by an independent path: the TCP of
        // the robot with each moved by a tenth of its u (a smaller step than
        // the propagation's), J by forward differences, then
        // U = 2 √(n̂ᵀ J Σ Jᵀ n̂) by hand.
        let r = robot();
        let params = ["actual[1].a_mm", "actual[2].theta_offset_deg"];
        let (u1, u2, rho) = (0.1, 0.02, 0.3);
        let u = uncertainty(&r, &params, &[u1, u2], rho);
        let q = [0.2, 0.3, -0.4, 0.1, 0.5, -0.2];
        let tcp = |m: &Robot| m.tcp_pose(Model::Actual, &q).translation.vector;
        let moved = |p: RobotParam, h: f64| {
            let v = r.param_value(p).unwrap_or(0.0);
            (tcp(&r.with_params(&[(p, v + h)]).unwrap()) - tcp(&r)) / h
        };
        let j1 = moved(
            RobotParam::Dh {
                joint: 1,
                field: DhField::A,
            },
            u1 / 10.0,
        );
        let j2 = moved(
            RobotParam::Dh {
                joint: 2,
                field: DhField::ThetaOffset,
            },
            u2 / 10.0,
        );
        let dev = Vector3::new(0.01, -0.02, 0.015);
        let n = dev.normalize();
        let (a, b) = (n.dot(&j1), n.dot(&j2));
        let var = (a * u1).powi(2) + (b * u2).powi(2) + 2.0 * rho * a * b * u1 * u2;
        let want = COVERAGE_K * var.sqrt();
        let got = target_u_mm(&u, &q, &dev).unwrap();
        // Forward differences at a tenth of u are first-order accurate:
        // within a few µm of the central ones here.
        assert!(want > 0.01, "the case has an uncertainty: {want}");
        assert_abs_diff_eq!(got, want, epsilon = 5e-3 * want);
    }

    #[test]
    fn the_annotation_writes_u_in_three_decimals_or_nothing() {
        let mut s = String::from("dev 0.120 mm");
        push_u(&mut s, None);
        assert_eq!(s, "dev 0.120 mm");
        push_u(&mut s, Some(0.0234));
        assert_eq!(s, "dev 0.120 mm U 0.023");
    }
}
