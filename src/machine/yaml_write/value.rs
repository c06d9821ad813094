//! The machine-file writer for layouts the in-place editor does not edit
//! (PyYAML's default layout with sequence items level with their key,
//! block lists of numbers, block maps where the bundled files write one-line
//! flow maps, axis entries whose `name` is not the first key, …): the
//! document is read as YAML values, the edits are applied to the values by
//! key path, and the document is written again. Everything the loader
//! reads is reached, whatever its layout; the comments above the first key
//! are kept (with the added header comments), inner comments are not, and
//! a comment line says so.

use serde_yaml::{Mapping, Value};

use super::{Edit, LETTERS, edit_err, round_to};
use crate::error::Result;
use crate::machine::robot::RobotParam;
use crate::machine::tool::ToolParam;

/// The comment line a rewritten document starts its body with.
pub const REWRITTEN: &str = "# Rewritten by postproc: this file's layout could not be edited in place, so the document was written again (comments inside it are not kept).";

fn num(v: f64) -> Value {
    Value::Number(serde_yaml::Number::from(v))
}

fn key(k: &str) -> Value {
    Value::String(k.into())
}

fn map(pairs: Vec<(&str, Value)>) -> Value {
    let mut m = Mapping::new();
    for (k, v) in pairs {
        m.insert(key(k), v);
    }
    Value::Mapping(m)
}

/// The value at the key path `path` (`a.b[2].c`, `axes[X]` = the item of
/// `axes` whose `name` is `X`); with `create`, missing mapping keys are
/// added as empty mappings.
fn resolve<'a>(mut cur: &'a mut Value, path: &str, create: bool) -> Option<&'a mut Value> {
    for seg in path.split('.') {
        let (k, idx) = match seg.split_once('[') {
            Some((k, rest)) => (k, Some(rest.trim_end_matches(']'))),
            None => (seg, None),
        };
        if !k.is_empty() {
            let m = cur.as_mapping_mut()?;
            if !m.contains_key(key(k)) {
                if !create {
                    return None;
                }
                m.insert(key(k), Value::Mapping(Mapping::new()));
            }
            cur = m.get_mut(key(k))?;
        }
        if let Some(i) = idx {
            let seq = cur.as_sequence_mut()?;
            cur = match i.parse::<usize>() {
                Ok(n) => seq.get_mut(n)?,
                Err(_) => seq
                    .iter_mut()
                    .find(|v| v.get("name").and_then(Value::as_str) == Some(i))?,
            };
        }
    }
    Some(cur)
}

/// Sets the number at `path` (which must exist unless `create`).
fn set(doc: &mut Value, file: &str, path: &str, v: f64, create: bool) -> Result<()> {
    let slot = resolve(doc, path, create)
        .ok_or_else(|| edit_err(file, format!("no value at `{path}`")))?;
    *slot = num(v);
    Ok(())
}

fn top<'a>(doc: &'a mut Value, file: &str) -> Result<&'a mut Mapping> {
    doc.as_mapping_mut()
        .ok_or_else(|| edit_err(file, "the document is not a mapping"))
}

fn robot(doc: &mut Value, file: &str, p: RobotParam, v: f64) -> Result<()> {
    let tcp: Vec<Value> = ["x_mm", "y_mm", "z_mm"]
        .iter()
        .map(|k| {
            num(doc
                .get("flange_to_tool")
                .and_then(|f| f.get(k))
                .and_then(Value::as_f64)
                .unwrap_or(0.0))
        })
        .collect();
    let m = top(doc, file)?;
    match p {
        RobotParam::Dh { .. } if !m.contains_key(key("actual")) => {
            let nominal = m
                .get(key("nominal"))
                .cloned()
                .ok_or_else(|| edit_err(file, "no `nominal` to copy into `actual`"))?;
            m.insert(key("actual"), nominal);
        }
        RobotParam::ToolOffset { .. } if !m.contains_key(key("flange_to_tool")) => {
            m.insert(
                key("flange_to_tool"),
                map(vec![
                    ("x_mm", num(0.0)),
                    ("y_mm", num(0.0)),
                    ("z_mm", num(0.0)),
                ]),
            );
        }
        RobotParam::PayloadMass if !m.contains_key(key("tool_load")) => {
            m.insert(
                key("tool_load"),
                map(vec![
                    ("mass_kg", num(0.0)),
                    ("cog_mm", Value::Sequence(tcp)),
                ]),
            );
        }
        _ => {}
    }
    set(doc, file, &p.path(), v, false)
}

fn tool(doc: &mut Value, file: &str, p: ToolParam, v: f64) -> Result<()> {
    match p {
        ToolParam::Component { .. } => Err(edit_err(
            file,
            format!(
                "`{}`: a component table is written whole, positions and both columns",
                p.path()
            ),
        )),
        ToolParam::Stiffness {
            cell: Some(cell), ..
        } => {
            let mut slot = resolve(doc, &p.path(), false);
            for i in cell {
                slot = slot
                    .and_then(|s| s.as_sequence_mut())
                    .and_then(|s| s.get_mut(i));
            }
            let slot =
                slot.ok_or_else(|| edit_err(file, format!("no grid cell at `{}`", p.path())))?;
            *slot = num(v);
            Ok(())
        }
        // A location error may be added with its section.
        ToolParam::Location { .. } | ToolParam::SpindleLocation { .. } => {
            set(doc, file, &p.path(), v, true)
        }
        _ => set(doc, file, &p.path(), v, false),
    }
}

/// The `thermal` mapping, added (with `init`) when absent.
fn thermal<'a>(
    doc: &'a mut Value,
    file: &str,
    init: Vec<(&str, Value)>,
) -> Result<&'a mut Mapping> {
    let m = top(doc, file)?;
    if !m.contains_key(key("thermal")) {
        m.insert(key("thermal"), map(init));
    }
    m.get_mut(key("thermal"))
        .and_then(Value::as_mapping_mut)
        .ok_or_else(|| edit_err(file, "`thermal` is not a mapping"))
}

/// Applies one edit to the document; header comments go to `header`.
fn one(doc: &mut Value, file: &str, edit: &Edit, header: &mut Vec<String>) -> Result<()> {
    match edit {
        Edit::Robot(p, v) => robot(doc, file, *p, *v),
        Edit::Tool(p, v) => tool(doc, file, *p, *v),
        Edit::ComponentTable {
            axis,
            error,
            positions,
            forward,
            reverse,
        } => {
            let l = |s: usize| LETTERS.get(s).copied().unwrap_or('?');
            let unit = if *error < 3 { "um" } else { "urad" };
            let path = format!(
                "axes[{}].component_errors.E{}{}_{unit}",
                l(*axis),
                l(*error),
                l(*axis)
            );
            let slot = resolve(doc, &path, true)
                .ok_or_else(|| edit_err(file, format!("no axis entry for `{path}`")))?;
            let list = |v: &[f64]| Value::Sequence(v.iter().map(|x| num(*x)).collect());
            let pos = if *axis < 3 {
                "positions_mm"
            } else {
                "positions_deg"
            };
            *slot = map(vec![
                (pos, list(positions)),
                ("forward", list(forward)),
                ("reverse", list(reverse)),
            ]);
            Ok(())
        }
        Edit::ThermalTerm {
            term,
            time_constant_min,
            comment,
        } => {
            if doc.get("thermal").is_none() && !comment.is_empty() {
                header.push(format!("# {comment}"));
            }
            let t = thermal(
                doc,
                file,
                vec![
                    ("time_constant_min", num(*time_constant_min)),
                    ("terms", Value::Sequence(Vec::new())),
                ],
            )?;
            if !t.contains_key(key("terms")) {
                t.insert(key("terms"), Value::Sequence(Vec::new()));
            }
            let terms = t
                .get_mut(key("terms"))
                .and_then(Value::as_sequence_mut)
                .ok_or_else(|| edit_err(file, "`thermal.terms` is not a list"))?;
            terms.push(map(vec![
                ("parameter", key(&term.parameter)),
                ("joint", Value::Number((term.joint as u64).into())),
                ("lb_mm", num(term.lb_mm)),
                ("ub_mm", num(term.ub_mm)),
                ("ts_per_w", num(term.ts_per_w)),
            ]));
            Ok(())
        }
        Edit::RatedPower { watts, comment } => {
            if doc.get("thermal").is_none() {
                return Err(edit_err(file, "no `thermal:` section for `rated_power_w`"));
            }
            if !comment.is_empty() {
                header.push(format!("# {comment}"));
            }
            thermal(doc, file, Vec::new())?.insert(key("rated_power_w"), num(*watts));
            Ok(())
        }
        Edit::Spindle {
            growth_um_per_kw,
            time_constant_min,
            comment,
        } => {
            if !comment.is_empty() {
                header.push(format!("# {comment}"));
            }
            let t = thermal(doc, file, Vec::new())?;
            if t.contains_key(key("spindle")) {
                return Err(edit_err(file, "`thermal.spindle` exists already"));
            }
            t.insert(
                key("spindle"),
                map(vec![
                    ("idle_w_per_rpm", num(0.0)),
                    ("growth_um_per_kw", num(*growth_um_per_kw)),
                    ("time_constant_min", num(*time_constant_min)),
                ]),
            );
            Ok(())
        }
        Edit::MeasurementFrame { xyz_mm, rpy_deg } => {
            let rpy = Value::Sequence(rpy_deg.iter().map(|v| num(round_to(*v, 6))).collect());
            let frame = map(vec![
                ("x_mm", num(round_to(xyz_mm[0], 4))),
                ("y_mm", num(round_to(xyz_mm[1], 4))),
                ("z_mm", num(round_to(xyz_mm[2], 4))),
                ("rpy_deg", rpy),
            ]);
            top(doc, file)?.insert(key("measurement_frame"), frame);
            Ok(())
        }
        Edit::Calibrated(c) => {
            let m = top(doc, file)?;
            m.insert(key("status"), key("calibrated"));
            if !m.contains_key(key("calibrations")) {
                m.insert(key("calibrations"), Value::Sequence(Vec::new()));
            }
            let list = m
                .get_mut(key("calibrations"))
                .and_then(Value::as_sequence_mut)
                .ok_or_else(|| edit_err(file, "`calibrations` is not a list"))?;
            list.push(map(vec![
                ("date", key(&c.date)),
                ("kind", key(&c.kind)),
                ("observations", key(&c.observations)),
                ("observations_sha256", key(&c.observations_sha256)),
                ("rows", Value::Number((c.rows as u64).into())),
                ("fit_rms_mm", num(round_to(c.fit_rms_mm, 4))),
            ]));
            Ok(())
        }
        Edit::HeaderComment(c) => {
            header.push(format!("# {c}"));
            Ok(())
        }
    }
}

/// Applies `edits` to the document `text` read as values and writes it
/// again (see the module comment).
pub(super) fn apply(text: &str, file: &str, edits: &[Edit]) -> Result<String> {
    let mut doc: Value = serde_yaml::from_str(text)
        .map_err(|e| edit_err(file, format!("the file does not read as YAML: {e}")))?;
    let mut header: Vec<String> = text
        .lines()
        .take_while(|l| l.starts_with('#') || l.trim().is_empty())
        .filter(|l| *l != REWRITTEN)
        .map(str::to_string)
        .collect();
    while header.last().is_some_and(|l| l.trim().is_empty()) {
        header.pop();
    }
    for e in edits {
        one(&mut doc, file, e, &mut header)?;
    }
    let body = serde_yaml::to_string(&doc)
        .map_err(|e| edit_err(file, format!("cannot write the document: {e}")))?;
    let mut out = header.join("\n");
    if !out.is_empty() {
        out.push('\n');
    }
    out.push_str(REWRITTEN);
    out.push('\n');
    out.push_str(&body);
    Ok(out)
}
