//! The crate's layers: a module may use modules of its own layer and of the
//! layers below it, never one above. Every `src/**/*.rs` file is read
//! (comments, string literals and `#[cfg(test)]` items left out) and each
//! `crate::` path — also grouped (`use crate::{a, b::c}`) — and each
//! `super::` path that climbs out of its top module is an edge from the
//! file's top module to the module it names.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use crate::common::repo;

/// The layers, lowest first; modules on one line share a layer.
const LAYERS: &[&[&str]] = &[
    // Located errors, units and limits shared by everything.
    &["error"],
    &["limits"],
    // Process physics (forces, cutting settings).
    &["process"],
    // Machine models.
    &["machine"],
    // Programs: syntax with spans, interpretation, name resolution.
    &["program"],
    // Forward prediction, then the inverse solve and its result types.
    &["predict"],
    &["compensate"],
    // Byte-faithful writers and reports, on result types only.
    &["emit"],
    // Whole programs from input to output.
    &["pipeline"],
    // Identification from measured data.
    &["calibrate"],
    &["diagnose"],
    // Acceptance tests to the standards.
    &["verify"],
    // Flags and commands.
    &["cli"],
];

/// Layer of a top module, `None` when it has none.
fn layer(module: &str) -> Option<usize> {
    LAYERS.iter().position(|l| l.contains(&module))
}

/// A token of Rust source with comments and literal contents removed.
#[derive(Debug, Clone, PartialEq)]
enum Tok {
    Ident(String),
    /// `::`
    Path,
    Punct(char),
}

/// Tokens of `src`: identifiers, `::` and punctuation; comments (line, doc
/// and block), string, raw string, byte string and character literals,
/// numbers and lifetimes are dropped.
fn tokens(src: &str) -> Vec<Tok> {
    let c: Vec<char> = src.chars().collect();
    let mut out = Vec::new();
    let mut i = 0;
    while i < c.len() {
        let ch = c[i];
        let next = c.get(i + 1).copied();
        if ch.is_whitespace() {
            i += 1;
        } else if ch == '/' && next == Some('/') {
            while i < c.len() && c[i] != '\n' {
                i += 1;
            }
        } else if ch == '/' && next == Some('*') {
            let mut depth = 0;
            while i < c.len() {
                if c[i] == '/' && c.get(i + 1) == Some(&'*') {
                    depth += 1;
                    i += 2;
                } else if c[i] == '*' && c.get(i + 1) == Some(&'/') {
                    depth -= 1;
                    i += 2;
                    if depth == 0 {
                        break;
                    }
                } else {
                    i += 1;
                }
            }
        } else if ch == '"' {
            i = skip_string(&c, i + 1);
        } else if ch == '\'' {
            // A character literal ('x', '\n', '\u{..}') or a lifetime ('a).
            if next == Some('\\') {
                i += 2;
                while i < c.len() && c[i] != '\'' {
                    i += 1;
                }
                i += 1;
            } else if c.get(i + 2) == Some(&'\'') {
                i += 3;
            } else {
                i += 1;
                while i < c.len() && (c[i].is_alphanumeric() || c[i] == '_') {
                    i += 1;
                }
            }
        } else if ch.is_ascii_digit() {
            while i < c.len() && (c[i].is_alphanumeric() || c[i] == '_' || c[i] == '.') {
                if c[i] == '.' && !c.get(i + 1).is_some_and(|d| d.is_ascii_digit()) {
                    break;
                }
                i += 1;
            }
        } else if ch.is_alphabetic() || ch == '_' {
            let start = i;
            while i < c.len() && (c[i].is_alphanumeric() || c[i] == '_') {
                i += 1;
            }
            let word: String = c[start..i].iter().collect();
            // Raw and byte string prefixes: r"..", r#".."#, b"..", br#".."#.
            let hashes = c[i..].iter().take_while(|&&h| h == '#').count();
            if matches!(word.as_str(), "r" | "br" | "b" | "rb")
                && c.get(i + hashes) == Some(&'"')
                && (hashes == 0 || word.contains('r'))
            {
                if word.contains('r') {
                    i = skip_raw_string(&c, i + hashes + 1, hashes);
                } else {
                    i = skip_string(&c, i + 1);
                }
            } else if word == "b" && c.get(i) == Some(&'\'') {
                // A byte literal: b'x' or b'\n'.
                i += 1;
                while i < c.len() && c[i] != '\'' {
                    i += if c[i] == '\\' { 2 } else { 1 };
                }
                i += 1;
            } else {
                out.push(Tok::Ident(word));
            }
        } else if ch == ':' && next == Some(':') {
            out.push(Tok::Path);
            i += 2;
        } else {
            out.push(Tok::Punct(ch));
            i += 1;
        }
    }
    out
}

/// The index after the string whose contents start at `i`.
fn skip_string(c: &[char], mut i: usize) -> usize {
    while i < c.len() && c[i] != '"' {
        i += if c[i] == '\\' { 2 } else { 1 };
    }
    i + 1
}

/// The index after the raw string with `hashes` hashes whose contents
/// start at `i`.
fn skip_raw_string(c: &[char], mut i: usize, hashes: usize) -> usize {
    while i < c.len() {
        if c[i] == '"'
            && c[i + 1..]
                .iter()
                .take(hashes)
                .filter(|&&h| h == '#')
                .count()
                == hashes
        {
            return i + 1 + hashes;
        }
        i += 1;
    }
    i
}

fn is_ident(t: Option<&Tok>, word: &str) -> bool {
    matches!(t, Some(Tok::Ident(w)) if w == word)
}

/// Index after the bracketed group that opens at `i` (`open`/`close`).
fn skip_group(t: &[Tok], mut i: usize, open: char, close: char) -> usize {
    let mut depth = 0usize;
    while i < t.len() {
        if t[i] == Tok::Punct(open) {
            depth += 1;
        } else if t[i] == Tok::Punct(close) {
            depth -= 1;
            if depth == 0 {
                return i + 1;
            }
        }
        i += 1;
    }
    i
}

/// `tokens` without the items marked `#[cfg(test)]`; also the names of the
/// module files such items declare (`#[cfg(test)] mod testing;`).
fn without_tests(t: &[Tok]) -> (Vec<Tok>, Vec<String>) {
    let cfg_test = [
        Tok::Punct('#'),
        Tok::Punct('['),
        Tok::Ident("cfg".into()),
        Tok::Punct('('),
        Tok::Ident("test".into()),
        Tok::Punct(')'),
        Tok::Punct(']'),
    ];
    let mut out = Vec::new();
    let mut test_files = Vec::new();
    let mut i = 0;
    while i < t.len() {
        if !t[i..].starts_with(&cfg_test) {
            out.push(t[i].clone());
            i += 1;
            continue;
        }
        i += cfg_test.len();
        // Further attributes of the same item.
        while t.get(i) == Some(&Tok::Punct('#')) {
            i = skip_group(t, i + 1, '[', ']');
        }
        let item = i;
        let mut paren = 0i32;
        while i < t.len() {
            match &t[i] {
                Tok::Punct('(' | '[') => paren += 1,
                Tok::Punct(')' | ']') => paren -= 1,
                Tok::Punct(';') if paren == 0 => {
                    if let Some(at) = t[item..i].iter().position(|x| is_ident(Some(x), "mod")) {
                        if let Some(Tok::Ident(name)) = t.get(item + at + 1) {
                            test_files.push(name.clone());
                        }
                    }
                    i += 1;
                    break;
                }
                Tok::Punct('{') if paren == 0 => {
                    i = skip_group(t, i, '{', '}');
                    break;
                }
                _ => {}
            }
            i += 1;
        }
    }
    (out, test_files)
}

/// First identifiers of the comma-separated items of the `{…}` group that
/// opens at `i`.
fn group_heads(t: &[Tok], i: usize) -> Vec<String> {
    let end = skip_group(t, i, '{', '}');
    let mut heads = Vec::new();
    let mut depth = 0;
    let mut expect = true;
    for tok in &t[i + 1..end.saturating_sub(1)] {
        match tok {
            Tok::Punct('{') => depth += 1,
            Tok::Punct('}') => depth -= 1,
            Tok::Punct(',') if depth == 0 => expect = true,
            Tok::Ident(w) if expect && depth == 0 => {
                heads.push(w.clone());
                expect = false;
            }
            _ => expect = false,
        }
    }
    heads
}

/// The top modules that the source of the module at `path` (module path
/// below the crate root, e.g. `["emit", "report"]`) names through `crate::`
/// paths and through `super::` paths that reach the crate root.
fn named_tops(path: &[&str], t: &[Tok]) -> Vec<String> {
    let mut found = Vec::new();
    // Inline modules (`mod name { … }`) open at a brace depth.
    let mut inline: Vec<usize> = Vec::new();
    let mut depth = 0usize;
    let mut i = 0;
    while i < t.len() {
        match &t[i] {
            Tok::Punct('{') => {
                depth += 1;
                if i >= 2 && is_ident(t.get(i - 2), "mod") {
                    inline.push(depth);
                }
            }
            Tok::Punct('}') => {
                if inline.last() == Some(&depth) {
                    inline.pop();
                }
                depth = depth.saturating_sub(1);
            }
            Tok::Ident(w) if w == "crate" || w == "super" => {
                let after_path = i > 0 && t[i - 1] == Tok::Path;
                let in_macro = i > 0 && t[i - 1] == Tok::Punct('$');
                if after_path || in_macro {
                    i += 1;
                    continue;
                }
                let mut j = i;
                let reaches_root = if w == "crate" {
                    j += 1;
                    true
                } else {
                    let mut climbs = 0;
                    while is_ident(t.get(j), "super") && t.get(j + 1) == Some(&Tok::Path) {
                        climbs += 1;
                        j += 2;
                    }
                    j = j.saturating_sub(1);
                    climbs == path.len() + inline.len() && climbs > 0
                };
                if reaches_root && t.get(j) == Some(&Tok::Path) {
                    match t.get(j + 1) {
                        Some(Tok::Ident(m)) => found.push(m.clone()),
                        Some(Tok::Punct('{')) => found.extend(group_heads(t, j + 1)),
                        _ => {}
                    }
                }
                i = j.max(i + 1);
                continue;
            }
            _ => {}
        }
        i += 1;
    }
    found
}

/// The `.rs` files under `dir`, sorted.
fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let mut entries: Vec<PathBuf> = std::fs::read_dir(dir)
        .expect("readable source folder")
        .map(|e| e.expect("folder entry").path())
        .collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|e| e == "rs") {
            out.push(p);
        }
    }
}

/// Module path of a file relative to `src/` (`emit/report.rs` →
/// `["emit", "report"]`, `emit/mod.rs` → `["emit"]`).
fn module_path(rel: &str) -> Vec<&str> {
    let mut parts: Vec<&str> = rel.trim_end_matches(".rs").split('/').collect();
    if parts.last() == Some(&"mod") {
        parts.pop();
    }
    parts
}

/// Items re-exported at the crate root (`pub use error::{Error, Result};`
/// in `lib.rs`), with the module they come from.
fn root_items(lib: &[Tok]) -> Vec<(String, String)> {
    let mut items = Vec::new();
    for (i, w) in lib.windows(3).enumerate() {
        if is_ident(Some(&w[0]), "pub") && is_ident(Some(&w[1]), "use") {
            if let (Tok::Ident(m), Some(Tok::Path)) = (&w[2], lib.get(i + 3)) {
                match lib.get(i + 4) {
                    Some(Tok::Ident(name)) => items.push((name.clone(), m.clone())),
                    Some(Tok::Punct('{')) => {
                        for name in group_heads(lib, i + 4) {
                            items.push((name, m.clone()));
                        }
                    }
                    _ => {}
                }
            }
        }
    }
    items
}

/// Every edge of the library from a lower layer to a higher one, as
/// `file: from → to`, and the top modules without a layer; then every edge
/// between two top modules seen, as `(from, to)`.
fn upward_edges() -> (Vec<String>, BTreeSet<(String, String)>) {
    let src = repo("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    let lib = tokens(&std::fs::read_to_string(src.join("lib.rs")).expect("lib.rs"));
    let roots = root_items(&lib);
    let mut test_only: BTreeSet<String> = BTreeSet::new();
    let mut bad = Vec::new();
    let mut all = BTreeSet::new();
    let mut per_file = Vec::new();
    for f in &files {
        let rel = f
            .strip_prefix(&src)
            .expect("under src")
            .to_string_lossy()
            .replace('\\', "/");
        let text = std::fs::read_to_string(f).expect("readable source file");
        let (toks, tests) = without_tests(&tokens(&text));
        // Files of a module declared in `a/mod.rs`, `lib.rs` or `main.rs`
        // live beside it; those of one declared in `a/b.rs` in `a/b/`.
        let children = match rel.rsplit_once('/') {
            Some((d, "mod.rs")) => format!("{d}/"),
            Some(_) => format!("{}/", rel.trim_end_matches(".rs")),
            None if rel == "lib.rs" || rel == "main.rs" => String::new(),
            None => format!("{}/", rel.trim_end_matches(".rs")),
        };
        for t in tests {
            test_only.insert(format!("{children}{t}.rs"));
            test_only.insert(format!("{children}{t}/mod.rs"));
        }
        per_file.push((rel, toks));
    }
    for (rel, toks) in &per_file {
        if rel == "lib.rs" || rel == "main.rs" || test_only.contains(rel) {
            continue;
        }
        let path = module_path(rel);
        let from = path[0];
        let Some(from_layer) = layer(from) else {
            bad.push(format!(
                "src/{rel}: module `{from}` has no layer in tests/layers.rs"
            ));
            continue;
        };
        let mut seen = BTreeSet::new();
        for to in named_tops(&path, toks) {
            let to = roots
                .iter()
                .find(|(n, _)| *n == to)
                .map(|(_, m)| m.clone())
                .unwrap_or(to);
            if to == from || !seen.insert(to.clone()) {
                continue;
            }
            all.insert((from.to_string(), to.clone()));
            match layer(&to) {
                Some(l) if l > from_layer => bad.push(format!("src/{rel}: {from} → {to}")),
                Some(_) => {}
                None => bad.push(format!("src/{rel}: {from} → {to}, which has no layer")),
            }
        }
    }
    (bad, all)
}

#[test]
fn no_module_uses_a_module_of_a_higher_layer() {
    let (bad, all) = upward_edges();
    // The reader sees the tree: edges every build has.
    for (from, to) in [
        ("pipeline", "emit"),
        ("emit", "compensate"),
        ("cli", "pipeline"),
    ] {
        assert!(
            all.contains(&(from.to_string(), to.to_string())),
            "edge {from} → {to} not seen; seen: {all:?}"
        );
    }
    assert!(
        bad.is_empty(),
        "edges from a lower layer to a higher one (layers, lowest first: {:?}):\n{}",
        LAYERS,
        bad.join("\n")
    );
}

#[test]
fn every_top_module_of_the_library_has_a_layer() {
    let lib = tokens(&std::fs::read_to_string(repo("src/lib.rs")).expect("lib.rs"));
    let modules: Vec<String> = lib
        .windows(3)
        .filter_map(|w| match w {
            [Tok::Ident(p), Tok::Ident(m), Tok::Ident(name)] if p == "pub" && m == "mod" => {
                Some(name.clone())
            }
            _ => None,
        })
        .collect();
    assert!(
        modules.len() >= LAYERS.len(),
        "modules of lib.rs: {modules:?}"
    );
    for m in &modules {
        assert!(
            layer(m).is_some(),
            "module `{m}` has no layer in tests/layers.rs"
        );
    }
}

#[test]
fn the_reader_sees_grouped_and_climbing_paths_not_comments_strings_or_tests() {
    let src = r##"
//! Uses [`crate::cli`] in a doc comment.
/// crate::diagnose in a doc comment.
// crate::calibrate in a comment.
/* crate::pipeline in a block comment /* nested crate::emit */ */
use crate::{machine::AxisVec, predict::{Effect, EffectSet}, error};
use super::super::program::Span;
use super::sibling::Thing;
const S: &str = "crate::cli in a string";
const R: &str = r#"crate::cli in a raw "string""#;
const C: char = '"';
fn f<'a>(x: &'a str) -> crate::limits::Mm { crate::compensate::solve(x) }
macro_rules! m { () => { $crate::cli::run() } }
pub(super) fn g() {}
mod inner {
    use super::super::super::process::Force;
}
#[cfg(test)]
mod tests {
    use crate::cli::Format;
}
#[cfg(test)]
mod testing;
"##;
    let (toks, test_files) = without_tests(&tokens(src));
    assert_eq!(test_files, vec!["testing".to_string()]);
    let mut got = named_tops(&["emit", "report"], &toks);
    got.sort();
    assert_eq!(
        got,
        [
            "compensate",
            "error",
            "limits",
            "machine",
            "predict",
            "process",
            "program"
        ]
    );
    // One level down, `super::super` stays inside the top module.
    let got = named_tops(&["emit", "report", "deep"], &toks);
    assert!(!got.contains(&"program".to_string()), "{got:?}");
}
