//! Integration tests: `postproc compensate` of RAPID modules through the real
//! binary, checked against the robot library.

use approx::assert_abs_diff_eq;
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use postproc::machine::ThermalStart;
use postproc::machine::robot::pose::pose_error;
use postproc::machine::robot::{Model, PointMass, Robot};
use postproc::pipeline::rapid::{RapidOptions, compensate_module};
use postproc::predict::EffectSet;
use postproc::predict::MoveContext;
use postproc::program::rapid::{DataValue, Module, RobTarget, Target, parse_module};

use crate::common::{
    postproc, repo, robtarget_conf as conf, robtarget_pose as pose, text_without_header,
    without_header, write,
};

/// Position agreement of the predicted attained TCP with the programmed one,
/// mm. Derivation: the compensation itself converges to 1e-7 mm; writing
/// the position with 3 decimals moves the commanded TCP by at most
/// 0.0005 mm per axis, |δ| ≤ 0.0005·√3 = 0.00087 mm, and the attained pose
/// follows the commanded one 1:1 to first order (deflection changes by
/// ~1e-3 of that). So 1 µm holds.
const POS_TOL_MM: f64 = 1e-3;
/// Orientation agreement, rad (1 µrad). Derivation: the IRB 1600 file
/// writes quaternions with 7 decimals: each component moves by ≤ 5e-8, so
/// |δq| ≤ 5e-8·√4 = 1e-7 and the rotation by at most 2·|δq| = 2e-7 rad
/// (the best of the 16 roundings is never worse than plain rounding).
const ROT_TOL_RAD: f64 = 1e-6;
/// Position agreement of a MoveAbsJ target written with 6-decimal degrees,
/// mm (1 µm). Derivation: each joint moves by ≤ 0.0000005° =
/// 8.7e-9 rad; the lever arm from any joint axis to the TCP is < 1.6 m for
/// this arm + tool (0.7 + 0.6 + 0.065 + 0.1825 m), so
/// |δp| ≤ 6 · 8.7e-9 · 1600 mm = 0.000084 mm, plus the solve's residual.
const JOINT_POS_TOL_MM: f64 = 0.001;
/// Orientation agreement for the MoveAbsJ target (1 µrad): Σ|δq| ≤
/// 6 · 8.7e-9 rad.
const JOINT_ROT_TOL_RAD: f64 = 1e-6;

fn robot_with_drill() -> Robot {
    let text = std::fs::read_to_string(repo("machines/abb-irb1600.yaml")).expect("machine file");
    let r = Robot::from_yaml_str(&text, "abb-irb1600.yaml").expect("valid robot");
    // tDrill of samples/drilling.mod: TCP 182.5 mm along the flange z axis,
    // 2.4 kg at 85 mm; no process load (the tests that use this view run
    // with --effects kinematic,gravity or set the load per move).
    r.with_tool(
        Isometry3::translation(0.0, 0.0, 182.5),
        Some(PointMass {
            mass_kg: 2.4,
            com_mm: Vector3::new(0.0, 0.0, 85.0),
        }),
    )
}

fn robtarget<'a>(m: &'a Module, name: &str, index: Option<usize>) -> &'a RobTarget {
    let d = m.decl(name).expect("declared");
    match (&d.value, index) {
        (Some(DataValue::RobTarget(rt)), None) => rt,
        (Some(DataValue::Array { items, .. }), Some(i)) => match &items[i - 1] {
            DataValue::RobTarget(rt) => rt,
            v => panic!("not a robtarget: {v:?}"),
        },
        v => panic!("not a robtarget: {v:?}"),
    }
}

/// wPlate of the sample: uframe translation (600, -200, 350), no rotation.
fn w_plate() -> Isometry3<f64> {
    Isometry3::translation(600.0, -200.0, 350.0)
}

fn run_sample(dir: &std::path::Path, extra: &[&str]) -> (std::path::PathBuf, std::path::PathBuf) {
    let input = dir.join("drilling.mod");
    std::fs::copy(repo("samples/drilling.mod"), &input).expect("copy sample");
    let output = dir.join("out.mod");
    let mut cmd = postproc();
    cmd.arg("compensate")
        .arg(&input)
        .args([
            "--machine",
            repo("machines/abb-irb1600.yaml").to_str().expect("utf8"),
        ])
        .arg("-o")
        .arg(&output)
        .args(extra);
    cmd.assert().success();
    (input, output)
}

#[test]
fn rapid_none_is_byte_identical() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (input, output) = run_sample(dir.path(), &["--effects", "none", "--annotate", "none"]);
    let a = std::fs::read(&input).expect("input");
    // The provenance header is the only addition.
    let b = without_header(&std::fs::read(&output).expect("output"));
    assert!(a == b, "output differs from the input");
}

#[test]
fn rapid_compensated_targets_land_on_programmed_poses() {
    let dir = tempfile::tempdir().expect("tempdir");
    // The joint targets too (the sample's jHome), as Cartesian poses.
    let (input, output) = run_sample(
        dir.path(),
        &[
            "--effects",
            "kinematic,gravity",
            "--compensate-joint-targets",
        ],
    );
    let src_in = std::fs::read_to_string(&input).expect("input");
    let src_out = std::fs::read_to_string(&output).expect("output");
    let m_in = parse_module(&src_in, "in").expect("input parses");
    let m_out = parse_module(&src_out, "out").expect("output re-parses");
    let robot = robot_with_drill();
    let moves_in: Vec<_> = m_in.moves().collect();
    let moves_out: Vec<_> = m_out.moves().collect();
    assert_eq!(moves_in.len(), moves_out.len());
    let mut checked = 0;
    for (a, b) in moves_in.iter().zip(&moves_out) {
        let line = src_out.lines().nth(b.line - 1).expect("line");
        assert!(line.contains("! dev "), "annotated: {line}");
        match &a.target {
            Target::Named {
                name, index: None, ..
            } if name == "jHome" => {
                // Programmed joints [0,-10,20,0,80,0]°: the goal is their
                // nominal TCP pose.
                let q_prog = [0.0f64, -10.0, 20.0, 0.0, 80.0, 0.0].map(f64::to_radians);
                let goal = robot.tcp_pose(Model::Nominal, &q_prog);
                let Some(DataValue::JointTarget(jt)) = &m_out.decl("jHome").expect("jHome").value
                else {
                    panic!("jointtarget")
                };
                let q = jt.robax.each_ref().map(|n| n.value.to_radians());
                let (dp, dr) = pose_error(
                    &robot.predict(&MoveContext::default(), &q, EffectSet::ALL),
                    &goal,
                );
                assert_abs_diff_eq!(dp.norm(), 0.0, epsilon = JOINT_POS_TOL_MM);
                assert_abs_diff_eq!(dr.norm(), 0.0, epsilon = JOINT_ROT_TOL_RAD);
            }
            Target::Named {
                name, index: None, ..
            } => {
                // pClear, no work object.
                let programmed = pose(robtarget(&m_in, name, None));
                let Target::Named { name: n2, .. } = &b.target else {
                    panic!("named")
                };
                let rt = robtarget(&m_out, n2, None);
                let q = robot.ik_conf(&pose(rt), conf(rt)).expect("controller IK");
                let (dp, dr) = pose_error(
                    &robot.predict(&MoveContext::default(), &q, EffectSet::ALL),
                    &programmed,
                );
                assert_abs_diff_eq!(dp.norm(), 0.0, epsilon = POS_TOL_MM);
                assert_abs_diff_eq!(dr.norm(), 0.0, epsilon = ROT_TOL_RAD);
            }
            Target::Offs { base, offsets, .. } => {
                let Target::Named {
                    name,
                    index: Some(ix),
                    ..
                } = base.as_ref()
                else {
                    panic!("Offs of an array element")
                };
                let i = ix.value.expect("literal index");
                // Offs(holes{i},dx,dy,dz): the hole translated in wPlate.
                let d = Vector3::new(
                    offsets[0].value.expect("dx"),
                    offsets[1].value.expect("dy"),
                    offsets[2].value.expect("dz"),
                );
                let hole = pose(robtarget(&m_in, name, Some(i)));
                let programmed = w_plate()
                    * Isometry3::from_parts(
                        Translation3::from(hole.translation.vector + d),
                        hole.rotation,
                    );
                let Target::Named { name: n2, .. } = &b.target else {
                    panic!("materialised: {:?}", b.target)
                };
                assert!(n2.starts_with(&format!("holes{i}_o")), "{n2}");
                let rt = robtarget(&m_out, n2, None);
                let q = robot
                    .ik_conf(&(w_plate() * pose(rt)), conf(rt))
                    .expect("controller IK");
                let (dp, dr) = pose_error(
                    &robot.predict(&MoveContext::default(), &q, EffectSet::ALL),
                    &programmed,
                );
                assert_abs_diff_eq!(dp.norm(), 0.0, epsilon = POS_TOL_MM);
                assert_abs_diff_eq!(dr.norm(), 0.0, epsilon = ROT_TOL_RAD);
            }
            t => panic!("unexpected target {t:?}"),
        }
        checked += 1;
    }
    // 2 MoveAbsJ + 2 pClear + 12 holes × 4 moves.
    assert_eq!(checked, 52);
}

#[test]
fn rapid_offs_target_is_materialised() {
    let dir = tempfile::tempdir().expect("tempdir");
    // Without thermal drift approach and retract have the same load state
    // (no thrust) and share one copy; with it every move has its own state.
    let (_, output) = run_sample(
        dir.path(),
        &[
            "--annotate",
            "none",
            "--effects",
            "kinematic,gravity,process",
        ],
    );
    let out = std::fs::read_to_string(&output).expect("output");
    assert!(!out.contains("Offs("), "every Offs is replaced");
    // Hole 3: approach (dz 40) and retract share holes3_o1; dz 2 → _o2,
    // dz -12 → _o3; declared after the holes array.
    assert!(out.contains("  LOCAL CONST robtarget holes3_o1 := [["));
    assert!(out.contains("    MoveJ holes3_o1, v500, zApproach, tDrill\\WObj:=wPlate;\n"));
    assert!(out.contains("    MoveL holes3_o3, vDrill, fine, tDrill\\WObj:=wPlate;\n"));
    assert!(out.contains("    MoveL holes3_o1, vRetract, z10, tDrill\\WObj:=wPlate;\n"));
    let holes_end = out.find("[9E9,9E9,9E9,9E9,9E9,9E9]]];").expect("array end");
    let decl = out.find("CONST robtarget holes1_o1").expect("decl");
    assert!(decl > holes_end);
    assert!(!out.contains("holes3_o4"));
}

#[test]
fn rapid_unreachable_target_exits_2_naming_its_line() {
    let dir = tempfile::tempdir().expect("tempdir");
    let input = dir.path().join("far.mod");
    let src = std::fs::read_to_string(repo("samples/drilling.mod")).expect("sample");
    let far = src.replace("pClear := [[750,0,650]", "pClear := [[5000,0,650]");
    assert_ne!(far, src);
    std::fs::write(&input, far).expect("write");
    let output = dir.path().join("far.out.mod");
    let out = postproc()
        .arg("compensate")
        .arg(&input)
        .args([
            "--machine",
            repo("machines/abb-irb1600.yaml").to_str().expect("utf8"),
        ])
        .arg("-o")
        .arg(&output)
        .output()
        .expect("run");
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    // pClear is declared on line 27; its literal starts at column 29
    // ("  CONST robtarget pClear := " is 28 bytes).
    assert!(err.contains("far.mod:27:29:"), "{err}");
    assert!(err.contains("out of reach"), "{err}");
    assert!(!output.exists(), "no output on error");
}

#[test]
fn rapid_target_under_two_tools_is_split() {
    let dir = tempfile::tempdir().expect("tempdir");
    let input = dir.path().join("split.mod");
    let src = "MODULE Split\n  PERS tooldata tLong := [TRUE,[[0,0,250],[1,0,0,0]],[4,[0,0,120],[1,0,0,0],0,0,0]];\n  CONST robtarget p10 := [[800,100,600],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\n  PROC main()\n    MoveL p10, v100, fine, tool0;\n    MoveL p10, v100, fine, tLong;\n    MoveL p10, v100, fine, tool0;\n  ENDPROC\nENDMODULE\n";
    std::fs::write(&input, src).expect("write");
    let output = dir.path().join("split.out.mod");
    postproc()
        .arg("compensate")
        .arg(&input)
        .args([
            "--machine",
            repo("machines/abb-irb1600.yaml").to_str().expect("utf8"),
        ])
        .args(["--annotate", "none", "-o"])
        .arg(&output)
        .assert()
        .success();
    let out = text_without_header(&std::fs::read_to_string(&output).expect("output"));
    let lines: Vec<&str> = out.lines().collect();
    assert!(lines[2].starts_with("  CONST robtarget p10 := [["), "{out}");
    assert!(
        lines[3].starts_with("  LOCAL CONST robtarget p10_c2 := [["),
        "{out}"
    );
    assert_eq!(lines[5], "    MoveL p10, v100, fine, tool0;");
    assert_eq!(lines[6], "    MoveL p10_c2, v100, fine, tLong;");
    assert_eq!(lines[7], "    MoveL p10, v100, fine, tool0;");
}

#[test]
fn rapid_confdata_without_solution_exits_2() {
    let dir = tempfile::tempdir().expect("tempdir");
    let input = dir.path().join("conf.mod");
    let src = std::fs::read_to_string(repo("samples/drilling.mod")).expect("sample");
    // Hole 1 lies at world y = -200 + 50 = -150 mm, so joint 1 is negative
    // (cf1 = -1); confdata [0,0,0,0] has no solution there.
    let bad = src.replacen(
        "[[100,50,0],[0,0,1,0],[-1,0,-1,0]",
        "[[100,50,0],[0,0,1,0],[0,0,0,0]",
        1,
    );
    assert_ne!(bad, src);
    std::fs::write(&input, bad).expect("write");
    let output = dir.path().join("conf.out.mod");
    let out = postproc()
        .arg("compensate")
        .arg(&input)
        .args([
            "--machine",
            repo("machines/abb-irb1600.yaml").to_str().expect("utf8"),
        ])
        .arg("-o")
        .arg(&output)
        .output()
        .expect("run");
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    // First use: line 51 `    MoveJ Offs(holes{1},0,0,40), …`; the Offs
    // expression starts after 4 spaces and "MoveJ " (column 11).
    assert!(err.contains("conf.mod:51:11:"), "{err}");
    assert!(
        err.contains("no joint solution with confdata [0,0,0,0]"),
        "{err}"
    );
    assert!(!output.exists(), "no output on error");
}

/// Thrust of the IRB 1600 file's drilling model at vDrill (4 mm/s), N:
/// K·(D/2)·f_rev = 450 · 3.4 · (4·60/3000 = 0.08 mm/rev) = 122.4 N.
const DRILL_THRUST_N: f64 = 122.4;

#[test]
fn drilling_sample_thrust_only_on_the_twelve_plunges_and_targets_land() {
    let src = std::fs::read_to_string(repo("samples/drilling.mod")).expect("sample");
    let text = std::fs::read_to_string(repo("machines/abb-irb1600.yaml")).expect("machine");
    let robot = Robot::from_yaml_str(&text, "abb-irb1600.yaml").expect("valid");
    let opts = RapidOptions {
        thermal_start: ThermalStart::Steady,
        ..RapidOptions::for_robot(&robot)
    };
    let out = compensate_module(&src, "drilling.mod", &robot, &opts).expect("compensates");
    let m_in = parse_module(&src, "in").expect("parses");
    let m_out = parse_module(&out.text, "out").expect("output re-parses");
    let moves_in: Vec<_> = m_in.moves().collect();
    let moves_out: Vec<_> = m_out.moves().collect();
    assert_eq!(out.records.len(), moves_in.len());
    // Thrust exactly on the twelve `vDrill` moves (the plunges), in the base
    // frame along −z of the programmed tool (checked per target below);
    // none on approach (v50: 1 mm/rev is positioning in air), on retract or
    // on joint moves.
    let mut drilled = 0;
    for (row, mv) in out.records.iter().zip(&moves_in) {
        assert_eq!(row.line, mv.line);
        let rec = row.robot.expect("a robot move's row");
        match (&rec.wrench, &*mv.speed.text) {
            (Some(w), "vDrill") => {
                assert!(!w.in_tool_frame());
                assert_abs_diff_eq!(w.force_n.norm(), DRILL_THRUST_N, epsilon = 1e-9);
                drilled += 1;
            }
            (None, s) => assert_ne!(s, "vDrill", "line {}", mv.line),
            (w, s) => panic!("line {}: {s} with {w:?}", mv.line),
        }
        // The thermal state is warm (steady), so the thermal share shows.
        // (Joint 1 turns about the vertical: gravity and the vertical thrust
        // give it no torque, so its modelled power is zero.)
        assert!(
            rec.thermal_power_w[1] > 0.0 && rec.deviation.thermal.pos_mm.norm() > 0.0,
            "line {}: {:?} {:?}",
            mv.line,
            rec.thermal_power_w,
            rec.deviation.thermal
        );
    }
    assert_eq!(drilled, 12);
    // Every WRITTEN Cartesian target, read back, lands within 1 µm / 1 µrad
    // once the controller's IK and the full prediction (with the move's
    // load and thermal state) are applied.
    let base = robot_with_drill();
    let mut checked = 0;
    for ((a, b), row) in moves_in.iter().zip(&moves_out).zip(&out.records) {
        let rec = row.robot.expect("a robot move's row");
        let view = &base;
        let ctx = MoveContext::default()
            .with_wrench(rec.wrench)
            .with_joint_powers(rec.thermal_power_w);
        let (programmed, wobj) = match &a.target {
            Target::Named {
                name, index: None, ..
            } if name == "pClear" => (pose(robtarget(&m_in, name, None)), Isometry3::identity()),
            Target::Offs { base, offsets, .. } => {
                let Target::Named {
                    name,
                    index: Some(ix),
                    ..
                } = base.as_ref()
                else {
                    panic!("Offs of an array element")
                };
                let hole = pose(robtarget(&m_in, name, Some(ix.value.expect("index"))));
                let d = Vector3::new(
                    offsets[0].value.expect("dx"),
                    offsets[1].value.expect("dy"),
                    offsets[2].value.expect("dz"),
                );
                let p = Isometry3::from_parts(
                    Translation3::from(hole.translation.vector + d),
                    hole.rotation,
                );
                (w_plate() * p, w_plate())
            }
            _ => continue,
        };
        if let (Some(w), "vDrill") = (&rec.wrench, &*a.speed.text) {
            // The workpiece pushes back along the PROGRAMMED tool axis (the
            // robot base is the world frame here).
            let z = programmed.rotation * Vector3::z();
            assert_abs_diff_eq!(w.force_n, -DRILL_THRUST_N * z, epsilon = 1e-9);
        }
        let Target::Named { name: n2, .. } = &b.target else {
            panic!("named output target")
        };
        let rt = robtarget(&m_out, n2, None);
        let q = view
            .ik_conf(&(wobj * pose(rt)), conf(rt))
            .expect("controller IK");
        let (dp, dr) = pose_error(&view.predict(&ctx, &q, EffectSet::ALL), &programmed);
        assert_abs_diff_eq!(dp.norm(), 0.0, epsilon = POS_TOL_MM);
        assert_abs_diff_eq!(dr.norm(), 0.0, epsilon = ROT_TOL_RAD);
        checked += 1;
    }
    assert_eq!(checked, 50);
}

#[test]
fn rapid_joint_limit_violation_exits_2_naming_target_and_line() {
    let dir = tempfile::tempdir().expect("tempdir");
    let input = dir.path().join("limit.mod");
    // Joint 1 at 200° is beyond the IRB 1600 limit of ±180°.
    let src = "MODULE Limit\n  CONST jointtarget jFar := [[200,0,0,0,30,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\n  PROC main()\n    MoveAbsJ jFar, v100, fine, tool0;\n  ENDPROC\nENDMODULE\n";
    std::fs::write(&input, src).expect("write");
    let output = dir.path().join("limit.out.mod");
    let out = postproc()
        .arg("compensate")
        .arg(&input)
        .args([
            "--machine",
            repo("machines/abb-irb1600.yaml").to_str().expect("utf8"),
        ])
        .arg("-o")
        .arg(&output)
        .output()
        .expect("run");
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    // The literal of jFar starts on line 2 at column 29
    // ("  CONST jointtarget jFar := " is 28 bytes).
    assert!(err.contains("limit.mod:2:29:"), "{err}");
    assert!(err.contains("jFar") && err.contains("line 4"), "{err}");
    assert!(err.contains("joint 1 at 200"), "{err}");
    assert!(!output.exists(), "no output on error");
}

#[test]
fn rapid_effects_flags_and_resonance_warning() {
    let dir = tempfile::tempdir().expect("tempdir");
    // Without thermal: every annotation shows a zero thermal share.
    let (_, output) = run_sample(
        dir.path(),
        &[
            "--effects",
            "kinematic,gravity,process,dynamic",
            "--gain",
            "gravity=0.5",
        ],
    );
    let out = std::fs::read_to_string(&output).expect("output");
    let notes: Vec<&str> = out.lines().filter(|l| l.contains("! dev ")).collect();
    // 52 moves, of which the two MoveAbsJ are reported, not annotated.
    assert_eq!(notes.len(), 50);
    assert!(
        notes.iter().all(|l| l.contains(" therm 0.000 ")),
        "{notes:?}"
    );
    assert!(notes.iter().any(|l| !l.contains(" proc 0.000 ")));
    // Unknown effects are usage errors.
    postproc()
        .args([
            "compensate",
            "samples/drilling.mod",
            "--machine",
            "machines/abb-irb1600.yaml",
            "--effects",
            "magic",
            "-o",
            "-",
        ])
        .current_dir(repo(""))
        .assert()
        .code(2);
    postproc()
        .args([
            "compensate",
            "samples/drilling.mod",
            "--machine",
            "machines/abb-irb1600.yaml",
            "--thermal-start",
            "lukewarm",
            "-o",
            "-",
        ])
        .current_dir(repo(""))
        .assert()
        .code(2);
    // Spindle at 255 rpm with 2 flutes excites 255·2/60 = 8.5 Hz, the x
    // mode: warned, with the suggested 5.25 Hz (0.7 of the y mode, clear
    // of every mode; tests/robot.rs) · 60 / 2 = 157.5 rpm. The
    // drilling feed limit is raised so that 4 mm/s (0.94 mm/rev) still drills.
    let text = std::fs::read_to_string(repo("machines/abb-irb1600.yaml")).expect("machine");
    let res = text
        .replace("spindle_rpm: 3000.0", "spindle_rpm: 255.0")
        .replace("max_feed_mm_per_rev: 0.5", "max_feed_mm_per_rev: 2.0");
    assert_ne!(res, text);
    let machine = dir.path().join("resonant.yaml");
    std::fs::write(&machine, res).expect("write");
    let out = postproc()
        .arg("compensate")
        .arg(repo("samples/drilling.mod"))
        .arg("--machine")
        .arg(&machine)
        .args(["-o", "-"])
        .output()
        .expect("run");
    assert_eq!(out.status.code(), Some(0));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("X natural frequency 8.50 Hz"), "{err}");
    assert!(err.contains("the tooth passing (5.25 Hz)"), "{err}");
    assert_eq!(
        err.matches("tooth-passing").count(),
        1,
        "once per speed: {err}"
    );
    // Read a window at a time from a warm start (two passes over the
    // module): still one warning.
    let out = postproc()
        .arg("compensate")
        .arg(repo("samples/drilling.mod"))
        .arg("--machine")
        .arg(&machine)
        .args([
            "--rapid-window-lines",
            "20",
            "--thermal-start",
            "steady",
            "-o",
            "-",
        ])
        .output()
        .expect("run");
    assert_eq!(out.status.code(), Some(0));
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(
        err.matches("tooth-passing").count(),
        1,
        "once per speed, read a window at a time: {err}"
    );
}

#[test]
fn random_written_targets_meet_one_micrometre_and_microradian() {
    // 40 reachable inline targets (nominal TCP poses of random joints away
    // from the singularities, tool0, no work object), each a MoveL with a
    // fixed speed, compensated with every effect and a warm start. Each
    // WRITTEN literal, read back, must land within 1 µm / 1 µrad.
    let text = std::fs::read_to_string(repo("machines/abb-irb1600.yaml")).expect("machine");
    let robot = Robot::from_yaml_str(&text, "abb-irb1600.yaml").expect("valid");
    // tool0: the flange, no load (the file's default TCP is not used).
    let tool0 = robot.with_tool(Isometry3::identity(), None);
    let lim = robot.joint_limits_rad();
    let mut seed = 0x2545_f491_4f6c_dd1d_u64;
    let mut unit = || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 11) as f64 / (1u64 << 53) as f64
    };
    let mut body = String::new();
    let mut goals = Vec::new();
    while goals.len() < 40 {
        let q: [f64; 6] = std::array::from_fn(|i| {
            let (lo, hi) = (lim[i][0] + 0.3, lim[i][1] - 0.3);
            lo + (hi - lo) * unit()
        });
        let wc = robot.frames(Model::Nominal, &q).link[4].translation.vector;
        if q[4].abs() < 0.1
            || wc.xy().norm() < 150.0
            || (q[2] + std::f64::consts::FRAC_PI_2).abs() < 0.1
        {
            continue;
        }
        let p = tool0.tcp_pose(Model::Nominal, &q);
        let c = robot.confdata(&q);
        let r = p.rotation.quaternion();
        let t = p.translation.vector;
        body.push_str(&format!(
            "    MoveL [[{:.3},{:.3},{:.3}],[{:.9},{:.9},{:.9},{:.9}],[{},{},{},{}],[9E9,9E9,9E9,9E9,9E9,9E9]], v200, fine, tool0;\n",
            t.x, t.y, t.z, r.w, r.i, r.j, r.k, c.cf1, c.cf4, c.cf6, c.cfx
        ));
        goals.push(());
    }
    let src = format!("MODULE Rand\n  PROC main()\n{body}  ENDPROC\nENDMODULE\n");
    let opts = RapidOptions {
        thermal_start: ThermalStart::WarmUpMin(45.0),
        ..RapidOptions::for_robot(&robot)
    };
    let out = compensate_module(&src, "rand.mod", &robot, &opts).expect("compensates");
    let m_in = parse_module(&src, "in").expect("parses");
    let m_out = parse_module(&out.text, "out").expect("re-parses");
    let mut checked = 0;
    for ((a, b), row) in m_in.moves().zip(m_out.moves()).zip(&out.records) {
        let rec = row.robot.expect("a robot move's row");
        let (Target::Inline(rin), Target::Inline(rout)) = (&a.target, &b.target) else {
            panic!("inline targets")
        };
        // No constant process force and no plunges: no load.
        assert!(rec.wrench.is_none());
        let view = &tool0;
        let ctx = MoveContext::default().with_joint_powers(rec.thermal_power_w);
        let q = view
            .ik_conf(&pose(rout), conf(rout))
            .expect("controller IK");
        let (dp, dr) = pose_error(&view.predict(&ctx, &q, EffectSet::ALL), &pose(rin));
        assert_abs_diff_eq!(dp.norm(), 0.0, epsilon = POS_TOL_MM);
        assert_abs_diff_eq!(dr.norm(), 0.0, epsilon = ROT_TOL_RAD);
        checked += 1;
    }
    assert_eq!(checked, 40);
}

/// Duration tolerance, s (plain arithmetic on literals).
const TIME_TOL_S: f64 = 1e-9;

#[test]
fn time_line_durations_and_workpiece_force_are_hand_derived() {
    // A constant force of 100 N along x of a work object turned 90° about z
    // (quaternion [cos45°, 0, 0, sin45°]) is 100 N along base +y, on MoveL
    // only. Durations: p1 → p2 is 100 mm along y.
    //  - MoveL at v100: 100 / 100 = 1 s.
    //  - MoveL back with \V:=50: 100 / 50 = 2 s.
    //  - MoveL at vSlow ([25, ...]): 100 / 25 = 4 s.
    //  - MoveAbsJ [0,0,0,0,30,0] then [30,0,0,0,30,0] at v5000: only joint
    //    1 moves, 30° at 150°/s = 0.2 s; the TCP (≤ 1 m from axis 1) moves
    //    along a chord ≤ 2·1000·sin 15° = 518 mm, 0.1 s at 5000 mm/s.
    //  - The first move takes 0 s.
    let text = std::fs::read_to_string(repo("machines/abb-irb1600.yaml")).expect("machine");
    let text = text.replace(
        "process_force:\n  model: drilling\n  thrust_coefficient_n_per_mm2: 450.0\n  drill_diameter_mm: 6.8\n  spindle_rpm: 3000.0\n  flutes: 2\n  max_feed_mm_per_rev: 0.5\n",
        "process_force: { model: constant, force_n: [100.0, 0.0, 0.0], frame: workpiece }\n",
    );
    assert!(text.contains("model: constant"));
    let robot = Robot::from_yaml_str(&text, "abb.yaml").expect("valid");
    let h = std::f64::consts::FRAC_1_SQRT_2;
    let src = format!(
        "MODULE T\n  CONST speeddata vSlow := [25,500,5000,1000];\n  PERS wobjdata wTurn := [FALSE,TRUE,\"\",[[0,0,0],[{h},0,0,{h}]],[[0,0,0],[1,0,0,0]]];\n  CONST robtarget p1 := [[0,-800,500],[0,1,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\n  CONST robtarget p2 := [[0,-700,500],[0,1,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\n  PROC main()\n    MoveJ p1, v1000, fine, tool0\\WObj:=wTurn;\n    MoveL p2, v100, fine, tool0\\WObj:=wTurn;\n    MoveL p1, v100\\V:=50, fine, tool0\\WObj:=wTurn;\n    MoveL p2, vSlow, fine, tool0\\WObj:=wTurn;\n    MoveAbsJ [[0,0,0,0,30,0],[9E9,9E9,9E9,9E9,9E9,9E9]], v5000, fine, tool0;\n    MoveAbsJ [[30,0,0,0,30,0],[9E9,9E9,9E9,9E9,9E9,9E9]], v5000, fine, tool0;\n  ENDPROC\nENDMODULE\n"
    );
    let opts = RapidOptions::for_robot(&robot);
    let out = compensate_module(&src, "t.mod", &robot, &opts).expect("compensates");
    let robots: Vec<_> = out
        .records
        .iter()
        .map(|r| r.robot.expect("a robot move's row"))
        .collect();
    let d: Vec<f64> = robots.iter().map(|r| r.duration_s).collect();
    assert_abs_diff_eq!(d[0], 0.0, epsilon = TIME_TOL_S);
    assert_abs_diff_eq!(d[1], 1.0, epsilon = TIME_TOL_S);
    assert_abs_diff_eq!(d[2], 2.0, epsilon = TIME_TOL_S);
    assert_abs_diff_eq!(d[3], 4.0, epsilon = TIME_TOL_S);
    assert_abs_diff_eq!(d[5], 0.2, epsilon = TIME_TOL_S);
    for (i, r) in robots.iter().enumerate() {
        match (i, &r.wrench) {
            (1..=3, Some(w)) => {
                assert!(!w.in_tool_frame());
                assert_abs_diff_eq!(w.force_n, Vector3::new(0.0, 100.0, 0.0), epsilon = 1e-12);
            }
            (0 | 4 | 5, None) => {}
            (i, w) => panic!("move {i}: {w:?}"),
        }
    }
}

/// Compensates `module` (a file in `dir`) with `--threads n`; returns the
/// written bytes.
fn compensate_threads(dir: &std::path::Path, module: &std::path::Path, n: usize) -> Vec<u8> {
    let output = dir.join(format!("out{n}.mod"));
    postproc()
        .arg("compensate")
        .arg(module)
        .args(["--machine", "abb-irb1600", "--effects", "all", "--threads"])
        .arg(n.to_string())
        .arg("-o")
        .arg(&output)
        .assert()
        .success();
    std::fs::read(&output).expect("output")
}

#[test]
fn rapid_output_is_the_same_for_one_and_two_threads() {
    let dir = tempfile::tempdir().expect("tempdir");
    // The drilling sample (named targets, copies, Offs, MoveAbsJ) and a
    // grid of 400 inline targets, enough to be split between threads.
    let sample = dir.path().join("drilling.mod");
    std::fs::copy(repo("samples/drilling.mod"), &sample).expect("copy sample");
    let mut grid = String::from(
        "MODULE Grid\n  PERS tooldata tSpindle := [TRUE,[[0,0,150],[1,0,0,0]],[2,[0,0,70],[1,0,0,0],0.01,0.01,0.004]];\n  PROC main()\n",
    );
    for i in 0..400 {
        let (x, y, z) = (650 + (i % 20) * 10, 50 + (i / 20) * 10, 300 + (i % 7) * 20);
        grid.push_str(&format!(
            "    MoveL [[{x},{y},{z}],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]],v200,z1,tSpindle;\n"
        ));
    }
    grid.push_str("  ENDPROC\nENDMODULE\n");
    let grid_path = dir.path().join("grid.mod");
    std::fs::write(&grid_path, &grid).expect("write grid");
    for module in [&sample, &grid_path] {
        let input = std::fs::read(module).expect("input");
        let one = compensate_threads(dir.path(), module, 1);
        let two = compensate_threads(dir.path(), module, 2);
        assert!(one != input, "nothing was compensated in {module:?}");
        assert!(one == two, "1 and 2 threads differ for {module:?}");
    }
}

/// A system module (`.sys`) and a module whose extension says nothing
/// (`.txt`, none) are read as RAPID without a machine file: `check`
/// reports the module's structure, not G-code errors. A G-code program
/// without a RAPID extension stays G-code.
#[test]
fn system_modules_and_modules_by_content_are_rapid() {
    let dir = tempfile::tempdir().expect("tempdir");
    let module = "%%%\r\n  VERSION:1\r\n  LANGUAGE:ENGLISH\r\n%%%\r\n\r\nMODULE user (SYSMODULE)\r\n  ! cell data\r\n  PERS num nCycles := 0;\r\n  PROC reset()\r\n    nCycles := 0;\r\n  ENDPROC\r\nENDMODULE\r\n";
    for name in [
        "user.sys",
        "USER.SYS",
        "cell.modx",
        "old.prg",
        "user.txt",
        "user",
    ] {
        let path = crate::common::write(dir.path(), name, module);
        let out = postproc().arg("check").arg(&path).output().expect("runs");
        let stdout = String::from_utf8_lossy(&out.stdout);
        assert!(
            out.status.success(),
            "{name}: {stdout} {}",
            String::from_utf8_lossy(&out.stderr)
        );
        assert!(
            stdout.contains("module user, 1 declarations, 1 routines, 0 moves"),
            "{name}: {stdout}"
        );
    }
    let gcode = crate::common::write(dir.path(), "part", "G21 G90\nG1 X10 F100\nM30\n");
    let out = postproc().arg("check").arg(&gcode).output().expect("runs");
    assert!(
        !String::from_utf8_lossy(&out.stdout).contains("module"),
        "{}",
        String::from_utf8_lossy(&out.stdout)
    );
}

/// A palletizing module as a controller saves it: ISO-8859-1 text (German
/// comments, a string with `é`), CRLF line ends, a `%%%` header.
fn latin1_module() -> Vec<u8> {
    let mut m = Vec::new();
    m.extend_from_slice(
        b"%%%\r\n  VERSION:1\r\n  LANGUAGE:ENGLISH\r\n%%%\r\n\r\nMODULE Palette\r\n",
    );
    m.extend_from_slice(b"  ! Gr\xf6\xdfe der Palette: 4 \xd7 3, Abst\xe4nde in mm\r\n");
    m.extend_from_slice(b"  CONST robtarget pAblage := [[750,0,500],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\r\n");
    m.extend_from_slice(b"  CONST robtarget pVor := [[760,20,480],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]]; ! \xfcber der Ablage\r\n");
    m.extend_from_slice(b"  PROC main()\r\n    TPWrite \"Palette voll, caf\xe9 \xb0C\";\r\n");
    m.extend_from_slice(b"    MoveJ pVor, v1000, z50, tool0;\r\n    MoveL pAblage, v100, fine, tool0; ! Ablegen\r\n");
    m.extend_from_slice(b"  ENDPROC\r\nENDMODULE\r\n");
    m
}

/// An ISO-8859-1 module is read and written back byte for byte: with
/// nothing to compensate the output is the input; compensated, every line
/// but the changed targets' is the input's, the new numbers are in the
/// same character set; `check` accepts it, with and without a robot.
#[test]
fn latin1_modules_come_back_byte_for_byte() {
    let dir = tempfile::tempdir().expect("tempdir");
    let input = dir.path().join("palette.mod");
    let module = latin1_module();
    assert!(std::str::from_utf8(&module).is_err(), "not UTF-8");
    std::fs::write(&input, &module).expect("write");
    let machine = repo("machines/abb-irb1600.yaml");
    let run = |out: &str, extra: &[&str]| -> Vec<u8> {
        let output = dir.path().join(out);
        postproc()
            .arg("compensate")
            .arg(&input)
            .arg("--machine")
            .arg(&machine)
            .arg("-o")
            .arg(&output)
            .args(extra)
            .assert()
            .success();
        without_header(&std::fs::read(&output).expect("output"))
    };
    let same = run("none.mod", &["--effects", "none", "--annotate", "none"]);
    assert!(same == module, "output differs from the input");
    let compensated = run("all.mod", &[]);
    // Asked to read it a window at a time, the run reads it whole.
    assert!(run("windows.mod", &["--rapid-window-lines", "1"]) == compensated);
    let lines = |b: &[u8]| -> Vec<Vec<u8>> {
        b.split_inclusive(|&c| c == b'\n')
            .map(<[u8]>::to_vec)
            .collect()
    };
    let (a, b) = (lines(&module), lines(&compensated));
    assert_eq!(a.len(), b.len());
    let mut changed = Vec::new();
    for (k, (x, y)) in a.iter().zip(&b).enumerate() {
        if x != y {
            changed.push(k + 1);
            // A changed line keeps its comment's bytes and its line end.
            if let Some(p) = x.iter().position(|&c| c == b'!') {
                let comment = &x[p..x.len() - 2];
                assert!(
                    y.windows(comment.len()).any(|w| w == comment),
                    "line {}",
                    k + 1
                );
            }
            assert!(y.ends_with(b"\r\n"));
        }
    }
    // The two targets and the two annotated moves.
    assert_eq!(changed, vec![8, 9, 12, 13]);
    assert!(b[8].ends_with(b"; ! \xfcber der Ablage\r\n"));
    assert!(b[12].windows(9).any(|w| w == b"! Ablegen"));
    assert!(b[12].windows(6).any(|w| w == b"! dev "));
    for args in [
        vec!["check", "--machine", machine.to_str().expect("utf8")],
        vec!["check"],
    ] {
        let out = postproc().args(&args).arg(&input).output().expect("runs");
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        assert!(
            String::from_utf8_lossy(&out.stdout)
                .contains("module Palette, 2 declarations, 1 routines, 2 moves"),
            "{}",
            String::from_utf8_lossy(&out.stdout)
        );
    }
}

/// An error in an ISO-8859-1 module is located by the bytes of the file:
/// the `é` before it is one byte there.
#[test]
fn latin1_error_columns_count_file_bytes() {
    let dir = tempfile::tempdir().expect("tempdir");
    let input = dir.path().join("bad.mod");
    let mut module = b"MODULE M\r\n  PROC main()\r\n    TPWrite \"caf\xe9\"; ".to_vec();
    // `MoveL` starts at byte 21 of line 3 (4 + 8 + 6 + 2 bytes before it).
    let column = module.len() - module.iter().rposition(|&b| b == b'\n').expect("line");
    assert_eq!(column, 21);
    module.extend_from_slice(b"MoveL p1, v100, z10;\r\n  ENDPROC\r\nENDMODULE\r\n");
    std::fs::write(&input, &module).expect("write");
    let machine = repo("machines/abb-irb1600.yaml");
    let output = dir.path().join("out.mod");
    let runs = [
        vec!["check".to_string()],
        vec![
            "compensate".to_string(),
            "--machine".to_string(),
            machine.display().to_string(),
            "-o".to_string(),
            output.display().to_string(),
        ],
    ];
    for args in runs {
        let out = postproc().args(&args).arg(&input).output().expect("runs");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {stderr}");
        assert!(
            stderr.contains("bad.mod:3:21: MoveL takes 4 arguments"),
            "{args:?}: {stderr}"
        );
    }
    assert!(!output.exists());
    // batch reads the module whole too, and names the same column.
    let out_dir = dir.path().join("out");
    let out = postproc()
        .args(["batch", "--machine"])
        .arg(&machine)
        .arg("--out-dir")
        .arg(&out_dir)
        .arg(&input)
        .output()
        .expect("runs");
    let all = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(out.status.code(), Some(2), "{all}");
    assert!(
        all.contains("bad.mod:3:21: MoveL takes 4 arguments"),
        "{all}"
    );
}

/// A main module in the shape of a controller backup, with every construct
/// of `grammar/rapid.md` that real modules use at once: `%%%` header,
/// ISO-8859-1 comments, CRLF, a record type, constant-sized arrays, a
/// socket loop with an error handler for a list of errors, compact IFs
/// with their statement on the next line and an unfinished routine. With
/// nothing to compensate it comes back byte for byte; compensated, the
/// unfinished routine and every line without a compensated move or target
/// are as written, and the unfinished routine's moves are named and counted.
#[test]
fn a_backup_module_with_every_construct_comes_back_as_written() {
    let mut module = Vec::new();
    module.extend_from_slice(
        b"%%%\r\n  VERSION:1\r\n  LANGUAGE:ENGLISH\r\n%%%\r\n\r\nMODULE MainModule\r\n",
    );
    module.extend_from_slice(b"  ! Zelle 3 \xb7 Schwei\xdfen und Palettieren\r\n");
    module.extend_from_slice(b"  CONST num MAX_PARTS := 2;\r\n  RECORD partdata\r\n    robtarget pPick;\r\n    num nHeight;\r\n  ENDRECORD\r\n");
    module.extend_from_slice(b"  VAR partdata parts{MAX_PARTS};\r\n  VAR socketdev sock;\r\n  VAR string cmd;\r\n  VAR bool bHome := FALSE;\r\n");
    module.extend_from_slice(b"  CONST robtarget pHome := [[750,0,500],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\r\n");
    module.extend_from_slice(b"  CONST robtarget pDrop{MAX_PARTS} := [[[700,30,450],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]],\r\n    [[700,80,450],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]]];\r\n");
    let main = b"  PROC main()\r\n    MoveJ pHome, v1000, z50, tool0;\r\n    WHILE TRUE DO\r\n      SocketReceive sock \\Str:=cmd \\Time:=30;\r\n      IF cmd = \"home\"\r\n        MoveJ pHome, v500, fine, tool0;\r\n      IF bHome\r\n        TPWrite \"Grundstellung \xfcberf\xe4hrt\";\r\n      MoveL pDrop{1}, v200, z10, tool0;\r\n      MoveL pDrop{2}, v200, fine, tool0;\r\n    ENDWHILE\r\n  ERROR (ERR_SOCK_TIMEOUT, ERR_SOCK_CLOSED)\r\n    SocketClose sock;\r\n    RETRY;\r\n  ENDPROC\r\n";
    let teach: &[u8] = b"  PROC teach()\r\n    MoveL pDrop{1}, v100, fine, tool0;\r\n    <SMT>\r\n    MoveL Offs(pHome, 0, 0, <EXP>), v100, fine, tool0;\r\n  ENDPROC\r\n";
    module.extend_from_slice(main);
    module.extend_from_slice(teach);
    module.extend_from_slice(b"ENDMODULE\r\n");
    let dir = tempfile::tempdir().expect("tempdir");
    let input = dir.path().join("MainModule.mod");
    std::fs::write(&input, &module).expect("write");
    let machine = repo("machines/abb-irb1600.yaml");
    let run = |out: &str, extra: &[&str]| -> Vec<u8> {
        let output = dir.path().join(out);
        postproc()
            .arg("compensate")
            .arg(&input)
            .arg("--machine")
            .arg(&machine)
            .arg("-o")
            .arg(&output)
            .args(extra)
            .assert()
            .success();
        without_header(&std::fs::read(&output).expect("output"))
    };
    let same = run("none.mod", &["--effects", "none", "--annotate", "none"]);
    assert!(same == module, "output differs from the input");
    let out = run("all.mod", &[]);
    assert!(out != module, "the main routine is compensated");
    assert!(
        out.windows(teach.len()).any(|w| w == teach),
        "teach is as written"
    );
    // teach's moves are named, each at its line, and counted.
    let teach_at = module
        .windows(teach.len())
        .position(|w| w == teach)
        .expect("teach");
    let teach_line = 1 + module[..teach_at].iter().filter(|&&b| b == b'\n').count();
    let told = postproc()
        .arg("compensate")
        .arg(&input)
        .arg("--machine")
        .arg(&machine)
        .arg("-o")
        .arg(dir.path().join("told.mod"))
        .output()
        .expect("runs");
    let stderr = String::from_utf8_lossy(&told.stderr);
    assert!(told.status.success(), "{stderr}");
    let named = format!(
        "MainModule.mod:{}: MoveL left as written: its routine holds an editor placeholder",
        teach_line + 1
    );
    assert!(stderr.contains(&named), "{named} in:\n{stderr}");
    let left = stderr.matches("left as written: its routine").count();
    assert!(left >= 1, "{stderr}");
    let summary = format!(
        "4 moves compensated, {left} left as written (its routine holds an editor placeholder)"
    );
    assert!(stderr.contains(&summary), "{summary} in:\n{stderr}");
    let check = postproc()
        .args(["check", "--machine"])
        .arg(&machine)
        .arg(&input)
        .output()
        .expect("runs");
    assert!(
        check.status.success(),
        "{}",
        String::from_utf8_lossy(&check.stderr)
    );
    // The moves of main (the one in a compact IF with them); teach's are
    // not counted.
    assert!(
        String::from_utf8_lossy(&check.stdout).contains("2 routines, 4 moves"),
        "{}",
        String::from_utf8_lossy(&check.stdout)
    );
}

/// `batch` takes system modules (`.sys`) with the program modules, and
/// writes an ISO-8859-1 module back in ISO-8859-1, byte for byte with
/// nothing to compensate; the task folder itself is one program, of which
/// no module changes, so none is written.
#[test]
fn batch_takes_system_modules_and_latin1_modules() {
    let dir = tempfile::tempdir().expect("tempdir");
    let input = dir.path().join("TASK1");
    std::fs::create_dir_all(input.join("PROGMOD")).expect("mkdir");
    std::fs::create_dir_all(input.join("SYSMOD")).expect("mkdir");
    let user = b"MODULE user (SYSMODULE)\r\n  PERS num nCycles := 0;\r\nENDMODULE\r\n";
    std::fs::write(input.join("SYSMOD/user.sys"), user).expect("write");
    let palette = latin1_module();
    std::fs::write(input.join("PROGMOD/Palette.mod"), &palette).expect("write");
    let out = dir.path().join("out");
    postproc()
        .args(["batch", "--machine", "abb-irb1600", "--effects", "none"])
        .args(["--annotate", "none", "--out-dir"])
        .arg(&out)
        .arg(input.join("SYSMOD/user.sys"))
        .arg(input.join("PROGMOD/Palette.mod"))
        .assert()
        .success();
    let written = |rel: &str| without_header(&std::fs::read(out.join(rel)).expect(rel));
    assert!(written("user.sys") == user, "user.sys");
    assert!(written("Palette.mod") == palette, "Palette.mod");
    let whole = dir.path().join("whole");
    postproc()
        .args(["batch", "--machine", "abb-irb1600", "--effects", "none"])
        .args(["--annotate", "none", "--out-dir"])
        .arg(&whole)
        .arg(&input)
        .assert()
        .success();
    assert!(!whole.join("TASK1").exists(), "no module changed");
    let summary: serde_json::Value =
        serde_json::from_slice(&std::fs::read(whole.join("batch-summary.json")).expect("summary"))
            .expect("JSON");
    assert_eq!(summary["results"].as_array().map(Vec::len), Some(1));
}

/// A target shared by a compensated routine and an unfinished one (an
/// editor placeholder in it): the declaration keeps its value for the
/// unfinished routine, and the compensated move goes to a copy of it.
#[test]
fn a_target_shared_with_an_unfinished_routine_keeps_its_value() {
    let decl =
        "  CONST robtarget pHome := [[750,0,500],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\n";
    let teach = "  PROC teach()\n    MoveL pHome, v100, fine, tool0;\n    <SMT>\n  ENDPROC\n";
    let module = format!(
        "MODULE M\n{decl}  PROC main()\n    MoveJ pHome, v1000, z50, tool0;\n  ENDPROC\n{teach}ENDMODULE\n"
    );
    let dir = tempfile::tempdir().expect("tempdir");
    let input = write(dir.path(), "M.mod", &module);
    let output = dir.path().join("out.mod");
    postproc()
        .args(["compensate", "--machine", "abb-irb1600", "-o"])
        .arg(&output)
        .arg(&input)
        .assert()
        .success();
    let out = std::fs::read_to_string(&output).expect("output");
    assert!(out.contains(decl), "pHome as written:\n{out}");
    assert!(out.contains(teach), "teach as written:\n{out}");
    assert!(
        out.contains("    MoveJ pHome_c"),
        "main's move goes to a copy:\n{out}"
    );
    assert!(
        out.contains("  LOCAL CONST robtarget pHome_c"),
        "the copy is declared:\n{out}"
    );
}

/// A module whose moves are a `MoveLDO`, a `TriggL`, an `ArcL` and a
/// `SearchL` (plus a `SearchPoint` robtarget the controller writes).
const PROCESS_MODULE: &str = "MODULE Process
  PERS tooldata tDrill := [TRUE,[[0,0,182.5],[1,0,0,0]],[2.4,[0,0,85],[1,0,0,0],0.012,0.012,0.004]];
  PERS wobjdata wPlate := [FALSE,TRUE,\"\",[[600,-200,350],[1,0,0,0]],[[0,0,0],[1,0,0,0]]];
  CONST robtarget pA := [[100,50,40],[0,0,1,0],[-1,0,-1,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST robtarget pB := [[175,50,40],[0,0,1,0],[-1,0,-1,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST robtarget pC := [[175,150,40],[0,0,1,0],[-1,0,-1,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST robtarget pD := [[250,150,0],[0,0,1,0],[-1,0,-1,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  VAR robtarget pFound := [[250,150,20],[0,0,1,0],[-1,0,-1,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  VAR triggdata trOn;

  PROC main()
    MoveLDO pA, v100, z1, tDrill\\WObj:=wPlate, doOn, 1;
    TriggL pB, v100, trOn, z1, tDrill\\WObj:=wPlate;
    ArcL pC, v100, seam1, weld1\\Weave:=weave1, z1, tDrill\\WObj:=wPlate;
    SearchL \\Stop, diTouch, pFound, pD, v20, tDrill\\WObj:=wPlate;
  ENDPROC
ENDMODULE
";

#[test]
fn process_motion_instructions_are_compensated_and_nothing_else_changes() {
    let dir = tempfile::tempdir().expect("tempdir");
    let input = write(dir.path(), "process.mod", PROCESS_MODULE);
    let machine = repo("machines/abb-irb1600.yaml");
    let run = |out: &str, effects: &str| -> String {
        let output = dir.path().join(out);
        postproc()
            .arg("compensate")
            .arg(&input)
            .arg("--machine")
            .arg(&machine)
            .args(["--effects", effects, "--annotate", "none", "-o"])
            .arg(&output)
            .assert()
            .success();
        text_without_header(&std::fs::read_to_string(&output).expect("output"))
    };
    assert_eq!(run("none.mod", "none"), PROCESS_MODULE);
    let out = run("out.mod", "kinematic,gravity");
    let (a, b): (Vec<&str>, Vec<&str>) = (PROCESS_MODULE.lines().collect(), out.lines().collect());
    assert_eq!(a.len(), b.len(), "{out}");
    let changed: Vec<&str> = a
        .iter()
        .zip(&b)
        .filter(|(x, y)| x != y)
        .map(|(x, _)| x.split(":=").next().unwrap_or("").trim())
        .collect();
    let want = [
        "CONST robtarget pA",
        "CONST robtarget pB",
        "CONST robtarget pC",
        "CONST robtarget pD",
    ];
    assert_eq!(changed, want, "{out}");
    // The SearchPoint robtarget is left alone.
    assert!(
        out.contains("VAR robtarget pFound := [[250,150,20],"),
        "{out}"
    );
    // The compensated targets, commanded, land on the programmed poses.
    let m_in = parse_module(PROCESS_MODULE, "in").expect("input parses");
    let m_out = parse_module(&out, "out").expect("output parses");
    let robot = robot_with_drill();
    for name in ["pA", "pB", "pC", "pD"] {
        let (p_in, p_out) = (robtarget(&m_in, name, None), robtarget(&m_out, name, None));
        assert_ne!(pose(p_in), pose(p_out), "{name} compensated");
        let programmed = w_plate() * pose(p_in);
        let q = robot
            .ik_conf(&(w_plate() * pose(p_out)), conf(p_out))
            .expect("controller IK");
        let (dp, dr) = pose_error(
            &robot.predict(&MoveContext::default(), &q, EffectSet::ALL),
            &programmed,
        );
        assert_abs_diff_eq!(dp.norm(), 0.0, epsilon = POS_TOL_MM);
        assert_abs_diff_eq!(dr.norm(), 0.0, epsilon = ROT_TOL_RAD);
    }
}

/// A pick-and-place cell whose part positions come from a vision PC over
/// a socket: targets declared, targets computed by straight-line code,
/// and targets known at run time only (a socket loop, a FOR index, a
/// routine parameter, `CRobT`, a target reassigned in another routine).
pub(crate) const PICK_CELL: &str = "MODULE PickCell
  ! Pick-and-place cell: part positions come from a vision PC over a socket.
  CONST robtarget pHome := [[857.5,93.098,1025.25],[0.3061862,-0.1767767,0.9185587,0.1767767],[0,0,-1,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST robtarget pPickBase := [[960.127,-147.664,665.921],[0.1828804,0.0723086,0.9537141,0.2274985],[-1,0,-1,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST robtarget pPlaceBase := [[960.127,147.664,665.921],[0.1828804,-0.0723086,0.9537141,-0.2274985],[0,-1,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  VAR robtarget pApproach := [[650,0,600],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  VAR robtarget pRecv := [[700,0,300],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  VAR robtarget pStack{2} := [[[700,200,350],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]],[[700,200,400],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]]];
  VAR robtarget pCur;
  CONST num nLift := 120;
  VAR num nHeight := 0;
  VAR socketdev sock;
  VAR string sData;
  VAR bool bOk;

  PROC main()
    MoveJ pHome, v1000, z50, tool0;
    pApproach := Offs(pPickBase, 0, 0, nLift);
    MoveJ pApproach, v1000, z50, tool0;
    MoveL Offs(pPickBase, 0, 0, 20), v200, fine, tool0;
    pApproach := RelTool(pPlaceBase, 10, 0, -100);
    MoveL pApproach, v500, z10, tool0;
    SocketCreate sock;
    SocketConnect sock, \"192.168.0.10\", 1025;
    WHILE TRUE DO
      SocketReceive sock \\Str:=sData;
      bOk := StrToVal(sData, pRecv);
      IF bOk THEN
        MoveL Offs(pRecv, 0, 0, nLift), v500, z10, tool0;
        MoveL pRecv, v100, fine, tool0;
      ENDIF
      nHeight := nHeight + 10;
      MoveL Offs(pPlaceBase, 0, 0, nHeight), v500, fine, tool0;
      stack;
      retreat;
    ENDWHILE
  ENDPROC

  PROC stack()
    FOR i FROM 1 TO 2 DO
      pStack{i} := Offs(pPlaceBase, 0, 0, i * 50);
      MoveL pStack{i}, v500, fine, tool0;
    ENDFOR
    place Offs(pPlaceBase, 0, 0, 10);
  ENDPROC

  PROC place(robtarget pt)
    MoveL pt, v200, fine, tool0;
  ENDPROC

  PROC retreat()
    pCur := CRobT(\\Tool:=tool0 \\WObj:=wobj0);
    MoveL Offs(pCur, 0, 0, 100), v200, fine, tool0;
    MoveL pApproach, v500, z10, tool0;
    MoveJ pHome, v1000, fine, tool0;
  ENDPROC
ENDMODULE
";

/// The moves of [`PICK_CELL`] left as written: line and reason.
const PICK_CELL_LEFT: [(usize, &str); 7] = [
    (29, "target reassigned in a loop"),
    (30, "target reassigned in a loop"),
    (33, "run-time offset"),
    (42, "indexed by a run-time value"),
    (48, "routine parameter"),
    (53, "CRobT"),
    (54, "target reassigned in another routine"),
];

/// Runs `postproc compensate` of `input` on the IRB 1600 with `extra`
/// flags into `output`; gives the exit code and standard error.
fn compensate_cell(
    input: &std::path::Path,
    output: &std::path::Path,
    extra: &[&str],
) -> (i32, String) {
    let out = postproc()
        .arg("compensate")
        .arg(input)
        .args([
            "--machine",
            repo("machines/abb-irb1600.yaml").to_str().expect("utf8"),
        ])
        .arg("-o")
        .arg(output)
        .args(extra)
        .output()
        .expect("run");
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn run_time_targets_are_left_as_written_and_named() {
    let dir = tempfile::tempdir().expect("tempdir");
    let input = write(dir.path(), "PickCell.mod", PICK_CELL);
    // Identity with nothing to compensate, every move still resolved.
    let same = dir.path().join("same.mod");
    let (code, err) = compensate_cell(&input, &same, &["--effects", "none", "--annotate", "none"]);
    assert_eq!(code, 0, "{err}");
    let got = without_header(&std::fs::read(&same).expect("output"));
    assert!(
        got == PICK_CELL.as_bytes(),
        "{}",
        String::from_utf8_lossy(&got)
    );
    // Every move left as written is named with its place and reason, and
    // counted in the summary.
    let out = dir.path().join("out.mod");
    let (code, err) = compensate_cell(&input, &out, &["--effects", "kinematic"]);
    assert_eq!(code, 0, "{err}");
    for (line, reason) in PICK_CELL_LEFT {
        let said = format!("PickCell.mod:{line}: MoveL left as written ({reason})");
        assert!(err.contains(&said), "{said}: {err}");
    }
    let summary = "5 moves compensated, 7 left as written (CRobT; indexed by a run-time value; routine parameter; run-time offset; target reassigned in a loop; target reassigned in another routine)";
    assert!(err.contains(summary), "{err}");
    // The moves left as written and the declarations they read are
    // written exactly as they were.
    let text = text_without_header(&std::fs::read_to_string(&out).expect("output"));
    let src_lines: Vec<&str> = PICK_CELL.lines().collect();
    for (line, _) in PICK_CELL_LEFT {
        let moved = src_lines[line - 1];
        assert!(text.lines().any(|l| l == moved), "{moved}\n{text}");
    }
    for kept in [6, 7, 8] {
        let decl = src_lines[kept - 1];
        assert!(text.lines().any(|l| l == decl), "{decl}\n{text}");
    }
}

#[test]
fn straight_line_targets_are_compensated_where_the_robot_goes() {
    let dir = tempfile::tempdir().expect("tempdir");
    let input = write(dir.path(), "PickCell.mod", PICK_CELL);
    let out = dir.path().join("out.mod");
    let (code, err) = compensate_cell(
        &input,
        &out,
        &["--effects", "kinematic", "--annotate", "none"],
    );
    assert_eq!(code, 0, "{err}");
    let text = text_without_header(&std::fs::read_to_string(&out).expect("output"));
    let m_in = parse_module(PICK_CELL, "in").expect("parses");
    let m_out = parse_module(&text, "out").expect("output re-parses");
    // The reassigned declaration keeps its value: the moves to it go to
    // new constants holding the compensated values of the assignments.
    assert_eq!(
        pose(robtarget(&m_out, "pApproach", None)),
        pose(robtarget(&m_in, "pApproach", None))
    );
    let base = |n: &str| pose(robtarget(&m_in, n, None));
    let offs = Isometry3::from_parts(
        Translation3::new(0.0, 0.0, 120.0),
        UnitQuaternion::identity(),
    ) * base("pPickBase");
    let reltool = base("pPlaceBase") * Translation3::new(10.0, 0.0, -100.0);
    let offs20 = Isometry3::from_parts(
        Translation3::new(0.0, 0.0, 20.0),
        UnitQuaternion::identity(),
    ) * base("pPickBase");
    let moves: Vec<_> = m_out.moves().collect();
    let robot = Robot::from_yaml_str(
        &std::fs::read_to_string(repo("machines/abb-irb1600.yaml")).expect("machine"),
        "abb-irb1600.yaml",
    )
    .expect("valid robot")
    // tool0: the flange.
    .with_tool(Isometry3::identity(), None);
    let kinematic = EffectSet {
        kinematic: 1.0,
        ..EffectSet::NONE
    };
    // The second to fourth moves: `MoveJ pApproach` (an assignment of an
    // `Offs` of a constant offset), `MoveL Offs(pPickBase, …)` and `MoveL
    // pApproach` (an assignment of a `RelTool`). The compensated target,
    // reached on the branch of the programmed one (the controller's joints
    // of the programmed target seed the solve), lands on the programmed
    // target.
    let programmed_conf = conf(robtarget(&m_in, "pPickBase", None));
    let place_conf = conf(robtarget(&m_in, "pPlaceBase", None));
    for (k, programmed, c) in [
        (0, base("pHome"), conf(robtarget(&m_in, "pHome", None))),
        (1, offs, programmed_conf),
        (2, offs20, programmed_conf),
        (3, reltool, place_conf),
    ] {
        let Target::Named { name, .. } = &moves[k].target else {
            panic!("move {k}: a named target")
        };
        let rt = robtarget(&m_out, name, None);
        let q0 = robot.ik_conf(&programmed, c).expect("programmed joints");
        let q = robot
            .ik_numeric(Model::Nominal, &pose(rt), &q0)
            .expect("compensated joints");
        let (dp, dr) = pose_error(
            &robot.predict(&MoveContext::default(), &q, kinematic),
            &programmed,
        );
        assert_abs_diff_eq!(dp.norm(), 0.0, epsilon = POS_TOL_MM);
        assert_abs_diff_eq!(dr.norm(), 0.0, epsilon = ROT_TOL_RAD);
        // Compensated indeed (not the programmed value written back).
        assert!((pose(rt).translation.vector - programmed.translation.vector).norm() > 0.01);
    }
}

#[test]
fn strict_refuses_a_module_with_a_move_left_as_written() {
    let dir = tempfile::tempdir().expect("tempdir");
    let input = write(dir.path(), "PickCell.mod", PICK_CELL);
    let out = dir.path().join("out.mod");
    let (code, err) = compensate_cell(&input, &out, &["--strict"]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains(
            "PickCell.mod:29:9: MoveL left as written (target reassigned in a loop); --strict"
        ),
        "{err}"
    );
    assert!(!out.exists(), "no output on error");
    // The same for a check, with and without a robot, and a report.
    for args in [
        vec!["check", "--strict"],
        vec!["check", "--strict", "--machine", "abb-irb1600"],
        vec!["report", "--strict", "--machine", "abb-irb1600"],
    ] {
        let o = postproc().args(&args).arg(&input).output().expect("run");
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
        assert!(
            err.contains("PickCell.mod:29:9: MoveL left as written"),
            "{err}"
        );
    }
    // A module whose moves are all known passes.
    let ok = postproc()
        .args(["check", "--strict", "--machine", "abb-irb1600"])
        .arg(repo("samples/milling.mod"))
        .output()
        .expect("run");
    assert_eq!(ok.status.code(), Some(0));
    // G-code has no move left as written: --strict is refused there.
    let g = postproc()
        .args(["check", "--strict"])
        .arg(repo("samples/part.nc"))
        .output()
        .expect("run");
    assert_eq!(g.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&g.stderr).contains("--strict applies to RAPID modules"));
}

/// The task folder of a controller backup: a calibration data module with
/// the tool, work object and targets, a `user.sys` with a constant, and a
/// main module whose moves use them.
fn backup(dir: &std::path::Path) -> std::path::PathBuf {
    let task = dir.join("RAPID").join("TASK1");
    std::fs::create_dir_all(task.join("PROGMOD")).expect("mkdir");
    std::fs::create_dir_all(task.join("SYSMOD")).expect("mkdir");
    write(
        &task.join("PROGMOD"),
        "CalibData.mod",
        "MODULE CalibData\n  ! Cell calibration: tool, work object and taught targets.\n  PERS tooldata tGripper := [TRUE,[[0,0,150],[1,0,0,0]],[2,[0,0,60],[1,0,0,0],0,0,0]];\n  TASK PERS wobjdata wTable := [FALSE,TRUE,\"\",[[400,-300,200],[1,0,0,0]],[[0,0,0],[1,0,0,0]]];\n  CONST robtarget pPick := [[500,150,300],[0.1828804,0.0723086,0.9537141,0.2274985],[-1,0,-1,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\n  CONST robtarget pPlace := [[500,450,300],[0.1828804,-0.0723086,0.9537141,-0.2274985],[0,-1,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\n  LOCAL CONST robtarget pHome := [[0,0,0],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\nENDMODULE\n",
    );
    write(
        &task.join("SYSMOD"),
        "user.sys",
        "MODULE user(SYSMODULE)\n  ! User data of the system.\n  CONST num nLift := 100;\n  VAR num reg1 := 0;\nENDMODULE\n",
    );
    write(
        &task.join("PROGMOD"),
        "MainModule.mod",
        "MODULE MainModule\n  PROC main()\n    MoveJ Offs(pPick, 0, 0, nLift), v1000, z50, tGripper\\WObj:=wTable;\n    MoveL pPick, v200, fine, tGripper\\WObj:=wTable;\n    MoveJ pPlace, v1000, fine, tGripper\\WObj:=wTable;\n    reg1 := reg1 + 1;\n  ENDPROC\nENDMODULE\n",
    );
    task
}

/// The files below `dir` with their bytes, sorted.
fn tree(dir: &std::path::Path) -> Vec<(std::path::PathBuf, Vec<u8>)> {
    fn walk(d: &std::path::Path, out: &mut Vec<(std::path::PathBuf, Vec<u8>)>) {
        for e in std::fs::read_dir(d).expect("dir") {
            let p = e.expect("entry").path();
            if p.is_dir() {
                walk(&p, out);
            } else {
                out.push((p.clone(), std::fs::read(&p).expect("read")));
            }
        }
    }
    let mut v = Vec::new();
    walk(dir, &mut v);
    v.sort();
    v
}

#[test]
fn a_backup_folder_is_one_program_and_only_changed_modules_are_written() {
    let dir = tempfile::tempdir().expect("tempdir");
    let task = backup(dir.path());
    let before = tree(&task);
    let m = repo("machines/abb-irb1600.yaml");
    // Nothing to compensate: nothing written, every module untouched.
    let o = postproc()
        .args(["compensate", "--machine", m.to_str().unwrap()])
        .args(["--effects", "none", "--annotate", "none"])
        .arg(&task)
        .output()
        .expect("run");
    assert_eq!(
        o.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert_eq!(tree(&task), before);
    // Names resolve across the modules; only the main module changes.
    let out = dir.path().join("out");
    let o = postproc()
        .args(["compensate", "--machine", m.to_str().unwrap()])
        .args(["--effects", "kinematic", "--annotate", "none", "--out-dir"])
        .arg(&out)
        .arg(&task)
        .output()
        .expect("run");
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(0), "{err}");
    assert!(err.contains("program of 3 modules → 1 written"), "{err}");
    assert!(err.contains("3 moves compensated"), "{err}");
    assert_eq!(tree(&task), before);
    let written = tree(&out);
    assert_eq!(written.len(), 1, "{written:?}");
    assert!(written[0].0.ends_with("PROGMOD/MainModule.mod"));
    let text = text_without_header(&String::from_utf8(written[0].1.clone()).expect("utf-8"));
    let main = parse_module(&text, "main").expect("re-parses");
    let calib = std::fs::read_to_string(task.join("PROGMOD/CalibData.mod")).expect("read");
    let calib = parse_module(&calib, "calib").expect("parses");
    // The targets of CalibData are never edited there: the moves go to
    // compensated copies in the main module, which land on the targets.
    let robot = Robot::from_yaml_str(
        &std::fs::read_to_string(&m).expect("machine"),
        "abb-irb1600.yaml",
    )
    .expect("valid robot")
    .with_tool(
        Isometry3::from_parts(
            Translation3::new(0.0, 0.0, 150.0),
            UnitQuaternion::identity(),
        ),
        None,
    );
    let wobj = Isometry3::from_parts(
        Translation3::new(400.0, -300.0, 200.0),
        UnitQuaternion::identity(),
    );
    let kinematic = EffectSet {
        kinematic: 1.0,
        ..EffectSet::NONE
    };
    let moves: Vec<_> = main.moves().collect();
    for (k, base, dz) in [(0, "pPick", 100.0), (1, "pPick", 0.0), (2, "pPlace", 0.0)] {
        let Target::Named { name, .. } = &moves[k].target else {
            panic!("move {k}: a named target")
        };
        let rt_in = robtarget(&calib, base, None);
        let programmed = wobj
            * Isometry3::from_parts(Translation3::new(0.0, 0.0, dz), UnitQuaternion::identity())
            * pose(rt_in);
        let rt = robtarget(&main, name, None);
        let q0 = robot
            .ik_conf(&programmed, conf(rt_in))
            .expect("programmed joints");
        let q = robot
            .ik_numeric(Model::Nominal, &(wobj * pose(rt)), &q0)
            .expect("compensated joints");
        let (dp, dr) = pose_error(
            &robot.predict(&MoveContext::default(), &q, kinematic),
            &programmed,
        );
        assert_abs_diff_eq!(dp.norm(), 0.0, epsilon = POS_TOL_MM);
        assert_abs_diff_eq!(dr.norm(), 0.0, epsilon = ROT_TOL_RAD);
    }
    // A .pgf program file names the same modules.
    let pgf = write(
        &task,
        "Cell.pgf",
        "<?xml version=\"1.0\" encoding=\"ISO-8859-1\" ?>\n<Program>\n  <Module>PROGMOD\\CalibData.mod</Module>\n  <Module>SYSMOD\\user.sys</Module>\n  <Module>PROGMOD\\MainModule.mod</Module>\n</Program>\n",
    );
    let o = postproc()
        .args(["check", "--machine", m.to_str().unwrap()])
        .arg(&pgf)
        .output()
        .expect("run");
    let said = String::from_utf8_lossy(&o.stdout);
    assert_eq!(
        o.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert_eq!(said.lines().count(), 3, "{said}");
    assert!(
        said.contains("MainModule.mod: module MainModule, 0 declarations, 1 routines, 3 moves")
    );
    // A strict check of a program resolves its names across the modules,
    // with a robot or without one.
    let o = postproc()
        .args(["check", "--strict"])
        .arg(&pgf)
        .output()
        .expect("run");
    assert_eq!(
        o.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let o = postproc()
        .args(["check", "--strict", "--machine", m.to_str().unwrap()])
        .arg(&pgf)
        .output()
        .expect("run");
    assert_eq!(o.status.code(), Some(0));
    // An error in another module's declaration points into that module.
    let calib_path = task.join("PROGMOD/CalibData.mod");
    let bad = std::fs::read_to_string(&calib_path)
        .expect("read")
        .replace("[0,-1,0,0]", "[5,5,5,5]");
    std::fs::write(&calib_path, bad).expect("write");
    let o = postproc()
        .args(["check", "--machine", m.to_str().unwrap()])
        .arg(&task)
        .output()
        .expect("run");
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("CalibData.mod:6:29: target `pPlace`"), "{err}");
}

/// A backup task folder whose moves are in two modules.
fn backup_with_service(dir: &std::path::Path) -> std::path::PathBuf {
    let task = backup(dir);
    write(
        &task.join("PROGMOD"),
        "Service.mod",
        "MODULE Service\n  ! Service position over the pick place.\n  PROC service()\n    MoveJ Offs(pPick, 0, 0, 200), v500, z50, tGripper\\WObj:=wTable;\n    MoveL pPick, v100, fine, tGripper\\WObj:=wTable;\n  ENDPROC\nENDMODULE\n",
    );
    task
}

/// The CSV rows of a report (comment lines left out) as cells, the header
/// first.
fn csv_rows(text: &str) -> Vec<Vec<String>> {
    text.lines()
        .filter(|l| !l.starts_with('#'))
        .map(|l| l.split(',').map(str::to_string).collect())
        .collect()
}

/// Checks the rows of a program's report: one per move of every module,
/// each naming a module file whose line holds that instruction.
fn assert_rows_point_into_their_files(rows: &[Vec<String>], task: &std::path::Path) {
    assert_eq!(rows[0][..3], ["file", "line", "motion"]);
    let mut files = std::collections::BTreeSet::new();
    for row in &rows[1..] {
        let text = std::fs::read_to_string(&row[0]).expect("the row's file");
        assert!(std::path::Path::new(&row[0]).starts_with(task), "{row:?}");
        let line: usize = row[1].parse().expect("line");
        let at = text
            .lines()
            .nth(line - 1)
            .expect("line in file")
            .trim_start();
        assert!(at.starts_with(&format!("{} ", row[2])), "{row:?}: {at}");
        files.insert(row[0].clone());
    }
    assert_eq!(files.len(), 2, "{files:?}");
}

#[test]
fn the_report_of_a_program_has_a_row_per_move_of_every_module() {
    let dir = tempfile::tempdir().expect("tempdir");
    let task = backup_with_service(dir.path());
    let m = repo("machines/abb-irb1600.yaml");
    let o = postproc()
        .args(["report", "--machine", m.to_str().unwrap()])
        .args(["--effects", "kinematic", "--format", "csv"])
        .arg(&task)
        .output()
        .expect("run");
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(0), "{err}");
    let rows = csv_rows(&String::from_utf8(o.stdout).expect("utf-8"));
    // Three moves in MainModule and two in Service, each module parsed
    // on its own for its count.
    let moves: usize = ["MainModule.mod", "Service.mod"]
        .iter()
        .map(|f| {
            let text = std::fs::read_to_string(task.join("PROGMOD").join(f)).expect("read");
            parse_module(&text, f).expect("parses").moves().count()
        })
        .sum();
    assert_eq!(moves, 5);
    assert_eq!(rows.len() - 1, moves, "{rows:?}");
    assert_rows_point_into_their_files(&rows, &task);
}

#[test]
fn compensate_of_a_program_writes_its_report() {
    let dir = tempfile::tempdir().expect("tempdir");
    let task = backup_with_service(dir.path());
    let before = tree(&task);
    let m = repo("machines/abb-irb1600.yaml");
    let out = dir.path().join("out");
    let report = dir.path().join("program.csv");
    let o = postproc()
        .args(["compensate", "--machine", m.to_str().unwrap()])
        .args(["--effects", "kinematic", "--annotate", "none", "--out-dir"])
        .arg(&out)
        .arg("--report")
        .arg(&report)
        .arg(&task)
        .output()
        .expect("run");
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(0), "{err}");
    assert!(err.contains("program of 4 modules → 2 written"), "{err}");
    assert_eq!(tree(&task), before);
    let rows = csv_rows(&std::fs::read_to_string(&report).expect("report"));
    assert_eq!(rows.len() - 1, 5, "{rows:?}");
    assert_rows_point_into_their_files(&rows, &task);
}

/// `check --strict` of a program needs no robot: names resolve across the
/// modules, and a move left as written (a target reassigned in a loop of
/// the sample) is refused, naming its module file and line.
#[test]
fn a_strict_check_of_a_program_without_a_machine_names_a_move_left_as_written() {
    let task = repo("samples/cell-backup/RAPID/TASK1");
    let o = postproc()
        .args(["check", "--strict"])
        .arg(&task)
        .output()
        .expect("run");
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    let main = task.join("PROGMOD/MainModule.mod");
    let text = std::fs::read_to_string(&main).expect("main");
    // The first move whose target is reassigned in the loop.
    let line = text
        .lines()
        .position(|l| l.trim_start().starts_with("MoveJ Offs(pStack"))
        .expect("the move")
        + 1;
    let at = format!("{}:{line}:", main.display());
    assert!(err.contains(&at), "{at} in {err}");
    assert!(
        err.contains("left as written (target reassigned in a loop)"),
        "{err}"
    );
    // Without --strict the same check passes.
    let o = postproc().arg("check").arg(&task).output().expect("run");
    assert_eq!(o.status.code(), Some(0));
}
