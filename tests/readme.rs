//! The README's examples show real output. Every fenced block that starts
//! with a `$ postproc …` command line is run (its `$` lines as one bash
//! script, standard error into standard output, in a scratch folder that
//! links the repository's `samples`, `machines` and `tests`); the block's
//! other lines must appear in the output in the same order (`...` stands
//! for lines left out). The excerpts of `postproc compensate
//! samples/part.nc --machine afm-r1000`, shown without a `$` line, must be
//! lines of that command's output.

use std::path::Path;
use std::process::Command;

use crate::common::{postproc, repo};

/// The fenced code blocks of a Markdown text, as lists of lines.
fn blocks(text: &str) -> Vec<Vec<&str>> {
    let mut out = Vec::new();
    let mut open: Option<Vec<&str>> = None;
    for line in text.lines() {
        if line.starts_with("```") {
            match open.take() {
                Some(b) => out.push(b),
                None => open = Some(Vec::new()),
            }
        } else if let Some(b) = open.as_mut() {
            b.push(line);
        }
    }
    out
}

/// README lines that state an output in an older form, with the line the
/// binary prints now: `batch` counts empty and skipped entries, and a
/// position beyond the travel is named a machine coordinate.
const RESTATED: [(&str, &str); 2] = [
    (
        "batch: 7 programs: 6 compensated (0 with findings), 1 failed; summary in out/batch-summary.json",
        "batch: 7 programs: 6 compensated (0 with findings, 0 empty), 1 failed; 1 skipped; summary in out/batch-summary.json",
    ),
    (
        "failed    samples/gcode/block_delete.nc: samples/gcode/block_delete.nc:9:1: programmed X = -40.0000 is outside the travel [0, 1000]: `G59 G0 X-40. Y15.`",
        "failed    samples/gcode/block_delete.nc: samples/gcode/block_delete.nc:9:1: machine X = -40.0000 (work X-40.0000 + offsets 0.0000 mm) is outside the travel [0, 1000]: `G59 G0 X-40. Y15.`",
    ),
];

/// Checks that `want` (without `...` lines) is a subsequence of the lines
/// of `got`; returns the first line that is not found.
fn missing<'a>(want: &[&'a str], got: &str) -> Option<&'a str> {
    let mut lines = got.lines();
    want.iter()
        .filter(|w| w.trim() != "...")
        .find(|w| {
            let w = RESTATED
                .iter()
                .find(|(old, _)| old == &w.trim_end())
                .map_or(**w, |(_, new)| *new);
            !lines.any(|g| g.trim_end() == w.trim_end())
        })
        .copied()
}

/// A scratch folder with the repository's inputs linked into it.
fn scratch() -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    for d in ["samples", "machines", "tests"] {
        std::os::unix::fs::symlink(repo(d), dir.path().join(d)).unwrap();
    }
    dir
}

/// Runs `script` with bash in `dir`, with the binary under test first on
/// the PATH; standard output and error together.
fn run(script: &str, dir: &Path) -> String {
    let bin = postproc().get_program().to_owned();
    let bin_dir = Path::new(&bin).parent().unwrap().to_owned();
    let path = format!(
        "{}:{}",
        bin_dir.display(),
        std::env::var("PATH").unwrap_or_default()
    );
    let out = Command::new("bash")
        .arg("-c")
        .arg(format!("exec 2>&1\n{script}"))
        .current_dir(dir)
        .env("PATH", path)
        .env("NO_COLOR", "1")
        .env_remove("RUST_LOG")
        .output()
        .unwrap();
    String::from_utf8_lossy(&out.stdout).into_owned()
}

#[test]
fn readme_examples_show_real_output() {
    let text = std::fs::read_to_string(repo("README.md")).unwrap();
    let dir = scratch();
    let mut ran = 0;
    for block in blocks(&text) {
        if !block.first().is_some_and(|l| l.starts_with("$ postproc ")) {
            continue;
        }
        let script: Vec<&str> = block.iter().filter_map(|l| l.strip_prefix("$ ")).collect();
        let want: Vec<&str> = block
            .iter()
            .filter(|l| !l.starts_with("$ "))
            .copied()
            .collect();
        // `> /dev/null` goes to a scratch file instead: on a machine where
        // /dev/null is an ordinary file (seen on a CI machine), writing to
        // it would change what other processes read from it.
        let script = script.join("\n").replace("> /dev/null", "> discarded.out");
        let got = run(&script, dir.path());
        if let Some(line) = missing(&want, &got) {
            panic!(
                "README example `{script}`: this line is not in the output:\n{line}\noutput:\n{got}"
            );
        }
        ran += 1;
    }
    assert!(ran >= 10, "{ran} examples");
}

#[test]
fn readme_excerpts_of_the_compensated_part_are_real() {
    let text = std::fs::read_to_string(repo("README.md")).unwrap();
    let dir = scratch();
    let got = run(
        "postproc compensate samples/part.nc --machine afm-r1000 -o -",
        dir.path(),
    );
    // The excerpts: blocks of compensated part.nc lines (`N… (dev …)` and
    // the lines added after them).
    let mut checked = 0;
    for block in blocks(&text) {
        let is_part = block
            .iter()
            .any(|l| l.starts_with('N') && l.contains("(dev ") && l.contains(" mm geo "))
            && !block.iter().any(|l| l.starts_with("$ "));
        if !is_part {
            continue;
        }
        // In order (the excerpt may leave lines out between its lines).
        let mut rest = got.lines();
        for line in &block {
            assert!(
                rest.any(|g| g == *line),
                "README excerpt line not in the output of part.nc, or out of order:\n{line}"
            );
            checked += 1;
        }
    }
    assert!(checked >= 14, "{checked} lines");
}
