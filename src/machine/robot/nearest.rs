//! The inverse kinematics a controller uses with configuration monitoring
//! off (`ConfL \Off`, `ConfJ \Off`): the solution nearest the joints the
//! robot comes from, whatever the target's confdata says.
//!
//! - With the closed form: every branch, each joint turned to the value
//!   nearest the reference, within the limits; the one with the smallest
//!   sum of squared joint differences (the first in branch order on a tie).
//! - Without it: the numeric solver started at the reference (it converges
//!   to the solution it reaches continuously from there), limits checked.

use nalgebra::Isometry3;

use super::ik;
use super::{Model, NUMERIC_BRANCH, Robot, RobotError};

impl Robot {
    /// Nominal joints of a TCP pose (world frame) nearest `reference`
    /// (rad), with the branch index that gave them (see the module
    /// documentation).
    pub(crate) fn ik_nearest(
        &self,
        tcp_world: &Isometry3<f64>,
        reference: &[f64; 6],
    ) -> Result<([f64; 6], usize), RobotError> {
        let flange = self.flange_for_tcp(tcp_world);
        let Some(cf) = self.d.closed_form.as_ref() else {
            let q = ik::solve_numeric(self.params(Model::Nominal), &flange, reference)?;
            self.check_limits(&q)?;
            return Ok((q, NUMERIC_BRANCH));
        };
        let mut best: Option<(f64, [f64; 6], usize)> = None;
        let mut limit_err = None;
        for (k, sol) in cf.solve(&flange, reference[3]).iter().enumerate() {
            let Some(mut q) = *sol else {
                continue;
            };
            for i in 0..6 {
                q[i] = ik::nearest_turn(q[i], reference[i]);
            }
            if let Err(e) = self.check_limits(&q) {
                limit_err.get_or_insert(e);
                continue;
            }
            let d: f64 = (0..6).map(|i| (q[i] - reference[i]).powi(2)).sum();
            if best.is_none_or(|(b, _, _)| d < b) {
                best = Some((d, q, k));
            }
        }
        match (best, limit_err) {
            (Some((_, q, k)), _) => Ok((q, k)),
            (None, Some(e)) => Err(e),
            (None, None) => Err(RobotError::Unreachable(
                "the wrist centre is farther from (or closer to) the shoulder than the arm can reach"
                    .into(),
            )),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Joint agreement of two solutions of one pose, rad (the numeric
    /// solver's convergence, amplified by the arm's conditioning).
    const SAME_JOINTS_RAD: f64 = 1e-7;

    /// From joints near a solution, the nearest solution is that one, on
    /// both robots; its confdata may differ from any the target declares.
    #[test]
    fn nearest_solution_is_the_one_next_to_the_reference() {
        let tx = Robot::from_yaml_str(
            include_str!("../../../machines/staubli-tx200.yaml"),
            "staubli-tx200.yaml",
        )
        .expect("bundled file");
        for r in [crate::machine::robot::test_irb1600(), tx] {
            let q = [0.3, 0.2, 0.4, 1.9, 0.8, -2.2];
            let pose = r.tcp_pose(Model::Nominal, &q);
            let near = q.map(|v| v + 0.05);
            let (got, _) = r.ik_nearest(&pose, &near).expect("reachable");
            for i in 0..6 {
                assert!((got[i] - q[i]).abs() < SAME_JOINTS_RAD, "{got:?}");
            }
        }
    }
}
