//! Integration tests: `ConfL \Off` / `ConfJ \Off` through the binary, on
//! both bundled robots. With configuration monitoring off a move takes the
//! solution nearest the previous move's joints whatever its confdata says;
//! the compensated target is written with that solution's confdata and
//! lands on the programmed pose; `\On` restores the confdata of the targets.

use nalgebra::{Isometry3, Vector3};
use postproc::machine::robot::pose::{pose_error, rotation_to_abb};
use postproc::machine::robot::{ConfData, Model, PointMass, Robot};
use postproc::predict::EffectSet;
use postproc::predict::MoveContext;
use postproc::program::rapid::{DataValue, Module, RobTarget, Target, parse_module};

use crate::common::{
    postproc, repo, robtarget_conf as conf, robtarget_pose as pose, without_header, write,
};

/// Agreement of the predicted attained TCP with the programmed one (the
/// written 3-decimal position and 7-decimal quaternion: tests/rapid_cli.rs).
const POS_TOL_MM: f64 = 1e-3;
const ROT_TOL_RAD: f64 = 1e-6;
/// Agreement of the controller's joints of a compensated target with the
/// nominal solution it was made from, rad: compensation moves them by the
/// joint motion of a correction under 2 mm at over 0.5 m (4e-3 rad); the
/// configurations the confdata asked for lie half a turn away.
const JOINTS_RAD: f64 = 0.01;

/// Starting joints (MoveAbsJ), degrees.
const START_DEG: [f64; 6] = [10.0, -5.0, 25.0, 30.0, 60.0, -40.0];
/// Joints of the free moves' targets, degrees: near the start.
const A_DEG: [f64; 6] = [14.0, -2.0, 21.0, 38.0, 64.0, -48.0];
const B_DEG: [f64; 6] = [18.0, 0.0, 18.0, 44.0, 66.0, -55.0];

/// (name, machine text): the bundled IRB 1600 and TX200 (the TX200 file
/// mounted for the samples' cell: tests/robot_samples.rs).
pub(crate) fn robots() -> [(&'static str, String); 2] {
    let text =
        |n: &str| std::fs::read_to_string(repo(&format!("machines/{n}.yaml"))).expect("file");
    [
        ("abb-irb1600", text("abb-irb1600")),
        ("staubli-tx200", text("staubli-tx200")),
    ]
}

pub(crate) fn with_spindle(r: Robot) -> Robot {
    r.with_tool(
        Isometry3::translation(0.0, 0.0, 182.5),
        Some(PointMass {
            mass_kg: 2.4,
            com_mm: Vector3::new(0.0, 0.0, 85.0),
        }),
    )
}

fn robtarget_text(p: &Isometry3<f64>, c: ConfData) -> String {
    let t = p.translation.vector;
    let q = rotation_to_abb(&p.rotation);
    format!(
        "[[{:.4},{:.4},{:.4}],[{:.9},{:.9},{:.9},{:.9}],[{},{},{},{}],[9E9,9E9,9E9,9E9,9E9,9E9]]",
        t.x, t.y, t.z, q[0], q[1], q[2], q[3], c.cf1, c.cf4, c.cf6, c.cfx
    )
}

/// The module: a MoveAbsJ start, then with ConfJ/ConfL off a MoveJ and a
/// MoveL to targets whose confdata is wrong (joints 4 and 6 half a turn
/// off), then ConfL on and a MoveL back to A with its true confdata.
/// `off`: whether the `ConfX \Off` lines are there.
pub(crate) fn module(r: &Robot, off: bool) -> (String, [ConfData; 2]) {
    let rad = |d: [f64; 6]| d.map(f64::to_radians);
    let (qa, qb) = (rad(A_DEG), rad(B_DEG));
    let (ca, cb) = (r.confdata(&qa), r.confdata(&qb));
    let wrong = |c: ConfData| ConfData {
        cf4: c.cf4 + 2,
        cf6: c.cf6 - 2,
        ..c
    };
    let a = r.tcp_pose(Model::Nominal, &qa);
    let b = r.tcp_pose(Model::Nominal, &qb);
    let s = START_DEG.map(|v| format!("{v}")).join(",");
    let switches = if off {
        "    ConfJ \\Off;\n    ConfL\\Off;\n"
    } else {
        ""
    };
    let text = format!(
        "MODULE FreeConf\n  PERS tooldata tSpindle := [TRUE,[[0,0,182.5],[1,0,0,0]],[2.4,[0,0,85],[1,0,0,0],0.012,0.012,0.004]];\n  CONST jointtarget jStart := [[{s}],[9E9,9E9,9E9,9E9,9E9,9E9]];\n  CONST robtarget pA := {};\n  CONST robtarget pB := {};\n  CONST robtarget pA2 := {};\n\n  PROC main()\n{switches}    MoveAbsJ jStart, v1000, fine, tSpindle;\n    MoveJ pA, v500, z10, tSpindle;\n    MoveL pB, v100, fine, tSpindle;\n    confl \\on;\n    MoveL pA2, v100, fine, tSpindle;\n  ENDPROC\nENDMODULE\n",
        robtarget_text(&a, wrong(ca)),
        robtarget_text(&b, wrong(cb)),
        robtarget_text(&a, ca),
    );
    (text, [ca, cb])
}

fn robtarget<'a>(m: &'a Module, name: &str) -> &'a RobTarget {
    match m.decl(name).and_then(|d| d.value.as_ref()) {
        Some(DataValue::RobTarget(rt)) => rt,
        v => panic!("{name}: {v:?}"),
    }
}

fn run(
    dir: &std::path::Path,
    machine: &std::path::Path,
    src: &str,
    extra: &[&str],
) -> std::process::Output {
    let input = write(dir, "free.mod", src);
    postproc()
        .arg("compensate")
        .arg(&input)
        .arg("--machine")
        .arg(machine)
        .arg("-o")
        .arg(dir.join("free.out.mod"))
        .args(extra)
        .output()
        .expect("runs")
}

/// With monitoring off, the targets with wrong confdata are compensated in
/// the configuration nearest the previous joints (the one they were made
/// from), written with its confdata, and land on the programmed poses;
/// without the `\Off` lines the same module is refused; with no effect it
/// comes back byte for byte.
#[test]
fn conf_off_solves_nearest_and_writes_its_confdata_on_both_robots() {
    let dir = tempfile::tempdir().expect("tempdir");
    for (name, text) in robots() {
        let machine = write(dir.path(), &format!("{name}.yaml"), &text);
        let robot = with_spindle(Robot::from_yaml_str(&text, name).expect("valid"));
        let (src, [ca, cb]) = module(&robot, true);
        let out = run(
            dir.path(),
            &machine,
            &src,
            &["--effects", "kinematic,gravity"],
        );
        assert!(
            out.status.success(),
            "{name}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        let written = std::fs::read_to_string(dir.path().join("free.out.mod")).expect("output");
        let (m_in, m_out) = (
            parse_module(&src, "in").expect("parses"),
            parse_module(&written, "out").expect("parses"),
        );
        let moves: Vec<_> = m_out.moves().collect();
        assert_eq!(moves.len(), 4);
        let expected = [("pA", ca, A_DEG), ("pB", cb, B_DEG), ("pA2", ca, A_DEG)];
        for (mv, (declared, want, q_deg)) in moves[1..].iter().zip(expected) {
            let Target::Named { name: n_out, .. } = &mv.target else {
                panic!("{name}: {:?}", mv.target)
            };
            let rt = robtarget(&m_out, n_out);
            assert_eq!(conf(rt), want, "{name} {declared}: written confdata");
            let q = robot
                .ik_conf(&pose(rt), conf(rt))
                .unwrap_or_else(|e| panic!("{name} {declared}: {e}"));
            for (j, v) in q.iter().enumerate() {
                assert!(
                    (v - q_deg[j].to_radians()).abs() < JOINTS_RAD,
                    "{name} {declared}: joint {}",
                    j + 1
                );
            }
            let programmed = pose(robtarget(&m_in, declared));
            let (dp, dr) = pose_error(
                &robot.predict(&MoveContext::default(), &q, EffectSet::ALL),
                &programmed,
            );
            assert!(
                dp.norm() < POS_TOL_MM,
                "{name} {declared}: {} mm",
                dp.norm()
            );
            assert!(
                dr.norm() < ROT_TOL_RAD,
                "{name} {declared}: {} rad",
                dr.norm()
            );
        }
        // The statements are what makes the difference.
        let (strict, _) = module(&robot, false);
        let out = run(
            dir.path(),
            &machine,
            &strict,
            &["--effects", "kinematic,gravity"],
        );
        assert_eq!(out.status.code(), Some(2), "{name}");
        assert!(
            String::from_utf8_lossy(&out.stderr).contains("no joint solution with confdata"),
            "{name}"
        );
        // Identity without effects.
        let out = run(
            dir.path(),
            &machine,
            &src,
            &["--effects", "none", "--annotate", "none"],
        );
        assert!(out.status.success(), "{name}");
        let back = std::fs::read(dir.path().join("free.out.mod")).expect("output");
        assert!(without_header(&back) == src.as_bytes(), "{name}");
    }
}

/// `ConfL \On` after `\Off` restores the confdata of the targets: a wrong
/// confdata there is refused.
#[test]
fn conf_on_restores_the_targets_confdata() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (name, text) = robots().into_iter().next().expect("a robot");
    let machine = write(dir.path(), &format!("{name}.yaml"), &text);
    let robot = with_spindle(Robot::from_yaml_str(&text, name).expect("valid"));
    let (src, [ca, _]) = module(&robot, true);
    // pA2 (after `confl \on`) gets pA's wrong confdata.
    let right = robtarget_text(
        &robot.tcp_pose(Model::Nominal, &A_DEG.map(f64::to_radians)),
        ca,
    );
    let wrong_line = src
        .lines()
        .find(|l| l.contains("robtarget pA :="))
        .expect("pA")
        .replace("pA :=", "pA2 :=");
    let src = src.replace(&format!("  CONST robtarget pA2 := {right};"), &wrong_line);
    assert!(src.matches("pA2 :=").count() == 1);
    let out = run(
        dir.path(),
        &machine,
        &src,
        &["--effects", "kinematic,gravity"],
    );
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("target `pA2`"), "{err}");
}

/// Which moves `ConfL`/`ConfJ` set free: by kind, until `\On`, each routine
/// starting on; MoveAbsJ never; other statements and look-alikes change
/// nothing.
#[test]
fn configuration_free_moves_follow_the_switches_per_routine() {
    let src = "MODULE M\n  PROC a()\n    MoveL p1, v100, fine, tool0;\n    ConfL \\Off;\n    MoveJ p2, v100, fine, tool0;\n    MoveL p3, v100, fine, tool0;\n    MoveC p4, p5, v100, fine, tool0;\n    ConfLine \\Off;\n    confj\\OFF;\n    MoveJ p6, v100, fine, tool0;\n    MoveAbsJ j1, v100, fine, tool0;\n    ConfL \\On;\n    MoveL p7, v100, fine, tool0;\n  ENDPROC\n  PROC b()\n    MoveJ p8, v100, fine, tool0;\n    MoveL p9, v100, fine, tool0;\n  ENDPROC\nENDMODULE\n";
    let m = parse_module(src, "m.mod").expect("parses");
    let free = m.configuration_free_moves(src);
    let names: Vec<String> = m
        .moves()
        .filter(|mv| free.contains(&mv.span.start))
        .map(|mv| match &mv.target {
            Target::Named { name, .. } => name.clone(),
            t => panic!("{t:?}"),
        })
        .collect();
    assert_eq!(names, ["p3", "p5", "p6"]);
}
