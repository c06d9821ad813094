//! Integration tests: which moves of a RAPID module are compensated and
//! which are left as written, through the real binary — arrays indexed at
//! run time, targets handed to procedures, arrays of several dimensions.
//! Each module comes back byte for byte with nothing to compensate, read
//! whole or a window at a time, and the compensated targets, commanded,
//! land on the programmed poses (forward kinematics of the robot library).

use approx::assert_abs_diff_eq;
use nalgebra::Isometry3;
use postproc::machine::robot::pose::pose_error;
use postproc::machine::robot::{Model, Robot};
use postproc::predict::EffectSet;
use postproc::predict::MoveContext;
use postproc::program::rapid::{DataValue, JointTarget, Module, RobTarget, parse_module};

use crate::common::{
    postproc, repo, robtarget_conf as conf, robtarget_pose as pose, text_without_header,
    without_header, write,
};

/// Position agreement of the predicted attained TCP with the programmed
/// one, mm: the written position has 3 decimals (≤ 0.0005 mm per axis,
/// 0.00087 mm in all) and the attained pose follows the command 1:1 to
/// first order.
const POS_TOL_MM: f64 = 1e-3;
/// Orientation agreement, rad: quaternions written with 7 decimals turn
/// the frame by at most 2e-7 rad.
const ROT_TOL_RAD: f64 = 1e-6;
/// Position agreement of a jointtarget written with 6-decimal degrees, mm:
/// each joint moves by ≤ 8.7e-9 rad, on lever arms under 1.6 m, so
/// 6 · 8.7e-9 · 1600 mm = 0.00008 mm plus the solve's residual.
const JOINT_POS_TOL_MM: f64 = 1e-3;
/// Orientation agreement of a jointtarget, rad: Σ|δq| ≤ 6 · 8.7e-9 rad.
const JOINT_ROT_TOL_RAD: f64 = 1e-6;

/// The effects the modules are compensated with (`--effects kinematic`).
const KINEMATIC: EffectSet = EffectSet {
    kinematic: 1.0,
    ..EffectSet::NONE
};

/// A robtarget literal at (x, y, z), tool pointing down.
fn rt(x: f64, y: f64, z: f64) -> String {
    format!("[[{x},{y},{z}],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]]")
}

/// The IRB 1600 with `tool0` (the flange, no load).
fn irb1600() -> Robot {
    let text = std::fs::read_to_string(repo("machines/abb-irb1600.yaml")).expect("machine file");
    Robot::from_yaml_str(&text, "abb-irb1600.yaml")
        .expect("valid robot")
        .with_tool(Isometry3::identity(), None)
}

/// Runs `postproc ARGS…` with the IRB 1600: exit code, standard error.
fn run(args: &[&str]) -> (i32, String) {
    let machine = repo("machines/abb-irb1600.yaml");
    let o = postproc()
        .args(args)
        .args(["--machine", machine.to_str().expect("utf8")])
        .output()
        .expect("runs");
    (
        o.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

/// Compensates `module` (written as `name` in `dir`) with `--effects
/// kinematic --annotate none`; checks that `--effects none` gives it back
/// byte for byte and that a window of 2 lines at a time gives the bytes of
/// the module read whole. Gives the output without its header and the
/// standard error.
fn compensate(dir: &std::path::Path, name: &str, module: &str) -> (String, String) {
    let input = write(dir, name, module);
    let input = input.to_str().expect("utf8");
    let path = |p: &str| dir.join(p).to_str().expect("utf8").to_string();
    let (same, out, windowed) = (path("same.mod"), path("out.mod"), path("win.mod"));
    let (code, err) = run(&[
        "compensate",
        input,
        "--effects",
        "none",
        "--annotate",
        "none",
        "-o",
        &same,
    ]);
    assert_eq!(code, 0, "{err}");
    let got = without_header(&std::fs::read(&same).expect("output"));
    assert!(got == module.as_bytes(), "identity");
    // MoveAbsJ too, in joint space (the copies of jointtargets).
    let args = [
        "--effects",
        "kinematic",
        "--annotate",
        "none",
        "--compensate-joint-targets",
    ];
    let (code, err) = run(&[&["compensate", input, "-o", &out][..], &args[..]].concat());
    assert_eq!(code, 0, "{err}");
    let win = [
        "compensate",
        "--rapid-window-lines",
        "2",
        input,
        "-o",
        &windowed,
    ];
    let (code, werr) = run(&[&win[..], &args[..]].concat());
    assert_eq!(code, 0, "{werr}");
    let whole = std::fs::read(&out).expect("output");
    assert!(
        whole == std::fs::read(&windowed).expect("output"),
        "windows"
    );
    let text = text_without_header(&String::from_utf8(whole).expect("utf8"));
    (text, err)
}

/// The value of declaration `name` of `m`, element `ks` (1-based, one per
/// dimension) of an array.
fn value<'m>(m: &'m Module, name: &str, ks: &[usize]) -> &'m DataValue {
    let mut v = m
        .decl(name)
        .and_then(|d| d.value.as_ref())
        .unwrap_or_else(|| panic!("`{name}` declared with a value"));
    for &k in ks {
        let DataValue::Array { items, .. } = v else {
            panic!("`{name}` has fewer dimensions");
        };
        v = &items[k - 1];
    }
    v
}

fn robtarget<'m>(m: &'m Module, name: &str, ks: &[usize]) -> &'m RobTarget {
    match value(m, name, ks) {
        DataValue::RobTarget(rt) => rt,
        v => panic!("not a robtarget: {v:?}"),
    }
}

fn jointtarget<'m>(m: &'m Module, name: &str, ks: &[usize]) -> &'m JointTarget {
    match value(m, name, ks) {
        DataValue::JointTarget(jt) => jt,
        v => panic!("not a jointtarget: {v:?}"),
    }
}

/// The compensated robtarget `out`, commanded, lands on the programmed
/// `programmed`, and differs from it.
fn assert_lands(robot: &Robot, out: &RobTarget, programmed: &RobTarget) {
    assert_ne!(pose(out), pose(programmed), "compensated");
    let q = robot.ik_conf(&pose(out), conf(out)).expect("reachable");
    let (dp, dr) = pose_error(
        &robot.predict(&MoveContext::default(), &q, KINEMATIC),
        &pose(programmed),
    );
    assert_abs_diff_eq!(dp.norm(), 0.0, epsilon = POS_TOL_MM);
    assert_abs_diff_eq!(dr.norm(), 0.0, epsilon = ROT_TOL_RAD);
}

/// The compensated jointtarget `out`, commanded, lands on the nominal pose
/// of `programmed`.
fn assert_joints_land(robot: &Robot, out: &JointTarget, programmed: &JointTarget) {
    let q = |jt: &JointTarget| jt.robax.each_ref().map(|n| n.value.to_radians());
    assert_ne!(q(out), q(programmed), "compensated");
    let goal = robot.tcp_pose(Model::Nominal, &q(programmed));
    let (dp, dr) = pose_error(
        &robot.predict(&MoveContext::default(), &q(out), KINEMATIC),
        &goal,
    );
    assert_abs_diff_eq!(dp.norm(), 0.0, epsilon = JOINT_POS_TOL_MM);
    assert_abs_diff_eq!(dr.norm(), 0.0, epsilon = JOINT_ROT_TOL_RAD);
}

/// Line `n` (1-based) of `text`.
fn line(text: &str, n: usize) -> &str {
    text.lines().nth(n - 1).expect("line")
}

#[test]
fn a_run_time_index_keeps_every_element_of_its_array_as_written() {
    let module = format!(
        "MODULE ArrIdx
  CONST robtarget pArr{{3}} := [{},{},{}];
  CONST jointtarget jArr{{2}} := [[[0,10,10,0,60,0],[9E9,9E9,9E9,9E9,9E9,9E9]],[[5,10,10,0,60,0],[9E9,9E9,9E9,9E9,9E9,9E9]]];
  PROC main()
    FOR i FROM 1 TO 3 DO
      MoveL pArr{{i}}, v100, fine, tool0;
    ENDFOR
    MoveL pArr{{2}}, v100, fine, tool0;
    FOR k FROM 1 TO 2 DO
      MoveAbsJ jArr{{k}}, v100, fine, tool0;
    ENDFOR
    MoveAbsJ jArr{{2}}, v100, fine, tool0;
  ENDPROC
ENDMODULE
",
        rt(700.0, 0.0, 500.0),
        rt(720.0, 0.0, 500.0),
        rt(740.0, 0.0, 500.0)
    );
    let dir = tempfile::tempdir().expect("tempdir");
    let (text, err) = compensate(dir.path(), "arr.mod", &module);
    for l in [6, 10] {
        let said = format!(
            "arr.mod:{l}: {} left as written (indexed by a run-time value)",
            if l == 6 { "MoveL" } else { "MoveAbsJ" }
        );
        assert!(err.contains(&said), "{said}: {err}");
    }
    let summary = "2 moves compensated, 2 left as written (indexed by a run-time value)";
    assert!(err.contains(summary), "{err}");
    // The loops go where they went: both arrays keep their values, and the
    // moves to an element go to compensated copies.
    for l in [2, 3, 6, 10] {
        assert!(
            text.lines().any(|t| t == line(&module, l)),
            "{}",
            line(&module, l)
        );
    }
    assert!(text.contains("MoveL pArr2_c2, v100"), "{text}");
    assert!(text.contains("MoveAbsJ jArr2_c2, v100"), "{text}");
    let (m_in, m_out) = (
        parse_module(&module, "in").expect("parses"),
        parse_module(&text, "out").expect("output parses"),
    );
    let robot = irb1600();
    assert_lands(
        &robot,
        robtarget(&m_out, "pArr2_c2", &[]),
        robtarget(&m_in, "pArr", &[2]),
    );
    assert_joints_land(
        &robot,
        jointtarget(&m_out, "jArr2_c2", &[]),
        jointtarget(&m_in, "jArr", &[2]),
    );
}

#[test]
fn constant_indices_of_several_dimensions_are_compensated() {
    let (a, b, c, d) = (
        rt(700.0, 0.0, 500.0),
        rt(720.0, 0.0, 500.0),
        rt(700.0, 20.0, 500.0),
        rt(720.0, 20.0, 500.0),
    );
    let (e, f, g, h) = (
        rt(700.0, 0.0, 550.0),
        rt(720.0, 0.0, 550.0),
        rt(700.0, 20.0, 550.0),
        rt(720.0, 20.0, 550.0),
    );
    let module = format!(
        "MODULE Grid
  CONST robtarget pGrid{{2,2}} := [[{a},{b}],[{c},{d}]];
  CONST robtarget pCube{{2,1,2}} := [[[{e},{f}]],[[{g},{h}]]];
  CONST robtarget pPal{{2,2}} := [[{a},{b}],[{c},{d}]];
  CONST num nRow := 2;
  PROC main()
    MoveL pGrid{{1,2}}, v100, z10, tool0;
    MoveL pGrid{{nRow, 1}}, v100, fine, tool0;
    MoveL pCube{{2,1,2}}, v100, fine, tool0;
    MoveL Offs(pGrid{{1,1}}, 0, 0, 50), v100, fine, tool0;
  ENDPROC
  PROC row(num r)
    MoveL pPal{{r,2}}, v100, fine, tool0;
    MoveL pPal{{2,2}}, v100, fine, tool0;
  ENDPROC
ENDMODULE
"
    );
    let dir = tempfile::tempdir().expect("tempdir");
    let (text, err) = compensate(dir.path(), "grid.mod", &module);
    assert!(
        err.contains("grid.mod:13: MoveL left as written (indexed by a run-time value)"),
        "{err}"
    );
    let summary = "5 moves compensated, 1 left as written (indexed by a run-time value)";
    assert!(err.contains(summary), "{err}");
    // The elements of constant indices are written in place in the nested
    // literal; the array read at run time keeps its values (a copy takes
    // `pPal{2,2}`'s); the rest of the text is as written.
    assert!(text.lines().any(|t| t == line(&module, 4)), "{text}");
    let kept = text
        .lines()
        .filter(|l| !l.contains("_c2 :=") && !l.contains("_o1 :="));
    for (a, b) in module.lines().zip(kept) {
        if !a.contains("CONST robtarget") && !a.contains("pPal{2,2}") && !a.contains("Offs") {
            assert_eq!(a, b);
        }
    }
    assert!(text.contains("MoveL pPal2_2_c2, v100"), "{text}");
    assert!(text.contains("MoveL pGrid1_1_o1, v100"), "{text}");
    let (m_in, m_out) = (
        parse_module(&module, "in").expect("parses"),
        parse_module(&text, "out").expect("output parses"),
    );
    let robot = irb1600();
    for (name, ks) in [
        ("pGrid", &[1, 2][..]),
        ("pGrid", &[2, 1]),
        ("pCube", &[2, 1, 2]),
    ] {
        assert_lands(
            &robot,
            robtarget(&m_out, name, ks),
            robtarget(&m_in, name, ks),
        );
    }
    for (name, ks) in [
        ("pGrid", &[1, 1][..]),
        ("pGrid", &[2, 2]),
        ("pCube", &[1, 1, 1]),
    ] {
        assert_eq!(
            pose(robtarget(&m_out, name, ks)),
            pose(robtarget(&m_in, name, ks))
        );
    }
    assert_lands(
        &robot,
        robtarget(&m_out, "pPal2_2_c2", &[]),
        robtarget(&m_in, "pPal", &[2, 2]),
    );
    let lifted = format!("CONST robtarget lifted := {};", rt(700.0, 0.0, 550.0));
    let lifted = parse_module(&format!("MODULE L\n{lifted}\nENDMODULE\n"), "l").expect("parses");
    assert_lands(
        &robot,
        robtarget(&m_out, "pGrid1_1_o1", &[]),
        robtarget(&lifted, "lifted", &[]),
    );
}

#[test]
fn an_index_outside_its_array_or_with_too_few_dimensions_is_an_error() {
    let dir = tempfile::tempdir().expect("tempdir");
    for (index, what) in [
        ("{3,1}", "index 3 is outside `pGrid` (1..=2)"),
        ("{1,1,1}", "`pGrid` has 2 dimensions; the index gives 3"),
        ("{1}", "`pGrid` has 2 dimensions; the index gives 1"),
    ] {
        let module = format!(
            "MODULE Bad\n  CONST robtarget pGrid{{2,2}} := [[{a},{a}],[{a},{a}]];\n  PROC main()\n    MoveL pGrid{index}, v100, fine, tool0;\n  ENDPROC\nENDMODULE\n",
            a = rt(700.0, 0.0, 500.0)
        );
        let input = write(dir.path(), "bad.mod", &module);
        let (code, err) = run(&["check", input.to_str().expect("utf8")]);
        assert_eq!(code, 2, "{err}");
        assert!(err.contains("bad.mod:4:"), "{err}");
        assert!(err.contains(what), "{what}: {err}");
    }
}

#[test]
fn a_target_passed_by_value_to_a_procedure_is_not_reassigned() {
    let module = format!(
        "MODULE Cell
  PERS robtarget pA := {};
  VAR robtarget pB := {};
  VAR robtarget pC := {};
  VAR robtarget pD := {};
  PROC main()
    MoveL pA, v100, fine, tool0;
    Drill pA;
    Drill2 pB, 30 \\Fast;
    MoveL pB, v100, fine, tool0;
    Shift pC, 5;
    MoveL pC, v100, fine, tool0;
    Grip pD;
    MoveL pD, v100, fine, tool0;
  ENDPROC
  PROC Drill(robtarget pHole)
    MoveL Offs(pHole, 0, 0, 20), v100, fine, tool0;
  ENDPROC
  PROC Drill2(robtarget pHole, num nDepth, \\switch Fast)
    WaitTime 0.1;
  ENDPROC
  PROC Shift(INOUT robtarget p, num dz)
    p := Offs(p, 0, 0, dz);
  ENDPROC
ENDMODULE
",
        rt(700.0, 0.0, 500.0),
        rt(720.0, 0.0, 500.0),
        rt(740.0, 0.0, 500.0),
        rt(760.0, 0.0, 500.0)
    );
    let dir = tempfile::tempdir().expect("tempdir");
    let (text, err) = compensate(dir.path(), "cell.mod", &module);
    // `Shift` changes its INOUT argument; `Grip` is declared nowhere in the
    // program, so it may change what it is given.
    for said in [
        "cell.mod:12: MoveL left as written (set by Shift)",
        "cell.mod:14: MoveL left as written (set by Grip)",
        "cell.mod:17: MoveL left as written (routine parameter)",
    ] {
        assert!(err.contains(said), "{said}: {err}");
    }
    let summary =
        "2 moves compensated, 3 left as written (routine parameter; set by Grip; set by Shift)";
    assert!(err.contains(summary), "{err}");
    let (m_in, m_out) = (
        parse_module(&module, "in").expect("parses"),
        parse_module(&text, "out").expect("output parses"),
    );
    let robot = irb1600();
    // `Drill` moves to its parameter, left as written: `pA` keeps its value
    // for the call, and the compensated `MoveL pA` goes to a copy.
    assert!(text.contains("    MoveL pA_c2, v100"), "{text}");
    assert_lands(
        &robot,
        robtarget(&m_out, "pA_c2", &[]),
        robtarget(&m_in, "pA", &[]),
    );
    assert_lands(
        &robot,
        robtarget(&m_out, "pB", &[]),
        robtarget(&m_in, "pB", &[]),
    );
    for l in [2, 4, 5] {
        assert!(
            text.lines().any(|t| t == line(&module, l)),
            "{}",
            line(&module, l)
        );
    }
}

#[test]
fn a_procedure_of_another_module_passes_its_arguments_as_its_parameters_say() {
    let main = format!(
        "MODULE MainMod
  PERS robtarget pA := {};
  PERS robtarget pB := {};
  PROC main()
    Drill pA;
    MoveL pA, v100, fine, tool0;
    Shift pB;
    MoveL pB, v100, fine, tool0;
  ENDPROC
ENDMODULE
",
        rt(700.0, 0.0, 500.0),
        rt(720.0, 0.0, 500.0)
    );
    let lib = "MODULE Lib(SYSMODULE)
  PROC Drill(robtarget pHole)
    WaitTime 0.1;
  ENDPROC
  PROC Shift(VAR robtarget p)
    p.trans.z := p.trans.z + 1;
  ENDPROC
ENDMODULE
";
    let dir = tempfile::tempdir().expect("tempdir");
    let m = write(dir.path(), "MainMod.mod", &main);
    let l = write(dir.path(), "Lib.sys", lib);
    let out = dir.path().join("out");
    let (code, err) = run(&[
        "compensate",
        m.to_str().expect("utf8"),
        l.to_str().expect("utf8"),
        "--effects",
        "kinematic",
        "--annotate",
        "none",
        "--out-dir",
        out.to_str().expect("utf8"),
    ]);
    assert_eq!(code, 0, "{err}");
    assert!(
        err.contains("MainMod.mod:8: MoveL left as written (set by Shift)"),
        "{err}"
    );
    assert!(
        err.contains("1 move compensated, 1 left as written"),
        "{err}"
    );
    let written = std::fs::read_to_string(out.join("MainMod.mod")).expect("output");
    let m_in = parse_module(&main, "in").expect("parses");
    let m_out = parse_module(&text_without_header(&written), "out").expect("output parses");
    assert_lands(
        &irb1600(),
        robtarget(&m_out, "pA", &[]),
        robtarget(&m_in, "pA", &[]),
    );
    assert_eq!(
        pose(robtarget(&m_out, "pB", &[])),
        pose(robtarget(&m_in, "pB", &[]))
    );
}

#[test]
fn an_instruction_not_in_the_table_keeps_its_target_as_written() {
    let module = format!(
        "MODULE Spot
  CONST robtarget pW1 := {};
  PROC main()
    MoveL pW1, v100, fine, tool0;
    PaintL pW1, v100, z10, tool0;
  ENDPROC
ENDMODULE
",
        rt(700.0, 0.0, 500.0)
    );
    let dir = tempfile::tempdir().expect("tempdir");
    let (text, err) = compensate(dir.path(), "spot.mod", &module);
    assert!(err.contains("spot.mod:5: PaintL left as written"), "{err}");
    assert!(text.lines().any(|t| t == line(&module, 2)), "{text}");
    assert!(text.contains("    MoveL pW1_c2, v100"), "{text}");
    assert!(text.contains("    PaintL pW1, v100"), "{text}");
    let (m_in, m_out) = (
        parse_module(&module, "in").expect("parses"),
        parse_module(&text, "out").expect("output parses"),
    );
    assert_lands(
        &irb1600(),
        robtarget(&m_out, "pW1_c2", &[]),
        robtarget(&m_in, "pW1", &[]),
    );
}

#[test]
fn a_target_passed_to_a_procedure_moving_to_its_parameter_keeps_its_value() {
    let module = format!(
        "MODULE Param
  CONST robtarget pC := {};
  CONST robtarget pE := {};
  PROC main()
    MoveL pC, v100, fine, tool0;
    Bohren pC;
    MoveL pE, v100, fine, tool0;
    Senken pE;
  ENDPROC
  PROC Bohren(robtarget pLoch)
    MoveL Offs(pLoch, 0, 0, 30), v200, z5, tool0;
    MoveL pLoch, v20, fine, tool0;
  ENDPROC
ENDMODULE
",
        rt(700.0, 0.0, 500.0),
        rt(720.0, 0.0, 500.0)
    );
    let dir = tempfile::tempdir().expect("tempdir");
    let (text, err) = compensate(dir.path(), "param.mod", &module);
    for l in [11, 12] {
        let said = format!("param.mod:{l}: MoveL left as written (routine parameter)");
        assert!(err.contains(&said), "{said}: {err}");
    }
    // `Senken` is declared nowhere: it may move to what it is given.
    for l in [2, 3, 6, 8] {
        assert!(
            text.lines().any(|t| t == line(&module, l)),
            "{}",
            line(&module, l)
        );
    }
    assert!(text.contains("    MoveL pC_c2, v100"), "{text}");
    assert!(text.contains("    MoveL pE_c2, v100"), "{text}");
    let (m_in, m_out) = (
        parse_module(&module, "in").expect("parses"),
        parse_module(&text, "out").expect("output parses"),
    );
    for name in ["pC", "pE"] {
        assert_lands(
            &irb1600(),
            robtarget(&m_out, &format!("{name}_c2"), &[]),
            robtarget(&m_in, name, &[]),
        );
    }
}
