//! The byte-faithful KRL writer: a compensated run over a KRL program's
//! move stream ([`crate::pipeline::robot`]) written back into its `.src`
//! and `.dat`. Only the numbers of the compensated targets change — `X`,
//! `Y`, `Z`, `A`, `B`, `C` of each aggregate, in place, and its `S` and `T`
//! when the compensated joint solution has another Status or Turn (written
//! as they were: a number or a `'B…'` bit string) — and, when annotated, a
//! `; dev …` comment ends each compensated motion line. Everything else
//! (folds, case, blanks, line ends) is the input's bytes.
//!
//! Positions get the robot's position decimals, angles that many plus one;
//! `A` and `C` are turned by whole turns to the written values nearest
//! (the same rotation). A point that two moves compensate differently
//! (another tool or base) keeps the first one's numbers; the second move
//! is warned about as left as written.

use std::collections::HashMap;
use std::ops::Range;

use nalgebra::Isometry3;

use crate::compensate::robot::Compensation;
use crate::emit::rapid::{EditList, push_fixed, write_dev_comment};
use crate::error::{Error, Result};
use crate::machine::robot::Robot;
use crate::program::euler::quaternion_to_zyx;
use crate::program::interp::Warning;
use crate::program::krl::config::StatusTurn;
use crate::program::krl::syntax::{Aggregate, File, Kind, Target, Value};
use crate::program::robot_moves::{LeftAsWritten, Place, RobotStep};

/// How the writer formats and what it adds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct KrlWrite {
    /// Decimals of positions, mm (angles get one more).
    pub position_decimals: usize,
    /// End each compensated motion line with a `; dev …` comment.
    pub annotate: bool,
    /// Write the compensated numbers (false: a run that predicts only).
    pub compensate: bool,
}

/// Every aggregate of a file by the start of its span.
fn aggregates(f: &File) -> HashMap<usize, &Aggregate> {
    let mut out: HashMap<usize, &Aggregate> = HashMap::new();
    for l in &f.lines {
        match &l.kind {
            Kind::Decl { value: Some(a), .. } | Kind::Assign(_, Some(a), _) => {
                out.insert(a.span.start, a);
            }
            Kind::Move { aux, target, .. } => {
                for t in aux.iter().chain([target]) {
                    if let Target::Aggregate(a) = t {
                        out.insert(a.span.start, a);
                    }
                }
            }
            _ => {}
        }
    }
    out
}

/// `v` turned by whole turns to the value nearest `written`, degrees.
fn nearest_turn(v: f64, written: f64) -> f64 {
    v + 360.0 * ((written - v) / 360.0).round()
}

/// A number with `decimals` decimals.
fn fixed(v: f64, decimals: usize) -> Result<String> {
    let mut s = String::new();
    if push_fixed(&mut s, v, decimals) {
        Ok(s)
    } else {
        Err(Error::Internal(format!(
            "a compensated value is not finite: {v}"
        )))
    }
}

/// The edits of one aggregate given its new pose (in its own frame) and,
/// when they changed, its new Status and Turn.
fn aggregate_edits(
    a: &Aggregate,
    pose: &Isometry3<f64>,
    st: Option<StatusTurn>,
    decimals: usize,
    edits: &mut Vec<(Range<usize>, String)>,
) -> Result<()> {
    let t = pose.translation.vector;
    let (za, yb, xc) = quaternion_to_zyx(&pose.rotation);
    let written = |k: &str| a.number(k).map_or(0.0, |n| n.value);
    let values = [
        ("X", t.x, decimals),
        ("Y", t.y, decimals),
        ("Z", t.z, decimals),
        ("A", nearest_turn(za, written("A")), decimals + 1),
        ("B", yb, decimals + 1),
        ("C", nearest_turn(xc, written("C")), decimals + 1),
    ];
    for (k, v, d) in values {
        let Some(n) = a.number(k) else {
            return Err(Error::Internal(format!("aggregate without {k}")));
        };
        edits.push((n.span.clone(), fixed(v, d)?));
    }
    if let Some(st) = st {
        for (k, v) in [("S", st.status), ("T", st.turn)] {
            match a.get(k) {
                Some(Value::Number(n)) => edits.push((n.span.clone(), v.to_string())),
                Some(Value::Bits(_, span)) => {
                    let width = span.len().saturating_sub(3);
                    edits.push((span.clone(), format!("'B{v:0width$b}'")));
                }
                _ => {}
            }
        }
    }
    Ok(())
}

/// The new Status and Turn of a compensated PTP target, when they differ
/// from those of its programmed joints and the aggregate writes them.
fn new_status_turn(robot: &Robot, a: &Aggregate, c: &Compensation) -> Option<StatusTurn> {
    a.bits("S")?;
    let before = StatusTurn::of_joints(robot, &c.q_programmed);
    let after = StatusTurn::of_joints(robot, &c.q_compensated);
    let keep_high = a.bits("S").unwrap_or(0) & !0b111;
    (before != after).then_some(StatusTurn {
        status: after.status | keep_high,
        ..after
    })
}

pub use crate::compensate::robot::Solved;

/// Writes a run back: the new texts of `texts` (the `.src`, then the data
/// files, as [`Place::source`] counts them) from the compensation of each
/// step, with the warnings of moves whose point another move compensated
/// differently.
pub fn rewrite(
    texts: &[&str],
    files: &[&File],
    steps: &[RobotStep],
    solved: &[Solved],
    (robot, u): (
        &Robot,
        Option<&crate::predict::uncertainty::BlockUncertainty>,
    ),
    how: KrlWrite,
) -> Result<(Vec<String>, Vec<Warning>)> {
    let found: Vec<_> = files.iter().map(|f| aggregates(f)).collect();
    let mut edits: Vec<Vec<(Range<usize>, String)>> = vec![Vec::new(); texts.len()];
    let mut owner: HashMap<Place, (usize, String)> = HashMap::new();
    let mut annotations = EditList::new();
    let mut warnings = Vec::new();
    let mut last_annotated = None;
    for (step, result) in steps.iter().zip(solved) {
        let (RobotStep::Target(t), Some((target, via))) = (step, result) else {
            continue;
        };
        if how.compensate {
            let places = std::iter::once((&t.place, target, true)).chain(
                t.via
                    .as_ref()
                    .zip(via.as_ref())
                    .map(|((_, p), c)| (p, c, false)),
            );
            for (place, comp, is_target) in places {
                let Some(a) = found
                    .get(place.source)
                    .and_then(|m| m.get(&place.span.start))
                else {
                    return Err(Error::Internal("a target's aggregate was not found".into()));
                };
                let pose = t.work.inverse() * comp.pose;
                let st = if is_target {
                    new_status_turn(robot, a, comp)
                } else {
                    None
                };
                let mut mine = Vec::new();
                aggregate_edits(a, &pose, st, how.position_decimals, &mut mine)?;
                let key: String = mine
                    .iter()
                    .map(|(_, s)| s.as_str())
                    .collect::<Vec<_>>()
                    .join(",");
                match owner.get(place) {
                    None => {
                        owner.insert(place.clone(), (t.line, key));
                        edits[place.source].extend(mine);
                    }
                    Some((_, k)) if *k == key => {}
                    Some((line, _)) => warnings.push(LeftAsWritten::warning(
                        t.line,
                        t.column,
                        t.instruction,
                        &format!(
                            "its point is compensated for the move at line {line}, with another tool, base or configuration"
                        ),
                    )),
                }
            }
        }
        if how.annotate && last_annotated != Some(t.line) {
            last_annotated = Some(t.line);
            let end = files
                .first()
                .and_then(|f| f.lines.get(t.line.wrapping_sub(1)))
                .map_or(0, |l| l.span.end);
            let mut c = String::from(" ; ");
            write_dev_comment(&mut c, &target.deviation);
            use crate::predict::robot_uncertainty::{push_u, target_u_mm};
            let dev = target.deviation.total.pos_mm;
            push_u(
                &mut c,
                u.and_then(|u| target_u_mm(u, &target.q_programmed, &dev)),
            );
            annotations.push_str(end..end, &c);
        }
    }
    let mut out = Vec::with_capacity(texts.len());
    for (i, text) in texts.iter().enumerate() {
        let mut list = if i == 0 {
            std::mem::take(&mut annotations)
        } else {
            EditList::new()
        };
        for (span, s) in &edits[i] {
            list.push_str(span.clone(), s);
        }
        out.push(list.apply(text)?);
    }
    Ok((out, warnings))
}
