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
use postproc::machine::robot::Model;
use postproc::program::gcode::{Block, parse_line};
use rs_opw_kinematics::kinematic_traits::Kinematics;

#[path = "../benches/peer_setup.rs"]
mod peer_setup;
use peer_setup::{irb1600, irb1600_opw, joints};

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
