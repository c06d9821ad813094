//! Property test of the compensated G-code as a program: whatever mix of
//! straight moves, arcs (I/J or R, either direction, full circles),
//! reversals, block-delete lines, cutter radius compensation, letter case,
//! spacing, line ends and a missing last line end the input has, the
//! output (with its takeup points, pieces and added arc lines) reads back
//! without error; each input move is there, annotated and in order, and
//! its block ends where the move ends (within the size of the
//! corrections); arcs that stay arcs keep their direction, centre and
//! radius; no takeup point is written while cutter radius compensation may
//! be active; every line ends as the input's lines do; and exactly the
//! lines of block-delete blocks start with `/`.

use std::io::{BufReader, Cursor};

use postproc::compensate::Settings;
use postproc::emit::gcode::EmitOptions;
use postproc::machine::Machine;
use postproc::machine::tool::MachineTool;
use postproc::pipeline::gcode::Job;
use postproc::predict::{EffectSet, ToolPredictor};
use postproc::program::gcode::{Block, parse_line};
use postproc::program::interp::{Interpreter, Setup};
use proptest::prelude::*;

use crate::common::repo;

/// Largest distance between the end of the compensated and of the
/// programmed program, mm (the AFM R-1000's corrections are tens of µm).
const END_TOL_MM: f64 = 0.1;

/// One block of a generated program (work coordinates, mm).
#[derive(Debug, Clone)]
enum Step {
    /// A straight feed to (x, y, z).
    Line(f64, f64, f64),
    /// An arc in the XY plane from the current point about the centre at
    /// `angle0` (the start seen from the centre) with `radius`, sweeping
    /// `sweep` degrees (negative: clockwise); `full` makes it a full circle;
    /// `r_form` writes it with R.
    Arc {
        radius: f64,
        angle0: f64,
        sweep: f64,
        full: bool,
        r_form: bool,
    },
    /// G41 (true) or G40 (false) on a short straight move in Y.
    Comp(bool),
}

fn step() -> impl Strategy<Value = Step> {
    prop_oneof![
        4 => (10.0..290.0f64, 10.0..190.0f64, -5.0..5.0f64).prop_map(|(x, y, z)| Step::Line(x, y, z)),
        3 => (2.0..20.0f64, 0.0..360.0f64, -350.0..350.0f64, prop::bool::weighted(0.15), any::<bool>())
            .prop_map(|(radius, angle0, sweep, full, r_form)| Step::Arc { radius, angle0, sweep, full, r_form }),
        1 => any::<bool>().prop_map(Step::Comp),
    ]
}

/// Style of a generated program.
#[derive(Debug, Clone, Copy)]
struct Style {
    lower: bool,
    spaced: bool,
    crlf: bool,
    last_eol: bool,
}

/// The program text; each block gets a `/` where `deleted` says so.
fn program(steps: &[(Step, bool)], style: Style) -> String {
    let (sep, eol) = (
        if style.spaced { " " } else { "" },
        if style.crlf { "\r\n" } else { "\n" },
    );
    let mut lines = vec![
        format!("G90{sep}G54{sep}G0{sep}X150.{sep}Y100.{sep}Z20."),
        format!("G43{sep}H1{sep}Z5."),
        format!("G1{sep}Z0{sep}F1500"),
    ];
    let (mut x, mut y) = (150.0f64, 100.0f64);
    for (s, deleted) in steps {
        let slash = if *deleted { "/" } else { "" };
        let line = match s {
            Step::Line(tx, ty, z) => {
                x = *tx;
                y = *ty;
                format!("{slash}G1{sep}X{x:.3}{sep}Y{y:.3}{sep}Z{z:.3}")
            }
            Step::Arc {
                radius,
                angle0,
                sweep,
                full,
                r_form,
            } => {
                let a0 = angle0.to_radians();
                let (cx, cy) = (x - radius * a0.cos(), y - radius * a0.sin());
                // Keep the circle inside the work area.
                if cx - radius < 5.0
                    || cx + radius > 295.0
                    || cy - radius < 5.0
                    || cy + radius > 195.0
                {
                    continue;
                }
                let sweep = if *full {
                    360f64.copysign(*sweep)
                } else {
                    *sweep
                };
                if sweep.abs() < 5.0 {
                    continue;
                }
                let g = if sweep < 0.0 { "G2" } else { "G3" };
                let (i, j) = (cx - x, cy - y);
                if *full {
                    format!("{slash}{g}{sep}I{i:.3}{sep}J{j:.3}")
                } else {
                    let a1 = a0 + sweep.to_radians();
                    let (ex, ey) = (cx + radius * a1.cos(), cy + radius * a1.sin());
                    let text = if *r_form {
                        let r = if sweep.abs() > 180.0 {
                            -radius
                        } else {
                            *radius
                        };
                        format!("{slash}{g}{sep}X{ex:.3}{sep}Y{ey:.3}{sep}R{r:.3}")
                    } else {
                        format!("{slash}{g}{sep}X{ex:.3}{sep}Y{ey:.3}{sep}I{i:.3}{sep}J{j:.3}")
                    };
                    // The next block starts where this one ends as printed.
                    x = (ex * 1000.0).round() / 1000.0;
                    y = (ey * 1000.0).round() / 1000.0;
                    text
                }
            }
            Step::Comp(on) => {
                y = if y > 100.0 { y - 1.0 } else { y + 1.0 };
                let g = if *on {
                    format!("G41{sep}D1{sep}")
                } else {
                    format!("G40{sep}")
                };
                format!("{slash}{g}G1{sep}Y{y:.3}")
            }
        };
        lines.push(line);
    }
    lines.push("M30".into());
    let mut text = lines.join(eol);
    if style.last_eol {
        text.push_str(eol);
    }
    if style.lower {
        text = text.to_ascii_lowercase();
    }
    text
}

fn afm() -> MachineTool {
    let text = std::fs::read_to_string(repo("machines/afm-r1000.yaml")).unwrap();
    let Ok(Machine::Tool(m)) = Machine::from_yaml_str(&text, "afm-r1000.yaml") else {
        panic!("not a machine tool")
    };
    m
}

/// The start, middle and end points (x, y) of an arc.
type ArcPoints = [[f64; 2]; 3];

/// What a program reads back to.
struct ReadBack {
    /// End point of every move.
    ends: Vec<[f64; 6]>,
    /// Per annotated line (one per compensated input move): the end of the
    /// last move before the next annotated line.
    block_ends: Vec<[f64; 6]>,
    /// Arcs: clockwise, centre (x, y), radius, and the start, middle and
    /// end points (x, y) of the arc.
    arcs: Vec<(bool, [f64; 2], f64, ArcPoints)>,
    /// Lines with a takeup point while cutter radius compensation may be
    /// active (from the G41/G42 block through the G40 block; a `/G40` does
    /// not end it).
    takeups_under_comp: usize,
}

/// Reads `text` back; panics with it when it does not.
fn read_back(machine: &MachineTool, text: &str) -> ReadBack {
    let mut it = Interpreter::new(Setup::for_machine(machine), "out.nc");
    let mut b = Block::default();
    let mut r = ReadBack {
        ends: Vec::new(),
        block_ends: Vec::new(),
        arcs: Vec::new(),
        takeups_under_comp: 0,
    };
    let mut comp = false;
    for (i, l) in text.split_inclusive('\n').enumerate() {
        let l = l.trim_end_matches(['\n', '\r']);
        if let Err(e) = parse_line(l.as_bytes(), i + 1, "out.nc", &mut b) {
            panic!("{e}\n{text}");
        }
        let plan = match it.step(&b, l.as_bytes()) {
            Ok(p) => p,
            Err(e) => panic!("{e}\n{text}"),
        };
        let upper = l.to_ascii_uppercase();
        let before = comp;
        if upper.contains("G41") || upper.contains("G42") {
            comp = true;
        } else if upper.contains("G40") && !upper.starts_with('/') {
            comp = false;
        }
        if l.contains("takeup") && (before || comp) {
            r.takeups_under_comp += 1;
        }
        if l.contains("(dev ") {
            r.block_ends.push([f64::NAN; 6]);
        }
        if let Some(mv) = plan.mv {
            r.ends.push(mv.end);
            if let Some(last) = r.block_ends.last_mut() {
                *last = mv.end;
            }
            if let Some(arc) = mv.arc {
                let cw = arc.sweep < 0.0;
                let c = [arc.center[0], arc.center[1]];
                let a0 = (mv.start[1] - c[1]).atan2(mv.start[0] - c[0]);
                let am = a0 + arc.sweep / 2.0;
                let mid = [c[0] + arc.radius * am.cos(), c[1] + arc.radius * am.sin()];
                let points = [[mv.start[0], mv.start[1]], mid, [mv.end[0], mv.end[1]]];
                r.arcs.push((cw, c, arc.radius, points));
            }
        }
    }
    r
}

/// Distance of two points in X, Y, Z, mm.
fn dist(a: &[f64; 6], b: &[f64; 6]) -> f64 {
    (0..3).map(|s| (a[s] - b[s]).powi(2)).sum::<f64>().sqrt()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn compensated_programs_read_back(
        steps in prop::collection::vec((step(), prop::bool::weighted(0.15)), 1..14),
        lower in any::<bool>(),
        spaced in any::<bool>(),
        crlf in any::<bool>(),
        last_eol in any::<bool>(),
        tolerance in prop_oneof![Just(0.001), Just(0.005), Just(0.02)],
    ) {
        let machine = afm();
        let input = program(&steps, Style { lower, spaced, crlf, last_eol });
        let job = Job {
            predictor: Some(ToolPredictor::new(&machine, EffectSet::default())),
            setup: Setup::for_machine(&machine),
            settings: Settings { tolerance_mm: tolerance },
            emit: EmitOptions { decimals_mm: Some(4), decimals_deg: None, annotate: true },
            pool: None,
            travel: None,
        };
        let mut out = Vec::new();
        let summary = job.run(BufReader::new(Cursor::new(input.as_bytes())), "in.nc", Some(&mut out), None);
        let summary = match summary {
            Ok(s) => s,
            Err(e) => panic!("{e}\n{input}"),
        };
        let out = String::from_utf8(out).unwrap();
        let before = read_back(&machine, &input);
        let after = read_back(&machine, &out);
        // Every input move is there, annotated, in order: each annotated
        // block (with its added lines) ends where its input move ends,
        // within the size of the corrections.
        prop_assert_eq!(after.block_ends.len(), before.ends.len(), "{}", out);
        for (k, (a, b)) in before.ends.iter().zip(&after.block_ends).enumerate() {
            prop_assert!(dist(a, b) < END_TOL_MM, "move {}: {} mm\n{}", k, dist(a, b), out);
        }
        prop_assert_eq!(summary.added, after.ends.len() - before.ends.len(), "{}", out);
        // Arcs that stay arcs (whole or in pieces) keep their direction and
        // radius (within the corrections), in order, and lie on the
        // programmed circle: their centre is the programmed one, or, for a
        // piece short enough that corrections of its ends swing its
        // centre (a chord of a few tenths of a millimetre), its start,
        // middle and end points lie on the programmed circle.
        let mut from = 0;
        for (cw, c, r, points) in &after.arcs {
            let found = before.arcs.get(from..).unwrap_or(&[]).iter().position(|(pcw, pc, pr, _)| {
                let on_circle = points
                    .iter()
                    .all(|p| ((p[0] - pc[0]).hypot(p[1] - pc[1]) - pr).abs() < END_TOL_MM);
                pcw == cw
                    && (pr - r).abs() < END_TOL_MM
                    && ((pc[0] - c[0]).hypot(pc[1] - c[1]) < END_TOL_MM || on_circle)
            });
            prop_assert!(found.is_some(), "arc cw={} c={:?} r={} not programmed\n{}", cw, c, r, out);
            from += found.unwrap_or(0);
        }
        // No takeup point while cutter radius compensation may be active.
        prop_assert_eq!(after.takeups_under_comp, 0, "{}", out);
        prop_assert_eq!(before.takeups_under_comp, 0);
        // Line ends: the input's on every line, none after the last line
        // where the input had none.
        prop_assert_eq!(out.ends_with('\n'), last_eol);
        for l in out.split_inclusive('\n').filter(|l| l.ends_with('\n')) {
            prop_assert_eq!(l.ends_with("\r\n"), crlf, "{:?}", l);
        }
        // A `/` line's added lines (up to the next annotated line) keep it;
        // no other line has one.
        let mut deleted = false;
        for l in out.lines() {
            if l.contains("(dev ") || l.starts_with('M') || l.starts_with('m') {
                deleted = l.starts_with('/');
            } else {
                prop_assert_eq!(l.starts_with('/'), deleted, "{}\n{}", l, out);
            }
        }
    }
}
