//! Hand-derived goldens for machine-tool compensation, through the real
//! binary: a single geometric error at a time, the exact output expected by
//! a derivation written beside each test; then the accuracy of compensated
//! programs checked by re-interpreting the output against the model.

use approx::assert_abs_diff_eq;
use nalgebra::Vector3;
use postproc::machine::Machine;
use postproc::machine::tool::MachineTool;
use postproc::program::gcode::{Block, parse_line};
use postproc::program::interp::{DIRECTION_DEADBAND, Interpreter, Motion, Setup};

use crate::common::{postproc, repo, text_without_header};

/// Resolution of a 4-decimal output word, mm.
const WORD_TOL_MM: f64 = 0.00005;
/// Written moves shorter than this inside a split move are takeups (onto
/// a split point solved for the next piece's directions), mm: the pieces
/// of the moves checked here are tens of millimetres long.
const TAKEUP_LEN_MM: f64 = 0.02;
/// Requirement on every emitted point: attained within 0.1 µm of the program.
const POINT_TOL_MM: f64 = 0.0001;
/// Agreement of a compensated arc's sweep with the programmed one, rad:
/// corrections of a few microns at the ends of an 8 mm radius turn them by
/// well under 1e-3 rad.
const SWEEP_TOL_RAD: f64 = 1e-3;
/// Agreement of a whole turn cut into pieces with 2π, rad: the takeup
/// points between the pieces (microns) leave a few mrad unswept.
const TURN_TOL_RAD: f64 = 0.01;

/// A three-axis machine (X on Y on the table, Z on the column) with one
/// error block inserted into the axis named by `axis`.
fn machine_yaml(x_extra: &str, y_extra: &str, z_extra: &str) -> String {
    format!(
        "kind: machine_tool
name: golden
units_default: mm
axes:
  - name: X
    type: linear
    side: workpiece
    travel_mm: [-10, 1010]
    rapid_mm_per_min: 20000
{x_extra}
  - name: Y
    type: linear
    side: workpiece
    travel_mm: [-10, 510]
    rapid_mm_per_min: 20000
{y_extra}
  - name: Z
    type: linear
    side: tool
    travel_mm: [-10, 510]
    rapid_mm_per_min: 20000
{z_extra}
tools:
  1: {{ length_mm: 100.0 }}
work_offsets_mm:
  G54: [0.0, 0.0, 0.0]
output:
  decimals_mm: 4
"
    )
}

fn compensate(dir: &std::path::Path, machine: &str, program: &str) -> String {
    compensate_with(dir, machine, program, &["--annotate", "none"])
}

/// Runs `postproc compensate ARGS -o - --machine m.yaml p.nc` on `machine`
/// and `program` written to `dir`, whatever its exit code.
fn run_compensate(
    dir: &std::path::Path,
    machine: &str,
    program: &str,
    args: &[&str],
) -> std::process::Output {
    let m = dir.join("m.yaml");
    std::fs::write(&m, machine).unwrap();
    let p = dir.join("p.nc");
    std::fs::write(&p, program).unwrap();
    postproc()
        .arg("compensate")
        .args(args)
        .args(["-o", "-", "--machine"])
        .arg(&m)
        .arg(&p)
        .output()
        .unwrap()
}

/// [`compensate`] with `args` instead of `--annotate none`.
fn compensate_with(dir: &std::path::Path, machine: &str, program: &str, args: &[&str]) -> String {
    let out = run_compensate(dir, machine, program, args);
    assert!(
        out.status.code() == Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    text_without_header(&String::from_utf8(out.stdout).unwrap())
}

fn word(line: &str, letter: char) -> Option<f64> {
    let mut b = Block::default();
    parse_line(line.as_bytes(), 1, "t", &mut b).unwrap();
    b.word(letter as u8).map(|w| w.value)
}

#[test]
fn positioning_error_shifts_x_by_minus_exx() {
    // EXX(x) = 20 µm per 1000 mm, linear from 0: EXX(500) = 0.010 mm.
    // Attained x = c + EXX(c); we need c + 2e-5·c = 500 → c = 500/1.00002
    // = 499.99000 (to 0.1 µm): X shifted by −EXX(x).
    let dir = tempfile::tempdir().unwrap();
    let m = machine_yaml(
        "    component_errors:\n      EXX_um: { positions_mm: [0, 1000], forward: [0, 20] }",
        "",
        "",
    );
    let out = compensate(dir.path(), &m, "G0 X0 Y0 Z50\nG1 X500 F1000\n");
    let line = out.lines().nth(1).unwrap();
    assert_abs_diff_eq!(word(line, 'X').unwrap(), 499.99, epsilon = WORD_TOL_MM);
    // Y and Z carry no error: the block keeps its only word.
    assert_eq!(word(line, 'Y'), None);
}

#[test]
fn squareness_ec0y_shifts_x_by_angle_times_y() {
    // EC0Y = ε = 50 µrad tilts the Y axis about z: moving Y by y takes the
    // tool to x = −ε·y (a small rotation of (0, y, 0) about z gives
    // (−ε·y, y, 0)). The compensation adds ε·y to X: at y = 400,
    // 400 · 50e-6 = 0.0200 mm, so X100 → X100.02; Y changes only by
    // y·(1 − cos ε) ≈ 5e-7 mm, below a 4-decimal word.
    let dir = tempfile::tempdir().unwrap();
    let m = machine_yaml("", "    location_errors:\n      EC0Y_urad: 50", "");
    let out = compensate(dir.path(), &m, "G0 X0 Y0 Z50\nG1 X100 Y400 F1000\n");
    let line = out.lines().nth(1).unwrap();
    assert_abs_diff_eq!(word(line, 'X').unwrap(), 100.02, epsilon = WORD_TOL_MM);
    assert_abs_diff_eq!(word(line, 'Y').unwrap(), 400.0, epsilon = WORD_TOL_MM);
}

#[test]
fn z_pitch_with_tool_length_gives_abbe_shift() {
    // EBZ = ε = 100 µrad (pitch of the tool-side Z carriage) turns the
    // spindle about the gauge line; the tip sits L = 100 mm below it, so the
    // tip moves by ε × (0, 0, −L) = (−L·ε, 0, 0) = −0.0100 mm in x (the
    // Abbe error). The compensation commands X + L·ε: X200 → X200.01.
    // Without tool length compensation (G49, L = 0) there is no shift.
    let dir = tempfile::tempdir().unwrap();
    let m = machine_yaml(
        "",
        "",
        "    component_errors:\n      EBZ_urad: { positions_mm: [0, 500], forward: [100, 100] }",
    );
    let out = compensate(
        dir.path(),
        &m,
        "G0 X0 Y0 Z50\nG43 H1 Z40\nG1 X200 Y100 F1000\nG49 G0 Z60\nG1 X300\n",
    );
    // `G43 H1 Z40` positions Z only: X stays at X0, which was right without
    // the tool. With it the start X0 needs the same Abbe shift, so the feed
    // first takes up X0.01; after `G49 G0 Z60` X stands at 200.01, and the
    // next feed, without tool length, first takes up X200.
    let lines: Vec<&str> = out.lines().collect();
    assert_abs_diff_eq!(word(lines[2], 'X').unwrap(), 0.01, epsilon = WORD_TOL_MM);
    assert_abs_diff_eq!(word(lines[3], 'X').unwrap(), 200.01, epsilon = WORD_TOL_MM);
    assert_abs_diff_eq!(word(lines[5], 'X').unwrap(), 200.0, epsilon = WORD_TOL_MM);
    assert_abs_diff_eq!(word(lines[6], 'X').unwrap(), 300.0, epsilon = WORD_TOL_MM);
    assert_eq!(lines.len(), 7, "{out}");
}

#[test]
fn error_free_machine_changes_nothing() {
    // With every error zero the predicted pose is the nominal one, so the
    // compensated program is byte-identical (annotations off).
    let dir = tempfile::tempdir().unwrap();
    let m = machine_yaml("", "", "").replace("G54: [0.0, 0.0, 0.0]", "G54: [100.0, 100.0, 100.0]");
    let prog = std::fs::read_to_string(repo("samples/part.nc")).unwrap();
    let prog = prog.replace("H2", "H1").replace("H3", "H1");
    let out = compensate(dir.path(), &m, &prog);
    assert_eq!(out, prog);
}

/// Interprets a program and returns its moves (end point, dirs, motion, line).
fn moves(machine: &MachineTool, text: &str) -> Vec<(postproc::program::interp::Move, usize)> {
    let mut it = Interpreter::new(Setup::for_machine(machine), "t");
    let mut b = Block::default();
    let mut out = vec![];
    for (i, l) in text.lines().enumerate() {
        parse_line(l.as_bytes(), i + 1, "t", &mut b).unwrap();
        let plan = it.step(&b, l.as_bytes()).unwrap();
        if let Some(mv) = plan.mv {
            out.push((mv, i + 1));
        }
    }
    out
}

/// How far the point `p` (X, Y, Z; the other axes of `at`) of a
/// compensated arc lands off the programmed circle `parc`, with the
/// directions of motion `dirs`, mm.
fn off_circle(
    machine: &MachineTool,
    (at, p): (&[f64; 6], &Vector3<f64>),
    dirs: &[i8; 6],
    tool: f64,
    parc: &postproc::program::interp::ArcGeom,
) -> f64 {
    let mut c = *at;
    c[0] = p[0];
    c[1] = p[1];
    c[2] = p[2];
    let got = machine.geometric(&c, dirs, tool).pos;
    ((got[0] - parc.center[0]).hypot(got[1] - parc.center[1]) - parc.radius).abs()
}

/// The bundled AFM R-1000 example file: its text and the machine.
fn afm() -> (String, MachineTool) {
    let text = std::fs::read_to_string(repo("machines/afm-r1000.yaml")).unwrap();
    // These tests are written for the default tolerance of 1 µm, not the
    // file's own.
    let text = text.replace("compensation:\n  tolerance_mm: 0.003\n", "");
    let Machine::Tool(machine) = Machine::from_yaml_str(&text, "afm").unwrap() else {
        panic!("not a machine tool")
    };
    (text, machine)
}

fn dist_to_segment(p: &Vector3<f64>, a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
    let ab = b - a;
    let t = ((p - a).dot(&ab) / ab.norm_squared()).clamp(0.0, 1.0);
    (a + ab * t - p).norm()
}

#[test]
fn compensated_long_moves_stay_within_tolerance() {
    // The bundled AFM R-1000 example calibration; a long diagonal feed and a
    // long X feed that need splitting at 1 µm.
    let (text, machine) = afm();
    let dir = tempfile::tempdir().unwrap();
    let program = "G90 G54 G0 X-200 Y-100 Z20\nG43 H1 Z5\nG1 X500 Y300 Z-10 F2000\nX-240\n";
    // With annotations: a takeup point is marked.
    let out = compensate_with(dir.path(), &text, program, &[]);
    let lines: Vec<&str> = out.lines().collect();
    let programmed: Vec<Vector3<f64>> = moves(&machine, program)
        .iter()
        .map(|(m, _)| m.end3())
        .collect();
    let compensated = moves(&machine, &out);
    assert!(
        compensated.len() > programmed.len() + 2,
        "the long moves must be split:\n{out}"
    );
    let tool = machine.tool_length_mm(1).unwrap();
    let tolerance = 0.001;
    // Programmed moves: G0, G43 Z5, the diagonal feed and the X feed; the
    // feed paths run from move 1's end to move 2's and on to move 3's.
    let paths = [
        (programmed[1], programmed[2]),
        (programmed[2], programmed[3]),
    ];
    // Each written piece moves with the directions the interpreter reads
    // from the written program (docs/compensation.md, Directions of
    // motion): an axis the programmed move does not drive follows the
    // correction's drift where it moves more than the deadband.
    let dist = |c: &[f64; 6], dirs: &[i8; 6], tl: f64| -> f64 {
        (0..2)
            .map(|k| {
                let p = machine.geometric(c, dirs, tl).pos;
                dist_to_segment(&p, &paths[k].0, &paths[k].1)
            })
            .fold(f64::INFINITY, f64::min)
    };
    let linear: Vec<&(postproc::program::interp::Move, usize)> = compensated
        .iter()
        .filter(|(m, _)| m.motion == Motion::Linear)
        .collect();
    let mut checked = 0;
    let mut takeups = 0;
    let mut split_takeups = 0;
    for (i, (mv, line)) in linear.iter().enumerate() {
        let tl = if mv.tool_len_mm > 0.0 {
            mv.tool_len_mm
        } else {
            tool
        };
        // The move onto a takeup point is not along the programmed path: it
        // brings the machine onto the start of the piece after it, solved
        // for that piece's directions, with which its end is checked. The
        // block's own line names it; inside a split move it is the move of
        // microns where an axis reverses.
        let named = lines[line - 1].contains("takeup");
        let length = (mv.end3() - mv.start3()).norm();
        if named || length < TAKEUP_LEN_MM {
            let next = linear.get(i + 1).map_or(&mv.dirs, |(n, _)| &n.dirs);
            let d_end = dist(&mv.end, next, tl);
            assert!(
                d_end <= POINT_TOL_MM,
                "takeup point off the programmed path by {d_end} mm: {}\n{out}",
                lines[line - 1]
            );
            if named {
                takeups += 1;
            } else {
                split_takeups += 1;
            }
            continue;
        }
        let d_end = dist(&mv.end, &mv.dirs, tl);
        assert!(
            d_end <= POINT_TOL_MM,
            "emitted point off the programmed path by {d_end} mm: {}\n{out}",
            lines[line - 1]
        );
        // Sample the straight command between consecutive emitted points.
        for k in 1..10 {
            let t = k as f64 / 10.0;
            let mut c = mv.start;
            for (ci, (s, e)) in c.iter_mut().zip(mv.start.iter().zip(mv.end.iter())) {
                *ci = s + (e - s) * t;
            }
            let d = dist(&c, &mv.dirs, tl);
            assert!(
                d <= tolerance + POINT_TOL_MM,
                "gap {d} mm along a split move: {}\n{out}",
                lines[line - 1]
            );
        }
        checked += 1;
    }
    assert!(checked >= 4);
    // After the positioning `G43 H1 Z5` (X and Y stay where they were,
    // right without the tool) and where X reverses.
    assert_eq!(takeups, 2, "{out}");
    // Inside the X feed the correction's drift reverses Y and Z (the
    // example calibration's EYX and EZX bow over X): taken up at the split.
    assert!(split_takeups >= 1, "{out}");
    // The final point of each programmed move is reached exactly.
    let last = compensated.last().unwrap().0;
    let got = machine.geometric(&last.end, &last.dirs, tool).pos;
    assert!((got - programmed[3]).norm() <= POINT_TOL_MM);
}

#[test]
fn out_of_travel_is_an_error_naming_the_block_and_writes_nothing() {
    // A target at the travel limit whose compensation leaves the travel.
    let dir = tempfile::tempdir().unwrap();
    let m = machine_yaml(
        "    component_errors:\n      EXX_um: { positions_mm: [0, 1010], forward: [-50, -50] }",
        "",
        "",
    );
    std::fs::write(dir.path().join("m.yaml"), m).unwrap();
    std::fs::write(dir.path().join("p.nc"), "G0 X0 Y0 Z50\nG1 X1010 F100\n").unwrap();
    let out_path = dir.path().join("p.comp.nc");
    postproc()
        .args(["compensate", "--machine"])
        .arg(dir.path().join("m.yaml"))
        .arg(dir.path().join("p.nc"))
        .assert()
        .code(2)
        .stderr(predicates::str::contains(
            "p.nc:2:1: compensated X = 1010.0500 is outside the travel",
        ));
    assert!(!out_path.exists());
}

#[test]
fn tool_orientation_error_is_reported() {
    // A Z pitch EBZ = 100 µrad tilts the spindle, and with it the tool axis,
    // by 100 µrad; a three-axis machine cannot correct that, so the report
    // lists it (orient_urad) beside the corrected position.
    let dir = tempfile::tempdir().unwrap();
    let m = machine_yaml(
        "",
        "",
        "    component_errors:\n      EBZ_urad: { positions_mm: [0, 500], forward: [100, 100] }",
    );
    std::fs::write(dir.path().join("m.yaml"), m).unwrap();
    std::fs::write(
        dir.path().join("p.nc"),
        "G0 X0 Y0 Z50\nG43 H1 Z40\nG1 X200 Y100 F1000\n",
    )
    .unwrap();
    let out = postproc()
        .args(["report", "--format", "csv", "--machine"])
        .arg(dir.path().join("m.yaml"))
        .arg(dir.path().join("p.nc"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(0));
    let text = String::from_utf8(out.stdout).unwrap();
    let header: Vec<&str> = text.lines().next().unwrap().split(',').collect();
    let col = header
        .iter()
        .position(|h| *h == "orient_urad")
        .expect("orient_urad column");
    let feed = text
        .lines()
        .find(|l| l.starts_with("3,"))
        .expect("row of line 3");
    let value: f64 = feed.split(',').nth(col).unwrap().parse().unwrap();
    assert_abs_diff_eq!(value, 100.0, epsilon = 0.01);
}

#[test]
fn five_axis_sample_is_compensated_to_its_word_resolution() {
    // The AC trunnion example: every feed end point of the compensated
    // program, re-interpreted, reaches the programmed tool tip within
    // 0.0001 mm. Written with `--decimals 6` (X Y Z each word rounded by
    // at most 0.0005 µm; A/C by 0.0000005° = 8.7 nrad, at most 0.003 µm
    // per axis at a 300 mm lever arm; without it A/C keep the program's
    // decimals and as many more as the tolerance needs, which rounds by
    // more than this bound); the solve itself converges to far below that.
    const FIVE_AXIS_TOL_MM: f64 = 0.0001;
    let text = std::fs::read_to_string(repo("machines/five-axis-ac.yaml")).unwrap();
    let Machine::Tool(machine) = Machine::from_yaml_str(&text, "ac").unwrap() else {
        panic!("not a machine tool")
    };
    let program = std::fs::read_to_string(repo("samples/five-axis.nc")).unwrap();
    let out = postproc()
        .args([
            "compensate",
            "--annotate",
            "none",
            "--decimals",
            "6",
            "-o",
            "-",
        ])
        .arg("--machine")
        .arg(repo("machines/five-axis-ac.yaml"))
        .arg(repo("samples/five-axis.nc"))
        .output()
        .unwrap();
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let compensated = String::from_utf8(out.stdout).unwrap();
    let tool = machine.tool_length_mm(1).unwrap();
    let before = moves(&machine, &program);
    let after = moves(&machine, &compensated);
    // Original blocks keep their lines; added segment lines have no N word
    // and shift the numbering, so match programmed feed ends by position on
    // the path: each programmed feed end must be attained by some emitted end.
    let mut checked = 0;
    for (mv, _) in before.iter().filter(|(m, _)| m.motion == Motion::Linear) {
        let want = machine.nominal(&mv.end, tool).pos;
        let best = after
            .iter()
            .filter(|(m, _)| m.motion == Motion::Linear)
            .map(|(m, _)| (machine.geometric(&m.end, &m.dirs, tool).pos - want).norm())
            .fold(f64::INFINITY, f64::min);
        assert!(
            best <= FIVE_AXIS_TOL_MM,
            "programmed point {:?} missed by {best} mm",
            mv.end
        );
        checked += 1;
    }
    assert!(checked >= 5);
}

#[test]
fn clamped_component_table_is_warned_once() {
    // EXX is tabulated over 0..1000 mm; X1005 lies beyond it, so the end
    // value (20 µm) is used and the user is told once, not per block.
    let dir = tempfile::tempdir().unwrap();
    let m = machine_yaml(
        "    component_errors:\n      EXX_um: { positions_mm: [0, 1000], forward: [0, 20] }",
        "",
        "",
    );
    std::fs::write(dir.path().join("m.yaml"), m).unwrap();
    std::fs::write(
        dir.path().join("p.nc"),
        "G0 X0 Y0 Z50\nG1 X1005 F100\nX1006\nX500\n",
    )
    .unwrap();
    let out = postproc()
        .args(["compensate", "--annotate", "none", "-o", "-", "--machine"])
        .arg(dir.path().join("m.yaml"))
        .arg(dir.path().join("p.nc"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(0));
    let stderr = String::from_utf8(out.stderr).unwrap();
    assert_eq!(
        stderr.matches("outside its component-error tables").count(),
        1,
        "{stderr}"
    );
    assert!(
        stderr.contains("p.nc:2: X axis position 1005.000"),
        "{stderr}"
    );
    // Clamped at 20 µm: X1005 is commanded as 1004.98.
    let line = text_without_header(&String::from_utf8(out.stdout).unwrap())
        .lines()
        .nth(1)
        .unwrap()
        .to_string();
    assert_abs_diff_eq!(word(&line, 'X').unwrap(), 1004.98, epsilon = WORD_TOL_MM);
}

#[test]
fn regression_g99_cycle_leaves_the_tool_at_the_r_level() {
    // After a G99 hole the controller is at the R level, and the emitter
    // tracks it there: were it to keep the Z from before the cycle, the
    // next feed block without a Z word would get a spurious `Z3.` inserted
    // even on an error-free machine.
    let dir = tempfile::tempdir().unwrap();
    let m = machine_yaml("", "", "").replace("G54: [0.0, 0.0, 0.0]", "G54: [100.0, 100.0, 100.0]");
    let prog =
        "G90 G54 G0 X0 Y0 Z25\nG43 H1 Z20\nG99 G81 X10 Y10 Z-5 R3 F100\nX20\nG80\nG1 X30 F200\n";
    assert_eq!(compensate(dir.path(), &m, prog), prog);
}

/// Z backlash of 10 µm (EZZ reverse column +10 µm, forward 0): the tip is
/// 10 µm high wherever Z arrived moving down. A G99 hole's R level is solved
/// for the direction the machine arrives there: the first hole comes down
/// from Z25 (R 3 − 0.010 = 2.99), the next one comes up from the bottom of
/// the hole before (the forward column: R 3.000).
#[test]
fn g99_r_level_is_solved_for_the_direction_of_arrival() {
    let dir = tempfile::tempdir().unwrap();
    let m = machine_yaml(
        "",
        "",
        "    component_errors:\n      EZZ_um: { positions_mm: [-10, 510], forward: [0, 0], reverse: [10, 10] }",
    );
    let prog = "G90 G54 G0 X0 Y0 Z25\nG43 H1 Z20\nG99 G81 X10 Y10 Z-5 R3 F100\nX20 R3\nG80\n";
    let out = compensate(dir.path(), &m, prog);
    let lines: Vec<&str> = out.lines().collect();
    assert_abs_diff_eq!(word(lines[2], 'R').unwrap(), 2.99, epsilon = WORD_TOL_MM);
    assert_abs_diff_eq!(word(lines[3], 'R').unwrap(), 3.0, epsilon = WORD_TOL_MM);
    // Both hole bottoms are reached moving down: Z −5 − 0.010 (the second
    // block keeps the modal Z).
    assert_abs_diff_eq!(word(lines[2], 'Z').unwrap(), -5.01, epsilon = WORD_TOL_MM);
    assert_eq!(word(lines[3], 'Z'), None, "{out}");
}

/// One convention for an axis that has not moved yet: the G-code
/// interpreter starts every axis moving in +, and an observation row without
/// a `dir` cell (what `simulate`, `calibrate` and `diagnose` read) is
/// predicted the same way — the forward column (machines/README.md).
#[test]
fn an_axis_that_has_not_moved_uses_the_forward_column_everywhere() {
    use postproc::calibrate::forward;
    use postproc::calibrate::observations::{Observation, Pose, ToolPose};
    let m = machine_yaml(
        "",
        "    component_errors:\n      EYY_um: { positions_mm: [-10, 510], forward: [0, 0], reverse: [7, 7] }",
        "",
    );
    let Machine::Tool(tool) = Machine::from_yaml_str(&m, "m.yaml").unwrap() else {
        panic!("machine tool")
    };
    // Only X moves: Y and Z have not moved yet.
    let mv = moves(&tool, "G90 G1 X100 F500\n").pop().unwrap().0;
    assert_eq!(&mv.dirs[..3], &[1, 1, 1]);
    let by_gcode = tool.geometric(&mv.end, &mv.dirs, 100.0).pos;
    let row = Observation {
        line: 1,
        id: "p".into(),
        t_s: None,
        measured_mm: Vector3::zeros(),
        force_n: Vector3::zeros(),
        moment_nm: Vector3::zeros(),
        ambient_c: None,
        orientation: None,
        pose: Pose::Tool(ToolPose {
            xyz_mm: Vector3::new(mv.end[0], mv.end[1], mv.end[2]),
            abc_deg: [None; 3],
            dir: [Some(1), None, None, None, None, None],
            tool_mm: Some(100.0),
            spindle_rpm: None,
            spindle_w: None,
            p_w: [None; 6],
        }),
    };
    let by_row = forward::predict(&Machine::Tool(tool.clone()), &row, "o.csv")
        .unwrap()
        .attained_mm;
    assert_abs_diff_eq!(by_row, by_gcode, epsilon = 1e-12);
    // The reverse column would put y 7 µm off: the convention matters here.
    let mut rev = mv.dirs;
    rev[1] = -1;
    let other = tool.geometric(&mv.end, &rev, 100.0).pos;
    assert_abs_diff_eq!((other - by_gcode).y, 0.007, epsilon = 1e-9);
}

fn run_ok(args: &[&str]) -> Vec<u8> {
    let out = postproc().args(args).output().unwrap();
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    out.stdout
}

#[test]
fn output_is_the_same_for_one_and_two_threads() {
    let part = repo("samples/part.nc");
    let part = part.to_str().unwrap();
    let one = run_ok(&[
        "compensate",
        part,
        "--machine",
        "afm-r1000",
        "-o",
        "-",
        "--threads",
        "1",
    ]);
    let two = run_ok(&[
        "compensate",
        part,
        "--machine",
        "afm-r1000",
        "-o",
        "-",
        "--threads",
        "2",
    ]);
    assert!(one.len() > 1000);
    assert_eq!(one, two);
}

#[test]
fn gain_scales_the_correction_linearly() {
    // EXX = 20 µm/m: at X500 the full correction is −0.0100 mm; with
    // --gain geometric=0.5 the predicted error halves and so does the shift
    // (c = 500/1.00001 = 499.9950).
    let dir = tempfile::tempdir().unwrap();
    let m = machine_yaml(
        "    component_errors:\n      EXX_um: { positions_mm: [0, 1000], forward: [0, 20] }",
        "",
        "",
    );
    std::fs::write(dir.path().join("m.yaml"), m).unwrap();
    std::fs::write(dir.path().join("p.nc"), "G0 X0 Y0 Z50\nG1 X500 F1000\n").unwrap();
    let (m, p) = (dir.path().join("m.yaml"), dir.path().join("p.nc"));
    let out = run_ok(&[
        "compensate",
        p.to_str().unwrap(),
        "--machine",
        m.to_str().unwrap(),
        "-o",
        "-",
        "--gain",
        "geometric=0.5",
    ]);
    let text = text_without_header(&String::from_utf8(out).unwrap());
    let line = text.lines().nth(1).unwrap();
    assert_abs_diff_eq!(word(line, 'X').unwrap(), 499.995, epsilon = WORD_TOL_MM);
    assert!(line.ends_with("(dev 0.0050 mm geo 0.0050)"), "{line}");
}

#[test]
fn report_option_writes_a_csv_beside_the_program() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("part.comp.nc");
    let rep = dir.path().join("part.csv");
    let part = repo("samples/part.nc");
    run_ok(&[
        "compensate",
        part.to_str().unwrap(),
        "--machine",
        "afm-r1000",
        "-o",
        out.to_str().unwrap(),
        "--report",
        rep.to_str().unwrap(),
    ]);
    let csv = std::fs::read_to_string(rep).unwrap();
    // One header, 54 motion rows (as `check` counts them), the positions'
    // frame, the cutting-move headline, the summary line and the
    // provenance line.
    assert_eq!(csv.lines().count(), 1 + 54 + 1 + 1 + 1 + 1);
    assert!(
        csv.lines()
            .last()
            .unwrap()
            .starts_with("# provenance: postproc ")
    );
    assert!(csv.starts_with("line,motion,X_mm,Y_mm,Z_mm,dx_mm"));
    assert!(out.exists());
}

#[test]
fn work_offset_and_decimals_options_apply() {
    // An error-free machine: --work-offset moves machine coordinates only, so
    // the program text is unchanged; EXX makes X500 → 499.99 and --decimals 2
    // writes it with two decimals.
    let dir = tempfile::tempdir().unwrap();
    let m = machine_yaml(
        "    component_errors:\n      EXX_um: { positions_mm: [0, 1000], forward: [0, 20] }",
        "",
        "",
    );
    std::fs::write(dir.path().join("m.yaml"), m).unwrap();
    std::fs::write(dir.path().join("p.nc"), "G0 X0 Y0 Z50\nG1 X400 F1000\n").unwrap();
    let (m, p) = (dir.path().join("m.yaml"), dir.path().join("p.nc"));
    // With G54 X = 100 the target is machine X500: EXX(500) = 0.010 mm.
    let out = run_ok(&[
        "compensate",
        p.to_str().unwrap(),
        "--machine",
        m.to_str().unwrap(),
        "-o",
        "-",
        "--annotate",
        "none",
        "--work-offset",
        "G54=100,0,0",
        "--decimals",
        "2",
        // Two decimals round by up to 0.005 mm: within this tolerance only.
        "--tolerance",
        "0.005",
    ]);
    let text = text_without_header(&String::from_utf8(out).unwrap());
    assert_eq!(text.lines().nth(1).unwrap(), "G1 X399.99 F1000");
}

#[test]
fn regression_reversed_passes_start_on_the_programmed_path() {
    // Raster passes along X with short Y steps on the AFM R-1000: every pass
    // reverses X, and the direction-dependent errors change the correction
    // at the reversal by about 3.5 µm. The step's end is solved for the
    // step's own direction; a pass that left from there would run its first
    // piece up to that far off the programmed path (fading along the
    // piece), beyond the 1 µm tolerance. So a takeup point (the pass's
    // start solved for the new direction) comes first. Every other
    // straight piece is checked against the programmed move it belongs
    // to, with that move's directions of motion, at 20 points.
    let (text, machine) = afm();
    let dir = tempfile::tempdir().unwrap();
    let mut program = String::from("G90 G54 G0 X-200 Y-100 Z20\nG43 H1 Z5\nG1 X300 F2000\n");
    for k in 1..=6 {
        let x = if k % 2 == 1 { -200 } else { 300 };
        program += &format!("Y{:.1}\nX{x}\n", -100.0 + 0.1 * k as f64);
    }
    let out = compensate_with(dir.path(), &text, &program, &["--effects", "geometric"]);
    let programmed = moves(&machine, &program);
    let compensated = moves(&machine, &out);
    let lines: Vec<&str> = out.lines().collect();
    let tool = machine.tool_length_mm(1).unwrap();
    let tolerance = 0.001;
    // Each annotated line starts the next programmed move's commands.
    let mut owner = vec![usize::MAX; lines.len() + 1];
    let mut j = usize::MAX;
    for (i, l) in lines.iter().enumerate() {
        if l.contains("(dev ") {
            j = j.wrapping_add(1);
        }
        owner[i + 1] = j;
    }
    let mut x_takeup = Vec::new();
    let mut y_takeup = Vec::new();
    let mut takeups = 0;
    let mut checked = 0;
    for (i, (mv, line)) in compensated.iter().enumerate() {
        let (pm, _) = &programmed[owner[*line]];
        if pm.motion != Motion::Linear {
            continue;
        }
        if lines[line - 1].contains("takeup") {
            // The move onto the takeup point: the programmed start with the
            // new direction at its end.
            let next = compensated.get(i + 1).map_or(&pm.dirs, |(n, _)| &n.dirs);
            let got = machine.geometric(&mv.end, next, tool).pos;
            assert!(
                (got - pm.start3()).norm() <= POINT_TOL_MM,
                "{}",
                lines[line - 1]
            );
            if pm.end[0] != pm.start[0] {
                // In the written words' 0.1 µm steps.
                x_takeup.push(((mv.end[0] - mv.start[0]).abs() * 1e4).round() / 1e4);
                takeups += 1;
            } else {
                // A Y step after a pass that drifted Y back by more than
                // the deadband reverses Y: its takeup takes that up.
                y_takeup.push((mv.end[1] - mv.start[1]).abs());
            }
            continue;
        }
        for k in 0..=20 {
            let t = k as f64 / 20.0;
            let mut c = mv.start;
            for (ci, (s, e)) in c.iter_mut().zip(mv.start.iter().zip(mv.end.iter())) {
                *ci = s + (e - s) * t;
            }
            let got = machine.geometric(&c, &mv.dirs, tool).pos;
            let d = dist_to_segment(&got, &pm.start3(), &pm.end3());
            assert!(
                d <= tolerance + POINT_TOL_MM,
                "gap {d} mm at {t} of the piece ending on line {line}: {}",
                lines[line - 1]
            );
        }
        checked += 1;
    }
    // At each X reversal the takeup moves X by the AFM R-1000's reversal
    // difference there (3.4–3.6 µm in its example calibration), less or
    // more the 0.4 µm of X the Y step's takeup before it moved (the first
    // takeup follows the `G43` positioning instead).
    for x in &x_takeup[1..] {
        assert!((0.0030..=0.0040).contains(x), "{x_takeup:?}");
    }
    // Words added to the one-word step blocks (`Y-99.9`) keep the
    // program's spacing.
    for l in &lines {
        let code = l.split('(').next().unwrap_or("").as_bytes();
        assert!(
            !code
                .windows(2)
                .any(|w| w[0].is_ascii_digit() && b"XYZ".contains(&w[1])),
            "{l}"
        );
    }
    // Every X pass after the first reverses X, and the first feed starts
    // after `G43 H1 Z5`, which positions Z only: X and Y stay where they
    // were, right without the tool, not with it.
    assert_eq!(takeups, 7, "{out}");
    // A Y step gets a takeup only where Y really reverses.
    for y in &y_takeup {
        assert!(*y > DIRECTION_DEADBAND, "{y_takeup:?}\n{out}");
    }
    assert!(checked >= 18, "{checked} pieces\n{out}");
}

#[test]
fn regression_kept_arcs_after_a_reversal_start_on_the_programmed_path() {
    // Pocket corners on the AFM R-1000: a straight move, then a quarter arc
    // whose first motion reverses an axis (X at the first corner, Y at the
    // second). The arc's correction is uniform enough to keep it as an
    // arc, but the machine stands where the straight move's end was solved
    // for the straight move's direction: an arc leaving from there would
    // start about 3.5 µm off its programmed start, beyond the 1 µm
    // tolerance. So the block's own line moves straight to a takeup point
    // (the arc's start solved for its first directions of motion) and the
    // arc follows on an added line.
    let (text, machine) = afm();
    let dir = tempfile::tempdir().unwrap();
    let program = "G90 G54 G0 X-200 Y-100 Z20\nG43 H1 Z5\nG1 X100 F2000\nY0\n\
                   G3 X92 Y8 R8\nG1 X-100\nG3 X-108 Y0 I0 J-8\nG1 Y-92\n";
    let out = compensate_with(dir.path(), &text, program, &["--effects", "geometric"]);
    let lines: Vec<&str> = out.lines().collect();
    let programmed = moves(&machine, program);
    let compensated = moves(&machine, &out);
    let tool = machine.tool_length_mm(1).unwrap();
    let tolerance = 0.001;
    // The arcs as programmed (lines 5 and 7) and their first directions of
    // motion, read off the drawing: the first leaves (100, 0) up and to the
    // left (−X after +X), the second leaves (−100, 8) to the left and down
    // (−Y after +Y).
    let arcs = [(5, [-1, 1]), (7, [-1, -1])];
    let mut checked = 0;
    for (line, first_xy) in arcs {
        let Some((pm, _)) = programmed.iter().find(|(_, l)| *l == line) else {
            panic!("no move on line {line}")
        };
        let Some(parc) = pm.arc else {
            panic!("line {line} is not an arc")
        };
        let mut dirs = pm.dirs;
        dirs[0] = first_xy[0];
        dirs[1] = first_xy[1];
        // The block's own line: a straight move onto the takeup point.
        let own = lines
            .iter()
            .position(|l| {
                l.starts_with(if line == 5 { "G1 X99" } else { "G1 X-100" }) && l.contains("takeup")
            })
            .unwrap_or_else(|| panic!("no takeup for line {line}\n{out}"));
        let Some((takeup, _)) = compensated.iter().find(|(_, l)| *l == own + 1) else {
            panic!("no move on output line {}", own + 1)
        };
        assert_eq!(takeup.motion, Motion::Linear, "{}", lines[own]);
        let got = machine.geometric(&takeup.end, &dirs, tool).pos;
        assert!(
            (got - pm.start3()).norm() <= POINT_TOL_MM,
            "{} lands {} mm off",
            lines[own],
            (got - pm.start3()).norm()
        );
        // The takeup moves the machine by the jump of the correction at the
        // reversal, 2.6–3.5 µm here: how far off its start the arc would
        // begin without it.
        let step = (takeup.end3() - takeup.start3()).norm();
        assert!(
            (0.0026..=0.0035).contains(&step),
            "{step} mm: {}",
            lines[own]
        );
        // The added line: the arc itself, kept, from the takeup point.
        let Some((mv, _)) = compensated.iter().find(|(_, l)| *l == own + 2) else {
            panic!("no move on output line {}", own + 2)
        };
        let arc = mv
            .arc
            .unwrap_or_else(|| panic!("not an arc: {}", lines[own + 1]));
        assert_eq!(mv.motion, pm.motion, "{}", lines[own + 1]);
        // Every point of it lands on the programmed circle within the
        // tolerance (a quarter arc: its directions of motion do not change).
        for k in 0..=20 {
            let s = k as f64 / 20.0;
            let p = arc.point(&mv.start3(), &mv.end3(), s);
            let radial = off_circle(&machine, (&mv.end, &p), &dirs, tool, &parc);
            assert!(
                radial <= tolerance + POINT_TOL_MM,
                "{radial} mm off the circle at {s} of {}",
                lines[own + 1]
            );
        }
        checked += 1;
    }
    assert_eq!(checked, 2);
    // The added arc line follows the program's style: lower case, two-digit
    // motion codes, no spaces.
    let haas = "g90g54g0x-200y-100z20\ng43h1z5\ng01x100f2000\ny0\ng03x92y8r8p1\ng01x-100\n";
    let out = compensate_with(dir.path(), &text, haas, &["--effects", "geometric"]);
    let lines: Vec<&str> = out.lines().collect();
    let own = lines
        .iter()
        .position(|l| l.starts_with("g01x99") && l.contains("takeup"))
        .unwrap_or_else(|| panic!("no takeup\n{out}"));
    // The arc's words leave the straight line: r, and the turn count p1.
    let code = lines[own].split('(').next().unwrap_or_default();
    assert!(!code.contains('r') && !code.contains('p'), "{out}");
    assert!(lines[own + 1].starts_with("g03x91.9"), "{out}");
    assert!(lines[own + 1].contains("r7.9999"), "{out}");
    assert!(!lines[own + 1].contains(' '), "{out}");
}

#[test]
fn regression_lines_added_after_a_last_line_without_newline_stay_lines() {
    // A program whose last line has no line end, ending in a move that gets
    // a takeup point and added lines (a kept arc; a straight pass after a
    // reversal). Each added line starts with a newline and the file still
    // ends without one: glued to the last line (`… takeup)G3 X…`), the
    // added lines would make a block no controller reads as intended and
    // that `check` refuses (two motion codes in one block).
    let (text, _) = afm();
    let dir = tempfile::tempdir().unwrap();
    for (program, added) in [
        (
            "G90 G54 G0 X-200 Y-100 Z20\nG43 H1 Z5\nG1 X100 F2000\nY0\nG3 X92 Y8 R8",
            "G3 X",
        ),
        (
            "G90 G54 G0 X-200 Y-100 Z20\nG43 H1 Z5\nG1 X300 F2000\nY-99.9\nX-200",
            "X",
        ),
    ] {
        let out = compensate_with(dir.path(), &text, program, &["--effects", "geometric"]);
        assert!(!out.ends_with('\n'), "{out:?}");
        let lines: Vec<&str> = out.lines().collect();
        let Some(own) = lines.iter().rposition(|l| l.contains("(dev ")) else {
            panic!("{out}")
        };
        assert!(lines[own].ends_with("takeup)"), "{out}");
        assert!(own + 1 < lines.len(), "no added lines\n{out}");
        assert!(lines[own + 1].starts_with(added), "{out}");
        // The output reads back.
        let p = dir.path().join("out.nc");
        std::fs::write(&p, &out).unwrap();
        let m = dir.path().join("m.yaml");
        postproc()
            .args(["check", "--machine"])
            .arg(&m)
            .arg(&p)
            .assert()
            .success();
    }
}

#[test]
fn regression_half_turns_given_by_r_keep_their_centre() {
    // A half circle written with `R8`, compensated. The centre an R word
    // gives sits on the chord's bisector at sqrt(R² − (c/2)²): near a half
    // turn that distance changes by R/h times any change of R, so the
    // rounded mean radius of a compensated arc would put the centre tens of
    // µm off, far beyond the tolerance. Such an arc is therefore written
    // with I and J. Checked with the takeup point's added arc line
    // (5 µm) and with the block's own line (20 µm, no takeup): every point
    // of the arc as written lands on the programmed circle within the
    // tolerance, with the direction of motion at that point.
    let (text, machine) = afm();
    let dir = tempfile::tempdir().unwrap();
    let program =
        "G90 G54 G0 X200 Y0 Z20\nG43 H1 Z5\nG1 X150 F2000\nX100\nG3 X100 Y-16 R8\nG1 X200\n";
    let programmed = moves(&machine, program);
    let Some((pm, _)) = programmed.iter().find(|(_, l)| *l == 5) else {
        panic!("no arc")
    };
    let parc = pm.arc.unwrap();
    let tool = machine.tool_length_mm(1).unwrap();
    for tolerance in [0.005, 0.02] {
        let out = compensate_with(
            dir.path(),
            &text,
            program,
            &[
                "--effects",
                "geometric",
                "--tolerance",
                &tolerance.to_string(),
            ],
        );
        let lines: Vec<&str> = out.lines().collect();
        let compensated = moves(&machine, &out);
        // The arc as written: whole, or cut where X reverses.
        let pieces: Vec<_> = compensated
            .iter()
            .filter(|(m, _)| m.motion == Motion::ArcCcw)
            .collect();
        assert!(!pieces.is_empty(), "no arc in\n{out}");
        let swept: f64 = pieces.iter().map(|(m, _)| m.arc.unwrap().sweep).sum();
        assert!(
            (swept - std::f64::consts::PI).abs() < SWEEP_TOL_RAD,
            "{swept}\n{out}"
        );
        for (mv, line) in pieces {
            let arc_line = lines[line - 1];
            let arc = mv.arc.unwrap();
            // Near a half turn the centre goes in I and J (the radius check
            // below also fails with the R word kept: 7 µm off the circle at
            // 5 µm tolerance).
            if (arc.sweep / 2.0).cos().abs() * 10.0 < 1.0 {
                assert!(!arc_line.contains('R') && arc_line.contains('I'), "{out}");
            }
            assert!(!arc_line.contains("takeup"), "{out}");
            for k in 0..=40 {
                let s = k as f64 / 40.0;
                let p = arc.point(&mv.start3(), &mv.end3(), s);
                let t = arc.tangent(&mv.start3(), &mv.end3(), s.clamp(1e-6, 1.0 - 1e-6));
                let mut dirs = pm.dirs;
                for i in 0..2 {
                    if t[i].abs() > 1e-9 {
                        dirs[i] = if t[i] > 0.0 { 1 } else { -1 };
                    }
                }
                let radial = off_circle(&machine, (&mv.end, &p), &dirs, tool, &parc);
                assert!(
                    radial <= tolerance + POINT_TOL_MM,
                    "{radial} mm off the circle at {s} of {arc_line} (tolerance {tolerance})"
                );
            }
        }
    }
}

#[test]
fn regression_lines_added_to_a_block_delete_block_are_skipped_with_it() {
    // A `/` block that gets added lines: a kept arc after a reversal (its
    // takeup point on the block's line, the arc on an added line) and a
    // straight move split into pieces. With the block-delete switch on,
    // the controller skips the `/` lines, so the added lines carry the `/`
    // too: without it the controller would skip the takeup but cut the arc
    // (or the rest of the pieces) anyway.
    let (text, _) = afm();
    let dir = tempfile::tempdir().unwrap();
    let program = "G90 G54 G0 X-200 Y-100 Z20\nG43 H1 Z5\nG1 X100 F2000\nY0\n\
                   /G3 X92 Y8 R8\n/G1 X-200 Y300 Z-10\nG1 X-150\n";
    let out = compensate_with(dir.path(), &text, program, &["--effects", "geometric"]);
    let lines: Vec<&str> = out.lines().collect();
    // Each block's lines: from its annotated line to the next one.
    let block_of = |start: &str| -> Vec<&str> {
        let Some(i) = lines.iter().position(|l| l.starts_with(start)) else {
            panic!("no `{start}` line\n{out}")
        };
        let n = lines[i + 1..]
            .iter()
            .position(|l| l.contains("(dev "))
            .unwrap_or(lines.len() - i - 1);
        lines[i..=i + n].to_vec()
    };
    let arc = block_of("/G1 X99.98");
    assert_eq!(arc.len(), 2, "{out}");
    assert!(
        arc[0].contains("takeup") && arc[1].starts_with("/G3 X91.98"),
        "{out}"
    );
    let pieces = block_of("/G1 X-");
    assert!(pieces.len() >= 2, "{out}");
    assert!(pieces.iter().all(|l| l.starts_with('/')), "{out}");
    // The block after them is not deleted, nor are its added lines.
    let Some(last) = lines.iter().rposition(|l| l.contains("(dev ")) else {
        panic!("{out}")
    };
    assert!(lines[last..].iter().all(|l| !l.starts_with('/')), "{out}");
    assert_eq!(lines[last - 1], *pieces.last().unwrap_or(&""));
}

#[test]
fn regression_no_takeups_under_cutter_compensation_and_the_gap_is_reported() {
    // Raster passes with G41 active, then G40 on a pass. Under cutter radius
    // compensation no takeup point is written (a move of microns against
    // the direction of travel upsets the controller's offset path), not
    // on the G40 block either, which still moves with the offset. What the
    // takeups would have removed (3–4 µm at 1 µm tolerance) is left, so
    // the run ends with exit code 1 and a warning that names the line.
    let (text, _) = afm();
    let dir = tempfile::tempdir().unwrap();
    let out = run_compensate(
        dir.path(),
        &text,
        "G90 G54 G0 X10 Y10 Z10\nG43 H1 Z5\nG41 D1 G1 X400 F1000\nY20\nX10\nG40 X400\nY30\nX10\nM30\n",
        &[],
    );
    assert_eq!(out.status.code(), Some(1));
    let stdout = text_without_header(&String::from_utf8(out.stdout).unwrap());
    let stderr = String::from_utf8(out.stderr).unwrap();
    let takeups: Vec<&str> = stdout.lines().filter(|l| l.contains("takeup")).collect();
    assert!(!takeups.is_empty(), "{stdout}");
    // The G40 block reverses X but has no takeup; the takeups are on the
    // reversals after it (the first on Y30's start, after the X
    // reversal), none before it.
    let lines: Vec<&str> = stdout.lines().collect();
    let g40 = lines.iter().position(|l| l.starts_with("G40")).unwrap();
    assert!(!lines[g40].contains("takeup"), "{stdout}");
    assert!(
        lines[..=g40].iter().all(|l| !l.contains("takeup")),
        "{stdout}"
    );
    assert!(takeups[0].starts_with("X399.98"), "{stdout}");
    assert!(stderr.contains("no takeup points are written"), "{stderr}");
    // The G41 block itself leaves with the gap: named with the miss of its
    // pieces from there, and the largest left over is summed up.
    assert!(
        stderr.contains("p.nc:3: a written piece of this block is predicted 0.00")
            && stderr.contains("beyond the tolerance 0.001 mm"),
        "{stderr}"
    );
    assert!(
        stderr.contains("the compensated program is still 0.00")
            && stderr.contains("more than the tolerance 0.001 mm"),
        "{stderr}"
    );
}

#[test]
fn regression_full_turns_that_do_not_close_are_written_as_arcs_that_go_round() {
    // A full circle (`G2 I0 J-8`, start = end) entered moving −X and left
    // moving −X after it: the machine stands where the entry's end was
    // solved for −X, the circle's end is solved for +X (its direction of
    // motion there), microns apart. At a tolerance loose enough for the
    // correction to count as uniform, kept as one arc it would run between
    // those two points, which a controller reads as an arc of almost
    // nothing (or almost a full turn). Through the binary: the block is
    // cut where its axes reverse into arcs of less than a half turn that go
    // round once clockwise, every point of them on the programmed circle
    // within the tolerance. Entered moving +X, its start and end are the
    // same command and it stays a full circle (`G2` with I and J, no end
    // words).
    let (text, machine) = afm();
    let dir = tempfile::tempdir().unwrap();
    let tolerance = 0.05;
    let args = [
        "--effects",
        "geometric",
        "--tolerance",
        "0.05",
        "--annotate",
        "none",
    ];
    let open = "G90 G54 G0 X200 Y100 Z20\nG43 H1 Z5\nG1 X150 F1000\nX100\nG2 I0 J-8\nG1 X50\n";
    let programmed = moves(&machine, open);
    let Some((pm, _)) = programmed.iter().find(|(m, _)| m.arc.is_some()) else {
        panic!("no arc")
    };
    let parc = pm.arc.unwrap();
    let tool = machine.tool_length_mm(1).unwrap();
    let out = compensate_with(dir.path(), &text, open, &args);
    let compensated = moves(&machine, &out);
    // The pieces: every move from the arc block's line up to the last
    // block's (the `G1 X50`, the last move).
    let pieces: Vec<_> = compensated
        .iter()
        .filter(|(_, l)| *l >= 5)
        .map(|(m, _)| m)
        .collect();
    let pieces = &pieces[..pieces.len() - 1];
    assert!(pieces.len() >= 4, "{} pieces\n{out}", pieces.len());
    let mut turned = 0.0;
    for mv in pieces {
        let Some(arc) = mv.arc else {
            // A takeup point where an axis reverses: microns long.
            assert!((mv.end3() - mv.start3()).norm() < 0.02, "{out}");
            continue;
        };
        assert_eq!(mv.motion, Motion::ArcCw, "{out}");
        assert!(arc.sweep.abs() < std::f64::consts::PI, "{out}");
        turned += arc.sweep;
        for k in 0..=20 {
            let s = k as f64 / 20.0;
            let p = arc.point(&mv.start3(), &mv.end3(), s);
            let t = arc.tangent(&mv.start3(), &mv.end3(), s.clamp(1e-6, 1.0 - 1e-6));
            let mut dirs = pm.dirs;
            for i in 0..2 {
                if t[i].abs() > 1e-9 {
                    dirs[i] = if t[i] > 0.0 { 1 } else { -1 };
                }
            }
            let radial = off_circle(&machine, (&mv.end, &p), &dirs, tool, &parc);
            assert!(
                radial <= tolerance + POINT_TOL_MM,
                "{radial} mm off the circle at {p:?}\n{out}"
            );
        }
    }
    // Clockwise once round.
    assert!(
        (turned + std::f64::consts::TAU).abs() < TURN_TOL_RAD,
        "turned {turned} rad\n{out}"
    );
    let closed = "G90 G54 G0 X0 Y100 Z20\nG43 H1 Z5\nG1 X50 F1000\nX100\nG2 I0 J-8\nG1 X150\n";
    let out = compensate_with(dir.path(), &text, closed, &args);
    let Some(arc_line) = out.lines().find(|l| l.contains("G2")) else {
        panic!("the closed circle is not an arc\n{out}")
    };
    assert!(
        arc_line.contains('I') && arc_line.contains('J') && !arc_line.contains('X'),
        "{out}"
    );
}

#[test]
fn regression_a_move_after_a_machine_coordinate_retract_starts_where_the_machine_stands() {
    // `G53 Z400` sends Z to a machine position, uncompensated; X and Y
    // stay where the line before left them (solved at Z 5). The feed move
    // after it needs X, Y and Z solved at its own start: its line becomes
    // a takeup point onto that start (attained within the words' rounding
    // of the programmed start) and the move follows on an added line.
    // The machine does not stand on the move's compensated start after a
    // G28/G53, so writing the move as if it did would start it microns off.
    let (text, machine) = afm();
    let dir = tempfile::tempdir().unwrap();
    let program = "G90 G54 G0 X200 Y100 Z20\nG43 H1 Z5\nG1 X300 F1000\nG53 Z400\nG1 X250\n";
    let programmed = moves(&machine, program);
    let Some((pm, _)) = programmed.iter().find(|(_, l)| *l == 5) else {
        panic!("no move on line 5")
    };
    let out = compensate_with(dir.path(), &text, program, &["--effects", "geometric"]);
    let lines: Vec<&str> = out.lines().collect();
    assert_eq!(lines.len(), 7, "{out}");
    assert_eq!(lines[4], "G53 Z400", "{out}");
    assert!(lines[5].contains("takeup"), "{out}");
    let compensated = moves(&machine, &out);
    let at_line = |n: usize| {
        compensated
            .iter()
            .find(|(_, l)| *l == n)
            .map(|(m, _)| *m)
            .unwrap_or_else(|| panic!("no move on line {n} of\n{out}"))
    };
    let (stood, takeup) = (at_line(4), at_line(6));
    let tool = machine.tool_length_mm(1).unwrap();
    let at = machine.geometric(&takeup.end, &takeup.dirs, tool).pos;
    let off = (0..3)
        .map(|i| (at[i] - pm.start[i]).powi(2))
        .sum::<f64>()
        .sqrt();
    assert!(off <= WORD_TOL_MM * 3f64.sqrt(), "{off} mm off\n{out}");
    // The takeup moves X by microns from where the line before left it.
    assert!((takeup.end[0] - stood.end[0]).abs() > 0.005, "{out}");
    // The move itself follows, to its compensated end.
    let end = machine
        .geometric(&at_line(7).end, &at_line(7).dirs, tool)
        .pos;
    let off = (0..3)
        .map(|i| (end[i] - pm.end[i]).powi(2))
        .sum::<f64>()
        .sqrt();
    assert!(
        off <= WORD_TOL_MM * 3f64.sqrt(),
        "{off} mm off at the end\n{out}"
    );
}

#[test]
fn regression_incremental_moves_after_a_machine_coordinate_retract_count_from_where_the_machine_stands()
 {
    // After `G53 Z400` only the axes G53 names are taken as standing at
    // their uncompensated command; the others keep their compensated
    // position, from which a following G91 move's increments count. Taking
    // every axis as moved would put the machine microns beside the point
    // the same program reaches written in G90. The two programs command the
    // same positions (re-interpreted, to the rounding of the words).
    let (text, machine) = afm();
    let dir = tempfile::tempdir().unwrap();
    let head = "G54 G0 X10 Y10\nG43 H1 Z20\nG1 X50 F1000\nG53 Z400.\n";
    let absolute = format!("{head}G1 X60.\nY30.\n");
    let incremental = format!("{head}G91 G1 X10.\nY20.\nG90\n");
    let args = ["--effects", "geometric"];
    let a = moves(
        &machine,
        &compensate_with(dir.path(), &text, &absolute, &args),
    );
    let i = moves(
        &machine,
        &compensate_with(dir.path(), &text, &incremental, &args),
    );
    assert_eq!(a.len(), i.len());
    assert!(a.len() >= 7, "{} moves", a.len());
    for ((ma, la), (mi, _)) in a.iter().zip(&i) {
        for s in 0..3 {
            assert!(
                (ma.end[s] - mi.end[s]).abs() <= 2.0 * WORD_TOL_MM,
                "line {la}, axis {s}: {} (G90) against {} (G91)",
                ma.end[s],
                mi.end[s]
            );
        }
    }
}

#[test]
fn regression_no_takeup_point_beyond_the_end_of_travel() {
    // `G28 Z0` leaves Z at the top of its travel (500 mm, uncompensated);
    // the feed down from there needs its start 11 µm higher, beyond the
    // travel, so no takeup point is written there (it would fail the run
    // with "outside the travel"): the move starts where the machine stands
    // and the gap is reported: exit code 1, a warning naming the line.
    let (text, _) = afm();
    let dir = tempfile::tempdir().unwrap();
    let out = run_compensate(
        dir.path(),
        &text,
        "G90 G0 X10 Y10 Z100\nG91 G28 Z0\nG90\nG0 X80 Y40\nG1 Z10 F900\nG1 X100\n",
        &[],
    );
    let stdout = text_without_header(&String::from_utf8_lossy(&out.stdout));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("p.nc:5: the compensated program is still"),
        "{stderr}"
    );
    let line5 = stdout.lines().nth(4).unwrap_or("");
    assert!(
        line5.starts_with("G1 ") && !line5.contains("takeup"),
        "{stdout}"
    );
}
