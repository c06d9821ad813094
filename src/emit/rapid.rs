//! Byte-faithful RAPID rewriting.
//!
//! The rewriter applies a list of [`Edit`]s (a byte span of the source and
//! its replacement text) and copies every other byte unchanged, so a program
//! with no edits comes out identical. Helpers format compensated robtarget
//! numbers (fixed decimals, never exponent notation, never `-0.000`), append
//! a `!` annotation at the end of a statement's line and insert new
//! declarations after an existing one with its indentation and line ending.
//!
//! The texts the RAPID pipeline writes are made here too: rewritten
//! robtarget and jointtarget literals, the `! dev …` comment of a
//! compensated move and the names of new declarations.

use std::collections::{HashMap, HashSet};
use std::ops::Range;

use nalgebra::Isometry3;

use crate::error::{Error, Located, Result};
use crate::machine::robot::ConfData;
use crate::predict::Breakdown;
use crate::program::rapid::resolve::line_col;
use crate::program::rapid::{Decl, JointTarget, RobTarget};

/// One edit: replace `span` of the source with `text` (an empty span inserts).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Edit {
    /// Byte range of the source to replace.
    pub span: Range<usize>,
    /// Replacement text.
    pub text: String,
}

impl Edit {
    /// Replaces `span` with `text`.
    pub fn replace(span: Range<usize>, text: impl Into<String>) -> Self {
        Edit {
            span,
            text: text.into(),
        }
    }

    /// Inserts `text` at byte offset `at`.
    pub fn insert(at: usize, text: impl Into<String>) -> Self {
        Edit {
            span: at..at,
            text: text.into(),
        }
    }
}

/// Number formatting of rewritten robtargets.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Format {
    /// Decimals of positions in mm (default 3).
    pub position_decimals: usize,
    /// Decimals of quaternion components (default 6).
    pub quaternion_decimals: usize,
}

impl Default for Format {
    fn default() -> Self {
        Format {
            position_decimals: 3,
            quaternion_decimals: 6,
        }
    }
}

/// Applies `edits` (non-overlapping, in any order) to `src`. Insertions at
/// the same offset keep their order in `edits`. Fails, without panicking, on
/// an edit outside the source, inside a UTF-8 character, or overlapping
/// another one: an [`Error::Internal`], as the writers never make such
/// edits.
pub fn apply_edits(src: &str, edits: &[Edit]) -> Result<String, Error> {
    let mut order: Vec<&Edit> = edits.iter().collect();
    order.sort_by_key(|e| (e.span.start, e.span.end));
    let extra: usize = edits.iter().map(|e| e.text.len()).sum();
    splice(
        src,
        order.into_iter().map(|e| (e.span.clone(), e.text.as_str())),
        extra,
    )
}

/// A list of edits whose texts share one buffer: pushing an edit allocates
/// nothing of its own (the list and the buffer grow amortised), so a
/// rewrite of a large module costs no allocation per edit.
/// [`EditList::apply`] is [`apply_edits`] of the same edits.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct EditList {
    /// Each edit's span of the source and the range of its text in `text`.
    items: Vec<(Range<usize>, Range<usize>)>,
    /// The edits' texts, one after the other.
    text: String,
}

impl EditList {
    /// An empty list.
    pub fn new() -> Self {
        Self::default()
    }

    /// Number of edits.
    pub fn len(&self) -> usize {
        self.items.len()
    }

    /// True when there is no edit.
    pub fn is_empty(&self) -> bool {
        self.items.is_empty()
    }

    /// Adds `edit` (its text copied into the shared buffer).
    pub fn push(&mut self, edit: &Edit) {
        self.push_str(edit.span.clone(), &edit.text);
    }

    /// Adds the replacement of `span` with `text`.
    pub fn push_str(&mut self, span: Range<usize>, text: &str) {
        let start = self.text.len();
        self.text.push_str(text);
        self.items.push((span, start..self.text.len()));
    }

    /// Adds an edit whose text `write` appends to the buffer and whose span
    /// it returns; on an error nothing is added. `write` must only append:
    /// a buffer shorter afterwards than before is refused (the edits
    /// before would lose their texts).
    pub fn push_with<E>(
        &mut self,
        write: impl FnOnce(&mut String) -> Result<Range<usize>, E>,
    ) -> Result<(), E> {
        let start = self.text.len();
        let written = write(&mut self.text);
        if self.text.len() < start {
            // Marks the list as broken: `apply` refuses it.
            self.items.push((0..0, start..start));
            return written.map(|_| ());
        }
        match written {
            Ok(span) => {
                self.items.push((span, start..self.text.len()));
                Ok(())
            }
            Err(e) => {
                self.text.truncate(start);
                Err(e)
            }
        }
    }

    /// The edits as [`Edit`]s, in the order they were added.
    pub fn to_edits(&self) -> Vec<Edit> {
        self.items
            .iter()
            .map(|(span, t)| Edit::replace(span.clone(), self.text.get(t.clone()).unwrap_or("")))
            .collect()
    }

    /// Splits the list at byte `boundary` of the source: the edits that
    /// start before it, and the others, each in the order pushed.
    pub fn split_at(&self, boundary: usize) -> (EditList, EditList) {
        let (mut below, mut rest) = (EditList::new(), EditList::new());
        for (span, t) in &self.items {
            let text = self.text.get(t.clone()).unwrap_or("");
            let side = if span.start < boundary {
                &mut below
            } else {
                &mut rest
            };
            side.push_str(span.clone(), text);
        }
        (below, rest)
    }

    /// Appends the edits of `other`, in their order.
    pub fn append(&mut self, other: &EditList) {
        for (span, t) in &other.items {
            self.push_str(span.clone(), other.text.get(t.clone()).unwrap_or(""));
        }
    }

    /// [`EditList::apply`] to the part `range` of `src`: every edit must
    /// lie within it (its spans count from the start of `src`).
    pub fn apply_in(&self, src: &str, range: Range<usize>) -> Result<String, Error> {
        let part = src.get(range.clone()).ok_or_else(|| {
            Error::Internal(format!(
                "part {range:?} is outside the program ({} bytes)",
                src.len()
            ))
        })?;
        let mut shifted = EditList::new();
        for (span, t) in &self.items {
            if span.start < range.start || span.end > range.end {
                return Err(Error::Internal(format!(
                    "edit {span:?} is outside the part {range:?} of the program"
                )));
            }
            let text = self.text.get(t.clone()).unwrap_or("");
            shifted.push_str(span.start - range.start..span.end - range.start, text);
        }
        shifted.apply(part)
    }

    /// `src` with the edits applied, as [`apply_edits`]. Fails on an edit
    /// whose text is not in the buffer (a writer that did not only append).
    pub fn apply(&self, src: &str) -> Result<String, Error> {
        let mut order = Vec::with_capacity(self.items.len());
        for (span, t) in &self.items {
            let text = self.text.get(t.clone()).ok_or_else(|| {
                Error::Internal(format!(
                    "edit text {t:?} is outside the edit buffer ({} bytes)",
                    self.text.len()
                ))
            })?;
            order.push((span.clone(), text));
        }
        order.sort_by_key(|(span, _)| (span.start, span.end));
        splice(src, order.into_iter(), self.text.len())
    }
}

/// `src` with the replacements `edits` (sorted by span) applied; `extra`
/// is the total length of their texts.
fn splice<'t>(
    src: &str,
    edits: impl Iterator<Item = (Range<usize>, &'t str)>,
    extra: usize,
) -> Result<String, Error> {
    let mut out = String::with_capacity(src.len() + extra);
    let mut at = 0;
    for (span, text) in edits {
        let Range { start, end } = span;
        if start > end || end > src.len() {
            return Err(Error::Internal(format!(
                "edit {start}..{end} is outside the program ({} bytes)",
                src.len()
            )));
        }
        if start < at {
            return Err(Error::Internal(format!(
                "edit {start}..{end} overlaps a previous edit ending at {at}"
            )));
        }
        let (Some(keep), Some(_)) = (src.get(at..start), src.get(start..end)) else {
            return Err(Error::Internal(format!(
                "edit {start}..{end} does not fall on character boundaries"
            )));
        };
        out.push_str(keep);
        out.push_str(text);
        at = end;
    }
    out.push_str(src.get(at..).unwrap_or(""));
    Ok(out)
}

/// Formats `v` with exactly `decimals` decimals, never in exponent notation
/// and never as a negative zero. `None` for NaN or infinity.
pub fn format_fixed(v: f64, decimals: usize) -> Option<String> {
    let mut s = String::with_capacity(24);
    push_fixed(&mut s, v, decimals).then_some(s)
}

/// [`format_fixed`] through `format!` (the reference of the fast path).
fn push_fixed_slow(out: &mut String, v: f64, decimals: usize) {
    out.push_str(&super::fixed::exact_fixed(v, decimals));
}

/// Appends [`format_fixed`]`(v, decimals)` to `out` without an allocation
/// of its own; false (nothing appended) for NaN or infinity. Byte-identical
/// to the `format!` path: the digits come from the shared fixed-decimal
/// formatter of the writers, which defers to `format!` near a rounding tie.
pub fn push_fixed(out: &mut String, v: f64, decimals: usize) -> bool {
    if !v.is_finite() {
        return false;
    }
    let mut buf = [0u8; super::fixed::FIXED_MAX];
    match super::fixed::fixed_digits(&mut buf, v, decimals) {
        // ASCII digits, sign and point: valid UTF-8, appended in one copy
        // (cheaper than a push per character).
        Some(len) => match buf.get(..len).map(std::str::from_utf8) {
            Some(Ok(text)) => out.push_str(text),
            _ => push_fixed_slow(out, v, decimals),
        },
        None => push_fixed_slow(out, v, decimals),
    }
    true
}

/// Appends `v.to_string()` to `out` without the formatting machinery (the
/// confdata numbers of a rewritten robtarget): the shared fixed-decimal
/// digits with no decimals, exact for every `i32`.
pub fn push_int(out: &mut String, v: i32) {
    push_fixed(out, f64::from(v), 0);
}

/// Formats a position (mm) with `fmt.position_decimals` decimals.
pub fn format_position(p: &[f64; 3], fmt: &Format) -> Result<[String; 3], Error> {
    let f = |v: f64| {
        format_fixed(v, fmt.position_decimals).ok_or_else(|| {
            Error::Internal(format!("position component {v} is not a finite number"))
        })
    };
    Ok([f(p[0])?, f(p[1])?, f(p[2])?])
}

/// Normalises a quaternion `[q1 (scalar), q2, q3, q4]` and chooses its sign:
/// the one closest to `reference` (the input's quaternion, so that a tool
/// pointing down keeps the sign style it was written with), or when there is
/// no usable reference the one with q1 ≥ 0 (first non-zero component
/// positive when q1 is zero). `None` for a zero or non-finite quaternion.
pub fn normalise_quaternion(q: &[f64; 4], reference: Option<&[f64; 4]>) -> Option<[f64; 4]> {
    let norm = q.iter().map(|c| c * c).sum::<f64>().sqrt();
    if !norm.is_finite() || norm <= f64::EPSILON {
        return None;
    }
    let mut n = q.map(|c| c / norm);
    let dot = reference.map_or(0.0, |r| n.iter().zip(r).map(|(a, b)| a * b).sum::<f64>());
    /// Below this |dot| the reference cannot tell the two signs apart.
    const SIGN_DOT_MIN: f64 = 1e-9;
    let flip = if dot.abs() > SIGN_DOT_MIN {
        dot < 0.0
    } else {
        n.iter()
            .find(|c| c.abs() > SIGN_DOT_MIN)
            .is_some_and(|&c| c < 0.0)
    };
    if flip {
        n = n.map(|c| -c);
    }
    Some(n)
}

/// Normalises (see [`normalise_quaternion`]) and formats a quaternion with
/// `fmt.quaternion_decimals` decimals. Of the 16 roundings of the four
/// components (each rounded down or up), the one whose rotation after
/// normalisation is closest to the exact one is written: the written
/// quaternion is then never worse than plain rounding, and usually several
/// times better (the reader normalises it anyway).
pub fn format_quaternion(
    q: &[f64; 4],
    reference: Option<&[f64; 4]>,
    fmt: &Format,
) -> Result<[String; 4], Error> {
    let c = quaternion_components(q, reference, fmt)?;
    let f = |v: f64| format_fixed(v, fmt.quaternion_decimals).unwrap_or_else(|| "0".to_string());
    Ok([f(c[0]), f(c[1]), f(c[2]), f(c[3])])
}

/// The components [`format_quaternion`] writes (before formatting).
pub fn quaternion_components(
    q: &[f64; 4],
    reference: Option<&[f64; 4]>,
    fmt: &Format,
) -> Result<[f64; 4], Error> {
    let n = normalise_quaternion(q, reference)
        .ok_or_else(|| Error::Internal(format!("quaternion {q:?} cannot be normalised")))?;
    let scale = 10f64.powi(i32::try_from(fmt.quaternion_decimals).unwrap_or(9).min(15));
    let lo = n.map(|c| (c * scale).floor());
    // The two candidate values of each component and their squares,
    // computed once for the 16 combinations (the same values as per
    // combination).
    let cand: [[f64; 2]; 4] =
        std::array::from_fn(|k| [0u32, 1].map(|b| (lo[k] + f64::from(b)) / scale));
    let sq = cand.map(|c| c.map(|x| x * x));
    let mut best = (f64::INFINITY, n);
    for mask in 0..16u32 {
        let bit = |k: usize| ((mask >> k) & 1) as usize;
        let c: [f64; 4] = std::array::from_fn(|k| cand[k][bit(k)]);
        let c2: [f64; 4] = std::array::from_fn(|k| sq[k][bit(k)]);
        let norm = c2.iter().sum::<f64>().sqrt();
        if norm <= f64::EPSILON {
            continue;
        }
        // Chord distance between unit quaternions: monotonic in the angle.
        let err: f64 = c.iter().zip(&n).map(|(a, b)| (a / norm - b).powi(2)).sum();
        if err < best.0 {
            best = (err, c);
        }
    }
    Ok(best.1)
}

/// [`robtarget_edits`] as ONE edit, pushed onto `edits` (its text written
/// straight into their shared buffer): from the first position number to
/// the last quaternion number (or the last position number without
/// `quat`), the text between the numbers copied from `src`. The same
/// output bytes (and the same errors) with one edit instead of seven. With
/// `conf` (and `quat`), the edit goes on to the last confdata number and
/// writes `conf` there too (as one edit per confdata number with
/// `to_string` would).
pub fn push_robtarget_edit(
    edits: &mut EditList,
    src: &str,
    rt: &RobTarget,
    pos: &[f64; 3],
    quat: Option<&[f64; 4]>,
    conf: Option<&[i32; 4]>,
    fmt: &Format,
) -> Result<(), Error> {
    edits.push_with(|text| {
        let start = rt.trans[0].span.start;
        let mut at = start;
        let mut gap = |text: &mut String, n: &crate::program::rapid::Number| {
            let between = src.get(at..n.span.start).ok_or_else(|| {
                Error::Internal(format!(
                    "robtarget number span {:?} is outside the program",
                    n.span
                ))
            })?;
            text.push_str(between);
            at = n.span.end;
            Ok::<(), Error>(())
        };
        for (n, &v) in rt.trans.iter().zip(pos) {
            gap(text, n)?;
            if !push_fixed(text, v, fmt.position_decimals) {
                return Err(Error::Internal(format!(
                    "position component {v} is not a finite number"
                )));
            }
        }
        if let Some(q) = quat {
            let reference = rt.rot.each_ref().map(|n| n.value);
            let c = quaternion_components(q, Some(&reference), fmt)?;
            for (n, &v) in rt.rot.iter().zip(&c) {
                gap(text, n)?;
                if !push_fixed(text, v, fmt.quaternion_decimals) {
                    text.push('0');
                }
            }
            if let Some(conf) = conf {
                for (n, v) in rt.robconf.iter().zip(conf) {
                    gap(text, n)?;
                    push_int(text, *v);
                }
            }
        }
        Ok(start..at)
    })
}

/// Edits replacing exactly the position numbers of `rt` with `pos` and, when
/// given, its quaternion numbers with `quat` (normalised, sign kept close to
/// the original quaternion). Configuration and external axes are untouched.
pub fn robtarget_edits(
    rt: &RobTarget,
    pos: &[f64; 3],
    quat: Option<&[f64; 4]>,
    fmt: &Format,
) -> Result<Vec<Edit>, Error> {
    let mut edits = Vec::with_capacity(7);
    for (n, text) in rt.trans.iter().zip(format_position(pos, fmt)?) {
        edits.push(Edit::replace(n.span.clone(), text));
    }
    if let Some(q) = quat {
        let reference = rt.rot.each_ref().map(|n| n.value);
        for (n, text) in rt
            .rot
            .iter()
            .zip(format_quaternion(q, Some(&reference), fmt)?)
        {
            edits.push(Edit::replace(n.span.clone(), text));
        }
    }
    Ok(edits)
}

/// The text of `rt`'s literal in `src` with its position (and quaternion)
/// replaced, every other character as written: for a materialised copy.
pub fn robtarget_literal(
    src: &str,
    rt: &RobTarget,
    pos: &[f64; 3],
    quat: Option<&[f64; 4]>,
    fmt: &Format,
) -> Result<String, Error> {
    let base = rt.span.start;
    let literal = src.get(rt.span.clone()).ok_or_else(|| {
        Error::Internal(format!(
            "robtarget span {:?} is outside the program",
            rt.span
        ))
    })?;
    let edits = robtarget_edits(rt, pos, quat, fmt)?
        .into_iter()
        .map(|e| Edit {
            span: e.span.start.saturating_sub(base)..e.span.end.saturating_sub(base),
            text: e.text,
        })
        .collect::<Vec<_>>();
    apply_edits(literal, &edits)
}

/// The line ending the file uses: `"\r\n"` when its first line break is
/// CRLF, otherwise `"\n"`.
pub fn line_ending(src: &str) -> &'static str {
    match src.find('\n') {
        Some(p) if p > 0 && src.as_bytes().get(p - 1) == Some(&b'\r') => "\r\n",
        _ => "\n",
    }
}

/// Offset of the end of the line holding byte `pos` (before its `\r\n` or `\n`).
fn line_end(src: &str, pos: usize) -> usize {
    let nl = src
        .get(pos..)
        .and_then(|s| s.find('\n'))
        .map_or(src.len(), |k| pos + k);
    if nl > 0 && nl < src.len() && src.as_bytes().get(nl - 1) == Some(&b'\r') {
        nl - 1
    } else {
        nl
    }
}

/// Offset of the start of the line holding byte `pos`.
fn line_start(src: &str, pos: usize) -> usize {
    src.get(..pos)
        .and_then(|s| s.rfind('\n'))
        .map_or(0, |k| k + 1)
}

/// An insertion of ` ! comment` at the end of the line where the statement
/// `stmt` ends (before the line break). Line breaks in `comment` become spaces.
pub fn annotate(src: &str, stmt: &Range<usize>, comment: &str) -> Edit {
    let last = stmt.end.saturating_sub(1).max(stmt.start);
    let at = line_end(src, last);
    let one_line: String = comment
        .chars()
        .map(|c| if c == '\r' || c == '\n' { ' ' } else { c })
        .collect();
    Edit::insert(at, format!(" ! {one_line}"))
}

/// [`annotate`] with the comment written by `write` (which must not write
/// a line break) straight after the ` ! `, into `edits`' shared buffer.
pub fn push_annotation(
    edits: &mut EditList,
    src: &str,
    stmt: &Range<usize>,
    write: impl FnOnce(&mut String),
) {
    let last = stmt.end.saturating_sub(1).max(stmt.start);
    let at = line_end(src, last);
    let pushed: Result<(), std::convert::Infallible> = edits.push_with(|text| {
        text.push_str(" ! ");
        write(text);
        Ok(at..at)
    });
    let Ok(()) = pushed;
}

/// An insertion of `text` (one or more lines, without a final line break) on
/// new lines just after the line where the declaration `decl` ends, each line
/// indented like the declaration and ended with the file's line ending.
pub fn insert_after_decl(src: &str, decl: &Range<usize>, text: &str) -> Edit {
    let ls = line_start(src, decl.start);
    let indent: String = src
        .get(ls..decl.start)
        .unwrap_or("")
        .chars()
        .take_while(|c| *c == ' ' || *c == '\t')
        .collect();
    let eol = line_ending(src);
    let end = line_end(src, decl.end.saturating_sub(1).max(decl.start));
    let mut block = String::new();
    for line in text.lines() {
        block.push_str(&indent);
        block.push_str(line);
        block.push_str(eol);
    }
    // After the existing line break, or a new one when the file ends here.
    match src.get(end..) {
        Some(rest) if rest.starts_with("\r\n") => Edit::insert(end + 2, block),
        Some(rest) if rest.starts_with('\n') => Edit::insert(end + 1, block),
        _ => {
            let trimmed = block.strip_suffix(eol).unwrap_or(&block);
            Edit::insert(end, format!("{eol}{trimmed}"))
        }
    }
}

/// The text of `decl` as written in `src` with its name replaced by
/// `new_name` and its value by `value` (e.g. a materialised compensated
/// copy `CONST robtarget p10_c1 := [...];`). `None` when `decl` has no value.
pub fn decl_copy(src: &str, decl: &Decl, new_name: &str, value: &str) -> Option<String> {
    let v = decl.value.as_ref()?.span();
    let base = decl.span.start;
    let text = src.get(decl.span.clone())?;
    let edits = [
        Edit::replace(
            decl.name_span.start.checked_sub(base)?..decl.name_span.end.checked_sub(base)?,
            new_name,
        ),
        Edit::replace(v.start.checked_sub(base)?..v.end.checked_sub(base)?, value),
    ];
    apply_edits(text, &edits).ok()
}

/// Decimals of rewritten jointtarget axis values (degrees): 0.0000005° =
/// 8.7 nrad per joint, ≤ 0.014 µm at the 1.6 m lever arm of an IRB 1600 with
/// a tool, so a compensated MoveAbsJ target lands within 1 µm / 1 µrad.
pub const JOINT_DECIMALS: usize = 6;

/// A compensated joint value as written, or an error naming the target when
/// the solve produced a non-finite number (it is never written as 0).
pub(crate) fn joint_word(v: f64, src: &str, file: &str, at: usize) -> Result<String> {
    format_fixed(v, JOINT_DECIMALS).ok_or_else(|| {
        let (line, column) = line_col(src, at);
        Error::Unachievable(Located::new(
            file,
            line,
            column,
            format!("the compensated joint value {v} is not a finite number"),
        ))
    })
}

/// The comment appended to a compensated move: the predicted deviation of
/// the uncompensated target and its parts (mm), and the vibration amplitude
/// (mm, reported only).
/// Writes [`dev_comment`] into `out` (fast fixed-decimal numbers, the
/// same text).
pub(crate) fn write_dev_comment(out: &mut String, d: &Breakdown) {
    let num = |out: &mut String, v: f64, decimals: usize| {
        if !push_fixed(out, v, decimals) {
            use std::fmt::Write;
            let _ = write!(out, "{v:.decimals$}");
        }
    };
    out.push_str("dev ");
    num(out, d.total.pos_mm.norm(), 3);
    out.push_str(" mm (kin ");
    num(out, d.kinematic.pos_mm.norm(), 3);
    out.push_str(" therm ");
    num(out, d.thermal.pos_mm.norm(), 3);
    out.push_str(" grav ");
    num(out, d.gravity.pos_mm.norm(), 3);
    out.push_str(" proc ");
    num(out, d.process.pos_mm.norm(), 3);
    out.push_str(" vib ");
    num(out, d.vibration_mm.norm(), 4);
    out.push(')');
}

#[cfg(test)]
pub(crate) fn dev_comment(d: &Breakdown) -> String {
    format!(
        "dev {:.3} mm (kin {:.3} therm {:.3} grav {:.3} proc {:.3} vib {:.4})",
        d.total.pos_mm.norm(),
        d.kinematic.pos_mm.norm(),
        d.thermal.pos_mm.norm(),
        d.gravity.pos_mm.norm(),
        d.process.pos_mm.norm(),
        d.vibration_mm.norm()
    )
}

/// The text of a robtarget literal with new position, quaternion and
/// confdata; the external axes as written.
pub(crate) fn robtarget_text(
    src: &str,
    rt: &RobTarget,
    pose: &Isometry3<f64>,
    conf: ConfData,
    fmt: &Format,
) -> Result<String> {
    let p = format_position(&pose.translation.vector.into(), fmt)?;
    let q = pose.rotation.quaternion();
    let reference = rt.rot.each_ref().map(|n| n.value);
    let q = format_quaternion(&[q.w, q.i, q.j, q.k], Some(&reference), fmt)?;
    let (Some(first), Some(last)) = (rt.extax.first(), rt.extax.last()) else {
        return Err(Error::Internal("robtarget without external axes".into()));
    };
    let extax = src
        .get(first.span.start..last.span.end)
        .ok_or_else(|| Error::Internal("robtarget span outside the program".into()))?;
    Ok(format!(
        "[[{},{},{}],[{},{},{},{}],[{},{},{},{}],[{extax}]]",
        p[0], p[1], p[2], q[0], q[1], q[2], q[3], conf.cf1, conf.cf4, conf.cf6, conf.cfx
    ))
}

/// In-place edits of a robtarget literal, pushed onto `edits`: one edit
/// for the position and quaternion numbers (and the confdata numbers when
/// the confdata changes) while they lie on one line; otherwise one edit per
/// number.
pub(crate) fn robtarget_in_place(
    edits: &mut EditList,
    src: &str,
    rt: &RobTarget,
    pose: &Isometry3<f64>,
    old_conf: ConfData,
    conf: ConfData,
    fmt: &Format,
) -> Result<()> {
    let q = pose.rotation.quaternion();
    let pos: [f64; 3] = pose.translation.vector.into();
    let quat = [q.w, q.i, q.j, q.k];
    // One edit over the whole position-and-quaternion text (and the
    // confdata when it changes) is cheaper, but only while it stays on one
    // line: an annotation inserted at the end of an earlier statement's
    // line would fall inside a multi-line span.
    let new_conf = [conf.cf1, conf.cf4, conf.cf6, conf.cfx];
    let changed = conf != old_conf;
    let end = if changed {
        rt.robconf[3].span.end
    } else {
        rt.rot[3].span.end
    };
    let one_line = src
        .get(rt.trans[0].span.start..end)
        .is_some_and(|t| !t.contains('\n'));
    if one_line {
        push_robtarget_edit(
            edits,
            src,
            rt,
            &pos,
            Some(&quat),
            changed.then_some(&new_conf),
            fmt,
        )?;
    } else {
        for e in robtarget_edits(rt, &pos, Some(&quat), fmt)? {
            edits.push(&e);
        }
        if changed {
            for (n, v) in rt.robconf.iter().zip(new_conf) {
                edits.push_str(n.span.clone(), &v.to_string());
            }
        }
    }
    Ok(())
}

pub(crate) fn joint_text(
    src: &str,
    file: &str,
    jt: &JointTarget,
    q_deg: &[f64; 6],
) -> Result<String> {
    let (Some(first), Some(last)) = (jt.extax.first(), jt.extax.last()) else {
        return Err(Error::Internal("jointtarget without external axes".into()));
    };
    let extax = src
        .get(first.span.start..last.span.end)
        .ok_or_else(|| Error::Internal("jointtarget span outside the program".into()))?;
    let words = q_deg
        .iter()
        .map(|&v| joint_word(v, src, file, jt.span.start))
        .collect::<Result<Vec<_>>>()?;
    Ok(format!("[[{}],[{extax}]]", words.join(",")))
}

/// The names created so far in one run (lower case), and for each stem and
/// tag the run of numbers known to be unavailable, so that a stem copied
/// many times costs the same for each copy.
#[derive(Debug, Default, Clone)]
pub struct TakenNames {
    names: HashSet<String>,
    /// (stem, tag) → (lo, next): every number in `lo..next` gives a name
    /// that is declared, reserved or taken.
    runs: HashMap<(String, String), (usize, usize)>,
}

/// A name not `declared` (in the module: the caller looks it up), nor
/// already created, nor in `reserved` (lower case: the routines, record
/// types and modules of the program), of at most [`MAX_IDENT_CHARS`]
/// characters: `{stem}_{tag}{n}` for the first `n` from `from` on, the stem
/// cut where the name would be too long.
pub(crate) fn fresh_name(
    declared: impl Fn(&str) -> bool,
    taken: &mut TakenNames,
    reserved: &HashSet<String>,
    stem: &str,
    tag: &str,
    from: usize,
) -> String {
    let key = (stem.to_string(), tag.to_string());
    // Numbers from `from` on known to be unavailable are skipped: names
    // only ever become unavailable within a run.
    let run = taken
        .runs
        .get(&key)
        .copied()
        .filter(|&(lo, next)| (lo..=next).contains(&from));
    let (lo, mut n) = run.unwrap_or((from, from));
    loop {
        let suffix = format!("_{tag}{n}");
        let keep = MAX_IDENT_CHARS.saturating_sub(suffix.len());
        let end = stem.char_indices().nth(keep).map_or(stem.len(), |(i, _)| i);
        let name = format!("{}{suffix}", &stem[..end]);
        let lower = name.to_ascii_lowercase();
        if !declared(&name) && !reserved.contains(&lower) && !taken.names.contains(&lower) {
            taken.names.insert(lower);
            taken.runs.insert(key, (lo, n + 1));
            return name;
        }
        n += 1;
    }
}

/// The longest identifier RAPID takes, characters: a new name is cut to
/// it (its stem shortened, its suffix kept).
pub const MAX_IDENT_CHARS: usize = 32;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::predict::robot::PoseDelta;
    use crate::program::rapid::Target;
    use crate::program::rapid::resolve::conf_of;
    use nalgebra::Vector3;
    use proptest::prelude::*;

    fn slow(v: f64, decimals: usize) -> Option<String> {
        if !v.is_finite() {
            return None;
        }
        let mut s = String::new();
        push_fixed_slow(&mut s, v, decimals);
        Some(s)
    }

    /// The shared-buffer list applies as the list of owned edits does:
    /// same text, same order of insertions at one offset, same errors; a
    /// failed `push_with` leaves nothing behind.
    #[test]
    fn edit_list_applies_as_owned_edits() {
        let src = "MoveL p1,v100,z1,tool0;\nMoveL p2,v100,fine,tool0;\n";
        let cases: Vec<Vec<Edit>> = vec![
            vec![],
            vec![Edit::replace(6..8, "p1_c2")],
            // Given out of order; two insertions at one offset keep theirs.
            vec![
                Edit::insert(23, " ! b"),
                Edit::replace(30..32, "p9"),
                Edit::insert(23, " ! a"),
                Edit::insert(0, "! head\n"),
            ],
            vec![Edit::insert(src.len(), "\n")],
            // Errors: overlap, outside the source.
            vec![Edit::replace(6..10, "x"), Edit::replace(8..12, "y")],
            vec![Edit::replace(40..999, "x")],
        ];
        for edits in cases {
            let mut list = EditList::new();
            for e in &edits {
                list.push(e);
            }
            assert_eq!(list.len(), edits.len());
            assert_eq!(list.to_edits(), edits);
            let (a, b) = (apply_edits(src, &edits), list.apply(src));
            assert_eq!(a.is_ok(), b.is_ok(), "{edits:?}");
            if let (Ok(a), Ok(b)) = (a, b) {
                assert_eq!(a, b);
            }
        }
        let mut list = EditList::new();
        list.push_str(6..8, "p1_c2");
        let failed: Result<(), &str> = list.push_with(|t| {
            t.push_str("half written");
            Err("no")
        });
        assert_eq!(failed, Err("no"));
        assert_eq!(list.len(), 1);
        assert_eq!(list.to_edits(), vec![Edit::replace(6..8, "p1_c2")]);
        assert_eq!(
            list.apply(src).expect("applies"),
            src.replacen("p1", "p1_c2", 1)
        );
        // A writer that takes text away is refused at `apply` instead of
        // leaving the earlier edit without its text.
        let cut: Result<(), &str> = list.push_with(|t| {
            t.clear();
            Ok(30..32)
        });
        assert_eq!(cut, Ok(()));
        assert!(list.apply(src).is_err());
    }

    #[test]
    fn fixed_format_edge_cases_match_format() {
        let values = [
            0.0,
            -0.0,
            0.5,
            -0.5,
            1.5,
            2.5,
            -0.0004,
            -0.0005,
            0.0005,
            f64::from_bits(0.0005f64.to_bits() - 1),
            1e-300,
            -1e-300,
            123.4565,
            -123.4565,
            std::f64::consts::FRAC_1_SQRT_2,
            -std::f64::consts::FRAC_1_SQRT_2,
            999.9995,
            9.9999999995,
            1e9,
            -4.5e12,
            1e20,
            f64::MAX,
            f64::MIN_POSITIVE,
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ];
        for v in values {
            for d in 0..=12 {
                assert_eq!(format_fixed(v, d), slow(v, d), "{v} with {d} decimals");
            }
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 20_000, ..ProptestConfig::default() })]
        #[test]
        fn fixed_format_matches_format(v in any::<f64>(), d in 0usize..12) {
            prop_assert_eq!(format_fixed(v, d), slow(v, d));
        }

        /// [`push_int`] against `to_string` (random and extreme values).
        #[test]
        fn int_push_matches_to_string(v in any::<i32>()) {
            for v in [v, 0, -1, 9, -10, i32::MAX, i32::MIN] {
                let mut s = String::from("x");
                push_int(&mut s, v);
                prop_assert_eq!(s, format!("x{v}"));
            }
        }

        /// The shared candidates of [`quaternion_components`] against the
        /// candidates computed per combination: the same components, bit
        /// for bit (signed zeros included).
        #[test]
        fn quaternion_candidates_match_per_combination(
            q in proptest::array::uniform4(-1.0f64..1.0),
            zero in proptest::array::uniform4(any::<bool>()),
            d in 0usize..10,
        ) {
            let q: [f64; 4] = std::array::from_fn(|k| if zero[k] { -0.0 } else { q[k] });
            let fmt = Format { position_decimals: 3, quaternion_decimals: d };
            let fast = quaternion_components(&q, None, &fmt).ok().map(|c| c.map(f64::to_bits));
            let slow = normalise_quaternion(&q, None).map(|n| {
                let scale = 10f64.powi(i32::try_from(d).unwrap_or(9).min(15));
                let lo = n.map(|c| (c * scale).floor());
                let mut best = (f64::INFINITY, n);
                for mask in 0..16u32 {
                    let c: [f64; 4] =
                        std::array::from_fn(|k| (lo[k] + f64::from((mask >> k) & 1)) / scale);
                    let norm = c.iter().map(|x| x * x).sum::<f64>().sqrt();
                    if norm <= f64::EPSILON {
                        continue;
                    }
                    let err: f64 = c.iter().zip(&n).map(|(a, b)| (a / norm - b).powi(2)).sum();
                    if err < best.0 {
                        best = (err, c);
                    }
                }
                best.1.map(f64::to_bits)
            });
            prop_assert_eq!(fast, slow);
        }

        #[test]
        fn fixed_format_matches_format_on_robot_ranges(
            v in -3000.0f64..3000.0,
            d in 0usize..10,
        ) {
            prop_assert_eq!(format_fixed(v, d), slow(v, d));
        }

        #[test]
        fn fixed_format_matches_format_near_ties(
            k in -2_000_000_000i64..2_000_000_000,
            d in 0usize..10,
            ulps in -3i64..=3,
        ) {
            // (k + ½)·10^-d and its neighbours a few ulps away.
            let v = (k as f64 + 0.5) / 10f64.powi(d as i32);
            let v = f64::from_bits((v.to_bits() as i64 + ulps) as u64);
            prop_assert_eq!(format_fixed(v, d), slow(v, d));
        }
    }

    /// The single edit of [`robtarget_in_place`] (position, quaternion and
    /// confdata) against one edit per number: the same output text, for
    /// literals on one line and spread over lines, with and without a
    /// confdata change.
    #[test]
    fn one_robtarget_edit_equals_the_per_number_edits() {
        let src = "MODULE M\n  PROC main()\n    MoveL [[650.0,50.0,300.0],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]],v200,z1,t1;\n    MoveL [ [ 1 , 2,3 ],[1,0 ,0,0] , [-1, 0,-2 ,5],[9E9,9E9,9E9,9E9,9E9,9E9]],v200,z1,t1;\n    MoveL [[1,2,3],[1,0,0,0],\n      [0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]],v200,z1,t1;\n  ENDPROC\nENDMODULE\n";
        let module = crate::program::rapid::parse_module(src, "t.mod").expect("valid module");
        let fmt = Format {
            position_decimals: 3,
            quaternion_decimals: 7,
        };
        let pose = Isometry3::from_parts(
            nalgebra::Translation3::new(650.97234, -49.2148, 300.92649),
            nalgebra::UnitQuaternion::from_euler_angles(0.0008, -0.0003, 3.1),
        );
        let confs = [
            ConfData {
                cf1: 0,
                cf4: 0,
                cf6: 0,
                cfx: 0,
            },
            ConfData {
                cf1: -1,
                cf4: 2,
                cf6: -3,
                cfx: 7,
            },
        ];
        let mut seen = 0;
        for mv in module.moves() {
            let Target::Inline(rt) = &mv.target else {
                panic!("inline targets")
            };
            let old = conf_of(rt).expect("integer confdata");
            for conf in confs {
                let mut one = EditList::new();
                robtarget_in_place(&mut one, src, rt, &pose, old, conf, &fmt).expect("edits");
                let q = pose.rotation.quaternion();
                let mut each = crate::emit::rapid::robtarget_edits(
                    rt,
                    &pose.translation.vector.into(),
                    Some(&[q.w, q.i, q.j, q.k]),
                    &fmt,
                )
                .expect("edits");
                if conf != old {
                    for (n, v) in rt
                        .robconf
                        .iter()
                        .zip([conf.cf1, conf.cf4, conf.cf6, conf.cfx])
                    {
                        each.push(Edit::replace(n.span.clone(), v.to_string()));
                    }
                }
                assert_eq!(
                    one.apply(src).expect("applies"),
                    apply_edits(src, &each).expect("applies")
                );
                seen += 1;
            }
        }
        assert_eq!(seen, 6);
    }

    #[test]
    fn fast_deviation_comment_equals_the_formatted_one() {
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = || {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            let u = (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5;
            // Magnitudes from 1e-6 mm to 1e3 mm, both signs.
            u * 10f64.powf((state % 10) as f64 - 6.0)
        };
        let mut delta = |k: f64| PoseDelta {
            pos_mm: Vector3::new(next(), next(), next()) * k,
            rot_rad: Vector3::zeros(),
        };
        let mut cases = vec![Breakdown::default()];
        for k in [1.0, 0.5, 1e-3, 2.0] {
            let (a, b, c, d, e) = (delta(k), delta(k), delta(k), delta(k), delta(k));
            cases.push(Breakdown {
                kinematic: a,
                thermal: b,
                gravity: c,
                process: d,
                total: e,
                vibration_mm: Vector3::new(0.00005, 0.0, 0.0) * k,
            });
        }
        let mut odd = Breakdown::default();
        odd.total.pos_mm = Vector3::new(f64::NAN, 0.0, 0.0);
        odd.process.pos_mm = Vector3::new(f64::INFINITY, 0.0, 0.0);
        cases.push(odd);
        for _ in 0..2000 {
            let (a, b, c, d, e) = (delta(1.0), delta(1.0), delta(1.0), delta(1.0), delta(1.0));
            cases.push(Breakdown {
                kinematic: a,
                thermal: b,
                gravity: c,
                process: d,
                total: e,
                vibration_mm: a.pos_mm,
            });
        }
        for d in &cases {
            let mut fast = String::new();
            write_dev_comment(&mut fast, d);
            assert_eq!(fast, dev_comment(d));
        }
    }
}
