//! Compensation of one robot target, beside the machine-tool solver
//! ([`crate::compensate`]).
//!
//! Compensation searches the commanded pose `C` whose predicted attained pose
//! ([`Robot::predict`] in the move's [`MoveContext`]) equals the programmed pose `P`, by the fixed-point
//! iteration `C ← C + (P − attained(C))` (position added, rotation vector
//! applied on the left). It converges quickly because the deviation changes
//! little over the size of the correction; near the wrist singularity it
//! switches to Newton steps.

use nalgebra::{Isometry3, Matrix6, Translation3, UnitQuaternion, Vector6};

use crate::machine::robot::kinematics::Prepared;
use crate::machine::robot::pose::pose_error;
use crate::machine::robot::{ConfData, IkSelect, Model, Robot, RobotError};
use crate::predict::context::{MoveContext, Wrench};
use crate::predict::robot::{Breakdown, EffectSet, PoseDelta};

/// The compensation of one step of a robot run, as the writers take it:
/// its target's and its auxiliary (via) point's (`None` for a step not
/// compensated).
pub type Solved<'a> = Option<(&'a Compensation, Option<&'a Compensation>)>;

/// Position tolerance of the compensation iteration, mm (0.1 nm).
pub const COMP_POS_TOL_MM: f64 = 1e-7;
/// Orientation tolerance of the compensation iteration, rad.
pub const COMP_ROT_TOL_RAD: f64 = 1e-10;
/// Iteration limit of the compensation.
pub const COMP_MAX_ITER: usize = 50;
/// Result of compensating one target.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Compensation {
    /// The pose to program instead (world frame).
    pub pose: Isometry3<f64>,
    /// Controller joints of the programmed (uncompensated) pose, rad.
    pub q_programmed: [f64; 6],
    /// Controller joints of the compensated pose, rad.
    pub q_compensated: [f64; 6],
    /// Confdata to write with the compensated target
    /// ([`crate::machine::robot::ik::confdata_written`]): the programmed
    /// quadrants of joints 1, 4, 6 while `q_compensated` lies in them
    /// (within the quadrant tolerance), the quadrant it lies in where
    /// compensation moves a joint across a boundary; cfx of
    /// `q_compensated` (always the programmed one: a change of it is
    /// refused as a reconfiguration).
    pub conf: ConfData,
    /// Predicted deviation of the uncompensated target.
    pub deviation: Breakdown,
    /// Remaining predicted error of the compensated target.
    pub residual: PoseDelta,
    /// Iterations used.
    pub iterations: usize,
}

/// What planning a move found about its programmed pose, to start its
/// compensation from ([`Robot::compensate_seeded`]).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub(crate) struct Seed {
    /// Controller joints of the programmed pose (`ik_nominal(programmed,
    /// sel)`, limits checked).
    pub q: Option<[f64; 6]>,
    /// Closed-form branch of `q` ([`Robot::ik_conf_indexed`]).
    pub branch: Option<usize>,
    /// Nominal flange pose (robot base frame) at `q`, computed as the last
    /// frame of `frames_prepared(nominal, q, 6)` (ignored without `q`).
    pub nominal_flange: Option<Isometry3<f64>>,
    /// The configuration the move is solved in instead of its target's
    /// confdata: that of `q`, the solution nearest the previous move's
    /// joints, where configuration monitoring is off (`ConfL \Off`,
    /// `ConfJ \Off`). Its confdata is written with the compensated target.
    pub conf: Option<ConfData>,
}

/// The closed-form branch of a target's inverse kinematics, kept over the
/// compensation iteration when `fixed`.
struct BranchMemo {
    fixed: bool,
    k: Option<usize>,
}

/// Weight of rotation against position in the progress test, mm/rad.
const ROT_SCALE_MM: f64 = 1000.0;

/// Moves a pose by `[Δp (mm); Δφ (rad)]`, rotation applied on the left.
fn perturb(c: &Isometry3<f64>, d: &Vector6<f64>) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::from(c.translation.vector + d.fixed_rows::<3>(0)),
        UnitQuaternion::from_scaled_axis(d.fixed_rows::<3>(3).into_owned()) * c.rotation,
    )
}

impl Robot {
    /// Controller joints of a commanded pose, continuing from `q`.
    /// With a branch in `branch` (the closed-form branch index of the
    /// target, once known), only that branch is solved
    /// ([`Robot::ik_conf_near_branch`]); otherwise every branch is
    /// searched, and the one found is kept when `branch.fixed`.
    fn controller_joints(
        &self,
        cmd: &Isometry3<f64>,
        q: &[f64; 6],
        sel: &IkSelect,
        branch: &mut BranchMemo,
    ) -> Result<[f64; 6], RobotError> {
        match sel {
            IkSelect::Conf(c) => match branch.k {
                Some(k) => self.ik_conf_near_branch(cmd, *c, q, k),
                None => {
                    let (q, k) = self.ik_conf_branch(cmd, *c, Some(q))?;
                    if branch.fixed {
                        branch.k = Some(k);
                    }
                    Ok(q)
                }
            },
            IkSelect::Near(_) => crate::machine::robot::ik::solve_numeric(
                self.params(Model::Nominal),
                &self.flange_for_tcp(cmd),
                q,
            ),
        }
    }

    /// Finite-difference Jacobian of the attained pose with respect to the
    /// commanded pose (both as `[Δp; Δφ]`).
    #[allow(clippy::too_many_arguments)]
    fn deviation_jacobian(
        &self,
        cmd: &Isometry3<f64>,
        q: &[f64; 6],
        attained: &Isometry3<f64>,
        sel: &IkSelect,
        model: &Prepared,
        effects: EffectSet,
        wrench: Option<&Wrench>,
        branch: &mut BranchMemo,
    ) -> Result<Matrix6<f64>, RobotError> {
        const H: [f64; 2] = [1e-4, 1e-7];
        let mut m = Matrix6::zeros();
        for k in 0..6 {
            let h = H[k / 3];
            let mut d = Vector6::zeros();
            d[k] = h;
            let qk = self.controller_joints(&perturb(cmd, &d), q, sel, branch)?;
            let (dp, dr) = pose_error(&self.predict_with(model, &qk, effects, wrench), attained);
            for r in 0..3 {
                m[(r, k)] = dp[r] / h;
                m[(r + 3, k)] = dr[r] / h;
            }
        }
        Ok(m)
    }

    /// Compensates one programmed TCP pose (world frame) in the move context
    /// `ctx`: returns the pose to program so that the predicted attained
    /// pose equals `programmed` within `COMP_POS_TOL_MM` /
    /// `COMP_ROT_TOL_RAD`.
    pub fn compensate(
        &self,
        ctx: &MoveContext,
        programmed: &Isometry3<f64>,
        sel: &IkSelect,
        effects: EffectSet,
    ) -> Result<Compensation, RobotError> {
        self.compensate_seeded(ctx, programmed, sel, effects, &Seed::default())
            .map_err(|e| self.with_reaching_configurations(programmed, e))
    }

    /// [`Robot::compensate`] with what planning the move already
    /// found ([`Seed`]): saves one inverse kinematics (and the nominal
    /// forward kinematics of the deviation breakdown, when given). A
    /// refusal by the numeric inverse does not list the configurations that
    /// reach the target: the caller that shows it adds them
    /// ([`Robot::with_reaching_configurations`]).
    pub(crate) fn compensate_seeded(
        &self,
        ctx: &MoveContext,
        programmed: &Isometry3<f64>,
        sel: &IkSelect,
        effects: EffectSet,
        seed: &Seed,
    ) -> Result<Compensation, RobotError> {
        let Seed {
            q: q_programmed,
            branch,
            nominal_flange,
            ..
        } = *seed;
        // The flange is that of the given joints only.
        let nominal_flange = nominal_flange.filter(|_| q_programmed.is_some());
        // The joints of the programmed pose, solved once for both paths
        // below (a target refused here is refused by both).
        let q0 = match q_programmed {
            Some(q) => q,
            None => self.ik_nominal_unlisted(programmed, sel)?,
        };
        // Fast path: the closed-form branch found by the first inverse
        // kinematics of the iteration is the only one solved afterwards.
        // Its result stands when the final joints still have the asked
        // cfx (the branch cannot change over sub-millimetre corrections);
        // otherwise, and on any error, the search over every branch at
        // every step decides (the same result and the same error as
        // before the fast path).
        if let IkSelect::Conf(c) = sel {
            let seed = q_programmed.and(branch);
            if let Ok(r) = self.compensate_branch(
                ctx,
                programmed,
                sel,
                effects,
                (q0, nominal_flange),
                Some(seed),
            ) {
                if r.conf.cfx == c.cfx {
                    return Ok(r);
                }
            }
        }
        self.compensate_branch(ctx, programmed, sel, effects, (q0, nominal_flange), None)
    }

    /// The predicted deviation of the TCP at joints `q` (a `MoveAbsJ`'s
    /// programmed joints, reported and not compensated): attained with
    /// `effects` in the move context `ctx` against the nominal pose, split
    /// as a compensation's ([`Breakdown`]).
    pub(crate) fn predict_at_joints(
        &self,
        ctx: &MoveContext,
        q: &[f64; 6],
        effects: EffectSet,
    ) -> Breakdown {
        let (kin, model) = self.prediction_prepared(effects, &self.growth_of(ctx));
        let st = self.stages_from(&kin, &model, q, effects, ctx.wrench.as_ref(), None);
        Breakdown {
            kinematic: PoseDelta::between(&st[1], &st[0]),
            thermal: PoseDelta::between(&st[2], &st[1]),
            gravity: PoseDelta::between(&st[3], &st[2]),
            process: PoseDelta::between(&st[4], &st[3]),
            total: PoseDelta::between(&st[4], &st[0]),
            vibration_mm: self.vibration_mm(ctx, q, effects),
        }
    }

    /// [`Robot::compensate_seeded`]; with `fixed_branch`, the inverse
    /// kinematics of the iteration solves only one branch: the given one,
    /// else the branch of its first solution.
    fn compensate_branch(
        &self,
        ctx: &MoveContext,
        programmed: &Isometry3<f64>,
        sel: &IkSelect,
        effects: EffectSet,
        (q0, nominal_flange): ([f64; 6], Option<Isometry3<f64>>),
        fixed_branch: Option<Option<usize>>,
    ) -> Result<Compensation, RobotError> {
        let mut branch = BranchMemo {
            fixed: fixed_branch.is_some(),
            k: fixed_branch.flatten(),
        };
        let wrench = ctx.wrench.as_ref();
        let (kin, model) = self.prediction_prepared(effects, &self.growth_of(ctx));
        let st = self.stages_from(&kin, &model, &q0, effects, wrench, nominal_flange);
        let deviation = Breakdown {
            kinematic: PoseDelta::between(&st[1], &st[0]),
            thermal: PoseDelta::between(&st[2], &st[1]),
            gravity: PoseDelta::between(&st[3], &st[2]),
            process: PoseDelta::between(&st[4], &st[3]),
            total: PoseDelta::between(&st[4], programmed),
            vibration_mm: self.vibration_mm(ctx, &q0, effects),
        };
        let mut cmd = *programmed;
        let mut q = q0;
        let mut attained = st[4];
        let mut last = (f64::INFINITY, f64::INFINITY);
        let mut newton = false;
        for it in 0..COMP_MAX_ITER {
            let (dp, dr) = pose_error(programmed, &attained);
            let prev = last.0 + ROT_SCALE_MM * last.1;
            last = (dp.norm(), dr.norm());
            if last.0 < COMP_POS_TOL_MM && last.1 < COMP_ROT_TOL_RAD {
                self.check_limits(&q)?;
                self.check_reconfiguration(&q0, &q)?;
                return Ok(Compensation {
                    pose: cmd,
                    q_programmed: q0,
                    q_compensated: q,
                    conf: crate::machine::robot::ik::confdata_written(
                        self.confdata(&q),
                        &q,
                        match sel {
                            IkSelect::Conf(c) => *c,
                            IkSelect::Near(_) => self.confdata(&q0),
                        },
                    ),
                    deviation,
                    residual: PoseDelta::between(&attained, programmed),
                    iterations: it,
                });
            }
            // The plain fixed-point step contracts unless the deviation
            // changes fast with the pose (near the wrist singularity); then
            // switch to Newton steps with a finite-difference Jacobian.
            if last.0 + ROT_SCALE_MM * last.1 > 0.5 * prev {
                newton = true;
            }
            let mut e = Vector6::zeros();
            e.fixed_rows_mut::<3>(0).copy_from(&dp);
            e.fixed_rows_mut::<3>(3).copy_from(&dr);
            let step = if newton {
                let m = self.deviation_jacobian(
                    &cmd,
                    &q,
                    &attained,
                    sel,
                    &model,
                    effects,
                    wrench,
                    &mut branch,
                )?;
                m.lu().solve(&e).unwrap_or(e)
            } else {
                e
            };
            cmd = perturb(&cmd, &step);
            q = self.controller_joints(&cmd, &q, sel, &mut branch)?;
            attained = self.predict_with(&model, &q, effects, wrench);
        }
        Err(RobotError::NoConvergence {
            what: "target compensation",
            iterations: COMP_MAX_ITER,
            pos_mm: last.0,
            rot_rad: last.1,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::machine::robot::ConfData;
    use approx::assert_abs_diff_eq;
    use nalgebra::Vector3;

    /// A seed with the nominal flange taken from the planning's frames
    /// gives the compensation computed without it, bit for bit.
    #[test]
    fn nominal_flange_seed_equals_the_unseeded_compensation() {
        let r = crate::machine::robot::test_irb1600();
        let ctx = MoveContext::default().with_joint_powers([30.0, 90.0, 40.0, 0.0, 0.0, 0.0]);
        let mut checked = 0;
        for (x, y, z) in [
            (650.0, 50.0, 300.0),
            (900.0, -200.0, 700.0),
            (500.0, 400.0, 150.0),
        ] {
            let pose = Isometry3::from_parts(
                Translation3::new(x, y, z),
                UnitQuaternion::from_axis_angle(&Vector3::y_axis(), 3.0),
            );
            let Ok(sols) = r.ik_all(&pose) else {
                continue;
            };
            for s in sols.iter().flatten() {
                let conf = r.confdata(s);
                let Ok((q, branch)) = r.ik_conf_indexed(&pose, conf) else {
                    continue;
                };
                let sel = IkSelect::Conf(conf);
                let (_, flange) = r.nominal_load_torques_and_flange(&q, None);
                let plain = Seed {
                    q: Some(q),
                    branch: Some(branch),
                    nominal_flange: None,
                    conf: None,
                };
                let seeded = Seed {
                    nominal_flange: Some(flange),
                    ..plain
                };
                let a = r.compensate_seeded(&ctx, &pose, &sel, EffectSet::ALL, &plain);
                let b = r.compensate_seeded(&ctx, &pose, &sel, EffectSet::ALL, &seeded);
                assert_eq!(a, b);
                checked += 1;
            }
        }
        assert!(checked >= 3);
    }

    /// The thermal stage at the joint powers of the move context moves the
    /// arm as the same robot with its actual DH lengths grown for those
    /// powers ([`Robot::at_joint_power`]) and the thermal stage off.
    #[test]
    fn joint_powers_of_the_context_equal_a_robot_at_that_power() {
        let r = crate::machine::robot::test_irb1600();
        // Warm joints 2 and 3 (W): the thermal section grows row 2's a.
        let p = [0.0, 150.0, 80.0, 0.0, 0.0, 0.0];
        let warm = MoveContext::default().with_joint_powers(p);
        assert!(r.growth_of(&warm).iter().flatten().any(|g| *g != 0.0));
        let pose = Isometry3::from_parts(
            Translation3::new(750.0, 150.0, 400.0),
            UnitQuaternion::from_axis_angle(&Vector3::y_axis(), std::f64::consts::PI),
        );
        let sel = IkSelect::Conf(ConfData {
            cf1: 0,
            cf4: 0,
            cf6: 0,
            cfx: 0,
        });
        let a = r
            .compensate(&warm, &pose, &sel, EffectSet::ALL)
            .expect("reachable");
        let no_thermal = EffectSet {
            thermal: 0.0,
            ..EffectSet::ALL
        };
        let b = r
            .at_joint_power(&p)
            .compensate(&MoveContext::default(), &pose, &sel, no_thermal)
            .expect("reachable");
        // The same lengths, prepared in two ways: rounding only.
        const PREPARED_MM: f64 = 1e-9;
        assert_abs_diff_eq!(
            a.pose.translation.vector,
            b.pose.translation.vector,
            epsilon = PREPARED_MM
        );
        assert_abs_diff_eq!(
            a.deviation.total.pos_mm,
            b.deviation.total.pos_mm,
            epsilon = PREPARED_MM
        );
        assert!(a.deviation.thermal.pos_mm.norm() > 1e-4);
        assert_eq!(b.deviation.thermal.pos_mm, Vector3::zeros());
    }
}
