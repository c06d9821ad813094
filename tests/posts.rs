//! Programs in the style of the posts real shops run: a Fusion 360 Haas
//! program with G187 smoothing, G103, G154/G110 work offsets and G30,
//! machine-axis five-axis programs for the AC trunnion (with G93 inverse-time
//! feed) and the B-head/C-table machine, and an inch program without G20 on
//! a control whose default unit is the inch. Each is read back byte for byte
//! with every effect off and compensated to a program that the interpreter
//! takes again and that reaches the programmed points.

use std::fs;

use postproc::machine::Machine;
use postproc::machine::tool::MachineTool;
use postproc::program::gcode::{Block, parse_line};
use postproc::program::interp::{Interpreter, Motion, Plan, Setup};

use crate::common::{postproc, repo};

/// Largest miss of a programmed five-axis point by the compensated program's
/// attained point, mm: the words' resolution (4 decimals on X Y Z, 6 on the
/// rotary axes, at most 0.09 µm together at the samples' lever arms).
const WORD_TOL_MM: f64 = 0.0001;

/// Largest difference of a G93 block's duration before and after
/// compensation, relative: the F words' last digit.
const DURATION_TOL: f64 = 1e-3;

fn machine(text: &str) -> MachineTool {
    match Machine::from_yaml_str(text, "m.yaml").expect("machine loads") {
        Machine::Tool(m) => m,
        Machine::Robot(_) => panic!("not a machine tool"),
    }
}

/// Interprets `program` on `m`; every plan in order.
fn plans(m: &MachineTool, program: &str) -> Vec<Plan> {
    let mut interp = Interpreter::new(Setup::for_machine(m), "p.nc");
    let mut block = Block::default();
    let mut out = Vec::new();
    for (i, line) in program.split_inclusive('\n').enumerate() {
        if let Err(e) = parse_line(line.as_bytes(), i + 1, "p.nc", &mut block) {
            panic!("{e}");
        }
        match interp.step(&block, line.as_bytes()) {
            Ok(p) => out.push(p),
            Err(e) => panic!("{e}"),
        }
    }
    out
}

/// `postproc compensate` of a repository program on a machine file, with
/// extra arguments; standard output.
fn compensate(program: &str, machine_file: &std::path::Path, extra: &[&str]) -> Vec<u8> {
    let out = postproc()
        .arg("compensate")
        .arg(repo(program))
        .arg("--machine")
        .arg(machine_file)
        .args(extra)
        .args(["-o", "-"])
        .output()
        .expect("runs");
    // Exit 1 only for holes warned about: a hole has one X and Y for its
    // depth, which a tolerance of a fraction of a micron may not hold.
    let stderr = String::from_utf8_lossy(&out.stderr);
    let beyond: Vec<&str> = stderr
        .lines()
        .filter(|l| l.contains("WARN") && l.contains("beyond the tolerance"))
        .collect();
    let holes_only = !beyond.is_empty()
        && beyond
            .iter()
            .all(|l| l.contains("the hole, drilled at one X and Y"));
    let want = if holes_only { Some(1) } else { Some(0) };
    assert_eq!(out.status.code(), want, "{program}: {stderr}");
    // The provenance header is checked by its own tests.
    crate::common::without_header(&out.stdout)
}

/// The post-style samples and their machines.
const SAMPLES: [(&str, &str); 4] = [
    ("samples/head-table.nc", "machines/head-table-bc.yaml"),
    ("samples/five-axis-g93.nc", "machines/five-axis-ac.yaml"),
    ("samples/five-axis.nc", "machines/five-axis-ac.yaml"),
    ("samples/fusion-haas.nc", "machines/afm-r1000.yaml"),
];

#[test]
fn post_style_programs_come_back_byte_for_byte_with_effects_off() {
    for (program, m) in SAMPLES {
        let out = compensate(
            program,
            &repo(m),
            &["--effects", "none", "--annotate", "none"],
        );
        assert!(
            out == fs::read(repo(program)).expect("sample"),
            "{program} changed"
        );
    }
}

#[test]
fn post_style_programs_compensate_to_their_programmed_points() {
    for (program, file) in SAMPLES {
        let m = machine(&fs::read_to_string(repo(file)).expect("machine file"));
        let text = fs::read_to_string(repo(program)).expect("sample");
        // Geometry alone: the prediction the check below repeats, at a
        // tolerance tight enough that neither the output decimals nor the
        // cycle words kept within a quarter of it (docs/compensation.md)
        // leave a point more than WORD_TOL_MM off.
        let out = compensate(
            program,
            &repo(file),
            &[
                "--effects",
                "geometric",
                "--annotate",
                "none",
                "--tolerance",
                "0.0002",
            ],
        );
        let out = String::from_utf8(out).expect("text");
        assert_ne!(out, text, "{program}: nothing compensated");
        let before = plans(&m, &text);
        let after = plans(&m, &out);
        let ends = |ps: &[Plan]| -> Vec<postproc::program::interp::Move> {
            ps.iter()
                .filter_map(|p| p.mv)
                .filter(|mv| mv.motion == Motion::Linear)
                .collect()
        };
        let (want, got) = (ends(&before), ends(&after));
        assert!(want.len() >= 5, "{program}");
        for mv in &want {
            let tip = m.nominal(&mv.end, mv.tool_len_mm);
            let best = got
                .iter()
                .map(|g| {
                    // With the directions the interpreter reads from the compensated
                    // program (docs/compensation.md, *Directions of motion*).
                    let at = m.geometric(&g.end, &g.dirs, mv.tool_len_mm);
                    (at.pos - tip.pos).norm()
                })
                .fold(f64::INFINITY, f64::min);
            assert!(
                best <= WORD_TOL_MM,
                "{program}: programmed point {:?} missed by {best} mm",
                mv.end
            );
        }
    }
}

/// Duration of each G93 feed block, s, in program order.
fn inverse_time_durations(ps: &[Plan]) -> Vec<f64> {
    ps.iter()
        .filter(|p| p.inverse_time)
        .filter_map(|p| p.mv)
        .map(|mv| mv.timed_length() / mv.feed_mm_min * 60.0)
        .collect()
}

#[test]
fn g93_blocks_keep_their_duration_when_compensated() {
    let (program, file) = SAMPLES[1];
    let m = machine(&fs::read_to_string(repo(file)).expect("machine file"));
    let text = fs::read_to_string(repo(program)).expect("sample");
    // A tight tolerance splits the moves: every piece needs its own F.
    let out = compensate(
        program,
        &repo(file),
        &["--annotate", "none", "--tolerance", "0.0002"],
    );
    let out = String::from_utf8(out).expect("text");
    let before = inverse_time_durations(&plans(&m, &text));
    // The interpreter refuses a G93 feed line without F: the output has one
    // on every piece.
    let after = inverse_time_durations(&plans(&m, &out));
    assert!(
        after.len() > before.len(),
        "no G93 move was split ({} lines)",
        after.len()
    );
    let total = |d: &[f64]| d.iter().sum::<f64>();
    let (t0, t1) = (total(&before), total(&after));
    assert!(
        (t1 - t0).abs() <= DURATION_TOL * t0,
        "G93 time {t0} s became {t1} s"
    );
}

#[test]
fn an_inch_program_without_g20_is_read_in_the_controls_default_unit() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let afm = fs::read_to_string(repo("machines/afm-r1000.yaml")).expect("afm");
    assert!(afm.contains("\nunits_default: mm\n"));
    let write = |name: &str, text: &str| {
        let p = tmp.path().join(name);
        fs::write(&p, text).expect("write");
        p
    };
    let inch_machine = write(
        "inch.yaml",
        &afm.replace("\nunits_default: mm\n", "\nunits_default: inch\n"),
    );
    let bare_machine = write("bare.yaml", &afm.replace("\nunits_default: mm\n", "\n"));
    let program = "samples/inch-default.nc";
    let text = fs::read_to_string(repo(program)).expect("sample");
    assert!(!text.contains("G20") && !text.contains("G21"));
    // Identity with every effect off.
    let same = compensate(
        program,
        &inch_machine,
        &["--effects", "none", "--annotate", "none"],
    );
    assert!(same == text.as_bytes(), "changed with effects off");
    // On the inch control the program is the one with G20 written in it.
    let got = String::from_utf8(compensate(program, &inch_machine, &[])).expect("text");
    let with_g20 = text.replacen("\nG0 G17", "\nG20\nG0 G17", 1);
    let g20 = write("g20.nc", &with_g20);
    let out = postproc()
        .arg("compensate")
        .arg(&g20)
        .args(["--machine", "afm-r1000", "-o", "-"])
        .output()
        .expect("runs");
    assert_eq!(out.status.code(), Some(0));
    let want = String::from_utf8(crate::common::without_header(&out.stdout))
        .expect("text")
        .replacen("\nG20\n", "\n", 1);
    assert_eq!(got, want);
    // `--units inch` does the same on a machine file without a default.
    let flagged =
        String::from_utf8(compensate(program, &bare_machine, &["--units", "inch"])).expect("text");
    assert_eq!(flagged, want);
    // Without a default the program is refused at its first length.
    let out = postproc()
        .arg("check")
        .arg(repo(program))
        .arg("--machine")
        .arg(&bare_machine)
        .output()
        .expect("runs");
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("inch-default.nc:5:9"), "{err}");
    assert!(err.contains("units_default"), "{err}");
}

/// Program coordinates (X, Y, Z, then the two rotary axes) of the twin
/// path: a tilted, turning sweep like a five-axis finishing pass.
const TWIN_PATH: [[f64; 5]; 5] = [
    [-40.0, -20.0, 20.0, 15.0, 0.0],
    [40.0, -20.0, 20.0, 15.0, 30.0],
    [40.0, 20.0, 22.0, 30.0, 60.0],
    [-40.0, 20.0, 24.0, 25.0, 90.0],
    [-20.0, 30.0, 10.0, -20.0, 120.0],
];

/// The twin path as a machine-axis program (`tcpm` false) or as a tool
/// centre point program (the nominal tool tips of the same axis positions
/// under G43.4) on `m` with G54 and H1.
fn twin_program(m: &MachineTool, rotary: [usize; 2], tcpm: bool) -> String {
    let tool = m.tool_length_mm(1).expect("H1");
    let g54 = m.work_offset_mm("G54").expect("G54");
    let letters = *b"XYZABC";
    let mut text = String::from("%\nG90 G17 G21 G40 G49 G80 G94\nT1 M6\nS10000 M3\n");
    text.push_str(if tcpm { "G43.4 H1\n" } else { "G43 H1\n" });
    for (i, p) in TWIN_PATH.iter().enumerate() {
        let mut cmd = [0.0; 6];
        for k in 0..3 {
            cmd[k] = p[k] + g54[k];
        }
        cmd[rotary[0]] = p[3];
        cmd[rotary[1]] = p[4];
        let words = if tcpm { m.tip_of(&cmd, tool) } else { cmd };
        text.push_str(if i == 0 { "G0" } else { "G1" });
        for k in 0..3 {
            text.push_str(&format!(" {}{:.4}", letters[k] as char, words[k] - g54[k]));
        }
        for r in rotary {
            text.push_str(&format!(" {}{:.4}", letters[r] as char, words[r]));
        }
        text.push_str(if i == 1 { " F1000.\n" } else { "\n" });
    }
    text.push_str("G49\nM30\n%\n");
    text
}

/// Largest miss of a programmed tip by a compensated tool centre point
/// program, mm: its tip words are the forward kinematics of the compensated
/// axis positions rounded to 4 decimals, and the control's inverse
/// kinematics of the rounded tip and rotary words is rounded once more, so
/// twice the word resolution.
const TCPM_WORD_TOL_MM: f64 = 2.0 * WORD_TOL_MM;

/// Attained tool tips of twin programs agree within this, mm: each is
/// within [`TCPM_WORD_TOL_MM`] of its own programmed tip, and the two
/// programmed tips differ by the rounding of the tip words to 4 decimals.
const TWIN_TOL_MM: f64 = 3.0 * WORD_TOL_MM;

#[test]
fn machine_axis_and_tcpm_twins_compensate_to_the_same_tips() {
    let tmp = tempfile::tempdir().expect("temp dir");
    for (file, rotary) in [
        ("machines/five-axis-ac.yaml", [3, 5]),
        ("machines/head-table-bc.yaml", [4, 5]),
    ] {
        let m = machine(&fs::read_to_string(repo(file)).expect("machine file"));
        let mut attained: Vec<Vec<nalgebra::Vector3<f64>>> = Vec::new();
        for tcpm in [false, true] {
            let text = twin_program(&m, rotary, tcpm);
            let input = tmp.path().join("twin.nc");
            fs::write(&input, &text).expect("write");
            let out = postproc()
                .arg("compensate")
                .arg(&input)
                .arg("--machine")
                .arg(repo(file))
                // Rotary words at 6 decimals, the word resolution the
                // tolerances above are for.
                .args([
                    "--effects",
                    "geometric",
                    "--annotate",
                    "none",
                    "--decimals",
                    "6",
                    "-o",
                    "-",
                ])
                .output()
                .expect("runs");
            assert_eq!(
                out.status.code(),
                Some(0),
                "{file} tcpm {tcpm}: {}",
                String::from_utf8_lossy(&out.stderr)
            );
            let out = String::from_utf8(out.stdout).expect("text");
            assert_ne!(out, text, "{file} tcpm {tcpm}: nothing compensated");
            let want: Vec<_> = plans(&m, &text).into_iter().filter_map(|p| p.mv).collect();
            let got: Vec<_> = plans(&m, &out).into_iter().filter_map(|p| p.mv).collect();
            assert_eq!(want.len(), TWIN_PATH.len());
            let mut tips = Vec::new();
            for mv in want.iter().skip(1) {
                let goal = m.nominal(&mv.end, mv.tool_len_mm).pos;
                let best = got
                    .iter()
                    .map(|g| m.geometric(&g.end, &g.dirs, mv.tool_len_mm).pos)
                    .min_by(|a, b| (a - goal).norm().total_cmp(&(b - goal).norm()))
                    .expect("moves");
                let tol = if tcpm { TCPM_WORD_TOL_MM } else { WORD_TOL_MM };
                assert!(
                    (best - goal).norm() <= tol,
                    "{file} tcpm {tcpm}: {:?} missed by {} mm",
                    mv.end,
                    (best - goal).norm()
                );
                tips.push(best);
            }
            attained.push(tips);
        }
        for (a, b) in attained[0].iter().zip(&attained[1]) {
            assert!((a - b).norm() <= TWIN_TOL_MM, "{file}: {a:?} vs {b:?}");
        }
    }
}
