//! Deep canned-cycle holes (issue 41 item 4): one X and Y per hole tilts a
//! deep hole by the Z squareness. Without `--expand-cycles` such a hole is
//! warned about with its line and counted in the summary; with it the hole
//! is written as the cycle's moves, corrected along the depth, and every
//! written feed, read back and predicted by the forward pass (the sampler
//! of tests/spiral.rs), lies within the tolerance of the programmed hole.

use crate::common::{postproc, write};
use crate::spiral::{job, machine, read, worst_miss};
use postproc::program::interp::PlanKind;

/// A Fanuc-style deep-hole peck drilling program: an 87 mm G83 hole, a
/// second one at the same depth, then a shallow hole of the same cycle
/// (its one X and Y holds), and a G73 and a G82 hole with a dwell.
const DEEP: &str = "\
%
O1000 (DEEP HOLES)
G21 G17 G90 G94 G40 G49 G80
T1 M6
S2000 M3
G0 G54 X50. Y50.
G43 Z100. H1 M8
G99 G83 X50. Y50. Z-87. R2. Q10. F100.
X80.
Y80. Z-3.
G73 X50. Z-60. Q15.
G98 G82 X20. Y20. Z-70. P500
G80
G0 Z100. M9
M30
%
";

/// Compensates `DEEP` with `flags`; exit code, stderr and the output.
fn run(flags: &[&str]) -> (Option<i32>, String, String) {
    run_program(DEEP, &["--machine", "afm-r1000"], flags)
}

/// Compensates `program` (as deep.nc) on `machine` (its flags) with
/// `flags`; exit code, stderr and the output.
fn run_program(program: &str, machine: &[&str], flags: &[&str]) -> (Option<i32>, String, String) {
    let dir = tempfile::tempdir().expect("tempdir");
    let input = write(dir.path(), "deep.nc", program);
    let out = dir.path().join("out.nc");
    let run = postproc()
        .arg("compensate")
        .args(machine)
        .args(flags)
        .arg(&input)
        .arg("-o")
        .arg(&out)
        .output()
        .expect("runs");
    let output = std::fs::read_to_string(&out).unwrap_or_default();
    (
        run.status.code(),
        String::from_utf8_lossy(&run.stderr).to_string(),
        output,
    )
}

#[test]
fn a_deep_hole_drilled_at_one_x_and_y_is_warned_about_with_its_line() {
    let (code, stderr, output) = run(&["--effects", "geometric"]);
    assert_eq!(code, Some(1), "{stderr}");
    for line in [8, 9] {
        assert!(
            stderr.contains(&format!(
                "deep.nc:{line}: the hole, drilled at one X and Y, is predicted 0.005"
            )),
            "line {line}: {stderr}"
        );
    }
    // The shallow hole holds the tolerance with one X and Y.
    assert!(!stderr.contains("deep.nc:10: the hole"), "{stderr}");
    assert!(
        stderr.contains("blocks beyond the tolerance (max"),
        "{stderr}"
    );
    assert!(output.contains("G99 G83 X"), "{output}");
    assert!(!output.contains("\nG1 "), "{output}");
}

#[test]
fn with_expand_cycles_a_deep_hole_is_written_as_its_moves_within_the_tolerance() {
    let tol = 0.003;
    let (code, stderr, output) = run(&["--effects", "geometric", "--expand-cycles"]);
    assert_eq!(code, Some(0), "{stderr}\n{output}");
    assert!(!stderr.contains("beyond the tolerance"), "{stderr}");
    let lines: Vec<&str> = output.lines().collect();
    // The first hole: positioning, R level, ten pecks of 10 mm (each but
    // the last out to R and back to 0.254 mm above the depth), retract.
    let first = lines
        .iter()
        .position(|l| l.starts_with("G99 G0 X"))
        .expect("the first hole's positioning");
    assert!(lines[first].contains("F100."), "{output}");
    assert!(!lines[first].contains('Z'), "{output}");
    let feeds = lines.iter().filter(|l| l.starts_with("G1 ")).count();
    // Nine feeds in each 87 mm hole, five in the G73 hole, one in G82.
    assert!(feeds >= 24, "{feeds} feeds:\n{output}");
    // The shallow hole states its cycle again (the control has none after
    // the moves): G code, Z, R and the peck depth.
    let shallow = lines
        .iter()
        .find(|l| l.starts_with("G83 "))
        .expect("the shallow hole");
    assert!(
        shallow.contains(" Z-2.99") && shallow.contains(" R2.") && shallow.contains("Q10."),
        "{shallow}"
    );
    // The G82 hole's dwell is written as a G4 with the cycle's word.
    assert!(output.contains("\nG4 P500\n"), "{output}");
    // The feeds land within the tolerance of the programmed holes.
    let m = machine("afm-r1000");
    let job = job(&m, "geometric", tol);
    let programmed = read(&job, DEEP);
    let want = |line: usize| {
        programmed
            .iter()
            .find(|(l, p, _)| *l == line && matches!(p.kind, PlanKind::Cycle { .. }))
            .and_then(|(_, p, _)| p.mv)
    };
    let (worst, line, pieces) = worst_miss(&job, DEEP, &output, &want);
    assert!(pieces >= feeds, "{pieces} pieces checked of {feeds}");
    assert!(
        worst <= tol + 1e-9,
        "line {line} misses by {worst:.6} mm\n{output}"
    );
    // Read back, the expanded program ends where the input does.
    let back = read(&job, &output);
    let end = |r: &[(usize, postproc::program::interp::Plan, _)]| {
        r.iter().rev().find_map(|(_, p, _)| p.mv).map(|mv| mv.end)
    };
    let (a, b) = (end(&programmed).expect("end"), end(&back).expect("end"));
    assert!((0..3).all(|k| (a[k] - b[k]).abs() < 0.01), "{a:?} {b:?}");
}

#[test]
fn without_effects_the_cycles_are_written_byte_for_byte() {
    let (code, stderr, output) =
        run(&["--effects", "none", "--annotate", "none", "--expand-cycles"]);
    assert_eq!(code, Some(0), "{stderr}");
    let body = crate::common::without_header(output.as_bytes());
    assert_eq!(String::from_utf8_lossy(&body), DEEP);
}

/// Every written feed of `output` (compensated from `input` on afm-r1000,
/// geometric effects), read back and predicted by the forward pass, lies
/// within `tol` of its programmed path: the worst miss, its input line
/// and the number of pieces checked.
fn feeds_within(input: &str, output: &str, tol: f64) -> (f64, usize, usize) {
    let m = machine("afm-r1000");
    let job = job(&m, "geometric", tol);
    let (mut worst, mut at, mut pieces) = (0.0f64, 0, 0);
    for (src, _, miss) in crate::repredict::misses(&job, input, output) {
        if miss > worst {
            (worst, at) = (miss, src);
        }
        pieces += 1;
    }
    (worst, at, pieces)
}

/// The machine Z (commanded) at the end of every block of `text` that
/// moves, as the forward pass reads it, with its line.
fn ends(text: &str) -> Vec<(usize, [f64; 6])> {
    let m = machine("afm-r1000");
    let job = job(&m, "geometric", 0.003);
    read(&job, text)
        .into_iter()
        .filter_map(|(l, p, _)| p.mv.map(|mv| (l, mv.end)))
        .collect()
}

/// Issue 43: under G91 a G99 hole leaves the tool at the R level; the
/// moves after the cycle are incremental from there. Programmed: initial
/// level work Z100, R 5 below it (Z95), the last feed 10 further down:
/// work Z85.
const INCREMENTAL_G99: &str = "\
%
O1001 (G91 G99)
G21 G17 G90 G94 G40 G49 G80
T1 M6
S2000 M3
G0 G54 X50. Y50.
G43 Z100. H1
G91
G99 G81 X10. Y0. Z-20. R-5. F100.
G80
G0 X10.
G1 Z-10.
G90 G0 Z100.
M30
%
";

#[test]
fn an_incremental_g99_hole_leaves_the_written_program_at_its_r_level() {
    let tol = 0.003;
    let (code, stderr, output) = run_program(
        INCREMENTAL_G99,
        &["--machine", "afm-r1000"],
        &["--effects", "geometric"],
    );
    assert_eq!(code, Some(0), "{stderr}\n{output}");
    // The input, read: the last feed ends 15 mm below the initial level
    // (R −5, then Z −10), 20 mm right of the start.
    let programmed = ends(INCREMENTAL_G99);
    let start = programmed
        .iter()
        .find(|(l, _)| *l == 7)
        .map(|(_, e)| *e)
        .expect("line 7");
    let last_in = programmed
        .iter()
        .find(|(l, _)| *l == 12)
        .map(|(_, e)| *e)
        .expect("line 12");
    assert!((last_in[2] - (start[2] - 15.0)).abs() < 1e-9, "{last_in:?}");
    assert!((last_in[0] - (start[0] + 20.0)).abs() < 1e-9, "{last_in:?}");
    // The output, read back: the G1 after the cycle ends there (within
    // the compensation, far below the 5 mm of the R level).
    let back = ends(&output);
    let g1 = output
        .lines()
        .position(|l| l.starts_with("G1 ") && l.contains(" Z-10.0"))
        .expect("the feed")
        + 1;
    let last_out = back
        .iter()
        .find(|(l, _)| *l == g1)
        .map(|(_, e)| *e)
        .expect("the feed read back");
    assert!(
        (last_out[2] - last_in[2]).abs() < 0.05,
        "{last_out:?} {last_in:?}\n{output}"
    );
    let (worst, line, pieces) = feeds_within(INCREMENTAL_G99, &output, tol);
    assert!(pieces >= 2, "{pieces}");
    assert!(
        worst <= tol + 1e-9,
        "line {line} misses by {worst:.6} mm\n{output}"
    );
}

/// Issue 43: a G91 G98 hole pattern from high above the part: each hole's
/// R is measured from the initial level and Z from R, so each hole gets
/// its own corrected R and Z words.
const INCREMENTAL_PATTERN: &str = "\
%
O1002 (G91 G98 PATTERN)
G21 G17 G90 G94 G40 G49 G80
T1 M6
S2000 M3
G0 G54 X50. Y50.
G43 Z250. H1
G91 G98 G81 X20. Y0. Z-30. R-240. F100.
X20.
X20.
Y20.
X-20.
G80
G90 G0 Z250.
M30
%
";

#[test]
fn each_hole_of_an_incremental_pattern_is_corrected_within_the_tolerance() {
    let tol = 0.003;
    let (code, stderr, output) = run_program(
        INCREMENTAL_PATTERN,
        &["--machine", "afm-r1000"],
        &["--effects", "geometric"],
    );
    assert_eq!(code, Some(0), "{stderr}\n{output}");
    let (worst, line, pieces) = feeds_within(INCREMENTAL_PATTERN, &output, tol);
    assert!(pieces >= 5, "{pieces} pieces\n{output}");
    assert!(
        worst <= tol + 1e-9,
        "line {line} misses by {worst:.6} mm\n{output}"
    );
    // G98: back to the initial level after every hole; the program ends
    // where it is programmed to.
    let (a, b) = (ends(INCREMENTAL_PATTERN), ends(&output));
    let (a, b) = (a.last().expect("end").1, b.last().expect("end").1);
    assert!((0..3).all(|k| (a[k] - b[k]).abs() < 0.05), "{a:?} {b:?}");
}

/// The deep holes of `DEEP` in G91: the same holes, measured from the
/// initial level (work Z100) and from R.
const DEEP_INCREMENTAL: &str = "\
%
O1003 (DEEP G91)
G21 G17 G90 G94 G40 G49 G80
T1 M6
S2000 M3
G0 G54 X50. Y50.
G43 Z100. H1 M8
G91 G99 G83 X0. Y0. Z-89. R-98. Q10. F100.
X30.
Y30. Z-5.
G98 G81 X-30. Z-60.
G80
G90 G0 Z100. M9
M30
%
";

#[test]
fn incremental_deep_holes_are_written_as_moves_within_the_tolerance() {
    let tol = 0.003;
    let (code, stderr, output) = run_program(
        DEEP_INCREMENTAL,
        &["--machine", "afm-r1000"],
        &["--effects", "geometric", "--expand-cycles"],
    );
    assert_eq!(code, Some(0), "{stderr}\n{output}");
    assert!(
        output.lines().filter(|l| l.starts_with("G1 ")).count() >= 9,
        "{output}"
    );
    let (worst, line, pieces) = feeds_within(DEEP_INCREMENTAL, &output, tol);
    assert!(pieces >= 9, "{pieces} pieces\n{output}");
    assert!(
        worst <= tol + 1e-9,
        "line {line} misses by {worst:.6} mm\n{output}"
    );
    let (a, b) = (ends(DEEP_INCREMENTAL), ends(&output));
    let (a, b) = (a.last().expect("end").1, b.last().expect("end").1);
    assert!((0..3).all(|k| (a[k] - b[k]).abs() < 0.05), "{a:?} {b:?}");
}

/// afm-r1000's machine file with `output.expand_deep_holes_to_moves` set
/// to `value`, written into `dir`.
fn machine_with_key(dir: &std::path::Path, value: &str) -> std::path::PathBuf {
    let text = crate::common::text("machines/afm-r1000.yaml");
    let with = text.replacen(
        "output:\n  decimals_mm: 4\n",
        &format!("output:\n  decimals_mm: 4\n  expand_deep_holes_to_moves: {value}\n"),
        1,
    );
    assert_ne!(with, text, "the key is added");
    write(dir, "m.yaml", &with)
}

#[test]
fn the_machine_file_key_expands_deep_holes_as_the_flag_does() {
    let dir = tempfile::tempdir().expect("tempdir");
    let m = machine_with_key(dir.path(), "true");
    let m = m.to_str().expect("path");
    let (code, stderr, by_key) = run_program(DEEP, &["--machine", m], &["--effects", "geometric"]);
    assert_eq!(code, Some(0), "{stderr}");
    let (_, _, by_flag) = run(&["--effects", "geometric", "--expand-cycles"]);
    let body = |t: &str| crate::common::text_without_header(t);
    assert_eq!(body(&by_key), body(&by_flag));
    assert!(by_key.lines().any(|l| l.starts_with("G1 ")), "{by_key}");
    // false: as without the flag.
    let m = machine_with_key(dir.path(), "false");
    let m = m.to_str().expect("path");
    let (code, stderr, kept) = run_program(DEEP, &["--machine", m], &["--effects", "geometric"]);
    assert_eq!(code, Some(1), "{stderr}");
    assert!(
        stderr.contains("deep.nc:8: the hole, drilled at one X and Y"),
        "{stderr}"
    );
    assert!(!kept.lines().any(|l| l.starts_with("G1 ")), "{kept}");
}

#[test]
fn a_machine_file_key_that_is_not_true_or_false_is_refused_by_name() {
    let dir = tempfile::tempdir().expect("tempdir");
    for bad in ["3", "yes please", "[true]"] {
        let m = machine_with_key(dir.path(), bad);
        let m = m.to_str().expect("path");
        let (code, stderr, _) = run_program(DEEP, &["--machine", m], &["--effects", "geometric"]);
        assert_eq!(code, Some(2), "{bad}: {stderr}");
        assert!(
            stderr.contains("expand_deep_holes_to_moves"),
            "{bad}: {stderr}"
        );
    }
}

/// Deep holes of the cycles that are never written as moves: a tap (its
/// feed follows the spindle) and a bore with a spindle stop.
const DEEP_TAP: &str = "\
%
O1004 (DEEP TAP AND BORE)
G21 G17 G90 G94 G40 G49 G80
T1 M6
S200 M3
G0 G54 X50. Y50.
G43 Z100. H1 M8
G99 G84 X50. Y50. Z-87. R2. F300.
G86 X80. Z-87.
G80
G0 Z100. M9
M30
%
";

#[test]
fn deep_tapping_and_boring_holes_stay_cycles_and_are_warned_about_by_name() {
    let (code, stderr, output) = run_program(
        DEEP_TAP,
        &["--machine", "afm-r1000"],
        &["--effects", "geometric", "--expand-cycles"],
    );
    assert_eq!(code, Some(1), "{stderr}");
    assert!(
        stderr.contains(
            "deep.nc:8: the G84 tapping hole, drilled at one X and Y (a tap's feed follows the spindle: never written as moves), is predicted 0.00"
        ),
        "{stderr}"
    );
    assert!(
        stderr.contains("deep.nc:9: the G86 boring hole, drilled at one X and Y (the spindle stops at the bottom: never written as moves), is predicted 0.00"),
        "{stderr}"
    );
    assert!(output.contains("G99 G84 X"), "{output}");
    assert!(output.contains("\nG86 X"), "{output}");
    assert!(!output.lines().any(|l| l.starts_with("G1 ")), "{output}");
}
