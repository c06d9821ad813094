//! Size and accuracy of compensated programs at the default tolerance: a
//! pocket with helical bores, a 3D surfacing program and a contour program,
//! each of a few thousand lines in the style of a CAM post, compensated on
//! the bundled AFM R-1000 (geometric errors). The output may have at most
//! twice the input's lines, and re-interpreted against the model every
//! written point and every piece between them (lines and arcs) must land
//! within the tolerance of the programmed path.

use std::fmt::Write as _;

use nalgebra::Vector3;
use postproc::machine::Machine;
use postproc::machine::tool::MachineTool;
use postproc::program::gcode::{Block, parse_line};
use postproc::program::interp::{Interpreter, Motion, Move, Setup};

use crate::common::{postproc, repo};

/// Allowance for the written words (4 decimals: 0.05 µm each) and the
/// re-interpretation of an arc with the mean of its two radii, mm.
const WORD_ALLOWANCE_MM: f64 = 0.0002;
/// Moves shorter than this are takeups (a move onto the start solved for
/// new directions of motion): only their end is on the path, checked as the
/// start of the move after them, mm.
const TAKEUP_LEN_MM: f64 = 0.02;
/// Tangent component (of a unit tangent) below which an axis of a written
/// arc counts as standing still (within 0.6° of a quadrant point).
const QUADRANT_TANGENT: f64 = 0.01;
/// Checked points along a written straight move.
const LINE_SAMPLES: usize = 16;
/// Largest angle between checked points of a written arc, rad.
const ARC_STEP_RAD: f64 = 0.02;

/// A Fusion-style pocket (Haas post): four helical bores ramped in half
/// turns, then an adaptive-style clearing of a rounded pocket in short
/// straight moves at three depths.
fn pocket_program() -> String {
    let mut s = String::from(
        "%\nO1001 (POCKET WITH BORES)\n(T1  D=10. CR=0. - ZMIN=-8. - FLAT END MILL)\nN10 G90 G94 G17 G49 G40 G80\nN15 G21\nN20 G28 G91 Z0.\nN25 G90\n\n(BORE1)\nN30 T1 M6\nN35 S8000 M3\nN40 G54\n",
    );
    let mut first = true;
    for (cx, cy) in [(30.0, 30.0), (170.0, 30.0), (170.0, 110.0), (30.0, 110.0)] {
        let r = 3.0;
        writeln!(s, "G0 X{:.3} Y{cy:.3}", cx + r).unwrap();
        if first {
            s.push_str("G43 Z15. H1\n");
            first = false;
        }
        s.push_str("Z5.\nG1 Z1. F1000.\nZ0. F300.\n");
        let mut z = 0.0;
        // The side of the centre the tool is on.
        let mut side = 1.0;
        while z > -8.0 + 1e-9 {
            z -= 0.25;
            let i = -side * r;
            side = -side;
            writeln!(s, "G3 X{:.3} Y{cy:.3} Z{z:.3} I{i:.3} J0.", cx + side * r).unwrap();
        }
        // Two half turns at the bottom.
        for _ in 0..2 {
            let i = -side * r;
            side = -side;
            writeln!(s, "G3 X{:.3} Y{cy:.3} I{i:.3} J0.", cx + side * r).unwrap();
        }
        writeln!(s, "G1 X{cx:.3} F1000.\nG0 Z15.").unwrap();
    }
    s.push_str("\n(ADAPTIVE1)\nG0 X60. Y45.\nZ5.\n");
    for depth in [-2.0, -4.0, -6.0] {
        writeln!(s, "G1 Z{depth:.3} F300.").unwrap();
        for k in 0..7 {
            let off = 15.0 - 2.0 * k as f64;
            let (x0, x1, y0, y1) = (60.0 + off - 15.0, 140.0 - off + 15.0, 45.0, 95.0);
            let rc = 4.0;
            writeln!(s, "G1 X{:.3} Y{y0:.3} F2000.", x0 + rc).unwrap();
            let steps = |a: f64, b: f64| ((b - a).abs() / 1.5).ceil() as usize;
            let n = steps(x0 + rc, x1 - rc);
            for i in 1..=n {
                let x = x0 + rc + (x1 - x0 - 2.0 * rc) * i as f64 / n as f64;
                writeln!(s, "X{x:.3}").unwrap();
            }
            writeln!(s, "G3 X{x1:.3} Y{:.3} I0. J{rc:.3}", y0 + rc).unwrap();
            let n = steps(y0 + rc, y1 - rc);
            for i in 1..=n {
                let y = y0 + rc + (y1 - y0 - 2.0 * rc) * i as f64 / n as f64;
                writeln!(s, "G1 Y{y:.3}").unwrap();
            }
            writeln!(s, "G3 X{:.3} Y{y1:.3} I{:.3} J0.", x1 - rc, -rc).unwrap();
            let n = steps(x0 + rc, x1 - rc);
            for i in 1..=n {
                let x = x1 - rc - (x1 - x0 - 2.0 * rc) * i as f64 / n as f64;
                writeln!(s, "G1 X{x:.3}").unwrap();
            }
            writeln!(s, "G3 X{x0:.3} Y{:.3} I0. J{:.3}", y1 - rc, -rc).unwrap();
            let n = steps(y0 + rc, y1 - rc);
            for i in 1..=n {
                let y = y1 - rc - (y1 - y0 - 2.0 * rc) * i as f64 / n as f64;
                writeln!(s, "G1 Y{y:.3}").unwrap();
            }
            writeln!(s, "G3 X{:.3} Y{y0:.3} I{rc:.3} J0.", x0 + rc).unwrap();
        }
    }
    s.push_str("G0 Z15.\nM5\nG28 G91 Z0.\nG90\nM30\n%\n");
    s
}

/// A Mastercam-style 3D surface finish: zig-zag passes over a saddle and a
/// dome with a ball mill, a point every 1.2 mm.
fn surfacing_program() -> String {
    let mut s = String::from(
        "%\nO0002(SURFACE FINISH)\n(MATERIAL - ALUMINUM MM - 2024)\n( T2 |  6. BALL ENDMILL | H2 )\nN100 G21\nN102 G0 G17 G40 G49 G80 G90\nN104 T2 M6\nN106 G0 G90 G54 X0. Y0. S10000 M3\nN108 G43 H2 Z25.\n",
    );
    let z = |x: f64, y: f64| {
        let (dx, dy) = (x - 90.0, y - 60.0);
        -3.0 + 6.0 * (-(dx * dx + dy * dy) / 1500.0).exp() + 0.0004 * (dx * dx - dy * dy)
    };
    writeln!(s, "Z{:.4}\nG1 Z{:.4} F500.", z(0.0, 0.0) + 5.0, z(0.0, 0.0)).unwrap();
    let (nx, ny) = (150, 20);
    for row in 0..ny {
        let y = row as f64 * 6.0;
        if row > 0 {
            let x = if row % 2 == 0 { 0.0 } else { 180.0 };
            writeln!(s, "Y{y:.4} Z{:.4}", z(x, y)).unwrap();
        }
        for i in 1..=nx {
            let i = if row % 2 == 0 { i } else { nx - i };
            let x = i as f64 * 1.2;
            writeln!(s, "X{x:.4} Z{:.4}", z(x, y)).unwrap();
        }
    }
    s.push_str("G0 Z25.\nM5\nG91 G28 Z0.\nG28 Y0.\nM30\n%\n");
    s
}

/// A 2D contour program (Fusion Fanuc-post style): rounded bosses and
/// circular islands at five depths, with tangent arcs, full circles in half
/// turns and a long outer contour.
fn contour_program() -> String {
    let mut s = String::from(
        "%\nO1003 (CONTOUR)\n(T3  D=8. CR=0. - ZMIN=-10. - FLAT END MILL)\nN10 G90 G94 G17\nN15 G21\nN20 G28 G91 Z0.\nN25 G90\nN30 T3 M6\nN35 S9000 M3\nN40 G54\nN45 G0 X-10. Y-10.\nN50 G43 Z15. H3\n",
    );
    for depth in 1..=10 {
        let z = -(depth as f64);
        // The outer contour: long sides with rounded corners.
        s.push_str("G0 X-10. Y-10.\nZ5.\n");
        writeln!(s, "G1 Z{z:.3} F300.\nG1 X-4. Y0. F1500.").unwrap();
        s.push_str("G3 X0. Y-4. I4. J0.\nG1 X200.\nG3 X204. Y0. I0. J4.\nG1 Y140.\nG3 X200. Y144. I-4. J0.\nG1 X0.\nG3 X-4. Y140. I0. J-4.\nG1 Y0.\nG0 Z5.\n");
        // Islands: rounded squares and circles on a grid.
        for gx in 0..6 {
            for gy in 0..4 {
                let (cx, cy) = (20.0 + 32.0 * gx as f64, 20.0 + 34.0 * gy as f64);
                if (gx + gy) % 2 == 0 {
                    let (h, r) = (8.0, 3.0);
                    writeln!(s, "G0 X{:.3} Y{:.3}", cx - h - 4.0, cy - h + r).unwrap();
                    writeln!(s, "G1 Z{z:.3} F300.").unwrap();
                    writeln!(s, "G1 X{:.3} F1500.", cx - h).unwrap();
                    writeln!(s, "Y{:.3}", cy + h - r).unwrap();
                    writeln!(s, "G2 X{:.3} Y{:.3} I{r:.3} J0.", cx - h + r, cy + h).unwrap();
                    writeln!(s, "G1 X{:.3}", cx + h - r).unwrap();
                    writeln!(s, "G2 X{:.3} Y{:.3} I0. J{:.3}", cx + h, cy + h - r, -r).unwrap();
                    writeln!(s, "G1 Y{:.3}", cy - h + r).unwrap();
                    writeln!(s, "G2 X{:.3} Y{:.3} I{:.3} J0.", cx + h - r, cy - h, -r).unwrap();
                    writeln!(s, "G1 X{:.3}", cx - h + r).unwrap();
                    writeln!(s, "G2 X{:.3} Y{:.3} I0. J{r:.3}", cx - h, cy - h + r).unwrap();
                } else {
                    let r = 9.0;
                    writeln!(s, "G0 X{:.3} Y{cy:.3}", cx - r - 4.0).unwrap();
                    writeln!(s, "G1 Z{z:.3} F300.").unwrap();
                    writeln!(s, "G1 X{:.3} F1500.", cx - r).unwrap();
                    writeln!(s, "G2 X{:.3} Y{cy:.3} I{r:.3} J0.", cx + r).unwrap();
                    writeln!(s, "X{:.3} Y{cy:.3} I{:.3} J0.", cx - r, -r).unwrap();
                }
                s.push_str("G0 Z5.\n");
            }
        }
    }
    s.push_str("G0 Z15.\nM5\nG28 G91 Z0.\nG90\nM30\n%\n");
    s
}

/// The bundled AFM R-1000.
fn afm() -> MachineTool {
    let text = std::fs::read_to_string(repo("machines/afm-r1000.yaml")).unwrap();
    let Machine::Tool(m) = Machine::from_yaml_str(&text, "afm").unwrap() else {
        panic!("not a machine tool")
    };
    m
}

/// The moves of a program, interpreted for `m`.
fn moves(m: &MachineTool, text: &str) -> Vec<Move> {
    let mut it = Interpreter::new(Setup::for_machine(m), "t");
    let mut b = Block::default();
    let mut out = vec![];
    for (i, l) in text.lines().enumerate() {
        parse_line(l.as_bytes(), i + 1, "t", &mut b).unwrap();
        let plan = it.step(&b, l.as_bytes()).unwrap();
        if let Some(mv) = plan.mv {
            out.push(mv);
        }
    }
    out
}

/// Distance from `p` to the programmed feed move `mv` (a segment, or a
/// helix: radially and along its axis at the same angle), mm.
fn dist_to_move(p: &Vector3<f64>, mv: &Move) -> f64 {
    let (s3, e3) = (mv.start3(), mv.end3());
    let Some(arc) = mv.arc else {
        let ab = e3 - s3;
        let t = if ab.norm_squared() > 0.0 {
            ((p - s3).dot(&ab) / ab.norm_squared()).clamp(0.0, 1.0)
        } else {
            0.0
        };
        return (s3 + ab * t - p).norm();
    };
    let (a, b, n) = arc.plane.axes();
    let c = arc.center;
    let a0 = (s3[b] - c[b]).atan2(s3[a] - c[a]);
    let phi = (p[b] - c[b]).atan2(p[a] - c[a]);
    let tau = std::f64::consts::TAU;
    // The parameter of the angle nearest the arc's range.
    let mut best = f64::INFINITY;
    for k in -2..=2 {
        let s = (phi + k as f64 * tau - a0) / arc.sweep;
        let sc = s.clamp(0.0, 1.0);
        let q = arc.point(&s3, &e3, sc);
        let d = if (0.0..=1.0).contains(&s) {
            let radial = (p[a] - c[a]).hypot(p[b] - c[b]) - arc.radius;
            radial.hypot(p[n] - q[n])
        } else {
            (p - q).norm()
        };
        best = best.min(d);
    }
    best
}

fn dirs_along(t: &Vector3<f64>, base: &[i8; 6]) -> [i8; 6] {
    let mut d = *base;
    for i in 0..3 {
        if t[i].abs() > 1e-9 {
            d[i] = if t[i] > 0.0 { 1 } else { -1 };
        }
    }
    d
}

/// Compensates `program` on the AFM R-1000 at its default tolerance and
/// checks the size and the attained path of the output.
fn check_compact(name: &str, program: &str, with_arcs: bool) {
    let m = afm();
    let tol = m
        .compensation_tolerance_mm()
        .expect("the bundled machine gives a tolerance");
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join(name);
    std::fs::write(&path, program).unwrap();
    let out = postproc()
        .args([
            "compensate",
            "--machine",
            "afm-r1000",
            "--effects",
            "geometric",
        ])
        .args(["--annotate", "none", "-o", "-"])
        .arg(&path)
        .current_dir(repo(""))
        .assert()
        .success()
        .get_output()
        .clone();
    let text = String::from_utf8(out.stdout).unwrap();
    let (n_in, n_out) = (program.lines().count(), text.lines().count());
    assert!(n_in > 2000, "{name}: {n_in} lines");
    assert!(
        n_out <= 2 * n_in,
        "{name}: {n_out} lines from {n_in}: more than twice"
    );
    let programmed: Vec<Move> = moves(&m, program)
        .into_iter()
        .filter(|mv| mv.motion != Motion::Rapid)
        .collect();
    let written = moves(&m, &text);
    let mut at = 0usize;
    let (mut checked, mut arcs, mut worst) = (0usize, 0usize, 0.0f64);
    for mv in written.iter().filter(|mv| mv.motion != Motion::Rapid) {
        let tool = mv.tool_len_mm;
        let (s3, e3) = (mv.start3(), mv.end3());
        // Takeups: only their end is on the path (the next move's start).
        if mv.arc.is_none() && (e3 - s3).norm() < TAKEUP_LEN_MM {
            continue;
        }
        let from = at;
        let window = from.saturating_sub(2)..(from + 3).min(programmed.len());
        let near = |p: &Vector3<f64>| {
            window
                .clone()
                .map(|k| (k, dist_to_move(p, &programmed[k])))
                .fold((from, f64::INFINITY), |b, x| if x.1 < b.1 { x } else { b })
        };
        // An axis the written move moves by microns only (a correction)
        // keeps the direction the programmed path gives it.
        // (the programmed move it belongs to: the one nearest its middle).
        let mut middle = mv.start;
        for (i, v) in middle.iter_mut().enumerate() {
            *v = (*v + mv.end[i]) / 2.0;
        }
        if let Some(arc) = mv.arc {
            let q = arc.point(&s3, &e3, 0.5);
            middle[..3].copy_from_slice(&[q[0], q[1], q[2]]);
        }
        let (owner, _) = near(&m.geometric(&middle, &mv.dirs, tool).pos);
        let base = programmed[owner].dirs;
        let mut step = e3 - s3;
        for v in step.iter_mut() {
            if v.abs() < TAKEUP_LEN_MM {
                *v = 0.0;
            }
        }
        let line_dirs = dirs_along(&step, &base);
        let points: Vec<(f64, [i8; 6])> = match mv.arc {
            None => (0..=LINE_SAMPLES)
                .map(|k| (k as f64 / LINE_SAMPLES as f64, line_dirs))
                .collect(),
            Some(arc) => {
                arcs += 1;
                let k = ((arc.sweep.abs() / ARC_STEP_RAD).ceil() as usize).max(4);
                // Near a quadrant point an axis moves by nanometres: it
                // keeps the direction it has in the middle of the piece.
                let still = |mut t: Vector3<f64>| {
                    for v in t.iter_mut() {
                        if v.abs() < QUADRANT_TANGENT {
                            *v = 0.0;
                        }
                    }
                    t
                };
                let mid = dirs_along(&still(arc.tangent(&s3, &e3, 0.5)), &base);
                (0..=k)
                    .map(|j| {
                        let f = j as f64 / k as f64;
                        (f, dirs_along(&still(arc.tangent(&s3, &e3, f)), &mid))
                    })
                    .collect()
            }
        };
        for (f, dirs) in points {
            let mut c = mv.start;
            for (i, ci) in c.iter_mut().enumerate() {
                *ci += (mv.end[i] - mv.start[i]) * f;
            }
            if let Some(arc) = mv.arc {
                let q = arc.point(&s3, &e3, f);
                c[0] = q[0];
                c[1] = q[1];
                c[2] = q[2];
            }
            let got = m.geometric(&c, &dirs, tool).pos;
            let (k, d) = near(&got);
            assert!(
                d <= tol + WORD_ALLOWANCE_MM,
                "{name}: {d:.6} mm off the path at {c:?} with {dirs:?} (written move to {:?}, nearest programmed move {k} of dirs {:?})",
                mv.end,
                programmed[k].dirs
            );
            worst = worst.max(d);
            if f == 1.0 {
                at = at.max(k);
            }
            checked += 1;
        }
    }
    assert!(checked > 1000, "{name}: {checked} points checked");
    assert!(
        worst.is_finite() && text != program,
        "{name}: not compensated"
    );
    eprintln!("{name}: {n_in} → {n_out} lines, worst {worst:.6} mm");
    if with_arcs {
        assert!(arcs > 50, "{name}: {arcs} arcs written");
    }
}

#[test]
fn a_pocket_with_helical_bores_stays_compact_and_within_the_tolerance() {
    check_compact("pocket.nc", &pocket_program(), true);
}

#[test]
fn a_surfacing_program_stays_compact_and_within_the_tolerance() {
    check_compact("surfacing.nc", &surfacing_program(), false);
}

#[test]
fn a_contour_program_stays_compact_and_within_the_tolerance() {
    check_compact("contour.nc", &contour_program(), true);
}
