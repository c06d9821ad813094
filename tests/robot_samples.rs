//! Integration tests: every bundled RAPID sample (the controller backup
//! included) compensated on every bundled robot through the binary, the
//! written targets checked against the forward kinematics of the robot library (the controller's inverse
//! of the written target and confdata, then the predicted attained pose).
//!
//! The samples describe a cell in front of an IRB 1600: the plate lies
//! 700–850 mm from the robot's axis 1, 350 mm up. The TX200 is a larger arm:
//! with joint 3 within ±145° its wrist centre cannot come closer than
//! about 545 mm to its shoulder, so the plate is out of its reach in the
//! samples' configurations from the world origin. The bundled TX200 file
//! therefore stands where the arm would in that cell: its `base` sets it
//! 300 mm behind the world origin, the cell otherwise unchanged. Both
//! bundled files are used as they are.

use nalgebra::{Isometry3, Translation3, Vector3};
use postproc::machine::robot::pose::pose_error;
use postproc::machine::robot::{Model, PointMass, Robot};
use postproc::predict::EffectSet;
use postproc::predict::MoveContext;
use postproc::program::rapid::{DataValue, Module, RobTarget, Target, parse_module};

use crate::common::{
    postproc, repo, robtarget_conf as conf, robtarget_pose as pose, text, tx200_at_the_origin_text,
    without_header, write,
};

/// Position agreement of the predicted attained TCP with the programmed one,
/// mm: the written position's 3 decimals move the TCP by at most
/// 0.0005·√3 = 0.00087 mm (the derivation of tests/rapid_cli.rs).
const POS_TOL_MM: f64 = 1e-3;
/// Orientation agreement, rad: 7-decimal quaternions move the rotation by
/// at most 2e-7 rad.
const ROT_TOL_RAD: f64 = 1e-6;
/// A MoveAbsJ target's agreement, mm and rad: 6-decimal degrees move each
/// joint by 8.7e-9 rad; the TX200's lever arm to the TCP is under 2.6 m:
/// 6 · 8.7e-9 · 2600 mm = 0.00014 mm.
const JOINT_POS_TOL_MM: f64 = 1e-3;
const JOINT_ROT_TOL_RAD: f64 = 1e-6;

/// The bundled RAPID samples.
const SAMPLES: [&str; 2] = ["drilling", "milling"];

/// (name, machine file text) of both bundled robots, as the samples run them.
fn robots() -> [(&'static str, String); 2] {
    ["abb-irb1600", "staubli-tx200"].map(|n| (n, text(&format!("machines/{n}.yaml"))))
}

/// The samples' spindle (tDrill / tMill): TCP 182.5 mm along the flange z
/// axis, 2.4 kg at 85 mm.
fn with_spindle(r: Robot) -> Robot {
    r.with_tool(
        Isometry3::translation(0.0, 0.0, 182.5),
        Some(PointMass {
            mass_kg: 2.4,
            com_mm: Vector3::new(0.0, 0.0, 85.0),
        }),
    )
}

/// The samples' plate frame (wPlate / wPart): translation (600, -200, 350).
fn plate() -> Isometry3<f64> {
    Isometry3::translation(600.0, -200.0, 350.0)
}

fn declared<'a>(m: &'a Module, name: &str, index: Option<usize>) -> &'a DataValue {
    let d = m.decl(name).expect("declared");
    let v = d.value.as_ref().expect("a value");
    match (v, index) {
        (DataValue::Array { items, .. }, Some(i)) => &items[i - 1],
        (v, None) => v,
        (v, _) => panic!("not an array: {v:?}"),
    }
}

fn robtarget<'a>(m: &'a Module, name: &str, index: Option<usize>) -> &'a RobTarget {
    match declared(m, name, index) {
        DataValue::RobTarget(rt) => rt,
        v => panic!("not a robtarget: {v:?}"),
    }
}

/// Programmed TCP pose (world) of an input move's target: a named
/// robtarget (no work object) or `Offs` of an array element in the plate.
fn programmed(m: &Module, t: &Target) -> Isometry3<f64> {
    match t {
        Target::Named {
            name, index: None, ..
        } => pose(robtarget(m, name, None)),
        Target::Offs { base, offsets, .. } => {
            let Target::Named {
                name,
                index: Some(ix),
                ..
            } = base.as_ref()
            else {
                panic!("Offs of an array element")
            };
            let d = Vector3::new(
                offsets[0].value.expect("dx"),
                offsets[1].value.expect("dy"),
                offsets[2].value.expect("dz"),
            );
            let p = pose(robtarget(m, name, Some(ix.value.expect("index"))));
            plate()
                * Isometry3::from_parts(Translation3::from(p.translation.vector + d), p.rotation)
        }
        t => panic!("unexpected target {t:?}"),
    }
}

fn compensate(
    dir: &std::path::Path,
    sample: &str,
    machine: &std::path::Path,
    extra: &[&str],
) -> (String, String) {
    let input = dir.join(format!("{sample}.mod"));
    std::fs::copy(repo(&format!("samples/{sample}.mod")), &input).expect("copy sample");
    let output = dir.join(format!("{sample}.out.mod"));
    postproc()
        .arg("compensate")
        .arg(&input)
        .arg("--machine")
        .arg(machine)
        .arg("-o")
        .arg(&output)
        .args(extra)
        .assert()
        .success();
    (
        std::fs::read_to_string(&input).expect("input"),
        std::fs::read_to_string(&output).expect("output"),
    )
}

/// Every move of every sample, compensated on each bundled robot, lands on
/// its programmed pose: the written robtarget (position, quaternion,
/// confdata) solved by the controller's inverse kinematics — the numeric
/// one on the TX200 — and predicted by the robot model, or the written
/// joints of a MoveAbsJ predicted directly.
#[test]
fn both_robots_compensate_every_sample_within_the_tolerance() {
    let dir = tempfile::tempdir().expect("tempdir");
    for (robot_name, machine_text) in robots() {
        let machine = write(dir.path(), &format!("{robot_name}.yaml"), &machine_text);
        let robot = with_spindle(Robot::from_yaml_str(&machine_text, robot_name).expect("valid"));
        for sample in SAMPLES {
            let (src_in, src_out) = compensate(
                dir.path(),
                sample,
                &machine,
                // The MoveAbsJ too, compensated in joint space.
                &[
                    "--effects",
                    "kinematic,gravity",
                    "--compensate-joint-targets",
                ],
            );
            let m_in = parse_module(&src_in, "in").expect("input parses");
            let m_out = parse_module(&src_out, "out").expect("output parses");
            let (a, b): (Vec<_>, Vec<_>) = (m_in.moves().collect(), m_out.moves().collect());
            assert_eq!(a.len(), b.len());
            let mut checked = 0;
            for (mi, mo) in a.iter().zip(&b) {
                let what = format!("{robot_name} {sample} line {}", mi.line);
                let Target::Named { name, .. } = &mo.target else {
                    panic!("{what}: written target {:?}", mo.target)
                };
                let (dp, dr, tol) = match declared(&m_out, name, None) {
                    DataValue::JointTarget(jt) => {
                        let Target::Named { name: n_in, .. } = &mi.target else {
                            panic!("{what}: a named jointtarget")
                        };
                        let DataValue::JointTarget(j_in) = declared(&m_in, n_in, None) else {
                            panic!("{what}: a jointtarget")
                        };
                        let goal = robot.tcp_pose(
                            Model::Nominal,
                            &j_in.robax.each_ref().map(|n| n.value.to_radians()),
                        );
                        let q = jt.robax.each_ref().map(|n| n.value.to_radians());
                        let (dp, dr) = pose_error(
                            &robot.predict(&MoveContext::default(), &q, EffectSet::ALL),
                            &goal,
                        );
                        (dp, dr, (JOINT_POS_TOL_MM, JOINT_ROT_TOL_RAD))
                    }
                    DataValue::RobTarget(rt) => {
                        let frame = if mo.wobj.is_some() {
                            plate()
                        } else {
                            Isometry3::identity()
                        };
                        let q = robot
                            .ik_conf(&(frame * pose(rt)), conf(rt))
                            .unwrap_or_else(|e| panic!("{what}: controller IK: {e}"));
                        let (dp, dr) = pose_error(
                            &robot.predict(&MoveContext::default(), &q, EffectSet::ALL),
                            &programmed(&m_in, &mi.target),
                        );
                        (dp, dr, (POS_TOL_MM, ROT_TOL_RAD))
                    }
                    v => panic!("{what}: {v:?}"),
                };
                assert!(dp.norm() < tol.0, "{what}: {} mm", dp.norm());
                assert!(dr.norm() < tol.1, "{what}: {} rad", dr.norm());
                checked += 1;
            }
            assert_eq!(checked, a.len());
            assert!(checked >= 16, "{robot_name} {sample}: {checked} moves");
        }
    }
}

/// With no effect and no annotation, every sample comes back byte for byte
/// on each bundled robot (the header aside).
#[test]
fn both_robots_write_every_sample_back_unchanged_without_effects() {
    let dir = tempfile::tempdir().expect("tempdir");
    for (robot_name, machine_text) in robots() {
        let machine = write(dir.path(), &format!("{robot_name}.yaml"), &machine_text);
        for sample in SAMPLES {
            let (src_in, src_out) = compensate(
                dir.path(),
                sample,
                &machine,
                &["--effects", "none", "--annotate", "none"],
            );
            assert!(
                without_header(src_out.as_bytes()) == src_in.as_bytes(),
                "{robot_name} {sample}"
            );
        }
    }
}

/// The TX200 at the world origin (the bundled file without its base)
/// cannot reach the samples' plate: the refusal names the target, its
/// configuration and the configurations that do reach it.
#[test]
fn tx200_at_the_origin_names_the_configurations_that_reach_the_plate() {
    let dir = tempfile::tempdir().expect("tempdir");
    let input = dir.path().join("milling.mod");
    std::fs::copy(repo("samples/milling.mod"), &input).expect("copy sample");
    let machine = write(dir.path(), "tx200.yaml", &tx200_at_the_origin_text());
    let out = postproc()
        .arg("compensate")
        .arg(&input)
        .arg("--machine")
        .arg(&machine)
        .arg("-o")
        .arg(dir.path().join("out.mod"))
        .output()
        .expect("runs");
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("no joint solution with confdata [0,0,0,0] (reachable configurations: ["),
        "{err}"
    );
    assert!(err.contains("milling.mod:43:"), "{err}");
}

/// The controller backup's gripper (tGripper): TCP 150 mm along the flange
/// z axis, 2 kg at 60 mm.
fn with_gripper(r: Robot) -> Robot {
    r.with_tool(
        Isometry3::translation(0.0, 0.0, 150.0),
        Some(PointMass {
            mass_kg: 2.0,
            com_mm: Vector3::new(0.0, 0.0, 60.0),
        }),
    )
}

/// The controller backup's conveyor frame (wTable): translation
/// (400, -300, 200).
fn table() -> Isometry3<f64> {
    Isometry3::translation(400.0, -300.0, 200.0)
}

/// The robot view of a move's tool and its work object, by the names the
/// bundled samples use.
fn view_of(robot: &Robot, mv: &postproc::program::rapid::Move) -> (Robot, Isometry3<f64>) {
    let view = match &*mv.tool.text {
        "tDrill" | "tMill" => with_spindle(robot.clone()),
        "tGripper" => with_gripper(robot.clone()),
        t => panic!("tool {t}"),
    };
    let frame = match mv.wobj.as_ref().map(|w| &*w.text) {
        None => Isometry3::identity(),
        Some("wPlate" | "wPart") => plate(),
        Some("wTable") => table(),
        Some(w) => panic!("wobj {w}"),
    };
    (view, frame)
}

/// A copy of the controller-backup sample's task folder in `dir`.
fn backup_copy(dir: &std::path::Path) -> std::path::PathBuf {
    let from = repo("samples/cell-backup/RAPID/TASK1");
    let task = dir.join("TASK1");
    for sub in ["PROGMOD", "SYSMOD"] {
        std::fs::create_dir_all(task.join(sub)).expect("mkdir");
        for e in std::fs::read_dir(from.join(sub)).expect("dir") {
            let p = e.expect("entry").path();
            std::fs::copy(&p, task.join(sub).join(p.file_name().expect("name"))).expect("copy");
        }
    }
    task
}

/// The command a user types, with the bundled TX200 file as it is:
/// `postproc compensate samples/drilling.mod --machine
/// machines/staubli-tx200.yaml` (and the milling sample, and the
/// controller-backup task folder as one program) succeeds with the default
/// effects, and every robtarget it writes is one the controller solves in
/// its written confdata within the joint limits.
#[test]
fn bundled_tx200_compensates_every_sample_as_a_user_runs_it() {
    let dir = tempfile::tempdir().expect("tempdir");
    let machine = repo("machines/staubli-tx200.yaml");
    let robot = Robot::from_yaml_str(&text("machines/staubli-tx200.yaml"), "tx200").expect("valid");
    let task = backup_copy(dir.path());
    let mut inputs: Vec<std::path::PathBuf> = SAMPLES
        .iter()
        .map(|s| {
            let p = dir.path().join(format!("{s}.mod"));
            std::fs::copy(repo(&format!("samples/{s}.mod")), &p).expect("copy sample");
            p
        })
        .collect();
    inputs.push(task.clone());
    for input in &inputs {
        let out = postproc()
            .arg("compensate")
            .arg(input)
            .arg("--machine")
            .arg(&machine)
            .output()
            .expect("runs");
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(0), "{}: {err}", input.display());
        assert!(err.contains("moves compensated"), "{err}");
    }
    let written = [
        dir.path().join("drilling.comp.mod"),
        dir.path().join("milling.comp.mod"),
        task.join("PROGMOD/MainModule.comp.mod"),
    ];
    let mut checked = 0;
    for path in &written {
        let src = std::fs::read_to_string(path).expect("written module");
        let m = parse_module(&src, "out").expect("output parses");
        for mv in m.moves() {
            let Target::Named {
                name, index: None, ..
            } = &mv.target
            else {
                continue;
            };
            let Some(DataValue::RobTarget(rt)) = m.decl(name).and_then(|d| d.value.as_ref()) else {
                continue;
            };
            let (view, frame) = view_of(&robot, mv);
            view.ik_conf(&(frame * pose(rt)), conf(rt))
                .unwrap_or_else(|e| panic!("{} line {}: {e}", path.display(), mv.line));
            checked += 1;
        }
    }
    assert!(checked >= 36, "{checked} written targets");
}

/// The controller-backup task folder compensated as one program on the
/// bundled TX200: the moves whose target is known before run time land on
/// their programmed pose (the written robtarget solved by the controller's
/// inverse kinematics in its written confdata, then predicted), the three
/// whose target is reassigned in the stacking loop are left as written.
#[test]
fn bundled_tx200_compensates_the_controller_backup_within_the_tolerance() {
    let dir = tempfile::tempdir().expect("tempdir");
    let task = backup_copy(dir.path());
    let out = postproc()
        .arg("compensate")
        .arg(&task)
        .arg("--machine")
        .arg(repo("machines/staubli-tx200.yaml"))
        .args(["--effects", "kinematic,gravity"])
        .output()
        .expect("runs");
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{err}");
    let read = |rel: &str| std::fs::read_to_string(task.join(rel)).expect("module");
    let (calib_src, user_src) = (read("PROGMOD/CalibData.mod"), read("SYSMOD/user.sys"));
    let (in_src, out_src) = (
        read("PROGMOD/MainModule.mod"),
        read("PROGMOD/MainModule.comp.mod"),
    );
    let calib = parse_module(&calib_src, "CalibData").expect("parses");
    let user = parse_module(&user_src, "user").expect("parses");
    let m_in = parse_module(&in_src, "in").expect("parses");
    let m_out = parse_module(&out_src, "out").expect("parses");
    let num = |s: &postproc::program::rapid::Scalar| match s.value {
        Some(v) => v,
        None => match declared(&user, &s.text, None) {
            DataValue::Num(n) => n.value,
            v => panic!("{v:?}"),
        },
    };
    // Programmed pose (wTable frame) of an input move's target.
    let programmed = |t: &Target| match t {
        Target::Named { name, .. } => pose(robtarget(&calib, name, None)),
        Target::Offs { base, offsets, .. } => {
            let Target::Named { name, .. } = base.as_ref() else {
                panic!("Offs of a name")
            };
            let p = pose(robtarget(&calib, name, None));
            let d = Vector3::new(num(&offsets[0]), num(&offsets[1]), num(&offsets[2]));
            Isometry3::from_parts(Translation3::from(p.translation.vector + d), p.rotation)
        }
        t => panic!("unexpected target {t:?}"),
    };
    let robot = Robot::from_yaml_str(&text("machines/staubli-tx200.yaml"), "tx200").expect("valid");
    let effects = EffectSet {
        kinematic: 1.0,
        gravity: 1.0,
        ..EffectSet::NONE
    };
    let (a, b): (Vec<_>, Vec<_>) = (m_in.moves().collect(), m_out.moves().collect());
    assert_eq!(a.len(), b.len());
    let (mut compensated, mut as_written) = (0, 0);
    for (mi, mo) in a.iter().zip(&b) {
        let (t_in, t_out) = (&in_src[mi.target.span()], &out_src[mo.target.span()]);
        if t_in.contains("pStack") {
            assert_eq!(t_in, t_out, "line {}", mi.line);
            as_written += 1;
            continue;
        }
        let Target::Named { name, .. } = &mo.target else {
            panic!("line {}: written target {t_out}", mi.line)
        };
        let rt = robtarget(&m_out, name, None);
        let (view, frame) = view_of(&robot, mo);
        let q = view
            .ik_conf(&(frame * pose(rt)), conf(rt))
            .unwrap_or_else(|e| panic!("line {}: controller IK: {e}", mi.line));
        let (dp, dr) = pose_error(
            &view.predict(&MoveContext::default(), &q, effects),
            &(frame * programmed(&mi.target)),
        );
        assert!(dp.norm() < POS_TOL_MM, "line {}: {} mm", mi.line, dp.norm());
        assert!(
            dr.norm() < ROT_TOL_RAD,
            "line {}: {} rad",
            mi.line,
            dr.norm()
        );
        compensated += 1;
    }
    assert_eq!((compensated, as_written), (4, 3));
}
