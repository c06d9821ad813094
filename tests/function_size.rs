//! Functions a reader holds in mind: no function of the library (outside
//! its `#[cfg(test)]` modules) is longer than [`MAX_LINES`] lines, counted
//! from the line of `fn` to the line of its closing brace.

use std::path::{Path, PathBuf};

use crate::common::repo;

/// Longest function allowed, in lines.
const MAX_LINES: usize = 150;

/// Every `.rs` file under `dir`, sorted.
fn rust_files(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).expect("read_dir").flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else if p.extension().is_some_and(|x| x == "rs") {
                out.push(p);
            }
        }
    }
    out.sort();
    out
}

/// The name of the function a line starts (`fn`, after visibility and
/// qualifiers), and the line's indentation.
fn fn_start(line: &str) -> Option<(&str, usize)> {
    let indent = line.len() - line.trim_start().len();
    let mut rest = line.trim_start();
    for q in [
        "pub(crate) ",
        "pub(super) ",
        "pub ",
        "const ",
        "async ",
        "unsafe ",
    ] {
        rest = rest.strip_prefix(q).unwrap_or(rest);
    }
    let name = rest.strip_prefix("fn ")?;
    let end = name
        .find(|c: char| !(c.is_alphanumeric() || c == '_'))
        .unwrap_or(name.len());
    Some((&name[..end], indent))
}

/// `(first line, length, name)` of every function of `text` longer than
/// `max` lines, outside a `#[cfg(test)]` module.
fn long_functions(text: &str, max: usize) -> Vec<(usize, usize, String)> {
    let lines: Vec<&str> = text.lines().collect();
    let end = lines
        .windows(2)
        .position(|w| w[0].trim() == "#[cfg(test)]" && w[1].trim_start().starts_with("mod "))
        .unwrap_or(lines.len());
    let mut out = Vec::new();
    for (i, line) in lines[..end].iter().enumerate() {
        let Some((name, indent)) = fn_start(line) else {
            continue;
        };
        if line.trim_end().ends_with(';') {
            continue; // a declaration in a trait
        }
        let close = format!("{}}}", " ".repeat(indent));
        let Some(len) = lines[i..].iter().position(|l| l.trim_end() == close) else {
            continue;
        };
        if len + 1 > max {
            out.push((i + 1, len + 1, name.to_string()));
        }
    }
    out
}

#[test]
fn no_library_function_is_longer_than_the_limit() {
    let src = repo("src");
    let mut found = Vec::new();
    for f in rust_files(&src) {
        let text = std::fs::read_to_string(&f).expect("source");
        let rel = f
            .strip_prefix(&src)
            .expect("under src")
            .display()
            .to_string();
        for (line, len, name) in long_functions(&text, MAX_LINES) {
            found.push(format!("src/{rel}:{line}: {name} has {len} lines"));
        }
    }
    assert!(
        found.is_empty(),
        "functions over {MAX_LINES} lines:\n{}",
        found.join("\n")
    );
}

#[test]
fn the_measure_sees_methods_and_skips_test_modules() {
    let body = |n: usize| "    let x = 1;\n".repeat(n);
    let text = format!(
        "fn short() {{\n{}}}\nimpl A {{\n    pub(crate) fn long(&self) {{\n    {}    }}\n}}\n\
         #[cfg(test)]\nmod tests {{\n    fn long_test() {{\n{}    }}\n}}\n",
        body(3),
        body(10),
        body(20)
    );
    let found = long_functions(&text, 8);
    assert_eq!(found.len(), 1, "{found:?}");
    assert_eq!(found[0].2, "long");
    assert_eq!(found[0].0, 7);
    // `fn long` spans its own line, 10 body lines and the closing brace.
    assert_eq!(found[0].1, 12);
}
