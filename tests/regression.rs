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
