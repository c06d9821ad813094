//! Prediction and compensation of one robot target.
//!
//! The controller turns a programmed TCP pose into joints with its NOMINAL
//! model (closed-form IK with confdata, or numeric IK from a seed). The real
//! arm then reaches
//! `base · FK_actual(q + Kθ⁻¹ (τ_gravity(q) + τ_process(q))) · tool`.
//! Small-deflection form: the torques are evaluated at the commanded joints
//! `q` of the actual model, not at the deflected ones (second-order effect).
//!
//! Compensation searches the commanded pose `C` whose predicted attained pose
//! equals the programmed pose `P`, by the fixed-point iteration
//! `C ← C + (P − attained(C))` (position added, rotation vector applied on
//! the left). It converges quickly because the deviation changes little over
//! the size of the correction.

use nalgebra::{Isometry3, Matrix6, Translation3, UnitQuaternion, Vector3, Vector6};

use super::dh::DhParams;
use super::kinematics::{
    Frames, HalfAngles, Prepared, flange_deflected, flange_prepared, frames_and_twin_flange,
    frames_with_half_angles,
};
use super::pose::pose_error;
use super::thermal::{DhGrowth, grown};
use super::{IkSelect, Model, Robot, RobotError};

/// Parameters `gain` of the way from `nominal` to `actual` (exactly one of
/// them for a gain of 0 or 1).
fn blend(nominal: &DhParams, actual: &DhParams, gain: f64) -> DhParams {
    if gain == 0.0 {
        return *nominal;
    }
    if gain == 1.0 {
        return *actual;
    }
    let mut out = *nominal;
    for (o, (n, a)) in out
        .joints
        .iter_mut()
        .zip(nominal.joints.iter().zip(&actual.joints))
    {
        o.a_mm = n.a_mm + gain * (a.a_mm - n.a_mm);
        o.alpha_rad = n.alpha_rad + gain * (a.alpha_rad - n.alpha_rad);
        o.d_mm = n.d_mm + gain * (a.d_mm - n.d_mm);
        o.theta_offset_rad = n.theta_offset_rad + gain * (a.theta_offset_rad - n.theta_offset_rad);
    }
    out
}

/// Largest change of any joint between the programmed and the compensated
/// target, degrees. A correction of a millimetre moves the joints by
/// hundredths of a degree; a larger change is the arm flipping its wrist
/// near a singularity.
pub const JOINT_JUMP_MAX_DEG: f64 = 5.0;

/// Position tolerance of the compensation iteration, mm (0.1 nm).
pub const COMP_POS_TOL_MM: f64 = 1e-7;
/// Orientation tolerance of the compensation iteration, rad.
pub const COMP_ROT_TOL_RAD: f64 = 1e-10;
/// Iteration limit of the compensation.
pub const COMP_MAX_ITER: usize = 50;

/// Which effects the prediction includes, as gains: 0 = off, 1 = as
/// modelled; other values scale the effect linearly (kinematic: the DH
/// parameters move `gain` of the way from nominal to actual; thermal: the DH
/// growth times `gain`; gravity and process: the torques times `gain`;
/// dynamic: the reported amplitude times `gain`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Effects {
    /// Actual (calibrated) instead of nominal DH parameters.
    pub kinematic: f64,
    /// Joint deflection from gravity (links and tool load).
    pub gravity: f64,
    /// Joint deflection from the process wrench.
    pub process: f64,
    /// Thermal growth of the DH lengths (Paper B).
    pub thermal: f64,
    /// Vibration amplitude (reported, never compensated).
    pub dynamic: f64,
}

impl Effects {
    /// Every effect on.
    pub const ALL: Effects = Effects {
        kinematic: 1.0,
        gravity: 1.0,
        process: 1.0,
        thermal: 1.0,
        dynamic: 1.0,
    };
    /// Every effect off (prediction = controller's nominal model).
    pub const NONE: Effects = Effects {
        kinematic: 0.0,
        gravity: 0.0,
        process: 0.0,
        thermal: 0.0,
        dynamic: 0.0,
    };
    /// The effects `--effects` turns on, scaled by `--gain`; names that do
    /// not apply to a robot (`static`) are refused.
    pub fn from_flags(
        spec: &crate::machine::effects::EffectSpec,
        gains: &[crate::machine::effects::Gain],
    ) -> crate::error::Result<Effects> {
        use crate::machine::effects::EffectName as N;
        let slot = |name| match name {
            N::Kinematic | N::Geometric => Some(0),
            N::Gravity => Some(1),
            N::Process | N::Load => Some(2),
            N::Thermal => Some(3),
            N::Dynamic | N::Vibration => Some(4),
            N::Static => None,
        };
        let [kinematic, gravity, process, thermal, dynamic] = crate::machine::effects::gains_for(
            spec,
            gains,
            slot,
            "a robot",
            "kinematic, gravity, process, thermal, dynamic",
        )?;
        Ok(Effects {
            kinematic,
            gravity,
            process,
            thermal,
            dynamic,
        })
    }

    /// True when some quasi-static effect (one that changes targets) is on.
    pub fn compensates(&self) -> bool {
        self.kinematic != 0.0 || self.gravity != 0.0 || self.process != 0.0 || self.thermal != 0.0
    }
}

/// A small pose difference: attained − reference.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PoseDelta {
    /// Position difference, mm (world frame).
    pub pos_mm: Vector3<f64>,
    /// Rotation vector of `R_attained · R_referenceᵀ`, rad (world frame).
    pub rot_rad: Vector3<f64>,
}

impl PoseDelta {
    fn between(attained: &Isometry3<f64>, reference: &Isometry3<f64>) -> Self {
        let (p, r) = pose_error(attained, reference);
        PoseDelta {
            pos_mm: p,
            rot_rad: r,
        }
    }
}

/// Predicted deviation of an uncompensated target, split by cause. The
/// parts are successive differences, so their positions sum to `total`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Deviation {
    /// Actual vs nominal parameters at the commanded joints.
    pub kinematic: PoseDelta,
    /// Added by the thermal growth of the DH lengths.
    pub thermal: PoseDelta,
    /// Added by gravity deflection.
    pub gravity: PoseDelta,
    /// Added by the process wrench deflection.
    pub process: PoseDelta,
    /// Attained − programmed.
    pub total: PoseDelta,
    /// Predicted vibration amplitude per direction of the robot base frame,
    /// mm (reported, not part of `total`).
    pub vibration_mm: Vector3<f64>,
}

/// Result of compensating one target.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Compensation {
    /// The pose to program instead (world frame).
    pub pose: Isometry3<f64>,
    /// Controller joints of the programmed (uncompensated) pose, rad.
    pub q_programmed: [f64; 6],
    /// Controller joints of the compensated pose, rad.
    pub q_compensated: [f64; 6],
    /// Confdata of `q_compensated`, to be written with the compensated
    /// target: it differs from the programmed one when a joint crosses a
    /// quadrant boundary (cf1/cf4/cf6) during compensation.
    pub conf: super::ConfData,
    /// Predicted deviation of the uncompensated target.
    pub deviation: Deviation,
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
}

/// The closed-form branch of a target's inverse kinematics, kept over the
/// compensation iteration when `fixed`.
struct BranchMemo {
    fixed: bool,
    k: Option<usize>,
}

/// True when two vectors are equal bit for bit (a computation from them
/// gives the same bits).
fn same_bits(a: &Vector6<f64>, b: &Vector6<f64>) -> bool {
    a.iter()
        .zip(b.iter())
        .all(|(x, y)| x.to_bits() == y.to_bits())
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
            IkSelect::Near(_) => {
                super::ik::solve_numeric(self.params(Model::Nominal), &self.flange_for_tcp(cmd), q)
            }
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
        effects: Effects,
        branch: &mut BranchMemo,
    ) -> Result<Matrix6<f64>, RobotError> {
        const H: [f64; 2] = [1e-4, 1e-7];
        let mut m = Matrix6::zeros();
        for k in 0..6 {
            let h = H[k / 3];
            let mut d = Vector6::zeros();
            d[k] = h;
            let qk = self.controller_joints(&perturb(cmd, &d), q, sel, branch)?;
            let (dp, dr) = pose_error(&self.predict_with(model, &qk, effects), attained);
            for r in 0..3 {
                m[(r, k)] = dp[r] / h;
                m[(r + 3, k)] = dr[r] / h;
            }
        }
        Ok(m)
    }

    /// The kinematic (calibrated, blended) and the full (kinematic plus
    /// thermal growth) parameter sets of a prediction. Resolved once per
    /// target: every iteration reuses them.
    fn prediction_params(&self, effects: Effects, growth: &DhGrowth) -> (DhParams, DhParams) {
        let kin = blend(
            self.params(Model::Nominal),
            self.params(Model::Actual),
            effects.kinematic,
        );
        let model = if effects.thermal != 0.0 {
            grown(&kin, growth, effects.thermal)
        } else {
            kin
        };
        (kin, model)
    }

    /// [`Robot::prediction_params`] prepared: the kinematic set (the
    /// robot's prepared nominal rows at a kinematic gain of 0) and the full
    /// set, which differs from it by lengths only and shares its twists.
    fn prediction_prepared(&self, effects: Effects, growth: &DhGrowth) -> (Prepared, Prepared) {
        let (kin, model) = self.prediction_params(effects, growth);
        let kin = if effects.kinematic == 0.0 {
            *self.nominal_prepared()
        } else if effects.kinematic == 1.0 {
            *self.actual_prepared()
        } else {
            Prepared::new(&kin)
        };
        let model = kin.with_lengths_of(&model);
        (kin, model)
    }

    /// TCP pose (world frame) of a flange pose.
    fn tcp_of(&self, flange: &Isometry3<f64>) -> Isometry3<f64> {
        self.base() * flange * self.flange_to_tool()
    }

    /// Gravity torques and gravity plus process torques (each scaled by
    /// its gain, zero when off) from the joint frames of the full model.
    /// The process torques are not computed where they cannot change the
    /// sum ([`Robot::process_torques_vanish`]).
    fn load_torques(&self, f: &Frames, effects: Effects) -> (Vector6<f64>, Vector6<f64>) {
        let tau_g = if effects.gravity != 0.0 {
            self.gravity_torques_at(f) * effects.gravity
        } else {
            Vector6::zeros()
        };
        let tau = if effects.process != 0.0 {
            if self.process_torques_vanish(&tau_g, effects.process) {
                tau_g
            } else {
                tau_g + self.process_torques_at(f) * effects.process
            }
        } else {
            tau_g
        };
        (tau_g, tau)
    }

    /// TCP pose (world frame) of the full model at `q` deflected by `tau`,
    /// from the half angles of `q` ([`flange_deflected`]).
    fn deflected_tcp(
        &self,
        model: &Prepared,
        q: &[f64; 6],
        half: &HalfAngles,
        tau: &Vector6<f64>,
    ) -> Isometry3<f64> {
        let dq = self.joint_deflection(tau);
        self.tcp_of(&flange_deflected(model, q, half, &dq))
    }

    /// Attained TCP pose with the parameter set `model` of
    /// [`Robot::prediction_params`]: one set of joint frames feeds the
    /// gravity and the process torques, one more forward kinematics gives
    /// the deflected pose (the hot path of the compensation iteration).
    fn predict_with(&self, model: &Prepared, q: &[f64; 6], effects: Effects) -> Isometry3<f64> {
        let (f, half) = frames_with_half_angles(model, q);
        let (tau_g, tau) = self.load_torques(&f, effects);
        if effects.process != 0.0 {
            self.deflected_tcp(model, q, &half, &tau)
        } else if effects.gravity != 0.0 {
            self.deflected_tcp(model, q, &half, &tau_g)
        } else {
            self.tcp_of(&f.flange())
        }
    }

    /// Predicted attained TCP pose (world frame) for controller joints `q`,
    /// with the intermediate poses `[nominal, +kinematic, +thermal,
    /// +gravity, +process]` in that order (the last is the attained pose).
    pub fn predict_stages(&self, q: &[f64; 6], effects: Effects) -> [Isometry3<f64>; 5] {
        let (kin, model) = self.prediction_prepared(effects, self.current_thermal_growth_mm());
        self.stages_with(&kin, &model, q, effects)
    }

    /// [`Robot::predict_stages`] with the parameter sets resolved.
    fn stages_with(
        &self,
        kin: &Prepared,
        model: &Prepared,
        q: &[f64; 6],
        effects: Effects,
    ) -> [Isometry3<f64>; 5] {
        self.stages_from(kin, model, q, effects, None)
    }

    /// [`Robot::stages_with`] with the nominal flange pose at `q`, when
    /// already known (the flange of `frames_prepared(nominal, q, 6)`, the
    /// same bits as [`flange_prepared`]).
    fn stages_from(
        &self,
        kin: &Prepared,
        model: &Prepared,
        q: &[f64; 6],
        effects: Effects,
        nominal_flange: Option<Isometry3<f64>>,
    ) -> [Isometry3<f64>; 5] {
        let nominal_flange =
            nominal_flange.unwrap_or_else(|| flange_prepared(self.nominal_prepared(), q));
        let p0 = self.tcp_of(&nominal_flange);
        // The full set differs from the kinematic one by lengths only: one
        // chain of half angles and rotations serves both.
        let (f, kin_flange, half) = match frames_and_twin_flange(model, kin, q) {
            Some(shared) => shared,
            None => {
                let kin_flange = flange_prepared(kin, q);
                let (f, half) = frames_with_half_angles(model, q);
                (f, kin_flange, half)
            }
        };
        let p1 = self.tcp_of(&kin_flange);
        let p2 = self.tcp_of(&f.flange());
        let (tau_g, tau) = self.load_torques(&f, effects);
        let p3 = if effects.gravity != 0.0 {
            self.deflected_tcp(model, q, &half, &tau_g)
        } else {
            p2
        };
        let p4 = if effects.process != 0.0 {
            // Without a process load (zero torques) the sum is the gravity
            // torques to the bit, and so is its deflected pose.
            if effects.gravity != 0.0 && same_bits(&tau, &tau_g) {
                p3
            } else {
                self.deflected_tcp(model, q, &half, &tau)
            }
        } else {
            p3
        };
        [p0, p1, p2, p3, p4]
    }

    /// Predicted vibration amplitude per direction (robot base frame, mm)
    /// at controller joints `q`: the process force taken as a harmonic
    /// force at the tooth-passing frequency, through the modal model.
    /// Zero without a modal model, a spindle speed or a process wrench.
    pub fn vibration_mm(&self, q: &[f64; 6], effects: Effects) -> Vector3<f64> {
        let (Some(modal), Some(f_hz)) = (
            self.modal(),
            self.process_force().and_then(|p| p.excitation_hz()),
        ) else {
            return Vector3::zeros();
        };
        if effects.dynamic == 0.0 || self.process_wrench().is_none() {
            return Vector3::zeros();
        }
        let w = self.process_wrench_base(Model::Nominal, q);
        let f_base = Vector3::new(w[0], w[1], w[2]);
        modal.amplitude_mm(&f_base, f_hz) * effects.dynamic
    }

    /// Predicted attained TCP pose (world frame) for controller joints `q`.
    pub fn predict(&self, q: &[f64; 6], effects: Effects) -> Isometry3<f64> {
        let (_, model) = self.prediction_prepared(effects, self.current_thermal_growth_mm());
        self.predict_with(&model, q, effects)
    }

    /// Compensates one programmed TCP pose (world frame): returns the pose to
    /// program so that the predicted attained pose equals `programmed`
    /// within `COMP_POS_TOL_MM` / `COMP_ROT_TOL_RAD`.
    pub fn compensate(
        &self,
        programmed: &Isometry3<f64>,
        sel: &IkSelect,
        effects: Effects,
    ) -> Result<Compensation, RobotError> {
        self.compensate_with_growth(programmed, sel, effects, self.current_thermal_growth_mm())
    }

    /// [`Robot::compensate`] with the thermal prediction stage using the DH
    /// growth `growth` (mm) instead of the robot's current one: the same
    /// result as `with_thermal_power(p).compensate(…)` for the growth of the
    /// powers `p`, without a copy of the robot per target.
    pub fn compensate_with_growth(
        &self,
        programmed: &Isometry3<f64>,
        sel: &IkSelect,
        effects: Effects,
        growth: &DhGrowth,
    ) -> Result<Compensation, RobotError> {
        self.compensate_seeded(programmed, sel, effects, growth, &Seed::default())
    }

    /// [`Robot::compensate_with_growth`] with what planning the move already
    /// found ([`Seed`]): saves one inverse kinematics (and the nominal
    /// forward kinematics of the deviation breakdown, when given).
    pub(crate) fn compensate_seeded(
        &self,
        programmed: &Isometry3<f64>,
        sel: &IkSelect,
        effects: Effects,
        growth: &DhGrowth,
        seed: &Seed,
    ) -> Result<Compensation, RobotError> {
        let Seed {
            q: q_programmed,
            branch,
            nominal_flange,
        } = *seed;
        // The flange is that of the given joints only.
        let nominal_flange = nominal_flange.filter(|_| q_programmed.is_some());
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
                programmed,
                sel,
                effects,
                growth,
                (q_programmed, nominal_flange),
                Some(seed),
            ) {
                if r.conf.cfx == c.cfx {
                    return Ok(r);
                }
            }
        }
        self.compensate_branch(
            programmed,
            sel,
            effects,
            growth,
            (q_programmed, nominal_flange),
            None,
        )
    }

    /// [`Robot::compensate_seeded`]; with `fixed_branch`, the inverse
    /// kinematics of the iteration solves only one branch: the given one,
    /// else the branch of its first solution.
    fn compensate_branch(
        &self,
        programmed: &Isometry3<f64>,
        sel: &IkSelect,
        effects: Effects,
        growth: &DhGrowth,
        (q_programmed, nominal_flange): (Option<[f64; 6]>, Option<Isometry3<f64>>),
        fixed_branch: Option<Option<usize>>,
    ) -> Result<Compensation, RobotError> {
        let mut branch = BranchMemo {
            fixed: fixed_branch.is_some(),
            k: fixed_branch.flatten(),
        };
        let q0 = match q_programmed {
            Some(q) => q,
            None => self.ik_nominal(programmed, sel)?,
        };
        let (kin, model) = self.prediction_prepared(effects, growth);
        let st = self.stages_from(&kin, &model, &q0, effects, nominal_flange);
        let deviation = Deviation {
            kinematic: PoseDelta::between(&st[1], &st[0]),
            thermal: PoseDelta::between(&st[2], &st[1]),
            gravity: PoseDelta::between(&st[3], &st[2]),
            process: PoseDelta::between(&st[4], &st[3]),
            total: PoseDelta::between(&st[4], programmed),
            vibration_mm: self.vibration_mm(&q0, effects),
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
                    conf: self.confdata(&q),
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
                    &mut branch,
                )?;
                m.lu().solve(&e).unwrap_or(e)
            } else {
                e
            };
            cmd = perturb(&cmd, &step);
            q = self.controller_joints(&cmd, &q, sel, &mut branch)?;
            attained = self.predict_with(&model, &q, effects);
        }
        Err(RobotError::NoConvergence {
            what: "target compensation",
            iterations: COMP_MAX_ITER,
            pos_mm: last.0,
            rot_rad: last.1,
        })
    }
}

impl Robot {
    /// Refuses a compensated solution `q` that moves a joint by more than
    /// [`JOINT_JUMP_MAX_DEG`] from the programmed `q0` or changes the
    /// configuration, unless the robot allows it.
    fn check_reconfiguration(&self, q0: &[f64; 6], q: &[f64; 6]) -> Result<(), RobotError> {
        if self.d.allow_reconfiguration {
            return Ok(());
        }
        let deltas: [f64; 6] = std::array::from_fn(|j| (q[j] - q0[j]).to_degrees());
        let jump = deltas.iter().any(|d| d.abs() > JOINT_JUMP_MAX_DEG);
        let (from, to) = (self.confdata(q0), self.confdata(q));
        if !jump && from.cfx == to.cfx {
            return Ok(());
        }
        let shown: Vec<String> = deltas.iter().map(|d| format!("{d:.3}")).collect();
        Err(RobotError::Reconfiguration {
            deltas: format!("[{}]°", shown.join(", ")),
            limit: JOINT_JUMP_MAX_DEG,
            from,
            to,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::super::kinematics::frames_prepared;
    use super::*;
    use crate::machine::robot::ConfData;
    use approx::assert_abs_diff_eq;

    /// Both paths run the same arithmetic: equal to the last bit.
    const SAME: f64 = 0.0;

    /// [`Robot::stages_with`] without its shortcuts (shared kinematic and
    /// full chains, the process stage reused without process torques,
    /// process torques skipped without a process wrench): every stage from
    /// its own forward kinematics and the full load torques.
    fn stages_reference(r: &Robot, q: &[f64; 6], effects: Effects) -> [Isometry3<f64>; 5] {
        let (kin, model) = r.prediction_prepared(effects, r.current_thermal_growth_mm());
        let p0 = r.tcp_of(&flange_prepared(r.nominal_prepared(), q));
        let p1 = r.tcp_of(&flange_prepared(&kin, q));
        let f = frames_prepared(&model, q, 6);
        let p2 = r.tcp_of(&f.flange());
        let tau_g = r.gravity_torques_at(&f) * effects.gravity;
        let tau_w = r.process_torques_at(&f) * effects.process;
        let deflected = |tau: &Vector6<f64>| {
            let dq = r.joint_deflection(tau);
            let qd: [f64; 6] = std::array::from_fn(|i| q[i] + dq[i]);
            r.tcp_of(&flange_prepared(&model, &qd))
        };
        let p3 = deflected(&tau_g);
        let p4 = deflected(&(tau_g + tau_w));
        [p0, p1, p2, p3, p4]
    }

    /// The deflected stages turn the half angles by the small deflection
    /// instead of calling `sin_cos` again: rounding only (a few ulp of each
    /// half angle, over an arm of about 1.5 m).
    const DEFLECTED_POS_MM: f64 = 1e-11;
    const DEFLECTED_QUAT: f64 = 1e-14;

    #[test]
    fn stages_and_prediction_equal_the_stage_by_stage_reference() {
        use crate::machine::robot::ProcessWrench;
        let r = crate::machine::robot::test_irb1600();
        let warm = r.with_thermal_power(&[20.0, 150.0, 80.0, 0.0, 0.0, 0.0]);
        let loaded = warm.with_process_wrench(Some(ProcessWrench {
            force_n: Vector3::new(10.0, -40.0, -120.0),
            moment_nmm: Vector3::new(0.0, 500.0, 0.0),
            in_tool_frame: true,
        }));
        let unloaded = warm.with_process_wrench(None);
        let mut next = crate::machine::robot::test_sequence(0x2545_f491_4f6c_dd1d);
        for view in [&r, &loaded, &unloaded] {
            for _ in 0..100 {
                let q: [f64; 6] = std::array::from_fn(|_| next());
                let fast = view.predict_stages(&q, Effects::ALL);
                let slow = stages_reference(view, &q, Effects::ALL);
                let attained = view.predict(&q, Effects::ALL);
                assert_abs_diff_eq!(
                    attained.translation.vector,
                    fast[4].translation.vector,
                    epsilon = SAME
                );
                assert_abs_diff_eq!(
                    attained.rotation.coords,
                    fast[4].rotation.coords,
                    epsilon = SAME
                );
                let f = frames_prepared(view.nominal_prepared(), &q, 6);
                assert_abs_diff_eq!(
                    view.nominal_load_torques(&q),
                    view.gravity_torques_at(&f) + view.process_torques_at(&f),
                    epsilon = SAME
                );
                for (k, (a, b)) in fast.iter().zip(&slow).enumerate() {
                    let (pos, rot) = if k < 3 {
                        (SAME, SAME)
                    } else {
                        (DEFLECTED_POS_MM, DEFLECTED_QUAT)
                    };
                    assert_abs_diff_eq!(a.translation.vector, b.translation.vector, epsilon = pos);
                    assert_abs_diff_eq!(a.rotation.coords, b.rotation.coords, epsilon = rot);
                }
                // Without process torques the process stage is the gravity
                // stage itself.
                if view.process_wrench().is_none() {
                    assert_eq!(fast[4], fast[3]);
                }
            }
        }
    }

    /// A seed with the nominal flange taken from the planning's frames
    /// gives the compensation computed without it, bit for bit.
    #[test]
    fn nominal_flange_seed_equals_the_unseeded_compensation() {
        let r = crate::machine::robot::test_irb1600();
        let growth = r.thermal_growth_mm(&[30.0, 90.0, 40.0, 0.0, 0.0, 0.0]);
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
                let (_, flange) = r.nominal_load_torques_and_flange(&q);
                let plain = Seed {
                    q: Some(q),
                    branch: Some(branch),
                    nominal_flange: None,
                };
                let seeded = Seed {
                    nominal_flange: Some(flange),
                    ..plain
                };
                let a = r.compensate_seeded(&pose, &sel, Effects::ALL, &growth, &plain);
                let b = r.compensate_seeded(&pose, &sel, Effects::ALL, &growth, &seeded);
                assert_eq!(a, b);
                checked += 1;
            }
        }
        assert!(checked >= 3);
    }

    #[test]
    fn growth_override_equals_a_robot_at_that_power() {
        let r = crate::machine::robot::test_irb1600();
        // Warm joints 2 and 3 (W): the thermal section grows row 2's a.
        let p = [0.0, 150.0, 80.0, 0.0, 0.0, 0.0];
        let warm = r.with_thermal_power(&p);
        let growth = r.thermal_growth_mm(&p);
        assert!(growth.iter().flatten().any(|g| *g != 0.0));
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
        let a = warm
            .compensate(&pose, &sel, Effects::ALL)
            .expect("reachable");
        let b = r
            .compensate_with_growth(&pose, &sel, Effects::ALL, &growth)
            .expect("reachable");
        assert_abs_diff_eq!(
            a.pose.translation.vector,
            b.pose.translation.vector,
            epsilon = SAME
        );
        assert_abs_diff_eq!(
            a.deviation.thermal.pos_mm,
            b.deviation.thermal.pos_mm,
            epsilon = SAME
        );
        assert!(a.deviation.thermal.pos_mm.norm() > 0.0);
    }
}
