//! Integration tests: regressions — every bug fixed gets a test here (or
//! beside the feature it broke), named after what went wrong.

use crate::common::{postproc, repo};

/// `report -o PROGRAM` once replaced the program with its own report
/// (G-code and RAPID); it must be refused like `compensate -o PROGRAM`.
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

/// A failure to create the output named the random temporary file
/// (`.postproc-XXXXXX`); it must name the output path the user gave.
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

/// `simulate`, `calibrate` and `diagnose --write-model` once wrote over
/// their own input files when `-o` named one of them (and `diagnose` wrote
/// non-atomically); each must be refused with the inputs left as they were.
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
