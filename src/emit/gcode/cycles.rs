//! Writing a canned-cycle hole as moves ([`crate::compensate::cycles`]):
//! the block's own line becomes the positioning `G0` (its cycle words
//! dropped, its other words kept), the added lines the cycle's rapids,
//! feeds and dwell. The cycle is then no longer in force on the control:
//! the next hole block of the same cycle that is not written as moves
//! states it again (its G code, Z, R, Q, P), and the modal motion the
//! cycle left in force is written again on the next block that relies on
//! it.
//!
//! A hole written as a cycle gets its corrected Z and R words
//! ([`Emitter::cycle_words`]): under `G90` the levels themselves, under
//! `G91` R from the initial level of the cycle in force in the written
//! program and Z from the R level in force, so that each hole of an
//! incremental pattern is corrected on its own.

use super::{
    Edits, Emitter, Slot, added_line_start, axis_slot_for, insert_point_for_motion, letter_case,
    round_to, to_machine, to_program, write_number,
};
use crate::compensate::BlockResult;
use crate::compensate::cycles::{self, StepKind};
use crate::machine::AXIS_LETTERS;
use crate::program::gcode::{Block, Word, strip_eol};
use crate::program::interp::{Plan, PlanKind};

/// True for a word of the cycle that a positioning `G0` must not carry:
/// the hole's Z, R level, peck depth, dwell and repeat count.
fn cycle_only(w: &Word) -> bool {
    matches!(w.letter, b'Z' | b'R' | b'Q' | b'P' | b'K' | b'L')
}

/// The block's canned-cycle G word, if it has one.
fn cycle_word(block: &Block) -> Option<&Word> {
    block.words.iter().find(|w| {
        w.letter == b'G'
            && matches!(
                w.code10(),
                730 | 810 | 820 | 830 | 840 | 850 | 860 | 870 | 880 | 890 | 740 | 760
            )
    })
}

/// The written value of a cycle's modal word (`Z` or `R`, program units)
/// for the corrected value `v` (rounded to `d` decimals): the word the
/// block has, or the modal one in force while it stays within `kept_mm`
/// (scaled by `scale`) of `v`. Returns the value in force after the block
/// and whether the block's word must be written (changed or inserted).
fn modal_word(
    w: Option<&Word>,
    modal: Option<f64>,
    (v, d): (f64, usize),
    (scale, kept_mm): (f64, f64),
) -> (f64, bool) {
    match w {
        Some(w) if v != round_to(w.value, d) => (v, true),
        Some(w) => (w.value, false),
        None => match modal {
            Some(m) if round_to(m, d) == v || (round_to(m, d) - v).abs() * scale <= kept_mm => {
                (m, false)
            }
            _ => (v, true),
        },
    }
}

impl Emitter {
    /// Follows whether the cycle is in force on the control: a `G80` or a
    /// `G0`–`G3` ends it in the program as well.
    pub(super) fn track_cycle(&mut self, block: &Block) {
        if block
            .words
            .iter()
            .any(|w| w.letter == b'G' && matches!(w.code10(), 0 | 10 | 20 | 30 | 800))
        {
            self.cycle_broken = false;
            self.cycle_initial = None;
            self.broken_initial = None;
        }
    }

    /// A hole block written unchanged (`before`: the machine Z before it):
    /// the cycle's initial level if it begins here, and the tool left at
    /// the hole's retract level rather than at its bottom.
    pub(super) fn cycle_unchanged(&mut self, plan: &Plan, before: f64) {
        if let PlanKind::Cycle { retract, .. } = plan.kind {
            self.cycle_initial.get_or_insert(before);
            self.emitted[2] = retract;
        }
    }

    /// The edits of the Z and R words of a hole written as a cycle, and
    /// the machine Z the written hole leaves the tool at: the R level in
    /// force under `G99`, the higher of the initial and R levels under
    /// `G98`. Under `G90` the words are the corrected levels; under `G91`
    /// R is written from the initial level of the cycle in force in the
    /// written program (where the tool stood when it began) and Z from the
    /// R level in force, so each hole of an incremental pattern gets its
    /// own correction. A word the block lacks is added only when the modal
    /// value misses the corrected one by more than the kept-word share of
    /// the tolerance.
    pub(super) fn cycle_words(
        &mut self,
        block: &Block,
        plan: &Plan,
        res: &BlockResult,
        edits: &mut Edits,
    ) -> f64 {
        let scale = plan.scale;
        let kept = (scale, self.kept_word_mm());
        let initial = *self.cycle_initial.get_or_insert(self.emitted[2]);
        // The program's levels are measured from here (G90: the work zero).
        let base_r = if plan.absolute {
            plan.offset[2]
        } else {
            initial
        };
        let (wr, wz) = (block.word(b'R'), block.word(b'Z'));
        let dr = self.decimals(wr, scale, false);
        let vr = round_to((res.r_level - base_r) / scale, dr);
        let (r, write_r) = modal_word(wr, self.cycle_r, (vr, dr), kept);
        let r_machine = base_r + r * scale;
        let base_z = if plan.absolute {
            plan.offset[2]
        } else {
            r_machine
        };
        let dz = self.decimals(wz, scale, false);
        let vz = round_to((res.end[2] - base_z) / scale, dz);
        let (z, write_z) = modal_word(wz, self.cycle_z, (vz, dz), kept);
        self.cycle_r = Some(r);
        self.cycle_z = Some(z);
        let lower = block.lower_case;
        let sep = if self.spaced { " " } else { "" };
        // Z with the axis words, R after it (or where Z is inserted).
        let z_slot = axis_slot_for(block, 2);
        for (letter, w, write, v, d) in [(b'Z', wz, write_z, z, dz), (b'R', wr, write_r, r, dr)] {
            match w {
                Some(w) if write => edits.number(w, v, d),
                Some(_) => {}
                None if write => {
                    let at = match wz {
                        Some(z) if letter == b'R' => Slot::After(z.end as usize),
                        _ => z_slot,
                    };
                    edits.insert_at(at, sep, letter_case(letter, lower), v, d);
                }
                None => {}
            }
        }
        match plan.kind {
            PlanKind::Cycle {
                r_level, retract, ..
            } if retract > r_level => initial.max(r_machine),
            _ => r_machine,
        }
    }

    /// Writes the hole of a cycle block as the moves of `res.expansion`.
    pub(super) fn write_expansion(
        &mut self,
        line: &[u8],
        block: &Block,
        plan: &Plan,
        res: &BlockResult,
        edits: &mut Edits,
        out: &mut Vec<u8>,
    ) {
        let text = strip_eol(line);
        let eol = &line[text.len()..];
        let lower = block.lower_case;
        let sep = if self.spaced { " " } else { "" };
        let scale = plan.scale;
        let before = self.emitted[2];
        let mut steps = res.expansion.iter();
        let Some(first) = steps.next() else {
            return;
        };
        // The own line: the positioning, its cycle words gone.
        let g = if lower { b'g' } else { b'G' };
        match cycle_word(block) {
            Some(w) => edits.push(w.start as usize, w.end as usize, |t| {
                t.extend_from_slice(&[g, b'0'])
            }),
            None => {
                let at = insert_point_for_motion(block);
                edits.push(at, at, |t| {
                    t.extend_from_slice(&[g, b'0']);
                    t.extend_from_slice(sep.as_bytes());
                });
            }
        }
        for w in block.words.iter().filter(|w| cycle_only(w)) {
            let mut start = w.start as usize;
            if start > 0 && text.get(start - 1) == Some(&b' ') {
                start -= 1;
            }
            edits.push(start, w.end as usize, |_| {});
        }
        for (slot, &letter) in AXIS_LETTERS.iter().enumerate().take(2) {
            let w = block.word(letter);
            let d = self.hole_decimals(w, slot, scale);
            let v = round_to(
                to_program(plan, slot, first.to[slot], self.emitted[slot]),
                d,
            );
            match w {
                Some(w) => edits.number(w, v, d),
                None => {
                    let l = letter_case(letter, lower);
                    let at = super::axis_slot_for(block, slot);
                    edits.insert_at(at, sep, l, v, d);
                }
            }
            self.emitted[slot] = to_machine(plan, slot, v, self.emitted[slot]);
        }
        if self.opts.annotate {
            let cmd = plan.mv.map_or(res.end, |m| m.end);
            self.annotation(block, text, (&cmd, res), scale, edits);
        }
        self.changed += 1;
        edits.apply(text, out);
        out.extend_from_slice(eol);
        for step in steps {
            added_line_start(block, eol, out);
            self.step_line(block, plan, step, out);
            out.extend_from_slice(eol);
            self.added += 1;
        }
        // The control has no cycle, nor its Z and R, any more; the
        // cycle stated again starts from its initial level.
        self.cycle_broken = true;
        let initial = self.cycle_initial.take().or(self.broken_initial);
        self.broken_initial = Some(initial.unwrap_or(before));
        self.cycle_z = None;
        self.cycle_r = None;
        self.motion_pending = plan.cycle.motion_before;
    }

    /// The decimals of the word `w` of axis `slot` of a hole written as
    /// moves: X and Y at least [`cycles::hole_decimals`], so that the
    /// squareness's drift of a feed piece is not written as a step of a
    /// whole direction deadband.
    fn hole_decimals(&self, w: Option<&Word>, slot: usize, scale: f64) -> usize {
        let d = self.decimals(w, scale, false);
        if slot < 2 {
            d.max(cycles::hole_decimals(scale))
        } else {
            d
        }
    }

    /// One added line of an expanded hole: `G0`/`G1` with the axis words
    /// whose written value changes, or `G4` with the cycle's dwell.
    fn step_line(
        &mut self,
        block: &Block,
        plan: &Plan,
        step: &crate::compensate::cycles::Step,
        out: &mut Vec<u8>,
    ) {
        let lower = block.lower_case;
        let sep: &[u8] = if self.spaced { b" " } else { b"" };
        let g = if lower { b'g' } else { b'G' };
        let code = match step.kind {
            StepKind::Feed => b'1',
            StepKind::Dwell => b'4',
            StepKind::Position | StepKind::Rapid => b'0',
        };
        out.extend_from_slice(&[g, code]);
        if step.kind == StepKind::Dwell {
            if let Some((p, decimals)) = plan.cycle.dwell_p {
                out.extend_from_slice(sep);
                out.push(letter_case(b'P', lower));
                let d = decimals.unwrap_or(0) as usize;
                write_number(out, p, d, false);
                if decimals.is_none() {
                    // Written as the cycle's word was: without a point.
                    out.pop();
                }
            }
            return;
        }
        let mut any = false;
        // A positioning moves X and Y only (an approach point before the
        // hole, [`crate::compensate::cycles`]).
        let axes = if step.kind == StepKind::Position {
            2
        } else {
            3
        };
        for (slot, &letter) in AXIS_LETTERS.iter().enumerate().take(axes) {
            let w = block.word(letter);
            let d = self.hole_decimals(w, slot, plan.scale);
            let now = round_to(
                to_program(plan, slot, self.emitted[slot], self.emitted[slot]),
                d,
            );
            let want = round_to(to_program(plan, slot, step.to[slot], self.emitted[slot]), d);
            if want != now || (slot == 2 && !any) {
                out.extend_from_slice(sep);
                out.push(letter_case(letter, lower));
                write_number(out, want, d, true);
                self.emitted[slot] = to_machine(plan, slot, want, self.emitted[slot]);
                any = true;
            }
        }
    }

    /// Before a hole block that states the cycle again: where the holes
    /// written as moves left the tool below the cycle's initial level (a
    /// G99 hole ends at its R level), a `G0` back up to that level, so the
    /// cycle stated again has the program's initial level (a G98 hole
    /// returns there). Written as a line of its own before the block's.
    pub(super) fn restore_initial(
        &mut self,
        line: &[u8],
        block: &Block,
        plan: &Plan,
        out: &mut Vec<u8>,
    ) {
        if !self.cycle_broken || !matches!(plan.kind, PlanKind::Cycle { .. }) {
            return;
        }
        let Some(initial) = self.broken_initial.take() else {
            return;
        };
        let w = block.word(b'Z');
        let d = self.decimals(w, plan.scale, false);
        let want = round_to(to_program(plan, 2, initial, self.emitted[2]), d);
        let now = round_to(to_program(plan, 2, self.emitted[2], self.emitted[2]), d);
        if want == now || initial <= self.emitted[2] {
            return;
        }
        let text = strip_eol(line);
        let eol: &[u8] = match &line[text.len()..] {
            [] => b"\n",
            e => e,
        };
        let lower = block.lower_case;
        let sep: &[u8] = if self.spaced { b" " } else { b"" };
        if block.block_delete {
            out.push(b'/');
        }
        out.extend_from_slice(if lower { b"g0" } else { b"G0" });
        out.extend_from_slice(sep);
        out.push(letter_case(b'Z', lower));
        write_number(out, want, d, true);
        out.extend_from_slice(eol);
        self.emitted[2] = to_machine(plan, 2, want, self.emitted[2]);
        self.added += 1;
    }

    /// The edits that state the cycle again on a hole block written as a
    /// cycle after a hole written as moves: its G code, and its peck depth
    /// and dwell where the cycle has them and the block lacks them (Z and R
    /// follow, as the control holds none).
    pub(super) fn restate_cycle(&mut self, block: &Block, plan: &Plan, edits: &mut Edits) {
        if !self.cycle_broken || !matches!(plan.kind, PlanKind::Cycle { .. }) {
            return;
        }
        self.cycle_broken = false;
        let lower = block.lower_case;
        let spaced = self.spaced;
        let spec = plan.cycle;
        if cycle_word(block).is_none() {
            let at = insert_point_for_motion(block);
            let g = if lower { b'g' } else { b'G' };
            edits.push(at, at, |t| {
                t.push(g);
                write_number(t, spec.code10 as f64 / 10.0, 0, true);
                t.pop();
                if spaced || at > 0 {
                    t.push(b' ');
                }
            });
        }
        let end = block.words.last().map_or(0, |w| w.end as usize);
        let sep = if spaced { " " } else { "" };
        if spec.peck_mm > 0.0 && block.word(b'Q').is_none() {
            let d = self.decimals(None, plan.scale, false);
            let q = round_to(spec.peck_mm / plan.scale, d);
            edits.insert_word(end, sep, letter_case(b'Q', lower), q, d);
        }
        if let (Some((p, decimals)), None) = (spec.dwell_p, block.word(b'P')) {
            let d = decimals.unwrap_or(0) as usize;
            edits.push(end, end, |t| {
                t.extend_from_slice(sep.as_bytes());
                t.push(letter_case(b'P', lower));
                write_number(t, p, d, false);
                if decimals.is_none() {
                    t.pop();
                }
            });
        }
    }
}
