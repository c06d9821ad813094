//! Byte-faithful G-code writer.
//!
//! Unchanged blocks are copied byte for byte. A compensated block gets only
//! its coordinate words rewritten (same decimals as the program, or the
//! machine file's setting, never exponent notation); missing axis words are
//! inserted after the block's last axis word when the compensation moves that
//! axis; added blocks (segments of a split move) copy the block's style
//! (case, spacing, line ending). An annotation comment with the predicted
//! deviation is appended in the program's comment style.

use crate::compensate::BlockResult;
use crate::machine::{AXIS_LETTERS, AxisVec};
use crate::predict::Effect;
use crate::program::gcode::{Block, Word, strip_eol};
use crate::program::interp::{Motion, Plan, PlanKind};

/// Output options.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EmitOptions {
    /// Decimals of rewritten mm coordinates (inch: one more); `None` keeps
    /// the program's own, with at least 3 (mm) or 4 (inch).
    pub decimals_mm: Option<usize>,
    /// Decimals of rewritten rotary-axis words (degrees); `None` keeps the
    /// program's own, with at least 3.
    pub decimals_deg: Option<usize>,
    /// Append `(dev … mm geo …)` comments to compensated blocks.
    pub annotate: bool,
}

/// Default decimals of rewritten mm words when the program has fewer.
pub const DEFAULT_DECIMALS_MM: usize = 3;

/// Streaming emitter state (what the controller will have been told so far).
#[derive(Debug, Clone)]
pub struct Emitter {
    opts: EmitOptions,
    /// Machine coordinates the emitted program has commanded so far.
    emitted: AxisVec,
    /// Output motion mode differs from the program's after a replaced arc.
    motion_pending: Option<Motion>,
    /// Emitted canned-cycle Z and R (program units), modal.
    cycle_z: Option<f64>,
    cycle_r: Option<f64>,
    /// The program writes `;` comments rather than `( )`.
    semicolon_comments: Option<bool>,
    /// Changed blocks so far.
    changed: usize,
    /// Blocks added by segmentation.
    added: usize,
}

/// Formats `v` with `d` decimals, never in exponent notation and never as
/// negative zero; `trim` drops trailing zeros (keeping the point).
pub fn format_number(v: f64, d: usize, trim: bool) -> String {
    let mut s = fixed(v, d).unwrap_or_else(|| format!("{v:.d$}"));
    if s.starts_with('-') && s[1..].bytes().all(|b| b == b'0' || b == b'.') {
        s.remove(0);
    }
    if trim && s.contains('.') {
        while s.ends_with('0') {
            s.pop();
        }
    }
    if !s.contains('.') {
        s.push('.');
    }
    s
}

/// `format!("{v:.d$}")` without the exact (big-number) float formatting,
/// when `v · 10^d` lies clearly away from a rounding tie so that the
/// floating-point product rounds to the same integer as the exact decimal
/// value; `None` otherwise (the caller formats exactly).
fn fixed(v: f64, d: usize) -> Option<String> {
    const POW10: [f64; 10] = [1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9];
    let scale = *POW10.get(d)?;
    let scaled = v * scale;
    let r = scaled.round();
    if !r.is_finite() || r.abs() >= 1e15 || (scaled - r).abs() > 0.25 {
        return None;
    }
    let n = r as i64;
    let digits = n.unsigned_abs().to_string();
    let mut s = String::with_capacity(digits.len() + 3);
    if n < 0 || (r == 0.0 && v.is_sign_negative() && v != 0.0) {
        s.push('-');
    }
    if d == 0 {
        s.push_str(&digits);
        return Some(s);
    }
    let (int, frac) = if digits.len() > d {
        digits.split_at(digits.len() - d)
    } else {
        ("0", digits.as_str())
    };
    s.push_str(int);
    s.push('.');
    for _ in frac.len()..d {
        s.push('0');
    }
    s.push_str(frac);
    Some(s)
}

fn round_to(v: f64, d: usize) -> f64 {
    let f = 10f64.powi(d as i32);
    (v * f).round() / f
}

struct Edit {
    start: usize,
    end: usize,
    text: String,
}

impl Emitter {
    /// A new emitter; the controller starts at machine zero.
    pub fn new(opts: EmitOptions) -> Self {
        Emitter {
            opts,
            emitted: [0.0; 6],
            motion_pending: None,
            cycle_z: None,
            cycle_r: None,
            semicolon_comments: None,
            changed: 0,
            added: 0,
        }
    }

    /// Number of blocks whose text changed.
    pub fn changed_blocks(&self) -> usize {
        self.changed
    }

    /// Number of blocks added by segmentation.
    pub fn added_blocks(&self) -> usize {
        self.added
    }

    fn decimals(&self, w: Option<&Word>, scale: f64, rotary: bool) -> usize {
        let own = w.and_then(|w| w.decimals).unwrap_or(0) as usize;
        let base = if rotary {
            self.opts.decimals_deg.unwrap_or(DEFAULT_DECIMALS_MM)
        } else {
            let d = self.opts.decimals_mm.unwrap_or(DEFAULT_DECIMALS_MM);
            if scale != 1.0 { d + 1 } else { d }
        };
        own.max(base)
    }

    /// Writes one line (`line` includes its end-of-line bytes).
    pub fn write(
        &mut self,
        line: &[u8],
        block: &Block,
        plan: &Plan,
        res: Option<&BlockResult>,
        out: &mut Vec<u8>,
    ) {
        if self.semicolon_comments.is_none() {
            if let Some(c) = block.comments.first() {
                self.semicolon_comments = Some(c.semicolon);
            }
        }
        let text = strip_eol(line);
        let eol = &line[text.len()..];
        let (Some(mv), Some(res)) = (plan.mv, res) else {
            out.extend_from_slice(line);
            self.track_unchanged(block, plan);
            return;
        };
        if plan.kind == PlanKind::Pass {
            out.extend_from_slice(line);
            return;
        }
        if plan.kind == PlanKind::Fixed {
            out.extend_from_slice(line);
            self.emitted = mv.end;
            return;
        }
        let mut edits: Vec<Edit> = Vec::new();
        let scale = plan.scale;
        let lower = block.lower_case;
        let sep = if block.spaced { " " } else { "" };
        let is_cycle = matches!(plan.kind, PlanKind::Cycle { .. });
        let first_target = if let Some(first) = res.segments.first() {
            *first
        } else {
            res.end
        };

        // Motion word handling for replaced arcs and pending modal motion.
        let motion_word = block
            .words
            .iter()
            .find(|w| w.letter == b'G' && matches!(w.code10(), 0 | 10 | 20 | 30));
        if res.arc_replaced {
            match motion_word {
                Some(w) => {
                    let old = &text[w.num_start as usize..w.end as usize];
                    let new = if old.len() >= 2 && old[0] == b'0' {
                        "01"
                    } else {
                        "1"
                    };
                    edits.push(Edit {
                        start: w.num_start as usize,
                        end: w.end as usize,
                        text: new.into(),
                    });
                }
                None => {
                    let at = insert_point_for_motion(block);
                    let g = if lower { "g1" } else { "G1" };
                    edits.push(Edit {
                        start: at,
                        end: at,
                        text: format!("{g}{}", if block.spaced || at > 0 { " " } else { "" }),
                    });
                }
            }
            for w in block
                .words
                .iter()
                .filter(|w| matches!(w.letter, b'I' | b'J' | b'K' | b'R'))
            {
                // Take the separating space before the word with it.
                let mut start = w.start as usize;
                if start > 0 && text.get(start - 1) == Some(&b' ') {
                    start -= 1;
                }
                edits.push(Edit {
                    start,
                    end: w.end as usize,
                    text: String::new(),
                });
            }
        } else if let Some(m) = self.motion_pending {
            if motion_word.is_none() && !is_cycle {
                let at = insert_point_for_motion(block);
                let code = match m {
                    Motion::ArcCw => "2",
                    Motion::ArcCcw => "3",
                    Motion::Linear => "1",
                    Motion::Rapid => "0",
                };
                let g = if lower { "g" } else { "G" };
                edits.push(Edit {
                    start: at,
                    end: at,
                    text: format!("{g}{code} "),
                });
            }
        }
        if motion_word.is_some() || !res.arc_replaced {
            self.motion_pending = None;
        }
        if res.arc_replaced {
            self.motion_pending = Some(mv.motion);
        }

        // Axis words.
        let start_emitted = self.emitted;
        let mut last_axis_end: Option<usize> = None;
        let mut new_emitted = self.emitted;
        for slot in 0..6 {
            let w = block.words.iter().find(|w| w.letter == AXIS_LETTERS[slot]);
            if let Some(w) = w {
                last_axis_end =
                    Some(last_axis_end.map_or(w.end as usize, |e: usize| e.max(w.end as usize)));
            }
            let rotary = slot >= 3;
            let target = first_target[slot];
            let moved_axis = is_cycle && slot == 2;
            let d = self.decimals(w, scale, rotary);
            if moved_axis {
                continue;
            }
            let rounded = round_to(to_program(plan, slot, target, self.emitted[slot]), d);
            match w {
                Some(w) => {
                    let orig = round_to(w.value, d);
                    if rounded != orig || w.decimals.unwrap_or(0) as usize > d {
                        edits.push(number_edit(w, rounded, d));
                        new_emitted[slot] = to_machine(plan, slot, rounded, self.emitted[slot]);
                    } else {
                        new_emitted[slot] = to_machine(plan, slot, w.value, self.emitted[slot]);
                    }
                }
                None => {
                    let now = round_to(
                        to_program(plan, slot, self.emitted[slot], self.emitted[slot]),
                        d,
                    );
                    let want = rounded;
                    // Rapids position only the axes they program.
                    let positioning =
                        mv.motion == Motion::Rapid && plan.programmed & (1 << slot) == 0;
                    if want != now
                        && !positioning
                        && (slot < 3 || self.has_axis_word_or_moved(slot, target))
                    {
                        let at = last_axis_end.unwrap_or_else(|| insert_point_for_axes(block));
                        let letter = letter_case(AXIS_LETTERS[slot], lower);
                        edits.push(Edit {
                            start: at,
                            end: at,
                            text: format!("{sep}{letter}{}", format_number(want, d, true)),
                        });
                        new_emitted[slot] = to_machine(plan, slot, want, self.emitted[slot]);
                    }
                }
            }
        }
        if let PlanKind::Cycle { .. } = plan.kind {
            self.cycle_words(block, plan, res, &mut edits, last_axis_end, sep, lower);
            // G99 leaves the tool at the (compensated) R level; G98 returns
            // it to the initial level it came from.
            if let PlanKind::Cycle {
                r_level, retract, ..
            } = plan.kind
            {
                if retract == r_level && plan.absolute {
                    new_emitted[2] = res.r_level;
                }
            }
        }
        // Arc centre words.
        if let (Some(center), Some(arc)) = (res.center, mv.arc) {
            let (a, b, _) = arc.plane.axes();
            let (la, lb) = arc.plane.center_letters();
            let r_word = block.word(b'R');
            if let Some(r) = r_word {
                let (e, st) = (first_target, start_emitted);
                let ra = ((st[a] - center[a]).hypot(st[b] - center[b])
                    + (e[a] - center[a]).hypot(e[b] - center[b]))
                    / 2.0;
                let d = self.decimals(Some(r), scale, false);
                let v = round_to(ra / scale * r.value.signum(), d);
                if v != round_to(r.value, d) {
                    edits.push(number_edit(r, v, d));
                }
            } else {
                for (slot, letter) in [(a, la), (b, lb)] {
                    let w = block.word(letter);
                    let d = self.decimals(w, scale, false);
                    let v = if plan.arc_absolute {
                        (center[slot] - plan.offset[slot]) / scale
                    } else {
                        (center[slot] - start_emitted[slot]) / scale
                    };
                    let v = round_to(v, d);
                    match w {
                        Some(w) => {
                            if v != round_to(w.value, d) {
                                edits.push(number_edit(w, v, d));
                            }
                        }
                        None => {
                            if v != 0.0 || plan.arc_absolute {
                                let at = block
                                    .words
                                    .iter()
                                    .filter(|w| matches!(w.letter, b'I' | b'J' | b'K'))
                                    .map(|w| w.end as usize)
                                    .max()
                                    .or(last_axis_end)
                                    .unwrap_or(text.len());
                                let l = letter_case(letter, lower);
                                edits.push(Edit {
                                    start: at,
                                    end: at,
                                    text: format!("{sep}{l}{}", format_number(v, d, true)),
                                });
                            }
                        }
                    }
                }
            }
        }
        if self.opts.annotate {
            let dev = res.deviation.total().norm() / scale;
            let unit = if scale != 1.0 { "in" } else { "mm" };
            let dd = if scale != 1.0 { 5 } else { 4 };
            let mut body = format!("dev {} {unit}", format_number(dev, dd, false));
            // Every part that is non-zero at the printed precision; the
            // dynamic one is a vibration amplitude (not in `dev`, not
            // compensated).
            for e in Effect::ALL {
                let part = res.deviation.part(e).norm() / scale;
                if round_to(part, dd) == 0.0 {
                    continue;
                }
                body.push_str(&format!(
                    " {} {}",
                    e.short(),
                    format_number(part, dd, false)
                ));
            }
            let c = if self.semicolon_comments == Some(true) {
                format!(" ; {body}")
            } else {
                format!(" ({body})")
            };
            // Before a trailing `;` comment, parentheses would be swallowed by it.
            let at = match block.comments.last() {
                Some(cm) if cm.semicolon && self.semicolon_comments != Some(true) => {
                    cm.start as usize
                }
                _ => text.len(),
            };
            let c = if at < text.len() {
                format!("{} ", c.trim_start())
            } else {
                c
            };
            edits.push(Edit {
                start: at,
                end: at,
                text: c,
            });
        }
        if edits.is_empty() {
            out.extend_from_slice(line);
        } else {
            self.changed += 1;
            edits.sort_by_key(|e| (e.start, e.end));
            let mut pos = 0;
            for e in &edits {
                if e.start < pos {
                    continue;
                }
                out.extend_from_slice(&text[pos..e.start]);
                out.extend_from_slice(e.text.as_bytes());
                pos = e.end;
            }
            out.extend_from_slice(&text[pos..]);
            out.extend_from_slice(eol);
        }
        self.emitted = new_emitted;
        // Added segment blocks.
        if !res.segments.is_empty() {
            let eol: &[u8] = if eol.is_empty() { b"\n" } else { eol };
            let mut points: Vec<AxisVec> = res.segments[1..].to_vec();
            points.push(res.end);
            for p in points {
                let mut parts: Vec<String> = Vec::new();
                for slot in 0..6 {
                    let w = block.words.iter().find(|w| w.letter == AXIS_LETTERS[slot]);
                    let d = self.decimals(w, scale, slot >= 3);
                    let now = self.emitted[slot];
                    let v = round_to(to_program(plan, slot, p[slot], now), d);
                    let cur = round_to(to_program(plan, slot, now, now), d);
                    if v != cur {
                        let letter = letter_case(AXIS_LETTERS[slot], lower);
                        parts.push(format!("{letter}{}", format_number(v, d, true)));
                        self.emitted[slot] = to_machine(plan, slot, v, now);
                    }
                }
                if parts.is_empty() {
                    continue;
                }
                out.extend_from_slice(
                    parts
                        .join(if block.spaced || parts.len() == 1 {
                            " "
                        } else {
                            ""
                        })
                        .as_bytes(),
                );
                out.extend_from_slice(eol);
                self.added += 1;
            }
        }
    }

    fn has_axis_word_or_moved(&self, slot: usize, target: f64) -> bool {
        (self.emitted[slot] - target).abs() > 1e-9
    }

    #[allow(clippy::too_many_arguments)]
    fn cycle_words(
        &mut self,
        block: &Block,
        plan: &Plan,
        res: &BlockResult,
        edits: &mut Vec<Edit>,
        last_axis_end: Option<usize>,
        sep: &str,
        lower: bool,
    ) {
        let scale = plan.scale;
        if !plan.absolute {
            // Incremental cycles: only the hole position is rewritten.
            return;
        }
        let at_end = last_axis_end.unwrap_or_else(|| insert_point_for_axes(block));
        for (letter, value) in [(b'Z', res.end[2]), (b'R', res.r_level)] {
            let w = block.word(letter);
            let d = self.decimals(w, scale, false);
            let v = round_to((value - plan.offset[2]) / scale, d);
            let modal = if letter == b'Z' {
                &mut self.cycle_z
            } else {
                &mut self.cycle_r
            };
            match w {
                Some(w) => {
                    if v != round_to(w.value, d) {
                        edits.push(number_edit(w, v, d));
                        *modal = Some(v);
                    } else {
                        *modal = Some(w.value);
                    }
                }
                None => {
                    let cur = modal.map(|m| round_to(m, d));
                    if cur != Some(v) {
                        let l = letter_case(letter, lower);
                        edits.push(Edit {
                            start: at_end,
                            end: at_end,
                            text: format!("{sep}{l}{}", format_number(v, d, true)),
                        });
                        *modal = Some(v);
                    }
                }
            }
        }
    }

    /// Keeps the emitted position in step for blocks written unchanged.
    fn track_unchanged(&mut self, block: &Block, plan: &Plan) {
        if let Some(mv) = plan.mv {
            self.emitted = mv.end;
            if block
                .words
                .iter()
                .any(|w| w.letter == b'G' && matches!(w.code10(), 0 | 10 | 20 | 30))
            {
                self.motion_pending = None;
            }
        }
        if let Some(z) = block.word(b'Z') {
            if matches!(plan.kind, PlanKind::Cycle { .. }) {
                self.cycle_z = Some(z.value);
            }
        }
        if let Some(r) = block.word(b'R') {
            if matches!(plan.kind, PlanKind::Cycle { .. }) {
                self.cycle_r = Some(r.value);
            }
        }
    }
}

/// Program value of a machine coordinate: absolute words are offset and
/// scaled, incremental ones are relative to what was emitted before.
fn to_program(plan: &Plan, slot: usize, machine: f64, emitted: f64) -> f64 {
    let s = if slot >= 3 { 1.0 } else { plan.scale };
    if plan.absolute {
        (machine - plan.offset[slot]) / s
    } else {
        (machine - emitted) / s
    }
}

/// Machine coordinate a program value commands (inverse of [`to_program`]).
fn to_machine(plan: &Plan, slot: usize, program: f64, emitted: f64) -> f64 {
    let s = if slot >= 3 { 1.0 } else { plan.scale };
    if plan.absolute {
        program * s + plan.offset[slot]
    } else {
        emitted + program * s
    }
}

/// Replaces a word's number, trimming trailing zeros when the program wrote
/// fewer decimals than `d`.
fn number_edit(w: &Word, v: f64, d: usize) -> Edit {
    Edit {
        start: w.num_start as usize,
        end: w.end as usize,
        text: format_number(v, d, w.decimals.is_none_or(|od| (od as usize) < d)),
    }
}

fn letter_case(letter: u8, lower: bool) -> char {
    if lower {
        letter.to_ascii_lowercase() as char
    } else {
        letter as char
    }
}

/// Where to insert a motion G word: after a leading N word, else at the
/// first word.
fn insert_point_for_motion(block: &Block) -> usize {
    match block.words.first() {
        Some(w) if w.letter == b'N' => block
            .words
            .get(1)
            .map_or(w.end as usize + 1, |n| n.start as usize),
        Some(w) => w.start as usize,
        None => 0,
    }
}

/// Where to insert an axis word in a block that has none.
fn insert_point_for_axes(block: &Block) -> usize {
    block
        .words
        .iter()
        .filter(|w| matches!(w.letter, b'N' | b'G'))
        .map(|w| w.end as usize)
        .max()
        .unwrap_or_else(|| block.words.last().map_or(0, |w| w.end as usize))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_are_fixed_point() {
        assert_eq!(format_number(1e-7, 4, false), "0.0000");
        assert_eq!(format_number(-0.00001, 3, false), "0.000");
        assert_eq!(format_number(12.5, 4, true), "12.5");
        assert_eq!(format_number(12.0, 3, true), "12.");
        assert_eq!(format_number(123456789.125, 3, false), "123456789.125");
    }

    #[test]
    fn fast_formatting_agrees_with_the_exact_one() {
        // The exact decimal formatting of the standard library is the
        // reference; ties (x.xxx5 exactly) fall back to it.
        let mut v = -1234.56789f64;
        for _ in 0..20_000 {
            for d in 0..8 {
                if let Some(fast) = fixed(v, d) {
                    assert_eq!(fast, format!("{v:.d$}"), "{v} with {d} decimals");
                }
            }
            v += 0.12345678901;
        }
        for (v, d) in [(0.5, 0), (2.5, 0), (0.125, 2), (-0.0004, 3), (1e20, 3)] {
            assert_eq!(format_number(v, d, false), {
                let s = format!("{v:.d$}");
                let s = if s.starts_with('-') && s[1..].bytes().all(|b| b == b'0' || b == b'.') {
                    s[1..].to_string()
                } else {
                    s
                };
                if s.contains('.') { s } else { format!("{s}.") }
            });
        }
    }
}
