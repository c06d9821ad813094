//! docs/architecture.md names the place of every source file: each
//! `src/**/*.rs` path must appear in it, written out in full
//! (`src/machine/yaml_write/tree.rs`), and each path it names must exist.
//! A new file fails this test until the document says where it belongs.

use std::path::Path;

use crate::common::repo;

/// Every `.rs` file under `dir`, as a path relative to the repository
/// root with `/` separators, sorted.
fn sources(root: &Path, dir: &Path, out: &mut Vec<String>) {
    let mut entries: Vec<_> = std::fs::read_dir(dir)
        .expect("readable source folder")
        .flatten()
        .map(|e| e.path())
        .collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            sources(root, &p, out);
        } else if p.extension().is_some_and(|e| e == "rs") {
            let rel = p.strip_prefix(root).expect("under the root");
            let parts: Vec<String> = rel
                .components()
                .map(|c| c.as_os_str().to_string_lossy().into_owned())
                .collect();
            out.push(parts.join("/"));
        }
    }
}

/// The `src/….rs` paths the document names.
fn named(doc: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut rest = doc;
    while let Some(at) = rest.find("src/") {
        let tail = &rest[at..];
        let end = tail
            .find(|c: char| !(c.is_ascii_alphanumeric() || matches!(c, '/' | '_' | '.' | '-')))
            .unwrap_or(tail.len());
        let path = tail[..end].trim_end_matches('.');
        if path.ends_with(".rs") {
            out.push(path.to_string());
        }
        rest = &tail[end.max(4)..];
    }
    out
}

#[test]
fn every_source_file_is_named_in_the_architecture_document() {
    let root = repo("");
    let doc = std::fs::read_to_string(repo("docs/architecture.md")).expect("docs/architecture.md");
    let mut files = Vec::new();
    sources(&root, &repo("src"), &mut files);
    assert!(files.len() > 100, "{} source files", files.len());
    let mentioned = named(&doc);
    let missing: Vec<&String> = files.iter().filter(|f| !mentioned.contains(f)).collect();
    assert!(
        missing.is_empty(),
        "docs/architecture.md does not say where these files live (name each with its full path):\n  {}",
        missing
            .iter()
            .map(|s| s.as_str())
            .collect::<Vec<_>>()
            .join("\n  ")
    );
    let stale: Vec<&String> = mentioned.iter().filter(|m| !files.contains(m)).collect();
    assert!(
        stale.is_empty(),
        "docs/architecture.md names files that do not exist:\n  {}",
        stale
            .iter()
            .map(|s| s.as_str())
            .collect::<Vec<_>>()
            .join("\n  ")
    );
}

#[test]
fn named_paths_are_read_whole() {
    let doc = "see `src/a/b.rs`, src/c.rs. and src/d/ and src/e_f.rs|";
    assert_eq!(named(doc), vec!["src/a/b.rs", "src/c.rs", "src/e_f.rs"]);
}
