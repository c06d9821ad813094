//! Inverse kinematics.
//!
//! - Closed form for the nominal model of ABB-style arms (modified DH, joint 1
//!   vertical, shoulder offset `a1`, parallel axes 2 and 3, optional elbow
//!   offset `a3`, spherical wrist): all eight solutions.
//! - ABB confdata `[cf1, cf4, cf6, cfx]` selects one of them and the turns of
//!   joints 1, 4 and 6.
//! - Damped least squares (Newton with a small damping) seeded from a joint
//!   vector, for the actual (non-spherical) model or robots without a closed
//!   form.
//!
//! ## cfx (ABB definition, as implemented)
//! `cfx = 4·b1 + 2·b2 + b3` with
//! - `b1 = 1` when the wrist centre is *behind* axis 1: its component along
//!   the x axis of frame 1 (the direction the shoulder offset points to),
//!   measured from axis 1, is negative;
//! - `b2 = 1` when the wrist centre is *behind* the lower arm: with `u` from
//!   axis 2 to axis 3 and `w` from axis 2 to the wrist centre,
//!   `(u × w) · z2 < 0` (at all joints zero the wrist is in front);
//! - `b3 = 1` when joint 5 is negative (`q5 < 0`; `q5 = 0` counts as positive).
//!
//! `cf1`, `cf4`, `cf6` are the quadrants `floor(q / 90°)` of joints 1, 4, 6
//! (`[0°, 90°) → 0`, `[90°, 180°) → 1`, `[−90°, 0°) → −1`, …).

use std::f64::consts::{FRAC_PI_2, PI};
use std::fmt;

use nalgebra::{Isometry3, Matrix6, UnitQuaternion, Vector3, Vector6};

use super::RobotError;
use super::dh::{Convention, DhParams};
use super::kinematics::{Prepared, frames, jacobian, prepared_transform, wrist_frames};
use super::pose::pose_error;

/// ABB robot configuration data `[cf1, cf4, cf6, cfx]`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct ConfData {
    /// Quadrant of joint 1.
    pub cf1: i32,
    /// Quadrant of joint 4.
    pub cf4: i32,
    /// Quadrant of joint 6.
    pub cf6: i32,
    /// Configuration number 0..=7 (see the module documentation).
    pub cfx: i32,
}

impl fmt::Display for ConfData {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "[{},{},{},{}]", self.cf1, self.cf4, self.cf6, self.cfx)
    }
}

/// Quadrant `floor(q / 90°)` of a joint value in radians.
pub fn quadrant(q: f64) -> i32 {
    (q / FRAC_PI_2).floor() as i32
}

/// Tolerance on the quadrant boundary when matching cf1/cf4/cf6, rad
/// (0.01°): a joint within it of a boundary lies in both quadrants. The
/// quadrant is the controller's (ABB, RAPID reference manual, "Motion and
/// I/O principles", robot configuration: the quarter revolution
/// `int(angle / 90°)` of a positive joint angle, `int(angle / 90°) − 1` of
/// a negative one), and a joint that close to a border is one a target
/// taught or generated there reaches either side of it: joint positions
/// are shown to 0.01° on the FlexPendant, and a written target's
/// resolution (7-decimal quaternions, 3-decimal millimetres) moves the
/// joints that solve it by a few µrad. So a target written with a quadrant
/// at its border is solved in that quadrant (`grammar/rapid.md`,
/// "Configurations").
pub const QUADRANT_TOL_RAD: f64 = 0.01 * std::f64::consts::PI / 180.0;
/// Band within which a joint keeps its programmed quadrant in the confdata
/// written with a compensated target ([`confdata_written`]), rad: well
/// inside [`QUADRANT_TOL_RAD`], the rest being the margin for the written
/// target's resolution. It is larger than the rounding of a joint shown
/// with four decimals of a degree (0.00005° = 8.7e-7 rad): a joint shown as
/// −0.0000° keeps quadrant 0.
pub const QUADRANT_KEEP_RAD: f64 = 1e-6;
/// Tolerance on structural parameters for the closed form.
const STRUCT_TOL: f64 = 1e-9;
/// Position convergence of the numeric solver, mm.
pub const IK_POS_TOL_MM: f64 = 1e-9;
/// Orientation convergence of the numeric solver, rad.
pub const IK_ROT_TOL_RAD: f64 = 1e-12;
/// Iteration limit of the numeric solver.
pub const IK_MAX_ITER: usize = 100;

/// Closed-form geometry extracted from a nominal parameter set.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClosedForm {
    d1: f64,
    a1: f64,
    a2: f64,
    a3: f64,
    d4: f64,
    d6: f64,
    s4: f64,
    alpha3: f64,
    /// `√(a3² + d4²)` and `atan2(d4, a3)`: constants of the elbow triangle
    /// (computed once, the same bits as per solve).
    rho: f64,
    gamma: f64,
    off: [f64; 6],
    /// `Rx(α3)⁻¹`, constant.
    rx3_inv: UnitQuaternion<f64>,
    /// The nominal rows with their twist sines and cosines precomputed
    /// (the rotation of frame 3 of every branch reuses them).
    prep: Prepared,
}

fn near(a: f64, b: f64) -> bool {
    (a - b).abs() <= STRUCT_TOL
}

impl ClosedForm {
    /// Recognises the ABB-style structure; `None` for any other robot.
    pub fn new(p: &DhParams) -> Option<Self> {
        let j = &p.joints;
        let ok = p.convention == Convention::ModifiedDh
            && near(j[0].a_mm, 0.0)
            && near(j[0].alpha_rad, 0.0)
            && near(j[1].alpha_rad, -FRAC_PI_2)
            && near(j[1].d_mm, 0.0)
            && near(j[2].alpha_rad, 0.0)
            && near(j[2].d_mm, 0.0)
            && near(j[3].alpha_rad, -FRAC_PI_2)
            && near(j[4].a_mm, 0.0)
            && near(j[4].alpha_rad.abs(), FRAC_PI_2)
            && near(j[4].d_mm, 0.0)
            && near(j[5].a_mm, 0.0)
            && near(j[5].alpha_rad, -j[4].alpha_rad)
            && j[2].a_mm > 0.0;
        ok.then(|| ClosedForm {
            d1: j[0].d_mm,
            a1: j[1].a_mm,
            a2: j[2].a_mm,
            a3: j[3].a_mm,
            d4: j[3].d_mm,
            d6: j[5].d_mm,
            s4: j[4].alpha_rad.signum(),
            alpha3: j[3].alpha_rad,
            rho: (j[3].a_mm * j[3].a_mm + j[3].d_mm * j[3].d_mm).sqrt(),
            gamma: j[3].d_mm.atan2(j[3].a_mm),
            rx3_inv: UnitQuaternion::from_axis_angle(&Vector3::x_axis(), j[3].alpha_rad).inverse(),
            prep: Prepared::new(p),
            off: [
                j[0].theta_offset_rad,
                j[1].theta_offset_rad,
                j[2].theta_offset_rad,
                j[3].theta_offset_rad,
                j[4].theta_offset_rad,
                j[5].theta_offset_rad,
            ],
        })
    }

    /// All eight solutions for a flange pose in the robot base frame, each in
    /// (−π, π]; `None` where that shoulder/elbow branch cannot reach. Index
    /// bits: 4 = second shoulder branch, 2 = second elbow branch, 1 = wrist
    /// flipped (these are not cfx; use [`confdata`] to classify).
    pub fn solve(&self, flange: &Isometry3<f64>, wrist_ref: f64) -> [Option<[f64; 6]>; 8] {
        let mut out = [None; 8];
        self.solve_until(flange, wrist_ref, |k, q| {
            if let Some(o) = out.get_mut(k) {
                *o = Some(q);
            }
            false
        });
        out
    }

    /// The solutions of [`ClosedForm::solve`] in index order, each passed to
    /// `visit` with its index, until `visit` returns true (the branches
    /// after it are not computed). Returns whether it did.
    pub fn solve_until(
        &self,
        flange: &Isometry3<f64>,
        wrist_ref: f64,
        mut visit: impl FnMut(usize, [f64; 6]) -> bool,
    ) -> bool {
        let pre = self.wrist_centre(flange);
        for sh in 0..2 {
            let Some(arm) = self.shoulder(&pre, sh) else {
                continue;
            };
            for el in 0..2 {
                let (q123, w) = self.elbow(flange, &arm, el, wrist_ref);
                for fl in 0..2 {
                    if visit(sh * 4 + el * 2 + fl, self.wrist(&q123, w, fl)) {
                        return true;
                    }
                }
            }
        }
        false
    }

    /// Solution `k` of [`ClosedForm::solve`] alone (the same arithmetic,
    /// the other branches not computed); `None` where it cannot reach.
    pub fn solve_branch(
        &self,
        flange: &Isometry3<f64>,
        wrist_ref: f64,
        k: usize,
    ) -> Option<[f64; 6]> {
        if k >= 8 {
            return None;
        }
        let pre = self.wrist_centre(flange);
        let arm = self.shoulder(&pre, k / 4)?;
        let (q123, w) = self.elbow(flange, &arm, (k / 2) % 2, wrist_ref);
        Some(self.wrist(&q123, w, k % 2))
    }

    /// Wrist centre, `ρ`, `γ` and the base angle of joint 1.
    fn wrist_centre(&self, flange: &Isometry3<f64>) -> WristCentre {
        let z6 = flange.rotation * Vector3::z();
        let pw = flange.translation.vector - self.d6 * z6;
        let (rho, gamma) = (self.rho, self.gamma);
        let base_t1 = if pw.x.hypot(pw.y) < 1e-9 {
            0.0
        } else {
            pw.y.atan2(pw.x)
        };
        WristCentre {
            pw,
            rho,
            gamma,
            base_t1,
        }
    }

    /// Joint 1 of shoulder branch `sh` and the planar arm problem; `None`
    /// when the wrist centre is out of reach.
    fn shoulder(&self, pre: &WristCentre, sh: usize) -> Option<Arm> {
        let pw = &pre.pw;
        let rho = pre.rho;
        let t1 = pre.base_t1 + if sh == 1 { PI } else { 0.0 };
        let (s1, c1) = t1.sin_cos();
        let r = c1 * pw.x + s1 * pw.y;
        let dr = r - self.a1;
        let dz = pw.z - self.d1;
        let l2 = dr * dr + dz * dz;
        let c = (l2 - self.a2 * self.a2 - rho * rho) / (2.0 * self.a2 * rho);
        if !c.is_finite() || c.abs() > 1.0 + 1e-12 {
            return None;
        }
        let ac = c.clamp(-1.0, 1.0).acos();
        Some(Arm {
            t1,
            dr,
            dz,
            ac,
            gamma: pre.gamma,
        })
    }

    /// Joints 1–3 of elbow branch `el` and the wrist angles `(β, θ4, θ6)`
    /// of the unflipped wrist.
    fn elbow(
        &self,
        flange: &Isometry3<f64>,
        arm: &Arm,
        el: usize,
        wrist_ref: f64,
    ) -> ([f64; 3], (f64, f64, f64)) {
        let Arm {
            t1,
            dr,
            dz,
            ac,
            gamma,
        } = *arm;
        let t3 = if el == 0 { ac } else { -ac } - gamma;
        let (s3, c3) = t3.sin_cos();
        let k1 = self.a2 + self.a3 * c3 - self.d4 * s3;
        let k2 = self.a3 * s3 + self.d4 * c3;
        let phi = dr.atan2(dz) - k2.atan2(k1);
        let t2 = phi - FRAC_PI_2;
        let q123 = [t1 - self.off[0], t2 - self.off[1], t3 - self.off[2]];
        // Rotation of frame 3 from the nominal joint transforms.
        let mut r03 = UnitQuaternion::identity();
        for (j, q) in self.prep.joints().iter().zip(&q123) {
            r03 *= prepared_transform(j, self.prep.convention(), *q).rotation;
        }
        let n = (self.rx3_inv * r03.inverse() * flange.rotation).to_rotation_matrix();
        let n = n.matrix();
        let sb = n[(0, 2)].hypot(n[(1, 2)]);
        let w = if sb < 1e-10 {
            let beta = sb.atan2(n[(2, 2)]);
            let t4 = wrist_ref + self.off[3];
            let ry = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), beta);
            let rz4 = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), t4);
            let m = (ry.inverse() * rz4.inverse()).to_rotation_matrix().matrix() * n;
            (beta, t4, m[(1, 0)].atan2(m[(0, 0)]))
        } else {
            (
                sb.atan2(n[(2, 2)]),
                n[(1, 2)].atan2(n[(0, 2)]),
                n[(2, 1)].atan2(-n[(2, 0)]),
            )
        };
        (q123, w)
    }

    /// The joint vector of wrist branch `fl` (1 = flipped), wrapped.
    fn wrist(&self, q123: &[f64; 3], (beta, t4, t6): (f64, f64, f64), fl: usize) -> [f64; 6] {
        let (b, a4, a6) = if fl == 0 {
            (beta, t4, t6)
        } else {
            (-beta, t4 + PI, t6 + PI)
        };
        let t5 = -self.s4 * b;
        let q = [
            q123[0],
            q123[1],
            q123[2],
            a4 - self.off[3],
            t5 - self.off[4],
            a6 - self.off[5],
        ];
        q.map(wrap)
    }
}

/// The pose-dependent constants of [`ClosedForm::solve_until`].
struct WristCentre {
    pw: Vector3<f64>,
    rho: f64,
    gamma: f64,
    base_t1: f64,
}

/// One shoulder branch of [`ClosedForm::solve_until`].
#[derive(Clone, Copy)]
struct Arm {
    t1: f64,
    dr: f64,
    dz: f64,
    ac: f64,
    gamma: f64,
}

/// Wraps an angle into (−π, π].
pub fn wrap(a: f64) -> f64 {
    // `a % 2π` is `a` itself (exactly) below one turn: no division then.
    let mut x = if a.abs() < 2.0 * PI {
        a
    } else {
        a % (2.0 * PI)
    };
    if x > PI {
        x -= 2.0 * PI;
    } else if x <= -PI {
        x += 2.0 * PI;
    }
    x
}

/// Confdata of a joint vector for a parameter set (normally the nominal one).
pub fn confdata(p: &DhParams, q: &[f64; 6]) -> ConfData {
    confdata_prepared(&Prepared::new(p), q)
}

/// [`confdata`] of a prepared parameter set.
pub(crate) fn confdata_prepared(p: &Prepared, q: &[f64; 6]) -> ConfData {
    // Frames up to link 5 (index 4): the wrist centre and the axes 1–3.
    let f = wrist_frames(p, q);
    // Wrist centre: origin of frame 5 (joints 4–6 intersect there for a
    // spherical wrist).
    let wc = f.wrist_centre;
    let x1 = f.x1;
    let behind1 = (wc - f.axis_origin[0]).dot(&x1) < 0.0;
    let u = f.axis_origin[2] - f.axis_origin[1];
    let w = wc - f.axis_origin[1];
    let behind_arm = u.cross(&w).dot(&f.axis_dir_2) < 0.0;
    let neg5 = q[4] < 0.0;
    ConfData {
        cf1: quadrant(q[0]),
        cf4: quadrant(q[3]),
        cf6: quadrant(q[5]),
        cfx: 4 * behind1 as i32 + 2 * behind_arm as i32 + neg5 as i32,
    }
}

/// Whether joint value `q` (rad) lies in quadrant `cf` by the rule used to
/// match confdata: `[cf·90° − tol, (cf+1)·90° + tol]` with
/// [`QUADRANT_TOL_RAD`].
pub fn in_quadrant(q: f64, cf: i32) -> bool {
    let lo = f64::from(cf) * FRAC_PI_2;
    q >= lo - QUADRANT_TOL_RAD && q <= lo + FRAC_PI_2 + QUADRANT_TOL_RAD
}

/// Whether joint value `q` (rad) keeps the programmed quadrant `cf` in
/// written confdata: `[cf·90° − keep, (cf+1)·90° + keep]` with
/// [`QUADRANT_KEEP_RAD`].
pub fn keeps_quadrant(q: f64, cf: i32) -> bool {
    let lo = f64::from(cf) * FRAC_PI_2;
    q >= lo - QUADRANT_KEEP_RAD && q <= lo + FRAC_PI_2 + QUADRANT_KEEP_RAD
}

/// The confdata to write for a target reached with joints `q` whose own
/// confdata is `own` ([`confdata`]), programmed with `programmed`: each of
/// cf1, cf4, cf6 stays the programmed quadrant while its joint lies in it
/// ([`keeps_quadrant`], so numerical noise at a boundary never changes the
/// written data), else it is the joint's own quadrant (the quadrant the
/// controller finds those joints in); cfx is the solution's. Either way
/// the written target is solved in the written quadrants again
/// ([`in_quadrant`] has the wider tolerance).
pub fn confdata_written(own: ConfData, q: &[f64; 6], programmed: ConfData) -> ConfData {
    let keep = |cf: i32, prog: i32, j: usize| {
        if keeps_quadrant(q[j], prog) { prog } else { cf }
    };
    ConfData {
        cf1: keep(own.cf1, programmed.cf1, 0),
        cf4: keep(own.cf4, programmed.cf4, 3),
        cf6: keep(own.cf6, programmed.cf6, 5),
        cfx: own.cfx,
    }
}

/// Moves `q` by whole turns into quadrant `cf`; `None` when impossible.
pub fn into_quadrant(q: f64, cf: i32) -> Option<f64> {
    let lo = cf as f64 * FRAC_PI_2;
    let k = ((lo + FRAC_PI_2 / 2.0 - q) / (2.0 * PI)).round();
    let v = q + 2.0 * PI * k;
    (v >= lo - QUADRANT_TOL_RAD && v < lo + FRAC_PI_2 + QUADRANT_TOL_RAD).then_some(v)
}

/// Moves `q` by whole turns as close as possible to `reference`.
pub fn nearest_turn(q: f64, reference: f64) -> f64 {
    q + 2.0 * PI * ((reference - q) / (2.0 * PI)).round()
}

/// Largest change of any joint between the programmed and the compensated
/// target, degrees. A correction of a millimetre moves the joints by
/// hundredths of a degree; a larger change is the arm flipping its wrist
/// near a singularity.
pub const JOINT_JUMP_MAX_DEG: f64 = 5.0;

impl super::Robot {
    /// Refuses a compensated solution `q` that moves a joint by more than
    /// [`JOINT_JUMP_MAX_DEG`] from the programmed `q0` or changes the
    /// configuration, unless the robot allows it.
    pub(crate) fn check_reconfiguration(
        &self,
        q0: &[f64; 6],
        q: &[f64; 6],
    ) -> Result<(), RobotError> {
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
thread_local! {
    /// Calls of [`solve_numeric`] on this thread (the cost of a search,
    /// counted by tests).
    pub(crate) static NUMERIC_SOLVES: std::cell::Cell<usize> = const { std::cell::Cell::new(0) };
}

/// Damped least-squares IK of the flange pose (robot base frame) for any
/// parameter set, seeded from `seed`. Rotation rows are weighted by 1000 mm.
pub fn solve_numeric(
    p: &DhParams,
    flange: &Isometry3<f64>,
    seed: &[f64; 6],
) -> Result<[f64; 6], RobotError> {
    const ROT_WEIGHT_MM: f64 = 1000.0;
    const DAMPING_MM2: f64 = 1e-6;
    const MAX_STEP_RAD: f64 = 0.2;
    #[cfg(test)]
    NUMERIC_SOLVES.with(|n| n.set(n.get() + 1));
    let mut q = *seed;
    let mut last = (f64::INFINITY, f64::INFINITY);
    for _ in 0..IK_MAX_ITER {
        let f = frames(p, &q);
        let (dp, dr) = pose_error(flange, &f.flange());
        last = (dp.norm(), dr.norm());
        if last.0 < IK_POS_TOL_MM && last.1 < IK_ROT_TOL_RAD {
            return Ok(q);
        }
        let mut j = jacobian(&f, &Vector3::zeros());
        let mut e = Vector6::zeros();
        e.fixed_rows_mut::<3>(0).copy_from(&dp);
        e.fixed_rows_mut::<3>(3).copy_from(&(dr * ROT_WEIGHT_MM));
        for c in 0..6 {
            for r in 3..6 {
                j[(r, c)] *= ROT_WEIGHT_MM;
            }
        }
        let a: Matrix6<f64> = j * j.transpose() + Matrix6::identity() * DAMPING_MM2;
        let Some(y) = a.lu().solve(&e) else {
            break;
        };
        let mut dq = j.transpose() * y;
        let m = dq.amax();
        if m > MAX_STEP_RAD {
            dq *= MAX_STEP_RAD / m;
        }
        for i in 0..6 {
            q[i] += dq[i];
        }
    }
    Err(RobotError::NoConvergence {
        what: "numeric inverse kinematics",
        iterations: IK_MAX_ITER,
        pos_mm: last.0,
        rot_rad: last.1,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;

    const TOL: f64 = 1e-12;

    /// The shortcut of [`wrap`] below one turn against the remainder it
    /// skips: the same bits, signed zeros and both sides of ±π and ±2π.
    #[test]
    fn wrap_equals_the_remainder_form() {
        let reference = |a: f64| {
            let mut x = a % (2.0 * PI);
            if x > PI {
                x -= 2.0 * PI;
            } else if x <= -PI {
                x += 2.0 * PI;
            }
            x
        };
        let mut cases = vec![0.0, -0.0, PI, -PI, 2.0 * PI, -2.0 * PI, 1e-300, f64::NAN];
        for base in [PI, 2.0 * PI, 3.0 * PI] {
            for s in [1.0, -1.0] {
                let v = s * base;
                cases.extend([v, v.next_up(), v.next_down()]);
            }
        }
        cases.extend((0..2000).map(|k| (f64::from(k) - 1000.0) * 0.0137));
        for a in cases {
            assert_eq!(wrap(a).to_bits(), reference(a).to_bits(), "{a}");
        }
    }

    #[test]
    fn quadrants_follow_abb() {
        // floor(q/90°): 45° → 0, 135° → 1, −1° → −1, −135° → −2, 370° → 4.
        for (deg, cf) in [(45.0, 0), (135.0, 1), (-1.0, -1), (-135.0, -2), (370.0, 4)] {
            assert_eq!(quadrant(f64::to_radians(deg)), cf);
        }
        // 50° moved into quadrant 4 is 410°; into quadrant 1 impossible.
        assert_abs_diff_eq!(
            into_quadrant(50f64.to_radians(), 4).unwrap_or(0.0),
            410f64.to_radians(),
            epsilon = TOL
        );
        assert!(into_quadrant(50f64.to_radians(), 1).is_none());
        assert_abs_diff_eq!(wrap(3.0 * PI), PI, epsilon = TOL);
        assert_abs_diff_eq!(nearest_turn(0.1, 2.0 * PI), 0.1 + 2.0 * PI, epsilon = TOL);
    }
}
