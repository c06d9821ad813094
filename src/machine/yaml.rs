//! YAML helpers shared by every machine-file loader: strict deserialization
//! with the key path and line of the first error, and locating a key path in
//! the text for errors found during validation.
//!
//! Before any typed deserialization the text is checked for its nesting
//! depth (at most [`limits::YAML_MAX_DEPTH`] levels, counted without parsing,
//! because the YAML parser's time grows with the square of the depth) and
//! for duplicate keys in every mapping at every level (YAML forbids them;
//! the parser would silently keep the last one).

use std::collections::BTreeSet;
use std::fmt;

use serde::de::{self, DeserializeOwned, MapAccess, SeqAccess, Visitor};

use crate::error::{Error, Invalid, Located};
use crate::limits;

/// Deserializes `text` into `T`, reporting `file:line:column: key.path: message`
/// on failure (unknown keys, wrong types, missing keys, duplicate keys,
/// nesting deeper than [`limits::YAML_MAX_DEPTH`]).
pub fn deserialize<T: DeserializeOwned>(text: &str, file: &str) -> Result<T, Error> {
    check_depth(text, file)?;
    check_unique_keys(text, file)?;
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
            Err(Error::Machine(Located::new(file, line, column, message)))
        }
    }
}

/// Refuses text nested deeper than [`limits::YAML_MAX_DEPTH`] levels: block
/// indentation levels, `- ` items opened on one line, and open flow brackets
/// (`[`, `{`) outside quotes and comments, summed. A lexical count: it may
/// count a bracket inside a plain scalar, never fewer levels than the parser
/// sees.
pub fn check_depth(text: &str, file: &str) -> Result<(), Error> {
    let mut indents: Vec<usize> = Vec::new();
    let mut flow = 0usize;
    let mut quote: Option<u8> = None;
    for (i, line) in text.lines().enumerate() {
        let bytes = line.as_bytes();
        let mut j = 0;
        if quote.is_none() && flow == 0 {
            let indent = bytes.iter().take_while(|&&b| b == b' ').count();
            let rest = &line[indent..];
            if rest.is_empty() || rest.starts_with('#') {
                continue;
            }
            while indents.last().is_some_and(|&top| top > indent) {
                indents.pop();
            }
            if indents.last() != Some(&indent) {
                indents.push(indent);
            }
            j = indent;
            // `- - - x`: each dash opens one more level.
            let mut dashes = 0;
            while j < bytes.len()
                && (bytes[j] == b'-' || bytes[j] == b'?')
                && bytes.get(j + 1).is_none_or(|&b| b == b' ')
            {
                dashes += 1;
                j += 2;
                while j < bytes.len() && bytes[j] == b' ' {
                    j += 1;
                }
            }
            too_deep(indents.len() + dashes, i, j, file)?;
        }
        let mut prev_space = true;
        while j < bytes.len() {
            let b = bytes[j];
            match quote {
                Some(b'"') if b == b'\\' => j += 1,
                Some(q) if b == q => quote = None,
                Some(_) => {}
                None => match b {
                    b'#' if prev_space => break,
                    b'"' | b'\'' => quote = Some(b),
                    b'[' | b'{' => {
                        flow += 1;
                        too_deep(indents.len() + flow, i, j, file)?;
                    }
                    b']' | b'}' => flow = flow.saturating_sub(1),
                    _ => {}
                },
            }
            prev_space = b == b' ' || b == b'\t';
            j += 1;
        }
    }
    Ok(())
}

fn too_deep(depth: usize, line: usize, col: usize, file: &str) -> Result<(), Error> {
    if depth > limits::YAML_MAX_DEPTH {
        return Err(Error::Machine(Located::new(
            file,
            line + 1,
            col + 1,
            format!(
                "nesting deeper than {} levels (a machine file needs fewer than 10)",
                limits::YAML_MAX_DEPTH
            ),
        )));
    }
    Ok(())
}

/// Refuses a mapping that has the same key twice, at any level, naming the
/// key path of the mapping, the key and the line of its second occurrence.
pub fn check_unique_keys(text: &str, file: &str) -> Result<(), Error> {
    let de = serde_yaml::Deserializer::from_str(text);
    let Err(err) = serde_path_to_error::deserialize::<_, Unique>(de) else {
        return Ok(());
    };
    let path = err.path().to_string();
    let inner = err.into_inner();
    let msg = inner.to_string();
    let Some(key) = msg
        .find(DUPLICATE)
        .and_then(|at| msg[at + DUPLICATE.len()..].split(DUPLICATE_END).next())
    else {
        // Not a duplicate: the typed pass reports it with its own words.
        return Ok(());
    };
    let mark = inner.location().map(|l| (l.line(), l.column()));
    let (line, column) = mark
        .and_then(|(l, c)| second_key_line(text, l, c, key))
        .or(mark)
        .unwrap_or((1, 1));
    let message = if path.is_empty() || path == "." {
        format!("duplicate key `{key}`: a key may appear once in a mapping")
    } else {
        format!("{path}: duplicate key `{key}`: a key may appear once in a mapping")
    };
    Err(Error::Machine(Located::new(file, line, column, message)))
}

const DUPLICATE: &str = "duplicate key \u{1}";
const DUPLICATE_END: &str = "\u{1}";

/// The line and column of the second block-style line with key `key` among
/// the keys of the mapping that starts at (`line`, `column`).
fn second_key_line(text: &str, line: usize, column: usize, key: &str) -> Option<(usize, usize)> {
    let indent = column.checked_sub(1)?;
    let mut seen = 0;
    for (i, l) in text.lines().enumerate().skip(line.checked_sub(1)?) {
        let trimmed = l.trim_start();
        if trimmed.is_empty() || trimmed.starts_with('#') {
            continue;
        }
        let ind = l.len() - trimmed.len();
        // The first key of a mapping inside a `- ` item sits after the dash.
        let (ind, body) = if i + 1 == line && ind < indent {
            (indent, l.get(indent..).unwrap_or(""))
        } else {
            (ind, trimmed)
        };
        if ind < indent {
            break;
        }
        if ind > indent {
            continue;
        }
        let k = body.split(':').next().unwrap_or("").trim();
        let k = k.trim_matches('"').trim_matches('\'');
        if k == key && body.contains(':') {
            seen += 1;
            if seen == 2 {
                return Some((i + 1, ind + 1));
            }
        }
    }
    None
}

/// Any YAML value, checked for duplicate mapping keys and then dropped.
struct Unique;

impl<'de> de::Deserialize<'de> for Unique {
    fn deserialize<D: de::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        d.deserialize_any(UniqueVisitor)
    }
}

/// A mapping key as text (scalars only; a complex key is not compared).
struct KeyText(Option<String>);

impl<'de> de::Deserialize<'de> for KeyText {
    fn deserialize<D: de::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = KeyText;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("a mapping key")
            }
            fn visit_bool<E>(self, v: bool) -> Result<KeyText, E> {
                Ok(KeyText(Some(v.to_string())))
            }
            fn visit_i64<E>(self, v: i64) -> Result<KeyText, E> {
                Ok(KeyText(Some(v.to_string())))
            }
            fn visit_u64<E>(self, v: u64) -> Result<KeyText, E> {
                Ok(KeyText(Some(v.to_string())))
            }
            fn visit_f64<E>(self, v: f64) -> Result<KeyText, E> {
                Ok(KeyText(Some(v.to_string())))
            }
            fn visit_str<E>(self, v: &str) -> Result<KeyText, E> {
                Ok(KeyText(Some(v.to_string())))
            }
            fn visit_unit<E>(self) -> Result<KeyText, E> {
                Ok(KeyText(Some("~".into())))
            }
            fn visit_seq<A: SeqAccess<'de>>(self, seq: A) -> Result<KeyText, A::Error> {
                UniqueVisitor.visit_seq(seq).map(|_| KeyText(None))
            }
            fn visit_map<A: MapAccess<'de>>(self, map: A) -> Result<KeyText, A::Error> {
                UniqueVisitor.visit_map(map).map(|_| KeyText(None))
            }
            fn visit_enum<A: de::EnumAccess<'de>>(self, e: A) -> Result<KeyText, A::Error> {
                UniqueVisitor.visit_enum(e).map(|_| KeyText(None))
            }
        }
        d.deserialize_any(V)
    }
}

struct UniqueVisitor;

impl<'de> Visitor<'de> for UniqueVisitor {
    type Value = Unique;
    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("any YAML value")
    }
    fn visit_bool<E>(self, _: bool) -> Result<Unique, E> {
        Ok(Unique)
    }
    fn visit_i64<E>(self, _: i64) -> Result<Unique, E> {
        Ok(Unique)
    }
    fn visit_u64<E>(self, _: u64) -> Result<Unique, E> {
        Ok(Unique)
    }
    fn visit_i128<E>(self, _: i128) -> Result<Unique, E> {
        Ok(Unique)
    }
    fn visit_u128<E>(self, _: u128) -> Result<Unique, E> {
        Ok(Unique)
    }
    fn visit_f64<E>(self, _: f64) -> Result<Unique, E> {
        Ok(Unique)
    }
    fn visit_str<E>(self, _: &str) -> Result<Unique, E> {
        Ok(Unique)
    }
    fn visit_bytes<E>(self, _: &[u8]) -> Result<Unique, E> {
        Ok(Unique)
    }
    fn visit_unit<E>(self) -> Result<Unique, E> {
        Ok(Unique)
    }
    fn visit_none<E>(self) -> Result<Unique, E> {
        Ok(Unique)
    }
    fn visit_some<D: de::Deserializer<'de>>(self, d: D) -> Result<Unique, D::Error> {
        d.deserialize_any(UniqueVisitor)
    }
    fn visit_newtype_struct<D: de::Deserializer<'de>>(self, d: D) -> Result<Unique, D::Error> {
        d.deserialize_any(UniqueVisitor)
    }
    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Unique, A::Error> {
        while seq.next_element::<Unique>()?.is_some() {}
        Ok(Unique)
    }
    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Unique, A::Error> {
        let mut seen = BTreeSet::new();
        while let Some(KeyText(key)) = map.next_key::<KeyText>()? {
            if let Some(k) = key {
                if !seen.insert(k.clone()) {
                    return Err(de::Error::custom(format!("{DUPLICATE}{k}{DUPLICATE_END}")));
                }
            }
            map.next_value::<Unique>()?;
        }
        Ok(Unique)
    }
    fn visit_enum<A: de::EnumAccess<'de>>(self, e: A) -> Result<Unique, A::Error> {
        use de::VariantAccess;
        let (_, variant) = e.variant::<KeyText>()?;
        variant.newtype_variant::<Unique>()?;
        Ok(Unique)
    }
}

/// Turns a validation failure into a located machine-file error.
pub fn invalid(text: &str, file: &str, inv: Invalid) -> Error {
    located(text, file, &inv.path, &inv.message)
}

/// Builds `file:line:column: path: message`, finding the line of `path` in
/// `text` where possible (line 1 otherwise).
pub fn located(text: &str, file: &str, path: &str, message: &str) -> Error {
    let (line, column) = locate(text, path).unwrap_or((1, 1));
    Error::Machine(Located::new(
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
