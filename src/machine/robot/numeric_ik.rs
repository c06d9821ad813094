//! Inverse kinematics with ABB confdata for robots without a closed form
//! (the nominal model is not an ABB-style arm, e.g. the Stäubli TX200).
//!
//! The damped least-squares solver of [`ik::solve_numeric`] reaches one
//! solution from a seed joint vector, to the same position and orientation
//! tolerance as the closed form ([`ik::IK_POS_TOL_MM`],
//! [`ik::IK_ROT_TOL_RAD`]). A solution is accepted for a target when it
//! lies in the target's configuration: its `cfx` (as
//! [`ik::confdata`] classifies it from the robot's own geometry) equals the
//! target's, and joints 1, 4 and 6 can be put by whole turns into the
//! quadrants `cf1`, `cf4`, `cf6` (with [`ik::QUADRANT_TOL_RAD`] at the
//! boundaries) and within the joint limits. Joints 2, 3 and 5 take the turn
//! that lies inside their limits, as with the closed form.
//!
//! ## Seeds
//! Tried in this order, the first accepted solution wins:
//! 1. the caller's reference, when given — the joints of the previous step
//!    of the compensation iteration on the same target — and its
//!    wrist-flipped twin (`q4 + 180°`, `−q5`, `q6 + 180°`). What the solver
//!    reaches from there is accepted by a wider test: the target's `cfx`,
//!    the joint limits, and joints 1, 4, 6 within half a turn of the middle
//!    of their quadrants, so that an iteration may carry a joint across a
//!    quadrant boundary (as the closed form's nearest turn does) but never
//!    to another turn;
//! 2. a fixed list derived from the target alone: joint 1 towards the wrist
//!    centre (in front of axis 1, then behind it, the order set by the
//!    `cfx` bit of the shoulder), joints 2 and 3 on a grid of ±0.3, ±1.0,
//!    ±2.0 and ±0.4, ±1.2, ±2.2 rad (the outer values for arms whose
//!    joints 2 and 3 turn far back, such as the GoFa),
//!    joints 4 and 6 in the middle of their confdata quadrants and joint 5
//!    at ±0.8 rad by the sign bit of `cfx`; each with its wrist flip.
//!
//! Within one configuration a 6R arm with a spherical wrist has a single
//! solution (the shoulder, elbow and wrist branches are fixed by `cfx`, the
//! turns by the quadrants), so the seed decides how fast the solver gets
//! there, not where: the result is the same for every seed that converges,
//! and deterministic. The list needs no allocation; only a refusal that
//! is shown builds its message (the configurations that do reach the
//! target, a seed search per configuration): a module refused at its first
//! target searches them once, however many of its targets are refused.

use std::f64::consts::{FRAC_PI_2, FRAC_PI_4, PI};

use nalgebra::{Isometry3, Vector3};

use super::ik::{self, ConfData};
use super::{Model, Robot, RobotError};

/// Joint 2 starting values of the seed list, rad.
const Q2_SEEDS_RAD: [f64; 6] = [0.3, -0.3, 1.0, -1.0, 2.0, -2.0];
/// Joint 3 starting values of the seed list, rad.
const Q3_SEEDS_RAD: [f64; 6] = [0.4, -0.4, 1.2, -1.2, 2.2, -2.2];
/// Seeds in the list: two for joint 1 times those of joints 2 and 3.
const SEEDS: usize = 2 * Q2_SEEDS_RAD.len() * Q3_SEEDS_RAD.len();
/// Magnitude of the joint 5 seed, rad (away from the wrist singularity).
const WRIST_SEED_RAD: f64 = 0.8;

/// Distance of the wrist centre from axis 1 below which it counts as on the
/// axis, mm: there joint 1 has no direction towards the wrist centre and
/// its seed is 0. Any value well below the arm's dimensions does; a
/// nanometre is far below them and far above the rounding of `atan2`'s
/// arguments.
const ON_AXIS_1_MM: f64 = 1e-9;

/// The configurations of a refusal that did not look for them.
pub(crate) const UNLISTED: &str = "not listed";

/// Starts of one seed search: the seed list and each seed's wrist flip.
#[cfg(test)]
pub(crate) const STARTS: usize = 2 * SEEDS;

/// Configurations probed by a listing of the reaching ones (every `cfx`).
#[cfg(test)]
pub(crate) const LISTED_CFX: usize = 8;

#[cfg(test)]
thread_local! {
    /// Listings of reaching configurations made on this thread (the cost of
    /// refusals, counted by tests).
    pub(crate) static LISTINGS: std::cell::Cell<usize> = const { std::cell::Cell::new(0) };
}

/// What the seeds found for a refused target.
enum Found {
    /// No seed converged to any solution.
    Nothing,
    /// Solutions exist, none in the asked configuration (or within the
    /// limits there).
    Elsewhere,
}

impl Robot {
    /// Nominal inverse kinematics of a TCP pose (world frame) in the
    /// configuration `conf` and within the joint limits, by the numeric
    /// solver (see the module documentation). With `turn_ref` (the joints
    /// of the previous step of an iteration on one target), the solver
    /// starts there first; what it converges to is accepted when it has
    /// the asked `cfx`, lies within the limits, and has joints 1, 4, 6 in
    /// the turns the quadrants name (possibly past a quadrant boundary,
    /// never a turn away); otherwise the seed list decides.
    ///
    /// A refusal does not list the configurations that reach the target
    /// (`available` is [`UNLISTED`]): that list costs a seed search per
    /// configuration, and most refusals are never shown (a move's plan,
    /// every target of a module refused at its first). The refusal that
    /// is shown gets it from [`Robot::with_reaching_configurations`].
    pub(crate) fn ik_conf_numeric(
        &self,
        tcp_world: &Isometry3<f64>,
        conf: ConfData,
        turn_ref: Option<&[f64; 6]>,
    ) -> Result<[f64; 6], RobotError> {
        let flange = self.flange_for_tcp(tcp_world);
        let params = self.params(Model::Nominal);
        if let Some(r) = turn_ref {
            for seed in [*r, wrist_flip(r)] {
                let Ok(q) = ik::solve_numeric(params, &flange, &seed) else {
                    continue;
                };
                if self.in_turns(&q, conf) {
                    return Ok(q);
                }
            }
        }
        let mut found = Found::Nothing;
        for seed in self.conf_seeds(&flange, conf) {
            for start in [seed, wrist_flip(&seed)] {
                let Ok(q) = ik::solve_numeric(params, &flange, &start) else {
                    continue;
                };
                found = Found::Elsewhere;
                if let Some(q) = self.in_configuration(&q, conf) {
                    return Ok(q);
                }
            }
        }
        Err(match found {
            Found::Nothing => RobotError::Unreachable(
                "no joint solution: the numeric inverse kinematics converged from none of its seeds"
                    .into(),
            ),
            Found::Elsewhere => RobotError::ConfMismatch {
                conf,
                available: UNLISTED.to_string(),
            },
        })
    }

    /// `e` with the configurations that reach `tcp_world` listed, when it
    /// is a refusal of the numeric inverse that did not list them
    /// ([`Robot::ik_conf_numeric`]); any other error as it is. For the
    /// refusal shown to the user: one seed search per configuration.
    pub(crate) fn with_reaching_configurations(
        &self,
        tcp_world: &Isometry3<f64>,
        e: RobotError,
    ) -> RobotError {
        match e {
            RobotError::ConfMismatch { conf, available } if available == UNLISTED => {
                RobotError::ConfMismatch {
                    conf,
                    available: self.reachable_configurations(&self.flange_for_tcp(tcp_world)),
                }
            }
            e => e,
        }
    }

    /// Whether `q` has the `cfx` of `conf`, lies within the joint limits,
    /// and has joints 1, 4 and 6 in the turns that the quadrants `cf1`,
    /// `cf4`, `cf6` name: within half a turn of the middle of their
    /// quadrant. A joint may so lie past a quadrant boundary (an iteration
    /// moving it across one, whose confdata is then written with the
    /// joint's own quadrant), never a whole turn away.
    fn in_turns(&self, q: &[f64; 6], conf: ConfData) -> bool {
        self.confdata(q).cfx == conf.cfx
            && [(0, conf.cf1), (3, conf.cf4), (5, conf.cf6)]
                .iter()
                .all(|&(i, c)| (q[i] - quadrant_middle(c)).abs() <= PI)
            && self.check_limits(q).is_ok()
    }

    /// `q` moved by whole turns into the configuration `conf` and the joint
    /// limits; `None` when its `cfx` differs or no turn fits.
    fn in_configuration(&self, q: &[f64; 6], conf: ConfData) -> Option<[f64; 6]> {
        let mut q = q.map(ik::wrap);
        if self.confdata(&q).cfx != conf.cfx {
            return None;
        }
        for (i, c) in [(0, conf.cf1), (3, conf.cf4), (5, conf.cf6)] {
            q[i] = ik::into_quadrant(q[i], c)?;
        }
        for i in [1, 2, 4] {
            let [lo, hi] = self.d.limits_rad[i];
            for t in [0.0, -2.0 * PI, 2.0 * PI] {
                if (lo..=hi).contains(&(q[i] + t)) {
                    q[i] += t;
                    break;
                }
            }
        }
        self.check_limits(&q).ok().map(|()| q)
    }

    /// The seed list of a flange pose (robot base frame) and confdata.
    fn conf_seeds(&self, flange: &Isometry3<f64>, conf: ConfData) -> [[f64; 6]; SEEDS] {
        let d6 = self.params(Model::Nominal).joints[5].d_mm;
        let pw = flange.translation.vector - d6 * (flange.rotation * Vector3::z());
        let toward = if pw.x.hypot(pw.y) < ON_AXIS_1_MM {
            0.0
        } else {
            pw.y.atan2(pw.x)
        };
        let behind = conf.cfx & 4 != 0;
        let q1s = if behind {
            [toward + PI, toward]
        } else {
            [toward, toward + PI]
        };
        let q5 = if conf.cfx & 1 != 0 {
            -WRIST_SEED_RAD
        } else {
            WRIST_SEED_RAD
        };
        let n = Q2_SEEDS_RAD.len() * Q3_SEEDS_RAD.len();
        std::array::from_fn(|k| {
            let (q2, q3) = (
                Q2_SEEDS_RAD[(k % n) / Q3_SEEDS_RAD.len()],
                Q3_SEEDS_RAD[k % Q3_SEEDS_RAD.len()],
            );
            [
                q1s[k / n],
                q2,
                q3,
                quadrant_middle(conf.cf4),
                q5,
                quadrant_middle(conf.cf6),
            ]
        })
    }

    /// The configurations (confdata, turns within the limits) of the
    /// solutions the seed list reaches, for a refusal's message.
    fn reachable_configurations(&self, flange: &Isometry3<f64>) -> String {
        #[cfg(test)]
        LISTINGS.with(|n| n.set(n.get() + 1));
        let params = self.params(Model::Nominal);
        let mut confs: Vec<ConfData> = Vec::new();
        for cfx in 0..8 {
            let probe = ConfData {
                cf1: 0,
                cf4: 0,
                cf6: 0,
                cfx,
            };
            for seed in self.conf_seeds(flange, probe) {
                for start in [seed, wrist_flip(&seed)] {
                    let Ok(q) = ik::solve_numeric(params, flange, &start) else {
                        continue;
                    };
                    let q = q.map(ik::wrap);
                    if self.check_limits(&q).is_ok() {
                        let c = self.confdata(&q);
                        if !confs.contains(&c) {
                            confs.push(c);
                        }
                    }
                }
            }
        }
        confs.sort_by_key(|c| (c.cfx, c.cf1, c.cf4, c.cf6));
        if confs.is_empty() {
            return "none within the joint limits".into();
        }
        confs
            .iter()
            .map(ToString::to_string)
            .collect::<Vec<_>>()
            .join(" ")
    }
}

/// The middle of quadrant `cf` of a joint, rad.
fn quadrant_middle(cf: i32) -> f64 {
    f64::from(cf) * FRAC_PI_2 + FRAC_PI_4
}

/// The other wrist solution of the same flange pose for a spherical wrist.
fn wrist_flip(q: &[f64; 6]) -> [f64; 6] {
    [q[0], q[1], q[2], q[3] + PI, -q[4], q[5] + PI]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::machine::robot::pose::pose_error;

    /// Joint agreement of two solutions of one configuration, rad (the
    /// solver's convergence, amplified by the arm's conditioning).
    const SAME_JOINTS_RAD: f64 = 1e-7;
    /// Distance from a quadrant boundary of joints 1, 4, 6 below which a
    /// random joint vector is skipped, in quarter turns (0.09°): far
    /// enough that the solution's quadrant is the generating one's beyond
    /// doubt ([`ik::QUADRANT_TOL_RAD`] is 9 times smaller).
    const AWAY_FROM_BOUNDARY_QUARTERS: f64 = 1e-3;
    /// Joints 3 and 5 closer to 0 than this are skipped, rad (the elbow
    /// and wrist singularities, where the arm's conditioning spoils the
    /// joint agreement).
    const AWAY_FROM_SINGULAR_RAD: f64 = 0.05;

    fn tx200() -> Robot {
        let text = include_str!("../../../machines/staubli-tx200.yaml");
        Robot::from_yaml_str(text, "staubli-tx200.yaml").expect("bundled file")
    }

    /// Random joint vectors inside the limits (away from the wrist
    /// singularity and from quadrant boundaries): the solution found for
    /// their pose and confdata, from no seed, is the same joint vector, and
    /// its forward kinematics is the pose within the solver's tolerance.
    #[test]
    fn tx200_solution_in_the_configuration_is_the_generating_one() {
        let r = tx200();
        let mut next = crate::machine::robot::test_sequence(0x05ee_d0f7_a200);
        let l = *r.joint_limits_rad();
        let mut checked = 0;
        while checked < 200 {
            let q: [f64; 6] = std::array::from_fn(|i| {
                l[i][0] + 0.05 + (l[i][1] - l[i][0] - 0.1) * (next() + 1.0) / 2.0
            });
            let near_boundary = [0, 3, 5].iter().any(|&i| {
                (q[i] / FRAC_PI_2 - (q[i] / FRAC_PI_2).round()).abs() < AWAY_FROM_BOUNDARY_QUARTERS
            });
            if q[4].abs() < AWAY_FROM_SINGULAR_RAD
                || q[2].abs() < AWAY_FROM_SINGULAR_RAD
                || near_boundary
            {
                continue;
            }
            let pose = r.tcp_pose(Model::Nominal, &q);
            let conf = r.confdata(&q);
            let got = r
                .ik_conf(&pose, conf)
                .expect("the generating solution exists");
            let (dp, dr) = pose_error(&pose, &r.tcp_pose(Model::Nominal, &got));
            assert!(
                dp.norm() < ik::IK_POS_TOL_MM && dr.norm() < ik::IK_ROT_TOL_RAD,
                "{dp} {dr}"
            );
            for i in 0..6 {
                assert!((got[i] - q[i]).abs() < SAME_JOINTS_RAD, "{q:?} {got:?}");
            }
            assert_eq!(r.confdata(&got), conf);
            checked += 1;
        }
    }

    /// A configuration that does not reach the pose is refused with the
    /// configurations that do.
    #[test]
    fn tx200_refusal_names_the_reaching_configurations() {
        let r = tx200();
        let q = [0.3, 0.4, 1.2, 0.5, 0.7, 0.2];
        let pose = r.tcp_pose(Model::Nominal, &q);
        let own = r.confdata(&q);
        // Joint 6 half a turn away: the wrist's other solution has it,
        // with the other sign of joint 5 (another cfx).
        let other = ConfData {
            cf6: own.cf6 + 2,
            ..own
        };
        match r.ik_conf(&pose, other) {
            Err(RobotError::ConfMismatch { conf, available }) => {
                assert_eq!(conf, other);
                assert!(available.contains(&own.to_string()), "{available}");
            }
            e => panic!("expected a configuration mismatch, got {e:?}"),
        }
    }

    /// A refusal of the numeric inverse does not search the configurations
    /// that reach the target; the refusal shown to the user (`ik_conf`, or
    /// one completed by `with_reaching_configurations`) does.
    #[test]
    fn only_the_shown_refusal_lists_the_reaching_configurations() {
        let r = tx200();
        let q = [0.3, 0.4, 1.2, 0.5, 0.7, -2.0];
        let pose = r.tcp_pose(Model::Nominal, &q);
        let mut other = r.confdata(&q);
        other.cfx ^= 1;
        let available = |e: &RobotError| match e {
            RobotError::ConfMismatch { available, .. } => available.clone(),
            e => panic!("{e}"),
        };
        let before = LISTINGS.with(std::cell::Cell::get);
        let plan = r.ik_conf_indexed(&pose, other).expect_err("other cfx");
        let unlisted = r
            .ik_conf_numeric(&pose, other, None)
            .expect_err("other cfx");
        assert_eq!(available(&plan), UNLISTED);
        assert_eq!(available(&unlisted), UNLISTED);
        assert_eq!(LISTINGS.with(std::cell::Cell::get), before);
        let shown = r.ik_conf(&pose, other).expect_err("other cfx");
        let completed = r.with_reaching_configurations(&pose, unlisted);
        assert_eq!(LISTINGS.with(std::cell::Cell::get), before + 2);
        assert!(
            available(&shown).contains(&r.confdata(&q).to_string()),
            "{shown}"
        );
        assert_eq!(available(&completed), available(&shown));
    }

    /// With a reference one turn away on joint 6 (still within its
    /// limits), the solver converges there, but that turn lies outside the
    /// target's quadrant `cf6`: the solution is the one in the quadrant.
    #[test]
    fn tx200_reference_a_turn_off_keeps_the_quadrant() {
        let r = tx200();
        let q = [0.3, 0.4, 1.2, 0.5, 0.7, -2.0];
        let pose = r.tcp_pose(Model::Nominal, &q);
        let conf = r.confdata(&q);
        let mut reference = q;
        reference[5] += 2.0 * PI;
        assert!(r.check_limits(&reference).is_ok(), "a reachable turn");
        let got = r
            .ik_conf_numeric(&pose, conf, Some(&reference))
            .expect("the target's own solution exists");
        assert_eq!(r.confdata(&got), conf, "{got:?}");
        for i in 0..6 {
            assert!((got[i] - q[i]).abs() < SAME_JOINTS_RAD, "{q:?} {got:?}");
        }
    }
}
