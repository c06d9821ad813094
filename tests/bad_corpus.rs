//! Integration tests: the corpus of malformed inputs in `tests/bad/`.
//!
//! Every file there has a sibling `<file>.expect` whose lines must all
//! appear in the error message. Programs and machine files go through the
//! real binary (exit status 2, no panic, no output file left behind);
//! observation files through the library reader (the commands that read
//! them share it).

use std::path::{Path, PathBuf};

use crate::common::{postproc, repo};
use postproc::calibrate::observations::load_observations;

/// Every corpus file of one kind with its expected message lines.
fn corpus(kind: &str) -> Vec<(PathBuf, Vec<String>)> {
    let dir = repo(&format!("tests/bad/{kind}"));
    let mut out = Vec::new();
    for entry in std::fs::read_dir(&dir).expect("corpus folder") {
        let path = entry.expect("corpus entry").path();
        if path.extension().is_some_and(|e| e == "expect") {
            continue;
        }
        let expect_path = PathBuf::from(format!("{}.expect", path.display()));
        let expect = std::fs::read_to_string(&expect_path)
            .unwrap_or_else(|_| panic!("{} has no .expect file", path.display()));
        let lines = expect
            .lines()
            .map(str::trim)
            .filter(|l| !l.is_empty())
            .map(String::from)
            .collect::<Vec<_>>();
        assert!(!lines.is_empty(), "{} is empty", expect_path.display());
        out.push((path, lines));
    }
    out.sort();
    out
}

fn name(p: &Path) -> String {
    p.file_name().unwrap().to_string_lossy().into_owned()
}

fn assert_message(file: &Path, message: &str, expect: &[String]) {
    assert!(
        !message.contains("panicked"),
        "{}: panic: {message}",
        file.display()
    );
    for want in expect {
        assert!(
            message.contains(want.as_str()),
            "{}: expected `{want}` in:\n{message}",
            file.display()
        );
    }
}

#[test]
fn bad_programs_fail_cleanly() {
    let files = corpus("programs");
    assert!(files.len() >= 15, "corpus too small: {}", files.len());
    let dir = tempfile::tempdir().unwrap();
    for (file, expect) in files {
        let is_rapid = file.extension().is_some_and(|e| e == "mod");
        let machine = if is_rapid { "abb-irb1600" } else { "afm-r1000" };
        let out_path = dir.path().join(format!("out-{}", name(&file)));
        let out = postproc()
            .args(["compensate", "--machine", machine, "-o"])
            .arg(&out_path)
            .arg(&file)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{}: {stderr}", file.display());
        assert_message(&file, &stderr, &expect);
        // The message is located: `file:line:column: …`.
        assert!(
            stderr.contains(&format!("{}:", name(&file))),
            "{}: message does not name the file: {stderr}",
            file.display()
        );
        assert!(
            !out_path.exists(),
            "{}: a partial output file was left",
            file.display()
        );
    }
}

#[test]
fn bad_machine_files_fail_cleanly() {
    let files = corpus("machines");
    assert!(files.len() >= 10, "corpus too small: {}", files.len());
    for (file, expect) in files {
        let out = postproc()
            .args(["check", "--machine"])
            .arg(&file)
            .arg(repo("samples/part.nc"))
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{}: {stderr}", file.display());
        assert_message(&file, &stderr, &expect);
    }
}

#[test]
fn bad_observation_files_fail_cleanly() {
    let files = corpus("observations");
    assert!(files.len() >= 10, "corpus too small: {}", files.len());
    for (file, expect) in files {
        match load_observations(&file) {
            Ok(_) => panic!("{}: accepted", file.display()),
            Err(e) => {
                let msg = e.to_string();
                assert_message(&file, &msg, &expect);
                assert!(
                    msg.contains(&name(&file)),
                    "{}: message does not name the file: {msg}",
                    file.display()
                );
            }
        }
    }
}
