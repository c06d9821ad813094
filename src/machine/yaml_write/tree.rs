//! The machine-file writer on the syntax tree: the file is parsed into a
//! lossless tree (the `yaml-edit` crate, on `rowan`: every byte, comment
//! and blank line is a token of the tree) and each edit splices the text
//! at the byte range of the node it changes — a scalar's token, a whole
//! value, or a new entry after the last one of a mapping or sequence. So
//! every layout the loader reads is written back with all its comments:
//! block lists (`- 1.0` on separate lines), flow lists and maps, nested
//! block maps, sequence items level with their key, quoted keys, comments
//! between items.
//!
//! A new value is written in the style of the mapping it goes into
//! ([`NewValue`]): under a block mapping, block lines at the indentation of
//! its siblings (`key:` with its entries one level deeper, a list of rows
//! as `- row` lines: the layout of the bundled files), the numbers of a
//! table and a row one-line flow lists and maps as there; in a flow
//! mapping, flow text. A comment that comes with a new entry goes above it
//! in a block parent, and after the file's leading comments in a flow one
//! (a comment cannot stand inside a flow collection on one line). A new
//! key of an existing mapping goes first in it (a location error, a
//! component table), after a named sibling or last; a mapping added on the
//! way to it (`component_errors` of an axis, a `thermal` section) after
//! the last key of its parent. An existing block collection written whole
//! is replaced by the block lines of the new value.
//!
//! The tree is the one the loader reads ([`crate::machine::yaml`]); what
//! this editor cannot write is refused there, when the file is loaded: an
//! alias (`*name`, editing the anchored value would change every alias of
//! it) and an explicit tag (`!!float 1`).

use yaml_edit::YamlNode;

use super::{Edit, LETTERS, NewValue, edit_err, number, round_to};
use crate::error::Result;
use crate::machine::robot::RobotParam;
use crate::machine::status::{self, Calibration, Status};
use crate::machine::tool::ToolParam;
use crate::machine::yaml::{self, Seg, child, key_text, range, segs};

/// The root mapping of `text`.
fn root(text: &str, file: &str) -> Result<YamlNode> {
    yaml::tree_root(text).map_err(|e| edit_err(file, e))
}

fn find(text: &str, file: &str, path: &[Seg]) -> Result<Option<YamlNode>> {
    let mut n = root(text, file)?;
    for s in path {
        match child(&n, s) {
            Some(c) => n = c,
            None => return Ok(None),
        }
    }
    Ok(Some(n))
}

fn is_block(n: &YamlNode) -> bool {
    match n {
        YamlNode::Mapping(m) => !m.is_flow_style(),
        YamlNode::Sequence(s) => !s.is_flow_style(),
        _ => false,
    }
}

/// The end of the last value written in `n` (a block collection's range
/// runs on over the comments and blank lines after it).
fn content_end(n: &YamlNode) -> usize {
    let last = match n {
        YamlNode::Mapping(m) if !m.is_flow_style() => {
            m.entries().last().and_then(|e| match e.value_node() {
                Some(v) if range(&v).1 > range(&v).0 => Some(content_end(&v)),
                _ => e.key_node().map(|k| range(&k).1),
            })
        }
        YamlNode::Sequence(s) if !s.is_flow_style() => s.values().last().map(|v| content_end(&v)),
        _ => None,
    };
    let (start, end) = range(n);
    last.unwrap_or(end).max(start)
}

fn line_start(text: &str, at: usize) -> usize {
    text[..at].rfind('\n').map_or(0, |i| i + 1)
}

/// The end of the line of `at`, before its `\n` (or `\r\n`).
fn line_end(text: &str, at: usize) -> usize {
    let end = text[at..].find('\n').map_or(text.len(), |i| at + i);
    if end > at && text.as_bytes()[end - 1] == b'\r' {
        end - 1
    } else {
        end
    }
}

fn splice(text: &str, from: usize, to: usize, new: &str) -> String {
    format!("{}{new}{}", &text[..from], &text[to..])
}

/// Replaces the value at `path` by `new` (flow text): a scalar's token, a
/// flow collection, or a block collection from its first to its last value.
fn set(text: &str, file: &str, path: &str, new: &str) -> Result<String> {
    let n = find(text, file, &segs(path))?
        .ok_or_else(|| edit_err(file, format!("no value at `{path}`")))?;
    let (start, end) = range(&n);
    match &n {
        YamlNode::Alias(_) | YamlNode::TaggedNode(_) => Err(edit_err(
            file,
            format!("`{path}` is an alias or a tagged value"),
        )),
        YamlNode::Scalar(s) if s.is_block() => Err(edit_err(
            file,
            format!("`{path}` is a block scalar (`|`, `>`)"),
        )),
        _ if is_block(&n) => Ok(splice(text, start, content_end(&n), new)),
        _ => Ok(splice(text, start, end, new)),
    }
}

/// Where a new key goes among its siblings.
#[derive(Clone, Copy)]
enum At<'a> {
    First,
    After(&'a str),
    Last,
}

/// Adds `key: new` to the mapping at `path` (`comment`, when not empty,
/// on comment lines above it), before or after its siblings as `at` says
/// (the last one when the key `at` names is not there). `new` is written
/// in the style of the mapping ([`NewValue`]).
fn insert(
    text: &str,
    file: &str,
    path: &str,
    key: &str,
    new: &NewValue,
    at: At,
    comment: &str,
) -> Result<String> {
    let n = find(text, file, &segs(path))?
        .ok_or_else(|| edit_err(file, format!("no mapping at `{path}`")))?;
    let m = n
        .as_mapping()
        .ok_or_else(|| edit_err(file, format!("`{path}` is not a mapping")))?;
    let entries: Vec<_> = m.entries().collect();
    let after_entry = |e: &yaml_edit::MappingEntry| match e.value_node() {
        Some(v) if range(&v).1 > range(&v).0 => content_end(&v),
        _ => e.key_node().map_or(range(&n).0, |k| range(&k).1),
    };
    let named = |k: &str| {
        entries
            .iter()
            .find(|e| e.key_node().as_ref().and_then(key_text).as_deref() == Some(k))
    };
    if m.is_flow_style() {
        let edited = with_header_comment(text, comment);
        // The comment lines, when added, come before the mapping.
        let shift = edited.len() - text.len();
        let body = format!("{key}: {}", new.flow());
        let (start, end) = range(&n);
        let (start, end) = (start + shift, end + shift);
        return Ok(match (entries.last(), at) {
            (None, _) => splice(&edited, start, end, &format!("{{ {body} }}")),
            (Some(_), At::First) => splice(&edited, start + 1, start + 1, &format!(" {body},")),
            (Some(last), _) => {
                let e = match at {
                    At::After(k) => named(k).unwrap_or(last),
                    _ => last,
                };
                let p = after_entry(e) + shift;
                splice(&edited, p, p, &format!(", {body}"))
            }
        });
    }
    let first_key = entries
        .first()
        .and_then(|e| e.key_node())
        .map_or(range(&n).0, |k| range(&k).0);
    let indent = " ".repeat(first_key - line_start(text, first_key));
    let mut lines = comment_lines(comment, &indent);
    new.block(key, &indent, &mut lines);
    let eol = eol_of(text);
    let block = lines.join(eol);
    let own_line = text[line_start(text, first_key)..first_key]
        .trim()
        .is_empty();
    let target = match at {
        At::First if own_line && !entries.is_empty() => None,
        At::First => entries.first(),
        At::After(k) => named(k).or(entries.last()),
        At::Last => entries.last(),
    };
    Ok(match target {
        None => {
            let p = line_start(text, first_key);
            splice(text, p, p, &format!("{block}{eol}"))
        }
        Some(e) => {
            let p = line_end(text, after_entry(e));
            splice(text, p, p, &format!("{eol}{block}"))
        }
    })
}

/// `comment` as comment lines (`# …`, one per line of it) at `indent`.
fn comment_lines(comment: &str, indent: &str) -> Vec<String> {
    comment
        .lines()
        .map(|l| match l.trim_end() {
            "" => format!("{indent}#"),
            l => format!("{indent}# {l}"),
        })
        .collect()
}

/// The line ending of `text`: `\r\n` when it has one, else `\n`.
fn eol_of(text: &str) -> &'static str {
    if text.contains("\r\n") { "\r\n" } else { "\n" }
}

/// `text` with the lines of `comment` (`# …`) after its leading comment
/// lines.
fn with_header_comment(text: &str, comment: &str) -> String {
    let lines = comment_lines(comment, "");
    if lines.is_empty() {
        return text.to_string();
    }
    let eol = eol_of(text);
    let at = header_end(text);
    splice(text, at, at, &format!("{}{eol}", lines.join(eol)))
}

/// The byte offset after the file's leading comment and blank lines.
fn header_end(text: &str) -> usize {
    let mut at = 0;
    for line in text.split_inclusive('\n') {
        if line.starts_with('#') || line.trim().is_empty() {
            at += line.len();
        } else {
            break;
        }
    }
    at
}

/// Appends `item` (flow text) to the sequence at `path`.
fn push(text: &str, file: &str, path: &str, item: &str) -> Result<String> {
    let n = find(text, file, &segs(path))?
        .ok_or_else(|| edit_err(file, format!("no list at `{path}`")))?;
    let s = n
        .as_sequence()
        .ok_or_else(|| edit_err(file, format!("`{path}` is not a list")))?;
    let (start, end) = range(&n);
    let last = s.values().last();
    Ok(match (last, s.is_flow_style()) {
        (None, _) => splice(text, start, end, &format!("[{item}]")),
        (Some(v), true) => {
            let p = range(&v).1;
            splice(text, p, p, &format!(", {item}"))
        }
        (Some(v), false) => {
            let indent = " ".repeat(start - line_start(text, start));
            let p = line_end(text, content_end(&v));
            splice(text, p, p, &format!("\n{indent}- {item}"))
        }
    })
}

/// Replaces the value at `path` by `new`: a block collection under a key
/// of a block mapping by the block lines of `new` (from the key's line to
/// the last line of the old value), anything else by `new`'s flow text.
fn replace(text: &str, file: &str, path: &str, new: &NewValue) -> Result<String> {
    let all = segs(path);
    let n =
        find(text, file, &all)?.ok_or_else(|| edit_err(file, format!("no value at `{path}`")))?;
    let (Some(Seg::Key(k)), true, false) =
        (all.last(), is_block(&n), matches!(new, NewValue::Text(_)))
    else {
        return set(text, file, path, &new.flow());
    };
    let parent = find(text, file, &all[..all.len() - 1])?;
    let key = parent.as_ref().and_then(|p| p.as_mapping()).and_then(|m| {
        m.entries()
            .find(|e| e.key_node().as_ref().and_then(key_text).as_deref() == Some(k))
            .and_then(|e| e.key_node())
    });
    let Some(key) = key else {
        return set(text, file, path, &new.flow());
    };
    let (ks, ke) = range(&key);
    let ls = line_start(text, ks);
    if !text[ls..ks].trim().is_empty() {
        return set(text, file, path, &new.flow());
    }
    let mut lines = Vec::new();
    new.block(&text[ks..ke], &text[ls..ks], &mut lines);
    let end = line_end(text, content_end(&n));
    Ok(splice(text, ls, end, &lines.join(eol_of(text))))
}

/// Sets the value at `path` to `new`, adding the missing mapping keys on
/// the way: the key that holds `new` goes where `leaf` says among its
/// siblings, a new mapping on the way after the last key of its parent;
/// `comment` goes above the first key added.
fn set_or_add(
    text: &str,
    file: &str,
    path: &str,
    new: &NewValue,
    leaf: At,
    comment: &str,
) -> Result<String> {
    let all = segs(path);
    if find(text, file, &all)?.is_some() {
        return replace(text, file, path, new);
    }
    let mut have = all.len();
    while have > 0 && find(text, file, &all[..have])?.is_none() {
        have -= 1;
    }
    let missing = &all[have..];
    let keys: Vec<&str> = missing
        .iter()
        .map(|s| match s {
            Seg::Key(k) => Ok(k.as_str()),
            _ => Err(edit_err(file, format!("no list item for `{path}`"))),
        })
        .collect::<Result<_>>()?;
    let mut value = new.clone();
    for k in keys[1..].iter().rev() {
        value = NewValue::Map(vec![((*k).to_string(), value)]);
    }
    let at = if keys.len() == 1 { leaf } else { At::Last };
    let parent = path_text(&all[..have]);
    insert(text, file, &parent, keys[0], &value, at, comment)
}

fn path_text(segs: &[Seg]) -> String {
    let mut s = String::new();
    for seg in segs {
        match seg {
            Seg::Key(k) => {
                if !s.is_empty() {
                    s.push('.');
                }
                s.push_str(k);
            }
            Seg::Index(i) => s.push_str(&format!("[{i}]")),
            Seg::Name(n) => s.push_str(&format!("[{n}]")),
        }
    }
    s
}

/// The scalar texts of the mapping at `path` as a flow map, in file order.
fn flow_copy(text: &str, file: &str, path: &str) -> Result<String> {
    let n = find(text, file, &segs(path))?
        .ok_or_else(|| edit_err(file, format!("no mapping at `{path}`")))?;
    let m = n
        .as_mapping()
        .ok_or_else(|| edit_err(file, format!("`{path}` is not a mapping")))?;
    let mut pairs = Vec::new();
    for e in m.entries() {
        let k = e.key_node().as_ref().and_then(key_text);
        let v = e.value_node();
        match (k, v) {
            (Some(k), Some(v @ YamlNode::Scalar(_))) => {
                let (a, b) = range(&v);
                pairs.push(format!("{k}: {}", &text[a..b]));
            }
            _ => {
                return Err(edit_err(
                    file,
                    format!("`{path}` has a value that is not a number"),
                ));
            }
        }
    }
    Ok(format!("{{ {} }}", pairs.join(", ")))
}

fn has(text: &str, file: &str, path: &str) -> Result<bool> {
    Ok(find(text, file, &segs(path))?.is_some())
}

/// The number at `path` as written, `0.0` when absent.
fn number_text(text: &str, file: &str, path: &str) -> Result<String> {
    Ok(match find(text, file, &segs(path))? {
        Some(n @ YamlNode::Scalar(_)) => {
            let (a, b) = range(&n);
            text[a..b].to_string()
        }
        _ => "0.0".into(),
    })
}

fn robot(text: &str, file: &str, by: &str, p: RobotParam, v: f64) -> Result<String> {
    let mut t = text.to_string();
    match p {
        RobotParam::Dh { .. } if !has(&t, file, "actual")? => {
            let n = find(&t, file, &segs("nominal"))?
                .and_then(|n| n.as_sequence().map(|s| s.len()))
                .ok_or_else(|| edit_err(file, "no `nominal` list to copy into `actual`"))?;
            let rows = (0..n)
                .map(|j| flow_copy(&t, file, &format!("nominal[{j}]")))
                .collect::<Result<Vec<_>>>()?;
            let comment = format!("Identified by `{by}`.");
            t = insert(
                &t,
                file,
                "",
                "actual",
                &NewValue::Rows(rows),
                At::After("nominal"),
                &comment,
            )?;
        }
        RobotParam::ToolOffset { .. } if !has(&t, file, "flange_to_tool")? => {
            let new = NewValue::Text("{ x_mm: 0.0, y_mm: 0.0, z_mm: 0.0 }".into());
            t = insert(&t, file, "", "flange_to_tool", &new, At::Last, "")?;
        }
        RobotParam::PayloadMass if !has(&t, file, "tool_load")? => {
            let c = |k: &str| number_text(&t, file, &format!("flange_to_tool.{k}"));
            let new = NewValue::Text(format!(
                "{{ mass_kg: 0.0, cog_mm: [{}, {}, {}] }}",
                c("x_mm")?,
                c("y_mm")?,
                c("z_mm")?
            ));
            t = insert(&t, file, "", "tool_load", &new, At::Last, "")?;
        }
        _ => {}
    }
    set(&t, file, &p.path(), &number(v))
}

fn tool(text: &str, file: &str, p: ToolParam, v: f64) -> Result<String> {
    match p {
        ToolParam::Component { .. } => Err(edit_err(
            file,
            format!(
                "`{}`: a component table is written whole, positions and both columns",
                p.path()
            ),
        )),
        ToolParam::Stiffness {
            cell: Some([iz, iy, ix]),
            ..
        } => set(
            text,
            file,
            &format!("{}[{iz}][{iy}][{ix}]", p.path()),
            &number(v),
        ),
        ToolParam::Location { .. } | ToolParam::SpindleLocation { .. } => {
            let new = NewValue::Text(number(v));
            set_or_add(text, file, &p.path(), &new, At::First, "")
        }
        _ => set(text, file, &p.path(), &number(v)),
    }
}

fn list(v: &[f64]) -> String {
    let items: Vec<String> = v.iter().map(|x| number(*x)).collect();
    format!("[{}]", items.join(", "))
}

/// Whether the table at `path` has exactly the lists `columns` name, each
/// of their length (so that it can be written number by number, the
/// comments between the numbers kept).
fn same_shape(text: &str, file: &str, path: &str, columns: &[(&str, &[f64]); 3]) -> Result<bool> {
    let Some(n) = find(text, file, &segs(path))? else {
        return Ok(false);
    };
    let Some(m) = n.as_mapping() else {
        return Ok(false);
    };
    if m.entries().count() != columns.len() {
        return Ok(false);
    }
    Ok(columns.iter().all(|(key, values)| {
        child(&n, &Seg::Key((*key).into()))
            .and_then(|l| l.as_sequence().map(|s| s.len()))
            .is_some_and(|len| len == values.len())
    }))
}

/// Writes the lists of the table at `path` number by number.
fn set_lists(text: &str, file: &str, path: &str, columns: &[(&str, &[f64]); 3]) -> Result<String> {
    let mut t = text.to_string();
    for (key, values) in columns {
        for (i, v) in values.iter().enumerate() {
            t = set(&t, file, &format!("{path}.{key}[{i}]"), &number(*v))?;
        }
    }
    Ok(t)
}

/// Writes a component table of axis slot `axis`, error direction `error`
/// (`columns`: positions, forward, reverse): number by number when the
/// file's table has the same shape, else whole (added first in the axis's
/// `component_errors`, or with that mapping after the axis's last key).
fn component_table(
    text: &str,
    file: &str,
    axis: usize,
    error: usize,
    columns: [&[f64]; 3],
) -> Result<String> {
    let l = |s: usize| LETTERS.get(s).copied().unwrap_or('?');
    let unit = if error < 3 { "um" } else { "urad" };
    let path = format!(
        "axes[{}].component_errors.E{}{}_{unit}",
        l(axis),
        l(error),
        l(axis)
    );
    // Rotary axes (A, B, C) give their positions in degrees.
    let pos = if axis < 3 {
        "positions_mm"
    } else {
        "positions_deg"
    };
    let columns = [
        (pos, columns[0]),
        ("forward", columns[1]),
        ("reverse", columns[2]),
    ];
    if same_shape(text, file, &path, &columns)? {
        return set_lists(text, file, &path, &columns);
    }
    let table = NewValue::Map(
        columns
            .iter()
            .map(|(k, v)| ((*k).to_string(), NewValue::Text(list(v))))
            .collect(),
    );
    set_or_add(text, file, &path, &table, At::First, "")
}

/// Applies one edit to `text`.
fn one(text: &str, file: &str, by: &str, edit: &Edit) -> Result<String> {
    match edit {
        Edit::Robot(p, v) => robot(text, file, by, *p, *v),
        Edit::Tool(p, v) => tool(text, file, *p, *v),
        Edit::ComponentTable {
            axis,
            error,
            positions,
            forward,
            reverse,
        } => component_table(text, file, *axis, *error, [positions, forward, reverse]),
        Edit::ThermalTerm {
            term,
            time_constant_min,
            comment,
        } => {
            let item = super::term_flow(term);
            if has(text, file, "thermal.terms")? {
                push(text, file, "thermal.terms", &item)
            } else if has(text, file, "thermal")? {
                let new = NewValue::Rows(vec![item]);
                insert(text, file, "thermal", "terms", &new, At::Last, "")
            } else {
                let new = NewValue::Map(vec![
                    (
                        "time_constant_min".into(),
                        NewValue::Text(number(*time_constant_min)),
                    ),
                    ("terms".into(), NewValue::Rows(vec![item])),
                ]);
                insert(text, file, "", "thermal", &new, At::Last, comment)
            }
        }
        Edit::RatedPower { watts, comment } => {
            if !has(text, file, "thermal")? {
                return Err(edit_err(file, "no `thermal:` section for `rated_power_w`"));
            }
            if has(text, file, "thermal.rated_power_w")? {
                return set(text, file, "thermal.rated_power_w", &number(*watts));
            }
            let new = NewValue::Text(number(*watts));
            let at = At::After("time_constant_min");
            insert(text, file, "thermal", "rated_power_w", &new, at, comment)
        }
        Edit::Spindle {
            growth_um_per_kw,
            time_constant_min,
            comment,
        } => {
            if has(text, file, "thermal.spindle")? {
                return Err(edit_err(file, "`thermal.spindle` is already in the file"));
            }
            let spindle = format!(
                "{{ idle_w_per_rpm: 0.0, growth_um_per_kw: {}, time_constant_min: {} }}",
                number(*growth_um_per_kw),
                number(*time_constant_min)
            );
            if has(text, file, "thermal")? {
                let new = NewValue::Text(spindle);
                insert(text, file, "thermal", "spindle", &new, At::First, comment)
            } else {
                let new = NewValue::Map(vec![("spindle".into(), NewValue::Text(spindle))]);
                insert(text, file, "", "thermal", &new, At::Last, comment)
            }
        }
        Edit::MeasurementFrame { xyz_mm, rpy_deg } => {
            let frame = format!(
                "{{ x_mm: {}, y_mm: {}, z_mm: {}, rpy_deg: [{}, {}, {}] }}",
                number(round_to(xyz_mm[0], 4)),
                number(round_to(xyz_mm[1], 4)),
                number(round_to(xyz_mm[2], 4)),
                number(round_to(rpy_deg[0], 6)),
                number(round_to(rpy_deg[1], 6)),
                number(round_to(rpy_deg[2], 6))
            );
            if has(text, file, "measurement_frame")? {
                return set(text, file, "measurement_frame", &frame);
            }
            let comment = "Pose of the measuring instrument in the machine's reference frame,\n\
                           identified by `postproc calibrate` or `diagnose` from `# frame: instrument`\n\
                           observations (docs/frames.md). Not part of the model.";
            let new = NewValue::Text(frame);
            insert(text, file, "", "measurement_frame", &new, At::Last, comment)
        }
        Edit::Calibrated(c) => calibrated(text, file, c),
        Edit::HeaderComment(c) => {
            let at = header_end(text);
            let eol = eol_of(text);
            let text = if at == text.len() && !text.is_empty() && !text.ends_with('\n') {
                format!("{text}{eol}")
            } else {
                text.to_string()
            };
            Ok(splice(&text, at, at, &format!("# {c}{eol}")))
        }
        Edit::Section {
            path,
            value,
            comment,
        } => set_or_add(text, file, path, value, At::Last, comment),
    }
}

/// Sets the top-level `status` to `value` (flow text). An existing value
/// is replaced with the comment after it on its line (it is about the old
/// word), by `note` when the mapping is in block style (`note` is the text
/// after the value: `   # …`); a new key goes after `name` (`kind` when
/// the file has no `name`).
pub(crate) fn set_status(text: &str, file: &str, value: &str, note: &str) -> Result<String> {
    let root = root(text, file)?;
    let flow = root.as_mapping().is_some_and(|m| m.is_flow_style());
    let note = if flow { "" } else { note };
    if let Some(n) = child(&root, &Seg::Key("status".into())) {
        let (start, end) = range(&n);
        let eol = line_end(text, end);
        let rest = text[end..eol].trim_start();
        if !is_block(&n) && (rest.is_empty() || rest.starts_with('#')) {
            return Ok(splice(text, start, eol, &format!("{value}{note}")));
        }
        return set(text, file, "status", value);
    }
    let after = if has(text, file, "name")? {
        "name"
    } else {
        "kind"
    };
    let new = NewValue::Text(format!("{value}{note}"));
    insert(text, file, "", "status", &new, At::After(after), "")
}

/// `status: calibrated` and one more `calibrations` entry, checked by
/// reading the status back.
fn calibrated(text: &str, file: &str, c: &Calibration) -> Result<String> {
    let mut t = set_status(text, file, "calibrated", "")?;
    let entry = status::calibration_flow(c);
    t = if has(&t, file, "calibrations")? {
        push(&t, file, "calibrations", &entry)?
    } else {
        let new = NewValue::Rows(vec![entry]);
        insert(&t, file, "", "calibrations", &new, At::After("status"), "")?
    };
    match Status::from_yaml_str(&t, file)? {
        Status::Calibrated(list) if list.last() == Some(&status::as_written(c)) => Ok(t),
        _ => Err(edit_err(
            file,
            "the edited `status`/`calibrations` keys do not read back",
        )),
    }
}

/// Applies `edits` in order to `text` on its syntax tree (see the module
/// comment).
pub(super) fn apply(text: &str, file: &str, by: &str, edits: &[Edit]) -> Result<String> {
    let mut t = text.to_string();
    for e in edits {
        t = one(&t, file, by, e)?;
    }
    Ok(t)
}

#[cfg(test)]
mod tests {
    use super::super::{Edit, ThermalTermText, apply};
    use super::*;
    use crate::machine::Machine;
    use crate::machine::robot::{DhField, Robot, ThermalField};
    use crate::machine::tool::{LocationParam, MachineTool};

    fn bundled(name: &str) -> String {
        let path = format!("{}/machines/{name}", env!("CARGO_MANIFEST_DIR"));
        std::fs::read_to_string(path).expect("bundled file")
    }

    fn robot(text: &str) -> Robot {
        match Machine::from_yaml_str(text, "r.yaml").expect("valid") {
            Machine::Robot(r) => r,
            Machine::Tool(_) => panic!("robot file"),
        }
    }

    fn tool(text: &str) -> MachineTool {
        match Machine::from_yaml_str(text, "t.yaml").expect("valid") {
            Machine::Tool(t) => t,
            Machine::Robot(_) => panic!("machine-tool file"),
        }
    }

    /// Every comment line of `before` is in `after`.
    fn comments_kept(before: &str, after: &str) {
        for l in before.lines().filter(|l| l.trim_start().starts_with('#')) {
            assert!(after.contains(l), "comment `{l}` lost:\n{after}");
        }
    }

    /// The IRB 1600 file with `k_nm_per_rad` and `actual` as block lists
    /// (one number or one block map per line, comments between items),
    /// `flange_to_tool` as a block map and a quoted key.
    fn irb1600_block() -> String {
        let text = bundled("abb-irb1600.yaml");
        let k = text
            .lines()
            .find(|l| l.starts_with("k_nm_per_rad:"))
            .expect("k line");
        let values: Vec<&str> = k
            .split_once('[')
            .and_then(|(_, r)| r.split_once(']'))
            .map(|(v, _)| v.split(", ").collect())
            .expect("flow list");
        let mut block = String::from("k_nm_per_rad:   # joint stiffness, block style\n");
        for (j, v) in values.iter().enumerate() {
            block.push_str(&format!("  # joint {}\n  - {v}  # J{}\n", j + 1, j + 1));
        }
        let tcp = text
            .lines()
            .find(|l| l.starts_with("flange_to_tool:"))
            .expect("tcp line");
        let out = text.replacen(&format!("{k}\n"), &block, 1).replacen(
            &format!("{tcp}\n"),
            "\"flange_to_tool\":\n  x_mm: 0.0   # tcp x\n  y_mm: 0.0\n  # between keys\n  z_mm: 150.0\n  quaternion: [1.0, 0.0, 0.0, 0.0]\n",
            1,
        );
        assert_ne!(out, text);
        out
    }

    /// The case: a robot whose `k_nm_per_rad` is a block list loads
    /// (so `check` passes), and the stiffness, TCP and DH values of a
    /// calibration are written back with every comment kept; the robot
    /// read back equals `with_params` of the same edits.
    #[test]
    fn block_lists_are_written_back_with_their_comments() {
        let text = irb1600_block();
        let before = robot(&text);
        let edits = [
            (RobotParam::JointStiffness { joint: 0 }, 271_000.5),
            (RobotParam::JointStiffness { joint: 5 }, 5_400.25),
            (RobotParam::ToolOffset { axis: 2 }, 151.125),
            (
                RobotParam::Dh {
                    joint: 1,
                    field: DhField::A,
                },
                150.05,
            ),
        ];
        let typed: Vec<Edit> = edits.iter().map(|&(p, v)| Edit::Robot(p, v)).collect();
        let out = apply(&text, "r.yaml", "test", &typed).expect("written");
        comments_kept(&text, &out);
        assert!(out.contains("  # joint 1\n  - 271000.5  # J1\n"), "{out}");
        assert!(out.contains("  - 5400.25  # J6\n"), "{out}");
        assert!(out.contains("  z_mm: 151.125\n"), "{out}");
        assert_eq!(out.lines().count(), text.lines().count());
        let want = before.with_params(&edits).expect("valid");
        assert_eq!(format!("{:?}", robot(&out)), format!("{want:?}"));
    }

    /// The same file in the layout a YAML library writes (keys sorted,
    /// items level with their key, no comments) and all in flow style on
    /// one line: the structural edits (a new `actual`, a thermal term, a
    /// rated power, the frame, the calibration record) are made and read
    /// back.
    #[test]
    fn structural_robot_edits_in_other_layouts() {
        let text = bundled("abb-irb1600.yaml");
        let start = text.find("\nactual:").expect("actual") + 1;
        let end = start
            + text[start..]
                .match_indices('\n')
                .nth(6)
                .map(|(i, _)| i + 1)
                .expect("rows");
        let bare = format!("{}{}", &text[..start], &text[end..]);
        let v: serde_yaml::Value = serde_yaml::from_str(&bare).expect("yaml");
        let library = serde_yaml::to_string(&v).expect("layout");
        let flow = serde_json::to_string(&v).expect("flow");
        let term = ThermalTermText {
            parameter: "a3".into(),
            joint: 2,
            lb_mm: 300.0,
            ub_mm: 300.0,
            ts_per_w: 1e-6,
        };
        let cal = Calibration {
            date: "2026-11-25".into(),
            kind: "kinematics".into(),
            observations: "poses.csv".into(),
            observations_sha256: "ab".repeat(32),
            rows: 40,
            fit_rms_mm: 0.0125,
        };
        let dh = RobotParam::Dh {
            joint: 2,
            field: DhField::D,
        };
        let edits = vec![
            Edit::Robot(dh, 0.5),
            Edit::ThermalTerm {
                term,
                time_constant_min: 30.0,
                comment: "added".into(),
            },
            Edit::RatedPower {
                watts: 450.0,
                comment: "assumed".into(),
            },
            Edit::MeasurementFrame {
                xyz_mm: [1.0, 2.0, 3.0],
                rpy_deg: [0.0, 0.5, 0.0],
            },
            Edit::Calibrated(cal.clone()),
        ];
        for layout in [library, flow] {
            let out = super::apply(&layout, "r.yaml", "test", &edits).expect("written");
            let r = robot(&out);
            let want = robot(&layout).with_params(&[(dh, 0.5)]).expect("valid");
            assert_eq!(r.param_value(dh), want.param_value(dh), "{out}");
            let terms = r.param_value(RobotParam::Thermal {
                term: 7,
                field: ThermalField::Ts,
            });
            assert_eq!(terms, Some(1e-6), "{out}");
            assert!(r.measurement_frame().is_some(), "{out}");
            match Status::from_yaml_str(&out, "r.yaml").expect("status") {
                Status::Calibrated(list) => assert_eq!(list, vec![cal.clone()]),
                other => panic!("{other:?}: {out}"),
            }
        }
    }

    /// Machine-tool edits on the AFM R-1000 file written with sequence
    /// items level with their key and block maps, comments between: a
    /// location error replaced and one added, a component table added, a
    /// spindle entry added; comments kept, the model read back equal to
    /// `with_params`.
    #[test]
    fn machine_tool_edits_in_a_block_layout_keep_comments() {
        let text = bundled("afm-r1000.yaml");
        let v: serde_yaml::Value = serde_yaml::from_str(&text).expect("yaml");
        let mut layout = String::from("# kept: head\n");
        for line in serde_yaml::to_string(&v).expect("layout").lines() {
            layout.push_str(line);
            layout.push('\n');
            if line.trim_start().starts_with("- name:") {
                layout.push_str("  # kept: an axis\n");
            }
        }
        let sq = |axis, r| ToolParam::Location {
            axis,
            error: LocationParam::Angle(r),
        };
        let edits = [(sq(1, 2), 75.25), (sq(2, 0), -3.5)];
        let mut typed: Vec<Edit> = edits.iter().map(|&(p, v)| Edit::Tool(p, v)).collect();
        typed.push(Edit::ComponentTable {
            axis: 2,
            error: 2,
            positions: vec![-300.0, 0.0],
            forward: vec![0.0, 1.5],
            reverse: vec![0.5, 2.0],
        });
        let out = super::apply(&layout, "t.yaml", "test", &typed).expect("written");
        comments_kept(&layout, &out);
        let read = tool(&out);
        let want = tool(&layout).with_params(&edits).expect("valid");
        assert_eq!(
            format!("{:?}", &read.axes()[..2]),
            format!("{:?}", &want.axes()[..2])
        );
        assert_eq!(
            read.component_table(2, 2).map(|t| t[1].to_vec()),
            Some(vec![0.0, 1.5]),
            "{out}"
        );
    }

    /// An alias is refused at load with its key path and line; a quoted key
    /// is read and written.
    #[test]
    fn aliases_are_refused_at_load_with_their_key_path() {
        let text = bundled("abb-irb1600.yaml").replacen(
            "k_nm_per_rad: [270990.0,",
            "k_nm_per_rad: [&k1 270990.0, *k1,",
            1,
        );
        let text = text.replacen(" 430040.0,", "", 1);
        let err = Machine::from_yaml_str(&text, "r.yaml")
            .expect_err("alias refused")
            .to_string();
        assert!(err.contains("k_nm_per_rad[1]: an alias"), "{err}");
        let line = text
            .lines()
            .position(|l| l.starts_with("k_nm_per_rad"))
            .expect("line")
            + 1;
        assert!(err.starts_with(&format!("r.yaml:{line}:")), "{err}");
    }

    /// Every machine file of the repository that loads is writable, and a
    /// value edit through the tree editor reads back.
    #[test]
    fn every_machine_file_of_the_repository_is_writable() {
        let root = env!("CARGO_MANIFEST_DIR");
        let mut seen = 0;
        for dir in [
            "machines",
            "samples",
            "samples/diagnose",
            "samples/observations",
        ] {
            let Ok(entries) = std::fs::read_dir(format!("{root}/{dir}")) else {
                continue;
            };
            for e in entries.flatten() {
                let p = e.path();
                if p.extension().is_none_or(|x| x != "yaml") {
                    continue;
                }
                let text = std::fs::read_to_string(&p).expect("text");
                let Ok(m) = Machine::from_yaml_str(&text, "f") else {
                    continue;
                };
                seen += 1;
                if let Machine::Robot(r) = m {
                    let p = RobotParam::JointStiffness { joint: 1 };
                    let v = round_to(r.param_value(p).expect("k2") * 1.01, 1);
                    let out = super::apply(&text, "f", "t", &[Edit::Robot(p, v)]).unwrap();
                    let want = r.with_params(&[(p, v)]).expect("valid");
                    assert_eq!(format!("{:?}", robot(&out)), format!("{want:?}"));
                }
            }
        }
        assert!(seen >= 20, "{seen}");
    }
}
