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

/// The bundled three-axis machine whose control reads the corner words
/// `,C` and `,R` (`corner_words: comma`), written into `dir`.
fn corner_machine(dir: &Path) -> PathBuf {
    let text = std::fs::read_to_string(repo("machines/afm-r1000.yaml")).expect("machine");
    write(
        dir,
        "afm-corners.yaml",
        &format!("{text}corner_words: comma\n"),
    )
}

/// The flags of [`MACHINE`] with the corner machine in place of the
/// bundled one.
fn corner_flags(machine: &Path) -> Vec<String> {
    let mut flags: Vec<String> = MACHINE.iter().map(|s| s.to_string()).collect();
    flags[1] = machine.display().to_string();
    flags
}

/// Without `corner_words` in the machine file the corner words are
/// refused by name, each at its comma.
#[test]
fn corner_words_are_refused_by_name_without_the_key() {
    let a = postproc()
        .arg("check")
        .args(MACHINE)
        .arg(program("haas_corners.nc"))
        .assert()
        .code(2);
    let err = String::from_utf8_lossy(&a.get_output().stderr).to_string();
    // Line 9 `G01 X40. Y10. ,C3.`: the comma is the 15th character.
    assert!(
        err.contains("haas_corners.nc:9:15: a chamfer word `,C` is not read"),
        "{err}"
    );
    assert!(
        err.contains("haas_corners.nc:10:11: a corner-radius word `,R` is not read"),
        "{err}"
    );
    assert!(err.contains("`corner_words: comma`"), "{err}");
}

/// With the key, the program is read as the control moves it and written
/// back byte for byte when nothing is compensated.
#[test]
fn a_corner_program_is_written_back_byte_for_byte() {
    let dir = tempfile::tempdir().expect("tempdir");
    let machine = corner_machine(dir.path());
    let input = program("haas_corners.nc");
    let out = dir.path().join("out.nc");
    postproc()
        .arg("compensate")
        .args(corner_flags(&machine))
        .args(["--effects", "none", "--annotate", "none"])
        .arg(&input)
        .arg("-o")
        .arg(&out)
        .assert()
        .success();
    let written = std::fs::read(&out).expect("output");
    assert!(
        without_header(&written) == std::fs::read(&input).expect("read"),
        "{}",
        String::from_utf8_lossy(&written)
    );
}

/// The corner pieces a Fanuc or Haas control makes between the line from
/// `a` to the corner `v` and the line from `v` to `b` (computed here on
/// their own, from the manuals' definitions: `,C` the distance of both
/// tangent points from the corner along its lines, `,R` the radius of the
/// arc tangent to both): points along the first line from `a` to the
/// first tangent point, along the chamfer or arc, and along the next line
/// to `b`.
fn control_path(a: [f64; 3], v: [f64; 3], b: [f64; 3], chamfer: bool, size: f64) -> Vec<[f64; 3]> {
    let sub = |p: [f64; 3], q: [f64; 3]| [p[0] - q[0], p[1] - q[1], p[2] - q[2]];
    let len = |p: [f64; 3]| (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
    let unit = |p: [f64; 3]| {
        let l = len(p);
        [p[0] / l, p[1] / l, p[2] / l]
    };
    let along =
        |p: [f64; 3], u: [f64; 3], t: f64| [p[0] + u[0] * t, p[1] + u[1] * t, p[2] + u[2] * t];
    let (u1, u2) = (unit(sub(v, a)), unit(sub(b, v)));
    let cos: f64 = (0..3).map(|i| u1[i] * u2[i]).sum();
    let turn = cos.clamp(-1.0, 1.0).acos();
    let d = if chamfer {
        size
    } else {
        size * (turn / 2.0).tan()
    };
    let (t1, t2) = (along(v, u1, -d), along(v, u2, d));
    let n = 200;
    let mut pts = Vec::new();
    for i in 0..=n {
        let s = i as f64 / n as f64;
        pts.push(along(a, u1, (len(sub(v, a)) - d) * s));
    }
    if chamfer {
        for i in 0..=n {
            let s = i as f64 / n as f64;
            pts.push(along(t1, sub(t2, t1), s));
        }
    } else {
        // The centre lies on the bisector, r / cos(turn/2) from the corner.
        let w = unit(sub(u2, u1));
        let c = along(v, w, size / (turn / 2.0).cos());
        let (e1, e2) = (unit(sub(t1, c)), unit(sub(t2, c)));
        for i in 0..=n {
            let s = i as f64 / n as f64;
            let (p, q) = (((1.0 - s) * turn).sin(), (s * turn).sin());
            let k = size / turn.sin();
            pts.push([
                c[0] + (e1[0] * p + e2[0] * q) * k,
                c[1] + (e1[1] * p + e2[1] * q) * k,
                c[2] + (e1[2] * p + e2[2] * q) * k,
            ]);
        }
    }
    for i in 0..=n {
        let s = i as f64 / n as f64;
        pts.push(along(t2, u2, (len(sub(b, v)) - d) * s));
    }
    pts
}

/// The compensated corner program, read again by the forward pass of the
/// library and moved as the control moves it: every point of each corner
/// the control makes from the compensated lines (the lines, the chamfer or
/// arc) is predicted within the tolerance of the corner it makes from the
/// programmed lines.
#[test]
fn compensated_corners_are_within_the_tolerance_as_the_control_moves_them() {
    let dir = tempfile::tempdir().expect("tempdir");
    let machine_path = corner_machine(dir.path());
    let input = program("haas_corners.nc");
    let out = dir.path().join("out.nc");
    let a = postproc()
        .arg("compensate")
        .args(corner_flags(&machine_path))
        .args(["--effects", "geometric", "--annotate", "none"])
        .arg(&input)
        .arg("-o")
        .arg(&out)
        .assert()
        .success();
    let stderr = String::from_utf8_lossy(&a.get_output().stderr).to_string();
    assert!(!stderr.contains("misses its programmed path"), "{stderr}");
    let output = std::fs::read_to_string(&out).expect("output");
    // The words are kept, each on the line that ends at its corner.
    for w in [",C3.", ",R5.", ",C2.5", ",R8."] {
        assert_eq!(output.matches(w).count(), 1, "{w}:\n{output}");
    }
    let text = std::fs::read_to_string(&machine_path).expect("machine");
    let m = postproc::machine::tool::MachineTool::from_yaml_str(&text, "m.yaml").expect("loads");
    let mut job = crate::repredict::job(&m, "geometric", TOLERANCE_MM);
    job.setup.work_offsets[0] = Some([100.0, 50.0, 200.0]);
    job.setup.tools.insert(1, 100.0);
    // The corner blocks' moves and the move after each, in order.
    let corners = |text: &str| {
        let reads = crate::repredict::forward(&job, text);
        let moves: Vec<_> = reads.iter().filter(|r| r.plan.mv.is_some()).collect();
        let mut out = Vec::new();
        for (k, r) in moves.iter().enumerate() {
            if let Some(c) = r.plan.corner {
                let next = moves.get(k + 1).expect("a move after the corner");
                out.push((c, r.plan.mv.expect("move"), next.plan.mv.expect("move")));
            }
        }
        out
    };
    let programmed = corners(&std::fs::read_to_string(&input).expect("input"));
    let written = corners(&output);
    assert_eq!(programmed.len(), 4);
    assert_eq!(written.len(), 4);
    let pred = job.predictor.as_ref().expect("predictor");
    for ((c, first, next), (cw, wfirst, wnext)) in programmed.iter().zip(&written) {
        assert_eq!(c, cw);
        let chamfer = c.kind == postproc::program::interp::CornerKind::Chamfer;
        let xyz = |p: [f64; 6]| [p[0], p[1], p[2]];
        let want = control_path(
            xyz(first.start),
            xyz(first.end),
            xyz(next.end),
            chamfer,
            c.size_mm,
        );
        let got = control_path(
            xyz(wfirst.start),
            xyz(wfirst.end),
            xyz(wnext.end),
            chamfer,
            c.size_mm,
        );
        // Each axis moves the way the commanded path goes at the point.
        let mut dirs = wfirst.dirs;
        let mut worst: f64 = 0.0;
        for (i, q) in got.iter().enumerate() {
            if let Some(p) = got.get(i + 1) {
                for s in 0..3 {
                    if (p[s] - q[s]).abs() > 1e-9 {
                        dirs[s] = if p[s] > q[s] { 1 } else { -1 };
                    }
                }
            }
            let mut cmd = wfirst.end;
            cmd[..3].copy_from_slice(q);
            let tip = pred.attained(&cmd, &dirs, wfirst.tool_len_mm).pos;
            let off = want
                .windows(2)
                .map(|w| to_segment(&[tip.x, tip.y, tip.z], &w[0], &w[1]))
                .fold(f64::INFINITY, f64::min);
            worst = worst.max(off);
        }
        assert!(
            worst <= TOLERANCE_MM + SAMPLING_MM,
            "{c:?}: the control's corner is predicted {worst:.5} mm from the programmed one"
        );
    }
}

/// How far the chords between the points [`control_path`] samples an arc
/// at may lie inside it, mm: the sagitta `r·(1 − cos(θ/2n))` ≤ `r·θ²/8n²`
/// of the largest radius of tests/shop/haas_corners.nc (8 mm) at a turn
/// below π in n = 200 steps: 8·π²/(8·200²) = 0.00025 mm.
const SAMPLING_MM: f64 = 0.00025;

/// Distance of `p` from the segment from `a` to `b`.
fn to_segment(p: &[f64; 3], a: &[f64; 3], b: &[f64; 3]) -> f64 {
    let d = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
    let dd: f64 = d.iter().map(|x| x * x).sum();
    let t = if dd > 0.0 {
        ((0..3).map(|i| (p[i] - a[i]) * d[i]).sum::<f64>() / dd).clamp(0.0, 1.0)
    } else {
        0.0
    };
    crate::repredict::dist(p, &[a[0] + d[0] * t, a[1] + d[1] * t, a[2] + d[2] * t])
}
