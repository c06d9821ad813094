//! Writing identified values into a machine file *as text*: the values of
//! the keys that were identified are replaced in place, every comment, key
//! order and layout of the original file is kept. Supported layouts are the
//! ones of the bundled machine files: top-level flow lists
//! (`k_nm_per_rad: [1, 2, 3]`), top-level flow maps on one line
//! (`flange_to_tool: { x_mm: 0, … }`), DH sections written as a block list of
//! one-line flow maps (`actual:` followed by `  - { a_mm: …, … }` rows), and
//! machine-tool component tables (`EXX_um:` with `positions_mm`, `forward`,
//! `reverse` flow lists). Anything else is a clear error; the caller re-loads
//! the result with `Machine::from_yaml_str` to prove it is valid.

use crate::error::{Error, Result};

/// Formats a value with at most `decimals` decimals, trailing zeros removed
/// (one decimal is kept so the value reads as a float).
pub fn fmt_value(v: f64, decimals: usize) -> String {
    let v = if v == 0.0 { 0.0 } else { v };
    let s = format!("{v:.decimals$}");
    if !s.contains('.') {
        return format!("{s}.0");
    }
    let t = s.trim_end_matches('0');
    let t = if t.ends_with('.') {
        format!("{t}0")
    } else {
        t.to_string()
    };
    if t == "-0.0" { "0.0".into() } else { t }
}

fn edit_err(file: &str, msg: impl Into<String>) -> Error {
    Error::Usage(format!(
        "{file}: cannot write the calibrated values: {}",
        msg.into()
    ))
}

/// Index of the top-level line `key:` (no indentation).
fn top_level_line(lines: &[String], key: &str) -> Option<usize> {
    let prefix = format!("{key}:");
    lines.iter().position(|l| l.starts_with(&prefix))
}

/// Splits a line into (content, comment) at the first `#` outside brackets
/// that follows a blank.
fn split_comment(line: &str) -> (&str, &str) {
    let b = line.as_bytes();
    for i in 0..b.len() {
        if b[i] == b'#' && (i == 0 || b[i - 1] == b' ' || b[i - 1] == b'\t') {
            return line.split_at(i);
        }
    }
    (line, "")
}

/// Replaces the flow list `[ … ]` on a line with `values`.
fn replace_list_in_line(line: &str, values: &[String]) -> Option<String> {
    let (content, comment) = split_comment(line);
    let open = content.find('[')?;
    let close = content.rfind(']')?;
    if close < open {
        return None;
    }
    let mut out = String::with_capacity(line.len() + 16);
    out.push_str(&content[..open]);
    out.push('[');
    out.push_str(&values.join(", "));
    out.push(']');
    out.push_str(&content[close + 1..]);
    out.push_str(comment);
    Some(out)
}

/// Replaces the top-level flow list `key: [ … ]` by `values`.
pub fn set_top_level_list(text: &str, file: &str, key: &str, values: &[String]) -> Result<String> {
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    let i = top_level_line(&lines, key)
        .ok_or_else(|| edit_err(file, format!("no top-level key `{key}`")))?;
    let new = replace_list_in_line(&lines[i], values)
        .ok_or_else(|| edit_err(file, format!("`{key}` is not a one-line flow list `[…]`")))?;
    lines[i] = new;
    Ok(join(lines, text))
}

fn join(lines: Vec<String>, original: &str) -> String {
    let mut s = lines.join("\n");
    if original.ends_with('\n') {
        s.push('\n');
    }
    s
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

/// Replaces `x_mm`, `y_mm`, `z_mm` of a top-level one-line frame map
/// (`flange_to_tool`, `base`).
pub fn set_frame_translation(
    text: &str,
    file: &str,
    key: &str,
    xyz_mm: [f64; 3],
) -> Result<String> {
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    let i = top_level_line(&lines, key)
        .ok_or_else(|| edit_err(file, format!("no top-level key `{key}`")))?;
    let pairs = [
        ("x_mm", fmt_value(xyz_mm[0], 4)),
        ("y_mm", fmt_value(xyz_mm[1], 4)),
        ("z_mm", fmt_value(xyz_mm[2], 4)),
    ];
    lines[i] = replace_map_values(&lines[i], &pairs).ok_or_else(|| {
        edit_err(
            file,
            format!("`{key}` is not a one-line flow map with x_mm, y_mm, z_mm"),
        )
    })?;
    Ok(join(lines, text))
}

/// Sets the top-level `measurement_frame:` (the pose of the measuring
/// instrument in the machine's reference frame) to a one-line flow map
/// `{ x_mm, y_mm, z_mm, rpy_deg: [roll, pitch, yaw] }`: the existing line is
/// replaced (its comment kept; a block map under it is refused), otherwise
/// the key is appended at the end of the file with a comment saying what it is.
pub fn set_measurement_frame(
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
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    match top_level_line(&lines, "measurement_frame") {
        Some(i) => {
            let (content, comment) = split_comment(&lines[i]);
            if !content.contains('{') {
                return Err(edit_err(
                    file,
                    "`measurement_frame` is not a one-line flow map",
                ));
            }
            lines[i] = format!("measurement_frame: {value}{}", {
                if comment.is_empty() {
                    String::new()
                } else {
                    format!("  {}", comment.trim_start())
                }
            });
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

/// One DH row as written in a machine file (lengths mm, angles degrees).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DhRow {
    /// `a_mm`.
    pub a_mm: f64,
    /// `alpha_deg`.
    pub alpha_deg: f64,
    /// `d_mm`.
    pub d_mm: f64,
    /// `theta_offset_deg`.
    pub theta_offset_deg: f64,
}

impl DhRow {
    fn pairs(&self) -> [(&'static str, String); 4] {
        [
            ("a_mm", fmt_value(self.a_mm, 4)),
            ("alpha_deg", fmt_value(self.alpha_deg, 5)),
            ("d_mm", fmt_value(self.d_mm, 4)),
            ("theta_offset_deg", fmt_value(self.theta_offset_deg, 5)),
        ]
    }
    fn flow(&self) -> String {
        let p = self.pairs();
        format!(
            "  - {{ a_mm: {}, alpha_deg: {}, d_mm: {}, theta_offset_deg: {} }}",
            p[0].1, p[1].1, p[2].1, p[3].1
        )
    }
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

/// Writes the actual DH rows: edits the values of an existing `actual:`
/// section in place, or inserts a new section after the `nominal:` rows.
pub fn set_actual_dh(text: &str, file: &str, rows: &[DhRow; 6]) -> Result<String> {
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    if top_level_line(&lines, "actual").is_some() {
        let idx = dh_row_lines(&lines, "actual").ok_or_else(|| {
            edit_err(
                file,
                "`actual` is not a list of six one-line flow maps `- { a_mm: … }`",
            )
        })?;
        for (k, &li) in idx.iter().enumerate() {
            lines[li] = replace_map_values(&lines[li], &rows[k].pairs()).ok_or_else(|| {
                edit_err(
                    file,
                    format!(
                        "`actual` row {} lacks a_mm/alpha_deg/d_mm/theta_offset_deg",
                        k + 1
                    ),
                )
            })?;
        }
    } else {
        let idx = dh_row_lines(&lines, "nominal").ok_or_else(|| {
            edit_err(
                file,
                "`nominal` is not a list of six one-line flow maps `- { a_mm: … }`",
            )
        })?;
        let after = idx.last().copied().unwrap_or(0) + 1;
        let mut block = vec![
            "# Identified by `postproc calibrate kinematics`.".to_string(),
            "actual:".to_string(),
        ];
        block.extend(rows.iter().map(DhRow::flow));
        lines.splice(after..after, block);
    }
    Ok(join(lines, text))
}

fn indent_of(l: &str) -> usize {
    l.len() - l.trim_start().len()
}

fn is_content(l: &str) -> bool {
    let t = l.trim_start();
    !t.is_empty() && !t.starts_with('#')
}

/// Line range `[start, end)` of the entry `- name: AXIS` of the top-level
/// `axes:` list, and the indentation of its keys.
fn axis_entry(lines: &[String], file: &str, axis: &str) -> Result<(usize, usize, usize)> {
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
            if rest.trim() == axis {
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
fn ensure_section(lines: &mut Vec<String>, file: &str, axis: &str, section: &str) -> Result<usize> {
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

/// Decimals of the component-table values and location errors written
/// ([`set_component_table`], [`set_location_error`]): 0.01 µm or µrad.
pub const ERROR_DECIMALS: usize = 2;

/// `v` as [`set_component_table`] and [`set_location_error`] write it,
/// read back: the value a model read from the written file holds.
pub fn as_written(v: f64) -> f64 {
    fmt_value(v, ERROR_DECIMALS).parse().unwrap_or(v)
}

/// Writes a bidirectional component-error table `key` (e.g. `EXX_um`) of a
/// machine-tool axis: replaces the table when present, adds it (and the
/// `component_errors:` section) when not. Values in the file's units.
pub fn set_component_table(
    text: &str,
    file: &str,
    axis: &str,
    key: &str,
    positions_mm: &[f64],
    forward: &[f64],
    reverse: &[f64],
) -> Result<String> {
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    let sec = ensure_section(&mut lines, file, axis, "component_errors")?;
    let sec_end = block_end(&lines, sec, lines.len());
    let child_indent = (sec + 1..sec_end)
        .find(|&i| is_content(&lines[i]))
        .map_or(indent_of(&lines[sec]) + 2, |i| indent_of(&lines[i]));
    let list = |v: &[f64], d: usize| -> String {
        v.iter()
            .map(|x| fmt_value(*x, d))
            .collect::<Vec<_>>()
            .join(", ")
    };
    let pad = " ".repeat(child_indent);
    let new = vec![
        format!("{pad}{key}:"),
        format!("{pad}  positions_mm: [{}]", list(positions_mm, 3)),
        format!("{pad}  forward: [{}]", list(forward, ERROR_DECIMALS)),
        format!("{pad}  reverse: [{}]", list(reverse, ERROR_DECIMALS)),
    ];
    match key_line(&lines, sec + 1, sec_end, child_indent, key) {
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
pub fn set_location_error(
    text: &str,
    file: &str,
    axis: &str,
    key: &str,
    value: f64,
) -> Result<String> {
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    let sec = ensure_section(&mut lines, file, axis, "location_errors")?;
    let sec_end = block_end(&lines, sec, lines.len());
    let child_indent = (sec + 1..sec_end)
        .find(|&i| is_content(&lines[i]))
        .map_or(indent_of(&lines[sec]) + 2, |i| indent_of(&lines[i]));
    let v = fmt_value(value, ERROR_DECIMALS);
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

fn term_flow(t: &ThermalTermText) -> String {
    format!(
        "{{ parameter: {}, joint: {}, lb_mm: {}, ub_mm: {}, ts_per_w: {} }}",
        t.parameter,
        t.joint,
        fmt_value(t.lb_mm, 6),
        fmt_value(t.ub_mm, 6),
        fmt_sig(t.ts_per_w)
    )
}

/// A small positive or negative number with six significant digits
/// (`ts_per_w` can be 1e-6).
fn fmt_sig(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return "0.0".into();
    }
    let digits = (5 - v.abs().log10().floor() as i64).clamp(1, 15) as usize;
    fmt_value(v, digits)
}

/// Replaces `lb_mm`, `ub_mm`, `ts_per_w` of the robot thermal term
/// `thermal.terms[index]` (a one-line flow map).
pub fn set_thermal_term(
    text: &str,
    file: &str,
    index: usize,
    lb_mm: f64,
    ub_mm: f64,
    ts_per_w: f64,
) -> Result<String> {
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    let path = format!("thermal.terms[{index}]");
    let bad = || {
        edit_err(
            file,
            format!(
                "`{path}` is not a one-line flow map `- {{ parameter: …, lb_mm: …, ub_mm: …, ts_per_w: … }}`"
            ),
        )
    };
    let (line, _) = crate::machine::yaml::locate(text, &path).ok_or_else(bad)?;
    let i = line.checked_sub(1).ok_or_else(bad)?;
    let l = lines.get(i).ok_or_else(bad)?;
    if !(l.trim_start().starts_with("- {") && l.contains("parameter:")) {
        return Err(bad());
    }
    let pairs = [
        ("lb_mm", fmt_value(lb_mm, 6)),
        ("ub_mm", fmt_value(ub_mm, 6)),
        ("ts_per_w", fmt_sig(ts_per_w)),
    ];
    let new = replace_map_values(l, &pairs).ok_or_else(bad)?;
    lines[i] = new;
    Ok(join(lines, text))
}

/// Adds a robot thermal term: to the block list `thermal.terms` when the
/// file has a `thermal:` section, else a new section at the end of the file
/// with `time_constant_min` (which steady-state rows cannot identify; the
/// caller says where it comes from in `comment`).
pub fn add_thermal_term(
    text: &str,
    file: &str,
    term: &ThermalTermText,
    time_constant_min: f64,
    comment: &str,
) -> Result<String> {
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
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
            while lines.last().is_some_and(|l| l.trim().is_empty()) {
                lines.pop();
            }
            if !comment.is_empty() {
                lines.push(format!("# {comment}"));
            }
            lines.push("thermal:".into());
            lines.push(format!(
                "  time_constant_min: {}",
                fmt_value(time_constant_min, 3)
            ));
            lines.push("  terms:".into());
            lines.push(format!("    - {item}"));
        }
    }
    let mut s = lines.join("\n");
    s.push('\n');
    Ok(s)
}

/// Sets `scale_ppm_per_kw` of the one-line flow map `thermal.axes.<axis>`.
pub fn set_axis_scale(text: &str, file: &str, axis: &str, scale_ppm_per_kw: f64) -> Result<String> {
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    let path = format!("thermal.axes.{axis}");
    let bad = || {
        edit_err(
            file,
            format!("`{path}` is not a one-line flow map with scale_ppm_per_kw"),
        )
    };
    let (line, _) = crate::machine::yaml::locate(text, &path).ok_or_else(bad)?;
    let i = line.checked_sub(1).ok_or_else(bad)?;
    let l = lines.get(i).ok_or_else(bad)?;
    if !(l.trim_start().starts_with(&format!("{axis}:")) && l.contains("scale_ppm_per_kw:")) {
        return Err(bad());
    }
    let new = replace_map_values(l, &[("scale_ppm_per_kw", fmt_value(scale_ppm_per_kw, 6))])
        .ok_or_else(bad)?;
    lines[i] = new;
    Ok(join(lines, text))
}

/// Sets `thermal.spindle.growth_um_per_kw` of a machine-tool file: in the
/// one-line flow map `spindle: { … }` when present, else adds `spindle:`
/// (to the `thermal:` section, or a new section at the end) with
/// `idle_w_per_rpm: 0.0` and `time_constant_min` (not identified from
/// steady-state rows; the caller explains it in `comment`).
pub fn set_spindle_growth(
    text: &str,
    file: &str,
    growth_um_per_kw: f64,
    time_constant_min: f64,
    comment: &str,
) -> Result<String> {
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    let g = fmt_value(growth_um_per_kw, 6);
    let new_map = format!(
        "{{ idle_w_per_rpm: 0.0, growth_um_per_kw: {g}, time_constant_min: {} }}",
        fmt_value(time_constant_min, 3)
    );
    match top_level_line(&lines, "thermal") {
        Some(t) => {
            let end = block_end(&lines, t, lines.len());
            match (t + 1..end).find(|&i| lines[i].trim_start().starts_with("spindle:")) {
                Some(k) => {
                    let l = &lines[k];
                    if !(l.contains('{') && l.contains("growth_um_per_kw:")) {
                        return Err(edit_err(
                            file,
                            "`thermal.spindle` is not a one-line flow map with growth_um_per_kw",
                        ));
                    }
                    let new =
                        replace_map_values(l, &[("growth_um_per_kw", g)]).ok_or_else(|| {
                            edit_err(file, "cannot edit `thermal.spindle.growth_um_per_kw`")
                        })?;
                    lines[k] = new;
                }
                None => {
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
            }
        }
        None => {
            while lines.last().is_some_and(|l| l.trim().is_empty()) {
                lines.pop();
            }
            if !comment.is_empty() {
                lines.push(format!("# {comment}"));
            }
            lines.push("thermal:".into());
            lines.push(format!("  spindle: {new_map}"));
        }
    }
    let mut s = lines.join("\n");
    s.push('\n');
    Ok(s)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lists_maps_and_rows_are_edited_in_place() {
        let text = "# c\nk_nm_per_rad: [1.0, 2.0]  # keep\nflange_to_tool: { x_mm: 0.0, y_mm: 0.0, z_mm: 150.0, quaternion: [1.0, 0.0, 0.0, 0.0] }\n";
        let t =
            set_top_level_list(text, "f", "k_nm_per_rad", &["3.5".into(), "4.0".into()]).unwrap();
        assert_eq!(t.lines().nth(1), Some("k_nm_per_rad: [3.5, 4.0]  # keep"));
        let t = set_frame_translation(&t, "f", "flange_to_tool", [0.1, -0.2, 150.25]).unwrap();
        assert_eq!(
            t.lines().nth(2),
            Some(
                "flange_to_tool: { x_mm: 0.1, y_mm: -0.2, z_mm: 150.25, quaternion: [1.0, 0.0, 0.0, 0.0] }"
            )
        );
        assert!(set_top_level_list(text, "f", "missing", &[]).is_err());
        assert_eq!(fmt_value(2.0, 3), "2.0");
        assert_eq!(fmt_value(-0.00001, 3), "0.0");
        assert_eq!(fmt_value(1.23456, 3), "1.235");
    }

    #[test]
    fn thermal_terms_set_and_added() {
        let text = "kind: robot\nthermal:\n  time_constant_min: 30  # c\n  terms:\n    - { parameter: a2, joint: 1, lb_mm: 0.10, ub_mm: 0.10, ts_per_w: 0.015 }  # J1\n    - { parameter: a2, joint: 2, lb_mm: 0.12, ub_mm: 0.12, ts_per_w: 0.020 }\nmodal: []\n";
        let t = set_thermal_term(text, "f", 1, 0.25, 0.2, 0.0123456789).unwrap();
        assert_eq!(
            t.lines().nth(5),
            Some("    - { parameter: a2, joint: 2, lb_mm: 0.25, ub_mm: 0.2, ts_per_w: 0.0123457 }")
        );
        assert!(t.contains("ts_per_w: 0.015 }  # J1"));
        assert!(set_thermal_term(text, "f", 2, 0.0, 0.0, 0.0).is_err());
        let term = ThermalTermText {
            parameter: "a3".into(),
            joint: 2,
            lb_mm: 300.0,
            ub_mm: 300.0,
            ts_per_w: 1e-6,
        };
        let t = add_thermal_term(text, "f", &term, 30.0, "").unwrap();
        assert_eq!(
            t.lines().nth(6),
            Some(
                "    - { parameter: a3, joint: 2, lb_mm: 300.0, ub_mm: 300.0, ts_per_w: 0.000001 }"
            )
        );
        assert_eq!(t.lines().nth(7), Some("modal: []"));
        let t = add_thermal_term("kind: robot\n", "f", &term, 30.0, "assumed").unwrap();
        assert_eq!(
            t,
            "kind: robot\n# assumed\nthermal:\n  time_constant_min: 30.0\n  terms:\n    - { parameter: a3, joint: 2, lb_mm: 300.0, ub_mm: 300.0, ts_per_w: 0.000001 }\n"
        );
    }

    #[test]
    fn spindle_growth_set_and_added() {
        let text = "kind: machine_tool\nthermal:\n  spindle: { idle_w_per_rpm: 0.2, growth_um_per_kw: 3.0, time_constant_min: 25.0 }\n";
        let t = set_spindle_growth(text, "f", 7.25, 30.0, "").unwrap();
        assert_eq!(
            t.lines().nth(2),
            Some(
                "  spindle: { idle_w_per_rpm: 0.2, growth_um_per_kw: 7.25, time_constant_min: 25.0 }"
            )
        );
        let t = set_spindle_growth("kind: machine_tool\n", "f", 5.0, 30.0, "").unwrap();
        assert_eq!(
            t,
            "kind: machine_tool\nthermal:\n  spindle: { idle_w_per_rpm: 0.0, growth_um_per_kw: 5.0, time_constant_min: 30.0 }\n"
        );
        let t = set_spindle_growth(
            "kind: machine_tool\nthermal:\n  axes:\n    X: { scale_ppm_per_kw: 1.0, time_constant_min: 9.0, friction_n: 1.0 }\n",
            "f",
            5.0,
            30.0,
            "",
        )
        .unwrap();
        assert_eq!(
            t.lines().nth(2),
            Some(
                "  spindle: { idle_w_per_rpm: 0.0, growth_um_per_kw: 5.0, time_constant_min: 30.0 }"
            )
        );
    }

    #[test]
    fn machine_tool_tables_and_location_errors() {
        let text = "kind: machine_tool\naxes:\n  - name: X\n    type: linear\n    component_errors:\n      EBX_urad:\n        forward: [1.0]\n  - name: Y\n    type: linear\n    location_errors:\n      EC0Y_urad: 35.0  # sq\n# end\ntools: {}\n";
        let t = set_component_table(
            text,
            "f",
            "X",
            "EXX_um",
            &[0.0, 100.0],
            &[0.0, 2.5],
            &[1.0, 3.0],
        )
        .unwrap();
        let t = set_component_table(&t, "f", "Y", "EYY_um", &[0.0], &[0.0], &[0.5]).unwrap();
        let t = set_location_error(&t, "f", "Y", "EC0Y_urad", -12.5).unwrap();
        let t = set_location_error(&t, "f", "X", "EB0X_urad", 3.0).unwrap();
        let want = "kind: machine_tool\naxes:\n  - name: X\n    type: linear\n    component_errors:\n      EXX_um:\n        positions_mm: [0.0, 100.0]\n        forward: [0.0, 2.5]\n        reverse: [1.0, 3.0]\n      EBX_urad:\n        forward: [1.0]\n    location_errors:\n      EB0X_urad: 3.0\n  - name: Y\n    type: linear\n    location_errors:\n      EC0Y_urad: -12.5  # sq\n    component_errors:\n      EYY_um:\n        positions_mm: [0.0]\n        forward: [0.0]\n        reverse: [0.5]\n# end\ntools: {}\n";
        assert_eq!(t, want);
        assert!(set_component_table(text, "f", "Q", "EQQ_um", &[], &[], &[]).is_err());
    }
}
