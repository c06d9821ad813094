//! Integration tests: regressions — each test pins one behaviour that a
//! specific fault would break (a lost file, a wrong edit, a crash, a
//! misleading message) and is named after that behaviour; others sit
//! beside the feature they guard.

use crate::common::{postproc, repo};

/// `report -o PROGRAM` must not replace the program with its own report
/// (G-code and RAPID): it is refused like `compensate -o PROGRAM`.
#[test]
fn regression_report_never_overwrites_its_input() {
    let dir = tempfile::tempdir().unwrap();
    for (sample, machine) in [
        ("samples/part.nc", "afm-r1000"),
        ("samples/drilling.mod", "abb-irb1600"),
    ] {
        let input = dir.path().join(sample.rsplit('/').next().unwrap());
        std::fs::copy(repo(sample), &input).unwrap();
        let before = std::fs::read(&input).unwrap();
        let out = postproc()
            .args(["report", "--machine", machine, "-o"])
            .arg(&input)
            .arg(&input)
            .output()
            .unwrap();
        assert_eq!(out.status.code(), Some(2), "{sample}");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(stderr.contains("would overwrite the input"), "{stderr}");
        assert_eq!(std::fs::read(&input).unwrap(), before, "{sample} changed");
    }
}

/// A failure to create the output names the output path the user gave,
/// never the random temporary file (`.postproc-XXXXXX`) it is written
/// through.
#[test]
fn regression_unwritable_output_names_the_output() {
    let dir = tempfile::tempdir().unwrap();
    let target = dir.path().join("no-such-folder").join("out.nc");
    let out = postproc()
        .args(["compensate", "--machine", "afm-r1000", "-o"])
        .arg(&target)
        .arg(repo("samples/part.nc"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("out.nc"), "{stderr}");
    assert!(!stderr.contains(".postproc-"), "{stderr}");
}

/// `simulate`, `calibrate` and `diagnose --write-model` refuse an `-o`
/// that names one of their own input files, and leave every input as it
/// was.
#[test]
fn regression_calibration_commands_never_overwrite_their_inputs() {
    let dir = tempfile::tempdir().unwrap();
    let copy = |rel: &str| {
        let p = dir.path().join(rel.rsplit('/').next().unwrap());
        std::fs::copy(repo(rel), &p).unwrap();
        p
    };
    let machine = copy("samples/observations/irb1600-truth.yaml");
    let poses = copy("samples/observations/irb1600-ldbb-poses.csv");
    let measured = copy("samples/observations/irb1600-ldbb-measured.csv");
    let model = copy("samples/diagnose/model.yaml");
    let diag = copy("samples/diagnose/measured.csv");
    let runs: Vec<(Vec<std::ffi::OsString>, &std::path::Path)> = vec![
        (
            vec![
                "simulate".into(),
                "--machine".into(),
                machine.clone().into(),
                "--observations".into(),
                poses.clone().into(),
                "-o".into(),
                poses.clone().into(),
            ],
            &poses,
        ),
        (
            vec![
                "calibrate".into(),
                "stiffness".into(),
                "--machine".into(),
                machine.clone().into(),
                "--observations".into(),
                measured.clone().into(),
                "-o".into(),
                machine.clone().into(),
            ],
            &machine,
        ),
        (
            vec![
                "diagnose".into(),
                "--machine".into(),
                model.clone().into(),
                "--observations".into(),
                diag.clone().into(),
                "--write-model".into(),
                model.clone().into(),
            ],
            &model,
        ),
    ];
    for (args, victim) in runs {
        let before = std::fs::read(victim).unwrap();
        let out = postproc().args(&args).output().unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {stderr}");
        assert!(stderr.contains("would overwrite the input"), "{stderr}");
        assert_eq!(std::fs::read(victim).unwrap(), before, "{args:?}");
    }
}

/// `-o /dev/null` (or any existing device or named pipe) is written to
/// directly, never renamed over: run as root, a rename would replace the
/// device with an ordinary file and break every other program that uses
/// it. Special files stay what they were.
#[cfg(unix)]
#[test]
fn regression_output_to_a_named_pipe_keeps_the_pipe() {
    use std::os::unix::fs::FileTypeExt;
    let dir = tempfile::tempdir().unwrap();
    let fifo = dir.path().join("out.fifo");
    let made = std::process::Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .expect("mkfifo runs");
    assert!(made.success());
    let reader = {
        let fifo = fifo.clone();
        std::thread::spawn(move || std::fs::read(fifo).unwrap())
    };
    let out = postproc()
        .args(["compensate", "--machine", "afm-r1000", "-o"])
        .arg(&fifo)
        .arg(repo("samples/part.nc"))
        .output()
        .unwrap();
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let through_pipe = reader.join().unwrap();
    assert!(
        std::fs::symlink_metadata(&fifo)
            .unwrap()
            .file_type()
            .is_fifo(),
        "the named pipe was replaced"
    );
    let plain = dir.path().join("plain.nc");
    postproc()
        .args(["compensate", "--machine", "afm-r1000", "-o"])
        .arg(&plain)
        .arg(repo("samples/part.nc"))
        .assert()
        .success();
    assert_eq!(through_pipe, std::fs::read(&plain).unwrap());
}

/// An output given as a symbolic link: the file it points at is replaced
/// and the link kept (a rename onto the link's own path would replace the
/// link with a file).
#[cfg(unix)]
#[test]
fn regression_output_through_a_symlink_keeps_the_link() {
    let dir = tempfile::tempdir().unwrap();
    let real = dir.path().join("real.nc");
    std::fs::write(&real, "old\n").unwrap();
    let link = dir.path().join("link.nc");
    std::os::unix::fs::symlink(&real, &link).unwrap();
    postproc()
        .args(["compensate", "--machine", "afm-r1000", "-o"])
        .arg(&link)
        .arg(repo("samples/part.nc"))
        .assert()
        .success();
    assert!(
        std::fs::symlink_metadata(&link)
            .unwrap()
            .file_type()
            .is_symlink()
    );
    let text = std::fs::read_to_string(&real).unwrap();
    assert!(text.contains("G1"), "{text}");
}

/// A robtarget literal spread over two lines, after another move on the
/// same line: its position-and-quaternion edit spans the line end where
/// the first move's annotation goes. The module is valid, so both targets
/// are rewritten (exit 0, no "edit … overlaps a previous edit") and the
/// line break inside the second literal is kept.
#[test]
fn regression_multi_line_robtarget_after_a_move_on_its_line() {
    let dir = tempfile::tempdir().unwrap();
    let module = dir.path().join("t.mod");
    std::fs::write(
        &module,
        "MODULE T\n\
  PERS tooldata tMill := [TRUE,[[0,0,182.5],[1,0,0,0]],[2.4,[0,0,85],[1,0,0,0],0.012,0.012,0.004]];\n\
  PROC main()\n\
    MoveL [[800,0,600],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]], v100, fine, tMill; MoveL [[800,50,600],\n\
      [0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]], v100, fine, tMill;\n\
  ENDPROC\n\
ENDMODULE\n",
    )
    .unwrap();
    let out = postproc()
        .args(["compensate", "--machine", "abb-irb1600", "-o", "-"])
        .arg(&module)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{stderr}");
    let text = String::from_utf8(out.stdout).unwrap();
    // Both targets rewritten (no literal keeps its programmed integers),
    // the line break inside the second literal kept.
    assert!(!text.contains("[[800,0,600]"), "{text}");
    assert!(!text.contains("[[800,50,600]"), "{text}");
    // The second literal still starts on the first move's line and ends on
    // the next one (its quaternion opens that line).
    let first = text.lines().position(|l| l.contains("tMill; MoveL [["));
    let next = first.and_then(|k| text.lines().nth(k + 1)).unwrap_or("");
    assert!(
        next.trim_start().starts_with('[') && next.contains("tMill;"),
        "the second literal's line break is gone:\n{text}"
    );
}

/// Errors of the input come before compensation failures wherever they are,
/// across the streaming pipeline's 4096-line chunks (the decision is made
/// for the whole program, not per chunk): `compensate` names the malformed
/// line `check` names, and a program whose only fault is an unreachable
/// target names that target. No output file either way.
#[test]
fn regression_input_errors_come_before_compensation_failures() {
    let dir = tempfile::tempdir().unwrap();
    let mut program = String::from("G90 G54 G0 X0 Y0 Z20\nG1 X900 Y10 F1000\n");
    for k in 0..6000 {
        program.push_str(&format!("G1 X{} Y{}\n", k % 300, k % 7));
    }
    let clean = dir.path().join("clean.nc");
    std::fs::write(&clean, &program).unwrap();
    // A syntax error some chunks after the unreachable target.
    let lines: Vec<&str> = program.lines().collect();
    let mut bad = lines.clone();
    bad[4999] = "G1 X1 Q";
    let faulty = dir.path().join("faulty.nc");
    std::fs::write(&faulty, bad.join("\n") + "\n").unwrap();

    let run = |cmd: &str, file: &std::path::Path| {
        let out_path = dir.path().join("out.nc");
        let mut c = postproc();
        c.args([cmd, "--machine", "afm-r1000"]);
        if cmd == "compensate" {
            c.arg("-o").arg(&out_path);
        }
        let out = c.arg(file).output().unwrap();
        assert!(!out_path.exists(), "no output file after an error");
        (
            out.status.code(),
            String::from_utf8_lossy(&out.stderr).into_owned(),
        )
    };
    for cmd in ["compensate", "check"] {
        let (code, err) = run(cmd, &faulty);
        assert_eq!(code, Some(2), "{cmd}: {err}");
        assert!(err.contains("faulty.nc:5000:"), "{cmd}: {err}");
    }
    let (code, err) = run("compensate", &clean);
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("clean.nc:2:") && err.contains("outside the travel"),
        "{err}"
    );
}

/// Move records are kept only when a report is written: a RAPID report
/// through `compensate --report` and through `batch --report-format` has
/// one row per move, and compensating without a report writes the same
/// module.
#[test]
fn regression_rapid_reports_keep_a_row_per_move() {
    let dir = tempfile::tempdir().unwrap();
    let input = repo("samples/drilling.mod");
    let moves = std::fs::read_to_string(&input)
        .unwrap()
        .lines()
        .filter(|l| {
            let t = l.trim_start();
            ["MoveL", "MoveJ", "MoveC", "MoveAbsJ"]
                .iter()
                .any(|k| t.starts_with(k))
        })
        .count();
    assert!(moves > 10);
    let rows = |path: &std::path::Path| {
        let v: serde_json::Value =
            serde_json::from_slice(&std::fs::read(path).expect("report written")).expect("JSON");
        v["rows"].as_array().map(Vec::len)
    };
    let with = dir.path().join("with.mod");
    let without = dir.path().join("without.mod");
    let report = dir.path().join("with.json");
    postproc()
        .args(["compensate", "--machine", "abb-irb1600", "-o"])
        .arg(&with)
        .arg("--report")
        .arg(&report)
        .arg(&input)
        .assert()
        .code(0);
    postproc()
        .args(["compensate", "--machine", "abb-irb1600", "-o"])
        .arg(&without)
        .arg(&input)
        .assert()
        .code(0);
    assert_eq!(rows(&report), Some(moves));
    assert_eq!(
        std::fs::read(&with).unwrap(),
        std::fs::read(&without).unwrap()
    );
    let out = dir.path().join("batch");
    postproc()
        .args([
            "batch",
            "--machine",
            "abb-irb1600",
            "--report-format",
            "json",
            "--out-dir",
        ])
        .arg(&out)
        .arg(&input)
        .assert()
        .code(0);
    assert_eq!(rows(&out.join("drilling.mod.report.json")), Some(moves));
}

/// The RAPID walks go a chunk of 4 096 jobs at a time (collecting the next
/// chunk, where a resolution error stops the collection, while the chunk
/// before is solved and written back): the error reported is still that of
/// the first failing move, whichever walk finds it and whichever chunks the
/// two failures are in (the cases put them on either side of a chunk
/// boundary, close together and far apart, in either order).
#[test]
fn regression_rapid_first_failing_move_across_chunks() {
    let dir = tempfile::tempdir().unwrap();
    let head = "MODULE M\n  PERS tooldata t1 := [TRUE,[[0,0,150],[1,0,0,0]],[2,[0,0,70],[1,0,0,0],0,0,0]];\n  PROC main()\n";
    // Line numbers: the header takes 3 lines, move k is on line k + 4.
    let far = "    MoveL [[9000,0,300],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]],v100,z1,t1;";
    let limits = "    MoveAbsJ [[500,0,0,0,30,0],[9E9,9E9,9E9,9E9,9E9,9E9]],v100,fine,t1;";
    // (unreachable target, joint-limit error): the first of the two fails.
    for (unreachable, beyond_limits) in [(4090, 4300), (4300, 4090), (100, 8800), (8800, 100)] {
        let mut text = String::from(head);
        for k in 0..9000 {
            let line = if k == unreachable {
                far.to_string()
            } else if k == beyond_limits {
                limits.to_string()
            } else {
                format!(
                    "    MoveL [[{:.1},{:.1},300],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]],v100,z1,t1;",
                    650.0 + (k % 50) as f64,
                    50.0 + (k % 37) as f64
                )
            };
            text.push_str(&line);
            text.push('\n');
        }
        text.push_str("  ENDPROC\nENDMODULE\n");
        let input = dir.path().join("m.mod");
        std::fs::write(&input, &text).unwrap();
        for threads in ["1", "2"] {
            let out = postproc()
                .args([
                    "compensate",
                    "--machine",
                    "abb-irb1600",
                    "--threads",
                    threads,
                    "-o",
                ])
                .arg(dir.path().join("out.mod"))
                .arg(&input)
                .output()
                .unwrap();
            let stderr = String::from_utf8_lossy(&out.stderr);
            let first = unreachable.min(beyond_limits) + 4;
            assert_eq!(out.status.code(), Some(2), "{stderr}");
            assert!(
                stderr.contains(&format!("m.mod:{first}:")),
                "{unreachable} {beyond_limits}: {stderr}"
            );
            assert!(!dir.path().join("out.mod").exists());
        }
    }
}

/// Runs `postproc ARGS…` in `dir`: exit code and stderr.
fn run_in(dir: &std::path::Path, args: &[&str]) -> (Option<i32>, String) {
    let out = postproc().current_dir(dir).args(args).output().unwrap();
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// Outputs are checked against every input, not only the program: `-o` or
/// `--report` on the machine file or the force table is refused, and two
/// spellings of one new file (`out.nc`, `./out.nc`) or a hard link of the
/// program are recognised as the same file.
#[test]
fn regression_outputs_never_overwrite_any_input_in_any_spelling() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::copy(repo("machines/afm-r1000.yaml"), d.join("m.yaml")).unwrap();
    std::fs::copy(repo("machines/abb-irb1600.yaml"), d.join("r.yaml")).unwrap();
    std::fs::copy(repo("samples/part.nc"), d.join("p.nc")).unwrap();
    std::fs::copy(repo("samples/drilling.mod"), d.join("d.mod")).unwrap();
    std::fs::write(d.join("f.csv"), "line,fx_n,fy_n,fz_n\n3,100,0,0\n").unwrap();
    std::fs::hard_link(d.join("p.nc"), d.join("hard.nc")).unwrap();
    std::fs::create_dir(d.join("sub")).unwrap();
    let before: Vec<(String, Vec<u8>)> = ["m.yaml", "r.yaml", "p.nc", "d.mod", "f.csv"]
        .iter()
        .map(|f| (f.to_string(), std::fs::read(d.join(f)).unwrap()))
        .collect();
    let cases: &[(&[&str], &str)] = &[
        (
            &["compensate", "p.nc", "-m", "m.yaml", "-o", "m.yaml"],
            "output would overwrite the input",
        ),
        (
            &["compensate", "p.nc", "-m", "m.yaml", "-o", "./m.yaml"],
            "output would overwrite the input",
        ),
        (
            &[
                "compensate",
                "p.nc",
                "-m",
                "m.yaml",
                "-o",
                "o.nc",
                "--report",
                "sub/../m.yaml",
            ],
            "report would overwrite the input",
        ),
        (
            &[
                "compensate",
                "p.nc",
                "-m",
                "m.yaml",
                "--force-table",
                "f.csv",
                "-o",
                "f.csv",
            ],
            "output would overwrite the input",
        ),
        (
            &[
                "report",
                "p.nc",
                "-m",
                "m.yaml",
                "--force-table",
                "f.csv",
                "-o",
                "./f.csv",
            ],
            "output would overwrite the input",
        ),
        (
            &["report", "p.nc", "-m", "m.yaml", "-o", "m.yaml"],
            "output would overwrite the input",
        ),
        (
            &["report", "d.mod", "-m", "r.yaml", "-o", "r.yaml"],
            "output would overwrite the input",
        ),
        (
            &[
                "compensate",
                "d.mod",
                "-m",
                "r.yaml",
                "-o",
                "o.mod",
                "--report",
                "./r.yaml",
            ],
            "report would overwrite the input",
        ),
        (
            &[
                "compensate",
                "p.nc",
                "-m",
                "m.yaml",
                "-o",
                "out.nc",
                "--report",
                "./out.nc",
            ],
            "report would overwrite the output",
        ),
        (
            &[
                "compensate",
                "d.mod",
                "-m",
                "r.yaml",
                "-o",
                "out.mod",
                "--report",
                "sub/../out.mod",
            ],
            "report would overwrite the output",
        ),
        (
            &["compensate", "p.nc", "-m", "m.yaml", "-o", "hard.nc"],
            "output would overwrite the input",
        ),
    ];
    for (args, want) in cases {
        let (code, err) = run_in(d, args);
        assert_eq!(code, Some(2), "{args:?}: {err}");
        assert!(err.contains(want), "{args:?}: {err}");
    }
    for (f, bytes) in &before {
        assert_eq!(&std::fs::read(d.join(f)).unwrap(), bytes, "{f} changed");
    }
    let mut left: Vec<String> = std::fs::read_dir(d)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    left.sort();
    assert_eq!(
        left,
        [
            "d.mod", "f.csv", "hard.nc", "m.yaml", "p.nc", "r.yaml", "sub"
        ]
    );
}

/// When standard output fails, `calibrate` exits 2 with a message naming
/// stdout, does not panic (no exit 101, as `print!` would), and writes no
/// model.
#[test]
fn regression_calibrate_on_a_failing_stdout_exits_2_and_writes_nothing() {
    if !std::path::Path::new("/dev/full").exists() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let out_yaml = dir.path().join("c.yaml");
    let out = std::process::Command::new(assert_cmd::cargo::cargo_bin("postproc"))
        .args([
            "calibrate",
            "kinematics",
            "--machine",
            "abb-irb1600",
            "--observations",
        ])
        .arg(repo("samples/observations/irb1600-kinematic-measured.csv"))
        .arg("-o")
        .arg(&out_yaml)
        .stdout(std::fs::File::create("/dev/full").unwrap())
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("stdout"), "{err}");
    assert!(!err.contains("panicked"), "{err}");
    assert!(!out_yaml.exists());
}

/// Noise beyond 10 mm is refused, as are negative and NaN values: taken,
/// `simulate --noise-um-per-m 1e308` would write `-inf` coordinates and
/// `--noise-um 1e9` 300-digit ones.
#[test]
fn regression_simulate_refuses_absurd_noise() {
    let dir = tempfile::tempdir().unwrap();
    let out_csv = dir.path().join("s.csv");
    for (flag, v) in [
        ("--noise-um-per-m", "1e308"),
        ("--noise-um", "1e9"),
        ("--noise-um=-1", ""),
        ("--noise-um", "NaN"),
    ] {
        let out = postproc()
            .args(["simulate", "--machine", "abb-irb1600", "--observations"])
            .arg(repo("samples/observations/irb1600-kinematic-poses.csv"))
            .args([flag, v].into_iter().filter(|a| !a.is_empty()))
            .arg("-o")
            .arg(&out_csv)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{flag} {v}: {err}");
        let name = flag.split('=').next().unwrap_or(flag);
        assert!(
            err.contains(&format!("{name} must be a number within 0..10000")),
            "{err}"
        );
        assert!(!out_csv.exists());
    }
}

/// Absurd or useless options are refused with exit 2: a robot warm-up of
/// 1e308 minutes, `--decimals` that would round the compensation away
/// (G-code 0–2 at the default tolerance; RAPID 0–2, refused rather than
/// raised to 3), a diagnose hold-out of no rows; and `batch` refuses its
/// options before it makes its output folder.
#[test]
fn regression_useless_options_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let o = dir.path().join("o.out");
    let o = o.to_str().unwrap();
    let part = repo("samples/part.nc");
    let drilling = repo("samples/drilling.mod");
    let (part, drilling) = (part.to_str().unwrap(), drilling.to_str().unwrap());
    let model = repo("samples/diagnose/model.yaml");
    let measured = repo("samples/diagnose/measured.csv");
    let out_dir = dir.path().join("batch-out");
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (
            vec![
                "compensate",
                drilling,
                "-m",
                "abb-irb1600",
                "-o",
                o,
                "--thermal-start",
                "1e308",
            ],
            "number of minutes (0..100000)",
        ),
        (
            vec![
                "compensate",
                part,
                "-m",
                "afm-r1000",
                "-o",
                o,
                "--decimals",
                "2",
            ],
            "--decimals 2: rounding moves coordinates by up to 0.005 mm",
        ),
        (
            vec![
                "compensate",
                drilling,
                "-m",
                "abb-irb1600",
                "-o",
                o,
                "--decimals",
                "0",
            ],
            "robot targets keep at least 3 decimals",
        ),
        (
            vec![
                "diagnose",
                "--machine",
                model.to_str().unwrap(),
                "--observations",
                measured.to_str().unwrap(),
                "--holdout",
                "0.0000001",
            ],
            "holds out 0 of the",
        ),
        (
            vec![
                "batch",
                part,
                "-m",
                "afm-r1000",
                "--out-dir",
                out_dir.to_str().unwrap(),
                "--tolerance",
                "0",
            ],
            "--tolerance 0",
        ),
    ];
    for (args, want) in cases {
        let out = postproc().args(&args).output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains(want), "{args:?}: {err}");
    }
    assert!(!std::path::Path::new(o).exists());
    assert!(!out_dir.exists(), "batch made its output folder");
    // Coarser decimals within a coarser tolerance are fine.
    let out = postproc()
        .args([
            "compensate",
            part,
            "-m",
            "afm-r1000",
            "-o",
            o,
            "--decimals",
            "2",
            "--tolerance",
            "0.005",
        ])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(0));
}

/// `batch` follows each folder once, so a link back up its folder tree
/// neither multiplies the outputs nor loops forever, and takes regular
/// files only, so a named pipe with a program's extension cannot hang it
/// (it is reported as "not a regular file").
#[cfg(unix)]
#[test]
fn regression_batch_follows_each_folder_once_and_takes_regular_files_only() {
    let dir = tempfile::tempdir().unwrap();
    let tree = dir.path().join("L");
    std::fs::create_dir(&tree).unwrap();
    std::fs::copy(repo("samples/part.nc"), tree.join("part.nc")).unwrap();
    std::os::unix::fs::symlink("../L", tree.join("self")).unwrap();
    std::os::unix::fs::symlink("..", tree.join("up")).unwrap();
    let fifo = tree.join("pipe.nc");
    let made = std::process::Command::new("mkfifo").arg(&fifo).status();
    let out_dir = dir.path().join("out");
    let out = postproc()
        .args(["batch", "--machine", "afm-r1000", "--out-dir"])
        .arg(&out_dir)
        .arg(&tree)
        .timeout(std::time::Duration::from_secs(60))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{err}");
    let mut written: Vec<String> = std::fs::read_dir(&out_dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    written.sort();
    assert_eq!(written, ["batch-summary.json", "part.nc"]);
    if made.is_ok_and(|s| s.success()) {
        let out = postproc()
            .args(["batch", "--machine", "afm-r1000", "--out-dir"])
            .arg(dir.path().join("out2"))
            .arg(&fifo)
            .timeout(std::time::Duration::from_secs(60))
            .output()
            .unwrap();
        let summary = std::fs::read_to_string(dir.path().join("out2/batch-summary.json")).unwrap();
        // A program that fails is bad input: exit 2.
        assert_eq!(out.status.code(), Some(2), "{summary}");
        assert!(summary.contains("not a regular file"), "{summary}");
    }
}

/// With `--report` on a device that fails (`/dev/full`) the run exits 2
/// and the program is not put in place either: neither output is renamed
/// into place unless both are written. G-code, RAPID read whole and a
/// window at a time.
#[test]
fn regression_a_failing_report_leaves_the_program_unwritten() {
    if !std::path::Path::new("/dev/full").exists() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("o.out");
    let o = out.to_str().unwrap();
    let part = repo("samples/part.nc");
    let drilling = repo("samples/drilling.mod");
    let (part, drilling) = (part.to_str().unwrap(), drilling.to_str().unwrap());
    for args in [
        vec![
            "compensate",
            part,
            "-m",
            "afm-r1000",
            "-o",
            o,
            "--report",
            "/dev/full",
        ],
        vec![
            "compensate",
            drilling,
            "-m",
            "abb-irb1600",
            "-o",
            o,
            "--report",
            "/dev/full",
        ],
        vec![
            "compensate",
            drilling,
            "-m",
            "abb-irb1600",
            "--rapid-window-lines",
            "2",
            "-o",
            o,
            "--report",
            "/dev/full",
        ],
    ] {
        // An earlier output stays as it was.
        std::fs::write(&out, "earlier\n").unwrap();
        let run = postproc().args(&args).output().unwrap();
        let err = String::from_utf8_lossy(&run.stderr);
        assert_eq!(run.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains("No space left"), "{args:?}: {err}");
        assert_eq!(
            std::fs::read_to_string(&out).unwrap(),
            "earlier\n",
            "{args:?}"
        );
        let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
        assert_eq!(left.len(), 1, "{args:?}: temporary files left");
    }
}

/// The tick labels of an SVG report are told apart and never `-0`, even
/// for a one-move module whose ranges are tiny (rounded naively, its axes
/// would read `-1 -0 -0 -0 -0 -0 0 0 0 0 0` and its source-line axis
/// `4 4 4 4 4 4 5 5 5 5 5`).
#[test]
fn regression_svg_ticks_are_distinct_and_never_negative_zero() {
    let dir = tempfile::tempdir().unwrap();
    let one = dir.path().join("one.mod");
    std::fs::write(
        &one,
        "MODULE One\n  PROC main()\n    MoveL [[700,0,400],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]],v100,z1,tool0;\n  ENDPROC\nENDMODULE\n",
    )
    .unwrap();
    let g28 = dir.path().join("g28.nc");
    std::fs::write(&g28, "G91 G28 Z0.\n").unwrap();
    for (p, m) in [(&one, "abb-irb1600"), (&g28, "afm-r1000")] {
        let out = postproc()
            .args(["report", "--machine", m, "--format", "svg"])
            .arg(p)
            .output()
            .unwrap();
        assert_eq!(out.status.code(), Some(0));
        let svg = String::from_utf8(out.stdout).unwrap();
        let doc = roxmltree::Document::parse(&svg).unwrap();
        let texts: Vec<String> = doc
            .descendants()
            .filter(|n| n.has_tag_name("text"))
            .map(|n| n.text().unwrap_or("").trim().to_string())
            .collect();
        let numeric: Vec<&String> = texts
            .iter()
            .filter(|t| !t.is_empty() && t.parse::<f64>().is_ok())
            .collect();
        assert!(numeric.len() > 10, "{texts:?}");
        for t in &numeric {
            assert!(
                !(t.starts_with('-') && t.parse::<f64>().unwrap() == 0.0),
                "{p:?}: {t}"
            );
        }
        for w in numeric.windows(2) {
            assert_ne!(w[0], w[1], "{p:?}: repeated tick label in {numeric:?}");
        }
    }
}

/// `check --machine` refuses programs that leave the machine's travel with
/// the same message as `compensate`, after any input error, rather than
/// passing them (exit 0, "warnings: 0").
#[test]
fn regression_check_refuses_positions_beyond_the_travel() {
    for bad in ["travel.nc", "wild-incremental.nc"] {
        let p = repo("tests/bad/programs").join(bad);
        let check = postproc()
            .args(["check", "--machine", "afm-r1000"])
            .arg(&p)
            .output()
            .unwrap();
        let comp = postproc()
            .args(["compensate", "--machine", "afm-r1000", "-o", "-"])
            .arg(&p)
            .output()
            .unwrap();
        let (ce, me) = (
            String::from_utf8_lossy(&check.stderr),
            String::from_utf8_lossy(&comp.stderr),
        );
        assert_eq!(check.status.code(), Some(2), "{bad}: {ce}");
        assert!(ce.contains("outside the travel"), "{bad}: {ce}");
        let error_line = |t: &str| {
            t.lines()
                .find(|l| l.starts_with("error:"))
                .map(str::to_string)
        };
        assert_eq!(error_line(&ce), error_line(&me), "{bad}");
    }
}

/// Messages locate the fault and stay short: a force table with invalid
/// UTF-8 gets a line and column, a machine path that is not a regular file
/// is called so (not "not found"), and an absurd option value is not
/// echoed in 309 digits.
#[test]
fn regression_messages_locate_and_stay_short() {
    let dir = tempfile::tempdir().unwrap();
    let table = dir.path().join("ft.csv");
    std::fs::write(&table, b"line,fx_n,fy_n,fz_n\n3,1\xff0,0,0\n").unwrap();
    let part = repo("samples/part.nc");
    let cases: Vec<(Vec<&std::ffi::OsStr>, &str)> = vec![
        (
            vec![
                "report".as_ref(),
                part.as_os_str(),
                "-m".as_ref(),
                "afm-r1000".as_ref(),
                "--force-table".as_ref(),
                table.as_os_str(),
            ],
            "ft.csv:2:4: invalid UTF-8: byte 0xFF",
        ),
        (
            vec![
                "check".as_ref(),
                part.as_os_str(),
                "--machine".as_ref(),
                dir.path().as_os_str(),
            ],
            "is not a regular file",
        ),
        (
            vec![
                "compensate".as_ref(),
                part.as_os_str(),
                "-m".as_ref(),
                "afm-r1000".as_ref(),
                "-o".as_ref(),
                "-".as_ref(),
                "--tolerance".as_ref(),
                "1e308".as_ref(),
            ],
            "--tolerance 1e308: must be within",
        ),
        (
            vec![
                "compensate".as_ref(),
                part.as_os_str(),
                "-m".as_ref(),
                "afm-r1000".as_ref(),
                "-o".as_ref(),
                "-".as_ref(),
                "--milling-depth".as_ref(),
                "1e308".as_ref(),
            ],
            "--milling-depth 1e308: must be within",
        ),
    ];
    for (args, want) in cases {
        let out = postproc().args(&args).output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains(want), "{args:?}: {err}");
        assert!(err.len() < 300, "{args:?}: {err}");
    }
}

/// An interrupt (SIGINT, SIGTERM) while a large program is being written
/// leaves no hidden temporary file (`.postproc-XXXXXX`, tens of MB) beside
/// the output: the run removes it before it ends.
#[cfg(unix)]
#[test]
fn regression_an_interrupt_leaves_no_temporary_file() {
    let dir = tempfile::tempdir().unwrap();
    let program = dir.path().join("big.nc");
    let mut text = String::from("G90 G17 G21 G54\nT1 M6\nG43 H1 G0 X0 Y0 Z20\nG1 Z0 F2000\n");
    for k in 0..400_000 {
        let x = if k % 2 == 0 { 400 } else { 0 };
        text.push_str(&format!("X{x} Y{:.3}\n", k as f64 * 0.001));
    }
    std::fs::write(&program, text).unwrap();
    let out_dir = dir.path().join("out");
    std::fs::create_dir(&out_dir).unwrap();
    let mut interrupted = 0;
    for signal in ["-INT", "-TERM"] {
        let mut child = std::process::Command::new(assert_cmd::cargo::cargo_bin("postproc"))
            .args(["compensate", "--machine", "afm-r1000", "-o"])
            .arg(out_dir.join("o.nc"))
            .arg(&program)
            .stderr(std::process::Stdio::null())
            .spawn()
            .unwrap();
        // Wait for the temporary file to appear (or the run to end).
        let mut seen = false;
        for _ in 0..400 {
            if std::fs::read_dir(&out_dir).unwrap().next().is_some() {
                seen = true;
                break;
            }
            if child.try_wait().unwrap().is_some() {
                break;
            }
            std::thread::sleep(std::time::Duration::from_millis(5));
        }
        let killed = std::process::Command::new("kill")
            .arg(signal)
            .arg(child.id().to_string())
            .status()
            .unwrap();
        let status = child.wait().unwrap();
        let left: Vec<String> = std::fs::read_dir(&out_dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        if seen && killed.success() && !status.success() {
            interrupted += 1;
            assert!(left.is_empty(), "{signal}: left {left:?}");
        } else {
            // The run ended before the signal: only the finished output.
            assert!(left.iter().all(|f| f == "o.nc"), "{signal}: left {left:?}");
            let _ = std::fs::remove_file(out_dir.join("o.nc"));
        }
    }
    // A 400 000-block program takes far longer than the wait for its
    // temporary file: at least one run was interrupted while writing.
    assert!(interrupted > 0, "no run was interrupted");
}

/// `batch` never writes its outputs and summary through a link planted in
/// the output folder that reaches an input such as the machine file: they
/// are checked against every input like `compensate`'s.
#[cfg(unix)]
#[test]
fn regression_batch_outputs_never_reach_an_input_through_a_link() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::copy(repo("machines/afm-r1000.yaml"), d.join("m.yaml")).unwrap();
    std::fs::copy(repo("samples/part.nc"), d.join("part.nc")).unwrap();
    let machine = std::fs::read(d.join("m.yaml")).unwrap();
    for planted in ["part.nc", "batch-summary.json"] {
        let out = d.join(format!("out-{planted}"));
        std::fs::create_dir(&out).unwrap();
        std::os::unix::fs::symlink(d.join("m.yaml"), out.join(planted)).unwrap();
        let run = postproc()
            .args(["batch", "--machine"])
            .arg(d.join("m.yaml"))
            .arg("--out-dir")
            .arg(&out)
            .arg(d.join("part.nc"))
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&run.stderr);
        assert_eq!(run.status.code(), Some(2), "{planted}: {err}");
        assert_eq!(
            std::fs::read(d.join("m.yaml")).unwrap(),
            machine,
            "{planted}"
        );
        // The planted link, and the summary of the failed program (a
        // summary that would reach an input is refused before any program).
        let mut left: Vec<String> = std::fs::read_dir(&out)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        left.sort();
        let want: &[&str] = if planted == "part.nc" {
            &["batch-summary.json", "part.nc"]
        } else {
            &["batch-summary.json"]
        };
        assert_eq!(left, want, "{planted}");
    }
}
