//! Reading a machine file, once: the text is checked for its nesting depth
//! (at most [`limits::YAML_MAX_DEPTH`] levels, counted without parsing,
//! because a YAML parser's time grows with the square of the depth), then
//! parsed into a lossless syntax tree (the `yaml-edit` crate: every byte and
//! comment is a token of the tree, so the writer, [`super::yaml_write`],
//! edits the same tree). One walk of the tree refuses duplicate keys in
//! every mapping at every level (YAML forbids them; a typed reader would
//! silently keep the last one) and the few layouts the writer cannot write
//! back (an alias, a tag), each with its key path and line, and reads the
//! file's `kind`. The checked text then goes through the strict typed pass
//! of its kind ([`Source::deserialize`]: serde raw structs that deny
//! unknown keys, with the key path and line of the first error), and key
//! paths of validation errors are located on the tree ([`locate`]).

use std::collections::BTreeSet;

use serde::de::DeserializeOwned;
use yaml_edit::{YamlFile, YamlNode};

use crate::error::{Error, Invalid, Located};
use crate::limits;

/// A machine file read and checked once (see the module comment): the text
/// with its `kind`, ready for the typed pass of its kind.
#[derive(Debug, Clone)]
pub struct Source<'a> {
    text: &'a str,
    file: &'a str,
    kind: Option<String>,
    mapping: bool,
}

impl<'a> Source<'a> {
    /// Reads machine YAML `text` (named `file` in errors): nesting depth,
    /// one syntax tree, no duplicate key, nothing the writer cannot write.
    pub fn read(text: &'a str, file: &'a str) -> Result<Source<'a>, Error> {
        check_depth(text, file)?;
        let parsed = YamlFile::parse(text);
        if let Some(e) = parsed.positioned_errors().first() {
            // Text the typed reader refuses too is reported in its words
            // (with the key path of the mapping it fails in).
            typed::<serde_yaml::Mapping>(text, file)?;
            return Err(at(
                text,
                file,
                e.range.start as usize,
                format!(
                    "the machine-file writer cannot read this layout ({}); write it in plain block or flow style",
                    e.message
                ),
            ));
        }
        let mut docs = parsed.tree().documents();
        let doc = docs.next();
        if docs.next().is_some() {
            return Err(Error::Machine(Located::new(
                file,
                1,
                1,
                "more than one YAML document (`---`): a machine file is one document",
            )));
        }
        let root = doc.and_then(|d| d.as_mapping()).map(YamlNode::Mapping);
        let kind = root
            .as_ref()
            .and_then(|r| child(r, &Seg::Key("kind".into())))
            .as_ref()
            .and_then(key_text);
        if let Some(r) = &root {
            check_tree(text, file, r)?;
        }
        Ok(Source {
            text,
            file,
            kind,
            mapping: root.is_some(),
        })
    }

    /// The text.
    pub fn text(&self) -> &'a str {
        self.text
    }

    /// How errors name the file.
    pub fn file(&self) -> &'a str {
        self.file
    }

    /// The top-level `kind` as written, when the document is a mapping
    /// that has one.
    pub fn kind(&self) -> Option<&str> {
        self.kind.as_deref()
    }

    /// Whether the document is a mapping.
    pub fn is_mapping(&self) -> bool {
        self.mapping
    }

    /// The typed pass: deserializes the text into `T`, reporting
    /// `file:line:column: key.path: message` on failure (unknown keys,
    /// wrong types, missing keys).
    pub fn deserialize<T: DeserializeOwned>(&self) -> Result<T, Error> {
        typed(self.text, self.file)
    }
}

/// Reads `text` ([`Source::read`]) and deserializes it into `T`, reporting
/// `file:line:column: key.path: message` on failure (unknown keys, wrong
/// types, missing keys, duplicate keys, nesting deeper than
/// [`limits::YAML_MAX_DEPTH`]).
pub fn deserialize<T: DeserializeOwned>(text: &str, file: &str) -> Result<T, Error> {
    Source::read(text, file)?.deserialize()
}

/// A located machine-file error at byte `offset` of `text`.
fn at(text: &str, file: &str, offset: usize, message: String) -> Error {
    let (line, column) = line_col(text, offset);
    Error::Machine(Located::new(file, line, column, message))
}

/// 1-based line and column (in characters) of byte `offset`.
fn line_col(text: &str, offset: usize) -> (usize, usize) {
    let mut offset = offset.min(text.len());
    while !text.is_char_boundary(offset) {
        offset -= 1;
    }
    let start = text[..offset].rfind('\n').map_or(0, |i| i + 1);
    (
        text[..offset].matches('\n').count() + 1,
        text[start..offset].chars().count() + 1,
    )
}

/// One walk of the tree: a key twice in one mapping, an alias or a tag is
/// refused with its key path.
fn check_tree(text: &str, file: &str, root: &YamlNode) -> Result<(), Error> {
    let mut stack = vec![(String::new(), root.clone())];
    while let Some((path, n)) = stack.pop() {
        let what = match &n {
            YamlNode::Alias(_) => Some(
                "an alias (`*name`), which `calibrate` and `diagnose --write-model` could not write back (the anchored value would change with it); write the value out",
            ),
            YamlNode::TaggedNode(_) => Some(
                "a tagged value (`!tag`), which `calibrate` and `diagnose --write-model` could not write back; write the plain value",
            ),
            _ => None,
        };
        if let Some(what) = what {
            let shown = if path.is_empty() { "." } else { &path };
            return Err(at(text, file, range(&n).0, format!("{shown}: {what}")));
        }
        match &n {
            YamlNode::Mapping(m) => {
                let mut seen = BTreeSet::new();
                let mut children = Vec::new();
                for e in m.entries() {
                    let key = e.key_node();
                    let k = key.as_ref().and_then(key_text).unwrap_or_default();
                    if !seen.insert(k.clone()) {
                        let off = key.as_ref().map_or(range(&n).0, |k| range(k).0);
                        let msg =
                            format!("duplicate key `{k}`: a key may appear once in a mapping");
                        let msg = if path.is_empty() {
                            msg
                        } else {
                            format!("{path}: {msg}")
                        };
                        return Err(at(text, file, off, msg));
                    }
                    let p = if path.is_empty() {
                        k
                    } else {
                        format!("{path}.{k}")
                    };
                    if let Some(v) = e.value_node() {
                        children.push((p, v));
                    }
                }
                // Depth first in file order: the first problem is reported.
                stack.extend(children.into_iter().rev());
            }
            YamlNode::Sequence(s) => {
                let items: Vec<_> = s
                    .values()
                    .enumerate()
                    .map(|(i, v)| (format!("{path}[{i}]"), v))
                    .collect();
                stack.extend(items.into_iter().rev());
            }
            _ => {}
        }
    }
    Ok(())
}

/// One step of a key path.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Seg {
    /// A mapping key.
    Key(String),
    /// A sequence item by position.
    Index(usize),
    /// The sequence item whose `name` is this (`axes[X]`).
    Name(String),
}

/// Splits `a.b[2].c` / `axes[X].e` into steps.
pub(crate) fn segs(path: &str) -> Vec<Seg> {
    let mut out = Vec::new();
    for part in path.split('.').filter(|p| !p.is_empty()) {
        let (key, mut rest) = part.split_at(part.find('[').unwrap_or(part.len()));
        if !key.is_empty() {
            out.push(Seg::Key(key.to_string()));
        }
        while let Some(s) = rest.strip_prefix('[') {
            let end = s.find(']').unwrap_or(s.len());
            let inner = &s[..end];
            out.push(match inner.parse::<usize>() {
                Ok(n) => Seg::Index(n),
                Err(_) => Seg::Name(inner.to_string()),
            });
            rest = s.get(end + 1..).unwrap_or("");
        }
    }
    out
}

/// The root mapping of `text`, when it parses as one YAML tree whose
/// document is a mapping; else the reason.
pub(crate) fn tree_root(text: &str) -> Result<YamlNode, String> {
    let parsed = YamlFile::parse(text);
    if let Some(e) = parsed.positioned_errors().first() {
        return Err(format!(
            "the file does not read as a YAML tree: {}",
            e.message
        ));
    }
    let mut docs = parsed.tree().documents();
    let doc = docs.next().ok_or("the file has no document")?;
    if docs.next().is_some() {
        return Err("the file has more than one document".into());
    }
    doc.as_mapping()
        .map(YamlNode::Mapping)
        .ok_or_else(|| "the document is not a mapping".into())
}

/// The text of a scalar key or value, unquoted.
pub(crate) fn key_text(k: &YamlNode) -> Option<String> {
    k.as_scalar().map(|s| s.as_string())
}

/// The child of `n` that `seg` names.
pub(crate) fn child(n: &YamlNode, seg: &Seg) -> Option<YamlNode> {
    match seg {
        Seg::Key(k) => n
            .as_mapping()?
            .entries()
            .find(|e| e.key_node().as_ref().and_then(key_text).as_deref() == Some(k))?
            .value_node(),
        Seg::Index(i) => n.as_sequence()?.get(*i),
        Seg::Name(name) => n.as_sequence()?.values().find(|item| {
            item.get("name")
                .as_ref()
                .and_then(key_text)
                .is_some_and(|s| s == *name)
        }),
    }
}

/// Byte range of a node in its text.
pub(crate) fn range(n: &YamlNode) -> (usize, usize) {
    let r = n.byte_range();
    (r.start as usize, r.end as usize)
}

/// The typed pass of [`Source::deserialize`].
fn typed<T: DeserializeOwned>(text: &str, file: &str) -> Result<T, Error> {
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
/// `axes[1].component_errors.EXX` in machine YAML text, on its syntax tree:
/// the key of a mapping entry, the dash of a block-list item (the item
/// itself in a flow list). Returns the deepest part of the path that could
/// be found; `None` when not even its first step is there (or the text is
/// not one YAML tree).
pub fn locate(text: &str, path: &str) -> Option<(usize, usize)> {
    let mut n = tree_root(text).ok()?;
    let mut found = None;
    for seg in segs(path) {
        let at = match &seg {
            Seg::Key(k) => n.as_mapping().and_then(|m| {
                m.entries()
                    .find(|e| e.key_node().as_ref().and_then(key_text).as_deref() == Some(k))
                    .and_then(|e| e.key_node())
                    .map(|k| range(&k).0)
            }),
            _ => child(&n, &seg).map(|item| {
                let start = range(&item).0;
                let before = text[..start].trim_end_matches(' ');
                if before.ends_with('-') {
                    before.len() - 1
                } else {
                    start
                }
            }),
        };
        let Some(at) = at else {
            break;
        };
        found = Some(line_col(text, at));
        match child(&n, &seg) {
            Some(next) => n = next,
            None => break,
        }
    }
    found
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
