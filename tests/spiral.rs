//! Arcs whose end lies off the circle of their start, read as the spiral
//! Fanuc and LinuxCNC move (grammar/gcode.md, "Arcs"): compensated through
//! the binary, then read back and predicted again along every written
//! piece by the forward pass (the interpreter and the predictor, not the
//! solver); each attained point lies within the tolerance of the
//! programmed spiral. The sampler here is shared with tests/cycles.rs.

use crate::common::{postproc, write};
use postproc::machine::tool::MachineTool;
use postproc::pipeline::gcode::Job;
use postproc::predict::{EffectSet, MoveContext, ToolPredictor};
use postproc::program::interp::{Motion, Move, Plan, PlanKind, Setup};

/// Sample spacing along a written piece, mm.
const SAMPLE_MM: f64 = 0.1;
/// Fewest samples of one written piece.
const MIN_SAMPLES: usize = 16;
/// Points of the programmed path searched before the search is refined.
const COARSE_POINTS: usize = 400;
/// Halvings of the bracket around the nearest coarse point.
const REFINE_STEPS: usize = 60;
/// Floating-point allowance of the comparison with the tolerance, mm.
const FLOAT_MM: f64 = 1e-9;

/// The forward pass of `machine` (bundled name) with `effects` at `tol`.
pub(crate) fn job<'a>(machine: &'a MachineTool, effects: &str, tol: f64) -> Job<'a> {
    let effects = EffectSet::from_flags(
        &effects.parse().expect("effects"),
        &[],
        postproc::predict::MachineKind::Tool,
    )
    .expect("effects");
    Job {
        predictor: Some(ToolPredictor::new(machine, effects)),
        setup: Setup::for_machine(machine),
        settings: postproc::compensate::Settings { tolerance_mm: tol },
        emit: postproc::emit::gcode::EmitOptions {
            decimals_mm: None,
            decimals_deg: None,
            annotate: true,
        },
        pool: None,
        travel: None,
    }
}

/// A bundled machine, read from its file.
pub(crate) fn machine(name: &str) -> MachineTool {
    let text = crate::common::text(&format!("machines/{name}.yaml"));
    MachineTool::from_yaml_str(&text, "m.yaml").expect("machine")
}

/// Every block of `text` as the forward pass reads it: line, plan, context.
pub(crate) fn read(job: &Job, text: &str) -> Vec<(usize, Plan, MoveContext)> {
    let mut out = Vec::new();
    job.forward(text.as_bytes(), "p.nc", &mut |line, plan, ctx| {
        out.push((line, *plan, *ctx))
    })
    .expect("reads");
    out
}

/// The point of a move at parameter `s` (an arc's on its helix or spiral).
pub(crate) fn point(mv: &Move, s: f64) -> [f64; 6] {
    let mut p = [0.0; 6];
    for (k, v) in p.iter_mut().enumerate() {
        *v = mv.start[k] + (mv.end[k] - mv.start[k]) * s;
    }
    if let Some(arc) = &mv.arc {
        let q = arc.point(&mv.start3(), &mv.end3(), s);
        p[..3].copy_from_slice(q.as_slice());
    }
    p
}

/// Distance of the tip `q` from the nominal tip path of the move `mv`:
/// the nearest of [`COARSE_POINTS`] points, refined by bisection of the
/// bracket around it.
pub(crate) fn off_path(pred: &ToolPredictor, mv: &Move, q: &nalgebra::Vector3<f64>) -> f64 {
    let d = |s: f64| (pred.nominal(&point(mv, s), mv.tool_len_mm).pos - q).norm();
    let h = 1.0 / COARSE_POINTS as f64;
    let k = (0..=COARSE_POINTS)
        .min_by(|&i, &j| d(i as f64 * h).total_cmp(&d(j as f64 * h)))
        .unwrap_or(0);
    let (mut lo, mut hi) = (
        ((k as f64) - 1.0).max(0.0) * h,
        ((k + 1) as f64 * h).min(1.0),
    );
    for _ in 0..REFINE_STEPS {
        let (m1, m2) = (lo + (hi - lo) / 3.0, hi - (hi - lo) / 3.0);
        if d(m1) < d(m2) {
            hi = m2;
        } else {
            lo = m1;
        }
    }
    d(k as f64 * h).min(d((lo + hi) / 2.0))
}

/// The input line each output line of a compensated program belongs to
/// (1-based): a line equal to the next input line, or annotated with its
/// deviation, is that input line; any other line was added after the input
/// line before it. Whether each output line is a takeup move.
pub(crate) fn align(input: &str, output: &str) -> Vec<(usize, bool)> {
    let ins: Vec<&str> = input.lines().collect();
    let mut i = 0;
    output
        .lines()
        .map(|l| {
            if ins.get(i) == Some(&l) || l.contains("(dev ") {
                i += 1;
            }
            (i.max(1), l.contains(" takeup)"))
        })
        .collect()
}

/// The worst distance, over every written feed piece of `output` (takeup
/// moves left out: they go onto a block's start by design) sampled along
/// its length, of the attained tip from the programmed path of its input
/// block `want` gives (`None`: not checked), with the input line.
pub(crate) fn worst_miss(
    job: &Job,
    input: &str,
    output: &str,
    want: &dyn Fn(usize) -> Option<Move>,
) -> (f64, usize, usize) {
    let pred = job.predictor.as_ref().expect("predictor");
    let map = align(input, output);
    let (mut worst, mut at, mut pieces) = (0.0f64, 0, 0);
    for (line, plan, ctx) in read(job, output) {
        let Some(mv) = plan.mv else { continue };
        let feeding = match plan.kind {
            PlanKind::Motion => mv.motion != Motion::Rapid,
            PlanKind::Cycle { .. } => true,
            _ => false,
        };
        let (src, takeup) = map[line - 1];
        let Some(prog) = want(src).filter(|_| feeding && !takeup) else {
            continue;
        };
        let p = pred.with_context(ctx);
        let n = ((mv.length_mm() / SAMPLE_MM).ceil() as usize).max(MIN_SAMPLES);
        for k in 0..=n {
            let c = point(&mv, k as f64 / n as f64);
            let q = p.attained(&c, &mv.dirs, mv.tool_len_mm).pos;
            let miss = off_path(&p, &prog, &q);
            if miss > worst {
                (worst, at) = (miss, src);
            }
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
