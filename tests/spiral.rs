//! Arcs whose end lies off the circle of their start, read as the spiral
//! Fanuc and LinuxCNC move (grammar/gcode.md, "Arcs"): compensated through
//! the binary, then read back and predicted again along every written
//! piece by the forward pass (the interpreter and the predictor, not the
//! solver); each attained point lies within the tolerance of the
//! programmed spiral. The re-prediction is tests/repredict.rs's, shared with tests/cycles.rs.

use crate::common::{postproc, write};
pub(crate) use crate::repredict::job;
use postproc::machine::tool::MachineTool;
use postproc::pipeline::gcode::Job;
use postproc::predict::MoveContext;
use postproc::program::interp::{Motion, Move, Plan, PlanKind};

/// Floating-point allowance of the comparison with the tolerance, mm.
const FLOAT_MM: f64 = 1e-9;

/// A bundled machine, read from its file.
pub(crate) fn machine(name: &str) -> MachineTool {
    let text = crate::common::text(&format!("machines/{name}.yaml"));
    MachineTool::from_yaml_str(&text, "m.yaml").expect("machine")
}

/// Every block of `text` as the forward pass reads it: line, plan, context.
pub(crate) fn read(job: &Job, text: &str) -> Vec<(usize, Plan, MoveContext)> {
    crate::repredict::forward(job, text)
        .into_iter()
        .map(|r| (r.line, r.plan, r.ctx))
        .collect()
}

/// The worst miss of the written feed pieces of `output` from their
/// programmed paths ([`crate::repredict::misses`]), over the input lines
/// `want` gives a programmed move for, with that line and the number of
/// pieces checked.
pub(crate) fn worst_miss(
    job: &Job,
    input: &str,
    output: &str,
    want: &dyn Fn(usize) -> Option<Move>,
) -> (f64, usize, usize) {
    let (mut worst, mut at, mut pieces) = (0.0f64, 0, 0);
    for (src, _, miss) in crate::repredict::misses(job, input, output) {
        if want(src).is_none() {
            continue;
        }
        if miss > worst {
            (worst, at) = (miss, src);
        }
        pieces += 1;
    }
    (worst, at, pieces)
}

/// A Fanuc-style pocket finish with a quarter arc whose end lies 5 µm off
/// the circle of its start (radius 40 at the start, 40.005 at the end).
const SPIRAL_PROGRAM: &str = "\
%
O2001 (SPIRAL QUARTER)
G21 G17 G90 G94 G40 G49 G80
T1 M6
S8000 M3
G0 G54 X60. Y40.
G43 Z15. H1
G0 Z2.
G1 Z-1. F300.
G1 X100. F800.
G3 X140.005 Y80. I0. J40.
G1 Y120.
G0 Z15.
M30
%
";

#[test]
fn an_arc_with_a_5_micron_radius_mismatch_compensates_and_re_predicts_within_the_tolerance() {
    let m = machine("afm-r1000");
    for tol in [0.003, 0.001] {
        let dir = tempfile::tempdir().expect("tempdir");
        let input = write(dir.path(), "in.nc", SPIRAL_PROGRAM);
        let out = dir.path().join("out.nc");
        let run = postproc()
            .args([
                "compensate",
                "--machine",
                "afm-r1000",
                "--effects",
                "geometric",
            ])
            .args(["--tolerance", &tol.to_string()])
            .arg(&input)
            .arg("-o")
            .arg(&out)
            .output()
            .expect("runs");
        let stderr = String::from_utf8_lossy(&run.stderr);
        assert_eq!(run.status.code(), Some(0), "{stderr}");
        assert!(!stderr.contains("beyond the tolerance"), "{stderr}");
        let output = std::fs::read_to_string(&out).expect("output");
        let job = job(&m, "geometric", tol);
        let programmed = read(&job, SPIRAL_PROGRAM);
        let want = |line: usize| {
            programmed
                .iter()
                .find(|(l, p, _)| *l == line && p.kind == PlanKind::Motion)
                .and_then(|(_, p, _)| p.mv)
                .filter(|mv| mv.motion != Motion::Rapid)
        };
        // The arc is read as the spiral: 2.5 µm off the circle of its
        // start halfway along it.
        let arc = want(11).expect("the arc");
        let g = arc.arc.expect("arc geometry");
        let mid = g.radius_at(&arc.start3(), &arc.end3(), 0.5);
        assert!((mid - 40.0025).abs() < 1e-9, "{mid}");
        let (worst, line, pieces) = worst_miss(&job, SPIRAL_PROGRAM, &output, &want);
        assert!(pieces >= 4, "{pieces} pieces:\n{output}");
        assert!(
            worst <= tol + FLOAT_MM,
            "at {tol} mm: line {line} misses by {worst:.6} mm\n{output}"
        );
    }
}

#[test]
fn a_spiral_arc_is_written_byte_for_byte_without_effects() {
    let dir = tempfile::tempdir().expect("tempdir");
    let input = write(dir.path(), "in.nc", SPIRAL_PROGRAM);
    let out = dir.path().join("out.nc");
    postproc()
        .args(["compensate", "--machine", "afm-r1000", "--effects", "none"])
        .args(["--annotate", "none"])
        .arg(&input)
        .arg("-o")
        .arg(&out)
        .assert()
        .success();
    let written = std::fs::read(&out).expect("output");
    let body = crate::common::without_header(&written);
    assert_eq!(String::from_utf8_lossy(&body), SPIRAL_PROGRAM);
}
