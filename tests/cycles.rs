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
    let dir = tempfile::tempdir().expect("tempdir");
    let input = write(dir.path(), "deep.nc", DEEP);
    let out = dir.path().join("out.nc");
    let run = postproc()
        .args(["compensate", "--machine", "afm-r1000"])
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
