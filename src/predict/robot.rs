//! Prediction of one robot target: where the arm really goes for commanded
//! joints, split by effect.
//!
//! The controller turns a programmed TCP pose into joints with its NOMINAL
//! model (closed-form IK with confdata, or numeric IK from a seed). The real
//! arm then reaches
//! `base · FK_actual(q + Kθ⁻¹ (τ_gravity(q) + τ_process(q))) · tool`.
//! Small-deflection form: the torques are evaluated at the commanded joints
//! `q` of the actual model, not at the deflected ones (second-order effect).
//! The inverse (the commanded pose whose prediction is the programmed one)
//! is solved in the compensation layer (`src/compensate/robot.rs`).
//!
//! The robot model is immutable: the process wrench, the joint powers of
//! the thermal stage and the tooth frequency of the vibration report come
//! per move in a [`MoveContext`] ([`Robot::file_context`] for a move that
//! only has the file's own).

use nalgebra::{Isometry3, Vector3, Vector6};

use super::context::{MoveContext, Wrench};
pub use super::effect::{Breakdown, EffectSet, PoseDelta};
use crate::machine::robot::dh::DhParams;
use crate::machine::robot::kinematics::{
    Frames, HalfAngles, Prepared, flange_deflected, flange_prepared, frames_and_twin_flange,
    frames_with_half_angles,
};
use crate::machine::robot::thermal::{DhGrowth, grown};
use crate::machine::robot::{Model, Robot};

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

/// True when two vectors are equal bit for bit (a computation from them
/// gives the same bits).
fn same_bits(a: &Vector6<f64>, b: &Vector6<f64>) -> bool {
    a.iter()
        .zip(b.iter())
        .all(|(x, y)| x.to_bits() == y.to_bits())
}

impl Robot {
    /// The context of a move with only what the robot file gives: its
    /// constant process wrench in the tool or base frame, if any, the
    /// tooth frequency of its spindle speed, cold joints.
    pub fn file_context(&self) -> MoveContext {
        let pf = self.process_force();
        MoveContext {
            wrench: self.file_wrench(),
            spindle_rpm: pf.and_then(|p| p.spindle_rpm).unwrap_or(0.0),
            tooth_hz: pf.and_then(|p| p.excitation_hz()).unwrap_or(0.0),
            ..MoveContext::default()
        }
    }

    /// DH growth of the thermal stage for the joint powers of `ctx`, mm.
    pub fn growth_of(&self, ctx: &MoveContext) -> DhGrowth {
        self.thermal_growth_mm(&ctx.joint_powers_w())
    }

    /// The kinematic (calibrated, blended) and the full (kinematic plus
    /// thermal growth) parameter sets of a prediction. Resolved once per
    /// target: every iteration reuses them.
    fn prediction_params(&self, effects: EffectSet, growth: &DhGrowth) -> (DhParams, DhParams) {
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
    pub(crate) fn prediction_prepared(
        &self,
        effects: EffectSet,
        growth: &DhGrowth,
    ) -> (Prepared, Prepared) {
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
    fn load_torques(
        &self,
        f: &Frames,
        effects: EffectSet,
        wrench: Option<&Wrench>,
    ) -> (Vector6<f64>, Vector6<f64>) {
        let tau_g = if effects.gravity != 0.0 {
            self.gravity_torques_at(f) * effects.gravity
        } else {
            Vector6::zeros()
        };
        let tau = if effects.process != 0.0 {
            if Robot::process_torques_vanish(&tau_g, effects.process, wrench) {
                tau_g
            } else {
                tau_g + self.process_torques_at(f, wrench) * effects.process
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
    pub(crate) fn predict_with(
        &self,
        model: &Prepared,
        q: &[f64; 6],
        effects: EffectSet,
        wrench: Option<&Wrench>,
    ) -> Isometry3<f64> {
        let (f, half) = frames_with_half_angles(model, q);
        let (tau_g, tau) = self.load_torques(&f, effects, wrench);
        if effects.process != 0.0 {
            self.deflected_tcp(model, q, &half, &tau)
        } else if effects.gravity != 0.0 {
            self.deflected_tcp(model, q, &half, &tau_g)
        } else {
            self.tcp_of(&f.flange())
        }
    }

    /// Predicted attained TCP pose (world frame) for controller joints `q`
    /// in the move context `ctx`, with the intermediate poses `[nominal,
    /// +kinematic, +thermal, +gravity, +process]` in that order (the last
    /// is the attained pose).
    pub fn predict_stages(
        &self,
        ctx: &MoveContext,
        q: &[f64; 6],
        effects: EffectSet,
    ) -> [Isometry3<f64>; 5] {
        let (kin, model) = self.prediction_prepared(effects, &self.growth_of(ctx));
        self.stages_from(&kin, &model, q, effects, ctx.wrench.as_ref(), None)
    }

    /// [`Robot::predict_stages`] with the parameter sets resolved, the
    /// process wrench `wrench` and the nominal flange pose at `q`, when
    /// already known (the flange of `frames_prepared(nominal, q, 6)`, the
    /// same bits as [`flange_prepared`]).
    pub(crate) fn stages_from(
        &self,
        kin: &Prepared,
        model: &Prepared,
        q: &[f64; 6],
        effects: EffectSet,
        wrench: Option<&Wrench>,
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
        let (tau_g, tau) = self.load_torques(&f, effects, wrench);
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
    /// at controller joints `q`: the process force of `ctx` taken as a
    /// harmonic force at its tooth-passing frequency, through the modal
    /// model. Zero without a modal model, a tooth frequency or a process
    /// wrench.
    pub fn vibration_mm(
        &self,
        ctx: &MoveContext,
        q: &[f64; 6],
        effects: EffectSet,
    ) -> Vector3<f64> {
        let (Some(modal), true) = (self.modal(), ctx.tooth_hz > 0.0) else {
            return Vector3::zeros();
        };
        let Some(wrench) = ctx.wrench.as_ref().filter(|_| effects.dynamic != 0.0) else {
            return Vector3::zeros();
        };
        let w = self.process_wrench_base(Model::Nominal, q, Some(wrench));
        let f_base = Vector3::new(w[0], w[1], w[2]);
        modal.amplitude_mm(&f_base, ctx.tooth_hz) * effects.dynamic
    }

    /// Predicted attained TCP pose (world frame) for controller joints `q`
    /// in the move context `ctx`.
    pub fn predict(&self, ctx: &MoveContext, q: &[f64; 6], effects: EffectSet) -> Isometry3<f64> {
        let (_, model) = self.prediction_prepared(effects, &self.growth_of(ctx));
        self.predict_with(&model, q, effects, ctx.wrench.as_ref())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::machine::robot::kinematics::frames_prepared;
    use crate::predict::context::WrenchFrame;
    use approx::assert_abs_diff_eq;

    /// Both paths run the same arithmetic: equal to the last bit.
    const SAME: f64 = 0.0;

    /// [`Robot::stages_from`] without its shortcuts (shared kinematic and
    /// full chains, the process stage reused without process torques,
    /// process torques skipped without a process wrench): every stage from
    /// its own forward kinematics and the full load torques.
    fn stages_reference(
        r: &Robot,
        ctx: &MoveContext,
        q: &[f64; 6],
        effects: EffectSet,
    ) -> [Isometry3<f64>; 5] {
        let (kin, model) = r.prediction_prepared(effects, &r.growth_of(ctx));
        let wrench = ctx.wrench.as_ref();
        let p0 = r.tcp_of(&flange_prepared(r.nominal_prepared(), q));
        let p1 = r.tcp_of(&flange_prepared(&kin, q));
        let f = frames_prepared(&model, q, 6);
        let p2 = r.tcp_of(&f.flange());
        let tau_g = r.gravity_torques_at(&f) * effects.gravity;
        let tau_w = r.process_torques_at(&f, wrench) * effects.process;
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
        let view = crate::machine::robot::test_irb1600();
        let warm = MoveContext::default().with_joint_powers([20.0, 150.0, 80.0, 0.0, 0.0, 0.0]);
        let loaded = warm.with_wrench(Some(Wrench {
            force_n: Vector3::new(10.0, -40.0, -120.0),
            moment_nmm: Vector3::new(0.0, 500.0, 0.0),
            frame: WrenchFrame::Tool,
        }));
        let unloaded = warm.with_wrench(None);
        let mut next = crate::machine::robot::test_sequence(0x2545_f491_4f6c_dd1d);
        for ctx in [view.file_context(), loaded, unloaded] {
            let wrench = ctx.wrench.as_ref();
            for _ in 0..100 {
                let q: [f64; 6] = std::array::from_fn(|_| next());
                let fast = view.predict_stages(&ctx, &q, EffectSet::ALL);
                let slow = stages_reference(&view, &ctx, &q, EffectSet::ALL);
                let attained = view.predict(&ctx, &q, EffectSet::ALL);
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
                    view.nominal_load_torques(&q, wrench),
                    view.gravity_torques_at(&f) + view.process_torques_at(&f, wrench),
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
                if wrench.is_none() {
                    assert_eq!(fast[4], fast[3]);
                }
            }
        }
    }
}
