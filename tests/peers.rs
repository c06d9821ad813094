//! Cross-checks against the peer implementations that `benches/peers.rs`
//! measures postproc against: the comparisons there are of the same work
//! only if both sides give the same answers, which these tests show.
//!
//! - gcode-rs 0.6 (`gcode` crate) reads the same words, in the same order,
//!   as postproc's parser on lines both dialects accept (gcode-rs keeps
//!   values as `f32`).
//! - rs-opw-kinematics, given the IRB 1600's nominal geometry as OPW
//!   parameters, has the same forward kinematics as postproc's
//!   modified-DH model and the same set of inverse solutions as its closed
//!   form: an independent check of both.

use approx::relative_eq;
use nalgebra::Isometry3;
use postproc::machine::Machine;
use postproc::machine::robot::{Model, Robot};
use postproc::program::gcode::{Block, parse_line};
use rs_opw_kinematics::kinematic_traits::Kinematics;
use rs_opw_kinematics::kinematics_impl::OPWKinematics;
use rs_opw_kinematics::parameters::opw_kinematics::Parameters;

use crate::common::repo;

/// Relative agreement of a word's value: gcode-rs parses into `f32`
/// (about 6e-8 relative rounding), postproc into `f64`.
const F32_VALUE_REL: f32 = 2e-7;
/// Position agreement of the two forward kinematics, mm (the products
/// differ in rounding only: about 1e-13 mm at a 1.5 m reach).
const FK_POS_TOL_MM: f64 = 1e-9;
/// Orientation agreement of the two forward kinematics (quaternion
/// components).
const FK_ROT_TOL: f64 = 1e-12;
/// Joint-angle agreement of matched inverse solutions, rad.
const IK_JOINT_TOL_RAD: f64 = 1e-9;

/// The words of each line by postproc's parser: (letter, value) in order.
fn postproc_words(src: &str) -> Vec<Vec<(char, f32)>> {
    let mut block = Block::default();
    src.lines()
        .enumerate()
        .map(|(i, line)| {
            parse_line(line.as_bytes(), i + 1, "peer.nc", &mut block).expect("postproc parses");
            block
                .words
                .iter()
                .map(|w| (char::from(w.letter), w.value as f32))
                .collect()
        })
        .collect()
}

/// The words of each line by gcode-rs: each command's letter and number,
/// then its arguments, in order.
fn gcode_rs_words(src: &str) -> Vec<Vec<(char, f32)>> {
    src.lines()
        .map(|line| {
            let mut words = Vec::new();
            for g in gcode::parse(line) {
                let letter = match g.mnemonic() {
                    gcode::Mnemonic::General => 'G',
                    gcode::Mnemonic::Miscellaneous => 'M',
                    gcode::Mnemonic::ProgramNumber => 'O',
                    gcode::Mnemonic::ToolChange => 'T',
                };
                let number = g.major_number() as f32 + g.minor_number() as f32 / 10.0;
                words.push((letter, number));
                words.extend(g.arguments().iter().map(|a| (a.letter, a.value)));
            }
            words
        })
        .collect()
}

#[test]
fn gcode_rs_reads_the_same_words_as_postproc() {
    let mut src = String::from(
        "G90 G17 G21\nG0 X1.5 Y-2 Z20\nG1 Z-0.25 F300\nG2 X10 Y0 I5 J0\nG3 X0 Y0 R5.0\nM3 S1200\nG1 X.5 Y-.75\nM5\n",
    );
    // The explicit-G1 raster of benches/peers.rs.
    let mut y = 0.0f64;
    for n in 0..2000 {
        let x = if (n / 2) % 2 == 0 { 400.0 } else { 0.0 };
        if n % 2 == 0 {
            src.push_str(&format!("G1 X{x:.3} Y{y:.3}\n"));
        } else {
            y += 0.01;
            src.push_str(&format!("G1 Y{y:.3}\n"));
        }
    }
    let (ours, theirs) = (postproc_words(&src), gcode_rs_words(&src));
    assert_eq!(ours.len(), theirs.len());
    let mut words = 0;
    for (i, (a, b)) in ours.iter().zip(&theirs).enumerate() {
        assert_eq!(a.len(), b.len(), "line {}: {a:?} against {b:?}", i + 1);
        for ((la, va), (lb, vb)) in a.iter().zip(b) {
            assert_eq!(la, lb, "line {}", i + 1);
            assert!(
                relative_eq!(
                    *va,
                    *vb,
                    epsilon = F32_VALUE_REL,
                    max_relative = F32_VALUE_REL
                ),
                "line {}: {la}{va} against {lb}{vb}",
                i + 1
            );
            words += 1;
        }
    }
    assert!(words > 5000, "{words} words compared");
}

/// The bundled IRB 1600 without its tool (the TCP is the flange).
fn irb1600() -> Robot {
    let text = std::fs::read_to_string(repo("machines/abb-irb1600.yaml")).expect("machine file");
    let Ok(Machine::Robot(r)) = Machine::from_yaml_str(&text, "abb-irb1600.yaml") else {
        panic!("abb-irb1600 is not a robot")
    };
    r.with_tool(Isometry3::identity(), None, true)
}

/// The IRB 1600's nominal geometry (machines/abb-irb1600.yaml) as OPW
/// parameters, in metres: shoulder offset a1 = 150 mm, no forearm offset,
/// base height c1 = 486.5 mm, upper arm c2 = 700 mm, forearm c3 = 600 mm,
/// wrist to flange c4 = 65 mm; ABB's joint 3 zero is 90° from OPW's.
fn irb1600_opw() -> OPWKinematics {
    OPWKinematics::new(Parameters {
        a1: 0.150,
        a2: 0.0,
        b: 0.0,
        c1: 0.4865,
        c2: 0.700,
        c3: 0.600,
        c4: 0.065,
        offsets: [0.0, 0.0, -std::f64::consts::FRAC_PI_2, 0.0, 0.0, 0.0],
        sign_corrections: [1; 6],
        dof: 6,
    })
}

/// Joint vectors spread over the IRB 1600's ranges (a fixed sequence).
fn joints(robot: &Robot, n: usize) -> Vec<[f64; 6]> {
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let mut next = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let lim = *robot.joint_limits_rad();
    (0..n)
        .map(|_| std::array::from_fn(|i| lim[i][0] + (lim[i][1] - lim[i][0]) * next()))
        .collect()
}

#[test]
fn opw_forward_kinematics_equals_postproc_nominal_model() {
    let (robot, opw) = (irb1600(), irb1600_opw());
    for q in joints(&robot, 500) {
        let ours = robot.flange_pose(Model::Nominal, &q);
        let theirs = opw.forward(&q);
        for i in 0..3 {
            let (a, b) = (
                ours.translation.vector[i],
                theirs.translation.vector[i] * 1000.0,
            );
            assert!((a - b).abs() <= FK_POS_TOL_MM, "{q:?}: {a} against {b} mm");
        }
        let (a, b) = (ours.rotation.coords, theirs.rotation.coords);
        // The same rotation: equal quaternions up to sign.
        let sign = if a.dot(&b) < 0.0 { -1.0 } else { 1.0 };
        for i in 0..4 {
            assert!(
                (a[i] - sign * b[i]).abs() <= FK_ROT_TOL,
                "{q:?}: quaternion {a:?} against {b:?}"
            );
        }
    }
}

/// Angle difference wrapped into (−π, π].
fn wrapped(a: f64) -> f64 {
    let t = std::f64::consts::TAU;
    a - t * (a / t).round()
}

#[test]
fn opw_inverse_solutions_are_postproc_closed_form_solutions() {
    let (robot, opw) = (irb1600(), irb1600_opw());
    let same = |a: &[f64; 6], b: &[f64; 6]| {
        a.iter()
            .zip(b)
            .all(|(x, y)| wrapped(x - y).abs() <= IK_JOINT_TOL_RAD)
    };
    let mut compared = 0;
    for q in joints(&robot, 500) {
        let pose = robot.flange_pose(Model::Nominal, &q);
        let ours: Vec<[f64; 6]> = robot
            .ik_all(&pose)
            .expect("reachable: the pose of joint values")
            .into_iter()
            .flatten()
            .collect();
        let theirs = opw.inverse(&opw.forward(&q));
        assert!(
            ours.iter().any(|s| same(s, &q)),
            "{q:?}: postproc's solutions miss the joints of the pose"
        );
        assert_eq!(
            ours.len(),
            theirs.len(),
            "{q:?}: {ours:?} against {theirs:?}"
        );
        for s in &theirs {
            assert!(
                ours.iter().any(|o| same(o, s)),
                "{q:?}: OPW solution {s:?} is not among {ours:?}"
            );
        }
        compared += theirs.len();
    }
    assert!(compared >= 500 * 4, "{compared} solutions compared");
}
