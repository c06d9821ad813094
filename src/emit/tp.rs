//! The byte-faithful TP writer: a compensated run over a `.ls` program's
//! move stream ([`crate::pipeline::robot`]) written back into its `/POS`.
//! Only the numbers of the compensated positions change — `X`, `Y`, `Z`,
//! `W`, `P`, `R` of group `GP1`, in place, right-aligned in the width the
//! number and the blanks before it had (the controller's columns), and its
//! `CONFIG` when the compensated joint solution has other turn numbers.
//! Everything else is the input's bytes, but when annotated: TP has no
//! comment that could end a motion line, so each compensated motion is
//! followed by `!` remark lines (at most [`REMARK_CHARS`] characters each,
//! as the controller keeps them) with its predicted deviation (and its
//! expanded uncertainty ` U …`, k = 2, when the robot file carries a
//! kinematics covariance, as the KRL annotations state it), the `/MN`
//! lines after it renumbered and `/ATTR`'s `LINE_COUNT` raised by the
//! lines added. Without annotation `/MN` is the input's bytes.
//!
//! Positions and angles get the robot's position decimals (the controller
//! writes three); `W` and `R` are turned by whole turns to the written
//! values nearest (the same rotation). A position that two moves
//! compensate differently (another tool or configuration) keeps the first
//! one's numbers; the second move is warned about as left as written.

use std::collections::HashMap;
use std::ops::Range;

use crate::emit::rapid::{EditList, push_fixed, write_dev_comment};
use crate::error::{Error, Result};
use crate::machine::robot::Robot;
use crate::program::euler::quaternion_to_zyx;
use crate::program::interp::Warning;
use crate::program::robot_moves::{LeftAsWritten, Place, RobotStep};
use crate::program::tp::config::Config;
use crate::program::tp::{Group, Number, Position, Program};

/// How the writer formats.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TpWrite {
    /// Decimals of positions (mm) and angles (degrees).
    pub decimals: usize,
    /// Write the compensated numbers (false: a run that predicts only).
    pub compensate: bool,
    /// Follow each compensated motion with `!` remark lines giving its
    /// predicted deviation (the `/MN` lines after it renumbered and
    /// `LINE_COUNT` counting them).
    pub annotate: bool,
}

/// The most characters of a remark (`! …`) a FANUC controller keeps.
pub const REMARK_CHARS: usize = 32;

/// `text` cut at blanks into pieces of at most [`REMARK_CHARS`]
/// characters, never before a number (a value stays with its name); a
/// word longer than that is a piece of its own.
pub fn remark_pieces(text: &str) -> Vec<String> {
    let number = |w: &str| w.starts_with(|c: char| c.is_ascii_digit() || c == '-' || c == '+');
    // A name and the numbers after it are one item.
    let mut items: Vec<String> = Vec::new();
    for w in text.split(' ').filter(|w| !w.is_empty()) {
        match items.last_mut() {
            Some(last) if number(w) => {
                last.push(' ');
                last.push_str(w);
            }
            _ => items.push(w.to_string()),
        }
    }
    let mut out: Vec<String> = Vec::new();
    let mut line = String::new();
    for item in items {
        let fits = line.chars().count() + 1 + item.chars().count() <= REMARK_CHARS;
        if !line.is_empty() && !fits {
            out.push(std::mem::take(&mut line));
        }
        if !line.is_empty() {
            line.push(' ');
        }
        line.push_str(&item);
    }
    if !line.is_empty() {
        out.push(line);
    }
    out
}

/// The remark lines after `/MN` instructions and the renumbering they
/// need: `after` holds, in source order, the instruction (its index in
/// `program.mn`) each group of remarks follows and the remarks.
fn remark_edits(
    text: &str,
    program: &Program,
    after: &[(usize, Vec<String>)],
    edits: &mut EditList,
) {
    let eol = crate::emit::rapid::line_ending(text);
    let mut inserted = 0u32;
    let mut next = after.iter().peekable();
    for (i, l) in program.mn.iter().enumerate() {
        let n = l.number.saturating_add(inserted);
        if inserted > 0 {
            let width = l.number_span.len();
            edits.push_str(l.number_span.clone(), &format!("{n:>width$}"));
        }
        while let Some((_, remarks)) = next.next_if(|(k, _)| *k == i) {
            let mut s = String::new();
            if !text[..l.end].ends_with('\n') {
                s.push_str(eol);
            }
            for (k, r) in remarks.iter().enumerate() {
                let m = n.saturating_add(u32::try_from(k + 1).unwrap_or(u32::MAX));
                s.push_str(&format!("{m:>4}:  ! {r} ;{eol}"));
            }
            inserted = inserted.saturating_add(u32::try_from(remarks.len()).unwrap_or(u32::MAX));
            edits.push_str(l.end..l.end, &s);
        }
    }
    if let (Some((count, span)), true) = (&program.line_count, inserted > 0) {
        edits.push_str(span.clone(), &count.saturating_add(inserted).to_string());
    }
}

pub use crate::compensate::robot::Solved;

/// `v` turned by whole turns to the value nearest `written`, degrees.
fn nearest_turn(v: f64, written: f64) -> f64 {
    v + 360.0 * ((written - v) / 360.0).round()
}

/// The edit of number `n` to `v`: the number and the blanks before it
/// replaced by `v` right-aligned in their width (at least one blank kept
/// when there was one).
fn number_edit(text: &str, n: &Number, v: f64, decimals: usize) -> Result<(Range<usize>, String)> {
    let mut s = String::new();
    if !push_fixed(&mut s, v, decimals) {
        return Err(Error::Internal(format!(
            "a compensated value is not finite: {v}"
        )));
    }
    let before = text.get(..n.span.start).unwrap_or("");
    let blanks = before.len() - before.trim_end_matches(' ').len();
    let width = blanks + n.span.len();
    let min = s.len() + usize::from(blanks > 0);
    let field = format!("{s:>w$}", w = width.max(min));
    Ok((n.span.start - blanks..n.span.end, field))
}

/// The edits of a group given its new pose (in its user frame) and, when
/// it changed, its new configuration.
fn group_edits(
    text: &str,
    g: &Group,
    pose: &nalgebra::Isometry3<f64>,
    config: Option<Config>,
    decimals: usize,
) -> Result<Vec<(Range<usize>, String)>> {
    let t = pose.translation.vector;
    let (r, p, w) = quaternion_to_zyx(&pose.rotation);
    let written = |k: &str| g.value(k).map_or(0.0, |n| n.value);
    let values = [
        ("X", t.x),
        ("Y", t.y),
        ("Z", t.z),
        ("W", nearest_turn(w, written("W"))),
        ("P", p),
        ("R", nearest_turn(r, written("R"))),
    ];
    let mut out = Vec::with_capacity(7);
    for (k, v) in values {
        let n = g
            .value(k)
            .ok_or_else(|| Error::Internal(format!("position without {k}")))?;
        out.push(number_edit(text, n, v, decimals)?);
    }
    if let (Some(c), Some((_, span))) = (config, &g.config) {
        out.push((span.clone(), c.to_string()));
    }
    Ok(out)
}

/// A warning for each motion left as written whose position `P[n]`
/// another motion compensated: the motion runs to the compensated numbers
/// (a position is one set of numbers), which its own warning does not say.
fn shared_position_notes(
    program: &Program,
    steps: &[RobotStep],
    owner: &HashMap<Place, (usize, String)>,
    warnings: &mut Vec<Warning>,
) {
    let by_line: HashMap<usize, &crate::program::tp::MnLine> =
        program.mn.iter().map(|l| (l.line, l)).collect();
    for step in steps {
        let RobotStep::Left(w) = step else { continue };
        let Some(crate::program::tp::Instruction::Move { via, target, .. }) =
            by_line.get(&w.line).map(|l| &l.instruction)
        else {
            continue;
        };
        for r in via.iter().chain([target]).filter(|r| !r.register) {
            let Some(p) = program.position(r.index) else {
                continue;
            };
            let place = Place {
                source: 0,
                span: p.span.clone(),
            };
            if let Some((line, _)) = owner.get(&place) {
                warnings.push(Warning {
                    line: w.line,
                    message: format!(
                        "line {}: the motion is left as written but its position P[{}] is compensated for the move at line {line}: it runs to the compensated numbers",
                        w.line, r.index
                    ),
                    count: 1,
                    left: None,
                });
            }
        }
    }
}

/// Writes a run back: the new text of `text` from the compensation of each
/// step, with the warnings of moves whose position another move
/// compensated differently.
pub fn rewrite(
    text: &str,
    program: &Program,
    steps: &[RobotStep],
    solved: &[Solved],
    (robot, u): (
        &Robot,
        Option<&crate::predict::uncertainty::BlockUncertainty>,
    ),
    how: TpWrite,
) -> Result<(String, Vec<Warning>)> {
    let positions: HashMap<usize, &Position> = program
        .positions
        .iter()
        .map(|p| (p.span.start, p))
        .collect();
    let mut edits = EditList::new();
    let mut owner: HashMap<Place, (usize, String)> = HashMap::new();
    let mut warnings = Vec::new();
    let by_line: HashMap<usize, usize> = program
        .mn
        .iter()
        .enumerate()
        .map(|(i, l)| (l.line, i))
        .collect();
    let mut remarks: Vec<(usize, Vec<String>)> = Vec::new();
    for (step, result) in steps.iter().zip(solved) {
        let (RobotStep::Target(t), Some((target, via))) = (step, result) else {
            continue;
        };
        if how.annotate {
            let mut c = String::new();
            write_dev_comment(&mut c, &target.deviation);
            use crate::predict::robot_uncertainty::{push_u, target_u_mm};
            let dev = target.deviation.total.pos_mm;
            push_u(
                &mut c,
                u.and_then(|u| target_u_mm(u, &target.q_programmed, &dev)),
            );
            if let Some(&i) = by_line.get(&t.line) {
                if remarks.last().is_none_or(|(k, _)| *k != i) {
                    remarks.push((i, remark_pieces(&c)));
                }
            }
        }
        if !how.compensate {
            continue;
        }
        let places = std::iter::once((&t.place, target, true)).chain(
            t.via
                .as_ref()
                .zip(via.as_ref())
                .map(|((_, p), c)| (p, c, false)),
        );
        for (place, comp, is_target) in places {
            let group = positions
                .get(&place.span.start)
                .and_then(|p| p.groups.iter().find(|g| g.name == "GP1"))
                .ok_or_else(|| Error::Internal("a target's position was not found".into()))?;
            let pose = t.work.inverse() * comp.pose;
            let before = Config::of_joints(robot, &comp.q_programmed);
            let after = Config::of_joints(robot, &comp.q_compensated);
            let config = (is_target && before != after).then_some(after);
            let mine = group_edits(text, group, &pose, config, how.decimals)?;
            let key: String = mine
                .iter()
                .map(|(_, s)| s.trim())
                .collect::<Vec<_>>()
                .join(",");
            match owner.get(place) {
                None => {
                    owner.insert(place.clone(), (t.line, key));
                    for (span, s) in &mine {
                        edits.push_str(span.clone(), s);
                    }
                }
                Some((_, k)) if *k == key => {}
                Some((line, _)) => warnings.push(LeftAsWritten::warning(
                    t.line,
                    t.column,
                    t.instruction,
                    &format!(
                        "its position is compensated for the move at line {line}, with another tool or configuration"
                    ),
                )),
            }
        }
    }
    shared_position_notes(program, steps, &owner, &mut warnings);
    remarks.sort_by_key(|(i, _)| *i);
    remarks.dedup_by_key(|(i, _)| *i);
    remark_edits(text, program, &remarks, &mut edits);
    Ok((edits.apply(text)?, warnings))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_keep_their_columns() {
        let text = "X =   420.500  mm";
        let n = Number {
            value: 420.5,
            span: 6..13,
        };
        let (span, s) = number_edit(text, &n, 421.25, 3).expect("finite");
        assert_eq!((span, s.as_str()), (3..13, "   421.250"));
        let (_, s) = number_edit(text, &n, -1234.5, 3).expect("finite");
        assert_eq!(s, " -1234.500");
        let (_, s) = number_edit(text, &n, -123456.5, 3).expect("finite");
        assert_eq!(s, " -123456.500");
        assert!(number_edit(text, &n, f64::NAN, 3).is_err());
    }

    #[test]
    fn remarks_are_cut_at_names_within_the_controllers_length() {
        let dev = "dev 1.140 mm (kin 0.000 therm 0.000 grav 1.140 proc 0.000 vib 0.0000)";
        let pieces = remark_pieces(dev);
        assert_eq!(
            pieces,
            [
                "dev 1.140 mm (kin 0.000",
                "therm 0.000 grav 1.140",
                "proc 0.000 vib 0.0000)"
            ]
        );
        assert_eq!(pieces.join(" "), dev);
        // A piece longer than a remark stays whole rather than split a word.
        let long = "x".repeat(REMARK_CHARS + 3);
        assert_eq!(
            remark_pieces(&format!("a {long} b")),
            ["a", long.as_str(), "b"]
        );
        assert!(remark_pieces("").is_empty());
    }
}
