//! Shop G-code: subprograms (`M98`/`M99` in the same file, LinuxCNC
//! `o<name> sub`/`call` and `o100 repeat`) followed through `check`,
//! `report` and `compensate` on programs written for this project in the
//! style of each control (tests/shop/): identity byte for byte, the
//! structure of the compensated output, every target attained again when
//! the output is predicted anew, and refusals by name.

use std::path::{Path, PathBuf};

use crate::common::{postproc, repo, without_header, write};
use crate::repredict::{Row, dist, report_with};

/// Tolerance of the compensation in these runs, mm (the machine file's).
const TOLERANCE_MM: f64 = 0.003;

/// The bundled three-axis machine with a work offset and tool length that
/// keep every program inside its travel.
const MACHINE: [&str; 6] = [
    "--machine",
    "afm-r1000",
    "--work-offset",
    "G54=100,50,200",
    "--tool",
    "H1=100",
];

fn program(name: &str) -> PathBuf {
    repo(&format!("tests/shop/{name}"))
}

/// `compensate` of `input` into `dir`: the output's bytes and stderr.
fn compensate(input: &Path, dir: &Path, extra: &[&str]) -> (Vec<u8>, String) {
    let out = dir.join("out.nc");
    let a = postproc()
        .arg("compensate")
        .args(MACHINE)
        .args(extra)
        .arg(input)
        .arg("-o")
        .arg(&out)
        .assert()
        .success();
    let stderr = String::from_utf8_lossy(&a.get_output().stderr).to_string();
    (std::fs::read(&out).expect("output written"), stderr)
}

#[test]
fn shop_programs_are_written_back_byte_for_byte_with_no_effects() {
    let dir = tempfile::tempdir().expect("tempdir");
    for name in [
        "haas_sub_four.nc",
        "haas_sub_repeat.nc",
        "linuxcnc_pocket.ngc",
        "fanuc_bolt_circle.nc",
        "plasma_no_z.nc",
        "inch_without_g20.nc",
        "linuxcnc_while_pocket.ngc",
        "macro_words_kept.nc",
    ] {
        let input = program(name);
        let (out, stderr) = compensate(
            &input,
            dir.path(),
            &["--effects", "none", "--annotate", "none"],
        );
        let original = std::fs::read(&input).expect("read");
        assert!(
            without_header(&out) == original,
            "{name}: identity differs:\n{}",
            String::from_utf8_lossy(&out)
        );
        let subprograms = !matches!(name, "plasma_no_z.nc" | "inch_without_g20.nc");
        assert!(
            stderr.contains("0 copies") == subprograms && !stderr.contains("written out"),
            "{name}: {stderr}"
        );
    }
}

#[test]
fn check_follows_every_call() {
    // Main program: 5 rapids and moves before and between the calls, 4
    // calls of 8 moves each.
    let a = postproc()
        .arg("check")
        .args(MACHINE)
        .arg(program("haas_sub_four.nc"))
        .assert()
        .success();
    let stdout = String::from_utf8_lossy(&a.get_output().stdout).to_string();
    assert!(
        stdout.contains("31 lines, 46 blocks, 36 moves (16 rapid, 20 feed"),
        "{stdout}"
    );
    // Extents: the fourth pocket ends at X100+40 work, +100 offset.
    assert!(stdout.contains("max X440.000 Y370.000"), "{stdout}");
}

/// The subprogram called at four positions needs a different correction
/// at each: four copies, each call pointing at its own.
#[test]
fn calls_with_different_corrections_get_their_own_copies() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (out, stderr) = compensate(&program("haas_sub_four.nc"), dir.path(), &[]);
    let text = String::from_utf8(out).expect("utf-8");
    assert!(
        stderr.contains("1 subprogram, 3 copies for calls with different corrections"),
        "{stderr}"
    );
    let calls: Vec<&str> = text.lines().filter(|l| l.starts_with("M98")).collect();
    assert_eq!(calls, ["M98 P2000", "M98 P2001", "M98 P2002", "M98 P2003"]);
    for head in [
        "O02000 (POCKET",
        "O02001 (POCKET",
        "O02002 (POCKET",
        "O02003 (POCKET",
    ] {
        assert_eq!(
            text.lines().filter(|l| l.starts_with(head)).count(),
            1,
            "{head}:\n{text}"
        );
    }
    assert_eq!(text.lines().filter(|l| *l == "M99").count(), 4);
    assert!(text.ends_with("M99\n%\n"), "{text}");
}

/// `M98 P2200 L4` whose four runs differ becomes four calls of four
/// copies; the coolant subprogram moves nothing and stays one.
#[test]
fn a_repeated_call_is_split_into_runs_of_one_copy() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (out, stderr) = compensate(
        &program("haas_sub_repeat.nc"),
        dir.path(),
        &["--annotate", "none"],
    );
    let text = String::from_utf8(out).expect("utf-8");
    assert!(stderr.contains("2 subprograms, 3 copies"), "{stderr}");
    let calls: Vec<&str> = text.lines().filter(|l| l.starts_with("M98")).collect();
    assert_eq!(
        calls,
        [
            "M98 P2200 L1",
            "M98 P2201 L1",
            "M98 P2202 L1",
            "M98 P2203 L1",
            "M98 P2300"
        ]
    );
    assert_eq!(
        text.lines().filter(|l| l.starts_with("O02300")).count(),
        1,
        "{text}"
    );
}

#[test]
fn linuxcnc_subroutines_and_loops_are_renamed_per_copy() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (out, stderr) = compensate(
        &program("linuxcnc_pocket.ngc"),
        dir.path(),
        &["--annotate", "none"],
    );
    let text = String::from_utf8(out).expect("utf-8");
    assert!(stderr.contains("2 subprograms, 4 copies"), "{stderr}");
    for line in [
        "o<pocket> sub",
        "o<pocket_1> sub",
        "o<pocket_2> endsub",
        "o100 repeat [1]",
        "o101 repeat [1]",
        "o102 endrepeat",
        "  o<pocket_2> call",
    ] {
        assert!(text.lines().any(|l| l == line), "{line}:\n{text}");
    }
}

fn report(path: &Path) -> Vec<Row> {
    report_with(&MACHINE, path)
}

/// The compensated program, with its subprogram copies, predicted again:
/// every cutting target of the input (each call's) is attained within the
/// tolerance.
#[test]
fn compensated_subprograms_attain_every_target_when_predicted_again() {
    for name in [
        "haas_sub_four.nc",
        "haas_sub_repeat.nc",
        "linuxcnc_pocket.ngc",
        "fanuc_bolt_circle.nc",
        "inch_without_g20.nc",
        "linuxcnc_while_pocket.ngc",
        "macro_words_kept.nc",
    ] {
        let dir = tempfile::tempdir().expect("tempdir");
        let input = program(name);
        let (out, _) = compensate(&input, dir.path(), &[]);
        let output = write(
            dir.path(),
            "landed.nc",
            &String::from_utf8(out).expect("utf-8"),
        );
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
                "{name}:{} ({}): attained {off:.6} mm from its target",
                t.line,
                t.motion
            );
            checked += 1;
        }
        assert!(checked >= 5, "{name}: {checked} targets");
    }
}

/// The Fanuc Macro B bolt circle: six holes from a `WHILE` loop, written
/// out as it runs with the moved values as numbers.
#[test]
fn a_macro_bolt_circle_is_written_out_with_its_values() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (out, stderr) = compensate(
        &program("fanuc_bolt_circle.nc"),
        dir.path(),
        &["--annotate", "none"],
    );
    let text = String::from_utf8(out).expect("utf-8");
    assert!(
        stderr.contains("macro program written out as it runs"),
        "{stderr}"
    );
    // The loop run through; its assignment lines written as they ran
    // (the values the kept expressions read), six times in the loop.
    assert!(!text.contains("WHILE") && !text.contains("END1"), "{text}");
    for (line, times) in [
        ("#1 = #1 + 1", 6),
        ("#2 = #1 * 360. / #103", 6),
        ("#1 = 0", 1),
    ] {
        assert_eq!(
            text.lines().filter(|l| *l == line).count(),
            times,
            "{line}:\n{text}"
        );
    }
    // Six holes: six feeds down to Z-5 (each near Z-5 after compensation).
    let downs = text
        .lines()
        .filter(|l| l.contains(" Z-4.99") || l.contains(" Z-5."))
        .count();
    assert_eq!(downs, 6, "{text}");
    // The first hole at the centre (200, 150) plus the radius 60 along X.
    assert!(text.contains("G0 X259.9"), "{text}");
}

/// A macro program written out as it runs keeps every word the program
/// wrote as an expression where the compensation does not move it, and
/// the assignment lines that give the expressions their values (run in
/// order, the loop statements left out); a number replaces an expression
/// only where the word moves. The values by hand (tests/shop/
/// macro_words_kept.nc, `#1` = 0, 1, 2): X 100/150/200 and 120/170/220,
/// Y 50, Z 5 and -2, F 300 and 600; no literal word of the program has
/// one of these values under its letter.
#[test]
fn macro_words_not_moved_keep_their_expressions() {
    let dir = tempfile::tempdir().expect("tempdir");
    // The static effect moves some words and not others on this machine.
    let (out, _) = compensate(
        &program("macro_words_kept.nc"),
        dir.path(),
        &["--effects", "static", "--annotate", "none"],
    );
    let text = String::from_utf8(out).expect("utf-8");
    let body: Vec<&str> = text.lines().filter(|l| !l.starts_with('(')).collect();
    assert!(!text.contains("WHILE") && !text.contains("END1"), "{text}");
    for line in ["#100 = 5. (CLEARANCE)", "#101 = 300. (FEED)", "#1 = 0"] {
        assert_eq!(
            body.iter().filter(|l| **l == line).count(),
            1,
            "{line}:\n{text}"
        );
    }
    assert_eq!(
        body.iter().filter(|l| **l == "#1 = #1 + 1").count(),
        3,
        "{text}"
    );
    let by_hand: [(char, &[f64]); 4] = [
        ('X', &[100.0, 150.0, 200.0, 120.0, 170.0, 220.0]),
        ('Y', &[50.0]),
        ('Z', &[5.0, -2.0]),
        ('F', &[300.0, 600.0]),
    ];
    let mut numbers = 0;
    for w in body.iter().flat_map(|l| l.split_whitespace()) {
        let Some((letter, values)) = by_hand.iter().find(|(c, _)| w.starts_with(*c)) else {
            continue;
        };
        let Ok(v) = w[1..].parse::<f64>() else {
            continue;
        };
        numbers += 1;
        assert!(
            !values.contains(&v),
            "{letter}{v}: an expression not moved written as its number:\n{text}"
        );
    }
    // Feeds never move: every F as the program wrote it.
    assert_eq!(text.matches(" F#101").count(), 3, "{text}");
    assert_eq!(text.matches(" F[#101 * 2]").count(), 3, "{text}");
    // Both: axis expressions kept, and moved words written as numbers.
    assert!(
        text.contains(" Z#100") && text.contains("X[100. + #1 * 50.]"),
        "{text}"
    );
    assert!(numbers >= 6, "{numbers} moved words:\n{text}");
}

/// The LinuxCNC pocket of three step-downs by an O-word `while` loop, an
/// `if` … `else` on the pass number: run offline and written out as it
/// runs, the loop and condition lines left out, each pass's depth a
/// number (1.5, 3 and 4.5 mm down), the spring pass (F600.) once, on the
/// last pass, and the diagonal of the `else` on the two others.
#[test]
fn a_linuxcnc_while_pocket_is_written_out_as_it_runs() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (out, stderr) = compensate(
        &program("linuxcnc_while_pocket.ngc"),
        dir.path(),
        &["--annotate", "none"],
    );
    let text = String::from_utf8(out).expect("utf-8");
    assert!(
        stderr.contains("macro program written out as it runs"),
        "{stderr}"
    );
    assert!(!text.contains("o101") && !text.contains("o102"), "{text}");
    // The pass counter's assignment written each time it ran.
    assert_eq!(
        text.lines().filter(|l| l.trim() == "#1 = [#1 + 1]").count(),
        3,
        "{text}"
    );
    // The depth words, as numbers near the programmed ones, never deeper
    // than the last pass.
    let zs: Vec<f64> = text
        .lines()
        .filter(|l| !l.starts_with('('))
        .flat_map(|l| l.split_whitespace())
        .filter_map(|w| w.strip_prefix('Z')?.parse::<f64>().ok())
        .collect();
    for z in [-1.5, -3.0, -4.5] {
        assert!(zs.iter().any(|v| (v - z).abs() < 0.01), "Z{z}: {text}");
    }
    assert!(zs.iter().all(|&v| v > -4.51), "{text}");
    // The spring pass once; the diagonal of the `else` (to Y127.5 and
    // its takeup back) on the two other passes.
    assert_eq!(text.matches("F600.").count(), 1, "{text}");
    assert_eq!(
        text.lines().filter(|l| l.contains(" Y127.4")).count(),
        4,
        "{text}"
    );
}

/// What a subprogram structure cannot hold is refused by name, at its
/// line, with exit code 2.
#[test]
fn subprogram_refusals_are_named_and_located() {
    let dir = tempfile::tempdir().expect("tempdir");
    let cases: &[(&str, &str, &str)] = &[
        (
            "G90 G0 X0 Y0\nM98 P3000\nM30\n",
            ":2:1:",
            "M98 calls O3000, which is not in this file",
        ),
        (
            "G90 G0 X0 Y0\nM98 P3000\nM30\nO3000\nG1 X1 F100\n",
            ":4:1:",
            "subprogram O3000 has no M99",
        ),
        (
            "G90\nG0 X1 M98 P3000\nM30\nO3000\nG1 X1 F100\nM99\n",
            ":2:1:",
            "a subprogram call shares its line with `G0`",
        ),
        (
            "G90\nM98 P3000\nM30\nO3000\nM98 P3000\nM99\n",
            ":5:1:",
            "calls nested deeper than 16 levels",
        ),
        (
            "G21 G90 G0 X0 Y0\nG38.2 Z-10. F50.\no101 while [#5070 EQ 0]\nG1 X1 F100\no101 endwhile\nM2\n",
            ":3:1:",
            "`#5070` is a system variable, known only on the control at run time",
        ),
        (
            "G21 G90 G0 X0 Y0\n#1 = 5\no101 while [#1 LT 2]\nG1 X1 F100\nM2\n",
            ":3:1:",
            "o101 while has no `o101 endwhile`",
        ),
        (
            "G21 G90 G0 X0 Y0\no102 if [#7 GT 0]\nG1 X1 F100\no102 endif\nM2\n",
            ":2:1:",
            "local variable `#7` is read before it is set",
        ),
        (
            "o<a> sub\nG1 X1 F100\no<a> endsub\no<a> call [2]\nM2\n",
            ":4:1:",
            "o<a> call with arguments",
        ),
        (
            "G0 X0\no<a> call\nM2\n",
            ":2:1:",
            "o<a> call: the subroutine is not defined",
        ),
        (
            "G90 G0 X0 Y0\n#1 = #5021 + 2.\nG1 X#1 F100\nM30\n",
            ":2:1:",
            "`#5021` is a system variable, known only on the control at run time",
        ),
        (
            "#1 = 0\nWHILE [#1 LT 3] DO1\nG91 G1 X1 F100\nEND1\nM30\n",
            ":4:1:",
            "the macro statements do not end within",
        ),
        (
            "o100 repeat [#5021]\nG0 X1\no100 endrepeat\nM2\n",
            ":1:1:",
            "`#5021` is not known before the program runs",
        ),
    ];
    for (body, at, phrase) in cases {
        let p = write(dir.path(), "p.nc", body);
        let a = postproc().arg("check").arg(&p).assert().code(2);
        let stderr = String::from_utf8_lossy(&a.get_output().stderr).to_string();
        assert!(stderr.contains(phrase), "{body:?}: {stderr}");
        assert!(stderr.contains(&format!("p.nc{at}")), "{body:?}: {stderr}");
    }
}

/// A Fusion-style Haas lathe program is named as a lathe program by
/// `check`, with exit code 2, at the line that shows it.
#[test]
fn check_of_a_lathe_program_exits_2_naming_it() {
    let a = postproc()
        .arg("check")
        .args(MACHINE)
        .arg(program("haas_lathe.nc"))
        .assert()
        .code(2);
    let stderr = String::from_utf8_lossy(&a.get_output().stderr).to_string();
    assert!(
        stderr.contains("haas_lathe.nc:6:1: lathe (turning) program: `G50 S…` spindle speed clamp with `G18` (line 4)"),
        "{stderr}"
    );
}

/// An inch program without `G20` on a machine file whose control reads
/// mm: read in mm, and the first block that relies on the machine file's
/// `units_default` says so, once, at its line.
#[test]
fn an_inch_program_without_g20_is_told_its_units_come_from_the_machine_file() {
    let input = program("inch_without_g20.nc");
    let a = postproc()
        .arg("check")
        .args(MACHINE)
        .arg(&input)
        .assert()
        .success();
    let stdout = String::from_utf8_lossy(&a.get_output().stdout).to_string();
    let stderr = String::from_utf8_lossy(&a.get_output().stderr).to_string();
    let said = "the program sets no units (G20 inch or G21 mm) before `X0.5`: read in mm, the machine file's `units_default: mm` (or --units)";
    assert!(stdout.contains("units: mm"), "{stdout}");
    assert!(
        stdout.contains(&format!("  line 6: {said} (1 block)")),
        "{stdout}"
    );
    assert_eq!(stderr.matches(said).count(), 1, "{stderr}");
    assert!(stderr.contains("inch_without_g20.nc:6: "), "{stderr}");
    // `compensate` says it too, once.
    let dir = tempfile::tempdir().expect("tempdir");
    let (_, stderr) = compensate(&input, dir.path(), &[]);
    assert_eq!(stderr.matches("`units_default: mm`").count(), 1, "{stderr}");
}

/// A plasma program never programs Z: the torch stays at the reference
/// position at the end of Z's travel, and the correction of each cut
/// would take Z a few µm past it. At a cutting tolerance larger than
/// that crossing the point is held at the end with one warning, and every
/// cut still attains its target within the tolerance; at a tolerance
/// smaller than the crossing the block is refused, naming the travel.
#[test]
fn a_plasma_program_without_z_is_held_at_the_end_of_travel() {
    let tolerance = 0.02;
    let input = program("plasma_no_z.nc");
    let dir = tempfile::tempdir().expect("tempdir");
    // The bundled machine at a cutting tolerance of 0.02 mm, as a plasma
    // table's machine file would give it (report reads the file's).
    let bundled = std::fs::read_to_string(repo("machines/afm-r1000.yaml")).expect("read");
    assert!(bundled.contains("tolerance_mm: 0.003"));
    let table = write(
        dir.path(),
        "table.yaml",
        &bundled.replace("tolerance_mm: 0.003", "tolerance_mm: 0.02"),
    );
    let table = table.to_str().expect("utf-8 path");
    let machine = ["--machine", table, "--work-offset", "G54=100,50,200"];
    let out = dir.path().join("out.nc");
    let a = postproc()
        .arg("compensate")
        .args(machine)
        .arg(&input)
        .arg("-o")
        .arg(&out)
        .assert()
        .success();
    let stderr = String::from_utf8_lossy(&a.get_output().stderr).to_string();
    let held = "the correction of Z would take it 0.0089 mm past the end of its travel (500), less than the tolerance 0.02 mm: held at the end";
    assert_eq!(stderr.matches(held).count(), 1, "{stderr}");
    assert!(stderr.contains("plasma_no_z.nc:8: "), "{stderr}");
    let text = std::fs::read_to_string(&out).expect("output");
    // A Z word written is the end of travel itself (machine Z500 = work
    // Z300 with the offset's Z200), never past it.
    let z_words: Vec<&str> = text
        .lines()
        .filter(|l| !l.starts_with('('))
        .flat_map(|l| l.split_whitespace())
        .filter(|w| w.starts_with('Z'))
        .collect();
    assert!(z_words.iter().all(|w| *w == "Z300."), "{z_words:?}\n{text}");
    let landed = report_with(&machine, &out);
    let mut checked = 0;
    for t in report_with(&machine, &input)
        .iter()
        .filter(|t| t.motion != "rapid" && t.motion != "fixed")
    {
        let off = landed
            .iter()
            .map(|l| dist(&l.attained, &t.programmed))
            .fold(f64::INFINITY, f64::min);
        assert!(
            off <= tolerance + t.residual_mm,
            "line {}: attained {off:.6} mm from its target",
            t.line
        );
        checked += 1;
    }
    assert!(checked >= 6, "{checked} targets");
    // The bundled file's tolerance, 3 µm, is less than the crossing.
    let a = postproc()
        .arg("compensate")
        .args(MACHINE)
        .arg(&input)
        .arg("-o")
        .arg(dir.path().join("refused.nc"))
        .assert()
        .code(2);
    let stderr = String::from_utf8_lossy(&a.get_output().stderr).to_string();
    assert!(
        stderr.contains(
            "plasma_no_z.nc:8:1: compensated Z = 500.0089 is outside the travel [0, 500]"
        ),
        "{stderr}"
    );
    assert!(!dir.path().join("refused.nc").exists());
}

/// Parentheses inside a comment nest: a message text in parentheses is a
/// comment, not a dialect this reader does not take, and is written back
/// as it is.
#[test]
fn nested_comments_are_read_and_kept() {
    let dir = tempfile::tempdir().expect("tempdir");
    let body = "G21 G90 G17 ($MESSAGE(\"CHANGE TOOL\") )\nG0 X10. Y10. Z5. (OUTER (INNER) STILL COMMENT)\nG1 Z-1. F100.\nM30\n";
    let p = write(dir.path(), "nested.nc", body);
    let a = postproc()
        .arg("check")
        .args(MACHINE)
        .arg(&p)
        .assert()
        .success();
    let stderr = String::from_utf8_lossy(&a.get_output().stderr).to_string();
    assert!(!stderr.contains("Siemens"), "{stderr}");
    let (out, _) = compensate(&p, dir.path(), &["--annotate", "none"]);
    let text = String::from_utf8(out).expect("utf-8");
    assert!(
        text.contains("G21 G90 G17 ($MESSAGE(\"CHANGE TOOL\") )\n"),
        "{text}"
    );
    assert!(text.contains(" (OUTER (INNER) STILL COMMENT)\n"), "{text}");
}
