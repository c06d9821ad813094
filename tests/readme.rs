//! The examples of README.md and of the command references in docs/ show
//! real output, and are run here.
//!
//! An example is a fenced block whose first line starts with `$ `. Each
//! `$ ` line is one command, run by bash in a scratch folder that holds
//! copies of the repository's `samples/`, `machines/`, `tests/bad/` and
//! the pictures of `docs/` (one folder per document, the examples run in
//! document order, so an example may read what an earlier one wrote). A
//! picture of `docs/` that an example writes must come out as committed. The lines after a command,
//! up to the next `$ ` line or the end of the block, are its output —
//! standard output and standard error together — compared exactly (blanks
//! at line ends and empty lines at the end aside). The binary under test
//! comes first on the PATH.
//!
//! Commands that start with `cargo` are shown, not run (installing, and the
//! test suite itself). Every fenced block of the README is an example: text
//! that only looks like output cannot drift from the program.
//!
//! When outputs change on purpose, refresh the shown outputs with
//!
//! ```text
//! UPDATE_README=1 cargo test --test integration readme
//! ```
//!
//! (which also writes the pictures of `docs/` the examples make) and read
//! the diff of the documents before committing it.

use std::path::{Path, PathBuf};
use std::process::Command;

use crate::common::{postproc, repo};

/// The documents whose examples are run: the README, then every
/// Markdown file of `docs/` in name order.
fn documents() -> Vec<String> {
    let mut docs: Vec<String> = std::fs::read_dir(repo("docs"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".md"))
        .map(|n| format!("docs/{n}"))
        .collect();
    docs.sort();
    docs.insert(0, "README.md".into());
    docs
}

/// The README stays a guide of a few hundred lines.
const README_MAX_LINES: usize = 400;

/// Whether the run rewrites the shown outputs instead of comparing them.
fn updating() -> bool {
    std::env::var_os("UPDATE_README").is_some_and(|v| v == "1")
}

/// Copies `from` into `to` recursively, leaving out compensated programs
/// (`*.comp.*`) that a run in the repository may have left behind.
fn copy_tree(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let entry = entry.unwrap();
        let name = entry.file_name();
        if name.to_string_lossy().contains(".comp.") {
            continue;
        }
        let kind = entry.file_type().unwrap();
        if kind.is_dir() {
            copy_tree(&entry.path(), &to.join(&name));
        } else if kind.is_file() {
            std::fs::copy(entry.path(), to.join(&name)).unwrap();
        }
    }
}

/// The files of `docs/` that are not Markdown (pictures the examples
/// make).
fn pictures() -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(repo("docs"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| !n.ends_with(".md"))
        .collect();
    v.sort();
    v
}

/// A scratch folder with copies of the inputs the examples use.
fn scratch() -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    for d in ["samples", "machines", "tests/bad"] {
        copy_tree(&repo(d), &dir.path().join(d));
    }
    std::fs::create_dir(dir.path().join("docs")).unwrap();
    for p in pictures() {
        let rel = format!("docs/{p}");
        std::fs::copy(repo(&rel), dir.path().join(&rel)).unwrap();
    }
    dir
}

/// The folder of the binary under test.
fn bin_dir() -> PathBuf {
    let bin = postproc().get_program().to_owned();
    Path::new(&bin).parent().unwrap().to_owned()
}

/// Runs one command line with bash in `dir`; standard output and error
/// together.
fn run(command: &str, dir: &Path) -> String {
    let path = format!(
        "{}:{}",
        bin_dir().display(),
        std::env::var("PATH").unwrap_or_default()
    );
    // `> /dev/null` goes to a scratch file instead: on a machine where
    // /dev/null is an ordinary file (seen on a CI machine), writing to it
    // would change what other processes read from it.
    let command = command.replace("> /dev/null", "> discarded.out");
    let out = Command::new("bash")
        .arg("-c")
        .arg(format!("exec 2>&1\n{command}"))
        .current_dir(dir)
        .env("PATH", path)
        .env("NO_COLOR", "1")
        .env_remove("RUST_LOG")
        .output()
        .unwrap();
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// Output lines as compared: blanks at line ends and empty lines at the
/// end dropped.
fn normalised<'a>(lines: impl Iterator<Item = &'a str>) -> Vec<&'a str> {
    let mut v: Vec<&str> = lines.map(str::trim_end).collect();
    while v.last().is_some_and(|l| l.is_empty()) {
        v.pop();
    }
    v
}

/// What running the examples of one document gave.
struct Outcome {
    /// The document with every shown output replaced by the real one.
    refreshed: String,
    /// Commands whose shown output differs: command, shown, real.
    differences: Vec<(String, String, String)>,
    /// Commands run.
    ran: usize,
    /// Fenced blocks that are not examples (first line of each).
    other_blocks: Vec<String>,
    /// `cargo` commands shown.
    cargo: Vec<String>,
    /// Pictures of `docs/` the examples wrote differently: name, bytes.
    pictures: Vec<(String, Vec<u8>)>,
}

/// Runs every example of `text` in a fresh scratch folder.
fn run_document(text: &str) -> Outcome {
    let dir = scratch();
    let lines: Vec<&str> = text.lines().collect();
    let mut out = Outcome {
        refreshed: String::with_capacity(text.len()),
        differences: Vec::new(),
        ran: 0,
        other_blocks: Vec::new(),
        cargo: Vec::new(),
        pictures: Vec::new(),
    };
    let mut i = 0;
    while i < lines.len() {
        let line = lines[i];
        out.refreshed.push_str(line);
        out.refreshed.push('\n');
        i += 1;
        if !line.starts_with("```") {
            continue;
        }
        // A fenced block: lines[i..end] is its body, lines[end] the fence.
        let end = (i..lines.len())
            .find(|&j| lines[j].starts_with("```"))
            .unwrap_or(lines.len());
        let body = &lines[i..end];
        if !body.first().is_some_and(|l| l.starts_with("$ ")) {
            out.other_blocks
                .push(body.first().copied().unwrap_or("(empty block)").to_owned());
            for l in body {
                out.refreshed.push_str(l);
                out.refreshed.push('\n');
            }
        } else {
            run_block(body, dir.path(), &mut out);
        }
        // The closing fence.
        if let Some(fence) = lines.get(end) {
            out.refreshed.push_str(fence);
            out.refreshed.push('\n');
        }
        i = end + 1;
    }
    if !text.ends_with('\n') {
        out.refreshed.pop();
    }
    for p in pictures() {
        let rel = format!("docs/{p}");
        let made = std::fs::read(dir.path().join(&rel)).unwrap();
        if made != std::fs::read(repo(&rel)).unwrap() {
            out.pictures.push((rel, made));
        }
    }
    out
}

/// Runs the commands of one example block, comparing and refreshing their
/// outputs.
fn run_block(body: &[&str], dir: &Path, out: &mut Outcome) {
    let mut k = 0;
    while k < body.len() {
        let command = body[k].strip_prefix("$ ").expect("a command line");
        let shown_end = (k + 1..body.len())
            .find(|&j| body[j].starts_with("$ "))
            .unwrap_or(body.len());
        let shown = &body[k + 1..shown_end];
        out.refreshed.push_str(body[k]);
        out.refreshed.push('\n');
        if command.starts_with("cargo ") {
            out.cargo.push(command.to_owned());
            for l in shown {
                out.refreshed.push_str(l);
                out.refreshed.push('\n');
            }
        } else {
            let got = run(command, dir);
            let got = normalised(got.lines());
            if got != normalised(shown.iter().copied()) {
                out.differences
                    .push((command.to_owned(), shown.join("\n"), got.join("\n")));
            }
            for l in &got {
                out.refreshed.push_str(l);
                out.refreshed.push('\n');
            }
            out.ran += 1;
        }
        k = shown_end;
    }
}

/// Runs the examples of one document; in update mode writes the real
/// outputs into it, else fails on the first difference.
fn check_document(rel: &str) -> Outcome {
    let path = repo(rel);
    let text = std::fs::read_to_string(&path).unwrap();
    let outcome = run_document(&text);
    if updating() {
        if outcome.refreshed != text {
            std::fs::write(&path, &outcome.refreshed).unwrap();
        }
        for (rel, bytes) in &outcome.pictures {
            std::fs::write(repo(rel), bytes).unwrap();
        }
    } else if let Some((command, shown, got)) = outcome.differences.first() {
        panic!(
            "{rel}: the example `{command}` shows an output that is not the real one \
             ({} of its examples differ; UPDATE_README=1 refreshes them).\n\
             shown:\n{shown}\nreal:\n{got}",
            outcome.differences.len()
        );
    } else if let Some((picture, _)) = outcome.pictures.first() {
        panic!(
            "{rel}: its examples make another {picture} than the committed one \
             (UPDATE_README=1 writes it)"
        );
    }
    outcome
}

#[test]
fn readme_examples_show_real_output() {
    let outcome = check_document("README.md");
    assert!(outcome.ran >= 10, "{} README examples", outcome.ran);
    assert!(
        outcome.other_blocks.is_empty(),
        "README blocks that are not examples (every block starts with a `$ ` command): {:?}",
        outcome.other_blocks
    );
}

#[test]
fn reference_examples_show_real_output() {
    let mut ran = 0;
    for rel in &documents()[1..] {
        ran += check_document(rel).ran;
    }
    assert!(ran >= 15, "{ran} examples in docs/");
}

/// A command of the program shown in `docs/` that is not an example
/// (`$ ` in a fenced block without a language): a `postproc` line of an
/// untagged fenced block without its `$ `, or an indented one. Blocks
/// tagged with a language (`bash`, `yaml`, `text`) are files and scripts,
/// not transcripts.
fn unrun_commands(text: &str) -> Vec<String> {
    let mut found = Vec::new();
    let mut fence: Option<&str> = None;
    for (n, line) in text.lines().enumerate() {
        if let Some(tag) = line.strip_prefix("```") {
            fence = match fence {
                Some(_) => None,
                None => Some(tag.trim()),
            };
            continue;
        }
        let t = line.trim_start();
        let command = t.starts_with("postproc ") || t.starts_with("$ postproc ");
        let unrun = match fence {
            Some("") => t.starts_with("postproc "),
            Some(_) => false,
            None => line.starts_with("    ") && command,
        };
        if unrun {
            found.push(format!("{}: {}", n + 1, t));
        }
    }
    found
}

#[test]
fn every_command_shown_in_docs_is_run() {
    let mut unrun = Vec::new();
    for rel in documents() {
        let text = std::fs::read_to_string(repo(&rel)).unwrap();
        unrun.extend(
            unrun_commands(&text)
                .into_iter()
                .map(|l| format!("{rel}:{l}")),
        );
    }
    assert!(
        unrun.is_empty(),
        "commands shown but not run as `$ ` examples:\n{}",
        unrun.join("\n")
    );
    // The check finds what it looks for.
    assert_eq!(
        unrun_commands(
            "```\npostproc check x\n```\n    postproc report y\n```bash\npostproc z\n```\n"
        )
        .len(),
        2
    );
}

#[test]
fn readme_installs_and_tests_with_the_commands_ci_runs() {
    let text = std::fs::read_to_string(repo("README.md")).unwrap();
    let mut cargo = Vec::new();
    for line in text.lines() {
        if let Some(c) = line.strip_prefix("$ cargo ") {
            cargo.push(c.trim());
        }
    }
    assert_eq!(
        cargo,
        ["install --locked --path .", "test"],
        "the README's cargo commands"
    );
    // The README's test command is the last command of the CI script.
    let ci = std::fs::read_to_string(repo(".ci/run")).unwrap();
    let last = ci
        .lines()
        .map(str::trim)
        .rfind(|l| l.starts_with("cargo "))
        .unwrap();
    assert_eq!(last, "cargo test", ".ci/run's test command");
}

#[test]
fn readme_is_a_guide_of_a_few_hundred_lines() {
    let text = std::fs::read_to_string(repo("README.md")).unwrap();
    let n = text.lines().count();
    assert!(n < README_MAX_LINES, "README.md has {n} lines");
}

/// Markdown files of the repository (build and fuzzing output left out).
fn markdown_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let entry = entry.unwrap();
        let name = entry.file_name();
        let name = name.to_string_lossy();
        if name.starts_with('.') || name == "target" || name == "corpus" || name == "artifacts" {
            continue;
        }
        let path = entry.path();
        if entry.file_type().unwrap().is_dir() {
            markdown_files(&path, out);
        } else if name.ends_with(".md") {
            out.push(path);
        }
    }
}

#[test]
fn no_document_links_outside_the_repository() {
    let mut files = Vec::new();
    markdown_files(&repo(""), &mut files);
    assert!(files.len() >= 5, "{} Markdown files", files.len());
    let mut outside = Vec::new();
    for f in &files {
        let text = std::fs::read_to_string(f).unwrap();
        for (n, line) in text.lines().enumerate() {
            if line.contains("http://") || line.contains("https://") || line.contains("](//") {
                outside.push(format!("{}:{}: {}", f.display(), n + 1, line.trim()));
            }
        }
    }
    assert!(
        outside.is_empty(),
        "links outside the repository:\n{}",
        outside.join("\n")
    );
}
