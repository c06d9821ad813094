//! Integration tests: robot configurations (ABB confdata) as the
//! controller handles them — quadrant boundaries with their tolerance, the
//! confdata written with a compensated target, the configuration branch kept
//! by compensation, and the configurations named when a target has no
//! solution in its own. Both bundled robots: the IRB 1600 (closed form) and
//! the TX200 (numeric inverse).

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use postproc::machine::robot::ik::{
    QUADRANT_KEEP_RAD, QUADRANT_TOL_RAD, confdata_written, in_quadrant, keeps_quadrant, quadrant,
};
use postproc::machine::robot::pose::pose_error;
use postproc::machine::robot::{ConfData, IkSelect, Model, PointMass, Robot, RobotError};
use postproc::predict::EffectSet;
use postproc::predict::MoveContext;

use crate::common::repo;

/// FK(IK(pose)) agreement, mm and rad (the solvers converge to 1e-9 mm and
/// 1e-12 rad; the closed form is exact to rounding).
const IK_POS_TOL_MM: f64 = 1e-6;
const IK_ROT_TOL_RAD: f64 = 1e-9;
/// Agreement of two solutions of one configuration, rad.
const SAME_JOINTS_RAD: f64 = 1e-7;
/// Largest joint motion of a compensation of these targets, rad (their
/// predicted deviation is below 2 mm at over 0.5 m from every axis).
const CONTINUOUS_RAD: f64 = 0.01;

fn load(name: &str) -> Robot {
    let text = std::fs::read_to_string(repo(&format!("machines/{name}.yaml"))).expect("file");
    Robot::from_yaml_str(&text, name).expect("valid")
}

/// Both bundled robots with the samples' spindle (182.5 mm, 2.4 kg).
fn robots() -> [(&'static str, Robot); 2] {
    let spindle = |r: Robot| {
        r.with_tool(
            Isometry3::translation(0.0, 0.0, 182.5),
            Some(PointMass {
                mass_kg: 2.4,
                com_mm: Vector3::new(0.0, 0.0, 85.0),
            }),
        )
    };
    [
        ("abb-irb1600", spindle(load("abb-irb1600"))),
        ("staubli-tx200", spindle(load("staubli-tx200"))),
    ]
}

/// Tool pointing down at (x, y, z), world frame.
fn down(x: f64, y: f64, z: f64) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(x, y, z),
        UnitQuaternion::from_axis_angle(&Vector3::y_axis(), std::f64::consts::PI),
    )
}

/// A reachable point for each robot, straight ahead of axis 1 (y = 0:
/// joint 1 at 0, joints 4 and 6 at 0 with the tool pointing down).
fn ahead(name: &str) -> Isometry3<f64> {
    match name {
        "abb-irb1600" => down(750.0, 0.0, 400.0),
        _ => down(1300.0, 0.0, 400.0),
    }
}

const ZERO: ConfData = ConfData {
    cf1: 0,
    cf4: 0,
    cf6: 0,
    cfx: 0,
};

/// The quadrant rule at its boundaries: a joint within
/// `QUADRANT_TOL_RAD` of a boundary lies in both quadrants; beyond it, in
/// one. A joint shown as −0.0000° is in quadrant 0.
#[test]
fn quadrant_boundaries_carry_the_tolerance() {
    let shown_as_minus_zero = -0.00004f64.to_radians();
    assert_eq!(quadrant(shown_as_minus_zero), -1, "the bare floor");
    assert!(in_quadrant(shown_as_minus_zero, 0));
    assert!(in_quadrant(shown_as_minus_zero, -1));
    assert!(in_quadrant(-0.5 * QUADRANT_TOL_RAD, 0));
    assert!(!in_quadrant(-2.0 * QUADRANT_TOL_RAD, 0));
    assert!(in_quadrant(-2.0 * QUADRANT_TOL_RAD, -1));
    let ninety = std::f64::consts::FRAC_PI_2;
    assert!(in_quadrant(ninety + 0.5 * QUADRANT_TOL_RAD, 0));
    assert!(!in_quadrant(ninety + 2.0 * QUADRANT_TOL_RAD, 0));
    assert!(in_quadrant(ninety + 2.0 * QUADRANT_TOL_RAD, 1));
    // The written quadrant is kept within the narrower band.
    assert!(keeps_quadrant(shown_as_minus_zero, 0));
    assert!(!keeps_quadrant(-2.0 * QUADRANT_KEEP_RAD, 0));
}

/// A target whose joints 1, 4 and 6 come out at (or a rounding below) zero
/// is solved in its programmed quadrants 0, on both robots, and the
/// confdata written for those joints stays `[0,0,0,cfx]`.
#[test]
fn joints_at_minus_zero_solve_in_quadrant_zero() {
    for (name, r) in robots() {
        let pose = ahead(name);
        let q = r
            .ik_conf(&pose, ZERO)
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        for j in [0, 3, 5] {
            assert!(
                q[j].abs() < QUADRANT_TOL_RAD,
                "{name}: joint {} {}",
                j + 1,
                q[j]
            );
        }
        // The same joints nudged to just below zero.
        let mut nudged = q;
        for j in [0, 3, 5] {
            nudged[j] = -0.5 * QUADRANT_KEEP_RAD;
        }
        let own = r.confdata(&nudged);
        assert_eq!(
            (own.cf1, own.cf4, own.cf6),
            (-1, -1, -1),
            "{name}: bare floor"
        );
        assert_eq!(confdata_written(own, &nudged, ZERO), ZERO, "{name}");
        let p = r.tcp_pose(Model::Nominal, &nudged);
        let again = r
            .ik_conf(&p, ZERO)
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        for j in 0..6 {
            assert!(
                (again[j] - nudged[j]).abs() < SAME_JOINTS_RAD,
                "{name}: {again:?}"
            );
        }
        // Beyond the tolerance the programmed quadrant does not hold.
        let mut beyond = q;
        beyond[0] = -1e-3;
        let p = r.tcp_pose(Model::Nominal, &beyond);
        assert!(
            matches!(r.ik_conf(&p, ZERO), Err(RobotError::ConfMismatch { .. })),
            "{name}"
        );
        let c = ConfData { cf1: -1, ..ZERO };
        assert!(r.ik_conf(&p, c).is_ok(), "{name}");
    }
}

/// Compensation keeps the configuration branch: targets around joint 1 = 0
/// (y from −0.5 to 0.5 mm) compensate to joints continuous with the
/// nominal ones (same cfx, every joint within a small motion), and the
/// written confdata is the controller's for them — solving the written
/// pose with the written confdata gives back the compensated joints. Where
/// a joint stays in its programmed quadrant (within the tolerance) the
/// written quadrant is the programmed one.
#[test]
fn compensation_keeps_the_branch_and_writes_the_controllers_confdata() {
    for (name, r) in robots() {
        let base = ahead(name);
        for k in -5..=5 {
            let y = f64::from(k) * 0.1;
            let programmed = Isometry3::from_parts(
                Translation3::new(base.translation.x, y, base.translation.z),
                base.rotation,
            );
            // Its configuration: joints 1 and 6 in quadrant 0 or −1.
            let conf = [(0, 0), (-1, 0), (0, -1), (-1, -1)]
                .map(|(cf1, cf6)| ConfData { cf1, cf6, ..ZERO })
                .into_iter()
                .find(|c| r.ik_conf(&programmed, *c).is_ok())
                .unwrap_or_else(|| panic!("{name} y {y}: reachable"));
            let c = r
                .compensate(
                    &MoveContext::default(),
                    &programmed,
                    &IkSelect::Conf(conf),
                    EffectSet::ALL,
                )
                .unwrap_or_else(|e| panic!("{name} y {y}: {e}"));
            assert_eq!(c.conf.cfx, conf.cfx, "{name} y {y}");
            for j in 0..6 {
                let d = (c.q_compensated[j] - c.q_programmed[j]).abs();
                assert!(
                    d < CONTINUOUS_RAD,
                    "{name} y {y}: joint {} moves {d}",
                    j + 1
                );
            }
            for (j, (written, prog)) in [
                (0, (c.conf.cf1, conf.cf1)),
                (3, (c.conf.cf4, conf.cf4)),
                (5, (c.conf.cf6, conf.cf6)),
            ] {
                assert!(
                    in_quadrant(c.q_compensated[j], written),
                    "{name} y {y}: joint {}",
                    j + 1
                );
                if keeps_quadrant(c.q_compensated[j], prog) {
                    assert_eq!(written, prog, "{name} y {y}: joint {}", j + 1);
                }
            }
            let q = r
                .ik_conf(&c.pose, c.conf)
                .unwrap_or_else(|e| panic!("{name} y {y}: written target: {e}"));
            for j in 0..6 {
                assert!(
                    (q[j] - c.q_compensated[j]).abs() < SAME_JOINTS_RAD,
                    "{name} y {y}: {q:?} vs {:?}",
                    c.q_compensated
                );
            }
            let (dp, dr) = pose_error(
                &r.predict(&MoveContext::default(), &q, EffectSet::ALL),
                &programmed,
            );
            assert!(
                dp.norm() < IK_POS_TOL_MM && dr.norm() < IK_ROT_TOL_RAD,
                "{name} y {y}"
            );
        }
    }
}

/// A target with no solution in its configuration is refused with the
/// configurations that reach it; each of them does.
#[test]
fn a_refusal_names_configurations_that_reach_the_target() {
    for (name, r) in robots() {
        let pose = ahead(name);
        // Joint 6 half a turn away: no solution in that configuration.
        let asked = ConfData { cf6: 2, ..ZERO };
        let available = match r.ik_conf(&pose, asked) {
            Err(RobotError::ConfMismatch { conf, available }) => {
                assert_eq!(conf, asked);
                available
            }
            e => panic!("{name}: expected a configuration mismatch, got {e:?}"),
        };
        let confs: Vec<ConfData> = available
            .split_whitespace()
            .map(|c| {
                let v: Vec<i32> = c
                    .trim_matches(['[', ']'])
                    .split(',')
                    .map(|n| n.parse().expect("a number"))
                    .collect();
                ConfData {
                    cf1: v[0],
                    cf4: v[1],
                    cf6: v[2],
                    cfx: v[3],
                }
            })
            .collect();
        assert!(!confs.is_empty(), "{name}: {available}");
        let mut reached = 0;
        for c in &confs {
            // A listed configuration may lie beyond the limits with its
            // turns (the closed form lists the branches); within them it
            // reaches the pose.
            match r.ik_conf(&pose, *c) {
                Ok(q) => {
                    let (dp, dr) = pose_error(&r.tcp_pose(Model::Nominal, &q), &pose);
                    assert!(
                        dp.norm() < IK_POS_TOL_MM && dr.norm() < IK_ROT_TOL_RAD,
                        "{name} {c}"
                    );
                    reached += 1;
                }
                Err(RobotError::JointLimit { .. }) => {}
                Err(e) => panic!("{name}: listed {c} does not reach: {e}"),
            }
        }
        assert!(reached > 0, "{name}: {available}");
    }
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(128))]

    /// The TX200's numeric inverse of a random reachable pose in its own
    /// configuration: forward kinematics gives the pose back within the
    /// solver's tolerance and the solution has the asked confdata (joints
    /// away from the wrist and elbow singularities and from quadrant
    /// boundaries, where the confdata of the generating joints is itself
    /// ambiguous).
    #[test]
    fn tx200_numeric_inverse_matches_forward_kinematics(
        u in proptest::array::uniform6(0.02f64..0.98)
    ) {
        let r = load("staubli-tx200");
        let l = *r.joint_limits_rad();
        let q: [f64; 6] = std::array::from_fn(|i| l[i][0] + (l[i][1] - l[i][0]) * u[i]);
        let quarter = std::f64::consts::FRAC_PI_2;
        let near_boundary = [0, 3, 5]
            .iter()
            .any(|&i| (q[i] / quarter - (q[i] / quarter).round()).abs() < 1e-3);
        proptest::prop_assume!(q[4].abs() > 0.05 && q[2].abs() > 0.05 && !near_boundary);
        let pose = r.tcp_pose(Model::Nominal, &q);
        let conf = r.confdata(&q);
        let got = r.ik_conf(&pose, conf);
        proptest::prop_assert!(got.is_ok(), "{:?}", got);
        let got = got.unwrap_or(q);
        let (dp, dr) = pose_error(&r.tcp_pose(Model::Nominal, &got), &pose);
        proptest::prop_assert!(dp.norm() < IK_POS_TOL_MM && dr.norm() < IK_ROT_TOL_RAD);
        proptest::prop_assert_eq!(r.confdata(&got), conf);
    }
}
