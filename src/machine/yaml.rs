//! YAML helpers shared by every machine-file loader: strict deserialization
//! with the key path and line of the first error, and locating a key path in
//! the text for errors found during validation.

use serde::de::DeserializeOwned;

use crate::error::{Error, Invalid, Located};

/// Deserializes `text` into `T`, reporting `file:line:column: key.path: message`
/// on failure (unknown keys, wrong types, missing keys).
pub fn deserialize<T: DeserializeOwned>(text: &str, file: &str) -> Result<T, Error> {
    let de = serde_yaml::Deserializer::from_str(text);
    match serde_path_to_error::deserialize::<_, T>(de) {
        Ok(v) => Ok(v),
        Err(err) => {
            let path = err.path().to_string();
            let inner = err.into_inner();
            let (line, column) = match inner.location() {
                Some(loc) => (loc.line(), loc.column()),
                None => locate(text, &path).unwrap_or((1, 1)),
            };
            let mut msg = inner.to_string();
            // serde_yaml appends " at line L column C"; the prefix says it already.
            if let Some(pos) = msg.find(" at line ") {
                msg.truncate(pos);
            }
            // serde_yaml sometimes prefixes the path of the enclosing key
            // (`axes[0]: unknown field …`); the key path below says it.
            if let Some((head, rest)) = msg.split_once(": ") {
                if !head.is_empty() && !head.contains(' ') && path.starts_with(head) {
                    msg = rest.to_string();
                }
            }
            let message = if path.is_empty() || path == "." {
                msg
            } else {
                format!("{path}: {msg}")
            };
            Err(Error::Input(Located::new(file, line, column, message)))
        }
    }
}

/// Turns a validation failure into a located input error.
pub fn invalid(text: &str, file: &str, inv: Invalid) -> Error {
    located(text, file, &inv.path, &inv.message)
}

/// Builds `file:line:column: path: message`, finding the line of `path` in
/// `text` where possible (line 1 otherwise).
pub fn located(text: &str, file: &str, path: &str, message: &str) -> Error {
    let (line, column) = locate(text, path).unwrap_or((1, 1));
    Error::Input(Located::new(
        file,
        line,
        column,
        format!("{path}: {message}"),
    ))
}

/// Finds the 1-based line and column of a key path such as
/// `axes[1].component_errors.EXX` in block-style YAML text. Returns the
/// deepest part of the path that could be found.
pub fn locate(text: &str, path: &str) -> Option<(usize, usize)> {
    let lines: Vec<&str> = text.lines().collect();
    let mut range = (0usize, lines.len());
    let mut min_indent: isize = -1;
    let mut found: Option<(usize, usize)> = None;
    for seg in split_path(path) {
        let (key, index) = seg;
        if !key.is_empty() {
            let mut hit = None;
            for (i, line) in lines.iter().enumerate().take(range.1).skip(range.0) {
                let trimmed = line.trim_start();
                let indent = (line.len() - trimmed.len()) as isize;
                let body = trimmed.strip_prefix("- ").unwrap_or(trimmed);
                let indent = if body.len() != trimmed.len() {
                    indent + 2
                } else {
                    indent
                };
                if indent <= min_indent {
                    continue;
                }
                let k = body
                    .split(':')
                    .next()
                    .unwrap_or("")
                    .trim()
                    .trim_matches('"')
                    .trim_matches('\'');
                if k == key && body.contains(':') {
                    hit = Some((i, indent));
                    break;
                }
            }
            let (i, indent) = hit?;
            found = Some((i + 1, indent as usize + 1));
            min_indent = indent;
            range = (i, block_end(&lines, i, indent));
            if index.is_none() {
                range.0 = i + 1;
                continue;
            }
        }
        if let Some(n) = index {
            // Find the n-th sequence item `- ` below the key.
            let mut count = 0usize;
            let mut item_indent: Option<isize> = None;
            let mut hit = None;
            for (i, line) in lines.iter().enumerate().take(range.1).skip(range.0 + 1) {
                let trimmed = line.trim_start();
                let indent = (line.len() - trimmed.len()) as isize;
                if trimmed.starts_with("- ") || trimmed == "-" {
                    if item_indent.is_none() {
                        item_indent = Some(indent);
                    }
                    if Some(indent) == item_indent {
                        if count == n {
                            hit = Some((i, indent));
                            break;
                        }
                        count += 1;
                    }
                }
            }
            let (i, indent) = hit?;
            found = Some((i + 1, indent as usize + 1));
            min_indent = indent;
            range = (i, block_end(&lines, i, indent + 1));
        }
    }
    found
}

fn block_end(lines: &[&str], start: usize, indent: isize) -> usize {
    for (i, line) in lines.iter().enumerate().skip(start + 1) {
        let trimmed = line.trim_start();
        if trimmed.is_empty() || trimmed.starts_with('#') {
            continue;
        }
        let ind = (line.len() - trimmed.len()) as isize;
        if ind < indent || (ind == indent && !trimmed.starts_with("- ")) {
            return i;
        }
    }
    lines.len()
}

/// Splits `a.b[2].c` into `[("a", None), ("b", Some(2)), ("c", None)]`.
fn split_path(path: &str) -> Vec<(&str, Option<usize>)> {
    let mut out = Vec::new();
    for part in path.split('.') {
        if part.is_empty() {
            continue;
        }
        match part.find('[') {
            Some(b) => {
                let key = &part[..b];
                let mut rest = &part[b..];
                let mut first = true;
                while let Some(stripped) = rest.strip_prefix('[') {
                    let end = stripped.find(']').unwrap_or(stripped.len());
                    let idx = stripped[..end].parse().ok();
                    out.push((if first { key } else { "" }, idx));
                    first = false;
                    rest = stripped.get(end + 1..).unwrap_or("");
                }
            }
            None => out.push((part, None)),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    const DOC: &str = "kind: machine_tool\naxes:\n  - name: X\n    travel_mm: [0, 1000]\n  - name: Y\n    travel_mm: [0, 500]\n    component_errors:\n      EXX: 3\n";

    #[test]
    fn locates_nested_key_paths() {
        assert_eq!(locate(DOC, "kind"), Some((1, 1)));
        assert_eq!(locate(DOC, "axes[1].travel_mm"), Some((6, 5)));
        assert_eq!(locate(DOC, "axes[1].component_errors.EXX"), Some((8, 7)));
        assert_eq!(locate(DOC, "axes[0].name"), Some((3, 5)));
    }

    #[test]
    fn deserialize_reports_path_and_line() {
        #[derive(serde::Deserialize, Debug)]
        #[serde(deny_unknown_fields)]
        #[allow(dead_code)]
        struct A {
            kind: String,
            axes: Vec<B>,
        }
        #[derive(serde::Deserialize, Debug)]
        #[serde(deny_unknown_fields)]
        #[allow(dead_code)]
        struct B {
            name: String,
            travel_mm: [f64; 2],
        }
        let err = deserialize::<A>(DOC, "m.yaml").unwrap_err().to_string();
        assert!(err.starts_with("m.yaml:7:"), "{err}");
        assert!(err.contains("axes[1]"), "{err}");
        assert!(err.contains("component_errors"), "{err}");
    }
}
