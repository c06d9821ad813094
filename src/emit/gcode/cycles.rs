//! Writing a canned-cycle hole as moves ([`crate::compensate::cycles`]):
//! the block's own line becomes the positioning `G0` (its cycle words
//! dropped, its other words kept), the added lines the cycle's rapids,
//! feeds and dwell. The cycle is then no longer in force on the control:
//! the next hole block of the same cycle that is not written as moves
//! states it again (its G code, Z, R, Q, P), and the modal motion the
//! cycle left in force is written again on the next block that relies on
//! it.

use super::{
    Edits, Emitter, added_line_start, insert_point_for_motion, letter_case, round_to, to_machine,
    to_program, write_number,
};
use crate::compensate::BlockResult;
use crate::compensate::cycles::StepKind;
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
            let d = self.decimals(w, scale, false);
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
            self.annotation(block, text, res, scale, edits);
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
        // The control has no cycle, nor its Z and R, any more.
        self.cycle_broken = true;
        self.cycle_z = None;
        self.cycle_r = None;
        self.motion_pending = plan.cycle.motion_before;
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
        for (slot, &letter) in AXIS_LETTERS.iter().enumerate().take(3) {
            let w = block.word(letter);
            let d = self.decimals(w, plan.scale, false);
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
