//! RAPID programs shaped like the ones robot cells really run, written for
//! these tests: a CAM milling module of 10 000 inline targets, an
//! arc-welding module, a spot-welding module and a module of process
//! instructions postproc does not compensate (paint, dispense, CAP). Each comes back byte for byte with nothing to
//! compensate, every move is compensated otherwise, and the compensated
//! targets, commanded, land on the programmed poses (forward kinematics of
//! the robot library).

use std::fmt::Write as _;

use approx::assert_abs_diff_eq;
use nalgebra::{Isometry3, Vector3};
use postproc::machine::robot::pose::pose_error;
use postproc::machine::robot::{PointMass, Robot};
use postproc::predict::EffectSet;
use postproc::predict::MoveContext;

/// The effects the modules are compensated with (`--effects
/// kinematic,gravity`), for the forward check.
const KINEMATIC_GRAVITY: EffectSet = EffectSet {
    kinematic: 1.0,
    gravity: 1.0,
    process: 0.0,
    thermal: 0.0,
    dynamic: 0.0,
};
use postproc::program::rapid::{DataValue, Module, RobTarget, Target, parse_module};

use crate::common::{
    postproc, repo, robtarget_conf as conf, robtarget_pose as pose, text_without_header, write,
};

/// Position agreement of the predicted attained TCP with the programmed
/// one, mm: the written position has 3 decimals (≤ 0.0005 mm per axis,
/// 0.00087 mm in all) and the attained pose follows the command 1:1 to
/// first order.
const POS_TOL_MM: f64 = 1e-3;
/// Orientation agreement, rad: quaternions written with 7 decimals turn
/// the frame by at most 2e-7 rad.
const ROT_TOL_RAD: f64 = 1e-6;

/// The IRB 1600 with a tool: its TCP along the flange z axis and its mass.
fn irb1600_with(tcp_z_mm: f64, mass_kg: f64, com_z_mm: f64) -> Robot {
    let text = std::fs::read_to_string(repo("machines/abb-irb1600.yaml")).expect("machine file");
    let r = Robot::from_yaml_str(&text, "abb-irb1600.yaml").expect("valid robot");
    r.with_tool(
        Isometry3::translation(0.0, 0.0, tcp_z_mm),
        Some(PointMass {
            mass_kg,
            com_mm: Vector3::new(0.0, 0.0, com_z_mm),
        }),
    )
}

/// Compensates `module` (written as `name`) on the IRB 1600 with `effects`
/// and no annotation; the output without its provenance header.
fn compensate(dir: &std::path::Path, name: &str, module: &str, effects: &str) -> String {
    let input = write(dir, name, module);
    let output = dir.join(format!("{effects}.{name}"));
    postproc()
        .arg("compensate")
        .arg(&input)
        .arg("--machine")
        .arg(repo("machines/abb-irb1600.yaml"))
        .args(["--effects", effects, "--annotate", "none", "-o"])
        .arg(&output)
        .assert()
        .success();
    text_without_header(&std::fs::read_to_string(&output).expect("output"))
}

/// The robtarget a move goes to: inline, or a declared name.
fn target_of<'m>(m: &'m Module, t: &'m Target) -> &'m RobTarget {
    match t {
        Target::Inline(rt) => rt,
        Target::Named {
            name, index: None, ..
        } => match m.decl(name).and_then(|d| d.value.as_ref()) {
            Some(DataValue::RobTarget(rt)) => rt,
            v => panic!("`{name}` is not a robtarget: {v:?}"),
        },
        t => panic!("unexpected target {t:?}"),
    }
}

/// Every move of `m_out`, commanded, lands on the pose its counterpart in
/// `m_in` programs (both in `wobj`); returns how many moves were checked.
fn assert_moves_land(robot: &Robot, wobj: &Isometry3<f64>, m_in: &Module, m_out: &Module) -> usize {
    let (a, b): (Vec<_>, Vec<_>) = (m_in.moves().collect(), m_out.moves().collect());
    assert_eq!(a.len(), b.len());
    for (mi, mo) in a.iter().zip(&b) {
        let (p_in, p_out) = (target_of(m_in, &mi.target), target_of(m_out, &mo.target));
        assert_ne!(pose(p_in), pose(p_out), "line {}: compensated", mi.line);
        let programmed = wobj * pose(p_in);
        let q = robot
            .ik_conf(&(wobj * pose(p_out)), conf(p_out))
            .unwrap_or_else(|e| panic!("line {}: {e}", mo.line));
        let (dp, dr) = pose_error(
            &robot.predict(&MoveContext::default(), &q, KINEMATIC_GRAVITY),
            &programmed,
        );
        assert_abs_diff_eq!(dp.norm(), 0.0, epsilon = POS_TOL_MM);
        assert_abs_diff_eq!(dr.norm(), 0.0, epsilon = ROT_TOL_RAD);
    }
    a.len()
}

/// Passes and points per pass of the milling module.
const PASSES: usize = 100;
const POINTS_PER_PASS: usize = 100;

/// A pocket-finishing module as a CAM post writes one: a spindle tool and
/// a table work object declared at the top, `ConfL \Off`, then one linear
/// move per point with an inline robtarget (no spaces, the controller's
/// `9E+09` for unused external axes), a declared cutting speed, a
/// feed-rate change written as an inline speeddata, and `WObj0`-style
/// capitalisation on the approach.
fn cam_milling_module() -> String {
    let mut m = String::from(
        "MODULE Pocket_Finish\n\
         ! Generated by a CAM post: pocket finishing, 100 passes of 100 points.\n\
         PERS tooldata tSpindle:=[TRUE,[[0,0,215.5],[1,0,0,0]],[8.5,[0,0,90],[1,0,0,0],0.05,0.05,0.02]];\n\
         PERS wobjdata wTable:=[FALSE,TRUE,\"\",[[650,0,300],[1,0,0,0]],[[0,0,0],[1,0,0,0]]];\n\
         VAR speeddata vCut:=[40,500,5000,1000];\n\
         PROC Pocket()\n\
         ConfL\\Off;\n\
         MoveL [[0,20,50],[0,0,1,0],[0,0,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]],v200,z5,tSpindle\\WObj:=wTable;\n",
    );
    for pass in 0..PASSES {
        let y = 20.0 + 2.0 * pass as f64;
        for k in 0..POINTS_PER_PASS {
            // Every pass reverses x; a gentle ramp in z (a 3D surface).
            let i = if pass % 2 == 0 {
                k
            } else {
                POINTS_PER_PASS - 1 - k
            };
            let x = 2.0 * i as f64;
            let z = -0.5 - 0.01 * x + 0.002 * y;
            let speed = if k == 0 { "[20,500,5000,1000]" } else { "vCut" };
            writeln!(
                m,
                "MoveL [[{x:.3},{y:.3},{z:.3}],[0,0,1,0],[0,0,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]],{speed},z1,tSpindle\\WObj:=wTable;"
            )
            .expect("string");
        }
    }
    m.push_str(
        "MoveL [[0,220,50],[0,0,1,0],[0,0,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]],v200,fine,tSpindle\\WObj:=wTable;\n\
         ENDPROC\n\
         ENDMODULE\n",
    );
    m
}

#[test]
fn a_cam_milling_module_of_ten_thousand_targets_is_compensated_move_by_move() {
    let dir = tempfile::tempdir().expect("tempdir");
    let module = cam_milling_module();
    assert_eq!(
        compensate(dir.path(), "pocket.mod", &module, "none"),
        module,
        "identity"
    );
    let out = compensate(dir.path(), "pocket.mod", &module, "kinematic,gravity");
    // Only the targets change: every line keeps its place, and the speed,
    // zone, tool and work object of each move are as written.
    let (a, b): (Vec<&str>, Vec<&str>) = (module.lines().collect(), out.lines().collect());
    assert_eq!(a.len(), b.len());
    for (x, y) in a.iter().zip(&b) {
        if x.starts_with("MoveL [[") {
            let tail = |l: &str| l.rsplit_once("]]").map(|(_, t)| t.to_string());
            assert_eq!(tail(x), tail(y), "{y}");
        } else {
            assert_eq!(x, y);
        }
    }
    let m_in = parse_module(&module, "in").expect("input parses");
    let m_out = parse_module(&out, "out").expect("output parses");
    let robot = irb1600_with(215.5, 8.5, 90.0);
    let w_table = Isometry3::translation(650.0, 0.0, 300.0);
    let checked = assert_moves_land(&robot, &w_table, &m_in, &m_out);
    assert_eq!(checked, PASSES * POINTS_PER_PASS + 2);
}

/// Two fillet seams as an arc-welding cell runs them: approach with
/// `MoveJ`, each seam `ArcLStart` … `ArcL` … `ArcLEnd` with seam, weld and
/// weave data, a circular piece with `ArcC`, and a torch clean routine
/// between the seams that goes to a fixed station.
const WELD_MODULE: &str = "MODULE Weld_Bracket
  ! Bracket fillet welds, torch 350 A, 22 deg neck.
  PERS tooldata tTorch := [TRUE,[[0,0,410],[1,0,0,0]],[3.2,[0,0,160],[1,0,0,0],0,0,0]];
  PERS wobjdata wFixture := [FALSE,TRUE,\"\",[[700,20,420],[1,0,0,0]],[[0,0,0],[1,0,0,0]]];
  PERS seamdata sm1 := [0.5,0.5,[5,0,24,120,0,0,0,0,0],0.5,1,10,0,5,[5,0,24,120,0,0,0,0,0],0,1,[5,0,24,120,0,0,0,0,0],0,0,[0,0,0,0,0,0,0,0,0],0];
  PERS welddata wd1 := [10,0,[5,0,24,180,0,0,0,0,0],[0,0,0,0,0,0,0,0,0]];
  PERS weavedata wv1 := [1,0,3,4,0,0,0,0,0,0,0,0,0,0,0];
  CONST robtarget pHome := [[600,0,800],[0,0,1,0],[0,0,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
  CONST robtarget pS1App := [[20,20,60],[0,0.0871557,0.9961947,0],[0,0,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
  CONST robtarget pS1Start := [[20,20,2],[0,0.0871557,0.9961947,0],[0,0,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
  CONST robtarget pS1Mid := [[120,20,2],[0,0.0871557,0.9961947,0],[0,0,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
  CONST robtarget pS1Via := [[150,32,2],[0,0.0871557,0.9961947,0],[0,0,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
  CONST robtarget pS1Arc := [[162,62,2],[0,0.0871557,0.9961947,0],[0,0,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
  CONST robtarget pS1End := [[162,180,2],[0,0.0871557,0.9961947,0],[0,0,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
  CONST robtarget pS2Start := [[60,240,2],[0,0.0871557,0.9961947,0],[0,0,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
  CONST robtarget pS2End := [[220,240,2],[0,0.0871557,0.9961947,0],[0,0,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
  CONST robtarget pClean := [[450,350,600],[0,0,1,0],[0,0,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];

  PROC main()
    MoveJ pHome, v1000, z50, tTorch;
    MoveJ pS1App, v500, z10, tTorch\\WObj:=wFixture;
    ArcLStart pS1Start, v100, sm1, wd1, fine, tTorch\\WObj:=wFixture;
    ArcL pS1Mid, v20, sm1, wd1\\Weave:=wv1, z1, tTorch\\WObj:=wFixture;
    ArcC pS1Via, pS1Arc, v20, sm1, wd1\\Weave:=wv1, z1, tTorch\\WObj:=wFixture;
    ArcLEnd pS1End, v20, sm1, wd1, fine, tTorch\\WObj:=wFixture;
    CleanTorch;
    ArcLStart pS2Start, v100, sm1, wd1, fine, tTorch\\WObj:=wFixture;
    ArcLEnd pS2End, v20, sm1, wd1\\Weave:=wv1, fine, tTorch\\WObj:=wFixture;
    MoveJ pHome, v1000, fine, tTorch;
  ENDPROC

  PROC CleanTorch()
    MoveJ pClean, v1000, fine, tTorch;
    WaitTime 2;
  ENDPROC
ENDMODULE
";

#[test]
fn an_arc_welding_module_has_every_seam_target_compensated() {
    let dir = tempfile::tempdir().expect("tempdir");
    assert_eq!(
        compensate(dir.path(), "weld.mod", WELD_MODULE, "none"),
        WELD_MODULE,
        "identity"
    );
    let out = compensate(dir.path(), "weld.mod", WELD_MODULE, "kinematic,gravity");
    // The declarations of the targets change, nothing else: the moves, the
    // seam, weld and weave data, the routine calls are as written.
    assert_eq!(WELD_MODULE.lines().count(), out.lines().count(), "{out}");
    let changed: Vec<&str> = WELD_MODULE
        .lines()
        .zip(out.lines())
        .filter(|(x, y)| x != y)
        .map(|(x, _)| x.split(":=").next().unwrap_or("").trim())
        .collect();
    let targets = [
        "pHome", "pS1App", "pS1Start", "pS1Mid", "pS1Via", "pS1Arc", "pS1End", "pS2Start",
        "pS2End", "pClean",
    ];
    let want: Vec<String> = targets
        .iter()
        .map(|t| format!("CONST robtarget {t}"))
        .collect();
    assert_eq!(changed, want, "{out}");
    let m_in = parse_module(WELD_MODULE, "in").expect("input parses");
    let m_out = parse_module(&out, "out").expect("output parses");
    let robot = irb1600_with(410.0, 3.2, 160.0);
    let w_fixture = Isometry3::translation(700.0, 20.0, 420.0);
    for name in targets {
        let rt = |m: &Module| match m.decl(name).and_then(|d| d.value.clone()) {
            Some(DataValue::RobTarget(rt)) => rt,
            v => panic!("{name}: {v:?}"),
        };
        let (p_in, p_out) = (rt(&m_in), rt(&m_out));
        // pHome and pClean are in the base frame; the seam in the fixture.
        let wobj = if matches!(name, "pHome" | "pClean") {
            Isometry3::identity()
        } else {
            w_fixture
        };
        let programmed = wobj * pose(&p_in);
        let q = robot
            .ik_conf(&(wobj * pose(&p_out)), conf(&p_out))
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        let (dp, dr) = pose_error(
            &robot.predict(&MoveContext::default(), &q, KINEMATIC_GRAVITY),
            &programmed,
        );
        assert_abs_diff_eq!(dp.norm(), 0.0, epsilon = POS_TOL_MM);
        assert_abs_diff_eq!(dr.norm(), 0.0, epsilon = ROT_TOL_RAD);
    }
}

/// Runs `postproc [-v] compensate` of `input` on the IRB 1600 with
/// `effects`, no annotation, and, given, a window of `lines` lines at a
/// time; the bytes written and the standard error.
fn compensate_run(
    input: &std::path::Path,
    output: &std::path::Path,
    effects: &str,
    lines: Option<&str>,
) -> (Vec<u8>, String) {
    let mut cmd = postproc();
    if let Some(n) = lines {
        cmd.args(["-v", "compensate", "--rapid-window-lines", n]);
    } else {
        cmd.arg("compensate");
    }
    let out = cmd
        .arg(input)
        .arg("--machine")
        .arg(repo("machines/abb-irb1600.yaml"))
        .args(["--effects", effects, "--annotate", "none", "-o"])
        .arg(output)
        .output()
        .expect("runs");
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(out.status.code(), Some(0), "{err}");
    if let Some(n) = lines {
        let said = format!("read a window of {n} lines at a time");
        assert!(err.contains(&said), "{err}");
    }
    (std::fs::read(output).expect("output"), err)
}

/// A door-panel spot-welding cell as a servo-gun cell runs it: home and
/// approach with `MoveJ`, five spots with `SpotL`/`SpotJ` in the IRC5
/// SpotWare form (gun data, one with `\GunD`, spot data, one with
/// `\InPos`), a departure with `MoveL`, and back home.
const SPOT_MODULE: &str = "MODULE Spot_Door
  ! Door inner panel, servo gun G1, five spots.
  PERS tooldata tGun := [TRUE,[[0,0,350],[1,0,0,0]],[8,[0,0,150],[1,0,0,0],0,0,0]];
  PERS wobjdata wFixture := [FALSE,TRUE,\"\",[[700,20,420],[1,0,0,0]],[[0,0,0],[1,0,0,0]]];
  PERS spotdata spot10 := [10,1,1,0];
  PERS spotdata spot20 := [20,2,1,0];
  CONST robtarget pHome := [[600,0,800],[0,0,1,0],[0,0,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
  CONST robtarget pApp := [[40,40,80],[0,0,1,0],[0,0,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
  CONST robtarget pW1 := [[40,40,2],[0,0,1,0],[0,0,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
  CONST robtarget pW2 := [[100,40,2],[0,0,1,0],[0,0,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
  CONST robtarget pW3 := [[160,40,2],[0,0.0871557,0.9961947,0],[0,0,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
  CONST robtarget pW4 := [[160,120,2],[0,0.0871557,0.9961947,0],[0,0,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
  CONST robtarget pW5 := [[100,180,2],[0,0,1,0],[0,0,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
  CONST robtarget pDep := [[100,180,90],[0,0,1,0],[0,0,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];

  PROC main()
    MoveJ pHome, v1000, z50, tGun;
    MoveJ pApp, v1000, z20, tGun\\WObj:=wFixture;
    SpotL pW1, vmax, gun1, spot10, tGun\\WObj:=wFixture;
    SpotL pW2, vmax, gun1\\GunD:=gunDiag, spot10, tGun\\WObj:=wFixture;
    SpotL pW3, v1500, gun1, spot20\\InPos, tGun\\WObj:=wFixture;
    SpotJ pW4, vmax, gun1, spot20, tGun\\WObj:=wFixture;
    SpotL pW5, vmax, gun1, spot10, tGun\\WObj:=wFixture;
    MoveL pDep, v1000, z20, tGun\\WObj:=wFixture;
    MoveJ pHome, v1000, fine, tGun;
  ENDPROC
ENDMODULE
";

/// The targets of [`SPOT_MODULE`], in order, and whether each is in the
/// fixture (else in the base frame).
const SPOT_TARGETS: [(&str, bool); 8] = [
    ("pHome", false),
    ("pApp", true),
    ("pW1", true),
    ("pW2", true),
    ("pW3", true),
    ("pW4", true),
    ("pW5", true),
    ("pDep", true),
];

/// Every target declaration of `module` named in `targets` changed in
/// `out`, and nothing else.
fn assert_only_targets_changed(module: &str, out: &str, targets: &[&str]) {
    assert_eq!(module.lines().count(), out.lines().count(), "{out}");
    let changed: Vec<&str> = module
        .lines()
        .zip(out.lines())
        .filter(|(x, y)| x != y)
        .map(|(x, _)| x.split(":=").next().unwrap_or("").trim())
        .collect();
    let want: Vec<String> = targets
        .iter()
        .map(|t| format!("CONST robtarget {t}"))
        .collect();
    assert_eq!(changed, want, "{out}");
}

/// The declared target `name` of `m_out`, commanded, lands on the pose
/// `m_in` declares for it (in `wobj`), with the effects compensated.
fn assert_target_lands(
    robot: &Robot,
    wobj: &Isometry3<f64>,
    m_in: &Module,
    m_out: &Module,
    name: &str,
) {
    let rt = |m: &Module| match m.decl(name).and_then(|d| d.value.clone()) {
        Some(DataValue::RobTarget(rt)) => rt,
        v => panic!("{name}: {v:?}"),
    };
    let (p_in, p_out) = (rt(m_in), rt(m_out));
    assert_ne!(pose(&p_in), pose(&p_out), "{name} compensated");
    let programmed = wobj * pose(&p_in);
    let q = robot
        .ik_conf(&(wobj * pose(&p_out)), conf(&p_out))
        .unwrap_or_else(|e| panic!("{name}: {e}"));
    let (dp, dr) = pose_error(
        &robot.predict(&MoveContext::default(), &q, KINEMATIC_GRAVITY),
        &programmed,
    );
    assert_abs_diff_eq!(dp.norm(), 0.0, epsilon = POS_TOL_MM);
    assert_abs_diff_eq!(dr.norm(), 0.0, epsilon = ROT_TOL_RAD);
}

#[test]
fn a_spot_welding_module_has_every_spot_compensated() {
    let dir = tempfile::tempdir().expect("tempdir");
    let input = write(dir.path(), "spot.mod", SPOT_MODULE);
    let (none, _) = compensate_run(&input, &dir.path().join("none.mod"), "none", None);
    let none = text_without_header(&String::from_utf8(none).expect("utf-8"));
    assert_eq!(none, SPOT_MODULE, "identity");
    let whole = dir.path().join("whole.mod");
    let (bytes, err) = compensate_run(&input, &whole, "kinematic,gravity", None);
    // Nine moves (two of them to pHome), none left as written.
    assert!(err.contains("spot.mod → "), "{err}");
    assert!(
        err.contains(": 9 moves compensated, 0 targets added"),
        "{err}"
    );
    assert!(!err.contains("left as written"), "{err}");
    let out = text_without_header(&String::from_utf8(bytes.clone()).expect("utf-8"));
    // The declarations of the targets change, nothing else: the spot
    // instructions, their gun and spot data, the spotdata declarations.
    let names: Vec<&str> = SPOT_TARGETS.iter().map(|(n, _)| *n).collect();
    assert_only_targets_changed(SPOT_MODULE, &out, &names);
    let m_in = parse_module(SPOT_MODULE, "in").expect("input parses");
    let m_out = parse_module(&out, "out").expect("output parses");
    let kinds: Vec<&str> = m_in.moves().map(|mv| mv.name).collect();
    let want = [
        "MoveJ", "MoveJ", "SpotL", "SpotL", "SpotL", "SpotJ", "SpotL", "MoveL", "MoveJ",
    ];
    assert_eq!(kinds, want);
    let robot = irb1600_with(350.0, 8.0, 150.0);
    let w_fixture = Isometry3::translation(700.0, 20.0, 420.0);
    for (name, in_fixture) in SPOT_TARGETS {
        let wobj = if in_fixture {
            w_fixture
        } else {
            Isometry3::identity()
        };
        assert_target_lands(&robot, &wobj, &m_in, &m_out, name);
    }
    // Read a window at a time: the same bytes and the same summary.
    for lines in ["1", "3"] {
        let streamed = dir.path().join(format!("s{lines}.mod"));
        let (got, err) = compensate_run(&input, &streamed, "kinematic,gravity", Some(lines));
        assert!(
            err.contains(": 9 moves compensated, 0 targets added"),
            "{err}"
        );
        assert!(got == bytes, "{lines} lines");
    }
}

/// A cell of process instructions postproc has no confirmed argument
/// order for — painting, dispensing, the continuous application platform,
/// multi-gun spot welding, and a `SpotL` in the older SpotWare form —
/// between plain moves: the plain moves are compensated, each process
/// instruction is left as written, named with its line and reason, and
/// counted, and its target keeps its declared value.
const PROCESS_CELL: &str = "MODULE Process_Cell
  PERS tooldata tApp := [TRUE,[[0,0,250],[1,0,0,0]],[4,[0,0,100],[1,0,0,0],0,0,0]];
  PERS wobjdata wPart := [FALSE,TRUE,\"\",[[700,20,420],[1,0,0,0]],[[0,0,0],[1,0,0,0]]];
  CONST robtarget pHome := [[600,0,800],[0,0,1,0],[0,0,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
  CONST robtarget pApp := [[40,40,120],[0,0,1,0],[0,0,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
  CONST robtarget pStroke1 := [[40,40,60],[0,0,1,0],[0,0,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
  CONST robtarget pStroke2 := [[200,40,60],[0,0,1,0],[0,0,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
  CONST robtarget pArcVia := [[240,80,60],[0,0,1,0],[0,0,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
  CONST robtarget pArcEnd := [[200,120,60],[0,0,1,0],[0,0,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
  CONST robtarget pBead1 := [[40,160,5],[0,0,1,0],[0,0,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
  CONST robtarget pBead2 := [[200,160,5],[0,0,1,0],[0,0,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
  CONST robtarget pCap1 := [[40,200,5],[0,0,1,0],[0,0,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
  CONST robtarget pCapVia := [[120,220,5],[0,0,1,0],[0,0,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
  CONST robtarget pCap2 := [[200,200,5],[0,0,1,0],[0,0,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
  CONST robtarget pSpot := [[120,240,2],[0,0,1,0],[0,0,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
  CONST robtarget pDep := [[120,240,120],[0,0,1,0],[0,0,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];

  PROC main()
    MoveJ pHome, v1000, z50, tApp;
    MoveJ pApp, v1000, z20, tApp\\WObj:=wPart;
    PaintL pStroke1, v800, z10, tApp\\WObj:=wPart;
    PaintL pStroke2, v800, z10, tApp\\WObj:=wPart;
    PaintC pArcVia, pArcEnd, v800, z10, tApp\\WObj:=wPart;
    DispL \\On, pBead1, v250, bead1, z10, tApp\\WObj:=wPart;
    DispL \\Off, pBead2, v250, bead1, fine, tApp\\WObj:=wPart;
    CapL pCap1, v100, cd1, wsd1, cwd1, fine, tApp\\WObj:=wPart;
    CapC pCapVia, pCap2, v100, cd1, wsd1, cwd1, fine, tApp\\WObj:=wPart;
    SpotML pSpot, vmax, spot10, tApp\\WObj:=wPart;
    SpotL pSpot, vmax, spot10, tApp\\WObj:=wPart;
    MoveL pDep, v1000, z20, tApp\\WObj:=wPart;
    MoveJ pHome, v1000, fine, tApp;
  ENDPROC
ENDMODULE
";

#[test]
fn process_instructions_not_in_the_table_are_named_and_counted() {
    let dir = tempfile::tempdir().expect("tempdir");
    let input = write(dir.path(), "cell.mod", PROCESS_CELL);
    let (none, _) = compensate_run(&input, &dir.path().join("none.mod"), "none", None);
    let none = text_without_header(&String::from_utf8(none).expect("utf-8"));
    assert_eq!(none, PROCESS_CELL, "identity");
    let whole = dir.path().join("whole.mod");
    let (bytes, err) = compensate_run(&input, &whole, "kinematic,gravity", None);
    // Lines 21 to 29 hold the nine process instructions: each named with
    // its line and reason, all counted; the four plain moves compensated.
    let unknown = "left as written: not a motion instruction postproc knows";
    let other_form = "left as written: positional arguments not those of its row";
    let named = [
        (21, "PaintL", unknown),
        (22, "PaintL", unknown),
        (23, "PaintC", unknown),
        (24, "DispL", unknown),
        (25, "DispL", unknown),
        (26, "CapL", unknown),
        (27, "CapC", unknown),
        (28, "SpotML", unknown),
        (29, "SpotL", other_form),
    ];
    for (line, name, why) in named {
        let said = format!("cell.mod:{line}: {name} {why}");
        assert!(err.contains(&said), "{said}\n{err}");
    }
    let counted = ": 4 moves compensated, 9 left as written (not a motion instruction postproc knows (its robtarget is not compensated); positional arguments not those of its row of the motion table (its robtarget is not compensated)), 0 targets added";
    assert!(err.contains(counted), "{err}");
    let out = text_without_header(&String::from_utf8(bytes.clone()).expect("utf-8"));
    // Only the targets of the plain moves change; the process targets keep
    // their declared values and every instruction its text.
    assert_only_targets_changed(PROCESS_CELL, &out, &["pHome", "pApp", "pDep"]);
    let m_in = parse_module(PROCESS_CELL, "in").expect("input parses");
    let m_out = parse_module(&out, "out").expect("output parses");
    let kinds: Vec<&str> = m_in.moves().map(|mv| mv.name).collect();
    assert_eq!(kinds, ["MoveJ", "MoveJ", "MoveL", "MoveJ"]);
    let robot = irb1600_with(250.0, 4.0, 100.0);
    let w_part = Isometry3::translation(700.0, 20.0, 420.0);
    assert_target_lands(&robot, &Isometry3::identity(), &m_in, &m_out, "pHome");
    for name in ["pApp", "pDep"] {
        assert_target_lands(&robot, &w_part, &m_in, &m_out, name);
    }
    for lines in ["1", "4"] {
        let streamed = dir.path().join(format!("s{lines}.mod"));
        let (got, err) = compensate_run(&input, &streamed, "kinematic,gravity", Some(lines));
        assert!(err.contains(counted), "{lines}: {err}");
        for (line, name, why) in named {
            assert!(
                err.contains(&format!("cell.mod:{line}: {name} {why}")),
                "{err}"
            );
        }
        assert!(got == bytes, "{lines} lines");
    }
}
