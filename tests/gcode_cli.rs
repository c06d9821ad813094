//! Integration tests: the G-code commands through the real binary —
//! byte-faithful pass-through of every sample, located errors for malformed
//! programs (exit 2, no output file), stdin, `check` counts and reports.

use std::fs;
use std::path::{Path, PathBuf};

use crate::common::{postproc, repo, text, text_without_header, without_header, write};

/// A minimal machine file: today's loader needs only the kind.
fn machine(dir: &Path) -> PathBuf {
    let path = dir.join("machine.yaml");
    // An error-free three-axis machine with travel wide enough for every sample.
    let mut text = String::from("kind: machine_tool\nname: test mill\naxes:\n");
    for (axis, side) in [("X", "workpiece"), ("Y", "workpiece"), ("Z", "tool")] {
        text.push_str(&format!("  - name: {axis}\n    type: linear\n    side: {side}\n    travel_mm: [-3000, 3000]\n    rapid_mm_per_min: 20000\n"));
    }
    fs::write(&path, text).expect("write machine file");
    path
}

/// Tool lengths for every H number the samples use (H1 … H12).
fn tool_args() -> Vec<String> {
    (1..=12)
        .flat_map(|h| ["--tool".to_string(), format!("H{h}={}", 60 + 5 * h)])
        .collect()
}

/// samples/part.nc and every program in samples/gcode/.
fn sample_programs() -> Vec<PathBuf> {
    let mut v = vec![repo("samples/part.nc")];
    let mut more: Vec<PathBuf> = fs::read_dir(repo("samples/gcode"))
        .expect("samples/gcode exists")
        .map(|e| e.expect("dir entry").path())
        .filter(|p| p.extension().is_some_and(|e| e != "md"))
        .collect();
    more.sort();
    assert!(more.len() >= 5, "samples/gcode has {} programs", more.len());
    v.extend(more);
    v
}

fn files_in(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = fs::read_dir(dir)
        .expect("read dir")
        .map(|e| e.expect("entry").file_name().to_string_lossy().to_string())
        .collect();
    v.sort();
    v
}

#[test]
fn compensate_without_effects_is_byte_identical_to_file() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let m = machine(tmp.path());
    for input in sample_programs() {
        let original = fs::read(&input).expect("read sample");
        let out = tmp.path().join("out.nc");
        postproc()
            .arg("compensate")
            .arg(&input)
            .arg("--machine")
            .arg(&m)
            .args(tool_args())
            .args(["--effects", "none", "--annotate", "none", "-o"])
            .arg(&out)
            .assert()
            .success();
        // The provenance header is the only addition.
        let written = without_header(&fs::read(&out).expect("output written"));
        assert!(
            written == original,
            "{}: output differs from input",
            input.display()
        );
    }
}

#[test]
fn compensate_without_effects_is_byte_identical_to_stdout() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let m = machine(tmp.path());
    for input in sample_programs() {
        let original = fs::read(&input).expect("read sample");
        let out = postproc()
            .arg("compensate")
            .arg(&input)
            .arg("--machine")
            .arg(&m)
            .args(tool_args())
            .args(["--effects", "none", "--annotate", "none", "-o", "-"])
            .assert()
            .success()
            .get_output()
            .stdout
            .clone();
        assert!(
            without_header(&out) == original,
            "{}: stdout differs from input",
            input.display()
        );
    }
}

#[test]
fn compensate_default_output_name_is_stem_comp_ext() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let m = machine(tmp.path());
    for input in sample_programs() {
        let name = input.file_name().expect("file name");
        let copy = tmp.path().join(name);
        fs::copy(&input, &copy).expect("copy sample");
        postproc()
            .arg("compensate")
            .arg(&copy)
            .arg("--machine")
            .arg(&m)
            .args(tool_args())
            .args(["--effects", "none", "--annotate", "none"])
            .assert()
            .success();
        let stem = input
            .file_stem()
            .expect("stem")
            .to_string_lossy()
            .to_string();
        let ext = input
            .extension()
            .expect("ext")
            .to_string_lossy()
            .to_string();
        let expected = tmp.path().join(format!("{stem}.comp.{ext}"));
        let written = without_header(
            &fs::read(&expected).unwrap_or_else(|_| panic!("{} not written", expected.display())),
        );
        assert!(
            written == fs::read(&input).expect("read"),
            "{}",
            expected.display()
        );
    }
}

#[test]
fn compensate_reads_stdin() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let m = machine(tmp.path());
    let original = fs::read(repo("samples/gcode/iso_spaced_crlf.nc")).expect("read");
    let out = postproc()
        .args(["compensate", "-", "--machine"])
        .arg(&m)
        .args(tool_args())
        .args(["--effects", "none", "--annotate", "none", "-o", "-"])
        .write_stdin(original.clone())
        .assert()
        .success()
        .get_output()
        .stdout
        .clone();
    assert!(
        without_header(&out) == original,
        "stdin pass-through differs"
    );
}

#[test]
fn compensate_refuses_to_overwrite_the_input() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let m = machine(tmp.path());
    let input = tmp.path().join("part.nc");
    fs::copy(repo("samples/part.nc"), &input).expect("copy");
    let original = fs::read(&input).expect("read");
    // The same path, and the same file through `sub/..`.
    fs::create_dir(tmp.path().join("sub")).expect("mkdir");
    let roundabout = tmp.path().join("sub").join("..").join("part.nc");
    for out in [input.clone(), roundabout] {
        let a = postproc()
            .arg("compensate")
            .arg(&input)
            .arg("--machine")
            .arg(&m)
            .args(tool_args())
            .arg("-o")
            .arg(&out)
            .assert()
            .code(2);
        let stderr = String::from_utf8_lossy(&a.get_output().stderr).to_string();
        assert!(stderr.contains("overwrite the input"), "{stderr}");
        assert!(fs::read(&input).expect("read") == original, "input changed");
    }
    assert_eq!(files_in(tmp.path()), ["machine.yaml", "part.nc", "sub"]);
}

/// Malformed programs: the bad construct sits on line `line` of
/// `%`, `G21 G90 G17`, … so the location is checked, not just the message.
#[test]
fn malformed_programs_exit_2_located_with_no_output() {
    // (body lines from line 3 on, expected line, expected column, phrase)
    let cases: &[(&str, usize, usize, &str)] = &[
        // `X` is byte 3 of `G1 X`: column 4.
        ("G1 X", 3, 4, "truncated word"),
        ("G1 X Y2", 3, 4, "without a number"),
        // The second `.` of `X1.2.3` is byte 7: column 8.
        ("G1 X1.2.3", 3, 8, "two numbers in one word"),
        ("G1 U5", 3, 4, "unknown word letter `U`"),
        // The error points at `#` (byte 4) right after the letter.
        (
            "G1 X#1",
            3,
            1,
            "local variable `#1` is read before it is set",
        ),
        ("#3000=2.", 3, 1, "`#3000` is a system variable"),
        (
            "G1 X[1+#5021]",
            3,
            1,
            "`#5021` is a system variable, known only on the control",
        ),
        ("o100 sub", 3, 1, "O-word subroutine o100 has no `endsub`"),
        (
            "O200 WHILE [1 LT 2]",
            3,
            1,
            "o200 while has no `o200 endwhile`",
        ),
        (
            "M98 P100",
            3,
            1,
            "M98 calls O100, which is not in this file",
        ),
        // M99 after `G0 X0 `: byte 6, column 7.
        (
            "G0 X0 M99",
            3,
            7,
            "subprogram calls cannot be compensated offline",
        ),
        ("G10 L2 P1 X0 Y0 Z0", 3, 1, "G10 (programmable data input)"),
        ("G92 X0 Y0", 3, 1, "G92 (coordinate system shift)"),
        ("G68 X0 Y0 R45.", 3, 1, "G68 (coordinate rotation)"),
        ("G51 X0 Y0 P2", 3, 1, "G51 (scaling/mirroring)"),
        // Corner words without their comma (issue 37): `R5.` starts at
        // byte 8 of `G1 X50. R5. F500`, `C2.` likewise.
        (
            "G1 X50. R5. F500",
            3,
            9,
            "`R` on a G1 line is not read: outside a canned cycle it is a corner radius",
        ),
        (
            "G1 X50. C2. F500",
            3,
            9,
            "the machine has no C axis; a chamfer is written `,C`",
        ),
        // The circle about (1,0) through (0,0) has radius 1; (5,0) is at 4:
        // located at the G2 word, byte 4 after `N40 `.
        (
            "G0 X0 Y0\nN40 G2 X5 Y0 I1 J0 F100",
            4,
            5,
            "arc end point is not on the circle",
        ),
        // `H77` starts at byte 4; only H1…H12 are given.
        (
            "G43 H77 Z50.",
            3,
            5,
            "tool length offset H77 is not in the tool table",
        ),
    ];
    let tmp = tempfile::tempdir().expect("temp dir");
    let m = machine(tmp.path());
    for (i, (body, line, column, phrase)) in cases.iter().enumerate() {
        let case_dir = tmp.path().join(format!("case{i}"));
        fs::create_dir(&case_dir).expect("mkdir");
        let input = case_dir.join("bad.nc");
        fs::write(&input, format!("%\nG21 G90 G17\n{body}\nM30\n%\n")).expect("write");
        let out = case_dir.join("out.nc");
        for cmd in ["compensate", "check"] {
            let mut c = postproc();
            c.arg(cmd)
                .arg(&input)
                .arg("--machine")
                .arg(&m)
                .args(tool_args());
            if cmd == "compensate" {
                c.arg("-o").arg(&out);
            }
            let a = c.assert().code(2);
            let stderr = String::from_utf8_lossy(&a.get_output().stderr).to_string();
            let location = format!("{}:{line}:{column}: ", input.display());
            assert!(
                stderr.contains(&location) && stderr.contains(phrase),
                "{cmd} `{body}`: expected `{location}…{phrase}`, got: {stderr}"
            );
            assert!(!stderr.contains("panicked"), "{stderr}");
        }
        assert!(!out.exists(), "`{body}`: output written");
        assert_eq!(files_in(&case_dir), ["bad.nc"], "`{body}`: stray files");
    }
}

#[test]
fn check_prints_the_summary_of_part_nc() {
    let input = repo("samples/part.nc");
    let a = postproc()
        .arg("check")
        .arg(&input)
        .args(tool_args())
        .assert()
        .success();
    let stdout = String::from_utf8_lossy(&a.get_output().stdout).to_string();
    // Counted by hand in samples/part.nc (81 lines):
    // - 11 lines without words: 2 `%`, 4 header comments, 5 section comments → 70 blocks.
    // - rapids 18: G28 at N20 N170 N530 N670 N680 (5); G0/modal rapids at
    //   N60 N70 N80, N150, N210 N220 N230, N400 N410 N420, N510, N570 N580 (13).
    // - feeds 19: N90–N140 (6), N240, N290 N300, N320, N340, N360, N380 N390 (8),
    //   N430 N440, N460, N480, N500 (5).
    // - arcs 11: N250–N280 (4), N310 N330 N350 N370 (4), N450 N470 N490 (3).
    // - cycle holes 6: G81 at N590–N620 (4), G83 at N630 N640 (2).
    // 18 + 19 + 11 + 6 = 54 moves.
    assert!(
        stdout
            .contains(": 81 lines, 70 blocks, 54 moves (18 rapid, 19 feed, 11 arc, 6 cycle holes)"),
        "{stdout}"
    );
    assert!(stdout.contains("units: mm"), "{stdout}");
    assert!(stdout.contains("tools: T1 T2 T3"), "{stdout}");
    assert!(stdout.contains("warnings: 0"), "{stdout}");
}

#[test]
fn check_reads_stdin_and_reports_inch_and_warnings() {
    let text = fs::read(repo("samples/gcode/block_delete.nc")).expect("read");
    let a = postproc()
        .args(["check", "-"])
        .args(tool_args())
        .write_stdin(text)
        .assert()
        .success();
    let stdout = String::from_utf8_lossy(&a.get_output().stdout).to_string();
    assert!(stdout.starts_with("-: 62 lines"), "{stdout}");
    // G41 at line 33 is passed through with one warning; the G53 Z0 of
    // line 25 goes down from machine Z50 (where the moves before left Z).
    assert!(stdout.contains("warnings: 2"), "{stdout}");
    assert!(stdout.contains("line 25: G53 moves Z down"), "{stdout}");
    assert!(
        stdout.contains("line 33: cutter radius compensation"),
        "{stdout}"
    );
    let a = postproc()
        .arg("check")
        .arg(repo("samples/gcode/inch_g20.nc"))
        .args(tool_args())
        .assert()
        .success();
    assert!(String::from_utf8_lossy(&a.get_output().stdout).contains("units: inch"));
}

#[test]
fn usage_errors_exit_2() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let part = repo("samples/part.nc");
    postproc()
        .arg("check")
        .arg(&part)
        .arg("--bogus")
        .assert()
        .code(2);
    postproc().arg("frobnicate").assert().code(2);
    for cmd in ["compensate", "report"] {
        let a = postproc()
            .arg(cmd)
            .arg(&part)
            .args(tool_args())
            .assert()
            .code(2);
        let stderr = String::from_utf8_lossy(&a.get_output().stderr).to_string();
        assert!(stderr.contains("needs --machine"), "{stderr}");
    }
    // Bad --tool value.
    let m = machine(tmp.path());
    postproc()
        .arg("check")
        .arg(&part)
        .arg("--machine")
        .arg(&m)
        .args(["--tool", "H1=abc"])
        .assert()
        .code(2);
    assert_eq!(files_in(tmp.path()), ["machine.yaml"]);
}

/// Regression: a tolerance at the solver's own convergence (1e-7 mm) cannot
/// be proven for any piece (its solved ends may each be 1e-7 mm off), so it
/// is refused as bad usage instead of failing with "more than 65536
/// segments" at the first feed move; 1e-6 mm, the smallest accepted, runs.
#[test]
fn regression_tolerance_below_the_solver_convergence_is_refused() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let m = machine(tmp.path());
    let out = tmp.path().join("out.nc");
    for (tol, code) in [("1e-7", 2), ("0.0000005", 2), ("1e-6", 0)] {
        let a = postproc()
            .arg("compensate")
            .arg(repo("samples/part.nc"))
            .arg("--machine")
            .arg(&m)
            .args(tool_args())
            .args(["--tolerance", tol, "-o"])
            .arg(&out)
            .assert()
            .code(code);
        let stderr = String::from_utf8_lossy(&a.get_output().stderr).to_string();
        if code == 2 {
            assert!(
                stderr.contains("--tolerance")
                    && stderr.contains("must be within [0.000001, 1] mm"),
                "{stderr}"
            );
            assert!(!out.exists(), "no output for a refused tolerance");
        } else {
            assert!(out.exists(), "{stderr}");
        }
    }
}

/// Runs `report` on samples/part.nc in a format; stdout.
fn report(format: &str) -> String {
    let tmp = tempfile::tempdir().expect("temp dir");
    let m = machine(tmp.path());
    let a = postproc()
        .arg("report")
        .arg(repo("samples/part.nc"))
        .arg("--machine")
        .arg(&m)
        .args(tool_args())
        .args(["--format", format])
        .assert()
        .success();
    String::from_utf8_lossy(&a.get_output().stdout).to_string()
}

/// One row per motion block: 54 in samples/part.nc (see the hand count in
/// `check_prints_the_summary_of_part_nc`).
const PART_MOTION_BLOCKS: usize = 54;

#[test]
fn report_csv_has_a_row_per_motion_block() {
    let out = report("csv");
    let mut lines = out.lines().filter(|l| !l.starts_with('#'));
    let header = lines.next().expect("header");
    assert!(header.starts_with("line,motion,"), "{header}");
    let rows: Vec<&str> = lines.collect();
    assert_eq!(rows.len(), PART_MOTION_BLOCKS);
    // The first motion block is N20 G91 G28 Z0. on line 8; the last N680 G28 on line 79.
    assert!(rows[0].starts_with("8,fixed,"), "{}", rows[0]);
    assert!(rows[PART_MOTION_BLOCKS - 1].starts_with("79,fixed,"));
}

#[test]
fn report_json_parses_with_a_row_per_motion_block() {
    let out = report("json");
    let v: serde_json::Value = serde_json::from_str(&out).expect("valid JSON");
    let rows = v["rows"].as_array().expect("rows array");
    assert_eq!(rows.len(), PART_MOTION_BLOCKS);
    // Lines strictly increase and every row names its motion.
    let mut last = 0;
    for r in rows {
        let line = r["line"].as_u64().expect("line number");
        assert!(line > last);
        last = line;
        assert!(r["motion"].as_str().is_some_and(|m| !m.is_empty()));
    }
    // Line 70 is N590, the first G81 hole.
    let hole = rows.iter().find(|r| r["line"] == 70).expect("line 70");
    assert_eq!(hole["motion"], "cycle");
}

#[test]
fn report_table_has_a_row_per_motion_block() {
    let out = report("table");
    let rows = out
        .lines()
        .filter(|l| {
            l.split_whitespace()
                .next()
                .is_some_and(|w| w.parse::<usize>().is_ok())
        })
        .count();
    assert_eq!(rows, PART_MOTION_BLOCKS);
    assert!(out.contains("summary: 54 rows"), "{out}");
}

#[test]
fn regression_travel_error_names_the_machine_coordinate_and_the_work_coordinate() {
    // Y350.05 in G54 (Y 150) is machine Y500.05, beyond the travel [0, 500]:
    // the message calls it a machine coordinate and shows the work
    // coordinate and the offset between them.
    let tmp = tempfile::tempdir().expect("temp dir");
    let p = tmp.path().join("p.nc");
    fs::write(&p, "G90 G54 G0 X10 Y10\nG0 Y350.05\n").expect("write");
    for command in ["check", "compensate"] {
        let out = postproc()
            .arg(command)
            .arg(&p)
            .args(
                ["--machine", "afm-r1000", "-o", "-"]
                    .iter()
                    .take(if command == "check" { 2 } else { 4 }),
            )
            .output()
            .expect("runs");
        assert_eq!(out.status.code(), Some(2), "{command}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            err.contains(
                "p.nc:2:1: machine Y = 500.0500 (work Y350.0500 + offsets 150.0000 mm) is outside the travel [0, 500]: `G0 Y350.05`"
            ),
            "{command}: {err}"
        );
    }
}

/// A hand-written Fanuc program without decimal points, on a control that
/// reads such words in increments (`integer_words: increments`): `X100` is
/// 0.100 mm, and every word the compensation writes has its point.
#[test]
fn integer_words_in_increments_are_read_and_written_as_the_control_does() {
    let dir = tempfile::tempdir().expect("dir");
    let mut machine = text("machines/afm-r1000.yaml");
    machine.push_str("integer_words: increments\n");
    let machine = write(dir.path(), "m.yaml", &machine);
    let program = write(
        dir.path(),
        "nodec.nc",
        "%\nO2000\nG21 G90 G54 G0 X100 Y50 Z50000\nG43 H1 Z20000\nG1 Z-5000 F200\nX150 F600\nM30\n%\n",
    );
    let out = postproc()
        .args(["compensate", "--effects", "geometric", "-o", "-"])
        .arg("--machine")
        .arg(&machine)
        .arg(&program)
        .assert()
        .success();
    let stderr = String::from_utf8_lossy(&out.get_output().stderr).to_string();
    // The first word read in increments names the machine file's key, once.
    assert_eq!(
        stderr
            .matches("nodec.nc:3: `X100` has no decimal point: read as 100 increments of 0.001 mm, the machine file's `integer_words: increments`")
            .count(),
        1,
        "{stderr}"
    );
    let text = String::from_utf8(out.get_output().stdout.clone()).expect("utf-8");
    let body = text_without_header(&text);
    // X150 is 0.150 mm: its compensated word is within microns of it.
    let line = body
        .lines()
        .find(|l| l.starts_with('X') && l.contains("F600"))
        .expect("the feed line");
    let x: f64 = line[1..]
        .split(|c: char| c.is_ascii_alphabetic() || c == ' ')
        .next()
        .and_then(|v| v.parse().ok())
        .expect("an X value");
    // A compensation of microns, not of the 149.85 mm a misreading gives.
    const NEAR_MM: f64 = 0.05;
    assert!((x - 0.15).abs() < NEAR_MM, "{line}");
    assert!(
        line[1..].split(' ').next().is_some_and(|w| w.contains('.')),
        "{line}"
    );
    // The same program on a file that does not say: read in whole units,
    // and warned about once.
    let out = postproc()
        .args(["check", "--machine", "afm-r1000"])
        .arg(&program)
        .assert();
    let stderr = String::from_utf8_lossy(&out.get_output().stderr).to_string();
    assert_eq!(
        stderr.matches("has no decimal point").count(),
        1,
        "{stderr}"
    );
}

/// Under G93 a takeup point of microns would need an inverse-time F of
/// hundreds of thousands: every F written stays within the range a Fanuc
/// control takes, and the compensated program reads back.
#[test]
fn inverse_time_pieces_stay_within_the_controls_range() {
    let dir = tempfile::tempdir().expect("dir");
    let program = write(
        dir.path(),
        "g93.nc",
        "%\nO1093\nG21 G90 G54 G0 X100. Y100. Z50.\nG43 H1 Z5.\nG1 Z-1. F200.\nG93 G1 X200. F250.\nX100. F250.\nY200. F250.\nY100. F250.\nG94 G0 Z50.\nM30\n%\n",
    );
    let out = dir.path().join("g93.comp.nc");
    postproc()
        .args([
            "compensate",
            "--machine",
            "afm-r1000",
            "--effects",
            "geometric",
        ])
        .arg(&program)
        .arg("-o")
        .arg(&out)
        .assert()
        .success();
    let text = std::fs::read_to_string(&out).expect("output");
    let body = text_without_header(&text);
    assert!(
        body.contains("takeup"),
        "a reversal gives a takeup point:\n{body}"
    );
    for word in body
        .split(|c: char| c.is_whitespace())
        .filter_map(|w| w.strip_prefix('F'))
    {
        let f: f64 = word.parse().expect("an F number");
        assert!(f <= 9999.999, "F{word} in\n{body}");
    }
    postproc()
        .args(["report", "--machine", "afm-r1000"])
        .arg(&out)
        .assert()
        .success();
}
