//! Integration tests: RAPID cells shaped like real ones (palletising with a
//! run-time tool, arc welding with parameter lists over several lines, a
//! `FOR` loop over an array, a `MoveAbsJ` home, a speed of another module,
//! targets at quadrant borders) on the bundled IRB 1600, through the
//! binary. Each: the identity run (`--effects none --annotate none`) gives
//! the module back byte for byte, the summary counts the compensated moves
//! and those left as written with their reasons, and each compensated target
//! is checked by forward kinematics: the robot's predicted pose at the
//! controller's joints for the written target is the programmed one.

use approx::assert_abs_diff_eq;
use nalgebra::{Isometry3, Vector3};
use postproc::machine::robot::pose::pose_error;
use postproc::machine::robot::{Model, PointMass, Robot};
use postproc::predict::EffectSet;
use postproc::predict::MoveContext;
use postproc::program::rapid::{DataValue, Module, RobTarget, parse_module};

use crate::common::{postproc, repo, robtarget_conf, robtarget_pose, without_header, write};

/// Predicted TCP against programmed, mm: the compensation converges to
/// 1e-6 mm; the written target's 3 decimals round by up to 0.0009 mm.
const POS_TOL_MM: f64 = 1e-3;
/// Rotation, rad: 7-decimal quaternions (0.2 µrad) and the convergence.
const ROT_TOL_RAD: f64 = 1e-6;

fn machine() -> String {
    repo("machines/abb-irb1600.yaml")
        .to_str()
        .expect("utf8")
        .to_string()
}

fn robot() -> Robot {
    let text = std::fs::read_to_string(machine()).expect("machine");
    Robot::from_yaml_str(&text, "abb-irb1600").expect("valid")
}

/// Runs `compensate` of the modules `files` (the first is written with
/// `-o` when alone, else into `--out-dir`): the exit code, the standard
/// error and the output text of the first module.
fn compensate(
    dir: &std::path::Path,
    files: &[(&str, &str)],
    extra: &[&str],
) -> (i32, String, String) {
    let paths: Vec<_> = files.iter().map(|(n, t)| write(dir, n, t)).collect();
    let out_dir = dir.join("out");
    let _ = std::fs::remove_dir_all(&out_dir);
    let mut cmd = postproc();
    cmd.arg("compensate")
        .args(&paths)
        .args(["--machine", &machine()]);
    let out = if files.len() == 1 {
        let o = dir.join("out.mod");
        cmd.arg("-o").arg(&o);
        o
    } else {
        cmd.arg("--out-dir").arg(&out_dir);
        out_dir.join(files[0].0)
    };
    let run = cmd.args(extra).output().expect("run");
    let err = String::from_utf8_lossy(&run.stderr).to_string();
    let text = std::fs::read_to_string(&out).unwrap_or_default();
    (run.status.code().unwrap_or(-1), err, text)
}

/// The identity run writes every module back byte for byte (the
/// provenance header aside).
fn assert_identity(files: &[(&str, &str)]) {
    let dir = tempfile::tempdir().expect("tempdir");
    let (code, err, text) = compensate(
        dir.path(),
        files,
        &["--effects", "none", "--annotate", "none"],
    );
    assert_eq!(code, 0, "{err}");
    if files.len() == 1 {
        assert!(
            without_header(text.as_bytes()) == files[0].1.as_bytes(),
            "identity differs:\n{text}"
        );
    }
}

fn robtarget<'a>(m: &'a Module, name: &str, elem: Option<usize>) -> &'a RobTarget {
    let d = m.decl(name).unwrap_or_else(|| panic!("{name} declared"));
    match (&d.value, elem) {
        (Some(DataValue::RobTarget(rt)), None) => rt,
        (Some(DataValue::Array { items, .. }), Some(i)) => match &items[i] {
            DataValue::RobTarget(rt) => rt,
            v => panic!("{name}{{{i}}}: {v:?}"),
        },
        (v, _) => panic!("{name}: {v:?}"),
    }
}

/// Forward kinematics check: the controller solves the written target
/// `written` (its confdata), and the robot with `tool` predicted at those
/// joints (kinematic and gravity effects: the runs compensate those) is at
/// the programmed pose `programmed`.
fn assert_lands(tool: &Robot, written: &RobTarget, programmed: &Isometry3<f64>, what: &str) {
    let q = tool
        .ik_conf(&robtarget_pose(written), robtarget_conf(written))
        .unwrap_or_else(|e| panic!("{what}: {e}"));
    let fx = EffectSet {
        thermal: 0.0,
        process: 0.0,
        dynamic: 0.0,
        ..EffectSet::ALL
    };
    let (dp, dr) = pose_error(&tool.predict(&MoveContext::default(), &q, fx), programmed);
    assert_abs_diff_eq!(dp.norm(), 0.0, epsilon = POS_TOL_MM);
    assert_abs_diff_eq!(dr.norm(), 0.0, epsilon = ROT_TOL_RAD);
}

/// The count `N moves compensated` and the left-as-written part of the
/// summary line.
fn counts(err: &str) -> (usize, String) {
    let line = err
        .lines()
        .find(|l| l.contains(" moves compensated") || l.contains(" move compensated"))
        .unwrap_or_else(|| panic!("summary in {err}"));
    let n = line
        .split(": ")
        .nth(1)
        .and_then(|s| s.split(' ').next())
        .and_then(|s| s.parse().ok())
        .expect("count");
    // `, N left as written (reason; reason)`: up to its closing parenthesis.
    let left = match line.find(" left as written (") {
        Some(k) => {
            let from = line[..k].rfind(", ").map_or(0, |p| p + 2);
            let mut depth = 0;
            let mut end = line.len();
            for (i, c) in line[k..].char_indices() {
                match c {
                    '(' => depth += 1,
                    ')' => {
                        depth -= 1;
                        if depth == 0 {
                            end = k + i + 1;
                            break;
                        }
                    }
                    _ => {}
                }
            }
            line[from..end].to_string()
        }
        None => String::new(),
    };
    (n, left)
}

const FX: &[&str] = &["--effects", "kinematic,gravity"];

const PALLET: &str = "MODULE Pallet
  PERS tooldata tGripper := [TRUE,[[0,0,160],[1,0,0,0]],[3.5,[0,0,70],[1,0,0,0],0,0,0]];
  PERS tooldata tSucker := [TRUE,[[0,0,120],[1,0,0,0]],[1.5,[0,0,50],[1,0,0,0],0,0,0]];
  PERS tooldata tActual := [TRUE,[[0,0,160],[1,0,0,0]],[3.5,[0,0,70],[1,0,0,0],0,0,0]];
  CONST robtarget pHome := [[700,-200,700],[0,0,1,0],[-1,0,-1,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST robtarget pPick := [[750,-150,350],[0,0,1,0],[-1,0,-1,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST robtarget pPlace := [[650,250,400],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  PROC main()
    tActual := tGripper;
    MoveJ pHome, v1000, z50, tGripper;
    MoveL pPick, v200, fine, tActual;
    MoveL pPlace, v200, fine, tGripper;
  ENDPROC
ENDMODULE
";

/// A palletising cell whose gripper is chosen at run time: the move with
/// `tActual` is left as written, named; the others are compensated.
#[test]
fn palletising_with_a_run_time_tool() {
    assert_identity(&[("Pallet.mod", PALLET)]);
    let dir = tempfile::tempdir().expect("tempdir");
    let (code, err, text) = compensate(dir.path(), &[("Pallet.mod", PALLET)], FX);
    assert_eq!(code, 0, "{err}");
    assert!(
        err.contains("Pallet.mod:11: MoveL left as written (run-time tool `tActual`)"),
        "{err}"
    );
    assert_eq!(
        counts(&err),
        (2, "1 left as written (run-time tool `tActual`)".into())
    );
    let m_in = parse_module(PALLET, "in").expect("input");
    let m_out = parse_module(&text, "out").expect("output");
    let grip = robot().with_tool(
        Isometry3::translation(0.0, 0.0, 160.0),
        Some(PointMass {
            mass_kg: 3.5,
            com_mm: Vector3::new(0.0, 0.0, 70.0),
        }),
    );
    for name in ["pHome", "pPlace"] {
        let programmed = robtarget_pose(robtarget(&m_in, name, None));
        assert_lands(&grip, robtarget(&m_out, name, None), &programmed, name);
    }
    // The move left as written keeps its target as written.
    assert_eq!(
        robtarget(&m_out, "pPick", None)
            .trans
            .each_ref()
            .map(|n| n.value),
        [750.0, -150.0, 350.0]
    );
}

const WELD: &str = "MODULE ArcCell
  CONST robtarget pApproach := [[800,-100,500],[0,0,1,0],[-1,0,-1,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST robtarget pSeamA := [[820,-80,420],[0,0,1,0],[-1,0,-1,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST robtarget pSeamB := [[820,80,420],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  VAR num nPasses := 1;
  PROC main()
    MoveJ pApproach, v1000, z50, tool0;
    weldSeam pSeamA,
      pSeamB, nPasses;
  ENDPROC
  PROC weldSeam(robtarget pStart, ! where the arc starts
                robtarget pEnd,
                VAR num nCount)
    MoveJ pStart, v200, fine, tool0;
    MoveL pEnd, v10, fine, tool0;
    nCount := nCount + 1;
  ENDPROC
ENDMODULE
";

/// An arc-welding module whose seam routine takes its parameters over
/// three lines (the last by reference): the module is read, the approach
/// compensated, and the seam's moves to its parameters compensated per
/// call: the call passes compensated copies of `pSeamA` and `pSeamB`.
#[test]
fn arc_welding_with_parameter_lists_over_several_lines() {
    assert_identity(&[("ArcCell.mod", WELD)]);
    let dir = tempfile::tempdir().expect("tempdir");
    let (code, err, text) = compensate(dir.path(), &[("ArcCell.mod", WELD)], FX);
    assert_eq!(code, 0, "{err}");
    assert_eq!(counts(&err), (3, String::new()));
    assert!(
        text.contains("    weldSeam pSeamA_c2,\n      pSeamB_c2, nPasses;\n"),
        "{text}"
    );
    let m_in = parse_module(WELD, "in").expect("input");
    let m_out = parse_module(&text, "out").expect("output");
    let flange = robot().with_tool(Isometry3::identity(), None);
    for (name, written) in [
        ("pApproach", "pApproach"),
        ("pSeamA", "pSeamA_c2"),
        ("pSeamB", "pSeamB_c2"),
    ] {
        let programmed = robtarget_pose(robtarget(&m_in, name, None));
        assert_lands(
            &flange,
            robtarget(&m_out, written, None),
            &programmed,
            written,
        );
    }
    // The seam's targets keep their values (the procedure reads them
    // through its parameters), and its moves are written as they were.
    for name in ["pSeamA", "pSeamB"] {
        assert_eq!(
            robtarget(&m_out, name, None)
                .trans
                .each_ref()
                .map(|n| n.value),
            robtarget(&m_in, name, None)
                .trans
                .each_ref()
                .map(|n| n.value)
        );
    }
    assert!(text.contains("    MoveL pEnd, v10, fine, tool0;"), "{text}");
}

const HOLES: &str = "MODULE Drill
  CONST jointtarget jHome := [[0,0,0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST robtarget holes{3} := [[[700,-60,300],[0,0,1,0],[-1,0,-1,0],[9E9,9E9,9E9,9E9,9E9,9E9]],[[700,20,300],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]],[[700,100,300],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]]];
  PROC main()
    MoveAbsJ jHome\\NoEOffs, v1000, fine, tool0;
    FOR k FROM 1 TO 3 DO
      MoveL holes{k}, v100, fine, tool0;
    ENDFOR
    MoveAbsJ jHome, v1000, fine, tool0;
  ENDPROC
ENDMODULE
";

/// A `FOR` loop over `holes{k}` compensates every hole in place; the
/// `MoveAbsJ` to the all-zero home (a wrist singularity) is reported and
/// left as written, never refused.
#[test]
fn a_for_loop_over_holes_and_a_move_abs_j_home() {
    assert_identity(&[("Drill.mod", HOLES)]);
    let dir = tempfile::tempdir().expect("tempdir");
    let (code, err, text) = compensate(dir.path(), &[("Drill.mod", HOLES)], FX);
    assert_eq!(code, 0, "{err}");
    assert_eq!(
        counts(&err),
        (
            3,
            "2 left as written (joint target: reported, not compensated)".into()
        )
    );
    assert!(
        text.contains("MoveAbsJ jHome\\NoEOffs, v1000, fine, tool0;\n"),
        "written as it was:\n{text}"
    );
    let m_in = parse_module(HOLES, "in").expect("input");
    let m_out = parse_module(&text, "out").expect("output");
    let flange = robot().with_tool(Isometry3::identity(), None);
    for i in 0..3 {
        let programmed = robtarget_pose(robtarget(&m_in, "holes", Some(i)));
        assert_lands(
            &flange,
            robtarget(&m_out, "holes", Some(i)),
            &programmed,
            "hole",
        );
    }
    // One annotation on the loop's move.
    assert_eq!(text.matches("! dev ").count(), 1, "{text}");
    // The report has the home's predicted deviation.
    let report = postproc()
        .arg("report")
        .arg(write(dir.path(), "Drill.mod", HOLES))
        .args(["--machine", &machine()])
        .output()
        .expect("report");
    let report = String::from_utf8_lossy(&report.stdout);
    assert!(report.contains("MoveAbsJ"), "{report}");
    // Asked for, the Cartesian correction of the singular home is refused
    // as before (its joints 4 and 6 would swing).
    let (code, err, _) = compensate(
        dir.path(),
        &[("Drill.mod", HOLES)],
        &["--compensate-joint-targets"],
    );
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("jointtarget `jHome`"), "{err}");
}

const MAIN: &str = "MODULE MainModule
  CONST robtarget pA := [[750,-50,400],[0,0,1,0],[-1,0,-1,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST robtarget pB := [[750,50,400],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  PROC main()
    MoveJ pA, vApproach, z10, tool0;
    MoveL pB, vTargetSpeed, fine, tool0;
  ENDPROC
ENDMODULE
";

const DATA: &str = "MODULE CellData(SYSMODULE)
  PERS speeddata vApproach := [400,500,5000,1000];
ENDMODULE
";

/// A speed declared in another module of the program is read from there;
/// one known at run time only takes the stated fallback on the time line
/// (warned once) instead of refusing the module.
#[test]
fn a_speed_of_another_module_and_one_known_at_run_time() {
    let files = [("MainModule.mod", MAIN), ("CellData.sys", DATA)];
    let dir = tempfile::tempdir().expect("tempdir");
    // A program's identity run changes no module, so writes none.
    let (code, err, _) = compensate(
        dir.path(),
        &files,
        &["--effects", "none", "--annotate", "none"],
    );
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("program of 2 modules → 0 written"), "{err}");
    assert!(!dir.path().join("out").exists());
    assert_identity(&[("MainModule.mod", MAIN)]);
    let (code, err, text) = compensate(dir.path(), &files, &[]);
    assert_eq!(code, 0, "{err}");
    assert!(
        !err.contains("vApproach"),
        "resolved in CellData.sys: {err}"
    );
    assert_eq!(
        err.matches("speed `vTargetSpeed` of MoveL cannot be resolved offline; the time line takes it as vmax").count(),
        1,
        "{err}"
    );
    assert!(err.contains("2 moves compensated"), "{err}");
    let m_in = parse_module(MAIN, "in").expect("input");
    let m_out = parse_module(&text, "out").expect("output");
    assert!(m_out.decl("pB").is_some() && m_in.decl("pB").is_some());
    // Without the thermal effect nothing needs the speed: no warning.
    let (code, err, text) = compensate(dir.path(), &files, FX);
    assert_eq!(code, 0, "{err}");
    assert!(!err.contains("vTargetSpeed"), "{err}");
    let m_out = parse_module(&text, "out").expect("output");
    let flange = robot().with_tool(Isometry3::identity(), None);
    for name in ["pA", "pB"] {
        let programmed = robtarget_pose(robtarget(&m_in, name, None));
        assert_lands(&flange, robtarget(&m_out, name, None), &programmed, name);
    }
}

/// A target at joints `q_deg` (tool0), written as a controller would:
/// position with 3 decimals, quaternion with 7, the confdata quadrants
/// `cf` (cf1, cf4, cf6) and the solution's cfx.
fn target_at(r: &Robot, q_deg: [f64; 6], cf: [i32; 3]) -> String {
    let q = q_deg.map(f64::to_radians);
    let p = r.tcp_pose(Model::Nominal, &q);
    let t = p.translation.vector;
    let o = p.rotation.quaternion();
    let cfx = r.confdata(&q).cfx;
    format!(
        "[[{:.3},{:.3},{:.3}],[{:.7},{:.7},{:.7},{:.7}],[{},{},{},{cfx}],[9E9,9E9,9E9,9E9,9E9,9E9]]",
        t.x, t.y, t.z, o.w, o.i, o.j, o.k, cf[0], cf[1], cf[2]
    )
}

/// Targets with joint 1 and joint 4 within 0.01° of 0°, either side,
/// programmed in quadrant 0: each is solved in its programmed
/// configuration, compensated, and lands on its programmed pose.
#[test]
fn targets_at_quadrant_borders_are_solved_as_programmed() {
    let flange = robot().with_tool(Isometry3::identity(), None);
    let joints = [
        [0.008, 10.0, 15.0, 30.0, 50.0, 20.0],
        [-0.008, 10.0, 15.0, 30.0, 50.0, 20.0],
        [25.0, 5.0, 20.0, 0.008, 60.0, 30.0],
        [25.0, 5.0, 20.0, -0.008, 60.0, 30.0],
        [-0.009, 0.0, 25.0, -0.009, 45.0, 10.0],
    ];
    let mut decls = String::new();
    let mut moves = String::new();
    for (i, q) in joints.iter().enumerate() {
        decls += &format!(
            "  CONST robtarget pB{i} := {};\n",
            target_at(&flange, *q, [0, 0, 0])
        );
        moves += &format!("    MoveL pB{i}, v100, fine, tool0;\n");
    }
    let module = format!("MODULE Border\n{decls}  PROC main()\n{moves}  ENDPROC\nENDMODULE\n");
    assert_identity(&[("Border.mod", &module)]);
    let dir = tempfile::tempdir().expect("tempdir");
    let (code, err, text) = compensate(dir.path(), &[("Border.mod", &module)], FX);
    assert_eq!(code, 0, "{err}");
    assert_eq!(counts(&err), (joints.len(), String::new()));
    let m_in = parse_module(&module, "in").expect("input");
    let m_out = parse_module(&text, "out").expect("output");
    for i in 0..joints.len() {
        let name = format!("pB{i}");
        let programmed = robtarget_pose(robtarget(&m_in, &name, None));
        assert_lands(&flange, robtarget(&m_out, &name, None), &programmed, &name);
    }
}

/// A joint limit is printed as the machine file writes it, not as the
/// float its conversion to radians and back gives.
#[test]
fn joint_limits_print_as_written() {
    let module = "MODULE Limit
  CONST jointtarget jFar := [[0,0,-250,0,30,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  PROC main()
    MoveAbsJ jFar, v100, fine, tool0;
  ENDPROC
ENDMODULE
";
    let dir = tempfile::tempdir().expect("tempdir");
    let (code, err, _) = compensate(dir.path(), &[("Limit.mod", module)], &[]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("[-245°, 65°]"), "{err}");
}

/// A named constant inside a robtarget literal is resolved (the move is
/// compensated, the compensated numbers replace the name); an expression
/// there is not evaluated: its move is left as written, named, and the
/// module is not refused.
#[test]
fn named_constants_inside_literals() {
    let module = "MODULE Stack
  CONST num safeHeight := 450;
  CONST num nRow := 100;
  CONST robtarget pAbove := [[800,0,safeHeight],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST robtarget pDown := [[800,nRow,300],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST robtarget pHigh := [[800,0,safeHeight+50],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  PROC main()
    MoveJ pAbove, v500, z10, tool0;
    MoveL pDown, v100, fine, tool0;
    MoveL pHigh, v100, fine, tool0;
  ENDPROC
ENDMODULE
";
    assert_identity(&[("Stack.mod", module)]);
    let dir = tempfile::tempdir().expect("tempdir");
    let (code, err, text) = compensate(dir.path(), &[("Stack.mod", module)], FX);
    assert_eq!(code, 0, "{err}");
    assert_eq!(
        counts(&err),
        (
            2,
            "1 left as written (robtarget value is an expression)".into()
        )
    );
    assert!(text.contains("[[800,0,safeHeight+50]"), "{text}");
    let m_in = parse_module(module, "in").expect("input");
    assert_eq!(
        robtarget(&m_in, "pAbove", None)
            .trans
            .each_ref()
            .map(|n| n.value),
        [800.0, 0.0, 450.0]
    );
    let m_out = parse_module(&text, "out").expect("output");
    let flange = robot().with_tool(Isometry3::identity(), None);
    for name in ["pAbove", "pDown"] {
        let programmed = robtarget_pose(robtarget(&m_in, name, None));
        assert_lands(&flange, robtarget(&m_out, name, None), &programmed, name);
    }
}

/// An `ALIAS` of robtarget: a target declared with the alias type is a
/// robtarget, compensated; the alias line is written as it was.
#[test]
fn an_alias_type_is_the_type_it_names() {
    let module = "MODULE Aliased
  LOCAL ALIAS robtarget target;
  ALIAS target point;
  CONST point pA := [[800,100,450],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  PROC main()
    MoveL pA, v100, fine, tool0;
  ENDPROC
ENDMODULE
";
    assert_identity(&[("Aliased.mod", module)]);
    let dir = tempfile::tempdir().expect("tempdir");
    let (code, err, text) = compensate(dir.path(), &[("Aliased.mod", module)], FX);
    assert_eq!(code, 0, "{err}");
    assert_eq!(counts(&err), (1, String::new()));
    assert!(text.contains("  LOCAL ALIAS robtarget target;\n  ALIAS target point;\n"));
    let m_in = parse_module(module, "in").expect("input");
    let m_out = parse_module(&text, "out").expect("output");
    let programmed = robtarget_pose(robtarget(&m_in, "pA", None));
    let flange = robot().with_tool(Isometry3::identity(), None);
    assert_lands(&flange, robtarget(&m_out, "pA", None), &programmed, "pA");
}
