//! Rough edges a newcomer meets in the first hour, each pinned: a closed
//! pipe ends a command quietly with exit 0, the release profile strips
//! debug information while a profiling profile keeps line tables.

use std::io::Read;
use std::process::{Command, Stdio};

use crate::common::{postproc, repo};

/// `postproc calibrate … | head -1`: the reader closes the pipe before the
/// report is written; the run ends with exit 0 and says nothing.
#[test]
fn a_closed_pipe_ends_the_run_quietly_with_exit_0() {
    let dir = tempfile::tempdir().expect("temp dir");
    let bin = postproc().get_program().to_owned();
    let mut child = Command::new(bin)
        .args(["calibrate", "stiffness", "--machine"])
        .arg(repo("machines/abb-irb1600.yaml"))
        .arg("--observations")
        .arg(repo("samples/observations/irb1600-ldbb-measured.csv"))
        .arg("-o")
        .arg(dir.path().join("c.yaml"))
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("runs");
    // Closed before the calibration (a fraction of a second) prints.
    drop(child.stdout.take());
    let mut err = String::new();
    child
        .stderr
        .take()
        .expect("stderr")
        .read_to_string(&mut err)
        .expect("stderr text");
    let status = child.wait().expect("exits");
    assert_eq!(status.code(), Some(0), "{err}");
    assert!(!err.contains("error"), "{err}");
    assert!(!err.contains("Broken pipe"), "{err}");
}

#[test]
fn release_builds_strip_debug_information_and_profiling_keeps_it() {
    let manifest: toml_like::Profiles = toml_like::profiles(
        &std::fs::read_to_string(repo("Cargo.toml")).expect("Cargo.toml"),
    );
    let release = manifest.get("release").expect("a release profile");
    assert_eq!(release.get("debug").map(String::as_str), Some("false"));
    assert_eq!(release.get("strip").map(String::as_str), Some("\"debuginfo\""));
    let profiling = manifest.get("profiling").expect("a profiling profile");
    assert_eq!(profiling.get("inherits").map(String::as_str), Some("\"release\""));
    assert_eq!(profiling.get("debug").map(String::as_str), Some("1"));
}

/// The `[profile.NAME]` tables of a Cargo manifest as key → raw value.
mod toml_like {
    use std::collections::BTreeMap;

    pub type Profiles = BTreeMap<String, BTreeMap<String, String>>;

    pub fn profiles(text: &str) -> Profiles {
        let mut out = Profiles::new();
        let mut current: Option<String> = None;
        for line in text.lines().map(str::trim) {
            if line.starts_with('[') {
                current = line
                    .strip_prefix("[profile.")
                    .and_then(|l| l.strip_suffix(']'))
                    .map(str::to_string);
                continue;
            }
            if let (Some(p), Some((k, v))) = (&current, line.split_once('=')) {
                if !line.starts_with('#') {
                    out.entry(p.clone())
                        .or_default()
                        .insert(k.trim().to_string(), v.trim().to_string());
                }
            }
        }
        out
    }
}
