//! Integration tests: the bundled robot library (nominal ABB, KUKA and
//! FANUC arms).
//!
//! - Each model against its published dimensions: the flange position at
//!   all joints zero (ABB's calibration position, KUKA's HOME, FANUC's
//!   zero) from the distances
//!   between the axes in the makers' dimension drawings, the flange
//!   orientation there, and the reach (axis 1 to the wrist centre, the arm stretched
//!   within its working ranges) from the technical data, all written here
//!   as the datasheet gives them.
//! - Forward kinematics of the spherical-wrist arms against
//!   rs-opw-kinematics given the same published dimensions.
//! - KUKA and FANUC arms in their controllers' joints (machines/README.md)
//!   against the joint chains of their ROS-Industrial descriptions, written
//!   here as published.
//! - Inverse kinematics against forward kinematics on every arm (closed
//!   form with confdata, or the numeric inverse of the GoFa's offset wrist).
//! - `postproc machines` lists them with reach and payload; `machines new`
//!   writes a cell file that loads.
//! - `simulate` with tracker noise, then `calibrate kinematics` on a nominal
//!   model recovers the simulated actual parameters within their stated
//!   uncertainties.
//! - RobotStudio-style path modules for an IRB 1200, an IRB 4600 and a
//!   GoFa (tests/robot_library/), each on its own bundled arm: written back
//!   byte for byte without effects, and every compensated target, solved by
//!   the controller's inverse kinematics, predicted onto its programmed
//!   pose.

use std::f64::consts::PI;

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use postproc::machine::robot::pose::pose_error;
use postproc::machine::robot::{Model, PointMass, Robot};
use postproc::machine::{Machine, MachineFile, Status};
use postproc::predict::EffectSet;
use postproc::predict::MoveContext;
use postproc::program::rapid::{DataValue, Module, RobTarget, Target, parse_module};
use rs_opw_kinematics::kinematic_traits::Kinematics;
use rs_opw_kinematics::kinematics_impl::OPWKinematics;
use rs_opw_kinematics::parameters::opw_kinematics::Parameters;

use crate::common::{
    postproc, repo, robtarget_conf as conf, robtarget_pose as pose, without_header, write,
};

/// One arm as its datasheet gives it: distances between the axes of the
/// dimension drawing (mm) and the technical data.
struct Published {
    machine: &'static str,
    /// Axis 2 above the base plate.
    base_height: f64,
    /// Axis 2 in front of axis 1.
    shoulder: f64,
    /// Axis 2 to axis 3.
    lower_arm: f64,
    /// Axis 4 above axis 3 (elbow offset).
    elbow: f64,
    /// Axis 3 to the wrist centre (to axis 5), along the forearm.
    forearm: f64,
    /// Axis 6 above axis 4 (offset wrist; 0 when axes 4 and 6 meet).
    wrist_offset: f64,
    /// Wrist centre (axis 5) to the flange, along axis 6.
    flange: f64,
    /// Published reach, mm.
    reach: f64,
    /// Reach agreement, mm: ABB gives the reach to 10 mm or, in the
    /// variant name, to 50 mm.
    reach_tol: f64,
    /// Rated payload, kg.
    payload: f64,
}

const fn arm(
    machine: &'static str,
    dims: [f64; 7],
    reach: f64,
    reach_tol: f64,
    payload: f64,
) -> Published {
    Published {
        machine,
        base_height: dims[0],
        shoulder: dims[1],
        lower_arm: dims[2],
        elbow: dims[3],
        forearm: dims[4],
        wrist_offset: dims[5],
        flange: dims[6],
        reach,
        reach_tol,
        payload,
    }
}

/// The library: [base height, shoulder, lower arm, elbow, forearm, wrist
/// offset, flange] of each drawing, the reach and payload of its data.
const ARMS: [Published; 21] = [
    arm(
        "abb-irb120",
        [290.0, 0.0, 270.0, 70.0, 302.0, 0.0, 72.0],
        580.0,
        5.0,
        3.0,
    ),
    arm(
        "abb-irb140",
        [352.0, 70.0, 360.0, 0.0, 380.0, 0.0, 65.0],
        810.0,
        5.0,
        6.0,
    ),
    arm(
        "abb-irb1200-0.7",
        [399.1, 0.0, 350.0, 42.0, 351.0, 0.0, 82.0],
        703.0,
        5.0,
        7.0,
    ),
    arm(
        "abb-irb1200-0.9",
        [399.1, 0.0, 448.0, 42.0, 451.0, 0.0, 82.0],
        901.0,
        5.0,
        5.0,
    ),
    // ABB names the reach 1.2 m; the stretched arm is 150 + 475 + 600 =
    // 1225 mm to the wrist centre.
    arm(
        "abb-irb1600-1.2",
        [486.5, 150.0, 475.0, 0.0, 600.0, 0.0, 65.0],
        1200.0,
        26.0,
        6.0,
    ),
    arm(
        "abb-irb2400",
        [615.0, 100.0, 705.0, 135.0, 755.0, 0.0, 85.0],
        1550.0,
        5.0,
        10.0,
    ),
    arm(
        "abb-irb2600-1.65",
        [445.0, 150.0, 700.0, 115.0, 795.0, 0.0, 85.0],
        1650.0,
        5.0,
        12.0,
    ),
    arm(
        "abb-irb2600-1.85",
        [445.0, 150.0, 900.0, 115.0, 795.0, 0.0, 85.0],
        1850.0,
        5.0,
        12.0,
    ),
    arm(
        "abb-irb4600-2.05",
        [495.0, 175.0, 900.0, 175.0, 960.0, 0.0, 135.0],
        2050.0,
        5.0,
        60.0,
    ),
    arm(
        "abb-irb4600-2.55",
        [495.0, 175.0, 1095.0, 175.0, 1270.0, 0.0, 135.0],
        2550.0,
        5.0,
        40.0,
    ),
    arm(
        "abb-irb6640",
        [780.0, 320.0, 1075.0, 200.0, 1392.0, 0.0, 200.0],
        2800.0,
        5.0,
        185.0,
    ),
    arm(
        "abb-irb6700",
        [780.0, 320.0, 1125.0, 200.0, 1142.5, 0.0, 200.0],
        2600.0,
        5.0,
        200.0,
    ),
    // KUKA: axis 2 above the foot; the elbow offset of the KR 16-2 lies
    // below the lower arm's line. KUKA gives the KR 6 R900 sixx's reach to
    // 0.5 mm.
    arm(
        "kuka-kr6-r900-sixx",
        [400.0, 25.0, 455.0, 35.0, 420.0, 0.0, 80.0],
        901.5,
        1.0,
        6.0,
    ),
    arm(
        "kuka-kr6-r900-2",
        [400.0, 25.0, 455.0, 25.0, 420.0, 0.0, 90.0],
        901.0,
        1.0,
        6.0,
    ),
    arm(
        "kuka-kr16-2",
        [675.0, 260.0, 680.0, -35.0, 670.0, 0.0, 158.0],
        1611.0,
        5.0,
        16.0,
    ),
    arm(
        "kuka-kr210-r2700-2",
        [645.0, 330.0, 1150.0, 115.0, 1220.0, 0.0, 215.0],
        2701.0,
        5.0,
        210.0,
    ),
    // FANUC: the world frame is at the height of axis 2 (base height 0).
    arm(
        "fanuc-lrmate200id",
        [0.0, 50.0, 330.0, 35.0, 335.0, 0.0, 80.0],
        717.0,
        5.0,
        7.0,
    ),
    arm(
        "fanuc-lrmate200id-7l",
        [0.0, 50.0, 440.0, 35.0, 420.0, 0.0, 80.0],
        911.0,
        5.0,
        7.0,
    ),
    arm(
        "fanuc-m20ia",
        [0.0, 150.0, 790.0, 250.0, 835.0, 0.0, 100.0],
        1811.0,
        5.0,
        20.0,
    ),
    arm(
        "fanuc-r2000ic-165f",
        [0.0, 312.0, 1075.0, 225.0, 1280.0, 0.0, 215.0],
        2655.0,
        5.0,
        165.0,
    ),
    // GoFa: axis 6 runs 80 mm above axis 4; the reach is given to the
    // point of axis 6 above axis 5.
    arm(
        "abb-crb15000",
        [265.0, 0.0, 444.0, 110.0, 470.0, 80.0, 101.0],
        950.0,
        5.0,
        5.0,
    ),
];

/// Agreement of a zero-pose flange position with the drawing, mm (the
/// products of exact zeros and ones: rounding only).
const ZERO_POSE_TOL_MM: f64 = 1e-9;
/// Agreement of the zero-pose flange orientation with tool0's published
/// quaternion (7 decimals as the jogging window shows it).
const ZERO_POSE_QUAT_TOL: f64 = 1e-7;
/// ABB's tool0 orientation at the calibration position: the flange z axis
/// along base x, its x axis pointing down, i.e. 90° about base y, as the
/// controller shows it [q1, q2, q3, q4] (scalar first).
#[allow(clippy::approx_constant)] // the 7 decimals the controller shows
const TOOL0_AT_ZERO: [f64; 4] = [0.7071068, 0.0, 0.7071068, 0.0];
/// FANUC's faceplate at all joints zero: z along base x, x up
/// (W, P, R = 180°, −90°, 0°: the half turn about (x + z)/√2).
#[allow(clippy::approx_constant)]
const FACEPLATE_AT_ZERO: [f64; 4] = [0.0, 0.7071068, 0.0, 0.7071068];

/// The flange orientation of a model at all joints zero: ABB's tool0 and
/// KUKA's $FLANGE at HOME are the same; FANUC's faceplate differs by a
/// half turn about the flange axis.
fn flange_at_zero(machine: &str) -> [f64; 4] {
    if machine.starts_with("fanuc-") {
        FACEPLATE_AT_ZERO
    } else {
        TOOL0_AT_ZERO
    }
}

fn robot(name: &str) -> Robot {
    let file = MachineFile::bundled(name).unwrap_or_else(|| panic!("{name} is bundled"));
    match file.load().expect("loads") {
        Machine::Robot(r) => r,
        Machine::Tool(_) => panic!("{name} is a robot"),
    }
}

/// `n` joint vectors within the joint ranges (a fixed sequence), joint 5
/// kept 3° away from the wrist singularity.
fn joints(robot: &Robot, n: usize, seed: u64) -> Vec<[f64; 6]> {
    let mut state = seed | 1;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let lim = *robot.joint_limits_rad();
    let mut out = Vec::with_capacity(n);
    while out.len() < n {
        let q: [f64; 6] = std::array::from_fn(|i| lim[i][0] + (lim[i][1] - lim[i][0]) * next());
        if q[4].abs() > 3f64.to_radians() {
            out.push(q);
        }
    }
    out
}

#[test]
fn every_arm_has_its_published_zero_pose_payload_and_status() {
    for a in &ARMS {
        let file = MachineFile::bundled(a.machine).expect("bundled");
        assert_eq!(
            file.status().expect("status"),
            Status::Nominal,
            "{}",
            a.machine
        );
        let r = robot(a.machine);
        let flange = r.flange_pose(Model::Nominal, &[0.0; 6]);
        let want = Vector3::new(
            a.shoulder + a.forearm + a.flange,
            0.0,
            a.base_height + a.lower_arm + a.elbow + a.wrist_offset,
        );
        let off = (flange.translation.vector - want).norm();
        assert!(
            off <= ZERO_POSE_TOL_MM,
            "{}: flange at {:?}, drawing {want:?}",
            a.machine,
            flange.translation
        );
        let q = flange.rotation.coords; // (x, y, z, w)
        let got = [q[3], q[0], q[1], q[2]];
        let want = flange_at_zero(a.machine);
        // q and −q are one rotation: compare with the sign that agrees.
        let dot: f64 = got.iter().zip(want).map(|(g, w)| g * w).sum();
        let sign = if dot < 0.0 { -1.0 } else { 1.0 };
        for (g, w) in got.iter().zip(want) {
            assert!(
                (sign * g - w).abs() <= ZERO_POSE_QUAT_TOL,
                "{}: tool0 {got:?}",
                a.machine
            );
        }
        let sheet = r.datasheet().expect("a datasheet");
        assert_eq!(sheet.payload_kg, a.payload, "{}", a.machine);
        assert_eq!(sheet.reach_mm, a.reach, "{}", a.machine);
        // The nominal model predicts no kinematic error.
        assert_eq!(r.params(Model::Actual), r.params(Model::Nominal));
    }
}

/// The largest distance from axis 1 of the wrist point (the flange moved
/// back along axis 6 by the published wrist-to-flange distance) over
/// joints 2 and 3 within their ranges: a 1° grid, then 0.02° around the
/// best.
fn reach_of(r: &Robot, flange_mm: f64) -> f64 {
    let lim = *r.joint_limits_rad();
    let radius = |q2: f64, q3: f64| {
        let f = r.flange_pose(Model::Nominal, &[0.0, q2, q3, 0.0, 0.0, 0.0]);
        let w = f.translation.vector - f.rotation * Vector3::z() * flange_mm;
        w.x.hypot(w.y)
    };
    let grid = |lo: f64, hi: f64, step: f64| {
        let n = ((hi - lo) / step).ceil() as usize;
        (0..=n).map(move |i| (lo + step * i as f64).min(hi))
    };
    let deg = 1f64.to_radians();
    let mut best = (0.0, 0.0, 0.0);
    for q2 in grid(lim[1][0], lim[1][1], deg) {
        for q3 in grid(lim[2][0], lim[2][1], deg) {
            let v = radius(q2, q3);
            if v > best.0 {
                best = (v, q2, q3);
            }
        }
    }
    let (_, c2, c3) = best;
    let fine = 0.02f64.to_radians();
    for q2 in grid((c2 - deg).max(lim[1][0]), (c2 + deg).min(lim[1][1]), fine) {
        for q3 in grid((c3 - deg).max(lim[2][0]), (c3 + deg).min(lim[2][1]), fine) {
            best.0 = f64::max(best.0, radius(q2, q3));
        }
    }
    best.0
}

#[test]
fn every_arm_reaches_as_far_as_published() {
    for a in &ARMS {
        let reach = reach_of(&robot(a.machine), a.flange);
        assert!(
            (reach - a.reach).abs() <= a.reach_tol,
            "{}: the model reaches {reach:.1} mm, published {} mm",
            a.machine,
            a.reach
        );
    }
}

/// Position agreement of two forward kinematics, mm (rounding only).
const FK_POS_TOL_MM: f64 = 1e-9;
/// Orientation agreement (quaternion components).
const FK_ROT_TOL: f64 = 1e-12;

/// The published dimensions as OPW parameters (metres): rs-opw-kinematics
/// measures the elbow offset downwards and ABB's joint 3 zero is 90° from
/// OPW's.
fn opw(a: &Published) -> OPWKinematics {
    OPWKinematics::new(Parameters {
        a1: a.shoulder / 1000.0,
        a2: -a.elbow / 1000.0,
        b: 0.0,
        c1: a.base_height / 1000.0,
        c2: a.lower_arm / 1000.0,
        c3: a.forearm / 1000.0,
        c4: a.flange / 1000.0,
        offsets: [0.0, 0.0, -std::f64::consts::FRAC_PI_2, 0.0, 0.0, 0.0],
        sign_corrections: [1; 6],
        dof: 6,
    })
}

#[test]
fn spherical_wrist_arms_agree_with_rs_opw_kinematics() {
    let mut compared = 0;
    for a in ARMS.iter().filter(|a| a.wrist_offset == 0.0) {
        let (r, theirs) = (robot(a.machine), opw(a));
        assert!(r.has_closed_form(), "{}", a.machine);
        for q in joints(&r, 100, 0x9e37_79b9_7f4a_7c15) {
            let ours = r.flange_pose(Model::Nominal, &q);
            let mut other = theirs.forward(&q);
            if a.machine.starts_with("fanuc-") {
                // OPW's flange is ABB's tool0; FANUC's faceplate is it
                // turned half a turn about its z axis.
                other.rotation *= UnitQuaternion::from_axis_angle(&Vector3::z_axis(), PI);
            }
            let dp = (ours.translation.vector - other.translation.vector * 1000.0).norm();
            assert!(dp <= FK_POS_TOL_MM * 10.0, "{} {q:?}: {dp} mm", a.machine);
            let (x, y) = (ours.rotation.coords, other.rotation.coords);
            let sign = if x.dot(&y) < 0.0 { -1.0 } else { 1.0 };
            assert!((x - sign * y).amax() <= FK_ROT_TOL, "{} {q:?}", a.machine);
            compared += 1;
        }
    }
    assert_eq!(compared, 2000);
}

/// A published ROS-Industrial arm description: the origin (mm) and axis of
/// each joint's frame in its parent's with every joint at zero, the fixed
/// flange offset, the `tool0` (KUKA $FLANGE, FANUC faceplate) rotation
/// (URDF roll, pitch, yaw in degrees) and the height of the controller's
/// base frame above `base_link`.
struct Urdf {
    machine: &'static str,
    joints: [([f64; 3], [f64; 3]); 6],
    flange: [f64; 3],
    tool0_rpy_deg: [f64; 3],
    base_mm: f64,
}

const NX: [f64; 3] = [-1.0, 0.0, 0.0];
const Y: [f64; 3] = [0.0, 1.0, 0.0];
const NY: [f64; 3] = [0.0, -1.0, 0.0];
const Z: [f64; 3] = [0.0, 0.0, 1.0];
const NZ: [f64; 3] = [0.0, 0.0, -1.0];

/// kuka_experimental (kr6r900sixx, kr6r900_2, kr16_2 macros) and fanuc
/// (lrmate200id, lrmate200id7l, m20ia macros), as published. KUKA's URDF
/// joints are the controller's axes; FANUC's joint 3 is J3 + J2.
const URDFS: [Urdf; 6] = [
    Urdf {
        machine: "kuka-kr6-r900-sixx",
        joints: [
            ([0.0, 0.0, 400.0], NZ),
            ([25.0, 0.0, 0.0], Y),
            ([455.0, 0.0, 0.0], Y),
            ([0.0, 0.0, 35.0], NX),
            ([420.0, 0.0, 0.0], Y),
            ([80.0, 0.0, 0.0], NX),
        ],
        flange: [0.0; 3],
        tool0_rpy_deg: [0.0, 90.0, 0.0],
        base_mm: 0.0,
    },
    Urdf {
        machine: "kuka-kr6-r900-2",
        joints: [
            ([0.0, 0.0, 400.0], NZ),
            ([25.0, 0.0, 0.0], Y),
            ([455.0, 0.0, 0.0], Y),
            ([0.0, 0.0, 25.0], NX),
            ([420.0, 0.0, 0.0], Y),
            ([90.0, 0.0, 0.0], NX),
        ],
        flange: [0.0; 3],
        tool0_rpy_deg: [0.0, 90.0, 0.0],
        base_mm: 0.0,
    },
    Urdf {
        machine: "kuka-kr16-2",
        joints: [
            ([0.0, 0.0, 675.0], NZ),
            ([260.0, 0.0, 0.0], Y),
            ([680.0, 0.0, 0.0], Y),
            ([670.0, 0.0, -35.0], NX),
            ([0.0, 0.0, 0.0], Y),
            ([0.0, 0.0, 0.0], NX),
        ],
        flange: [158.0, 0.0, 0.0],
        tool0_rpy_deg: [0.0, 90.0, 0.0],
        base_mm: 0.0,
    },
    Urdf {
        machine: "fanuc-lrmate200id",
        joints: [
            ([0.0, 0.0, 330.0], Z),
            ([50.0, 0.0, 0.0], Y),
            ([0.0, 0.0, 330.0], NY),
            ([0.0, 0.0, 35.0], NX),
            ([335.0, 0.0, 0.0], NY),
            ([80.0, 0.0, 0.0], NX),
        ],
        flange: [0.0; 3],
        tool0_rpy_deg: [180.0, -90.0, 0.0],
        base_mm: 330.0,
    },
    Urdf {
        machine: "fanuc-lrmate200id-7l",
        joints: [
            ([0.0, 0.0, 330.0], Z),
            ([50.0, 0.0, 0.0], Y),
            ([0.0, 0.0, 440.0], NY),
            ([0.0, 0.0, 35.0], NX),
            ([420.0, 0.0, 0.0], NY),
            ([80.0, 0.0, 0.0], NX),
        ],
        flange: [0.0; 3],
        tool0_rpy_deg: [180.0, -90.0, 0.0],
        base_mm: 330.0,
    },
    Urdf {
        machine: "fanuc-m20ia",
        joints: [
            ([0.0, 0.0, 525.0], Z),
            ([150.0, 0.0, 0.0], Y),
            ([0.0, 0.0, 790.0], NY),
            ([0.0, 0.0, 250.0], NX),
            ([835.0, 0.0, 0.0], NY),
            ([100.0, 0.0, 0.0], NX),
        ],
        flange: [0.0; 3],
        tool0_rpy_deg: [180.0, -90.0, 0.0],
        base_mm: 525.0,
    },
];

/// `tool0` of a URDF chain in the controller's base frame for the URDF's
/// joint values (rad).
fn urdf_tool0(u: &Urdf, q: &[f64; 6]) -> Isometry3<f64> {
    let mut t = Isometry3::translation(0.0, 0.0, -u.base_mm);
    for ((xyz, axis), v) in u.joints.iter().zip(q) {
        let axis = nalgebra::Unit::new_normalize(Vector3::from(*axis));
        t = t
            * Isometry3::translation(xyz[0], xyz[1], xyz[2])
            * UnitQuaternion::from_axis_angle(&axis, *v);
    }
    let [r, p, y] = u.tool0_rpy_deg.map(f64::to_radians);
    t * Isometry3::translation(u.flange[0], u.flange[1], u.flange[2])
        * UnitQuaternion::from_euler_angles(r, p, y)
}

/// The URDF joint values of the controller's joints (degrees).
fn urdf_joints(machine: &str, controller_deg: &[f64; 6]) -> [f64; 6] {
    let mut j = *controller_deg;
    if machine.starts_with("fanuc-") {
        j[2] += j[1]; // the ROS-I driver's J23 linkage: J3 + J2
    }
    j.map(f64::to_radians)
}

/// Every model's joints, turned into the controller's by the documented
/// relation (machines/README.md), put the published URDF chain's tool0
/// where the model puts its flange; KUKA's mechanical zero (all axes 0,
/// the arm stretched forward) and HOME are where the drawing puts them.
#[test]
fn kuka_and_fanuc_joints_drive_the_published_chains_like_the_models() {
    use postproc::program::{krl, tp};
    for u in &URDFS {
        let r = robot(u.machine);
        for q in joints(&r, 100, 0x3c6e_f372_fe94_f82b) {
            let controller = if u.machine.starts_with("kuka-") {
                krl::config::model_to_axes(&q)
            } else {
                tp::config::model_to_joints(&q)
            };
            let theirs = urdf_tool0(u, &urdf_joints(u.machine, &controller));
            let ours = r.flange_pose(Model::Nominal, &q);
            let (dp, dr) = pose_error(&ours, &theirs);
            assert!(dp.norm() <= 1e-9, "{} {q:?}: {} mm", u.machine, dp.norm());
            assert!(dr.norm() <= 1e-12, "{} {q:?}: {} rad", u.machine, dr.norm());
        }
    }
    // KR 6 R900 sixx at its mechanical zero: 25 + 455 + 420 + 80 = 980 mm
    // forward, 400 + 35 = 435 mm up; at HOME 525 mm forward, 890 mm up.
    let r = robot("kuka-kr6-r900-sixx");
    for (axes, x, z) in [
        ([0.0; 6], 980.0, 435.0),
        ([0.0, -90.0, 90.0, 0.0, 0.0, 0.0], 525.0, 890.0),
    ] {
        let f = r.flange_pose(Model::Nominal, &krl::config::axes_to_model(&axes));
        let want = Vector3::new(x, 0.0, z);
        assert!((f.translation.vector - want).norm() <= ZERO_POSE_TOL_MM);
    }
}

/// Joint agreement of an inverse solution with the joints it came from,
/// rad.
const IK_JOINT_TOL_RAD: f64 = 1e-7;
/// Pose agreement of the forward kinematics of an inverse solution, mm and
/// rad (the numeric solver's tolerances are 1e-9 mm and 1e-12 rad).
const IK_POS_TOL_MM: f64 = 1e-6;
const IK_ROT_TOL_RAD: f64 = 1e-9;

/// On every arm, the controller's inverse kinematics (closed form, or the
/// numeric inverse of the GoFa's offset wrist) of the pose of joint values
/// with their confdata lands on that pose in that configuration; the
/// closed form gives those joint values back.
#[test]
fn inverse_kinematics_gives_back_the_joints_of_every_pose() {
    for a in &ARMS {
        let r = robot(a.machine);
        assert_eq!(r.has_closed_form(), a.wrist_offset == 0.0, "{}", a.machine);
        let n = if r.has_closed_form() { 150 } else { 40 };
        for q in joints(&r, n, 0x2545_f491_4f6c_dd1d) {
            let pose = r.tcp_pose(Model::Nominal, &q);
            let c = r.confdata(&q);
            let back = r
                .ik_conf(&pose, c)
                .unwrap_or_else(|e| panic!("{} {q:?} {c}: {e}", a.machine));
            let (dp, dr) = pose_error(&r.tcp_pose(Model::Nominal, &back), &pose);
            assert!(
                dp.norm() <= IK_POS_TOL_MM,
                "{} {q:?}: {} mm",
                a.machine,
                dp.norm()
            );
            assert!(
                dr.norm() <= IK_ROT_TOL_RAD,
                "{} {q:?}: {} rad",
                a.machine,
                dr.norm()
            );
            assert_eq!(r.confdata(&back), c, "{} {q:?}", a.machine);
            // A spherical wrist has one solution per configuration; an
            // offset wrist may have two close to each other in one.
            if r.has_closed_form() {
                for i in 0..6 {
                    assert!(
                        (back[i] - q[i]).abs() <= IK_JOINT_TOL_RAD,
                        "{} {q:?} {c}: joint {} back at {}",
                        a.machine,
                        i + 1,
                        back[i]
                    );
                }
            }
        }
    }
}

#[test]
fn machines_lists_every_arm_with_reach_and_payload() {
    let out = postproc().arg("machines").output().expect("runs");
    assert_eq!(out.status.code(), Some(0));
    let text = String::from_utf8(out.stdout).expect("utf-8");
    let robots = text.lines().filter(|l| l.contains(" robot ")).count();
    assert!(robots >= 14, "{text}");
    for a in &ARMS {
        let line = text
            .lines()
            .find(|l| l.split_whitespace().next() == Some(a.machine))
            .unwrap_or_else(|| panic!("{} listed:\n{text}", a.machine));
        let reach = format!("{:.0} mm", a.reach);
        let payload = format!("{} kg", a.payload);
        assert!(line.contains(" nominal "), "{line}");
        assert!(line.contains(&reach) && line.contains(&payload), "{line}");
    }
}

/// `machines new` writes a cell file of each arm that loads, with the
/// model's kinematics and what to measure; it never writes over a file
/// and refuses a machine tool.
#[test]
fn machines_new_writes_a_cell_file_that_loads() {
    let dir = tempfile::tempdir().expect("tempdir");
    for a in &ARMS {
        let cell = dir.path().join(format!("{}-cell.yaml", a.machine));
        postproc()
            .args(["machines", "new", a.machine, "-o"])
            .arg(&cell)
            .assert()
            .success();
        let text = std::fs::read_to_string(&cell).expect("written");
        let Machine::Robot(r) = Machine::from_yaml_str(&text, "cell.yaml").expect("loads") else {
            panic!("a robot")
        };
        assert_eq!(
            r.params(Model::Nominal),
            robot(a.machine).params(Model::Nominal)
        );
        for key in [
            "base:",
            "flange_to_tool:",
            "tool_load",
            "wobjdata",
            "MEASURE",
        ] {
            assert!(text.contains(key), "{}: {key}", a.machine);
        }
        assert_eq!(text.matches("\nbase:").count(), 1, "{}", a.machine);
        assert_eq!(text.matches("\nflange_to_tool:").count(), 1);
    }
    // The IRB 1200 cell checks the IRB 1200 path.
    let cell = dir.path().join("abb-irb1200-0.7-cell.yaml");
    postproc()
        .arg("check")
        .arg(repo("tests/robot_library/irb1200_path.mod"))
        .arg("--machine")
        .arg(&cell)
        .assert()
        .success();
    let before = std::fs::read(&cell).expect("cell");
    postproc()
        .args(["machines", "new", "abb-irb120", "-o"])
        .arg(&cell)
        .assert()
        .code(2);
    assert_eq!(std::fs::read(&cell).expect("cell"), before);
    // `-o -`: the same cell on standard output.
    let out = postproc()
        .args(["machines", "new", "abb-irb1200-0.7", "-o", "-"])
        .output()
        .expect("runs");
    assert_eq!(out.status.code(), Some(0));
    assert_eq!(out.stdout, before);
    let tool = dir.path().join("tool.yaml");
    postproc()
        .args(["machines", "new", "afm-r1000", "-o"])
        .arg(&tool)
        .assert()
        .code(2);
    postproc()
        .args(["machines", "new", "abb-irb9999", "-o"])
        .arg(&tool)
        .assert()
        .code(2);
    assert!(!tool.exists());
}

/// Largest difference of an identified parameter from its simulated true
/// value, in its standard uncertainty u (k = 1): 3u.
const K_TEST: f64 = 3.0;

/// The simulated robot's errors from a nominal model, per DH row (a_mm,
/// alpha_deg, d_mm, theta_offset_deg), of the size of an uncalibrated arm.
/// Only what poses measured in the base frame identify is changed:
/// `calibrate` fixes the rest (row 5 θ, row 6 α and θ) and keeps those
/// the data do not show (row 1 a and α, the TCP across the flange axis) at
/// the start value, which is then the truth. Two pairs move the measured
/// point alike and are compared by their sum ([`PAIRS`]).
const TRUE_ERRORS: [[f64; 4]; 6] = [
    [0.0, 0.0, 0.42, 0.021],
    [-0.31, -0.018, 0.0, 0.027],
    [0.55, 0.015, -0.24, -0.033],
    [0.28, 0.022, 0.37, 0.019],
    [-0.19, -0.026, 0.23, 0.0],
    [0.0, 0.0, -0.29, 0.0],
];

/// Parameters that only their sum shows: offsets along the parallel axes
/// 2 and 3, and the flange distance and the TCP along axis 6. `calibrate`
/// fixes one of each pair and identifies the other as the sum.
const PAIRS: [[&str; 2]; 2] = [["j2.d_mm", "j3.d_mm"], ["j6.d_mm", "tool.z_mm"]];

/// `n` calibration poses within the joint ranges of `r` (90 % of each
/// range about its middle), as an observation file without measurements.
fn poses_file(r: &Robot, n: usize) -> String {
    let mut text = String::from("id,q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\n");
    for (k, q) in joints(r, n, 0x5851_f42d_4c95_7f2d).iter().enumerate() {
        let lim = r.joint_limits_rad();
        let row: Vec<String> = q
            .iter()
            .zip(lim)
            .map(|(v, l)| {
                let mid = 0.5 * (l[0] + l[1]);
                format!("{:.3}", (mid + 0.9 * (v - mid)).to_degrees())
            })
            .collect();
        text.push_str(&format!("K{},{}\n", k + 1, row.join(",")));
    }
    text
}

/// The nominal file with an `actual` block of the nominal rows plus
/// [`TRUE_ERRORS`], as `status: example` (a simulated robot), and the true
/// value of every parameter `calibrate` lists (the TCP is the flange).
fn truth_file(nominal_text: &str, r: &Robot) -> (String, Vec<(String, f64)>) {
    let fields = ["a_mm", "alpha_deg", "d_mm", "theta_offset_deg"];
    let mut truth = Vec::new();
    let mut block = String::from("actual:\n");
    for (i, j) in r.params(Model::Nominal).joints.iter().enumerate() {
        let e = TRUE_ERRORS[i];
        let row = [
            j.a_mm + e[0],
            j.alpha_rad.to_degrees() + e[1],
            j.d_mm + e[2],
            j.theta_offset_rad.to_degrees() + e[3],
        ];
        block.push_str(&format!(
            "  - {{ a_mm: {}, alpha_deg: {}, d_mm: {}, theta_offset_deg: {} }}\n",
            row[0], row[1], row[2], row[3]
        ));
        for (f, v) in fields.iter().zip(row) {
            truth.push((format!("j{}.{f}", i + 1), v));
        }
    }
    for axis in ["x", "y", "z"] {
        truth.push((format!("tool.{axis}_mm"), 0.0));
    }
    let text = nominal_text
        .replacen("status: nominal", "status: example", 1)
        .replacen("joint_limits_deg:", &format!("{block}joint_limits_deg:"), 1);
    (text, truth)
}

/// (identified value, u) of each parameter row of `calibrate`'s table
/// (`name start identified u U …`); fixed parameters have no u.
fn identified(stdout: &str) -> Vec<(String, f64, Option<f64>)> {
    let mut rows = Vec::new();
    for line in stdout.lines() {
        let c: Vec<&str> = line.split_whitespace().collect();
        let named = c.len() >= 7
            && c[0].contains('.')
            && (c[0].starts_with('j') || c[0].starts_with("tool."));
        if let (true, Ok(value)) = (named, c.get(2).map_or(Ok(f64::NAN), |v| v.parse::<f64>())) {
            rows.push((c[0].to_string(), value, c[3].parse().ok()));
        }
    }
    rows
}

/// Simulates tracker data (20 µm + 6 µm/m) of the nominal model `name` with
/// [`TRUE_ERRORS`], calibrates the bundled nominal model from it and
/// checks every parameter (or pair sum) against the truth; the number of
/// identified parameters compared.
fn calibrate_recovers(name: &str, dir: &std::path::Path) -> usize {
    let nominal_text = MachineFile::bundled(name)
        .expect("bundled")
        .text
        .to_string();
    let r = robot(name);
    let (truth_text, truth) = truth_file(&nominal_text, &r);
    let truth_file = write(dir, &format!("{name}-truth.yaml"), &truth_text);
    let poses = write(dir, &format!("{name}-poses.csv"), &poses_file(&r, 60));
    let measured = dir.join(format!("{name}-measured.csv"));
    postproc()
        .args([
            "simulate",
            "--noise-um",
            "20",
            "--noise-um-per-m",
            "6",
            "--seed",
            "5",
        ])
        .arg("--machine")
        .arg(&truth_file)
        .arg("--observations")
        .arg(&poses)
        .arg("-o")
        .arg(&measured)
        .assert()
        .success();
    let out_file = dir.join(format!("{name}-calibrated.yaml"));
    let run = postproc()
        .args([
            "calibrate",
            "kinematics",
            "--machine",
            name,
            "--observations",
        ])
        .arg(&measured)
        .arg("-o")
        .arg(&out_file)
        .output()
        .expect("runs");
    let stdout = String::from_utf8(run.stdout).expect("utf-8");
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(0), "{name}: {stdout}\n{stderr}");
    let table = identified(&stdout);
    let row = |key: &str| {
        let (_, v, u) = table
            .iter()
            .find(|(n, ..)| n == key)
            .unwrap_or_else(|| panic!("{name}: {key} in\n{stdout}"));
        let t = truth
            .iter()
            .find(|(n, _)| n == key)
            .expect("a true value")
            .1;
        (*v, *u, t)
    };
    let mut checked = 0;
    let mut check = |what: &str, value: f64, u: Option<f64>, true_value: f64| match u {
        Some(u) => {
            assert!(
                (value - true_value).abs() <= K_TEST * u,
                "{name} {what}: identified {value} ± {u}, true {true_value}\n{stdout}"
            );
            checked += 1;
        }
        // Fixed: the file's value, which must then be the truth.
        None => assert!(
            (value - true_value).abs() <= 1e-9,
            "{name} {what}: fixed at {value}, true {true_value}"
        ),
    };
    for (key, _) in &truth {
        if !PAIRS.iter().flatten().any(|p| p == key) {
            let (v, u, t) = row(key);
            check(key, v, u, t);
        }
    }
    for [a, b] in PAIRS {
        let ((va, ua, ta), (vb, ub, tb)) = (row(a), row(b));
        assert!(
            ua.is_none() || ub.is_none(),
            "{name}: {a} and {b} both identified"
        );
        check(&format!("{a} + {b}"), va + vb, ua.or(ub), ta + tb);
    }
    let written = std::fs::read_to_string(&out_file).expect("calibrated file");
    assert!(matches!(
        Status::from_yaml_str(&written, "calibrated.yaml").expect("status"),
        Status::Calibrated(_)
    ));
    Machine::from_yaml_str(&written, "calibrated.yaml").expect("loads");
    checked
}

/// `calibrate kinematics` from simulated tracker data, starting from the
/// bundled nominal model, recovers the simulated robot within the stated
/// uncertainties: a large and a small spherical-wrist arm and the GoFa's
/// offset wrist.
#[test]
fn calibrate_kinematics_recovers_simulated_arms_from_their_nominal_models() {
    let dir = tempfile::tempdir().expect("tempdir");
    for name in ["abb-irb4600-2.05", "abb-irb1200-0.9", "abb-crb15000"] {
        let checked = calibrate_recovers(name, dir.path());
        // 24 DH parameters and 3 of the TCP, less 3 fixed and 1 of each
        // pair; some are kept (not significant) with their uncertainty.
        assert!(checked >= 20, "{name}: {checked} parameters compared");
    }
}

/// The RobotStudio-style modules and the bundled arm each was written for,
/// with the module's tool (TCP, load) and work object frame.
struct Cell {
    module: &'static str,
    machine: &'static str,
    tcp_mm: [f64; 3],
    load: (f64, [f64; 3]),
    wobj_mm: [f64; 3],
    /// Moves of the module.
    moves: usize,
}

const CELLS: [Cell; 3] = [
    Cell {
        module: "tests/robot_library/irb1200_path.mod",
        machine: "abb-irb1200-0.7",
        tcp_mm: [0.0, 0.0, 120.0],
        load: (0.8, [0.0, 0.0, 45.0]),
        wobj_mm: [330.0, -110.0, 180.0],
        moves: 10,
    },
    Cell {
        module: "tests/robot_library/irb4600_path.mod",
        machine: "abb-irb4600-2.05",
        tcp_mm: [0.0, 0.0, 250.0],
        load: (22.0, [0.0, 0.0, 110.0]),
        wobj_mm: [1150.0, -400.0, 300.0],
        moves: 10,
    },
    // The GoFa's offset wrist: the numeric inverse with confdata.
    Cell {
        module: "tests/robot_library/gofa_path.mod",
        machine: "abb-crb15000",
        tcp_mm: [0.0, 0.0, 90.0],
        load: (0.5, [0.0, 0.0, 40.0]),
        wobj_mm: [400.0, -100.0, 150.0],
        moves: 4,
    },
];

/// Position agreement of the predicted attained TCP with the programmed
/// one, mm: the written position's 3 decimals move the TCP by at most
/// 0.0005·√3 = 0.00087 mm.
const POS_TOL_MM: f64 = 1e-3;
/// Orientation agreement, rad: 7-decimal quaternions move the rotation by
/// at most 2e-7 rad.
const ROT_TOL_RAD: f64 = 1e-6;

fn compensate(cell: &Cell, dir: &std::path::Path, extra: &[&str]) -> (Vec<u8>, Vec<u8>, String) {
    let input = repo(cell.module);
    let output = dir.join("out.mod");
    let run = postproc()
        .arg("compensate")
        .arg(&input)
        .args(["--machine", cell.machine, "-o"])
        .arg(&output)
        .args(extra)
        .output()
        .expect("runs");
    let stderr = String::from_utf8_lossy(&run.stderr).into_owned();
    assert_eq!(run.status.code(), Some(0), "{}: {stderr}", cell.module);
    (
        std::fs::read(&input).expect("input"),
        std::fs::read(&output).expect("output"),
        stderr,
    )
}

fn robtarget<'a>(m: &'a Module, name: &str) -> &'a RobTarget {
    match m.decl(name).and_then(|d| d.value.as_ref()) {
        Some(DataValue::RobTarget(rt)) => rt,
        v => panic!("{name}: {v:?}"),
    }
}

#[test]
fn robotstudio_paths_come_back_byte_for_byte_without_effects() {
    let dir = tempfile::tempdir().expect("tempdir");
    for cell in &CELLS {
        let (input, output, _) = compensate(
            cell,
            dir.path(),
            &["--effects", "none", "--annotate", "none"],
        );
        assert!(without_header(&output) == input, "{}", cell.module);
    }
}

#[test]
fn robotstudio_paths_compensate_onto_their_programmed_poses() {
    let dir = tempfile::tempdir().expect("tempdir");
    for cell in &CELLS {
        let (input, output, stderr) = compensate(cell, dir.path(), &[]);
        assert!(stderr.contains("`status: nominal`"), "{stderr}");
        let src_in = String::from_utf8(input).expect("utf-8");
        let src_out = String::from_utf8(output).expect("utf-8");
        assert!(src_out.contains("machine status nominal"));
        let m_in = parse_module(&src_in, "in").expect("input parses");
        let m_out = parse_module(&src_out, "out").expect("output parses");
        let (load_kg, cog) = cell.load;
        let r = robot(cell.machine).with_tool(
            Isometry3::translation(cell.tcp_mm[0], cell.tcp_mm[1], cell.tcp_mm[2]),
            Some(PointMass {
                mass_kg: load_kg,
                com_mm: Vector3::from(cog),
            }),
        );
        let wobj = Isometry3::from_parts(
            Translation3::new(cell.wobj_mm[0], cell.wobj_mm[1], cell.wobj_mm[2]),
            UnitQuaternion::identity(),
        );
        let (a, b): (Vec<_>, Vec<_>) = (m_in.moves().collect(), m_out.moves().collect());
        assert_eq!(
            (a.len(), b.len()),
            (cell.moves, cell.moves),
            "{}",
            cell.module
        );
        let mut moved = 0.0f64;
        for (mi, mo) in a.iter().zip(&b) {
            let (Target::Named { name: n_in, .. }, Target::Named { name: n_out, .. }) =
                (&mi.target, &mo.target)
            else {
                panic!("{} line {}: named targets", cell.module, mi.line)
            };
            let (rt_in, rt_out) = (robtarget(&m_in, n_in), robtarget(&m_out, n_out));
            let q = r
                .ik_conf(&(wobj * pose(rt_out)), conf(rt_out))
                .unwrap_or_else(|e| panic!("{} line {}: {e}", cell.module, mi.line));
            let goal = wobj * pose(rt_in);
            let (dp, dr) = pose_error(
                &r.predict(&MoveContext::default(), &q, EffectSet::ALL),
                &goal,
            );
            assert!(
                dp.norm() < POS_TOL_MM,
                "{} line {}: {} mm",
                cell.module,
                mi.line,
                dp.norm()
            );
            assert!(
                dr.norm() < ROT_TOL_RAD,
                "{} line {}: {} rad",
                cell.module,
                mi.line,
                dr.norm()
            );
            moved = moved
                .max((pose(rt_out).translation.vector - pose(rt_in).translation.vector).norm());
        }
        // The gravity sag of the estimated masses is corrected: targets move.
        assert!(
            moved > 0.05,
            "{}: largest correction {moved} mm",
            cell.module
        );
    }
}

/// A report of a path on a nominal arm records `status: nominal` in its
/// provenance, as schemas/report.schema.json allows.
#[test]
fn reports_on_a_nominal_arm_say_so_within_the_schema() {
    let run = postproc()
        .args(["report", "--format", "json", "--machine", "abb-irb1200-0.7"])
        .arg(repo("tests/robot_library/irb1200_path.mod"))
        .output()
        .expect("runs");
    assert_eq!(
        run.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let report: serde_json::Value = serde_json::from_slice(&run.stdout).expect("JSON");
    assert_eq!(report["provenance"]["machine"]["status"], "nominal");
    let schema: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(repo("schemas/report.schema.json")).expect("schema file"),
    )
    .expect("schema is JSON");
    let (mut schemas, mut compiler) = (boon::Schemas::new(), boon::Compiler::new());
    let url = "https://postproc.example/schemas/report.schema.json";
    compiler.add_resource(url, schema).expect("schema resource");
    let idx = compiler
        .compile(url, &mut schemas)
        .expect("schema compiles");
    if let Err(e) = schemas.validate(&report, idx) {
        panic!("report does not match the schema: {e:#}");
    }
    let mut other = report.clone();
    other["provenance"]["machine"]["status"] = serde_json::json!("measured");
    assert!(schemas.validate(&other, idx).is_err());
}
