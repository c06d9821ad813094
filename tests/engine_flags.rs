//! The effect and run flags through the binary, for both languages: G-code
//! (samples/part.nc on afm-r1000) and RAPID (samples/drilling.mod on
//! abb-irb1600) take the same spellings of `--thermal-start`, `--effects`
//! and `--gain` alike, refuse bad values with the same message, and refuse
//! the flags that do not apply to their engine (exit 2, nothing written).

use crate::common::{postproc, repo};

/// The two languages: program and machine.
const ENGINES: [(&str, &str); 2] = [
    ("samples/part.nc", "afm-r1000"),
    ("samples/drilling.mod", "abb-irb1600"),
];

/// `postproc -q report PROGRAM -m MACHINE --format csv ARGS…`: exit code,
/// stdout and stderr.
fn report(program: &str, machine: &str, args: &[&str]) -> (Option<i32>, String, String) {
    let out = postproc()
        .args(["-q", "report"])
        .arg(repo(program))
        .args(["-m", machine, "--format", "csv"])
        .args(args)
        .output()
        .expect("runs");
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// The report of a run that must succeed.
fn report_ok(program: &str, machine: &str, args: &[&str]) -> String {
    let (code, stdout, stderr) = report(program, machine, args);
    assert_eq!(code, Some(0), "{program} {args:?}: {stderr}");
    stdout
}

#[test]
fn thermal_start_spellings_behave_the_same_for_both_languages() {
    for (program, machine) in ENGINES {
        let cold = report_ok(program, machine, &[]);
        let steady = report_ok(program, machine, &["--thermal-start", "steady"]);
        assert_ne!(steady, cold, "{program}: a steady start changes the report");
        for spelling in ["STEADY", "Steady", " steady "] {
            let other = report_ok(program, machine, &["--thermal-start", spelling]);
            assert_eq!(other, steady, "{program}: --thermal-start {spelling:?}");
        }
        let cold_upper = report_ok(program, machine, &["--thermal-start", "COLD"]);
        assert_eq!(cold_upper, cold, "{program}: --thermal-start COLD");
    }
}

#[test]
fn effect_and_gain_spellings_behave_the_same_for_both_languages() {
    for (program, machine) in ENGINES {
        let all = report_ok(program, machine, &[]);
        assert_eq!(report_ok(program, machine, &["--effects", "ALL"]), all);
        let thermal = report_ok(program, machine, &["--effects", "thermal"]);
        assert_ne!(thermal, all, "{program}");
        assert_eq!(
            report_ok(program, machine, &["--effects", "Thermal"]),
            thermal,
            "{program}"
        );
        // `geometric` is a name of both engines (robots: the kinematic errors).
        let geometric = report_ok(program, machine, &["--effects", "geometric,thermal"]);
        assert_eq!(
            report_ok(program, machine, &["--effects", "GEOMETRIC, thermal"]),
            geometric,
            "{program}"
        );
        let half = report_ok(program, machine, &["--gain", "thermal=0.5"]);
        assert_eq!(
            report_ok(program, machine, &["--gain", "THERMAL=0.5"]),
            half,
            "{program}"
        );
        // A gain scales an effect that is on; one switched off stays off.
        assert_eq!(
            report_ok(
                program,
                machine,
                &["--effects", "geometric", "--gain", "thermal=0.5"]
            ),
            report_ok(program, machine, &["--effects", "geometric"]),
            "{program}"
        );
    }
}

/// The message of a refused value, from its `error:` line on (the same
/// text whatever the program and machine).
fn error_line(stderr: &str) -> String {
    stderr
        .lines()
        .find(|l| l.starts_with("error:"))
        .unwrap_or_default()
        .to_string()
}

#[test]
fn bad_values_give_the_same_message_for_both_languages() {
    let cases: [(&[&str], &str); 7] = [
        (
            &["--thermal-start", "warm"],
            "for '--thermal-start <START>': `warm` is not cold, steady or a number of minutes (0..100000)",
        ),
        (
            &["--thermal-start", "1e308"],
            "`1e308` is not cold, steady or a number of minutes (0..100000)",
        ),
        (
            &["--effects", "magic"],
            "for '--effects <EFFECTS>': unknown effect `magic` (all, none; machine tools: geometric, static, thermal, dynamic; robots: kinematic (geometric), gravity, process (load), thermal, dynamic (vibration))",
        ),
        (
            &["--gain", "thermal"],
            "expected EFFECT=GAIN, got `thermal`",
        ),
        (&["--gain", "thermal=x"], "thermal: `x` is not a number"),
        (&["--gain", "thermal=11"], "thermal: 11 is outside 0..10"),
        (
            &["--force", "constant:1,2"],
            "for '--force <SPEC>': `constant:1,2`: expected none or constant:FX,FY,FZ[@workpiece|tool|feed] (N)",
        ),
    ];
    for (args, want) in cases {
        let mut messages = Vec::new();
        for (program, machine) in ENGINES {
            let (code, stdout, stderr) = report(program, machine, args);
            assert_eq!(code, Some(2), "{program} {args:?}: {stderr}");
            assert!(stdout.is_empty(), "{program} {args:?}");
            let line = error_line(&stderr);
            assert!(line.contains(want), "{program} {args:?}: {stderr}");
            messages.push(line);
        }
        assert_eq!(messages[0], messages[1], "{args:?}");
    }
}

#[test]
fn effect_names_of_the_other_engine_are_refused() {
    for (program, machine, args, want) in [
        (
            "samples/part.nc",
            "afm-r1000",
            ["--effects", "gravity"],
            "unknown effect `gravity` in --effects for a machine tool (known: geometric, static, thermal, dynamic)",
        ),
        (
            "samples/part.nc",
            "afm-r1000",
            ["--gain", "process=0.5"],
            "unknown effect `process` in --gain for a machine tool",
        ),
        (
            "samples/drilling.mod",
            "abb-irb1600",
            ["--effects", "static"],
            "unknown effect `static` in --effects for a robot (known: kinematic, gravity, process, thermal, dynamic)",
        ),
        (
            "samples/drilling.mod",
            "abb-irb1600",
            ["--gain", "static=2"],
            "unknown effect `static` in --gain for a robot",
        ),
    ] {
        let (code, _, stderr) = report(program, machine, &args);
        assert_eq!(code, Some(2), "{args:?}: {stderr}");
        assert!(stderr.contains(want), "{args:?}: {stderr}");
    }
}

#[test]
fn flags_of_the_other_engine_are_refused_and_nothing_is_written() {
    let dir = tempfile::tempdir().expect("temp dir");
    let cases: [(usize, &[&str], &str); 7] = [
        (
            1,
            &["--tolerance", "0.01"],
            "--tolerance is a G-code option",
        ),
        (1, &["--units", "mm"], "--units is a G-code option"),
        (
            1,
            &["--tool", "H1=100"],
            "--tool and --work-offset are G-code options",
        ),
        (
            1,
            &["--work-offset", "G54=0,0,0"],
            "--tool and --work-offset are G-code options",
        ),
        (
            0,
            &["--allow-reconfiguration"],
            "--allow-reconfiguration is a robot option",
        ),
        (
            0,
            &["--rapid-window-lines", "10"],
            "--rapid-window-lines is a RAPID option",
        ),
        // The same with the engine chosen by the machine, not the extension.
        (
            2,
            &["--tolerance", "0.01"],
            "--tolerance is a G-code option",
        ),
    ];
    let piped = dir.path().join("drilling.txt");
    std::fs::copy(repo("samples/drilling.mod"), &piped).expect("copy");
    for (engine, args, want) in cases {
        let (program, machine) = match engine {
            0 => (repo(ENGINES[0].0), ENGINES[0].1),
            1 => (repo(ENGINES[1].0), ENGINES[1].1),
            _ => (piped.clone(), ENGINES[1].1),
        };
        let out = dir.path().join("out");
        let run = postproc()
            .arg("compensate")
            .arg(&program)
            .args(["-m", machine])
            .args(args)
            .arg("-o")
            .arg(&out)
            .output()
            .expect("runs");
        let stderr = String::from_utf8_lossy(&run.stderr);
        assert_eq!(run.status.code(), Some(2), "{args:?}: {stderr}");
        assert!(stderr.contains(want), "{args:?}: {stderr}");
        assert!(!out.exists(), "{args:?}: nothing written");
    }
    // `batch` refuses them too, before it makes its folder.
    let out_dir = dir.path().join("batch");
    let run = postproc()
        .arg("batch")
        .arg(repo("samples/drilling.mod"))
        .args(["-m", "abb-irb1600", "--tolerance", "0.01", "--out-dir"])
        .arg(&out_dir)
        .output()
        .expect("runs");
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("--tolerance is a G-code option"),
        "{stderr}"
    );
    assert!(!out_dir.exists());
    // `check` takes the program flags only, and refuses those of the other
    // engine alike.
    let run = postproc()
        .arg("check")
        .arg(repo("samples/drilling.mod"))
        .args(["-m", "abb-irb1600", "--units", "inch"])
        .output()
        .expect("runs");
    assert_eq!(run.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&run.stderr).contains("--units is a G-code option"));
}

#[test]
fn the_same_flags_apply_where_they_belong() {
    // Each flag refused above is accepted by the engine it belongs to.
    let (program, machine) = ENGINES[0];
    for args in [
        &["--tool", "H1=100"][..],
        &["--work-offset", "G54=250,150,150"][..],
        &["--units", "mm"][..],
    ] {
        report_ok(program, machine, args);
    }
    let (program, machine) = ENGINES[1];
    for args in [
        &["--allow-reconfiguration"][..],
        &["--rapid-window-lines", "10"][..],
    ] {
        report_ok(program, machine, args);
    }
}

/// Regression: `compensate PROGRAM.nc --out-dir DIR` wrote the G-code
/// output beside the input (`PROGRAM.comp.nc`) and never made `DIR`. Both
/// languages write `DIR/<the program's file name>`, the same bytes as
/// `-o`, and nothing beside the input.
#[test]
fn regression_out_dir_takes_the_output_for_both_languages() {
    for (program, machine) in ENGINES {
        let dir = tempfile::tempdir().unwrap();
        let name = std::path::Path::new(program).file_name().unwrap();
        let input = dir.path().join(name);
        std::fs::copy(repo(program), &input).unwrap();
        let out_dir = dir.path().join("out");
        postproc()
            .args(["-q", "compensate"])
            .arg(&input)
            .args(["-m", machine, "--out-dir"])
            .arg(&out_dir)
            .assert()
            .success();
        let written = std::fs::read(out_dir.join(name)).expect("output in --out-dir");
        let beside: Vec<_> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(beside.len(), 2, "{program}: {beside:?}");
        let by_o = dir.path().join("by-o");
        postproc()
            .args(["-q", "compensate"])
            .arg(&input)
            .args(["-m", machine, "-o"])
            .arg(&by_o)
            .assert()
            .success();
        assert_eq!(written, std::fs::read(&by_o).unwrap(), "{program}");
    }
    // Standard input has no name to write under.
    let dir = tempfile::tempdir().unwrap();
    let out = postproc()
        .args(["compensate", "-", "-m", "afm-r1000", "--out-dir"])
        .arg(dir.path().join("out"))
        .write_stdin("G21 G90 G54\nG1 X10. F100.\n")
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("--out-dir needs a program file"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(!dir.path().join("out").exists());
}
