//! A compensated program, read and predicted again with the same machine
//! model (`report` of the output), attains every programmed target of the
//! input within the tolerance: the directions of motion, the feed
//! directions and the process loads of its written pieces are those the
//! compensation was solved with. Checked through the interpreter and the
//! predictor, not through the compensation's own residual.

use crate::common::{postproc, repo};

/// Tolerance of the compensation in these runs, mm.
const TOLERANCE_MM: f64 = 0.003;

/// One row of a `report --format csv`: line, motion, the programmed point
/// and the attained point (programmed + predicted deviation), residual.
pub(crate) struct Row {
    pub(crate) line: String,
    pub(crate) motion: String,
    pub(crate) programmed: [f64; 3],
    pub(crate) attained: [f64; 3],
    pub(crate) residual_mm: f64,
}

fn report(path: &std::path::Path) -> Vec<Row> {
    report_with(&["--machine", "afm-r1000"], path)
}

/// `report --format csv` of `path` with the machine flags `machine`, read
/// into rows.
pub(crate) fn report_with(machine: &[&str], path: &std::path::Path) -> Vec<Row> {
    let out = postproc()
        .arg("report")
        .args(machine)
        .args(["--format", "csv"])
        .arg(path)
        .output()
        .expect("runs");
    assert!(
        out.status.success() || out.status.code() == Some(1),
        "{out:?}"
    );
    let text = String::from_utf8(out.stdout).expect("utf-8");
    let mut lines = text.lines().filter(|l| !l.starts_with('#'));
    let head: Vec<&str> = lines.next().expect("header").split(',').collect();
    let col = |name: &str| head.iter().position(|h| *h == name).expect(name);
    let num = |cells: &[&str], name: &str| -> f64 { cells[col(name)].parse().expect(name) };
    lines
        .map(|l| {
            let c: Vec<&str> = l.split(',').collect();
            let p = [num(&c, "X_mm"), num(&c, "Y_mm"), num(&c, "Z_mm")];
            let d = [num(&c, "dx_mm"), num(&c, "dy_mm"), num(&c, "dz_mm")];
            Row {
                line: c[col("line")].to_string(),
                motion: c[col("motion")].to_string(),
                programmed: p,
                attained: [p[0] + d[0], p[1] + d[1], p[2] + d[2]],
                residual_mm: num(&c, "residual_mm"),
            }
        })
        .collect()
}

pub(crate) fn dist(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    (0..3).map(|i| (a[i] - b[i]).powi(2)).sum::<f64>().sqrt()
}

fn attains_every_target(name: &str) {
    let input = repo(&format!("tests/repredict/{name}"));
    let dir = tempfile::tempdir().expect("tempdir");
    let output = dir.path().join(name);
    postproc()
        .args(["compensate", "--machine", "afm-r1000", "--tolerance"])
        .arg(TOLERANCE_MM.to_string())
        .arg(&input)
        .arg("-o")
        .arg(&output)
        .assert()
        .success();
    let landed = report(&output);
    let targets = report(&input);
    let mut checked = 0;
    for t in targets
        .iter()
        .filter(|t| t.motion != "rapid" && t.motion != "fixed")
    {
        let off = landed
            .iter()
            .map(|l| dist(&l.attained, &t.programmed))
            .fold(f64::INFINITY, f64::min);
        assert!(
            off <= TOLERANCE_MM + t.residual_mm,
            "{name}:{} ({}): attained {off:.6} mm from its target, tolerance {TOLERANCE_MM} mm, residual {} mm",
            t.line,
            t.motion,
            t.residual_mm
        );
        checked += 1;
    }
    assert!(checked > 5, "{name}: {checked} targets");
}

#[test]
fn a_compensated_hand_written_frame_attains_its_targets() {
    attains_every_target("hand_frame.nc");
}

// ---------------------------------------------------------------------
// The promise along every written piece: a compensated program, read back
// by the interpreter and put on its own time line (the forward pass the
// prediction shares with `report`, not the solver), sampled along every
// written feed piece; each attained point lies within the header's
// tolerance of the programmed path of the block the piece belongs to.

use postproc::machine::tool::MachineTool;
use postproc::pipeline::gcode::Job;
use postproc::predict::{EffectSet, MoveContext, ProcessSetup, ToolPredictor};
use postproc::program::interp::{Motion, Move, Plan, PlanKind, Setup};

/// Sample spacing along a written piece, mm (and at least
/// [`MIN_SAMPLES`] per piece).
const SAMPLE_MM: f64 = 0.25;
const MIN_SAMPLES: usize = 8;
/// Points of a programmed move searched for the nearest one before the
/// search is refined.
const PATH_POINTS: usize = 48;
/// Floating-point allowance of the comparison with the tolerance, mm.
const FLOAT_MM: f64 = 1e-9;

/// One program of the check: where it is, the machine it runs on, and
/// whether it needs the shop machine and tool table of `samples/gcode`.
struct Case {
    program: String,
    machine: &'static str,
    shop: bool,
}

fn machine_text(name: &str, shop: bool) -> String {
    let text = std::fs::read_to_string(repo(&format!("machines/{name}.yaml"))).expect("machine");
    if shop {
        text.replace("G58: [0.0, 0.0, 0.0]", "G58: [300.0, 200.0, 250.0]")
            .replace("G59: [0.0, 0.0, 0.0]", "G59: [300.0, 200.0, 250.0]")
    } else {
        text
    }
}

/// Tool lengths of the shop-style samples.
fn shop_tools() -> Vec<(u32, f64)> {
    (1..=12).map(|h| (h, 60.0 + 5.0 * h as f64)).collect()
}

/// A block as the forward pass reads it.
pub(crate) struct Read {
    pub(crate) line: usize,
    pub(crate) plan: Plan,
    pub(crate) ctx: MoveContext,
}

/// Every block of `text` as the forward pass of `job` reads it.
pub(crate) fn forward(job: &Job, text: &str) -> Vec<Read> {
    let mut out = Vec::new();
    job.forward(text.as_bytes(), "p.nc", &mut |line, plan, ctx| {
        out.push(Read {
            line,
            plan: *plan,
            ctx: *ctx,
        })
    })
    .expect("reads back");
    out
}

/// The input line each output line belongs to (1-based), from the text:
/// an output line equal to the next input line is that line; a line with
/// a `(dev` annotation is the next input line rewritten; any other line
/// was added after the input line before it (a piece, or the header).
/// The output lines that are a block's takeup move are marked.
fn align(input: &str, output: &str) -> (Vec<usize>, Vec<bool>) {
    let ins: Vec<&str> = input.lines().collect();
    let mut map = Vec::new();
    let mut takeup = Vec::new();
    let mut i = 0;
    for l in output.lines() {
        let annotated = l.contains("(dev ") || l.contains("; dev ");
        if ins.get(i) == Some(&l) || annotated {
            i += 1;
        }
        map.push(i.max(1));
        takeup.push(l.contains(" takeup)") || l.ends_with(" takeup"));
    }
    (map, takeup)
}

/// The point at parameter `s` of a move, and the directions of motion the
/// machine moves with there: an axis of an arc's plane the way the arc's
/// tangent goes, every other axis as the interpreter reads the move.
fn at(mv: &Move, s: f64) -> ([f64; 6], [i8; 6]) {
    let mut p = [0.0; 6];
    for (k, v) in p.iter_mut().enumerate() {
        *v = mv.start[k] + (mv.end[k] - mv.start[k]) * s;
    }
    let mut d = mv.dirs;
    if let Some(arc) = &mv.arc {
        let (s3, e3) = (mv.start3(), mv.end3());
        let q = arc.point(&s3, &e3, s);
        let (a, b, _) = arc.plane.axes();
        p[..3].copy_from_slice(q.as_slice());
        // An axis of the plane moves the way its last stretch of more than
        // the deadband before this point went (the first one after the
        // start, at the start).
        let x = |u: f64| arc.point(&s3, &e3, u);
        for k in [a, b] {
            let mut u = s;
            let step = 1.0 / ARC_STEPS;
            let found = loop {
                let back = s > 0.0;
                u = if back { u - step } else { u + step };
                if !(0.0..=1.0).contains(&u) {
                    break None;
                }
                let dx = if back { q[k] - x(u)[k] } else { x(u)[k] - q[k] };
                if dx.abs() > DEADBAND_MM {
                    break Some(dx);
                }
            };
            if let Some(dx) = found {
                d[k] = if dx > 0.0 { 1 } else { -1 };
            }
        }
    }
    (p, d)
}

/// Steps of the search for an arc axis' last stretch of travel.
const ARC_STEPS: f64 = 4000.0;
/// The interpreter's deadband of a direction of motion, mm.
const DEADBAND_MM: f64 = 1e-3;

/// The feed path of a block: the move, or for a canned-cycle hole the feed
/// from the R level to the bottom (its `mv`).
fn feed(plan: &Plan) -> Option<Move> {
    let mv = plan.mv?;
    match plan.kind {
        PlanKind::Motion if mv.motion != Motion::Rapid => Some(mv),
        PlanKind::Cycle { .. } => Some(mv),
        _ => None,
    }
}

/// Distance of the tip `q` from the nominal path of the programmed move.
fn off_path(pred: &ToolPredictor, mv: &Move, q: &nalgebra::Vector3<f64>) -> f64 {
    let tool = mv.tool_len_mm;
    let d = |s: f64| (pred.nominal(&at(mv, s).0, tool).pos - q).norm();
    let coarse: Vec<f64> = (0..=PATH_POINTS)
        .map(|k| d(k as f64 / PATH_POINTS as f64))
        .collect();
    let h = 1.0 / PATH_POINTS as f64;
    let g = 0.5 * (5f64.sqrt() - 1.0);
    let mut best = f64::INFINITY;
    // Golden-section refinement around every local minimum of the coarse
    // points (a full circle has two at its ends).
    for k in 0..=PATH_POINTS {
        let v = coarse[k];
        let left = k == 0 || coarse[k - 1] >= v;
        let right = k == PATH_POINTS || coarse[k + 1] >= v;
        if !(left && right) {
            continue;
        }
        let s = k as f64 * h;
        let (mut lo, mut hi) = ((s - h).max(0.0), (s + h).min(1.0));
        for _ in 0..40 {
            let (x1, x2) = (hi - g * (hi - lo), lo + g * (hi - lo));
            if d(x1) < d(x2) {
                hi = x2;
            } else {
                lo = x1;
            }
        }
        best = best.min(v).min(d((lo + hi) / 2.0));
    }
    best
}

/// The worst miss of the compensated `output` of `input`: per output line,
/// the largest distance of its sampled piece from its block's programmed
/// path, with the line of the input block.
pub(crate) fn misses(job: &Job, input: &str, output: &str) -> Vec<(usize, usize, f64)> {
    let pred = job.predictor.as_ref().expect("predictor");
    let programmed: std::collections::HashMap<usize, Move> = forward(job, input)
        .into_iter()
        .filter_map(|r| feed(&r.plan).map(|mv| (r.line, mv)))
        .collect();
    let (map, takeup) = align(input, output);
    let mut out = Vec::new();
    let reads = forward(job, output);
    for (i, r) in reads.iter().enumerate() {
        let Some(mv) = feed(&r.plan) else { continue };
        let src = map[r.line - 1];
        // A block's takeup move goes onto its start, off the path by
        // design; the pieces after it start on it.
        if takeup[r.line - 1] {
            continue;
        }
        let Some(want) = programmed.get(&src) else {
            // Not matched to a programmed feed: reported as a miss.
            out.push((src, r.line, f64::INFINITY));
            continue;
        };
        // A short straight line inside an arc block is a takeup at a
        // reversal of the arc (onto the next part's start).
        if want.arc.is_some() && mv.arc.is_none() && mv.length_mm() < 0.05 {
            continue;
        }
        // So is a short straight line inside a straight block after which
        // the block's next piece moves an axis the other way (a takeup
        // point where the correction's drift reverses an axis).
        if want.arc.is_none() && mv.arc.is_none() && mv.length_mm() < 0.05 {
            let next = reads.get(i + 1).and_then(|n| {
                let same = n.line >= 1 && map[n.line - 1] == src && !takeup[n.line - 1];
                feed(&n.plan).filter(|_| same)
            });
            if next.is_some_and(|n| n.arc.is_none() && n.dirs != mv.dirs) {
                continue;
            }
        }
        let p = pred.with_context(r.ctx);
        let n = ((mv.length_mm() / SAMPLE_MM).ceil() as usize).max(MIN_SAMPLES);
        let mut worst = 0.0f64;
        for k in 0..=n {
            let (c, d) = at(&mv, k as f64 / n as f64);
            let q = p.attained(&c, &d, mv.tool_len_mm).pos;
            worst = worst.max(off_path(&p, want, &q));
        }
        out.push((src, r.line, worst));
    }
    out
}

/// The forward pass of `machine` with `effects` at `tol` (no process
/// load, the machine's own setup).
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

/// Compensates `case` through the binary at `tol` with `effects` and checks
/// every written piece; a piece beyond the tolerance must be warned about
/// (its line named) and counted in the summary line.
fn promise_holds(case: &Case, effects: &str, tol: f64) -> Outcome {
    promise_holds_with(case, effects, tol, &[])
}

/// [`promise_holds`] with the extra flags `flags` on the compensation.
fn promise_holds_with(case: &Case, effects: &str, tol: f64, flags: &[&str]) -> Outcome {
    let dir = tempfile::tempdir().expect("tempdir");
    let mtext = machine_text(case.machine, case.shop);
    let mpath = dir.path().join(format!("{}.yaml", case.machine));
    std::fs::write(&mpath, &mtext).expect("machine");
    let input = std::fs::read_to_string(repo(&case.program)).expect("program");
    let inpath = dir.path().join("in.nc");
    std::fs::write(&inpath, &input).expect("program");
    let outpath = dir.path().join("out.nc");
    let mut cmd = postproc();
    cmd.args(["compensate", "--machine"])
        .arg(&mpath)
        .args(["--effects", effects, "--tolerance", &tol.to_string()])
        .args(flags)
        .arg(&inpath)
        .arg("-o")
        .arg(&outpath);
    if case.shop {
        for (h, l) in shop_tools() {
            cmd.args(["--tool", &format!("H{h}={l}")]);
        }
    }
    let run = cmd.output().expect("runs");
    let stderr = String::from_utf8_lossy(&run.stderr).to_string();
    assert!(
        matches!(run.status.code(), Some(0) | Some(1)),
        "{}: {stderr}",
        case.program
    );
    let output = std::fs::read_to_string(&outpath).expect("output");
    assert!(output.contains(&format!("tolerance {tol} mm")), "{output}");
    let m = MachineTool::from_yaml_str(&mtext, "m.yaml").expect("machine");
    let process = ProcessSetup::for_machine(&m);
    let mut setup = Setup::for_machine(&m);
    if case.shop {
        setup.tools.extend(shop_tools());
    }
    let mut job = job(&m, effects, tol);
    job.predictor = job.predictor.map(|p| p.with_process(&process));
    job.setup = setup;
    let found = misses(&job, &input, &output);
    assert!(!found.is_empty(), "{}: no pieces", case.program);
    let mut silent = Vec::new();
    let mut worst = 0.0f64;
    let mut warned = 0;
    for (line, out_line, miss) in &found {
        worst = worst.max(*miss);
        if *miss > tol + FLOAT_MM {
            let named =
                stderr.contains(&format!(":{line}: ")) && stderr.contains("beyond the tolerance");
            if named {
                warned += 1;
            } else {
                silent.push(format!("line {line} (output {out_line}): {miss:.5} mm"));
            }
        }
    }
    if warned > 0 {
        assert!(stderr.contains("beyond the tolerance (max"), "{stderr}");
    }
    Outcome {
        warned,
        worst,
        silent,
    }
}

/// What [`promise_holds`] found.
struct Outcome {
    /// Pieces beyond the tolerance, each warned about.
    warned: usize,
    /// The largest miss, mm.
    worst: f64,
    /// Pieces beyond the tolerance without a warning.
    silent: Vec<String>,
}

fn cases() -> Vec<Case> {
    let mut v: Vec<Case> = [
        ("samples/part.nc", "afm-r1000", false),
        ("samples/effects.nc", "afm-r1000", false),
        ("samples/fusion-haas.nc", "afm-r1000", false),
        ("samples/inch-default.nc", "afm-r1000", false),
        ("samples/five-axis.nc", "five-axis-ac", false),
        ("samples/gcode/block_delete.nc", "afm-r1000", true),
        ("samples/gcode/fusion_fanuc.nc", "afm-r1000", true),
        ("samples/gcode/inch_g20.nc", "afm-r1000", true),
        ("samples/gcode/iso_spaced_crlf.nc", "afm-r1000", true),
        ("samples/gcode/linuxcnc.ngc", "afm-r1000", true),
        ("samples/gcode/mastercam_haas.nc", "afm-r1000", true),
        ("tests/repredict/hand_frame.nc", "afm-r1000", false),
        ("tests/repredict/after_cycle.nc", "afm-r1000", false),
        (
            "tests/repredict/five_axis_unnamed.nc",
            "five-axis-ac",
            false,
        ),
        ("tests/repredict/haas_tap_inch.nc", "afm-r1000", true),
    ]
    .into_iter()
    .map(|(p, m, shop)| Case {
        program: p.to_string(),
        machine: m,
        shop,
    })
    .collect();
    v.retain(|c| repo(&c.program).exists());
    v
}

/// Runs every case at the bundled tolerance and at 1 µm with `effects`:
/// no piece may be beyond the tolerance without a warning that names its
/// line (and the summary counting it). The pieces warned about are listed
/// on standard error.
fn every_case(effects: &str) {
    let mut report = Vec::new();
    for case in cases() {
        for tol in [0.003, 0.001] {
            let o = promise_holds(&case, effects, tol);
            if o.warned > 0 {
                eprintln!(
                    "{} at {tol} mm: {} pieces beyond the tolerance, warned (worst {:.5} mm)",
                    case.program, o.warned, o.worst
                );
            }
            if !o.silent.is_empty() {
                report.push(format!(
                    "{} at {tol} mm: silent: {}",
                    case.program,
                    o.silent.join(", ")
                ));
            }
        }
    }
    assert!(report.is_empty(), "{}", report.join("\n"));
}

#[test]
fn every_written_piece_lands_within_the_tolerance_geometric() {
    every_case("geometric");
}

#[test]
fn every_written_piece_lands_within_the_tolerance_quasi_static() {
    every_case("geometric,static,thermal");
}

/// A 400 mm straight pass and its return on afm-r1000: every written
/// piece within the tolerance (none warned beyond it). The correction
/// moves Z, which the block does not drive, by about the deadband of a
/// direction of motion along the pass: a piece read back with Z moving
/// would take the Z reversal error the solve did not (regression: 3.95
/// µm at 3 µm, and a takeup point inside the pass taken for a miss).
#[test]
fn a_long_straight_pass_lands_within_the_tolerance() {
    let case = Case {
        program: "tests/repredict/long_pass.nc".to_string(),
        machine: "afm-r1000",
        shop: false,
    };
    for tol in [0.003, 0.001] {
        let o = promise_holds(&case, "geometric", tol);
        assert!(o.silent.is_empty(), "at {tol} mm: {}", o.silent.join(", "));
        assert!(
            o.worst <= tol + FLOAT_MM,
            "at {tol} mm: worst {:.5} mm",
            o.worst
        );
    }
}

#[test]
fn the_first_feed_after_a_canned_cycle_and_g28_is_taken_up() {
    // The program: the feed after a drilled hole, `G28`, a new
    // position and tool length. Its machine stands where the rapids left
    // it (X and Y solved with Z at the reference position): the feed
    // starts with a takeup and lands within the tolerance.
    let case = Case {
        program: "tests/repredict/after_cycle.nc".to_string(),
        machine: "afm-r1000",
        shop: false,
    };
    let o = promise_holds(&case, "geometric", 0.003);
    assert!(o.silent.is_empty() && o.warned == 0, "{:?}", o.silent);
    assert!(o.worst <= 0.003, "{}", o.worst);
}

#[test]
fn a_five_axis_program_that_never_names_its_rotaries_lands_within_the_tolerance() {
    // A and C stand at the reference position the whole program: the
    // machine is known there from the start, so the first feed gets its
    // takeup and every piece holds the tolerance.
    let case = Case {
        program: "tests/repredict/five_axis_unnamed.nc".to_string(),
        machine: "five-axis-ac",
        shop: false,
    };
    for tol in [0.003, 0.001] {
        let o = promise_holds(&case, "geometric", tol);
        assert!(
            o.silent.is_empty() && o.warned == 0,
            "{tol}: {:?}",
            o.silent
        );
    }
}

#[test]
fn a_frame_of_half_circles_lands_within_one_micron() {
    // Straight sides and half circles over a quadrant point each, kept
    // as arcs about shifted centres or cut at the reversal: every piece
    // within 1 µm along its length, geometric effects.
    let case = Case {
        program: "tests/repredict/hand_frame.nc".to_string(),
        machine: "afm-r1000",
        shop: false,
    };
    let o = promise_holds(&case, "geometric", 0.001);
    assert!(o.silent.is_empty(), "{:?}", o.silent);
}

#[test]
fn inch_tapping_after_tool_changes_lands_within_the_tolerance() {
    // Spot, drill and tap in inch, each after a tool change and G28, then a
    // feed after the last cycle: its start is taken up.
    let case = Case {
        program: "tests/repredict/haas_tap_inch.nc".to_string(),
        machine: "afm-r1000",
        shop: true,
    };
    let o = promise_holds(&case, "geometric", 0.003);
    assert!(o.silent.is_empty(), "{:?}", o.silent);
}

#[test]
fn a_tcpm_feed_from_a_point_at_the_top_of_z_lands_within_the_tolerance() {
    // Issue 43: under G43.4 a rapid that names only Z moves every linear
    // axis, and ends where the correction of the feed after it would take
    // Z past the top of its travel by about 2 µm (the reversal error of Z).
    // The feed starts from the rapid's solved command on every axis and
    // its takeup point is held at the end of travel; its pieces are
    // proven from there (regression: "more than 65536 segments"). At
    // 1 µm the takeup point would lie farther past the end than the
    // tolerance: the feed leaves from the rapid's end, and its miss there
    // is warned about, never silent.
    let case = Case {
        program: "tests/repredict/tcpm_held_top.nc".to_string(),
        machine: "five-axis-ac",
        shop: false,
    };
    let o = promise_holds(&case, "geometric", 0.003);
    assert!(o.silent.is_empty(), "{}", o.silent.join(", "));
    assert!(o.worst <= 0.003 + FLOAT_MM, "worst {:.5} mm", o.worst);
    let o = promise_holds(&case, "geometric", 0.001);
    assert!(o.silent.is_empty(), "at 1 µm: {}", o.silent.join(", "));
}

#[test]
fn canned_holes_written_as_moves_land_within_one_micron() {
    // Issue 41: drilled and pecked holes (G81, G82, G83) whose one X and
    // Y per hole cannot hold 1 µm along their depth (the Z squareness and
    // angular errors tilt them) are written as their moves with
    // `--expand-cycles`; re-predicted, every written piece of every
    // program with such holes lies within 1 µm of its programmed path,
    // for geometric and for all quasi-static effects.
    let programs = [
        ("samples/part.nc", false),
        ("samples/fusion-haas.nc", false),
        ("samples/gcode/fusion_fanuc.nc", true),
        ("samples/gcode/mastercam_haas.nc", true),
        ("samples/gcode/inch_g20.nc", true),
        ("tests/repredict/after_cycle.nc", false),
    ];
    let mut report = Vec::new();
    for (program, shop) in programs {
        let case = Case {
            program: program.to_string(),
            machine: "afm-r1000",
            shop,
        };
        for effects in ["geometric", "geometric,static,thermal"] {
            let o = promise_holds_with(&case, effects, 0.001, &["--expand-cycles"]);
            if !o.silent.is_empty() || o.worst > 0.001 + FLOAT_MM {
                report.push(format!(
                    "{program} ({effects}): worst {:.5} mm, {} warned, silent: {}",
                    o.worst,
                    o.warned,
                    o.silent.join(", ")
                ));
            }
        }
    }
    assert!(report.is_empty(), "{}", report.join("\n"));
}
