//! The one writer of machine files: a list of typed edits ([`Edit`]) —
//! values of the model by parameter id ([`ToolParam`], [`RobotParam`]) and
//! the few structural changes identification makes (a whole component
//! table, a new thermal term or spindle entry, the measurement frame, the
//! calibration record) — applied to the file *as text*. Every comment, the
//! key order and every byte the edits do not touch are kept.
//!
//! A model value is written exactly: the shortest decimal that reads back as
//! the same `f64` (`150.05`, `0.000001`, `3.0`), so the model read from the
//! written file equals [`crate::machine::tool::MachineTool::with_params`] or
//! [`crate::machine::robot::Robot::with_params`] of the same edits. The
//! resolution a value is written with is the caller's choice: it rounds the
//! value first ([`round_to`], [`round_sig`]).
//!
//! Two editors share the work. The line editor of this file edits the
//! layouts of the bundled machine files: top-level flow lists
//! (`k_nm_per_rad: [1, 2, 3]`), one-line flow maps (`flange_to_tool: { x_mm:
//! 0, … }`, `spindle: { … }`, thermal terms), DH sections written as block
//! lists of one-line flow maps (`actual:` followed by `  - { a_mm: …, … }`
//! rows) and machine-tool axis entries in block style (`- name: X` with
//! `component_errors:` / `location_errors:` maps); its output on those files
//! is what the snapshots and the tests below fix byte for byte. Every other
//! layout the loader reads — block lists of numbers, block maps, sequence
//! items level with their key, everything in flow style, quoted keys — is
//! edited on the file's lossless syntax tree ([`tree`]), with every comment
//! kept as well. Every edited model value is read back from the result.
//! The few layouts the tree editor does not write (aliases, tags) are
//! refused when the file is loaded ([`super::yaml::Source::read`]), never
//! after a fit.

use serde_yaml::Value;

use super::robot::{DhField, RobotParam, ThermalField};
use super::status::Calibration;
use super::tool::{LocationParam, ToolParam};
use crate::error::{Error, Result};

/// Axis and error-direction letters in slot order.
const LETTERS: [char; 6] = ['X', 'Y', 'Z', 'A', 'B', 'C'];

/// One change of a machine file.
#[derive(Debug, Clone, PartialEq)]
pub enum Edit {
    /// A value of a machine tool's model, in the unit of its key. A
    /// location error is added (with its section) when the file lacks it;
    /// component tables are written whole ([`Edit::ComponentTable`]).
    Tool(ToolParam, f64),
    /// A value of a robot's model, in the unit of its key. A DH edit in a
    /// file without `actual` adds the section (a copy of `nominal`) after
    /// the `nominal` rows.
    Robot(RobotParam, f64),
    /// A machine-tool component error table (positions and both columns,
    /// in the file's units), replaced or added with its section.
    ComponentTable {
        /// Axis slot 0..6.
        axis: usize,
        /// Error direction 0..6 (X Y Z translations, A B C rotations).
        error: usize,
        /// `positions_mm` (`positions_deg` for a rotary axis A, B, C).
        positions: Vec<f64>,
        /// `forward`.
        forward: Vec<f64>,
        /// `reverse`.
        reverse: Vec<f64>,
    },
    /// A new robot thermal term, appended to `thermal.terms` (a new
    /// `thermal:` section with `time_constant_min` when the file has none,
    /// preceded by `comment`).
    ThermalTerm {
        /// The term.
        term: ThermalTermText,
        /// `time_constant_min` of a new section.
        time_constant_min: f64,
        /// Comment line above a new section (empty: none).
        comment: String,
    },
    /// The robot's `thermal.rated_power_w` (the section must exist):
    /// replaced, or added after `time_constant_min` preceded by the
    /// comment line `comment` (empty: none).
    RatedPower {
        /// Highest mean motor power of a joint, W.
        watts: f64,
        /// Comment line above a new key.
        comment: String,
    },
    /// A new machine-tool `thermal.spindle` entry with
    /// `idle_w_per_rpm: 0.0` (in the `thermal:` section, or a new one),
    /// preceded by `comment`.
    Spindle {
        /// `growth_um_per_kw`.
        growth_um_per_kw: f64,
        /// `time_constant_min`.
        time_constant_min: f64,
        /// Comment line above the entry (empty: none).
        comment: String,
    },
    /// The top-level `measurement_frame` (the instrument's pose in the
    /// machine's reference frame; not part of the model), written with
    /// 0.1 µm and 10⁻⁶ degree resolution.
    MeasurementFrame {
        /// Translation, mm.
        xyz_mm: [f64; 3],
        /// Roll, pitch, yaw, degrees.
        rpy_deg: [f64; 3],
    },
    /// `status: calibrated` and one more entry of `calibrations`
    /// ([`set_calibrated`]).
    Calibrated(Calibration),
    /// A comment line `# …` added at the end of the file's leading comment
    /// block (after the comment lines added before it).
    HeaderComment(String),
    /// The value at the key path `path` (`thermal.spindle`,
    /// `axes[X].component_errors`, `covariance.kinematics`): replaced whole
    /// when the file has it, else added with the mappings missing on the
    /// way, after the last key of the mapping it goes into. `value` is
    /// written in the style of that mapping ([`NewValue`]); `comment`, when
    /// not empty, goes on comment lines above a new key (one `# ` line per
    /// line of it).
    Section {
        /// Key path of the value, keys joined by `.`, list items as `[n]`
        /// or `[name]` (the item whose `name` is that).
        path: String,
        /// The value.
        value: NewValue,
        /// Comment above a new key (empty: none).
        comment: String,
    },
}

/// A value the writer adds to a machine file, written in the style of the
/// mapping it goes into: block lines under a block mapping (the layout of
/// the bundled files: `key:` and its entries one level deeper, a list of
/// rows as `- row` lines), flow text in a flow mapping (`key: { a: 1.0 }`,
/// `key: [row, row]`).
#[derive(Debug, Clone, PartialEq)]
pub enum NewValue {
    /// A scalar or a flow collection, as its text (`1.5`, `[1.0, 2.0]`,
    /// `{ x_mm: 0.0 }`): one line in either style.
    Text(String),
    /// A list of rows, each a flow text (`{ a_mm: 0.0, d_mm: 1.0 }`).
    Rows(Vec<String>),
    /// A mapping, its keys in order.
    Map(Vec<(String, NewValue)>),
}

impl NewValue {
    /// The value as flow text.
    pub fn flow(&self) -> String {
        match self {
            NewValue::Text(t) => t.clone(),
            NewValue::Rows(r) => format!("[{}]", r.join(", ")),
            NewValue::Map(m) if m.is_empty() => "{}".into(),
            NewValue::Map(m) => {
                let pairs: Vec<String> = m
                    .iter()
                    .map(|(k, v)| format!("{k}: {}", v.flow()))
                    .collect();
                format!("{{ {} }}", pairs.join(", "))
            }
        }
    }

    /// The lines of `key: value` in block style at indentation `indent`.
    fn block(&self, key: &str, indent: &str, out: &mut Vec<String>) {
        match self {
            NewValue::Rows(r) if !r.is_empty() => {
                out.push(format!("{indent}{key}:"));
                out.extend(r.iter().map(|row| format!("{indent}  - {row}")));
            }
            NewValue::Map(m) if !m.is_empty() => {
                out.push(format!("{indent}{key}:"));
                let deeper = format!("{indent}  ");
                for (k, v) in m {
                    v.block(k, &deeper, out);
                }
            }
            _ => out.push(format!("{indent}{key}: {}", self.flow())),
        }
    }
}

/// One Paper B thermal term as written in a robot file.
#[derive(Debug, Clone, PartialEq)]
pub struct ThermalTermText {
    /// DH length, `a1..a6` / `d1..d6`.
    pub parameter: String,
    /// Joint whose power drives it, 1..6.
    pub joint: usize,
    /// `lb_mm`.
    pub lb_mm: f64,
    /// `ub_mm`.
    pub ub_mm: f64,
    /// `ts_per_w`.
    pub ts_per_w: f64,
}

mod tree;

pub(crate) use tree::set_status;

/// Applies `edits` in order to the machine file `text` (named `file` in
/// errors). `by` names the program in the comment above a section it adds
/// (`# Identified by `…`.`). Every comment and every byte the edits do not
/// touch are kept: the layouts of the bundled files are edited by the
/// line editor of this module (whose output the snapshots fix), any other
/// layout the loader reads — or an edit whose result does not read back as
/// the value it wrote — on the file's syntax tree ([`tree`]). The caller
/// reads the result back as the machine it writes.
pub fn apply(text: &str, file: &str, by: &str, edits: &[Edit]) -> Result<String> {
    let in_place = (|| {
        let mut t = text.to_string();
        for e in edits {
            t = apply_one(&t, file, by, e)?;
        }
        Ok::<_, Error>(t)
    })();
    let check = |t: &str| reads_back(t, edits);
    let line_ok = matches!(&in_place, Ok(t) if check(t) == ReadBack::Values);
    if line_ok && in_place.as_ref().is_ok_and(|t| comments_kept(text, t)) {
        return in_place;
    }
    let on_tree = tree::apply(text, file, by, edits);
    let not_back = || {
        edit_err(
            file,
            "an edited value does not read back as written; the layout of its key cannot be edited",
        )
    };
    match (in_place, on_tree) {
        (_, Ok(v)) if check(&v) == ReadBack::Values => Ok(v),
        (Ok(t), _) if line_ok || check(&t) == ReadBack::Invalid => Ok(t),
        (Ok(_), _) => Err(not_back()),
        (Err(_), Ok(v)) if check(&v) == ReadBack::Invalid => Ok(v),
        (Err(_), Ok(_)) => Err(not_back()),
        (Err(e), Err(tree_err)) => {
            tracing::debug!("line editor: {e}; tree editor: {tree_err}");
            Err(tree_err)
        }
    }
}

/// Whether every comment line of `before` is still in `after` (a table
/// replaced whole by the line editor drops the comments inside it).
fn comments_kept(before: &str, after: &str) -> bool {
    let kept: std::collections::BTreeSet<&str> = after.lines().map(str::trim).collect();
    before
        .lines()
        .map(str::trim)
        .filter(|l| l.starts_with('#'))
        .all(|l| kept.contains(l))
}

/// What an edited text reads back as.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum ReadBack {
    /// A valid machine with every edited model value as written.
    Values,
    /// A valid machine with an edited value that differs.
    Wrong,
    /// Not a valid machine file (the caller reports why).
    Invalid,
}

fn reads_back(text: &str, edits: &[Edit]) -> ReadBack {
    let Ok(m) = super::Machine::from_yaml_str(text, "(edited file)") else {
        return ReadBack::Invalid;
    };
    let mut last: Vec<(Option<f64>, f64)> = Vec::new();
    let mut robot: Vec<RobotParam> = Vec::new();
    let mut tool: Vec<ToolParam> = Vec::new();
    for e in edits {
        match (e, &m) {
            (Edit::Robot(p, v), super::Machine::Robot(r)) => {
                if let Some(i) = robot.iter().position(|q| q == p) {
                    last[i].1 = *v;
                } else {
                    robot.push(*p);
                    last.push((r.param_value(*p), *v));
                }
            }
            (Edit::Tool(p, v), super::Machine::Tool(t)) => {
                if let Some(i) = tool.iter().position(|q| q == p) {
                    last[robot.len() + i].1 = *v;
                } else {
                    tool.push(*p);
                    last.push((t.param_value(*p), *v));
                }
            }
            _ => {}
        }
    }
    if last.iter().all(|(got, want)| *got == Some(*want)) {
        ReadBack::Values
    } else {
        ReadBack::Wrong
    }
}

fn apply_one(text: &str, file: &str, by: &str, edit: &Edit) -> Result<String> {
    match edit {
        Edit::Tool(p, v) => set_tool_param(text, file, *p, *v),
        Edit::Robot(p, v) => set_robot_param(text, file, by, *p, *v),
        Edit::ComponentTable {
            axis,
            error,
            positions,
            forward,
            reverse,
        } => set_component_table(
            text,
            file,
            *axis,
            *error,
            [positions.as_slice(), forward, reverse],
        ),
        Edit::ThermalTerm {
            term,
            time_constant_min,
            comment,
        } => add_thermal_term(text, file, term, *time_constant_min, comment),
        Edit::RatedPower { watts, comment } => set_rated_power(text, file, *watts, comment),
        Edit::Spindle {
            growth_um_per_kw,
            time_constant_min,
            comment,
        } => add_spindle(text, file, *growth_um_per_kw, *time_constant_min, comment),
        Edit::MeasurementFrame { xyz_mm, rpy_deg } => {
            set_measurement_frame(text, file, *xyz_mm, *rpy_deg)
        }
        Edit::Calibrated(c) => set_calibrated(text, file, c),
        Edit::Section { .. } => Err(edit_err(file, "a section is written on the tree")),
        Edit::HeaderComment(c) => {
            let mut lines = lines_of(text);
            let at = lines
                .iter()
                .take_while(|l| l.starts_with('#') || l.trim().is_empty())
                .count();
            lines.insert(at, format!("# {c}"));
            Ok(join_nl(lines))
        }
    }
}

// ---------------------------------------------------------------------------
// Numbers
// ---------------------------------------------------------------------------

/// `v` written exactly: the shortest decimal that reads back as `v`, with
/// one decimal at least so that it reads as a float (`-0` is `0.0`).
pub fn number(v: f64) -> String {
    let v = if v == 0.0 { 0.0 } else { v };
    let s = format!("{v}");
    if s.contains(['.', 'e', 'E', 'N', 'i']) {
        s
    } else {
        format!("{s}.0")
    }
}

/// `v` rounded to `decimals` decimals (the value a file written with that
/// resolution holds).
pub fn round_to(v: f64, decimals: usize) -> f64 {
    format!("{v:.decimals$}").parse().unwrap_or(v)
}

/// `v` rounded to six significant digits (a small coefficient such as
/// `ts_per_w = 1e-6`); 0 for 0 or a non-finite value.
pub fn round_sig(v: f64) -> f64 {
    if v == 0.0 || !v.is_finite() {
        return 0.0;
    }
    let digits = (5 - v.abs().log10().floor() as i64).clamp(1, 15) as usize;
    round_to(v, digits)
}

/// `v` with at most `decimals` decimals, trailing zeros removed (one
/// decimal kept): [`number`] of [`round_to`].
pub fn fmt_value(v: f64, decimals: usize) -> String {
    number(round_to(v, decimals))
}

// ---------------------------------------------------------------------------
// Lines
// ---------------------------------------------------------------------------

fn edit_err(file: &str, msg: impl Into<String>) -> Error {
    Error::Usage(format!(
        "{file}: cannot write the calibrated values: {}",
        msg.into()
    ))
}

fn lines_of(text: &str) -> Vec<String> {
    text.lines().map(str::to_string).collect()
}

/// The lines joined, with a final newline when `original` had one.
fn join(lines: Vec<String>, original: &str) -> String {
    let mut s = lines.join("\n");
    if original.ends_with('\n') {
        s.push('\n');
    }
    s
}

/// The lines joined, with a final newline.
fn join_nl(lines: Vec<String>) -> String {
    let mut s = lines.join("\n");
    s.push('\n');
    s
}

/// Index of the top-level line `key:` (no indentation).
fn top_level_line(lines: &[String], key: &str) -> Option<usize> {
    let prefix = format!("{key}:");
    lines.iter().position(|l| l.starts_with(&prefix))
}

/// Splits a line into (content, comment) at the first `#` that follows a
/// blank.
fn split_comment(line: &str) -> (&str, &str) {
    let b = line.as_bytes();
    for i in 0..b.len() {
        if b[i] == b'#' && (i == 0 || b[i - 1] == b' ' || b[i - 1] == b'\t') {
            return line.split_at(i);
        }
    }
    (line, "")
}

fn indent_of(l: &str) -> usize {
    l.len() - l.trim_start().len()
}

fn is_content(l: &str) -> bool {
    let t = l.trim_start();
    !t.is_empty() && !t.starts_with('#')
}

/// Index of the line of the key path `path` whose key is `last` (empty:
/// the line of a sequence item `- …`, for a path ending in `[n]`), when the
/// file has it.
fn path_line(text: &str, path: &str, last: &str) -> Option<usize> {
    let (line, _) = super::yaml::locate(text, path)?;
    let i = line.checked_sub(1)?;
    let body = text.lines().nth(i)?.trim_start();
    if last.is_empty() {
        return body.starts_with("- ").then_some(i);
    }
    let body = body.strip_prefix("- ").unwrap_or(body);
    body.starts_with(&format!("{last}:")).then_some(i)
}

/// Replaces the values of `key: value` pairs inside a one-line flow map.
/// Every key must be present.
fn replace_map_values(line: &str, pairs: &[(&str, String)]) -> Option<String> {
    let (content, comment) = split_comment(line);
    let mut out = content.to_string();
    for (key, val) in pairs {
        let pat = format!("{key}:");
        let mut search = 0;
        let start = loop {
            let at = out[search..].find(&pat)? + search;
            let before = out[..at].chars().last();
            if matches!(before, Some('{') | Some(' ') | Some(',')) {
                break at + pat.len();
            }
            search = at + pat.len();
        };
        let rest = &out[start..];
        let end = rest.find([',', '}']).map(|e| start + e)?;
        let lead = if out[start..end].starts_with(' ') {
            " "
        } else {
            ""
        };
        let trail_len = out[start..end].len() - out[start..end].trim_end().len();
        let trail = " ".repeat(trail_len);
        out.replace_range(start..end, &format!("{lead}{val}{trail}"));
    }
    out.push_str(comment);
    Some(out)
}

/// Sets `key` of the one-line flow map on the line of `path` (whose last
/// key is `last`).
fn set_in_flow_map(
    text: &str,
    file: &str,
    path: &str,
    last: &str,
    key: &str,
    v: f64,
) -> Result<String> {
    let bad = || {
        edit_err(
            file,
            format!("`{path}` is not a one-line flow map with {key}"),
        )
    };
    let i = path_line(text, path, last).ok_or_else(bad)?;
    let mut lines = lines_of(text);
    let l = &lines[i];
    if !(l.contains('{') && l.contains(&format!("{key}:"))) {
        return Err(bad());
    }
    lines[i] = replace_map_values(l, &[(key, number(v))]).ok_or_else(bad)?;
    Ok(join(lines, text))
}

/// Sets the scalar `key: value` on the line of `path` (its comment kept).
fn set_scalar(text: &str, file: &str, path: &str, key: &str, v: f64) -> Result<String> {
    let bad = || edit_err(file, format!("`{path}` is not a scalar on one line"));
    let i = path_line(text, path, key).ok_or_else(bad)?;
    let mut lines = lines_of(text);
    let l = &lines[i];
    let (content, comment) = split_comment(l);
    let colon = content.find(':').ok_or_else(bad)?;
    let value = content[colon + 1..].trim();
    if value.is_empty() || value.starts_with(['{', '[', '|', '>', '&', '*', '!']) {
        return Err(bad());
    }
    let trail = &content[content.trim_end().len()..];
    lines[i] = format!("{}: {}{trail}{comment}", &content[..colon], number(v));
    Ok(join(lines, text))
}

/// Replaces item `index` of the one-line flow list `[ … ]` on top-level
/// line `key` (items joined by `, `).
fn set_list_item(text: &str, file: &str, key: &str, index: usize, v: f64) -> Result<String> {
    let bad = || edit_err(file, format!("`{key}` is not a one-line flow list `[…]`"));
    let mut lines = lines_of(text);
    let i = top_level_line(&lines, key)
        .ok_or_else(|| edit_err(file, format!("no top-level key `{key}`")))?;
    let (content, comment) = split_comment(&lines[i]);
    let open = content.find('[').ok_or_else(bad)?;
    let close = content.rfind(']').filter(|&c| c > open).ok_or_else(bad)?;
    let mut items: Vec<String> = content[open + 1..close]
        .split(',')
        .map(|s| s.trim().to_string())
        .collect();
    *items
        .get_mut(index)
        .ok_or_else(|| edit_err(file, format!("`{key}` has no item {index}")))? = number(v);
    lines[i] = format!(
        "{}[{}]{}{comment}",
        &content[..open],
        items.join(", "),
        &content[close + 1..]
    );
    Ok(join(lines, text))
}

// ---------------------------------------------------------------------------
// Robot
// ---------------------------------------------------------------------------

fn dh_key(f: DhField) -> &'static str {
    match f {
        DhField::A => "a_mm",
        DhField::Alpha => "alpha_deg",
        DhField::D => "d_mm",
        DhField::ThetaOffset => "theta_offset_deg",
    }
}

fn set_robot_param(text: &str, file: &str, by: &str, p: RobotParam, v: f64) -> Result<String> {
    match p {
        RobotParam::Dh { joint, field } => set_dh(text, file, by, joint, field, v),
        RobotParam::JointStiffness { joint } => set_list_item(text, file, "k_nm_per_rad", joint, v),
        RobotParam::ToolOffset { axis } => {
            let key = ["x_mm", "y_mm", "z_mm"]
                .get(axis)
                .ok_or_else(|| edit_err(file, "no such tool offset"))?;
            let text = with_top_level(text, "flange_to_tool", || {
                "{ x_mm: 0.0, y_mm: 0.0, z_mm: 0.0 }".into()
            });
            set_in_flow_map(&text, file, "flange_to_tool", "flange_to_tool", key, v)
        }
        RobotParam::PayloadMass => {
            let text = with_top_level(text, "tool_load", || {
                let doc: Value = serde_yaml::from_str(text).unwrap_or(Value::Null);
                let c = |k: &str| {
                    number(
                        doc.get("flange_to_tool")
                            .and_then(|f| f.get(k))
                            .and_then(|v| v.as_f64().or_else(|| v.as_i64().map(|i| i as f64)))
                            .unwrap_or(0.0),
                    )
                };
                format!(
                    "{{ mass_kg: 0.0, cog_mm: [{}, {}, {}] }}",
                    c("x_mm"),
                    c("y_mm"),
                    c("z_mm")
                )
            });
            set_in_flow_map(&text, file, "tool_load", "tool_load", "mass_kg", v)
        }
        RobotParam::Thermal { term, field } => {
            let key = match field {
                ThermalField::Lb => "lb_mm",
                ThermalField::Ub => "ub_mm",
                ThermalField::Ts => "ts_per_w",
            };
            let path = format!("thermal.terms[{term}]");
            set_in_flow_map(text, file, &path, "", key, v).map_err(|_| {
                edit_err(
                    file,
                    format!(
                        "`{path}` is not a one-line flow map `- {{ parameter: …, lb_mm: …, ub_mm: …, ts_per_w: … }}`"
                    ),
                )
            })
        }
        RobotParam::ThermalTimeConstant => set_scalar(
            text,
            file,
            "thermal.time_constant_min",
            "time_constant_min",
            v,
        ),
    }
}

/// `text` with the top-level line `key: value()` appended when it has no
/// top-level `key`.
fn with_top_level(text: &str, key: &str, value: impl FnOnce() -> String) -> String {
    if top_level_line(&lines_of(text), key).is_some() {
        return text.to_string();
    }
    let mut t = text.to_string();
    if !t.is_empty() && !t.ends_with('\n') {
        t.push('\n');
    }
    t.push_str(&format!("{key}: {}\n", value()));
    t
}

/// Indices of the six `  - { … }` rows following the top-level line `key:`.
fn dh_row_lines(lines: &[String], key: &str) -> Option<Vec<usize>> {
    let i = top_level_line(lines, key)?;
    let mut rows = Vec::with_capacity(6);
    for (k, l) in lines.iter().enumerate().skip(i + 1) {
        let t = l.trim_start();
        if t.is_empty() || t.starts_with('#') {
            continue;
        }
        if t.starts_with("- {") && l.starts_with(' ') {
            rows.push(k);
            if rows.len() == 6 {
                return Some(rows);
            }
        } else {
            break;
        }
    }
    None
}

/// The `actual:` section as a copy of the `nominal` rows, inserted after
/// them with a comment naming `by`; returns the new text.
fn add_actual(text: &str, file: &str, by: &str) -> Result<String> {
    let mut lines = lines_of(text);
    let bad = || {
        edit_err(
            file,
            "`nominal` is not a list of six one-line flow maps `- { a_mm: … }`",
        )
    };
    let idx = dh_row_lines(&lines, "nominal").ok_or_else(bad)?;
    let doc: Value = serde_yaml::from_str(text).map_err(|_| bad())?;
    let nominal = doc
        .get("nominal")
        .and_then(Value::as_sequence)
        .ok_or_else(bad)?;
    let field = |row: &Value, key: &str| {
        row.get(key)
            .and_then(|v| v.as_f64().or_else(|| v.as_i64().map(|i| i as f64)))
            .unwrap_or(0.0)
    };
    let mut block = vec![format!("# Identified by `{by}`."), "actual:".to_string()];
    for j in 0..6 {
        let row = nominal.get(j).ok_or_else(bad)?;
        block.push(format!(
            "  - {{ a_mm: {}, alpha_deg: {}, d_mm: {}, theta_offset_deg: {} }}",
            number(field(row, "a_mm")),
            number(field(row, "alpha_deg")),
            number(field(row, "d_mm")),
            number(field(row, "theta_offset_deg"))
        ));
    }
    let after = idx.last().copied().unwrap_or(0) + 1;
    lines.splice(after..after, block);
    Ok(join(lines, text))
}

fn set_dh(text: &str, file: &str, by: &str, joint: usize, f: DhField, v: f64) -> Result<String> {
    let mut text = text.to_string();
    if top_level_line(&lines_of(&text), "actual").is_none() {
        text = add_actual(&text, file, by)?;
    }
    let mut lines = lines_of(&text);
    let idx = dh_row_lines(&lines, "actual").ok_or_else(|| {
        edit_err(
            file,
            "`actual` is not a list of six one-line flow maps `- { a_mm: … }`",
        )
    })?;
    let li = *idx
        .get(joint)
        .ok_or_else(|| edit_err(file, format!("no DH row {}", joint + 1)))?;
    lines[li] = replace_map_values(&lines[li], &[(dh_key(f), number(v))]).ok_or_else(|| {
        edit_err(
            file,
            format!(
                "`actual` row {} lacks a_mm/alpha_deg/d_mm/theta_offset_deg",
                joint + 1
            ),
        )
    })?;
    Ok(join(lines, &text))
}

fn term_flow(t: &ThermalTermText) -> String {
    format!(
        "{{ parameter: {}, joint: {}, lb_mm: {}, ub_mm: {}, ts_per_w: {} }}",
        t.parameter,
        t.joint,
        number(t.lb_mm),
        number(t.ub_mm),
        number(t.ts_per_w)
    )
}

/// Adds a robot thermal term: to the block list `thermal.terms` when the
/// file has a `thermal:` section, else a new section at the end of the file.
fn add_thermal_term(
    text: &str,
    file: &str,
    term: &ThermalTermText,
    time_constant_min: f64,
    comment: &str,
) -> Result<String> {
    let mut lines = lines_of(text);
    let item = term_flow(term);
    match top_level_line(&lines, "thermal") {
        Some(t) => {
            let end = block_end(&lines, t, lines.len());
            let k = (t + 1..end)
                .find(|&i| lines[i].trim_start().starts_with("terms:"))
                .ok_or_else(|| edit_err(file, "`thermal` has no `terms:` key"))?;
            if lines[k].contains('[') {
                return Err(edit_err(
                    file,
                    "`thermal.terms` is a flow list; write it as a block list to add a term",
                ));
            }
            let base = indent_of(&lines[k]);
            // Items: deeper lines, or `- ` lines at the key's indentation.
            let mut last = k;
            let mut item_indent = base + 2;
            for (i, l) in lines.iter().enumerate().skip(k + 1) {
                if !is_content(l) {
                    continue;
                }
                let ind = indent_of(l);
                if ind > base || (ind == base && l.trim_start().starts_with("- ")) {
                    if l.trim_start().starts_with("- ") {
                        item_indent = ind;
                    }
                    last = i;
                } else {
                    break;
                }
            }
            lines.insert(last + 1, format!("{}- {item}", " ".repeat(item_indent)));
        }
        None => {
            new_section(&mut lines, comment);
            lines.push(format!(
                "  time_constant_min: {}",
                number(time_constant_min)
            ));
            lines.push("  terms:".into());
            lines.push(format!("    - {item}"));
        }
    }
    Ok(join_nl(lines))
}

/// Sets `thermal.rated_power_w` of a robot file in block style: the
/// existing line's value (its comment kept), or a new line after
/// `time_constant_min` (first in the section when it has none), preceded by
/// `# comment`.
fn set_rated_power(text: &str, file: &str, watts: f64, comment: &str) -> Result<String> {
    let mut lines = lines_of(text);
    let t = top_level_line(&lines, "thermal")
        .ok_or_else(|| edit_err(file, "no `thermal:` section for `rated_power_w`"))?;
    if split_comment(&lines[t]).0.trim_end() != "thermal:" {
        return Err(edit_err(
            file,
            "`thermal` is not a block map; write it in block style to add `rated_power_w`",
        ));
    }
    let end = block_end(&lines, t, lines.len());
    let child = (t + 1..end)
        .find(|&i| is_content(&lines[i]))
        .map_or(2, |i| indent_of(&lines[i]));
    if let Some(i) = key_line(&lines, t + 1, end, child, "rated_power_w") {
        let (content, c) = split_comment(&lines[i]);
        let trail = &content[content.trim_end().len()..];
        lines[i] = format!(
            "{}rated_power_w: {}{trail}{c}",
            " ".repeat(child),
            number(watts)
        );
        return Ok(join(lines, text));
    }
    let at = key_line(&lines, t + 1, end, child, "time_constant_min").map_or(t + 1, |i| i + 1);
    let pad = " ".repeat(child);
    let mut new = Vec::new();
    if !comment.is_empty() {
        new.push(format!("{pad}# {comment}"));
    }
    new.push(format!("{pad}rated_power_w: {}", number(watts)));
    lines.splice(at..at, new);
    Ok(join(lines, text))
}

/// Starts a `thermal:` section at the end of `lines` (trailing blank lines
/// dropped), after the comment line `comment` when it is not empty.
fn new_section(lines: &mut Vec<String>, comment: &str) {
    while lines.last().is_some_and(|l| l.trim().is_empty()) {
        lines.pop();
    }
    if !comment.is_empty() {
        lines.push(format!("# {comment}"));
    }
    lines.push("thermal:".into());
}

/// Sets the top-level `measurement_frame:` to a one-line flow map
/// `{ x_mm, y_mm, z_mm, rpy_deg: [roll, pitch, yaw] }`: the existing line
/// is replaced (its comment kept), otherwise the key is appended at the end
/// of the file with a comment saying what it is.
fn set_measurement_frame(
    text: &str,
    file: &str,
    xyz_mm: [f64; 3],
    rpy_deg: [f64; 3],
) -> Result<String> {
    let value = format!(
        "{{ x_mm: {}, y_mm: {}, z_mm: {}, rpy_deg: [{}, {}, {}] }}",
        fmt_value(xyz_mm[0], 4),
        fmt_value(xyz_mm[1], 4),
        fmt_value(xyz_mm[2], 4),
        fmt_value(rpy_deg[0], 6),
        fmt_value(rpy_deg[1], 6),
        fmt_value(rpy_deg[2], 6)
    );
    let mut lines = lines_of(text);
    match top_level_line(&lines, "measurement_frame") {
        Some(i) => {
            let (content, comment) = split_comment(&lines[i]);
            if !content.contains('{') {
                return Err(edit_err(
                    file,
                    "`measurement_frame` is not a one-line flow map",
                ));
            }
            let comment = if comment.is_empty() {
                String::new()
            } else {
                format!("  {}", comment.trim_start())
            };
            lines[i] = format!("measurement_frame: {value}{comment}");
            Ok(join(lines, text))
        }
        None => {
            let mut t = text.to_string();
            if !t.is_empty() && !t.ends_with('\n') {
                t.push('\n');
            }
            t.push_str(
                "# Pose of the measuring instrument in the machine's reference frame,\n\
                 # identified by `postproc calibrate` or `diagnose` from `# frame: instrument`\n\
                 # observations (docs/frames.md). Not part of the model.\n",
            );
            t.push_str(&format!("measurement_frame: {value}\n"));
            Ok(t)
        }
    }
}

// ---------------------------------------------------------------------------
// Machine tool
// ---------------------------------------------------------------------------

fn letter(slot: usize) -> char {
    LETTERS.get(slot).copied().unwrap_or('?')
}

fn set_tool_param(text: &str, file: &str, p: ToolParam, v: f64) -> Result<String> {
    match p {
        ToolParam::Location { axis, error } => {
            let l = |s: usize| letter(s);
            let key = match error {
                LocationParam::Offset(t) => format!("E{}0{}_mm", l(t), l(axis)),
                LocationParam::Angle(r) => format!("E{}0{}_urad", l(r + 3), l(axis)),
                LocationParam::Zero => format!("E{}0{}_urad", l(axis), l(axis)),
            };
            set_location_error(text, file, letter(axis), &key, v)
        }
        ToolParam::Component { .. } => Err(edit_err(
            file,
            format!(
                "`{}`: a component table is written whole, positions and both columns",
                p.path()
            ),
        )),
        ToolParam::Stiffness {
            dir,
            positive,
            cell: None,
        } => {
            let key = format!(
                "{}_{}",
                letter(dir).to_ascii_lowercase(),
                if positive { "pos" } else { "neg" }
            );
            let map = "stiffness.k_n_per_um";
            if path_line(text, map, "k_n_per_um")
                .and_then(|i| text.lines().nth(i))
                .is_some_and(|l| l.contains('{'))
            {
                set_in_flow_map(text, file, map, "k_n_per_um", &key, v)
            } else {
                set_scalar(text, file, &format!("{map}.{key}"), &key, v)
            }
        }
        ToolParam::Stiffness {
            dir,
            positive,
            cell: Some(cell),
        } => {
            let key = format!(
                "{}_{}",
                letter(dir).to_ascii_lowercase(),
                if positive { "pos" } else { "neg" }
            );
            set_grid_cell(text, file, &format!("stiffness.k_n_per_um.{key}"), cell, v)
        }
        ToolParam::SpindleLocation { error } => {
            let key = super::tool::spindle_key(error);
            set_spindle_location(text, file, &key, v)
        }
        ToolParam::SpindleGrowth => set_in_flow_map(
            text,
            file,
            "thermal.spindle",
            "spindle",
            "growth_um_per_kw",
            v,
        ),
        ToolParam::SpindleTimeConstant => set_in_flow_map(
            text,
            file,
            "thermal.spindle",
            "spindle",
            "time_constant_min",
            v,
        ),
        ToolParam::AxisScale { axis } | ToolParam::AxisTimeConstant { axis } => {
            let key = if matches!(p, ToolParam::AxisScale { .. }) {
                "scale_ppm_per_kw"
            } else {
                "time_constant_min"
            };
            let name = letter(axis).to_string();
            let path = format!("thermal.axes.{name}");
            set_in_flow_map(text, file, &path, &name, key, v)
        }
    }
}

/// Sets cell `[iz, iy, ix]` of a stiffness grid written as one block-list
/// item per z plane, each a one-line nested flow list `- [[…], […]]`: only
/// the number of that cell is replaced.
fn set_grid_cell(text: &str, file: &str, path: &str, cell: [usize; 3], v: f64) -> Result<String> {
    let [iz, iy, ix] = cell;
    let bad = || {
        edit_err(
            file,
            format!("`{path}[{iz}]` is not a one-line nested flow list with cell [{iy}][{ix}]"),
        )
    };
    let i = path_line(text, &format!("{path}[{iz}]"), "").ok_or_else(bad)?;
    let mut lines = lines_of(text);
    let (content, comment) = split_comment(&lines[i]);
    let (start, end) = nested_item(content, iy, ix).ok_or_else(bad)?;
    lines[i] = format!(
        "{}{}{}{comment}",
        &content[..start],
        number(v),
        &content[end..]
    );
    Ok(join(lines, text))
}

/// Byte range of item `ix` of inner list `iy` in `- [[a, b], [c, d]]`.
fn nested_item(content: &str, iy: usize, ix: usize) -> Option<(usize, usize)> {
    let open = content.find('[')?;
    let mut depth = 0;
    let (mut row, mut col) = (0usize, 0usize);
    let mut start = None;
    for (k, c) in content.char_indices().skip_while(|&(k, _)| k < open) {
        match c {
            '[' => {
                depth += 1;
                if depth == 2 && row == iy && col == ix {
                    start = Some(k + 1);
                }
            }
            ']' | ',' => {
                if depth == 2 && row == iy && col == ix {
                    let s = start?;
                    let item = &content[s..k];
                    let lead = item.len() - item.trim_start().len();
                    return Some((s + lead, s + item.trim_end().len()));
                }
                if depth == 2 && c == ',' {
                    col += 1;
                    if row == iy && col == ix {
                        start = Some(k + 1);
                    }
                }
                if c == ']' {
                    depth -= 1;
                    if depth == 1 {
                        row += 1;
                        col = 0;
                    }
                    if depth == 0 {
                        return None;
                    }
                }
            }
            _ => {}
        }
    }
    None
}

/// Sets the spindle location error `key`: its line under the top-level
/// `spindle:` section's `location_errors:` map, added there when absent.
fn set_spindle_location(text: &str, file: &str, key: &str, v: f64) -> Result<String> {
    let path = format!("spindle.location_errors.{key}");
    if path_line(text, &path, key).is_some() {
        return set_scalar(text, file, &path, key, v);
    }
    let bad = || {
        edit_err(
            file,
            format!("`{path}`: the file has no block map `spindle.location_errors` to add it to"),
        )
    };
    let sec = path_line(text, "spindle.location_errors", "location_errors").ok_or_else(bad)?;
    let mut lines = lines_of(text);
    if lines[sec].contains('{') {
        return Err(bad());
    }
    let end = block_end(&lines, sec, lines.len());
    let child = (sec + 1..end)
        .find(|&i| is_content(&lines[i]))
        .map_or(indent_of(&lines[sec]) + 2, |i| indent_of(&lines[i]));
    lines.insert(
        sec + 1,
        format!("{}{key}: {}", " ".repeat(child), number(v)),
    );
    Ok(join(lines, text))
}

/// Line range `[start, end)` of the entry `- name: AXIS` of the top-level
/// `axes:` list, and the indentation of its keys.
fn axis_entry(lines: &[String], file: &str, axis: char) -> Result<(usize, usize, usize)> {
    let axes =
        top_level_line(lines, "axes").ok_or_else(|| edit_err(file, "no top-level key `axes`"))?;
    let mut k = axes + 1;
    while k < lines.len() {
        let l = &lines[k];
        if is_content(l) && indent_of(l) == 0 {
            break;
        }
        let t = l.trim_start();
        if let Some(rest) = t.strip_prefix("- name:") {
            if rest.trim() == axis.to_string() {
                let dash = indent_of(l);
                let mut end = k + 1;
                while end < lines.len() {
                    let m = &lines[end];
                    if is_content(m) && indent_of(m) <= dash {
                        break;
                    }
                    end += 1;
                }
                // Trailing blank/comment lines belong to what follows.
                while end > k + 1 && !is_content(&lines[end - 1]) {
                    end -= 1;
                }
                return Ok((k, end, dash + 2));
            }
        }
        k += 1;
    }
    Err(edit_err(
        file,
        format!("no axis entry `- name: {axis}` (block style) under `axes`"),
    ))
}

/// Line index of `key:` at indentation `indent` within `[start, end)`.
fn key_line(lines: &[String], start: usize, end: usize, indent: usize, key: &str) -> Option<usize> {
    let pat = format!("{key}:");
    (start..end).find(|&i| {
        lines
            .get(i)
            .is_some_and(|l| indent_of(l) == indent && l.trim_start().starts_with(&pat))
    })
}

/// End (exclusive) of the block of children of line `at` (deeper indentation).
fn block_end(lines: &[String], at: usize, end: usize) -> usize {
    let base = lines.get(at).map_or(0, |l| indent_of(l));
    let mut k = at + 1;
    while k < end {
        let l = &lines[k];
        if is_content(l) && indent_of(l) <= base {
            break;
        }
        k += 1;
    }
    while k > at + 1 && !is_content(&lines[k - 1]) {
        k -= 1;
    }
    k
}

/// Makes sure the axis entry has the mapping key `section:`; returns its
/// line index (inserted at the end of the entry when absent).
fn ensure_section(lines: &mut Vec<String>, file: &str, axis: char, section: &str) -> Result<usize> {
    let (start, end, ki) = axis_entry(lines, file, axis)?;
    if let Some(i) = key_line(lines, start + 1, end, ki, section) {
        if lines[i].contains('{') {
            return Err(edit_err(
                file,
                format!("`{section}` of axis {axis} is a flow map; write it in block style"),
            ));
        }
        return Ok(i);
    }
    lines.insert(end, format!("{}{section}:", " ".repeat(ki)));
    Ok(end)
}

/// The section `section` of an axis entry, made present, with the end of
/// its block and the indentation of its children.
fn axis_section(
    lines: &mut Vec<String>,
    file: &str,
    axis: char,
    section: &str,
) -> Result<(usize, usize, usize)> {
    let sec = ensure_section(lines, file, axis, section)?;
    let sec_end = block_end(lines, sec, lines.len());
    let child_indent = (sec + 1..sec_end)
        .find(|&i| is_content(&lines[i]))
        .map_or(indent_of(&lines[sec]) + 2, |i| indent_of(&lines[i]));
    Ok((sec, sec_end, child_indent))
}

/// Writes a bidirectional component-error table of a machine-tool axis:
/// replaces the table when present, adds it (and the `component_errors:`
/// section) when not. `columns`: positions, forward, reverse.
fn set_component_table(
    text: &str,
    file: &str,
    axis: usize,
    error: usize,
    columns: [&[f64]; 3],
) -> Result<String> {
    let unit = if error < 3 { "um" } else { "urad" };
    let key = format!("E{}{}_{unit}", letter(error), letter(axis));
    let mut lines = lines_of(text);
    let (sec, sec_end, child_indent) =
        axis_section(&mut lines, file, letter(axis), "component_errors")?;
    let list =
        |v: &[f64]| -> String { v.iter().map(|x| number(*x)).collect::<Vec<_>>().join(", ") };
    let pad = " ".repeat(child_indent);
    // Rotary axes (A, B, C) give their positions in degrees.
    let positions = if axis < 3 {
        "positions_mm"
    } else {
        "positions_deg"
    };
    let new = vec![
        format!("{pad}{key}:"),
        format!("{pad}  {positions}: [{}]", list(columns[0])),
        format!("{pad}  forward: [{}]", list(columns[1])),
        format!("{pad}  reverse: [{}]", list(columns[2])),
    ];
    match key_line(&lines, sec + 1, sec_end, child_indent, &key) {
        Some(i) => {
            let e = block_end(&lines, i, sec_end);
            lines.splice(i..e, new);
        }
        None => {
            lines.splice(sec + 1..sec + 1, new);
        }
    }
    Ok(join(lines, text))
}

/// Writes a location error `key: value` (e.g. `EC0Y_urad`) of a
/// machine-tool axis, adding the key (and `location_errors:`) when absent.
fn set_location_error(text: &str, file: &str, axis: char, key: &str, value: f64) -> Result<String> {
    let mut lines = lines_of(text);
    let (sec, sec_end, child_indent) = axis_section(&mut lines, file, axis, "location_errors")?;
    let v = number(value);
    match key_line(&lines, sec + 1, sec_end, child_indent, key) {
        Some(i) => {
            let (_, comment) = split_comment(&lines[i]);
            let comment = if comment.is_empty() {
                String::new()
            } else {
                format!("  {comment}")
            };
            lines[i] = format!("{}{key}: {v}{comment}", " ".repeat(child_indent));
        }
        None => lines.insert(sec + 1, format!("{}{key}: {v}", " ".repeat(child_indent))),
    }
    Ok(join(lines, text))
}

/// Adds `spindle:` (to the `thermal:` section, or a new section at the
/// end) with `idle_w_per_rpm: 0.0`; refuses a file that has one.
fn add_spindle(
    text: &str,
    file: &str,
    growth_um_per_kw: f64,
    time_constant_min: f64,
    comment: &str,
) -> Result<String> {
    let mut lines = lines_of(text);
    let new_map = format!(
        "{{ idle_w_per_rpm: 0.0, growth_um_per_kw: {}, time_constant_min: {} }}",
        number(growth_um_per_kw),
        number(time_constant_min)
    );
    match top_level_line(&lines, "thermal") {
        Some(t) => {
            let end = block_end(&lines, t, lines.len());
            if (t + 1..end).any(|i| lines[i].trim_start().starts_with("spindle:")) {
                return Err(edit_err(file, "`thermal.spindle` is already in the file"));
            }
            let ind = (t + 1..end)
                .find(|&i| is_content(&lines[i]))
                .map_or(2, |i| indent_of(&lines[i]));
            let mut at = t + 1;
            if !comment.is_empty() {
                lines.insert(at, format!("{}# {comment}", " ".repeat(ind)));
                at += 1;
            }
            lines.insert(at, format!("{}spindle: {new_map}", " ".repeat(ind)));
        }
        None => {
            new_section(&mut lines, comment);
            lines.push(format!("  spindle: {new_map}"));
        }
    }
    Ok(join_nl(lines))
}

fn set_calibrated(text: &str, file: &str, calibration: &Calibration) -> Result<String> {
    let eol = if text.contains("\r\n") { "\r\n" } else { "\n" };
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    let entry = format!("  - {}", super::status::calibration_flow(calibration));
    let top =
        |lines: &[String], key: &str| lines.iter().position(|l| l.starts_with(&format!("{key}:")));
    let status_at = match top(&lines, "status") {
        Some(i) => {
            lines[i] = "status: calibrated".into();
            i
        }
        None => {
            let after = top(&lines, "name")
                .or_else(|| top(&lines, "kind"))
                .ok_or_else(|| {
                    Error::Machine(crate::error::Located::whole_file(
                        file,
                        "cannot record the calibration: no top-level `kind:` line",
                    ))
                })?;
            lines.insert(after + 1, "status: calibrated".into());
            after + 1
        }
    };
    match top(&lines, "calibrations") {
        Some(i) => {
            if lines[i].trim_end() != "calibrations:" {
                return Err(Error::Machine(crate::error::Located::whole_file(
                    file,
                    "cannot record the calibration: `calibrations` must be a block list (one `  - { … }` line per calibration)",
                )));
            }
            let mut end = i + 1;
            while end < lines.len() && lines[end].starts_with("  - ") {
                end += 1;
            }
            lines.insert(end, entry);
        }
        None => {
            lines.insert(status_at + 1, "calibrations:".into());
            lines.insert(status_at + 2, entry);
        }
    }
    let mut out = lines.join(eol);
    if text.ends_with('\n') || !text.is_empty() {
        out.push_str(eol);
    }
    // The edited file must read back with the new entry (its RMS as
    // written).
    match super::Status::from_yaml_str(&out, file)? {
        super::Status::Calibrated(list)
            if list.last() == Some(&super::status::as_written(calibration)) =>
        {
            Ok(out)
        }
        _ => Err(Error::Machine(crate::error::Located::whole_file(
            file,
            "cannot record the calibration: the edited `status`/`calibrations` keys do not read back",
        ))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::machine::Machine;
    use crate::machine::robot::Robot;
    use crate::machine::tool::MachineTool;

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

    /// The lines of `b` that differ from those of `a` (same line count).
    fn changed(a: &str, b: &str) -> Vec<String> {
        assert_eq!(a.lines().count(), b.lines().count(), "{b}");
        a.lines()
            .zip(b.lines())
            .filter(|(x, y)| x != y)
            .map(|(_, y)| y.to_string())
            .collect()
    }

    #[test]
    fn numbers_are_written_exactly_and_read_back_equal() {
        assert_eq!(number(2.0), "2.0");
        assert_eq!(number(-0.0), "0.0");
        assert_eq!(number(1e-6), "0.000001");
        assert_eq!(fmt_value(1.23456, 3), "1.235");
        assert_eq!(fmt_value(-0.00001, 3), "0.0");
        assert_eq!(fmt_value(0.0123456789, 7), "0.0123457");
        assert_eq!(round_sig(0.0123456789), 0.0123457);
        for v in [150.05, 0.1 + 0.2, -1.0 / 3.0, 123_529.721, 1e-9] {
            assert_eq!(number(v).parse::<f64>().ok(), Some(v));
        }
    }

    /// Robot edits of every kind on the bundled IRB 1600 file: only the
    /// edited values change (comments and other bytes kept), and the robot
    /// read back equals `with_params` of the same edits.
    #[test]
    fn robot_file_read_back_equals_with_params() {
        let text = bundled("abb-irb1600.yaml");
        let edits = [
            (
                RobotParam::Dh {
                    joint: 1,
                    field: DhField::A,
                },
                150.05,
            ),
            (
                RobotParam::Dh {
                    joint: 4,
                    field: DhField::Alpha,
                },
                90.031_25,
            ),
            (RobotParam::JointStiffness { joint: 2 }, 123_529.721),
            (
                RobotParam::Thermal {
                    term: 1,
                    field: ThermalField::Ts,
                },
                0.0123457,
            ),
            (RobotParam::ThermalTimeConstant, 42.5),
            (RobotParam::ToolOffset { axis: 2 }, 150.25),
        ];
        let typed: Vec<Edit> = edits.iter().map(|&(p, v)| Edit::Robot(p, v)).collect();
        let out = apply(&text, "r.yaml", "test", &typed).expect("written");
        let lines = changed(&text, &out);
        assert_eq!(lines.len(), 6, "{lines:?}");
        assert!(out.contains("# Paper C Table 6"), "comments kept");
        assert!(out.contains("k_nm_per_rad: [270990.0, 430040.0, 123529.721,"));
        let want = robot(&text).with_params(&edits).expect("valid");
        assert_eq!(format!("{:?}", robot(&out)), format!("{want:?}"));
    }

    /// A DH edit in a file without `actual` adds the section as a copy of
    /// `nominal` after its rows; the robot read back equals `with_params`.
    #[test]
    fn actual_section_is_added_from_nominal() {
        let text = bundled("abb-irb1600.yaml");
        let start = text.find("\nactual:").expect("actual section") + 1;
        let end = start
            + text[start..]
                .match_indices("\n")
                .nth(6)
                .map(|(i, _)| i + 1)
                .expect("six rows");
        let bare = format!("{}{}", &text[..start], &text[end..]);
        assert!(!bare.contains("\nactual:"));
        let p = RobotParam::Dh {
            joint: 0,
            field: DhField::D,
        };
        let out = apply(&bare, "r.yaml", "postproc test", &[Edit::Robot(p, 486.5)]).unwrap();
        assert!(out.contains("# Identified by `postproc test`.\nactual:\n  - { a_mm: "));
        let want = robot(&bare).with_params(&[(p, 486.5)]).expect("valid");
        assert_eq!(format!("{:?}", robot(&out)), format!("{want:?}"));
    }

    /// Machine-tool edits on the bundled AFM R1000 file: a location error
    /// replaced and one added, the spindle growth and a stiffness value;
    /// the model read back equals `with_params` of the same edits.
    #[test]
    fn tool_file_read_back_equals_with_params() {
        let text = bundled("afm-r1000.yaml");
        let sq = |axis, r| ToolParam::Location {
            axis,
            error: LocationParam::Angle(r),
        };
        let edits = [
            (sq(1, 2), 75.25),
            (sq(2, 0), -3.5),
            (ToolParam::SpindleGrowth, 11.0),
        ];
        let typed: Vec<Edit> = edits.iter().map(|&(p, v)| Edit::Tool(p, v)).collect();
        let out = apply(&text, "t.yaml", "test", &typed).expect("written");
        assert!(out.contains("      EC0Y_urad: 75.25"));
        assert!(
            out.contains("# Structure: X is carried by Y"),
            "comments kept"
        );
        let want = tool(&text).with_params(&edits).expect("valid");
        let read = tool(&out);
        assert_eq!(
            format!(
                "{:?}{:?}{:?}",
                read.axes(),
                read.stiffness(),
                read.thermal()
            ),
            format!(
                "{:?}{:?}{:?}",
                want.axes(),
                want.stiffness(),
                want.thermal()
            )
        );
    }

    /// Uniform stiffness values and thermal axis values of a small file,
    /// in a flow map and in block style.
    #[test]
    fn stiffness_and_thermal_axes_read_back_equal_with_params() {
        let text = "kind: machine_tool
name: T
axes:
  - name: Y
    type: linear
    side: workpiece
    travel_mm: [0, 400]
    rapid_mm_per_min: 20000
  - name: X
    type: linear
    side: tool
    travel_mm: [0, 500]
    rapid_mm_per_min: 20000
  - name: Z
    type: linear
    side: tool
    travel_mm: [-300, 0]
    rapid_mm_per_min: 15000
stiffness:
  k_n_per_um: { x_pos: 20, x_neg: 20, y_pos: 25, y_neg: 25, z_pos: 40, z_neg: 40 }  # flow
thermal:
  spindle: { growth_um_per_kw: 8, time_constant_min: 20 }
  axes:
    X: { scale_ppm_per_kw: 3, time_constant_min: 30 }
";
        let edits = [
            (
                ToolParam::Stiffness {
                    dir: 1,
                    positive: false,
                    cell: None,
                },
                30.5,
            ),
            (ToolParam::SpindleTimeConstant, 22.0),
            (ToolParam::AxisTimeConstant { axis: 0 }, 45.0),
        ];
        let typed: Vec<Edit> = edits.iter().map(|&(p, v)| Edit::Tool(p, v)).collect();
        let out = apply(text, "t.yaml", "test", &typed).expect("written");
        assert_eq!(changed(text, &out).len(), 3);
        assert!(out.contains("z_neg: 40 }  # flow"));
        let want = tool(text).with_params(&edits).expect("valid");
        let read = tool(&out);
        assert_eq!(
            format!("{:?}{:?}", read.stiffness(), read.thermal()),
            format!("{:?}{:?}", want.stiffness(), want.thermal())
        );
        let block = text.replace(
            "  k_n_per_um: { x_pos: 20, x_neg: 20, y_pos: 25, y_neg: 25, z_pos: 40, z_neg: 40 }  # flow\n",
            "  k_n_per_um:\n    x_pos: 20\n    x_neg: 20\n    y_pos: 25\n    y_neg: 25  # block\n    z_pos: 40\n    z_neg: 40\n",
        );
        let out = apply(&block, "t.yaml", "test", &typed[..1]).expect("written");
        assert!(out.contains("    y_neg: 30.5  # block\n"), "{out}");
        let read = tool(&out);
        assert_eq!(
            format!("{:?}", read.stiffness()),
            format!("{:?}", want.stiffness())
        );
    }

    /// A payload and a TCP on a robot file without `tool_load` and
    /// `flange_to_tool`: the keys are added, and the robot read back equals
    /// `with_params` (the new load at the TCP).
    #[test]
    fn payload_and_tcp_added_read_back_equal_with_params() {
        let text = bundled("abb-irb1600.yaml");
        let with_tcp = text
            .lines()
            .filter(|l| !l.starts_with("tool_load:"))
            .map(|l| format!("{l}\n"))
            .collect::<String>();
        let edits = [(RobotParam::PayloadMass, 7.5)];
        let out = apply(&with_tcp, "r.yaml", "t", &[Edit::Robot(edits[0].0, 7.5)]).unwrap();
        assert!(out.ends_with("tool_load: { mass_kg: 7.5, cog_mm: [0.0, 0.0, 150.0] }\n"));
        let want = robot(&with_tcp).with_params(&edits).expect("valid");
        assert_eq!(format!("{:?}", robot(&out)), format!("{want:?}"));
        let bare = with_tcp
            .lines()
            .filter(|l| !l.starts_with("flange_to_tool:"))
            .map(|l| format!("{l}\n"))
            .collect::<String>();
        let edits = [(RobotParam::ToolOffset { axis: 2 }, 120.0)];
        let out = apply(&bare, "r.yaml", "t", &[Edit::Robot(edits[0].0, 120.0)]).unwrap();
        assert!(out.ends_with("flange_to_tool: { x_mm: 0.0, y_mm: 0.0, z_mm: 120.0 }\n"));
        let want = robot(&bare).with_params(&edits).expect("valid");
        assert_eq!(format!("{:?}", robot(&out)), format!("{want:?}"));
    }

    /// A stiffness grid cell and spindle location errors (one replaced, one
    /// added): only those numbers change, and the model read back equals
    /// `with_params`.
    #[test]
    fn grid_cells_and_spindle_errors_read_back_equal_with_params() {
        let text = bundled("afm-r1000.yaml");
        let cell = ToolParam::Stiffness {
            dir: 0,
            positive: false,
            cell: Some([1, 1, 2]),
        };
        let out = apply(&text, "t.yaml", "t", &[Edit::Tool(cell, 18.25)]).unwrap();
        assert_eq!(
            changed(&text, &out),
            vec!["      - [[20.0, 22.0, 20.0], [19.0, 21.0, 18.25]]".to_string()]
        );
        let want = tool(&text).with_params(&[(cell, 18.25)]).expect("valid");
        assert_eq!(
            format!("{:?}", tool(&out).stiffness()),
            format!("{:?}", want.stiffness())
        );
        let text = bundled("five-axis-ac.yaml");
        let edits = [
            (
                ToolParam::SpindleLocation {
                    error: LocationParam::Angle(0),
                },
                11.5,
            ),
            (
                ToolParam::SpindleLocation {
                    error: LocationParam::Offset(1),
                },
                0.02,
            ),
        ];
        let typed: Vec<Edit> = edits.iter().map(|&(p, v)| Edit::Tool(p, v)).collect();
        let out = apply(&text, "t.yaml", "t", &typed).unwrap();
        assert!(
            out.contains("spindle:\n  location_errors:\n    EY0S_mm: 0.02\n    EA0S_urad: 11.5\n")
        );
        let want = tool(&text).with_params(&edits).expect("valid");
        let read = tool(&out);
        assert_eq!(
            format!("{:?}", read.spindle_errors()),
            format!("{:?}", want.spindle_errors())
        );
    }

    /// Header comments go after the leading comment block, in order.
    #[test]
    fn header_comments_follow_the_leading_comments() {
        let text = "# a\n\n# b\nkind: robot\n# c\n";
        let out = apply(
            text,
            "f",
            "t",
            &[
                Edit::HeaderComment("one".into()),
                Edit::HeaderComment("two".into()),
            ],
        )
        .unwrap();
        assert_eq!(out, "# a\n\n# b\n# one\n# two\nkind: robot\n# c\n");
    }

    #[test]
    fn lists_maps_and_frames_are_edited_in_place() {
        let text = "# c\nk_nm_per_rad: [1.0, 2.0]  # keep\nflange_to_tool: { x_mm: 0.0, y_mm: 0.0, z_mm: 150.0, quaternion: [1.0, 0.0, 0.0, 0.0] }\n";
        let k = |joint, v| Edit::Robot(RobotParam::JointStiffness { joint }, v);
        let t = apply(text, "f", "t", &[k(0, 3.5), k(1, 4.0)]).unwrap();
        assert_eq!(t.lines().nth(1), Some("k_nm_per_rad: [3.5, 4.0]  # keep"));
        let tcp = |axis, v| Edit::Robot(RobotParam::ToolOffset { axis }, v);
        let t = apply(&t, "f", "t", &[tcp(0, 0.1), tcp(1, -0.2), tcp(2, 150.25)]).unwrap();
        assert_eq!(
            t.lines().nth(2),
            Some(
                "flange_to_tool: { x_mm: 0.1, y_mm: -0.2, z_mm: 150.25, quaternion: [1.0, 0.0, 0.0, 0.0] }"
            )
        );
        assert!(apply(text, "f", "t", &[k(5, 1.0)]).is_err());
        let frame = Edit::MeasurementFrame {
            xyz_mm: [1.0, 2.00004, -3.0],
            rpy_deg: [0.0, 0.1234567, 0.0],
        };
        let t = apply(&t, "f", "t", std::slice::from_ref(&frame)).unwrap();
        assert!(t.ends_with(
            "Not part of the model.\nmeasurement_frame: { x_mm: 1.0, y_mm: 2.0, z_mm: -3.0, rpy_deg: [0.0, 0.123457, 0.0] }\n"
        ));
        let again = apply(&t, "f", "t", &[frame]).unwrap();
        assert_eq!(again, t, "an existing frame line is replaced");
    }

    #[test]
    fn thermal_terms_set_and_added() {
        let text = "kind: robot\nthermal:\n  time_constant_min: 30  # c\n  terms:\n    - { parameter: a2, joint: 1, lb_mm: 0.10, ub_mm: 0.10, ts_per_w: 0.015 }  # J1\n    - { parameter: a2, joint: 2, lb_mm: 0.12, ub_mm: 0.12, ts_per_w: 0.020 }\nmodal: []\n";
        let f = |term, field, v| Edit::Robot(RobotParam::Thermal { term, field }, v);
        let t = apply(
            text,
            "f",
            "t",
            &[
                f(1, ThermalField::Lb, 0.25),
                f(1, ThermalField::Ub, 0.2),
                f(1, ThermalField::Ts, 0.0123457),
                Edit::Robot(RobotParam::ThermalTimeConstant, 45.0),
            ],
        )
        .unwrap();
        assert_eq!(
            t.lines().nth(5),
            Some("    - { parameter: a2, joint: 2, lb_mm: 0.25, ub_mm: 0.2, ts_per_w: 0.0123457 }")
        );
        assert_eq!(t.lines().nth(2), Some("  time_constant_min: 45.0  # c"));
        assert!(t.contains("ts_per_w: 0.015 }  # J1"));
        assert!(apply(text, "f", "t", &[f(2, ThermalField::Lb, 0.0)]).is_err());
        let term = ThermalTermText {
            parameter: "a3".into(),
            joint: 2,
            lb_mm: 300.0,
            ub_mm: 300.0,
            ts_per_w: 1e-6,
        };
        let add = |comment: &str| Edit::ThermalTerm {
            term: term.clone(),
            time_constant_min: 30.0,
            comment: comment.into(),
        };
        let t = apply(text, "f", "t", &[add("")]).unwrap();
        assert_eq!(
            t.lines().nth(6),
            Some(
                "    - { parameter: a3, joint: 2, lb_mm: 300.0, ub_mm: 300.0, ts_per_w: 0.000001 }"
            )
        );
        assert_eq!(t.lines().nth(7), Some("modal: []"));
        let t = apply("kind: robot\n", "f", "t", &[add("assumed")]).unwrap();
        assert_eq!(
            t,
            "kind: robot\n# assumed\nthermal:\n  time_constant_min: 30.0\n  terms:\n    - { parameter: a3, joint: 2, lb_mm: 300.0, ub_mm: 300.0, ts_per_w: 0.000001 }\n"
        );
    }

    #[test]
    fn spindle_growth_set_and_added() {
        let text = "kind: machine_tool\nthermal:\n  spindle: { idle_w_per_rpm: 0.2, growth_um_per_kw: 3.0, time_constant_min: 25.0 }\n";
        let t = apply(
            text,
            "f",
            "t",
            &[Edit::Tool(ToolParam::SpindleGrowth, 7.25)],
        )
        .unwrap();
        assert_eq!(
            t.lines().nth(2),
            Some(
                "  spindle: { idle_w_per_rpm: 0.2, growth_um_per_kw: 7.25, time_constant_min: 25.0 }"
            )
        );
        let add = Edit::Spindle {
            growth_um_per_kw: 5.0,
            time_constant_min: 30.0,
            comment: String::new(),
        };
        assert!(apply(text, "f", "t", std::slice::from_ref(&add)).is_err());
        let t = apply("kind: machine_tool\n", "f", "t", std::slice::from_ref(&add)).unwrap();
        assert_eq!(
            t,
            "kind: machine_tool\nthermal:\n  spindle: { idle_w_per_rpm: 0.0, growth_um_per_kw: 5.0, time_constant_min: 30.0 }\n"
        );
        let t = apply(
            "kind: machine_tool\nthermal:\n  axes:\n    X: { scale_ppm_per_kw: 1.0, time_constant_min: 9.0, friction_n: 1.0 }\n",
            "f",
            "t",
            &[add, Edit::Tool(ToolParam::AxisScale { axis: 0 }, 2.5)],
        )
        .unwrap();
        assert_eq!(
            t,
            "kind: machine_tool\nthermal:\n  spindle: { idle_w_per_rpm: 0.0, growth_um_per_kw: 5.0, time_constant_min: 30.0 }\n  axes:\n    X: { scale_ppm_per_kw: 2.5, time_constant_min: 9.0, friction_n: 1.0 }\n"
        );
    }

    #[test]
    fn machine_tool_tables_and_location_errors() {
        let text = "kind: machine_tool\naxes:\n  - name: X\n    type: linear\n    component_errors:\n      EBX_urad:\n        forward: [1.0]\n  - name: Y\n    type: linear\n    location_errors:\n      EC0Y_urad: 35.0  # sq\n# end\ntools: {}\n";
        let table = |axis, error, p: &[f64], f: &[f64], r: &[f64]| Edit::ComponentTable {
            axis,
            error,
            positions: p.to_vec(),
            forward: f.to_vec(),
            reverse: r.to_vec(),
        };
        let loc = |axis, r, v| {
            Edit::Tool(
                ToolParam::Location {
                    axis,
                    error: LocationParam::Angle(r),
                },
                v,
            )
        };
        let t = apply(
            text,
            "f",
            "t",
            &[
                table(0, 0, &[0.0, 100.0], &[0.0, 2.5], &[1.0, 3.0]),
                table(1, 1, &[0.0], &[0.0], &[0.5]),
                loc(1, 2, -12.5),
                loc(0, 1, 3.0),
            ],
        )
        .unwrap();
        let want = "kind: machine_tool\naxes:\n  - name: X\n    type: linear\n    component_errors:\n      EXX_um:\n        positions_mm: [0.0, 100.0]\n        forward: [0.0, 2.5]\n        reverse: [1.0, 3.0]\n      EBX_urad:\n        forward: [1.0]\n    location_errors:\n      EB0X_urad: 3.0\n  - name: Y\n    type: linear\n    location_errors:\n      EC0Y_urad: -12.5  # sq\n    component_errors:\n      EYY_um:\n        positions_mm: [0.0]\n        forward: [0.0]\n        reverse: [0.5]\n# end\ntools: {}\n";
        assert_eq!(t, want);
        let q = table(3, 3, &[], &[], &[]);
        assert!(apply(text, "f", "t", &[q]).is_err());
        let node = ToolParam::Component {
            axis: 0,
            error: 0,
            node: 0,
            forward: true,
        };
        assert!(apply(text, "f", "t", &[Edit::Tool(node, 1.0)]).is_err());
    }

    /// The edits a calibration or a diagnosis writes, one at a time, on a
    /// machine file of either kind: every value the file has, moved a
    /// little, and each structural edit.
    fn writes_of(m: &Machine) -> Vec<Edit> {
        let mut out = Vec::new();
        match m {
            Machine::Robot(r) => {
                let fields = [DhField::A, DhField::Alpha, DhField::D, DhField::ThetaOffset];
                let mut params: Vec<RobotParam> = (0..6)
                    .flat_map(|joint| fields.map(|field| RobotParam::Dh { joint, field }))
                    .collect();
                params.extend((0..6).map(|joint| RobotParam::JointStiffness { joint }));
                params.extend((0..3).map(|axis| RobotParam::ToolOffset { axis }));
                for term in 0..3 {
                    for field in [ThermalField::Lb, ThermalField::Ub, ThermalField::Ts] {
                        params.push(RobotParam::Thermal { term, field });
                    }
                }
                params.extend([RobotParam::ThermalTimeConstant, RobotParam::PayloadMass]);
                for p in params {
                    if let Some(v) = r.param_value(p) {
                        out.push(Edit::Robot(p, round_sig(v * 1.001 + 0.0625)));
                    }
                }
                out.push(Edit::ThermalTerm {
                    term: ThermalTermText {
                        parameter: "a2".into(),
                        joint: 2,
                        lb_mm: 0.01,
                        ub_mm: 0.25,
                        ts_per_w: 0.002,
                    },
                    time_constant_min: 45.0,
                    comment: "Identified by `postproc calibrate thermal`.".into(),
                });
                if r.param_value(RobotParam::ThermalTimeConstant).is_some() {
                    out.push(Edit::RatedPower {
                        watts: 812.5,
                        comment: "Highest mean motor power of a joint.".into(),
                    });
                }
            }
            Machine::Tool(t) => {
                let mut params = Vec::new();
                for axis in 0..6 {
                    for error in 0..6 {
                        for node in 0..3 {
                            for forward in [true, false] {
                                params.push(ToolParam::Component {
                                    axis,
                                    error,
                                    node,
                                    forward,
                                });
                            }
                        }
                    }
                    for k in 0..3 {
                        params.extend([
                            ToolParam::Location {
                                axis,
                                error: LocationParam::Offset(k),
                            },
                            ToolParam::Location {
                                axis,
                                error: LocationParam::Angle(k),
                            },
                        ]);
                    }
                    params.extend([
                        ToolParam::AxisScale { axis },
                        ToolParam::AxisTimeConstant { axis },
                    ]);
                }
                for k in 0..3 {
                    params.extend([
                        ToolParam::SpindleLocation {
                            error: LocationParam::Offset(k),
                        },
                        ToolParam::SpindleLocation {
                            error: LocationParam::Angle(k),
                        },
                    ]);
                }
                for dir in 0..3 {
                    for positive in [true, false] {
                        params.push(ToolParam::Stiffness {
                            dir,
                            positive,
                            cell: None,
                        });
                    }
                }
                params.extend([ToolParam::SpindleGrowth, ToolParam::SpindleTimeConstant]);
                for p in params {
                    if let Some(v) = t.param_value(p) {
                        out.push(Edit::Tool(p, round_sig(v * 1.001 + 0.0625)));
                    }
                }
                out.push(Edit::ComponentTable {
                    axis: 0,
                    error: 1,
                    positions: vec![-100.0, 0.0, 100.0],
                    forward: vec![-1.5, 0.0, 2.25],
                    reverse: vec![-1.0, 0.5, 2.0],
                });
                out.push(Edit::Spindle {
                    growth_um_per_kw: 7.5,
                    time_constant_min: 30.0,
                    comment: "Identified by `postproc calibrate thermal`.".into(),
                });
            }
        }
        out.push(Edit::MeasurementFrame {
            xyz_mm: [1.25, -2.5, 0.125],
            rpy_deg: [0.01, -0.02, 0.5],
        });
        out.push(Edit::Calibrated(Calibration {
            date: "2026-01-02".into(),
            kind: "geometry".into(),
            observations: "obs.csv".into(),
            observations_sha256: "0".repeat(64),
            rows: 12,
            fit_rms_mm: 0.0125,
        }));
        out.push(Edit::HeaderComment("Calibrated by a test.".into()));
        out
    }

    /// On every bundled machine file, each edit a calibration or a
    /// diagnosis writes is written by the tree editor byte for byte as the
    /// line editor writes it, wherever the line editor's text is the one
    /// [`apply`] keeps (it succeeds, keeps every comment and reads back).
    ///
    /// Ignored: it fails on 84 of the 966 edits, all of them new sections
    /// or keys, which the tree editor writes in flow style on one line
    /// where the line editor writes block lines (a new `thermal:` section
    /// with its term or spindle entry, a component table added to an axis,
    /// the `measurement_frame` section and its wrapped comment), puts a new
    /// `location_errors` map first in its axis entry, and keeps the comment
    /// after `status: nominal` when it writes `status: calibrated`. The
    /// line editor can go once this test passes (`cargo test --lib
    /// the_tree_editor -- --ignored`).
    #[test]
    fn the_tree_editor_writes_the_bundled_files_as_the_line_editor() {
        let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/machines");
        let mut names: Vec<String> = std::fs::read_dir(dir)
            .expect("machines/")
            .filter_map(|e| e.ok()?.file_name().into_string().ok())
            .filter(|n| n.ends_with(".yaml"))
            .collect();
        names.sort();
        assert!(names.len() > 20, "{names:?}");
        let (mut compared, mut differ) = (0, Vec::new());
        for name in &names {
            let text = bundled(name);
            let m = Machine::from_yaml_str(&text, name).expect("bundled file loads");
            for edit in writes_of(&m) {
                let edits = std::slice::from_ref(&edit);
                let Ok(line) = apply_one(&text, name, "postproc test", &edit) else {
                    continue;
                };
                if reads_back(&line, edits) != ReadBack::Values || !comments_kept(&text, &line) {
                    continue;
                }
                compared += 1;
                match tree::apply(&text, name, "postproc test", edits) {
                    Ok(t) if t == line => {}
                    Ok(t) => {
                        let at = line
                            .lines()
                            .zip(t.lines())
                            .position(|(a, b)| a != b)
                            .unwrap_or(0);
                        differ.push(format!(
                            "{name} {edit:?}: line {}: {:?} / {:?}",
                            at + 1,
                            line.lines().nth(at),
                            t.lines().nth(at)
                        ));
                    }
                    Err(e) => differ.push(format!("{name} {edit:?}: tree: {e}")),
                }
            }
        }
        assert!(compared > 500, "{compared} edits compared");
        assert!(
            differ.is_empty(),
            "{} of {compared} differ:\n{}",
            differ.len(),
            differ.join("\n")
        );
    }
}
