//! Integration tests: RAPID modules read a window at a time
//! (`--rapid-window-lines`, the default for modules of 1 MB and more)
//! give, through the binary, the bytes, messages and exit codes of the
//! module read whole.

use std::path::{Path, PathBuf};

use crate::common::{postproc, repo};

/// The sample modules with the robot file each is written for, and
/// another robot file for each.
fn cases() -> Vec<(PathBuf, PathBuf)> {
    let milling = repo("samples/irb1600-milling.yaml");
    let plain = repo("machines/abb-irb1600.yaml");
    let mut v = Vec::new();
    for m in ["samples/milling.mod", "samples/drilling.mod"] {
        v.push((repo(m), milling.clone()));
        v.push((repo(m), plain.clone()));
    }
    v
}

/// Runs `postproc ARGS…` and returns exit code, stdout and stderr.
fn run(args: &[&str]) -> (i32, Vec<u8>, String) {
    let out = postproc().args(args).output().expect("runs");
    (
        out.status.code().unwrap_or(-1),
        out.stdout,
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// `postproc -v SUB --rapid-window-lines LINES REST…`: a run that reads
/// its module a window at a time (and says so at `-v`).
fn run_windowed(sub: &str, lines: &str, rest: &[&str]) -> (i32, Vec<u8>, String) {
    let mut args = vec!["-v", sub, "--rapid-window-lines", lines];
    args.extend(rest);
    run(&args)
}

/// The files in `dir`, sorted.
fn listing(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .expect("dir")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

#[test]
fn streamed_compensation_writes_the_bytes_of_the_whole_module() {
    let dir = tempfile::tempdir().expect("tempdir");
    for (k, (module, machine)) in cases().iter().enumerate() {
        let (m, p) = (machine.to_str().unwrap(), module.to_str().unwrap());
        let whole = dir.path().join(format!("whole{k}.mod"));
        let (code, _, err) = run(&[
            "compensate",
            "--machine",
            m,
            "--effects",
            "all",
            "-o",
            whole.to_str().unwrap(),
            p,
        ]);
        assert_eq!(code, 0, "{p}: {err}");
        let want = std::fs::read(&whole).expect("output");
        for lines in ["1", "2", "5", "1000"] {
            let streamed = dir.path().join(format!("s{k}_{lines}.mod"));
            let out = streamed.to_str().unwrap();
            let args = ["--machine", m, "--effects", "all", "-o", out, p];
            let (code, _, err) = run_windowed("compensate", lines, &args);
            assert_eq!(code, 0, "{p}: {err}");
            // Read a window at a time indeed (not read whole after all).
            let said = format!("read a window of {lines} lines at a time");
            assert!(err.contains(&said), "{err}");
            assert_eq!(
                std::fs::read(&streamed).expect("output"),
                want,
                "{p} with {m}, windows of {lines} lines"
            );
        }
        // To standard output as well.
        let (code, stdout, err) = run(&[
            "compensate",
            "--machine",
            m,
            "--effects",
            "all",
            "--rapid-window-lines",
            "3",
            "-o",
            "-",
            p,
        ]);
        assert_eq!(code, 0, "{p}: {err}");
        assert_eq!(stdout, want, "{p} to standard output");
    }
    // Outputs only: no temporary file is left beside them.
    assert!(
        listing(dir.path())
            .iter()
            .all(|f| f.starts_with("whole") || f.starts_with('s')),
        "{:?}",
        listing(dir.path())
    );
}

#[test]
fn streamed_check_prints_what_the_whole_module_check_prints() {
    for (module, machine) in cases() {
        let (m, p) = (machine.to_str().unwrap(), module.to_str().unwrap());
        // Against a robot, and of the syntax alone (no machine).
        for machine_args in [vec!["--machine", m], vec![]] {
            let mut args = machine_args.clone();
            args.push(p);
            let mut whole_args = vec!["check"];
            whole_args.extend(&args);
            let whole = run(&whole_args);
            let streamed = run_windowed("check", "2", &args);
            assert_eq!(whole.0, 0, "{p}: {}", whole.2);
            assert!(streamed.2.contains("at a time"), "{}", streamed.2);
            assert_eq!(streamed.0, whole.0);
            assert_eq!(
                String::from_utf8_lossy(&streamed.1),
                String::from_utf8_lossy(&whole.1)
            );
        }
    }
}

/// Warm thermal starts (steady, warm-up: a first pass adds up the time
/// line) give the bytes of the module read whole.
#[test]
fn warm_thermal_starts_give_the_whole_module_bytes() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (m, p) = (
        repo("samples/irb1600-milling.yaml"),
        repo("samples/milling.mod"),
    );
    let (m, p) = (m.to_str().unwrap(), p.to_str().unwrap());
    for start in ["steady", "20"] {
        let mut outs = Vec::new();
        for window in [&[][..], &["--rapid-window-lines", "2"][..]] {
            let out = dir.path().join(format!("o{}.mod", outs.len()));
            let mut args = vec!["compensate", "--machine", m, "--effects", "all"];
            args.extend(["--thermal-start", start]);
            args.extend(window);
            args.extend(["-o", out.to_str().unwrap(), p]);
            args.insert(0, "-v");
            let (code, _, err) = run(&args);
            assert_eq!(code, 0, "{err}");
            assert_eq!(err.contains("at a time"), !window.is_empty(), "{err}");
            outs.push(std::fs::read(&out).expect("output"));
        }
        assert_eq!(outs[0], outs[1], "--thermal-start {start}");
    }
}

/// Reports of every move (`compensate --report`, `report`) written a
/// window at a time are those of the module read whole, in every format.
#[test]
fn reports_from_windows_are_the_whole_module_reports() {
    let dir = tempfile::tempdir().expect("tempdir");
    for (module, machine) in cases() {
        let (m, p) = (machine.to_str().unwrap(), module.to_str().unwrap());
        for ext in ["csv", "json", "svg"] {
            let mut got = Vec::new();
            for window in [&[][..], &["--rapid-window-lines", "3"][..]] {
                let k = got.len();
                let out = dir.path().join(format!("o{k}.mod"));
                let report = dir.path().join(format!("r{k}.{ext}"));
                let mut args = vec!["-v", "compensate", "--machine", m, "--effects", "all"];
                args.extend(window);
                args.extend(["--report", report.to_str().unwrap()]);
                args.extend(["-o", out.to_str().unwrap(), p]);
                let (code, _, err) = run(&args);
                assert_eq!(code, 0, "{p} {ext}: {err}");
                assert_eq!(err.contains("at a time"), !window.is_empty(), "{err}");
                got.push(std::fs::read(&out).expect("output"));
                got.push(std::fs::read(&report).expect("report"));
                // The dry run, to standard output.
                let mut args = vec!["report", "--machine", m, "--effects", "all"];
                args.extend(window);
                args.extend(["--format", ext, p]);
                let (code, stdout, err) = run(&args);
                assert_eq!(code, 0, "{p} {ext}: {err}");
                got.push(stdout);
            }
            assert!(got[1].len() > 100 && got[2].len() > 100);
            assert_eq!(got[..3], got[3..], "{p} with {m}, {ext}");
        }
    }
    let left = listing(dir.path());
    assert!(
        left.iter()
            .all(|f| f.starts_with('o') || f.starts_with('r')),
        "{left:?}"
    );
}

/// A module with an error — one the window reader meets in a later window,
/// after earlier windows were written — and the malformed modules of the
/// corpus: the message and exit code of the whole-module run, and no
/// output file.
#[test]
fn errors_are_those_of_the_whole_module_and_leave_nothing() {
    let dir = tempfile::tempdir().expect("tempdir");
    let mut src = String::from(
        "MODULE Late\n  PERS tooldata t1 := [TRUE,[[0,0,150],[1,0,0,0]],[2,[0,0,70],[1,0,0,0],0.01,0.01,0.004]];\n  PROC main()\n",
    );
    for k in 0..40 {
        src.push_str(&format!(
            "    MoveL [[{},50,300],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]],v200,z1,t1;\n",
            650 + 5 * k
        ));
    }
    src.push_str(
        "    MoveL [[5000,50,300],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]],v200,z1,t1;\n",
    );
    // Line 44: a target out of reach (found when solving); line 45 in the
    // second file: an undeclared one (found when planning, first).
    let unreachable = dir.path().join("late_unreachable.mod");
    std::fs::write(&unreachable, format!("{src}  ENDPROC\nENDMODULE\n")).expect("write");
    let missing = dir.path().join("late_missing.mod");
    std::fs::write(
        &missing,
        format!("{src}    MoveL pMissing,v200,z1,t1;\n  ENDPROC\nENDMODULE\n"),
    )
    .expect("write");
    let mut files = vec![unreachable, missing];
    for e in std::fs::read_dir(repo("tests/bad/programs")).expect("corpus") {
        let p = e.expect("entry").path();
        if p.extension().is_some_and(|x| x == "mod") {
            files.push(p);
        }
    }
    files.sort();
    let m = repo("machines/abb-irb1600.yaml");
    let m = m.to_str().unwrap();
    for p in &files {
        let p = p.to_str().unwrap();
        let out = dir.path().join("out.mod");
        let whole = run(&["compensate", "--machine", m, "-o", out.to_str().unwrap(), p]);
        assert_ne!(whole.0, 0, "{p} compensates");
        assert!(!out.exists());
        for lines in ["1", "4"] {
            let streamed = run(&[
                "compensate",
                "--machine",
                m,
                "--rapid-window-lines",
                lines,
                "-o",
                out.to_str().unwrap(),
                p,
            ]);
            assert_eq!((streamed.0, &streamed.2), (whole.0, &whole.2), "{p}");
            assert!(!out.exists(), "{p}: output left");
            let check = run(&["check", "--machine", m, "--rapid-window-lines", lines, p]);
            let check_whole = run(&["check", "--machine", m, p]);
            assert_eq!((check.0, &check.2), (check_whole.0, &check_whole.2), "{p}");
            // The syntax check (no machine) as well.
            let syntax = run(&["check", "--rapid-window-lines", lines, p]);
            let syntax_whole = run(&["check", p]);
            assert_eq!(syntax, syntax_whole, "{p}");
        }
    }
    let m_out = dir.path().join("out.mod");
    for (file, want) in [
        ("late_unreachable.mod", "late_unreachable.mod:44:"),
        (
            "late_missing.mod",
            "late_missing.mod:45:11: `pMissing` is not declared",
        ),
    ] {
        let (_, _, err) = run(&[
            "compensate",
            "--machine",
            m,
            "--rapid-window-lines",
            "2",
            "-o",
            m_out.to_str().unwrap(),
            dir.path().join(file).to_str().unwrap(),
        ]);
        assert!(err.contains(want), "{file}: {err}");
    }
    assert_eq!(
        listing(dir.path()),
        vec![
            "late_missing.mod".to_string(),
            "late_unreachable.mod".to_string()
        ]
    );
}

#[test]
fn a_window_of_zero_lines_is_refused() {
    let (code, _, err) = run(&[
        "check",
        "--machine",
        "abb-irb1600",
        "--rapid-window-lines",
        "0",
        repo("samples/milling.mod").to_str().unwrap(),
    ]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("--rapid-window-lines must be at least 1"),
        "{err}"
    );
}

/// `batch` reads RAPID modules a window at a time as `compensate` does
/// (forced here): the same programs and reports as read whole.
#[test]
fn batch_reads_modules_a_window_at_a_time_with_the_same_results() {
    let dir = tempfile::tempdir().expect("tempdir");
    let mut outs = Vec::new();
    for window in [&[][..], &["--rapid-window-lines", "2"][..]] {
        let out = dir.path().join(format!("out{}", outs.len()));
        let (code, _, err) = {
            let mut args = vec![
                "-v",
                "batch",
                "--machine",
                "abb-irb1600",
                "--report-format",
                "csv",
            ];
            args.extend(window);
            args.push("--out-dir");
            let o = postproc()
                .args(&args)
                .arg(&out)
                .arg(repo("samples/drilling.mod"))
                .arg(repo("samples/milling.mod"))
                .output()
                .expect("runs");
            (
                o.status.code().unwrap_or(-1),
                o.stdout,
                String::from_utf8_lossy(&o.stderr).into_owned(),
            )
        };
        assert_eq!(code, 0, "{err}");
        assert_eq!(err.contains("at a time"), !window.is_empty(), "{err}");
        let files: Vec<Vec<u8>> = [
            "drilling.mod",
            "milling.mod",
            "drilling.mod.report.csv",
            "milling.mod.report.csv",
        ]
        .iter()
        .map(|f| std::fs::read(out.join(f)).unwrap_or_else(|_| panic!("{f}")))
        .collect();
        outs.push(files);
    }
    assert_eq!(outs[0], outs[1]);
}

/// The prologue of the modules of the cases below: two robtargets.
const P: &str = "MODULE T\n  CONST robtarget p1 := [[750,0,500],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\n  CONST robtarget p2 := [[760,20,480],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\n";

/// Modules whose lines outside any window the whole parse refuses (end
/// lines with text after the end word, a bad header of an empty routine,
/// blanks the parser does not take) and a TRAP with a statement on its
/// header line: `check` and `compensate` with windows say and write what
/// they do without (the refused modules fail rather than run to exit 0,
/// and the TRAP move is counted once, not once per window).
#[test]
fn lines_outside_windows_are_held_to_the_whole_parse() {
    let dir = tempfile::tempdir().expect("tempdir");
    let body = "  PROC main()\n    MoveL p1, v100, z1, tool0;\n    MoveL p2, v100, z1, tool0;\n";
    let cases = [
        format!("{P}{body}  ENDPROC;\nENDMODULE\n"),
        format!("{P}{body}  ENDPROC x\nENDMODULE\n"),
        format!("{P}{body}  ENDPROC\nENDMODULE garbage\n"),
        format!("{P}{body}  ENDPROC\n  PROC 9bad()\n  ENDPROC\nENDMODULE\n"),
        format!("{P}{body}  ENDPROC\n\u{c}\nENDMODULE\n"),
        format!("{P}{body}  ENDPROC\n\u{a0}\nENDMODULE\n"),
        format!("{P}{body}  ENDPROC\nENDMODULE\n\u{3000}\n"),
        format!(
            "{P}{body}  ENDPROC\n  TRAP t MoveL p2, v100, z1, tool0;\n    MoveL p1, v100, z1, tool0;\n  ENDTRAP\nENDMODULE\n"
        ),
        // Taken a window at a time: a main loop, an empty routine.
        format!(
            "{P}  PROC main()\n    WHILE TRUE DO\n      MoveL p1, v100, z1, tool0;\n    ENDWHILE\n  ENDPROC\n  PROC none()\n  ENDPROC\nENDMODULE\n"
        ),
    ];
    let mut windowed = 0;
    for (k, src) in cases.iter().enumerate() {
        let path = dir.path().join(format!("c{k}.mod"));
        std::fs::write(&path, src).expect("write");
        let p = path.to_str().unwrap();
        let out = dir.path().join("out.mod");
        let o = out.to_str().unwrap();
        let whole_check = run(&["check", "--machine", "abb-irb1600", p]);
        let whole = run(&["compensate", "--machine", "abb-irb1600", "-o", o, p]);
        let whole_out = std::fs::read(&out).ok();
        let _ = std::fs::remove_file(&out);
        for lines in ["1", "2"] {
            let check = run(&[
                "-v",
                "check",
                "--machine",
                "abb-irb1600",
                "--rapid-window-lines",
                lines,
                p,
            ]);
            let comp = run(&[
                "compensate",
                "--machine",
                "abb-irb1600",
                "--rapid-window-lines",
                lines,
                "-o",
                o,
                p,
            ]);
            assert_eq!(
                (check.0, &check.1),
                (whole_check.0, &whole_check.1),
                "case {k}"
            );
            let syntax = run(&["check", "--rapid-window-lines", lines, p]);
            assert_eq!(syntax, run(&["check", p]), "case {k}");
            assert_eq!((comp.0, &comp.2), (whole.0, &whole.2), "case {k}");
            assert_eq!(std::fs::read(&out).ok(), whole_out, "case {k}");
            let _ = std::fs::remove_file(&out);
            windowed += usize::from(check.2.contains("at a time"));
        }
    }
    // The last case is taken a window at a time; the others are not.
    assert_eq!(windowed, 2);
}

/// Outputs that are devices or in folders that do not exist: the module
/// read a window at a time writes to the device, and fails on the folder
/// with the message of the whole-module run (the folder is checked before
/// any temporary file is made beside the output).
#[test]
fn device_and_missing_folder_outputs_behave_as_whole() {
    let p = repo("samples/drilling.mod");
    let p = p.to_str().unwrap();
    let dev = run_windowed(
        "compensate",
        "3",
        &["--machine", "abb-irb1600", "-o", "/dev/null", p],
    );
    assert_eq!(dev.0, 0, "{}", dev.2);
    assert!(dev.2.contains("at a time"), "{}", dev.2);
    let dir = tempfile::tempdir().expect("tempdir");
    let missing = dir.path().join("nodir/out.mod");
    let m = missing.to_str().unwrap();
    let whole = run(&["compensate", "--machine", "abb-irb1600", "-o", m, p]);
    let mut args = vec!["compensate", "--rapid-window-lines", "3"];
    args.extend(["--machine", "abb-irb1600", "-o", m, p]);
    let windows = run(&args);
    assert_ne!(whole.0, 0);
    assert_eq!((windows.0, &windows.2), (whole.0, &whole.2));
    let report = dir.path().join("nodir/r.csv");
    let out = dir.path().join("o.mod");
    let mut got = Vec::new();
    for window in [&[][..], &["--rapid-window-lines", "3"][..]] {
        let mut args = vec!["compensate", "--machine", "abb-irb1600"];
        args.extend(window);
        args.extend([
            "--report",
            report.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
            p,
        ]);
        let r = run(&args);
        got.push((r.0, r.2, std::fs::read(&out).ok()));
        let _ = std::fs::remove_file(&out);
    }
    assert_ne!(got[0].0, 0);
    assert_eq!(got[0], got[1]);
}

/// Runs `postproc ARGS…` with `input` on standard input.
fn run_piped(args: &[&str], input: &[u8]) -> (i32, Vec<u8>, String) {
    let out = postproc()
        .args(args)
        .write_stdin(input.to_vec())
        .output()
        .expect("runs");
    (
        out.status.code().unwrap_or(-1),
        out.stdout,
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// A module on standard input is copied to a temporary file (from
/// 1 MB on; whatever its length with `--rapid-window-lines`) and read a
/// window at a time: the bytes, reports, messages and exit codes of the
/// module read whole from standard input.
#[test]
fn standard_input_is_read_a_window_at_a_time() {
    for (module, machine) in cases() {
        let (m, p) = (machine.to_str().unwrap(), module.to_str().unwrap());
        let src = std::fs::read(&module).expect("module");
        for sub in [
            vec![
                "compensate",
                "--machine",
                m,
                "--effects",
                "all",
                "-o",
                "-",
                "-",
            ],
            vec![
                "compensate",
                "--machine",
                m,
                "--thermal-start",
                "steady",
                "-o",
                "-",
                "-",
            ],
            vec!["report", "--machine", m, "--format", "csv", "-"],
            vec!["check", "--machine", m, "-"],
        ] {
            let whole = run_piped(&sub, &src);
            assert_eq!(whole.0, 0, "{p} {sub:?}: {}", whole.2);
            let mut args = vec!["-v", sub[0], "--rapid-window-lines", "3"];
            args.extend(&sub[1..]);
            let streamed = run_piped(&args, &src);
            assert!(
                streamed.2.contains("-: read a window of 3 lines at a time"),
                "{p} {sub:?}: {}",
                streamed.2
            );
            assert_eq!(
                (streamed.0, &streamed.1),
                (whole.0, &whole.1),
                "{p} {sub:?}"
            );
        }
    }
    // Errors: those of the module read whole, for every malformed module.
    let m = repo("machines/abb-irb1600.yaml");
    let m = m.to_str().unwrap();
    for e in std::fs::read_dir(repo("tests/bad/programs")).expect("corpus") {
        let p = e.expect("entry").path();
        if p.extension().is_none_or(|x| x != "mod") {
            continue;
        }
        let src = std::fs::read(&p).expect("module");
        let whole = run_piped(&["compensate", "--machine", m, "-o", "-", "-"], &src);
        let streamed = run_piped(
            &[
                "compensate",
                "--machine",
                m,
                "--rapid-window-lines",
                "2",
                "-o",
                "-",
                "-",
            ],
            &src,
        );
        assert_ne!(whole.0, 0, "{p:?}");
        assert_eq!(streamed, whole, "{p:?}");
    }
}

/// Modules of 1 MB and more are read a window at a time by default; with a
/// warm thermal start (a first pass over the module) only from 16 MB on.
/// The same module on standard input is copied to a temporary file and
/// taken the same way.
#[test]
fn windows_are_taken_from_one_megabyte_on_and_from_sixteen_with_a_warm_start() {
    let dir = tempfile::tempdir().expect("tempdir");
    let src = one_megabyte_module();
    let big = dir.path().join("big.mod");
    std::fs::write(&big, &src).expect("write");
    let b = big.to_str().unwrap();
    let out = dir.path().join("out.mod");
    let o = out.to_str().unwrap();
    let said = |err: &str| err.contains("read a window of 8192 lines at a time");
    let (code, _, err) = run(&["-v", "check", b]);
    assert!(code == 0 && said(&err), "{err}");
    let (code, _, err) = run(&["-v", "check", "--machine", "abb-irb1600", b]);
    assert!(code == 0 && said(&err), "{err}");
    let (code, _, err) = run(&["-v", "compensate", "--machine", "abb-irb1600", "-o", o, b]);
    assert!(code == 0 && said(&err), "{err}");
    let cold = std::fs::read(&out).expect("output");
    let piped = run_piped(
        &[
            "-v",
            "compensate",
            "--machine",
            "abb-irb1600",
            "-o",
            "-",
            "-",
        ],
        src.as_bytes(),
    );
    assert!(said(&piped.2), "{}", piped.2);
    assert_eq!((piped.0, &piped.1), (0, &cold));
    let steady = [
        "-v",
        "compensate",
        "--machine",
        "abb-irb1600",
        "--thermal-start",
        "steady",
        "-o",
        o,
        b,
    ];
    let (code, _, err) = run(&steady);
    assert!(code == 0 && !err.contains("at a time"), "{err}");
    // Without the thermal effect there is no first pass: windows again.
    let mut no_thermal = steady.to_vec();
    no_thermal.splice(4..4, ["--effects", "geometric"]);
    let (code, _, err) = run(&no_thermal);
    assert!(code == 0 && said(&err), "{err}");
}

/// A module read a window at a time fails as the whole module does: write
/// errors name standard output as the whole-module run does (`stdout`,
/// `report`), never `-`; a check against a machine that cannot be loaded reports the
/// module's syntax error first (the module is parsed first);
/// `--rapid-window-lines 0` on standard input is refused before it is read.
#[test]
fn errors_of_windows_read_as_the_whole_module_s() {
    let dir = tempfile::tempdir().expect("tempdir");
    let src = std::fs::read_to_string(repo("samples/drilling.mod")).expect("module");
    let good = dir.path().join("good.mod");
    std::fs::write(&good, &src).expect("write");
    let bad = dir.path().join("bad.mod");
    std::fs::write(&bad, src.replace("ENDMODULE", "")).expect("write");
    let (g, b) = (good.to_str().unwrap(), bad.to_str().unwrap());
    let full = std::path::Path::new("/dev/full");
    for args in [
        vec!["compensate", "--machine", "abb-irb1600", "-o", "-", g],
        vec!["report", "--machine", "abb-irb1600", g],
    ] {
        if !full.exists() {
            break;
        }
        let mut windowed = args.clone();
        windowed.splice(1..1, ["--rapid-window-lines", "2"]);
        let outputs: Vec<(Option<i32>, String)> = [args, windowed]
            .iter()
            .map(|a| {
                let out = std::process::Command::new(assert_cmd::cargo::cargo_bin("postproc"))
                    .args(a)
                    .stdout(std::fs::File::create(full).expect("/dev/full"))
                    .output()
                    .expect("runs");
                (
                    out.status.code(),
                    String::from_utf8_lossy(&out.stderr).into_owned(),
                )
            })
            .collect();
        assert_eq!(outputs[0], outputs[1]);
        assert_eq!(outputs[0].0, Some(2));
        assert!(!outputs[0].1.contains(" -:"), "{}", outputs[0].1);
    }
    for machine in ["nosuch", "afm-r1000", "abb-irb1600"] {
        for p in [g, b] {
            let whole = run(&["check", "--machine", machine, p]);
            let windowed = run(&[
                "check",
                "--machine",
                machine,
                "--rapid-window-lines",
                "2",
                p,
            ]);
            assert_eq!(windowed, whole, "{machine} {p}");
        }
    }
    let whole_bad = run(&["check", "--machine", "nosuch", b]);
    assert!(whole_bad.2.contains("without ENDMODULE"), "{}", whole_bad.2);
    let zero = run_piped(
        &[
            "compensate",
            "--machine",
            "abb-irb1600",
            "--rapid-window-lines",
            "0",
            "-o",
            "-",
            "-",
        ],
        src.as_bytes(),
    );
    assert_eq!(zero.0, 2);
    assert!(
        zero.2.contains("--rapid-window-lines must be at least 1"),
        "{}",
        zero.2
    );
}

/// Standard input with a warm thermal start is held in memory below 16 MB
/// (windows only from there on), not copied to a temporary file to be read
/// back whole; and standard input is held in memory when no temporary file
/// can be made.
#[test]
fn standard_input_is_copied_only_when_windows_will_read_it() {
    let src = one_megabyte_module();
    let args = |start: &'static str| {
        vec![
            "-v",
            "compensate",
            "--machine",
            "abb-irb1600",
            "--thermal-start",
            start,
            "-o",
            "-",
            "-",
        ]
    };
    let cold = run_piped(&args("cold"), src.as_bytes());
    assert!(
        cold.2.contains("-: read a window of 8192 lines"),
        "{}",
        cold.2
    );
    let steady = run_piped(&args("steady"), src.as_bytes());
    assert_eq!(steady.0, 0, "{}", steady.2);
    assert!(!steady.2.contains("at a time"), "{}", steady.2);
    // No temporary folder: held in memory, the same bytes.
    let out = postproc()
        .args(args("cold"))
        .env("TMPDIR", "/nonexistent/postproc-test")
        .write_stdin(src.clone().into_bytes())
        .output()
        .expect("runs");
    assert_eq!(out.status.code(), Some(0));
    assert_eq!(out.stdout, cold.1);
}

/// A module of one routine of one-line moves, just over 1 MB (the default
/// size from which modules are read a window at a time).
fn one_megabyte_module() -> String {
    let mut src = String::from("MODULE Big\n  PROC main()\n");
    let mut k = 0;
    while src.len() < (1 << 20) {
        src.push_str(&format!(
            "    MoveL [[{},{},400],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]],v200,z1,tool0;\n",
            700 + k % 50,
            k % 40
        ));
        k += 1;
    }
    src.push_str("  ENDPROC\nENDMODULE\n");
    src
}

/// A module in the shape controller backups have: a `%%%` header, a
/// record type and a constant-sized array among the declarations, a
/// compact `IF` with its move on the next line and an error handler with a
/// list of error numbers. Read a window at a time it gives the bytes and
/// messages of the module read whole; with an editor placeholder in a
/// routine it is read whole (the routine is left as written as a whole).
#[test]
fn real_module_constructs_read_a_window_at_a_time() {
    let dir = tempfile::tempdir().expect("tempdir");
    let head = "%%%\r\n  VERSION:1\r\n  LANGUAGE:ENGLISH\r\n%%%\r\n\r\nMODULE Cell\r\n  CONST num N := 2;\r\n  RECORD partdata\r\n    robtarget pPick;\r\n    num nHeight;\r\n  ENDRECORD\r\n  CONST robtarget p1 := [[750,0,500],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\r\n  CONST robtarget p2 := [[760,20,480],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\r\n  CONST robtarget row{N} := [[[700,30,450],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]],\r\n    [[700,80,450],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]]];\r\n";
    let main = "  PROC main()\r\n    MoveJ p1, v1000, z50, tool0;\r\n    IF bSkip\r\n      MoveL p2, v100, fine, tool0;\r\n    MoveL row{1}, v100, z10, tool0;\r\n    MoveL row{2}, v100, fine, tool0;\r\n  ERROR (ERR_PATH_STOP,\r\n      ERR_COLL_STOP)\r\n    RETRY;\r\n  ENDPROC\r\n";
    let teach = "  PROC teach()\r\n    MoveL p1, v100, fine, tool0;\r\n    <SMT>\r\n  ENDPROC\r\n";
    let plain = format!("{head}{main}ENDMODULE\r\n");
    let unfinished = format!("{head}{main}{teach}ENDMODULE\r\n");
    for (k, (src, windows)) in [(&plain, true), (&unfinished, false)].iter().enumerate() {
        let path = dir.path().join(format!("cell{k}.mod"));
        std::fs::write(&path, src).expect("write");
        let p = path.to_str().unwrap();
        let whole_out = dir.path().join(format!("whole{k}.mod"));
        let (code, _, err) = run(&[
            "compensate",
            "--machine",
            "abb-irb1600",
            "-o",
            whole_out.to_str().unwrap(),
            p,
        ]);
        assert_eq!(code, 0, "{err}");
        let want = std::fs::read(&whole_out).expect("output");
        for lines in ["1", "2", "5"] {
            let out = dir.path().join(format!("w{k}_{lines}.mod"));
            let args = ["--machine", "abb-irb1600", "-o", out.to_str().unwrap(), p];
            let (code, _, err) = run_windowed("compensate", lines, &args);
            assert_eq!(code, 0, "{err}");
            assert_eq!(err.contains("at a time"), *windows, "{err}");
            if !windows {
                assert!(err.contains("editor placeholder"), "{err}");
            }
            assert_eq!(std::fs::read(&out).expect("output"), want, "case {k}");
            let check = run_windowed("check", lines, &["--machine", "abb-irb1600", p]);
            assert_eq!(check.0, 0, "{}", check.2);
            // The move in the compact IF is a move; the one of the
            // unfinished routine is not counted.
            assert!(
                String::from_utf8_lossy(&check.1).contains("4 moves"),
                "{}",
                String::from_utf8_lossy(&check.1)
            );
        }
        // The unfinished routine is written as it was read.
        let text = String::from_utf8(want).expect("utf-8");
        assert_eq!(text.contains(teach), !*windows);
        assert!(!text.contains(main), "main is compensated");
    }
}

/// A move that is the statement of a compact `IF` (on the IF's line or the
/// next) is compensated like any other: its target's line changes, every
/// other byte is the input's (the IF lines, the target no move goes to),
/// and windows of any size give the bytes of the module read whole.
#[test]
fn moves_in_compact_ifs_are_compensated() {
    let dir = tempfile::tempdir().expect("tempdir");
    let rt = |xyz: &str| format!("[[{xyz}],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]]");
    let src = format!(
        "MODULE Gate\n  CONST robtarget p1 := {};\n  CONST robtarget p2 := {};\n  CONST robtarget p3 := {};\n  CONST robtarget p4 := {};\n  VAR bool bGo := TRUE;\n  PROC main()\n    MoveJ p1, v1000, z50, tool0;\n    IF bGo MoveL p2, v100, z10, tool0;\n    IF bGo AND (nCount > 2) ! counted first\n      MoveL p3, v100, fine, tool0;\n    IF msg = \"a;b\" TPWrite \"p4\";\n  ENDPROC\nENDMODULE\n",
        rt("750,0,500"),
        rt("760,20,480"),
        rt("770,10,490"),
        rt("700,0,450"),
    );
    let path = dir.path().join("gate.mod");
    std::fs::write(&path, &src).expect("write");
    let p = path.to_str().unwrap();
    let compensate = |out: &str, extra: &[&str]| -> Vec<u8> {
        let out = dir.path().join(out);
        let mut args = vec!["compensate", "--machine", "abb-irb1600", "-o"];
        args.push(out.to_str().unwrap());
        args.extend(extra);
        args.push(p);
        let (code, _, err) = run(&args);
        assert_eq!(code, 0, "{err}");
        let text = std::fs::read(&out).expect("output");
        crate::common::without_header(&text)
    };
    let same = compensate("none.mod", &["--effects", "none", "--annotate", "none"]);
    assert!(same == src.as_bytes(), "{}", String::from_utf8_lossy(&same));
    let want = compensate("whole.mod", &["--annotate", "none"]);
    let text = String::from_utf8(want.clone()).expect("utf-8");
    let changed: Vec<usize> = src
        .lines()
        .zip(text.lines())
        .enumerate()
        .filter(|(_, (a, b))| a != b)
        .map(|(k, _)| k + 1)
        .collect();
    // The targets of the three moves; not p4, not the IF lines.
    assert_eq!(changed, vec![2, 3, 4], "{text}");
    assert_eq!(src.lines().count(), text.lines().count());
    for lines in ["1", "2", "5"] {
        let out = dir.path().join(format!("w{lines}.mod"));
        let args = ["--machine", "abb-irb1600", "--annotate", "none", "-o"];
        let mut args = args.to_vec();
        args.extend([out.to_str().unwrap(), p]);
        let (code, _, err) = run_windowed("compensate", lines, &args);
        assert_eq!(code, 0, "{err}");
        assert!(err.contains("at a time"), "{err}");
        let got = crate::common::without_header(&std::fs::read(&out).expect("output"));
        assert!(got == want, "windows of {lines} lines");
    }
}

#[test]
fn streamed_process_motion_instructions_give_the_bytes_of_the_whole_module() {
    let dir = tempfile::tempdir().expect("tempdir");
    let src = "MODULE Process\n  PERS tooldata tDrill := [TRUE,[[0,0,182.5],[1,0,0,0]],[2.4,[0,0,85],[1,0,0,0],0.012,0.012,0.004]];\n  PERS wobjdata wPlate := [FALSE,TRUE,\"\",[[600,-200,350],[1,0,0,0]],[[0,0,0],[1,0,0,0]]];\n  CONST robtarget pA := [[100,50,40],[0,0,1,0],[-1,0,-1,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\n  CONST robtarget pD := [[250,150,0],[0,0,1,0],[-1,0,-1,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\n  VAR robtarget pFound := [[250,150,20],[0,0,1,0],[-1,0,-1,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\n  PROC main()\n    MoveLDO pA, v100, z1, tDrill\\WObj:=wPlate, doOn, 1;\n    TriggL [[175,50,40],[0,0,1,0],[-1,0,-1,0],[9E9,9E9,9E9,9E9,9E9,9E9]], v100, trOn, z1, tDrill\\WObj:=wPlate;\n    ArcL Offs(pA,75,100,0), v100, seam1, weld1\\Weave:=weave1, z1, tDrill\\WObj:=wPlate;\n    SearchL \\Stop, diTouch, pFound, pD, v20, tDrill\\WObj:=wPlate;\n  ENDPROC\nENDMODULE\n";
    let input = dir.path().join("process.mod");
    std::fs::write(&input, src).expect("write");
    let m = repo("machines/abb-irb1600.yaml");
    let (m, p) = (m.to_str().unwrap(), input.to_str().unwrap());
    let whole = dir.path().join("whole.mod");
    let (code, _, err) = run(&[
        "compensate",
        "--machine",
        m,
        "-o",
        whole.to_str().unwrap(),
        p,
    ]);
    assert_eq!(code, 0, "{err}");
    let want = std::fs::read(&whole).expect("output");
    assert_ne!(want, src.as_bytes());
    for lines in ["1", "2", "5"] {
        let streamed = dir.path().join(format!("s{lines}.mod"));
        let out = streamed.to_str().unwrap();
        let (code, _, err) = run_windowed("compensate", lines, &["--machine", m, "-o", out, p]);
        assert_eq!(code, 0, "{err}");
        assert!(
            err.contains(&format!("read a window of {lines} lines at a time")),
            "{err}"
        );
        assert_eq!(
            std::fs::read(&streamed).expect("output"),
            want,
            "{lines} lines"
        );
    }
}

/// A statement that looks like a motion instruction to a declared
/// robtarget but is not in the table (`PaintL`) is left as written, named
/// with its line and counted, whether the module is read whole or a window
/// at a time.
#[test]
fn unknown_motion_instructions_are_named_and_counted() {
    let dir = tempfile::tempdir().expect("tempdir");
    let src = "MODULE Paint\n  CONST robtarget p10 := [[750,0,500],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\n  CONST robtarget p20 := [[700,50,450],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\n  PROC main()\n    MoveJ p20, v1000, z50, tool0;\n    PaintL p10, v800, z10, tool0;\n  ENDPROC\nENDMODULE\n";
    let input = dir.path().join("paint.mod");
    std::fs::write(&input, src).expect("write");
    let m = repo("machines/abb-irb1600.yaml");
    let (m, p) = (m.to_str().unwrap(), input.to_str().unwrap());
    let named = "paint.mod:6: PaintL left as written: not a motion instruction postproc knows";
    let counted = "1 move compensated, 1 left as written (not a motion instruction postproc knows";
    let whole = dir.path().join("whole.mod");
    let (code, _, err) = run(&[
        "compensate",
        "--machine",
        m,
        "-o",
        whole.to_str().unwrap(),
        p,
    ]);
    assert_eq!(code, 0, "{err}");
    assert!(err.contains(named) && err.contains(counted), "{err}");
    let out = std::fs::read_to_string(&whole).expect("output");
    assert!(out.contains("    PaintL p10, v800, z10, tool0;\n"), "{out}");
    assert!(
        out.contains(&src.lines().nth(1).expect("p10").to_string()),
        "{out}"
    );
    for lines in ["1", "2"] {
        let streamed = dir.path().join(format!("s{lines}.mod"));
        let out = streamed.to_str().unwrap();
        let (code, _, err) = run_windowed("compensate", lines, &["--machine", m, "-o", out, p]);
        assert_eq!(code, 0, "{err}");
        assert!(
            err.contains(named) && err.contains(counted),
            "{lines}: {err}"
        );
        assert_eq!(
            std::fs::read(&streamed).expect("output"),
            std::fs::read(&whole).expect("output"),
            "{lines} lines"
        );
    }
}

/// Moves left as written give the same bytes, summary and warnings read a
/// window at a time as read whole: read so when they read no declared
/// target (a `CRobT` offset, a routine parameter), read whole when a
/// routine assigns module data that moves read (the socket cell).
#[test]
fn moves_left_as_written_give_the_bytes_of_the_whole_module() {
    let dir = tempfile::tempdir().expect("tempdir");
    let windowed_src = "MODULE Cell\n  CONST robtarget p10 := [[700,-200,300],[0,0,1,0],[-1,0,-1,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\n  CONST robtarget p20 := [[700,200,300],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\n  PROC main()\n    MoveJ p10, v1000, z50, tool0;\n    MoveL Offs(CRobT(), 0, 0, 50), v100, fine, tool0;\n    MoveL p20, v200, fine, tool0;\n    place p20;\n  ENDPROC\n  PROC place(robtarget pt)\n    MoveL Offs(pt, 0, 0, 50), v500, z10, tool0;\n    MoveL pt, v100, fine, tool0;\n    MoveL p20, v100, fine, tool0;\n  ENDPROC\nENDMODULE\n";
    let m = repo("machines/abb-irb1600.yaml");
    let m = m.to_str().unwrap();
    // A declared target handed to a procedure that moves to its parameter
    // keeps its value: read whole unless the move to it and the call share
    // a window.
    let shared_src = windowed_src.replace(
        "    MoveL Offs(CRobT(), 0, 0, 50), v100, fine, tool0;\n",
        "",
    );
    let windowed_src = &windowed_src.replace("place p20;", "place CRobT();");
    let cases = [
        (windowed_src.as_str(), Some(true)),
        (crate::rapid_cli::PICK_CELL, Some(false)),
        (shared_src.as_str(), None),
    ];
    for (k, (src, windowed)) in cases.into_iter().enumerate() {
        let input = dir.path().join(format!("cell{k}.mod"));
        std::fs::write(&input, src).expect("write");
        let p = input.to_str().unwrap();
        let whole = dir.path().join(format!("whole{k}.mod"));
        let (code, _, err) = run(&[
            "compensate",
            "--machine",
            m,
            "-o",
            whole.to_str().unwrap(),
            p,
        ]);
        assert_eq!(code, 0, "{err}");
        let want = std::fs::read(&whole).expect("output");
        let summary = |err: &str| {
            err.lines()
                .find(|l| l.contains("left as written ("))
                .map(|l| l.split(": ").nth(1).unwrap_or("").to_string())
                .unwrap_or_default()
        };
        let left = |err: &str| -> Vec<String> {
            err.lines()
                .filter(|l| l.contains(": MoveL left as written ("))
                .map(str::to_string)
                .collect()
        };
        assert!(!left(&err).is_empty(), "{err}");
        for lines in ["1", "2", "5"] {
            let out = dir.path().join(format!("w{k}_{lines}.mod"));
            let args = ["--machine", m, "-o", out.to_str().unwrap(), p];
            let (code, _, werr) = run_windowed("compensate", lines, &args);
            assert_eq!(code, 0, "{werr}");
            let said = format!("read a window of {lines} lines at a time");
            if let Some(windowed) = windowed {
                assert_eq!(werr.contains(&said), windowed, "{werr}");
            }
            assert_eq!(std::fs::read(&out).expect("output"), want, "{lines} lines");
            assert_eq!(summary(&werr), summary(&err));
            assert_eq!(left(&werr), left(&err));
        }
    }
}

/// Issue 43: a window that continues a routine carries its configuration
/// monitoring. With `ConfJ \Off` / `ConfL \Off` in force from the first
/// lines of the routine, windows of every size give the bytes of the
/// module read whole (before, a window after the switch solved its moves
/// by their confdata and the run refused them or wrote other targets).
#[test]
fn windows_carry_configuration_monitoring_off() {
    let dir = tempfile::tempdir().expect("tempdir");
    for (name, text) in crate::conf_off::robots() {
        let machine = dir.path().join(format!("{name}.yaml"));
        std::fs::write(&machine, &text).expect("write");
        let robot = crate::conf_off::with_spindle(
            postproc::machine::robot::Robot::from_yaml_str(&text, name).expect("valid"),
        );
        let (src, _) = crate::conf_off::module(&robot, true);
        let input = dir.path().join(format!("{name}.mod"));
        std::fs::write(&input, &src).expect("write");
        let (m, p) = (machine.to_str().unwrap(), input.to_str().unwrap());
        let rest = [
            "--machine",
            m,
            "--effects",
            "kinematic,gravity",
            p,
            "-o",
            "-",
        ];
        let mut whole_args = vec!["compensate"];
        whole_args.extend(rest);
        let (code, whole, err) = run(&whole_args);
        assert_eq!(code, 0, "{name} whole: {err}");
        for lines in ["1", "2", "3", "5"] {
            let (code, windowed, err) = run_windowed("compensate", lines, &rest);
            assert_eq!(code, 0, "{name}, windows of {lines} lines: {err}");
            assert!(
                err.contains("read a window of"),
                "{name}, {lines}: read a window at a time: {err}"
            );
            assert_eq!(
                String::from_utf8_lossy(&windowed),
                String::from_utf8_lossy(&whole),
                "{name}, windows of {lines} lines"
            );
        }
    }
}

/// Issue 43: a module of over a megabyte (read a window of 8 192 lines at
/// a time by default) with `ConfJ \Off` / `ConfL \Off` at the top of its
/// routine solves the moves after line 8 192 in the configuration of the
/// moves before them, as one window over the whole routine does.
#[test]
fn a_big_module_keeps_configuration_monitoring_off_past_its_first_window() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (name, text) = crate::conf_off::robots()
        .into_iter()
        .next()
        .expect("a robot");
    let machine = dir.path().join(format!("{name}.yaml"));
    std::fs::write(&machine, &text).expect("write");
    let robot = crate::conf_off::with_spindle(
        postproc::machine::robot::Robot::from_yaml_str(&text, name).expect("valid"),
    );
    let (small, _) = crate::conf_off::module(&robot, true);
    // The small module's declarations and switches, then moves between its
    // two targets of wrong confdata, each after a long comment line, to
    // over a megabyte and past line 8 192.
    let head = &small[..small.find("    MoveJ pA").expect("MoveJ")];
    let mut src = String::from(head);
    let comment = format!("    ! {}\n", "-".repeat(200));
    let mut k = 0;
    while src.len() < (1 << 20) + 4096 {
        src.push_str(&comment);
        src.push_str(if k % 2 == 0 {
            "    MoveL pB, v100, z1, tSpindle;\n"
        } else {
            "    MoveL pA, v100, z1, tSpindle;\n"
        });
        k += 1;
    }
    src.push_str("  ENDPROC\nENDMODULE\n");
    assert!(src.lines().count() > 8192 + 100);
    let input = dir.path().join("big.mod");
    std::fs::write(&input, &src).expect("write");
    let (m, p) = (machine.to_str().unwrap(), input.to_str().unwrap());
    let rest = [
        "--machine",
        m,
        "--effects",
        "kinematic,gravity",
        p,
        "-o",
        "-",
    ];
    let mut default_args = vec!["-v", "compensate"];
    default_args.extend(rest);
    let (code, by_default, err) = run(&default_args);
    assert_eq!(code, 0, "read a window at a time by default: {err}");
    assert!(err.contains("read a window of 8192 lines"), "{err}");
    let (code, one_window, err) = run_windowed("compensate", "1000000", &rest);
    assert_eq!(code, 0, "one window: {err}");
    assert!(
        by_default == one_window,
        "the windows of 8192 lines give other bytes than one window"
    );
}
