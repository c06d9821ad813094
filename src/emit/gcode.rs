//! Byte-faithful G-code writer.
//!
//! Unchanged blocks are copied byte for byte. A compensated block gets only
//! its coordinate words rewritten (same decimals as the program, or the
//! machine file's setting, never exponent notation); missing axis words are
//! inserted after the block's last axis word when the compensation moves that
//! axis; added blocks (segments of a split move) copy the block's style
//! (case, spacing, line ending). An annotation comment with the predicted
//! deviation is appended in the program's comment style.

mod cycles;

use super::fixed::{FIXED_MAX, exact_fixed, fixed_digits, pow10, round_half_away};
use super::inverse_time::{PieceFeeds, decimals};
use nalgebra::Vector3;

use crate::compensate::BlockResult;
pub use crate::compensate::outcome::AddedLines;
use crate::machine::{AXIS_LETTERS, AxisVec};
use crate::predict::Effect;
use crate::program::gcode::{Block, Word, strip_eol};
use crate::program::interp::{ArcGeom, Motion, Plan, PlanKind};

/// Output options.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EmitOptions {
    /// Decimals of rewritten mm coordinates (inch: one more); `None` keeps
    /// the program's own, with at least 3 (mm) or 4 (inch).
    pub decimals_mm: Option<usize>,
    /// Decimals of rewritten rotary-axis words (degrees); `None` keeps the
    /// program's own, with at least the fewest whose rounding keeps to
    /// [`ROUNDING_SHARE`] of the tolerance at [`ROTARY_LEVER_MM`].
    pub decimals_deg: Option<usize>,
    /// Append `(dev … mm geo …)` comments to compensated blocks.
    pub annotate: bool,
}

/// Default decimals of rewritten mm words when the program has fewer.
pub const DEFAULT_DECIMALS_MM: usize = 3;

/// Share of the tolerance that rounding a written coordinate may take (half
/// a unit of its last decimal, in mm): the decimals grow until it fits.
pub const ROUNDING_SHARE: f64 = 0.25;

/// Share of the tolerance within which a canned cycle's hole block keeps
/// the modal Z, R or axis value it inherits instead of getting a word for
/// the corrected one (per word; X, Y and Z together stay within about 0.43
/// of the tolerance).
pub const KEPT_WORD_SHARE: f64 = 0.25;

/// Most decimals a written coordinate gets.
const MAX_DECIMALS: usize = 8;

/// Rounding allowance of the travel limits, mm or deg (the one the
/// compensation and `check` keep to).
const LIMIT_SLACK: f64 = 1e-9;

/// The distance of the tool tip from a rotary axis at which the rounding
/// of a rotary word is judged, mm: half a metre bounds it on the machine
/// tools this writes for (a table of 500 mm or a head with a tool of
/// 200 mm and a pivot of 300 mm).
pub const ROTARY_LEVER_MM: f64 = 500.0;

/// The fewest decimals of a rotary word (degrees) whose rounding (half a
/// unit of its last decimal) moves the tip by at most [`ROUNDING_SHARE`]
/// of `tol` at [`ROTARY_LEVER_MM`].
fn rotary_tolerance_decimals(tol: f64) -> usize {
    (0..MAX_DECIMALS)
        .find(|&d| (0.5 / pow10(d)).to_radians() * ROTARY_LEVER_MM <= tol * ROUNDING_SHARE)
        .unwrap_or(MAX_DECIMALS)
}

/// How far (mm) the rounding of the two rotary words of a written point
/// can move its tip at [`ROTARY_LEVER_MM`], with the decimals a
/// compensation at `tolerance_mm` writes rotary words without decimals of
/// their own with: added to [`rounding_mm`] on machines with rotary axes.
pub fn rotary_rounding_mm(opts: &EmitOptions, tolerance_mm: f64) -> f64 {
    let d = opts
        .decimals_deg
        .unwrap_or_else(|| rotary_tolerance_decimals(tolerance_mm));
    2.0 * (0.5 / pow10(d)).to_radians() * ROTARY_LEVER_MM
}

/// How far (mm) the rounding of the written words can move a written
/// piece off the one that was solved, with the decimals a compensation at
/// `tolerance_mm` writes linear words with ([`Emitter::with_tolerance`]),
/// in a program of units `scale` mm (1 for mm, 25.4 for inch): half a
/// unit of the last decimal per word, for the three coordinates of each
/// end and the two centre words of an arc read from the rounded start
/// (four half units bound both). The compensation solves within the
/// tolerance less this, so that the written program keeps the tolerance it
/// states.
pub fn rounding_mm(opts: &EmitOptions, tolerance_mm: f64, scale: f64) -> f64 {
    4.0 * half_unit_mm(opts, tolerance_mm, scale)
}

/// Half a unit of the last decimal of a rewritten linear word without
/// decimals of its own, mm, in program units of `scale` mm.
fn half_unit_mm(opts: &EmitOptions, tolerance_mm: f64, scale: f64) -> f64 {
    let d = opts.decimals_mm.unwrap_or(DEFAULT_DECIMALS_MM);
    let d = if scale != 1.0 { d + 1 } else { d };
    let d = d.max(tolerance_decimals(tolerance_mm, scale));
    0.5 * scale / pow10(d)
}

/// The fewest decimals of a linear word (in program units of `scale` mm)
/// whose rounding stays within [`ROUNDING_SHARE`] of `tol`.
fn tolerance_decimals(tol: f64, scale: f64) -> usize {
    (0..MAX_DECIMALS)
        .find(|&d| 0.5 * scale / pow10(d) <= tol * ROUNDING_SHARE)
        .unwrap_or(MAX_DECIMALS)
}

/// What an added line is (see [`AddedLines`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum AddedKind {
    Arc,
    Chord,
    Split,
}

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
    /// A hole was written as moves: the control has no cycle in force
    /// until the program ends it (see `cycles`).
    cycle_broken: bool,
    /// Machine Z of the initial level of the cycle in force in the written
    /// program (where the tool stood when it began); `None` without one.
    cycle_initial: Option<f64>,
    /// The initial level of the cycle a hole written as moves ended, to
    /// return to before the cycle is stated again.
    broken_initial: Option<f64>,
    /// The program writes `;` comments rather than `( )`.
    semicolon_comments: Option<bool>,
    /// The program separates its words by spaces (from its last block of
    /// two words or more; a block of one word shows no style).
    spaced: bool,
    /// Changed blocks so far.
    changed: usize,
    /// Blocks added by segmentation.
    added: usize,
    /// The added blocks by why they were added.
    added_by: AddedLines,
    /// Edits of the block being written (kept for their buffers).
    edits: Edits,
    /// Tolerance of the compensation, mm (see [`Emitter::with_tolerance`]).
    tolerance_mm: Option<f64>,
    /// [`tolerance_decimals`] of the tolerance in millimetres, worked out
    /// once (every word of a millimetre program asks for it).
    tolerance_decimals_mm: usize,
    /// The travel of each axis in the coordinates of the plans written
    /// ([`Emitter::set_limits`]): a rounded word that would leave it is
    /// rounded the other way.
    limits: [Option<(f64, f64)>; 6],
    /// Where each line written for the last compensated block leaves the
    /// machine, in the coordinates of its plan ([`Emitter::written`]).
    written: Vec<AxisVec>,
    /// The uncertainty the annotations state ([`Emitter::with_uncertainty`]).
    uncertainty: Option<std::sync::Arc<crate::predict::uncertainty::BlockUncertainty>>,
}

/// Formats `v` with `d` decimals, never in exponent notation and never as
/// negative zero; `trim` drops trailing zeros (keeping the point).
pub fn format_number(v: f64, d: usize, trim: bool) -> String {
    let mut out = Vec::with_capacity(24);
    write_number(&mut out, v, d, trim);
    String::from_utf8(out).unwrap_or_default()
}

/// [`format_number`] appended to `out`, without an intermediate string.
pub fn write_number(out: &mut Vec<u8>, v: f64, d: usize, trim: bool) {
    let mut buf = [0u8; FIXED_MAX];
    if let Some(len) = fixed_digits(&mut buf, v, d) {
        // `fixed_digits` writes no sign for a zero, the point when there are
        // decimals: what is left of the clean-up is the trimming, and the
        // point of a whole number.
        let mut s = buf.get(..len).unwrap_or(&[]);
        if d > 0 && trim {
            while let Some((&b'0', rest)) = s.split_last() {
                s = rest;
            }
        }
        // The whole buffer (a copy of constant size, no library call), cut
        // back to the text.
        let start = out.len();
        out.extend_from_slice(&buf);
        out.truncate(start + s.len());
        if d == 0 {
            out.push(b'.');
        }
        return;
    }
    let start = out.len();
    out.extend_from_slice(exact_fixed(v, d).as_bytes());
    let has_point = out[start..].contains(&b'.');
    if trim && has_point {
        while out.last() == Some(&b'0') {
            out.pop();
        }
    }
    if !has_point {
        out.push(b'.');
    }
}

/// [`fixed_digits`] with the sign of a zero kept (exactly `format!`'s text),
/// appended to `out`; whether it was safe.
#[cfg(test)]
fn write_fixed(out: &mut Vec<u8>, v: f64, d: usize) -> bool {
    let mut buf = [0u8; FIXED_MAX];
    match fixed_digits(&mut buf, v, d) {
        Some(len) => {
            if buf.first() != Some(&b'-') && v.is_sign_negative() {
                out.push(b'-');
            }
            out.extend_from_slice(buf.get(..len).unwrap_or(&[]));
            true
        }
        None => false,
    }
}

/// `round_to(v, d) == 0.0` without the division: the rounded product is
/// zero exactly when it is below one half in magnitude (false for NaN).
#[inline]
fn rounds_to_zero(v: f64, d: usize) -> bool {
    (v * pow10(d)).abs() < 0.5
}

fn round_to(v: f64, d: usize) -> f64 {
    let f = pow10(d);
    round_half_away(v * f) / f
}

/// A replacement of `start..end` of the line by `text` (a range of
/// [`Edits::text`]).
#[derive(Debug, Clone)]
struct Edit {
    start: usize,
    end: usize,
    text: std::ops::Range<usize>,
    /// The removal of a word that goes to the block's last piece (see
    /// [`acts_at_block_end`]).
    moved: bool,
}

/// M codes that act before the motion of their block: spindle start
/// (`M3`, `M4`), coolant on (`M7`, `M8`) and spindle start with coolant
/// (`M13`, `M14`). A block written as several pieces keeps them on its
/// first line.
pub const M_BEFORE_MOTION: [i64; 6] = [3, 4, 7, 8, 13, 14];

/// True for a word that acts at or after the end of its block's motion:
/// every M code but those of [`M_BEFORE_MOTION`] (program stop and end,
/// spindle and coolant off, tool change, orientation, machine-builder
/// codes), the one-shot exact stop `G9` and the corner words `,C`/`,R`.
/// When a block is written as
/// several pieces (a takeup point, a split move, an arc cut at its
/// reversals) these words go to the last piece, so that they act where
/// the block's motion ends; every other word (N, modal G codes, F, S, T,
/// H, D) stays on the block's own line, the first piece, and acts before
/// the motion as written.
pub fn acts_at_block_end(w: &Word) -> bool {
    match w.letter {
        b'M' => !w
            .exact_code10()
            .is_some_and(|c| c % 10 == 0 && M_BEFORE_MOTION.contains(&(c / 10))),
        b'G' => w.exact_code10() == Some(90),
        // The control makes the corner where the block's line ends.
        crate::program::gcode::CHAMFER | crate::program::gcode::CORNER_RADIUS => true,
        _ => false,
    }
}

/// The edits of one block, their texts in one buffer; reused between blocks
/// so that rewriting a block allocates nothing.
#[derive(Debug, Clone, Default)]
struct Edits {
    list: Vec<Edit>,
    text: Vec<u8>,
}

impl Edits {
    fn clear(&mut self) {
        self.list.clear();
        self.text.clear();
    }

    fn is_empty(&self) -> bool {
        self.list.is_empty()
    }

    /// An edit whose text `write` appends to the buffer.
    fn push(&mut self, start: usize, end: usize, write: impl FnOnce(&mut Vec<u8>)) {
        let from = self.text.len();
        write(&mut self.text);
        self.list.push(Edit {
            start,
            end,
            text: from..self.text.len(),
            moved: false,
        });
    }

    /// Removes the word `w` of `text` and one space next to it (the one
    /// before it, else the one after it; not one another moved word takes),
    /// marked as moved. The word and its space are two edits, so that a
    /// word inserted before `w` stays.
    fn remove_moved(&mut self, w: &Word, text: &[u8]) {
        let (start, end) = (w.start as usize, w.end as usize);
        let free = |at: usize| {
            text.get(at) == Some(&b' ') && !self.list.iter().any(|e| e.moved && e.start == at)
        };
        let space = [start.checked_sub(1), Some(end)]
            .into_iter()
            .flatten()
            .find(|&at| free(at));
        for (s, e) in [Some((start, end)), space.map(|s| (s, s + 1))]
            .into_iter()
            .flatten()
        {
            self.list.push(Edit {
                start: s,
                end: e,
                text: 0..0,
                moved: true,
            });
        }
    }

    /// Drops the removals of moved words (their words stay where they are).
    fn keep_moved(&mut self) {
        self.list.retain(|e| !e.moved);
    }

    /// Inserts ` X1.234` (with `sep` before the letter) at `at`.
    fn insert_word(&mut self, at: usize, sep: &str, letter: u8, v: f64, d: usize) {
        self.insert_at(Slot::After(at), sep, letter, v, d);
    }

    /// Inserts a word at `slot`: ` X1.234` after a word, `X1.234 ` before
    /// one (`sep` between the words).
    fn insert_at(&mut self, slot: Slot, sep: &str, letter: u8, v: f64, d: usize) {
        let at = slot.pos();
        self.push(at, at, |t| {
            if let Slot::After(_) = slot {
                t.extend_from_slice(sep.as_bytes());
            }
            t.push(letter);
            write_number(t, v, d, true);
            if let Slot::Before(_) = slot {
                t.extend_from_slice(sep.as_bytes());
            }
        });
    }

    /// Replaces a word's number, trimming trailing zeros when the program
    /// wrote fewer decimals than `d`.
    fn number(&mut self, w: &Word, v: f64, d: usize) {
        self.push(w.num_start as usize, w.end as usize, |t| {
            write_number(t, v, d, w.decimals.is_none_or(|od| (od as usize) < d))
        });
    }

    /// Writes `text` with the edits applied (in order of position; edits at
    /// the same place in the order they were made) into `out`.
    fn apply(&mut self, text: &[u8], out: &mut Vec<u8>) {
        self.list.sort_by_key(|e| (e.start, e.end));
        let mut pos = 0;
        for e in &self.list {
            if e.start < pos {
                continue;
            }
            out.extend_from_slice(&text[pos..e.start]);
            out.extend_from_slice(&self.text[e.text.clone()]);
            pos = e.end;
        }
        out.extend_from_slice(&text[pos..]);
    }
}

/// Where an inserted word goes: after the word ending at the position, or
/// before the word starting there.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Slot {
    After(usize),
    Before(usize),
}

impl Slot {
    fn pos(self) -> usize {
        match self {
            Slot::After(p) | Slot::Before(p) => p,
        }
    }
}

/// Where a missing axis word of `slot` goes so that the block's axis words
/// stay together and in axis order (X Y Z A B C): after the block's word of
/// the nearest axis before it, else before the word of the nearest axis
/// after it, else where [`insert_point_for_axes`] puts the first axis word
/// of a block (before its feed, speed and auxiliary words).
fn axis_slot_for(block: &Block, slot: usize) -> Slot {
    let word = |s: usize| {
        AXIS_LETTERS
            .get(s)
            .and_then(|&l| block.words.iter().find(|w| w.letter == l))
    };
    if let Some(w) = (0..slot).rev().find_map(word) {
        return Slot::After(w.end as usize);
    }
    if let Some(w) = (slot + 1..6).find_map(word) {
        return Slot::Before(w.start as usize);
    }
    insert_point_for_axes(block)
}

/// Starts a line added after `block`'s: a newline first when the block's
/// line has no line end (the file's last line), and the `/` of a
/// block-delete block (the switch skips the added lines with it). Returns
/// where the line's words begin.
fn added_line_start(block: &Block, eol: &[u8], out: &mut Vec<u8>) -> usize {
    if eol.is_empty() {
        out.push(b'\n');
    }
    if block.block_delete {
        out.push(b'/');
    }
    out.len()
}

/// Largest gain from a rounding or a correction to the centre an `R` word
/// gives, at which a moved arc keeps its `R` word. The centre moves by the
/// ratio of the radius to the centre's distance from the chord times the
/// change of the radius, so within about 11.5° of a half turn (where that
/// ratio exceeds 10) the rounding of `R` and the two slightly different
/// radii of a compensated arc would put the centre microns off. It moves
/// by the ratio of the radius to the half chord times the rounding of the
/// end points, so an arc (or piece of one) of less than about 11.5° gets
/// its centre words too: a piece of a few microns cut off at a reversal
/// next to the arc's start would otherwise put the centre far off.
pub const R_FORM_MAX_GAIN: f64 = 10.0;

/// An `R` word can carry the centre of `arc` (see [`R_FORM_MAX_GAIN`]).
fn r_form_holds(arc: &crate::program::interp::ArcGeom) -> bool {
    let half = arc.sweep / 2.0;
    half.cos().abs() * R_FORM_MAX_GAIN >= 1.0 && half.sin().abs() * R_FORM_MAX_GAIN >= 1.0
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
            cycle_broken: false,
            cycle_initial: None,
            broken_initial: None,
            semicolon_comments: None,
            spaced: true,
            changed: 0,
            added: 0,
            added_by: AddedLines::default(),
            edits: Edits::default(),
            tolerance_mm: None,
            tolerance_decimals_mm: 0,
            limits: [None; 6],
            written: Vec::new(),
            uncertainty: None,
        }
    }

    /// The emitter stating in each annotation the expanded uncertainty
    /// `U` (k=2) of the block's predicted deviation, from the machine
    /// file's parameter covariance (`None`: annotations without it).
    pub fn with_uncertainty(
        mut self,
        u: Option<std::sync::Arc<crate::predict::uncertainty::BlockUncertainty>>,
    ) -> Self {
        self.uncertainty = u;
        self
    }

    /// The emitter for a compensation at `tolerance_mm`: words are written
    /// with enough decimals that rounding moves a point by at most
    /// [`ROUNDING_SHARE`] of the tolerance (inch programs get more decimals
    /// than the machine file's mm setting gives them when needed), and the
    /// hole blocks of canned cycles get no word they lack while the modal
    /// value stays within [`KEPT_WORD_SHARE`] of the tolerance of the
    /// corrected one.
    pub fn with_tolerance(mut self, tolerance_mm: f64) -> Self {
        self.tolerance_mm = Some(tolerance_mm);
        self.tolerance_decimals_mm = tolerance_decimals(tolerance_mm, 1.0);
        self
    }

    /// How far (mm) a canned cycle's modal word may be from its corrected
    /// value before the hole block gets the word: [`KEPT_WORD_SHARE`] of
    /// the tolerance (0 without one: any change adds the word).
    fn kept_word_mm(&self) -> f64 {
        self.tolerance_mm.map_or(0.0, |t| t * KEPT_WORD_SHARE)
    }

    /// Number of blocks whose text changed.
    pub fn changed_blocks(&self) -> usize {
        self.changed
    }

    /// Number of blocks added by segmentation.
    pub fn added_blocks(&self) -> usize {
        self.added
    }

    /// The blocks added by segmentation, by why they were added.
    pub fn added_by(&self) -> AddedLines {
        self.added_by
    }

    /// Sets the travel of each axis (mm or deg, `None` for an axis without
    /// one) in the coordinates of the plans written next (machine
    /// coordinates; tool tips under TCPM): a written word whose rounding
    /// would leave it is rounded the other way, one unit of its last
    /// decimal nearer the inside.
    pub fn set_limits(&mut self, limits: [Option<(f64, f64)>; 6]) {
        self.limits = limits;
    }

    /// Where each line written for the last compensated block (its own and
    /// the added ones) leaves the machine, in the coordinates of its plan,
    /// as the written words command it.
    pub fn written(&self) -> &[AxisVec] {
        &self.written
    }

    /// `v` (a program value of axis `slot` rounded to `d` decimals, with
    /// `now` where the machine stands) one unit of its last decimal nearer
    /// the inside when the machine coordinate it commands is beyond the
    /// limits of [`Emitter::set_limits`] (a point solved at the end of the
    /// travel rounds past it by up to half a unit).
    fn inside(&self, plan: &Plan, slot: usize, v: f64, d: usize, now: f64) -> f64 {
        let Some((lo, hi)) = self.limits[slot] else {
            return v;
        };
        let m = to_machine(plan, slot, v, now);
        let unit = 1.0 / pow10(d);
        if m > hi + LIMIT_SLACK {
            round_to(v - unit, d)
        } else if m < lo - LIMIT_SLACK {
            round_to(v + unit, d)
        } else {
            v
        }
    }

    fn decimals(&self, w: Option<&Word>, scale: f64, rotary: bool) -> usize {
        let own = w.and_then(|w| w.decimals).unwrap_or(0) as usize;
        let own = own.min(crate::limits::EMIT_MAX_DECIMALS);
        let base = if rotary {
            // The program's own decimals, as many more as the tolerance
            // needs (or exactly what `--decimals` or the machine file ask
            // for, at least the program's).
            self.opts.decimals_deg.unwrap_or_else(|| {
                self.tolerance_mm
                    .map_or(DEFAULT_DECIMALS_MM, rotary_tolerance_decimals)
            })
        } else {
            let d = self.opts.decimals_mm.unwrap_or(DEFAULT_DECIMALS_MM);
            let d = if scale != 1.0 { d + 1 } else { d };
            d.max(self.tolerance_decimals(scale))
        };
        own.max(base)
    }

    /// The fewest decimals of a linear word (in program units of `scale` mm)
    /// whose rounding stays within [`ROUNDING_SHARE`] of the tolerance (0
    /// without a tolerance).
    fn tolerance_decimals(&self, scale: f64) -> usize {
        let Some(tol) = self.tolerance_mm else {
            return 0;
        };
        if scale == 1.0 {
            return self.tolerance_decimals_mm;
        }
        tolerance_decimals(tol, scale)
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
        self.written.clear();
        if self.semicolon_comments.is_none() {
            if let Some(c) = block.comments.first() {
                self.semicolon_comments = Some(c.semicolon);
            }
        }
        if block.words.len() > 1 {
            self.spaced = block.spaced;
        }
        self.track_cycle(block);
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
            self.track_unchanged(block, plan);
            return;
        }
        let mut edits = std::mem::take(&mut self.edits);
        edits.clear();
        if res.expansion.is_empty() {
            // A hole after one written as moves states its cycle again;
            // a modal motion to restore waits for the cycle's end.
            let is_cycle = matches!(plan.kind, PlanKind::Cycle { .. });
            let pending = self.motion_pending.filter(|_| is_cycle);
            self.restore_initial(line, block, plan, out);
            self.restate_cycle(block, plan, &mut edits);
            self.write_edited(line, block, plan, mv, res, &mut edits, out);
            if pending.is_some() {
                self.motion_pending = pending;
            }
        } else {
            self.write_expansion(line, block, plan, res, &mut edits, out);
        }
        self.edits = edits;
    }

    /// [`Emitter::write`] of a compensated block, with `edits` as workspace.
    #[allow(clippy::too_many_arguments)]
    fn write_edited(
        &mut self,
        line: &[u8],
        block: &Block,
        plan: &Plan,
        mv: crate::program::interp::Move,
        res: &BlockResult,
        edits: &mut Edits,
        out: &mut Vec<u8>,
    ) {
        let text = strip_eol(line);
        let eol = &line[text.len()..];
        let scale = plan.scale;
        let is_cycle = matches!(plan.kind, PlanKind::Cycle { .. });
        let first_target = if let Some(first) = res.segments.first() {
            *first
        } else {
            res.end
        };

        // The arc piece the block's own line writes, if any; without one,
        // an arc block's own line is a straight move (G1, no centre words)
        // to a takeup point or the first chord's end.
        let own_piece = res.arcs.first().filter(|p| p.to == 0);
        let own_linear = mv.arc.is_some() && own_piece.is_none();

        let motion_word = self.motion_edits(block, text, (own_linear, is_cycle), edits);

        // Axis words.
        let start_emitted = self.emitted;
        let (mut new_emitted, last_axis_end) =
            self.axis_edits(block, plan, &mv, &first_target, edits);
        if let PlanKind::Cycle { .. } = plan.kind {
            // Where the written hole leaves the tool (see `cycles`).
            new_emitted[2] = self.cycle_words(block, plan, res, edits);
        }
        // Arc centre words.
        if let (Some(piece), Some(arc)) = (own_piece, mv.arc) {
            let ends = (&start_emitted, &first_target, last_axis_end);
            self.centre_edits(block, text, plan, (&mv, &arc, piece), ends, edits);
        }
        // G93: each piece of a split move gets its share of the duration.
        let feeds = (plan.inverse_time && !res.segments.is_empty())
            .then(|| block.word(b'F'))
            .flatten()
            .map(|f| {
                let pieces = res.segments.iter().chain(std::iter::once(&res.end));
                let feeds = PieceFeeds::new(f.value, &start_emitted, pieces);
                edits.number(f, feeds.feed(&start_emitted, &first_target), decimals(f));
                (feeds, decimals(f), first_target)
            });
        if self.opts.annotate {
            self.annotation(block, text, (&mv.end, res), scale, edits);
        }
        // Words that act where the block's motion ends go to its last piece.
        let moved = !res.segments.is_empty() && block.words.iter().any(acts_at_block_end);
        if moved {
            for w in block.words.iter().filter(|w| acts_at_block_end(w)) {
                edits.remove_moved(w, text);
            }
        }
        let own_start = out.len();
        self.write_own(line, eol, edits, out);
        let own_end = out.len();
        self.emitted = new_emitted;
        self.written.push(new_emitted);
        // Added lines end with the block's line end; after a last line
        // without one, each starts with a newline instead (the file still
        // ends without one).
        if !res.segments.is_empty() {
            // `G02` in programs that write two digits.
            let two_digit = motion_word.is_some_and(|w| {
                w.end > w.num_start + 1 && text.get(w.num_start as usize) == Some(&b'0')
            });
            let first = if own_linear {
                Motion::Linear
            } else {
                mv.motion
            };
            let last = self.added_lines(
                block,
                plan,
                (&mv, res),
                (first, two_digit, feeds.as_ref()),
                eol,
                out,
            );
            if mv.arc.is_some() && last != mv.motion {
                self.motion_pending = Some(mv.motion);
            }
            if moved {
                self.place_moved(block, line, eol, edits, (own_start, own_end), out);
            }
        } else if own_linear {
            self.motion_pending = Some(mv.motion);
        }
    }

    /// Writes a compensated block's own line: `line` with `edits` applied
    /// (`line` itself when there are none), ending with `eol`.
    fn write_own(&mut self, line: &[u8], eol: &[u8], edits: &mut Edits, out: &mut Vec<u8>) {
        if edits.is_empty() {
            out.extend_from_slice(line);
        } else {
            self.changed += 1;
            edits.apply(strip_eol(line), out);
            out.extend_from_slice(eol);
        }
    }

    /// Puts the words of a block written as several pieces that act at
    /// the end of its motion ([`acts_at_block_end`]) at the end of its last
    /// line, as written and in their order. When no line was added after
    /// the block's own one (`own` its range in `out`), that line is the
    /// whole move and is written again with the words where they were.
    fn place_moved(
        &mut self,
        block: &Block,
        line: &[u8],
        eol: &[u8],
        edits: &mut Edits,
        (own_start, own_end): (usize, usize),
        out: &mut Vec<u8>,
    ) {
        if out.len() == own_end {
            out.truncate(own_start);
            if !edits.is_empty() {
                self.changed -= 1;
            }
            edits.keep_moved();
            self.write_own(line, eol, edits, out);
            return;
        }
        let text = strip_eol(line);
        let mut words = Vec::new();
        for w in block.words.iter().filter(|w| acts_at_block_end(w)) {
            if self.spaced {
                words.push(b' ');
            }
            words.extend_from_slice(text.get(w.start as usize..w.end as usize).unwrap_or(b""));
        }
        let at = out.len() - eol.len();
        out.splice(at..at, words);
    }

    /// The edits of a compensated block's motion word: `G1` where an arc
    /// block's own line is straight (its centre and turn words dropped),
    /// the motion mode a block lacks after a line that changed it. Returns
    /// the block's motion word.
    fn motion_edits<'b>(
        &mut self,
        block: &'b Block,
        text: &[u8],
        (own_linear, is_cycle): (bool, bool),
        edits: &mut Edits,
    ) -> Option<&'b Word> {
        let lower = block.lower_case;
        let spaced = self.spaced;
        // Motion word handling for replaced arcs and pending modal motion.
        let motion_word = block
            .words
            .iter()
            .find(|w| w.letter == b'G' && matches!(w.code10(), 0 | 10 | 20 | 30));
        if own_linear {
            match motion_word {
                Some(w) => {
                    let old = &text[w.num_start as usize..w.end as usize];
                    let new: &[u8] = if old.len() >= 2 && old[0] == b'0' {
                        b"01"
                    } else {
                        b"1"
                    };
                    edits.push(w.num_start as usize, w.end as usize, |t| {
                        t.extend_from_slice(new)
                    });
                }
                None => {
                    let at = insert_point_for_motion(block);
                    let g: &[u8] = if lower { b"g1" } else { b"G1" };
                    edits.push(at, at, |t| {
                        t.extend_from_slice(g);
                        if spaced || at > 0 {
                            t.push(b' ');
                        }
                    });
                }
            }
            // The arc's words go: its centre and its number of turns (`P1`;
            // more turns are refused by the interpreter).
            for w in block
                .words
                .iter()
                .filter(|w| matches!(w.letter, b'I' | b'J' | b'K' | b'R' | b'P'))
            {
                // Take the separating space before the word with it.
                let mut start = w.start as usize;
                if start > 0 && text.get(start - 1) == Some(&b' ') {
                    start -= 1;
                }
                edits.push(start, w.end as usize, |_| {});
            }
        } else if let Some(m) = self.motion_pending {
            if motion_word.is_none() && !is_cycle {
                let at = insert_point_for_motion(block);
                let code = match m {
                    Motion::ArcCw => b'2',
                    Motion::ArcCcw => b'3',
                    Motion::Linear => b'1',
                    Motion::Rapid => b'0',
                };
                let g = if lower { b'g' } else { b'G' };
                edits.push(at, at, |t| t.extend_from_slice(&[g, code, b' ']));
            }
        }
        // Set again after the added lines (see `added_lines`).
        self.motion_pending = None;
        motion_word
    }

    /// The edits of a compensated block's axis words for its first target:
    /// its own words rewritten, the words its correction needs inserted in
    /// axis order. Returns where the machine then stands and where the
    /// block's last axis word ends.
    fn axis_edits(
        &self,
        block: &Block,
        plan: &Plan,
        mv: &crate::program::interp::Move,
        first_target: &AxisVec,
        edits: &mut Edits,
    ) -> (AxisVec, Option<usize>) {
        let scale = plan.scale;
        let lower = block.lower_case;
        let sep = if self.spaced { " " } else { "" };
        let is_cycle = matches!(plan.kind, PlanKind::Cycle { .. });
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
            match w {
                Some(w) => {
                    let now = self.emitted[slot];
                    let rounded = round_to(to_program(plan, slot, target, now), d);
                    let rounded = self.inside(plan, slot, rounded, d, now);
                    let orig = round_to(w.value, d);
                    if rounded != orig || w.decimals.unwrap_or(0) as usize > d {
                        edits.number(w, rounded, d);
                        new_emitted[slot] = to_machine(plan, slot, rounded, self.emitted[slot]);
                    } else {
                        new_emitted[slot] = to_machine(plan, slot, w.value, self.emitted[slot]);
                    }
                }
                None => {
                    // An axis that stays where it is needs no word (the
                    // rounded values below would be equal).
                    if target == self.emitted[slot] {
                        continue;
                    }
                    let now = round_to(
                        to_program(plan, slot, self.emitted[slot], self.emitted[slot]),
                        d,
                    );
                    let want = round_to(to_program(plan, slot, target, self.emitted[slot]), d);
                    let want = self.inside(plan, slot, want, d, self.emitted[slot]);
                    // Rapids position only the axes they program (under
                    // TCPM every tip word moves the other axes: a rapid
                    // gets each word its correction needs, so that the
                    // machine goes where it was solved, travel ends too).
                    let positioning = mv.motion == Motion::Rapid
                        && !plan.tcpm
                        && plan.programmed & (1 << slot) == 0;
                    // A hole of a canned cycle keeps the modal value
                    // while it is close enough to the corrected one.
                    let kept =
                        is_cycle && slot < 3 && (want - now).abs() * scale <= self.kept_word_mm();
                    if want != now
                        && !positioning
                        && !kept
                        && (slot < 3 || self.has_axis_word_or_moved(slot, target))
                    {
                        let letter = letter_case(AXIS_LETTERS[slot], lower);
                        edits.insert_at(axis_slot_for(block, slot), sep, letter, want, d);
                        new_emitted[slot] = to_machine(plan, slot, want, self.emitted[slot]);
                    }
                }
            }
        }
        (new_emitted, last_axis_end)
    }

    /// The edits of the centre words of the arc piece a block's own line
    /// writes (from `start` to `first`; `last_axis_end` where the block's
    /// axis words end).
    fn centre_edits(
        &self,
        block: &Block,
        text: &[u8],
        plan: &Plan,
        (mv, arc, piece): (
            &crate::program::interp::Move,
            &ArcGeom,
            &crate::compensate::ArcPiece,
        ),
        (start_emitted, first_target, last_axis_end): (&AxisVec, &AxisVec, Option<usize>),
        edits: &mut Edits,
    ) {
        let lower = block.lower_case;
        let sep = if self.spaced { " " } else { "" };
        let center = piece.center;
        let arc = ArcGeom {
            sweep: piece.sweep,
            ..*arc
        };
        // An `R` word that cannot carry the moved centre is replaced by
        // the centre words.
        let moved = *first_target != mv.end || *start_emitted != mv.start;
        let r_form = !moved || r_form_holds(&arc);
        if let Some(r) = block.word(b'R').filter(|_| !r_form) {
            let mut start = r.start as usize;
            if start > 0 && text.get(start - 1) == Some(&b' ') {
                start -= 1;
            }
            edits.push(start, r.end as usize, |_| {});
        }
        let words = self.centre_words(
            block,
            plan,
            &arc,
            &center,
            (start_emitted, first_target),
            r_form,
        );
        for (letter, v, d, w) in words.into_iter().flatten() {
            match w {
                Some(w) => {
                    if v != round_to(w.value, d) {
                        edits.number(w, v, d);
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
                        edits.insert_word(at, sep, l, v, d);
                    }
                }
            }
        }
    }

    /// The annotation of a compensated block (at command `cmd`):
    /// `(dev … mm geo …)` with the predicted deviation and its parts,
    /// `U …` after the deviation where the machine file carries a
    /// covariance (its expanded uncertainty, k=2, at the spindle nose as
    /// the report states it), and `takeup` where the block's own line goes
    /// to a takeup point.
    fn annotation(
        &self,
        block: &Block,
        text: &[u8],
        (cmd, res): (&AxisVec, &BlockResult),
        scale: f64,
        edits: &mut Edits,
    ) {
        let dev = res.deviation.total().norm() / scale;
        let u = self.uncertainty.as_ref().and_then(|u| {
            u.tool_total_mm(cmd, &res.dirs, 0.0, &res.deviation.total())
                .map(|t| t / scale)
        });
        let unit: &[u8] = if scale != 1.0 { b"in" } else { b"mm" };
        let dd = if scale != 1.0 { 5 } else { 4 };
        let semicolon = self.semicolon_comments == Some(true);
        // Before a trailing `;` comment, parentheses would be swallowed by it.
        let at = match block.comments.last() {
            Some(cm) if cm.semicolon && !semicolon => cm.start as usize,
            _ => text.len(),
        };
        let inside = at < text.len();
        edits.push(at, at, |t| {
            // ` (dev … mm geo …)` at the end, `(dev … mm geo …) ` inside.
            if !inside {
                t.push(b' ');
            }
            t.extend_from_slice(if semicolon { b"; dev " } else { b"(dev " });
            write_number(t, dev, dd, false);
            t.push(b' ');
            t.extend_from_slice(unit);
            if let Some(u) = u {
                t.extend_from_slice(b" U ");
                write_number(t, u, dd, false);
            }
            // Every part that is non-zero at the printed precision; the
            // dynamic one is a vibration amplitude (not in `dev`, not
            // compensated).
            for e in Effect::TOOL {
                let part = res.deviation.part(e).norm() / scale;
                if rounds_to_zero(part, dd) {
                    continue;
                }
                t.push(b' ');
                t.extend_from_slice(e.short().as_bytes());
                t.push(b' ');
                write_number(t, part, dd, false);
            }
            // The block's own words carry a takeup point (see
            // `BlockResult::takeup`); the move follows on added lines.
            if res.takeup {
                t.extend_from_slice(b" takeup");
            }
            if !semicolon {
                t.push(b')');
            }
            if inside {
                t.push(b' ');
            }
        });
    }

    /// The lines added after a compensated block's own line: to each of the
    /// block's targets after the first, a straight move (`G1` first where
    /// the line before was an arc) or, for the pieces of an arc written as
    /// arcs, an arc line. `motion` is the motion mode in force after the
    /// block's own line; returns the one after the last added line.
    fn added_lines(
        &mut self,
        block: &Block,
        plan: &Plan,
        (mv, res): (&crate::program::interp::Move, &BlockResult),
        (mut motion, two_digit, feeds): (Motion, bool, Option<&(PieceFeeds, usize, AxisVec)>),
        eol: &[u8],
        out: &mut Vec<u8>,
    ) -> Motion {
        let n = res.segments.len();
        // Under G93, where the line before ended (each piece's F is its
        // share of the block's duration).
        let mut prev = feeds.map(|f| f.2);
        // Decimals per axis (from the block's word), found at the axis'
        // first word.
        let mut digits = [None; 6];
        let mut pieces = res.arcs.iter().filter(|p| p.to > 0).peekable();
        for k in 1..=n {
            let p = res.segments.get(k).unwrap_or(&res.end);
            // The line exists because of a takeup point: it goes to one
            // inside an arc, or on from the block's first.
            let takeup = res.takeup_at.contains(&k) || (k == 1 && res.takeup);
            let piece = pieces.next_if(|pc| pc.to == k);
            if let (Some(pc), Some(arc)) = (piece, mv.arc) {
                let sub = ArcGeom {
                    sweep: pc.sweep,
                    ..arc
                };
                self.arc_line(
                    block,
                    plan,
                    (mv.motion, two_digit),
                    &sub,
                    &pc.center,
                    p,
                    eol,
                    out,
                );
                if let (Some((feeds, d, _)), Some(from)) = (feeds, prev.as_mut()) {
                    let at = out.len() - eol.len();
                    let mut word = Vec::new();
                    word.extend_from_slice(if self.spaced { b" F" } else { b"F" });
                    write_number(&mut word, feeds.feed(from, p), *d, true);
                    out.splice(at..at, word);
                    *from = *p;
                }
                motion = mv.motion;
                self.count_added(takeup, AddedKind::Arc);
                self.written.push(self.emitted);
                continue;
            }
            let mark = out.len();
            let words = added_line_start(block, eol, out);
            if motion != Motion::Linear {
                out.push(letter_case(b'G', block.lower_case));
                if two_digit {
                    out.push(b'0');
                }
                out.push(b'1');
            }
            let start = out.len();
            self.axis_words(block, plan, p, (words, &mut digits), out);
            if out.len() == start {
                out.truncate(mark);
                continue;
            }
            if let (Some((feeds, d, _)), Some(from)) = (feeds, prev.as_mut()) {
                out.extend_from_slice(if self.spaced { b" " } else { b"" });
                out.push(letter_case(b'F', block.lower_case));
                write_number(out, feeds.feed(from, p), *d, true);
                *from = *p;
            }
            out.extend_from_slice(eol);
            self.written.push(self.emitted);
            motion = Motion::Linear;
            let kind = if mv.arc.is_some() {
                AddedKind::Chord
            } else {
                AddedKind::Split
            };
            self.count_added(takeup, kind);
        }
        motion
    }

    /// Counts an added line by why it was added.
    fn count_added(&mut self, takeup: bool, kind: AddedKind) {
        self.added += 1;
        let by = &mut self.added_by;
        match (takeup, kind) {
            (true, _) => by.takeups += 1,
            (false, AddedKind::Arc) => by.arcs += 1,
            (false, AddedKind::Chord) => by.chords += 1,
            (false, AddedKind::Split) => by.splits += 1,
        }
    }

    /// The words of the axes whose value at `p` differs, as written, from
    /// where the machine was left (which they update), each after a space
    /// in a spaced program unless it is the first after `words` (where the
    /// line's words begin); `digits` keeps each axis' decimals, found at
    /// its first word.
    fn axis_words(
        &mut self,
        block: &Block,
        plan: &Plan,
        p: &AxisVec,
        (words, digits): (usize, &mut [Option<usize>; 6]),
        out: &mut Vec<u8>,
    ) {
        for slot in 0..6 {
            let now = self.emitted[slot];
            // An axis that stays where it is needs no word.
            if p[slot] == now {
                continue;
            }
            let d = *digits[slot].get_or_insert_with(|| {
                let w = block.words.iter().find(|w| w.letter == AXIS_LETTERS[slot]);
                self.decimals(w, plan.scale, slot >= 3)
            });
            let v = round_to(to_program(plan, slot, p[slot], now), d);
            let v = self.inside(plan, slot, v, d, now);
            let cur = round_to(to_program(plan, slot, now, now), d);
            if v != cur {
                if out.len() > words && self.spaced {
                    out.push(b' ');
                }
                out.push(letter_case(AXIS_LETTERS[slot], block.lower_case));
                write_number(out, v, d, true);
                self.emitted[slot] = to_machine(plan, slot, v, now);
            }
        }
    }

    /// The added line of a kept arc after its takeup point: the motion
    /// word (two digits when the block's has them), the end point's words
    /// that differ from where the takeup point left the machine, and the
    /// centre (`R` when the block gives one, else the centre words: the
    /// block's own and any that are non-zero), relative to the takeup point
    /// unless the program's arc centres are absolute.
    #[allow(clippy::too_many_arguments)]
    fn arc_line(
        &mut self,
        block: &Block,
        plan: &Plan,
        (motion, two_digit): (Motion, bool),
        arc: &crate::program::interp::ArcGeom,
        center: &Vector3<f64>,
        end: &AxisVec,
        eol: &[u8],
        out: &mut Vec<u8>,
    ) {
        let lower = block.lower_case;
        let sep: &[u8] = if self.spaced { b" " } else { b"" };
        let start = self.emitted;
        let words = added_line_start(block, eol, out);
        out.push(if lower { b'g' } else { b'G' });
        if two_digit {
            out.push(b'0');
        }
        out.push(if motion == Motion::ArcCw { b'2' } else { b'3' });
        self.axis_words(block, plan, end, (words, &mut [None; 6]), out);
        let words = self.centre_words(block, plan, arc, center, (&start, end), r_form_holds(arc));
        for (letter, v, d, w) in words.into_iter().flatten() {
            if w.is_some() || v != 0.0 || plan.arc_absolute {
                out.extend_from_slice(sep);
                out.push(letter_case(letter, lower));
                write_number(out, v, d, true);
            }
        }
        out.extend_from_slice(eol);
    }

    /// The centre words of an arc from `start` to `end` (machine
    /// coordinates) about `center`, rounded, each with its decimals and the
    /// block's own word: `R` when the block gives one and `r_form` holds
    /// (the mean of the two radii, with the sign of the block's), else the
    /// plane's two centre letters, relative to `start` unless the program's
    /// arc centres are absolute.
    #[allow(clippy::type_complexity)]
    fn centre_words<'b>(
        &self,
        block: &'b Block,
        plan: &Plan,
        arc: &crate::program::interp::ArcGeom,
        center: &Vector3<f64>,
        (start, end): (&AxisVec, &AxisVec),
        r_form: bool,
    ) -> [Option<(u8, f64, usize, Option<&'b Word>)>; 2] {
        let scale = plan.scale;
        let (a, b, _) = arc.plane.axes();
        if let Some(r) = block.word(b'R').filter(|_| r_form) {
            let ra = ((start[a] - center[a]).hypot(start[b] - center[b])
                + (end[a] - center[a]).hypot(end[b] - center[b]))
                / 2.0;
            let d = self.decimals(Some(r), scale, false);
            // Negative for more than a half turn (a piece of an arc may
            // sweep less than the block's).
            let sign = if arc.sweep.abs() > std::f64::consts::PI {
                -1.0
            } else {
                1.0
            };
            let v = round_to(ra / scale * sign, d);
            return [Some((b'R', v, d, Some(r))), None];
        }
        let (la, lb) = arc.plane.center_letters();
        [(a, la), (b, lb)].map(|(slot, letter)| {
            let w = block.word(letter);
            let d = self.decimals(w, scale, false);
            let v = if plan.arc_absolute {
                (center[slot] - plan.offset[slot]) / scale
            } else {
                (center[slot] - start[slot]) / scale
            };
            Some((letter, round_to(v, d), d, w))
        })
    }

    fn has_axis_word_or_moved(&self, slot: usize, target: f64) -> bool {
        (self.emitted[slot] - target).abs() > 1e-9
    }

    /// Keeps the emitted position in step for blocks written unchanged.
    fn track_unchanged(&mut self, block: &Block, plan: &Plan) {
        if let Some(mv) = plan.mv {
            if plan.kind == PlanKind::Fixed {
                // A move to a machine-defined place (G28, G53): the axes it
                // names go to their (uncompensated) commands, the others
                // stay where the lines before left them.
                for (slot, e) in self.emitted.iter_mut().enumerate() {
                    if plan.programmed & (1 << slot) != 0 {
                        *e = mv.end[slot];
                    }
                }
            } else {
                let before = self.emitted[2];
                self.emitted = mv.end;
                self.cycle_unchanged(plan, before);
            }
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

fn letter_case(letter: u8, lower: bool) -> u8 {
    if lower {
        letter.to_ascii_lowercase()
    } else {
        letter
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

/// Where to insert an axis word in a block that has none: before its
/// first feed, speed, tool or auxiliary word (F, S, T, M) that follows its
/// last N or G word, else after its last word.
fn insert_point_for_axes(block: &Block) -> Slot {
    let codes_end = block
        .words
        .iter()
        .filter(|w| matches!(w.letter, b'N' | b'G'))
        .map(|w| w.end)
        .max()
        .unwrap_or(0);
    let trailing = block
        .words
        .iter()
        .find(|w| w.start >= codes_end && matches!(w.letter, b'F' | b'S' | b'T' | b'M'));
    match trailing {
        Some(w) => Slot::Before(w.start as usize),
        None => Slot::After(block.words.last().map_or(0, |w| w.end as usize)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::program::gcode::parse_line;

    #[test]
    fn r_words_are_kept_only_where_they_fix_the_centre() {
        // The centre of an `R` arc is 10× as sensitive as its radius at
        // 2·acos(0.1) = 168.5°, and 10× as sensitive as its end points at
        // 2·asin(0.1) = 11.5°: kept between the two, and for the mirror
        // images beyond a half turn.
        let arc = |deg: f64| crate::program::interp::ArcGeom {
            plane: crate::program::interp::Plane::XY,
            center: Vector3::zeros(),
            sweep: deg.to_radians(),
            radius: 2.0,
        };
        for (deg, holds) in [
            (0.1, false),
            (11.0, false),
            (12.0, true),
            (90.0, true),
            (-90.0, true),
            (168.0, true),
            (169.0, false),
            (191.0, false),
            (192.0, true),
            (-348.0, true),
            (-349.0, false),
        ] {
            assert_eq!(r_form_holds(&arc(deg)), holds, "{deg}°");
        }
    }

    #[test]
    fn words_acting_at_the_block_end_are_stops_ends_and_exact_stop() {
        let text: &[u8] =
            b"N10 G9 G90 G1 G17 X1. F100. S3000 T2 H1 M0 M01 M2 M30 M5 M6 M9 M19 M60 M3 M04 M8 M7 M13 M14";
        let mut block = Block::default();
        parse_line(text, 1, "t", &mut block).unwrap();
        let moved: Vec<&str> = block
            .words
            .iter()
            .filter(|w| acts_at_block_end(w))
            .map(|w| std::str::from_utf8(&text[w.start as usize..w.end as usize]).unwrap())
            .collect();
        assert_eq!(
            moved,
            [
                "G9", "M0", "M01", "M2", "M30", "M5", "M6", "M9", "M19", "M60"
            ]
        );
    }

    #[test]
    fn moved_words_take_one_space_with_them() {
        for (line, want) in [
            ("G1 X1. M30", "G1 X1."),
            ("G9 G1 X1.", "G1 X1."),
            ("M5 M9 G1 X1.", "G1 X1."),
            ("G1 X1. M5 M9", "G1 X1."),
            ("G1 X1. M5 (END)", "G1 X1. (END)"),
            ("G1X1.M30", "G1X1."),
        ] {
            let mut block = Block::default();
            parse_line(line.as_bytes(), 1, "t", &mut block).unwrap();
            let mut edits = Edits::default();
            for w in block.words.iter().filter(|w| acts_at_block_end(w)) {
                edits.remove_moved(w, line.as_bytes());
            }
            let mut out = Vec::new();
            edits.apply(line.as_bytes(), &mut out);
            assert_eq!(String::from_utf8(out).unwrap(), want, "{line}");
            edits.keep_moved();
            assert!(edits.is_empty());
        }
    }

    #[test]
    fn power_table_is_powi() {
        for (d, p) in crate::emit::fixed::POW10.iter().enumerate() {
            assert_eq!(p.to_bits(), 10f64.powi(d as i32).to_bits());
        }
    }

    #[test]
    fn rounding_edge_cases_are_the_library_ones() {
        for x in [
            0.5,
            -0.5,
            1.5,
            2.5,
            -2.5,
            0.49999999999999994,
            -0.49999999999999994,
            -0.0,
            0.0,
            -0.4,
            4503599627370495.5,
            -4503599627370495.5,
            4503599627370496.0,
            1e300,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::MIN_POSITIVE,
        ] {
            assert_eq!(round_half_away(x).to_bits(), x.round().to_bits(), "{x:e}");
        }
        assert!(round_half_away(f64::NAN).is_nan());
    }

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
                let mut fast = Vec::new();
                if write_fixed(&mut fast, v, d) {
                    assert_eq!(fast, format!("{v:.d$}").as_bytes(), "{v} with {d} decimals");
                }
            }
            v += 0.12345678901;
        }
        for (v, d) in [
            (0.5, 0),
            (2.5, 0),
            (0.125, 2),
            (-0.0004, 3),
            (1e20, 3),
            (-0.0, 3),
            (0.0, 0),
            (f64::NAN, 3),
            (f64::INFINITY, 2),
            (1.0005, 3),
            (-2.675, 2),
            (999999.99995, 4),
        ] {
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

    /// The reference: the exact formatting of the standard library with the
    /// same clean-up rules as [`format_number`].
    fn exact(v: f64, d: usize, trim: bool) -> String {
        let mut s = format!("{v:.d$}");
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

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(20_000))]

        #[test]
        fn zero_test_is_the_rounded_value_s(
            v in proptest::prelude::any::<f64>(),
            m in -1.0f64..1.0,
            d in 0usize..12,
        ) {
            // Any value, and values near a half unit of the last digit.
            let near = m * 1e-3 / 10f64.powi(d as i32) + 0.5 / 10f64.powi(d as i32);
            for x in [v, m, near, -near, f64::from_bits(near.to_bits() + 1), f64::from_bits(near.to_bits() - 1)] {
                proptest::prop_assert_eq!(rounds_to_zero(x, d), round_to(x, d) == 0.0, "{:e} {}", x, d);
            }
        }

        #[test]
        fn rounding_is_the_library_one(
            v in proptest::prelude::any::<f64>(),
            k in -60i32..60,
            half in proptest::prelude::any::<bool>(),
        ) {
            // Any value, and values at and next to halves of every size.
            let h = (k as f64 + if half { 0.5 } else { 0.0 }) * 2f64.powi(k.rem_euclid(53));
            for x in [v, h, -h, f64::from_bits(h.to_bits() + 1), f64::from_bits(h.to_bits().wrapping_sub(1))] {
                let (a, b) = (round_half_away(x), x.round());
                proptest::prop_assert!(a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan()), "{x:e}: {a:e} != {b:e}");
            }
        }

        #[test]
        fn written_numbers_are_the_exact_ones(
            v in proptest::prelude::any::<f64>(),
            d in 0usize..12,
            trim in proptest::prelude::any::<bool>(),
        ) {
            let mut out = b"X".to_vec();
            write_number(&mut out, v, d, trim);
            let want = exact(v, d, trim);
            proptest::prop_assert_eq!(&out[1..], want.as_bytes());
        }

        #[test]
        fn written_coordinates_are_the_exact_ones(
            // Coordinates at the program's precision, and near rounding ties.
            units in -2_000_000_000i64..2_000_000_000,
            from in 0u32..7,
            nudge in -3i32..=3,
            d in 0usize..8,
            trim in proptest::prelude::any::<bool>(),
        ) {
            let base = units as f64 / 10f64.powi(from as i32) + 0.5 / 10f64.powi(d as i32);
            let v = f64::from_bits((base.to_bits() as i64 + i64::from(nudge)) as u64);
            let mut out = Vec::new();
            write_number(&mut out, v, d, trim);
            proptest::prop_assert_eq!(out, exact(v, d, trim).into_bytes());
        }
    }
}
