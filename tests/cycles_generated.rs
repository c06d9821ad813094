//! Generated canned-cycle programs (issue 43): rows of holes under G91
//! (incremental) and G90 (absolute), G98 and G99, each cycle the writer knows, deep and
//! shallow, compensated in process with and without writing holes as
//! moves. Each program is processed or refused cleanly; read back by the
//! forward pass (the interpreter and the predictor, not the solver), its
//! output ends where its input does, and every written hole feed lies
//! within the tolerance of its programmed hole: always where the hole may
//! be written as moves, else (a tap, a bore that stops the spindle, no
//! expansion allowed) unless the run counted a block beyond it.
//! `HOSTILE_MUTANTS` sets the count (`scripts/hostile`).

use crate::spiral::machine;
use postproc::pipeline::gcode::Job;
use postproc::program::interp::PlanKind;

/// Programs per run in the test suite (`HOSTILE_MUTANTS` overrides).
const CI_PROGRAMS: usize = 60;

/// Tolerance of the runs, mm.
const TOL_MM: f64 = 0.003;

/// Floating-point allowance of the comparison with the tolerance, mm.
const FLOAT_MM: f64 = 1e-9;

/// How far the written program's end may be from the programmed one
/// (commanded machine positions: the compensation itself), mm.
const END_MM: f64 = 0.05;

/// A small deterministic generator (SplitMix64).
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
    /// A whole number of mm in `lo..=hi`.
    fn mm(&mut self, lo: i64, hi: i64) -> i64 {
        lo + self.below((hi - lo + 1) as usize) as i64
    }
}

/// The cycles generated, with the words each needs besides R and Z.
const CYCLES: &[(&str, &str)] = &[
    ("G81", ""),
    ("G82", " P300"),
    ("G83", " Q7."),
    ("G73", " Q9."),
    ("G85", ""),
    ("G89", " P200"),
    ("G84", ""),
    ("G86", ""),
];

/// One generated program: the part's zero at G54 (work Z0 = machine
/// Z150 plus the tool), an initial level 40–250 mm above it, a row of 1–6 holes of
/// one or two cycles with incremental or absolute levels, then `G80` and
/// incremental moves that count from where the cycle left the tool.
fn program(rng: &mut Rng, incremental: bool) -> String {
    let mut p = String::from("%\nG21 G17 G90 G94 G40 G49 G80\nT1 M6\nS1000 M3\n");
    let (x0, y0) = (rng.mm(50, 200), rng.mm(50, 200));
    let initial = rng.mm(40, 250);
    p += &format!("G0 G54 X{x0}. Y{y0}.\nG43 Z{initial}. H1\n");
    let holes = 1 + rng.below(6);
    let (mut x, mut y) = (x0, y0);
    for i in 0..holes {
        let (dx, dy) = (rng.mm(-30, 30), rng.mm(-30, 30));
        let (nx, ny) = (x + dx, y + dy);
        if !(10..=500).contains(&nx) || !(10..=300).contains(&ny) {
            continue;
        }
        let xy = if incremental {
            format!("X{dx}. Y{dy}.")
        } else {
            format!("X{nx}. Y{ny}.")
        };
        (x, y) = (nx, ny);
        let retract = if rng.below(2) == 0 { "G98" } else { "G99" };
        let first = i == 0 || rng.below(4) == 0;
        if first {
            let (code, extra) = CYCLES[rng.below(CYCLES.len())];
            let r = rng.mm(1, 5);
            let depth = rng.mm(2, 90);
            let levels = if incremental {
                format!("Z-{depth}. R-{}.", initial - r)
            } else {
                format!("Z{}. R{r}.", r - depth)
            };
            let mode = if incremental { "G91 " } else { "G90 " };
            p += &format!("{mode}{retract} {code} {xy} {levels}{extra} F100.\n");
        } else if rng.below(3) == 0 {
            let depth = rng.mm(2, 90);
            p += &format!("{retract} {xy} Z-{depth}.\n");
        } else {
            p += &format!("{xy}\n");
        }
    }
    p += "G80\n";
    if incremental {
        p += &format!("G91 G0 X{}.\nG1 Z-{}. F200.\n", rng.mm(-5, 5), rng.mm(1, 5));
    }
    p += &format!("G90 G0 Z{initial}.\nM30\n%\n");
    p
}

/// The job of the runs: geometric effects, holes written as moves or not.
fn job(m: &postproc::machine::tool::MachineTool, expand: bool) -> Job<'_> {
    let mut job = crate::repredict::job(m, "geometric", TOL_MM);
    job.setup.expand_cycles = expand;
    job
}

/// Checks one program; `Ok(false)` when it is refused (cleanly).
fn check(
    m: &postproc::machine::tool::MachineTool,
    text: &str,
    expand: bool,
) -> Result<bool, String> {
    let job = job(m, expand);
    let mut out = Vec::new();
    let summary = match job.run(text.as_bytes(), "g.nc", Some(&mut out), None) {
        Ok(s) => s,
        Err(e) => {
            let msg = e.to_string();
            return if msg.contains("g.nc:") {
                Ok(false)
            } else {
                Err(format!("refused without a place: {msg}"))
            };
        }
    };
    let output = String::from_utf8(out).map_err(|_| "output not UTF-8".to_string())?;
    let mut back = Vec::new();
    job.forward(output.as_bytes(), "out.nc", &mut |_, plan, _| {
        back.push(*plan)
    })
    .map_err(|e| format!("the output is refused by its reader: {e}"))?;
    let mut input = Vec::new();
    job.forward(text.as_bytes(), "g.nc", &mut |line, plan, _| {
        input.push((line, *plan))
    })
    .map_err(|e| format!("input read: {e}"))?;
    let end = |plans: &mut dyn Iterator<Item = &postproc::program::interp::Plan>| {
        plans.filter_map(|p| p.mv).last().map(|mv| mv.end)
    };
    let (a, b) = (
        end(&mut input.iter().map(|(_, p)| p)).ok_or("no move")?,
        end(&mut back.iter()).ok_or("no move written")?,
    );
    if (0..3).any(|k| (a[k] - b[k]).abs() > END_MM) {
        return Err(format!("the output ends at {b:?}, the input at {a:?}"));
    }
    // Each hole, and whether it may be written as moves.
    let holes: std::collections::HashMap<usize, bool> = input
        .iter()
        .filter(|(_, p)| matches!(p.kind, PlanKind::Cycle { .. }))
        .map(|(l, p)| (*l, p.cycle.expandable))
        .collect();
    for (src, _, miss) in crate::repredict::misses(&job, text, &output) {
        let Some(&expandable) = holes.get(&src) else {
            continue;
        };
        if miss <= TOL_MM + FLOAT_MM {
            continue;
        }
        // A hole that may be written as moves is written within the
        // tolerance; one that may not (a tap, a bore that stops the
        // spindle, no expansion allowed) is warned about.
        if expandable {
            return Err(format!(
                "line {src}: a hole written as moves misses by {miss:.6} mm"
            ));
        }
        if summary.beyond.count == 0 {
            return Err(format!(
                "line {src}: a hole feed misses by {miss:.6} mm, unwarned"
            ));
        }
    }
    Ok(true)
}

/// Runs `HOSTILE_MUTANTS` (or [`CI_PROGRAMS`]) generated programs with
/// incremental (G91) or absolute (G90) hole positions and levels.
fn run(incremental: bool, seed: u64) {
    let count = std::env::var("HOSTILE_MUTANTS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(CI_PROGRAMS);
    let m = machine("afm-r1000");
    let mut rng = Rng(seed);
    let start = std::time::Instant::now();
    let (mut accepted, mut findings) = (0, Vec::new());
    for i in 0..count {
        let text = program(&mut rng, incremental);
        let expand = i % 2 == 1;
        let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| check(&m, &text, expand)));
        match r {
            Ok(Ok(ok)) => accepted += usize::from(ok),
            Ok(Err(e)) => findings.push(format!("{e} (expand {expand})\n{text}")),
            Err(_) => findings.push(format!("panic (expand {expand})\n{text}")),
        }
    }
    let kind = if incremental {
        "incremental"
    } else {
        "absolute"
    };
    eprintln!(
        "\nhostile {kind}-cycles: {count} programs ({accepted} accepted) in {:.1} s, {} findings",
        start.elapsed().as_secs_f64(),
        findings.len()
    );
    assert!(accepted * 2 >= count, "{accepted} of {count} accepted");
    assert!(
        findings.is_empty(),
        "{}",
        findings
            .iter()
            .take(3)
            .cloned()
            .collect::<Vec<_>>()
            .join("\n")
    );
}

#[test]
fn generated_incremental_cycle_programs_land_within_the_tolerance_where_written_as_moves() {
    run(true, 0xC1C1E5);
}

#[test]
fn generated_absolute_cycle_programs_land_within_the_tolerance_where_written_as_moves() {
    run(false, 0xA6C1E5);
}

/// Machine Z where the last move before the `G80` line of `text` ends
/// (read by the forward pass).
fn z_before_g80(job: &Job, text: &str) -> f64 {
    let g80 = 1 + text
        .lines()
        .position(|l| l.starts_with("G80"))
        .expect("G80");
    let mut z = f64::NAN;
    job.forward(text.as_bytes(), "t.nc", &mut |line, plan, _| {
        if let (true, Some(mv)) = (line < g80, plan.mv) {
            z = match plan.kind {
                PlanKind::Cycle { retract, .. } => retract,
                _ => mv.end[2],
            };
        }
    })
    .expect("forward");
    z
}

/// A G98 hole right after a G99 hole returns to the cycle's initial level
/// (Fanuc, Haas), not to the R level the G99 hole left the tool at: where
/// the written holes leave the tool before `G80` is where the programmed
/// ones do, holes written as moves or as the cycle. Deep G85 holes, so
/// that they are written as moves when allowed (their way out written).
#[test]
fn a_g98_hole_after_a_g99_hole_returns_to_the_initial_level() {
    let m = machine("afm-r1000");
    let text = "%\nG21 G17 G90 G94 G40 G49 G80\nT1 M6\nS1000 M3\n\
                G0 G54 X100. Y100.\nG43 Z150. H1\n\
                G99 G85 X110. Y100. Z-80. R2. F100.\n\
                G98 X130. Y100. Z-80.\nG80\nG91 G1 X5. F200.\nM30\n%\n";
    for expand in [true, false] {
        assert_eq!(check(&m, text, expand), Ok(true), "expand {expand}");
        let job = job(&m, expand);
        let mut out = Vec::new();
        job.run(text.as_bytes(), "t.nc", Some(&mut out), None)
            .expect("compensates");
        let out = String::from_utf8(out).expect("UTF-8");
        let (want, got) = (z_before_g80(&job, text), z_before_g80(&job, &out));
        assert!(
            (want - got).abs() <= END_MM,
            "expand {expand}: the written holes leave Z{got}, the programmed Z{want}\n{out}"
        );
    }
}

/// Compensates `text` with holes written as moves: the number of blocks
/// the run counted beyond the tolerance, and the output.
fn beyond(m: &postproc::machine::tool::MachineTool, text: &str) -> (usize, String) {
    let job = job(m, true);
    let mut out = Vec::new();
    let summary = job
        .run(text.as_bytes(), "t.nc", Some(&mut out), None)
        .expect("compensates");
    (summary.beyond.count, String::from_utf8(out).expect("UTF-8"))
}

/// A G89 hole written as moves on the default three decimals: the Z
/// squareness moves X and Y by 0.4 µm on each feed piece, against the
/// directions the positioning left (regression: written with three
/// decimals, a piece stepped by 0.001 mm, a whole direction deadband,
/// which the forward pass read as a reversal, 5.3 µm off the hole). The
/// hole's X and Y are written with four decimals: every piece within the
/// tolerance, none counted beyond it.
#[test]
fn a_g89_hole_written_as_moves_is_within_the_tolerance() {
    let m = machine("afm-r1000");
    let text = "%\nG21 G17 G90 G94 G40 G49 G80\nT1 M6\nS1000 M3\n\
                G0 G54 X128. Y81.\nG43 Z172. H1\n\
                G90 G99 G89 X111. Y79. Z-59. R2. P200 F100.\nG80\n\
                G90 G0 Z172.\nM30\n%\n";
    assert_eq!(check(&m, text, true), Ok(true));
    let (count, out) = beyond(&m, text);
    assert_eq!(count, 0, "{out}");
    assert!(out.contains("\nG1 X110.9888 Y78.9896 Z-5.622\n"), "{out}");
}

/// A G83 hole after a G99 G82 hole whose solve and positioning never
/// agree: solved with X moving +, the positioning reverses X (−2.3 µm);
/// solved with X moving −, it moves X +0.6 µm, less than the deadband,
/// and leaves it moving + (regression: every feed 3.24 µm off the hole,
/// unwarned). The positioning approaches the hole from the side the hole
/// is solved with: a `G0` to 5 µm before it in X, then the hole's X.
#[test]
fn a_hole_whose_positioning_reverses_its_solve_is_approached_from_one_side() {
    let m = machine("afm-r1000");
    let text = "%\nG21 G17 G90 G94 G40 G49 G80\nT1 M6\nS1000 M3\n\
                G0 G54 X143. Y148.\nG43 Z94. H1\n\
                G90 G99 G82 X143. Y160. Z-49. R3. P300 F100.\n\
                G90 G98 G83 X143. Y171. Z-85. R5. Q7. F100.\nG80\n\
                G90 G0 Z94.\nM30\n%\n";
    assert_eq!(check(&m, text, true), Ok(true));
    let (count, out) = beyond(&m, text);
    assert_eq!(count, 0, "{out}");
    let lines: Vec<&str> = out.lines().collect();
    let at = lines
        .iter()
        .position(|l| l.starts_with("G90 G98 G0 X"))
        .expect("the G83 hole's positioning");
    // 5 µm below the hole's X, then up to it (Y as positioned).
    let x = |l: &str| -> f64 {
        let w = l.split(' ').find(|w| w.starts_with('X')).expect("X");
        w[1..].parse().expect("number")
    };
    assert!(lines[at + 1].starts_with("G0 X"), "{out}");
    assert!(!lines[at + 1].contains('Y'), "{out}");
    let step = x(lines[at + 1]) - x(lines[at]);
    assert!((step - 0.005).abs() < 1e-9, "{step}\n{out}");
}

/// A G89 hole drilled at one X and Y after another G89 hole, 1 µm apart
/// in X as written on three decimals (`X187.994` then `X187.993`): read
/// back, X may or may not reverse (regression: solved without the
/// reversal, read with it, 4.36 µm off the hole, unwarned). Measured
/// under both readings, the hole is written as moves, within the
/// tolerance.
#[test]
fn a_hole_whose_written_positioning_may_reverse_an_axis_is_measured_both_ways() {
    let m = machine("afm-r1000");
    let text = "%\nG21 G17 G90 G94 G40 G49 G80\nT1 M6\nS1000 M3\n\
                G0 G54 X179. Y117.\nG43 Z242. H1\n\
                G90 G98 G89 X162. Y138. Z-50. R1. P200 F100.\n\
                G98 X188. Y135. Z-21.\nX188. Y124.\nG80\n\
                G90 G0 Z242.\nM30\n%\n";
    assert_eq!(check(&m, text, true), Ok(true));
    let (count, out) = beyond(&m, text);
    assert_eq!(count, 0, "{out}");
}
